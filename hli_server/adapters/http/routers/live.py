"""``/api/live`` (the dashboard's event stream), the scene, the program table and the collision pairs."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import StreamingResponse

from hli_server.adapters.http.deps import HostDep
from hli_server.adapters.http.live_feed import LiveFeed, TooManyStreamsError
from schemas.results import CollisionPair, ProgramEntry, Scene

__all__ = ["router"]

router = APIRouter(tags=["dashboard"])


def _feed(request: Request) -> LiveFeed:
    feed: LiveFeed = request.app.state.live
    return feed


@router.get(
    "/api/live",
    summary="Server-sent events: hello, state (20 Hz), event, scene, dropped (the dashboard's feed)",
    response_class=StreamingResponse,
    responses={
        200: {"content": {"text/event-stream": {}}, "description": "an endless event stream"},
        503: {"description": "all stream slots are taken (max_streams)"},
    },
)
async def get_live(request: Request) -> StreamingResponse:
    feed = _feed(request)
    # with --api-token the events (the event log, live) go to holders of the token only (guard.py)
    events = bool(getattr(request.state, "hli_token", True))
    try:
        stream = feed.open(events=events)
    except TooManyStreamsError as exc:
        raise HTTPException(503, str(exc)) from None
    except RuntimeError as exc:
        raise HTTPException(503, str(exc)) from None
    hello = feed.hello(events=events)
    loop = asyncio.get_running_loop()

    async def chunks() -> AsyncIterator[bytes]:
        try:
            stream.sending_since = loop.time()
            yield hello
            while True:
                stream.sending_since = None  # the page took the last message
                chunk = await stream.next_chunk()
                if chunk is None:
                    return
                stream.sending_since = loop.time()
                yield chunk
        finally:
            feed.release(stream)

    return StreamingResponse(
        chunks(),
        media_type="text/event-stream",
        headers={"cache-control": "no-cache", "x-accel-buffering": "no"},
    )


@router.get(
    "/api/channels/{number}/scene",
    summary="The channel's live scene: areas, trail, path ahead, TCP, refused block (as check --plot draws)",
)
async def get_scene(host: HostDep, number: int) -> Scene:
    return host.operator.scene(number)


@router.get("/api/channels/{number}/programs", summary="The channel's program table (for select)")
async def get_programs(host: HostDep, number: int) -> list[ProgramEntry]:
    return host.operator.programs(number)


@router.get("/api/collision-pairs", summary="Collision pairs (FCT-C3): distance, minimum, braking distances")
async def get_collision_pairs(host: HostDep) -> list[CollisionPair]:
    return host.operator.collision_pairs()
