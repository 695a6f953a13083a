"""PLC-side handle on the shared-memory process image (H-01, H-02).

``ImageClient.attach(name)`` maps the image a server created, checks it (magic, format version,
layout version, layout hash) and gives field access by ST path::

    with ImageClient.attach("hli_demo") as plc:
        plc.write("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w", -500_000)
        plc.write("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.enable_w", True)
        snap = plc.snapshot()            # one consistent CNC->PLC cycle
        snap["gpAx[0]^ipo_mc_control.dyn_pos_limit_low.state_r"]

Where the layout comes from: the server stores the layout JSON in the segment (after the header);
the client rebuilds the :class:`~schemas.layout.Layout` from it and checks that its hash is the
one in the header. A client that was built for a particular machine passes ``expect=`` (a layout
built from the same configuration, or its hash) and gets :class:`ImageMismatchError` when the
server runs another one. No configuration file is needed to attach.

The client never unlinks the segment and does not register it with the ``multiprocessing``
resource tracker, so neither its exit nor its tracker removes the server's image or warns about it.
It imports ``schemas`` only, never ``hli_server``.

A server running in this very process (the pytest harness, H-07) may keep its image in a plain
buffer instead of ``/dev/shm``; ``ImageClient.over(buffer)`` attaches to that buffer with the same
checks and the same protocol (``ShmTransport`` takes either client).
"""

from __future__ import annotations

import struct
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from multiprocessing import shared_memory
from typing import Any

from plc_clients._closing import ClosesOnExit
from schemas import image_format as fmt
from schemas.image_format import (
    ImageBusyError,
    ImageError,
    ImageMismatchError,
    ImageNotReadyError,
    attach_untracked,
)
from schemas.layout import Direction, Layout, ReadOnlySignalError, Signal, SignalType

__all__ = [
    "ImageBusyError",
    "ImageClient",
    "ImageError",
    "ImageMismatchError",
    "ImageNotReadyError",
    "ReadOnlySignalError",
    "Snapshot",
    "attach_untracked",
]

_LE: dict[SignalType, struct.Struct] = {
    t: struct.Struct("<" + t.struct_char) for t in SignalType if t is not SignalType.STRING
}
"""The CNC->PLC fields' formats (a STRING is a V.E. variable's, PLC->CNC: ``read`` reads it)."""


@dataclass(frozen=True, slots=True)
class Snapshot:
    """One consistent CNC->PLC cycle: ``snap[st_path]``, ``snap.cycle``, ``snap.as_dict()``."""

    cycle: int
    data: bytes
    layout: Layout

    def __getitem__(self, st_path: str) -> Any:
        s = self.layout.signal(st_path)
        if s.plc_writable:
            raise KeyError(f"{st_path} is a PLC->CNC field; read it with ImageClient.read()")
        return _LE[s.type].unpack_from(self.data, s.offset)[0]

    def as_dict(self) -> dict[str, Any]:
        return self.layout.unpack(Direction.CNC_TO_PLC, self.data)


