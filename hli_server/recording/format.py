"""The recording file: gzip-compressed JSON Lines, written while the server runs (docs/record-replay.md,
B-02).

Why this format (docs/record-replay.md says it for users):

* **Open without us.** ``zcat session.jsonl.gz | jq .`` reads it; so does any language with gzip and
  JSON. Arrow would be faster to scan, but it needs pyarrow (or another Arrow library) to read at all,
  and a recording is a sparse list of changes of different kinds, not a table.
* **Readable after a crash up to the last flush.** Every flush writes one complete gzip member (RFC
  1952 allows a file of several members; gzip, zcat and Python's ``gzip`` read them as one stream).
  A server killed mid-write leaves at most one incomplete member at the end; :func:`read_records`
  stops before it and says so. Nothing already flushed is ever rewritten.
* **Small.** Only changes are stored, as ``[index, value, ...]`` into the signal lists of the header;
  gzip takes out the repetition.

One JSON object per line. The first is the header (``"record": "header"``); then, in the order they
happened::

    {"c": 1204, "i": [3, true, 7, 150000]}          PLC->CNC signals latched in cycle 1204 (changes)
    {"c": 1204, "o": [0, 1204, 12, 503311], "e": [...]}  CNC->PLC published in cycle 1204, its events
    {"c": 1205, "op": "start", "args": {"channel": 1}, "error": null}   operator request before 1205
    {"c": 1205, "file": "/abs/part.nc", "text": "%part\\n..."}          a program file the engine read
    {"c": 1205, "program_file": "UP1.NC", "found": "UP1.NC", "text": "...", "origin": "..."}  a subprogram
    {"c": 1300, "fault": "set", "id": 2, "spec": {...}}                 a communication fault began
    {"c": 1350, "fault": "end", "id": 2, "reason": "count"}             ... and ended
    {"c": 2000, "end": "stopped"}                                       the last line of a clean stop

``c`` is the cycle: the interpolation cycle that latched the input or published the output (the first
cycle of a machine is 1; time = c * T_A). An operator request is stamped with the cycle that latches
it. The first ``i`` and the first ``o`` line hold every signal; later ones what changed. Outputs are
recorded from the header's ``window_start`` on; inputs always from cycle 1 (a recording started in a
running server carries the server's input journal from its start, so that a replay can reach the same
state). BOOL values are ``true``/``false``, DINT/UDINT integers, LREAL numbers (``"NaN"``,
``"Infinity"``, ``"-Infinity"`` for the values JSON has no number for), a V.E. STRING its text in a
list of one (``["teach_01.dat"]``; version 3). The outputs the header lists in
``follow_cycle`` (the ``cycle_r`` counters) equal the cycle mod 2**31 unless a line lists them.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import os
import re
import zlib
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Final

from schemas.layout import STRING_ENCODING

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MAX_SPAN",
    "SUFFIX",
    "RecordChecker",
    "RecordingError",
    "RecordingFullError",
    "RecordingWriter",
    "Records",
    "check_recording",
    "decode_value",
    "encode_text",
    "encode_value",
    "gzip_member",
    "read_header",
    "read_records",
    "signal_pattern",
    "text_bytes",
]

FORMAT: Final = "hli-recording"
FORMAT_VERSION: Final = 4
"""Raised when a reader of this version could not read the new files; readers refuse newer versions.
4: a recording started in a running server carries a snapshot of the machine (a ``snapshot`` line after
the journal; the header's ``snapshot`` and ``snapshot_note``); 3: V.E. STRING values; 2: the outputs
sampled every ``outputs_every`` cycles; 1: every cycle's outputs."""
SUFFIX: Final = ".jsonl.gz"
COMPRESS_LEVEL: Final = 1
"""zlib level of the members: the fastest (140 MB/s here against 76 at level 3 and 24 at level 6, for
9 % and 22 % more bytes; docs/record-replay.md)."""
MAX_LINE_BYTES: Final = 256 * 1024 * 1024
"""A line longer than this is refused by the reader (a program text may be up to 64 MiB, escaped)."""
MAX_SPAN: Final = 2**31
"""Cycles a recording may span from its first line to its last (24.8 days at T_A = 1 ms, the range of the
HLI's cycle counter): what a replay may have to run, bounded by the file itself (issue 36, finding 6)."""
_RANGES: Final = {"DINT": (-(2**31), 2**31 - 1), "UDINT": (0, 2**32 - 1)}
_KINDS: Final = ("i", "o", "e", "op", "file", "program_file", "fault", "snapshot", "end")
_TYPES: Final = ("BOOL", "DINT", "UDINT", "LREAL", "STRING")
_STRING_TYPE: Final = re.compile(r"STRING\(([1-9][0-9]{0,3})\)")
_FINGERPRINT: Final = re.compile(r"[0-9a-f]{1,64}")


def _known_type(name: object) -> bool:
    """A type a recording's signal may have: an IEC base type or a V.E. STRING(n) of n <= 9999 bytes."""
    return isinstance(name, str) and (name in _TYPES or _STRING_TYPE.fullmatch(name) is not None)


_READ_CHUNK: Final = 1 << 20
_CLOEXEC: Final = getattr(os, "O_CLOEXEC", 0)


class RecordingError(ValueError):
    """A file that is no recording, or one this version cannot read; the message says which."""


class RecordingFullError(OSError):
    """The recording reached its size limit; it was closed with what it had."""


def encode_value(value: bool | int | float) -> bool | int | float | str:
    """A signal value for JSON: non-finite floats by name."""
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    return value


_NON_FINITE: Final = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


def encode_text(raw: bytes) -> list[str]:
    """A STRING field's value for JSON: its bytes up to the first NUL as Windows-1252 text, in a list of
    one (so that no text is taken for a number's name); a byte that is no Windows-1252 character is
    kept as an escape (``surrogateescape``), so the replay writes the very bytes back."""
    return [raw.partition(b"\0")[0].decode(STRING_ENCODING, "surrogateescape")]


def text_bytes(text: str) -> bytes:
    """The bytes of a STRING value :func:`decode_value` read (the inverse of :func:`encode_text`)."""
    return text.encode(STRING_ENCODING, "surrogateescape")


def decode_value(value: Any) -> Any:
    """The inverse of :func:`encode_value` and :func:`encode_text` (a string a number has no other
    meaning in a recording; a STRING's text comes as a list of one)."""
    if isinstance(value, list) and len(value) == 1 and isinstance(value[0], str):
        return value[0]
    if isinstance(value, str):
        try:
            return _NON_FINITE[value]
        except KeyError:
            raise RecordingError(f"a signal value {value!r} is neither a number nor a boolean") from None
    return value


def signal_pattern(patterns: Sequence[str]) -> Callable[[str], bool]:
    """A matcher of ST paths: ``*`` any text, ``?`` one character, everything else literal (the
    brackets of ``gpAx[0]`` too); no patterns match everything."""
    if not patterns:
        return lambda _path: True
    parts = [re.escape(p).replace(r"\*", ".*").replace(r"\?", ".") for p in patterns]
    regex = re.compile("^(?:" + "|".join(parts) + ")$")
    return lambda path: regex.match(path) is not None


_ENCODER: Final = json.JSONEncoder(separators=(",", ":"), ensure_ascii=True, allow_nan=False)
encode_json: Final = _ENCODER.encode
"""Compact ASCII JSON, non-finite numbers refused (ValueError): one encoder for every line."""


def dumps(record: dict[str, Any]) -> str:
    """One line (compact, ASCII, a newline at the end)."""
    return encode_json(record) + "\n"


def gzip_member(text: str, level: int = COMPRESS_LEVEL) -> bytes:
    """``text`` as one complete gzip member (header, deflate stream, CRC and size)."""
    compressor = zlib.compressobj(level, zlib.DEFLATED, 31)
    return compressor.compress(text.encode("ascii")) + compressor.flush()


class RecordingWriter:
    """Appends lines to a recording file, one gzip member per :meth:`flush` (crash-safe up to it).

    Compressing and writing run in a thread of the writer's own (zlib and file writes release the GIL),
    in order, so that the event loop and the cycle do not wait for them. An error there (the size limit,
    a full disk) is raised by the next :meth:`flush`. ``max_bytes`` bounds the file: the member that would
    pass it is not written; :meth:`close` then ends the file with an ``"end": "full"`` line."""

    def __init__(
        self, path: Path, *, max_bytes: int, overwrite: bool = False, level: int = COMPRESS_LEVEL
    ) -> None:
        self.path = path
        self.max_bytes = max_bytes
        self.level = level
        # the owner's alone (0600): a recording holds the programs' text, every input and every event,
        # which the HTTP door gives only to the API token's holders (docs/reliability.md, "Access")
        flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL) | _CLOEXEC
        fd = os.open(path, flags, 0o600)
        if overwrite:
            os.fchmod(fd, 0o600)
        self._file: IO[bytes] | None = os.fdopen(fd, "wb")
        self._lines: list[str] = []
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="hli-record-writer")
        self._error: OSError | None = None
        self.bytes_written = 0
        self.flushes = 0

    @property
    def closed(self) -> bool:
        return self._file is None

    def write_line(self, line: str) -> None:
        self._lines.append(line)

    def write_lines(self, lines: Sequence[str]) -> None:
        self._lines.extend(lines)

    def write_member(self, member: bytes) -> None:
        """A ready gzip member (the input journal's), after what is buffered."""
        self.flush()
        self._executor.submit(self._write, member)

    def flush(self) -> None:
        """Hand what is buffered to the writer thread; raises what went wrong there before."""
        if self._error is not None:
            raise self._error
        if not self._lines or self._file is None:
            return
        text = "".join(self._lines)
        self._lines.clear()
        self._executor.submit(self._compress_and_write, text)

    def wait(self) -> None:
        """Until everything handed over is written (tests, benchmarks)."""
        self._executor.submit(lambda: None).result()
        if self._error is not None:
            raise self._error

    def _compress_and_write(self, text: str) -> None:
        if self._error is None:
            self._write(gzip_member(text, self.level))

    def _write(self, member: bytes) -> None:
        file = self._file
        if file is None or self._error is not None:
            return
        if self.bytes_written + len(member) > self.max_bytes:
            self._error = RecordingFullError(
                f"{self.path}: the recording reached its limit of {self.max_bytes / 1e6:.1f} MB "
                "(--record-max-mb); it was closed there"
            )
            return
        try:
            file.write(member)
            file.flush()
        except OSError as exc:
            self._error = exc
            return
        self.bytes_written += len(member)
        self.flushes += 1

    def close(self, end: dict[str, Any] | None = None) -> None:
        """Write what is buffered, ``end`` as the last line (a member of its own, written whatever the
        bound: a reader sees why the file ends), and close."""
        file = self._file
        if file is None:
            return
        try:
            if self._lines and self._error is None:
                text = "".join(self._lines)
                self._lines.clear()
                self._executor.submit(self._compress_and_write, text)
            self._executor.shutdown(wait=True)
            if isinstance(self._error, RecordingFullError):
                end = {**(end or {}), "end": "full"}
            if end is not None and not (
                self._error is not None and not isinstance(self._error, RecordingFullError)
            ):
                member = gzip_member(dumps(end))
                file.write(member)
                self.bytes_written += len(member)
            file.flush()
            os.fsync(file.fileno())
        finally:
            self._file = None
            file.close()


