"""ADS over UDP: the discovery answer and AddRoute, where the TCP door listens (H-04, docs/ads.md).

The asyncio shell around the sans-I/O codec :mod:`hli_server.codecs.ads.udp`:

* **Discovery** (service 1; TwinCAT's "Broadcast Search", ``pyads``' NetId discovery): answered with the
  server's NetId, the host name, an OS version and the TwinCAT version the server answers as (3.1.4024).
* **AddRoute** (service 6; ``pyads.add_route_to_plc``, AdsLib's ``AddRemoteRoute``, TwinCAT's "Add
  Route" dialog): with ``route_user``/``route_password`` configured and matching, the route is added
  (:class:`~hli_server.adapters.ads.routes.Routes`) and answered 0; otherwise, as TwinCAT answers wrong
  credentials, 0x704. A route's address may be a host name: it is resolved (2 s at most), and when it
  does not resolve the route admits the address the request came from.
* **Bounds**: the socket is bound where the TCP door is bound (loopback by default: nothing beyond this
  computer can discover it or add routes); every sender gets ``udp_rate`` answers per second (bursts of
  twice that), all senders together ``udp_rate_total`` - and beyond it still its fair share of that, so
  that many senders cannot lock out one that asks now and then (:class:`RateLimiter`) - and AddRoute one
  per second per sender (bursts of 3): datagrams beyond are dropped, counted and logged once per 10 s. A
  datagram that does not parse is dropped (UDP has no error reply). Answers are never longer than about
  400 bytes.
"""

from __future__ import annotations

import asyncio
import hmac
import importlib.metadata
import ipaddress
import logging
import math
import platform
import socket
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final, cast

from hli_server.adapters.ads.options import canonical_ip
from hli_server.adapters.ads.routes import RouteError, Routes
from hli_server.adapters.ads.system import TWINCAT_VERSION
from hli_server.codecs.ads import AdsCodecError, ErrorCode, NetId
from hli_server.codecs.ads.udp import (
    AddRouteRequest,
    UdpMessage,
    UdpService,
    decode_udp,
    encode_add_route_reply,
    encode_discovery_reply,
    os_version_tag,
)

if TYPE_CHECKING:
    from hli_server.adapters.ads.options import AdsOptions

__all__ = ["RateLimiter", "UdpDoor", "UdpStats"]

logger = logging.getLogger(__name__)

MAX_SENDERS: Final = 4096
"""Senders the rate limiter remembers; beyond, the oldest are forgotten."""
RATE_WINDOW_S: Final = 2.0
"""The span over which a sender's recent rate is averaged, and the active senders counted (the fair share)."""
RESOLVE_TIMEOUT_S: Final = 2.0
MAX_RESOLVING: Final = 4
"""Host names resolved at once for AddRoute; AddRoutes beyond are answered 0x708 (device busy)."""


@dataclass(slots=True)
class UdpStats:
    datagrams: int = 0
    discovery: int = 0
    routes_added: int = 0
    routes_refused: int = 0
    rate_limited: int = 0
    malformed: int = 0
    ignored: int = 0


