"""Options of the HTTP control API adapter (light: importing it does not import FastAPI)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

from pydantic import Field

from hli_server.adapters.options import RenamedOptions

__all__ = ["DEFAULT_MAX_BODY_BYTES", "DEFAULT_PORT", "HttpOptions"]

DEFAULT_PORT = 8080
DEFAULT_MAX_BODY_BYTES = 16 * 1024 * 1024


class HttpOptions(RenamedOptions):
    """``[[adapters]] name = "http"`` / ``--adapter http:KEY=VALUE`` / ``--http-port``.

    The names follow the TCP doors' (``hli_server.adapters.tcp.TcpDoorOptions``): seconds end in ``_s``,
    ``port``, ``max_connections`` and ``idle_timeout_s`` mean what they mean for Modbus and ADS.
    ``request_timeout_s`` is the HTTP door's ``frame_timeout_s`` (a request, head and body, must arrive
    within it). The names used before (``graceful_timeout``, ``idle_timeout``, ``request_timeout``,
    ``write_timeout``, ``keep_alive``) still load, with a DeprecationWarning and a log line, for one minor
    version (:class:`~hli_server.adapters.options.RenamedOptions`)."""

    RENAMED: ClassVar[Mapping[str, str | None]] = {
        "graceful_timeout": "graceful_timeout_s",
        "idle_timeout": "idle_timeout_s",
        "request_timeout": "request_timeout_s",
        "write_timeout": "write_timeout_s",
        "keep_alive": "keep_alive_s",
    }
    DOOR: ClassVar[str] = "HTTP"

    port: int = Field(default=DEFAULT_PORT, ge=0, le=65535, description="TCP port (0: any free port)")
    graceful_timeout_s: int = Field(
        default=2, ge=0, le=60, description="seconds open requests get to finish at shutdown"
    )
    max_connections: int = Field(
        default=256,
        ge=1,
        le=4096,
        description="connections at once; beyond, the longest idle one is closed, else 503",
    )
    idle_timeout_s: float = Field(
        default=30.0, ge=0.0, le=3600.0, description="seconds a connection may stay silent (0: no limit)"
    )
    request_timeout_s: float = Field(
        default=10.0,
        ge=0.0,
        le=3600.0,
        description="seconds from a request's first byte to the end of its body (408 after; 0: no limit)",
    )
    write_timeout_s: float = Field(
        default=10.0,
        ge=0.0,
        le=3600.0,
        description="seconds a client may leave an answer unread (then it is dropped; 0: no limit)",
    )
    keep_alive_s: int = Field(
        default=5, ge=1, le=300, description="seconds an idle keep-alive connection stays open"
    )
    max_body_bytes: int = Field(
        default=DEFAULT_MAX_BODY_BYTES, ge=1024, le=1 << 30, description="largest request body (else 413)"
    )
    max_streams: int = Field(
        default=16,
        ge=1,
        le=256,
        description="dashboard event streams (GET /api/live) open at once (else 503)",
    )
    live_rate_hz: float = Field(
        default=20.0, ge=1.0, le=100.0, description="state updates per second on each dashboard event stream"
    )
