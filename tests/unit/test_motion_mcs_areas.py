"""The area monitors (FCT-C14) with coordinate systems and tools active (issue 24, M-15, M-19)."""

from __future__ import annotations

from typing import Any

import pytest

from hli_server.engine.machine import Machine
from schemas.config import AxisConfig, ChannelConfig, MachineConfig
from schemas.wire import Mode, ProgramState
from tests.unit.areas.helpers import alarm_ids, run

TOOLS = [{"number": 1, "length": 1_000_000, "radius": 50_000}]

SQUARE = """\
N10 #CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N20 G01 F1000 X0 Y0
N30 X100
N40 Y100
N50 X0
N60 Y0
N70 #CONTROL AREA END
"""
"""A 100 x 100 mm work area in machine coordinates, Z from -50 to 50."""


def machine(**channel: Any) -> Machine:
    names = ["X", "Y", "Z"]
    axes = [
        AxisConfig(number=i + 1, name=n, swe_neg=-10_000_000, swe_pos=10_000_000) for i, n in enumerate(names)
    ]
    return Machine(MachineConfig(axes=axes, channels=[ChannelConfig(axes=names, tools=TOOLS, **channel)]))


def go(program: str) -> tuple[Machine, list[float]]:
    m = machine()
    ch = run(m, "%t\n" + program + "M30\n")
    return m, ch.setpoints()


@pytest.mark.req("M-19", "N-09")
def test_path_check_under_rotated_cs() -> None:
    head = SQUARE + "G01 X10 Y10 F5000\n#CONTROL AREA ON [ID1]\n"
    # (80, 10) is inside the square in machine coordinates ...
    m, pos = go(head + "X80 Y10\n")
    assert 120486 not in alarm_ids(m)
    assert pos[:2] == pytest.approx([80.0, 10.0])
    # ... but in the CS turned by 45° about (50, 50) it is machine (99.5, 113.6): the path leaves the area
    m, pos = go(head + "#CS ON [50, 50, 0, 0, 0, 45]\nX70 Y0\nX80 Y10\n")
    assert 120486 in alarm_ids(m)
    assert pos[:2] == pytest.approx([99.497, 99.497], abs=1e-3)  # stopped at the start of the failing block


@pytest.mark.req("M-19")
def test_area_defined_under_cs_stays_in_machine_coordinates() -> None:
    # defined while a rotated CS is active: the contour is taken as written (machine coordinates)
    program = "G01 X10 Y10 F5000\n#CS ON [50, 50, 0, 0, 0, 45]\n" + SQUARE
    m, pos = go(program + "#CS OFF\n#CONTROL AREA ON [ID1]\nX95 Y5\n")
    assert 120486 not in alarm_ids(m)
    assert pos[:2] == pytest.approx([95.0, 5.0])


@pytest.mark.req("M-19")
def test_tool_radius_makes_the_path_leave_the_work_area() -> None:
    head = SQUARE + "G01 X10 Y10 F5000\n#CONTROL AREA ON [ID1]\n"
    # along y = 3 the programmed path is inside; with G42 and a 5 mm tool the tool runs at y = -2
    m, _ = go(head + "X10 Y3\nX90\nX90 Y10\n")
    assert 120486 not in alarm_ids(m)
    m, _ = go(head + "D1 G41\nX10 Y3\nX90\nG40 X90 Y10\n")  # tool left of +x: y = 8, inside
    assert 120486 not in alarm_ids(m)
    m, _ = go(head + "D1 G42\nX10 Y3\nX90\nG40 X90 Y10\n")
    assert 120486 in alarm_ids(m)


@pytest.mark.req("M-15")
def test_areas_monitor_the_tool_tip() -> None:
    head = SQUARE + "G01 X10 Y10 Z0 F5000\n#CONTROL AREA ON [ID1]\n"
    # with a 100 mm tool the Z axis stands at 100 while the tip is at 0: inside the excursion -50..50
    m, pos = go(head + "D1\nZ0\nX20\n")
    assert 120486 not in alarm_ids(m)
    assert pos == pytest.approx([20.0, 10.0, 100.0])
    m, pos = go(head + "D1\nZ0\nZ60\n")  # the tip at 60 leaves the excursion
    assert 120486 in alarm_ids(m)
    assert pos[2] == pytest.approx(100.0)


