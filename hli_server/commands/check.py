"""``hli-server check PROGRAM``: run a program offline and report what the monitors find.

Two modes:

* full (default): the program runs free in automatic mode on the machine, cycle by cycle, with every
  monitor active, from the start to M30/M02 or the end of the file;
* ``--geometry-only``: the program is decoded and every block's whole path is checked (soft limits,
  work and protection areas), without interpolating cycles - the mode for programs of millions of
  blocks. Cycle-based monitors (dynamic limits, collision, position monitoring) need cycles and are
  not evaluated in this mode.

Exit codes: 0 ran to the end without an error alarm; 1 an error alarm stopped it; 2 usage, file or
configuration errors.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import click

from hli_server.engine import Machine
from hli_server.engine.alarms import Alarm, Severity
from hli_server.engine.nc.parser import iter_blocks
from hli_server.engine.planner import Marker, MarkerKind, Motion
from schemas.wire import ProgramState

__all__ = ["CheckResult", "check", "check_program"]

DEFAULT_MAX_CYCLES = 50_000_000


class CheckResult:
    def __init__(self, machine: Machine, channel: int, mode: str) -> None:
        self.machine = machine
        self.channel = channel
        self.mode = mode
        self.completed = False
        self.blocks = 0
        self.alarms: list[Alarm] = []
        self.final_position: dict[str, float] = {}
        self.path: list[tuple[float, ...]] = []
        self.stop_point: tuple[float, ...] | None = None
        self.elapsed_s = 0.0

    @property
    def stopped_by_error(self) -> bool:
        return any(a.severity == Severity.ERROR for a in self.alarms)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "completed": self.completed,
            "mode": self.mode,
            "channel": self.channel,
            "cycles": self.machine.cycle,
            "simulated_time_s": round(self.machine.time, 6),
            "blocks": self.blocks,
            "alarms": [
                {
                    "id": a.number,
                    "severity": str(a.severity),
                    "line": a.line,
                    "block": a.block,
                    "message": a.message,
                    "params": a.params,
                    "cycle": a.cycle,
                }
                for a in self.alarms
            ],
            "final_position": self.final_position,
            "elapsed_s": round(self.elapsed_s, 3),
        }
        areas = _areas_json(self.machine, self.channel)
        if areas is not None:
            out["areas"] = areas
        return out


def _areas_json(machine: Machine, channel: int) -> list[dict[str, Any]] | None:
    """The channel's area table, when the area monitor is installed (FCT-C14)."""
    for mon in machine.monitors:
        table = getattr(mon, "areas_json", None)
        if callable(table):
            result: list[dict[str, Any]] = table(machine.channel(channel))
            return result
    return None


class _Progress:
    """Progress on stderr, only when stderr is a terminal."""

    def __init__(self, total_lines: int, enabled: bool) -> None:
        self.total = max(total_lines, 1)
        self.enabled = enabled and sys.stderr.isatty()
        self._last = 0.0

    def update(self, line: int) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < 0.2:
            return
        self._last = now
        pct = 100.0 * line / self.total
        sys.stderr.write(f"\rchecking: line {line}/{self.total} ({pct:5.1f} %)")
        sys.stderr.flush()

    def done(self) -> None:
        if self.enabled:
            sys.stderr.write("\r" + " " * 60 + "\r")
            sys.stderr.flush()


def check_program(
    machine: Machine,
    text: str,
    *,
    channel: int = 1,
    geometry_only: bool = False,
    max_cycles: int = DEFAULT_MAX_CYCLES,
    record_path: bool = False,
    progress: bool = False,
) -> CheckResult:
    """Run (or decode) ``text`` on ``machine`` and collect the result."""
    began = time.perf_counter()
    result = CheckResult(machine, channel, "geometry" if geometry_only else "full")
    ch = machine.channel(channel)
    meter = _Progress(text.count("\n") + 1, progress)
    history_start = len(machine.alarm_history)
    if record_path:
        result.path.append(tuple(ch.setpoints()))
    if geometry_only:
        _decode_only(machine, text, channel, result, meter, record_path)
    else:
        ch.load_program(text, "check")
        ch.request_start()
        step = machine.step
        running = (ProgramState.RUNNING, ProgramState.HELD)
        step(1)
        countdown = 0
        while ch.state in running and machine.cycle < max_cycles:
            step(1)
            if record_path and machine.cycle % 10 == 0:
                result.path.append(tuple(ch.setpoints()))
            countdown -= 1
            if countdown <= 0:
                countdown = 1000
                if ch.current_block is not None:
                    meter.update(ch.current_block.line)
        # let the axes come to rest after an abort
        for _ in range(100_000):
            if all(a.setpoint_step == 0.0 for a in ch.axes):
                break
            step(1)
        result.completed = ch.state == ProgramState.FINISHED
        result.blocks = ch.decoder.blocks_decoded
        result.final_position = {a.name: round(a.setpoint, 6) for a in ch.axes}
        if ch.state in running:
            result.completed = False
    meter.done()
    result.alarms = list(machine.alarm_history)[history_start:]
    if result.stopped_by_error:
        result.completed = False
        result.stop_point = tuple(
            result.final_position[n] for n in ch.axis_names if n in result.final_position
        )
    result.elapsed_s = time.perf_counter() - began
    return result


