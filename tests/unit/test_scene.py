"""The scene: what ``check --plot`` and the dashboard draw, computed once (issue 15, FCT-C14).

The programs run through ``check`` on the demo machine (channel 1: X, Y, Z), the way a user gets the
picture; the geometry of the scene is held against shapely, the project's geometry oracle.
"""

from __future__ import annotations

import ast
import json
import math
import random
import sys
from pathlib import Path

import pytest
from shapely.geometry import LineString, Point, Polygon

from hli_server.commands.check import CheckResult, check_program, scene_of
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.scene import build_scene, round_mm, round_numbers
from tests.spec_examples import CIRC_PROT_OLD, U_AREA

XYZ = ("X", "Y", "Z")

# CIRC_PROT_OLD: protection cylinder, centre (150, 0), radius 50, band Z -70..70; the axes start at 0
ABOVE = CIRC_PROT_OLD + "N50 G01 Z100 F6000\nN60 #CONTROL AREA ON [ID4]\nN70 G01 X300\nN80 Z0\nN90 M30\n"
BELOW = CIRC_PROT_OLD + "N50 G01 Z-100 F6000\nN60 #CONTROL AREA ON [ID4]\nN70 G01 X300\nN80 M30\n"
THROUGH_INACTIVE = CIRC_PROT_OLD + "N50 G01 X300 Z20 F6000\nN60 M30\n"
THROUGH_ACTIVE = CIRC_PROT_OLD + "N50 #CONTROL AREA ON [ID4]\nN60 G01 X300 Z20 F6000\nN70 M30\n"
TANGENT = CIRC_PROT_OLD + "N50 G01 Y50 F6000\nN60 X300\nN70 M30\n"
APART = CIRC_PROT_OLD + "N50 G01 Y-80 F6000\nN60 X300\nN70 M30\n"

# the U work area (FCT-C14 3.1.1); the path leaves it through its inner corner (120486)
U_LINE = U_AREA + "N150 G01 X-100 Y50 F3000\nN160 #CONTROL AREA ON [ID3]\nN170 G01 X100 Y50\nN180 M30\n"
# the same with an arc around (-50, 50), radius 50: it leaves the U at Y75 (X -6.6987...)
U_ARC = U_AREA + "N150 G01 X-100 Y50 F3000\nN160 #CONTROL AREA ON [ID3]\nN170 G02 X0 Y50 I50 J0\nN180 M30\n"
# ON at the origin, which is in the notch of the U, outside the work area (120484, C14-11)
U_ON_OUTSIDE = U_AREA + "N150 #CONTROL AREA ON [ID3]\nN160 G01 X10 F3000\nN170 M30\n"


def run_check(program: str, *, geometry_only: bool = False) -> CheckResult:
    return check_program(Machine(load_machine(None)), program, geometry_only=geometry_only, record_path=True)


def scene_for(program: str, *, geometry_only: bool = False) -> dict:
    return scene_of(run_check(program, geometry_only=geometry_only))


def area(scene: dict, area_id: int) -> dict:
    (found,) = [a for a in scene["areas"] if a["id"] == area_id]
    return found


MODES = pytest.mark.parametrize("geometry_only", [False, True], ids=["full", "geometry"])


@pytest.mark.req("C14-06", "C14-14")
@MODES
def test_a_path_over_a_protection_cylinder_passes_above_it(geometry_only: bool) -> None:
    scene = scene_for(ABOVE, geometry_only=geometry_only)
    cylinder = area(scene, 4)
    assert cylinder["state"] == "active"
    assert cylinder["relation"] == "above"
    # over the base region from X100 to X200: s from 100 to 200 (the climb to Z100 has no footprint)
    (span,) = cylinder["spans"]
    assert (span["from"], span["to"], span["relation"], span["refused"]) == (100.0, 200.0, "above", False)
    assert scene["refused"] is None
    assert scene["violation"] is None


@pytest.mark.req("C14-06")
def test_a_path_under_the_band_passes_below() -> None:
    assert area(scene_for(BELOW, geometry_only=True), 4)["relation"] == "below"


