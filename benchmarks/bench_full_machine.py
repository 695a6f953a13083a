"""The full machine in simulated time, compiled and pure engine, against the demo machine.

The full machine (``machines/full.toml``, ``benchmarks/scenarios.py``): 2 channels, 8 axes; channel 1
mills a pocket (lines, G02/G03, 12 depth levels) after defining and activating 20 areas; channel 2
shuttles four carriages that form 3 collision pairs; all 16 dynamic position limits enabled in both
FCT_DYN_POS_LIMIT channels; every axis position-monitored. Goal: 50x real time or more on one core at
T_A = 1 ms, with the outputs of the pure engine cycle for cycle (``tests/unit/test_compiled_engine.py``).

Measured in the same run, interleaved in slices of 500 cycles so that load on the host hits all alike:
the full machine and the demo machine as ``bench_engine`` ran it (channel 1 running the long program, no
dynamic limit enabled, channel 2 idle), each in a worker process with the compiled engine and one with
``HLI_PURE_PYTHON=1``. Real time is a constant (1,000 cycles/s at T_A = 1 ms): figures are multiples of
it, best of ``--rounds`` rounds of ``--seconds`` each.

    .venv/bin/python -m benchmarks.bench_full_machine [--seconds S] [--rounds N]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).parents[1]
SLICE = 500
WORKER = r"""
import json, sys, time
import hli_server._compiled as compiled
from benchmarks.bench_engine import long_program
from benchmarks.scenarios import demo_machine, full_machine
machines = {"full": full_machine(), "demo": demo_machine(long_program(200_000))}
print(json.dumps({"compiled": compiled.ENGINE_COMPILED}), flush=True)
for line in sys.stdin:
    name, cycles = line.split()
    m = machines[name]
    t0 = time.perf_counter()
    m.step(int(cycles))
    dt = time.perf_counter() - t0
    running = all(ch.state.label == "running" for ch in m.channels) if name == "full" else True
    print(json.dumps({"dt": dt, "alarms": len(m.active_alarms), "running": running}), flush=True)
"""


class Worker:
    def __init__(self, pure: bool) -> None:
        env = dict(os.environ)
        env.pop("HLI_PURE_PYTHON", None)
        if pure:
            env["HLI_PURE_PYTHON"] = "1"
        self.proc = subprocess.Popen(
            [sys.executable, "-c", WORKER],
            cwd=ROOT,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        self.compiled = bool(json.loads(self.proc.stdout.readline())["compiled"])

    def step(self, name: str, cycles: int) -> dict[str, float]:
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        self.proc.stdin.write(f"{name} {cycles}\n")
        self.proc.stdin.flush()
        reply: dict[str, float] = json.loads(self.proc.stdout.readline())
        return reply

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        self.proc.wait(timeout=30)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=4.0, help="wall time of one round, all machines")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    workers = {"compiled": Worker(pure=False), "pure": Worker(pure=True)}
    if not workers["compiled"].compiled:
        print("note: the engine is not compiled here (no C compiler or mypyc at install): pure only")
        workers["compiled"].close()
        del workers["compiled"]
    keys = [(w, m) for w in workers for m in ("full", "demo")]
    best = dict.fromkeys(keys, 0.0)
    trouble: list[str] = []
    for _ in range(args.rounds):
        spent = dict.fromkeys(keys, 0.0)
        cycles = dict.fromkeys(keys, 0)
        began = time.perf_counter()
        while time.perf_counter() - began < args.seconds:
            for w, m in keys:
                reply = workers[w].step(m, SLICE)
                spent[(w, m)] += reply["dt"]
                cycles[(w, m)] += SLICE
                if reply["alarms"] or not reply["running"]:
                    trouble.append(f"{w}/{m}: alarms {reply['alarms']}, running {reply['running']}")
        for key in keys:
            best[key] = max(best[key], cycles[key] / spent[key])
    for w in workers.values():
        w.close()
    realtime = 1000.0
    for w, m in keys:
        label = (
            "full machine (2 channels, 8 axes, 20 areas, 16 dyn. limits, 3 pairs)"
            if m == "full"
            else ("demo machine (channel 1 running, no dyn. limit enabled, channel 2 idle)")
        )
        print(f"{w:8} {label}: {best[(w, m)]:,.0f} cycles/s = {best[(w, m)] / realtime:.1f}x real time")
    print(
        f"reference: real time at T_A = 1 ms = {realtime:,.0f} cycles/s (a constant; best of {args.rounds})"
    )
    if "compiled" in workers:
        ratio = best[("compiled", "full")] / best[("pure", "full")]
        print(f"ratio compiled / pure engine, full machine: {ratio:.2f}")
    for w in workers:
        print(f"ratio full / demo machine, {w}: {best[(w, 'full')] / best[(w, 'demo')]:.2f}")
    if trouble:
        print("WARNING: " + "; ".join(sorted(set(trouble))[:5]))


if __name__ == "__main__":
    main()
