"""Axis collision monitoring, FCT-C3 (C3-01..C3-10), stepped cycle by cycle.

Distance convention (docs/monitors.md): in the master axis' coordinates,
d = |x_master - (coll_zero_position_offset + sigma * x_partner)|, sigma = -1 with P-AXIS-00262.
"""

from __future__ import annotations

from itertools import pairwise

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hli_server.engine import Machine
from hli_server.engine.monitors.collision import (
    CollisionMonitor,
)
from hli_server.image.projection import engine_value
from schemas.config import AxisConfig, ChannelConfig, MachineConfig
from schemas.layout import build_layout
from schemas.wire import Mode, ProgramState

RUNNING = (ProgramState.RUNNING, ProgramState.HELD)
PAIR = 0x8001
A_MAX = 2000.0
"""P-AXIS-00008 of the pair in these tests (the kernel's default is 1000; the numbers below are for 2000)."""


def one_channel(
    *,
    x1: float = 0.0,
    x2: float = 100.0,
    offset: int = 200_000,
    master: dict[str, object] | None = None,
    partner: dict[str, object] | None = None,
) -> Machine:
    """X1 (A_ID 1) and X2 (A_ID 2, master) on one rail in one channel, with the lift Z1."""
    axes = [
        AxisConfig(
            number=1,
            name="X1",
            achs_mode=PAIR,
            start_position=round(x1 * 1e4),
            **{"a_max": A_MAX, **(partner or {})},  # type: ignore[arg-type]
        ),
        AxisConfig(
            number=2,
            name="X2",
            achs_mode=PAIR,
            coll_check_ax_nr=1,
            coll_offset=offset,
            start_position=round(x2 * 1e4),
            **{"a_max": A_MAX, **(master or {})},  # type: ignore[arg-type]
        ),
        AxisConfig(number=3, name="Z1"),
    ]
    ch = ChannelConfig(axes=["X1", "X2", "Z1"], main_axes=("X1", "X2", "Z1"))
    return Machine(MachineConfig(axes=axes, channels=[ch]))


def two_channels(*, x1: float = 0.0, x2: float = 0.0, **master: object) -> Machine:
    """FCT-C3 Abb. 5: X1 (A_ID 1) in channel 1, X2 (A_ID 6, master) in channel 2."""
    axes = [
        AxisConfig(number=1, name="X1", achs_mode=PAIR, start_position=round(x1 * 1e4), a_max=A_MAX),
        AxisConfig(number=2, name="Y1"),
        AxisConfig(number=3, name="Z1"),
        AxisConfig(
            number=6,
            name="X2",
            achs_mode=PAIR,
            coll_check_ax_nr=1,
            coll_offset=200_000,
            start_position=round(x2 * 1e4),
            **{"a_max": A_MAX, **master},  # type: ignore[arg-type]
        ),
        AxisConfig(number=7, name="Y2"),
        AxisConfig(number=8, name="Z2"),
    ]
    channels = [
        ChannelConfig(number=1, axes=["X1", "Y1", "Z1"], main_axes=("X1", "Y1", "Z1")),
        ChannelConfig(number=2, name="Channel 2", axes=["X2", "Y2", "Z2"], main_axes=("X2", "Y2", "Z2")),
    ]
    return Machine(MachineConfig(axes=axes, channels=channels))


def start(m: Machine, program: str, channel: int = 1) -> None:
    ch = m.channel(channel)
    ch.load_program(program)
    ch.request_start()


def run_until_stopped(m: Machine, limit: int = 20_000) -> None:
    for _ in range(limit):
        m.step(1)
        if all(ch.state not in RUNNING for ch in m.channels) and all(
            a.setpoint_step == 0.0 and a.stop_velocity == 0.0 for a in m.axes
        ):
            return
    raise AssertionError("still moving")


def distance(m: Machine) -> float:
    return abs(m.axis("X2").setpoint - m.axis("X1").setpoint)


def monitor(m: Machine) -> CollisionMonitor:
    return m.monitor(CollisionMonitor)


def obj(m: Machine, a_id: int, element: int) -> bool | int | float:
    """The CNC object at ADS port 551, group 0x120300, offset (A_ID << 16) | element (C3-10): the
    layout names the field, the engine keeps its value."""
    signal = build_layout(m.config).ads_index()[(551, 0x120300, (a_id << 16) | element)]
    return engine_value(m.hli, signal)


