"""``hli-server events``: every kind of event with its topic and payload (the source of the tables in
docs/api.md and docs/mqtt.md; generated from ``schemas/events.py``)."""

from __future__ import annotations

import dataclasses
import typing

import click

from schemas.events import EVENT_TYPES, Alarm, Event

__all__ = ["events", "events_markdown"]

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


@click.command()
def events() -> None:
    """Print the kinds of events, their topics and payloads (Markdown)."""
    click.echo(events_markdown(), nl=False)
