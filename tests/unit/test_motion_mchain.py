"""The chained path (issue 24, M-30..M-33): radius compensation -> frames and tool length -> contouring ->
the path checks. A contoured program under a #CS with G41/G42 and a tool runs; its tool path stays within
the deviation of the compensated path (and within deviation + the compensation's bound of the programmed
one), in machine coordinates; the area checks test the blended, compensated path; the gouge check of the
radius compensation refuses a slot narrower than the tool and an approach or departure too short for it."""

from __future__ import annotations

import itertools
import math
import random
from typing import Any

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from hli_server.engine.alarms import ALARMS
from hli_server.engine.decoder import DecodeError
from hli_server.engine.geometry import LineSegment, Segment
from hli_server.engine.machine import Machine
from hli_server.engine.nc.source import ProgramText
from hli_server.engine.path.contour import distance_to_path
from hli_server.engine.planner import Marker, MarkerKind, Motion
from schemas.config import AxisConfig, ChannelConfig, MachineConfig
from schemas.wire import ProgramState
from tests import fuzz
from tests.unit.areas.helpers import alarm_ids, errors

TOOLS = [
    {"number": 1, "length": 1_000_000, "radius": 50_000},  # 100 mm, r 5 mm
    {"number": 2, "length": 500_000, "radius": 20_000},  # 50 mm, r 2 mm
]
ROOT2 = math.sqrt(2.0)


def machine(**channel: Any) -> Machine:
    names = ["X", "Y", "Z"]
    axes = [
        AxisConfig(number=i + 1, name=n, swe_neg=-10_000_000, swe_pos=10_000_000) for i, n in enumerate(names)
    ]
    return Machine(MachineConfig(axes=axes, channels=[ChannelConfig(axes=names, tools=TOOLS, **channel)]))


def decode(text: str, m: Machine | None = None) -> tuple[list[Segment], list[DecodeError], int]:
    """The program through the decoder alone (no stepping): the motions' segments in machine
    coordinates, the errors, the corners the contouring stage blended."""
    m = m if m is not None else machine()
    ch = m.channel(1)
    source = ProgramText(text, "t")
    ch.interpreter.start(source, "t")
    decoder = ch.decoder
    decoder.start(ch.interpreter, ch.setpoints())
    segments: list[Segment] = []
    errs: list[DecodeError] = []
    for _ in range(100_000):
        if decoder.finished:
            break
        ch.interpreter.refill()
        for item in decoder.next_items():
            if isinstance(item, Motion):
                segments.append(item.segment)
            elif isinstance(item, Marker) and item.kind is MarkerKind.ERROR:
                assert isinstance(item.payload, DecodeError)
                errs.append(item.payload)
    assert decoder.finished
    return segments, errs, decoder.contour.corners


def samples(segments: list[Segment], per: int = 6) -> list[tuple[float, ...]]:
    return [s.point_at(s.length * k / per) for s in segments for k in range(per + 1)]


def departure(segments: list[Segment], reference: list[Segment]) -> float:
    return max(distance_to_path(p, reference) for p in samples(segments))


def trace(text: str) -> tuple[list[tuple[float, ...]], Machine]:
    """The program stepped cycle by cycle: the axes' setpoints of every cycle."""
    m = machine()
    ch = m.channel(1)
    ch.load_program(text, "t")
    ch.request_start()
    pts: list[tuple[float, ...]] = []
    for _ in range(400_000):
        m.step(1)
        pts.append(tuple(a.setpoint for a in m.axes))
        if ch.state not in (ProgramState.RUNNING, ProgramState.HELD):
            break
    return pts, m


def program(
    points: list[tuple[float, float]],
    *,
    cs: str = "#CS ON [10, 20, 0, 0, 0, 30]",
    side: int = 41,
    tool: int = 1,
    contour: str | None = "#CONTOUR MODE [DEV PATH_DEV=1]\nG261",
    compensate: bool = True,
    head: str = "",
) -> str:
    """A milling program: positioning to the start, the approach with G41/G42, the contour, the departure
    with G40. ``points`` = start, contour points, departure end (program coordinates)."""
    (sx, sy), *rest, (ex, ey) = points
    lines = ["%chain", head, cs, f"N10 G01 X{sx:.6f} Y{sy:.6f} Z0 F6000 D{tool}"]
    if contour:
        lines.append(contour)
    g = f"G{side} " if compensate else ""
    for k, (x, y) in enumerate(rest):
        lines.append(f"N{20 + 10 * k} {g if k == 0 else ''}X{x:.6f} Y{y:.6f}")
    lines.append(f"N900 {'G40 ' if compensate else ''}X{ex:.6f} Y{ey:.6f}")
    lines.append("N910 M30")
    return "\n".join(line for line in lines if line) + "\n"


