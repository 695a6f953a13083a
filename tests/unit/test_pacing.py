"""The clock's tracer (issue 26): why a cycle was late, from what the clock saw of its thread.

``PacingStats.explain`` is fed the times and the thread's (CPU, run-queue wait) at the points where the
clock looked; each case is one way a cycle starts late, and the cause the tracer must name.
"""

from __future__ import annotations

import asyncio
import os
import selectors
import threading
import time

import pytest

from hli_server.runtime.pacing import (
    CAUSES,
    DOORS_SLICE_NS,
    PacingStats,
    PreciseEpollSelector,
    WaitProbe,
    ask_for_time_slice,
    run_realtime,
    summarize,
)
from tests.scheduler import custom_slices, shown_slice

T_A = 0.001


def stats() -> PacingStats:
    s = PacingStats(T_A)
    s.started_at = 0.0
    return s


def probe(began: float, until: float, ended: float) -> WaitProbe:
    p = WaitProbe()
    p.wait_began, p.wait_until, p.wait_ended = began, until, ended
    return p


@pytest.mark.req("E-01")
def test_a_late_timer_of_a_busy_machine_is_the_operating_systems() -> None:
    """The clock went to sleep at 9.7 ms for its cycle due at 10 ms; the loop's wait returned at 28 ms and
    the thread spent those 18 ms runnable without a CPU."""
    s = stats()
    slow = s.explain(
        10, 0.0183, due=0.010, began=0.0281, ended=0.0283, woke=0.0280, slept=0.0097,
        at_ended=(1.0003, 0.518), at_woke=(1.0001, 0.518), at_slept=(1.0, 0.500),
        probe=probe(0.0097, 0.0100, 0.0280),
    )  # fmt: skip
    assert slow.cause == "os"
    assert slow.parts["os"] == pytest.approx(0.018, abs=1e-4)
    assert "operating system" in slow.detail()


@pytest.mark.req("E-01")
def test_a_callback_that_holds_the_loop_is_the_loops_whether_it_computes_or_blocks() -> None:
    """Another callback ran from 9.8 ms to 40 ms before the loop got to wait: with the CPU (computing) or
    without it but not waiting for one (blocked in a call): either way the loop's, not the machine's."""
    for cpu in (0.0302, 0.0):  # computing, then blocked in a system call
        s = stats()
        slow = s.explain(
            10, 0.0304, due=0.010, began=0.0402, ended=0.0404, woke=0.0401, slept=0.0098,
            at_ended=(1.0 + cpu + 0.0003, 0.5), at_woke=(1.0 + cpu, 0.5), at_slept=(1.0, 0.5),
            probe=probe(0.0400, 0.0400, 0.0401),
        )  # fmt: skip
        assert slow.cause == "loop", slow.parts
        assert slow.parts["loop"] == pytest.approx(0.0301, abs=2e-4)


@pytest.mark.req("E-01")
def test_requests_served_past_the_due_time_are_the_services() -> None:
    """The previous wake-up served requests from 9.5 ms to 14 ms (running all the while): the cycle due at
    10 ms waited for them."""
    s = stats()
    s.service = (0.0095, 0.014, 1.0)
    slow = s.explain(
        10, 0.0043, due=0.010, began=0.0141, ended=0.0143, woke=0.0141, slept=0.0140,
        at_ended=(1.0002, 0.5), at_woke=(1.0, 0.5), at_slept=(1.0, 0.5), previous=(1.0, 0.0),
    )  # fmt: skip
    assert slow.cause == "service"
    assert slow.parts["service"] == pytest.approx(0.004, abs=1e-4)


@pytest.mark.req("E-01")
def test_a_backlog_is_explained_by_what_held_its_cycles() -> None:
    """Forty cycles caught up in one wake-up, the thread preempted for 30 ms in the middle: the last of
    them is late because it lost the CPU, not "because of the backlog"."""
    s = stats()
    slow = s.explain(
        40, 0.035, due=0.040, began=0.0748, ended=0.075, woke=0.0405, slept=0.0399,
        at_ended=(1.004, 0.530), at_woke=(1.0, 0.5), at_slept=(1.0, 0.5),
        probe=probe(0.0399, 0.0400, 0.0404),
    )  # fmt: skip
    assert slow.cause == "preempted"
    assert slow.parts["preempted"] == pytest.approx(0.030, abs=2e-4)
    assert slow.parts["cycle"] == pytest.approx(0.0045, abs=3e-4)  # the cycles' own work


