"""The long tail of issue 33 (item 5): one construct after the other, each as the manual page cited in
docs/nc-language.md describes it - block numbers from expressions, the spindle-specific syntax, #TOOL,
#IDENT, the default feed, the dwell forms - and the messages that once named the wrong thing."""

from __future__ import annotations

import pytest

from hli_server.engine import Machine
from hli_server.engine.nc.directives import SyncAction
from tests.unit.engine_helpers import mill, mill_config, positions, run, start
from tests.unit.nc_helpers import FakeHost, interpret


def alarms(machine: Machine) -> list[int]:
    return [a.number for a in machine.alarm_history]


# --- N<expr> (PM 206817035) ---------------------------------------------------------------------------
@pytest.mark.req("LT-01")
def test_a_block_number_is_an_expression_rounded_to_a_whole_number() -> None:
    run_ = interpret("P123 = 40\nNP123 X1\n$FOR P1 = 1, 3\nN[P1*100 + 0.4] XP1\n$ENDFOR\nN[2.5] X0\nM30\n")
    assert run_.error is None
    assert [b.number for b in run_.blocks if b.axes] == [40, 100, 200, 300, 3]


@pytest.mark.req("LT-01")
def test_a_computed_block_number_names_the_block_of_an_alarm() -> None:
    m = mill()
    run(m, "P5 = 70\nG01 X1 F1000\nNP5 G02 X2\nM30\n")
    [alarm] = [a for a in m.alarm_history if a.severity == "error"]
    assert alarm.block == "N70"


@pytest.mark.req("LT-01")
@pytest.mark.parametrize("program", ["P1 = -1\nNP1 X1\nM30\n", "P1 = 1E12\nNP1 X1\nM30\n"])
def test_a_computed_block_number_out_of_range_is_910108(program: str) -> None:
    run_ = interpret(program.replace("1E12", "1000000000000"))
    assert run_.alarm == 910108


# --- spindle-specific syntax (PM 208178187, 208317067) -----------------------------------------------
@pytest.mark.req("LT-02")
def test_the_main_spindles_m3_and_rev_are_the_speed_g95_multiplies_with() -> None:
    plain = mill()
    run(plain, "N10 M3 S1000\nN20 G95 G01 X10 F0.5\nM30\n")
    specific = mill()
    run(specific, "N10 S[M3 REV1000]\nN20 G95 G01 X10 F0.5\nM30\n")
    assert alarms(specific) == []
    assert positions(specific)["X"] == pytest.approx(10.0)
    assert specific.cycle == plain.cycle  # 500 mm/min either way


@pytest.mark.req("LT-02")
def test_other_spindles_and_plcopen_commands_are_accepted_with_one_warning_each() -> None:
    program = (
        "N10 S1[MC_MoveVelocity Velocity=1333 Acceleration=770 Deceleration=880 \\\n"
        "Jerk=10000 Direction=1]\n"
        "N20 S2[M4 REV5000] S2[M19 POS45]\n"
        "N30 S1[MC_Stop]\n"
        "N40 G01 X1 F1000\nM30\n"
    )
    run_ = interpret(program)
    assert run_.error is None
    warnings = run_.host.warnings
    assert [w[0] for w in warnings] == [911041, 911041]  # once per spindle and program
    assert "S1[MC_MOVEVELOCITY]" in warnings[0][1]
    assert "S2[M4 REV]" in warnings[1][1]
    assert run_.values() == [1.0]


@pytest.mark.req("LT-02")
def test_a_spindle_value_is_evaluated_and_its_errors_are_the_blocks() -> None:
    run_ = interpret("N10 S2[M3 REV 1/0]\nM30\n")
    assert run_.alarm == 914001


