"""The network doors in a process of their own (``run --doors-process``, the default; docs/reliability.md,
docs/runtime.md).

The image lives in shared memory, so the doors that serve it (Modbus, ADS) attach it by name like a PLC
does and answer from there; the doors that need the engine (the HTTP API with the dashboard's streams,
MQTT) reach its operator panel, its events and its stepped clock over a socket (``runtime/remote.py``),
served by the clock between cycles. Then the work of 200 polling PLCs, a flooding client, a read of ten
thousand events or a dashboard that never reads runs in another interpreter, on another core if there is
one, with its own garbage collector, and the cycle's timer competes with none of it. What changes for a
client: nothing (the same ports, the same answers, the same image).

* :class:`AttachedImage`: the :class:`~hli_server.adapters.host.ImagePort` of a process that attached the
  image by name (the same format code as the server's own image and as a PLC's ``ImageClient``);
* :class:`DoorsHost`: the host of the doors (that image, the remote operator, the mirrored events, the
  remote stepped clock, ``on_cycle`` driven by watching the image's publish counter);
* :func:`doors_main`: the child process (spawned, so it shares nothing with the parent but the image and
  the socket), at a lower priority than the clock's (``DOORS_NICE``) and with a longer time slice
  (``pacing.DOORS_SLICE_NS``);
* :class:`DoorsProcess`: the parent's handle, an adapter of the runtime whose endpoints are the child's.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import gc
import logging
import multiprocessing
import operator
import os
import signal
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Any, Final, Protocol, cast

from hli_server.adapters.faults import CommFaults
from hli_server.adapters.host import (
    AccessPolicy,
    AdapterHost,
    CheckPort,
    EventFeed,
    ImagePort,
    OperatorPort,
    Readiness,
    RecorderPort,
    Trace,
    Value,
    door_host,
)
from hli_server.adapters.registry import Adapter, create_adapter
from hli_server.runtime.checks import ProgramChecker
from hli_server.runtime.event_loop import lean_event_loop
from hli_server.runtime.pacing import DOORS_SLICE_NS, ask_for_time_slice
from hli_server.runtime.remote import (
    EngineSide,
    EventMirror,
    OperatorService,
    RemoteFaults,
    RemoteLink,
    RemoteOperator,
    RemoteRecorder,
)
from schemas import image_format as fmt
from schemas.layout import Direction, Layout, Signal

if TYPE_CHECKING:
    from schemas.config import MachineConfig

__all__ = [
    "DOORS_NICE",
    "AttachedImage",
    "DoorsHost",
    "DoorsPlan",
    "DoorsProcess",
    "DoorsRuntime",
    "doors_main",
]

logger = logging.getLogger(__name__)

START_TIMEOUT_S = 30.0
"""How long the parent waits for the doors process to report its ports."""
DOORS_NICE = 5
"""The doors process runs this much nicer than the clock's: where both want the CPU, the cycle wins."""


_PUBLISH_COUNT_WORD: Final = fmt.OFF_PUBLISH_COUNT // 8
_CYCLE_WORD: Final = fmt.OFF_CYCLE // 8
_HEADER_WORDS: Final = max(_PUBLISH_COUNT_WORD, _CYCLE_WORD) + 1


