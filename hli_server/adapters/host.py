"""The one door an adapter gets: the host (design.md, point 2).

An adapter never sees the runtime or the machine. It is handed an :class:`AdapterHost` with

* ``image`` (:class:`ImagePort`): the process image, the PLC's door. Modbus, ADS and the HTTP image
  endpoints read and write it exactly as a PLC attached to the shared memory does; a value reaches
  each of them the same way, from the same publish;
* ``operator`` (:class:`OperatorPort`): what an operator panel may do: load and select programs,
  start, reset, feedhold, mode, jog, override, referencing, fault injection, and the state to show.
  Requests are latched by the channel at the next cycle, as a PLC's are. The HTTP API and the
  dashboard use it; the PLC doors do not;
* ``events`` (:class:`EventFeed`): the typed events of ``schemas.events``, live and as a log;
* ``recorder`` (:class:`RecorderPort`): start and stop a recording of the session, list and fetch
  recordings (docs/record-replay.md; the HTTP API and the dashboard);
* ``faults`` (:class:`~hli_server.adapters.faults.CommFaults`): faults in the PLC's communication on
  demand, which the doors consult once per request (docs/record-replay.md);
* ``step(n)`` for the stepped clock (``step_traced(n, signals)`` also returns chosen signals in every
  one of those cycles, :class:`Trace`), and ``on_cycle`` for work that must follow every published
  cycle (ADS device notifications).

The runtime implements these protocols (``hli_server/runtime/operator_panel.py``). ``make lint`` forbids
``hli_server.adapters`` to import ``hli_server.engine`` or ``hli_server.runtime``: everything an
adapter may use is named here.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol

from hli_server.adapters.faults import CommFaults
from schemas.events import Event
from schemas.layout import Direction, Layout, Signal, SignalType
from schemas.results import (
    AlarmList,
    AreaTable,
    AxisFaults,
    CheckReport,
    CollisionPair,
    MachineState,
    ProbeDeviation,
    ProgramEntry,
    ProgramLoaded,
    ProgramSelected,
    ReadinessJson,
    RecorderStatus,
    RecordingFile,
    Scene,
    SoftLimits,
    Timing,
    TraceJson,
)
from schemas.wire import Mode

if TYPE_CHECKING:
    import numpy.typing as npt

__all__ = [
    "CHECK_MAX_CYCLES",
    "CHECK_MAX_ITERATIONS",
    "CHECK_MAX_TIMEOUT_S",
    "CHECK_TIMEOUT_S",
    "LOOPBACK_NAMES",
    "Accepted",
    "AccessPolicy",
    "AdapterHost",
    "CheckPort",
    "CheckTimeoutError",
    "ConflictError",
    "DoorView",
    "EventFeed",
    "ImagePort",
    "InvalidRequestError",
    "LoggedEvent",
    "NotFoundError",
    "OperatorError",
    "OperatorPort",
    "Readiness",
    "RecorderPort",
    "StepRefusedError",
    "Trace",
    "UnavailableError",
    "Value",
    "door_host",
]

Value = bool | int | float | str


LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1", "[::1]"})


@dataclass(frozen=True, slots=True)
class AccessPolicy:
    """Who may do what through the network doors (docs/reliability.md; ``hli-server run`` flags).

    * ``api_token``: state-changing HTTP requests need ``Authorization: Bearer <token>``
      (``--api-token`` or ``HLI_API_TOKEN``); ``run`` requires one when it binds beyond loopback,
      unless ``--insecure``.
    * ``read_only``: no network door accepts a write (HTTP state changes 403, Modbus writes exception
      0x01, ADS writes 0x704); the PLC on shared memory still works (``--read-only``).
    * ``allowed_hosts``: host names the HTTP ``Host`` header may carry besides loopback names and IP
      literals (DNS rebinding: a page of another site that resolves to this server is refused).
    * ``allowed_origins``: origins (``http://host:port``) whose pages may send state-changing requests
      besides the server's own (a page of another site in the user's browser is refused).

    * ``read_only_doors``: the doors (``http``, ``modbus``, ``ads``) that accept no write, the others do
      (``--read-only-door NAME``); :meth:`for_door` is the policy one door sees.

    The token guards the HTTP door only; Modbus and ADS are guarded by their allowlists of peer addresses
    (their ``allow`` option) or by being read-only (reliability.md, round 2, finding 8; ``hli-server run``
    refuses to open an unguarded write door beyond loopback without ``--insecure``).
    """

    api_token: str | None = None
    read_only: bool = False
    allowed_hosts: tuple[str, ...] = ()
    allowed_origins: tuple[str, ...] = ()
    read_only_doors: tuple[str, ...] = ()

    def for_door(self, door: str) -> AccessPolicy:
        """The policy door ``door`` applies: read-only if the server is, or if that door is."""
        if self.read_only or door not in self.read_only_doors:
            return self
        return AccessPolicy(
            api_token=self.api_token,
            read_only=True,
            allowed_hosts=self.allowed_hosts,
            allowed_origins=self.allowed_origins,
            read_only_doors=self.read_only_doors,
        )


class OperatorError(Exception):
    """An operator request the machine cannot take; the message says what and why."""


class NotFoundError(OperatorError, LookupError):
    """No such channel, axis, program or signal."""


class ConflictError(OperatorError):
    """Not now: a program runs, the channel is in the wrong mode, ..."""


class InvalidRequestError(OperatorError, ValueError):
    """A value the machine cannot take (out of range, unknown field)."""


class StepRefusedError(OperatorError):
    """``step()`` outside the stepped clock, or while the runtime does not run."""


class UnavailableError(OperatorError):
    """The engine cannot answer now (the doors process lost it, or it did not answer in time): 503."""


class CheckTimeoutError(OperatorError):
    """A program check did not finish within its wall-clock limit and was ended: 504."""


@dataclass(frozen=True, slots=True)
class Accepted:
    """An operator request the channel latches at ``effective_cycle``."""

    channel: int
    request: str
    cycle: int
    effective_cycle: int


@dataclass(frozen=True, slots=True)
class LoggedEvent:
    """An event with its sequence number in the runtime's log (``GET /api/events?since=seq``)."""

    seq: int
    event: Event

    def to_json(self) -> dict[str, Any]:
        """The event's fields (they differ per event type: ``schemas.events`` and docs/api.md list them)
        with its ``seq``."""
        return {"seq": self.seq, **self.event.to_json()}


