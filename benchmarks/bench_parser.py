"""Throughput of the NC parser (E-04): blocks/s of ``iter_blocks`` on simple motion lines.

The reference, measured in the same run over the same text, is a plain ``str.split()`` per line
(the least any line-based parser has to do), so the figure can be compared across machines by the
ratio rather than by the absolute number.

    .venv/bin/python benchmarks/bench_parser.py [--lines N] [--repeat R]
"""

from __future__ import annotations

import argparse
import io
import time
from collections.abc import Callable

from hli_server.engine.nc.parser import iter_blocks

AXES = ("X", "Y", "Z")


def make_program(lines: int) -> str:
    """``lines`` lines like ``N100 G01 X12.5 Y-3.25 F1000`` (numbers vary, as in a real program)."""
    return "".join(
        f"N{10 * (i + 1)} G01 X{(i % 1000) * 0.5:.2f} Y-{(i % 777) * 0.25:.2f} F1000\n" for i in range(lines)
    )


def run_parser(text: str) -> int:
    count = 0
    for _ in iter_blocks(text, AXES):
        count += 1
    return count


def run_split(text: str) -> int:
    count = 0
    for line in io.StringIO(text, newline=""):  # the same lazy line iteration as iter_blocks
        if line.split():
            count += 1
    return count


def best_rate(fn: Callable[[str], int], text: str, repeat: int) -> tuple[float, int]:
    best = float("inf")
    count = 0
    for _ in range(repeat):
        t0 = time.perf_counter()
        count = fn(text)
        best = min(best, time.perf_counter() - t0)
    return count / best, count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lines", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    text = make_program(args.lines)
    sample = text.split("\n", 1)[0]
    parse_rate, parsed = best_rate(run_parser, text, args.repeat)
    split_rate, split = best_rate(run_split, text, args.repeat)
    assert parsed == split == args.lines, (parsed, split, args.lines)
    print(f"lines: {args.lines:,} like {sample!r}, best of {args.repeat}")
    print(f"iter_blocks : {parse_rate:12,.0f} blocks/s")
    print(f"str.split() : {split_rate:12,.0f} lines/s (reference)")
    print(f"ratio       : {split_rate / parse_rate:12.1f}x slower than str.split()")


if __name__ == "__main__":
    main()