class AttachedImage(ImagePort):
    """The image of another process, attached by name (``schemas.image_format``, the format code the
    server's own image and a PLC's ``ImageClient`` share): reads of consistent publishes, PLC writes."""

    def __init__(self, segment: fmt.AttachedSegment) -> None:
        self._segment = segment
        self._buf = segment.buf
        self._plan = segment.header.plan
        self._layout = segment.layout
        self._name = segment.name
        self._closed = False
        self._words = segment.buf[: _HEADER_WORDS * 8].cast("Q")
        """The header's first 64-bit words: the publish counter and the cycle, one aligned load each (a door
        asks the publish counter at every read, to know whether its copy of the half is still the newest)"""

    @classmethod
    def attach(cls, name: str, *, timeout: float = 0.0) -> AttachedImage:
        return cls(fmt.attach_segment(name, timeout=timeout))

    @property
    def name(self) -> str:
        return self._name

    @property
    def layout(self) -> Layout:
        return self._layout

    @property
    def cycle(self) -> int:
        value: int = self._words[_CYCLE_WORD]
        return value

    @property
    def publish_count(self) -> int:
        value: int = self._words[_PUBLISH_COUNT_WORD]
        return value

    def publish_counter(self) -> Callable[[], int]:
        counter = functools.partial(operator.getitem, self._words, _PUBLISH_COUNT_WORD)
        return cast("Callable[[], int]", counter)

    @property
    def closed(self) -> bool:
        """True once the server closed the image (it is then unlinked; the mapping stays valid), or this
        process detached it (:meth:`close`: the mapping is gone)."""
        if self._closed:
            return True
        flags: int = fmt.HEADER.unpack_from(self._buf, 0)[13]
        return bool(flags & fmt.FLAG_CLOSED)

    def read(self, st_path: str) -> Value:
        signal = self._layout.signal(st_path)
        if signal.plc_writable:
            return fmt.read_field(self._buf, self._plan.p2c_offset, signal)
        return fmt.read_c2p_field(self._buf, self._plan, signal, self._name)

    def write(self, st_path: str, value: object) -> None:
        self.write_signal(self._layout.signal(st_path), value)

    def write_signal(self, signal: Signal, value: object) -> None:
        signal.check_plc_write()
        fmt.write_field(self._buf, self._plan.p2c_offset, signal, signal.coerce(value))

    def write_bytes(self, offset: int, data: bytes) -> None:
        fmt.write_p2c_bytes(self._buf, self._plan, self._layout, offset, data)

    def read_half(self, direction: Direction) -> bytes:
        if direction is Direction.CNC_TO_PLC:
            return fmt.read_c2p(self._buf, self._plan, self._name)[1]
        off = self._plan.p2c_offset
        return bytes(self._buf[off : off + self._plan.p2c_size])

    def snapshot(self) -> tuple[int, bytes]:
        return fmt.read_c2p(self._buf, self._plan, self._name)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._words.release()  # the mapping cannot close while a view of it is held
            self._segment.close()


class DoorsHost(AdapterHost):
    """The host of the doors process: the attached image, the engine's operator panel, events and stepped
    clock over the link (``runtime/remote.py``). ``on_cycle`` listeners are called when the image's publish
    counter moves (it is watched every quarter cycle); several publishes between two looks are one call
    with the newest cycle."""

    def __init__(
        self,
        image: AttachedImage,
        link: RemoteLink,
        events: EventMirror,
        *,
        t_a_us: int,
        clock: str,
        bind: str,
        policy: AccessPolicy,
        checker: ProgramChecker,
    ):
        self._checker = checker
        self._image = image
        self._link = link
        self._operator = RemoteOperator(link, image, t_a_us)
        self._events = events
        self._clock = clock
        self._bind = bind
        self._policy = policy
        self._listeners: list[Callable[[int], None]] = []
        self._watch: asyncio.Task[None] | None = None
        self._t_a_s = t_a_us * 1e-6
        self._faults = RemoteFaults(link, lambda: image.cycle)
        """A mirror of the server's communication faults (the engine's process owns them,
        docs/record-replay.md)."""
        self._recorder = RemoteRecorder(link)

    @property
    def image(self) -> ImagePort:
        return self._image

    @property
    def operator(self) -> OperatorPort:
        return self._operator

    @property
    def events(self) -> EventFeed:
        return self._events

    @property
    def clock(self) -> str:
        return self._clock

    @property
    def bind(self) -> str:
        return self._bind

    @property
    def policy(self) -> AccessPolicy:
        return self._policy

    @property
    def recorder(self) -> RecorderPort:
        return self._recorder

    @property
    def faults(self) -> CommFaults:
        return self._faults

    async def step(self, cycles: int = 1) -> int:
        return await self._operator.step(cycles)

    async def step_traced(self, cycles: int, signals: Sequence[str]) -> Trace:
        return await self._operator.step_traced(cycles, signals)

    async def restart(self) -> int:
        cycle: int = await self._link.call_async("restart")
        return cycle

    def on_cycle(self, listener: Callable[[int], None]) -> Callable[[], None]:
        self._listeners.append(listener)
        if self._watch is None:
            self._watch = asyncio.get_running_loop().create_task(
                self._watch_publishes(), name="hli-doors-watch"
            )

        def unsubscribe() -> None:
            with contextlib.suppress(ValueError):
                self._listeners.remove(listener)

        return unsubscribe

    async def _watch_publishes(self) -> None:
        seen = self._image.publish_count
        while True:
            await asyncio.sleep(self._t_a_s / 4)
            count = self._image.publish_count
            if count == seen:
                continue
            seen = count
            cycle = self._image.cycle
            for listener in list(self._listeners):
                try:
                    listener(cycle)
                except Exception:
                    logger.exception("cycle listener %r failed at cycle %d", listener, cycle)

    def readiness(self) -> Readiness:
        """The server's readiness, the engine's process' to say (it knows the clock, and these doors once
        this process reported them listening)."""
        readiness: Readiness = self._link.call("readiness")
        return readiness

    @property
    def checker(self) -> CheckPort:
        """Checks run here, in a worker of the doors process: the engine's process never sees them."""
        return self._checker

    async def close(self) -> None:
        await self._checker.close()
        if self._watch is not None:
            self._watch.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._watch


