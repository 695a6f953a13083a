"""The built-in cycle stand-ins run without a machine (tests/unit/cycles_helpers.py's context): their
parameter checks with the kernel's IDs, their moves, the simulated probe's deviation reaching the results,
and the geometry's oracles (docs/cycles.md)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hli_server.engine.cycles import BUILT, NOT_BUILT, CycleError, NotBuilt, StandIn, find, run
from hli_server.engine.cycles.geometry import (
    circle_points,
    fit_circle,
    frame_angles,
    line_points,
    sphere_from_ring,
)
from hli_server.engine.cycles.milling import depth_levels, pocket_rings
from hli_server.engine.cycles.probe import HalfSpace, Hole, Sphere, Spigot, first_touch
from tests.unit.cycles_helpers import FakeContext, close, run_standin

# --- calls as the pages' examples make them (the corpus programs' calls are among them) ---------------
EXAMPLES: dict[str, tuple[tuple[float, float, float], dict[int, float | str]]] = {
    "SysMeasWcs1.ecy": ((-50, 0, -10), {4: 10, 7: 54}),
    "SysMeasWcs2.ecy": ((0, -50, -10), {5: 10}),
    "SysMeasWcs3.ecy": ((0, 0, 10), {6: -10}),
    "SysMeasWcs4.ecy": ((-50, -50, -10), {4: 10, 5: 10, 7: 54, 17: 15, 18: 20}),
    "SysMeasWcs5.ecy": ((-50, 0, 5), {4: 10, 6: -10, 7: 54, 17: 20, 19: -15}),
    "SysMeasWcs6.ecy": ((0, -50, 5), {5: 10, 6: -10, 18: 20, 19: -15}),
    "SysMeasWcs7.ecy": ((0, 0, 5), {4: 10, 5: 10, 6: -10, 7: 54, 17: 20, 18: 15, 19: -13}),
    "SysMeasWcs8.ecy": ((0, 0, -10), {2: 40, 7: 54, 13: 5, 33: 10}),
    "SysMeasWcs9.ecy": ((0, 0, -10), {2: 40, 7: 54, 13: 5, 14: 30, 15: 150, 16: 270, 33: 10}),
    "SysMeasWcs10.ecy": ((0, 0, 5), {2: 20, 7: 54, 13: 10, 19: -10, 33: 10}),
    "SysMeasWcs11.ecy": ((0, 0, 5), {2: 20, 7: 54, 13: 10, 14: 30, 15: 150, 16: 270, 19: -10, 33: 10}),
    "SysMeasWcs14.ecy": ((0, 0, 5), {3: 20, 7: 54, 13: 5, 19: -10, 33: 10}),
    "SysMeasWcs29.ecy": ((0, 0, 5), {7: 54, 13: 10, 19: -15, 31: 40, 32: 60, 33: 10}),
    "SysMeasWcs18.ecy": ((0, 0, 5), {2: 40, 7: 54, 13: 5, 19: -15, 33: 20}),
    "SysMeasWcs19.ecy": ((0, 0, 5), {4: 10, 7: 54, 18: 10, 19: 5, 20: -15}),
    "SysMeasWcs20.ecy": ((0, 0, 5), {5: 10, 7: 54, 17: 10, 19: 5, 20: -15}),
    "SysMeasWcs21.ecy": ((0, 0, 5), {2: 20, 7: 54, 17: 50, 18: 20, 19: 10, 22: -15, 29: 30, 33: 10}),
    "SysMeasWcs22.ecy": ((0, 0, 5), {2: 20, 7: 54, 13: 5, 17: 50, 18: 20, 19: 10, 22: -15, 29: 30, 33: 10}),
    "SysMeasWcs23.ecy": ((0, 0, 5), {2: 20, 22: -15, 29: 30, 17: 50, 18: 20, 19: 10, 33: 10}),
    "SysMeasWcs24.ecy": ((0, 0, 5), {2: 20, 4: 10, 7: 54, 17: 50, 18: 20, 19: 10, 22: -10, 33: 10}),
    "SysMeasWcs26.ecy": ((0, 0, 5), {2: 20, 5: 10, 17: 50, 18: 20, 19: 10, 22: -15, 33: 10}),
    "SysMeasWcs25.ecy": ((0, 0, 5), {2: 20, 4: 10, 7: 54, 13: 10, 17: 50, 18: 20, 19: -15, 22: -10, 33: 10}),
    "SysMeasWcs27.ecy": ((0, 0, 5), {2: 20, 5: 10, 7: 54, 13: 10, 17: 50, 18: 20, 19: 10, 22: -15, 33: 10}),
    "SysMeasWcs36.ecy": ((50, 20, -10), {2: 20, 7: 54, 13: 1, 14: 20, 15: 70, 33: 0.5}),
    "SysMeasWcs38.ecy": ((50, 20, 10), {2: 20, 7: 54, 13: 3, 14: 20, 15: 70, 33: 5}),
    "SysMeasWcs39.ecy": ((50, 20, 10), {2: 20, 7: 54, 13: 3, 14: 20, 15: 70, 33: 5}),
    "SysMeasWcs40.ecy": ((100, 300, 10), {6: 100, 7: 56, 13: 100, 14: 90, 15: 45, 33: 100, 64: 1, 87: 400}),
    "SysMeasCs1.ecy": ((0, 0, 0), {39: 1}),
    "SysMeasCs2.ecy": ((0, 0, 0), {4: 30, 5: 30, 6: -40, 9: 0, 10: 0, 11: 0, 14: 0, 15: 90, 16: 0, 39: 3}),
    "SysMeasCs5.ecy": ((0, 0, 0), {6: 40, 39: 2, 41: 40, 42: 60, 43: 40, 44: 50, 87: 20}),
    "SysCalibTouchprobe1.ecy": ((100, 100, 50), {2: 50, 14: 20, 15: 70, 33: 30}),
    "SysDrillCenterHole.ecy": ((20, 20, 100), {1: 0, 2: 20, 3: 5, 4: 6, 17: 1}),
    "SysDrillDeepHole.ecy": ((20, 20, 100), {1: 0, 2: 20, 3: 5, 4: 25, 11: 3, 31: 2, 61: 0.5}),
    "SysDrillReaming.ecy": ((0, 20, 100), {1: 0, 2: 20, 3: 5, 4: 24}),
    "SysDrillBoring.ecy": ((0, 20, 100), {1: 0, 2: 20, 3: 5, 4: 24, 92: 2, 93: 0.2, 62: 90}),
    "SysDrillPatternLine.ecy": (
        (0, 0, 100),
        {1: 0, 2: 20, 3: 2, 4: 30, 11: 3, 31: 2, 61: 0.5, 100: "SysDrillDeepHole", 104: 10, 107: 4},
    ),
    "SysDrillPatternCircle.ecy": (
        (0, 0, 100),
        {1: 0, 2: 20, 3: 2, 4: 30, 11: 3, 31: 2, 61: 0.5, 100: "SysDrillDeepHole", 107: 6, 111: 30},
    ),
    "SysMillRectangularPocket.ecy": (
        (50, 50, 60),
        {1: 0, 2: 50, 3: 2, 4: 12, 5: 4, 6: 4, 21: 1000, 31: "Roughing", 72: 20, 73: 20},
    ),
    "SysMillCircularPocket.ecy": (
        (50, 50, 60),
        {1: 0, 2: 50, 3: 2, 4: 20, 5: 3, 6: 4, 20: 600, 21: 400, 31: "Roughing", 68: 20},
    ),
}


def test_every_built_cycle_has_an_example() -> None:
    assert sorted(EXAMPLES) == sorted(s.name for s in BUILT)


@pytest.mark.req("CY-01", "CY-03")
@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_the_pages_example_runs(name: str) -> None:
    """Every stand-in runs its page's example call: blocks the parser made, back where the caller's modal
    state is restored, the documented outputs written."""
    start, params = EXAMPLES[name]
    # the page's three spheres are 2.4 mm apart: a probe of radius 2 would touch the 2nd beside the 3rd
    ctx = run_standin(name, params, FakeContext(start, radius=0.5 if name == "SysMeasCs5.ecy" else 2.0))
    spec = find(name)
    assert isinstance(spec, StandIn)
    assert ctx.blocks, name
    reference = params.get(100)
    owners = {spec.name, f"{reference}.ecy"}
    assert all(b.program in owners for b in ctx.blocks)
    assert ctx.blocks[-1].g_codes == (1, 90)
    assert ctx.blocks[-1].feed == 1000.0
    for out in spec.outputs:
        assert out.name in ctx.results, (name, out.name)
    if spec.measuring and name not in ("SysMeasCs1.ecy",):
        assert any(100 in b.g_codes for b in ctx.blocks)


def test_a_measuring_cycle_returns_to_its_start() -> None:
    for name in (
        "SysMeasWcs1.ecy",
        "SysMeasWcs7.ecy",
        "SysMeasWcs9.ecy",
        "SysMeasWcs39.ecy",
        "SysMeasWcs40.ecy",
    ):
        start, params = EXAMPLES[name]
        ctx = run_standin(name, params, FakeContext(start, radius=1.0))
        assert all(close(a, b) for a, b in zip(ctx.at, start, strict=True)), name


# --- the simulated probe's deviation reaches the results exactly ----------------------------------------
deviation = st.tuples(*(st.floats(-0.4, 0.4, allow_nan=False),) * 3)
"""Within every example's crossover (the smallest is SysMeasWcs36's 0.5 mm)."""
radius = st.floats(0.0, 3.0, allow_nan=False)


@pytest.mark.req("CY-04", "CY-05")
@settings(max_examples=40, deadline=None)
@given(dev=deviation, r=radius)
def test_a_hole_off_by_a_deviation_is_measured_off_by_it(dev: tuple[float, float, float], r: float) -> None:
    for name in ("SysMeasWcs8.ecy", "SysMeasWcs9.ecy", "SysMeasWcs36.ecy"):
        start, params = EXAMPLES[name]
        ctx = run_standin(name, params, FakeContext(start, radius=r, deviation=dev))
        assert close(ctx.results["SysRetX"], start[0] + dev[0]), name
        assert close(ctx.results["SysRetY"], start[1] + dev[1]), name
        assert close(ctx.results["SysRetDiameter"], params[2]), name
        assert close(ctx.offsets["G54"]["X"], start[0] + dev[0])


@pytest.mark.req("CY-04", "CY-05")
@settings(max_examples=40, deadline=None)
@given(dev=deviation, r=radius)
def test_a_spigot_off_by_a_deviation_is_measured_off_by_it(dev: tuple[float, float, float], r: float) -> None:
    for name in ("SysMeasWcs10.ecy", "SysMeasWcs11.ecy", "SysMeasWcs38.ecy", "SysMeasWcs39.ecy"):
        start, params = EXAMPLES[name]
        ctx = run_standin(name, params, FakeContext(start, radius=r, deviation=(dev[0], dev[1], 0.0)))
        assert close(ctx.results["SysRetX"], start[0] + dev[0]), name
        assert close(ctx.results["SysRetY"], start[1] + dev[1]), name
        assert close(ctx.results["SysRetDiameter"], params[2]), name


@pytest.mark.req("CY-04")
@settings(max_examples=40, deadline=None)
@given(dev=deviation, r=radius)
def test_a_block_and_a_web_off_by_a_deviation(dev: tuple[float, float, float], r: float) -> None:
    start, params = EXAMPLES["SysMeasWcs29.ecy"]
    ctx = run_standin("SysMeasWcs29.ecy", params, FakeContext(start, radius=r, deviation=dev))
    assert close(ctx.results["SysRetX"], dev[0])
    assert close(ctx.results["SysRetY"], dev[1])
    assert close(ctx.results["SysRetLengthX"], 40.0)
    assert close(ctx.results["SysRetLengthY"], 60.0)
    start, params = EXAMPLES["SysMeasWcs14.ecy"]
    ctx = run_standin("SysMeasWcs14.ecy", params, FakeContext(start, radius=r, deviation=dev))
    assert close(ctx.results["SysRetX"], dev[0])
    assert close(ctx.results["SysRetLengthX"], 20.0)


@pytest.mark.req("CY-04")
@settings(max_examples=40, deadline=None)
@given(dev=deviation, r=radius)
def test_faces_off_by_a_deviation_are_measured_off_by_it(dev: tuple[float, float, float], r: float) -> None:
    start, params = EXAMPLES["SysMeasWcs7.ecy"]
    nominal = run_standin("SysMeasWcs7.ecy", params, FakeContext(start, radius=r))
    ctx = run_standin("SysMeasWcs7.ecy", params, FakeContext(start, radius=r, deviation=dev))
    for axis, d in zip("XYZ", dev, strict=True):
        assert close(ctx.results[f"SysRet{axis}"], nominal.results[f"SysRet{axis}"] + d), axis


@pytest.mark.req("CY-04")
@settings(max_examples=25, deadline=None)
@given(dev=deviation, r=radius)
def test_a_sphere_and_three_spheres(dev: tuple[float, float, float], r: float) -> None:
    start, params = EXAMPLES["SysMeasWcs40.ecy"]
    nominal = run_standin("SysMeasWcs40.ecy", params, FakeContext(start, radius=r))
    ctx = run_standin("SysMeasWcs40.ecy", params, FakeContext(start, radius=r, deviation=dev))
    for axis, d in zip("XYZ", dev, strict=True):
        assert close(ctx.results[f"SysRet{axis}"], nominal.results[f"SysRet{axis}"] + d), axis
    assert close(ctx.results["SysRetDiameter"], 400.0)
    # a pure shift of the three spheres: the CS's origin moves by it, its angles stay 0
    cs = dict(EXAMPLES["SysMeasCs5.ecy"][1])
    cs.update({41: 60, 43: 0, 42: 0, 44: 60})
    base = run_standin("SysMeasCs5.ecy", cs, FakeContext((0, 0, 0), radius=r))
    moved = run_standin("SysMeasCs5.ecy", cs, FakeContext((0, 0, 0), radius=r, deviation=dev))
    for axis, d in zip("XYZ", dev, strict=True):
        assert close(moved.results[f"SysRet{axis}"], base.results[f"SysRet{axis}"] + d), axis
    for axis in "ABC":
        assert close(moved.results[f"SysRet{axis}"], 0.0, 1e-6)


def test_the_point_and_spigot_angle() -> None:
    """SysMeasWcs27: the angle of the line from the measured point to the spigot's centre, less @P12."""
    start, params = EXAMPLES["SysMeasWcs27.ecy"]
    ctx = run_standin("SysMeasWcs27.ecy", params, FakeContext(start, radius=0.0))
    # the point: y of the edge 5 (the path 10 less the crossover 5) at x 0; the spigot at (50, 20)
    assert close(ctx.results["SysRetC"], math.degrees(math.atan2(20 - 5, 50 - 0)))
    shifted = run_standin(
        "SysMeasWcs27.ecy", {**params, 12: 10.0}, FakeContext(start, radius=0.0, deviation=(0, 1, 0))
    )
    assert close(shifted.results["SysRetC"], math.degrees(math.atan2(21 - 6, 50 - 0)) - 10.0)
    assert ctx.warnings
    assert ctx.warnings[0][0] == 917001


