"""Work and protection area monitoring of the channels (FCT-C14, C14-01..C14-23).

One :class:`ChannelAreas` per channel puts the parts together, each a module of its own:

* :mod:`~hli_server.engine.areas.definitions`: the decoder's area handler (``#CONTROL AREA`` commands and
  the contour blocks between BEGIN and END);
* :mod:`~hli_server.engine.areas.path_check`: every motion block's whole path, before it is queued;
* :mod:`~hli_server.engine.areas.measuring`: G100 measuring moves and the probe;
* :mod:`~hli_server.engine.areas.manual`: the jog guard and the mode-change check of manual mode;
* :mod:`~hli_server.engine.areas.common`: the tables they share, numbers and texts.

:class:`AreaMonitor` declares them to the machine (``channel_hooks``) and does what happens per cycle:
the probe input, the PLC flag, reset and the mode-change check.

Decode time and execution time
------------------------------
The decoder runs up to 64 blocks ahead of the path. Each channel therefore keeps two tables:

* ``planned``: the table as it will be when the path reaches the block being decoded. Commands are
  validated and applied to it at decode time, so the path checks of the blocks after an ON see the
  area, and the ON check uses the position where the path will be (C14-11).
* ``effective``: the table as it is now. The same operation is applied to it by the callable the
  handler returns, which the channel runs when the path reaches the block (at standstill there).
  The PLC, the jog guard, the mode-change check and ``channel_areas(...).to_json()`` see it.

At every program start (and after a reset) ``planned`` is copied from ``effective``: commands that
were decoded but never reached (program aborted) did not happen.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Final

from hli_server.engine.areas.common import (
    ALARM_DEFINITION,
    MAX_CONTOUR_BLOCKS,
    PROTECTION_MARGIN,
    VIOLATION_ALARMS,
    ChannelAreaTables,
)
from hli_server.engine.areas.definitions import AreaDefinitions
from hli_server.engine.areas.geometry import Group
from hli_server.engine.areas.manual import ManualGuard
from hli_server.engine.areas.measuring import MeasuringMoves
from hli_server.engine.areas.path_check import AreaPathCheck
from hli_server.engine.areas.table import AreaEvent, AreaTable
from hli_server.engine.geometry import Point
from hli_server.engine.monitors.base import ChannelHooks, MachineView, Monitor
from schemas.events import Alarm, AreaViolation
from schemas.units import increments_from_mm
from schemas.wire import Mode, ProgramState

if TYPE_CHECKING:
    from hli_server.engine.channel import Channel

__all__ = [
    "MAX_CONTOUR_BLOCKS",
    "PROTECTION_MARGIN",
    "VIOLATION_ALARMS",
    "AreaMonitor",
    "ChannelAreas",
    "channel_areas",
]

# enum members the cycle compares with (Final: a compiled module reads them directly)
_AUTOMATIC: Final = Mode.AUTOMATIC
_MANUAL: Final = Mode.MANUAL
_FINISHED: Final = ProgramState.FINISHED


class ChannelAreas:
    """The area monitoring of one channel: its tables and its parts."""

    def __init__(self, machine: MachineView, channel: Channel) -> None:
        self.machine = machine
        self.channel = channel
        self.tables = ChannelAreaTables(machine, channel)
        self.definitions = AreaDefinitions(self.tables)
        self.path_check = AreaPathCheck(self.tables)
        self.measuring = MeasuringMoves(self.tables)
        self.manual = ManualGuard(self.tables)
        self._blocks_seen: object = None

    # --- views (tests, the API, check) -----------------------------------------------------
    @property
    def planned(self) -> AreaTable:
        return self.tables.planned

    @property
    def effective(self) -> AreaTable:
        return self.tables.effective

    @property
    def names(self) -> list[str]:
        return self.tables.names

    @property
    def measurement(self) -> dict[str, Any] | None:
        """The last probe result (C14-23): block, positions in mm, cycle."""
        return self.measuring.measurement

    def to_json(self, planned: bool = False) -> dict[str, Any]:
        """The area table as ``check`` lists it: ``{"channel", "axes", "areas": [...]}``."""
        return self.tables.to_json(planned)

    def allowed(self, point: Point) -> bool:
        """Is ``point`` in the allowed space of the effective table (tests, API)?"""
        return self.tables.allowed(point)

    def groups(self, planned: bool = False) -> list[Group]:
        return self.tables.groups(planned)

    def request_probe(self, on: bool) -> None:
        """The operator's (tests', API's) probe input, OR'ed with ``mc_command.probe_w`` (C14-23)."""
        self.measuring.request_probe(on)

    # --- reset and cycle -------------------------------------------------------------------
    def reset(self) -> None:
        """C14-10: reset deactivates every area; the definitions stay."""
        tables = self.tables
        for table in (tables.effective, tables.planned):
            for area_id in list(table.states):
                table.apply(area_id, AreaEvent.RESET)
        tables.sync_planned()
        tables.violation_auto = False
        self.manual._release_manual()
        tables.emit_table()

    def before_cycle(self) -> None:
        ch = self.channel
        blocks = ch.decoder.blocks
        if blocks is not self._blocks_seen:
            self._blocks_seen = blocks
            self.tables.sync_planned()
        if ch.mode is _AUTOMATIC:
            self.measuring.probe_cycle()
        else:
            self.measuring.follow_probe()

    def after_cycle(self) -> None:
        ch = self.channel
        tables = self.tables
        pending = tables.pending
        if pending is not None and ch.state is _FINISHED:
            begin = pending.block
            area_id = pending.begin.area_id
            tables.pending = None
            self.machine.raise_alarm(
                ALARM_DEFINITION,
                ch,
                f"program ended inside the definition of area {area_id} begun at {begin.label}: "
                "#CONTROL AREA END missing; the area was not defined",
                line=begin.line,
                block=begin.label,
            )
        self.manual.announce_stop()
        ch.hli.bahn_state.area_mon_violation_detected_r = tables.violation_auto or (
            ch.mode is _MANUAL and tables.violation_manual
        )


class AreaMonitor(Monitor):
    """FCT-C14 for every channel of the machine."""

    def __init__(self, machine: MachineView) -> None:
        self.machine = machine
        self.channels: dict[int, ChannelAreas] = {
            ch.number: ChannelAreas(machine, ch) for ch in machine.channels
        }

    def channel_hooks(self, channel: Channel) -> ChannelHooks:
        handler = self.channels[channel.number]
        return ChannelHooks(
            path_check=handler.path_check.path_check,
            jog_guard=handler.manual,
            area_handler=handler.definitions,
            measure_handler=handler.measuring,
        )

    def handler(self, channel_number: int) -> ChannelAreas:
        return self.channels[channel_number]

    def areas_json(self, channel: Channel) -> list[dict[str, Any]]:
        """The channel's area table (effective states) as ``check`` lists it: ``[{"id", "kind",
        "shape", "state", "points" | "center"/"radius", "min", "max", "axes", "height_axis"}]``."""
        return self.channels[channel.number].effective.to_json()

    def on_alarm(self, alarm: Alarm) -> None:
        """C14-22: a violation alarm sets ``area_mon_violation_detected_r`` until the reset; it is
        also told as an :class:`~schemas.events.AreaViolation` with its block and points."""
        if alarm.number not in VIOLATION_ALARMS or not alarm.channel:
            return
        self.channels[alarm.channel].tables.violation_auto = True
        p = alarm.params

        def point(key: str) -> tuple[int, ...] | None:
            value = p.get(key)
            return tuple(increments_from_mm(v) for v in value) if isinstance(value, list | tuple) else None

        m = self.machine
        axes = p.get("axes")
        m.emit(
            AreaViolation(
                cycle=m.cycle,
                time_s=m.time,
                channel=alarm.channel,
                alarm=alarm.number,
                area=p.get("area"),
                area_kind=p.get("kind"),
                line=alarm.line,
                block=alarm.block,
                axes=tuple(axes) if isinstance(axes, list) else tuple(self.channels[alarm.channel].names),
                start=point("start"),
                end=point("end"),
                point=point("intersection") or point("position"),
            )
        )

    def before_interpolation(self) -> None:
        for handler in self.channels.values():
            handler.before_cycle()

    def after_interpolation(self) -> None:
        for handler in self.channels.values():
            handler.after_cycle()

    def on_reset(self, channel: Channel) -> None:
        self.channels[channel.number].reset()

    def allow_mode_change(self, channel: Channel, mode: Mode) -> bool:
        handler = self.channels[channel.number]
        if mode == Mode.MANUAL:
            return handler.manual.mode_check()
        handler.manual._release_manual()
        return True


def channel_areas(machine: MachineView, channel: int = 1) -> ChannelAreas:
    """The area monitoring of one channel (by its number): ``channel_areas(m, 1).to_json()``."""
    return machine.monitor(AreaMonitor).handler(channel)
