"""``hli-server check PROGRAM``: run a program offline and report what the monitors find.

Two modes:

* full (default): the program runs free in automatic mode on the machine, cycle by cycle, with every
  monitor active, from the start to M30/M02 or the end of the file;
* ``--geometry-only``: the program is decoded and every block's whole path is checked (soft limits,
  work and protection areas), without interpolating cycles - the mode for programs of millions of
  blocks. Cycle-based monitors (dynamic limits, collision, position monitoring) need cycles and are
  not evaluated in this mode.

Output: the report on stdout (text, or ``--format json``), numbers rounded to the machine's resolution
(0.1 µm) where they are shown, not in the engine's math. On stderr: a progress bar (tqdm) when stderr is
a terminal, and with ``--plot PATH`` ``plot written: PATH`` or ``error: plot not written: ...``. The
picture is the scene of :mod:`hli_server.scene` drawn by :mod:`hli_server.plot` (docs/areas.md); its
format and place are checked before the run, and it is drawn after the report is printed, so a failing
drawing never costs the report or changes the exit code.

Exit codes: 0 ran to the end without an error alarm; 1 an error alarm stopped it; 2 usage, file or
configuration errors (an unusable ``--plot`` target included).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, TextIO

import click

from hli_server.engine import Machine
from hli_server.engine.alarms import Alarm, Severity
from hli_server.engine.areas.monitor import AreaMonitor
from hli_server.engine.batch import BatchGeometryCheck, unsupported
from hli_server.engine.channel import Channel
from hli_server.engine.geometry import ArcSegment, Segment
from hli_server.engine.nc.parser import iter_blocks
from hli_server.engine.planner import Marker, MarkerKind, Motion
from hli_server.scene import build_scene, round_mm, round_numbers
from schemas.wire import ProgramState

__all__ = ["CheckResult", "check", "check_program", "scene_of"]

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
        """The JSON report; positions and the floats of alarm params rounded to 0.1 µm (1e-4 mm)."""
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
                    "params": round_numbers(a.params),
                    "cycle": a.cycle,
                }
                for a in self.alarms
            ],
            "final_position": {k: round_mm(v) for k, v in self.final_position.items()},
            "elapsed_s": round(self.elapsed_s, 3),
        }
        areas = _areas_json(self.machine, self.channel)
        if areas is not None:
            out["areas"] = round_numbers(areas)
        return out


def _areas_json(machine: Machine, channel: int) -> list[dict[str, Any]] | None:
    """The channel's area table, when the area monitor is installed (FCT-C14)."""
    if not machine.has_monitor(AreaMonitor):
        return None
    return machine.monitor(AreaMonitor).areas_json(machine.channel(channel))


class _Progress:
    """Progress of a long check on stderr, only when stderr is a terminal (tqdm): lines of the program
    done, lines/s, blocks/s and the time left (E-04: programs of millions of blocks)."""

    refresh_s = 0.2
    """Least time between two redraws (tqdm's ``mininterval``)."""

    def __init__(self, total_lines: int, enabled: bool) -> None:
        self._bar: Any = None
        if enabled and sys.stderr.isatty():
            from tqdm import tqdm

            self._bar = tqdm(
                total=max(total_lines, 1),
                desc="checking",
                unit=" lines",
                unit_scale=True,
                file=sys.stderr,
                leave=False,
                mininterval=self.refresh_s,
                dynamic_ncols=True,
                bar_format="{desc} {percentage:3.0f}%|{bar}| line {n_fmt}/{total_fmt} "
                "[{elapsed}<{remaining}, {rate_fmt}{postfix}]",
            )

    def update(self, line: int, blocks: int) -> None:
        bar = self._bar
        if bar is None or line <= bar.n:
            return
        elapsed = bar.format_dict["elapsed"]
        if elapsed > 0.0:
            bar.set_postfix_str(f"{bar.format_sizeof(blocks / elapsed)} blocks/s", refresh=False)
        bar.update(line - bar.n)

    def done(self) -> None:
        if self._bar is not None:
            self._bar.close()


