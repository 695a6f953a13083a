"""A channel: mode, program, decoder, path interpolation and jog (E-03, E-05).

Inputs come from two doors, both latched at the start of a cycle: the PLC's HLI fields
(``mc_command``, ``bahn_mc_control``, ``manual``) and the operator's requests (API, CLI, tests:
:meth:`Channel.request_start` and friends). Outputs are published into ``bahn_state`` at the end.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import TYPE_CHECKING, Protocol

from hli_server.engine.axis import Axis
from hli_server.engine.decoder import DecodeError, Decoder
from hli_server.engine.geometry import Point
from hli_server.engine.hli import ChannelHli, ModeRequest, ProgramState
from hli_server.engine.nc.blocks import Block
from hli_server.engine.nc.parser import iter_blocks
from hli_server.engine.planner import Marker, MarkerKind, Planner
from schemas.config import ChannelConfig
from schemas.units import mm_from_increments

if TYPE_CHECKING:
    from hli_server.engine.machine import Machine

__all__ = ["LOOKAHEAD_ITEMS", "Channel", "JogGuard", "Mode"]

LOOKAHEAD_ITEMS = 64
"""Motion blocks decoded ahead of the interpolator (the look-ahead buffer, P-STUP-00070's size)."""


class Mode:
    AUTOMATIC = ModeRequest.AUTOMATIC
    MANUAL = ModeRequest.MANUAL


class JogGuard(Protocol):
    """Asked every cycle in manual mode: would the axes, braking from the next cycle on, stop at
    ``stop_point`` in a forbidden place (C14-19, E-06)? ``path`` is (current, stop_point)."""

    def must_brake(self, channel: Channel, current: Point, stop_point: Point) -> bool: ...


class Channel:
    def __init__(self, machine: Machine, config: ChannelConfig, index: int, axes: list[Axis]) -> None:
        self.machine = machine
        self.config = config
        self.index = index
        self.number = config.number
        self.axes = axes
        self.axis_names = [a.name for a in axes]
        self.hli: ChannelHli = machine.hli.channels[index]
        self.t_a = machine.t_a
        self.mode = Mode.AUTOMATIC
        self.state = ProgramState.IDLE
        self.program_text: str | None = None
        self.program_name = ""
        self.program_number = 0
        zero_offsets: dict[str, dict[str, float]] = {
            str(zo.code): {ax: mm_from_increments(v) for ax, v in zo.offsets.items()}
            for zo in config.zero_offsets
        }
        self.decoder = Decoder(
            self.axis_names,
            config.main_axes,
            {a.name: (a.v_max, a.v_rapid, a.a_max) for a in axes},
            zero_offsets,
        )
        self.planner = Planner(t_a=self.t_a, feedhold_decel=config.feedhold_deceleration)
        self.jog_guards: list[JogGuard] = []
        self.jog_velocity: list[float] = [0.0] * len(axes)
        self.current_block: Block | None = None
        self.aborting = False
        # operator requests (API), latched at the next cycle
        self._req_start = False
        self._req_reset = False
        self._req_mode: int | None = None
        self._req_feedhold: bool | None = None
        self._req_override: int | None = None
        self._req_jog: dict[int, int] = {}
        self._jog_keys: list[int] = [0] * len(axes)
        self._op_feedhold = False
        self._op_override = 1000
        self._prev_start_w = False
        self._prev_reset_w = False
        self._prev_mode_w = ModeRequest.AUTOMATIC
        self.feedhold_active = False
        self.override_permille = 1000

    # --- operator requests ---------------------------------------------------------------
    def load_program(self, text: str, name: str = "program", number: int = 0) -> None:
        """Select a program (text). Refused while a program runs."""
        if self.state in (ProgramState.RUNNING, ProgramState.HELD):
            self.machine.raise_alarm(911021, self, f"cannot load {name!r}: a program is running")
            return
        self.program_text = text
        self.program_name = name
        self.program_number = number
        self.state = ProgramState.IDLE

    def request_start(self) -> None:
        self._req_start = True

    def request_reset(self) -> None:
        self._req_reset = True

    def request_mode(self, mode: int) -> None:
        self._req_mode = mode

    def request_feedhold(self, on: bool) -> None:
        self._req_feedhold = on

    def request_override(self, permille: int) -> None:
        self._req_override = max(0, min(1200, permille))

    def request_jog(self, axis: str, direction: int) -> None:
        """direction +1, -1, or 0 (release the key)."""
        self._req_jog[self.axis_names.index(axis)] = max(-1, min(1, direction))

    # --- positions -----------------------------------------------------------------------
    def setpoints(self) -> list[float]:
        return [a.setpoint for a in self.axes]

    def axis(self, name: str) -> Axis:
        return self.axes[self.axis_names.index(name)]

    # --- the cycle -----------------------------------------------------------------------
    def latch_inputs(self) -> None:
        hli = self.hli
        cmd = hli.mc_command
        if self._req_reset or (cmd.reset_w and not self._prev_reset_w):
            self.reset()
        self._prev_reset_w = cmd.reset_w
        self._req_reset = False
        mode_req = self._req_mode
        if cmd.mode_w != self._prev_mode_w:
            mode_req = cmd.mode_w
        self._prev_mode_w = cmd.mode_w
        self._req_mode = None
        if mode_req is not None and mode_req != self.mode:
            self.change_mode(mode_req)
        if cmd.program_select_w and cmd.program_select_w != self.program_number:
            self.select_program(cmd.program_select_w)
        start = self._req_start or (cmd.start_w and not self._prev_start_w)
        self._prev_start_w = cmd.start_w
        self._req_start = False
        if start:
            self.start()
        # feedhold and override: control units; the CNC's own request is the operator's
        if self._req_feedhold is not None:
            self._op_feedhold = self._req_feedhold
            self._req_feedhold = None
        if self._req_override is not None:
            self._op_override = self._req_override
            self._req_override = None
        ctl = hli.bahn_mc_control
        ctl.feedhold.request_r = self._op_feedhold
        ctl.override.request_r = self._op_override
        self.feedhold_active = ctl.feedhold.effective()
        self.override_permille = max(0, min(1200, ctl.override.effective()))
        ctl.feedhold.state_r = self.feedhold_active
        ctl.override.state_r = self.override_permille
        ctl.suppress_area_mon_manual_mode.state_r = ctl.suppress_area_mon_manual_mode.effective()
        for k, direction in self._req_jog.items():
            self._jog_keys[k] = direction
        self._req_jog.clear()

    def select_program(self, number: int) -> None:
        for entry in self.config.programs:
            if entry.number == number:
                text = entry.text
                if text is None and self.machine.read_program is not None and entry.path is not None:
                    try:
                        text = self.machine.read_program(entry.path)
                    except (OSError, UnicodeDecodeError) as exc:
                        self.machine.raise_alarm(
                            911021, self, f"program {number}: cannot read {entry.path}: {exc}"
                        )
                        return
                if text is None:
                    self.machine.raise_alarm(
                        911021, self, f"program {number}: no program text for {entry.path}"
                    )
                    return
                self.load_program(text, entry.name, number)
                return
        self.machine.raise_alarm(911021, self, f"program number {number} is not in the program table")

    def start(self) -> None:
        if self.mode != Mode.AUTOMATIC:
            self.machine.raise_alarm(911021, self, "program start refused: channel is in manual mode")
            return
        if self.state == ProgramState.HELD or (self.state == ProgramState.RUNNING and self.feedhold_active):
            return
        if self.state == ProgramState.RUNNING:
            return
        if self.machine.channel_has_error(self):
            self.machine.raise_alarm(911021, self, "program start refused: reset the error first")
            return
        if self.program_text is None:
            self.machine.raise_alarm(911021, self, "program start refused: no program selected")
            return
        not_referenced = [a.name for a in self.axes if not a.referenced]
        if not_referenced:
            self.machine.raise_alarm(911020, self, f"axes not referenced: {', '.join(not_referenced)}")
            return
        blocks: Iterator[Block] = iter_blocks(self.program_text, self.axis_names)
        self.planner.clear()
        self.decoder.start(blocks, self.setpoints())
        self.aborting = False
        self.current_block = None
        self.state = ProgramState.RUNNING
        self.machine.emit("program_state", self, state="running", program=self.program_name)

    def reset(self) -> None:
        """E-03: stop motion, clear the channel's errors, reset modal state; hooks for the monitors."""
        for axis in self.axes:
            axis.start_independent_stop(axis.a_max, self.t_a)
        self.planner.clear()
        self.decoder.reset_modal()
        self.aborting = False
        self.jog_velocity = [0.0] * len(self.axes)
        self._jog_keys = [0] * len(self.axes)
        self.state = ProgramState.IDLE
        self.current_block = None
        self.machine.on_channel_reset(self)
        self.machine.emit("program_state", self, state="reset")

    def change_mode(self, mode: int) -> None:
        if mode not in (Mode.AUTOMATIC, Mode.MANUAL):
            self.machine.raise_alarm(911021, self, f"unknown mode {mode}")
            return
        if self.state in (ProgramState.RUNNING, ProgramState.HELD):
            self.machine.raise_alarm(911021, self, "mode change refused: a program is running")
            return
        if any(abs(v) > 0 for v in self.jog_velocity):
            self.machine.raise_alarm(911021, self, "mode change refused: axes are jogging")
            return
        if not self.machine.allow_mode_change(self, mode):
            return
        self.mode = mode
        self.machine.emit("mode", self, mode="manual" if mode == Mode.MANUAL else "automatic")

    def abort(self) -> None:
        """Program abort: the path brakes with the feedhold deceleration and the program ends."""
        if self.state in (ProgramState.RUNNING, ProgramState.HELD):
            self.state = ProgramState.ABORTED
            self.aborting = True
            self.machine.emit("program_state", self, state="aborted")

    def interpolate(self) -> None:
        if any(a.stopping for a in self.axes):
            # axes brake on their own (collision, drive error, reset): the path is lost
            self.planner.clear()
            if self.state in (ProgramState.RUNNING, ProgramState.HELD):
                self.abort()
            self.aborting = False
            return
        if self.mode == Mode.MANUAL:
            self._jog()
            return
        if self.state not in (ProgramState.RUNNING, ProgramState.HELD, ProgramState.ABORTED):
            return
        if self.aborting:
            self.planner.feedhold = True
            point, _ = self.planner.step()
            self._apply(point)
            if self.planner.velocity <= 0.0:
                self.planner.clear()
                self.aborting = False
            return
        self._fill()
        self.planner.feedhold = self.feedhold_active
        self.planner.override = self.override_permille / 1000.0
        point, markers = self.planner.step()
        self._apply(point)
        head = self.planner.current()
        if head is not None and head.block is not None:
            self.current_block = head.block
        self.state = (
            ProgramState.HELD
            if self.feedhold_active and self.planner.velocity == 0.0
            else ProgramState.RUNNING
        )
        for marker in markers:
            self._marker(marker)

    def _fill(self) -> None:
        while self.planner.motion_items < LOOKAHEAD_ITEMS and not self.decoder.finished:
            for item in self.decoder.next_items():
                self.planner.push(item)

    def _apply(self, point: Point | None) -> None:
        if point is None:
            return
        for axis, value in zip(self.axes, point, strict=True):
            axis.setpoint = value

    def _marker(self, marker: Marker) -> None:
        if marker.block is not None:
            self.current_block = marker.block
        if marker.kind == MarkerKind.ACTION:
            marker.payload()
        elif marker.kind == MarkerKind.END:
            self.warn_missing_program_end(marker)
            self.state = ProgramState.FINISHED
            self.planner.clear()
            self.machine.emit("program_state", self, state="finished", program=self.program_name)
        elif marker.kind == MarkerKind.ERROR:
            self.raise_decode_error(marker)
            self.state = ProgramState.ABORTED
            self.planner.clear()

    def raise_decode_error(self, marker: Marker) -> None:
        """The alarm an error marker carries, with the line and block of the refused block (or, for
        a line the parser could not read, the place the parser named)."""
        err: DecodeError = marker.payload
        block = marker.block
        line = block.line if block is not None else err.params.get("line")
        label = block.label if block is not None else err.params.get("block")
        self.machine.raise_alarm(
            err.alarm, self, err.message, line=line, block=label, params=err.params, axis=err.axis
        )

    def warn_missing_program_end(self, marker: Marker) -> None:
        """Warning 911005 when the program ran off the end of its text without M30 / M02."""
        if marker.payload == "eof":
            block = marker.block
            self.machine.raise_alarm(
                911005,
                self,
                "program ended at the end of its text without M30 / M02",
                line=block.line if block is not None else None,
                block=block.label if block is not None else None,
            )

    # --- manual mode ---------------------------------------------------------------------
    def _jog(self) -> None:
        """E-05 jog: each axis ramps to its jog velocity while its key is held; guards may brake."""
        t = self.t_a
        req = list(self._jog_keys)
        for k, axis in enumerate(self.axes):
            man = self.machine.hli.axes[axis.index].manual
            if man.jog_plus_w != man.jog_minus_w:
                req[k] = 1 if man.jog_plus_w else -1
        current = tuple(self.setpoints())
        proposed = list(self.jog_velocity)
        for k, axis in enumerate(self.axes):
            target = req[k] * axis.jog_velocity
            v = proposed[k]
            dv = axis.jog_acceleration * t
            proposed[k] = min(v + dv, target) if target > v else max(v - dv, target)
        # where would the axes come to rest if they began braking after this cycle?
        stop_point = tuple(
            p + v * t + math.copysign(v * v / (2.0 * a.jog_acceleration), v)
            for p, v, a in zip(current, proposed, self.axes, strict=True)
        )
        if any(proposed) and any(g.must_brake(self, current, stop_point) for g in self.jog_guards):
            for k, axis in enumerate(self.axes):
                v = self.jog_velocity[k]
                dv = axis.jog_acceleration * t
                proposed[k] = max(0.0, v - dv) if v > 0 else min(0.0, v + dv)
        self.jog_velocity = proposed
        for axis, v in zip(self.axes, proposed, strict=True):
            axis.setpoint += v * t

    # --- outputs -------------------------------------------------------------------------
    def publish(self) -> None:
        st = self.hli.bahn_state
        st.mode_r = self.mode
        st.program_state_r = self.state
        st.program_number_r = self.program_number
        block = self.current_block
        st.block_nr_r = block.number or 0 if block is not None else 0
        st.line_nr_r = block.line if block is not None else 0
        st.feedhold_active_r = self.feedhold_active
        st.cycle_r = self.machine.cycle % (2**31)
