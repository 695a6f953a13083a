"""Modbus TCP transports (H-03): :class:`ModbusTransport` (pymodbus' synchronous client) and
:class:`AsyncModbusTransport` (its asyncio client), with the protocol's logic written once.

**One body, two loops.** What a snapshot, a read, a write or a look at the cycle does on the wire (which
requests, in which order, when the snapshot register freezes or thaws this connection's inputs, how
``cycle_r`` is unwrapped, what a Modbus exception answer means) is written once, in :class:`_ModbusCore`, as
generators that yield the requests they need (:class:`_Call`) and receive the answers: a sans-I/O core in
the way h11 is one. :meth:`ModbusTransport._drive` (blocking) and :meth:`AsyncModbusTransport._drive`
(``await``) are the two short loops that carry each request to pymodbus and the answer (or the
:class:`~plc_clients.transports.base.TransportError`) back. Chosen over a generated twin (httpcore's
``unasync``) because the logic then exists once in the source a reader opens, needs no code generator and no
drift check in CI, and the two loops are eight lines each; the cost is a generator frame per call, a few
microseconds against a network round trip.

**Consistency.** Modbus has no atomic read of several tables: each request is answered from one publish of
the CNC->PLC half, but two requests may fall into two CNC cycles. A snapshot reads only what is watched
(fewest requests, :mod:`plc_clients.modbus_codec`). When that takes more than one request it first writes 1
to the server's snapshot register (holding register :data:`~schemas.layout.MODBUS_SNAPSHOT_REGISTER`): the
server then answers this connection's reads of inputs from one copy of the newest publish, so the whole
snapshot is one CNC cycle (:attr:`Inputs.consistent` is True) for one request more. A later single read of
an input writes 0 first (live values again). Against a server without the register (it answers 0x02) the
transport reads ``cycle_r`` before and after instead, and ``consistent`` says whether both came from the
same publish.

pymodbus is imported only when a transport is made.
"""

from __future__ import annotations

import os
from collections.abc import Collection, Generator, Iterable
from dataclasses import dataclass, field
from typing import Any, ClassVar, Final

from plc_clients._closing import ClosesOnExit
from plc_clients.modbus_codec import ModbusCodec, ReadRequest
from plc_clients.transports.base import (
    CYCLE_SIGNAL,
    Inputs,
    TransportError,
    Value,
    _c2p_watch,
    _CycleCounter,
    load_layout,
)
from schemas.layout import MODBUS_SNAPSHOT_REGISTER, Layout, LayoutError, ModbusTable, Signal

__all__ = ["AsyncModbusTransport", "ModbusTransport"]


@dataclass(frozen=True, slots=True)
class _Call:
    """One request of the core: the pymodbus client method, its arguments, and how to name it in errors."""

    what: str
    method: str
    args: tuple[Any, ...]
    kwargs: dict[str, Any] = field(default_factory=dict)


_Steps = Generator[_Call, Any, Any]
"""A protocol operation: yields :class:`_Call`\\ s, is sent each answer (or thrown its TransportError),
returns the operation's result."""

_READ_METHOD: Final = {
    ModbusTable.COIL: "read_coils",
    ModbusTable.DISCRETE_INPUT: "read_discrete_inputs",
    ModbusTable.HOLDING_REGISTER: "read_holding_registers",
    ModbusTable.INPUT_REGISTER: "read_input_registers",
}
_BITS: Final = (ModbusTable.COIL, ModbusTable.DISCRETE_INPUT)
_EXCEPTION_HINT: Final = {
    0x02: " (illegal data address: the layout does not match the server's - load it from this server)",
    0x03: " (illegal data value)",
    0x0B: " (no such unit id: use the server's --modbus-unit-id)",
}


