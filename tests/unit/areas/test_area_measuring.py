"""G100 measuring moves and P-CHAN-00268 (C14-23); the kernel's measuring types 1..4 and offsets."""

from __future__ import annotations

import pytest

from hli_server.engine.machine import Machine
from schemas.wire import ProgramState

from .helpers import areas, errors, only_alarm
from .helpers import make_machine as _make_machine

SWE_X = {"X": {"swe_pos": 2_000_000, "swe_toleranz": 10_000}}  # X: limit 200 mm, actual +1 mm
MEASURING = {"messachse": True, "a_max": 2000.0}
"""P-AXIS-00118 on every axis (G100 needs it); a_max 2000 mm/s² (the braking sums below)."""


def make_machine(**kwargs: object) -> Machine:
    """The area tests' machine with measuring axes (``axis`` adds to :data:`MEASURING`)."""
    axis = {**MEASURING, **kwargs.pop("axis", {})}  # type: ignore[dict-item]
    return _make_machine(axis=axis, **kwargs)  # type: ignore[arg-type]


def start(m: Machine, program: str) -> None:
    ch = m.channel(1)
    ch.load_program(program, "measure")
    ch.request_start()
    m.step(1)


def run_with_probe_at(m: Machine, program: str, x_probe: float | None, *, via_hli: bool = False) -> None:
    """Run; fire the probe once X passes ``x_probe`` (None: never)."""
    start(m, program)
    ch = m.channel(1)
    fired = False
    for _ in range(100_000):
        if ch.state not in (ProgramState.RUNNING, ProgramState.HELD):
            return
        if x_probe is not None and not fired and ch.axis("X").setpoint >= x_probe:
            fired = True
            if via_hli:
                m.hli.channels[0].mc_command.probe_w = True
            else:
                areas(m).request_probe(True)
        m.step(1)
    raise AssertionError("program did not end")


@pytest.mark.req("C14-23")
@pytest.mark.parametrize("via_hli", [False, True], ids=["request_probe", "mc_command.probe_w"])
def test_probe_ends_the_move_and_the_program_continues_from_there(via_hli: bool) -> None:
    m = make_machine()
    run_with_probe_at(m, "N10 G01 Y5 F6000\nN20 G100 X150\nN30 G01 Y20\nM30\n", 40.0, via_hli=via_hli)
    ch = m.channel(1)
    assert errors(m) == []
    assert ch.state == ProgramState.FINISHED
    result = areas(m).measurement
    assert result is not None
    assert result["block"] == "N20"
    assert 40.0 <= result["setpoint"]["X"] < 40.0 + 100.0 * m.t_a + 1e-9
    x = ch.axis("X").setpoint
    v = 100.0  # F6000
    assert result["setpoint"]["X"] < x <= result["setpoint"]["X"] + v * m.t_a + v * v / (2 * 2000.0) + 1e-6
    assert ch.setpoints()[1] == pytest.approx(20.0)  # N30 ran, from where the probe stopped X


@pytest.mark.req("C14-23")
def test_no_probe_signal_before_the_target_type_1() -> None:
    """Type 1 (P-CHAN-00057 = 1, the default here): no error without a probe signal unless P-CHAN-00176
    ``meas_error_no_signal`` is set (https://infosys.beckhoff.com/content/1033/tccncchannelparameter/
    15274803083.html); the program goes on from the target."""
    m = make_machine()
    run_with_probe_at(m, "N10 G100 X50 F6000\nN20 G01 Y20\nM30\n", None)
    assert list(m.alarm_history) == []
    assert m.channel(1).state == ProgramState.FINISHED
    assert m.channel(1).setpoints()[:2] == [pytest.approx(50.0), pytest.approx(20.0)]
    m = make_machine(meas_error_no_signal=True)
    run_with_probe_at(m, "N10 G100 X50 F6000\nN20 G01 Y20\nM30\n", None)
    alarm = only_alarm(m, 912010)
    assert alarm.block == "N10"
    assert "measuring type 1 with P-CHAN-00176 = 1" in alarm.message
    assert m.channel(1).axis("X").setpoint == pytest.approx(50.0)
    assert m.channel(1).setpoints()[1] == 0.0  # N20 did not run


