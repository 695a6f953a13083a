"""P-EXTV-00013 ``init``: the V.E. variables' values at the controller's start (machine file
``external_init``, the kernel's list's ``init`` lines), evaluated in order; a failed line is warning
21840 or 21841 and leaves its variable 0."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from pydantic import ValidationError

from hli_server.cli import main
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from schemas.config import MachineConfig
from tests.machines import demo_config
from tests.unit.engine_helpers import run

pytestmark = pytest.mark.req("N-05")

VARIABLES: list[dict[str, Any]] = [
    {"name": "R64", "type": "REAL64"},
    {"name": "S32", "type": "SGN32"},
    {"name": "FLAG", "type": "BOOLEAN"},
    {"name": "NAME", "type": "STRING"},
    {"name": "TABLE", "type": "REAL64", "dims": [3]},
    {"name": "OWN", "type": "UNS16", "channel": 1},
    {"name": "UI", "type": "UI_T"},
]
STRUCTURES = [
    {"name": "UI_T", "elements": [{"name": "Message", "type": "STRING"}, {"name": "Answer", "type": "SGN32"}]}
]


def machine(*lines: str) -> Machine:
    data = {
        **demo_config().model_dump(),
        "external_variables": VARIABLES,
        "external_structures": STRUCTURES,
        "external_init": list(lines),
    }
    return Machine(MachineConfig.model_validate(data))


def warnings(m: Machine) -> list[tuple[int, dict[str, Any]]]:
    return [(a.number, a.params) for a in m.alarm_history]


def test_values_of_each_type_are_there_at_start() -> None:
    m = machine(
        "V.E.R64 = 1234.5",
        "V.E.S32 = -7 * 3",
        "V.E.FLAG = TRUE",
        'V.E.NAME = "teach.nc"',
        "V.E.TABLE[2] = SQRT[16]",
        "V.E.OWN = 65535",
        'V.E.UI.Message = "hello"',
        "v.e.ui.answer = 42",
    )
    store = m.external
    assert store.read("R64", 1) == 1234.5
    assert store.read("S32", 1) == -21
    assert store.read("FLAG", 1) is True
    assert store.read("NAME", 1) == "teach.nc"
    assert store.read("TABLE", 1, (2,)) == 4.0
    assert store.read("OWN", 1) == 65535  # a channel's own variable
    assert store.read("UI.Message", 1) == "hello"
    assert store.read("UI.Answer", 1) == 42
    assert not m.alarm_history


def test_other_variables_and_order() -> None:
    m = machine("V.E.S32 = 5", "V.E.R64 = V.E.S32 * 2 + 0.5", "V.E.S32 = V.E.S32 + 1", 'V.E.NAME = "a" + "b"')
    assert m.external.read("R64", 1) == 10.5  # the value of the line before, not the later one
    assert m.external.read("S32", 1) == 6
    # a value read before its init line runs is the start's zero
    m = machine("V.E.R64 = V.E.S32 + 1", "V.E.S32 = 5")
    assert m.external.read("R64", 1) == 1.0


def test_a_failed_line_is_21840_and_its_variable_zero() -> None:
    m = machine(
        "V.E.S32 = 9", "V.E.S32 = 1 / 0", 'V.E.NAME = "this text is longer than twenty"', "V.E.R64 = [1 +"
    )
    assert m.external.read("S32", 1) == 0  # set to 0, not the 9 of the line before
    assert m.external.read("NAME", 1) == ""
    got = warnings(m)
    assert got == [
        (21840, {"variable": "V.E.S32", "line": 2}),
        (21840, {"variable": "V.E.NAME", "line": 3}),
        (21840, {"variable": "V.E.R64", "line": 4}),
    ]
    messages = [a.message for a in m.alarm_history]
    assert "[914001]" in messages[0]
    assert "[21462]" in messages[1]
    assert not m.active_alarms  # class 2: the machine starts, nothing to acknowledge
    # an undeclared variable, a line that is no assignment
    m = machine("V.E.NOPE = 1", "G01 X10", "V.E.S32 = 3")
    assert [n for n, _ in warnings(m)] == [21840, 21840]
    assert "not declared" in m.alarm_history[0].message
    assert m.external.read("S32", 1) == 3  # the lines after a failed one still run


def test_only_ve_variables_21841() -> None:
    m = machine(
        "V.E.R64 = 7", "V.E.R64 = V.A.ABS.X + 1", "V.E.S32 = P1", "V.P.X = 1", "V.E.FLAG = EXIST[V.G.WZR]"
    )
    assert warnings(m) == [
        (21841, {"variable": "V.E.R64", "line": 2}),
        (21841, {"variable": "V.E.S32", "line": 3}),
        (21841, {"variable": "V.P.X", "line": 4}),
        (21841, {"variable": "V.E.FLAG", "line": 5}),
    ]
    assert m.external.read("R64", 1) == 0.0


def test_nc_programs_see_the_values_and_the_restart_runs_them_again() -> None:
    m = machine("V.E.S32 = 12")
    run(m, "N10 V.E.R64 = V.E.S32 * 2\nN20 V.E.S32 = 0\nM30\n")
    assert m.external.read("R64", 1) == 24.0
    # a program's start does not run them again (the kernel evaluates them at controller start only)
    run(m, "N10 V.E.R64 = V.E.S32\nM30\n")
    assert m.external.read("R64", 1) == 0.0
    assert Machine(m.config).external.read("S32", 1) == 12  # a restart is a new start


def test_the_field_is_bounded() -> None:
    with pytest.raises(ValidationError, match="external_init"):
        machine("V.E.S32 = 1\nV.E.R64 = 2")
    with pytest.raises(ValidationError, match="external_init"):
        machine("V.E.NAME = " + '"' + "x" * 600 + '"')
    with pytest.raises(ValidationError, match="external_init"):
        machine(*["V.E.S32 = 1"] * 1025)


def test_the_kernels_list_init_lines(tmp_path: Path) -> None:
    (tmp_path / "ve.lis").write_text(
        "var[0].name COUNT\nvar[0].type SGN32\nvar[0].scope GLOBAL\n"
        "var[1].name LABEL\nvar[1].type STRING\nvar[1].scope CHANNEL\n"
        "init V.E.COUNT = 3 (the first)\n"
        'init V.E.LABEL = "n(" + "o"\n',
        encoding="utf-8",
    )
    (tmp_path / "m.toml").write_text(
        'name = "m"\nexternal_init = ["V.E.COUNT = 1"]\n'
        + "".join(f'[[axes]]\nnumber = {i}\nname = "{a}"\n' for i, a in enumerate("XYZ", 1))
        + '[[channels]]\nnumber = 1\nname = "c"\naxes = ["X", "Y", "Z"]\n'
        + 'external_variables_list = "ve.lis"\n',
        encoding="utf-8",
    )
    config = load_machine(tmp_path / "m.toml")
    assert config.external_init == ["V.E.COUNT = 1", "V.E.COUNT = 3", 'V.E.LABEL = "n(" + "o"']
    m = Machine(config)
    assert m.external.read("COUNT", 1) == 3
    assert m.external.read("LABEL", 1) == "n(o"


def test_check_reports_the_start_warnings(tmp_path: Path) -> None:
    robot = Path(__file__).resolve().parents[1] / "data" / "robot"
    text = (robot / "machine.toml").read_text(encoding="utf-8")
    bad = text.replace("external_init = [", "external_init = ['V.E.TEACH_ACS = P1', ", 1)
    assert bad != text
    (tmp_path / "robot.toml").write_text(bad, encoding="utf-8")
    done = CliRunner().invoke(
        main,
        ["check", "--format", "json", "--config", str(tmp_path / "robot.toml"), "--program-dir",
         str(robot / "subs"), str(robot / "pick_and_teach.nc")],
    )  # fmt: skip
    report = json.loads(done.stdout)
    assert done.exit_code == 0, report
    first = report["alarms"][0]
    assert (first["id"], first["params"]) == (21841, {"variable": "V.E.TEACH_ACS", "line": 1})