@pytest.mark.req("CY-04", "CY-06")
@settings(max_examples=25, deadline=None)
@given(dev=deviation, r=radius)
def test_twists_are_those_of_the_nominal_part_when_it_is_only_shifted(
    dev: tuple[float, float, float], r: float
) -> None:
    """The angle cycles measure a rotation: a part shifted without turning keeps its angles (the faces' twist
    0, the line between two centres its nominal angle), whatever the probe's radius."""
    for name in ("SysMeasWcs19.ecy", "SysMeasWcs20.ecy"):
        start, params = EXAMPLES[name]
        assert close(
            run_standin(name, params, FakeContext(start, radius=r, deviation=dev)).results["SysRetC"], 0.0
        )
    for name in ("SysMeasWcs21.ecy", "SysMeasWcs22.ecy", "SysMeasWcs23.ecy"):
        start, params = EXAMPLES[name]
        found = run_standin(
            name, {**params, 12: 3.0}, FakeContext(start, radius=r, deviation=(dev[0], dev[1], 0.0))
        )
        assert close(found.results["SysRetC"], math.degrees(math.atan2(20, 50)) - 3.0), name


def test_calibration_finds_the_probe_radius_wherever_the_ring_is() -> None:
    start, params = EXAMPLES["SysCalibTouchprobe1.ecy"]
    for dev in ((0.0, 0.0, 0.0), (0.7, -0.4, 0.0)):
        ctx = run_standin("SysCalibTouchprobe1.ecy", params, FakeContext(start, radius=2.5, deviation=dev))
        assert close(ctx.results["SysRetToolRadius"], 2.5)


