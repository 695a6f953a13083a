"""The operator's door across processes: the engine's process serves its operator panel, its event feed
and its stepped clock to the doors process over a socket pair (docs/runtime.md, docs/reliability.md).

Why: the HTTP API, the dashboard's streams and MQTT are work of the network, and on the clock's event
loop each of them cost cycles (a long read of the event log held the loop and dropped cycles; the
collector's passes over the server's objects came on top: docs/performance.md, "The clock under load", has
the figures). In the doors process
they cost the clock nothing: what remains in the engine's process is this service, and the clock serves it
*between* cycles (``run_realtime``'s ``serve``), in the slack before the next cycle is due.

What crosses the socket (frames: a 4-byte length, then a pickle; both ends are this package)::

    doors -> engine   ("call", id, method, args, kwargs)     an OperatorPort method (sync at the doors)
                      ("timing", id)                           the clock's statistics, unsorted
                      ("readiness", id)                        the server's readiness (GET /api/ready)
                      ("step", id, cycles, signals | None)     the stepped clock (async at the doors)
                      ("restart", id)                          power the machine off and on (stepped clock)
                      ("cancel", id)                           the client of that step went away
                      ("recorder", id, method, args)           the session recorder (docs/record-replay.md)
                      ("faults", id, op, args)                 set, end or reset communication faults
                      ("fault-ended", 0, fault id, reason)     a fault the doors used up (no answer)
    engine -> doors   ("ok", id, result) / ("err", id, exception)
                      ("events", [(seq, class, values), ...])  the engine's events, numbered, in order (an
                                                               event as its class and its fields' values)
                      ("faults", table, ended)                 the communication faults, on every change, with
                                                               the reasons of those ended since (id -> reason)

The messages are typed ``Any`` inside this module (a frame holds whatever the method called takes and
answers); the answers are typed where they leave it: each :class:`RemoteOperator`, :class:`RemoteRecorder`
and :class:`RemoteFaults` method names its result's shape (``schemas.results``), as the ports do.

The events cost the clock the same whatever their consumers do (issue 36, finding 4): the clock's end
queues each (an append), sends them after each batch of cycles as plain tuples (a third of pickling the
event objects), and when the doors process does not take them (its socket buffer holds more than
:data:`MIRROR_BUFFER_BYTES`) it keeps only the newest :data:`~hli_server.runtime.event_log.EVENT_LOG` for
later: what is lost shows as a gap in the numbers, which ``GET /api/events`` counts as ``missed``.
The consumers (MQTT, the dashboard's streams, the readers of the log) all live in the doors process.

The doors process keeps its own copy of the event log (``GET /api/events`` and the streams read it there),
answers what never changes from a cache (channels, axes, program tables, the machine's name), reads cycle
and time from the image it attached, and sorts the timing samples itself: a read, however large its
answer, reaches the engine as one small request or not at all.

The engine's process owns the communication faults (docs/record-replay.md: the recording notes every change,
a stall acts on the publish); the doors process keeps a mirror that its connections consult
(:class:`RemoteFaults`), which sends what users set through the doors (the HTTP API) to the engine and takes
the engine's table on every change.

* :class:`OperatorService`: the engine's end, an ``asyncio.Protocol`` on the clock's loop;
* :class:`RemoteLink`, :class:`RemoteOperator`, :class:`EventMirror`, :class:`RemoteFaults`,
  :class:`RemoteRecorder`: the doors process' end.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import itertools
import logging
import operator
import pickle
import select
import socket
import struct
import time
from collections import deque
from collections.abc import Callable, Coroutine, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

from hli_server.adapters.faults import ActiveFault, CommFaults, FaultError, FaultMirror, FaultSpec
from hli_server.adapters.host import (
    Accepted,
    AdapterHost,
    EventFeed,
    ImagePort,
    LoggedEvent,
    OperatorError,
    OperatorPort,
    Readiness,
    RecorderPort,
    Trace,
    UnavailableError,
)
from hli_server.runtime.event_log import EVENT_LOG, EventLog
from hli_server.runtime.pacing import PacingRaw, summarize_timing
from schemas.events import Event
from schemas.results import (
    AlarmList,
    AreaTable,
    AxisFaults,
    CollisionPair,
    CommFaultChange,
    MachineState,
    ProbeDeviation,
    ProgramEntry,
    ProgramLoaded,
    ProgramSelected,
    RecorderStatus,
    RecordingFile,
    Scene,
    SoftLimits,
    Timing,
)
from schemas.wire import Mode

__all__ = [
    "CALL_TIMEOUT_S",
    "MIRROR_BUFFER_BYTES",
    "OPERATOR_CALLS",
    "EngineSide",
    "EventMirror",
    "OperatorService",
    "RemoteFaults",
    "RemoteLink",
    "RemoteOperator",
    "RemoteRecorder",
    "event_from_wire",
    "event_to_wire",
]

logger = logging.getLogger(__name__)

_HEAD = struct.Struct("!I")
_READ_SIZE = 1 << 20

CALL_TIMEOUT_S = 10.0
"""How long the doors process waits for an answer of the engine before it says it is unavailable (503)."""
MIRROR_BUFFER_BYTES = 8 << 20
"""While more than this waits in the socket for the doors process, the clock sends no events (it keeps the
newest ``EVENT_LOG`` for when the doors take them again): a doors process that falls behind costs the
clock neither time nor memory."""
LOST_LOG_INTERVAL_S = 5.0
"""Events the doors process did not get are logged at most this often (with their count)."""

OPERATOR_CALLS = frozenset(
    {
        "channel_numbers",
        "axis_names",
        "load_program",
        "select_program",
        "start",
        "reset",
        "feedhold",
        "mode",
        "override",
        "jog",
        "probe",
        "probe_deviation",
        "set_probe_deviation",
        "reference",
        "faults",
        "inject_faults",
        "clear_faults",
        "snapshot",
        "alarms",
        "areas",
        "scene",
        "programs",
        "collision_pairs",
        "soft_limits",
        "set_soft_limits",
        "update_axis_record",
        "machine_name",
        "t_a_us",
    }
)
"""The :class:`~hli_server.adapters.host.OperatorPort` members the doors process may call (properties
too: a call of a property's name returns its value)."""

_STATIC = frozenset({"channel_numbers", "axis_names", "programs", "machine_name", "t_a_us"})
"""Calls whose answer never changes while the server runs: asked once, then answered by the doors."""
_RECORDER_CALLS = frozenset({"status", "start", "stop", "files", "file"})
"""The :class:`~hli_server.adapters.host.RecorderPort` members the doors process may call."""


def frame(message: object) -> bytes:
    payload = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    return _HEAD.pack(len(payload)) + payload


class FrameReader:
    """Bytes in, messages out (frames may arrive in any pieces)."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Any]:
        buf = self._buf
        buf += data
        out: list[Any] = []
        pos = 0
        while len(buf) - pos >= 4:
            (size,) = _HEAD.unpack_from(buf, pos)
            if len(buf) - pos - 4 < size:
                break
            out.append(pickle.loads(memoryview(buf)[pos + 4 : pos + 4 + size]))
            pos += 4 + size
        if pos:
            del buf[:pos]
        return out


_EVENT_FIELDS: dict[type[Event], tuple[tuple[str, ...], Callable[[Event], tuple[Any, ...]]]] = {}


def _event_fields(cls: type[Event]) -> tuple[tuple[str, ...], Callable[[Event], tuple[Any, ...]]]:
    spec = _EVENT_FIELDS.get(cls)
    if spec is None:
        names = tuple(f.name for f in dataclasses.fields(cls))  # cycle, time_s, channel and its own
        spec = _EVENT_FIELDS[cls] = (names, operator.attrgetter(*names))
    return spec


def event_to_wire(seq: int, event: Event) -> tuple[int, type[Event], tuple[Any, ...]]:
    """``(seq, class, values)``: what crosses the socket for an event (a third of pickling the object)."""
    cls = type(event)
    return seq, cls, _event_fields(cls)[1](event)


def event_from_wire(cls: type[Event], values: Sequence[Any]) -> Event:
    return cls(**dict(zip(_event_fields(cls)[0], values, strict=True)))


def _portable(exc: BaseException) -> BaseException:
    """``exc`` if it survives pickling (our errors do), else a RuntimeError with its text."""
    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:
        return RuntimeError(f"{type(exc).__name__}: {exc}")
    return exc


# --------------------------------------------------------------------------------------------
# The engine's end
# --------------------------------------------------------------------------------------------


class EngineSide(Protocol):
    """What the engine's end of the link needs of the runtime (:class:`~hli_server.runtime.Runtime` is
    one; a protocol, so that this module does not import the runtime that builds on it)."""

    @property
    def defers_requests(self) -> bool: ...

    @property
    def event_log(self) -> EventLog: ...

    @property
    def comm_faults(self) -> CommFaults: ...

    @property
    def recorder_port(self) -> RecorderPort: ...

    @property
    def operator(self) -> OperatorPort: ...

    @property
    def host(self) -> AdapterHost: ...

    def timing_raw(self) -> PacingRaw: ...

    def readiness(self) -> Readiness: ...


class OperatorService(asyncio.Protocol):
    """The engine's end of the link, on the clock's loop.

    A request that arrives is only decoded and queued (microseconds); it is served by :meth:`serve`, which
    the realtime clock calls after each wake-up's cycles with the time by which it must be done, so that
    requests fill the slack between cycles instead of delaying one. Without a running realtime clock
    (stepped, free, before the first and after the last cycle) requests are served as they arrive. A step
    runs as a task of its own (other requests are served while it runs; its client may cancel it).
    Events are sent after each batch of cycles, before any answer, so that an answer never overtakes the
    events of the cycles it reports."""

    def __init__(self, runtime: EngineSide) -> None:
        self._rt = runtime
        self._panel = runtime.operator
        self._reader = FrameReader()
        self._transport: asyncio.Transport | None = None
        self._pending: deque[Any] = deque()
        self._steps: dict[int, asyncio.Task[None]] = {}
        self._outbox: deque[tuple[int, Event]] = deque(maxlen=EVENT_LOG)
        self.withheld = 0
        """Flushes that sent no events because the doors process had not taken the earlier ones."""
        self._unsubscribe = runtime.event_log.subscribe(self._on_event)
        self._faults_changed = runtime.comm_faults.active  # the doors start with the engine's table
        self._faults_ended: dict[int, str] = {}
        """Why each fault ended since the table was last sent: the mirror's history and listeners say the
        engine's reason ("api", "reset", "cycles", ...), as the engine's log and the recording do."""
        self._unsubscribe_faults = runtime.comm_faults.subscribe(self._on_fault)
        self.served = 0
        self.closed = asyncio.get_running_loop().create_future()

    # --- the socket ---------------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport

    def data_received(self, data: bytes) -> None:
        messages = self._reader.feed(data)
        if self._rt.defers_requests:
            self._pending.extend(messages)
            return
        for message in messages:
            self._handle(message)

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None
        self.close()
        if not self.closed.done():
            self.closed.set_result(None)

    def close(self) -> None:
        self._unsubscribe()
        self._unsubscribe_faults()
        for task in self._steps.values():
            task.cancel()
        self._steps.clear()
        self._pending.clear()
        if self._transport is not None:
            self._transport.close()

    @property
    def buffered(self) -> int:
        """Bytes sent that wait in this end's buffer for the doors process to read them."""
        return self._transport.get_write_buffer_size() if self._transport is not None else 0

    @property
    def held(self) -> int:
        """Events not yet sent (at most ``EVENT_LOG``: the newest)."""
        return len(self._outbox)

    # --- the clock's side ---------------------------------------------------------------------
    def _on_event(self, event: Event) -> None:
        self._outbox.append((self._rt.event_log.latest, event))

    def _on_fault(self, change: CommFaultChange) -> None:
        self._faults_changed = True  # sent with the next flush (a change may come inside the cycle)
        if change["fault"] == "end":
            self._faults_ended[change["id"]] = str(change.get("reason", "engine"))

    def _fault_table(self) -> tuple[list[FaultMirror], dict[int, str]]:
        """The table for the mirror and the reasons of the ends since it was last sent."""
        self._faults_changed = False
        ended, self._faults_ended = self._faults_ended, {}
        return self._rt.comm_faults.export(), ended

    def flush(self) -> None:
        """Send the events of the cycles run since the last flush (after each batch of cycles), and the
        table of communication faults if it changed. While the doors process has not taken what was
        sent (:data:`MIRROR_BUFFER_BYTES`), the events wait (the newest ``EVENT_LOG`` of them)."""
        transport = self._transport
        if transport is None:
            return
        outbox = self._outbox
        if outbox:
            if transport.get_write_buffer_size() > MIRROR_BUFFER_BYTES:
                self.withheld += 1
            else:
                transport.write(frame(("events", [event_to_wire(seq, event) for seq, event in outbox])))
                outbox.clear()
        if self._faults_changed:
            transport.write(frame(("faults", *self._fault_table())))

    def serve(self, deadline: float) -> bool:
        """Serve queued requests until ``deadline`` (``time.monotonic``), at least one if any wait;
        whether there was any."""
        self.flush()
        pending = self._pending
        if not pending:
            return False
        clock = time.monotonic
        while pending:
            self._handle(pending.popleft())
            if clock() >= deadline:
                break
        return True

    def serve_all(self) -> None:
        """Serve everything queued (the realtime clock stopped)."""
        self.flush()
        while self._pending:
            self._handle(self._pending.popleft())

    # --- requests -----------------------------------------------------------------------------
    def _handle(self, message: Any) -> None:
        self.served += 1
        kind, ident = message[0], message[1]
        try:
            if kind == "call":
                _, _, name, args, kwargs = message
                result = self._call(name, args, kwargs)
                self.flush()  # the events of the request (a program load) before its answer
                self._answer(ident, result)
            elif kind == "timing":
                self._answer(ident, self._rt.timing_raw())
            elif kind == "readiness":
                self._answer(ident, self._rt.readiness())
            elif kind == "step":
                _, _, cycles, signals = message
                host = self._rt.host
                self._run(ident, host.step(cycles) if signals is None else host.step_traced(cycles, signals))
            elif kind == "restart":
                self._run(ident, self._rt.host.restart())
            elif kind == "cancel":
                task = self._steps.pop(ident, None)
                if task is not None:
                    task.cancel()
            elif kind == "recorder":
                _, _, name, args = message
                if name not in _RECORDER_CALLS:
                    raise OperatorError(f"{name!r} is not a request of the session recorder")
                self._answer(ident, getattr(self._rt.recorder_port, name)(*args))
            elif kind == "faults":
                _, _, op, args = message
                self._answer(ident, self._fault_request(op, args))
            elif kind == "fault-ended":
                _, _, fault_id, reason = message
                faults = self._rt.comm_faults
                if faults.get(fault_id) is not None:
                    faults.end(fault_id, reason)
            else:
                raise ValueError(f"unknown request {kind!r}")
        except Exception as exc:
            if ident == 0:  # a message that wants no answer
                logger.warning("message %r of the doors process failed: %s", kind, exc)
            else:
                self._fail(ident, exc)

    def _fault_request(self, op: str, args: Sequence[Any]) -> Any:
        """What the doors' users ask of the communication faults; the answer carries the new table (and
        why the faults that ended since it was sent ended)."""
        faults = self._rt.comm_faults
        result: Any
        if op == "add":
            result = faults.add(args[0]).id
        elif op == "end":
            fault = faults.end(args[0], args[1])
            result = (fault.mirror(), fault.ended)
        elif op == "reset":
            result = faults.reset(args[0])
        else:
            raise OperatorError(f"{op!r} is not a request of the communication faults")
        return result, *self._fault_table()  # the answer carries the table

    def _call(self, name: str, args: Sequence[Any], kwargs: dict[str, Any]) -> Any:
        if name not in OPERATOR_CALLS:
            raise OperatorError(f"{name!r} is not an operator request")
        member = getattr(self._panel, name)
        return member(*args, **kwargs) if callable(member) else member

    def _run(self, ident: int, work: Coroutine[Any, Any, Any]) -> None:
        """A step or a restart of the machine: a task of its own (its client may cancel it)."""
        self._steps[ident] = asyncio.get_running_loop().create_task(
            self._answer_when_done(ident, work), name=f"hli-remote-step-{ident}"
        )

    async def _answer_when_done(self, ident: int, work: Coroutine[Any, Any, Any]) -> None:
        try:
            result = await work
        except asyncio.CancelledError:
            return  # its client went away (or the link closed): nobody waits for an answer
        except Exception as exc:
            self._fail(ident, exc)
        else:
            self.flush()
            self._answer(ident, result)
        finally:
            self._steps.pop(ident, None)

    def _answer(self, ident: int, result: Any) -> None:
        if self._transport is not None:
            self._transport.write(frame(("ok", ident, result)))

    def _fail(self, ident: int, exc: BaseException) -> None:
        if not isinstance(exc, OperatorError | LookupError | ValueError):  # FaultError is a ValueError
            logger.exception("request %r of the doors process failed", ident, exc_info=exc)
        if self._transport is not None:
            self._transport.write(frame(("err", ident, _portable(exc))))