SQUARE_MILL = [
    (-20.0, -20.0),
    (0.0, 0.0),
    (100.0, 0.0),
    (100.0, 60.0),
    (0.0, 60.0),
    (0.0, 10.0),
    (-20.0, 10.0),
]


# --- what chains now ----------------------------------------------------------------------------------
@pytest.mark.req("M-30")
@pytest.mark.parametrize(
    "transform", ["#CS ON [5, 5, 0, 0, 0, 10]", "#ROTATION ON [ANGLE=30]", "D1", "D1 G42 X10 Y0"]
)
@pytest.mark.parametrize(
    "contouring", ["G261", "#CONTOUR MODE [DEV PATH_DEV=0.5]\nG261", "#HSC ON", "#SPLINE ON", "G64"]
)
def test_contouring_with_a_frame_a_tool_or_compensation_runs_contoured(
    transform: str, contouring: str
) -> None:
    """What was refused with 910110 until the stages were chained: every contouring function under a
    coordinate system, a rotation, a tool or the radius compensation runs, and its corners are blended."""
    text = f"%t\nG01 X10 Y10 F5000\n{contouring}\n{transform}\nX20 Y10\nX20 Y20\nX30 Y25\nG40 X40 Y25\nM30\n"
    segments, errs, corners = decode(text)
    assert errs == []
    assert corners >= 2
    assert any(isinstance(s, LineSegment) and s.length < 1.0 for s in segments)  # the support points' chords
    pts, m = trace(text)
    assert errors(m) == []
    assert [a for a in alarm_ids(m) if a != 911040] == []  # 911040: #HSC/#SPLINE simulated as DEV
    assert m.channel(1).state == ProgramState.FINISHED
    assert pts[-1] == pytest.approx(segments[-1].end)


@pytest.mark.req("M-30", "M-31")
def test_stepped_g41_contouring_under_a_rotated_cs_stays_within_the_deviation_of_the_compensated_path() -> (
    None
):
    """The everyday milling program: a #CS turned by 30°, a tool with length and radius, G41, contouring
    with PATH_DEV 1 mm. Cycle by cycle, every setpoint lies within PATH_DEV of the compensated path with
    sharp corners (machine coordinates), and within PATH_DEV + r·√2 of the programmed path."""
    dev, r = 1.0, 5.0
    text = program(SQUARE_MILL)
    compensated, errs, _ = decode(program(SQUARE_MILL, contour=None))
    assert errs == []
    programmed, errs, _ = decode(program(SQUARE_MILL, contour=None, compensate=False))
    assert errs == []
    blended, errs, corners = decode(text)
    assert errs == []
    assert corners >= 5  # the approach corner, the four corners of the contour, the departure corner
    assert departure(blended, compensated) <= dev + 1e-6
    pts, m = trace(text)
    assert errors(m) == []
    assert m.channel(1).state == ProgramState.FINISHED
    assert pts[-1] == pytest.approx(compensated[-1].end)
    worst = max(distance_to_path(p, compensated) for p in pts[::3])
    assert worst <= dev + 1e-6
    assert worst >= 0.3 * dev  # the corners are blended, not sharp
    assert max(distance_to_path(p, programmed) for p in pts[::3]) <= dev + r * ROOT2 + 1e-6
    # the tool length is in the axis position (Z = 0 + 100 mm), the turned CS in X/Y
    assert pts[-1][2] == pytest.approx(100.0)
    # and the blended path is faster than the one with sharp corners
    sharp, m2 = trace(program(SQUARE_MILL, contour=None))
    assert errors(m2) == []
    assert len(pts) < len(sharp)


