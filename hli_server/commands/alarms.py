"""``hli-server alarms``: the alarm table as Markdown (the source of docs/alarms.md).

The ``ID`` column says whose number it is: ``kernel`` (the kernel's own ID, from a function
description or a diagnosis page, linked) or ``project`` (the project's own number, where the kernel
documents none). ``replaces`` names the project numbers an earlier version raised for the same case.
"""

from __future__ import annotations

import click

from hli_server.engine.alarms import ALARMS, AlarmDef

__all__ = ["alarms", "alarms_markdown"]


def _origin(a: AlarmDef) -> str:
    if not a.kernel:
        return "project"
    return f"[kernel]({a.page})" if a.page else "kernel"


def alarms_markdown() -> str:
    lines = [
        "| number | ID | severity | reaction | text | source | replaces |",
        "|---:|---|---|---|---|---|---|",
    ]
    for number in sorted(ALARMS):
        a = ALARMS[number]
        replaces = ", ".join(str(n) for n in a.replaces) or "-"
        lines.append(
            f"| {a.number} | {_origin(a)} | {a.severity} | {a.reaction} | {a.text} | {a.source} "
            f"| {replaces} |"
        )
    return "\n".join(lines) + "\n"


@click.command()
def alarms() -> None:
    """Print the alarm table (Markdown): the kernel's IDs with their pages, the project's numbers."""
    click.echo(alarms_markdown(), nl=False)