@pytest.mark.req("LT-02", "N-08")
@pytest.mark.parametrize(
    ("block", "construct"),
    [
        ("X[INDP_SYN POS=10 G90 G01 FEED=1000]", "synchronous independent axis motion"),
        ("Y[INDP_ASYN POS=10 G90 G00]", "asynchronous independent axis motion"),
        ("Z[OSC ON]", "oscillating axis motion"),
        ("X[MC_MoveAbsolute Position=133 Velocity=1000 Direction=2]", "PLCopen motion of a path axis"),
    ],
)
def test_axis_specific_functions_are_refused_by_name(block: str, construct: str) -> None:
    run_ = interpret(f"N10 {block}\nM30\n")
    assert run_.alarm == 910110
    assert run_.error is not None
    assert construct in run_.error.message
    assert "unknown name" not in run_.error.message


@pytest.mark.req("N-03")
def test_an_axis_value_in_brackets_is_still_an_expression() -> None:
    assert interpret("P1 = 2\nX[P1 + 3] S[P1 * 100]\nM30\n").values() == [5.0]


# --- #TIME, G04 S (PM 206132747) and the unit tests of the decoder's forms: test_motion_mslope_units --------


# --- #TOOL (PM 208577419, 208592267) -----------------------------------------------------------------
@pytest.mark.req("LT-03")
def test_tool_prep_is_the_t_word_and_tool_data_the_d_word() -> None:
    run_ = interpret("#TOOL PREP [4]\n#TOOL DATA [P1 + 2, 0, ]\nM30\n".replace("P1 + 2", "2"))
    extras = [b.extra for b in run_.blocks if b.extra]
    assert extras == [{"T": 4.0}, {"D": 2.0}]


@pytest.mark.req("LT-03")
def test_tool_data_selects_the_tool_the_areas_watch() -> None:
    from schemas.config import ToolEntry

    config = mill_config()
    config.channels[0].tools.append(ToolEntry(number=2, length=500_000, radius=20_000))
    m = Machine(config)
    run(m, "N10 #TOOL DATA [2]\nN20 G01 Z100 F6000\nN30 V.P.R = V.G.WZ_AKT.R\nM30\n")
    assert alarms(m) == []
    assert positions(m)["Z"] == pytest.approx(150.0)  # the length in the tool axis (M-15)


@pytest.mark.req("LT-03")
def test_a_sister_or_variant_tool_is_the_kernels_20861() -> None:
    assert interpret("#TOOL DATA [1, 2]\nM30\n").alarm == 20861
    assert interpret("#TOOL PREP [1, , 3]\nM30\n").alarm == 20861


@pytest.mark.req("LT-03")
@pytest.mark.parametrize(
    ("line", "alarm"),
    [
        ("#TOOL DATA", 914000),
        ("#TOOL DATA [, 2]", 914015),
        ("#TOOL PREP [1, 2, 3, 4]", 914015),
        ("#TOOL LIFE", 914015),
    ],
)
def test_malformed_tool_commands_are_refused(line: str, alarm: int) -> None:
    assert interpret(f"{line}\nM30\n").alarm == alarm


@pytest.mark.req("LT-03")
def test_tool_life_is_accepted_with_one_warning() -> None:
    run_ = interpret("#TOOL LIFE READ [1]\n#TOOL LIFE READ[2]\n#TOOL LIFE REMOVE\nG01 X1 F100\nM30\n")
    assert run_.error is None
    assert run_.warnings == [911041]
    assert "#TOOL LIFE READ" in run_.host.warnings[0][1]


# --- #IDENT (PM 207352971, 207359627, 207365515) -------------------------------------------------------
@pytest.mark.req("LT-04")
def test_ident_reads_back_what_was_written_as_the_telegram_carries_it() -> None:
    program = (
        "#IDENT WR [AX=X ID S-0-0104 VAL 655.35 TYP 2 DEC 2 SERC]\n"
        "#IDENT RD [AX X ID S-0-0104 P=P1 TYP 2 DEC 2 SERC]\n"
        "#IDENT RD [AX=X, ID=S-0-0104, P=P2, TYP=4, DEC=0, SERC]\n"
        "#IDENT WR [AX=Y ID S-0-0104 VAL 655.357 TYP 2 DEC 2 SERC]\n"
        "#IDENT RD [AX=Y ID S-0-0104 P=P3 TYP 4 DEC 2 SERC]\n"
        "#IDENT WR SYN [AXNR=1 ID 0x6072_00 VAL -1 TYP 2 DEC 0 CAN NO_WAIT]\n"
        "#IDENT RD [AXNR 1 ID 0x6072_00 P=V.P.V TYP 2 DEC 0 CAN]\n"
        "X[P1] Y[P2] Z[P3] V.P.W = V.P.V\nM30\n"
    )
    run_ = interpret(program)
    assert run_.error is None
    # 655.35 with 2 decimals is the integer 65535; read with 0 decimals it is that integer; 655.357 rounds
    # to 65536, which 2 bytes carry as 0; -1 in 2 bytes is 65535
    assert run_.axes[-1] == {"X": 655.35, "Y": 65535.0, "Z": 0.0}
    assert interpret(program.replace("M30", "X[V.P.W]\nM30")).values()[-1] == 65535.0


