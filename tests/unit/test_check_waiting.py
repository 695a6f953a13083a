"""An offline check of a program that waits for the PLC (issue 33; N-13): presets give the PLC's inputs
(``check --set``, ``--set-file``; ``engine/presets.py``, ``codecs/presets.py``), and a program that waits on
inputs nobody can change stops within seconds, naming its loop and the variables (warning 914052, exit 3,
``capped.by == "waiting"``) instead of turning toward the cap of 50,000,000 cycles; the progress bar moves
with the cycles."""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from hli_server.cli import main
from hli_server.codecs.presets import PresetSyntaxError, parse_preset, parse_preset_file, parse_preset_value
from hli_server.commands.check import _Progress, check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.engine.external import ExternalType, ExternalVariables, ExternalVarSpec
from hli_server.engine.presets import PresetError, apply_presets
from hli_server.engine.program_check import WAIT_CYCLES, WAIT_SAMPLE_CYCLES, ProgramCheck

pytestmark = pytest.mark.req("N-13")

WAITS = """\
%ve_wait
N10 G90 G00 X0 Y0 Z0
N20 $WHILE V.E.PLC_READY == 0       ( wait for the PLC
N30 $ENDWHILE
N40 $IF V.E.MODE == 2
N50   G01 X20 F6000
N60 $ELSE
N70   G01 X10 F6000
N80 $ENDIF
N90 M30
"""
"""The README's ve_mode pattern on the demo machine's V.E. variables (PLC_READY, MODE)."""


def full(text: str, **kwargs: Any) -> Any:
    return ProgramCheck(Machine(load_machine(None)), 1, **kwargs).run(text)


# --- stopping a program that waits ----------------------------------------------------------------------
def test_a_program_waiting_on_the_plc_stops_within_seconds_naming_the_variable_and_line() -> None:
    result = full(WAITS)
    assert result.capped == "waiting"
    assert not result.completed
    assert not result.stopped_by_error
    (alarm,) = result.alarms
    assert (alarm.number, alarm.line, alarm.block) == (914052, 3, "N20")
    assert "V.E.PLC_READY" in alarm.message
    assert "$WHILE loop at N20" in alarm.message
    assert "--set V.E.PLC_READY=<value>" in alarm.message
    assert alarm.params["variables"] == ["V.E.PLC_READY"]
    # deterministic: after WAIT_CYCLES of nothing changing, counted from the first look that saw it
    assert WAIT_CYCLES <= result.machine.cycle <= WAIT_CYCLES + 2 * WAIT_SAMPLE_CYCLES + 2
    assert result.elapsed_s < 30  # not the hour toward 50,000,000 cycles


def test_presets_give_the_plcs_values_and_the_program_runs() -> None:
    result = full(WAITS, presets={"V.E.PLC_READY": True, "v.e.mode": 2})
    assert result.completed
    assert result.alarms == []
    assert result.final_position["X"] == 20.0


@pytest.mark.parametrize(
    ("program", "words"),
    [
        # a #FLUSH WAIT in the loop: decoding waits for the path each time, which is at rest
        ("N10 G01 X1 F1000\nN20 $WHILE V.E.MODE <> 3\nN25 #FLUSH WAIT\nN30 $ENDWHILE\nM30\n", ["V.E.MODE"]),
        # a jump back
        ("N10 G01 X1 F1000\nN20: $IF V.E.MODE == 0 $GOTO N20\nX3\nM30\n", ["V.E.MODE", "jump back at N20"]),
        # $DO .. $ENDDO, the condition at its end, two variables
        (
            "N10 G01 X1 F1000\nN20 $DO\nN30 P1 = V.E.MODE\nN40 $ENDDO V.E.PLC_READY == 0\nM30\n",
            ["V.E.MODE, V.E.PLC_READY", "$DO loop at N20"],
        ),
        # waiting in a subroutine's loop
        ("N10 G01 X1 F1000\nN20 L wait.nc\nM30\n", ["V.E.PLC_READY", "of wait.nc"]),
    ],
    ids=["flush-wait", "goto", "do-two-variables", "subroutine"],
)
def test_every_way_of_waiting_is_stopped_and_named(program: str, words: list[str], tmp_path: Path) -> None:
    from hli_server.engine.programs import MemoryLibrary

    machine = Machine(
        load_machine(None),
        programs=MemoryLibrary({"wait.nc": "N5 $WHILE NOT[V.E.PLC_READY]\nN6 $ENDWHILE\nM17\n"}),
    )
    result = ProgramCheck(machine, 1).run(program)
    assert result.capped == "waiting", result.alarms
    (alarm,) = result.alarms
    assert alarm.number == 914052
    for word in words:
        assert word in alarm.message