_DTYPE = {
    SignalType.BOOL: "bool",
    SignalType.DINT: "int32",
    SignalType.UDINT: "uint32",
    SignalType.LREAL: "float64",
    SignalType.STRING: "object",
}


@dataclass(frozen=True, slots=True)
class Readiness:
    """Whether the server is ready: the clock runs and every door asked for listens (``GET /api/ready``,
    the health checks of the image and the compose bench).

    ``doors`` maps each adapter asked for (``http``, ``modbus``, ``ads``, ``mqtt``, ...) to whether it
    has started: a listening door listens, MQTT has its client task (it never waits for the broker).
    ``state`` is ``starting``, ``running`` or ``stopping``; ``ready`` is ``running`` with every door up.
    ``ports`` maps each door that listens on TCP to its port (what a client that knows only the HTTP
    address needs to reach the others: the pytest plugin's ``--hli-url``)."""

    ready: bool
    state: Literal["starting", "running", "stopping"]
    doors: Mapping[str, bool]
    ports: Mapping[str, int] = field(default_factory=dict)

    def to_json(self) -> ReadinessJson:
        waiting = [name for name, up in self.doors.items() if not up]
        return {
            "ready": self.ready,
            "state": self.state,
            "doors": dict(self.doors),
            "waiting_for": waiting,
            "ports": dict(self.ports),
        }


