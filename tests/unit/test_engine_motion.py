"""Engine core, stepped cycle by cycle: determinism, motion, modes, offsets, soft limits (E-01..E-06)."""

from __future__ import annotations

import math

import pytest

from hli_server.engine.hli import Mode, ProgramState
from schemas.config import ZeroOffset
from tests.unit.engine_helpers import cycles_until_done, mill, positions, run, settle, start

PROGRAM = """\
N10 G90 G01 X100 Y50 F6000
N20 G02 X150 Y100 I50 J0
N30 G03 X100 Y150 I-50 J0
N40 G00 X0 Y0 Z10
N50 G91 G01 X10 Y-5 Z-10 F3000
N60 M30
"""


def trace(machine_factory, program: str) -> list[tuple[float, ...]]:
    m = machine_factory()
    out: list[tuple[float, ...]] = []
    start(m, program)
    for _ in cycles_until_done(m):
        out.append(tuple(v for a in m.axes for v in (a.setpoint, a.measured)))
    return out


@pytest.mark.req("E-01")
def test_same_inputs_give_the_same_cycles():
    first = trace(mill, PROGRAM)
    second = trace(mill, PROGRAM)
    assert len(first) > 1000
    assert first == second  # bit for bit, cycle for cycle


@pytest.mark.req("E-01")
def test_cycle_time_is_configurable():
    m1, m2 = mill(cycle_time_us=1000), mill(cycle_time_us=500)
    run(m1, PROGRAM)
    run(m2, PROGRAM)
    assert positions(m1) == pytest.approx(positions(m2), abs=1e-6)
    # same motion, twice the cycles at half the cycle time
    assert m2.cycle == pytest.approx(2 * m1.cycle, rel=0.02)
    assert m2.time == pytest.approx(m1.time, rel=0.02)


@pytest.mark.req("E-04", "E-05")
def test_program_reaches_programmed_end_point():
    m = mill()
    run(m, PROGRAM)
    assert m.channel(1).state == ProgramState.FINISHED
    assert positions(m) == {"X": 10.0, "Y": -5.0, "Z": 0.0}
    assert not m.active_alarms


@pytest.mark.req("E-02", "E-05")
def test_axis_velocity_and_acceleration_stay_within_limits():
    m = mill(a_max=1500.0, v_max=12_000.0)
    t = m.t_a
    a_max = 1500.0
    prev_v: dict[str, float] = {}
    worst_a = 0.0
    worst_v = 0.0
    worst_at_rest = 0.0

    def check(machine):
        nonlocal worst_a, worst_v, worst_at_rest
        for a in machine.axes:
            v = a.setpoint_step / t
            worst_v = max(worst_v, abs(v))
            if a.name in prev_v:
                acc = abs(v - prev_v[a.name]) / t
                # the cycle in which an axis comes to rest ends with a partial step
                if min(abs(v), abs(prev_v[a.name])) < 2 * a_max * t:
                    worst_at_rest = max(worst_at_rest, acc)
                else:
                    worst_a = max(worst_a, acc)
            prev_v[a.name] = v

    run(m, "N10 G01 X200 F20000\nN20 X0\nN30 G00 Y300\nN40 M30\n", each=check)
    assert worst_v == pytest.approx(12_000 / 60)
    assert worst_a <= a_max * (1 + 1e-9)
    assert worst_at_rest <= 2 * a_max


@pytest.mark.req("E-02", "A3-02")
def test_following_error_during_motion_and_settling_into_the_window():
    m = mill()
    start(m, "N10 G01 X100 F6000\nN20 M30\n")
    max_fe = 0.0
    for _ in cycles_until_done(m):
        max_fe = max(max_fe, abs(m.axis("X").following_error))
    # realistic following error in motion: some µm, not zero and not millimetres
    assert 0.001 < max_fe < 1.0
    settle(m, 200)
    x = m.axis("X")
    assert abs(x.following_error) * 10_000 <= x.config.window
    assert m.hli.axes[0].ipo_state.in_position_r


