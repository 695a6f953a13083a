"""``/api/channels/{n}/...``: programs and the channel's operator requests (latched next cycle, 202)."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError

from hli_server.adapters.http.deps import HostDep, accepted
from hli_server.adapters.http.models import (
    AcceptedBody,
    FeedholdBody,
    JogBody,
    ModeBody,
    OverrideBody,
    ProbeBody,
    ProbeDeviationBody,
    ProgramBody,
    SelectBody,
)
from hli_server.codecs.nc_text import decode_program
from schemas.results import ProbeDeviation, ProgramLoaded, ProgramSelected
from schemas.wire import Mode

__all__ = ["router"]

router = APIRouter(tags=["channels"])

_PROGRAM_BODY_DOC = {
    "requestBody": {
        "required": True,
        "content": {
            "text/plain": {"schema": {"type": "string"}, "example": "N10 G01 X10 F1000\nN20 M30\n"},
            "application/json": {"schema": ProgramBody.model_json_schema()},
        },
    }
}


@router.post(
    "/api/channels/{number}/program",
    summary="Load an NC program (text/plain body, or JSON {text, name, files} with its subprograms)",
    openapi_extra=_PROGRAM_BODY_DOC,
    responses={409: {"description": "a program is running"}, 422: {"description": "no text"}},
)
async def post_program(
    host: HostDep,
    request: Request,
    number: int,
    name: Annotated[str, Query(min_length=1, max_length=200, description="name for a text body")] = "program",
) -> ProgramLoaded:
    raw = await request.body()
    content_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if content_type == "application/json":
        try:
            body = ProgramBody.model_validate_json(raw)
        except ValidationError as exc:
            raise RequestValidationError(exc.errors(include_url=False)) from None
        text, prog_name, files = body.text, body.name, body.files
    else:
        files = {}
        try:
            text = decode_program(raw)  # UTF-8 (a byte order mark or not) or Windows-1252, as files
        except UnicodeDecodeError as exc:  # a UTF-16 body cut short
            raise HTTPException(422, f"program text cannot be read: {exc}") from None
        prog_name = name
        if not text.strip():
            raise HTTPException(422, "empty program: send the NC text as the body (text/plain)")
    return host.operator.load_program(number, text, prog_name, files)


@router.post("/api/channels/{number}/select", summary="Select a program of the table")
async def post_select(host: HostDep, number: int, body: SelectBody) -> ProgramSelected:
    return host.operator.select_program(number, body.number)


@router.post("/api/channels/{number}/start", status_code=202, summary="Program start")
async def post_start(host: HostDep, number: int) -> AcceptedBody:
    return accepted(host.operator.start(number))


@router.post("/api/channels/{number}/reset", status_code=202, summary="Channel reset")
async def post_reset(host: HostDep, number: int) -> AcceptedBody:
    return accepted(host.operator.reset(number))


@router.post("/api/channels/{number}/feedhold", status_code=202, summary="Feedhold on/off")
async def post_feedhold(host: HostDep, number: int, body: FeedholdBody) -> AcceptedBody:
    return accepted(host.operator.feedhold(number, body.on))


@router.post(
    "/api/channels/{number}/mode",
    status_code=202,
    summary='Mode: {"mode": "automatic"|"manual"} (or the bare string)',
)
async def post_mode(
    host: HostDep, number: int, body: ModeBody | Literal["automatic", "manual"]
) -> AcceptedBody:
    mode = body.mode if isinstance(body, ModeBody) else body
    return accepted(host.operator.mode(number, Mode.MANUAL if mode == "manual" else Mode.AUTOMATIC))


@router.post("/api/channels/{number}/override", status_code=202, summary="Feed override")
async def post_override(host: HostDep, number: int, body: OverrideBody) -> AcceptedBody:
    return accepted(host.operator.override(number, round(body.percent * 10)))


@router.post("/api/channels/{number}/jog", status_code=202, summary="Jog key (manual mode)")
async def post_jog(host: HostDep, number: int, body: JogBody) -> AcceptedBody:
    return accepted(host.operator.jog(number, body.axis, body.direction))


@router.post(
    "/api/channels/{number}/probe", status_code=202, summary="Probe input for G100 measuring moves (C14-23)"
)
async def post_probe(host: HostDep, number: int, body: ProbeBody) -> AcceptedBody:
    return accepted(host.operator.probe(number, body.on))


@router.get(
    "/api/channels/{number}/probe/deviation",
    summary="The simulated workpiece's deviation per axis [0.1 µm] (built-in measuring cycles, "
    "docs/cycles.md)",
)
async def get_probe_deviation(host: HostDep, number: int) -> ProbeDeviation:
    return host.operator.probe_deviation(number)


@router.put(
    "/api/channels/{number}/probe/deviation",
    summary="Set the simulated workpiece's deviation per axis [0.1 µm]; an axis with a V.E. variable has it "
    "written",
)
async def put_probe_deviation(host: HostDep, number: int, body: ProbeDeviationBody) -> ProbeDeviation:
    return host.operator.set_probe_deviation(number, dict(body.deviation))