ACTIVE, VELOCITY, BRAKE_DIST, OFFSET, DECEL = 0x0234, 0x0244, 0x0245, 0x0246, 0x0247


@pytest.mark.slow
@pytest.mark.req("C3-01", "C3-08", "C3-10")
def test_pair_stops_when_distance_less_braking_distance_falls_below_the_minimum():
    m = one_channel()
    start(m, "N10 G01 X1=90 F12000\nN20 M30\n")
    x1 = m.axis("X1")
    margins: list[float] = []
    trip_cycle = None
    for _ in range(3000):
        m.step(1)
        if m.active_alarms:
            trip_cycle = m.cycle
            break
        # C3-08 from the setpoints, and the CNC objects say the same
        v = (x1.setpoint - x1.prev_setpoint) / m.t_a
        s_brake = v * v / (2 * 2000.0)
        assert obj(m, 1, VELOCITY) == pytest.approx(v * 1e4)
        assert obj(m, 1, BRAKE_DIST) == pytest.approx(s_brake * 1e4)
        assert obj(m, 2, VELOCITY) == 0.0
        margins.append(distance(m) - s_brake)
    assert trip_cycle is not None
    assert min(margins) >= 20.0 - 1e-9  # every setpoint given to the drives passed the check
    (alarm,) = m.active_alarms
    assert alarm.number == 70092
    assert (alarm.line, alarm.block, alarm.axis) == (1, "N10", "X2/X1")
    assert alarm.params["distance"] - alarm.params["brake_dist"] < alarm.params["coll_offset"] == 200_000
    # X1 brakes on its own with a_max (P-AXIS-00008) from the last checked state
    v_prev = x1.setpoint_step / m.t_a
    velocities = [v_prev]
    while x1.stopping and x1.stop_velocity > 0:
        m.step(1)
        velocities.append(x1.setpoint_step / m.t_a)
    steps = [a - b for a, b in pairwise(velocities) if b > 0]
    assert steps
    assert all(s == pytest.approx(2000.0 * m.t_a) for s in steps)
    assert distance(m) >= 20.0
    assert m.channel(1).state == ProgramState.ABORTED
    m.step(50)
    assert distance(m) >= 20.0
    assert x1.stopping


@pytest.mark.req("C3-01", "C3-07", "C3-10")
def test_each_axis_brakes_with_its_own_deceleration_and_leaves_the_contour():
    m = one_channel(
        master={"coll_use_a_emergency": True, "a_max": 4000.0, "a_emergency": 8000.0},
        partner={"a_max": 1000.0},
    )
    assert obj(m, 2, DECEL) == 8000.0  # P-AXIS-00267 on the master: both axes use a_emergency
    # the partner's a_emergency is the kernel's default 0: P-AXIS-00003 is then a_max (its page)
    assert obj(m, 1, DECEL) == 1000.0
    start(m, "N10 G01 X1=60 X2=70 F12000\nN20 M30\n")  # both towards each other, 2:1
    x1, x2 = m.axis("X1"), m.axis("X2")
    while not m.active_alarms:
        m.step(1)
    v1, v2 = [x1.setpoint_step / m.t_a], [x2.setpoint_step / m.t_a]
    while x1.stop_velocity or x2.stop_velocity:
        m.step(1)
        v1.append(x1.setpoint_step / m.t_a)
        v2.append(x2.setpoint_step / m.t_a)
    d1 = {round((a - b) / m.t_a) for a, b in pairwise(v1) if abs(b) > 0}
    d2 = {round((b - a) / m.t_a) for a, b in pairwise(v2) if abs(b) > 0}
    assert d1 == {1000}
    assert d2 == {8000}
    travelled_1, travelled_2 = x1.setpoint, 100.0 - x2.setpoint
    assert travelled_1 / travelled_2 != pytest.approx(2.0, rel=0.01)  # off the programmed line
    assert distance(m) >= 20.0


