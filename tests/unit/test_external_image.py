"""V.E. variables in the layout and the process image (N-05).

The layout places every element of every V.E. variable (``gpVEGlob^name``, ``gpVECh[i]^name[j]``)
after the axis blocks of the PLC->CNC half and in the V.E. area of the coils and holding registers;
the image keeps the fields and the engine's store (``machine.external``) in step, the last writer
winning (``hli_server/image/external.py``). The race of a PLC write and an NC write is played out
cycle by cycle with the image in a buffer and the engine stepped by hand.
"""

from __future__ import annotations

import math
import sys

import pytest
from pydantic import ValidationError

from hli_server.engine.external import ExternalVariableError
from hli_server.engine.machine import Machine
from hli_server.image import ProcessImage
from plc_clients import ImageClient
from schemas import image_format as fmt
from schemas.config import ExternalVariableConfig, MachineConfig
from schemas.layout import (
    ADS_GROUP_PLC_TO_CNC,
    MODBUS_EXTERNAL_BASE,
    MODBUS_EXTERNAL_END,
    REAL32_MAX,
    Direction,
    Layout,
    LayoutError,
    ModbusTable,
    Scope,
    SignalType,
    SignalValueError,
    build_layout,
)
from tests.machines import EXTERNAL_VARIABLES, demo_config

pytestmark = pytest.mark.req("N-05")

P2C = Direction.PLC_TO_CNC


@pytest.fixture(scope="module")
def config() -> MachineConfig:
    return demo_config(external=True)


@pytest.fixture(scope="module")
def layout(config: MachineConfig) -> Layout:
    return build_layout(config)


# --- the layout ---------------------------------------------------------------------------------


def test_every_element_is_a_signal_named_as_the_plc_programmer_declares_it(layout: Layout) -> None:
    paths = [s.st_path for s in layout.external_signals]
    assert paths[:5] == [
        "gpVEGlob^PLC_READY",
        "gpVEGlob^S8",
        "gpVEGlob^U8[0]",
        "gpVEGlob^U8[1]",
        "gpVEGlob^U8[2]",
    ]
    assert "gpVECh[0]^PART_COUNT" in paths
    # row-major, as the engine's store counts them (ExternalVarSpec.flat_index)
    pos = [p for p in paths if p.startswith("gpVECh[1]^POS")]
    assert pos == [f"gpVECh[1]^POS[{i},{j}]" for i in range(2) for j in range(3)]
    store = Machine(demo_config(external=True)).external
    spec = store.spec("POS", 2)
    assert spec is not None
    assert [spec.flat_index(layout.signal(p).external_element[1]) for p in pos] == list(range(6))
    assert layout.signal("gpVECh[1]^POS[1,2]").name == "ch2.V.E.POS[1,2]"
    assert layout.signal("gpVEGlob^S8").name == "V.E.S8"


def test_the_kernel_types_lie_in_the_images_types_with_their_own_ranges(layout: Layout) -> None:
    want = {
        "gpVEGlob^PLC_READY": (SignalType.BOOL, None),
        "gpVEGlob^S8": (SignalType.DINT, (-128, 127)),
        "gpVEGlob^U8[0]": (SignalType.UDINT, (0, 255)),
        "gpVECh[0]^S16": (SignalType.DINT, (-32768, 32767)),
        "gpVECh[0]^U16": (SignalType.UDINT, (0, 65535)),
        "gpVECh[0]^PART_COUNT": (SignalType.DINT, None),
        "gpVECh[0]^U32": (SignalType.UDINT, None),
        "gpVECh[1]^R32[0]": (SignalType.LREAL, (-REAL32_MAX, REAL32_MAX)),
        "gpVECh[1]^POS[0,0]": (SignalType.LREAL, (-sys.float_info.max, sys.float_info.max)),
    }
    assert {p: (layout.signal(p).type, layout.signal(p).limits) for p in want} == want
    assert "(SGN16, area of channel 1)" in layout.signal("gpVECh[0]^S16").description