# --------------------------------------------------------------------------------------------
# The doors process' end
# --------------------------------------------------------------------------------------------


class RemoteLink:
    """The doors process' end of the socket: synchronous calls (the operator port is synchronous: the
    caller waits, the loop with it, for an answer that comes between two of the engine's cycles), async
    calls (steps), and the events the engine sends (``on_events``)."""

    def __init__(
        self, sock: socket.socket, on_events: Callable[[list[tuple[int, type[Event], Sequence[Any]]]], None]
    ) -> None:
        sock.setblocking(False)
        self._sock = sock
        self._on_events = on_events
        self.on_faults: Callable[[list[FaultMirror], dict[int, str]], None] | None = None
        """Takes the engine's table of communication faults and why the faults that left it ended
        (:class:`RemoteFaults`)."""
        self._reader = FrameReader()
        self._ids = itertools.count(1)
        self._answers: dict[int, tuple[str, Any]] = {}
        self._futures: dict[int, asyncio.Future[Any]] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self.closed = False

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        loop.add_reader(self._sock, self._readable)

    def close(self) -> None:
        if self._loop is not None and not self.closed:
            with contextlib.suppress(Exception):
                self._loop.remove_reader(self._sock)
        self._lost()
        self._sock.close()

    # --- in ------------------------------------------------------------------------------------
    def _readable(self) -> None:
        self._receive()

    def _receive(self) -> bool:
        """Read what is there; False when there was nothing."""
        try:
            data = self._sock.recv(_READ_SIZE)
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:
            data = b""
        if not data:
            self._lost()
            return True
        for message in self._reader.feed(data):
            self._dispatch(message)
        return True

    def _dispatch(self, message: Any) -> None:
        kind = message[0]
        if kind == "events":
            self._on_events(message[1])
            return
        if kind == "faults":
            if self.on_faults is not None:
                self.on_faults(message[1], message[2])
            return
        ident = message[1]
        future = self._futures.pop(ident, None)
        if future is None:
            self._answers[ident] = (kind, message[2])
        elif not future.done():
            if kind == "ok":
                future.set_result(message[2])
            else:
                future.set_exception(message[2])

    def _lost(self) -> None:
        if self.closed:
            return
        self.closed = True
        if self._loop is not None:
            with contextlib.suppress(Exception):
                self._loop.remove_reader(self._sock)
        for future in self._futures.values():
            if not future.done():
                future.set_exception(UnavailableError("the engine's process is gone"))
        self._futures.clear()

    # --- out -----------------------------------------------------------------------------------
    def _send(self, data: bytes) -> None:
        if self.closed:
            raise UnavailableError("the engine's process is gone")
        view = memoryview(data)
        deadline = time.monotonic() + CALL_TIMEOUT_S
        while view:
            try:
                sent = self._sock.send(view)
            except (BlockingIOError, InterruptedError):
                # the engine reads everything as it arrives; while it does, take what it sent us
                left = deadline - time.monotonic()
                if left <= 0:
                    raise UnavailableError("the engine's process does not take requests") from None
                readable, _, _ = select.select([self._sock], [self._sock], [], min(left, 0.05))
                if readable:
                    self._receive()
                continue
            except OSError:
                self._lost()
                raise UnavailableError("the engine's process is gone") from None
            view = view[sent:]

    def call(self, kind: str, *fields: Any) -> Any:
        """Send ``(kind, id, *fields)`` and wait for the answer (raising the engine's error)."""
        ident = next(self._ids)
        self._send(frame((kind, ident, *fields)))
        deadline = time.monotonic() + CALL_TIMEOUT_S
        while ident not in self._answers:
            if self.closed:
                raise UnavailableError("the engine's process is gone")
            left = deadline - time.monotonic()
            if left <= 0:
                raise UnavailableError(
                    f"the engine did not answer within {CALL_TIMEOUT_S:.0f} s; try again later"
                )
            if not self._receive():
                select.select([self._sock], [], [], min(left, 1.0))
        status, value = self._answers.pop(ident)
        if status == "err":
            raise value
        return value

    def tell(self, kind: str, *fields: Any) -> None:
        """Send ``(kind, 0, *fields)``, which gets no answer."""
        with contextlib.suppress(UnavailableError):
            self._send(frame((kind, 0, *fields)))

    async def call_async(self, kind: str, *fields: Any) -> Any:
        """Send ``(kind, id, *fields)`` and await the answer; cancelling the awaiting task tells the
        engine to cancel its work (``("cancel", id)``)."""
        assert self._loop is not None
        ident = next(self._ids)
        future: asyncio.Future[Any] = self._loop.create_future()
        self._futures[ident] = future
        self._send(frame((kind, ident, *fields)))
        try:
            return await future
        except asyncio.CancelledError:
            self._futures.pop(ident, None)
            with contextlib.suppress(UnavailableError):
                self._send(frame(("cancel", ident)))
            raise


