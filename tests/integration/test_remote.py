"""The doors process' link to the engine (``runtime/remote.py``, issue 26), over a real socket pair.

The engine's end (``OperatorService``) runs on a stepped runtime in this process; the doors' end
(``RemoteLink``, ``RemoteOperator``, ``EventMirror``) uses the other end of the pair, as the doors process
does: operator requests, the event log mirrored with the engine's numbers, steps with traces, a step
cancelled by its client, and requests that are not the operator's refused.
"""

from __future__ import annotations

import asyncio
import socket
import threading
import time
from collections.abc import Coroutine
from typing import Any, TypeVar

import httpx
import pytest

from hli_server.adapters.host import ConflictError, NotFoundError, OperatorError
from hli_server.configuration import load_machine
from hli_server.runtime import Runtime, remote
from hli_server.runtime.event_log import EVENT_LOG
from hli_server.runtime.remote import (
    EventMirror,
    FrameReader,
    OperatorService,
    RemoteFaults,
    RemoteLink,
    RemoteOperator,
    frame,
)
from schemas.events import NcMessage

PROGRAM = "N10 G01 X200 F600\nN20 M30\n"  # 20 s: it still runs when the test is done
FLOOD = 'P1 = 0\n$WHILE 1\nP1 = P1 + 1\n#MSG ["part %d of the batch done", P1]\n$ENDWHILE\nM30\n'
T = TypeVar("T")


def test_frames_arrive_whole_however_the_bytes_are_split() -> None:
    messages = [("call", 1, "snapshot", (), {}), ("events", [(1, "x")]), ("ok", 2, b"\x00" * 70_000)]
    data = b"".join(frame(m) for m in messages)
    for size in (1, 3, 4096, len(data)):
        reader = FrameReader()
        out = []
        for i in range(0, len(data), size):
            out += reader.feed(data[i : i + size])
        assert out == messages


class Engine:
    """A stepped runtime and its ``OperatorService`` on a loop of their own (a thread): the engine's process
    of ``hli-server run``, so that the doors' side may block in this test's loop as it does in its own."""

    def __init__(self) -> None:
        self.ours, self.theirs = socket.socketpair()
        self.ready = threading.Event()
        self.rt: Runtime | None = None
        self.service: OperatorService | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()), daemon=True)

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        async with Runtime(load_machine(None), clock="stepped", http_port=None) as rt:
            self.rt = rt
            _, service = await self._loop.connect_accepted_socket(lambda: OperatorService(rt), self.ours)
            self.service = service
            remove = rt.add_service(service)
            self.ready.set()
            await self._stop.wait()
            remove()
            service.close()

    def __enter__(self) -> Engine:
        self._thread.start()
        assert self.ready.wait(30)
        return self

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        """``coro`` on the engine's loop, waited for here."""
        assert self._loop is not None
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result(60)

    def __exit__(self, *exc: object) -> None:
        assert self._loop is not None
        assert self._stop is not None
        self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(30)


def doors_side(engine: Engine) -> tuple[Runtime, EventMirror, RemoteLink, RemoteOperator]:
    """The doors process' end of the link in this test's loop: the event mirror, the link, the operator."""
    rt = engine.rt
    assert rt is not None
    loop = asyncio.get_running_loop()
    mirror = EventMirror()
    mirror.start(loop)
    link = RemoteLink(engine.theirs, mirror.take)
    link.start(loop)
    return rt, mirror, link, RemoteOperator(link, rt.image, rt.config.cycle_time_us)


@pytest.mark.req("H-01", "H-07")
async def test_operator_requests_events_and_steps_cross_the_link() -> None:
    with Engine() as engine:
        rt, mirror, link, op = doors_side(engine)
        seen: list[str] = []
        mirror.subscribe(lambda e: seen.append(e.kind))
        try:
            assert op.machine_name == "demo"
            assert op.channel_numbers() == [1, 2]
            assert op.load_program(1, PROGRAM, "p")["lines"] == 2
            assert op.start(1).effective_cycle == 1
            with pytest.raises(NotFoundError, match="no channel 9"):
                op.start(9)
            assert await op.step(300) == 300
            trace = await op.step_traced(5, ["gpAx[0]^ipo_state.cmd_pos_r"])
            assert trace.cycles == [301, 302, 303, 304, 305]
            assert op.cycle == 305  # from the image
            events, latest = mirror.since(0)
            assert latest == rt.event_log.latest >= 2  # the engine's numbers, the engine's events
            assert [e.seq for e in events] == [e.seq for e in rt.events_since(0)[0]]
            await asyncio.sleep(0)  # the subscribers are called from the loop
            assert "program_state" in seen
            with pytest.raises(ConflictError):
                op.load_program(1, PROGRAM, "again")  # a program runs: the channel's own refusal
            with pytest.raises(OperatorError, match="not an operator request"):
                link.call("call", "_channel", (1,), {})
            timing = op.timing()
            assert timing["clock"] == "stepped"
            assert timing["cycles"] == 305

            step = asyncio.create_task(op.step(1_000_000))  # a long step, then its client goes away
            await asyncio.sleep(0.3)
            step.cancel()
            with pytest.raises(asyncio.CancelledError):
                await step
            await asyncio.sleep(0.3)
            stopped_at = rt.machine.cycle
            await asyncio.sleep(0.3)
            assert rt.machine.cycle == stopped_at < 1_000_305  # cancelled in the engine too
            assert await op.step(1) == stopped_at + 1  # the next step runs
        finally:
            link.close()


