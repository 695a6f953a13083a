"""NC programs with the language's constructs on a running machine and through ``check`` (N-01..N-08,
issue 20's "Bad input"): V.E. variables the PLC changes, messages as events, #FLUSH on the path, the
interpreter's budget per cycle, the caps of ``check``."""

from __future__ import annotations

import itertools
import json

import pytest
from click.testing import CliRunner

from hli_server.cli import main
from hli_server.commands.check import EXIT_CAPPED, check_program
from hli_server.engine import Machine
from hli_server.engine.nc import STATEMENTS_PER_CYCLE
from hli_server.engine.programs import MemoryLibrary
from schemas.config import ExternalVariableConfig
from schemas.events import NcFileWrite, NcMessage
from schemas.wire import ProgramState
from tests.unit.engine_helpers import RUNNING, cycles_until_done, mill_config, record_events, start

SUB = "N10 G91 G01 X[P10] F6000\nN20 $FOR P1 = 1, P11\nN30   Y[P12]\nN40 $ENDFOR\nN50 G90\nN60 M17\n"
LOOPS = """\
%MAIN
N10 G90 G01 X0 Y0 F6000
#VAR
  V.P.STEP : REAL64 = 2.5
#ENDVAR
N20 P10 = 10 P11 = 3 P12 = V.P.STEP
N30 $WHILE V.E.RUN == 1
N40   L sub.nc
N50   V.E.COUNT = V.E.COUNT + 1
N60   $IF V.E.COUNT >= 3
N70     V.E.RUN = 0
N80   $ENDIF
N90 $ENDWHILE
N100 #MSG ["passes: %d", V.E.COUNT]
N110 M30
"""


def machine_with(*variables: ExternalVariableConfig, files: dict[str, str] | None = None) -> Machine:
    config = mill_config().model_copy(update={"external_variables": list(variables)})
    return Machine(config, programs=MemoryLibrary(files or {}))


def ve(name: str, synchronous: bool = False, type_: str = "REAL64") -> ExternalVariableConfig:
    return ExternalVariableConfig(name=name, type=type_, synchronous=synchronous)  # type: ignore[arg-type]


@pytest.mark.req("N-02", "N-04", "N-05", "N-06", "N-07")
def test_loops_subroutines_and_ve_variables_run_on_the_machine():
    machine = machine_with(ve("RUN", type_="BOOLEAN"), ve("COUNT", type_="SGN32"), files={"sub.nc": SUB})
    machine.external.write("RUN", None, True)
    events = record_events(machine)
    start(machine, LOOPS)
    for _ in cycles_until_done(machine, limit=100_000):
        pass
    ch = machine.channel(1)
    assert ch.state == ProgramState.FINISHED, machine.alarm_history
    assert machine.external.read("COUNT", 1) == 3
    assert ch.axis("X").setpoint == pytest.approx(30.0)
    assert ch.axis("Y").setpoint == pytest.approx(22.5)
    messages = [e for e in events if isinstance(e, NcMessage)]
    assert [m.text for m in messages] == ["passes: 3"]
    assert (messages[0].line, messages[0].block) == (14, "N100")


@pytest.mark.req("N-05")
def test_the_plc_changes_a_ve_variable_that_a_running_program_waits_for():
    """The program loops (with a #FLUSH WAIT so that it reads the variable afresh) until the PLC
    writes V.E.GO; then it moves on."""
    program = (
        "N10 G01 X10 F6000\nN20 $WHILE V.E.GO == 0\nN30   #FLUSH WAIT\nN40 $ENDWHILE\nN50 X20\nN60 M30\n"
    )
    machine = machine_with(ve("GO", type_="BOOLEAN"))
    start(machine, program)
    machine.step(3000)
    ch = machine.channel(1)
    assert ch.state in RUNNING
    assert ch.axis("X").setpoint == pytest.approx(10.0)
    machine.external.write("GO", None, True)
    for _ in cycles_until_done(machine):
        pass
    assert ch.state == ProgramState.FINISHED
    assert ch.axis("X").setpoint == pytest.approx(20.0)


