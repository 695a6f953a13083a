"""Coordinate systems and tools in the decoder (issue 24 items 2 and 4): #CS, #ACS, #ROTATION, D/T,
tool length, G40/G41/G42."""

from __future__ import annotations

import itertools
import math
from typing import Any

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from hli_server.engine.geometry import ArcSegment
from hli_server.engine.machine import Machine
from hli_server.engine.planner import Marker, MarkerKind, Motion
from schemas.config import AxisConfig, ChannelConfig, MachineConfig


def machine(**channel: Any) -> Machine:
    names = ["X", "Y", "Z"]
    axes = [
        AxisConfig(number=i + 1, name=n, swe_neg=-10_000_000, swe_pos=10_000_000) for i, n in enumerate(names)
    ]
    return Machine(MachineConfig(axes=axes, channels=[ChannelConfig(axes=names, **channel)]))


def decode(program: str, **channel: Any) -> tuple[list[Motion], Marker | None]:
    """Decode the whole program; the motions and the error marker (if any)."""
    m = machine(**channel)
    ch = m.channel(1)
    ch.interpreter.start(program, "t")
    ch.decoder.start(ch.interpreter, ch.setpoints())
    motions: list[Motion] = []
    for _ in range(10_000):
        items = ch.decoder.next_items()
        if not items:
            ch.interpreter.refill()
        for item in items:
            if isinstance(item, Motion):
                motions.append(item)
            elif item.kind is MarkerKind.ERROR:
                return motions, item
        if ch.decoder.finished:
            break
    return motions, None


def ends(motions: list[Motion]) -> list[tuple[float, ...]]:
    return [tuple(round(v, 6) for v in mo.segment.end) for mo in motions]


TOOLS = [{"number": 1, "length": 1_000_000, "radius": 50_000}, {"number": 2, "length": 0, "radius": 20_000}]


@pytest.mark.req("M-10")
def test_cs_on_translates_and_rotates() -> None:
    motions, err = decode(
        "%t\nN10 #CS ON [10, 20, 0, 0, 0, 90]\nN20 G01 X10 Y0 F1000\nN30 #CS OFF\nN40 X10 Y0\nM30\n"
    )
    assert err is None
    # in the CS rotated by 90° about Z and shifted by (10, 20): program (10, 0) is machine (10, 30)
    assert ends(motions)[0] == pytest.approx((10.0, 30.0, 0.0))
    assert ends(motions)[1] == pytest.approx((10.0, 0.0, 0.0))


@pytest.mark.req("M-10")
def test_cs_def_then_on_by_id_and_undefined_id() -> None:
    motions, err = decode("%t\n#CS DEF [2] [5, 0, 0]\n#CS ON [2]\nG01 X1 F100\n#CS OFF ALL\nX1\nM30\n")
    assert err is None
    assert [e[0] for e in ends(motions)] == pytest.approx([6.0, 1.0])
    _, err = decode("%t\n#CS ON [3]\nG01 X1 F100\nM30\n")
    assert err is not None
    assert err.payload.alarm == 20821


@pytest.mark.req("M-11")
def test_acs_below_zero_offset_and_cs_on_top() -> None:
    # ACS rotated 90°: the zero offset acts in the ACS' axes; the CS shifts in the workpiece system
    motions, err = decode(
        "%t\n#ACS ON [0, 0, 0, 0, 0, 90]\nG54\n#CS ON [1, 0, 0]\nG01 X1 Y0 F100\nM30\n",
        zero_offsets=[{"code": "G54", "offsets": {"X": 100_000}}],
    )
    assert err is None
    # program (1,0) -> CS (2,0) -> + G54 10 mm -> (12, 0) -> ACS 90° -> machine (0, 12)
    assert ends(motions)[0] == pytest.approx((0.0, 12.0, 0.0))


@pytest.mark.req("M-12")
def test_rotation_about_centre_and_plane_change_deselects() -> None:
    motions, err = decode(
        "%t\n#ROTATION ON [ANGLE=90 CENTER1=10 CENTER2=0]\nG01 X20 Y0 F100\nG18\nG17\nX20 Y0\nM30\n"
    )
    assert err is None
    assert ends(motions)[0] == pytest.approx((10.0, 10.0, 0.0))
    assert ends(motions)[1] == pytest.approx((20.0, 0.0, 0.0))


