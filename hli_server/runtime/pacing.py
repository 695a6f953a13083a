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
import contextlib
import gc
import logging
import math
import os
import select
import selectors
import struct
import sys
import time
from array import array
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import NotRequired, TypedDict

from hli_server.runtime.event_loop import LeanSelectorEventLoop
from schemas.results import Lateness, PacingSummary, SlowCycleJson, Timing

__all__ = [
    "CAUSES",
    "DOORS_SLICE_NS",
    "FREE_SLICE_S",
    "LOW_LATENCY_SLICE_NS",
    "PRIORITIES",
    "STEP_BATCH",
    "Clock",
    "ClockError",
    "GcProbe",
    "PacingRaw",
    "PacingStats",
    "PreciseEpollSelector",
    "ProbedEpollSelector",
    "SlowCycle",
    "ThreadClock",
    "WaitProbe",
    "ask_for_low_latency",
    "ask_for_time_slice",
    "loop_probe",
    "precise_event_loop",
    "probed_default_loop",
    "raise_priority",
    "run_free",
    "run_realtime",
    "summarize",
    "summarize_timing",
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


class WaitProbe:
    """When the event loop last *waited* (a select with a timeout other than zero): the clock's tracer
    tells from it whether the time between a cycle's due time and the clock's wake-up went to the loop's
    other work (before or after the wait) or to a wait that returned later than asked. A selector that has
    these attributes is a probe; :func:`loop_probe` finds it."""

    wait_began = 0.0
    """``time.monotonic()`` when the newest blocking wait began."""
    wait_until = 0.0
    """When it was asked to end (``wait_began`` + timeout; ``inf`` without a timeout)."""
    wait_ended = 0.0
    """When it returned."""

    def _note(self, began: float, timeout: float | None) -> None:
        self.wait_began = began
        self.wait_until = began + timeout if timeout is not None else math.inf
        self.wait_ended = time.monotonic()


class ThreadClock:
    """The calling thread's CPU time and the time it waited, runnable, for a CPU (seconds, both growing):
    ``/proc/thread-self/schedstat`` on Linux (one read of an open file, a few microseconds). Elsewhere the
    CPU time only (``time.thread_time``), and the tracer takes wall time without CPU as the operating
    system's. Open it in the thread it is to measure."""

    def __init__(self) -> None:
        self._fd: int | None = None
        with contextlib.suppress(OSError):
            self._fd = os.open("/proc/thread-self/schedstat", os.O_RDONLY)
        self.precise = self._fd is not None
        """Whether the run-queue wait is measured (else it is reported as 0)."""

    def read(self) -> tuple[float, float]:
        """``(CPU seconds, run-queue seconds)`` of the thread so far."""
        if self._fd is not None:
            fields = os.pread(self._fd, 96, 0).split()
            return int(fields[0]) * 1e-9, int(fields[1]) * 1e-9
        return time.thread_time(), 0.0

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


class ProbedEpollSelector(WaitProbe, selectors.EpollSelector):
    """asyncio's own selector on Linux (``--event-loop default``), its waits noted (:class:`WaitProbe`)."""

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        if timeout is not None and timeout <= 0:
            return super().select(timeout)
        began = time.monotonic()
        ready = super().select(timeout)
        self._note(began, timeout)
        return ready


def loop_probe(loop: asyncio.AbstractEventLoop) -> WaitProbe | None:
    """The :class:`WaitProbe` of ``loop``'s selector, if it has one (the loops of this module do)."""
    selector = getattr(loop, "_selector", None)
    return selector if isinstance(selector, WaitProbe) else None


class PreciseEpollSelector(WaitProbe, selectors.EpollSelector):
    """epoll for readiness, ``select(2)`` on the epoll descriptor for a timeout to the microsecond.

    asyncio's default loop on Linux waits in ``epoll_wait``, whose timeout is whole milliseconds
    (Python rounds it up): with T_A = 1 ms every wake-up would come up to a millisecond late. A plain
    ``select(2)`` loop takes microseconds but cannot watch a descriptor numbered 1024 or above
    (FD_SETSIZE): about a thousand open connections crashed such a server (docs/reliability.md). This selector
    waits with ``select(2)`` on one descriptor only, the epoll instance itself (created with the loop,
    so its number is small; it is readable when any registered descriptor is ready), then collects the
    ready descriptors with a non-blocking ``epoll_wait`` (none when the wait ended by its timeout with
    nothing ready: the realtime clock's usual wake-up costs one system call, not two). Precise timers, no
    descriptor limit.
    """

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        if timeout is not None and timeout <= 0:
            return super().select(timeout)
        began = time.monotonic()
        if timeout is not None:
            epoll_fd = self._selector.fileno()  # type: ignore[attr-defined]
            readable, _, _ = select.select([epoll_fd], [], [], timeout)
            ready = super().select(0) if readable else []
        else:
            ready = super().select(None)
        self._note(began, timeout)
        return ready


def precise_event_loop() -> asyncio.AbstractEventLoop:
    """An asyncio loop whose timers wake to the microsecond and that takes any number of descriptors
    (:class:`PreciseEpollSelector`; plain ``select(2)`` where epoll does not exist). ``hli-server run``
    uses it (``--event-loop select``, the default): the realtime clock's lateness is then the kernel's
    wake-up latency (about 0.1 ms) instead of up to a millisecond."""
    if hasattr(selectors, "EpollSelector"):
        return LeanSelectorEventLoop(PreciseEpollSelector())
    return asyncio.SelectorEventLoop(selectors.SelectSelector())  # pragma: no cover - not Linux


def probed_default_loop() -> asyncio.AbstractEventLoop:
    """asyncio's default loop on Linux (``epoll``, whole-millisecond timeouts) with its waits noted, so
    that the clock's tracer can name the cause of a late cycle there too (``--event-loop default``)."""
    if hasattr(selectors, "EpollSelector"):
        return LeanSelectorEventLoop(ProbedEpollSelector())
    return asyncio.new_event_loop()  # pragma: no cover - not Linux


PRIORITIES = ("auto", "normal", "high", "realtime")
"""``hli-server run --priority``: how the clock's thread asks the operating system for the CPU (``auto``, the
default of ``run``: ``realtime`` where the process may, else ``normal``)."""


LOW_LATENCY_SLICE_NS = 100_000
"""The time slice the clock's thread asks the scheduler for (Linux 6.12+, EEVDF: a task with a short slice
gets an early deadline, so that it preempts the running task as soon as its timer wakes it; it still gets
its fair share of the CPU, no more)."""

DOORS_SLICE_NS = 6_000_000
"""The time slice the doors process asks the scheduler for (Linux 6.12+, EEVDF): longer than the kernel's
default (0.7 ms times 1 + log2 of the CPUs up to eight: 1.4 ms on two CPUs, 2.8 ms from eight on), so that a
turn of the doors (read a request, answer it, write the reply) is seldom preempted in the middle by the
client its reply just woke; the clock still preempts it at once (a realtime policy, or its shorter slice),
and it still gets its fair share of the CPU, no more (docs/runtime.md, docs/performance.md)."""


def ask_for_low_latency() -> list[str]:
    """Ask Linux to run the calling thread (the clock's) soon after its timers fire, without privileges:
    a timer slack of 1 ns instead of 50 µs (``PR_SET_TIMERSLACK``) and a scheduler time slice of
    :data:`LOW_LATENCY_SLICE_NS` (:func:`ask_for_time_slice`). Returns what was granted, in words."""
    slice_ns = int(os.environ.get("HLI_SLICE_NS", LOW_LATENCY_SLICE_NS))
    return ask_for_time_slice(slice_ns, timer_slack=True)


def ask_for_time_slice(slice_ns: int, *, timer_slack: bool = False) -> list[str]:
    """Ask Linux for a scheduler time slice of ``slice_ns`` for the calling thread (``sched_setattr`` with
    ``SCHED_OTHER``'s ``sched_runtime``, Linux 6.12+; the thread's nice value is kept; threads and processes
    started later inherit it) and, with ``timer_slack``, a timer slack of 1 ns (``PR_SET_TIMERSLACK``). No
    privileges needed. Returns what was granted, in words: nothing where the system does not have it, or
    the thread runs a realtime policy (which has no slices), or ``HLI_NO_LOW_LATENCY`` is set."""
    if not sys.platform.startswith("linux") or os.environ.get("HLI_NO_LOW_LATENCY"):
        return []
    granted = []
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        if timer_slack and int(libc.prctl(29, 1, 0, 0, 0)) == 0:  # PR_SET_TIMERSLACK
            granted.append("timer slack 1 ns")
        if os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0) != os.SCHED_OTHER:
            return granted  # a realtime policy has no slices (and sched_setattr would end it)
        nice = os.getpriority(os.PRIO_PROCESS, 0)
        # struct sched_attr (SCHED_ATTR_SIZE_VER1): size, policy SCHED_OTHER, flags, nice, priority,
        # runtime (the slice), deadline, period, util_min, util_max
        attr = ctypes.create_string_buffer(
            struct.pack("<IIQiIQQQII", 56, 0, 0, nice, 0, slice_ns, 0, 0, 0, 0), 56
        )
        # sched_setattr, sched_getattr
        calls = {"x86_64": (314, 315), "aarch64": (274, 275)}.get(os.uname().machine)
        if calls is not None and int(libc.syscall(calls[0], 0, attr, 0)) == 0:
            # a kernel before 6.12 accepts the request and ignores the slice; from 6.12 on sched_getattr
            # reports a SCHED_OTHER thread's slice in sched_runtime (before: 0), clamped to 0.1-100 ms
            got = ctypes.create_string_buffer(56)
            if int(libc.syscall(calls[1], 0, got, 56, 0)) == 0:
                runtime = struct.unpack_from("<Q", got, 24)[0]
                if runtime:
                    granted.append(f"time slice {_slice_words(runtime)}")
    except (OSError, AttributeError):  # pragma: no cover - no libc
        pass
    return granted


