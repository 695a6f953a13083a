"""``/api/step``: the stepped clock; ``/api/machine/restart``: the machine powered off and on (stepped).

One step at a time per server: a second ``POST /api/step`` while one runs is refused (409) rather than
queued behind it, and a step whose client goes away (closes its connection) is cancelled between two
slices of cycles (reliability.md, round 2, finding 6). A traced step's answer is written a slice at a time
from the trace's arrays (``Trace.json_chunks``), so that a long trace is never all of it Python objects or one
string (finding 9).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator
from typing import Any

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import Response, StreamingResponse

from hli_server.adapters.http.deps import HostDep, json_bytes
from hli_server.adapters.http.models import StepBody
from hli_server.adapters.http.routers.image import normalize_st_path
from schemas.layout import UnknownSignalError

__all__ = ["router"]

router = APIRouter(tags=["clock"])


async def _client_gone(request: Request) -> None:
    """Returns when the client closes its connection (the body was read already)."""
    while True:
        message = await request.receive()
        if message["type"] == "http.disconnect":
            return


@router.post(
    "/api/step",
    summary="Run N cycles (stepped clock only), optionally with a per-cycle trace of chosen signals",
    responses={
        404: {"description": "a traced ST path is not in the layout"},
        409: {"description": "the runtime does not run the stepped clock, or another step runs"},
    },
)
async def post_step(host: HostDep, request: Request, body: StepBody | None = None) -> Response:
    """Runs the cycles now. With ``trace``, the answer carries every traced signal in every one of
    these cycles (H-07): ``{"trace": {"signals": [...], "cycles": [c1, ..., cN], "values": {path:
    [v1, ..., vN]}}}``, so that a scenario is cycle-exact in one request instead of a state request
    and image reads per cycle. One step runs at a time (409 while another runs); closing the connection
    cancels the step."""
    cycles = body.cycles if body is not None else 1
    traced = [normalize_st_path(p) for p in body.trace] if body is not None and body.trace else None
    state = request.app.state
    running = getattr(state, "step_running", None)
    if running is not None:
        raise HTTPException(
            409,
            f"a step of {running[0]} cycles runs (for {time.monotonic() - running[1]:.1f} s): one step at a "
            "time; wait for its answer, or close its connection to cancel it",
        )
    state.step_running = (cycles, time.monotonic())
    try:
        work: asyncio.Future[Any] = asyncio.ensure_future(
            host.step(cycles) if traced is None else host.step_traced(cycles, traced)
        )
        gone = asyncio.ensure_future(_client_gone(request))
        try:
            await asyncio.wait({work, gone}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            gone.cancel()
            if not work.done():  # the client went away (or this request was cancelled): stop stepping
                work.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await work
        if work.cancelled():
            return Response(status_code=499)  # nobody reads it: the client is gone
        try:
            result = work.result()
        except UnknownSignalError as exc:
            raise HTTPException(404, str(exc)) from None
    finally:
        state.step_running = None
    head = {"cycles": cycles, "cycle": host.operator.cycle, "time_s": host.operator.time_s}
    if traced is None:
        return Response(json_bytes({**head, "cycle": result}), media_type="application/json")
    trace = result

    async def chunks() -> AsyncIterator[bytes]:
        yield json_bytes(head)[:-1] + b',"trace":'
        for chunk in trace.json_chunks():
            yield chunk
        yield b"}"

    return StreamingResponse(chunks(), media_type="application/json")


@router.post(
    "/api/machine/restart",
    summary="Power the machine off and on (stepped clock only): the machine file's machine at cycle 0",
    responses={409: {"description": "the runtime does not run the stepped clock, or a recording runs"}},
)
async def post_machine_restart(host: HostDep) -> Response:
    """A new machine from the machine file, as at the server's start: cycle 0, the axes where the file puts
    them, the PLC's half of the image as at start, no alarm, no injected or communication fault, no file
    uploaded with a program; the input journal begins anew. The doors stay open and their connections too;
    the event log goes on. After a step that runs, never inside one. What a test bench does between two
    tests on a server it did not start (``pytest --hli-url``, docs/testing.md): ``{"cycle": 0}``."""
    cycle = await host.restart()
    return Response(
        json_bytes({"cycle": cycle, "time_s": host.operator.time_s}), media_type="application/json"
    )