class Trace:
    """Chosen signals in every cycle of a run (H-07): the per-cycle record of a scenario.

    ``trace[st_path]`` is the column as a numpy array (``bool``, ``int32``, ``uint32`` or ``float64``
    after the signal's type, ``object`` holding ``str`` for a V.E. STRING; read-only), ready for
    ``argmax``, ``diff`` and friends; ``cycles[k]`` is the cycle of the ``k``-th published cycle and
    ``values[st_path][k]`` the signal's value in it (CNC->PLC as published, PLC->CNC as latched), as
    Python lists made when asked for. The columns are kept as arrays
    (a value takes its own width, not a Python object): :meth:`json_chunks` writes ``POST /api/step``'s
    answer from them a slice at a time, :meth:`to_json` is the same as one dictionary.
    """

    __slots__ = ("_columns", "_cycles", "signals", "types")

    def __init__(
        self,
        signals: Sequence[str],
        cycles: Sequence[int] | npt.NDArray[Any],
        values: Mapping[str, Sequence[Value] | npt.NDArray[Any]],
        types: Mapping[str, SignalType],
    ) -> None:
        import numpy as np

        self.signals: tuple[str, ...] = tuple(signals)
        self.types: dict[str, SignalType] = {p: types[p] for p in self.signals}
        self._cycles = np.asarray(cycles, dtype=np.int64)
        self._cycles.flags.writeable = False
        self._columns: dict[str, npt.NDArray[Any]] = {}
        for path in self.signals:
            column = np.asarray(values[path], dtype=_DTYPE[self.types[path]])
            column.flags.writeable = False
            self._columns[path] = column

    @property
    def cycles(self) -> list[int]:
        out: list[int] = self._cycles.tolist()
        return out

    @property
    def values(self) -> dict[str, list[Value]]:
        return {path: column.tolist() for path, column in self._columns.items()}

    def __len__(self) -> int:
        return len(self._cycles)

    def __getitem__(self, st_path: str) -> npt.NDArray[Any]:
        try:
            return self._columns[st_path]
        except KeyError:
            raise KeyError(f"{st_path!r} was not traced; the trace has {', '.join(self.signals)}") from None

    def at(self, cycle: int) -> dict[str, Value]:
        """Every traced signal in ``cycle`` (KeyError when the trace does not hold that cycle)."""
        import numpy as np

        found = np.flatnonzero(self._cycles == cycle)
        if not len(found):
            first, last = (int(self._cycles[0]), int(self._cycles[-1])) if len(self._cycles) else (None, None)
            raise KeyError(f"cycle {cycle} is not in the trace (cycles {first}..{last})")
        k = int(found[0])
        return {path: self._columns[path].item(k) for path in self.signals}

    def to_json(self) -> TraceJson:
        return {"signals": list(self.signals), "cycles": self.cycles, "values": self.values}

    def json_chunks(self, slice_size: int = 65_536) -> Iterator[bytes]:
        """:meth:`to_json` as JSON text in pieces of at most ``slice_size`` values: the answer of a long
        trace is written without the whole of it ever being Python objects or one string."""

        def array(column: npt.NDArray[Any]) -> Iterator[bytes]:
            yield b"["
            for start in range(0, len(column), slice_size):
                part = column[start : start + slice_size].tolist()
                text = json.dumps(part, allow_nan=True, separators=(",", ":"))
                if "N" in text or "I" in text:  # NaN, Infinity: named, as every answer does
                    text = json.dumps([_finite_or_name(v) for v in part], separators=(",", ":"))
                yield (b"," if start else b"") + text[1:-1].encode("ascii")
            yield b"]"

        yield b'{"signals":' + json.dumps(list(self.signals)).encode("ascii") + b',"cycles":'
        yield from array(self._cycles)
        yield b',"values":{'
        for i, path in enumerate(self.signals):
            yield (b"," if i else b"") + json.dumps(path).encode("ascii") + b":"
            yield from array(self._columns[path])
        yield b"}}"

    def __repr__(self) -> str:
        return f"Trace({len(self)} cycles of {', '.join(self.signals)})"


def _finite_or_name(value: Value) -> Value | str:
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    return value