def _slice_words(slice_ns: int) -> str:
    return f"{slice_ns / 1e6:g} ms" if slice_ns >= 1_000_000 else f"{slice_ns / 1000:g} µs"


def raise_priority(priority: str) -> str:
    """Give the calling thread (the clock's) the operating system's ``priority``: ``normal`` changes
    nothing; ``high`` is nice -10; ``realtime`` is ``SCHED_FIFO`` priority 10 (the thread runs before every
    normal process whenever its timer is due; Linux keeps 5 % of each second for the others); ``auto`` is
    ``realtime`` where the process may, else ``normal``. ``high`` and ``realtime`` need the privilege (root,
    or ``CAP_SYS_NICE``: ``docker run --cap-add SYS_NICE``). Returns what was done, in words (the ``run``
    banner prints it); a refusal is said, not raised.

    Why ``run`` asks for ``realtime`` by default (docs/runtime.md): on a machine with other work the clock's
    lateness is the time its thread waits for a CPU (the tracer's ``os``), and no amount of work saved in
    the server changes that; with ``SCHED_FIFO`` the same load costs the cycle nothing (docs/performance.md,
    "The clock under load"). The thread sleeps between cycles (a fraction of one CPU); the doors process
    and the test harness keep the normal priority."""
    if priority == "normal":
        return "normal"
    if priority == "auto":
        granted = raise_priority("realtime")
        if granted.startswith("realtime"):
            return granted
        return "normal (realtime not permitted: root or CAP_SYS_NICE, e.g. docker run --cap-add SYS_NICE)"
    try:
        if priority == "high":
            os.setpriority(os.PRIO_PROCESS, 0, -10)
            return "high (nice -10)"
        if priority == "realtime":
            # the processes and threads this one starts later (the doors process, executor threads) do not
            # inherit the policy
            policy = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
            os.sched_setscheduler(0, policy, os.sched_param(10))
            return "realtime (SCHED_FIFO 10)"
    except (PermissionError, OSError, AttributeError) as exc:
        why = getattr(exc, "strerror", None) or exc
        return f"normal ({priority} refused by the operating system: {why}; needs root or CAP_SYS_NICE)"
    raise ValueError(f"unknown priority {priority!r}; use one of {', '.join(PRIORITIES)}")


