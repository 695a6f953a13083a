"""The ADS device: requests in, replies out, served from the process image; no sockets (H-04, C3-10).

:class:`AdsDevice` answers decoded AMS frames for one :class:`Session` (one TCP connection) and runs
the device notifications from the cycle. It does no I/O: the asyncio server
(:mod:`hli_server.adapters.ads.server`) feeds it frames and gives each session two hooks,
``send(bytes)`` and ``backlogged()``, so the unit tests and the fuzz test drive it without a network.

AMS ports and what they serve (``docs/ads.md`` has the table for users)::

    851  HLI        Read/Write  0xF030  PLC->CNC half, offset = byte offset (whole fields on write)
                    Read        0xF020  CNC->PLC half (newest consistent publish); Write = 0x704
                    Read/Write  0xF005  value by handle (offset = handle; length = the symbol's size)
                    ReadWrite   0xF003  handle by name;  Write 0xF006 release handle
                    ReadWrite   0xF004  value by name;   0xF009 symbol info;  0xF011 data type by name
                    Read        0xF008  symbol version;  0xF00B/0xF00E uploads;  0xF00C/0xF00F upload info
                    Read        0xF100  ADS state (RUN) and device state
                    ReadWrite   0xF080/0xF081/0xF082 sum read / write / read-write (offset = count)
    551  GEO        Read        0x120300 the dyn_coll_mon objects, offset (A_ID << 16) | element, exact
                                         size (FCT-C3 4.3, C3-10); every Write on port 551 = 0x704
    both            ReadDeviceInfo, ReadState (RUN), WriteControl (RUN only),
                    Add/DeleteDeviceNotification on every readable data address above

Errors carry their ADS code from where they are raised (:class:`AdsError`): unknown index group
0x702, unknown offset or an offset inside a field 0x703, a write to a CNC->PLC value or on port
551 0x704, a length that does not fit 0x705, a value the field cannot take 0x706, an unknown symbol
or handle 0x710, a command that is no request 0x701, a transmission mode other than server cycle /
server on change 0x713, an unknown notification handle 0x714, no notification handle left 0x716.
AMS-level errors (in the AMS header, no payload): another NetId than the server's 0x7, a port
other than 851/551 0x6.

Device notifications: :meth:`AdsDevice.on_cycle` runs after every published cycle. It does nothing
unless a notification is due in this cycle; then it takes one copy of each half that a due
notification watches, compares bytes per notification (on change) and queues the samples in their
session. The session's frames are built and written by the server in a later turn of the loop
(:meth:`Session.flush`), so several cycles caught up at once go out as one frame with several
stamps. A session whose client does not read (``backlogged()``) is skipped: its notifications are
not evaluated, and an on-change value is sent once the client drains.
"""

from __future__ import annotations

import heapq
import logging
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

from hli_server.adapters.ads.symbols import Symbol, SymbolTable
from hli_server.codecs.ads import (
    AddDeviceNotificationRequest,
    AddDeviceNotificationResponse,
    AdsError,
    AdsState,
    AmsAddress,
    AmsHeader,
    AmsPacket,
    CommandId,
    DeleteDeviceNotificationRequest,
    DeleteDeviceNotificationResponse,
    ErrorCode,
    HandleInfo,
    IndexGroup,
    NotificationSample,
    NotificationStamp,
    ReadDeviceInfoRequest,
    ReadDeviceInfoResponse,
    ReadRequest,
    ReadResponse,
    ReadStateRequest,
    ReadStateResponse,
    ReadWriteRequest,
    ReadWriteResponse,
    SumRead,
    SumReadWrite,
    SumWrite,
    TransmissionMode,
    WriteControlRequest,
    WriteControlResponse,
    WriteRequest,
    WriteResponse,
    decode_name,
    decode_request,
    encode_error_response,
    encode_handle_reply,
    encode_notification,
    encode_request,
    encode_response,
    encode_sum_read_reply,
    encode_sum_read_write_reply,
    encode_sum_write_reply,
    error_reply_payload,
    unix_ns_to_filetime,
)
from schemas.layout import (
    ADS_GROUP_CNC_TO_PLC,
    ADS_GROUP_GEO_AXIS,
    ADS_GROUP_PLC_TO_CNC,
    ADS_PORT_GEO,
    ADS_PORT_HLI,
    Direction,
    LayoutError,
    ReadOnlySignalError,
    Signal,
    SignalValueError,
)