@pytest.mark.req("C3-10")
def test_cnc_objects_by_index_group_and_offset():
    m = one_channel()
    m.step(1)
    layout = build_layout(m.config)
    objects = {s.path.split(".")[1]: s for s in layout if s.path.startswith("dyn_coll_mon.") and s.index == 0}
    assert {
        name: (str(s.type), s.size, s.ads_port, s.ads_group, s.ads_offset & 0xFFFF)
        for name, s in objects.items()
    } == {
        "active": ("BOOL", 1, 551, 0x120300, 0x0234),
        "velocity": ("LREAL", 8, 551, 0x120300, 0x0244),
        "brake_dist": ("LREAL", 8, 551, 0x120300, 0x0245),
        "coll_offset": ("UDINT", 4, 551, 0x120300, 0x0246),
        "deceleration": ("LREAL", 8, 551, 0x120300, 0x0247),
    }
    assert obj(m, 2, 0x0234) is True
    assert obj(m, 1, 0x0246) == 200_000
    assert obj(m, 2, 0x0247) == 2000.0
    assert obj(m, 3, 0x0234) is False  # Z1: no pair
    for address in ((551, 0x120301, 0x00010234), (551, 0x120300, 0x00010235), (551, 0x120300, 0x00090234)):
        assert address not in layout.ads_index()


@pytest.mark.req("C3-10", "B-04")
def test_the_coll_offset_object_is_the_minimum_distance_in_effect_not_the_current_distance():
    """FCT-C3 4.3 names object 0x..0246 "dyn_coll_mon coll_offset - Distanz zwischen Kollisionsachsen",
    UNS32, 0.1 µm (the kernel's page: https://infosys.beckhoff.com/content/1033/tf5200_axis_collision_mon/
    1223993099.html). Decided (issue 21, docs/monitors.md): it is the minimum distance in effect, the
    parameter P-AXIS-00045 coll_offset ("Minimale Distanz zwischen zwei Kollisionsachsen"), not the
    distance the axes have now: it has the parameter's name, type and unit; a distance of setpoints is
    signed (the axes can pass each other with P-AXIS-00262/00263) and would be a REAL64 like velocity
    and brake_dist; and #COLL MON ON, the NC command of the same dynamic collision monitoring, sets it
    as DIST "analog zu P-AXIS-00045"."""
    m = one_channel(x1=0.0, x2=100.0)
    m.step(1)
    assert (obj(m, 1, 0x0246), obj(m, 2, 0x0246)) == (200_000, 200_000)  # both axes of the pair
    start(m, "N10 G01 X1=50 F6000\nN20 M30\n")
    run_until_stopped(m)
    assert distance(m) == pytest.approx(50.0)
    assert (obj(m, 1, 0x0246), obj(m, 2, 0x0246)) == (200_000, 200_000)  # not 500000: not the distance
    # the older two-sided form with two values: the larger applies (70162) and is the object's value
    two_sided = one_channel(offset=200_000, partner={"coll_check_ax_nr": 2, "coll_offset": 250_000})
    two_sided.step(1)
    assert (obj(two_sided, 1, 0x0246), obj(two_sided, 2, 0x0246)) == (250_000, 250_000)
    assert obj(two_sided, 3, 0x0246) == 0  # Z1: no pair


@pytest.mark.req("C3-06")
def test_monitoring_starts_only_when_both_axes_are_referenced():
    m = one_channel(x1=0.0, x2=100.0, partner={"referenced": False})
    ch = m.channel(1)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    assert obj(m, 1, ACTIVE) is False
    assert obj(m, 2, ACTIVE) is False
    ch.request_jog("X1", +1)
    while m.axis("X1").setpoint < 90.0:
        m.step(1)
    ch.request_jog("X1", 0)
    m.step(200)
    assert not m.alarm_history  # 10 mm apart, but X1 is not referenced
    m.axis("X1").referenced = True
    m.step(1)
    assert obj(m, 1, ACTIVE) is True
    assert [a.number for a in m.active_alarms] == [70092]  # too close the moment monitoring starts


