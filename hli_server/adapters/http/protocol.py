"""uvicorn's HTTP/1.1 protocol with bounds: connections per door, time to send a request, time to read an
answer, and a slot for a newcomer (reliability.md, round 1, finding 3; reliability.md, round 2, findings 2
and 4).

uvicorn keeps a connection that never sends a request open forever, waits forever for a body that was
announced and never comes, keeps the answer of a client that never reads in memory, and refuses requests
beyond ``limit_concurrency`` only after reading them. What that allowed: a thousand idle connections took
the server down; 256 POST heads that never sent their bodies got every other client a 503 for as long as
they stayed; dashboards that never read held their slots forever. :func:`bounded_protocol` makes a
subclass of uvicorn's ``H11Protocol`` that

* counts connections and, beyond ``max_connections``, closes the *least useful* one to make room for the
  newcomer: first a connection that has not yet delivered a whole request, silent or still sending it
  (the one that connected longest ago: a silent or stalled one), then one that was answered and whose
  next request is still arriving (the one that began longest ago), then a keep-alive connection between
  two requests of its client (idle longest), then one whose client does not read its answer (paused
  longest). So an honest client is closed only after every silent or stalled connection: its keep-alive
  connection (a storm of stalled bodies closed it before, one GET in 15 reset; issue 36, finding 9) ranks
  above all of them once answered, and its new connection, accepted but not read yet, is the newest of
  them (ranked "silent" below every stalled sender, it was closed by the next sender coming back: 1-3 GETs
  of 60 were still reset). A connection whose request the server is working on is never closed for a
  newcomer; only if every connection is such, the newcomer gets ``503`` with ``Connection: close`` before
  it is registered with the event loop (it costs one descriptor for a moment);
* gives a request ``request_timeout_s`` seconds from its first byte to the end of its body: a client that
  announces a body and never sends it (or sends it a byte at a time) gets ``408 Request Timeout`` and the
  connection is closed; the application sees the client go away;
* gives a client ``write_timeout_s`` seconds to take an answer the server is waiting to send (the
  transport's buffer is full because the client does not read): then the connection is dropped, and
  what was buffered for it with it (a dashboard's stream that never reads, a large answer nobody takes).
  The kernel's send buffer of a connection is held to :data:`SEND_BUFFER` bytes (Linux doubles it, and
  grows it to 4 MB otherwise, which a stream of 60 kB/s takes a minute to fill before anyone can tell
  that its page does not read); that is still as much as a local network needs in flight;
* closes a connection that sends nothing for ``idle_timeout_s`` seconds while no request of it is in
  progress (uvicorn's own keep-alive timeout closes idle connections between requests sooner).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import time
from collections.abc import Iterable
from typing import Any, ClassVar

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

__all__ = ["SEND_BUFFER", "abort_stalled", "bounded_protocol"]

logger = logging.getLogger(__name__)


def _raw_answer(status: int, reason: str, detail: str) -> bytes:
    body = b'{"detail":"%s"}' % detail.encode("ascii")
    return (
        b"HTTP/1.1 %d %s\r\ncontent-type: application/json\r\nconnection: close\r\n"
        % (status, reason.encode())
        + b"content-length: %d\r\n\r\n" % len(body)
        + body
    )


_REFUSAL = _raw_answer(
    503, "Service Unavailable", "too many connections to the control API, all of them busy; try again later"
)
SEND_BUFFER = 64 * 1024
"""``SO_SNDBUF`` of every connection of the door (see the module docstring)."""
_TIMEOUT_DETAIL = (
    "the request did not arrive within the request_timeout_s of this door; send it whole, at once"
)
_TIMEOUT = _raw_answer(408, "Request Timeout", _TIMEOUT_DETAIL)


class _BoundedH11Protocol(H11Protocol):
    max_connections: ClassVar[int] = 256
    idle_timeout_s: ClassVar[float] = 30.0
    request_timeout_s: ClassVar[float] = 10.0
    write_timeout_s: ClassVar[float] = 10.0
    counters: ClassVar[dict[str, int]] = {}
    """refused, evicted, timed_out (408), write_stalled, idle_closed: for the tests and the docs."""

    _check_handle: asyncio.TimerHandle | None = None
    _last_active: float = 0.0
    _connected_at: float = 0.0
    _request_began: float | None = None
    _write_paused_at: float | None = None
    _admitted: bool = False
    _served: bool = False
    """it has had an answer: between two requests it is a keep-alive client, not a silent one"""

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        if len(self.connections) >= self.max_connections and not self._make_room():
            self._count("refused")
            transport.write(_REFUSAL)
            transport.close()
            return
        self._admitted = True
        sock = transport.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER)
        super().connection_made(transport)
        self._last_active = self._connected_at = time.monotonic()
        self._arm_check()

    @classmethod
    def _count(cls, what: str) -> None:
        cls.counters[what] = cls.counters.get(what, 0) + 1

    # --- what a connection is doing ----------------------------------------------------------------
    def _arriving(self) -> bool:
        """A request of this connection is still arriving (its head or its body is incomplete)."""
        return self._request_began is not None

    def _working(self) -> bool:
        """The server works on a request of this connection (it arrived whole; the answer is not done)."""
        cycle = self.cycle
        return cycle is not None and not cycle.response_complete and not self._arriving()

    def _usefulness(self) -> tuple[int, float] | None:
        """Lower = closed first for a newcomer; None = never (the server is working for it)."""
        if self._write_paused_at is not None:
            return (3, self._write_paused_at)  # it does not read what it asked for
        if self._working():
            return None
        if not self._served:
            return (0, self._connected_at)  # no whole request yet (silent, or sending it): oldest first
        if self._arriving():
            assert self._request_began is not None
            return (1, self._request_began)  # a client's next request, still arriving: slow or stalled
        return (2, self._last_active)  # a client between two of its requests (keep-alive)

    def _make_room(self) -> bool:
        """Close the least useful connection (see the module docstring), if there is one."""
        ranked = []
        for c in self.connections:
            if isinstance(c, _BoundedH11Protocol):
                rank = c._usefulness()
                if rank is not None:
                    ranked.append((rank, id(c), c))
        if not ranked:
            return False
        _, _, victim = min(ranked)
        self._count("evicted")
        logger.info(
            "HTTP: %d connections open: closing %s to make room", len(self.connections), victim.client
        )
        victim.transport.abort()
        self.connections.discard(victim)
        return True

    # --- the timer ----------------------------------------------------------------------------------
    def _arm_check(self) -> None:
        period = min(
            t for t in (self.idle_timeout_s, self.request_timeout_s, self.write_timeout_s, 3600.0) if t > 0
        )
        self._check_handle = self.loop.call_later(max(period / 4, 0.05), self._check)

    def _check(self) -> None:
        self._check_handle = None
        closing = self.transport.is_closing()
        if closing and self.transport.get_write_buffer_size() == 0:
            return
        now = time.monotonic()
        paused = self._write_paused_at
        if self.write_timeout_s > 0 and paused is not None and now - paused >= self.write_timeout_s:
            self._count("write_stalled")
            logger.info(
                "HTTP: dropping %s: it did not read its answer for %.0f s", self.client, self.write_timeout_s
            )
            self.transport.abort()
            return
        if closing:  # closed with an answer still buffered: wait for the client to take it, or drop it
            self._arm_check()
            return
        began = self._request_began
        if self.request_timeout_s > 0 and began is not None and now - began >= self.request_timeout_s:
            self._time_out_request()
            return
        quiet = self._request_began is None and (self.cycle is None or self.cycle.response_complete)
        if self.idle_timeout_s > 0 and quiet and now - self._last_active >= self.idle_timeout_s:
            self._count("idle_closed")
            self.transport.close()
            return
        self._arm_check()

    def _time_out_request(self) -> None:
        """408 and close: the request did not arrive in time (a stalled body or head)."""
        self._count("timed_out")
        logger.info(
            "HTTP: %s did not send its request within %.0f s (408)", self.client, self.request_timeout_s
        )
        cycle = self.cycle
        if cycle is not None and not cycle.response_complete:
            # the application waits for the body: it sees the client go away, and sends nothing more
            cycle.disconnected = True
            cycle.message_event.set()
            if cycle.response_started:
                self.transport.abort()
                return
        self.transport.write(_TIMEOUT)
        self.transport.close()

    # --- events of the transport --------------------------------------------------------------------
    def data_received(self, data: bytes) -> None:
        now = time.monotonic()
        self._last_active = now
        if self._request_began is None and (self.cycle is None or self.cycle.response_complete):
            self._request_began = now  # the first bytes of a new request
        super().data_received(data)
        self._note_arrival()

    def handle_events(self) -> None:
        super().handle_events()
        self._note_arrival()

    def _note_arrival(self) -> None:
        """The request has arrived whole once h11 says the client is done sending it."""
        if self._request_began is not None and self.conn.their_state in (
            h11.DONE,
            h11.MUST_CLOSE,
            h11.CLOSED,
        ):
            self._request_began = None

    def on_response_complete(self) -> None:
        self._served = True
        super().on_response_complete()
        self._note_arrival()

    def pause_writing(self) -> None:
        self._write_paused_at = time.monotonic()
        super().pause_writing()

    def resume_writing(self) -> None:
        self._write_paused_at = None
        super().resume_writing()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._check_handle is not None:
            self._check_handle.cancel()
            self._check_handle = None
        if self._admitted:
            super().connection_lost(exc)


def abort_stalled(connections: Iterable[object]) -> int:
    """Drop the connections whose clients do not read what they were sent (at shutdown: their answers
    would hold the graceful stop for its whole timeout); how many."""
    dropped = 0
    for c in list(connections):
        if isinstance(c, _BoundedH11Protocol) and c._write_paused_at is not None:
            c.transport.abort()
            dropped += 1
    return dropped


def bounded_protocol(
    max_connections: int,
    idle_timeout_s: float,
    request_timeout_s: float = 10.0,
    write_timeout_s: float = 10.0,
) -> type[Any]:
    """A protocol class for ``uvicorn.Config(http=...)`` with these bounds (one class per adapter)."""
    return type(
        "BoundedH11Protocol",
        (_BoundedH11Protocol,),
        {
            "max_connections": max_connections,
            "idle_timeout_s": idle_timeout_s,
            "request_timeout_s": request_timeout_s,
            "write_timeout_s": write_timeout_s,
            "counters": {},
        },
    )
