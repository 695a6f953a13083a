"""ISG-style robot programs on a stand-in machine of our own (issue 33; tests/data/robot/README.md): six
axes X Y Z A B C, the teach-in HMI's V.E. variables, a start-up subroutine that limits the path velocity
in T1 (``#VECTOR LIMIT ON [VEL=..]``) and a program that writes the reached pose after ``#CHANNEL INIT
[CMDPOS]`` - run as a user runs them (``hli-server check --config --program-dir --set``) and on the
machine cycle by cycle."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from hli_server.cli import main
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.engine.presets import apply_presets
from hli_server.runtime.programs import ProgramDirectories
from tests.unit.engine_helpers import cycles_until_done, record_events, start

pytestmark = pytest.mark.req("N-08")

ROBOT = Path(__file__).resolve().parents[1] / "data" / "robot"
PROGRAM = ROBOT / "pick_and_teach.nc"
HMI = ["--set", 'V.E.TEACH_FILE_NAME="teach.nc"', "--set", "V.E.TEACH_ACS=1"]


def check(*args: str) -> tuple[int, dict[str, Any]]:
    done = CliRunner().invoke(main, ["check", "--format", "json", *args, str(PROGRAM)])
    return done.exit_code, json.loads(done.stdout)


@pytest.mark.parametrize("mode", [(), ("--geometry-only",)])
def test_the_program_runs_with_the_stand_ins(mode: tuple[str, ...]) -> None:
    config = ["--config", str(ROBOT / "machine.toml"), "--program-dir", str(ROBOT / "subs")]
    code, report = check(*config, *HMI, "--set", "V.E.REDUCED_SPEED_ACTIVE=1", *mode)
    assert code == 0, report
    assert report["completed"] is True
    assert [a["id"] for a in report["alarms"]] == [911041]  # ACC/DEC of #VECTOR LIMIT: approximated
    assert [m["text"] for m in report["messages"]] == [
        "G01 G90 F1000 X=300.000 Y=250.000 Z=350.000 A=10.000 B=80.000 C=-30.000"
    ]
    assert report["final_position"] == {"X": 300.0, "Y": 250.0, "Z": 350.0, "A": 10.0, "B": 80.0, "C": -30.0}


def test_without_the_machine_it_stops_naming_what_is_missing() -> None:
    code, report = check("--program-dir", str(ROBOT / "subs"))
    assert code == 1
    (alarm,) = report["alarms"]
    assert alarm["id"] == 914003
    assert "NC_LOG_PATH_NUMBER" in alarm["message"]


def peak_tcp_speed(reduced: bool) -> tuple[float, list[str]]:
    """The program on the machine: the highest speed of X/Y/Z together [mm/min] and the messages."""
    machine = Machine(load_machine(ROBOT / "machine.toml"), programs=ProgramDirectories([ROBOT / "subs"]))
    apply_presets(
        machine.external,
        1,
        {"V.E.TEACH_FILE_NAME": "teach.nc", "V.E.TEACH_ACS": False, "V.E.REDUCED_SPEED_ACTIVE": reduced},
    )
    events = record_events(machine)
    t_a = machine.channel(1).t_a
    last = [a.setpoint for a in machine.axes[:3]]
    peak = 0.0
    start(machine, PROGRAM.read_text(encoding="utf-8"))
    for _ in cycles_until_done(machine):
        now = [a.setpoint for a in machine.axes[:3]]
        peak = max(peak, math.dist(now, last) / t_a * 60.0)
        last = now
    return peak, [str(getattr(e, "text", "")) for e in events if hasattr(e, "text")]


def test_t1_limits_the_path_velocity_to_the_start_ups_vel() -> None:
    reduced, messages = peak_tcp_speed(True)
    free, _ = peak_tcp_speed(False)
    assert reduced == pytest.approx(12000.0, rel=2e-3)  # #VECTOR LIMIT ON [VEL=12000]
    assert free > 20000.0  # F30000 and the axes' own limits
    assert messages[-1] == "G01 G90 F5000 X=300.000 Y=250.000 Z=350.000"  # cartesian: TEACH_ACS FALSE


def test_the_machine_file_names_the_teach_file_at_start() -> None:
    """P-EXTV-00013 init: the machine starts with V.E.TEACH_FILE_NAME set, no --set needed for it."""
    config = ["--config", str(ROBOT / "machine.toml"), "--program-dir", str(ROBOT / "subs")]
    code, report = check(*config, "--set", "V.E.TEACH_ACS=1")
    assert code == 0, report
    assert report["completed"] is True
    assert [m["text"] for m in report["messages"]] == [
        "G01 G90 F1000 X=300.000 Y=250.000 Z=350.000 A=10.000 B=80.000 C=-30.000"
    ]
    machine = Machine(load_machine(ROBOT / "machine.toml"))
    assert machine.external.read("TEACH_FILE_NAME", 1) == "teach.nc"
    assert not machine.alarm_history
