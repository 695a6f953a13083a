"""The ADS symbol table of the HLI, built from the one layout (H-04, H-08).

Every signal of the layout is a symbol on AMS port 851 named by its ST path
(``gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w``). Names are matched as TwinCAT matches
them, without regard to case, and the dereference may be spelt the three ways PLC programmers write
it: ``gpAx[0]^ipo_mc_control...`` (the layout's), ``gpAx[0]^.ipo_mc_control...`` and
``gpAx[0].ipo_mc_control...``.

A symbol's index group/offset (what 0xF009 and the upload report, and what ``pyads``'
``get_symbol(...).read()`` then reads raw) is its place in the image on port 851: group 0xF030
(PLC->CNC half) or 0xF020 (CNC->PLC half), offset = byte offset in the half. The dyn_coll_mon CNC
objects (C3-10) are symbols too, at their image place; their kernel address is port 551, group
0x120300, offset ``(A_ID << 16) | element`` (``hli-server map`` prints both).

Data types: the four base types of the image (BOOL, DINT, UDINT, LREAL) answer 0xF011 and the
data-type upload; there are no structured types (a control unit's fields live in both halves).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from hli_server.codecs.ads import (
    AdsDataType,
    DataTypeEntry,
    SymbolEntry,
    SymbolFlag,
    UploadInfo,
    UploadInfo2,
    UploadInfoFlag,
)
from schemas.layout import Layout, Signal, SignalType

__all__ = ["ADS_TYPES", "MAX_SYMBOL_INFO", "SymbolTable", "normalize_name"]

MAX_SYMBOL_INFO: Final = 798
"""pyads asks symbol info (0xF009) with this read length: every entry must fit (comments are cut)."""

ADS_TYPES: Final[dict[SignalType, AdsDataType]] = {
    SignalType.BOOL: AdsDataType.BIT,
    SignalType.DINT: AdsDataType.INT32,
    SignalType.UDINT: AdsDataType.UINT32,
    SignalType.LREAL: AdsDataType.REAL64,
}

_DEREF: Final = re.compile(r"^(gp(?:ch|ax)\[\d+\])(?:\^\.|\^|\.)")


def normalize_name(name: str) -> str:
    """The lookup key of a symbol name: lower case, ``^``, ``^.`` and ``.`` after ``gpAx[i]`` all as ``^``."""
    return _DEREF.sub(r"\1^", name.strip().lower(), count=1)


@dataclass(frozen=True, slots=True)
class Symbol:
    """A signal as an ADS symbol: its image address on port 851 and its encoded entries."""

    signal: Signal
    index_group: int
    index_offset: int
    entry: bytes
    """The AdsSymbolEntry (0xF009 reply, one piece of the 0xF00B upload)."""


class SymbolTable:
    """Lookups by name and the prepared replies of the symbol services (built once per layout)."""

    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self.version = 1
        """0xF008: constant while the server runs (the layout never changes)."""
        self._by_key: dict[str, Symbol] = {}
        entries: list[bytes] = []
        for s in layout.signals:
            symbol = Symbol(s, s.image_ads_group, s.offset, _entry(s))
            self._by_key[normalize_name(s.st_path)] = symbol
            entries.append(symbol.entry)
        self.upload = b"".join(entries)
        self.symbol_count = len(entries)
        types = [DataTypeEntry.base(t.value, ADS_TYPES[t], t.size) for t in SignalType]
        self._types = {t.name.lower(): t.encode() for t in types}
        self.type_upload = b"".join(self._types.values())
        self.upload_info = UploadInfo(self.symbol_count, len(self.upload)).encode()
        info2 = UploadInfo2(
            self.symbol_count,
            len(self.upload),
            len(types),
            len(self.type_upload),
            flags=int(UploadInfoFlag.IS_64_BIT_PLATFORM | UploadInfoFlag.INCLUDES_BASE_TYPES),
        )
        self.upload_info2 = info2.encode(24)
        self.upload_info2_long = info2.encode(64)

    def __len__(self) -> int:
        return self.symbol_count

    def find(self, name: str) -> Symbol | None:
        """The symbol of a name in any of the accepted spellings, or None."""
        return self._by_key.get(normalize_name(name))

    def data_type(self, name: str) -> bytes | None:
        """The AdsDatatypeEntry of a base type name (``DINT``), or None."""
        return self._types.get(name.strip().lower())


def _entry(s: Signal) -> bytes:
    flags = 0 if s.plc_writable else int(SymbolFlag.READ_ONLY)
    comment = s.description if s.unit in ("", "-") else f"{s.description} [{s.unit}]"
    comment = comment.encode("cp1252", "replace").decode("cp1252")  # what the wire can carry
    entry = SymbolEntry(
        s.image_ads_group, s.offset, s.size, int(ADS_TYPES[s.type]), s.st_path, s.type.value, comment, flags
    )
    raw = entry.encode()
    if len(raw) > MAX_SYMBOL_INFO:  # keep every entry within pyads' read length: cut the comment
        room = len(comment.encode("cp1252", "replace")) - (len(raw) - MAX_SYMBOL_INFO)
        entry = SymbolEntry(
            s.image_ads_group,
            s.offset,
            s.size,
            int(ADS_TYPES[s.type]),
            s.st_path,
            s.type.value,
            comment[: max(0, room - 3)] + "...",
            flags,
        )
        raw = entry.encode()
    return raw