@pytest.mark.req("E-01")
def test_garbage_collection_is_taken_out_of_what_it_interrupted() -> None:
    s = stats()
    s.gc.spans.append((0.0102, 0.0252, 2))  # a collection of generation 2 inside the cycle's work
    slow = s.explain(
        10, 0.0153, due=0.010, began=0.0101, ended=0.0253, woke=0.0100, slept=0.0098,
        at_ended=(1.0152, 0.5), at_woke=(1.0, 0.5), at_slept=(1.0, 0.5),
    )  # fmt: skip
    assert slow.cause == "gc"
    assert slow.parts["gc"] == pytest.approx(0.015, abs=1e-4)
    assert "generation 2" in slow.detail()


@pytest.mark.req("E-01")
def test_the_worst_five_are_five_stalls_and_the_summary_reports_them() -> None:
    s = stats()
    for k, late in enumerate([0.002, 0.009, 0.003, 0.007, 0.004, 0.006, 0.001]):
        s.wakeups = k  # one wake-up each
        due = 0.01 * (k + 1)
        s.record(late)
        s.explain(
            k, late, due=due, began=due + late - 0.0001, ended=due + late, woke=due + late - 0.0001,
            slept=due - 0.0002, at_ended=(1.0, 0.5 + late), at_woke=(1.0, 0.5 + late), at_slept=(1.0, 0.5),
        )  # fmt: skip
    s.wakeups = 3  # a second, smaller late cycle of the stall of wake-up 3: still one entry
    s.explain(
        99, 0.0065, due=0.04, began=0.0464, ended=0.0465, woke=0.0401, slept=0.0398,
        at_ended=(1.0, 0.5065), at_woke=(1.0, 0.5), at_slept=(1.0, 0.5),
    )  # fmt: skip
    assert [round(w.lateness * 1e3) for w in s.worst] == [9, 7, 6, 4, 3]
    out = summarize(s.raw("realtime", 7))  # type: ignore[arg-type]
    assert set(out["lateness_us"]) == {"p50", "p99", "p999", "max"}
    assert len(out["worst"]) == 5
    assert all(w["cause"] in CAUSES for w in out["worst"])
    assert out["late_causes"] == {"os": 6, "preempted": 1}  # later than T_A: the machine's, each


@pytest.mark.req("E-01")
def test_a_wait_that_returns_late_without_wanting_a_cpu_is_the_timers() -> None:
    """asyncio's own loop waits in whole milliseconds: asked to wake at 10.0 ms, it returned at 11.0 ms,
    the thread never waiting for a CPU (the timer's resolution, issue 26's list of suspects)."""
    s = stats()
    slow = s.explain(
        10, 0.0012, due=0.010, began=0.01105, ended=0.0112, woke=0.01104, slept=0.0091,
        at_ended=(1.00015, 0.5), at_woke=(1.0, 0.5), at_slept=(1.0, 0.5),
        probe=probe(0.0091, 0.0100, 0.0110),
    )  # fmt: skip
    assert slow.cause == "timer"
    assert slow.parts["timer"] == pytest.approx(0.001, abs=1e-5)
    assert "resolution" in slow.detail()


# --- the precise selector (the realtime clock's loop) ---------------------------------------------------


@pytest.mark.req("E-01")
def test_the_precise_selector_waits_to_its_timeout_and_reports_what_is_ready() -> None:
    """A timed wait that ends with nothing ready returns no descriptor (and costs one system call, not
    two); a descriptor that is ready, or becomes ready during the wait, is returned at once, with or
    without a timeout; the wait is noted for the tracer."""
    sel = PreciseEpollSelector()
    r, w = os.pipe()
    try:
        sel.register(r, selectors.EVENT_READ, "pipe")
        began = time.monotonic()
        assert sel.select(0.002) == []
        waited = time.monotonic() - began
        assert waited >= 0.0019
        assert sel.wait_until == pytest.approx(sel.wait_began + 0.002)
        os.write(w, b"x")
        for timeout in (0.5, None, 0):
            began = time.monotonic()
            ready = sel.select(timeout)
            assert [(key.data, events) for key, events in ready] == [("pipe", selectors.EVENT_READ)]
            assert time.monotonic() - began < 0.25
        os.read(r, 1)
        assert sel.select(0) == []
    finally:
        sel.close()
        os.close(r)
        os.close(w)


