"""The process data over ADS: the halves, the structured view, the CNC objects, values by handle (H-04).

What each index group serves (``docs/ads.md`` has the table for users)::

    851  0xF030  PLC->CNC half, offset = byte offset        Read, Write (whole fields), notification
         0xF020  CNC->PLC half (newest consistent publish)  Read, notification; Write = 0x704
         0x4040  the structured view (symbols.VIEW_GROUP)   Read, Write (whole fields; _r members are
                                                            left to the CNC), notification
         0xF003  handle by name (ReadWrite)   0xF005 value by handle (offset = handle)
         0xF006  release a handle (Write)     0xF004 value by name (ReadWrite)
    551  0x120300 the dyn_coll_mon objects, offset (A_ID << 16) | element, exact size (FCT-C3 4.3,
                  C3-10); every Write on port 551 = 0x704

Writes change nothing unless every value is acceptable (a BOOL byte other than 0/1 is 0x706) and every
range covers whole fields. A V.E. STRING read by handle or by name answers its own bytes to a longer
read (pyads reads a STRING with a read length of 1024 and takes what comes, as TwinCAT answers; a read at
its address in 0xF030 gets the bytes up to the end of the half) and takes a shorter write up to its NUL
(pyads writes the text and one NUL): the rest of the field is then NUL; a STRING's bytes without a NUL
within the field (a character too many) are 0x706. A structure written as a whole (ads-client
``writeValue`` of a control unit, pyads ``write_structure_by_name``) sets its ``_w`` members; its ``_r``
members are the CNC's, which overwrites them every cycle in the kernel, so their bytes in the write are
ignored here. A write that covers no ``_w`` member at all is refused with 0x704, as a write of a ``_r``
field by name is.
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING, Final

from hli_server.adapters.ads.session import Watch
from hli_server.adapters.ads.symbols import VIEW_GROUP, Symbol, SymbolTable
from hli_server.codecs.ads import AdsError, ErrorCode, decode_name
from schemas.image_format import decode_field
from schemas.layout import (
    ADS_GROUP_CNC_TO_PLC,
    ADS_GROUP_GEO_AXIS,
    ADS_GROUP_PLC_TO_CNC,
    ADS_PORT_GEO,
    Direction,
    LayoutError,
    ReadOnlySignalError,
    Signal,
    SignalType,
    SignalValueError,
)

if TYPE_CHECKING:
    from hli_server.adapters.ads.session import DeviceLimits, Session
    from hli_server.adapters.host import ImagePort

__all__ = ["DataService"]

_P2C: Final = Direction.PLC_TO_CNC
_C2P: Final = Direction.CNC_TO_PLC
_U32: Final = struct.Struct("<I")


class DataService:
    """Reads, writes and watches of the image's bytes (module docstring)."""

    def __init__(
        self, image: ImagePort, symbols: SymbolTable, limits: DeviceLimits, *, read_only: bool
    ) -> None:
        self.image = image
        self.symbols = symbols
        self.layout = image.layout
        self.limits = limits
        self.read_only = read_only
        """``--read-only``: every write is refused with 0x704 (docs/reliability.md)."""
        self.sizes = {d: image.layout.size(d) for d in Direction}
        self._c2p = b""
        self._c2p_count = -1
        self._publish_count = image.publish_counter()
        self._c2p_size = self.sizes[_C2P]
        self._geo: dict[int, Signal] = {
            s.ads_offset: s for s in self.layout.signals if s.ads_port == ADS_PORT_GEO
        }
        self._p2c_inside = _interior(self.layout.half(_P2C))
        self._p2c_strings = frozenset(s.offset for s in self.layout.half(_P2C) if s.type is SignalType.STRING)
        """Where a V.E. STRING starts: a read from there may ask more than the half has left (pyads'
        ``AdsSymbol.read`` of a STRING asks 1024 bytes at its address) and gets the bytes to the end."""

    # --- the halves -------------------------------------------------------------------------------
    def c2p(self) -> bytes:
        """The CNC->PLC half of the newest publish (one copy per publish)."""
        count = self._publish_count()
        if count != self._c2p_count:
            self._c2p = self.image.snapshot()[1]
            self._c2p_count = count
        return self._c2p

    def p2c(self) -> bytes:
        return self.image.read_half(_P2C)

    def half(self, direction: Direction) -> bytes:
        return self.c2p() if direction is _C2P else self.p2c()

    def gather(self, symbol: Symbol) -> bytes:
        pieces = symbol.pieces
        if len(pieces) == 1:
            direction, start, end = pieces[0]
            return self.half(direction)[start:end]
        halves: dict[Direction, bytes] = {}
        parts = []
        for direction, start, end in pieces:
            half = halves.get(direction)
            if half is None:
                half = halves[direction] = self.half(direction)
            parts.append(half[start:end])
        return b"".join(parts)

    # --- reads: (session, offset, length) -> bytes ------------------------------------------------
    def read_c2p(self, session: Session, offset: int, length: int) -> bytes:
        # the raw read of a PLC's polling: one comparison covers both of _check_range's cases (the length
        # is unsigned); only a read out of range calls it, for its precise error
        end = offset + length
        if end > self._c2p_size:
            self._check_range(_C2P, ADS_GROUP_CNC_TO_PLC, offset, length)
        return self.c2p()[offset:end]

    def read_p2c(self, session: Session, offset: int, length: int) -> bytes:
        if offset in self._p2c_strings:  # a STRING read the pyads way (1024 bytes): up to the half's end
            length = min(length, self.sizes[_P2C] - offset)
        self._check_range(_P2C, ADS_GROUP_PLC_TO_CNC, offset, length)
        return self.p2c()[offset : offset + length]

    def read_view(self, session: Session, offset: int, length: int) -> bytes:
        pieces = self.symbols.view_pieces(offset, length)
        halves: dict[Direction, bytes] = {}
        parts = []
        for direction, start, end in pieces:
            half = halves.get(direction)
            if half is None:
                half = halves[direction] = self.half(direction)
            parts.append(half[start:end])
        return b"".join(parts)

    def read_by_handle(self, session: Session, handle: int, length: int) -> bytes:
        symbol = session.handles.get(handle)
        if symbol is None:
            symbol = self.handle(session, handle)  # raises 0x710
        if length != symbol.size:
            _check_size(symbol, length, "read")
        return self.gather(symbol)

    def read_geo(self, session: Session, offset: int, length: int) -> bytes:
        signal = self._geo_signal(offset, length)
        return self.c2p()[signal.offset : signal.offset + signal.size]

    def _geo_signal(self, offset: int, length: int) -> Signal:
        signal = self._geo.get(offset)
        if signal is None:
            axes = ", ".join(f"{a.name}=0x{a.number:X}" for a in self.layout.axes)
            raise AdsError(
                ErrorCode.INVALID_INDEX_OFFSET,
                f"port 551 group 0x{ADS_GROUP_GEO_AXIS:X}: no CNC object at offset 0x{offset:08X}; "
                f"the offset is (A_ID << 16) | element, A_ID of the axes: {axes}; elements 0x0234 active, "
                "0x0244 velocity, 0x0245 brake_dist, 0x0246 coll_offset, 0x0247 deceleration (FCT-C3 4.3)",
            )
        if length != signal.size:
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"port 551 0x{ADS_GROUP_GEO_AXIS:X}/0x{offset:08X} is {signal.name} ({signal.type}, "
                f"{signal.size} bytes), read asked {length} bytes",
            )
        return signal

    def _check_range(self, direction: Direction, group: int, offset: int, length: int) -> None:
        size = self.sizes[direction]
        if offset > size:
            raise AdsError(
                ErrorCode.INVALID_INDEX_OFFSET,
                f"index group 0x{group:X} ({direction} half) has {size} bytes, offset {offset} lies beyond",
            )
        if offset + length > size:
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"index group 0x{group:X} ({direction} half, {size} bytes): {length} bytes from offset "
                f"{offset} run past its end",
            )

    # --- watches: (session, offset, length) -> Watch ----------------------------------------------
    def watch_c2p(self, session: Session, offset: int, length: int) -> Watch:
        self._check_range(_C2P, ADS_GROUP_CNC_TO_PLC, offset, length)
        return Watch(((_C2P, offset, offset + length),))

    def watch_p2c(self, session: Session, offset: int, length: int) -> Watch:
        self._check_range(_P2C, ADS_GROUP_PLC_TO_CNC, offset, length)
        return Watch(((_P2C, offset, offset + length),))

    def watch_view(self, session: Session, offset: int, length: int) -> Watch:
        return Watch(tuple(self.symbols.view_pieces(offset, length)))

    def watch_handle(self, session: Session, handle: int, length: int) -> Watch:
        symbol = self.handle(session, handle)
        _check_size(symbol, length, "watch")
        return Watch(symbol.pieces)

    def watch_geo(self, session: Session, offset: int, length: int) -> Watch:
        s = self._geo_signal(offset, length)
        return Watch(((_C2P, s.offset, s.offset + s.size),))

    # --- writes: (session, offset, data) -> None --------------------------------------------------
    def write_p2c(self, session: Session, offset: int, data: bytes) -> None:
        self._refuse_if_read_only()
        size = self.sizes[_P2C]
        end = offset + len(data)
        if offset > size or offset in self._p2c_inside:
            where = "lies beyond the half" if offset > size else "is inside a field"
            raise AdsError(
                ErrorCode.INVALID_INDEX_OFFSET,
                f"0xF030 (PLC->CNC half, {size} bytes): offset {offset} {where}; write whole fields "
                "from their offset (`hli-server map` lists them)",
            )
        if end > size or end in self._p2c_inside:
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"0xF030: {len(data)} bytes from offset {offset} "
                + ("run past the half's end" if end > size else "end inside a field: write whole fields"),
            )
        self._write_bytes(offset, data)

    def write_c2p(self, session: Session, offset: int, data: bytes) -> None:
        raise AdsError(
            ErrorCode.READ_WRITE_NOT_PERMITTED,
            "index group 0xF020 is the CNC->PLC half: only the CNC writes it (H-02); "
            "the PLC writes the _w fields in 0xF030",
        )

    def write_view(self, session: Session, offset: int, data: bytes) -> None:
        self._write_leaves(self.symbols.view_leaves(offset, len(data)), data, f"0x{VIEW_GROUP:X}/{offset}")

    def write_by_handle(self, session: Session, handle: int, data: bytes) -> None:
        self.write_symbol(self.handle(session, handle), data)

    def write_symbol(self, symbol: Symbol, data: bytes) -> None:
        _check_size(symbol, len(data), "write")
        s = symbol.signal
        if s is not None:
            if not s.plc_writable:
                raise AdsError(ErrorCode.READ_WRITE_NOT_PERMITTED, _read_only_text(s))
            self._refuse_if_read_only()
            if len(data) < s.size:  # a STRING's text and its NUL (_check_size let nothing else through)
                _check_value(s, data)
                data = data.partition(b"\0")[0].ljust(s.size, b"\0")
            self._write_bytes(s.offset, data)
            return
        start = symbol.view_offset
        self._write_leaves(self.symbols.view_leaves(start, len(data)), data, symbol.name)

    def release_handle(self, session: Session, offset: int, data: bytes) -> None:
        if len(data) != 4:
            raise AdsError(ErrorCode.SIZE_WRONG, f"0xF006 takes a 4-byte handle, got {len(data)} bytes")
        handle = _U32.unpack(data)[0]
        if session.handles.pop(handle, None) is None:
            raise AdsError(ErrorCode.SYMBOL_NOT_FOUND, f"0xF006: no symbol handle 0x{handle:X} to release")

    def refuse_geo_write(self, session: Session, offset: int, data: bytes) -> None:
        raise AdsError(
            ErrorCode.READ_WRITE_NOT_PERMITTED,
            "port 551 serves the CNC objects of FCT-C3 4.3 read-only (C3-10)",
        )

    def _write_leaves(self, leaves: list[tuple[int, Signal]], data: bytes, where: str) -> None:
        """Write the ``_w`` leaves of a view range: all values checked, then each run of the half."""
        writes = [(pos, s) for pos, s in leaves if s.plc_writable]
        if not writes:
            names = ", ".join(s.st_path for _, s in leaves[:3]) + (" ..." if len(leaves) > 3 else "")
            raise AdsError(
                ErrorCode.READ_WRITE_NOT_PERMITTED,
                f"{where} covers only CNC->PLC fields ({names}): only the CNC writes them (H-02); "
                "the PLC writes the _w fields",
            )
        self._refuse_if_read_only()
        for pos, s in writes:
            _check_value(s, data[pos : pos + s.size])
        runs: list[tuple[int, bytearray]] = []
        for pos, s in writes:  # half offsets ascend with view offsets inside a block: join neighbours
            if runs and runs[-1][0] + len(runs[-1][1]) == s.offset:
                runs[-1][1].extend(data[pos : pos + s.size])
            else:
                runs.append((s.offset, bytearray(data[pos : pos + s.size])))
        for offset, run in runs:
            self._write_bytes(offset, bytes(run))

    def _write_bytes(self, offset: int, data: bytes) -> None:
        try:
            self.image.write_bytes(offset, data)
        except SignalValueError as exc:
            raise AdsError(ErrorCode.INVALID_VALUE, f"0xF030 offset {offset}: {exc}") from None
        except ReadOnlySignalError as exc:  # pragma: no cover - the half holds only _w fields
            raise AdsError(ErrorCode.READ_WRITE_NOT_PERMITTED, str(exc)) from None
        except LayoutError as exc:  # pragma: no cover - the checks above cover what it refuses
            raise AdsError(ErrorCode.SIZE_WRONG, str(exc)) from None

    def _refuse_if_read_only(self) -> None:
        if self.read_only:
            raise AdsError(
                ErrorCode.READ_WRITE_NOT_PERMITTED, "the server runs --read-only: writes are refused"
            )

    # --- handles ------------------------------------------------------------------------------------
    def handle(self, session: Session, handle: int) -> Symbol:
        symbol = session.handles.get(handle)
        if symbol is None:
            raise AdsError(
                ErrorCode.SYMBOL_NOT_FOUND,
                f"no symbol handle 0x{handle:X} on this connection (handles live as long as their "
                "connection; get one with 0xF003)",
            )
        return symbol

    def symbol(self, data: bytes) -> Symbol:
        symbol = self.symbols.find_raw(data)
        if symbol is None:
            name = decode_name(data)
            raise AdsError(
                ErrorCode.SYMBOL_NOT_FOUND,
                f"no symbol {name[:200]!r}: symbols are the ST paths of `hli-server map` and every level "
                "above them, e.g. gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w or "
                "gpAx[0]^ipo_mc_control.dyn_pos_limit_high (also spelt gpAx[0].ipo_... and gpAx[0]^.ipo_...)",
            )
        return symbol

    def handle_by_name(self, session: Session, offset: int, read_length: int, data: bytes) -> bytes:
        symbol = self.symbol(data)
        if len(session.handles) >= self.limits.max_handles:
            raise AdsError(
                ErrorCode.NO_MEMORY,
                f"this connection holds {len(session.handles)} symbol handles (max_handles); "
                "release some with 0xF006",
            )
        if read_length < 4:
            raise AdsError(ErrorCode.SIZE_WRONG, f"0xF003 answers a 4-byte handle, read length {read_length}")
        handle = _U32.pack(session.new_handle(symbol))
        tail = symbol.handle_tail  # the extended reply when it fits (ads-client), else the handle (pyads)
        return handle + tail if read_length >= 4 + len(tail) else handle

    def value_by_name(self, session: Session, offset: int, read_length: int, data: bytes) -> bytes:
        symbol = self.symbol(data)
        _check_size(symbol, read_length, "read")
        return self.gather(symbol)


