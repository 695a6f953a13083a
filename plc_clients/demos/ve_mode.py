"""V.E. variables: the PLC selects what a running NC program does, and sees what it did (N-05).

External variables are how PLC and NC programs talk in the kernel (programming manual, "External
variables (V.E.)", https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/207988747.html;
the PLC's side: gpVECh[i]^ / gpVEGlob^). The demo machine declares three (``hli-server map``):

* ``V.E.PLC_READY`` (BOOLEAN): the program waits for it in a ``$WHILE`` loop;
* ``V.E.MODE`` (SGN32): 1 = pocket, 2 = contour; the program branches on it with ``$IF`` and calls
  the subprogram ``pocket.nc`` or ``contour.nc`` (``L name``, uploaded with the program);
* ``V.E.PART_COUNT`` (UNS32): the program counts its parts in it, from 0 (it sets it at its start: the
  variable keeps its value from one run to the next); the PLC reads it.

All three lie in the global area (``gpVEGlob^``), which every channel's programs see.

The PLC program, cycle by cycle:

1. writes ``MODE`` and ``PLC_READY`` = FALSE, then starts the program the operator loaded (a rising edge
   of ``mc_command.start_w``);
2. lets the program wait ``release_after`` CNC cycles in its ``$WHILE`` loop, then writes
   ``PLC_READY`` = TRUE;
3. from then on reports every part the program counts (``PART_COUNT``), and finishes with the program.

Its decisions depend on CNC cycles only, so it runs the same over shared memory, Modbus and ADS.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

from plc_clients.demos import Demo
from schemas.wire import ProgramState

if TYPE_CHECKING:
    from plc_clients.task import IoImage

__all__ = ["CONTOUR", "POCKET", "PROGRAM", "VeModeDemo"]

CH = "gpCh[0]^"
PROGRAM_STATE = CH + "bahn_state.program_state_r"
ERROR_ID = CH + "bahn_state.error_id_r"
START = CH + "mc_command.start_w"
READY = "gpVEGlob^PLC_READY"
MODE = "gpVEGlob^MODE"
PART_COUNT = "gpVEGlob^PART_COUNT"

PROGRAM = """\
%ve_mode
(the PLC selects V.E.MODE and releases the program with V.E.PLC_READY)
N10 G90 G17 G00 X0 Y0 Z0
N15 V.E.PART_COUNT = 0              ( a new batch: the count of a run before stays otherwise
N20 $WHILE V.E.PLC_READY == 0       ( wait for the PLC
N30 $ENDWHILE
N40 $FOR P1 = 1, 3, 1               ( three parts, 30 mm apart
N50   G00 X[P1 * 30] Y0
N60   $IF V.E.MODE == 1
N70     L pocket.nc
N80   $ELSE
N90     L contour.nc
N100  $ENDIF
N110  V.E.PART_COUNT = V.E.PART_COUNT + 1
N120  #MSG SAVE["part %d done", V.E.PART_COUNT]
N130 $ENDFOR
N140 G00 X0 Y0
N150 M30
"""
"""The main program (the README's tour shows it)."""

POCKET = """\
%pocket
(a 10 x 10 mm pocket around the point where it is called, 2 mm deep)
N10 G91 G01 Z-2 F6000
N20 X5 Y5
N30 X-10
N40 Y-10
N50 X10
N60 Y10
N70 X-5 Y-5
N80 Z2
N90 G90
N100 M17
"""

CONTOUR = """\
%contour
(a circle of radius 5 mm beside the point where it is called)
N10 G91 G01 X5 F6000
N20 G02 X0 Y0 I-5 J0
N30 G01 X-5
N40 G90
N50 M17
"""


class VeModeDemo(Demo):
    """N-05: the PLC selects ``V.E.MODE`` and releases the program; it counts parts in ``PART_COUNT``."""

    name = "ve-mode"
    document = "V.E."
    summary = "the PLC sets V.E.MODE and V.E.PLC_READY; the NC program waits, branches and counts parts"
    channel = 1
    nc_program: ClassVar[str] = PROGRAM
    nc_files: ClassVar[dict[str, str]] = {"pocket.nc": POCKET, "contour.nc": CONTOUR}

    def __init__(
        self, printer: Callable[[str], object] | None = None, *, mode: int = 1, release_after: int = 200
    ) -> None:
        super().__init__(printer)
        self.mode = mode
        self.release_after = release_after
        self.started_at: int | None = None
        self.released_at: int | None = None
        self.parts = 0
        self.watch = (PROGRAM_STATE, ERROR_ID, PART_COUNT)

    def __call__(self, io: IoImage) -> None:
        if self.done:
            return
        state = io.read(PROGRAM_STATE)
        if self.step == "start":  # a rising edge of start_w: low in this cycle, high in the next
            io.write(MODE, self.mode)
            io.write(READY, False)
            io.write(START, False)
            io.write(CH + "mc_command.program_select_w", 0)  # keep the operator's program
            self.step = "starting"
            return
        if self.step == "starting":
            io.write(START, True)
            if state == ProgramState.ABORTED:
                io.write(START, False)
                error = int(io.read(ERROR_ID))
                self.finish(
                    io,
                    f"the program was refused at its start: alarm {error} (`hli-server alarms`)",
                    failed=True,
                )
                return
            if state == ProgramState.RUNNING:
                io.write(START, False)
                self.started_at = io.cycle
                what = "pocket" if self.mode == 1 else "contour"
                self.say(
                    io, f"program started with V.E.MODE = {self.mode} ({what}); it waits for V.E.PLC_READY"
                )
                self.step = "waiting"
            return
        if (
            self.step == "waiting"
            and self.started_at is not None
            and io.cycle - self.started_at >= self.release_after
        ):
            io.write(READY, True)
            self.released_at = io.cycle
            self.say(io, "V.E.PLC_READY = TRUE: the program is released")
            self.step = "running"
        if self.step == "running":  # the program counts from its release on (the count before is 0)
            count = int(io.read(PART_COUNT))
            if count != self.parts:
                self.parts = count
                self.say(io, f"part {count} done (V.E.PART_COUNT = {count})")
        if state == ProgramState.FINISHED:
            self.finish(io, f"program finished: {self.parts} parts")
        elif state == ProgramState.ABORTED:
            self.finish(io, f"the program was aborted: alarm {int(io.read(ERROR_ID))}", failed=True)
