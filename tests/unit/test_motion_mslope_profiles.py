"""Acceleration profiles (#SLOPE, P-CHAN-00071, P-AXIS-00195..00198; issue 24 item 1, M-01..M-05),
stepped cycle by cycle: the axes' setpoints are what a drive would get."""

from __future__ import annotations

from itertools import pairwise

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hli_server.engine import Machine
from hli_server.engine.path.profiles import PathFilter, SlopeProfile, SlopeType
from schemas.config import AxisConfig, ChannelConfig, MachineConfig
from schemas.wire import ProgramState
from tests.unit.engine_helpers import cycles_until_done, positions, start
from tests.unit.nc_helpers import error

T_A = 1e-3


def machine(
    *, profile: int = 0, ramp_us: int = 50_000, a_max: float = 1000.0, feedhold: float = 1000.0, fct: str = ""
) -> Machine:
    axes = [
        AxisConfig(
            number=i + 1,
            name=n,
            a_max=a_max,
            tr_beschl_ab=ramp_us,
            tr_beschl_zu=ramp_us,
            tr_brems_ab=ramp_us,
            tr_brems_zu=ramp_us,
        )
        for i, n in enumerate("XYZ")
    ]
    channel = ChannelConfig(
        axes=["X", "Y", "Z"],
        slope_profile=profile,
        feedhold_deceleration=feedhold,
        **({"interpolator_function": fct} if fct else {}),  # type: ignore[arg-type]
    )
    return Machine(MachineConfig(axes=axes, channels=[channel]))


def trace(m: Machine, program: str, axis: str = "X") -> list[float]:
    start(m, program)
    xs = [m.axis(axis).setpoint]
    for _ in cycles_until_done(m):
        xs.append(m.axis(axis).setpoint)
    return xs


def derivatives(xs: list[float]) -> tuple[list[float], list[float], list[float]]:
    v = [(b - a) / T_A for a, b in pairwise(xs)]
    acc = [(b - a) / T_A for a, b in pairwise(v)]
    jerk = [(b - a) / T_A for a, b in pairwise(acc)]
    return v, acc, jerk


LINE = "N10 G01 X100 F6000\nN20 X0\nN30 M30\n"


# --- the profiles ------------------------------------------------------------------------------------
@pytest.mark.req("M-01", "M-02")
@pytest.mark.parametrize(
    ("head", "expected", "jerk_bound"),
    [
        ("", SlopeType.STEP, None),
        ("#SLOPE [TYPE=STEP]\n", SlopeType.STEP, None),
        ("#SLOPE [TYPE=TRAPEZ]\n", SlopeType.TRAPEZ, 1.0),
        ("#SLOPE [TYPE=SIN2 NO_OPT=1]\n", SlopeType.SIN2, 3.1416 / 2),
        ("#SLOPE [TYPE=HSC]\n", SlopeType.HSC, 1.0),
    ],
)
def test_slope_type_shapes_the_acceleration(head: str, expected: SlopeType, jerk_bound: float | None) -> None:
    """The manual's #SLOPE example (207190411): the profile from the block on. The jerk of a
    jerk-limited profile is a / t_r (TRAPEZ, HSC) or pi/2 * a / t_r (SIN2's steepest point), the
    acceleration never above the planner's; STEP lets the acceleration jump."""
    m = machine()
    xs = trace(m, head + LINE)
    assert m.channel(1).planner.profile.type == expected
    assert positions(m)["X"] == pytest.approx(0.0)
    assert max(xs) == pytest.approx(100.0)
    _, acc, jerk = derivatives(xs)
    a, t_r = 1000.0, 0.05
    assert max(abs(x) for x in acc) <= 1.13 * a  # the step profile's discrete ramp reaches 1.125 a
    if jerk_bound is None:
        assert max(abs(j) for j in jerk) > 10 * a / t_r  # steps in the acceleration (a/T_A)
    else:
        # the step profile's own rounding (its first cycle at a/2, its braking curve) adds up to 1/8
        assert max(abs(j) for j in jerk) <= 1.13 * jerk_bound * a / t_r
        assert max(abs(j) for j in jerk) >= 0.9 * jerk_bound * a / t_r


