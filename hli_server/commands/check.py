"""``hli-server check PROGRAM``: run a program offline and report what the monitors find.

The check itself is the engine's (:class:`hli_server.engine.program_check.ProgramCheck`); this command
reads the program and the machine file, draws the progress bar and the picture, and prints the report.

Two modes:

* full (default): the program runs free in automatic mode on the machine, cycle by cycle, with every
  monitor active, from the start to M30/M02 or the end of the file;
* ``--geometry-only``: the program is interpreted and every block's whole path is checked (soft limits,
  work and protection areas), without interpolating cycles - the mode for programs of millions of
  blocks. Cycle-based monitors (dynamic limits, collision, position monitoring) need cycles and are
  not evaluated in this mode.

Subroutines and cycles (``L name``, ``L CYCLE [NAME=..]``) are found in the program's own directory, then
in each ``--program-dir`` in the order given.

Output: the report on stdout (text, or ``--format json``), numbers rounded to the machine's resolution
(0.1 µm) where they are shown, not in the engine's math; the program's ``#MSG`` messages with it. On
stderr: a progress bar (tqdm) when stderr is a terminal, and with ``--plot PATH`` ``plot written: PATH``
or ``error: plot not written: ...``. The picture is the scene of :mod:`hli_server.scene` drawn by
:mod:`hli_server.plot` (docs/areas.md); its format and place are checked before the run, and it is drawn
after the report is printed, so a failing drawing never costs the report or changes the exit code.

Exit codes: 0 ran to the end without an error alarm; 1 an error alarm stopped it; 2 usage, file or
configuration errors (an unusable ``--plot`` target included); 3 the program did not end: the check
stopped at its cap (``--max-cycles``, or ``--max-iterations`` in a geometry check) and says so.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TextIO

import click

from hli_server.codecs.presets import PresetSyntaxError, parse_preset, parse_preset_file
from hli_server.engine import Machine
from hli_server.engine.presets import PresetError, PresetValue
from hli_server.engine.program_check import (
    DEFAULT_MAX_CYCLES,
    DEFAULT_MAX_ITERATIONS,
    CheckResult,
    ProgramCheck,
)
from hli_server.scene import build_scene, round_mm, round_numbers

__all__ = ["EXIT_CAPPED", "CheckResult", "check", "check_program", "scene_of"]

EXIT_CAPPED = 3
"""Exit code of a check that stopped at its cap: the program did not end."""


class _Progress:
    """Progress of a long check on stderr, only when stderr is a terminal (tqdm): lines of the program
    done, lines/s, blocks/s and the time left (E-04: programs of millions of blocks); in a full check
    also the cycles run and the machine time they are, so that the bar moves while a loop turns on one
    line (N-13)."""

    refresh_s = 0.2
    """Least time between two redraws (tqdm's ``mininterval``)."""

    def __init__(self, total_lines: int, enabled: bool, cycle_s: float = 0.001) -> None:
        self.cycle_s = cycle_s
        self._drawn = 0.0
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

    def update(self, line: int, blocks: int, cycles: int = 0) -> None:
        bar = self._bar
        if bar is None:
            return
        elapsed = bar.format_dict["elapsed"]
        postfix = f"{bar.format_sizeof(blocks / elapsed)} blocks/s" if elapsed > 0.0 else ""
        if cycles:
            postfix += f", cycle {bar.format_sizeof(cycles)} ({cycles * self.cycle_s:.0f} s machine time)"
        bar.set_postfix_str(postfix, refresh=False)
        if line > bar.n:
            bar.update(line - bar.n)
        elif time.monotonic() - self._drawn >= self.refresh_s:
            bar.refresh()  # a loop on one line: the cycles still move
        else:
            return
        self._drawn = time.monotonic()

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
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    record_path: bool = False,
    progress: bool = False,
    name: str = "check",
    presets: Mapping[str, PresetValue] | None = None,
) -> CheckResult:
    """Run (or interpret and path-check) ``text`` on ``machine`` with the engine's
    :class:`~hli_server.engine.program_check.ProgramCheck`; ``progress`` draws a bar on a terminal.

    ``record_path``: keep the path for the picture (``--plot``). ``text`` may be an open text file
    (``newline=""``): a geometry check then streams it with flat memory (docs/performance.md).
    ``presets``: ``V.E.`` values before the start (:class:`~hli_server.engine.presets.PresetError`)."""
    meter = _Progress(_count_lines(text) if progress else 0, progress, machine.channel(channel).t_a)
    try:
        return ProgramCheck(
            machine,
            channel,
            geometry_only=geometry_only,
            max_cycles=max_cycles,
            max_iterations=max_iterations,
            record_path=record_path,
            batch=os.environ.get(BATCH_ENV, "") != "0",
            progress=meter.update,
            name=name,
            presets=presets,
        ).run(text)
    finally:
        meter.done()


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


