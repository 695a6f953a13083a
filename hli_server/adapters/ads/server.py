"""ADS over TCP: the asyncio server around the sans-I/O codec and the device (H-04, C3-10;
docs/reliability.md).

One :class:`_Connection` (an ``asyncio.Protocol``) per client: bytes go into its
:class:`~hli_server.codecs.ads.AmsStreamDecoder`, each complete frame is answered by the
:class:`~hli_server.adapters.ads.device.AdsDevice` synchronously, and the replies of one turn go out
in one write. What a real TwinCAT router does and what this one does:

* **Router messages.** 0x1000 port connect is answered with the server's NetId and an AMS port for
  the client (the one it asked for, or a free one from 32768 on), so that clients without a router
  of their own (Node ``ads-client`` without ``localAmsNetId``) work; 0x0001 port close is answered;
  0x1002 gets the server's NetId. They carry no NetId, so they are answered only where the allowlist
  restricts no NetId or admits the server's own (:meth:`Routes.answers_router_messages`): a client
  outside the allowlist learns nothing, not even the NetId (reliability.md, round 2, finding 9).
* **Routes.** A client neither the allowlist nor a route added by AddRoute admits
  (:class:`~hli_server.adapters.ads.routes.Routes`) is treated as a TwinCAT router treats a peer it has
  no route for: the TCP connection is closed without an answer (its IP: at once; its NetId: at its first
  frame, after the answers to the frames before it went out). AdsLib logs "connection closed by remote"
  and the call fails; ads-client reports the closed socket. The refusal is logged here with the IP or
  NetId and what would admit it.
* **ADS over UDP** (discovery, AddRoute) listens where the TCP door does: :mod:`.udp`.
* **Replies** go to the NetId and port that sent the request, so AdsLib's several AMS ports on one
  socket each get theirs; requests are answered in the order they arrived.

Bounds (options in :class:`~hli_server.adapters.ads.options.AdsOptions`, figures in
docs/reliability.md):

* ``max_connections`` at once (512). A full house never refuses a newcomer: it closes its least useful
  connection (reliability.md, round 2, finding 3): one that has held an incomplete frame the longest, else
  one that never completed a request (oldest first), else the one whose last complete request is oldest (a
  client that reads its notifications counts as active).
* ``frame_timeout_s``: a frame begun must be complete within this long. Only a complete frame counts
  as activity, so a client trickling a byte every second neither holds its slot nor escapes
  ``idle_timeout_s`` (a connection that completed no request for that long and has no notification it
  reads is closed).
* ``max_requests_per_turn`` and ``max_turn_ms``: a connection's pipelined requests are served that
  many at a time, for at most that long; then the loop turns (other clients, the clock) before the
  rest. Requests waiting for their turn stay
  in the decoder's buffer, which holds at most one read of the socket plus one frame: reading is
  paused meanwhile, so a flood waits in the client's own socket buffer.
* ``max_queued_output``: the transport's high-water mark. Above it the connection is not read (no
  new requests, so no new replies) and its notifications are not evaluated until the client
  drains.
* The cycle never writes to a socket: notifications are sampled in ``host.on_cycle`` and written
  by :meth:`AdsAdapter._flush` in the next turn of the loop. The door subscribes to the cycle only while
  it has notifications.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import TYPE_CHECKING, Any, Final

from pydantic import ValidationError

from hli_server.adapters.ads.device import AdsDevice
from hli_server.adapters.ads.options import AdsOptions, is_loopback
from hli_server.adapters.ads.routes import RouteError, Routes
from hli_server.adapters.ads.session import DeviceLimits, Session
from hli_server.adapters.ads.udp import UdpDoor
from hli_server.adapters.faults import CommFaults, Door
from hli_server.adapters.tcp import listen
from hli_server.codecs.ads import (
    MAX_AMS_LENGTH,
    NEED_DATA,
    AdsCodecError,
    AmsPacket,
    AmsStreamDecoder,
    AmsStreamError,
    AmsTcpCommand,
    AmsTcpFrame,
    NetId,
    OversizeAmsFrame,
    encode_port_close_reply,
    encode_port_connect_reply,
    encode_router_frame,
    port_of_port_request,
)
from schemas.layout import ADS_GROUP_CNC_TO_PLC, ADS_GROUP_GEO_AXIS, ADS_GROUP_PLC_TO_CNC

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from hli_server.adapters.host import AdapterHost, ImagePort

__all__ = ["AdsAdapter", "ServerStats"]

logger = logging.getLogger(__name__)

_monotonic: Final = time.monotonic

FIRST_CLIENT_PORT: Final = 32768
"""AMS ports handed out on 0x1000 port connect when the client asks for any (0)."""


class ServerStats:
    """Connection counters since start (the device counts requests and errors)."""

    def __init__(self) -> None:
        self.connections = 0
        self.refused_route = 0
        self.refused_router_messages = 0
        self.evicted = 0
        self.idle_closed = 0
        self.frame_timeouts = 0
        self.broken_streams = 0
        self.paused_reading = 0
        self.turns = 0
        self.longest_turn_us = 0
        """the most CPU time one connection's turn of a burst took (serving its requests; turns of one
        small request are not timed): how long the door can hold the event loop, and with it the clock,
        on a machine that does not preempt it"""
        self.turns_over_1ms = 0

    def as_dict(self) -> dict[str, int]:
        return dict(vars(self))

    def turn(self, seconds: float) -> None:
        self.turns += 1
        us = int(seconds * 1e6)
        self.longest_turn_us = max(self.longest_turn_us, us)
        if us > 1000:
            self.turns_over_1ms += 1


_TIMED_TURN_BYTES: Final = 256
"""Turns that start with at least this many bytes buffered (a pipelined burst, a large write) have their
CPU time measured (``longest_turn_us``); a turn of one small request costs less than the two
``thread_time`` calls would (about 3 us each on a loaded machine)."""


class _Refused:
    """The type of :data:`_REFUSED`."""


_REFUSED: Final = _Refused()
"""What :meth:`_Connection._answer` returns for a frame whose sender has no route: close after the
answers before it."""


_FAST_MAX: Final = 6 + MAX_AMS_LENGTH
MAX_SKIPPED_FRAME: Final = 16 * 1024 * 1024
"""An AMS frame above the decoder's 64 KiB (a sum write of 500 items of 200 bytes: 100 KB) but within this
is answered 0x705 and its bytes dropped as they arrive; beyond, its connection is closed (issue 36,
finding 9: such a frame closed the connection without an ADS error code)."""
"""The longest read :meth:`_Connection.data_received` answers on its fast path (one whole AMS frame)."""


class _Connection(asyncio.Protocol):
    """One client: frames in, replies out, a fair share of each turn of the loop."""

    def __init__(self, adapter: AdsAdapter) -> None:
        self._adapter = adapter
        self._device = adapter.device
        self._options = adapter.options
        self._routes = adapter.routes
        self._decoder = AmsStreamDecoder(max_skipped_length=MAX_SKIPPED_FRAME)
        self._gate = adapter.faults.gate(Door.ADS, None)
        self._transport: asyncio.Transport | None = None
        self._raw: asyncio.Transport | None = None
        """the socket's own transport, for the replies of :meth:`data_received`'s fast path (no fault acts)"""
        self.peer: Any = None
        self.host: str | None = None
        self.session = Session(self._send, self._backlogged)
        now = time.monotonic()
        self.connected_at = now
        self.last_activity = now
        """when the client last completed a request (or read what it was sent)"""
        self.frames = 0
        self.partial_since: float | None = None
        """since when an incomplete frame waits for its rest (None: none)"""
        self._write_paused = False
        self._read_paused = False
        self._scheduled = False
        self._eof = False
        self._client_port = 0
        self._admitted: bytes | None = None
        self._stats = adapter.stats
        self._fast = False
        """What :meth:`data_received`'s fast path needs of the connection's state, in one flag (kept by
        :meth:`_refresh_fast` wherever that state changes): a transport, the admitted NetId, reading not
        paused, no turn scheduled, nothing buffered in the decoder (so no frame begun)"""

    # --- asyncio.Protocol ---------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        self.peer = transport.get_extra_info("peername")
        host = self.peer[0] if isinstance(self.peer, tuple) and self.peer else None
        self.host = host
        self.session.name = f"{host}:{self.peer[1]}" if host is not None else str(self.peer)
        self.session.remote_host = None if host is None or is_loopback(host) else host
        if not self._routes.admits_ip(host):
            self._adapter.stats.refused_route += 1
            logger.warning(
                "ADS: no route for %s: closing its connection as a TwinCAT router does; add the address "
                "to the allowlist (--adapter ads:allow=...) or add a route (AddRoute, docs/ads.md) to "
                "admit it",
                host,
            )
            self._transport = None
            self._fast = False
            transport.abort()
            return
        self._adapter._accept(self)
        limit = self._options.max_queued_output
        transport.set_write_buffer_limits(high=limit, low=limit // 2)
        self._gate = self._adapter.faults.gate(Door.ADS, transport)  # communication faults on demand
        self._transport = self._gate.transport
        self._raw = transport
        self._refresh_fast()
        self._adapter.stats.connections += 1
        logger.debug("ADS: connection from %s", self.session.name)

    def data_received(self, data: bytes) -> None:
        if self._fast and 38 <= len(data) <= _FAST_MAX and self._gate.quiet:
            # the fast path: one Read/Write/ReadWrite in flight, all of it in this read, no fault acting
            raw: Any = self._raw
            if raw.is_closing():
                return
            admitted: Any = self._admitted  # not None where _fast is set
            reply = self._device.handle_frame(self.session, data, admitted)
            if reply is not None:
                raw.write(reply)  # the answer first: the counters while the client reads it
                self._stats.turns += 1
                self.frames += 1
                self.last_activity = _monotonic()
                return
        transport = self._transport
        if transport is None:
            return
        if transport.is_closing():
            return
        if not self._read_paused and not self._scheduled:
            packet = self._decoder.single_frame(data)
            if packet is not None:  # one request in flight, all of it in this read: no buffering
                self._serve_one(transport, packet)
                self._refresh_fast()
                return
        self._decoder.receive_data(data)
        self._serve()
        self._refresh_fast()

    def _refresh_fast(self) -> None:
        self._fast = (
            self._transport is not None
            and self._raw is not None
            and self._admitted is not None
            and not self._read_paused
            and not self._scheduled
            and not self._decoder.pending
            and self.partial_since is None
        )

    def _serve_one(self, transport: asyncio.Transport, packet: AmsPacket) -> None:
        """:meth:`_serve_turn` for a read that is exactly one AMS frame (the decoder holds nothing)."""
        self._adapter.stats.turns += 1
        reply = self._answer(packet)
        self.frames += 1
        self.last_activity = time.monotonic()
        self.partial_since = None
        if isinstance(reply, _Refused):
            self._transport = None
            transport.close()
        elif reply is not None:
            transport.write(reply)

    def eof_received(self) -> bool | None:
        """The client sent all it will send: answer what is buffered, then close."""
        self._eof = True
        self._fast = False
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
        self._fast = False
        self._device.close_session(self.session)
        self._adapter._forget(self)

    # --- serving ------------------------------------------------------------------------------
    def _serve(self) -> None:
        """Answer up to ``max_requests_per_turn`` buffered frames; leave the rest for the next turn."""
        if self._decoder.pending < _TIMED_TURN_BYTES:  # one small request: not worth two system calls
            self._adapter.stats.turns += 1
            self._serve_turn()
            return
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
        refused = False
        served = 0
        decoder = self._decoder
        while True:
            # queued above the limit means the transport paused us (its high-water mark is the limit)
            if budget <= 0 or queued > limit or (served and time.perf_counter() >= deadline):
                more = True
                break
            try:
                frame = decoder.next_frame()
            except AmsStreamError as exc:
                broken = str(exc)
                break
            if frame is NEED_DATA:
                break
            budget -= 1
            served += 1
            reply = self._answer(frame)
            if reply is None:
                continue
            if isinstance(reply, _Refused):
                refused = True
                break
            out.append(reply)
            queued += len(reply)
        if served:
            self.frames += served
            self.last_activity = time.monotonic()
        if not more:
            if decoder.pending:  # an incomplete frame waits: since now if frames completed this turn
                if served or self.partial_since is None:
                    self.partial_since = time.monotonic()
            else:
                self.partial_since = None
        if out:
            transport.write(out[0] if len(out) == 1 else b"".join(out))
        if refused or broken is not None:
            if broken is not None:
                self._adapter.stats.broken_streams += 1
                logger.warning("ADS: closing the connection from %s: %s", self.session.name, broken)
            self._transport = None
            transport.close()  # the answers written above still go out
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
            self._fast = False
            self._adapter.stats.paused_reading += 1
            self._transport.pause_reading()

    def _schedule(self) -> None:
        if not self._scheduled:
            self._scheduled = True
            self._fast = False
            asyncio.get_running_loop().call_soon(self._continue)

    def _continue(self) -> None:
        self._scheduled = False
        if self._transport is not None and not self._transport.is_closing():
            self._serve()
        self._refresh_fast()

    def _answer(self, frame: AmsPacket | AmsTcpFrame | OversizeAmsFrame) -> bytes | _Refused | None:
        if isinstance(frame, OversizeAmsFrame):
            source = frame.header.source_net_id
            if source is not self._admitted and not self._admit(source):
                return _REFUSED
            return self._device.refuse_oversize(self.session, frame.header, frame.length)
        if isinstance(frame, AmsPacket):
            source = frame.header.source_net_id
            if source is not self._admitted and not self._admit(source):
                return _REFUSED
            faulted = self._gate.ads(frame)  # a fault's answer (adapters/faults.py), or None: serve it
            if faulted is not None:
                return faulted or None
            return self._device.handle(self.session, frame)
        return self._router_message(frame)

    def _admit(self, net_id: NetId) -> bool:
        if self._routes.admits(net_id, self.host):
            self._admitted = net_id
            return True
        self._adapter.stats.refused_route += 1
        logger.warning(
            "ADS: no route for NetId %s (from %s): closing its connection as a TwinCAT router does; add the "
            "NetId to the allowlist or add a route (AddRoute, docs/ads.md) to admit it",
            net_id,
            self.session.name,
        )
        return False

    def _router_message(self, frame: AmsTcpFrame) -> bytes | _Refused | None:
        command = frame.command
        if command in (AmsTcpCommand.PORT_CONNECT, AmsTcpCommand.GET_LOCAL_NETID) and not (
            self._routes.answers_router_messages(self.host)
        ):
            self._adapter.stats.refused_router_messages += 1
            logger.warning(
                "ADS: router message 0x%04X from %s not answered: the allowlist names NetIds and not the "
                "server's own, so a client without a NetId of its own cannot be admitted; closing its "
                "connection (give the client its NetId: ads-client localAmsNetId, docs/ads.md)",
                command,
                self.session.name,
            )
            return _REFUSED
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
            return _REFUSED
        return None  # a router note from a client: nothing to answer

    # --- hooks of the session (notifications) -------------------------------------------------
    def _send(self, data: bytes) -> None:
        transport = self._transport
        if transport is None or transport.is_closing():
            return
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

    def usefulness(self, now: float) -> tuple[int, float]:
        """Lowest first is closed first at a full house (module docstring)."""
        if self.partial_since is not None:
            return (0, self.partial_since)
        if not self.frames:
            return (1, self.connected_at)
        return (2, self.idle_since(now))

    def abort(self) -> None:
        transport, self._transport = self._transport, None
        self._fast = False
        if transport is not None:
            transport.abort()


class _Slots:
    """The door's connections; a full house closes its least useful one for a newcomer."""

    def __init__(self, max_connections: int) -> None:
        self.max_connections = max_connections
        self._connections: set[_Connection] = set()

    def __len__(self) -> int:
        return len(self._connections)

    def __iter__(self) -> Iterator[_Connection]:
        return iter(list(self._connections))

    def admit(self, connection: _Connection) -> _Connection | None:
        """Take ``connection``; the connection closed to make room, if one was."""
        evicted = None
        if len(self._connections) >= self.max_connections:
            now = time.monotonic()
            evicted = min(self._connections, key=lambda c: c.usefulness(now))
            self._connections.discard(evicted)
        self._connections.add(connection)
        return evicted

    def forget(self, connection: _Connection) -> None:
        self._connections.discard(connection)

    def abort_all(self) -> None:
        for connection in list(self._connections):
            connection.abort()
        self._connections.clear()