@pytest.mark.req("B-03")
async def test_a_fault_ended_through_the_doors_says_how_often_it_acted_and_why() -> None:
    """Issue 37, item 4: the doors process counts what its connections use of a fault (the engine's table
    does not); ending the fault through the doors (``DELETE /api/comm/faults/1``) answers with that
    count, and the doors' fault history gives the engine's reason ("api", "cycles"), as the engine's log
    and the recording do, not "engine"."""
    with Engine() as engine:
        rt, _, link, op = doors_side(engine)
        faults = RemoteFaults(link, lambda: rt.image.cycle)
        try:
            fault = faults.add({"kind": "error", "door": "modbus", "code": 2, "count": 5})
            faults.acted(fault)  # two Modbus requests of the doors' connections answered with the error
            faults.acted(fault)
            ended = faults.end(fault.id, "api").to_json()
            assert (ended["used"], ended["left"]) == (2, 3)
            assert faults.get(fault.id) is None
            by_api = {"fault": "end", "id": fault.id, "reason": "api"}.items()
            assert by_api <= faults.history[-1].items()
            assert by_api <= rt.comm_faults.history[-1].items()  # the engine's: what the log says

            stall = faults.add({"kind": "stall", "cycles": 3})  # ended by the engine when its cycles are over
            await op.step(5)
            deadline = time.monotonic() + 10
            while faults.get(stall.id) is not None:  # the engine's table comes after the step's cycles
                assert time.monotonic() < deadline, "the engine's table never came"
                await asyncio.sleep(0.01)
            assert {"fault": "end", "id": stall.id, "reason": "cycles"}.items() <= faults.history[-1].items()
            assert faults.reset() == 0
        finally:
            link.close()


@pytest.mark.req("H-05")
async def test_a_doors_process_that_lags_costs_the_engine_no_memory_and_sees_the_gap(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The doors process does not read (busy, stopped): the engine sends events until 64 KiB wait in its
    socket buffer (``MIRROR_BUFFER_BYTES``, 8 MiB in the server), then keeps only the newest ``EVENT_LOG``
    for later; when the doors read again they get those, and the numbers say what they missed (issue 36,
    finding 4: the events must cost the clock the same whatever their consumers do)."""
    monkeypatch.setattr(remote, "MIRROR_BUFFER_BYTES", 64 * 1024)
    with Engine() as engine:
        rt, service = engine.rt, engine.service
        assert rt is not None
        assert service is not None

        async def flood(cycles: int) -> int:
            if rt.machine.cycle == 0:
                rt.operator.load_program(1, FLOOD, "flood")
                rt.operator.start(1)
            for _ in range(cycles):  # a step a cycle: a flush a cycle, as the realtime clock's wake-ups
                await rt.step(1)
            return service.buffered

        async def flush() -> None:
            service.flush()

        buffered = engine.run(flood(1500))  # 32 events a cycle, 48,000 events: far more than the bound
        assert service.withheld > 0
        assert buffered <= 64 * 1024 + 200_000  # the bound plus one batch, not 48,000 events' worth
        assert service.held == EVENT_LOG  # the newest, for when the doors read again
        latest = rt.event_log.latest
        assert latest > 40_000

        loop = asyncio.get_running_loop()
        mirror = EventMirror()
        mirror.start(loop)
        link = RemoteLink(engine.theirs, mirror.take)
        link.start(loop)  # the doors read again
        try:
            for _ in range(200):
                await asyncio.sleep(0.02)
                if mirror.log.latest >= latest:
                    break
                engine.run(flush())  # as after a batch of cycles: sent once the doors took the rest
            assert mirror.log.latest >= latest
        finally:
            link.close()
    assert mirror.lost > 0  # the gap: counted, not hidden
    events, newest = mirror.since(0, 10_000)
    assert newest == events[-1].seq >= latest
    assert [e.seq for e in events] == sorted({e.seq for e in events})  # in order, none twice


@pytest.mark.req("H-05")
async def test_the_event_log_counts_a_gap_in_the_numbers_as_missed() -> None:
    """``missed`` counts every number between ``since`` and the last event answered that is not there:
    those the log's bound dropped, and those the doors process never got (a gap)."""
    async with Runtime(load_machine(None), clock="stepped", http_port=0) as rt:
        log = rt.event_log
        first = log.latest
        event = NcMessage(cycle=0, time_s=0.0, channel=1, text="x")
        log.extend([(first + 1, event), (first + 2, event), (first + 6, event), (first + 7, event)])
        async with httpx.AsyncClient(base_url=rt.http_url, timeout=10) as c:
            body = (await c.get(f"/api/events?since={first}")).json()
            assert [e["seq"] for e in body["events"]] == [first + 1, first + 2, first + 6, first + 7]
            assert body["missed"] == 3
            body = (await c.get(f"/api/events?since={first + 1}&limit=1")).json()
            assert body["missed"] == 0
            assert body["next"] == first + 2
            body = (await c.get(f"/api/events?since={first + 2}&limit=1")).json()
            assert body["missed"] == 3
