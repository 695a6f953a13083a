"""Machines and program runners for the FCT-C14 tests."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from hli_server.engine.alarms import Alarm
from hli_server.engine.areas import ChannelAreas, channel_areas
from hli_server.engine.channel import Channel
from hli_server.engine.hli import ProgramState
from hli_server.engine.machine import Machine
from schemas.config import AxisConfig, ChannelConfig, MachineConfig, ManualConfig

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


U_AREA = """N10 #CONTROL AREA BEGIN [ID3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N20 G01 F1000 G90 X-150 Y75 (Startpunkt)
N30 X-50 Y150
N40 X50 Y150
N50 X150 Y75
N60 X150 Y0
N70 X50 Y0
N80 X50 Y75
N90 X-50 Y75
N100 X-50 Y0
N120 X-150 Y0
N130 X-150 Y75 (Endpunkt identisch mit Startpunkt)
N140 #CONTROL AREA END
"""
"""FCT-C14 3.1.1, the U-shaped polygonal work area (BEGIN)."""

U_AREA_START = U_AREA.replace("BEGIN", "START")
"""The same with the older keyword START (the excerpt 001)."""

CIRC_PROT = """N10 #CONTROL AREA BEGIN [ID4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]
N20 G01 X0 Y0 F10000      (Startpunkt für zylindrischen Schutzraum)
N30 G02 G162 I0 J75      ( Definition des Vollkreises)
N40 #CONTROL AREA END
"""
"""FCT-C14 3.1.2, the cylindrical protection area: centre (0, 75), radius 75."""

CIRC_PROT_OLD = """N10 #CONTROL AREA START [ID4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]
N20 G01 X100 Y0 F10000 (Startpunkt für zylindrischen Schutzraum)
N30 G02 G162 I50 J0
N40 #CONTROL AREA END
"""
"""The excerpt 001's circle: centre (150, 0), radius 50."""

EXTRA_AXES_AREA = """N10 #CONTROL AREA BEGIN [ID4 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N20 G01 F1000 G90 X2=100 Y2=100 ;Startpunkt
N30 X2=-100
N40 Y2=-100
N50 X2=100
N60 X2=100 Y2=100 ;Endpunkt identisch mit Startpunkt
N70 #CONTROL AREA END
"""
"""FCT-C14 section 4: a work area for the additional axes X2, Y2 (height Z2)."""

TWO_PATH_AREA = """N040 #CONTROL AREA START [ID=1 WORK MONITOR_LVL = "IMCS" POLY MIN_EXCUR
= -100 MAX_EXCUR = 100]
N050 : G0 X200 Y0 : G0 U150 V0
N060 : G0 X200 Y200 : G0 U150 V150
N070 : G0 X-200 Y200 : G0 U-150 V150
N080 : G0 X-200 Y-200 : G0 U-150 V-150
N090 : G0 X200 Y-200 : G0 U150 V-150
N100 : G0 X200 Y0 : G0 U150 V0
N110 #CONTROL AREA END
"""
"""FCT-C14 2.4, the two-path work area (IMCS): not simulated."""
