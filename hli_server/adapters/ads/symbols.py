"""The ADS symbols and data types of the HLI, built from the one layout, whatever it holds (H-04, H-08).

Every signal of the layout is reachable on AMS port 851 by its ST path
(``gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w``), and so is every level above it: the
control unit ``gpAx[0]^ipo_mc_control.dyn_pos_limit_high`` as an ``MC_CONTROL_SGN32_UNIT``, the
axis ``gpAx[0]`` as a structure, ``gpAx`` as an array of them. Nothing here names a signal: the tree
is read off the ST paths, so signals a later layout adds (the NC program's ``V.E.`` variables, more
units) become symbols and members of their structures without a change here.

Names are matched as TwinCAT matches them, without regard to case; the dereference of the kernel's
pointers may be spelt as PLC programmers write it: ``gpAx[0]^ipo_mc_control...`` (the layout's),
``gpAx[0]^.ipo_mc_control...`` and ``gpAx[0].ipo_mc_control...``.

**Types.** A leaf has its IEC base type (BOOL, DINT, UDINT, LREAL, ...); a V.E. STRING is TwinCAT's
``STRING(n)`` (ADS data type 30, n + 1 bytes, Windows-1252, NUL-terminated). A structure whose members
are ``request_r, enable_w, command_w, state_r`` is a control unit of the kernel and gets the
kernel's type name from its ``command_w`` type: ``MC_CONTROL_BOOL_UNIT``, ``MC_CONTROL_SGN32_UNIT``,
``MC_CONTROL_UNS32_UNIT``, ``MC_CONTROL_REAL64_UNIT`` (FCT-C43 3.1.1: "Data type
MC_CONTROL_SGN32_UNIT", https://infosys.beckhoff.com/content/1033/tf5200_dynposlimit/174766219.html;
the unit's members in the kernel's order, https://infosys.beckhoff.com/content/1033/tf5200_hli_interface/174725259.html).
A V.E. structure (N-05) has the type name its declaration gives (``struct[i].name``: the kernel's
export to the PLC names the types so, "Section 2: type declaration from the V.E. variable list",
https://infosys.beckhoff.com/content/1033/expextvar/15424453899.html). Other structures are named by their
place: ``HLI_AX`` for an element of ``gpAx``, ``HLI_AX_IPO_STATE`` for its member ``ipo_state`` (the
project's names: the kernel library's are not public). Indexed
levels whose elements share one type are arrays, ``ARRAY [0..4] OF HLI_AX``; the kernel's ``gpAx`` is
an array of pointers, here it is the array of what they point to, so ``gpAx[0]`` and ``gpAx[0]^`` are
the same structure. Elements of differing types cannot form an array: they become symbols of their
own (``gpCh[0]``, ``gpCh[1]``).

**Addresses.** A leaf's index group/offset (what 0xF009 reports and ``pyads``' ``get_symbol(...).read()``
then reads raw) is its place in the image on port 851: group 0xF030 (PLC->CNC half) or 0xF020 (CNC->PLC
half), offset = byte offset in the half. A structure or array lives in the *structured view*, index
group :data:`VIEW_GROUP`: every top-level symbol's bytes back to back, members in order without padding
(TwinCAT's ``{attribute 'pack_mode' := '1'}``, the packing ``pyads``' ``read_structure_by_name`` requires;
ads-client and TwinCAT read the member offsets from the type). The image keeps a control unit's ``_w``
fields in the PLC->CNC half and its ``_r`` fields in the CNC->PLC half; the view gathers them on a read
(:meth:`SymbolTable.view_pieces`) and scatters a write to the ``_w`` members, leaving the ``_r`` members
to the CNC (:meth:`SymbolTable.view_leaves`; docs/ads.md, "Structures").

The dyn_coll_mon CNC objects (C3-10) are members too, at their image place; their kernel address is
port 551, group 0x120300, offset ``(A_ID << 16) | element`` (``hli-server map`` prints both).
"""

from __future__ import annotations

import bisect
import logging
import re
from dataclasses import dataclass, field
from typing import Final

from hli_server.codecs.ads import (
    BASE_TYPES,
    AdsDataType,
    AdsError,
    ArrayInfo,
    DataTypeEntry,
    ErrorCode,
    HandleInfo,
    SymbolEntry,
    SymbolFlag,
    UploadInfo,
    UploadInfo2,
    UploadInfoFlag,
    ads_type_name,
    decode_name,
)
from schemas.layout import Direction, Layout, Scope, Signal