class AdsAdapter:
    """ADS over TCP on ``bind:port`` for the runtime's process image, and over UDP beside it (H-04, C3-10;
    docs/ads.md).

    Options: :class:`AdsOptions` (``--adapter ads:port=48898,ams_net_id=127.0.0.1.1.1`` or the
    ``run`` flags ``--ads-port``, ``--ams-net-id``); ``port`` 0 binds a free port (:attr:`port` tells
    which after start, :attr:`udp_port` the UDP one).
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
        try:
            self.routes = Routes(
                self.options.allowlist(),
                bytes(self.net_id),
                self.options.routes_file,
                self.options.max_routes,
            )
        except RouteError as exc:
            raise ValueError(f"ADS adapter: routes_file: {exc}") from None
        self.allowlist = self.routes.allowlist
        self.requested_port = self.options.port
        self.turn_s = self.options.max_turn_ms / 1000.0
        self.port: int | None = None
        self.udp_port: int | None = None
        self.udp: UdpDoor | None = None
        self.stats = ServerStats()
        self.device: AdsDevice
        self.faults = CommFaults()
        """The communication faults the connections consult (the host's, once started)."""
        self._listener: asyncio.Server | None = None
        self._udp_transport: asyncio.DatagramTransport | None = None
        self._slots = _Slots(self.options.max_connections)
        self._flush_pending: set[Session] = set()
        self._flush_scheduled = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._host: AdapterHost | None = None
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
        lines = [
            f"ADS (AMS/TCP): {self.host}:{self.port}  (AMS NetId {self.net_id}; port 851 HLI symbols, "
            f"groups 0x{ADS_GROUP_PLC_TO_CNC:X}/0x{ADS_GROUP_CNC_TO_PLC:X}; port 551 CNC objects, "
            f"group 0x{ADS_GROUP_GEO_AXIS:X}; port 10000 system service; "
            f"allow: {', '.join(self.options.allow) or 'everybody'}"
            f"{f', {len(self.routes)} routes' if len(self.routes) else ''})"
        ]
        if self.udp_port is not None:
            o = self.options
            adding = (
                "accepted with route_user/route_password" if o.route_user else "refused (no credentials set)"
            )
            lines.append(f"ADS (UDP): {self.host}:{self.udp_port}  (discovery; AddRoute {adding})")
        return lines

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
                max_notifications_per_net_id=o.max_notifications_per_net_id,
                max_notifications_per_host=o.max_notifications_per_host,
                max_notifications_total=o.max_notifications_total,
                max_sum_items=o.max_sum_items,
            ),
            call_later=self._call_later,
            request_flush=self._request_flush,
            first_sample_delay_s=o.first_sample_delay_ms / 1000.0,
            read_only=read_only,
        )
        self.device.notifications.on_active = self._cycles_wanted
        return self.device

    async def start(self, host: AdapterHost) -> None:
        self.faults = host.faults
        self.serve_image(host.image, host.operator.t_a_us, read_only=host.policy.read_only)
        self._host = host
        try:
            await self._listen()
        except BaseException:
            self._host = None
            raise

    async def start_for(self, image: ImagePort, t_a_us: int = 1000) -> None:
        """Listen for an image without a runtime (tests, tools); drive notifications with
        ``adapter.device.on_cycle(cycle)``."""
        self.serve_image(image, t_a_us)
        await self._listen()

    def _cycles_wanted(self, wanted: bool) -> None:
        """The device has notifications (True) or none any more (False): follow the cycle or stop."""
        if self._host is None:
            return
        if wanted and self._unsubscribe is None:
            self._unsubscribe = self._host.on_cycle(self.device.on_cycle)
        elif not wanted and self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None

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
        try:
            if self.options.udp:
                await self._listen_udp()
        except BaseException:
            await self._close_listener()
            raise
        self._idle_task = self._loop.create_task(self._watch_idle(), name="hli-ads-idle")
        logger.info("ADS listening on %s:%d (AMS NetId %s)", self.bind, self.port, self.net_id)

    async def _listen_udp(self) -> None:
        assert self._loop is not None
        port = self.options.udp_port_to_bind
        door = UdpDoor(self.options, self.net_id, self.routes)
        try:
            transport, _ = await self._loop.create_datagram_endpoint(
                lambda: door, local_addr=(self.bind, port), reuse_port=False
            )
        except OSError as exc:
            raise OSError(
                exc.errno,
                f"ADS: cannot listen for UDP on {self.bind}:{port}: {exc.strerror}; choose another "
                "--adapter ads:udp_port=N (0 = any free port), udp=false, or --bind address "
                "(is a TwinCAT router on 48899?)",
            ) from None
        self.udp = door
        self._udp_transport = transport
        self.udp_port = transport.get_extra_info("sockname")[1]

    async def stop(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        self._host = None
        if self._idle_task is not None:
            self._idle_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._idle_task
            self._idle_task = None
        if self._udp_transport is not None:
            self._udp_transport.close()
            self._udp_transport = None
        self.udp_port = None
        await self._close_listener()

    async def _close_listener(self) -> None:
        listener, self._listener = self._listener, None
        if listener is not None:
            listener.close()
        self._slots.abort_all()
        if listener is not None:
            with contextlib.suppress(Exception):
                await listener.wait_closed()
        self.port = None

    # --- connections --------------------------------------------------------------------------
    def _accept(self, connection: _Connection) -> None:
        """Admit ``connection``; at the limit the least useful one makes room (module docstring)."""
        evicted = self._slots.admit(connection)
        if evicted is not None:
            self.stats.evicted += 1
            category, since = evicted.usefulness(time.monotonic())
            why = ("an incomplete frame", "no complete request", "no request")[category]
            logger.info(
                "ADS: %d connections open (max_connections): closing %s (%s for %.1f s) to make room for %s",
                len(self._slots),
                evicted.session.name,
                why,
                time.monotonic() - since,
                connection.session.name,
            )
            evicted.abort()

    def _forget(self, connection: _Connection) -> None:
        self._slots.forget(connection)
        self._flush_pending.discard(connection.session)

    def next_client_port(self) -> int:
        port = self._next_client_port
        self._next_client_port = port + 1 if port < 65535 else FIRST_CLIENT_PORT
        return port

    async def _watch_idle(self) -> None:
        timeout = self.options.idle_timeout_s
        frame_timeout = self.options.frame_timeout_s
        period = min(1.0, timeout / 4, frame_timeout / 4)
        while True:
            await asyncio.sleep(period)
            now = time.monotonic()
            for connection in self._slots:
                partial = connection.partial_since
                if partial is not None and now - partial > frame_timeout:
                    self.stats.frame_timeouts += 1
                    logger.info(
                        "ADS: closing %s: a frame begun %.1f s ago is not complete (frame_timeout_s)",
                        connection.session.name,
                        now - partial,
                    )
                elif now - connection.idle_since(now) > timeout:
                    self.stats.idle_closed += 1
                    logger.info(
                        "ADS: closing %s: no request for %.0f s (idle_timeout_s)",
                        connection.session.name,
                        timeout,
                    )
                else:
                    continue
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
