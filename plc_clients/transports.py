"""Transports: how PLC logic in Python reaches the process image (H-06).

One small protocol, several implementations (python-can's interface registry and its ``virtual``
bus are the model):

================================ ========================= =========================================
transport                        door                      consistency of :meth:`snapshot`
================================ ========================= =========================================
:class:`ShmTransport`            shared memory (H-01)      one publish of the whole CNC->PLC half
:class:`ModbusTransport`         Modbus TCP, sync (H-03)   per request; see below
:class:`AsyncModbusTransport`    Modbus TCP, asyncio       per request; see below
:class:`MemoryTransport`         :class:`MemoryImage`      one publish of the twin (unit tests)
================================ ========================= =========================================

The protocol (:class:`Transport`; :class:`AsyncTransport` has the same methods as coroutines):

* ``layout``: the :class:`~schemas.layout.Layout` of the image (every ST path and address);
* ``snapshot(watch=None) -> Inputs``: the PLC's input image for one task cycle: the CNC->PLC
  values (all of them, or at least those in ``watch``) and ``cycle``, the CNC cycle they were
  published in (a monotonic count; over Modbus the unwrapped ``gpCh[0]^bahn_state.cycle_r``);
* ``read(st_path)``, ``write(st_path, value)``, ``write_many(items)`` (in the given order: write
  the field that arms the others last, ``command_w`` before ``enable_w``, H-02);
* ``close()``.

Failures of the door (no server, connection lost, a Modbus exception answer, the server closed
the image) raise :class:`TransportError`. Mistakes in the caller's code (an unknown ST path, a write
to a ``_r`` field, a value the field cannot hold) raise the layout's own errors
(:class:`~schemas.layout.UnknownSignalError`, :class:`~schemas.layout.ReadOnlySignalError`,
:class:`~schemas.layout.SignalValueError`) before anything is sent.

**Where the Modbus transports get the layout.** Modbus carries no description of the map, so the
client must be given the same layout the server runs. ``layout=`` takes a
:class:`~schemas.layout.Layout`, the path of a JSON file written by
``hli-server map --format json > layout.json``, or the URL of the server's HTTP API
(``http://127.0.0.1:8080``, which serves ``GET /api/layout``); :func:`load_layout` does the
loading. The shared-memory transport needs none of this: the image carries its own layout and
hash. A layout of another machine gives wrong addresses without any error on the wire - take it
from the server you talk to.

**Consistency over Modbus.** Modbus has no atomic read of several tables: each request is
answered from one publish of the CNC->PLC half (the server serves it without yielding), but two
requests may fall into two CNC cycles. :meth:`ModbusTransport.snapshot` reads only what is
watched (fewest requests, :mod:`plc_clients.modbus_codec`). When that takes more than one request
it first writes 1 to the server's snapshot register (holding register
:data:`~schemas.layout.MODBUS_SNAPSHOT_REGISTER`): the server then answers this connection's reads
of inputs from one copy of the newest publish, so the whole snapshot is one CNC cycle
(:attr:`Inputs.consistent` is True) for one request more. A later single read of an input
(:meth:`read`) writes 0 first (live values again). Against a server without the register (it
answers 0x02) the transport reads ``cycle_r`` before and after instead, and ``consistent`` says
whether both came from the same publish. With the default ``watch=None`` it reads the whole half
(22 requests on the demo machine): pass the inputs the program reads (the PLC task learns them,
:class:`~plc_clients.task.PlcTask`).

Imports ``schemas`` (and pymodbus' clients, lazily, in the Modbus transports), never ``hli_server``.
"""

from __future__ import annotations

import logging
import os
import urllib.error
import urllib.request
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Final, Protocol, runtime_checkable

from plc_clients._closing import ClosesOnExit
from plc_clients.modbus_codec import ModbusCodec, ReadRequest
from plc_clients.shm import ImageClient, ImageError
from schemas.layout import (
    MODBUS_SNAPSHOT_REGISTER,
    Direction,
    Layout,
    LayoutError,
    ModbusTable,
    Signal,
    SignalType,
)

if TYPE_CHECKING:
    from plc_clients.shm import Snapshot

__all__ = [
    "CYCLE_R_MODULUS",
    "CYCLE_SIGNAL",
    "AsyncMemoryTransport",
    "AsyncModbusTransport",
    "AsyncTransport",
    "Inputs",
    "MemoryImage",
    "MemoryTransport",
    "ModbusTransport",
    "ShmTransport",
    "Transport",
    "TransportError",
    "Value",
    "load_layout",
]

