"""The binary format of the shared-memory process image and its consistency protocol (H-01).

Both sides import this module: the server (``hli_server/image``) writes the image, a PLC-side
client (``plc_clients/shm.py``) attaches to it. The field layout of the halves comes from
:mod:`schemas.layout`; this module adds the header, the placement of the halves in the segment
and the read side of the protocol. ``docs/process-image.md`` describes the same in prose.

Segment (all integers little-endian; the image is only supported on little-endian hosts)::

    0      header (128 bytes, :data:`HEADER`)
    128    layout JSON (UTF-8, compact; the contract, :meth:`schemas.layout.Layout.to_json`)
    p2c    PLC->CNC half (64-byte aligned)
    c2p0   CNC->PLC buffer 0: seq u64 | cycle u64 | half        (64-byte aligned)
    c2p1   CNC->PLC buffer 1: seq u64 | cycle u64 | half        (64-byte aligned)

Header::

    off size field
      0   8  magic               b"HLI-IMG\\0"   (written last: a segment without it is not ready)
      8   4  format_version      FORMAT_VERSION (this header and protocol)
     12   4  layout_version      schemas.layout.LAYOUT_VERSION
     16  32  layout_hash         SHA-256 digest (raw bytes) of the layout, see Layout.hash
     48   4  header_size         128
     52   4  total_size          bytes of the segment the server uses
     56   4  layout_json_offset
     60   4  layout_json_size
     64   4  p2c_offset
     68   4  p2c_size
     72   4  c2p_offset_0        offset of buffer 0 (its seq word)
     76   4  c2p_offset_1
     80   4  c2p_size            bytes of the half in each buffer (without the 16-byte buffer header)
     84   4  flags               FLAG_CLOSED when the server has shut down
     88   8  publish_count       number of completed publishes; the newest is in buffer count & 1
     96   8  cycle               cycle of the newest publish (for information;
                                 the consistent one is in the buffer)
    104   4  server_pid
    108   8  server_start        start time of the server process (clock ticks since boot, 0 unknown)
    116   8  server_pid_ns       inode of the server's PID namespace (0 unknown)
    124   4  reserved

``server_pid`` with ``server_start`` names the very process that wrote the image: a PID the kernel
has since given to another process has another start time, so a restarted server can tell its
crashed predecessor's segment from the image of a live server (H-01; reliability.md, round 1, finding 7). The
PID namespace says whether the PID means anything here (another container's PIDs do not).

Consistency:

* **CNC->PLC: double buffer, each buffer guarded by a sequence counter (seqlock).** Publish number
  ``k`` goes to buffer ``k & 1``: the writer makes that buffer's ``seq`` odd, copies the packed half
  (and its cycle) in with one memcpy, makes ``seq`` even again and then sets ``publish_count = k``.
  A reader takes buffer ``publish_count & 1``, reads ``seq``, copies the buffer, reads ``seq`` again
  and accepts the copy only if both are equal and even; otherwise it tries the other buffer (which
  holds the publish before), and retries. The writer only ever writes the buffer that is not the
  newest, so a reader has a whole cycle to copy and never waits for the writer.
* **PLC->CNC: single-field writes.** Every field is naturally aligned and written with one store of
  its size (``struct`` native formats, which copy with one ``memcpy`` of 1/4/8 bytes); the server
  copies the whole half with one memcpy per cycle and decodes the copy. A PLC that wants two fields
  to take effect together writes the one that arms the other last (``command_w`` before ``enable_w``).

The 8-byte counters are written and read with single aligned 8-byte accesses (native ``Q``).
Store order is that of the program on x86-64 (TSO); on weakly ordered CPUs the protocol relies on
the same order, which CPython does not formally guarantee (see the docs).
"""

from __future__ import annotations

import struct
import sys
import threading
import time
from collections.abc import Sized
from dataclasses import dataclass
from multiprocessing import resource_tracker, shared_memory
from typing import Final

from schemas.layout import (
    LAYOUT_VERSION,
    STRING_ENCODING,
    Direction,
    Layout,
    LayoutError,
    Signal,
    SignalType,
    SignalValueError,
)

