"""G100 measuring moves and P-CHAN-00268 (C14-23)."""

from __future__ import annotations

import pytest

from hli_server.engine.machine import Machine
from schemas.wire import ProgramState

from .helpers import areas, errors, make_machine, only_alarm

SWE_X = {"X": {"swe_pos": 2_000_000, "swe_toleranz": 10_000}}  # X: limit 200 mm, actual +1 mm


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
def test_no_probe_signal_before_the_target() -> None:
    m = make_machine()
    run_with_probe_at(m, "N10 G100 X50 F6000\nN20 G01 Y20\nM30\n", None)
    alarm = only_alarm(m, 912010)
    assert alarm.block == "N10"
    assert m.channel(1).axis("X").setpoint == pytest.approx(50.0)
    assert m.channel(1).setpoints()[1] == 0.0  # N20 did not run


@pytest.mark.req("C14-23", "E-06")
def test_p_chan_00268_0_target_beyond_the_software_limit_is_refused() -> None:
    m = make_machine(per_axis=SWE_X)
    run_with_probe_at(m, "N10 G100 X300 F6000\nM30\n", 100.0)
    alarm = only_alarm(m, 911011)
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
    assert 911011 not in [a.number for a in m.alarm_history]


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
