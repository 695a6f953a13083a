"""The session recorder: the runtime's tap at the latch boundary (docs/record-replay.md, B-02).

Every cycle the runtime hands :meth:`SessionTap.after_cycle` the PLC->CNC half it latched and the
CNC->PLC half it packed. The tap keeps, in the cycle, only what changed, as raw bytes (a slice, a
comparison, sometimes an append: about a microsecond); a task of the event loop turns them into lines
(numpy finds the changed fields of many cycles at once) and writes them out, off the cycle.

Two sinks:

* **the input journal**, always, from the server's first cycle: every input the CNC takes (the latched
  PLC->CNC changes, the operator's requests with their program texts, the program files the engine
  read, the communication faults), compressed in memory and bounded (``journal_limit``). It is what
  makes a recording started in a running server replayable: the replay runs the same inputs from cycle
  1 and compares the outputs from the recording's window on;
* **the recording file**, between :meth:`SessionTap.start` and :meth:`SessionTap.stop`: the header, the
  journal so far, a snapshot of the machine's state where the recording starts (:mod:`.snapshot`: the
  replay starts there instead of at cycle 1, so that its cost is the recording's length), then the
  inputs of every cycle that changed them, the events at their cycle, and the outputs (the CNC->PLC
  half) sampled every ``outputs_every`` cycles where they changed (:mod:`hli_server.recording.format`).
  The engine is deterministic: the inputs reproduce every cycle, the samples are the replay's
  checkpoints, and the cycle pays one comparison for them.

The operator's requests reach the tap through :class:`JournaledOperator`, the runtime's operator panel
wrapped; program files through :meth:`SessionTap.wrap_reader`.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import dataclasses
import datetime
import importlib.metadata
import logging
import platform
import re
import struct
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from hli_server.adapters.host import (
    Accepted,
    ConflictError,
    InvalidRequestError,
    NotFoundError,
    OperatorError,
    OperatorPort,
)
from hli_server.recording.format import (
    FORMAT,
    FORMAT_VERSION,
    SUFFIX,
    RecordingError,
    RecordingFullError,
    RecordingWriter,
    dumps,
    encode_json,
    encode_text,
    encode_value,
    gzip_member,
)
from hli_server.recording.snapshot import SnapshotError, capture
from schemas.layout import Direction, Signal, SignalType
from schemas.results import (
    AlarmList,
    AreaTable,
    AxisFaults,
    CollisionPair,
    CommFaultChange,
    MachineState,
    ProbeDeviation,
    ProgramEntry,
    ProgramLoaded,
    ProgramSelected,
    RecorderStatus,
    RecordingFile,
    Scene,
    SoftLimits,
    Timing,
)
from schemas.wire import Mode

if TYPE_CHECKING:
    from hli_server.engine.machine import Machine
    from hli_server.engine.programs import ProgramFile, ProgramLibrary
    from hli_server.image.shm import ProcessImage
    from schemas.config import MachineConfig
    from schemas.events import Event
    from schemas.layout import Layout

__all__ = [
    "DEFAULT_FLUSH_S",
    "DEFAULT_JOURNAL_LIMIT",
    "DEFAULT_MAX_BYTES",
    "DEFAULT_OUTPUTS_EVERY",
    "OPERATOR_REQUESTS",
    "HalfCodec",
    "JournaledOperator",
    "RecordingOptions",
    "RecordingStatus",
    "SessionRecorderPort",
    "SessionTap",
    "server_info",
]

logger = logging.getLogger(__name__)

DEFAULT_FLUSH_S: Final = 1.0
"""Seconds between two flushes of a recording (what a crash can lose at most)."""
DEFAULT_MAX_BYTES: Final = 2 * 1024**3
"""A recording file is closed when it reaches this size (2 GiB; ``--record-max-mb``)."""
DEFAULT_OUTPUTS_EVERY: Final = 100
"""The outputs (CNC->PLC half) are sampled every this many cycles (``--record-outputs-every``; 100 =
0.1 s at 1 ms): the engine is deterministic, so the inputs stored at their cycles reproduce every cycle, and
the samples are the checkpoints the replay verifies. Events (alarms) are stored at their own cycle
always. 1 stores every cycle whose outputs changed (format version 1's behaviour; its cost per cycle is
in docs/performance.md)."""
DEFAULT_JOURNAL_LIMIT: Final = 256 * 1024**2
"""The input journal in memory (compressed) is dropped beyond this (256 MiB); a recording started
later then cannot be replayed from the server's first cycle, and says so."""
TICK_S: Final = 0.05
"""How often the encoder task looks for work."""
ENCODE_SLICE: Final = 2000
"""Cycles encoded before the encoder yields to the event loop (the clock's timer)."""
MAX_PENDING: Final = 20_000
"""Cycles of raw changes held in memory; beyond, the cycle itself encodes (the loop was starved)."""
JOURNAL_MEMBER_BYTES: Final = 256 * 1024
"""Journal text compressed into a member once it is this long."""
FOLLOW_CYCLE_SUFFIXES: Final = ("bahn_state.cycle_r",)
"""Outputs that count the cycles (``cycle_r`` = cycle mod 2**31): a recording lists them only when they
do not (the header's ``follow_cycle``), so that an idle machine writes nothing."""
CYCLE_MODULUS: Final = 2**31
NAME_RE: Final = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")