def check_program(
    machine: Machine,
    text: str | TextIO,
    *,
    channel: int = 1,
    geometry_only: bool = False,
    max_cycles: int = DEFAULT_MAX_CYCLES,
    record_path: bool = False,
    progress: bool = False,
) -> CheckResult:
    """Run (or decode) ``text`` on ``machine`` and collect the result.

    ``record_path``: keep the path for the picture (``--plot``): every 10th cycle's setpoints in a full
    check, every block's end (arcs every few degrees) with ``geometry_only``.

    ``text`` may be an open text file (``newline=""``): a geometry check then streams it line by line,
    with flat memory however long the program (issue 16); a full check reads it whole."""
    began = time.perf_counter()
    result = CheckResult(machine, channel, "geometry" if geometry_only else "full")
    ch = machine.channel(channel)
    meter = _Progress(_count_lines(text) if progress else 0, progress)
    history_start = len(machine.alarm_history)
    if record_path:
        result.path.append(tuple(ch.setpoints()))
    if geometry_only:
        _decode_only(machine, text, channel, result, meter, record_path)
    else:
        ch.load_program(text if isinstance(text, str) else text.read(), "check")
        ch.request_start()
        step = machine.step
        running = (ProgramState.RUNNING, ProgramState.HELD)
        step(1)
        countdown = 0
        while ch.state in running and machine.cycle < max_cycles:
            step(1)
            if record_path and machine.cycle % 10 == 0:
                _record(result.path, tuple(ch.setpoints()))
            countdown -= 1
            if countdown <= 0:
                countdown = 1000
                if ch.current_block is not None:
                    meter.update(ch.current_block.line, ch.decoder.blocks_decoded)
        # let the axes come to rest after an abort
        for _ in range(100_000):
            if all(a.setpoint_step == 0.0 for a in ch.axes):
                break
            step(1)
        result.completed = ch.state == ProgramState.FINISHED
        result.blocks = ch.decoder.blocks_decoded
        result.final_position = {a.name: a.setpoint for a in ch.axes}
        if record_path:
            _record(result.path, tuple(ch.setpoints()))
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


def _count_lines(text: str | TextIO) -> int:
    """Lines of the program for the progress bar (only drawn on a terminal): a file is counted in a
    binary pass and rewound, so that streaming it keeps memory flat."""
    if isinstance(text, str):
        return text.count("\n") + 1
    if not sys.stderr.isatty() or not text.seekable():
        return 0
    raw = getattr(text, "buffer", None)
    if raw is None:
        return 0
    lines = 1
    while chunk := raw.read(1 << 20):
        lines += chunk.count(b"\n")
    text.seek(0)
    return lines


def _record(path: list[tuple[float, ...]], point: tuple[float, ...]) -> None:
    """Append ``point`` unless the axes stand where the last one was (dwell, waiting at a marker)."""
    if not path or path[-1] != point:
        path.append(point)


_ARC_CHORD_MM = 0.01
"""Largest sagitta of the chords an arc is recorded with in a geometry check's path (a picture's
precision), with at most :data:`_ARC_MAX_POINTS` points per arc."""
_ARC_MAX_POINTS = 90


def _segment_points(segment: Segment) -> list[tuple[float, ...]]:
    """A block's path for the picture: the end of a line; an arc (helix) every few degrees, so the
    picture does not draw its chord (the path check itself is exact, C14-15)."""
    if not isinstance(segment, ArcSegment) or segment.radius <= _ARC_CHORD_MM:
        return [segment.end]
    step = 2.0 * math.acos(1.0 - _ARC_CHORD_MM / segment.radius)
    n = min(_ARC_MAX_POINTS, max(2, math.ceil(abs(segment.sweep) / step)))
    length = segment.length
    return [segment.point_at(length * k / n) for k in range(1, n + 1)]


BATCH_ENV = "HLI_BATCH_CHECK"
"""Set to 0 to decode a geometry check block by block (the exact path) although the batch could run."""


def batch_in_use(machine: Machine, channel: int, record_path: bool) -> bool:
    """Does a geometry check of this channel run as a batch (``hli_server/engine/batch.py``)? Not with
    ``record_path`` (``--plot`` draws every block's path), not with a path check the batch does not know
    (a user's monitor), not with ``HLI_BATCH_CHECK=0``."""
    if record_path or os.environ.get(BATCH_ENV, "") == "0":
        return False
    return unsupported(machine.channel(channel)) is None


def _decode_only(
    machine: Machine,
    text: str | TextIO,
    channel: int,
    result: CheckResult,
    meter: _Progress,
    record_path: bool,
) -> None:
    ch = machine.channel(channel)
    decoder = ch.decoder
    if batch_in_use(machine, channel, record_path):
        batch = BatchGeometryCheck(ch)
        for items in batch.items(text):
            for item in items:
                if isinstance(item, Marker):
                    _handle_marker(ch, item, result)
            meter.update(batch.line, decoder.blocks_decoded)
    else:
        decoder.start(iter_blocks(text, ch.axis_names), ch.setpoints())
        motions = 0
        next_update = 4096
        line = 0
        while not decoder.finished:
            for item in decoder.next_items():
                if isinstance(item, Motion):
                    motions += 1
                    line = item.block.line
                    if record_path:
                        result.path.extend(_segment_points(item.segment))
                elif isinstance(item, Marker):
                    if item.block is not None:
                        line = item.block.line
                    _handle_marker(ch, item, result)
            if motions >= next_update:  # the decoder hands out items in batches: a threshold, not a modulo
                next_update = motions + 4096
                meter.update(line, decoder.blocks_decoded)
    result.blocks = decoder.blocks_decoded
    result.final_position = dict(zip(ch.axis_names, decoder.position, strict=True))


