"""Coordinate systems and tools (M-10..M-18): decoding and checking a pocket with a rotated #CS and tool
radius compensation, against the same programmed path without them.

The program: ``--blocks`` motion blocks of a zig-zag pocket (lines and G02/G03 half circles) inside a
work area that is active (so every block goes through the area path check). Two runs, interleaved round by
round, best of ``--rounds``, both block by block through the exact decoder (the batch check decodes block
by block while a frame or the compensation is active, so this is the path ``check`` takes):

* compensated: ``#CS ON [5, 5, 0, 0, 0, 10]`` (shift and a 10° turn), ``D1 G41`` (2 mm tool, G25
  corners): every block goes through the radius compensation, the frames and the tool-tip check;
* reference: the same blocks with neither.

    .venv/bin/python -m benchmarks.bench_motion_tools [--blocks N] [--rounds R]
"""

from __future__ import annotations

import argparse
import time

from hli_server._compiled import ENGINE_COMPILED
from hli_server.engine.machine import Machine
from hli_server.engine.planner import MarkerKind, Motion
from schemas.config import AxisConfig, ChannelConfig, MachineConfig

AREA = """\
#CONTROL AREA BEGIN [ID1 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
G01 F1000 X-60 Y-60
X260
Y260
X-60
Y-60
#CONTROL AREA END
#CONTROL AREA ON [ID1]
"""


def pocket(blocks: int, compensated: bool) -> str:
    lines = ["%pocket", "G01 X0 Y0 F3000", AREA.rstrip("\n")]
    if compensated:
        lines += ["#CS ON [5, 5, 0, 0, 0, 10]", "D1 G41"]
    lines.append("G01 X10 Y10")
    y = 10.0
    k = 0
    while k < blocks:
        lines.append(f"G01 X150 Y{y:.3f}")
        lines.append(f"G03 X150 Y{y + 6:.3f} I0 J3")
        lines.append(f"G01 X10 Y{y + 6:.3f}")
        lines.append(f"G02 X10 Y{y + 12:.3f} I0 J3")
        k += 4
        y += 12.0
        if y > 170:
            y = 10.0
            lines.append("G01 X10 Y10")
            k += 1
    if compensated:
        lines.append("G01 G40 X0 Y0")
    lines.append("M30")
    return "\n".join(lines) + "\n"


def machine() -> Machine:
    names = ["X", "Y", "Z"]
    axes = [
        AxisConfig(number=i + 1, name=n, swe_neg=-10_000_000, swe_pos=10_000_000) for i, n in enumerate(names)
    ]
    tools = [{"number": 1, "length": 500_000, "radius": 20_000}]
    return Machine(MachineConfig(axes=axes, channels=[ChannelConfig(axes=names, tools=tools)]))


def decode_rate(program: str) -> tuple[float, int]:
    """Blocks per second decoding and checking the whole program; the number of motions."""
    m = machine()
    ch = m.channel(1)
    ch.interpreter.start(program, "pocket")
    ch.decoder.start(ch.interpreter, ch.setpoints())
    motions = 0
    t0 = time.perf_counter()
    while not ch.decoder.finished:
        items = ch.decoder.next_items()
        if not items:
            ch.interpreter.refill()  # the interpreter's budget per cycle (the machine refills it each cycle)
        for item in items:
            if isinstance(item, Motion):
                motions += 1
            elif item.kind is MarkerKind.ERROR:
                raise SystemExit(f"the benchmark program failed: {item.payload}")
    elapsed = time.perf_counter() - t0
    return ch.decoder.blocks_decoded / elapsed, motions


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--blocks", type=int, default=20_000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    plain, comp = pocket(args.blocks, False), pocket(args.blocks, True)
    best_plain = best_comp = 0.0
    n_plain = n_comp = 0
    for _ in range(args.rounds):
        rate, n_plain = decode_rate(plain)
        best_plain = max(best_plain, rate)
        rate, n_comp = decode_rate(comp)
        best_comp = max(best_comp, rate)
    engine = "compiled" if ENGINE_COMPILED else "pure Python"
    print(f"engine: {engine}; {args.blocks:,} pocket blocks with an active work area, best of {args.rounds}")
    print(f"#CS + G41 (compensated) : {best_comp:12,.0f} blocks/s ({n_comp:,} motions)")
    print(f"programmed path (ref.)  : {best_plain:12,.0f} blocks/s ({n_plain:,} motions)")
    print(f"ratio                   : {best_comp / best_plain:12.2f}x the reference")


if __name__ == "__main__":
    main()