@pytest.mark.req("N-05", "N-07")
def test_a_synchronous_ve_read_waits_until_the_path_got_there():
    program = "N10 G01 X50 F6000\nN20 P1 = V.E.SENSOR\nN30 G01 Y[P1] F6000\nN40 M30\n"
    machine = machine_with(ve("SENSOR", synchronous=True))
    start(machine, program)
    ch = machine.channel(1)
    # while X moves, the PLC sets the value; the read happens only when X stands at 50
    machine.step(100)
    assert ch.decoder.waiting
    machine.external.write("SENSOR", None, 12.0)
    for _ in cycles_until_done(machine):
        pass
    assert ch.axis("Y").setpoint == pytest.approx(12.0)


@pytest.mark.req("N-05", "N-07")
def test_a_synchronous_ve_write_happens_when_the_path_passes_without_stopping_it():
    program = "N10 G01 X50 F6000\nN20 V.E.MARK = 1\nN30 X100\nN40 M30\n"
    machine = machine_with(ve("MARK", synchronous=True))
    start(machine, program)
    ch = machine.channel(1)
    seen: list[tuple[float, float]] = []
    for _ in cycles_until_done(machine):
        seen.append((ch.axis("X").setpoint, float(machine.external.read("MARK", 1))))
    first = next(x for x, mark in seen if mark == 1.0)
    assert 49.0 <= first <= 51.0
    # the path did not stop at X50: the velocity there is well above zero
    at = [x for x, _ in seen]
    steps = [b - a for a, b in itertools.pairwise(at)]
    k = min(range(len(at)), key=lambda i: abs(at[i] - 50.0))
    assert steps[k] > 0.05


@pytest.mark.req("N-07")
def test_msg_is_an_event_at_decoding_msg_syn_when_the_path_gets_there_save_writes_a_file():
    program = (
        'N10 G01 X100 F6000\nN20 #MSG ["decoded"]\nN30 #MSG SYN ["reached"]\n'
        'N35 #FILE NAME [MSG="flow.txt"]\nN40 #MSG SAVE ["saved %d", 5]\nN50 X0\nN60 M30\n'
    )
    machine = machine_with()
    events = record_events(machine)
    start(machine, program)
    for _ in cycles_until_done(machine):
        pass
    by_text = {e.text: e for e in events if isinstance(e, NcMessage)}
    assert by_text["decoded"].cycle < 100  # decoded with the look-ahead, long before X reaches 100
    assert by_text["reached"].cycle > 900  # 100 mm at 100 mm/s
    assert by_text["saved 5"].save
    (write,) = [e for e in events if isinstance(e, NcFileWrite)]
    assert (write.file, write.text, write.channel) == ("flow.txt", "saved 5", 1)


@pytest.mark.req("N-07")
def test_flush_stops_the_path_between_two_blocks_that_would_blend():
    def min_speed_near(program: str) -> float:
        machine = machine_with()
        start(machine, program)
        ch = machine.channel(1)
        speeds = []
        for _ in cycles_until_done(machine):
            speeds.append((ch.axis("X").setpoint, ch.planner.velocity))
        return min(v for x, v in speeds if 40.0 < x < 60.0)

    straight = "N10 G01 X50 F6000\nN20 X100\nN30 M30\n"
    flushed = "N10 G01 X50 F6000\nN15 #FLUSH\nN20 X100\nN30 M30\n"
    assert min_speed_near(straight) > 50.0
    assert min_speed_near(flushed) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.req("N-03")
def test_acceleration_weighting_g131_slows_the_ramp():
    def cycles(program: str) -> int:
        machine = machine_with()
        start(machine, program)
        return len(list(cycles_until_done(machine)))

    full = cycles("N10 G01 X20 F30000\nN20 M30\n")
    half = cycles("N10 G131=25\nN20 G01 X20 F30000\nN30 M30\n")
    assert half > full * 1.3


# --- the budget per cycle (issue 20, "Bad input") --------------------------------------------------------


@pytest.mark.req("N-08")
def test_blocks_without_motion_spend_a_budget_per_cycle_and_go_on_next_cycle():
    machine = machine_with()
    ch = machine.channel(1)
    start(machine, "N10 G01 X1 Y1 F1000\n" * 20_000 + "M30\n")
    most = 0
    while ch.state in RUNNING:
        before = ch.interpreter.statements
        machine.step(1)
        most = max(most, ch.interpreter.statements - before)
    assert ch.state == ProgramState.FINISHED
    assert most <= STATEMENTS_PER_CYCLE
    assert machine.cycle >= 20_000 // STATEMENTS_PER_CYCLE