class _ModbusCore:
    """The Modbus transports' protocol logic, without I/O: layout, codec, the requests of each operation,
    the snapshot register's state, errors. Subclasses add a client and a loop (``_drive``)."""

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

    # --- the answers ------------------------------------------------------------------------------
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

    # --- the operations, as steps -----------------------------------------------------------------
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

    @staticmethod
    def _is_input(signal: Signal) -> bool:
        return signal.modbus_table in (ModbusTable.DISCRETE_INPUT, ModbusTable.INPUT_REGISTER)

    def _write_request(self, st_path: str, value: Value) -> tuple[Signal, Value]:
        s = self.layout.signal(st_path)
        s.check_plc_write()
        return s, s.coerce(value)

    def _read_steps(self, request: ReadRequest) -> _Steps:
        what = f"FC{request.function_code} read of {request.count} from address {request.address}"
        call = _Call(what, _READ_METHOD[request.table], (request.address,), {"count": request.count})
        response = yield call
        bits_or_regs = response.bits if request.table in _BITS else response.registers
        return self.codec.decode(request, bits_or_regs)

    def _snapshot_register_steps(self, value: int) -> _Steps:
        """Write the server's snapshot register: 1 freezes this connection's inputs, 0 thaws. False: the
        server has no such register (an older server answers 0x02)."""
        what = f"FC6 write of the snapshot register {MODBUS_SNAPSHOT_REGISTER}"
        try:
            yield _Call(what, "write_register", (MODBUS_SNAPSHOT_REGISTER, value))
        except TransportError as error:
            if error.modbus_exception != 0x02:
                raise
            self._has_snapshot_register = False
            self._frozen = False
            return False
        self._has_snapshot_register = True
        self._frozen = value == 1
        return True

    def _snapshot_steps(self, watch: Collection[str] | None) -> _Steps:
        plan = self._plan(watch)
        # a snapshot of several requests freezes (and so does any while frozen: a new copy)
        wants_freeze = (len(plan) > 1 or self._frozen) and self._has_snapshot_register is not False
        frozen = wants_freeze and (yield from self._snapshot_register_steps(1))
        values: dict[str, Value] = {}
        for request in plan:
            values.update((yield from self._read_steps(request)))
        first = int(values[CYCLE_SIGNAL])
        last = None
        if len(plan) > 1 and not frozen:
            last = int((yield from self._read_steps(self._cycle_request()))[CYCLE_SIGNAL])
        cycle = self._counter.update(first)
        return Inputs(cycle, values, last is None or last == first)

    def _read_one_steps(self, st_path: str) -> _Steps:
        s = self.layout.signal(st_path)
        if self._frozen and self._is_input(s):
            yield from self._snapshot_register_steps(0)
        return (yield from self._read_steps(self.codec.read_requests([s])[0]))[s.st_path]

    def _write_steps(self, st_path: str, value: Value) -> _Steps:
        s, v = self._write_request(st_path, value)
        if s.modbus_table is ModbusTable.COIL:
            yield _Call(f"FC5 write of {st_path}", "write_coil", (s.modbus_address, bool(v)))
        else:
            regs = self.codec.registers(s, v)
            yield _Call(f"FC16 write of {st_path}", "write_registers", (s.modbus_address, regs))

    def _write_many_steps(self, items: Iterable[tuple[str, Value]]) -> _Steps:
        """One request per field, in the given order (check all first)."""
        checked = [(st_path, self._write_request(st_path, value)[1]) for st_path, value in items]
        for st_path, v in checked:
            yield from self._write_steps(st_path, v)

    def _cycle_steps(self) -> _Steps:
        if self._frozen:
            yield from self._snapshot_register_steps(0)
        return self._counter.update(int((yield from self._read_steps(self._cycle_request()))[CYCLE_SIGNAL]))


class ModbusTransport(_ModbusCore, ClosesOnExit):
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

    def _call(self, call: _Call) -> Any:
        from pymodbus.exceptions import ModbusException

        try:
            method = getattr(self._client, call.method)
            response = method(*call.args, device_id=self.unit_id, **call.kwargs)
        except (ModbusException, OSError) as exc:
            raise self._failed(call.what, exc) from exc
        return self._answer(call.what, response)

    def _drive(self, steps: _Steps) -> Any:
        """The blocking loop: each request of ``steps`` to the client, its answer (or error) back."""
        try:
            call = next(steps)
            while True:
                try:
                    answer = self._call(call)
                except TransportError as exc:
                    call = steps.throw(exc)
                else:
                    call = steps.send(answer)
        except StopIteration as done:
            return done.value

    def snapshot(self, watch: Collection[str] | None = None) -> Inputs:
        result: Inputs = self._drive(self._snapshot_steps(watch))
        return result

    def read(self, st_path: str) -> Value:
        result: Value = self._drive(self._read_one_steps(st_path))
        return result

    def write(self, st_path: str, value: Value) -> None:
        self._drive(self._write_steps(st_path, value))

    def write_many(self, items: Iterable[tuple[str, Value]]) -> None:
        """One request per field, in the given order (check all first)."""
        self._drive(self._write_many_steps(items))

    @property
    def cycle(self) -> int:
        """The CNC's newest cycle (one request)."""
        result: int = self._drive(self._cycle_steps())
        return result

    def close(self) -> None:
        self._client.close()

    def __repr__(self) -> str:
        return f"ModbusTransport({self.host!r}, {self.port}, word order {self.codec.word_order})"


class AsyncModbusTransport(_ModbusCore):
    """Modbus TCP with pymodbus' ``AsyncModbusTcpClient``: for PLC tasks in an event loop.

    Same behaviour as :class:`ModbusTransport` (the same core); every method is a coroutine. Construct
    with ``await AsyncModbusTransport.connect(...)``.
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

    async def _call(self, call: _Call) -> Any:
        from pymodbus.exceptions import ModbusException

        try:
            response = await getattr(self._client, call.method)(
                *call.args, device_id=self.unit_id, **call.kwargs
            )
        except (ModbusException, OSError) as exc:
            raise self._failed(call.what, exc) from exc
        return self._answer(call.what, response)

    async def _drive(self, steps: _Steps) -> Any:
        """The asyncio loop: each request of ``steps`` to the client, its answer (or error) back."""
        try:
            call = next(steps)
            while True:
                try:
                    answer = await self._call(call)
                except TransportError as exc:
                    call = steps.throw(exc)
                else:
                    call = steps.send(answer)
        except StopIteration as done:
            return done.value

    async def snapshot(self, watch: Collection[str] | None = None) -> Inputs:
        result: Inputs = await self._drive(self._snapshot_steps(watch))
        return result

    async def read(self, st_path: str) -> Value:
        result: Value = await self._drive(self._read_one_steps(st_path))
        return result

    async def write(self, st_path: str, value: Value) -> None:
        await self._drive(self._write_steps(st_path, value))

    async def write_many(self, items: Iterable[tuple[str, Value]]) -> None:
        await self._drive(self._write_many_steps(items))

    async def close(self) -> None:
        self._client.close()

    def __repr__(self) -> str:
        return f"AsyncModbusTransport({self.host!r}, {self.port}, word order {self.codec.word_order})"
