"""Units and words (issue 24 item 5, M-06..M-09): G70/G71 with MIN_EXCUR/MAX_EXCUR, G94/G95, circles by
radius R, G08/G09/G900/G901; each with the programming manual's example where it has one."""

from __future__ import annotations

import math

import pytest

from hli_server.engine import Machine
from tests.unit.areas.helpers import make_machine, only_alarm
from tests.unit.areas.helpers import run as run_areas
from tests.unit.engine_helpers import cycles_until_done, mill, positions, start
from tests.unit.nc_helpers import error


def run(m: Machine, program: str) -> list[tuple[float, float, float]]:
    start(m, program)
    pts = [tuple(a.setpoint for a in m.axes[:3])]
    for _ in cycles_until_done(m):
        pts.append(tuple(a.setpoint for a in m.axes[:3]))
    return pts  # type: ignore[return-value]


def alarms(m: Machine) -> list[int]:
    return [a.number for a in m.alarm_history]


# --- G70 / G71 -------------------------------------------------------------------------------------
@pytest.mark.req("M-06")
def test_g70_g71_example_of_the_manual() -> None:
    """The manual's example (tf5100 9231467147, as the kernel's G70/G71 page 206272267 says: G70/G71
    act on all path and coordinate values, in the block that programs them already): N10 ends at
    X 50.8 mm, N20 at Y 25.4 mm, N30 (G71 again) at X 80 mm, Y 25.4 mm, a horizontal line."""
    m = mill()
    pts = run(m, "N10 G01 X2 G70 F60\nN20 G01 Y1\nN30 G01 X80 Y25.4 G71\nM02\n")
    assert not alarms(m)
    assert positions(m) == {"X": 80.0, "Y": 25.4, "Z": 0.0}
    # N10 along X to 50.8 mm, N20 along Y at X 50.8 mm (the corner is passed with the junction's
    # velocity, so the points lie on the lines, not necessarily on the corner)
    assert max(p[0] for p in pts if p[1] < 1e-9) == pytest.approx(50.8, abs=0.05)
    assert all(p[0] == pytest.approx(50.8, abs=1e-9) for p in pts if 1e-3 < p[1] < 25.4 - 1e-3)
    # N30 is horizontal: every point after (50.8, 25.4) keeps Y
    i = next(k for k, p in enumerate(pts) if abs(p[1] - 25.4) < 1e-9)
    assert all(abs(p[1] - 25.4) < 1e-9 for p in pts[i:])


@pytest.mark.req("M-06")
def test_g70_scales_feed_centres_radius_and_g92() -> None:
    m = mill()
    start(m, "N10 G70 G01 X1 F60\nN20 G92 X0\nN30 G02 X1 Y1 I0 J1\nN40 G03 X2 Y0 R1\nN50 M30\n")
    v_max = 0.0
    x = m.axis("X")
    for _ in cycles_until_done(m):
        v_max = max(v_max, abs(x.setpoint_step) / m.t_a)
    assert not alarms(m)
    # G92 X0 at X 25.4 mm: the program's X2 is 25.4 + 50.8 mm
    assert positions(m)["X"] == pytest.approx(25.4 + 50.8)
    assert positions(m)["Y"] == pytest.approx(0.0, abs=1e-9)
    assert v_max <= 60 * 25.4 / 60 + 1e-6  # F60 inch/min = 25.4 mm/s


