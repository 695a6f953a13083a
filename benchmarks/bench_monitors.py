"""What the monitors of FCT-C43, FCT-C3 and FCT-A3 cost per cycle.

The demo machine runs a long program in channel 1 (lines and arcs, as in ``bench_engine``) and
keeps the collision pair X1/X2 of channel 2 moving, with every dynamic position limit of every axis
enabled (far enough out that the look-ahead runs every cycle without braking), the pair monitored
and every axis position-monitored. Reference, in the same run: the same machine with these three
monitors removed (soft limits and areas stay in both). The two machines are stepped in alternating
slices so that both see the same load on the host; printed as cycles/s and their ratio.

    .venv/bin/python -m benchmarks.bench_monitors [--seconds S]
"""

from __future__ import annotations

import argparse
import time

from benchmarks.bench_engine import long_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.engine.monitors.collision import CollisionMonitor
from hli_server.engine.monitors.dyn_pos_limit import DynPosLimits
from hli_server.engine.monitors.position import PositionMonitor
from schemas.wire import DynPosLimitState, ProgramState

MONITORS = (DynPosLimits, CollisionMonitor, PositionMonitor)
COLLISION = CollisionMonitor.__module__
SLICE = 500

GANTRY = (
    "".join(
        f"N{10 * i + 10} G01 X1={100 + 40 * (i % 4)} X2={400 - 30 * (i % 5)} F{3000 + 1000 * (i % 7)}\n"
        for i in range(2000)
    )
    + "N99999 M30\n"
)
"""The carriages shuttle in 100..220 mm and 280..400 mm: never closer than 60 mm (minimum 20 mm)."""


def build(with_monitors: bool) -> Machine:
    machine = Machine(load_machine(None))
    if not with_monitors:
        machine.monitors = [m for m in machine.monitors if not isinstance(m, MONITORS)]
        for ch in machine.channels:
            ch.planner.exact_stop_gate = None
            ch.decoder.path_checks = [c for c in ch.decoder.path_checks if type(c).__module__ != COLLISION]
            ch.jog_guards = [g for g in ch.jog_guards if type(g).__module__ != COLLISION]
    for axis, hli in zip(machine.axes, machine.hli.axes, strict=True):
        ctl = hli.ipo_mc_control
        ctl.dyn_pos_limit_low.command_w = axis.config.swe_neg + 1_000
        ctl.dyn_pos_limit_high.command_w = axis.config.swe_pos - 1_000
        ctl.dyn_pos_limit_low.enable_w = ctl.dyn_pos_limit_high.enable_w = True
    machine.step(2)
    ch1, ch2 = machine.channel(1), machine.channel(2)
    ch1.load_program(long_program(200_000), "bench")
    ch2.load_program(GANTRY, "gantry")
    ch1.request_start()
    ch2.request_start()
    machine.step(1)
    return machine


def running(machine: Machine) -> bool:
    return all(ch.state == ProgramState.RUNNING for ch in machine.channels)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=6.0, help="total wall time of both machines")
    args = ap.parse_args()
    full, bare = build(True), build(False)
    limits = next(m for m in full.monitors if isinstance(m, DynPosLimits))
    active = sum(
        1
        for a in full.axes
        for side in ("low", "high")
        if limits.state(a.name, side) == DynPosLimitState.ACTIVE
    )
    pairs = len(next(m for m in full.monitors if isinstance(m, CollisionMonitor)).pairs)
    spent = {id(full): 0.0, id(bare): 0.0}
    cycles = {id(full): 0, id(bare): 0}
    began = time.perf_counter()
    while time.perf_counter() - began < args.seconds and running(full) and running(bare):
        for machine in (full, bare):
            t0 = time.perf_counter()
            machine.step(SLICE)
            spent[id(machine)] += time.perf_counter() - t0
            cycles[id(machine)] += SLICE
    assert not full.active_alarms, [a.message for a in full.active_alarms]
    rate_full = cycles[id(full)] / spent[id(full)]
    rate_bare = cycles[id(bare)] / spent[id(bare)]
    print(
        f"with monitors: {rate_full:,.0f} cycles/s (demo machine, {active} dynamic limits active in "
        f"FCT_DYN_POS_LIMIT channels, {pairs} collision pair, {len(full.axes)} axes position-monitored)"
    )
    print(f"reference: same machine without FCT-C43/C3/A3 monitors: {rate_bare:,.0f} cycles/s")
    print(f"ratio: {rate_full / rate_bare:.2f} (with / without)")


if __name__ == "__main__":
    main()
