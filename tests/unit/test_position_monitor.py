"""Position monitoring, FCT-A3 (A3-01..A3-05), and fault injection, stepped cycle by cycle."""

from __future__ import annotations

import pytest

from hli_server.engine import Machine
from hli_server.engine.monitors.position import PositionMonitor, settling_time_us
from schemas.config import AxisConfig, ChannelConfig, MachineConfig
from schemas.events import FaultInjected
from schemas.wire import Mode, ProgramState
from tests.unit.engine_helpers import record_events

RUNNING = (ProgramState.RUNNING, ProgramState.HELD)


def machine(**axis: object) -> Machine:
    """X/Y/Z; the drive model's defaults settle into the default 50 µm window within a few ms."""
    axes = [
        AxisConfig(number=i + 1, name=n, **{"position_settling_time_us": 100_000, **axis})  # type: ignore[arg-type]
        for i, n in enumerate("XYZ")
    ]
    return Machine(MachineConfig(axes=axes, channels=[ChannelConfig(axes=["X", "Y", "Z"])]))


def start(m: Machine, program: str) -> None:
    ch = m.channel(1)
    ch.load_program(program)
    ch.request_start()


def monitor(m: Machine) -> PositionMonitor:
    return m.monitor(PositionMonitor)


def cycle_target_reached(m: Machine, axis: str, limit: int = 20_000) -> int:
    """Step until ``axis``' setpoint stands still after moving; returns t1, the cycle in which the
    setpoint reached its target (the last cycle it moved; the machine stands one cycle later)."""
    ax = m.axis(axis)
    moved = False
    for _ in range(limit):
        m.step(1)
        if ax.setpoint_step != 0.0:
            moved = True
        elif moved:
            return m.cycle - 1
    raise AssertionError(f"{axis} did not reach a target")


def alarms(m: Machine) -> list[tuple[int, str | None]]:
    return [(a.number, a.axis) for a in m.alarm_history]


@pytest.mark.req("A3-01", "A3-02")
def test_healthy_axis_settles_into_the_window_and_the_timer_stops():
    m = machine()
    start(m, "N10 G01 X50 F6000\nN20 M30\n")
    t1 = cycle_target_reached(m, "X")
    w = monitor(m).watches[0]
    assert w.timer_start == t1 or w.timer_start is None  # started at t1 ...
    x = m.axis("X")
    cycles = 0
    while w.timer_start is not None:
        m.step(1)
        cycles += 1
    assert abs(x.measured - x.setpoint) <= 0.05  # ... stopped in the window (t2)
    assert cycles < 100
    m.step(500)
    assert not m.alarm_history
    assert m.hli.axes[0].ipo_state.in_position_r


@pytest.mark.req("A3-01", "A3-03", "A3-04")
def test_slow_settling_raises_70082_exactly_after_the_settling_time():
    m = machine()
    m.inject_fault("X", gain_factor=0.05)  # a worn loop: settles 20 times slower
    start(m, "N10 G01 X50 F6000\nN20 M30\n")
    t1 = cycle_target_reached(m, "X")
    for _ in range(1000):
        if m.alarm_history:
            break
        m.step(1)
    (alarm,) = m.active_alarms
    assert (alarm.number, alarm.axis) == (70082, "X")
    assert m.cycle - t1 == 100  # the cycle in which 100 000 µs after t1 have run out (T_A = 1 ms)
    assert alarm.params["settling_time_us"] == 100_000
    assert abs(alarm.params["deviation"]) > 500
    assert m.axis("X").stopping
    m.step(100)
    assert len(m.alarm_history) == 1  # once
    m.channel(1).request_reset()
    m.step(2)
    assert not m.active_alarms
    assert not m.axis("X").stopping


