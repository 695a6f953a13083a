"""The HTTP control API: the operator's door (and the integration tests' remote control).

``options.py`` (its options, light), ``server.py`` (the adapter: uvicorn in the runtime's loop),
``app.py`` (the FastAPI application), ``routers/`` (one router per concern), ``models.py`` (bodies),
``deps.py`` (the host as a dependency, operator errors as HTTP codes). This package is the only
importer of FastAPI and uvicorn.
"""

from hli_server.adapters.http.options import HttpOptions

__all__ = ["HttpOptions"]