logger = logging.getLogger(__name__)

Value = bool | int | float

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


# ================================================================================================
# Shared memory
# ================================================================================================


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


# ================================================================================================
# The in-memory twin
# ================================================================================================

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


# ================================================================================================
# Modbus TCP
# ================================================================================================


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


class _ModbusCommon:
    """What the sync and the asyncio Modbus transports share: layout, codec, requests, errors."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 5020,
        *,
        layout: Layout | str | os.PathLike[str],
        word_order: str = "ABCD",
        unit_id: int = 1,
        timeout: float = 2.0,
    ) -> None:
        self.host = host
        self.port = port
        self.layout: Layout = load_layout(layout)
        self.codec = ModbusCodec(self.layout, word_order)
        self.unit_id = unit_id
        self.timeout = timeout
        if CYCLE_SIGNAL not in self.layout:
            raise LayoutError(
                f"the layout has no {CYCLE_SIGNAL}: the Modbus transports need channel 1's cycle"
            )
        self._cycle_signal = self.layout.signal(CYCLE_SIGNAL)
        self._counter = _CycleCounter()
        self._plans: dict[frozenset[str] | None, list[ReadRequest]] = {}
        self._frozen = False
        """This connection's input reads are frozen on one publish (the snapshot register)."""
        self._has_snapshot_register: bool | None = None
        """None until the first freeze tells; False: an older server, before and after cycle reads."""
        self._client = self._make_client(host, port, timeout)

    def _make_client(self, host: str, port: int, timeout: float) -> Any:
        """pymodbus' sync or asyncio client (imported only when a Modbus transport is made)."""
        raise NotImplementedError

    @property
    def where(self) -> str:
        return f"Modbus TCP {self.host}:{self.port} (unit id {self.unit_id})"

    def _plan(self, watch: Collection[str] | None) -> list[ReadRequest]:
        """The read requests of a snapshot; the one with the cycle counter first (cached)."""
        key = None if watch is None else frozenset(watch)
        plan = self._plans.get(key)
        if plan is None:
            signals = _c2p_watch(self.layout, watch)
            signals.append(self._cycle_signal)
            requests = self.codec.read_requests(signals)
            requests.sort(key=lambda r: self._cycle_signal not in r.signals)
            plan = requests
            if len(self._plans) > 64:
                self._plans.clear()
            self._plans[key] = plan
        return plan

    def _cycle_request(self) -> ReadRequest:
        return self.codec.read_requests([self._cycle_signal])[0]

    def _wants_freeze(self, plan: list[ReadRequest]) -> bool:
        """A snapshot of several requests freezes (and so does any while frozen: a new copy)."""
        return (len(plan) > 1 or self._frozen) and self._has_snapshot_register is not False

    def _froze(self, value: int, error: TransportError | None) -> bool:
        """Book-keeping after a write of the snapshot register; False: the server has none."""
        if error is not None:
            if error.modbus_exception != 0x02:
                raise error
            self._has_snapshot_register = False
            self._frozen = False
            return False
        self._has_snapshot_register = True
        self._frozen = value == 1
        return True

    @staticmethod
    def _is_input(signal: Signal) -> bool:
        return signal.modbus_table in (ModbusTable.DISCRETE_INPUT, ModbusTable.INPUT_REGISTER)

    def _inputs(self, values: dict[str, Value], first_raw: int, last_raw: int | None) -> Inputs:
        cycle = self._counter.update(int(first_raw))
        consistent = last_raw is None or last_raw == first_raw
        return Inputs(cycle, values, consistent)

    def _write_request(self, st_path: str, value: Value) -> tuple[Signal, Value]:
        s = self.layout.signal(st_path)
        s.check_plc_write()
        return s, s.coerce(value)

    def _answer(self, what: str, response: Any) -> Any:
        if response.isError():
            code = int(getattr(response, "exception_code", 0) or 0)
            raise TransportError(
                f"{self.where}: {what} was refused with Modbus exception 0x{code:02X}"
                f"{_EXCEPTION_HINT.get(code, '')}",
                modbus_exception=code,
            )
        return response

    def _failed(self, what: str, exc: Exception) -> TransportError:
        return TransportError(
            f"{self.where}: {what} failed: {exc}; is `hli-server run` running and serving Modbus "
            "on this port (--modbus-port, 5020 by default)?"
        )


_EXCEPTION_HINT: Final = {
    0x02: " (illegal data address: the layout does not match the server's - load it from this server)",
    0x03: " (illegal data value)",
    0x0B: " (no such unit id: use the server's --modbus-unit-id)",
}


