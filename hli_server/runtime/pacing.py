"""Pacing: how simulated time advances against the wall clock (E-01).

Clocks (:class:`Clock`):

* ``realtime`` (the default): simulated time follows the monotonic clock. Cycle ``k`` is due when the
  wall clock reaches ``epoch + k * T_A``; the loop sleeps until the next cycle is due and then runs
  every cycle that is due, so a late wake-up is caught up with several cycles at once. At most
  ``max_catch_up`` cycles are run per wake-up; a backlog beyond that is dropped (the simulated
  time slips behind the wall clock), counted in :attr:`PacingStats.slipped_cycles` and logged: the
  runtime reports running late, it never hides it (design.md, "the runtime owns pacing"). The
  lateness of every cycle (wall time at publish minus its due time) is measured; p50/p99/max are in
  :meth:`PacingStats.summary` (``GET /api/timing``).
* ``stepped``: cycles run only through ``Runtime.step`` (tests, the H-07 harness, ``POST
  /api/step``). Deterministic: the same inputs give the same cycles.
* ``free``: as fast as the engine goes, yielding to the event loop every few milliseconds so that
  the adapters stay responsive.

:func:`run_realtime` and :func:`run_free` are the two loops; they know nothing of the machine: they
call ``run_cycle()`` for one cycle and ``after_cycles()`` after each batch.
"""

from __future__ import annotations

import asyncio
import logging
import math
import select
import selectors
import time
from collections.abc import Callable, Sequence
from enum import StrEnum
from typing import Any

__all__ = [
    "FREE_SLICE_S",
    "STEP_BATCH",
    "Clock",
    "ClockError",
    "PacingStats",
    "PreciseEpollSelector",
    "precise_event_loop",
    "run_free",
    "run_realtime",
]

logger = logging.getLogger(__name__)

FREE_SLICE_S = 0.005
"""Free-running and long ``step(n)`` calls yield to the event loop at least this often [s]."""

STEP_BATCH = 1_000
"""``step(n)`` yields to the event loop after this many cycles (and after FREE_SLICE_S)."""


class Clock(StrEnum):
    """How simulated time advances (E-01)."""

    REALTIME = "realtime"
    STEPPED = "stepped"
    FREE = "free"


class ClockError(RuntimeError):
    """An operation that the current clock does not allow (e.g. ``step`` outside stepped mode)."""


class PreciseEpollSelector(selectors.EpollSelector):
    """epoll for readiness, ``select(2)`` on the epoll descriptor for a timeout to the microsecond.

    asyncio's default loop on Linux waits in ``epoll_wait``, whose timeout is whole milliseconds
    (Python rounds it up): with T_A = 1 ms every wake-up would come up to a millisecond late. A plain
    ``select(2)`` loop takes microseconds but cannot watch a descriptor numbered 1024 or above
    (FD_SETSIZE): about a thousand open connections crashed such a server (issue 12). This selector
    waits with ``select(2)`` on one descriptor only, the epoll instance itself (created with the loop,
    so its number is small; it is readable when any registered descriptor is ready), then collects the
    ready descriptors with a non-blocking ``epoll_wait``. Precise timers, no descriptor limit.
    """

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        if timeout is not None and timeout > 0:
            epoll_fd = self._selector.fileno()  # type: ignore[attr-defined]
            select.select([epoll_fd], [], [], timeout)
            timeout = 0
        return super().select(timeout)


def precise_event_loop() -> asyncio.AbstractEventLoop:
    """An asyncio loop whose timers wake to the microsecond and that takes any number of descriptors
    (:class:`PreciseEpollSelector`; plain ``select(2)`` where epoll does not exist). ``hli-server run``
    uses it (``--event-loop select``, the default): the realtime clock's lateness is then the kernel's
    wake-up latency (about 0.1 ms) instead of up to a millisecond."""
    if hasattr(selectors, "EpollSelector"):
        return asyncio.SelectorEventLoop(PreciseEpollSelector())
    return asyncio.SelectorEventLoop(selectors.SelectSelector())  # pragma: no cover - not Linux


# --------------------------------------------------------------------------------------------
# Pacing statistics
# --------------------------------------------------------------------------------------------


