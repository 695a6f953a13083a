"""The runtime: owns the engine and the process image, paces the cycle, hosts the adapters (E-01, H-01).

One asyncio event loop, no threads for the engine. Every cycle::

    image.latch_into(machine.hli)                  PLC->CNC half into the engine (one consistent copy)
    machine.step(1)                                one interpolation cycle of T_A
    image.publish_from(machine.hli, machine.cycle) CNC->PLC half out (never half-written)

The pieces live beside this module: ``pacing.py`` (the clocks and their statistics), ``events.py``
(the event log), ``image.py`` (creating the image), ``programs.py`` (program files) and ``host.py``
(what the adapters get: image, operator panel, events, step).

Adapters start in order after the image exists and before the first cycle and stop in reverse
order; then the image is closed and unlinked. :meth:`Runtime.serve` does all of it and stops
cleanly on SIGINT/SIGTERM.

A failure inside a cycle never ends the server (docs/reliability.md): the cycle's exception is logged with its
traceback, every channel takes alarm 919000 (its axes stop, its program is aborted), the failed
cycles are counted (``GET /api/timing``), and the clock keeps pacing. A reset clears the alarm.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import os
import signal
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Literal, Protocol

from hli_server._compiled import stale_notice
from hli_server.adapters.faults import CommFaults
from hli_server.adapters.host import (
    AccessPolicy,
    CheckPort,
    EventFeed,
    ImagePort,
    LoggedEvent,
    OperatorPort,
    Readiness,
    RecorderPort,
    StepRefusedError,
    Trace,
    door_host,
)
from hli_server.adapters.registry import ADAPTERS, Adapter, AdapterError, create_adapter
from hli_server.engine.machine import Machine
from hli_server.recording.tap import JournaledOperator, RecordingOptions, SessionRecorderPort, SessionTap
from hli_server.runtime.checks import ProgramChecker
from hli_server.runtime.doors import DoorsProcess
from hli_server.runtime.event_log import EventLog
from hli_server.runtime.image_factory import ImageFactory, RuntimeImage, shared_memory_image
from hli_server.runtime.nc_files import NcFileWriter
from hli_server.runtime.operator_panel import OperatorPanel
from hli_server.runtime.pacing import (
    FREE_SLICE_S,
    PRIORITIES,
    STEP_BATCH,
    Clock,
    ClockError,
    PacingRaw,
    PacingStats,
    ask_for_low_latency,
    raise_priority,
    run_free,
    run_realtime,
    summarize_timing,
)
from hli_server.runtime.programs import RuntimeLibrary, cycle_libraries, read_program_file
from schemas.results import Timing

if TYPE_CHECKING:
    from types import TracebackType

    from hli_server.image import SignalRecorder
    from schemas.config import MachineConfig
    from schemas.events import Event
    from schemas.layout import Layout

__all__ = [
    "AdapterSpec",
    "Recording",
    "RequestService",
    "Runtime",
    "RuntimeHost",
    "RuntimeStateError",
    "summarize_timing",
]

logger = logging.getLogger(__name__)

FAILURE_LOG_INTERVAL_S = 5.0
"""A cycle that keeps failing is logged with its traceback at most this often."""


class RequestService(Protocol):
    """Work the clock's loop does between cycles (``runtime/remote.py``'s ``OperatorService``)."""

    def flush(self) -> None: ...

    def serve(self, deadline: float) -> bool:
        """Serve what waits until ``deadline``; whether there was anything."""
        ...

    def serve_all(self) -> None: ...


class RuntimeStateError(RuntimeError):
    """The runtime is not in the state the call needs (not started, already stopped)."""


class _StartInterrupted(BaseException):  # like KeyboardInterrupt: not an error, not caught as one
    """A stop was asked for (a signal) while the runtime started: :meth:`Runtime.serve` stops cleanly."""


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
        read_program: Callable[[str], str] | None = read_program_file,
        policy: AccessPolicy | None = None,
        doors_process: bool = False,
        priority: str = "normal",
        recording: RecordingOptions | None = None,
        program_dirs: Sequence[str | os.PathLike[str]] = (),
        nc_output_dir: str | os.PathLike[str] | None = None,
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
        self.policy = policy or AccessPolicy()
        self.doors_process = doors_process
        """Run the network doors in a process of their own (``runtime/doors.py``)."""
        if priority not in PRIORITIES:
            raise ValueError(f"unknown priority {priority!r}; use one of {', '.join(PRIORITIES)}")
        self.priority = priority
        """What the realtime clock's thread asks of the operating system (``pacing.raise_priority``)."""
        self.priority_granted = "normal"
        """What it got, in words (the banner)."""
        self.http_port = http_port
        self.image_name = image_name
        self.max_catch_up = max_catch_up
        self.stop_after_cycles = stop_after_cycles
        self.programs = RuntimeLibrary([*program_dirs, *config.program_directories])
        """Where ``L name`` finds global subprograms: uploads, ``program_dirs``, the machine file's (N-02)."""
        self.checker = ProgramChecker(config, self.programs.directories.directories)
        """Checks programs offline for ``POST /api/check`` (a worker process, started at the first check)."""
        self.session = SessionTap(config, recording)
        """Records the session (docs/record-replay.md): the input journal always, a recording file on
        demand."""
        self._read_program = read_program
        self.event_log = EventLog()
        self.machine = self._power_on()
        self.nc_files = NcFileWriter(self.machine, nc_output_dir)
        """Carries out the programs' ``#MSG SAVE`` writes inside its output directory (N-07)."""
        self.machine.event_listeners.append(self.nc_files)
        self.comm_faults = CommFaults(lambda: self.machine.cycle)
        """Faults in the PLC's communication on demand (docs/record-replay.md, ``adapters/faults.py``)."""
        self.comm_faults.subscribe(self.session.note_fault)
        self.recorder_port = SessionRecorderPort(self.session)
        self.t_a = self.machine.t_a
        self.stats = PacingStats(self.t_a)
        self._cycle_listeners: list[Callable[[int], None]] = []
        self._services: list[RequestService] = []
        self._recorders: list[SignalRecorder] = []
        self.panel = OperatorPanel(self.machine, self.timing, library=self.programs)
        self.operator = JournaledOperator(self.panel, self.session)
        self.host = RuntimeHost(self, self.panel)
        self._image_factory = image_factory or shared_memory_image
        self._image: RuntimeImage | None = None
        specs: list[AdapterSpec]
        if adapters is None:
            specs = [("http", {"port": http_port})] if http_port is not None else []
        else:
            specs = list(adapters)
        self._adapter_specs = specs
        self.adapters: list[Adapter] = []
        self._started_adapters: list[Adapter] = []
        self._pacer: asyncio.Task[None] | None = None
        self._stop_event: asyncio.Event | None = None
        self._step_lock: asyncio.Lock | None = None
        self._cycle_waiters: list[tuple[int, asyncio.Future[None]]] = []
        self._failure: BaseException | None = None
        self._stop_cycle: int | None = None
        self.failed_cycles = 0
        self.cycle_failure_hook: Callable[[Exception], bool] | None = None
        """Takes a failing cycle's exception first; True: taken (no log, no 919000). A replay from a
        recording's snapshot sets it: there a failing cycle says the restored state does not fit."""
        self._last_failure_log = -FAILURE_LOG_INTERVAL_S
        self.started = False
        self.stopped = False
        self._serving = False
        self.stop_requested = False
        """Set by :meth:`request_stop`, also before :meth:`start` (a signal during start-up)."""

    def _power_on(self) -> Machine:
        """A machine as the machine file starts it, wired to the session recorder and the event log."""
        machine = Machine(
            self.config,
            read_program=self.session.wrap_reader(self._read_program),
            programs=self.programs,
            cycle_programs={
                n: self.session.wrap_library(lib) for n, lib in cycle_libraries(self.config).items()
            },
        )
        self.session.bind(machine)
        machine.programs = self.session.wrap_library(machine.programs)
        machine.event_listeners.append(self.event_log)
        return machine

    async def restart_machine(self) -> int:
        """Power the machine off and on (stepped clock only; ``POST /api/machine/restart``): a new machine
        from the machine file, as at start, with cycle 0, the PLC's half of the image as at start, no files
        uploaded with programs, no communication fault, and the input journal begun anew. What stays: the
        doors and their connections, the event log (its numbers go on), files ``#MSG SAVE`` wrote. A test
        harness that drives a server it did not start (``pytest --hli-url``) restarts it between two tests,
        so that no test's state reaches the next. Returns the cycle counter (0)."""
        if self.clock is not Clock.STEPPED:
            raise ClockError(
                f"a restart of the machine needs the stepped clock; this runtime runs the {self.clock} clock "
                "(a test bench's server runs --clock stepped)"
            )
        self._running_or_raise()
        if self.session.recording:
            raise RuntimeStateError("a recording runs: stop it first (POST /api/recording/stop)")
        assert self._step_lock is not None
        async with self._step_lock:  # between two steps, never inside one
            old = self.machine
            for listener in (self.event_log, self.nc_files):
                with contextlib.suppress(ValueError):
                    old.event_listeners.remove(listener)
            self.comm_faults.reset("restart")
            self.programs.clear_uploads()
            self.session.restart()
            machine = self._power_on()
            machine.event_listeners.append(self.nc_files)
            self.nc_files.rebind(machine)
            self.panel.rebind(machine)
            self.machine = machine
            self.image.init_from(machine.hli, machine.cycle, machine.external)
            self.stats.cycles_at_start = machine.cycle
            if self.stop_after_cycles is not None:
                self._stop_cycle = machine.cycle + self.stop_after_cycles
            logger.info("the machine was restarted (power off and on): cycle %d", machine.cycle)
        return machine.cycle

    # --- properties -----------------------------------------------------------------------
    @property
    def image(self) -> RuntimeImage:
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
        """Base URL of the HTTP control API (after start; in this process or the doors process)."""
        for a in self.adapters:
            if a.name == "http":
                url: str = getattr(a, "url")  # noqa: B009 - the HTTP adapter's own attribute
                return url
            door_url = getattr(a, "door_url", None)
            if door_url is not None and door_url("http") is not None:
                found: str = door_url("http")
                return found
        raise KeyError(f"no HTTP adapter is running (running: {[a.name for a in self.adapters]})")

    def endpoints(self) -> list[str]:
        """Where everything listens, one line each (the ``run`` banner)."""
        backing = getattr(self.image, "backing", "shared memory")
        lines = [f"{backing} image: {self.image.name}"]
        for a in self.adapters:
            lines.extend(a.endpoints())
        return lines

    def readiness(self) -> Readiness:
        """Ready: the clock runs and every adapter asked for has started (``GET /api/ready``). The doors
        of the doors process count once that process reports them listening."""
        doors = {_spec_name(spec): False for spec in self._adapter_specs}
        ports: dict[str, int] = {}
        for adapter in self._started_adapters:
            inner = getattr(adapter, "doors", None)  # the doors process: the doors it serves
            served = inner if isinstance(inner, dict) else {adapter.name: (getattr(adapter, "port", None),)}
            for name, door in served.items():
                doors[name] = True
                if isinstance(door[0], int):
                    ports[name] = door[0]
        state: Literal["starting", "running", "stopping"]
        if self.stopped or self.stop_requested:
            state = "stopping"
        elif self.started and self.stats.started_at is not None:
            state = "running"
        else:
            state = "starting"
        return Readiness(
            ready=state == "running" and all(doors.values()), state=state, doors=doors, ports=ports
        )

    # --- events and cycle listeners --------------------------------------------------------
    def events_since(self, since: int = 0, limit: int = 1000) -> tuple[list[LoggedEvent], int]:
        """Events with ``seq > since`` (oldest first, at most ``limit``) and the newest seq."""
        events, latest = self.event_log.since(since, limit)
        return list(events), latest

    def add_event_listener(self, listener: Callable[[Event], None]) -> Callable[[], None]:
        """Called synchronously, inside the cycle, for every engine event (MQTT, H-05). Keep it
        short: queue the event and do the I/O in a task of your own. Returns the unsubscribe call."""
        return self.event_log.subscribe(listener)

    def on_cycle(self, listener: Callable[[int], None]) -> Callable[[], None]:
        """``listener(cycle)`` after every published cycle (harnesses, ADS notifications); keep it short.
        Returns the unsubscribe call."""
        self._cycle_listeners.append(listener)

        def unsubscribe() -> None:
            with contextlib.suppress(ValueError):
                self._cycle_listeners.remove(listener)

        return unsubscribe

    # --- requests served between cycles (the doors process: runtime/remote.py) ------------------
    def add_service(self, service: RequestService) -> Callable[[], None]:
        """Serve ``service`` between cycles: ``flush()`` after every batch of cycles, ``serve(deadline)``
        in the slack before the next realtime cycle is due (see :attr:`defers_requests`). Returns the
        call that removes it."""
        self._services.append(service)

        def remove() -> None:
            with contextlib.suppress(ValueError):
                self._services.remove(service)

        return remove

    @property
    def defers_requests(self) -> bool:
        """True while the realtime clock runs: a service queues what arrives and the clock serves it
        between cycles; otherwise a service answers at once."""
        return self.clock is Clock.REALTIME and self._pacer is not None and not self._pacer.done()

    def _serve_between_cycles(self, deadline: float) -> bool:
        served = False
        for service in self._services:
            try:
                served = service.serve(deadline) or served
            except Exception:  # a service's bug must not stop the clock
                logger.exception("service %r failed between cycles", service)
        return served

    # --- per-cycle traces (H-07) -------------------------------------------------------------
    def record(self, signals: Sequence[str]) -> Recording:
        """Record ``signals`` (ST paths, either half) in every published cycle from now on, whatever
        steps the clock, until :meth:`Recording.stop`. One ``unpack_from`` per cycle; unknown paths
        raise the layout's ``UnknownSignalError`` at once."""
        self._running_or_raise()
        recorder = self.image.recorder(signals)
        self._recorders.append(recorder)
        return Recording(self, recorder)

    def _stop_recording(self, recorder: SignalRecorder) -> None:
        with contextlib.suppress(ValueError):
            self._recorders.remove(recorder)

    async def step_traced(self, cycles: int, signals: Sequence[str]) -> Trace:
        """:meth:`step`, and ``signals`` in every one of these cycles (exactly these: a step that
        waits for the step lock does not see another caller's cycles)."""
        self._check_step(cycles)
        recorder = self.image.recorder(signals)  # unknown paths fail before any cycle runs
        assert self._step_lock is not None
        async with self._step_lock:
            self._recorders.append(recorder)
            try:
                await self._run_cycles(cycles)
            finally:
                self._stop_recording(recorder)
        return _trace(recorder)

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
        notice = stale_notice()
        if notice is not None:
            logger.warning("%s", notice)
        self._stop_event = asyncio.Event()
        self._step_lock = asyncio.Lock()
        if self.stop_after_cycles is not None:
            self._stop_cycle = self.machine.cycle + self.stop_after_cycles
        if self.clock is Clock.REALTIME:
            # before the doors process starts, so that it knows whether the clock goes first anyway; the
            # processes and threads started from here on do not inherit it (SCHED_RESET_ON_FORK)
            self.priority_granted = raise_priority(self.priority)
        try:
            self._image = self._image_factory(self.config, self.image_name)
            self._image.init_from(self.machine.hli, self.machine.cycle, self.machine.external)
            self.session.attach(self._image)
            for spec in self._in_process_specs():
                self._check_interrupted()
                adapter = self._make_adapter(spec)
                self.adapters.append(adapter)
                await adapter.start(door_host(self.host, adapter.name))
                self._started_adapters.append(adapter)
                logger.info("adapter %s started: %s", adapter.name, "; ".join(adapter.endpoints()))
            self._check_interrupted()
        except BaseException:
            await self.stop()
            raise
        self.stats.started_at = time.monotonic()
        self.stats.cycles_at_start = self.machine.cycle
        if self.clock is Clock.REALTIME:
            # after the doors process started: it must not inherit the short time slice (it serves many
            # clients: a longer slice suits it)
            self.priority_granted = ", ".join([self.priority_granted, *ask_for_low_latency()])
            self.stats.gc.install()
            self._pacer = asyncio.create_task(
                run_realtime(
                    self._one_cycle,
                    self._after_cycles,
                    self._cycles_left,
                    self.stats,
                    max_catch_up=self.max_catch_up,
                    serve=self._serve_between_cycles,
                ),
                name="hli-runtime-realtime",
            )
        elif self.clock is Clock.FREE:
            self._pacer = asyncio.create_task(
                run_free(self._one_cycle, self._after_cycles, self._cycles_left, self.stats),
                name="hli-runtime-free",
            )
        if self._pacer is not None:
            self._pacer.add_done_callback(self._pacer_done)
        self._check_stop_cycle()

    async def start_adapter(self, spec: AdapterSpec) -> Adapter:
        """Start one more adapter on a running runtime (the test harness opens the doors a test
        asks for); it is stopped with the others. Raises what the adapter's start raises."""
        self._running_or_raise()
        adapter = self._make_adapter(spec)
        if any(a.name == adapter.name for a in self.adapters):
            raise AdapterError(f"adapter {adapter.name!r} runs already: {'; '.join(adapter.endpoints())}")
        await adapter.start(door_host(self.host, adapter.name))
        self.adapters.append(adapter)
        self._started_adapters.append(adapter)
        logger.info("adapter %s started: %s", adapter.name, "; ".join(adapter.endpoints()))
        return adapter

    def _in_process_specs(self) -> list[AdapterSpec]:
        """The adapters to start here; with ``doors_process`` the network doors (every registered kind
        that can: ``image_only`` or ``doors``) go to one :class:`~hli_server.runtime.doors.DoorsProcess`,
        started in their place, and the clock's loop keeps only the cycle and the requests it serves
        between cycles."""
        if not self.doors_process:
            return list(self._adapter_specs)
        here: list[AdapterSpec] = []
        moved: list[tuple[str, dict[str, Any]]] = []
        for spec in self._adapter_specs:
            name, options = (
                (spec, {}) if isinstance(spec, str) else spec if isinstance(spec, tuple) else ("", {})
            )
            kind = ADAPTERS.get(name)
            if kind is not None and (kind.image_only or kind.doors):
                moved.append((name, dict(options)))
            else:
                here.append(spec)
        if moved:
            if self._image_factory is not shared_memory_image:
                raise RuntimeStateError(
                    "the doors process needs the image in shared memory (the default image)"
                )
            here.append(DoorsProcess(moved, runtime=self))
        return here

    def _make_adapter(self, spec: AdapterSpec) -> Adapter:
        if isinstance(spec, str):
            return create_adapter(spec, bind=self.bind)
        if isinstance(spec, tuple):
            name, options = spec
            return create_adapter(name, bind=self.bind, options=options)
        if not isinstance(spec, Adapter):
            raise AdapterError(f"not an adapter: {spec!r} (needs name, start(host), stop(), endpoints())")
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
        self.stats.gc.uninstall()
        await self.session.close()
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
        self._recorders.clear()
        if self._image is not None:
            image, self._image = self._image, None
            image.close()
        with contextlib.suppress(ValueError):
            self.machine.event_listeners.remove(self.event_log)
        self.nc_files.close()
        await self.checker.close()
        if errors:
            raise errors[0]

    def request_stop(self) -> None:
        """Ask :meth:`wait_stopped` / :meth:`serve` to shut down (signal handlers, ``--cycles``). Asked
        before or while :meth:`serve` starts, it stops the start between two steps, cleanly."""
        self.stop_requested = True
        if self._stop_event is not None:
            self._stop_event.set()

    def _check_interrupted(self) -> None:
        if self.stop_requested and self._serving:
            raise _StartInterrupted("stopped during start-up")

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

        ``ready`` is called once everything listens (the CLI prints its banner there). The signal
        handlers are in place before the first step of the start: a signal at any moment of the
        start-up stops it after the step under way and undoes what was started (nothing is left: no
        process, no socket, no shared memory), and ``ready`` is not called.
        """
        loop = asyncio.get_running_loop()
        handled: list[signal.Signals] = []
        if install_signal_handlers:
            for sig in (signal.SIGINT, signal.SIGTERM):
                with contextlib.suppress(NotImplementedError, RuntimeError):
                    loop.add_signal_handler(sig, self._on_signal, sig)
                    handled.append(sig)
        self._serving = True
        try:
            if self.stop_requested:
                return
            try:
                await self.start()
            except _StartInterrupted:
                logger.info("stopped during start-up")
                return
            # everything built so far lives as long as the process: keep it out of the cyclic garbage
            # collector's full passes, which otherwise scan it again and again and delay cycles by
            # tens of milliseconds (measured under a flooding client, docs/reliability.md). Before the
            # banner: a client that reads it finds the clock already running.
            gc.collect()
            gc.freeze()
            if ready is not None:
                ready(self)
            await self.wait_stopped()
        finally:
            gc.unfreeze()
            try:
                await self.stop()  # a second signal meanwhile changes nothing: the handlers stay till done
            finally:
                for sig in handled:
                    loop.remove_signal_handler(sig)

    def _on_signal(self, sig: int) -> None:
        logger.info("received %s: shutting down", signal.Signals(sig).name)
        self.request_stop()

    def _pacer_done(self, task: asyncio.Task[None]) -> None:
        for service in self._services:  # what waited for the clock's slack is served now
            asyncio.get_running_loop().call_soon(service.serve_all)
        if task.cancelled():
            return
        exc = task.exception()
        if exc is not None:
            logger.error("the %s clock stopped at cycle %d: %r", self.clock, self.machine.cycle, exc)
            self._failure = exc
        self.request_stop()

    # --- the cycle ------------------------------------------------------------------------
    def _one_cycle(self) -> int:
        image = self._image
        if image is None:
            raise RuntimeStateError("the runtime is stopped")
        machine = self.machine
        session = self.session  # the recording tap at the latch boundary (hli_server/recording)
        latched = b""
        packed: bytearray | None = None
        try:
            session.before_cycle(machine.cycle + 1)
            latched = image.latch_into(machine.hli)
            machine.step(1)
        except Exception as exc:  # the server outlives a failing cycle: the channels take an error
            self._cycle_failed(exc)
        files = self.nc_files  # #MSG SAVE is written off this thread; its refusals come back here
        if files.active:
            try:
                files.after_cycle(inline=self.clock is Clock.STEPPED)
            except Exception as exc:
                self._cycle_failed(exc)
        try:
            stalled = self.comm_faults.publish_stalled(machine.cycle)  # a stalled publish, on demand
            if session.needs_outputs(machine.cycle) or self._recorders or self._cycle_listeners:
                packed = image.publish_from(machine.hli, machine.cycle, commit=not stalled)
            elif not stalled:  # nobody reads this cycle's half (a replay between its comparisons)
                image.publish_external()
        except Exception as exc:
            self._cycle_failed(exc)
        session.after_cycle(machine.cycle, latched, packed)
        for recorder in self._recorders:
            recorder.sample()
        for listener in self._cycle_listeners:
            try:
                listener(machine.cycle)
            except Exception:  # an adapter's bug must not stop the clock
                logger.exception("cycle listener %r failed at cycle %d", listener, machine.cycle)
        return machine.cycle

    def _cycle_failed(self, exc: Exception) -> None:
        self.failed_cycles += 1
        hook = self.cycle_failure_hook
        if hook is not None and hook(exc):
            return
        now = time.monotonic()
        if now - self._last_failure_log >= FAILURE_LOG_INTERVAL_S:
            self._last_failure_log = now
            logger.error(
                "cycle %d failed (%d failed cycles so far); the channels were stopped with alarm 919000 and "
                "the clock goes on. Please report this with the traceback:",
                self.machine.cycle,
                self.failed_cycles,
                exc_info=exc,
            )
        self.machine.cycle_failed(exc)

    def _after_cycles(self) -> None:
        cycle = self.machine.cycle
        for service in self._services:
            service.flush()
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
        self._check_step(cycles)
        assert self._step_lock is not None
        async with self._step_lock:
            await self._run_cycles(cycles)
        return self.machine.cycle

    def _check_step(self, cycles: int) -> None:
        if self.clock is not Clock.STEPPED:
            raise ClockError(
                f"step() needs the stepped clock; this runtime runs the {self.clock} clock "
                "(start it with clock='stepped' / --clock stepped)"
            )
        if cycles < 0:
            raise ValueError(f"cycles must be >= 0, got {cycles}")
        self._running_or_raise()

    async def _run_cycles(self, cycles: int) -> None:
        """``cycles`` cycles under the step lock, yielding to the loop every FREE_SLICE_S."""
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

    async def wait_cycle(self, cycle: int, timeout: float | None = None) -> int:
        """Until the machine has run ``cycle`` (any clock; in stepped mode someone must step)."""
        self._running_or_raise()
        if self.machine.cycle >= cycle:
            return self.machine.cycle
        fut: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._cycle_waiters.append((cycle, fut))
        await asyncio.wait_for(fut, timeout)
        return self.machine.cycle

    # --- reporting ------------------------------------------------------------------------
    def timing(self) -> Timing:
        """Pacing statistics (``GET /api/timing``)."""
        return summarize_timing(self.timing_raw())

    def timing_raw(self) -> PacingRaw:
        """:meth:`timing` before its percentiles are sorted out (cheap: the doors process sorts)."""
        raw = self.stats.raw(self.clock, self.machine.cycle)
        raw["failed_cycles"] = self.failed_cycles
        return raw

    def __repr__(self) -> str:
        state = "stopped" if self.stopped else "running" if self.started else "new"
        return f"Runtime({self.config.name!r}, {self.clock} clock, cycle {self.machine.cycle}, {state})"


def _spec_name(spec: AdapterSpec) -> str:
    if isinstance(spec, str):
        return spec
    if isinstance(spec, tuple):
        return spec[0]
    return spec.name


def _trace(recorder: SignalRecorder) -> Trace:
    cycles, values = recorder.columns()
    return Trace(signals=recorder.paths, cycles=cycles, values=values, types=recorder.types)


class Recording:
    """Signals recorded in every published cycle (:meth:`Runtime.record`); a context manager.

    :meth:`trace` gives what was recorded so far (it can be called while recording goes on);
    :meth:`stop` ends the recording (the runtime's :meth:`Runtime.stop` ends it too)."""

    def __init__(self, runtime: Runtime, recorder: SignalRecorder) -> None:
        self._runtime = runtime
        self._recorder = recorder

    @property
    def signals(self) -> tuple[str, ...]:
        return self._recorder.paths

    def __len__(self) -> int:
        return len(self._recorder)

    def trace(self) -> Trace:
        return _trace(self._recorder)

    def stop(self) -> Trace:
        self._runtime._stop_recording(self._recorder)
        return self.trace()

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class RuntimeHost:
    """The :class:`~hli_server.adapters.host.AdapterHost` of a running :class:`Runtime`."""

    def __init__(self, runtime: Runtime, operator: OperatorPanel) -> None:
        self._rt = runtime
        self._operator = operator
        # the operator panel's trails follow the cycles, its scenes the events (the dashboard)
        self._dashboard_off = (
            runtime.on_cycle(operator.recorder.after_cycle),
            runtime.event_log.subscribe(operator.recorder.on_event),
        )

    def detach_dashboard(self) -> None:
        """Draw no trails and count no scene changes from now on: a runtime nobody watches (a replay)."""
        for off in self._dashboard_off:
            off()

    @property
    def image(self) -> ImagePort:
        return self._rt.image

    @property
    def operator(self) -> OperatorPort:
        return self._rt.operator  # the panel, with every request noted by the session recorder

    @property
    def recorder(self) -> RecorderPort:
        return self._rt.recorder_port

    @property
    def faults(self) -> CommFaults:
        return self._rt.comm_faults

    @property
    def checker(self) -> CheckPort:
        return self._rt.checker

    @property
    def events(self) -> EventFeed:
        return self._rt.event_log

    @property
    def clock(self) -> str:
        return str(self._rt.clock)

    @property
    def bind(self) -> str:
        return self._rt.bind

    @property
    def policy(self) -> AccessPolicy:
        return self._rt.policy

    async def step(self, cycles: int = 1) -> int:
        try:
            return await self._rt.step(cycles)
        except (ClockError, RuntimeStateError) as exc:
            raise StepRefusedError(str(exc)) from None

    async def step_traced(self, cycles: int, signals: Sequence[str]) -> Trace:
        try:
            return await self._rt.step_traced(cycles, signals)
        except (ClockError, RuntimeStateError) as exc:
            raise StepRefusedError(str(exc)) from None

    def on_cycle(self, listener: Callable[[int], None]) -> Callable[[], None]:
        return self._rt.on_cycle(listener)

    async def restart(self) -> int:
        try:
            return await self._rt.restart_machine()
        except (ClockError, RuntimeStateError) as exc:
            raise StepRefusedError(str(exc)) from None

    def readiness(self) -> Readiness:
        return self._rt.readiness()

    def __repr__(self) -> str:
        return f"RuntimeHost({self._rt!r})"