__all__ = [
    "MAX_SYMBOL_INFO",
    "VIEW_GROUP",
    "Piece",
    "Symbol",
    "SymbolTable",
    "ads_data_type",
    "normalize_name",
    "parse_path",
]

logger = logging.getLogger(__name__)

MAX_SYMBOL_INFO: Final = 798
"""pyads asks symbol info (0xF009) with this read length: every entry must fit (comments are cut)."""

VIEW_GROUP: Final = 0x4040
"""Index group of the structured view (TwinCAT's group of a PLC's own data; project's choice)."""

_UNIT_KINDS: Final = {
    "BOOL": "BOOL",
    "SINT": "SGN08",
    "USINT": "UNS08",
    "INT": "SGN16",
    "UINT": "UNS16",
    "DINT": "SGN32",
    "UDINT": "UNS32",
    "REAL": "REAL32",
    "LREAL": "REAL64",
}
"""The kernel's names of a control unit's value type (``MC_CONTROL_<kind>_UNIT``), by the IEC name."""

_UNIT_MEMBERS: Final = ("request_r", "enable_w", "command_w", "state_r")
"""A control unit's members in the kernel's order (H-02; tf5200_hli_interface "Control unit")."""

_BASE_ALWAYS: Final = ("BOOL", "DINT", "UDINT", "LREAL")
"""Base types 0xF011 answers even when the layout has none of them (clients probe them)."""

Piece = tuple[Direction, int, int]
"""A slice of one half: direction, start, end (bytes)."""

Step = str | int
"""One step of a path: a member name (lower case) or an index."""

_STRING_TYPE: Final = re.compile(r"^STRING\((\d{1,5})\)$", re.IGNORECASE)
"""TwinCAT's ``STRING(n)``: n characters and the NUL."""

_TOKEN: Final = re.compile(r"\s*(?:([A-Za-z_][A-Za-z0-9_]*)|\[([0-9 ,]+)\]|(\^)|(\.))")


def parse_path(text: str) -> list[tuple[Step, int]] | None:
    """The steps of an ST path and where each ends in ``text``; None when it is no path.

    ``gpAx[0]^ipo_state.cmd_pos_r`` -> ``[("gpax", 4), (0, 7), ("ipo_state", 18), ("cmd_pos_r", 28)]``.
    ``^`` and ``.`` separate members in any order (``^.``, ``^``, ``.`` after an index);
    ``[1,2]`` is ``[1][2]``.
    """
    steps: list[tuple[Step, int]] = []
    pos = 0
    end = len(text.rstrip())
    prev = "start"  # start, item (a name or an index), caret, dot
    while pos < end:
        m = _TOKEN.match(text, pos)
        if m is None:
            return None
        name, index, caret, _dot = m.groups()
        pos = m.end()
        if name is not None:
            if prev not in ("start", "caret", "dot"):
                return None
            steps.append((name.lower(), pos))
            prev = "item"
        elif index is not None:
            parts = [p.strip() for p in index.split(",")]
            if prev != "item" or not all(p.isdecimal() and len(p) <= 9 for p in parts):
                return None
            steps.extend((int(part), pos) for part in parts)
        elif caret is not None:
            if prev != "item":
                return None
            prev = "caret"
        else:
            if prev not in ("item", "caret"):
                return None
            prev = "dot"
    if not steps or prev not in ("item", "caret"):
        return None
    return steps


def normalize_name(name: str) -> str:
    """The lookup key of a symbol name: lower case, ``^``, ``^.`` and ``.`` after an index all as ``.``
    (``gpax[0].ipo_mc_control.dyn_pos_limit_high.command_w``); the name itself when it is no path."""
    steps = parse_path(name)
    if steps is None:
        return name.strip().lower()
    return _key_text(tuple(s for s, _ in steps))


def _key_text(key: tuple[Step, ...]) -> str:
    out: list[str] = []
    for step in key:
        if isinstance(step, int):
            out.append(f"[{step}]")
        else:
            out.append(f".{step}" if out else step)
    return "".join(out)