def test_teach_in_writes_the_cs_subroutine() -> None:
    ctx = run_standin(
        "SysMeasCs2.ecy",
        EXAMPLES["SysMeasCs2.ecy"][1],
        FakeContext((0, 0, 0), radius=1.0, deviation=(0.5, 0.25, -0.125)),
    )
    text = ctx.programs["CS_BASE_3.bcs"]
    assert text.startswith("%CS_BASE_3.bcs\n")
    x, y, z = ctx.results["SysRetX"], ctx.results["SysRetY"], ctx.results["SysRetZ"]
    # the touches 5 mm (the crossover) before the paths' ends, the faces a probe radius beyond the centre
    assert close(x, 26.5)
    assert close(y, 26.25)
    assert close(z, -35.125)
    assert "#CS DEF [3][26.5,26.25,-35.125,0,90,0]" in text
    assert "#CS ON [3]" in text
    assert text.endswith("M17\n")


# --- the error IDs ------------------------------------------------------------------------------------
def _error(name: str, params: dict[int, float | str], ctx: FakeContext | None = None) -> CycleError:
    with pytest.raises(CycleError) as info:
        run_standin(name, params, ctx or FakeContext(EXAMPLES[name][0], radius=2.0))
    return info.value


@pytest.mark.req("CY-02")
@pytest.mark.parametrize(
    ("name", "change", "alarm", "param"),
    [
        ("SysMeasWcs1.ecy", {4: None}, 917000, 4),
        ("SysMeasWcs1.ecy", {4: 0}, 917000, 4),
        ("SysMeasWcs1.ecy", {7: 60}, 13408, 7),
        ("SysMeasWcs1.ecy", {7: 2.5}, 13408, 7),
        ("SysMeasWcs1.ecy", {7: 57.0, 4: 10}, None, 0),
        ("SysMeasWcs8.ecy", {2: -4}, 917000, 2),
        ("SysMeasWcs9.ecy", {15: 30}, 917000, 15),
        ("SysMeasWcs11.ecy", {19: None}, 917000, 19),
        ("SysMeasCs1.ecy", {39: 11}, 13448, 39),
        ("SysMeasCs1.ecy", {39: 2.5}, 13448, 39),
        ("SysMeasCs5.ecy", {87: None}, 917000, 87),
        ("SysDrillCenterHole.ecy", {3: 0}, 13100, 3),
        ("SysDrillCenterHole.ecy", {3: None}, 13100, 3),
        ("SysDrillCenterHole.ecy", {182: 1}, 910110, 182),
        ("SysDrillCenterHole.ecy", {2: 1}, 917000, 2),
        ("SysDrillDeepHole.ecy", {11: None}, 13103, 11),
        ("SysDrillDeepHole.ecy", {61: None}, 13105, 61),
        ("SysDrillDeepHole.ecy", {31: 3}, 917000, 31),
        ("SysDrillPatternLine.ecy", {100: "SysDrillNothing"}, 14346, 100),
        ("SysDrillPatternLine.ecy", {100: 5}, 14346, 100),
        ("SysDrillPatternLine.ecy", {100: None}, 14346, 100),
        ("SysMillRectangularPocket.ecy", {31: "Polishing"}, 13166, 31),
        ("SysMillRectangularPocket.ecy", {31: 4}, 13166, 31),
        ("SysMillRectangularPocket.ecy", {5: None}, 13103, 5),
        ("SysMillRectangularPocket.ecy", {6: 9}, 917000, 6),
        ("SysMillCircularPocket.ecy", {68: 1}, 14327, 68),
        ("SysMillCircularPocket.ecy", {68: None}, 14327, 68),
    ],
)
def test_parameter_errors_carry_the_kernels_ids(
    name: str, change: dict[int, float | str | None], alarm: int | None, param: int
) -> None:
    params: dict[int, float | str] = dict(EXAMPLES[name][1])
    for k, v in change.items():
        if v is None:
            params.pop(k, None)
        else:
            params[k] = v
    if alarm is None:
        ctx = run_standin(name, params, FakeContext(EXAMPLES[name][0], radius=1.0))
        assert "G57" in ctx.offsets
        return
    err = _error(name, params)
    assert err.alarm == alarm, err.message
    assert err.param == param
    assert name in err.message


