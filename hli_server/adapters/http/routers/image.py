"""``/api/layout`` and ``/api/image/{st_path}``: the process image by ST path (H-01, H-02)."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException

from hli_server.adapters.host import AdapterHost, Value
from hli_server.adapters.http.deps import HostDep
from hli_server.adapters.http.models import ImageWriteBody
from schemas.layout import LayoutJson, ReadOnlySignalError, Signal, SignalValueError, UnknownSignalError
from schemas.results import ImageField

__all__ = ["router"]

router = APIRouter(tags=["image"])

ST_PATH_EXAMPLE = "gpCh[0]^bahn_mc_control.override.command_w"


@router.get("/api/layout", summary="The image layout (as `hli-server map --format json`)")
async def get_layout(host: HostDep) -> LayoutJson:
    return host.image.layout.to_dict()


@router.get(
    "/api/image/{st_path:path}",
    summary=f"Read an image field by ST path, e.g. {ST_PATH_EXAMPLE}",
    responses={404: {"description": "unknown ST path"}},
)
async def get_image(host: HostDep, st_path: str) -> ImageField:
    signal = _signal_or_404(host, st_path)
    return _field_json(host, signal, host.image.read(signal.st_path))


@router.put(
    "/api/image/{st_path:path}",
    summary="Write a PLC->CNC image field (_w) by ST path; latched at the next cycle",
    responses={
        403: {"description": "a CNC->PLC field (_r): only the CNC writes it (H-02)"},
        404: {"description": "unknown ST path"},
        422: {"description": "the value does not fit the field's type"},
    },
)
async def put_image(host: HostDep, st_path: str, body: ImageWriteBody) -> ImageField:
    signal = _signal_or_404(host, st_path)
    try:
        signal.check_plc_write()
        value = signal.coerce(body.value)
        host.image.write_signal(signal, value)
    except ReadOnlySignalError as exc:
        raise HTTPException(403, str(exc)) from None
    except SignalValueError as exc:
        raise HTTPException(422, str(exc)) from None
    out = _field_json(host, signal, value)
    out["effective_cycle"] = host.operator.cycle + 1
    return out


def normalize_st_path(path: str) -> str:
    """Accept ``gpAx[0].ipo_state.act_pos_r`` for ``gpAx[0]^ipo_state.act_pos_r`` (``^`` is awkward
    in URLs: it must be sent as ``%5E``), and so ``gpVECh[0].MODE`` and ``gpVEGlob.MODE`` for the V.E.
    variables (N-05)."""
    path = path.strip("/")
    if "^" not in path and path.startswith(("gpCh[", "gpAx[", "gpVECh[")):
        head, dot, rest = path.partition("].")
        if dot:
            return f"{head}]^{rest}"
    if "^" not in path and path.startswith("gpVEGlob."):
        return "gpVEGlob^" + path.removeprefix("gpVEGlob.")
    return path


def _signal_or_404(host: AdapterHost, st_path: str) -> Signal:
    try:
        return host.image.layout.signal(normalize_st_path(st_path))
    except UnknownSignalError as exc:
        raise HTTPException(404, str(exc)) from None


def _field_json(host: AdapterHost, signal: Signal, value: Value) -> ImageField:
    return {
        "st_path": signal.st_path,
        "value": value,
        "type": signal.type_name,
        "direction": str(signal.direction),
        "access": signal.access,
        "unit": signal.unit,
        "cycle": host.operator.cycle,
    }
