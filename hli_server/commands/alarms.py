"""``hli-server alarms``: the alarm table as Markdown (the source of docs/alarms.md)."""

from __future__ import annotations

import click

from hli_server.engine.alarms import ALARMS


def alarms_markdown() -> str:
    lines = [
        "| number | severity | reaction | text | source |",
        "|---:|---|---|---|---|",
    ]
    for number in sorted(ALARMS):
        a = ALARMS[number]
        lines.append(f"| {a.number} | {a.severity} | {a.reaction} | {a.text} | {a.source} |")
    return "\n".join(lines) + "\n"


@click.command()
def alarms() -> None:
    """Print the alarm table (Markdown)."""
    click.echo(alarms_markdown(), nl=False)