@pytest.mark.req("E-05")
def test_circle_keeps_its_radius_and_direction():
    m = mill()
    radii = []
    angles = []

    def sample(machine):
        x, y = machine.axis("X").setpoint, machine.axis("Y").setpoint
        radii.append(math.hypot(x - 50, y))
        angles.append(math.atan2(y, x - 50))

    # G02: clockwise full circle around (50, 0) from (100, 0)
    run(m, "N10 G01 X100 Y0 F6000\nN20 G02 X100 Y0 I-50 J0\nN30 M30\n", each=sample)
    on_circle = radii[len(radii) // 2 :]
    assert max(abs(r - 50) for r in on_circle) < 1e-6
    # first movement on the circle goes to negative angles (clockwise from angle 0)
    circle_angles = [a for a, r in zip(angles, radii, strict=True) if abs(r - 50) < 1e-6 and abs(a) > 1e-3]
    assert circle_angles[0] < 0


@pytest.mark.req("E-04")
@pytest.mark.parametrize(
    ("program", "expected"),
    [
        ("N10 G01 X100 Y0 F6000\nN20 G162 G03 X0 Y100 I-100 J0\nN30 M30\n", {"X": 0.0, "Y": 100.0}),
        ("N10 G01 X100 Y0 F6000\nN20 G161 G03 X0 Y100 I0 J0\nN30 M30\n", {"X": 0.0, "Y": 100.0}),
        ("N10 G18 G01 X100 Z0 F6000\nN20 G02 X0 Z100 I-100 K0\nN30 M30\n", {"X": 0.0, "Z": 100.0}),
        ("N10 G19 G01 Y100 Z0 F6000\nN20 G03 Y0 Z100 J-100 K0\nN30 M30\n", {"Y": 0.0, "Z": 100.0}),
    ],
)
def test_circle_centre_modes_and_planes(program, expected):
    m = mill()
    run(m, program)
    assert not m.active_alarms, m.active_alarms
    pos = positions(m)
    for axis, value in expected.items():
        assert pos[axis] == pytest.approx(value, abs=1e-9)


@pytest.mark.req("E-04")
def test_circle_with_inconsistent_centre_is_refused_with_line_and_block():
    m = mill()
    run(m, "N10 G01 X100 Y0 F6000\nN20 G02 X0 Y90 I-100 J0\nN30 M30\n")
    (alarm,) = m.active_alarms
    assert alarm.number == 911001
    assert (alarm.line, alarm.block) == (2, "N20")
    assert positions(m)["X"] == pytest.approx(100.0)  # stopped at the block's start point


@pytest.mark.req("E-04", "C14-16")
def test_zero_offsets_g54_and_g92():
    m = mill(zero_offsets=[ZeroOffset(code="G54", offsets={"X": 1_000_000, "Y": -500_000})])
    run(m, "N10 G54 G01 X10 Y10 F6000\nN20 G92 X0 Y0\nN30 X5 Y5\nN40 G53 X1 Y1\nN50 M30\n")
    # G53 deselects G54 (modal); the G92 shift (10, 10) stays until reset
    assert positions(m)["X"] == pytest.approx(11.0)
    assert positions(m)["Y"] == pytest.approx(11.0)
    m2 = mill(zero_offsets=[ZeroOffset(code="G54", offsets={"X": 1_000_000, "Y": -500_000})])
    run(m2, "N10 G54 G01 X10 Y10 F6000\nN20 G92 X0 Y0\nN30 X5 Y5\nN40 M30\n")
    # G54 shifts by (100, -50); G92 makes (110, -40) the new (0, 0); X5 Y5 is (115, -35) in MCS
    assert positions(m2)["X"] == pytest.approx(115.0)
    assert positions(m2)["Y"] == pytest.approx(-35.0)


@pytest.mark.req("E-04")
def test_both_axis_word_forms():
    m = mill(extra_axes=("X2",))
    run(m, "N10 G01 X2=25 X5 F6000\nN20 M30\n")
    assert positions(m)["X2"] == pytest.approx(25.0)
    assert positions(m)["X"] == pytest.approx(5.0)


@pytest.mark.req("E-04")
def test_syntax_error_stops_at_the_line_and_engine_stays_usable():
    m = mill()
    run(m, "N10 G01 X10 F6000\nN20 X20 Q5\nN30 X30\nN40 M30\n")
    (alarm,) = m.active_alarms
    assert alarm.number == 910100
    assert (alarm.line, alarm.block) == (2, "N20")
    assert "Q5" in alarm.message
    assert positions(m)["X"] == pytest.approx(10.0)  # blocks before the error ran
    assert m.channel(1).state == ProgramState.ABORTED
    # a new program after reset runs normally
    m.channel(1).request_reset()
    m.step(1)
    assert not m.active_alarms
    run(m, "N10 G01 X40 F6000\nN20 M30\n")
    assert positions(m)["X"] == pytest.approx(40.0)
    assert m.channel(1).state == ProgramState.FINISHED


@pytest.mark.req("E-04")
def test_feed_move_without_feed_is_an_error():
    m = mill()
    run(m, "N10 G01 X10\nN20 M30\n")
    assert [a.number for a in m.active_alarms] == [20008]


@pytest.mark.req("E-05")
def test_feedhold_brakes_with_its_deceleration_and_resumes():
    m = mill()
    ch = m.channel(1)
    start(m, "N10 G01 X400 F12000\nN20 M30\n")
    m.step(800)
    v0 = ch.planner.velocity
    assert v0 == pytest.approx(200.0)
    ch.request_feedhold(True)
    m.step(1)
    held_cycles = 0
    while ch.planner.velocity > 0:
        m.step(1)
        held_cycles += 1
    # v / a_feedhold = 200 mm/s / 1000 mm/s² = 0.2 s = 200 cycles
    assert held_cycles == pytest.approx(200, abs=2)
    assert ch.state == ProgramState.HELD
    assert m.hli.channels[0].bahn_state.feedhold_active_r
    x_held = m.axis("X").setpoint
    m.step(100)
    assert m.axis("X").setpoint == x_held
    ch.request_feedhold(False)
    for _ in cycles_until_done(m):
        pass
    assert positions(m)["X"] == pytest.approx(400.0)


@pytest.mark.req("E-05", "H-02")
def test_override_through_the_control_unit():
    m = mill()
    start(m, "N10 G01 X400 F12000\nN20 M30\n")
    unit = m.hli.channels[0].bahn_mc_control.override
    unit.command_w = 500
    unit.enable_w = True
    m.step(1000)
    assert m.channel(1).planner.velocity == pytest.approx(100.0)
    assert unit.state_r == 500
    unit.enable_w = False  # back to the CNC's own request (100 %)
    m.step(1000)
    assert m.channel(1).planner.velocity == pytest.approx(200.0)


@pytest.mark.req("E-03")
def test_reset_stops_motion_and_mode_change_needs_a_stopped_program():
    m = mill()
    ch = m.channel(1)
    start(m, "N10 G01 X400 F12000\nN20 M30\n")
    m.step(300)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    assert ch.mode == Mode.AUTOMATIC
    assert m.alarm_history[-1].number == 911021
    ch.request_reset()
    m.step(1)
    assert ch.state == ProgramState.IDLE
    for _ in range(1000):
        m.step(1)
        if m.axis("X").setpoint_step == 0.0:
            break
    x = m.axis("X").setpoint
    m.step(50)
    assert m.axis("X").setpoint == x
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    assert ch.mode == Mode.MANUAL
    assert m.hli.channels[0].bahn_state.mode_r == Mode.MANUAL


@pytest.mark.req("E-03", "E-05")
def test_jog_in_manual_mode_ramps_with_jog_acceleration():
    m = mill()
    ch = m.channel(1)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    m.hli.axes[1].manual.jog_plus_w = True  # Y+ through the PLC's jog key
    m.step(200)
    y = m.axis("Y")
    v = y.setpoint_step / m.t_a
    assert v == pytest.approx(min(y.jog_acceleration * 0.2, y.jog_velocity), rel=0.02)
    m.step(2000)
    assert y.setpoint_step / m.t_a == pytest.approx(y.jog_velocity)
    m.hli.axes[1].manual.jog_plus_w = False
    m.step(200)
    assert y.setpoint_step == 0.0
    assert ch.state == ProgramState.IDLE


@pytest.mark.req("E-06")
def test_programmed_position_beyond_soft_limit_is_refused_before_the_block():
    m = mill()
    run(m, "N10 G01 X100 F6000\nN20 X600\nN30 M30\n")
    (alarm,) = m.active_alarms
    assert alarm.number == 120002  # the kernel's ID (software limit switch description)
    assert alarm.block == "N20"
    assert m.axis("X").setpoint == pytest.approx(100.0)


@pytest.mark.req("E-06")
def test_arc_whose_bulge_passes_the_soft_limit_is_refused():
    m = mill()
    # end points inside +-500 mm, but counter-clockwise the half circle reaches Y = -450 - 100 = -550
    run(m, "N10 G01 X0 Y-450 F6000\nN20 G03 X200 Y-450 I100 J0\nN30 M30\n")
    assert [a.number for a in m.active_alarms] == [120003]
    m2 = mill()
    run(m2, "N10 G01 X0 Y-450 F6000\nN20 G02 X200 Y-450 I100 J0\nN30 M30\n")
    assert not m2.active_alarms  # the other way round the bulge stays inside


@pytest.mark.req("E-06")
def test_actual_position_checked_against_limit_plus_tolerance():
    m = mill(swe_toleranz=1000)  # 0.1 mm
    x = m.axis("X")
    x.actual = x.measured = 500.05  # beyond swe_pos, within the tolerance
    m.step(1)
    assert not m.active_alarms
    x.actual = 500.2
    x.measured = 500.2
    m.step(1)
    assert [a.number for a in m.active_alarms] == [70021]


@pytest.mark.req("E-06", "E-05")
def test_jog_stops_at_the_soft_limit_without_passing_it():
    # the drive may overshoot the setpoint by some µm: that is what swe_toleranz (P-AXIS-00179) is for
    m = mill(move_limit_warning=True, swe_toleranz=500)
    ch = m.channel(1)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    ch.request_jog("X", +1)
    for _ in range(20_000):
        m.step(1)
        assert m.axis("X").setpoint <= 500.0 + 1e-9
    assert m.axis("X").setpoint > 499.0
    assert m.axis("X").setpoint_step == 0.0
    assert not m.active_alarms
    assert any(a.number == 911013 for a in m.alarm_history)


@pytest.mark.req("E-02")
def test_unreferenced_axis_refuses_program_start():
    m = mill(referenced=False)
    start(m, "N10 G01 X10 F1000\nN20 M30\n")
    assert m.alarm_history[-1].number == 911020
    assert m.channel(1).state == ProgramState.IDLE


@pytest.mark.req("E-02", "H-01")
def test_published_axis_state_in_interface_units():
    m = mill()
    start(m, "N10 G01 X400 F12000\nN20 M30\n")
    m.step(1500)  # constant 200 mm/s after the ramp
    st = m.hli.axes[0].ipo_state
    x = m.axis("X")
    assert st.velocity_r == pytest.approx(2_000_000, rel=1e-3)  # 200 mm/s in 0.1 µm/s
    assert st.cmd_pos_r == round(x.setpoint * 10_000)
    assert st.act_pos_r == round(x.measured * 10_000)
    assert st.following_error_r == round(x.following_error * 10_000)
    assert st.moving_r
    assert not st.in_position_r