@pytest.mark.req("LT-04")
def test_ident_of_the_cycle_times_reads_the_channels_and_is_not_changeable() -> None:
    run_ = interpret("#IDENT RD [AX=Y ID=S-0-0002 P=P1 TYP=2 DEC=2 SERC]\nX[P1]\nM30\n")
    assert run_.values() == [10.0]  # 1000 µs, two decimals
    assert interpret("#IDENT WR [AX=X ID S-0-0002 VAL 5 TYP 2 DEC 0 SERC]\nM30\n").alarm == 50357


@pytest.mark.req("LT-04")
def test_ident_an_unknown_ident_warns_140032_and_reads_0() -> None:
    run_ = interpret("P1 = 7\n#IDENT RD [AX=Z ID=P-0-0129 P=P1 TYP=4 DEC=0 SERC]\nX[P1]\nM30\n")
    assert run_.warnings == [140032]
    assert run_.values() == [0.0]


@pytest.mark.req("LT-04")
def test_ident_wr_syn_writes_when_the_path_passes() -> None:
    run_ = interpret("G01 X1 F100\n#IDENT WR SYN [AX=X ID S-0-0104 VAL 3 TYP 2 DEC 0 SERC]\nM30\n")
    assert any(isinstance(out, SyncAction) for out in run_.outputs)


@pytest.mark.req("LT-04")
@pytest.mark.parametrize(
    ("line", "alarm"),
    [
        ("#IDENT WR [AX=Q ID S-0-1 VAL 1 TYP 2 DEC 0 SERC]", 20797),
        ("#IDENT WR [AX=X ID S-0-1 TYP 2 DEC 0 SERC]", 914015),
        ("#IDENT RD [AX=X ID S-0-1 TYP 2 DEC 0 SERC]", 914015),
        ("#IDENT WR [AX=X ID S-0-1 VAL 1 TYP 3 DEC 0 SERC]", 914015),
        ("#IDENT WR [AX=X ID S-0-1 VAL 1 TYP 2 DEC 0]", 914015),
        ("#IDENT WR [AX=X ID S-0-1 VAL 1 TYP 2 DEC 0 SERC FOO]", 914015),
        ("#IDENT", 910110),
    ],
)
def test_malformed_ident_commands(line: str, alarm: int) -> None:
    assert interpret(f"{line}\nM30\n").alarm == alarm


@pytest.mark.req("LT-04")
def test_the_drive_keeps_what_was_written_across_programs() -> None:
    host = FakeHost()
    from hli_server.engine.nc import Compiler, Interpreter

    it = Interpreter(Compiler(host.axes, ("X", "Y", "Z")), host, budget=None)
    interpret("#IDENT WR [AX=X ID P-0-0001 VAL 12 TYP 4 DEC 0 SERC]\nM30\n", host=host, interpreter=it)
    again = interpret(
        "#IDENT RD [AX=X ID P-0-0001 P=P1 TYP 4 DEC 0 SERC]\nX[P1]\nM30\n", host=host, interpreter=it
    )
    assert again.values() == [12.0]


