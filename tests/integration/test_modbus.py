"""The Modbus TCP view of the process image over real sockets (H-03; C43-02 for the last test).

Clients: pymodbus 3.16's ``AsyncModbusTcpClient`` for ordinary traffic, a raw asyncio stream for
what a well-behaved client cannot send (pipelining, malformed frames, bad coil values).
Servers bind port 0. Two set-ups:

* a bare :class:`ProcessImage` whose CNC->PLC half is published from values chosen by the test
  (every type, extreme values) and whose PLC->CNC half is read back directly;
* the :class:`Runtime` with the stepped clock and the ``modbus`` adapter, for live values, the
  latch at the next cycle and the dynamic position limit stopping an axis.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import random
import struct
import time
from collections.abc import AsyncIterator, Iterator, Sequence
from typing import Any

import pytest
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.pdu import ModbusPDU

from hli_server.adapters.modbus import ModbusAdapter
from hli_server.configuration import load_machine
from hli_server.image import ProcessImage
from hli_server.testing import Harness
from schemas.config import MachineConfig
from schemas.layout import MODBUS_SNAPSHOT_REGISTER, Direction, Layout, ModbusTable, build_layout
from schemas.wire import ProgramState
from tests.integration.servers import door_port, read_banner, start_server, stop_server

pytestmark = pytest.mark.req("H-03")

C2P = Direction.CNC_TO_PLC

# a few signals of the demo machine, one of each kind
COIL = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.enable_w"
COIL_B = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.enable_w"
HOLDING_DINT = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w"
HOLDING_DINT_B = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w"
HOLDING_UDINT = "gpCh[0]^mc_command.program_select_w"
DISCRETE = "gpAx[1]^ipo_state.moving_r"
INPUT_DINT = "gpAx[1]^ipo_state.cmd_pos_r"
INPUT_UDINT = "gpCh[0]^bahn_state.cycle_r"
INPUT_LREAL = "gpAx[4]^dyn_coll_mon.velocity"


@pytest.fixture(scope="module")
def demo() -> MachineConfig:
    return load_machine(None)


@pytest.fixture(scope="module")
def layout(demo: MachineConfig) -> Layout:
    return build_layout(demo)


def image_name(tag: str) -> str:
    return f"hli_test_mb_{tag}_{os.getpid()}_{time.monotonic_ns() % 1_000_000}"


@pytest.fixture
def image(layout: Layout) -> Iterator[ProcessImage]:
    img = ProcessImage.create(layout, name=image_name("img"))
    try:
        yield img
    finally:
        img.close()


async def serve(image: ProcessImage, **options: Any) -> ModbusAdapter:
    adapter = ModbusAdapter(port=0, **options)
    await adapter.start_for(image)
    return adapter


@pytest.fixture
async def adapter(image: ProcessImage) -> AsyncIterator[ModbusAdapter]:
    a = await serve(image)
    yield a
    await a.stop()


@pytest.fixture
async def client(adapter: ModbusAdapter) -> AsyncIterator[AsyncModbusTcpClient]:
    c = AsyncModbusTcpClient("127.0.0.1", port=adapter.port or 0, timeout=2, retries=0)
    assert await c.connect()
    yield c
    c.close()


def addr(layout: Layout, st_path: str) -> int:
    return layout.signal(st_path).modbus_address


def ok(response: ModbusPDU) -> ModbusPDU:
    assert not response.isError(), f"unexpected exception response {response}"
    return response


def exception_code(response: ModbusPDU) -> int:
    assert response.isError(), f"expected an exception, got {response}"
    return int(response.exception_code)


def int32(registers: Sequence[int]) -> int:
    """A DINT from two ABCD registers, through pymodbus' own converter."""
    value = AsyncModbusTcpClient.convert_from_registers(list(registers), AsyncModbusTcpClient.DATATYPE.INT32)
    assert isinstance(value, int)
    return value


def regs32(value: int, signed: bool = True, order: str = "ABCD") -> list[int]:
    hi, lo = struct.unpack(">HH", struct.pack(">i" if signed else ">I", value))
    return [hi, lo] if order == "ABCD" else [lo, hi]


# --- a raw Modbus TCP client --------------------------------------------------------------------


def adu(tid: int, pdu: bytes, unit: int = 1, pid: int = 0) -> bytes:
    return struct.pack(">HHHB", tid, pid, len(pdu) + 1, unit) + pdu