@pytest.mark.req("M-13")
def test_cs_add_stack_example() -> None:
    # the manual's #CS ADD example (1037259147): three CS linked; the top is PCS
    motions, err = decode(
        "%t\nN10 #CS ADD [ICS] [10,10,0,0,0,45]\nN20 #CS ADD [WCS] [15,20,0,0,0,0]\n"
        "N30 #CS ADD [PCS] [10,15,0,0,0,5]\nG01 X0 Y0 F100\nM30\n"
    )
    assert err is None
    c, s = math.cos(math.radians(45)), math.sin(math.radians(45))
    # PCS origin in WCS (10,15) -> ICS (25, 35) -> rotated 45° + (10, 10)
    x, y = 25.0, 35.0
    assert ends(motions)[0][:2] == pytest.approx((10 + c * x - s * y, 10 + s * x + c * y))


@pytest.mark.req("M-10")
def test_arc_under_rotated_cs_stays_an_arc() -> None:
    motions, err = decode("%t\n#CS ON [0, 0, 0, 0, 0, 90]\nG01 X10 Y0 F100\nG03 X0 Y10 I-10 J0\nM30\n")
    assert err is None
    arc = motions[1].segment
    assert isinstance(arc, ArcSegment)
    assert arc.centre == pytest.approx((0.0, 0.0))
    assert arc.end[:2] == pytest.approx((-10.0, 0.0))
    assert arc.sweep > 0


@pytest.mark.req("M-14")
def test_tool_length_applied_at_next_absolute_tool_axis_move() -> None:
    motions, err = decode("%t\nG01 X0 Y0 Z0 F100\nD1\nX10\nZ5\nD0\nZ5\nM30\n", tools=TOOLS)
    assert err is None
    # D1 alone does not move Z (P-CHAN-00100 = 0); Z5 with D1: the axis goes to 5 + 100
    assert ends(motions) == [(10.0, 0.0, 0.0), (10.0, 0.0, 105.0), (10.0, 0.0, 5.0)]


@pytest.mark.req("M-14")
def test_unknown_d_is_an_error() -> None:
    _, err = decode("%t\nD7\nM30\n", tools=TOOLS)
    assert err is not None
    assert err.payload.alarm == 916001


@pytest.mark.req("M-16")
def test_g41_square_outer_corners_g25() -> None:
    prog = "%t\nG01 X-10 Y0 F1000\nD2 G41\nX0 Y0\nX10\nY10\nX0\nY0\nG40 X-10\nM30\n"
    motions, err = decode(prog, tools=TOOLS)
    assert err is None
    # ccw square, tool on the left = inside: inner corners at (2, 2) (8, 2) (8, 8) (2, 8)
    pts = ends(motions)
    for corner in [(8.0, 2.0), (8.0, 8.0), (2.0, 8.0)]:
        assert any(p[:2] == pytest.approx(corner) for p in pts), pts
    assert pts[-1][:2] == pytest.approx((-10.0, 0.0))


@pytest.mark.req("M-17")
def test_g42_outer_corners_with_g26_arcs() -> None:
    prog = "%t\nG01 X-10 Y0 F1000\nD2 G42 G26\nX0 Y0\nX10\nY10\nX0\nY0\nG40 X-10\nM30\n"
    motions, err = decode(prog, tools=TOOLS)
    assert err is None
    arcs = [mo.segment for mo in motions if isinstance(mo.segment, ArcSegment)]
    assert len(arcs) >= 3
    assert all(a.radius == pytest.approx(2.0) for a in arcs)


@pytest.mark.req("M-18")
def test_radius_too_large_for_inside_arc_is_90017() -> None:
    prog = "%t\nG01 X0 Y-5 F1000\nD2 G41\nX0 Y0\nG03 X0 Y2 I0 J1\nM30\n"  # radius 1, tool left of ccw arc
    _, err = decode(prog, tools=TOOLS)
    assert err is not None
    assert err.payload.alarm == 90017


@pytest.mark.req("M-18")
def test_selection_in_a_circle_is_90008() -> None:
    _, err = decode("%t\nG01 X0 Y0 F1000\nD2 G41\nG02 X10 Y0 I5 J0\nM30\n", tools=TOOLS)
    assert err is not None
    assert err.payload.alarm == 90008


@pytest.mark.req("M-18")
def test_slot_narrower_than_tool_is_a_contour_violation() -> None:
    # a 1 mm step inward with a 2 mm tool: the compensated middle block would run backwards
    prog = "%t\nG01 X0 Y0 F1000\nD2 G41\nX10 Y0\nY1\nX11\nY10\nG40 X20\nM30\n"
    _, err = decode(prog, tools=TOOLS)
    assert err is not None
    assert err.payload.alarm == 916000


