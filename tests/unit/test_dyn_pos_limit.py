"""Dynamic position limits, FCT-C43 (C43-01..C43-09), stepped cycle by cycle.

What a PLC sees is the control units ``gpAx[i]^ipo_mc_control.dyn_pos_limit_low/high``: it writes
``command_w`` (0.1 µm) and ``enable_w`` and reads ``state_r`` (HLI_DYNPL_STATE_*).
"""

from __future__ import annotations

from itertools import pairwise

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hli_server.engine import Machine
from hli_server.engine.hli import ControlUnitSgn32
from hli_server.engine.monitors.dyn_pos_limit import (
    RAMP_SAMPLES,
    TRANSITIONS,
    DplEvent,
    DynPosLimits,
    _braking_ramp,
    next_state,
)
from schemas.config import AxisConfig, ChannelConfig, MachineConfig
from schemas.events import DynPosLimitChanged
from schemas.wire import DynPosLimitState, HoldSource, Mode, ProgramState
from tests.unit.engine_helpers import record_events

INACTIVE, ACTIVATION, ACTIVE, BRAKING, BRAKE = (int(s) for s in DynPosLimitState)
FCT = "FCT_LOOK_AHEAD_STANDARD | FCT_DYN_POS_LIMIT"


def machine(
    *,
    function: str = FCT,
    feedhold: float = 1000.0,
    a_max: float = 2000.0,
    tol: int = 0,
    input_cycles: int = 1,
) -> Machine:
    axes = [AxisConfig(number=i + 1, name=n, a_max=a_max) for i, n in enumerate("XYZ")]
    channel = ChannelConfig(
        axes=["X", "Y", "Z"],
        interpolator_function=function,
        feedhold_deceleration=feedhold,
        dpl_tol_limit_change=tol,
        dpl_input_cycles=input_cycles,
    )
    return Machine(MachineConfig(axes=axes, channels=[channel]))


def unit(m: Machine, axis: str = "X", side: str = "high") -> ControlUnitSgn32:
    ctl = m.hli.axes[m.axis(axis).index].ipo_mc_control
    return ctl.dyn_pos_limit_high if side == "high" else ctl.dyn_pos_limit_low


def set_limit(m: Machine, mm: float, axis: str = "X", side: str = "high", enable: bool = True) -> None:
    u = unit(m, axis, side)
    u.command_w = round(mm * 10_000)
    u.enable_w = enable


def start(m: Machine, program: str) -> None:
    ch = m.channel(1)
    ch.load_program(program)
    ch.request_start()


def step_until(m: Machine, done, limit: int = 50_000) -> None:  # type: ignore[no-untyped-def]
    for _ in range(limit):
        if done():
            return
        m.step(1)
    raise AssertionError(f"condition not reached within {limit} cycles")


def compress(values: list[int]) -> list[int]:
    out: list[int] = []
    for v in values:
        if not out or out[-1] != v:
            out.append(v)
    return out


# --- the state machine ---------------------------------------------------------------------------


@pytest.mark.req("C43-03")
def test_transition_table_covers_the_documented_states():
    assert [int(s) for s in DynPosLimitState] == [0, 1, 2, 3, 4]
    reachable = {DynPosLimitState.INACTIVE} | set(TRANSITIONS.values())
    assert reachable == set(DynPosLimitState)
    # every state can be left by lifting the limit
    for state in DynPosLimitState:
        assert next_state(state, DplEvent.DISABLE) == DynPosLimitState.INACTIVE
    with pytest.raises(RuntimeError, match="standstill"):
        next_state(DynPosLimitState.ACTIVE, DplEvent.STANDSTILL)


