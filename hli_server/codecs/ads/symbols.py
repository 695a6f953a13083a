"""Payloads of the symbol services, sum commands and FILETIME (H-04).

Layouts as pyads 3.6 (``pyads/structs.py`` ``SAdsSymbolEntry``, ``pyads_ex.py`` ``adsSumRead``) and Node
ads-client 2.1 (``parseAdsResponseSymbol``, ``parseAdsResponseDataType``, ``readPlcUploadInfo``,
``readRawMulti``, ``createVariableHandle``) read and write them; all integers little-endian. Strings are
Windows-1252 (what pyads decodes; the 64-byte upload info can announce UTF-8 instead) with a NUL
after each; the length fields do not count the NUL.

AdsSymbolEntry (reply to 0xF009 symbol info by name; 0xF00B upload is these back to back)::

    | entry length u32 | index group u32 | index offset u32 | size u32 | data type u32 |
    | flags u16 | array dim u16 | name len u16 | type len u16 | comment len u16 |
    | name \\0 | type name \\0 | comment \\0 | array dim x (lower bound i32, elements u32) | extra |

    entry length counts the whole entry including itself; size 0 = a bit; data type: AdsDataType;
    extra = what the flags announce (type GUID 16 bytes, attributes, extended flags), kept verbatim.
    pyads reads flags and array dim as one u32 (it ignores both) and asks 0xF009 with read length 798:
    a reply must fit, so name + type + comment stay below ~760 bytes.

AdsDatatypeEntry (reply to 0xF011 data type by name; 0xF00E upload is these back to back)::

    | entry length u32 | version u32 (1) | hash u32 | type hash u32 | size u32 | offset u32 |
    | data type u32 | flags u32 | name len u16 | type len u16 | comment len u16 | array dim u16 |
    | sub items u16 | name \\0 | type \\0 | comment \\0 | array dim x (lower bound i32, elements u32) |
    | sub item entries (each a full AdsDatatypeEntry with its own entry length) | extra |

    A type has flag DATA_TYPE (1), a struct member DATA_ITEM (2) with ``offset`` = byte offset in the
    struct; a base type (DINT) has no sub items. extra: GUID, copy mask, methods, attributes, enum
    infos... when the flags announce them, kept verbatim.

Upload info::

    0xF00C (8 bytes):   | symbol count u32 | symbol bytes u32 |
    0xF00F (24 bytes):  | symbol count | symbol bytes | data type count | data type bytes |
                        | max dynamic symbols | dynamic symbols |                       (all u32)
    0xF00F (64 bytes, newer TwinCAT 3.1; ads-client asks 64 and tells the version by the size):
                        the 24 bytes, then | invalid dynamic symbols u32 | encoding code page u32 |
                        | flags u32 (UploadInfoFlag: 64-bit platform, includes base types, UTF-8) |
                        | reserved 28 |

Handle by name (0xF003, ReadWrite, name\\0 in)::

    read length 4 (pyads):           | handle u32 |
    longer (ads-client: 0xFFFFFFFF): | handle u32 | size u32 | type decoration u32 | type len u16 | type \\0 |

Sum commands (ReadWrite on 0xF080/0xF081/0xF082, index offset = number of sub requests N)::

    0xF080 read:        write data  N x | group u32 | offset u32 | length u32 |
                        read data   N x | result u32 |, then N x data (length each, zeros on error)
    0xF081 write:       write data  N x | group u32 | offset u32 | length u32 |, then N x data
                        read data   N x | result u32 |
    0xF082 read/write:  write data  N x | group u32 | offset u32 | read len u32 | write len u32 |,
                                    then N x write data
                        read data   N x | result u32 | length u32 |, then N x data (length each)

    pyads asks 0xF080 with read length 4N + sum(lengths) and skips ``length`` bytes per sub request
    whatever its result; ads-client does the same, and for 0xF082 skips the returned length.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Final, Self

from hli_server.codecs.ads.constants import AdsDataType, DataTypeFlag, ErrorCode
from hli_server.codecs.ads.errors import AdsError

__all__ = [
    "FILETIME_UNIX_EPOCH",
    "ArrayInfo",
    "DataTypeEntry",
    "HandleInfo",
    "SumRead",
    "SumReadItem",
    "SumReadWrite",
    "SumReadWriteItem",
    "SumWrite",
    "SumWriteItem",
    "SymbolEntry",
    "UploadInfo",
    "UploadInfo2",
    "datetime_to_filetime",
    "decode_data_type_upload",
    "decode_name",
    "decode_sum_read_reply",
    "decode_sum_read_write_reply",
    "decode_sum_write_reply",
    "decode_symbol_upload",
    "encode_handle_reply",
    "encode_sum_read_reply",
    "encode_sum_read_write_reply",
    "encode_sum_write_reply",
    "filetime_to_datetime",
    "filetime_to_unix_ns",
    "unix_ns_to_filetime",
]

ENCODING: Final = "cp1252"
FILETIME_UNIX_EPOCH: Final = 116_444_736_000_000_000
"""1970-01-01T00:00:00Z as FILETIME (100 ns ticks since 1601-01-01T00:00:00Z)."""
MAX_TYPE_NESTING: Final = 32
"""Sub items nested deeper than this are refused (a crafted entry could otherwise recurse without end)."""

_U32: Final = struct.Struct("<I")
_U32x2: Final = struct.Struct("<II")
_ARRAY: Final = struct.Struct("<iI")
_SYMBOL_HEAD: Final = struct.Struct("<IIIIIHHHHH")
_DT_HEAD: Final = struct.Struct("<IIIIIIIIHHHHH")
_HANDLE_EXTENDED: Final = struct.Struct("<IIIH")
_SUM_READ: Final = struct.Struct("<III")
_SUM_READ_WRITE: Final = struct.Struct("<IIII")
_UPLOAD_INFO2: Final = struct.Struct("<6I")
_UPLOAD_INFO3: Final = struct.Struct("<9I28s")


def _invalid(what: str) -> AdsError:
    return AdsError(ErrorCode.INVALID_VALUE, what)


def _short(what: str) -> AdsError:
    return AdsError(ErrorCode.SIZE_WRONG, what)


def decode_name(data: bytes) -> str:
    """A symbol or type name as a client sends it to 0xF003/0xF009/0xF011: up to the first NUL (pyads and
    ads-client send one; a missing NUL is tolerated), Windows-1252. Bytes that are not Windows-1252 become
    U+FFFD and so match no symbol: the server answers 0x710 as for any unknown name."""
    return data.split(b"\0", 1)[0].decode(ENCODING, "replace")


def _encode_text(text: str, what: str) -> bytes:
    raw = text.encode(ENCODING)
    if len(raw) > 0xFFFF or b"\0" in raw:
        raise ValueError(f"{what} {text!r} must be under 64 KiB and free of NUL")
    return raw


def _take_text(data: bytes, pos: int, length: int, end: int, what: str) -> tuple[str, int]:
    stop = pos + length
    if stop >= end:
        raise _short(f"{what} of {length} bytes and its NUL run past the entry's end")
    if data[stop] != 0:
        raise _invalid(f"{what} of {length} bytes is not followed by a NUL")
    return bytes(data[pos:stop]).decode(ENCODING, "replace"), stop + 1


@dataclass(frozen=True, slots=True)
class ArrayInfo:
    """One array dimension: lower bound (``ARRAY[0..9]`` -> 0) and number of elements (10)."""

    lower_bound: int
    elements: int


def _take_arrays(data: bytes, pos: int, count: int, end: int, what: str) -> tuple[tuple[ArrayInfo, ...], int]:
    if end - pos < 8 * count:
        raise _short(f"{what}: {count} array dimensions run past the entry's end")
    dims = tuple(ArrayInfo(*_ARRAY.unpack_from(data, pos + 8 * i)) for i in range(count))
    return dims, pos + 8 * count


def _entry_bounds(data: bytes, offset: int, limit: int, head_size: int, what: str) -> int:
    """The end of the entry at ``offset``, which must lie within ``limit`` (its parent's end)."""
    if limit - offset < head_size:
        raise _short(f"{what} at byte {offset}: {limit - offset} bytes left, the head alone is {head_size}")
    length: int = _U32.unpack_from(data, offset)[0]
    if length < head_size or offset + length > limit:
        raise _short(f"{what} at byte {offset}: entry length {length} does not fit {limit - offset} bytes")
    return offset + length


@dataclass(frozen=True, slots=True)
class SymbolEntry:
    """An AdsSymbolEntry (module docstring): where a symbol lives and what type it has."""

    index_group: int
    index_offset: int
    size: int
    data_type: int
    name: str
    type_name: str
    comment: str = ""
    flags: int = 0
    array_dims: tuple[ArrayInfo, ...] = ()
    extra: bytes = b""

    def encode(self) -> bytes:
        name = _encode_text(self.name, "symbol name")
        type_name = _encode_text(self.type_name, "type name")
        comment = _encode_text(self.comment, "comment")
        tail = b"".join(
            [name, b"\0", type_name, b"\0", comment, b"\0"]
            + [_ARRAY.pack(d.lower_bound, d.elements) for d in self.array_dims]
            + [self.extra]
        )
        return (
            _SYMBOL_HEAD.pack(
                _SYMBOL_HEAD.size + len(tail),
                self.index_group,
                self.index_offset,
                self.size,
                self.data_type,
                self.flags,
                len(self.array_dims),
                len(name),
                len(type_name),
                len(comment),
            )
            + tail
        )

    @classmethod
    def decode(cls, data: bytes, offset: int = 0) -> tuple[Self, int]:
        """The entry at ``offset`` and the offset after it; raises :class:`AdsError`."""
        end = _entry_bounds(data, offset, len(data), _SYMBOL_HEAD.size, "symbol entry")
        _, group, index_offset, size, data_type, flags, dims, n_name, n_type, n_comment = (
            _SYMBOL_HEAD.unpack_from(data, offset)
        )
        pos = offset + _SYMBOL_HEAD.size
        name, pos = _take_text(data, pos, n_name, end, "symbol name")
        type_name, pos = _take_text(data, pos, n_type, end, f"type name of {name!r}")
        comment, pos = _take_text(data, pos, n_comment, end, f"comment of {name!r}")
        array_dims, pos = _take_arrays(data, pos, dims, end, f"symbol {name!r}")
        entry = cls(
            group,
            index_offset,
            size,
            data_type,
            name,
            type_name,
            comment,
            flags,
            array_dims,
            bytes(data[pos:end]),
        )
        return entry, end


def decode_symbol_upload(data: bytes) -> tuple[SymbolEntry, ...]:
    """The entries of a 0xF00B upload, in order."""
    entries: list[SymbolEntry] = []
    pos = 0
    while pos < len(data):
        entry, pos = SymbolEntry.decode(data, pos)
        entries.append(entry)
    return tuple(entries)


@dataclass(frozen=True, slots=True)
class DataTypeEntry:
    """An AdsDatatypeEntry (module docstring); use :meth:`base`, :meth:`struct` and :meth:`item`."""

    name: str
    type_name: str
    size: int
    data_type: int
    flags: int = int(DataTypeFlag.DATA_TYPE)
    offset: int = 0
    comment: str = ""
    array_dims: tuple[ArrayInfo, ...] = ()
    sub_items: tuple[DataTypeEntry, ...] = ()
    version: int = 1
    hash_value: int = 0
    type_hash_value: int = 0
    extra: bytes = b""

    @classmethod
    def base(cls, name: str, data_type: AdsDataType, size: int) -> DataTypeEntry:
        """A base type such as ``DataTypeEntry.base("LREAL", AdsDataType.REAL64, 8)``."""
        return cls(name, "", size, int(data_type))

    @classmethod
    def item(cls, name: str, type_name: str, data_type: AdsDataType, size: int, offset: int) -> DataTypeEntry:
        """A struct member ``name : type_name`` at byte ``offset``."""
        return cls(name, type_name, size, int(data_type), int(DataTypeFlag.DATA_ITEM), offset)

    @classmethod
    def struct(cls, name: str, size: int, items: Sequence[DataTypeEntry]) -> DataTypeEntry:
        """A structure of ``items`` (made with :meth:`item`), ``size`` bytes in all."""
        return cls(name, "", size, int(AdsDataType.BIGTYPE), sub_items=tuple(items))

    def encode(self) -> bytes:
        name = _encode_text(self.name, "type name")
        type_name = _encode_text(self.type_name, "base type name")
        comment = _encode_text(self.comment, "comment")
        tail = b"".join(
            [name, b"\0", type_name, b"\0", comment, b"\0"]
            + [_ARRAY.pack(d.lower_bound, d.elements) for d in self.array_dims]
            + [item.encode() for item in self.sub_items]
            + [self.extra]
        )
        return (
            _DT_HEAD.pack(
                _DT_HEAD.size + len(tail),
                self.version,
                self.hash_value,
                self.type_hash_value,
                self.size,
                self.offset,
                self.data_type,
                self.flags,
                len(name),
                len(type_name),
                len(comment),
                len(self.array_dims),
                len(self.sub_items),
            )
            + tail
        )

    @classmethod
    def decode(cls, data: bytes, offset: int = 0) -> tuple[DataTypeEntry, int]:
        """The entry at ``offset`` (sub items included) and the offset after it; raises :class:`AdsError`."""
        return _decode_data_type(data, offset, len(data), 0)


def _decode_data_type(data: bytes, offset: int, limit: int, depth: int) -> tuple[DataTypeEntry, int]:
    if depth > MAX_TYPE_NESTING:
        raise _invalid(f"data type entry at byte {offset}: sub items nested deeper than {MAX_TYPE_NESTING}")
    end = _entry_bounds(data, offset, limit, _DT_HEAD.size, "data type entry")
    (
        _,
        version,
        hash_value,
        type_hash,
        size,
        item_offset,
        data_type,
        flags,
        n_name,
        n_type,
        n_comment,
        dims,
        n_items,
    ) = _DT_HEAD.unpack_from(data, offset)
    pos = offset + _DT_HEAD.size
    name, pos = _take_text(data, pos, n_name, end, "type name")
    type_name, pos = _take_text(data, pos, n_type, end, f"base type of {name!r}")
    comment, pos = _take_text(data, pos, n_comment, end, f"comment of {name!r}")
    array_dims, pos = _take_arrays(data, pos, dims, end, f"type {name!r}")
    items: list[DataTypeEntry] = []
    for _ in range(n_items):
        item, pos = _decode_data_type(data, pos, end, depth + 1)
        items.append(item)
    entry = DataTypeEntry(
        name,
        type_name,
        size,
        data_type,
        flags,
        item_offset,
        comment,
        array_dims,
        tuple(items),
        version,
        hash_value,
        type_hash,
        bytes(data[pos:end]),
    )
    return entry, end


def decode_data_type_upload(data: bytes) -> tuple[DataTypeEntry, ...]:
    """The entries of a 0xF00E upload, in order."""
    entries: list[DataTypeEntry] = []
    pos = 0
    while pos < len(data):
        entry, pos = DataTypeEntry.decode(data, pos)
        entries.append(entry)
    return tuple(entries)


@dataclass(frozen=True, slots=True)
class UploadInfo:
    """0xF00C: how many symbols and how many bytes their 0xF00B upload has."""

    symbol_count: int
    symbol_length: int

    def encode(self) -> bytes:
        return _U32x2.pack(self.symbol_count, self.symbol_length)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        if len(data) != 8:
            raise _short(f"upload info (0xF00C) is {len(data)} bytes, expected 8")
        return cls(*_U32x2.unpack(data))


@dataclass(frozen=True, slots=True)
class UploadInfo2:
    """0xF00F: the counts and byte lengths of both uploads; :meth:`encode` gives 24 or 64 bytes.

    The 64-byte form (newer TwinCAT 3.1) adds the invalid dynamic symbol count, the code page of
    STRING data and symbol names (65001 = UTF-8, else Windows-1252), and :class:`UploadInfoFlag`.
    """

    symbol_count: int
    symbol_length: int
    data_type_count: int
    data_type_length: int
    max_dynamic_symbol_count: int = 0
    dynamic_symbol_count: int = 0
    invalid_dynamic_symbol_count: int = 0
    encoding_code_page: int = 1252
    flags: int = 0

    def encode(self, size: int = 24) -> bytes:
        """``size`` 24 (what pyads-era TwinCAT answers) or 64; answer 64 only to a read of 64 or more."""
        head = (
            self.symbol_count,
            self.symbol_length,
            self.data_type_count,
            self.data_type_length,
            self.max_dynamic_symbol_count,
            self.dynamic_symbol_count,
        )
        if size == 24:
            return _UPLOAD_INFO2.pack(*head)
        if size == 64:
            return _UPLOAD_INFO3.pack(
                *head, self.invalid_dynamic_symbol_count, self.encoding_code_page, self.flags, bytes(28)
            )
        raise ValueError(f"upload info 2 is 24 or 64 bytes, not {size}")

    @classmethod
    def decode(cls, data: bytes) -> Self:
        if len(data) == 24:
            return cls(*_UPLOAD_INFO2.unpack(data))
        if len(data) == 64:
            return cls(*_UPLOAD_INFO3.unpack(data)[:9])
        raise _short(f"upload info 2 (0xF00F) is {len(data)} bytes, expected 24 or 64")


@dataclass(frozen=True, slots=True)
class HandleInfo:
    """The extended 0xF003 reply ads-client asks for (read length 0xFFFFFFFF)."""

    handle: int
    size: int
    type_name: str
    type_decoration: int = 0

    def encode(self) -> bytes:
        raw = _encode_text(self.type_name, "type name")
        return _HANDLE_EXTENDED.pack(self.handle, self.size, self.type_decoration, len(raw)) + raw + b"\0"

    @classmethod
    def decode(cls, data: bytes) -> Self:
        if len(data) < _HANDLE_EXTENDED.size:
            raise _short(f"handle info is {len(data)} bytes, the head alone is {_HANDLE_EXTENDED.size}")
        handle, size, decoration, n_type = _HANDLE_EXTENDED.unpack_from(data)
        if len(data) != _HANDLE_EXTENDED.size + n_type + 1:
            raise _short(f"handle info is {len(data)} bytes, its type name of {n_type} needs {15 + n_type}")
        type_name, _ = _take_text(data, _HANDLE_EXTENDED.size, n_type, len(data), "type name")
        return cls(handle, size, type_name, decoration)


def encode_handle_reply(read_length: int, info: HandleInfo) -> bytes:
    """The 0xF003 reply for a request with ``read_length``: the extended form when it fits, else the
    handle alone (pyads asks 4 bytes and checks it got exactly 4)."""
    extended = info.encode()
    return extended if read_length >= len(extended) else _U32.pack(info.handle)


# --------------------------------------------------------------------------------------------
# Sum commands
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SumReadItem:
    index_group: int
    index_offset: int
    length: int


@dataclass(frozen=True, slots=True)
class SumRead:
    """0xF080 request (the ReadWrite's write data) of ``len(items)`` = index offset sub reads."""

    items: tuple[SumReadItem, ...]

    @property
    def reply_length(self) -> int:
        """4N + the lengths: what pyads and ads-client ask as read length."""
        return 4 * len(self.items) + sum(i.length for i in self.items)

    def encode(self) -> bytes:
        return b"".join(_SUM_READ.pack(i.index_group, i.index_offset, i.length) for i in self.items)

    @classmethod
    def decode(cls, count: int, data: bytes) -> Self:
        if len(data) != 12 * count:
            raise _short(f"sum read of {count} sub requests carries {len(data)} bytes, expected {12 * count}")
        return cls(tuple(SumReadItem(*t) for t in _SUM_READ.iter_unpack(data)))


def encode_sum_read_reply(request: SumRead, results: Sequence[tuple[int, bytes]]) -> bytes:
    """The 0xF080 read data: N results, then each sub read's data padded or cut to its requested length
    (clients skip ``length`` bytes per sub request whatever its result, so an error is zeros)."""
    if len(results) != len(request.items):
        raise ValueError(f"{len(results)} results for {len(request.items)} sub reads")
    head = b"".join(_U32.pack(code) for code, _ in results)
    pairs = zip(request.items, results, strict=True)
    body = b"".join(data[: item.length].ljust(item.length, b"\0") for item, (_, data) in pairs)
    return head + body


def decode_sum_read_reply(request: SumRead, data: bytes) -> list[tuple[int, bytes]]:
    """Client side of :func:`encode_sum_read_reply`: (result, data) per sub read."""
    if len(data) != request.reply_length:
        raise _short(f"sum read reply is {len(data)} bytes, its request asks {request.reply_length}")
    n = len(request.items)
    results: list[tuple[int, bytes]] = []
    pos = 4 * n
    for i, item in enumerate(request.items):
        results.append((_U32.unpack_from(data, 4 * i)[0], bytes(data[pos : pos + item.length])))
        pos += item.length
    return results


@dataclass(frozen=True, slots=True)
class SumWriteItem:
    index_group: int
    index_offset: int
    data: bytes


@dataclass(frozen=True, slots=True)
class SumWrite:
    """0xF081 request: N (group, offset, length) then the N data blocks."""

    items: tuple[SumWriteItem, ...]

    def encode(self) -> bytes:
        head = b"".join(_SUM_READ.pack(i.index_group, i.index_offset, len(i.data)) for i in self.items)
        return head + b"".join(i.data for i in self.items)

    @classmethod
    def decode(cls, count: int, data: bytes) -> Self:
        if len(data) < 12 * count:
            raise _short(
                f"sum write of {count} sub requests carries {len(data)} bytes, its heads need {12 * count}"
            )
        heads = list(_SUM_READ.iter_unpack(data[: 12 * count]))
        if len(data) != 12 * count + sum(h[2] for h in heads):
            raise _short(
                f"sum write of {count} sub requests carries {len(data) - 12 * count} data bytes, "
                f"its lengths add up to {sum(h[2] for h in heads)}"
            )
        pos = 12 * count
        items: list[SumWriteItem] = []
        for group, offset, length in heads:
            items.append(SumWriteItem(group, offset, bytes(data[pos : pos + length])))
            pos += length
        return cls(tuple(items))


def encode_sum_write_reply(results: Sequence[int]) -> bytes:
    """The 0xF081 read data: one u32 result per sub write."""
    return b"".join(_U32.pack(code) for code in results)


def decode_sum_write_reply(count: int, data: bytes) -> list[int]:
    """Client side of :func:`encode_sum_write_reply`: the result of each sub write."""
    if len(data) != 4 * count:
        raise _short(f"sum write reply is {len(data)} bytes, {count} results need {4 * count}")
    return [code for (code,) in _U32.iter_unpack(data)]


@dataclass(frozen=True, slots=True)
class SumReadWriteItem:
    index_group: int
    index_offset: int
    read_length: int
    data: bytes


@dataclass(frozen=True, slots=True)
class SumReadWrite:
    """0xF082 request: N (group, offset, read length, write length) then the N write blocks."""

    items: tuple[SumReadWriteItem, ...]

    def encode(self) -> bytes:
        head = b"".join(
            _SUM_READ_WRITE.pack(i.index_group, i.index_offset, i.read_length, len(i.data))
            for i in self.items
        )
        return head + b"".join(i.data for i in self.items)

    @classmethod
    def decode(cls, count: int, data: bytes) -> Self:
        if len(data) < 16 * count:
            raise _short(
                f"sum read/write of {count} sub requests carries {len(data)} bytes, "
                f"its heads need {16 * count}"
            )
        heads = list(_SUM_READ_WRITE.iter_unpack(data[: 16 * count]))
        if len(data) != 16 * count + sum(h[3] for h in heads):
            raise _short(
                f"sum read/write of {count} sub requests carries {len(data) - 16 * count} data bytes, "
                f"its write lengths add up to {sum(h[3] for h in heads)}"
            )
        pos = 16 * count
        items: list[SumReadWriteItem] = []
        for group, offset, read_length, write_length in heads:
            items.append(SumReadWriteItem(group, offset, read_length, bytes(data[pos : pos + write_length])))
            pos += write_length
        return cls(tuple(items))


def encode_sum_read_write_reply(results: Sequence[tuple[int, bytes]]) -> bytes:
    """The 0xF082 read data: N (result, length), then each sub request's data (its own length)."""
    head = b"".join(_U32x2.pack(code, len(data)) for code, data in results)
    return head + b"".join(data for _, data in results)


def decode_sum_read_write_reply(count: int, data: bytes) -> list[tuple[int, bytes]]:
    """Client side of :func:`encode_sum_read_write_reply`: (result, data) per sub request."""
    if len(data) < 8 * count:
        raise _short(f"sum read/write reply is {len(data)} bytes, {count} heads need {8 * count}")
    heads = list(_U32x2.iter_unpack(data[: 8 * count]))
    if len(data) != 8 * count + sum(length for _, length in heads):
        raise _short(f"sum read/write reply is {len(data)} bytes, its heads announce a different length")
    results: list[tuple[int, bytes]] = []
    pos = 8 * count
    for code, length in heads:
        results.append((code, bytes(data[pos : pos + length])))
        pos += length
    return results


# --------------------------------------------------------------------------------------------
# FILETIME
# --------------------------------------------------------------------------------------------


def unix_ns_to_filetime(unix_ns: int) -> int:
    """Nanoseconds since 1970 (``time.time_ns()``) -> FILETIME (100 ns since 1601), the notification stamp."""
    return FILETIME_UNIX_EPOCH + unix_ns // 100


def filetime_to_unix_ns(filetime: int) -> int:
    return (filetime - FILETIME_UNIX_EPOCH) * 100


def datetime_to_filetime(when: datetime) -> int:
    """A datetime (naive = UTC, as pyads assumes) -> FILETIME, exact to the microsecond."""
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    delta = when - datetime(1970, 1, 1, tzinfo=UTC)
    return FILETIME_UNIX_EPOCH + (delta // timedelta(microseconds=1)) * 10


def filetime_to_datetime(filetime: int) -> datetime:
    """FILETIME -> aware UTC datetime (100 ns ticks below a microsecond are dropped)."""
    return datetime(1970, 1, 1, tzinfo=UTC) + timedelta(microseconds=(filetime - FILETIME_UNIX_EPOCH) // 10)
