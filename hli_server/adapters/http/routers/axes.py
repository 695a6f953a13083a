"""``/api/axes/{name}/...``: fault injection (A3-05), referencing, software limits (E-06)."""

from __future__ import annotations

from fastapi import APIRouter

from hli_server.adapters.http.deps import HostDep, accepted
from hli_server.adapters.http.models import AcceptedBody, AxisRecordBody, FaultsBody, SoftLimitsBody
from schemas.results import AxisFaults, SoftLimits

__all__ = ["router"]

router = APIRouter(tags=["axes"])


@router.get("/api/axes/{name}/faults", summary="Injected faults of an axis")
async def get_faults(host: HostDep, name: str) -> AxisFaults:
    return host.operator.faults(name)


@router.post("/api/axes/{name}/faults", summary="Inject faults (A3-05); omitted fields stay")
async def post_faults(host: HostDep, name: str, body: FaultsBody) -> AxisFaults:
    return host.operator.inject_faults(name, **body.model_dump(exclude_none=True))


@router.delete("/api/axes/{name}/faults", summary="Clear all injected faults of an axis")
async def delete_faults(host: HostDep, name: str) -> AxisFaults:
    return host.operator.clear_faults(name)


@router.post(
    "/api/axes/{name}/reference",
    status_code=202,
    summary="Reference (home) the axis: a homing move to its reference position (no program may run)",
)
async def post_reference(host: HostDep, name: str) -> AcceptedBody:
    return accepted(host.operator.reference(name))


@router.get(
    "/api/axes/{name}/soft-limits", summary="Software limits in effect and in the axis record [0.1 µm]"
)
async def get_soft_limits(host: HostDep, name: str) -> SoftLimits:
    return host.operator.soft_limits(name)


@router.put(
    "/api/axes/{name}/soft-limits",
    summary="Set the software limits in effect until the next reset or mode change (as G98/G99)",
)
async def put_soft_limits(host: HostDep, name: str, body: SoftLimitsBody) -> SoftLimits:
    return host.operator.set_soft_limits(name, **body.model_dump(exclude_none=True))


@router.put(
    "/api/axes/{name}/record",
    summary="Change the axis record's software limits: taken over at the next reset or mode change",
)
async def put_record(host: HostDep, name: str, body: AxisRecordBody) -> SoftLimits:
    return host.operator.update_axis_record(name, **body.model_dump(exclude_none=True))