_P2C, _C2P = Direction.PLC_TO_CNC, Direction.CNC_TO_PLC
_IN, _OUT, _MISC = 0, 1, 2


def server_info() -> dict[str, Any]:
    """What made a recording: hli-server's version, the engine (compiled or pure), Python."""
    try:
        version = importlib.metadata.version("hli-server")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - a source tree not installed
        version = "unknown"
    from hli_server import _compiled

    return {
        "name": "hli-server",
        "version": version,
        "engine": "compiled" if _compiled.ENGINE_COMPILED else "pure",
        "python": platform.python_version(),
    }


class HalfCodec:
    """One half of the image as the recording sees it: its signals in offset order (the indices of
    the header's lists), one ``Struct`` for all of them, and the byte ranges numpy compares."""

    def __init__(self, layout: Layout, direction: Direction) -> None:
        self.signals: tuple[Signal, ...] = tuple(sorted(layout.half(direction), key=lambda s: s.offset))
        self.size = layout.size(direction)
        parts = ["<"]
        cursor = 0
        for s in self.signals:
            if s.offset > cursor:
                parts.append(f"{s.offset - cursor}x")
            parts.append(s.struct_char)
            cursor = s.offset + s.size
        if self.size > cursor:
            parts.append(f"{self.size - cursor}x")
        self.struct = struct.Struct("".join(parts))
        self.texts = [k for k, s in enumerate(self.signals) if s.type is SignalType.STRING]
        """The V.E. STRING fields: their bytes are recorded as text (format.encode_text)."""
        self.unpack = self._unpack_texts if self.texts else self.struct.unpack
        self.starts = np.array([s.offset for s in self.signals], dtype=np.intp)
        self.floats = frozenset(k for k, s in enumerate(self.signals) if s.type is SignalType.LREAL)
        self.index = {s.st_path: k for k, s in enumerate(self.signals)}
        self.follow = [
            k
            for k, s in enumerate(self.signals)
            if direction is _C2P
            and s.st_path.endswith(FOLLOW_CYCLE_SUFFIXES)
            and s.type is not SignalType.LREAL
        ]

    def _unpack_texts(self, row: bytes) -> list[Any]:
        values = list(self.struct.unpack(row))
        for k in self.texts:
            values[k] = encode_text(values[k])
        return values

    def header(self) -> list[list[str]]:
        return [[s.st_path, s.type_name] for s in self.signals]

    def changes(
        self, rows: Sequence[bytes], previous: bytes | None, cycles: Sequence[int] = ()
    ) -> list[list[Any]]:
        """For each row, ``[index, value, ...]`` of the fields that differ from the row before
        (``previous`` before the first; None: every field). With ``cycles`` (one per row), the
        :attr:`follow` fields are listed only where they are not the cycle mod 2**31."""
        n = len(rows)
        data = np.frombuffer(b"".join(rows), dtype=np.uint8).reshape(n, self.size)
        before = np.empty_like(data)
        if previous is None:
            before[0] = ~data[0]  # every byte differs: every field is listed
        else:
            before[0] = np.frombuffer(previous, dtype=np.uint8)
        before[1:] = data[:-1]
        changed = np.logical_or.reduceat(data != before, self.starts, axis=1) if len(self.starts) else None
        out: list[list[Any]] = []
        if changed is None:
            return [[] for _ in rows]
        follow = self.follow if cycles else []
        if follow:
            changed[:, follow] = False
            if previous is None:
                changed[0, follow] = True
        counts = changed.sum(axis=1).tolist()
        fields = np.nonzero(changed)[1].tolist()
        at = 0
        unpack = self.unpack
        # non-finite LREALs stay floats here: the line's encoder names them (_dumps_values)
        for n, (row, count) in enumerate(zip(rows, counts, strict=True)):
            values = None
            flat: list[Any] = []
            if count:
                values = unpack(row)
                flat = [x for k in fields[at : at + count] for x in (k, values[k])]
                at += count
            if follow and not (n == 0 and previous is None):
                own = cycles[n] % CYCLE_MODULUS
                if values is None:
                    values = unpack(row)
                for k in follow:
                    if values[k] != own:
                        flat.append(k)
                        flat.append(values[k])
            out.append(flat)
        return out


@dataclass(frozen=True, slots=True)
class RecordingStatus:
    """What ``GET /api/recording`` shows."""

    recording: bool
    file: str | None = None
    name: str | None = None
    started_cycle: int | None = None
    cycles: int = 0
    bytes_written: int = 0
    last_flush_s_ago: float | None = None
    journal_bytes: int = 0
    journal_complete: bool = True
    error: str | None = None
    directory: str | None = None

    def to_json(self) -> RecorderStatus:
        return {
            "recording": self.recording,
            "file": self.file,
            "name": self.name,
            "started_cycle": self.started_cycle,
            "cycles": self.cycles,
            "bytes_written": self.bytes_written,
            "last_flush_s_ago": self.last_flush_s_ago,
            "journal_bytes": self.journal_bytes,
            "journal_complete": self.journal_complete,
            "error": self.error,
            "directory": self.directory,
        }


