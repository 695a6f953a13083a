"""The NC language of the kernel, construct by construct (N-01..N-08; docs/nc-language.md).

Each construct is run through the interpreter alone (``tests/unit/nc_helpers.py``): the blocks it
hands the decoder, the values they carry, and for every mistake the kernel's error ID where its
diagnosis pages give one (the "Wrong" examples of those pages are in ``test_nc_manual_examples.py``).
"""

from __future__ import annotations

import pytest

from hli_server.engine.alarms import ALARMS
from hli_server.engine.nc import STATEMENTS_PER_CYCLE, Compiler, Interpreter
from hli_server.engine.nc.directives import PAUSE, FlushStop, FlushWait
from hli_server.engine.nc.language import MAX_CALL_DEPTH
from hli_server.engine.programs import ProgramFile
from tests.unit.nc_helpers import FakeHost, error, interpret, real

# --- program structure (N-01) ----------------------------------------------------------------------------


@pytest.mark.req("N-01")
def test_main_program_header_and_local_subroutines_before_and_after_it():
    text = """\
%L UP1           (1st local subroutine)
N1 G01 X[P1] F1000
N9 M17           (M17 may be omitted)
%MAIN            (main program)
N10 P1 = 5
N20 LL UP1
N30 LL UP2
N40 M30
%L UP2
N50 X7
"""
    run = interpret(text)
    assert run.error is None
    assert run.values() == [5.0, 7.0]
    assert [b.program for b in run.blocks if b.axes] == ["UP1", "UP2"]
    assert run.blocks[-1].m_codes == (30,)


@pytest.mark.req("N-01")
def test_a_program_without_header_starts_at_its_first_line_and_ends_at_m30():
    run = interpret("N10 X1\nN20 M30\nN30 X99\n")
    assert run.values() == [1.0]
    assert run.ended


@pytest.mark.req("N-01")
def test_m02_ends_the_program_too():
    run = interpret("N10 X1\nN20 M02\nN30 X99\n")
    assert run.values() == [1.0]


@pytest.mark.req("N-01")
def test_the_end_of_the_text_ends_a_program_without_m30():
    run = interpret("N10 X1\nN20 X2\n")
    assert run.ended
    assert run.values() == [1.0, 2.0]


@pytest.mark.req("N-01")
@pytest.mark.parametrize(
    ("line", "x"),
    [
        ("N10 X1 (a (nested) comment) Y2", 1.0),
        ("N10 X1 (unclosed: runs to the end of the line X99", 1.0),
        ("N10 X1 ; Y2 X3", 1.0),
        ("N10 X1 (first) (second)", 1.0),
        ("N10 X1 #MSG not here", None),
    ],
)
def test_comments(line, x):
    run = interpret(line + "\nM30\n")
    if x is None:
        assert run.error is not None
        return
    assert run.error is None, run.error
    assert run.values() == [x]


@pytest.mark.req("N-01")
def test_a_parenthesis_inside_a_string_is_no_comment():
    run = interpret('#MSG ["(x) ; y"]\nM30\n')
    assert run.messages == ["(x) ; y"]


@pytest.mark.req("N-01")
def test_comment_block_begin_end_spans_lines():
    text = "N10 X1\n#COMMENT BEGIN\nN20 X99 this is not code $IF\n#COMMENT END\nN30 X2\nM30\n"
    assert interpret(text).values() == [1.0, 2.0]


@pytest.mark.req("N-01")
def test_comment_block_without_end_is_an_alarm():
    err = error("#COMMENT BEGIN\nN20 X99\n")
    assert err.alarm == 914016


@pytest.mark.req("N-01")
def test_block_skip_slash_runs_the_block_as_with_skip_off():
    run = interpret("/ N10 X1\n/1 N20 X2\nM30\n")
    assert run.values() == [1.0, 2.0]


@pytest.mark.req("N-01")
def test_backslash_continues_a_block_on_the_next_line():
    run = interpret("N10 G01 X1 \\\n   Y2 F100\nM30\n")
    assert run.axes == [{"X": 1.0, "Y": 2.0}]


@pytest.mark.req("N-01")
def test_m17_ends_a_subroutine_m30_in_a_subroutine_ends_the_program_with_a_warning():
    run = interpret("L sub.nc\nX5\nM30\n", {"sub.nc": "X1\nM30\nX2\n"})
    assert run.values() == [1.0]
    assert run.warnings == [914030]
    err = error("X1\nM17\nM30\n")
    assert err.alarm == 914032


# --- subroutines and cycles (N-02) -----------------------------------------------------------------------


@pytest.mark.req("N-02")
def test_global_subroutine_sees_and_changes_the_p_parameters():
    run = interpret("P10=3\nL sub.nc\nX[P10]\nM30\n", {"sub.nc": "G01 X[P10*2] F100\nP10=7\nM17\n"})
    assert run.values() == [6.0, 7.0]
    assert run.blocks[0].program == "sub.nc"


