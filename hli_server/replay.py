"""Replay a recording as a regression test (docs/record-replay.md, B-02): ``hli-server replay FILE``,
``hli.replay(path)``.

The replay builds the recorded machine from the recorded configuration and runs it on the stepped clock
(a :class:`~hli_server.runtime.Runtime` with its image in memory and no doors): a driver of the runtime,
so it sits above it, below the commands and the test harness that call it; the recording it reads
(:mod:`hli_server.recording`) sits below the runtime. Its tap slot holds a
:class:`Feeder` instead of the recorder: before each cycle it writes the PLC->CNC half recorded for that
cycle into the image and repeats the operator's requests stamped with it (program texts and the files
the engine read come from the recording); after the cycle it compares the CNC->PLC half the engine
packed with the recorded one at every recorded sample of the outputs (every cycle in format version 1;
every ``outputs_every`` cycles from the window's first in version 2), and the events at every cycle.
The first difference ends the replay (``all_differences``: every difference is counted, the first
``max_differences`` kept).

Where it starts: a recording started in a running server carries a snapshot of the machine where it
started (format version 4, :mod:`hli_server.recording.snapshot`); the replay puts it into its machine
and runs the recording's cycles only, so its cost is the recording's length. Where the snapshot is of
another engine (another version, an edited engine), cannot be restored, or is missing (its state could
not be kept, an older recording), the replay runs the recording's input journal from the server's first
cycle instead, and says so; ``from_journal`` asks for that. The report counts the cycles replayed and the
cycles compared (the recording's) apart.

Verdicts and exit statuses: ``pass`` 0, ``differ`` 1, ``cannot replay`` 3 (2 is a usage error): a file that
is no recording or of a newer format, a recording whose start state cannot be rebuilt (started in a
running server after its input journal was dropped, and its snapshot of no use here), a configuration
that this version refuses or that differs from the one given, signals this version's image no longer
has, or another hli-server version when ``same_version`` is asked for. Without ``same_version`` another
version replays (what a regression test is for) and the report names both versions.
"""

from __future__ import annotations

import asyncio
import base64
import binascii
import contextlib
import functools
import inspect
import json
import math
import struct
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from hli_server.adapters.faults import FaultSpec
from hli_server.adapters.host import OperatorError
from hli_server.recording.format import (
    RecordingError,
    Records,
    check_recording,
    decode_value,
    read_records,
    signal_pattern,
    text_bytes,
)
from hli_server.recording.snapshot import SnapshotRestoreError, engine_fingerprint, restore
from hli_server.recording.tap import CYCLE_MODULUS, OPERATOR_REQUESTS, _finite, server_info
from schemas.layout import Direction, Signal, SignalType
from schemas.wire import Mode

if TYPE_CHECKING:
    from hli_server.engine.machine import Machine
    from hli_server.engine.programs import ProgramFile
    from hli_server.runtime import Runtime
    from schemas.config import MachineConfig
    from schemas.events import Event

__all__ = [
    "EXIT_STATUS",
    "CannotReplayError",
    "Difference",
    "ReplayReport",
    "Verdict",
    "replay",
    "replay_sync",
]

CHUNK: Final = 5000
"""Cycles run per step of the stepped clock (the feeder reads that far ahead)."""
_P2C, _C2P = Direction.PLC_TO_CNC, Direction.CNC_TO_PLC
_NO_EVENTS: Final[list[Any]] = []
"""A cycle's events when there were none (never appended to)."""


class Verdict(StrEnum):
    PASS = "pass"
    DIFFER = "differ"
    CANNOT = "cannot replay"


EXIT_STATUS: Final = {Verdict.PASS: 0, Verdict.DIFFER: 1, Verdict.CANNOT: 3}


class CannotReplayError(Exception):
    """The recording cannot be replayed here; the message says why (version, configuration, ...)."""


class _StopReplayError(Exception):
    """The feeder found what ends the replay (the first difference)."""


@dataclass(frozen=True, slots=True)
class Difference:
    """One output that differs: in ``cycle``, ``signal`` (an ST path, ``events`` or ``operator ...``)."""

    cycle: int
    signal: str
    expected: Any
    actual: Any
    t_a_us: int = 1000

    def __str__(self) -> str:
        return (
            f"cycle {self.cycle} ({self.cycle * self.t_a_us / 1e6:.3f} s): {self.signal}: "
            f"expected {_show(self.expected)}, got {_show(self.actual)}"
        )

    def to_json(self) -> dict[str, Any]:
        return {
            "cycle": self.cycle,
            "time_s": self.cycle * self.t_a_us / 1e6,
            "signal": self.signal,
            "expected": _finite(self.expected),
            "actual": _finite(self.actual),
        }


def _show(value: Any) -> str:
    text = json.dumps(_finite(value), ensure_ascii=False) if not isinstance(value, str) else value
    return text if len(text) <= 300 else text[:297] + "..."


