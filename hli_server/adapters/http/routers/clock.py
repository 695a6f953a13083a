"""``/api/step``: the stepped clock."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, HTTPException

from hli_server.adapters.http.deps import HostDep
from hli_server.adapters.http.models import StepBody
from hli_server.adapters.http.routers.image import normalize_st_path
from schemas.layout import UnknownSignalError

__all__ = ["router"]

router = APIRouter(tags=["clock"])


@router.post(
    "/api/step",
    summary="Run N cycles (stepped clock only), optionally with a per-cycle trace of chosen signals",
    responses={
        404: {"description": "a traced ST path is not in the layout"},
        409: {"description": "the runtime does not run the stepped clock"},
    },
)
async def post_step(host: HostDep, body: StepBody | None = None) -> dict[str, Any]:
    """Runs the cycles now. With ``trace``, the answer carries every traced signal in every one of
    these cycles (H-07): ``{"trace": {"signals": [...], "cycles": [c1, ..., cN], "values": {path:
    [v1, ..., vN]}}}``, so that a scenario is cycle-exact in one request instead of a state request
    and image reads per cycle."""
    cycles = body.cycles if body is not None else 1
    if body is None or not body.trace:
        cycle = await host.step(cycles)
        return {"cycles": cycles, "cycle": cycle, "time_s": host.operator.time_s}
    try:
        trace = await host.step_traced(cycles, [normalize_st_path(p) for p in body.trace])
    except UnknownSignalError as exc:
        raise HTTPException(404, str(exc)) from None
    return {
        "cycles": cycles,
        "cycle": host.operator.cycle,
        "time_s": host.operator.time_s,
        "trace": trace.to_json(),
    }