def ads_data_type(type_name: str) -> tuple[AdsDataType, int]:
    """The ADS data type id and size of a base type name (``DINT`` -> INT32, 4; the kernel's ``SGN32``
    too; ``STRING(20)`` -> STRING, 21)."""
    string = _STRING_TYPE.match(type_name)
    if string is not None:
        return AdsDataType.STRING, int(string[1]) + 1
    found = BASE_TYPES.get(ads_type_name(type_name))
    if found is None:
        raise ValueError(f"{type_name!r} is no IEC base type the ADS door knows ({', '.join(BASE_TYPES)})")
    return found


# --------------------------------------------------------------------------------------------
# Types
# --------------------------------------------------------------------------------------------


@dataclass(eq=False, slots=True)
class _Type:
    name: str
    size: int
    data_type: AdsDataType
    members: tuple[tuple[str, _Type, int], ...] = ()
    """structure: (member name as the layout spells it, type, byte offset)"""
    element: _Type | None = None
    """array: the element type"""
    lower: int = 0
    count: int = 0
    entry: bytes = b""

    @property
    def is_base(self) -> bool:
        return not self.members and self.element is None


@dataclass(eq=False, slots=True)
class _Node:
    key: tuple[Step, ...]
    name: str
    """as the layout spells it (the ST path up to this level)"""
    member: str
    """the last step as spelt: a member name, or ``[i]``"""
    children: dict[Step, _Node] = field(default_factory=dict)
    signal: Signal | None = None
    type: _Type | None = None


@dataclass(frozen=True, slots=True)
class Symbol:
    """One addressable level of the tree: a leaf (a signal of the image) or a structure/array."""

    name: str
    type_name: str
    size: int
    index_group: int
    index_offset: int
    entry: bytes
    """The AdsSymbolEntry (0xF009 reply; a top-level symbol's is one piece of the 0xF00B upload)."""
    signal: Signal | None
    """The leaf's signal; None for a structure or an array."""
    pieces: tuple[Piece, ...]
    """Its bytes, in order: slices of the halves (one for a leaf)."""
    view_offset: int
    """Its place in the structured view (:data:`VIEW_GROUP`)."""
    writable: bool
    """A leaf the PLC may write, or a structure/array with at least one such member."""
    handle_tail: bytes = b""
    """The extended 0xF003 reply after the handle: size, type decoration, type name (ads-client asks it)."""


