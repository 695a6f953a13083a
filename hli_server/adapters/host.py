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
  recordings (issue 25; the HTTP API and the dashboard);
* ``faults`` (:class:`~hli_server.adapters.faults.CommFaults`): faults in the PLC's communication on
  demand, which the doors consult once per request (issue 25);
* ``step(n)`` for the stepped clock (``step_traced(n, signals)`` also returns chosen signals in every
  one of those cycles, :class:`Trace`), and ``on_cycle`` for work that must follow every published
  cycle (ADS device notifications).

The runtime implements these protocols (``hli_server/runtime/host.py``). ``make lint`` forbids
``hli_server.adapters`` to import ``hli_server.engine`` or ``hli_server.runtime``: everything an
adapter may use is named here.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from hli_server.adapters.faults import CommFaults
from schemas.events import Event
from schemas.layout import Direction, Layout, Signal, SignalType
from schemas.wire import Mode

if TYPE_CHECKING:
    import numpy.typing as npt

__all__ = [
    "LOOPBACK_NAMES",
    "Accepted",
    "AccessPolicy",
    "AdapterHost",
    "ConflictError",
    "EventFeed",
    "ImagePort",
    "InvalidRequestError",
    "LoggedEvent",
    "NotFoundError",
    "OperatorError",
    "OperatorPort",
    "RecorderPort",
    "StepRefusedError",
    "Trace",
    "Value",
]

Value = bool | int | float


LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1", "[::1]"})


@dataclass(frozen=True, slots=True)
class AccessPolicy:
    """Who may do what through the network doors (issue 12; ``hli-server run`` flags).

    * ``api_token``: state-changing HTTP requests need ``Authorization: Bearer <token>``
      (``--api-token`` or ``HLI_API_TOKEN``); ``run`` requires one when it binds beyond loopback,
      unless ``--insecure``.
    * ``read_only``: no network door accepts a write (HTTP state changes 403, Modbus writes exception
      0x01, ADS writes 0x704); the PLC on shared memory still works (``--read-only``).
    * ``allowed_hosts``: host names the HTTP ``Host`` header may carry besides loopback names and IP
      literals (DNS rebinding: a page of another site that resolves to this server is refused).
    * ``allowed_origins``: origins (``http://host:port``) whose pages may send state-changing requests
      besides the server's own (a page of another site in the user's browser is refused).
    """

    api_token: str | None = None
    read_only: bool = False
    allowed_hosts: tuple[str, ...] = ()
    allowed_origins: tuple[str, ...] = ()


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
        return {"seq": self.seq, **self.event.to_json()}


_DTYPE = {
    SignalType.BOOL: "bool",
    SignalType.DINT: "int32",
    SignalType.UDINT: "uint32",
    SignalType.LREAL: "float64",
}


