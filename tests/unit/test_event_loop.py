"""The servers' asyncio loop (``runtime/event_loop.py``): asyncio's selector loop with Python 3.13's turn on
3.11 and 3.12. It must behave as asyncio's: timers in time order, cancellation, callbacks in the order they
were scheduled, I/O, the debug mode's slow-callback warning, the clamped timeout, the compaction of many
cancelled timers."""

from __future__ import annotations

import asyncio
import logging
import selectors
import socket
import sys
import time
from asyncio import base_events
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

import pytest

from hli_server.runtime.event_loop import BACKPORTED, LeanSelectorEventLoop, lean_event_loop
from hli_server.runtime.pacing import PreciseEpollSelector, precise_event_loop, probed_default_loop

T = TypeVar("T")


def run(main: Callable[[], Coroutine[Any, Any, T]]) -> T:
    with asyncio.Runner(loop_factory=lean_event_loop) as runner:
        assert isinstance(runner.get_loop(), LeanSelectorEventLoop)
        return runner.run(main())


def test_the_turn_is_backported_before_3_13_and_asyncios_own_after() -> None:
    assert (sys.version_info < (3, 13)) == BACKPORTED
    ours = LeanSelectorEventLoop.__dict__.get("_run_once")
    assert (ours is not None) == BACKPORTED
    if not BACKPORTED:
        assert LeanSelectorEventLoop._run_once is base_events.BaseEventLoop._run_once  # type: ignore[attr-defined]


def test_the_servers_loops_are_lean() -> None:
    for factory in (precise_event_loop, probed_default_loop, lean_event_loop):
        loop = factory()
        try:
            assert isinstance(loop, LeanSelectorEventLoop)
        finally:
            loop.close()
    loop = precise_event_loop()
    try:
        assert isinstance(loop._selector, PreciseEpollSelector)  # type: ignore[attr-defined]
    finally:
        loop.close()


def test_timers_fire_in_time_order_and_a_cancelled_one_never() -> None:
    async def main() -> list[object]:
        loop = asyncio.get_running_loop()
        out: list[object] = []
        loop.call_later(0.03, out.append, "c")
        loop.call_later(0.01, out.append, "a")
        loop.call_later(0.02, out.append, "b").cancel()
        loop.call_at(loop.time() - 1.0, out.append, "past")  # due already: the next turn
        loop.call_soon(out.append, "soon")
        await asyncio.sleep(0.06)
        return out

    assert run(main) == ["soon", "past", "a", "c"]


def test_a_timer_waits_at_least_its_delay() -> None:
    async def main() -> float:
        loop = asyncio.get_running_loop()
        fired = loop.create_future()
        began = loop.time()
        loop.call_later(0.02, lambda: fired.set_result(loop.time()))
        at: float = await fired
        return at - began

    assert run(main) >= 0.02


def test_callbacks_scheduled_by_a_callback_run_in_the_next_turn() -> None:
    async def main() -> list[str]:
        loop = asyncio.get_running_loop()
        out: list[str] = []

        def first() -> None:
            out.append("first")
            loop.call_soon(out.append, "from first")

        loop.call_soon(first)
        loop.call_soon(out.append, "second")
        await asyncio.sleep(0)
        await asyncio.sleep(0)
        return out

    assert run(main) == ["first", "second", "from first"]


def test_many_cancelled_timers_are_compacted_and_the_live_ones_still_fire() -> None:
    async def main() -> tuple[list[int], int]:
        loop = asyncio.get_running_loop()
        out: list[int] = []
        handles = [loop.call_later(10.0 + i, out.append, i) for i in range(300)]
        for h in handles[:250]:
            h.cancel()
        keep = [loop.call_later(0.001 * (i + 1), out.append, 1000 + i) for i in range(3)]
        await asyncio.sleep(0.02)
        left = len(loop._scheduled)  # type: ignore[attr-defined]
        for h in handles[250:] + keep:
            h.cancel()
        return out, left

    out, left = run(main)
    assert out == [1000, 1001, 1002]
    assert left == 50  # the 250 cancelled ones were dropped, the 50 live far ones remain


def test_a_far_timer_does_not_wait_beyond_the_clamp() -> None:
    """A timer a year away: the loop still serves I/O and the timeout it asks for is clamped (no error)."""

    async def main() -> bytes:
        loop = asyncio.get_running_loop()
        far = loop.call_later(365 * 24 * 3600.0, lambda: None)
        a, b = socket.socketpair()
        try:
            a.setblocking(False)
            b.setblocking(False)
            got = loop.create_future()
            loop.add_reader(b, lambda: got.set_result(b.recv(16)))
            loop.call_later(0.01, a.send, b"ping")
            data: bytes = await asyncio.wait_for(got, 5.0)
            loop.remove_reader(b)
            return data
        finally:
            far.cancel()
            a.close()
            b.close()

    assert run(main) == b"ping"


def test_the_timeout_asked_of_the_selector_is_the_next_timers_clamped() -> None:
    asked: list[float | None] = []

    class Recording(selectors.DefaultSelector):
        """Notes the timeout asked for and does not wait (the turn is what is under test)."""

        def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
            asked.append(timeout)
            return list(super().select(0))

    far_away = 10.0 * base_events.MAXIMUM_SELECT_TIMEOUT  # type: ignore[attr-defined]
    loop = LeanSelectorEventLoop(Recording())
    try:
        loop.call_later(far_away, lambda: None)
        loop.call_soon(lambda: None)
        turn: Callable[[], None] = loop._run_once
        turn()  # a callback is ready: no wait
        turn()  # only the far timer: its time, clamped
        loop.call_later(0.5, lambda: None)
        turn()  # the nearer timer: its time
        loop.call_at(loop.time() - 1.0, lambda: None)
        turn()  # a timer overdue: no wait
    finally:
        loop.close()
    assert asked[0] == 0
    assert asked[1] == base_events.MAXIMUM_SELECT_TIMEOUT  # type: ignore[attr-defined]
    assert asked[2] is not None
    assert 0.4 < asked[2] <= 0.5
    assert asked[3] == 0


def test_debug_mode_warns_of_a_slow_callback(caplog: pytest.LogCaptureFixture) -> None:
    async def main() -> None:
        loop = asyncio.get_running_loop()
        loop.slow_callback_duration = 0.001
        loop.call_soon(time.sleep, 0.01)
        await asyncio.sleep(0.02)

    with (
        caplog.at_level(logging.WARNING, logger="asyncio"),
        asyncio.Runner(loop_factory=lean_event_loop, debug=True) as runner,
    ):
        runner.run(main())
    assert any("took" in r.getMessage() and "sleep" in r.getMessage() for r in caplog.records)


def test_a_failing_callback_is_reported_and_the_loop_goes_on() -> None:
    async def main() -> list[object]:
        loop = asyncio.get_running_loop()
        seen: list[object] = []
        loop.set_exception_handler(lambda _loop, context: seen.append(type(context.get("exception"))))
        loop.call_soon(lambda: 1 / 0)
        loop.call_later(0.001, seen.append, "after")
        await asyncio.sleep(0.01)
        return seen

    assert run(main) == [ZeroDivisionError, "after"]
