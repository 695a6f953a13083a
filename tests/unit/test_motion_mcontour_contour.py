"""Polynomial contouring (issue 24 item 3, M-20..M-26): the transition model, the manual's examples
stepped cycle by cycle, the area checks on the blended path (FCT-C14 section 2.3), the warnings and
errors of #CONTOUR MODE / #HSC / #SPLINE."""

from __future__ import annotations

import itertools
import math
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hli_server.engine.geometry import ArcSegment, LineSegment, Segment, arc_from_centre
from hli_server.engine.nc.blocks import Block
from hli_server.engine.path.contour import (
    CHORD_TOLERANCE,
    Contour,
    ContourSettings,
    Piece,
    distance_to_path,
)
from schemas.wire import ProgramState
from tests.fuzz import count, seed_for
from tests.unit.areas.helpers import alarm_ids, errors, make_machine, only_alarm

BLOCK = Block(1, 10, "N10")
DEV = ContourSettings(path_dev=1.0)


def _emit(segments: list[Segment], settings: ContourSettings | None = DEV) -> list[Piece]:
    stage = Contour()
    out: list[Piece] = []
    for k, seg in enumerate(segments):
        last = k == len(segments) - 1
        out += stage.push(Piece(seg, BLOCK, feed=6000.0, blend=None if last else settings))
    return out + stage.flush()


def _samples(pieces: list[Piece], per: int = 8) -> list[tuple[float, ...]]:
    pts = []
    for p in pieces:
        for k in range(per + 1):
            pts.append(p.segment.point_at(p.segment.length * k / per))
    return pts


def _independent_departure(points: list[tuple[float, ...]], path: list[Segment]) -> float:
    """The largest distance of ``points`` from ``path``, measured independently of the stage's own
    measure: the path sampled densely (arcs by 2000 chords, sagitta below 3e-5 mm here), numpy."""
    dense: list[tuple[float, ...]] = [path[0].start]
    for seg in path:
        n = 1 if isinstance(seg, LineSegment) else 2000
        dense += [seg.point_at(seg.length * k / n) for k in range(1, n + 1)]
    a, b = np.array(dense[:-1]), np.array(dense[1:])
    ab = b - a
    den = np.maximum((ab * ab).sum(axis=1), 1e-300)
    worst = 0.0
    for p in points:
        q = np.array(p)
        t = np.clip(((q - a) * ab).sum(axis=1) / den, 0.0, 1.0)
        d = np.sqrt((((a + t[:, None] * ab) - q) ** 2).sum(axis=1)).min()
        worst = max(worst, float(d))
    return worst


def _continuous(pieces: list[Piece], start: tuple[float, ...], end: tuple[float, ...]) -> None:
    assert math.dist(pieces[0].segment.start, start) < 1e-9
    for a, b in itertools.pairwise(pieces):
        assert math.dist(a.segment.end, b.segment.start) < 1e-9
    assert math.dist(pieces[-1].segment.end, end) < 1e-9