class Raw:
    """A raw stream: send any bytes, read whole ADUs back as (tid, unit, pdu)."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader = reader
        self.writer = writer

    @classmethod
    async def connect(cls, port: int) -> Raw:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        return cls(reader, writer)

    async def send(self, data: bytes) -> None:
        self.writer.write(data)
        await self.writer.drain()

    async def answer(self, timeout: float = 2.0) -> tuple[int, int, bytes]:
        head = await asyncio.wait_for(self.reader.readexactly(7), timeout)
        tid, pid, length, unit = struct.unpack(">HHHB", head)
        assert pid == 0
        pdu = await asyncio.wait_for(self.reader.readexactly(length - 1), timeout)
        return tid, unit, pdu

    async def ask(self, tid: int, pdu: bytes, unit: int = 1) -> bytes:
        await self.send(adu(tid, pdu, unit))
        got_tid, got_unit, answer = await self.answer()
        assert (got_tid, got_unit) == (tid, unit)
        return answer

    async def closed_by_server(self, timeout: float = 2.0) -> bool:
        return await asyncio.wait_for(self.reader.read(1), timeout) == b""

    async def close(self) -> None:
        self.writer.close()
        with contextlib.suppress(ConnectionError, OSError):
            await self.writer.wait_closed()


@pytest.fixture
async def raw(adapter: ModbusAdapter) -> AsyncIterator[Raw]:
    r = await Raw.connect(adapter.port or 0)
    yield r
    await r.close()


def read_pdu(fc: int, address: int, count: int) -> bytes:
    return struct.pack(">BHH", fc, address, count)


# ================================================================================================
# Every kind of field
# ================================================================================================


async def test_coils_fc5_fc15_write_the_image_and_fc1_reads_them(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout
) -> None:
    a = addr(layout, COIL)
    assert addr(layout, COIL_B) == a + 1
    ok(await client.write_coil(a, True))
    assert image.read(COIL) is True
    assert image.read(COIL_B) is False
    assert ok(await client.read_coils(a, count=2)).bits[:2] == [True, False]

    ok(await client.write_coils(a, [False, True]))
    assert image.read(COIL) is False
    assert image.read(COIL_B) is True
    # a whole channel block of coils at once (FC 15): enable/command of the units, start, reset, probe
    channel_coils = sorted(
        (s for s in layout.signals if s.modbus_table is ModbusTable.COIL and s.st_path.startswith("gpCh[1]")),
        key=lambda s: s.modbus_address,
    )
    first = channel_coils[0].modbus_address
    assert [s.modbus_address for s in channel_coils] == list(range(first, first + len(channel_coils)))
    pattern = [i % 3 == 0 for i in range(len(channel_coils))]
    ok(await client.write_coils(first, pattern))
    assert [image.read(s.st_path) for s in channel_coils] == pattern
    assert ok(await client.read_coils(first, count=len(pattern))).bits[: len(pattern)] == pattern


async def test_discrete_inputs_fc2_read_the_published_half(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout
) -> None:
    flags = sorted(
        (
            s
            for s in layout.signals
            if s.modbus_table is ModbusTable.DISCRETE_INPUT and s.st_path.startswith("gpAx[1]")
        ),
        key=lambda s: s.modbus_address,
    )
    values = {s.st_path: i % 2 == 1 for i, s in enumerate(flags)}
    image.publish_bytes(layout.pack(C2P, values), cycle=1)
    response = ok(await client.read_discrete_inputs(flags[0].modbus_address, count=len(flags)))
    assert response.bits[: len(flags)] == [values[s.st_path] for s in flags]
    assert ok(await client.read_discrete_inputs(addr(layout, DISCRETE), count=1)).bits[0] is values[DISCRETE]


@pytest.mark.parametrize("value", [0, 1, -1, 123_456_789, -2_000_000_000, 2**31 - 1, -(2**31)])
async def test_holding_dint_fc16_write_fc3_read(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout, value: int
) -> None:
    a = addr(layout, HOLDING_DINT)
    ok(await client.write_registers(a, regs32(value)))
    assert image.read(HOLDING_DINT) == value
    assert ok(await client.read_holding_registers(a, count=2)).registers == regs32(value)
    registers = ok(await client.read_holding_registers(a, count=2)).registers
    assert client.convert_from_registers(registers, client.DATATYPE.INT32) == value


@pytest.mark.parametrize("value", [0, 7, 2**31, 2**32 - 1])
async def test_holding_udint_fc16_write_fc3_read(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout, value: int
) -> None:
    a = addr(layout, HOLDING_UDINT)
    ok(await client.write_registers(a, regs32(value, signed=False)))
    assert image.read(HOLDING_UDINT) == value
    registers = ok(await client.read_holding_registers(a, count=2)).registers
    assert client.convert_from_registers(registers, client.DATATYPE.UINT32) == value


async def test_holding_registers_several_values_in_one_request(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout
) -> None:
    a = addr(layout, HOLDING_DINT)
    assert addr(layout, HOLDING_DINT_B) == a + 2
    ok(await client.write_registers(a, regs32(-500_000) + regs32(500_000)))
    assert (image.read(HOLDING_DINT), image.read(HOLDING_DINT_B)) == (-500_000, 500_000)
    assert ok(await client.read_holding_registers(a, count=4)).registers == regs32(-500_000) + regs32(500_000)


async def test_fc23_writes_then_reads(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout
) -> None:
    a = addr(layout, HOLDING_DINT)
    response = ok(
        await client.readwrite_registers(
            read_address=a, read_count=4, write_address=a + 2, values=regs32(-42)
        )
    )
    assert image.read(HOLDING_DINT_B) == -42
    assert response.registers == regs32(0) + regs32(-42)  # the read sees the write (V1.1b3 6.17)


async def test_input_registers_fc4_every_type(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout
) -> None:
    values = {INPUT_DINT: -1_234_567, INPUT_UDINT: 4_000_000_000, INPUT_LREAL: -1234.5678e3}
    image.publish_bytes(layout.pack(C2P, values), cycle=5)
    dint = ok(await client.read_input_registers(addr(layout, INPUT_DINT), count=2)).registers
    assert client.convert_from_registers(dint, client.DATATYPE.INT32) == values[INPUT_DINT]
    udint = ok(await client.read_input_registers(addr(layout, INPUT_UDINT), count=2)).registers
    assert client.convert_from_registers(udint, client.DATATYPE.UINT32) == values[INPUT_UDINT]
    lreal = ok(await client.read_input_registers(addr(layout, INPUT_LREAL), count=4)).registers
    assert lreal == list(struct.unpack(">4H", struct.pack(">d", values[INPUT_LREAL])))
    assert client.convert_from_registers(lreal, client.DATATYPE.FLOAT64) == values[INPUT_LREAL]


async def test_input_registers_a_run_of_fields_in_one_read(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout
) -> None:
    """Modbus order and image order differ in an axis block (state_r after request_r, fields of the
    other half between them): one read returns each field at its own address."""
    run = sorted(
        (
            s
            for s in layout.signals
            if s.modbus_table is ModbusTable.INPUT_REGISTER
            and s.st_path.startswith("gpAx[2]^")
            and s.modbus_address < layout.signal("gpAx[2]^dyn_coll_mon.coll_offset").modbus_address
        ),
        key=lambda s: s.modbus_address,
    )
    values: dict[str, int | float] = {}
    for i, s in enumerate(run):
        values[s.st_path] = (i + 1) * 1.5 if s.type == "LREAL" else -(i + 1) * 1001
    image.publish_bytes(layout.pack(C2P, values), cycle=9)
    count = sum(s.modbus_count for s in run)
    registers = ok(await client.read_input_registers(run[0].modbus_address, count=count)).registers
    pos = 0
    for s in run:
        chunk = registers[pos : pos + s.modbus_count]
        kind = client.DATATYPE.FLOAT64 if s.type == "LREAL" else client.DATATYPE.INT32
        assert client.convert_from_registers(chunk, kind) == values[s.st_path], s.st_path
        pos += s.modbus_count


async def test_reads_are_live(client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout) -> None:
    a = addr(layout, INPUT_UDINT)
    for cycle in (1, 2, 3):
        image.publish_bytes(layout.pack(C2P, {INPUT_UDINT: cycle * 10}), cycle=cycle)
        registers = ok(await client.read_input_registers(a, count=2)).registers
        assert client.convert_from_registers(registers, client.DATATYPE.UINT32) == cycle * 10
    image.write(HOLDING_DINT, 99)  # another PLC door (shared memory, ADS) wrote the value
    assert ok(await client.read_holding_registers(addr(layout, HOLDING_DINT), count=2)).registers == regs32(
        99
    )


# ================================================================================================
# Word order
# ================================================================================================


async def test_word_order_abcd_and_cdab(image: ProcessImage, layout: Layout) -> None:
    abcd, cdab = await serve(image), await serve(image, word_order="CDAB")
    try:
        ca = AsyncModbusTcpClient("127.0.0.1", port=abcd.port or 0, timeout=2, retries=0)
        cc = AsyncModbusTcpClient("127.0.0.1", port=cdab.port or 0, timeout=2, retries=0)
        assert await ca.connect()
        assert await cc.connect()
        a = addr(layout, HOLDING_DINT)
        # the worked example of docs/modbus.md: 100000 = 0x000186A0
        ok(await ca.write_registers(a, [0x0001, 0x86A0]))
        assert image.read(HOLDING_DINT) == 100_000
        assert ok(await cc.read_holding_registers(a, count=2)).registers == [0x86A0, 0x0001]
        ok(await cc.write_registers(a, [0xFFFE, 0xFFFF]))  # -2, low word first
        assert image.read(HOLDING_DINT) == -2
        assert ok(await ca.read_holding_registers(a, count=2)).registers == [0xFFFF, 0xFFFE]
        registers = ok(await cc.read_holding_registers(a, count=2)).registers
        assert cc.convert_from_registers(registers, cc.DATATYPE.INT32, word_order="little") == -2

        value = 1.0e-3 + 2**40
        image.publish_bytes(layout.pack(C2P, {INPUT_LREAL: value}), cycle=1)
        words = list(struct.unpack(">4H", struct.pack(">d", value)))
        assert ok(await ca.read_input_registers(addr(layout, INPUT_LREAL), count=4)).registers == words
        assert ok(await cc.read_input_registers(addr(layout, INPUT_LREAL), count=4)).registers == words[::-1]
        ca.close()
        cc.close()
    finally:
        await abcd.stop()
        await cdab.stop()


def test_unknown_word_order_is_refused() -> None:
    with pytest.raises(ValueError, match=r"word_order: .*'ABCD' or 'CDAB' \(got 'BADC'\)"):
        ModbusAdapter(word_order="BADC")


# ================================================================================================
# Exceptions
# ================================================================================================


async def test_exception_unknown_address(client: AsyncModbusTcpClient, layout: Layout) -> None:
    gap = 50  # between channel 0's block (0..99, used up to 21) and channel 1's
    assert exception_code(await client.read_holding_registers(gap, count=2)) == 2
    assert exception_code(await client.read_input_registers(60_000, count=1)) == 2
    assert exception_code(await client.read_coils(1_000, count=1)) == 2
    assert exception_code(await client.read_discrete_inputs(65_000, count=8)) == 2
    assert exception_code(await client.write_coil(1_000, True)) == 2
    assert exception_code(await client.write_registers(gap, [0, 1])) == 2
    # a range that starts on a signal and runs into a gap
    last = layout.signal("gpCh[0]^mc_command.probe_w").modbus_address
    assert exception_code(await client.read_coils(last, count=2)) == 2


async def test_exception_partial_32bit_access(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout
) -> None:
    a = addr(layout, HOLDING_DINT)
    image.write(HOLDING_DINT, 17)
    assert exception_code(await client.read_holding_registers(a, count=1)) == 2
    assert exception_code(await client.read_holding_registers(a + 1, count=2)) == 2
    assert exception_code(await client.write_register(a, 5)) == 2  # FC 6 writes half a DINT
    assert exception_code(await client.write_registers(a + 1, [1, 2])) == 2
    assert exception_code(await client.read_input_registers(addr(layout, INPUT_LREAL), count=2)) == 2
    assert image.read(HOLDING_DINT) == 17


async def test_exception_write_to_cnc_to_plc_value(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout
) -> None:
    """CNC->PLC values live in the read-only tables; their addresses are not writable (H-02)."""
    state = layout.signal("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.state_r")
    flag = layout.signal("gpAx[0]^dyn_coll_mon.active")
    assert state.modbus_table is ModbusTable.INPUT_REGISTER
    assert flag.modbus_table is ModbusTable.DISCRETE_INPUT
    cycle = layout.signal(INPUT_UDINT)  # input register 16: nothing in the holding table there
    assert exception_code(await client.write_registers(cycle.modbus_address, [0, 1])) == 2
    assert exception_code(await client.write_coil(flag.modbus_address, True)) == 2
    assert image.read(INPUT_UDINT) == 0
    assert image.read(flag.st_path) is False


async def test_a_refused_write_changes_nothing(
    client: AsyncModbusTcpClient, image: ProcessImage, layout: Layout
) -> None:
    a = addr(layout, HOLDING_DINT)
    image.write(HOLDING_DINT, 11)
    image.write(HOLDING_DINT_B, 22)
    # two good values, then half of the next: the whole request is refused before any store
    assert exception_code(await client.write_registers(a, [0, 1, 0, 2, 0])) == 2
    assert (image.read(HOLDING_DINT), image.read(HOLDING_DINT_B)) == (11, 22)
    coils = layout.signal("gpCh[0]^mc_command.start_w").modbus_address
    assert exception_code(await client.write_coils(coils, [True, True, True, True])) == 2
    assert image.read("gpCh[0]^mc_command.start_w") is False


async def test_exception_illegal_value(raw: Raw, image: ProcessImage, layout: Layout) -> None:
    a = addr(layout, COIL)
    assert await raw.ask(1, struct.pack(">BHH", 5, a, 0x1234)) == b"\x85\x03"
    assert await raw.ask(2, struct.pack(">BHH", 5, a, 0x0001)) == b"\x85\x03"
    assert image.read(COIL) is False
    assert await raw.ask(3, struct.pack(">BHH", 5, a, 0xFF00)) == struct.pack(">BHH", 5, a, 0xFF00)
    assert image.read(COIL) is True
    assert await raw.ask(4, read_pdu(3, 0, 0)) == b"\x83\x03"  # quantity 0
    assert await raw.ask(5, read_pdu(3, 0, 126)) == b"\x83\x03"  # quantity > 125
    assert await raw.ask(6, b"\x10" + struct.pack(">HHB", 0, 2, 3) + b"\x00\x01\x02") == b"\x90\x03"


async def test_exception_illegal_function(raw: Raw, client: AsyncModbusTcpClient) -> None:
    assert exception_code(await client.read_exception_status()) == 1  # FC 7
    for fc in (0, 7, 8, 11, 17, 20, 22, 24, 43, 100, 127):
        assert await raw.ask(fc, bytes([fc, 0, 0, 0, 1])) == bytes([fc | 0x80, 1])


@pytest.mark.parametrize("unit", [1, 0, 255])
async def test_own_unit_ids_are_served(client: AsyncModbusTcpClient, layout: Layout, unit: int) -> None:
    ok(await client.read_holding_registers(addr(layout, HOLDING_DINT), count=2, device_id=unit))


async def test_other_unit_ids_get_gateway_exception(client: AsyncModbusTcpClient, layout: Layout) -> None:
    response = await client.read_holding_registers(addr(layout, HOLDING_DINT), count=2, device_id=7)
    assert exception_code(response) == 0x0B


async def test_unit_id_is_configurable_and_others_can_be_ignored(image: ProcessImage, layout: Layout) -> None:
    adapter = await serve(image, unit_id=17, unknown_unit="ignore")
    raw = await Raw.connect(adapter.port or 0)
    try:
        request = read_pdu(3, addr(layout, HOLDING_DINT), 2)
        await raw.send(adu(1, request, unit=1) + adu(2, request, unit=17))
        # unit 1 gets no answer at all: the first answer on the stream is the one for unit 17
        assert (await raw.answer())[:2] == (2, 17)
        assert adapter.server.stats.dropped == 1
    finally:
        await raw.close()
        await adapter.stop()


def test_bad_unit_options_are_refused() -> None:
    with pytest.raises(ValueError, match=r"unit_id: .*less than or equal to 255 \(got 300\)"):
        ModbusAdapter(unit_id=300)
    with pytest.raises(ValueError, match=r"unknown_unit: .*'exception' or 'ignore' \(got 'drop'\)"):
        ModbusAdapter(unknown_unit="drop")


# ================================================================================================
# Pipelining
# ================================================================================================


async def test_five_pipelined_requests_in_one_write_get_five_answers_in_order(
    raw: Raw, image: ProcessImage, layout: Layout
) -> None:
    a = addr(layout, HOLDING_DINT)
    requests = [
        read_pdu(3, a, 2),
        b"\x10" + struct.pack(">HHB", a, 2, 4) + struct.pack(">HH", *regs32(-7)),
        read_pdu(3, a, 2),
        read_pdu(3, 50, 2),  # an exception in the middle does not break the sequence
        struct.pack(">BHH", 5, addr(layout, COIL), 0xFF00),
    ]
    await raw.send(b"".join(adu(100 + i, pdu) for i, pdu in enumerate(requests)))
    answers = [await raw.answer() for _ in requests]
    assert [tid for tid, _, _ in answers] == [100, 101, 102, 103, 104]
    assert answers[0][2] == b"\x03\x04" + struct.pack(">HH", *regs32(0))
    assert answers[1][2] == b"\x10" + struct.pack(">HH", a, 2)
    assert answers[2][2] == b"\x03\x04" + struct.pack(">HH", *regs32(-7))  # sees the write before it
    assert answers[3][2] == b"\x83\x02"
    assert answers[4][2] == requests[4]
    assert image.read(COIL) is True


async def test_pipelined_requests_split_across_writes(raw: Raw, layout: Layout) -> None:
    request = read_pdu(4, addr(layout, INPUT_UDINT), 2)
    stream = b"".join(adu(i, request) for i in range(40))
    pos = 0
    rng = random.Random(3)
    while pos < len(stream):
        step = rng.randint(1, 23)
        await raw.send(stream[pos : pos + step])
        pos += step
    tids = [(await raw.answer())[0] for _ in range(40)]
    assert tids == list(range(40))


async def test_a_request_read_whole_and_one_read_among_others_get_the_same_answer(
    raw: Raw, adapter: ModbusAdapter, image: ProcessImage, layout: Layout
) -> None:
    """A read that is exactly one ADU is answered on the fast path (``_Connection.data_received``), a
    read holding more than one through the decoder and the connection's queue: same answers, same
    counters, whatever the request."""
    image.write(HOLDING_DINT, -7)
    image.write(COIL, True)
    a = addr(layout, HOLDING_DINT)
    requests = [
        (1, read_pdu(3, a, 2)),
        (1, read_pdu(1, addr(layout, COIL), 2)),
        (1, read_pdu(2, addr(layout, DISCRETE), 1)),
        (1, read_pdu(4, addr(layout, INPUT_LREAL), 4)),
        (1, read_pdu(3, a + 1, 2)),  # cuts a DINT: 0x02
        (1, read_pdu(3, 50, 2)),  # nothing there: 0x02
        (1, read_pdu(3, a, 0)),  # quantity 0: 0x03
        (1, b"\x03\x00"),  # truncated: 0x03
        (1, b"\x2b\x0e\x01\x00"),  # FC 43: 0x01
        (1, struct.pack(">BHH", 5, addr(layout, COIL), 0x1234)),  # neither ON nor OFF: 0x03
        (1, b"\x10" + struct.pack(">HHB", a, 2, 4) + struct.pack(">HH", *regs32(-7))),
        (0, read_pdu(3, a, 2)),  # unit 0: this device
        (9, read_pdu(3, a, 2)),  # another unit: 0x0B
    ]
    probe = adu(999, read_pdu(3, a, 2))
    whole: list[tuple[int, int, bytes]] = []
    before = adapter.server.stats.requests, dict(adapter.server.stats.exceptions)
    for tid, (unit, pdu) in enumerate(requests):
        await raw.send(adu(tid, pdu, unit))
        whole.append(await raw.answer())
    stats = adapter.server.stats
    requests_whole = stats.requests - before[0]
    exceptions_whole = {c: n - before[1].get(c, 0) for c, n in stats.exceptions.items()}
    among: list[tuple[int, int, bytes]] = []
    for tid, (unit, pdu) in enumerate(requests):
        await raw.send(adu(tid, pdu, unit) + probe)  # two ADUs in one write: the decoder's path
        among.append(await raw.answer())
        assert (await raw.answer())[0] == 999
    assert among == whole
    assert [pdu[0] & 0x80 for _, _, pdu in whole] == [0] * 4 + [0x80] * 6 + [0, 0, 0x80]
    assert requests_whole == len(requests)
    assert stats.requests - before[0] == 3 * len(requests)  # and the probes
    assert exceptions_whole == {0x01: 1, 0x02: 2, 0x03: 3, 0x0B: 1}
    assert {c: n - before[1].get(c, 0) for c, n in stats.exceptions.items()} == {
        0x01: 2,
        0x02: 4,
        0x03: 6,
        0x0B: 2,
    }


async def test_many_pipelined_requests_from_several_clients(adapter: ModbusAdapter, layout: Layout) -> None:
    request = read_pdu(3, addr(layout, HOLDING_DINT), 4)

    async def one_client(k: int) -> list[int]:
        r = await Raw.connect(adapter.port or 0)
        try:
            await r.send(b"".join(adu(k * 1000 + i, request) for i in range(200)))
            return [(await r.answer())[0] for _ in range(200)]
        finally:
            await r.close()

    results = await asyncio.gather(*(one_client(k) for k in range(5)))
    for k, tids in enumerate(results):
        assert tids == [k * 1000 + i for i in range(200)]


# ================================================================================================
# Malformed input
# ================================================================================================


async def test_malformed_pdu_then_a_good_request(raw: Raw, layout: Layout) -> None:
    good = read_pdu(3, addr(layout, HOLDING_DINT), 2)
    assert await raw.ask(1, b"\x03\x00") == b"\x83\x03"  # truncated
    assert await raw.ask(2, b"\x10\x00\x00\x00\x02\x04\x00") == b"\x90\x03"  # data missing
    assert (await raw.ask(3, good))[:2] == b"\x03\x04"


async def test_other_protocol_id_is_dropped_and_the_next_request_served(
    raw: Raw, adapter: ModbusAdapter, layout: Layout
) -> None:
    good = read_pdu(3, addr(layout, HOLDING_DINT), 2)
    await raw.send(adu(1, good, pid=7) + adu(2, good))
    tid, _, pdu = await raw.answer()
    assert tid == 2
    assert pdu[:2] == b"\x03\x04"
    assert adapter.server.stats.dropped == 1


async def test_broken_length_closes_only_that_connection(adapter: ModbusAdapter, layout: Layout) -> None:
    good = read_pdu(3, addr(layout, HOLDING_DINT), 2)
    bad = await Raw.connect(adapter.port or 0)
    other = await Raw.connect(adapter.port or 0)
    try:
        # the good request before the damage is still answered, then the server hangs up
        await bad.send(adu(1, good) + struct.pack(">HHHB", 2, 0, 0x0400, 1) + good)
        assert (await bad.answer())[0] == 1
        assert await bad.closed_by_server()
        assert (await other.ask(3, good))[:2] == b"\x03\x04"
        fresh = await Raw.connect(adapter.port or 0)
        assert (await fresh.ask(4, good))[:2] == b"\x03\x04"
        await fresh.close()
        assert adapter.server.stats.broken_streams == 1
    finally:
        await bad.close()
        await other.close()


async def test_random_garbage_never_stops_the_server(adapter: ModbusAdapter, layout: Layout) -> None:
    rng = random.Random(42)
    good = read_pdu(3, addr(layout, HOLDING_DINT), 2)
    for round_ in range(30):
        r = await Raw.connect(adapter.port or 0)
        garbage = bytes(rng.randrange(256) for _ in range(rng.randint(1, 600)))
        if round_ % 2:  # a plausible header with a random PDU
            pdu = bytes(rng.randrange(256) for _ in range(rng.randint(1, 253)))
            garbage = adu(round_, pdu, unit=rng.choice([0, 1, 255, 9]))
        await r.send(garbage)
        await r.close()
    r = await Raw.connect(adapter.port or 0)
    assert (await r.ask(9, good))[:2] == b"\x03\x04"
    await r.close()
    assert adapter.server.stats.exceptions.get(4, 0) == 0  # no request hit an unexpected fault


async def test_a_client_that_does_not_read_does_not_block_the_others(
    adapter: ModbusAdapter, layout: Layout
) -> None:
    greedy = await Raw.connect(adapter.port or 0)
    polite = await Raw.connect(adapter.port or 0)
    try:
        request = adu(1, read_pdu(4, addr(layout, INPUT_LREAL), 4))
        for _ in range(50):
            greedy.writer.write(request * 200)  # never reads its answers
        assert (await polite.ask(2, read_pdu(3, addr(layout, HOLDING_DINT), 2)))[:2] == b"\x03\x04"
    finally:
        greedy.writer.transport.abort()
        await polite.close()


async def test_a_full_house_closes_the_connection_served_longest_ago(
    image: ProcessImage, layout: Layout
) -> None:
    """Issue 27, finding 3: at max_connections the newcomer is admitted and the connection whose last
    request was answered longest ago makes room (never the newcomer refused)."""
    adapter = await serve(image, max_connections=2)
    clients = [await Raw.connect(adapter.port or 0) for _ in range(2)]
    try:
        good = read_pdu(3, addr(layout, HOLDING_DINT), 2)
        assert (await clients[0].ask(1, good))[:2] == b"\x03\x04"
        await asyncio.sleep(0.01)
        assert (await clients[1].ask(2, good))[:2] == b"\x03\x04"
        clients.append(await Raw.connect(adapter.port or 0))
        assert (await clients[2].ask(3, good))[:2] == b"\x03\x04"  # the newcomer is served
        assert await clients[0].closed_by_server()  # served longest ago: it made room
        assert (await clients[1].ask(4, good))[:2] == b"\x03\x04"
        assert adapter.server.stats.evicted == 1
    finally:
        for c in clients:
            await c.close()
        await adapter.stop()


async def test_stop_closes_the_listener_and_the_connections(image: ProcessImage, layout: Layout) -> None:
    adapter = await serve(image)
    port = adapter.port or 0
    r = await Raw.connect(port)
    await adapter.stop()
    await adapter.stop()  # idempotent
    assert await r.closed_by_server()
    await r.close()
    with pytest.raises(OSError, match=r"refused|failed"):
        await Raw.connect(port)
    assert adapter.endpoints() == ["Modbus TCP: not listening"]


# ================================================================================================
# With the runtime: live values, the latch at the next cycle, the adapter from its registry name
# ================================================================================================


@pytest.fixture
async def rt_client(hli: Harness) -> AsyncIterator[AsyncModbusTcpClient]:
    """A client of the harness' Modbus door (the adapter by its registry name, on a free port)."""
    adapter = hli.serve("modbus")
    assert isinstance(adapter, ModbusAdapter)
    assert any(f":{adapter.port} " in line for line in hli.runtime.endpoints())
    c = AsyncModbusTcpClient("127.0.0.1", port=adapter.port or 0, timeout=2, retries=0)
    assert await c.connect()
    yield c
    c.close()


