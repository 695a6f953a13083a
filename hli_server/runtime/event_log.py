"""The runtime's event log: every engine event with a sequence number (``GET /api/events``, H-05).

The engine keeps no events; it hands each one to its listeners inside the cycle. The log is one of
them: it numbers the events and keeps the newest :data:`EVENT_LOG` for readers who poll
(``since(seq)``); live listeners (MQTT, the dashboard) subscribe through it and are called in the
cycle, in order.
"""

from __future__ import annotations

import contextlib
import logging
from collections import deque
from collections.abc import Callable, Iterable, Sequence

from hli_server.adapters.host import LoggedEvent
from schemas.events import Event

__all__ = ["EVENT_LOG", "EventLog"]

logger = logging.getLogger(__name__)

EVENT_LOG = 10_000
"""Events kept for ``GET /api/events?since=`` (the oldest are dropped first)."""


class EventLog:
    """Numbers and keeps the engine's events; passes them on to subscribers (an :class:`EventFeed`)."""

    def __init__(self, size: int = EVENT_LOG) -> None:
        self._events: deque[LoggedEvent] = deque(maxlen=size)
        self._seq = 0
        self._listeners: list[Callable[[Event], None]] = []

    @property
    def latest(self) -> int:
        return self._seq

    def __call__(self, event: Event) -> None:
        """The engine's listener: log ``event`` and hand it to the subscribers."""
        self._seq += 1
        self._events.append(LoggedEvent(self._seq, event))
        for listener in self._listeners:
            try:
                listener(event)
            except Exception:  # a subscriber's bug must not stop the cycle or the other subscribers
                logger.exception("event subscriber %r failed on %s", listener, event.kind)

    def extend(self, logged: Iterable[tuple[int, Event]]) -> list[Event]:
        """Take events numbered elsewhere (the engine's log, mirrored in the doors process:
        ``runtime/remote.py``); returns them for the caller to hand to :meth:`deliver` when it suits."""
        out = []
        for seq, event in logged:
            self._seq = max(self._seq, seq)
            self._events.append(LoggedEvent(seq, event))
            out.append(event)
        return out

    def deliver(self, events: Iterable[Event]) -> None:
        """Hand ``events`` to the subscribers, in order (what :meth:`__call__` does for one)."""
        for event in events:
            for listener in self._listeners:
                try:
                    listener(event)
                except Exception:  # a subscriber's bug must not stop the others
                    logger.exception("event subscriber %r failed on %s", listener, event.kind)

    def subscribe(self, listener: Callable[[Event], None]) -> Callable[[], None]:
        self._listeners.append(listener)

        def unsubscribe() -> None:
            with contextlib.suppress(ValueError):
                self._listeners.remove(listener)

        return unsubscribe

    def since(self, seq: int = 0, limit: int = 1000) -> tuple[Sequence[LoggedEvent], int]:
        """Events with a sequence number above ``seq`` (oldest first, at most ``limit``), and the newest."""
        out: list[LoggedEvent] = []
        if seq < self._seq:
            for logged in self._events:
                if logged.seq > seq:
                    out.append(logged)
                    if len(out) >= limit:
                        break
        return out, self._seq