class SymbolTable:
    """Lookups by name, the structured view and the prepared replies of the symbol services (built once
    per layout)."""

    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self.version = 1
        """0xF008: constant while the server runs (the layout never changes)."""
        self._types: dict[tuple[object, ...], _Type] = {}
        self._type_names: dict[str, _Type] = {}
        self._ordered_types: list[_Type] = []
        roots = self._tree(layout)
        for name in _BASE_ALWAYS:
            self._base(name)
        for root in roots:
            self._resolve(root)
        # the view: every top-level typed node back to back
        self._by_key: dict[tuple[Step, ...], Symbol] = {}
        self._top: list[Symbol] = []
        self._view_starts: list[int] = []
        self._view_leaves: list[Signal] = []
        self.view_size = 0
        for root in roots:
            self._place_top(root)
        self.symbol_count = len(self._top)
        self.leaf_count = len(self._view_leaves)
        self.upload = b"".join(s.entry for s in self._top)
        for t in self._ordered_types:
            t.entry = self._type_entry(t).encode()
        self._type_entries = {_type_key(t.name): t.entry for t in self._ordered_types}
        self.type_upload = b"".join(t.entry for t in self._ordered_types)
        self.type_count = len(self._ordered_types)
        self.upload_info = UploadInfo(self.symbol_count, len(self.upload)).encode()
        info2 = UploadInfo2(
            self.symbol_count,
            len(self.upload),
            self.type_count,
            len(self.type_upload),
            flags=int(UploadInfoFlag.IS_64_BIT_PLATFORM | UploadInfoFlag.INCLUDES_BASE_TYPES),
        )
        self.upload_info2 = info2.encode(24)
        self.upload_info2_long = info2.encode(64)
        self._names: dict[str, Symbol | None] = {}
        self._raw: dict[bytes, Symbol | None] = {}
        """names asked for -> their symbol (or None): clients ask the same few names again and again"""

    # --- building -----------------------------------------------------------------------------
    @staticmethod
    def _tree(layout: Layout) -> list[_Node]:
        roots: dict[Step, _Node] = {}
        for s in layout.signals:
            steps = parse_path(s.st_path)
            if steps is None:
                logger.warning("ADS: %r is no ST path; it is not served as a symbol", s.st_path)
                continue
            level = roots
            node: _Node | None = None
            key: tuple[Step, ...] = ()
            start = 0
            for step, end in steps:
                key = (*key, step)
                child = level.get(step)
                if child is None:
                    member = f"[{step}]" if isinstance(step, int) else s.st_path[start:end].strip(" ^.")
                    child = level[step] = _Node(key, s.st_path[:end].rstrip("^."), member)
                node, level, start = child, child.children, end
            assert node is not None
            if node.signal is not None or node.children:
                logger.warning("ADS: %s is both a value and a structure; served as the first", s.st_path)
                continue
            node.signal = s
        return list(roots.values())

    def _base(self, name: str, size: int = 0) -> _Type:
        name = ads_type_name(name)
        sig = ("base", name)
        found = self._types.get(sig)
        if found is None:
            try:
                data_type, size = ads_data_type(name)
            except ValueError:  # a type this door does not know: bytes of its size
                logger.warning("ADS: type %s is unknown here; served as %d plain bytes", name, size)
                data_type = AdsDataType.BIGTYPE
            found = self._register(sig, _Type(name.upper(), size, data_type))
        return found

    def _register(self, sig: tuple[object, ...], t: _Type) -> _Type:
        name = t.name
        n = 1
        while _type_key(t.name) in self._type_names:  # another shape of the same name: number it
            n += 1
            t.name = f"{name}_{n}"
        self._types[sig] = t
        self._type_names[_type_key(t.name)] = t
        self._ordered_types.append(t)
        return t

    def _resolve(self, node: _Node) -> _Type | None:
        """The node's type (structures and arrays after their members), or None when it has none."""
        for child in node.children.values():
            self._resolve(child)
        if node.signal is not None:
            node.type = self._base(node.signal.type_name, node.signal.size)
            return node.type
        kids = list(node.children.values())
        if not kids or any(k.type is None for k in kids):
            return None
        keys = list(node.children)
        if all(isinstance(k, int) for k in keys):
            element = kids[0].type
            lower = keys[0]
            assert isinstance(lower, int)
            if any(k.type is not element for k in kids) or keys != list(range(lower, lower + len(keys))):
                return None
            assert element is not None
            sig: tuple[object, ...] = ("array", id(element), lower, len(keys))
            t = self._types.get(sig)
            if t is None:
                t = self._register(
                    sig,
                    _Type(
                        f"ARRAY [{lower}..{lower + len(keys) - 1}] OF {element.name}",
                        element.size * len(keys),
                        element.data_type,
                        element=element,
                        lower=lower,
                        count=len(keys),
                    ),
                )
            node.type = t
            return t
        if any(isinstance(k, int) for k in keys):
            return None
        members: list[tuple[str, _Type, int]] = []
        offset = 0
        for k in kids:
            assert k.type is not None
            members.append((k.member, k.type, offset))
            offset += k.type.size
        sig = ("struct", tuple((name.lower(), id(t), off) for name, t, off in members))
        t = self._types.get(sig)
        if t is None:
            t = self._register(
                sig, _Type(self._struct_name(node, members), offset, AdsDataType.BIGTYPE, tuple(members))
            )
        node.type = t
        return t

    @staticmethod
    def _struct_name(node: _Node, members: list[tuple[str, _Type, int]]) -> str:
        names = tuple(name.lower() for name, _, _ in members)
        command = next((t for name, t, _ in members if name.lower() == "command_w"), None)
        if names == _UNIT_MEMBERS and command is not None and command.name in _UNIT_KINDS:
            return f"MC_CONTROL_{_UNIT_KINDS[command.name]}_UNIT"
        declared = _declared_structure(node)
        if declared is not None:
            return declared
        words = [str(s) for s in node.key if not isinstance(s, int)]
        root = re.sub(r"^g?p?(?=[A-Z])", "", node.name.split("[", 1)[0].split("^", 1)[0].split(".", 1)[0])
        words[0] = root or words[0]
        return "HLI_" + "_".join(w.upper() for w in words)

    def _place_top(self, node: _Node) -> None:
        if node.type is None:  # no type of its own: its typed members become symbols of their own
            for child in node.children.values():
                self._place_top(child)
            return
        symbol = self._place(node, self.view_size)
        self._top.append(symbol)
        self.view_size += node.type.size

    def _place(self, node: _Node, view_offset: int) -> Symbol:
        """The symbols of ``node`` and below, at ``view_offset`` of the view; the node's is returned."""
        t = node.type
        assert t is not None
        s = node.signal
        if s is not None:
            self._view_starts.append(view_offset)
            self._view_leaves.append(s)
            pieces: tuple[Piece, ...] = ((s.direction, s.offset, s.offset + s.size),)
            symbol = Symbol(
                node.name,
                t.name,
                s.size,
                s.image_ads_group,
                s.offset,
                _leaf_entry(s, t),
                s,
                pieces,
                view_offset,
                s.plc_writable,
                _handle_tail(s.size, t.name),
            )
        else:
            collected: list[Piece] = []
            writable = False
            offset = view_offset
            for child in node.children.values():
                sub = self._place(child, offset)
                offset += sub.size
                collected.extend(sub.pieces)
                writable = writable or sub.writable
            symbol = Symbol(
                node.name,
                t.name,
                t.size,
                VIEW_GROUP,
                view_offset,
                _entry(
                    VIEW_GROUP,
                    view_offset,
                    t.size,
                    t.data_type,
                    node.name,
                    t.name,
                    "",
                    0 if writable else int(SymbolFlag.READ_ONLY),  # only CNC->PLC members
                ),
                None,
                _merge(collected),
                view_offset,
                writable,
                _handle_tail(t.size, t.name),
            )
        self._by_key[node.key] = symbol
        return symbol

    def _type_entry(self, t: _Type) -> DataTypeEntry:
        if t.element is not None:
            return DataTypeEntry(
                t.name,
                t.element.name,
                t.size,
                int(t.data_type),
                array_dims=(ArrayInfo(t.lower, t.count),),
            )
        if t.members:
            items = [
                DataTypeEntry.item(name, m.name, m.data_type, m.size, offset) for name, m, offset in t.members
            ]
            return DataTypeEntry.struct(t.name, t.size, items)
        return DataTypeEntry.base(t.name, t.data_type, t.size)

    # --- lookups --------------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.symbol_count

    @property
    def symbols(self) -> tuple[Symbol, ...]:
        """The top-level symbols, in the order of the upload."""
        return tuple(self._top)

    def all_symbols(self) -> list[Symbol]:
        """Every level of every symbol (leaves and structures), in layout order."""
        return list(self._by_key.values())

    def find(self, name: str) -> Symbol | None:
        """The symbol of a name in any of the accepted spellings, or None."""
        if name in self._names:
            return self._names[name]
        steps = parse_path(name)
        symbol = None if steps is None else self._by_key.get(tuple(s for s, _ in steps))
        if len(self._names) >= 4096:  # a client cycling through names: stay bounded
            self._names.clear()
        self._names[name] = symbol
        return symbol

    def find_raw(self, data: bytes) -> Symbol | None:
        """:meth:`find` of a name as a client sends it (NUL-terminated, Windows-1252), cached by its bytes."""
        try:
            return self._raw[data]  # one lookup where the name was seen (a name is asked again and again)
        except KeyError:
            pass
        symbol = self.find(decode_name(data))
        if len(self._raw) >= 4096:
            self._raw.clear()
        self._raw[bytes(data)] = symbol
        return symbol

    def data_type(self, name: str) -> bytes | None:
        """The AdsDatatypeEntry of a type name (``DINT``, ``MC_CONTROL_SGN32_UNIT``,
        ``ARRAY [0..4] OF HLI_AX``), or None."""
        return self._type_entries.get(_type_key(name))

    @property
    def type_names(self) -> list[str]:
        return [t.name for t in self._ordered_types]

    # --- the structured view --------------------------------------------------------------------
    def view_pieces(self, offset: int, length: int) -> tuple[Piece, ...]:
        """The half slices behind ``length`` bytes at ``offset`` of the view (reads may cut fields)."""
        self._check_view(offset, length)
        starts, leaves = self._view_starts, self._view_leaves
        i = bisect.bisect_right(starts, offset) - 1
        pos, end = offset, offset + length
        pieces: list[Piece] = []
        while pos < end:
            s, start = leaves[i], starts[i]
            stop = min(end, start + s.size)
            pieces.append((s.direction, s.offset + pos - start, s.offset + stop - start))
            pos = stop
            i += 1
        return _merge(pieces)

    def view_leaves(self, offset: int, length: int) -> list[tuple[int, Signal]]:
        """The leaves a write of ``length`` bytes at ``offset`` of the view covers, each with its offset in
        the written data; raises 0x703/0x705 when the range cuts a field."""
        self._check_view(offset, length)
        starts, leaves = self._view_starts, self._view_leaves
        i = bisect.bisect_left(starts, offset)
        if i >= len(starts) or starts[i] != offset:
            raise AdsError(
                ErrorCode.INVALID_INDEX_OFFSET,
                f"0x{VIEW_GROUP:X} (structured view, {self.view_size} bytes): offset {offset} is inside a "
                "field; write whole fields from their offset (a symbol's offset: 0xF009)",
            )
        end = offset + length
        found: list[tuple[int, Signal]] = []
        while i < len(starts) and starts[i] < end:
            s = leaves[i]
            if starts[i] + s.size > end:
                raise AdsError(
                    ErrorCode.SIZE_WRONG,
                    f"0x{VIEW_GROUP:X}: {length} bytes from offset {offset} end inside {s.st_path}: "
                    "write whole fields",
                )
            found.append((starts[i] - offset, s))
            i += 1
        return found

    def _check_view(self, offset: int, length: int) -> None:
        if offset > self.view_size:
            raise AdsError(
                ErrorCode.INVALID_INDEX_OFFSET,
                f"index group 0x{VIEW_GROUP:X} (structured view) has {self.view_size} bytes, offset {offset} "
                "lies beyond",
            )
        if offset + length > self.view_size:
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"index group 0x{VIEW_GROUP:X} (structured view, {self.view_size} bytes): {length} bytes "
                f"from offset {offset} run past its end",
            )