@pytest.mark.req("M-06", "C14-06")
def test_min_excur_max_excur_in_inch_under_g70() -> None:
    """FCT-C14: MIN_EXCUR / MAX_EXCUR "in [mm, inch]": the cylinder of the document in inch."""
    prot = (
        "N5 G70\n"
        "N10 #CONTROL AREA BEGIN [ID4 PROT CIRC MIN_EXCUR=-1 MAX_EXCUR=1]\n"
        "N20 G01 X0 Y0 F100\nN30 G02 G162 I0 J1\nN40 #CONTROL AREA END\nN45 G71\n"
    )
    # above 25.4 mm the cylinder (radius 25.4 mm around (0, 25.4)) can be passed
    m = make_machine()
    run_areas(m, prot + "N50 G01 X-50 Y25.4 Z30 F30000\n#CONTROL AREA ON [ID4]\nN60 X50\nM30\n")
    assert not m.alarm_history, [(a.number, a.message) for a in m.alarm_history]
    m = make_machine()
    run_areas(m, prot + "N50 G01 X-50 Y25.4 Z20 F30000\n#CONTROL AREA ON [ID4]\nN60 X50\nM30\n")
    alarm = only_alarm(m, 912001)
    assert alarm.params["intersection"][:3] == pytest.approx([-25.4, 25.4, 20.0], abs=1e-6)


@pytest.mark.req("M-06")
def test_g70_and_g71_in_one_block_are_refused() -> None:
    assert error("N10 G70 G71 X1\nM30\n").alarm == 910106


# --- G94 / G95 -------------------------------------------------------------------------------------
@pytest.mark.req("M-07")
def test_g95_example_of_the_manual() -> None:
    """The manual's example (208081931): F1000 G94; G95 F1.5 at S1200 is 1800 mm/min; G94 X50 goes
    back to the F1000 of N10 (the G95 F word is not adopted)."""
    m = mill()
    z, x = m.axis("Z"), m.axis("X")
    start(m, "N10 F1000 G01 X0 Z100 M3 S1200\nN20 G95 F1.5\nN30 Z50\nN40 G94 X50\nN70 M30\n")
    vz = vx = 0.0
    for _ in cycles_until_done(m):
        if z.setpoint < 100 - 1e-9:
            vz = max(vz, abs(z.setpoint_step) / m.t_a * 60)
        if x.setpoint > 1e-9:
            vx = max(vx, abs(x.setpoint_step) / m.t_a * 60)
    assert not alarms(m)
    assert vz == pytest.approx(1800.0)
    assert vx == pytest.approx(1000.0)
    assert positions(m) == {"X": 50.0, "Y": 0.0, "Z": 50.0}


@pytest.mark.req("M-07")
@pytest.mark.parametrize(
    "program",
    [
        "N10 G95 F1.5 G01 X10\nM30\n",
        "N10 M3 S0 G95 F1.5 G01 X10\nM30\n",
        "N10 M3 S100\nM5\nG95 F1 G01 X10\nM30\n",
    ],
)
def test_g95_with_the_spindle_stopped_is_the_kernels_60131(program: str) -> None:
    m = mill()
    run(m, program)
    assert 60131 in alarms(m)
    assert positions(m)["X"] == 0.0


@pytest.mark.req("M-07")
def test_g95_without_its_own_f_word_is_refused() -> None:
    m = mill()
    run(m, "N10 G01 X1 F1000 M3 S1000\nN20 G95 X2\nM30\n")
    assert 20008 in alarms(m)


# --- circles by radius ------------------------------------------------------------------------------
@pytest.mark.req("M-08")
@pytest.mark.parametrize(
    ("word", "centre", "sweep_over_180"),
    [("G02", (10.0, 0.0), False), ("G03", (0.0, 10.0), False)],
)
def test_circle_by_radius_short_arc(word: str, centre: tuple[float, float], sweep_over_180: bool) -> None:
    """R > 0: the arc of at most 180°; the centre lies right of the chord for G02, left for G03."""
    m = mill()
    pts = run(m, f"N10 G01 X0 Y0 F3000\nN20 {word} X10 Y10 R10\nN30 M30\n")
    assert not alarms(m)
    assert positions(m)["X"] == pytest.approx(10.0)
    for p in pts:
        assert math.hypot(p[0] - centre[0], p[1] - centre[1]) == pytest.approx(10.0, abs=1e-6)
    assert m.channel(1).decoder.last_centre == pytest.approx({"I": centre[0], "J": centre[1]}, abs=1e-9)