@dataclass(frozen=True, slots=True)
class RecordingOptions:
    """How the server records (``hli-server run --record FILE --record-dir DIR ...``)."""

    file: Path | None = None
    """Record from the first cycle into this file (``--record``)."""
    directory: Path | None = None
    """Where recordings started by name (HTTP API, dashboard) go (``--record-dir``); None: the
    directory of ``file``, else none (the API then refuses to start one)."""
    flush_s: float = DEFAULT_FLUSH_S
    max_bytes: int = DEFAULT_MAX_BYTES
    journal_limit: int = DEFAULT_JOURNAL_LIMIT
    overwrite: bool = False
    outputs_every: int = DEFAULT_OUTPUTS_EVERY
    """Sample the outputs every this many cycles (``--record-outputs-every``; 1: every cycle)."""


class SessionTap:
    """The runtime's recording tap (module docstring). One per runtime; the runtime calls
    :meth:`bind` with its machine, :meth:`attach` at start, :meth:`before_cycle` / :meth:`after_cycle`
    around every cycle and :meth:`close` at stop."""

    def __init__(self, config: MachineConfig, options: RecordingOptions | None = None) -> None:
        options = options or RecordingOptions()
        self.options = options
        self.config = config
        self.directory = options.directory or (options.file.parent if options.file is not None else None)
        self.flush_s = options.flush_s
        self.max_bytes = options.max_bytes
        self.journal_limit = options.journal_limit
        if options.outputs_every < 1:
            raise ValueError(f"outputs_every must be at least 1 cycle, not {options.outputs_every}")
        self.outputs_every = options.outputs_every
        self._next_out = 0
        """the next cycle whose outputs are sampled (while recording)"""
        self._packed: bytearray | None = None
        """the runtime's packing buffer, for the sample of the recording's last cycle"""
        self.machine: Machine | Any = None
        self.layout: Layout | None = None
        self.inputs: HalfCodec | None = None
        self.outputs: HalfCodec | None = None
        self._in_cycle: int | None = None
        self._last_in: bytes = b""
        self._last_out: bytearray | None = None
        self._pending: list[tuple[int, int, Any]] = []
        self._events: list[Event] = []
        # encoder state (off the cycle)
        self._enc_in: bytes | None = None
        self._enc_out: bytes | None = None
        self._journal: list[bytes] = []
        self._journal_text: list[str] = []
        self._journal_text_len = 0
        self.journal_bytes = 0
        self.journal_lost_at: int | None = None
        # the recording
        self._writer: RecordingWriter | None = None
        self._window_start: int | None = None
        self._recording_out = False
        self._last_flush = 0.0
        self._last_cycle = 0
        self.error: str | None = None
        self._task: asyncio.Task[None] | None = None
        self._closed = False
        self._listening = False
        self._image: Any = None
        self._stalls: dict[int, tuple[int, dict[str, Any]]] = {}
        """the stall faults in effect: id -> (the cycle that latched their start, spec); a snapshot
        carries them (the replay repeats a stall)"""
        self.snapshot_s = 0.0
        """what the last snapshot cost (seconds, in the pause between two cycles)"""

    # --- life cycle (the runtime) ------------------------------------------------------------
    def bind(self, machine: Machine) -> None:
        self.machine = machine

    def restart(self) -> None:
        """The machine was powered off and on (``Runtime.restart_machine``; :meth:`bind` follows with the
        new one): the input journal begins anew, as at the server's start, so that a recording started from
        now on replays from the new machine's first cycle. Refused while a recording runs."""
        if self._writer is not None:
            raise RecordingError(f"a recording runs: {self._writer.path}; stop it first")
        self._pending.clear()
        self._events.clear()
        self._journal.clear()
        self._journal_text.clear()
        self._journal_text_len = 0
        self.journal_bytes = 0
        self.journal_lost_at = None
        self._last_in = b""
        self._enc_in = self._enc_out = None
        self._last_out = None
        self._in_cycle = None
        self._last_cycle = 0

    def attach(self, image: ProcessImage | Any) -> None:
        """The image exists: the halves' codecs; the encoder task starts in the running loop; with
        ``RecordingOptions.file`` the recording starts (before the first cycle)."""
        self.layout = image.layout
        self._image = image
        self.inputs = HalfCodec(image.layout, _P2C)
        self.outputs = HalfCodec(image.layout, _C2P)
        with contextlib.suppress(RuntimeError):  # no running loop: encoded by close() / the bound
            self._task = asyncio.get_running_loop().create_task(self._encoder(), name="hli-record")
        if self.options.file is not None:
            self.start(self.options.file, origin="run --record", overwrite=self.options.overwrite)

    async def close(self) -> None:
        """Stop the encoder, end a running recording cleanly (its end line). Idempotent."""
        if self._closed:
            return
        self._closed = True
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        if self._writer is not None:
            self.stop(reason="server stopped")
        self._stop_listening()

    # --- the cycle ---------------------------------------------------------------------------
    def before_cycle(self, cycle: int) -> None:
        """``cycle`` is about to latch (what the replay's feeder uses; here it marks notes made inside
        the cycle, such as a program file the engine reads, with this cycle)."""
        self._in_cycle = cycle

    def needs_outputs(self, cycle: int) -> bool:
        """Whether the runtime packs and publishes the CNC->PLC half after ``cycle``: always in a server
        (its PLC reads every cycle); the replay's feeder, which takes this slot, asks only for the cycles it
        compares."""
        return True

    def after_cycle(self, cycle: int, latched: bytes, packed: bytearray | None) -> None:
        """The cycle latched ``latched`` and packed ``packed`` (the cycle word, then the half)."""
        self._in_cycle = None
        self._last_cycle = cycle
        pending = self._pending
        if latched and latched != self._last_in:
            pending.append((_IN, cycle, latched))
            self._last_in = latched
        if self._recording_out and packed is not None:
            if cycle >= self._next_out:  # a sample of the outputs (a checkpoint of the replay)
                self._next_out = cycle + self.outputs_every
                self._packed = packed  # the runtime's packing buffer (the same every cycle): the last sample
                half = packed[8:]
                if half != self._last_out:
                    pending.append((_OUT, cycle, (bytes(half), self._take_events())))
                    self._last_out = half
                elif self._events:
                    pending.append((_OUT, cycle, (None, self._take_events())))
            elif self._events:  # events at their own cycle, every cycle
                pending.append((_OUT, cycle, (None, self._take_events())))
        if len(pending) > MAX_PENDING:
            self._encode(len(pending))

    def _take_events(self) -> list[Event]:
        events, self._events = self._events, []
        return events

    def _on_event(self, event: Event) -> None:
        self._events.append(event)

    def stamp(self) -> int:
        """The cycle a note belongs to: the running cycle inside one, else the next (that latches it)."""
        return self._in_cycle if self._in_cycle is not None else self.machine.cycle + 1

    # --- notes: inputs that are no image field ---------------------------------------------------
    def note(self, record: dict[str, Any]) -> None:
        """An input record (``op``, ``file``, ``fault``); ``c`` is added."""
        self._pending.append((_MISC, self.stamp(), record))

    def note_op(self, name: str, args: dict[str, Any], error: BaseException | None) -> None:
        text = None if error is None else f"{type(error).__name__}: {error}"
        self.note({"op": name, "args": args, "error": text})

    def note_fault(self, change: CommFaultChange) -> None:
        """A communication fault set or ended (``CommFaults.subscribe``)."""
        self.note(dict(change))
        spec = change.get("spec")
        if change["fault"] == "set" and isinstance(spec, dict) and spec.get("kind") == "stall":
            self._stalls[change["id"]] = (self.stamp(), dict(spec))
        elif change["fault"] == "end":
            self._stalls.pop(change["id"], None)

    def wrap_library(self, library: ProgramLibrary) -> ProgramLibrary:
        """The machine's program library (global subprograms, N-02), with every lookup noted: the
        program's name, text and origin, or that it was not found and where it was looked for."""
        return _NotedLibrary(library, self)

    def wrap_reader(self, read: Callable[[str], str] | None) -> Callable[[str], str] | None:
        """``read_program`` of the engine, with every file it reads noted (path and text)."""
        if read is None:
            return None

        def read_and_note(path: str) -> str:
            text = read(path)
            self.note({"file": path, "text": text})
            return text

        return read_and_note

    # --- recording ---------------------------------------------------------------------------
    @property
    def recording(self) -> bool:
        return self._writer is not None

    def resolve(self, name: str | None) -> Path:
        """The file of a recording started by name (HTTP, dashboard): inside :attr:`directory`, a
        plain name (no path), ``.jsonl.gz`` added; None: a name from the date and time."""
        if self.directory is None:
            raise RecordingError(
                "this server has no recording directory: start it with --record-dir DIR (or --record FILE)"
            )
        if name is None or name == "":
            stamp = datetime.datetime.now(datetime.UTC).strftime("%Y%m%d-%H%M%S")
            name = f"session-{stamp}"
        if not NAME_RE.match(name):
            raise RecordingError(
                f"recording name {name!r}: use up to 100 characters of A-Z a-z 0-9 _ . - (no path), starting "
                "with a letter or digit"
            )
        if not name.endswith(SUFFIX):
            name += SUFFIX
        return self.directory / name

    def start(
        self, path: Path, *, origin: str = "api", overwrite: bool = False, outputs_every: int | None = None
    ) -> RecordingStatus:
        """Start recording into ``path`` (a new file, unless ``overwrite``): the header, the input
        journal so far, the machine's snapshot (started in a running server), then every cycle's changes
        (the outputs every ``outputs_every`` cycles; None: the server's setting). RecordingError when one
        runs already."""
        if self.layout is None or self.inputs is None or self.outputs is None:
            raise RecordingError("the server is not running yet")
        if outputs_every is not None and outputs_every < 1:
            raise RecordingError(f"outputs_every must be at least 1 cycle, not {outputs_every}")
        if self._writer is not None:
            raise RecordingError(f"a recording runs already: {self._writer.path}; stop it first")
        self._encode(len(self._pending))
        self._flush_journal_text()
        window = self.machine.cycle + 1
        snapshot, note = self._snapshot(window)
        try:
            writer = RecordingWriter(path, max_bytes=self.max_bytes, overwrite=overwrite)
        except FileExistsError:
            raise RecordingError(f"{path} exists already; choose another name") from None
        except OSError as exc:
            raise RecordingError(f"cannot create {path}: {exc.strerror or exc}") from None
        header = {
            "record": "header",
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "server": server_info(),
            "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="milliseconds"),
            "origin": origin,
            "machine": self.config.name,
            "t_a_us": self.config.cycle_time_us,
            "config": self.config.model_dump(mode="json"),
            "layout": {"version": self.layout.version, "hash": self.layout.hash},
            "inputs": self.inputs.header(),
            "outputs": self.outputs.header(),
            "follow_cycle": self.outputs.follow,
            "outputs_every": outputs_every or self.options.outputs_every,
            "window_start": window,
            "journal": {
                "from_cycle": 1,
                "complete": self.journal_lost_at is None,
                "lost_at": self.journal_lost_at,
            },
            "snapshot": None
            if snapshot is None
            else {"cycle": window - 1, "fingerprint": snapshot["snapshot"]["fingerprint"]},
            "snapshot_note": note,
        }
        try:
            writer.write_line(dumps(header))
            writer.flush()
            for member in self._journal:
                writer.write_member(member)
            if snapshot is not None:  # after the journal: a replay from the snapshot skips what is before
                writer.write_line(_dumps_values(snapshot))
        except OSError as exc:
            writer.close()
            raise RecordingError(f"cannot write {path}: {exc}") from None
        self._writer = writer
        self.outputs_every = outputs_every or self.options.outputs_every
        self._window_start = window
        self._recording_out = True
        self._next_out = window
        self._last_out = None
        self._enc_out = None
        self._events = []
        self._last_flush = time.monotonic()
        self.error = None
        if not self._listening:
            self.machine.event_listeners.append(self._on_event)
            self._listening = True
        logger.info("recording to %s from cycle %d", path, window)
        return self.status()

    def _snapshot(self, window: int) -> tuple[dict[str, Any] | None, str | None]:
        """The record of the machine's state before cycle ``window`` (``{"c", "snapshot", "in",
        "external", "faults"}``), or None and why not: at the server's first cycle there is nothing
        before; a state that cannot be kept as data (:class:`SnapshotError`) leaves the replay the input
        journal from cycle 1, and the log and the header say why."""
        if window <= 1 or self.inputs is None:
            return None, None
        began = time.perf_counter()
        try:
            state = capture(self.machine)
        except SnapshotError as exc:
            note = f"the machine's state at cycle {window - 1:,} cannot be kept as data: {exc}"
            logger.warning(
                "recording: %s; a replay runs the input journal from cycle 1%s",
                note,
                "" if self.journal_lost_at is None else ", which was dropped: it cannot be replayed",
            )
            return None, note
        record: dict[str, Any] = {
            "c": window - 1,
            "snapshot": state,
            # the PLC->CNC half as the last cycle latched it (every field), and the V.E. sync's bytes
            "in": self.inputs.changes([self._last_in], None)[0] if self._last_in else [],
            "external": None,
            "faults": [],
        }
        raw = getattr(self._image, "external_raw", None)
        if isinstance(raw, bytes | bytearray):
            record["external"] = base64.b64encode(bytes(raw)).decode("ascii")
        for fault_id, (stamp, spec) in sorted(self._stalls.items()):
            ends = stamp - 1 + int(spec.get("cycles", 0))  # CommFaults.add: the cycle it was set + cycles
            left = ends - (window - 1)
            if left > 0:
                record["faults"].append({"id": fault_id, "spec": {**spec, "cycles": left}})
        self.snapshot_s = time.perf_counter() - began
        logger.info(
            "recording: snapshot of cycle %d, %d objects, in %.1f ms",
            window - 1,
            len(state["objects"]),
            self.snapshot_s * 1000,
        )
        return record, None

    def stop(self, reason: str = "stopped") -> RecordingStatus:
        """End the recording: everything encoded and flushed, the end line, the file closed."""
        writer = self._writer
        if writer is None:
            raise RecordingError("no recording runs")
        packed, last = self._packed, self._last_cycle
        if (
            packed is not None and self._next_out - self.outputs_every < last
        ):  # the last cycle is a sample too
            half = packed[8:]
            self._pending.append(
                (_OUT, last, (bytes(half) if half != self._last_out else None, self._take_events()))
            )
        self._recording_out = False
        self._packed = None
        self._stop_listening()
        self._encode(len(self._pending))
        status = self.status()
        self._writer = None
        last = self._last_cycle
        try:
            writer.close({"c": last, "end": reason})
        except OSError as exc:
            self.error = f"closing {writer.path}: {exc}"
            logger.error("recording %s: %s", writer.path, self.error)
        logger.info(
            "recording %s ended at cycle %d (%s): %d bytes", writer.path, last, reason, writer.bytes_written
        )
        return dataclasses.replace(status, recording=False, bytes_written=writer.bytes_written)

    def _stop_listening(self) -> None:
        if self._listening:
            with contextlib.suppress(ValueError):
                self.machine.event_listeners.remove(self._on_event)
            self._listening = False

    def status(self) -> RecordingStatus:
        writer = self._writer
        directory = str(self.directory) if self.directory is not None else None
        if writer is None:
            return RecordingStatus(
                recording=False,
                journal_bytes=self.journal_bytes,
                journal_complete=self.journal_lost_at is None,
                error=self.error,
                directory=directory,
            )
        start = self._window_start or 0
        return RecordingStatus(
            recording=True,
            file=str(writer.path),
            name=writer.path.name,
            started_cycle=start,
            cycles=max(0, self.machine.cycle - start + 1),
            bytes_written=writer.bytes_written,
            last_flush_s_ago=round(time.monotonic() - self._last_flush, 3),
            journal_bytes=self.journal_bytes,
            journal_complete=self.journal_lost_at is None,
            error=self.error,
            directory=directory,
        )

    def flush(self) -> None:
        """Everything so far encoded and, when recording, written out now (waits for the writer)."""
        self._encode(len(self._pending))
        self._flush_file()
        writer = self._writer
        if writer is not None:
            try:
                writer.wait()
            except OSError as exc:
                self._fail(str(exc), reason="full" if isinstance(exc, RecordingFullError) else "write error")

    # --- the encoder (off the cycle) -----------------------------------------------------------
    async def _encoder(self) -> None:
        while True:
            await asyncio.sleep(TICK_S)
            try:
                while self._pending:
                    self._encode(ENCODE_SLICE)
                    if self._pending:
                        await asyncio.sleep(0)
                if self._writer is not None and time.monotonic() - self._last_flush >= self.flush_s:
                    self._flush_file()
            except asyncio.CancelledError:
                raise
            except Exception:  # the recorder must never take the server down
                logger.exception("the session recorder failed; the recording is stopped")
                self._fail("the recorder failed (see the server log)")

    def _flush_file(self) -> None:
        writer = self._writer
        if writer is None:
            return
        self._last_flush = time.monotonic()
        try:
            writer.flush()
        except RecordingFullError as exc:
            self._fail(str(exc), reason="full")
        except OSError as exc:
            self._fail(f"writing {writer.path}: {exc.strerror or exc}", reason="write error")

    def _fail(self, message: str, reason: str = "error") -> None:
        self.error = message
        logger.error("recording: %s", message)
        if self._writer is not None:
            with contextlib.suppress(Exception):
                self.stop(reason=reason)
            self.error = message

    def _encode(self, limit: int) -> None:
        """Turn up to ``limit`` pending items into lines for the journal and the recording."""
        if not self._pending or self.inputs is None or self.outputs is None:
            return
        items, self._pending = self._pending[:limit], self._pending[limit:]
        in_rows = [raw for kind, _, raw in items if kind == _IN]
        out_items = [(cycle, raw[0]) for kind, cycle, raw in items if kind == _OUT and raw[0] is not None]
        out_rows = [raw for _, raw in out_items]
        in_changes = iter(self.inputs.changes(in_rows, self._enc_in) if in_rows else [])
        out_changes = iter(
            self.outputs.changes(out_rows, self._enc_out, [c for c, _ in out_items]) if out_rows else []
        )
        if in_rows:
            self._enc_in = in_rows[-1]
        if out_rows:
            self._enc_out = out_rows[-1]
        journal: list[str] = []
        file: list[str] = []
        writer = self._writer
        for kind, cycle, raw in items:
            if kind == _IN:
                flat = next(in_changes)
                if flat:
                    line = _dumps_values({"c": cycle, "i": flat})
                    journal.append(line)
            elif kind == _OUT:
                half, events = raw
                flat = next(out_changes) if half is not None else []
                if events:
                    record: dict[str, Any] = {"c": cycle}
                    if flat:
                        record["o"] = flat
                    record["e"] = [_event_json(e) for e in events]
                    file.append(_dumps_values(record))
                elif flat:
                    try:
                        file.append(f'{{"c":{cycle},"o":{encode_json(flat)}}}\n')
                    except ValueError:
                        file.append(_dumps_values({"c": cycle, "o": flat}))
                continue
            else:
                line = _dumps_values({"c": cycle, **raw})
                journal.append(line)
            if writer is not None:
                file.append(line)
        if journal:
            self._journal_add(journal)
        if file and writer is not None:
            writer.write_lines(file)

    def _journal_add(self, lines: list[str]) -> None:
        if self.journal_lost_at is not None:
            return
        self._journal_text.extend(lines)
        self._journal_text_len += sum(len(line) for line in lines)
        if self._journal_text_len >= JOURNAL_MEMBER_BYTES:
            self._flush_journal_text()

    def _flush_journal_text(self) -> None:
        if not self._journal_text or self.journal_lost_at is not None:
            return
        member = gzip_member("".join(self._journal_text))
        self._journal_text.clear()
        self._journal_text_len = 0
        self._journal.append(member)
        self.journal_bytes += len(member)
        if self.journal_bytes > self.journal_limit:
            self.journal_lost_at = self.machine.cycle
            self._journal.clear()
            logger.warning(
                "the input journal passed its limit of %d MB at cycle %d and was dropped: a recording "
                "started from now on cannot be replayed from the first cycle (record from the start with "
                "`hli-server run --record FILE`, or raise --journal-limit-mb)",
                self.journal_limit // 1024**2,
                self.journal_lost_at,
            )


