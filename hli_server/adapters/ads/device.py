"""The ADS device: requests in, replies out, dispatched by tables to the services; no sockets (H-04, C3-10).

:class:`AdsDevice` answers decoded AMS frames for one :class:`Session` (one TCP connection). It does no
I/O: the asyncio server (:mod:`hli_server.adapters.ads.server`) feeds it frames and gives each session
two hooks, ``send(bytes)`` and ``backlogged()``, so the unit tests and the fuzz test drive it without a
network.

Dispatch is data, as h11 keeps its state machine in tables: :data:`COMMANDS` maps each ADS command to
the service method that answers it, and one :class:`PortTable` per AMS port maps each index group to
the service that reads, writes, read-writes or watches it. A group a port does not list in the table
asked for is refused from the tables alone: 0x701 when the port serves it with another command ("takes
Read and Write, not ReadWrite"), 0x702 when the port does not know it. The services, one module each,
stand on :mod:`.session` (the :class:`Session`, the limits, the port table) and never import this module::

    session.py        what the services read: Session, DeviceLimits, DeviceStats, PortTable, Watch
    system.py         ReadDeviceInfo, ReadState, WriteControl; port 10000 (TwinCAT system service)
    data.py           the halves 0xF020/0xF030, the structured view 0x4040, handles 0xF003/0xF005/0xF006,
                      value by name 0xF004, the CNC objects of port 551 (0x120300)
    symbol_info.py    symbol version 0xF008, info 0xF009, uploads 0xF00B..0xF00F, types 0xF011, state 0xF100
    sums.py           sum read / write / read-write 0xF080..0xF082
    notifications.py  Add/DeleteDeviceNotification and the samples of the cycle

Errors carry their ADS code from where they are raised (:class:`AdsError`, docs/ads.md "Errors");
AMS-level errors go in the AMS header with no payload: another NetId than the server's 0x7, a port the
server does not serve 0x6. An unexpected exception is answered 0x700 and logged; the connection goes on.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from typing import TYPE_CHECKING, Final

from hli_server.adapters.ads.data import DataService
from hli_server.adapters.ads.notifications import MAX_PENDING_SAMPLES, NotificationService
from hli_server.adapters.ads.session import (
    DeviceLimits,
    DeviceStats,
    PortTable,
    ReadWriteHandler,
    Session,
)
from hli_server.adapters.ads.sums import SumService
from hli_server.adapters.ads.symbol_info import SymbolInfoService
from hli_server.adapters.ads.symbols import VIEW_GROUP, SymbolTable
from hli_server.adapters.ads.system import GROUP_SYSTEM_STATE, SYSTEM_SERVICE_PORT, SystemService
from hli_server.codecs.ads import (
    MAX_AMS_LENGTH,
    AddDeviceNotificationRequest,
    AddDeviceNotificationResponse,
    AdsError,
    AmsHeader,
    AmsPacket,
    CommandId,
    DeleteDeviceNotificationRequest,
    DeleteDeviceNotificationResponse,
    ErrorCode,
    IndexGroup,
    NetId,
    ReadRequest,
    ReadWriteRequest,
    WriteRequest,
    encode_error_response,
    encode_response,
    error_reply_payload,
)
from schemas.layout import (
    ADS_GROUP_CNC_TO_PLC,
    ADS_GROUP_GEO_AXIS,
    ADS_GROUP_PLC_TO_CNC,
    ADS_PORT_GEO,
    ADS_PORT_HLI,
)

if TYPE_CHECKING:
    from hli_server.adapters.host import ImagePort

__all__ = ["COMMANDS", "MAX_PENDING_SAMPLES", "SERVED_PORTS", "AdsDevice"]

logger = logging.getLogger(__name__)

SERVED_PORTS: Final = (ADS_PORT_HLI, ADS_PORT_GEO, SYSTEM_SERVICE_PORT)

_U32x3: Final = struct.Struct("<III")
_U32x4: Final = struct.Struct("<IIII")
_RESULT_AND_LENGTH: Final = struct.Struct("<II")
_OK: Final = bytes(4)
_FRAME_HEAD: Final = struct.Struct("<HI6sH6sHHHIII")
"""AMS/TCP header and AMS header of one frame (the codec's layout), for :meth:`AdsDevice.handle_frame`."""
_FrameHead = tuple[int, int, bytes, int, bytes, int, int, int, int, int, int]
_RESPONSE_FLAGS: Final = 0x0005
_FLAGS: Final = _RESPONSE_FLAGS
_DATA_REPLY: Final = struct.Struct("<HI6sH6sHHHIIIII")
"""The frame head, then a Read or ReadWrite reply's result and length (the data follows)."""
_RESULT_REPLY: Final = struct.Struct("<HI6sH6sHHHIIII")
"""The frame head, then a Write reply's result."""
_READ_NO: Final = int(CommandId.READ)
_WRITE_NO: Final = int(CommandId.WRITE)
_READ_WRITE_NO: Final = int(CommandId.READ_WRITE)
"""The three commands of :meth:`AdsDevice.handle_frame` as plain numbers (compared with the frame's)."""
_C2P_GROUP: Final = int(ADS_GROUP_CNC_TO_PLC)
_BY_HANDLE: Final = int(IndexGroup.SYM_VALUE_BY_HANDLE)
_HANDLE_BY_NAME: Final = int(IndexGroup.SYM_HANDLE_BY_NAME)
_RELEASE_HANDLE: Final = int(IndexGroup.SYM_RELEASE_HANDLE)
"""The index groups of a PLC's polling (a raw read of the CNC->PLC half; pyads' ``read_by_name``: a handle,
a read by it, its release), which :meth:`AdsDevice.handle_frame` calls straight on port 851 (the table of
:meth:`AdsDevice._port_tables` maps them to the same methods: tests/unit/test_ads_device.py)."""
_NO_HEADER: Final = AmsHeader(NetId(bytes(6)), 0, NetId(bytes(6)), 0, 0, 0, 0, 0, 0)
"""The header argument of the data commands in :meth:`AdsDevice.handle_frame` (Read, Write, ReadWrite do
not read it: they answer from their payload)."""


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
        self.layout = image.layout
        self.net_id = net_id
        self.limits = limits or DeviceLimits()
        self.stats = DeviceStats()
        self.symbols = SymbolTable(self.layout)
        self.data = DataService(image, self.symbols, self.limits, read_only=read_only)
        self.info = SymbolInfoService(self.symbols, self.data)
        self.system = SystemService()
        self.sums = SumService(self.stats, self.limits.max_sum_items)
        self.notifications = NotificationService(
            image,
            self.data.half,
            t_a_us=t_a_us,
            limits=self.limits,
            stats=self.stats,
            call_later=call_later,
            request_flush=request_flush or (lambda session: None),  # no loop: call session.flush()
            first_sample_delay_s=first_sample_delay_s,
        )
        self.ports = self._port_tables()
        self._hli = self.ports[ADS_PORT_HLI]
        self._commands: dict[int, Callable[[Session, PortTable, AmsHeader, bytes], bytes]] = {
            command: getattr(self, method) for command, method in COMMANDS.items()
        }
        self._net_id_bytes = bytes(net_id)

    @property
    def read_only(self) -> bool:
        return self.data.read_only

    # =========================================================================================
    # The tables
    # =========================================================================================
    def _port_tables(self) -> dict[int, PortTable]:
        d, i, s, sums = self.data, self.info, self.system, self.sums
        hli = PortTable(
            ADS_PORT_HLI,
            "Plc30 App",
            read={
                ADS_GROUP_CNC_TO_PLC: d.read_c2p,
                ADS_GROUP_PLC_TO_CNC: d.read_p2c,
                VIEW_GROUP: d.read_view,
                IndexGroup.SYM_VALUE_BY_HANDLE: d.read_by_handle,
                IndexGroup.SYM_VERSION: i.version,
                IndexGroup.SYM_UPLOAD: i.upload,
                IndexGroup.SYM_UPLOAD_INFO: i.upload_info,
                IndexGroup.SYM_DT_UPLOAD: i.type_upload,
                IndexGroup.SYM_UPLOAD_INFO2: i.upload_info2,
                IndexGroup.DEVICE_DATA: i.device_state,
            },
            write={
                ADS_GROUP_PLC_TO_CNC: d.write_p2c,
                ADS_GROUP_CNC_TO_PLC: d.write_c2p,
                VIEW_GROUP: d.write_view,
                IndexGroup.SYM_VALUE_BY_HANDLE: d.write_by_handle,
                IndexGroup.SYM_RELEASE_HANDLE: d.release_handle,
            },
            read_write={
                IndexGroup.SYM_HANDLE_BY_NAME: d.handle_by_name,
                IndexGroup.SYM_VALUE_BY_NAME: d.value_by_name,
                IndexGroup.SYM_INFO_BY_NAME_EX: i.info_by_name,
                IndexGroup.DATA_TYPE_INFO_BY_NAME_EX: i.type_by_name,
            },
            watch={
                ADS_GROUP_CNC_TO_PLC: d.watch_c2p,
                ADS_GROUP_PLC_TO_CNC: d.watch_p2c,
                VIEW_GROUP: d.watch_view,
                IndexGroup.SYM_VALUE_BY_HANDLE: d.watch_handle,
                IndexGroup.SYM_VERSION: i.watch_version,
                IndexGroup.DEVICE_DATA: i.watch_device_state,
            },
            hint=f"port 851 serves 0x{ADS_GROUP_PLC_TO_CNC:X} (PLC->CNC half), 0x{ADS_GROUP_CNC_TO_PLC:X} "
            f"(CNC->PLC half), 0x{VIEW_GROUP:X} (structures) and the symbol services 0xF003..0xF100 "
            "(docs/ads.md)",
        )
        geo = PortTable(
            ADS_PORT_GEO,
            "HLI-Server GEO",
            read={ADS_GROUP_GEO_AXIS: d.read_geo},
            watch={ADS_GROUP_GEO_AXIS: d.watch_geo},
            refuse_writes=d.refuse_geo_write,
            hint=f"port 551 serves group 0x{ADS_GROUP_GEO_AXIS:X} (the dyn_coll_mon objects, C3-10)",
        )
        system = PortTable(
            SYSTEM_SERVICE_PORT,
            "TwinCAT System",
            read={GROUP_SYSTEM_STATE: s.extended_state},
            hint=f"port {SYSTEM_SERVICE_PORT} (system service) serves ReadState, ReadDeviceInfo and group "
            f"0x{GROUP_SYSTEM_STATE:X} (the extended state)",
        )
        for table in (hli, geo):
            table.read_write[IndexGroup.SUMUP_READ] = _bind(sums.read, table)
            table.read_write[IndexGroup.SUMUP_WRITE] = _bind(sums.write, table)
            table.read_write[IndexGroup.SUMUP_READWRITE] = _bind(sums.read_write, table)
        return {t.port: t for t in (hli, geo, system)}

    # =========================================================================================
    # Frames
    # =========================================================================================
    def handle(self, session: Session, packet: AmsPacket) -> bytes | None:
        """The reply to one AMS frame (None: no reply, e.g. a response sent by the client)."""
        header = packet.header
        if header.state_flags & 0x0001:  # a response: nothing to answer
            return None
        self.stats.requests += 1
        if header.target_net_id != self.net_id:
            self.stats.count_error(ErrorCode.TARGET_MACHINE_NOT_FOUND)
            logger.debug("ADS: request for NetId %s, this server is %s", header.target_net_id, self.net_id)
            return encode_error_response(header, ErrorCode.TARGET_MACHINE_NOT_FOUND)
        table = self.ports.get(header.target_port)
        if table is None:
            self.stats.count_error(ErrorCode.TARGET_PORT_NOT_FOUND)
            return encode_error_response(header, ErrorCode.TARGET_PORT_NOT_FOUND)
        try:
            serve = self._commands.get(header.command)
            if serve is None:
                raise AdsError(
                    ErrorCode.SERVICE_NOT_SUPPORTED,
                    f"ADS command {header.command} is no request (1..7, 9: ReadDeviceInfo .. ReadWrite)",
                )
            payload = serve(session, table, header, packet.data)
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

    def refuse_oversize(self, session: Session, header: AmsHeader, length: int) -> bytes | None:
        """The reply to an AMS frame longer than the door takes (the server dropped its bytes): 0x705 with
        the command's reply layout, as for any size the device refuses (None for a response)."""
        if header.state_flags & 0x0001:
            return None
        self.stats.requests += 1
        self.stats.count_error(ErrorCode.SIZE_WRONG)
        logger.info(
            "ADS %s: an AMS frame of %d bytes (command %d) is longer than this server takes (%d): 0x705",
            session.name,
            length,
            header.command,
            MAX_AMS_LENGTH,
        )
        return encode_response(header, error_reply_payload(header.command, ErrorCode.SIZE_WRONG))

    def handle_frame(self, session: Session, frame: bytes, source: bytes) -> bytes | None:
        """:meth:`handle` for the requests that make up a client's polling (Read, Write, ReadWrite), taken
        straight from one AMS/TCP ``frame`` (the 6-byte TCP header, then the AMS header) without building
        its header objects: the reply, or None where the frame is anything else (a response, another
        command, a NetId other than this server's or a source NetId other than ``source``, the admitted
        one, an unknown port, sizes that do not add up): then the caller decodes it and calls
        :meth:`handle`, which answers every such case. Same replies, errors and counters as :meth:`handle`."""
        head: _FrameHead = _FRAME_HEAD.unpack_from(frame)  # typed: the compiled build compares plain ints
        reserved, length, tn, tp, sn, sp, cmd, flags, data_length, _, invoke = head
        if (
            reserved
            or cmd not in (_READ_NO, _WRITE_NO, _READ_WRITE_NO)
            or flags & 0x0001
            or length + 6 != len(frame)
            or data_length + 32 != length
            or tn != self._net_id_bytes
            or sn != source
        ):
            return None
        table = self.ports.get(tp)
        if table is None:
            return None
        self.stats.requests += 1
        direct = table is self._hli
        try:
            # the canonical shapes of the three commands straight from the frame: no payload copy, no
            # command method, the reply in one pack (the others take the command methods below); a PLC's
            # polling groups called straight, the others through the port's table
            if cmd == _READ_NO:
                if data_length == 12:
                    group, offset, size = _U32x3.unpack_from(frame, 38)
                    if direct and group == _C2P_GROUP:
                        value = self.data.read_c2p(session, offset, size)
                    elif direct and group == _BY_HANDLE:
                        value = self.data.read_by_handle(session, offset, size)
                    else:
                        serve = table.read.get(group)
                        if serve is None:
                            raise table.missing("Read", group)
                        value = serve(session, offset, size)
                    n = len(value)
                    return (
                        _DATA_REPLY.pack(0, 40 + n, sn, sp, tn, tp, cmd, _FLAGS, 8 + n, 0, invoke, 0, n)
                        + value
                    )
            elif cmd == _WRITE_NO:
                if data_length >= 12:
                    group, offset, size = _U32x3.unpack_from(frame, 38)
                    if size == data_length - 12:
                        if direct and group == _RELEASE_HANDLE:
                            self.data.release_handle(session, offset, frame[50:])
                        else:
                            table.write_group(session, group, offset, frame[50:])
                        return _RESULT_REPLY.pack(0, 36, sn, sp, tn, tp, cmd, _FLAGS, 4, 0, invoke, 0)
            elif data_length >= 16:  # ReadWrite
                group, offset, read_length, size = _U32x4.unpack_from(frame, 38)
                if size == data_length - 16:
                    if direct and group == _HANDLE_BY_NAME:
                        value = self.data.handle_by_name(session, offset, read_length, frame[54:])
                    else:
                        value = self._read_write(session, table, group, offset, read_length, frame[54:])
                    n = len(value)
                    return (
                        _DATA_REPLY.pack(0, 40 + n, sn, sp, tn, tp, cmd, _FLAGS, 8 + n, 0, invoke, 0, n)
                        + value
                    )
            payload = self._commands[cmd](session, table, _NO_HEADER, frame[38:])
        except AdsError as exc:
            self.stats.count_error(exc.code)
            logger.debug("ADS %s port %d: %s", session.name, tp, exc)
            payload = error_reply_payload(cmd, exc.code)
        except Exception:
            self.stats.failures += 1
            self.stats.count_error(ErrorCode.GENERAL_DEVICE_ERROR)
            logger.exception("ADS: request %d to port %d from %s failed", cmd, tp, session.name)
            payload = error_reply_payload(cmd, ErrorCode.GENERAL_DEVICE_ERROR)
        return (
            _FRAME_HEAD.pack(
                0, 32 + len(payload), sn, sp, tn, tp, cmd, _RESPONSE_FLAGS, len(payload), 0, invoke
            )
            + payload
        )

    # --- the commands: (session, port table, header, payload) -> reply payload --------------------
    def read_device_info(self, session: Session, table: PortTable, header: AmsHeader, data: bytes) -> bytes:
        return self.system.read_device_info(session, table, header, data)

    def read_state(self, session: Session, table: PortTable, header: AmsHeader, data: bytes) -> bytes:
        return self.system.read_state(session, table, header, data)

    def write_control(self, session: Session, table: PortTable, header: AmsHeader, data: bytes) -> bytes:
        return self.system.write_control(session, table, header, data)

    def read_command(self, session: Session, table: PortTable, header: AmsHeader, data: bytes) -> bytes:
        if len(data) != 12:
            ReadRequest.decode(data)  # raises the codec's 0x705, naming the sizes
        group, offset, length = _U32x3.unpack(data)
        value = table.read_group(session, group, offset, length)
        return _RESULT_AND_LENGTH.pack(0, len(value)) + value

    def write_command(self, session: Session, table: PortTable, header: AmsHeader, data: bytes) -> bytes:
        if len(data) < 12 or _U32x3.unpack_from(data)[2] != len(data) - 12:
            WriteRequest.decode(data)  # raises the codec's 0x705
        group, offset, _ = _U32x3.unpack_from(data)
        table.write_group(session, group, offset, data[12:])
        return _OK

    def read_write_command(self, session: Session, table: PortTable, header: AmsHeader, data: bytes) -> bytes:
        if len(data) < 16 or _U32x4.unpack_from(data)[3] != len(data) - 16:
            ReadWriteRequest.decode(data)  # raises the codec's 0x705
        group, offset, read_length, _ = _U32x4.unpack_from(data)
        value = self._read_write(session, table, group, offset, read_length, data[16:])
        return _RESULT_AND_LENGTH.pack(0, len(value)) + value

    @staticmethod
    def _read_write(
        session: Session, table: PortTable, group: int, offset: int, read_length: int, data: bytes
    ) -> bytes:
        value = table.read_write_group(session, group, offset, read_length, data)
        if len(value) > read_length:
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"index group 0x{group:X} answers {len(value)} bytes, the read length is {read_length}",
            )
        return value

    def add_notification(self, session: Session, table: PortTable, header: AmsHeader, data: bytes) -> bytes:
        request = AddDeviceNotificationRequest.decode(data)
        if request.length <= 0:
            raise AdsError(ErrorCode.SIZE_WRONG, "a device notification watches at least 1 byte")
        watch = table.watch.get(request.index_group)
        if watch is None:
            raise table.missing("notification", request.index_group)
        handle = self.notifications.add(
            session,
            header,
            watch(session, request.index_offset, request.length),
            request.transmission_mode,
            request.max_delay,
            request.cycle_time,
        )
        return AddDeviceNotificationResponse(0, handle).encode()

    def delete_notification(
        self, session: Session, table: PortTable, header: AmsHeader, data: bytes
    ) -> bytes:
        request = DeleteDeviceNotificationRequest.decode(data)
        self.notifications.delete(session, request.handle)
        return DeleteDeviceNotificationResponse(0).encode()

    # =========================================================================================
    # Notifications and sessions
    # =========================================================================================
    def on_cycle(self, cycle: int) -> None:
        """After every published cycle (``host.on_cycle``); see :mod:`.notifications`."""
        self.notifications.on_cycle(cycle)

    def close_session(self, session: Session) -> None:
        """The client went away: release its handles, notifications and queued samples."""
        session.closed = True
        self.notifications.close_session(session)
        session.handles.clear()

    @property
    def notification_count(self) -> int:
        return self.notifications.count


COMMANDS: Final[dict[int, str]] = {
    CommandId.READ_DEVICE_INFO: "read_device_info",
    CommandId.READ: "read_command",
    CommandId.WRITE: "write_command",
    CommandId.READ_STATE: "read_state",
    CommandId.WRITE_CONTROL: "write_control",
    CommandId.ADD_DEVICE_NOTIFICATION: "add_notification",
    CommandId.DELETE_DEVICE_NOTIFICATION: "delete_notification",
    CommandId.READ_WRITE: "read_write_command",
}
"""ADS command -> the :class:`AdsDevice` method that answers it. DeviceNotification (8) comes from a
server, never to it: like 0 and anything above 9 it is answered 0x701."""


def _bind(
    method: Callable[[Session, PortTable, int, int, bytes], bytes], table: PortTable
) -> ReadWriteHandler:
    def serve(session: Session, offset: int, read_length: int, data: bytes) -> bytes:
        return method(session, table, offset, read_length, data)

    return serve
