"""Software limit switches with the kernel's numbers (E-06, B-04; issue 21).

The pages these tests hold the engine to:

* the kernel's software limit switch description (messages):
  https://infosys.beckhoff.com/content/1033/swlimit/15311258251.html ("message [ID: 120002 or 120003]"
  for a programmed position, "(ID: 70021 or 70022)" for an actual one);
* ID 70021 "Positive software limit switch actuated":
  https://www.isg-stuttgart.de/fileadmin/kernel/kernel-html/en-GB/259906699.html;
* P-AXIS-00179 ``swe_toleranz``, default 1000 (0.1 mm), "to prevent ... slight overshoot":
  https://infosys.beckhoff.com/content/1033/tf5200_axis_parameter/117309963.html;
* P-CHAN-00120 ``soft_limit_tolerance``: https://infosys.beckhoff.com/content/1033/tf5200_channel_parameter/149357707.html;
* P-AXIS-00177/00178 "Anmerkungen": "Der Wert des Parameters wird bei Reset, Betriebsartenwechsel und
  Achstausch aus dem Achsdatensatz übernommen" (FCT-C14 6.2).
"""

from __future__ import annotations

import math

import pytest

from hli_server.engine import Machine
from schemas.config import AxisConfig, ChannelConfig, MachineConfig
from schemas.wire import Mode, ProgramState

from .engine_helpers import mill, run


def machine(**axis: object) -> Machine:
    """X/Y/Z within -600..600 mm, the default drive model (it overshoots a stop by some 20 µm)."""
    axes = [
        AxisConfig(number=i + 1, name=n, swe_neg=-6_000_000, swe_pos=6_000_000, **axis)  # type: ignore[arg-type]
        for i, n in enumerate("XYZ")
    ]
    return Machine(MachineConfig(axes=axes, channels=[ChannelConfig(axes=["X", "Y", "Z"])]))


@pytest.mark.req("E-06", "B-04")
def test_a_path_that_ends_on_the_limit_is_no_error_with_the_kernels_default_tolerance() -> None:
    """The issue's case: the actual position settles past a setpoint stopped on the limit. With the
    kernel's default P-AXIS-00179 (1000 = 0.1 mm) that is no error; with 0 it is 70021."""
    assert AxisConfig(number=1, name="X").swe_toleranz == 1000
    m = machine()
    run(m, "N10 G01 X600 F10000\nN20 M30\n")
    x = m.axis("X")
    overshoot = 0.0
    for _ in range(2000):
        m.step(1)
        overshoot = max(overshoot, x.measured - 600.0)
    assert x.setpoint == pytest.approx(600.0)
    assert 0.001 < overshoot < 0.1  # the drive ran past the stopped setpoint, within the tolerance
    assert list(m.alarm_history) == []
    assert m.channel(1).state == ProgramState.FINISHED
    strict = machine(swe_toleranz=0)
    run(strict, "N10 G01 X600 F10000\nN20 M30\n")
    strict.step(2000)
    (alarm,) = [a for a in strict.alarm_history if a.number == 70021]
    assert alarm.axis == "X"
    assert alarm.params["limit"] == 6_000_000
    assert 6_000_000 < alarm.params["position"] < 6_001_000  # past the limit by less than 0.1 mm


@pytest.mark.req("E-06", "B-04")
def test_programmed_positions_beyond_a_limit_are_120002_and_120003() -> None:
    m = mill()
    run(m, "N10 G01 X100 F6000\nN20 X501\nN30 M30\n")
    (alarm,) = m.active_alarms
    assert (alarm.number, alarm.block, alarm.axis) == (120002, "N20", "X")
    assert alarm.params == {
        "axes": ["X", "Y", "Z"],
        "start": [100.0, 0.0, 0.0],
        "end": [501.0, 0.0, 0.0],
        "axis": "X",
        "axis_number": 1,
        "position": 5_010_000,
        "limit": 5_000_000,
        "intersection": [500.0, 0.0, 0.0],  # where the refused block would cross the limit
    }
    assert "beyond the positive software limit 500.0000 mm (P-AXIS-00178)" in alarm.message
    assert m.axis("X").setpoint == pytest.approx(100.0)  # the block was not executed
    m = mill()
    run(m, "N10 G01 Y-500.0001 F6000\nN20 M30\n")
    (alarm,) = m.active_alarms
    assert (alarm.number, alarm.axis, alarm.params["limit"]) == (120003, "Y", -5_000_000)


@pytest.mark.req("E-06", "B-04")
def test_actual_positions_beyond_a_limit_are_70021_and_70022() -> None:
    for position, number in ((500.2, 70021), (-500.2, 70022)):
        m = mill()  # swe_toleranz 1000 (the default): 0.1 mm
        x = m.axis("X")
        x.actual = x.measured = position
        m.step(1)
        (alarm,) = m.active_alarms
        assert (alarm.number, alarm.axis, alarm.severity) == (number, "X", "error")
        side = "positive" if number == 70021 else "negative"
        assert f"beyond the {side} software limit" in alarm.message


