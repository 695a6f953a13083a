"""Who may talk to the ADS door: the allowlist, and the routes AddRoute adds (H-04, docs/ads.md).

A TwinCAT router talks to a peer it has a route for: a route names an AMS NetId and the address where
it lives. Here a client is admitted when

* the allowlist admits it (its IP matches an IP entry or there is none, AND its source NetId matches a
  NetId entry or there is none: :class:`~hli_server.adapters.ads.options.RouteAllowlist`), or
* a route admits it: the route's NetId is the client's source NetId and the route's address is where the
  connection comes from.

Routes come from ``pyads.add_route_to_plc`` / AdsLib's ``AddRemoteRoute`` / a TwinCAT engineering PC over
ADS/UDP (:mod:`hli_server.adapters.ads.udp`), with the credentials configured. They last as long as the
server; with ``routes_file`` they are written there (JSON, atomically replaced) and read back at the next
start. A route for a NetId that already has one replaces it, as TwinCAT's route table does.

Router messages (AMS/TCP 0x1000 port connect, 0x1002 the router's NetId) carry no NetId: they are
answered only where the allowlist restricts no NetId or admits the server's own (the one a port-connected
client then sends from), so that a client outside the allowlist learns nothing (reliability.md, round 2,
finding 9)."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import tempfile
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Final

from hli_server.adapters.ads.options import RouteAllowlist, canonical_ip
from hli_server.codecs.ads import NetId

__all__ = ["ROUTES_FORMAT", "Route", "RouteError", "Routes"]

logger = logging.getLogger(__name__)

ROUTES_FORMAT: Final = "hli-ads-routes"


class RouteError(ValueError):
    """A routes file that cannot be read; the message names the file and what is wrong."""


@dataclass(frozen=True, slots=True)
class Route:
    name: str
    net_id: NetId
    address: str
    """as AddRoute gave it: an IP address or a host name"""
    ips: frozenset[str]
    """the addresses connections of this route may come from"""
    added: str
    """when (ISO 8601, UTC)"""

    def to_dict(self) -> dict[str, object]:
        return {
            "name": self.name,
            "net_id": str(self.net_id),
            "address": self.address,
            "ips": sorted(self.ips),
            "added": self.added,
        }


class Routes:
    """The allowlist and the added routes, with the admission checks of the door (module docstring)."""

    def __init__(
        self, allowlist: RouteAllowlist, server_net_id: bytes, file: str | None = None, max_routes: int = 128
    ) -> None:
        self.allowlist = allowlist
        self.server_net_id = server_net_id
        self.file = Path(file) if file else None
        self.max_routes = max_routes
        self._by_net_id: dict[bytes, Route] = {}
        self._ips: dict[str, int] = {}
        if self.file is not None and self.file.exists():
            for route in _load(self.file):
                self._put(route)

    @property
    def routes(self) -> list[Route]:
        return list(self._by_net_id.values())

    def __len__(self) -> int:
        return len(self._by_net_id)

    # --- admission ------------------------------------------------------------------------------
    def admits_ip(self, host: str | None) -> bool:
        """May a TCP connection from ``host`` be accepted at all (its NetId is checked at its first frame)?"""
        if self.allowlist.allows_ip(host):
            return True
        ip = canonical_ip(host)
        return ip is not None and ip in self._ips

    def admits(self, net_id: bytes, host: str | None) -> bool:
        """May frames from NetId ``net_id`` on a connection from ``host`` be served?"""
        allow = self.allowlist
        if allow.allows_ip(host) and allow.allows_net_id(net_id):
            return True
        route = self._by_net_id.get(net_id)
        return route is not None and canonical_ip(host) in route.ips

    def answers_router_messages(self, host: str | None) -> bool:
        """Are router messages (0x1000, 0x1002) from ``host`` answered (module docstring)?"""
        allow = self.allowlist
        return allow.allows_ip(host) and allow.allows_net_id(self.server_net_id)

    # --- adding ---------------------------------------------------------------------------------
    def add(self, name: str, net_id: NetId, address: str, ips: frozenset[str]) -> Route:
        """Add (or replace) the route of ``net_id``; written to the routes file when there is one.
        Raises :class:`RouteError` when the table is full or the file cannot be written."""
        if net_id not in self._by_net_id and len(self._by_net_id) >= self.max_routes:
            raise RouteError(f"the route table holds {len(self._by_net_id)} routes (max_routes)")
        route = Route(name[:256], net_id, address[:256], ips, datetime.now(UTC).isoformat(timespec="seconds"))
        old = self._by_net_id.get(net_id)
        if old is not None:
            self._drop(old)
        self._put(route)
        if self.file is not None:
            try:
                self._save(self.file)
            except OSError as exc:
                raise RouteError(f"the routes file {self.file} cannot be written: {exc.strerror}") from None
        return route

    def _put(self, route: Route) -> None:
        self._by_net_id[bytes(route.net_id)] = route
        for ip in route.ips:
            self._ips[ip] = self._ips.get(ip, 0) + 1

    def _drop(self, route: Route) -> None:
        del self._by_net_id[bytes(route.net_id)]
        for ip in route.ips:
            left = self._ips[ip] - 1
            if left:
                self._ips[ip] = left
            else:
                del self._ips[ip]

    def _save(self, path: Path) -> None:
        text = json.dumps(
            {
                "format": ROUTES_FORMAT,
                "version": 1,
                "routes": [r.to_dict() for r in self._by_net_id.values()],
            },
            indent=1,
        )
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text + "\n")
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise


def _load(path: Path) -> list[Route]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise RouteError(f"{path}: cannot read the routes file: {exc.strerror}") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise RouteError(f"{path}: not a routes file (JSON): {exc}") from None
    if (
        not isinstance(data, dict)
        or data.get("format") != ROUTES_FORMAT
        or not isinstance(data.get("routes"), list)
    ):
        raise RouteError(
            f'{path}: not a routes file: expected {{"format": "{ROUTES_FORMAT}", "routes": [...]}}; '
            "it is written by the server (routes_file), or remove it"
        )
    routes = []
    for i, item in enumerate(data["routes"]):
        try:
            ips = item["ips"]
            if not isinstance(ips, list) or any(canonical_ip(str(ip)) is None for ip in ips):
                raise ValueError("ips must be a list of IP addresses")
            routes.append(
                Route(
                    str(item["name"]),
                    NetId.parse(str(item["net_id"])),
                    str(item["address"]),
                    frozenset(str(canonical_ip(str(ip))) for ip in ips),
                    str(item.get("added", "")),
                )
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise RouteError(f"{path}: route {i}: {exc}") from None
    return routes
