"""Device notifications: Add/DeleteDeviceNotification and the samples the cycle sends (H-04, docs/ads.md).

TwinCAT's behaviour, as pyads, ads-client and AdsLib rely on it (Beckhoff Information System, "ADS
Device Notification"; ``AdsSyncAddDeviceNotificationReqEx``: ``nMaxDelay`` "at the latest after this
time the notification is sent", ``nCycleTime`` "the server checks whether the value has changed after
this interval", both in 100 ns):

* **Transmission modes.** Server cycle (3, and 5 "in context") sends a sample every cycle time; server
  on change (4, 6) checks every cycle time and sends when the bytes differ from the last sample sent.
  Modes the client evaluates itself (1, 2) and "no transmission" (0) are refused with 0x713.
* **Cycle time** in 100 ns, rounded up to whole CNC cycles (at least one; 0 = every cycle).
* **Max delay** in 100 ns: a sample is held up to this long (wall-clock time, so that a stepped clock
  that stops stepping still delivers) and goes out with the others taken meanwhile: one
  DeviceNotification with a stamp per sampling time and every sample of one time in its stamp. 0 sends
  each cycle's samples in the next turn of the event loop (and with them whatever waits).
* **The first sample** of every notification follows the add response after ``first_sample_delay_s``
  (AdsLib registers its callback only after reading the response and drops what arrives before).
* **Release**: DeleteDeviceNotification releases one handle (0x714 for one this connection does not
  hold); a connection that closes releases all of its notifications and queued samples at once.
* **The budget is shared fairly** (reliability.md, round 2, finding 5): at most ``max_notifications`` per
connection,
  ``max_notifications_per_net_id`` per client NetId (all its connections together),
  ``max_notifications_per_host`` per remote host (all its NetIds; loopback peers are one computer with
  the server and not limited by this), and ``max_notifications_total`` on the server. So one client can
  never hold the whole budget: eight connections of one NetId asking 256 each get 512 in all and a
  newcomer still finds room. Every refusal is 0x716 and says which bound it met.
* **A newcomer gets its share, the hog pays** (issue 36, finding 9): when the server's budget is full
  (eight NetIds of 256 each on loopback, where the per-host bound does not apply), a NetId that holds
  less than its fair share (``max_notifications_total`` / the NetIds holding any, itself counted) is
  still served: the NetId that holds the most, above that share, loses its newest notification (deleted
  as by DeleteDeviceNotification: no more samples; logged at most every 10 s) to make room.

The cycle's side (:meth:`NotificationService.on_cycle`) does nothing unless a notification is due; then
it takes one copy of each half a due notification watches, compares bytes (on change) and queues the
samples in their session. A session whose client does not read (``backlogged()``) is skipped: its
notifications are not evaluated, and an on-change value is sent once the client drains. No socket is
touched here: the server writes a session's samples in a later turn (:meth:`Session.flush`).
"""

from __future__ import annotations

import heapq
import logging
import time
from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Final

from hli_server.adapters.ads.session import Subscription
from hli_server.codecs.ads import (
    AdsError,
    AmsHeader,
    ErrorCode,
    TransmissionMode,
    unix_ns_to_filetime,
)
from schemas.layout import Direction

if TYPE_CHECKING:
    from hli_server.adapters.ads.session import DeviceLimits, DeviceStats, Session, Watch
    from hli_server.adapters.host import ImagePort

__all__ = ["MAX_PENDING_SAMPLES", "NotificationService"]

logger = logging.getLogger(__name__)

MAX_PENDING_SAMPLES: Final = 8192
"""Samples queued for one connection between two flushes (a long ``step(n)`` runs many cycles without a
turn of the loop); beyond, its notifications are skipped as for a client that does not read."""

_SERVER_MODES: Final = frozenset(
    {
        TransmissionMode.SERVER_CYCLE,
        TransmissionMode.SERVER_ON_CHANGE,
        TransmissionMode.SERVER_CYCLE_IN_CONTEXT,
        TransmissionMode.SERVER_ON_CHANGE_IN_CONTEXT,
    }
)
_ON_CHANGE: Final = frozenset(
    {TransmissionMode.SERVER_ON_CHANGE, TransmissionMode.SERVER_ON_CHANGE_IN_CONTEXT}
)