class ImagePort(Protocol):
    """The process image as the PLC doors see it (``hli_server.image.ProcessImage`` and the
    buffer-backed image implement it)."""

    @property
    def name(self) -> str: ...

    @property
    def layout(self) -> Layout: ...

    @property
    def cycle(self) -> int:
        """Cycle of the newest publish."""
        ...

    @property
    def publish_count(self) -> int: ...

    def publish_counter(self) -> Callable[[], int]:
        """:attr:`publish_count` as a function, for a door that asks it at every request (whether its copy
        of the CNC->PLC half is still the newest): as cheap as the image can make it (no Python frame)."""
        ...

    def read(self, st_path: str) -> Value:
        """A field by ST path: PLC->CNC from the live half, CNC->PLC from the newest publish."""
        ...

    def write(self, st_path: str, value: object) -> None:
        """A PLC->CNC field by ST path (latched at the next cycle); CNC->PLC fields are refused."""
        ...

    def write_signal(self, signal: Signal, value: object) -> None: ...

    def write_bytes(self, offset: int, data: bytes) -> None:
        """Raw write into the PLC->CNC half: whole fields only, every value checked first."""
        ...

    def read_half(self, direction: Direction) -> bytes:
        """A copy of one half: PLC->CNC as it is now, CNC->PLC as last published."""
        ...

    def snapshot(self) -> tuple[int, bytes]:
        """``(cycle, CNC->PLC half)`` of the newest consistent publish."""
        ...


class OperatorPort(Protocol):
    """The operator panel's door (the HTTP API, the dashboard, the test harness).

    Every method raises :class:`OperatorError` subclasses with a message for people:
    :class:`NotFoundError` (unknown channel, axis, program), :class:`ConflictError` (not in this
    state), :class:`InvalidRequestError` (a value out of range)."""

    @property
    def cycle(self) -> int: ...

    @property
    def time_s(self) -> float: ...

    @property
    def t_a_us(self) -> int: ...

    @property
    def machine_name(self) -> str: ...

    def channel_numbers(self) -> list[int]: ...

    def axis_names(self, channel: int | None = None) -> list[str]:
        """All axes, or those of one channel, in their order."""
        ...

    def load_program(
        self, channel: int, text: str, name: str = "program", files: Mapping[str, str] | None = None
    ) -> ProgramLoaded:
        """Load ``text`` as the channel's program; ``files`` (name -> text) are its subprograms and
        cycles, found by ``L name`` before the program directories (they replace the files of the
        channel's previous load). InvalidRequestError for a file name that leaves its directory
        (``..``, absolute), too many or too large files; ConflictError while a program runs."""
        ...

    def select_program(self, channel: int, number: int) -> ProgramSelected: ...

    def start(self, channel: int) -> Accepted: ...

    def reset(self, channel: int) -> Accepted: ...

    def feedhold(self, channel: int, on: bool) -> Accepted: ...

    def mode(self, channel: int, mode: Mode) -> Accepted: ...

    def override(self, channel: int, permille: int) -> Accepted: ...

    def jog(self, channel: int, axis: str, direction: int) -> Accepted: ...

    def probe(self, channel: int, on: bool) -> Accepted: ...

    def probe_deviation(self, channel: int) -> ProbeDeviation:
        """The simulated workpiece's deviation per axis [0.1 µm] (the built-in measuring cycles' probe)."""
        ...

    def set_probe_deviation(self, channel: int, values: dict[str, int]) -> ProbeDeviation:
        """Set it for the named axes [0.1 µm]; an axis with a V.E. variable gets the variable written."""
        ...

    def reference(self, axis: str) -> Accepted: ...

    def faults(self, axis: str) -> AxisFaults: ...

    def inject_faults(self, axis: str, **fields: float | bool) -> AxisFaults: ...

    def clear_faults(self, axis: str) -> AxisFaults: ...

    def soft_limits(self, axis: str) -> SoftLimits:
        """The software limits in effect and in the axis record [0.1 µm] (P-AXIS-00177/00178/00179)."""
        ...

    def set_soft_limits(self, axis: str, **values: int) -> SoftLimits:
        """Limits in effect until the next reset or mode change (the kernel's G98/G99) [0.1 µm]."""
        ...

    def update_axis_record(self, axis: str, **values: int) -> SoftLimits:
        """The axis record's limits [0.1 µm]: taken over at the next reset or mode change."""
        ...

    def snapshot(self) -> MachineState:
        """Channels, axes, active alarms, the V.E. variables (``external``): ``GET /api/state``."""
        ...

    def alarms(self, history: int = 200) -> AlarmList:
        """``{"active": [...], "history": [...]}`` (the newest ``history`` of the history)."""
        ...

    def areas(self, channel: int) -> AreaTable:
        """The channel's area table (FCT-C14) as ``check`` lists it."""
        ...

    def timing(self) -> Timing:
        """Pacing statistics of the clock (``GET /api/timing``)."""
        ...

    # --- what the dashboard draws (docs/dashboard.md); lengths in mm ----------------------------------
    def scene(self, channel: int) -> Scene:
        """The channel's live scene, as :func:`hli_server.scene.build_scene` computes it for ``check
        --plot``: the area table, the recent trail of the setpoints (since the last program start, the
        newest points), the active alarms' refused block and violation point, the position now and the
        path the channel has decoded ahead. Unchanged inputs give the same (cached) object."""
        ...

    def programs(self, channel: int) -> list[ProgramEntry]:
        """The channel's program table: ``[{"number", "name"}]`` (for ``select_program``)."""
        ...

    def collision_pairs(self) -> list[CollisionPair]:
        """The collision pairs (FCT-C3) now: ``{"master", "partner", "distance", "min_distance",
        "brake_master", "brake_partner", "monitoring", "stopped", "latched"}``."""
        ...


