"""The batch geometry check on programs with loops, subroutines and variables (issue 20; ``engine/batch.py``).

The blocks the interpreter builds in a loop or a subroutine that only move (``G91 X[@P3 * V.P.DIR]``) are
kept and checked as a batch, like the plain lines of the main program. These tests hold that to the exact
path (``HLI_BATCH_CHECK=0``, block by block) on seeded random programs and on the edges one by one: the
same alarms (numbers, messages, lines, blocks, parameters, points bit for bit), the same ``#MSG`` messages
(none after the block that fails), the same block count, final position and area table; and that such a
program is in fact mostly batched.
"""

from __future__ import annotations

import random
from typing import Any

import pytest

from benchmarks.bench_language import POCKET_SUB
from hli_server.commands.check import CheckResult, check_program
from hli_server.engine import Machine
from hli_server.engine import batch as batch_module
from hli_server.engine.alarms import Severity
from hli_server.engine.batch import BatchGeometryCheck
from hli_server.engine.programs import MemoryLibrary
from schemas.config import MachineConfig
from tests.unit.test_batch_check import AREAS, _batch_settings, config, report

__all__ = ["config"]

# the zigzag of a pass (the pocket benchmark's global cycle, pass.nc, with @P parameters), a local
# subroutine and a global one
ZIG_LOCAL = """%L ZIG
N100 G90 G01 X[P11] Y[P12] F6000
N110 $FOR P10 = 1, P13
N120   G91 X[P14 * V.P.DIR] Y[P15]
N130   V.P.DIR = -V.P.DIR
N140 $ENDFOR
N150 G90
N160 M17
"""
ARC_SUB = """%arcs
N10 G91 G02 X[2 * P30] Y0 I[P30] J0
N20 G03 X[-2 * P30] Y0 I[-P30] J0
N30 G90
N40 M29
"""


FILES = {"pass.nc": POCKET_SUB, "arcs.nc": ARC_SUB}


def run_language(
    config: MachineConfig, text: str, exact: bool, small: int | None = None, max_iterations: int = 100_000
) -> CheckResult:
    with _batch_settings(exact, small=small):
        return check_program(
            Machine(config, programs=MemoryLibrary(FILES)),
            text,
            geometry_only=True,
            max_iterations=max_iterations,
        )


def full_report(result: CheckResult) -> dict[str, Any]:
    out = report(result)
    out["messages"] = [(m.text, m.program, m.line, m.block) for m in result.messages]
    out["capped"] = result.capped
    return out


def assert_same(config: MachineConfig, text: str, small: int | None = None) -> CheckResult:
    exact = run_language(config, text, exact=True)
    batched = run_language(config, text, exact=False, small=small)
    assert full_report(batched) == full_report(exact), text
    return batched


def _pass(rng: random.Random, k: int) -> list[str]:
    """One pass of the random program: a call of the zigzag (local, cycle) or of the arcs, or a loop."""
    x0 = rng.choice((-150.0, -40.0, -30.0, 20.0, 30.0, 45.0, 100.0))
    y0 = rng.choice((-120.0, -45.0, -30.0, -5.0, 10.0, 60.0))
    dx = rng.choice((20.0, 30.0, 40.0, 60.0, 0.5))
    dy = rng.choice((0.5, 1.0, 2.0, -1.5))
    n = rng.randint(1, 40)
    kind = rng.randrange(5)
    if kind == 0:
        return [f"P11 = {x0}", f"P12 = {y0}", f"P13 = {n}", f"P14 = {dx}", f"P15 = {dy}", "LL ZIG"]
    if kind == 1:
        return [f"L CYCLE [NAME=pass.nc @P1={x0} @P2={y0} @P3={dx} @P4={dy} @P5={n}]"]
    if kind == 2:
        return [f"G90 G01 X{x0} Y{y0}", f"P30 = {rng.choice((1.0, 5.0, 12.5))}", "L arcs.nc"]
    if kind == 3:
        # a loop in the main program: its blocks are the interpreter's too
        return [
            f"G90 X{x0} Y{y0}",
            f"$WHILE P40 < {k * 50 + n}",
            f"  G91 X[{dx} * V.P.DIR] Y{dy}",
            "  V.P.DIR = -V.P.DIR",
            "  P40 = P40 + 1",
            "$ENDWHILE",
            "G90",
        ]
    # reads of the decoder's state and messages between the moves
    return [
        f"G90 G01 X{x0} Y{y0}",
        '#MSG ["at %.4f %.4f, last I %.4f", V.A.PROG.X, V.A.PROG.Y, V.G.I]',
    ]


def random_program(seed: int) -> str:
    rng = random.Random(seed)
    lines = [ZIG_LOCAL.rstrip("\n"), "%MAIN", AREAS.rstrip("\n")]
    lines += ["#VAR", "  V.P.DIR = 1", "#ENDVAR", "P40 = 0"]
    for k in range(rng.randint(1, 8)):
        lines += _pass(rng, k)
        if rng.random() < 0.3:
            lines.append(f'#MSG ["pass %d", {k}]')
    lines.append("M30")
    return "\n".join(lines) + "\n"


