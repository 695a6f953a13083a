"""Faults in the PLC's communication, on demand (docs/record-replay.md, B-03): a policy the doors consult.

How does a PLC program react when the CNC link hiccups? :class:`CommFaults` holds the faults a user
asked for (``POST /api/comm/faults``, the pytest plugin's ``hli.comm_faults``), each with its end: a
duration (wall clock, ``duration_ms``), a number of cycles (``cycles``) or a count (``count``), or
earlier by ``DELETE`` / :meth:`CommFaults.reset`.

=============== ============== =======================================================================
kind            door           what the PLC sees
=============== ============== =======================================================================
``delay``       modbus, ads    each matching request's answer ``delay_ms`` later (the request is served
                               at once: a write lands, a read reads the image of that moment)
``drop``        modbus, ads    a connection is closed (reset) instead of answering its request after
                               ``after`` requests (counted per connection from when the fault began)
``error``       modbus, ads    matching requests get the exception ``code`` (Modbus: 1, 2, 3, 4, 10 or
                               11) or the ADS error ``code`` instead of their answer; matching: an
                               address range (``first``..``last``: Modbus address, ADS index offset),
                               a Modbus ``table`` or an ADS ``index_group``
``stall``       shm            the CNC->PLC half is not published for ``cycles`` cycles: every door
                               (shared memory, Modbus, ADS) sees the same old cycle counter and values;
                               the engine runs on and latches the PLC's writes
``disconnect``  mqtt           the MQTT adapter drops its broker connection (abruptly: the broker sends
                               the Will ``offline``) and stays away until the fault ends; the events of
                               that time are queued as for any lost broker (docs/mqtt.md)
=============== ============== =======================================================================

``count`` counts what the fault does: answers delayed, answers replaced by the error, connections
dropped, and must be given for ``drop`` (or defaults to 1). Everything is bounded
(:data:`MAX_ACTIVE` faults at once, ``delay_ms`` up to 10 s, durations up to an hour, counts up to a
million): a fault can delay an answer, never the clock, and never hangs a connection for longer than
its delay.

The doors: each connection takes a :class:`ConnectionGate` (``faults.gate(door, transport)``) and asks it
once per request (:meth:`ConnectionGate.modbus`, :meth:`ConnectionGate.ads`): None serves the request
as usual; bytes are the fault's answer (the exception or ADS error reply; ``b""`` when the connection
was dropped). Delays are done by the gate's transport, a thin wrapper that holds the answers back. The
runtime asks :meth:`CommFaults.publish_stalled` once per cycle. With the doors in a process of their own
(``hli-server run``'s default) that process holds a mirror of the table (:meth:`CommFaults.load`) and
reports what ended there by count (:meth:`CommFaults.subscribe`).

Every change (a fault set, a fault ended, and why) goes to the listeners: the session recorder keeps
it as an input of the recording, so that a replay reproduces a stall (the effects of the doors' faults
are in the PLC->CNC half the engine latched, which the recording holds anyway).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import struct
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Final, Literal, TypedDict

from pydantic import BaseModel, ConfigDict, Field, model_validator

from hli_server.codecs.ads import AmsPacket, encode_response, error_reply_payload
from hli_server.codecs.modbus_frames import ExceptionCode, Frame, encode_adu, encode_exception
from schemas.results import CommFault, CommFaultChange, CommFaultLogged

__all__ = [
    "MAX_ACTIVE",
    "ActiveFault",
    "CommFaults",
    "ConnectionGate",
    "Door",
    "FaultError",
    "FaultKind",
    "FaultMirror",
    "FaultSpec",
]

logger = logging.getLogger(__name__)

MAX_ACTIVE: Final = 16
"""Faults active at once; one more is refused (end one, or reset)."""
MAX_DELAY_MS: Final = 10_000
MAX_DURATION_MS: Final = 3_600_000
MAX_CYCLES: Final = 3_600_000
MAX_COUNT: Final = 1_000_000
MAX_HELD_BYTES: Final = 4 * 1024 * 1024
"""Answers one connection's delay may hold back; beyond, the door's own back-pressure pauses it."""


class FaultError(ValueError):
    """A fault that cannot be set (too many, an unknown id); the message says why."""


class Door(StrEnum):
    MODBUS = "modbus"
    ADS = "ads"
    SHM = "shm"
    MQTT = "mqtt"


class FaultKind(StrEnum):
    DELAY = "delay"
    DROP = "drop"
    ERROR = "error"
    STALL = "stall"
    DISCONNECT = "disconnect"


_DOORS: Final = {
    FaultKind.DELAY: (Door.MODBUS, Door.ADS),
    FaultKind.DROP: (Door.MODBUS, Door.ADS),
    FaultKind.ERROR: (Door.MODBUS, Door.ADS),
    FaultKind.STALL: (Door.SHM,),
    FaultKind.DISCONNECT: (Door.MQTT,),
}
_MODBUS_CODES: Final = frozenset(int(c) for c in ExceptionCode)
_MODBUS_TABLES: Final = {
    1: "coils",
    5: "coils",
    15: "coils",
    2: "discrete_inputs",
    3: "holding_registers",
    6: "holding_registers",
    16: "holding_registers",
    23: "holding_registers",
    4: "input_registers",
}
ModbusTableName = Literal["coils", "discrete_inputs", "holding_registers", "input_registers"]


class FaultSpec(BaseModel):
    """One fault as asked for (``POST /api/comm/faults``); see the module docstring."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    kind: FaultKind = Field(description="delay, drop, error (Modbus/ADS), stall (shm), disconnect (mqtt)")
    door: Door | None = Field(
        default=None, description="modbus or ads for delay/drop/error; stall is shm's, disconnect mqtt's"
    )
    delay_ms: int | None = Field(default=None, ge=1, le=MAX_DELAY_MS, description="delay: ms per answer")
    after: int | None = Field(
        default=None,
        ge=0,
        le=MAX_COUNT,
        description="drop: requests a connection is answered before it is dropped",
    )
    code: int | None = Field(
        default=None,
        ge=1,
        le=0xFFFF_FFFF,
        description="error: the Modbus exception code (1, 2, 3, 4, 10, 11) or the ADS error code",
    )
    first: int | None = Field(
        default=None,
        ge=0,
        le=0xFFFF_FFFF,
        description="error/delay: first address (Modbus) or index offset (ADS)",
    )
    last: int | None = Field(default=None, ge=0, le=0xFFFF_FFFF, description="... and the last (inclusive)")
    table: ModbusTableName | None = Field(default=None, description="Modbus: only requests to this table")
    index_group: int | None = Field(
        default=None, ge=0, le=0xFFFF_FFFF, description="ADS: only this index group"
    )
    duration_ms: int | None = Field(
        default=None, ge=1, le=MAX_DURATION_MS, description="ends after this long"
    )
    cycles: int | None = Field(default=None, ge=1, le=MAX_CYCLES, description="ends after this many cycles")
    count: int | None = Field(
        default=None,
        ge=1,
        le=MAX_COUNT,
        description="ends after acting this many times (answers, connections)",
    )

    @model_validator(mode="after")
    def _consistent(self) -> FaultSpec:
        kind = self.kind
        doors = _DOORS[kind]
        door = self.door if self.door is not None else (doors[0] if len(doors) == 1 else None)
        if door is None:
            raise ValueError(f"{kind}: give the door: {' or '.join(doors)}")
        if door not in doors:
            raise ValueError(f"{kind} is a fault of {' or '.join(doors)}, not of {door}")
        object.__setattr__(self, "door", door)
        own = {
            FaultKind.DELAY: {"delay_ms"},
            FaultKind.DROP: {"after"},
            FaultKind.ERROR: {"code"},
            FaultKind.STALL: set(),
            FaultKind.DISCONNECT: set(),
        }[kind]
        for name in own:
            if getattr(self, name) is None:
                raise ValueError(f"{kind}: give {name}")
        for name in ("delay_ms", "after", "code"):
            if name not in own and getattr(self, name) is not None:
                raise ValueError(f"{name} belongs to another kind of fault than {kind}")
        ranged = kind in (FaultKind.DELAY, FaultKind.ERROR)
        for name in ("first", "last", "table", "index_group"):
            if getattr(self, name) is not None and not ranged:
                raise ValueError(f"{name}: only delay and error faults match addresses")
        if self.table is not None and door is not Door.MODBUS:
            raise ValueError(
                "table: a Modbus table (coils, discrete_inputs, holding_registers, input_registers)"
            )
        if self.index_group is not None and door is not Door.ADS:
            raise ValueError("index_group: only ADS requests have one")
        if (self.first is None) != (self.last is None):
            raise ValueError("an address range needs both first and last")
        if self.first is not None and self.last is not None:
            if self.last < self.first:
                raise ValueError(f"address range {self.first}..{self.last}: last is before first")
            if door is Door.MODBUS and self.last > 0xFFFF:
                raise ValueError("a Modbus address is 0..65535")
        if kind is FaultKind.ERROR and door is Door.MODBUS and self.code not in _MODBUS_CODES:
            raise ValueError(f"Modbus exception code {self.code}: use one of {sorted(_MODBUS_CODES)}")
        ends = [n for n in ("duration_ms", "cycles", "count") if getattr(self, n) is not None]
        if kind is FaultKind.STALL:
            if ends != ["cycles"]:
                raise ValueError("stall: give cycles (how many cycles the publish stalls), nothing else")
        elif kind is FaultKind.DISCONNECT:
            if len(ends) != 1 or ends[0] == "count":
                raise ValueError("disconnect: give duration_ms or cycles (how long the broker stays away)")
        elif kind is FaultKind.DROP:
            if len(ends) > 1:
                raise ValueError(f"give one end of the fault, not {' and '.join(ends)}")
        elif len(ends) != 1:
            raise ValueError(
                f"{kind}: give one end of the fault: duration_ms, cycles or count"
                + (f", not {' and '.join(ends)}" if ends else "")
            )
        return self

    def matches_modbus(self, pdu: bytes) -> bool:
        if self.first is None and self.table is None:
            return True
        fc = pdu[0] if pdu else 0
        if self.table is not None and _MODBUS_TABLES.get(fc) != self.table:
            return False
        if self.first is None or self.last is None:
            return True
        for start, count in _modbus_spans(pdu):
            if start <= self.last and start + max(count, 1) - 1 >= self.first:
                return True
        return False

    def matches_ads(self, packet: AmsPacket) -> bool:
        if self.first is None and self.index_group is None:
            return True
        address = _ads_address(packet)
        if address is None:
            return False
        group, offset = address
        if self.index_group is not None and group != self.index_group:
            return False
        if self.first is None or self.last is None:
            return True
        return self.first <= offset <= self.last

    def describe(self) -> str:
        what = {
            FaultKind.DELAY: f"{self.door} answers {self.delay_ms} ms late",
            FaultKind.DROP: f"{self.door} connection dropped after {self.after} requests",
            FaultKind.ERROR: f"{self.door} error {self.code:#x}" if self.code is not None else "",
            FaultKind.STALL: f"shared-memory publish stalled for {self.cycles} cycles",
            FaultKind.DISCONNECT: "MQTT disconnected",
        }[self.kind]
        if self.first is not None:
            what += f" for addresses {self.first}..{self.last}"
        return what


