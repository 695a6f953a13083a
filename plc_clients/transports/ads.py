"""The ADS transport: the image over ADS/TCP with pyads (H-06 over H-04).

:class:`AdsTransport` (blocking, for scripts and threads) and :class:`AsyncAdsTransport` (the same
calls run in a worker thread, for PLC tasks in an event loop) have the protocol of
:mod:`plc_clients.transports.base`: ``snapshot``, ``read``, ``write``, ``write_many``, ``close``,
``layout``.

* ``snapshot()`` is one ADS Read of the whole CNC->PLC half (index group 0xF020 on AMS port 851):
  every value comes from one publish, so :attr:`~plc_clients.transports.Inputs.consistent` is
  always True (unlike Modbus, where a snapshot may take several requests);
* ``read``/``write`` address one field by its image place (0xF020/0xF030 + byte offset);
* ``write_many`` is one sum write (0xF081) of the fields in the given order: the server performs
  them in that order within one turn, so no CNC cycle falls between them.

**The layout** must be the server's, as for Modbus (a :class:`~schemas.layout.Layout`, the file of
``hli-server map --format json`` or the URL of the HTTP API); unlike Modbus, ADS can check it:
:meth:`AdsTransport.connect` asks the server's symbol info (0xF009) of every signal, 50 in one sum
read/write (0xF082), and raises :class:`~schemas.layout.LayoutError` naming the first signal the server
does not have at the same place with the same type.

**pyads/AdsLib on Linux** has one AMS router per process with one route per NetId. This module adds
the route on connect and deletes it with the last transport of the process that uses it (AdsLib
crashes when a route is deleted while another port still has notifications on it). Two servers with
the same NetId cannot be reached from one process: start them with different ``--ams-net-id``.
``local_net_id`` sets the process' own NetId (what the server's allowlist sees).

Imports ``schemas``, the sans-I/O ADS codec and pyads, never the server.
"""

from __future__ import annotations

import asyncio
import os
import struct
import threading
from collections.abc import Collection, Iterable
from typing import Any, ClassVar, Final

from hli_server.codecs.ads import (
    AdsCodecError,
    SumReadWrite,
    SumReadWriteItem,
    SymbolEntry,
    ads_type_name,
    decode_sum_read_write_reply,
)
from plc_clients._closing import ClosesOnExit
from plc_clients.transports.base import (
    CYCLE_SIGNAL,
    Inputs,
    TransportError,
    Value,
    _CycleCounter,
    load_layout,
)
from schemas.layout import STRING_ENCODING, Direction, Layout, LayoutError, Signal, SignalType

__all__ = [
    "DEFAULT_AMS_PORT",
    "DEFAULT_NET_ID",
    "AdsTransport",
    "AdsTransportError",
    "AsyncAdsTransport",
    "close_pyads",
    "open_pyads",
]

DEFAULT_NET_ID: Final = "127.0.0.1.1.1"
DEFAULT_AMS_PORT: Final = 851
_TCP_PORT: Final = 48898
_C2P, _P2C = Direction.CNC_TO_PLC, Direction.PLC_TO_CNC
_GROUP = {_C2P: 0xF020, _P2C: 0xF030}
_SUM_WRITE: Final = 0xF081
_SUM_READ_WRITE: Final = 0xF082
_SYMBOL_INFO: Final = 0xF009
_SYMBOL_INFO_LENGTH: Final = 798
"""The read length pyads asks symbol info with (the server keeps every entry within it)."""
_CHECK_CHUNK: Final = 50
_TAKE_IT: Final = (
    "take it from this server (`hli-server map --format json` of its machine file, or its HTTP API)"
)
_ROUTER_IN_USE: Final = 1286

_NO_ENTRY: Final = SymbolEntry(0, 0, 0, 0, "", "")

_routes_lock = threading.Lock()
_routes: dict[str, tuple[str, int]] = {}
"""NetId -> (address, open connections of this process on it); the last one deletes AdsLib's route."""


