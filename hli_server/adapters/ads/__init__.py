"""ADS: the HLI's symbols on AMS port 851, the FCT-C3 CNC objects on port 551, the TwinCAT system service
on port 10000, over TCP; discovery and AddRoute over UDP (H-04, C3-10).

* :mod:`.options`: :class:`AdsOptions` (port, NetId, route allowlist, credentials, limits) - light, no I/O;
* :mod:`.symbols`: the symbols and data types read off the layout (names, structures, the structured view);
* :mod:`.session`: what the services stand on: :class:`Session` (one connection), :class:`DeviceLimits`, the
  port tables' :class:`~.session.PortTable`;
* :mod:`.device`: :class:`AdsDevice`, the dispatch tables, and the services it dispatches to
  (:mod:`.system`, :mod:`.data`, :mod:`.symbol_info`, :mod:`.sums`, :mod:`.notifications`) - sans-I/O;
* :mod:`.routes`: the allowlist and the routes added by AddRoute (and their file);
* :mod:`.server`: :class:`AdsAdapter`, the asyncio TCP server around the codec
  (:mod:`hli_server.codecs.ads`) and the device; :mod:`.udp`, its UDP door.

docs/ads.md tells users how to connect pyads, Node ads-client and TwinCAT.
"""

from hli_server.adapters.ads.device import AdsDevice
from hli_server.adapters.ads.options import (
    DEFAULT_NET_ID,
    DEFAULT_PORT,
    DEFAULT_UDP_PORT,
    AdsOptions,
    RouteAllowlist,
)
from hli_server.adapters.ads.routes import Route, Routes
from hli_server.adapters.ads.server import AdsAdapter
from hli_server.adapters.ads.session import DeviceLimits, Session
from hli_server.adapters.ads.symbols import VIEW_GROUP, SymbolTable, normalize_name

__all__ = [
    "DEFAULT_NET_ID",
    "DEFAULT_PORT",
    "DEFAULT_UDP_PORT",
    "VIEW_GROUP",
    "AdsAdapter",
    "AdsDevice",
    "AdsOptions",
    "DeviceLimits",
    "Route",
    "RouteAllowlist",
    "Routes",
    "Session",
    "SymbolTable",
    "normalize_name",
]
