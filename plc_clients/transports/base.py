"""What every transport shares (H-06): the protocol (:class:`Transport`, :class:`AsyncTransport`), the input
image of one task cycle (:class:`Inputs`), the door's error (:class:`TransportError`), where a layout comes
from (:func:`load_layout`). Imports ``schemas`` only."""

from __future__ import annotations

import os
import urllib.error
import urllib.request
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, Final, Protocol, runtime_checkable

from schemas.layout import Direction, Layout, LayoutError, Signal, SignalType

__all__ = [
    "CYCLE_R_MODULUS",
    "CYCLE_SIGNAL",
    "AsyncTransport",
    "Inputs",
    "Transport",
    "TransportError",
    "Value",
    "load_layout",
]

Value = bool | int | float | str
"""A field's value: BOOL, a number, or the text of a V.E. STRING."""

CYCLE_SIGNAL: Final = "gpCh[0]^bahn_state.cycle_r"
"""The CNC's interpolation cycle counter as the Modbus transports see it (channel 1's copy)."""
CYCLE_R_MODULUS: Final = 2**31
"""``cycle_r`` counts modulo 2**31 (the server's channel publish); the Modbus transports unwrap it."""

_P2C, _C2P = Direction.PLC_TO_CNC, Direction.CNC_TO_PLC
_ZERO: Final[dict[SignalType, Value]] = {
    SignalType.BOOL: False,
    SignalType.DINT: 0,
    SignalType.UDINT: 0,
    SignalType.LREAL: 0.0,
    SignalType.STRING: "",
}


class TransportError(OSError):
    """The door to the image failed: no server, connection lost, an exception answer, image closed.

    ``modbus_exception`` is the Modbus exception code when the server answered with one.
    """

    def __init__(self, message: str, *, modbus_exception: int | None = None) -> None:
        super().__init__(message)
        self.modbus_exception = modbus_exception

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "transport failure"


@dataclass(frozen=True, slots=True)
class Inputs:
    """The PLC's input image of one task cycle: CNC->PLC values by ST path and the CNC cycle.

    ``values`` holds every CNC->PLC signal (shared memory, memory twin) or the watched ones
    (Modbus). ``consistent`` is False when the values came from more than one CNC publish.
    """

    cycle: int
    values: Mapping[str, Value]
    consistent: bool = True

    def __getitem__(self, st_path: str) -> Value:
        return self.values[st_path]

    def __contains__(self, st_path: object) -> bool:
        return st_path in self.values

    def get(self, st_path: str, default: Value | None = None) -> Value | None:
        return self.values.get(st_path, default)


@runtime_checkable
class Transport(Protocol):
    """A synchronous door to the image (see the module docstring)."""

    layout: Layout
    is_async: ClassVar[bool]
    blocking: ClassVar[bool]
    """True when calls wait for the network (do not call them from an event loop)."""

    def snapshot(self, watch: Collection[str] | None = None) -> Inputs: ...

    def read(self, st_path: str) -> Value: ...

    def write(self, st_path: str, value: Value) -> None: ...

    def write_many(self, items: Iterable[tuple[str, Value]]) -> None: ...

    def close(self) -> None: ...


@runtime_checkable
class AsyncTransport(Protocol):
    """The same door for asyncio: every method is a coroutine."""

    layout: Layout
    is_async: ClassVar[bool]

    async def snapshot(self, watch: Collection[str] | None = None) -> Inputs: ...

    async def read(self, st_path: str) -> Value: ...

    async def write(self, st_path: str, value: Value) -> None: ...

    async def write_many(self, items: Iterable[tuple[str, Value]]) -> None: ...

    async def close(self) -> None: ...


def load_layout(source: Layout | str | os.PathLike[str], *, timeout: float = 5.0) -> Layout:
    """A layout from a :class:`Layout`, a JSON file (``hli-server map --format json``) or a URL.

    A URL (``http://host:port`` or ``.../api/layout``) is fetched from the server's HTTP API with
    a blocking request: in asyncio code call it before the loop, or with ``asyncio.to_thread``.
    """
    if isinstance(source, Layout):
        return source
    text = os.fspath(source)
    if text.startswith(("http://", "https://")):
        url = text.rstrip("/")
        if not url.endswith("/api/layout"):
            url += "/api/layout"
        try:
            with urllib.request.urlopen(url, timeout=timeout) as response:
                body = response.read()
        except (urllib.error.URLError, OSError) as exc:
            raise TransportError(
                f"cannot fetch the layout from {url}: {exc}; is `hli-server run` running with its "
                "HTTP API? (or pass the file of `hli-server map --format json`)"
            ) from exc
        try:
            return Layout.from_json(body)
        except LayoutError as exc:
            raise LayoutError(f"layout from {url}: {exc}") from exc
    path = Path(text)
    try:
        raw = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise FileNotFoundError(
            f"layout file {path}: {exc.strerror}; write it with `hli-server map --format json > {path}`"
        ) from exc
    try:
        return Layout.from_json(raw)
    except LayoutError as exc:
        raise LayoutError(f"layout file {path}: {exc}") from exc


def _c2p_watch(layout: Layout, watch: Collection[str] | None) -> list[Signal]:
    """The CNC->PLC signals to read: all, or the watched ones (``_w`` paths in ``watch`` are
    outputs and are skipped; an unknown path raises the layout's error)."""
    if watch is None:
        return list(layout.half(_C2P))
    out = []
    for path in watch:
        s = layout.signal(path)
        if not s.plc_writable:
            out.append(s)
    return out


class _CycleCounter:
    """Unwraps ``cycle_r`` (modulo :data:`CYCLE_R_MODULUS`) into a monotonic count."""

    __slots__ = ("_base", "_last")

    def __init__(self) -> None:
        self._base = 0
        self._last: int | None = None

    def update(self, raw: int) -> int:
        if self._last is not None and raw < self._last:
            self._base += CYCLE_R_MODULUS
        self._last = raw
        return self._base + raw
