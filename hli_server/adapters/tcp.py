"""What the TCP doors (Modbus, ADS) share: listening with a clear error, and bounded connections with a
slot for a newcomer (issue 12, finding 4).

A door holds at most ``max_connections``. At the limit a new client is not refused while another has been
silent for ``evict_after`` seconds: the one silent the longest is closed to make room (a PLC that
reconnects after a restart must never find the door locked by the dead connections of its former self).
Only when every connection is busy is the newcomer refused.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Iterator
from enum import Enum
from typing import Generic, Protocol, TypeVar

__all__ = ["Admission", "Connection", "ConnectionSlots", "close", "listen"]

logger = logging.getLogger(__name__)


class Connection(Protocol):
    def idle_since(self, now: float) -> float:
        """When the client was last active (``now`` while it is busy: it is not idle)."""
        ...

    def abort(self) -> None: ...


C = TypeVar("C", bound=Connection)


class Admission(Enum):
    ADMITTED = "admitted"
    EVICTED = "admitted after closing the connection silent the longest"
    REFUSED = "refused: every connection busy"


class ConnectionSlots(Generic[C]):
    """The connections of one door, bounded (see the module docstring)."""

    def __init__(self, door: str, max_connections: int, evict_after: float) -> None:
        self.door = door
        self.max_connections = max_connections
        self.evict_after = evict_after
        self._connections: set[C] = set()

    def __len__(self) -> int:
        return len(self._connections)

    def __iter__(self) -> Iterator[C]:
        return iter(list(self._connections))

    def admit(self, connection: C, peer: object = None) -> Admission:
        """Take ``connection``, making room if it must; REFUSED: the caller closes it."""
        admission = Admission.ADMITTED
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