@pytest.mark.slow
@pytest.mark.req("N-08")
def test_a_long_run_of_blocks_without_motion_never_stalls_a_cycle():
    """800,000 blocks without motion were once decoded inside one cycle (a 3.9 s stall of the realtime
    clock); now no cycle runs more than the budget's statements and the program goes on. 200,000 of them
    here: the bound is per cycle, so a quarter proves it as well (1,500 cycles at the budget)."""
    machine = machine_with()
    ch = machine.channel(1)
    start(machine, "N10 G01 X1 Y1 F1000\n" * 200_000 + "M30\n")
    most = 0
    while ch.state in RUNNING:
        before = ch.interpreter.statements
        machine.step(1)
        most = max(most, ch.interpreter.statements - before)
    assert ch.state == ProgramState.FINISHED
    assert ch.decoder.blocks_decoded >= 200_000 - 1
    assert most <= STATEMENTS_PER_CYCLE
    assert machine.cycle >= 200_000 // STATEMENTS_PER_CYCLE


@pytest.mark.req("N-08")
def test_a_while_without_motion_runs_on_cycle_by_cycle_and_a_reset_stops_it():
    machine = machine_with()
    ch = machine.channel(1)
    start(machine, "P1 = 0\n$WHILE 1\nP1 = P1 + 1\n$ENDWHILE\nM30\n")
    machine.step(200)
    assert ch.state == ProgramState.RUNNING
    assert machine.cycle == 201
    ch.request_reset()
    machine.step(1)
    assert ch.state not in RUNNING
    start(machine, "N10 G01 X5 F6000\nN20 M30\n")
    for _ in cycles_until_done(machine):
        pass
    assert ch.state == ProgramState.FINISHED


# --- errors carry the subroutine's name ------------------------------------------------------------------


@pytest.mark.req("N-02", "N-08")
def test_an_error_in_a_subroutine_names_it_with_line_and_block():
    machine = machine_with(files={"sub.nc": "N5 G01 X10 F6000\nN6 G01 X9000\nN7 M17\n"})
    start(machine, "N10 L sub.nc\nN20 M30\n")
    for _ in cycles_until_done(machine):
        pass
    (alarm,) = [a for a in machine.alarm_history if a.severity == "error"]
    assert alarm.number == 120002  # beyond the positive software limit (was 911011)
    assert (alarm.line, alarm.block) == (2, "N6")
    assert alarm.params["program"] == "sub.nc"
    machine = machine_with(files={"sub.nc": "N5 X[1/0]\nN7 M17\n"})
    start(machine, "N10 L sub.nc\nN20 M30\n")
    for _ in cycles_until_done(machine):
        pass
    (alarm,) = [a for a in machine.alarm_history if a.severity == "error"]
    assert (alarm.number, alarm.line, alarm.block, alarm.params["program"]) == (914001, 1, "N5", "sub.nc")


# --- check -----------------------------------------------------------------------------------------------


@pytest.mark.req("N-02", "N-06")
@pytest.mark.parametrize("geometry_only", [False, True])
def test_check_runs_loops_subroutines_and_variables_in_both_modes(geometry_only):
    machine = machine_with(ve("RUN", type_="BOOLEAN"), ve("COUNT", type_="SGN32"), files={"sub.nc": SUB})
    machine.external.write("RUN", None, True)
    result = check_program(machine, LOOPS, geometry_only=geometry_only)
    assert result.completed, result.alarms
    assert result.final_position["X"] == pytest.approx(30.0)
    assert [m.text for m in result.messages] == ["passes: 3"]
    assert result.to_json()["messages"][0]["text"] == "passes: 3"


def _invoke(tmp_path, program: str, *args: str):
    path = tmp_path / "prog.nc"
    path.write_text(program)
    return CliRunner().invoke(main, ["check", str(path), *args])


@pytest.mark.req("N-06")
def test_check_of_an_endless_loop_stops_at_the_cycle_cap_with_exit_3(tmp_path):
    result = _invoke(
        tmp_path,
        "N10 $WHILE 1\nN20 G91 X1 F6000\nN30 X-1\nN40 $ENDWHILE\nM30\n",
        "--max-cycles",
        "1000",
        "--format",
        "json",
    )
    assert result.exit_code == EXIT_CAPPED, result.output
    report = json.loads(result.stdout)
    assert report["capped"] == {"by": "cycles", "cap": 1000}
    assert report["completed"] is False
    assert report["cycles"] <= 1000
    assert report["alarms"][-1]["id"] == 914050
    assert "did not end" in result.stderr