async def test_a_write_is_latched_at_the_next_cycle(hli: Harness, rt_client: AsyncModbusTcpClient) -> None:
    layout = hli.layout
    unit = hli.runtime.machine.hli.axes[0].ipo_mc_control.dyn_pos_limit_low
    ok(await rt_client.write_registers(addr(layout, HOLDING_DINT), regs32(-123_456)))
    ok(await rt_client.write_coil(addr(layout, COIL), True))
    assert (unit.command_w, unit.enable_w) == (0, False)  # not before the cycle
    hli.step(1)
    assert (unit.command_w, unit.enable_w) == (-123_456, True)


async def test_input_registers_follow_the_engine(hli: Harness, rt_client: AsyncModbusTcpClient) -> None:
    layout = hli.layout
    channel = hli.runtime.machine.channel(1)
    channel.load_program("N10 G01 X-20 F6000\nN20 M30\n", "p")
    channel.request_start()
    for _ in range(3):
        hli.step(37)
        cycle = ok(await rt_client.read_input_registers(addr(layout, INPUT_UDINT), count=2)).registers
        assert rt_client.convert_from_registers(cycle, rt_client.DATATYPE.UINT32) == hli.runtime.machine.cycle
        pos = ok(await rt_client.read_input_registers(addr(layout, "gpAx[0]^ipo_state.cmd_pos_r"), count=2))
        value = int32(pos.registers)
        assert value == hli.runtime.image.read("gpAx[0]^ipo_state.cmd_pos_r")
        assert value < 0
        moving = ok(await rt_client.read_discrete_inputs(addr(layout, "gpAx[0]^ipo_state.moving_r"), count=1))
        assert moving.bits[0] is True


