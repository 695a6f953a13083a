"""Machines and program runners for the FCT-C14 tests."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from hli_server.engine.alarms import Alarm
from hli_server.engine.areas import ChannelAreas, channel_areas
from hli_server.engine.channel import Channel
from hli_server.engine.machine import Machine
from schemas.config import AxisConfig, ChannelConfig, MachineConfig, ManualConfig
from schemas.wire import ProgramState
from tests.spec_examples import (  # noqa: F401 - the documents' programs, re-exported for the area tests
    CIRC_PROT,
    CIRC_PROT_OLD,
    EXTRA_AXES_AREA,
    TWO_PATH_AREA,
    U_AREA,
    U_AREA_START,
)

MAIN = ("X", "Y", "Z")
EXTRA = ("X2", "Y2", "Z2")


def make_machine(
    axes: Iterable[str] = MAIN + EXTRA,
    *,
    axis: dict[str, Any] | None = None,
    per_axis: dict[str, dict[str, Any]] | None = None,
    move_limit_warning: bool = False,
    **channel: Any,
) -> Machine:
    """A one-channel machine; ``axis`` sets fields of every AxisConfig, ``channel`` of the channel."""
    names = list(axes)
    configs = [
        AxisConfig(number=i + 1, name=n, **{**(axis or {}), **((per_axis or {}).get(n, {}))})
        for i, n in enumerate(names)
    ]
    cfg = MachineConfig(
        axes=configs,
        channels=[ChannelConfig(axes=names, **channel)],
        manual=ManualConfig(move_limit_warning=move_limit_warning),
    )
    return Machine(cfg)


def areas(machine: Machine, number: int = 1) -> ChannelAreas:
    return channel_areas(machine, number)


def run(machine: Machine, program: str, max_cycles: int = 200_000, channel: int = 1) -> Channel:
    """Load, start and run until the program is no longer running."""
    ch = machine.channel(channel)
    ch.load_program(program, "test")
    ch.request_start()
    machine.step(1)
    for _ in range(max_cycles):
        if ch.state not in (ProgramState.RUNNING, ProgramState.HELD):
            return ch
        machine.step(1)
    raise AssertionError(f"program still running after {max_cycles} cycles at {ch.setpoints()}")


def errors(machine: Machine) -> list[Alarm]:
    return [a for a in machine.alarm_history if a.severity == "error"]


def alarm_ids(machine: Machine) -> list[int]:
    return [a.number for a in machine.alarm_history]


def only_alarm(machine: Machine, number: int) -> Alarm:
    found = [a for a in machine.alarm_history if a.number == number]
    assert found, f"no alarm {number}; got {[(a.number, a.message) for a in machine.alarm_history]}"
    return found[0]


def state_of(machine: Machine, area_id: int, channel: int = 1) -> str | None:
    for entry in areas(machine, channel).to_json()["areas"]:
        if entry["id"] == area_id:
            return str(entry["state"])
    return None