class _Budget:
    """Notifications held per connection, NetId, remote host and on the server (module docstring)."""

    def __init__(self, limits: DeviceLimits) -> None:
        self.limits = limits
        self.total = 0
        self.by_net_id: dict[bytes, int] = {}
        self.by_host: dict[str, int] = {}

    def check(self, session: Session, net_id: bytes, host: str | None) -> None:
        lim = self.limits
        held = len(session.notifications)
        if held >= lim.max_notifications:
            raise AdsError(
                ErrorCode.NO_MORE_NOTIFICATION_HANDLES,
                f"this connection has {held} notifications (max_notifications {lim.max_notifications})",
            )
        by_id = self.by_net_id.get(net_id, 0)
        if by_id >= lim.max_notifications_per_net_id:
            raise AdsError(
                ErrorCode.NO_MORE_NOTIFICATION_HANDLES,
                f"NetId {'.'.join(str(b) for b in net_id)} holds {by_id} notifications on all its "
                f"connections "
                f"(max_notifications_per_net_id {lim.max_notifications_per_net_id}): delete some first",
            )
        if host is not None:
            by_host = self.by_host.get(host, 0)
            if by_host >= lim.max_notifications_per_host:
                raise AdsError(
                    ErrorCode.NO_MORE_NOTIFICATION_HANDLES,
                    f"host {host} holds {by_host} notifications (max_notifications_per_host "
                    f"{lim.max_notifications_per_host})",
                )
        if self.total >= lim.max_notifications_total:
            raise AdsError(
                ErrorCode.NO_MORE_NOTIFICATION_HANDLES,
                f"the server has {self.total} notifications (max_notifications_total "
                f"{lim.max_notifications_total})",
            )

    def take(self, sub: Subscription) -> None:
        self.total += 1
        self.by_net_id[sub.net_id] = self.by_net_id.get(sub.net_id, 0) + 1
        if sub.host is not None:
            self.by_host[sub.host] = self.by_host.get(sub.host, 0) + 1

    def give_back(self, sub: Subscription) -> None:
        self.total -= 1
        _decrement(self.by_net_id, sub.net_id)
        if sub.host is not None:
            _decrement(self.by_host, sub.host)


def _decrement(counts: dict[bytes, int] | dict[str, int], key: object) -> None:
    left = counts[key] - 1  # type: ignore[index]
    if left:
        counts[key] = left  # type: ignore[index]
    else:
        del counts[key]  # type: ignore[arg-type]


