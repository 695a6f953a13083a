"""The kernel's own example programs, as printed (N-01..N-08).

From the diagnosis pages (TF5200 diagnosis, https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/):
each page's "Wrong" program raises that page's ID here, its "Correct" program runs. From the
programming manual (https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/): the examples
of indirect parameters, coordinates by parameters, self-defined variables, messages, file names, jump
labels and M/H functions with values. ``:`` lines are the documents' elisions (no block). The programs
that run are run through ``hli-server check`` too.
"""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from hli_server.cli import main
from hli_server.commands.check import check_program
from hli_server.engine import Machine
from hli_server.engine.programs import MemoryLibrary
from tests.unit.engine_helpers import mill_config
from tests.unit.nc_helpers import error, interpret

# page ID: (wrong program, correct program or None where the page's correct one is a schematic loop)
DIAGNOSIS: dict[int, tuple[str, str | None]] = {
    20212: (
        "N10 G00 X0 Y0 Z0 P1=0\nN20 $IF P1==1 X100 G01 F1000\nN30 Y200\nN40 $ENDIF\n:\nN1000 M30\n",
        "N10 G00 X0 Y0 Z0 P1=0\nN20 $IF P1==1\nN25 X100 G01 F1000\nN30 Y200\nN40 $ENDIF\n:\nN1000 M30\n",
    ),
    20214: (
        "N10 G00 X0 Y0 Z0\nN20 $ELSE\n:\nN1000 M30\n",
        "N01 P1=0\nN05 $IF P1==1\nN10 G00 X0 Y0 Z0\nN20 $ELSE\nN25 G01 X100 Y0 Z0 F1000\nN30 $ENDIF\n:\n\n"
        "N1000 M30\n",
    ),
    20215: (
        "N10 G00 X0 Y0 Z0 P1=0\nN20 $IF P1\nN30 G01 X100 F100\nN40 $ELSE G01 X200 F500\nN50 $ENDIF\n:\n"
        "N1000 M30\n",
        "N10 G00 X0 Y0 Z0 P1=0\nN20 $IF P1\nN30 G01 X100 F100\nN40 $ELSE\nN45 G01 X200 F500\nN50 $ENDIF\n:\n"
        "\nN1000 M30\n",
    ),
    20216: (
        "N10 G00 X0 Y0 Z0\nN20 $ELSEIF\n:\nN1000 M30\n",
        "N01 P1=0\nN05 $IF P1==1\nN10 G00 X0 Y0 Z0\nN20 $ELSEIF P1==2\nN30 G00 X100 Y0 Z0\nN40 $ENDIF\n:\n\n"
        "N1000 M30\n",
    ),
    20217: (
        "N10 G00 X0 Y0 Z0\nN251 P2=0\nN252 $IF P2\n:\nN253 $ELSEIF P2==100 G01 X200 F500\n:\nN254 $ENDIF\n:\n"
        "N1000 M30\n",
        "N10 G00 X0 Y0 Z0\nN251 P2=0\nN252 $IF P2\n:\nN253 $ELSEIF P2==100\nN254 G01 X200 F500\n:\n"
        "N254 $ENDIF\n:\n",
    ),
    20218: (
        "N10 G00 X0 Y0 Z0 P1=0\nN20 G01 X100 F10000\nN30 $ENDIF\n:\nN1000 M30\n",
        "N10 G00 X0 Y0 Z0 P1=0\nN15 $IF P1==0\nN20 G01 X100 F10000\nN30 $ENDIF\n:\n",
    ),
    20219: (
        "N10 G00 X0 Y0 Z0 P1=0\nN20 $IF P1\nN30 $ENDIF G01 X100 F10000\n:\nN1000 M30\n",
        "N10 G00 X0 Y0 Z0 P1=0\nN20 $IF P1\nN30 $ENDIF\nN40 G01 X100 F10000\n:\n",
    ),
    20221: (
        "N10 G00 X0 Y0 Z0 P1=47\nN20 $CASE P1\n:\nN1000 M30\n",
        "N10 G00 X0 Y0 Z0 P1=47\nN20 $SWITCH P1\nN20 $CASE 1\n:\nN30 $ENDSWITCH\n:\n",
    ),
    20223: ("N10 G00 X0 Y0 Z0\nN20 $DEFAULT\n:\nN1000 M30\n", None),
    20224: (
        "N10 G00 X0 Y0 Z0\nN20 P1=5\nN50 $SWITCH P1\n:\nN62 $DEFAULT G01 X100 F10000\n:\nN65 $ENDSWITCH\n:\n"
        "N1000 M30\n",
        "N10 G00 X0 Y0 Z0\nN20 P1=5\nN50 $SWITCH P1\n:\nN62 $DEFAULT\nN63 G01 X100 F10000\n:\n"
        "N65 $ENDSWITCH\n:\nN1000 M30\n",
    ),
    20225: (
        "N10 G00 X0 Y0 Z0\nN20 P1=5\nN30 $ENDSWITCH\n:\nN1000 M30\n",
        "N10 G00 X0 Y0 Z0\nN20 P1=5\nN30 $SWITCH P1\n:\nN40 $ENDSWITCH\n:\n",
    ),
    20232: (
        "N10 G00 X0 Y0 Z0 P1=1\nN20 $ENDFOR\n:\nN1000 M30\n",
        "N10 G00 X0 Y0 Z0 P1=1\nN15 $FOR P1=100, 200, 300\n:\nN20 $ENDFOR\n:\nN1000 M30\n",
    ),
    20235: (
        "N10 G00 X0 Y0 Z0\nN20 P1=1\nN30 $WHILE P1>0 G01 X100 F1000\n:\nN40 $ENDWHILE\n:\nN1000 M30\n",
        None,
    ),
    20237: ("N10 G00 X0 Y0 Z0 P1=1\nN20 $ENDWHILE\n:\nN1000 M30\n", None),
    20238: (
        "N10 G00 X0 Y0 Z0\nN20 P1=1\nN30 $WHILE P1\n:\nN40 $ENDWHILE G01 X200 F500\n:\nN1000 M30\n",
        None,
    ),
    20239: (
        "N10 G00 X0 Y0 Z0 P1=0\nN20 $DO P1=P1+1\n:\nN50 $ENDDO P1<2\n:\nN1000 M30\n",
        "N10 G00 X0 Y0 Z0 P1=0\nN20 $DO\nN30 P1=P1+1\n:\nN50 $ENDDO P1<2\n:\nN1000 M30\n",
    ),
    20241: (
        "N10 G00 X0 Y0 Z0\nN20 P2=10\nN30 $DO\n:\nN40 $ENDDO P2 >= 10 G01 X100 F1000\n:\nN1000 M30\n",
        None,
    ),
    20243: (
        "N10 G00 X0 Y0 Z0\nN20 $BREAK\n:\nN1000 M30\n",
        "N10 G00 X0 Y0 Z0 P1=1\nN20 $SWITCH P1\nN30 $CASE 2\nN35 G01 X100 F10000\nN40 $BREAK\n:\n"
        "N100 $ENDSWITCH\n:\n\nN1000 M30\n",
    ),
    20244: (
        "N10 G00 X0 Y0 Z0\nN20 $CONTINUE\n:\nN1000 M30\n",
        "N10 G00 X0 Y0 Z0 P1=1\nN20 $DO\nN30 P1=P1+1\nN40 $IF P1 == 2\nN50 $CONTINUE\nN60 $ENDIF\n:\n"
        "N100 $ENDDO P1 < 10\n:\nN1000 M30\n",
    ),
    21501: (
        "% main\nN10 G00 X0 Y0 Z0\nN20 P1=0\nN30 $IF P1 == 1\nN40 Y100\nN100 X100\nN150 M30\n",
        "% main\nN10 G00 X0 Y0 Z0\nN20 P1=0\nN30 $IF P1 == 1\nN40 Y100\nN100 X100\nN105 $ENDIF\nN150 M30\n",
    ),
    21500: (
        "%L sub1\nN10 G00 X0 Y0 Z0\nN20 P1=0\nN30 $IF P1 == 1\nN40 Y100\nN100 X100\nN110 M29\n"
        "%main\nN010 X0 Y0 Z0\nN020 LL sub1\n:\nN1000 M30\n",
        "%L sub1\nN10 G00 X0 Y0 Z0\nN20 P1=0\nN30 $IF P1 == 1\nN40 Y100\nN100 X100\nN105 $ENDIF\nN110 M29\n"
        "% main\nN010 X0 Y0 Z0\nN020 LL sub1\n:\nN1000 M30\n",
    ),
    21502: ("N10 L glob_sub.nc\nN1000 M30\n", None),
    21542: ("N10 G91 X100 L GLOBALUP.NC Y200\nN30 M30\n", "N10 G91 X100 Y200 L GLOBALUP.NC\nN30 M30\n"),
    21382: (
        "%main\nN05 X0 Y0 Z0 G00\nN20 G01 X200 F3000\nN25 @P1=10\nN40 L CYCLE [NAME=dummy1.cyc]\n"
        "N50 G01 Y300 F1000\nN60 G01 Z300 F2000\nN90 M30\n",
        "%main\nN05 X0 Y0 Z0 G00\nN20 G01 X200 F3000\nN25 V.L.VAR1=10\n"
        "N40 L CYCLE [NAME=dummy1.cyc @P1=V.L.VAR1]\n"
        "N50 G01 Y300 F1000\nN60 G01 Z300 F2000\nN90 M30\n",
    ),
}
FILES = {
    "glob_sub.nc": "% glob_sub\nN10 G00 X0 Y0 Z0\nN20 P1=0\nN30 $IF P1 == 1\nN40 Y100\nN100 X100\nN150 M29\n",
    "GLOBALUP.NC": "N10 G90 Z10\nN20 M17\n",
    "dummy1.cyc": "N10 X[@P1]\nN20 M17\n",
}
RUNS_ON_THE_MILL = [(k, v[1]) for k, v in DIAGNOSIS.items() if v[1] is not None]


