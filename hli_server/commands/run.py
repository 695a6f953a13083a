"""``hli-server run``: the machine, its process image and its adapters, until stopped (E-01, H-01).

    hli-server run [--config FILE] [--clock realtime|stepped|free] [--bind 127.0.0.1]
                   [--image-name NAME] [--adapter NAME[:key=value,...]] [--cycles N]
                   [--event-loop select|default] [--max-catch-up N]
                   [the adapters' short flags: --http-port N, --no-http, --modbus-port N, ...]

The adapters and their options are planned in one place, ``hli_server.adapters.registry.plan_adapters``
(defaults, the machine file's ``[[adapters]]``, ``--adapter``, the short flags of ``CLI_ALIASES``);
this command has no code of its own for any adapter.

Prints where everything listens (shared-memory image name, HTTP URL, the ports of further adapters)
and the clock, then runs until SIGINT/SIGTERM, or for ``--cycles`` cycles (scripts). On the way out
the adapters close their sockets and the shared memory is unlinked. Exit codes: 0 after a clean
stop, 1 when the engine failed while running, 2 for configuration or start-up errors (bad file,
port in use, image name taken).
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from hli_server.adapters.host import AccessPolicy
from hli_server.adapters.registry import CLI_ALIASES, AdapterError, options_model, plan_adapters
from hli_server.configuration import ConfigError, ConfigFileError, load_machine, machine_summary
from hli_server.recording.tap import RecordingOptions
from hli_server.runtime import Clock, Runtime, precise_event_loop

__all__ = ["run"]

logger = logging.getLogger(__name__)

_EXIT_FAILED = 1
_EXIT_START = 2


def _banner(runtime: Runtime, event_loop: str) -> None:
    config = runtime.config
    click.echo(f"hli-server: {machine_summary(config)}")
    click.echo(f"  clock: {runtime.clock} (T_A = {config.cycle_time_us} µs, event loop: {event_loop})")
    image = runtime.image
    layout = runtime.layout
    click.echo(
        f"  shared memory image: {image.name}  (/dev/shm/{image.name}; PLC->CNC {layout.p2c_size} B, "
        f"CNC->PLC {layout.c2p_size} B, layout {layout.hash[:12]})"
    )
    for adapter in runtime.adapters:
        for line in adapter.endpoints():
            click.echo(f"  {line}")
    policy = runtime.policy
    guards = [
        "read-only" if policy.read_only else "",
        "API token required for changes" if policy.api_token else "",
    ]
    if any(guards):
        click.echo(f"  access: {', '.join(g for g in guards if g)}")
    status = runtime.session.status()
    if status.recording:
        click.echo(f"  recording to {status.file} from cycle {status.started_cycle}")
    if runtime.stop_after_cycles is not None:
        click.echo(f"  stops after {runtime.stop_after_cycles} cycles")
    click.echo("  stop with Ctrl+C or SIGTERM")


def _is_loopback(bind: str) -> bool:
    if bind.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(bind.strip("[]")).is_loopback
    except ValueError:
        return False


def _farewell(runtime: Runtime) -> None:
    timing = runtime.timing()
    text = f"hli-server: stopped at cycle {runtime.machine.cycle} (simulated {runtime.machine.time:.3f} s)"
    lateness = timing["lateness_us"]
    if lateness is not None:
        text += (
            f"; lateness p50 {lateness['p50']:.0f} µs, p99 {lateness['p99']:.0f} µs, "
            f"max {lateness['max']:.0f} µs, {timing['slipped_cycles']} cycles dropped"
        )
    click.echo(text)


def _alias_options(command: Callable[..., None]) -> Callable[..., None]:
    """The adapters' short flags (``CLI_ALIASES``) as click options; their values go to ``plan_adapters``."""
    for alias in reversed(CLI_ALIASES):
        dest = "alias_" + alias.flag.removeprefix("--").replace("-", "_")
        if alias.option is None:
            option = click.option(alias.flag, dest, is_flag=True, default=False, help=alias.help)
        else:
            kind: Any = (
                click.Choice(list(alias.kind), case_sensitive=False)
                if isinstance(alias.kind, tuple)
                else alias.kind
            )
            default_value = options_model(alias.adapter).model_fields[alias.option].default
            option = click.option(
                alias.flag,
                dest,
                type=kind,
                default=None,
                metavar=alias.metavar or None,
                help=f"{alias.help} [default: {default_value}; "
                f"same as --adapter {alias.adapter}:{alias.option}=...]",
            )
        command = option(command)
    return command