@st.composite
def milling_paths(draw: st.DrawFn) -> tuple[list[tuple[float, float]], float, float, str, int]:
    heading = draw(st.floats(-math.pi, math.pi))
    n = draw(st.integers(2, 5))
    pts = [(0.0, 0.0)]
    for _ in range(n):
        length = draw(st.floats(25.0, 60.0))
        pts.append((pts[-1][0] + length * math.cos(heading), pts[-1][1] + length * math.sin(heading)))
        turn = draw(st.floats(math.radians(25), math.radians(120))) * draw(st.sampled_from([-1, 1]))
        heading += turn
    # the approach from 20 mm away at 45° to the first block, the departure likewise after the last
    d0 = math.atan2(pts[1][1] - pts[0][1], pts[1][0] - pts[0][0]) + math.radians(45)
    d1 = math.atan2(pts[-1][1] - pts[-2][1], pts[-1][0] - pts[-2][0]) - math.radians(45)
    start = (pts[0][0] - 20.0 * math.cos(d0), pts[0][1] - 20.0 * math.sin(d0))
    end = (pts[-1][0] + 20.0 * math.cos(d1), pts[-1][1] + 20.0 * math.sin(d1))
    dev = draw(st.floats(0.05, 2.0))
    angle = draw(st.floats(-180.0, 180.0))
    dx, dy = draw(st.floats(-50.0, 50.0)), draw(st.floats(-50.0, 50.0))
    cs = f"#CS ON [{dx:.4f}, {dy:.4f}, 0, 0, 0, {angle:.4f}]"
    return [start, *pts, end], dev, 5.0, cs, draw(st.sampled_from([41, 42]))


@pytest.mark.req("M-31", "M-21", "M-17")
@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(milling_paths())
def test_property_the_chained_path_stays_within_the_deviation_of_the_compensated_one(
    case: tuple[list[tuple[float, float]], float, float, str, int],
) -> None:
    """Random contours, G41 or G42 with r = 5 mm, a random PATH_DEV, a random turned #CS: in machine
    coordinates the blended tool path departs from the compensated path by at most PATH_DEV and from the
    programmed path by at most PATH_DEV + r·√2 (G25's outer-corner bound)."""
    points, dev, r, cs, side = case
    kw: dict[str, Any] = {"cs": cs, "side": side}
    compensated, errs, _ = decode(program(points, contour=None, **kw))
    assume(not errs)  # a random contour the compensation refuses (916000) is not this property's case
    programmed, errs, _ = decode(program(points, contour=None, compensate=False, **kw))
    assert errs == []
    blended, errs, corners = decode(
        program(points, contour=f"#CONTOUR MODE [DEV PATH_DEV={dev:.6f}]\nG261", **kw)
    )
    assert errs == []
    assert corners >= len(points) - 2
    assert departure(blended, compensated) <= dev * (1 + 1e-6) + 1e-6
    assert departure(blended, programmed) <= dev + r * ROOT2 + 1e-6
    assert blended[-1].end == pytest.approx(compensated[-1].end)
    for a, b in itertools.pairwise(blended):  # one continuous path
        assert math.dist(a.end, b.start) < 1e-9


# --- the monitors on the chained path (FCT-C14 2.3) ---------------------------------------------------
def _square(centre: tuple[float, ...], half: float) -> str:
    x, y = centre[0], centre[1]
    return (
        "N1 #CONTROL AREA BEGIN [ID7 PROT POLY MIN_EXCUR=-50 MAX_EXCUR=50]\n"
        f"N2 G01 X{x - half:.6f} Y{y - half:.6f} F6000\nN3 X{x + half:.6f}\nN4 Y{y + half:.6f}\n"
        f"N5 X{x - half:.6f}\nN6 Y{y - half:.6f}\nN7 #CONTROL AREA END\nN8 #CONTROL AREA ON [ID7]\n"
    )


CORNER = [(-20.0, -20.0), (0.0, 0.0), (100.0, 0.0), (100.0, 100.0), (120.0, 120.0)]
BLEND = "#CONTOUR MODE [DEV PATH_DEV=5]\nG261"


