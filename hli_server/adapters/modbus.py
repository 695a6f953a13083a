"""Modbus TCP view of the process image (H-03).

The four Modbus tables are views on the two halves of the image, addressed as the one layout table
says (:mod:`schemas.layout`: ``Signal.modbus_table`` / ``modbus_address``):

=================== ===================== ======================================== ===========
table               function codes        signals                                  half
=================== ===================== ======================================== ===========
coils               1 read, 5, 15 write   BOOL PLC->CNC (``enable_w``, ``start_w``) PLC->CNC
                                          and BOOLEAN V.E. variables (1200..1899)
discrete inputs     2 read                BOOL CNC->PLC (``state_r``, flags)        CNC->PLC
holding registers   3, 23 read; 6, 16, 23 DINT/UDINT PLC->CNC (``command_w``)       PLC->CNC
                                          and numeric V.E. variables (1200..1899)
input registers     4 read                DINT/UDINT/LREAL CNC->PLC                 CNC->PLC
=================== ===================== ======================================== ===========

The V.E. variables (N-05) are written by the NC as well: a read returns the value last stored by
either side (hli_server/image/external.py); a write outside the range of the variable's kernel type
(an SGN16 carried in a DINT) is refused with exception 0x03. A V.E. STRING is its bytes two to a
register (``hli_server/codecs/modbus_words.py``; no word order), read and written whole; a write whose
bytes hold no NUL within the field (a character too many) or a byte that is no Windows-1252 character
is refused with exception 0x03.

* **Live.** A read of coils or holding registers returns the PLC->CNC half as it is now (what any
  PLC door, shared memory, ADS or Modbus, wrote last); a read of discrete inputs or input registers
  returns the newest consistent publish of the CNC->PLC half. A write lands in the PLC->CNC half at
  once (one store per field) and is latched by the engine at the start of the next cycle.
* **32-bit and 64-bit values** take two (four) registers. Word order ``ABCD`` (default: the most
  significant word first, each word big-endian, as pymodbus and most devices) or ``CDAB`` (the
  least significant word first: Schneider style, mbpoll's default). Example: DINT -2 = 0xFFFFFFFE
  is ``[0xFFFF, 0xFFFE]`` in ABCD and ``[0xFFFE, 0xFFFF]`` in CDAB; 100000 = 0x000186A0 is
  ``[0x0001, 0x86A0]`` / ``[0x86A0, 0x0001]``.
* **Exceptions** (each carries its wire code from where it is raised): an address no signal
  occupies, a range that cuts a 32/64-bit value, a write to a CNC->PLC value (its address is not in
  the written table) = 0x02; a value the field cannot take (FC5 other than 0xFF00/0x0000, a value
  the image refuses) or a malformed request PDU = 0x03; a function code other than 1, 2, 3, 4, 5,
  6, 15, 16, 23 = 0x01; an unexpected fault while serving = 0x04 (logged with a traceback).
* **Unit id.** The server answers its unit id (default 1), 0 and 255 (the Implementation Guide's
  value for "the device addressed by its IP address"). Other unit ids get exception 0x0B (gateway
  target device failed to respond), the answer of a Modbus TCP gateway that has no such device
  behind it, so that a client with a wrong unit id fails at once instead of waiting for a time-out
  (``unknown_unit="exception"``, the default); ``unknown_unit="ignore"`` drops them without an
  answer, as a serial slave that is not addressed does.
* **Consistent snapshots.** One request is answered from one publish; a PLC that reads more than one
  request's worth of inputs (two tables, distant addresses, more than 125 registers) can have them
  all from one publish: writing 1 to holding register ``MODBUS_SNAPSHOT_REGISTER`` (1900, FC 6)
  freezes *this connection's* reads of discrete inputs and input registers on a copy of the newest
  publish, taken at that write, until the connection writes the register again (1: a new copy,
  0: live again; other values: 0x03). Other connections are not affected; the copy is the
  connection's, not the machine's. ``plc_clients``' Modbus transports freeze before every snapshot
  of more than one request (docs/modbus.md).
* **Pipelining.** Requests are answered one by one, in the order they arrived, however they are
  split into TCP segments: several in one segment, one across several. The framing is the sans-I/O
  :class:`~hli_server.codecs.modbus_frames.MbapDecoder`; each request is served synchronously from
  the image (no awaits between a request and its answer), so answers cannot overtake each other.
  A plain pymodbus 3.16 server answers only the first of several pipelined requests (its transport
  keeps one pending request; pymodbus-dev/pymodbus#1949), which is why this adapter frames and
  serves requests itself.
* **Malformed input never stops the server.** A bad PDU gets its exception and the next request on
  the connection is served; an ADU with a protocol id other than 0 is dropped; an MBAP length field
  out of range (the stream cannot be resynchronised) closes that connection only.

pymodbus: this adapter does not need pymodbus' server, datastore or PDU classes (the PDU codec
lives in :mod:`hli_server.codecs.modbus_frames`, which checks what pymodbus 3.16's request classes
let through: coil values other than 0xFF00/0x0000, byte counts). pymodbus is the client of the
integration tests, the oracle of the codec's unit tests and the reference server of the benchmark.
"""

