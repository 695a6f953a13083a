"""Cost of a kinematic transformation (K-09): the same program with ``#TRAFO ON`` against without.

The program is ``bench_engine``'s (squares of lines and quarter arcs, as a CAM system emits them) on the
five-axis machine (``hli_server/machines/five_axis.toml``), with the head tilted (A 30°, C 45°). With
``#KIN ID[5]`` / ``#TRAFO ON`` after its first block (the machine's CA head, RTCP, tool D1 of 100 mm)
the planner plans the tool tip and every cycle turns its point into the axes (the inverse transformation),
and every block's axes' path is computed and checked; without, the same text is plain three-axis motion.
Each figure against the same program without the transformation, in the same run:

1. full simulation of the program to its end: engine cycles per second of wall time, and the machining
   time (cycles; the same path of the tip: the same time, unless an axis limits the velocity);
2. ``check --geometry-only`` blocks per second (a transformation decodes block by block; the reference is
   the untransformed program's exact check, block by block, and its batch figure is printed too);
3. the same with the head turning: ``C`` changes with every block (a rotary axis moves, the axes' path is
   sampled every 0.25°).

    .venv/bin/python -m benchmarks.bench_kinematics [--blocks N] [--full-blocks N]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from benchmarks.bench_engine import long_program
from benchmarks.bench_motion import _run_to_end as run_to_end
from hli_server.commands.check import BATCH_ENV, check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine

MACHINE = Path(__file__).resolve().parents[1] / "hli_server" / "machines" / "five_axis.toml"
HEAD = "D1\nG01 X0 Y0 Z0 C45 A30\n"
ON = "#KIN ID[5]\n#TRAFO ON\n"


def plain(text: str) -> str:
    """The program with the head tilted after its first block, no transformation."""
    first, rest = text.split("\n", 1)
    return f"{first}\n{HEAD}{rest}"


def transformed(text: str) -> str:
    """The same with the CA head's RTCP transformation on after the tilt, off before the end."""
    first, rest = text.split("\n", 1)
    body, end = rest.rstrip("\n").rsplit("\n", 1)
    return f"{first}\n{HEAD}{ON}{body}\n#TRAFO OFF\n{end}\n"


def turning(text: str) -> str:
    """Every line of the program turns the head's C axis too (C 40°..50°)."""
    out = []
    for k, line in enumerate(text.split("\n")):
        if " G01 X" in line and not line.startswith("N1 "):
            line += f" C{40 + (k % 11)}"
        out.append(line)
    return "\n".join(out)


def machine() -> Machine:
    return Machine(load_machine(MACHINE))


def _run_to_end(text: str) -> tuple[int, float]:
    """Cycles the program takes on the five-axis machine and the wall seconds (``bench_motion``'s run)."""
    cycles, elapsed, _ = run_to_end(text, machine())
    return cycles, elapsed


def _geometry(text: str, exact: bool) -> tuple[float, int]:
    saved = os.environ.get(BATCH_ENV)
    os.environ[BATCH_ENV] = "0" if exact else "1"
    try:
        result = check_program(machine(), text, geometry_only=True)
    finally:
        if saved is None:
            del os.environ[BATCH_ENV]
        else:
            os.environ[BATCH_ENV] = saved
    assert result.completed, result.to_json()["alarms"]
    return result.blocks / result.elapsed_s, result.blocks


def bench_full(blocks: int, rounds: int = 2) -> None:
    base = long_program(blocks)
    for label, make in (("head tilted", lambda t: t), ("head turning", turning)):
        text = make(base)
        _run_to_end(plain(text))  # warm-up
        best = best_plain = 0.0
        cycles = plain_cycles = 0
        for _ in range(rounds):  # alternately, best of ``rounds``
            plain_cycles, s = _run_to_end(plain(text))
            best_plain = max(best_plain, plain_cycles / s)
            cycles, s = _run_to_end(transformed(text))
            best = max(best, cycles / s)
        print(f"full simulation, {label}, #TRAFO ON: {best:,.0f} cycles/s")
        print(f"reference: the same program without the transformation: {best_plain:,.0f} cycles/s")
        print(f"ratio: {best / best_plain:.2f} (with / without)")
        print(f"machining time with the transformation: {cycles:,} cycles; without: {plain_cycles:,} cycles")


def bench_geometry(blocks: int, rounds: int = 2) -> None:
    base = long_program(blocks)
    for label, make in (("head tilted", lambda t: t), ("head turning", turning)):
        text = make(base)
        exact = rate = batched = 0.0
        count = 0
        for _ in range(rounds):
            exact = max(exact, _geometry(plain(text), exact=True)[0])
            r, count = _geometry(transformed(text), exact=False)
            rate = max(rate, r)
            batched = max(batched, _geometry(plain(text), exact=False)[0])
        print(f"check --geometry-only, {label}, #TRAFO ON: {rate:,.0f} blocks/s ({count:,} blocks)")
        print(f"reference: without the transformation, exact path (block by block): {exact:,.0f} blocks/s")
        print(f"ratio: {rate / exact:.2f} (with / without)")
        print(f"(without the transformation, batched: {batched:,.0f} blocks/s; with it the batch is off)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--blocks", type=int, default=5_000, help="blocks of the geometry checks")
    ap.add_argument("--full-blocks", type=int, default=400, help="blocks of the full simulation")
    args = ap.parse_args()
    bench_full(args.full_blocks)
    bench_geometry(args.blocks)


if __name__ == "__main__":
    main()