if TYPE_CHECKING:
    from hli_server.adapters.host import ImagePort
    from hli_server.codecs.ads import NetId

__all__ = ["SERVED_PORTS", "AdsDevice", "DeviceLimits", "DeviceStats", "Session", "Subscription"]

logger = logging.getLogger(__name__)

SERVED_PORTS: Final = (ADS_PORT_HLI, ADS_PORT_GEO)
DEVICE_NAMES: Final = {ADS_PORT_HLI: "HLI-Server", ADS_PORT_GEO: "HLI-Server GEO"}
DEVICE_VERSION: Final = (0, 1, 0)
"""ReadDeviceInfo: major, minor, build (the package's version)."""

MAX_PENDING_SAMPLES: Final = 8192
"""Samples queued for one connection between two turns of the loop (a long ``step(n)`` runs many
cycles without one); beyond, its notifications are skipped as for a client that does not read."""

_P2C: Final = Direction.PLC_TO_CNC
_C2P: Final = Direction.CNC_TO_PLC
_U32: Final = struct.Struct("<I")
_STATE: Final = struct.Struct("<HH").pack(AdsState.RUN, 0)
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
_READ_WRITE_ONLY: Final = frozenset(
    {
        IndexGroup.SYM_HANDLE_BY_NAME,
        IndexGroup.SYM_VALUE_BY_NAME,
        IndexGroup.SYM_INFO_BY_NAME_EX,
        IndexGroup.DATA_TYPE_INFO_BY_NAME_EX,
        IndexGroup.SUMUP_READ,
        IndexGroup.SUMUP_WRITE,
        IndexGroup.SUMUP_READWRITE,
    }
)
_READ_ONLY_GROUPS: Final = frozenset(
    {
        IndexGroup.SYM_VERSION,
        IndexGroup.SYM_UPLOAD,
        IndexGroup.SYM_UPLOAD_INFO,
        IndexGroup.SYM_DT_UPLOAD,
        IndexGroup.SYM_UPLOAD_INFO2,
        IndexGroup.DEVICE_DATA,
    }
)


def _error(code: ErrorCode, message: str) -> AdsError:
    return AdsError(code, message)


@dataclass(frozen=True, slots=True)
class DeviceLimits:
    """Per-session and server-wide bounds (the adapter's options)."""

    max_handles: int = 2048
    max_notifications: int = 256
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

    def count_error(self, code: int) -> None:
        self.errors[code] = self.errors.get(code, 0) + 1


@dataclass(frozen=True, slots=True)
class _Watch:
    """Bytes a notification watches: a slice of one half, or a constant (symbol version, ADS state)."""

    direction: Direction | None
    start: int
    end: int
    constant: bytes = b""


@dataclass(slots=True, eq=False)
class Subscription:
    """One device notification of one session."""

    session: Session
    handle: int
    watch: _Watch
    on_change: bool
    period: int
    """cycles between checks (on change) or samples (cyclic); at least 1."""
    client: AmsAddress
    """where the samples go: the AddDeviceNotification's source."""
    server: AmsAddress
    """the samples' AMS source: the address the client subscribed to (AdsLib dispatches by it)."""
    last: bytes | None = None
    deleted: bool = False


class Session:
    """One client connection's state: symbol handles, notifications, queued samples.

    ``send`` writes bytes to the client; ``backlogged`` says whether its output queue is full. The
    server sets both; the defaults (a list and False) serve unit tests.
    """

    def __init__(
        self,
        send: Callable[[bytes], None] | None = None,
        backlogged: Callable[[], bool] | None = None,
        name: str = "session",
    ) -> None:
        self.name = name
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
        stamps = self._pending.get((sub.client, sub.server))
        if stamps is None:
            stamps = self._pending[(sub.client, sub.server)] = []
        self.pending_samples += 1
        if stamps and stamps[-1][0] == filetime:
            stamps[-1][1].append(NotificationSample(sub.handle, data))
        else:
            stamps.append((filetime, [NotificationSample(sub.handle, data)]))

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