def _corner_points() -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Machine coordinates of the compensated sharp corner of N30/N40 and of the blended curve's
    interim point there (G41, r = 5 mm, under #CS ON [10, 20, 0, 0, 0, 30])."""
    sharp, errs, _ = decode(program(CORNER, contour=None))
    assert errs == []
    # the compensated inner corner (95, 5) in program coordinates: the 3rd segment's end
    corner = sharp[2].end
    blended, errs, _ = decode(program(CORNER, contour=BLEND))
    assert errs == []
    interim = min(
        (p for s in blended for p in (s.start, s.end) if math.dist(p, corner) > 1.0),
        key=lambda p: math.dist(p, corner),
    )
    assert math.dist(interim, corner) == pytest.approx(5.0, abs=0.01)  # PATH_DEV
    return corner, interim


@pytest.mark.req("M-32", "M-24", "M-19", "C14-15")
def test_protection_area_missed_by_the_compensated_corner_is_hit_by_the_blended_one_under_a_cs() -> None:
    _, interim = _corner_points()
    area = _square(interim, 1.0)  # 3.5 mm from the sharp compensated path, on the blended one
    pts, m = trace(area + program(CORNER, contour=None).replace("%chain\n", ""))
    assert errors(m) == []
    assert m.channel(1).state == ProgramState.FINISHED
    pts, m = trace(area + program(CORNER, contour=BLEND).replace("%chain\n", ""))
    (err,) = errors(m)
    assert m.channel(1).state == ProgramState.ABORTED
    # the transition carries its pre-block N30; the area sees the tool tip (Z 0, the axis at 100 mm)
    assert err.number == 912001
    assert "N30" in err.message
    assert err.params["area"] == 7
    assert err.params["intersection"][2] == pytest.approx(0.0)
    # refused before the tool enters it: the path stops at the start of the refused support-point chord
    assert all(not (abs(p[0] - interim[0]) <= 1.0 and abs(p[1] - interim[1]) <= 1.0) for p in pts)
    assert 1.0 < math.dist(pts[-1][:2], interim[:2]) < 6.0


@pytest.mark.req("M-32", "M-24", "M-19", "C14-15")
def test_protection_area_hit_by_the_compensated_corner_is_missed_by_the_blended_one_under_a_cs() -> None:
    corner, _ = _corner_points()
    area = _square(corner, 1.0)  # on the sharp compensated corner, 5 mm from the blended path
    pts, m = trace(area + program(CORNER, contour=None).replace("%chain\n", ""))
    assert len(errors(m)) == 1
    assert m.channel(1).state == ProgramState.ABORTED
    assert math.dist(pts[-1][:2], corner[:2]) > 1.0
    pts, m = trace(area + program(CORNER, contour=BLEND).replace("%chain\n", ""))
    assert errors(m) == []
    assert m.channel(1).state == ProgramState.FINISHED


# --- the manual's milling example that combines them ---------------------------------------------------
MILLING_EXAMPLE = """\
%path_milling
T1 D1
G90 G54 S6000 M03 F5000
#CS ON [40, 30, 0, 0, 0, 15]
G0 Z10
; polynomial contouring for smooth movements (the cycle example's own line)
#CONTOUR MODE [DEV, PATH_DEV = V.G.WZ_AKT.R / 100]
G261
G01 X0 Y0 Z-5
G41 X25 Y25
G91 X50
Y50
X50
G90 X150 Y150
X25
Y25
G40 X0 Y10
G0 Z10
M30
"""
"""After the path-milling example of the milling cycles (tf5293_tc3_cnc_cycles_millingbase/781132427.html):
its technology head, its contouring line ``#CONTOUR MODE [DEV, PATH_DEV = V.G.WZ_AKT.R / 100]`` and G261,
the contour run with G41 directly (the cycle SysMillContourPath itself is not simulated), under a #CS."""


@pytest.mark.req("M-30", "M-31")
def test_manual_path_milling_example_with_contouring_compensation_and_a_cs() -> None:
    segments, errs, corners = decode(MILLING_EXAMPLE)
    assert errs == []
    assert corners >= 6
    sharp, errs, _ = decode(MILLING_EXAMPLE.replace("G261\n", "G260\n"))
    assert errs == []
    dev = 5.0 / 100  # V.G.WZ_AKT.R of D1 is 5 mm
    assert departure(segments, sharp) <= dev * (1 + 1e-6) + 1e-6
    pts, m = trace(MILLING_EXAMPLE)
    assert errors(m) == []
    assert m.channel(1).state == ProgramState.FINISHED
    assert max(distance_to_path(p, sharp) for p in pts[::5]) <= dev + 1e-6
    # the tool tip went 5 mm deep: the axis at -5 + 100 mm of tool length
    assert any(abs(p[2] - 95.0) < 1e-6 for p in pts)
    assert min(p[2] for p in pts[len(pts) // 10 :]) >= 95.0 - 1e-6
    assert pts[-1][2] == pytest.approx(110.0)


# --- flush points empty the stages in pipeline order -------------------------------------------------
@pytest.mark.req("M-30")
@pytest.mark.parametrize(
    ("between", "contoured"),
    [
        ("M08", True),  # an M function is a non-relevant block: both stages keep the corner
        ("#CONTOUR MODE [DEV PATH_DEV=0.5]", True),  # modal settings only
        ("#FLUSH", False),
        ("#CS ON [1, 0, 0, 0, 0, 0]", False),
        ("G54", False),
        ("G17 G53", True),  # the plane and the zero offset in effect already: no frame change
    ],
)
def test_flush_points_empty_the_compensation_then_the_contouring(between: str, contoured: bool) -> None:
    text = (
        "%t\n#CS ON [10, 20, 0, 0, 0, 30]\nG01 X-20 Y-20 Z0 F6000 D1\nG261\nG41 X0 Y0\nX100\n"
        f"{between}\nY100\nX50\nG40 X40 Y120\nM30\n"
    )
    segments, errs, corners = decode(text)
    assert errs == []
    for a, b in itertools.pairwise(segments):  # the path stays continuous across the flush point
        assert math.dist(a.end, b.start) < 1e-9
    # the compensated corner of X100/Y100 (95, 5): the path passes through it, or about PATH_DEV (1 mm)
    # inside it where the corner is contoured
    sharp, _, _ = decode(text.replace("G261\n", "").replace(f"{between}\n", ""))
    corner = sharp[2].end
    closest = distance_to_path(corner, segments)
    assert (closest > 0.9) is contoured, closest
    assert corners >= 3
    pts, m = trace(text)
    assert errors(m) == []
    assert pts[-1] == pytest.approx(segments[-1].end)


@pytest.mark.req("M-30")
def test_a_held_corner_that_fails_its_check_at_a_flush_point_stops_the_program_there() -> None:
    """The contouring stage holds the last compensated block when #FLUSH WAIT comes: it is checked first
    (a soft limit here), its error replaces the directive's marker and decoding ends."""
    text = "%t\nG01 X0 Y0 Z0 F6000 D1\nG261\nG41 X10 Y0\nX1500\n#FLUSH WAIT\nY100\nM30\n"
    _, errs, _ = decode(text)
    assert len(errs) == 1
    pts, m = trace(text)
    assert len(errors(m)) == 1
    assert m.channel(1).state == ProgramState.ABORTED
    assert max(p[0] for p in pts) <= 1000.0 + 1e-6


# --- the gouge check of the radius compensation (PM 207844107) ----------------------------------------
@pytest.mark.req("M-33", "M-18")
@pytest.mark.parametrize("contouring", ["", "G261\n"])
@pytest.mark.parametrize(
    ("name", "body", "line"),
    [
        # a slot 8 mm wide for a tool of 10 mm: the slot bottom's compensated block runs backwards (found
        # when the corner after it is computed, at the next block)
        ("slot", "G41 X0 Y0\nX50\nY-30\nX58\nY0\nX100\n", 8),
        # the approach 3 mm long, then an inner corner: the compensated approach runs backwards
        ("approach", "G41 X0 Y-17\nX-50\nY50\n", 5),
        # the departure 3 mm long out of an inner corner
        ("departure", "G41 X0 Y0\nX50\nY30\nG40 X47 Y30\n", 7),
    ],
)
def test_gouge_check_refuses_a_compensated_block_that_would_cut_into_the_contour(
    name: str, body: str, line: int, contouring: str
) -> None:
    end = "" if name == "departure" else "G40 X0 Y200\n"
    text = f"%t\n#CS ON [5, 5, 0, 0, 0, 20]\nG01 X0 Y-20 Z0 F6000 D1\n{contouring}{body}{end}M30\n"
    line += 1 if contouring else 0
    _, errs, _ = decode(text)
    assert [e.alarm for e in errs] == [916000]
    assert "contour violation" in errs[0].message
    pts, m = trace(text)
    (err,) = errors(m)
    assert err.number == 916000
    assert m.channel(1).state == ProgramState.ABORTED
    assert err.line == line
    if name == "approach":
        assert "approach block" in err.message
    # the tool never went past the block before the one refused
    assert all(p[2] == pytest.approx(100.0) or p[2] < 100.0 for p in pts)


@pytest.mark.req("M-33")
def test_a_slot_as_wide_as_the_tool_and_a_long_enough_approach_pass_the_gouge_check() -> None:
    ok = "%t\nG01 X0 Y-20 Z0 F6000 D1\nG41 X0 Y0\nX50\nY-30\nX60\nY0\nX100\nG40 X100 Y20\nM30\n"
    _, errs, _ = decode(ok)
    assert errs == []
    ok = "%t\nG01 X0 Y-30 Z0 F6000 D1\nG41 X0 Y0\nX-50\nY50\nG40 X-70 Y50\nM30\n"
    _, errs, _ = decode(ok)
    assert errs == []


@pytest.mark.req("M-30", "M-27")
@pytest.mark.slow
def test_the_chained_benchmark_program_runs_contoured_and_faster() -> None:
    """``benchmarks/bench_motion.py``'s chained case, small: with #CS, D1, G41 and contouring together the
    program runs to its end without an alarm, contours its corners and takes fewer cycles than the exact
    path without them."""
    from benchmarks.bench_engine import long_program
    from benchmarks.bench_motion import _run_to_end, chained
    from benchmarks.bench_motion_tools import machine as tools_machine

    text = long_program(40)
    plain_cycles, _, plain_corners = _run_to_end(text, tools_machine())
    cycles, _, corners = _run_to_end(chained(text), tools_machine())
    assert plain_corners == 0
    assert corners > 20
    assert cycles < plain_cycles


CHAIN_SEEDS = [
    "#CS ON [10, 20, 0, 0, 0, 30]",
    "#CS OFF",
    "#ROTATION ON [ANGLE=45]",
    "#CONTOUR MODE [DEV PATH_DEV=0.5]",
    "#CONTOUR MODE [DIST PRE_DIST=2 POST_DIST=1]",
    "G261",
    "G260",
    "G61 X20 Y5",
    "#HSC ON",
    "#HSC OFF",
    "D1 G41",
    "G42 D2",
    "G40 X0 Y0",
    "G26",
    "G02 X30 Y0 I5 J0",
    "G01 X40 Y40 Z-2",
    "G91 X10 Y-5",
    "G90",
    "G54",
    "M08",
    "#FLUSH",
    "X0.001 Y0",
]


@pytest.mark.fuzz
@pytest.mark.req("M-30", "M-33")
def test_fuzzed_chained_programs_never_crash_and_the_next_program_runs() -> None:
    """Random mixes of frames, tools, G41/G42/G40, contouring and flush points, one line mutated: only
    numbered alarms of the table, a continuous finite path, and the next program on the same machine runs
    as before."""
    seed = fuzz.seed_for("test_fuzzed_chained_programs_never_crash_and_the_next_program_runs")
    rng = random.Random(seed)
    m = machine()
    clean = program(SQUARE_MILL)
    reference, errs, _ = decode(clean, m)
    assert errs == []
    for example in range(fuzz.count(150)):
        lines = [rng.choice(CHAIN_SEEDS) for _ in range(rng.randint(2, 12))]
        moves = [f"X{rng.uniform(-80, 80):.3f} Y{rng.uniform(-80, 80):.3f}" for _ in range(rng.randint(1, 6))]
        lines = [*lines, *moves]
        rng.shuffle(lines)
        if rng.random() < 0.5:
            k = rng.randrange(len(lines))
            lines[k] = fuzz.mutate(rng, lines[k])
        text = "%t\nG01 X0 Y0 Z0 F3000\n" + "\n".join(lines) + "\nM30\n"
        try:
            segments, errs, _ = decode(text, m)
        except Exception as exc:  # pragma: no cover - the failure report
            raise AssertionError(f"crash (seed {seed}, example {example}): {text!r}") from exc
        for err in errs:
            assert err.alarm in ALARMS, (err, text)
            assert err.message
        for a, b in itertools.pairwise(segments):
            assert math.dist(a.end, b.start) < 1e-6, text
            assert all(math.isfinite(v) for v in b.end)
    again, errs, _ = decode(clean, m)
    assert errs == []
    assert [v for s in again for v in s.end] == pytest.approx([v for s in reference for v in s.end])