@pytest.mark.req("C3-02")
def test_after_reset_the_pair_may_only_move_apart():
    m = one_channel()
    ch = m.channel(1)
    start(m, "N10 G01 X1=95 F6000\nN20 M30\n")
    run_until_stopped(m)
    assert [a.number for a in m.active_alarms] == [70092]
    stopped_at = distance(m)
    ch.request_reset()
    m.step(2)
    assert not m.active_alarms
    # a block that brings the pair closer is refused before it moves
    x1_before = m.axis("X1").setpoint
    start(m, "N10 G01 X1=50 F6000\nN20 G01 X1=80.5\nN30 M30\n")
    run_until_stopped(m)
    (alarm,) = m.active_alarms
    assert (alarm.number, alarm.block, alarm.line) == (913000, "N20", 2)
    assert m.axis("X1").setpoint == pytest.approx(50.0)  # N10 (apart) ran, N20 did not
    assert x1_before > 50.0
    ch.request_reset()
    m.step(2)
    # the pair was moved apart: normal monitoring again, an approach trips again
    start(m, "N10 G01 X1=85 F6000\nN20 M30\n")
    run_until_stopped(m)
    assert [a.number for a in m.active_alarms] == [70092]
    assert distance(m) >= 20.0
    assert stopped_at >= 20.0


@pytest.mark.req("C3-02")
def test_after_reset_jogging_towards_each_other_brakes_and_apart_moves():
    m = one_channel()
    ch = m.channel(1)
    start(m, "N10 G01 X1=95 F6000\nN20 M30\n")
    run_until_stopped(m)
    ch.request_reset()
    ch.request_mode(Mode.MANUAL)
    m.step(2)
    assert ch.mode == Mode.MANUAL
    x1 = m.axis("X1")
    held = x1.setpoint
    ch.request_jog("X1", +1)  # towards X2
    m.step(300)
    assert x1.setpoint == held
    assert not m.active_alarms
    ch.request_jog("X1", -1)  # apart
    m.step(300)
    assert x1.setpoint < held - 5.0
    ch.request_jog("X1", 0)
    m.step(200)
    assert not monitor(m).pairs[0].latched  # moved apart and at rest: released


@pytest.mark.req("C3-03", "C3-10")
def test_chain_of_pairs():
    axes = [
        AxisConfig(number=1, name="X1", achs_mode=PAIR),
        AxisConfig(
            number=2,
            name="X2",
            achs_mode=PAIR,
            coll_check_ax_nr=1,
            coll_offset=200_000,
            start_position=500_000,
        ),
        AxisConfig(
            number=3,
            name="X3",
            achs_mode=PAIR,
            coll_check_ax_nr=2,
            coll_offset=300_000,
            start_position=1_000_000,
        ),
    ]
    cfg = MachineConfig(
        axes=axes, channels=[ChannelConfig(axes=["X1", "X2", "X3"], main_axes=("X1", "X2", "X3"))]
    )
    m = Machine(cfg)
    assert [p.label for p in monitor(m).pairs] == ["X2/X1", "X3/X2"]
    m.step(1)
    assert [obj(m, a, OFFSET) for a in (1, 2, 3)] == [200_000, 200_000, 300_000]
    start(m, "N10 G01 X2=90 F6000\nN20 M30\n")  # X2 towards X3
    run_until_stopped(m)
    (alarm,) = m.active_alarms
    assert alarm.axis == "X3/X2"
    assert m.axis("X3").setpoint - m.axis("X2").setpoint >= 30.0
    m.channel(1).request_reset()
    m.step(2)
    start(m, "N10 G01 X2=10 F6000\nN20 M30\n")  # now towards X1
    run_until_stopped(m)
    (alarm,) = m.active_alarms
    assert alarm.axis == "X2/X1"
    assert m.axis("X2").setpoint - m.axis("X1").setpoint >= 20.0


@pytest.mark.req("C3-04")
def test_older_two_sided_configuration_takes_the_larger_offset_with_warning_70162():
    m = one_channel(offset=200_000, partner={"coll_check_ax_nr": 2, "coll_offset": 250_000})
    warnings = [a for a in m.alarm_history if a.number == 70162]
    assert len(warnings) == 1
    assert not m.active_alarms
    assert "250000" in warnings[0].message
    assert len(monitor(m).pairs) == 1
    start(m, "N10 G01 X1=90 F6000\nN20 M30\n")
    run_until_stopped(m)
    assert [a.number for a in m.active_alarms] == [70092]
    assert 25.0 <= distance(m) < 26.0
    assert len([a for a in m.alarm_history if a.number == 70162]) == 1  # once, at start
    same = one_channel(partner={"coll_check_ax_nr": 2, "coll_offset": 200_000})
    assert not same.alarm_history


