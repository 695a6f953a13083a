"""The door's guard: every request passes it before a router sees it (reliability.md, round 1, findings 5, 6
and 8).

A plain ASGI middleware (no per-request task, no streaming of its own):

* **Host** (DNS rebinding): the ``Host`` header must be a loopback name, an IP literal, the bind
  address, or a name of ``AccessPolicy.allowed_hosts``. A page of another site whose name resolves to
  this server sends its own name and is refused (421).
* **Origin** (cross-site requests): a state-changing request (POST, PUT, PATCH, DELETE) that carries
  an ``Origin`` is refused (403) unless that origin is this server's own (same host and port) or in
  ``allowed_origins``. Browsers send ``Origin`` with every cross-site POST, so a web page in the user's
  browser cannot load or start a program here. ``Origin: null`` (a sandboxed frame, a ``data:`` or
  ``file:`` page) is such a foreign origin too (reliability.md, round 2, finding 7).
* **Token**: with ``api_token`` set, a state-changing request needs ``Authorization: Bearer <token>``
  (401 with ``WWW-Authenticate`` otherwise), and so do the reads of what was done on the machine: the
  event log (``GET /api/events``; reliability.md, round 2, finding 8) and the recordings of sessions, which
  hold the programs' text, every input and every event (``GET /api/recordings``, ``GET
  /api/recordings/{name}``; round 3, finding 5): :data:`TOKEN_READS`. A ``GET`` may carry the token as
  ``?access_token=`` instead (RFC 6750, 2.3: a browser's ``EventSource`` cannot send headers). The reads of
  the machine as it is now stay open (state, active alarms, image, scene, timing, whether a recording
  runs); the dashboard's stream (``/api/live``) and page carry the events only to a holder of the token:
  whether the request had it is ``scope["state"]["hli_token"]`` for the routes.
* **Read-only**: with ``read_only`` set, every state-changing request is refused (403).
* **Body size**: a body above ``max_body_bytes`` is refused with 413 and never reaches the application
  (nor memory: past the bound it is read and discarded, so that the client sees the answer rather than a
  reset connection; a body that says or turns out to be more than four times the bound is cut off at
  once). A body within the bound is read (and buffered) here, so the application never sees a partial one.
"""

from __future__ import annotations

import hmac
import ipaddress
import json
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any
from urllib.parse import parse_qs

from hli_server.adapters.host import LOOPBACK_NAMES, AccessPolicy

__all__ = ["TOKEN_READS", "Guard"]

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

_STATE_CHANGING = frozenset({"POST", "PUT", "PATCH", "DELETE"})
TOKEN_READS: dict[str, str] = {"/api/events": "the event log", "/api/recordings": "the recordings"}
"""Reads that need the token when one is set (what was done on the machine, by whom, with which programs):
a path and every path below it, and what the 401 names."""
_DRAIN_FACTOR = 4
"""A body above the bound is read to its end and discarded (so that the client sees the 413 instead of a
reset connection), unless it is more than this many times the bound: then the answer comes at once."""


def _host_name(host_header: str) -> str:
    """``host:port`` -> ``host`` (IPv6 literals keep their brackets off)."""
    if host_header.startswith("["):
        return host_header[1 : host_header.find("]")] if "]" in host_header else host_header
    return host_header.rsplit(":", 1)[0] if host_header.count(":") == 1 else host_header


def _token_read(path: str) -> str | None:
    """What ``path`` reads if it is one of :data:`TOKEN_READS` (or below one), else None."""
    for guarded, what in TOKEN_READS.items():
        if path == guarded or path.startswith(guarded + "/"):
            return what
    return None


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


