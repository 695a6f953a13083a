"""Cost of polynomial contouring (M-27): the same program with contouring active against without.

The program is ``bench_engine``'s: squares of lines and quarter arcs, as a CAM system emits them
(line-line, line-arc and arc-line corners). With ``#CONTOUR MODE [DEV PATH_DEV=0.5]`` and G261 every
corner is replaced by a quartic transition segmented into support points (FCT-C14 2.3): more, shorter
segments for the path checks and the planner. Each figure is measured against the same program without
contouring, in the same run:

1. full simulation (every monitor installed) of a program run to its end: engine cycles per second of
   wall time, and the machining time (cycles) the program takes;
2. ``check --geometry-only`` blocks per second, against the exact (block by block) check of the program
   without contouring; the batch's figure without contouring is printed too (with contouring on the
   batch is off: the transitions are segments it does not know);
3. the same with 20 active areas (the hard case: each support-point chord is checked against every area);
4. the chained path (M-30): the same program with ``#CS ON [5, 5, 0, 0, 0, 10]``, ``D1`` (50 mm tool
   length, 2 mm radius), ``G41`` and contouring (PATH_DEV 0.5) together, on ``bench_motion_tools``'s machine
   (it has the tool table): every block goes through the radius compensation, the frames, the contouring
   stage and the tool-tip checks. Against the exact path without any of them (the same programmed
   blocks), same run: decoding (blocks/s, block by block, the way ``check`` decodes while a frame is
   active), and a full simulation to the end (cycles/s and the machining time).

    .venv/bin/python -m benchmarks.bench_motion [--blocks N] [--full-blocks N] [--chain-blocks N]
"""

from __future__ import annotations

import argparse
import os
import time

from benchmarks.bench_engine import area_header, long_program
from benchmarks.bench_motion_tools import decode_rate
from benchmarks.bench_motion_tools import machine as tools_machine
from hli_server.commands.check import BATCH_ENV, check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from schemas.wire import ProgramState

CONTOUR_ON = "#CONTOUR MODE [DEV PATH_DEV=0.5]\nG261\n"


def contoured(text: str) -> str:
    """The program with contouring switched on after its first block."""
    first, rest = text.split("\n", 1)
    return f"{first}\n{CONTOUR_ON}{rest}"


def _run_to_end(text: str, machine: Machine | None = None) -> tuple[int, float, int]:
    """Cycles the program takes, wall seconds, corners contoured (the demo machine unless ``machine``)."""
    machine = machine if machine is not None else Machine(load_machine(None))
    ch = machine.channel(1)
    ch.load_program(text, "bench-motion")
    ch.request_start()
    machine.step(1)
    began = time.perf_counter()
    start_cycle = machine.cycle
    while ch.state in (ProgramState.RUNNING, ProgramState.HELD):
        machine.step(10)
    elapsed = time.perf_counter() - began
    assert ch.state == ProgramState.FINISHED, [a.message for a in machine.alarm_history]
    return machine.cycle - start_cycle, elapsed, ch.decoder.contour.corners


def bench_full(blocks: int) -> None:
    text = long_program(blocks)
    _run_to_end(text)  # warm-up
    plain_cycles, plain_s, _ = _run_to_end(text)
    cycles, seconds, corners = _run_to_end(contoured(text))
    rate, plain_rate = cycles / seconds, plain_cycles / plain_s
    print(f"full simulation, contouring on ({corners:,} corners): {rate:,.0f} cycles/s")
    print(f"reference: the same program without contouring: {plain_rate:,.0f} cycles/s")
    print(f"ratio: {rate / plain_rate:.2f} (with / without)")
    print(f"machining time with contouring: {cycles:,} cycles")
    print(f"reference: without contouring: {plain_cycles:,} cycles")
    print(f"ratio: {cycles / plain_cycles:.2f} (with / without; below 1: the corners are not stops)")


def _geometry(text: str, exact: bool) -> tuple[float, int]:
    """``check --geometry-only`` blocks/s; ``exact``: block by block (``HLI_BATCH_CHECK=0``), the way a
    program with contouring on is always checked."""
    saved = os.environ.get(BATCH_ENV)
    os.environ[BATCH_ENV] = "0" if exact else "1"
    try:
        result = check_program(Machine(load_machine(None)), text, geometry_only=True)
    finally:
        if saved is None:
            del os.environ[BATCH_ENV]
        else:
            os.environ[BATCH_ENV] = saved
    assert result.completed, result.to_json()["alarms"]
    return result.blocks / result.elapsed_s, result.blocks