class _Halves:
    """The two halves as bytes: CNC->PLC copied once per publish, PLC->CNC read live."""

    __slots__ = ("_c2p", "_c2p_count", "image", "sizes")

    def __init__(self, image: ImagePort) -> None:
        self.image = image
        self.sizes = {d: image.layout.size(d) for d in Direction}
        self._c2p = b""
        self._c2p_count = -1

    def c2p(self) -> bytes:
        count = self.image.publish_count
        if count != self._c2p_count:
            self._c2p = self.image.snapshot()[1]
            self._c2p_count = count
        return self._c2p

    def p2c(self) -> bytes:
        return self.image.read_half(_P2C)

    def get(self, direction: Direction) -> bytes:
        return self.c2p() if direction is _C2P else self.p2c()


class AdsDevice:
    """Serves AMS frames from an image; runs the notifications from the cycle (module docstring)."""

    def __init__(
        self,
        image: ImagePort,
        net_id: NetId,
        *,
        t_a_us: int = 1000,
        limits: DeviceLimits | None = None,
        call_later: Callable[[float, Callable[[], None]], object] | None = None,
        request_flush: Callable[[Session], None] | None = None,
        first_sample_delay_s: float = 0.03,
        read_only: bool = False,
    ) -> None:
        self.image = image
        self.read_only = read_only
        """``--read-only``: every write is refused with 0x704 (issue 12)."""
        self.layout = image.layout
        self.net_id = net_id
        self.t_a_100ns = max(1, t_a_us * 10)
        self.limits = limits or DeviceLimits()
        self.symbols = SymbolTable(self.layout)
        self.halves = _Halves(image)
        self.stats = DeviceStats()
        self.first_sample_delay_s = first_sample_delay_s
        self._call_later = call_later
        self._request_flush = request_flush or (lambda session: None)  # no loop: call session.flush()
        self._geo: dict[int, Signal] = {
            s.ads_offset: s for s in self.layout.signals if s.ads_port == ADS_PORT_GEO
        }
        self._p2c_inside = _interior(self.layout.half(_P2C))
        self._notification_count = 0
        self._due: dict[int, list[Subscription]] = {}
        self._heap: list[int] = []
        self._cycle = image.cycle

    # =========================================================================================
    # Frames
    # =========================================================================================
    def handle(self, session: Session, packet: AmsPacket) -> bytes | None:
        """The reply to one AMS frame (None: no reply, e.g. a response sent by the client)."""
        header = packet.header
        if header.is_response:
            return None
        self.stats.requests += 1
        if header.target_net_id != self.net_id:
            self.stats.count_error(ErrorCode.TARGET_MACHINE_NOT_FOUND)
            logger.debug("ADS: request for NetId %s, this server is %s", header.target_net_id, self.net_id)
            return encode_error_response(header, ErrorCode.TARGET_MACHINE_NOT_FOUND)
        if header.target_port not in SERVED_PORTS:
            self.stats.count_error(ErrorCode.TARGET_PORT_NOT_FOUND)
            return encode_error_response(header, ErrorCode.TARGET_PORT_NOT_FOUND)
        try:
            request = decode_request(header.command, packet.data)
            payload = self._serve(session, header, request)
        except AdsError as exc:
            self.stats.count_error(exc.code)
            logger.debug("ADS %s port %d: %s", session.name, header.target_port, exc)
            return encode_response(header, error_reply_payload(header.command, exc.code))
        except Exception:
            self.stats.failures += 1
            self.stats.count_error(ErrorCode.GENERAL_DEVICE_ERROR)
            logger.exception("ADS: request %s from %s failed", header, session.name)
            return encode_response(
                header, error_reply_payload(header.command, ErrorCode.GENERAL_DEVICE_ERROR)
            )
        return encode_response(header, payload)

    def _serve(self, session: Session, header: AmsHeader, request: object) -> bytes:
        port = header.target_port
        if isinstance(request, ReadRequest):
            data = self.read(session, port, request.index_group, request.index_offset, request.length)
            return ReadResponse(0, data).encode()
        if isinstance(request, WriteRequest):
            self.write(session, port, request.index_group, request.index_offset, request.data)
            return WriteResponse(0).encode()
        if isinstance(request, ReadWriteRequest):
            data = self.read_write(
                session, port, request.index_group, request.index_offset, request.read_length, request.data
            )
            return ReadWriteResponse(0, data).encode()
        if isinstance(request, AddDeviceNotificationRequest):
            handle = self.add_notification(session, header, request)
            return AddDeviceNotificationResponse(0, handle).encode()
        if isinstance(request, DeleteDeviceNotificationRequest):
            self.delete_notification(session, request.handle)
            return DeleteDeviceNotificationResponse(0).encode()
        if isinstance(request, ReadStateRequest):
            return ReadStateResponse(0, AdsState.RUN, 0).encode()
        if isinstance(request, ReadDeviceInfoRequest):
            major, minor, build = DEVICE_VERSION
            return ReadDeviceInfoResponse(0, major, minor, build, DEVICE_NAMES[port]).encode()
        if isinstance(request, WriteControlRequest):
            if request.ads_state != AdsState.RUN:
                name = AdsState(request.ads_state).name if request.ads_state in set(AdsState) else "unknown"
                raise _error(
                    ErrorCode.SERVICE_NOT_SUPPORTED,
                    f"WriteControl to ADS state {request.ads_state} ({name}): the simulated CNC stays in "
                    "RUN; stop it with SIGTERM / Ctrl+C of `hli-server run`",
                )
            return WriteControlResponse(0).encode()
        raise _error(ErrorCode.SERVICE_NOT_SUPPORTED, f"{type(request).__name__} is not served")

    # =========================================================================================
    # Read
    # =========================================================================================
    def read(self, session: Session, port: int, group: int, offset: int, length: int) -> bytes:
        """The bytes of a Read (raises AdsError)."""
        if port == ADS_PORT_GEO:
            return self._read_geo(group, offset, length)
        if group in (ADS_GROUP_CNC_TO_PLC, ADS_GROUP_PLC_TO_CNC):
            direction = _C2P if group == ADS_GROUP_CNC_TO_PLC else _P2C
            self._check_range(direction, group, offset, length)
            return self.halves.get(direction)[offset : offset + length]
        if group == IndexGroup.SYM_VALUE_BY_HANDLE:
            symbol = self._handle(session, offset)
            _check_size(symbol, length, "read")
            return self._symbol_value(symbol)
        if group in _READ_ONLY_GROUPS:
            return self._read_service(group, offset, length)
        if group in _READ_WRITE_ONLY:
            raise _error(
                ErrorCode.SERVICE_NOT_SUPPORTED,
                f"index group 0x{group:X} takes ReadWrite (name or sub-requests in), not Read",
            )
        raise _unknown_group(port, group)

    def _read_geo(self, group: int, offset: int, length: int) -> bytes:
        if group != ADS_GROUP_GEO_AXIS:
            raise _unknown_group(ADS_PORT_GEO, group)
        signal = self._geo.get(offset)
        if signal is None:
            axes = ", ".join(f"{a.name}=0x{a.number:X}" for a in self.layout.axes)
            raise _error(
                ErrorCode.INVALID_INDEX_OFFSET,
                f"port 551 group 0x{group:X}: no CNC object at offset 0x{offset:08X}; the offset is "
                f"(A_ID << 16) | element, A_ID of the axes: {axes}; elements 0x0234 active, 0x0244 "
                "velocity, 0x0245 brake_dist, 0x0246 coll_offset, 0x0247 deceleration (FCT-C3 4.3)",
            )
        if length != signal.size:
            raise _error(
                ErrorCode.SIZE_WRONG,
                f"port 551 0x{group:X}/0x{offset:08X} is {signal.name} ({signal.type}, {signal.size} bytes), "
                f"read asked {length} bytes",
            )
        return self.halves.c2p()[signal.offset : signal.offset + signal.size]

    def _check_range(self, direction: Direction, group: int, offset: int, length: int) -> None:
        size = self.halves.sizes[direction]
        if offset > size:
            raise _error(
                ErrorCode.INVALID_INDEX_OFFSET,
                f"index group 0x{group:X} ({direction} half) has {size} bytes, offset {offset} lies beyond",
            )
        if offset + length > size:
            raise _error(
                ErrorCode.SIZE_WRONG,
                f"index group 0x{group:X} ({direction} half, {size} bytes): {length} bytes from offset "
                f"{offset} run past its end",
            )

    def _symbol_value(self, symbol: Symbol) -> bytes:
        s = symbol.signal
        half = self.halves.c2p() if s.direction is _C2P else self.halves.p2c()
        return half[s.offset : s.offset + s.size]

    def _handle(self, session: Session, handle: int) -> Symbol:
        symbol = session.handles.get(handle)
        if symbol is None:
            raise _error(
                ErrorCode.SYMBOL_NOT_FOUND,
                f"no symbol handle 0x{handle:X} on this connection (handles live as long as their "
                "connection; get one with 0xF003)",
            )
        return symbol

    def _read_service(self, group: int, offset: int, length: int) -> bytes:
        t = self.symbols
        if group == IndexGroup.SYM_VERSION:
            data = bytes((t.version,))
        elif group == IndexGroup.SYM_UPLOAD:
            data = t.upload
        elif group == IndexGroup.SYM_UPLOAD_INFO:
            data = t.upload_info
        elif group == IndexGroup.SYM_DT_UPLOAD:
            data = t.type_upload
        elif group == IndexGroup.SYM_UPLOAD_INFO2:
            data = t.upload_info2_long if length >= len(t.upload_info2_long) else t.upload_info2
        else:  # DEVICE_DATA: ADS state and device state
            data = _STATE
        if length < len(data):
            raise _error(
                ErrorCode.SIZE_WRONG,
                f"index group 0x{group:X} answers {len(data)} bytes, the read asked only {length}",
            )
        return data

    # =========================================================================================
    # Write
    # =========================================================================================
    def write(self, session: Session, port: int, group: int, offset: int, data: bytes) -> None:
        """Perform a Write (raises AdsError; a refused write changes nothing)."""
        if port == ADS_PORT_GEO:
            raise _error(
                ErrorCode.READ_WRITE_NOT_PERMITTED,
                "port 551 serves the CNC objects of FCT-C3 4.3 read-only (C3-10)",
            )
        if group == ADS_GROUP_PLC_TO_CNC:
            self._write_p2c(offset, data)
            return
        if group == ADS_GROUP_CNC_TO_PLC:
            raise _error(
                ErrorCode.READ_WRITE_NOT_PERMITTED,
                "index group 0xF020 is the CNC->PLC half: only the CNC writes it (H-02); "
                "the PLC writes the _w fields in 0xF030",
            )
        if group == IndexGroup.SYM_VALUE_BY_HANDLE:
            self._write_symbol(self._handle(session, offset), data)
            return
        if group == IndexGroup.SYM_RELEASE_HANDLE:
            if len(data) != 4:
                raise _error(ErrorCode.SIZE_WRONG, f"0xF006 takes a 4-byte handle, got {len(data)} bytes")
            handle = _U32.unpack(data)[0]
            if session.handles.pop(handle, None) is None:
                raise _error(ErrorCode.SYMBOL_NOT_FOUND, f"0xF006: no symbol handle 0x{handle:X} to release")
            return
        if group in _READ_ONLY_GROUPS or group in _READ_WRITE_ONLY:
            raise _error(ErrorCode.SERVICE_NOT_SUPPORTED, f"index group 0x{group:X} takes no Write")
        raise _unknown_group(port, group)

    def _write_symbol(self, symbol: Symbol, data: bytes) -> None:
        s = symbol.signal
        _check_size(symbol, len(data), "write")
        if not s.plc_writable:
            raise _error(ErrorCode.READ_WRITE_NOT_PERMITTED, _read_only_text(s))
        self._write_p2c(s.offset, data)

    def _write_p2c(self, offset: int, data: bytes) -> None:
        if self.read_only:
            raise _error(
                ErrorCode.READ_WRITE_NOT_PERMITTED, "the server runs --read-only: writes are refused"
            )
        size = self.halves.sizes[_P2C]
        end = offset + len(data)
        if offset > size or offset in self._p2c_inside:
            where = "lies beyond the half" if offset > size else "is inside a field"
            raise _error(
                ErrorCode.INVALID_INDEX_OFFSET,
                f"0xF030 (PLC->CNC half, {size} bytes): offset {offset} {where}; write whole fields "
                "from their offset (`hli-server map` lists them)",
            )
        if end > size or end in self._p2c_inside:
            raise _error(
                ErrorCode.SIZE_WRONG,
                f"0xF030: {len(data)} bytes from offset {offset} "
                + ("run past the half's end" if end > size else "end inside a field: write whole fields"),
            )
        try:
            self.image.write_bytes(offset, data)
        except SignalValueError as exc:
            raise _error(ErrorCode.INVALID_VALUE, f"0xF030 offset {offset}: {exc}") from None
        except ReadOnlySignalError as exc:  # pragma: no cover - the half holds only _w fields
            raise _error(ErrorCode.READ_WRITE_NOT_PERMITTED, str(exc)) from None
        except LayoutError as exc:  # pragma: no cover - the checks above cover what it refuses
            raise _error(ErrorCode.SIZE_WRONG, str(exc)) from None

    # =========================================================================================
    # ReadWrite: symbol services and sum commands
    # =========================================================================================
    def read_write(
        self, session: Session, port: int, group: int, offset: int, read_length: int, data: bytes
    ) -> bytes:
        if group == IndexGroup.SUMUP_READ:
            return self._sum_read(session, port, offset, read_length, data)
        if group == IndexGroup.SUMUP_WRITE:
            return self._sum_write(session, port, offset, read_length, data)
        if group == IndexGroup.SUMUP_READWRITE:
            return self._sum_read_write(session, port, offset, read_length, data)
        if port != ADS_PORT_HLI:
            raise _unknown_group(port, group)
        if group == IndexGroup.SYM_HANDLE_BY_NAME:
            symbol = self._symbol(data)
            if len(session.handles) >= self.limits.max_handles:
                raise _error(
                    ErrorCode.NO_MEMORY,
                    f"this connection holds {len(session.handles)} symbol handles (max_handles); "
                    "release some with 0xF006",
                )
            if read_length < 4:
                raise _error(
                    ErrorCode.SIZE_WRONG, f"0xF003 answers a 4-byte handle, read length {read_length}"
                )
            handle = session.new_handle(symbol)
            s = symbol.signal
            return encode_handle_reply(read_length, HandleInfo(handle, s.size, s.type.value))
        if group == IndexGroup.SYM_VALUE_BY_NAME:
            symbol = self._symbol(data)
            _check_size(symbol, read_length, "read")
            return self._symbol_value(symbol)
        if group == IndexGroup.SYM_INFO_BY_NAME_EX:
            symbol = self._symbol(data)
            if read_length < len(symbol.entry):
                raise _error(
                    ErrorCode.SIZE_WRONG,
                    f"symbol info of {symbol.signal.st_path} is {len(symbol.entry)} bytes, read length "
                    f"{read_length}",
                )
            return symbol.entry
        if group == IndexGroup.DATA_TYPE_INFO_BY_NAME_EX:
            name = decode_name(data)
            entry = self.symbols.data_type(name)
            if entry is None:
                raise _error(
                    ErrorCode.SYMBOL_NOT_FOUND,
                    f"no data type {name!r}: the image has the base types BOOL, DINT, UDINT, LREAL",
                )
            if read_length < len(entry):
                raise _error(
                    ErrorCode.SIZE_WRONG, f"data type {name} is {len(entry)} bytes, read {read_length}"
                )
            return entry
        if group in (ADS_GROUP_CNC_TO_PLC, ADS_GROUP_PLC_TO_CNC, IndexGroup.SYM_VALUE_BY_HANDLE):
            raise _error(
                ErrorCode.SERVICE_NOT_SUPPORTED,
                f"index group 0x{group:X} takes Read and Write, not ReadWrite",
            )
        if group in _READ_ONLY_GROUPS:
            raise _error(
                ErrorCode.SERVICE_NOT_SUPPORTED, f"index group 0x{group:X} takes Read, not ReadWrite"
            )
        raise _unknown_group(port, group)

    def _symbol(self, data: bytes) -> Symbol:
        name = decode_name(data)
        symbol = self.symbols.find(name)
        if symbol is None:
            raise _error(
                ErrorCode.SYMBOL_NOT_FOUND,
                f"no symbol {name[:200]!r}: symbols are the ST paths of `hli-server map`, e.g. "
                "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w "
                "(also spelt gpAx[0].ipo_... and gpAx[0]^.ipo_...)",
            )
        return symbol

    def _sum_count(self, count: int, what: str) -> None:
        if count > self.limits.max_sum_items:
            raise _error(
                ErrorCode.SIZE_WRONG,
                f"{what} of {count} sub-requests: at most {self.limits.max_sum_items} per sum command",
            )

    def _sum_read(self, session: Session, port: int, count: int, read_length: int, data: bytes) -> bytes:
        self._sum_count(count, "sum read 0xF080")
        request = SumRead.decode(count, data)
        if read_length < request.reply_length:
            raise _error(
                ErrorCode.SIZE_WRONG,
                f"sum read of {count}: the reply is {request.reply_length} bytes, read length {read_length}",
            )
        results: list[tuple[int, bytes]] = []
        for item in request.items:
            try:
                results.append(
                    (0, self.read(session, port, item.index_group, item.index_offset, item.length))
                )
            except AdsError as exc:
                self.stats.count_error(exc.code)
                results.append((int(exc.code), b""))
        return encode_sum_read_reply(request, results)

    def _sum_write(self, session: Session, port: int, count: int, read_length: int, data: bytes) -> bytes:
        self._sum_count(count, "sum write 0xF081")
        request = SumWrite.decode(count, data)
        if read_length < 4 * count:
            raise _error(ErrorCode.SIZE_WRONG, f"sum write of {count}: the reply is {4 * count} bytes")
        results: list[int] = []
        for item in request.items:
            try:
                self.write(session, port, item.index_group, item.index_offset, item.data)
                results.append(0)
            except AdsError as exc:
                self.stats.count_error(exc.code)
                results.append(int(exc.code))
        return encode_sum_write_reply(results)

    def _sum_read_write(
        self, session: Session, port: int, count: int, read_length: int, data: bytes
    ) -> bytes:
        self._sum_count(count, "sum read/write 0xF082")
        request = SumReadWrite.decode(count, data)
        results: list[tuple[int, bytes]] = []
        for item in request.items:
            try:
                results.append(
                    (
                        0,
                        self.read_write(
                            session, port, item.index_group, item.index_offset, item.read_length, item.data
                        ),
                    )
                )
            except AdsError as exc:
                self.stats.count_error(exc.code)
                results.append((int(exc.code), b""))
        reply = encode_sum_read_write_reply(results)
        if read_length < len(reply):
            raise _error(
                ErrorCode.SIZE_WRONG,
                f"sum read/write of {count}: the reply is {len(reply)} bytes, read length {read_length}",
            )
        return reply

    # =========================================================================================
    # Device notifications
    # =========================================================================================
    def _watch(self, session: Session, port: int, group: int, offset: int, length: int) -> _Watch:
        if length <= 0:
            raise _error(ErrorCode.SIZE_WRONG, "a device notification watches at least 1 byte")
        if port == ADS_PORT_GEO:
            self._read_geo(group, offset, length)  # raises for an unknown address or a wrong size
            s = self._geo[offset]
            return _Watch(_C2P, s.offset, s.offset + s.size)
        if group in (ADS_GROUP_CNC_TO_PLC, ADS_GROUP_PLC_TO_CNC):
            direction = _C2P if group == ADS_GROUP_CNC_TO_PLC else _P2C
            self._check_range(direction, group, offset, length)
            return _Watch(direction, offset, offset + length)
        if group == IndexGroup.SYM_VALUE_BY_HANDLE:
            symbol = self._handle(session, offset)
            _check_size(symbol, length, "watch")
            s = symbol.signal
            return _Watch(s.direction, s.offset, s.offset + s.size)
        if group in (IndexGroup.SYM_VERSION, IndexGroup.DEVICE_DATA):
            value = self._read_service(group, offset, max(length, 4))
            return _Watch(None, 0, 0, value[:length])
        if group in _READ_ONLY_GROUPS or group in _READ_WRITE_ONLY:
            raise _error(
                ErrorCode.SERVICE_NOT_SUPPORTED,
                f"index group 0x{group:X} cannot be watched by a notification",
            )
        raise _unknown_group(port, group)

    def add_notification(
        self, session: Session, header: AmsHeader, request: AddDeviceNotificationRequest
    ) -> int:
        mode = request.transmission_mode
        if mode not in _SERVER_MODES:
            raise _error(
                ErrorCode.TRANSMISSION_MODE_NOT_SUPPORTED,
                f"transmission mode {mode}: this server sends server cycle (3) and server on change (4)",
            )
        watch = self._watch(
            session, header.target_port, request.index_group, request.index_offset, request.length
        )
        if len(session.notifications) >= self.limits.max_notifications:
            raise _error(
                ErrorCode.NO_MORE_NOTIFICATION_HANDLES,
                f"this connection has {len(session.notifications)} notifications (max_notifications)",
            )
        if self._notification_count >= self.limits.max_notifications_total:
            raise _error(
                ErrorCode.NO_MORE_NOTIFICATION_HANDLES,
                f"the server has {self._notification_count} notifications (max_notifications_total)",
            )
        # cycle time in 100 ns (pyads and ads-client send ms * 10 000): whole cycles, at least one
        period = max(1, -(-request.cycle_time // self.t_a_100ns))
        handle = session.new_notification_handle()
        sub = Subscription(
            session,
            handle,
            watch,
            on_change=mode in _ON_CHANGE,
            period=period,
            client=header.source,
            server=header.target,
        )
        session.notifications[handle] = sub
        self._notification_count += 1
        if self._call_later is not None and self.first_sample_delay_s > 0:
            self._call_later(self.first_sample_delay_s, lambda: self._first_sample(sub))
        else:
            self._first_sample(sub)
        return handle

    def _first_sample(self, sub: Subscription) -> None:
        """The first sample, whatever the mode, then the sub is due every ``period`` cycles."""
        if sub.deleted:
            return
        data = self._sample(sub, {})
        sub.last = data
        sub.session.queue(sub, unix_ns_to_filetime(time.time_ns()), data)
        self._request_flush(sub.session)
        self._schedule(sub, max(self._cycle, self.image.cycle) + sub.period)

    def _sample(self, sub: Subscription, halves: dict[Direction, bytes]) -> bytes:
        w = sub.watch
        if w.direction is None:
            return w.constant
        half = halves.get(w.direction)
        if half is None:
            half = halves[w.direction] = self.halves.get(w.direction)
        return half[w.start : w.end]

    def _schedule(self, sub: Subscription, cycle: int) -> None:
        bucket = self._due.get(cycle)
        if bucket is None:
            self._due[cycle] = [sub]
            heapq.heappush(self._heap, cycle)
        else:
            bucket.append(sub)

    def delete_notification(self, session: Session, handle: int) -> None:
        sub = session.notifications.pop(handle, None)
        if sub is None:
            raise _error(
                ErrorCode.NOTIFICATION_HANDLE_INVALID,
                f"no notification handle 0x{handle:X} on this connection",
            )
        sub.deleted = True
        self._notification_count -= 1

    def close_session(self, session: Session) -> None:
        """The client went away: release its handles and notifications."""
        session.closed = True
        for sub in session.notifications.values():
            sub.deleted = True
        self._notification_count -= len(session.notifications)
        session.notifications.clear()
        session.handles.clear()

    @property
    def notification_count(self) -> int:
        return self._notification_count

    def on_cycle(self, cycle: int) -> None:
        """After every published cycle (``host.on_cycle``): sample what is due, queue, ask for a flush.

        Cheap when nothing is due (one comparison); otherwise one copy per watched half and one
        bytes comparison per due notification. No socket is touched here.
        """
        self._cycle = cycle
        heap = self._heap
        if not heap or heap[0] > cycle:
            return
        halves: dict[Direction, bytes] = {}
        filetime = 0
        flush = self._request_flush
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
                first = not session.has_pending
                session.queue(sub, filetime, data)
                if first:
                    flush(session)


def _check_size(symbol: Symbol, length: int, what: str) -> None:
    s = symbol.signal
    if length != s.size:
        raise _error(
            ErrorCode.SIZE_WRONG,
            f"{s.st_path} is {s.type} ({s.size} bytes): the {what} has {length} bytes",
        )


def _read_only_text(s: Signal) -> str:
    return (
        f"{s.st_path} is CNC->PLC: only the CNC writes it (H-02). "
        "The PLC writes the _w fields (command_w, enable_w, ...) and reads the _r fields"
    )


def _unknown_group(port: int, group: int) -> AdsError:
    if port == ADS_PORT_GEO:
        hint = f"port 551 serves group 0x{ADS_GROUP_GEO_AXIS:X} (the dyn_coll_mon objects, C3-10)"
    else:
        hint = (
            f"port 851 serves 0x{ADS_GROUP_PLC_TO_CNC:X} (PLC->CNC half), 0x{ADS_GROUP_CNC_TO_PLC:X} "
            "(CNC->PLC half) and the symbol services 0xF003..0xF082 (docs/ads.md)"
        )
    return _error(ErrorCode.INVALID_INDEX_GROUP, f"port {port}: no index group 0x{group:X}; {hint}")


def _interior(signals: tuple[Signal, ...]) -> frozenset[int]:
    """Byte offsets strictly inside a field (a write may neither start nor end there)."""
    return frozenset(o for s in signals for o in range(s.offset + 1, s.offset + s.size))