class Guard:
    """See the module docstring. ``bind`` is the address the door listens on."""

    def __init__(self, app: ASGIApp, *, policy: AccessPolicy, bind: str, max_body_bytes: int) -> None:
        self.app = app
        self.policy = policy
        self.max_body_bytes = max_body_bytes
        self._hosts = {h.lower() for h in (*LOOPBACK_NAMES, bind, *policy.allowed_hosts)}
        self._origins = {o.rstrip("/").lower() for o in policy.allowed_origins}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        method = str(scope.get("method", "GET")).upper()
        authorized = self._token_given(method, headers, scope)
        scope.setdefault("state", {})["hli_token"] = authorized
        refusal = self._refusal(method, headers, str(scope.get("path", "")), authorized)
        if refusal is not None:
            status, detail, extra = refusal
            await _answer(send, status, detail, extra)
            return
        if method not in _STATE_CHANGING:
            await self.app(scope, receive, send)
            return
        length = headers.get("content-length")
        declared = int(length) if length is not None and length.isdigit() else None
        if declared is not None and declared > self.max_body_bytes * _DRAIN_FACTOR:
            await self._too_large(send, declared)  # far too large to read even to discard it
            return
        chunks: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                return  # the client went away: nothing to answer
            body = message.get("body", b"")
            size += len(body)
            if size <= self.max_body_bytes:
                chunks.append(body)
            elif size > self.max_body_bytes * _DRAIN_FACTOR:
                break  # stop reading a stream that does not end
            if not message.get("more_body", False):
                break
        if size > self.max_body_bytes:
            # read to its end (discarded, so that the client sees the answer, not a reset), then 413
            await self._too_large(send, declared if declared is not None else size)
            return
        replay = [{"type": "http.request", "body": b"".join(chunks), "more_body": False}]

        async def buffered() -> Message:
            if replay:
                return replay.pop()
            return await receive()

        await self.app(scope, buffered, send)

    def _token_given(self, method: str, headers: dict[str, str], scope: Scope) -> bool:
        """Whether the request carries the token (always True when the server has none)."""
        token = self.policy.api_token
        if token is None:
            return True
        scheme, _, value = headers.get("authorization", "").partition(" ")
        if scheme.lower() == "bearer" and hmac.compare_digest(value.strip().encode(), token.encode()):
            return True
        if method == "GET":
            query = scope.get("query_string", b"")
            for given in parse_qs(query.decode("latin-1") if isinstance(query, bytes) else str(query)).get(
                "access_token", []
            ):
                if hmac.compare_digest(given.encode(), token.encode()):
                    return True
        return False

    def _refusal(
        self, method: str, headers: dict[str, str], path: str, authorized: bool
    ) -> tuple[int, str, list[tuple[bytes, bytes]]] | None:
        host = _host_name(headers.get("host", "")).lower()
        if host and host not in self._hosts and not _is_ip(host):
            return (
                421,
                f"Host {host!r} is not this server's: use 127.0.0.1 or localhost, or start the server with "
                f"--allow-host {host}",
                [],
            )
        if method not in _STATE_CHANGING:
            what = None if authorized else _token_read(path)
            if what is not None:
                return (
                    401,
                    f"{what} is read with the token only: send 'Authorization: Bearer <token>' (the "
                    "server's --api-token / HLI_API_TOKEN)",
                    [(b"www-authenticate", b'Bearer realm="hli-server"')],
                )
            return None
        origin = headers.get("origin")
        if origin is not None:
            own = f"{headers.get('x-forwarded-proto', 'http')}://{headers.get('host', '')}".lower()
            if origin.rstrip("/").lower() not in ({own} | self._origins):
                return (
                    403,
                    f"cross-site request from {origin} refused: only this server's own pages (or "
                    "--allow-origin) may change its state",
                    [],
                )
        if self.policy.read_only:
            return 403, "the server runs --read-only: the network doors accept no writes", []
        if not authorized:
            return (
                401,
                "this request changes the machine's state: send 'Authorization: Bearer <token>' "
                "(the server's --api-token / HLI_API_TOKEN)",
                [(b"www-authenticate", b'Bearer realm="hli-server"')],
            )
        return None

    async def _too_large(self, send: Send, size: int) -> None:
        await _answer(
            send,
            413,
            f"request body of {size} bytes is larger than the {self.max_body_bytes} bytes this door takes "
            "(max_body_bytes); put large NC programs in the program table and select them",
            [],
        )


async def _answer(send: Send, status: int, detail: str, extra: list[tuple[bytes, bytes]]) -> None:
    body = json.dumps({"detail": detail}, ensure_ascii=True).encode("ascii")
    headers = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
        (b"connection", b"close"),
        *extra,
    ]
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body, "more_body": False})