@pytest.mark.req("M-01")
def test_p_chan_00071_is_the_profile_at_start_and_slope_default_restores_it() -> None:
    m = machine(profile=2)
    ch = m.channel(1)
    seen: list[SlopeType] = []
    start(m, "N10 G01 X10 F6000\n#SLOPE [TYPE=TRAPEZ]\nN20 X20\n#SLOPE DEFAULT\nN30 X30\nN40 M30\n")
    for _ in cycles_until_done(m):
        if not seen or seen[-1] != ch.planner.profile.type:
            seen.append(ch.planner.profile.type)
    assert seen == [SlopeType.SIN2, SlopeType.TRAPEZ, SlopeType.SIN2]
    assert positions(m)["X"] == pytest.approx(30.0)
    # every program start begins with P-CHAN-00071 again
    start(m, "N10 G01 X0 F6000\n#SLOPE [TYPE=STEP]\nN20 X5\nN30 M30\n")
    assert ch.planner.profile.type == SlopeType.SIN2
    for _ in cycles_until_done(m):
        pass
    assert ch.planner.profile.type == SlopeType.STEP


@pytest.mark.req("M-01")
@pytest.mark.parametrize(
    "line",
    [
        "#SLOPE [TYPE=LINEAR]",
        "#SLOPE [NO_OPT=1]",
        "#SLOPE TRAPEZ",
        "#SLOPE [TYPE=TRAPEZ] X10",
        "#SLOPE [TYPE=TRAPEZ NO_OPT=2]",
        "#SLOPE [TYPE=TRAPEZ FOO]",
    ],
)
def test_malformed_slope_is_refused_with_the_line(line: str) -> None:
    err = error(f"%p\nN10 G01 X1 F100\n{line}\nN30 M30\n")
    assert err.line == 3
    assert "#SLOPE" in err.message
    assert err.alarm in (914015, 914000)


@pytest.mark.req("M-01")
def test_the_older_set_slope_profil_is_refused_by_name() -> None:
    err = error("%p\n#SET SLOPE PROFIL[1]\nN30 M30\n")
    assert err.alarm == 910110


@pytest.mark.req("M-02")
def test_axes_rest_where_the_planned_path_rests() -> None:
    """A reversal is a standstill in every profile: the filtered path reaches the corner at rest
    (otherwise the axes would turn with velocity: an infinite acceleration), and the program end
    comes only when the axes are at rest."""
    m = machine(profile=1)
    xs = trace(m, LINE)
    i = xs.index(max(xs))
    assert xs[i] == pytest.approx(100.0)
    assert xs[i] - xs[i - 1] < 1e-9 + 1000.0 * T_A * T_A  # arrives with (almost) no velocity
    assert m.channel(1).state == ProgramState.FINISHED
    assert m.channel(1).planner.at_rest


@pytest.mark.req("M-02")
def test_the_filtered_path_keeps_the_programmed_geometry() -> None:
    """The profile acts on the path coordinate: every setpoint lies on the programmed contour."""
    m = machine(profile=2)
    start(m, "N10 G01 X50 Y0 F12000\nN20 G02 X100 Y0 I25 J0\nN30 G01 X100 Y-50\nN40 M30\n")
    for _ in cycles_until_done(m):
        x, y = m.axis("X").setpoint, m.axis("Y").setpoint
        on_line1 = abs(y) < 1e-9 and -1e-9 <= x <= 50 + 1e-9
        on_arc = abs(((x - 75) ** 2 + y**2) ** 0.5 - 25) < 1e-6 and y >= -1e-9
        on_line2 = abs(x - 100) < 1e-9 and -50 - 1e-9 <= y <= 1e-9
        assert on_line1 or on_arc or on_line2, (x, y)


# --- braking ----------------------------------------------------------------------------------------
def _feedhold_distance(m: Machine) -> tuple[float, float]:
    """Steady motion, then feedhold: (velocity at the request, distance until the axes rest)."""
    ch = m.channel(1)
    x = m.axis("X")
    start(m, "N10 G01 X2000 F6000\nN20 M30\n")
    m.step(400)
    v = (x.setpoint - x.prev_setpoint) / T_A
    x0 = x.setpoint
    ch.request_feedhold(True)
    for _ in range(10_000):
        m.step(1)
        if ch.planner.at_rest:
            break
    assert ch.planner.at_rest
    return v, x.setpoint - x0


