"""Modbus TCP framing and PDU codec, sans-I/O (H-03).

Bytes in, requests out; responses in, bytes out. No sockets, no asyncio, no pymodbus: the asyncio
server (:mod:`hli_server.adapters.modbus`) is a thin loop around this module, and this module can be
fuzzed and tested without a network. Sources: *MODBUS Application Protocol Specification V1.1b3*
(function codes, quantities, exception codes) and *MODBUS Messaging on TCP/IP Implementation
Guide V1.0b* (MBAP header).

One Modbus TCP ADU (all integers big-endian)::

    [            MBAP header (7 bytes)             ][          PDU (1..253 bytes)          ]
    [ transaction id ][ protocol id ][ length ][ unit id ][ function code ][    data        ]
          2 bytes          2 bytes     2 bytes   1 byte        1 byte        0..252 bytes

    protocol id = 0 (Modbus); length = 1 (unit id) + len(PDU), so 2..254

A TCP stream carries ADUs back to back with no delimiter; one ``recv`` may hold a part of one, or
several (pipelining). :class:`MbapDecoder` buffers partial ADUs and returns every complete one, in
order. The length field is the only way to find the next ADU: when it is out of range (< 2 or
> 254) the stream cannot be resynchronised, and the decoder reports it (:attr:`MbapDecoder.broken`)
so that the server closes that connection. An ADU with a protocol id other than 0 is delivered
with its ``protocol_id``; the server discards it (it is not Modbus) and goes on with the next.

Request PDUs decoded here (function code: data)::

    01 read coils              address u16, quantity u16 (1..2000)
    02 read discrete inputs    address u16, quantity u16 (1..2000)
    03 read holding registers  address u16, quantity u16 (1..125)
    04 read input registers    address u16, quantity u16 (1..125)
    05 write single coil       address u16, value u16 (0xFF00 = ON, 0x0000 = OFF; else 0x03)
    06 write single register   address u16, value u16
    15 write multiple coils    address u16, quantity u16 (1..1968), byte count u8 (= ceil(q/8)), bits
    16 write multiple regs     address u16, quantity u16 (1..123), byte count u8 (= 2q), registers
    23 read/write multiple     read address u16, read quantity u16 (1..125), write address u16,
                               write quantity u16 (1..121), byte count u8 (= 2 wq), registers

A PDU that is too short or too long for its function code, a quantity out of range or a byte count
that does not match gets exception 0x03 (illegal data value), as the specification's state diagrams
say; ``address + quantity > 65536`` gets 0x02 (illegal data address); any other function code gets
0x01 (illegal function). Bits are packed LSB first, the first bit in the lowest bit of the first byte.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Final, NamedTuple

__all__ = [
    "MAX_ADU",
    "MAX_PDU",
    "MBAP_HEADER",
    "MBAP_SIZE",
    "ExceptionCode",
    "Frame",
    "FunctionCode",
    "MbapDecoder",
    "ModbusError",
    "ReadBits",
    "ReadRegisters",
    "ReadWriteRegisters",
    "Request",
    "WriteCoils",
    "WriteRegisters",
    "WriteSingleCoil",
    "WriteSingleRegister",
    "decode_request",
    "encode_adu",
    "encode_exception",
    "encode_read_bits",
    "encode_read_registers",
    "encode_write_multiple",
    "pack_bits",
    "unpack_bits",
]

MBAP_HEADER: Final = struct.Struct(">HHHB")
"""transaction id, protocol id, length, unit id."""
MBAP_SIZE: Final = MBAP_HEADER.size  # 7
MAX_PDU: Final = 253
MAX_ADU: Final = MBAP_SIZE + MAX_PDU
"""260 bytes: the largest ADU."""
_MIN_LENGTH: Final = 2
_MAX_LENGTH: Final = 1 + MAX_PDU

MAX_READ_BITS: Final = 2000
MAX_READ_REGISTERS: Final = 125
MAX_WRITE_COILS: Final = 1968
MAX_WRITE_REGISTERS: Final = 123
MAX_RW_WRITE_REGISTERS: Final = 121

COIL_ON: Final = 0xFF00
COIL_OFF: Final = 0x0000


class FunctionCode(IntEnum):
    """The function codes this codec decodes (V1.1b3 section 6)."""

    READ_COILS = 1
    READ_DISCRETE_INPUTS = 2
    READ_HOLDING_REGISTERS = 3
    READ_INPUT_REGISTERS = 4
    WRITE_SINGLE_COIL = 5
    WRITE_SINGLE_REGISTER = 6
    WRITE_MULTIPLE_COILS = 15
    WRITE_MULTIPLE_REGISTERS = 16
    READ_WRITE_MULTIPLE_REGISTERS = 23


class ExceptionCode(IntEnum):
    """Modbus exception codes (V1.1b3 section 7)."""

    ILLEGAL_FUNCTION = 0x01
    ILLEGAL_DATA_ADDRESS = 0x02
    ILLEGAL_DATA_VALUE = 0x03
    SERVER_DEVICE_FAILURE = 0x04
    GATEWAY_PATH_UNAVAILABLE = 0x0A
    GATEWAY_TARGET_FAILED_TO_RESPOND = 0x0B


class ModbusError(Exception):
    """A request that gets a Modbus exception response; ``code`` travels over the wire."""

    def __init__(self, code: ExceptionCode, message: str) -> None:
        super().__init__(message)
        self.code = code

    def __str__(self) -> str:
        return f"{self.args[0]} (Modbus exception 0x{int(self.code):02X} {self.code.name})"


class Frame(NamedTuple):
    """One complete ADU: the MBAP fields and the PDU (function code + data)."""

    transaction_id: int
    protocol_id: int
    unit_id: int
    pdu: bytes


class MbapDecoder:
    """Splits a TCP byte stream into ADUs; keeps the tail of an incomplete one for the next call.

    ``feed(data)`` returns every ADU completed by ``data``, in stream order. After a length field
    out of range, :attr:`broken` holds the reason and every later ``feed`` returns nothing: the
    frames before the damage are still returned and should be answered, then the connection closed.
    """

    __slots__ = ("_buffer", "broken")

    def __init__(self) -> None:
        self._buffer = b""
        self.broken: str | None = None

    @property
    def pending(self) -> int:
        """Bytes of an incomplete ADU held back."""
        return len(self._buffer)

    def feed(self, data: bytes) -> list[Frame]:
        if self.broken is not None:
            return []
        buf = self._buffer + data if self._buffer else data
        frames: list[Frame] = []
        pos = 0
        end = len(buf)
        unpack = MBAP_HEADER.unpack_from
        while end - pos >= MBAP_SIZE:
            tid, pid, length, unit = unpack(buf, pos)
            if not _MIN_LENGTH <= length <= _MAX_LENGTH:
                self.broken = (
                    f"MBAP length field {length} at stream byte {pos} is outside "
                    f"{_MIN_LENGTH}..{_MAX_LENGTH}: "
                    "the stream cannot be resynchronised"
                )
                self._buffer = b""
                return frames
            stop = pos + 6 + length
            if stop > end:
                break
            frames.append(Frame(tid, pid, unit, bytes(buf[pos + MBAP_SIZE : stop])))
            pos = stop
        self._buffer = bytes(buf[pos:]) if pos < end else b""
        return frames


def encode_adu(transaction_id: int, unit_id: int, pdu: bytes) -> bytes:
    """MBAP header + PDU."""
    return MBAP_HEADER.pack(transaction_id, 0, len(pdu) + 1, unit_id) + pdu


# --------------------------------------------------------------------------------------------
# Requests
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ReadBits:
    """FC 1 (coils) or 2 (discrete inputs)."""

    function_code: int
    address: int
    count: int


@dataclass(frozen=True, slots=True)
class ReadRegisters:
    """FC 3 (holding) or 4 (input registers)."""

    function_code: int
    address: int
    count: int


@dataclass(frozen=True, slots=True)
class WriteSingleCoil:
    """FC 5; the response echoes the request PDU."""

    address: int
    value: bool
    function_code: int = FunctionCode.WRITE_SINGLE_COIL


@dataclass(frozen=True, slots=True)
class WriteSingleRegister:
    """FC 6; ``data`` is the register as sent (2 bytes, big-endian). The response echoes the request."""

    address: int
    data: bytes
    function_code: int = FunctionCode.WRITE_SINGLE_REGISTER

    @property
    def count(self) -> int:
        return 1


@dataclass(frozen=True, slots=True)
class WriteCoils:
    """FC 15."""

    address: int
    values: tuple[bool, ...]
    function_code: int = FunctionCode.WRITE_MULTIPLE_COILS

    @property
    def count(self) -> int:
        return len(self.values)


@dataclass(frozen=True, slots=True)
class WriteRegisters:
    """FC 16; ``data`` holds the registers as sent (2 bytes each, big-endian)."""

    address: int
    data: bytes
    function_code: int = FunctionCode.WRITE_MULTIPLE_REGISTERS

    @property
    def count(self) -> int:
        return len(self.data) // 2


@dataclass(frozen=True, slots=True)
class ReadWriteRegisters:
    """FC 23: the write is performed before the read (V1.1b3 6.17)."""

    read_address: int
    read_count: int
    write_address: int
    data: bytes
    function_code: int = FunctionCode.READ_WRITE_MULTIPLE_REGISTERS

    @property
    def write_count(self) -> int:
        return len(self.data) // 2


Request = (
    ReadBits
    | ReadRegisters
    | WriteSingleCoil
    | WriteSingleRegister
    | WriteCoils
    | WriteRegisters
    | ReadWriteRegisters
)

_U16x2: Final = struct.Struct(">HH")
_RW_HEAD: Final = struct.Struct(">HHHHB")
_MULTI_HEAD: Final = struct.Struct(">HHB")


def _value_error(fc: int, text: str) -> ModbusError:
    return ModbusError(ExceptionCode.ILLEGAL_DATA_VALUE, f"function {fc}: {text}")


def _check_range(fc: int, address: int, count: int, what: str = "") -> None:
    if address + count > 0x10000:
        raise ModbusError(
            ExceptionCode.ILLEGAL_DATA_ADDRESS,
            f"function {fc}: {what}address {address} + quantity {count} runs past 65535",
        )


def _check_quantity(fc: int, count: int, maximum: int, what: str = "quantity") -> None:
    if not 1 <= count <= maximum:
        raise _value_error(fc, f"{what} {count} is outside 1..{maximum}")


def decode_request(pdu: bytes) -> Request:
    """Decode a request PDU; raise :class:`ModbusError` with the exception code to answer."""
    if not pdu:
        raise ModbusError(ExceptionCode.ILLEGAL_FUNCTION, "empty PDU: no function code")
    fc = pdu[0]
    size = len(pdu)
    if fc in (1, 2, 3, 4):
        if size != 5:
            raise _value_error(fc, f"request PDU is {size} bytes, expected 5")
        address, count = _U16x2.unpack_from(pdu, 1)
        _check_quantity(fc, count, MAX_READ_BITS if fc <= 2 else MAX_READ_REGISTERS)
        _check_range(fc, address, count)
        return ReadBits(fc, address, count) if fc <= 2 else ReadRegisters(fc, address, count)
    if fc == 5:
        if size != 5:
            raise _value_error(fc, f"request PDU is {size} bytes, expected 5")
        address, value = _U16x2.unpack_from(pdu, 1)
        if value not in (COIL_ON, COIL_OFF):
            raise _value_error(fc, f"coil value 0x{value:04X} is neither 0xFF00 (ON) nor 0x0000 (OFF)")
        return WriteSingleCoil(address, value == COIL_ON)
    if fc == 6:
        if size != 5:
            raise _value_error(fc, f"request PDU is {size} bytes, expected 5")
        address = _U16x2.unpack_from(pdu, 1)[0]
        return WriteSingleRegister(address, bytes(pdu[3:5]))
    if fc in (15, 16):
        if size < 6:
            raise _value_error(fc, f"request PDU is {size} bytes, too short for its header")
        address, count, byte_count = _MULTI_HEAD.unpack_from(pdu, 1)
        if fc == 15:
            _check_quantity(fc, count, MAX_WRITE_COILS)
            expected = (count + 7) // 8
        else:
            _check_quantity(fc, count, MAX_WRITE_REGISTERS)
            expected = 2 * count
        if byte_count != expected or size != 6 + byte_count:
            raise _value_error(
                fc,
                f"byte count {byte_count} with {size - 6} data bytes does not fit quantity {count} "
                f"(expected {expected})",
            )
        _check_range(fc, address, count)
        payload = bytes(pdu[6:])
        if fc == 15:
            return WriteCoils(address, tuple(unpack_bits(payload, count)))
        return WriteRegisters(address, payload)
    if fc == 23:
        if size < 10:
            raise _value_error(fc, f"request PDU is {size} bytes, too short for its header")
        read_address, read_count, write_address, write_count, byte_count = _RW_HEAD.unpack_from(pdu, 1)
        _check_quantity(fc, read_count, MAX_READ_REGISTERS, "read quantity")
        _check_quantity(fc, write_count, MAX_RW_WRITE_REGISTERS, "write quantity")
        if byte_count != 2 * write_count or size != 10 + byte_count:
            raise _value_error(
                fc,
                f"byte count {byte_count} with {size - 10} data bytes does not fit write quantity "
                f"{write_count} (expected {2 * write_count})",
            )
        _check_range(fc, read_address, read_count, "read ")
        _check_range(fc, write_address, write_count, "write ")
        return ReadWriteRegisters(read_address, read_count, write_address, bytes(pdu[10:]))
    raise ModbusError(ExceptionCode.ILLEGAL_FUNCTION, f"function code {fc} is not supported")


# --------------------------------------------------------------------------------------------
# Responses
# --------------------------------------------------------------------------------------------


def pack_bits(bits: Sequence[int | bool]) -> bytes:
    """LSB first: bit ``i`` goes to byte ``i // 8``, bit position ``i % 8``."""
    acc = 0
    for i, bit in enumerate(bits):
        if bit:
            acc |= 1 << i
    return acc.to_bytes((len(bits) + 7) // 8, "little")


def unpack_bits(data: bytes, count: int) -> list[bool]:
    """The first ``count`` bits of ``data`` (LSB first)."""
    acc = int.from_bytes(data, "little")
    return [bool(acc >> i & 1) for i in range(count)]


def encode_read_bits(function_code: int, bits: Sequence[int | bool]) -> bytes:
    """Response PDU of FC 1/2: byte count, packed bits."""
    packed = pack_bits(bits)
    return bytes((function_code, len(packed))) + packed


def encode_read_registers(function_code: int, data: bytes) -> bytes:
    """Response PDU of FC 3/4/23: byte count, the registers (already big-endian 16-bit words)."""
    return bytes((function_code, len(data))) + data


def encode_write_multiple(function_code: int, address: int, count: int) -> bytes:
    """Response PDU of FC 15/16: address and quantity."""
    return bytes((function_code,)) + _U16x2.pack(address, count)


def encode_exception(function_code: int, code: int) -> bytes:
    """Exception response PDU: function code | 0x80, exception code."""
    return bytes(((function_code | 0x80) & 0xFF, code))
