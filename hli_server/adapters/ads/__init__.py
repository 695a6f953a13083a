"""ADS over TCP: the HLI's symbols on AMS port 851, the FCT-C3 CNC objects on port 551 (H-04, C3-10).

* :mod:`.options`: :class:`AdsOptions` (port, NetId, route allowlist, limits) - light, no I/O;
* :mod:`.symbols`: the symbol table built from the layout (names, entries, uploads);
* :mod:`.device`: :class:`AdsDevice`, the requests served from the image, and the device
  notifications run from the cycle - sans-I/O;
* :mod:`.server`: :class:`AdsAdapter`, the asyncio server around the codec
  (:mod:`hli_server.codecs.ads`) and the device.

docs/ads.md tells users how to connect pyads and other ADS clients.
"""

from hli_server.adapters.ads.device import AdsDevice, DeviceLimits, Session
from hli_server.adapters.ads.options import DEFAULT_NET_ID, DEFAULT_PORT, AdsOptions, RouteAllowlist
from hli_server.adapters.ads.server import AdsAdapter
from hli_server.adapters.ads.symbols import SymbolTable, normalize_name

__all__ = [
    "DEFAULT_NET_ID",
    "DEFAULT_PORT",
    "AdsAdapter",
    "AdsDevice",
    "AdsOptions",
    "DeviceLimits",
    "RouteAllowlist",
    "Session",
    "SymbolTable",
    "normalize_name",
]
