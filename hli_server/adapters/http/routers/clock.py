"""``/api/step``: the stepped clock."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from hli_server.adapters.http.deps import HostDep
from hli_server.adapters.http.models import StepBody

__all__ = ["router"]

router = APIRouter(tags=["clock"])


@router.post(
    "/api/step",
    summary="Run N cycles (stepped clock only)",
    responses={409: {"description": "the runtime does not run the stepped clock"}},
)
async def post_step(host: HostDep, body: StepBody | None = None) -> dict[str, Any]:
    cycles = body.cycles if body is not None else 1
    cycle = await host.step(cycles)
    return {"cycles": cycles, "cycle": cycle, "time_s": host.operator.time_s}