@dataclass(frozen=True, slots=True)
class Trace:
    """Chosen signals in every cycle of a run (H-07): the per-cycle record of a scenario.

    ``cycles[k]`` is the cycle of the ``k``-th published cycle; ``values[st_path][k]`` the signal's
    value in it (CNC->PLC as published, PLC->CNC as latched). ``trace[st_path]`` is the column as a
    numpy array (``bool``, ``int32``, ``uint32`` or ``float64`` after the signal's type), ready for
    ``argmax``, ``diff`` and friends; :meth:`to_json` is what ``POST /api/step`` returns.
    """

    signals: tuple[str, ...]
    cycles: Sequence[int]
    values: Mapping[str, Sequence[Value]]
    types: Mapping[str, SignalType]

    def __len__(self) -> int:
        return len(self.cycles)

    def __getitem__(self, st_path: str) -> npt.NDArray[Any]:
        import numpy as np

        try:
            column = self.values[st_path]
        except KeyError:
            raise KeyError(f"{st_path!r} was not traced; the trace has {', '.join(self.signals)}") from None
        return np.asarray(column, dtype=_DTYPE[self.types[st_path]])

    def at(self, cycle: int) -> dict[str, Value]:
        """Every traced signal in ``cycle`` (KeyError when the trace does not hold that cycle)."""
        try:
            k = list(self.cycles).index(cycle)
        except ValueError:
            first, last = (self.cycles[0], self.cycles[-1]) if self.cycles else (None, None)
            raise KeyError(f"cycle {cycle} is not in the trace (cycles {first}..{last})") from None
        return {path: self.values[path][k] for path in self.signals}

    def to_json(self) -> dict[str, Any]:
        return {
            "signals": list(self.signals),
            "cycles": list(self.cycles),
            "values": {path: list(self.values[path]) for path in self.signals},
        }


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

    def load_program(self, channel: int, text: str, name: str = "program") -> dict[str, Any]: ...

    def select_program(self, channel: int, number: int) -> dict[str, Any]: ...

    def start(self, channel: int) -> Accepted: ...

    def reset(self, channel: int) -> Accepted: ...

    def feedhold(self, channel: int, on: bool) -> Accepted: ...

    def mode(self, channel: int, mode: Mode) -> Accepted: ...

    def override(self, channel: int, permille: int) -> Accepted: ...

    def jog(self, channel: int, axis: str, direction: int) -> Accepted: ...

    def probe(self, channel: int, on: bool) -> Accepted: ...

    def reference(self, axis: str) -> Accepted: ...

    def faults(self, axis: str) -> dict[str, Any]: ...

    def inject_faults(self, axis: str, **fields: float | bool) -> dict[str, Any]: ...

    def clear_faults(self, axis: str) -> dict[str, Any]: ...

    def soft_limits(self, axis: str) -> dict[str, Any]:
        """The software limits in effect and in the axis record [0.1 µm] (P-AXIS-00177/00178/00179)."""
        ...

    def set_soft_limits(self, axis: str, **values: int) -> dict[str, Any]:
        """Limits in effect until the next reset or mode change (the kernel's G98/G99) [0.1 µm]."""
        ...

    def update_axis_record(self, axis: str, **values: int) -> dict[str, Any]:
        """The axis record's limits [0.1 µm]: taken over at the next reset or mode change."""
        ...

    def snapshot(self) -> dict[str, Any]:
        """Channels, axes, active alarms: ``GET /api/state``."""
        ...

    def alarms(self, history: int = 200) -> dict[str, Any]:
        """``{"active": [...], "history": [...]}`` (the newest ``history`` of the history)."""
        ...

    def areas(self, channel: int) -> dict[str, Any]:
        """The channel's area table (FCT-C14) as ``check`` lists it."""
        ...

    def timing(self) -> dict[str, Any]:
        """Pacing statistics of the clock (``GET /api/timing``)."""
        ...

    # --- what the dashboard draws (issue 15); lengths in mm ----------------------------------
    def scene(self, channel: int) -> dict[str, Any]:
        """The channel's live scene, as :func:`hli_server.scene.build_scene` computes it for ``check
        --plot``: the area table, the recent trail of the setpoints (since the last program start, the
        newest points), the active alarms' refused block and violation point, the position now and the
        path the channel has decoded ahead. Unchanged inputs give the same (cached) object."""
        ...

    def programs(self, channel: int) -> list[dict[str, Any]]:
        """The channel's program table: ``[{"number", "name"}]`` (for ``select_program``)."""
        ...

    def collision_pairs(self) -> list[dict[str, Any]]:
        """The collision pairs (FCT-C3) now: ``{"master", "partner", "distance", "min_distance",
        "brake_master", "brake_partner", "monitoring", "stopped", "latched"}``."""
        ...


class RecorderPort(Protocol):
    """Recording the session (issue 25, docs/record-replay.md): one recording at a time, by name in the
    server's recording directory. Errors are :class:`OperatorError` subclasses."""

    def status(self) -> dict[str, Any]:
        """``{"recording", "file", "name", "started_cycle", "cycles", "bytes_written", ...}``."""
        ...

    def start(self, name: str | None = None) -> dict[str, Any]:
        """Start recording into ``<dir>/<name>.jsonl.gz`` (None: a name from the time); the status."""
        ...

    def stop(self) -> dict[str, Any]:
        """End the recording (flushed, closed); its final status."""
        ...

    def files(self) -> list[dict[str, Any]]:
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
        """Recording the session (issue 25)."""
        ...

    @property
    def faults(self) -> CommFaults:
        """Faults in the PLC's communication on demand (issue 25); the doors consult it per request."""
        ...

    async def step(self, cycles: int = 1) -> int:
        """Run ``cycles`` cycles now (stepped clock only; else :class:`StepRefusedError`); returns
        the machine's cycle counter."""
        ...

    async def step_traced(self, cycles: int, signals: Sequence[str]) -> Trace:
        """:meth:`step`, and the value of each of ``signals`` (ST paths) in every one of those
        cycles. An unknown path raises the layout's ``UnknownSignalError`` before any cycle runs."""
        ...

    def on_cycle(self, listener: Callable[[int], None]) -> Callable[[], None]:
        """Call ``listener(cycle)`` after every published cycle (keep it short). Returns the
        unsubscribe call."""
        ...