from __future__ import annotations

import asyncio
import logging
import struct
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from operator import itemgetter
from typing import TYPE_CHECKING, Any, ClassVar, Final, Literal

from pydantic import Field, ValidationError, field_validator

from hli_server.adapters.faults import CommFaults, Door
from hli_server.adapters.tcp import (
    AddressAllowlist,
    Admission,
    ConnectionSlots,
    TcpDoorOptions,
    close,
    listen,
)
from hli_server.codecs.modbus_frames import (
    MAX_ADU,
    MBAP_HEADER,
    MBAP_SIZE,
    ExceptionCode,
    Frame,
    MbapDecoder,
    ModbusError,
    ReadBits,
    ReadRegisters,
    ReadWriteRegisters,
    Request,
    WriteCoils,
    WriteRegisters,
    WriteSingleCoil,
    WriteSingleRegister,
    decode_request,
    encode_adu,
    encode_exception,
    encode_read_registers,
    encode_write_multiple,
)
from hli_server.codecs.modbus_words import WORD_ORDERS, check_word_order, decode_value, swap_words
from schemas.image_format import decode_field
from schemas.layout import (
    MODBUS_SNAPSHOT_REGISTER,
    Direction,
    Layout,
    ModbusTable,
    ReadOnlySignalError,
    Signal,
    SignalValueError,
)

if TYPE_CHECKING:
    from hli_server.adapters.host import AdapterHost, ImagePort

__all__ = [
    "DEFAULT_PORT",
    "WORD_ORDERS",
    "ModbusAdapter",
    "ModbusOptions",
    "ModbusServer",
    "RegisterMap",
    "Session",
]

logger = logging.getLogger(__name__)

DEFAULT_PORT: Final = 5020
"""Not 502: binding ports below 1024 needs privileges. ``--modbus-port 502`` where allowed."""
UNKNOWN_UNIT_POLICIES: Final = ("exception", "ignore")
ANY_UNIT_IDS: Final = frozenset({0, 255})
"""Unit ids answered besides the configured one: 0 and 255 mean "this device" on Modbus TCP."""
BATCH: Final = 32
"""Frames answered per turn of one connection before the others (and the clock) get theirs."""
_MIN_ADU: Final = MBAP_SIZE + 1
"""The shortest ADU: the MBAP header and a function code (length field 2)."""
READER_CACHE_SIZE: Final = 4096
"""Compiled readers kept per server (one per distinct read request); cleared when full."""

_P2C: Final = Direction.PLC_TO_CNC
_C2P: Final = Direction.CNC_TO_PLC
_TABLE_OF_FC: Final = {
    1: ModbusTable.COIL,
    2: ModbusTable.DISCRETE_INPUT,
    3: ModbusTable.HOLDING_REGISTER,
    4: ModbusTable.INPUT_REGISTER,
}
_FREEZE_PDU_HEAD: Final = bytes((6,)) + MODBUS_SNAPSHOT_REGISTER.to_bytes(2, "big")
"""FC 6 to the snapshot register: the first three bytes of a freeze request's PDU."""
_TABLE_TEXT: Final = {
    ModbusTable.COIL: "coil",
    ModbusTable.DISCRETE_INPUT: "discrete input",
    ModbusTable.HOLDING_REGISTER: "holding register",
    ModbusTable.INPUT_REGISTER: "input register",
}


# --------------------------------------------------------------------------------------------
# The register map: Modbus requests against the image (no I/O)
# --------------------------------------------------------------------------------------------

Reader = Callable[[], bytes]
"""A compiled read: returns the response PDU (or an exception PDU) from the image as it is now."""


@dataclass(slots=True)
class _Span:
    signal: Signal
    first: int
    """address of the first register/bit of the signal"""


