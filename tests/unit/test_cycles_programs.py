"""The built-in cycles in NC programs on a machine, cycle by cycle (docs/cycles.md): found after the
user's own files, the simulated probe's deviation reaching ``V.CYC.SysRet*`` and from there the PLC's V.E.
variables, the moves checked by the monitors, zero offsets and the teach-in's subroutine, and the same
results from a geometry check."""

from __future__ import annotations

import pytest

from hli_server.engine import Machine
from hli_server.engine.program_check import ProgramCheck
from hli_server.engine.programs import MemoryLibrary
from schemas.config import (
    AxisConfig,
    ChannelConfig,
    ExternalVariableConfig,
    MachineConfig,
    ProbeConfig,
    ToolEntry,
)
from tests.unit.engine_helpers import run

RADIUS = 2.0
"""The touch probe's sphere (D1)."""


def config(*, swe: int = 5_000_000, variables: dict[str, str] | None = None) -> MachineConfig:
    names = ("X", "Y", "Z")
    return MachineConfig(
        axes=[
            AxisConfig(number=i + 1, name=n, swe_neg=-swe, swe_pos=swe, messachse=True)
            for i, n in enumerate(names)
        ],
        channels=[
            ChannelConfig(
                axes=list(names),
                tools=[
                    ToolEntry(number=1, radius=round(RADIUS * 10_000)),
                    ToolEntry(number=2, radius=30_000),
                ],
                probe=ProbeConfig(
                    measuring_feed=300.0, positioning_feed=3000.0, deviation_variables=variables or {}
                ),
            )
        ],
        external_variables=[
            ExternalVariableConfig(name=n) for n in ("MEAS_X", "MEAS_Y", "MEAS_D", "MEAS_C", "DEV_X", "MARK")
        ],
    )


SPIGOT = """
T1 D1
G53
G00 X50 Y20 Z10
#VAR
  V.CYC.SysRetX
  V.CYC.SysRetY
  V.CYC.SysRetDiameter
#ENDVAR
L CYCLE [NAME=SysMeasWcs39.ecy @P2=20 @P7=54 @P13=4 @P14=10 @P33=5]
V.E.MEAS_X = V.CYC.SysRetX
V.E.MEAS_Y = V.CYC.SysRetY
V.E.MEAS_D = V.CYC.SysRetDiameter
M30
"""


def alarms(machine: Machine) -> list[tuple[int, str]]:
    return [(a.number, a.message) for a in machine.alarm_history]


@pytest.mark.req("CY-04", "CY-05")
def test_the_deviation_reaches_the_plc_through_the_results() -> None:
    machine = Machine(config())
    machine.set_probe_deviation(1, {"X": 0.3, "Y": -0.125})
    run(machine, SPIGOT)
    assert [a for a in alarms(machine) if a[0] != 917001] == []
    ext = machine.external
    assert ext.read("MEAS_X", 1) == pytest.approx(50.3, abs=1e-4)
    assert ext.read("MEAS_Y", 1) == pytest.approx(19.875, abs=1e-4)
    assert ext.read("MEAS_D", 1) == pytest.approx(20.0, abs=1e-4)
    # @P7 = 54 with G53 at the call: the measured centre is G54's zero now
    assert machine.channel(1).decoder.modal.zero_offsets["G54"]["X"] == pytest.approx(50.3, abs=1e-4)


@pytest.mark.req("CY-04")
def test_the_plc_sets_the_deviation_through_a_ve_variable() -> None:
    machine = Machine(config(variables={"X": "DEV_X"}))
    machine.external.write("DEV_X", 1, -0.5)  # the PLC writes gpVEGlob^DEV_X
    run(machine, SPIGOT)
    assert machine.external.read("MEAS_X", 1) == pytest.approx(49.5, abs=1e-4)


@pytest.mark.req("CY-04")
def test_a_part_too_far_off_is_13413_at_the_call() -> None:
    machine = Machine(config())
    machine.set_probe_deviation(1, {"X": 6.0})  # beyond the 5 mm crossover on the touch from X+
    run(machine, SPIGOT)
    errors = [a for a in machine.alarm_history if a.number in (13413, 13414)]
    assert errors, alarms(machine)
    assert errors[0].line == 10
    assert "SysMeasWcs39.ecy" in errors[0].message
    assert machine.external.read("MEAS_X", 1) == 0.0  # the program stopped at the call


@pytest.mark.req("CY-05", "N-10")
def test_a_geometry_check_measures_the_same() -> None:
    for geometry in (False, True):
        machine = Machine(config())
        machine.set_probe_deviation(1, {"Y": 0.2})
        report = ProgramCheck(machine, 1, geometry_only=geometry).run(SPIGOT)
        assert report.completed, report
        assert machine.external.read("MEAS_Y", 1) == pytest.approx(20.2, abs=1e-4)


@pytest.mark.req("CY-01")
def test_the_users_own_cycle_file_wins() -> None:
    own = "V.CYC.SysRetX = 42 + @P2\nM17\n"
    for programs, cycles in (
        (MemoryLibrary({"SysMeasWcs39.ecy": own}), None),
        (None, {1: MemoryLibrary({"sysmeaswcs39.ECY": own}, where="cycles")}),
    ):
        machine = Machine(config(), programs=programs, cycle_programs=cycles)
        run(machine, SPIGOT)
        assert machine.external.read("MEAS_X", 1) == 62.0


