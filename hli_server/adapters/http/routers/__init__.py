"""The control API's routers, one per concern; ``app.py`` includes them all."""

from hli_server.adapters.http.routers import axes, channels, clock, events, image, state

ROUTERS = (state.router, channels.router, axes.router, clock.router, events.router, image.router)

__all__ = ["ROUTERS"]
