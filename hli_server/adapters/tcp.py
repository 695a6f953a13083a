"""What the TCP doors (Modbus, ADS) share: listening with a clear error, bounded connections with a slot
for a newcomer (reliability.md, round 1, finding 4; reliability.md, round 2, finding 3), and an allowlist of
peer addresses.

A door holds at most ``max_connections``. At the limit a newcomer is never locked out by connections that
do nothing for anyone (a PLC that reconnects after a restart must never find the door locked by the dead
connections of its former self). Two policies:

* ``least_useful`` (Modbus): the least useful connection makes room (:meth:`ServedConnection.usefulness`):
  one that has never had a request answered (the one connected longest ago first: a connection that
  trickles a byte now and then without ever completing a frame, or never sends anything), then the one
  whose last request was answered longest ago; one whose requests are being answered counts as served
  now. Honest clients that poll keep their slots, even while a burst of new connections comes in. The
  newcomer is never refused.
* otherwise (ADS, for now): a connection silent for ``evict_after`` seconds makes room (the one silent the
  longest); when every connection has been active more recently, the newcomer is refused.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import time
from collections.abc import Callable, Iterable, Iterator
from enum import Enum
from typing import ClassVar, Generic, Protocol, TypeVar

from pydantic import Field, field_validator

from hli_server.adapters.options import RenamedOptions

__all__ = [
    "AddressAllowlist",
    "Admission",
    "Connection",
    "ConnectionSlots",
    "ServedConnection",
    "TcpDoorOptions",
    "check_allowlist",
    "close",
    "listen",
]

logger = logging.getLogger(__name__)


class Connection(Protocol):
    def idle_since(self, now: float) -> float:
        """When the client was last active (``now`` while it is busy: it is not idle)."""
        ...

    def abort(self) -> None: ...


class ServedConnection(Connection, Protocol):
    def usefulness(self, now: float) -> tuple[int, float]:
        """``(0, connect time)`` while no request of the client was answered, else ``(1, when the last
        one was)`` (``now`` while requests of it wait for their answers): the lowest makes room first."""
        ...


C = TypeVar("C", bound=Connection)


class Admission(Enum):
    ADMITTED = "admitted"
    EVICTED = "admitted after closing the connection silent the longest"
    REFUSED = "refused: every connection busy"


class ConnectionSlots(Generic[C]):
    """The connections of one door, bounded (see the module docstring)."""

    def __init__(
        self, door: str, max_connections: int, evict_after: float, *, least_useful: bool = False
    ) -> None:
        self.door = door
        self.max_connections = max_connections
        self.evict_after = evict_after
        self.least_useful = least_useful
        """Make room by closing the connection served longest ago, never refuse (see the module docstring)."""
        self._connections: set[C] = set()

    def __len__(self) -> int:
        return len(self._connections)

    def __iter__(self) -> Iterator[C]:
        return iter(list(self._connections))

    def admit(self, connection: C, peer: object = None) -> Admission:
        """Take ``connection``, making room if it must; REFUSED: the caller closes it."""
        admission = Admission.ADMITTED
        if len(self._connections) >= self.max_connections and self.least_useful:
            now = time.monotonic()
            victim = min(self._connections, key=lambda c: c.usefulness(now))  # type: ignore[attr-defined]
            served, since = victim.usefulness(now)  # type: ignore[attr-defined]
            logger.info(
                "%s: %d connections open: closing one %s %.1f s ago to make room for %s",
                self.door,
                len(self._connections),
                "last answered" if served else "never answered, connected",
                now - since,
                peer,
            )
            self._connections.discard(victim)
            victim.abort()
            self._connections.add(connection)
            return Admission.EVICTED
        if len(self._connections) >= self.max_connections:
            now = time.monotonic()
            oldest = min(self._connections, key=lambda c: c.idle_since(now))
            idle = now - oldest.idle_since(now)
            if idle < self.evict_after:
                logger.warning(
                    "%s: refused a connection from %s: %d connections open and none silent for %.0f s "
                    "(max_connections, evict_after)",
                    self.door,
                    peer,
                    len(self._connections),
                    self.evict_after,
                )
                return Admission.REFUSED
            admission = Admission.EVICTED
            logger.info(
                "%s: %d connections open: closing the one silent for %.1f s to make room for %s",
                self.door,
                len(self._connections),
                idle,
                peer,
            )
            self._connections.discard(oldest)
            oldest.abort()
        self._connections.add(connection)
        return admission

    def forget(self, connection: C) -> None:
        self._connections.discard(connection)

    def abort_all(self) -> None:
        for connection in list(self._connections):
            connection.abort()
        self._connections.clear()


class AddressAllowlist:
    """Which peers a door lets in: IP addresses and networks (``10.0.0.0/8``, ``::1``); the word
    ``loopback`` for 127.0.0.0/8 and ::1. An empty list lets everybody in. IPv4-mapped IPv6 peers are
    taken as their IPv4 address."""

    def __init__(self, entries: Iterable[str]) -> None:
        self.entries = [e.strip() for e in entries if e.strip()]
        self.loopback = any(e.lower() == "loopback" for e in self.entries)
        self.networks = [
            ipaddress.ip_network(e, strict=False) for e in self.entries if e.lower() != "loopback"
        ]

    def __bool__(self) -> bool:
        return bool(self.entries)

    @property
    def open_to_all(self) -> bool:
        """Empty, or a network that holds every address (0.0.0.0/0, ::/0)."""
        return not self.entries or any(n.prefixlen == 0 for n in self.networks)

    def allows(self, peer: object) -> bool:
        """``peer``: a transport's ``peername`` (``(host, port, ...)``) or a host text."""
        if not self.entries:
            return True
        host = peer[0] if isinstance(peer, tuple) and peer else peer
        if not isinstance(host, str):
            return False
        try:
            address = ipaddress.ip_address(host.split("%", 1)[0])
        except ValueError:
            return False
        if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
            address = address.ipv4_mapped
        if self.loopback and address.is_loopback:
            return True
        return any(address in network for network in self.networks)

    def __str__(self) -> str:
        return ", ".join(self.entries) or "everybody"


