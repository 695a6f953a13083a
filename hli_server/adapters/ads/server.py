"""ADS over TCP: the asyncio server around the sans-I/O codec and the device (H-04, C3-10; issue 12).

One :class:`_Connection` (an ``asyncio.Protocol``) per client: bytes go into its
:class:`~hli_server.codecs.ads.AmsStreamDecoder`, each complete frame is answered by the
:class:`~hli_server.adapters.ads.device.AdsDevice` synchronously, and the replies of one turn go out
in one write. What a real TwinCAT router does and what this one does:

* **Router messages.** 0x1000 port connect is answered with the server's NetId and an AMS port for
  the client (the one it asked for, or a free one from 32768 on), so that clients without a router
  of their own (Node ``ads-client`` without ``localAmsNetId``) work; 0x0001 port close is answered;
  0x1002 gets the server's NetId.
* **Routes.** A client outside the allowlist (:class:`~hli_server.adapters.ads.options.RouteAllowlist`)
  is treated as a TwinCAT router treats a peer it has no route for: the TCP connection is closed
  without an answer (its IP: at once; its NetId: at its first frame). AdsLib logs "connection closed
  by remote" and the call fails; ads-client reports the closed socket. The refusal is logged here
  with the IP or NetId and the option that would admit it.
* **Replies** go to the NetId and port that sent the request, so AdsLib's several AMS ports on one
  socket each get theirs; requests are answered in the order they arrived.

Bounds (options in :class:`~hli_server.adapters.ads.options.AdsOptions`, figures in
docs/reliability.md):

* ``max_connections`` at once (512). When all are taken, a new client replaces the connection idle
  the longest if that one has been idle ``evict_idle_after_s``; else the new one is closed at once.
  A connection that sent nothing for ``idle_timeout_s`` and has no notification it reads is closed.
* ``max_requests_per_turn`` and ``max_turn_ms``: a connection's pipelined requests are served that
  many at a time, for at most that long; then the loop turns (other clients, the clock) before the
  rest. Requests waiting for their turn stay
  in the decoder's buffer, which holds at most one read of the socket plus one frame: reading is
  paused meanwhile, so a flood waits in the client's own socket buffer.
* ``max_queued_output``: the transport's high-water mark. Above it the connection is not read (no
  new requests, so no new replies) and its notifications are not evaluated until the client
  drains.
* The cycle never writes to a socket: notifications are sampled in ``host.on_cycle`` and written
  by :meth:`AdsAdapter._flush` in the next turn of the loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import TYPE_CHECKING, Any, Final

from pydantic import ValidationError

from hli_server.adapters.ads.device import AdsDevice, DeviceLimits, Session
from hli_server.adapters.ads.options import AdsOptions
from hli_server.adapters.faults import CommFaults, Door
from hli_server.adapters.tcp import Admission, ConnectionSlots, close, listen
from hli_server.codecs.ads import (
    NEED_DATA,
    AdsCodecError,
    AmsPacket,
    AmsStreamDecoder,
    AmsStreamError,
    AmsTcpCommand,
    AmsTcpFrame,
    NetId,
    encode_port_close_reply,
    encode_port_connect_reply,
    encode_router_frame,
    port_of_port_request,
)
from schemas.layout import ADS_GROUP_CNC_TO_PLC, ADS_GROUP_GEO_AXIS, ADS_GROUP_PLC_TO_CNC

if TYPE_CHECKING:
    from collections.abc import Callable

    from hli_server.adapters.host import AdapterHost, ImagePort

__all__ = ["AdsAdapter", "ServerStats"]

logger = logging.getLogger(__name__)

FIRST_CLIENT_PORT: Final = 32768
"""AMS ports handed out on 0x1000 port connect when the client asks for any (0)."""


class ServerStats:
    """Connection counters since start (the device counts requests and errors)."""

    def __init__(self) -> None:
        self.connections = 0
        self.refused_route = 0
        self.refused_full = 0
        self.evicted = 0
        self.idle_closed = 0
        self.broken_streams = 0
        self.paused_reading = 0
        self.turns = 0
        self.longest_turn_us = 0
        """the most CPU time one connection's turn took (serving its requests): how long the door can
        hold the event loop, and with it the clock, on a machine that does not preempt it"""
        self.turns_over_1ms = 0

    def as_dict(self) -> dict[str, int]:
        return dict(vars(self))

    def turn(self, seconds: float) -> None:
        self.turns += 1
        us = int(seconds * 1e6)
        self.longest_turn_us = max(self.longest_turn_us, us)
        if us > 1000:
            self.turns_over_1ms += 1


class _Connection(asyncio.Protocol):
    """One client: frames in, replies out, a fair share of each turn of the loop."""

    def __init__(self, adapter: AdsAdapter) -> None:
        self._adapter = adapter
        self._device = adapter.device
        self._options = adapter.options
        self._decoder = AmsStreamDecoder()
        self._gate = adapter.faults.gate(Door.ADS, None)
        self._transport: asyncio.Transport | None = None
        self.peer: Any = None
        self.session = Session(self._send, self._backlogged)
        self.last_activity = time.monotonic()
        self._write_paused = False
        self._read_paused = False
        self._scheduled = False
        self._eof = False
        self._client_port = 0

    # --- asyncio.Protocol ---------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        self.peer = transport.get_extra_info("peername")
        host = self.peer[0] if isinstance(self.peer, tuple) and self.peer else None
        self.session.name = f"{host}:{self.peer[1]}" if host is not None else str(self.peer)
        if not self._adapter.allowlist.allows_ip(host):
            self._adapter.stats.refused_route += 1
            logger.warning(
                "ADS: no route for %s: closing its connection as a TwinCAT router does; add the address "
                "to the allowlist (--adapter ads:allow=..., docs/ads.md) to admit it",
                host,
            )
            self._transport = None
            transport.abort()
            return
        if not self._adapter._accept(self):
            self._transport = None
            transport.abort()
            return
        limit = self._options.max_queued_output
        transport.set_write_buffer_limits(high=limit, low=limit // 2)
        self._gate = self._adapter.faults.gate(Door.ADS, transport)  # communication faults on demand
        self._transport = self._gate.transport
        self._adapter.stats.connections += 1
        logger.debug("ADS: connection from %s", self.session.name)

    def data_received(self, data: bytes) -> None:
        if self._transport is None or self._transport.is_closing():
            return
        self.last_activity = time.monotonic()
        self._decoder.receive_data(data)
        self._serve()

    def eof_received(self) -> bool | None:
        """The client sent all it will send: answer what is buffered, then close."""
        self._eof = True
        if not self._scheduled and not self._write_paused and self._transport is not None:
            self._serve()
        return True  # keep the transport open until the answers are written (closed in _serve)

    def pause_writing(self) -> None:
        self._write_paused = True
        self._pause_reading()

    def resume_writing(self) -> None:
        self._write_paused = False
        self.last_activity = time.monotonic()
        self._continue()

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None
        self._device.close_session(self.session)
        self._adapter._forget(self)

    # --- serving ------------------------------------------------------------------------------
    def _serve(self) -> None:
        """Answer up to ``max_requests_per_turn`` buffered frames; leave the rest for the next turn."""
        started = time.thread_time()  # CPU time: what the door costs, not the machine's preemptions
        try:
            self._serve_turn()
        finally:
            self._adapter.stats.turn(time.thread_time() - started)

    def _serve_turn(self) -> None:
        transport = self._transport
        if transport is None:
            return
        out: list[bytes] = []
        budget = self._options.max_requests_per_turn
        limit = self._options.max_queued_output
        deadline = time.perf_counter() + self._adapter.turn_s
        queued = transport.get_write_buffer_size()
        more = False
        broken: str | None = None
        while True:
            # queued above the limit means the transport paused us (its high-water mark is the limit)
            if budget <= 0 or queued > limit or time.perf_counter() >= deadline:
                more = True
                break
            try:
                frame = self._decoder.next_frame()
            except AmsStreamError as exc:
                broken = str(exc)
                break
            if frame is NEED_DATA:
                break
            budget -= 1
            reply = self._answer(frame)
            if reply is None:
                if self._transport is None:  # refused: the connection is gone
                    return
                continue
            out.append(reply)
            queued += len(reply)
        if out:
            transport.write(out[0] if len(out) == 1 else b"".join(out))
        if broken is not None:
            self._adapter.stats.broken_streams += 1
            logger.warning("ADS: closing the connection from %s: %s", self.session.name, broken)
            transport.close()
            return
        if more or self._write_paused:
            self._pause_reading()
            if not self._write_paused:
                self._schedule()
        elif self._eof:
            transport.close()  # everything the client sent is answered
        elif self._read_paused:
            self._read_paused = False
            transport.resume_reading()

    def _pause_reading(self) -> None:
        if not self._read_paused and self._transport is not None and not self._transport.is_closing():
            self._read_paused = True
            self._adapter.stats.paused_reading += 1
            self._transport.pause_reading()

    def _schedule(self) -> None:
        if not self._scheduled:
            self._scheduled = True
            asyncio.get_running_loop().call_soon(self._continue)

    def _continue(self) -> None:
        self._scheduled = False
        if self._transport is not None and not self._transport.is_closing():
            self._serve()

    def _answer(self, frame: AmsPacket | AmsTcpFrame) -> bytes | None:
        if isinstance(frame, AmsPacket):
            if not self._adapter.allowlist.allows_net_id(frame.header.source_net_id):
                self._adapter.stats.refused_route += 1
                logger.warning(
                    "ADS: no route for NetId %s (from %s): closing its connection as a TwinCAT router does; "
                    "add the NetId to the allowlist (docs/ads.md) to admit it",
                    frame.header.source_net_id,
                    self.session.name,
                )
                self.abort()
                return None
            faulted = self._gate.ads(frame)  # a fault's answer (adapters/faults.py), or None: serve it
            if faulted is not None:
                return faulted or None
            return self._device.handle(self.session, frame)
        return self._router_message(frame)

    def _router_message(self, frame: AmsTcpFrame) -> bytes | None:
        command = frame.command
        try:
            if command == AmsTcpCommand.PORT_CONNECT:
                wanted = port_of_port_request(frame)
                self._client_port = wanted or self._adapter.next_client_port()
                return encode_port_connect_reply(self._adapter.net_id, self._client_port)
            if command == AmsTcpCommand.PORT_CLOSE:
                return encode_port_close_reply(port_of_port_request(frame))
            if command == AmsTcpCommand.GET_LOCAL_NETID:
                return encode_router_frame(AmsTcpCommand.GET_LOCAL_NETID, bytes(self._adapter.net_id))
        except AdsCodecError as exc:
            logger.warning("ADS: closing the connection from %s: %s", self.session.name, exc)
            if self._transport is not None:
                self._transport.close()
            self._transport = None
            return None
        return None  # a router note from a client: nothing to answer

    # --- hooks of the session (notifications) -------------------------------------------------
    def _send(self, data: bytes) -> None:
        transport = self._transport
        if transport is None or transport.is_closing():
            return
        if transport.get_write_buffer_size() < self._options.max_queued_output:
            self.last_activity = time.monotonic()
        transport.write(data)

    def _backlogged(self) -> bool:
        transport = self._transport
        return (
            transport is None
            or transport.is_closing()
            or transport.get_write_buffer_size() >= self._options.max_queued_output
        )

    def idle_since(self, now: float) -> float:
        """When this client was last active. A client with notifications that reads them is
        active (AdsLib sends no keep-alives: an HMI watching a value that does not change sends and
        receives nothing for as long as it likes); one whose output is full is not."""
        if self.session.notifications and not self._backlogged():
            return now
        return self.last_activity

    def abort(self) -> None:
        transport, self._transport = self._transport, None
        if transport is not None:
            transport.abort()


class AdsAdapter:
    """ADS over TCP on ``bind:port`` for the runtime's process image (H-04, C3-10; docs/ads.md).

    Options: :class:`AdsOptions` (``--adapter ads:port=48898,ams_net_id=127.0.0.1.1.1`` or the
    ``run`` flags ``--ads-port``, ``--ams-net-id``); ``port`` 0 binds a free port (:attr:`port` tells
    which after start).
    """

    name = "ads"

    Options = AdsOptions

    def __init__(self, *, bind: str = "127.0.0.1", **options: object) -> None:
        try:
            self.options = AdsOptions.model_validate(options)
        except ValidationError as exc:
            first = exc.errors()[0]
            where = ".".join(str(p) for p in first["loc"])
            raise ValueError(f"ADS adapter: {where}: {first['msg']} (got {first.get('input')!r})") from None
        self.bind = bind
        self.net_id = NetId.parse(self.options.ams_net_id)
        self.allowlist = self.options.allowlist()
        self.requested_port = self.options.port
        self.turn_s = self.options.max_turn_ms / 1000.0
        self.port: int | None = None
        self.stats = ServerStats()
        self.device: AdsDevice
        self.faults = CommFaults()
        """The communication faults the connections consult (the host's, once started)."""
        self._listener: asyncio.Server | None = None
        self._slots: ConnectionSlots[_Connection] = ConnectionSlots(
            "ADS", self.options.max_connections, self.options.evict_idle_after_s
        )
        self._flush_pending: set[Session] = set()
        self._flush_scheduled = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._unsubscribe: Callable[[], None] | None = None
        self._idle_task: asyncio.Task[None] | None = None
        self._next_client_port = FIRST_CLIENT_PORT

    @property
    def host(self) -> str:
        return f"[{self.bind}]" if ":" in self.bind else self.bind

    @property
    def connection_count(self) -> int:
        return len(self._slots)

    def endpoints(self) -> list[str]:
        if self.port is None:
            return ["ADS (AMS/TCP): not listening"]
        return [
            f"ADS (AMS/TCP): {self.host}:{self.port}  (AMS NetId {self.net_id}; port 851 HLI symbols, "
            f"groups 0x{ADS_GROUP_PLC_TO_CNC:X}/0x{ADS_GROUP_CNC_TO_PLC:X}; port 551 CNC objects, "
            f"group 0x{ADS_GROUP_GEO_AXIS:X}; allow: {', '.join(self.options.allow) or 'everybody'})"
        ]

    def serve_image(self, image: ImagePort, t_a_us: int = 1000, *, read_only: bool = False) -> AdsDevice:
        """Bind the device to an image (done by :meth:`start`; tests may call it directly)."""
        o = self.options
        self.device = AdsDevice(
            image,
            self.net_id,
            t_a_us=t_a_us,
            limits=DeviceLimits(
                max_handles=o.max_handles,
                max_notifications=o.max_notifications,
                max_notifications_total=o.max_notifications_total,
                max_sum_items=o.max_sum_items,
            ),
            call_later=self._call_later,
            request_flush=self._request_flush,
            first_sample_delay_s=o.first_sample_delay_ms / 1000.0,
            read_only=read_only,
        )
        return self.device

    async def start(self, host: AdapterHost) -> None:
        self.faults = host.faults
        self.serve_image(host.image, host.operator.t_a_us, read_only=host.policy.read_only)
        self._unsubscribe = host.on_cycle(self.device.on_cycle)
        try:
            await self._listen()
        except BaseException:
            self._unsubscribe()
            self._unsubscribe = None
            raise

    async def start_for(self, image: ImagePort, t_a_us: int = 1000) -> None:
        """Listen for an image without a runtime (tests, tools); drive notifications with
        ``adapter.device.on_cycle(cycle)``."""
        self.serve_image(image, t_a_us)
        await self._listen()

    async def _listen(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._listener = await listen(
            lambda: _Connection(self),
            self.bind,
            self.requested_port,
            "ADS",
            "choose another --ads-port (0 = any free port) or --bind address (is a TwinCAT router on 48898?)",
        )
        self.port = self._listener.sockets[0].getsockname()[1]
        self._idle_task = self._loop.create_task(self._watch_idle(), name="hli-ads-idle")
        logger.info("ADS listening on %s:%d (AMS NetId %s)", self.bind, self.port, self.net_id)

    async def stop(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self._idle_task is not None:
            self._idle_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._idle_task
            self._idle_task = None
        listener, self._listener = self._listener, None
        await close(listener, self._slots)
        self.port = None

    # --- connections --------------------------------------------------------------------------
    def _accept(self, connection: _Connection) -> bool:
        """Admit ``connection``; at the limit the one idle longest (``evict_idle_after_s``) makes room
        (``adapters/tcp.py``)."""
        admission = self._slots.admit(connection, connection.session.name)
        if admission is Admission.REFUSED:
            self.stats.refused_full += 1
            return False
        if admission is Admission.EVICTED:
            self.stats.evicted += 1
        return True

    def _forget(self, connection: _Connection) -> None:
        self._slots.forget(connection)
        self._flush_pending.discard(connection.session)

    def next_client_port(self) -> int:
        port = self._next_client_port
        self._next_client_port = port + 1 if port < 65535 else FIRST_CLIENT_PORT
        return port

    async def _watch_idle(self) -> None:
        timeout = self.options.idle_timeout_s
        period = min(1.0, timeout / 4)
        while True:
            await asyncio.sleep(period)
            now = time.monotonic()
            for connection in [c for c in self._slots if now - c.idle_since(now) > timeout]:
                self.stats.idle_closed += 1
                logger.info(
                    "ADS: closing %s: idle for %.0f s (idle_timeout_s)", connection.session.name, timeout
                )
                self._slots.forget(connection)
                connection.abort()

    # --- notifications: sampled in the cycle, written in the next turn -------------------------
    def _call_later(self, delay: float, callback: Callable[[], None]) -> object:
        loop = self._loop or asyncio.get_running_loop()
        return loop.call_later(delay, callback)

    def _request_flush(self, session: Session) -> None:
        self._flush_pending.add(session)
        if not self._flush_scheduled:
            self._flush_scheduled = True
            loop = self._loop or asyncio.get_running_loop()
            loop.call_soon(self._flush)

    def _flush(self) -> None:
        self._flush_scheduled = False
        sessions, self._flush_pending = self._flush_pending, set()
        stats = self.device.stats
        for session in sessions:
            frames, samples = session.flush()
            stats.notifications_sent += frames
            stats.samples_sent += samples