def _distance_to_polyline(p: tuple[float, float], pts: list[tuple[float, float]]) -> float:
    best = math.inf
    for (ax, ay), (bx, by) in itertools.pairwise(pts):
        dx, dy = bx - ax, by - ay
        n2 = dx * dx + dy * dy
        t = 0.0 if n2 == 0 else max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / n2))
        best = min(best, math.hypot(p[0] - ax - t * dx, p[1] - ay - t * dy))
    return best


@pytest.mark.req("M-17")
@settings(max_examples=60, deadline=None)
@given(
    turns=st.lists(st.floats(-150.0, 150.0), min_size=2, max_size=7),
    lengths=st.lists(st.floats(12.0, 40.0), min_size=8, max_size=8),
    side=st.sampled_from([41, 42]),
    transition=st.sampled_from([25, 26]),
)
def test_compensated_path_stays_within_the_radius(
    turns: list[float], lengths: list[float], side: int, transition: int
) -> None:
    """Property: every point of the compensated path is at most r (G26) or r·√2 (G25) from the programmed
    path; a program the compensation refuses (a contour violation) is skipped."""
    heading = 0.0
    pts = [(0.0, 0.0)]
    for k, turn in enumerate([0.0, *turns]):
        heading += math.radians(turn)
        x, y = pts[-1]
        pts.append((x + lengths[k] * math.cos(heading), y + lengths[k] * math.sin(heading)))
    lines = "".join(f"X{x:.4f} Y{y:.4f}\n" for x, y in pts[1:-1])
    last = pts[-1]
    prog = f"%t\nG01 X0 Y0 F1000\nD2 G{side} G{transition}\n{lines}G40 X{last[0]:.4f} Y{last[1]:.4f}\nM30\n"
    motions, err = decode(prog, tools=TOOLS)
    assume(err is None)
    r = 2.0
    bound = r if transition == 26 else r * math.sqrt(2.0)
    programmed = [(round(x, 4), round(y, 4)) for x, y in pts]
    for mo in motions:
        seg = mo.segment
        for k in range(11):
            q = seg.point_at(seg.length * k / 10)
            assert _distance_to_polyline((q[0], q[1]), programmed) <= bound + 1e-6


@pytest.mark.req("M-10")
@pytest.mark.parametrize(
    ("components", "expected"),
    [
        # the manual's examples (208480907): gaps are 0, shortened lists are allowed
        ("[,,10,,,45]", (0.0, math.sqrt(2.0), 10.0)),
        ("[0,0,10,0,0,45]", (0.0, math.sqrt(2.0), 10.0)),
        ("[0,0,10]", (1.0, 1.0, 10.0)),
        ("[0,0,10,0,30]", (1.0 * math.cos(math.radians(30)), 1.0, 10.0 - math.sin(math.radians(30)))),
    ],
)
def test_cs_component_forms_of_the_manual(components: str, expected: tuple[float, float, float]) -> None:
    motions, err = decode(f"%t\n#CS ON {components}\nG01 X1 Y1 Z0 F100\nM30\n")
    assert err is None
    assert motions[0].segment.end == pytest.approx(expected)


@pytest.mark.req("M-10")
def test_cs_angle_out_of_range_is_20676() -> None:
    # the diagnosis page's own example: #CS ON [10,20,0,45,0,450]
    _, err = decode("%t\n#CS ON [10,20,0,45,0,450]\nG01 X1 F100\nM30\n")
    assert err is not None
    assert err.payload.alarm == 20676


@pytest.mark.req("M-10")
@pytest.mark.parametrize(
    "line",
    [
        "#CS",
        "#CS ON [1,2",
        "#CS ON [1,2,3,4,5,6,7]",
        "#CS MODE ON",
        "#ROTATION ON [FOO=1]",
        "#CS ADD [TOOLONGNAME] [1]",
        "#CS ON [1] X10",
        "#ACS ADD [A] [1]",
    ],
)
def test_malformed_coordinate_commands_are_precise_errors(line: str) -> None:
    _, err = decode(f"%t\n{line}\nM30\n")
    assert err is not None
    assert err.payload.alarm in {910110, 914000, 914015, 910105}, err.payload
    assert err.payload.params.get("line") == 2