@pytest.mark.req("N-02")
def test_global_subroutine_name_is_matched_case_insensitively_and_may_hold_local_subroutines():
    sub = "%L INNER\nY[P1]\nM17\n%SUBMAIN\nLL INNER\nM29\n"
    run = interpret("P1 = 4\nL SUB.NC\nM30\n", {"sub.nc": sub})
    assert run.values("Y") == [4.0]


@pytest.mark.req("N-02")
def test_a_global_subroutine_is_compiled_once_but_its_new_text_is_run_when_it_changed():
    class ChangingHost(FakeHost):
        calls = 0

        def find_program(self, name: str) -> ProgramFile | None:
            self.calls += 1
            x = 1 if self.calls <= 2 else 5
            return ProgramFile("sub.nc", f"G01 X[P1 + {x}] F100\nM17\n", "upload:sub.nc")

    program = "P1 = 0\nL sub.nc\nP1 = 10\nL sub.nc\nP1 = 20\nL sub.nc\nM30\n"
    host = ChangingHost()
    it = Interpreter(Compiler(host.axes, ("X", "Y", "Z")), host, budget=None)
    run = interpret(program, host=host, interpreter=it)
    assert run.values() == [1.0, 11.0, 25.0]
    assert [b.program for b in run.blocks if b.axes] == ["sub.nc"] * 3


@pytest.mark.req("N-02")
def test_a_missing_global_subroutine_names_itself_and_every_place_searched():
    err = error("L missing.nc\nM30\n", {"other.nc": "M17\n"})
    assert err.alarm == 914010
    assert "missing.nc" in err.message
    assert "uploaded files" in err.message


@pytest.mark.req("N-02")
def test_a_missing_local_subroutine_is_an_alarm_naming_it():
    err = error("LL NOPE\nM30\n")
    assert err.alarm == 914010
    assert "NOPE" in err.message


@pytest.mark.req("N-02")
def test_recursion_without_end_is_the_kernels_stack_overflow():
    err = error("L self.nc\nM30\n", {"self.nc": "L self.nc\nM17\n"})
    assert err.alarm == 20360
    assert err.program == "self.nc"
    assert str(MAX_CALL_DEPTH) in err.message


@pytest.mark.req("N-02")
def test_nothing_may_follow_a_call_in_its_block():
    assert error("N10 L sub.nc X100\nM30\n", {"sub.nc": "M17\n"}).alarm == 21542
    run = interpret("N10 X100 L sub.nc\nM30\n", {"sub.nc": "Y1\nM17\n"})
    assert run.axes == [{"X": 100.0}, {"Y": 1.0}]


@pytest.mark.req("N-02")
def test_cycle_call_with_parameters_and_exist():
    cycle = "X[@P1] Y[@P2]\n$IF EXIST[@P3]\nZ1\n$ELSE\nZ2\n$ENDIF\n@P1 = @P1 + 1\nX[@P1]\nM17\n"
    run = interpret("P1 = 2\nL CYCLE [NAME=cyc.ecy @P1=5 @P2=P1*3]\nM30\n", {"cyc.ecy": cycle})
    assert run.axes == [{"X": 5.0, "Y": 6.0}, {"Z": 2.0}, {"X": 6.0}]


@pytest.mark.req("N-02")
def test_cycle_parameters_over_several_lines_and_local_cycles():
    text = "%L CYC\nX[@P1 + @P50]\nM17\n%MAIN\nLL CYCLE [NAME = CYC \\\n   @P1 = 10 \\\n   @P50 = 2]\nM30\n"
    assert interpret(text).values() == [12.0]


@pytest.mark.req("N-02")
def test_cycle_parameters_outside_a_cycle_are_the_kernels_21382():
    assert error("@P1 = 10\nM30\n").alarm == 21382
    assert error("X[@P1]\nM30\n").alarm == 21382


@pytest.mark.req("N-02")
def test_a_cycle_parameter_not_given_is_an_alarm_naming_it():
    err = error("L CYCLE [NAME=c.ecy @P1=1]\nM30\n", {"c.ecy": "X[@P2]\nM17\n"})
    assert err.alarm == 914003
    assert "@P2" in err.message


@pytest.mark.req("N-02")
def test_modal_cycle_calls_are_refused_by_name():
    err = error("L CYCLE [NAME=c.ecy MODAL_MOVE @P1=1]\nM30\n", {"c.ecy": "M17\n"})
    assert err.alarm == 910110
    assert "MODAL_MOVE" in err.message


@pytest.mark.req("N-02")
def test_call_depth_as_the_kernel_allows():
    files = {f"s{k}.nc": f"L s{k + 1}.nc\nM17\n" for k in range(MAX_CALL_DEPTH - 2)}
    files[f"s{MAX_CALL_DEPTH - 2}.nc"] = "X1\nM17\n"
    assert interpret("L s0.nc\nM30\n", files).values() == [1.0]


# --- expressions (N-03) ----------------------------------------------------------------------------------


