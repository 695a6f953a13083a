"""The machine: axes, channels, monitors, alarms; stepped by whole cycles (E-01).

One cycle::

    latch inputs (HLI _w fields and operator requests)
    -> monitors.before_interpolation (look-ahead checks that steer the path, e.g. FCT-C43)
    -> interpolate (path, jog or referencing), independent axis stops
    -> monitors.after_interpolation (soft limits, collision, areas: this cycle's setpoints)
    -> position loop (actual positions)
    -> monitors.after_position_loop (position monitoring, FCT-A3: this cycle's actual positions)
    -> publish (HLI _r fields)

Nothing here knows a wall clock: ``cycle * T_A`` is the time. The same configuration, programs and
inputs give the same outputs, cycle for cycle. Events (``schemas.events``) go to the listeners
synchronously, inside the cycle; the machine keeps none of them.

The machine builds the channels and the monitors and does all the wiring: each monitor declares
what it plugs in (:class:`~hli_server.engine.monitors.base.Monitor`), and the machine calls only
the hooks a monitor overrides.
"""

from __future__ import annotations

import contextlib
import math
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from typing import Any, TypeVar

from pydantic import ValidationError

from hli_server.engine.alarms import ALARMS, Reaction, Severity
from hli_server.engine.areas.monitor import AreaMonitor
from hli_server.engine.axis import Axis, AxisFaults, check_fault_value
from hli_server.engine.channel import Channel
from hli_server.engine.cycles import ProbeDeviation
from hli_server.engine.external import ExternalVariables, external_specs
from hli_server.engine.external_init import run_external_init
from hli_server.engine.hli import AxisHli, ChannelHli, MachineHli
from hli_server.engine.increments import increments_clamped
from hli_server.engine.monitors.base import Monitor, MonitorFactory
from hli_server.engine.monitors.collision import CollisionMonitor
from hli_server.engine.monitors.dyn_pos_limit import DynPosLimits
from hli_server.engine.monitors.position import PositionMonitor
from hli_server.engine.monitors.soft_limits import SoftLimits
from hli_server.engine.ports import ChannelRef
from hli_server.engine.programs import MemoryLibrary, ProgramLibrary
from schemas.config import AxisConfig, MachineConfig
from schemas.events import (
    Alarm,
    AlarmRaised,
    AlarmsCleared,
    Event,
    FaultInjected,
    ReferenceChanged,
)
from schemas.units import s_from_us
from schemas.wire import Mode

__all__ = ["ALARM_HISTORY", "DEFAULT_MONITORS", "EventListener", "Machine"]

ALARM_INTERNAL = 919000
"""Error: a cycle failed inside the simulator (a bug); the channels stop, the server goes on."""
ALARM_HISTORY = 1_000
"""Alarms kept in :attr:`Machine.alarm_history` (the newest; ``GET /api/alarms`` shows them)."""

EventListener = Callable[[Event], None]

DEFAULT_MONITORS: tuple[MonitorFactory, ...] = (
    SoftLimits,  # E-06
    AreaMonitor,  # FCT-C14
    DynPosLimits,  # FCT-C43
    CollisionMonitor,  # FCT-C3
    PositionMonitor,  # FCT-A3
)
"""The monitoring functions a machine gets by default, in the order they run each cycle: soft limits
first (a block beyond them is refused before the areas look at it), then the areas, the dynamic
limits (they steer the path before interpolation), collision and position monitoring."""
M = TypeVar("M", bound=Monitor)

SOFT_LIMIT_RECORD_FIELDS: tuple[str, ...] = ("swe_neg", "swe_pos", "swe_toleranz")
"""The axis record's fields :meth:`Machine.update_axis_record` changes (P-AXIS-00177/00178/00179)."""


def _overrides(monitor: Monitor, hook: str) -> bool:
    return getattr(type(monitor), hook) is not getattr(Monitor, hook)