@pytest.mark.req("CY-01")
def test_a_cycle_not_built_and_an_unknown_cycle() -> None:
    machine = Machine(config(), cycle_programs={1: MemoryLibrary({"other.ecy": "M17\n"}, where="my cycles")})
    run(machine, "G00 X0\nL CYCLE [NAME=SysMillFace.ecy @P1=0]\nM30\n")
    last = machine.alarm_history[-1]
    assert (last.number, last.line) == (910110, 2)
    assert "SysMillFace.ecy" in last.message
    machine = Machine(config(), cycle_programs={1: MemoryLibrary({"other.ecy": "M17\n"}, where="my cycles")})
    run(machine, "L CYCLE [NAME=NoSuchCycle.ecy]\nM30\n")
    last = machine.alarm_history[-1]
    assert last.number == 914010
    assert "my cycles" in last.message


@pytest.mark.req("N-04")
def test_cycle_variables_of_the_main_program_and_string_parameters() -> None:
    """V.CYC. declared in the main program is seen by the levels it calls (PM 486123531); a string @P."""
    cycle = (
        '$IF @P31 == "Roughing"\n  V.CYC.Got = 1\n$ELSE\n  V.CYC.Got = 2\n$ENDIF\n'
        "V.CYC.Depth = V.CYC.Depth + 1\nM17\n"
    )
    machine = Machine(config(), programs=MemoryLibrary({"mine.ecy": cycle}))
    program = (
        "#VAR\n  V.CYC.Got = 0\n  V.CYC.Depth = 5\n#ENDVAR\n"
        'L CYCLE [NAME=mine.ecy @P31="Roughing"]\nV.E.MEAS_X = V.CYC.Got\nV.E.MEAS_Y = V.CYC.Depth\nM30\n'
    )
    run(machine, program)
    assert (machine.external.read("MEAS_X", 1), machine.external.read("MEAS_Y", 1)) == (1.0, 6.0)


@pytest.mark.req("CY-03")
def test_a_soft_limit_stops_a_pocket_ring() -> None:
    """The stand-in's moves are ordinary blocks: the soft limit refuses the ring that would cross it."""
    machine = Machine(config(swe=560_000))  # +/-56 mm: the tool centre of the pocket at X50 reaches X57
    program = (
        "T2 D2\nG00 X50 Y0 Z50\nF1000\n"
        "L CYCLE [NAME=SysMillRectangularPocket.ecy @P1=0 @P2=50 @P3=2 @P4=4 @P5=4 @P6=6 @P72=20 "
        "@P73=10]\nM30\n"
    )
    run(machine, program)
    refused = [a for a in machine.alarm_history if a.number == 120002]
    assert refused, alarms(machine)
    assert refused[0].line == 4, alarms(machine)
    assert refused[0].params.get("program") == "SysMillRectangularPocket.ecy"
    assert max(a.setpoint for a in machine.axes if a.name == "X") <= 56.0 + 1e-9


@pytest.mark.req("CY-03")
def test_the_callers_modal_state_is_restored() -> None:
    machine = Machine(config())
    program = (
        "T2 D2\nG00 X0 Y0 Z50\nG91 G01 F777\n"
        "L CYCLE [NAME=SysDrillCenterHole.ecy @P1=0 @P2=20 @P3=2 @P4=5]\nX10\nM30\n"
    )
    run(machine, program)
    assert alarms(machine) == []
    modal = machine.channel(1).decoder.modal
    assert (modal.absolute, modal.motion, modal.feed) == (False, 1, 777.0)
    assert machine.axes[0].setpoint == pytest.approx(10.0)  # the X10 after the call is incremental


@pytest.mark.req("CY-05", "N-09")
def test_the_teach_in_subroutine_sets_a_cs() -> None:
    machine = Machine(config())
    machine.set_probe_deviation(1, {"X": 1.0, "Y": 2.0, "Z": -0.5})
    program = (
        "T1 D1\nG53\nG00 X0 Y0 Z0\n"
        "L CYCLE [NAME=SysMeasCs5.ecy @P6=40 @P39=2 @P41=60 @P42=0 @P43=0 @P44=60 @P87=20]\n"
        "L CS_BASE_2.bcs\nG01 X0 Y0 Z20 F1000\n#CS OFF\nM30\n"
    )
    run(machine, program)
    assert alarms(machine) == []
    # the CS's origin is the first sphere's centre (0 + 1, 0 + 2, -45 - 0.5): X0 Y0 Z20 of the CS
    x, y, z = (a.setpoint for a in machine.axes)
    assert (x, y, z) == (
        pytest.approx(1.0, abs=1e-4),
        pytest.approx(2.0, abs=1e-4),
        pytest.approx(-25.5, abs=1e-4),
    )
    assert "#CS DEF [2][1,2,-45.5,0,0,0]" in (machine.channel(1).written.find("CS_BASE_2.bcs") or None).text  # type: ignore[union-attr]


@pytest.mark.req("CY-03", "C14-02")
def test_a_protection_area_stops_the_drill_above_a_clamp() -> None:
    """A clamp's protection area below Z-1 around X30: the stand-in's feed to the depth enters it and is
    refused by the area monitor at the call's line; the drill's rapid above it was allowed."""
    machine = Machine(config())
    program = (
        "G90 F1000\n#CONTROL AREA BEGIN [ID=1 PROT POLY MIN_EXCUR=-50 MAX_EXCUR=-1]\n"
        "G01 X25 Y-5\nX35 Y-5\nX35 Y5\nX25 Y5\nX25 Y-5\n#CONTROL AREA END\n#CONTROL AREA ON ALL\n"
        "T2 D2\nG00 X30 Y0 Z50\n"
        "L CYCLE [NAME=SysDrillCenterHole.ecy @P1=0 @P2=20 @P3=2 @P4=5]\nM30\n"
    )
    run(machine, program)
    entered = [a for a in machine.alarm_history if a.number in (912000, 912001)]
    assert entered, alarms(machine)
    assert entered[0].line == 12, alarms(machine)  # the call's line
    assert min(a.setpoint for a in machine.axes if a.name == "Z") >= -1.0 - 1e-6