@pytest.mark.req("A3-01", "A3-03", "A3-04")
@pytest.mark.parametrize("settling_ms", [20, 30, 50])
def test_70082_fires_in_the_cycle_the_settling_time_runs_out(settling_ms: int):
    """t1 + t3: at 1 ms per cycle, 70082 comes exactly ``settling_ms`` cycles after the setpoint
    reached its target, judged on the actual position of that cycle (the monitor runs after the
    position loop)."""
    m = machine(position_settling_time_us=settling_ms * 1000)
    m.inject_fault("X", gain_factor=0.05)
    start(m, "N10 G01 X50 F6000\nN20 M30\n")
    t1 = cycle_target_reached(m, "X")
    while not m.alarm_history and m.cycle < t1 + 1000:
        m.step(1)
    assert alarms(m) == [(70082, "X")]
    assert m.cycle - t1 == settling_ms
    assert m.alarm_history[0].cycle == t1 + settling_ms


@pytest.mark.req("A3-03")
def test_settling_time_zero_switches_the_check_off():
    m = machine(position_settling_time_us=0)
    m.inject_fault("X", gain_factor=0.05)
    start(m, "N10 G01 X50 F6000\nN20 M30\n")
    cycle_target_reached(m, "X")
    m.step(2000)
    assert not m.alarm_history


@pytest.mark.req("A3-03")
@pytest.mark.parametrize(("legacy_us", "expected"), [(50_000, 50), (0, None)])
def test_negative_settling_time_uses_p_axis_00151(legacy_us: int, expected: int | None):
    m = machine(position_settling_time_us=-1, settling_time_legacy_us=legacy_us)
    assert settling_time_us(m.axis("X")) == legacy_us
    m.inject_fault("X", gain_factor=0.05)
    start(m, "N10 G01 X50 F6000\nN20 M30\n")
    t1 = cycle_target_reached(m, "X")
    for _ in range(1000):
        if m.alarm_history:
            break
        m.step(1)
    if expected is None:
        assert not m.alarm_history
    else:
        assert alarms(m) == [(70082, "X")]
        assert m.cycle - t1 == expected


@pytest.mark.req("A3-04")
def test_70082_stops_the_axis_and_every_axis_interpolated_with_it():
    m = machine()
    m.inject_fault("X", friction=30.0)  # stiction: the loop cannot push X into the window
    start(m, "N10 G01 X20 F6000\nN20 G01 Y150\nN30 M30\n")
    cycle_target_reached(m, "X")
    y = m.axis("Y")
    for _ in range(1000):
        m.step(1)
        if m.alarm_history:
            break
    assert alarms(m) == [(70082, "X")]
    assert y.stopping
    assert y.stop_deceleration == y.a_emergency
    assert not m.axis("Z").stopping  # Z did not move
    v = [y.setpoint_step / m.t_a]
    while y.stop_velocity > 0:
        m.step(1)
        v.append(y.setpoint_step / m.t_a)
    assert v[0] - v[1] == pytest.approx(y.a_emergency * m.t_a)  # immediate stop, a_emergency
    assert y.setpoint < 100.0
    assert m.channel(1).state == ProgramState.ABORTED
    assert m.active_alarms[0].block == "N20"


@pytest.mark.req("A3-05")
def test_g60_waits_for_the_exact_stop_window_before_the_next_block():
    def run(program: str) -> tuple[int, float]:
        m = machine(window=20)  # 2 µm
        start(m, program)
        x, y = m.axis("X"), m.axis("Y")
        t_x = None
        for _ in range(5000):
            m.step(1)
            if t_x is None and x.setpoint == 40.0:
                t_x = m.cycle  # X's setpoint at its target
            if y.setpoint_step != 0.0:
                assert t_x is not None
                return m.cycle - t_x, abs(x.measured - x.setpoint)
        raise AssertionError("Y never moved")

    waited, deviation = run("N10 G60 G01 X40 F6000\nN20 G01 Y10\nN30 M30\n")
    assert waited > 1
    assert deviation <= 0.002  # in the window when Y starts
    waited_g01, deviation_g01 = run("N10 G01 X40 F6000\nN20 G01 Y10\nN30 M30\n")
    assert waited_g01 == 0  # a plain corner: no stop, Y starts in the same cycle
    assert deviation_g01 > 0.002