def test_elements_are_plc_writable_shared_fields_with_their_own_addresses(layout: Layout) -> None:
    hli_end = max(s.offset + s.size for s in layout.hli_half(P2C))
    for s in layout.external_signals:
        assert s.direction is P2C
        assert s.access == "read/write"
        assert s.scope in (Scope.VE_GLOBAL, Scope.VE_CHANNEL)
        assert s.offset >= hli_end
        assert s.offset % s.alignment == 0  # a number at a multiple of its size, a STRING anywhere
        assert (s.ads_group, s.ads_offset) == (ADS_GROUP_PLC_TO_CNC, s.offset)
        assert MODBUS_EXTERNAL_BASE <= s.modbus_address < MODBUS_EXTERNAL_END
        table = ModbusTable.COIL if s.type is SignalType.BOOL else ModbusTable.HOLDING_REGISTER
        assert s.modbus_table is table
        if s.type is not SignalType.STRING:
            assert s.modbus_address % s.modbus_count == 0  # 2- and 4-register values aligned
        assert s.reqs == ("N-05",)
        assert "last writer wins" in s.description
    assert layout.signal("gpVEGlob^PLC_READY").description.startswith("the PLC is ready. V.E.PLC_READY")
    assert layout.signal("gpVECh[0]^S16").modbus_count == 2  # an SGN16 in a DINT
    assert layout.reference_digits == 5  # the V.E. area keeps the map's 40001-style references
    assert layout.modbus_reference(layout.signal("gpVEGlob^PLC_READY")) == "01201"


def test_the_global_area_comes_first_then_each_channel_in_order(layout: Layout) -> None:
    scopes = [(s.scope, s.index) for s in layout.external_signals]
    assert scopes == sorted(scopes, key=lambda k: (k[0] is Scope.VE_CHANNEL, k[1]))


def test_adding_an_axis_keeps_the_modbus_addresses_and_names(layout: Layout) -> None:
    bigger = build_layout(demo_config(extra_axes=2, external=True))
    for s in layout.external_signals:
        other = bigger.signal(s.st_path)
        assert (other.modbus_table, other.modbus_address) == (s.modbus_table, s.modbus_address)
        # the image offset follows the last axis block (documented in docs/process-image.md)
        assert other.offset > s.offset


def test_the_json_layout_carries_the_variables(layout: Layout) -> None:
    again = Layout.from_json(layout.to_json())
    assert again.hash == layout.hash
    assert [s.st_path for s in again.external_signals] == [s.st_path for s in layout.external_signals]
    assert again.signal("gpVECh[0]^S16").scope is Scope.VE_CHANNEL


def test_construct_and_struct_agree_on_the_v_e_area(layout: Layout) -> None:
    values = {s.st_path: "" if s.type is SignalType.STRING else 0 for s in layout.half(P2C)}
    values["gpVECh[0]^S16"] = -2
    values["gpVECh[1]^R32[1]"] = 0.5
    values["gpVECh[0]^UserInteraction.Message"] = "Camera at A1"
    packed = layout.pack(P2C, values)
    parsed = layout.construct(P2C).parse(packed)
    assert (parsed["gpVECh[0]^S16"], parsed["gpVECh[0]^UserInteraction.Message"]) == (-2, "Camera at A1")
    unpacked = layout.unpack(P2C, packed)
    assert (unpacked["gpVECh[1]^R32[1]"], unpacked["gpVECh[0]^UserInteraction.Message"]) == (
        0.5,
        "Camera at A1",
    )


def test_every_door_refuses_what_the_kernel_type_cannot_hold(layout: Layout) -> None:
    from schemas.layout import SignalValueError

    assert layout.signal("gpVEGlob^S8").coerce(-128) == -128
    for path, bad in (("gpVEGlob^S8", 128), ("gpVEGlob^U8[0]", -1), ("gpVECh[0]^S16", 40_000)):
        with pytest.raises(SignalValueError, match=r"out of range for the V\.E\. variable"):
            layout.signal(path).coerce(bad)
    for bad_real in (1e39, math.nan, math.inf):
        with pytest.raises(SignalValueError, match="finite numbers only"):
            layout.signal("gpVECh[1]^R32[0]").coerce(bad_real)
    with pytest.raises(SignalValueError, match="finite numbers only"):
        layout.signal("gpVECh[1]^POS[0,0]").coerce(math.nan)
    assert layout.signal("gpVECh[1]^POS[0,0]").coerce(1e300) == 1e300
    assert layout.signal("gpVECh[0]^PART_COUNT").coerce(-(2**31)) == -(2**31)