class RateLimiter:
    """Token buckets per sender and for all senders together (``rate`` per second, bursts of ``burst``),
    with a fair share (issue 36, finding 7).

    The shared bucket alone is first come, first served: many senders, each within its own rate, drain it
    and an honest client that asks now and then finds it empty. So when the shared bucket is empty, a
    sender is still let in (within its own bucket) while its recent rate (an average over
    :data:`RATE_WINDOW_S`) stays within its share of the whole, ``rate_total`` / the senders active in the
    last window: the senders that ask more than their share are the ones held back, and all the light
    ones together never exceed ``rate_total`` again (at most twice ``rate_total`` is answered in all)."""

    def __init__(self, rate: float, burst: float, rate_total: float, burst_total: float) -> None:
        self.rate, self.burst = rate, burst
        self.rate_total, self.burst_total = rate_total, burst_total
        self._senders: dict[str, tuple[float, float, float]] = {}
        """sender -> (its tokens, when last seen, its recent rate in datagrams per second)"""
        self._total = (burst_total, time.monotonic())
        self._window = (time.monotonic(), 0, set[str]())
        """(when this window began, senders active in the last one, senders seen in this one)"""

    def active(self, sender: str, now: float) -> int:
        """Senders that sent in this window or the last (``sender`` counted)."""
        began, before, seen = self._window
        if now - began >= RATE_WINDOW_S:
            self._window = (now, len(seen), set())
            began, before, seen = self._window
        if len(seen) < MAX_SENDERS:
            seen.add(sender)
        return max(before, len(seen), 1)

    def allow(self, sender: str, now: float | None = None) -> bool:
        now = time.monotonic() if now is None else now
        tokens, last = self._total
        tokens = min(self.burst_total, tokens + (now - last) * self.rate_total)
        own, own_last, recent = self._senders.get(sender, (self.burst, now, 0.0))
        own = min(self.burst, own + (now - own_last) * self.rate)
        recent = recent * math.exp(-(now - own_last) / RATE_WINDOW_S) + 1.0 / RATE_WINDOW_S
        share = self.rate_total / self.active(sender, now)
        allowed = own >= 1 and (tokens >= 1 or recent <= share)
        if allowed:
            own -= 1
            if tokens >= 1:
                tokens -= 1
        self._total = (tokens, now)
        if len(self._senders) >= MAX_SENDERS and sender not in self._senders:
            self._senders.pop(next(iter(self._senders)))
        self._senders[sender] = (own, now, recent)
        return allowed


@dataclass(slots=True)
class _Identity:
    net_id: NetId
    host_name: str
    os_version: bytes = field(default=b"")