@pytest.mark.req("M-16")
def test_line_arc_line_with_g41_outside_of_a_convex_arc() -> None:
    # a 10 mm half circle bulging to -y, run clockwise from (0,0) to (20,0); tool left = outside, radius 2
    prog = "%t\nG01 X-10 Y0 F1000\nD2 G41\nX0 Y0\nG02 X20 Y0 I10 J0\nG01 X30\nG40 X40\nM30\n"
    motions, err = decode(prog, tools=TOOLS)
    assert err is None
    arcs = [mo.segment for mo in motions if isinstance(mo.segment, ArcSegment)]
    assert len(arcs) == 1
    assert arcs[0].radius == pytest.approx(12.0)
    assert arcs[0].centre == pytest.approx((10.0, 0.0))
    assert motions[-1].segment.end[:2] == pytest.approx((40.0, 0.0))
    # the tool path is continuous
    for a, b in itertools.pairwise(motions):
        assert a.segment.end == pytest.approx(b.segment.start)


@pytest.mark.req("M-16")
def test_arc_inside_shrinks_by_the_radius_and_corners_meet() -> None:
    # counter-clockwise quarter circle radius 10 with the tool left (inside): radius 8
    prog = "%t\nG01 X10 Y-10 F1000\nD2 G41\nX10 Y0\nG03 X0 Y10 I-10 J0\nG01 X-10\nG40 X-10 Y20\nM30\n"
    motions, err = decode(prog, tools=TOOLS)
    assert err is None
    arcs = [mo.segment for mo in motions if isinstance(mo.segment, ArcSegment)]
    assert len(arcs) == 1
    assert arcs[0].radius == pytest.approx(8.0)
    for a, b in itertools.pairwise(motions):
        assert a.segment.end == pytest.approx(b.segment.start)


@pytest.mark.req("M-17")
def test_g25_inserts_lines_next_to_a_circle_at_an_outer_corner() -> None:
    # line +x then a ccw arc turning away to the right of the tool (G41: outer corner of 90°)
    prog = "%t\nG01 X-10 Y0 F1000\nD2 G41 G25\nX0 Y0\nX10\nG02 X20 Y-10 I0 J-10\nG01 G40 X30 Y-10\nM30\n"
    motions, err = decode(prog, tools=TOOLS)
    assert err is None
    kinds = ["arc" if isinstance(mo.segment, ArcSegment) else "line" for mo in motions]
    assert kinds.count("arc") == 1
    for a, b in itertools.pairwise(motions):
        assert a.segment.end == pytest.approx(b.segment.start)


@pytest.mark.req("M-18")
def test_two_circles_whose_equidistants_do_not_meet_are_90031() -> None:
    # found by a seeded search: with a 9 mm tool on the right the two compensated circles have no common point
    tools = [{"number": 9, "radius": 90_000}]
    prog = (
        "%t\nG01 X-10 Y0 F1000\nD9 G42\nX0 Y0\n"
        "G02 X8.659952 Y18.967213 I15.454018 J4.404649\n"
        "G03 X16.440994 Y4.067401 I17.836257 J-0.167105\n"
        "G01 G40 X26.441 Y4.0674\nM30\n"
    )
    _, err = decode(prog, tools=tools)
    assert err is not None
    assert err.payload.alarm == 90031
    # a smaller tool passes
    _, err = decode(prog, tools=[{"number": 9, "radius": 10_000}])
    assert err is None


@pytest.mark.req("M-14")
def test_tool_and_rotation_variables_read_in_program_order() -> None:
    prog = (
        "%t\nD2\n#ROTATION ON [ANGLE=30 CENTER1=1]\n"
        "$IF V.G.WZ_AKT.R == 2 && V.G.WZR == 2 && V.G.WZ_AKT.NR == 2 && V.G.ROT_ACTIVE == 1\n"
        "$IF V.G.ROT_ANGLE == 30 && V.G.ROT_CENTER1 == 1 && V.G.WZ_AKT.L == 0\nG01 X7 F100\n$ENDIF\n$ENDIF\n"
        "#ROTATION OFF\nD0\n$IF V.G.WZ_AKT.R == 0 && V.G.ROT_ACTIVE == 0\nG01 X9 Y0\n$ENDIF\nM30\n"
    )
    motions, err = decode(prog, tools=TOOLS)
    assert err is None
    assert len(motions) == 2
    assert motions[1].segment.end[:2] == pytest.approx((9.0, 0.0))


