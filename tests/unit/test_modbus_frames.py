"""The sans-I/O Modbus TCP codec (H-03): framing, request decoding, response encoding.

pymodbus 3.16's PDU classes are the oracle for well-formed traffic: requests they encode decode
here to the same fields, responses encoded here decode there to the same values.
"""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymodbus.pdu import DecodePDU
from pymodbus.pdu.bit_message import (
    ReadCoilsRequest,
    ReadDiscreteInputsRequest,
    WriteMultipleCoilsRequest,
    WriteSingleCoilRequest,
)
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersRequest,
    ReadInputRegistersRequest,
    ReadWriteMultipleRegistersRequest,
    WriteMultipleRegistersRequest,
    WriteSingleRegisterRequest,
)

from hli_server.codecs.modbus_frames import (
    MAX_ADU,
    ExceptionCode,
    Frame,
    MbapDecoder,
    ModbusError,
    ReadBits,
    ReadRegisters,
    ReadWriteRegisters,
    WriteCoils,
    WriteRegisters,
    WriteSingleCoil,
    WriteSingleRegister,
    decode_request,
    encode_adu,
    encode_exception,
    encode_read_bits,
    encode_read_registers,
    encode_write_multiple,
    pack_bits,
    unpack_bits,
)

pytestmark = pytest.mark.req("H-03")


def adu(tid: int, pdu: bytes, unit: int = 1, pid: int = 0) -> bytes:
    return struct.pack(">HHHB", tid, pid, len(pdu) + 1, unit) + pdu


# --------------------------------------------------------------------------------------------
# Framing
# --------------------------------------------------------------------------------------------


def test_one_frame() -> None:
    frames = MbapDecoder().feed(adu(7, b"\x03\x00\x10\x00\x02", unit=1))
    assert frames == [Frame(7, 0, 1, b"\x03\x00\x10\x00\x02")]


def test_several_frames_in_one_read_come_out_in_order() -> None:
    data = b"".join(adu(i, bytes([3, 0, i, 0, 1])) for i in range(5))
    frames = MbapDecoder().feed(data)
    assert [f.transaction_id for f in frames] == [0, 1, 2, 3, 4]
    assert [f.pdu[2] for f in frames] == [0, 1, 2, 3, 4]


def test_a_frame_split_anywhere_is_reassembled() -> None:
    data = adu(1, b"\x10\x00\x00\x00\x02\x04\x01\x02\x03\x04") + adu(2, b"\x01\x00\x00\x00\x08")
    for cut in range(1, len(data)):
        decoder = MbapDecoder()
        first = decoder.feed(data[:cut])
        assert decoder.pending == cut - sum(len(f.pdu) + 7 for f in first)
        rest = decoder.feed(data[cut:])
        assert [f.transaction_id for f in first + rest] == [1, 2]
        assert decoder.pending == 0


def test_byte_by_byte() -> None:
    data = adu(1, b"\x03\x00\x00\x00\x01") * 3
    decoder = MbapDecoder()
    frames = [f for b in data for f in decoder.feed(bytes([b]))]
    assert len(frames) == 3


def test_other_protocol_id_is_delivered_for_the_server_to_drop() -> None:
    frames = MbapDecoder().feed(adu(1, b"\x03\x00\x00\x00\x01", pid=1) + adu(2, b"\x03\x00\x00\x00\x01"))
    assert [(f.transaction_id, f.protocol_id) for f in frames] == [(1, 1), (2, 0)]


@pytest.mark.parametrize("length", [0, 1, 255, 0xFFFF])
def test_length_out_of_range_breaks_the_stream_after_the_good_frames(length: int) -> None:
    good = adu(1, b"\x03\x00\x00\x00\x01")
    bad = struct.pack(">HHHB", 2, 0, length, 1) + b"\x03\x00\x00\x00\x01"
    decoder = MbapDecoder()
    frames = decoder.feed(good + bad + good)
    assert [f.transaction_id for f in frames] == [1]
    assert decoder.broken is not None
    assert f"length field {length}" in decoder.broken
    assert decoder.feed(good) == []


def test_largest_adu() -> None:
    pdu = b"\x10" + bytes(252)
    data = adu(1, pdu)
    assert len(data) == MAX_ADU
    assert MbapDecoder().feed(data)[0].pdu == pdu


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(min_size=0, max_size=80), max_size=8))
def test_random_bytes_never_raise(chunks: list[bytes]) -> None:
    decoder = MbapDecoder()
    codes = set()
    for chunk in chunks:
        for frame in decoder.feed(chunk):
            try:
                decode_request(frame.pdu)
            except ModbusError as exc:
                codes.add(exc.code)
    assert codes <= {1, 2, 3}
    assert decoder.pending < MAX_ADU


