"""The process image, server side: in POSIX shared memory, or in a plain buffer (H-01, H-02).

The server creates the segment, writes the header and the layout JSON, and then, once per cycle,

1. :meth:`ProcessImage.latch_into` copies the PLC->CNC half with one memcpy and assigns the decoded
   values to the engine's HLI objects;
2. the runtime steps the engine;
3. :meth:`ProcessImage.publish_from` packs the CNC->PLC fields of the engine objects into a private
   buffer and publishes it through the double-buffered seqlock of :mod:`schemas.image_format`.

The protocol adapters (Modbus, ADS) are PLC doors into the same image: :meth:`ProcessImage.write`
writes one PLC->CNC field with a single store and refuses CNC->PLC fields (H-02);
:meth:`ProcessImage.read` and :meth:`ProcessImage.snapshot` read. The segment is unlinked by
:meth:`ProcessImage.close` (and, if the server dies, by the resource tracker of the server process).

A segment of the wanted name that exists already (H-01; reliability.md, round 1, finding 7) is replaced only
when it is provably a stale HLI image: it has an image header, and the process that wrote it is gone. The
header records that process as PID *and* start time (``/proc/<pid>/stat``, clock ticks since boot):
a PID the kernel has since handed to another process has another start time, so a crashed server's
segment is replaced even when its PID is alive again. The start time beats reading
``/proc/<pid>/cmdline``: it names the very process, not a program, so it holds for a server started
as ``python -m``, inside pytest, or several servers on one host. A segment without an image header
belongs to another program and is never touched; neither is one whose writer cannot be judged (a PID
of another PID namespace, i.e. another container sharing /dev/shm). Without /proc (not Linux) the
start time is 0 and a live PID counts as a running server, as before.

Where the bytes live is the only difference between the two kinds (the format, the seqlock and
every method are the same code):

* :meth:`ProcessImage.create`: a POSIX shared-memory segment ``/dev/shm/NAME`` that another process
  maps by name (``hli-server run``, the default);
* :meth:`ProcessImage.in_memory`: a ``bytearray`` of the same format, for a server that runs inside
  the process of its PLC (the pytest harness, H-07): it needs no ``/dev/shm``, so it runs where shared
  memory is restricted (containers, sandboxes), and it cannot leak a segment. A PLC in the same
  process attaches with ``plc_clients.ImageClient.over(image.buffer)``.

:meth:`ProcessImage.recorder` samples chosen signals of every publish (per-cycle traces, H-07).
"""

from __future__ import annotations

import functools
import logging
import operator
import os
import re
import secrets
import struct
from collections.abc import Callable, Iterable
from multiprocessing import shared_memory
from pathlib import Path
from types import TracebackType
from typing import Any, Final

from hli_server.engine.external import ExternalVariables
from hli_server.engine.hli import MachineHli
from hli_server.image.external import ExternalSync
from hli_server.image.projection import Projection, compile_projection, diagnose
from schemas import image_format as fmt
from schemas.layout import STRING_ENCODING, Direction, Layout, Signal, SignalType, SignalValueError

__all__ = [
    "IMAGE_NAME_PREFIX",
    "ProcessImage",
    "SignalRecorder",
    "default_image_name",
    "open_image_names",
    "pid_namespace",
    "process_start_ticks",
]

log = logging.getLogger(__name__)

IMAGE_NAME_PREFIX: Final = "hli_"
"""Default names start with this (``/dev/shm/hli_...`` on Linux)."""

_NAME_RE: Final = re.compile(r"^[A-Za-z0-9_.-]{1,200}$")
_PUBLISH_COUNT_OF: Final = operator.attrgetter("_publish_count")
"""``image._publish_count`` without a Python frame (:meth:`ProcessImage.publish_counter`)."""
_P2C: Final = Direction.PLC_TO_CNC
_C2P: Final = Direction.CNC_TO_PLC

_open_images: dict[str, ProcessImage] = {}
"""Images this process created and has not closed yet (the test suite checks for leaks)."""


