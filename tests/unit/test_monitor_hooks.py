"""A monitor of one's own: its hooks run every cycle, in the cycle's order, compiled engine or not.

The machine calls each hook on the monitor that overrides it (``Machine._install``); a monitor written in
Python subclasses the compiled ``Monitor`` (the one engine class that allows it, docs/performance.md), so
its overrides must be the ones called, and the built-in monitors' hooks must run beside them.
"""

from __future__ import annotations

from typing import Any

import hli_server._compiled as compiled
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.engine.machine import DEFAULT_MONITORS
from hli_server.engine.monitors.base import Monitor
from tests.unit.engine_helpers import start


class Recorder(Monitor):
    """Notes which hook ran in which cycle, and where the axes stood when it ran."""

    def __init__(self, machine: Any) -> None:
        self.machine = machine
        self.calls: list[tuple[int, str]] = []
        self.setpoints: dict[tuple[int, str], float] = {}

    def _note(self, hook: str) -> None:
        cycle = self.machine.cycle
        self.calls.append((cycle, hook))
        self.setpoints[(cycle, hook)] = self.machine.axis("X").setpoint

    def before_interpolation(self) -> None:
        self._note("before")

    def after_interpolation(self) -> None:
        self._note("after")

    def after_position_loop(self) -> None:
        self._note("loop")


class OnlyAfter(Monitor):
    """Overrides one hook: the others are not called on it."""

    def __init__(self, machine: Any) -> None:
        self.cycles: list[int] = []
        self.machine = machine

    def after_interpolation(self) -> None:
        self.cycles.append(self.machine.cycle)


def test_a_python_monitors_hooks_run_every_cycle_in_order_beside_the_built_in_ones() -> None:
    machine = Machine(load_machine(None), monitors=(*DEFAULT_MONITORS, Recorder, OnlyAfter))
    recorder, only_after = machine.monitor(Recorder), machine.monitor(OnlyAfter)
    start(machine, "G90 G01 X50 F6000\nM30\n")
    first = machine.cycle + 1
    machine.step(20)
    cycles = range(first, first + 20)
    calls = [call for call in recorder.calls if call[0] >= first]
    assert recorder.calls[: -len(calls)] == [(first - 1, hook) for hook in ("before", "after", "loop")]
    assert calls == [(c, hook) for c in cycles for hook in ("before", "after", "loop")]
    assert only_after.cycles == [first - 1, *cycles]
    # before the interpolation the axes stand where the last cycle left them; after it they moved
    moved = [c for c in cycles if recorder.setpoints[(c, "after")] != recorder.setpoints[(c, "before")]]
    assert moved, f"X moved in none of the cycles (engine compiled: {compiled.ENGINE_COMPILED})"
    assert all(recorder.setpoints[(c, "after")] == recorder.setpoints[(c, "loop")] for c in cycles)
    # installed after the built-in ones, which keep their places
    assert [type(m) for m in machine.monitors] == [*DEFAULT_MONITORS, Recorder, OnlyAfter]