@dataclass(slots=True)
class ReplayReport:
    """The outcome: verdict, where, what differs, and what the reader should know."""

    path: str
    verdict: Verdict = Verdict.PASS
    reason: str | None = None
    differences: list[Difference] = field(default_factory=list)
    counts: dict[str, list[int]] = field(default_factory=dict)
    """signal -> [differences, first cycle, last cycle] (all of them, also beyond max_differences)."""
    first_cycle: int = 1
    """the first cycle the replay ran: the recording's first after a snapshot, else 1 (the journal)"""
    window_start: int = 1
    last_cycle: int = 0
    started_from: str = "journal"
    """``snapshot`` (the recorded state where the recording began) or ``journal`` (cycle 1 on)"""
    t_a_us: int = 1000
    wall_s: float = 0.0
    recorded_with: dict[str, Any] = field(default_factory=dict)
    replayed_with: dict[str, Any] = field(default_factory=server_info)
    notes: list[str] = field(default_factory=list)

    @property
    def exit_status(self) -> int:
        return EXIT_STATUS[self.verdict]

    @property
    def first(self) -> Difference | None:
        return self.differences[0] if self.differences else None

    @property
    def cycles(self) -> int:
        """The cycles the replay ran (from :attr:`first_cycle`)."""
        return max(0, self.last_cycle - self.first_cycle + 1)

    @property
    def cycles_compared(self) -> int:
        """The recording's cycles: from its window's first on."""
        return max(0, self.last_cycle - self.window_start + 1)

    def text(self, *, limit: int = 20) -> str:
        lines: list[str] = []
        if self.verdict is Verdict.CANNOT:
            lines.append(f"replay of {self.path}: CANNOT REPLAY: {self.reason}")
        else:
            replayed = self.cycles
            rate = replayed / self.wall_s if self.wall_s > 0 else 0.0
            compared = self.cycles_compared
            start = (
                f"from the snapshot of cycle {self.first_cycle - 1:,}"
                if self.started_from == "snapshot"
                else f"from the input journal (cycles {self.first_cycle:,}..{self.last_cycle:,})"
            )
            lines.append(
                f"replay of {self.path}: {'PASS' if self.verdict is Verdict.PASS else 'DIFFER'}: "
                f"{compared:,} cycles compared (cycles {self.window_start:,}..{self.last_cycle:,}, "
                f"{compared * self.t_a_us / 1e6:.3f} s of machine time)"
            )
            lines.append(
                f"{replayed:,} cycles replayed {start} in {self.wall_s:.2f} s ({rate:,.0f} cycles/s)"
            )
            first = self.first
            if first is not None:
                lines.append(f"first difference: {first}")
                total = sum(c[0] for c in self.counts.values())
                if len(self.counts) > 1 or total > 1:
                    lines.append(f"{total:,} differences in {len(self.counts)} signals:")
                    shown = sorted(self.counts.items(), key=lambda kv: (kv[1][1], kv[0]))
                    for signal, (count, first_cycle, last_cycle) in shown[:limit]:
                        lines.append(f"  {signal}: {count:,} cycles, {first_cycle:,}..{last_cycle:,}")
                    if len(shown) > limit:
                        lines.append(f"  ... and {len(shown) - limit} more signals")
        versions = (self.recorded_with.get("version"), self.replayed_with.get("version"))
        if self.recorded_with:
            same = versions[0] == versions[1]
            lines.append(
                f"recorded with hli-server {versions[0]} ({self.recorded_with.get('engine')} engine), "
                f"replayed with {versions[1]} ({self.replayed_with.get('engine')} engine)"
                + ("" if same else ": versions differ")
            )
        lines.extend(f"note: {note}" for note in self.notes)
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        return {
            "path": self.path,
            "verdict": str(self.verdict),
            "exit_status": self.exit_status,
            "reason": self.reason,
            "window_start": self.window_start,
            "first_cycle": self.first_cycle,
            "last_cycle": self.last_cycle,
            "started_from": self.started_from,
            "cycles_replayed": self.cycles,
            "cycles_compared": self.cycles_compared,
            "t_a_us": self.t_a_us,
            "wall_s": round(self.wall_s, 3),
            "first": self.first.to_json() if self.first else None,
            "differences": [d.to_json() for d in self.differences],
            "counts": {k: {"count": v[0], "first": v[1], "last": v[2]} for k, v in self.counts.items()},
            "recorded_with": self.recorded_with,
            "replayed_with": self.replayed_with,
            "notes": self.notes,
        }


# --------------------------------------------------------------------------------------------
# checks before any cycle runs
# --------------------------------------------------------------------------------------------


def _config_differences(a: Any, b: Any, where: str = "") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out: list[str] = []
        for key in sorted(set(a) | set(b)):
            sub = f"{where}.{key}" if where else str(key)
            if key not in a or key not in b:
                out.append(sub)
            else:
                out.extend(_config_differences(a[key], b[key], sub))
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        out = []
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            out.extend(_config_differences(x, y, f"{where}[{k}]"))
        return out
    return [] if a == b else [where or "(the whole configuration)"]


