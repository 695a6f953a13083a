"""The NC language's front end (N-01..N-08) against what it replaced and what it must not be slower than.

1. The geometry check of plain programs (``check --geometry-only`` as a batch, the full machine): plain
   lines without areas, arcs near 20 areas (``near_area_arcs``), lines and arcs near 20 areas
   (``near_area_lines``), by this checkout and by another git revision
   (``--reference main``: the code before the language), each in a process of its own, interleaved round
   by round, best of ``--rounds``. Both processes run the same engine kind: pure Python unless the
   reference checkout is compiled too (``HLI_PURE_PYTHON`` is set for both where it is not): a ``git
   archive`` is not; ``--reference-dir DIR`` takes a checkout of the reference that may be (compiled in
   place: ``python setup.py build_ext --inplace`` there), and with this checkout compiled (``make
   compile``) both run compiled.
2. A program with loops, subroutines and variables (a pocket cleared by a ``$FOR`` over depths and
   a ``$WHILE`` over passes, each pass a global subroutine with ``@P`` parameters, variables for the
   step and the direction) against the exact path (block by block, ``HLI_BATCH_CHECK=0``) of the same
   moves written out as plain lines: the language may not be slower than the exact path.
3. The same two in a full check (cycles), the language program against its plain twin.
4. The realtime clock with blocks that do not move (``--still-blocks`` of them, a running machine, cycle by
   cycle): the longest cycle and the median, this checkout against the reference (which decoded them all
   in one cycle: 800,000 such blocks stalled the clock 3.9 s), and a ``$WHILE`` without motion.

    .venv/bin/python -m benchmarks.bench_language [--blocks N] [--rounds R] [--reference REV]
        [--reference-dir DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.programs import FULL_MACHINE, near_area_arcs, near_area_lines, write_lines
from hli_server._compiled import ENGINE_COMPILED, PURE_ENV

ROOT = Path(__file__).resolve().parents[1]

POCKET_SUB = """\
%pass
N10 G90 G01 X[@P1] Y[@P2] F6000
N20 $FOR P20 = 1, @P5
N30   G91 X[@P3 * V.P.DIR] Y[@P4]
N40   V.P.DIR = -V.P.DIR
N50 $ENDFOR
N60 G90
N70 M17
"""
POCKET_MAIN = """\
%pocket
N10 G90 G17 G01 X0 Y0 Z0 F6000
#VAR
  V.P.DIR = 1
  V.P.STEP : REAL64 = 0.5
#ENDVAR
N20 P1 = 0
N30 $FOR P2 = 0, {levels}
N40   G01 Z[-P2 * 0.01] F3000
N50   P3 = 0
N60   $WHILE P3 < {passes}
N70     L CYCLE [NAME=pass.nc @P1=-100 + P3 * V.P.STEP @P2=-60 @P3=40 @P4=V.P.STEP @P5={zigzag}]
N80     P3 = P3 + 1
N90     $IF P3 MOD 10 == 0
N100      #MSG ["pass %d of level %d", P3, P2]
N110    $ENDIF
N120  $ENDWHILE
N130 $ENDFOR
N140 M30
"""


def pocket(blocks: int) -> tuple[str, dict[str, str]]:
    """The language program of about ``blocks`` motion blocks, and its subroutine."""
    zigzag, passes = 20, 20
    per_level = passes * (zigzag + 1) + 1
    levels = max(1, blocks // per_level)
    return POCKET_MAIN.format(levels=levels - 1, passes=passes, zigzag=zigzag), {"pass.nc": POCKET_SUB}


_RUNNER = """
import json, os, sys, time
from pathlib import Path
from hli_server.commands.check import check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
path, machine_file, geometry, library = sys.argv[1], sys.argv[2], sys.argv[3] == "1", sys.argv[4]
config = load_machine(Path(machine_file) if machine_file else None)
if library:
    from hli_server.engine.programs import MemoryLibrary
    files = {p.name: p.read_text() for p in Path(library).glob("*.nc") if p.name != Path(path).name}
    machine = Machine(config, programs=MemoryLibrary(files))
else:
    machine = Machine(config)
