"""``/api/axes/{name}/...``: fault injection (A3-05) and referencing."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from hli_server.adapters.http.deps import HostDep, accepted
from hli_server.adapters.http.models import AcceptedBody, FaultsBody

__all__ = ["router"]

router = APIRouter(tags=["axes"])


@router.get("/api/axes/{name}/faults", summary="Injected faults of an axis")
async def get_faults(host: HostDep, name: str) -> dict[str, Any]:
    return host.operator.faults(name)


@router.post("/api/axes/{name}/faults", summary="Inject faults (A3-05); omitted fields stay")
async def post_faults(host: HostDep, name: str, body: FaultsBody) -> dict[str, Any]:
    return host.operator.inject_faults(name, **body.model_dump(exclude_none=True))


@router.delete("/api/axes/{name}/faults", summary="Clear all injected faults of an axis")
async def delete_faults(host: HostDep, name: str) -> dict[str, Any]:
    return host.operator.clear_faults(name)


@router.post(
    "/api/axes/{name}/reference",
    status_code=202,
    summary="Reference (home) the axis: a homing move to its reference position (no program may run)",
)
async def post_reference(host: HostDep, name: str) -> AcceptedBody:
    return accepted(host.operator.reference(name))