# ================================================================================================
# C43 over Modbus: a dynamic position limit set by a Modbus client stops the axis
# ================================================================================================


@pytest.mark.req("H-03", "C43-02", "C43-03", "C43-04")
async def test_dyn_pos_limit_set_over_modbus_stops_the_axis(
    hli: Harness, rt_client: AsyncModbusTcpClient
) -> None:
    layout = hli.layout
    high = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high"
    limit = 300_000  # 30 mm in 0.1 µm
    # the PLC sets the limit over Modbus: command_w first, then enable_w (the image's write order rule)
    ok(await rt_client.write_registers(addr(layout, f"{high}.command_w"), regs32(limit)))
    ok(await rt_client.write_coil(addr(layout, f"{high}.enable_w"), True))
    hli.step(5)
    state = addr(layout, f"{high}.state_r")
    registers = ok(await rt_client.read_input_registers(state, count=2)).registers
    assert int32(registers) == 2  # ACTIVE

    channel = hli.runtime.machine.channel(1)
    channel.load_program("N10 G01 X100 F6000\nN20 M30\n", "p")
    channel.request_start()
    hli.step(3000)  # 3 s: without the limit X would reach 100 mm long before
    pos = ok(await rt_client.read_input_registers(addr(layout, "gpAx[0]^ipo_state.cmd_pos_r"), count=2))
    x = int32(pos.registers)
    one_cycle = 6000 / 60 * hli.t_a * 10_000  # F6000 mm/min for one cycle, in 0.1 µm
    assert limit - one_cycle <= x <= limit + one_cycle  # C43-06: passed by at most one cycle
    registers = ok(await rt_client.read_input_registers(state, count=2)).registers
    assert int32(registers) == 4  # ACTIVE_BRAKE
    assert channel.state != ProgramState.FINISHED
    moving = ok(await rt_client.read_discrete_inputs(addr(layout, "gpAx[0]^ipo_state.moving_r"), count=1))
    assert moving.bits[0] is False

    # C43-07: the PLC lifts the limit over Modbus and the program continues to its end
    ok(await rt_client.write_coil(addr(layout, f"{high}.enable_w"), False))
    hli.step(3000)
    pos = ok(await rt_client.read_input_registers(addr(layout, "gpAx[0]^ipo_state.cmd_pos_r"), count=2))
    assert int32(pos.registers) == 1_000_000