@dataclass(frozen=True)
class DoorsPlan:
    """What the doors process is told at its start (pickled to it)."""

    image_name: str
    specs: list[tuple[str, dict[str, Any]]]
    bind: str
    policy: AccessPolicy
    t_a_us: int
    clock: str
    config: MachineConfig | None = None
    """The machine file's configuration, for the checks of ``POST /api/check`` (a fresh machine each)."""
    program_dirs: tuple[str, ...] = ()
    """Where the checks find subprograms after the files sent with the program (the server's directories)."""
    nice: int = 0
    """How much nicer than the clock's process the doors run (:data:`DOORS_NICE` unless the clock runs at
    the realtime priority, which goes first anyway: then the doors need not give way to other work)."""


def doors_main(plan: DoorsPlan, link: socket.socket, conn: Connection) -> None:
    """The doors process: attach the image, start the adapters, report their ports, serve until the
    parent says stop, goes away, or closes the image, or SIGTERM. SIGINT is ignored (the parent spawns
    it so, and it stays so): a Ctrl+C reaches the whole process group, and the parent stops the doors."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if plan.nice:
        with contextlib.suppress(OSError):  # the clock's process wins the CPU from its doors
            # (docs/runtime.md)
            os.nice(plan.nice)
    # a turn of the doors (a request read, answered, its reply written) seldom preempted by the client the
    # reply wakes (docs/runtime.md); after the nice value, which the request keeps
    granted = ask_for_time_slice(DOORS_SLICE_NS)
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s doors %(name)s: %(message)s")
    # asyncio's own loop (its turn as Python 3.13 has it: event_loop.py): the doors need no timer finer than
    # a millisecond, and its one epoll_wait a turn costs less than the precise loop's select-then-epoll
    # (Modbus: about a fifth less CPU per request)
    with asyncio.Runner(loop_factory=lean_event_loop) as runner:
        runner.run(_serve_doors(plan, link, conn, granted))


async def _serve_doors(plan: DoorsPlan, sock: socket.socket, conn: Connection, granted: list[str]) -> None:
    loop = asyncio.get_running_loop()
    terminated = asyncio.Event()
    handled = False
    with contextlib.suppress(NotImplementedError, RuntimeError):
        loop.add_signal_handler(signal.SIGTERM, terminated.set)
        handled = True
    try:
        await _serve_doors_until(plan, sock, conn, terminated, granted)
    finally:
        # before the loop closes: asyncio's close shuts the signal wake-up pipe first and removes the
        # handler after, so a SIGTERM from the clock's process in between printed "Exception ignored
        # ... signal wakeup fd ... Bad file descriptor" (seen when a door cannot listen and the clock's
        # process stops this one); from here on SIGTERM just ends the process
        if handled:
            loop.remove_signal_handler(signal.SIGTERM)


async def _serve_doors_until(
    plan: DoorsPlan,
    sock: socket.socket,
    conn: Connection,
    terminated: asyncio.Event,
    granted: list[str],
) -> None:
    parent = os.getppid()
    loop = asyncio.get_running_loop()
    try:
        image = AttachedImage.attach(plan.image_name, timeout=5.0)
    except Exception as exc:
        _tell(conn, ("error", f"the doors process cannot attach the image {plan.image_name!r}: {exc}"))
        return
    events = EventMirror()
    events.start(loop)
    link = RemoteLink(sock, events.take)
    policy = plan.policy
    if plan.config is None:
        raise ValueError("the doors plan has no machine configuration")
    checker = ProgramChecker(plan.config, plan.program_dirs)
    host = DoorsHost(
        image,
        link,
        events,
        t_a_us=plan.t_a_us,
        clock=plan.clock,
        bind=plan.bind,
        policy=policy,
        checker=checker,
    )
    link.start(loop)  # the host's fault mirror takes the engine's table from the first message on
    started: list[Adapter] = []
    try:
        for name, options in plan.specs:
            adapter = create_adapter(name, bind=plan.bind, options=options)
            try:
                await adapter.start(door_host(host, name))
            except Exception as exc:  # a port in use, ...: the parent says it (no traceback of ours)
                _tell(conn, ("error", str(exc)))
                return
            started.append(adapter)
        await _first_connections(started)
        # the parent may have gone while the doors started (stopped during its start-up): then stop too
        doors = [(a.name, getattr(a, "port", None), a.endpoints(), _url(a)) for a in started]
        if _tell(conn, ("ready", (doors, granted))):
            # what was built to serve lives as long as the process: out of the collector's full passes
            gc.collect()
            gc.freeze()
            await _until_stopped(
                conn, terminated, lambda: os.getppid() != parent or image.closed or link.closed
            )
    except Exception as exc:
        _tell(conn, ("error", f"the doors process failed: {exc}"))
        raise
    finally:
        for adapter in reversed(started):
            with contextlib.suppress(Exception):
                await adapter.stop()
        await host.close()
        link.close()
        image.close()


#: how often the doors process looks whether its parent, the image or the link went away without a word
#: (the parent's word, and its end of the pipe closing when it dies, wake the process at once)
WATCH_S: Final = 1.0


async def _until_stopped(conn: Connection, terminated: asyncio.Event, gone: Callable[[], bool]) -> None:
    """Serve until the parent says stop or goes away (its word or the end of its pipe makes ``conn``
    readable: the loop watches it, no thread polls it), SIGTERM (``terminated``), or ``gone()``.

    No thread, and one wake-up every :data:`WATCH_S`: the thread that polled the pipe five times a second
    (and woke the serving loop each time) was half the CPU of an idle doors process (docs/performance.md)."""
    loop = asyncio.get_running_loop()
    fd = conn.fileno()
    loop.add_reader(fd, terminated.set)  # what the parent says is "stop"; nothing else comes this way
    try:
        while not terminated.is_set() and not gone():
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(terminated.wait(), WATCH_S)
    finally:
        loop.remove_reader(fd)


def _url(adapter: Adapter) -> str | None:
    try:
        url = getattr(adapter, "url", None)
    except RuntimeError:
        return None
    return url if isinstance(url, str) else None


#: how long the doors process waits for a client door's first connection (the MQTT broker) before it
#: reports ready: the banner then says "connected" as it did in the clock's process; an absent broker
#: costs the start this much once and is retried in the background
FIRST_CONNECT_S: Final = 1.0


async def _first_connections(started: list[Adapter]) -> None:
    waits = [w(FIRST_CONNECT_S) for a in started if callable(w := getattr(a, "wait_connected", None))]
    if waits:
        await asyncio.gather(*waits, return_exceptions=True)  # a time-out only means "not yet"


def _tell(conn: Connection, message: tuple[str, object]) -> bool:
    """Send ``message`` to the parent; False when the parent has gone (a broken pipe is no error here)."""
    try:
        conn.send(message)
    except (OSError, EOFError):
        return False
    return True


class DoorsRuntime(EngineSide, Protocol):
    """What :class:`DoorsProcess` needs of the runtime that starts it (:class:`~hli_server.runtime.Runtime`
    is one; a protocol, so that this module does not import the runtime that builds on it)."""

    @property
    def bind(self) -> str: ...

    @property
    def policy(self) -> AccessPolicy: ...

    @property
    def config(self) -> MachineConfig: ...

    @property
    def clock(self) -> object: ...

    @property
    def priority_granted(self) -> str: ...

    @property
    def checker(self) -> ProgramChecker: ...

    def add_service(self, service: OperatorService) -> Callable[[], None]: ...


class DoorsProcess:
    """The parent's side: an adapter of the runtime that runs the network doors in a child process and
    serves them the engine's operator panel, events and stepped clock between cycles
    (:class:`~hli_server.runtime.remote.OperatorService`)."""

    name = "doors-process"

    def __init__(self, specs: list[tuple[str, dict[str, Any]]], *, runtime: DoorsRuntime) -> None:
        self.specs = specs
        self.runtime = runtime
        self.doors: dict[str, tuple[int | None, list[str], str | None]] = {}
        self.granted: list[str] = []
        """What the operating system granted the doors process, in words
        (:func:`~hli_server.runtime.pacing.ask_for_time_slice`); empty where it has no such request."""
        self._process: multiprocessing.process.BaseProcess | None = None
        self._conn: Connection | None = None
        self._service: OperatorService | None = None
        self._remove_service: Callable[[], None] | None = None

    @property
    def pid(self) -> int | None:
        return self._process.pid if self._process is not None else None

    def endpoints(self) -> list[str]:
        pid = self.pid if self.pid is not None else "-"
        return [
            f"{line}  [doors process, pid {pid}]" for _, lines, _ in self.doors.values() for line in lines
        ]

    def port(self, name: str) -> int | None:
        return self.doors[name][0]

    def door_url(self, name: str) -> str | None:
        """The base URL of door ``name`` (the HTTP control API), None if it does not run here."""
        door = self.doors.get(name)
        return door[2] if door is not None else None

    async def start(self, host: AdapterHost) -> None:
        rt = self.runtime
        ctx = multiprocessing.get_context("spawn")
        parent_conn, child_conn = ctx.Pipe()
        self._conn = parent_conn
        ours, theirs = socket.socketpair()
        loop = asyncio.get_running_loop()
        _, service = await loop.connect_accepted_socket(lambda: OperatorService(rt), ours)
        self._service = service
        self._remove_service = rt.add_service(service)
        plan = DoorsPlan(
            image_name=host.image.name,
            specs=self.specs,
            bind=rt.bind,
            policy=rt.policy,
            t_a_us=rt.config.cycle_time_us,
            clock=str(rt.clock),
            config=rt.config,
            program_dirs=rt.checker.directories,
            nice=0 if rt.priority_granted.startswith("realtime") else DOORS_NICE,
        )
        self._process = ctx.Process(
            target=doors_main, args=(plan, theirs, child_conn), name="hli-doors", daemon=True
        )
        # the child starts with SIGINT ignored (inherited through exec): a Ctrl+C while it imports would
        # otherwise print its traceback; the parent stops it
        in_main = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if in_main else None
        try:
            self._process.start()
        finally:
            if previous is not None:
                signal.signal(signal.SIGINT, previous)
        child_conn.close()
        theirs.close()
        began = time.monotonic()
        while not await loop.run_in_executor(None, parent_conn.poll, 0.2):
            if not self._process.is_alive():
                raise RuntimeError("the doors process ended during start-up (see its log above)")
            if time.monotonic() - began > START_TIMEOUT_S:
                raise RuntimeError(
                    f"the doors process did not report its ports within {START_TIMEOUT_S:.0f} s"
                )
        kind, payload = parent_conn.recv()
        if kind != "ready":
            raise RuntimeError(str(payload))
        doors, self.granted = payload
        self.doors = {name: (port, lines, url) for name, port, lines, url in doors}

    async def stop(self) -> None:
        process, conn = self._process, self._conn
        self._process = self._conn = None
        if conn is not None:
            with contextlib.suppress(OSError, EOFError, BrokenPipeError):
                conn.send(("stop", None))
        if process is not None:
            loop = asyncio.get_running_loop()
            await loop.run_in_executor(None, process.join, 10.0)
            if process.is_alive():
                process.terminate()
                await loop.run_in_executor(None, process.join, 5.0)
        if conn is not None:
            conn.close()
        if self._remove_service is not None:
            self._remove_service()
            self._remove_service = None
        if self._service is not None:
            self._service.close()
            self._service = None
