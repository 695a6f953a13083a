"""The one layout table (H-01, H-02, H-08): templates in step with the engine's HLI objects,
addresses derived and stable, formats that agree with each other, and the map command."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import typing

import pytest
from click.testing import CliRunner

from hli_server.engine import hli
from schemas.config import AxisConfig, AxisType, ChannelConfig, MachineConfig
from schemas.layout import (
    ADS_GROUP_CNC_TO_PLC,
    ADS_GROUP_GEO_AXIS,
    ADS_GROUP_PLC_TO_CNC,
    ADS_PORT_GEO,
    ADS_PORT_HLI,
    AXIS_TEMPLATES,
    CHANNEL_TEMPLATES,
    LAYOUT_VERSION,
    MAX_AXES,
    MODBUS_AXIS_BASE,
    MODBUS_BLOCK_STRIDE,
    Direction,
    Layout,
    LayoutError,
    ModbusTable,
    ReadOnlySignalError,
    SignalType,
    SignalValueError,
    UnknownSignalError,
    build_layout,
)
from tests.machines import demo_config, distinct_values

PYTHON_TYPE = {SignalType.BOOL: bool, SignalType.DINT: int, SignalType.UDINT: int, SignalType.LREAL: float}
UNIT_ORDER = ["request_r", "enable_w", "command_w", "state_r"]


def _leaves(cls: type, prefix: str = "") -> list[tuple[str, type]]:
    """(path, annotated type) of every non-dataclass field below ``cls``, in field order."""
    hints = typing.get_type_hints(cls)
    out: list[tuple[str, type]] = []
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        path = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(tp):
            out.extend(_leaves(tp, path + "."))
        else:
            out.append((path, tp))
    return out


@pytest.fixture(scope="module")
def layout() -> Layout:
    return build_layout(demo_config())


# --- the table and the engine's objects --------------------------------------------------------


@pytest.mark.req("H-01")
@pytest.mark.parametrize(
    ("engine_cls", "templates"), [(hli.ChannelHli, CHANNEL_TEMPLATES), (hli.AxisHli, AXIS_TEMPLATES)]
)
def test_every_engine_field_has_a_template_of_a_compatible_type_in_the_same_order(engine_cls, templates):
    engine = _leaves(engine_cls)
    assert [p for p, _ in engine] == [t.path for t in templates], (
        "schemas/layout.py templates and hli_server/engine/hli.py fields differ: "
        f"only in hli.py {sorted({p for p, _ in engine} - {t.path for t in templates})}, "
        f"only in layout.py {sorted({t.path for t in templates} - {p for p, _ in engine})}"
    )
    for (path, tp), t in zip(engine, templates, strict=True):
        assert tp is PYTHON_TYPE[t.type], f"{path}: hli.py says {tp.__name__}, the layout {t.type}"


@pytest.mark.req("H-01")
def test_engine_defaults_fit_their_signals(layout):
    """Every default of the engine objects can be written into the image unchanged."""
    from hli_server.image import engine_value

    machine = hli.MachineHli(
        channels=[hli.ChannelHli() for _ in layout.channels], axes=[hli.AxisHli() for _ in layout.axes]
    )
    for s in layout:
        value = engine_value(machine, s)
        assert s.coerce(value) == value


@pytest.mark.req("H-02")
def test_control_units_keep_the_kernel_order_in_the_table_and_in_each_half(layout):
    units = layout.control_units()
    assert "gpAx[0]^ipo_mc_control.dyn_pos_limit_low" in units
    assert "gpCh[1]^bahn_mc_control.suppress_area_mon_manual_mode" in units
    for unit, fields in units.items():
        assert [f.st_path.rsplit(".", 1)[1] for f in fields] == UNIT_ORDER, unit
        request, enable, command, state = fields
        assert request.offset < state.offset, unit
        assert enable.offset < command.offset, unit
        assert request.modbus_address < state.modbus_address, unit
        assert {request.direction, state.direction} == {Direction.CNC_TO_PLC}
        assert {enable.direction, command.direction} == {Direction.PLC_TO_CNC}


@pytest.mark.req("H-02")
def test_direction_follows_the_suffix_and_cnc_objects_are_read_only(layout):
    for s in layout:
        leaf = s.path.rsplit(".", 1)[1]
        if leaf.endswith("_w"):
            assert s.direction is Direction.PLC_TO_CNC
            assert s.access == "read/write"
        else:  # _r and the dyn_coll_mon objects
            assert s.direction is Direction.CNC_TO_PLC
            assert s.access == "read"
            with pytest.raises(ReadOnlySignalError, match="only the CNC writes it"):
                s.check_plc_write()


@pytest.mark.req("C14-22", "C43-02", "C3-10", "H-01")
def test_the_documents_signals_have_their_names_types_and_origins(layout):
    s = layout.signal("gpCh[1]^bahn_state.area_mon_violation_detected_r")
    assert (s.type, s.direction, s.origin) == (SignalType.BOOL, Direction.CNC_TO_PLC, "FCT-C14 6.3")
    s = layout.signal("gpCh[0]^bahn_mc_control.suppress_area_mon_manual_mode.command_w")
    assert (s.type, s.origin) == (SignalType.BOOL, "FCT-C14 6.3")
    for side in ("low", "high"):
        s = layout.signal(f"gpAx[4]^ipo_mc_control.dyn_pos_limit_{side}.command_w")
        assert (s.type, s.unit, s.origin) == (SignalType.DINT, "0.1 µm", "FCT-C43 3.1.1")
        assert layout.signal(f"gpAx[4]^ipo_mc_control.dyn_pos_limit_{side}.state_r").type is SignalType.DINT
    expected = {
        "active": (SignalType.BOOL, 0x0234),
        "velocity": (SignalType.LREAL, 0x0244),
        "brake_dist": (SignalType.LREAL, 0x0245),
        "coll_offset": (SignalType.UDINT, 0x0246),
        "deceleration": (SignalType.LREAL, 0x0247),
    }
    for j, axis in enumerate(layout.axes):
        for leaf, (sig_type, element) in expected.items():
            s = layout.signal(f"gpAx[{j}]^dyn_coll_mon.{leaf}")
            assert s.type is sig_type
            assert s.origin == "FCT-C3 4.3"
            assert (s.ads_port, s.ads_group, s.ads_offset) == (
                ADS_PORT_GEO,
                ADS_GROUP_GEO_AXIS,
                (axis.number << 16) | element,
            )


# --- addresses -----------------------------------------------------------------------------------


@pytest.mark.req("H-08")
def test_hli_ads_offset_is_the_byte_offset_in_the_half(layout):
    for s in layout:
        if s.path.startswith("dyn_coll_mon."):
            continue
        group = ADS_GROUP_PLC_TO_CNC if s.plc_writable else ADS_GROUP_CNC_TO_PLC
        assert (s.ads_port, s.ads_group, s.ads_offset) == (ADS_PORT_HLI, group, s.offset)
        assert s.symbol == s.st_path


@pytest.mark.req("H-08")
def test_modbus_tables_follow_type_and_direction_with_fixed_blocks(layout):
    for s in layout:
        table = {
            (SignalType.BOOL, True): ModbusTable.COIL,
            (SignalType.BOOL, False): ModbusTable.DISCRETE_INPUT,
        }.get(
            (s.type, s.plc_writable),
            ModbusTable.HOLDING_REGISTER if s.plc_writable else ModbusTable.INPUT_REGISTER,
        )
        assert s.modbus_table is table, s.st_path
        assert s.modbus_count == {SignalType.BOOL: 1, SignalType.LREAL: 4}.get(s.type, 2)
        base = (MODBUS_AXIS_BASE if s.st_path.startswith("gpAx") else 0) + MODBUS_BLOCK_STRIDE * s.index
        assert base <= s.modbus_address
        assert s.modbus_address + s.modbus_count <= base + MODBUS_BLOCK_STRIDE
        if s.modbus_count > 1:
            assert s.modbus_address % 2 == 0
    # every occupied register belongs to exactly one signal
    index = layout.modbus_index(ModbusTable.INPUT_REGISTER)
    sig = layout.signal("gpAx[1]^dyn_coll_mon.velocity")
    assert [index[sig.modbus_address + k] for k in range(4)] == [(sig, k) for k in range(4)]


@pytest.mark.req("H-08")
def test_modbus_references_are_one_based_with_the_table_prefix(layout):
    s = layout.signal("gpCh[0]^bahn_mc_control.override.command_w")
    assert (s.modbus_table, s.modbus_address, layout.modbus_reference(s)) == (
        ModbusTable.HOLDING_REGISTER,
        0,
        "40001",
    )
    assert layout.modbus_reference(layout.signal("gpCh[0]^bahn_state.mode_r")) == "30001"
    assert (
        layout.modbus_reference(layout.signal("gpCh[0]^bahn_state.area_mon_violation_detected_r")) == "10001"
    )
    enable = layout.signal("gpCh[0]^bahn_mc_control.suppress_area_mon_manual_mode.enable_w")
    assert layout.modbus_reference(enable) == "00001"
    s = layout.signal("gpAx[1]^ipo_mc_control.dyn_pos_limit_low.command_w")
    assert (
        layout.modbus_reference(s)
        == f"4{MODBUS_AXIS_BASE + MODBUS_BLOCK_STRIDE + s.modbus_address % 100 + 1}"
    )


@pytest.mark.req("H-08")
@pytest.mark.parametrize("change", ["axis", "channel"])
def test_adding_an_axis_or_a_channel_moves_no_address(layout, change):
    config = demo_config()
    if change == "axis":
        bigger = demo_config(extra_axes=1)
    else:
        extra = [
            AxisConfig(number=9, name="W"),
            AxisConfig(number=10, name="V"),
            AxisConfig(number=11, name="Q"),
        ]
        bigger = config.model_copy(
            update={
                "axes": [*config.axes, *extra],
                "channels": [
                    *config.channels,
                    ChannelConfig(number=3, axes=["W", "V", "Q"], main_axes=("W", "V", "Q")),
                ],
            }
        )
        bigger = MachineConfig.model_validate(bigger.model_dump())
    big = build_layout(bigger)
    assert len(big) > len(layout)
    for s in layout:
        t = big.signal(s.st_path)
        assert (t.offset, t.modbus_table, t.modbus_address, t.ads_port, t.ads_group, t.ads_offset) == (
            s.offset,
            s.modbus_table,
            s.modbus_address,
            s.ads_port,
            s.ads_group,
            s.ads_offset,
        ), s.st_path
    assert big.hash != layout.hash


@pytest.mark.req("H-01")
def test_fields_are_naturally_aligned_and_never_overlap(layout):
    for d in Direction:
        end = 0
        for s in layout.half(d):
            assert s.offset % s.size == 0, s.st_path
            assert s.offset >= end, s.st_path
            end = s.offset + s.size
        assert layout.size(d) % 8 == 0
        assert end <= layout.size(d)


@pytest.mark.req("H-01")
def test_rotary_axes_get_rotary_units():
    config = demo_config()
    config.axes[2] = AxisConfig(number=3, name="Z", axis_type=AxisType.ROTARY)
    layout = build_layout(MachineConfig.model_validate(config.model_dump()))
    assert layout.signal("gpAx[2]^ipo_state.act_pos_r").unit == "0.0001°"
    assert layout.signal("gpAx[2]^dyn_coll_mon.deceleration").unit == "°/s²"
    assert layout.signal("gpAx[1]^ipo_state.velocity_r").unit == "0.1 µm/s"


def test_configs_the_addressing_cannot_hold_are_refused():
    too_many = [AxisConfig(number=n + 1, name=f"A{n}") for n in range(MAX_AXES + 1)]
    config = MachineConfig.model_construct(
        name="big",
        axes=too_many,
        channels=[ChannelConfig(axes=["A0", "A1", "A2"], main_axes=("A0", "A1", "A2"))],
    )
    with pytest.raises(LayoutError, match="Modbus map has blocks for 635"):
        build_layout(config)
    config = demo_config()
    config = config.model_copy(
        update={"axes": [config.axes[0].model_copy(update={"number": 70_000}), *config.axes[1:]]}
    )
    with pytest.raises(LayoutError, match="does not fit the 16 bits"):
        build_layout(config)


# --- formats ---------------------------------------------------------------------------------------


@pytest.mark.req("H-01", "H-08")
@pytest.mark.parametrize("direction", list(Direction))
def test_struct_and_construct_describe_the_same_bytes(layout, direction):
    values = distinct_values(layout, direction, salt=3)
    packed = layout.pack(direction, values)
    assert len(packed) == layout.size(direction) == layout.construct(direction).sizeof()
    assert layout.construct(direction).build(values) == packed
    parsed = layout.construct(direction).parse(packed)
    assert {k: parsed[k] for k in values} == values
    assert layout.unpack(direction, packed) == values


@pytest.mark.req("H-08")
def test_json_export_rebuilds_the_same_layout_and_detects_edits(layout):
    text = layout.to_json()
    again = Layout.from_json(text)
    assert again.hash == layout.hash
    assert again.signals == layout.signals
    data = json.loads(text)
    assert data["layout_version"] == LAYOUT_VERSION
    assert len(data["signals"]) == len(layout)
    data["signals"][5]["unit"] = "mm"
    with pytest.raises(LayoutError, match="does not match its content"):
        Layout.from_dict(data)
    data["signals"][5]["offset"] += 4
    with pytest.raises(LayoutError, match=r"damaged layout JSON: .*overlaps"):
        Layout.from_dict(data)
    with pytest.raises(LayoutError, match="not a layout"):
        Layout.from_dict({"format": "something else"})


@pytest.mark.req("H-01")
def test_hash_ignores_documentation_but_not_addresses(layout):
    demo = demo_config()
    channels = [demo.channels[0].model_copy(update={"name": "another name"}), *demo.channels[1:]]
    renamed = demo.model_copy(update={"name": "other", "channels": channels})
    assert build_layout(renamed).hash == layout.hash
    renumbered = demo.model_copy(
        update={"axes": [demo.axes[0].model_copy(update={"number": 42}), *demo.axes[1:]]}
    )
    assert build_layout(renumbered).hash != layout.hash  # dyn_coll_mon ADS offsets changed


@pytest.mark.req("H-01")
def test_values_are_checked_against_the_type(layout):
    s = layout.signal("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w")
    assert s.coerce(-(2**31)) == -(2**31)
    with pytest.raises(SignalValueError, match=r"out of range for DINT \[-2147483648, 2147483647\]"):
        s.coerce(2**31)
    with pytest.raises(SignalValueError, match="takes an integer"):
        s.coerce(1.5)
    with pytest.raises(SignalValueError, match="takes an integer"):
        s.coerce(True)
    b = layout.signal("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.enable_w")
    assert b.coerce(1) is True
    assert b.coerce(False) is False
    with pytest.raises(SignalValueError, match="BOOL takes"):
        b.coerce(2)
    u = layout.signal("gpCh[0]^mc_command.program_select_w")
    with pytest.raises(SignalValueError, match="UDINT"):
        u.coerce(-1)


def test_unknown_paths_get_suggestions(layout):
    with pytest.raises(UnknownSignalError, match=r"did you mean gpAx\[0\]\^ipo_mc_control.dyn_pos_limit_low"):
        layout.signal("gpAx[0]^ipo_mc_control.dyn_pos_limit_lo.command_w")


@pytest.mark.req("H-01")
def test_raw_ranges_must_cover_whole_fields(layout):
    s = layout.signal("gpCh[0]^bahn_mc_control.override.command_w")
    assert layout.signals_in_range(Direction.PLC_TO_CNC, s.offset, 4) == (s,)
    with pytest.raises(LayoutError, match="cut"):
        layout.signals_in_range(Direction.PLC_TO_CNC, s.offset + 1, 4)
    with pytest.raises(LayoutError, match="outside"):
        layout.signals_in_range(Direction.PLC_TO_CNC, layout.p2c_size - 2, 4)


# --- hli-server map --------------------------------------------------------------------------------


@pytest.mark.req("H-08")
def test_map_renders_one_row_per_signal_in_every_format(layout):
    from hli_server.commands.map import COLUMNS, render_map

    rows = list(csv.DictReader(io.StringIO(render_map(layout, "csv"))))
    assert [r["st_path"] for r in rows] == [s.st_path for s in layout]
    assert list(rows[0]) == list(COLUMNS)
    row = next(r for r in rows if r["st_path"] == "gpAx[1]^dyn_coll_mon.brake_dist")
    assert (row["ads_port"], row["ads_group"], row["ads_offset"], row["type"], row["access"]) == (
        "551",
        "0x120300",
        "0x20245",
        "LREAL",
        "read",
    )
    md = render_map(layout, "md")
    table_rows = [line for line in md.splitlines() if line.startswith("| ") and "`gp" in line]
    assert len(table_rows) == len(layout)
    assert layout.hash in md
    assert "40001" in md
    assert Layout.from_json(render_map(layout, "json")).hash == layout.hash


@pytest.mark.req("H-08")
def test_map_command_prints_the_demo_machine_map_as_json():
    from hli_server.cli import main
    from hli_server.configuration import load_machine

    result = CliRunner().invoke(main, ["map", "--format", "json"])
    assert result.exit_code == 0, result.output
    assert Layout.from_json(result.output).hash == build_layout(load_machine(None)).hash


def test_map_command_reports_a_missing_config_file(tmp_path):
    from hli_server.cli import main

    result = CliRunner().invoke(main, ["map", "--config", str(tmp_path / "nope.toml")])
    assert result.exit_code == 2
    assert "nope.toml" in result.output