@pytest.mark.req("N-03")
@pytest.mark.parametrize(
    ("expr", "value"),
    [
        ("2 + 3 * 4", 14.0),
        ("[2 + 3] * 4", 20.0),
        ("2 ** 3 ** 2", 512.0),
        ("-2 ** 2", -4.0),
        ("11 MOD 3", 2.0),
        ("7 / 2", 3.5),
        ("1 + 2 == 3", 1.0),
        ("1 < 2 AND 2 < 1", 0.0),
        ("1 < 2 OR 2 < 1", 1.0),
        ("1 < 2 && 2 < 3", 1.0),
        ("0 || 1", 1.0),
        ("1 XOR 1", 0.0),
        ("6 & 3", 2.0),
        ("6 | 3", 7.0),
        ("6 ^ 3", 5.0),
        ("INV[0]", -1.0),
        ("NOT[0]", 1.0),
        ("1 != 2", 1.0),
        ("2 >= 2", 1.0),
        ("2 <= 1", 0.0),
        ("TRUE + TRUE", 2.0),
        ("FALSE", 0.0),
        ("ABS[-3]", 3.0),
        ("SQR[3]", 9.0),
        ("SQRT[16]", 4.0),
        ("SIN[30]", 0.5),
        ("COS[60]", 0.5),
        ("TAN[45]", 1.0),
        ("COT[45]", 1.0),
        ("ASIN[0.5]", 30.0),
        ("ACOS[0.5]", 60.0),
        ("ATAN[1]", 45.0),
        ("ATAN2[1, 1]", 45.0),
        ("ACOT[1]", 45.0),
        ("INT[-2.7]", -2.0),
        ("FRACT[2.75]", 0.75),
        ("ROUND[2.5]", 3.0),
        ("ROUND[-2.5]", -3.0),
        ("FLOOR[-2.5]", -3.0),
        ("CEIL[2.1]", 3.0),
        ("EXP[0]", 1.0),
        ("LN[1]", 0.0),
        ("DEXP[2]", 100.0),
        ("LOG[1000]", 3.0),
        ("PI", 3.141592653589793),
        ("SIN [30]", 0.5),
    ],
)
def test_operators_precedence_and_functions(expr, value):
    run = interpret(f"P1 = {expr}\nX[P1]\nM30\n")
    assert run.error is None, run.error
    assert run.values() == [pytest.approx(value, rel=1e-12, abs=1e-12)]


@pytest.mark.req("N-03")
def test_expressions_wherever_a_value_goes():
    run = interpret(
        "P1 = 3 P2 = 30\nN10 G[P1 - 2] X P1*SIN[P2] Y[P1 * 2] F[P2 * 100] S[P1] M[P1] H P1\nM30\n"
    )
    (block, _) = run.blocks
    assert block.g_codes == (1,)
    assert dict(block.axes) == {"X": pytest.approx(1.5), "Y": 6.0}
    assert block.feed == 3000.0
    assert block.m_codes == (3,)
    assert block.extra == {"S": 3.0, "H": 3.0}


@pytest.mark.req("N-03")
def test_axis_values_from_parameters_without_brackets():
    """The manual's "Programming of coordinates by parameters": XP1*SIN[P2*30]."""
    run = interpret("P1 = 10 P2 = 1\nN10 XP1*SIN[P2*30] YV.P.A\nM30\n".replace("YV.P.A", "YP1"))
    assert run.axes == [{"X": pytest.approx(5.0), "Y": 10.0}]


@pytest.mark.req("N-03")
def test_m_and_h_functions_with_values_and_g_functions_with_values():
    run = interpret("N10 M200=40 H5=-345 G231=50 G131=80\nN20 M52=-P1\nM30\n".replace("-P1", "-1"))
    first = run.blocks[0]
    assert first.m_codes == (200,)
    assert set(first.g_codes) == {231, 131}
    assert first.extra["G231"] == 50.0
    assert first.extra["G131"] == 80.0


@pytest.mark.req("N-03")
@pytest.mark.parametrize(
    ("program", "alarm", "words"),
    [
        ("X[1/0]", 914001, "division by zero"),
        ("P1 = 0\nX[5 MOD P1]", 914001, "MOD 0"),
        ("X[SQRT[-1]]", 914002, "SQRT"),
        ("X[LN[0]]", 914002, "LN"),
        ("X[ASIN[2]]", 914002, "ASIN"),
        ("X[[1 + 2]", 914000, "']' missing"),
        ("X[1 + 2]]", 910100, "unexpected"),
        ("X[FOO + 1]", 914000, "FOO"),
        ("X[SIN[1, 2]]", 914000, "SIN takes 1"),
        ('P1 = "a" + 1', 914006, "string"),
        ("X[P1 = 2]", 914000, "=="),
        ("X[" + "[" * 70 + "1" + "]" * 70 + "]", 914020, "nested"),
        ("X[" + "+".join(["1"] * 3000) + "]", 914020, "operands"),
        ('#MSG ["' + "a" * 300 + '"]', 914020, "at most"),
    ],
)
def test_expression_errors_name_what_is_wrong(program, alarm, words):
    err = error(program + "\nM30\n")
    assert err.alarm == alarm, err
    assert words in err.message
    assert err.alarm in ALARMS