class UdpDoor(asyncio.DatagramProtocol):
    """The UDP socket's protocol (module docstring)."""

    def __init__(self, options: AdsOptions, net_id: NetId, routes: Routes) -> None:
        self.options = options
        self.routes = routes
        self.stats = UdpStats()
        self.identity = _Identity(
            net_id,
            socket.gethostname()[:64] or "hli-server",
            os_version_tag(0, 0, 0, 0, f"hli-server {_version()}: simulated ISG CNC on {platform.system()}"),
        )
        self._limit = RateLimiter(
            options.udp_rate, 2 * options.udp_rate, options.udp_rate_total, 2 * options.udp_rate_total
        )
        self._route_limit = RateLimiter(1.0, 3.0, 10.0, 20.0)
        self._transport: asyncio.DatagramTransport | None = None
        self._last_warning = 0.0
        self._resolving: set[asyncio.Task[None]] = set()

    # --- asyncio ------------------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast("asyncio.DatagramTransport", transport)

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None
        for task in self._resolving:
            task.cancel()

    def error_received(self, exc: Exception) -> None:  # an ICMP error for an earlier answer: nothing to do
        logger.debug("ADS/UDP: %s", exc)

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.stats.datagrams += 1
        sender = str(addr[0]) if isinstance(addr, tuple) and addr else str(addr)
        if not self._limit.allow(sender):
            self._rate_limited(sender)
            return
        try:
            message = decode_udp(data)
        except AdsCodecError as exc:
            self.stats.malformed += 1
            logger.debug("ADS/UDP from %s dropped: %s", sender, exc)
            return
        if message.is_response:
            self.stats.ignored += 1
            return
        if message.service == UdpService.SERVER_INFO:
            self.stats.discovery += 1
            self._send(
                encode_discovery_reply(
                    message,
                    self.identity.net_id,
                    self.identity.host_name,
                    TWINCAT_VERSION,
                    self.identity.os_version,
                ),
                addr,
            )
        elif message.service == UdpService.ADD_ROUTE:
            if not self._route_limit.allow(sender):
                self._rate_limited(sender)
                return
            self._add_route(message, sender, addr)
        else:
            self.stats.ignored += 1
            logger.debug("ADS/UDP from %s: service %d is not answered here", sender, message.service)

    # --- AddRoute -------------------------------------------------------------------------------
    def _add_route(self, message: UdpMessage, sender: str, addr: Any) -> None:
        try:
            request = AddRouteRequest.from_message(message)
        except AdsCodecError as exc:
            self.stats.malformed += 1
            logger.info("ADS/UDP: AddRoute from %s refused: %s", sender, exc)
            self._answer_route(message, addr, ErrorCode.INVALID_PARAMETER)
            return
        refusal = self._credentials(request)
        if refusal is not None:
            self.stats.routes_refused += 1
            logger.warning(
                "ADS/UDP: AddRoute from %s for NetId %s refused: %s", sender, request.net_id, refusal
            )
            self._answer_route(message, addr, ErrorCode.READ_WRITE_NOT_PERMITTED)
            return
        ip = canonical_ip(request.address)
        if ip is not None:
            self._finish_route(message, addr, request, frozenset({ip}))
            return
        if len(self._resolving) >= MAX_RESOLVING:
            self._answer_route(message, addr, ErrorCode.BUSY)
            return
        task = asyncio.get_running_loop().create_task(self._resolve(message, addr, request, sender))
        self._resolving.add(task)
        task.add_done_callback(self._resolving.discard)

    def _credentials(self, request: AddRouteRequest) -> str | None:
        user, password = self.options.route_user, self.options.route_password
        if user is None or password is None:
            return "no credentials are configured (route_user, route_password: docs/ads.md, Routes)"
        if request.password is None or request.user is None:
            return "it carries no plain user name and password (pyads and AdsLib send them)"
        ok_user = hmac.compare_digest(request.user.casefold().encode(), user.casefold().encode())
        ok_password = hmac.compare_digest(request.password.encode(), password.encode())
        return None if ok_user and ok_password else "wrong user name or password"

    async def _resolve(self, message: UdpMessage, addr: Any, request: AddRouteRequest, sender: str) -> None:
        loop = asyncio.get_running_loop()
        try:
            infos = await asyncio.wait_for(
                loop.getaddrinfo(request.address, None, type=socket.SOCK_STREAM), RESOLVE_TIMEOUT_S
            )
            ips = frozenset(
                str(canonical_ip(str(info[4][0]))) for info in infos if canonical_ip(str(info[4][0]))
            )
        except (OSError, TimeoutError, UnicodeError):
            ips = frozenset()
        if not ips:
            own = canonical_ip(sender)
            logger.warning(
                "ADS/UDP: the route address %r does not resolve; the route admits %s, where AddRoute "
                "came from",
                request.address,
                own,
            )
            ips = frozenset({own}) if own else frozenset()
        self._finish_route(message, addr, request, ips)

    def _finish_route(
        self, message: UdpMessage, addr: Any, request: AddRouteRequest, ips: frozenset[str]
    ) -> None:
        try:
            route = self.routes.add(request.route_name, request.net_id, request.address, ips)
        except RouteError as exc:
            self.stats.routes_refused += 1
            logger.warning("ADS/UDP: AddRoute for NetId %s refused: %s", request.net_id, exc)
            self._answer_route(message, addr, ErrorCode.NO_MEMORY)
            return
        self.stats.routes_added += 1
        logger.info(
            "ADS: route %r added: NetId %s at %s (%s)%s",
            route.name,
            route.net_id,
            route.address,
            ", ".join(sorted(route.ips)),
            f", kept in {self.routes.file}" if self.routes.file else "",
        )
        self._answer_route(message, addr, 0)

    def _answer_route(self, message: UdpMessage, addr: Any, status: int) -> None:
        self._send(encode_add_route_reply(message, self.identity.net_id, status), addr)

    # --- helpers --------------------------------------------------------------------------------
    def _send(self, data: bytes, addr: Any) -> None:
        if self._transport is not None and not self._transport.is_closing():
            self._transport.sendto(data, addr)

    def _rate_limited(self, sender: str) -> None:
        self.stats.rate_limited += 1
        now = time.monotonic()
        if now - self._last_warning > 10.0:
            self._last_warning = now
            logger.warning(
                "ADS/UDP: datagrams from %s beyond the rate limit dropped (%d so far; udp_rate, "
                "udp_rate_total)",
                sender,
                self.stats.rate_limited,
            )


def _version() -> str:
    try:
        return importlib.metadata.version("hli-server")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - a source tree without install
        return "?"


def family_of(bind: str) -> socket.AddressFamily:
    try:
        return socket.AF_INET6 if ipaddress.ip_address(bind).version == 6 else socket.AF_INET
    except ValueError:
        return socket.AF_UNSPEC