# --- the default feed (P-CHAN-00099) and 20008 (DG 250515083) ----------------------------------------------
@pytest.mark.req("LT-05")
def test_a_program_without_f_runs_at_the_channels_default_feed() -> None:
    config = mill_config()
    config.channels[0] = config.channels[0].model_copy(update={"default_feedrate": 600.0})
    m = Machine(config)
    run(m, "N10 G01 X10\nM30\n")
    assert alarms(m) == []
    assert positions(m)["X"] == pytest.approx(10.0)
    reference = mill()
    run(reference, "N10 G01 X10 F600\nM30\n")
    assert m.cycle == reference.cycle


@pytest.mark.req("LT-05")
def test_without_a_default_feed_a_feed_move_without_f_is_the_kernels_20008() -> None:
    m = mill()
    run(m, "N10 G00 X1\nN20 G01 X10\nM30\n")
    [alarm] = m.alarm_history
    assert (alarm.number, alarm.block) == (20008, "N20")
    assert "P-CHAN-00099" in alarm.message


# --- G74 programmable homing (PM 206138635) -----------------------------------------------------------------
@pytest.mark.req("LT-07")
def test_g74_moves_the_groups_to_their_reference_points_in_the_programmed_order() -> None:
    from schemas.events import ReferenceChanged
    from tests.unit.engine_helpers import record_events

    m = mill()
    events = record_events(m)
    trail: list[tuple[float, float, float]] = []

    def each(machine: Machine) -> None:
        trail.append((machine.axes[0].setpoint, machine.axes[1].setpoint, machine.axes[2].setpoint))

    run(m, "G01 X100 Y50 Z10 F6000\nN20 G74 X2 Y3 Z1\nG01 X10 Y10\nM30\n", each=each)
    assert alarms(m) == []
    assert positions(m) == {"X": 10.0, "Y": 10.0, "Z": 0.0}
    # Z first (1), then X (2), then Y (3): each group alone, the others standing
    home_z = next(k for k, p in enumerate(trail) if p[2] == 0.0)
    home_x = next(k for k, p in enumerate(trail) if p[0] == 0.0)
    home_y = next(k for k, p in enumerate(trail) if p[1] == 0.0)
    assert home_z < home_x < home_y
    assert all(p[0] == pytest.approx(100.0) and p[1] == pytest.approx(50.0) for p in trail[: home_z + 1][-5:])
    referenced = [e.axis for e in events if isinstance(e, ReferenceChanged) and e.state == "referenced"]
    assert referenced == ["Z", "X", "Y"]


@pytest.mark.req("LT-07", "C14-14")
@pytest.mark.parametrize("geometry_only", [False, True])
def test_the_homing_move_is_checked_like_any_block(geometry_only: bool) -> None:
    from hli_server.commands.check import check_program

    area = (
        "#CONTROL AREA BEGIN [ID=1 PROT POLY MIN_EXCUR=-100 MAX_EXCUR=100]\n"
        "G01 X40 Y-5 F1000\nX60\nY5\nX40\nY-5\n#CONTROL AREA END\n#CONTROL AREA ON ALL\n"
    )
    text = "G01 X100 Y0 F6000\n" + area + "N20 G74 X1\nM30\n"
    result = check_program(Machine(mill_config()), text, geometry_only=geometry_only)
    [alarm] = result.alarms
    assert (alarm.number, alarm.block) == (912001, "N20")
    assert result.final_position["X"] == pytest.approx(100.0)


# --- #AKIMA (PM 207222923, 207229579, 207237003) and #FILTER (TF5200 FIR filter 542033291) ----------------
AKIMA = """N10 G01 X20 Y0 F1000
N20 #AKIMA TRANS[START=USER END=AUTO]
N30 # AKIMA STARTVECTOR X1 Y1 Z0
N35 #AKIMA ENDVECTOR X=1 Y-1 Z[0]
N40 G151
N50 G01 X40 Y20
N60 X60
N70 Y0
N80 X80
N90 Y10
N100 G150
N110 X70
N120 M30
"""


@pytest.mark.req("LT-09")
def test_the_manuals_akima_example_runs_as_the_spline_with_one_warning_more() -> None:
    with_akima = mill()
    run(with_akima, AKIMA)
    without = mill()
    run(without, "".join(line + "\n" for line in AKIMA.splitlines() if "AKIMA" not in line))
    assert alarms(with_akima) == [911041, 911040]
    assert alarms(without) == [911040]
    assert with_akima.cycle == without.cycle  # the path is the same: the tangents are not simulated
    assert positions(with_akima) == positions(without)