def _modbus_spans(pdu: bytes) -> list[tuple[int, int]]:
    fc = pdu[0] if pdu else 0
    if len(pdu) < 5:
        return []
    address, count = struct.unpack_from(">HH", pdu, 1)
    if fc in (5, 6):
        return [(address, 1)]
    if fc == 23 and len(pdu) >= 9:
        write_address, write_count = struct.unpack_from(">HH", pdu, 5)
        return [(address, count), (write_address, write_count)]
    return [(address, count)]


_ADDRESSED: Final = frozenset({2, 3, 6, 9})
"""Read, Write, AddDeviceNotification, ReadWrite: the ADS commands with index group and offset."""


def _ads_address(packet: AmsPacket) -> tuple[int, int] | None:
    if packet.header.command not in _ADDRESSED or len(packet.data) < 8:
        return None
    group, offset = struct.unpack_from("<II", packet.data, 0)
    return group, offset


@dataclass(slots=True, eq=False)
class ActiveFault:
    """A fault in effect: its spec, when it began, how often it acted."""

    id: int
    spec: FaultSpec
    started_cycle: int
    started_at: float
    """time.monotonic() when it began (the same clock in every process of the machine)."""
    expires_at: float | None = None
    ends_cycle: int | None = None
    used: int = 0
    ended: str | None = None

    def to_json(self, now: float | None = None) -> CommFault:
        now = time.monotonic() if now is None else now
        spec = self.spec
        left_ms = None if self.expires_at is None else max(0, round((self.expires_at - now) * 1000))
        count = spec.count if spec.kind is not FaultKind.DROP else (spec.count or 1)
        out: CommFault = {
            "id": self.id,
            **spec.model_dump(mode="json", exclude_none=True),  # type: ignore[typeddict-item]  # the spec's keys
            "door": str(spec.door),
            "description": spec.describe(),
            "started_cycle": self.started_cycle,
            "ends_cycle": self.ends_cycle,
            "left_ms": left_ms,
            "used": self.used,
            "left": None if count is None else max(0, count - self.used),
        }
        return out

    def mirror(self) -> FaultMirror:
        """What a mirror in another process needs (:meth:`CommFaults.load`)."""
        return {
            "id": self.id,
            "spec": self.spec.model_dump(mode="json", exclude_none=True),
            "started_cycle": self.started_cycle,
            "started_at": self.started_at,
            "expires_at": self.expires_at,
            "used": self.used,
        }


