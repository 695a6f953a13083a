"""Modbus addressing for the PLC side, without I/O (H-03, H-06).

What :class:`~plc_clients.transports.ModbusTransport` and
:class:`~plc_clients.transports.AsyncModbusTransport` need to talk to the server's Modbus view of
the process image, kept apart from the sockets so that it can be tested without a server:

* :meth:`ModbusCodec.read_requests`: the fewest read requests (FC 1/2/3/4) that cover a set of
  signals. The server answers only ranges that are occupied by signals from end to end (an empty
  address, or a range that cuts a 32/64-bit value, is exception 0x02; ``docs/modbus.md``), so a
  request never spans a gap between the layout's occupied address runs; inside one run it reads
  from the first wanted signal to the last one, unwanted signals in between included, in chunks
  of at most 125 registers (2000 bits).
* :meth:`ModbusCodec.decode` turns an answer's registers or bits into values per ST path.
* :meth:`ModbusCodec.registers` encodes a value for FC 16 (holding registers).

Word order (must match the server's ``--modbus-word-order``): the server's own codec,
:mod:`hli_server.codecs.modbus_words` (``ABCD`` most significant word first, ``CDAB`` least
significant first), so that it exists once.

Imports ``schemas`` (the layout is the one source of every address, H-08) and the server's codecs.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final

from hli_server.codecs import modbus_words
from hli_server.codecs.modbus_words import WORD_ORDERS
from schemas.layout import STRING_ENCODING, Layout, ModbusTable, Signal, SignalType

__all__ = [
    "MAX_READ_BITS",
    "MAX_READ_REGISTERS",
    "WORD_ORDERS",
    "ModbusCodec",
    "ReadRequest",
]

MAX_READ_REGISTERS: Final = 125
"""FC 3/4: at most 125 registers per request (Modbus application protocol, 6.3/6.4)."""
MAX_READ_BITS: Final = 2000
"""FC 1/2: at most 2000 bits per request."""
_BIT_TABLES: Final = (ModbusTable.COIL, ModbusTable.DISCRETE_INPUT)

Value = bool | int | float | str


@dataclass(frozen=True, slots=True)
class ReadRequest:
    """One read: ``count`` registers/bits of ``table`` from ``address``; ``signals`` are the
    wanted ones inside it (others in the range are read and dropped)."""

    table: ModbusTable
    address: int
    count: int
    signals: tuple[Signal, ...]

    @property
    def function_code(self) -> int:
        return _FUNCTION_CODE[self.table]


_FUNCTION_CODE: Final = {
    ModbusTable.COIL: 1,
    ModbusTable.DISCRETE_INPUT: 2,
    ModbusTable.HOLDING_REGISTER: 3,
    ModbusTable.INPUT_REGISTER: 4,
}


class ModbusCodec:
    """Read planning and value encoding for one layout and word order (no I/O)."""

    def __init__(self, layout: Layout, word_order: str = "ABCD") -> None:
        try:
            order = modbus_words.check_word_order(word_order)
        except ValueError as exc:
            raise ValueError(f"{exc} (the same as the server's --modbus-word-order)") from None
        self.layout = layout
        self.word_order = order
        self._run_of: dict[ModbusTable, dict[int, int]] = {}
        """table -> first address of a signal -> number of the occupied run it lies in."""
        for table in ModbusTable:
            run = -1
            end = -1
            starts: dict[int, int] = {}
            for s in sorted((s for s in layout.signals if s.modbus_table is table), key=_address):
                if s.modbus_address != end:
                    run += 1
                starts[s.modbus_address] = run
                end = s.modbus_address + s.modbus_count
            self._run_of[table] = starts

    # --- reads -------------------------------------------------------------------------------
    def read_requests(self, signals: Iterable[Signal]) -> list[ReadRequest]:
        """The fewest requests that cover ``signals`` (any tables), ordered by table and address."""
        by_table: dict[ModbusTable, list[Signal]] = {}
        for s in {s.st_path: s for s in signals}.values():
            by_table.setdefault(s.modbus_table, []).append(s)
        requests: list[ReadRequest] = []
        for table in ModbusTable:
            wanted = sorted(by_table.get(table, ()), key=_address)
            limit = MAX_READ_BITS if table in _BIT_TABLES else MAX_READ_REGISTERS
            runs = self._run_of[table]
            group: list[Signal] = []
            for s in wanted:
                if group:
                    first = group[0]
                    same_run = runs[s.modbus_address] == runs[first.modbus_address]
                    fits = s.modbus_address + s.modbus_count - first.modbus_address <= limit
                    if not (same_run and fits):
                        requests.append(_request(table, group))
                        group = []
                group.append(s)
            if group:
                requests.append(_request(table, group))
        return requests

    def decode(self, request: ReadRequest, payload: Sequence[int] | Sequence[bool]) -> dict[str, Value]:
        """Values of the wanted signals from an answer's registers (FC 3/4) or bits (FC 1/2).

        Bit answers may be padded to a multiple of 8 (pymodbus does); registers must be exact.
        """
        if request.table in _BIT_TABLES:
            if len(payload) < request.count:
                raise ValueError(f"{len(payload)} bits for a request of {request.count}")
            return {s.st_path: bool(payload[s.modbus_address - request.address]) for s in request.signals}
        if len(payload) != request.count:
            raise ValueError(f"{len(payload)} registers for a request of {request.count}")
        out: dict[str, Value] = {}
        for s in request.signals:
            k = s.modbus_address - request.address
            out[s.st_path] = self.value(s, payload[k : k + s.modbus_count])
        return out

    def value(self, signal: Signal, registers: Sequence[int]) -> int | float | str:
        """One DINT/UDINT/LREAL from its registers in this codec's word order; a STRING's text up to
        its NUL (docs/modbus.md)."""
        words = list(registers)
        if len(words) != signal.modbus_count:
            raise ValueError(f"{signal.st_path}: {len(words)} registers, expected {signal.modbus_count}")
        if signal.type is SignalType.STRING:
            text = modbus_words.text_data(words)[: signal.size].partition(b"\0")[0]
            return text.decode(STRING_ENCODING, "replace")
        return modbus_words.value(signal.struct_char, words, self.word_order)

    # --- writes ------------------------------------------------------------------------------
    def registers(self, signal: Signal, value: int | float | str) -> list[int]:
        """The registers of a (coerced) DINT/UDINT/LREAL value in this codec's word order, or of a
        STRING's text (NUL-padded to all its registers)."""
        if signal.type is SignalType.BOOL:
            raise ValueError(f"{signal.st_path} is a BOOL: it is a coil, not registers")
        if isinstance(value, str):
            return modbus_words.text_registers(value.encode(STRING_ENCODING), signal.modbus_count)
        return modbus_words.registers(signal.struct_char, value, self.word_order)


def _address(s: Signal) -> int:
    return s.modbus_address


def _request(table: ModbusTable, group: list[Signal]) -> ReadRequest:
    first, last = group[0], group[-1]
    count = last.modbus_address + last.modbus_count - first.modbus_address
    return ReadRequest(table, first.modbus_address, count, tuple(group))