class _NotedLibrary:
    """A :class:`ProgramLibrary` whose finds are inputs of the recording (``SessionTap.wrap_library``)."""

    def __init__(self, inner: ProgramLibrary, tap: SessionTap) -> None:
        self.inner = inner
        self._tap = tap

    def find(self, name: str) -> ProgramFile | None:
        found = self.inner.find(name)
        if found is None:
            self._tap.note({"program_file": name, "found": None, "searched": list(self.inner.searched())})
        else:
            self._tap.note(
                {"program_file": name, "found": found.name, "text": found.text, "origin": found.origin}
            )
        return found

    def searched(self) -> tuple[str, ...]:
        return self.inner.searched()

    def __getattr__(self, name: str) -> Any:  # what else the runtime's library offers (uploads)
        return getattr(self.inner, name)


def _event_json(event: Event) -> dict[str, Any]:
    return event.to_json()


def _dumps_values(record: dict[str, Any]) -> str:
    """:func:`dumps`, with non-finite numbers anywhere (event payloads) by name."""
    try:
        return dumps(record)
    except ValueError:
        return dumps(_finite(record))


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return encode_value(value)
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


class JournaledOperator(OperatorPort):
    """The operator panel with every request noted in the session tap (an input of the recording),
    refused ones too (a replay must refuse them alike). What only reads goes straight through."""

    def __init__(self, panel: OperatorPort, tap: SessionTap) -> None:
        self.panel = panel
        self._tap = tap

    def _do(self, name: str, args: dict[str, Any], call: Callable[[], Any]) -> Any:
        try:
            result = call()
        except OperatorError as exc:
            self._tap.note_op(name, args, exc)
            raise
        self._tap.note_op(name, args, None)
        return result

    # --- what is noted ---------------------------------------------------------------------------
    def load_program(
        self, channel: int, text: str, name: str = "program", files: Mapping[str, str] | None = None
    ) -> ProgramLoaded:
        args: dict[str, Any] = {"channel": channel, "text": text, "name": name}
        if files:  # the subprograms uploaded with it (N-02): the replay uploads them again
            args["files"] = dict(files)
        result: ProgramLoaded = self._do(
            "load_program", args, lambda: self.panel.load_program(channel, text, name, files)
        )
        return result

    def select_program(self, channel: int, number: int) -> ProgramSelected:
        result: ProgramSelected = self._do(
            "select_program",
            {"channel": channel, "number": number},
            lambda: self.panel.select_program(channel, number),
        )
        return result

    def start(self, channel: int) -> Accepted:
        result: Accepted = self._do("start", {"channel": channel}, lambda: self.panel.start(channel))
        return result

    def reset(self, channel: int) -> Accepted:
        result: Accepted = self._do("reset", {"channel": channel}, lambda: self.panel.reset(channel))
        return result

    def feedhold(self, channel: int, on: bool) -> Accepted:
        result: Accepted = self._do(
            "feedhold", {"channel": channel, "on": on}, lambda: self.panel.feedhold(channel, on)
        )
        return result

    def mode(self, channel: int, mode: Mode) -> Accepted:
        result: Accepted = self._do(
            "mode", {"channel": channel, "mode": int(mode)}, lambda: self.panel.mode(channel, mode)
        )
        return result

    def override(self, channel: int, permille: int) -> Accepted:
        result: Accepted = self._do(
            "override",
            {"channel": channel, "permille": permille},
            lambda: self.panel.override(channel, permille),
        )
        return result

    def jog(self, channel: int, axis: str, direction: int) -> Accepted:
        result: Accepted = self._do(
            "jog",
            {"channel": channel, "axis": axis, "direction": direction},
            lambda: self.panel.jog(channel, axis, direction),
        )
        return result

    def probe(self, channel: int, on: bool) -> Accepted:
        result: Accepted = self._do(
            "probe", {"channel": channel, "on": on}, lambda: self.panel.probe(channel, on)
        )
        return result

    def probe_deviation(self, channel: int) -> ProbeDeviation:
        return self.panel.probe_deviation(channel)

    def set_probe_deviation(self, channel: int, values: dict[str, int]) -> ProbeDeviation:
        result: ProbeDeviation = self._do(
            "set_probe_deviation",
            {"channel": channel, "values": dict(values)},
            lambda: self.panel.set_probe_deviation(channel, values),
        )
        return result

    def reference(self, axis: str) -> Accepted:
        result: Accepted = self._do("reference", {"axis": axis}, lambda: self.panel.reference(axis))
        return result

    def inject_faults(self, axis: str, **fields: float | bool) -> AxisFaults:
        result: AxisFaults = self._do(
            "inject_faults", {"axis": axis, **fields}, lambda: self.panel.inject_faults(axis, **fields)
        )
        return result

    def clear_faults(self, axis: str) -> AxisFaults:
        result: AxisFaults = self._do("clear_faults", {"axis": axis}, lambda: self.panel.clear_faults(axis))
        return result

    def set_soft_limits(self, axis: str, **values: int) -> SoftLimits:
        result: SoftLimits = self._do(
            "set_soft_limits", {"axis": axis, **values}, lambda: self.panel.set_soft_limits(axis, **values)
        )
        return result

    def update_axis_record(self, axis: str, **values: int) -> SoftLimits:
        result: SoftLimits = self._do(
            "update_axis_record",
            {"axis": axis, **values},
            lambda: self.panel.update_axis_record(axis, **values),
        )
        return result

    # --- what only reads -------------------------------------------------------------------------
    @property
    def cycle(self) -> int:
        return self.panel.cycle

    @property
    def time_s(self) -> float:
        return self.panel.time_s

    @property
    def t_a_us(self) -> int:
        return self.panel.t_a_us

    @property
    def machine_name(self) -> str:
        return self.panel.machine_name

    def channel_numbers(self) -> list[int]:
        return self.panel.channel_numbers()

    def axis_names(self, channel: int | None = None) -> list[str]:
        return self.panel.axis_names(channel)

    def faults(self, axis: str) -> AxisFaults:
        return self.panel.faults(axis)

    def soft_limits(self, axis: str) -> SoftLimits:
        return self.panel.soft_limits(axis)

    def snapshot(self) -> MachineState:
        return self.panel.snapshot()

    def alarms(self, history: int = 200) -> AlarmList:
        return self.panel.alarms(history)

    def areas(self, channel: int) -> AreaTable:
        return self.panel.areas(channel)

    def timing(self) -> Timing:
        return self.panel.timing()

    def scene(self, channel: int) -> Scene:
        return self.panel.scene(channel)

    def programs(self, channel: int) -> list[ProgramEntry]:
        return self.panel.programs(channel)

    def collision_pairs(self) -> list[CollisionPair]:
        return self.panel.collision_pairs()