@pytest.mark.req("CY-05")
def test_writing_a_zero_offset_needs_g53() -> None:
    err = _error(
        "SysMeasWcs1.ecy", EXAMPLES["SysMeasWcs1.ecy"][1], FakeContext((-50, 0, -10), zero_offset="G55")
    )
    assert err.alarm == 14421
    assert "G55" in err.message
    ctx = run_standin("SysMeasWcs1.ecy", {4: 10}, FakeContext((-50, 0, -10), zero_offset="G55"))
    assert ctx.offsets == {}
    assert "SysRetX" in ctx.results


@pytest.mark.req("CY-04")
def test_no_workpiece_is_13413() -> None:
    start, params = EXAMPLES["SysMeasWcs1.ecy"]
    err = _error("SysMeasWcs1.ecy", params, FakeContext(start, radius=1.0, deviation=(5.5, 0, 0)))
    assert err.alarm == 13413
    assert "no workpiece detected" in err.message
    err = _error("SysMeasWcs8.ecy", EXAMPLES["SysMeasWcs8.ecy"][1], FakeContext((0, 0, -10), radius=25.0))
    assert err.alarm == 917000
    assert "does not fit the hole" in err.message


@pytest.mark.req("CY-04")
def test_a_spigot_in_the_way_of_a_positioning_move_is_13414() -> None:
    start, params = EXAMPLES["SysMeasWcs39.ecy"]
    err = _error("SysMeasWcs39.ecy", params, FakeContext(start, radius=1.0, deviation=(14.0, 0, 0)))
    assert err.alarm == 13414
    assert "collision on positioning" in err.message