__all__ = [
    "C2P_BUFFER_HEADER",
    "FLAG_CLOSED",
    "FORMAT_VERSION",
    "HEADER",
    "HEADER_SIZE",
    "MAGIC",
    "OFF_CYCLE",
    "OFF_FLAGS",
    "OFF_MAGIC",
    "OFF_PUBLISH_COUNT",
    "AttachedSegment",
    "ImageBusyError",
    "ImageError",
    "ImageHeader",
    "ImageMismatchError",
    "ImageNotReadyError",
    "SegmentPlan",
    "attach_segment",
    "attach_untracked",
    "check_host",
    "check_layout",
    "check_segment",
    "decode_field",
    "header_construct",
    "plan_segment",
    "read_c2p",
    "read_c2p_field",
    "read_field",
    "read_header",
    "read_u64",
    "write_field",
    "write_p2c_bytes",
    "write_u64",
]

MAGIC: Final = b"HLI-IMG\x00"
FORMAT_VERSION: Final = 1
HEADER_SIZE: Final = 128
HEADER: Final = struct.Struct("<8sII32sIIIIIIIIIIQQIQQ4x")
"""The header as one ``struct`` (field order as in the module docstring)."""

OFF_MAGIC: Final = 0
OFF_FLAGS: Final = 84
OFF_PUBLISH_COUNT: Final = 88
OFF_CYCLE: Final = 96
C2P_BUFFER_HEADER: Final = 16
"""seq u64 + cycle u64 in front of each CNC->PLC buffer."""
FLAG_CLOSED: Final = 0x1

_ALIGN: Final = 64
_U64: Final = struct.Struct("@Q")
"""Native 8-byte access: CPython copies it with one memcpy of 8 bytes (a single load/store)."""
_NATIVE: Final[dict[SignalType, struct.Struct]] = {
    t: struct.Struct("@" + t.struct_char) for t in SignalType if t is not SignalType.STRING
}
"""Single-store access per type (1, 2, 4 or 8 bytes). A STRING field is copied byte by byte (no single
store: a reader may see a string half written, docs/process-image.md)."""

if HEADER.size != HEADER_SIZE:  # pragma: no cover - a typo in the format
    raise RuntimeError(f"header format is {HEADER.size} bytes, expected {HEADER_SIZE}")


class ImageError(RuntimeError):
    """Base of the process image's errors."""


class ImageNotReadyError(ImageError):
    """The segment exists but the server has not finished writing its header."""


class ImageMismatchError(ImageError):
    """The segment is not an image, or its format/layout differs from what the reader expects."""


class ImageBusyError(ImageError):
    """No consistent CNC->PLC snapshot could be taken in time (the writer is stuck or too fast)."""


def check_host() -> None:
    """The image is little-endian and relies on native single stores having that byte order."""
    if sys.byteorder != "little":  # pragma: no cover - no big-endian CI
        raise ImageError("the process image needs a little-endian host (x86-64, aarch64)")


def header_construct() -> object:
    """The header as a ``construct.Struct`` (documentation and tests; the hot path uses HEADER)."""
    import construct as cs

    return cs.Struct(
        "magic" / cs.Bytes(8),
        "format_version" / cs.Int32ul,
        "layout_version" / cs.Int32ul,
        "layout_hash" / cs.Bytes(32),
        "header_size" / cs.Int32ul,
        "total_size" / cs.Int32ul,
        "layout_json_offset" / cs.Int32ul,
        "layout_json_size" / cs.Int32ul,
        "p2c_offset" / cs.Int32ul,
        "p2c_size" / cs.Int32ul,
        "c2p_offset_0" / cs.Int32ul,
        "c2p_offset_1" / cs.Int32ul,
        "c2p_size" / cs.Int32ul,
        "flags" / cs.Int32ul,
        "publish_count" / cs.Int64ul,
        "cycle" / cs.Int64ul,
        "server_pid" / cs.Int32ul,
        "server_start" / cs.Int64ul,
        "server_pid_ns" / cs.Int64ul,
        cs.Padding(4),
    )


@dataclass(frozen=True, slots=True)
class SegmentPlan:
    """Where everything lies in the segment."""

    layout_json_offset: int
    layout_json_size: int
    p2c_offset: int
    p2c_size: int
    c2p_offsets: tuple[int, int]
    c2p_size: int
    total_size: int

    def c2p_data_offset(self, buffer: int) -> int:
        return self.c2p_offsets[buffer] + C2P_BUFFER_HEADER