def test_the_machine_file_is_refused_when_the_modbus_area_is_too_small() -> None:
    base = demo_config()
    too_big = [ExternalVariableConfig(name="TRACK", type="REAL64", dims=[176])]  # 704 registers
    with pytest.raises(
        ValidationError, match=r"need 704 Modbus holding registers.*reserves 700 \(1200..1899\)"
    ):
        MachineConfig.model_validate(
            {**base.model_dump(), "external_variables": [v.model_dump() for v in too_big]}
        )
    fits = [ExternalVariableConfig(name="TRACK", type="REAL64", dims=[175])]
    config = MachineConfig.model_validate(
        {**base.model_dump(), "external_variables": [v.model_dump() for v in fits]}
    )
    assert build_layout(config).external_signals[-1].modbus_address == MODBUS_EXTERNAL_END - 4
    with pytest.raises(ValidationError, match="coils for their BOOLEAN elements"):
        MachineConfig.model_validate(
            {**base.model_dump(), "external_variables": [{"name": "BITS", "type": "BOOLEAN", "dims": [701]}]}
        )


def test_build_layout_refuses_what_the_area_cannot_hold_even_without_the_model_check() -> None:
    config = demo_config().model_copy(
        update={"external_variables": [ExternalVariableConfig(name="BITS", type="BOOLEAN", dims=[800])]}
    )
    with pytest.raises(LayoutError, match="coils"):
        build_layout(config)


# --- the image: latch and publish --------------------------------------------------------------


class Rig:
    """A machine and its image in a buffer, cycled by hand: latch, (NC writes), step, publish."""

    def __init__(self, config: MachineConfig) -> None:
        self.machine = Machine(config)
        self.image = ProcessImage.in_memory(build_layout(config))
        self.image.init_from(self.machine.hli, 0, self.machine.external)
        self.plc = ImageClient.over(self.image.buffer, name=self.image.name, expect=self.image.layout)

    def latch(self) -> None:
        self.image.latch_into(self.machine.hli)

    def publish(self) -> None:
        self.machine.step(1)
        self.image.publish_from(self.machine.hli, self.machine.cycle)

    def cycle(self) -> None:
        self.latch()
        self.publish()

    def close(self) -> None:
        self.plc.close()
        self.image.close()


@pytest.fixture
def rig(config: MachineConfig) -> Rig:
    r = Rig(config)
    yield r
    r.close()


def test_a_plc_write_reaches_the_store_at_the_next_latch(rig: Rig) -> None:
    rig.plc.write("gpVECh[0]^PART_COUNT", 41)
    rig.plc.write("gpVEGlob^PLC_READY", True)
    rig.plc.write("gpVECh[1]^POS[1,2]", -2.5)
    assert rig.machine.external.read("PART_COUNT", 1) == 0  # not before the latch
    rig.latch()
    ext = rig.machine.external
    assert (ext.read("PART_COUNT", 1), ext.read("PLC_READY", None), ext.read("POS", 2, (1, 2))) == (
        41,
        True,
        -2.5,
    )
    assert ext.read("PLC_READY", 2) is True  # a channel sees the global variable


def test_an_nc_write_reaches_every_reader_at_the_publish(rig: Rig) -> None:
    rig.latch()
    rig.machine.external.write("S16", 1, -300)
    rig.machine.external.write("FLAGS", 2, True, (3,))
    assert rig.plc.read("gpVECh[0]^S16") == 0
    rig.publish()
    assert rig.plc.read("gpVECh[0]^S16") == -300
    assert rig.plc.read("gpVECh[1]^FLAGS[3]") is True
    assert rig.image.read("gpVECh[0]^S16") == -300  # the doors' read (Modbus, ADS, HTTP)
    rig.cycle()  # the NC's own value is no PLC write: nothing comes back into the store
    assert rig.machine.external.read("S16", 1) == -300