@pytest.mark.req("N-06")
def test_geometry_check_of_an_endless_loop_stops_at_the_iteration_cap_with_exit_3(tmp_path):
    result = _invoke(
        tmp_path, "$WHILE 1\nP1 = 1\n$ENDWHILE\nM30\n", "--geometry-only", "--max-iterations", "500"
    )
    assert result.exit_code == EXIT_CAPPED, result.output
    assert "DID NOT END" in result.stdout
    assert "914051" in result.stdout


@pytest.mark.req("N-02")
def test_check_finds_subroutines_in_the_program_dir_and_names_what_it_searched(tmp_path):
    library = tmp_path / "lib"
    library.mkdir()
    (library / "Drill.NC").write_text("G91 G01 Z-5 F600\nZ5\nG90\nM17\n")
    program = "N10 G01 X10 F6000\nN20 L drill.nc\nN30 M30\n"
    result = _invoke(tmp_path, program, "--program-dir", str(library), "--format", "json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["completed"] is True
    missing = _invoke(tmp_path, "N10 L nothere.nc\nM30\n", "--program-dir", str(library))
    assert missing.exit_code == 1
    assert "nothere.nc" in missing.stdout
    assert str(library) in missing.stdout
    assert str(tmp_path) in missing.stdout


@pytest.mark.req("N-02")
def test_check_does_not_follow_a_name_out_of_its_directories(tmp_path):
    (tmp_path / "secret.nc").write_text("X1\nM17\n")
    inner = tmp_path / "inner"
    inner.mkdir()
    path = inner / "prog.nc"
    path.write_text("L ../secret.nc\nM30\n")
    result = CliRunner().invoke(main, ["check", str(path)])
    assert result.exit_code == 1
    assert "914010" in result.stdout


@pytest.mark.req("N-07")
def test_check_reports_the_programs_messages(tmp_path):
    result = _invoke(tmp_path, 'N10 P1 = 3\nN20 #MSG ["P1 is %d", P1]\nN30 M30\n')
    assert result.exit_code == 0
    assert "message (prog.nc, line 2, N20): P1 is 3" in result.stdout


# --- #MEAS MODE: the measuring type of G100 (C14-23's hook, manual 207084683) -----------------------------


@pytest.mark.req("N-01", "C14-23")
def test_meas_mode_selects_the_measuring_type_of_the_g100_blocks_after_it():
    from tests.unit.areas.helpers import only_alarm
    from tests.unit.areas.test_area_measuring import make_machine, run_with_probe_at

    # the channel's default is type 5 (G310's): G100 is ID 20138 until #MEAS MODE [3] selects type 3
    m = make_machine(messtyp=5)
    run_with_probe_at(m, "N10 #MEAS MODE [3]\nN20 G100 X50 F6000\nN30 G01 Y5\nM30\n", None)
    assert list(m.alarm_history) == []
    assert m.channel(1).setpoints()[:2] == [pytest.approx(50.0), pytest.approx(5.0)]
    # #MEAS MODE without a value: the default again
    m = make_machine(messtyp=5)
    program = "N10 #MEAS MODE [1 + 2]\nN20 G100 X50 F6000\nN30 #MEAS MODE\nN40 G100 X60\nM30\n"
    run_with_probe_at(m, program, None)
    assert only_alarm(m, 20138).params == {"type": 5}
    # a type from the program that G100 does not allow
    m = make_machine(messtyp=1)
    run_with_probe_at(m, "N10 P1 = 6\nN20 #MEAS MODE [P1]\nN30 G100 X50 F6000\nM30\n", None)
    assert only_alarm(m, 20138).params == {"type": 6}


@pytest.mark.req("N-01")
def test_meas_mode_out_of_range_or_with_other_words_and_other_meas_commands_are_alarms():
    from tests.unit.nc_helpers import error

    assert error("#MEAS MODE [8]\nM30\n").alarm == 914005
    assert error("#MEAS MODE [3] X10\nM30\n").alarm == 914015
    err = error("#MEAS [TYPE3]\nM30\n")
    assert err.alarm == 910110
    assert "#MEAS" in err.message