@pytest.mark.req("C14-23", "E-06")
def test_p_chan_00268_0_target_beyond_the_software_limit_is_refused() -> None:
    m = make_machine(per_axis=SWE_X)
    run_with_probe_at(m, "N10 G100 X300 F6000\nM30\n", 100.0)
    alarm = only_alarm(m, 120002)
    assert alarm.block == "N10"
    assert m.channel(1).axis("X").setpoint == 0.0  # not started


@pytest.mark.req("C14-23")
def test_p_chan_00268_1_stops_at_the_software_limit_with_50706() -> None:
    m = make_machine(per_axis=SWE_X, meas_soft_limit_move_path=True)
    run_with_probe_at(m, "N10 G100 X300 F6000\nM30\n", None)
    alarm = only_alarm(m, 50706)
    assert alarm.block == "N10"
    assert "software limit of X (200 mm)" in alarm.message
    assert m.channel(1).axis("X").setpoint == pytest.approx(200.0)
    assert 120002 not in [a.number for a in m.alarm_history]


@pytest.mark.req("C14-23")
def test_p_chan_00268_1_with_a_probe_signal_is_a_normal_measurement() -> None:
    m = make_machine(per_axis=SWE_X, meas_soft_limit_move_path=True)
    run_with_probe_at(m, "N10 G100 X300 F6000\nN20 G01 Y1\nM30\n", 120.0)
    assert errors(m) == []
    assert m.channel(1).state == ProgramState.FINISHED
    assert 120.0 <= m.channel(1).axis("X").setpoint < 125.0


@pytest.mark.req("C14-23", "C14-14")
def test_p_chan_00268_1_stops_before_a_protection_area() -> None:
    m = make_machine(meas_soft_limit_move_path=True)
    program = (
        "#CONTROL AREA BEGIN [ID=1 PROT POLY MIN_EXCUR=-10 MAX_EXCUR=10]\n"
        "G01 X80 Y-10 F1000\nX90\nY10\nX80\nY-10\n#CONTROL AREA END\n#CONTROL AREA ON ALL\n"
        "N10 G100 X300 F6000\nM30\n"
    )
    run_with_probe_at(m, program, None)
    alarm = only_alarm(m, 50706)
    assert "protection area 1" in alarm.message
    x = m.channel(1).axis("X").setpoint
    assert x == pytest.approx(80.0 - 1e-3, abs=1e-9)
    assert areas(m).allowed(tuple(m.channel(1).setpoints()))


@pytest.mark.req("C14-23", "C14-14")
def test_p_chan_00268_1_stops_at_the_work_area_boundary() -> None:
    m = make_machine(meas_soft_limit_move_path=True)
    program = (
        "#CONTROL AREA BEGIN [ID=1 WORK CIRC MIN_EXCUR=-10 MAX_EXCUR=10]\n"
        "G01 X-60 Y0 F1000\nG02 I60 J0\n#CONTROL AREA END\n#CONTROL AREA ON ALL\n"
        "N10 G100 X30 Y300 F6000\nM30\n"
    )
    run_with_probe_at(m, program, None)
    alarm = only_alarm(m, 50706)
    assert "work area 1" in alarm.message
    x, y = m.channel(1).setpoints()[:2]
    assert (x * x + y * y) ** 0.5 == pytest.approx(60.0, abs=1e-9)


@pytest.mark.req("C14-23", "C14-15")
def test_p_chan_00268_0_a_measuring_path_out_of_the_work_area_is_refused() -> None:
    m = make_machine()
    program = (
        "#CONTROL AREA BEGIN [ID=1 WORK CIRC MIN_EXCUR=-10 MAX_EXCUR=10]\n"
        "G01 X-60 Y0 F1000\nG02 I60 J0\n#CONTROL AREA END\n#CONTROL AREA ON ALL\n"
        "N10 G100 X300 F6000\nM30\n"
    )
    run_with_probe_at(m, program, 20.0)
    alarm = only_alarm(m, 120486)
    assert alarm.block == "N10"
    assert alarm.params["intersection"][:2] == pytest.approx([60.0, 0.0])


@pytest.mark.req("C14-23")
def test_g100_needs_a_feed_and_a_target() -> None:
    m = make_machine()
    run_with_probe_at(m, "N10 G100 X50\nM30\n", None)
    assert only_alarm(m, 911000).block == "N10"
    m = make_machine()
    run_with_probe_at(m, "N10 G100 X0 F100\nM30\n", None)
    assert "target is the current position" in only_alarm(m, 912011).message