# ================================================================================================
# Consistent snapshots: the snapshot register (H-03, docs/modbus.md)
# ================================================================================================


def uint32(registers: Sequence[int]) -> int:
    value = AsyncModbusTcpClient.convert_from_registers(list(registers), AsyncModbusTcpClient.DATATYPE.UINT32)
    assert isinstance(value, int)
    return value


@pytest.mark.req("H-03")
async def test_the_snapshot_register_freezes_one_connections_inputs_on_one_publish(
    hli: Harness, rt_client: AsyncModbusTcpClient
) -> None:
    layout = hli.layout
    other = AsyncModbusTcpClient("127.0.0.1", port=hli.port("modbus"), timeout=2, retries=0)
    assert await other.connect()
    cycle = addr(layout, INPUT_UDINT)
    moving = addr(layout, "gpAx[0]^ipo_state.moving_r")
    try:
        hli.step(5)
        ok(await rt_client.write_register(MODBUS_SNAPSHOT_REGISTER, 1))  # freeze: cycle 5
        hli.operator.load_program(1, "N10 G01 X10 F6000\nN20 M30\n")
        hli.operator.start(1)
        hli.step(7)
        assert uint32(ok(await rt_client.read_input_registers(cycle, count=2)).registers) == 5
        assert ok(await rt_client.read_discrete_inputs(moving, count=1)).bits[0] is False
        assert uint32(ok(await other.read_input_registers(cycle, count=2)).registers) == 12  # not frozen
        assert ok(await other.read_discrete_inputs(moving, count=1)).bits[0] is True
        # the PLC's own outputs (coils, holding registers) stay live on the frozen connection
        ok(await other.write_registers(addr(layout, HOLDING_DINT), regs32(-77)))
        assert (
            int32(ok(await rt_client.read_holding_registers(addr(layout, HOLDING_DINT), count=2)).registers)
            == -77
        )
        ok(await rt_client.write_register(MODBUS_SNAPSHOT_REGISTER, 1))  # a new copy: cycle 12
        assert uint32(ok(await rt_client.read_input_registers(cycle, count=2)).registers) == 12
        ok(await rt_client.write_register(MODBUS_SNAPSHOT_REGISTER, 0))  # live again
        hli.step(1)
        assert uint32(ok(await rt_client.read_input_registers(cycle, count=2)).registers) == 13
        assert exception_code(await rt_client.write_register(MODBUS_SNAPSHOT_REGISTER, 2)) == 0x03
    finally:
        other.close()


