"""Kinematic transformations in the running engine (issue 35): the path planned on the tool tip, the axes
on the inverse, and the monitors watching the axes (K-04, K-05).

The commands are handed to the decoder as the interpreter hands them (:mod:`hli_server.engine.nc.
kinematic_commands`); the blocks are parsed lines."""

from __future__ import annotations

import math
from collections.abc import Sequence

import pytest

from hli_server.engine import Machine
from hli_server.engine.channel import Channel
from hli_server.engine.nc.blocks import Block
from hli_server.engine.nc.directives import CoordinateCommand
from hli_server.engine.nc.kinematic_commands import (
    AxisEntry,
    CaxTrack,
    CylSelect,
    KinematicCommand,
    KinParamWrite,
    KinSelect,
    SetAxes,
    ToolOriCs,
    TrafoSwitch,
)
from hli_server.engine.nc.parser import parse_line
from hli_server.engine.planner import Marker, MarkerKind, Motion
from schemas.config import AxisConfig, ChannelConfig, KinematicAxis, KinematicEntry, MachineConfig, ToolEntry
from schemas.wire import ProgramState

AXES = ("X", "Y", "Z", "C", "A")
FCT = "FCT_LOOK_AHEAD_STANDARD | FCT_DYN_POS_LIMIT"
TOOL_MM = 100.0


def ca_head(pivot_mm: float = 0.0) -> KinematicEntry:
    """Universal Kinematics of a CA fork head, RTCP: X, Y, Z, then C about Z and A about X through a pivot
    ``pivot_mm`` above the tool's fixing point."""
    p = round(pivot_mm * 10_000)
    return KinematicEntry(
        id=7,
        type=91,
        zero_orientation=(0, 0, 1),
        zero_position=(0, 0, 0),
        axes=[
            KinematicAxis(type=1, orientation=(1, 0, 0)),
            KinematicAxis(type=1, orientation=(0, 1, 0)),
            KinematicAxis(type=1, orientation=(0, 0, 1)),
            KinematicAxis(type=2, orientation=(0, 0, 1)),
            KinematicAxis(type=2, orientation=(1, 0, 0), point=(0, 0, p)),
        ],
        rtcp=1,
    )


def machine(*, swe_mm: float = 1000.0, **channel: object) -> Machine:
    swe = round(swe_mm * 10_000)
    axes = [
        AxisConfig(
            number=i + 1, name=n, axis_type="R" if n in "CA" else "T", swe_neg=-swe, swe_pos=swe, a_max=2000.0
        )
        for i, n in enumerate(AXES)
    ]
    ch = ChannelConfig(
        axes=list(AXES),
        kinematics=[ca_head()],
        kinematik_id=7,
        tools=[ToolEntry(number=1, length=round(TOOL_MM * 10_000))],
        **channel,  # type: ignore[arg-type]
    )
    return Machine(MachineConfig(axes=axes, channels=[ch]))


class Feed:
    """The decoder's feed: parsed blocks and the kinematic commands, as the interpreter hands them."""

    def __init__(
        self, items: Sequence[str | KinematicCommand | CoordinateCommand], axes: Sequence[str] = AXES
    ) -> None:
        self._items = list(items)
        self._line = 0
        self._axes = tuple(axes)

    def next(self) -> object:
        if not self._items:
            return None
        item = self._items.pop(0)
        self._line += 1
        if isinstance(item, str):
            block = parse_line(item, self._line, self._axes)
            assert block is not None
            return block
        if item.block is None:
            item.block = Block(self._line, None, "")
        return item


def _feed(axes: Sequence[str], items: Sequence[str | KinematicCommand]) -> Feed:
    return Feed(items, axes)


def start(m: Machine, items: Sequence[str | KinematicCommand]) -> Channel:
    ch = m.channel(1)
    ch.load_program("M30\n")
    ch.start()
    assert ch.state == ProgramState.RUNNING, list(m.alarm_history)
    ch.decoder.blocks = Feed(items)  # type: ignore[assignment]
    return ch


def errors(m: Machine) -> list[int]:
    return [a.number for a in m.alarm_history if a.severity == "error"]


def run(m: Machine, ch: Channel, limit: int = 100_000, each=None) -> None:  # type: ignore[no-untyped-def]
    for _ in range(limit):
        if ch.state not in (ProgramState.RUNNING, ProgramState.HELD) and ch.planner.at_rest:
            return
        m.step(1)
        if each is not None:
            each(ch)
    raise AssertionError("program still running")


def tip(ch: Channel) -> tuple[float, ...]:
    return ch.tool_tip(ch.setpoints())