def test_encode_adu() -> None:
    assert encode_adu(0x1234, 9, b"\x03\x02\xab\xcd") == bytes.fromhex("1234 0000 0005 09 0302abcd")


# --------------------------------------------------------------------------------------------
# Requests: agreement with pymodbus' request classes
# --------------------------------------------------------------------------------------------


def encoded(request: object) -> bytes:
    return bytes([request.function_code]) + request.encode()  # type: ignore[attr-defined]


@settings(max_examples=100, deadline=None)
@given(address=st.integers(0, 65535), count=st.integers(1, 2000))
def test_read_bits_like_pymodbus(address: int, count: int) -> None:
    for cls, fc in ((ReadCoilsRequest, 1), (ReadDiscreteInputsRequest, 2)):
        pdu = encoded(cls(address=address, count=count))
        if address + count > 65536:
            with pytest.raises(ModbusError) as info:
                decode_request(pdu)
            assert info.value.code == ExceptionCode.ILLEGAL_DATA_ADDRESS
        else:
            assert decode_request(pdu) == ReadBits(fc, address, count)


@settings(max_examples=100, deadline=None)
@given(address=st.integers(0, 65535 - 125), count=st.integers(1, 125))
def test_read_registers_like_pymodbus(address: int, count: int) -> None:
    for cls, fc in ((ReadHoldingRegistersRequest, 3), (ReadInputRegistersRequest, 4)):
        assert decode_request(encoded(cls(address=address, count=count))) == ReadRegisters(fc, address, count)


@settings(max_examples=100, deadline=None)
@given(address=st.integers(0, 65535), value=st.booleans())
def test_write_single_coil_like_pymodbus(address: int, value: bool) -> None:
    pdu = encoded(WriteSingleCoilRequest(address=address, bits=[value]))
    assert decode_request(pdu) == WriteSingleCoil(address, value)


@settings(max_examples=100, deadline=None)
@given(address=st.integers(0, 65535), value=st.integers(0, 65535))
def test_write_single_register_like_pymodbus(address: int, value: int) -> None:
    pdu = encoded(WriteSingleRegisterRequest(address=address, registers=[value]))
    assert decode_request(pdu) == WriteSingleRegister(address, struct.pack(">H", value))


@settings(max_examples=100, deadline=None)
@given(address=st.integers(0, 60000), bits=st.lists(st.booleans(), min_size=1, max_size=1968))
def test_write_coils_like_pymodbus(address: int, bits: list[bool]) -> None:
    pdu = encoded(WriteMultipleCoilsRequest(address=address, bits=bits))
    assert decode_request(pdu) == WriteCoils(address, tuple(bits))


@settings(max_examples=100, deadline=None)
@given(address=st.integers(0, 60000), registers=st.lists(st.integers(0, 65535), min_size=1, max_size=123))
def test_write_registers_like_pymodbus(address: int, registers: list[int]) -> None:
    pdu = encoded(WriteMultipleRegistersRequest(address=address, registers=registers))
    request = decode_request(pdu)
    assert request == WriteRegisters(address, struct.pack(f">{len(registers)}H", *registers))
    assert isinstance(request, WriteRegisters)
    assert request.count == len(registers)


@settings(max_examples=100, deadline=None)
@given(
    read_address=st.integers(0, 60000),
    read_count=st.integers(1, 125),
    write_address=st.integers(0, 60000),
    registers=st.lists(st.integers(0, 65535), min_size=1, max_size=121),
)
def test_read_write_registers_like_pymodbus(
    read_address: int, read_count: int, write_address: int, registers: list[int]
) -> None:
    pdu = encoded(
        ReadWriteMultipleRegistersRequest(
            read_address=read_address,
            read_count=read_count,
            write_address=write_address,
            write_registers=registers,
        )
    )
    expected = ReadWriteRegisters(
        read_address, read_count, write_address, struct.pack(f">{len(registers)}H", *registers)
    )
    assert decode_request(pdu) == expected


# --------------------------------------------------------------------------------------------
# Requests: what gets which exception
# --------------------------------------------------------------------------------------------

