"""What the machine tells its listeners: one frozen dataclass per kind of event (H-05).

The engine emits these objects, cycle for cycle; the runtime's event log keeps them for ``GET
/api/events``; the MQTT adapter publishes them on their topic; the dashboard draws them. Nobody
builds an event dictionary by hand: the JSON form is :meth:`Event.to_json` (the event log adds a
sequence number, MQTT adds the machine name and the wall time).

Every event carries ``cycle`` (the interpolation cycle it happened in), ``time_s`` (the simulated
time, ``cycle * T_A``) and ``channel`` (the channel number, 1-based, or None for the machine). The
rest of its fields are its payload. Units are the interface's: positions and distances in 0.1 µm
(0.0001° rotary) as integers, where the payload names a position; alarm parameters as the alarm
table gives them.

Topics are relative to the adapter's prefix (``hli/<machine>/``) and derived from the fields:
``ch/{channel}/state``, ``ax/{axis}/dyn_pos_limit``. :data:`EVENT_TYPES` lists every kind; the MQTT
topic table in docs/mqtt.md and the event list in docs/api.md are generated from it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

__all__ = [
    "EVENT_TYPES",
    "Alarm",
    "AlarmRaised",
    "AlarmsCleared",
    "AreaViolation",
    "AreasChanged",
    "CollisionStop",
    "ControlUnitChanged",
    "DynPosLimitChanged",
    "Event",
    "FaultInjected",
    "HoldChanged",
    "Measurement",
    "ModeChanged",
    "NcFileWrite",
    "NcMessage",
    "PositionError",
    "ProgramStateChanged",
    "ReferenceChanged",
    "event_type",
    "place",
]

_ENVELOPE = frozenset({"cycle", "time_s", "channel"})
_SCALARS = frozenset({int, float, str, bool})


def _plain(value: Any) -> Any:
    """JSON-able copy: tuples become lists, dataclasses dictionaries."""
    if value is None or type(value) in _SCALARS:  # most leaves (an area's vertices: many numbers)
        return value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        to_json = getattr(value, "to_json", None)
        if callable(to_json):
            return to_json()
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def place(line: int | None, block: str | None) -> str:
    """Where in the program: ``line 14, N130``; ``line 14`` when the block has no N number (its label
    is then ``line 14`` itself); ``""`` when neither is known."""
    if line is None:
        return block or ""
    if block is None or block == f"line {line}":
        return f"line {line}"
    return f"line {line}, {block}"


@dataclass(frozen=True, slots=True)
class Alarm:
    """One raised alarm, as the channel, the HTTP API and the events show it.

    ``number`` is from the one alarm table (``hli-server alarms``, docs/alarms.md); ``severity`` is
    ``"error"`` or ``"warning"``; ``line`` / ``block`` name the NC block where there is one."""

    number: int
    severity: str
    cycle: int
    channel: int
    message: str
    line: int | None = None
    block: str | None = None
    axis: str | None = None
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def place(self) -> str:
        """``line 14, N130``, or ``line 14`` for a block without a number, or ``""``."""
        return place(self.line, self.block)

    def to_json(self) -> dict[str, Any]:
        return {
            "id": self.number,
            "severity": self.severity,
            "cycle": self.cycle,
            "channel": self.channel,
            "line": self.line,
            "block": self.block,
            "axis": self.axis,
            "message": self.message,
            "params": _plain(self.params),
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class Event:
    """Base of every event: when (``cycle``, ``time_s``) and where (``channel``)."""

    KIND: ClassVar[str] = ""
    TOPIC: ClassVar[str] = ""
    """Relative topic, formatted with the event's fields (``ch/{channel}/state``)."""
    DESCRIPTION: ClassVar[str] = ""

    cycle: int
    time_s: float
    channel: int | None = None

    @property
    def kind(self) -> str:
        return self.KIND

    def payload(self) -> dict[str, Any]:
        """The event's own fields (everything but cycle, time and channel), JSON-able."""
        return {
            f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self) if f.name not in _ENVELOPE
        }

    def topic(self) -> str:
        """The topic below the adapter's prefix: ``ch/1/state``."""
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return self.TOPIC.format(**values)

    def to_json(self) -> dict[str, Any]:
        """``{"kind", "cycle", "time_s", "channel", "data": {...payload}}``."""
        return {
            "kind": self.KIND,
            "cycle": self.cycle,
            "time_s": self.time_s,
            "channel": self.channel,
            "data": self.payload(),
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class AlarmRaised(Event):
    KIND = "alarm"
    TOPIC = "alarms"
    DESCRIPTION = "an alarm of the table was raised (error or warning), with line and block where known"

    alarm: Alarm


@dataclass(frozen=True, slots=True, kw_only=True)
class AlarmsCleared(Event):
    KIND = "alarms_cleared"
    TOPIC = "alarms"
    DESCRIPTION = "the channel's pending error alarms were cleared (by a reset)"

    numbers: tuple[int, ...]
    cause: str = "reset"


@dataclass(frozen=True, slots=True, kw_only=True)
class ProgramStateChanged(Event):
    KIND = "program_state"
    TOPIC = "ch/{channel}/state"
    DESCRIPTION = (
        "the channel's program state changed (bahn_state.program_state_r); cause: load, start, hold, "
        "release, end, error, reset"
    )

    state: str
    """``idle``, ``running``, ``held``, ``aborted``, ``finished`` (schemas.wire.ProgramState)."""
    code: int
    """The number ``program_state_r`` shows."""
    previous: str
    cause: str
    program: str


@dataclass(frozen=True, slots=True, kw_only=True)
class ModeChanged(Event):
    KIND = "mode"
    TOPIC = "ch/{channel}/state"
    DESCRIPTION = "the channel's mode changed (bahn_state.mode_r): automatic or manual"

    mode: str
    previous: str


@dataclass(frozen=True, slots=True, kw_only=True)
class HoldChanged(Event):
    KIND = "hold"
    TOPIC = "ch/{channel}/hold"
    DESCRIPTION = (
        "what holds the channel's path changed (bahn_state.hold_source_r): the PLC's feedhold, a dynamic "
        "position limit"
    )

    hold_source: int
    """``bahn_state.hold_source_r`` (schemas.wire.HoldSource bits)."""
    sources: tuple[str, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class ControlUnitChanged(Event):
    KIND = "control_unit"
    TOPIC = "ch/{channel}/control_unit"
    DESCRIPTION = (
        "the state_r of a channel control unit changed (feedhold, override, area monitoring in manual)"
    )

    unit: str
    """ST path of the unit, e.g. ``gpCh[0]^bahn_mc_control.feedhold``."""
    state: int | bool
    previous: int | bool


@dataclass(frozen=True, slots=True, kw_only=True)
class DynPosLimitChanged(Event):
    KIND = "dyn_pos_limit"
    TOPIC = "ax/{axis}/dyn_pos_limit"
    DESCRIPTION = "state_r of a dynamic position limit changed (HLI_DYNPL_STATE_*, FCT-C43)"

    axis: str
    side: str
    """``low`` or ``high``."""
    state: int
    state_name: str
    limit: int
    """The adopted limit [0.1 µm or 0.0001°]."""


@dataclass(frozen=True, slots=True, kw_only=True)
class AreaViolation(Event):
    KIND = "area_violation"
    TOPIC = "ch/{channel}/areas"
    DESCRIPTION = (
        "a work or protection area refused a block or a mode change (FCT-C14), with the block, its start "
        "and end point and the exact intersection point"
    )

    alarm: int
    area: int | None
    area_kind: str | None
    """``WORK`` or ``PROT``."""
    line: int | None
    block: str | None
    axes: tuple[str, ...]
    start: tuple[int, ...] | None = None
    """Start point of the refused block [0.1 µm], in the order of ``axes``."""
    end: tuple[int, ...] | None = None
    point: tuple[int, ...] | None = None
    """Where the path leaves the allowed space [0.1 µm]."""


@dataclass(frozen=True, slots=True, kw_only=True)
class AreasChanged(Event):
    KIND = "areas"
    TOPIC = "ch/{channel}/areas"
    DESCRIPTION = "the channel's area table changed (defined, activated, deactivated, cleared, reset)"

    areas: tuple[dict[str, Any], ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class CollisionStop(Event):
    KIND = "collision"
    TOPIC = "ax/{master}/collision"
    DESCRIPTION = "a collision pair was stopped (P-ERR-70092, FCT-C3), distances in 0.1 µm"

    master: str
    partner: str
    distance: int
    brake_dist: int
    coll_offset: int


@dataclass(frozen=True, slots=True, kw_only=True)
class PositionError(Event):
    KIND = "position_monitoring"
    TOPIC = "ax/{axis}/position_monitoring"
    DESCRIPTION = "an axis missed its exact-stop window within the settling time (P-ERR-70082, FCT-A3)"

    axis: str
    deviation: int
    """Actual minus target [0.1 µm] when the time ran out."""
    window: int
    settling_time_us: int


@dataclass(frozen=True, slots=True, kw_only=True)
class FaultInjected(Event):
    KIND = "fault"
    TOPIC = "ax/{axis}/faults"
    DESCRIPTION = "faults of an axis' drive model were injected or cleared (A3-05)"

    axis: str
    faults: dict[str, float | bool]
    """All fault fields after the change."""
    changed: dict[str, float | bool]
    """The fields set by this injection (empty: all cleared)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Measurement(Event):
    KIND = "measurement"
    TOPIC = "ch/{channel}/measurement"
    DESCRIPTION = "the probe fired during a G100 measuring move (C14-23); positions in mm"

    block: str
    line: int
    position: dict[str, float]
    setpoint: dict[str, float]


@dataclass(frozen=True, slots=True, kw_only=True)
class ReferenceChanged(Event):
    KIND = "reference"
    TOPIC = "ax/{axis}/reference"
    DESCRIPTION = "an axis began referencing (homing), finished it, or lost its reference"

    axis: str
    state: str
    """``referencing``, ``referenced`` or ``unreferenced``."""


@dataclass(frozen=True, slots=True, kw_only=True)
class NcMessage(Event):
    """``#MSG`` of an NC program (N-07; programming manual "Programming a message (#MSG)",
    https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/507845131.html)."""

    KIND = "nc_message"
    TOPIC = "ch/{channel}/messages"
    DESCRIPTION = (
        "an NC program sent a message (#MSG, #MSG SAVE), with the formatted text, the program, line and block"
    )

    text: str
    """The message as formatted (format string filled in), at most the engine's string bound."""
    save: bool = False
    """True for ``#MSG SAVE``: the text is also written to the report file (see :class:`NcFileWrite`)."""
    program: str = ""
    """The program (file) name the block belongs to: a subprogram's own name inside a subprogram."""
    line: int | None = None
    block: str | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class NcFileWrite(Event):
    """A write to a report file asked for by an NC program (``#MSG SAVE`` into the file named by
    ``#FILE NAME``; programming manual "Writing messages to a file (#MSG SAVE)",
    https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/207171211.html).

    The engine touches no file: the runtime carries the write out inside its NC output directory
    (``hli-server run --nc-output-dir``) and refuses any name that would leave it."""

    KIND = "nc_file_write"
    TOPIC = "ch/{channel}/files"
    DESCRIPTION = (
        "an NC program appended text to a report file (#MSG SAVE, #FILE NAME); the server writes it inside "
        "its NC output directory only"
    )

    file: str
    """The file name as programmed (``#FILE NAME [MSG="..."]``; programming manual "Definition of
    file names (#FILE NAME)",
    https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/207504523.html), or the
    kernel's default ``message.txt``; relative to the output directory."""
    text: str
    """The text to append, time stamp included where the program asked for one."""
    mode: str = "line"
    """``line``: append ``text`` and end the line; ``continue`` (``#MSG SAVE CONTINUE``): append
    ``text`` without a line break, the next write goes on in the same line."""
    program: str = ""
    line: int | None = None
    block: str | None = None


EVENT_TYPES: tuple[type[Event], ...] = (
    AlarmRaised,
    AlarmsCleared,
    ProgramStateChanged,
    ModeChanged,
    HoldChanged,
    ControlUnitChanged,
    DynPosLimitChanged,
    AreaViolation,
    AreasChanged,
    CollisionStop,
    PositionError,
    FaultInjected,
    Measurement,
    ReferenceChanged,
    NcMessage,
    NcFileWrite,
)
"""Every kind of event, in the order the docs list them."""

_BY_KIND = {t.KIND: t for t in EVENT_TYPES}


def event_type(kind: str) -> type[Event]:
    """The event class of ``kind`` (``"alarm"`` -> :class:`AlarmRaised`)."""
    try:
        return _BY_KIND[kind]
    except KeyError:
        raise KeyError(f"no event kind {kind!r}; kinds: {', '.join(_BY_KIND)}") from None