class EventMirror(EventFeed):
    """The engine's event log as the doors process keeps it: the same numbers, the same bound; the
    subscribers (the dashboard's streams, MQTT) are called from the loop after each batch arrives. Events
    the engine could not send (this process fell behind) are a gap in the numbers: counted in :attr:`lost`
    and logged (at most every :data:`LOST_LOG_INTERVAL_S`)."""

    def __init__(self) -> None:
        self.log = EventLog()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._last: int | None = None
        self.lost = 0
        self._lost_logged = 0
        self._last_log = -LOST_LOG_INTERVAL_S

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop

    def take(self, wired: Iterable[tuple[int, type[Event], Sequence[Any]]]) -> None:
        """A batch as the engine sent it (:func:`event_to_wire`)."""
        logged = []
        last = self._last
        for seq, cls, values in wired:
            if last is not None and seq > last + 1:
                self.lost += seq - last - 1
            last = seq
            logged.append((seq, event_from_wire(cls, values)))
        self._last = last
        if self.lost != self._lost_logged and time.monotonic() - self._last_log >= LOST_LOG_INTERVAL_S:
            self._last_log = time.monotonic()
            logger.warning(
                "the doors process fell behind the engine's events: %d not taken (%d in all; the event log "
                "counts them as missed, MQTT and the dashboards did not get them)",
                self.lost - self._lost_logged,
                self.lost,
            )
            self._lost_logged = self.lost
        events = self.log.extend(logged)
        if events and self._loop is not None:
            self._loop.call_soon(self.log.deliver, events)

    def subscribe(self, listener: Callable[[Event], None]) -> Callable[[], None]:
        return self.log.subscribe(listener)

    def since(self, seq: int = 0, limit: int = 1000) -> tuple[Sequence[LoggedEvent], int]:
        return self.log.since(seq, limit)


