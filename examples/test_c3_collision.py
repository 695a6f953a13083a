"""FCT-C3 from the PLC's side: the PLC reads the collision objects and stops the carriages itself.

The gantry of the demo machine (X1 and X2 on one rail, minimum distance 20 mm) runs a program that
drives the carriages toward each other. Without a PLC the CNC's collision monitor stops both with
error 70092 and aborts the program (FCT-C3, section 2). The PLC program
``plc_clients.demos.c3_collision.CollisionDemo`` (``hli-plc c3-collision``) reads ``dyn_coll_mon``
(velocity, coll_offset: FCT-C3 4.3) every cycle, predicts where the pair would come to rest under
feedhold, and holds the path early enough: the carriages stop outside the minimum distance, on the
contour, without the error.
"""

from __future__ import annotations

import pytest

from plc_clients import PlcTask
from plc_clients.demos.c3_collision import CollisionDemo

pytestmark = pytest.mark.req("C3-01", "C3-10", "H-06", "H-07")

X1, X2 = "gpAx[3]^ipo_state.cmd_pos_r", "gpAx[4]^ipo_state.cmd_pos_r"
ERROR = "gpCh[1]^bahn_state.error_id_r"
PROGRAM_STATE = "gpCh[1]^bahn_state.program_state_r"
MINIMUM = 200_000  # coll_offset of the pair: 20 mm
COLLISION_ERROR = 70092
HELD = 2


def test_without_the_plc_the_cnc_stops_the_pair_with_error_70092(hli):
    hli.operator.load_program(CollisionDemo.channel, CollisionDemo.nc_program)
    hli.operator.start(CollisionDemo.channel)
    hli.run_until(lambda: hli.image[ERROR] == COLLISION_ERROR, max_cycles=3000)
    hli.step(300)  # both carriages brake to a stop with a_max
    assert abs(hli.image[X2] - hli.image[X1]) >= MINIMUM


def test_the_plc_holds_the_carriages_outside_the_minimum_distance_without_the_error(hli, plc_transport):
    demo = CollisionDemo()
    hli.operator.load_program(demo.channel, demo.nc_program)
    task = PlcTask(plc_transport, 0.001, demo, watch=demo.watch)
    with hli.trace(X1, X2, PROGRAM_STATE) as recording:
        hli.run_until(lambda: demo.done, max_cycles=4000, plc=task)
    trace = recording.trace()
    assert not demo.failed, demo.log
    assert COLLISION_ERROR not in [a["id"] for a in hli.operator.alarms(history=1000)["history"]]
    gap = abs(trace[X2] - trace[X1])
    assert gap.min() >= MINIMUM
    assert (trace[PROGRAM_STATE] == HELD).sum() >= demo.hold_cycles  # held on the contour, not aborted
    steps = ["program started", "feedhold", "carriages at rest", "channel reset"]
    assert len(demo.log) == len(steps), demo.log
    assert all(text.startswith(step) for (_, text), step in zip(demo.log, steps, strict=True)), demo.log
