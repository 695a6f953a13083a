"""Options of the ADS adapter (light: importing it imports neither asyncio servers nor the codec).

``[[adapters]] name = "ads"`` in the machine file, ``--adapter ads:KEY=VALUE``, ``--ads-port`` and
``--ams-net-id`` (H-04; docs/ads.md). The limits are the door's robustness bar (docs/reliability.md): every
one bounds what one client can make the server hold or do, and each has a default that serves a test
farm of a few hundred clients.
"""

from __future__ import annotations

import ipaddress
import logging
import os
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar, Final

from pydantic import Field, field_validator, model_validator

from hli_server.adapters.tcp import TcpDoorOptions

__all__ = [
    "DEFAULT_NET_ID",
    "DEFAULT_PORT",
    "DEFAULT_UDP_PORT",
    "ROUTE_PASSWORD_ENV",
    "AdsOptions",
    "RouteAllowlist",
    "canonical_ip",
]

logger = logging.getLogger(__name__)

DEFAULT_PORT: Final = 48898
"""The AMS/TCP port of a TwinCAT router; ``--ads-port 0`` binds a free one (printed in the banner)."""
DEFAULT_UDP_PORT: Final = 48899
"""The UDP port of TwinCAT's route discovery and AddRoute (pyads and AdsLib send there, always)."""
DEFAULT_NET_ID: Final = "127.0.0.1.1.1"
"""The server's AMS NetId: the clients' target (``pyads.Connection("127.0.0.1.1.1", 851, ...)``)."""
ROUTE_PASSWORD_ENV: Final = "HLI_ADS_ROUTE_PASSWORD"
"""The environment variable that gives ``route_password`` (with ``route_user`` set, and neither
``route_password`` nor ``route_password_file`` given): a command line is shown to every local user by
``ps``, the environment of a process only to its owner."""


def read_secret_file(path: str, what: str) -> str:
    """The first line of the file ``path`` (without its line end), or ValueError saying what is wrong;
    a file that other users may read is taken with a warning (``chmod 600`` it)."""
    file = Path(path).expanduser()
    try:
        info = file.stat()
        text = file.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ValueError(f"{what} {path}: cannot be read ({reason})") from None
    secret = text.splitlines()[0] if text else ""
    if not secret:
        raise ValueError(f"{what} {path}: its first line is empty")
    if info.st_mode & (stat.S_IRWXG | stat.S_IRWXO):
        logger.warning("%s %s may be read by other users: chmod 600 %s", what, path, path)
    return secret


def _net_id_octets(text: str) -> tuple[int, ...] | None:
    parts = text.strip().split(".")
    if len(parts) == 6 and all(p.isdecimal() and int(p) <= 255 for p in parts):
        return tuple(int(p) for p in parts)
    return None


def _address(host: str | None) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    if host is None:
        return None
    try:
        address = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return None
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        return address.ipv4_mapped
    return address


def canonical_ip(host: str | None) -> str | None:
    """An IP address as one spelling (IPv4-mapped IPv6 as IPv4, no zone), or None when it is none."""
    address = _address(host)
    return None if address is None else str(address)


def is_loopback(host: str | None) -> bool:
    address = _address(host)
    return address is not None and address.is_loopback


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
        address = _address(host)
        if address is None:
            return False
        if self.loopback and address.is_loopback:
            return True
        return any(address in network for network in self.networks)

    def allows_net_id(self, net_id: bytes) -> bool:
        return not self.net_ids or net_id in self.net_ids


