"""What the machine shows: ``/api/state``, ``/api/timing``, ``/api/ready``, ``/api/alarms``, areas (the
page ``/`` is ``page.py``)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from hli_server.adapters.http.deps import HostDep
from schemas.results import AlarmList, AreaTable, MachineInfo, MachineState, ReadinessJson, Timing

__all__ = ["router"]

router = APIRouter(tags=["state"])

ALARM_HISTORY_SHOWN = 200


@router.get("/api/state", summary="Machine snapshot: channels, axes, active alarms")
async def get_state(host: HostDep) -> MachineState:
    snap = host.operator.snapshot()
    snap["clock"] = host.clock
    return snap


@router.get("/api/machine", summary="The machine: its name, T_A, the clock, the channels and their axes")
async def get_machine(host: HostDep) -> MachineInfo:
    operator = host.operator
    return {
        "name": operator.machine_name,
        "t_a_us": operator.t_a_us,
        "clock": host.clock,
        "channels": [{"number": n, "axes": operator.axis_names(n)} for n in operator.channel_numbers()],
    }


@router.get("/api/timing", summary="Pacing statistics of the clock (lateness in µs)")
async def get_timing(host: HostDep) -> Timing:
    return host.operator.timing()


@router.get(
    "/api/ready",
    summary="Readiness: 200 when the clock runs and every door asked for listens, else 503",
    response_model=ReadinessJson,
    responses={
        503: {"description": "starting (a door does not listen yet) or stopping", "model": ReadinessJson}
    },
)
async def get_ready(host: HostDep) -> JSONResponse:
    """The health checks of the image and the compose bench ask this, and an orchestrator's readiness
    probe should: the HTTP API answers a moment before the Modbus and ADS doors (their own process)
    listen, and goes on answering while the server stops. ``{"ready": true, "state": "running",
    "doors": {"http": true, "modbus": true, ...}, "waiting_for": []}``."""
    readiness = host.readiness()
    return JSONResponse(readiness.to_json(), status_code=200 if readiness.ready else 503)


@router.get("/api/alarms", summary="Active alarms and the newest of the history")
async def get_alarms(host: HostDep) -> AlarmList:
    return host.operator.alarms(ALARM_HISTORY_SHOWN)


@router.get("/api/channels/{number}/areas", summary="The channel's work and protection areas (FCT-C14)")
async def get_areas(host: HostDep, number: int) -> AreaTable:
    return host.operator.areas(number)
