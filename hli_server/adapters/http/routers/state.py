"""What the machine shows: ``/api/state``, ``/api/timing``, ``/api/alarms``, areas (the page ``/`` is
``page.py``)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from hli_server.adapters.http.deps import HostDep

__all__ = ["router"]

router = APIRouter(tags=["state"])

ALARM_HISTORY_SHOWN = 200


@router.get("/api/state", summary="Machine snapshot: channels, axes, active alarms")
async def get_state(host: HostDep) -> dict[str, Any]:
    snap = host.operator.snapshot()
    snap["clock"] = host.clock
    return snap


@router.get("/api/timing", summary="Pacing statistics of the clock (lateness in µs)")
async def get_timing(host: HostDep) -> dict[str, Any]:
    return host.operator.timing()


@router.get("/api/alarms", summary="Active alarms and the newest of the history")
async def get_alarms(host: HostDep) -> dict[str, Any]:
    return host.operator.alarms(ALARM_HISTORY_SHOWN)


@router.get("/api/channels/{number}/areas", summary="The channel's work and protection areas (FCT-C14)")
async def get_areas(host: HostDep, number: int) -> dict[str, Any]:
    return host.operator.areas(number)
