"""The PLC doors the harness can open, by name (H-06, H-07): a small registry.

One behaviour test runs through every door of the same server (asyncua's ``opc`` fixture is the
model): the ``plc_transport`` fixture is parametrized over this registry. Each entry says which
server adapter its door needs, which modules must be importable, and how to open a synchronous
:class:`plc_clients.Transport` to a running :class:`~hli_server.testing.Harness`:

========= ========================== ============================================================
name      server side                PLC side (``plc_clients``)
========= ========================== ============================================================
``shm``   the process image          :class:`ShmTransport` (over the buffer of a memory image, or
                                     attached by name to ``/dev/shm``)
``modbus`` adapter ``modbus``         :class:`ModbusTransport` with the server's layout
``ads``   adapter ``ads``            ``plc_clients.ads.AdsTransport`` (pyads), once both exist
========= ========================== ============================================================

A door whose parts are missing is skipped with the reason (:func:`unavailable`), never failed: the
ADS door plugs in by itself when ``plc_clients.ads`` and the ``ads`` adapter are installed.
``register_transport`` adds a door (a plugin, a user's own fieldbus).
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from hli_server.adapters.registry import Adapter
    from hli_server.runtime import Runtime
    from plc_clients.transports import Transport
    from schemas.layout import Layout

__all__ = [
    "TRANSPORTS",
    "ServerUnderTest",
    "TransportKind",
    "open_transport",
    "register_transport",
    "transport_names",
    "unavailable",
]


class ServerUnderTest(Protocol):
    """What a door's opener needs of the server under test: :class:`~hli_server.testing.Harness` is one
    (a protocol, so that this registry does not import the harness that uses it)."""

    bind: str

    @property
    def runtime(self) -> Runtime: ...

    @property
    def layout(self) -> Layout: ...

    def serve(self, adapter: str, **options: Any) -> Adapter: ...

    def port(self, adapter: str) -> int: ...


@dataclass(frozen=True, slots=True)
class TransportKind:
    """One PLC door of the harness."""

    name: str
    summary: str
    open: Callable[[ServerUnderTest], Transport]
    """Open a synchronous transport to the harness' server (start the adapter it needs first)."""
    adapter: str | None = None
    """The server adapter the door needs (checked in the adapter registry)."""
    requires: tuple[str, ...] = ()
    """Modules that must be importable."""


def _open_shm(hli: ServerUnderTest) -> Transport:
    from hli_server.image import ProcessImage
    from plc_clients.transports import ShmTransport

    image = hli.runtime.image
    if isinstance(image, ProcessImage) and image.backing == "memory":
        return ShmTransport.over(image.buffer, name=image.name, expect=image.layout)
    return ShmTransport.attach(image.name, expect=image.layout)


def _open_modbus(hli: ServerUnderTest) -> Transport:
    from plc_clients.transports import ModbusTransport

    adapter = hli.serve("modbus")
    options = getattr(adapter, "options", None)
    return ModbusTransport.connect(
        hli.bind,
        hli.port("modbus"),
        layout=hli.layout,
        word_order=getattr(options, "word_order", "ABCD"),
        unit_id=getattr(options, "unit_id", 1),
    )


def _open_ads(hli: ServerUnderTest) -> Transport:
    """The ADS door: ``plc_clients.ads.AdsTransport.connect(host, port, layout=...)`` to the ``ads``
    adapter on a free port (the constructor the Modbus transport has; adjust here if it differs)."""
    ads = importlib.import_module("plc_clients.ads")
    transport: Transport = ads.AdsTransport.connect(hli.bind, hli.port("ads"), layout=hli.layout)
    return transport


TRANSPORTS: dict[str, TransportKind] = {
    kind.name: kind
    for kind in (
        TransportKind("shm", "the shared-memory process image (H-01)", _open_shm),
        TransportKind("modbus", "Modbus TCP (H-03)", _open_modbus, adapter="modbus", requires=("pymodbus",)),
        TransportKind(
            "ads", "ADS over TCP (H-04)", _open_ads, adapter="ads", requires=("plc_clients.ads", "pyads")
        ),
    )
}
"""Name -> door, in the order the ``plc_transport`` fixture runs them."""


def register_transport(kind: TransportKind) -> None:
    """Add (or replace) a door of the harness."""
    TRANSPORTS[kind.name] = kind


def transport_names() -> list[str]:
    return list(TRANSPORTS)


def _importable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # a parent package is missing
        return False


def unavailable(name: str) -> str | None:
    """Why door ``name`` cannot be opened in this installation, or None when it can."""
    kind = TRANSPORTS.get(name)
    if kind is None:
        return f"no PLC transport {name!r} is registered (registered: {', '.join(TRANSPORTS)})"
    missing = [m for m in kind.requires if not _importable(m)]
    if missing:
        return f"the {name} transport needs {', '.join(missing)}, which this installation does not have"
    if kind.adapter is not None:
        from hli_server.adapters.registry import available_adapters

        if kind.adapter not in available_adapters():
            return f"the {name} transport needs the server adapter {kind.adapter!r}, which is not installed"
    return None


def open_transport(hli: ServerUnderTest, name: str) -> Transport:
    """Open door ``name`` to ``hli``'s server; a missing part raises ``LookupError`` with the reason."""
    reason = unavailable(name)
    if reason is not None:
        raise LookupError(reason)
    return TRANSPORTS[name].open(hli)
