"""What the ADS services stand on: one connection's :class:`Session`, the :class:`DeviceLimits` and
:class:`DeviceStats`, the :class:`PortTable` of one AMS port and what a notification watches (H-04).

The services (:mod:`.system`, :mod:`.data`, :mod:`.symbol_info`, :mod:`.sums`, :mod:`.notifications`)
read these and nothing above them; the dispatcher (:mod:`.device`) builds the tables from the services
and sits on top, so no service imports it (as h11 keeps its state in one module that everything reads).

A :class:`PortTable` is data, index group -> service method per command, and dispatches through itself
(:meth:`PortTable.read_group` and its two siblings): the device's commands and the sum commands'
sub-requests go the same way.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from hli_server.codecs.ads import (
    AdsError,
    AmsAddress,
    CommandId,
    ErrorCode,
    NotificationSample,
    NotificationStamp,
    encode_notification,
    encode_request,
)

if TYPE_CHECKING:
    from hli_server.adapters.ads.symbols import Piece, Symbol

__all__ = [
    "DeviceLimits",
    "DeviceStats",
    "PortTable",
    "ReadHandler",
    "ReadWriteHandler",
    "Session",
    "Subscription",
    "Watch",
    "WatchHandler",
    "WriteHandler",
]


@dataclass(frozen=True, slots=True)
class Watch:
    """Bytes a notification watches: slices of the halves (a value, a structure), or a constant (symbol
    version, ADS state)."""

    pieces: tuple[Piece, ...]
    constant: bytes = b""

    @classmethod
    def of_constant(cls, value: bytes) -> Watch:
        return cls((), value)


@dataclass(slots=True, eq=False)
class Subscription:
    """One device notification of one session."""

    session: Session
    handle: int
    watch: Watch
    on_change: bool
    period: int
    """cycles between checks (on change) or samples (cyclic); at least 1."""
    max_delay: float
    """seconds a sample may wait to go out with later ones (0: the next turn of the loop)."""
    client: AmsAddress
    """where the samples go: the AddDeviceNotification's source."""
    server: AmsAddress
    """the samples' AMS source: the address the client subscribed to (AdsLib dispatches by it)."""
    net_id: bytes
    host: str | None
    """the remote host it counts against (None: a loopback peer)"""
    last: bytes | None = None
    deleted: bool = False


ReadHandler = Callable[["Session", int, int], bytes]
"""(session, index offset, length) -> the bytes read"""
WriteHandler = Callable[["Session", int, bytes], None]
"""(session, index offset, data)"""
ReadWriteHandler = Callable[["Session", int, int, bytes], bytes]
"""(session, index offset, read length, write data) -> the bytes read"""
WatchHandler = Callable[["Session", int, int], Watch]
"""(session, index offset, length) -> what a notification watches"""


@dataclass(slots=True)
class PortTable:
    """What one AMS port serves: its device name and, per command, index group -> service method."""

    port: int
    name: str
    """ReadDeviceInfo's device name"""
    read: dict[int, ReadHandler] = field(default_factory=dict)
    write: dict[int, WriteHandler] = field(default_factory=dict)
    read_write: dict[int, ReadWriteHandler] = field(default_factory=dict)
    watch: dict[int, WatchHandler] = field(default_factory=dict)
    refuse_writes: WriteHandler | None = None
    """answers every Write of the port (port 551: read-only)"""
    hint: str = ""
    """what the port serves, for the 0x702 message"""

    def missing(self, command: str, group: int) -> AdsError:
        """The error for a group this port does not serve with ``command`` (0x701 or 0x702)."""
        served = [
            name
            for name, table in (
                ("Read", self.read),
                ("Write", self.write),
                ("ReadWrite", self.read_write),
            )
            if group in table
        ]
        if served:
            what = "cannot be watched by a notification" if command == "notification" else f"is no {command}"
            return AdsError(
                ErrorCode.SERVICE_NOT_SUPPORTED,
                f"index group 0x{group:X} {what}: it takes {' and '.join(served)}",
            )
        return AdsError(
            ErrorCode.INVALID_INDEX_GROUP, f"port {self.port}: no index group 0x{group:X}; {self.hint}"
        )

    # --- one index group through the table: the device's Read, Write, ReadWrite and the sum commands' items
    def read_group(self, session: Session, group: int, offset: int, length: int) -> bytes:
        serve = self.read.get(group)
        if serve is None:
            raise self.missing("Read", group)
        return serve(session, offset, length)

    def write_group(self, session: Session, group: int, offset: int, data: bytes) -> None:
        if self.refuse_writes is not None:
            self.refuse_writes(session, offset, data)
        serve = self.write.get(group)
        if serve is None:
            raise self.missing("Write", group)
        serve(session, offset, data)

    def read_write_group(
        self, session: Session, group: int, offset: int, read_length: int, data: bytes
    ) -> bytes:
        serve = self.read_write.get(group)
        if serve is None:
            raise self.missing("ReadWrite", group)
        return serve(session, offset, read_length, data)


