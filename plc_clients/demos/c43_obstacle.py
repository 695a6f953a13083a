"""FCT-C43's use case: an obstacle in the work space limits axis X for as long as it is there (C43-10).

FCT-C43, section 1: "Ein möglicher Anwendungsfall ist das Einschränken des Verfahrbereichs einer
Achse wegen eines Hindernisses innerhalb des Arbeitsraums der Achse", and section 2: the function
suits limits caused by events "z.B. durch einen Sensor, während des Programmablaufs" and of limited
duration; "Wird die Begrenzung durch die SPS aufgehoben, wird das Bearbeitungsprogramm fortgesetzt."

The PLC program, cycle by cycle:

1. starts the NC program the operator loaded (a rising edge of ``mc_command.start_w``): X goes home,
   then (block N20) toward +100 mm;
2. reads the obstacle sensor. The sensor is simulated: it reports an obstacle from
   ``obstacle_from`` to ``obstacle_until`` CNC cycles after X set off toward it (block N20 began;
   a light curtain that someone walks through). While it does, ``MCV_DynPosLimitHigh`` holds X
   below ``limit``;
3. the CNC brakes X so that it stops at the limit (``state_r`` ACTIVE_BRAKING, then ACTIVE_BRAKE)
   and holds the program there (C43-04, C43-06);
4. the obstacle leaves: Enable FALSE lifts the limit, the program goes on (C43-07) and finishes.

The sensor counts CNC cycles (the input image's ``io.cycle``), not PLC cycles or seconds, so the
scenario is the same, cycle for cycle, whichever door the PLC uses and however fast its task runs.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

from plc_clients.demos import Demo
from plc_clients.plcopen import AXIS_REF, DynPosLimitState, MCV_DynPosLimitHigh
from schemas.wire import ProgramState

if TYPE_CHECKING:
    from plc_clients.task import IoImage

__all__ = ["ObstacleDemo"]

CH = "gpCh[0]^"
PROGRAM_STATE = CH + "bahn_state.program_state_r"
BLOCK = CH + "bahn_state.block_nr_r"
START = CH + "mc_command.start_w"


class ObstacleDemo(Demo):
    """FCT-C43: hold X below ``limit`` (0.1 µm) while the simulated obstacle sensor reports one."""

    name = "c43-obstacle"
    document = "FCT-C43"
    summary = "an obstacle limits X with MCV_DynPosLimitHigh; the program holds, then finishes"
    channel = 1
    nc_program: ClassVar[str] = (
        "N10 G90 G00 X0 Y0 (home)\nN20 G01 X100 F6000 (toward the obstacle's side)\nN30 M30\n"
    )
    approach_block: ClassVar[int] = 20
    """The obstacle sensor's clock starts when this block (N number) becomes active."""

    def __init__(
        self,
        printer: Callable[[str], object] | None = None,
        *,
        axis: str = "X",
        limit: int = 500_000,
        obstacle_from: int = 100,
        obstacle_until: int = 1000,
    ) -> None:
        super().__init__(printer)
        self.axis_name = axis
        self.limit = limit
        self.obstacle_from = obstacle_from
        self.obstacle_until = obstacle_until
        self.block = MCV_DynPosLimitHigh()
        self.axis: AXIS_REF | None = None
        self.position = ""
        self.started_at: int | None = None
        self.obstacle = False
        self.held = False
        self.watch = (PROGRAM_STATE, BLOCK)

    def obstacle_present(self, cycle: int) -> bool:
        """The simulated sensor: TRUE from ``obstacle_from`` to ``obstacle_until`` CNC cycles after X
        set off toward the obstacle."""
        if self.started_at is None:
            return False
        since = cycle - self.started_at
        return self.obstacle_from <= since < self.obstacle_until

    def __call__(self, io: IoImage) -> None:
        if self.done:
            return
        if self.axis is None:
            self.axis = AXIS_REF.by_name(io.layout, self.axis_name)
            self.position = f"gpAx[{self.axis.index}]^ipo_state.cmd_pos_r"
            io.add_watch(self.position)
        state = io.read(PROGRAM_STATE)
        if self.step == "start":  # a rising edge of start_w: low in this cycle, high in the next
            io.write(START, False)
            io.write(CH + "mc_command.program_select_w", 0)  # keep the operator's program (0 = no selection)
            self.step = "starting"
        elif self.step == "starting":
            io.write(START, True)
            if state == ProgramState.RUNNING:
                io.write(START, False)
                self.say(io, "program started; watching the obstacle sensor")
                self.step = "running"
        if self.step != "running":
            return
        if self.started_at is None and io.read(BLOCK) == self.approach_block:
            self.started_at = io.cycle
        present = self.obstacle_present(io.cycle)
        if present != self.obstacle:
            self.obstacle = present
            if present:
                self.say(
                    io, f"obstacle entered: MCV_DynPosLimitHigh keeps {self.axis_name} <= {_mm(self.limit)}"
                )
            else:
                self.say(io, "obstacle left: the limit is lifted")
        block = self.block(Axis=self.axis, Enable=present, Position=self.limit)
        if block.Error:
            self.finish(
                io, f"MCV_DynPosLimitHigh error 0x{block.ErrorID:04X}: {block.ErrorText}", failed=True
            )
            return
        where = f"{self.axis_name} = {_mm(int(io.read(self.position)))}"
        if block.MonitoringState == DynPosLimitState.ACTIVE_BRAKE and not self.held:
            self.held = True
            self.say(io, f"{self.axis_name} stopped at the limit in effect, {_mm(int(block.State))}: {where}")
        if state == ProgramState.FINISHED:
            self.finish(io, f"program finished: {where}")
        elif state == ProgramState.ABORTED:
            self.finish(io, "the program was aborted (see the CNC's alarms)", failed=True)


def _mm(value: int) -> str:
    return f"{value / 10_000:.3f} mm"