class RemoteOperator(OperatorPort):
    """:class:`~hli_server.adapters.host.OperatorPort` of the doors process: each request is one call
    to the engine's :class:`OperatorService`; what never changes is asked once; cycle and time come from
    the attached image (the newest publish); the timing samples are sorted here."""

    def __init__(self, link: RemoteLink, image: ImagePort, t_a_us: int) -> None:
        self._link = link
        self._image = image
        self._t_a_us = t_a_us
        self._cache: dict[tuple[str, tuple[Any, ...]], Any] = {}

    def _call(self, name: str, *args: Any, **kwargs: Any) -> Any:
        key = (name, args)
        if name in _STATIC and not kwargs:
            if key in self._cache:
                return self._cache[key]
            value = self._link.call("call", name, args, kwargs)
            self._cache[key] = value
            return value
        return self._link.call("call", name, args, kwargs)

    @property
    def cycle(self) -> int:
        return self._image.cycle

    @property
    def time_s(self) -> float:
        return self._image.cycle * self._t_a_us / 1_000_000  # exact to the µs, as the engine's

    @property
    def t_a_us(self) -> int:
        return self._t_a_us

    @property
    def machine_name(self) -> str:
        name: str = self._call("machine_name")
        return name

    def channel_numbers(self) -> list[int]:
        out: list[int] = self._call("channel_numbers")
        return out

    def axis_names(self, channel: int | None = None) -> list[str]:
        out: list[str] = self._call("axis_names", channel)
        return out

    def load_program(
        self, channel: int, text: str, name: str = "program", files: Mapping[str, str] | None = None
    ) -> ProgramLoaded:
        out: ProgramLoaded = self._call("load_program", channel, text, name, dict(files) if files else None)
        return out

    def select_program(self, channel: int, number: int) -> ProgramSelected:
        out: ProgramSelected = self._call("select_program", channel, number)
        return out

    def _accepted(self, name: str, *args: Any) -> Accepted:
        out: Accepted = self._call(name, *args)
        return out

    def start(self, channel: int) -> Accepted:
        return self._accepted("start", channel)

    def reset(self, channel: int) -> Accepted:
        return self._accepted("reset", channel)

    def feedhold(self, channel: int, on: bool) -> Accepted:
        return self._accepted("feedhold", channel, on)

    def mode(self, channel: int, mode: Mode) -> Accepted:
        return self._accepted("mode", channel, mode)

    def override(self, channel: int, permille: int) -> Accepted:
        return self._accepted("override", channel, permille)

    def jog(self, channel: int, axis: str, direction: int) -> Accepted:
        return self._accepted("jog", channel, axis, direction)

    def probe(self, channel: int, on: bool) -> Accepted:
        return self._accepted("probe", channel, on)

    def probe_deviation(self, channel: int) -> ProbeDeviation:
        out: ProbeDeviation = self._call("probe_deviation", channel)
        return out

    def set_probe_deviation(self, channel: int, values: dict[str, int]) -> ProbeDeviation:
        out: ProbeDeviation = self._call("set_probe_deviation", channel, values)
        return out

    def reference(self, axis: str) -> Accepted:
        return self._accepted("reference", axis)

    def faults(self, axis: str) -> AxisFaults:
        out: AxisFaults = self._call("faults", axis)
        return out

    def inject_faults(self, axis: str, **fields: float | bool) -> AxisFaults:
        out: AxisFaults = self._call("inject_faults", axis, **fields)
        return out

    def clear_faults(self, axis: str) -> AxisFaults:
        out: AxisFaults = self._call("clear_faults", axis)
        return out

    def soft_limits(self, axis: str) -> SoftLimits:
        out: SoftLimits = self._call("soft_limits", axis)
        return out

    def set_soft_limits(self, axis: str, **values: int) -> SoftLimits:
        out: SoftLimits = self._call("set_soft_limits", axis, **values)
        return out

    def update_axis_record(self, axis: str, **values: int) -> SoftLimits:
        out: SoftLimits = self._call("update_axis_record", axis, **values)
        return out

    def snapshot(self) -> MachineState:
        out: MachineState = self._call("snapshot")
        return out

    def alarms(self, history: int = 200) -> AlarmList:
        out: AlarmList = self._call("alarms", history)
        return out

    def areas(self, channel: int) -> AreaTable:
        out: AreaTable = self._call("areas", channel)
        return out

    def timing(self) -> Timing:
        raw: PacingRaw = self._link.call("timing")
        return summarize_timing(raw)

    def scene(self, channel: int) -> Scene:
        out: Scene = self._call("scene", channel)
        return out

    def programs(self, channel: int) -> list[ProgramEntry]:
        out: list[ProgramEntry] = self._call("programs", channel)
        return out

    def collision_pairs(self) -> list[CollisionPair]:
        out: list[CollisionPair] = self._call("collision_pairs")
        return out

    async def step(self, cycles: int) -> int:
        cycle: int = await self._link.call_async("step", cycles, None)
        return cycle

    async def step_traced(self, cycles: int, signals: Sequence[str]) -> Trace:
        trace: Trace = await self._link.call_async("step", cycles, list(signals))
        return trace