class ImageClient(ClosesOnExit):
    """A PLC's handle on the image. Attach with :meth:`attach` (shared memory, by name) or
    :meth:`over` (a buffer of this process); use as a context manager."""

    def __init__(
        self,
        buffer: memoryview,
        header: fmt.ImageHeader,
        layout: Layout,
        *,
        name: str,
        shm: shared_memory.SharedMemory | None = None,
    ) -> None:
        self._shm = shm
        self._buf = buffer
        self.name = name
        self.header = header
        self.plan = header.plan
        self.layout = layout
        self._closed = False

    @classmethod
    def attach(cls, name: str, *, expect: Layout | str | None = None, timeout: float = 0.0) -> ImageClient:
        """Attach to the image ``name``.

        ``expect``: a layout (or a layout hash) the caller was built for; a different layout in the
        image raises :class:`ImageMismatchError`. ``timeout``: keep trying that many seconds while
        the segment does not exist yet or the server is still writing its header.
        """
        expected_hash = expect.hash if isinstance(expect, Layout) else expect
        seg = fmt.attach_segment(name, expected_hash=expected_hash, timeout=timeout)
        return cls(seg.buf, seg.header, seg.layout, name=seg.name, shm=seg.shm)

    @classmethod
    def over(
        cls, buffer: memoryview | bytearray, *, name: str = "memory", expect: Layout | str | None = None
    ) -> ImageClient:
        """Attach to an image in a buffer of this process (a server in the same process keeps it
        there: ``ProcessImage.in_memory(...).buffer``). Same checks as :meth:`attach`; ``name`` is
        used in messages only."""
        fmt.check_host()
        expected_hash = expect.hash if isinstance(expect, Layout) else expect
        view = memoryview(buffer)  # our own view: it stays valid when the server releases its own
        header, layout = fmt.check_segment(view, name, len(view), expected_hash)
        return cls(view, header, layout, name=name)

    def close(self) -> None:
        """Unmap (never unlink: the server owns the segment). Idempotent."""
        if not self._closed:
            self._closed = True
            if self._shm is not None:
                self._shm.close()
            else:
                self._buf.release()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"ImageClient({self.name!r}, layout {self.layout.hash[:12]}, {state})"

    # --- access ------------------------------------------------------------------------------
    def signal(self, st_path: str) -> Signal:
        return self.layout.signal(st_path)

    def write(self, st_path: str, value: object) -> None:
        """Write one PLC->CNC field with a single store; ``_r`` fields are refused (H-02)."""
        s = self.layout.signal(st_path)
        s.check_plc_write()
        fmt.write_field(self._buf, self.plan.p2c_offset, s, s.coerce(value))

    def write_many(self, values: Mapping[str, object]) -> None:
        """Write several fields in the given order (each a single store; check all first).

        The server may latch between two of the stores: order them so that the field that arms
        the others comes last (``command_w`` before ``enable_w``).
        """
        checked = []
        for st_path, value in values.items():
            s = self.layout.signal(st_path)
            s.check_plc_write()
            checked.append((s, s.coerce(value)))
        for s, v in checked:
            fmt.write_field(self._buf, self.plan.p2c_offset, s, v)

    def read(self, st_path: str) -> Any:
        """One field: PLC->CNC as it is now, CNC->PLC from a consistent publish."""
        s = self.layout.signal(st_path)
        if s.plc_writable:
            return fmt.read_field(self._buf, self.plan.p2c_offset, s)
        return fmt.read_c2p_field(self._buf, self.plan, s, self.name)

    def snapshot(self) -> Snapshot:
        """All CNC->PLC fields of one cycle (never a half-written one)."""
        cycle, data = fmt.read_c2p(self._buf, self.plan, self.name)
        return Snapshot(cycle, data, self.layout)

    def outputs(self) -> dict[str, Any]:
        """The PLC->CNC half as it is now (one copy)."""
        off = self.plan.p2c_offset
        return self.layout.unpack(Direction.PLC_TO_CNC, bytes(self._buf[off : off + self.plan.p2c_size]))

    def raw(self, direction: Direction) -> bytes:
        """A copy of one half: PLC->CNC as it is now, CNC->PLC of one consistent cycle."""
        if direction is Direction.CNC_TO_PLC:
            return fmt.read_c2p(self._buf, self.plan, self.name)[1]
        off = self.plan.p2c_offset
        return bytes(self._buf[off : off + self.plan.p2c_size])

    @property
    def cycle(self) -> int:
        """Cycle of the newest publish (header)."""
        return fmt.read_u64(self._buf, fmt.OFF_CYCLE)

    @property
    def publish_count(self) -> int:
        return fmt.read_u64(self._buf, fmt.OFF_PUBLISH_COUNT)

    @property
    def server_closed(self) -> bool:
        """True once the server has closed the image (it is then unlinked; the mapping stays valid)."""
        flags: int = fmt.HEADER.unpack_from(self._buf, 0)[13]
        return bool(flags & fmt.FLAG_CLOSED)

    def wait_for_publish(self, count: int, timeout: float = 1.0) -> Snapshot:
        """Wait until the server has published at least ``count`` times; then a snapshot.

        Polls the header every 0.2 ms (a PLC task would instead run on its own cycle)."""
        deadline = time.monotonic() + timeout
        while self.publish_count < count:
            if self.server_closed:
                raise ImageError(f"image {self.name!r}: the server closed the image")
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f"image {self.name!r}: publish {count} not reached in {timeout} s "
                    f"(now {self.publish_count}); is the server's clock running?"
                )
            time.sleep(0.0002)
        return self.snapshot()

    def iter_snapshots(self) -> Iterator[Snapshot]:
        """Snapshots for ever (for scripts); each one consistent."""
        while True:
            yield self.snapshot()