def _recorded_config(header: dict[str, Any], given: MachineConfig | None) -> MachineConfig:
    from pydantic import ValidationError

    from schemas.config import MachineConfig

    recorded = header.get("config")
    if not isinstance(recorded, dict):
        raise CannotReplayError("the recording's header holds no machine configuration")
    try:
        config = MachineConfig.model_validate(recorded)
    except ValidationError as exc:
        first = exc.errors()[0]
        raise CannotReplayError(
            f"configuration mismatch: this hli-server ({server_info()['version']}) refuses the recorded "
            f"configuration: {'.'.join(str(p) for p in first['loc'])}: {first['msg']}"
        ) from None
    if given is not None:
        diffs = _config_differences(config.model_dump(mode="json"), given.model_dump(mode="json"))
        if diffs:
            shown = ", ".join(diffs[:8]) + (f" and {len(diffs) - 8} more" if len(diffs) > 8 else "")
            raise CannotReplayError(
                f"configuration mismatch: the machine given differs from the recorded one in {shown}"
            )
    return config


# --------------------------------------------------------------------------------------------
# the feeder: the replay's tap
# --------------------------------------------------------------------------------------------


class Feeder:
    """Feeds the recorded inputs and compares the outputs, cycle by cycle (module docstring)."""

    def __init__(
        self,
        header: dict[str, Any],
        records: Iterator[dict[str, Any]],
        info: Records,
        report: ReplayReport,
        *,
        signals: Sequence[str] | None,
        events: bool,
        all_differences: bool,
        max_differences: int,
        until: int | None,
        start: dict[str, Any] | None = None,
    ) -> None:
        self.header = header
        self.start = start
        """the snapshot record the replay starts from (None: the journal, from cycle 1)"""
        self._write_inputs = False
        self._records = records
        self.info = info
        self.report = report
        self.signal_patterns = tuple(signals or ())
        self._matches = signal_pattern(self.signal_patterns)
        self.compare_events = events
        self.all_differences = all_differences
        self.max_differences = max_differences
        self.until = until
        self.window = int(header.get("window_start", 1))
        self.t_a_us = int(header.get("t_a_us", 1000))
        self.every = max(1, int(header.get("outputs_every", 1)))
        """the outputs were sampled every this many cycles from the window's first (format 2)"""
        self._buffer: deque[dict[str, Any]] = deque()
        self._exhausted = False
        self.end_cycle: int | None = None
        self.last_record_cycle = 0
        self.files: dict[str, deque[str]] = {}
        self.library_finds: dict[str, deque[dict[str, Any]]] = {}
        self._searched: tuple[str, ...] = ()
        self._last_file: dict[str, str] = {}
        self.runtime: Runtime | None = None
        self._fault_ids: dict[int, int] = {}
        self._events: list[Event] = []
        self._expected_events: list[Any] = []
        self._stop_after_cycle = False
        self._outputs_asked: tuple[int, bool] = (-1, True)
        """(cycle, whether its outputs were asked for): the last :meth:`needs_outputs` answer."""
        self._failure: CannotReplayError | SnapshotRestoreError | None = None

    # --- set-up ----------------------------------------------------------------------------------
    def bind(self, runtime: Runtime) -> None:
        """Map the recorded signals onto this version's image (CannotReplayError for what is gone)."""
        self.runtime = runtime
        layout = runtime.image.layout
        self.image: Any = (
            runtime.image
        )  # the replay's own ProcessImage in memory (image_factory=memory_image)
        self.inputs = self._map(layout, self.header.get("inputs"), _P2C, "input")
        self.p2c_size = layout.size(_P2C)
        self.expected_in = bytearray(runtime.image.read_half(_P2C))
        c2p = sorted(layout.half(_C2P), key=lambda s: s.offset)
        self.c2p_signals = c2p
        self.c2p_struct = layout.struct(_C2P)
        position = {s.st_path: k for k, s in enumerate(layout.half(_C2P))}
        recorded = self._map(layout, self.header.get("outputs"), _C2P, "output")
        selected = [s for s in recorded if s is not None and self._selected(s.st_path)]
        if self.signal_patterns and not selected:
            raise CannotReplayError(
                f"--signals {', '.join(self.signal_patterns)}: no recorded output matches (see `hli-server "
                "record show --signals`)"
            )
        self.outputs = recorded
        self.out_position = [position[s.st_path] if s is not None else -1 for s in recorded]
        self.compared = sorted({position[s.st_path] for s in selected})
        self.names = [s.st_path for s in layout.half(_C2P)]
        self.types = [s.type for s in layout.half(_C2P)]
        self.expected_out: list[Any] = [None] * len(self.names)
        same_layout = self.header.get("layout", {}).get("hash") == layout.hash
        self.fast = same_layout and not self.signal_patterns
        if not same_layout:
            self.report.notes.append(
                "the image's layout changed since the recording (another version or configuration): the "
                "recorded signals are compared by name"
            )
        self.expected_bytes = bytearray(layout.size(_C2P))
        self.out_structs = [struct_for(s) for s in layout.half(_C2P)]
        self.offsets = [s.offset for s in layout.half(_C2P)]
        follow = self.header.get("follow_cycle") or []
        self.follow = [
            self.out_position[k] for k in follow if 0 <= k < len(recorded) and self.out_position[k] >= 0
        ]
        runtime.machine.event_listeners.append(self._events.append)
        if self.start is not None:
            self._start_image(runtime, self.start)

    def _start_image(self, runtime: Runtime, start: dict[str, Any]) -> None:
        """What the snapshot record holds besides the machine: the PLC->CNC half the last cycle latched
        (written into the image before the first cycle), the V.E. sync's bytes, the stalls in effect."""
        flat = start.get("in")
        if not isinstance(flat, list):
            raise CannotReplayError("the recording's snapshot holds no PLC->CNC half")
        self._apply_inputs(flat)
        self._write_inputs = True
        external = start.get("external")
        if external is not None:
            try:
                self.image.external_raw = base64.b64decode(str(external), validate=True)
            except (ValueError, binascii.Error) as exc:
                raise CannotReplayError(f"the recording's snapshot: its V.E. fields: {exc}") from None
        for fault in start.get("faults") or []:
            if isinstance(fault, dict) and isinstance(fault.get("spec"), dict):
                self._apply_fault({"fault": "set", "id": fault.get("id", -1), "spec": fault["spec"]})

    def _map(self, layout: Any, listed: Any, direction: Direction, what: str) -> list[Signal | None]:
        if not isinstance(listed, list):
            raise CannotReplayError(f"the recording's header has no list of {what}s")
        out: list[Signal | None] = []
        missing: list[str] = []
        for entry in listed:
            path, kind = entry[0], entry[1]
            if path not in layout:
                if what == "output" and self.signal_patterns and not self._selected(path):
                    out.append(None)
                    continue
                missing.append(path)
                out.append(None)
                continue
            signal = layout.signal(path)
            if signal.direction is not direction or signal.type_name != kind:
                missing.append(f"{path} (was {kind}, is {signal.type_name})")
                out.append(None)
                continue
            out.append(signal)
        if missing:
            shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
            hint = "" if what == "input" else "; compare the others with --signals"
            raise CannotReplayError(f"this version's image has no recorded {what} {shown}{hint}")
        return out

    def _selected(self, path: str) -> bool:
        return self._matches(path)

    # --- reading ahead -----------------------------------------------------------------------------
    def _fill(self, upto: int) -> None:
        while not self._exhausted and (not self._buffer or self._buffer[-1].get("c", 0) <= upto):
            try:
                record = next(self._records)
            except StopIteration:
                self._exhausted = True
                break
            cycle = record.get("c")
            if not isinstance(cycle, int):
                raise RecordingError(f"a record without its cycle: {str(record)[:200]}")
            if "end" in record:
                self.end_cycle = cycle
                self._exhausted = True
                break
            self.last_record_cycle = max(self.last_record_cycle, cycle)
            self._buffer.append(record)

    def horizon(self, cycle: int) -> int:
        """The last cycle the replay may run to now (``cycle`` is the machine's; 0 steps: done)."""
        self._fill(cycle + CHUNK)
        end = cycle + CHUNK
        if self._exhausted:
            last = self.end_cycle if self.end_cycle is not None else self.last_record_cycle
            end = min(end, last)
        if self.until is not None:
            end = min(end, self.until)
        return end

    # --- the tap interface (the runtime calls these) -------------------------------------------------
    def attach(self, image: Any) -> None:
        pass

    async def close(self) -> None:
        pass

    def note_fault(self, change: dict[str, Any]) -> None:
        pass

    def restored_state_failed(self, exc: Exception) -> bool:
        """The runtime's ``cycle_failure_hook`` of a replay from a snapshot: the engine failing on the
        restored state (a damaged or forged snapshot that restore() took: an attribute of the wrong kind)
        ends the replay after the cycle as a snapshot that does not fit, never as alarm 919000."""
        if self._failure is None:
            cycle = self.runtime.machine.cycle if self.runtime is not None else 0
            self._failure = SnapshotRestoreError(
                f"the restored state fails the engine in cycle {cycle}: {type(exc).__name__}: "
                f"{str(exc)[:300]}"
            )
        return True

    def before_cycle(self, cycle: int) -> None:
        """The recorded inputs of ``cycle``, before it runs. Called inside the runtime's cycle, whose
        failures become alarm 919000: what stops the replay here is raised after the cycle instead."""
        try:
            self._before_cycle(cycle)
        except _StopReplayError:
            self._stop_after_cycle = True
        except Exception as exc:
            self._failure = CannotReplayError(f"cycle {cycle}: {type(exc).__name__}: {exc}")

    def _before_cycle(self, cycle: int) -> None:
        buffer = self._buffer
        changed = False
        while buffer and buffer[0]["c"] <= cycle and "o" not in buffer[0] and "e" not in buffer[0]:
            record = buffer.popleft()
            if "i" in record:
                self._apply_inputs(record["i"])
                changed = True
            elif "op" in record:
                self._apply_op(cycle, record)
            elif "program_file" in record:
                self.library_finds.setdefault(str(record["program_file"]), deque()).append(record)
            elif "file" in record:
                text = record.get("text")
                if isinstance(text, str):
                    self.files.setdefault(str(record["file"]), deque()).append(text)
            elif "fault" in record:
                self._apply_fault(record)
        if changed or self._write_inputs:  # the half as the recorded cycle latched it, byte for byte
            self._write_inputs = False
            offset = self.image.plan.p2c_offset
            self.image.buffer[offset : offset + self.p2c_size] = self.expected_in

    def _apply_inputs(self, flat: list[Any]) -> None:
        inputs = self.inputs
        buf = self.expected_in
        for k in range(0, len(flat) - 1, 2):
            signal = inputs[flat[k]]
            if signal is None:
                continue
            value = decode_value(flat[k + 1])
            kind = signal.type
            plain = (
                bool(value)
                if kind is SignalType.BOOL
                else float(value)
                if kind is SignalType.LREAL
                else text_bytes(value)
                if kind is SignalType.STRING
                else int(value)
            )
            struct_for(signal).pack_into(buf, signal.offset, plain)

    def _apply_op(self, cycle: int, record: dict[str, Any]) -> None:
        name = record.get("op")
        args = dict(record.get("args") or {})
        if name not in OPERATOR_REQUESTS:
            raise CannotReplayError(
                f"cycle {cycle}: an operator request this version does not know: {name!r}"
            )
        if name == "mode" and "mode" in args:
            args["mode"] = Mode(args["mode"])
        assert self.runtime is not None
        panel = self.runtime.panel
        outcome: str | None = None
        try:
            getattr(panel, str(name))(**args)
        except OperatorError as exc:
            outcome = f"{type(exc).__name__}: {exc}"
        except TypeError as exc:
            raise CannotReplayError(f"cycle {cycle}: operator request {name} {args}: {exc}") from None
        recorded = record.get("error")
        if (recorded is None) != (outcome is None) or (
            recorded is not None and outcome is not None and recorded.split(":")[0] != outcome.split(":")[0]
        ):
            what = f"operator {name} " + ", ".join(f"{k}={v}" for k, v in args.items() if k != "text")
            expected = "accepted" if recorded is None else f"refused ({recorded})"
            actual = "accepted" if outcome is None else f"refused ({outcome})"
            if cycle >= self.window:
                self._differ(cycle, what, expected, actual)
            else:
                self.report.notes.append(
                    f"before the recording's window, cycle {cycle}: {what}: {expected}, {actual}"
                )

    def _apply_fault(self, record: dict[str, Any]) -> None:
        """A stall is repeated (it acts on the publish); the doors' faults acted on what the PLC sent,
        which the recorded inputs hold."""
        assert self.runtime is not None
        faults = self.runtime.comm_faults
        if record.get("fault") == "set":
            spec = record.get("spec") or {}
            if spec.get("kind") == "stall":
                fault = faults.add(spec)
                self._fault_ids[int(record["id"])] = fault.id
        elif record.get("fault") == "end" and record.get("reason") in ("api", "reset"):
            own = self._fault_ids.pop(int(record.get("id", -1)), None)
            if own is not None and faults.get(own) is not None:
                faults.end(own, str(record.get("reason")))

    def read_file(self, path: str) -> str:
        """The engine's ``read_program``: the files in the recording, in the order they were read."""
        queue = self.files.get(path)
        if queue:
            text = queue.popleft()
            self._last_file[path] = text
            return text
        if path in self._last_file:
            return self._last_file[path]
        raise OSError(f"{path} is not in the recording (the recorded session did not read it)")

    def find(self, name: str) -> ProgramFile | None:
        """The machine's program library: what the recorded session's library found, find by find."""
        from hli_server.engine.programs import ProgramFile

        queue = self.library_finds.get(name)
        if not queue:
            return None
        record = queue.popleft()
        if record.get("found") is None:
            self._searched = tuple(str(s) for s in record.get("searched") or ())
            return None
        return ProgramFile(str(record["found"]), str(record.get("text", "")), str(record.get("origin", "")))

    def searched(self) -> tuple[str, ...]:
        return self._searched

    def needs_outputs(self, cycle: int) -> bool:
        """Whether the runtime packs the CNC->PLC half after ``cycle``: the cycles :meth:`after_cycle`
        compares, which it takes from this answer. A replay's image has no other reader (the runtime packs
        anyway where a signal recorder or a cycle listener is attached): the half of the other cycles is
        never looked at, what the engine does does not depend on it, and its V.E. writes still go into
        the image (``ProcessImage.publish_external``)."""
        window = self.window
        needed = cycle >= window and (
            self.every == 1 or not (cycle - window) % self.every or self._has_sample(cycle)
        )
        self._outputs_asked = (cycle, needed)
        return needed

    def _has_sample(self, cycle: int) -> bool:
        """A recorded sample of the outputs at ``cycle`` (its record is at the buffer's head then)."""
        buffer = self._buffer
        return bool(buffer) and buffer[0]["c"] == cycle and bool(buffer[0].get("o"))

    def after_cycle(self, cycle: int, latched: bytes, packed: bytearray | None) -> None:
        if self._failure is not None:
            raise self._failure
        if self._stop_after_cycle:
            raise _StopReplayError
        asked, wanted = self._outputs_asked
        if asked != cycle:  # the runtime asks before it publishes; anyone else gets the same answer
            wanted = self.needs_outputs(cycle)
        if not wanted and not self._events and not self._expected_events:
            # most cycles: nothing recorded at this cycle, no event, nothing to compare
            buffer = self._buffer
            if not buffer or buffer[0]["c"] != cycle:
                self.report.last_cycle = cycle
                return
        own_events = self._events  # the machine's listener appends to this very list
        events = own_events[:] if own_events else _NO_EVENTS
        if own_events:
            own_events.clear()
        buffer = self._buffer
        flat = None
        if buffer and buffer[0]["c"] == cycle and ("o" in buffer[0] or "e" in buffer[0]):
            record = buffer.popleft()
            flat = record.get("o")  # a sample of the outputs (the recording's last cycle is one as well)
            self._expected_events = record.get("e") or _NO_EVENTS
        elif self._expected_events:
            self._expected_events = _NO_EVENTS
        self.report.last_cycle = cycle
        window = self.window
        # the outputs are compared where needs_outputs asked for them; no half there: the publish failed
        compared = wanted and packed is not None
        publish_failed = wanted and packed is None
        # the cycle counters the outputs follow are set only where the outputs are compared: every such
        # cycle sets them before its recorded sample is applied, so skipping the others changes nothing
        if compared and self.follow and cycle > window:
            own = cycle % CYCLE_MODULUS
            for at in self.follow:
                self.expected_out[at] = own
                if self.fast:
                    self.out_structs[at].pack_into(self.expected_bytes, self.offsets[at], own)
        if flat:
            self._expect(flat)
        if not compared:
            if cycle < window or publish_failed:
                return
        elif self.fast:
            assert packed is not None
            if packed[8:] != self.expected_bytes:
                self._compare_values(cycle, packed)
        else:
            assert packed is not None
            self._compare_values(cycle, packed)
        if self.compare_events and (events or self._expected_events):
            actual = [json.loads(json.dumps(_finite(e.to_json()))) for e in events]
            if actual != self._expected_events:
                self._differ(cycle, "events", _event_summary(self._expected_events), _event_summary(actual))

    def _expect(self, flat: list[Any]) -> None:
        positions = self.out_position
        expected = self.expected_out
        buf = self.expected_bytes
        fast = self.fast
        for k in range(0, len(flat) - 1, 2):
            at = positions[flat[k]]
            if at < 0:
                continue
            value = decode_value(flat[k + 1])
            expected[at] = value
            if fast:
                self.out_structs[at].pack_into(buf, self.offsets[at], value)

    def _compare_values(self, cycle: int, packed: bytearray) -> None:
        actual = self.c2p_struct.unpack_from(packed, 8)
        expected = self.expected_out
        for at in self.compared:
            want, got = expected[at], actual[at]
            if want is None or want == got:
                continue
            if isinstance(want, float) and isinstance(got, float) and math.isnan(want) and math.isnan(got):
                continue
            if self.types[at] is SignalType.BOOL and bool(want) == bool(got):
                continue
            self._differ(cycle, self.names[at], want, got)

    def _differ(self, cycle: int, signal: str, expected: Any, actual: Any) -> None:
        report = self.report
        report.verdict = Verdict.DIFFER
        count = report.counts.get(signal)
        if count is None:
            report.counts[signal] = [1, cycle, cycle]
        else:
            count[0] += 1
            count[2] = cycle
        if len(report.differences) < self.max_differences:
            report.differences.append(Difference(cycle, signal, expected, actual, self.t_a_us))
        if not self.all_differences:
            raise _StopReplayError