@pytest.mark.req("LT-09")
@pytest.mark.parametrize(
    "line",
    [
        "#AKIMA TRANS [START=FOO]",
        "#AKIMA TRANS [START=AUTO START=USER]",
        "#AKIMA TRANS [START=AUTO",
        "#AKIMA STARTVECTOR",
        "#AKIMA",
    ],
)
def test_malformed_akima_commands_are_refused(line: str) -> None:
    assert interpret(f"{line}\nM30\n").alarm in (914015, 910110)


@pytest.mark.req("LT-09")
def test_an_akima_transition_list_without_its_bracket_says_so() -> None:
    error = interpret("#AKIMA TRANS [START=AUTO, END=USER\nM30\n").error
    assert error is not None
    assert (error.alarm, error.line) == (914015, 1)
    assert "#AKIMA TRANS [: ']' missing" in error.message


@pytest.mark.req("LT-09")
def test_filter_runs_the_path_unfiltered_with_one_warning_naming_the_tolerance() -> None:
    m = mill()
    run(m, "#FILTER ON [ORDER=20 AX_DEV=0.01]\nG01 X10 Y10 F3000\nX20\n#FILTER OFF\n#FILTER ON\nM30\n")
    assert alarms(m) == [911041]
    assert "AX_DEV=0.01" in m.alarm_history[0].message
    assert positions(m)["X"] == pytest.approx(20.0)
    assert interpret("#FILTER ON [FOO=1]\nM30\n").alarm == 914015
    assert interpret("#FILTER ON [ORDER=-1]\nM30\n").alarm == 910111


# --- realtime cycles #RT CYCLE and $IF ONCE|EDGE|ALWAYS (TF5261) ----------------------------------------
def _counter_machine() -> Machine:
    from schemas.config import ExternalVariableConfig

    config = mill_config()
    config = config.model_copy(
        update={"external_variables": [ExternalVariableConfig(name="COUNT", type="UNS32", synchronous=False)]}
    )
    return Machine(config)


RT_PROGRAM = """N05 G00 X0 Y0 Z0
#RT CYCLE [SCOPE = PROG]
  $IF {freq} V.RTA.ACS.ACT_POS.X > 200
    M100
    V.E.COUNT = V.E.COUNT + 1
  $ENDIF
  $IF V.RTA.ACS.ACT_POS.X > 300
    V.RTG.OVERRIDE.VEL.CYCLE = 50
  $ELSEIF V.RTA.MCS.CMD_POS.X > 250
    V.RTG.OVERRIDE.VEL.CYCLE = 75
  $ELSE
    V.RTG.OVERRIDE.VEL.CYCLE = 100
  $ENDIF
#RT CYCLE END
N10 G01 X400 F6000
N20 G01 X100
N30 G01 X400
M30
"""


@pytest.mark.req("LT-10")
@pytest.mark.parametrize(("freq", "count"), [("ONCE", 1), ("EDGE", 2), ("ALWAYS", None)])
def test_a_realtime_cycle_runs_every_cycle_with_its_ifs_qualified(freq: str, count: int | None) -> None:
    """TF5261 444686091: the path passes X=200 outward twice (out, back below it, out again): ONCE counts the
    first time only, EDGE each change to TRUE, ALWAYS every cycle from the first time on."""
    m = _counter_machine()
    run(m, RT_PROGRAM.format(freq=freq))
    assert alarms(m) == []
    value = m.external.read("COUNT", 1)
    if count is None:
        assert value > 5000  # every cycle from the first X > 200 on
    else:
        assert value == count


