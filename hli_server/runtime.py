"""The runtime: owns the engine and the process image and paces the cycle (E-01, H-01, H-07).

One asyncio event loop, no threads for the engine. Every cycle::

    image.latch_into(machine.hli)                  PLC->CNC half into the engine (one consistent copy)
    machine.step(1)                                one interpolation cycle of T_A
    image.publish_from(machine.hli, machine.cycle) CNC->PLC half out (never half-written)

Clocks (:class:`Clock`):

* ``realtime`` (the default): simulated time follows the monotonic clock. Cycle ``k`` is due when the
  wall clock reaches ``epoch + k * T_A``; the loop sleeps until the next cycle is due and then runs
  every cycle that is due, so a late wake-up is caught up with several cycles at once. At most
  ``max_catch_up`` cycles are run per wake-up; a backlog beyond that is dropped (the simulated
  time slips behind the wall clock), counted in :attr:`PacingStats.slipped_cycles` and logged: the
  runtime reports running late, it never hides it (design.md, "the runtime owns pacing"). The
  lateness of every cycle (wall time at publish minus its due time) is measured; p50/p99/max are in
  :meth:`PacingStats.summary` (``GET /api/timing``).
* ``stepped``: cycles run only through :meth:`Runtime.step` (tests, the H-07 harness, ``POST
  /api/step``). Deterministic: the same inputs give the same cycles.
* ``free``: as fast as the engine goes, yielding to the event loop every few milliseconds so that
  the adapters stay responsive.

Adapters (:mod:`hli_server.adapters.registry`) start in order after the image exists and before
the first cycle and stop in reverse order; then the image is closed and unlinked. :meth:`Runtime.serve`
does all of it and stops cleanly on SIGINT/SIGTERM.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import selectors
import signal
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from hli_server.adapters.registry import Adapter, AdapterError, create_adapter
from hli_server.engine.machine import Machine
from schemas.events import Event

if TYPE_CHECKING:
    from types import TracebackType

    from hli_server.engine.hli import MachineHli
    from schemas.config import MachineConfig
    from schemas.layout import Layout

__all__ = [
    "Clock",
    "ClockError",
    "ImageFactory",
    "PacingStats",
    "ProcessImageLike",
    "Runtime",
    "RuntimeStateError",
    "precise_event_loop",
]

logger = logging.getLogger(__name__)

EVENT_LOG = 10_000
"""Events kept for ``GET /api/events?since=`` (the oldest are dropped first)."""

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


class RuntimeStateError(RuntimeError):
    """The runtime is not in the state the call needs (not started, already stopped)."""


class ProcessImageLike(Protocol):
    """What the runtime needs of the shared-memory image (``hli_server.image.ProcessImage``)."""

    @property
    def name(self) -> str: ...

    @property
    def layout(self) -> Layout: ...

    def latch_into(self, hli: MachineHli) -> None: ...

    def publish_from(self, hli: MachineHli, cycle: int) -> None: ...

    def read(self, st_path: str) -> bool | int | float:
        """A field by ST path: PLC->CNC from the live half, CNC->PLC from the newest publish."""
        ...

    def write(self, st_path: str, value: bool | int | float) -> None:
        """A PLC->CNC field by ST path (a PLC's write; latched at the next cycle)."""
        ...

    def init_from(self, hli: MachineHli, cycle: int) -> None:
        """Start-up: the PLC->CNC half takes the engine's ``_w`` values; the CNC->PLC half is published."""
        ...

    def close(self) -> None:
        """Mark closed for attached clients, unmap and unlink the segment. Idempotent."""
        ...


ImageFactory = Callable[["MachineConfig", "str | None"], ProcessImageLike]
"""``(config, name or None) -> image``; the segment exists when this returns. ``None``: a unique name."""


def _default_image_factory(config: MachineConfig, name: str | None) -> ProcessImageLike:
    from hli_server.image import ProcessImage
    from schemas.layout import build_layout

    # replace_stale: a segment left by a crashed server of the same name is replaced; the image of a
    # running server never is (ProcessImage.create checks its pid)
    image: ProcessImageLike = ProcessImage.create(build_layout(config), name=name, replace_stale=True)
    return image


def _read_program_file(path: str) -> str:
    """Program table entries given by ``path`` (absolute after loading the configuration) are read
    when the PLC or the API selects them; the engine itself does no I/O."""
    return Path(path).read_text(encoding="utf-8")


def precise_event_loop() -> asyncio.AbstractEventLoop:
    """An asyncio loop whose timers wake to the microsecond: ``select(2)`` instead of ``epoll``.

    asyncio's default loop on Linux waits in ``epoll_wait``, whose timeout is whole milliseconds
    (Python rounds it up): with T_A = 1 ms every wake-up comes up to a millisecond late, and the
    realtime clock's lateness is about half a cycle at the median. ``select`` takes microseconds,
    which leaves the kernel's wake-up latency (about 0.1 ms). ``hli-server run`` uses this loop
    (``--event-loop select``, the default). Its limit: file descriptors must be below FD_SETSIZE
    (1024), plenty for one simulated CNC and its clients.
    """
    return asyncio.SelectorEventLoop(selectors.SelectSelector())


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
# The runtime
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class LoggedEvent:
    """An engine event with its sequence number (``GET /api/events?since=seq``)."""

    seq: int
    event: Event

    def to_json(self) -> dict[str, Any]:
        return {"seq": self.seq, **self.event.to_json()}


AdapterSpec = Adapter | str | tuple[str, Mapping[str, Any]]


class Runtime:
    """The machine, its image and its adapters, paced by one clock (E-01, H-01, H-07).

    ``adapters`` lists what to start: adapter objects, registered names (``"modbus"``) or
    ``(name, options)``. ``None`` means the HTTP control API on ``bind:http_port`` when
    ``http_port`` is not None. ``http_port`` 0 binds a free port (ask :attr:`http_url`).

    Use it as ``async with Runtime(config, clock="stepped", http_port=None) as rt: await rt.step(10)``,
    or :meth:`serve` for a process that runs until a signal.
    """

    def __init__(
        self,
        config: MachineConfig,
        clock: Clock | str = Clock.REALTIME,
        bind: str = "127.0.0.1",
        http_port: int | None = 8080,
        image_name: str | None = None,
        adapters: Iterable[AdapterSpec] | None = None,
        *,
        max_catch_up: int = 50,
        image_factory: ImageFactory | None = None,
        stop_after_cycles: int | None = None,
        read_program: Callable[[str], str] | None = _read_program_file,
    ) -> None:
        try:
            self.clock = Clock(clock)
        except ValueError:
            raise ValueError(
                f"unknown clock {clock!r}; use one of {', '.join(c.value for c in Clock)}"
            ) from None
        if max_catch_up < 1:
            raise ValueError(f"max_catch_up must be at least 1 cycle, got {max_catch_up}")
        if http_port is not None and not 0 <= http_port <= 65535:
            raise ValueError(f"HTTP port {http_port} is out of range 0..65535 (0 = a free port)")
        self.config = config
        self.bind = bind
        self.http_port = http_port
        self.image_name = image_name
        self.max_catch_up = max_catch_up
        self.stop_after_cycles = stop_after_cycles
        self.machine = Machine(config, read_program=read_program)
        self.t_a = self.machine.t_a
        self.stats = PacingStats(self.t_a)
        self._image_factory = image_factory or _default_image_factory
        self._image: ProcessImageLike | None = None
        specs: list[AdapterSpec]
        if adapters is None:
            specs = [("http", {"port": http_port})] if http_port is not None else []
        else:
            specs = list(adapters)
        self._adapter_specs = specs
        self.adapters: list[Adapter] = []
        self._started_adapters: list[Adapter] = []
        self.cycle_listeners: list[Callable[[int], None]] = []
        """Called with the cycle number after every published cycle (harnesses, PLC emulations in
        the same loop); keep them short, they run inside the cycle."""
        self._events: deque[LoggedEvent] = deque(maxlen=EVENT_LOG)
        self._event_seq = 0
        self.machine.event_listeners.append(self._log_event)
        self._pacer: asyncio.Task[None] | None = None
        self._stop_event: asyncio.Event | None = None
        self._step_lock: asyncio.Lock | None = None
        self._cycle_waiters: list[tuple[int, asyncio.Future[None]]] = []
        self._failure: BaseException | None = None
        self._stop_cycle: int | None = None
        self.started = False
        self.stopped = False

    # --- properties -----------------------------------------------------------------------
    @property
    def image(self) -> ProcessImageLike:
        if self._image is None:
            raise RuntimeStateError("the process image exists only while the runtime runs (await start())")
        return self._image

    @property
    def layout(self) -> Layout:
        return self.image.layout

    @property
    def cycle(self) -> int:
        return self.machine.cycle

    def adapter(self, name: str) -> Adapter:
        for a in self.adapters:
            if a.name == name:
                return a
        raise KeyError(f"no adapter {name!r} is running (running: {[a.name for a in self.adapters]})")

    @property
    def http_url(self) -> str:
        """Base URL of the HTTP control API (after start)."""
        url: str = getattr(self.adapter("http"), "url")  # noqa: B009 - the HTTP adapter's own attribute
        return url

    def endpoints(self) -> list[str]:
        """Where everything listens, one line each (the ``run`` banner)."""
        lines = [f"shared memory image: {self.image.name}"]
        for a in self.adapters:
            lines.extend(a.endpoints())
        return lines

    # --- events ---------------------------------------------------------------------------
    def _log_event(self, event: Event) -> None:
        self._event_seq += 1
        self._events.append(LoggedEvent(self._event_seq, event))

    def events_since(self, since: int = 0, limit: int = 1000) -> tuple[list[LoggedEvent], int]:
        """Events with ``seq > since`` (oldest first, at most ``limit``) and the newest seq."""
        out = [e for e in self._events if e.seq > since][:limit]
        return out, self._event_seq

    def add_event_listener(self, listener: Callable[[Event], None]) -> None:
        """Called synchronously, inside the cycle, for every engine event (MQTT, H-05). Keep it
        short: queue the event and do the I/O in a task of your own."""
        self.machine.event_listeners.append(listener)

    def remove_event_listener(self, listener: Callable[[Event], None]) -> None:
        with contextlib.suppress(ValueError):
            self.machine.event_listeners.remove(listener)

    # --- life cycle -----------------------------------------------------------------------
    async def __aenter__(self) -> Runtime:
        await self.start()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.stop()

    async def start(self) -> None:
        """Create the image, start the adapters in order, then the clock. On failure, undo all."""
        if self.started:
            raise RuntimeStateError("the runtime was started already; build a new Runtime to run again")
        self.started = True
        self._stop_event = asyncio.Event()
        self._step_lock = asyncio.Lock()
        if self.stop_after_cycles is not None:
            self._stop_cycle = self.machine.cycle + self.stop_after_cycles
        try:
            self._image = self._image_factory(self.config, self.image_name)
            self._image.init_from(self.machine.hli, self.machine.cycle)
            for spec in self._adapter_specs:
                adapter = self._make_adapter(spec)
                self.adapters.append(adapter)
                await adapter.start(self)
                self._started_adapters.append(adapter)
                logger.info("adapter %s started: %s", adapter.name, "; ".join(adapter.endpoints()))
        except BaseException:
            await self.stop()
            raise
        self.stats.started_at = time.monotonic()
        self.stats.cycles_at_start = self.machine.cycle
        if self.clock is Clock.REALTIME:
            self._pacer = asyncio.create_task(self._run_realtime(), name="hli-runtime-realtime")
        elif self.clock is Clock.FREE:
            self._pacer = asyncio.create_task(self._run_free(), name="hli-runtime-free")
        if self._pacer is not None:
            self._pacer.add_done_callback(self._pacer_done)
        self._check_stop_cycle()

    def _make_adapter(self, spec: AdapterSpec) -> Adapter:
        if isinstance(spec, str):
            return create_adapter(spec, bind=self.bind)
        if isinstance(spec, tuple):
            name, options = spec
            return create_adapter(name, bind=self.bind, options=options)
        if not isinstance(spec, Adapter):
            raise AdapterError(f"not an adapter: {spec!r} (needs name, start(runtime), stop(), endpoints())")
        return spec

    async def stop(self) -> None:
        """Stop the clock, the adapters (reverse order), then close and unlink the image. Idempotent."""
        if self.stopped:
            return
        self.stopped = True
        if self._stop_event is not None:
            self._stop_event.set()
        if self._pacer is not None:
            self._pacer.cancel()
            # a failure of the clock was recorded by _pacer_done and is raised by wait_stopped/serve;
            # here it must not keep the adapters and the image from being closed
            await asyncio.wait([self._pacer])
        errors: list[BaseException] = []
        for adapter in reversed(self._started_adapters):
            try:
                await adapter.stop()
            except Exception as exc:  # one adapter's failure must not leave the others running
                logger.exception("adapter %s failed to stop cleanly", adapter.name)
                errors.append(exc)
        self._started_adapters.clear()
        for _, fut in self._cycle_waiters:
            if not fut.done():
                fut.cancel()
        self._cycle_waiters.clear()
        if self._image is not None:
            image, self._image = self._image, None
            image.close()
        self.machine.event_listeners[:] = [
            lst for lst in self.machine.event_listeners if lst != self._log_event
        ]
        if errors:
            raise errors[0]

    def request_stop(self) -> None:
        """Ask :meth:`wait_stopped` / :meth:`serve` to shut down (signal handlers, ``--cycles``)."""
        if self._stop_event is not None:
            self._stop_event.set()

    async def wait_stopped(self) -> None:
        """Until :meth:`request_stop` (or a failure of the clock); re-raises the clock's failure."""
        if self._stop_event is None:
            raise RuntimeStateError("the runtime is not started")
        await self._stop_event.wait()
        if self._failure is not None:
            raise self._failure

    async def serve(
        self, *, install_signal_handlers: bool = True, ready: Callable[[Runtime], None] | None = None
    ) -> None:
        """Start, run until SIGINT/SIGTERM (or ``stop_after_cycles``), stop cleanly.

        ``ready`` is called once everything listens (the CLI prints its banner there).
        """
        loop = asyncio.get_running_loop()
        handled: list[signal.Signals] = []
        try:
            await self.start()
            if install_signal_handlers:
                for sig in (signal.SIGINT, signal.SIGTERM):
                    with contextlib.suppress(NotImplementedError, RuntimeError):
                        loop.add_signal_handler(sig, self._on_signal, sig)
                        handled.append(sig)
            if ready is not None:
                ready(self)
            await self.wait_stopped()
        finally:
            for sig in handled:
                loop.remove_signal_handler(sig)
            await self.stop()

    def _on_signal(self, sig: int) -> None:
        logger.info("received %s: shutting down", signal.Signals(sig).name)
        self.request_stop()

    def _pacer_done(self, task: asyncio.Task[None]) -> None:
        if task.cancelled():
            return
        exc = task.exception()
        if exc is not None:
            logger.error("the %s clock stopped at cycle %d: %r", self.clock, self.machine.cycle, exc)
            self._failure = exc
        self.request_stop()

    # --- the cycle ------------------------------------------------------------------------
    def _one_cycle(self) -> None:
        image = self._image
        if image is None:
            raise RuntimeStateError("the runtime is stopped")
        machine = self.machine
        image.latch_into(machine.hli)
        machine.step(1)
        image.publish_from(machine.hli, machine.cycle)
        for listener in self.cycle_listeners:
            listener(machine.cycle)

    def _after_cycles(self) -> None:
        cycle = self.machine.cycle
        if self._cycle_waiters:
            keep: list[tuple[int, asyncio.Future[None]]] = []
            for target, fut in self._cycle_waiters:
                if fut.done():
                    continue
                if cycle >= target:
                    fut.set_result(None)
                else:
                    keep.append((target, fut))
            self._cycle_waiters = keep
        self._check_stop_cycle()

    def _check_stop_cycle(self) -> None:
        if self._stop_cycle is not None and self.machine.cycle >= self._stop_cycle:
            self.request_stop()

    def _cycles_left(self) -> int:
        """Cycles until ``stop_after_cycles`` (a large number without it)."""
        if self._stop_cycle is None:
            return 1 << 62
        return max(0, self._stop_cycle - self.machine.cycle)

    def _running_or_raise(self) -> None:
        if not self.started or self.stopped or self._image is None:
            raise RuntimeStateError("the runtime is not running (await start() first, or it was stopped)")

    async def step(self, cycles: int = 1) -> int:
        """Run ``cycles`` cycles now (stepped clock only); returns the machine's cycle counter.

        Long runs yield to the event loop now and then, so the adapters stay responsive; concurrent
        calls run one after the other.
        """
        if self.clock is not Clock.STEPPED:
            raise ClockError(
                f"step() needs the stepped clock; this runtime runs the {self.clock} clock "
                "(start it with clock='stepped' / --clock stepped)"
            )
        if cycles < 0:
            raise ValueError(f"cycles must be >= 0, got {cycles}")
        self._running_or_raise()
        assert self._step_lock is not None
        async with self._step_lock:
            left = cycles
            while left > 0:
                self._running_or_raise()
                slice_end = time.monotonic() + FREE_SLICE_S
                batch = min(left, STEP_BATCH)
                done = 0
                while done < batch:
                    self._one_cycle()
                    done += 1
                    if time.monotonic() > slice_end:
                        break
                left -= done
                self.stats.wakeup(done)
                self._after_cycles()
                if left > 0:
                    await asyncio.sleep(0)
        return self.machine.cycle

    async def wait_cycle(self, cycle: int, timeout: float | None = None) -> int:
        """Until the machine has run ``cycle`` (any clock; in stepped mode someone must step)."""
        self._running_or_raise()
        if self.machine.cycle >= cycle:
            return self.machine.cycle
        fut: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._cycle_waiters.append((cycle, fut))
        await asyncio.wait_for(fut, timeout)
        return self.machine.cycle

    async def _run_realtime(self) -> None:
        """Realtime pacing (E-01): see the module docstring."""
        t_a = self.t_a
        stats = self.stats
        cap = self.max_catch_up
        clock = time.monotonic
        epoch = clock()
        done = 0  # cycles run since epoch
        stats.started_at = epoch
        stats.cycles_at_start = self.machine.cycle
        last_slip_log = -math.inf
        while self._cycles_left() > 0:
            now = clock()
            backlog = int((now - epoch) / t_a) - done
            if backlog > 0:
                run = min(backlog, cap, self._cycles_left())
                for _ in range(run):
                    self._one_cycle()
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
                            self.machine.cycle,
                            cap,
                            dropped,
                            stats.slipped_cycles * t_a,
                            stats.slipped_cycles,
                        )
                self._after_cycles()
            delay = epoch + (done + 1) * t_a - clock()
            await asyncio.sleep(delay if delay > 0 else 0)

    async def _run_free(self) -> None:
        """Free running (E-01): cycles back to back, yielding every FREE_SLICE_S."""
        clock = time.monotonic
        while self._cycles_left() > 0:
            slice_end = clock() + FREE_SLICE_S
            run = 0
            limit = self._cycles_left()
            while run < limit:
                self._one_cycle()
                run += 1
                if clock() >= slice_end:
                    break
            self.stats.wakeup(run)
            self._after_cycles()
            await asyncio.sleep(0)

    # --- reporting ------------------------------------------------------------------------
    def timing(self) -> dict[str, Any]:
        """Pacing statistics (``GET /api/timing``)."""
        return self.stats.summary(self.clock, self.machine.cycle)