def _standing_beyond(soft_limit_tolerance: bool) -> Machine:
    """X stands at 500.05 mm, past its limit 500 mm but within its tolerance 0.1 mm."""
    axes = [
        AxisConfig(number=i + 1, name=n, swe_neg=-5_000_000, swe_pos=5_000_000, start_position=start)
        for i, (n, start) in enumerate((("X", 5_000_500), ("Y", 0), ("Z", 0)))
    ]
    channel = ChannelConfig(axes=["X", "Y", "Z"], soft_limit_tolerance=soft_limit_tolerance)
    return Machine(MachineConfig(axes=axes, channels=[channel]))


@pytest.mark.req("E-06", "B-04")
def test_p_chan_00120_tolerance_in_path_preparation_for_axes_that_do_not_move() -> None:
    """P-CHAN-00120: with 0 an axis outside the limits makes the program's blocks a software limit
    error ("Stehen Achsen bei Programmstart außerhalb ... meldet die CNC einen SWE-Fehler"); with 1 the
    tolerance P-AXIS-00179 is considered, "nur, wenn die Achse nicht programmiert bzw. bewegt ist"."""
    program = "N10 G01 Y50 F6000\nN20 M30\n"
    without = _standing_beyond(False)
    run(without, program)
    (alarm,) = without.active_alarms
    assert (alarm.number, alarm.axis, alarm.block) == (120002, "X", "N10")
    with_tolerance = _standing_beyond(True)
    run(with_tolerance, program)
    assert list(with_tolerance.alarm_history) == []
    assert with_tolerance.channel(1).setpoints()[1] == pytest.approx(50.0)
    # the axis is programmed (moved): no tolerance for it
    moved = _standing_beyond(True)
    run(moved, "N10 G01 X500.04 F6000\nN20 M30\n")
    (alarm,) = moved.active_alarms
    assert (alarm.number, alarm.axis) == (120002, "X")
    assert "P-CHAN-00120" not in alarm.message


@pytest.mark.req("E-06", "B-04")
def test_limits_set_in_between_hold_until_reset_then_the_axis_record_applies() -> None:
    m = mill()
    x = m.axis("X")
    x.set_soft_limits(positive=100.0)  # what the kernel's G99 does
    run(m, "N10 G01 X150 F6000\nN20 M30\n")
    assert [a.number for a in m.active_alarms] == [120002]
    ch = m.channel(1)
    ch.request_reset()
    m.step(50)
    assert x.swe_pos == 500.0  # P-AXIS-00178 from the axis record at the reset
    run(m, "N10 G01 X150 F6000\nN20 M30\n")
    assert list(m.active_alarms) == []
    assert x.setpoint == pytest.approx(150.0)


@pytest.mark.req("E-06", "B-04")
def test_a_mode_change_takes_the_limits_from_the_axis_record() -> None:
    m = mill()
    x = m.axis("X")
    x.set_soft_limits(negative=-10.0, positive=10.0)
    ch = m.channel(1)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    assert ch.mode == Mode.MANUAL
    assert (x.swe_neg, x.swe_pos) == (-500.0, 500.0)


@pytest.mark.req("E-06", "B-04")
def test_a_changed_axis_record_takes_effect_at_reset_and_mode_change_only() -> None:
    m = mill()
    x = m.axis("X")
    m.update_axis_record("X", swe_pos=1_000_000)  # 100 mm in the record
    assert x.swe_pos == 500.0  # not yet
    run(m, "N10 G01 X150 F6000\nN20 M30\n")
    assert list(m.active_alarms) == []
    m.channel(1).request_reset()
    m.step(1)
    assert x.swe_pos == 100.0
    m.update_axis_record("X", swe_toleranz=2000)
    m.channel(1).request_mode(Mode.MANUAL)
    m.step(1)
    assert x.swe_tol == pytest.approx(0.2)
    with pytest.raises(ValueError, match="swe_neg"):
        m.update_axis_record("X", swe_neg=2_000_000)  # above swe_pos: the parameter's range
    with pytest.raises(ValueError, match="cannot be changed at run time"):
        m.update_axis_record("X", a_max=10.0)
    assert x.config.swe_pos == 1_000_000  # a refused change changes nothing


@pytest.mark.req("E-06")
def test_a_refused_arc_names_where_it_would_first_cross_the_limit() -> None:
    """Issue 37, item 3: the alarm carries the refused block's path (its arc) and the first point on it
    beyond the limit, so that ``check --plot`` and the dashboard draw it as they draw an area's refusal.
    The clockwise circle from (100, 0) around (-260, 0), radius 360, goes down first and meets X = -500 at
    the angle whose cosine is -240/360, below the X axis."""
    m = mill()  # X within -500..500 mm
    run(m, "N10 G01 X100 F6000\nN20 G02 X100 Y0 I-360 J0\nN30 M30\n")
    (alarm,) = m.active_alarms
    assert (alarm.number, alarm.block, alarm.axis) == (120003, "N20", "X")
    params = alarm.params
    assert params["arc"] == {"plane": ["X", "Y"], "centre": [-260.0, 0.0], "sweep_deg": -360.0}
    x, y, z = params["intersection"]
    assert x == pytest.approx(-500.0)
    assert y == pytest.approx(-360.0 * math.sin(math.acos(-240.0 / 360.0)))
    assert y < 0.0
    assert z == 0.0
