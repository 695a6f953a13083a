"""Programs of the ISG programming manual through ``hli-server check`` (issue 20): each runs, or stops with
the alarm that names what is not simulated. The files and their pages:
tests/data/manual_programs/README.md."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from hli_server.cli import main

PROGRAMS = Path(__file__).resolve().parents[1] / "data" / "manual_programs"


def check(name: str, *args: str) -> tuple[int, dict[str, Any]]:
    done = CliRunner().invoke(main, ["check", "--format", "json", *args, str(PROGRAMS / name)])
    assert done.exit_code in (0, 1), done.output
    report: dict[str, Any] = json.loads(done.stdout)
    return done.exit_code, report


@pytest.mark.req("N-01", "N-02")
@pytest.mark.parametrize("mode", [(), ("--geometry-only",)])
def test_local_subroutines_206828043_run(mode: tuple[str, ...]) -> None:
    code, report = check("local_subroutines.nc", *mode)
    assert code == 0, report["alarms"]
    assert report["completed"]
    assert (report["final_position"]["X"], report["final_position"]["Y"]) == (10.0, 10.0)


@pytest.mark.req("N-02", "N-08")
@pytest.mark.parametrize("mode", [(), ("--geometry-only",)])
def test_global_subroutines_206834699_run_until_the_absolute_path(mode: tuple[str, ...]) -> None:
    code, report = check("global_subroutines.nc", *mode)
    assert code == 1
    assert report["final_position"]["X"] == 20.0  # L gup_1.nc ran
    [alarm] = [a for a in report["alarms"] if a["severity"] == "error"]
    assert (alarm["id"], alarm["line"], alarm["block"]) == (914010, 6, "N250")
    assert "D:\\prog\\ini_1.nc not found" in alarm["message"]
    assert str(PROGRAMS) in alarm["message"]  # the directory searched
    assert "absolute" in alarm["message"]
    assert "unknown word" not in alarm["message"]


@pytest.mark.req("N-03", "N-06")
@pytest.mark.parametrize("mode", [(), ("--geometry-only",)])
def test_counting_loop_206929163_runs(mode: tuple[str, ...]) -> None:
    code, report = check("counting_loop.nc", *mode)
    assert code == 0, report["alarms"]
    assert report["final_position"]["X"] == pytest.approx(math.sin(math.radians(500)), abs=1e-4)
    assert report["final_position"]["Y"] == pytest.approx(math.cos(math.radians(500)), abs=1e-4)


@pytest.mark.req("N-08")
def test_the_parameterised_subroutine_jump_206781707_is_refused_by_name() -> None:
    code, report = check("subroutine_jump.nc")
    assert code == 1
    [alarm] = [a for a in report["alarms"] if a["severity"] == "error"]
    assert (alarm["id"], alarm["line"], alarm["block"]) == (910110, 3, "N20")
    assert "parameterised jump of M17/M29" in alarm["message"]
    assert "not simulated" in alarm["message"]
    assert report["final_position"]["X"] == 10.0  # the subroutine's motion ran up to it


def test_every_program_of_the_directory_is_tested_and_cited() -> None:
    readme = (PROGRAMS / "README.md").read_text(encoding="utf-8")
    for program in PROGRAMS.glob("*.nc"):
        assert f"`{program.name}`" in readme
    assert readme.count("https://infosys.beckhoff.com/") >= 4


# --- messages that must name the right thing (issue 20's list, and those found since) -----------------------
MESSAGES = [
    # (program line, None: runs; else (alarm, words the message must hold, words it must not))
    ("N20 P1 = 0", None),
    ("M110=0", None),
    ("(a (nested) b)", None),
    ("N10 G01 X1 F100 (a (nested) b) Y2", None),
    ("V.E.X1 = 5", (914003, ["V.E.X1", "not declared"], ["axis"])),
    ("N250 L D:\\prog\\ini_1.nc", (914010, ["D:\\prog\\ini_1.nc", "absolute"], ["unknown word"])),
    ("N10 L", (914015, ["L without a program name"], ["unknown word"])),
    ("N10 LL", (914015, ["LL without a program name"], ["global subroutine"])),
    ("N10 M17 MAIN [ERR]", (910110, ["parameterised jump of M17/M29"], ["unknown name"])),
    ("N10 M29 JUMPS=2 N100", (910110, ["parameterised jump of M17/M29"], [])),
    ("N10 M17 [MAIN [ERR]]", (910110, ["parameterised jump of M17/M29"], ["label"])),
    # issue 33: a block number from a parameter, the spindle- and axis-specific syntax, unknown words
    ("P123 = 4\nNP123 G00 X1", None),
    ("S1[MC_MoveVelocity Velocity=1333 Direction=1]", None),
    ("X[INDP_SYN POS=10 G90 G01 FEED=1000]", (910110, ["X[INDP_SYN", "independent axis"], ["unknown name"])),
    ("N25 HierStehtIrgendwasKomisches", (910100, ["'HIERSTEHTIRGENDWASKOMISCHES'"], ["'IERSTEHT"])),
    ("FOO X2", (910100, ["unknown word 'FOO'"], ["'OO'", "in an expression"])),
    ("G04 Y2", (20014, ["first main axis"], [])),
    ("G805[-45.785, 32.720, 2.620]", (20131, ["G805", "P-CHAN-00187"], ["label"])),
    ("G850[1]", (910102, ["G850[..]", "G800..G839"], ["space", "label"])),
    ("G01 X1 F100 [LBL]", (910100, ["'[LBL]'", "label"], [])),
    ("#FOO BAR", (910109, ["#FOO", "#TOOL PREP", "#RT CYCLE", "#IDENT WR"], ["#FOO BAR"])),
]


@pytest.mark.req("N-01", "N-08")
@pytest.mark.parametrize(("line", "expected"), MESSAGES)
def test_no_message_names_the_wrong_thing(tmp_path: Path, line: str, expected: Any) -> None:
    program = tmp_path / "prog.nc"
    program.write_text(f"%prog\n{line}\nM30\n", encoding="utf-8")
    done = CliRunner().invoke(main, ["check", "--format", "json", str(program)])
    report = json.loads(done.stdout)
    errors = [a for a in report["alarms"] if a["severity"] == "error"]
    if expected is None:
        assert done.exit_code == 0, errors
        return
    alarm, holds, never = expected
    assert done.exit_code == 1
    assert (errors[0]["id"], errors[0]["line"]) == (alarm, 2)
    for words in holds:
        assert words in errors[0]["message"]
    for words in never:
        assert words not in errors[0]["message"]
