"""What every router needs: the host as a FastAPI dependency, and operator errors as HTTP answers."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, FastAPI, Request
from fastapi.responses import JSONResponse

from hli_server.adapters.host import (
    Accepted,
    AdapterHost,
    ConflictError,
    InvalidRequestError,
    NotFoundError,
    OperatorError,
    StepRefusedError,
)
from hli_server.adapters.http.models import AcceptedBody

__all__ = ["HostDep", "accepted", "get_host", "install_error_handlers"]


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
)


def install_error_handlers(app: FastAPI) -> None:
    """An operator error becomes ``{"detail": message}`` with 404 / 409 / 422."""

    async def operator_error(_request: Request, exc: Exception) -> JSONResponse:
        status = next((code for kind, code in _STATUS if isinstance(exc, kind)), 400)
        return JSONResponse({"detail": str(exc)}, status_code=status)

    app.add_exception_handler(OperatorError, operator_error)