@dataclass(slots=True)
class Records:
    """What :func:`read_records` found besides the records: where and why it stopped."""

    truncated: str | None = None
    """Why reading stopped before the end of the file (a crash mid-write), or None."""
    lines: int = 0
    members: int = 0
    compressed_bytes: int = 0
    notes: list[str] = field(default_factory=list)


def _members(path: Path, info: Records) -> Iterator[bytes]:
    """The decompressed text of each complete gzip member of ``path``."""
    with open(path, "rb") as file:
        decompressor = zlib.decompressobj(31)
        parts: list[bytes] = []
        pending = b""
        while True:
            chunk = pending or file.read(_READ_CHUNK)
            pending = b""
            if not chunk:
                break
            info.compressed_bytes += len(chunk)
            try:
                parts.append(decompressor.decompress(chunk))
            except zlib.error as exc:
                info.truncated = f"a damaged gzip member after {info.members} complete ones ({exc})"
                return
            if decompressor.eof:
                info.members += 1
                yield b"".join(parts)
                parts = []
                pending = decompressor.unused_data
                info.compressed_bytes -= len(pending)
                decompressor = zlib.decompressobj(31)
        if parts or decompressor.unconsumed_tail:
            info.truncated = (
                f"the last gzip member is incomplete (the writer stopped mid-write after {info.members} "
                "complete members: a crash?); read up to the last complete flush"
            )