# --------------------------------------------------------------------------------------------
# Pacing statistics
# --------------------------------------------------------------------------------------------


class GcProbe:
    """When the cyclic garbage collector ran (``gc.callbacks``): the newest ``size`` collections as
    ``(began, ended, generation)`` in ``time.monotonic()`` seconds. One per runtime; :meth:`install` /
    :meth:`uninstall` around the clock."""

    def __init__(self, size: int = 256) -> None:
        self.spans: deque[tuple[float, float, int]] = deque(maxlen=size)
        self.collections = [0, 0, 0]
        """collections per generation since install."""
        self._began = 0.0

    def __call__(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self._began = time.monotonic()
            return
        generation = int(info.get("generation", 0))
        self.spans.append((self._began, time.monotonic(), generation))
        if 0 <= generation < 3:
            self.collections[generation] += 1

    def install(self) -> None:
        if self not in gc.callbacks:
            gc.callbacks.append(self)

    def uninstall(self) -> None:
        with contextlib.suppress(ValueError):
            gc.callbacks.remove(self)

    def overlap(self, a: float, b: float) -> tuple[float, int]:
        """Seconds of collection within ``[a, b]`` and the highest generation collected there (-1: none)."""
        total, gen = 0.0, -1
        for began, ended, generation in reversed(self.spans):
            if ended <= a:
                break
            part = min(ended, b) - max(began, a)
            if part > 0:
                total += part
                gen = max(gen, generation)
        return total, gen


CAUSES = {
    "gc": "garbage collection",
    "os": "the operating system woke the clock late (the process was not scheduled: other load)",
    "timer": "the loop's timer fired late (its resolution: whole milliseconds in asyncio's own loop)",
    "loop": "other work on the clock's event loop ran past the due time",
    "service": "requests of the doors process, served between cycles, ran past the due time",
    "cycle": "the cycles' own work (the engine's step; with a backlog, the cycles caught up before it)",
    "preempted": "the cycle lost the CPU while it ran (other load on the machine)",
}
"""The causes the tracer tells apart (``GET /api/timing``: ``worst[].cause``, ``late_causes``)."""


@dataclass(slots=True)
class SlowCycle:
    """One late cycle and why (:meth:`PacingStats.explain`); times in seconds."""

    cycle: int
    lateness: float
    cause: str
    parts: dict[str, float]
    at: float
    """seconds since the clock started"""
    gc_generation: int = -1
    wake: int = 0
    """the clock's wake-up it ran in (the five worst are of five different wake-ups)"""

    def to_json(self) -> SlowCycleJson:
        return {
            "cycle": self.cycle,
            "lateness_us": _us(self.lateness),
            "cause": self.cause,
            "detail": self.detail(),
            "parts_us": {k: _us(v) for k, v in self.parts.items() if v > 0},
            "at_s": round(self.at, 3),
        }

    def detail(self) -> str:
        part = self.parts.get(self.cause, 0.0) * 1e3
        if self.cause == "gc":
            return f"garbage collection of generation {self.gc_generation}: {part:.2f} ms"
        text = CAUSES.get(self.cause, self.cause)
        return f"{text}: {part:.2f} ms"


class PacingRaw(TypedDict):
    """:meth:`PacingStats.raw`: the pacing before its percentiles are sorted out (the samples as the bytes of
    an ``array("d")``, seconds); what the clock's process hands the doors process (``runtime/remote.py``).
    The runtime adds ``failed_cycles`` (``Runtime.timing_raw``)."""

    clock: str
    t_a: float
    samples: bytes
    next: int
    measured: int
    max: float
    cycles: int
    simulated_s: float
    wall_s: float
    late_cycles: int
    late_causes: dict[str, int]
    worst: list[SlowCycleJson]
    gc_collections: list[int]
    wakeups: int
    catch_up_wakeups: int
    max_catch_up: int
    slipped_cycles: int
    failed_cycles: NotRequired[int]


class PacingStats:
    """How the clock kept pace (E-01).

    Realtime: the lateness of cycle ``k`` is the wall time at which it was published minus the time
    it was due (``epoch + k * T_A``); it is never negative. The newest ``window`` samples are kept for
    the percentiles; ``max`` and the counters cover the whole run. Stepped and free clocks count
    cycles and wake-ups only (they have no due times).

    The slowest cycles are explained (:meth:`explain`): the five worst of the run (five different
    wake-ups) are kept with the cause that took most of their lateness, and every cycle later than T_A is
    counted by its cause (``late_causes``). The lateness of a cycle is cut where the clock's thread was
    seen (the previous wake-up's end, the loop's wait, the wake-up, the cycle's start) and each piece
    split by the CPU the thread used in it: CPU of cycles (``cycle``), of requests served between cycles
    (``service``), of the loop's other callbacks (``loop``), of garbage collection (``gc``, taken out of
    the others); wall time without CPU is the operating system's (``os`` before the wake-up,
    ``preempted`` while cycles ran).
    """

    WORST = 5

    def __init__(self, t_a: float, window: int = 60_000) -> None:
        self.t_a = t_a
        self._samples = array("d", bytes(8 * window))
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
        self.worst: list[SlowCycle] = []
        """The :attr:`WORST` latest cycles of the run, worst first, each with its cause."""
        self.late_causes: dict[str, int] = {}
        """Cycles later than T_A, by cause."""
        self.explain_above = 0.0
        """Cycles later than this are explained (the fifth worst so far, at most T_A)."""
        self.gc = GcProbe()
        self.service: tuple[float, float, float] = (0.0, 0.0, 1.0)
        """When the clock last served requests between cycles (``run_realtime``'s ``serve``): began, ended,
        and the share of that time the thread ran (the rest it waited for a CPU)."""

    def record(self, lateness: float) -> None:
        self._samples[self._next] = lateness
        self._next = (self._next + 1) % self._window
        self.measured += 1
        self.max_lateness = max(self.max_lateness, lateness)
        if lateness > self.t_a:
            self.late_cycles += 1

    def explain(
        self,
        cycle: int,
        lateness: float,
        *,
        due: float,
        began: float,
        ended: float,
        woke: float,
        slept: float,
        at_ended: tuple[float, float],
        at_woke: tuple[float, float],
        at_slept: tuple[float, float],
        previous: tuple[float, float] = (1.0, 0.0),
        precise: bool = True,
        probe: WaitProbe | None = None,
    ) -> SlowCycle:
        """Why ``cycle`` was ``lateness`` late (see the class docstring). Times are ``time.monotonic()``:
        ``due`` when it was due; ``began``/``ended`` its own work; ``woke`` when the clock woke for it;
        ``slept`` when the clock went to sleep before that. ``at_*``: the clock's thread's ``(CPU, run-queue
        wait)`` (:class:`ThreadClock`) at ``ended``, ``woke`` and ``slept``; ``previous``: the shares of CPU
        and of run-queue wait in the previous wake-up's work (before ``slept``); ``precise``: whether the
        run-queue wait is measured (else wall time without CPU counts as the operating system's);
        ``probe``: the loop's last wait.

        The time from the due time to the publish is cut where the clock's thread was seen: the end of the
        previous wake-up's work, the loop's wait, the wake-up. In each piece the thread ran (CPU: the
        cycles', the requests', the loop's other callbacks'), waited for a CPU it was ready to use (the
        operating system's: ``os``, ``preempted``), or was blocked (in the loop's wait: only the part
        past its asked end is late, the operating system's; elsewhere: a callback blocked the loop)."""
        parts = dict.fromkeys(("cycle", "preempted", "loop", "service", "os", "timer"), 0.0)
        # 1. the previous wake-up's work (its cycles, then its requests) ran past this cycle's due time
        if due < slept:
            s_began, s_ended, s_share = self.service
            served = max(0.0, min(s_ended, slept) - max(s_began, due))
            if served > 0.0:  # the requests, with what the thread got of the CPU while it served them
                parts["service"] += served * s_share
                parts["os"] += served * (1.0 - s_share)
            rest = slept - due - served
            cpu_share, wait_share = previous
            waited = rest * (wait_share if precise else 1.0 - cpu_share)
            parts["os"] += waited
            parts["cycle"] += rest - waited
        # 2. from the clock's sleep to its wake-up: the loop
        start = max(due, slept)
        if woke > start:
            span = woke - start
            cpu = max(0.0, at_woke[0] - at_slept[0])
            waited = max(0.0, at_woke[1] - at_slept[1]) if precise else max(0.0, span - cpu)
            overdue = 0.0  # the loop's wait returned later than it asked
            if probe is not None and slept < probe.wait_ended <= woke:
                overdue = max(0.0, probe.wait_ended - max(start, probe.wait_until, probe.wait_began))
            waited = min(span, waited)
            timer = min(span - waited, max(0.0, overdue - waited))  # late, though not for want of a CPU
            parts["os"] += waited
            parts["timer"] += timer
            parts["loop"] += span - waited - timer
        # 3. the cycles of this wake-up up to and with this one
        start = max(due, woke)
        if ended > start:
            span = ended - start
            waited = max(0.0, at_ended[1] - at_woke[1])
            if not precise:
                waited = max(0.0, (ended - woke) - (at_ended[0] - at_woke[0]))
            lost = min(span, waited)
            parts["preempted"] += lost
            parts["cycle"] += span - lost
        collected, generation = self.gc.overlap(due, ended)
        if collected > 0.0:  # collections are CPU time of whatever they interrupted
            rest = collected
            for key in ("cycle", "loop", "service"):
                moved = min(rest, parts[key])
                parts[key] -= moved
                rest -= moved
            parts["gc"] = collected - rest
        cause = max(parts, key=lambda k: parts[k])
        at = ended - self.started_at if self.started_at is not None else 0.0
        slow = SlowCycle(cycle, lateness, cause, parts, at, generation if cause == "gc" else -1, self.wakeups)
        if lateness > self.t_a:
            self.late_causes[cause] = self.late_causes.get(cause, 0) + 1
        worst = self.worst
        same = next((s for s in worst if s.wake == slow.wake), None)
        if same is not None:  # one stall is one entry: its worst cycle
            if lateness > same.lateness:
                worst[worst.index(same)] = slow
                worst.sort(key=lambda s: s.lateness, reverse=True)
        elif len(worst) < self.WORST or lateness > worst[-1].lateness:
            worst.append(slow)
            worst.sort(key=lambda s: s.lateness, reverse=True)
            del worst[self.WORST :]
            if len(worst) == self.WORST:
                self.explain_above = min(self.t_a, worst[-1].lateness)
        return slow

    def wakeup(self, cycles_run: int) -> None:
        self.cycles += cycles_run
        self.wakeups += 1
        if cycles_run > 1:
            self.catch_up_wakeups += 1
        self.max_catch_up = max(self.max_catch_up, cycles_run)

    def samples(self) -> list[float]:
        """The newest lateness samples [s], oldest first."""
        return _ordered(self._samples, self._next, self.measured)

    def raw(self, clock: Clock, machine_cycle: int) -> PacingRaw:
        """What :func:`summarize` needs, taken without sorting anything (a copy of the samples' bytes):
        the clock's process hands this to the doors process, which does the sorting for ``GET
        /api/timing`` (``runtime/remote.py``)."""
        wall = (time.monotonic() - self.started_at) if self.started_at is not None else 0.0
        return {
            "clock": str(clock),
            "t_a": self.t_a,
            "samples": bytes(self._samples),
            "next": self._next,
            "measured": self.measured,
            "max": self.max_lateness,
            "cycles": self.cycles,
            "simulated_s": (machine_cycle - self.cycles_at_start) * self.t_a,
            "wall_s": wall,
            "late_cycles": self.late_cycles,
            "late_causes": dict(self.late_causes),
            "worst": [s.to_json() for s in self.worst],
            "gc_collections": list(self.gc.collections),
            "wakeups": self.wakeups,
            "catch_up_wakeups": self.catch_up_wakeups,
            "max_catch_up": self.max_catch_up,
            "slipped_cycles": self.slipped_cycles,
        }

    def summary(self, clock: Clock, machine_cycle: int) -> PacingSummary:
        """Times in µs; percentiles over the newest ``window`` cycles; ``rate`` = simulated / wall time."""
        return summarize(self.raw(clock, machine_cycle))


def _ordered(samples: array[float], next_index: int, measured: int) -> list[float]:
    if measured <= len(samples):
        return samples[:measured].tolist()
    return samples[next_index:].tolist() + samples[:next_index].tolist()


def summarize(raw: PacingRaw) -> PacingSummary:
    """``GET /api/timing`` from :meth:`PacingStats.raw` (see docs/runtime.md for the fields)."""
    samples = array("d")
    samples.frombytes(raw["samples"])
    data = sorted(_ordered(samples, raw["next"], raw["measured"]))
    lateness: Lateness | None = None
    if data:
        lateness = {
            "p50": _us(_percentile(data, 50)),
            "p99": _us(_percentile(data, 99)),
            "p999": _us(_percentile(data, 99.9)),
            "max": _us(raw["max"]),
        }
    wall, simulated = raw["wall_s"], raw["simulated_s"]
    return {
        "clock": raw["clock"],
        "t_a_us": round(raw["t_a"] * 1e6),
        "cycles": raw["cycles"],
        "lateness_us": lateness,
        "lateness_window": len(data),
        "late_cycles": raw["late_cycles"],
        "late_causes": dict(sorted(raw["late_causes"].items(), key=lambda kv: -kv[1])),
        "worst": raw["worst"],
        "gc_collections": raw["gc_collections"],
        "wakeups": raw["wakeups"],
        "catch_up_wakeups": raw["catch_up_wakeups"],
        "max_catch_up": raw["max_catch_up"],
        "slipped_cycles": raw["slipped_cycles"],
        "wall_s": round(wall, 6),
        "simulated_s": round(simulated, 6),
        "rate": round(simulated / wall, 6) if wall > 0 else None,
    }


def summarize_timing(raw: PacingRaw) -> Timing:
    """``GET /api/timing`` from the runtime's ``timing_raw()`` (the pacing figures and the failed cycles)."""
    return {**summarize(raw), "failed_cycles": raw.get("failed_cycles", 0)}


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

SERVE_MARGIN_S = 0.0002
"""``run_realtime`` stops serving requests between cycles this long before the next cycle is due."""


async def run_realtime(
    run_cycle: Callable[[], int],
    after_cycles: Callable[[], None],
    cycles_left: Callable[[], int],
    stats: PacingStats,
    *,
    max_catch_up: int,
    serve: Callable[[float], bool] | None = None,
) -> None:
    """Realtime pacing (E-01): see the module docstring. ``run_cycle`` returns the machine's cycle.

    ``serve(deadline)``, if given, is called after every wake-up's cycles, with the time (``monotonic``)
    by which it should be done: the work the clock's loop does besides the cycles goes there, where it
    delays no cycle (the requests of the doors process, ``runtime/remote.py``); it returns whether it did
    any (the tracer then knows when, ``service``).

    Each wake-up is a timer callback of the running loop (``call_at`` the next cycle's due time), not a
    coroutine that sleeps: one turn of the loop per wake-up, no future and no task step made for it (a
    sleeping coroutine costs two turns and their system calls every millisecond; docs/performance.md).
    The loop's clock is ``time.monotonic``, the one the due times are computed with."""
    pacer = _RealtimePacer(run_cycle, after_cycles, cycles_left, stats, max_catch_up, serve)
    await pacer.run()


class _RealtimePacer:
    """:func:`run_realtime`'s state between wake-ups; :meth:`wake` is one wake-up."""

    def __init__(
        self,
        run_cycle: Callable[[], int],
        after_cycles: Callable[[], None],
        cycles_left: Callable[[], int],
        stats: PacingStats,
        max_catch_up: int,
        serve: Callable[[float], bool] | None,
    ) -> None:
        self.run_cycle, self.after_cycles, self.cycles_left = run_cycle, after_cycles, cycles_left
        self.stats, self.cap, self.serve = stats, max_catch_up, serve
        self.t_a = stats.t_a
        self.thread = ThreadClock()
        self.loop = asyncio.get_running_loop()
        self.probe = loop_probe(self.loop)
        self.epoch = time.monotonic()
        self.done = 0  # cycles run since epoch
        stats.started_at = self.epoch
        self.cycle = 0
        self.last_slip_log = -math.inf
        self.slept = self.epoch
        self.at_slept = self.thread.read()
        self.previous = (1.0, 0.0)  # shares of CPU and of run-queue wait in the previous wake-up's work
        self.finished: asyncio.Future[None] = self.loop.create_future()
        self.handle: asyncio.Handle | None = None

    async def run(self) -> None:
        try:
            if self.cycles_left() > 0:
                self.handle = self.loop.call_soon(self.wake)
                await self.finished
        finally:
            if self.handle is not None:
                self.handle.cancel()
            self.thread.close()

    def wake(self) -> None:
        """One wake-up: every cycle that is due (at most ``max_catch_up``), the requests between cycles,
        then the timer for the next cycle's due time."""
        self.handle = None
        if self.finished.done():
            return
        try:
            self._wake()
            left = self.cycles_left()
        except Exception as exc:  # the clock stops; the runtime logs it (Runtime._pacer_done)
            self.finished.set_exception(exc)
            return
        if left <= 0:
            self.finished.set_result(None)
            return
        due = self.epoch + (self.done + 1) * self.t_a
        if due > self.slept:
            self.handle = self.loop.call_at(due, self.wake)
        else:
            self.handle = self.loop.call_soon(self.wake)

    def _wake(self) -> None:
        stats, t_a, clock, read = self.stats, self.t_a, time.monotonic, self.thread.read
        woke = now = clock()
        at_woke = read()
        backlog = int((now - self.epoch) / t_a) - self.done
        if backlog > 0:
            cap = self.cap
            run = min(backlog, cap, self.cycles_left())
            cycle = self.cycle
            for _ in range(run):
                began = clock()
                cycle = self.run_cycle()
                self.done += 1
                ended = clock()
                due = self.epoch + self.done * t_a
                lateness = ended - due
                stats.record(lateness)
                if lateness > stats.explain_above:
                    stats.explain(
                        cycle,
                        lateness,
                        due=due,
                        began=began,
                        ended=ended,
                        woke=woke,
                        slept=self.slept,
                        at_ended=read(),
                        at_woke=at_woke,
                        at_slept=self.at_slept,
                        previous=self.previous,
                        precise=self.thread.precise,
                        probe=self.probe,
                    )
            self.cycle = cycle
            stats.wakeup(run)
            if backlog > cap:
                dropped = backlog - cap
                self.epoch += dropped * t_a
                stats.slipped_cycles += dropped
                if now - self.last_slip_log > 1.0:
                    self.last_slip_log = now
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
            self.after_cycles()
        serve = self.serve
        if serve is not None:
            began, at_began = clock(), read()
            if serve(self.epoch + (self.done + 1) * t_a - SERVE_MARGIN_S):
                ended, at_served = clock(), read()
                wall = ended - began
                if wall <= 0:
                    share = 1.0
                elif self.thread.precise:  # ran or was blocked (serving), as against waiting for a CPU
                    share = 1.0 - min(1.0, (at_served[1] - at_began[1]) / wall)
                else:
                    share = min(1.0, (at_served[0] - at_began[0]) / wall)
                stats.service = (began, ended, share)
        self.slept = slept = clock()
        self.at_slept = at_slept = read()
        span = slept - woke
        if span > 0:
            self.previous = ((at_slept[0] - at_woke[0]) / span, (at_slept[1] - at_woke[1]) / span)


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
