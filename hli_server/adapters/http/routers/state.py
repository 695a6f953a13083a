"""What the machine shows: ``/``, ``/api/state``, ``/api/timing``, ``/api/alarms``, areas."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from fastapi.responses import HTMLResponse

from hli_server.adapters.http.deps import HostDep

__all__ = ["router"]

router = APIRouter(tags=["state"])

ALARM_HISTORY_SHOWN = 200

_INDEX = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>hli-server {name}</title></head>
<body style="font-family: sans-serif; max-width: 40em; margin: 2em auto">
<h1>hli-server: machine {name}</h1>
<p>The simulated CNC kernel's control API. Cycle {cycle}, clock {clock}.</p>
<ul>
<li><a href="/docs">/docs</a>: the API, interactive (OpenAPI)</li>
<li><a href="/api/state">/api/state</a>: channels, axes, active alarms</li>
<li><a href="/api/layout">/api/layout</a>: the process image's address map</li>
<li><a href="/api/events">/api/events</a>: the event log</li>
</ul>
</body></html>
"""


@router.get("/", response_class=HTMLResponse, include_in_schema=False)
async def index(host: HostDep) -> str:
    op = host.operator
    return _INDEX.format(name=op.machine_name, cycle=op.cycle, clock=host.clock)


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