@pytest.mark.req("K-04")
def test_rtcp_keeps_the_tool_tip_while_the_head_turns() -> None:
    """#TRAFO ON, then only the A axis programmed: the tip stays on the programmed point every cycle while
    the linear axes move on the circle of the tool (RTCP, TF5240 introduction)."""
    m = machine()
    ch = start(
        m,
        [
            "D1",
            "G90 G01 X10 Y20 Z30 C0 A0 F3000",
            TrafoSwitch(None, True),
            "G01 X10 Y20 Z30 A90",
            "C90",
            TrafoSwitch(None, False),
            "M30",
        ],
    )
    seen_a: list[float] = []
    worst = 0.0

    def each(c: Channel) -> None:
        nonlocal worst
        if c.kinematic is not None:
            t = tip(c)
            worst = max(worst, math.dist(t[:3], (10.0, 20.0, 30.0)))
            seen_a.append(c.axis("A").setpoint)

    run(m, ch, each=each)
    assert errors(m) == [], list(m.alarm_history)
    assert worst <= 1e-9
    assert max(seen_a) == pytest.approx(90.0)
    assert len(seen_a) > 50
    # A 90°, C 90°: the tool points along +X; the head is 100 mm from the tip up the tool
    pos = ch.setpoints()
    assert pos[:3] == pytest.approx((10.0 + TOOL_MM, 20.0, 30.0), abs=1e-9)
    assert ch.kinematic is None


@pytest.mark.req("K-04")
def test_the_tip_moves_with_the_programmed_feed() -> None:
    """With the head tilted the tip's path is planned: a line of the tip at F6000 (100 mm/s) moves the tip
    100 mm/s (0.1 mm per 1 ms cycle) at constant velocity, the axes on the same line shifted."""
    m = machine()
    ch = start(
        m,
        [
            "D1",
            "G90 G01 X0 Y0 Z0 C0 A30 F6000",
            TrafoSwitch(None, True),
            "G01 X0 Y0 Z0",
            "X200",
            TrafoSwitch(None, False),
            "M30",
        ],
    )
    steps: list[float] = []
    last: list[tuple[float, ...]] = []

    def each(c: Channel) -> None:
        if c.kinematic is not None:
            t = tip(c)
            if last:
                steps.append(math.dist(t[:3], last[-1][:3]))
            last.append(t)

    run(m, ch, each=each)
    assert max(steps) == pytest.approx(0.1, rel=1e-9)
    assert last[-1][:3] == pytest.approx((200.0, 0.0, 0.0), abs=1e-9)


@pytest.mark.req("K-05")
def test_dynamic_limit_stops_the_turning_head_by_an_axis() -> None:
    """FCT-C43 on the Y *axis* (low limit -50 mm): the tool tip never leaves Y 0, but turning A towards 90°
    swings the head (100 mm up the tool) to Y -100; the path stops where the Y axis reaches -50 (A 30°)."""
    m = machine(interpolator_function=FCT)
    ctl = m.hli.axes[m.axis("Y").index].ipo_mc_control.dyn_pos_limit_low
    ctl.command_w = -50 * 10_000
    ctl.enable_w = True
    m.step(3)
    ch = start(m, ["D1", "G90 G01 X0 Y0 Z0 C0 A0 F3000", TrafoSwitch(None, True), "A90", "M30"])
    tips: list[float] = []
    for _ in range(20_000):
        m.step(1)
        if ch.kinematic is not None:
            tips.append(tip(ch)[1])
        if ch.planner.at_rest and ch.state == ProgramState.HELD:
            break
    y = ch.axis("Y").setpoint
    a = ch.axis("A").setpoint
    assert y >= -50.0 - 1e-6
    assert y == pytest.approx(-50.0, abs=0.2)
    assert a == pytest.approx(30.0, abs=0.2)  # sin(30°) * 100 mm = 50 mm
    assert max(abs(v) for v in tips) <= 1e-9  # the tip never moved: the axis reached the limit


@pytest.mark.req("K-05")
def test_software_limit_of_an_axis_refuses_the_block() -> None:
    """The tip's target is well inside the software limits (±80 mm), but the Y axis of the tilted head
    would go to -100 mm: the block is refused before it moves (the axes' path is checked)."""
    m = machine(swe_mm=80.0)
    ch = start(m, ["D1", "G90 G01 X0 Y0 Z-50 C0 A0 F3000", TrafoSwitch(None, True), "A90", "M30"])
    run(m, ch)
    found = [a for a in m.alarm_history if a.severity == "error"]
    assert found, "no error"
    assert found[0].axis == "Y", found
    assert abs(ch.axis("Y").setpoint) < 1e-9
    assert ch.axis("A").setpoint == pytest.approx(0.0)


