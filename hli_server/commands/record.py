"""``hli-server record show|export`` and ``hli-server replay`` (docs/record-replay.md).

    hli-server record show FILE [--format text|json] [--limit N]
    hli-server record export FILE (--csv OUT | --vcd OUT | --plot OUT.png|.pdf) [--signals PATTERN ...]
    hli-server replay FILE [--config MACHINE] [--until CYCLE|SECONDS s] [--signals PATTERN ...]
                           [--all] [--no-events] [--report OUT.json] [--same-version] [--from-journal]

Exit codes of ``replay``: 0 pass, 1 the outputs differ, 3 cannot replay (the reason is printed: a
version or configuration mismatch, a file that is no recording, ...), 2 usage. ``record``: 0, or 2 when
the file cannot be read.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from hli_server.recording.format import RecordingError

__all__ = ["record", "replay_command"]

_EXIT_USAGE = 2


@click.group()
def record() -> None:
    """Look into a recording (hli-server run --record FILE, POST /api/recording/start)."""


@record.command("show")
@click.argument("file", type=click.Path(path_type=Path, dir_okay=False, exists=True))
@click.option("--format", "fmt", type=click.Choice(["text", "json"]), default="text", show_default=True)
@click.option("--limit", type=click.IntRange(1, 100_000), default=30, show_default=True, help="rows per list")
def show(file: Path, fmt: str, limit: int) -> None:
    """What is in FILE: duration, the signals that changed, alarms, programs, operator requests."""
    from hli_server.recording.inspect import summarize

    try:
        summary = summarize(file)
    except RecordingError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(_EXIT_USAGE)
    if fmt == "json":
        click.echo(json.dumps(summary.to_json(), indent=1))
    else:
        click.echo(summary.text(limit=limit))


@record.command("export")
@click.argument("file", type=click.Path(path_type=Path, dir_okay=False, exists=True))
@click.option(
    "--csv", "csv_out", type=click.Path(path_type=Path, dir_okay=False), help="CSV file ('-': stdout)"
)
@click.option(
    "--vcd", "vcd_out", type=click.Path(path_type=Path, dir_okay=False), help="VCD file for GTKWave"
)
@click.option("--plot", "plot_out", type=click.Path(path_type=Path, dir_okay=False), help="PNG, PDF or SVG")
@click.option(
    "--signals",
    "-s",
    multiple=True,
    metavar="PATTERN",
    help="ST paths, * and ? as wildcards (gpAx[0]^*); repeatable; default: every signal (CSV, VCD)",
)
@click.option(
    "--every-cycle", is_flag=True, help="CSV: a row for every cycle (default: cycles with a change)"
)
def export(
    file: Path,
    csv_out: Path | None,
    vcd_out: Path | None,
    plot_out: Path | None,
    signals: tuple[str, ...],
    every_cycle: bool,
) -> None:
    """FILE's signals as CSV, as a VCD that GTKWave opens, or as a plot."""
    from hli_server.recording import inspect

    if not (csv_out or vcd_out or plot_out):
        raise click.UsageError("give --csv, --vcd or --plot (or several)")
    try:
        if csv_out is not None:
            if str(csv_out) == "-":
                rows = inspect.write_csv(file, sys.stdout, signals, every_cycle=every_cycle)
            else:
                with open(csv_out, "w", encoding="utf-8", newline="") as out:
                    rows = inspect.write_csv(file, out, signals, every_cycle=every_cycle)
                click.echo(f"{csv_out}: {rows:,} rows", err=True)
        if vcd_out is not None:
            with open(vcd_out, "w", encoding="ascii") as out:
                changes = inspect.write_vcd(file, out, signals)
            click.echo(f"{vcd_out}: {changes:,} value changes (open it with gtkwave)", err=True)
        if plot_out is not None:
            panels = inspect.write_plot(file, plot_out, signals)
            click.echo(f"{plot_out}: {panels} signals", err=True)
    except RecordingError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(_EXIT_USAGE)


def _until(value: str | None, t_a_us: int) -> int | None:
    if value is None:
        return None
    text = value.strip().lower()
    try:
        if text.endswith("s"):
            return round(float(text[:-1]) * 1e6 / t_a_us)
        return int(text.replace("_", "").replace(",", ""))
    except ValueError:
        raise click.BadParameter(
            f"{value!r}: a cycle (12000) or a time (12.5s)", param_hint="--until"
        ) from None


@click.command("replay")
@click.argument("file", type=click.Path(path_type=Path, dir_okay=False, exists=True))
@click.option(
    "--config",
    "config_path",
    type=click.Path(path_type=Path, dir_okay=False, exists=True),
    help="the machine file to replay on; it must equal the recorded configuration (default: the recorded)",
)
@click.option("--until", metavar="CYCLE|SECONDSs", help="stop after this cycle (or machine time: 12.5s)")
@click.option(
    "--signals",
    "-s",
    multiple=True,
    metavar="PATTERN",
    help="compare only these outputs (ST paths, * and ? as wildcards)",
)
@click.option("--all", "all_differences", is_flag=True, help="go on after the first difference; report all")
@click.option("--max-differences", type=click.IntRange(1, 1_000_000), default=1000, show_default=True)
@click.option("--events/--no-events", default=True, show_default=True, help="compare the events (alarms ...)")
@click.option(
    "--report", "report_out", type=click.Path(path_type=Path, dir_okay=False), help="the report as JSON"
)
@click.option(
    "--same-version", is_flag=True, help="cannot replay when the recording was made by another version"
)
@click.option(
    "--from-journal",
    is_flag=True,
    help="start from the input journal (the server's first cycle) although the recording holds a snapshot",
)
@click.option(
    "--limit", type=click.IntRange(1, 100_000), default=20, show_default=True, help="signals listed"
)
def replay_command(
    file: Path,
    config_path: Path | None,
    until: str | None,
    signals: tuple[str, ...],
    all_differences: bool,
    max_differences: int,
    events: bool,
    report_out: Path | None,
    same_version: bool,
    from_journal: bool,
    limit: int,
) -> None:
    """Replay FILE on the recorded machine, cycle by cycle, and compare every recorded output.

    Exit status: 0 pass, 1 differ (the first difference: cycle, signal, expected, actual), 3 cannot replay.
    """
    from hli_server.configuration import ConfigError, ConfigFileError, load_machine
    from hli_server.recording.format import read_header
    from hli_server.replay import EXIT_STATUS, Verdict, replay_sync

    config = None
    if config_path is not None:
        try:
            config = load_machine(config_path)
        except (ConfigFileError, ConfigError) as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(_EXIT_USAGE)
    try:
        t_a_us = int(read_header(file).get("t_a_us", 1000))
    except RecordingError as exc:
        click.echo(f"replay of {file}: CANNOT REPLAY: {exc}", err=True)
        sys.exit(EXIT_STATUS[Verdict.CANNOT])
    report = replay_sync(
        file,
        config=config,
        until=_until(until, t_a_us),
        signals=signals,
        events=events,
        all_differences=all_differences,
        max_differences=max_differences,
        same_version=same_version,
        from_journal=from_journal,
    )
    click.echo(report.text(limit=limit), err=report.verdict is Verdict.CANNOT)
    if report_out is not None:
        report_out.write_text(json.dumps(report.to_json(), indent=1), encoding="utf-8")
    sys.exit(report.exit_status)