def open_pyads(net_id: str, ams_port: int, address: str, timeout: float = 2.0) -> Any:
    """An open ``pyads.Connection`` to ``net_id:ams_port`` at ``address`` (``host:tcp_port``).

    AdsLib has one route per NetId per process: the first connection adds it, later ones to the
    same address share it; one to another address with the same NetId is refused (ValueError)."""
    pyads = _pyads()
    conn = pyads.Connection(net_id, ams_port, address)
    with _routes_lock:
        known = _routes.get(net_id)
        if known is not None and known[0] != address:
            raise ValueError(
                f"this process already talks to AMS NetId {net_id} at {known[0]}, not {address}: AdsLib "
                "has one route per NetId; give each server its own --ams-net-id"
            )
        if known is not None:
            conn._port = pyads.pyads_ex.adsPortOpenEx()
            conn._open = True
        else:
            try:
                conn.open()
            except pyads.ADSError as exc:
                if exc.err_code != _ROUTER_IN_USE:
                    raise
                # a route left behind by a connection closed the pyads way: replace it
                pyads.pyads_ex.adsDelRoute(conn._adr.netIdStruct())
                conn.open()
        _routes[net_id] = (address, (known[1] if known else 0) + 1)
    conn.set_timeout(int(timeout * 1000))  # AdsLib's time-out belongs to the open AMS port
    return conn


def close_pyads(conn: Any) -> None:
    """Close a connection of :func:`open_pyads`: its AMS port first, the route with the last one
    (pyads' own ``close`` deletes the route first, and AdsLib then crashes closing a second port
    on it that had notifications)."""
    pyads = _pyads()
    with _routes_lock:
        if not conn._open:
            return
        if conn._port is not None:
            pyads.pyads_ex.adsPortCloseEx(conn._port)
            conn._port = None
        conn._open = False
        net_id = conn.ams_net_id
        address, count = _routes.get(net_id, ("", 1))
        if count <= 1:
            _routes.pop(net_id, None)
            pyads.pyads_ex.adsDelRoute(conn._adr.netIdStruct())
        else:
            _routes[net_id] = (address, count - 1)


class AdsTransportError(TransportError):
    """A failure of the ADS door; ``ads_error`` is the ADS error code when the server answered one
    (0x704 not permitted, 0x710 symbol not found, ..., 1861 AdsLib's time-out)."""

    def __init__(self, message: str, *, ads_error: int | None = None) -> None:
        super().__init__(message)
        self.ads_error = ads_error


def _pyads() -> Any:
    import pyads  # type: ignore[import-untyped]  # no type information shipped

    return pyads


