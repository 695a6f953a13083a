"""The V.E. store of the engine (N-05): declared in the machine file, zero at start, typed writes."""

from __future__ import annotations

import re

import pytest
from pydantic import ValidationError

from hli_server.engine import Machine
from hli_server.engine.external import ExternalType, ExternalVariableError, ExternalVariables, ExternalVarSpec
from hli_server.engine.programs import MemoryLibrary
from schemas.config import MachineConfig
from tests.machines import demo_config


def _config(**extra: object) -> MachineConfig:
    return MachineConfig.model_validate({**demo_config().model_dump(), **extra})


@pytest.mark.req("N-05")
def test_declared_variables_start_at_zero_and_keep_their_type() -> None:
    machine = Machine(
        _config(
            external_variables=[
                {"name": "EXT1", "type": "SGN32"},
                {"name": "flag", "type": "BOOLEAN", "channel": 1},
                {"name": "table", "type": "REAL64", "dims": [2, 3]},
            ]
        )
    )
    store = machine.external
    assert store.read("EXT1", 1) == 0
    assert store.read("FLAG", 1) is False  # names are case-insensitive
    store.write("ext1", 1, 41.9)
    assert store.read("EXT1", 1) == 41  # a real assigned to an integer variable is truncated
    store.write("TABLE", 1, 2.5, (1, 2))
    assert store.values(store.spec("table", None) or pytest.fail("not found")) == [0.0] * 5 + [2.5]
    store.reset()
    assert store.read("TABLE", 1, (1, 2)) == 0.0


@pytest.mark.req("N-05")
def test_a_channel_variable_shadows_the_global_one_of_the_same_name() -> None:
    store = ExternalVariables(
        [ExternalVarSpec("X", ExternalType.REAL64), ExternalVarSpec("X", ExternalType.SGN32, channel=2)]
    )
    store.write("X", 2, 7)
    assert store.read("X", 1) == 0.0  # channel 1 sees the global one
    assert store.read("X", 2) == 7
    assert store.read("X", None) == 0.0


@pytest.mark.req("N-05")
@pytest.mark.parametrize(
    ("name", "index", "value", "message"),
    [
        ("NOPE", (), 1, "V.E.NOPE is not declared"),
        ("B", (), 256, "outside 0 .. 255"),
        ("A", (2,), 1.0, "index 1 is 2, allowed 0 to 1"),
        ("A", (), 1.0, "takes 1 index(es), got 0"),
        ("A", (0,), float("nan"), "not a number"),
    ],
)
def test_refused_reads_and_writes_say_what_and_which(
    name: str, index: tuple[int, ...], value: float, message: str
) -> None:
    store = ExternalVariables(
        [ExternalVarSpec("A", ExternalType.REAL64, (2,)), ExternalVarSpec("B", ExternalType.UNS08)]
    )
    with pytest.raises(ExternalVariableError, match=re.escape(message)):
        store.write(name, 1, value, index)
    assert store.read("A", 1, (1,)) == 0.0  # nothing was changed


@pytest.mark.req("N-05")
def test_the_machine_file_refuses_a_duplicate_or_a_missing_channel() -> None:
    with pytest.raises(ValidationError, match="declared twice"):
        _config(external_variables=[{"name": "a"}, {"name": "A"}])
    with pytest.raises(ValidationError, match="channel 7 does not exist"):
        _config(external_variables=[{"name": "a", "channel": 7}])
    with pytest.raises(ValidationError):
        _config(external_variables=[{"name": "x" * 21}])


@pytest.mark.req("N-02")
def test_memory_library_finds_exactly_then_ignoring_case_and_names_where_it_looked() -> None:
    lib = MemoryLibrary({"UP1.nc": "%UP1\nM17\n"})
    found = lib.find("up1.NC")
    assert found is not None
    assert (found.name, found.origin) == ("UP1.nc", "upload:UP1.nc")
    assert lib.find("UP2.nc") is None
    assert lib.searched() == ("uploaded files",)
    assert Machine(_config()).programs.searched() == ()
