"""What every router needs: the host as a FastAPI dependency, and operator errors as HTTP answers."""

from __future__ import annotations

import json
from typing import Annotated, Any

from fastapi import Depends, FastAPI, HTTPException, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from hli_server.adapters.host import (
    Accepted,
    AdapterHost,
    CheckTimeoutError,
    ConflictError,
    InvalidRequestError,
    NotFoundError,
    OperatorError,
    StepRefusedError,
    UnavailableError,
)
from hli_server.adapters.http.models import AcceptedBody
from hli_server.codecs.json_policy import dumps_ascii, finite

__all__ = [
    "ECHO_LIMIT",
    "HostDep",
    "SafeJSONResponse",
    "accepted",
    "get_host",
    "install_error_handlers",
    "json_bytes",
]


def json_bytes(content: Any) -> bytes:
    """Compact JSON that always renders (see :class:`SafeJSONResponse`); also the event stream's."""
    return dumps_ascii(content)


class SafeJSONResponse(JSONResponse):
    """JSON that always renders (docs/reliability.md, finding 6): non-finite numbers as null (the project's
    JSON policy, :mod:`hli_server.codecs.json_policy`), text escaped to ASCII (a lone surrogate in a
    client's string cannot break the answer)."""

    def render(self, content: Any) -> bytes:
        return json_bytes(content)


ECHO_LIMIT = 200
"""Characters of a refused input that a 422 quotes back (reliability.md, round 2, finding 9: a list of
100,000 trace names was sent back whole, 3.9 MB); beyond, the answer says what it was and how large."""


def _brief(value: Any) -> Any:
    """``value`` if its JSON is short, else a description of it (type and size)."""
    try:
        text = json.dumps(finite(value), ensure_ascii=True, default=str)
    except (TypeError, ValueError, RecursionError):
        text = repr(value)
    if len(text) <= ECHO_LIMIT:
        return value
    if isinstance(value, list | tuple):
        return f"(a list of {len(value):,} items, {len(text):,} characters: not quoted)"
    if isinstance(value, dict):
        return f"(an object of {len(value):,} keys, {len(text):,} characters: not quoted)"
    if isinstance(value, str | bytes):
        return f"{value[:80]!r}... ({len(value):,} characters: not quoted whole)"
    return f"(a {type(value).__name__} of {len(text):,} characters: not quoted)"


def get_host(request: Request) -> AdapterHost:
    host: AdapterHost = request.app.state.host
    return host


HostDep = Annotated[AdapterHost, Depends(get_host)]


def accepted(answer: Accepted) -> AcceptedBody:
    return AcceptedBody(
        channel=answer.channel,
        request=answer.request,
        cycle=answer.cycle,
        effective_cycle=answer.effective_cycle,
    )


_STATUS: tuple[tuple[type[OperatorError], int], ...] = (
    (NotFoundError, 404),
    (ConflictError, 409),
    (StepRefusedError, 409),
    (InvalidRequestError, 422),
    (UnavailableError, 503),
    (CheckTimeoutError, 504),
)


def install_error_handlers(app: FastAPI) -> None:
    """An operator error becomes ``{"detail": message}`` with 404 / 409 / 422."""

    async def operator_error(_request: Request, exc: Exception) -> JSONResponse:
        status = next((code for kind, code in _STATUS if isinstance(exc, kind)), 400)
        return SafeJSONResponse({"detail": str(exc)}, status_code=status)

    async def validation_error(_request: Request, exc: Exception) -> JSONResponse:
        assert isinstance(exc, RequestValidationError)
        errors = [{**e, "input": _brief(e["input"])} if "input" in e else e for e in exc.errors()]
        return SafeJSONResponse({"detail": jsonable_encoder(errors)}, status_code=422)

    async def http_error(_request: Request, exc: Exception) -> JSONResponse:
        assert isinstance(exc, HTTPException)
        return SafeJSONResponse({"detail": exc.detail}, status_code=exc.status_code, headers=exc.headers)

    app.add_exception_handler(OperatorError, operator_error)
    app.add_exception_handler(RequestValidationError, validation_error)
    app.add_exception_handler(HTTPException, http_error)
