"""Fuzz of the new inputs of issue 24 items 1 and 5 (#SLOPE, G70/G71, G94/G95, R, G08/G09/G900/G901):
seeded and bounded (tests/fuzz.py); malformed text gets a numbered NC error, programs keep the machine
stepping with finite setpoints and a clear state."""

from __future__ import annotations

import math
import random
import traceback

import pytest

from hli_server.engine.alarms import ALARMS
from schemas.wire import ProgramState
from tests import fuzz
from tests.unit.engine_helpers import mill
from tests.unit.nc_helpers import interpret

pytestmark = pytest.mark.fuzz

_PIECES = (
    "#SLOPE",
    " [",
    "]",
    "TYPE=",
    "STEP",
    "TRAPEZ",
    "SIN2",
    "HSC",
    "NO_OPT=",
    "0",
    "1",
    "2",
    " DEFAULT",
    ",",
    " ",
    "G70",
    "G71",
    "G94",
    "G95",
    "G08",
    "G09",
    "G900",
    "G901",
    " R",
    "-",
    "1e3",
    "99999999",
    "X",
    "Y",
    "F",
    "S",
    "M3",
    "M5",
    "G02",
    "G03",
)


def _line(rng: random.Random) -> str:
    return "".join(rng.choice(_PIECES) for _ in range(rng.randint(1, 8)))


def _program(rng: random.Random) -> str:
    lines = ["N1 G01 X0 Y0 F3000 M3 S500"]
    for n in range(2, rng.randint(3, 9)):
        choice = rng.random()
        if choice < 0.2:
            lines.append(
                rng.choice(
                    ("#SLOPE [TYPE=TRAPEZ]", "#SLOPE [TYPE=SIN2]", "#SLOPE DEFAULT", "#SLOPE [TYPE=STEP]")
                )
            )
        elif choice < 0.4:
            r = rng.choice((-1, 1)) * rng.uniform(0.0, 30.0)
            lines.append(
                f"N{n} {rng.choice(('G02', 'G03'))} X{rng.uniform(-20, 20):.3f} "
                f"Y{rng.uniform(-20, 20):.3f} R{r:.3f}"
            )
        elif choice < 0.6:
            g = rng.choice(
                ("G70", "G71", "G94", "G95 F0.5", "G95", "G08", "G09", "G900", "G901", "M5", "M3 S0")
            )
            lines.append(
                f"N{n} {g} G01 X{rng.uniform(-1, 1):.3f} Y{rng.uniform(-1, 1):.3f} "
                f"F{rng.uniform(1, 3000):.1f}"
            )
        else:
            lines.append(f"N{n} G01 X{rng.uniform(-20, 20):.3f} Y{rng.uniform(-20, 20):.3f}")
    lines.append("M30")
    return "\n".join(lines) + "\n"


@pytest.mark.req("M-01", "M-06", "M-08")
def test_fuzz_new_words_raise_only_numbered_nc_errors() -> None:
    seed = fuzz.seed_for("mslope-lines")
    rng = random.Random(seed)
    for example in range(fuzz.count(600)):
        text = f"%f\nN1 G01 X1 F100\n{_line(rng)}\nM30\n"
        try:
            run = interpret(text)
        except Exception:  # anything but a numbered NcError is a finding
            pytest.fail(f"{text!r} (seed {seed}, example {example}):\n{traceback.format_exc()}")
        if run.error is not None:
            assert run.error.alarm in ALARMS, (text, run.error.alarm)
            assert run.error.line >= 1


@pytest.mark.req("M-02", "M-06", "M-07", "M-08")
def test_fuzz_programs_with_profiles_and_units_keep_the_machine_stepping() -> None:
    seed = fuzz.seed_for("mslope-programs")
    rng = random.Random(seed)
    for example in range(fuzz.count(12)):
        text = _program(rng)
        m = mill(swe=(-100_000_000, 100_000_000))
        ch = m.channel(1)
        try:
            ch.load_program(text)
            ch.request_start()
            for _ in range(30_000):
                m.step(1)
                if ch.state not in (ProgramState.RUNNING, ProgramState.HELD) and ch.planner.at_rest:
                    break
            assert all(math.isfinite(a.setpoint) for a in m.axes)
            ch.request_reset()
            m.step(400)
            ch.load_program("N1 G01 X0 Y0 F6000\nM30\n")
            ch.request_start()
            m.step(4000)
            assert not m.active_alarms, [a.message for a in m.active_alarms]
        except Exception:
            pytest.fail(f"{text!r} (seed {seed}, example {example}):\n{traceback.format_exc()}")