def test_an_endless_loop_that_reads_nothing_is_stopped_as_not_ending() -> None:
    result = full("N10 G01 X1 F1000\nN20 $WHILE 1\nN30 $ENDWHILE\nM30\n")
    assert result.capped == "waiting"
    (alarm,) = result.alarms
    assert alarm.number == 914052
    assert "does not end" in alarm.message
    assert alarm.params["variables"] == []


@pytest.mark.parametrize(
    "program",
    [
        # a loop that counts: its variable changes every turn (4,200 cycles without motion)
        "N10 G01 X1 F1000\nP1 = 0\n$WHILE P1 < 180000\nP1 = P1 + 1\n$ENDWHILE\nX2\nM30\n",
        # a long dwell: nothing turns
        "N10 G01 X1 F1000\nG04 X12\nX2\nM30\n",
        # a loop that moves
        "N10 G01 X1 F6000\nP1 = 0\n$WHILE P1 < 40\nG91 X1\nX-1\nP1 = P1 + 1\n$ENDWHILE\nG90 X2\nM30\n",
    ],
    ids=["counting", "dwell", "moving"],
)
def test_a_program_that_makes_progress_is_not_stopped(program: str) -> None:
    result = full(program)
    assert result.completed, result.alarms
    assert result.capped is None
    assert result.final_position["X"] == 2.0


def test_the_program_writing_its_own_variable_is_progress() -> None:
    # the loop writes V.E.MODE itself: the value changes, the loop ends
    text = "N10 G01 X1 F1000\nV.E.MODE = 0\n$WHILE V.E.MODE < 150000\n"
    text += "V.E.MODE = V.E.MODE + 1\n$ENDWHILE\nX2\nM30\n"
    assert full(text).completed


def test_the_geometry_checks_cap_names_the_variables_too() -> None:
    result = full(WAITS, geometry_only=True, max_iterations=500)
    assert result.capped == "iterations"
    (alarm,) = result.alarms
    assert alarm.number == 914051
    assert "$WHILE loop at N20 reads V.E.PLC_READY" in alarm.message
    assert alarm.params["variables"] == ["V.E.PLC_READY"]


# --- presets: their text, their values ----------------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "value"),
    [("1", 1), ("-2.5", -2.5), ("1e3", 1000.0), ("TRUE", True), ("false", False), ('"A1 ok"', "A1 ok")],
)
def test_preset_values(text: str, value: object) -> None:
    parsed = parse_preset_value(text)
    assert parsed == value
    assert type(parsed) is type(value)


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("V.E.X", "write V.E.NAME=value"),
        ("V.E.X=", "write V.E.NAME=value"),
        ("PLC_READY=1", "names a V.E. variable"),
        ("V.P.X=1", "names a V.E. variable"),
        ("V.E.X=yes", "is no value"),
        ("V.E.X=1e999", "out of range"),
        ("V.E.A..B=1", "names a V.E. variable"),
        ("V.E.A[x]=1", "names a V.E. variable"),
        ("V.E.A.=1", "names a V.E. variable"),
    ],
)
def test_malformed_presets_say_why(text: str, why: str) -> None:
    with pytest.raises(PresetSyntaxError, match=why):
        parse_preset(text)