BATCH_ENV = "HLI_BATCH_CHECK"
"""Set to 0 to decode a geometry check block by block (the exact path) although the batch could run."""


def batch_in_use(machine: Machine, channel: int, record_path: bool) -> bool:
    """Does a geometry check of this channel run as a batch (``hli_server/engine/batch.py``)? Not with
    ``record_path`` (``--plot`` draws every block's path), not with a path check the batch does not know
    (a user's monitor), not with ``HLI_BATCH_CHECK=0``."""
    return ProgramCheck(
        machine,
        channel,
        geometry_only=True,
        record_path=record_path,
        batch=os.environ.get(BATCH_ENV, "") != "0",
    ).batch_in_use()


def _text_report(result: CheckResult, program: str) -> str:
    """The report for people: positions and the floats of alarm params rounded to 0.1 µm."""
    lines = []
    if result.capped == "waiting":
        verdict = f"DID NOT END: stopped at cycle {result.cap}: its loop turns with nothing changing"
    elif result.capped is not None:
        verdict = f"DID NOT END: stopped at the cap of {result.cap} {result.capped}"
    else:
        verdict = "OK: ran to the end" if result.completed else "STOPPED"
    lines.append(
        f"{program}: {verdict} ({result.mode} check, {result.blocks} blocks, {result.machine.cycle} cycles)"
    )
    for m in result.messages:
        where = f"line {m.line}" + (f", {m.block}" if m.block and m.block != f"line {m.line}" else "")
        if m.program:
            where = f"{m.program}, {where}"
        lines.append(f"  message ({where}): {m.text}")
    for a in result.alarms:
        where = f"{a.place}: " if a.place else ""
        lines.append(f"  {a.severity} {a.number}: {where}{a.message}")
        if a.params:
            lines.append(f"      params: {json.dumps(round_numbers(a.params))}")
    pos = ", ".join(f"{k}={round_mm(v):.4f}" for k, v in result.final_position.items())
    lines.append(f"  final position (mm): {pos}")
    if result.kinematics.used:
        # K-06/K-08: what the axes and the tool tip did while a kinematic transformation was on
        kin = result.to_json()["kinematics"]
        used = ", ".join(f"ID {k['id']} ({k['name']})" for k in kin["used"])
        lines.append(f"  kinematic transformation: {used}")
        ranges = ", ".join(f"{n} {lo:g}..{hi:g}" for n, (lo, hi) in kin["axis_range"].items() if lo != hi)
        lines.append(f"    axes while it was on (mm, °): {ranges or 'at rest'}")
        tip = ", ".join(f"{n} {lo:g}..{hi:g}" for n, (lo, hi) in kin["tool_tip_range"].items())
        lines.append(f"    tool tip (TCP, mm): {tip}")
        if kin["final_tool_tip"] is not None:
            end = ", ".join(f"{n}={v:.4f}" for n, v in kin["final_tool_tip"].items())
            lines.append(f"    tool tip at the end of it (mm): {end}")
    areas = result.areas_json()
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
        result.areas_json() or [],
        result.path,
        axis_names=ch.axis_names,
        main_axes=ch.config.main_axes,
        alarms=[a.to_json() for a in result.alarms],
        stop=result.stop_point,
        channel=result.channel,
        tool_path=result.kinematics.tool_path,
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
@click.option(
    "--max-cycles",
    type=click.IntRange(min=1),
    default=DEFAULT_MAX_CYCLES,
    show_default=True,
    help="a full check stops here (exit 3) if the program has not ended",
)
@click.option(
    "--max-iterations",
    type=click.IntRange(min=1),
    default=DEFAULT_MAX_ITERATIONS,
    show_default=True,
    help="a geometry check stops after this many loop iterations and jumps back (exit 3)",
)
@click.option(
    "--program-dir",
    "program_dirs",
    type=click.Path(file_okay=False, exists=True, path_type=Path),
    multiple=True,
    help="a directory of subroutines and cycles (L name, L CYCLE); several may be given, searched in order "
    "after the program's own directory",
)
@click.option(
    "--set",
    "sets",
    metavar="V.E.NAME=VALUE",
    multiple=True,
    help="a V.E. variable's value before the start, as the PLC would give it (no PLC is attached to a "
    'check): a number, TRUE/FALSE or "text"; may be given several times',
)
@click.option(
    "--set-file",
    "set_file",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None,
    help="a file of V.E. values, one V.E.NAME = VALUE per line (# or ; begins a comment); --set wins",
)
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
    max_iterations: int,
    program_dirs: tuple[Path, ...],
    sets: tuple[str, ...],
    set_file: Path | None,
    plot_path: Path | None,
) -> None:
    """Run PROGRAM on the machine and report alarms (exit 0 ok, 1 error alarm, 2 usage/config, 3 the
    program did not end within the cap).

    The report goes to stdout (text or JSON); progress, ``plot written: PATH`` and errors to stderr."""
    from hli_server.configuration import ConfigError, load_machine
    from hli_server.runtime.programs import (
        ProgramDirectories,
        cycle_libraries,
        open_program,
        read_program_file,
    )

    if plot_path is not None:
        _check_plot_target(plot_path)
    presets = _presets(sets, set_file)
    try:
        # a geometry check streams the file (flat memory for programs of millions of blocks); the
        # full check reads it whole; UTF-8 or Windows-1252 alike, the name without regard to case
        text: str | TextIO = open_program(program) if geometry_only else read_program_file(program)
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
        library = ProgramDirectories([program.parent, *program_dirs])
        machine = Machine(config, programs=library, cycle_programs=cycle_libraries(config))
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
                max_iterations=max_iterations,
                record_path=plot_path is not None,
                progress=True,
                name=program.name,
                presets=presets,
            )
        except (OSError, UnicodeDecodeError) as exc:
            click.echo(f"error: cannot read {program}: {exc}", err=True)
            sys.exit(2)
        except PresetError as exc:
            click.echo(f"error: preset: {exc}", err=True)
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
    if result.stopped_by_error:
        sys.exit(1)
    if result.capped == "waiting":
        click.echo(
            f"error: {program} did not end: its loop turns with nothing changing; warning 914052 names it "
            "and the V.E. variables it waits on (--set V.E.NAME=VALUE gives them)",
            err=True,
        )
        sys.exit(EXIT_CAPPED)
    if result.capped is not None:
        click.echo(
            f"error: {program} did not end: the check stopped at its cap of {result.cap} {result.capped} "
            f"(--max-{'cycles' if result.capped == 'cycles' else 'iterations'})",
            err=True,
        )
        sys.exit(EXIT_CAPPED)
    sys.exit(0 if result.completed else 1)


def _presets(sets: tuple[str, ...], set_file: Path | None) -> dict[str, PresetValue]:
    """``--set-file`` then each ``--set`` (a later one wins); a malformed one is a usage error (exit 2)."""
    presets: dict[str, PresetValue] = {}
    try:
        if set_file is not None:
            from hli_server.runtime.programs import read_program_file

            presets.update(parse_preset_file(read_program_file(set_file), str(set_file)))
        for text in sets:
            name, value = parse_preset(text)
            presets[name] = value
    except PresetSyntaxError as exc:
        raise click.BadParameter(str(exc), param_hint="'--set'") from None
    except OSError as exc:
        raise click.BadParameter(f"cannot read {set_file}: {exc}", param_hint="'--set-file'") from None
    return presets


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
