"""FCT-C43's use case, tested through every PLC door: an obstacle limits X for as long as it is there.

The PLC program is ``plc_clients.demos.c43_obstacle.ObstacleDemo`` (``hli-plc c43-obstacle`` runs it
against a live server): while a simulated sensor reports an obstacle, ``MCV_DynPosLimitHigh`` keeps X
below 50 mm; the NC program moving X to 100 mm holds at the limit, and finishes once the obstacle
has left and the PLC lifted the limit (FCT-C43, sections 1 and 2).

The test runs the same PLC program over shared memory, Modbus and ADS (the ``plc_transport``
fixture) and checks that the machine does the same thing, cycle for cycle, whatever the door.
"""

from __future__ import annotations

import numpy as np
import pytest

from hli_server.testing import Harness
from plc_clients import PlcTask
from plc_clients.demos.c43_obstacle import ObstacleDemo

pytestmark = pytest.mark.req("C43-03", "C43-04", "C43-06", "C43-07", "C43-10", "H-06", "H-07")

X = "gpAx[0]^ipo_state.cmd_pos_r"
UNIT = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high"
PROGRAM_STATE = "gpCh[0]^bahn_state.program_state_r"
TRACED = (X, f"{UNIT}.enable_w", f"{UNIT}.state_r", PROGRAM_STATE)
LIMIT = 500_000  # 50 mm in 0.1 µm
ONE_CYCLE = 1_000  # X's travel in one 1 ms cycle at F6000 (100 mm/s), in 0.1 µm
FINISHED = 4


def run_obstacle(hli: Harness, transport: object) -> tuple[ObstacleDemo, object]:
    """The operator loads the demo's NC program; the PLC does the rest, cycle by cycle with the CNC."""
    demo = ObstacleDemo(limit=LIMIT)
    hli.operator.load_program(demo.channel, demo.nc_program)
    task = PlcTask(transport, 0.001, demo, watch=demo.watch)
    with hli.trace(*TRACED) as recording:
        hli.run_until(lambda: demo.done, max_cycles=3000, plc=task)
    return demo, recording.trace()


@pytest.fixture(scope="module")
def over_shared_memory() -> tuple[ObstacleDemo, object]:
    """The reference run: the same scenario over shared memory, in a harness of its own."""
    with Harness() as hli:
        return run_obstacle(hli, hli.transport("shm"))


def test_the_obstacle_holds_x_at_the_limit_and_the_program_finishes_after_it(hli, plc_transport):
    demo, trace = run_obstacle(hli, plc_transport)
    assert not demo.failed, demo.log
    x, enabled, state = trace[X], trace[f"{UNIT}.enable_w"], trace[f"{UNIT}.state_r"]

    # the CNC's states, in order: INACTIVE, ACTIVATION, ACTIVE, ACTIVE_BRAKING, ACTIVE_BRAKE, INACTIVE
    changes = state[np.flatnonzero(np.diff(state, prepend=-1))]
    assert changes.tolist() == [0, 1, 2, 3, 4, 0]
    # while the limit is in effect X never passes it by more than one cycle's travel (C43-06)
    assert x[state >= 2].max() <= LIMIT + ONE_CYCLE
    # ... it stops there (ACTIVE_BRAKE) and stays while the obstacle is there (C43-04)
    held = x[state == 4]
    assert len(held) > 300
    assert held.min() == held.max() >= LIMIT - ONE_CYCLE
    # the PLC lifts the limit: the program goes on and finishes at X = 100 mm (C43-07)
    assert not enabled[-1]
    assert (trace[PROGRAM_STATE][-1], x[-1]) == (FINISHED, 1_000_000)
    steps = ["program started", "obstacle entered", "X stopped at", "obstacle left", "program finished"]
    assert len(demo.log) == len(steps), demo.log
    assert all(text.startswith(step) for (_, text), step in zip(demo.log, steps, strict=True)), demo.log


def test_every_door_gives_the_same_run_cycle_for_cycle(hli, plc_transport, over_shared_memory):
    demo, trace = run_obstacle(hli, plc_transport)
    reference_demo, reference = over_shared_memory
    assert demo.log == reference_demo.log  # the same decisions in the same CNC cycles
    assert trace.to_json() == reference.to_json()  # the same machine, every cycle