@pytest.mark.req("M-19")
def test_manual_mode_guard_under_an_active_cs() -> None:
    """The program leaves a turned CS active; in manual mode the guard holds the axes at the machine
    coordinates' boundary (X 100), not at a boundary the CS would give."""
    names = ["X", "Y", "Z"]
    axes = [
        AxisConfig(
            number=i + 1,
            name=n,
            swe_neg=-10_000_000,
            swe_pos=10_000_000,
            jog_velocity=3000.0,
            jog_acceleration=1000.0,
        )
        for i, n in enumerate(names)
    ]
    m = Machine(MachineConfig(axes=axes, channels=[ChannelConfig(axes=names, tools=TOOLS)]))
    ch = run(
        m,
        "%t\n"
        + SQUARE
        + "G01 X10 Y10 F5000\n#CONTROL AREA ON [ID1]\n#CS ON [50, 50, 0, 0, 0, 45]\nX20 Y-40\nM30\n",
    )
    assert ch.state == ProgramState.FINISHED, [a.message for a in m.alarm_history]
    assert ch.setpoints()[:2] == pytest.approx(
        [50 + 20 * 0.7071068 + 40 * 0.7071068, 50 + 20 * 0.7071068 - 40 * 0.7071068], abs=1e-4
    )
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    ch.request_jog("X", +1)
    previous = None
    for _ in range(20_000):
        m.step(1)
        x = ch.setpoints()[0]
        assert x <= 100.0
        if x == previous:
            break
        previous = x
    assert 99.0 <= ch.setpoints()[0] <= 100.0


@pytest.mark.req("M-15")
def test_area_on_checks_the_tool_tip() -> None:
    # the Z axis at 100 with a 100 mm tool: the tip at 0 is inside the excursion, so ON is allowed
    m, _ = go(SQUARE + "G01 X10 Y10 Z0 F5000\nD1\nZ0\n#CONTROL AREA ON [ID1]\nX20\n")
    assert [a.number for a in m.alarm_history if a.severity == "error"] == []


@pytest.mark.req("M-15")
def test_manual_mode_after_a_program_with_a_tool_length_sees_the_tip() -> None:
    # the program ends with the Z axis at 100 (tip at 0): entering manual mode is allowed (P-CHAN-00442 = 0)
    m = machine()
    ch = run(m, "%t\n" + SQUARE + "G01 X10 Y10 Z0 F5000\n#CONTROL AREA ON [ID1]\nD1\nZ0\nM30\n")
    assert ch.setpoints()[2] == pytest.approx(100.0)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    assert ch.mode == Mode.MANUAL
    assert 50961 not in alarm_ids(m)


@pytest.mark.req("M-19")
def test_g100_measuring_move_under_a_cs_targets_the_framed_point() -> None:
    from tests.unit.areas.test_area_measuring import make_machine as measuring_machine
    from tests.unit.areas.test_area_measuring import run_with_probe_at

    m = measuring_machine()
    # in the CS shifted by 10 in X, "G100 X50" ends at machine X 60 (no probe: type 1 goes to the target)
    run_with_probe_at(m, "N05 #CS ON [10, 0, 0]\nN10 G100 X50 F6000\nN20 G01 Y20\nM30\n", None)
    assert m.channel(1).state == ProgramState.FINISHED, [a.message for a in m.alarm_history]
    assert m.channel(1).setpoints()[:2] == pytest.approx([60.0, 20.0])


@pytest.mark.req("M-19")
def test_check_geometry_only_batch_agrees_with_the_exact_path_under_a_cs() -> None:
    from tests.unit.test_batch_check import AREAS, _count_batched, _zigzag, assert_same, config

    cfg = config.__wrapped__()  # the fixture's function (the demo machine with G54)
    body = _zigzag(400)
    # a turned CS active over a long stretch of plain lines: decoded block by block, same result
    text = (
        AREAS
        + "#CS ON [5, -5, 0, 0, 0, 20]\n"
        + "\n".join([*body, "#CS OFF", *body, "G01 X0 Y-300", "M30"])
        + "\n"
    )
    result = assert_same(cfg, text)
    assert [a.number for a in result.alarms] == [120486]
    batched, exact = _count_batched(cfg, text, small=None)
    assert exact >= 400  # the stretch under the CS
    assert batched >= 350  # the stretch after #CS OFF is batched again


@pytest.mark.req("M-27", "M-20")
def test_the_motion_benchmarks_program_runs_contoured_and_faster() -> None:
    """``benchmarks/bench_motion.py``'s comparison, small: the same program with contouring on runs to
    its end without an alarm, contours its corners and takes fewer cycles (a contoured corner is not a
    stop)."""
    from benchmarks.bench_engine import long_program
    from benchmarks.bench_motion import _run_to_end, contoured

    text = long_program(40)
    plain_cycles, _, plain_corners = _run_to_end(text)
    cycles, _, corners = _run_to_end(contoured(text))
    assert plain_corners == 0
    assert corners > 20
    assert cycles < plain_cycles