class NotificationService:
    """Add/DeleteDeviceNotification and the cycle's sampling (module docstring)."""

    def __init__(
        self,
        image: ImagePort,
        halves: Callable[[Direction], bytes],
        *,
        t_a_us: int,
        limits: DeviceLimits,
        stats: DeviceStats,
        call_later: Callable[[float, Callable[[], None]], object] | None,
        request_flush: Callable[[Session], None],
        first_sample_delay_s: float,
    ) -> None:
        self.image = image
        self._half = halves
        self.t_a_100ns = max(1, t_a_us * 10)
        self.budget = _Budget(limits)
        self.stats = stats
        self._call_later = call_later
        self._request_flush = request_flush
        self.first_sample_delay_s = first_sample_delay_s
        self._due: dict[int, list[Subscription]] = {}
        self._held: dict[bytes, dict[Subscription, None]] = {}
        """the notifications of each client NetId, oldest first (who holds how many, and the newest)"""
        self._last_eviction_log = -10.0
        self._heap: list[int] = []
        self._delayed: dict[Session, object] = {}
        """sessions holding samples for a max delay: the timer that sends them"""
        self._cycle = image.cycle
        self.on_active: Callable[[bool], None] | None = None
        """called with True when the first notification is added, False when the last one goes (the
        server follows the cycle only meanwhile)"""

    @property
    def count(self) -> int:
        return self.budget.total

    # --- add / delete ---------------------------------------------------------------------------
    def add(
        self,
        session: Session,
        header: AmsHeader,
        watch: Watch,
        mode: int,
        max_delay_100ns: int,
        cycle_time_100ns: int,
    ) -> int:
        if mode not in _SERVER_MODES:
            raise AdsError(
                ErrorCode.TRANSMISSION_MODE_NOT_SUPPORTED,
                f"transmission mode {mode}: this server sends server cycle (3, 5) and server on change "
                "(4, 6)",
            )
        net_id = bytes(header.source_net_id)
        host = session.remote_host
        if self.budget.total >= self.budget.limits.max_notifications_total:
            self._make_room(net_id)
        self.budget.check(session, net_id, host)
        sub = Subscription(
            session,
            session.new_notification_handle(),
            watch,
            on_change=mode in _ON_CHANGE,
            period=max(1, -(-cycle_time_100ns // self.t_a_100ns)),
            max_delay=max_delay_100ns / 1e7,
            client=header.source,
            server=header.target,
            net_id=net_id,
            host=host,
        )
        session.notifications[sub.handle] = sub
        self.budget.take(sub)
        self._held.setdefault(net_id, {})[sub] = None
        if self.budget.total == 1 and self.on_active is not None:
            self.on_active(True)
        if self._call_later is not None and self.first_sample_delay_s > 0:
            self._call_later(self.first_sample_delay_s, lambda: self._first_sample(sub))
        else:
            self._first_sample(sub)
        return sub.handle

    def delete(self, session: Session, handle: int) -> None:
        sub = session.notifications.pop(handle, None)
        if sub is None:
            raise AdsError(
                ErrorCode.NOTIFICATION_HANDLE_INVALID,
                f"no notification handle 0x{handle:X} on this connection",
            )
        sub.deleted = True
        self.budget.give_back(sub)
        self._release(sub)
        session.drop_samples_of(handle)
        self._maybe_idle()

    def close_session(self, session: Session) -> None:
        """The client went away: release its notifications and whatever samples wait for it."""
        for sub in session.notifications.values():
            sub.deleted = True
            self.budget.give_back(sub)
            self._release(sub)
        session.notifications.clear()
        session.discard_pending()
        _cancel(self._delayed.pop(session, None))
        self._maybe_idle()

    def _release(self, sub: Subscription) -> None:
        held = self._held.get(sub.net_id)
        if held is not None:
            held.pop(sub, None)
            if not held:
                del self._held[sub.net_id]

    def _make_room(self, net_id: bytes) -> None:
        """The server's budget is full: if ``net_id`` holds less than its fair share, the NetId holding the
        most (above that share) gives up its newest notification (module docstring)."""
        holders = len(self._held) + (0 if net_id in self._held else 1)
        share = self.budget.limits.max_notifications_total // max(1, holders)
        mine = len(self._held.get(net_id, ()))
        if mine >= share or not self._held:
            return
        hog_id, held = max(self._held.items(), key=lambda item: len(item[1]))
        if len(held) <= share or hog_id == net_id:
            return
        victim = next(reversed(held))
        self.stats.notifications_evicted += 1
        now = time.monotonic()
        if now - self._last_eviction_log >= 10.0:
            self._last_eviction_log = now
            logger.warning(
                "ADS: NetId %s holds %d notifications, more than its share of %d while the server's %d are "
                "taken: its newest (handle 0x%X) makes room for NetId %s (%d evicted so far)",
                ".".join(str(b) for b in hog_id),
                len(held),
                share,
                self.budget.limits.max_notifications_total,
                victim.handle,
                ".".join(str(b) for b in net_id),
                self.stats.notifications_evicted,
            )
        self.delete(victim.session, victim.handle)

    def _maybe_idle(self) -> None:
        if self.budget.total == 0 and self.on_active is not None:
            self.on_active(False)

    # --- sampling -------------------------------------------------------------------------------
    def _first_sample(self, sub: Subscription) -> None:
        """The first sample, whatever the mode and max delay, then the sub is due every ``period``."""
        if sub.deleted:
            return
        data = self._sample(sub, {})
        sub.last = data
        sub.session.queue(sub, unix_ns_to_filetime(time.time_ns()), data)
        self._request_flush(sub.session)
        self._schedule(sub, max(self._cycle, self.image.cycle) + sub.period)

    def _sample(self, sub: Subscription, halves: dict[Direction, bytes]) -> bytes:
        pieces = sub.watch.pieces
        if not pieces:
            return sub.watch.constant
        parts = []
        for direction, start, end in pieces:
            half = halves.get(direction)
            if half is None:
                half = halves[direction] = self._half(direction)
            parts.append(half[start:end])
        return parts[0] if len(parts) == 1 else b"".join(parts)

    def _schedule(self, sub: Subscription, cycle: int) -> None:
        bucket = self._due.get(cycle)
        if bucket is None:
            self._due[cycle] = [sub]
            heapq.heappush(self._heap, cycle)
        else:
            bucket.append(sub)

    def on_cycle(self, cycle: int) -> None:
        """After every published cycle (``host.on_cycle``): sample what is due, queue, ask for flushes.

        Cheap when nothing is due (two comparisons); otherwise one copy per watched half and one bytes
        comparison per due notification.
        """
        self._cycle = cycle
        heap = self._heap
        if heap and heap[0] <= cycle:
            self._sample_due(cycle)

    def _sample_due(self, cycle: int) -> None:
        heap = self._heap
        halves: dict[Direction, bytes] = {}
        filetime = 0
        while heap and heap[0] <= cycle:
            for sub in self._due.pop(heapq.heappop(heap)):
                if sub.deleted:
                    continue
                self._schedule(sub, cycle + sub.period)
                session = sub.session
                if session.pending_samples >= MAX_PENDING_SAMPLES or session.backlogged():
                    self.stats.samples_skipped += 1
                    continue
                data = self._sample(sub, halves)
                if sub.on_change and data == sub.last:
                    continue
                sub.last = data
                if not filetime:
                    filetime = unix_ns_to_filetime(time.time_ns())
                session.queue(sub, filetime, data)
                if sub.max_delay <= 0 or self._call_later is None:
                    _cancel(self._delayed.pop(session, None))
                    self._request_flush(session)
                elif session not in self._delayed:
                    self._delayed[session] = self._call_later(
                        sub.max_delay, partial(self._send_delayed, session)
                    )

    def _send_delayed(self, session: Session) -> None:
        if self._delayed.pop(session, None) is not None:
            self._request_flush(session)


def _cancel(timer: object) -> None:
    cancel = getattr(timer, "cancel", None)
    if cancel is not None:
        cancel()