class AdsTransport(ClosesOnExit):
    """ADS/TCP with pyads' ``Connection`` (blocking). Construct with :meth:`connect`."""

    is_async: ClassVar[bool] = False
    blocking: ClassVar[bool] = True

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = _TCP_PORT,
        *,
        layout: Layout | str | os.PathLike[str],
        ams_net_id: str = DEFAULT_NET_ID,
        ams_port: int = DEFAULT_AMS_PORT,
        timeout: float = 2.0,
    ) -> None:
        self.host = host
        self.port = port
        self.ams_net_id = ams_net_id
        self.ams_port = ams_port
        self.timeout = timeout
        self.layout: Layout = load_layout(layout)
        self._c2p_size = self.layout.c2p_size
        self._c2p_struct = struct.Struct(self.layout.struct_format(_C2P))
        self._c2p_paths = [s.st_path for s in self.layout.half(_C2P)]
        self._counter = _CycleCounter()
        self._conn: Any = None

    @property
    def where(self) -> str:
        return f"ADS {self.host}:{self.port} (AMS NetId {self.ams_net_id}, port {self.ams_port})"

    @classmethod
    def connect(
        cls,
        host: str = "127.0.0.1",
        port: int = _TCP_PORT,
        *,
        layout: Layout | str | os.PathLike[str],
        ams_net_id: str = DEFAULT_NET_ID,
        ams_port: int = DEFAULT_AMS_PORT,
        local_net_id: str | None = None,
        timeout: float = 2.0,
        check_layout: bool = True,
    ) -> AdsTransport:
        """Connect and (``check_layout``) compare the layout with the server's symbols.

        Raises :class:`AdsTransportError` when no server answers, :class:`LayoutError` when the
        layout is not the server's."""
        transport = cls(host, port, layout=layout, ams_net_id=ams_net_id, ams_port=ams_port, timeout=timeout)
        transport._open(local_net_id)
        try:
            transport._call("reading the ADS state", transport._conn.read_state)
            if check_layout:
                transport._check_layout()
        except BaseException:
            transport.close()
            raise
        return transport

    # --- connection -------------------------------------------------------------------------
    def _open(self, local_net_id: str | None) -> None:
        pyads = _pyads()
        if local_net_id is not None:
            pyads.open_port()
            pyads.set_local_address(local_net_id)
            pyads.close_port()
        try:
            self._conn = open_pyads(self.ams_net_id, self.ams_port, f"{self.host}:{self.port}", self.timeout)
        except pyads.ADSError as exc:
            raise AdsTransportError(
                f"{self.where}: connecting failed: {exc}", ads_error=exc.err_code
            ) from exc
        except ValueError as exc:
            raise AdsTransportError(f"{self.where}: {exc}") from exc

    def close(self) -> None:
        """Close the AMS port; the last transport on a NetId deletes AdsLib's route."""
        conn, self._conn = self._conn, None
        if conn is not None:
            close_pyads(conn)

    def _call(self, what: str, fn: Any, *args: Any, **kwargs: Any) -> Any:
        if self._conn is None:
            raise AdsTransportError(f"{self.where}: {what}: the transport is closed")
        pyads = _pyads()
        try:
            return fn(*args, **kwargs)
        except pyads.ADSError as exc:
            code = exc.err_code
            hint = (
                "; is `hli-server run --ads-port ...` running with this AMS NetId?"
                if code in (1861, 6, 7, 0x745)
                else ""
            )
            raise AdsTransportError(f"{self.where}: {what} failed: {exc}{hint}", ads_error=code) from exc
        except (OSError, RuntimeError) as exc:
            raise AdsTransportError(f"{self.where}: {what} failed: {exc}") from exc

    def _read_raw(self, what: str, group: int, offset: int, size: int) -> bytes:
        pyads = _pyads()
        data = self._call(what, self._conn.read, group, offset, pyads.PLCTYPE_BYTE * size, return_ctypes=True)
        return bytes(data)

    def _check_layout(self) -> None:
        signals = self.layout.signals
        for start in range(0, len(signals), _CHECK_CHUNK):
            chunk = signals[start : start + _CHECK_CHUNK]
            for s, (code, entry) in zip(chunk, self._symbol_infos(chunk), strict=True):
                if code:
                    raise LayoutError(
                        f"{self.where}: the server has no symbol {s.st_path} (ADS error 0x{code:X}): "
                        f"the layout is not the server's; {_TAKE_IT}"
                    )
                ours = (s.st_path, s.image_ads_group, s.offset, s.size, ads_type_name(s.type_name))
                theirs = (entry.name, entry.index_group, entry.index_offset, entry.size, entry.type_name)
                if ours != theirs:
                    raise LayoutError(
                        f"{self.where}: the layout is not the server's: here {ours}, on the server {theirs}; "
                        f"{_TAKE_IT}"
                    )

    def _symbol_infos(self, chunk: tuple[Signal, ...]) -> list[tuple[int, SymbolEntry]]:
        """The symbol info (0xF009) of each signal, in one sum read/write (0xF082)."""
        pyads = _pyads()
        items = tuple(
            SumReadWriteItem(_SYMBOL_INFO, 0, _SYMBOL_INFO_LENGTH, s.st_path.encode("cp1252") + b"\0")
            for s in chunk
        )
        request = SumReadWrite(items).encode()
        n = len(items)
        raw = bytes(
            self._call(
                "reading the symbol info",
                self._conn.read_write,
                _SUM_READ_WRITE,
                n,
                pyads.PLCTYPE_BYTE * (n * (8 + _SYMBOL_INFO_LENGTH)),
                request,
                pyads.PLCTYPE_BYTE * len(request),
                return_ctypes=True,
                check_length=False,
            )
        )
        try:
            heads = struct.unpack_from(f"<{2 * n}I", raw)
            length = 8 * n + sum(heads[1::2])
            results = decode_sum_read_write_reply(n, raw[:length])
            return [(code, SymbolEntry.decode(data)[0] if not code else _NO_ENTRY) for code, data in results]
        except (AdsCodecError, struct.error) as exc:
            raise LayoutError(f"{self.where}: the server's symbol info does not decode: {exc}") from exc

    # --- the transport protocol ---------------------------------------------------------------
    def snapshot(self, watch: Collection[str] | None = None) -> Inputs:
        """The whole CNC->PLC half in one Read (one publish); ``watch`` only checks the paths."""
        if watch is not None:
            for path in watch:
                self.layout.signal(path)
        raw = self._read_raw("reading the CNC->PLC half", _GROUP[_C2P], 0, self._c2p_size)
        values = dict(zip(self._c2p_paths, self._c2p_struct.unpack(raw), strict=True))
        cycle = self._counter.update(int(values[CYCLE_SIGNAL])) if CYCLE_SIGNAL in values else 0
        return Inputs(cycle, values, True)

    def read(self, st_path: str) -> Value:
        s = self.layout.signal(st_path)
        raw = self._read_raw(f"reading {st_path}", _GROUP[s.direction], s.offset, s.size)
        return _value(s, raw)

    @staticmethod
    def _encode(s: Signal, value: Value) -> bytes:
        s.check_plc_write()
        return struct.pack("<" + s.struct_char, s.encode(s.coerce(value)))

    def write(self, st_path: str, value: Value) -> None:
        s = self.layout.signal(st_path)
        data = self._encode(s, value)
        pyads = _pyads()
        self._call(
            f"writing {st_path}", self._conn.write, _GROUP[_P2C], s.offset, data, pyads.PLCTYPE_BYTE * s.size
        )

    def write_many(self, items: Iterable[tuple[str, Value]]) -> None:
        """One sum write (0xF081), performed by the server in the given order; all checked first."""
        fields = []
        for st_path, value in items:
            s = self.layout.signal(st_path)
            fields.append((s, self._encode(s, value)))
        if not fields:
            return
        if len(fields) == 1:
            s, data = fields[0]
            self.write(s.st_path, _value(s, data))
            return
        heads = b"".join(struct.pack("<III", _GROUP[_P2C], s.offset, s.size) for s, _ in fields)
        payload = heads + b"".join(data for _, data in fields)
        pyads = _pyads()
        n = len(fields)
        reply = self._call(
            f"sum write of {n} fields",
            self._conn.read_write,
            _SUM_WRITE,
            n,
            pyads.PLCTYPE_BYTE * (4 * n),
            bytearray(payload),  # pyads passes a sum write's data as a writable buffer
            pyads.PLCTYPE_BYTE * len(payload),
            return_ctypes=True,
        )
        for (s, _), (code,) in zip(fields, struct.iter_unpack("<I", bytes(reply)), strict=True):
            if code:
                raise AdsTransportError(
                    f"{self.where}: writing {s.st_path} was refused with ADS error 0x{code:X}", ads_error=code
                )

    @property
    def cycle(self) -> int:
        """The CNC's newest cycle (one request)."""
        return self._counter.update(int(self.read(CYCLE_SIGNAL)))

    def __repr__(self) -> str:
        return f"AdsTransport({self.host!r}, {self.port}, {self.ams_net_id}:{self.ams_port})"