def read_records(path: Path | str, info: Records | None = None) -> Iterator[dict[str, Any]]:
    """Every line of the recording as a dict, header first; stops before an incomplete last member
    (``info.truncated`` says so). Raises :class:`RecordingError` for a file that is no recording, and for
    a line that is not what a recording holds, naming the file, the line and the field
    (:class:`RecordChecker`: a recording is input like any other, issue 36, finding 6)."""
    path = Path(path)
    info = info if info is not None else Records()
    first = True
    checker: RecordChecker | None = None
    rest = b""
    try:
        for text in _members(path, info):
            data = rest + text
            lines = data.split(b"\n")
            rest = lines.pop()
            if len(rest) > MAX_LINE_BYTES:
                raise RecordingError(f"{path}: a line longer than {MAX_LINE_BYTES} bytes")
            for raw in lines:
                if not raw:
                    continue
                try:
                    record = json.loads(raw)
                except ValueError as exc:
                    raise RecordingError(f"{path}: line {info.lines + 1} is not JSON: {exc}") from None
                if not isinstance(record, dict):
                    raise RecordingError(f"{path}: line {info.lines + 1} is not a JSON object")
                info.lines += 1
                if first:
                    _check_header(path, record)
                    checker = RecordChecker(path, record)
                    first = False
                elif checker is not None:
                    checker.check(info.lines, record)
                yield record
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if first:
        if info.truncated is not None:
            raise RecordingError(f"{path}: no complete header ({info.truncated})")
        raise RecordingError(f"{path}: empty: no recording header")
    if rest:
        info.notes.append(f"an unterminated last line ({len(rest)} bytes) was left out")