@pytest.mark.req("K-03")
def test_kin_id_while_active_is_20687() -> None:
    m = machine()
    ch = start(m, [TrafoSwitch(None, True), KinSelect(None, 5), "M30"])
    run(m, ch)
    assert errors(m) == [20687]


@pytest.mark.req("K-01")
def test_param_writes_reach_the_data_set() -> None:
    """V.G.KIN[90].PARAM[0] = 100 mm (HD1) before #KIN ID[90] / #TRAFO ON: the TF5290 AB head with a
    100 mm offset to the tool's fixing point; C0 A45 (CA programming) tilts the tool about X."""
    m = machine()
    ch = start(
        m,
        [
            KinParamWrite(None, 90, 0, 1_000_000),
            KinParamWrite(None, 90, 13, 1),
            KinSelect(None, 90),
            "G90 G01 X0 Y0 Z0 C0 A0 F3000",
            TrafoSwitch(None, True),
            "X0 Y0 Z0 C0 A45",
        ],
    )
    run(m, ch)
    s = 100.0 * math.sqrt(0.5)
    assert ch.setpoints() == pytest.approx([0.0, -s, s, 45.0, 0.0], abs=1e-6)


# --- #CAXTRACK, #SET AX, #TOOL ORI CS, #CYL -------------------------------------------------------------
def decode_all(
    m: Machine, items: Sequence[str | KinematicCommand | CoordinateCommand]
) -> tuple[list[Motion], list[Marker]]:
    """Decode the whole feed (no motion): the motions and the markers."""
    ch = m.channel(1)
    ch.load_program("M30\n")
    ch.start()
    ch.decoder.blocks = Feed(items)  # type: ignore[assignment]
    motions: list[Motion] = []
    markers: list[Marker] = []
    for _ in range(10_000):
        out = ch.decoder.next_items()
        for item in out:
            (motions if isinstance(item, Motion) else markers).append(item)  # type: ignore[arg-type]
        if ch.decoder.finished:
            break
    return motions, markers


@pytest.mark.req("K-04")
def test_caxtrack_follows_the_tangent_as_the_manuals_example() -> None:
    """The block search page's #CAXTRACK example (https://infosys.beckhoff.com/content/1033/tf5200_blocksearch/
    348522379.html): after X10 Y10 (45°) the move X20 turns C to 0° by an inserted block (beyond ANGLIMIT 3°),
    X40 keeps 0°, X30 (backwards) is 180°, Y0 is -90° (written 270° here: the shortest way from 180°)."""
    m = machine()
    motions, markers = decode_all(
        m,
        [
            "G00 G90 X0 Y0 Z0 C0",
            "X5 Y5 C45",
            CaxTrack(None, True, anglimit=3.0, offset=0.0),
            "G01 X10 Y10 F1000",
            "X20",
            "X40",
            "X30",
            "Y0",
            CaxTrack(None, False),
            "M30",
        ],
    )
    assert not [mk for mk in markers if mk.kind is MarkerKind.ERROR]
    c = AXES.index("C")
    ends = [
        (round(mo.segment.end[0], 6), round(mo.segment.end[1], 6), round(mo.segment.end[c], 6))
        for mo in motions
    ]
    assert ends[1:] == [
        (10.0, 10.0, 45.0),
        (10.0, 10.0, 0.0),  # inserted: C turns at rest
        (20.0, 10.0, 0.0),
        (40.0, 10.0, 0.0),
        (40.0, 10.0, 180.0),
        (30.0, 10.0, 180.0),
        (30.0, 10.0, 270.0),
        (30.0, 0.0, 270.0),
    ]


@pytest.mark.req("K-04")
def test_caxtrack_turns_along_a_circle() -> None:
    """Along a full circle the tracking axis turns 360° with it, linearly: tangential at every point."""
    m = machine()
    motions, _ = decode_all(
        m,
        ["G01 G90 X0 Y0 Z0 C90 F1000", CaxTrack(None, True, anglimit=1.0), "G03 I-10", CaxTrack(None, False)],
    )
    arc = motions[-1]
    c = AXES.index("C")
    assert (arc.segment.start[c], arc.segment.end[c]) == pytest.approx((90.0, 450.0))
    for k in range(1, 8):
        s = arc.length * k / 8
        d = arc.segment.direction_at(s)
        tangent = math.degrees(math.atan2(d[1], d[0]))
        assert (arc.segment.point_at(s)[c] - tangent) % 360.0 == pytest.approx(0.0, abs=1e-9)