CHECK_MAX_CYCLES = 10_000_000
"""A check through the API stops here unless the request says otherwise (2.8 h of machine time at 1 ms)."""
CHECK_MAX_ITERATIONS = 1_000_000
"""A geometry check through the API stops after this many loop iterations (``check``'s default)."""
CHECK_TIMEOUT_S = 120.0
"""Wall-clock limit of one check through the API unless the request says otherwise [s]."""
CHECK_MAX_TIMEOUT_S = 600.0


class CheckPort(Protocol):
    """Checking a program offline on a fresh machine of the server's machine file, as ``hli-server check``
    does (N-10; ``POST /api/check``): the engine's ``ProgramCheck``, in a process of its own, so that
    the running machine is never touched and its clock never waits."""

    async def check(
        self,
        text: str,
        *,
        name: str = "program",
        files: Mapping[str, str] | None = None,
        channel: int = 1,
        geometry_only: bool = False,
        max_cycles: int = CHECK_MAX_CYCLES,
        max_iterations: int = CHECK_MAX_ITERATIONS,
        timeout_s: float = CHECK_TIMEOUT_S,
        presets: Mapping[str, bool | int | float | str] | None = None,
    ) -> CheckReport:
        """``check --format json``'s report with ``program``, ``status`` (``ok``, ``stopped``, ``capped``)
        and ``exit_code``; ``presets`` are V.E. values before the start (``check --set``). NotFoundError
        (channel), InvalidRequestError (files, presets), UnavailableError (busy), CheckTimeoutError (the
        wall-clock limit)."""
        ...


class RecorderPort(Protocol):
    """Recording the session (docs/record-replay.md): one recording at a time, by name in the
    server's recording directory. Errors are :class:`OperatorError` subclasses."""

    def status(self) -> RecorderStatus:
        """``{"recording", "file", "name", "started_cycle", "cycles", "bytes_written", ...}``."""
        ...

    def start(self, name: str | None = None) -> RecorderStatus:
        """Start recording into ``<dir>/<name>.jsonl.gz`` (None: a name from the time); the status."""
        ...

    def stop(self) -> RecorderStatus:
        """End the recording (flushed, closed); its final status."""
        ...

    def files(self) -> list[RecordingFile]:
        """The recordings in the directory: ``[{"name", "bytes", "modified", "recording"}]``."""
        ...

    def file(self, name: str) -> Path:
        """The path of one of them (:class:`NotFoundError` when there is none)."""
        ...