def test_a_cycle_not_built_is_refused_naming_it() -> None:
    found = find("SysMillFace.ecy")
    assert isinstance(found, NotBuilt)
    with pytest.raises(CycleError) as info:
        run("sysmillface", {}, FakeContext(), 1)
    assert info.value.alarm == 910110
    assert "SysMillFace.ecy" in info.value.message
    assert run("MyOwnCycle.ecy", {}, FakeContext(), 1) is None
    assert {c.name for c in NOT_BUILT}.isdisjoint({c.name for c in BUILT})


def test_names_are_found_without_regard_to_case_or_extension() -> None:
    assert find("sysmeaswcs27.ECY") is find("SysMeasWcs27") is find('"SysMeasWcs27.ecy"')


# --- geometric oracles ----------------------------------------------------------------------------------
@settings(max_examples=60, deadline=None)
@given(
    cx=st.floats(-100, 100),
    cy=st.floats(-100, 100),
    r=st.floats(0.5, 200),
    angles=st.lists(st.floats(0, 360), min_size=3, max_size=8, unique=True),
)
def test_fit_circle_is_exact_for_points_on_a_circle(
    cx: float, cy: float, r: float, angles: list[float]
) -> None:
    pts = [(cx + r * math.cos(math.radians(a)), cy + r * math.sin(math.radians(a))) for a in angles]
    spread = max(angles) - min(angles)
    if spread < 30 or any(abs(a - b) < 5.0 for i, a in enumerate(angles) for b in angles[i + 1 :]):
        return
    (fx, fy), fr = fit_circle(pts)
    assert close(fx, cx, 1e-6 * r + 1e-6)
    assert close(fy, cy, 1e-6 * r + 1e-6)
    assert close(fr, r, 1e-6 * r + 1e-6)