@pytest.mark.req("K-04")
@pytest.mark.parametrize(
    ("entries", "alarm"),
    [
        ([("X", 1, 0), ("Y", 2, 1), ("Z", 3, 2), ("C", 4, 3), ("C", 5, 4)], 21256),
        ([("X", 1, 0), ("Y", 2, 1), ("Z", 3, 2), ("C", 4, 3), ("A", 5, 3)], 21257),
        ([("X", 1, 0), ("Y", 2, 1), ("Z", 3, 2), ("C", 4, 3), ("A", 4, 4)], 21258),
        ([("X", 1, 0), ("Y", 2, 1), ("Z", 3, 2), ("C", 9, 3)], 20312),
    ],
)
def test_set_ax_errors(entries: list[tuple[str, int, int]], alarm: int) -> None:
    m = machine()
    _, markers = decode_all(m, [SetAxes(None, tuple(AxisEntry(*e) for e in entries)), "M30"])
    assert [mk.payload.alarm for mk in markers if mk.kind is MarkerKind.ERROR] == [alarm]


@pytest.mark.req("K-04")
def test_set_ax_renames_and_orders_the_kinematic_axes() -> None:
    """#SET AX [X,1,0][Y,2,1][Z,3,2][A,4,3][C,5,4]: the names swap (A is axis 4, C axis 5) and the
    kinematic's indices follow: the CA head's first rotary axis (index 3) is now the one programmed as A."""
    m = machine()
    entries = (("X", 1, 0), ("Y", 2, 1), ("Z", 3, 2), ("A", 4, 3), ("C", 5, 4))
    motions, markers = decode_all(
        m,
        [
            SetAxes(None, tuple(AxisEntry(*e) for e in entries)),
            "D1",
            "G01 G90 X0 Y0 Z0 A0 C0 F1000",
            TrafoSwitch(None, True),
            "C90",  # axis 5 (the head's A, about X) to 90°
            TrafoSwitch(None, False),
            "M30",
        ],
    )
    assert not [mk for mk in markers if mk.kind is MarkerKind.ERROR]
    end = motions[-1].axes_end()
    assert end[:3] == pytest.approx((0.0, -TOOL_MM, 0.0), abs=1e-9)  # slot 4 turned about X
    assert end[3:] == pytest.approx((0.0, 90.0))
    assert m.channel(1).decoder.axes == ["X", "Y", "Z", "A", "C"]


@pytest.mark.req("K-04")
def test_tool_ori_cs_turns_the_tool_onto_the_cs_z_axis() -> None:
    """#CS ON [0,0,0,30,0,0] (turned 30° about X), #TOOL ORI CS: the CA head turns the tool parallel to the
    CS's Z axis with RTCP on (the tip rests): A 30° (the nearer of the poses C 0°/A 30° and C 180°/A -30°)."""
    m = machine()
    motions, markers = decode_all(
        m,
        [
            "D1",
            "G01 G90 X0 Y0 Z0 C0 A0 F1000",
            TrafoSwitch(None, True),
            CoordinateCommand(Block(0, None, ""), "CS", "ON", values=(0.0, 0.0, 0.0, 30.0, 0.0, 0.0)),
            ToolOriCs(None),
            "M30",
        ],
    )
    assert not [mk for mk in markers if mk.kind is MarkerKind.ERROR]
    last = motions[-1]
    assert last.kin is not None  # (the program's end has switched the transformation off since)
    trafo = last.kin.trafo
    axes = last.axes_end()
    assert axes[3:] == pytest.approx((0.0, 30.0), abs=1e-9)
    assert trafo.to_tip(axes)[:3] == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    z_cs = (0.0, -math.sin(math.radians(30.0)), math.cos(math.radians(30.0)))
    assert trafo.orientation(axes) == pytest.approx(z_cs, abs=1e-12)


@pytest.mark.req("K-04")
def test_cyl_programs_the_development_in_mm() -> None:
    """#CYL [X, C, Z35]: C programmed in mm of the development on a radius of 35 mm: C 10 mm is
    10 * 180 / (35 pi) degrees at the axis; #CYL OFF ends it."""
    m = machine()
    motions, markers = decode_all(
        m,
        [
            "G01 G90 X0 Y0 Z35 C0 A0 F1000",
            CylSelect(None, ("X", "C", "Z"), 35.0),
            "G01 X5 C10",
            CylSelect(None),
            "M30",
        ],
    )
    assert not [mk for mk in markers if mk.kind is MarkerKind.ERROR]
    end = motions[-1].axes_end()
    assert end[0] == pytest.approx(5.0)
    assert end[3] == pytest.approx(10.0 * 180.0 / (35.0 * math.pi))
    assert m.channel(1).decoder.kin.active is None


