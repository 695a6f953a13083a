"""``/api/events``: the event log, polled by sequence number.

The answer is written a slice of :data:`SLICE` events at a time, with the door's loop free between two
slices: a read of the whole log (10,000 events, about 1.4 MB) then delays the door's other clients by
milliseconds, not by the whole answer (reliability.md, round 2, finding 1; the clock's loop it does not reach
at all: the doors process keeps its own copy of the log, ``runtime/remote.py``).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import Annotated, Any

from fastapi import APIRouter, Query
from fastapi.responses import StreamingResponse

from hli_server.adapters.http.deps import HostDep, json_bytes

__all__ = ["SLICE", "router"]

router = APIRouter(tags=["events"])

SLICE = 250
"""Events rendered between two turns of the door's loop."""


@router.get(
    "/api/events",
    summary="Engine events after sequence number `since`",
    response_class=StreamingResponse,
    responses={200: {"content": {"application/json": {}}, "description": "{events, next, latest, missed}"}},
)
async def get_events(
    host: HostDep,
    since: Annotated[int, Query(ge=0, description="last seq you have seen (0: from the start)")] = 0,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 1000,
) -> StreamingResponse:
    events, latest = host.events.since(since, limit)
    # missed: the numbers between since and the last event answered that are not among them (dropped from
    # the log's bound, or never mirrored into the doors process: runtime/remote.py)
    last = events[-1].seq if events else latest
    tail: dict[str, Any] = {
        "next": events[-1].seq if events else max(since, 0),
        "latest": latest,
        "missed": max(0, last - since - len(events)),
    }

    async def chunks() -> AsyncIterator[bytes]:
        yield b'{"events":['
        for start in range(0, len(events), SLICE):
            part = json_bytes([e.to_json() for e in events[start : start + SLICE]])[1:-1]
            yield (b"," if start else b"") + part
            await asyncio.sleep(0)  # the door's other clients between two slices
        yield b"]," + json_bytes(tail)[1:]

    return StreamingResponse(chunks(), media_type="application/json")
