"""uvicorn's HTTP/1.1 protocol with bounds: connections per door, idle connections, a slot for a newcomer.

uvicorn keeps a connection that never sends a request open forever and refuses requests beyond
``limit_concurrency`` only after reading them. Issue 12 measured what that does: a thousand idle
connections took the server down, and idle clients can lock others out. :func:`bounded_protocol` makes
a subclass of uvicorn's ``H11Protocol`` that

* counts connections and refuses one beyond ``max_connections`` at once, with ``503`` and ``Connection:
  close``, before it is registered with the event loop (so it costs one descriptor for a moment);
* keeps a slot for a new client: at the limit, the connection that has been idle longest (no request in
  progress) is closed to make room, before the newcomer is refused;
* closes a connection that sends nothing for ``idle_timeout`` seconds (uvicorn's own keep-alive timeout
  closes idle connections between requests sooner).
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import Any, ClassVar

from uvicorn.protocols.http.h11_impl import H11Protocol

__all__ = ["bounded_protocol"]

logger = logging.getLogger(__name__)

_REFUSAL_BODY = b'{"detail":"too many connections to the control API; try again later"}'
_REFUSAL = (
    b"HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\nconnection: close\r\n"
    + b"content-length: %d\r\n\r\n" % len(_REFUSAL_BODY)
    + _REFUSAL_BODY
)


class _BoundedH11Protocol(H11Protocol):
    max_connections: ClassVar[int] = 256
    idle_timeout: ClassVar[float] = 30.0
    refused: ClassVar[list[int]] = [0]
    evicted: ClassVar[list[int]] = [0]

    _idle_handle: asyncio.TimerHandle | None = None
    _last_active: float = 0.0
    _admitted: bool = False

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        if len(self.connections) >= self.max_connections and not self._make_room():
            type(self).refused[0] += 1
            transport.write(_REFUSAL)
            transport.close()
            return
        self._admitted = True
        super().connection_made(transport)
        self._last_active = time.monotonic()
        self._arm_idle_timer()

    def _make_room(self) -> bool:
        """Close the connection idle the longest (no request in progress), if there is one."""
        idle = [
            c
            for c in self.connections
            if isinstance(c, _BoundedH11Protocol) and (c.cycle is None or c.cycle.response_complete)
        ]
        if not idle:
            return False
        victim = min(idle, key=lambda c: c._last_active)
        type(self).evicted[0] += 1
        victim.transport.close()
        self.connections.discard(victim)
        return True

    def _arm_idle_timer(self) -> None:
        if self.idle_timeout > 0:
            self._idle_handle = self.loop.call_later(self.idle_timeout, self._idle_check)

    def _idle_check(self) -> None:
        self._idle_handle = None
        busy = self.cycle is not None and not self.cycle.response_complete
        quiet = time.monotonic() - self._last_active
        if not busy and quiet >= self.idle_timeout:
            self.transport.close()
            return
        remaining = self.idle_timeout - quiet if not busy else self.idle_timeout
        self._idle_handle = self.loop.call_later(max(remaining, 0.05), self._idle_check)

    def data_received(self, data: bytes) -> None:
        self._last_active = time.monotonic()
        super().data_received(data)

    def connection_lost(self, exc: Exception | None) -> None:
        if self._idle_handle is not None:
            self._idle_handle.cancel()
            self._idle_handle = None
        if self._admitted:
            super().connection_lost(exc)


def bounded_protocol(max_connections: int, idle_timeout: float) -> type[Any]:
    """A protocol class for ``uvicorn.Config(http=...)`` with these bounds (one class per adapter)."""
    return type(
        "BoundedH11Protocol",
        (_BoundedH11Protocol,),
        {"max_connections": max_connections, "idle_timeout": idle_timeout, "refused": [0], "evicted": [0]},
    )
