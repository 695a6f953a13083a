"""What the ports of ``hli_server.adapters.host`` answer, typed: the operator port's machine state, its
alarms, an axis' faults and software limits, the area table, the dashboard's scene, the program table, the
collision pairs and the clock's pacing (``timing``); the recorder port's status and files; the
communication faults; an image field; the readiness; a program check's report. Every door serves these
shapes (the HTTP API declares them as its ``response_model``, so the OpenAPI description at
``/openapi.json`` says what comes back; the MQTT snapshot and the remote link carry the same dictionaries).

They are ``TypedDict``\\ s, not classes: the values stay plain JSON-able dictionaries (what the engine builds,
what a recording journals, what crosses the doors process' link), and mypy checks the keys. Keys a shape
has only sometimes are ``NotRequired``; a shape that may grow keys without a schema change allows extra
keys. Lengths are mm here (the operator's view), positions on the image are 0.1 µm (``schemas.units``).
Non-finite numbers follow the project's one JSON policy: ``null``. ``Any`` stays only where a value is
really arbitrary JSON (an alarm's own parameters, a V.E. variable's value), and says so.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, NotRequired

from pydantic import ConfigDict, Field
from typing_extensions import TypedDict

__all__ = [
    "AlarmJson",
    "AlarmList",
    "AreaTable",
    "AxisFaults",
    "AxisState",
    "ChannelState",
    "CheckAlarm",
    "CheckCap",
    "CheckMessage",
    "CheckReport",
    "CollisionPair",
    "CommFault",
    "CommFaultChange",
    "CommFaultLogged",
    "CommFaultTable",
    "CommFaultsEnded",
    "ExternalVariable",
    "ImageField",
    "Lateness",
    "LimitValues",
    "MachineChannel",
    "MachineInfo",
    "MachineState",
    "PacingSummary",
    "ProbeDeviation",
    "ProgramEntry",
    "ProgramLoaded",
    "ProgramSelected",
    "ReadinessJson",
    "RecorderStatus",
    "RecordingFile",
    "Scene",
    "SlowCycleJson",
    "SoftLimits",
    "Timing",
    "TraceJson",
]

_OPEN = ConfigDict(extra="allow")


class AlarmJson(TypedDict):
    """One alarm (``schemas.events.Alarm.to_json``): the kernel's error ID and where it happened."""

    id: int
    severity: str
    cycle: int
    channel: int | None
    line: int | None
    block: str | None
    axis: str | None
    message: str
    params: dict[str, Any]  # the alarm's own values (they differ per alarm ID): really arbitrary JSON


class ChannelState(TypedDict):
    number: int
    mode: str
    program_state: int
    program_state_name: str
    hold_source: int
    holds: list[str]
    program: str | None
    block: str | None
    line: int | None


class AxisState(TypedDict):
    setpoint_mm: float | None
    actual_mm: float | None
    following_error_mm: float | None
    referenced: bool
    referencing: bool


class ExternalVariable(TypedDict):
    """A V.E. variable and its value now (N-05); ``value`` is a list, row-major, for an array."""

    name: str
    channel: int | None
    symbol: str
    type: str
    dims: list[int]
    value: Any  # BOOLEAN, a number, a string or a row-major list of them, after the variable's type and dims


class MachineChannel(TypedDict):
    number: int
    axes: list[str]


class MachineInfo(TypedDict):
    """``GET /api/machine``: what the machine is and how its clock runs (what never changes while it runs)."""

    name: str
    t_a_us: int
    clock: str
    channels: list[MachineChannel]


class MachineState(TypedDict):
    """``GET /api/state``: channels, axes (by name), the active alarms; the runtime adds the V.E. variables
    (``external``) and the HTTP API the clock (``clock``)."""

    __pydantic_config__ = _OPEN  # type: ignore[misc]

    cycle: int
    time_s: float
    channels: list[ChannelState]
    axes: dict[str, AxisState]
    alarms: list[AlarmJson]
    external: NotRequired[list[ExternalVariable]]
    clock: NotRequired[str]


class AlarmList(TypedDict):
    """``GET /api/alarms``: the active alarms and the newest of the history."""

    active: list[AlarmJson]
    history: list[AlarmJson]


class ProbeDeviation(TypedDict):
    """The simulated workpiece's deviation of a channel, per axis [0.1 µm] (docs/cycles.md); ``variables``:
    the axes whose value a V.E. variable holds (axis -> variable name)."""

    channel: int
    deviation: dict[str, int]
    variables: dict[str, str]


class AxisFaults(TypedDict):
    """An axis' injected faults (E-08): ``friction``, ``gain_factor``, ``encoder_stuck``, ``encoder_drift``,
    ``drive_error``."""

    axis: str
    friction: float
    gain_factor: float
    encoder_stuck: bool
    encoder_drift: float
    drive_error: bool


