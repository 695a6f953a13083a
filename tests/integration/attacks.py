"""Slow clients and large reads against a running ``hli-server run`` (issue 27), for the regression tests and
the soak (``tests/integration/test_slow_clients.py``). Loopback only; every attack is bounded in count and
stops when its ``stop`` event is set.

The clock is judged by what the server itself says (``GET /api/timing``): cycles dropped, and the parts of
the five worst cycles' lateness that the clock's own event loop spent on anything but cycles (``loop``,
``service``; ``runtime/pacing.py``). Time the operating system did not give the process (``os``,
``preempted``) is the shared machine's, not the door's; the servers of these tests run with a catch-up large
enough that such a stall is caught up rather than dropped, so that a dropped cycle means the server's fault.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
import subprocess
import time
from collections.abc import Iterator
from typing import Any

import httpx

from plc_clients.shm import ImageClient
from tests.integration.servers import door_port, read_banner, start_server, stop_server

__all__ = [
    "LOOP_BOUND_US",
    "Server",
    "clock_since",
    "event_log_reader",
    "fill_event_log",
    "modbus_poller",
    "modbus_trickler",
    "server",
    "stalled_posts",
    "unread_streams",
]

LOOP_BOUND_US = 5_000.0
"""The most the clock's loop may have spent on other work than cycles in any of the five worst cycles."""
CATCH_UP = "2000"
"""``--max-catch-up`` of these servers: a stall of the shared machine (seconds at worst) is caught up."""


class Server:
    """A running ``hli-server run`` and where its doors are."""

    def __init__(self, proc: subprocess.Popen[str], banner: dict[str, str]) -> None:
        self.proc = proc
        self.banner = banner
        self.url = banner["url"]
        self.host, port = self.url.removeprefix("http://").rsplit(":", 1)
        self.http_port = int(port)
        self.modbus_port = door_port(banner["Modbus TCP"]) if "Modbus TCP" in banner else None
        self.image = banner["image"]

    def timing(self) -> dict[str, Any]:
        answer: dict[str, Any] = httpx.get(self.url + "/api/timing", timeout=30).json()
        return answer


@contextlib.contextmanager
def server(*args: str) -> Iterator[Server]:
    """``hli-server run`` (realtime clock unless ``args`` say otherwise, the doors process, free ports)."""
    proc = start_server("--http-port", "0", "--modbus-port", "0", "--max-catch-up", CATCH_UP, *args)
    try:
        yield Server(proc, read_banner(proc, timeout=60))
    finally:
        stop_server(proc)


def clock_since(before: dict[str, Any], after: dict[str, Any]) -> dict[str, Any]:
    """What happened to the clock between two ``/api/timing`` answers: cycles, dropped, the worst loop
    and service parts of those of the five worst cycles of the run that came after ``before``, the late
    cycles' causes (of the run)."""
    worst = [w for w in after["worst"] if w["at_s"] >= before["wall_s"]]
    worst_loop = max(
        (w["parts_us"].get("loop", 0.0) + w["parts_us"].get("service", 0.0) for w in worst),
        default=0.0,
    )
    return {
        "cycles": after["cycles"] - before["cycles"],
        "dropped": after["slipped_cycles"] - before["slipped_cycles"],
        "failed": after["failed_cycles"] - before["failed_cycles"],
        "worst_loop_us": worst_loop,
        "lateness_us": after["lateness_us"],
        "late_causes": after["late_causes"],
        "worst": worst,
    }


def fill_event_log(image: str, url: str, wanted: int = 10_000, headers: dict[str, str] | None = None) -> int:
    """A PLC on the shared memory toggles both channels' override and feedhold (four events a cycle) until
    the event log holds ``wanted`` events; returns the newest sequence number."""

    def latest() -> int:
        r = httpx.get(url + "/api/events?since=0&limit=1", headers=headers or {}, timeout=30)
        return int(r.json()["latest"])

    with ImageClient.attach(image, timeout=5.0) as plc:
        for ch in (0, 1):
            plc.write(f"gpCh[{ch}]^bahn_mc_control.override.enable_w", True)
            plc.write(f"gpCh[{ch}]^bahn_mc_control.feedhold.enable_w", True)
        flip = False
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and latest() < wanted:
            for _ in range(250):
                flip = not flip
                for ch in (0, 1):
                    plc.write(f"gpCh[{ch}]^bahn_mc_control.override.command_w", 600 if flip else 500)
                    plc.write(f"gpCh[{ch}]^bahn_mc_control.feedhold.command_w", flip)
                time.sleep(0.0011)
        for ch in (0, 1):
            plc.write(f"gpCh[{ch}]^bahn_mc_control.feedhold.command_w", False)
    return latest()


