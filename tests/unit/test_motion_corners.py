"""Chamfers and roundings G301/G302 (issue 33; PM 206609163, 206615051, 206621707): the corner replaced by
a line or an arc of the programmed size, as the path checks and the axes see it. The geometry is held to an
oracle (property tests); the manual's examples run; the kernel's IDs for the mistakes."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hli_server.commands.check import check_program
from hli_server.engine import Machine
from hli_server.engine.geometry import ArcSegment, LineSegment, Point, Segment, arc_from_centre
from hli_server.engine.path.corners import CHAMFER, ROUNDING, CornerError, insert_corner
from hli_server.engine.programs import MemoryLibrary
from tests.unit.areas.test_area_programs import square
from tests.unit.engine_helpers import mill, mill_config, positions, run
from tests.unit.test_batch_check import _batch_settings

TOL = 1e-6


def alarms(machine: Machine) -> list[int]:
    return [a.number for a in machine.alarm_history]


def joined(pieces: list[Segment]) -> bool:
    return all(math.dist(a.end, b.start) < TOL for a, b in itertools.pairwise(pieces))


def unit(v: Point) -> Point:
    n = math.sqrt(sum(x * x for x in v))
    return tuple(x / n for x in v)


def line_distance(p: Point, a: Point, direction: Point) -> float:
    """Distance of ``p`` from the infinite line through ``a`` along ``direction`` (a unit vector)."""
    d = [pk - ak for pk, ak in zip(p, a, strict=True)]
    along = sum(dk * uk for dk, uk in zip(d, direction, strict=True))
    return math.sqrt(max(0.0, sum(dk * dk for dk in d) - along * along))


# --- the geometry against an oracle ---------------------------------------------------------------------
angles = st.floats(0.2, math.pi - 0.2)
lengths = st.floats(20.0, 200.0)
sizes = st.floats(0.5, 8.0)


@pytest.mark.req("LT-06")
@settings(max_examples=150, derandomize=True, deadline=None)
@given(
    heading=st.floats(-math.pi, math.pi),
    turn=angles,
    left=st.booleans(),
    l1=lengths,
    l2=lengths,
    size=sizes,
    kind=st.sampled_from([CHAMFER, ROUNDING]),
)
def test_lines_in_a_plane(
    heading: float, turn: float, left: bool, l1: float, l2: float, size: float, kind: int
) -> None:
    """Chamfer: both ends at I from the corner, on the lines. Rounding: an arc of radius I whose centre is
    I from both lines, tangent to both at its ends, inside the corner (nearer the corner's bisector side)."""
    c = (10.0, -5.0, 3.0)
    u = (math.cos(heading), math.sin(heading), 0.0)
    h2 = heading + (turn if left else -turn)
    v = (math.cos(h2), math.sin(h2), 0.0)
    pre = LineSegment(tuple(ck - l1 * uk for ck, uk in zip(c, u, strict=True)), c)
    post = LineSegment(c, tuple(ck + l2 * vk for ck, vk in zip(c, v, strict=True)))
    needs = size if kind == CHAMFER else size * math.tan(turn / 2.0)
    if needs > min(l1, l2):
        with pytest.raises(CornerError) as refused:
            insert_corner(pre, post, kind, size)
        assert refused.value.alarm == 916003
        return
    result = insert_corner(pre, post, kind, size)
    assert result is not None
    head, middle, tail = result
    assert joined([head, *middle, tail])
    assert head.start == pre.start
    assert tail.end == post.end
    p1, p2 = middle[0].start, middle[-1].end
    assert line_distance(p1, c, u) < TOL
    assert line_distance(p2, c, v) < TOL
    if kind == CHAMFER:
        assert math.dist(p1, c) == pytest.approx(size, abs=TOL)
        assert math.dist(p2, c) == pytest.approx(size, abs=TOL)
        assert isinstance(middle[0], LineSegment)
        return
    [arc] = middle
    assert isinstance(arc, ArcSegment)
    assert arc.radius == pytest.approx(size, rel=1e-9)
    centre = (*arc.centre, c[2])
    assert line_distance(centre, c, u) == pytest.approx(size, abs=TOL)
    assert line_distance(centre, c, v) == pytest.approx(size, abs=TOL)
    # tangential: the arc leaves the pre-block and enters the post-block in their directions
    assert math.dist(unit(arc.direction_at(0.0)), u) < 1e-6
    assert math.dist(unit(arc.direction_at(arc.length)), v) < 1e-6
    assert math.dist(p1, c) == pytest.approx(size * math.tan(turn / 2.0), rel=1e-6)


@pytest.mark.req("LT-06")
@settings(max_examples=80, derandomize=True, deadline=None)
@given(u=st.tuples(*[st.floats(-1, 1)] * 3), v=st.tuples(*[st.floats(-1, 1)] * 3), size=sizes)
def test_a_rounding_of_a_corner_in_space_is_chords_of_its_arc(
    u: tuple[float, float, float], v: tuple[float, float, float], size: float
) -> None:
    nu, nv = math.sqrt(sum(x * x for x in u)), math.sqrt(sum(x * x for x in v))
    if nu < 0.2 or nv < 0.2:
        return
    u1, v1 = unit(u), unit(v)
    cos_turn = sum(a * b for a, b in zip(u1, v1, strict=True))
    if not -0.95 < cos_turn < 0.98:
        return
    c = (0.0, 0.0, 0.0)
    pre = LineSegment(tuple(-300.0 * x for x in u1), c)
    post = LineSegment(c, tuple(300.0 * x for x in v1))
    result = insert_corner(pre, post, ROUNDING, size)
    assert result is not None
    head, middle, tail = result
    assert joined([head, *middle, tail])
    turn = math.acos(cos_turn)
    w = unit(tuple(b - a for a, b in zip(u1, v1, strict=True)))
    centre = tuple(size / math.cos(turn / 2.0) * x for x in w)
    for piece in middle:  # an arc (the corner lies in a plane of two axes), or chords within 5 µm of it
        assert math.dist(piece.start, centre) == pytest.approx(size, abs=1e-9)
        assert math.dist(piece.end, centre) == pytest.approx(size, abs=1e-9)
        if isinstance(piece, ArcSegment):
            assert piece.radius == pytest.approx(size)
            continue
        mid = tuple(0.5 * (a + b) for a, b in zip(piece.start, piece.end, strict=True))
        assert size - math.dist(mid, centre) <= 0.005 + 1e-9


def _arc(start: Point, centre: tuple[float, float], sweep: float) -> ArcSegment:
    a0 = math.atan2(start[1] - centre[1], start[0] - centre[0])
    r = math.hypot(start[0] - centre[0], start[1] - centre[1])
    end = (centre[0] + r * math.cos(a0 + sweep), centre[1] + r * math.sin(a0 + sweep), start[2])
    arc, _ = arc_from_centre(start, end, (0, 1), centre, clockwise=sweep < 0)
    return arc


@pytest.mark.req("LT-06")
@settings(max_examples=200, derandomize=True, deadline=None)
@given(
    first_arc=st.booleans(),
    second_arc=st.booleans(),
    r1=st.floats(30.0, 150.0),
    r2=st.floats(30.0, 150.0),
    s1=st.sampled_from([1.0, -1.0]),
    s2=st.sampled_from([1.0, -1.0]),
    turn=st.floats(0.3, 2.6),
    left=st.booleans(),
    size=st.floats(0.5, 6.0),
    kind=st.sampled_from([CHAMFER, ROUNDING]),
)
def test_lines_and_circles_in_their_plane(
    first_arc: bool,
    second_arc: bool,
    r1: float,
    r2: float,
    s1: float,
    s2: float,
    turn: float,
    left: bool,
    size: float,
    kind: int,
) -> None:
    """A corner at the origin between a line or an arc and a line or an arc. Chamfer: chords of I from the
    corner on both elements. Rounding: centre at I from both elements (the equidistants), its ends on the
    elements and tangent to them."""
    c: Point = (0.0, 0.0, 0.0)
    t_in = (1.0, 0.0)
    h = turn if left else -turn
    t_out = (math.cos(h), math.sin(h))
    pre: Segment
    post: Segment
    if first_arc:  # an arc of 0.6 rad ending at c with tangent t_in; its centre left (s1 > 0) or right
        centre = (0.0, s1 * r1)
        start_angle = math.atan2(-centre[1], -centre[0]) - s1 * 0.6
        start = (centre[0] + r1 * math.cos(start_angle), centre[1] + r1 * math.sin(start_angle), 0.0)
        pre = _arc(start, centre, s1 * 0.6)
    else:
        pre = LineSegment((-60.0, 0.0, 0.0), c)
    if second_arc:
        n = (-t_out[1] * s2, t_out[0] * s2)
        post = _arc(c, (n[0] * r2, n[1] * r2), s2 * 0.6)
    else:
        post = LineSegment(c, (60.0 * t_out[0], 60.0 * t_out[1], 0.0))
    assert math.dist(unit(pre.direction_at(pre.length))[:2], t_in) < 1e-6
    assert math.dist(unit(post.direction_at(0.0))[:2], t_out) < 1e-6
    try:
        result = insert_corner(pre, post, kind, size)
    except CornerError as exc:
        refused = exc.alarm  # the element does not fit: a reversal (never silently)
    else:
        refused = 0
    if refused:
        assert refused == 916003
        return
    assert result is not None
    head, middle, tail = result
    assert joined([head, *middle, tail])
    [element] = middle
    p1, p2 = element.start, element.end
    assert _on(pre, p1)
    assert _on(post, p2)
    if kind == CHAMFER:
        assert math.dist(p1, c) == pytest.approx(size, abs=1e-6)
        assert math.dist(p2, c) == pytest.approx(size, abs=1e-6)
        return
    assert isinstance(element, ArcSegment)
    assert element.radius == pytest.approx(size, rel=1e-6)
    assert math.dist(unit(element.direction_at(0.0)), unit(head.direction_at(head.length))) < 1e-5
    assert math.dist(unit(element.direction_at(element.length)), unit(tail.direction_at(0.0))) < 1e-5


def _on(seg: Segment, p: Point) -> bool:
    if isinstance(seg, LineSegment):
        d = unit(tuple(b - a for a, b in zip(seg.start, seg.end, strict=True)))
        along = sum((pk - ak) * dk for pk, ak, dk in zip(p, seg.start, d, strict=True))
        return line_distance(p, seg.start, d) < 1e-6 and -1e-6 <= along <= seg.length + 1e-6
    return abs(math.hypot(p[0] - seg.centre[0], p[1] - seg.centre[1]) - seg.radius) < 1e-6


# --- the manual's examples and the machine's path ---------------------------------------------------------
def _path(program: str) -> tuple[Machine, list[tuple[float, float]]]:
    m = mill()
    points: list[tuple[float, float]] = []

    def each(machine: Machine) -> None:
        x, y = machine.axes[0].setpoint, machine.axes[1].setpoint
        points.append((x, y))

    run(m, program, each=each)
    return m, points


@pytest.mark.req("LT-06")
def test_the_manuals_chamfer_between_two_lines_206615051() -> None:
    m, points = _path("N5 G01 X0 Y0 F6000\nN10 G91 G01 X80 Y-40\nN20 G301 I40\nN30 G01 X80 Y40\nM30\n")
    assert alarms(m) == []
    assert positions(m)["X"] == pytest.approx(160.0)
    corner = (80.0, -40.0)
    # the chamfer's middle is 40 / sqrt(5) from the corner: the axes never come nearer
    assert min(math.dist(p, corner) for p in points) == pytest.approx(40.0 / math.sqrt(5.0), abs=0.01)


@pytest.mark.req("LT-06")
def test_the_manuals_rounding_between_two_lines_206621707() -> None:
    m, points = _path("N5 G01 X0 Y0 F6000\nN10 G91 G01 X60\nN20 G302 I30\nN30 X-40 Y-55\nM30\n")
    assert alarms(m) == []
    u, v = (1.0, 0.0), unit((-40.0, -55.0))
    turn = math.acos(u[0] * v[0] + u[1] * v[1])
    expected = 30.0 / math.cos(turn / 2.0) - 30.0  # corner to the arc's middle
    assert min(math.dist(p, (60.0, 0.0)) for p in points) == pytest.approx(expected, abs=0.01)


@pytest.mark.req("LT-06")
def test_the_manuals_chamfer_between_two_arcs_and_roundings_between_circles_run() -> None:
    for program in (
        "N5 G01 X0 Y0 F6000\nN10 G91 G03 I50 X95 Y-15\nN20 G301 I30\nN30 G03 X80 Y-5 I40 J15\nM30\n",
        "N5 G01 X0 Y0 F6000\nN10 G91 G02 X80 I40\nN20 G302 I40\nN30 G02 X50 I25 J-15\nM30\n",
        "N5 G01 X0 Y0 F6000\nN10 G91 G02 X80 I40\nN20 G302 I5\nN30 G02 X60 Y35 I20 J35\nM30\n",
    ):
        m, _ = _path(program)
        assert [a for a in alarms(m) if a != 911001] == [], program


@pytest.mark.req("LT-06")
def test_the_manuals_direction_reversal_is_an_error() -> None:
    """PM 206615051, example 3: a chamfer of I30 after a block of 20 mm reverses it."""
    m, _ = _path("N10 G91 G01 X20 Y-10 F6000\nN20 X20\nN30 G301 I30\nN40 X60 Y50\nM30\n")
    [alarm] = m.alarm_history
    assert (alarm.number, alarm.block) == (916003, "N40")
    assert positions(m)["X"] == pytest.approx(20.0)  # the path stops where the corner's pre-block begins


@pytest.mark.req("LT-06")
def test_the_size_is_stored_and_a_g301_in_a_motion_block_is_at_its_end() -> None:
    stored, _ = _path("G01 X0 Y0 F6000\nX50\nG302 I5\nY50\nX0\nG302\nY0\nM30\n")
    same, _ = _path("G01 X0 Y0 F6000\nX50 G302 I5\nY50\nX0 G302\nY0\nM30\n")
    assert alarms(stored) == alarms(same) == []
    assert stored.cycle == same.cycle


@pytest.mark.req("LT-06")
def test_the_look_ahead_sees_past_comment_lines() -> None:
    m, points = _path("G01 X0 Y0 F6000\nX50\n(the corner)\n\n; rounded\nG302 I5\nY50\nM30\n")
    assert alarms(m) == []
    assert min(math.dist(p, (50.0, 0.0)) for p in points) == pytest.approx(5.0 * (math.sqrt(2) - 1), abs=0.01)


@pytest.mark.req("LT-06")
@pytest.mark.parametrize(
    ("program", "alarm"),
    [
        ("G01 X0 Y0 F6000\nX10\nG301\nY10\nM30\n", 20012),  # DG 250528139
        ("G01 X0 Y0 F6000\nX10\nG302 I0\nY10\nM30\n", 20012),
        ("G01 X0 Y0 F6000\nX10\nG301 I10 G302\nY50\nM30\n", 20130),  # DG 250885003
        ("G01 X0 Y0 F6000\nX10\nG301 I-1\nY10\nM30\n", 20800),
        ("G01 X0 Y0 F6000 D0\nV.G.WZR = 2\nG41 X10\nX20\nG301 I1\nY10\nG40 Y20\nM30\n", 910110),
    ],
)
def test_the_mistakes(program: str, alarm: int) -> None:
    m = mill()
    run(m, program)
    assert [a for a in alarms(m) if a >= 20000] == [alarm]


@pytest.mark.req("LT-06")
def test_control_statements_between_are_looked_past_a_call_is_not() -> None:
    m, points = _path("G01 X0 Y0 F6000\nX10\n$IF 1\nG302 I1\n$ENDIF\nY10\nM30\n")
    assert alarms(m) == []
    assert min(math.dist(p, (10.0, 0.0)) for p in points) == pytest.approx(math.sqrt(2) - 1, abs=0.01)
    m = Machine(mill_config(), programs=MemoryLibrary({"sub.nc": "G302 I1\nM17\n"}))
    run(m, "G01 X0 Y0 F6000\nX10\nL sub.nc\nY10\nM30\n")
    [alarm] = m.alarm_history
    assert alarm.number == 910110
    assert "right after the motion block" in alarm.message


@pytest.mark.req("LT-06")
def test_without_a_motion_before_it_the_kernel_warns_20351_and_twice_20701() -> None:
    m = mill()
    run(m, "G301 I5\nG01 X10 Y0 F6000\nG301 I2\nG302 I3\nY10\nM30\n")
    assert alarms(m) == [20351, 20701]
    assert positions(m)["Y"] == pytest.approx(10.0)


# --- the monitors see the inserted element ------------------------------------------------------------------
def _areas(kind: str, x0: float, y0: float, x1: float, y1: float) -> str:
    return square(1, x0, y0, x1, y1, kind) + "#CONTROL AREA ON ALL\n"


@pytest.mark.req("LT-06", "C14-14")
@pytest.mark.parametrize("geometry_only", [False, True])
def test_a_protection_area_in_the_corner_is_passed_by_the_rounding_and_hit_by_the_sharp_corner(
    geometry_only: bool,
) -> None:
    area = _areas("PROT", 99.5, -0.5, 100.5, 0.5)
    moves = (
        "".join(f"X{k} Y0\n" for k in range(1, 90))
        + "X100 Y0\n{corner}Y60\n"
        + "".join(f"X{100 - k * 0.5} Y60\n" for k in range(1, 80))
    )
    text = "G01 X0 Y0 F6000\n" + area + moves + "M30\n"
    for exact in (True, False):
        with _batch_settings(exact, small=16):
            sharp = check_program(Machine(mill_config()), text.format(corner=""), geometry_only=geometry_only)
            rounded = check_program(
                Machine(mill_config()), text.format(corner="G302 I5\n"), geometry_only=geometry_only
            )
        assert [a.number for a in sharp.alarms] == [912001]
        assert [a.number for a in rounded.alarms] == [], rounded.alarms
        assert rounded.final_position["X"] == pytest.approx(60.5)


@pytest.mark.req("LT-06", "C14-14")
def test_a_protection_area_the_chamfer_enters_is_refused_naming_the_g301_block() -> None:
    area = _areas("PROT", 93.0, 3.0, 96.0, 6.0)  # inside the corner: the sharp corner misses it
    text = "G01 X0 Y0 F6000\n" + area + "N10 X100 Y0\nN20 G301 I10\nN30 X100 Y50\nM30\n"
    sharp = check_program(Machine(mill_config()), text.replace("N20 G301 I10\n", ""))
    assert sharp.alarms == []
    chamfered = check_program(Machine(mill_config()), text)
    [alarm] = chamfered.alarms
    assert (alarm.number, alarm.block) == (912001, "N20")


@pytest.mark.req("LT-06")
@pytest.mark.parametrize("chunk", [None, 200])
def test_the_batch_geometry_check_inserts_the_same_corners_as_the_exact_one(chunk: int | None) -> None:
    """Plain stretches and the blocks of a loop before a G301/G302: the last of them is decoded exactly
    (held for the corner), also where the G301 line opens the next chunk of the text."""
    from hli_server.configuration import load_machine
    from tests.unit.test_batch_check import assert_same

    config = load_machine(None)
    plain = "".join(f"G01 X{k} Y{(k % 2) * 0.25}\n" for k in range(1, 60))
    loop = "$FOR P1 = 1, 40\nG01 X[70 + P1 * 10] Y[40 + [P1 MOD 2] * 0.25]\n$ENDFOR\n"
    text = (
        "G01 X0 Y0 F6000\n"
        + plain
        + "X70 Y0\nG301 I3\nX70 Y40\n"
        + loop
        + "G302 I4 F3000\nX470 Y80\nX0 Y80\n"
        "G302 I2\nX0 Y0\nM30\n"
    )
    result = assert_same(config, text, chunk=chunk, small=16)
    assert result.final_position["X"] == pytest.approx(0.0)
    assert [a.number for a in result.alarms] == []


@pytest.mark.req("LT-06")
def test_frc_the_feed_of_the_inserted_element_is_accepted_with_one_warning() -> None:
    m, points = _path("G01 X0 Y0 F6000\nX50\n#FRC=500\nG302 I5\nY50\nM30\n")
    assert alarms(m) == [911041]
    assert min(math.dist(p, (50.0, 0.0)) for p in points) == pytest.approx(5.0 * (math.sqrt(2) - 1), abs=0.01)
