"""The control API as a FastAPI application on an adapter host (OpenAPI at ``/openapi.json``, ``/docs``).

The operator panel of the simulated machine and the remote control of the integration tests (H-07):
machine state, programs, start/feedhold/reset, mode, jog, override, referencing, stepping the stepped
clock, fault injection (A3-05), alarms and events, and every image field by its ST path (H-01, H-02);
the live dashboard at ``/`` (docs/dashboard.md, ``routers/page.py``, ``live_feed.py``).
Each concern is a router of its own (``routers/``); each takes the host as a dependency and knows
nothing of the runtime or the engine.

Operator requests (start, reset, mode, jog, ...) are latched by the channel at the next cycle, as a
PLC's are; the answers say from which cycle they take effect (``202 Accepted``). Image writes go to
the PLC->CNC half of the image exactly like a PLC's write and are latched the same way; writes to
CNC->PLC fields (``_r``) are refused with 403 (H-02).
"""

from __future__ import annotations

from fastapi import FastAPI

from hli_server.adapters.host import AdapterHost
from hli_server.adapters.http.deps import SafeJSONResponse, install_error_handlers
from hli_server.adapters.http.guard import Guard
from hli_server.adapters.http.live_feed import DEFAULT_MAX_STREAMS, DEFAULT_RATE_HZ, LiveFeed
from hli_server.adapters.http.options import DEFAULT_MAX_BODY_BYTES
from hli_server.adapters.http.routers import ROUTERS

__all__ = ["create_app"]


def create_app(
    host: AdapterHost,
    *,
    max_body_bytes: int = DEFAULT_MAX_BODY_BYTES,
    max_streams: int = DEFAULT_MAX_STREAMS,
    live_rate_hz: float = DEFAULT_RATE_HZ,
) -> FastAPI:
    """The FastAPI application for ``host`` (usable without a socket, e.g. with an ASGI client), behind
    the guard (Host, Origin, token, read-only, body size: ``guard.py``). ``app.state.live`` is the
    dashboard's :class:`~hli_server.adapters.http.live_feed.LiveFeed` (close it before stopping the
    server)."""
    app = FastAPI(
        default_response_class=SafeJSONResponse,
        title="hli-server control API",
        version="1",
        description=(
            "Operator panel and remote control of the simulated CNC kernel: state, programs, "
            "start/feedhold/reset, mode, jog, override, referencing, stepping (stepped clock), fault "
            "injection, alarms, events and the process image by ST path; the dashboard at / with its "
            "event stream /api/live. Requests to a channel are latched at the next cycle (202). See "
            "docs/api.md and docs/dashboard.md."
        ),
    )
    app.state.host = host
    app.state.live = LiveFeed(host, max_streams=max_streams, rate_hz=live_rate_hz)
    install_error_handlers(app)
    for router in ROUTERS:
        app.include_router(router)
    app.add_middleware(Guard, policy=host.policy, bind=host.bind, max_body_bytes=max_body_bytes)
    return app
