"""``hli-server config``: validate and show machine configurations (E-07).

* ``hli-server config validate FILE``: exit 0 and an ``OK: ...`` summary; exit 1 with every finding
  (``file:line: key: text``) on stderr when the configuration is invalid; exit 2 when FILE is
  missing or cannot be read.
* ``hli-server config show [FILE]``: the effective configuration (TOML plus parameter lists, with
  defaults) as JSON; the built-in demo machine without FILE.
* ``hli-server config parameters``: the parameter table of ``docs/configuration.md`` (Markdown).
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from hli_server.configuration import (
    ConfigError,
    ConfigFileError,
    load_machine_with_warnings,
    machine_summary,
    parameter_table_markdown,
)
from schemas.config import MachineConfig

__all__ = ["config"]

_EXIT_INVALID = 1
_EXIT_FILE = 2


def _load(ctx: click.Context, path: Path | None) -> tuple[MachineConfig, list[str]]:
    try:
        return load_machine_with_warnings(path)
    except ConfigFileError as exc:
        for message in exc.messages:
            click.echo(f"error: {message}", err=True)
        ctx.exit(_EXIT_FILE)
    except ConfigError as exc:
        for message in [*exc.messages, *exc.notes]:
            click.echo(message, err=True)
        count = len(exc.messages)
        click.echo(f"{count} error{'s' if count != 1 else ''}: configuration is invalid", err=True)
        ctx.exit(_EXIT_INVALID)
    raise AssertionError("unreachable")  # ctx.exit raises


@click.group()
def config() -> None:
    """Machine configuration: validate, show, parameters."""


@config.command()
@click.argument("file", type=click.Path(path_type=Path, dir_okay=True))
@click.pass_context
def validate(ctx: click.Context, file: Path) -> None:
    """Check a machine file and the parameter lists it names."""
    machine, warnings = _load(ctx, file)
    for warning in warnings:
        click.echo(f"warning: {warning}", err=True)
    click.echo(f"OK: {file}: {machine_summary(machine)}")


@config.command()
@click.argument("file", type=click.Path(path_type=Path, dir_okay=True), required=False)
@click.pass_context
def show(ctx: click.Context, file: Path | None) -> None:
    """Print the effective configuration as JSON (the demo machine without FILE)."""
    machine, warnings = _load(ctx, file)
    for warning in warnings:
        click.echo(f"warning: {warning}", err=True)
    click.echo(json.dumps(machine.model_dump(mode="json"), indent=2, ensure_ascii=False))


@config.command()
def parameters() -> None:
    """Print every configuration parameter (P-ID, ISG path, unit, default, range) as Markdown."""
    click.echo(parameter_table_markdown(), nl=False)