async def _request(host: str, port: int, raw: bytes, timeout: float = 30.0) -> tuple[int, bytes]:
    reader, writer = await asyncio.open_connection(host, port)
    try:
        writer.write(raw)
        data = await asyncio.wait_for(reader.read(), timeout)
    finally:
        writer.close()
    head, _, body = data.partition(b"\r\n\r\n")
    return (int(head.split()[1]) if head else 0), body


async def event_log_reader(srv: Server, stop: asyncio.Event, got: list[int]) -> None:
    """Reads the whole event log (``limit=10000``) back to back; ``got``: [answers, bytes]."""
    raw = f"GET /api/events?since=0&limit=10000 HTTP/1.1\r\nhost: {srv.host}\r\nconnection: close\r\n\r\n"
    while not stop.is_set():
        status, body = await _request(srv.host, srv.http_port, raw.encode())
        if status == 200:
            got[0] += 1
            got[1] += len(body)


async def stalled_posts(srv: Server, count: int, stop: asyncio.Event, closed: list[int]) -> None:
    """``count`` connections that send a POST head announcing a body and never send it; ``closed``
    counts those the server ended (408 or dropped)."""

    async def one() -> None:
        reader, writer = await asyncio.open_connection(srv.host, srv.http_port)
        writer.write(
            b"POST /api/channels/1/program HTTP/1.1\r\nhost: %s\r\ncontent-type: text/plain\r\n"
            b"content-length: 4096\r\n\r\nN10" % srv.host.encode()
        )
        try:
            while not stop.is_set():
                with contextlib.suppress(TimeoutError):
                    if not await asyncio.wait_for(reader.read(65536), 0.2):
                        closed[0] += 1
                        return
        except ConnectionError:
            closed[0] += 1
        finally:
            writer.transport.abort()

    await asyncio.gather(*(one() for _ in range(count)), return_exceptions=True)


async def unread_streams(srv: Server, count: int, stop: asyncio.Event) -> None:
    """``count`` dashboard streams (``/api/live``) whose clients never read (tiny receive buffers, so that
    the server's side fills at once)."""

    async def one() -> None:
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.setblocking(False)
        loop = asyncio.get_running_loop()
        try:
            await loop.sock_connect(sock, (srv.host, srv.http_port))
            await loop.sock_sendall(sock, b"GET /api/live HTTP/1.1\r\nhost: %s\r\n\r\n" % srv.host.encode())
            await stop.wait()
        finally:
            sock.close()

    await asyncio.gather(*(one() for _ in range(count)), return_exceptions=True)


def _read_request(tid: int) -> bytes:
    return struct.pack(">HHHBBHH", tid & 0xFFFF, 0, 6, 1, 4, 2000, 20)


async def modbus_poller(srv: Server, period: float, stop: asyncio.Event, answers: list[int]) -> None:
    """An honest PLC: 20 input registers every ``period`` s, one request in flight; reconnects when the
    server closed it. ``answers``: [answered, connections opened]."""
    assert srv.modbus_port is not None
    tid = 0
    while not stop.is_set():
        try:
            reader, writer = await asyncio.open_connection(srv.host, srv.modbus_port)
        except OSError:
            await asyncio.sleep(period)
            continue
        answers[1] += 1
        try:
            while not stop.is_set():
                tid += 1
                writer.write(_read_request(tid))
                head = await asyncio.wait_for(reader.readexactly(7), 5)
                await reader.readexactly(struct.unpack(">H", head[4:6])[0] - 1)
                answers[0] += 1
                await asyncio.sleep(period)
        except (ConnectionError, asyncio.IncompleteReadError, TimeoutError):
            pass
        finally:
            writer.transport.abort()


async def modbus_trickler(
    srv: Server, count: int, every: float, stop: asyncio.Event, closed: list[int]
) -> None:
    """``count`` connections sending a Modbus request one byte every ``every`` seconds; ``closed``
    counts those the server ended."""
    assert srv.modbus_port is not None
    frame = _read_request(7)

    async def one() -> None:
        try:
            reader, writer = await asyncio.open_connection(srv.host, srv.modbus_port)
        except OSError:
            return
        try:
            k = 0
            while not stop.is_set():
                writer.write(frame[k % len(frame) : k % len(frame) + 1])
                k += 1
                with contextlib.suppress(TimeoutError):
                    if not await asyncio.wait_for(reader.read(1024), every):
                        closed[0] += 1
                        return
        except ConnectionError:
            closed[0] += 1
        finally:
            writer.transport.abort()

    await asyncio.gather(*(one() for _ in range(count)), return_exceptions=True)