@pytest.mark.req("C43-02", "C43-03", "C43-04", "C43-07")
def test_state_sequence_a_plc_sees_cycle_by_cycle():
    m = machine()
    events = record_events(m)
    ch = m.channel(1)
    u = unit(m)
    states: list[int] = [u.state_r]
    set_limit(m, 50.0)
    m.step(1)
    states.append(u.state_r)
    assert u.state_r == ACTIVATION  # the cycle the PLC enabled it
    m.step(1)
    states.append(u.state_r)
    assert u.state_r == ACTIVE  # taken over one cycle later
    start(m, "N10 G01 X100 F6000\nN20 M30\n")
    step_until(m, lambda: (states.append(u.state_r) or u.state_r == BRAKE) and ch.planner.velocity == 0.0)
    held_at = m.axis("X").setpoint
    for _ in range(200):  # held at the limit, nothing creeps
        m.step(1)
        states.append(u.state_r)
    assert m.axis("X").setpoint == held_at
    # the hold is visible at the channel, and what holds it (FCT-C43: "bereichsspezifischer Feedhold")
    bahn = m.hli.channels[0].bahn_state
    assert ch.state == ProgramState.HELD
    assert (bahn.program_state_r, bahn.feedhold_active_r, bahn.hold_source_r) == (
        ProgramState.HELD,
        True,
        HoldSource.DYN_POS_LIMIT,
    )
    set_limit(m, 50.0, enable=False)  # the PLC lifts the limit
    step_until(m, lambda: states.append(u.state_r) or ch.state == ProgramState.FINISHED)
    assert compress(states) == [INACTIVE, ACTIVATION, ACTIVE, BRAKING, BRAKE, INACTIVE]
    assert states.count(ACTIVATION) == 1
    assert m.axis("X").setpoint == pytest.approx(100.0)  # the program continued (C43-07)
    assert u.request_r == 0  # not supported (FCT-C43 3.1.1)
    assert not m.active_alarms
    kinds = [e.state_name for e in events if isinstance(e, DynPosLimitChanged)]
    assert kinds == ["ACTIVATION", "ACTIVE", "ACTIVE_BRAKING", "ACTIVE_BRAKE", "INACTIVE"]


