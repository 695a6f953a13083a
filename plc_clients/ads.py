"""``plc_clients.ads``: the documented import path of the ADS transport (docs/ads.md, docs/plc-clients.md);
the code lives in :mod:`plc_clients.transports.ads`, beside the other doors."""

from plc_clients.transports.ads import (
    DEFAULT_AMS_PORT,
    DEFAULT_NET_ID,
    AdsTransport,
    AdsTransportError,
    AsyncAdsTransport,
    close_pyads,
    open_pyads,
)

__all__ = [
    "DEFAULT_AMS_PORT",
    "DEFAULT_NET_ID",
    "AdsTransport",
    "AdsTransportError",
    "AsyncAdsTransport",
    "close_pyads",
    "open_pyads",
]
