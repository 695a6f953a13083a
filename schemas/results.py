"""What the operator port answers (``hli_server.adapters.host.OperatorPort``), typed: the machine's state,
its alarms, an axis' faults and software limits, the area table, the dashboard's scene, the program table,
the collision pairs. Every door serves these shapes (the HTTP API declares them as its ``response_model``, so
the OpenAPI description at ``/openapi.json`` says what comes back; the MQTT snapshot and the remote link
carry the same dictionaries).

They are ``TypedDict``\\ s, not classes: the values stay plain JSON-able dictionaries (what the engine builds,
what a recording journals, what crosses the doors process' link), and mypy checks the keys. Keys a shape
has only sometimes are ``NotRequired``; a shape that may grow keys without a schema change allows extra
keys. Lengths are mm here (the operator's view), positions on the image are 0.1 µm (``schemas.units``).
Non-finite numbers follow the project's one JSON policy: ``null``.
"""

from __future__ import annotations

from typing import Any, NotRequired

from pydantic import ConfigDict
from typing_extensions import TypedDict

__all__ = [
    "AlarmJson",
    "AlarmList",
    "AreaTable",
    "AxisFaults",
    "AxisState",
    "ChannelState",
    "CollisionPair",
    "ExternalVariable",
    "LimitValues",
    "MachineState",
    "ProgramEntry",
    "ProgramLoaded",
    "ProgramSelected",
    "Scene",
    "SoftLimits",
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
    params: dict[str, Any]


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
    value: Any


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