def open_image_names() -> frozenset[str]:
    """Names of the images this process created and has not closed."""
    return frozenset(_open_images)


def default_image_name() -> str:
    """``hli_<pid>_<random>``: unique per server process."""
    return f"{IMAGE_NAME_PREFIX}{os.getpid()}_{secrets.token_hex(3)}"


def _check_name(name: str) -> str:
    plain = name.removeprefix("/")
    if not _NAME_RE.match(plain):
        raise ValueError(
            f"image name {name!r}: use 1..200 characters of A-Z a-z 0-9 _ . - (no '/'); "
            f"e.g. {IMAGE_NAME_PREFIX}demo"
        )
    return plain


def _buffer(shm: shared_memory.SharedMemory) -> memoryview:
    buf = shm.buf
    if buf is None:  # pragma: no cover - only after close()
        raise ValueError(f"shared memory {shm.name!r} is closed")
    return buf


def _server_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def process_start_ticks(pid: int) -> int:
    """Start time of process ``pid`` in clock ticks since boot (``/proc/<pid>/stat`` field 22);
    0 when it cannot be read (no such process, no /proc)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_bytes()
    except OSError:
        return 0
    # "pid (comm) state ppid ...": comm may hold blanks and parentheses; the fields after the last
    # ")" start with field 3 (state), so starttime (field 22) is the 20th of them
    fields = stat.rpartition(b")")[2].split()
    try:
        return int(fields[19])
    except (IndexError, ValueError):  # pragma: no cover - a kernel with another stat format
        return 0


def pid_namespace(pid: int | str = "self") -> int:
    """Inode of the PID namespace of ``pid`` (default: this process); 0 when unknown."""
    try:
        return os.stat(f"/proc/{pid}/ns/pid").st_ino
    except OSError:
        return 0


def _writer_state(header: fmt.ImageHeader) -> str:
    """``"gone"``, ``"alive"`` or ``"foreign"`` (cannot be judged): is the process that wrote the
    header still running? See the module docstring for why the start time decides."""
    ours = pid_namespace()
    if header.server_pid_ns and ours and header.server_pid_ns != ours:
        return "foreign"
    if not _server_alive(header.server_pid):
        return "gone"
    if header.server_start:
        now = process_start_ticks(header.server_pid)
        if now and now != header.server_start:
            return "gone"  # the PID was given to another process since
    return "alive"


class ProcessImage:
    """The server's handle on the image. Create with :meth:`create` (shared memory) or
    :meth:`in_memory` (a buffer in this process)."""

    def __init__(
        self,
        buffer: memoryview,
        layout: Layout,
        plan: fmt.SegmentPlan,
        *,
        name: str,
        shm: shared_memory.SharedMemory | None = None,
    ) -> None:
        self._shm = shm
        self._buf = buffer
        self.name: str = name
        self.layout = layout
        self.plan = plan
        self._projection: Projection = compile_projection(layout)
        self._p2c_struct = _field_struct(list(layout.hli_half(_P2C)))
        self._external = ExternalSync(layout, plan.p2c_offset) if layout.external_signals else None
        self._c2p_struct = struct.Struct("<Q" + layout.struct_format(_C2P).removeprefix("<"))
        self._c2p_private = bytearray(self._c2p_struct.size)
        self._latched: bytes | None = None
        self._latched_for: MachineHli | None = None
        """The PLC->CNC half last assigned to the engine's ``_w`` fields, and whose fields: a latch of the
        same bytes into the same engine assigns nothing (only the projection writes ``_w`` fields)."""
        self._seq = [0, 0]
        self._publish_count = 0
        self._cycle = 0
        self._closed = False

    # --- life cycle ----------------------------------------------------------------------
    @classmethod
    def create(cls, layout: Layout, name: str | None = None, *, replace_stale: bool = False) -> ProcessImage:
        """Create the segment ``name`` (default :func:`default_image_name`) for ``layout``.

        An existing segment of that name is an error, unless ``replace_stale`` is set and the
        segment is the image of a server that is gone (it is then unlinked and made anew). A segment
        that is no HLI image, or the image of a running server, is never touched (FileExistsError
        that names the segment and says what to do; see the module docstring).
        """
        fmt.check_host()
        plain = _check_name(name or default_image_name())
        layout_json = layout.to_json(indent=None).encode("utf-8")
        plan = fmt.plan_segment(len(layout_json), layout.p2c_size, layout.c2p_size)
        try:
            shm = shared_memory.SharedMemory(name=plain, create=True, size=plan.total_size)
        except FileExistsError:
            if not replace_stale:
                raise FileExistsError(
                    f"shared memory {plain!r} exists already: another server is running with this "
                    f"image name, or one crashed. Choose another name, or remove /dev/shm/{plain} "
                    "if no server uses it (the runtime's replace_stale option does that)"
                ) from None
            cls._remove_stale(plain)
            shm = shared_memory.SharedMemory(name=plain, create=True, size=plan.total_size)
        image = cls(_buffer(shm), layout, plan, name=shm.name.removeprefix("/"), shm=shm)
        return image._ready(layout_json)

    @classmethod
    def in_memory(cls, layout: Layout, name: str | None = None) -> ProcessImage:
        """The same image in a ``bytearray`` of this process: no ``/dev/shm``, nothing to unlink.

        ``name`` only names it in logs and reports (default :func:`default_image_name`). A PLC in
        this process attaches with ``ImageClient.over(image.buffer)`` (the pytest harness does).
        """
        fmt.check_host()
        plain = _check_name(name or default_image_name())
        layout_json = layout.to_json(indent=None).encode("utf-8")
        plan = fmt.plan_segment(len(layout_json), layout.p2c_size, layout.c2p_size)
        image = cls(memoryview(bytearray(plan.total_size)), layout, plan, name=plain)
        return image._ready(layout_json)

    def _ready(self, layout_json: bytes) -> ProcessImage:
        try:
            self._write_header(layout_json)
        except BaseException:
            self.close()
            raise
        _open_images[self.name] = self
        log.info(
            "process image %s created in %s: %d bytes (PLC->CNC %d, CNC->PLC %d), layout %s",
            self.name,
            self.backing,
            self.plan.total_size,
            self.layout.p2c_size,
            self.layout.c2p_size,
            self.layout.hash[:12],
        )
        return self

    @property
    def backing(self) -> str:
        """``shared memory`` (``/dev/shm/NAME``) or ``memory`` (a buffer of this process)."""
        return "shared memory" if self._shm is not None else "memory"

    @property
    def buffer(self) -> memoryview:
        """The whole segment (header, layout, halves): what a PLC in this process attaches to
        (``ImageClient.over``). Valid until :meth:`close`."""
        return self._buf

    @staticmethod
    def _remove_stale(name: str) -> None:
        # look without registering with the resource tracker: a tracked mapping would be unlinked
        # when this process ends, even when it belongs to a running server and is left alone
        try:
            old = fmt.attach_untracked(name)
        except PermissionError:
            raise FileExistsError(
                f"shared memory {name!r} exists and this user may not open it: it is not ours. Choose "
                "another image name (--image-name)"
            ) from None
        try:
            buf = _buffer(old)
            try:
                header = fmt.read_header(buf, name, segment_size=len(buf), unready_ok=True)
            except fmt.ImageError:
                raise FileExistsError(
                    f"shared memory {name!r} exists and is not an HLI process image (no image header): "
                    "it belongs to another program and is left alone. Choose another image name "
                    f"(--image-name), or remove /dev/shm/{name} yourself if you know it is unused"
                ) from None
            writer = "gone" if header.closed else _writer_state(header)
            if writer == "alive":
                raise FileExistsError(
                    f"shared memory {name!r} is the image of the running server pid {header.server_pid}: "
                    "stop that server or choose another image name"
                )
            if writer == "foreign":
                raise FileExistsError(
                    f"shared memory {name!r} is the image of a server in another PID namespace (pid "
                    f"{header.server_pid} there; a container sharing /dev/shm): whether it runs cannot be "
                    f"told from here. Choose another image name, or remove /dev/shm/{name} once that "
                    "server is stopped"
                )
        finally:
            old.close()
        log.warning(
            "replacing the stale process image %s (its server pid %d is gone%s)",
            name,
            header.server_pid,
            "; the image was closed" if header.closed else "",
        )
        stale = shared_memory.SharedMemory(name=name, create=False)
        stale.close()
        stale.unlink()

    def _write_header(self, layout_json: bytes) -> None:
        plan = self.plan
        buf = self._buf
        buf[plan.layout_json_offset : plan.layout_json_offset + len(layout_json)] = layout_json
        header = fmt.ImageHeader(
            magic=b"\x00" * 8,
            format_version=fmt.FORMAT_VERSION,
            layout_version=self.layout.version,
            layout_hash=self.layout.hash,
            header_size=fmt.HEADER_SIZE,
            total_size=plan.total_size,
            plan=plan,
            flags=0,
            publish_count=0,
            cycle=0,
            server_pid=os.getpid(),
            server_start=process_start_ticks(os.getpid()),
            server_pid_ns=pid_namespace(),
        )
        buf[: fmt.HEADER_SIZE] = header.pack()
        buf[fmt.OFF_MAGIC : fmt.OFF_MAGIC + 8] = fmt.MAGIC  # last: the image is ready

    def close(self) -> None:
        """Mark the image closed for attached clients, unmap it and unlink it. Idempotent.

        A buffer-backed image keeps its bytes for the clients still attached (they see the
        closed flag, as they do on shared memory); the server's own view is released."""
        if self._closed:
            return
        self._closed = True
        _open_images.pop(self.name, None)
        try:
            flags = struct.unpack_from("<I", self._buf, fmt.OFF_FLAGS)[0]
            struct.pack_into("<I", self._buf, fmt.OFF_FLAGS, flags | fmt.FLAG_CLOSED)
        except (ValueError, TypeError):  # pragma: no cover - buffer already released
            pass
        if self._shm is None:
            self._buf.release()  # later use raises "released memoryview", as with shared memory
            log.info("process image %s (memory) closed", self.name)
            return
        self._shm.close()  # releases self._buf: later use raises "released memoryview"
        try:
            self._shm.unlink()
        except FileNotFoundError:
            log.warning("process image %s was already unlinked by someone else", self.name)
        log.info("process image %s closed and unlinked", self.name)

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self) -> ProcessImage:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else f"cycle {self._cycle}"
        return f"ProcessImage({self.name!r}, {self.backing}, {self.plan.total_size} bytes, {state})"

    # --- the cycle ---------------------------------------------------------------------------
    def latch_into(self, machine: MachineHli) -> bytes:
        """Copy the PLC->CNC half (one memcpy) and assign it to the engine's ``_w`` fields; returns the
        bytes latched (what the session recorder keeps, ``hli_server/recording``).

        A half equal to the one latched last into the same engine is not assigned again: the ``_w`` fields
        hold it already, since nothing but this projection writes them (the engine reads them; a PLC
        writes the image). Most cycles a PLC changes nothing: one comparison instead of some hundred
        assignments (docs/performance.md)."""
        off = self.plan.p2c_offset
        data = bytes(self._buf[off : off + self.plan.p2c_size])
        if data != self._latched or machine is not self._latched_for:
            values = self._p2c_struct.unpack_from(data)
            try:
                self._projection.unpack[_P2C](machine, values)
            except (IndexError, AttributeError) as exc:
                self._latched = self._latched_for = None
                raise diagnose(self.layout, machine, _P2C, exc) from exc
            self._latched, self._latched_for = data, machine
        if self._external is not None:
            self._external.latch(data, self._buf)
        return data

    def publish_from(self, machine: MachineHli, cycle: int, *, commit: bool = True) -> bytearray:
        """Pack the engine's CNC->PLC fields and publish them as ``cycle`` (seqlock, one memcpy); the
        V.E. elements the NC changed go into their fields (``hli_server/image/external.py``).

        Returns the packed buffer (the cycle as u64, then the half; valid until the next call).
        ``commit=False`` packs without publishing: the readers keep the previous publish (a stalled
        publish, a communication fault), and the NC's V.E. writes wait for the next publish."""
        if commit:
            self.publish_external()
        private = self._c2p_private
        try:
            self._projection.pack[_C2P](machine, self._c2p_struct.pack_into, private, 0, cycle)
        except (struct.error, IndexError, AttributeError, TypeError) as exc:
            if isinstance(exc, struct.error) and not 0 <= cycle < 2**64:
                raise SignalValueError(f"cycle {cycle} does not fit the image's u64 cycle counter") from exc
            raise diagnose(self.layout, machine, _C2P, exc) from exc
        if commit:
            self._commit(private, cycle)
        return private

    def publish_external(self) -> None:
        """The NC's V.E. writes into their fields, as :meth:`publish_from` stores them, without packing or
        publishing the half: a cycle whose outputs nobody reads (a replay's cycle between its
        comparisons) keeps the V.E. fields as a published cycle would."""
        if self._external is not None:
            self._external.publish(self._buf)

    def publish_bytes(self, half: bytes | bytearray, cycle: int) -> None:
        """Publish a ready-made CNC->PLC half (replay, tests); same protocol as :meth:`publish_from`."""
        if len(half) != self.plan.c2p_size:
            raise ValueError(f"CNC->PLC half is {self.plan.c2p_size} bytes, got {len(half)}")
        self._commit(struct.pack("<Q", cycle) + bytes(half), cycle)

    def _begin_publish(self) -> tuple[int, int]:
        """Start writing the buffer of the next publish: its seq goes odd. Returns (buffer, data offset)."""
        b = (self._publish_count + 1) & 1
        self._seq[b] += 1
        fmt.write_u64(self._buf, self.plan.c2p_offsets[b], self._seq[b])
        return b, self.plan.c2p_data_offset(b)

    def _end_publish(self, b: int, cycle: int) -> None:
        self._seq[b] += 1
        fmt.write_u64(self._buf, self.plan.c2p_offsets[b], self._seq[b])
        self._publish_count += 1
        self._cycle = cycle
        fmt.write_u64(self._buf, fmt.OFF_PUBLISH_COUNT, self._publish_count)
        fmt.write_u64(self._buf, fmt.OFF_CYCLE, cycle)

    def _commit(self, cycle_and_half: bytes | bytearray, cycle: int) -> None:
        b, _ = self._begin_publish()
        start = self.plan.c2p_offsets[b] + 8  # the buffer's cycle word, then the half
        self._buf[start : start + len(cycle_and_half)] = cycle_and_half
        self._end_publish(b, cycle)

    def init_from(
        self, machine: MachineHli, cycle: int = 0, external: ExternalVariables | None = None
    ) -> None:
        """Start-up: the PLC->CNC half takes the engine's ``_w`` values, the CNC->PLC half is published.
        ``external`` is the engine's store of V.E. variables (``machine.external``), which the image
        keeps in step with its V.E. fields from now on; needed when the layout has any."""
        p2c = bytearray(self.plan.p2c_size)
        try:
            self._projection.pack[_P2C](machine, self._p2c_struct.pack_into, p2c, 0)
        except (struct.error, IndexError, AttributeError, TypeError) as exc:
            raise diagnose(self.layout, machine, _P2C, exc) from exc
        off = self.plan.p2c_offset
        self._buf[off : off + len(p2c)] = p2c
        if self._external is not None:
            if external is None:
                raise ValueError(
                    f"the image layout has {len(self.layout.external_signals)} V.E. elements: pass the "
                    "engine's store (init_from(hli, cycle, external=machine.external))"
                )
            self._external.init(self._buf, external)
        self._latched = self._latched_for = None  # the next latch assigns the half, whatever it was
        self.publish_from(machine, cycle)

    @property
    def external_raw(self) -> bytes | None:
        """The V.E. sync's bytes (:attr:`ExternalSync.raw`), None without V.E. variables: what a
        recording's snapshot keeps of the image besides the PLC->CNC half (docs/record-replay.md)."""
        return None if self._external is None else self._external.raw

    @external_raw.setter
    def external_raw(self, value: bytes) -> None:
        if self._external is None:
            raise ValueError("this image has no V.E. variables")
        self._external.raw = value

    @property
    def cycle(self) -> int:
        """Cycle of the newest publish."""
        return self._cycle

    @property
    def publish_count(self) -> int:
        return self._publish_count

    def publish_counter(self) -> Callable[[], int]:
        counter: Callable[[], int] = functools.partial(_PUBLISH_COUNT_OF, self)
        return counter

    # --- the PLC door (adapters) ---------------------------------------------------------
    def write(self, st_path: str, value: object) -> None:
        """Write one PLC->CNC field (single store); CNC->PLC fields are refused (H-02)."""
        self.write_signal(self.layout.signal(st_path), value)

    def write_signal(self, signal: Signal, value: object) -> None:
        signal.check_plc_write()
        fmt.write_field(self._buf, self.plan.p2c_offset, signal, signal.coerce(value))

    def write_bytes(self, offset: int, data: bytes) -> None:
        """Raw write into the PLC->CNC half (ADS index group of the half): whole fields only,
        every value checked before any is written; padding bytes in the range are ignored."""
        fmt.write_p2c_bytes(self._buf, self.plan, self.layout, offset, data)

    def read(self, st_path: str) -> Any:
        """One field: PLC->CNC from the live half, CNC->PLC from the newest consistent publish."""
        signal = self.layout.signal(st_path)
        if signal.plc_writable:
            return fmt.read_field(self._buf, self.plan.p2c_offset, signal)
        return fmt.read_c2p_field(self._buf, self.plan, signal, self.name)

    def read_half(self, direction: Direction) -> bytes:
        """A copy of one half: PLC->CNC as it is now (one memcpy), CNC->PLC as last published."""
        if direction is _P2C:
            off = self.plan.p2c_offset
            return bytes(self._buf[off : off + self.plan.p2c_size])
        return self.snapshot()[1]

    def snapshot(self) -> tuple[int, bytes]:
        """``(cycle, CNC->PLC half)`` of the newest consistent publish."""
        return fmt.read_c2p(self._buf, self.plan, self.name)

    # --- per-cycle traces (H-07) ---------------------------------------------------------
    def recorder(self, st_paths: Iterable[str]) -> SignalRecorder:
        """A recorder of ``st_paths`` (either half): :meth:`SignalRecorder.sample` after a publish
        keeps their values in that publish; unknown paths raise the layout's error at once."""
        return SignalRecorder(self, st_paths)

    def _newest_half_offset(self) -> int:
        """Offset of the newest publish's buffer (its cycle word, then the half); writer side only."""
        return self.plan.c2p_offsets[self._publish_count & 1] + 8


