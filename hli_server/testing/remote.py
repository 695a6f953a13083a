"""A hli-server that runs elsewhere, driven over its HTTP control API: the harness of ``pytest --hli-url``.

A test lab runs its simulated CNCs as servers of their own (containers, a Kubernetes StatefulSet:
docs/kubernetes.md), one per machine variant or per PLC under test, and its CI fans the tests out over them:
each pytest-xdist worker takes one CNC (:func:`worker_url`). :class:`RemoteHarness` gives a test what the
in-process :class:`~hli_server.testing.Harness` gives, as far as HTTP lets it: the server runs
``--clock stepped`` and the harness steps it (``POST /api/step``), reads and writes the image by ST path
(``/api/image``), drives the operator panel (``/api/channels``, ``/api/axes``) and the communication faults,
and opens the PLC doors (Modbus, ADS) on the server's host. At its start it powers the machine off and on
(``POST /api/machine/restart``): every test begins with the machine file's machine at cycle 0, whatever the
test before it left behind.

**Cost.** A cycle of :meth:`RemoteHarness.run_until` is one request: the step traces the signals the
condition read (``POST /api/step`` with ``trace``), and their values answer the condition's next reads
without a request of their own: 4.5 ms a cycle over loopback on the shared, loaded 2-core development
machine; across a cluster a round trip more. A long stretch without a condition is one
:meth:`RemoteHarness.step`.

What differs from the in-process harness (docs/testing.md, "A fleet of CNCs"): no ``runtime`` (the server
is another process), no shared-memory door, no ``record`` (the server's recorder is its HTTP API's),
``check`` runs here on the machine file the test names; ``image.snapshot()`` asks for every field.
"""

from __future__ import annotations

import asyncio
import http.client
import json
import os
import time
import types
import urllib.parse
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from hli_server.adapters.host import (
    Accepted,
    ConflictError,
    InvalidRequestError,
    NotFoundError,
    OperatorError,
    StepRefusedError,
    Trace,
    UnavailableError,
)
from hli_server.adapters.http.routers.image import normalize_st_path
from hli_server.testing.harness import (
    REPORT_CYCLES,
    CommFaultsView,
    ConditionNotMetError,
    HarnessError,
    ReplayFailedError,
    _Programs,
    describe,
    load_machine_spec,
)
from hli_server.testing.transports import open_transport
from schemas.layout import Direction, Layout, Signal
from schemas.results import (
    AlarmList,
    AreaTable,
    AxisFaults,
    CollisionPair,
    CommFault,
    MachineState,
    ProbeDeviation,
    ProgramEntry,
    ProgramLoaded,
    ProgramSelected,
    Scene,
    SoftLimits,
    Timing,
)
from schemas.wire import Mode

if TYPE_CHECKING:
    from hli_server.adapters.host import Value
    from plc_clients.task import PlcTask
    from plc_clients.transports import Transport
    from schemas.config import MachineConfig

__all__ = ["MAX_TRACED", "RemoteHarness", "RemoteOperator", "worker_url"]

MAX_TRACED = 64
"""Signals one step may trace (the server's bound): the condition's reads traced beyond it are asked."""
IDLE_RECONNECT_S = 2.0
"""A kept-alive connection idle this long is replaced before the next request (the server closes idle ones
after 5 s; a request sent into one it is closing would be lost)."""

_C2P = Direction.CNC_TO_PLC
_ERRORS: dict[int, type[OperatorError]] = {
    404: NotFoundError,
    409: ConflictError,
    422: InvalidRequestError,
    503: UnavailableError,
}


def worker_url(urls: Sequence[str], worker: str | None) -> str:
    """The CNC of pytest-xdist worker ``worker`` (``gw0``, ``gw1``, ...; None without xdist: the first).

    ``urls`` are the ``--hli-url`` values: worker ``gwN`` takes the N-th; a URL with ``{n}`` stands for as
    many CNCs as there are workers (``http://cnc-{n}.cnc:8080``: worker ``gwN`` takes CNC N). Raises
    ValueError when there are fewer CNCs than workers: two workers must never share a CNC."""
    if not urls:
        raise ValueError("no --hli-url was given")
    n = int(worker.removeprefix("gw")) if worker and worker.startswith("gw") else 0
    if len(urls) == 1 and "{n}" in urls[0]:
        return urls[0].replace("{n}", str(n))
    if n >= len(urls):
        raise ValueError(
            f"worker {worker} has no CNC of its own: {len(urls)} --hli-url for more workers; give one URL "
            "per worker (or a pattern with {n}), or fewer workers (-n)"
        )
    return urls[n]