def check_allowlist(value: object) -> object:
    """A pydantic ``before`` validator for an ``allow`` option: one text (entries separated by spaces,
    commas or ``;``) or a list; every entry an IP address, a network or ``loopback``."""
    if isinstance(value, str):
        value = value.replace(";", " ").replace(",", " ").split()
    if isinstance(value, list):
        for entry in value:
            if not isinstance(entry, str):
                raise ValueError(f"allow entry {entry!r} is not text")
            if entry.strip().lower() == "loopback":
                continue
            try:
                ipaddress.ip_network(entry.strip(), strict=False)
            except ValueError:
                raise ValueError(
                    f"allow entry {entry!r} is neither an IP address, a network (10.0.0.0/8), nor 'loopback'"
                ) from None
    return value


async def listen(
    factory: Callable[[], asyncio.Protocol], bind: str, port: int, door: str, hint: str
) -> asyncio.Server:
    """``loop.create_server`` for a door; a port that cannot be had is an OSError that says what to do."""
    loop = asyncio.get_running_loop()
    try:
        return await loop.create_server(factory, host=bind, port=port, reuse_address=True, backlog=256)
    except OSError as exc:
        raise OSError(exc.errno, f"{door}: cannot listen on {bind}:{port}: {exc.strerror}; {hint}") from None


async def close(server: asyncio.Server | None, slots: ConnectionSlots[C]) -> None:
    """Stop listening and end every connection of the door."""
    if server is not None:
        server.close()
    slots.abort_all()
    if server is not None:
        with contextlib.suppress(Exception):
            await server.wait_closed()


class TcpDoorOptions(RenamedOptions):
    """The options every TCP door (Modbus, ADS) has, under one set of names: ``port``, ``max_connections``,
    ``idle_timeout_s``, ``frame_timeout_s`` and ``allow``. A door's model derives from this one and sets its
    own defaults and ranges (``--adapter modbus:idle_timeout_s=60`` and ``ads:idle_timeout_s=60`` mean the
    same thing).

    Names a door used before (``RENAMED``: Modbus' ``idle_timeout``, ``frame_timeout``, ``evict_after``, ADS'
    ``evict_idle_after_s``) are still accepted, with a ``DeprecationWarning`` and a log line that name the new
    option; they go in the next minor version. An old name that has no effect any more maps to None.
    """

    DOOR: ClassVar[str] = "TCP"

    port: int = Field(default=0, ge=0, le=65535, description="TCP port (0: any free port)")
    max_connections: int = Field(
        default=256,
        ge=1,
        le=10_000,
        description="connections at once; beyond, the least useful one makes room for a newcomer",
    )
    idle_timeout_s: float = Field(
        default=120.0, ge=0.0, le=86_400.0, description="seconds a connection may stay silent"
    )
    frame_timeout_s: float = Field(
        default=2.0,
        ge=0.0,
        le=3600.0,
        description="seconds a request frame may take from its first byte to its last",
    )
    allow: list[str] = Field(
        default_factory=list,
        description="peers allowed in: IP addresses, networks (10.0.0.0/8) or 'loopback'; empty: everybody",
    )

    @field_validator("allow", mode="before")
    @classmethod
    def _allow(cls, value: object) -> object:
        return check_allowlist(value)