class LimitValues(TypedDict):
    swe_neg: int
    swe_pos: int
    swe_toleranz: int


class SoftLimits(TypedDict):
    """The software limits in effect and in the axis record [0.1 µm] (P-AXIS-00177/00178/00179)."""

    axis: str
    in_effect: LimitValues
    record: LimitValues


class AreaTable(TypedDict):
    """A channel's area table (FCT-C14) as ``check`` lists it; each area as ``check --json`` writes it."""

    channel: int
    axes: list[str]
    areas: list[dict[str, Any]]


class ProgramLoaded(TypedDict):
    channel: int
    program: str
    lines: int
    files: list[str]
    cycle: int


class ProgramSelected(TypedDict):
    channel: int
    program: str
    number: int
    cycle: int


class ProgramEntry(TypedDict):
    number: int
    name: str


class CollisionPair(TypedDict):
    """A collision pair (FCT-C3) now, lengths in mm."""

    master: str
    partner: str
    distance: float | None
    min_distance: float | None
    brake_master: float | None
    brake_partner: float | None
    monitoring: bool
    stopped: bool
    latched: bool


class Scene(TypedDict):
    """What ``check --plot`` and the dashboard draw (``hli_server.scene``, whose docstring describes every
    key); lengths in mm, points ``[a, b, height, s]``."""

    __pydantic_config__ = _OPEN  # type: ignore[misc]

    scene: int
    channel: int | None
    axes: list[str]
    view: dict[str, str | None]
    bounds: dict[str, Any]
    areas: list[dict[str, Any]]
    path: list[list[list[float | None]]]
    refused: dict[str, Any] | None
    violation: dict[str, Any] | None
    stop: list[float | None] | None
    position: list[float | None] | None
    ahead: list[list[float | None]]


# --- the clock's pacing (``GET /api/timing``; docs/runtime.md, "Timing") ---------------------------------
class Lateness(TypedDict):
    """Percentiles of the lateness over the newest cycles and its maximum over the run [µs]."""

    p50: float
    p99: float
    p999: float
    max: float


class SlowCycleJson(TypedDict):
    """One of the worst cycles of the run and why it was late (``hli_server.runtime.pacing.CAUSES``)."""

    cycle: int
    lateness_us: float
    cause: str
    detail: str
    parts_us: dict[str, float]
    at_s: float


class PacingSummary(TypedDict):
    """How the clock kept pace (E-01), times in µs; ``lateness_us`` is None for a clock without due times
    (stepped, free); ``rate`` is simulated / wall time (None before any wall time passed)."""

    clock: str
    t_a_us: int
    cycles: int
    lateness_us: Lateness | None
    lateness_window: int
    late_cycles: int
    late_causes: dict[str, int]
    worst: list[SlowCycleJson]
    gc_collections: list[int]
    wakeups: int
    catch_up_wakeups: int
    max_catch_up: int
    slipped_cycles: int
    wall_s: float
    simulated_s: float
    rate: float | None


class Timing(PacingSummary):
    """``GET /api/timing``: the pacing and the cycles that failed (an exception in the engine's step)."""

    failed_cycles: int


# --- the recorder port (docs/record-replay.md) -----------------------------------------------------------
class RecorderStatus(TypedDict):
    """``GET /api/recording``: whether a recording runs, into which file, how far."""

    recording: bool
    file: str | None
    name: str | None
    started_cycle: int | None
    cycles: int
    bytes_written: int
    last_flush_s_ago: float | None
    journal_bytes: int
    journal_complete: bool
    error: str | None
    directory: str | None


class RecordingFile(TypedDict):
    """A recording in the recording directory (``GET /api/recordings``); ``modified`` in ISO 8601, UTC."""

    name: str
    bytes: int
    modified: str
    recording: bool


# --- the communication faults (B-03; docs/record-replay.md) ---------------------------------------------
class CommFault(TypedDict):
    """A communication fault in effect: its spec (the fields given, as ``POST /api/comm/faults`` took them),
    what it does in words, since when, how long and how often it has left."""

    id: int
    kind: Literal["delay", "drop", "error", "stall", "disconnect"]
    door: Literal["modbus", "ads", "shm", "mqtt"]
    delay_ms: NotRequired[int]
    after: NotRequired[int]
    code: NotRequired[int]
    first: NotRequired[int]
    last: NotRequired[int]
    table: NotRequired[str]
    index_group: NotRequired[int]
    duration_ms: NotRequired[int]
    cycles: NotRequired[int]
    count: NotRequired[int]
    description: str
    started_cycle: int
    ends_cycle: int | None
    left_ms: int | None
    used: int
    left: int | None