class RegisterMap:
    """Serves decoded Modbus requests from a :class:`ImagePort` (H-03). Synchronous, no I/O.

    ``execute(request)`` returns the response PDU or raises :class:`ModbusError`. ``read(pdu)``
    is the fast path of FC 1-4: the request PDU's bytes select a compiled reader (cached), which
    checks nothing at run time because the layout does not change while the server runs.
    """

    def __init__(self, image: ImagePort, word_order: str = "ABCD", *, read_only: bool = False) -> None:
        order = check_word_order(word_order)
        self.read_only = read_only
        """``--read-only``: every write function is refused with exception 0x01 (docs/reliability.md)."""
        self.image = image
        self.layout: Layout = image.layout
        self.word_order = order
        self._index = {t: self.layout.modbus_index(t) for t in ModbusTable}
        self._readers: dict[bytes, Reader] = {}
        self._c2p_count = -1
        self._c2p = b""
        self._publish_count = self.image.publish_counter()
        self.frozen: bytes | None = None
        """The CNC->PLC half the current request is served from when its connection froze one."""

    # --- the halves --------------------------------------------------------------------------
    def _p2c_half(self) -> bytes:
        return self.image.read_half(_P2C)

    def _c2p_half(self) -> bytes:
        """The newest consistent CNC->PLC publish (copied again only after a new publish), or the
        copy the requesting connection froze (:class:`Session`)."""
        if self.frozen is not None:
            return self.frozen
        count = self._publish_count()
        if count != self._c2p_count:
            self._c2p = self.image.snapshot()[1]
            self._c2p_count = count
        return self._c2p

    # --- addressing --------------------------------------------------------------------------
    def reference(self, table: ModbusTable, address: int) -> str:
        """``address 2000 (reference 42001)``: both numbers, as a PLC programmer may think of either."""
        width = self.layout.reference_digits - 1
        reference = f"{table.reference_prefix}{address + 1:0{width}d}"
        return f"{_TABLE_TEXT[table]} address {address} (reference {reference})"

    def spans(self, table: ModbusTable, address: int, count: int) -> list[_Span]:
        """The signals that exactly cover ``address .. address + count - 1`` of ``table``.

        Raises 0x02 when an address is unoccupied, or when the range starts or ends inside a
        32/64-bit value (a partial access would tear the value).
        """
        index = self._index[table]
        spans: list[_Span] = []
        a = address
        end = address + count
        while a < end:
            slot = index.get(a)
            if slot is None:
                raise ModbusError(
                    ExceptionCode.ILLEGAL_DATA_ADDRESS,
                    f"no signal at {self.reference(table, a)}; `hli-server map` lists the addresses",
                )
            signal, part = slot
            width = signal.modbus_count
            if part != 0 or a + width > end:
                first = a - part
                raise ModbusError(
                    ExceptionCode.ILLEGAL_DATA_ADDRESS,
                    f"{self.reference(table, address)} x {count} cuts {signal.st_path} "
                    f"({signal.type_name}, {width} registers from address {first}): "
                    "read and write 32/64-bit values and strings whole",
                )
            spans.append(_Span(signal, a))
            a += width
        return spans

    # --- reads -------------------------------------------------------------------------------
    def read(self, pdu: bytes) -> bytes | None:
        """Response PDU of a read request PDU (FC 1-4, exactly 5 bytes), or None for other PDUs."""
        reader = self._readers.get(pdu)
        if reader is None:
            if len(pdu) != 5 or pdu[0] not in _TABLE_OF_FC:
                return None
            reader = self._compile_read(pdu)
            if len(self._readers) >= READER_CACHE_SIZE:
                self._readers.clear()
            self._readers[bytes(pdu)] = reader
        return reader()

    def _compile_read(self, pdu: bytes) -> Reader:
        fc = pdu[0]
        try:
            request = decode_request(pdu)
            assert isinstance(request, (ReadBits, ReadRegisters))
            table = _TABLE_OF_FC[fc]
            spans = self.spans(table, request.address, request.count)
        except ModbusError as exc:
            answer = encode_exception(fc, exc.code)
            message = str(exc)

            def refuse() -> bytes:
                logger.debug("refused: %s", message)
                return answer

            return refuse
        half = self._p2c_half if table in (ModbusTable.COIL, ModbusTable.HOLDING_REGISTER) else self._c2p_half
        if table in (ModbusTable.COIL, ModbusTable.DISCRETE_INPUT):
            return self._bit_reader(fc, half, [s.signal.offset for s in spans])
        return self._register_reader(fc, half, [s.signal for s in spans])

    @staticmethod
    def _bit_reader(fc: int, half: Callable[[], bytes], offsets: list[int]) -> Reader:
        count = len(offsets)
        nbytes = (count + 7) // 8
        head = bytes((fc, nbytes))
        if count == 1:
            (only,) = offsets

            def read_one() -> bytes:
                return head + (b"\x01" if half()[only] else b"\x00")

            return read_one
        getter = itemgetter(*offsets)

        def read_bits() -> bytes:
            acc = 0
            for i, byte in enumerate(getter(half())):
                if byte:
                    acc |= 1 << i
            return head + acc.to_bytes(nbytes, "little")

        return read_bits

    def _register_reader(self, fc: int, half: Callable[[], bytes], signals: list[Signal]) -> Reader:
        """One ``unpack_from`` of the fields (in byte order, with padding), one ``pack`` of the
        registers (in address order); CDAB swaps the bytes of each word of the little-endian pack."""
        by_offset = sorted(range(len(signals)), key=lambda i: signals[i].offset)
        start = signals[by_offset[0]].offset
        fmt = ["<"]
        cursor = start
        for i in by_offset:
            s = signals[i]
            if s.offset > cursor:
                fmt.append(f"{s.offset - cursor}x")
            fmt.append(s.struct_char)
            cursor = s.offset + s.size
        unpack_from = struct.Struct("".join(fmt)).unpack_from
        # a STRING's bytes go out as they are, NUL-padded to its registers (``Ns`` packs so)
        chars = "".join(f"{2 * s.modbus_count}s" if s.string_size else s.struct_char for s in signals)
        texts = [i for i, s in enumerate(signals) if s.string_size]
        order = [by_offset.index(i) for i in range(len(signals))]
        permute = None if order == sorted(order) else itemgetter(*order)
        nbytes = 2 * sum(s.modbus_count for s in signals)
        head = bytes((fc, nbytes))
        if self.word_order == "ABCD":
            pack = struct.Struct(">" + chars).pack

            def read_abcd() -> bytes:
                values = unpack_from(half(), start)
                if permute is not None:
                    values = permute(values)
                return head + pack(*values)

            return read_abcd
        pack_le = struct.Struct("<" + chars).pack
        if texts:  # CDAB swaps the bytes of every word after the pack: a STRING's are swapped before
            widths = {i: 2 * signals[i].modbus_count for i in texts}

            def read_cdab_texts() -> bytes:
                values = list(unpack_from(half(), start))
                if permute is not None:
                    values = list(permute(values))
                for i in texts:
                    values[i] = swap_words(values[i].ljust(widths[i], b"\0"))
                return head + swap_words(pack_le(*values))

            return read_cdab_texts

        def read_cdab() -> bytes:
            values = unpack_from(half(), start)
            if permute is not None:
                values = permute(values)
            return head + swap_words(pack_le(*values))

        return read_cdab

    def read_registers(self, fc: int, address: int, count: int) -> bytes:
        """Response PDU of a register read (FC 3/4, and the read half of FC 23)."""
        pdu = bytes((fc,)) + struct.pack(">HH", address, count)
        answer = self.read(pdu)
        assert answer is not None
        if answer[0] & 0x80:
            raise ModbusError(ExceptionCode(answer[1]), self._refusal(fc, address, count))
        return answer

    def _refusal(self, fc: int, address: int, count: int) -> str:
        try:
            self.spans(_TABLE_OF_FC[fc], address, count)
        except ModbusError as exc:
            return str(exc.args[0])
        return f"read of {count} at {address} refused"  # pragma: no cover - spans() raised before

    # --- writes ------------------------------------------------------------------------------
    def _decode_register_value(self, signal: Signal, data: bytes) -> int | float | str:
        if signal.string_size:
            try:
                return decode_field(signal, data[: signal.size])
            except SignalValueError as exc:
                raise ModbusError(ExceptionCode.ILLEGAL_DATA_VALUE, str(exc)) from None
        return decode_value(signal.struct_char, data, self.word_order)

    def _commit(self, fc: int, writes: list[tuple[Signal, object]]) -> None:
        """Check every value first, then write them all: a refused request changes nothing."""
        if self.read_only:
            raise ModbusError(
                ExceptionCode.ILLEGAL_FUNCTION, f"FC {fc}: the server runs --read-only, writes are refused"
            )
        checked: list[tuple[Signal, bool | int | float | str]] = []
        for signal, value in writes:
            try:
                signal.check_plc_write()
                checked.append((signal, signal.coerce(value)))
            except ReadOnlySignalError as exc:  # pragma: no cover - CNC->PLC signals are in other tables
                raise ModbusError(ExceptionCode.ILLEGAL_DATA_ADDRESS, f"function {fc}: {exc}") from None
            except SignalValueError as exc:
                raise ModbusError(ExceptionCode.ILLEGAL_DATA_VALUE, f"function {fc}: {exc}") from None
        write = self.image.write_signal
        for signal, value in checked:
            try:
                write(signal, value)
            except SignalValueError as exc:  # the image's own range checks, if it has any
                raise ModbusError(ExceptionCode.ILLEGAL_DATA_VALUE, f"function {fc}: {exc}") from None
            except ReadOnlySignalError as exc:  # pragma: no cover - see above
                raise ModbusError(ExceptionCode.ILLEGAL_DATA_ADDRESS, f"function {fc}: {exc}") from None

    def _register_writes(self, fc: int, address: int, data: bytes) -> list[tuple[Signal, object]]:
        spans = self.spans(ModbusTable.HOLDING_REGISTER, address, len(data) // 2)
        writes: list[tuple[Signal, object]] = []
        for span in spans:
            pos = 2 * (span.first - address)
            chunk = data[pos : pos + 2 * span.signal.modbus_count]
            writes.append((span.signal, self._decode_register_value(span.signal, chunk)))
        return writes

    def execute(self, request: Request, pdu: bytes) -> bytes:
        """Serve one decoded request; ``pdu`` is its raw PDU (FC 5/6 echo it)."""
        if isinstance(request, (ReadBits, ReadRegisters)):
            answer = self.read(pdu)
            assert answer is not None
            return answer
        if isinstance(request, WriteSingleCoil):
            spans = self.spans(ModbusTable.COIL, request.address, 1)
            self._commit(request.function_code, [(spans[0].signal, request.value)])
            return pdu
        if isinstance(request, WriteCoils):
            spans = self.spans(ModbusTable.COIL, request.address, request.count)
            self._commit(
                request.function_code,
                [(s.signal, v) for s, v in zip(spans, request.values, strict=True)],
            )
            return encode_write_multiple(request.function_code, request.address, request.count)
        if isinstance(request, WriteSingleRegister):
            writes = self._register_writes(request.function_code, request.address, request.data)
            self._commit(request.function_code, writes)
            return pdu
        if isinstance(request, WriteRegisters):
            writes = self._register_writes(request.function_code, request.address, request.data)
            self._commit(request.function_code, writes)
            return encode_write_multiple(request.function_code, request.address, request.count)
        if isinstance(request, ReadWriteRegisters):
            fc = request.function_code
            writes = self._register_writes(fc, request.write_address, request.data)
            self.spans(ModbusTable.HOLDING_REGISTER, request.read_address, request.read_count)
            self._commit(fc, writes)  # V1.1b3 6.17: the write is performed before the read
            registers = self.read_registers(3, request.read_address, request.read_count)
            return encode_read_registers(fc, registers[2:])
        raise ModbusError(ExceptionCode.ILLEGAL_FUNCTION, f"function {request.function_code} is not served")


# --------------------------------------------------------------------------------------------
# The server: frames in, answers out, in order
# --------------------------------------------------------------------------------------------


@dataclass(slots=True)
class ServerStats:
    """Counters since start (for the log, tests and ``GET /api/...`` later)."""

    connections: int = 0
    requests: int = 0
    exceptions: dict[int, int] = field(default_factory=dict)
    dropped: int = 0
    """frames not answered: protocol id not 0, or an unknown unit id with ``unknown_unit="ignore"``"""
    broken_streams: int = 0
    """connections closed because an MBAP length field could not be resynchronised"""
    refused: int = 0
    """connections refused at max_connections (kept for the counters' shape: the door now makes room)"""
    evicted: int = 0
    """connections closed to make room for a new client (the one served longest ago)"""
    idle_closed: int = 0
    """connections closed after idle_timeout_s seconds of silence"""
    frame_timeouts: int = 0
    """connections closed because a frame did not complete within frame_timeout_s seconds"""
    not_allowed: int = 0
    """connections closed at once: the peer's address is not in the allowlist (``allow``)"""


@dataclass(slots=True)
class Session:
    """What one connection holds: the copy of the CNC->PLC half it froze (``(cycle, half)``) or None.

    Connection state, not machine state: the adapter still keeps nothing of the machine's own."""

    frozen: tuple[int, bytes] | None = None


class ModbusServer:
    """Answers Modbus TCP frames from a :class:`RegisterMap` (no I/O; :meth:`answer` is sync)."""

    def __init__(
        self,
        register_map: RegisterMap,
        *,
        unit_id: int = 1,
        unknown_unit: str = "exception",
    ) -> None:
        if not 0 <= unit_id <= 255:
            raise ValueError(f"Modbus unit id {unit_id} is outside 0..255")
        if unknown_unit not in UNKNOWN_UNIT_POLICIES:
            raise ValueError(f"unknown_unit={unknown_unit!r}: use one of {', '.join(UNKNOWN_UNIT_POLICIES)}")
        self.map = register_map
        self.unit_id = unit_id
        self.unknown_unit = unknown_unit
        self.units = frozenset({unit_id}) | ANY_UNIT_IDS
        self.stats = ServerStats()

    def answer(self, frame: Frame, session: Session | None = None) -> bytes | None:
        """The response ADU of one frame, or None when the frame gets no answer. ``session``: the
        connection's state (the consistent snapshot it froze); without one nothing can be frozen."""
        tid, pid, unit, pdu = frame
        self.stats.requests += 1
        if pid != 0:
            self.stats.dropped += 1
            logger.debug("dropped an ADU with protocol id %d (not Modbus)", pid)
            return None
        fc = pdu[0] if pdu else 0
        if unit not in self.units:
            if self.unknown_unit == "ignore":
                self.stats.dropped += 1
                return None
            return self._exception(tid, unit, fc, ExceptionCode.GATEWAY_TARGET_FAILED_TO_RESPOND)
        if session is not None and pdu[:3] == _FREEZE_PDU_HEAD and len(pdu) == 5:
            return self._freeze(tid, unit, pdu, session)
        self.map.frozen = session.frozen[1] if session is not None and session.frozen is not None else None
        try:
            answer = self.map.read(pdu)
            if answer is None:
                answer = self.map.execute(decode_request(pdu), pdu)
            elif answer[0] & 0x80:
                self._count(answer[1])
        except ModbusError as exc:
            logger.debug("unit %d, transaction %d: %s", unit, tid, exc)
            return self._exception(tid, unit, fc, exc.code)
        except Exception:
            logger.exception("Modbus request %s (unit %d, transaction %d) failed", pdu.hex(" "), unit, tid)
            return self._exception(tid, unit, fc, ExceptionCode.SERVER_DEVICE_FAILURE)
        finally:
            self.map.frozen = None
        return encode_adu(tid, unit, answer)

    def _freeze(self, tid: int, unit: int, pdu: bytes, session: Session) -> bytes:
        """FC 6 to the snapshot register: 1 freezes a copy of the newest publish, 0 thaws."""
        value = int.from_bytes(pdu[3:5], "big")
        if value == 1:
            session.frozen = self.map.image.snapshot()
        elif value == 0:
            session.frozen = None
        else:
            logger.debug("snapshot register: %d is neither 1 (freeze) nor 0 (live)", value)
            return self._exception(tid, unit, 6, ExceptionCode.ILLEGAL_DATA_VALUE)
        return encode_adu(tid, unit, pdu)

    def _count(self, code: int) -> None:
        self.stats.exceptions[code] = self.stats.exceptions.get(code, 0) + 1

    def _exception(self, tid: int, unit: int, fc: int, code: ExceptionCode) -> bytes:
        self._count(code)
        return encode_adu(tid, unit, encode_exception(fc, code))


class _Connection(asyncio.Protocol):
    """One client: its requests are answered in order, in turns of at most ``BATCH`` frames.

    A client that pipelines thousands of requests (or never reads its answers) must neither delay the
    cycle nor starve another client (reliability.md, round 1, finding 5): after a turn of ``BATCH`` frames
    the rest waits in this connection's queue, reading from the socket is paused, and the next turn is
    scheduled behind every other ready callback (the clock's wake-up and the other connections' turns
    included). Reading resumes when the queue is empty and the client reads its answers (asyncio's write
    high-water mark pauses us too). Input held per connection is therefore bounded by one socket read.
    """

    def __init__(self, adapter: ModbusAdapter) -> None:
        self._adapter = adapter
        self._server = adapter.server
        self._gate = adapter.faults.gate(Door.MODBUS, None)
        self._decoder = MbapDecoder()
        self._session = Session()
        self._transport: asyncio.Transport | None = None
        self._raw: asyncio.Transport | None = None
        """The socket's own transport (``_transport`` is the fault gate's wrapper of it): the fast path's."""
        self._peer: Any = None
        self._queue: deque[Frame] = deque()
        self._turn: asyncio.Handle | None = None
        self._write_paused = False
        self.last_active = time.monotonic()
        self.connected_at = self.last_active
        self.last_answered: float | None = None
        """When a request of this client was last answered (None until one is)."""
        self.partial_since: float | None = None
        """When the bytes of the incomplete frame held back began to arrive (None: no partial frame)."""
        self._idle: asyncio.TimerHandle | None = None
        self._frame_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        self._peer = transport.get_extra_info("peername")
        if not self._adapter.allowlist.allows(self._peer):
            self._server.stats.not_allowed += 1
            logger.info("Modbus: closed a connection from %s: not in the allowlist (allow)", self._peer)
            transport.abort()
            self._transport = None
            return
        if not self._adapter._accept(self, self._peer):
            transport.abort()
            self._transport = None
            return
        self._gate = self._adapter.faults.gate(Door.MODBUS, transport)  # communication faults on demand
        self._transport = self._gate.transport
        self._raw = transport
        self._server.stats.connections += 1
        logger.debug("Modbus: connection from %s", self._peer)
        self._arm_idle()

    def _arm_idle(self) -> None:
        timeout = self._adapter.idle_timeout
        if timeout > 0:
            self._idle = asyncio.get_running_loop().call_later(timeout, self._idle_check)

    def _idle_check(self) -> None:
        self._idle = None
        if self._transport is None:
            return
        quiet = time.monotonic() - self.last_active
        timeout = self._adapter.idle_timeout
        if quiet >= timeout and not self._queue:
            logger.info(
                "Modbus: closing connection from %s: silent for %.0f s (idle_timeout_s)", self._peer, quiet
            )
            self._server.stats.idle_closed += 1
            self._transport.close()
            return
        self._idle = asyncio.get_running_loop().call_later(max(timeout - quiet, 0.05), self._idle_check)

    def _frame_check(self) -> None:
        """A frame must complete within ``frame_timeout`` of its first byte (reliability.md, round 2, finding
        3: a byte every 1.5 s kept a connection "active" for ever)."""
        self._frame_timer = None
        began, transport = self.partial_since, self._transport
        if began is None or transport is None or transport.is_closing():
            return
        timeout = self._adapter.frame_timeout
        waited = time.monotonic() - began
        if waited >= timeout:
            self._server.stats.frame_timeouts += 1
            logger.info(
                "Modbus: closing connection from %s: a frame did not complete within %.1f s "
                "(frame_timeout_s)",
                self._peer,
                timeout,
            )
            transport.abort()
            return
        self._frame_timer = asyncio.get_running_loop().call_later(timeout - waited, self._frame_check)

    def data_received(self, data: bytes) -> None:
        raw = self._raw
        if raw is None or raw.is_closing():
            return
        now = self.last_active = time.monotonic()
        decoder = self._decoder
        size = len(data)
        if (  # the fast path: this read is one whole ADU, nothing else waits, no fault acts
            _MIN_ADU <= size <= MAX_ADU
            and size == 6 + (data[4] << 8 | data[5])
            and self._turn is None
            and not self._queue
            and not decoder.pending
            and self._gate.quiet
        ):
            self.partial_since = None
            tid, pid, _, unit = MBAP_HEADER.unpack_from(data)
            reply = self._server.answer(Frame(tid, pid, unit, data[MBAP_SIZE:]), self._session)
            if reply:
                raw.write(reply)
                self.last_answered = now
            return
        transport = self._transport
        if transport is None or transport.is_closing():
            return
        self._queue.extend(decoder.feed(data))
        if not decoder.pending:
            self.partial_since = None
        elif self.partial_since is None:
            self.partial_since = now
            if self._frame_timer is None and self._adapter.frame_timeout > 0:
                self._frame_timer = asyncio.get_running_loop().call_later(
                    self._adapter.frame_timeout, self._frame_check
                )
        if decoder.broken is not None:
            self._server.stats.broken_streams += 1
            logger.warning("Modbus: closing connection from %s: %s", self._peer, self._decoder.broken)
        if self._turn is None:
            self._serve()

    def _serve(self) -> None:
        """One turn: answer up to BATCH queued frames with one write, then yield if more wait."""
        self._turn = None
        transport = self._transport
        if transport is None or transport.is_closing():
            self._queue.clear()
            return
        queue, answer, session, gate = self._queue, self._server.answer, self._session, self._gate
        out: list[bytes] = []
        for _ in range(min(BATCH, len(queue))):
            frame = queue.popleft()
            reply = gate.modbus(frame)  # a fault's answer (adapters/faults.py), or None: serve it
            if reply is None:
                reply = answer(frame, session)
            if reply:
                out.append(reply)
        if out:
            transport.write(out[0] if len(out) == 1 else b"".join(out))
            self.last_answered = time.monotonic()
        if queue and not self._write_paused:
            transport.pause_reading()
            self._turn = asyncio.get_running_loop().call_soon(self._serve)
        elif not queue:
            if self._decoder.broken is not None:
                transport.close()
            elif not self._write_paused:
                transport.resume_reading()

    def pause_writing(self) -> None:
        """The client does not read its answers: stop reading and answering until it does."""
        self._write_paused = True
        if self._transport is not None:
            self._transport.pause_reading()
        if self._turn is not None:
            self._turn.cancel()
            self._turn = None

    def resume_writing(self) -> None:
        self._write_paused = False
        if self._transport is not None and not self._transport.is_closing():
            if self._queue:
                self._serve()
            else:
                self._transport.resume_reading()

    def connection_lost(self, exc: Exception | None) -> None:
        self._adapter._forget(self)
        self._transport = self._raw = None
        self._queue.clear()
        for handle in (self._turn, self._idle, self._frame_timer):
            if handle is not None:
                handle.cancel()
        self._turn = self._idle = self._frame_timer = None

    def idle_since(self, now: float) -> float:
        """When the client was last active; ``now`` while requests of it wait for their turn."""
        return self.last_active if not self._queue and self._turn is None else now

    def usefulness(self, now: float) -> tuple[int, float]:
        """``adapters/tcp.py``, ``least_useful``: never answered (by connect time) before answered (by
        the last answer); ``now`` while requests of it wait for their turn."""
        if self._queue or self._turn is not None:
            return (1, now)
        if self.last_answered is None:
            return (0, self.connected_at)
        return (1, self.last_answered)

    def abort(self) -> None:
        if self._transport is not None:
            self._transport.abort()


class ModbusOptions(TcpDoorOptions):
    """``[[adapters]] name = "modbus"`` / ``--adapter modbus:KEY=VALUE`` / ``--modbus-port`` and friends; the
    options every TCP door has (``max_connections``, ``idle_timeout_s``, ``frame_timeout_s``, ``allow``)
    come from :class:`~hli_server.adapters.tcp.TcpDoorOptions`."""

    RENAMED: ClassVar[Mapping[str, str | None]] = {
        "idle_timeout": "idle_timeout_s",
        "frame_timeout": "frame_timeout_s",
        "evict_after": None,
    }
    DOOR: ClassVar[str] = "Modbus"

    port: int = Field(default=DEFAULT_PORT, ge=0, le=65535, description="TCP port (0: any free port)")
    word_order: Literal["ABCD", "CDAB"] = Field(
        default="ABCD", description="order of the two registers of a 32-bit value (ABCD: high word first)"
    )
    unit_id: int = Field(default=1, ge=0, le=255, description="the unit id answered (besides 0 and 255)")
    unknown_unit: Literal["exception", "ignore"] = Field(
        default="exception", description="other unit ids: exception 0x0B, or no answer"
    )
    max_connections: int = Field(
        default=256,
        ge=1,
        le=10_000,
        description="connections at once; beyond, the one answered longest ago makes room for a newcomer",
    )
    idle_timeout_s: float = Field(
        default=120.0, ge=0.0, le=86_400.0, description="seconds a connection may stay silent (0: no limit)"
    )
    frame_timeout_s: float = Field(
        default=2.0,
        ge=0.0,
        le=600.0,
        description="seconds a request frame may take from its first byte to its last (0: no limit)",
    )

    @field_validator("word_order", mode="before")
    @classmethod
    def _upper(cls, value: object) -> object:
        return value.upper() if isinstance(value, str) else value


class ModbusAdapter:
    """Modbus TCP on ``bind:port`` for the runtime's process image (H-03).

    Options (``--adapter modbus:port=5020,word_order=CDAB`` or the ``run`` flags): ``port``
    (0 = a free port; :attr:`port` tells which after start), ``word_order`` ``ABCD``/``CDAB``,
    ``unit_id`` (1), ``unknown_unit`` ``exception``/``ignore``, ``max_connections`` (256), ``idle_timeout_s``
    (120 s), ``frame_timeout_s`` (2 s), ``allow`` (the peers let in; empty: everybody).
    """

    name = "modbus"

    Options = ModbusOptions

    def __init__(self, *, bind: str = "127.0.0.1", **options: object) -> None:
        try:
            self.options = ModbusOptions.model_validate(options)
        except ValidationError as exc:
            first = exc.errors()[0]
            where = ".".join(str(p) for p in first["loc"])
            got = first.get("input")
            raise ValueError(f"Modbus adapter: {where}: {first['msg']} (got {got!r})") from None
        self.bind = bind
        self.requested_port = self.options.port
        self.word_order = self.options.word_order
        self.unit_id = self.options.unit_id
        self.unknown_unit = self.options.unknown_unit
        self.max_connections = self.options.max_connections
        self.idle_timeout = self.options.idle_timeout_s
        self.frame_timeout = self.options.frame_timeout_s
        self.allowlist = AddressAllowlist(self.options.allow)
        self.port: int | None = None
        self.server: ModbusServer
        self.faults = CommFaults()
        """The communication faults the connections consult (the host's, once started)."""
        self._listener: asyncio.Server | None = None
        self._slots: ConnectionSlots[_Connection] = ConnectionSlots(
            "Modbus", self.options.max_connections, 0.0, least_useful=True
        )

    @property
    def host(self) -> str:
        return f"[{self.bind}]" if ":" in self.bind else self.bind

    def endpoints(self) -> list[str]:
        if self.port is None:
            return ["Modbus TCP: not listening"]
        return [
            f"Modbus TCP: {self.host}:{self.port}  (unit id {self.unit_id}, "
            f"32-bit word order {self.word_order}, 0-based addresses as in `hli-server map`)"
        ]

    def serve_image(self, image: ImagePort, *, read_only: bool = False) -> None:
        """Bind the protocol logic to an image (done by :meth:`start`; tests may call it directly)."""
        self.server = ModbusServer(
            RegisterMap(image, self.word_order, read_only=read_only),
            unit_id=self.unit_id,
            unknown_unit=self.unknown_unit,
        )

    async def start(self, host: AdapterHost) -> None:
        self.faults = host.faults
        await self.start_for(host.image, read_only=host.policy.read_only)

    async def start_for(self, image: ImagePort, *, read_only: bool = False) -> None:
        """Listen for an image without a runtime (tests, tools)."""
        self.serve_image(image, read_only=read_only)
        self._listener = await listen(
            lambda: _Connection(self),
            self.bind,
            self.requested_port,
            "Modbus TCP",
            "choose another --modbus-port (0 = any free port) or --bind address",
        )
        self.port = self._listener.sockets[0].getsockname()[1]
        logger.info("Modbus TCP listening on %s:%d", self.bind, self.port)

    async def stop(self) -> None:
        listener, self._listener = self._listener, None
        await close(listener, self._slots)
        self.port = None

    def _accept(self, connection: _Connection, peer: object) -> bool:
        """Admit ``connection``; at the limit, the connection whose last request was answered longest ago
        makes room (reliability.md, round 1, finding 4; reliability.md, round 2, finding 3;
        ``adapters/tcp.py``)."""
        admission = self._slots.admit(connection, peer)
        if admission is Admission.REFUSED:
            self.server.stats.refused += 1
            return False
        if admission is Admission.EVICTED:
            self.server.stats.evicted += 1
        return True

    def _forget(self, connection: _Connection) -> None:
        self._slots.forget(connection)