@pytest.mark.req("M-03")
@pytest.mark.parametrize("profile", [0, 1, 2, 3])
def test_feedhold_brakes_within_the_profiles_distance(profile: int) -> None:
    m = machine(profile=profile, feedhold=500.0)
    v, d = _feedhold_distance(m)
    assert v == pytest.approx(100.0)
    expected = SlopeProfile(SlopeType(profile), 0.05).stop_distance(v, 500.0, T_A)
    assert d <= expected + 1e-6
    # and not shorter than one cycle's travel less: the profile is what brakes (stop_distance counts
    # the discrete ramp's half cycle at both ends)
    assert d >= expected - v * T_A - 1e-6
    assert m.channel(1).state == ProgramState.HELD


@pytest.mark.req("M-03")
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    profile=st.sampled_from([1, 2, 3]),
    ramp_us=st.integers(min_value=0, max_value=200_000),
    feed=st.integers(min_value=600, max_value=12_000),
    decel=st.floats(min_value=200.0, max_value=3000.0),
)
def test_property_a_jerk_limited_brake_stops_within_its_profiles_distance(
    profile: int, ramp_us: int, feed: int, decel: float
) -> None:
    m = machine(profile=profile, ramp_us=ramp_us, feedhold=decel, a_max=3000.0)
    ch = m.channel(1)
    x = m.axis("X")
    start(m, f"N10 G01 X2000 F{feed}\nN20 M30\n")
    m.step(int(feed / 60 / 3000 / T_A) + int(ramp_us / 1000) + 20)  # steady
    v = (x.setpoint - x.prev_setpoint) / T_A
    assert v == pytest.approx(feed / 60.0)
    x0 = x.setpoint
    ch.request_feedhold(True)
    while not ch.planner.at_rest:
        m.step(1)
    bound = ch.planner.profile.stop_distance(v, decel, T_A)
    assert x.setpoint - x0 <= bound + 1e-6
    # the profile's acceleration never exceeds the feedhold deceleration (plus the discrete ramp's 1/8)
    assert bound == pytest.approx(v * v / (2 * decel) + v * T_A / 2 + v * ch.planner.profile.lag(T_A))


# --- the filter ---------------------------------------------------------------------------------------
@pytest.mark.req("M-02")
@given(
    steps=st.lists(st.floats(min_value=0.0, max_value=5.0), min_size=1, max_size=200),
    taps=st.integers(min_value=1, max_value=60),
    sin2=st.booleans(),
)
def test_property_the_filtered_path_never_passes_the_planned_one(
    steps: list[float], taps: int, sin2: bool
) -> None:
    profile = SlopeProfile(SlopeType.SIN2 if sin2 else SlopeType.TRAPEZ, taps * T_A)
    f = PathFilter(profile.kernel(T_A))
    s = 0.0
    last = 0.0
    for ds in steps:
        s += ds
        out = f.push(s)
        assert last - 1e-9 <= out <= s + 1e-9
        last = out
    for _ in range(taps):
        out = f.push(s)
    assert out == pytest.approx(s)
    assert f.settled


# --- the monitors with a profile ---------------------------------------------------------------------
FCT = "FCT_LOOK_AHEAD_STANDARD | FCT_DYN_POS_LIMIT"


def _set_limit(m: Machine, mm: float) -> None:
    unit = m.hli.axes[m.axis("X").index].ipo_mc_control.dyn_pos_limit_high
    unit.command_w = round(mm * 10_000)
    unit.enable_w = True


@pytest.mark.req("M-04", "C43-06")
@pytest.mark.parametrize("profile", [0, 1, 2])
@pytest.mark.parametrize("feed", [3000, 6000, 18000])
def test_dynamic_limit_brakes_with_the_profile_and_stops_within_one_cycle(profile: int, feed: int) -> None:
    """FCT-C43 with #SLOPE active: the axes come to rest on the limit, within one cycle's travel
    (the documents' tolerance), and the state is ACTIVE_BRAKE only when they are at rest."""
    m = machine(profile=profile, fct=FCT, feedhold=800.0)
    _set_limit(m, 30.0)
    m.step(2)
    x = m.axis("X")
    start(m, f"N10 G01 X100 F{feed}\nN20 M30\n")
    v_max = 0.0
    unit = m.hli.axes[x.index].ipo_mc_control.dyn_pos_limit_high
    for _ in range(20_000):
        m.step(1)
        v_max = max(v_max, abs(x.setpoint_step) / T_A)
        assert x.setpoint <= 30.0 + v_max * T_A + 1e-9
        if unit.state_r == 4:  # ACTIVE_BRAKE
            break
    assert unit.state_r == 4
    assert m.channel(1).planner.at_rest
    assert abs(x.setpoint - 30.0) <= v_max * T_A + 1e-9


