"""Speed of the engine (E-01) and of ``check --geometry-only``.

1. Cycles per second of the demo machine running a long program (lines and arcs), in full simulation
   with every monitor installed. Reference: real time at T_A = 1 ms (1000 cycles/s); printed as a
   multiple of real time.
2. NC blocks per second of ``check --geometry-only`` on a long program. Reference, same run, same
   text: the parser alone (``iter_blocks``); the ratio shows what decoding and path checks cost on top.
3. The same with 20 active areas (FCT-C14): a million blocks of lines and arcs inside a work
   polygon, past 19 protection areas (polygons and circles). ``check --geometry-only`` blocks/s,
   against the same program without areas (same run); and the program's cycles/s in the full
   simulation, against real time.

    .venv/bin/python -m benchmarks.bench_engine [--blocks N] [--seconds S]
"""

from __future__ import annotations

import argparse
import time

from hli_server.commands.check import check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.engine.nc.parser import iter_blocks
from schemas.wire import ProgramState


def long_program(blocks: int) -> str:
    """Squares of lines and quarter arcs inside +-200 mm, as a CAM system would emit them."""
    out = ["N1 G90 G01 X0 Y0 Z0 F6000"]
    n = 2
    while n < blocks:
        r = 20.0 + (n % 50)
        out.append(f"N{n} G01 X{r:.3f} Y0")
        out.append(f"N{n + 1} G03 X0 Y{r:.3f} I-{r:.3f} J0")
        out.append(f"N{n + 2} G01 X-{r:.3f} Y{r:.3f}")
        out.append(f"N{n + 3} G01 X0 Y0")
        n += 4
    out.append(f"N{n} M30")
    return "\n".join(out) + "\n"


def bench_cycles(seconds: float) -> None:
    config = load_machine(None)
    machine = Machine(config)
    ch = machine.channel(1)
    ch.load_program(long_program(200_000), "bench")
    ch.request_start()
    machine.step(1)
    began = time.perf_counter()
    cycles = 0
    while time.perf_counter() - began < seconds and ch.state == ProgramState.RUNNING:
        machine.step(1000)
        cycles += 1000
    elapsed = time.perf_counter() - began
    rate = cycles / elapsed
    realtime = 1e6 / config.cycle_time_us
    print(f"engine: {rate:,.0f} cycles/s (demo machine, {len(machine.monitors)} monitors, program running)")
    print(f"reference: real time at T_A = {config.cycle_time_us} us = {realtime:,.0f} cycles/s")
    print(f"ratio: {rate / realtime:.2f}x real time")


def bench_geometry(blocks: int) -> None:
    text = long_program(blocks)
    machine = Machine(load_machine(None))
    axes = machine.channel(1).axis_names
    began = time.perf_counter()
    parsed = sum(1 for _ in iter_blocks(text, axes))
    parse_rate = parsed / (time.perf_counter() - began)
    result = check_program(machine, text, geometry_only=True)
    check_rate = result.blocks / result.elapsed_s
    assert result.completed, result.to_json()["alarms"]
    print(f"check --geometry-only: {check_rate:,.0f} blocks/s ({result.blocks:,} blocks)")
    print(f"reference: parser alone: {parse_rate:,.0f} blocks/s")
    print(f"ratio: {check_rate / parse_rate:.2f} (check / parse)")


def area_header() -> str:
    """One work polygon around the tool path and 19 protection areas (10 circles, 9 squares) outside it."""
    import math

    out = [
        "N1 #CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]",
        "N2 G01 G90 F1000 X-300 Y-300",
        "N3 X300 Y-300",
        "N4 X300 Y300",
        "N5 X-300 Y300",
        "N6 X-300 Y-300",
        "N7 #CONTROL AREA END",
    ]
    for k in range(19):
        area_id = k + 2
        angle = 2 * math.pi * k / 19
        cx, cy = 200 * math.cos(angle), 200 * math.sin(angle)
        if k % 2 == 0:
            out += [
                f"#CONTROL AREA BEGIN [ID={area_id} PROT CIRC MIN_EXCUR=-100 MAX_EXCUR=100]",
                f"G01 X{cx + 10:.3f} Y{cy:.3f}",
                "G02 I-10 J0",
                "#CONTROL AREA END",
            ]
        else:
            out += [
                f"#CONTROL AREA BEGIN [ID={area_id} PROT POLY MIN_EXCUR=-100 MAX_EXCUR=100]",
                f"G01 X{cx - 8:.3f} Y{cy - 8:.3f}",
                f"X{cx + 8:.3f} Y{cy - 8:.3f}",
                f"X{cx + 8:.3f} Y{cy + 8:.3f}",
                f"X{cx - 8:.3f} Y{cy + 8:.3f}",
                f"X{cx - 8:.3f} Y{cy - 8:.3f}",
                "#CONTROL AREA END",
            ]
    out += ["G01 X0 Y0 F6000", "#CONTROL AREA ON ALL"]
    return "\n".join(out) + "\n"


def bench_areas(blocks: int, seconds: float) -> None:
    body = long_program(blocks)
    with_areas = area_header() + body
    plain_machine = Machine(load_machine(None))
    plain = check_program(plain_machine, body, geometry_only=True)
    machine = Machine(load_machine(None))
    result = check_program(machine, with_areas, geometry_only=True)
    assert result.completed, result.to_json()["alarms"]
    active = sum(1 for a in result.to_json().get("areas", []) if a["state"] == "active")
    rate = result.blocks / result.elapsed_s
    plain_rate = plain.blocks / plain.elapsed_s
    print(
        f"check --geometry-only with {active} active areas: {rate:,.0f} blocks/s ({result.blocks:,} blocks)"
    )
    print(f"reference: the same program without areas: {plain_rate:,.0f} blocks/s")
    print(f"ratio: {rate / plain_rate:.2f} (with / without areas)")
    full = Machine(load_machine(None))
    ch = full.channel(1)
    ch.load_program(with_areas, "bench-areas")
    ch.request_start()
    full.step(1)
    while ch.state == ProgramState.RUNNING and not any(a["state"] == "active" for a in _areas(full)):
        full.step(100)
    began = time.perf_counter()
    cycles = 0
    while time.perf_counter() - began < seconds and ch.state == ProgramState.RUNNING:
        full.step(1000)
        cycles += 1000
    elapsed = time.perf_counter() - began
    assert not full.active_alarms, full.active_alarms
    realtime = 1e6 / full.config.cycle_time_us
    print(f"full simulation of that program, {active} areas active: {cycles / elapsed:,.0f} cycles/s")
    print(
        f"reference: real time {realtime:,.0f} cycles/s; ratio {cycles / elapsed / realtime:.2f}x real time"
    )


def _areas(machine: Machine) -> list[dict[str, object]]:
    for mon in machine.monitors:
        table = getattr(mon, "areas_json", None)
        if callable(table):
            result: list[dict[str, object]] = table(machine.channel(1))
            return result
    return []


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--blocks", type=int, default=200_000)
    ap.add_argument("--area-blocks", type=int, default=1_000_000)
    ap.add_argument("--seconds", type=float, default=5.0)
    args = ap.parse_args()
    bench_cycles(args.seconds)
    bench_geometry(args.blocks)
    bench_areas(args.area_blocks, args.seconds)


if __name__ == "__main__":
    main()