@pytest.mark.req("M-08")
def test_circle_by_negative_radius_is_the_long_arc() -> None:
    m = mill()
    pts = run(m, "N10 G01 X0 Y0 F3000\nN20 G02 X10 Y10 R-10\nN30 M30\n")
    assert not alarms(m)
    # the long arc around (0, 10) passes through (-10, 10) and (0, 0)..(0, 20)
    assert min(p[0] for p in pts) == pytest.approx(-10.0, abs=1e-3)
    assert max(p[1] for p in pts) == pytest.approx(20.0, abs=1e-3)
    for p in pts:
        assert math.hypot(p[0], p[1] - 10.0) == pytest.approx(10.0, abs=1e-6)


@pytest.mark.req("M-08")
@pytest.mark.parametrize(
    ("block", "alarm"),
    [
        ("G02 X30 Y0 R10", 911001),  # farther than the diameter
        ("G02 X0 Y0 R10", 911001),  # a full circle needs its centre
        ("G02 X10 Y10 R10 I5", 911002),  # both
        ("G02 X10 Y10 R0", 911001),
    ],
)
def test_impossible_radius_circles_are_refused(block: str, alarm: int) -> None:
    m = mill()
    run(m, f"N10 G01 X0 Y0 F3000\nN20 {block}\nN30 M30\n")
    assert alarm in alarms(m)
    assert positions(m)["X"] == 0.0


# --- G08 / G09 / G900 / G901, G60 ------------------------------------------------------------------
@pytest.mark.req("M-09")
def test_g08_g09_g900_g901_are_accepted_with_the_documented_approximation() -> None:
    """The simulator decelerates to the next block's feed before the block end in every case (the
    G09/G900 behaviour: never later than the kernel): docs/nc-language.md."""
    program = "N10 G08 G01 X10 F6000\nN20 G901 X20 F1000\nN30 G09 X30\nN40 G900 X40 F3000\nN50 M30\n"
    m = mill()
    run(m, program)
    assert not alarms(m)
    assert positions(m)["X"] == pytest.approx(40.0)
    m2 = mill()
    run(m2, program.replace("G08 ", "").replace("G901 ", "").replace("G09 ", "").replace("G900 ", ""))
    assert m2.cycle == m.cycle  # the same motion, cycle for cycle
    assert error("N10 G900 G901 X1\nM30\n").alarm == 910106


# --- G04 dwell ---------------------------------------------------------------------------------------
@pytest.mark.req("M-09")
def test_g04_example_of_the_manual_waits_its_seconds() -> None:
    """PM 206132747's example without its spindle lines: 4.5 + 3.0 + 2.0 + 3.5 s."""
    m = mill()
    start(m, "N10 G04 X4.5\nN20 G04 3.0\nN30 P1=2\nN40 G04 P1\nN50 V.L.TIME=3.5\nN60 G04 V.L.TIME\nN90 M30\n")
    first = m.cycle
    for _ in cycles_until_done(m):
        pass
    assert not alarms(m)
    assert (m.cycle - first) * m.t_a == pytest.approx(13.0, abs=0.01)


@pytest.mark.req("M-09")
def test_g04_rests_between_moves_and_is_seconds_under_g70() -> None:
    def duration(program: str) -> int:
        m = mill()
        run(m, program)
        assert not alarms(m)
        return m.cycle

    plain = duration("N10 G01 X10 F6000\nN30 G01 X20\nM30\n")
    dwell = duration("N10 G01 X10 F6000\nN20 G04 X0.5\nN30 G01 X20\nM30\n")
    inch = duration("N5 G70\nN10 G01 X0.3937 F236.22\nN20 G04 X0.5\nN30 G01 X0.7874\nM30\n")
    assert dwell - plain >= 500  # the rest, plus the stop at N10's end
    assert inch == pytest.approx(dwell, abs=3)


