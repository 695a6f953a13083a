"""FCT-C14 in manual mode: jogging stops before every kind of boundary, without an error (C14-19..22)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import pytest
from shapely.geometry import Point as ShapelyPoint
from shapely.geometry import Polygon as ShapelyPolygon

from hli_server.engine.machine import Machine
from schemas.wire import Mode, ProgramState

from .helpers import alarm_ids, errors, make_machine, run

WORK_SQUARE = """#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=-30 MAX_EXCUR=20]
G01 X-50 Y-50 F1000
X50
Y50
X-50
Y-50
#CONTROL AREA END
"""
WORK_CIRCLE = """#CONTROL AREA BEGIN [ID=2 WORK CIRC MIN_EXCUR=-30 MAX_EXCUR=30]
G01 X0 Y-40 F1000
G03 I0 J40
#CONTROL AREA END
"""
PROT_SQUARE = """#CONTROL AREA BEGIN [ID=3 PROT POLY MIN_EXCUR=-30 MAX_EXCUR=30]
G01 X30 Y-10 F1000
X60
Y10
X30
Y-10
#CONTROL AREA END
"""
PROT_CIRCLE = """#CONTROL AREA BEGIN [ID=4 PROT CIRC MIN_EXCUR=-30 MAX_EXCUR=30]
G01 X-40 Y0 F1000
G02 I-10 J0
#CONTROL AREA END
"""

_SQUARE = ShapelyPolygon([(-50, -50), (50, -50), (50, 50), (-50, 50)])
_PROT_SQUARE = ShapelyPolygon([(30, -10), (60, -10), (60, 10), (30, 10)])


@dataclass(frozen=True)
class Boundary:
    """One kind of boundary: its definition, where the jog starts, which keys, and the oracle:
    ``gap(point)`` >= 0 is allowed (< 0 forbidden; for protection 0 is forbidden too)."""

    name: str
    program: str
    start: tuple[float, float, float]
    keys: tuple[tuple[str, int], ...]
    gap: Callable[[tuple[float, ...]], float]
    protection: bool


BOUNDARIES = [
    Boundary(
        "work polygon edge",
        WORK_SQUARE,
        (35.0, 0.0, 0.0),
        (("X", +1),),
        lambda p: (
            _SQUARE.exterior.distance(ShapelyPoint(p[0], p[1]))
            * (1 if _SQUARE.covers(ShapelyPoint(p[0], p[1])) else -1)
        ),
        False,
    ),
    Boundary(
        "work circle",
        WORK_CIRCLE,
        (0.0, 25.0, 0.0),
        (("Y", +1),),
        lambda p: 40.0 - math.hypot(p[0], p[1]),
        False,
    ),
    Boundary(
        "protection polygon",
        PROT_SQUARE,
        (15.0, 0.0, 0.0),
        (("X", +1),),
        lambda p: _PROT_SQUARE.distance(ShapelyPoint(p[0], p[1])),
        True,
    ),
    Boundary(
        "protection circle",
        PROT_CIRCLE,
        (-25.0, 0.0, 0.0),
        (("X", -1),),
        lambda p: math.hypot(p[0] + 50.0, p[1]) - 10.0,
        True,
    ),
    Boundary(
        "height band",
        WORK_SQUARE,
        (0.0, 0.0, 5.0),
        (("Z", +1),),
        lambda p: 20.0 - p[2],
        False,
    ),
    Boundary(
        "protection circle, two axes",
        PROT_CIRCLE,
        (-35.0, 15.0, 0.0),
        (("X", -1), ("Y", -1)),
        lambda p: math.hypot(p[0] + 50.0, p[1]) - 10.0,
        True,
    ),
]

SPEEDS = [(600.0, 1000.0), (3000.0, 1000.0), (12000.0, 2000.0), (6000.0, 300.0)]
"""(jog velocity mm/min, jog acceleration mm/s²)"""


def setup(boundary: Boundary, jog_velocity: float, jog_acceleration: float, **kw: object) -> Machine:
    m = make_machine(
        axis={"jog_velocity": jog_velocity, "jog_acceleration": jog_acceleration, "v_max": 60000.0},
        **kw,  # type: ignore[arg-type]
    )
    x, y, z = boundary.start
    ch = run(m, boundary.program + f"G01 X{x} Y{y} Z{z} F30000\n#CONTROL AREA ON ALL\nM30\n")
    assert ch.state == ProgramState.FINISHED, [a.message for a in m.alarm_history]
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    assert ch.mode == Mode.MANUAL
    return m


def jog_until_rest(m: Machine, boundary: Boundary, max_cycles: int = 20_000) -> tuple[float, ...]:
    """Hold the keys; assert every cycle that the setpoints are allowed; return the rest point."""
    ch = m.channel(1)
    for axis, direction in boundary.keys:
        ch.request_jog(axis, direction)
    still = 0
    moved = False
    previous = tuple(ch.setpoints())
    for _ in range(max_cycles):
        m.step(1)
        point = tuple(ch.setpoints())
        gap = boundary.gap(point)
        assert gap >= 0.0, f"{boundary.name}: cycle {m.cycle} at {point} is beyond the boundary ({gap})"
        if boundary.protection:
            assert gap > 0.0, f"{boundary.name}: cycle {m.cycle} touches the protection area at {point}"
        if point == previous:
            still += 1
            if still >= 50 and moved:
                return point
        else:
            still = 0
            moved = True
        previous = point
    raise AssertionError(f"{boundary.name}: no rest after {max_cycles} cycles, at {ch.setpoints()}")


@pytest.mark.req("C14-19", "C14-21")
@pytest.mark.parametrize("boundary", BOUNDARIES, ids=[b.name for b in BOUNDARIES])
@pytest.mark.parametrize(("jog_velocity", "jog_acceleration"), SPEEDS)
def test_jog_stops_before_the_boundary(
    boundary: Boundary, jog_velocity: float, jog_acceleration: float
) -> None:
    m = setup(boundary, jog_velocity, jog_acceleration)
    rest = jog_until_rest(m, boundary)
    gap = boundary.gap(rest)
    # braking starts when the rest point of the next cycle would pass the boundary: the axes come
    # to rest less than 1.5 cycles of travel before it (plus the ramp's discretisation)
    t_a = m.t_a
    v = jog_velocity / 60.0 * (math.sqrt(2.0) if len(boundary.keys) == 2 else 1.0)
    assert 0.0 <= gap <= 1.5 * v * t_a + 2.0 * jog_acceleration * t_a**2, f"stopped {gap} mm before it"
    assert errors(m) == []  # a stop, not an error
    assert 912004 not in alarm_ids(m)  # P-MANU-00014 not set: no warning
    flag = m.hli.channels[0].bahn_state
    assert flag.area_mon_violation_detected_r  # held at the boundary
    assert m.channel(1).jog_velocity == [0.0] * 6


@pytest.mark.req("C14-19")
def test_warning_with_p_manu_00014_and_flag_clears_when_jogging_away() -> None:
    boundary = BOUNDARIES[0]
    m = setup(boundary, 3000.0, 1000.0, move_limit_warning=True)
    jog_until_rest(m, boundary)
    warnings = [a for a in m.alarm_history if a.number == 912004]
    assert len(warnings) == 1
    assert warnings[0].severity == "warning"
    assert "work area 1" in warnings[0].message
    x = m.channel(1).axis("X").setpoint  # the warning names where the axes came to rest
    assert f"at (X{round(x, 4):g}, " in warnings[0].message
    assert errors(m) == []
    ch = m.channel(1)
    ch.request_jog("X", -1)
    m.step(50)
    assert ch.axis("X").setpoint < 49.0
    assert not m.hli.channels[0].bahn_state.area_mon_violation_detected_r


@pytest.mark.req("C14-22")
def test_suppress_unit_lets_the_axes_move_freely() -> None:
    boundary = BOUNDARIES[2]  # protection polygon at x = 30
    m = setup(boundary, 12000.0, 2000.0)
    unit = m.hli.channels[0].bahn_mc_control.suppress_area_mon_manual_mode
    unit.enable_w = True
    unit.command_w = True
    ch = m.channel(1)
    ch.request_jog("X", +1)
    m.step(300)
    assert ch.axis("X").setpoint > 40.0  # inside the protection area
    assert unit.state_r
    assert errors(m) == []


@pytest.mark.req("C14-20")
def test_p_chan_00442_mode_1_no_monitoring_in_manual_mode() -> None:
    boundary = BOUNDARIES[0]
    m = setup(boundary, 12000.0, 2000.0, suppress_workspace_monitoring_manual_mode=1)
    ch = m.channel(1)
    ch.request_jog("X", +1)
    m.step(300)
    assert ch.axis("X").setpoint > 55.0
    ch.request_jog("X", 0)
    m.step(300)
    ch.request_mode(Mode.AUTOMATIC)
    m.step(1)
    ch.request_mode(Mode.MANUAL)  # outside the work area: allowed with 1
    m.step(1)
    assert ch.mode == Mode.MANUAL
    assert errors(m) == []


def _jog_out_with_unit(m: Machine, axis: str, target: float) -> None:
    """Jog out of the allowed space with the suppress unit, then back to automatic, unit off."""
    ch = m.channel(1)
    unit = m.hli.channels[0].bahn_mc_control.suppress_area_mon_manual_mode
    unit.enable_w = unit.command_w = True
    ch.request_jog(axis, +1)
    while ch.axis(axis).setpoint < target:
        m.step(1)
    ch.request_jog(axis, 0)
    m.step(300)
    ch.request_mode(Mode.AUTOMATIC)
    m.step(1)
    unit.command_w = False
    m.step(1)
    assert ch.mode == Mode.AUTOMATIC


@pytest.mark.req("C14-20")
def test_p_chan_00442_mode_0_entering_manual_outside_the_work_area_is_50961() -> None:
    m = setup(BOUNDARIES[0], 12000.0, 2000.0)
    _jog_out_with_unit(m, "X", 60.0)
    ch = m.channel(1)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    assert ch.mode == Mode.AUTOMATIC  # refused
    alarm = next(a for a in m.alarm_history if a.number == 50961)
    assert "outside the work area(s) 1" in alarm.message
    assert m.hli.channels[0].bahn_state.area_mon_violation_detected_r


@pytest.mark.req("C14-20")
def test_p_chan_00442_mode_0_entering_manual_in_a_protection_area_is_50962() -> None:
    m = setup(BOUNDARIES[2], 12000.0, 2000.0)
    _jog_out_with_unit(m, "X", 40.0)
    ch = m.channel(1)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    assert ch.mode == Mode.AUTOMATIC
    alarm = next(a for a in m.alarm_history if a.number == 50962)
    assert "protection area 3" in alarm.message


@pytest.mark.req("C14-20", "C14-22")
def test_p_chan_00442_mode_2_manual_outside_allowed_back_only_with_the_unit() -> None:
    m = setup(BOUNDARIES[0], 12000.0, 2000.0, suppress_workspace_monitoring_manual_mode=2)
    _jog_out_with_unit(m, "X", 60.0)
    ch = m.channel(1)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    assert ch.mode == Mode.MANUAL  # no check on entering
    assert errors(m) == []
    x = ch.axis("X").setpoint
    ch.request_jog("X", -1)  # monitoring is active: outside, nothing may move
    m.step(100)
    assert ch.axis("X").setpoint == x
    unit = m.hli.channels[0].bahn_mc_control.suppress_area_mon_manual_mode
    unit.command_w = True
    m.step(600)
    assert ch.axis("X").setpoint < 50.0  # back inside with the unit
    assert errors(m) == []
