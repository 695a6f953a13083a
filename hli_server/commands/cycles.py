"""``hli-server cycles``: the built-in cycle stand-ins and the documented cycles not built, as Markdown
(the generated part of docs/cycles.md): each stand-in's parameters as its table checks them, with the
kernel's error ID, its outputs and what it moves."""

from __future__ import annotations

import click

from hli_server.engine.cycles import BUILT, NOT_BUILT, StandIn

__all__ = ["cycles", "cycles_markdown"]


def _standin(spec: StandIn) -> list[str]:
    lines = [
        f"### {spec.name}: {spec.title}",
        "",
        f"{spec.package}, [page]({spec.page}). Moves: {spec.moves}.",
        "",
        "| @P | meaning | required | default | checked | ID |",
        "|---:|---|---|---|---|---|",
    ]
    for p in sorted(spec.params, key=lambda p: p.number):
        alarm = str(p.alarm) if p.alarm else "917000"
        lines.append(
            f"| {p.number} | {p.meaning} | {'yes' if p.required else '-'} | {p.default_doc} | {p.rule_doc} | "
            f"{alarm} |"
        )
    if spec.outputs:
        lines += ["", "| output | value |", "|---|---|"]
        lines += [f"| `V.CYC.{o.name}` | {o.meaning} |" for o in spec.outputs]
    return [*lines, ""]


def cycles_markdown() -> str:
    out = [f"## Built ({len(BUILT)})", ""]
    for spec in BUILT:
        out += _standin(spec)
    out += [
        f"## Not built ({len(NOT_BUILT)}): refused with 910110 naming the cycle",
        "",
        "| cycle | package | what | page |",
        "|---|---|---|---|",
    ]
    out += [f"| {c.name} | {c.package} | {c.title} | [page]({c.page}) |" for c in NOT_BUILT]
    return "\n".join(out) + "\n"


@click.command()
def cycles() -> None:
    """Print the built-in cycles (Markdown): parameters, error IDs, outputs; and those not built."""
    click.echo(cycles_markdown(), nl=False)