def test_sphere_from_an_off_centre_top_touch() -> None:
    centre, reach = (1.0, 2.0, -30.0), 12.0
    top = (1.5, 1.0, centre[2] + math.sqrt(reach**2 - 0.25 - 1.0))
    ring_h = -33.0
    rho = math.sqrt(reach**2 - 9.0)
    ring = [(1.0 + rho * math.cos(a), 2.0 + rho * math.sin(a)) for a in (0.1, 1.7, 3.9, 5.0)]
    (x, y, z), found = sphere_from_ring(top, ring, ring_h)
    assert close(x, 1.0)
    assert close(y, 2.0)
    assert close(z, -30.0)
    assert close(found, 12.0)


def test_frame_angles_of_a_turned_triangle() -> None:
    nominal = [(0.0, 0.0, 0.0), (10.0, 0.0, 0.0), (0.0, 10.0, 0.0)]
    c = math.radians(7.0)
    turned = [
        (x * math.cos(c) - y * math.sin(c) + 3, x * math.sin(c) + y * math.cos(c) - 1, 2.0)
        for x, y, _ in nominal
    ]
    a, b, cc = frame_angles(nominal, turned)
    assert close(a, 0.0)
    assert close(b, 0.0)
    assert close(cc, 7.0)


@pytest.mark.req("CY-06")
@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 12),
    d=st.floats(-50, 50),
    rot=st.floats(-180, 180),
    x=st.floats(-100, 100),
    y=st.floats(-100, 100),
)
def test_the_row_pattern_drills_where_the_page_says(n: int, d: float, rot: float, x: float, y: float) -> None:
    ctx = run_standin(
        "SysDrillPatternLine.ecy",
        {1: 0, 2: 20, 3: 2, 4: 5, 100: "SysDrillCenterHole", 104: d, 107: n, 101: x, 102: y, 109: rot},
        FakeContext((0, 0, 100)),
    )
    bottoms = [(b.axes, e) for s, e, b in ctx.path if close(e[2], -5.0)]
    assert len(bottoms) == n
    expect = line_points((x, y), d, n, rot)
    for (_, end), (px, py) in zip(bottoms, expect, strict=True):
        assert close(end[0], px)
        assert close(end[1], py)
        assert close(end[0], x + (expect.index((px, py))) * d * math.cos(math.radians(rot)))


