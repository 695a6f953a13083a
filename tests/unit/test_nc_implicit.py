"""Implicit subprogram calls G80..G89 and G800..G839 (N-11; PM 206278923 "Implicit subroutine calls";
P-CHAN-00160..00169, P-CHAN-00187; ``hli_server/engine/nc/implicit.py``): which program a G code calls,
its values as ``@P``, ``#FILE NAME [G8xx=..]``, the kernel's 20131 without an assignment - through the
interpreter alone, then as a user meets them: a machine file (TOML or the kernel's channel list) and
``hli-server check`` in both modes."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from hli_server.cli import main
from hli_server.configuration import ConfigError, load_machine, parse_parameter_list
from hli_server.engine.nc import Compiler, Interpreter
from tests.unit.nc_helpers import FakeHost, Run, interpret

pytestmark = pytest.mark.req("N-11")

SAFE = "%safe\nG00 Z40\nM17\n"
"""A stand-in 'move to the safe height' (what RegenHU's G803 does on its machine)."""
ORIGIN = "%origin\nG00 X[@P1] Y[@P3]\n$IF EXIST[@P2]\nZ[@P2]\n$ENDIF\nM17\n"
"""A stand-in with values: X from @P1, Y from @P3, Z from @P2 where given."""


def run(text: str, implicit: dict[int, str] | None = None, files: dict[str, str] | None = None) -> Run:
    host = FakeHost(files if files is not None else {"safe.nc": SAFE, "origin.nc": ORIGIN}, implicit=implicit)
    return interpret(text, host=host)


def test_an_assigned_g_code_calls_its_subprogram_at_the_end_of_its_block() -> None:
    done = run("G01 X5 F1000 G803\nG01 X6\nM30\n", {803: "safe.nc"})
    assert done.error is None
    # the block's own words first, then the subprogram, then the program goes on
    assert done.axes == [{"X": 5.0}, {"Z": 40.0}, {"X": 6.0}]
    assert [b.program for b in done.blocks if b.axes] == ["", "safe.nc", ""]


def test_it_is_not_modal() -> None:
    done = run("G803\nG01 X1 F1000\nX2\nM30\n", {803: "safe.nc"})
    assert done.axes == [{"Z": 40.0}, {"X": 1.0}, {"X": 2.0}]


@pytest.mark.parametrize(
    ("g", "parameter"),
    [
        (80, "P-CHAN-00160 g80_prog_file"),
        (89, "P-CHAN-00169 g89_prog_file"),
        (800, "P-CHAN-00187 g800_prog_file[0]"),
        (803, "P-CHAN-00187 g800_prog_file[3]"),
        (839, "P-CHAN-00187 g800_prog_file[39]"),
    ],
)
def test_without_an_assignment_it_is_the_kernels_20131(g: int, parameter: str) -> None:
    done = run(f"G01 X1 F1000\nG{g}\nM30\n")
    assert done.error is not None
    assert (done.error.alarm, done.error.line) == (20131, 2)
    assert f"unknown G function G{g}" in done.error.message
    assert parameter in done.error.message
    assert f'#FILE NAME [G{g}="name"]' in done.error.message
    assert done.axes == [{"X": 1.0}]


def test_values_in_brackets_are_a_cycle_call_read_as_at_p() -> None:
    done = run("G805[10.0, 2.5, 9.7]\nM30\n", {805: "origin.nc"})
    assert done.error is None
    assert done.axes == [{"X": 10.0, "Y": 9.7}, {"Z": 2.5}]


def test_a_gap_leaves_its_at_p_unset_and_values_are_expressions() -> None:
    done = run("P1 = 4\nG805[P1 * 2.5, , SIN[30] * 2]\nM30\n", {805: "origin.nc"})
    assert done.error is None
    assert done.axes == [{"X": 10.0, "Y": pytest.approx(1.0)}]  # EXIST[@P2] is false: no Z


def test_a_value_not_given_is_the_cycles_914003_when_read() -> None:
    done = run("G805[1]\nM30\n", {805: "origin.nc"})
    assert done.error is not None
    assert done.error.alarm == 914003
    assert "@P3" in done.error.message


def test_file_name_assigns_and_reassigns_until_the_program_ends() -> None:
    text = (
        '#FILE NAME [G803="origin.nc"]\nG803[1, , 2]\n#FILENAME [G803="safe.nc" MSG="log.txt"]\nG803\nM30\n'
    )
    host = FakeHost({"safe.nc": SAFE, "origin.nc": ORIGIN}, implicit={803: ""})
    it = Interpreter(Compiler(host.axes, ("X", "Y", "Z")), host, budget=None)
    done = interpret(text, host=host, interpreter=it)
    assert done.error is None
    assert done.axes == [{"X": 1.0, "Y": 2.0}, {"Z": 40.0}]
    # the next program starts with the channel's parameters again: G803 has none
    again = interpret("G803\nM30\n", host=host, interpreter=it)
    assert again.error is not None
    assert again.error.alarm == 20131


def test_file_name_overrides_the_channel_parameter() -> None:
    done = run('#FILE NAME [G81="origin.nc"]\nG81[3,,4]\nM30\n', {81: "safe.nc"})
    assert done.axes == [{"X": 3.0, "Y": 4.0}]


def test_a_program_not_found_is_914010_naming_it() -> None:
    done = run("G803\nM30\n", {803: "missing.nc"})
    assert done.error is not None
    assert done.error.alarm == 914010
    assert "missing.nc" in done.error.message


@pytest.mark.parametrize(
    ("block", "alarm"),
    [
        ("G803 G805", 910103),  # one G group (P-CHAN-00022 g_gruppe[13])
        ("G803 L safe.nc", 21542),
        ("L safe.nc G803", 21542),
        ("G803 $GOTO N10", 21542),
        ("G805[1, 2", 914015),
        ("G805[1 2]", 914015),
        ("G805[" + ",".join(["1"] * 51) + "]", 914020),
        ("G803 M30", 914015),
    ],
)
def test_malformed_implicit_calls_are_refused_with_their_alarm(block: str, alarm: int) -> None:
    done = run(f"N10 G01 X1 F1000\n{block}\nM30\n", {803: "safe.nc", 805: "origin.nc"})
    assert done.error is not None, done.blocks
    assert (done.error.alarm, done.error.line) == (alarm, 2)


def test_fifty_values_are_taken() -> None:
    sub = "X[@P1 + @P50]\nM17\n"
    done = run(
        "G01 F1000 G805[" + ",".join(str(k) for k in range(1, 51)) + "]\nM30\n", {805: "s.nc"}, {"s.nc": sub}
    )
    assert done.error is None
    assert done.axes == [{"X": 51.0}]


def test_other_file_name_ids_stay_refused() -> None:
    done = run('#FILE NAME [M6="tool.nc"]\nM30\n')
    assert done.error is not None
    assert done.error.alarm == 910110
    done = run('#FILE NAME [G79="x.nc"]\nM30\n')
    assert done.error is not None
    assert done.error.alarm == 910110


def test_g80_to_g89_are_not_known_g_codes_of_the_word_parser_elsewhere() -> None:
    """G80 is no canned-cycle cancel here (DIN 66025's meaning): it is the kernel's implicit call."""
    done = run("G80\nM30\n")
    assert done.error is not None
    assert done.error.alarm == 20131


# --- as a user meets them: a machine file and `hli-server check` -----------------------------------------
def machine(tmp_path: Path, channel: str, list_text: str | None = None) -> Path:
    text = textwrap.dedent(
        """\
        [[axes]]
        number = 1
        name = "X"
        swe_neg = -5_000_000
        swe_pos = 5_000_000

        [[axes]]
        number = 2
        name = "Y"
        swe_neg = -5_000_000
        swe_pos = 5_000_000

        [[axes]]
        number = 3
        name = "Z"
        swe_neg = -5_000_000
        swe_pos = 5_000_000

        [[channels]]
        number = 1
        axes = ["X", "Y", "Z"]
        """
    )
    text += textwrap.dedent(channel)
    if list_text is not None:
        (tmp_path / "ch1.lis").write_text(list_text, encoding="utf-8")
        text += 'parameter_list = "ch1.lis"\n'
    path = tmp_path / "machine.toml"
    path.write_text(text, encoding="utf-8")
    return path


def check_with(config: Path, subs: Path, program: Path, *mode: str) -> tuple[int, dict[str, Any]]:
    """``hli-server check --config CONFIG --program-dir SUBS PROGRAM``, as a user runs it."""
    args = ["check", "--format", "json", *mode, "--config", str(config), "--program-dir", str(subs)]
    done = CliRunner().invoke(main, [*args, str(program)])
    return done.exit_code, json.loads(done.stdout)


def check(tmp_path: Path, config: Path, program: str, *mode: str) -> tuple[int, dict[str, Any]]:
    subs = tmp_path / "subs"
    subs.mkdir(exist_ok=True)
    (subs / "SAFE.NC").write_text(SAFE, encoding="utf-8")
    (subs / "origin.nc").write_text(ORIGIN, encoding="utf-8")
    (tmp_path / "main.nc").write_text(program, encoding="utf-8")
    return check_with(config, subs, tmp_path / "main.nc", *mode)


PROGRAM = "N10 G01 X1 F6000\nN20 G803\nN30 G805[10, 2.5, 9.7]\nN40 G81\nN50 M30\n"


@pytest.mark.parametrize("mode", [(), ("--geometry-only",)])
def test_a_machine_file_assigns_them_in_toml(tmp_path: Path, mode: tuple[str, ...]) -> None:
    config = machine(
        tmp_path, 'g81_prog_file = "safe.nc"\ng800_prog_file = ["", "", "", "safe.nc", "", "origin.nc"]\n'
    )
    code, report = check(tmp_path, config, PROGRAM, *mode)
    assert code == 0, report
    assert report["final_position"] == {"X": 10.0, "Y": 9.7, "Z": 40.0}


@pytest.mark.parametrize("mode", [(), ("--geometry-only",)])
def test_the_kernels_channel_list_assigns_them(tmp_path: Path, mode: tuple[str, ...]) -> None:
    lis = (
        "g81_prog_file            safe.nc            (Name des UP bei G81)\n"
        "g800_prog_file[3]        safe.nc            (Name des UP bei G803)\n"
        "g800_prog_file[5]        origin.nc\n"
    )
    config = machine(tmp_path, "", lis)
    code, report = check(tmp_path, config, PROGRAM, *mode)
    assert code == 0, report
    assert report["final_position"] == {"X": 10.0, "Y": 9.7, "Z": 40.0}


def test_without_the_machine_they_stop_on_20131_naming_the_g_code(tmp_path: Path) -> None:
    code, report = check(tmp_path, machine(tmp_path, ""), PROGRAM)
    assert code == 1
    (alarm,) = report["alarms"]
    assert (alarm["id"], alarm["line"], alarm["block"]) == (20131, 2, "N20")
    assert "G803" in alarm["message"]


def test_the_lists_entries_are_checked(tmp_path: Path) -> None:
    parsed = parse_parameter_list(
        "g800_prog_file[40] x.nc\ng800_prog_file[1] a.nc\ng800_prog_file[1] b.nc\n"
        f"g82_prog_file {'x' * 84}\ng800_prog_file[2]\n",
        "channel",
        source="ch1.lis",
    )
    assert parsed.values == {"g800_prog_file": ["", "a.nc"]}
    assert parsed.errors[0] == "ch1.lis:1: g800_prog_file[40]: index 40 is out of range: 0 .. 39"
    assert parsed.errors[1] == "ch1.lis:3: g800_prog_file[1]: given twice (first in line 2)"
    assert parsed.errors[2].startswith("ch1.lis:4: g82_prog_file:")
    assert "83" in parsed.errors[2]
    assert parsed.errors[3] == "ch1.lis:5: g800_prog_file[2]: no value (write `g800_prog_file[2] <value>`)"
    with pytest.raises(ConfigError, match="g800_prog_file"):
        load_machine(machine(tmp_path, "g800_prog_file = [" + ", ".join(['"a.nc"'] * 41) + "]\n"))


# --- a machine with stand-ins of its own (tests/data/implicit_calls/README.md) -----------------------------
STANDINS = Path(__file__).resolve().parents[1] / "data" / "implicit_calls"


@pytest.mark.parametrize("mode", [(), ("--geometry-only",)])
def test_a_dispensing_program_runs_with_the_machine_and_its_stand_ins(mode: tuple[str, ...]) -> None:
    code, report = check_with(
        STANDINS / "machine.toml", STANDINS / "subs", STANDINS / "dispense_squares.nc", *mode
    )
    assert code == 0, report
    assert report["completed"] is True
    assert report["alarms"] == []
    assert [m["text"] for m in report["messages"]] == ["G801: tool measured"]
    assert report["final_position"] == {"X": 0.0, "Y": 0.0, "Z": 100.0}  # G800: home


def test_the_stand_ins_hand_their_values_to_the_plc() -> None:
    from hli_server.engine import Machine
    from hli_server.engine.program_check import ProgramCheck
    from hli_server.runtime.programs import ProgramDirectories

    machine = Machine(
        load_machine(STANDINS / "machine.toml"), programs=ProgramDirectories([STANDINS / "subs"])
    )
    text = "G805[-7.82, 28.955, 2.87]\nG807[2, 0.3, 0.25]\nM30\n"
    assert ProgramCheck(machine, 1).run(text).completed
    external = machine.external
    assert [external.read("ORIGIN", 1, [i]) for i in range(3)] == [-7.82, 28.955, 2.87]
    assert [external.read("DELAYS", 1, [i]) for i in range(3)] == [2.0, 0.3, 0.25]
    # G807 without values: a plain subroutine call (no @P), the mode back to 0
    assert ProgramCheck(machine, 1).run("G807\nM30\n").completed
    assert external.read("DELAYS", 1, [0]) == 0.0
    # what the program tells the operator: a structure's VSTRING, for the HMI
    program = (STANDINS / "dispense_squares.nc").read_text(encoding="utf-8")
    assert ProgramCheck(machine, 1).run(program).completed
    assert external.read("UserInteraction.Message", 1) == "Squares done - take the plate, then click OK"


def test_without_the_machine_the_program_stops_naming_the_g_code() -> None:
    done = CliRunner().invoke(main, ["check", "--format", "json", str(STANDINS / "dispense_squares.nc")])
    assert done.exit_code == 1
    (alarm,) = json.loads(done.stdout)["alarms"]
    assert (alarm["id"], alarm["line"]) == (20131, 6)
    assert "G803" in alarm["message"]
