"""ADS command payloads 1..9, requests and responses, as frozen dataclasses (H-04).

Each class decodes its payload (``decode(data)``, raising :class:`AdsError` with the code to answer)
and encodes it (``encode() -> bytes``); all integers little-endian. The payload is what follows the
32-byte AMS header (:mod:`.frames`). Sources: Beckhoff Information System, TC3 ADS introduction
("ADS Read", "ADS Write", ... one page per command); AdsLib ``AmsHeader.h``; the bytes pyads 3.6 and
Node ads-client 2.1 send (``tests/data/ads_golden_frames.json``).

Requests (client -> server)::

    1 ReadDeviceInfo            (empty)
    2 Read                      | index group u32 | index offset u32 | length u32 |
    3 Write                     | index group u32 | index offset u32 | length u32 | data (length) |
    4 ReadState                 (empty)
    5 WriteControl              | ads state u16 | device state u16 | length u32 | data (length) |
    6 AddDeviceNotification     | index group u32 | index offset u32 | length u32 |
                                | transmission mode u32 | max delay u32 | cycle time u32 | reserved 16 |
                                  max delay, cycle time in 100 ns (pyads, ads-client send ms * 10 000)
    7 DeleteDeviceNotification  | notification handle u32 |
    9 ReadWrite                 | index group u32 | index offset u32 | read length u32 | write length u32 |
                                | data (write length) |

Responses (server -> client)::

    1 ReadDeviceInfo            | result u32 | major u8 | minor u8 | build u16 | device name (16, NUL-padded)|
    2 Read                      | result u32 | length u32 | data (length) |
    3 Write                     | result u32 |
    4 ReadState                 | result u32 | ads state u16 | device state u16 |
    5 WriteControl              | result u32 |
    6 AddDeviceNotification     | result u32 | notification handle u32 |
    7 DeleteDeviceNotification  | result u32 |
    9 ReadWrite                 | result u32 | length u32 | data (length) |

    An error reply keeps the command's fixed part, zero-filled behind the result
    (:func:`error_reply_payload`): AdsLib waits for 8 bytes from Read and ReadWrite and times out
    (1861) on a 4-byte reply instead of raising the error (``../shared/reference/ads.md``).

DeviceNotification (command 8, server -> client, state flags 0x0004, no reply; its AMS source must be
the NetId and port the client sent AddDeviceNotification to: AdsLib finds the dispatcher by that
source and the target port, ads-client by the handle; neither reads the invoke id)::

    | length u32 | stamps u32 | stamp ... |            length = bytes after this field
    stamp:  | timestamp u64 (FILETIME) | samples u32 | sample ... |
    sample: | notification handle u32 | size u32 | data (size) |

Which requests are decoded strictly: a payload longer or shorter than its command's layout (a
Write whose length field disagrees with the data that follows, a Read with extra bytes) is answered
with 0x705 (size wrong); a command id that is not a request (0, 8, anything above 9) with 0x701
(service not supported).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar, Final, Self

from hli_server.codecs.ads.constants import CommandId, ErrorCode
from hli_server.codecs.ads.errors import AdsError

__all__ = [
    "AddDeviceNotificationRequest",
    "AddDeviceNotificationResponse",
    "DeleteDeviceNotificationRequest",
    "DeleteDeviceNotificationResponse",
    "DeviceNotification",
    "NotificationSample",
    "NotificationStamp",
    "ReadDeviceInfoRequest",
    "ReadDeviceInfoResponse",
    "ReadRequest",
    "ReadResponse",
    "ReadStateRequest",
    "ReadStateResponse",
    "ReadWriteRequest",
    "ReadWriteResponse",
    "Request",
    "Response",
    "WriteControlRequest",
    "WriteControlResponse",
    "WriteRequest",
    "WriteResponse",
    "decode_request",
    "decode_response",
    "encode_notification",
    "error_reply_payload",
]

_U32: Final = struct.Struct("<I")
_U32x2: Final = struct.Struct("<II")
_U32x3: Final = struct.Struct("<III")
_U32x4: Final = struct.Struct("<IIII")
_WRITE_CONTROL: Final = struct.Struct("<HHI")
_ADD_NOTIFICATION: Final = struct.Struct("<IIIIII16s")
_DEVICE_INFO: Final = struct.Struct("<IBBH16s")
_READ_STATE: Final = struct.Struct("<IHH")
_STAMP_HEAD: Final = struct.Struct("<QI")
_NO_RESERVED: Final = bytes(16)


def _size_error(command: CommandId, what: str, size: int, expected: str) -> AdsError:
    return AdsError(
        ErrorCode.SIZE_WRONG, f"{command.name} {what}: payload is {size} bytes, expected {expected}"
    )


def _fixed(data: bytes, size: int, command: CommandId, what: str) -> None:
    if len(data) != size:
        raise _size_error(command, what, len(data), str(size))


# --------------------------------------------------------------------------------------------
# Requests
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ReadDeviceInfoRequest:
    """Command 1: no payload."""

    command: ClassVar[CommandId] = CommandId.READ_DEVICE_INFO

    def encode(self) -> bytes:
        return b""

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 0, cls.command, "request")
        return cls()


@dataclass(frozen=True, slots=True)
class ReadRequest:
    """Command 2: read ``length`` bytes at index group/offset."""

    index_group: int
    index_offset: int
    length: int
    command: ClassVar[CommandId] = CommandId.READ

    def encode(self) -> bytes:
        return _U32x3.pack(self.index_group, self.index_offset, self.length)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 12, cls.command, "request")
        return cls(*_U32x3.unpack(data))


@dataclass(frozen=True, slots=True)
class WriteRequest:
    """Command 3: write ``data`` at index group/offset (the length field is ``len(data)``)."""

    index_group: int
    index_offset: int
    data: bytes
    command: ClassVar[CommandId] = CommandId.WRITE

    def encode(self) -> bytes:
        return _U32x3.pack(self.index_group, self.index_offset, len(self.data)) + self.data

    @classmethod
    def decode(cls, data: bytes) -> Self:
        if len(data) < 12:
            raise _size_error(cls.command, "request", len(data), "at least 12")
        group, offset, length = _U32x3.unpack_from(data)
        if len(data) != 12 + length:
            raise _size_error(cls.command, f"request with length field {length}", len(data), str(12 + length))
        return cls(group, offset, bytes(data[12:]))


@dataclass(frozen=True, slots=True)
class ReadStateRequest:
    """Command 4: no payload."""

    command: ClassVar[CommandId] = CommandId.READ_STATE

    def encode(self) -> bytes:
        return b""

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 0, cls.command, "request")
        return cls()


@dataclass(frozen=True, slots=True)
class WriteControlRequest:
    """Command 5: wanted ADS state and device state, optional data (pyads sends 2 bytes, ads-client none)."""

    ads_state: int
    device_state: int
    data: bytes = b""
    command: ClassVar[CommandId] = CommandId.WRITE_CONTROL

    def encode(self) -> bytes:
        return _WRITE_CONTROL.pack(self.ads_state, self.device_state, len(self.data)) + self.data

    @classmethod
    def decode(cls, data: bytes) -> Self:
        if len(data) < 8:
            raise _size_error(cls.command, "request", len(data), "at least 8")
        ads_state, device_state, length = _WRITE_CONTROL.unpack_from(data)
        if len(data) != 8 + length:
            raise _size_error(cls.command, f"request with length field {length}", len(data), str(8 + length))
        return cls(ads_state, device_state, bytes(data[8:]))


@dataclass(frozen=True, slots=True)
class AddDeviceNotificationRequest:
    """Command 6: watch ``length`` bytes at index group/offset; times in 100 ns. The 16 reserved bytes
    are sent as zeros and not kept."""

    index_group: int
    index_offset: int
    length: int
    transmission_mode: int
    max_delay: int
    cycle_time: int
    command: ClassVar[CommandId] = CommandId.ADD_DEVICE_NOTIFICATION

    def encode(self) -> bytes:
        return _ADD_NOTIFICATION.pack(
            self.index_group,
            self.index_offset,
            self.length,
            self.transmission_mode,
            self.max_delay,
            self.cycle_time,
            _NO_RESERVED,
        )

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 40, cls.command, "request")
        return cls(*_ADD_NOTIFICATION.unpack(data)[:6])


@dataclass(frozen=True, slots=True)
class DeleteDeviceNotificationRequest:
    """Command 7: the handle the add response gave."""

    handle: int
    command: ClassVar[CommandId] = CommandId.DELETE_DEVICE_NOTIFICATION

    def encode(self) -> bytes:
        return _U32.pack(self.handle)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 4, cls.command, "request")
        return cls(_U32.unpack(data)[0])


@dataclass(frozen=True, slots=True)
class ReadWriteRequest:
    """Command 9: write ``data``, then read up to ``read_length`` bytes (symbol and sum services use it)."""

    index_group: int
    index_offset: int
    read_length: int
    data: bytes
    command: ClassVar[CommandId] = CommandId.READ_WRITE

    def encode(self) -> bytes:
        return _U32x4.pack(self.index_group, self.index_offset, self.read_length, len(self.data)) + self.data

    @classmethod
    def decode(cls, data: bytes) -> Self:
        if len(data) < 16:
            raise _size_error(cls.command, "request", len(data), "at least 16")
        group, offset, read_length, write_length = _U32x4.unpack_from(data)
        if len(data) != 16 + write_length:
            raise _size_error(
                cls.command, f"request with write length {write_length}", len(data), str(16 + write_length)
            )
        return cls(group, offset, read_length, bytes(data[16:]))


Request = (
    ReadDeviceInfoRequest
    | ReadRequest
    | WriteRequest
    | ReadStateRequest
    | WriteControlRequest
    | AddDeviceNotificationRequest
    | DeleteDeviceNotificationRequest
    | ReadWriteRequest
)

_REQUESTS: Final[dict[int, type[Request]]] = {
    cls.command: cls
    for cls in (
        ReadDeviceInfoRequest,
        ReadRequest,
        WriteRequest,
        ReadStateRequest,
        WriteControlRequest,
        AddDeviceNotificationRequest,
        DeleteDeviceNotificationRequest,
        ReadWriteRequest,
    )
}


_COMMAND_IDS: Final = frozenset(int(c) for c in CommandId)


def decode_request(command: int, data: bytes) -> Request:
    """Decode the payload of a request with AMS command id ``command``.

    Raises :class:`AdsError`: 0x701 for a command id that is no request, 0x705 for a payload whose size
    does not fit the command.
    """
    cls = _REQUESTS.get(command)
    if cls is None:
        name = CommandId(command).name if command in _COMMAND_IDS else "unknown"
        raise AdsError(
            ErrorCode.SERVICE_NOT_SUPPORTED,
            f"ADS command {command} ({name}) is not a request this server serves",
        )
    return cls.decode(data)


# --------------------------------------------------------------------------------------------
# Responses
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ReadDeviceInfoResponse:
    """Command 1: version and a device name of at most 16 bytes (NUL-padded on the wire)."""

    result: int
    major: int
    minor: int
    build: int
    name: str
    command: ClassVar[CommandId] = CommandId.READ_DEVICE_INFO

    def encode(self) -> bytes:
        raw = self.name.encode("cp1252")
        if len(raw) > 16 or b"\0" in raw:
            raise ValueError(f"ADS device name {self.name!r} must fit 16 bytes and be free of NUL")
        return _DEVICE_INFO.pack(self.result, self.major, self.minor, self.build, raw)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 24, cls.command, "response")
        result, major, minor, build, raw = _DEVICE_INFO.unpack(data)
        return cls(result, major, minor, build, raw.split(b"\0", 1)[0].decode("cp1252", "replace"))


@dataclass(frozen=True, slots=True)
class ReadResponse:
    """Command 2: result, then the data read (the length field is ``len(data)``)."""

    result: int
    data: bytes = b""
    command: ClassVar[CommandId] = CommandId.READ

    def encode(self) -> bytes:
        return _U32x2.pack(self.result, len(self.data)) + self.data

    @classmethod
    def decode(cls, data: bytes) -> Self:
        result, payload = _result_and_data(cls.command, data)
        return cls(result, payload)


@dataclass(frozen=True, slots=True)
class WriteResponse:
    """Command 3: result only."""

    result: int
    command: ClassVar[CommandId] = CommandId.WRITE

    def encode(self) -> bytes:
        return _U32.pack(self.result)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 4, cls.command, "response")
        return cls(_U32.unpack(data)[0])


@dataclass(frozen=True, slots=True)
class ReadStateResponse:
    """Command 4: ADS state (5 = RUN) and device state."""

    result: int
    ads_state: int
    device_state: int
    command: ClassVar[CommandId] = CommandId.READ_STATE

    def encode(self) -> bytes:
        return _READ_STATE.pack(self.result, self.ads_state, self.device_state)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 8, cls.command, "response")
        return cls(*_READ_STATE.unpack(data))


@dataclass(frozen=True, slots=True)
class WriteControlResponse:
    """Command 5: result only."""

    result: int
    command: ClassVar[CommandId] = CommandId.WRITE_CONTROL

    def encode(self) -> bytes:
        return _U32.pack(self.result)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 4, cls.command, "response")
        return cls(_U32.unpack(data)[0])


@dataclass(frozen=True, slots=True)
class AddDeviceNotificationResponse:
    """Command 6: result and the new notification handle."""

    result: int
    handle: int
    command: ClassVar[CommandId] = CommandId.ADD_DEVICE_NOTIFICATION

    def encode(self) -> bytes:
        return _U32x2.pack(self.result, self.handle)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 8, cls.command, "response")
        return cls(*_U32x2.unpack(data))


@dataclass(frozen=True, slots=True)
class DeleteDeviceNotificationResponse:
    """Command 7: result only."""

    result: int
    command: ClassVar[CommandId] = CommandId.DELETE_DEVICE_NOTIFICATION

    def encode(self) -> bytes:
        return _U32.pack(self.result)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        _fixed(data, 4, cls.command, "response")
        return cls(_U32.unpack(data)[0])


@dataclass(frozen=True, slots=True)
class ReadWriteResponse:
    """Command 9: result, then the data read (the length field is ``len(data)``)."""

    result: int
    data: bytes = b""
    command: ClassVar[CommandId] = CommandId.READ_WRITE

    def encode(self) -> bytes:
        return _U32x2.pack(self.result, len(self.data)) + self.data

    @classmethod
    def decode(cls, data: bytes) -> Self:
        result, payload = _result_and_data(cls.command, data)
        return cls(result, payload)


def _result_and_data(command: CommandId, data: bytes) -> tuple[int, bytes]:
    if len(data) < 8:
        raise _size_error(command, "response", len(data), "at least 8")
    result, length = _U32x2.unpack_from(data)
    if len(data) != 8 + length:
        raise _size_error(command, f"response with length field {length}", len(data), str(8 + length))
    return result, bytes(data[8:])


Response = (
    ReadDeviceInfoResponse
    | ReadResponse
    | WriteResponse
    | ReadStateResponse
    | WriteControlResponse
    | AddDeviceNotificationResponse
    | DeleteDeviceNotificationResponse
    | ReadWriteResponse
)

_RESPONSES: Final[dict[int, type[Response]]] = {
    cls.command: cls
    for cls in (
        ReadDeviceInfoResponse,
        ReadResponse,
        WriteResponse,
        ReadStateResponse,
        WriteControlResponse,
        AddDeviceNotificationResponse,
        DeleteDeviceNotificationResponse,
        ReadWriteResponse,
    )
}

_ERROR_FIXED_PART: Final[dict[int, int]] = {
    CommandId.READ_DEVICE_INFO: 24,
    CommandId.READ: 8,
    CommandId.WRITE: 4,
    CommandId.READ_STATE: 8,
    CommandId.WRITE_CONTROL: 4,
    CommandId.ADD_DEVICE_NOTIFICATION: 8,
    CommandId.DELETE_DEVICE_NOTIFICATION: 4,
    CommandId.READ_WRITE: 8,
}


def decode_response(command: int, data: bytes) -> Response:
    """Decode the payload of a response (client side, tests); raises :class:`AdsError` as requests do."""
    cls = _RESPONSES.get(command)
    if cls is None:
        raise AdsError(ErrorCode.SERVICE_NOT_SUPPORTED, f"ADS command {command} has no response")
    return cls.decode(data)


def error_reply_payload(command: int, code: int) -> bytes:
    """The payload of an error reply to ``command``: the result, then the rest of the command's fixed part
    as zeros (Read/ReadWrite: length 0; AddDeviceNotification: handle 0). For a command id with no
    response layout: the result alone."""
    return _U32.pack(code) + bytes(_ERROR_FIXED_PART.get(command, 4) - 4)


# --------------------------------------------------------------------------------------------
# DeviceNotification (command 8)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class NotificationSample:
    """One watched value: the handle the add response gave and the bytes at its address."""

    handle: int
    data: bytes


@dataclass(frozen=True, slots=True)
class NotificationStamp:
    """Samples taken at one time (FILETIME: 100 ns since 1601-01-01 UTC, see ``symbols.filetime_*``)."""

    timestamp: int
    samples: tuple[NotificationSample, ...]


@dataclass(frozen=True, slots=True)
class DeviceNotification:
    """Command 8 payload: one or more stamps. The server sends it unasked; there is no reply."""

    stamps: tuple[NotificationStamp, ...]
    command: ClassVar[CommandId] = CommandId.DEVICE_NOTIFICATION

    def encode(self) -> bytes:
        return encode_notification(self.stamps)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        command = cls.command
        if len(data) < 8:
            raise _size_error(command, "stream", len(data), "at least 8")
        length, count = _U32x2.unpack_from(data)
        if length != len(data) - 4:
            raise _size_error(command, f"stream with length field {length}", len(data), str(length + 4))
        pos = 8
        end = len(data)
        stamps: list[NotificationStamp] = []
        for i in range(count):
            if end - pos < 12:
                raise AdsError(
                    ErrorCode.SIZE_WRONG, f"{command.name}: stamp {i} of {count} runs past the end"
                )
            timestamp, sample_count = _STAMP_HEAD.unpack_from(data, pos)
            pos += 12
            samples: list[NotificationSample] = []
            for j in range(sample_count):
                if end - pos < 8:
                    raise AdsError(
                        ErrorCode.SIZE_WRONG, f"{command.name}: stamp {i} sample {j} header runs past the end"
                    )
                handle, size = _U32x2.unpack_from(data, pos)
                pos += 8
                if end - pos < size:
                    raise AdsError(
                        ErrorCode.SIZE_WRONG,
                        f"{command.name}: stamp {i} sample {j} of {size} bytes runs past the end",
                    )
                samples.append(NotificationSample(handle, bytes(data[pos : pos + size])))
                pos += size
            stamps.append(NotificationStamp(timestamp, tuple(samples)))
        if pos != end:
            raise AdsError(ErrorCode.SIZE_WRONG, f"{command.name}: {end - pos} bytes after the last stamp")
        return cls(tuple(stamps))


def encode_notification(stamps: Sequence[NotificationStamp]) -> bytes:
    """The DeviceNotification payload (the server calls this once per connection and publish step)."""
    parts = [b"", _U32.pack(len(stamps))]
    for stamp in stamps:
        parts.append(_STAMP_HEAD.pack(stamp.timestamp, len(stamp.samples)))
        for sample in stamp.samples:
            parts.append(_U32x2.pack(sample.handle, len(sample.data)))
            parts.append(sample.data)
    body = b"".join(parts)
    return _U32.pack(len(body)) + body
