"""FCT-C14 in manual mode: the PLC suppresses the work area monitoring to jog out and back (C14-19..22).

FCT-C14, section 5: in manual mode "Wird eine IMCS / MCS Grenze erreicht stoppen alle Achsen ohne
Fehler vor der Grenze"; with P-CHAN-00442 = 0 "Bei aktivem Handbetrieb kann die
Arbeitsraumüberwachung über das gesetzte Signal der Control Unit [suppress_area_mon_manual_mode]
deaktiviert werden. Es kann dann über die Arbeitsraumgrenzen hinaus- und zurückgefahren werden."
Section 6.3: ``bahn_state.area_mon_violation_detected_r`` tells the PLC that the monitoring caught a
violation.

The operator's NC program defines the work area (a square of +-50 mm in X/Y), activates it and
leaves X at 40 mm. The PLC program then:

1. starts that program and waits for its end;
2. switches to manual mode (``mc_command.mode_w``) and jogs X+ (``manual.jog_plus_w``): X stops
   before the boundary at 50 mm, without an error, and ``area_mon_violation_detected_r`` goes TRUE;
3. sets the control unit ``suppress_area_mon_manual_mode`` (``ControlBoolUnit``, command TRUE) and
   jogs X+ again: now X passes the boundary; at ``outside`` it releases the key;
4. jogs X- back into the area (to ``back_to``), then lifts the suppression (Enable FALSE);
5. jogs X+ once more: the monitoring holds X at the boundary again; back to automatic mode.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

from plc_clients.demos import Demo
from plc_clients.plcopen import AXIS_REF, ControlBoolUnit
from schemas.wire import Mode, ProgramState

if TYPE_CHECKING:
    from plc_clients.task import IoImage

__all__ = ["ManualModeDemo"]

CH = "gpCh[0]^"
PROGRAM_STATE = CH + "bahn_state.program_state_r"
MODE = CH + "bahn_state.mode_r"
VIOLATION = CH + "bahn_state.area_mon_violation_detected_r"
START = CH + "mc_command.start_w"
MODE_W = CH + "mc_command.mode_w"
SUPPRESS = CH + "bahn_mc_control.suppress_area_mon_manual_mode"

WORK_AREA = """\
N10 G90 G17 G01 X0 Y0 Z0 F6000
N20 #CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=-200 MAX_EXCUR=200] (the work area: +-50 mm in X/Y)
N30 G01 X-50 Y-50
N40 X50
N50 Y50
N60 X-50
N70 Y-50
N80 #CONTROL AREA END
N90 #CONTROL AREA ON [ID=1]
N100 G01 X40 Y0
N110 M30
"""


class ManualModeDemo(Demo):
    """FCT-C14: jog to the work area's boundary, suppress the monitoring to leave it and come back."""

    name = "c14-manual"
    document = "FCT-C14"
    summary = "manual mode: the jog stops at the work area; suppress_area_mon_manual_mode lets X out and back"
    channel = 1
    nc_program: ClassVar[str] = WORK_AREA

    def __init__(
        self,
        printer: Callable[[str], object] | None = None,
        *,
        axis: str = "X",
        outside: int = 600_000,
        back_to: int = 400_000,
        settle_cycles: int = 20,
    ) -> None:
        super().__init__(printer)
        self.axis_name = axis
        self.outside = outside
        self.back_to = back_to
        self.settle_cycles = settle_cycles
        self.suppress = ControlBoolUnit(SUPPRESS)
        self.axis: AXIS_REF | None = None
        self.still_since = 0
        self.watch = (PROGRAM_STATE, MODE, VIOLATION, SUPPRESS + ".state_r")

    def _paths(self, io: IoImage) -> None:
        self.axis = AXIS_REF.by_name(io.layout, self.axis_name)
        ax = f"gpAx[{self.axis.index}]^"
        self.position = ax + "ipo_state.cmd_pos_r"
        self.moving = ax + "ipo_state.moving_r"
        self.jog_plus = ax + "manual.jog_plus_w"
        self.jog_minus = ax + "manual.jog_minus_w"
        for path in (self.position, self.moving):
            io.add_watch(path)

    def _stopped(self, io: IoImage) -> bool:
        """X has stood still for ``settle_cycles`` CNC cycles."""
        if io.read(self.moving):
            self.still_since = io.cycle
        return io.cycle - self.still_since >= self.settle_cycles

    def __call__(self, io: IoImage) -> None:
        if self.done:
            return
        if self.axis is None:
            self._paths(io)
        x = int(io.read(self.position))
        step = self.step
        suppressing = step in ("suppress", "jog out", "jog back", "back inside")
        unit = self.suppress(Enable=suppressing, Command=suppressing)
        if unit.Error:
            self.finish(io, f"suppress_area_mon_manual_mode: {unit.ErrorText}", failed=True)
            return
        if io.read(PROGRAM_STATE) == ProgramState.ABORTED:
            self.finish(io, "the program was aborted (see the CNC's alarms)", failed=True)
            return
        if step == "start":
            io.write(START, False)
            io.write(CH + "mc_command.program_select_w", 0)  # keep the operator's program (0 = no selection)
            self.step = "starting"
        elif step == "starting":
            io.write(START, True)
            if io.read(PROGRAM_STATE) == ProgramState.FINISHED:
                io.write(START, False)
                self.say(io, f"work area +-50 mm defined and active; {self.axis_name} = {_mm(x)}")
                io.write(MODE_W, Mode.MANUAL)
                self.step = "manual"
        elif step == "manual":
            if io.read(MODE) == Mode.MANUAL:
                self.say(io, f"manual mode; jog {self.axis_name}+ toward the boundary")
                io.write(self.jog_plus, True)
                self.still_since = io.cycle
                self.step = "to boundary"
        elif step == "to boundary":
            if self._stopped(io) and io.read(VIOLATION):
                io.write(self.jog_plus, False)
                self.say(
                    io,
                    f"{self.axis_name} stopped before the boundary at {_mm(x)}, no error; "
                    "area_mon_violation_detected_r = TRUE",
                )
                self.step = "suppress"
        elif step == "suppress":
            if unit.Valid:
                self.say(
                    io, "suppress_area_mon_manual_mode on: the work area is not monitored in manual mode"
                )
                io.write(self.jog_plus, True)
                self.step = "jog out"
        elif step == "jog out":
            if x >= self.outside:
                io.write(self.jog_plus, False)
                self.say(io, f"{self.axis_name} = {_mm(x)}: outside the work area; jog back")
                self.step = "jog back"
        elif step == "jog back":
            if self._stopped(io):
                io.write(self.jog_minus, True)
                self.step = "back inside"
        elif step == "back inside":
            if x <= self.back_to:
                io.write(self.jog_minus, False)
                self.step = "lift"
        elif step == "lift":
            if self._stopped(io) and not unit.Valid and not io.read(SUPPRESS + ".state_r"):
                self.say(io, f"back inside at {_mm(x)}; suppression lifted: the work area is monitored again")
                io.write(self.jog_plus, True)
                self.still_since = io.cycle
                self.step = "to boundary again"
        elif step == "to boundary again":
            if self._stopped(io) and io.read(VIOLATION):
                io.write(self.jog_plus, False)
                io.write(MODE_W, Mode.AUTOMATIC)
                self.say(io, f"{self.axis_name} stopped at the boundary again at {_mm(x)}")
                self.step = "automatic"
        elif step == "automatic" and io.read(MODE) == Mode.AUTOMATIC:
            self.finish(io, "back in automatic mode")


def _mm(value: int) -> str:
    return f"{value / 10_000:.3f} mm"
