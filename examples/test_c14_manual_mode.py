"""FCT-C14 in manual mode: the PLC suppresses the work area monitoring to jog out and back in.

The PLC program is ``plc_clients.demos.c14_manual_mode.ManualModeDemo`` (``hli-plc c14-manual``):
after the operator's NC program has defined and switched on a work area of +-50 mm, the PLC switches
to manual mode and jogs X+: X stops before the boundary without an error and
``area_mon_violation_detected_r`` goes TRUE. The PLC then sets the control unit
``suppress_area_mon_manual_mode``, jogs out to 60 mm and back, lifts the suppression, and the next
jog stops at the boundary again (FCT-C14, sections 5 and 6.3).
"""

from __future__ import annotations

import pytest

from plc_clients import PlcTask
from plc_clients.demos.c14_manual_mode import ManualModeDemo

pytestmark = pytest.mark.req("C14-19", "C14-21", "C14-22", "H-06", "H-07")

X = "gpAx[0]^ipo_state.cmd_pos_r"
VIOLATION = "gpCh[0]^bahn_state.area_mon_violation_detected_r"
SUPPRESSED = "gpCh[0]^bahn_mc_control.suppress_area_mon_manual_mode.state_r"
MODE = "gpCh[0]^bahn_state.mode_r"
BOUNDARY = 500_000  # the work area ends at X = 50 mm


def test_suppression_lets_x_out_of_the_work_area_and_back_only_while_it_is_set(hli, plc_transport):
    demo = ManualModeDemo()
    hli.operator.load_program(demo.channel, demo.nc_program)
    task = PlcTask(plc_transport, 0.001, demo, watch=demo.watch)
    with hli.trace(X, VIOLATION, SUPPRESSED, MODE) as recording:
        hli.run_until(lambda: demo.done, max_cycles=4000, plc=task)
    trace = recording.trace()
    assert not demo.failed, demo.log
    x, suppressed, manual = trace[X], trace[SUPPRESSED], trace[MODE] == 1

    # monitored (not suppressed): the jog never takes X over the boundary, and no alarm is raised
    assert x[manual & ~suppressed].max() < BOUNDARY
    assert hli.operator.alarms()["active"] == []
    # the PLC sees the stop at the boundary: area_mon_violation_detected_r, twice (C14-22)
    rising = (trace[VIOLATION][1:] & ~trace[VIOLATION][:-1]).sum()
    assert rising >= 2
    # suppressed: X leaves the work area and comes back (FCT-C14 5, P-CHAN-00442 = 0)
    assert x[suppressed].max() >= demo.outside
    steps = [
        "work area +-50 mm defined and active",
        "manual mode; jog X+",
        "X stopped before the boundary",
        "suppress_area_mon_manual_mode on",
        "X = 60.",
        "back inside",
        "X stopped at the boundary again",
        "back in automatic mode",
    ]
    assert len(demo.log) == len(steps), demo.log
    assert all(text.startswith(step) for (_, text), step in zip(demo.log, steps, strict=True)), demo.log