def struct_for(signal: Signal) -> struct.Struct:
    return _struct("<" + signal.struct_char)


@functools.lru_cache(maxsize=16)
def _struct(fmt: str) -> struct.Struct:
    return struct.Struct(fmt)


def _event_summary(events: list[Any]) -> list[str]:
    out = []
    for e in events:
        data = e.get("data") or {}
        alarm = data.get("alarm") if isinstance(data, dict) else None
        if isinstance(alarm, dict):
            out.append(f"{e.get('kind')} {alarm.get('id')}: {alarm.get('message')}")
        else:
            out.append(f"{e.get('kind')} {json.dumps(data, sort_keys=True)[:160]}")
    return out


# --------------------------------------------------------------------------------------------
# the replay
# --------------------------------------------------------------------------------------------


async def replay(
    path: Path | str,
    *,
    config: MachineConfig | None = None,
    until: int | None = None,
    signals: Sequence[str] | None = None,
    events: bool = True,
    all_differences: bool = False,
    max_differences: int = 1000,
    same_version: bool = False,
    prepare: Callable[[Machine], None] | None = None,
    from_journal: bool = False,
) -> ReplayReport:
    """Replay ``path`` (module docstring); never raises for what a recording holds: the report says.

    ``prepare(machine)`` is called once the machine is built (and holds the recording's snapshot), before
    its first cycle: a test can change the engine there (a drive parameter, a monitor) and see whether the
    recording notices. ``from_journal``: start from the input journal (cycle 1) although the recording
    holds a snapshot."""
    path = Path(path)
    report = ReplayReport(path=str(path))
    began = time.perf_counter()
    info = Records()
    options: dict[str, Any] = {
        "signals": signals,
        "events": events,
        "all_differences": all_differences,
        "max_differences": max_differences,
        "until": until,
    }
    try:
        # every line checked before the first cycle runs: a bad line anywhere (a cycle out of order, an
        # index beyond the header's signals, a field of the wrong kind) is refused with its place, and the
        # replay runs no further than the recording's own last cycle (issue 36, finding 6)
        check_recording(path, _replayable)
        records = read_records(path, info)
        header = next(records)
        report.recorded_with = dict(header.get("server") or {})
        report.t_a_us = int(header.get("t_a_us", 1000))
        report.window_start = int(header.get("window_start", 1))
        if same_version and report.recorded_with.get("version") != report.replayed_with.get("version"):
            raise CannotReplayError(
                f"version mismatch: recorded with hli-server {report.recorded_with.get('version')}, this is "
                f"{report.replayed_with.get('version')} (--same-version)"
            )
        machine_config = _recorded_config(header, config)
        start = _snapshot_record(header, records, report, from_journal)
        if start is not None:
            line = info.lines
            try:
                await _run(machine_config, header, records, info, report, options, prepare, start)
            except SnapshotRestoreError as exc:
                # the fingerprint says this engine wrote it: a snapshot it cannot restore is damaged or
                # forged (docs/record-replay.md); the input journal may still serve, if the user wants
                raise RecordingError(
                    f"{path}: line {line}: snapshot: {exc} (hli-server replay --from-journal replays the "
                    "recording from its input journal instead)"
                ) from None
        else:
            report.started_from, report.first_cycle = "journal", 1
            await _run(machine_config, header, records, info, report, options, prepare, None)
    except CannotReplayError as exc:
        report.verdict = Verdict.CANNOT
        report.reason = str(exc)
    except RecordingError as exc:
        report.verdict = Verdict.CANNOT
        report.reason = str(exc)
    report.wall_s = time.perf_counter() - began
    if info.truncated is not None and report.verdict is not Verdict.CANNOT:
        report.notes.append(f"{info.truncated}: replayed up to cycle {report.last_cycle}")
    elif report.verdict is Verdict.PASS and report.last_cycle == 0 and until != 0:
        report.notes.append("the recording holds no cycle")
    report.notes.extend(info.notes)
    return report