PROT_BOX = [
    "#CONTROL AREA BEGIN [ID=1 PROT POLY MIN_EXCUR=-300 MAX_EXCUR=300]",
    "G01 X-20 Y-120 F1000",
    "X20",
    "Y-40",
    "X-20",
    "Y-120",
    "#CONTROL AREA END",
    "#CONTROL AREA ON [ID=1]",
]


@pytest.mark.req("K-05")
def test_protection_area_watches_the_tool_tip_not_the_axes() -> None:
    """FCT-C14 watches the TCP: the head swings the Y axis through a protection area (Y -120..-40) while
    the tip rests at the origin: nothing is refused. Moving the tip itself into the area is refused."""
    m = machine()
    ch = start(
        m, ["D1", "G90 G01 X0 Y0 Z0 C0 A0 F3000", TrafoSwitch(None, True), *PROT_BOX, "A90", "A0", "M30"]
    )
    lowest = 0.0

    def each(c: Channel) -> None:
        nonlocal lowest
        lowest = min(lowest, c.axis("Y").setpoint)

    run(m, ch, each=each)
    assert errors(m) == [], list(m.alarm_history)
    assert lowest == pytest.approx(-TOOL_MM)  # the Y axis was deep inside the area

    m = machine()
    ch = start(m, ["D1", "G90 G01 X0 Y0 Z0 C0 A0 F3000", TrafoSwitch(None, True), *PROT_BOX, "Y-60", "M30"])
    run(m, ch)
    assert errors(m), "the tip entering the protection area is refused"
    assert ch.tool_tip(ch.setpoints())[1] > -40.0


@pytest.mark.req("K-05")
def test_collision_monitoring_sees_the_swinging_axis() -> None:
    """FCT-C3 on the pair X / W (W at 190 mm, minimum distance 20 mm): the tool tip stays at X 80 while a
    CB head turns B towards 90°, which swings the X axis (the head 100 mm up the tool) towards 180 mm; the
    pair's distance falls below 20 mm by the X axis: the move is refused, the tip never came near W."""
    names = ("X", "Y", "Z", "C", "B", "W")
    axes = [
        AxisConfig(
            number=i + 1,
            name=n,
            axis_type="R" if n in "CB" else "T",
            swe_neg=-10_000_000,
            swe_pos=10_000_000,
            a_max=2000.0,
            **(
                {"achs_mode": 0x8001}
                if n == "X"
                else {
                    "achs_mode": 0x8001,
                    "coll_check_ax_nr": 1,
                    "coll_offset": 200_000,
                    "start_position": 1_900_000,
                }
                if n == "W"
                else {}
            ),  # type: ignore[arg-type]
        )
        for i, n in enumerate(names)
    ]
    cb_head = KinematicEntry(
        id=8,
        type=91,
        rtcp=1,
        zero_orientation=(0, 0, 1),
        zero_position=(0, 0, 0),
        axes=[
            KinematicAxis(type=1, orientation=(1, 0, 0)),
            KinematicAxis(type=1, orientation=(0, 1, 0)),
            KinematicAxis(type=1, orientation=(0, 0, 1)),
            KinematicAxis(type=2, orientation=(0, 0, 1)),
            KinematicAxis(type=2, orientation=(0, 1, 0)),
        ],
    )
    ch_config = ChannelConfig(
        axes=list(names),
        kinematics=[cb_head],
        kinematik_id=8,
        tools=[ToolEntry(number=1, length=round(TOOL_MM * 10_000))],
    )
    m = Machine(MachineConfig(axes=axes, channels=[ch_config]))
    ch = m.channel(1)
    ch.load_program("M30\n")
    ch.start()
    ch.decoder.blocks = _feed(
        names, ["D1", "G90 G01 X80 Y0 Z0 C0 B0 F3000", TrafoSwitch(None, True), "B90", "M30"]
    )
    tip_x: list[float] = []
    run(m, ch, each=lambda c: tip_x.append(c.tool_tip(c.setpoints())[0]) if c.kinematic is not None else None)
    found = [a for a in m.alarm_history if a.severity == "error"]
    assert found, "the swinging X axis comes within 20 mm of W"
    assert max(tip_x) == pytest.approx(80.0, abs=1e-9)
    assert ch.axis("X").setpoint < 170.0 + 1e-6