@pytest.mark.req("N-03")
def test_strings_compare_and_concatenate():
    text = '#VAR\nV.P.S : STRING[10] = "ab"\n#ENDVAR\n$IF V.P.S + "c" == "abc"\nX1\n$ENDIF\nM30\n'
    assert interpret(text).values() == [1.0]


# --- variables (N-04) ------------------------------------------------------------------------------------


@pytest.mark.req("N-04")
def test_p_parameters_are_created_by_their_first_write():
    run = interpret("N110 P1 = 20  P2 = 40\nX[P1 + P2]\nM30\n")
    assert run.values() == [60.0]


@pytest.mark.req("N-04")
def test_a_p_parameter_read_before_written_is_an_alarm_naming_it():
    err = error("X[P7 + 1]\nM30\n")
    assert err.alarm == 914007
    assert "P7" in err.message


@pytest.mark.req("N-04")
def test_p_parameter_numbers_are_bounded():
    assert error("P1000 = 1\nM30\n").alarm == 914005
    assert error("P1 = 1.5\nP[P1] = 1\nM30\n").alarm == 914005


@pytest.mark.req("N-04")
def test_indirect_parameters_and_parameter_arrays():
    run = interpret("P1 = 20\nPP1 = 50\nX[P20]\nP100[3] = 7\nY[P100[3]]\nP[P1 + 1] = 2\nZ[P21]\nM30\n")
    assert run.axes == [{"X": 50.0}, {"Y": 7.0}, {"Z": 2.0}]


@pytest.mark.req("N-04")
def test_var_declarations_with_types_arrays_and_initial_values():
    text = """\
#VAR
  V.P.VAR_1                           ;REAL64, 0.0
  V.P.VAR_2 : UNS32 = 200             ;UNS32, 200
  V.P.VAR_3 : REAL64 = 11.34
  V.P.VAR_4 : STRING[20] = "END_OK"
  V.P.VAR_5 = 20
  V.P.ARRAY_1[3][6] = [10,11,12,13,14,15, \\
  20,21,22,23,24,25, \\
  30,31,32,33,34,35 ]
  V.L.FLAG : BOOLEAN
#ENDVAR
X[V.P.VAR_1 + V.P.VAR_2] Y[V.P.VAR_3] Z[V.P.ARRAY_1[2][5]]
X[V.P.VAR_5 + V.L.FLAG]
V.P.VAR_2 = 7.9
Y[V.P.VAR_2]
M30
"""
    run = interpret(text)
    assert run.error is None, run.error
    assert run.axes == [{"X": 200.0, "Y": 11.34, "Z": 35.0}, {"X": 20.0}, {"Y": 7.0}]


@pytest.mark.req("N-04")
@pytest.mark.parametrize(
    ("program", "alarm", "words"),
    [
        ("V.P.NOPE[2] = 1", 914003, "V.P.NOPE is not declared"),
        ("X[V.L.NOPE]", 914003, "V.L.NOPE"),
        ("#VAR\nV.P.A : UNS08\n#ENDVAR\nV.P.A = 256", 914002, "0 .. 255"),
        ("#VAR\nV.P.A : UNS08\n#ENDVAR\nV.P.A = -1", 914002, "UNS08"),
        ('#VAR\nV.P.S : STRING[2]\n#ENDVAR\nV.P.S = "abc"', 21462, "at most 2"),
        ("#VAR\nV.P.A[3]\n#ENDVAR\nX[V.P.A[3]]", 914005, "allowed 0 to 2"),
        ("#VAR\nV.P.A[3]\n#ENDVAR\nX[V.P.A]", 914005, "index"),
        ("#VAR\nV.P.A\nV.P.A\n#ENDVAR", 914008, "twice"),
        ("#VAR\nV.P.A : FOO\n#ENDVAR", 914008, "unknown type"),
        ("#VAR\nV.P.A[2] = [1, 2, 3]\n#ENDVAR", 914008, "3 initial values"),
        ("#VAR\nV.P.A", 914008, "#VAR without #ENDVAR"),
        ("#ENDVAR", 914008, "#ENDVAR without #VAR"),
        ("V.A.ABS.X = 5", 914004, "read-only"),
        ("X[V.A.FOO.X]", 910110, "V.A.FOO.X is not simulated"),
        ("X[V.G.NOPE]", 910110, "V.G.NOPE is not simulated"),
        ("X[V.TOOL.X]", 910110, "V.TOOL."),
    ],
)
def test_variable_errors(program, alarm, words):
    err = error(program + "\nM30\n")
    assert err.alarm == alarm, err
    assert words in err.message


@pytest.mark.req("N-04")
def test_a_write_creates_an_undeclared_scalar_variable_a_read_does_not():
    """As the kernel's own example of ID 21382 does: ``N25 V.L.VAR1=10`` without #VAR."""
    assert interpret("V.L.VAR1 = 10\nX[V.L.VAR1]\nM30\n").values() == [10.0]
    assert error("X[V.L.NEVER]\nM30\n").alarm == 914003