class Machine:
    """The simulated CNC. ``Machine(config).step(n)`` runs n interpolation cycles.

    ``monitors`` builds the monitoring functions (default: all of them, ``DEFAULT_MONITORS``);
    ``read_program`` loads a program-table entry given by path and ``programs`` finds the global
    subprograms a program calls (the engine does no I/O itself; the runtime passes a file reader and
    a library over the program directories)."""

    def __init__(
        self,
        config: MachineConfig,
        read_program: Callable[[str], str] | None = None,
        *,
        programs: ProgramLibrary | None = None,
        cycle_programs: Mapping[int, ProgramLibrary] | None = None,
        monitors: Iterable[MonitorFactory] | None = None,
    ) -> None:
        self.config = config
        self.read_program = read_program
        self.programs: ProgramLibrary = MemoryLibrary() if programs is None else programs
        self.cycle_programs: dict[int, ProgramLibrary] = dict(cycle_programs or {})
        """Per channel: its ``cycle_directories`` (the runtime's; searched after ``programs`` for cycles)."""
        self.probes: dict[int, ProbeDeviation] = {
            ch.number: ProbeDeviation(ch.probe.deviation_variables) for ch in config.channels
        }
        """Per channel: the simulated workpiece's deviation (docs/cycles.md, "The simulated probe")."""
        self.external = ExternalVariables(external_specs(config))
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
            self.channels.append(Channel(self, ch_cfg, i, ch_axes, self.hli.channels[i], self.hli.axes))
        self._channel_by_number = {ch.number: ch for ch in self.channels}
        self.active_alarms: list[Alarm] = []
        self.alarm_history: deque[Alarm] = deque(maxlen=ALARM_HISTORY)
        self.event_listeners: list[EventListener] = []
        self.monitors: tuple[Monitor, ...] = ()
        self._by_type: dict[type[Monitor], Monitor] = {}
        # the monitors that override each hook, in installation order: the cycle calls the method on
        # the monitor (compiled, a call through the class' table; a stored bound method would be called
        # through the interpreter)
        self._before: list[Monitor] = []
        self._after: list[Monitor] = []
        self._after_loop: list[Monitor] = []
        self._on_alarm: list[Callable[[Alarm], None]] = []
        self._install(DEFAULT_MONITORS if monitors is None else tuple(monitors))
        # the controller's start: the V.E. variables' init lines (P-EXTV-00013), in order; a failed line
        # is a warning (the kernel's class-2 21840/21841) and its variable 0, the machine starts
        for failure in run_external_init(self.external, config.external_init):
            self.raise_alarm(
                failure.alarm,
                None,
                failure.message,
                params={"variable": failure.variable, "line": failure.line},
            )
        self._publish_rows = [
            (axis, hli.ipo_state) for axis, hli in zip(self.axes, self.hli.axes, strict=True)
        ]
        self.publish()

    def _install(self, factories: tuple[MonitorFactory, ...]) -> None:
        """Build the monitors and wire what each declares (design: the machine does all the wiring)."""
        monitors: list[Monitor] = []
        for factory in factories:
            mon = factory(self)
            monitors.append(mon)
            self._by_type[type(mon)] = mon
            for ch in self.channels:
                hooks = mon.channel_hooks(ch)
                if hooks.path_check is not None:
                    ch.decoder.path_checks.append(hooks.path_check)
                if hooks.jog_guard is not None:
                    ch.jog_guards.append(hooks.jog_guard)
                if hooks.area_handler is not None:
                    ch.decoder.area_handler = hooks.area_handler
                if hooks.measure_handler is not None:
                    ch.decoder.measure_handler = hooks.measure_handler
                if hooks.exact_stop_gate is not None:
                    ch.planner.exact_stop_gate = hooks.exact_stop_gate
        self.monitors = tuple(monitors)
        self._before = [m for m in monitors if _overrides(m, "before_interpolation")]
        self._after = [m for m in monitors if _overrides(m, "after_interpolation")]
        self._after_loop = [m for m in monitors if _overrides(m, "after_position_loop")]
        self._on_alarm = [m.on_alarm for m in monitors if _overrides(m, "on_alarm")]

    # --- access --------------------------------------------------------------------------
    def channel(self, number: int = 1) -> Channel:
        """Channel by its number (1-based, as configured)."""
        try:
            return self._channel_by_number[number]
        except KeyError:
            raise KeyError(f"no channel {number} (channels: {sorted(self._channel_by_number)})") from None

    def axis(self, name: str) -> Axis:
        return self.axes_by_name[name]

    def monitor(self, kind: type[M]) -> M:
        """The installed monitor of class ``kind``: ``machine.monitor(AreaMonitor)``."""
        mon = self._by_type.get(kind)
        if mon is None:
            raise LookupError(f"the machine has no {kind.__name__} installed")
        assert isinstance(mon, kind)
        return mon

    def has_monitor(self, kind: type[Monitor]) -> bool:
        return kind in self._by_type

    def channel_of(self, axis: Axis) -> Channel:
        return self.channels[axis.channel]

    def update_axis_record(self, axis_name: str, **values: int) -> AxisConfig:
        """Change the software limits in the axis record (a parameter download, 0.1 µm): they take
        effect where the kernel takes them from the record, at the next reset, mode change or axis
        exchange (P-AXIS-00177/00178 "Anmerkungen"); until then the limits in effect stay. ValueError
        for an unknown field or a value the parameter refuses (then nothing changes)."""
        axis = self.axes_by_name.get(axis_name)
        if axis is None:
            raise KeyError(f"no axis {axis_name!r} (axes: {', '.join(self.axes_by_name)})")
        unknown = sorted(set(values) - set(SOFT_LIMIT_RECORD_FIELDS))
        if unknown:
            raise ValueError(
                f"axis {axis_name}: {', '.join(unknown)} cannot be changed at run time; the software limit "
                f"parameters can: {', '.join(SOFT_LIMIT_RECORD_FIELDS)}"
            )
        try:
            record = AxisConfig.model_validate({**axis.config.model_dump(), **values})
        except ValidationError as exc:
            problems = "; ".join(str(e["msg"]) for e in exc.errors())
            raise ValueError(f"axis {axis_name}: {problems}") from None
        axis.config = record
        self.config = self.config.model_copy(
            update={"axes": [record if a.name == axis_name else a for a in self.config.axes]}
        )
        return record

    def cycle_library(self, channel: int) -> ProgramLibrary:
        """Where channel ``channel``'s cycle calls look after the program directories."""
        library = self.cycle_programs.get(channel)
        if library is None:
            library = self.cycle_programs[channel] = MemoryLibrary(where="cycle directories")
        return library

    def probe_deviation(self, channel: int = 1) -> dict[str, float]:
        """The simulated workpiece's deviation per axis of channel ``channel`` [mm]: the V.E. variable of an
        axis that ``[channels.probe] deviation_variables`` names, else the value set by
        :meth:`set_probe_deviation` (0 until set)."""
        ch = self.channel(channel)
        probe = self.probes[ch.number]
        values: dict[str, float] = {}
        for name in ch.axis_names:
            var = probe.variables.get(name.upper())
            if var is not None:
                value = self.external.read(var, ch.number)
                values[name] = float(value)
            else:
                values[name] = probe.values.get(name, 0.0)
        return values

    def set_probe_deviation(self, channel: int, values: Mapping[str, float]) -> None:
        """Set the simulated workpiece's deviation along the named axes [mm]; an axis with a V.E. variable
        gets it written into the variable (as the PLC would write it). KeyError for an axis the channel does
        not have, ValueError for a value that is not finite or beyond +/-10000 mm; nothing changes then."""
        ch = self.channel(channel)
        probe = self.probes[ch.number]
        names = {n.upper(): n for n in ch.axis_names}
        checked: dict[str, float] = {}
        for axis, value in values.items():
            name = names.get(axis.upper())
            if name is None:
                raise KeyError(
                    f"probe deviation: channel {ch.number} has no axis {axis!r} ({', '.join(ch.axis_names)})"
                )
            number = float(value)
            if not math.isfinite(number) or abs(number) > 10_000.0:
                raise ValueError(f"probe deviation {name} = {value!r}: a finite value within +/-10000 mm")
            checked[name] = number
        for name, number in checked.items():
            var = probe.variables.get(name.upper())
            if var is not None:
                self.external.write(var, ch.number, number)
            else:
                probe.values[name] = number

    def inject_fault(self, axis_name: str, **fields: object) -> None:
        """Fault injection (A3-05): set fields of the axis' :class:`AxisFaults` (friction,
        gain_factor, encoder_drift, encoder_stuck, drive_error); effective from the next cycle.
        ``inject_fault("X", friction=5.0)``; ``inject_fault("X")`` with no fields clears all faults.
        Values out of range raise ValueError (``check_fault_value``) and change nothing."""
        axis = self.axes_by_name.get(axis_name)
        if axis is None:
            raise KeyError(f"inject_fault: no axis {axis_name!r} (axes: {', '.join(self.axes_by_name)})")
        known = AxisFaults.__dataclass_fields__
        unknown = sorted(set(fields) - set(known))
        if unknown:
            raise ValueError(
                f"inject_fault({axis_name!r}): unknown fault field(s) {unknown}; known: {', '.join(known)}"
            )
        checked = {name: check_fault_value(axis, name, value) for name, value in fields.items()}
        if not checked:
            axis.reset_faults()
        for name, value in checked.items():
            setattr(axis.faults, name, value)
        self.emit(
            FaultInjected(
                cycle=self.cycle,
                time_s=self.time,
                channel=self.channels[axis.channel].number,
                axis=axis_name,
                faults=axis.faults.as_dict(),
                changed=checked,
            )
        )

    @property
    def time(self) -> float:
        """Simulated time [s], exact to the µs of the cycle (T_A is whole µs): 0.013, not
        0.013000000000000001 (only reported, never computed with)."""
        return self.cycle * self.config.cycle_time_us / 1_000_000

    # --- stepping ------------------------------------------------------------------------
    def step(self, cycles: int = 1) -> None:
        for _ in range(cycles):
            self._cycle()

    def _cycle(self) -> None:
        self.cycle += 1
        t_a = self.t_a
        for ch in self.channels:
            ch.latch_inputs()
        for axis in self.axes:
            axis.begin_cycle()
        for mon in self._before:
            mon.before_interpolation()
        for ch in self.channels:
            ch.interpolate()
        for axis in self.axes:
            if axis.stopping:
                axis.advance_independent_stop(t_a)
        for mon in self._after:
            mon.after_interpolation()
        for axis in self.axes:
            axis.update_drive(t_a)
            if (
                axis.stopping
                and axis.stop_velocity == 0.0
                and not self.channel_has_error(self.channels[axis.channel])
            ):
                axis.release_stop()
        for mon in self._after_loop:
            mon.after_position_loop()
        self.publish()

    def cycle_failed(self, exc: Exception) -> None:
        """The runtime caught ``exc`` from a cycle: every channel takes alarm 919000 (once, until its
        reset), its axes stop with a_emergency and its program is aborted. The engine itself lets
        exceptions through (tests want to see them); the runtime decides that the server goes on."""
        for ch in self.channels:
            if any(a.number == ALARM_INTERNAL and a.channel == ch.number for a in self.active_alarms):
                continue
            self.raise_alarm(
                ALARM_INTERNAL,
                ch,
                f"internal error in cycle {self.cycle}: {type(exc).__name__}: {exc}; the axes were stopped. "
                "Reset the channel; please report this with the server log",
                params={"exception": type(exc).__name__},
            )
        # best effort: the PLC should see the alarm even if publishing is what failed (the runtime
        # has logged the cycle's failure already)
        with contextlib.suppress(Exception):
            self.publish()

    # --- alarms and events ---------------------------------------------------------------
    def raise_alarm(
        self,
        number: int,
        channel: ChannelRef | None,
        message: str,
        *,
        line: int | None = None,
        block: str | None = None,
        params: dict[str, Any] | None = None,
        axis: str | None = None,
    ) -> Alarm:
        """Raise an alarm of the table and apply its reaction."""
        definition = ALARMS[number]
        ch = self._channel_by_number[channel.number] if channel is not None else None
        alarm = Alarm(
            number=number,
            severity=str(definition.severity),
            cycle=self.cycle,
            channel=ch.number if ch is not None else 0,
            message=message,
            line=line,
            block=block,
            axis=axis,
            params=dict(params or {}),
        )
        if definition.severity == Severity.ERROR:
            self.active_alarms.append(alarm)
        self.alarm_history.append(alarm)
        if ch is not None:
            st = ch.hli.bahn_state
            st.alarm_count_r += 1
            if definition.severity == Severity.ERROR:
                st.error_present_r = True
                st.error_id_r = number
            else:
                st.warning_id_r = number
        self.emit(AlarmRaised(cycle=self.cycle, time_s=self.time, channel=alarm.channel or None, alarm=alarm))
        for hook in self._on_alarm:
            hook(alarm)
        if ch is not None and definition.severity == Severity.ERROR:
            # the reaction last, so that its events (program aborted) follow the alarm's; an error
            # aborts the channel's program in the cycle it is raised, whatever stops the axes
            if definition.reaction == Reaction.AXIS_STOP and axis is None:
                for ax in ch.axes:
                    ax.start_independent_stop(ax.a_emergency, self.t_a)
            ch.abort()
        return alarm

    def channel_has_error(self, channel: ChannelRef) -> bool:
        number = channel.number
        return any(a.channel == number for a in self.active_alarms)

    def emit(self, event: Event) -> None:
        for listener in self.event_listeners:
            listener(event)

    # --- what the channels report (MachinePort) -----------------------------------------
    def channel_reset(self, channel: ChannelRef) -> None:
        ch = self._channel_by_number[channel.number]
        cleared = tuple(a.number for a in self.active_alarms if a.channel == ch.number)
        self.active_alarms = [a for a in self.active_alarms if a.channel != ch.number]
        st = ch.hli.bahn_state
        st.error_present_r = False
        st.error_id_r = 0
        st.warning_id_r = 0
        for axis in ch.axes:
            axis.faults.drive_error = False
        for mon in self.monitors:
            mon.on_reset(ch)
        if cleared:
            self.emit(AlarmsCleared(cycle=self.cycle, time_s=self.time, channel=ch.number, numbers=cleared))

    def allow_mode_change(self, channel: ChannelRef, mode: Mode) -> bool:
        ch = self._channel_by_number[channel.number]
        return all(mon.allow_mode_change(ch, mode) for mon in self.monitors)

    def referencing_changed(self, axis_index: int) -> None:
        axis = self.axes[axis_index]
        state = "referencing" if axis.referencing else "referenced" if axis.referenced else "unreferenced"
        self.emit(
            ReferenceChanged(
                cycle=self.cycle,
                time_s=self.time,
                channel=self.channels[axis.channel].number,
                axis=axis.name,
                state=state,
            )
        )

    # --- outputs -------------------------------------------------------------------------
    def publish(self) -> None:
        """The HLI ``_r`` fields of every axis and channel. Positions in 0.1 µm as
        :func:`~schemas.units.increments_from_mm` converts them (rounded to the nearest, clamped to a
        DINT), by :func:`~hli_server.engine.increments.increments_clamped`, which computes the same
        without the interpreter's ``round``: 32 conversions a cycle on an 8-axis machine
        (docs/performance.md)."""
        for axis, st in self._publish_rows:
            setpoint = axis.setpoint
            measured = axis.measured
            st.cmd_pos_r = increments_clamped(setpoint)
            st.act_pos_r = increments_clamped(measured)
            st.velocity_r = increments_clamped(axis.drive_velocity)
            err = increments_clamped(setpoint - measured)
            st.following_error_r = err
            st.referenced_r = axis.referenced
            st.referencing_r = axis.referencing
            moving = setpoint - axis.prev_setpoint != 0.0
            st.moving_r = moving
            window = axis.window_inc
            st.in_position_r = -window <= err <= window and not moving
            st.error_r = axis.faults.drive_error
        for ch in self.channels:
            ch.publish(self.cycle)

    def snapshot(self) -> dict[str, Any]:
        """A JSON-able picture of the machine (for the API, ``check`` and tests)."""
        return {
            "cycle": self.cycle,
            "time_s": self.time,
            "channels": [
                {
                    "number": ch.number,
                    "mode": ch.mode.label,
                    "program_state": int(ch.state),
                    "program_state_name": ch.state.label,
                    "hold_source": int(ch.hold_source),
                    "holds": ch.hold_source.labels,
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
                    "referencing": a.referencing,
                }
                for a in self.axes
            },
            "alarms": [a.to_json() for a in self.active_alarms],
        }
