"""Fuzzed #CS/#ACS/#ROTATION lines and compensated programs (issue 24, mcs): no crash, a precise error."""

from __future__ import annotations

import random

import pytest

from tests import fuzz
from tests.unit.test_motion_mcs_frames import TOOLS, decode

pytestmark = pytest.mark.fuzz

SEEDS = [
    "#CS ON [10, 20, 0, 0, 0, 45]",
    "#CS DEF [2] [,,10,,,45]",
    "#CS ON [2]",
    "#CS OFF ALL",
    "#ACS ON [1, 2, 3, 10, 20, 30]",
    "#CS ADD [ICS] [10,10,0,0,0,45]",
    "#CS SET [ICS] [20,10,0,0,0,10]",
    "#CS DEL ALL",
    "#ROTATION ON [ANGLE=30 CENTER1=5 CENTER2=-5]",
    "#ROTATION OFF",
    "D2 G41 G26",
    "G42 D1",
    "G40 X0 Y0",
    "G02 X10 Y0 I5 J0",
    "G01 X5 Y5 Z-3",
]


@pytest.mark.req("M-10", "M-18")
def test_mutated_coordinate_and_compensation_programs_never_crash() -> None:
    seed = fuzz.seed_for("test_mutated_coordinate_and_compensation_programs_never_crash")
    rng = random.Random(seed)
    for example in range(fuzz.count(300)):
        lines = [rng.choice(SEEDS) for _ in range(rng.randint(1, 8))]
        k = rng.randrange(len(lines))
        lines[k] = fuzz.mutate(rng, lines[k])
        program = "%t\nG01 X0 Y0 Z0 F1000\n" + "\n".join(lines) + "\nM30\n"
        try:
            _, err = decode(program, tools=TOOLS)
        except Exception as exc:  # pragma: no cover - the failure report
            raise AssertionError(f"crash (seed {seed}, example {example}): {program!r}") from exc
        if err is not None:
            assert isinstance(err.payload.alarm, int)
            assert err.payload.message