@pytest.mark.req("N-04")
def test_v_l_is_local_to_its_level_and_visible_below_it_v_p_everywhere():
    text = """\
%L SUB
#VAR
V.L.A = 2
#ENDVAR
Y[V.L.A + V.L.B]
M17
%MAIN
#VAR
V.L.A = 1
V.L.B = 10
V.P.G = 5
#ENDVAR
LL SUB
X[V.L.A + V.P.G]
M30
"""
    run = interpret(text)
    assert run.axes == [{"Y": 12.0}, {"X": 6.0}]


@pytest.mark.req("N-04")
def test_v_s_lives_across_programs_and_resets_v_p_and_p_do_not():
    host = FakeHost()
    it = Interpreter(Compiler(("X", "Y", "Z"), ("X", "Y", "Z")), host, budget=None)
    interpret("#VAR\nV.S.KEEP = 5\nV.P.GONE = 1\n#ENDVAR\nP1 = 3\nM30\n", interpreter=it, host=host)
    it.reset()
    assert interpret("X[V.S.KEEP]\nM30\n", interpreter=it, host=host).values() == [5.0]
    assert interpret("X[V.P.GONE]\nM30\n", interpreter=it, host=host).alarm == 914003
    assert interpret("X[P1]\nM30\n", interpreter=it, host=host).alarm == 914007
    declared = interpret(
        "$IF EXIST[V.S.KEEP] == TRUE\nX1\n$ELSE\n#VAR\nV.S.KEEP = 2\n#ENDVAR\n$ENDIF\nM30\n",
        interpreter=it,
        host=host,
    )
    assert declared.values() == [1.0]


@pytest.mark.req("N-04")
def test_system_variables_of_the_axes_and_the_channel():
    host = FakeHost()
    host.position["X"] = 12.5
    run = interpret("X[V.A.ABS.X + 1] Y[V.A.ABS[0]] Z[V.A.+SWE.X]\nM30\n", host=host)
    assert run.axes == [{"X": 13.5, "Y": 12.5, "Z": 500.0}]


# --- V.E. variables (N-05) -------------------------------------------------------------------------------


@pytest.mark.req("N-05")
def test_external_variables_are_read_and_written_through_the_store():
    host = FakeHost(external=[real("COUNT"), real("TABLE", dims=(3,))])
    host.external.write("TABLE", None, 4.5, [2])
    run = interpret("V.E.COUNT = V.E.COUNT + 1\nX[V.E.COUNT] Y[V.E.TABLE[2]]\nM30\n", host=host)
    assert run.axes == [{"X": 1.0, "Y": 4.5}]
    assert host.external.read("COUNT", 1) == 1.0


@pytest.mark.req("N-05", "N-08")
def test_an_undeclared_external_variable_is_named_not_taken_for_an_axis():
    err = error("V.E.X1 = 5\nM30\n")
    assert err.alarm == 914003
    assert "V.E.X1" in err.message
    assert "axis" not in err.message


@pytest.mark.req("N-05")
def test_a_synchronous_external_variable_waits_for_the_path_and_is_written_at_path_time():
    host = FakeHost(external=[real("SYNC", synchronous=True)])
    run = interpret("X10\nP1 = V.E.SYNC\nV.E.SYNC = 3\nX20\nM30\n", host=host)
    kinds = [type(o).__name__ for o in run.outputs]
    assert kinds == ["Block", "FlushWait", "SyncAction", "Block", "Block"]
    assert host.external.read("SYNC", 1) == 3.0


# --- control flow (N-06) ---------------------------------------------------------------------------------


@pytest.mark.req("N-06")
@pytest.mark.parametrize(("p1", "x"), [(1, 10.0), (2, 20.0), (3, 30.0)])
def test_if_elseif_else(p1, x):
    text = f"P1 = {p1}\n$IF P1 == 1\nX10\n$ELSEIF P1 == 2\nX20\n$ELSE\nX30\n$ENDIF\nM30\n"
    assert interpret(text).values() == [x]


@pytest.mark.req("N-06")
def test_nested_ifs_skip_whole_blocks():
    text = "P1 = 0\n$IF P1\n$IF 1\nX1\n$ELSE\nX2\n$ENDIF\nX3\n$ELSE\nX4\n$ENDIF\nM30\n"
    assert interpret(text).values() == [4.0]


@pytest.mark.req("N-06")
def test_while_do_repeat_and_for_loops():
    text = """\
P1 = 0
$WHILE P1 < 3
  P1 = P1 + 1
  X[P1]
$ENDWHILE
$DO
  P1 = P1 - 1
  Y[P1]
$ENDDO P1 > 1
$REPEAT
  P1 = P1 + 10
$UNTIL P1 > 25
Z[P1]
$FOR P2 = 10, 0, -5
  X[P2]
$ENDFOR
$FOR V.P.I = 1, 2
  Y[V.P.I * 100]
$ENDFOR
M30
"""
    run = interpret(text.replace("$FOR V.P.I", "#VAR\nV.P.I\n#ENDVAR\n$FOR V.P.I"))
    assert run.error is None, run.error
    assert run.values("X") == [1.0, 2.0, 3.0, 10.0, 5.0, 0.0]
    assert run.values("Y") == [2.0, 1.0, 100.0, 200.0]
    assert run.values("Z") == [31.0]


