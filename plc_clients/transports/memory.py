"""The in-memory twin of the process image (:class:`MemoryImage`) and its transports: unit tests of PLC logic
without a server or a socket (python-can's ``virtual`` bus is the model)."""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable
from dataclasses import dataclass, field
from typing import ClassVar

from plc_clients.transports.base import (
    _C2P,
    _P2C,
    _ZERO,
    CYCLE_R_MODULUS,
    CYCLE_SIGNAL,
    Inputs,
    TransportError,
    Value,
    _c2p_watch,
)
from schemas.layout import Layout

__all__ = ["AsyncMemoryTransport", "CncModel", "MemoryImage", "MemoryTransport"]


CncModel = Callable[["MemoryImage"], None]


@dataclass(slots=True)
class MemoryImage:
    """An in-memory twin of the process image, for unit tests of PLC logic (no server, no sockets).

    Like the real image it has two halves and a cycle. The PLC side uses a :class:`MemoryTransport`
    on it; the test plays the CNC: :meth:`set` CNC->PLC values, :meth:`step` one CNC cycle, which
    latches the PLC->CNC half (:attr:`latched`), runs the ``models`` (callables that play a part of
    the CNC, reading :attr:`latched` and calling :meth:`set`), and publishes. ``fault``: when set,
    every transport call raises it (a broken connection). ``writes`` logs every PLC write as
    ``(cycle, st_path, value)`` in order.
    """

    layout: Layout
    cycle: int = 0
    models: list[CncModel] = field(default_factory=list)
    fault: TransportError | None = None
    writes: list[tuple[int, str, Value]] = field(default_factory=list)
    outputs: dict[str, Value] = field(init=False)
    """The PLC->CNC half as the PLC wrote it (live)."""
    latched: dict[str, Value] = field(init=False)
    """The PLC->CNC half as the CNC latched it at the start of the newest :meth:`step`."""
    _working: dict[str, Value] = field(init=False)
    published: dict[str, Value] = field(init=False)
    """The CNC->PLC half of the newest publish."""

    def __post_init__(self) -> None:
        self.outputs = {s.st_path: _ZERO[s.type] for s in self.layout.half(_P2C)}
        self.latched = dict(self.outputs)
        self._working = {s.st_path: _ZERO[s.type] for s in self.layout.half(_C2P)}
        self.published = dict(self._working)

    def set(self, st_path: str, value: Value) -> None:
        """The CNC side sets a CNC->PLC value; the PLC sees it after the next :meth:`step`."""
        s = self.layout.signal(st_path)
        if s.plc_writable:
            raise ValueError(f"{st_path} is PLC->CNC: the PLC writes it (use a transport)")
        self._working[st_path] = s.coerce(value)

    def get(self, st_path: str) -> Value:
        """The CNC side's current CNC->PLC value (not yet published)."""
        return self._working[self.layout.signal(st_path).st_path]

    def step(self, cycles: int = 1) -> int:
        """``cycles`` CNC cycles: latch, models, publish. Returns the cycle."""
        for _ in range(cycles):
            self.latched = dict(self.outputs)
            for model in self.models:
                model(self)
            self.cycle += 1
            if CYCLE_SIGNAL in self._working:
                self._working[CYCLE_SIGNAL] = self.cycle % CYCLE_R_MODULUS
            self.published = dict(self._working)
        return self.cycle


class MemoryTransport:
    """The PLC side of a :class:`MemoryImage`. ``partial=True``: :meth:`snapshot` holds only the
    watched signals (and the cycle counter), as the Modbus transports do."""

    is_async: ClassVar[bool] = False
    blocking: ClassVar[bool] = False

    def __init__(self, image: MemoryImage, *, partial: bool = False) -> None:
        self.image = image
        self.layout: Layout = image.layout
        self.partial = partial
        self.closed = False

    def _check(self) -> None:
        if self.closed:
            raise TransportError("memory transport: closed")
        if self.image.fault is not None:
            raise self.image.fault

    def snapshot(self, watch: Collection[str] | None = None) -> Inputs:
        self._check()
        image = self.image
        if self.partial and watch is not None:
            paths = {s.st_path for s in _c2p_watch(self.layout, watch)}
            if CYCLE_SIGNAL in image.published:
                paths.add(CYCLE_SIGNAL)
            values: dict[str, Value] = {p: image.published[p] for p in paths}
        else:
            values = dict(image.published)
        return Inputs(image.cycle, values)

    def read(self, st_path: str) -> Value:
        self._check()
        s = self.layout.signal(st_path)
        return self.image.outputs[s.st_path] if s.plc_writable else self.image.published[s.st_path]

    def write(self, st_path: str, value: Value) -> None:
        self.write_many([(st_path, value)])

    def write_many(self, items: Iterable[tuple[str, Value]]) -> None:
        self._check()
        checked = []
        for st_path, value in items:
            s = self.layout.signal(st_path)
            s.check_plc_write()
            checked.append((s.st_path, s.coerce(value)))
        for st_path, v in checked:
            self.image.outputs[st_path] = v
            self.image.writes.append((self.image.cycle, st_path, v))

    @property
    def cycle(self) -> int:
        return self.image.cycle

    def close(self) -> None:
        self.closed = True

    def __repr__(self) -> str:
        return f"MemoryTransport(cycle {self.image.cycle}, partial={self.partial})"


class AsyncMemoryTransport:
    """:class:`MemoryTransport` with coroutine methods (tests of asyncio PLC tasks); partial by default."""

    is_async: ClassVar[bool] = True
    blocking: ClassVar[bool] = False

    def __init__(self, image: MemoryImage, *, partial: bool = True) -> None:
        self._sync = MemoryTransport(image, partial=partial)
        self.image = image
        self.layout: Layout = image.layout

    async def snapshot(self, watch: Collection[str] | None = None) -> Inputs:
        return self._sync.snapshot(watch)

    async def read(self, st_path: str) -> Value:
        return self._sync.read(st_path)

    async def write(self, st_path: str, value: Value) -> None:
        self._sync.write(st_path, value)

    async def write_many(self, items: Iterable[tuple[str, Value]]) -> None:
        self._sync.write_many(items)

    async def close(self) -> None:
        self._sync.close()