def read_header(path: Path | str) -> dict[str, Any]:
    """The header line alone."""
    for record in read_records(path):
        return record
    raise RecordingError(f"{path}: no recording header")  # pragma: no cover - read_records raises first


def check_recording(
    path: Path | str, each: Callable[[int, dict[str, Any]], str | None] | None = None
) -> tuple[dict[str, Any], Records, int]:
    """Read the whole recording once (every line checked): its header, what was read, and its last
    cycle. A replay does this first, so that a bad line anywhere is refused before the first cycle runs.
    ``each(line, record)`` checks more (the replay: what it will do with the line); a text it returns is
    the problem, raised as :class:`RecordingError` with the file and the line."""
    info = Records()
    records = read_records(path, info)
    header = next(records)
    last = 0
    for record in records:
        last = record["c"]
        problem = each(info.lines, record) if each is not None else None
        if problem is not None:
            raise RecordingError(f"{path}: line {info.lines}: {problem}")
    return header, info, last


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


class RecordChecker:
    """Checks each line after the header against it: the cycle (a whole number, in order, the whole within
    :data:`MAX_SPAN`), the kind of line, every field's type, every signal index against the header's lists
    and every value against its signal's type."""

    def __init__(self, path: Path, header: dict[str, Any]) -> None:
        self.path = path
        self.inputs = [str(kind) for _, kind in header["inputs"]]
        self.outputs = [str(kind) for _, kind in header["outputs"]]
        self.first: int | None = None
        self.last = 0
        self.line = 0
        announced = header.get("snapshot")
        self.snapshot_cycle: int | None = announced.get("cycle") if isinstance(announced, dict) else None
        self.snapshot_seen = False

    def fail(self, field: str, what: str) -> RecordingError:
        return RecordingError(f"{self.path}: line {self.line}: {field}: {what}")

    def check(self, line: int, record: dict[str, Any]) -> None:
        self.line = line
        cycle = record.get("c")
        if type(cycle) is not int or cycle < 0:
            raise self.fail("c", f"the cycle is a whole number >= 0, got {_short(cycle)}")
        if cycle < self.last:
            raise self.fail("c", f"cycle {cycle} after cycle {self.last}: a recording's lines are in order")
        if self.first is None:
            self.first = cycle
        if cycle - self.first > MAX_SPAN:
            raise self.fail(
                "c",
                f"cycle {cycle} lies {cycle - self.first} cycles after the first line's ({self.first}); a "
                f"recording spans at most {MAX_SPAN} cycles",
            )
        self.last = cycle
        if not any(kind in record for kind in _KINDS):
            raise self.fail("record", f"none of {', '.join(_KINDS)}: {_short(record)}")
        if "i" in record:
            self._changes("i", record["i"], self.inputs)
        if "o" in record:
            self._changes("o", record["o"], self.outputs)
        if "e" in record:
            self._events(record["e"])
        if "op" in record:
            self._text(record, "op")
            if not isinstance(record.get("args", {}), dict | None):
                raise self.fail("args", f"an object, got {_short(record.get('args'))}")
            self._text(record, "error", optional=True)
        for key in ("file", "program_file"):
            if key in record:
                self._text(record, key)
                self._text(record, "text", optional=True)
        if "program_file" in record:
            self._text(record, "found", optional=True)
            self._text(record, "origin", optional=True)
            searched = record.get("searched", [])
            if not isinstance(searched, list | None) or not all(isinstance(x, str) for x in searched or ()):
                raise self.fail("searched", f"a list of directories, got {_short(searched)}")
        if "fault" in record:
            if record["fault"] not in ("set", "end"):
                raise self.fail("fault", f"set or end, got {_short(record['fault'])}")
            if type(record.get("id")) is not int:
                raise self.fail("id", f"a fault's number, got {_short(record.get('id'))}")
            if record["fault"] == "set" and not isinstance(record.get("spec"), dict):
                raise self.fail("spec", f"the fault as an object, got {_short(record.get('spec'))}")
            self._text(record, "reason", optional=True)
        if "snapshot" in record:
            self._snapshot(record)
        if "end" in record:
            self._text(record, "end")

    def _snapshot(self, record: dict[str, Any]) -> None:
        """The line that holds the machine's state where the recording began (format 4): once, at the cycle
        before the header's window, its envelope of the shape :mod:`.snapshot` writes. What the objects
        hold is read as untrusted data by :func:`~hli_server.recording.snapshot.restore` (engine classes
        by name only, values by kind, nesting bounded) when the replay starts from it."""
        if self.snapshot_seen:
            raise self.fail("snapshot", "a second snapshot line (a recording holds one)")
        self.snapshot_seen = True
        if self.snapshot_cycle is None:
            raise self.fail("snapshot", "a snapshot line in a recording whose header announces none")
        if record["c"] != self.snapshot_cycle:
            raise self.fail(
                "c", f"the snapshot is of cycle {record['c']}, the header's of cycle {self.snapshot_cycle}"
            )
        state = record["snapshot"]
        if not isinstance(state, dict):
            raise self.fail("snapshot", f"the machine's state as an object, got {_short(state)}")
        if type(state.get("snapshot")) is not int:
            raise self.fail(
                "snapshot.snapshot", f"the snapshot's layout number, got {_short(state.get('snapshot'))}"
            )
        fingerprint = state.get("fingerprint")
        if not isinstance(fingerprint, str) or not _FINGERPRINT.fullmatch(fingerprint):
            raise self.fail(
                "snapshot.fingerprint", f"the engine's hash (hex digits), got {_short(fingerprint)}"
            )
        if type(state.get("cycle")) is not int or state["cycle"] != record["c"]:
            raise self.fail(
                "snapshot.cycle", f"the line's cycle {record['c']}, got {_short(state.get('cycle'))}"
            )
        root = state.get("root")
        if not isinstance(root, dict) or set(root) != {"r"} or type(root["r"]) is not int:
            raise self.fail("snapshot.root", f"a reference to the machine's object, got {_short(root)}")
        objects = state.get("objects")
        if not isinstance(objects, list) or not 0 <= root["r"] < len(objects):
            raise self.fail(
                "snapshot.objects", f"the list of objects the root's index lies in, got {_short(objects)}"
            )
        if not all(isinstance(entry, dict) for entry in objects):
            raise self.fail("snapshot.objects", "every object is a JSON object")
        self._changes("in", record.get("in"), self.inputs)
        external = record.get("external")
        if external is not None:
            if not isinstance(external, str):
                raise self.fail("external", f"the V.E. fields' bytes in base64, got {_short(external)}")
            try:
                base64.b64decode(external, validate=True)
            except (ValueError, binascii.Error):
                raise self.fail("external", "the V.E. fields' bytes are no base64") from None
        faults = record.get("faults", [])
        if not isinstance(faults, list) or not all(
            isinstance(f, dict) and type(f.get("id")) is int and isinstance(f.get("spec"), dict)
            for f in faults
        ):
            raise self.fail(
                "faults", f"the stall faults in effect as {{id, spec}} objects, got {_short(faults)}"
            )

    def _text(self, record: dict[str, Any], key: str, *, optional: bool = False) -> None:
        value = record.get(key)
        if not isinstance(value, str) and not (optional and value is None):
            raise self.fail(key, f"text, got {_short(value)}")

    def _changes(self, field: str, flat: object, kinds: list[str]) -> None:
        if not isinstance(flat, list) or len(flat) % 2:
            raise self.fail(field, f"pairs of a signal's index and its value, got {_short(flat)}")
        for k in range(0, len(flat), 2):
            index, value = flat[k], flat[k + 1]
            if type(index) is not int or not 0 <= index < len(kinds):
                raise self.fail(
                    field, f"signal index {_short(index)} is not one of the header's {len(kinds)} signals"
                )
            kind = kinds[index]
            if kind == "BOOL":
                ok = isinstance(value, bool) or value in (0, 1)
            elif kind.startswith("STRING"):
                ok = isinstance(value, list) and len(value) == 1 and isinstance(value[0], str)
            elif kind == "LREAL":
                ok = (isinstance(value, int | float) and not isinstance(value, bool)) or value in _NON_FINITE
            else:
                low, high = _RANGES.get(kind, (0, -1))
                ok = type(value) is int and low <= value <= high
            if not ok:
                raise self.fail(field, f"signal {index} is a {kind}, its value {_short(value)} is none")

    def _events(self, events: object) -> None:
        if not isinstance(events, list):
            raise self.fail("e", f"a list of events, got {_short(events)}")
        for event in events:
            if (
                not isinstance(event, dict)
                or not isinstance(event.get("kind"), str)
                or not isinstance(event.get("data", {}), dict)
            ):
                raise self.fail("e", f"an event is an object with its kind and data, got {_short(event)}")