def _decode_only(
    machine: Machine, text: str, channel: int, result: CheckResult, meter: _Progress, record_path: bool
) -> None:
    ch = machine.channel(channel)
    decoder = ch.decoder
    decoder.start(iter_blocks(text, ch.axis_names), ch.setpoints())
    motions = 0
    line = 0
    while not decoder.finished:
        for item in decoder.next_items():
            if isinstance(item, Motion):
                motions += 1
                line = item.block.line
                if record_path:
                    result.path.append(item.segment.end)
            elif isinstance(item, Marker):
                if item.block is not None:
                    line = item.block.line
                if item.kind == MarkerKind.ACTION:
                    item.payload()
                elif item.kind == MarkerKind.END:
                    ch.warn_missing_program_end(item)
                    result.completed = True
                elif item.kind == MarkerKind.ERROR:
                    ch.raise_decode_error(item)
        if motions % 4096 == 0:
            meter.update(line)
    result.blocks = decoder.blocks_decoded
    result.final_position = {n: round(v, 6) for n, v in zip(ch.axis_names, decoder.position, strict=True)}


def _text_report(result: CheckResult, program: str) -> str:
    lines = []
    verdict = "OK: ran to the end" if result.completed else "STOPPED"
    lines.append(
        f"{program}: {verdict} ({result.mode} check, {result.blocks} blocks, {result.machine.cycle} cycles)"
    )
    for a in result.alarms:
        where = f"line {a.line}, {a.block}: " if a.line is not None else ""
        lines.append(f"  {a.severity} {a.number}: {where}{a.message}")
        if a.params:
            lines.append(f"      params: {json.dumps(a.params)}")
    pos = ", ".join(f"{k}={v:.4f}" for k, v in result.final_position.items())
    lines.append(f"  final position (mm): {pos}")
    areas = _areas_json(result.machine, result.channel)
    if areas:
        lines.append("  areas:")
        for area in areas:
            lines.append(f"    ID{area.get('id')} {area.get('kind')} {area.get('shape')} {area.get('state')}")
    return "\n".join(lines)


@click.command()
@click.argument("program", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--config",
    "config_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="machine file (default: the built-in demo machine)",
)
@click.option(
    "--channel", type=int, default=1, show_default=True, help="channel number to run the program in"
)
@click.option("--format", "fmt", type=click.Choice(["text", "json"]), default="text", show_default=True)
@click.option("--geometry-only", is_flag=True, help="decode and check every block's path without cycles")
@click.option("--max-cycles", type=int, default=DEFAULT_MAX_CYCLES, show_default=True)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="draw areas, path and stop point into an .svg or .png file",
)
def check(
    program: Path,
    config_path: Path | None,
    channel: int,
    fmt: str,
    geometry_only: bool,
    max_cycles: int,
    plot_path: Path | None,
) -> None:
    """Run PROGRAM on the machine and report alarms (exit 0 ok, 1 error alarm, 2 usage/config)."""
    from hli_server.configuration import ConfigError, load_machine

    try:
        text = program.read_text(encoding="utf-8", errors="strict")
    except (OSError, UnicodeDecodeError) as exc:
        click.echo(f"error: cannot read {program}: {exc}", err=True)
        sys.exit(2)
    try:
        config = load_machine(config_path)
    except ConfigError as exc:
        click.echo(f"error: configuration: {exc}", err=True)
        sys.exit(2)
    except OSError as exc:
        click.echo(f"error: cannot read configuration: {exc}", err=True)
        sys.exit(2)
    machine = Machine(config)
    try:
        machine.channel(channel)
    except KeyError:
        click.echo(f"error: no channel {channel} in the configuration", err=True)
        sys.exit(2)
    result = check_program(
        machine,
        text,
        channel=channel,
        geometry_only=geometry_only,
        max_cycles=max_cycles,
        record_path=plot_path is not None,
        progress=True,
    )
    if plot_path is not None:
        _plot(result, plot_path)
    if fmt == "json":
        click.echo(json.dumps(result.to_json(), indent=2))
    else:
        click.echo(_text_report(result, str(program)))
    sys.exit(0 if result.completed and not result.stopped_by_error else 1)


def _plot(result: CheckResult, out: Path) -> None:
    try:
        from hli_server.plot import plot_areas
    except ImportError:
        click.echo("error: plotting needs hli_server.plot (matplotlib)", err=True)
        sys.exit(2)
    ch = result.machine.channel(result.channel)
    main = ch.config.main_axes
    idx = (ch.axis_names.index(main[0]), ch.axis_names.index(main[1]))
    path = [(p[idx[0]], p[idx[1]]) for p in result.path]
    stop = (result.stop_point[idx[0]], result.stop_point[idx[1]]) if result.stop_point else None
    plot_areas(_areas_json(result.machine, result.channel) or [], path, stop, out)
