"""Realtime pacing of the runtime (E-01): lateness p50/p99/max at T_A = 1 ms.

The runtime's realtime clock (demo machine, shared-memory image, a program running, no HTTP) runs for
``--seconds`` of wall time; the lateness of every cycle is the wall time at which it was published
minus the time it was due (``epoch + k * T_A``).

The runtime runs in the event loop ``hli-server run`` uses (``select``, microsecond timers) first *and*
last, and in between in asyncio's default loop (``epoll``, whose timeouts are whole milliseconds): a
machine whose load changed during the run shows itself in the two ``select`` runs. The core count and the
load average are printed with each run, and the five worst cycles of each with their cause (what the
clock's tracer says: the operating system, garbage collection, other work on the loop, the cycle).

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
import os
import time
from collections.abc import Coroutine
from typing import Any

from benchmarks.bench_engine import long_program
from hli_server.configuration import load_machine
from hli_server.runtime import Runtime, precise_event_loop
from hli_server.runtime.pacing import probed_default_loop


def percentile(data: list[float], q: float) -> float:
    ordered = sorted(data)
    if not ordered:
        return 0.0
    return ordered[max(0, min(len(ordered) - 1, math.ceil(q / 100 * len(ordered)) - 1))]


PROGRAM = long_program(200_000)
"""Built once, before the clocks start (building it would block the event loop)."""


def prepared_runtime(clock: str) -> Runtime:
    """The demo machine with the program started and its first cycle run before the clock starts
    (the first cycle opens the program and fills the look-ahead: tens of ms for a long program),
    so that the figures are those of steady running."""
    rt = Runtime(load_machine(None), clock=clock, http_port=None)
    ch = rt.machine.channel(1)
    ch.load_program(PROGRAM, "bench")
    ch.request_start()
    rt.machine.step(1)
    return rt


def machine_line() -> str:
    load = os.getloadavg()
    return f"{os.cpu_count()} cores, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}"


async def runtime_pacing(seconds: float) -> dict[str, Any]:
    async with prepared_runtime("realtime") as rt:
        await asyncio.sleep(seconds)
        timing = rt.timing()
    lateness = timing["lateness_us"]
    return {
        "p999": lateness["p999"],
        "worst": timing["worst"],
        "late_causes": timing["late_causes"],
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


async def sleep_pacing(seconds: float) -> dict[str, Any]:
    async with prepared_runtime("stepped") as rt:
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


def run_in(loop_name: str, coro: Coroutine[Any, Any, dict[str, Any]]) -> dict[str, Any]:
    # asyncio's default loop as `hli-server run --event-loop default` builds it: its waits noted, so that
    # the tracer can tell a late timer (whole milliseconds) from other work on the loop
    factory = precise_event_loop if loop_name == "select" else probed_default_loop
    with asyncio.Runner(loop_factory=factory) as runner:
        return runner.run(coro)


def print_runtime(label: str, rt: dict[str, Any], seconds: float) -> None:
    print(
        f"{label}: T_A = {rt['t_a_us']:.0f} us, {seconds:g} s: {rt['cycles']:,} cycles, "
        f"rate {rt['rate']:.4f} ({rt['machine']})"
    )
    print(
        f"  lateness p50 {rt['p50']:,.0f} us, p99 {rt['p99']:,.0f} us, p99.9 {rt['p999']:,.0f} us, "
        f"max {rt['max']:,.0f} us; {rt['late']:,} cycles later than T_A; catch-up in {rt['catch_up']:.1%} of "
        f"wake-ups (at most {rt['max_catch_up']} cycles), {rt['dropped']} cycles dropped"
    )
    causes = ", ".join(f"{k} {v}" for k, v in rt["late_causes"].items()) or "none"
    print(f"  cycles later than T_A by cause: {causes}")
    for w in rt["worst"]:
        late = w["lateness_us"] / 1e3
        print(f"    cycle {w['cycle']:>6} at {w['at_s']:6.2f} s: {late:7.2f} ms late: {w['detail']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="wall time of each of the three runs")
    args = ap.parse_args()
    sec = args.seconds
    print(f"machine: {machine_line()}")
    first = {"machine": machine_line(), **run_in("select", runtime_pacing(sec))}
    default = {"machine": machine_line(), **run_in("default", runtime_pacing(sec))}
    ref = run_in("default", sleep_pacing(sec))
    last = {"machine": machine_line(), **run_in("select", runtime_pacing(sec))}
    precise = first if first["p99"] >= last["p99"] else last  # the worse of the two for the ratios
    print_runtime("runtime, realtime clock, select loop (hli-server run), first", first, sec)
    print_runtime("runtime, realtime clock, asyncio's default loop (epoll)", default, sec)
    print_runtime("runtime, realtime clock, select loop (hli-server run), last", last, sec)
    print(
        f"reference: asyncio.sleep(T_A) loop, default loop, {sec:g} s: {ref['cycles']:,} cycles, "
        f"rate {ref['rate']:.4f}"
    )
    print(
        f"  lateness p50 {ref['p50']:,.0f} us, p99 {ref['p99']:,.0f} us, max {ref['max']:,.0f} us "
        f"(grows: it never catches up); sleep overshoot p50 {ref['overshoot_p50']:,.0f} us, "
        f"p99 {ref['overshoot_p99']:,.0f} us"
    )
    for label, rt in (("select loop, the worse of first and last", precise), ("default loop", default)):
        print(
            f"ratio ({label}): rate {rt['rate'] / ref['rate']:.3f}x the sleep loop's; lateness "
            f"p99 {ref['p99'] / max(rt['p99'], 1.0):,.0f}x and "
            f"max {ref['max'] / max(rt['max'], 1.0):,.0f}x lower"
        )
    print(f"select vs default loop: lateness p50 {default['p50'] / max(precise['p50'], 1.0):.1f}x lower")


if __name__ == "__main__":
    main()