@pytest.mark.req("C14-06", "C14-14")
@MODES
def test_a_path_through_an_inactive_cylinder_crosses_it(geometry_only: bool) -> None:
    cylinder = area(scene_for(THROUGH_INACTIVE, geometry_only=geometry_only), 4)
    assert cylinder["state"] == "defined"
    assert cylinder["relation"] == "crosses"
    assert cylinder["relation_text"] == "path goes through it"  # not active: nothing stopped it
    (span,) = cylinder["spans"]
    assert span["from"] == pytest.approx(100.0)
    assert span["to"] == pytest.approx(200.0)


@pytest.mark.req("C14-15")
@MODES
def test_the_refused_block_through_an_active_cylinder_crosses_it(geometry_only: bool) -> None:
    scene = scene_for(THROUGH_ACTIVE, geometry_only=geometry_only)
    cylinder = area(scene, 4)
    assert cylinder["relation"] == "crosses"
    # the legend says what happened (issue 23): not "the path goes through it"
    assert cylinder["relation_text"] == "the refused block N60 would enter it; the axes stopped before it"
    (span,) = cylinder["spans"]
    assert span["refused"] is True
    refused = scene["refused"]
    assert (refused["alarm"], refused["block"], refused["line"], refused["area"]) == (912001, "N60", 6, 4)
    assert refused["points"] == [[0.0, 0.0, 0.0, 0.0], [300.0, 0.0, 20.0, 300.0]]
    # where the path would first touch the cylinder: X100, at a third of the climb to Z20
    assert scene["violation"]["point"] == [100.0, 0.0, 6.6667, 100.0]
    assert scene["violation"]["position"] == {"X": 100.0, "Y": 0.0, "Z": 6.6667}
    assert scene["stop"] == [0.0, 0.0, 0.0, 0.0]


@pytest.mark.req("C14-14")
def test_a_tangent_touch_is_a_span_of_no_length() -> None:
    """A protection area may not be touched (FCT-C14 2.3): the touch point is shown as crossing."""
    cylinder = area(scene_for(TANGENT, geometry_only=True), 4)
    assert cylinder["relation"] == "crosses"
    (span,) = cylinder["spans"]
    assert span["from"] == span["to"] == pytest.approx(50.0 + 150.0)


def test_a_path_that_never_comes_over_an_area_is_apart() -> None:
    cylinder = area(scene_for(APART, geometry_only=True), 4)
    assert (cylinder["relation"], cylinder["spans"]) == ("apart", [])
    assert cylinder["relation_text"] == "path never over it"


@pytest.mark.req("C14-15")
@MODES
def test_refused_block_and_intersection_of_a_120486_program(geometry_only: bool) -> None:
    scene = scene_for(U_LINE, geometry_only=geometry_only)
    refused = scene["refused"]
    assert (refused["alarm"], refused["line"], refused["block"], refused["kind"]) == (
        120486,
        16,
        "N170",
        "WORK",
    )
    start, end = refused["points"][0], refused["points"][-1]
    assert start[:3] == [-100.0, 50.0, 0.0]
    assert end[:3] == [100.0, 50.0, 0.0]
    assert end[3] - start[3] == pytest.approx(200.0)
    violation = scene["violation"]
    assert violation["point"][:3] == [-50.0, 50.0, 0.0]
    assert violation["point"][3] == pytest.approx(start[3] + 50.0)
    assert scene["stop"][:3] == [-100.0, 50.0, 0.0]
    # the travelled path ends where the refused block starts
    assert scene["path"][0][-1][:3] == start[:3]
    u = area(scene, 3)
    assert u["relation"] == "crosses"
    assert [s["refused"] for s in u["spans"]][-1] is True


@pytest.mark.req("C14-15")
def test_a_refused_arc_is_drawn_on_its_circle() -> None:
    scene = scene_for(U_ARC, geometry_only=True)
    points = scene["refused"]["points"]
    assert len(points) > 10
    for x, y, _, _ in points:
        assert math.hypot(x + 50.0, y - 50.0) == pytest.approx(50.0, abs=1e-4)
    assert max(y for _, y, _, _ in points) == pytest.approx(100.0, abs=1e-3)  # the top of the half circle
    # the engine's intersection was 75.00000000000001: rounded to the resolution
    assert scene["violation"]["point"][:3] == [-6.6987, 75.0, 0.0]