def test_race_an_nc_write_in_the_cycle_a_plc_write_lands_stores_last_and_wins(rig: Rig) -> None:
    """The PLC writes 5 after the latch of a cycle in which the NC writes 7: the NC stores at the
    publish, after the PLC: 7 stays, in the store and in the field (last writer wins)."""
    rig.latch()
    rig.plc.write("gpVECh[0]^PART_COUNT", 5)  # lands between this cycle's latch and publish
    rig.machine.external.write("PART_COUNT", 1, 7)  # the NC, in the step
    rig.publish()
    assert rig.plc.read("gpVECh[0]^PART_COUNT") == 7
    rig.cycle()
    assert rig.machine.external.read("PART_COUNT", 1) == 7


def test_race_a_plc_write_after_the_nc_write_wins(rig: Rig) -> None:
    """The NC writes 7 in one cycle; the PLC writes 5 after that publish: 5 reaches the NC at the
    next latch and stays."""
    rig.latch()
    rig.machine.external.write("PART_COUNT", 1, 7)
    rig.publish()
    rig.plc.write("gpVECh[0]^PART_COUNT", 5)
    rig.cycle()
    assert rig.machine.external.read("PART_COUNT", 1) == 5
    assert rig.plc.read("gpVECh[0]^PART_COUNT") == 5


def test_race_a_plc_write_during_a_cycle_that_writes_another_element_is_kept(rig: Rig) -> None:
    rig.latch()
    rig.plc.write("gpVECh[1]^POS[0,0]", 1.5)  # between latch and publish
    rig.machine.external.write("POS", 2, 9.0, (0, 1))  # the NC writes a neighbour
    rig.publish()
    assert rig.plc.read("gpVECh[1]^POS[0,0]") == 1.5
    rig.latch()
    assert rig.machine.external.read("POS", 2, (0, 0)) == 1.5
    assert rig.machine.external.read("POS", 2, (0, 1)) == 9.0


def test_rewriting_the_value_a_field_holds_changes_nothing(rig: Rig) -> None:
    rig.latch()
    rig.machine.external.write("U16", 1, 12)
    rig.publish()
    rig.plc.write("gpVECh[0]^U16", 12)  # the same value: no change, nothing to latch
    rig.machine.external.write("U16", 1, 13)  # the NC moves on before the latch
    rig.latch()
    assert rig.machine.external.read("U16", 1) == 13


def test_an_sgn16_stored_past_the_doors_is_refused_at_the_latch(rig: Rig) -> None:
    raw = rig.image.layout.signal("gpVECh[0]^S16")
    fmt.write_field(rig.image.buffer, rig.image.plan.p2c_offset, raw, 40_000)
    rig.latch()
    assert rig.machine.external.read("S16", 1) == 0
    assert rig.plc.read("gpVECh[0]^S16") == 0


