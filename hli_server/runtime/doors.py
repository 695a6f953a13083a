"""The PLC's network doors in a process of their own (``hli-server run --doors-process``, issue 12).

The Modbus and ADS doors serve the process image and nothing else (their adapter kinds say
``image_only``). The image lives in shared memory, so they can serve it from another process than the
one that steps the engine: then the work of 200 polling PLCs and a flooding client runs on another core
and in another interpreter, and the cycle's timer competes with none of it. What changes for a client:
nothing (the same ports, the same answers, the same image). What the doors process cannot do: the
operator panel and the event feed belong to the engine's process (the HTTP API and MQTT stay there).

* :class:`AttachedImage`: the :class:`~hli_server.adapters.host.ImagePort` of a process that attached the
  image by name (the same format code as the server's own image and as a PLC's ``ImageClient``);
* :class:`DoorsHost`: the host of the doors (image, a small operator that knows the cycle and T_A, no
  events, ``on_cycle`` driven by watching the image's publish counter);
* :func:`doors_main`: the child process (spawned, so it shares nothing with the parent but the image);
* :class:`DoorsProcess`: the parent's handle, an adapter of the runtime whose endpoints are the child's.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict
from multiprocessing.connection import Connection
from typing import Any, cast

from hli_server.adapters.faults import CommFaults
from hli_server.adapters.host import (
    AccessPolicy,
    AdapterHost,
    ConflictError,
    EventFeed,
    ImagePort,
    LoggedEvent,
    OperatorPort,
    RecorderPort,
    StepRefusedError,
    Trace,
    Value,
)
from hli_server.adapters.registry import Adapter, create_adapter
from plc_clients.shm import ImageClient
from schemas import image_format as fmt
from schemas.events import Event
from schemas.layout import Direction, Layout, Signal

__all__ = ["AttachedImage", "DoorsHost", "DoorsProcess", "doors_main"]

logger = logging.getLogger(__name__)

START_TIMEOUT_S = 30.0
"""How long the parent waits for the doors process to report its ports."""


class AttachedImage(ImagePort):
    """The image of another process, attached by name: reads of consistent publishes, PLC writes."""

    def __init__(self, client: ImageClient) -> None:
        self._client = client
        self._buf = client._buf
        self._plan = client.plan

    @property
    def name(self) -> str:
        return self._client.name

    @property
    def layout(self) -> Layout:
        return self._client.layout

    @property
    def cycle(self) -> int:
        return self._client.cycle

    @property
    def publish_count(self) -> int:
        return self._client.publish_count

    @property
    def closed(self) -> bool:
        return self._client.server_closed

    def read(self, st_path: str) -> Value:
        value: Value = self._client.read(st_path)
        return value

    def write(self, st_path: str, value: object) -> None:
        self._client.write(st_path, value)

    def write_signal(self, signal: Signal, value: object) -> None:
        signal.check_plc_write()
        fmt.write_field(self._buf, self._plan.p2c_offset, signal, signal.coerce(value))

    def write_bytes(self, offset: int, data: bytes) -> None:
        fmt.write_p2c_bytes(self._buf, self._plan, self.layout, offset, data)

    def read_half(self, direction: Direction) -> bytes:
        return self._client.raw(direction)

    def snapshot(self) -> tuple[int, bytes]:
        return fmt.read_c2p(self._buf, self._plan, self.name)

    def close(self) -> None:
        self._client.close()


class _DoorsOperator:
    """What the doors need of the operator: the cycle and T_A. Everything else is the engine's (it raises
    :class:`ConflictError`), which is why :attr:`DoorsHost.operator` casts it to the port."""

    def __init__(self, image: AttachedImage, t_a_us: int, machine_name: str) -> None:
        self._image = image
        self._t_a_us = t_a_us
        self._name = machine_name

    @property
    def cycle(self) -> int:
        return self._image.cycle

    @property
    def time_s(self) -> float:
        return self._image.cycle * self._t_a_us * 1e-6

    @property
    def t_a_us(self) -> int:
        return self._t_a_us

    @property
    def machine_name(self) -> str:
        return self._name

    def __getattr__(self, name: str) -> Any:
        raise ConflictError(
            f"{name}: the doors process serves the image only; use the HTTP API of the server"
        )


class _NoEvents(EventFeed):
    def subscribe(self, listener: Callable[[Event], None]) -> Callable[[], None]:
        return lambda: None

    def since(self, seq: int = 0, limit: int = 1000) -> tuple[Sequence[LoggedEvent], int]:
        return [], 0


class DoorsHost(AdapterHost):
    """The host of the doors process. ``on_cycle`` listeners are called when the image's publish
    counter moves (it is watched every quarter cycle); several publishes between two looks are one call
    with the newest cycle."""

    def __init__(self, image: AttachedImage, t_a_us: int, machine_name: str, bind: str, policy: AccessPolicy):
        self._image = image
        self._operator = _DoorsOperator(image, t_a_us, machine_name)
        self._events = _NoEvents()
        self._bind = bind
        self._policy = policy
        self._listeners: list[Callable[[int], None]] = []
        self._watch: asyncio.Task[None] | None = None
        self._t_a_s = t_a_us * 1e-6
        self._faults = CommFaults(lambda: image.cycle)
        """A mirror of the server's communication faults (sent by the parent, issue 25)."""

    @property
    def image(self) -> ImagePort:
        return self._image

    @property
    def operator(self) -> OperatorPort:
        return cast(OperatorPort, self._operator)

    @property
    def events(self) -> EventFeed:
        return self._events

    @property
    def clock(self) -> str:
        return "realtime"

    @property
    def bind(self) -> str:
        return self._bind

    @property
    def policy(self) -> AccessPolicy:
        return self._policy

    @property
    def recorder(self) -> RecorderPort:
        return cast(RecorderPort, self._operator)  # the engine's process records; this raises ConflictError

    @property
    def faults(self) -> CommFaults:
        return self._faults

    async def step(self, cycles: int = 1) -> int:
        raise StepRefusedError("the doors process does not step the clock")

    async def step_traced(self, cycles: int, signals: Sequence[str]) -> Trace:
        raise StepRefusedError("the doors process does not step the clock")

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

    async def close(self) -> None:
        if self._watch is not None:
            self._watch.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._watch