def _value(s: Signal, raw: bytes) -> Value:
    """A field's value from its bytes (a STRING's text up to its NUL)."""
    if s.type is SignalType.STRING:
        return raw.partition(b"\0")[0].decode(STRING_ENCODING, "replace")
    value: Value = struct.unpack("<" + s.struct_char, raw)[0]
    return value


class AsyncAdsTransport:
    """:class:`AdsTransport` for asyncio: every call runs in a worker thread (pyads blocks).

    Construct with ``await AsyncAdsTransport.connect(...)`` (same arguments)."""

    is_async: ClassVar[bool] = True
    blocking: ClassVar[bool] = False

    def __init__(self, sync: AdsTransport) -> None:
        self._sync = sync
        self.layout: Layout = sync.layout

    @classmethod
    async def connect(cls, *args: Any, **kwargs: Any) -> AsyncAdsTransport:
        return cls(await asyncio.to_thread(AdsTransport.connect, *args, **kwargs))

    async def snapshot(self, watch: Collection[str] | None = None) -> Inputs:
        return await asyncio.to_thread(self._sync.snapshot, watch)

    async def read(self, st_path: str) -> Value:
        return await asyncio.to_thread(self._sync.read, st_path)

    async def write(self, st_path: str, value: Value) -> None:
        await asyncio.to_thread(self._sync.write, st_path, value)

    async def write_many(self, items: Iterable[tuple[str, Value]]) -> None:
        await asyncio.to_thread(self._sync.write_many, list(items))

    async def close(self) -> None:
        await asyncio.to_thread(self._sync.close)

    def __repr__(self) -> str:
        return f"Async{self._sync!r}"