def _journal_or_cannot(header: dict[str, Any], report: ReplayReport, why: str) -> None:
    """The replay starts from the input journal because of ``why`` (a note), or cannot (the journal of a
    recording started in a running server was dropped)."""
    journal = header.get("journal") or {}
    if not journal.get("complete", True):
        raise CannotReplayError(
            f"the recording began at cycle {report.window_start} in a running server whose input journal "
            f"had been dropped at cycle {journal.get('lost_at')} (--journal-limit-mb), and {why}: the state "
            "at its start cannot be rebuilt; replay it with the hli-server that made it, or record from the "
            "start (hli-server run --record FILE)"
        )
    if report.window_start > 1:
        report.notes.append(
            f"{why}: the replay runs the recording's input journal from cycle 1 "
            f"({report.window_start - 1:,} cycles before the recording's first)"
        )


def _snapshot_record(
    header: dict[str, Any], records: Iterator[dict[str, Any]], report: ReplayReport, from_journal: bool
) -> dict[str, Any] | None:
    """The snapshot record to start from (the journal before it read past), or None: start from the
    journal (the notes say why, or CannotReplayError when neither serves)."""
    snapshot = header.get("snapshot")
    note = header.get("snapshot_note")
    if snapshot is None:
        if report.window_start > 1:
            why = f"the recording holds no snapshot ({note})" if note else "the recording holds no snapshot"
            _journal_or_cannot(header, report, why)
        return None
    if not isinstance(snapshot, dict):
        raise CannotReplayError("the recording's header: its snapshot entry is no object")
    if from_journal:
        _journal_or_cannot(header, report, "the recording's snapshot is left aside (--from-journal)")
        return None
    if snapshot.get("fingerprint") != engine_fingerprint():
        _journal_or_cannot(
            header,
            report,
            "the recording's snapshot is of another engine (recorded with hli-server "
            f"{report.recorded_with.get('version')}, whose engine sources differ from this one's)",
        )
        return None
    for record in records:  # the journal before it: the snapshot holds what it built
        if "snapshot" in record:
            if record.get("c") != report.window_start - 1:
                raise CannotReplayError(
                    f"the recording's snapshot is of cycle {record.get('c')}, its window begins at cycle "
                    f"{report.window_start}"
                )
            report.started_from, report.first_cycle = "snapshot", report.window_start
            return record
    raise CannotReplayError("the recording's header announces a snapshot, and the file holds none")