def test_a_value_the_store_refuses_is_not_taken_and_the_field_is_restored(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    rig.plc.write("gpVECh[1]^POS[0,0]", 4.0)
    rig.latch()
    raw = rig.image.layout.signal("gpVECh[1]^POS[0,0]")
    fmt.write_field(rig.image.buffer, rig.image.plan.p2c_offset, raw, math.nan)  # past every door's check
    rig.plc.write("gpVECh[1]^POS[0,1]", 2.0)
    rig.latch()
    ext = rig.machine.external
    assert (ext.read("POS", 2, (0, 0)), ext.read("POS", 2, (0, 1))) == (4.0, 2.0)
    assert rig.plc.read("gpVECh[1]^POS[0,0]") == 4.0
    assert "gpVECh[1]^POS[0,0]: the PLC wrote nan, refused" in caplog.text


def test_start_up_gives_every_field_the_stores_value(config: MachineConfig) -> None:
    machine = Machine(config)
    machine.external.write("PART_COUNT", 1, 99)
    with ProcessImage.in_memory(build_layout(config)) as image:
        image.init_from(machine.hli, 0, machine.external)
        assert image.read("gpVECh[0]^PART_COUNT") == 99


def test_an_image_with_v_e_fields_needs_the_engines_store(config: MachineConfig) -> None:
    machine = Machine(config)
    with (
        ProcessImage.in_memory(build_layout(config)) as image,
        pytest.raises(ValueError, match="pass the engine's store"),
    ):
        image.init_from(machine.hli, 0)


def test_every_kernel_type_round_trips_through_plc_and_nc(rig: Rig) -> None:
    cases = [
        ("PLC_READY", None, (), "gpVEGlob^PLC_READY", True),
        ("S8", None, (), "gpVEGlob^S8", -128),
        ("U8", None, (2,), "gpVEGlob^U8[2]", 255),
        ("S16", 1, (), "gpVECh[0]^S16", -32768),
        ("U16", 1, (), "gpVECh[0]^U16", 65535),
        ("PART_COUNT", 1, (), "gpVECh[0]^PART_COUNT", -(2**31)),
        ("U32", 1, (), "gpVECh[0]^U32", 2**32 - 1),
        ("R32", 2, (1,), "gpVECh[1]^R32[1]", -REAL32_MAX),
        ("POS", 2, (0, 2), "gpVECh[1]^POS[0,2]", 1e300),
    ]
    for _name, _ch, _index, path, value in cases:
        rig.plc.write(path, value)
    rig.latch()
    for name, ch, index, _path, value in cases:
        assert rig.machine.external.read(name, ch, index) == value
    for name, ch, index, _path, _value in cases:
        zero = rig.machine.external.spec(name, ch)
        assert zero is not None
        rig.machine.external.write(name, ch, zero.zero(), index)
    rig.publish()
    assert all(not rig.plc.read(path) for *_, path, _v in cases)


def test_the_variables_the_test_machine_declares_cover_every_kernel_type() -> None:
    assert {v.type for v in EXTERNAL_VARIABLES} == {
        "BOOLEAN", "SGN08", "UNS08", "SGN16", "UNS16", "SGN32", "UNS32", "REAL32", "REAL64",
        "STRING", "VSTRING", "UserInteractionType", "Point",
    }  # fmt: skip


def test_bytes_between_the_fields_are_not_taken_for_a_write(rig: Rig) -> None:
    """The latch compares the V.E. area's bytes; a store into the padding between two fields (only a
    PLC on shared memory can make one) changes no variable."""
    layout = rig.image.layout
    a, b = layout.signal("gpVEGlob^PLC_READY"), layout.signal("gpVEGlob^S8")
    assert b.offset - (a.offset + a.size) > 0  # the BOOL is followed by padding up to the DINT
    rig.image.buffer[rig.image.plan.p2c_offset + a.offset + 1] = 0xFF
    rig.plc.write("gpVEGlob^S8", -5)
    rig.latch()
    assert (rig.machine.external.read("PLC_READY", None), rig.machine.external.read("S8", None)) == (
        False,
        -5,
    )


# --- STRING and structures ---------------------------------------------------------------------


def test_strings_and_structures_are_fields_of_their_own_size(layout: Layout) -> None:
    teach = layout.signal("gpVEGlob^TEACH_FILE_NAME")
    assert (teach.type, teach.type_name, teach.size, teach.modbus_count) == (
        SignalType.STRING,
        "STRING(20)",
        21,
        11,
    )
    note = layout.signal("gpVECh[1]^NOTES[1]")
    assert (note.type_name, note.size, note.modbus_count) == ("STRING(8)", 9, 5)
    # a structure's elements in order, each at its alignment; the structure at its most aligned one's
    message = layout.signal("gpVECh[0]^UserInteraction.Message")
    answer = layout.signal("gpVECh[0]^UserInteraction.Answer")
    done = layout.signal("gpVECh[0]^UserInteraction.Done")
    assert message.offset % 4 == 0
    assert (answer.offset - message.offset, done.offset - answer.offset) == (24, 4)
    assert message.structures == ("UserInteractionType",)
    # an array of structures: every element of the same shape (X 8, VALID 1, LABEL 6, padded to 16)
    x0, x1 = layout.signal("gpVECh[1]^TRACK[0].X"), layout.signal("gpVECh[1]^TRACK[1].X")
    assert x1.offset - x0.offset == 16
    label = layout.signal("gpVECh[1]^TRACK[1].LABEL")
    assert (label.type_name, label.external_element) == ("STRING(5)", ("TRACK.LABEL", (1,)))
    # Modbus: strings two bytes to a register, numbers at their alignment, the BOOLs in the coils
    assert answer.modbus_address == message.modbus_address + 12  # 11, then an even address
    assert done.modbus_table is ModbusTable.COIL


def test_a_string_goes_both_ways_and_the_last_writer_wins(rig: Rig) -> None:
    ext = rig.machine.external
    rig.plc.write("gpVEGlob^TEACH_FILE_NAME", "teach_01.dat")
    rig.plc.write("gpVECh[1]^TRACK[1].LABEL", "P7")
    rig.latch()
    assert ext.read("TEACH_FILE_NAME", 1) == "teach_01.dat"
    assert ext.read("TRACK.LABEL", 2, (1,)) == "P7"
    ext.write("UserInteraction.Message", 1, "Camera at A1 - click")
    ext.write("TEACH_FILE_NAME", None, "a.dat")  # shorter than before: the rest of the field is NUL
    rig.publish()
    assert rig.plc.read("gpVECh[0]^UserInteraction.Message") == "Camera at A1 - click"
    assert rig.plc.read("gpVEGlob^TEACH_FILE_NAME") == "a.dat"
    field = rig.image.layout.signal("gpVEGlob^TEACH_FILE_NAME")
    start = rig.image.plan.p2c_offset + field.offset
    assert bytes(rig.image.buffer[start : start + field.size]) == b"a.dat".ljust(21, b"\0")
    rig.plc.write("gpVECh[0]^UserInteraction.Message", "")
    rig.cycle()
    assert ext.read("UserInteraction.Message", 1) == ""


def test_a_string_without_its_nul_stored_into_shared_memory_is_not_taken(rig: Rig) -> None:
    """Every door refuses a 21st character; a PLC on shared memory that stores one all the same (no NUL
    in the field) gets the store's value back, as for a NaN."""
    with pytest.raises(SignalValueError, match="holds at most 20"):
        rig.plc.write("gpVEGlob^TEACH_FILE_NAME", "x" * 21)
    rig.plc.write("gpVEGlob^TEACH_FILE_NAME", "ok")
    rig.latch()
    field = rig.image.layout.signal("gpVEGlob^TEACH_FILE_NAME")
    start = rig.image.plan.p2c_offset + field.offset
    rig.image.buffer[start : start + 21] = b"y" * 21
    rig.latch()
    assert rig.machine.external.read("TEACH_FILE_NAME", None) == "ok"
    assert rig.plc.read("gpVEGlob^TEACH_FILE_NAME") == "ok"
    rig.image.buffer[start : start + 3] = b"\x81a\0"  # 0x81 is no Windows-1252 character
    rig.latch()
    assert rig.plc.read("gpVEGlob^TEACH_FILE_NAME") == "ok"


def test_a_string_too_long_or_of_the_wrong_kind_is_refused_by_the_store() -> None:
    ext = Machine(demo_config(external=True)).external
    with pytest.raises(ExternalVariableError, match="holds at most 8 characters") as info:
        ext.write("NOTES", 2, "123456789", (0,))
    assert info.value.alarm == 21462
    with pytest.raises(ExternalVariableError, match="is a number") as info:
        ext.write("UserInteraction.Answer", 1, "yes")
    assert info.value.alarm == 914006
    with pytest.raises(ExternalVariableError, match="is a STRING") as info:
        ext.write("TEACH_FILE_NAME", 1, 5)
    with pytest.raises(ExternalVariableError, match="no Windows-1252 character"):
        ext.write("TEACH_FILE_NAME", 1, "\u4e2d")
    ext.write("TEACH_FILE_NAME", 1, "Zürich €")
    assert ext.read("TEACH_FILE_NAME", 1) == "Zürich €"


def test_the_store_names_a_structures_elements() -> None:
    ext = Machine(demo_config(external=True)).external
    assert ext.elements("UserInteraction", 1) == ["Message", "Answer", "Done"]
    assert ext.elements("UserInteraction", 2) is None  # channel 1's own
    assert "name one of its elements (Message, Answer, Done)" in str(ext.unknown("userinteraction", 1))
    assert "has no element Mesage" in str(ext.unknown("UserInteraction.Mesage", 1))
    assert "did you mean Message?" in str(ext.unknown("UserInteraction.Mesage", 1))
    assert "did you mean V.E.TEACH_FILE_NAME?" in str(ext.unknown("TEACH_FILENAME", 1))
    spec = ext.spec("track.label", 2)
    assert spec is not None
    assert (spec.path, spec.element_path((1,)), spec.declared) == (
        "V.E.TRACK[].LABEL",
        "V.E.TRACK[1].LABEL",
        "VSTRING",
    )
