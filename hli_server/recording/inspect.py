"""What is in a recording, for people: ``record show``, CSV, VCD (GTKWave) and a plot (docs/record-replay.md,
B-02).

Everything here streams the file once (:func:`~hli_server.recording.format.read_records`), so an hour of
recording is read in bounded memory except for what is asked for: the summary keeps counts, the
exports keep only the chosen signals' changes.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Final

from hli_server.recording.format import RecordingError, Records, decode_value, read_records, signal_pattern

__all__ = ["Change", "Summary", "signal_changes", "summarize", "write_csv", "write_plot", "write_vcd"]

MAX_LISTED: Final = 200
"""Operator requests, alarms, faults and programs listed in a summary (all are counted)."""


@dataclass(slots=True)
class Summary:
    """The contents of a recording (``hli-server record show``)."""

    path: str
    header: dict[str, Any]
    first_cycle: int | None = None
    last_cycle: int = 0
    end: str | None = None
    truncated: str | None = None
    compressed_bytes: int = 0
    lines: int = 0
    inputs: dict[str, list[int]] = field(default_factory=dict)
    """ST path -> [changes, first cycle, last cycle] (after the first, full, line)."""
    outputs: dict[str, list[int]] = field(default_factory=dict)
    events: dict[str, int] = field(default_factory=dict)
    alarms: list[dict[str, Any]] = field(default_factory=list)
    alarm_count: int = 0
    operator: list[dict[str, Any]] = field(default_factory=list)
    operator_count: int = 0
    programs: list[dict[str, Any]] = field(default_factory=list)
    faults: list[dict[str, Any]] = field(default_factory=list)

    @property
    def t_a_us(self) -> int:
        return int(self.header.get("t_a_us", 1000))

    @property
    def window_start(self) -> int:
        return int(self.header.get("window_start", 1))

    def start_text(self) -> str:
        """Where a replay starts: the snapshot, or the journal (and why), or nowhere."""
        h = self.header
        snapshot = h.get("snapshot")
        journal_complete = (h.get("journal") or {}).get("complete", True)
        if isinstance(snapshot, dict):
            return (
                f"the snapshot of cycle {snapshot.get('cycle', 0):,} (a replay runs the recording's cycles "
                "only; an engine of other sources replays the input journal"
                + (")" if journal_complete else ", which was dropped: not replayable there)")
            )
        if self.window_start <= 1:
            return "cycle 1"
        why = f" ({h['snapshot_note']})" if h.get("snapshot_note") else ""
        if not journal_complete:
            return f"nowhere: no snapshot{why} and the input journal was dropped (not replayable)"
        return f"the input journal, cycle 1 (no snapshot{why})"

    def duration_s(self) -> float:
        return max(0, self.last_cycle - self.window_start + 1) * self.t_a_us / 1e6

    def to_json(self) -> dict[str, Any]:
        header = {k: v for k, v in self.header.items() if k not in ("config", "inputs", "outputs")}
        return {
            "path": self.path,
            "header": header,
            "first_cycle": self.first_cycle,
            "last_cycle": self.last_cycle,
            "window_start": self.window_start,
            "duration_s": self.duration_s(),
            "end": self.end,
            "truncated": self.truncated,
            "bytes": self.compressed_bytes,
            "lines": self.lines,
            "inputs_changed": _counts(self.inputs),
            "outputs_changed": _counts(self.outputs),
            "events": self.events,
            "alarms": self.alarms,
            "alarm_count": self.alarm_count,
            "operator": self.operator,
            "operator_count": self.operator_count,
            "programs": self.programs,
            "faults": self.faults,
        }

    def text(self, *, limit: int = 30) -> str:
        h = self.header
        server = h.get("server") or {}
        t = self.t_a_us / 1e6
        lines = [
            f"{self.path}: recording of machine {h.get('machine')!r} by hli-server {server.get('version')} "
            f"({server.get('engine')} engine), {h.get('created')}, {h.get('origin', '?')}",
            f"  T_A {self.t_a_us} µs; outputs from cycle {self.window_start:,} to {self.last_cycle:,}: "
            f"{self.duration_s():.3f} s of machine time; inputs from cycle 1"
            + ("" if (h.get("journal") or {}).get("complete", True) else " (INCOMPLETE)"),
            f"  starts from: {self.start_text()}",
            f"  {self.compressed_bytes:,} bytes, {self.lines:,} lines; "
            + (
                f"ended: {self.end}"
                if self.end
                else f"NO END LINE: {self.truncated or 'the writer did not close it'}"
            ),
        ]
        lines.append(f"  inputs that changed ({len(self.inputs)}):")
        lines.extend(_listing(self.inputs, limit, t))
        lines.append(f"  outputs that changed ({len(self.outputs)}):")
        lines.extend(_listing(self.outputs, limit, t))
        if self.events:
            lines.append("  events: " + ", ".join(f"{k} {v}" for k, v in sorted(self.events.items())))
        lines.append(f"  alarms ({self.alarm_count}):")
        lines.extend(
            f"    cycle {a['cycle']:,}: {a['id']} {a.get('severity', '')}: {a.get('message', '')}"
            for a in self.alarms[:limit]
        )
        lines.append(f"  programs ({len(self.programs)}):")
        lines.extend(
            f"    cycle {p['cycle']:,}: {p['what']} {p['name']} ({p['lines']} lines)"
            for p in self.programs[:limit]
        )
        lines.append(f"  operator requests ({self.operator_count}):")
        lines.extend(
            f"    cycle {o['cycle']:,}: {o['op']} {o['args']}"
            + (f" -> {o['error']}" if o.get("error") else "")
            for o in self.operator[:limit]
        )
        if self.faults:
            lines.append(f"  communication faults ({len(self.faults)} changes):")
            lines.extend(f"    cycle {f['cycle']:,}: {f['what']}" for f in self.faults[:limit])
        return "\n".join(lines)


def _counts(table: dict[str, list[int]]) -> dict[str, dict[str, int]]:
    return {k: {"changes": v[0], "first": v[1], "last": v[2]} for k, v in sorted(table.items())}


def _listing(table: dict[str, list[int]], limit: int, t: float) -> list[str]:
    rows = sorted(table.items(), key=lambda kv: (-kv[1][0], kv[0]))
    out = [
        f"    {path}: {n:,} changes, {first * t:.3f}..{last * t:.3f} s"
        for path, (n, first, last) in rows[:limit]
    ]
    if len(rows) > limit:
        out.append(f"    ... and {len(rows) - limit} more")
    return out


def _bump(table: dict[str, list[int]], path: str, cycle: int) -> None:
    entry = table.get(path)
    if entry is None:
        table[path] = [1, cycle, cycle]
    else:
        entry[0] += 1
        entry[2] = cycle


def summarize(path: Path | str) -> Summary:
    """Read the whole recording once and count what is in it."""
    info = Records()
    records = read_records(path, info)
    header = next(records)
    summary = Summary(path=str(path), header=header)
    inputs = [entry[0] for entry in header.get("inputs", [])]
    outputs = [entry[0] for entry in header.get("outputs", [])]
    seen_in = seen_out = False
    for record in records:
        cycle = record.get("c", 0)
        if summary.first_cycle is None:
            summary.first_cycle = cycle
        summary.last_cycle = max(summary.last_cycle, cycle)
        if "i" in record:
            if seen_in:
                for k in record["i"][0::2]:
                    _bump(summary.inputs, inputs[k], cycle)
            seen_in = True
        if "o" in record:
            if seen_out:
                for k in record["o"][0::2]:
                    _bump(summary.outputs, outputs[k], cycle)
            seen_out = True
        for event in record.get("e", ()):
            kind = str(event.get("kind"))
            summary.events[kind] = summary.events.get(kind, 0) + 1
            alarm = (event.get("data") or {}).get("alarm")
            if kind == "alarm" and isinstance(alarm, dict):
                summary.alarm_count += 1
                if len(summary.alarms) < MAX_LISTED:
                    summary.alarms.append(
                        {
                            "cycle": cycle,
                            "id": alarm.get("id"),
                            "severity": alarm.get("severity"),
                            "message": alarm.get("message"),
                            "channel": alarm.get("channel"),
                        }
                    )
        if "op" in record:
            summary.operator_count += 1
            args = {k: v for k, v in (record.get("args") or {}).items() if k != "text"}
            if len(summary.operator) < MAX_LISTED:
                summary.operator.append(
                    {"cycle": cycle, "op": record["op"], "args": args, "error": record.get("error")}
                )
            if record["op"] == "load_program" and len(summary.programs) < MAX_LISTED:
                text = str((record.get("args") or {}).get("text", ""))
                summary.programs.append(
                    {"cycle": cycle, "what": "loaded", "name": args.get("name"), "lines": text.count("\n")}
                )
        if "file" in record and len(summary.programs) < MAX_LISTED:
            text = str(record.get("text", ""))
            summary.programs.append(
                {"cycle": cycle, "what": "read file", "name": record["file"], "lines": text.count("\n")}
            )
        if "program_file" in record and len(summary.programs) < MAX_LISTED:
            found = record.get("found")
            summary.programs.append(
                {
                    "cycle": cycle,
                    "what": "subprogram" if found is not None else "subprogram NOT FOUND",
                    "name": f"{record['program_file']} ({record.get('origin', ', '.join(record.get('searched') or []))})",  # noqa: E501
                    "lines": str(record.get("text", "")).count("\n"),
                }
            )
        if "fault" in record:
            what = (
                f"set {record.get('id')}: {record.get('spec')}"
                if record["fault"] == "set"
                else f"ended {record.get('id')} ({record.get('reason')})"
            )
            summary.faults.append({"cycle": cycle, "what": what})
        if "end" in record:
            summary.end = str(record["end"])
    summary.truncated = info.truncated
    summary.compressed_bytes = Path(path).stat().st_size
    summary.lines = info.lines
    return summary


# --------------------------------------------------------------------------------------------
# signals over time
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Change:
    cycle: int
    values: dict[str, Any]
    """The chosen signals that changed in this cycle (the first change holds them all)."""


def select_signals(header: dict[str, Any], patterns: Sequence[str]) -> list[tuple[str, str, str]]:
    """``(half, path, type)`` of the signals matching ``patterns`` (``*``, ``?``; none: every signal)."""
    out = []
    matches = signal_pattern(patterns)
    for half, key in (("in", "inputs"), ("out", "outputs")):
        for path, kind in header.get(key, []):
            if matches(path):
                out.append((half, path, kind))
    if patterns and not out:
        raise RecordingError(f"no recorded signal matches {', '.join(patterns)}")
    return out


def signal_changes(
    path: Path | str, patterns: Sequence[str] = ()
) -> tuple[dict[str, Any], list[tuple[str, str, str]], Iterator[Change]]:
    """The header, the chosen signals and, lazily, every cycle in which one of them changed."""
    records = read_records(path)
    header = next(records)
    chosen = select_signals(header, patterns)
    wanted_in = {path: k for k, (half, path, _) in enumerate(chosen) if half == "in"}
    wanted_out = {path: k for k, (half, path, _) in enumerate(chosen) if half == "out"}
    in_index = {k: p for k, (p, _) in enumerate(header.get("inputs", [])) if p in wanted_in}
    out_index = {k: p for k, (p, _) in enumerate(header.get("outputs", [])) if p in wanted_out}
    follow = [out_index[k] for k in header.get("follow_cycle") or [] if k in out_index]
    window = int(header.get("window_start", 1))

    def changes() -> Iterator[Change]:
        current: dict[str, Any] = {}
        for record in records:
            values: dict[str, Any] = {}
            cycle = int(record.get("c", 0))
            if follow and cycle > window and ("o" in record or "i" in record):
                for name in follow:  # these count the cycles (format.py): listed only when they do not
                    own = cycle % 2**31
                    if current.get(name) != own:
                        current[name] = own
                        values[name] = own
            for key, index in (("i", in_index), ("o", out_index)):
                flat = record.get(key)
                if not flat:
                    continue
                for k in range(0, len(flat) - 1, 2):
                    name = index.get(flat[k])
                    if name is None:
                        continue
                    value = decode_value(flat[k + 1])
                    if current.get(name, _MISSING) != value:
                        current[name] = value
                        values[name] = value
            if values:
                yield Change(int(record["c"]), values)

    return header, chosen, changes()


_MISSING: Final = object()


def write_csv(
    path: Path | str, out: IO[str], patterns: Sequence[str] = (), *, every_cycle: bool = False
) -> int:
    """The chosen signals as CSV: ``cycle, time_s, <signal>...``, a row per cycle in which one changed
    (``every_cycle``: every cycle, values carried forward); returns the rows written."""
    header, chosen, changes = signal_changes(path, patterns)
    t = int(header.get("t_a_us", 1000)) / 1e6
    names = [p for _, p, _ in chosen]
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["cycle", "time_s", *names])
    current: dict[str, Any] = {}
    rows = 0
    last: int | None = None

    def row(cycle: int) -> list[Any]:
        return [cycle, f"{cycle * t:.6f}", *(_csv_value(current.get(n)) for n in names)]

    for change in changes:
        if every_cycle and last is not None:
            for c in range(last + 1, change.cycle):
                writer.writerow(row(c))
                rows += 1
        current.update(change.values)
        writer.writerow(row(change.cycle))
        rows += 1
        last = change.cycle
    return rows


def _csv_value(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, bool):
        return int(value)
    return value


_VCD_NAME = re.compile(r"[^A-Za-z0-9_]")


def _vcd_scope_and_name(st_path: str) -> tuple[str, str]:
    """``gpAx[0]^ipo_state.cmd_pos_r`` -> scope ``hli.gpAx_0.ipo_state``, name ``cmd_pos_r``."""
    parts = re.split(r"[\^.]", st_path)
    clean = [_VCD_NAME.sub("_", p.replace("]", "")).strip("_") or "_" for p in parts]
    return ".".join(["hli", *clean[:-1]]), clean[-1]


def write_vcd(path: Path | str, out: IO[str], patterns: Sequence[str] = ()) -> int:
    """The chosen signals as a VCD (IEEE 1364) that GTKWave opens, time in µs (cycle x T_A; pyvcd
    writes it); returns the value changes written."""
    from vcd import VCDWriter

    header, chosen, changes = signal_changes(path, patterns)
    t_a_us = int(header.get("t_a_us", 1000))
    written = 0
    # VCD allows 1, 10 or 100 as the timescale's number (GTKWave refuses "1000 us"): time in µs
    with VCDWriter(
        out,
        timescale="1 us",
        date=str(header.get("created", "")),
        comment=f"hli-server recording {path}",
    ) as vcd:
        variables: dict[str, Any] = {}
        for _, st_path, kind in chosen:
            scope, name = _vcd_scope_and_name(st_path)
            if kind == "BOOL":
                variables[st_path] = vcd.register_var(scope, name, "wire", size=1)
            elif kind == "LREAL":
                variables[st_path] = vcd.register_var(scope, name, "real")
            else:
                variables[st_path] = vcd.register_var(scope, name, "integer", size=32)
        for change in changes:
            for st_path, value in change.values.items():
                var = variables[st_path]
                if isinstance(value, float) and not math.isfinite(value):
                    continue  # VCD reals are finite
                if isinstance(value, bool):
                    value = int(value)
                elif isinstance(value, int) and value < 0:
                    value &= 0xFFFF_FFFF  # two's complement, as a 32-bit vector
                vcd.change(var, change.cycle * t_a_us, value)
                written += 1
    return written


def write_plot(path: Path | str, out: Path, patterns: Sequence[str], *, title: str | None = None) -> int:
    """A step plot of the chosen signals over machine time (one panel each, at most 16) in any format
    matplotlib writes (PNG, PDF, SVG by the file's suffix); returns the panels drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not patterns:
        raise RecordingError("name the signals to plot (--signals PATTERN)")
    header, chosen, changes = signal_changes(path, patterns)
    if len(chosen) > 16:
        raise RecordingError(f"{len(chosen)} signals match; plot at most 16 at once")
    t = int(header.get("t_a_us", 1000)) / 1e6
    series: dict[str, tuple[list[float], list[float]]] = {p: ([], []) for _, p, _ in chosen}
    last_cycle = 0
    for change in changes:
        last_cycle = change.cycle
        for st_path, value in change.values.items():
            xs, ys = series[st_path]
            xs.append(change.cycle * t)
            ys.append(float(value))
    fig, axes = plt.subplots(
        len(chosen), 1, sharex=True, figsize=(10, 1.6 + 1.7 * len(chosen)), squeeze=False
    )
    for ax, (_, st_path, kind) in zip(axes[:, 0], chosen, strict=True):
        xs, ys = series[st_path]
        if xs:
            xs = [*xs, last_cycle * t]
            ys = [*ys, ys[-1]]
        ax.step(xs, ys, where="post")
        ax.set_ylabel(st_path.split("^")[-1], fontsize=7)
        ax.set_title(st_path, fontsize=8, loc="left")
        ax.grid(True, alpha=0.3)
        if kind == "BOOL":
            ax.set_yticks([0, 1])
    axes[-1, 0].set_xlabel("machine time [s]")
    fig.suptitle(title or f"{header.get('machine')}: {Path(path).name}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return len(chosen)
