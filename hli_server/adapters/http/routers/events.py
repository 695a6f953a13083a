"""``/api/events``: the event log, polled by sequence number."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query

from hli_server.adapters.http.deps import HostDep

__all__ = ["router"]

router = APIRouter(tags=["events"])


@router.get("/api/events", summary="Engine events after sequence number `since`")
async def get_events(
    host: HostDep,
    since: Annotated[int, Query(ge=0, description="last seq you have seen (0: from the start)")] = 0,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 1000,
) -> dict[str, Any]:
    events, latest = host.events.since(since, limit)
    oldest = events[0].seq if events else latest + 1
    return {
        "events": [e.to_json() for e in events],
        "next": events[-1].seq if events else max(since, 0),
        "latest": latest,
        "missed": max(0, oldest - since - 1),
    }