class ModbusTransport(_ModbusCommon, ClosesOnExit):
    """Modbus TCP with pymodbus' synchronous ``ModbusTcpClient`` (H-03): for scripts and threads.

    Every call waits for the server (``blocking``): do not use it inside an event loop that also
    runs the server; use :class:`AsyncModbusTransport` there. ``word_order`` and ``unit_id`` must be
    the server's (``--modbus-word-order``, ``--modbus-unit-id``). Construct with :meth:`connect`.
    """

    is_async: ClassVar[bool] = False
    blocking: ClassVar[bool] = True

    def _make_client(self, host: str, port: int, timeout: float) -> Any:
        from pymodbus.client import ModbusTcpClient

        return ModbusTcpClient(host, port=port, timeout=timeout, retries=0)

    @classmethod
    def connect(
        cls,
        host: str = "127.0.0.1",
        port: int = 5020,
        *,
        layout: Layout | str | os.PathLike[str],
        word_order: str = "ABCD",
        unit_id: int = 1,
        timeout: float = 2.0,
    ) -> ModbusTransport:
        """Connect (raises :class:`TransportError` when no server answers)."""
        transport = cls(host, port, layout=layout, word_order=word_order, unit_id=unit_id, timeout=timeout)
        if not transport._client.connect():
            transport.close()
            raise transport._failed("connecting", ConnectionRefusedError("no answer"))
        return transport

    def _call(self, what: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        from pymodbus.exceptions import ModbusException

        try:
            response = fn(*args, device_id=self.unit_id, **kwargs)
        except (ModbusException, OSError) as exc:
            raise self._failed(what, exc) from exc
        return self._answer(what, response)

    def _read(self, request: ReadRequest) -> dict[str, Value]:
        c = self._client
        fn = {
            ModbusTable.COIL: c.read_coils,
            ModbusTable.DISCRETE_INPUT: c.read_discrete_inputs,
            ModbusTable.HOLDING_REGISTER: c.read_holding_registers,
            ModbusTable.INPUT_REGISTER: c.read_input_registers,
        }[request.table]
        what = f"FC{request.function_code} read of {request.count} from address {request.address}"
        response = self._call(what, fn, request.address, count=request.count)
        bits_or_regs = response.bits if request.table in _BITS else response.registers
        return self.codec.decode(request, bits_or_regs)

    def _snapshot_register(self, value: int) -> bool:
        """Write the server's snapshot register: 1 freezes this connection's inputs, 0 thaws."""
        try:
            self._call(
                f"FC6 write of the snapshot register {MODBUS_SNAPSHOT_REGISTER}",
                self._client.write_register,
                MODBUS_SNAPSHOT_REGISTER,
                value,
            )
        except TransportError as exc:
            return self._froze(value, exc)
        return self._froze(value, None)

    def snapshot(self, watch: Collection[str] | None = None) -> Inputs:
        plan = self._plan(watch)
        frozen = self._wants_freeze(plan) and self._snapshot_register(1)
        values: dict[str, Value] = {}
        for request in plan:
            values.update(self._read(request))
        first = int(values[CYCLE_SIGNAL])
        last = None
        if len(plan) > 1 and not frozen:
            last = int(self._read(self._cycle_request())[CYCLE_SIGNAL])
        return self._inputs(values, first, last)

    def read(self, st_path: str) -> Value:
        s = self.layout.signal(st_path)
        if self._frozen and self._is_input(s):
            self._snapshot_register(0)
        return self._read(self.codec.read_requests([s])[0])[s.st_path]

    def write(self, st_path: str, value: Value) -> None:
        s, v = self._write_request(st_path, value)
        if s.modbus_table is ModbusTable.COIL:
            self._call(f"FC5 write of {st_path}", self._client.write_coil, s.modbus_address, bool(v))
        else:
            regs = self.codec.registers(s, v)
            self._call(f"FC16 write of {st_path}", self._client.write_registers, s.modbus_address, regs)

    def write_many(self, items: Iterable[tuple[str, Value]]) -> None:
        """One request per field, in the given order (check all first)."""
        checked = [(st_path, self._write_request(st_path, value)[1]) for st_path, value in items]
        for st_path, v in checked:
            self.write(st_path, v)

    @property
    def cycle(self) -> int:
        """The CNC's newest cycle (one request)."""
        if self._frozen:
            self._snapshot_register(0)
        return self._counter.update(int(self._read(self._cycle_request())[CYCLE_SIGNAL]))

    def close(self) -> None:
        self._client.close()

    def __repr__(self) -> str:
        return f"ModbusTransport({self.host!r}, {self.port}, word order {self.codec.word_order})"


_BITS: Final = (ModbusTable.COIL, ModbusTable.DISCRETE_INPUT)


class AsyncModbusTransport(_ModbusCommon):
    """Modbus TCP with pymodbus' ``AsyncModbusTcpClient``: for PLC tasks in an event loop.

    Same behaviour as :class:`ModbusTransport`; every method is a coroutine. Construct with
    ``await AsyncModbusTransport.connect(...)``.
    """

    is_async: ClassVar[bool] = True
    blocking: ClassVar[bool] = False

    def _make_client(self, host: str, port: int, timeout: float) -> Any:
        from pymodbus.client import AsyncModbusTcpClient

        return AsyncModbusTcpClient(host, port=port, timeout=timeout, retries=0)

    @classmethod
    async def connect(
        cls,
        host: str = "127.0.0.1",
        port: int = 5020,
        *,
        layout: Layout | str | os.PathLike[str],
        word_order: str = "ABCD",
        unit_id: int = 1,
        timeout: float = 2.0,
    ) -> AsyncModbusTransport:
        """Connect (raises :class:`TransportError` when no server answers). ``layout`` as a URL is
        fetched with a blocking request: prefer a :class:`Layout` or a file here."""
        transport = cls(host, port, layout=layout, word_order=word_order, unit_id=unit_id, timeout=timeout)
        if not await transport._client.connect():
            transport._client.close()
            raise transport._failed("connecting", ConnectionRefusedError("no answer"))
        return transport

    async def _call(self, what: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        from pymodbus.exceptions import ModbusException

        try:
            response = await fn(*args, device_id=self.unit_id, **kwargs)
        except (ModbusException, OSError) as exc:
            raise self._failed(what, exc) from exc
        return self._answer(what, response)

    async def _read(self, request: ReadRequest) -> dict[str, Value]:
        c = self._client
        fn = {
            ModbusTable.COIL: c.read_coils,
            ModbusTable.DISCRETE_INPUT: c.read_discrete_inputs,
            ModbusTable.HOLDING_REGISTER: c.read_holding_registers,
            ModbusTable.INPUT_REGISTER: c.read_input_registers,
        }[request.table]
        what = f"FC{request.function_code} read of {request.count} from address {request.address}"
        response = await self._call(what, fn, request.address, count=request.count)
        bits_or_regs = response.bits if request.table in _BITS else response.registers
        return self.codec.decode(request, bits_or_regs)

    async def _snapshot_register(self, value: int) -> bool:
        try:
            await self._call(
                f"FC6 write of the snapshot register {MODBUS_SNAPSHOT_REGISTER}",
                self._client.write_register,
                MODBUS_SNAPSHOT_REGISTER,
                value,
            )
        except TransportError as exc:
            return self._froze(value, exc)
        return self._froze(value, None)

    async def snapshot(self, watch: Collection[str] | None = None) -> Inputs:
        plan = self._plan(watch)
        frozen = self._wants_freeze(plan) and await self._snapshot_register(1)
        values: dict[str, Value] = {}
        for request in plan:
            values.update(await self._read(request))
        first = int(values[CYCLE_SIGNAL])
        last = None
        if len(plan) > 1 and not frozen:
            last = int((await self._read(self._cycle_request()))[CYCLE_SIGNAL])
        return self._inputs(values, first, last)

    async def read(self, st_path: str) -> Value:
        s = self.layout.signal(st_path)
        if self._frozen and self._is_input(s):
            await self._snapshot_register(0)
        return (await self._read(self.codec.read_requests([s])[0]))[s.st_path]

    async def write(self, st_path: str, value: Value) -> None:
        s, v = self._write_request(st_path, value)
        if s.modbus_table is ModbusTable.COIL:
            await self._call(f"FC5 write of {st_path}", self._client.write_coil, s.modbus_address, bool(v))
        else:
            regs = self.codec.registers(s, v)
            await self._call(f"FC16 write of {st_path}", self._client.write_registers, s.modbus_address, regs)

    async def write_many(self, items: Iterable[tuple[str, Value]]) -> None:
        checked = [(st_path, self._write_request(st_path, value)[1]) for st_path, value in items]
        for st_path, v in checked:
            await self.write(st_path, v)

    async def close(self) -> None:
        self._client.close()

    def __repr__(self) -> str:
        return f"AsyncModbusTransport({self.host!r}, {self.port}, word order {self.codec.word_order})"