def _check_header(path: Path, record: dict[str, Any]) -> None:
    if record.get("record") != "header" or record.get("format") != FORMAT:
        raise RecordingError(f"{path}: not an hli-server recording (its first line is no {FORMAT} header)")
    version = record.get("format_version")
    if not isinstance(version, int) or version < 1:
        raise RecordingError(f"{path}: the header has no valid format_version ({version!r})")
    if version > FORMAT_VERSION:
        raise RecordingError(
            f"{path}: recording format version {version} is newer than this hli-server reads "
            f"({FORMAT_VERSION}); replay it with the hli-server that made it ({record.get('server')})"
        )

    def bad(field: str, what: str) -> RecordingError:
        return RecordingError(f"{path}: line 1 (the header): {field}: {what}")

    for key in ("inputs", "outputs"):
        listed = record.get(key)
        if not isinstance(listed, list) or not all(
            isinstance(e, list) and len(e) >= 2 and isinstance(e[0], str) and _known_type(e[1])
            for e in listed
        ):
            raise bad(key, "a list of [ST path, type] (BOOL, DINT, UDINT, LREAL, STRING(n))")
    for key, low in (("t_a_us", 1), ("window_start", 0), ("outputs_every", 1)):
        value = record.get(key, low)
        if type(value) is not int or not low <= value <= 2**62:
            raise bad(key, f"a whole number >= {low}, got {_short(value)}")
    for key in ("server", "layout", "journal", "config"):
        if not isinstance(record.get(key, {}), dict):
            raise bad(key, f"an object, got {_short(record.get(key))}")
    snapshot = record.get("snapshot")
    if snapshot is not None and not (
        isinstance(snapshot, dict)
        and type(snapshot.get("cycle")) is int
        and snapshot["cycle"] == record.get("window_start", 1) - 1 >= 1
        and isinstance(snapshot.get("fingerprint"), str)
        and _FINGERPRINT.fullmatch(snapshot["fingerprint"]) is not None
    ):
        raise bad("snapshot", f"null or {{cycle: window_start - 1, fingerprint}}, got {_short(snapshot)}")
    if not isinstance(record.get("snapshot_note"), str | None):
        raise bad("snapshot_note", f"text, got {_short(record.get('snapshot_note'))}")
    follow = record.get("follow_cycle") or []
    if not isinstance(follow, list) or not all(
        type(k) is int and 0 <= k < len(record["outputs"]) for k in follow
    ):
        raise bad("follow_cycle", f"indices of the header's outputs, got {_short(follow)}")