def _best(text: str, other: str, rounds: int = 2) -> tuple[float, float, float, int]:
    """Best rates, run alternately (the first run pays for warm-up): ``text`` exact, ``other`` (with
    contouring: exact by itself), ``text`` batched."""
    a = b = c = 0.0
    count = 0
    for _ in range(rounds):
        a = max(a, _geometry(text, exact=True)[0])
        rate, count = _geometry(other, exact=False)
        b = max(b, rate)
        c = max(c, _geometry(text, exact=False)[0])
    return a, b, c, count


def bench_geometry(blocks: int) -> None:
    text = long_program(blocks)
    for label, head in (("", ""), ("20 active areas, ", area_header())):
        plain, rate, batched, count = _best(head + text, head + contoured(text))
        print(f"check --geometry-only, {label}contouring on: {rate:,.0f} blocks/s ({count:,} blocks)")
        print(f"reference: {label}without contouring, exact path (block by block): {plain:,.0f} blocks/s")
        print(f"ratio: {rate / plain:.2f} (with / without)")
        print(f"(without contouring, batched: {batched:,.0f} blocks/s; with contouring the batch is off)")


CHAIN_ON = "#CS ON [5, 5, 0, 0, 0, 10]\nD1 Z0\nG41\n"
"""The frame, the tool (its length taken at ``Z0``) and the compensation of the chained case."""


def chained(text: str) -> str:
    """The program with #CS, D1, G41 and contouring on together after its first block (M-30); G40 with
    a departure line before its end."""
    first, rest = text.split("\n", 1)
    body, end = rest.rstrip("\n").rsplit("\n", 1)
    return f"{first}\n{CHAIN_ON}{CONTOUR_ON}{body}\nG40 X10 Y-20\n{end}\n"


def bench_chain(blocks: int, full_blocks: int, rounds: int = 2) -> None:
    text, plain = chained(long_program(blocks)), long_program(blocks)
    best = best_plain = 0.0
    motions = plain_motions = 0
    for _ in range(rounds):  # alternately, best of ``rounds``
        rate, motions = decode_rate(text)
        best = max(best, rate)
        rate, plain_motions = decode_rate(plain)
        best_plain = max(best_plain, rate)
    print(
        f"decoding, #CS + D1 G41 + contouring ({blocks:,} blocks, {motions:,} motions): {best:,.0f} blocks/s"
    )
    print(f"reference: the exact path without them ({plain_motions:,} motions): {best_plain:,.0f} blocks/s")
    print(f"ratio: {best / best_plain:.2f} (with / without)")
    text, plain = chained(long_program(full_blocks)), long_program(full_blocks)
    _run_to_end(plain, tools_machine())  # warm-up
    plain_cycles, plain_s, _ = _run_to_end(plain, tools_machine())
    cycles, seconds, corners = _run_to_end(text, tools_machine())
    rate, plain_rate = cycles / seconds, plain_cycles / plain_s
    print(f"full simulation, #CS + G41 + contouring ({corners:,} corners): {rate:,.0f} cycles/s")
    print(f"reference: the exact path without them: {plain_rate:,.0f} cycles/s")
    print(f"ratio: {rate / plain_rate:.2f} (with / without)")
    print(f"machining time, chained: {cycles:,} cycles; reference: {plain_cycles:,} cycles")
    print(f"ratio: {cycles / plain_cycles:.2f} (with / without; below 1: the corners are not stops)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--blocks", type=int, default=5_000, help="blocks of the geometry checks")
    ap.add_argument("--full-blocks", type=int, default=400, help="blocks of the full simulation")
    ap.add_argument("--chain-blocks", type=int, default=4_000, help="blocks of the chained decoding")
    args = ap.parse_args()
    bench_full(args.full_blocks)
    bench_geometry(args.blocks)
    bench_chain(args.chain_blocks, args.full_blocks)


if __name__ == "__main__":
    main()