@pytest.mark.req("CY-06")
@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 12), r=st.floats(1, 80), start=st.floats(-180, 180))
def test_the_circle_pattern_drills_where_the_page_says(n: int, r: float, start: float) -> None:
    ctx = run_standin(
        "SysDrillPatternCircle.ecy",
        {1: 0, 2: 20, 3: 2, 4: 5, 100: "SysDrillReaming", 107: n, 111: r, 112: start},
        FakeContext((10, -5, 100)),
    )
    bottoms = [e for s, e, b in ctx.path if close(e[2], -5.0)]
    for (ex, ey, _), (px, py) in zip(bottoms, circle_points((10, -5), r, n, start, 360.0 / n), strict=True):
        assert close(ex, px)
        assert close(ey, py)
        assert close(math.hypot(ex - 10, ey + 5), r)
    assert len(bottoms) == n


def _swept_inside_rect(ctx: FakeContext, cx: float, cy: float, hx: float, hy: float, r: float) -> bool:
    for s, e, _ in ctx.path:
        for p in (s, e):
            if p[2] < 0 and (abs(p[0] - cx) > hx - r + 2e-6 or abs(p[1] - cy) > hy - r + 2e-6):
                return False
    return True


@pytest.mark.req("CY-06")
@settings(max_examples=40, deadline=None)
@given(
    length=st.floats(6, 80),
    width=st.floats(6, 80),
    r=st.floats(0.5, 2.9),
    step_frac=st.floats(0.1, 1.0),
    depth=st.floats(0.5, 30),
    dz=st.floats(0.5, 10),
    mode=st.sampled_from([1, 2, 3]),
)
def test_a_rectangular_pocket_stays_inside_its_outline(
    length: float, width: float, r: float, step_frac: float, depth: float, dz: float, mode: int
) -> None:
    ctx = run_standin(
        "SysMillRectangularPocket.ecy",
        {
            1: 0,
            2: 50,
            3: 2,
            4: depth,
            5: dz,
            6: 2 * r * step_frac,
            21: 500,
            31: mode,
            72: length,
            73: width,
            16: 0.1,
            15: 0.1,
        },
        FakeContext((40, 30, 60), radius=r),
    )
    assert _swept_inside_rect(ctx, 40, 30, length / 2, width / 2, r)
    assert min(e[2] for _, e, _ in ctx.path) >= -depth - 1e-6  # 1e-6: the blocks' text holds 1 nm
    if mode != 2:  # roughing: every infeed at most @P5 (finishing alone goes to the depth at once)
        levels = sorted({round(e[2], 9) for _, e, b in ctx.path if e[2] < 0}, reverse=True)
        for a, b in zip([0.0, *levels], levels, strict=False):
            assert a - b <= dz + 1e-6