class CommFaultChange(TypedDict):
    """A change of the fault table, as its listeners get it: ``set`` (with the spec: the fields given, as
    ``POST /api/comm/faults`` took them) or ``end`` (with the reason: ``api``, ``reset``, ``duration``,
    ``cycles``, ``count``, ``engine``)."""

    fault: Literal["set", "end"]
    id: int
    spec: NotRequired[dict[str, int | str]]
    reason: NotRequired[str]


class CommFaultLogged(CommFaultChange):
    """A change of the fault table with the cycle it happened in (the table's history)."""

    cycle: int


class CommFaultTable(TypedDict):
    """``GET /api/comm/faults``: the faults in effect and the newest 50 changes."""

    faults: list[CommFault]
    history: list[CommFaultLogged]


class CommFaultsEnded(TypedDict):
    """``DELETE /api/comm/faults``: how many faults were in effect and ended."""

    ended: int


# --- the image by ST path (H-01, H-02) -------------------------------------------------------------------
class ImageField(TypedDict):
    """``GET``/``PUT /api/image/{st_path}``: a field's value (in the interface's units, ``unit``) with its
    type, direction and the cycle; a write adds the cycle that latches it (``effective_cycle``)."""

    st_path: str
    value: bool | int | float | str
    type: str
    direction: str
    access: str
    unit: str
    cycle: int
    effective_cycle: NotRequired[int]


class ReadinessJson(TypedDict):
    """``GET /api/ready``: ``ready`` is ``state == "running"`` with every door asked for up."""

    ready: bool
    state: Literal["starting", "running", "stopping"]
    doors: dict[str, bool]
    waiting_for: list[str]
    ports: dict[str, int]
    """the TCP port of each door that listens (``http``, ``modbus``, ``ads``)"""


# --- a program check (N-10; ``POST /api/check``, ``hli-server check --format json``) ---------------------
class CheckAlarm(TypedDict):
    id: Annotated[
        int, Field(description="the alarm number (the kernel's error ID where it has one; docs/alarms.md)")
    ]
    severity: str
    line: Annotated[
        int | None, Field(description="line of the program (or of the subprogram named in the message)")
    ]
    block: Annotated[str | None, Field(description="the block's label (N10) or `line N`")]
    message: str
    params: dict[str, Any]  # the alarm's own values (differ per alarm ID): really arbitrary JSON
    cycle: int


class CheckMessage(TypedDict):
    cycle: int
    text: Annotated[str, Field(description="the #MSG text, formatted")]
    save: Annotated[bool, Field(description="#MSG SAVE (a check writes no file)")]
    program: str
    line: int
    block: str


class CheckCap(TypedDict):
    by: Annotated[
        Literal["cycles", "iterations", "waiting"],
        Field(
            description="cycles / iterations: the check's cap; waiting: the program waits on inputs nobody "
            "changes in an offline check (warning 914052 names the loop and its V.E. variables; presets give "
            "them)"
        ),
    ]
    cap: Annotated[int, Field(description="the cap, or the cycle a waiting program was stopped at")]


class CheckReport(TypedDict):
    """What ``hli-server check --format json`` prints, with the program's name and the verdict."""

    program: str
    status: Annotated[
        Literal["ok", "stopped", "capped"],
        Field(
            description="ok: ran to its end without an error alarm; stopped: an error alarm stopped it (or "
            "it ended without M30/M02 where that is an error); capped: it did not end within max_cycles / "
            "max_iterations, or it waits on inputs nobody changes (capped.by: waiting)"
        ),
    ]
    exit_code: Annotated[
        int, Field(description="what `hli-server check` would exit with: 0 ok, 1 stopped, 3 capped")
    ]
    completed: bool
    mode: Literal["full", "geometry"]
    channel: int
    cycles: int
    simulated_time_s: float
    blocks: int
    alarms: list[CheckAlarm]
    messages: list[CheckMessage]
    capped: CheckCap | None
    final_position: Annotated[
        dict[str, float], Field(description="mm (degrees for rotary axes), rounded to 0.1 µm")
    ]
    elapsed_s: Annotated[float, Field(description="wall-clock time of the check [s]")]
    areas: Annotated[
        list[dict[str, Any]] | None,
        Field(description="the channel's work and protection areas at the end (FCT-C14); null: none defined"),
    ]


class TraceJson(TypedDict):
    """``POST /api/step``'s trace (H-07): the cycles and, per traced ST path, its value in each of them."""

    signals: list[str]
    cycles: list[int]
    values: dict[str, list[bool | int | float | str]]