# --- the transition model -------------------------------------------------------------------------------
@pytest.mark.req("M-20")
def test_line_line_corner_deviation_is_path_dev_and_the_blocks_are_shortened_symmetrically() -> None:
    segs = [
        LineSegment((0.0, 0.0, 0.0), (100.0, 0.0, 0.0)),
        LineSegment((100.0, 0.0, 0.0), (100.0, 100.0, 0.0)),
    ]
    out = _emit(segs)
    _continuous(out, (0.0, 0.0, 0.0), (100.0, 100.0, 0.0))
    head, *chords, tail = out
    assert all(p.transition for p in chords)
    assert not head.transition
    assert not tail.transition
    d_pre = 100.0 - head.segment.end[0]
    d_post = tail.segment.start[1]
    assert d_pre == pytest.approx(d_post, rel=1e-9)
    # d = 8 dev' / (3 sin(theta/2)) with dev' = PATH_DEV less the chord tolerance
    assert d_pre == pytest.approx(8 * (1.0 - CHORD_TOLERANCE) / (3 * math.sin(math.pi / 4)), rel=1e-6)
    # the interim point (the middle support point) is PATH_DEV (less the chord tolerance) from the corner
    interim = chords[len(chords) // 2].segment.start
    assert math.dist(interim, (100.0, 0.0, 0.0)) == pytest.approx(1.0 - CHORD_TOLERANCE, abs=1e-6)
    # smooth: the direction changes by a few degrees at most between neighbouring pieces
    for a, b in itertools.pairwise(out):
        ta, tb = a.segment.direction_at(a.segment.length), b.segment.direction_at(0.0)
        assert math.degrees(math.acos(min(1.0, sum(x * y for x, y in zip(ta, tb, strict=True))))) < 15.0


@pytest.mark.req("M-20")
def test_corner_distance_is_limited_to_half_the_block_length() -> None:
    segs = [LineSegment((0.0, 0.0), (4.0, 0.0)), LineSegment((4.0, 0.0), (4.0, 100.0))]
    head, *_, tail = _emit(segs, ContourSettings(path_dev=10.0))
    assert head.segment.end[0] == pytest.approx(2.0)  # half of the 4 mm pre-block
    assert tail.segment.start[1] == pytest.approx(2.0)  # both limited symmetrically (475164939)


@pytest.mark.req("M-20")
def test_short_equal_blocks_are_each_contoured_at_both_ends() -> None:
    """A CAM polyline of equal 1 mm blocks: each is shortened by half at both ends, and still every
    corner gets its transition (none is left sharp because a block was used up)."""
    pts = [(float(k), float(k % 2)) for k in range(12)]
    segs: list[Segment] = [LineSegment(a, b) for a, b in itertools.pairwise(pts)]
    out = _emit(segs, ContourSettings(path_dev=5.0))
    _continuous(out, pts[0], pts[-1])
    drawn = _samples(out, per=16)
    for corner in pts[1:-1]:
        assert min(math.dist(p, corner) for p in drawn) > 0.05, corner


@pytest.mark.req("M-20")
def test_dist_mode_uses_the_programmed_corner_distances() -> None:
    segs = [LineSegment((0.0, 0.0), (50.0, 0.0)), LineSegment((50.0, 0.0), (50.0, 50.0))]
    head, *_, tail = _emit(segs, ContourSettings(mode="DIST", pre_dist=3.0, post_dist=5.0))
    assert head.segment.end[0] == pytest.approx(47.0)
    assert tail.segment.start[1] == pytest.approx(5.0)


@pytest.mark.req("M-20")
def test_no_contouring_at_tangential_transitions_reversals_rapids_and_exact_stops() -> None:
    line = LineSegment((0.0, 0.0), (10.0, 0.0))
    on = LineSegment((10.0, 0.0), (20.0, 0.0))
    back = LineSegment((10.0, 0.0), (0.0, 0.0))
    up = LineSegment((10.0, 0.0), (10.0, 10.0))
    assert [p.segment for p in _emit([line, on])] == [line, on]
    assert [p.segment for p in _emit([line, back])] == [line, back]
    stage = Contour()
    assert stage.push(Piece(line, BLOCK, feed=100.0, blend=DEV)) == []
    out = stage.push(Piece(up, BLOCK, rapid=True))
    assert [p.segment for p in out] == [line, up]
    assert stage.push(Piece(line, BLOCK, feed=100.0, blend=DEV)) == []
    out = stage.push(Piece(up, BLOCK, feed=100.0, exact_stop=True))
    assert [p.segment for p in out] == [line, up]


_coord = st.floats(min_value=-200.0, max_value=200.0, allow_nan=False)


@pytest.mark.req("M-21")
@settings(max_examples=60, deadline=None)
@given(
    points=st.lists(st.tuples(_coord, _coord, _coord), min_size=3, max_size=6),
    dev=st.floats(min_value=0.01, max_value=20.0),
)
def test_property_a_blended_polyline_never_departs_by_more_than_path_dev(
    points: list[tuple[float, float, float]], dev: float
) -> None:
    segs: list[Segment] = [LineSegment(a, b) for a, b in itertools.pairwise(points) if math.dist(a, b) > 1e-3]
    if len(segs) < 2:
        return
    segs = [s for k, s in enumerate(segs) if k == 0 or math.dist(segs[k - 1].end, s.start) < 1e-12]
    out = _emit(segs, ContourSettings(path_dev=dev))
    _continuous(out, segs[0].start, segs[-1].end)
    assert _independent_departure(_samples(out), segs) <= dev * (1 + 1e-6) + 3e-5


@pytest.mark.req("M-21")
@pytest.mark.slow
@settings(max_examples=40, deadline=None)
@given(
    radius=st.floats(min_value=2.0, max_value=80.0),
    sweep=st.floats(min_value=0.3, max_value=3.0),
    angle=st.floats(min_value=-3.0, max_value=3.0),
    cw=st.booleans(),
    dev=st.floats(min_value=0.01, max_value=5.0),
)
def test_property_line_arc_line_never_departs_by_more_than_path_dev(
    radius: float, sweep: float, angle: float, cw: bool, dev: float
) -> None:
    # a line into an arc that starts with a kink, and a line out of its end with another kink
    a0 = (0.0, 0.0)
    corner = (50.0, 0.0)
    centre = (corner[0] + radius * math.cos(angle), corner[1] + radius * math.sin(angle))
    start_angle = math.atan2(corner[1] - centre[1], corner[0] - centre[0])
    end_angle = start_angle + (-sweep if cw else sweep)
    end = (centre[0] + radius * math.cos(end_angle), centre[1] + radius * math.sin(end_angle))
    arc, mismatch = arc_from_centre(corner, end, (0, 1), centre, cw)
    assert mismatch < 1e-6
    out_pt = (end[0] + 30.0, end[1] - 40.0)
    segs: list[Segment] = [LineSegment(a0, corner), arc, LineSegment(end, out_pt)]
    out = _emit(segs, ContourSettings(path_dev=dev))
    _continuous(out, a0, out_pt)
    assert _independent_departure(_samples(out), segs) <= dev * (1 + 1e-6) + 3e-5
    assert any(isinstance(p.segment, ArcSegment) for p in out)  # the arc's middle is kept as an arc


# --- the manual's examples, stepped cycle by cycle ----------------------------------------------------
def _trace(program: str, **kw: object) -> tuple[list[tuple[float, float, float]], object]:
    m = make_machine(("X", "Y", "Z"), **kw)  # type: ignore[arg-type]
    ch = m.channel(1)
    ch.load_program(program, "test")
    ch.request_start()
    pts: list[tuple[float, float, float]] = []
    for _ in range(400_000):
        m.step(1)
        pts.append(tuple(a.setpoint for a in m.axes))  # type: ignore[arg-type]
        if ch.state not in (ProgramState.RUNNING, ProgramState.HELD):
            break
    return pts, m


def _polyline(points: list[tuple[float, float]]) -> list[Segment]:
    return [LineSegment((*a, 0.0), (*b, 0.0)) for a, b in itertools.pairwise(points)]


POLY_POINTS = [(0, 0), (20, 100), (40, 100), (60, 20), (80, 20), (100, 100), (120, 100), (140, 20), (160, 20)]

POLY_G61 = """\
%poly_G61
N10  X0   Y0 G01 F1000
N20 X20 Y100
N30  G61  X40 Y100
N40  G61  X60 Y20
N50  G61  X80 Y20
N60  G61  X100 Y100
N70  X120 Y100
N80  X140 Y20
N90  X160 Y20
N100 M30
"""
POLY_G261_1 = """\
%poly_G261_1
N10  X0   Y0 G01 F1000
N20  X20  Y100
N30  G261 X40 Y100
N40  X60  Y20
N50  X80  Y20
N60  X100 Y100
N70  G260 X120 Y100
N80  X140 Y20
N90  X160 Y20
N100 M30
"""
"""The manual's comparison of G61 and G261/G260 (tf5200_programming_manual/475073291.html): both give
the same contour, corners contoured at the ends of N30..N60."""


@pytest.mark.req("M-22", "M-20")
@pytest.mark.slow
def test_manual_example_g61_and_g261_give_the_identical_contour() -> None:
    p61, m61 = _trace(POLY_G61)
    p261, m261 = _trace(POLY_G261_1)
    assert errors(m61) == []
    assert errors(m261) == []
    assert p61 == p261  # bit for bit, cycle for cycle
    path = _polyline([(float(x), float(y)) for x, y in POLY_POINTS])
    worst = max(distance_to_path(p, path) for p in p61)
    assert worst <= 1.0 + 1e-6  # PATH_DEV's default 1 mm (475164939)
    # the corners at the ends of N30..N60 are cut, those of N20, N70, N80 are not
    near = {c: min(math.dist(p[:2], c) for p in p61) for c in POLY_POINTS[1:-1]}
    for c in [(40, 100), (60, 20), (80, 20), (100, 100)]:
        assert 0.9 < near[c] <= 1.01, (c, near[c])
    for c in [(20, 100), (120, 100), (140, 20)]:
        assert near[c] < 0.02, (c, near[c])  # a cycle's sample next to the exact corner
    assert p61[-1][:2] == pytest.approx((160.0, 20.0))


@pytest.mark.req("M-22")
def test_manual_example_contour_mode_on_off() -> None:
    """%Contour_on_off (475156491): #CONTOUR MODE ON [DEV PATH_DEV=1.0] = G261, OFF = G260."""
    program = """\
%Contour_on_off
N10 G90 G01 X0 Y0 Z0 F6000
N20 #CONTOUR MODE ON [DEV PATH_DEV=1.0]    ;Parameterisation and activation (= G261)
N30 X100
N40 Y100
N50 X0
N60 Y0
N70 #CONTOUR MODE OFF                      ;Deactivation (= G260)
N80 M30
"""
    pts, m = _trace(program)
    assert errors(m) == []
    square = _polyline([(0, 0), (100, 0), (100, 100), (0, 100), (0, 0)])
    assert max(distance_to_path(p, square) for p in pts) <= 1.0 + 1e-6
    for corner in [(100, 0), (100, 100), (0, 100)]:
        assert 0.9 < min(math.dist(p[:2], corner) for p in pts) <= 1.01
    assert pts[-1] == pytest.approx((0.0, 0.0, 0.0))  # the last corner: OFF ends the contouring


@pytest.mark.req("M-22")
def test_manual_example_type_4_with_comma_and_g261_g260() -> None:
    """Polynomial contouring type 4 (hsc/15427937931): #CONTOUR MODE [DEV, PATH_DEV=5], G261 ... G260."""
    program = """\
N05 #CONTOUR MODE [DEV, PATH_DEV=5]
N10 G261
N20 G01 G01 G90 X100 F10000
N30 Y100
N40 X0
N2000 G260
M30
"""
    pts, m = _trace(program)
    assert errors(m) == []
    path = _polyline([(0, 0), (100, 0), (100, 100), (0, 100)])
    assert max(distance_to_path(p, path) for p in pts) <= 5.0 + 1e-6
    assert 4.9 < min(math.dist(p[:2], (100.0, 0.0)) for p in pts) <= 5.0 * 1.01


@pytest.mark.req("M-22")
def test_manual_example_poly_const_speed() -> None:
    """%poly_const_speed (PM 475135755) without its ``#SLOPE[TYPE=TRAPEZ]`` line (acceleration profiles
    are issue 24 item 1): CONST_VEL is accepted without effect; N6/N7 and N9/N10 are contoured with
    the default PATH_DEV 1 mm."""
    program = """\
%poly_const_speed
N0004 G1 X0 Y0 Z0 F8000
N0005 #CONTOUR MODE [CONST_VEL=0]
N0006 X100 G61
N0007 Y100
N0008 #CONTOUR MODE [CONST_VEL=1]
N0009 X0 G61
N0010 Y0
N0020 M30
"""
    pts, m = _trace(program)
    assert errors(m) == []
    assert alarm_ids(m) == []
    for corner, cut in [((100.0, 0.0), True), ((100.0, 100.0), False), ((0.0, 100.0), True)]:
        near = min(math.dist(p[:2], corner) for p in pts)
        assert (0.9 < near <= 1.01) if cut else near < 0.02, (corner, near)


@pytest.mark.req("M-23")
@pytest.mark.parametrize(
    ("switch_on", "switch_off", "dev"),
    [
        ("#HSC[OPMODE 1 CONTERROR 0.5]\n#HSC ON", "#HSC OFF", 0.5),
        ("N10 #HSC ON [OPMODE 1 CONTERROR 1]", "N2000 #HSC OFF", 1.0),
        ("#HSC ON", "#HSC OFF", 0.1),
        ("#HSC ON [BSPLINE PATH_DEV=0.3]", "#HSC OFF", 0.3),
        ("#HSC ON [BSPLINE]", "#HSC OFF", 0.2),
        ("#SPLINE ON", "#SPLINE OFF", 0.2),
        ("#SET SPLINE ON", "#SET SPLINE OFF", 0.2),
        ("N5 G151", "G150", 0.2),
    ],
    ids=[
        "hsc-opmode1",
        "hsc-on-params",
        "hsc-default",
        "hsc-bspline",
        "hsc-bspline-default",
        "spline",
        "set-spline",
        "g151",
    ],
)
def test_hsc_and_splines_are_simulated_as_contouring_and_say_so(
    switch_on: str, switch_off: str, dev: float
) -> None:
    program = f"G01 X0 Y0 F6000\n{switch_on}\nX50\nY50\n{switch_off}\nX0\nY0\nM30\n"
    pts, m = _trace(program)
    assert errors(m) == []
    warning = only_alarm(m, 911040)
    assert "simulated as polynomial contouring" in warning.message
    assert f"PATH_DEV={dev:g} mm" in warning.message
    square = _polyline([(0, 0), (50, 0), (50, 50), (0, 50), (0, 0)])
    assert max(distance_to_path(p, square) for p in pts) <= dev * (1 + 1e-6)
    for corner in [(50.0, 0.0), (50.0, 50.0)]:  # the corner at the end of the block before OFF too
        assert 0.9 * dev < min(math.dist(p[:2], corner) for p in pts) <= dev * 1.01
    assert min(math.dist(p[:2], (0.0, 50.0)) for p in pts) < 0.02  # switched off before that corner


@pytest.mark.req("M-23")
def test_an_unmodelled_contouring_type_is_simulated_as_dev_with_a_warning() -> None:
    program = "G01 X0 Y0 F6000\n#CONTOUR MODE [DIST_SOFT PATH_DEV=2]\nG261 X50\nY50\nG260 X0\nM30\n"
    pts, m = _trace(program)
    assert errors(m) == []
    assert "#CONTOUR MODE [DIST_SOFT]" in only_alarm(m, 911040).message
    assert 1.9 < min(math.dist(p[:2], (50.0, 0.0)) for p in pts) <= 2.0 * 1.01


@pytest.mark.req("M-20")
def test_dist_mode_in_a_program() -> None:
    program = "G01 X0 Y0 F6000\n#CONTOUR MODE [DIST PRE_DIST=4 POST_DIST=4]\nG61 X50\nY50\nM30\n"
    pts, m = _trace(program)
    assert errors(m) == []
    assert alarm_ids(m) == []
    # leaves the X line 4 mm before the corner, joins the Y line 4 mm after it
    on_x = [p for p in pts if abs(p[1]) < 1e-9 and p[0] > 40]
    assert max(p[0] for p in on_x) == pytest.approx(46.0, abs=1e-6)


@pytest.mark.req("M-20")
def test_contouring_is_deterministic_and_the_velocity_stays_up_through_the_corner() -> None:
    program = "G01 X0 Y0 F6000\n#CONTOUR MODE [DEV PATH_DEV=0.5]\nG261 X100\nY100\nG260 X0\nM30\n"
    exact = "G01 X0 Y0 F6000\nX100\nY100\nX0\nM30\n"
    pts, _ = _trace(program)
    again, _ = _trace(program)
    assert pts == again
    ref, _ = _trace(exact)
    assert len(pts) < len(ref)  # the blended corners are not stops: the program ends sooner
    # the slowest speed near the first corner is well above a standstill
    speeds = [math.dist(a, b) * 1000.0 * 60.0 for a, b in itertools.pairwise(pts)]
    corner = [v for p, v in zip(pts, speeds, strict=False) if math.dist(p[:2], (100.0, 0.0)) < 3.0]
    assert min(corner) > 1000.0  # mm/min, of F6000


# --- the area checks on the blended path (FCT-C14 section 2.3) -----------------------------------------
def _prot(x0: float, x1: float, y0: float, y1: float) -> str:
    return (
        "N1 #CONTROL AREA BEGIN [ID7 PROT POLY MIN_EXCUR=-50 MAX_EXCUR=50]\n"
        f"N2 G01 X{x0} Y{y0} F6000\nN3 X{x1}\nN4 Y{y1}\nN5 X{x0}\nN6 Y{y0}\n"
        "N7 #CONTROL AREA END\nN8 #CONTROL AREA ON [ID7]\n"
    )


CORNER = "N10 G01 X0 Y0 F6000\nN20 X100\nN30 Y100\nN40 M30\n"


def _with(contour: bool, body: str = CORNER) -> str:
    head = "N9 #CONTOUR MODE [DEV PATH_DEV=5]\nN11 G261\n" if contour else ""
    return head + body


@pytest.mark.req("M-24", "C14-15")
def test_protection_area_missed_by_the_programmed_corner_is_hit_by_the_blended_one() -> None:
    # a small area inside the corner around the transition's interim point (96.46, 3.54)
    area = _prot(95.5, 97.5, 2.5, 4.5)
    pts, m = _trace(area + _with(False))
    assert errors(m) == []
    assert pts[-1][:2] == pytest.approx((100.0, 100.0))
    pts, m = _trace(area + _with(True))
    (err,) = errors(m)
    assert m.channel(1).state == ProgramState.ABORTED
    # refused before the axes enter it: the path stops at the start of the failing chord
    assert all(not (95.5 <= p[0] <= 97.5 and 2.5 <= p[1] <= 4.5) for p in pts)
    assert 90.0 < pts[-1][0] < 97.5
    assert pts[-1][1] < 2.5
    assert "N20" in str(err.params.get("block", "")) or err.line in (12, 13)


@pytest.mark.req("M-24", "C14-15")
def test_protection_area_hit_by_the_programmed_corner_is_missed_by_the_blended_one() -> None:
    area = _prot(99.5, 101.0, -1.0, 0.5)
    pts, m = _trace(area + _with(False))
    assert len(errors(m)) == 1
    assert pts[-1][0] < 99.5 + 1e-9
    assert pts[-1][1] == pytest.approx(0.0)
    pts, m = _trace(area + _with(True))
    assert errors(m) == []
    assert pts[-1][:2] == pytest.approx((100.0, 100.0))


@pytest.mark.req("M-24")
def test_work_area_left_only_by_the_blended_path_is_accepted_and_one_left_by_it_is_refused() -> None:
    """A work area whose corner the programmed path follows exactly: the blended path stays inside
    (it cuts the corner towards the inside); a work area ending inside the corner's cut is left."""
    work = (
        "N1 #CONTROL AREA BEGIN [ID8 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]\n"
        "N2 G01 X-1 Y-1 F6000\nN3 X101\nN4 Y101\nN5 X-1\nN6 Y-1\n"
        "N7 #CONTROL AREA END\nN8 #CONTROL AREA ON [ID8]\n"
    )
    pts, m = _trace(work + _with(True))
    assert errors(m) == []
    # an L-shaped work area that follows the two programmed lines 1 mm wide: the cut corner leaves it
    narrow = (
        "N1 #CONTROL AREA BEGIN [ID8 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]\n"
        "N2 G01 X-1 Y-1 F6000\nN3 X101\nN4 Y101\nN5 X99\nN6 Y1\nN7 X-1\nN8 Y-1\nN9 #CONTROL AREA END\n"
        "N10 #CONTROL AREA ON [ID8]\n"
    )
    pts, m = _trace(narrow + "N10 G01 X0 Y0 F6000\n" + _with(False, "N20 X100\nN30 Y100\nN40 M30\n"))
    assert errors(m) == []
    pts, m = _trace(narrow + "N10 G01 X0 Y0 F6000\n" + _with(True, "N20 X100\nN30 Y100\nN40 M30\n"))
    assert len(errors(m)) == 1
    assert all(p[1] <= 1.0 + 1e-9 or p[0] >= 99.0 - 1e-9 for p in pts)


# --- errors, warnings, what stays refused ---------------------------------------------------------------
@pytest.mark.req("M-25")
@pytest.mark.parametrize(
    ("line", "alarm", "text"),
    [
        ("#CONTOUR MODE [DEV PATH_DEV=-1]", 120129, "PATH_DEV=-1"),
        ("#CONTOUR MODE [DEV WIGGLE=3]", 914015, "unknown parameter 'WIGGLE'"),
        ("#CONTOUR MODE ON OFF", 914015, "ON and OFF"),
        ("#CONTOUR MODE [DEV DIST]", 914015, "two contouring types"),
        ("#CONTOUR MODE [DEV PATH_DEV=1", 914015, "']' missing"),
        ("#CONTOUR MODE [DEV PATH_DEV=]", 914015, "without a value"),
        ("#HSC [OPMODE 3]", 910111, "OPMODE 3"),
        ("#HSC [CONTERROR -0.1]", 120129, "CONTERROR"),
        ("#SPLINE", 914015, "ON, OFF or TYPE"),
        ("#SPLINE TYPE CUBIC", 914015, "unknown word 'CUBIC'"),
        ("#CONTOUR MODE [DIST PRE_DIST=-2]", 910111, "PRE_DIST"),
    ],
)
def test_malformed_contouring_commands_are_refused_with_line_and_block(
    line: str, alarm: int, text: str
) -> None:
    m = make_machine(("X", "Y", "Z"))
    ch = m.channel(1)
    ch.load_program(f"N10 G01 X10 F1000\nN20 {line}\nN30 X20\nM30\n", "test")
    ch.request_start()
    m.step(2000)
    err = only_alarm(m, alarm)
    assert text in err.message, err.message
    assert err.params.get("line") == 2
    assert ch.setpoints()[0] == pytest.approx(10.0)  # the block before ran; nothing after it


@pytest.mark.req("M-26")
@pytest.mark.parametrize(
    ("line", "text"),
    [
        ("N50 : G0 X200 Y0 : G0 X10 Y0", "two-path programming"),
        (
            '#CONTROL AREA BEGIN [ID1 PROT POLY MIN_EXCUR=0 MAX_EXCUR=1 MONITOR_LVL="IMCS"]',
            'MONITOR_LVL="IMCS"',
        ),
    ],
    ids=["two-path", "imcs"],
)
def test_what_stays_refused_is_refused_with_a_clear_alarm(line: str, text: str) -> None:
    m = make_machine()
    ch = m.channel(1)
    ch.load_program(f"N10 G01 X10 F1000\n{line}\nN30 X20\nM30\n", "test")
    ch.request_start()
    m.step(2000)
    (err,) = errors(m)
    assert err.number in (910110, 21797, 120479, 50785), err
    assert text in err.message
    assert "docs/nc-language.md" in err.message
    assert ch.state == ProgramState.ABORTED


@pytest.mark.req("M-25")
@pytest.mark.fuzz
@pytest.mark.slow
def test_fuzzed_contouring_commands_never_crash_and_never_corrupt_the_next_program() -> None:
    rnd = random.Random(seed_for("contouring commands"))
    words = [
        "ON",
        "OFF",
        "DEV",
        "DIST",
        "PATH_DEV=",
        "PRE_DIST=",
        "POST_DIST=",
        "[",
        "]",
        ",",
        "OPMODE",
        "1",
        "-3",
        "CONTERROR",
        "1e400",
        "P1",
        "BSPLINE",
        "TYPE",
        "AKIMA",
        "=",
        "(x",
        ";",
        "9" * 40,
        "\x00",
        "#",
    ]
    heads = ["#CONTOUR MODE", "#HSC", "#SPLINE", "#SET SPLINE", "#SET SPLINETYPE", "G61", "G261", "G151"]
    m = make_machine(("X", "Y", "Z"))
    ch = m.channel(1)
    for _ in range(count(80)):
        line = rnd.choice(heads) + " " + " ".join(rnd.choice(words) for _ in range(rnd.randint(0, 6)))
        ch.request_reset()
        m.step(5)
        ch.load_program(f"N10 G01 X0 Y0 F30000\n{line}\nN30 X5\nN40 Y5\nM30\n", "fuzz")
        ch.request_start()
        m.step(1500)
        assert ch.state in (ProgramState.FINISHED, ProgramState.ABORTED), (line, ch.state)
    # the machine still runs a clean program exactly as before
    ch.request_reset()
    m.step(5)
    ch.load_program(CORNER, "clean")
    ch.request_start()
    m.step(20_000)
    assert ch.state == ProgramState.FINISHED
    assert ch.setpoints()[:2] == pytest.approx([100.0, 100.0])


# --- check --geometry-only's batch ------------------------------------------------------------------------
@pytest.mark.req("M-24", "C14-15")
@pytest.mark.slow
def test_the_geometry_batch_checks_the_blended_path_while_contouring_is_on() -> None:
    """The batch clears plain lines by their programmed boxes; with contouring on every line goes through
    the contouring stage instead, so a protection area only the transition enters is refused there too,
    with the same alarm, line, block and point as the exact decoder."""
    from tests.unit.test_batch_check import AREAS, _count_batched, _zigzag, assert_same
    from tests.unit.test_batch_check import config as config_fixture

    config = config_fixture.__wrapped__()  # type: ignore[attr-defined]
    zigzag = _zigzag(400)
    plain = AREAS + "\n".join([*zigzag, "M30"]) + "\n"
    contoured = AREAS + "\n".join(["#CONTOUR MODE [DEV PATH_DEV=0.5]", "G261", *zigzag, "G260", "M30"]) + "\n"
    assert assert_same(config, plain).completed
    assert _count_batched(config, plain, small=None)[0] > 300  # without contouring: batched
    assert assert_same(config, contoured).completed
    assert _count_batched(config, contoured, small=None)[0] == 0  # with contouring: block by block
    area = _prot(95.5, 97.5, 2.5, 4.5)
    hit = area + "\n".join(["N9 #CONTOUR MODE [DEV PATH_DEV=5]", "N10 G01 X0 Y0 F6000", "N11 G261"])
    hit += "\n" + "\n".join(f"G01 X{k % 2 * 10} Y{20 + k % 3}" for k in range(100))
    hit += "\nG01 X0 Y0\nN20 X100\nN30 Y100\nN40 M30\n"
    result = assert_same(config, hit)
    assert [a.number for a in result.alarms if a.severity == "error"] == [912001]


@pytest.mark.req("M-20", "C14-23")
def test_a_measuring_move_after_a_contoured_block_comes_after_it_uncontoured() -> None:
    """G100 with contouring on: the held block runs first, to its programmed end (no transition into a
    measuring move), then the measuring move; M30 in a contoured block ends at its end point."""
    from tests.unit.areas.helpers import areas
    from tests.unit.areas.test_area_measuring import make_machine as measuring_machine
    from tests.unit.areas.test_area_measuring import start

    m = measuring_machine()
    seen: list[tuple[float, float]] = []
    ch = m.channel(1)
    program = "N10 G01 X0 Y0 F6000\nN15 G261\nN20 Y10\nN30 G100 X50\nN40 G01 Y20\nN50 G260 M30\n"
    # as run_with_probe_at, with every cycle's setpoints kept (the compiled Machine's step is read-only)
    start(m, program)
    fired = False
    for _ in range(100_000):
        if ch.state not in (ProgramState.RUNNING, ProgramState.HELD):
            break
        if not fired and ch.axis("X").setpoint >= 30.0:
            fired = True
            areas(m).request_probe(True)
        m.step(1)
        seen.append((ch.axis("X").setpoint, ch.axis("Y").setpoint))
    else:
        raise AssertionError("program did not end")
    assert min(math.dist(p, (0.0, 10.0)) for p in seen) < 0.02  # the corner before G100: exact
    assert all(abs(p[0]) < 1e-9 for p in seen if p[1] < 9.99)  # N20 ran first, along X0
    assert errors(m) == []
    assert ch.state == ProgramState.FINISHED
    x, y = ch.axis("X").setpoint, ch.axis("Y").setpoint
    assert y == pytest.approx(20.0)
    assert 30.0 <= x < 50.0