def _check_size(symbol: Symbol, length: int, what: str) -> None:
    if length != symbol.size and not _string_size_fits(symbol, length, what):
        raise AdsError(
            ErrorCode.SIZE_WRONG,
            f"{symbol.name} is {symbol.type_name} ({symbol.size} bytes): the {what} has {length} bytes",
        )


def _string_size_fits(symbol: Symbol, length: int, what: str) -> bool:
    """A STRING symbol's read may ask more (it gets the field), its write may give less (its text and
    the NUL, at least one byte)."""
    s = symbol.signal
    if s is None or s.type is not SignalType.STRING:
        return False
    return length > s.size if what == "read" else 0 < length < s.size


def _check_value(s: Signal, raw: bytes) -> None:
    """Refuse (0x706) bytes the field cannot take, before anything is written: a BOOL byte other than
    0/1, a STRING without its NUL, and whatever the signal's own check refuses (a V.E. variable's kernel
    range, for one)."""
    try:
        s.coerce(decode_field(s, raw))
    except SignalValueError as exc:
        raise AdsError(ErrorCode.INVALID_VALUE, str(exc)) from None


def _read_only_text(s: Signal) -> str:
    return (
        f"{s.st_path} is CNC->PLC: only the CNC writes it (H-02). "
        "The PLC writes the _w fields (command_w, enable_w, ...) and reads the _r fields"
    )


def _interior(signals: tuple[Signal, ...]) -> frozenset[int]:
    """Byte offsets strictly inside a field (a write may neither start nor end there)."""
    return frozenset(o for s in signals for o in range(s.offset + 1, s.offset + s.size))
