"""FCT-C3 from the PLC's side: read the collision objects, stop approaching slides before the CNC must.

FCT-C3, section 2: when the distance of a collision pair, less the braking distances, falls below
the minimum, "stoppen die Achsen sofort ... und die CNC gibt die Meldung P-ERR-70092 aus"; the stop
generally leaves the programmed contour and the program is aborted. Section 4.3 publishes what the
monitor sees as CNC objects (``dyn_coll_mon``: active, velocity [0.1 µm/s], brake_dist, coll_offset
[0.1 µm], deceleration), in the image as ``gpAx[i]^dyn_coll_mon.*`` (and over ADS on port 551).

A PLC that reads them can do better than the error: hold the path with feedhold early enough that
the pair comes to rest outside the minimum distance, on the contour, with the program only held.
The gantry of the demo machine, X1 and X2 on one rail (minimum distance 20 mm), runs the operator's
program that drives the carriages toward each other. Every cycle the PLC program

1. reads ``dyn_coll_mon.active``, ``.velocity`` of X1 and X2, ``.coll_offset`` of the pair and the
   commanded positions;
2. predicts where the pair would rest if it held the path now: the distance, less the way each
   carriage needs to stop under feedhold (the channel's feedhold deceleration, shared along the
   path: ``|v_i| * |v| / (2 a_feedhold)``), less what the pair closes until the CNC brakes: the
   CNC cycles between two runs of the PLC task (the task decides once per cycle; measured from
   ``io.cycle``, the most seen) plus ``latch_cycles`` until the CNC has latched the feedhold;
3. sets the channel's feedhold control unit (``ControlBoolUnit``) when that rest distance comes
   within ``margin`` of the minimum; reports where the carriages stopped;
4. after ``hold_cycles`` resets the channel (``mc_command.reset_w``) and releases the feedhold.

The PLC knows two machine parameters, as a PLC programmer does: the feedhold deceleration of the
gantry channel (1000 mm/s² on the demo machine) and the CNC cycle time (1 ms).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

from plc_clients.demos import Demo
from plc_clients.plcopen import AXIS_REF, ControlBoolUnit
from schemas.wire import ProgramState

if TYPE_CHECKING:
    from plc_clients.task import IoImage

__all__ = ["CollisionDemo"]

APPROACH = """\
N10 G90 G00 X1=0 X2=500 (apart first: from wherever the last run left them)
N20 G01 X1=300 X2=310 F12000 (the carriages close in on each other: 10 mm apart at the end)
N30 M30
"""


class CollisionDemo(Demo):
    """FCT-C3: hold the gantry's carriages X1/X2 with feedhold before the CNC's error 70092."""

    name = "c3-collision"
    document = "FCT-C3"
    summary = "the PLC reads dyn_coll_mon of X1/X2 and holds the approaching carriages before error 70092"
    channel = 2
    nc_program: ClassVar[str] = APPROACH

    def __init__(
        self,
        printer: Callable[[str], object] | None = None,
        *,
        partner: str = "X1",
        master: str = "X2",
        third: str = "Z1",
        feedhold_deceleration: float = 1000.0,
        cycle_time_s: float = 0.001,
        latch_cycles: int = 2,
        margin: int = 20_000,
        hold_cycles: int = 200,
    ) -> None:
        super().__init__(printer)
        self.names = (partner, master, third)
        self.a_feedhold = feedhold_deceleration * 10_000.0  # mm/s² -> 0.1 µm/s²
        self.t_a = cycle_time_s
        self.latch_cycles = latch_cycles
        self.task_cycles = 1
        """CNC cycles between two runs of the PLC task (the most seen)."""
        self.last_cycle: int | None = None
        self.margin = margin
        self.hold_cycles = hold_cycles
        self.ready = False
        self.held_at = 0
        self.min_gap = math.inf
        self.feedhold: ControlBoolUnit | None = None

    def _paths(self, io: IoImage) -> None:
        layout = io.layout
        axes = [AXIS_REF.by_name(layout, name) for name in self.names]
        channel = next(c for c in layout.channels if self.names[0] in c.axes)
        ch = f"gpCh[{channel.index}]^"
        self.program_state = ch + "bahn_state.program_state_r"
        self.error_id = ch + "bahn_state.error_id_r"
        self.start = ch + "mc_command.start_w"
        self.reset = ch + "mc_command.reset_w"
        self.select = ch + "mc_command.program_select_w"
        self.feedhold = ControlBoolUnit(ch + "bahn_mc_control.feedhold")
        p, m, z = (f"gpAx[{a.index}]^" for a in axes)
        self.pos = (p + "ipo_state.cmd_pos_r", m + "ipo_state.cmd_pos_r")
        self.vel = (p + "dyn_coll_mon.velocity", m + "dyn_coll_mon.velocity", z + "ipo_state.velocity_r")
        self.active = m + "dyn_coll_mon.active"
        self.coll_offset = m + "dyn_coll_mon.coll_offset"
        self.watch = (self.program_state, self.error_id, *self.pos, *self.vel, self.active, self.coll_offset)
        for path in self.watch:
            io.add_watch(path)
        self.ready = True

    def rest_gap(self, io: IoImage) -> tuple[float, float]:
        """``(distance now, distance at rest if the PLC held the path now)`` in 0.1 µm.

        Each carriage goes on at its velocity until the CNC brakes (the latency), then brakes under
        feedhold along the path: ``|v_i| * |v| / (2 a_feedhold)`` in its direction of motion."""
        x1, x2 = (float(io.read(p)) for p in self.pos)
        v1, v2, vz = (float(io.read(p)) for p in self.vel)
        speed = math.sqrt(v1 * v1 + v2 * v2 + vz * vz)
        latency_s = (self.task_cycles + self.latch_cycles) * self.t_a
        rest = [
            x + v * latency_s + math.copysign(abs(v) * speed / (2.0 * self.a_feedhold), v)
            for x, v in ((x1, v1), (x2, v2))
        ]
        return abs(x2 - x1), abs(rest[1] - rest[0])

    def __call__(self, io: IoImage) -> None:
        if self.done:
            return
        if not self.ready:
            self._paths(io)
        assert self.feedhold is not None
        if self.last_cycle is not None:
            self.task_cycles = max(self.task_cycles, io.cycle - self.last_cycle)
        self.last_cycle = io.cycle
        hold = self.step in ("holding", "held")
        unit = self.feedhold(Enable=hold, Command=hold)
        state = io.read(self.program_state)
        error = int(io.read(self.error_id))
        if error:
            self.finish(io, f"the CNC raised error {error}: the PLC was too late", failed=True)
            return
        gap, at_rest = self.rest_gap(io)
        self.min_gap = min(self.min_gap, gap)
        if self.step == "start":
            io.write(self.start, False)
            io.write(self.select, 0)  # keep the operator's program (0 = no selection)
            self.step = "starting"
        elif self.step == "starting":
            io.write(self.start, True)
            if state == ProgramState.RUNNING:
                io.write(self.start, False)
                self.say(io, f"program started; collision monitoring active: {bool(io.read(self.active))}")
                self.step = "watching"
        elif self.step == "watching":
            offset = int(io.read(self.coll_offset))
            if at_rest <= offset + self.margin:
                self.say(
                    io,
                    f"feedhold: distance {_mm(gap)}, at rest it would be {_mm(at_rest)} "
                    f"(minimum {_mm(offset)} + margin {_mm(self.margin)})",
                )
                self.step = "holding"
            elif state == ProgramState.FINISHED:
                self.finish(io, "the program ended without the carriages coming close")
        elif self.step == "holding":
            v1, v2 = (float(io.read(p)) for p in self.vel[:2])
            if unit.Valid and v1 == 0.0 and v2 == 0.0:
                self.held_at = io.cycle
                self.say(
                    io,
                    f"carriages at rest {_mm(gap)} apart (minimum {_mm(int(io.read(self.coll_offset)))}), "
                    "program held, no error 70092",
                )
                self.step = "held"
        elif self.step == "held":
            if io.cycle - self.held_at >= self.hold_cycles:
                io.write(self.reset, True)
                self.step = "reset"
        elif self.step == "reset":
            io.write(self.reset, False)
            if state in (ProgramState.IDLE, ProgramState.ABORTED) and not unit.Valid:
                self.finish(io, "channel reset, feedhold released")


def _mm(value: float) -> str:
    return f"{value / 10_000:.3f} mm"
