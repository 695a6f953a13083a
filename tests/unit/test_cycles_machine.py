"""The machine's side of the built-in cycles: the channel's ``cycle_directories`` and ``[channels.probe]``
in the machine file, the simulated workpiece's deviation through the V.E. variables and the engine's
setter (docs/cycles.md)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hli_server.configuration import load_machine
from hli_server.engine import Machine
from tests.unit.config_helpers import errors_of, write

MACHINE = """
    [[axes]]
    number = 1
    name = "X"
    [[axes]]
    number = 2
    name = "Y"
    [[axes]]
    number = 3
    name = "Z"

    [[channels]]
    axes = ["X", "Y", "Z"]
    cycle_directories = {dirs}
    [channels.probe]
    measuring_feed = 150.0
    deviation_variables = {variables}

    [[external_variables]]
    name = "PROBE_DEV_X"
    type = "REAL64"
    [[external_variables]]
    name = "FLAG"
    type = "BOOLEAN"
"""


def machine_file(tmp_path: Path, dirs: str = "[]", variables: str = '{ X = "PROBE_DEV_X" }') -> Path:
    return write(tmp_path, "m.toml", MACHINE.format(dirs=dirs, variables=variables))


@pytest.mark.req("CY-01")
def test_cycle_directories_are_relative_to_the_machine_file(tmp_path: Path) -> None:
    (tmp_path / "cycles").mkdir()
    config = load_machine(machine_file(tmp_path, dirs='["cycles"]'))
    assert config.channels[0].cycle_directories == [str((tmp_path / "cycles").resolve())]
    assert config.channels[0].probe.measuring_feed == 150.0
    errors = errors_of(machine_file(tmp_path, dirs='["nowhere"]'))
    assert any("cycle directory" in e and "nowhere" in e and "not found" in e for e in errors), errors


@pytest.mark.parametrize(
    ("variables", "says"),
    [
        ('{ Q = "PROBE_DEV_X" }', "not an axis of the channel"),
        ('{ X = "UNDECLARED" }', "no such V.E. variable"),
        ('{ X = "FLAG" }', "must be a numeric scalar"),
    ],
)
def test_the_deviation_variables_are_checked(tmp_path: Path, variables: str, says: str) -> None:
    errors = errors_of(machine_file(tmp_path, variables=variables))
    assert any(says in e for e in errors), errors


@pytest.mark.req("CY-04")
def test_the_deviation_comes_from_the_ve_variable_or_the_setter(tmp_path: Path) -> None:
    machine = Machine(load_machine(machine_file(tmp_path)))
    assert machine.probe_deviation(1) == {"X": 0.0, "Y": 0.0, "Z": 0.0}
    machine.external.write("PROBE_DEV_X", 1, 0.25)  # the PLC (or a program) writes the variable
    machine.set_probe_deviation(1, {"Y": -0.5})
    assert machine.probe_deviation(1) == {"X": 0.25, "Y": -0.5, "Z": 0.0}
    machine.set_probe_deviation(1, {"x": 1.5})  # the setter writes the axis' variable, as the PLC would
    assert machine.external.read("PROBE_DEV_X", 1) == 1.5
    with pytest.raises(KeyError, match="no axis 'Q'"):
        machine.set_probe_deviation(1, {"Q": 1.0})
    with pytest.raises(ValueError, match="within"):
        machine.set_probe_deviation(1, {"Y": 20_000.0, "Z": 1.0})
    with pytest.raises(ValueError, match="finite"):
        machine.set_probe_deviation(1, {"Z": float("nan")})
    assert machine.probe_deviation(1) == {"X": 1.5, "Y": -0.5, "Z": 0.0}  # nothing changed by the refusals