@pytest.mark.req("H-03")
async def test_a_frozen_connection_that_closes_leaves_nothing_behind(hli: Harness) -> None:
    adapter = hli.serve("modbus")
    assert isinstance(adapter, ModbusAdapter)
    first = await Raw.connect(hli.port("modbus"))
    assert await first.ask(1, struct.pack(">BHH", 6, MODBUS_SNAPSHOT_REGISTER, 1)) == struct.pack(
        ">BHH", 6, MODBUS_SNAPSHOT_REGISTER, 1
    )
    await first.close()
    hli.step(3)
    second = await Raw.connect(hli.port("modbus"))
    answer = await second.ask(2, read_pdu(4, addr(hli.layout, INPUT_UDINT), 2))
    assert struct.unpack(">BBI", answer) == (4, 4, 3)  # a new connection reads live
    await second.close()


# ================================================================================================
# `hli-server run` serves Modbus
# ================================================================================================


async def test_run_serves_modbus_on_a_free_port_with_the_given_options() -> None:
    proc = start_server(
        "--no-http",
        "--modbus-port",
        "0",
        "--modbus-word-order",
        "cdab",
        "--modbus-unit-id",
        "9",
        "--image-name",
        image_name("run"),
    )
    try:
        line = read_banner(proc)["Modbus TCP"]
        assert "unit id 9" in line
        assert "word order CDAB" in line
        port = door_port(line)
        client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
        assert await client.connect()
        layout = build_layout(load_machine(None))
        cycle_address = addr(layout, INPUT_UDINT)
        first = ok(await client.read_input_registers(cycle_address, count=2, device_id=9)).registers
        await asyncio.sleep(0.05)
        second = ok(await client.read_input_registers(cycle_address, count=2, device_id=9)).registers
        as_cycle = [r[1] << 16 | r[0] for r in (first, second)]  # CDAB: low word first
        assert 0 <= as_cycle[0] < as_cycle[1]  # the realtime clock runs; reads are live (the first may
        # come before the first cycle: the doors process serves the image as soon as the banner is out)
        assert exception_code(await client.read_input_registers(cycle_address, count=2, device_id=1)) == 0x0B
        client.close()
    finally:
        stop_server(proc)
    assert proc.returncode == 0