# --- the kernel's measuring types 1..4 (P-CHAN-00057) and the measuring offsets ------------------------
# https://infosys.beckhoff.com/content/1033/tf5200_measurement/342039563.html (the types),
# https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/206177803.html (type 2),
# .../206185227.html (type 3), .../206191115.html (type 4)


@pytest.mark.req("C14-23", "B-04")
def test_every_programmed_axis_must_be_a_measuring_axis() -> None:
    """P-AXIS-00118: "must be TRUE for all axes that take part in a measuring run"; else ID 50059
    (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/257565323.html)."""
    m = make_machine(per_axis={"Y": {"messachse": False}})
    run_with_probe_at(m, "N10 G100 X50 Y10 F6000\nM30\n", None)
    alarm = only_alarm(m, 50059)
    assert (alarm.block, alarm.axis, alarm.params["axis_number"]) == ("N10", "Y", 2)
    assert m.channel(1).setpoints()[:2] == [0.0, 0.0]  # refused before it moved


@pytest.mark.req("C14-23", "B-04")
def test_type_2_one_axis_its_feed_from_p_axis_00215_and_an_error_without_probe() -> None:
    """Type 2: exactly one axis (more is ID 50061, https://infosys.beckhoff.com/content/1033/
    tf5200_diagnosis/257574027.html), the feed is P-AXIS-00215 ``vb_messen`` (µm/s, not the F word),
    "an error message is output if no probe signal is adopted in the measuring block"."""
    m = make_machine(messtyp=2)
    run_with_probe_at(m, "N10 G100 X50 Y10 F6000\nM30\n", None)
    alarm = only_alarm(m, 50061)
    assert alarm.params == {"count": 2, "limit": 1, "type": 2}
    # no F word needed; vb_messen 50000 µm/s = 50 mm/s
    m = make_machine(messtyp=2, per_axis={"X": {"vb_messen": 50_000}})
    start(m, "N10 G100 X40\nM30\n")
    ch = m.channel(1)
    top = 0.0
    while ch.state in (ProgramState.RUNNING, ProgramState.HELD):
        top = max(top, ch.axis("X").setpoint_step / m.t_a)
        m.step(1)
    assert top == pytest.approx(50.0, rel=1e-6)
    alarm = only_alarm(m, 912010)
    assert "measuring type 2" in alarm.message
    assert ch.axis("X").setpoint == pytest.approx(40.0)


@pytest.mark.req("C14-23", "B-04")
def test_type_4_takes_the_main_axes_only() -> None:
    m = make_machine(messtyp=4)
    run_with_probe_at(m, "N10 G100 X50 X2=10 F6000\nM30\n", None)
    alarm = only_alarm(m, 912011)
    assert "measuring type 4 measures with the main axes X/Y/Z only, X2 is not one" in alarm.message
    m = make_machine(messtyp=4)
    run_with_probe_at(m, "N10 G100 X50 Y20 Z5 F6000\nN20 G01 X0\nM30\n", 10.0)
    assert errors(m) == []
    assert m.channel(1).state == ProgramState.FINISHED


@pytest.mark.req("C14-23", "B-04")
@pytest.mark.parametrize(("mtype", "alarm"), [(5, 20138), (6, 20138), (7, 910110)])
def test_types_that_are_no_g100_type(mtype: int, alarm: int) -> None:
    """Types 5 and 6 are G310's: G100 with them is ID 20138 "G100 is not allowed with current measuring
    type" (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/250906763.html); type 7 (fixed
    stop) is not simulated."""
    m = make_machine(messtyp=mtype)
    run_with_probe_at(m, "N10 G100 X50 F6000\nM30\n", None)
    assert only_alarm(m, alarm).params == {"type": mtype}


@pytest.mark.req("C14-23", "B-04")
def test_type_3_and_4_end_without_probe_without_an_error() -> None:
    for mtype in (3, 4):
        m = make_machine(messtyp=mtype)
        run_with_probe_at(m, "N10 G100 X50 F6000\nN20 G01 Y5\nM30\n", None)
        assert list(m.alarm_history) == [], mtype
        assert m.channel(1).setpoints()[:2] == [pytest.approx(50.0), pytest.approx(5.0)]