async def _run(
    machine_config: MachineConfig,
    header: dict[str, Any],
    records: Iterator[dict[str, Any]],
    info: Records,
    report: ReplayReport,
    options: dict[str, Any],
    prepare: Callable[[Machine], None] | None,
    start: dict[str, Any] | None,
) -> None:
    """Build the replay's runtime (from the snapshot, when ``start`` is one) and run it to the end or the
    first difference. SnapshotRestoreError when the snapshot does not fit this engine (no cycle ran)."""
    from hli_server.runtime import Runtime, memory_image

    feeder = Feeder(header, records, info, report, start=start, **options)
    runtime = Runtime(
        machine_config,
        clock="stepped",
        http_port=None,
        adapters=[],
        image_factory=memory_image,
        read_program=feeder.read_file,
    )
    runtime.session = feeder  # type: ignore[assignment]  # the replay's tap: feeds and compares
    runtime.host.detach_dashboard()  # nobody watches a replay's dashboard
    runtime.machine.programs = feeder  # the subprograms the recorded session found
    # and the cycle files its channels' cycle directories gave (noted in the same stream, find by find)
    runtime.machine.cycle_programs = dict.fromkeys(runtime.machine.cycle_programs, feeder)
    if start is not None:
        restore(start.get("snapshot") or {}, runtime.machine)
        runtime.cycle_failure_hook = feeder.restored_state_failed
    if prepare is not None:
        prepare(runtime.machine)
    try:
        async with runtime:
            feeder.bind(runtime)
            with contextlib.suppress(_StopReplayError):
                while True:
                    cycle = runtime.machine.cycle
                    end = feeder.horizon(cycle)
                    if end <= cycle:
                        break
                    await runtime.step(end - cycle)
    except (CannotReplayError, RecordingError, SnapshotRestoreError):
        raise
    except Exception as exc:
        if start is None:
            raise
        # the runtime's start (the image published from the machine) on a restored state of the wrong
        # kinds: the snapshot does not fit, as restore() says of what it sees itself
        raise SnapshotRestoreError(
            f"the restored state fails the runtime: {type(exc).__name__}: {str(exc)[:300]}"
        ) from None