@pytest.mark.req("C43-04", "C43-06")
def test_current_acceleration_holds_until_the_braking_point_then_feedhold_deceleration():
    free, limited = machine(), machine(feedhold=800.0)
    set_limit(limited, 60.0)
    limited.step(2)
    free.step(2)
    program = "N10 G01 X100 F9000\nN20 M30\n"
    start(free, program)
    start(limited, program)
    x_free: list[float] = []
    x_lim: list[float] = []
    u = unit(limited)
    for _ in range(1500):
        free.step(1)
        limited.step(1)
        x_free.append(free.axis("X").setpoint)
        x_lim.append(limited.axis("X").setpoint)
    first_diff = next(i for i, (a, b) in enumerate(zip(x_free, x_lim, strict=True)) if a != b)
    # the same path cycle for cycle until the braking point ...
    v_before = (x_lim[first_diff - 1] - x_lim[first_diff - 2]) / limited.t_a
    assert v_before == pytest.approx(150.0)
    # ... which lies where braking with the feedhold deceleration ends on the limit
    braking_distance = 60.0 - x_lim[first_diff - 1]
    assert braking_distance == pytest.approx(150.0**2 / (2 * 800.0), abs=150.0 * limited.t_a)
    tail = x_lim[first_diff - 1 :]
    velocities = [(b - a) / limited.t_a for a, b in pairwise(tail)]
    decel = [(v0 - v1) / limited.t_a for v0, v1 in pairwise(velocities) if v0 > 0]
    assert max(decel[:-2]) <= 800.0 * 1.001  # the feedhold deceleration ...
    assert max(decel[-2:]) <= 2 * 800.0  # ... the last two steps fit the ramp onto the stop point
    assert sorted(decel)[len(decel) // 2] == pytest.approx(800.0, rel=0.01)
    assert max(x_lim) == pytest.approx(60.0, abs=1e-6)  # on the limit, within one cycle's travel
    assert u.state_r == BRAKE


@pytest.mark.req("C43-04")
def test_low_limit_and_a_path_in_the_plane():
    m = machine()
    set_limit(m, -20.0, axis="Y", side="low")
    m.step(2)
    start(m, "N10 G01 X30 Y-60 F6000\nN20 M30\n")
    ch = m.channel(1)
    step_until(m, lambda: unit(m, "Y", "low").state_r == BRAKE)
    assert m.axis("Y").setpoint == pytest.approx(-20.0, abs=1e-6)
    # the path stopped on its contour: X went along in proportion
    assert m.axis("X").setpoint == pytest.approx(30.0 * 20.0 / 60.0, abs=1e-6)
    assert unit(m, "X", "high").state_r == INACTIVE
    set_limit(m, -80.0, axis="Y", side="low")  # moved beyond the target: the program continues
    step_until(m, lambda: ch.state == ProgramState.FINISHED)
    assert (m.axis("X").setpoint, m.axis("Y").setpoint) == pytest.approx((30.0, -60.0))


@pytest.mark.req("C43-05")
def test_already_beyond_at_activation_stops_at_once_with_feedhold_deceleration():
    m = machine(feedhold=500.0)
    ch = m.channel(1)
    start(m, "N10 G01 X200 F6000\nN20 M30\n")
    step_until(m, lambda: m.axis("X").setpoint > 60.0)
    assert ch.planner.velocity == pytest.approx(100.0)
    set_limit(m, 40.0)  # the axis is 20 mm inside the forbidden zone
    m.step(1)
    assert unit(m).state_r == ACTIVATION
    v: list[float] = []
    states: list[int] = []
    for _ in range(400):
        m.step(1)
        v.append(ch.planner.velocity)
        states.append(unit(m).state_r)
    assert compress(states) == [BRAKING, BRAKE]
    # braking from the first cycle on, with the feedhold deceleration: 100 mm/s -> 0 in 0.2 s
    assert v[0] == pytest.approx(100.0 - 500.0 * m.t_a)
    assert v.index(0.0) == pytest.approx(200, abs=2)
    assert m.axis("X").setpoint == pytest.approx(60.0 + 100.0**2 / (2 * 500.0), abs=0.2)
    # held there until the PLC moves the limit beyond the axis
    x_held = m.axis("X").setpoint
    m.step(100)
    assert m.axis("X").setpoint == x_held
    set_limit(m, 150.0)
    m.step(2)
    assert unit(m).state_r == ACTIVE
    step_until(m, lambda: unit(m).state_r == BRAKE and ch.planner.velocity == 0.0)
    assert m.axis("X").setpoint == pytest.approx(150.0, abs=1e-6)


@pytest.mark.req("C43-07")
def test_moving_the_limit_continues_the_program_up_to_the_new_limit():
    m = machine()
    ch = m.channel(1)
    set_limit(m, 30.0)
    m.step(2)
    start(m, "N10 G01 X100 F6000\nN20 G01 X0\nN30 M30\n")
    step_until(m, lambda: unit(m).state_r == BRAKE)
    assert m.axis("X").setpoint == pytest.approx(30.0, abs=1e-6)
    set_limit(m, 70.0)
    m.step(1)
    assert unit(m).state_r in (ACTIVE, BRAKING)
    step_until(m, lambda: unit(m).state_r == BRAKE)
    assert m.axis("X").setpoint == pytest.approx(70.0, abs=1e-6)
    set_limit(m, 120.0)  # beyond the program's reach: it runs to its end
    step_until(m, lambda: ch.state == ProgramState.FINISHED)
    assert m.axis("X").setpoint == pytest.approx(0.0)
    assert unit(m).state_r == ACTIVE


@pytest.mark.req("C43-01")
def test_without_fct_dyn_pos_limit_the_control_units_have_no_effect():
    m = machine(function="FCT_LOOK_AHEAD_STANDARD")
    set_limit(m, 30.0)
    start(m, "N10 G01 X100 F6000\nN20 M30\n")
    step_until(m, lambda: m.channel(1).state == ProgramState.FINISHED)
    assert m.axis("X").setpoint == pytest.approx(100.0)
    assert unit(m).state_r == INACTIVE


@pytest.mark.req("C43-09")
def test_manual_mode_is_not_monitored():
    m = machine()
    ch = m.channel(1)
    set_limit(m, 5.0)
    ch.request_mode(Mode.MANUAL)
    m.step(2)
    assert unit(m).state_r == ACTIVE
    ch.request_jog("X", +1)
    states = set()
    for _ in range(400):
        m.step(1)
        states.add(unit(m).state_r)
    assert m.axis("X").setpoint > 10.0  # jogged through the limit (documented limitation)
    assert states == {ACTIVE}


@pytest.mark.req("C43-06")
def test_stop_point_inside_an_item_is_reached_exactly_without_creeping():
    m = machine()
    ch = m.channel(1)
    start(m, "N10 G01 X100 F6000\nN20 M30\n")
    m.step(10)
    ch.planner.stop_points["test"] = 33.333
    step_until(m, lambda: ch.planner.velocity == 0.0)
    assert m.axis("X").setpoint == pytest.approx(33.333, abs=1e-9)
    m.step(500)
    assert m.axis("X").setpoint == pytest.approx(33.333, abs=1e-9)
    del ch.planner.stop_points["test"]
    step_until(m, lambda: ch.state == ProgramState.FINISHED)


@pytest.mark.req("C43-04", "C43-08")
def test_braking_ramp_is_sampled_at_twenty_points_from_one_cycle_ahead():
    m = machine(feedhold=1000.0)
    ch = m.channel(1)
    start(m, "N10 G01 X500 F6000\nN20 M30\n")
    m.step(300)
    pl = ch.planner
    v = pl.velocity
    assert v == pytest.approx(100.0)
    ramp = _braking_ramp(pl)
    assert ramp is not None
    assert len(ramp.samples) == RAMP_SAMPLES == 20
    s1 = pl.s_abs + v * m.t_a  # at programmed feed the velocity stays
    assert ramp.samples[-1][0] == pytest.approx(s1 + v * v / (2 * 1000.0))
    gaps = [b[0] - a[0] for a, b in pairwise(ramp.samples)]
    assert gaps == sorted(gaps, reverse=True)  # even in time: densest where the ramp ends


MISSED = "N10 G01 X0 Y200 F30000\nN20 X0.2 Y200.2\nN30 X0 Y200.4\nN40 Y600\nN50 M30\n"
"""A fast line along Y with a 0.2 mm bump in X, shorter than the spacing of the ramp's samples."""


@pytest.mark.req("C43-08")
def test_documented_limitation_a_short_contour_element_between_samples_is_missed():
    m = machine(feedhold=300.0)
    set_limit(m, 0.198)
    m.step(2)
    start(m, MISSED)
    states = set()
    x_max = 0.0
    ch = m.channel(1)
    while ch.state != ProgramState.FINISHED:
        m.step(1)
        states.add(unit(m).state_r)
        x_max = max(x_max, m.axis("X").setpoint)
    assert states == {ACTIVE}  # never noticed: the bump lay between two of the 20 samples
    assert x_max > 0.198 + 0.001  # the axis passed the limit
    assert m.axis("Y").setpoint == pytest.approx(600.0)


@pytest.mark.req("C43-08")
def test_documented_limitation_a_short_element_seen_late_overruns_more_than_one_cycle():
    m = machine(feedhold=1000.0)
    set_limit(m, 4.95)
    m.step(2)
    start(m, "N10 G01 X0 Y200 F30000\nN20 X5 Y201\nN30 X0 Y202\nN40 Y600\nN50 M30\n")
    overrun, step_at_overrun = 0.0, 0.0
    x = m.axis("X")
    for _ in range(5000):
        m.step(1)
        if x.setpoint - 4.95 > overrun:
            overrun, step_at_overrun = x.setpoint - 4.95, abs(x.setpoint_step)
        if unit(m).state_r == BRAKE:
            break
    assert unit(m).state_r == BRAKE  # it was seen, but only when too close to stop in front of it
    assert overrun > 0.04
    assert overrun > 10 * step_at_overrun  # far more than the one cycle FCT-C43 allows otherwise


@pytest.mark.req("C43-07")
def test_limit_change_below_p_chan_00751_is_not_adopted():
    m = machine(tol=5_000)  # 0.5 mm
    set_limit(m, 30.0)
    m.step(2)
    start(m, "N10 G01 X100 F6000\nN20 M30\n")
    step_until(m, lambda: unit(m).state_r == BRAKE)
    set_limit(m, 30.4)  # 0.4 mm: below the tolerance, the braking point stays
    m.step(300)
    assert m.axis("X").setpoint == pytest.approx(30.0, abs=1e-6)
    assert unit(m).state_r == BRAKE
    set_limit(m, 30.6)
    step_until(m, lambda: unit(m).state_r == BRAKE and m.axis("X").setpoint > 30.5)
    assert m.axis("X").setpoint == pytest.approx(30.6, abs=1e-6)


@pytest.mark.req("C43-07")
def test_limit_changes_are_adopted_every_p_chan_00874_cycles():
    m = machine(input_cycles=4)
    set_limit(m, 30.0)
    m.step(2)
    start(m, "N10 G01 X100 F6000\nN20 M30\n")
    step_until(m, lambda: unit(m).state_r == BRAKE)
    m.step((4 - m.cycle % 4) % 4 + 1)  # one cycle past an adoption cycle
    set_limit(m, 60.0)
    waited = 0
    while unit(m).state_r == BRAKE:
        m.step(1)
        waited += 1
    assert m.cycle % 4 == 0
    assert waited == 3


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    targets=st.lists(
        st.tuples(
            st.floats(-120, 120),
            st.floats(-50, 50),
            st.sampled_from([0, 1]),
            st.sampled_from([1200, 6000, 15000, 30000]),
        ),
        min_size=1,
        max_size=5,
    ),
    high=st.floats(5, 100),
    low=st.floats(-100, -5),
    feedhold=st.sampled_from([300.0, 1000.0, 4000.0]),
    a_max=st.sampled_from([500.0, 2000.0, 8000.0]),
)
@pytest.mark.req("C43-04", "C43-06")
def test_property_a_dynamic_limit_is_never_passed_by_more_than_one_cycle(
    targets: list[tuple[float, float, int, int]], high: float, low: float, feedhold: float, a_max: float
) -> None:
    m = machine(feedhold=feedhold, a_max=a_max)
    high, low = round(high, 4), round(low, 4)
    set_limit(m, high)
    set_limit(m, low, side="low")
    m.step(2)
    program = "".join(f"G0{g} X{x:.4f} Y{y:.4f} F{f}\n" for x, y, g, f in targets) + "M30\n"
    start(m, program)
    ch = m.channel(1)
    x = m.axis("X")
    worst, largest_step = 0.0, 0.0
    for _ in range(60_000):
        m.step(1)
        largest_step = max(largest_step, abs(x.setpoint_step))
        worst = max(worst, x.setpoint - high, low - x.setpoint)
        held = ch.planner.velocity == 0.0 and BRAKE in (unit(m).state_r, unit(m, side="low").state_r)
        if ch.state != ProgramState.RUNNING or held:
            break
    else:
        raise AssertionError("program neither ended nor held")
    assert worst <= largest_step + 1e-9
    assert worst <= 1e-6  # in fact the simulator stops on the limit when the ramp saw it in time
    assert not m.active_alarms


def test_monitor_state_lookup():
    m = machine()
    mon = m.monitor(DynPosLimits)
    set_limit(m, 1.0, side="low")
    m.step(2)
    assert mon.state("X", "low") == DynPosLimitState.ACTIVE
    with pytest.raises(KeyError):
        mon.state("Q", "low")


@pytest.mark.req("C43-03", "C43-07")
def test_reset_while_held_drops_the_stop_and_a_restart_stops_again():
    m = machine()
    ch = m.channel(1)
    set_limit(m, 25.0)
    m.step(2)
    start(m, "N10 G01 X100 F6000\nN20 M30\n")
    step_until(m, lambda: unit(m).state_r == BRAKE)
    ch.request_reset()
    m.step(2)
    assert unit(m).state_r == ACTIVE  # still enabled, nothing to brake for
    assert not ch.planner.stop_points
    start(m, "N10 G01 X0 F6000\nN20 X100\nN30 M30\n")  # away first, then towards the limit again
    m.step(2)
    step_until(m, lambda: unit(m).state_r == BRAKE)
    assert m.axis("X").setpoint == pytest.approx(25.0, abs=1e-6)
