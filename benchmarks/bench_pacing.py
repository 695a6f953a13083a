"""Realtime pacing of the runtime (E-01): lateness p50/p99/max at T_A = 1 ms.

The runtime's realtime clock (demo machine, shared-memory image, a program running, no HTTP) runs for
``--seconds`` of wall time; the lateness of every cycle is the wall time at which it was published
minus the time it was due (``epoch + k * T_A``).

Reference, same run, same machine and program: a plain loop paced by ``await asyncio.sleep(T_A)``
before each cycle (what one writes first). Its lateness is measured against the same schedule; as it
never catches up, it falls behind the wall clock for good, which the rate (simulated seconds per wall
second) shows. The ratios compare the two.

    .venv/bin/python -m benchmarks.bench_pacing [--seconds 10]      # --seconds 60 for the full minute
"""

from __future__ import annotations

import argparse
import asyncio
import math
import time

from benchmarks.bench_engine import long_program
from hli_server.configuration import load_machine
from hli_server.runtime import Runtime


def percentile(data: list[float], q: float) -> float:
    ordered = sorted(data)
    if not ordered:
        return 0.0
    return ordered[max(0, min(len(ordered) - 1, math.ceil(q / 100 * len(ordered)) - 1))]


PROGRAM = long_program(200_000)
"""Built once, before the clocks start (building it would block the event loop)."""


def start_program(rt: Runtime) -> None:
    ch = rt.machine.channel(1)
    ch.load_program(PROGRAM, "bench")
    ch.request_start()


async def runtime_pacing(seconds: float) -> dict[str, float]:
    async with Runtime(load_machine(None), clock="realtime", http_port=None) as rt:
        start_program(rt)
        await asyncio.sleep(seconds)
        timing = rt.timing()
    lateness = timing["lateness_us"]
    return {
        "t_a_us": timing["t_a_us"],
        "cycles": timing["cycles"],
        "rate": timing["rate"],
        "p50": lateness["p50"],
        "p99": lateness["p99"],
        "max": lateness["max"],
        "late": timing["late_cycles"],
        "catch_up": timing["catch_up_wakeups"] / max(1, timing["wakeups"]),
        "max_catch_up": timing["max_catch_up"],
        "dropped": timing["slipped_cycles"],
    }


async def sleep_pacing(seconds: float) -> dict[str, float]:
    async with Runtime(load_machine(None), clock="stepped", http_port=None) as rt:
        start_program(rt)
        t_a = rt.t_a
        lateness: list[float] = []
        overshoot: list[float] = []
        epoch = time.monotonic()
        k = 0
        while True:
            before = time.monotonic()
            if before - epoch >= seconds:
                break
            await asyncio.sleep(t_a)
            woke = time.monotonic()
            overshoot.append(woke - before - t_a)
            await rt.step(1)
            k += 1
            lateness.append(time.monotonic() - (epoch + k * t_a))
        wall = time.monotonic() - epoch
    return {
        "cycles": k,
        "rate": k * t_a / wall,
        "p50": percentile(lateness, 50) * 1e6,
        "p99": percentile(lateness, 99) * 1e6,
        "max": max(lateness) * 1e6,
        "overshoot_p50": percentile(overshoot, 50) * 1e6,
        "overshoot_p99": percentile(overshoot, 99) * 1e6,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="wall time of each of the two runs")
    args = ap.parse_args()
    rt = asyncio.run(runtime_pacing(args.seconds))
    ref = asyncio.run(sleep_pacing(args.seconds))
    print(
        f"runtime realtime clock, T_A = {rt['t_a_us']:.0f} us, {args.seconds:g} s: {rt['cycles']:,} cycles, "
        f"rate {rt['rate']:.4f}"
    )
    print(
        f"  lateness p50 {rt['p50']:,.0f} us, p99 {rt['p99']:,.0f} us, max {rt['max']:,.0f} us; "
        f"{rt['late']:,} cycles later than T_A; catch-up in {rt['catch_up']:.1%} of wake-ups "
        f"(at most {rt['max_catch_up']} cycles), {rt['dropped']} cycles dropped"
    )
    print(
        f"reference: asyncio.sleep(T_A) loop, same {args.seconds:g} s: {ref['cycles']:,} cycles, "
        f"rate {ref['rate']:.4f}"
    )
    print(
        f"  lateness p50 {ref['p50']:,.0f} us, p99 {ref['p99']:,.0f} us, max {ref['max']:,.0f} us "
        f"(grows: it never catches up); sleep overshoot p50 {ref['overshoot_p50']:,.0f} us, "
        f"p99 {ref['overshoot_p99']:,.0f} us"
    )
    print(
        f"ratio: rate {rt['rate'] / ref['rate']:.3f}x the sleep loop; max lateness "
        f"{ref['max'] / max(rt['max'], 1.0):.1f}x lower; p99 {ref['p99'] / max(rt['p99'], 1.0):.1f}x lower"
    )


if __name__ == "__main__":
    main()