@pytest.mark.req("C14-11")
def test_an_on_refused_outside_the_work_area_marks_the_position() -> None:
    scene = scene_for(U_ON_OUTSIDE, geometry_only=True)
    assert scene["refused"] is None
    violation = scene["violation"]
    assert (violation["alarm"], violation["area"]) == (120484, 3)
    assert violation["point"][:3] == [0.0, 0.0, 0.0]


def test_the_scene_is_json_and_rounded_to_the_resolution() -> None:
    scene = scene_for(U_ARC)
    text = json.dumps(scene)
    assert json.loads(text) == scene
    numbers: list[float] = []

    def collect(v: object) -> None:
        if isinstance(v, float):
            numbers.append(v)
        elif isinstance(v, dict):
            for x in v.values():
                collect(x)
        elif isinstance(v, list):
            for x in v:
                collect(x)

    collect(scene)
    assert numbers
    assert all(round(v, 4) == v for v in numbers)
    assert "e-" not in text


def test_round_mm_removes_float_noise() -> None:
    assert round_mm(7.105427357601002e-15) == 0.0
    assert math.copysign(1.0, round_mm(-1.1102230246251565e-16)) == 1.0  # no -0.0
    assert round_mm(100.00000000000001) == 100.0
    assert round_mm(-6.698729810778076) == -6.6987
    assert round_numbers({"a": [1, 2.00000000000001, "x"], "n": 5}) == {"a": [1, 2.0, "x"], "n": 5}


def test_an_arc_of_a_geometry_check_is_recorded_along_the_arc() -> None:
    """``--geometry-only`` records block ends; an arc would be its chord without the points between."""
    result = run_check("N10 G01 X100 Y50 F6000\nN20 G02 X150 Y100 I50 J0\nN30 M30\n", geometry_only=True)
    on_arc = [p for p in result.path if p[0] > 100.0]
    assert len(on_arc) > 10
    for x, y, _ in on_arc:
        assert math.hypot(x - 150.0, y - 50.0) == pytest.approx(50.0, abs=1e-9)


def test_the_drawn_path_is_simplified_within_the_tolerance() -> None:
    circle = [
        (100.0 * math.cos(k / 2000 * math.tau), 100.0 * math.sin(k / 2000 * math.tau), 0.0)
        for k in range(2001)
    ]
    line = [(k * 0.01, 0.0, 0.0) for k in range(10_001)]
    scene = build_scene([], line, axis_names=XYZ, main_axes=XYZ, tolerance=0.01)
    assert [p[:2] for p in scene["path"][0]] == [[0.0, 0.0], [100.0, 0.0]]
    assert scene["path"][0][-1][3] == 100.0
    scene = build_scene([], circle, axis_names=XYZ, main_axes=XYZ, tolerance=0.05)
    kept = scene["path"][0]
    assert 20 < len(kept) < 400
    drawn = LineString([(p[0], p[1]) for p in kept])
    assert max(drawn.distance(Point(x, y)) for x, y, _ in circle) <= 0.05 + 1e-4


def test_a_path_point_with_the_wrong_number_of_axes_is_refused() -> None:
    with pytest.raises(ValueError, match="path point 1 has 2 coordinates, the channel has 3 axes"):
        build_scene([], [(0.0, 0.0, 0.0), (1.0, 2.0)], axis_names=XYZ, main_axes=XYZ)


def _random_polygon(rng: random.Random) -> list[tuple[float, float]]:
    """A star-shaped simple polygon (need not be convex, as the U)."""
    cx, cy = rng.uniform(-50, 50), rng.uniform(-50, 50)
    n = rng.randint(3, 12)
    angles = sorted(rng.uniform(0, math.tau) for _ in range(n))
    return [(cx + (r := rng.uniform(10, 80)) * math.cos(a), cy + r * math.sin(a)) for a in angles]