@pytest.mark.req("N-06", "N-08")
@pytest.mark.parametrize(("alarm", "program"), [(k, v[0]) for k, v in DIAGNOSIS.items()])
def test_each_diagnosis_pages_wrong_program_raises_its_id(alarm, program):
    assert error(program, FILES).alarm == alarm


@pytest.mark.req("N-06")
@pytest.mark.parametrize(("alarm", "program"), RUNS_ON_THE_MILL)
def test_each_diagnosis_pages_correct_program_runs(alarm, program):
    run = interpret(program, FILES)
    assert run.error is None, run.error
    assert run.ended


@pytest.mark.req("N-06")
def test_the_open_control_block_example_of_20375_warns_and_goes_on():
    wrong = (
        "N10 G00 X0 Y0 Z0\nN20 P1=1 P2=2\nN30 $IF P1 == 1\nN40 Y100\nN50 $IF P2==4\nN60 Z200\nN70 $ENDIF\n:\n"
        "N100 X100\n:\nN1000 M30\n"
    )
    correct = wrong.replace("N70 $ENDIF\n", "N70 $ENDIF\nN80 $ENDIF\n")
    run = interpret(wrong)
    assert run.warnings == [20375]
    assert run.values() == [0.0, 100.0]
    assert interpret(correct).warnings == []


