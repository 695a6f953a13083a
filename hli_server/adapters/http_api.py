"""The control API over HTTP (JSON; OpenAPI at ``/openapi.json``, docs at ``/docs``).

The operator panel of the simulated machine and the remote control of the integration tests (H-07):
machine state, programs, start/feedhold/reset, mode, jog, override, stepping the stepped clock,
fault injection (A3-05), alarms and events, and every image field by its ST path (H-01, H-02).
This module is the only importer of FastAPI and uvicorn.

It is served by uvicorn *inside the runtime's event loop* (``uvicorn.Server.serve()`` as a task on
a socket the adapter binds itself); the runtime owns the signals. Every handler is ``async def``:
a plain ``def`` handler would run in a worker thread and touch the engine from outside the loop.

Operator requests (start, reset, mode, jog, ...) are latched by the channel at the next cycle, as a
PLC's are; the answers say from which cycle they take effect (``202 Accepted``). Image writes go to
the PLC->CNC half of the shared memory exactly like a PLC's write and are latched the same way;
writes to CNC->PLC fields (``_r``) are refused with 403 (H-02).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Generator
from typing import TYPE_CHECKING, Annotated, Any, Literal

import uvicorn
from fastapi import FastAPI, HTTPException, Query, Request
from fastapi.exceptions import RequestValidationError
from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictFloat, StrictInt, ValidationError

from hli_server.runtime import Clock, ClockError
from schemas.layout import ReadOnlySignalError, SignalValueError, UnknownSignalError
from schemas.wire import Mode

if TYPE_CHECKING:
    from hli_server.engine.axis import Axis
    from hli_server.engine.channel import Channel
    from hli_server.runtime import Runtime

__all__ = ["HttpApiAdapter", "create_app"]

logger = logging.getLogger(__name__)

MAX_STEP = 10_000_000
"""Most cycles one ``POST /api/step`` may ask for (10 000 s of simulated time at 1 ms)."""

ALARM_HISTORY_SHOWN = 200


# --------------------------------------------------------------------------------------------
# Request and response models
# --------------------------------------------------------------------------------------------


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ProgramBody(_Body):
    text: str = Field(min_length=1, description="the NC program (DIN 66025 blocks, one per line)")
    name: str = Field(default="program", min_length=1, max_length=200, description="shown in the state")


class SelectBody(_Body):
    number: int = Field(ge=1, le=65535, description="program number in the channel's program table")


class FeedholdBody(_Body):
    on: StrictBool = Field(description="true: hold the path; false: release it")


class ModeBody(_Body):
    mode: Literal["automatic", "manual"]


class OverrideBody(_Body):
    percent: float = Field(ge=0.0, le=120.0, description="feed override 0..120 %, in steps of 0.1 %")


class JogBody(_Body):
    axis: str = Field(description="axis name of this channel, e.g. X")
    direction: Literal[-1, 0, 1] = Field(description="+1 / -1: key pressed; 0: key released")


class StepBody(_Body):
    cycles: int = Field(default=1, ge=1, le=MAX_STEP, description="cycles of T_A to run")


class FaultsBody(_Body):
    """Fault injection (A3-05), units of the engine: mm/s for friction and drift. Fields left out
    keep their value."""

    friction: float | None = Field(default=None, ge=0.0, description="stiction dead band [mm/s]")
    gain_factor: float | None = Field(default=None, gt=0.0, le=100.0, description="multiplies kv")
    encoder_stuck: StrictBool | None = Field(default=None, description="the encoder stops counting")
    encoder_drift: float | None = Field(default=None, description="encoder drift [mm/s]")
    drive_error: StrictBool | None = Field(default=None, description="the drive reports an error")


class ImageWriteBody(_Body):
    # strict: "yes" or "300" are refused (422), not read as true or 300; the field's type is checked
    # by the layout afterwards (Signal.coerce), with its own one-line message
    value: StrictBool | StrictInt | StrictFloat = Field(
        description="BOOL: true/false or 0/1; DINT/UDINT: integer; LREAL: number"
    )


class Accepted(BaseModel):
    channel: int
    request: str
    cycle: int = Field(description="the machine's cycle when the request was taken")
    effective_cycle: int = Field(description="the cycle that latches the request")


# --------------------------------------------------------------------------------------------
# The application
# --------------------------------------------------------------------------------------------

ST_PATH_EXAMPLE = "gpCh[0]^bahn_mc_control.override.command_w"


def create_app(runtime: Runtime) -> FastAPI:
    """The FastAPI application for ``runtime`` (usable without a socket, e.g. with an ASGI client)."""
    app = FastAPI(
        title="hli-server control API",
        version="1",
        description=(
            "Operator panel and remote control of the simulated CNC kernel: state, programs, "
            "start/feedhold/reset, mode, jog, override, stepping (stepped clock), fault injection, "
            "alarms, events and the process image by ST path. Requests to a channel are latched at "
            "the next cycle (202). See docs/api.md."
        ),
    )
    app.state.runtime = runtime

    def rt(request: Request) -> Runtime:
        r: Runtime = request.app.state.runtime
        return r

    def channel_of(r: Runtime, number: int) -> Channel:
        try:
            return r.machine.channel(number)
        except KeyError:
            have = ", ".join(str(c.number) for c in r.machine.channels)
            raise HTTPException(404, f"no channel {number}; the machine has channels {have}") from None

    def axis_of(r: Runtime, name: str) -> Axis:
        axis = r.machine.axes_by_name.get(name)
        if axis is None:
            have = ", ".join(r.machine.axes_by_name)
            raise HTTPException(404, f"no axis {name!r}; the machine has axes {have}")
        return axis

    def accepted(r: Runtime, ch: Channel, what: str) -> Accepted:
        cycle = r.machine.cycle
        return Accepted(channel=ch.number, request=what, cycle=cycle, effective_cycle=cycle + 1)

    # --- state ------------------------------------------------------------------------
    @app.get("/api/state", tags=["state"], summary="Machine snapshot: channels, axes, active alarms")
    async def get_state(request: Request) -> dict[str, Any]:
        r = rt(request)
        snap = r.machine.snapshot()
        snap["clock"] = str(r.clock)
        return snap

    @app.get("/api/timing", tags=["state"], summary="Pacing statistics of the clock (lateness in µs)")
    async def get_timing(request: Request) -> dict[str, Any]:
        return rt(request).timing()

    @app.get("/api/alarms", tags=["state"], summary="Active alarms and the newest of the history")
    async def get_alarms(request: Request) -> dict[str, Any]:
        m = rt(request).machine
        history = list(m.alarm_history)[-ALARM_HISTORY_SHOWN:]
        return {
            "active": [a.to_json() for a in m.active_alarms],
            "history": [a.to_json() for a in history],
        }

    @app.get("/api/events", tags=["state"], summary="Engine events after sequence number `since`")
    async def get_events(
        request: Request,
        since: Annotated[int, Query(ge=0, description="last seq you have seen (0: from the start)")] = 0,
        limit: Annotated[int, Query(ge=1, le=10_000)] = 1000,
    ) -> dict[str, Any]:
        events, latest = rt(request).events_since(since, limit)
        oldest = events[0].seq if events else latest + 1
        return {
            "events": [e.to_json() for e in events],
            "next": events[-1].seq if events else max(since, 0),
            "latest": latest,
            "missed": max(0, oldest - since - 1),
        }

    # --- channels ---------------------------------------------------------------------
    program_body_doc = {
        "requestBody": {
            "required": True,
            "content": {
                "text/plain": {"schema": {"type": "string"}, "example": "N10 G01 X10 F1000\nN20 M30\n"},
                "application/json": {"schema": ProgramBody.model_json_schema()},
            },
        }
    }

    @app.post(
        "/api/channels/{number}/program",
        tags=["channels"],
        summary="Load an NC program (text/plain body, or JSON {text, name})",
        openapi_extra=program_body_doc,
        responses={409: {"description": "a program is running"}, 422: {"description": "no text"}},
    )
    async def post_program(
        request: Request,
        number: int,
        name: Annotated[
            str, Query(min_length=1, max_length=200, description="name for a text body")
        ] = "program",
    ) -> dict[str, Any]:
        r = rt(request)
        ch = channel_of(r, number)
        raw = await request.body()
        content_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
        if content_type == "application/json":
            try:
                body = ProgramBody.model_validate_json(raw)
            except ValidationError as exc:
                raise RequestValidationError(exc.errors(include_url=False)) from None
            text, prog_name = body.text, body.name
        else:
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise HTTPException(422, f"program text is not UTF-8 (byte {exc.start})") from None
            prog_name = name
            if not text.strip():
                raise HTTPException(422, "empty program: send the NC text as the body (text/plain)")
        refused = ch.load_program(text, prog_name)
        if refused is not None:
            raise HTTPException(409, f"channel {number}: {refused.message}; reset the channel first")
        lines = text.count("\n") + (0 if text.endswith("\n") else 1)
        return {"channel": number, "program": prog_name, "lines": lines, "cycle": r.machine.cycle}

    @app.post("/api/channels/{number}/select", tags=["channels"], summary="Select a program of the table")
    async def post_select(request: Request, number: int, body: SelectBody) -> dict[str, Any]:
        r = rt(request)
        ch = channel_of(r, number)
        entry = next((p for p in ch.config.programs if p.number == body.number), None)
        if entry is None:
            have = ", ".join(str(p.number) for p in ch.config.programs) or "none"
            raise HTTPException(
                404, f"channel {number}: program {body.number} is not in the program table (have: {have})"
            )
        refused = ch.select_program(body.number)
        if refused is not None:
            raise HTTPException(409, f"channel {number}: {refused.message}; reset the channel first")
        return {"channel": number, "program": entry.name, "number": body.number, "cycle": r.machine.cycle}

    @app.post("/api/channels/{number}/start", tags=["channels"], status_code=202, summary="Program start")
    async def post_start(request: Request, number: int) -> Accepted:
        r = rt(request)
        ch = channel_of(r, number)
        ch.request_start()
        return accepted(r, ch, "start")

    @app.post("/api/channels/{number}/reset", tags=["channels"], status_code=202, summary="Channel reset")
    async def post_reset(request: Request, number: int) -> Accepted:
        r = rt(request)
        ch = channel_of(r, number)
        ch.request_reset()
        return accepted(r, ch, "reset")

    @app.post(
        "/api/channels/{number}/feedhold", tags=["channels"], status_code=202, summary="Feedhold on/off"
    )
    async def post_feedhold(request: Request, number: int, body: FeedholdBody) -> Accepted:
        r = rt(request)
        ch = channel_of(r, number)
        ch.request_feedhold(body.on)
        return accepted(r, ch, f"feedhold {'on' if body.on else 'off'}")

    @app.post(
        "/api/channels/{number}/mode",
        tags=["channels"],
        status_code=202,
        summary='Mode: {"mode": "automatic"|"manual"} (or the bare string)',
    )
    async def post_mode(
        request: Request, number: int, body: ModeBody | Literal["automatic", "manual"]
    ) -> Accepted:
        r = rt(request)
        ch = channel_of(r, number)
        mode = body.mode if isinstance(body, ModeBody) else body
        ch.request_mode(Mode.MANUAL if mode == "manual" else Mode.AUTOMATIC)
        return accepted(r, ch, f"mode {mode}")

    @app.post("/api/channels/{number}/override", tags=["channels"], status_code=202, summary="Feed override")
    async def post_override(request: Request, number: int, body: OverrideBody) -> Accepted:
        r = rt(request)
        ch = channel_of(r, number)
        ch.request_override(round(body.percent * 10))
        return accepted(r, ch, f"override {body.percent:g} %")

    @app.post(
        "/api/channels/{number}/jog", tags=["channels"], status_code=202, summary="Jog key (manual mode)"
    )
    async def post_jog(request: Request, number: int, body: JogBody) -> Accepted:
        r = rt(request)
        ch = channel_of(r, number)
        if body.axis not in ch.axis_names:
            raise HTTPException(
                404, f"channel {number} has no axis {body.axis!r}; its axes are {', '.join(ch.axis_names)}"
            )
        ch.request_jog(body.axis, body.direction)
        key = {1: "+", -1: "-"}.get(body.direction, " released")
        return accepted(r, ch, f"jog {body.axis}{key}")

    # --- clock ------------------------------------------------------------------------
    @app.post(
        "/api/step",
        tags=["clock"],
        summary="Run N cycles (stepped clock only)",
        responses={409: {"description": "the runtime does not run the stepped clock"}},
    )
    async def post_step(request: Request, body: StepBody | None = None) -> dict[str, Any]:
        r = rt(request)
        cycles = body.cycles if body is not None else 1
        if r.clock is not Clock.STEPPED:
            raise HTTPException(
                409,
                f"stepping needs the stepped clock; this server runs the {r.clock} clock (--clock stepped)",
            )
        try:
            cycle = await r.step(cycles)
        except ClockError as exc:
            raise HTTPException(409, str(exc)) from None
        return {"cycles": cycles, "cycle": cycle, "time_s": r.machine.time}

    # --- axes -------------------------------------------------------------------------
    def faults_json(axis: Axis) -> dict[str, Any]:
        f = axis.faults
        return {
            "axis": axis.name,
            "friction": f.friction,
            "gain_factor": f.gain_factor,
            "encoder_stuck": f.encoder_stuck,
            "encoder_drift": f.encoder_drift,
            "drive_error": f.drive_error,
        }

    @app.get("/api/axes/{name}/faults", tags=["axes"], summary="Injected faults of an axis")
    async def get_faults(request: Request, name: str) -> dict[str, Any]:
        return faults_json(axis_of(rt(request), name))

    @app.post("/api/axes/{name}/faults", tags=["axes"], summary="Inject faults (A3-05); omitted fields stay")
    async def post_faults(request: Request, name: str, body: FaultsBody) -> dict[str, Any]:
        r = rt(request)
        axis = axis_of(r, name)
        try:
            r.machine.inject_fault(axis.name, **body.model_dump(exclude_none=True))
        except ValueError as exc:
            raise HTTPException(422, str(exc)) from None
        return faults_json(axis)

    @app.delete("/api/axes/{name}/faults", tags=["axes"], summary="Clear all injected faults of an axis")
    async def delete_faults(request: Request, name: str) -> dict[str, Any]:
        r = rt(request)
        axis = axis_of(r, name)
        r.machine.inject_fault(axis.name)
        return faults_json(axis)

    # --- the process image ------------------------------------------------------------
    @app.get("/api/layout", tags=["image"], summary="The image layout (as `hli-server map --format json`)")
    async def get_layout(request: Request) -> dict[str, Any]:
        layout_dict: dict[str, Any] = rt(request).layout.to_dict()
        return layout_dict

    @app.get(
        "/api/image/{st_path:path}",
        tags=["image"],
        summary=f"Read an image field by ST path, e.g. {ST_PATH_EXAMPLE}",
        responses={404: {"description": "unknown ST path"}},
    )
    async def get_image(request: Request, st_path: str) -> dict[str, Any]:
        r = rt(request)
        signal = _signal_or_404(r, st_path)
        value = r.image.read(signal.st_path)
        return _field_json(r, signal, value)

    @app.put(
        "/api/image/{st_path:path}",
        tags=["image"],
        summary="Write a PLC->CNC image field (_w) by ST path; latched at the next cycle",
        responses={
            403: {"description": "a CNC->PLC field (_r): only the CNC writes it (H-02)"},
            404: {"description": "unknown ST path"},
            422: {"description": "the value does not fit the field's type"},
        },
    )
    async def put_image(request: Request, st_path: str, body: ImageWriteBody) -> dict[str, Any]:
        r = rt(request)
        signal = _signal_or_404(r, st_path)
        try:
            signal.check_plc_write()
            value = signal.coerce(body.value)
            r.image.write(signal.st_path, value)
        except ReadOnlySignalError as exc:
            raise HTTPException(403, str(exc)) from None
        except SignalValueError as exc:
            raise HTTPException(422, str(exc)) from None
        out = _field_json(r, signal, value)
        out["effective_cycle"] = r.machine.cycle + 1
        return out

    return app


def _normalize_st_path(path: str) -> str:
    """Accept ``gpAx[0].ipo_state.act_pos_r`` for ``gpAx[0]^ipo_state.act_pos_r`` (``^`` is awkward
    in URLs: it must be sent as ``%5E``)."""
    path = path.strip("/")
    if "^" not in path and path.startswith(("gpCh[", "gpAx[")):
        head, dot, rest = path.partition("].")
        if dot:
            return f"{head}]^{rest}"
    return path


def _signal_or_404(r: Runtime, st_path: str) -> Any:
    try:
        return r.layout.signal(_normalize_st_path(st_path))
    except UnknownSignalError as exc:
        raise HTTPException(404, str(exc)) from None


def _field_json(r: Runtime, signal: Any, value: object) -> dict[str, Any]:
    return {
        "st_path": signal.st_path,
        "value": value,
        "type": str(signal.type),
        "direction": str(signal.direction),
        "access": signal.access,
        "unit": signal.unit,
        "cycle": r.machine.cycle,
    }


# --------------------------------------------------------------------------------------------
# The adapter
# --------------------------------------------------------------------------------------------


class _Server(uvicorn.Server):
    """uvicorn without its own signal handling: the runtime owns SIGINT/SIGTERM."""

    @contextlib.contextmanager
    def capture_signals(self) -> Generator[None, None, None]:
        yield


class HttpApiAdapter:
    """Serves :func:`create_app` on ``bind:port`` (0 = a free port; :attr:`port` tells which)."""

    name = "http"

    def __init__(self, *, bind: str = "127.0.0.1", port: int = 8080, graceful_timeout: int = 2) -> None:
        self.bind = bind
        self.requested_port = port
        self.port: int | None = None
        self.graceful_timeout = graceful_timeout
        self._server: _Server | None = None
        self._task: asyncio.Task[None] | None = None
        self._socket: socket.socket | None = None

    @property
    def url(self) -> str:
        if self.port is None:
            raise RuntimeError("the HTTP API is not listening (start it first)")
        host = f"[{self.bind}]" if ":" in self.bind else self.bind
        return f"http://{host}:{self.port}"

    def endpoints(self) -> list[str]:
        if self.port is None:
            return ["HTTP control API: not listening"]
        return [f"HTTP control API: {self.url}  (OpenAPI: {self.url}/docs)"]

    async def start(self, runtime: Runtime) -> None:
        self._socket = sock = _listen(self.bind, self.requested_port)
        self.port = sock.getsockname()[1]
        config = uvicorn.Config(
            create_app(runtime),
            log_config=None,
            access_log=False,
            lifespan="off",
            ws="none",
            timeout_graceful_shutdown=self.graceful_timeout,
        )
        self._server = server = _Server(config)
        self._task = task = asyncio.create_task(server.serve(sockets=[sock]), name="hli-http-api")
        while not server.started:
            if task.done():
                sock.close()
                task.result()  # raises what went wrong
                raise RuntimeError(f"HTTP control API on {self.bind}:{self.port} stopped during start-up")
            await asyncio.sleep(0.005)

    async def stop(self) -> None:
        server, task = self._server, self._task
        self._server = self._task = None
        if server is not None and task is not None:
            server.should_exit = True
            try:
                await asyncio.wait_for(asyncio.shield(task), self.graceful_timeout + 3.0)
            except TimeoutError:
                logger.warning("HTTP control API did not stop in time; closing its connections")
                server.force_exit = True
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
        if self._socket is not None:
            self._socket.close()
            self._socket = None
        self.port = None


def _listen(bind: str, port: int) -> socket.socket:
    try:
        infos = socket.getaddrinfo(bind, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise OSError(f"HTTP control API: cannot resolve bind address {bind!r}: {exc.strerror}") from None
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(128)
    except OSError as exc:
        sock.close()
        raise OSError(
            exc.errno,
            f"HTTP control API: cannot listen on {bind}:{port}: {exc.strerror}; "
            "choose another --http-port (0 = any free port) or --bind address",
        ) from None
    sock.setblocking(False)
    return sock