@pytest.mark.req("N-06")
def test_a_false_loop_runs_its_body_never_and_for_runs_its_end_inclusive():
    assert interpret("$WHILE 0\nX1\n$ENDWHILE\nX2\nM30\n").values() == [2.0]
    assert interpret("$FOR P1 = 5, 1\nX1\n$ENDFOR\nX2\nM30\n").values() == [2.0]
    assert interpret("$FOR P1 = 1, 3, 1\nX[P1]\n$ENDFOR\nM30\n").values() == [1.0, 2.0, 3.0]


@pytest.mark.req("N-06")
def test_for_with_step_zero_is_refused():
    assert error("$FOR P1 = 1, 3, 0\n$ENDFOR\nM30\n").alarm == 914021


@pytest.mark.req("N-06")
@pytest.mark.parametrize(("value", "xs"), [(1, [1.0]), (2, [2.0, 3.0]), (5, [3.0]), (7, [7.0])])
def test_switch_case_default_break_and_fall_through(value, xs):
    text = f"""\
P1 = {value}
$SWITCH P1
$CASE 1
  X1
  $BREAK
$DEFAULT
  X3
  $BREAK
$CASE 2
  X2
$CASE 7
  $IF P1 == 7
    X7
    $BREAK
  $ENDIF
  X3
$ENDSWITCH
M30
"""
    assert interpret(text).values() == xs


@pytest.mark.req("N-06")
def test_break_and_continue_in_nested_loops():
    text = """\
P1 = 0
$WHILE P1 < 10
  P1 = P1 + 1
  $IF P1 == 2
    $CONTINUE
  $ENDIF
  $IF P1 == 4
    $BREAK
  $ENDIF
  $FOR P2 = 1, 3
    $IF P2 == 2
      $BREAK
    $ENDIF
    X[P1 * 10 + P2]
  $ENDFOR
$ENDWHILE
Y[P1]
M30
"""
    run = interpret(text)
    assert run.values() == [11.0, 31.0]
    assert run.values("Y") == [4.0]


@pytest.mark.req("N-06")
def test_goto_forward_backward_and_string_labels():
    text = """\
P1 = 0
N10: X[P1]
P1 = P1 + 1
$IF P1 < 3 $GOTO N10
$GOTO [end]
X99
[end]
N20 $WHILE 1
  $GOTO [out]
$ENDWHILE
[out]
M30
"""
    assert interpret(text).values() == [0.0, 1.0, 2.0]


@pytest.mark.req("N-06", "N-08")
@pytest.mark.parametrize(
    ("program", "alarm"),
    [
        ("$GOTO N99", 914013),
        ("N10 X1\n$GOTO N10", None),  # N10 without ':' is no jump target
        ("$GOTO X", 20839),
        ("$GOTO [a] X1", 20839),
    ],
)
def test_goto_errors(program, alarm):
    err = error(program + "\nM30\n")
    assert err.alarm == (alarm or 914013)


@pytest.mark.req("N-06")
def test_conditional_interpretation():
    text = "P1 = 1\n#IF P1 == 2\nX1\n#ELSE\nX2\n#ENDIF\n#IF P1 == 1\nY1\n#ENDIF\nM30\n"
    run = interpret(text)
    assert run.axes == [{"X": 2.0}, {"Y": 1.0}]
    assert error("N10 #IF 1\n#ENDIF\nM30\n").alarm == 20593
    assert error("#ENDIF\nM30\n").alarm == 914017


@pytest.mark.req("N-06", "N-08")
@pytest.mark.parametrize(
    ("program", "alarm"),
    [
        ("N10 $IF 1 X100\n$ENDIF", 20212),
        ("$ELSE", 20214),
        ("$IF 0\n$ELSE X1\n$ENDIF", 20215),
        ("$ELSEIF 1", 20216),
        ("$IF 0\n$ELSEIF 1 X1\n$ENDIF", 20217),
        ("$ENDIF", 20218),
        ("$IF 1\n$ENDIF X1", 20219),
        ("$CASE 1", 20221),
        ("$DEFAULT", 20223),
        ("$SWITCH 1\n$DEFAULT X1\n$ENDSWITCH", 20224),
        ("$ENDSWITCH", 20225),
        ("$ENDFOR", 20232),
        ("$WHILE 1 X1\n$ENDWHILE", 20235),
        ("$ENDWHILE", 20237),
        ("$WHILE 0\n$ENDWHILE X1", 20238),
        ("$DO X1\n$ENDDO 0", 20239),
        ("$DO\n$ENDDO 0 X1", 20241),
        ("$BREAK", 20243),
        ("$CONTINUE", 20244),
        ("$SWITCH 1\n$CASE 1\n$CONTINUE\n$ENDSWITCH", 20244),
        ("$ENDDO 1", 914017),
        ("$UNTIL 1", 914017),
        ("$IF\n$ENDIF", 914015),
        ("$FOO", 914015),
        ("$WHILE 1\n$ENDIF", 20218),
        ("X1 $IF 1", 914015),
    ],
)
def test_control_block_errors_are_the_kernels_ids(program, alarm):
    err = error(program + "\nM30\n")
    assert err.alarm == alarm, err
    assert ALARMS[alarm].severity == "error"