class _Api:
    """JSON over one kept-alive HTTP connection (stdlib only: the plugin's users need no HTTP library)."""

    def __init__(self, url: str, token: str | None, timeout_s: float) -> None:
        parts = urllib.parse.urlsplit(url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise HarnessError(f"--hli-url {url!r}: give the server's HTTP address, http://HOST:PORT")
        self.url = url.rstrip("/")
        self.host = parts.hostname
        self._https = parts.scheme == "https"
        self._port = parts.port or (443 if self._https else 80)
        self._prefix = parts.path.rstrip("/")
        self._headers = {"Accept": "application/json"}
        if token:
            self._headers["Authorization"] = f"Bearer {token}"
        self.timeout_s = timeout_s
        self._conn: http.client.HTTPConnection | None = None
        self._used = 0.0

    def _connection(self) -> http.client.HTTPConnection:
        if self._conn is not None and time.monotonic() - self._used > IDLE_RECONNECT_S:
            self.close()
        if self._conn is None:
            kind = http.client.HTTPSConnection if self._https else http.client.HTTPConnection
            self._conn = kind(self.host, self._port, timeout=self.timeout_s)
        return self._conn

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def call(self, method: str, path: str, body: object = None, *, ok: Sequence[int] = ()) -> tuple[int, Any]:
        """``(status, answer)``; an error status not in ``ok`` raises the operator's error of that status
        (404 NotFoundError, 409 ConflictError, 422 InvalidRequestError, 503 UnavailableError)."""
        headers = dict(self._headers)
        data = None
        if body is not None:
            data = json.dumps(body).encode("utf-8")
            headers["Content-Type"] = "application/json"
        conn = self._connection()
        try:
            conn.request(method, self._prefix + path, body=data, headers=headers)
            response = conn.getresponse()
            raw = response.read()
        except (OSError, http.client.HTTPException) as exc:
            self.close()
            raise UnavailableError(f"{method} {self.url}{path}: {exc or type(exc).__name__}") from None
        self._used = time.monotonic()
        if response.will_close:
            self.close()
        try:
            answer = json.loads(raw) if raw else None
        except ValueError:
            answer = raw.decode("utf-8", "replace")
        status = response.status
        if status >= 400 and status not in ok:
            detail = answer.get("detail", answer) if isinstance(answer, dict) else answer
            if status == 401:
                detail = f"{detail} (the server wants its API token: --hli-token or HLI_API_TOKEN)"
            raise _ERRORS.get(status, OperatorError)(f"{method} {path}: {status} {detail}")
        return status, answer

    def get(self, path: str) -> Any:
        return self.call("GET", path)[1]

    def post(self, path: str, body: object = None) -> Any:
        return self.call("POST", path, {} if body is None else body)[1]


def _quoted(st_path: str) -> str:
    return urllib.parse.quote(st_path, safe="[]._")


class RemoteOperator:
    """The operator panel of a remote server (:class:`~hli_server.adapters.host.OperatorPort`'s calls)
    over its HTTP API: the same answers as in-process, the same errors (by their HTTP status)."""

    def __init__(self, harness: RemoteHarness) -> None:
        self._h = harness
        self._api = harness._api

    # --- what and where -------------------------------------------------------------------------
    @property
    def cycle(self) -> int:
        return self._h.cycle

    @property
    def time_s(self) -> float:
        return self._h.cycle * self.t_a_us / 1_000_000

    @property
    def t_a_us(self) -> int:
        return int(self._h.machine["t_a_us"])

    @property
    def machine_name(self) -> str:
        return str(self._h.machine["name"])

    def channel_numbers(self) -> list[int]:
        return [int(ch["number"]) for ch in self._h.machine["channels"]]

    def axis_names(self, channel: int | None = None) -> list[str]:
        channels = self._h.machine["channels"]
        if channel is None:
            return list(dict.fromkeys(a for ch in channels for a in ch["axes"]))
        for ch in channels:
            if ch["number"] == channel:
                return list(ch["axes"])
        raise NotFoundError(f"no channel {channel} (channels: {self.channel_numbers()})")

    # --- programs and the channel's requests ------------------------------------------------------
    def load_program(
        self, channel: int, text: str, name: str = "program", files: Mapping[str, str] | None = None
    ) -> ProgramLoaded:
        body = {"text": text, "name": name, "files": dict(files or {})}
        out: ProgramLoaded = self._api.post(f"/api/channels/{channel}/program", body)
        return out

    def select_program(self, channel: int, number: int) -> ProgramSelected:
        out: ProgramSelected = self._api.post(f"/api/channels/{channel}/select", {"number": number})
        return out

    def _accepted(self, channel: int, request: str, body: object = None) -> Accepted:
        answer = self._api.post(f"/api/channels/{channel}/{request}", body)
        return Accepted(answer["channel"], answer["request"], answer["cycle"], answer["effective_cycle"])

    def start(self, channel: int) -> Accepted:
        return self._accepted(channel, "start")

    def reset(self, channel: int) -> Accepted:
        return self._accepted(channel, "reset")

    def feedhold(self, channel: int, on: bool) -> Accepted:
        return self._accepted(channel, "feedhold", {"on": on})

    def mode(self, channel: int, mode: Mode) -> Accepted:
        return self._accepted(channel, "mode", {"mode": "manual" if mode == Mode.MANUAL else "automatic"})

    def override(self, channel: int, permille: int) -> Accepted:
        return self._accepted(channel, "override", {"percent": permille / 10})

    def jog(self, channel: int, axis: str, direction: int) -> Accepted:
        return self._accepted(channel, "jog", {"axis": axis, "direction": direction})

    def probe(self, channel: int, on: bool) -> Accepted:
        return self._accepted(channel, "probe", {"on": on})

    def probe_deviation(self, channel: int) -> ProbeDeviation:
        out: ProbeDeviation = self._api.get(f"/api/channels/{channel}/probe/deviation")
        return out

    def set_probe_deviation(self, channel: int, values: dict[str, int]) -> ProbeDeviation:
        body = {"deviation": values}
        out: ProbeDeviation = self._api.call("PUT", f"/api/channels/{channel}/probe/deviation", body)[1]
        return out

    # --- axes -----------------------------------------------------------------------------------
    def reference(self, axis: str) -> Accepted:
        answer = self._api.post(f"/api/axes/{axis}/reference")
        return Accepted(answer["channel"], answer["request"], answer["cycle"], answer["effective_cycle"])

    def faults(self, axis: str) -> AxisFaults:
        out: AxisFaults = self._api.get(f"/api/axes/{axis}/faults")
        return out

    def inject_faults(self, axis: str, **fields: float | bool) -> AxisFaults:
        out: AxisFaults = self._api.post(f"/api/axes/{axis}/faults", fields)
        return out

    def clear_faults(self, axis: str) -> AxisFaults:
        out: AxisFaults = self._api.call("DELETE", f"/api/axes/{axis}/faults")[1]
        return out

    def soft_limits(self, axis: str) -> SoftLimits:
        out: SoftLimits = self._api.get(f"/api/axes/{axis}/soft-limits")
        return out

    def set_soft_limits(self, axis: str, **values: int) -> SoftLimits:
        out: SoftLimits = self._api.call("PUT", f"/api/axes/{axis}/soft-limits", values)[1]
        return out

    def update_axis_record(self, axis: str, **values: int) -> SoftLimits:
        out: SoftLimits = self._api.call("PUT", f"/api/axes/{axis}/record", values)[1]
        return out

    # --- what the machine shows -------------------------------------------------------------------
    def snapshot(self) -> MachineState:
        out: MachineState = self._api.get("/api/state")
        return out

    def alarms(self, history: int = 200) -> AlarmList:
        out: AlarmList = self._api.get("/api/alarms")
        out["history"] = out["history"][-history:] if history else []
        return out

    def areas(self, channel: int) -> AreaTable:
        out: AreaTable = self._api.get(f"/api/channels/{channel}/areas")
        return out

    def timing(self) -> Timing:
        out: Timing = self._api.get("/api/timing")
        return out

    def scene(self, channel: int) -> Scene:
        out: Scene = self._api.get(f"/api/channels/{channel}/scene")
        return out

    def programs(self, channel: int) -> list[ProgramEntry]:
        out: list[ProgramEntry] = self._api.get(f"/api/channels/{channel}/programs")
        return out

    def collision_pairs(self) -> list[CollisionPair]:
        out: list[CollisionPair] = self._api.get("/api/collision-pairs")
        return out

    def __repr__(self) -> str:
        return f"<operator panel of {self._api.url}>"


class RemoteImage:
    """``hli.image`` of a remote server: reads and writes by ST path (``/api/image``). CNC->PLC values are
    kept for the cycle they were read in, and the signals read are traced by the next single steps
    (:data:`MAX_TRACED` at most), so that a condition read after every cycle costs no request."""

    def __init__(self, harness: RemoteHarness) -> None:
        self._h = harness
        self._api = harness._api
        self._values: dict[str, Value] = {}
        self._cycle = -1
        self.watched: dict[str, None] = {}
        """The CNC->PLC signals read so far (in the order of their first read), traced by single steps."""

    @property
    def layout(self) -> Layout:
        return self._h.layout

    @property
    def name(self) -> str:
        return self._h.url

    def _signal(self, st_path: str) -> Signal:
        return self.layout.signal(normalize_st_path(st_path))

    def __getitem__(self, st_path: str) -> Value:
        return self.read(st_path)

    def __setitem__(self, st_path: str, value: Value) -> None:
        self.write(st_path, value)

    def read(self, st_path: str, *, watch: bool = True) -> Value:
        """The field's value (CNC->PLC: of the newest publish); ``watch``: trace it in the next steps."""
        signal = self._signal(st_path)
        path = signal.st_path
        if signal.direction is _C2P and self._cycle == self._h.cycle and path in self._values:
            return self._values[path]
        answer = self._api.get(f"/api/image/{_quoted(path)}")
        value: Value = answer["value"]
        if signal.direction is _C2P:
            if answer["cycle"] != self._cycle:
                self._values = {}
                self._cycle = answer["cycle"]
            self._values[path] = value
            if watch and len(self.watched) < MAX_TRACED:
                self.watched[path] = None
        return value

    def write(self, st_path: str, value: Value) -> None:
        """Write a PLC->CNC field; latched at the start of the next cycle, as a PLC's write is."""
        path = self._signal(st_path).st_path
        self._api.call("PUT", f"/api/image/{_quoted(path)}", {"value": value})

    def took(self, cycle: int, values: Mapping[str, Value]) -> None:
        """The values a traced step answered for its last cycle (CNC->PLC ones are kept)."""
        self._cycle = cycle
        self._values = {p: v for p, v in values.items() if self.layout.signal(p).direction is _C2P}

    def snapshot(self) -> dict[str, Value]:
        """Every CNC->PLC field of the newest publish (and ``"cycle"``): one request per field."""
        values: dict[str, Value] = {
            s.st_path: self.read(s.st_path, watch=False) for s in self.layout.half(_C2P)
        }
        values["cycle"] = self._h.cycle
        return values

    def outputs(self) -> dict[str, Value]:
        """Every PLC->CNC field as it is now: one request per field."""
        return {s.st_path: self.read(s.st_path, watch=False) for s in self.layout.half(Direction.PLC_TO_CNC)}

    def __repr__(self) -> str:
        return f"RemoteImage({self._h.url!r})"


class RemoteCommFaults(CommFaultsView):
    """``hli.comm_faults`` of a remote server (``/api/comm/faults``)."""

    def __init__(self, harness: RemoteHarness) -> None:
        self._api = harness._api

    def add(self, **spec: Any) -> CommFault:
        fault: CommFault = self._api.post("/api/comm/faults", spec)
        return fault

    def end(self, fault_id: int) -> None:
        self._api.call("DELETE", f"/api/comm/faults/{fault_id}")

    def reset(self) -> int:
        return int(self._api.call("DELETE", "/api/comm/faults")[1]["ended"])

    def table(self) -> list[CommFault]:
        table: list[CommFault] = self._api.get("/api/comm/faults")["faults"]
        return table


class _RemoteDoor:
    """A door of the remote server, as :meth:`RemoteHarness.serve` returns it (``port``, ``options``)."""

    def __init__(self, name: str, port: int, options: Mapping[str, Any]) -> None:
        self.name = name
        self.port = port
        self.options = types.SimpleNamespace(**options)

    def endpoints(self) -> list[str]:
        return [f"{self.name}: port {self.port}"]


class _RemoteRecording:
    """:meth:`RemoteHarness.trace`: the signals traced by every step from now on."""

    def __init__(self, harness: RemoteHarness, signals: Sequence[str]) -> None:
        self._h = harness
        self.signals = tuple(signals)
        self.cycles: list[int] = []
        self.values: dict[str, list[Value]] = {p: [] for p in self.signals}
        self.active = True

    def take(self, trace: Mapping[str, Any]) -> None:
        self.cycles.extend(trace["cycles"])
        for path in self.signals:
            self.values[path].extend(trace["values"][path])

    def __len__(self) -> int:
        return len(self.cycles)

    def trace(self) -> Trace:
        types = {p: self._h.layout.signal(p).type for p in self.signals}
        return Trace(self.signals, self.cycles, self.values, types)

    def stop(self) -> Trace:
        if self.active:
            self.active = False
            self._h._recordings.remove(self)
        return self.trace()

    def __enter__(self) -> _RemoteRecording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class RemoteHarness(_Programs):
    """A hli-server running elsewhere (``hli-server run --clock stepped``), driven over its HTTP API with the
    :class:`~hli_server.testing.Harness`'s calls (module docstring). ``url``: its HTTP address; ``token``:
    its API token (``--api-token``), if it has one; ``machine``: the machine file the tests expect (for
    :meth:`check`; None: the demo machine); ``restart``: power the machine off and on at start (the default;
    every test begins from the machine file's state); ``timeout_s``: how long to wait for the server to be
    ready, and for any answer."""

    remote = True

    def __init__(
        self,
        url: str,
        *,
        token: str | None = None,
        machine: Any = None,
        base: Path | None = None,
        restart: bool = True,
        timeout_s: float = 60.0,
        program_dirs: Sequence[str | os.PathLike[str]] = (),
    ) -> None:
        self._api = _Api(url, token, timeout_s)
        self.url = self._api.url
        self.bind = self._api.host
        """The server's host (the PLC doors are opened there)."""
        self._base = base
        self._machine_spec = machine
        self._restart = restart
        self.timeout_s = timeout_s
        self.program_dirs = [Path(os.fspath(d)) for d in program_dirs]
        self._layout: Layout | None = None
        self._image: RemoteImage | None = None
        self._operator: RemoteOperator | None = None
        self.machine: dict[str, Any] = {}
        """``GET /api/machine``: name, t_a_us, clock, channels with their axes."""
        self.ports: dict[str, int] = {}
        """The server's doors and their TCP ports (``GET /api/ready``)."""
        self._cycle = 0
        self._transports: list[Transport] = []
        self._recordings: list[_RemoteRecording] = []
        self._started = False

    # --- life cycle ---------------------------------------------------------------------------
    def start(self) -> RemoteHarness:
        """Wait until the server is ready, check that it runs the stepped clock, restart its machine."""
        if self._started:
            raise HarnessError("the harness was started already; make a new RemoteHarness to run again")
        self._started = True
        deadline = time.monotonic() + self.timeout_s
        while True:
            try:
                status, ready = self._api.call("GET", "/api/ready", ok=(503,))
            except UnavailableError as exc:
                status, ready = 0, str(exc)
            if status == 200:
                break
            if time.monotonic() > deadline:
                raise HarnessError(f"the CNC at {self.url} is not ready after {self.timeout_s:g} s: {ready}")
            time.sleep(0.2)
        self.ports = {k: int(v) for k, v in ready.get("ports", {}).items()}
        self.machine = self._api.get("/api/machine")
        if self.machine["clock"] != "stepped":
            raise HarnessError(
                f"the CNC at {self.url} runs the {self.machine['clock']} clock: the harness steps it, so it "
                "must run `hli-server run --clock stepped`"
            )
        if self._restart:
            self.restart()
        else:
            self._cycle = int(self._api.get("/api/state")["cycle"])
        self._layout = Layout.from_dict(self._api.get("/api/layout"))
        self._image = RemoteImage(self)
        self._operator = RemoteOperator(self)
        return self

    def restart(self) -> int:
        """Power the server's machine off and on (``POST /api/machine/restart``): cycle 0, the machine
        file's state. Returns the cycle counter."""
        try:
            self._cycle = int(self._api.post("/api/machine/restart")["cycle"])
        except ConflictError as exc:
            raise HarnessError(f"the CNC at {self.url} cannot be restarted: {exc}") from None
        if self._image is not None:
            self._image.took(-1, {})
        return self._cycle

    def stop(self) -> None:
        """Close the transports it opened and the connection; the server goes on running."""
        errors: list[BaseException] = []
        for transport in reversed(self._transports):
            try:
                transport.close()
            except Exception as exc:  # every door is closed, whatever one of them does
                errors.append(exc)
        self._transports.clear()
        self._api.close()
        if errors:
            raise errors[0]

    def __enter__(self) -> RemoteHarness:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def __repr__(self) -> str:
        return f"RemoteHarness({self.url!r}, machine {self.machine.get('name')!r}, cycle {self._cycle})"

    # --- the machine ----------------------------------------------------------------------------
    def _ready(self) -> None:
        if self._layout is None:
            raise HarnessError("the harness is not started (use it as a context manager, or start())")

    @property
    def runtime(self) -> Any:
        raise HarnessError(
            f"the CNC at {self.url} runs in another process: its runtime is not here (the harness of "
            "--hli-url offers what the HTTP API does; docs/testing.md)"
        )

    @property
    def layout(self) -> Layout:
        self._ready()
        assert self._layout is not None
        return self._layout

    @property
    def cycle(self) -> int:
        return self._cycle

    @property
    def t_a(self) -> float:
        return int(self.machine["t_a_us"]) / 1_000_000

    @property
    def image(self) -> RemoteImage:
        self._ready()
        assert self._image is not None
        return self._image

    @property
    def operator(self) -> RemoteOperator:
        self._ready()
        assert self._operator is not None
        return self._operator

    def _probe_port(self) -> RemoteOperator:
        return self.operator

    @property
    def comm_faults(self) -> RemoteCommFaults:
        return RemoteCommFaults(self)

    @property
    def http_url(self) -> str:
        return self.url

    # --- the clock --------------------------------------------------------------------------------
    def step(self, cycles: int = 1) -> int:
        """Run ``cycles`` cycles now; returns the machine's cycle counter."""
        self._ready()
        if cycles < 0:
            raise ValueError(f"cycles must be >= 0, got {cycles}")
        traced = list(dict.fromkeys(p for r in self._recordings for p in r.signals))
        if cycles == 1:  # the condition's signals too: its next reads need no request
            traced = list(dict.fromkeys([*traced, *self.image.watched]))[:MAX_TRACED]
        try:
            answer = self._api.post(
                "/api/step", {"cycles": cycles, "trace": traced} if traced else {"cycles": cycles}
            )
        except ConflictError as exc:
            raise StepRefusedError(str(exc)) from None
        self._cycle = int(answer["cycle"])
        trace = answer.get("trace")
        if trace is not None and trace["cycles"]:
            for recording in self._recordings:
                recording.take(trace)
            self.image.took(self._cycle, {p: column[-1] for p, column in trace["values"].items()})
        return self._cycle

    def trace(self, *signals: str) -> _RemoteRecording:
        """Record ``signals`` (ST paths) in every cycle from now on (each step traces them), until the
        recording's ``stop()`` or the end of a ``with`` block; ``recording.trace()[path]`` is an array."""
        self._ready()
        paths = [self.image._signal(s).st_path for s in signals]
        recording = _RemoteRecording(self, paths)
        self._recordings.append(recording)
        return recording

    def run_until(
        self,
        condition: Callable[[], object],
        max_cycles: int,
        *,
        plc: PlcTask | None = None,
        show: Sequence[str] = (),
        what: str | None = None,
    ) -> int:
        """Run cycles until ``condition()`` is true, as :meth:`Harness.run_until` (one PLC cycle, then one
        CNC cycle, with ``plc``); the report of a condition that never came shows the signals it read."""
        __tracebackhide__ = True
        self._ready()
        if max_cycles < 0:
            raise ValueError(f"max_cycles must be >= 0, got {max_cycles}")
        if plc is not None and plc.is_async:
            raise TypeError("run_until drives the PLC task synchronously: give it a synchronous transport")
        image = self.image
        shown = [image._signal(p).st_path for p in show]
        for path in self._channel_state_paths():
            image.watched.setdefault(path, None)
        for path in shown:
            image.watched.setdefault(path, None)
        start = self.cycle
        if condition():
            return 0
        frames: deque[tuple[int, dict[str, Value]]] = deque(maxlen=REPORT_CYCLES)
        for ran in range(1, max_cycles + 1):
            if plc is not None:
                plc.run_cycle()
            self.step(1)
            frames.append((self.cycle, dict(image._values)))
            if condition():
                return ran
        from hli_server.testing.report import frames_report

        raise ConditionNotMetError(
            frames_report(
                what=what or describe(condition),
                max_cycles=max_cycles,
                first_cycle=start + 1,
                layout=self.layout,
                frames=list(frames),
                show=[self.layout.signal(p) for p in shown],
                alarms=self.operator.alarms(history=0)["active"],
                plc=plc,
            )
        )

    def _channel_state_paths(self) -> list[str]:
        paths = []
        for index in range(len(self.layout.channels)):
            for leaf in ("program_state_r", "error_id_r"):
                path = f"gpCh[{index}]^bahn_state.{leaf}"
                if path in self.layout:
                    paths.append(path)
        return paths

    # --- programs: load_program and check of _Programs --------------------------------------------
    def _load(self, channel: int, text: str, name: str, files: dict[str, str]) -> ProgramLoaded:
        return self.operator.load_program(channel, text, name, files)  # the files go with the request

    def _check_machine(self) -> tuple[MachineConfig, list[str | os.PathLike[str]]]:
        """A check runs here, on the machine file the test names (the remote server is not asked)."""
        config = load_machine_spec(self._machine_spec, self._base)
        return config, [*self.program_dirs, *config.program_directories]

    # --- recording and replay -------------------------------------------------------------------------
    def record(self, path: str | os.PathLike[str], **options: Any) -> Any:
        raise HarnessError(
            f"hli.record is not offered for the CNC at {self.url}: its recorder writes on its own machine; "
            "start and fetch a recording through its HTTP API (docs/record-replay.md)"
        )

    def replay(self, path: str | os.PathLike[str], **options: Any) -> Any:
        """Replay a recording as a test, here (a machine of its own, built from the recording)."""
        __tracebackhide__ = True
        from hli_server.replay import Verdict, replay

        report = asyncio.run(replay(Path(os.fspath(path)), **options))
        if report.verdict is not Verdict.PASS:
            raise ReplayFailedError(report)
        return report

    @property
    def nc_files(self) -> Path:
        raise HarnessError(f"the CNC at {self.url} writes #MSG SAVE's files on its own machine")

    # --- doors ------------------------------------------------------------------------------------
    def serve(self, adapter: str, **options: Any) -> _RemoteDoor:
        """The server's door ``adapter`` (not opened from here: HarnessError when it does not run)."""
        port = self.ports.get(adapter)
        if port is None:
            raise HarnessError(
                f"the CNC at {self.url} has no {adapter} door (it serves {', '.join(self.ports) or 'none'}): "
                f"start it with the door (hli-server run --{adapter}-port N)"
            )
        return _RemoteDoor(adapter, port, {"word_order": "ABCD", "unit_id": 1, **options})

    def port(self, adapter: str) -> int:
        return self.serve(adapter).port

    def transport(self, kind: str = "modbus") -> Transport:
        """A PLC transport to the server (``"modbus"``, ``"ads"``; not ``"shm"``): closed with the harness."""
        self._ready()
        if kind == "shm":
            raise HarnessError(f"the CNC at {self.url} is remote: its shared-memory image is not here")
        transport = open_transport(cast("Any", self), kind)
        self._transports.append(transport)
        return transport
