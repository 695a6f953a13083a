"""The machine: axes, channels, monitors, alarms; stepped by whole cycles (E-01).

One cycle::

    latch inputs (HLI _w fields and operator requests)
    -> monitors.before_interpolation (look-ahead checks that steer the path, e.g. FCT-C43)
    -> interpolate (path or jog), independent axis stops
    -> monitors.after_interpolation (soft limits, collision, position monitoring, areas)
    -> position loop (actual positions)
    -> publish (HLI _r fields) and events

Nothing here knows a wall clock: ``cycle * T_A`` is the time. The same configuration, programs and
inputs give the same outputs, cycle for cycle.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from hli_server.engine.alarms import ALARMS, Alarm, Reaction, Severity
from hli_server.engine.axis import Axis, AxisFaults, check_fault_value
from hli_server.engine.channel import Channel, Mode
from hli_server.engine.hli import AxisHli, ChannelHli, MachineHli
from schemas.config import MachineConfig
from schemas.units import increments_from_mm, s_from_us

__all__ = ["Event", "Machine", "Monitor"]

EVENT_BUFFER = 10_000
ALARM_HISTORY = 1_000


@dataclass(frozen=True, slots=True)
class Event:
    """Something a subscriber (MQTT, the control API, a test) may want to know."""

    cycle: int
    kind: str
    channel: int | None
    data: dict[str, Any] = field(default_factory=dict)


class Monitor:
    """A monitoring function. Subclasses override what they need; the defaults do nothing."""

    def before_interpolation(self, machine: Machine) -> None:
        return None

    def after_interpolation(self, machine: Machine) -> None:
        return None

    def on_reset(self, channel: Channel) -> None:
        return None

    def allow_mode_change(self, channel: Channel, mode: int) -> bool:
        return True


class Machine:
    def __init__(self, config: MachineConfig, read_program: Callable[[str], str] | None = None) -> None:
        """``read_program`` loads a program table entry given by path (the engine does no I/O itself;
        the runtime passes a file reader)."""
        self.config = config
        self.read_program = read_program
        self.t_a = s_from_us(config.cycle_time_us)
        self.cycle = 0
        self.axes = [Axis(cfg, i) for i, cfg in enumerate(config.axes)]
        self.axes_by_name = {a.name: a for a in self.axes}
        self.axes_by_number = {a.number: a for a in self.axes}
        self.hli = MachineHli(
            channels=[ChannelHli() for _ in config.channels],
            axes=[AxisHli() for _ in config.axes],
        )
        self.channels: list[Channel] = []
        for i, ch_cfg in enumerate(config.channels):
            ch_axes = [self.axes_by_name[n] for n in ch_cfg.axes]
            for a in ch_axes:
                a.channel = i
            self.channels.append(Channel(self, ch_cfg, i, ch_axes))
        self.active_alarms: list[Alarm] = []
        self.alarm_history: deque[Alarm] = deque(maxlen=ALARM_HISTORY)
        self.events: deque[Event] = deque(maxlen=EVENT_BUFFER)
        self.event_listeners: list[Callable[[Event], None]] = []
        self.monitors: list[Monitor] = []
        from hli_server.engine.monitors import install_default_monitors

        install_default_monitors(self)
        self.publish()

    # --- access --------------------------------------------------------------------------
    def channel(self, number: int = 1) -> Channel:
        """Channel by its number (1-based, as configured)."""
        for ch in self.channels:
            if ch.number == number:
                return ch
        raise KeyError(f"no channel {number}")

    def axis(self, name: str) -> Axis:
        return self.axes_by_name[name]

    def inject_fault(self, axis_name: str, **fields: float | bool) -> None:
        """Fault injection (A3-05): set fields of the axis' :class:`AxisFaults` (friction,
        gain_factor, encoder_drift, encoder_stuck, drive_error); effective from the next cycle.
        ``inject_fault("X", friction=5.0)``; ``inject_fault("X")`` with no fields clears all faults.
        Values out of range raise ValueError (``check_fault_value``) and change nothing."""
        axis = self.axes_by_name.get(axis_name)
        if axis is None:
            raise KeyError(f"inject_fault: no axis {axis_name!r} (axes: {', '.join(self.axes_by_name)})")
        if not fields:
            axis.reset_faults()
            return
        known = AxisFaults.__dataclass_fields__
        unknown = sorted(set(fields) - set(known))
        if unknown:
            raise ValueError(
                f"inject_fault({axis_name!r}): unknown fault field(s) {unknown}; known: {', '.join(known)}"
            )
        checked = {name: check_fault_value(axis, name, value) for name, value in fields.items()}
        for name, value in checked.items():
            setattr(axis.faults, name, value)
        self.emit("fault", self.channels[axis.channel], axis=axis_name, **fields)

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self.cycle * self.t_a

    # --- stepping ------------------------------------------------------------------------
    def step(self, cycles: int = 1) -> None:
        for _ in range(cycles):
            self._cycle()

    def _cycle(self) -> None:
        self.cycle += 1
        for ch in self.channels:
            ch.latch_inputs()
        for axis in self.axes:
            axis.begin_cycle()
        for mon in self.monitors:
            mon.before_interpolation(self)
        for ch in self.channels:
            ch.interpolate()
        for axis in self.axes:
            if axis.stopping:
                axis.advance_independent_stop(self.t_a)
        for mon in self.monitors:
            mon.after_interpolation(self)
        for axis in self.axes:
            axis.update_drive(self.t_a)
            if (
                axis.stopping
                and axis.stop_velocity == 0.0
                and not self.channel_has_error(self.channels[axis.channel])
            ):
                axis.release_stop()
        self.publish()

    # --- alarms and events ---------------------------------------------------------------
    def raise_alarm(
        self,
        number: int,
        channel: Channel | None,
        message: str,
        *,
        line: int | None = None,
        block: str | None = None,
        params: dict[str, Any] | None = None,
        axis: str | None = None,
    ) -> Alarm:
        """Raise an alarm of the table and apply its reaction."""
        definition = ALARMS[number]
        alarm = Alarm(
            number=number,
            cycle=self.cycle,
            channel=channel.number if channel is not None else 0,
            message=message,
            line=line,
            block=block,
            axis=axis,
            params=dict(params or {}),
        )
        if definition.severity == Severity.ERROR:
            self.active_alarms.append(alarm)
        self.alarm_history.append(alarm)
        if channel is not None:
            st = channel.hli.bahn_state
            st.alarm_count_r += 1
            if definition.severity == Severity.ERROR:
                st.error_present_r = True
                st.error_id_r = number
            else:
                st.warning_id_r = number
            if definition.reaction == Reaction.PROGRAM_ABORT:
                channel.abort()
            elif definition.reaction == Reaction.AXIS_STOP and axis is None:
                for ax in channel.axes:
                    ax.start_independent_stop(ax.a_emergency, self.t_a)
        self.emit("alarm", channel, alarm=alarm.to_json())
        return alarm

    def channel_has_error(self, channel: Channel) -> bool:
        return any(a.channel == channel.number for a in self.active_alarms)

    def emit(self, kind: str, channel: Channel | None, **data: Any) -> None:
        event = Event(self.cycle, kind, channel.number if channel is not None else None, data)
        self.events.append(event)
        for listener in self.event_listeners:
            listener(event)

    def drain_events(self) -> list[Event]:
        out = list(self.events)
        self.events.clear()
        return out

    # --- hooks the channels call ---------------------------------------------------------
    def on_channel_reset(self, channel: Channel) -> None:
        self.active_alarms = [a for a in self.active_alarms if a.channel != channel.number]
        st = channel.hli.bahn_state
        st.error_present_r = False
        st.error_id_r = 0
        st.warning_id_r = 0
        for axis in channel.axes:
            axis.faults.drive_error = False
        for mon in self.monitors:
            mon.on_reset(channel)

    def allow_mode_change(self, channel: Channel, mode: int) -> bool:
        return all(mon.allow_mode_change(channel, mode) for mon in self.monitors)

    # --- outputs -------------------------------------------------------------------------
    def publish(self) -> None:
        for axis, hli in zip(self.axes, self.hli.axes, strict=True):
            st = hli.ipo_state
            st.cmd_pos_r = increments_from_mm(axis.setpoint)
            st.act_pos_r = increments_from_mm(axis.measured)
            st.velocity_r = increments_from_mm(axis.drive_velocity)
            st.following_error_r = increments_from_mm(axis.following_error)
            st.referenced_r = axis.referenced
            st.moving_r = axis.setpoint_step != 0.0
            st.in_position_r = abs(st.following_error_r) <= axis.config.window and not st.moving_r
            st.error_r = axis.faults.drive_error
        for ch in self.channels:
            ch.publish()

    def snapshot(self) -> dict[str, Any]:
        """A JSON-able picture of the machine (for the API, ``check`` and tests)."""
        return {
            "cycle": self.cycle,
            "time_s": self.time,
            "channels": [
                {
                    "number": ch.number,
                    "mode": "manual" if ch.mode == Mode.MANUAL else "automatic",
                    "program_state": ch.state,
                    "program": ch.program_name,
                    "block": ch.current_block.label if ch.current_block else None,
                    "line": ch.current_block.line if ch.current_block else None,
                }
                for ch in self.channels
            ],
            "axes": {
                a.name: {
                    "setpoint_mm": a.setpoint,
                    "actual_mm": a.measured,
                    "following_error_mm": a.following_error,
                    "referenced": a.referenced,
                }
                for a in self.axes
            },
            "alarms": [a.to_json() for a in self.active_alarms],
        }