def _declared_structure(node: _Node) -> str | None:
    """The declared type of a V.E. structure's node (``gpVEGlob^curve[2].point[5]`` -> ``typ_pos``): its
    leaves name the structure of every level of their path (``Signal.structures``)."""
    leaf = node
    while leaf.signal is None:
        if not leaf.children:
            return None
        leaf = next(iter(leaf.children.values()))
    signal = leaf.signal
    if not signal.scope.external or not signal.structures:
        return None
    area = 1 if signal.scope is Scope.VE_GLOBAL else 2  # gpVEGlob / gpVECh, [i]
    depth = sum(1 for step in node.key[area:] if not isinstance(step, int))
    return signal.structures[depth - 1] if 1 <= depth <= len(signal.structures) else None


def _handle_tail(size: int, type_name: str) -> bytes:
    return HandleInfo(0, size, type_name).encode()[4:]


def _type_key(name: str) -> str:
    return "".join(name.split()).lower()


def _merge(pieces: list[Piece]) -> tuple[Piece, ...]:
    merged: list[Piece] = []
    for d, start, end in pieces:
        if merged and merged[-1][0] is d and merged[-1][2] == start:
            merged[-1] = (d, merged[-1][1], end)
        else:
            merged.append((d, start, end))
    return tuple(merged)


def _entry(
    group: int, offset: int, size: int, data_type: int, name: str, type_name: str, comment: str, flags: int
) -> bytes:
    comment = comment.encode("cp1252", "replace").decode("cp1252")  # what the wire can carry
    raw = SymbolEntry(group, offset, size, int(data_type), name, type_name, comment, flags).encode()
    if len(raw) > MAX_SYMBOL_INFO:  # keep every entry within pyads' read length: cut the comment
        room = len(comment.encode("cp1252", "replace")) - (len(raw) - MAX_SYMBOL_INFO)
        comment = comment[: max(0, room - 3)] + "..."
        raw = SymbolEntry(group, offset, size, int(data_type), name, type_name, comment, flags).encode()
    return raw


def _leaf_entry(s: Signal, t: _Type) -> bytes:
    flags = 0 if s.plc_writable else int(SymbolFlag.READ_ONLY)
    comment = s.description if s.unit in ("", "-") else f"{s.description} [{s.unit}]"
    return _entry(s.image_ads_group, s.offset, s.size, t.data_type, s.st_path, t.name, comment, flags)