@dataclass(frozen=True, slots=True)
class DeviceLimits:
    """Per-session, per-client and server-wide bounds (the adapter's options)."""

    max_handles: int = 2048
    max_notifications: int = 256
    max_notifications_per_net_id: int = 512
    max_notifications_per_host: int = 1024
    max_notifications_total: int = 2048
    max_sum_items: int = 500


@dataclass(slots=True)
class DeviceStats:
    """Counters since start (logs, tests, docs/reliability.md)."""

    requests: int = 0
    errors: dict[int, int] = field(default_factory=dict)
    notifications_sent: int = 0
    samples_sent: int = 0
    samples_skipped: int = 0
    """samples not evaluated because the client's output queue was full (it does not read)."""
    failures: int = 0
    """unexpected exceptions while serving a request (answered 0x700 and logged)."""
    notifications_evicted: int = 0
    """notifications of a NetId above its share deleted to make room for a newcomer (the budget full)."""

    def count_error(self, code: int) -> None:
        code = int(code)  # the number, not the ErrorCode member: the same keys compiled and pure
        self.errors[code] = self.errors.get(code, 0) + 1


class Session:
    """One client connection's state: symbol handles, notifications, queued samples.

    ``send`` writes bytes to the client; ``backlogged`` says whether its output queue is full. The server
    sets both; the defaults (a list and False) serve unit tests. ``remote_host`` is the peer's address when
    it is not a loopback one (the notification budget per host).
    """

    def __init__(
        self,
        send: Callable[[bytes], None] | None = None,
        backlogged: Callable[[], bool] | None = None,
        name: str = "session",
        remote_host: str | None = None,
    ) -> None:
        self.name = name
        self.remote_host = remote_host
        self.sent: list[bytes] = []
        self.send: Callable[[bytes], None] = send if send is not None else self.sent.append
        self.backlogged: Callable[[], bool] = backlogged if backlogged is not None else (lambda: False)
        self.handles: dict[int, Symbol] = {}
        self._next_handle = 0x1000_0001
        self.notifications: dict[int, Subscription] = {}
        self._next_notification = 0x100
        self._pending: dict[tuple[AmsAddress, AmsAddress], list[tuple[int, list[NotificationSample]]]] = {}
        self.pending_samples = 0
        self.closed = False

    def new_handle(self, symbol: Symbol) -> int:
        while self._next_handle in self.handles or self._next_handle == 0:
            self._next_handle = (self._next_handle + 1) & 0xFFFF_FFFF
        handle = self._next_handle
        self._next_handle = (handle + 1) & 0xFFFF_FFFF
        self.handles[handle] = symbol
        return handle

    def new_notification_handle(self) -> int:
        while self._next_notification in self.notifications or self._next_notification == 0:
            self._next_notification = (self._next_notification + 1) & 0xFFFF_FFFF
        handle = self._next_notification
        self._next_notification = (handle + 1) & 0xFFFF_FFFF
        return handle

    @property
    def has_pending(self) -> bool:
        return bool(self._pending)

    def queue(self, sub: Subscription, filetime: int, data: bytes) -> None:
        """One sample; samples of one time share a stamp (TwinCAT packs them so)."""
        stamps = self._pending.get((sub.client, sub.server))
        if stamps is None:
            stamps = self._pending[(sub.client, sub.server)] = []
        self.pending_samples += 1
        if stamps and stamps[-1][0] == filetime:
            stamps[-1][1].append(NotificationSample(sub.handle, data))
        else:
            stamps.append((filetime, [NotificationSample(sub.handle, data)]))

    def drop_samples_of(self, handle: int) -> None:
        """A released notification sends nothing more, not even what waits (DeleteDeviceNotification)."""
        for key, stamps in list(self._pending.items()):
            kept = []
            for filetime, batch in stamps:
                rest = [s for s in batch if s.handle != handle]
                self.pending_samples -= len(batch) - len(rest)
                if rest:
                    kept.append((filetime, rest))
            if kept:
                self._pending[key] = kept
            else:
                del self._pending[key]

    def discard_pending(self) -> None:
        self._pending.clear()
        self.pending_samples = 0

    def flush(self) -> tuple[int, int]:
        """Write the queued samples, one DeviceNotification per (client, server) address pair;
        returns (frames, samples)."""
        self.pending_samples = 0
        if not self._pending or self.closed:
            self._pending.clear()
            return 0, 0
        pending, self._pending = self._pending, {}
        frames = samples = 0
        for (client, server), stamps in pending.items():
            payload = encode_notification([NotificationStamp(t, tuple(batch)) for t, batch in stamps])
            self.send(encode_request(client, server, CommandId.DEVICE_NOTIFICATION, 0, payload))
            frames += 1
            samples += sum(len(batch) for _, batch in stamps)
        return frames, samples