@pytest.mark.req("C3-09", "C3-05")
def test_two_channels_inverted_direction_and_zero_offset():
    # X2's zero point lies at 100 mm in X1... no: X1's zero point lies at 100 mm in X2's coordinates,
    # and X1 counts the other way (FCT-C3 Abb. 5/6): X1 = 0 is 100 mm from X2 = 0.
    m = two_channels(x1=0.0, x2=0.0, coll_moving_dir_inverted=True, coll_zero_position_offset=1_000_000)

    def d() -> float:
        return abs(m.axis("X2").setpoint - (100.0 - m.axis("X1").setpoint))

    assert d() == 100.0
    start(m, "N10 G01 X1=-50 F6000\nN20 M30\n", channel=1)  # mechanically away from X2
    run_until_stopped(m)
    assert not m.active_alarms
    assert d() == pytest.approx(150.0)
    start(m, "N10 G01 X1=60 F3000\nN20 M30\n", channel=1)
    start(m, "N10 G01 X2=40 F1200\nN20 M30\n", channel=2)
    run_until_stopped(m)
    assert sorted((a.number, a.channel) for a in m.active_alarms) == [(70092, 1), (70092, 2)]
    assert d() >= 20.0
    assert m.channel(1).state == m.channel(2).state == ProgramState.ABORTED


@pytest.mark.req("C3-05")
@pytest.mark.parametrize("decelerate_chan", [True, False])
def test_drive_error_of_one_axis_stops_both_channels_with_p_axis_00044(decelerate_chan: bool):
    m = two_channels(x1=0.0, x2=500.0, coll_decelerate_chan=decelerate_chan)
    start(m, "N10 G01 X1=100 Y1=100 F3000\nN20 M30\n", channel=1)
    start(m, "N10 G01 X2=600 Y2=100 F3000\nN20 M30\n", channel=2)
    m.step(300)
    m.inject_fault("X1", drive_error=True)
    m.step(1)
    raised = sorted((a.number, a.channel) for a in m.active_alarms)
    if decelerate_chan:
        assert raised == [(911030, 1), (911030, 2)]
        assert all(a.stopping for a in m.axes if a.name in ("X2", "Y2", "Z2"))
        run_until_stopped(m)
        assert m.channel(2).state == ProgramState.ABORTED
    else:
        assert raised == [(911030, 1)]
        run_until_stopped(m)
        assert m.channel(2).state == ProgramState.FINISHED
    assert m.channel(1).state == ProgramState.ABORTED


@pytest.mark.slow
@pytest.mark.req("C3-01", "C3-02")
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    programs=st.lists(
        st.lists(
            st.tuples(
                st.floats(-50, 150),
                st.floats(-50, 150),
                st.sampled_from([0, 1]),
                st.sampled_from([600, 6000, 30000]),
            ),
            min_size=1,
            max_size=4,
        ),
        min_size=1,
        max_size=3,
    ),
    a_max=st.tuples(st.sampled_from([300.0, 2000.0, 6000.0]), st.sampled_from([300.0, 2000.0, 6000.0])),
    use_emergency=st.booleans(),
)
def test_property_the_pair_never_gets_closer_than_the_minimum(
    programs: list[list[tuple[float, float, int, int]]], a_max: tuple[float, float], use_emergency: bool
) -> None:
    m = one_channel(
        x1=0.0,
        x2=100.0,
        partner={"a_max": a_max[0]},
        master={"a_max": a_max[1], "coll_use_a_emergency": use_emergency},
    )
    ch = m.channel(1)
    closest = distance(m)
    for blocks in programs:
        text = "".join(f"G0{g} X1={a:.3f} X2={b:.3f} F{f}\n" for a, b, g, f in blocks) + "M30\n"
        start(m, text)
        for _ in range(100_000):
            m.step(1)
            closest = min(closest, distance(m))
            if ch.state not in RUNNING and all(a.setpoint_step == 0.0 for a in m.axes):
                break
        if m.active_alarms:
            assert {a.number for a in m.active_alarms} <= {70092, 913000}
            ch.request_reset()
            m.step(2)
            closest = min(closest, distance(m))
    assert closest >= 20.0 - 1e-9