@pytest.mark.req("N-06")
def test_open_control_blocks_at_program_end():
    run = interpret("P1 = 1\n$IF P1 == 1\nY100\nM30\n")
    assert run.warnings == [20375]
    assert run.values("Y") == [100.0]
    assert error("P1 = 0\n$IF P1 == 1\nY100\nM30\n").alarm == 21501
    assert error("LL S\nM30\n%L S\n$IF 0\nX1\nM17\n").alarm == 21500
    assert error("L s.nc\nM30\n", {"s.nc": "$IF 0\nX1\nM29\n"}).alarm == 21502


@pytest.mark.req("N-06")
def test_nesting_and_iterations_are_bounded():
    deep = "$IF 1\n" * 70 + "X1\n" + "$ENDIF\n" * 70 + "M30\n"
    assert error(deep).alarm == 914014


# --- messages, files, flush (N-07) -----------------------------------------------------------------------


@pytest.mark.req("N-07")
def test_msg_with_format_and_values():
    run = interpret(
        'P1 = 20\n#MSG ["RED,%d,BOLD", P1]\n#MSG HMI ["x=%.3f %s %5.1f%%", 1.23456, "ok", 2]\nM30\n'
    )
    assert run.messages == ["RED,20,BOLD", "x=1.235 ok   2.0%"]


@pytest.mark.req("N-07")
@pytest.mark.parametrize(
    ("program", "alarm", "words"),
    [
        ('#MSG ["%d %d", 1]', 20721, "more formats than values"),  # the kernel's IDs where it has one
        ('#MSG ["%d", 1, 2]', 20721, "2 values for 1"),
        ('#MSG ["%q", 1]', 21232, "unknown format"),
        ('#MSG ["abc %", 1]', 21232, "incomplete format"),
        ('#MSG ["%d", "a"]', 914031, "needs a number"),
        ("#MSG [1]", 914031, "a string in quotes"),
    ],
)
def test_msg_format_errors(program, alarm, words):
    err = error(program + "\nM30\n")
    assert err.alarm == alarm
    assert words in err.message


@pytest.mark.req("N-07", "N-08")
@pytest.mark.parametrize(
    ("fmt", "values", "words"),
    [
        ("%.300000000f", "1.5", "asks for 300000000 characters"),  # issue 36, finding 1: 300 MB in the cycle
        ("%.999999999f", "1.5", "asks for 999999999 characters"),
        ("%0300000000d", "1", "asks for 300000000 characters"),
        ("%256s", '"a"', "asks for 256 characters"),
        ("%.256e", "1", "asks for 256 characters"),
        ("%200d%200d", "1, 2", "grows beyond 255"),
        ("%f", "EXP[709]", "grows beyond 255"),  # 308 digits before the point
    ],
)
def test_msg_widths_and_precisions_are_bounded_before_the_text_is_built(fmt, values, words):
    """A width, a precision that fixes the digits, or the text beyond 255 characters: the kernel's 21870
    ("String exceeds the maximum length"), refused before anything that large is made."""
    err = error(f'N10 #MSG ["{fmt}", {values}]\nM30\n')
    assert err.alarm == 21870, err
    assert words in err.message
    assert err.block == "N10"


@pytest.mark.req("N-07")
def test_msg_precisions_that_only_cut_and_the_longest_message_pass():
    run = interpret('#MSG ["%.999999999g|%.999999999s|%255d", 1.5, "abc", 7]\nM30\n')
    assert run.error is not None  # 1.5|abc| and 255 characters: 263
    assert run.error.alarm == 21870
    run = interpret('#MSG ["%.999999999g|%.999999999s|%.2f", 1.5, "abc", 7]\nM30\n')
    assert run.host.messages[0][0] == "1.5|abc|7.00"
    run = interpret('#MSG ["%255d", 7]\nM30\n')
    assert run.host.messages[0][0] == " " * 254 + "7"


@pytest.mark.req("N-07")
def test_msg_save_writes_to_the_file_named_by_file_name():
    run = interpret('#MSG SAVE ["one"]\n#FILE NAME [MSG="prog_flow.txt"]\n#MSG SAVE ["two %d", 2]\nM30\n')
    assert [(m[0], m[1], m[2]) for m in run.host.messages] == [
        ("one", True, "message.txt"),
        ("two 2", True, "prog_flow.txt"),
    ]


@pytest.mark.req("N-07")
def test_msg_syn_waits_for_the_path_and_plain_msg_does_not():
    run = interpret('X10\n#MSG SYN ["at X10"]\n#MSG ["decoded"]\nX20\nM30\n')
    kinds = [type(o).__name__ for o in run.outputs]
    assert kinds == ["Block", "SyncAction", "Block", "Block"]
    assert run.messages == ["at X10", "decoded"]  # the action ran when handed out here