@pytest.mark.req("C14-15", "N-10")
@pytest.mark.fuzz
@pytest.mark.parametrize("seed", range(40))
def test_batch_and_exact_agree_on_random_programs_with_loops_and_subroutines(
    config: MachineConfig, seed: int
) -> None:
    assert_same(config, random_program(seed), small=(1, 4, 16, None)[seed % 4])


@pytest.mark.req("C14-15", "N-10")
def test_a_violation_inside_a_loop_stops_before_the_message_after_it(config: MachineConfig) -> None:
    """The block into the protection circle is the 20th of a loop's kept blocks: the check stops there,
    with the exact path's alarm, and the #MSG after the loop is not given."""
    text = (
        "%MAIN\n" + AREAS + "G90 G01 X20 Y0\nP1 = 0\n$WHILE P1 < 40\n  G91 X1 Y0\n  P1 = P1 + 1\n$ENDWHILE\n"
        '#MSG ["after"]\nM30\n'
    )
    result = assert_same(config, text, small=1)
    assert [a.number for a in result.alarms if a.severity == Severity.ERROR] == [912001]
    assert result.messages == []


@pytest.mark.req("C14-15", "N-10")
def test_a_message_reads_the_position_of_the_blocks_before_it(config: MachineConfig) -> None:
    """V.A.PROG in a #MSG after kept blocks: they are decoded first (the same position as the exact path)."""
    text = (
        "%MAIN\nG90 G01 X0 Y0 F1000\nP1 = 0\n$WHILE P1 < 30\n  G91 X0.5 Y[0.25 * P1]\n  P1 = P1 + 1\n"
        '  $IF P1 MOD 10 == 0\n    #MSG ["%.6f %.6f %d", V.A.PROG.X, V.A.PROG.Y, V.G.BLOCK_NR]\n  $ENDIF\n'
        "$ENDWHILE\nM30\n"
    )
    result = assert_same(config, text, small=1)
    assert result.messages[0].text == "5.000000 11.250000 0"


@pytest.mark.req("C14-15", "N-10")
def test_the_iteration_cap_after_kept_blocks_checks_them_first(config: MachineConfig) -> None:
    text = "%MAIN\n" + AREAS + "G90 G01 X20 Y0\n$WHILE 1\n  G91 X1 Y0\n$ENDWHILE\nM30\n"
    for small in (1, None):
        exact = run_language(config, text, exact=True)
        batched = run_language(config, text, exact=False, small=small)
        assert full_report(batched) == full_report(exact)
        assert [a.number for a in batched.alarms if a.severity == Severity.ERROR] == [912001]
    # clear moves up to the cap: the same blocks checked, the same cap
    endless = "%MAIN\nG90 G01 X0 Y0 F1000\n$WHILE 1\n  G91 X0.001\n  X-0.001\n$ENDWHILE\nM30\n"
    exact = run_language(config, endless, exact=True, max_iterations=500)
    batched = run_language(config, endless, exact=False, max_iterations=500)
    assert exact.capped == "iterations"
    assert full_report(batched) == full_report(exact)


@pytest.mark.req("C14-15", "N-10")
def test_a_long_loop_is_checked_a_bounded_number_of_blocks_at_a_time(
    config: MachineConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A loop that only moves is checked ROWS_KEPT blocks at a time (memory stays flat), with the exact
    path's result, also where the violation lies beyond the first of those batches."""
    monkeypatch.setattr(batch_module, "ROWS_KEPT", 50)
    text = (
        "%MAIN\n" + AREAS + "G90 G01 X-30 Y-40\nP1 = 0\n$WHILE P1 < 200\n  G91 X60 Y0.1\n  X-60 Y0.1\n"
        "  P1 = P1 + 1\n$ENDWHILE\nG90 X20 Y0\nP1 = 0\n$WHILE P1 < 300\n  G91 X0.1\n  P1 = P1 + 1\n"
        '$ENDWHILE\n#MSG ["after"]\nM30\n'
    )
    result = assert_same(config, text, small=4)
    assert [a.number for a in result.alarms if a.severity == Severity.ERROR] == [912001]


def test_a_pocket_with_loops_and_a_cycle_is_mostly_batched(config: MachineConfig) -> None:
    """The kept blocks are checked as a batch: far fewer blocks go to the exact decoder than are run."""
    text = (
        "%MAIN\n" + AREAS + "#VAR\n  V.P.DIR = 1\n#ENDVAR\nG90 G01 X30 Y-45 F6000\n$FOR P1 = 0, 9\n"
        "  L CYCLE [NAME=pass.nc @P1=-30 @P2=-45 + P1 @P3=60 @P4=0.5 @P5=30]\n$ENDFOR\nM30\n"
    )
    result = assert_same(config, text)
    assert not result.alarms
    machine = Machine(config, programs=MemoryLibrary(FILES))
    with _batch_settings(False):
        checker = BatchGeometryCheck(machine.channel(1))
        for _ in checker.items(text):
            pass
    assert checker.batched_blocks > 5 * checker.exact_blocks, (checker.batched_blocks, checker.exact_blocks)