def _replayable(line: int, record: dict[str, Any]) -> str | None:
    """What the replay will do with ``record`` that the file's own check cannot know: an operator request
    it knows with arguments its panel takes, a stall fault it can set; the problem in words, or None."""
    from hli_server.runtime.operator_panel import OperatorPanel

    name = record.get("op")
    if name is not None:
        if name not in OPERATOR_REQUESTS:
            return f"op: an operator request this version does not know: {str(name)[:60]!r}"
        args = dict(record.get("args") or {})
        try:
            inspect.signature(getattr(OperatorPanel, str(name))).bind(None, **args)
            if name == "mode" and "mode" in args:
                Mode(args["mode"])
        except (TypeError, ValueError) as exc:
            return f"args: operator request {name}: {exc}"
    if record.get("fault") == "set" and (record.get("spec") or {}).get("kind") == "stall":
        return _stall_problem("spec", record["spec"])
    for k, fault in enumerate(record.get("faults") or () if "snapshot" in record else ()):
        problem = _stall_problem(f"faults[{k}].spec", {**fault["spec"], "kind": "stall"})
        if problem is not None:
            return problem
    return None


def _stall_problem(field: str, spec: dict[str, Any]) -> str | None:
    """A stall fault the replay cannot set (``field``: where it is in the line), or None."""
    try:
        FaultSpec.model_validate(spec)
    except ValueError as exc:
        return f"{field}: {' '.join(str(exc).split())[:300]}"
    return None


def replay_sync(path: Path | str, **options: Any) -> ReplayReport:
    """:func:`replay` in an event loop of its own (the command line)."""
    report: ReplayReport = asyncio.run(replay(path, **options))
    return report
