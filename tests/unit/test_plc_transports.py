"""PLC-side transports without a server: the Modbus codec (checked against pymodbus' own
converters), layout loading, the memory twin (H-06, H-03 word order, H-08 one layout)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pymodbus.client import ModbusTcpClient

from hli_server.configuration import load_machine
from plc_clients import MemoryImage, MemoryTransport, TransportError, load_layout
from plc_clients.modbus_codec import MAX_READ_BITS, MAX_READ_REGISTERS, ModbusCodec
from plc_clients.transports import CYCLE_R_MODULUS, CYCLE_SIGNAL
from plc_clients.transports.base import _CycleCounter
from schemas.layout import (
    Direction,
    Layout,
    LayoutError,
    ModbusTable,
    ReadOnlySignalError,
    SignalType,
    SignalValueError,
    build_layout,
)

pytestmark = pytest.mark.req("H-06")

DT = ModbusTcpClient.DATATYPE


@pytest.fixture(scope="module")
def layout() -> Layout:
    return build_layout(load_machine(None))


# ================================================================================================
# The Modbus codec
# ================================================================================================


@pytest.mark.parametrize("watch", ["all", "few"])
def test_read_requests_cover_the_signals_and_never_touch_an_empty_address(layout: Layout, watch: str) -> None:
    codec = ModbusCodec(layout)
    c2p = layout.half(Direction.CNC_TO_PLC)
    wanted = list(c2p) if watch == "all" else [s for s in c2p if s.st_path.endswith(("state_r", "moving_r"))]
    requests = codec.read_requests(wanted)
    covered = {s.st_path for r in requests for s in r.signals}
    assert covered == {s.st_path for s in wanted}
    for r in requests:
        index = layout.modbus_index(r.table)  # address -> (signal, part): the server's view
        assert r.count <= (MAX_READ_BITS if r.table in ("coil", "discrete_input") else MAX_READ_REGISTERS)
        for a in range(r.address, r.address + r.count):
            assert a in index, f"{r} reads the empty address {a}: the server answers 0x02"
        assert index[r.address][1] == 0  # starts at the first register of a value
        last, part = index[r.address + r.count - 1]
        assert part == last.modbus_count - 1  # ends with the last register of a value
    if watch == "all":
        # one request per occupied run of each table (demo machine: 2 channels, 6 axes)
        assert len(requests) == 22


def test_read_requests_of_one_run_are_merged_and_of_two_runs_are_not(layout: Layout) -> None:
    codec = ModbusCodec(layout)
    a = layout.signal("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.state_r")
    b = layout.signal("gpAx[0]^ipo_state.cmd_pos_r")
    c = layout.signal("gpAx[1]^ipo_state.cmd_pos_r")
    requests = codec.read_requests([c, b, a, a])
    assert [(r.address, r.count, len(r.signals)) for r in requests] == [
        (a.modbus_address, b.modbus_address + 2 - a.modbus_address, 2),
        (c.modbus_address, 2, 1),
    ]
    assert requests[0].function_code == 4


@pytest.mark.parametrize(("order", "pymodbus_order"), [("ABCD", "big"), ("CDAB", "little")])
@pytest.mark.parametrize(
    ("path", "values", "datatype"),
    [
        ("gpAx[0]^ipo_state.cmd_pos_r", [0, -2, 100_000, 2**31 - 1, -(2**31)], DT.INT32),
        ("gpCh[0]^bahn_state.cycle_r", [0, 1, 2**32 - 1, 0x12345678], DT.UINT32),
        ("gpAx[4]^dyn_coll_mon.velocity", [0.0, -1.5, 1e300, 123456.789], DT.FLOAT64),
    ],
)
def test_values_agree_with_pymodbus_converters(
    layout: Layout, order: str, pymodbus_order: str, path: str, values: list[float], datatype: object
) -> None:
    codec = ModbusCodec(layout, order.lower())
    signal = layout.signal(path)
    for value in values:
        registers = codec.registers(signal, value)
        assert registers == ModbusTcpClient.convert_to_registers(value, datatype, word_order=pymodbus_order)  # type: ignore[arg-type]
        assert codec.value(signal, registers) == value


def test_dint_minus_two_in_both_word_orders(layout: Layout) -> None:
    """The worked example of docs/modbus.md."""
    s = layout.signal("gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w")
    assert ModbusCodec(layout, "ABCD").registers(s, -2) == [0xFFFF, 0xFFFE]
    assert ModbusCodec(layout, "CDAB").registers(s, -2) == [0xFFFE, 0xFFFF]


def test_decode_bits_registers_and_refuse_short_answers(layout: Layout) -> None:
    codec = ModbusCodec(layout)
    moving = layout.signal("gpAx[0]^ipo_state.moving_r")
    error = layout.signal("gpAx[0]^ipo_state.error_r")
    (bits,) = codec.read_requests([moving, error])
    padded = [False, True, True, False, False, False, False, False]  # pymodbus pads to whole bytes
    assert codec.decode(bits, padded[: bits.count] + [False] * (8 - bits.count)) == {
        moving.st_path: padded[0],
        error.st_path: padded[1],
    }
    with pytest.raises(ValueError, match="bits for a request"):
        codec.decode(bits, [])
    (regs,) = codec.read_requests([layout.signal("gpAx[0]^ipo_state.cmd_pos_r")])
    with pytest.raises(ValueError, match="registers for a request"):
        codec.decode(regs, [1])
    with pytest.raises(ValueError, match="is a BOOL"):
        codec.registers(moving, 1)
    with pytest.raises(ValueError, match="word order 'BADC'"):
        ModbusCodec(layout, "BADC")


def test_every_bit_and_register_table_gets_its_function_code(layout: Layout) -> None:
    codec = ModbusCodec(layout)
    per_table = {s.modbus_table: s for s in layout.signals}
    requests = codec.read_requests(per_table.values())
    assert {r.table: r.function_code for r in requests} == {
        ModbusTable.COIL: 1,
        ModbusTable.DISCRETE_INPUT: 2,
        ModbusTable.HOLDING_REGISTER: 3,
        ModbusTable.INPUT_REGISTER: 4,
    }


def test_the_cycle_counter_unwraps_cycle_r() -> None:
    counter = _CycleCounter()
    assert [counter.update(r) for r in (5, 9, CYCLE_R_MODULUS - 1, 2, 3)] == [
        5,
        9,
        CYCLE_R_MODULUS - 1,
        CYCLE_R_MODULUS + 2,
        CYCLE_R_MODULUS + 3,
    ]


# ================================================================================================
# Layout loading
# ================================================================================================


def test_load_layout_from_a_layout_a_file_and_with_clear_errors(layout: Layout, tmp_path: Path) -> None:
    assert load_layout(layout) is layout
    path = tmp_path / "layout.json"
    path.write_text(layout.to_json(), encoding="utf-8")  # as `hli-server map --format json`
    assert load_layout(path).hash == layout.hash
    assert load_layout(str(path)).hash == layout.hash
    with pytest.raises(FileNotFoundError, match="hli-server map --format json"):
        load_layout(tmp_path / "missing.json")
    data = json.loads(layout.to_json())
    data["layout_hash"] = "0" * 64
    path.write_text(json.dumps(data), encoding="utf-8")
    with pytest.raises(LayoutError, match=r"layout file .*layout\.json: .*does not match its content"):
        load_layout(path)


def test_load_layout_from_an_unreachable_url_is_a_transport_error() -> None:
    with pytest.raises(TransportError, match=r"127\.0\.0\.1:9/api/layout"):
        load_layout("http://127.0.0.1:9", timeout=2)


# ================================================================================================
# The memory twin
# ================================================================================================


def test_the_memory_twin_latches_runs_its_models_and_publishes(layout: Layout) -> None:
    image = MemoryImage(layout)
    plc = MemoryTransport(image)
    seen: list[object] = []
    image.models.append(lambda img: seen.append(img.latched["gpCh[0]^mc_command.start_w"]))
    plc.write_many([("gpCh[0]^mc_command.start_w", True)])
    image.set("gpAx[0]^ipo_state.cmd_pos_r", 10)
    assert plc.snapshot()["gpAx[0]^ipo_state.cmd_pos_r"] == 0  # not before the publish
    assert image.step(2) == 2
    snap = plc.snapshot()
    assert (snap.cycle, snap["gpAx[0]^ipo_state.cmd_pos_r"], snap[CYCLE_SIGNAL]) == (2, 10, 2)
    assert seen == [True, True]
    assert plc.read("gpCh[0]^mc_command.start_w") is True
    assert image.writes == [(0, "gpCh[0]^mc_command.start_w", True)]
    assert plc.cycle == 2


def test_the_memory_twin_refuses_what_the_image_refuses(layout: Layout) -> None:
    image = MemoryImage(layout)
    plc = MemoryTransport(image, partial=True)
    with pytest.raises(ReadOnlySignalError):
        plc.write("gpAx[0]^ipo_state.cmd_pos_r", 1)
    with pytest.raises(SignalValueError):
        plc.write_many(
            [("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w", 1), ("gpCh[0]^mc_command.mode_w", -1)]
        )
    assert image.writes == []  # all checked before any is written
    with pytest.raises(ValueError, match="PLC->CNC"):
        image.set("gpCh[0]^mc_command.mode_w", 1)
    assert set(plc.snapshot(["gpAx[0]^ipo_state.moving_r", "gpCh[0]^mc_command.mode_w"]).values) == {
        "gpAx[0]^ipo_state.moving_r",
        CYCLE_SIGNAL,
    }
    assert len(plc.snapshot().values) == len(layout.half(Direction.CNC_TO_PLC))
    image.fault = TransportError("unplugged")
    with pytest.raises(TransportError, match="unplugged"):
        plc.snapshot()
    image.fault = None
    plc.close()
    with pytest.raises(TransportError, match="closed"):
        plc.read(CYCLE_SIGNAL)
    assert layout.signal(CYCLE_SIGNAL).type is SignalType.UDINT
