"""The simulated probe of the built-in measuring cycles through the harness and the PLC image
(docs/cycles.md): a test sets the workpiece's deviation with ``hli.set_probe_deviation``, the PLC sees it
in its V.E. variable, the measuring cycle finds the part where it is, and the program hands the measured
value to the PLC."""

from __future__ import annotations

import pytest

from hli_server.adapters.host import NotFoundError
from hli_server.testing import Harness
from hli_server.testing.remote import RemoteHarness
from schemas.config import ExternalVariableConfig, MachineConfig, ProbeConfig
from schemas.wire import ProgramState
from tests.integration.servers import read_banner, start_server, stop_server
from tests.machines import demo_config


def _machine() -> MachineConfig:
    base = demo_config()
    mill = base.channels[0].model_copy(
        update={
            "probe": ProbeConfig(
                measuring_feed=3000.0, positioning_feed=20_000.0, deviation_variables={"X": "DEV_X"}
            )
        }
    )
    axes = [a.model_copy(update={"messachse": a.name in {"X", "Y", "Z"}}) for a in base.axes]
    return base.model_copy(
        update={
            "axes": axes,
            "channels": [mill, *base.channels[1:]],
            "external_variables": [ExternalVariableConfig(name=n) for n in ("DEV_X", "MEAS_X", "MEAS_Y")],
        }
    )


PROBE_MACHINE = _machine()
PROGRAM_STATE = "gpCh[0]^bahn_state.program_state_r"
SPIGOT = """
G53
G00 X50 Y20 Z10
#VAR
  V.CYC.SysRetX
  V.CYC.SysRetY
#ENDVAR
L CYCLE [NAME=SysMeasWcs39.ecy @P2=20 @P13=4 @P33=5]
V.E.MEAS_X = V.CYC.SysRetX
V.E.MEAS_Y = V.CYC.SysRetY
M30
"""


@pytest.mark.req("CY-04", "CY-05", "H-07")
@pytest.mark.hli(machine=PROBE_MACHINE)
def test_the_harness_sets_the_deviation_the_plc_reads_the_measured_part(hli: Harness) -> None:
    assert hli.set_probe_deviation(X=0.4, Y=-0.2) == {"X": 0.4, "Y": -0.2, "Z": 0.0}
    hli.step(1)  # the image is published each cycle
    assert hli.image["gpVEGlob^DEV_X"] == pytest.approx(0.4)  # the PLC sees the X deviation it could set
    hli.load_program(1, SPIGOT, name="spigot")
    hli.operator.start(1)
    ended = (ProgramState.FINISHED, ProgramState.ABORTED)
    hli.run_until(lambda: hli.image[PROGRAM_STATE] in ended, max_cycles=50_000)
    assert hli.image[PROGRAM_STATE] == ProgramState.FINISHED, hli.runtime.machine.alarm_history
    assert hli.image["gpVEGlob^MEAS_X"] == pytest.approx(50.4, abs=1e-4)
    assert hli.image["gpVEGlob^MEAS_Y"] == pytest.approx(19.8, abs=1e-4)
    # the PLC moves the part: the next measurement follows its V.E. variable
    hli.image["gpVEGlob^DEV_X"] = -1.0
    hli.step(2)
    assert hli.probe_deviation()["X"] == pytest.approx(-1.0)


@pytest.mark.req("CY-04", "H-12")
@pytest.mark.slow
def test_the_remote_harness_sets_the_deviation_over_http() -> None:
    """``pytest --hli-url``'s harness has the same calls: over the server's HTTP API, in mm."""
    proc = start_server("--clock", "stepped", "--http-port", "0", "--no-modbus")
    try:
        with RemoteHarness(read_banner(proc, timeout=90)["url"]) as hli:
            assert hli.set_probe_deviation(X=0.25, Z=-0.5) == {"X": 0.25, "Y": 0.0, "Z": -0.5}
            assert hli.probe_deviation() == {"X": 0.25, "Y": 0.0, "Z": -0.5}
            with pytest.raises(NotFoundError):
                hli.set_probe_deviation(Q=1.0)
    finally:
        stop_server(proc)