with open(path, encoding="utf-8", newline="") as f:
    began = time.perf_counter()
    result = check_program(machine, f, geometry_only=geometry)
    elapsed = time.perf_counter() - began
errors = [a.number for a in result.alarms if str(a.severity) == "error"]
print(json.dumps({"elapsed": elapsed, "blocks": result.blocks, "errors": errors, "cycles": machine.cycle}))
"""


_REALTIME = """
import json, statistics, sys, time
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from schemas.wire import ProgramState
path, limit = sys.argv[1], int(sys.argv[2])
machine = Machine(load_machine(None))
ch = machine.channel(1)
with open(path, encoding="utf-8") as f:
    ch.load_program(f.read())
ch.request_start()
times, cpu = [], []
for _ in range(limit):
    began, began_cpu = time.perf_counter(), time.thread_time()
    machine.step(1)
    times.append(time.perf_counter() - began)
    cpu.append(time.thread_time() - began_cpu)
    if ch.state not in (ProgramState.RUNNING, ProgramState.HELD):
        break
print(json.dumps({"cycles": len(times), "max": max(times), "median": statistics.median(times),
                  "cpu_max": max(cpu), "total": sum(times), "state": str(ch.state)}))
"""


def _realtime(checkout: Path, program: Path, env: dict[str, str], limit: int) -> dict[str, float]:
    done = subprocess.run(
        [sys.executable, "-c", _REALTIME, str(program), str(limit)],
        cwd=checkout,
        env={**env, "PYTHONPATH": str(checkout)},
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-3000:])
    out: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return out


def _run(
    checkout: Path,
    program: Path,
    machine: Path | None,
    geometry: bool,
    env: dict[str, str],
    library: Path | None = None,
) -> dict[str, float]:
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            _RUNNER,
            str(program),
            str(machine or ""),
            "1" if geometry else "0",
            str(library or ""),
        ],
        cwd=checkout,
        env={**env, "PYTHONPATH": str(checkout)},
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-3000:])
    out: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    if out["errors"]:
        raise RuntimeError(f"{program.name} in {checkout}: alarms {out['errors']}")
    return out


def _reference_checkout(rev: str, into: Path) -> Path | None:
    """A copy of revision ``rev`` of this repository (git archive), or None where git cannot give one."""
    target = into / "reference"
    target.mkdir()
    archive = subprocess.run(["git", "archive", rev], cwd=ROOT, capture_output=True, check=False)
    if archive.returncode != 0:
        return None
    subprocess.run(["tar", "-x", "-C", str(target)], input=archive.stdout, check=True)
    return target


def _compiled_checkout(checkout: Path) -> bool:
    """Has ``checkout`` its engine compiled in place (mypyc's modules beside the sources)?"""
    return any((checkout / "hli_server" / "engine").glob("native__mypyc*.so"))


def _unrolled(language: Path, files: dict[str, str], out: Path) -> tuple[int, int]:
    """The language program's moves written out as plain lines (G90 absolute targets, exact floats):
    how many moves, and how many NC blocks (statements) the language program runs for them."""
    from hli_server.engine.nc import Compiler, Interpreter
    from hli_server.engine.nc.blocks import Block
    from tests.unit.nc_helpers import FakeHost

    host = FakeHost(files, axes=("X", "Y", "Z"))
    it = Interpreter(Compiler(("X", "Y", "Z"), ("X", "Y", "Z")), host, budget=None)
    it.start(language.read_text(encoding="utf-8"), "pocket")
    position = {"X": 0.0, "Y": 0.0, "Z": 0.0}
    absolute = True
    lines = ["N1 G90 G17 G01 X0 Y0 Z0 F6000"]
    while (out_ := it.next()) is not None:
        if not isinstance(out_, Block):
            continue
        if 90 in out_.g_codes:
            absolute = True
        if 91 in out_.g_codes:
            absolute = False
        if 30 in out_.m_codes:
            break
        if not out_.axes:
            continue
        for name, value in out_.axes:
            position[name] = value if absolute else position[name] + value
        feed = f" F{out_.feed:g}" if out_.feed is not None else ""
        lines.append("G01 " + " ".join(f"{k}{v!r}" for k, v in position.items()) + feed)
    lines.append("M30")
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return len(lines) - 2, it.statements


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--blocks", type=int, default=200_000, help="motion blocks of the plain program")
    ap.add_argument(
        "--arc-blocks",
        type=int,
        default=20_000,
        help="motion blocks of the arcs program (the reference decodes most arcs one by one: slow)",
    )
    ap.add_argument(
        "--language-blocks", type=int, default=50_000, help="motion blocks of the language program"
    )
    ap.add_argument(
        "--full-blocks", type=int, default=500, help="motion blocks of the language program in a full check"
    )
    ap.add_argument(
        "--still-blocks", type=int, default=800_000, help="blocks without motion on the running machine"
    )
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument(
        "--reference",
        default="main",
        help="git revision of the code before the language (with --reference-dir: its name in the output)",
    )
    ap.add_argument(
        "--reference-dir",
        type=Path,
        default=None,
        help="a checkout of the reference (compiled in place or not) instead of a git archive of --reference",
    )
    args = ap.parse_args()
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        near = d / "near.nc"
        write_lines(near, near_area_lines(args.blocks))
        reference = args.reference_dir or _reference_checkout(args.reference, d)
        compiled_here = ENGINE_COMPILED and not os.environ.get(PURE_ENV)
        if reference is not None and not (compiled_here and _compiled_checkout(reference)):
            # the reference copy is not compiled (or this one is not): both run pure Python, so that the
            # figures compare
            env[PURE_ENV] = "1"
        kind = "pure Python" if env.get(PURE_ENV) else ("compiled" if compiled_here else "pure Python")
        programs = {
            "plain lines (no areas)": d / "lines.nc",
            "arcs near 20 areas (near_area_arcs)": d / "arcs.nc",
            "lines and arcs near 20 areas (near_area_lines)": near,
        }
        write_lines(programs["plain lines (no areas)"], near_area_lines(args.blocks, with_areas=False))
        write_lines(programs["arcs near 20 areas (near_area_arcs)"], near_area_arcs(args.arc_blocks))
        for title, program in programs.items():
            _versus_reference(title, program, reference, env, args, kind)

        if args.still_blocks:
            _still(d, args, reference, env)

        # the language program against the exact path of its plain twin
        language, plain, moves, statements = _pocket_files(d / "lang", args.language_blocks)
        lang_env = dict(os.environ)
        exact_env = {**lang_env, "HLI_BATCH_CHECK": "0"}
        figures = {"language": 0.0, "exact": 0.0, "batch": 0.0, "full_language": 0.0, "full_plain": 0.0}
        for _ in range(args.rounds):
            out = _run(ROOT, language, None, True, lang_env, language.parent)
            figures["language"] = max(figures["language"], 1 / out["elapsed"])
            out = _run(ROOT, plain, None, True, exact_env)
            figures["exact"] = max(figures["exact"], 1 / out["elapsed"])
            out = _run(ROOT, plain, None, True, lang_env)
            figures["batch"] = max(figures["batch"], 1 / out["elapsed"])
        kind = "compiled" if ENGINE_COMPILED and not os.environ.get(PURE_ENV) else "pure Python"
        print(
            f"language program (loops, a global cycle with @P, variables; {moves:,} moves, {statements:,} NC "
            f"blocks run), geometry check ({kind}): {figures['language'] * statements:,.0f} NC blocks/s, "
            f"{figures['language'] * moves:,.0f} moves/s"
        )
        print(
            f"reference: the exact path (HLI_BATCH_CHECK=0) of the same moves as plain lines (one NC block "
            f"each): {figures['exact'] * moves:,.0f} blocks/s; ratio language / exact: "
            f"{figures['language'] * statements / (figures['exact'] * moves):.2f} per NC block, "
            f"{figures['language'] / figures['exact']:.2f} per move"
        )
        print(f"(the same plain lines as a batch: {figures['batch'] * moves:,.0f} moves/s)")

        # a full check (cycles) of a smaller pocket against its plain twin
        language, plain, moves, statements = _pocket_files(d / "full", args.full_blocks)
        for _ in range(max(1, args.rounds - 1)):
            out = _run(ROOT, language, None, False, lang_env, language.parent)
            figures["full_language"] = max(figures["full_language"], out["cycles"] / out["elapsed"])
            out = _run(ROOT, plain, None, False, lang_env)
            figures["full_plain"] = max(figures["full_plain"], out["cycles"] / out["elapsed"])
        print(
            f"full check (cycles, {moves:,} moves): "
            f"language program {figures['full_language']:,.0f} cycles/s, "
            f"its plain twin {figures['full_plain']:,.0f} cycles/s; "
            f"ratio {figures['full_language'] / figures['full_plain']:.2f}"
        )


def _versus_reference(
    title: str,
    program: Path,
    reference: Path | None,
    env: dict[str, str],
    args: argparse.Namespace,
    kind: str,
) -> None:
    """``check --geometry-only`` of ``program`` here and by the reference, interleaved, best of the rounds."""
    best = {"ours": 0.0, "reference": 0.0}
    blocks = 0
    for _ in range(args.rounds):
        out = _run(ROOT, program, FULL_MACHINE, True, env)
        blocks = int(out["blocks"])
        best["ours"] = max(best["ours"], blocks / out["elapsed"])
        if reference is not None:
            # the reference's own machine file: the configuration's rules may differ between the two
            ref_machine = reference / FULL_MACHINE.relative_to(ROOT)
            ref = _run(reference, program, ref_machine, True, env)
            best["reference"] = max(best["reference"], ref["blocks"] / ref["elapsed"])
    line = (
        f"{title}, check --geometry-only ({kind}): {best['ours']:,.0f} blocks/s ({blocks:,} blocks, best of "
        f"{args.rounds})"
    )
    if best["reference"]:
        line += (
            f"; reference {args.reference}, same program, same run: {best['reference']:,.0f} blocks/s; "
            f"ratio this / {args.reference}: {best['ours'] / best['reference']:.2f}"
        )
    else:
        line += f"; reference {args.reference}: skipped (git archive failed)"
    print(line)


def _still(d: Path, args: argparse.Namespace, reference: Path | None, env: dict[str, str]) -> None:
    still = d / "still.nc"
    still.write_text("N10 G90 G01 X0 Y0 F1000\n" * args.still_blocks + "M30\n", encoding="utf-8")
    ours = _realtime(ROOT, still, env, 1_000_000)
    line = (
        f"{args.still_blocks:,} blocks without motion on a running machine: {ours['cycles']:,.0f} cycles, "
        f"longest {ours['max'] * 1000:.1f} ms (CPU time of the longest: {ours['cpu_max'] * 1000:.1f} ms), "
        f"median {ours['median'] * 1000:.2f} ms"
    )
    if reference is not None:
        ref = _realtime(reference, still, env, 1_000_000)
        line += (
            f"; reference {args.reference}: {ref['cycles']:,.0f} cycles, longest {ref['max'] * 1000:.1f} ms, "
            f"median {ref['median'] * 1000:.2f} ms"
        )
    print(line)
    spin = d / "spin.nc"
    spin.write_text("P1 = 0\n$WHILE 1\nP1 = P1 + 1\n$ENDWHILE\nM30\n", encoding="utf-8")
    ours = _realtime(ROOT, spin, env, 5_000)
    print(
        f"a $WHILE without motion, 5,000 cycles: longest {ours['max'] * 1000:.1f} ms "
        f"(CPU: {ours['cpu_max'] * 1000:.1f} ms), "
        f"median {ours['median'] * 1000:.2f} ms (the program runs on; the reference would hang the clock)"
    )


def _pocket_files(where: Path, blocks: int) -> tuple[Path, Path, int, int]:
    """The pocket program and its subroutine in ``where``, its plain twin beside them; moves and
    NC blocks run."""
    text, files = pocket(blocks)
    where.mkdir()
    language = where / "pocket.nc"
    language.write_text(text, encoding="utf-8")
    for name, body in files.items():
        (where / name).write_text(body, encoding="utf-8")
    plain = where.parent / f"{where.name}_plain.nc"
    moves, statements = _unrolled(language, files, plain)
    return language, plain, moves, statements


if __name__ == "__main__":
    main()
