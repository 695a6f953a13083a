"""MCV_DynPosLimitHigh in a PLC task stops a running program at the limit, through every transport
(C43-10, H-06; FCT-C43 3.2 with C43-04/06/07 as the server implements them).

One behaviour, run over each door to the same server (asyncua's ``opc`` fixture is the model): the
project's pytest plugin gives the server (``hli``: the real runtime, demo machine, stepped clock)
and the door (``plc_transport``: shared memory, Modbus TCP, ADS). The PLC task and the CNC run in
lock-step (``hli.run_until(..., plc=task)``), so the block's outputs are checked to the cycle.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from hli_server.testing import Harness
from plc_clients import AXIS_REF, IoImage, MCV_DynPosLimitHigh, PlcTask, Transport
from schemas.wire import ProgramState

pytestmark = [pytest.mark.req("C43-10", "H-06"), pytest.mark.timeout(60)]

UNIT = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high"
X_POS = "gpAx[0]^ipo_state.cmd_pos_r"
X_MOVING = "gpAx[0]^ipo_state.moving_r"
PROGRAM_STATE = "gpCh[0]^bahn_state.program_state_r"
LIMIT = 500_000  # 50 mm in 0.1 µm
TARGET = 2_000_000  # the program moves X toward +200 mm
FEED = 6000.0  # mm/min


@dataclass
class Observed:
    """What the PLC program saw, cycle by cycle (as a PLC would log it)."""

    states: list[int] = field(default_factory=list)
    valid: bool = False
    state: int = 0
    x: int = 0
    moving: bool = True
    program_state: int = 0
    limit: int = 0

    def state_path(self) -> list[int]:
        """The states in the order seen, without repeats."""
        path: list[int] = []
        for s in self.states:
            if not path or path[-1] != s:
                path.append(s)
        return path


def test_dyn_pos_limit_high_stops_x_at_the_limit_and_lifting_it_lets_the_program_finish(
    hli: Harness, plc_transport: Transport
) -> None:
    x_axis = AXIS_REF.by_name(plc_transport.layout, "X")
    limit = MCV_DynPosLimitHigh()
    seen = Observed()
    enable = [True]

    def program(io: IoImage) -> None:
        limit(Axis=x_axis, Enable=enable[0], Position=LIMIT)
        seen.states.append(int(limit.MonitoringState))
        seen.valid, seen.state, seen.limit = limit.Valid, int(limit.MonitoringState), int(limit.State)
        seen.x = int(io.read(X_POS))
        seen.moving = bool(io.read(X_MOVING))
        seen.program_state = int(io.read(PROGRAM_STATE))

    task = PlcTask(plc_transport, 0.001, program, watch=[X_POS, X_MOVING, PROGRAM_STATE])

    # 1. the block sets the limit; the CNC reports it in effect
    hli.run_until(lambda: seen.valid, max_cycles=20, plc=task)
    assert not limit.Error, limit.ErrorText
    assert seen.state == 2  # MonitoringState: HLI_DYNPL_STATE_ACTIVE
    assert seen.limit == LIMIT  # State: "Aktueller Positionsgrenzwert" (FCT-C43 3.2)
    unit = hli.runtime.machine.hli.axes[0].ipo_mc_control.dyn_pos_limit_high
    assert (unit.enable_w, unit.command_w) == (True, LIMIT)

    # 2. a program moves X toward +200 mm; the limit holds it at 50 mm
    hli.operator.load_program(1, f"N10 G90 G01 X{TARGET / 10_000:g} F{FEED:g}\nN20 M30\n", "toward_200")
    hli.operator.start(1)
    seen.states.clear()
    hli.run_until(lambda: seen.state == 4 and not seen.moving, max_cycles=2000, plc=task)
    assert seen.valid
    path = seen.state_path()
    assert path[-3:] == [2, 3, 4], f"state_r seen by the block: {path}"  # ACTIVE, BRAKING, BRAKE
    one_cycle = FEED / 60.0 * hli.t_a * 10_000  # travel of one CNC cycle at F, in 0.1 µm
    assert LIMIT - one_cycle <= seen.x <= LIMIT + one_cycle  # C43-06 / FCT-C43 3.2: at most one cycle
    assert seen.program_state in (ProgramState.RUNNING, ProgramState.HELD)  # held, not finished

    # it stays there while the limit is in effect
    stopped_at = seen.x
    cycles_before = task.stats.cycles
    hli.run_until(lambda: task.stats.cycles >= cycles_before + 100, max_cycles=100, plc=task)
    assert seen.x == stopped_at
    assert (seen.state, seen.valid) == (4, True)

    # 3. Enable FALSE lifts the limit: the program continues to its end (C43-07)
    enable[0] = False
    hli.run_until(
        lambda: seen.program_state == ProgramState.FINISHED and seen.x == TARGET, max_cycles=3000, plc=task
    )
    assert (limit.Valid, limit.State, limit.MonitoringState, limit.Error, limit.ErrorID) == (
        False,
        0,
        0,
        False,
        0,
    )
    assert unit.enable_w is False
    assert unit.state_r == 0
    assert task.stats.input_faults == task.stats.output_faults == 0