def test_a_file_of_presets() -> None:
    text = (
        '# the PLC at the start\nV.E.PLC_READY = TRUE   ; released\n\nv.e.POS[1][2]=2.5\nV.E.TEXT = "a;b#c"\n'
        'V.E.UserInteraction.Message = "Camera at A1"\n'
    )
    assert parse_preset_file(text, "p.txt") == {
        "V.E.PLC_READY": True,
        "v.e.POS[1][2]": 2.5,
        "V.E.TEXT": "a;b#c",
        "V.E.UserInteraction.Message": "Camera at A1",
    }
    with pytest.raises(PresetSyntaxError, match=r"^p.txt:2: "):
        parse_preset_file("V.E.A=1\nV.E.B\n", "p.txt")


def test_presets_are_checked_against_the_declarations_before_anything_is_written() -> None:
    external = ExternalVariables(
        [
            ExternalVarSpec("READY", ExternalType.BOOLEAN),
            ExternalVarSpec("POS", ExternalType.REAL64, (2, 3), channel=1),
            ExternalVarSpec("COUNT", ExternalType.UNS08),
            ExternalVarSpec("NAME", ExternalType.STRING, string_size=21),
            # a structure's leaves (V.E.UserInteraction.Message, V.E.curve[i].point[j].X)
            ExternalVarSpec(
                "UserInteraction.Message",
                ExternalType.STRING,
                string_size=21,
                levels=(("UserInteraction", 0), ("Message", 0)),
            ),
            ExternalVarSpec(
                "curve.point.X", ExternalType.REAL64, (2, 3), levels=(("curve", 1), ("point", 1), ("X", 0))
            ),
        ]
    )
    apply_presets(
        external,
        1,
        {
            "V.E.ready": True,
            "V.E.POS[1][2]": 2.5,
            "V.E.NAME": "teach.nc",
            "V.E.UserInteraction.Message": "OK",
            "V.E.curve[1].point[2].X": 7.5,
            "V.E.POS[0, 1]": -1,
        },
    )
    assert external.read("READY", 1) is True
    assert external.read("POS", 1, [1, 2]) == 2.5
    assert external.read("POS", 1, [0, 1]) == -1.0
    assert external.read("NAME", 1) == "teach.nc"
    assert external.read("UserInteraction.Message", 1) == "OK"
    assert external.read("curve.point.X", 1, [1, 2]) == 7.5
    for presets, why in (
        ({"V.E.NOPE": 1}, "V.E.NOPE is not declared"),
        ({"V.E.UserInteraction.Answer": 1}, "has no element Answer"),
        ({"V.E.POS[2][0]": 1}, "index 1 is 2"),
        ({"V.E.POS": 1}, "takes 2 index"),
        ({"V.E.COUNT": 300}, "outside 0 .. 255"),
        ({"V.E.COUNT": "x"}, "is a string"),
        ({"V.E.NAME": 1}, "is a number"),
        ({"V.E.NAME": "x" * 21}, "at most 20 characters"),
        ({"V.E.COUNT": 1, "V.E.NOPE": 1}, "V.E.NOPE"),
    ):
        with pytest.raises(PresetError, match=why):
            apply_presets(external, 1, presets)
    assert external.read("COUNT", 1) == 0  # the last one refused: nothing of it was written


# --- the command -------------------------------------------------------------------------------------------
def invoke(tmp_path: Path, *args: str) -> Any:
    program = tmp_path / "ve_wait.nc"
    program.write_text(WAITS, encoding="utf-8")
    return CliRunner().invoke(main, ["check", "--format", "json", *args, str(program)])


def test_check_stops_a_waiting_program_with_exit_3_and_says_why(tmp_path: Path) -> None:
    done = invoke(tmp_path)
    assert done.exit_code == 3
    report = json.loads(done.stdout)
    assert report["capped"]["by"] == "waiting"
    assert [a["id"] for a in report["alarms"]] == [914052]
    assert "--set V.E.NAME=VALUE" in done.stderr


