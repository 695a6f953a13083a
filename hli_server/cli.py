"""The command line: ``hli-server run | check | config | map | alarms | cycles | events | record | replay``.

Each command lives in its own module under ``hli_server/commands``; this file only assembles them.
Exit codes: 0 success, 1 the checked program or the validated file has an error, 2 usage, file or
configuration errors.
"""

from __future__ import annotations

import importlib
import importlib.util
import logging

import click

__all__ = ["main"]

_COMMANDS = {
    "config": "hli_server.commands.config:config",
    "check": "hli_server.commands.check:check",
    "run": "hli_server.commands.run:run",
    "map": "hli_server.commands.map:map_command",
    "alarms": "hli_server.commands.alarms:alarms",
    "cycles": "hli_server.commands.cycles:cycles",
    "events": "hli_server.commands.events:events",
    "record": "hli_server.commands.record:record",
    "replay": "hli_server.commands.record:replay_command",
}


class _LazyGroup(click.Group):
    """Imports a command's module only when it is used (keeps ``--help`` and ``check`` fast)."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(name for name, target in _COMMANDS.items() if _available(target))

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        target = _COMMANDS.get(cmd_name)
        if target is None or not _available(target):
            return None
        module, attr = target.split(":")
        cmd: click.Command = getattr(importlib.import_module(module), attr)
        return cmd


def _available(target: str) -> bool:
    module = target.split(":", maxsplit=1)[0]
    return importlib.util.find_spec(module) is not None


@click.group(cls=_LazyGroup)
@click.option("-v", "--verbose", count=True, help="more log output (-vv for debug)")
@click.version_option(package_name="hli-server")
def main(verbose: int) -> None:
    """A simulated CNC kernel with its PLC interface (HLI)."""
    level = logging.WARNING - 10 * min(verbose, 2)
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
