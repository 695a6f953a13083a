"""``hli-server run``: the machine, its process image and the control API, until stopped (E-01, H-01).

    hli-server run [--config FILE] [--clock realtime|stepped|free] [--bind 127.0.0.1]
                   [--http-port N] [--image-name NAME] [--adapter NAME[:key=value,...]] [--cycles N]
                   [--event-loop select|default] [--max-catch-up N]
                   [--modbus-port N] [--modbus-word-order ABCD|CDAB] [--modbus-unit-id N] [--no-modbus]

Prints where everything listens (shared-memory image name, HTTP URL, the ports of further adapters)
and the clock, then runs until SIGINT/SIGTERM, or for ``--cycles`` cycles (scripts). On the way out
the adapters close their sockets and the shared memory is unlinked. Exit codes: 0 after a clean
stop, 1 when the engine failed while running, 2 for configuration or start-up errors (bad file,
port in use, image name taken).
"""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path
from typing import Any

import click

from hli_server.adapters.registry import AdapterError, available_adapters, parse_adapter_spec
from hli_server.configuration import ConfigError, ConfigFileError, load_machine, machine_summary
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
    if runtime.stop_after_cycles is not None:
        click.echo(f"  stops after {runtime.stop_after_cycles} cycles")
    click.echo("  stop with Ctrl+C or SIGTERM")


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
    "--http-port",
    type=click.IntRange(0, 65535),
    default=8080,
    show_default=True,
    help="port of the HTTP control API (0: any free port)",
)
@click.option("--no-http", is_flag=True, help="do not start the HTTP control API")
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
    help="start another adapter, e.g. --adapter modbus:port=5020 (repeatable)",
)
@click.option(
    "--modbus-port",
    type=click.IntRange(0, 65535),
    default=5020,
    show_default=True,
    help="port of the Modbus TCP view of the image (H-03; 0: any free port)",
)
@click.option(
    "--modbus-word-order",
    type=click.Choice(["ABCD", "CDAB"], case_sensitive=False),
    default="ABCD",
    show_default=True,
    help="Modbus: order of the two registers of a 32-bit value (ABCD: high word first)",
)
@click.option(
    "--modbus-unit-id", type=click.IntRange(0, 255), default=1, show_default=True, help="Modbus unit id"
)
@click.option("--no-modbus", is_flag=True, help="do not start the Modbus TCP server")
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
@click.pass_context
def run(
    ctx: click.Context,
    config_path: Path | None,
    clock: str,
    bind: str,
    http_port: int,
    no_http: bool,
    image_name: str | None,
    adapter_specs: tuple[str, ...],
    modbus_port: int,
    modbus_word_order: str,
    modbus_unit_id: int,
    no_modbus: bool,
    max_catch_up: int,
    event_loop: str,
    cycles: int | None,
) -> None:
    """Run the machine with its process image and control API until stopped."""
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

    adapters: list[tuple[str, dict[str, Any]]] = []
    if not no_http:
        adapters.append(("http", {"port": http_port}))
    try:
        from_cli = [parse_adapter_spec(spec) for spec in adapter_specs]
        cli_names = {name for name, _ in from_cli}
        # the machine file's adapters first; an --adapter of the same name replaces its entry
        configured = [(a.name, dict(a.options)) for a in config.adapters if a.name not in cli_names]
        for name, options in [*configured, *from_cli]:
            if name not in available_adapters():
                raise AdapterError(f"unknown adapter {name!r}; available: {', '.join(available_adapters())}")
            if no_modbus and name == "modbus":
                continue
            adapters.append((name, options))
        if not no_modbus and not any(name == "modbus" for name, _ in adapters):
            modbus = {"port": modbus_port, "word_order": modbus_word_order.upper(), "unit_id": modbus_unit_id}
            adapters.append(("modbus", modbus))
        runtime = Runtime(
            config,
            clock=clock,
            bind=bind,
            http_port=None if no_http else http_port,
            image_name=image_name,
            adapters=adapters,
            max_catch_up=max_catch_up,
            stop_after_cycles=cycles,
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
