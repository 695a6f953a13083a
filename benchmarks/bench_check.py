"""``check --geometry-only`` (N-10) on a program that runs close to 20 areas, against its references.

The program (``benchmarks/programs.py``, ``near_area_lines``): lines and G02/G03 arcs round every one of
the 19 protection areas 0.5..2 mm off them and along the work polygon's edges 0.5..2 mm inside it, on
the full machine (``machines/full.toml``) after its 20 areas are defined and activated; it touches
nothing, so every block is checked exactly to the end. Goal: 200,000 blocks/s or more, memory flat
however long the program, and at least 1.0x LinuxCNC's ``rs274`` on the same moves.

``check --geometry-only`` runs as a batch (``hli_server/engine/batch.py``): plain motion lines tokenized
and checked with numpy a megabyte at a time, only the blocks a conservative prefilter cannot clear (and
every other line) through the exact decoder (docs/performance.md, docs/check.md).

References, measured in the same run, interleaved round by round (best of ``--rounds``):

* the same check of the same moves without the areas (what the 20 areas cost);
* the exact path, block by block (``HLI_BATCH_CHECK=0``: what ``check`` did before the batch, and does
  with ``--plot``), on the same program (skip with ``--no-exact``);
* ``rs274 -g`` (LinuxCNC's C++ interpreter, Debian's ``linuxcnc-uspace``) on the same moves in its
  dialect, without areas (it has none), timed as a process; skipped with a note where it is absent;
* shapely's batched ``intersects`` of all the program's lines against the 20 areas in one call (the
  honest reference for the area check: it answers only "touches or not", for lines only);
* the same moves (a fifth as many) with other lines among them, batch against the exact path: a comment
  every 5 motion lines (comment lines do not end a stretch), an ``M08`` line every 50, 200 and 1,000
  (they do: stretches shorter than ``SMALL_RUN`` + ``SMALL_RUN_PER_AREA`` per active area go block by
  block);
* peak memory (``ru_maxrss``) of ``hli-server check`` processes on the program and on one twice as long:
  a streaming check stays flat.

Then the hard case for arcs (``near_area_arcs``): a program of as many motion blocks, most of
them arcs close to the same 20 areas (rings of G02/G03 and short chords hugging the protection circles,
offset curves and bulging arcs round the squares, travel arcs, arcs in G18 and G19 beside the areas,
G161/G162 tour by tour), against ``rs274 -g`` on the same moves (``near_area_arcs_rs274``), the same
program without areas, and the plain-line figure above, all in the same run; the exact path on
its first 1/200 (an arc in G18/G19 is cut into chords there: slow).

With ``--before DIR`` (another checkout of this repository with its engine built, e.g. the commit
before a change, ``python setup.py build_ext --inplace`` there for the compiled engine), the plain-line
and the arc programs are also checked by that engine and by this one, each in a process of its own,
interleaved round by round: before and after in the same run.

    .venv/bin/python -m benchmarks.bench_check [--blocks N] [--rounds R] [--only-arcs] [--before DIR]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.programs import (
    FULL_MACHINE,
    PROTECTIONS,
    WORK_POLYGON,
    _near_moves,
    interleaved,
    near_area_arcs,
    near_area_arcs_rs274,
    near_area_lines,
    near_area_lines_rs274,
    write_lines,
)
from hli_server._compiled import ENGINE_COMPILED
from hli_server.commands.check import BATCH_ENV, check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.engine.batch import BatchGeometryCheck
from hli_server.engine.planner import Marker, MarkerKind


def _ours(path: Path, exact: bool = False) -> tuple[float, int]:
    machine = Machine(load_machine(FULL_MACHINE))
    saved = os.environ.get(BATCH_ENV)
    os.environ[BATCH_ENV] = "0" if exact else "1"
    try:
        with path.open(encoding="utf-8", newline="") as f:
            began = time.perf_counter()
            result = check_program(machine, f, geometry_only=True)
            elapsed = time.perf_counter() - began
    finally:
        if saved is None:
            os.environ.pop(BATCH_ENV, None)
        else:
            os.environ[BATCH_ENV] = saved
    assert result.completed, result.to_json()["alarms"][:2]
    assert not result.alarms, result.to_json()["alarms"][:2]
    return elapsed, result.blocks


def _exact_share(path: Path) -> tuple[int, int]:
    """How many of the program's blocks the batch handed to the exact decoder, of how many (untimed)."""
    machine = Machine(load_machine(FULL_MACHINE))
    batch = BatchGeometryCheck(machine.channel(1))
    with path.open(encoding="utf-8", newline="") as f:
        for items in batch.items(f):
            for item in items:  # the area definitions and activation run, as in check_program
                if isinstance(item, Marker) and item.kind == MarkerKind.ACTION:
                    item.payload()
    return batch.exact_blocks, batch.exact_blocks + batch.batched_blocks


