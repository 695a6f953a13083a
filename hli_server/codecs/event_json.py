"""Events as JSON messages (H-05): the envelope every JSON door puts around a ``schemas.events`` event,
and the MQTT topics below a prefix (docs/mqtt.md, generated from this module and the schema).

No I/O: the MQTT adapter publishes what :func:`encode_event` returns, ``hli-server events`` draws its
tables from the same functions. An event's message::

    {"machine": "demo", "kind": "mode", "seq": 17, "cycle": 1203, "time_s": 1.203,
     "wall_time": "2025-05-01T09:30:12.345Z", "channel": 1, "axis": null, "data": {...payload}}

Non-finite numbers follow the project's JSON policy (:mod:`hli_server.codecs.json_policy`): ``null``.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any, Final

from hli_server.codecs.json_policy import dumps_utf8
from schemas.events import AlarmRaised, Event

__all__ = [
    "DROPPED_TOPIC",
    "SNAPSHOT_TOPIC",
    "STATUS_TOPIC",
    "dumps",
    "encode_event",
    "event_message",
    "wall_time_text",
]

STATUS_TOPIC: Final = "status"
"""Retained ``online``/``offline`` below the prefix; ``offline`` is also the Will."""
SNAPSHOT_TOPIC: Final = "snapshot"
"""Retained JSON picture of the channels and the active alarms below the prefix."""
DROPPED_TOPIC: Final = "dropped"
"""JSON report of the events the bounded queue dropped, below the prefix."""


def wall_time_text(wall: float) -> str:
    """``2025-05-01T09:30:12.345Z``: UTC, milliseconds."""
    return datetime.fromtimestamp(wall, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _axis_of(event: Event) -> str | None:
    if isinstance(event, AlarmRaised):
        return event.alarm.axis
    for name in ("axis", "master"):
        value = getattr(event, name, None)
        if isinstance(value, str):
            return value
    return None


def dumps(obj: dict[str, Any]) -> bytes:
    """Compact JSON, UTF-8; non-finite floats as null (the project's JSON policy)."""
    return dumps_utf8(obj)


def event_message(event: Event, *, machine: str, seq: int, wall: float) -> dict[str, Any]:
    """The JSON object of one event (docs/mqtt.md): envelope plus the schema's payload as ``data``."""
    return {
        "machine": machine,
        "kind": event.KIND,
        "seq": seq,
        "cycle": event.cycle,
        "time_s": event.time_s,
        "wall_time": wall_time_text(wall),
        "channel": event.channel,
        "axis": _axis_of(event),
        "data": event.payload(),
    }


def encode_event(event: Event, *, prefix: str, machine: str, seq: int, wall: float) -> tuple[str, bytes]:
    """``(topic, payload)`` of one event."""
    return prefix + event.topic(), dumps(event_message(event, machine=machine, seq=seq, wall=wall))