@pytest.mark.req("C14-23", "B-04")
def test_measuring_offset_lets_the_move_run_past_its_target() -> None:
    """P-AXIS-00467 (every type but 3): the move may run past the target by the offset when the probe
    has not fired; the probe can still end it there (the kernel's page of P-AXIS-00114)."""
    m = make_machine(axis={"meas_offset": 50_000})  # 5 mm
    run_with_probe_at(m, "N10 G100 X50 F6000\nN20 G01 Y5\nM30\n", None)
    assert m.channel(1).axis("X").setpoint == pytest.approx(55.0)
    assert list(m.alarm_history) == []
    m = make_machine(axis={"meas_offset": 50_000})
    run_with_probe_at(m, "N10 G100 X50 F6000\nN20 G01 Y5\nM30\n", 52.0)
    result = areas(m).measurement
    assert result is not None
    assert 52.0 <= result["setpoint"]["X"] < 52.2
    # type 3: no offset
    m = make_machine(messtyp=3, axis={"meas_offset": 50_000})
    run_with_probe_at(m, "N10 G100 X50 F6000\nM30\n", None)
    assert m.channel(1).axis("X").setpoint == pytest.approx(50.0)


@pytest.mark.req("C14-23", "B-04")
def test_type_2_uses_p_axis_00114_where_p_axis_00467_is_0() -> None:
    m = make_machine(messtyp=2, per_axis={"X": {"mess_offset": 30_000}})
    run_with_probe_at(m, "N10 G100 X50\nM30\n", None)
    assert m.channel(1).axis("X").setpoint == pytest.approx(53.0)
    assert "run-on of 3 mm (measuring offset)" in only_alarm(m, 912010).message


@pytest.mark.req("C14-23", "B-04")
def test_the_offset_runs_along_the_path_as_far_as_every_axis_allows() -> None:
    # X 10 mm per offset, Y 2 mm: a 45° move may run on 2 * sqrt(2) mm (Y's 2 mm)
    m = make_machine(per_axis={"X": {"meas_offset": 100_000}, "Y": {"meas_offset": 20_000}})
    run_with_probe_at(m, "N10 G100 X30 Y30 F6000\nM30\n", None)
    assert m.channel(1).setpoints()[:2] == [pytest.approx(32.0), pytest.approx(32.0)]
    # an axis with offset 0 that moves: no run-on at all
    m = make_machine(per_axis={"X": {"meas_offset": 100_000}})
    run_with_probe_at(m, "N10 G100 X30 Y30 F6000\nM30\n", None)
    assert m.channel(1).setpoints()[:2] == [pytest.approx(30.0), pytest.approx(30.0)]


@pytest.mark.req("C14-23", "B-04")
def test_offsets_apply_only_when_the_move_is_not_limited() -> None:
    """FCT-C14 6.2, P-CHAN-00268: "In den Achsparametern eingestellte Messoffsetwerte P-AXIS-00114 oder
    P-AXIS-00467 sind nur wirksam, wenn die CNC keine Begrenzung der Messverfahrbewegung ausführt." """
    limited = make_machine(
        meas_soft_limit_move_path=True, per_axis={"X": {**SWE_X["X"], "meas_offset": 50_000}}
    )
    run_with_probe_at(limited, "N10 G100 X300 F6000\nM30\n", None)
    assert limited.channel(1).axis("X").setpoint == pytest.approx(200.0)  # at the limit, no offset
    assert "software limit of X (200 mm)" in only_alarm(limited, 50706).message
    # not limited: the offset applies, and its run-on stops at the software limit
    free = make_machine(meas_soft_limit_move_path=True, per_axis={"X": {**SWE_X["X"], "meas_offset": 50_000}})
    run_with_probe_at(free, "N10 G100 X198 F6000\nM30\n", None)
    assert free.channel(1).axis("X").setpoint == pytest.approx(200.0)
    assert list(free.alarm_history) == []


@pytest.mark.req("C14-23", "B-04")
def test_a_probe_signal_already_on_at_the_start_is_50052() -> None:
    """ID 50052 "Probe already actuated": "before starting measurement motion ... check whether the
    measuring probe is currently active" (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/
    257543563.html)."""
    m = make_machine()
    areas(m).request_probe(True)
    run_with_probe_at(m, "N10 G100 X50 F6000\nM30\n", None)
    alarm = only_alarm(m, 50052)
    assert alarm.block == "N10"
    assert m.channel(1).state == ProgramState.ABORTED
    assert m.channel(1).axis("X").setpoint < 1.0