@pytest.mark.req("N-06")
@pytest.mark.parametrize(("alarm", "program"), [(k, p) for k, p in RUNS_ON_THE_MILL if k != 21542])
def test_the_correct_programs_pass_check(alarm, program):
    """(21542's correct example moves with G01 and no F word: the kernel's 20008, as printed.)"""
    machine = Machine(mill_config(), programs=MemoryLibrary(FILES))
    result = check_program(machine, program, geometry_only=True)
    assert not result.stopped_by_error, result.alarms


# --- the programming manual's examples -------------------------------------------------------------------


@pytest.mark.req("N-04")
def test_indirect_parameters_206884875():
    text = """\
:
N110 P1 = 20  P2 = 40
N120 PP1 = 50
N130 PP2 = PP1
N140 X[P20] Y[P40]
N150 P120=10
N160 PP120=123.456
N170 PP121=SQRT[2.0]
N180 Z[P10]
N210 $FOR P1 = 10,20,1
N220 P[P1 + 5] = 0.0
N230 $ENDFOR
N240 X[P15 + P25]
M30
"""
    run = interpret(text.replace("N170 PP121=SQRT[2.0]\n", "N165 P121 = 11\nN170 PP121=SQRT[2.0]\n"))
    assert run.error is None, run.error
    assert run.axes == [{"X": 50.0, "Y": 50.0}, {"Z": 123.456}, {"X": 0.0}]


@pytest.mark.req("N-03")
def test_coordinates_by_parameters_206878987():
    assert interpret("P1 = 10 P2 = 1\nXP1*SIN[P2*30]\nM30\n").values() == [pytest.approx(5.0)]
    assert interpret("P1 = 10 P2 = 1\nX P1*SIN [P2*30]\nM30\n").values() == [pytest.approx(5.0)]


@pytest.mark.req("N-04")
def test_self_defined_variables_207966475_207981323_207973899():
    vp = """\
:
#VAR
  V.P.VAR_1                           ;REAL64, 0.0
  V.P.VAR_2 : UNS32 = 200             ;UNS32, 200
  V.P.VAR_3 : REAL64 = 11.34          ;REAL64, 11.34
  V.P.VAR_4 : STRING[20] = "END_OK"   ;STRING, END_OK
  V.P.VAR_5 = 20                      ;REAL64, 20.0
#ENDVAR
; …
XV.P.VAR_5        ;X20.0
:
"""
    vl = """\
:
#VAR
  V.L.LOC_VAR1                    ;REAL64, 0.0
  V.L.LOC_VAR2 : UNS32 = 200      ;UNS32, 200
  V.L.LOC_VAR3 : REAL64 = 11.34   ;REAL64, 11.34
  V.L.LOC_VAR4 : BOOLEAN          ;BOOLEAN, FALSE or 0
  V.L.LOC_VAR5 = 10               ;REAL64, 10.0
#ENDVAR
:
XV.L.LOC_VAR5        ;X10.0
:
"""
    vs = """\
:
#VAR
  V.S.VAR1                      ;REAL64, 0.0
  V.S.VAR2 : UNS32 = 200        ;UNS32, 200
  V.S.VAR3 : REAL64 = 11.34     ;REAL64, 11.34
  V.S.VAR4 : BOOLEAN            ;BOOLEAN, FALSE or 0
  V.S.VAR[5] = [5,10,10,15,20]  ;Array with REAL64 values
#ENDVAR
:
XV.S.VAR[4]        ;X20.0
:
"""
    assert interpret(vp).values() == [20.0]
    assert interpret(vl).values() == [10.0]
    assert interpret(vs).values() == [20.0]