class EventFeed(Protocol):
    """The typed events (``schemas.events``): live, and the runtime's log."""

    def subscribe(self, listener: Callable[[Event], None]) -> Callable[[], None]:
        """Call ``listener`` for every event from now on, synchronously inside the cycle (keep it
        short: queue the event, do the I/O in a task of your own). Returns the unsubscribe call."""
        ...

    def since(self, seq: int = 0, limit: int = 1000) -> tuple[Sequence[LoggedEvent], int]:
        """Logged events with ``seq`` greater than ``seq`` (oldest first, at most ``limit``) and the
        newest sequence number."""
        ...


class DoorView:
    """``host`` as door ``door`` sees it: the same image, operator, events and clock, the door's own policy
    (:meth:`AccessPolicy.for_door`). The runtime starts each adapter with one."""

    def __init__(self, host: AdapterHost, door: str) -> None:
        self._host = host
        self._policy = host.policy.for_door(door)

    @property
    def image(self) -> ImagePort:
        return self._host.image

    @property
    def operator(self) -> OperatorPort:
        return self._host.operator

    @property
    def events(self) -> EventFeed:
        return self._host.events

    @property
    def clock(self) -> str:
        return self._host.clock

    @property
    def bind(self) -> str:
        return self._host.bind

    @property
    def policy(self) -> AccessPolicy:
        return self._policy

    @property
    def recorder(self) -> RecorderPort:
        return self._host.recorder

    @property
    def checker(self) -> CheckPort:
        return self._host.checker

    @property
    def faults(self) -> CommFaults:
        return self._host.faults

    async def step(self, cycles: int = 1) -> int:
        return await self._host.step(cycles)

    async def step_traced(self, cycles: int, signals: Sequence[str]) -> Trace:
        return await self._host.step_traced(cycles, signals)

    async def restart(self) -> int:
        return await self._host.restart()

    def on_cycle(self, listener: Callable[[int], None]) -> Callable[[], None]:
        return self._host.on_cycle(listener)

    def readiness(self) -> Readiness:
        return self._host.readiness()


def door_host(host: AdapterHost, door: str) -> AdapterHost:
    """The host door ``door`` is started with (its own policy where it differs)."""
    if host.policy.for_door(door) is host.policy:
        return host
    return DoorView(host, door)


class AdapterHost(Protocol):
    """What the runtime hands an adapter's ``start()``."""

    @property
    def image(self) -> ImagePort: ...

    @property
    def operator(self) -> OperatorPort: ...

    @property
    def events(self) -> EventFeed: ...

    @property
    def clock(self) -> str:
        """``realtime``, ``stepped`` or ``free``."""
        ...

    @property
    def bind(self) -> str:
        """The address the network doors listen on (``--bind``)."""
        ...

    @property
    def policy(self) -> AccessPolicy:
        """Who may do what through the network doors."""
        ...

    @property
    def recorder(self) -> RecorderPort:
        """Recording the session (docs/record-replay.md)."""
        ...

    @property
    def checker(self) -> CheckPort:
        """Checking programs offline (N-10, ``POST /api/check``)."""
        ...

    @property
    def faults(self) -> CommFaults:
        """Faults in the PLC's communication on demand (docs/record-replay.md); the doors consult it per
        request."""
        ...

    async def step(self, cycles: int = 1) -> int:
        """Run ``cycles`` cycles now (stepped clock only; else :class:`StepRefusedError`); returns
        the machine's cycle counter."""
        ...

    async def step_traced(self, cycles: int, signals: Sequence[str]) -> Trace:
        """:meth:`step`, and the value of each of ``signals`` (ST paths) in every one of those
        cycles. An unknown path raises the layout's ``UnknownSignalError`` before any cycle runs."""
        ...

    async def restart(self) -> int:
        """Power the machine off and on (stepped clock only, no recording running; else
        :class:`StepRefusedError`): the machine file's machine at cycle 0, between two steps. Returns the
        cycle counter."""
        ...

    def on_cycle(self, listener: Callable[[int], None]) -> Callable[[], None]:
        """Call ``listener(cycle)`` after every published cycle (keep it short). Returns the
        unsubscribe call."""
        ...

    def readiness(self) -> Readiness:
        """Whether every door asked for listens and the clock runs (``GET /api/ready``)."""
        ...