def _field_struct(signals: list[Signal], head: str = "") -> struct.Struct:
    """One ``Struct`` that reads ``signals`` (sorted by offset) from the start of their half in a
    single ``unpack_from``; ``head`` is read first (the buffer's cycle word)."""
    parts = ["<", head]
    cursor = 0
    for s in signals:
        if s.offset > cursor:
            parts.append(f"{s.offset - cursor}x")
        parts.append(s.struct_char)
        cursor = s.offset + s.size
    return struct.Struct("".join(parts))


_NUMPY_TYPE = {"?": "?", "i": "<i4", "I": "<u4", "d": "<f8", "Q": "<u8"}


def _numpy_type(char: str) -> str:
    """The numpy type of a field's ``struct`` format: ``21s`` (a STRING) is ``S21``."""
    return f"S{char[:-1]}" if char.endswith("s") else _NUMPY_TYPE[char]


def _column(values: Any, char: str) -> Any:
    """One recorded column: a STRING's as ``str`` objects (its bytes up to the NUL), the others as
    they are."""
    import numpy as np

    if not char.endswith("s"):
        return np.array(values, copy=True)
    texts = [raw.partition(b"\0")[0].decode(STRING_ENCODING, "replace") for raw in values.tolist()]
    column = np.empty(len(texts), dtype=object)
    column[:] = texts
    return column


