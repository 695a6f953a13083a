"""AMS/TCP framing: NetIds, the AMS header, the incremental stream decoder, frame encoding (H-04).

One AMS/TCP frame (all integers little-endian)::

    [ AMS/TCP header (6 bytes) ][ AMS header (32 bytes) ][ ADS payload (data length bytes) ]

    AMS/TCP header
     0      2              6
    +------+--------------+
    | rsvd |    length    |   rsvd u16: 0x0000 AMS frame (below); 0x0001, 0x1000, 0x1001, 0x1002
    +------+--------------+   router messages (AmsTcpCommand) whose body has no AMS header;
                              length u32: bytes after these 6 (AMS frame: 32 + data length)

    AMS header
     0                        6        8                        14       16
    +------------------------+--------+------------------------+--------+
    |    target AMS NetId    | t.port |    source AMS NetId    | s.port |
    +-------+-------+--------+--------+-------+-------+--------+--------+
    |  cmd  | flags |  data length    |   error code   |   invoke id    |
    +-------+-------+-----------------+----------------+----------------+
     16      18      20                24               28               32

    cmd u16: CommandId 1..9; flags u16: 0x0004 request, 0x0005 response; data length u32: ADS
    payload bytes; error code u32: AMS-level error (a reply with a non-zero code and no payload is
    what AdsLib returns as the error at once); invoke id u32: echoed by the reply.

A reply swaps target and source and echoes command and invoke id (:func:`encode_response`). AdsLib
matches replies by invoke id and (target) AMS port; several AMS ports share one socket, so several
requests may be in flight on one connection.

A TCP stream carries frames back to back with no delimiter. :class:`AmsStreamDecoder` buffers
partial frames and hands out every complete one in order, h11-style (``receive_data`` then
``next_frame`` until :data:`NEED_DATA`) or as an iterator (``feed``). The length field is the only
way to find the next frame, so a frame that cannot be delimited breaks the stream for good:
:class:`AmsStreamError` (close the connection) when

* the reserved word is none of the AMS/TCP commands (the bytes are not AMS/TCP),
* the length of an AMS frame is below 32 or above the decoder's limit (default
  :data:`MAX_AMS_LENGTH`: 32 + :data:`MAX_ADS_PAYLOAD`), or a router message is longer than
  :data:`MAX_ROUTER_LENGTH`: checked as soon as the 6 header bytes are in, before any body is buffered,
  so a peer can never make the decoder hold more than one maximal frame plus one ``recv``,
* the AMS header's data length disagrees with the AMS/TCP length (AdsLib delimits by the one,
  ads-client by the other: such a frame desynchronises one of them, and no client sends it).

A decoder made with ``max_skipped_length`` (the server's) hands out an AMS frame above its limit but
within that bound as :class:`OversizeAmsFrame` (its header, once its first 38 bytes are in) and drops the
rest of it as it arrives, never holding it: the server answers it with 0x705 instead of closing the
connection without a word (a sum write of 500 items of 200 bytes is 100 KB; issue 36, finding 9).

Everything inside a well-delimited frame (unknown command, a payload too short for its command)
is answerable: :mod:`.commands` raises :class:`AdsError` carrying the ADS code to answer with.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from enum import Enum
from typing import Final, Literal, NamedTuple

from hli_server.codecs.ads.constants import REQUEST_FLAGS, RESPONSE_FLAGS, AmsTcpCommand, ErrorCode
from hli_server.codecs.ads.errors import AdsError, AmsStreamError

__all__ = [
    "AMS_HEADER_SIZE",
    "AMS_TCP_HEADER_SIZE",
    "MAX_ADS_PAYLOAD",
    "MAX_AMS_LENGTH",
    "MAX_ROUTER_LENGTH",
    "NEED_DATA",
    "AmsAddress",
    "AmsHeader",
    "AmsPacket",
    "AmsStreamDecoder",
    "AmsTcpFrame",
    "Frame",
    "NeedData",
    "NetId",
    "OversizeAmsFrame",
    "encode_error_response",
    "encode_port_close_reply",
    "encode_port_connect_reply",
    "encode_request",
    "encode_response",
    "encode_router_frame",
    "port_of_port_request",
]

AMS_TCP_HEADER_SIZE: Final = 6
AMS_HEADER_SIZE: Final = 32
MAX_ADS_PAYLOAD: Final = 0x10000 + 16
"""Largest ADS payload the decoder accepts by default: 64 KiB of data behind the largest command header
(ReadWrite, 16 bytes), so a Write or ReadWrite of 64 KiB still fits. Replies the server sends are not
limited by it."""
MAX_AMS_LENGTH: Final = AMS_HEADER_SIZE + MAX_ADS_PAYLOAD
"""Largest AMS/TCP length field of an AMS frame accepted by default (65 584)."""
MAX_ROUTER_LENGTH: Final = 1024
"""Router messages carry a port or a NetId and a port; anything longer is not one."""

_TCP_HEADER: Final = struct.Struct("<HI")
_AMS_HEADER: Final = struct.Struct("<6sH6sHHHIII")
_FRAME_HEAD: Final = struct.Struct("<HI6sH6sHHHIII")
"""AMS/TCP header + AMS header in one pack (38 bytes)."""
_U16: Final = struct.Struct("<H")
_ROUTER_COMMANDS: Final = frozenset(int(c) for c in AmsTcpCommand if c != AmsTcpCommand.AMS_CMD)


class NetId(bytes):
    """An AMS NetId: 6 octets, written ``127.0.0.1.1.1``."""

    __slots__ = ()

    def __new__(cls, octets: bytes | bytearray | tuple[int, ...] | list[int]) -> NetId:
        value = super().__new__(cls, octets)
        if len(value) != 6:
            raise ValueError(f"an AMS NetId has 6 octets, got {len(value)}: {bytes(value)!r}")
        return value

    @classmethod
    def parse(cls, text: str) -> NetId:
        """``"127.0.0.1.1.1"`` -> NetId; raises ValueError naming the text when it is not 6 octets."""
        parts = text.strip().split(".")
        if len(parts) != 6 or not all(p.isdecimal() and int(p) <= 255 for p in parts):
            raise ValueError(
                f"AMS NetId {text!r} is not six numbers 0..255 separated by dots (127.0.0.1.1.1)"
            )
        return cls(bytes(int(p) for p in parts))

    def __str__(self) -> str:
        return ".".join(str(b) for b in self)

    def __repr__(self) -> str:
        return f"NetId('{self}')"


_NET_IDS: dict[bytes, NetId] = {}
_NET_ID_CACHE_SIZE: Final = 4096


def _net_id(octets: bytes) -> NetId:
    """The NetId of 6 octets, shared: a connection sends the same two NetIds in every frame."""
    net_id = _NET_IDS.get(octets)
    if net_id is None:
        if len(_NET_IDS) >= _NET_ID_CACHE_SIZE:  # a peer cycling through NetIds: stay bounded
            _NET_IDS.clear()
        net_id = _NET_IDS[octets] = NetId(octets)
    return net_id


class AmsAddress(NamedTuple):
    """NetId and AMS port: where a request goes to or comes from."""

    net_id: NetId
    port: int

    def __str__(self) -> str:
        return f"{self.net_id}:{self.port}"


class AmsHeader(NamedTuple):
    """The 32-byte AMS header, field by field.

    A NamedTuple, flat, unlike the payload dataclasses: one is made for every frame, and a frozen
    dataclass of 9 fields costs ~2 us to build against ~0.3 us (a third of a Read's whole decode).
    """

    target_net_id: NetId
    target_port: int
    source_net_id: NetId
    source_port: int
    command: int
    """A :class:`CommandId` value, kept as the int sent (an unknown command still gets an answer)."""
    state_flags: int
    data_length: int
    error_code: int
    invoke_id: int

    @property
    def target(self) -> AmsAddress:
        return AmsAddress(self.target_net_id, self.target_port)

    @property
    def source(self) -> AmsAddress:
        return AmsAddress(self.source_net_id, self.source_port)

    @property
    def is_response(self) -> bool:
        return bool(self.state_flags & 0x0001)


class AmsPacket(NamedTuple):
    """One AMS frame: header and the raw ADS payload (decode it with :mod:`.commands`); a NamedTuple
    for the reason :class:`AmsHeader` is one."""

    header: AmsHeader
    data: bytes

    def to_bytes(self) -> bytes:
        """The frame as sent: AMS/TCP header, AMS header (data length = ``len(data)``), payload."""
        h = self.header
        return (
            _FRAME_HEAD.pack(
                0,
                AMS_HEADER_SIZE + len(self.data),
                h.target_net_id,
                h.target_port,
                h.source_net_id,
                h.source_port,
                h.command,
                h.state_flags,
                len(self.data),
                h.error_code,
                h.invoke_id,
            )
            + self.data
        )


@dataclass(frozen=True, slots=True)
class AmsTcpFrame:
    """A router message (reserved word other than 0): its :class:`AmsTcpCommand` and raw body."""

    command: int
    data: bytes

    def to_bytes(self) -> bytes:
        return encode_router_frame(self.command, self.data)


Frame = AmsPacket | AmsTcpFrame


class OversizeAmsFrame(NamedTuple):
    """An AMS frame longer than the decoder takes (``length``, its AMS/TCP length): its header only, the
    rest dropped as it arrives (:class:`AmsStreamDecoder` with ``max_skipped_length``)."""

    header: AmsHeader
    length: int


class NeedData(Enum):
    """h11's ``NEED_DATA``: no complete frame buffered; call ``receive_data`` with more bytes."""

    NEED_DATA = "NEED_DATA"


NEED_DATA: Final = NeedData.NEED_DATA


class AmsStreamDecoder:
    """Splits one connection's byte stream into frames; keeps an incomplete tail for the next read.

    h11-style: ``receive_data(data)``, then ``next_frame()`` until it returns :data:`NEED_DATA`. Or
    ``for frame in decoder.feed(data)``: the frames completed by ``data``, in stream order. A frame
    that cannot be delimited raises :class:`AmsStreamError` in its turn, after every frame before it
    was handed out; from then on the decoder is broken (:attr:`broken` says why) and raises again.

    Memory: a frame's length is checked when its 6 header bytes arrive, so what is held is at most one
    frame of ``max_ams_length`` plus the bytes of the last read that the caller has not drained yet.
    """

    __slots__ = ("_buffer", "_max_ams_length", "_max_skipped", "_pos", "_skip", "broken")

    def __init__(self, max_ams_length: int = MAX_AMS_LENGTH, max_skipped_length: int = 0) -> None:
        if max_ams_length < AMS_HEADER_SIZE:
            raise ValueError(f"max_ams_length {max_ams_length} is below the AMS header's 32 bytes")
        self._buffer = bytearray()
        self._pos = 0
        self._max_ams_length = max_ams_length
        self._max_skipped = max_skipped_length
        self._skip = 0
        """bytes of an oversize frame still to drop as they arrive"""
        self.broken: str | None = None

    @property
    def pending(self) -> int:
        """Bytes received and not yet handed out as frames (an oversize frame being dropped counts)."""
        return len(self._buffer) - self._pos + (1 if self._skip else 0)

    def receive_data(self, data: bytes) -> None:
        """Append the bytes of one read (``b""`` at EOF is fine: it adds nothing)."""
        if self._skip:
            dropped = min(self._skip, len(data))
            self._skip -= dropped
            data = data[dropped:]
        if self._pos and self._pos == len(self._buffer):
            self._buffer.clear()
            self._pos = 0
        self._buffer += data

    def feed(self, data: bytes) -> Iterator[Frame | OversizeAmsFrame]:
        """``receive_data(data)`` now; the iterator yields the complete frames (raising as ``next_frame``)."""
        self.receive_data(data)
        return self._drain()

    def _drain(self) -> Iterator[Frame | OversizeAmsFrame]:
        while True:
            frame = self.next_frame()
            if frame is NEED_DATA:
                return
            yield frame

    def single_frame(self, data: bytes) -> AmsPacket | None:
        """A shortcut for the common case of a client with one request in flight: when nothing is
        buffered and ``data`` (one read of the socket) is exactly one well-formed AMS frame, its packet,
        taken without copying ``data`` into the buffer. None otherwise: then ``receive_data(data)`` and
        ``next_frame()`` as always (they find every problem this shortcut leaves to them)."""
        if self._pos != len(self._buffer) or self._skip or len(data) < 38 or self.broken is not None:
            return None
        reserved, length, tn, tp, sn, sp, cmd, flags, data_length, error, invoke = _FRAME_HEAD.unpack_from(
            data
        )
        if (
            reserved != 0
            or length + AMS_TCP_HEADER_SIZE != len(data)
            or length > self._max_ams_length
            or data_length != length - AMS_HEADER_SIZE
        ):
            return None
        nets = _NET_IDS
        header = AmsHeader(
            nets.get(tn) or _net_id(tn),
            tp,
            nets.get(sn) or _net_id(sn),
            sp,
            cmd,
            flags,
            data_length,
            error,
            invoke,
        )
        return AmsPacket(header, data[38:])

    def next_frame(self) -> Frame | OversizeAmsFrame | Literal[NeedData.NEED_DATA]:
        """The next complete frame, or :data:`NEED_DATA`; raises :class:`AmsStreamError` (see module doc)."""
        if self.broken is not None:
            raise AmsStreamError(self.broken)
        buf = self._buffer
        pos = self._pos
        end = len(buf)
        if end - pos < AMS_TCP_HEADER_SIZE:
            return self._need_data()
        reserved, length = _TCP_HEADER.unpack_from(buf, pos)
        if reserved == 0:
            if self._max_ams_length < length <= self._max_skipped:
                return self._oversize(length)
            if not AMS_HEADER_SIZE <= length <= self._max_ams_length:
                self._break(
                    f"AMS/TCP length {length} at stream byte {pos} is outside {AMS_HEADER_SIZE}.."
                    f"{self._max_ams_length} for an AMS frame"
                )
        elif reserved in _ROUTER_COMMANDS:
            if length > MAX_ROUTER_LENGTH:
                self._break(
                    f"AMS/TCP length {length} at stream byte {pos} is above {MAX_ROUTER_LENGTH} for router "
                    f"message 0x{reserved:04X} ({AmsTcpCommand(reserved).name})"
                )
        else:
            self._break(
                f"AMS/TCP reserved word 0x{reserved:04X} at stream byte {pos} is no AMS/TCP command "
                "(0x0000 AMS frame, 0x0001, 0x1000, 0x1001, 0x1002 router messages): this is not AMS/TCP"
            )
        stop = pos + AMS_TCP_HEADER_SIZE + length
        if stop > end:
            return self._need_data()
        frame: Frame
        if reserved == 0:
            tn, tp, sn, sp, cmd, flags, data_length, error, invoke = _AMS_HEADER.unpack_from(buf, pos + 6)
            if data_length != length - AMS_HEADER_SIZE:
                self._break(
                    f"AMS header at stream byte {pos} announces {data_length} data bytes, its AMS/TCP "
                    f"length {length} leaves {length - AMS_HEADER_SIZE}: the frame cannot be delimited"
                )
            nets = _NET_IDS
            header = AmsHeader(
                nets.get(tn) or _net_id(tn),
                tp,
                nets.get(sn) or _net_id(sn),
                sp,
                cmd,
                flags,
                data_length,
                error,
                invoke,
            )
            frame = AmsPacket(header, bytes(buf[pos + 38 : stop]))
        else:
            frame = AmsTcpFrame(reserved, bytes(buf[pos + AMS_TCP_HEADER_SIZE : stop]))
        self._pos = stop
        return frame

    def _oversize(self, length: int) -> OversizeAmsFrame | Literal[NeedData.NEED_DATA]:
        """An AMS frame above the limit, within ``max_skipped_length``: its header once 38 bytes are in
        (its data length must agree, or the stream cannot be delimited), the rest dropped."""
        buf, pos = self._buffer, self._pos
        if len(buf) - pos < 38:
            return self._need_data()
        tn, tp, sn, sp, cmd, flags, data_length, error, invoke = _AMS_HEADER.unpack_from(buf, pos + 6)
        if data_length != length - AMS_HEADER_SIZE:
            self._break(
                f"AMS header at stream byte {pos} announces {data_length} data bytes, its AMS/TCP length "
                f"{length} leaves {length - AMS_HEADER_SIZE}: the frame cannot be delimited"
            )
        header = AmsHeader(_net_id(tn), tp, _net_id(sn), sp, cmd, flags, data_length, error, invoke)
        stop = pos + AMS_TCP_HEADER_SIZE + length
        here = min(stop, len(buf))
        self._skip = stop - here
        self._pos = here
        return OversizeAmsFrame(header, length)

    def _need_data(self) -> Literal[NeedData.NEED_DATA]:
        pos = self._pos
        if pos:
            if pos == len(self._buffer):
                self._buffer.clear()
            else:
                del self._buffer[:pos]
            self._pos = 0
        return NEED_DATA

    def _break(self, reason: str) -> None:
        self.broken = f"{reason}: the stream cannot be resynchronised; close the connection"
        self._buffer = bytearray()
        self._pos = 0
        raise AmsStreamError(self.broken)


# --------------------------------------------------------------------------------------------
# Encoding
# --------------------------------------------------------------------------------------------


def encode_request(
    target: AmsAddress,
    source: AmsAddress,
    command: int,
    invoke_id: int,
    payload: bytes,
    state_flags: int = REQUEST_FLAGS,
) -> bytes:
    """A request frame (state flags 0x0004); the server uses it for DeviceNotification (command 8)."""
    return (
        _FRAME_HEAD.pack(
            0,
            AMS_HEADER_SIZE + len(payload),
            target[0],
            target[1],
            source[0],
            source[1],
            command,
            state_flags,
            len(payload),
            0,
            invoke_id,
        )
        + payload
    )


def encode_response(request: AmsHeader, payload: bytes, error_code: int = 0) -> bytes:
    """The reply to ``request``: target and source swapped, command and invoke id echoed, flags 0x0005."""
    return (
        _FRAME_HEAD.pack(
            0,
            AMS_HEADER_SIZE + len(payload),
            request.source_net_id,
            request.source_port,
            request.target_net_id,
            request.target_port,
            request.command,
            RESPONSE_FLAGS,
            len(payload),
            error_code,
            request.invoke_id,
        )
        + payload
    )


def encode_error_response(request: AmsHeader, code: int) -> bytes:
    """An AMS-level error reply: the code in the AMS header, no payload (unknown port 0x6, unknown
    command 0x8, an address outside the route allowlist). AdsLib returns the header's code at once."""
    return encode_response(request, b"", code)


def encode_router_frame(command: int, data: bytes) -> bytes:
    """An AMS/TCP frame without AMS header (router message)."""
    return _TCP_HEADER.pack(command, len(data)) + data


def port_of_port_request(frame: AmsTcpFrame) -> int:
    """The u16 port of a PORT_CONNECT (wanted port, 0 = any) or PORT_CLOSE request (port to release).

    Raises :class:`AdsError` (SIZE_WRONG) when the body is not 2 bytes: the server then closes, as
    there is no reply format for a broken router message.
    """
    if len(frame.data) != 2:
        raise AdsError(
            ErrorCode.SIZE_WRONG,
            f"router message 0x{frame.command:04X} carries {len(frame.data)} bytes, expected a 2-byte port",
        )
    port: int = _U16.unpack(frame.data)[0]
    return port


def encode_port_connect_reply(net_id: NetId, port: int) -> bytes:
    """Reply to PORT_CONNECT (0x1000): the NetId and AMS port the client is to use as its source."""
    return encode_router_frame(AmsTcpCommand.PORT_CONNECT, bytes(net_id) + _U16.pack(port))


def encode_port_close_reply(port: int) -> bytes:
    """Reply to PORT_CLOSE (0x0001): the same command with the released port.

    What a TwinCAT router answers is not recorded here; ads-client accepts any 0x0001 frame or the
    connection closing, AdsLib never sends PORT_CLOSE.
    """
    return encode_router_frame(AmsTcpCommand.PORT_CLOSE, _U16.pack(port))