@pytest.mark.req("M-09")
@pytest.mark.parametrize(
    ("block", "alarm"),
    [("G04 Y2", 20014), ("G04 S10", 20007), ("G04", 20014), ("G04 X-1", 911000), ("#TIME -1", 20751)],
)
def test_g04_forms_that_are_wrong_are_refused_with_the_kernels_id(block: str, alarm: int) -> None:
    """DG 250536843 (20014: ``G04 Y2``, the dwell time not by the first main axis); a dwell in revolutions
    with the spindle stopped (20007, spindle speed 0); #TIME out of range (DG 252425611, 20751)."""
    m = mill()
    run(m, f"N10 G01 X1 F6000\nN20 {block}\nN30 X2\nM30\n")
    assert alarms(m) == [alarm]
    assert positions(m)["X"] == pytest.approx(1.0)


@pytest.mark.req("M-09")
def test_g04_with_another_axis_warns_20685_and_dwells_by_the_first() -> None:
    """DG 252216715: class 1, "continue NC program processing" - the time is X's, Y is ignored."""
    m = mill()
    run(m, "N10 G01 X1 F6000\nN20 G04 X1 Y3\nN30 X2\nM30\n")
    assert alarms(m) == [20685]
    assert positions(m) == {"X": pytest.approx(2.0), "Y": 0.0, "Z": 0.0}


@pytest.mark.req("M-09")
@pytest.mark.parametrize(
    ("dwell", "seconds"),
    [("N20 #TIME 0.5", 0.5), ("N15 P1 = 0.5\nN20 #TIME P1", 0.5), ("N15 M3 S600\nN20 G04 S5", 0.5)],
)
def test_time_and_g04_in_revolutions_rest_as_long_as_the_manual_says(dwell: str, seconds: float) -> None:
    """PM 206132747: ``#TIME <s>`` and ``G04 S<revolutions>`` (10 revolutions at S200 are 3 s)."""

    def duration(program: str) -> int:
        m = mill()
        run(m, program)
        assert not alarms(m)
        return m.cycle

    g04 = duration(f"N10 G01 X10 F6000\nN20 G04 X{seconds}\nN30 G01 X20\nM30\n")
    rest = duration(f"N10 G01 X10 F6000\n{dwell}\nN30 G01 X20\nM30\n")
    assert rest == pytest.approx(g04, abs=1)


# --- the batch geometry check ------------------------------------------------------------------------
@pytest.mark.req("M-06", "M-07")
def test_batch_geometry_check_agrees_under_g70_and_g95() -> None:
    """``check --geometry-only`` decodes plain lines in batches; under G70 and G95 it leaves them to the
    exact decoder, so that inch values are scaled and a G95 move with the spindle stopped is refused."""
    from schemas.config import MachineConfig
    from tests.unit.test_batch_check import assert_same
    from tests.unit.test_batch_check import run as run_check

    config: MachineConfig = MachineConfig.model_validate(
        {
            "axes": [{"number": i + 1, "name": n} for i, n in enumerate("XYZ")],
            "channels": [{"axes": ["X", "Y", "Z"]}],
        }
    )
    lines = [f"G01 X{(k % 5) * 0.1:.1f} Y{(k % 3) * 0.2:.1f}" for k in range(200)]
    inch = "G70 G01 X0 Y0 Z0 F60\n" + "\n".join(lines) + "\nG01 X1\nM30\n"
    result = assert_same(config, inch)
    assert result.final_position["X"] == pytest.approx(25.4)
    stopped = "G01 X0 Y0 F600\nG95 F0.5\n" + "\n".join(lines) + "\nM30\n"
    result = assert_same(config, stopped)
    assert [a.number for a in result.alarms][:1] == [60131]
    assert run_check(config, stopped, exact=True).alarms[0].number == 60131