class FaultMirror(TypedDict):
    """A fault as the mirror in another process takes it (:meth:`CommFaults.load`): the spec's fields given,
    and the times in ``time.monotonic()`` seconds."""

    id: int
    spec: dict[str, Any]  # FaultSpec.model_dump(mode="json"): validated again by the mirror
    started_cycle: int
    started_at: float
    expires_at: float | None
    used: int


Listener = Callable[[CommFaultChange], None]


class CommFaults:
    """The faults in effect and their ends; consulted by the doors and once per cycle by the runtime.

    ``cycle`` tells the machine's cycle (the runtime's; a mirror in the doors process has none)."""

    def __init__(self, cycle: Callable[[], int] | None = None) -> None:
        self._cycle = cycle or (lambda: 0)
        self._faults: dict[int, ActiveFault] = {}
        self._ids = itertools.count(1)
        self._listeners: list[Listener] = []
        self._timers: dict[int, asyncio.TimerHandle] = {}
        self.active = False
        """True while any fault is in effect: the doors' fast path reads only this."""
        self._by_door: dict[Door, tuple[ActiveFault, ...]] = {}
        self._cycle_bound = False
        self.history: deque[CommFaultLogged] = deque(maxlen=200)

    # --- what users do --------------------------------------------------------------------------
    def add(self, spec: FaultSpec | dict[str, Any]) -> ActiveFault:  # a dict: JSON that FaultSpec validates
        """Set a fault now (FaultError when :data:`MAX_ACTIVE` are in effect); returns it."""
        spec = spec if isinstance(spec, FaultSpec) else FaultSpec.model_validate(spec)
        self._expire(time.monotonic())
        if len(self._faults) >= MAX_ACTIVE:
            raise FaultError(f"{MAX_ACTIVE} faults are in effect already: end one (DELETE) or reset them all")
        now = time.monotonic()
        cycle = self._cycle()
        fault = ActiveFault(id=next(self._ids), spec=spec, started_cycle=cycle + 1, started_at=now)
        if spec.duration_ms is not None:
            fault.expires_at = now + spec.duration_ms / 1000
        if spec.cycles is not None:
            fault.ends_cycle = cycle + spec.cycles
        self._faults[fault.id] = fault
        self._index()
        if fault.expires_at is not None:
            self._arm_timer(fault)
        logger.warning("communication fault %d set: %s", fault.id, spec.describe())
        self._tell({"fault": "set", "id": fault.id, "spec": spec.model_dump(mode="json", exclude_none=True)})
        return fault

    def end(self, fault_id: int, reason: str = "api") -> ActiveFault:
        fault = self._faults.pop(fault_id, None)
        if fault is None:
            have = ", ".join(str(i) for i in self._faults) or "none"
            raise FaultError(f"no communication fault {fault_id} is in effect (in effect: {have})")
        fault.ended = reason
        timer = self._timers.pop(fault_id, None)
        if timer is not None:
            timer.cancel()
        self._index()
        logger.warning("communication fault %d ended (%s): %s", fault_id, reason, fault.spec.describe())
        self._tell({"fault": "end", "id": fault_id, "reason": reason})
        return fault

    def reset(self, reason: str = "reset") -> int:
        """End every fault; returns how many were in effect."""
        ids = list(self._faults)
        for fault_id in ids:
            self.end(fault_id, reason)
        return len(ids)

    def table(self) -> list[CommFault]:
        now = time.monotonic()
        self._expire(now)
        return [f.to_json(now) for f in self._faults.values()]

    def get(self, fault_id: int) -> ActiveFault | None:
        return self._faults.get(fault_id)

    def subscribe(self, listener: Listener) -> Callable[[], None]:
        """``listener({"fault": "set"|"end", "id", ...})`` for every change. Returns the unsubscribe call."""
        self._listeners.append(listener)

        def unsubscribe() -> None:
            with contextlib.suppress(ValueError):
                self._listeners.remove(listener)

        return unsubscribe

    # --- a mirror in the doors process -----------------------------------------------------------
    def export(self) -> list[FaultMirror]:
        return [f.mirror() for f in self._faults.values()]

    def load(self, table: list[FaultMirror]) -> None:
        """Take the table of the process that owns the faults (keeps the counts of faults it has)."""
        faults: dict[int, ActiveFault] = {}
        for entry in table:
            old = self._faults.get(entry["id"])
            fault = ActiveFault(
                id=entry["id"],
                spec=FaultSpec.model_validate(entry["spec"]),
                started_cycle=entry["started_cycle"],
                started_at=entry["started_at"],
                expires_at=entry["expires_at"],
                used=max(entry["used"], old.used if old is not None else 0),
            )
            faults[fault.id] = fault
        self._faults = faults
        self._index()

    # --- the runtime, once per cycle -------------------------------------------------------------
    def publish_stalled(self, cycle: int) -> bool:
        """Whether the publish of ``cycle`` is stalled; ends the faults whose cycles are over."""
        if not self._cycle_bound:
            return False
        stalled = False
        for fault in list(self._faults.values()):
            if fault.ends_cycle is not None and cycle > fault.ends_cycle:
                self.end(fault.id, "cycles")
                continue
            if fault.spec.kind is FaultKind.STALL and cycle >= fault.started_cycle:
                stalled = True
                fault.used += 1
        return stalled

    def door_down(self, door: Door) -> bool:
        """The door is cut (MQTT disconnect) now."""
        if not self.active:
            return False
        self._expire(time.monotonic())
        return any(f.spec.kind is FaultKind.DISCONNECT for f in self._by_door.get(door, ()))

    # --- the doors -------------------------------------------------------------------------------
    def gate(self, door: Door, transport: Any) -> ConnectionGate:
        """The gate of one new connection of ``door`` (its transport wrapped for delays)."""
        return ConnectionGate(self, door, transport)

    def faults_of(self, door: Door) -> tuple[ActiveFault, ...]:
        if not self.active:
            return ()
        faults = self._by_door.get(door, ())
        if faults and any(f.expires_at is not None for f in faults):
            self._expire(time.monotonic())
            faults = self._by_door.get(door, ())
        return faults

    def acted(self, fault: ActiveFault) -> None:
        """``fault`` acted once more; it ends when its count is used up."""
        fault.used += 1
        limit = fault.spec.count if fault.spec.kind is not FaultKind.DROP else (fault.spec.count or 1)
        if limit is not None and fault.used >= limit and fault.id in self._faults:
            self.end(fault.id, "count")

    # --- inside -------------------------------------------------------------------------------------
    def _index(self) -> None:
        by_door: dict[Door, list[ActiveFault]] = {}
        for fault in self._faults.values():
            assert fault.spec.door is not None
            by_door.setdefault(fault.spec.door, []).append(fault)
        self._by_door = {door: tuple(faults) for door, faults in by_door.items()}
        self.active = bool(self._faults)
        self._cycle_bound = any(
            f.ends_cycle is not None or f.spec.kind is FaultKind.STALL for f in self._faults.values()
        )

    def _expire(self, now: float) -> None:
        for fault in list(self._faults.values()):
            if fault.expires_at is not None and now >= fault.expires_at:
                self.end(fault.id, "duration")

    def _arm_timer(self, fault: ActiveFault) -> None:
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            return  # no loop here: ended lazily when it is next consulted
        assert fault.expires_at is not None
        delay = max(0.0, fault.expires_at - time.monotonic())

        def expire() -> None:
            self._timers.pop(fault.id, None)
            if fault.id in self._faults:
                self.end(fault.id, "duration")

        self._timers[fault.id] = loop.call_later(delay, expire)

    def _tell(self, change: CommFaultChange) -> None:
        self.history.append({**change, "cycle": self._cycle()})
        for listener in list(self._listeners):
            try:
                listener(change)
            except Exception:
                logger.exception("a listener of the communication faults failed")


