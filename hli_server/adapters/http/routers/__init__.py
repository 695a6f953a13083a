"""The control API's routers, one per concern; ``app.py`` includes them all."""

from hli_server.adapters.http.routers import (
    axes,
    channels,
    check,
    clock,
    events,
    image,
    live,
    page,
    record,
    state,
)

ROUTERS = (
    page.router,
    state.router,
    channels.router,
    check.router,
    axes.router,
    clock.router,
    events.router,
    image.router,
    live.router,
    record.router,
)

__all__ = ["ROUTERS"]