def _handle_marker(ch: Channel, item: Marker, result: CheckResult) -> None:
    if item.kind == MarkerKind.ACTION:
        item.payload()
    elif item.kind == MarkerKind.END:
        ch.warn_missing_program_end(item)
        result.completed = True
    elif item.kind == MarkerKind.ERROR:
        ch.raise_decode_error(item)


def _text_report(result: CheckResult, program: str) -> str:
    """The report for people: positions and the floats of alarm params rounded to 0.1 µm."""
    lines = []
    verdict = "OK: ran to the end" if result.completed else "STOPPED"
    lines.append(
        f"{program}: {verdict} ({result.mode} check, {result.blocks} blocks, {result.machine.cycle} cycles)"
    )
    for a in result.alarms:
        where = f"{a.place}: " if a.place else ""
        lines.append(f"  {a.severity} {a.number}: {where}{a.message}")
        if a.params:
            lines.append(f"      params: {json.dumps(round_numbers(a.params))}")
    pos = ", ".join(f"{k}={round_mm(v):.4f}" for k, v in result.final_position.items())
    lines.append(f"  final position (mm): {pos}")
    areas = _areas_json(result.machine, result.channel)
    if areas:
        lines.append("  areas:")
        for area in areas:
            band = f"{area.get('height_axis')} {round_mm(area['min']):g}..{round_mm(area['max']):g}"
            lines.append(
                f"    ID{area.get('id')} {area.get('kind')} {area.get('shape')} {area.get('state')}, "
                f"{'/'.join(area.get('axes', []))} plane, height {band}"
            )
    return "\n".join(lines)


def scene_of(result: CheckResult) -> dict[str, Any]:
    """The scene (:mod:`hli_server.scene`) of a check run with ``record_path``: what ``--plot`` draws
    and what the dashboard draws for the same channel."""
    ch = result.machine.channel(result.channel)
    return build_scene(
        _areas_json(result.machine, result.channel) or [],
        result.path,
        axis_names=ch.axis_names,
        main_axes=ch.config.main_axes,
        alarms=[a.to_json() for a in result.alarms],
        stop=result.stop_point,
        channel=result.channel,
    )


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
    help="draw the areas, the path with its height (top and side view), the refused block, the violation "
    "and the stop point into this file; its suffix chooses the format (.pdf, .svg, .png, ...: any "
    "matplotlib writes)",
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
    """Run PROGRAM on the machine and report alarms (exit 0 ok, 1 error alarm, 2 usage/config).

    The report goes to stdout (text or JSON); progress, ``plot written: PATH`` and errors to stderr."""
    from hli_server.configuration import ConfigError, load_machine

    if plot_path is not None:
        _check_plot_target(plot_path)
    try:
        # a geometry check streams the file (flat memory for programs of millions of blocks); the
        # full check reads it whole
        text: str | TextIO = (
            program.open(encoding="utf-8", errors="strict", newline="")
            if geometry_only
            else program.read_text(encoding="utf-8", errors="strict")
        )
    except (OSError, UnicodeDecodeError) as exc:
        click.echo(f"error: cannot read {program}: {exc}", err=True)
        sys.exit(2)
    try:
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
        try:
            result = check_program(
                machine,
                text,
                channel=channel,
                geometry_only=geometry_only,
                max_cycles=max_cycles,
                record_path=plot_path is not None,
                progress=True,
            )
        except (OSError, UnicodeDecodeError) as exc:
            click.echo(f"error: cannot read {program}: {exc}", err=True)
            sys.exit(2)
    finally:
        if not isinstance(text, str):
            text.close()
    # the report first: whatever the drawing does, the user has the verdict
    if fmt == "json":
        click.echo(json.dumps(result.to_json(), indent=2))
    else:
        click.echo(_text_report(result, str(program)))
    if plot_path is not None:
        _plot(result, plot_path, str(program))
    sys.exit(0 if result.completed and not result.stopped_by_error else 1)


def _check_plot_target(plot_path: Path) -> None:
    """Before the run: a format matplotlib cannot write here, or a place that is not writable, is a
    usage error (exit 2), not a traceback after a long check."""
    try:
        from hli_server.plot import PlotTargetError, check_plot_target
    except ImportError as exc:
        click.echo(
            f"error: --plot needs matplotlib ({exc}); install hli-server with its dependencies", err=True
        )
        sys.exit(2)
    try:
        check_plot_target(plot_path)
    except PlotTargetError as exc:
        raise click.BadParameter(str(exc), param_hint="'--plot'") from exc


def _plot(result: CheckResult, out: Path, program: str) -> None:
    """Draw after the report; a failure is said on stderr and leaves the check's exit code alone."""
    from hli_server.plot import plot_scene

    try:
        written = plot_scene(scene_of(result), out, title=None)
    except Exception as exc:  # the report is out; any drawing failure is only reported
        click.echo(f"error: plot not written: {out}: {type(exc).__name__}: {exc}", err=True)
        return
    click.echo(f"plot written: {written}", err=True)
