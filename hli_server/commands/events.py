"""``hli-server events``: every kind of event with its topic and payload (the source of the tables in
docs/api.md and docs/mqtt.md; generated from ``schemas/events.py``)."""

from __future__ import annotations

import dataclasses
import typing

import click

from schemas.events import EVENT_TYPES, Alarm, Event

__all__ = ["events", "events_markdown", "mqtt_markdown"]

_ENVELOPE = {f.name for f in dataclasses.fields(Event)}


def _fields(kind: type[Event]) -> str:
    hints = typing.get_type_hints(kind)
    parts = []
    for f in dataclasses.fields(kind):
        if f.name in _ENVELOPE:
            continue
        parts.append(f"`{f.name}`: {_type_name(hints[f.name])}")
    return ", ".join(parts)


def _type_name(tp: object) -> str:
    if tp is Alarm:
        return "object {" + ", ".join(Alarm(0, "", 0, 0, "").to_json()) + "}"
    text = str(tp)
    for noise in ("typing.", "schemas.events.", "<class '", "'>"):
        text = text.replace(noise, "")
    return text.replace("|", "\\|")


def events_markdown() -> str:
    lines = ["| kind | topic | payload (`data`) | when |", "|---|---|---|---|"]
    for kind in EVENT_TYPES:
        lines.append(f"| `{kind.KIND}` | `{kind.TOPIC}` | {_fields(kind)} | {kind.DESCRIPTION} |")
    return "\n".join(lines) + "\n"


def mqtt_markdown(prefix: str = "hli/<machine>/") -> str:
    """The MQTT topics below ``prefix`` (docs/mqtt.md): the adapter's own three, then one per kind of
    event, with its payload, and an example message."""
    import json

    from hli_server.codecs.event_json import DROPPED_TOPIC, SNAPSHOT_TOPIC, STATUS_TOPIC, encode_event
    from schemas.events import ModeChanged

    own = (
        (
            STATUS_TOPIC,
            "yes",
            "`online` or `offline` (text, not JSON)",
            "`online` at every (re)connect, `offline` at a clean stop; `offline` is also the Will, "
            "published by the broker when the server vanishes",
        ),
        (
            SNAPSHOT_TOPIC,
            "yes",
            "`machine`, `seq`, `cycle`, `time_s`, `wall_time`, `channels` (as `GET /api/state`), "
            "`alarms` (active)",
            "at every (re)connect and after the channel state changed (at most every 0.25 s): what a "
            "late subscriber needs to see the present",
        ),
        (
            DROPPED_TOPIC,
            "no",
            "`machine`, `dropped`, `dropped_total`, `first_seq`, `last_seq`, `queue_size`, `wall_time`",
            "after a reconnect (or, with a slow broker, at most every second) when the bounded queue "
            "dropped events; `first_seq`..`last_seq` are the `seq` numbers lost",
        ),
    )
    lines = ["| topic | retained | kind | payload (`data`) | when |", "|---|---|---|---|---|"]
    lines += [f"| `{prefix}{topic}` | {kept} | | {payload} | {when} |" for topic, kept, payload, when in own]
    for kind in EVENT_TYPES:
        lines.append(
            f"| `{prefix}{kind.TOPIC}` | no | `{kind.KIND}` | {_fields(kind)} | {kind.DESCRIPTION} |"
        )
    example = ModeChanged(cycle=1203, time_s=1.203, channel=1, mode="manual", previous="automatic")
    topic, payload = encode_event(example, prefix="hli/demo/", machine="demo", seq=17, wall=1746091812.345)
    text = json.dumps(json.loads(payload), indent=2, ensure_ascii=False)
    lines += ["", f"An event as it arrives, on `{topic}`:", "", "```json", text, "```"]
    return "\n".join(lines) + "\n"


@click.command()
@click.option("--mqtt", "mqtt", is_flag=True, help="the MQTT topics with their payloads (docs/mqtt.md)")
def events(mqtt: bool) -> None:
    """Print the kinds of events, their topics and payloads (Markdown)."""
    click.echo(mqtt_markdown() if mqtt else events_markdown(), nl=False)