@click.command()
@click.option(
    "--config",
    "config_path",
    type=click.Path(path_type=Path, dir_okay=False),
    default=None,
    help="machine file (TOML); default: the built-in demo machine",
)
@click.option(
    "--clock",
    type=click.Choice([c.value for c in Clock]),
    default=Clock.REALTIME.value,
    show_default=True,
    help="realtime: follow the wall clock; stepped: advance only via POST /api/step; "
    "free: as fast as possible",
)
@click.option("--bind", default="127.0.0.1", show_default=True, help="address the network adapters listen on")
@click.option(
    "--api-token",
    envvar="HLI_API_TOKEN",
    default=None,
    metavar="TOKEN",
    help="state-changing HTTP requests need 'Authorization: Bearer TOKEN' (or env HLI_API_TOKEN); "
    "required with a --bind beyond loopback",
)
@click.option("--insecure", is_flag=True, help="allow a --bind beyond loopback without --api-token")
@click.option(
    "--doors-process/--no-doors-process",
    default=True,
    show_default=True,
    help="serve Modbus and ADS from a second process attached to the shared memory, so that network "
    "load does not compete with the cycle (docs/reliability.md)",
)
@click.option("--read-only", is_flag=True, help="the network doors accept no writes (HTTP, Modbus, ADS)")
@click.option(
    "--allow-host",
    "allow_hosts",
    multiple=True,
    metavar="NAME",
    help="a host name the HTTP Host header may carry besides localhost and IP addresses (repeatable)",
)
@click.option(
    "--allow-origin",
    "allow_origins",
    multiple=True,
    metavar="ORIGIN",
    help="a web origin (http://host:port) whose pages may change the state (repeatable)",
)
@click.option(
    "--image-name",
    default=None,
    help="name of the shared-memory image (/dev/shm/NAME); default: a unique hli_<pid>_<random>",
)
@click.option(
    "--adapter",
    "adapter_specs",
    multiple=True,
    metavar="NAME[:KEY=VALUE,...]",
    help="start an adapter or set its options, e.g. --adapter modbus:port=5020 (repeatable)",
)
@_alias_options
@click.option(
    "--max-catch-up",
    type=click.IntRange(1, 1_000_000),
    default=50,
    show_default=True,
    help="realtime: most cycles run at once when the loop was late (beyond: simulated time slips)",
)
@click.option(
    "--event-loop",
    type=click.Choice(["select", "default"]),
    default="select",
    show_default=True,
    help="select: microsecond timers (realtime lateness ~0.1 ms); default: asyncio's (epoll, whole ms)",
)
@click.option("--cycles", type=click.IntRange(min=0), default=None, help="stop after N cycles (for scripts)")
@click.option(
    "--record",
    "record_file",
    type=click.Path(path_type=Path, dir_okay=False),
    default=None,
    help="record the session from the first cycle into FILE (.jsonl.gz; docs/record-replay.md)",
)
@click.option(
    "--record-dir",
    type=click.Path(path_type=Path, file_okay=False),
    default=None,
    help="where recordings started through the HTTP API or the dashboard go [default: the --record "
    "file's directory, else ./recordings]",
)
@click.option(
    "--record-flush",
    type=click.FloatRange(0.05, 60.0),
    default=1.0,
    show_default=True,
    help="seconds between flushes of a recording (what a crash can lose at most)",
)
@click.option(
    "--record-max-mb",
    type=click.IntRange(1, 1_000_000),
    default=2048,
    show_default=True,
    help="a recording is closed when it reaches this size",
)
@click.option(
    "--journal-limit-mb",
    type=click.IntRange(1, 100_000),
    default=256,
    show_default=True,
    help="the input journal in memory (what makes a recording started later replayable) is dropped "
    "beyond this",
)
@click.pass_context
def run(
    ctx: click.Context,
    /,
    config_path: Path | None,
    clock: str,
    bind: str,
    api_token: str | None,
    insecure: bool,
    doors_process: bool,
    read_only: bool,
    allow_hosts: tuple[str, ...],
    allow_origins: tuple[str, ...],
    image_name: str | None,
    adapter_specs: tuple[str, ...],
    max_catch_up: int,
    event_loop: str,
    cycles: int | None,
    record_file: Path | None,
    record_dir: Path | None,
    record_flush: float,
    record_max_mb: int,
    journal_limit_mb: int,
    **alias_values: Any,
) -> None:
    """Run the machine with its process image and adapters until stopped."""
    try:
        config = load_machine(config_path)
    except ConfigFileError as exc:
        for message in exc.messages:
            click.echo(f"error: {message}", err=True)
        ctx.exit(_EXIT_START)
    except ConfigError as exc:
        for message in [*exc.messages, *exc.notes]:
            click.echo(message, err=True)
        click.echo("the configuration is invalid: check it with `hli-server config validate FILE`", err=True)
        ctx.exit(_EXIT_START)

    if not _is_loopback(bind) and not api_token and not insecure:
        click.echo(
            f"error: --bind {bind} lets other machines in: give an --api-token (or HLI_API_TOKEN) so that "
            "only holders of the token can change the machine's state, or --insecure if this network is "
            "yours alone",
            err=True,
        )
        ctx.exit(_EXIT_START)
    policy = AccessPolicy(
        api_token=api_token or None,
        read_only=read_only,
        allowed_hosts=tuple(allow_hosts),
        allowed_origins=tuple(allow_origins),
    )
    aliases = {
        alias.flag: alias_values.get("alias_" + alias.flag.removeprefix("--").replace("-", "_"))
        for alias in CLI_ALIASES
    }
    try:
        adapters = plan_adapters([(a.name, dict(a.options)) for a in config.adapters], adapter_specs, aliases)
        runtime = Runtime(
            config,
            clock=clock,
            bind=bind,
            image_name=image_name,
            adapters=adapters,
            max_catch_up=max_catch_up,
            stop_after_cycles=cycles,
            policy=policy,
            doors_process=doors_process,
            recording=RecordingOptions(
                file=record_file,
                directory=record_dir or (None if record_file is not None else Path("recordings")),
                flush_s=record_flush,
                max_bytes=record_max_mb * 1024 * 1024,
                journal_limit=journal_limit_mb * 1024 * 1024,
            ),
        )
    except (AdapterError, ValueError) as exc:
        click.echo(f"error: {exc}", err=True)
        ctx.exit(_EXIT_START)

    try:
        loop_factory = precise_event_loop if event_loop == "select" else None
        with asyncio.Runner(loop_factory=loop_factory) as runner:
            runner.run(runtime.serve(ready=lambda rt: _banner(rt, event_loop)))
    except KeyboardInterrupt:  # Ctrl+C before the signal handlers were installed
        pass
    except Exception as exc:
        if runtime.stats.started_at is None:  # start-up failed: port in use, image name taken, ...
            click.echo(f"error: {exc}", err=True)
            ctx.exit(_EXIT_START)
        logger.exception("the runtime failed")
        click.echo(f"error: the runtime failed at cycle {runtime.machine.cycle}: {exc!r}", err=True)
        ctx.exit(_EXIT_FAILED)
    _farewell(runtime)