@pytest.mark.req("LT-10")
def test_the_realtime_override_slows_the_path_where_the_cycle_says() -> None:
    slow = _counter_machine()
    run(slow, RT_PROGRAM.format(freq="ONCE"))
    plain = _counter_machine()
    run(plain, RT_PROGRAM.format(freq="ONCE").replace("= 50", "= 100").replace("= 75", "= 100"))
    # 50 mm at 75 % and 100 mm at 50 %, on each of the three passes, at 100 mm/s
    extra = (50 / 0.75 - 50 + 100 / 0.5 - 100) * 3 / 100.0
    assert (slow.cycle - plain.cycle) / 1000.0 == pytest.approx(extra, rel=0.05)


@pytest.mark.req("LT-10")
def test_realtime_cycles_are_managed_by_id_and_scope() -> None:
    m = _counter_machine()
    program = (
        "#RT CYCLE DEF [ID=17 SCOPE=PROG]\n  V.E.COUNT = V.E.COUNT + 1\n#RT CYCLE END\n"
        "G01 X10 F600\n"  # 1 s: the cycle is defined, not started
        "#RT CYCLE START [ID=17]\nG01 X20\n#RT CYCLE HOLD [ID=17]\nG01 X30\n#RT CYCLE CONTINUE [ID=17]\n"
        "G01 X40\n#RT CYCLE DELETE [ID=17]\nG01 X50\nM30\n"
    )
    run(m, program)
    assert alarms(m) == []
    assert 1900 <= m.external.read("COUNT", 1) <= 2100  # X10..X20 and X30..X40: 2 s


@pytest.mark.req("LT-10")
def test_a_block_scope_cycle_acts_on_the_next_block_only() -> None:
    m = _counter_machine()
    run(
        m, "G01 X0 F600\n#RT CYCLE [SCOPE=BLOCK]\n  V.E.COUNT = V.E.COUNT + 1\n#RT CYCLE END\nX10\nX20\nM30\n"
    )
    assert alarms(m) == []
    assert 950 <= m.external.read("COUNT", 1) <= 1050  # the 1 s of X0..X10


@pytest.mark.req("LT-10")
@pytest.mark.parametrize(
    ("program", "alarm"),
    [
        ("#RT CYCLE [SCOPE=PROG]\nG01 X10 F100\n#RT CYCLE END\nM30\n", 910110),  # motion in it
        ("#RT CYCLE [SCOPE=PROG]\nX[INDP_ASYN POS=10 G90 G00]\n#RT CYCLE END\nM30\n", 910110),
        ("#RT CYCLE [SCOPE=PROG]\nP1 = 2\n#RT CYCLE END\nM30\n", 910110),
        ("#RT CYCLE [SCOPE=PROG]\n$WHILE 1\n$ENDWHILE\n#RT CYCLE END\nM30\n", 910110),
        ("#RT CYCLE [SCOPE=PROG]\n$IF ONCE 1\n$ELSE\n$ENDIF\n#RT CYCLE END\nM30\n", 914000),
        ("#RT CYCLE DEF [SCOPE=PROG]\n#RT CYCLE END\nM30\n", 22003),  # DEF needs an ID
        ("#RT CYCLE [SCOPE=GLOBAL]\n#RT CYCLE END\nM30\n", 22003),
        ("#RT CYCLE [SCOPE=PROG]\nM100\n", 914015),  # no #RT CYCLE END
        ("#RT CYCLE END\nM30\n", 914015),
        ("$IF ONCE 1\n$ENDIF\nM30\n", 914015),
        ("P1 = V.RTA.ACS.ACT_POS.X\nM30\n", 910110),
        ("#RT WHILE\nM30\n", 910110),
    ],
)
def test_what_a_realtime_cycle_cannot_hold_here_is_refused_by_name(program: str, alarm: int) -> None:
    assert interpret(program).alarm == alarm


# --- E, the feed at block end (PM 206811147) ----------------------------------------------------------------
@pytest.mark.req("LT-08")
def test_the_feed_at_block_end_runs_the_same_path_with_one_warning() -> None:
    with_e = mill()
    run(with_e, "G01 X10 F1000 E100\nX20 E[50]\nM30\n")
    without = mill()
    run(without, "G01 X10 F1000\nX20\nM30\n")
    assert alarms(with_e) == [911041]
    assert "E (the feed at the block's end)" in with_e.alarm_history[0].message
    assert positions(with_e) == positions(without)
    assert with_e.cycle == without.cycle


