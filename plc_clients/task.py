"""The cyclic PLC task (H-06, C43-10: "cyclic execution like a PLC task").

A PLC runs its program in a task: every cycle it reads its inputs into an input image, runs the
program on that image, and writes the outputs the program set. :class:`PlcTask` does the same over
any :mod:`transport <plc_clients.transports>`::

    each cycle:  inputs = transport.snapshot(watch)      one consistent CNC->PLC image (+ its CNC cycle)
                 program(io)                             function blocks read io, write io
                 transport.write_many(changed outputs)   in the order the program wrote them

:class:`IoImage` is what the program sees. Reads of CNC->PLC fields come from this cycle's input
image, so every block of one cycle sees the same CNC cycle. Writes are collected and sent at the
end of the cycle, only when the value differs from what this task sent last (a PLC owns its
outputs: one writer per field), in the order of the program's writes (``command_w`` before
``enable_w``, H-02). A write that could not be delivered stays pending and is sent again next cycle.

Inputs over Modbus: the snapshot holds only the *watched* fields (each one costs Modbus traffic).
A read of a field that is not in this cycle's image adds it to the watch set; with a synchronous
transport it is read at once (one request), with an asyncio transport it cannot be awaited inside
the program, so :class:`InputNotReadyError` is raised and the field is there from the next cycle
on (function blocks treat that as "no input yet"; declare fields up front with ``watch=``).
Shared memory and the memory twin always hold every field.

Running:

* :meth:`PlcTask.run_cycle` / :meth:`run_cycles`: cycles at once, no pacing (tests);
* :meth:`PlcTask.run`: paced to ``cycle_time_s`` with a synchronous transport (a script, a thread);
* ``await`` :meth:`PlcTask.run_async` (or :meth:`start` for an ``asyncio.Task``): paced in an event
  loop, with an asyncio transport or a non-blocking synchronous one (shared memory, memory twin).

Overruns: a cycle whose execution (read, program, write) takes longer than the cycle time is an
overrun; the paced runners then skip the ticks that passed (as a PLC does) and count them. Both are
in :attr:`PlcTask.stats` and logged (at most once a second): the task reports running late,
it never hides it.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import logging
import math
import time
from collections.abc import Callable, Collection, Iterable, Sequence
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any, Final, Protocol

from plc_clients.transports import AsyncTransport, Inputs, Transport, TransportError, Value
from schemas.layout import Layout

__all__ = [
    "LATCH_MARGIN",
    "InputNotReadyError",
    "IoImage",
    "PlcTask",
    "TaskStats",
    "current_image",
]

logger = logging.getLogger(__name__)

LATCH_MARGIN: Final = 2
"""CNC cycles after the first input image read after a delivered write until the write's effect
is certainly published: the server latches the PLC->CNC half at the start of the next cycle, and a
write into shared memory can land between a latch and its publish (one more cycle)."""

_MISSING: Final = object()
_current: ContextVar[IoImage | None] = ContextVar("plc_clients_current_image", default=None)


def current_image() -> IoImage | None:
    """The :class:`IoImage` of the PLC task cycle running now (None outside a task's program)."""
    return _current.get()


class InputNotReadyError(KeyError):
    """A CNC->PLC field is not in this cycle's input image (asyncio transport); it is watched
    from the next cycle on."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "input not ready"


class IoImage:
    """The task's process image: this cycle's inputs, the outputs the program writes (H-06).

    ``read``/``get`` a field by ST path, ``write`` an output, ``latched(path)`` whether the CNC has
    certainly taken over the newest written value. ``cycle`` is the CNC cycle of the inputs.
    ``fault`` is the transport failure of this cycle (the input image could not be read) or of the
    previous cycle's output write; None when the door works.
    """

    def __init__(self, transport: Transport | AsyncTransport, *, watch: Iterable[str] = ()) -> None:
        self.transport = transport
        self.layout: Layout = transport.layout
        self._sync_reads = not getattr(transport, "is_async", False)
        self.watch: set[str] = set()
        for path in watch:
            self.add_watch(path)
        self._inputs: Inputs | None = None
        self.input_fault: TransportError | None = None
        self.output_fault: TransportError | None = None
        self._pending: dict[str, Value] = {}
        self._sent: dict[str, Value] = {}
        self._awaiting_inputs: set[str] = set()
        self._effective_from: dict[str, int] = {}

    # --- the task's side ---------------------------------------------------------------------
    def begin_cycle(self, inputs: Inputs | None, fault: TransportError | None = None) -> None:
        """A new cycle: the input image (None when it could not be read, with ``fault``)."""
        self.input_fault = fault
        if inputs is not None:
            self._inputs = inputs
            for path in self._awaiting_inputs:
                self._effective_from[path] = inputs.cycle + LATCH_MARGIN
            self._awaiting_inputs.clear()

    def outputs_to_send(self) -> list[tuple[str, Value]]:
        """The outputs that changed since they were last sent, in the program's write order."""
        return list(self._pending.items())

    def delivered(self, items: Sequence[tuple[str, Value]]) -> None:
        """The transport took ``items``; their effect is dated by the next input image."""
        self.output_fault = None
        for path, value in items:
            self._sent[path] = value
            if self._pending.get(path, _MISSING) == value:
                del self._pending[path]
            self._awaiting_inputs.add(path)
            self._effective_from.pop(path, None)

    def delivery_failed(self, fault: TransportError) -> None:
        """The outputs could not be written: they stay pending; blocks see ``fault`` next cycle."""
        self.output_fault = fault

    @property
    def fault(self) -> TransportError | None:
        return self.input_fault or self.output_fault

    # --- the program's side ------------------------------------------------------------------
    @property
    def inputs(self) -> Inputs | None:
        return self._inputs

    @property
    def cycle(self) -> int:
        """The CNC cycle of this cycle's input image (0 before the first one)."""
        return self._inputs.cycle if self._inputs is not None else 0

    def add_watch(self, st_path: str) -> None:
        """Have ``st_path`` (a CNC->PLC field) in the input image from the next cycle on."""
        s = self.layout.signal(st_path)
        if not s.plc_writable:
            self.watch.add(s.st_path)

    def read(self, st_path: str) -> Value:
        """A field: CNC->PLC from this cycle's input image; PLC->CNC as this task wrote it.

        Raises :class:`~plc_clients.transports.TransportError` when this cycle's inputs could not
        be read, :class:`InputNotReadyError` for a field an asyncio transport has not read yet.
        """
        s = self.layout.signal(st_path)
        path = s.st_path
        if s.plc_writable:
            value = self._pending.get(path, self._sent.get(path, _MISSING))
            if value is not _MISSING:
                return value  # type: ignore[return-value]
            if self._sync_reads:
                return self.transport.read(path)  # type: ignore[return-value]
            raise InputNotReadyError(
                f"{path}: this task has not written it, and an asyncio transport cannot read it "
                "inside the program"
            )
        if self.input_fault is not None:
            raise self.input_fault
        if self._inputs is not None and path in self._inputs:
            return self._inputs[path]
        self.watch.add(path)
        if self._sync_reads:
            return self.transport.read(path)  # type: ignore[return-value]
        raise InputNotReadyError(
            f"{path} is not in this cycle's input image; it is read from the next cycle on "
            "(declare it with PlcTask(watch=[...]) to have it from the first cycle)"
        )

    def get(self, st_path: str, default: Value | None = None) -> Value | None:
        """Like :meth:`read`, but ``default`` for a field that is not ready yet."""
        try:
            return self.read(st_path)
        except InputNotReadyError:
            return default

    def write(self, st_path: str, value: Value) -> None:
        """Set an output (sent at the end of the cycle if it changed). ``_r`` fields and values
        the field cannot hold are refused at once (the layout's errors)."""
        s = self.layout.signal(st_path)
        s.check_plc_write()
        v = s.coerce(value)
        path = s.st_path
        self._pending.pop(path, None)
        if self._sent.get(path, _MISSING) != v:
            self._pending[path] = v  # (re)inserted last: the order of this cycle's writes

    def latched(self, st_path: str) -> bool:
        """True when the newest value this task wrote to ``st_path`` was delivered and this
        cycle's inputs were published after the CNC latched it (:data:`LATCH_MARGIN`)."""
        path = self.layout.signal(st_path).st_path
        if path in self._pending or path not in self._sent:
            return False
        since = self._effective_from.get(path)
        return since is not None and self.cycle >= since


class _Executable(Protocol):
    def execute(self) -> object: ...


Program = Callable[[IoImage], object] | _Executable | Sequence[_Executable]


@dataclass(slots=True)
class TaskStats:
    """How the task kept its cycle (times in s)."""

    cycles: int = 0
    overruns: int = 0
    """cycles whose execution took longer than the cycle time."""
    skipped_ticks: int = 0
    """ticks of the paced runners that passed while a cycle overran (those cycles did not run)."""
    last_exec_s: float = 0.0
    max_exec_s: float = 0.0
    input_faults: int = 0
    """cycles whose input image could not be read."""
    output_faults: int = 0
    """cycles whose outputs could not be written."""
    last_fault: str | None = None


class PlcTask:
    """A cyclic PLC task over one transport (H-06).

    ``program``: a callable that takes the :class:`IoImage`, a function block, or a sequence of
    function blocks (each is executed with the inputs it holds, in order). Function blocks called
    inside the program find the task's image on their own (:func:`current_image`).
    ``watch``: CNC->PLC fields to have in the input image from the first cycle on.
    """

    def __init__(
        self,
        transport: Transport | AsyncTransport,
        cycle_time_s: float,
        program: Program,
        *,
        watch: Iterable[str] = (),
        name: str = "PlcTask",
        on_overrun: Callable[[PlcTask, float], None] | None = None,
    ) -> None:
        if not cycle_time_s > 0:
            raise ValueError(f"cycle_time_s must be > 0, got {cycle_time_s}")
        self.transport = transport
        self.cycle_time_s = float(cycle_time_s)
        self.name = name
        self.image = IoImage(transport, watch=watch)
        self._program = _as_callable(program)
        self.on_overrun = on_overrun
        self.stats = TaskStats()
        self._last_overrun_log = -math.inf
        self._stop = False
        self._task: asyncio.Task[int] | None = None

    @property
    def is_async(self) -> bool:
        return bool(getattr(self.transport, "is_async", False))

    # --- one cycle ---------------------------------------------------------------------------
    def _watch(self) -> Collection[str]:
        return frozenset(self.image.watch)

    def _run_program(self) -> None:
        token = _current.set(self.image)
        try:
            self._program(self.image)
        finally:
            _current.reset(token)

    def run_cycle(self) -> None:
        """One cycle now: read the inputs, run the program, write the changed outputs."""
        if self.is_async:
            raise TypeError(f"{self.name}: the transport is asyncio; use `await task.run_cycle_async()`")
        t0 = time.perf_counter()
        transport: Transport = self.transport  # type: ignore[assignment]
        try:
            inputs: Inputs | None = transport.snapshot(self._watch())
            fault = None
        except TransportError as exc:
            inputs, fault = None, exc
        self._begin(inputs, fault)
        self._run_program()
        items = self.image.outputs_to_send()
        if items:
            try:
                transport.write_many(items)
            except TransportError as exc:
                self._write_failed(exc)
            else:
                self.image.delivered(items)
        self._end(time.perf_counter() - t0)

    async def run_cycle_async(self) -> None:
        """One cycle now, in an event loop (awaits an asyncio transport's calls)."""
        if not self.is_async and getattr(self.transport, "blocking", False):
            raise TypeError(
                f"{self.name}: {self.transport!r} blocks on the network: in an event loop use "
                "AsyncModbusTransport, or run this task with run() outside the loop"
            )
        t0 = time.perf_counter()
        transport: Any = self.transport
        try:
            result = transport.snapshot(self._watch())
            inputs: Inputs | None = await result if inspect.isawaitable(result) else result
            fault = None
        except TransportError as exc:
            inputs, fault = None, exc
        self._begin(inputs, fault)
        self._run_program()
        items = self.image.outputs_to_send()
        if items:
            try:
                result = transport.write_many(items)
                if inspect.isawaitable(result):
                    await result
            except TransportError as exc:
                self._write_failed(exc)
            else:
                self.image.delivered(items)
        self._end(time.perf_counter() - t0)

    def _begin(self, inputs: Inputs | None, fault: TransportError | None) -> None:
        if fault is not None:
            self.stats.input_faults += 1
            self.stats.last_fault = str(fault)
            logger.debug("%s: input image not read: %s", self.name, fault)
        self.image.begin_cycle(inputs, fault)

    def _write_failed(self, exc: TransportError) -> None:
        self.stats.output_faults += 1
        self.stats.last_fault = str(exc)
        logger.debug("%s: outputs not written: %s", self.name, exc)
        self.image.delivery_failed(exc)

    def _end(self, exec_s: float) -> None:
        st = self.stats
        st.cycles += 1
        st.last_exec_s = exec_s
        st.max_exec_s = max(st.max_exec_s, exec_s)
        if exec_s > self.cycle_time_s:
            st.overruns += 1
            if self.on_overrun is not None:
                self.on_overrun(self, exec_s)
            now = time.monotonic()
            if now - self._last_overrun_log > 1.0:
                self._last_overrun_log = now
                logger.warning(
                    "%s: cycle %d took %.2f ms, longer than the cycle time %.2f ms (%d overruns so far)",
                    self.name,
                    st.cycles,
                    exec_s * 1e3,
                    self.cycle_time_s * 1e3,
                    st.overruns,
                )

    def run_cycles(self, count: int) -> None:
        """``count`` cycles back to back, without pacing (tests)."""
        for _ in range(count):
            self.run_cycle()

    # --- paced ---------------------------------------------------------------------------------
    def _next_tick(self, start: float, tick: int, now: float) -> tuple[int, float]:
        """The next tick after ``tick`` that is still ahead; counts the ones that passed."""
        t = self.cycle_time_s
        due = start + (tick + 1) * t
        if now > due:
            passed = math.floor((now - start) / t) - tick
            self.stats.skipped_ticks += passed
            tick += passed
            due = start + (tick + 1) * t
        return tick + 1, due

    def _done(self, ran: int, cycles: int | None, until: Callable[[], bool] | None) -> bool:
        return self._stop or (cycles is not None and ran >= cycles) or (until is not None and until())

    def _timed_out(self, deadline: float | None, ran: int) -> None:
        if deadline is not None and time.monotonic() > deadline:
            raise TimeoutError(
                f"{self.name}: the stop condition was not met within the timeout ({ran} cycles run)"
            )

    def run(
        self,
        cycles: int | None = None,
        *,
        until: Callable[[], bool] | None = None,
        timeout_s: float | None = None,
    ) -> int:
        """Run paced to the cycle time until ``cycles`` ran, ``until()`` is true (checked after
        each cycle) or :meth:`stop`; ``TimeoutError`` after ``timeout_s``. Returns cycles run."""
        self._stop = False
        start = time.monotonic()
        deadline = None if timeout_s is None else start + timeout_s
        tick, ran = 0, 0
        while not self._done(ran, cycles, until):
            self._timed_out(deadline, ran)
            self.run_cycle()
            ran += 1
            if self._done(ran, cycles, until):
                break
            tick, due = self._next_tick(start, tick, time.monotonic())
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        return ran

    async def run_async(
        self,
        cycles: int | None = None,
        *,
        until: Callable[[], bool] | None = None,
        timeout_s: float | None = None,
    ) -> int:
        """:meth:`run` in an event loop (``asyncio.sleep`` between cycles)."""
        self._stop = False
        start = time.monotonic()
        deadline = None if timeout_s is None else start + timeout_s
        tick, ran = 0, 0
        while not self._done(ran, cycles, until):
            self._timed_out(deadline, ran)
            await self.run_cycle_async()
            ran += 1
            if self._done(ran, cycles, until):
                break
            tick, due = self._next_tick(start, tick, time.monotonic())
            await asyncio.sleep(max(0.0, due - time.monotonic()))
        return ran

    def start(self) -> asyncio.Task[int]:
        """Run for ever as an ``asyncio.Task`` (until :meth:`stop`); exceptions of the program end it."""
        if self._task is not None and not self._task.done():
            raise RuntimeError(f"{self.name} is running already")
        self._task = asyncio.create_task(self.run_async(), name=self.name)
        return self._task

    def stop(self) -> None:
        """Ask the runner to end after the current cycle."""
        self._stop = True

    async def wait_stopped(self) -> None:
        """After :meth:`stop`: until the asyncio task has ended (re-raises its failure)."""
        if self._task is not None:
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

    def __repr__(self) -> str:
        return f"PlcTask({self.name!r}, {self.cycle_time_s * 1e3:g} ms, {self.transport!r})"


def _as_callable(program: Program) -> Callable[[IoImage], object]:
    if hasattr(program, "execute"):
        block: Any = program
        return lambda _io: block.execute()
    if isinstance(program, Sequence):
        blocks = list(program)
        for b in blocks:
            if not hasattr(b, "execute"):
                raise TypeError(f"program sequence item {b!r} is not a function block (no execute())")

        def run_blocks(_io: IoImage) -> None:
            for b in blocks:
                b.execute()

        return run_blocks
    if callable(program):
        return program
    raise TypeError(f"program must be a callable(io), a function block or a list of them, not {program!r}")