@pytest.mark.req("M-19")
def test_program_coordinates_read_back_through_the_frames() -> None:
    prog = (
        "%t\n#CS ON [10, 0, 0, 0, 0, 90]\nG01 X5 Y0 F100\n"
        "$IF ABS[V.A.PROG.X - 5] < 0.0001 && ABS[V.A.PROG.Y] < 0.0001\nG01 X5 Y3\n$ENDIF\nM30\n"
    )
    motions, err = decode(prog)
    assert err is None
    assert len(motions) == 2
    # the axes: program (5, 3) in the CS turned 90° and shifted 10 in X is machine (7, 5)
    assert motions[1].segment.end[:2] == pytest.approx((7.0, 5.0))


@pytest.mark.req("M-16")
def test_a_z_move_between_compensated_blocks_keeps_the_offset() -> None:
    prog = "%t\nG01 X-10 Y0 Z5 F1000\nD2 G41\nX0 Y0\nX10\nZ-1\nX20\nG40 X30 Y10\nM30\n"
    motions, err = decode(prog, tools=TOOLS)
    assert err is None
    z_moves = [mo.segment for mo in motions[1:] if mo.segment.start[2] != mo.segment.end[2]]
    assert len(z_moves) == 1
    assert z_moves[0].start[:2] == pytest.approx((10.0, 2.0))  # perpendicular at the end of X10
    assert z_moves[0].end == pytest.approx((10.0, 2.0, -1.0))
    for a, b in itertools.pairwise(motions):
        assert a.segment.end == pytest.approx(b.segment.start)
    assert motions[-1].segment.end == pytest.approx((30.0, 10.0, -1.0))


@pytest.mark.req("M-10")
def test_circle_in_a_tilted_cs_is_refused() -> None:
    _, err = decode("%t\n#CS ON [0, 0, 0, 30, 0, 0]\nG01 X10 Y0 F100\nG03 X0 Y10 I-10 J0\nM30\n")
    assert err is not None
    assert err.payload.alarm == 910110


@pytest.mark.req("M-14")
def test_without_a_tool_table_d_words_select_zero_data() -> None:
    motions, err = decode("%t\nT1 D1 M6\nG01 X10 Z5 F100\nM30\n")
    assert err is None
    assert motions[0].segment.end == pytest.approx((10.0, 0.0, 5.0))


@pytest.mark.req("M-10")
def test_g92_under_a_cs_keeps_the_cs() -> None:
    motions, err = decode("%t\n#CS ON [10, 0, 0, 0, 0, 90]\nG01 X5 Y0 F100\nG92 X0\nX1\nM30\n")
    assert err is None
    # X5 in the CS: machine (10, 5); G92 X0 there; X1 is 1 mm further along the CS' X (machine +Y)
    assert ends(motions)[0] == pytest.approx((10.0, 5.0, 0.0))
    assert ends(motions)[1] == pytest.approx((10.0, 6.0, 0.0))


@pytest.mark.req("M-16")
def test_manual_example_reaction_on_contour_change() -> None:
    """The programming manual's example "Reaction on contour change" (207823755), run as written:
    V.G.WZR sets the radius, G41 -> G42 without G40 is a deselection and a selection."""
    prog = (
        "%t\nN05 G01 Y10 F100 G41 V.G.WZR=2\nN10 X20 Y25\nN20 X40 G42\nN30 X60 Y10\nN40 X0 Y0 G40\nN50 M30\n"
    )
    motions, err = decode(prog)
    assert err is None
    for a, b in itertools.pairwise(motions):
        assert a.segment.end == pytest.approx(b.segment.start)
    programmed = [(0.0, 0.0), (0.0, 10.0), (20.0, 25.0), (40.0, 25.0), (60.0, 10.0), (0.0, 0.0)]
    for mo in motions[1:-1]:
        for k in range(11):
            q = mo.segment.point_at(mo.segment.length * k / 10)
            assert _distance_to_polyline((q[0], q[1]), programmed) <= 2.0 * math.sqrt(2.0) + 1e-6
    # N10 runs left of its direction (+x, +y): the tool is above the programmed line
    n10 = next(mo for mo in motions if mo.block.number == 10)
    assert n10.segment.end[1] > 25.0
    # N30 runs right of its direction (+x, -y): the tool is below-left of the programmed line
    n30 = [mo for mo in motions if mo.block.number == 30]
    mid = n30[0].segment.point_at(n30[0].segment.length / 2)
    assert mid[1] < 25.0 - 15.0 * (mid[0] - 40.0) / 20.0 - 1.9
    assert motions[-1].segment.end[:2] == pytest.approx((0.0, 0.0))