def test_spans_agree_with_shapely() -> None:
    """Random polygons, circles and segments (seeded): the path is over the base region exactly where
    shapely says, and for as long; cases within 1e-6 mm of a boundary are left to the touch test."""
    rng = random.Random(15)
    checked = 0
    for _ in range(400):
        if rng.random() < 0.5:
            corners = _random_polygon(rng)
            entry = {"id": 1, "kind": "PROT", "shape": "POLY", "points": [list(p) for p in corners]}
            region = Polygon(corners)
        else:
            c, r = (rng.uniform(-50, 50), rng.uniform(-50, 50)), rng.uniform(5, 80)
            entry = {"id": 1, "kind": "PROT", "shape": "CIRC", "center": list(c), "radius": r}
            region = Point(c).buffer(r, quad_segs=4096)
        if not region.is_valid:
            continue
        entry |= {"state": "active", "axes": ["X", "Y"], "height_axis": "Z", "min": -10.0, "max": 10.0}
        p = (rng.uniform(-150, 150), rng.uniform(-150, 150), 0.0)
        q = (rng.uniform(-150, 150), rng.uniform(-150, 150), 0.0)
        segment = LineString([p[:2], q[:2]])
        if region.exterior.distance(segment) < 1e-6 and not region.exterior.crosses(segment):
            continue  # a near touch: shapely's buffered circle and the exact one may disagree
        (got,) = build_scene([entry], [p, q], axis_names=XYZ, main_axes=XYZ, tolerance=0.0)["areas"]
        inside = segment.intersection(region).length
        assert (got["relation"] == "crosses") == segment.intersects(region), (entry, p, q)
        total = sum(s["to"] - s["from"] for s in got["spans"])
        assert total == pytest.approx(inside, abs=2e-3), (entry, p, q)
        checked += 1
    assert checked > 300


def test_the_scene_module_imports_only_the_standard_library_and_schemas() -> None:
    """The dashboard's side imports it: no matplotlib, engine, runtime or adapters (issue 15)."""
    source = Path(__file__).parents[2] / "hli_server" / "scene.py"
    tree = ast.parse(source.read_text(encoding="utf-8"))
    imported: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            imported.add(node.module.split(".")[0])
    assert imported - {"__future__", "schemas"} <= set(sys.stdlib_module_names), imported


@pytest.mark.req("C14-15")
def test_the_legend_says_what_happened_at_the_area_that_refused_a_block(tmp_path: Path) -> None:
    """Issue 23: ``check --plot``'s legend said a protection area is one the "path goes through" when the
    machine stopped before it. It says what happened: the refused block would enter the protection area,
    would leave the work area; the axes stopped before."""
    from hli_server.plot import plot_scene

    through = scene_for(THROUGH_ACTIVE)
    svg = plot_scene(through, tmp_path / "through.svg").read_text(encoding="utf-8")
    assert "the refused block N60 would enter it; the axes stopped before it" in svg
    assert "path goes through it" not in svg
    work = area(scene_for(U_LINE), 3)
    assert work["relation_text"] == "the refused block N170 would leave it; the axes stopped inside"


@pytest.mark.req("E-06")
@MODES
def test_a_software_limit_refusal_gives_the_refused_block_and_where_it_crosses(geometry_only: bool) -> None:
    """Issue 37, item 3: X's software limit is 600 mm on the demo machine; N20 from X100 Y0 to X700 Y100 is
    refused before it starts (120002). The scene draws it as an area's refusal: the refused block, the
    point where it would cross the limit, and what refused it."""
    scene = scene_for("N10 G01 X100 Y0 F6000\nN20 X700 Y100\nN30 M30\n", geometry_only=geometry_only)
    refused = scene["refused"]
    assert (refused["alarm"], refused["line"], refused["block"], refused["area"], refused["axis"]) == (
        120002,
        2,
        "N20",
        None,
        "X",
    )
    assert refused["cause"] == "the software limit of X (600.0000 mm)"
    assert [p[:3] for p in refused["points"]] == [[100.0, 0.0, 0.0], [700.0, 100.0, 0.0]]
    violation = scene["violation"]
    assert violation["point"][:3] == [600.0, 83.3333, 0.0]
    assert violation["position"] == {"X": 600.0, "Y": 83.3333, "Z": 0.0}
    assert violation["point"][3] == pytest.approx(100.0 + math.hypot(500.0, 83.3333), abs=1e-3)