@pytest.mark.req("A3-05")
def test_g60_that_never_reaches_the_window_ends_with_70082():
    m = machine()
    m.inject_fault("X", friction=30.0)
    start(m, "N10 G60 G01 X40 F6000\nN20 G01 Y10\nN30 M30\n")
    for _ in range(3000):
        m.step(1)
        if m.alarm_history:
            break
    assert alarms(m) == [(70082, "X")]
    assert m.axis("Y").setpoint == 0.0  # N20 never started
    assert m.active_alarms[0].block in ("N10", "N20")


@pytest.mark.req("A3-05", "A3-04")
@pytest.mark.parametrize(
    "fault",
    [
        {"friction": 30.0},
        {"gain_factor": 0.05},
        {"encoder_drift": 5.0},
        {"encoder_stuck": True},
    ],
    ids=["friction", "low gain", "drifting encoder", "stuck encoder"],
)
def test_injected_faults_trigger_the_position_monitor(fault: dict[str, float | bool]):
    m = machine()
    events = record_events(m)
    start(m, "N10 G01 X50 F6000\nN20 M30\n")
    m.step(100)  # faults strike during the move
    m.inject_fault("X", **fault)
    for _ in range(3000):
        m.step(1)
        if m.alarm_history:
            break
    assert alarms(m) == [(70082, "X")]
    assert [type(e) for e in events].count(FaultInjected) == 1


@pytest.mark.req("A3-05", "A3-04")
def test_healthy_axis_with_small_faults_stays_quiet():
    m = machine()
    m.inject_fault("X", friction=1.0, encoder_drift=0.5)  # dead band and drift inside the window
    start(m, "N10 G01 X50 F6000\nN20 G01 X0\nN30 M30\n")
    for _ in range(3000):
        m.step(1)
    assert m.channel(1).state == ProgramState.FINISHED
    assert not m.alarm_history


@pytest.mark.req("A3-05", "C3-05")
def test_drive_error_raises_911030_and_stops_the_channel():
    m = machine()
    start(m, "N10 G01 X50 Y50 F6000\nN20 M30\n")
    m.step(200)
    m.inject_fault("Y", drive_error=True)
    m.step(1)
    assert alarms(m) == [(911030, "Y")]
    assert all(a.stopping for a in m.axes)
    m.step(1000)
    assert alarms(m) == [(911030, "Y")]  # once, and no 70082 for a drive that is off
    assert m.channel(1).state == ProgramState.ABORTED
    m.channel(1).request_reset()  # reset clears the drive error
    m.step(2)
    assert not m.axis("Y").faults.drive_error
    assert not m.active_alarms


@pytest.mark.req("A3-01", "A3-04")
def test_jogging_is_position_monitored_too():
    m = machine()
    ch = m.channel(1)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    m.inject_fault("Z", gain_factor=0.05)
    ch.request_jog("Z", +1)
    m.step(300)
    ch.request_jog("Z", 0)
    for _ in range(1000):
        m.step(1)
        if m.alarm_history:
            break
    assert alarms(m) == [(70082, "Z")]


@pytest.mark.req("A3-05")
def test_inject_fault_api():
    m = machine()
    with pytest.raises(KeyError, match="no axis 'Q'"):
        m.inject_fault("Q", friction=1.0)
    with pytest.raises(ValueError, match="unknown fault field"):
        m.inject_fault("X", fricton=1.0)
    m.inject_fault("X", friction=2.0, encoder_stuck=True)
    assert m.axis("X").faults.friction == 2.0
    assert m.axis("X").faults.encoder_stuck
    m.inject_fault("X")
    assert not m.axis("X").faults.any()
