"""Manual mode limits and P-MANU-00014 (C14-19, E-06, B-04; issue 21).

FCT-C14 6.2, P-MANU-00014 ``move_limit_warning``: "Ist der Parameter mit TRUE belegt, so generiert die
CNC eine Warnung, falls die Handbetriebsbewegung an einer relativen Offsetgrenze (P-AXIS-00137,
P-AXIS-00138) oder einer absoluten Offsetgrenze (P-AXIS-00492, P-AXIS-00493) stoppt."

The kernel's pages of those parameters:
https://infosys.beckhoff.com/content/1033/tf5200_axis_parameter/118110347.html (P-AXIS-00137, default
-1000000, both 0: off), .../118108811.html (P-AXIS-00138, default 1000000),
https://infosys.beckhoff.com/content/1033/tf5200_manual_mode_offset_limit/77659787.html (P-AXIS-00492,
default 0), .../tf5200_axis_parameter/118116619.html (P-AXIS-00493: "both 0: monitoring off"),
https://infosys.beckhoff.com/content/1033/tf5200_manual_mode_offset_limit/77661323.html (P-CHAN-00114:
the relative offset limits in manual mode G200 only when set, default 0).
"""

from __future__ import annotations

import pytest

from hli_server.engine import Machine
from schemas.config import AxisConfig, ChannelConfig, MachineConfig, ManualConfig
from schemas.wire import Mode


def machine(*, warn: bool = True, offsets_in_g200: bool = False, start_x: int = 0, **x: int) -> Machine:
    axes = [
        AxisConfig(number=1, name="X", swe_neg=-5_000_000, swe_pos=5_000_000, start_position=start_x, **x),
        AxisConfig(number=2, name="Y", swe_neg=-5_000_000, swe_pos=5_000_000),
        AxisConfig(number=3, name="Z", swe_neg=-5_000_000, swe_pos=5_000_000),
    ]
    channel = ChannelConfig(axes=["X", "Y", "Z"], rel_offset_limits_std_manual_mode=offsets_in_g200)
    return Machine(MachineConfig(axes=axes, channels=[channel], manual=ManualConfig(move_limit_warning=warn)))


def jog_until_rest(m: Machine, direction: int, cycles: int = 200_000) -> float:
    """Manual mode, hold the X key; the highest |X| the setpoint reached on the way."""
    ch = m.channel(1)
    ch.request_mode(Mode.MANUAL)
    m.step(1)
    assert ch.mode == Mode.MANUAL
    ch.request_jog("X", direction)
    x = m.axis("X")
    m.step(5)
    for _ in range(cycles):
        m.step(1)
        if x.setpoint_step == 0.0:
            break
    ch.request_jog("X", 0)
    return x.setpoint


def warnings(m: Machine) -> list[str]:
    return [a.message for a in m.alarm_history if a.number == 911013]


@pytest.mark.req("C14-19", "B-04")
def test_the_kernels_defaults_of_the_offset_limits() -> None:
    axis = AxisConfig(number=1, name="X")
    assert (axis.offsetgrenze_neg, axis.offsetgrenze_pos) == (-1_000_000, 1_000_000)
    assert (axis.acs_limit_neg, axis.acs_limit_pos) == (0, 0)
    assert ChannelConfig(axes=["X", "Y", "Z"]).rel_offset_limits_std_manual_mode is False


@pytest.mark.req("C14-19", "B-04")
def test_the_acs_limits_stop_a_jog_with_the_p_manu_00014_warning() -> None:
    m = machine(acs_limit_neg=-1_000_000, acs_limit_pos=1_500_000)
    x = jog_until_rest(m, +1)
    assert 149.0 < x <= 150.0
    (message,) = warnings(m)
    assert "positive ACS limit in manual mode (P-AXIS-00493), 150.0000 mm (P-MANU-00014)" in message
    assert [a for a in m.alarm_history if a.severity == "error"] == []
    x = jog_until_rest(m, -1)
    assert -100.0 <= x < -99.0
    assert "negative ACS limit in manual mode (P-AXIS-00492)" in warnings(m)[-1]
    # without P-MANU-00014 the axes stop just the same, silently
    quiet = machine(warn=False, acs_limit_neg=-1_000_000, acs_limit_pos=1_500_000)
    assert 149.0 < jog_until_rest(quiet, +1) <= 150.0
    assert warnings(quiet) == []


@pytest.mark.req("C14-19", "B-04")
def test_the_relative_offset_limits_count_from_where_manual_mode_was_selected() -> None:
    # P-CHAN-00114 = 1: in G200 the default offsets, +/-100 mm from X = 20 mm
    m = machine(offsets_in_g200=True, start_x=200_000)
    x = jog_until_rest(m, +1)
    assert 119.0 < x <= 120.0
    assert "positive offset limit (P-AXIS-00138, 100 mm from 20 mm" in warnings(m)[0]
    # a new selection of manual mode counts from the new place
    m.channel(1).request_mode(Mode.AUTOMATIC)
    m.step(1)
    x = jog_until_rest(m, -1)
    assert 19.0 < x <= 20.0 + 1e-6  # 100 mm below where it stood (about 120 mm)
    assert "negative offset limit (P-AXIS-00137, 100 mm from 119.99" in warnings(m)[-1]


@pytest.mark.req("C14-19", "B-04")
def test_without_p_chan_00114_or_with_both_offsets_0_the_offsets_do_not_limit_g200() -> None:
    m = machine(start_x=200_000)  # P-CHAN-00114 = 0 (the default)
    assert 499.0 < jog_until_rest(m, +1) <= 500.0
    assert "positive software limit (P-AXIS-00178)" in warnings(m)[0]
    off = machine(offsets_in_g200=True, offsetgrenze_neg=0, offsetgrenze_pos=0)
    assert 499.0 < jog_until_rest(off, +1) <= 500.0