class SignalRecorder:
    """Chosen signals of every publish, kept packed (H-07: per-cycle traces).

    Cheap per cycle: :meth:`sample` is one ``unpack_from`` for the CNC->PLC signals (with the
    publish's cycle) and one for the PLC->CNC signals, packed without gaps onto a ``bytearray``
    (the signals' own widths: 2,000,000 cycles of one LREAL take 32 MB, not the 200 MB of Python
    objects an earlier version kept, reliability.md, round 2, finding 9); the columns are built once, as
    numpy arrays, by :meth:`columns`. Sample on the writer's side, right after a publish (the runtime does):
    the newest buffer is then not being written, so no seqlock retry is needed. PLC->CNC values are those of
    the live half at that moment (what the cycle latched, unless a PLC wrote since).
    """

    __slots__ = (
        "_c2p",
        "_c2p_data",
        "_c2p_pack",
        "_c2p_types",
        "_count",
        "_image",
        "_order",
        "_p2c",
        "_p2c_data",
        "_p2c_off",
        "_p2c_pack",
        "_p2c_types",
        "paths",
        "types",
    )

    def __init__(self, image: ProcessImage, st_paths: Iterable[str]) -> None:
        layout = image.layout
        signals = [layout.signal(p) for p in st_paths]
        paths = [s.st_path for s in signals]
        if len(set(paths)) != len(paths):
            raise ValueError(f"each signal once, please: {paths}")
        self._image = image
        self.paths: tuple[str, ...] = tuple(paths)
        self.types: dict[str, SignalType] = {s.st_path: s.type for s in signals}
        c2p = sorted((s for s in signals if s.direction is _C2P), key=lambda s: s.offset)
        p2c = sorted((s for s in signals if s.direction is _P2C), key=lambda s: s.offset)
        self._c2p = _field_struct(c2p, "Q").unpack_from
        self._c2p_types = ["Q", *(s.struct_char for s in c2p)]
        self._c2p_pack = struct.Struct("<" + "".join(self._c2p_types)).pack
        self._p2c = _field_struct(p2c).unpack_from if p2c else None
        self._p2c_types = [s.struct_char for s in p2c]
        self._p2c_pack = struct.Struct("<" + "".join(self._p2c_types)).pack
        self._p2c_off = image.plan.p2c_offset
        recorded = [s.st_path for s in c2p] + [s.st_path for s in p2c]
        self._order = [recorded.index(p) for p in paths]
        self._c2p_data = bytearray()
        self._p2c_data = bytearray()
        self._count = 0

    def sample(self) -> None:
        """Keep the signals of the newest publish (call right after it)."""
        image = self._image
        buf = image._buf
        self._c2p_data += self._c2p_pack(*self._c2p(buf, image._newest_half_offset()))
        if self._p2c is not None:
            self._p2c_data += self._p2c_pack(*self._p2c(buf, self._p2c_off))
        self._count += 1

    def __len__(self) -> int:
        return self._count

    def columns(self) -> tuple[Any, dict[str, Any]]:
        """``(cycles, {st_path: values})`` as numpy arrays (``uint64``; ``bool``, ``int32``, ``uint32``,
        ``float64`` after each signal's type, ``object`` holding ``str`` for a STRING): one value per
        sample, in the order sampled."""
        import numpy as np

        count = self._count
        cols: list[Any] = []
        for data, types in ((self._c2p_data, self._c2p_types), (self._p2c_data, self._p2c_types)):
            if not types:
                continue
            dtype = np.dtype([(f"f{i}", _numpy_type(c)) for i, c in enumerate(types)])
            with memoryview(data) as view:  # no copy of the packed rows; released before the next sample
                rows = np.frombuffer(view, dtype=dtype, count=count)
                cols += [_column(rows[f"f{i}"], c) for i, c in enumerate(types)]
                del rows
        cycles = cols[0]
        values = cols[1:]
        return cycles, {p: values[k] for p, k in zip(self.paths, self._order, strict=True)}