OPERATOR_REQUESTS: Final = (
    "load_program",
    "select_program",
    "start",
    "reset",
    "feedhold",
    "mode",
    "override",
    "jog",
    "probe",
    "set_probe_deviation",
    "reference",
    "inject_faults",
    "clear_faults",
    "set_soft_limits",
    "update_axis_record",
)
"""The operator requests a recording holds (and a replay repeats), by :class:`OperatorPort` name."""


class SessionRecorderPort:
    """The :class:`~hli_server.adapters.host.RecorderPort` of a runtime's tap: recordings by name in
    the recording directory, errors as the operator's (409 / 404 / 422 in the HTTP API)."""

    def __init__(self, tap: SessionTap) -> None:
        self._tap = tap

    def status(self) -> RecorderStatus:
        return self._tap.status().to_json()

    def start(self, name: str | None = None) -> RecorderStatus:
        tap = self._tap
        try:
            path = tap.resolve(name)
            try:
                path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)  # a new one: its owner's only
            except OSError as exc:
                raise RecordingError(f"cannot create the recording directory {path.parent}: {exc}") from None
            return tap.start(path, origin="api").to_json()
        except RecordingError as exc:
            raise _operator_error(exc) from None

    def stop(self) -> RecorderStatus:
        try:
            return self._tap.stop().to_json()
        except RecordingError as exc:
            raise ConflictError(str(exc)) from None

    def files(self) -> list[RecordingFile]:
        directory = self._tap.directory
        if directory is None or not directory.is_dir():
            return []
        running = self._tap.status().file
        out: list[RecordingFile] = []
        for path in sorted(directory.glob(f"*{SUFFIX}")):
            with contextlib.suppress(OSError):
                stat = path.stat()
                out.append(
                    {
                        "name": path.name,
                        "bytes": stat.st_size,
                        "modified": datetime.datetime.fromtimestamp(stat.st_mtime, datetime.UTC).isoformat(
                            timespec="seconds"
                        ),
                        "recording": str(path) == running,
                    }
                )
        return out

    def file(self, name: str) -> Path:
        """The path of recording ``name`` in the directory (NotFoundError when there is none)."""
        directory = self._tap.directory
        if directory is None or not NAME_RE.match(name) or not name.endswith(SUFFIX):
            raise NotFoundError(f"no recording {name!r}")
        path = directory / name
        if not path.is_file():
            raise NotFoundError(f"no recording {name!r} in {directory}")
        return path


def _operator_error(exc: RecordingError) -> OperatorError:
    text = str(exc)
    if "recording name" in text:
        return InvalidRequestError(text)
    return ConflictError(text)
