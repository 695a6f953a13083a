"""The symbol server's information services on port 851: what the symbols and types are (H-04).

::

    0xF008  Read        symbol version (u8; 1: the layout does not change while the server runs);
                        a notification on it never fires again after its first sample
    0xF009  ReadWrite   symbol info by name: one AdsSymbolEntry (every entry fits pyads' 798-byte read)
    0xF00B  Read        symbol upload: the top-level symbols (``gpCh``, ``gpAx``, ...)
    0xF00C  Read        upload info (8 bytes: symbol count and bytes)
    0xF00E  Read        data-type upload: every type, members before the structures that hold them
    0xF00F  Read        upload info 2 (24 bytes, or 64 to a read of 64 or more, as newer TwinCAT answers)
    0xF011  ReadWrite   data type by name (base types, control units, structures, arrays)
    0xF100  Read        ADS state RUN (5) and device state 0 of the PLC runtime; notifications too

The tables themselves are built once from the layout (:class:`~hli_server.adapters.ads.symbols.SymbolTable`).
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING, Final

from hli_server.adapters.ads.session import Watch
from hli_server.codecs.ads import AdsError, AdsState, ErrorCode, IndexGroup, decode_name

if TYPE_CHECKING:
    from hli_server.adapters.ads.data import DataService
    from hli_server.adapters.ads.session import Session
    from hli_server.adapters.ads.symbols import SymbolTable

__all__ = ["SymbolInfoService"]

_STATE: Final = struct.Struct("<HH").pack(AdsState.RUN, 0)


class SymbolInfoService:
    def __init__(self, symbols: SymbolTable, data: DataService) -> None:
        self.symbols = symbols
        self.data = data

    def _fits(self, group: int, value: bytes, length: int) -> bytes:
        if length < len(value):
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"index group 0x{group:X} answers {len(value)} bytes, the read asked only {length}",
            )
        return value

    # --- reads ------------------------------------------------------------------------------------
    def version(self, session: Session, offset: int, length: int) -> bytes:
        return self._fits(IndexGroup.SYM_VERSION, bytes((self.symbols.version,)), length)

    def upload(self, session: Session, offset: int, length: int) -> bytes:
        return self._fits(IndexGroup.SYM_UPLOAD, self.symbols.upload, length)

    def upload_info(self, session: Session, offset: int, length: int) -> bytes:
        return self._fits(IndexGroup.SYM_UPLOAD_INFO, self.symbols.upload_info, length)

    def type_upload(self, session: Session, offset: int, length: int) -> bytes:
        return self._fits(IndexGroup.SYM_DT_UPLOAD, self.symbols.type_upload, length)

    def upload_info2(self, session: Session, offset: int, length: int) -> bytes:
        t = self.symbols
        value = t.upload_info2_long if length >= len(t.upload_info2_long) else t.upload_info2
        return self._fits(IndexGroup.SYM_UPLOAD_INFO2, value, length)

    def device_state(self, session: Session, offset: int, length: int) -> bytes:
        return self._fits(IndexGroup.DEVICE_DATA, _STATE, length)

    # --- watches of the constants (ads-client subscribes both on connect) --------------------------
    def watch_version(self, session: Session, offset: int, length: int) -> Watch:
        return _constant_watch(IndexGroup.SYM_VERSION, bytes((self.symbols.version,)), length)

    def watch_device_state(self, session: Session, offset: int, length: int) -> Watch:
        return _constant_watch(IndexGroup.DEVICE_DATA, _STATE, length)

    # --- read-writes --------------------------------------------------------------------------------
    def info_by_name(self, session: Session, offset: int, read_length: int, data: bytes) -> bytes:
        symbol = self.data.symbol(data)
        if read_length < len(symbol.entry):
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"symbol info of {symbol.name} is {len(symbol.entry)} bytes, read length {read_length}",
            )
        return symbol.entry

    def type_by_name(self, session: Session, offset: int, read_length: int, data: bytes) -> bytes:
        name = decode_name(data)
        entry = self.symbols.data_type(name)
        if entry is None:
            raise AdsError(
                ErrorCode.SYMBOL_NOT_FOUND,
                f"no data type {name[:200]!r}; the types are {', '.join(self.symbols.type_names[:12])}, ... "
                "(the data-type upload 0xF00E lists them all)",
            )
        if read_length < len(entry):
            raise AdsError(
                ErrorCode.SIZE_WRONG, f"data type {name} is {len(entry)} bytes, read {read_length}"
            )
        return entry


MAX_CONSTANT_WATCH: Final = 64
"""Bytes a notification of a constant may watch (the value, padded with zeros); beyond it is 0x705: a
notification of 0x7FFFFFFF bytes built a 2 GB sample and 0xFFFFFFFF none at all, without an answer
(issue 36, finding 9)."""


def _constant_watch(group: int, value: bytes, length: int) -> Watch:
    if length > MAX_CONSTANT_WATCH:
        raise AdsError(
            ErrorCode.SIZE_WRONG,
            f"index group 0x{group:X} holds {len(value)} bytes; a notification of it watches at most "
            f"{MAX_CONSTANT_WATCH}, not {length}",
        )
    return Watch.of_constant(value.ljust(length, b"\0")[:length])