@pytest.mark.req("LT-08", "N-08")
def test_every_hash_command_of_the_kernel_has_its_decision_in_the_docs() -> None:
    """docs/nc-language.md says for every `#` command whether it runs (and how) or why it is refused."""
    from pathlib import Path

    from hli_server.engine.nc.language import HASH_COMMANDS

    doc = (Path(__file__).parents[2] / "docs" / "nc-language.md").read_text(encoding="utf-8")
    missing = [name for name in HASH_COMMANDS if f"`#{name}" not in doc]
    assert missing == [], f"docs/nc-language.md does not name #{missing}"


# --- #FILENAME [MSG=V.E.name] (PM 207504523, issue 33 item 5) ---------------------------------------------
@pytest.mark.req("LT-04", "N-07")
def test_the_message_file_named_by_a_string_variable() -> None:
    from hli_server.engine.external import ExternalType, ExternalVarSpec

    name = ExternalVarSpec("TEACH_FILE_NAME", ExternalType.STRING, (), None, False, string_size=64)
    host = FakeHost(external=[name])
    host.external.write("TEACH_FILE_NAME", None, "points.txt")
    run_ = interpret(
        'N10 #FILENAME [MSG=V.E.TEACH_FILE_NAME]\n#MSG SAVE ["P1"]\n#VAR\nV.L.F : STRING[20] = "other.txt"\n'
        '#ENDVAR\n#FILE NAME [MSG=V.L.F]\n#MSG SAVE ["P2"]\nM30\n',
        host=host,
    )
    assert run_.error is None
    assert [(m[0], m[2]) for m in host.messages] == [("P1", "points.txt"), ("P2", "other.txt")]
    assert interpret("P1 = 2\n#FILE NAME [MSG=V.P.X]\nM30\n").alarm == 914003
    numeric = interpret("V.P.X = 2\n#FILE NAME [MSG=V.P.X]\nM30\n")
    assert numeric.alarm == 914006


# --- a recording's snapshot (recording/snapshot.py) keeps what the long tail leaves in the machine ---
SNAPSHOT_PROGRAM = (
    RT_PROGRAM.format(freq="EDGE").replace("M30\n", "")
    + "G74 Z1 X2\n"
    + "G01 X10 Y0 F3000\n"
    + "G301 X10 Y10 I2\n"
    + "#IDENT WR SYN [AX=X ID S-0-0104 VAL 3 TYP 2 DEC 0 SERC]\n"
    + "G302 X0 Y10 I1\n"
    + "#FILTER ON [ORDER=20 AX_DEV=0.01]\n"
    + "X0 Y0\n"
    + "M30\n"
)


@pytest.mark.req("LT-10", "LT-06", "LT-04")
def test_a_snapshot_taken_in_the_middle_of_the_long_tail_goes_on_as_the_machine() -> None:
    """A realtime cycle running, a G74 group on its way, a motion held for a rounding and an #IDENT WR SYN
    waiting in the look-ahead: a snapshot taken at any cycle holds them as data (no function made at run
    time), and the machine restored from it goes on exactly as the live one."""
    import json

    from hli_server.recording.snapshot import capture, restore

    live = _counter_machine()
    start(live, SNAPSHOT_PROGRAM)
    twin: Machine | None = None
    for _ in range(400):
        live.step(100)
        taken = capture(live)  # never SnapshotError
        if twin is None and live.cycle >= 3000:
            twin = _counter_machine()
            restore(json.loads(json.dumps(taken, allow_nan=False)), twin)
        elif twin is not None:
            twin.step(100)
            if live.cycle % 2000 == 0:
                assert capture(twin) == taken, f"the machines differ at cycle {live.cycle}"
        if not live.channel(1).program_running:
            break
    assert twin is not None
    assert not live.channel(1).program_running
    assert [a.number for a in live.alarm_history] == [a.number for a in twin.alarm_history]
    assert live.external.read("COUNT", 1) == twin.external.read("COUNT", 1) == 2