@pytest.mark.req("N-07")
def test_flush_stops_the_path_flush_wait_waits_flush_continue_neither():
    run = interpret("X1\n#FLUSH\n#FLUSH CONTINUE\n#FLUSH WAIT\nX2\nM30\n")
    assert [type(o) for o in run.outputs[1:3]] == [FlushStop, FlushWait]


# --- not simulated: refused by name (N-08) ---------------------------------------------------------------


@pytest.mark.req("N-08")
@pytest.mark.parametrize(
    ("program", "alarm", "words"),
    [
        ("#CS MODE ON", 910110, "#CS"),
        ("#CS SELECT [A]", 910110, "#CS"),
        ("#TLAX [Z+]", 910110, "#TLAX"),
        ('"STRING1" = "5"', 910110, "macros"),
        ("#TIMER", 910110, "#TIMER"),
        ("#KIN TCP DEF [1]", 910110, "#KIN"),  # #KIN ID is simulated (issue 35), other #KIN forms not
        ("#TLC ON", 910110, "#TLC"),
        ("#SET SLOPE PROFIL[1]", 910110, "#SET"),
        ("#FILE DELETE", 910110, "#FILE"),
        ("#FOO", 910109, "#FOO"),
        ("#ANG [5]", 910110, "#ANG"),
        ("G77 X1", 910102, "G77"),
        ('#MSG INFO ["x"]', 910110, "INFO"),
        ("X[V.TLM.X]", 910110, "V.TLM."),
    ],
)
def test_constructs_not_simulated_are_refused_by_name(program, alarm, words):
    err = error(program + "\nM30\n")
    assert err.alarm == alarm, err
    assert words in err.message
    if alarm == 910110:
        assert "docs/nc-language.md" in err.message


@pytest.mark.req("N-08")
@pytest.mark.parametrize(
    ("program", "check"),
    [
        ("N20 P1 = 0\nX[P1]", lambda run: run.values() == [0.0]),
        ("M110=0", lambda run: run.blocks[0].m_codes == (110,)),
        ("N10 G01 X10 F100 (a (nested) b)", lambda run: run.values() == [10.0]),
    ],
)
def test_the_issues_misleading_messages_are_gone(program, check):
    run = interpret(program + "\nM30\n")
    assert run.error is None, run.error
    assert check(run)


@pytest.mark.req("N-08")
def test_a_refused_construct_in_a_skipped_branch_does_not_stop_the_program():
    assert interpret("$IF 0\n#SLOPE [TYPE=STEP]\nG41\n$ENDIF\nX1\nM30\n").values() == [1.0]


# --- the per-cycle budget (issue 20, "Bad input") --------------------------------------------------------


def test_the_interpreter_pauses_when_its_budget_for_the_cycle_is_spent():
    host = FakeHost()
    it = Interpreter(Compiler(("X", "Y", "Z"), ("X", "Y", "Z")), host)
    it.start("P1 = 0\n$WHILE 1\nP1 = P1 + 1\n$ENDWHILE\nM30\n")
    for _ in range(5):
        it.refill()
        before = it.statements
        assert it.next() is PAUSE
        assert it.statements - before == STATEMENTS_PER_CYCLE


def test_bad_input_is_bounded():
    assert error("X[" + "1" * 70_000 + "]\nM30\n").alarm == 914020


@pytest.mark.req("N-08")
def test_docs_nc_language_names_every_alarm_of_the_language():
    from pathlib import Path

    doc = (Path(__file__).parents[2] / "docs" / "nc-language.md").read_text(encoding="utf-8")
    language = [n for n, a in ALARMS.items() if 20200 <= n < 22000 and "area" not in a.text.lower()]
    language += [n for n in ALARMS if 914000 <= n < 915000]
    assert len(language) > 40
    missing = [n for n in language if str(n) not in doc]
    assert missing == [], f"docs/nc-language.md does not name {missing}"


@pytest.mark.req("N-08")
def test_a_motion_function_not_simulated_says_so_and_where_to_read_more():
    """The refusal names the construct and the page listing what is not simulated, not a project issue."""
    err = error("#TRC [LIMIT_ANGLE=10]\nM30\n")
    assert err.alarm == 910110
    assert err.message.startswith("#TRC: tool radius compensation options (#TRC) is not simulated (N-08)")
    assert "see docs/nc-language.md" in err.message
    assert "issue" not in err.message


@pytest.mark.req("N-08")
def test_an_unknown_hash_command_lists_every_command_simulated() -> None:
    """Issue 37, item 5: 910109's list of the simulated ``#`` commands is the table's (``HASH_COMMANDS``,
    the spellings each simulates), #SLOPE and #CONTOUR MODE among them."""
    from hli_server.engine.nc.language import HASH_COMMANDS

    err = error("#FOO\nM30\n")
    assert err.alarm == 910109
    spellings = [
        f"#{name} {form}".rstrip()
        for name, rule in HASH_COMMANDS.items()
        if rule.alarm == 0 or rule.forms
        for form in rule.forms
    ]
    assert "#SLOPE" in spellings
    assert "#CONTOUR MODE" in spellings
    missing = [spelling for spelling in spellings if spelling not in err.message]
    assert not missing, f"910109 does not name {missing}: {err.message}"
