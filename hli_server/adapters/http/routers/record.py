"""``/api/recording``, ``/api/recordings`` and ``/api/comm/faults`` (docs/record-replay.md).

Recording: start and stop a recording of the session (one at a time, by name in the server's recording
directory, ``--record-dir``), its status, the list of recordings and their download. Communication
faults: set one (``POST``, a :class:`~hli_server.adapters.faults.FaultSpec`), list them, end one or all.
"""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import FileResponse
from pydantic import BaseModel, ConfigDict, Field

from hli_server.adapters.faults import FaultError, FaultSpec
from hli_server.adapters.host import ConflictError, NotFoundError
from hli_server.adapters.http.deps import HostDep
from schemas.results import CommFault, CommFaultsEnded, CommFaultTable, RecorderStatus, RecordingFile

__all__ = ["router"]

router = APIRouter(tags=["record and faults"])


class RecordingStartBody(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str | None = Field(
        default=None,
        max_length=120,
        description="file name in the recording directory (A-Z a-z 0-9 _ . -; .jsonl.gz is added); "
        "default: session-<date>-<time>",
    )


@router.get("/api/recording", summary="Whether a recording runs, into which file, how far")
async def get_recording(host: HostDep) -> RecorderStatus:
    return host.recorder.status()


@router.post(
    "/api/recording/start",
    status_code=201,
    summary="Start recording the session (every input with its cycle, the outputs beside them)",
    responses={409: {"description": "a recording runs already, or the server has no recording directory"}},
)
async def start_recording(host: HostDep, body: RecordingStartBody | None = None) -> RecorderStatus:
    return host.recorder.start(body.name if body is not None else None)


@router.post(
    "/api/recording/stop",
    summary="Stop the recording: flushed, its end line written, closed",
    responses={409: {"description": "no recording runs"}},
)
async def stop_recording(host: HostDep) -> RecorderStatus:
    return host.recorder.stop()


@router.get("/api/recordings", summary="The recordings in the recording directory")
async def list_recordings(host: HostDep) -> list[RecordingFile]:
    return host.recorder.files()


@router.get(
    "/api/recordings/{name}",
    summary="Download a recording (gzip JSON Lines; `hli-server replay` replays it)",
    response_class=FileResponse,
    responses={404: {"description": "no such recording"}},
)
async def download_recording(host: HostDep, name: str) -> FileResponse:
    path = host.recorder.file(name)
    return FileResponse(path, media_type="application/gzip", filename=name)


@router.get("/api/comm/faults", summary="The communication faults in effect")
async def get_comm_faults(host: HostDep) -> CommFaultTable:
    return {"faults": host.faults.table(), "history": list(host.faults.history)[-50:]}


@router.post(
    "/api/comm/faults",
    status_code=201,
    summary="Set a communication fault: delay, drop, error (Modbus, ADS), stall (shm), disconnect (MQTT)",
    responses={409: {"description": "too many faults in effect"}, 422: {"description": "an invalid fault"}},
)
async def post_comm_fault(host: HostDep, body: FaultSpec) -> CommFault:
    try:
        return host.faults.add(body).to_json()
    except FaultError as exc:
        raise ConflictError(str(exc)) from None


@router.delete("/api/comm/faults/{fault_id}", summary="End one communication fault now")
async def delete_comm_fault(host: HostDep, fault_id: int) -> CommFault:
    try:
        return host.faults.end(fault_id, "api").to_json()
    except FaultError as exc:
        raise NotFoundError(str(exc)) from None


@router.delete("/api/comm/faults", summary="End every communication fault (reset)")
async def reset_comm_faults(host: HostDep) -> CommFaultsEnded:
    return {"ended": host.faults.reset("reset")}