def doors_main(
    image_name: str,
    specs: list[tuple[str, dict[str, Any]]],
    bind: str,
    policy: dict[str, Any],
    t_a_us: int,
    machine_name: str,
    conn: Connection,
) -> None:
    """The doors process: attach the image, start the adapters, report their ports, serve until the
    parent says stop, goes away, or closes the image."""
    from hli_server.runtime.pacing import precise_event_loop

    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s doors %(name)s: %(message)s")
    with asyncio.Runner(loop_factory=precise_event_loop) as runner:
        runner.run(_serve_doors(image_name, specs, bind, AccessPolicy(**policy), t_a_us, machine_name, conn))


async def _serve_doors(
    image_name: str,
    specs: list[tuple[str, dict[str, Any]]],
    bind: str,
    policy: AccessPolicy,
    t_a_us: int,
    machine_name: str,
    conn: Connection,
) -> None:
    parent = os.getppid()
    try:
        image = AttachedImage(ImageClient.attach(image_name, timeout=5.0))
    except Exception as exc:
        conn.send(("error", f"the doors process cannot attach the image {image_name!r}: {exc}"))
        return
    host = DoorsHost(image, t_a_us, machine_name, bind, policy)
    started: list[Adapter] = []
    try:
        for name, options in specs:
            adapter = create_adapter(name, bind=bind, options=options)
            await adapter.start(host)
            started.append(adapter)
        conn.send(("ready", [(a.name, getattr(a, "port", None), a.endpoints()) for a in started]))

        # what ends here by count goes back to the server, which owns the faults
        def report(change: dict[str, Any]) -> None:
            if change["fault"] == "end":
                conn.send(("fault-ended", change))

        host.faults.subscribe(report)
        loop = asyncio.get_running_loop()
        while True:  # until the parent says stop, goes away, or closes the image
            if await loop.run_in_executor(None, conn.poll, 0.2):
                kind, payload = conn.recv()
                if kind != "faults":
                    break
                host.faults.load(payload)
            if os.getppid() != parent or image.closed:
                break
    except Exception as exc:
        with contextlib.suppress(Exception):
            conn.send(("error", f"the doors process failed: {exc}"))
        raise
    finally:
        for adapter in reversed(started):
            with contextlib.suppress(Exception):
                await adapter.stop()
        await host.close()
        image.close()


class DoorsProcess:
    """The parent's side: an adapter of the runtime that runs the image-only doors in a child process."""

    name = "doors-process"

    def __init__(
        self,
        specs: list[tuple[str, dict[str, Any]]],
        *,
        bind: str,
        policy: AccessPolicy,
        t_a_us: int,
        machine_name: str,
    ) -> None:
        self.specs = specs
        self.bind = bind
        self.policy = policy
        self.t_a_us = t_a_us
        self.machine_name = machine_name
        self.doors: dict[str, tuple[int | None, list[str]]] = {}
        self._process: multiprocessing.process.BaseProcess | None = None
        self._conn: Connection | None = None
        self._faults_link: Callable[[], None] | None = None
        self._reader: asyncio.Task[None] | None = None

    def endpoints(self) -> list[str]:
        pid = self._process.pid if self._process is not None else "-"
        return [f"{line}  [doors process, pid {pid}]" for _, lines in self.doors.values() for line in lines]

    def port(self, name: str) -> int | None:
        return self.doors[name][0]

    async def start(self, host: AdapterHost) -> None:
        ctx = multiprocessing.get_context("spawn")
        parent_conn, child_conn = ctx.Pipe()
        self._conn = parent_conn
        self._process = ctx.Process(
            target=doors_main,
            args=(
                host.image.name,
                self.specs,
                self.bind,
                asdict(self.policy),
                self.t_a_us,
                self.machine_name,
                child_conn,
            ),
            name="hli-doors",
            daemon=True,
        )
        self._process.start()
        child_conn.close()
        loop = asyncio.get_running_loop()
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
        self.doors = {name: (port, lines) for name, port, lines in payload}
        self._link_faults(host.faults, parent_conn)

    def _link_faults(self, faults: CommFaults, conn: Connection) -> None:
        """The communication faults go to the doors' mirror on every change; what ends there by count
        comes back (issue 25)."""

        def send(_change: dict[str, Any]) -> None:
            with contextlib.suppress(OSError, EOFError, BrokenPipeError):
                conn.send(("faults", faults.export()))

        self._faults_link = faults.subscribe(send)
        if faults.active:
            send({})

        async def read() -> None:
            loop = asyncio.get_running_loop()
            while True:
                if not await loop.run_in_executor(None, conn.poll, 0.2):
                    continue
                try:
                    kind, change = conn.recv()
                except (OSError, EOFError):
                    return
                if kind == "fault-ended" and faults.get(change["id"]) is not None:
                    faults.end(change["id"], change.get("reason", "count"))

        self._reader = asyncio.get_running_loop().create_task(read(), name="hli-doors-faults")

    async def stop(self) -> None:
        process, conn = self._process, self._conn
        self._process = self._conn = None
        if self._faults_link is not None:
            self._faults_link()
            self._faults_link = None
        if self._reader is not None:
            self._reader.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._reader
            self._reader = None
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
