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
import signal
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from hli_server._compiled import stale_notice
from hli_server.adapters.host import AccessPolicy
from hli_server.adapters.registry import (
    CLI_ALIASES,
    AdapterError,
    DoorGuard,
    door_guards,
    options_model,
    plan_adapters,
)
from hli_server.configuration import ConfigError, ConfigFileError, load_machine, machine_summary
from hli_server.recording.tap import DEFAULT_OUTPUTS_EVERY, RecordingOptions
from hli_server.runtime import Clock, Runtime, precise_event_loop
from hli_server.runtime.doors import DoorsProcess
from hli_server.runtime.pacing import PRIORITIES, probed_default_loop

__all__ = ["run"]

logger = logging.getLogger(__name__)

_EXIT_FAILED = 1
_EXIT_START = 2


def doors_line(runtime: Runtime) -> str:
    """Which process serves the network doors: ``run`` serves them from a second process by default, a
    ``Runtime`` built in Python (the test harness) from its own; the banner says which one runs."""
    doors = next((a for a in runtime.adapters if isinstance(a, DoorsProcess)), None)
    if doors is not None:
        granted = "".join(f", {g}" for g in doors.granted)
        return (
            f"network doors: served by a second process (pid {doors.pid}{granted}), attached to the shared "
            "memory (--no-doors-process: in the clock's process)"
        )
    if runtime.doors_process:
        return "network doors: none that a second process serves (everything runs in the clock's process)"
    return "network doors: served in the clock's process (--doors-process: from a second process)"


def _banner(runtime: Runtime, event_loop: str, guards: list[DoorGuard]) -> None:
    config = runtime.config
    click.echo(f"hli-server: {machine_summary(config)}")
    clock = f"  clock: {runtime.clock} (T_A = {config.cycle_time_us} µs, event loop: {event_loop}"
    if runtime.clock == "realtime":
        clock += f", priority: {runtime.priority_granted}"
    click.echo(clock + ")")
    notice = stale_notice()
    if notice is not None:  # an edited compiled source: the whole engine runs as pure Python
        click.echo(f"  WARNING: {notice}")
    image = runtime.image
    layout = runtime.layout
    click.echo(
        f"  shared memory image: {image.name}  (/dev/shm/{image.name}; PLC->CNC {layout.p2c_size} B, "
        f"CNC->PLC {layout.c2p_size} B, layout {layout.hash[:12]})"
    )
    click.echo(f"  {doors_line(runtime)}")
    for adapter in runtime.adapters:
        for line in adapter.endpoints():
            click.echo(f"  {line}")
    click.echo(f"  NC output directory (#MSG SAVE report files): {runtime.nc_files.directory}")
    searched = runtime.programs.directories.searched()
    if searched:
        click.echo(f"  program directories (L name): {', '.join(searched)}")
    policy = runtime.policy
    if not _is_loopback(runtime.bind) or policy.read_only or policy.read_only_doors or policy.api_token:
        where = "loopback only" if _is_loopback(runtime.bind) else f"bound to {runtime.bind}"
        click.echo(f"  access ({where}):")
        for guard in guards:  # by door name: a script that reads the banner's door lines is not misled
            click.echo(f"    door {guard.door}: {guard.how}")
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
    causes = timing.get("late_causes") or {}
    late = sum(causes.values())
    machine = causes.get("os", 0) + causes.get("preempted", 0)
    if late >= 10 and machine > late / 2 and not runtime.priority_granted.startswith("realtime"):
        click.echo(
            f"hli-server: {machine} of the {late} cycles later than T_A waited for a CPU (other load on the "
            "machine): the realtime priority (root or CAP_SYS_NICE, e.g. docker run --cap-add SYS_NICE) lets "
            "the clock go first (docs/runtime.md)"
        )