def _align(value: int) -> int:
    return -(-value // _ALIGN) * _ALIGN


def plan_segment(layout_json_size: int, p2c_size: int, c2p_size: int) -> SegmentPlan:
    """Place the layout JSON and the halves; halves and buffers start on 64-byte cache lines."""
    p2c = _align(HEADER_SIZE + layout_json_size)
    c2p0 = _align(p2c + p2c_size)
    c2p1 = _align(c2p0 + C2P_BUFFER_HEADER + c2p_size)
    total = _align(c2p1 + C2P_BUFFER_HEADER + c2p_size)
    return SegmentPlan(HEADER_SIZE, layout_json_size, p2c, p2c_size, (c2p0, c2p1), c2p_size, total)


@dataclass(frozen=True, slots=True)
class ImageHeader:
    magic: bytes
    format_version: int
    layout_version: int
    layout_hash: str
    """hex"""
    header_size: int
    total_size: int
    plan: SegmentPlan
    flags: int
    publish_count: int
    cycle: int
    server_pid: int
    server_start: int = 0
    """Start time of the server process in clock ticks since boot (``/proc/<pid>/stat``); 0 unknown."""
    server_pid_ns: int = 0
    """Inode of the server's PID namespace (``/proc/<pid>/ns/pid``); 0 unknown."""

    @property
    def closed(self) -> bool:
        return bool(self.flags & FLAG_CLOSED)

    def pack(self) -> bytes:
        p = self.plan
        return HEADER.pack(
            self.magic,
            self.format_version,
            self.layout_version,
            bytes.fromhex(self.layout_hash),
            self.header_size,
            self.total_size,
            p.layout_json_offset,
            p.layout_json_size,
            p.p2c_offset,
            p.p2c_size,
            p.c2p_offsets[0],
            p.c2p_offsets[1],
            p.c2p_size,
            self.flags,
            self.publish_count,
            self.cycle,
            self.server_pid,
            self.server_start,
            self.server_pid_ns,
        )


def read_header(
    buf: memoryview | bytes, name: str = "?", *, segment_size: int | None = None, unready_ok: bool = False
) -> ImageHeader:
    """Decode and check the header: magic, format version and that the offsets fit the segment.

    The layout version and hash are checked by the caller, which knows what it expects. With
    ``unready_ok`` a header whose magic is not written yet (a server that is starting, or that died
    while starting) is decoded too, when everything else in it is an image's; the server uses that
    to judge a segment that is in the way of its own (H-01).
    """
    if len(buf) < HEADER_SIZE:
        raise ImageMismatchError(
            f"shared memory {name!r} is {len(buf)} bytes, smaller than an image header: not an HLI image"
        )
    raw = HEADER.unpack_from(buf, 0)
    magic = raw[0]
    if magic != MAGIC and not (unready_ok and magic == b"\x00" * 8):
        if magic == b"\x00" * 8:
            raise ImageNotReadyError(
                f"shared memory {name!r} has no image header yet: the server is still starting; retry"
            )
        raise ImageMismatchError(
            f"shared memory {name!r} is not an HLI process image (magic {magic!r}, expected {MAGIC!r})"
        )
    if raw[1] != FORMAT_VERSION:
        raise ImageMismatchError(
            f"image {name!r} has format version {raw[1]}, this code reads {FORMAT_VERSION}: "
            "use a client from the same release as the server"
        )
    plan = SegmentPlan(raw[6], raw[7], raw[8], raw[9], (raw[10], raw[11]), raw[12], raw[5])
    header = ImageHeader(
        magic=magic,
        format_version=raw[1],
        layout_version=raw[2],
        layout_hash=raw[3].hex(),
        header_size=raw[4],
        total_size=raw[5],
        plan=plan,
        flags=raw[13],
        publish_count=raw[14],
        cycle=raw[15],
        server_pid=raw[16],
        server_start=raw[17],
        server_pid_ns=raw[18],
    )
    size = len(buf) if segment_size is None else segment_size
    ends = (
        plan.layout_json_offset + plan.layout_json_size,
        plan.p2c_offset + plan.p2c_size,
        plan.c2p_offsets[0] + C2P_BUFFER_HEADER + plan.c2p_size,
        plan.c2p_offsets[1] + C2P_BUFFER_HEADER + plan.c2p_size,
        header.total_size,
    )
    if header.header_size != HEADER_SIZE or max(ends) > size:
        raise ImageMismatchError(f"image {name!r}: header offsets do not fit the segment ({size} bytes)")
    return header


def check_layout(header: ImageHeader, name: str, expected_hash: str | None) -> None:
    """Layout version must be this code's; the hash must be the expected one when one is given."""
    if header.layout_version != LAYOUT_VERSION:
        raise ImageMismatchError(
            f"image {name!r} has layout version {header.layout_version}, this client knows "
            f"{LAYOUT_VERSION}: use a client from the same release as the server"
        )
    if expected_hash is not None and header.layout_hash != expected_hash:
        raise ImageMismatchError(
            f"image {name!r} has layout hash {header.layout_hash[:16]}..., expected "
            f"{expected_hash[:16]}...: the server runs another machine configuration. Load the same "
            "configuration, or attach without an expected layout to use the server's"
        )


# --------------------------------------------------------------------------------------------
# Reading and writing (both sides)
# --------------------------------------------------------------------------------------------


def read_u64(buf: memoryview, offset: int) -> int:
    value: int = _U64.unpack_from(buf, offset)[0]
    return value


def write_u64(buf: memoryview, offset: int, value: int) -> None:
    _U64.pack_into(buf, offset, value)


def write_field(buf: memoryview, half_offset: int, signal: Signal, value: bool | int | float | str) -> None:
    """One store of the field's size (PLC->CNC single-field write). ``value`` must be coerced. A STRING
    is copied with NUL after its last character to the end of its field."""
    if isinstance(value, str):
        start = half_offset + signal.offset
        buf[start : start + signal.size] = value.encode(STRING_ENCODING).ljust(signal.size, b"\0")
        return
    _NATIVE[signal.type].pack_into(buf, half_offset + signal.offset, value)


def write_p2c_bytes(buf: memoryview, plan: SegmentPlan, layout: Layout, offset: int, data: bytes) -> None:
    """A raw write into the PLC->CNC half (ADS's index group of the half): whole fields only, every value
    checked before any is written (a refused write changes nothing); padding bytes in the range are
    ignored. Raises the layout's errors (SignalValueError, a range that cuts a field)."""
    signals = layout.signals_in_range(Direction.PLC_TO_CNC, offset, len(data))
    values: list[tuple[Signal, bool | int | float | str]] = []
    for s in signals:
        raw = data[s.offset - offset : s.offset - offset + s.size]
        values.append((s, s.coerce(decode_field(s, raw))))
    for s, v in values:
        write_field(buf, plan.p2c_offset, s, v)


def decode_field(signal: Signal, raw: bytes) -> bool | int | float | str:
    """A field's value from its bytes as a PLC wrote them; :class:`SignalValueError` for bytes no value
    has: a BOOL byte other than 0/1, a STRING without its NUL or with a byte that is no Windows-1252
    character (the value's range is :meth:`Signal.coerce`'s)."""
    if signal.type is SignalType.BOOL:
        if raw[0] > 1:
            raise SignalValueError(f"{signal.st_path}: BOOL byte must be 0 or 1, got {raw[0]}")
        return bool(raw[0])
    if signal.type is SignalType.STRING:  # its bytes up to the NUL (a write may give fewer than the field)
        return signal.decode(bytes(raw))
    return signal.decode(struct.unpack("<" + signal.struct_char, raw)[0])


def read_field(buf: memoryview, half_offset: int, signal: Signal) -> bool | int | float | str:
    """One load of the field's size (a STRING: its bytes up to the first NUL, as text)."""
    if signal.string_size:
        start = half_offset + signal.offset
        raw = bytes(buf[start : start + signal.size])
        text = raw.partition(b"\0")[0]
        return text.decode(STRING_ENCODING, "replace")
    value: bool | int | float = _NATIVE[signal.type].unpack_from(buf, half_offset + signal.offset)[0]
    return value


_RETRY_LIMIT: Final = 100_000
_RETRY_SECONDS: Final = 0.5


def read_c2p(buf: memoryview, plan: SegmentPlan, name: str = "?") -> tuple[int, bytes]:
    """A consistent copy of the CNC->PLC half: ``(cycle, half bytes)``.

    Before the first publish both buffers are zeros (cycle 0). Raises
    :class:`ImageBusyError` when no consistent copy could be taken within half a second.
    """
    size = plan.c2p_size
    deadline = 0.0
    for attempt in range(_RETRY_LIMIT):
        newest = read_u64(buf, OFF_PUBLISH_COUNT) & 1
        for b in (newest, newest ^ 1):
            base = plan.c2p_offsets[b]
            seq = read_u64(buf, base)
            if seq & 1:
                continue  # being written: the other buffer holds the publish before
            data = bytes(buf[base + 8 : base + C2P_BUFFER_HEADER + size])
            if read_u64(buf, base) == seq:
                cycle: int = _U64.unpack_from(data, 0)[0]
                return cycle, data[8:]
        if attempt == 100:
            deadline = time.monotonic() + _RETRY_SECONDS
        elif attempt > 100 and time.monotonic() > deadline:
            break
    raise ImageBusyError(
        f"image {name!r}: no consistent CNC->PLC snapshot within {_RETRY_SECONDS} s; "
        "is the server stuck in a publish?"
    )


def read_c2p_field(
    buf: memoryview, plan: SegmentPlan, signal: Signal, name: str = "?"
) -> bool | int | float | str:
    """One CNC->PLC field, consistent with the cycle it was published in (seqlock-protected)."""
    for _ in range(_RETRY_LIMIT):
        newest = read_u64(buf, OFF_PUBLISH_COUNT) & 1
        for b in (newest, newest ^ 1):
            base = plan.c2p_offsets[b]
            seq = read_u64(buf, base)
            if seq & 1:
                continue
            value = read_field(buf, base + C2P_BUFFER_HEADER, signal)
            if read_u64(buf, base) == seq:
                return value
    raise ImageBusyError(f"image {name!r}: no consistent read of {signal.st_path}; is the server stuck?")


_TRACKER_LOCK = threading.Lock()


def attach_untracked(name: str) -> shared_memory.SharedMemory:
    """Map an existing segment without registering it with the resource tracker.

    Python < 3.13 registers every ``SharedMemory`` it opens, and the tracker unlinks (and warns
    about) registered segments when the process ends: an attaching client would remove the
    server's image. 3.13 has ``track=False``; before that the registration is skipped here.
    """
    plain = name.removeprefix("/")
    if sys.version_info >= (3, 13):  # pragma: no cover - the project runs 3.11
        return shared_memory.SharedMemory(name=plain, create=False, track=False)  # type: ignore[call-arg]
    with _TRACKER_LOCK:
        original = resource_tracker.register

        def _skip_shared_memory(name: Sized, rtype: str) -> None:
            if rtype != "shared_memory":
                original(name, rtype)

        resource_tracker.register = _skip_shared_memory
        try:
            return shared_memory.SharedMemory(name=plain, create=False)
        finally:
            resource_tracker.register = original


def check_segment(
    buf: memoryview, name: str, size: int, expected_hash: str | None
) -> tuple[ImageHeader, Layout]:
    """The header and the layout stored in a segment, checked against each other (and against
    ``expected_hash``, the layout the caller was built for, when given)."""
    header = read_header(buf, name, segment_size=size)
    check_layout(header, name, expected_hash)
    plan = header.plan
    raw = bytes(buf[plan.layout_json_offset : plan.layout_json_offset + plan.layout_json_size])
    try:
        layout = Layout.from_json(raw)
    except LayoutError as exc:
        raise ImageMismatchError(f"image {name!r}: the stored layout is damaged: {exc}") from exc
    if layout.hash != header.layout_hash:
        raise ImageMismatchError(
            f"image {name!r}: header hash {header.layout_hash[:16]}... does not match the stored "
            f"layout ({layout.hash[:16]}...): the segment is damaged; restart the server"
        )
    if layout.p2c_size != plan.p2c_size or layout.c2p_size != plan.c2p_size:
        raise ImageMismatchError(f"image {name!r}: half sizes in the header differ from the layout")
    return header, layout


@dataclass(frozen=True, slots=True)
class AttachedSegment:
    """An image another process created, mapped by name and checked: what a PLC client and the server's
    doors process both attach. ``close`` unmaps it (never unlinks: the creator owns the segment)."""

    shm: shared_memory.SharedMemory
    buf: memoryview
    header: ImageHeader
    layout: Layout
    name: str

    def close(self) -> None:
        self.shm.close()


def _attach_once(name: str, expected_hash: str | None) -> AttachedSegment:
    shm = attach_untracked(name)
    try:
        buf = shm.buf
        assert buf is not None
        header, layout = check_segment(buf, name, shm.size, expected_hash)
        return AttachedSegment(shm, buf, header, layout, shm.name.removeprefix("/"))
    except BaseException:
        shm.close()
        raise


def attach_segment(name: str, *, expected_hash: str | None = None, timeout: float = 0.0) -> AttachedSegment:
    """Attach image ``name``: keep trying ``timeout`` seconds while the segment does not exist yet or its
    creator is still writing the header. A layout other than ``expected_hash`` raises
    :class:`ImageMismatchError`."""
    check_host()
    deadline = time.monotonic() + timeout
    while True:
        try:
            return _attach_once(name, expected_hash)
        except (FileNotFoundError, ImageNotReadyError) as exc:
            if time.monotonic() >= deadline:
                if isinstance(exc, FileNotFoundError):
                    raise FileNotFoundError(
                        f"no shared memory {name!r}: is the server running, and with this image name? "
                        "(`hli-server run` prints it)"
                    ) from None
                raise
            time.sleep(0.01)