_BAD_REQUESTS = [
    ("empty PDU", b"", ExceptionCode.ILLEGAL_FUNCTION),
    ("FC 7 read exception status", b"\x07", ExceptionCode.ILLEGAL_FUNCTION),
    ("FC 8 diagnostics", b"\x08\x00\x00\x12\x34", ExceptionCode.ILLEGAL_FUNCTION),
    ("FC 43 device identification", b"\x2b\x0e\x01\x00", ExceptionCode.ILLEGAL_FUNCTION),
    ("FC 0", b"\x00", ExceptionCode.ILLEGAL_FUNCTION),
    ("FC 0x83 (a response code)", b"\x83\x02", ExceptionCode.ILLEGAL_FUNCTION),
    ("FC 3 short", b"\x03\x00\x00\x00", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 3 long", b"\x03\x00\x00\x00\x01\x00", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 3 count 0", b"\x03\x00\x00\x00\x00", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 3 count 126", b"\x03\x00\x00\x00\x7e", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 4 past 65535", b"\x04\xff\xff\x00\x02", ExceptionCode.ILLEGAL_DATA_ADDRESS),
    ("FC 1 count 2001", b"\x01\x00\x00\x07\xd1", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 5 value 0x1234", b"\x05\x00\x00\x12\x34", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 5 value 0x0001", b"\x05\x00\x00\x00\x01", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 6 short", b"\x06\x00\x00\x00", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 15 byte count too small", b"\x0f\x00\x00\x00\x09\x01\xff", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 15 data missing", b"\x0f\x00\x00\x00\x09\x02\xff", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 15 count 0", b"\x0f\x00\x00\x00\x00\x00", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 16 header cut", b"\x10\x00\x00\x00", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 16 odd byte count", b"\x10\x00\x00\x00\x01\x03\x00\x00\x00", ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 16 count 124", b"\x10\x00\x00\x00\x7c\xf8" + bytes(248), ExceptionCode.ILLEGAL_DATA_VALUE),
    ("FC 16 trailing byte", b"\x10\x00\x00\x00\x01\x02\x00\x00\x00", ExceptionCode.ILLEGAL_DATA_VALUE),
    (
        "FC 23 write count 122",
        b"\x17\x00\x00\x00\x01\x00\x00\x00\x7a\xf4" + bytes(244),
        ExceptionCode.ILLEGAL_DATA_VALUE,
    ),
    (
        "FC 23 read count 0",
        b"\x17\x00\x00\x00\x00\x00\x00\x00\x01\x02\x00\x00",
        ExceptionCode.ILLEGAL_DATA_VALUE,
    ),
    ("FC 23 short", b"\x17\x00\x00\x00\x01\x00\x00\x00", ExceptionCode.ILLEGAL_DATA_VALUE),
]


@pytest.mark.parametrize(("what", "pdu", "code"), _BAD_REQUESTS, ids=[b[0] for b in _BAD_REQUESTS])
def test_bad_requests_get_their_exception_code(what: str, pdu: bytes, code: ExceptionCode) -> None:
    with pytest.raises(ModbusError) as info:
        decode_request(pdu)
    assert info.value.code == code
    assert f"0x{int(code):02X}" in str(info.value)


# --------------------------------------------------------------------------------------------
# Responses: pymodbus' client decoder reads them back
# --------------------------------------------------------------------------------------------

_CLIENT = DecodePDU(is_server=False)


@settings(max_examples=100, deadline=None)
@given(bits=st.lists(st.booleans(), min_size=1, max_size=2000))
def test_read_bits_response_decodes_in_pymodbus(bits: list[bool]) -> None:
    for fc in (1, 2):
        response = _CLIENT.decode(encode_read_bits(fc, bits))
        assert response is not None
        assert response.function_code == fc
        assert list(response.bits[: len(bits)]) == bits
        assert not any(response.bits[len(bits) :])


@settings(max_examples=100, deadline=None)
@given(registers=st.lists(st.integers(0, 65535), min_size=1, max_size=125))
def test_read_registers_response_decodes_in_pymodbus(registers: list[int]) -> None:
    data = struct.pack(f">{len(registers)}H", *registers)
    for fc in (3, 4, 23):
        response = _CLIENT.decode(encode_read_registers(fc, data))
        assert response is not None
        assert response.function_code == fc
        assert list(response.registers) == registers


def test_write_multiple_and_exception_responses_decode_in_pymodbus() -> None:
    response = _CLIENT.decode(encode_write_multiple(16, 2000, 4))
    assert response is not None
    assert (response.address, response.count) == (2000, 4)
    error = _CLIENT.decode(encode_exception(3, ExceptionCode.ILLEGAL_DATA_ADDRESS))
    assert error is not None
    assert error.isError()
    assert error.exception_code == 2


@given(bits=st.lists(st.booleans(), max_size=100))
def test_pack_unpack_bits_round_trip(bits: list[bool]) -> None:
    assert unpack_bits(pack_bits(bits), len(bits)) == bits


def test_bit_order_is_lsb_first() -> None:
    # V1.1b3 6.1: coils 20..27 = CD hex -> 1100 1101, coil 27 is the MSB
    assert pack_bits([True, False, True, True, False, False, True, True]) == b"\xcd"
    assert pack_bits([True] + [False] * 8) == b"\x01\x00"