class _HeldTransport:
    """The connection's transport with its answers held back while a delay fault acts: every write
    after a delayed one waits its turn, so answers keep their order."""

    def __init__(self, transport: Any) -> None:
        self._inner = transport
        self._held: deque[tuple[float, bytes]] = deque()
        self._held_bytes = 0
        self._timer: asyncio.TimerHandle | None = None
        self.hold_s = 0.0
        """Delay of the next write (set by the gate for the requests it answers); consumed by it."""
        self.dropped = False

    def write(self, data: bytes) -> None:
        if self.dropped:
            return
        hold, self.hold_s = self.hold_s, 0.0
        if hold <= 0 and not self._held:
            self._inner.write(data)
            return
        due = time.monotonic() + hold
        if self._held:
            due = max(due, self._held[-1][0])
        self._held.append((due, bytes(data)))
        self._held_bytes += len(data)
        self._arm()

    def _arm(self) -> None:
        if self._timer is None and self._held:
            loop = asyncio.get_running_loop()
            delay = max(0.0, self._held[0][0] - time.monotonic())
            self._timer = loop.call_later(delay, self._release)

    def _release(self) -> None:
        self._timer = None
        now = time.monotonic()
        out: list[bytes] = []
        while self._held and self._held[0][0] <= now:
            _, data = self._held.popleft()
            self._held_bytes -= len(data)
            out.append(data)
        if out and not self._inner.is_closing():
            self._inner.write(b"".join(out))
        self._arm()

    @property
    def idle(self) -> bool:
        """Nothing held back, no delay asked for, not dropped: a write would go straight through."""
        return not self._held and self.hold_s <= 0 and not self.dropped

    def get_write_buffer_size(self) -> int:
        return int(self._inner.get_write_buffer_size()) + self._held_bytes

    def drop(self) -> None:
        self.dropped = True
        self._clear()
        self._inner.abort()

    def _clear(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._held.clear()
        self._held_bytes = 0

    def close(self) -> None:
        if self._held:  # answers still held: they go out first (after their delay), then the close
            loop = asyncio.get_running_loop()
            loop.call_later(max(0.0, self._held[-1][0] - time.monotonic()) + 0.001, self._inner.close)
            return
        self._inner.close()

    def abort(self) -> None:
        self._clear()
        self._inner.abort()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


@dataclass(slots=True, eq=False)
class ConnectionGate:
    """One connection's view of the faults (the module docstring). ``transport`` is the connection's
    transport to use: the original while no delay is asked for, held back while one acts."""

    faults: CommFaults
    door: Door
    raw: Any
    _held: _HeldTransport = field(init=False)
    _seen: dict[int, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._held = _HeldTransport(self.raw)

    @property
    def transport(self) -> Any:
        return self._held

    @property
    def quiet(self) -> bool:
        """No fault acts and nothing is held back: the connection may answer straight on ``raw``."""
        held = self._held
        return not self.faults.active and not held._held and held.hold_s <= 0 and not held.dropped

    def modbus(self, frame: Frame) -> bytes | None:
        """None: serve ``frame``; bytes: the answer the fault gives instead (b"": none, dropped)."""
        faults = self.faults.faults_of(self.door) if self.faults.active else ()
        if not faults:
            return None
        pdu = frame[3]
        return self._apply(
            faults, lambda f: f.spec.matches_modbus(pdu), lambda code: _modbus_error(frame, code)
        )

    def ads(self, packet: AmsPacket) -> bytes | None:
        """None: serve ``packet``; bytes: the answer the fault gives instead (b"": none, dropped)."""
        faults = self.faults.faults_of(self.door) if self.faults.active else ()
        if not faults or packet.header.is_response:
            return None
        return self._apply(
            faults,
            lambda f: f.spec.matches_ads(packet),
            lambda code: encode_response(packet.header, error_reply_payload(packet.header.command, code)),
        )

    def _apply(
        self,
        faults: tuple[ActiveFault, ...],
        matches: Callable[[ActiveFault], bool],
        error: Callable[[int], bytes],
    ) -> bytes | None:
        policy = self.faults
        for fault in faults:
            spec = fault.spec
            if spec.kind is FaultKind.DROP:
                seen = self._seen.get(fault.id, 0) + 1
                self._seen[fault.id] = seen
                assert spec.after is not None
                if seen > spec.after:
                    logger.info("communication fault %d: dropping a %s connection", fault.id, self.door)
                    self._held.drop()
                    policy.acted(fault)
                    return b""
        for fault in faults:
            spec = fault.spec
            if spec.kind is FaultKind.ERROR and matches(fault):
                assert spec.code is not None
                policy.acted(fault)
                return error(spec.code)
        for fault in faults:
            spec = fault.spec
            if spec.kind is FaultKind.DELAY and matches(fault):
                assert spec.delay_ms is not None
                self._held.hold_s = max(self._held.hold_s, spec.delay_ms / 1000)
                policy.acted(fault)
                break
        return None


def _modbus_error(frame: Frame, code: int) -> bytes:
    tid, _, unit, pdu = frame
    fc = pdu[0] if pdu else 0
    return encode_adu(tid, unit, encode_exception(fc & 0x7F, code))