class AdsOptions(TcpDoorOptions):
    """``[[adapters]] name = "ads"`` / ``--adapter ads:KEY=VALUE`` / ``--ads-port``, ``--ams-net-id``; the
    options every TCP door has (``max_connections``, ``idle_timeout_s``, ``frame_timeout_s``, ``allow``) come
    from :class:`~hli_server.adapters.tcp.TcpDoorOptions`."""

    RENAMED: ClassVar[Mapping[str, str | None]] = {"evict_idle_after_s": None}
    DOOR: ClassVar[str] = "ADS"

    port: int = Field(default=DEFAULT_PORT, ge=0, le=65535, description="AMS/TCP port (0: any free port)")
    ams_net_id: str = Field(
        default=DEFAULT_NET_ID, description="the server's AMS NetId (the clients' target NetId)"
    )
    allow: list[str] = Field(
        default_factory=lambda: ["loopback"],
        description="route allowlist: IPs/networks and/or AMS NetIds, 'loopback' = 127.0.0.0/8 and ::1; "
        "empty = everybody (docs/ads.md)",
    )
    udp: bool = Field(
        default=True,
        description="answer ADS over UDP where the TCP door listens: the discovery answer (TwinCAT's "
        "Broadcast Search, pyads' NetId discovery) and AddRoute (docs/ads.md)",
    )
    udp_port: int | None = Field(
        default=None,
        ge=0,
        le=65535,
        description="UDP port (default: 48899 when `port` is 48898, as TwinCAT's, else any free port; "
        "0: any free)",
    )
    route_user: str | None = Field(
        default=None,
        max_length=256,
        description="user name AddRoute must carry (pyads.add_route_to_plc's username); unset: every "
        "AddRoute is refused with 0x704 as TwinCAT refuses wrong credentials",
    )
    route_password: str | None = Field(
        default=None,
        max_length=256,
        description=f"password AddRoute must carry, with `route_user` (on a command line `ps` shows it to "
        f"every local user: prefer `route_password_file` or the environment variable {ROUTE_PASSWORD_ENV})",
    )
    route_password_file: str | None = Field(
        default=None,
        description="file whose first line is `route_password` (instead of giving it; mode 600)",
    )
    routes_file: str | None = Field(
        default=None,
        description="JSON file the routes added by AddRoute are kept in (read at start, written on each "
        "AddRoute); unset: they last as long as the server",
    )
    max_routes: int = Field(default=128, ge=1, le=10_000, description="routes AddRoute may add")
    udp_rate: float = Field(
        default=20.0, gt=0, le=100_000, description="datagrams per second answered per sender (burst: twice)"
    )
    udp_rate_total: float = Field(
        default=200.0, gt=0, le=1_000_000, description="datagrams per second answered in all (burst: twice)"
    )
    max_connections: int = Field(default=512, ge=1, le=900, description="connections served at once")
    idle_timeout_s: float = Field(
        default=120.0,
        gt=0,
        le=86_400,
        description="close a connection that sent nothing for this long and has no notification it reads",
    )
    frame_timeout_s: float = Field(
        default=5.0,
        gt=0,
        le=3600,
        description="a frame begun must be complete within this long, or the connection is closed (a client "
        "trickling a byte at a time does not hold a slot)",
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
    max_notifications_per_net_id: int = Field(
        default=512,
        ge=1,
        le=1_000_000,
        description="device notifications of one client NetId, all its connections",
    )
    max_notifications_per_host: int = Field(
        default=1024,
        ge=1,
        le=1_000_000,
        description="device notifications of one remote host, all its NetIds (loopback peers are not "
        "counted so)",
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

    @model_validator(mode="before")
    @classmethod
    def _password_from_a_file_or_the_environment(cls, data: Any) -> Any:
        """``route_password`` from ``route_password_file``, else from :data:`ROUTE_PASSWORD_ENV` (when
        ``route_user`` is set and no password is given)."""
        if not isinstance(data, Mapping):
            return data
        given, path = data.get("route_password"), data.get("route_password_file")
        if path is None and (given is not None or data.get("route_user") is None):
            return data
        if given is not None:
            raise ValueError("route_password and route_password_file: give one of them")
        out = dict(data)
        if path is not None:
            if not isinstance(path, str):
                raise ValueError("route_password_file is the path of a file")
            out["route_password"] = read_secret_file(path, "route_password_file")
            out["route_password_file"] = None  # read once: the options carry the password on (doors)
        elif os.environ.get(ROUTE_PASSWORD_ENV):
            out["route_password"] = os.environ[ROUTE_PASSWORD_ENV]
        return out

    @field_validator("route_user", "route_password", mode="before")
    @classmethod
    def _text(cls, value: object) -> object:
        if isinstance(value, int) and not isinstance(value, bool):  # --adapter ads:route_password=1
            return str(value)
        return value

    @model_validator(mode="after")
    def _credentials(self) -> AdsOptions:
        if (self.route_user is None) != (self.route_password is None):
            raise ValueError(
                "route_user and route_password go together: AddRoute is accepted with both, refused without "
                f"(the password: route_password, route_password_file or {ROUTE_PASSWORD_ENV})"
            )
        return self

    @property
    def udp_port_to_bind(self) -> int:
        """The UDP port: ``udp_port``, or 48899 beside TwinCAT's 48898, else any free one (0)."""
        if self.udp_port is not None:
            return self.udp_port
        return DEFAULT_UDP_PORT if self.port == DEFAULT_PORT else 0

    def allowlist(self) -> RouteAllowlist:
        return RouteAllowlist(self.allow)
