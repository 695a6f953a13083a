"""Options of the ADS adapter (light: importing it imports neither asyncio servers nor the codec).

``[[adapters]] name = "ads"`` in the machine file, ``--adapter ads:KEY=VALUE``, ``--ads-port`` and
``--ams-net-id`` (H-04; docs/ads.md). The limits are the door's robustness bar (issue 12): every one
bounds what one client can make the server hold or do, and each has a default that serves a test
farm of a few hundred clients.
"""

from __future__ import annotations

import ipaddress
from typing import Final

from pydantic import BaseModel, ConfigDict, Field, field_validator

__all__ = ["DEFAULT_NET_ID", "DEFAULT_PORT", "AdsOptions", "RouteAllowlist"]

DEFAULT_PORT: Final = 48898
"""The AMS/TCP port of a TwinCAT router; ``--ads-port 0`` binds a free one (printed in the banner)."""
DEFAULT_NET_ID: Final = "127.0.0.1.1.1"
"""The server's AMS NetId: the clients' target (``pyads.Connection("127.0.0.1.1.1", 851, ...)``)."""


def _net_id_octets(text: str) -> tuple[int, ...] | None:
    parts = text.strip().split(".")
    if len(parts) == 6 and all(p.isdecimal() and int(p) <= 255 for p in parts):
        return tuple(int(p) for p in parts)
    return None


class RouteAllowlist:
    """Who may talk to the server: TCP peer addresses (IPs or networks) and/or AMS NetIds.

    An entry with six numbers (``192.168.1.50.1.1``) is a NetId, anything else an IP address or a
    network (``10.0.0.0/8``, ``::1``). The word ``loopback`` allows every loopback peer (127.0.0.0/8
    and ::1). A client passes when its peer address matches an IP entry (or there are none) AND its
    source NetId matches a NetId entry (or there are none); an empty list allows everybody.
    """

    def __init__(self, entries: list[str]) -> None:
        self.networks: list[ipaddress.IPv4Network | ipaddress.IPv6Network] = []
        self.loopback = False
        net_ids: set[bytes] = set()
        for entry in entries:
            text = entry.strip()
            octets = _net_id_octets(text)
            if octets is not None:
                net_ids.add(bytes(octets))
            elif text.lower() == "loopback":
                self.loopback = True
            else:
                self.networks.append(ipaddress.ip_network(text, strict=False))
        self.net_ids: frozenset[bytes] = frozenset(net_ids)
        self.checks_ip = self.loopback or bool(self.networks)

    def allows_ip(self, host: str | None) -> bool:
        if not self.checks_ip:
            return True
        if host is None:
            return False
        try:
            address = ipaddress.ip_address(host.split("%", 1)[0])
        except ValueError:
            return False
        if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
            address = address.ipv4_mapped
        if self.loopback and address.is_loopback:
            return True
        return any(address in network for network in self.networks)

    def allows_net_id(self, net_id: bytes) -> bool:
        return not self.net_ids or net_id in self.net_ids


class AdsOptions(BaseModel):
    """``[[adapters]] name = "ads"`` / ``--adapter ads:KEY=VALUE`` / ``--ads-port``, ``--ams-net-id``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    port: int = Field(default=DEFAULT_PORT, ge=0, le=65535, description="AMS/TCP port (0: any free port)")
    ams_net_id: str = Field(
        default=DEFAULT_NET_ID, description="the server's AMS NetId (the clients' target NetId)"
    )
    allow: list[str] = Field(
        default_factory=lambda: ["loopback"],
        description="route allowlist: IPs/networks and/or AMS NetIds, 'loopback' = 127.0.0.0/8 and ::1; "
        "empty = everybody (docs/ads.md)",
    )
    max_connections: int = Field(default=512, ge=1, le=900, description="connections served at once")
    idle_timeout_s: float = Field(
        default=120.0,
        gt=0,
        le=86_400,
        description="close a connection that sent nothing for this long and has no notification it reads",
    )
    evict_idle_after_s: float = Field(
        default=5.0,
        ge=0,
        description="when every slot is taken, a new client replaces the longest-idle one if it has "
        "been idle this long",
    )
    max_queued_output: int = Field(
        default=256 * 1024,
        ge=4096,
        le=64 * 1024 * 1024,
        description="bytes of replies and notifications queued for one client before it is not read "
        "(and not sent notifications) until it drains",
    )
    max_requests_per_turn: int = Field(
        default=32,
        ge=1,
        le=10_000,
        description="requests of one connection served before the others and the clock get a turn",
    )
    max_turn_ms: float = Field(
        default=0.25,
        gt=0,
        le=100,
        description="time one connection's requests may hold the event loop before the others and the "
        "clock get a turn (checked after each request)",
    )
    max_handles: int = Field(default=2048, ge=1, le=1_000_000, description="symbol handles per connection")
    max_notifications: int = Field(
        default=256, ge=1, le=100_000, description="device notifications per connection"
    )
    max_notifications_total: int = Field(
        default=2048, ge=1, le=1_000_000, description="device notifications of all connections together"
    )
    max_sum_items: int = Field(
        default=500, ge=1, le=100_000, description="sub-requests of one sum command (TwinCAT's limit: 500)"
    )
    first_sample_delay_ms: float = Field(
        default=30.0,
        ge=0,
        le=10_000,
        description="the first sample of a notification follows its add response after this delay "
        "(AdsLib registers its callback only after reading the response)",
    )

    @field_validator("ams_net_id")
    @classmethod
    def _net_id(cls, value: str) -> str:
        if _net_id_octets(value) is None:
            raise ValueError(
                f"AMS NetId {value!r} is not six numbers 0..255 separated by dots (127.0.0.1.1.1)"
            )
        return value.strip()

    @field_validator("allow", mode="before")
    @classmethod
    def _allow(cls, value: object) -> object:
        if isinstance(value, str):  # machine file / --adapter: one text, entries separated by spaces or ';'
            value = value.replace(";", " ").replace(",", " ").split()
        if isinstance(value, list):
            for entry in value:
                if not isinstance(entry, str):
                    raise ValueError(f"allow entry {entry!r} is not text")
                if _net_id_octets(entry) is None and entry.strip().lower() != "loopback":
                    try:
                        ipaddress.ip_network(entry.strip(), strict=False)
                    except ValueError:
                        raise ValueError(
                            f"allow entry {entry!r} is neither an AMS NetId (192.168.1.50.1.1), an IP "
                            "address or network (10.0.0.0/8), nor 'loopback'"
                        ) from None
        return value

    def allowlist(self) -> RouteAllowlist:
        return RouteAllowlist(self.allow)