@pytest.mark.req("CY-06")
@settings(max_examples=40, deadline=None)
@given(
    d=st.floats(8, 80), r=st.floats(0.5, 3.5), step_frac=st.floats(0.1, 1.0), mode=st.sampled_from([1, 2, 3])
)
def test_a_circular_pocket_stays_inside_its_outline(d: float, r: float, step_frac: float, mode: int) -> None:
    ctx = run_standin(
        "SysMillCircularPocket.ecy",
        {1: 0, 2: 50, 3: 2, 4: 10, 5: 3, 6: 2 * r * step_frac, 20: 500, 31: mode, 68: d},
        FakeContext((0, 0, 60), radius=r),
    )
    for s, e, b in ctx.path:
        for p in (s, e):
            if p[2] < 0:
                assert math.hypot(p[0], p[1]) <= d / 2 - r + 2e-6
        if 2 in b.g_codes or 3 in b.g_codes:  # an arc's every point: its radius about the centre
            assert math.hypot(s[0], s[1]) <= d / 2 - r + 2e-6


@given(final=st.floats(0, 100), step=st.floats(0.01, 50))
def test_pocket_rings_step_at_most_the_infeed(final: float, step: float) -> None:
    rings = pocket_rings(final, step)
    assert close(rings[-1], final)
    assert all(b - a <= step + 1e-9 for a, b in zip([0.0, *rings], rings, strict=False))


@given(top=st.floats(-50, 50), depth=st.floats(0, 60), step=st.floats(0.1, 20))
def test_depth_levels_step_at_most_the_infeed(top: float, depth: float, step: float) -> None:
    levels = depth_levels(top, top - depth, step)
    assert close(levels[-1], top - depth)
    assert all(a - b <= step + 1e-9 for a, b in zip([top, *levels], levels, strict=False))


# --- the probe's contact geometry ---------------------------------------------------------------------
def test_first_touch_of_each_feature() -> None:
    assert close(first_touch(HalfSpace((5, 0, 0), (-1, 0, 0)), (0, 0, 0), (10, 0, 0), 1.0) or 0, 0.4)
    assert first_touch(HalfSpace((5, 0, 0), (-1, 0, 0)), (0, 0, 0), (-10, 0, 0), 1.0) is None
    assert close(first_touch(HalfSpace((0, 0, -5), (0, 0, 1)), (0, 0, 0), (0, 0, -10), 1.0) or 0, 0.5)
    assert close(first_touch(Hole((0, 0, 0), 10), (0, 0, 0), (20, 0, 0), 2.0) or 0, 0.4)
    assert close(first_touch(Spigot((0, 0, 0), 10, 0), (20, 0, -5), (0, 0, -5), 2.0) or 0, 0.4)
    assert first_touch(Spigot((0, 0, 0), 10, 0), (20, 0, 5), (0, 0, 5), 2.0) is None  # above its top
    assert close(
        first_touch(Spigot((0, 0, 0), 10, 0), (5, 0, 10), (5, 0, -10), 1.0) or 0, 0.5
    )  # onto its top
    assert close(first_touch(Sphere((0, 0, 0), 10), (0, 0, 20), (0, 0, 0), 1.0) or 0, 0.5)
