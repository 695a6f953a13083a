"""``POST /api/check``: check a program offline, as ``hli-server check`` does (N-10).

The engine's ``ProgramCheck`` runs on a fresh machine of the server's machine file, in a worker process
(``runtime/checks.py``): the running machine, its programs and its V.E. variables are not touched, and the
realtime clock does not wait. The answer is ``check --format json``'s report with the verdict.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError

from hli_server.adapters.http.deps import HostDep
from hli_server.adapters.http.models import CheckBody
from hli_server.codecs.nc_text import decode_program
from hli_server.codecs.presets import PresetSyntaxError, parse_preset
from schemas.results import CheckReport

__all__ = ["router"]

router = APIRouter(tags=["check"])

_BODY_DOC = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {"schema": CheckBody.model_json_schema()},
            "text/plain": {"schema": {"type": "string"}, "example": "N10 G01 X10 F1000\nN20 M30\n"},
        },
    }
}


def _presets(texts: list[str]) -> dict[str, bool | int | float | str]:
    """``?set=V.E.NAME=VALUE`` (repeated), as ``check --set``; a malformed one is 422."""
    presets: dict[str, bool | int | float | str] = {}
    for text in texts:
        try:
            name, value = parse_preset(text)
        except PresetSyntaxError as exc:
            raise HTTPException(422, f"set: {exc}") from None
        presets[name] = value
    return presets


@router.post(
    "/api/check",
    summary="Check a program offline (as `hli-server check`): JSON {text, name, files, channel, "
    "geometry_only, max_cycles, max_iterations, timeout_s, presets}, or the NC text as text/plain with "
    "those as query parameters (presets as set=V.E.NAME=VALUE, repeated)",
    openapi_extra=_BODY_DOC,
    response_model=CheckReport,
    responses={
        404: {"description": "no such channel"},
        422: {"description": "no text, a bad file name, a value out of range"},
        503: {"description": "the checker is busy (one check runs, four wait)"},
        504: {"description": "the check did not finish within timeout_s and was ended"},
    },
)
async def post_check(
    host: HostDep,
    request: Request,
    name: Annotated[str, Query(min_length=1, max_length=200)] = "program",
    channel: Annotated[int, Query(ge=1, le=255)] = 1,
    geometry_only: bool = False,
    max_cycles: Annotated[int | None, Query(ge=1, le=50_000_000)] = None,
    max_iterations: Annotated[int | None, Query(ge=1, le=100_000_000)] = None,
    timeout_s: Annotated[float | None, Query(gt=0, le=600)] = None,
    set_: Annotated[
        list[str] | None,
        Query(alias="set", max_length=4096, description="V.E.NAME=VALUE, as `check --set` (a text body)"),
    ] = None,
) -> CheckReport:
    raw = await request.body()
    content_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if content_type == "application/json":
        try:
            body = CheckBody.model_validate_json(raw)
        except ValidationError as exc:
            raise RequestValidationError(exc.errors(include_url=False)) from None
    else:
        try:
            text = decode_program(raw)  # UTF-8 (a byte order mark or not) or Windows-1252, as files
        except UnicodeDecodeError as exc:  # a UTF-16 body cut short
            raise HTTPException(422, f"program text cannot be read: {exc}") from None
        if not text.strip():
            raise HTTPException(422, "empty program: send the NC text as the body (text/plain)")
        fields: dict[str, Any] = {
            "text": text,
            "name": name,
            "channel": channel,
            "geometry_only": geometry_only,
        }
        for key, value in (
            ("max_cycles", max_cycles),
            ("max_iterations", max_iterations),
            ("timeout_s", timeout_s),
        ):
            if value is not None:
                fields[key] = value
        if set_:
            fields["presets"] = _presets(set_)
        body = CheckBody(**fields)
    return await host.checker.check(
        body.text,
        name=body.name,
        files=body.files,
        channel=body.channel,
        geometry_only=body.geometry_only,
        max_cycles=body.max_cycles,
        max_iterations=body.max_iterations,
        timeout_s=body.timeout_s,
        presets=body.presets,
    )