class _EarlySignals:
    """SIGINT/SIGTERM from the first line of the command until the runtime's own handlers take over
    (``Runtime.serve`` installs them before its first step): a signal is noted, never raised in the
    middle of a start-up step, and the runtime stops between two steps, undoing what it started.
    :meth:`restore` puts the previous handlers back (the command run in-process, by a test)."""

    def __init__(self) -> None:
        self.runtime: Runtime | None = None
        self.signalled = False
        self._previous: dict[int, Any] = {}
        if threading.current_thread() is threading.main_thread():  # else Python has no handlers to set
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.signal(sig, self._note)

    def _note(self, signum: int, frame: object) -> None:
        self.signalled = True
        if self.runtime is not None:
            self.runtime.stop_requested = True  # a plain flag: the event loop may be mid-step here

    def restore(self) -> None:
        for sig, handler in self._previous.items():
            if handler is not None:
                signal.signal(sig, handler)
        self._previous.clear()


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
    help="the HTTP door's changes, its event log and the recordings need 'Authorization: Bearer TOKEN' "
    "(or env HLI_API_TOKEN); it guards HTTP only: Modbus and ADS by their allow lists or --read-only-door",
)
@click.option(
    "--insecure",
    is_flag=True,
    help="allow a --bind beyond loopback with doors that accept writes from anyone (a warning says which)",
)
@click.option(
    "--doors-process/--no-doors-process",
    default=True,
    show_default=True,
    help="serve Modbus and ADS from a second process attached to the shared memory, so that network "
    "load does not compete with the cycle (docs/reliability.md)",
)
@click.option("--read-only", is_flag=True, help="the network doors accept no writes (HTTP, Modbus, ADS)")
@click.option(
    "--read-only-door",
    "read_only_doors",
    multiple=True,
    type=click.Choice(["http", "modbus", "ads"]),
    help="this door accepts no writes, the others do (repeatable)",
)
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
@click.option(
    "--priority",
    type=click.Choice(list(PRIORITIES)),
    default="auto",
    show_default=True,
    help="the realtime clock's thread: realtime (SCHED_FIFO) or high (nice -10) where permitted (root or "
    "CAP_SYS_NICE), so that other load on the machine delays the cycle less; auto: realtime if permitted, "
    "else normal (docs/runtime.md)",
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
    "--record-outputs-every",
    type=click.IntRange(1, 1_000_000),
    default=DEFAULT_OUTPUTS_EVERY,
    show_default=True,
    help="a recording samples the outputs every N cycles (the replay's checkpoints; the inputs and "
    "events are stored at every cycle); 1: every cycle, at a cost per cycle (docs/record-replay.md)",
)
@click.option(
    "--journal-limit-mb",
    type=click.IntRange(1, 100_000),
    default=256,
    show_default=True,
    help="the input journal in memory (what makes a recording started later replayable) is dropped "
    "beyond this",
)
@click.option(
    "--program-dir",
    "program_dirs",
    multiple=True,
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    help="a directory where `L name` finds global subprograms and cycles; searched before the machine "
    "file's program_directories (repeatable, in order)",
)
@click.option(
    "--nc-output-dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="where #MSG SAVE writes the programs' report files (never elsewhere); default: a new "
    "temporary directory, named in the banner",
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
    read_only_doors: tuple[str, ...],
    allow_hosts: tuple[str, ...],
    allow_origins: tuple[str, ...],
    image_name: str | None,
    adapter_specs: tuple[str, ...],
    max_catch_up: int,
    event_loop: str,
    priority: str,
    cycles: int | None,
    record_file: Path | None,
    record_dir: Path | None,
    record_flush: float,
    record_max_mb: int,
    journal_limit_mb: int,
    record_outputs_every: int,
    program_dirs: tuple[Path, ...],
    nc_output_dir: Path | None,
    **alias_values: Any,
) -> None:
    """Run the machine with its process image and adapters until stopped."""
    early = _EarlySignals()
    ctx.call_on_close(early.restore)
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

    policy = AccessPolicy(
        api_token=api_token or None,
        read_only=read_only,
        allowed_hosts=tuple(allow_hosts),
        allowed_origins=tuple(allow_origins),
        read_only_doors=tuple(read_only_doors),
    )
    aliases = {
        alias.flag: alias_values.get("alias_" + alias.flag.removeprefix("--").replace("-", "_"))
        for alias in CLI_ALIASES
    }
    try:
        adapters = plan_adapters([(a.name, dict(a.options)) for a in config.adapters], adapter_specs, aliases)
    except (AdapterError, ValueError) as exc:
        click.echo(f"error: {exc}", err=True)
        ctx.exit(_EXIT_START)
    guards = door_guards(adapters, policy)
    open_doors = [g for g in guards if not g.guarded]
    if not _is_loopback(bind) and open_doors:
        if not insecure:
            lines = [f"  {g.label} ({g.how}): {g.fix}" for g in open_doors]
            click.echo(
                f"error: --bind {bind} lets other machines in, and these doors would take their writes "
                "unguarded (the API token guards the HTTP door only):\n"
                + "\n".join(lines)
                + "\nor give --insecure if this network is yours alone",
                err=True,
            )
            ctx.exit(_EXIT_START)
        click.echo(
            f"warning: --insecure: on {bind}, anyone on the network can change the machine through "
            + ", ".join(g.label for g in open_doors),
            err=True,
        )
    try:
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
            priority=priority,
            recording=RecordingOptions(
                file=record_file,
                directory=record_dir or (None if record_file is not None else Path("recordings")),
                flush_s=record_flush,
                max_bytes=record_max_mb * 1024 * 1024,
                journal_limit=journal_limit_mb * 1024 * 1024,
                outputs_every=record_outputs_every,
            ),
            program_dirs=program_dirs,
            nc_output_dir=nc_output_dir,
        )
    except (AdapterError, ValueError, OSError) as exc:  # OSError: --nc-output-dir cannot be made
        click.echo(f"error: {exc}", err=True)
        ctx.exit(_EXIT_START)
    early.runtime = runtime
    if early.signalled:
        click.echo("hli-server: stopped before it started")
        return

    try:
        loop_factory = precise_event_loop if event_loop == "select" else probed_default_loop
        with asyncio.Runner(loop_factory=loop_factory) as runner:
            runner.run(runtime.serve(ready=lambda rt: _banner(rt, event_loop, guards)))
    except KeyboardInterrupt:  # Ctrl+C before the signal handlers were installed
        pass
    except Exception as exc:
        if runtime.stats.started_at is None:  # start-up failed: port in use, image name taken, ...
            click.echo(f"error: {exc}", err=True)
            ctx.exit(_EXIT_START)
        logger.exception("the runtime failed")
        click.echo(f"error: the runtime failed at cycle {runtime.machine.cycle}: {exc!r}", err=True)
        ctx.exit(_EXIT_FAILED)
    if runtime.stats.started_at is None:
        click.echo("hli-server: stopped during start-up")
        return
    _farewell(runtime)