@pytest.mark.req("N-07")
def test_messages_507845131_and_file_names_207504523():
    run = interpret(
        '#MSG HMI ["Text_1"]\n#MSG SYN HMI ["Text_2"]\n#MSG ["Text_3"]\n#MSG SYN ["Text_4"]\n'
        '#MSG SYN_ACK ["Text_5"]\nM30\n'
    )
    assert run.messages == ["Text_1", "Text_2", "Text_3", "Text_4", "Text_5"]
    flow = """\
%example1
N10 #FILENAME[ MSG="prog_flow.txt" ]
N20 $IF V.E.PLC_START_HOME == 1
N30 G74 X1 Y2 Z3
N40 #MSG SAVE["Homing executed"]
N50 $ENDIF
:
Nxx #MSG SAVE["Roughing OK"]
:
Nxx #MSG SAVE["Finishing OK"]
:
N985 V.E.WP_CNTR = V.E.WP_CNTR+1
N990 #MSG SAVE["Workpiece No. %d OK", V.E.WP_CNTR]
M30
"""
    from tests.unit.nc_helpers import FakeHost, real

    host = FakeHost(external=[real("PLC_START_HOME"), real("WP_CNTR")])
    run = interpret(flow.replace("Nxx ", ""), host=host)
    assert run.error is None, run.error
    assert [(m[0], m[2]) for m in host.messages] == [
        ("Roughing OK", "prog_flow.txt"),
        ("Finishing OK", "prog_flow.txt"),
        ("Workpiece No. 1 OK", "prog_flow.txt"),
    ]


@pytest.mark.req("N-06")
def test_jump_labels_of_the_streaming_example_222579211():
    text = """\
N01 G01 X0 Y0 Z0 F1000
N10 G01 X20
N20 $GOTO N40
N30 G01 Z40
N40: G01 X40
N50 $GOTO N80
N60 G01 Y20
N70 G01 Y40
N80: G01 X-20
N90 G01 X-40
:
M30
"""
    run = interpret(text)
    assert run.values() == [0.0, 20.0, 40.0, -20.0, -40.0]
    assert run.values("Y") == [0.0]


@pytest.mark.req("N-03")
def test_m_and_h_functions_with_additional_values_15556839051():
    text = """\
%m_h_add_fct
(M functions with additional value)
N10 M52=-345
N20 M12=123
N30 M10=321
N35 P1 = 567 P2 = 345
N70 M63=-789 M52=-P2 M54=567
(H functions with additional value)
N110 H5=-345
N120 H6=123
N135 P3 = 567 P4 = -345
N170 H8=-789 H5=P4 H7=567
M30
"""
    run = interpret(text)
    assert run.error is None, run.error
    assert [b.m_codes for b in run.blocks] == [(52,), (12,), (10,), (63, 52, 54), (), (), (), (30,)]
    # the axis-specific form X[M54=..] (issue 33): an M function of the axis, accepted as every M function
    axis_specific = interpret("N35 P1 = 567\nN40 X[M54=P1] Y1\nM30\n")
    assert axis_specific.error is None
    assert axis_specific.values("Y") == [1.0]


@pytest.mark.req("N-06")
def test_conditional_interpretation_example_of_20593():
    text = "P1 = 1\n#IF P1 == TRUE\nN10 X100\n#ELSE\nN20 X200 Y200 Z100\n#ENDIF\n:\nN1000 M30\n"
    assert interpret(text).axes == [{"X": 100.0}]


@pytest.mark.req("N-01", "N-06")
def test_the_examples_run_through_hli_server_check(tmp_path):
    """The manual's examples as a user runs them: ``hli-server check`` on the demo machine."""
    program = tmp_path / "example.nc"
    program.write_text(DIAGNOSIS[20244][1] or "", encoding="utf-8")
    result = CliRunner().invoke(main, ["check", str(program)])
    assert result.exit_code == 0, result.output
    program.write_text(DIAGNOSIS[20244][0], encoding="utf-8")
    result = CliRunner().invoke(main, ["check", str(program), "--geometry-only"])
    assert result.exit_code == 1
    assert "20244" in result.output