class PacingStats:
    """How the clock kept pace (E-01).

    Realtime: the lateness of cycle ``k`` is the wall time at which it was published minus the time
    it was due (``epoch + k * T_A``); it is never negative. The newest ``window`` samples are kept for
    the percentiles; ``max`` and the counters cover the whole run. Stepped and free clocks count
    cycles and wake-ups only (they have no due times).
    """

    def __init__(self, t_a: float, window: int = 60_000) -> None:
        self.t_a = t_a
        self._samples = [0.0] * window
        self._window = window
        self._next = 0
        self.cycles = 0
        """cycles run by this clock."""
        self.measured = 0
        """cycles whose lateness was measured (realtime)."""
        self.max_lateness = 0.0
        self.late_cycles = 0
        """cycles published more than one T_A after they were due."""
        self.wakeups = 0
        self.catch_up_wakeups = 0
        """wake-ups that had to run more than one cycle."""
        self.max_catch_up = 0
        """most cycles run in one wake-up."""
        self.slipped_cycles = 0
        """cycles dropped because the backlog exceeded the catch-up cap (simulated time slipped)."""
        self.started_at: float | None = None
        self.cycles_at_start = 0

    def record(self, lateness: float) -> None:
        self._samples[self._next] = lateness
        self._next = (self._next + 1) % self._window
        self.measured += 1
        self.max_lateness = max(self.max_lateness, lateness)
        if lateness > self.t_a:
            self.late_cycles += 1

    def wakeup(self, cycles_run: int) -> None:
        self.cycles += cycles_run
        self.wakeups += 1
        if cycles_run > 1:
            self.catch_up_wakeups += 1
        self.max_catch_up = max(self.max_catch_up, cycles_run)

    def samples(self) -> list[float]:
        """The newest lateness samples [s], oldest first."""
        if self.measured <= self._window:
            return self._samples[: self.measured]
        return self._samples[self._next :] + self._samples[: self._next]

    def summary(self, clock: Clock, machine_cycle: int) -> dict[str, Any]:
        """Times in µs; percentiles over the newest ``window`` cycles; ``rate`` = simulated / wall time."""
        data = sorted(self.samples())
        wall = (time.monotonic() - self.started_at) if self.started_at is not None else 0.0
        simulated = (machine_cycle - self.cycles_at_start) * self.t_a
        lateness: dict[str, float] | None = None
        if data:
            lateness = {
                "p50": _us(_percentile(data, 50)),
                "p99": _us(_percentile(data, 99)),
                "max": _us(self.max_lateness),
            }
        return {
            "clock": str(clock),
            "t_a_us": round(self.t_a * 1e6),
            "cycles": self.cycles,
            "lateness_us": lateness,
            "lateness_window": len(data),
            "late_cycles": self.late_cycles,
            "wakeups": self.wakeups,
            "catch_up_wakeups": self.catch_up_wakeups,
            "max_catch_up": self.max_catch_up,
            "slipped_cycles": self.slipped_cycles,
            "wall_s": round(wall, 6),
            "simulated_s": round(simulated, 6),
            "rate": round(simulated / wall, 6) if wall > 0 else None,
        }


def _percentile(sorted_data: Sequence[float], q: float) -> float:
    if not sorted_data:
        return 0.0
    k = max(0, min(len(sorted_data) - 1, math.ceil(q / 100 * len(sorted_data)) - 1))
    return sorted_data[k]


def _us(seconds: float) -> float:
    return round(seconds * 1e6, 1)


# --------------------------------------------------------------------------------------------
# The loops
# --------------------------------------------------------------------------------------------


async def run_realtime(
    run_cycle: Callable[[], int],
    after_cycles: Callable[[], None],
    cycles_left: Callable[[], int],
    stats: PacingStats,
    *,
    max_catch_up: int,
) -> None:
    """Realtime pacing (E-01): see the module docstring. ``run_cycle`` returns the machine's cycle."""
    t_a = stats.t_a
    cap = max_catch_up
    clock = time.monotonic
    epoch = clock()
    done = 0  # cycles run since epoch
    stats.started_at = epoch
    cycle = 0
    last_slip_log = -math.inf
    while cycles_left() > 0:
        now = clock()
        backlog = int((now - epoch) / t_a) - done
        if backlog > 0:
            run = min(backlog, cap, cycles_left())
            for _ in range(run):
                cycle = run_cycle()
                done += 1
                stats.record(clock() - (epoch + done * t_a))
            stats.wakeup(run)
            if backlog > cap:
                dropped = backlog - cap
                epoch += dropped * t_a
                stats.slipped_cycles += dropped
                if now - last_slip_log > 1.0:
                    last_slip_log = now
                    logger.warning(
                        "realtime clock ran %.1f ms late at cycle %d: caught up %d cycles, dropped %d "
                        "(simulated time now %.3f s behind the wall clock; %d dropped in all)",
                        backlog * t_a * 1e3,
                        cycle,
                        cap,
                        dropped,
                        stats.slipped_cycles * t_a,
                        stats.slipped_cycles,
                    )
            after_cycles()
        delay = epoch + (done + 1) * t_a - clock()
        await asyncio.sleep(delay if delay > 0 else 0)


async def run_free(
    run_cycle: Callable[[], int],
    after_cycles: Callable[[], None],
    cycles_left: Callable[[], int],
    stats: PacingStats,
) -> None:
    """Free running (E-01): cycles back to back, yielding every FREE_SLICE_S."""
    clock = time.monotonic
    while cycles_left() > 0:
        slice_end = clock() + FREE_SLICE_S
        run = 0
        limit = cycles_left()
        while run < limit:
            run_cycle()
            run += 1
            if clock() >= slice_end:
                break
        stats.wakeup(run)
        after_cycles()
        await asyncio.sleep(0)