class RemoteFaults(CommFaults):
    """The doors process' communication faults: a mirror of the engine's table, which its connections
    consult; what users set, end or reset through the doors (the HTTP API) is done by the engine, whose
    answer updates the mirror at once; what the doors use up (a count, a duration) ends here too and is
    told to the engine. Each change of the engine's table reaches the mirror's listeners (MQTT's
    disconnect fault) as a change of this one."""

    def __init__(self, link: RemoteLink, cycle: Callable[[], int]) -> None:
        super().__init__(cycle)
        self._link = link
        self._taking = False
        link.on_faults = self.take
        self.subscribe(self._report)

    def _report(self, change: CommFaultChange) -> None:
        if change["fault"] == "end" and not self._taking and change.get("reason") in ("count", "duration"):
            self._link.tell("fault-ended", change["id"], change["reason"])

    def take(self, table: list[FaultMirror], ended: Mapping[int, str]) -> None:
        """The engine's table: load it and tell the listeners what was set and what ended, and why
        (``ended``: the engine's reasons; "engine" where it gave none)."""
        before = self.get_ids()
        self._taking = True
        try:
            self.load(table)
            after = self.get_ids()
            for fault_id in sorted(after - before):
                fault = self.get(fault_id)
                assert fault is not None
                spec = fault.spec.model_dump(mode="json", exclude_none=True)
                self._tell({"fault": "set", "id": fault_id, "spec": spec})
            for fault_id in sorted(before - after):
                self._tell({"fault": "end", "id": fault_id, "reason": ended.get(fault_id, "engine")})
        finally:
            self._taking = False

    def get_ids(self) -> set[int]:
        return {f["id"] for f in self.export()}

    def add(self, spec: FaultSpec | dict[str, Any]) -> ActiveFault:
        data = spec.model_dump(mode="json", exclude_none=True) if isinstance(spec, FaultSpec) else dict(spec)
        fault_id, table, ended = self._link.call("faults", "add", (data,))
        self.take(table, ended)
        fault = self.get(fault_id)
        if fault is None:  # it ended in the engine before the answer came (a duration of 0, ...)
            raise FaultError(f"communication fault {fault_id} ended as soon as it was set")
        return fault

    def end(self, fault_id: int, reason: str = "api") -> ActiveFault:
        if reason in ("count", "duration"):  # the doors' own: ends here, told to the engine
            return super().end(fault_id, reason)
        here = self.get(fault_id)
        (mirror, why), table, ended = self._link.call("faults", "end", (fault_id, reason))
        self.take(table, ended)
        spec = FaultSpec.model_validate(mirror["spec"])
        return ActiveFault(
            id=mirror["id"],
            spec=spec,
            started_cycle=mirror["started_cycle"],
            started_at=mirror["started_at"],
            expires_at=mirror["expires_at"],
            # the doors count what they used (the engine's copy counts only a stall's cycles): the answer
            # says how often the fault acted up to its end
            used=max(mirror["used"], here.used if here is not None else 0),
            ended=why,
        )

    def reset(self, reason: str = "reset") -> int:
        count, table, ended = self._link.call("faults", "reset", (reason,))
        self.take(table, ended)
        result: int = count
        return result


class RemoteRecorder(RecorderPort):
    """The session recorder of the engine's process, asked over the link (docs/record-replay.md). A
    recording's file is on the machine's file system, which both processes see: ``file`` gives its path."""

    def __init__(self, link: RemoteLink) -> None:
        self._link = link

    def status(self) -> RecorderStatus:
        out: RecorderStatus = self._link.call("recorder", "status", ())
        return out

    def start(self, name: str | None = None) -> RecorderStatus:
        out: RecorderStatus = self._link.call("recorder", "start", (name,))
        return out

    def stop(self) -> RecorderStatus:
        out: RecorderStatus = self._link.call("recorder", "stop", ())
        return out

    def files(self) -> list[RecordingFile]:
        out: list[RecordingFile] = self._link.call("recorder", "files", ())
        return out

    def file(self, name: str) -> Path:
        out: Path = self._link.call("recorder", "file", (name,))
        return out