def test_check_takes_set_and_set_file_a_later_set_wins(tmp_path: Path) -> None:
    presets = tmp_path / "plc.txt"
    presets.write_text("V.E.PLC_READY = TRUE\nV.E.MODE = 1\n", encoding="utf-8")
    done = invoke(tmp_path, "--set-file", str(presets), "--set", "V.E.MODE=2")
    assert done.exit_code == 0, done.output
    assert json.loads(done.stdout)["final_position"]["X"] == 20.0
    done = invoke(tmp_path, "--set-file", str(presets))
    assert json.loads(done.stdout)["final_position"]["X"] == 10.0


@pytest.mark.parametrize(
    ("args", "why"),
    [
        (["--set", "V.E.PLC_READY"], "write V.E.NAME=value"),
        (["--set", "V.E.NOPE=1"], "V.E.NOPE is not declared"),
        (["--set", "V.E.MODE=TRUE", "--set", 'V.E.PLC_READY="x"'], "is a string"),
    ],
)
def test_a_preset_that_cannot_be_taken_is_a_usage_error(tmp_path: Path, args: list[str], why: str) -> None:
    done = invoke(tmp_path, *args)
    assert done.exit_code == 2
    assert why in done.stderr


TEACH_IN = """\
%teach_in
N10 #MSG ["teach-in file %s", V.E.TEACH_FILE_NAME]
N20 $WHILE V.E.UserInteraction.Answer == 0   ( the operator clicks OK on the HMI
N30 $ENDWHILE
N40 $IF V.E.UserInteraction.Message == "Camera at A1"
N50   G01 X5 F6000
N60 $ENDIF
N70 M30
"""
"""A program that reads a V.E. STRING and a structure's members (tests/data/implicit_calls/machine.toml)."""
STANDIN_MACHINE = Path(__file__).resolve().parents[1] / "data" / "implicit_calls" / "machine.toml"


def test_string_and_structure_presets_through_the_command(tmp_path: Path) -> None:
    program = tmp_path / "teach_in.nc"
    program.write_text(TEACH_IN, encoding="utf-8")
    args = ["check", "--format", "json", "--config", str(STANDIN_MACHINE)]
    presets = [
        "--set",
        'V.E.TEACH_FILE_NAME="abc.dat"',
        "--set",
        'v.e.userinteraction.message = "Camera at A1"',
        "--set",
        "V.E.UserInteraction.Answer=1",
    ]
    done = CliRunner().invoke(main, [*args, *presets, str(program)])
    assert done.exit_code == 0, done.output
    report = json.loads(done.stdout)
    assert [m["text"] for m in report["messages"]] == ["teach-in file abc.dat"]
    assert report["final_position"]["X"] == 5.0
    # without the operator's answer the program waits on the structure's member: stopped, named
    done = CliRunner().invoke(main, [*args, *presets[:4], str(program)])
    assert done.exit_code == 3
    (alarm,) = json.loads(done.stdout)["alarms"]
    assert alarm["id"] == 914052
    assert "waits on V.E.UserInteraction.Answer: its $WHILE loop at N20" in alarm["message"]  # as declared
    assert alarm["params"]["variables"] == ["V.E.UserInteraction.Answer"]
    # a text longer than the STRING holds is refused before the program starts
    done = CliRunner().invoke(main, [*args, "--set", f'V.E.TEACH_FILE_NAME="{"x" * 21}"', str(program)])
    assert done.exit_code == 2
    assert "at most 20 characters" in done.stderr


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_progress_bar_moves_with_cycles_while_a_loop_turns_on_one_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    monkeypatch.setattr(_Progress, "refresh_s", 0.0)
    result = check_program(Machine(load_machine(None)), WAITS, progress=True)
    assert result.capped == "waiting"
    shown = terminal.getvalue()
    assert "cycle 1.00k (1 s machine time)" in shown
    assert "cycle 3.00k (3 s machine time)" in shown