_TIMED = """
import sys, time
from hli_server._compiled import ENGINE_COMPILED
from hli_server.commands.check import check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
machine = Machine(load_machine(sys.argv[1]))
with open(sys.argv[2], encoding="utf-8", newline="") as f:
    began = time.perf_counter()
    result = check_program(machine, f, geometry_only=True)
    elapsed = time.perf_counter() - began
assert result.completed and not result.alarms
print(result.blocks / elapsed, "compiled" if ENGINE_COMPILED else "pure")
"""


def _ours_in(tree: Path, path: Path) -> tuple[float, str]:
    """blocks/s of ``check --geometry-only`` on ``path`` with the engine of the checkout ``tree``, in a
    process of its own (and whether that engine ran compiled)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    env.pop(BATCH_ENV, None)
    done = subprocess.run(
        [sys.executable, "-c", _TIMED, str(FULL_MACHINE), str(path)],
        capture_output=True,
        text=True,
        check=True,
        timeout=1200,
        env=env,
        cwd=tree,
    )
    rate, engine = done.stdout.split()
    return float(rate), engine


def _arc_share(path: Path) -> float:
    """Per cent of the program's motion blocks that are arcs."""
    arcs = moves = 0
    with path.open(encoding="utf-8") as f:
        for line in f:
            if line.startswith(("G01", "G02", "G03")):
                moves += 1
                arcs += not line.startswith("G01")
    return 100.0 * arcs / max(moves, 1)


def _rs274(path: Path, tool_table: Path, out: Path) -> float | None:
    exe = shutil.which("rs274")
    if exe is None:
        return None
    began = time.perf_counter()
    subprocess.run(
        [exe, "-t", str(tool_table), "-g", str(path), str(out)],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        check=True,
        timeout=600,
    )
    return time.perf_counter() - began


def _shapely_batched(blocks: int) -> tuple[float, int] | None:
    try:
        import numpy as np
        import shapely
    except ImportError:
        return None
    coords = []
    x, y = 0.0, 0.0
    for kind, v in _near_moves(blocks):
        if kind == "L":
            coords.append(((x, y), (v[0], v[1])))
        x, y = v[0], v[1]
    shapes = [shapely.Polygon(WORK_POLYGON).exterior]  # leaving the work area = touching its boundary
    for shape, cx, cy, size in PROTECTIONS:
        if shape == "CIRC":
            shapes.append(shapely.Point(cx, cy).buffer(size, quad_segs=16))
        else:
            shapes.append(shapely.box(cx - size, cy - size, cx + size, cy + size))
    geoms = np.array(shapes, dtype=object)
    arr = np.array(coords)
    began = time.perf_counter()
    lines = shapely.linestrings(arr)
    hits = int(shapely.intersects(lines[:, None], geoms[None, :]).any(axis=1).sum())
    elapsed = time.perf_counter() - began
    assert hits == 0, (
        f"shapely finds {hits} lines touching an area: the program is not 'near without touching'"
    )
    return elapsed, len(coords)


