"""The shared-memory transport (H-01): one publish of the whole CNC->PLC half per snapshot."""

from __future__ import annotations

from collections.abc import Collection, Iterable, Iterator, Mapping
from typing import TYPE_CHECKING, ClassVar

from plc_clients._closing import ClosesOnExit
from plc_clients.shm import ImageClient, ImageError
from plc_clients.transports.base import _C2P, Inputs, TransportError, Value
from schemas.layout import Layout

if TYPE_CHECKING:
    from plc_clients.shm import Snapshot

__all__ = ["ShmTransport"]


class _SnapshotValues(Mapping[str, Value]):
    """A shared-memory snapshot as a mapping of the CNC->PLC paths (decoded on access)."""

    __slots__ = ("_paths", "_snap")

    def __init__(self, snap: Snapshot, paths: frozenset[str]) -> None:
        self._snap = snap
        self._paths = paths

    def __getitem__(self, st_path: str) -> Value:
        if st_path not in self._paths:
            raise KeyError(st_path)
        value: Value = self._snap[st_path]
        return value

    def __contains__(self, st_path: object) -> bool:
        return st_path in self._paths

    def __iter__(self) -> Iterator[str]:
        return iter(self._paths)

    def __len__(self) -> int:
        return len(self._paths)


class ShmTransport(ClosesOnExit):
    """The shared-memory image (H-01) through :class:`~plc_clients.shm.ImageClient`.

    Never blocks (no system call per access), so it can be used from an event loop as well as
    from a plain loop. The layout comes from the image itself. ``snapshot`` always holds the
    whole CNC->PLC half of one publish (one copy); ``watch`` is ignored.
    """

    is_async: ClassVar[bool] = False
    blocking: ClassVar[bool] = False

    def __init__(self, client: ImageClient) -> None:
        self.client = client
        self.layout: Layout = client.layout
        self._c2p_paths = frozenset(s.st_path for s in self.layout.half(_C2P))

    @classmethod
    def attach(cls, name: str, *, expect: Layout | str | None = None, timeout: float = 0.0) -> ShmTransport:
        """Map the image ``name`` (printed by ``hli-server run``); see :meth:`ImageClient.attach`."""
        try:
            return cls(ImageClient.attach(name, expect=expect, timeout=timeout))
        except FileNotFoundError as exc:
            raise TransportError(str(exc)) from exc

    @classmethod
    def over(
        cls, buffer: memoryview | bytearray, *, name: str = "memory", expect: Layout | str | None = None
    ) -> ShmTransport:
        """The image of a server in this process that keeps it in a buffer instead of ``/dev/shm``
        (the pytest harness); the same protocol, see :meth:`ImageClient.over`."""
        return cls(ImageClient.over(buffer, name=name, expect=expect))

    def _check_open(self) -> None:
        if self.client.server_closed:
            raise TransportError(
                f"image {self.client.name!r}: the server closed the image (it stopped); "
                "attach again to the new server's image"
            )

    def snapshot(self, watch: Collection[str] | None = None) -> Inputs:
        self._check_open()
        try:
            snap = self.client.snapshot()
        except ImageError as exc:
            raise TransportError(str(exc)) from exc
        return Inputs(snap.cycle, _SnapshotValues(snap, self._c2p_paths))

    def read(self, st_path: str) -> Value:
        self._check_open()
        try:
            value: Value = self.client.read(st_path)
        except ImageError as exc:
            raise TransportError(str(exc)) from exc
        return value

    def write(self, st_path: str, value: Value) -> None:
        self._check_open()
        self.client.write(st_path, value)

    def write_many(self, items: Iterable[tuple[str, Value]]) -> None:
        self._check_open()
        self.client.write_many(dict(items))

    @property
    def cycle(self) -> int:
        """The CNC cycle of the newest publish."""
        return self.client.cycle

    def close(self) -> None:
        self.client.close()

    def __repr__(self) -> str:
        return f"ShmTransport({self.client.name!r})"
