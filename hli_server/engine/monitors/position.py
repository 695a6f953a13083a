"""Position monitoring (FCT-A3): the exact-stop window and the settling time (A3-01..A3-05).

Per axis, every cycle (FCT-A3 section 2, "Ablauf"):

1. When the axis' setpoint has reached its target - it stood still this cycle after moving, i.e.
   the axis is no longer interpolated - the timer starts (t1, A3-01).
2. The timer stops when the actual position (what the encoder reports, ``Axis.measured``) lies in
   the exact-stop window P-AXIS-00236 ``getriebe[i].window``: |measured - setpoint| <= window (t2,
   A3-02). If the setpoint moves again first, the timer is dropped (that was no target).
3. The window must be reached within P-AXIS-00532 ``getriebe[i].position_settling_time`` (t3, µs);
   0 switches the check off, a negative value means P-AXIS-00151 (``settling_time_legacy_us``) is
   used, and that being <= 0 switches it off too (A3-03).
4. Else P-ERR-70082, an immediate stop of the axis (a_emergency) and of every axis interpolated
   with it - the axes of its channel that are moving - and the channel's program is aborted (A3-04).
   The axis is not checked again until its channel is reset.

G60 (A3-05, FCT-A3 "Hinweis"): after a G60 block the path waits until every axis the block moved is
in the same window (the planner's ``exact_stop_gate``); if an axis never gets there, the settling
time check above fires (unless it is switched off: then the program waits, as a real control would).

Drive errors: an axis whose drive reports an error (``faults.drive_error``) raises 911030 in its
channel once; the channel's axes stop with a_emergency (reaction of the alarm table). The position
check is not made for an axis whose drive is off. (The other channel of a collision pair with
P-AXIS-00044 is stopped by the collision monitor, C3-05.)

Faults that slow or prevent settling are injected with ``Machine.inject_fault`` (A3-05): friction
(a dead band larger than kv * window holds the axis outside the window), a low gain factor (slow
settling), a drifting encoder (a standing following error of drift / kv), a stuck encoder (the
measured position never reaches the target).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from hli_server.engine.channel import Channel
from hli_server.engine.monitors.base import ChannelHooks, MachineView, Monitor
from hli_server.engine.planner import Motion
from schemas.events import PositionError
from schemas.units import increments_from_mm

if TYPE_CHECKING:
    from hli_server.engine.axis import Axis

__all__ = ["PositionMonitor", "settling_time_us"]


def settling_time_us(axis: Axis) -> int:
    """A3-03: the effective settling time [µs]; 0 means the check is off."""
    value = axis.config.position_settling_time_us
    if value < 0:
        value = axis.config.settling_time_legacy_us
    return max(0, value)


@dataclass(slots=True)
class _AxisWatch:
    axis: Axis
    window: float
    """mm"""
    settling_us: int
    was_moving: bool = False
    timer_start: int | None = None
    """Cycle in which the setpoint reached its target (t1)."""
    failed: bool = False
    """70082 raised; not checked again until reset."""
    drive_error_reported: bool = False


class PositionMonitor(Monitor):
    """FCT-A3 for every axis, the G60 gate for every channel, and drive errors."""

    def __init__(self, machine: MachineView) -> None:
        self.machine = machine
        self.watches = [_AxisWatch(a, a.window, settling_time_us(a)) for a in machine.axes]
        self._cycle_us = machine.config.cycle_time_us

    def channel_hooks(self, channel: Channel) -> ChannelHooks:
        return ChannelHooks(exact_stop_gate=_ExactStopGate(self, channel))

    def in_window(self, axis: Axis) -> bool:
        """A3-02: the actual position lies in the exact-stop window around the setpoint."""
        return abs(axis.measured - axis.setpoint) <= self.watches[axis.index].window + 1e-12

    # --- the cycle -----------------------------------------------------------------------
    def after_position_loop(self) -> None:
        """Runs after the position loop, so that it judges this cycle's actual positions."""
        machine = self.machine
        cycle_us = self._cycle_us
        for w in self.watches:
            axis = w.axis
            if axis.faults.drive_error:
                self._drive_error(w)
                w.timer_start = None
                w.was_moving = axis.setpoint_step != 0.0
                continue
            w.drive_error_reported = False
            moving = axis.setpoint_step != 0.0
            if moving:
                w.timer_start = None  # interpolated: no target reached yet
            elif w.was_moving and not w.failed:
                # t1 (A3-01): the setpoint reached its target at the end of the previous cycle
                w.timer_start = machine.cycle - 1
            w.was_moving = moving
            if w.timer_start is None:
                continue
            if self.in_window(axis):
                w.timer_start = None  # t2 (A3-02)
            elif w.settling_us > 0 and (machine.cycle - w.timer_start) * cycle_us >= w.settling_us:
                self._fail(w)  # t1 + t3 has come and the actual position is not in the window

    def on_reset(self, channel: Channel) -> None:
        for w in self.watches:
            if w.axis.channel == channel.index:
                w.failed = False
                w.timer_start = None

    # --- pieces --------------------------------------------------------------------------
    def _fail(self, w: _AxisWatch) -> None:
        """A3-04: 70082, immediate stop of the axis and of the axes interpolated with it."""
        machine = self.machine
        axis = w.axis
        w.failed = True
        w.timer_start = None
        ch = machine.channels[axis.channel]
        error = axis.measured - axis.setpoint
        block = ch.current_block
        machine.raise_alarm(
            70082,
            ch,
            f"axis {axis.name}: actual position {axis.measured:.4f} mm not in the exact-stop window "
            f"{w.window:.4f} mm (P-AXIS-00236) around the target {axis.setpoint:.4f} mm within "
            f"{w.settling_us} µs (P-AXIS-00532); deviation {error:.4f} mm. Check the axis (friction, "
            "drive tuning, measuring system), then reset",
            line=block.line if block is not None else None,
            block=block.label if block is not None else None,
            axis=axis.name,
            params={
                "axis": axis.name,
                "deviation": increments_from_mm(error),
                "window": axis.window_inc,
                "settling_time_us": w.settling_us,
            },
        )
        t = machine.t_a
        machine.emit(
            PositionError(
                cycle=machine.cycle,
                time_s=machine.time,
                channel=ch.number,
                axis=axis.name,
                deviation=increments_from_mm(error),
                window=axis.window_inc,
                settling_time_us=w.settling_us,
            )
        )
        axis.start_independent_stop(axis.a_emergency, t)
        for other in ch.axes:
            if other is not axis and not other.stopping and other.setpoint_step != 0.0:
                other.start_independent_stop(other.a_emergency, t)

    def _drive_error(self, w: _AxisWatch) -> None:
        if w.drive_error_reported:
            return
        w.drive_error_reported = True
        axis = w.axis
        ch = self.machine.channels[axis.channel]
        self.machine.raise_alarm(
            911030,
            ch,
            f"axis {axis.name}: the drive reports an error; the axes of channel {ch.number} stop. Remove "
            "the cause, then reset",
            axis=axis.name,
            params={"axis": axis.name},
        )
        for other in ch.axes:
            other.start_independent_stop(other.a_emergency, self.machine.t_a)


class _ExactStopGate:
    """A3-05: after a G60 block, the next block starts when the moved axes are in their window."""

    def __init__(self, monitor: PositionMonitor, channel: Channel) -> None:
        self.monitor = monitor
        self.channel = channel

    def __call__(self, motion: Motion) -> bool:
        seg = motion.segment
        for k, axis in enumerate(self.channel.axes):
            lo, hi = seg.axis_extent(k)
            if hi - lo > 0.0 and not self.monitor.in_window(axis):
                return False
        return True
