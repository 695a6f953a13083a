"""Machines set up and running as the benchmarks and the recorded-scenario tests use them.

* :func:`full_machine`: the full machine (``machines/full.toml``) with its 16 dynamic position limits
  enabled inside the software limits, the pocket running in channel 1 and the carriages shuttling in
  channel 2 (``benchmarks/programs.py``).
* :func:`demo_machine`: the built-in demo machine as ``bench_engine`` always ran it (channel 1 only, no
  dynamic limit enabled, channel 2 idle): the reference the full machine is compared with.
* :func:`trace_digest`: what the PLC and the event listeners see, cycle by cycle, folded into one
  digest (every published HLI field of every axis and channel, every event): two engines that give the
  same digest gave the same outputs in every cycle, bit for bit.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import fields, is_dataclass
from enum import Enum
from typing import Any

from benchmarks.programs import FULL_MACHINE, pocket_program, shuttle_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from schemas.events import Event

__all__ = ["DYN_LIMITS", "demo_machine", "enable_dyn_limits", "full_machine", "trace_digest"]

DYN_LIMITS: dict[str, tuple[float, float]] = {
    "X": (-300.0, 300.0),
    "Y": (-300.0, 300.0),
    "Z": (-150.0, 150.0),
    "W": (-250.0, 250.0),
    "X1": (-150.0, 150.0),
    "X2": (150.0, 450.0),
    "X3": (450.0, 750.0),
    "X4": (750.0, 1050.0),
}
"""mm, low and high: all 16 dynamic position limits of the full machine, inside the software limits
and outside what the programs reach (the pocket +-100 x +-60 mm, each carriage +-100 mm about home):
the look-ahead runs every cycle and never brakes."""


def enable_dyn_limits(machine: Machine, limits: dict[str, tuple[float, float]]) -> None:
    for name, (low, high) in limits.items():
        ctl = machine.hli.axes[machine.axis(name).index].ipo_mc_control
        ctl.dyn_pos_limit_low.command_w = round(low * 10_000)
        ctl.dyn_pos_limit_high.command_w = round(high * 10_000)
        ctl.dyn_pos_limit_low.enable_w = ctl.dyn_pos_limit_high.enable_w = True


def full_machine(
    *, levels: int = 12, shuttles: int = 4000, limits: dict[str, tuple[float, float]] | None = None
) -> Machine:
    """The full machine (``machines/full.toml``), the dynamic limits active, both programs started at the
    next cycle."""
    machine = Machine(load_machine(FULL_MACHINE))
    enable_dyn_limits(machine, DYN_LIMITS if limits is None else limits)
    machine.step(2)  # enable -> adopted
    ch1, ch2 = machine.channel(1), machine.channel(2)
    ch1.load_program(pocket_program(levels), "pocket")
    ch2.load_program(shuttle_program(shuttles), "shuttle")
    ch1.request_start()
    ch2.request_start()
    return machine


def demo_machine(program: str) -> Machine:
    """The demo machine running ``program`` in channel 1 (what ``bench_engine`` measured before)."""
    machine = Machine(load_machine(None))
    ch = machine.channel(1)
    ch.load_program(program, "bench")
    ch.request_start()
    machine.step(1)
    return machine


_PLAIN, _ENUM, _DATACLASS, _SEQUENCE, _MAPPING = range(5)
_KINDS: dict[type, tuple[int, tuple[str, ...]]] = {}


def _kind(cls: type) -> tuple[int, tuple[str, ...]]:
    """How :func:`_fold` takes a value of ``cls`` apart (asked once per type, then cached)."""
    if issubclass(cls, Enum):
        kind = (_ENUM, ())
    elif is_dataclass(cls):
        kind = (_DATACLASS, tuple(f.name for f in fields(cls)))
    elif issubclass(cls, list | tuple):
        kind = (_SEQUENCE, ())
    elif issubclass(cls, dict):
        kind = (_MAPPING, ())
    else:
        kind = (_PLAIN, ())
    _KINDS[cls] = kind
    return kind


def _fold(value: Any) -> Any:
    """Plain values of the outputs: an enum counts as its value (the compiled engine stores the int a
    field is declared as, the interpreter the IntEnum that was assigned; the wire carries the same).
    Dispatched on the value's type, cached: the digest folds the whole HLI every cycle."""
    cls = type(value)
    kind, names = _KINDS.get(cls) or _kind(cls)
    if kind == _PLAIN:
        return value
    if kind == _DATACLASS:
        return tuple((name, _fold(getattr(value, name))) for name in names)
    if kind == _ENUM:
        return value.value
    if kind == _SEQUENCE:
        return tuple(_fold(v) for v in value)
    return tuple((k, _fold(v)) for k, v in value.items())


def trace_digest(
    machine: Machine,
    cycles: int,
    *,
    each: Callable[[Machine], None] | None = None,
    checkpoint: int = 1000,
) -> tuple[str, list[str]]:
    """Step ``cycles`` cycles and fold every cycle's outputs (the whole HLI and the events) into a
    sha256; returns it and the digest at every ``checkpoint``-th cycle (to find the first difference).
    ``each(machine)`` runs before every cycle (inputs a scenario changes)."""
    events: list[Event] = []
    machine.event_listeners.append(events.append)
    h = hashlib.sha256()
    marks: list[str] = []
    try:
        for k in range(1, cycles + 1):
            if each is not None:
                each(machine)
            machine.step(1)
            state = (
                machine.cycle,
                _fold(machine.hli),
                tuple((a.setpoint, a.actual, a.measured, a.drive_velocity) for a in machine.axes),
                tuple((type(e).__name__, _fold(e)) for e in events),
            )
            events.clear()
            h.update(repr(state).encode())
            if k % checkpoint == 0:
                marks.append(h.hexdigest()[:16])
    finally:
        machine.event_listeners.remove(events.append)
    return h.hexdigest(), marks