@pytest.mark.req("M-04")
def test_dynamic_limit_with_sin2_has_a_jerk_limited_brake() -> None:
    m = machine(profile=2, fct=FCT, feedhold=800.0)
    _set_limit(m, 30.0)
    m.step(2)
    xs = trace_until_rest(m, "N10 G01 X100 F6000\nN20 M30\n")
    _, acc, jerk = derivatives(xs)
    assert min(acc) >= -1.13 * 1000.0
    assert max(abs(j) for j in jerk) <= 1.13 * 3.1416 / 2 * 1000.0 / 0.05
    assert xs[-1] == pytest.approx(30.0, abs=0.1)


def trace_until_rest(m: Machine, program: str) -> list[float]:
    ch = m.channel(1)
    x = m.axis("X")
    start(m, program)
    xs = [x.setpoint]
    for _ in range(20_000):
        m.step(1)
        xs.append(x.setpoint)
        if ch.planner.at_rest and len(xs) > 10:
            break
    return xs


@pytest.mark.req("M-05")
@pytest.mark.parametrize("ramp_us", [0, 50_000, 150_000])
def test_independent_stop_runs_within_the_braking_distance_fct_c3_counts(ramp_us: int) -> None:
    """FCT-C3 subtracts the braking distance of the active profile: a stop that builds its
    deceleration up over the ramp time runs at most v²/(2a) + v t_r / 2, and that is what is counted."""
    m = machine(profile=1, ramp_us=ramp_us)
    x = m.axis("X")
    start(m, "N10 G01 X2000 F6000\nN20 M30\n")
    m.step(400)
    v = x.setpoint_step / T_A
    assert v == pytest.approx(100.0)
    assert x.slope_ramp == pytest.approx(ramp_us / 1e6)
    counted = x.stop_distance(v, 1000.0)
    x0 = x.setpoint
    x.start_independent_stop(1000.0, T_A)
    for _ in range(5000):
        x.begin_cycle()
        x.advance_independent_stop(T_A)
        if x.stop_velocity == 0.0:
            break
    travelled = x.setpoint - x0
    assert travelled <= counted + 1e-9
    assert travelled >= counted - v * T_A - 1000.0 * (ramp_us / 1e6) ** 2 / 24 - 1e-9


@pytest.mark.req("M-05", "C3-01")
@pytest.mark.parametrize("profile", [0, 1, 2])
def test_collision_pair_rests_no_closer_than_coll_offset_in_every_profile(profile: int) -> None:
    """FCT-C3 with #SLOPE: X1 runs at X2; the pair trips earlier by the profile's v t_r / 2, its stop
    builds the deceleration up over t_r, and it comes to rest no closer than coll_offset (20 mm)."""
    pair = 0x8001
    axes = [
        AxisConfig(number=1, name="X1", achs_mode=pair, a_max=2000.0),
        AxisConfig(
            number=2,
            name="X2",
            achs_mode=pair,
            coll_check_ax_nr=1,
            coll_offset=200_000,
            start_position=1_000_000,
            a_max=2000.0,
        ),
        AxisConfig(number=3, name="Z1"),
    ]
    ch = ChannelConfig(axes=["X1", "X2", "Z1"], main_axes=("X1", "X2", "Z1"), slope_profile=profile)
    m = Machine(MachineConfig(axes=axes, channels=[ch]))
    x1, x2 = m.axis("X1"), m.axis("X2")
    start(m, "N10 G01 X1=90 F12000\nN20 M30\n")
    tripped_at = None
    for _ in range(5000):
        m.step(1)
        if tripped_at is None and m.active_alarms:
            tripped_at = x2.setpoint - x1.setpoint
        if (tripped_at is not None and not x1.stopping) or (x1.stopping and x1.stop_velocity == 0.0):
            break
    assert [a.number for a in m.active_alarms] == [70092]
    assert x1.slope_ramp == (0.0 if profile == 0 else pytest.approx(0.05))
    assert x2.setpoint - x1.setpoint >= 20.0 - 1e-9
    assert tripped_at is not None
    # the trip came while the counted braking distance still fitted: with a ramp, earlier
    expected_brake = 200.0**2 / (2 * 2000.0) + (0.0 if profile == 0 else 200.0 * 0.05 / 2)
    assert tripped_at >= 20.0 + expected_brake - 200.0 * T_A - 1e-6