def _peak_rss_mb(path: Path) -> float:
    """Peak resident memory of an ``hli-server check --geometry-only`` process on ``path`` [MB]."""
    code = (
        "import sys\n"
        "from hli_server.cli import main\n"
        "sys.argv = ['hli-server', 'check', '--geometry-only', '--config', sys.argv[1], sys.argv[2]]\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        # VmHWM, not ru_maxrss: Linux keeps ru_maxrss across exec (it would be this benchmark's own)
        "hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM')][0].split()[1]\n"
        "print(hwm, file=sys.stderr)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(FULL_MACHINE), str(path)],
        capture_output=True,
        text=True,
        check=True,
        timeout=1200,
    )
    return int(done.stderr.strip().splitlines()[-1]) / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--blocks", type=int, default=1_000_000, help="motion blocks of the program")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--no-memory", action="store_true", help="skip the peak-memory comparison")
    ap.add_argument("--no-exact", action="store_true", help="skip the exact (block by block) reference")
    ap.add_argument(
        "--only-arcs", action="store_true", help="only the arc program, the lines and rs274 on both"
    )
    ap.add_argument("--before", type=Path, help="another checkout: its engine against this one, same run")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        with_areas, plain, ngc = d / "near.nc", d / "near_plain.nc", d / "near.ngc"
        write_lines(with_areas, near_area_lines(args.blocks))
        write_lines(plain, near_area_lines(args.blocks, with_areas=False))
        write_lines(ngc, near_area_lines_rs274(args.blocks))
        arcs, arcs_plain, arcs_ngc = d / "arcs.nc", d / "arcs_plain.nc", d / "arcs.ngc"
        arcs_short = d / "arcs_short.nc"
        write_lines(arcs, near_area_arcs(args.blocks))
        write_lines(arcs_plain, near_area_arcs(args.blocks, with_areas=False))
        write_lines(arcs_ngc, near_area_arcs_rs274(args.blocks))
        write_lines(arcs_short, near_area_arcs(max(args.blocks // 200, 1)))
        tool_table = d / "tool.tbl"
        tool_table.write_text("T1 P1 D0 Z0 ;\n", encoding="utf-8")
        mixes = [] if args.only_arcs else [(5, "(a comment)"), (50, "M08"), (200, "M08"), (1000, "M08")]
        mixed = [d / f"mixed{k}.nc" for k in range(len(mixes))]
        for (every, extra), path in zip(mixes, mixed, strict=True):
            write_lines(path, interleaved(near_area_lines(args.blocks // 5), every, extra))
        best_mixed = [[0.0, 0.0] for _ in mixes]
        best = {
            "areas": 0.0,
            "plain": 0.0,
            "rs274": 0.0,
            "exact": 0.0,
            "arcs": 0.0,
            "arcs_plain": 0.0,
            "arcs_rs274": 0.0,
            "arcs_exact": 0.0,
        }
        blocks = arc_blocks = 0
        here = Path(__file__).resolve().parent.parent
        trees = {"before": args.before.resolve(), "after": here} if args.before else {}
        versus = {(name, kind): 0.0 for name in trees for kind in ("lines", "arcs")}
        engines: dict[str, str] = {}
        for _ in range(args.rounds):
            for (name, kind), figure in versus.items():
                rate, engines[name] = _ours_in(trees[name], with_areas if kind == "lines" else arcs_short)
                versus[name, kind] = max(figure, rate)
            t, blocks = _ours(with_areas)
            best["areas"] = max(best["areas"], blocks / t)
            t, arc_blocks = _ours(arcs)
            best["arcs"] = max(best["arcs"], arc_blocks / t)
            t, n = _ours(arcs_plain)
            best["arcs_plain"] = max(best["arcs_plain"], n / t)
            t, n = _ours(plain)
            best["plain"] = max(best["plain"], n / t)
            t_rs = _rs274(arcs_ngc, tool_table, d / "rs274_arcs.out")
            if t_rs is not None:
                best["arcs_rs274"] = max(best["arcs_rs274"], (args.blocks + 2) / t_rs)
            if not args.no_exact:
                t, n = _ours(arcs_short, exact=True)
                best["arcs_exact"] = max(best["arcs_exact"], n / t)
            if not args.no_exact and not args.only_arcs:
                t, n = _ours(with_areas, exact=True)
                best["exact"] = max(best["exact"], n / t)
            for path, figures in zip(mixed, best_mixed, strict=True):
                for k, exact in enumerate((False, True)):
                    t, n = _ours(path, exact=exact)
                    figures[k] = max(figures[k], n / t)
            t_rs = _rs274(ngc, tool_table, d / "rs274.out")
            if t_rs is not None:
                best["rs274"] = max(best["rs274"], (args.blocks + 2) / t_rs)
        engine = "compiled" if ENGINE_COMPILED else "pure Python"
        print(
            f"check --geometry-only, 20 active areas ({engine} engine): {best['areas']:,.0f} blocks/s "
            f"({blocks:,} blocks, best of {args.rounds})"
        )
        print(
            f"reference: the same moves without areas: {best['plain']:,.0f} blocks/s; "
            f"ratio with / without areas: {best['areas'] / best['plain']:.2f}"
        )
        exact, total = _exact_share(with_areas)
        print(
            f"blocks the prefilter could not clear, decoded exactly: {exact:,} of {total:,} "
            f"({100.0 * exact / max(total, 1):.2f} %)"
        )
        if best["exact"]:
            print(
                f"reference: the exact path, block by block ({BATCH_ENV}=0), same program: "
                f"{best['exact']:,.0f} blocks/s; batch / exact: {best['areas'] / best['exact']:.1f}"
            )
        if best["rs274"]:
            print(
                f"reference: LinuxCNC rs274 -g, same moves, no areas: {best['rs274']:,.0f} blocks/s; "
                f"ratio ours (20 areas) / rs274: {best['areas'] / best['rs274']:.2f}, "
                f"ours without areas / rs274: {best['plain'] / best['rs274']:.2f}"
            )
        else:
            print("reference rs274: skipped (not installed; Debian: apt-get install linuxcnc-uspace)")
        exact_arcs, total_arcs = _exact_share(arcs)
        print(
            f"mostly arcs near the same 20 areas ({arc_blocks:,} blocks, {_arc_share(arcs):.0f} % of them "
            f"arcs): {best['arcs']:,.0f} blocks/s; without areas: {best['arcs_plain']:,.0f} blocks/s; "
            f"arcs / plain lines (same run): {best['arcs'] / best['areas']:.2f}; decoded exactly: "
            f"{exact_arcs:,} of {total_arcs:,}"
        )
        if best["arcs_rs274"]:
            print(
                f"reference: LinuxCNC rs274 -g, the same arcs, no areas: {best['arcs_rs274']:,.0f} blocks/s; "
                f"ratio ours (20 areas) / rs274: {best['arcs'] / best['arcs_rs274']:.2f}, "
                f"ours without areas / rs274: {best['arcs_plain'] / best['arcs_rs274']:.2f}"
            )
        if best["arcs_exact"]:
            print(
                f"reference: the exact path on the first {max(args.blocks // 200, 1):,} blocks of the arc "
                f"program: {best['arcs_exact']:,.0f} blocks/s; batch / exact: "
                f"{best['arcs'] / best['arcs_exact']:.1f}"
            )
        for (every, extra), (batch, exact) in zip(mixes, best_mixed, strict=True):
            print(
                f"the same moves ({args.blocks // 5:,}) with {extra!r} after every {every} motion lines: "
                f"{batch:,.0f} blocks/s; the exact path: {exact:,.0f} blocks/s; "
                f"batch / exact: {batch / exact:.2f}"
            )
        shp = None if args.only_arcs else _shapely_batched(args.blocks)
        if shp is not None:
            t, n = shp
            print(
                f"reference: shapely batched intersects, the program's {n:,} lines x 20 areas, one call: "
                f"{n / t:,.0f} lines/s (yes/no only); ratio ours / shapely: {best['areas'] / (n / t):.2f}"
            )
        for kind in ("lines", "arcs") if trees else ():
            before, after = versus["before", kind], versus["after", kind]
            print(
                f"before / after ({kind} near 20 areas{'' if kind == 'lines' else ', the first 1/200'}, "
                f"{engines['before']} / {engines['after']} engine, own "
                f"processes, same run): {before:,.0f} / {after:,.0f} blocks/s; after / before: "
                f"{after / before:.2f}"
            )
        if not args.no_memory and not args.only_arcs:
            double = d / "near2.nc"
            write_lines(double, near_area_lines(2 * args.blocks))
            m1, m2 = _peak_rss_mb(with_areas), _peak_rss_mb(double)
            print(
                f"peak memory of hli-server check: {m1:,.0f} MB ({args.blocks:,} blocks), "
                f"{m2:,.0f} MB ({2 * args.blocks:,} blocks); file sizes "
                f"{with_areas.stat().st_size / 1e6:,.0f} and {double.stat().st_size / 1e6:,.0f} MB"
            )


if __name__ == "__main__":
    main()