# --- the realtime loop ------------------------------------------------------------------------------------


@pytest.mark.req("E-01")
async def test_the_realtime_loop_runs_each_cycle_when_due_serves_between_and_stops_when_told() -> None:
    """Cycle k is due at epoch + k * T_A: 30 cycles take at least 29 ms; between the wake-ups' cycles the
    requests are served with a deadline before the next cycle is due; the loop ends when no cycle is
    left, passes a failing cycle's exception on, and a cancelled loop runs no further cycle."""
    ran: list[float] = []
    left = [30]
    batches: list[int] = []
    served: list[tuple[float, float]] = []

    def run_cycle() -> int:
        ran.append(time.monotonic())
        left[0] -= 1
        return len(ran)

    def serve(deadline: float) -> bool:
        served.append((time.monotonic(), deadline))
        return False

    stats = PacingStats(T_A)
    await asyncio.wait_for(
        run_realtime(
            run_cycle, lambda: batches.append(len(ran)), lambda: left[0], stats, max_catch_up=5, serve=serve
        ),
        5,
    )
    assert len(ran) == 30
    assert batches[-1] == 30
    assert batches == sorted(batches)
    assert ran[-1] - ran[0] >= 0.029 - 1e-4
    assert stats.measured == 30
    assert stats.wakeups >= 6  # at most max_catch_up cycles a wake-up
    assert served
    assert all(deadline > at - T_A for at, deadline in served)

    def failing() -> int:
        raise RuntimeError("a cycle failed")

    with pytest.raises(RuntimeError, match="a cycle failed"):
        await asyncio.wait_for(
            run_realtime(failing, lambda: None, lambda: 1, PacingStats(T_A), max_catch_up=5), 5
        )

    count = [0]

    def counting() -> int:
        count[0] += 1
        return count[0]

    task = asyncio.ensure_future(
        run_realtime(counting, lambda: None, lambda: 1 << 40, PacingStats(T_A), max_catch_up=5)
    )
    await asyncio.sleep(0.02)
    assert count[0] > 0
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    stopped_at = count[0]
    await asyncio.sleep(0.01)
    assert count[0] == stopped_at


def slice_in_a_thread(slice_ns: int) -> tuple[list[str], int, int]:
    """``ask_for_time_slice`` in a thread of its own (the test process keeps its slice): what it said, the
    thread's slice as the scheduler shows it, and the slice of a thread that thread started after."""
    out: list[tuple[list[str], int, int]] = []

    def run() -> None:
        granted = ask_for_time_slice(slice_ns)
        child: list[int] = []
        started = threading.Thread(target=lambda: child.append(shown_slice()))
        started.start()
        started.join()
        out.append((granted, shown_slice(), child[0]))

    t = threading.Thread(target=run)
    t.start()
    t.join()
    return out[0]


@pytest.mark.req("E-01")
@pytest.mark.skipif(not custom_slices(), reason="needs Linux 6.12+ with its scheduler's slices in /proc")
def test_the_doors_slice_is_granted_inherited_and_said_as_the_kernel_set_it() -> None:
    granted, mine, childs = slice_in_a_thread(DOORS_SLICE_NS)
    assert granted == ["time slice 6 ms"]
    assert mine == childs == DOORS_SLICE_NS  # the threads the doors start later have it too
    # the kernel clamps a request to 0.1-100 ms: what is said is what it set
    granted, mine, _ = slice_in_a_thread(50)
    assert granted == ["time slice 100 µs"]
    assert mine == 100_000


@pytest.mark.req("E-01")
def test_no_slice_is_asked_for_where_the_user_said_so(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HLI_NO_LOW_LATENCY", "1")
    assert ask_for_time_slice(DOORS_SLICE_NS, timer_slack=True) == []
