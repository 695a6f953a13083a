"""Recorded scenarios: the engine's outputs, cycle for cycle, are those recorded before issue 16's speed work.

Each scenario steps a machine and folds every cycle's outputs - the whole HLI (what the PLC sees),
setpoints, actual and measured positions, every event - into one sha256 (``benchmarks.scenarios.
trace_digest``). ``tests/data/recorded_scenarios.json`` holds the digests the engine gave at commit
859e97f, before any optimisation, with one digest per 1000 cycles to find the first cycle that differs
(re-recorded once since, in issue 23, for the events' ``time_s``: cycle x T_A exact to the µs, where
the product in floating point had given 5.123000000000001; nothing else changed; and in issue 35 for the
new ``bahn_state`` fields of the kinematic transformation, K-07: with those five fields left out of the
fold every scenario gave the digest recorded before, so nothing else changed).
An optimisation that changes any output in any cycle, by one bit, fails here; so does the compiled
engine if it computes anything differently from the pure one (``HLI_PURE_PYTHON``, docs/performance.md).

Re-record only for an intended change of behaviour: ``python -m tests.unit.test_recorded_scenarios``.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from benchmarks.bench_engine import long_program
from benchmarks.programs import FULL_MACHINE, near_area_lines
from benchmarks.scenarios import demo_machine, full_machine, trace_digest
from hli_server.commands.check import check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine

RECORDED = Path(__file__).parents[1] / "data" / "recorded_scenarios.json"

MOTION_PROGRAM = """\
N10 G90 G01 X100 Y50 F6000
N20 G02 X150 Y100 I50 J0
N30 G03 X100 Y150 I-50 J0
N40 G00 X0 Y0 Z10
N50 G91 G01 X10 Y-5 Z-10 F3000
N55 G90 G60 G01 X20 Y20
N56 G18 G02 X40 Z0 I10 K0
N57 G17
N60 M30
"""

COLLIDE = """\
G90 G01 F6000
X1=50 X2=120
X2=60 F12000
X1=0 X2=300 X3=600
M30
"""


def _full(cycles: int) -> tuple[str, list[str]]:
    return trace_digest(full_machine(), cycles)


def _full_braking(cycles: int) -> tuple[str, list[str]]:
    """Dynamic limits that the paths run into (braking, at rest on the limit, moved: released)."""
    machine = full_machine(limits={"X": (-300.0, 60.0), "X2": (150.0, 340.0), "Z": (-5.5, 150.0)})

    def each(m: Machine) -> None:
        ctl = m.hli.axes[m.axis("X").index].ipo_mc_control.dyn_pos_limit_high
        if m.cycle == 4000:
            ctl.command_w = 1_200_000
        if m.cycle == 6000:
            ctl.enable_w = False

    return trace_digest(machine, cycles, each=each)


def _collision_and_faults(cycles: int) -> tuple[str, list[str]]:
    """A collision stop in channel 2, a reset, moving apart; a settling fault in channel 1."""
    machine = full_machine(limits={"X": (-300.0, 300.0), "Y": (-300.0, 300.0)})
    ch2 = machine.channel(2)

    def each(m: Machine) -> None:
        if m.cycle == 300:
            ch2.request_reset()
        if m.cycle == 400:
            ch2.load_program(COLLIDE, "collide")
            ch2.request_start()
        if m.cycle == 1500:
            m.inject_fault("Y", friction=30.0)
        if m.cycle == 3000:
            ch2.request_reset()
            m.channel(1).request_reset()
        if m.cycle == 3100:
            m.inject_fault("Y")
            ch2.load_program("G90 G01 X2=300 F3000\nM30\n", "apart")
            ch2.request_start()

    return trace_digest(machine, cycles, each=each)


def _demo_motion_jog(cycles: int) -> tuple[str, list[str]]:
    """The demo machine: lines, arcs in two planes, G60; then manual mode, jog, referencing."""
    machine = demo_machine(MOTION_PROGRAM)
    ch = machine.channel(1)

    def each(m: Machine) -> None:
        if m.cycle == 5200:
            ch.request_mode(1)
        if m.cycle == 5210:
            ch.request_jog("X", 1)
        if m.cycle == 5600:
            ch.request_jog("X", 0)
            ch.request_jog("Y", -1)
        if m.cycle == 6000:
            ch.request_jog("Y", 0)
        if m.cycle == 6500:
            ch.request_reference("Z")

    return trace_digest(machine, cycles, each=each)


def _demo_long(cycles: int) -> tuple[str, list[str]]:
    return trace_digest(demo_machine(long_program(20_000)), cycles)


def _geometry_check(blocks: int) -> tuple[str, list[str]]:
    """``check --geometry-only`` of the near-area program with a violation appended."""
    import hashlib

    text = "\n".join(near_area_lines(blocks)).replace("M30", "G01 X180 Y0\nM30") + "\n"
    machine = Machine(load_machine(FULL_MACHINE))
    report = check_program(machine, text, geometry_only=True).to_json()
    report.pop("elapsed_s")
    return hashlib.sha256(json.dumps(report, sort_keys=True).encode()).hexdigest(), []


SCENARIOS: dict[str, tuple[Callable[[int], tuple[str, list[str]]], int]] = {
    "full_machine": (_full, 8000),
    "full_machine_dyn_limits_braking": (_full_braking, 8000),
    "full_machine_collision_and_faults": (_collision_and_faults, 5000),
    "demo_motion_jog": (_demo_motion_jog, 8000),
    "demo_long_program": (_demo_long, 6000),
    "geometry_check_near_areas": (_geometry_check, 5000),
}


def _recorded() -> dict[str, dict[str, object]]:
    return json.loads(RECORDED.read_text(encoding="utf-8"))  # type: ignore[no-any-return]


@pytest.mark.req("E-01")
@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_outputs_are_the_recorded_ones_cycle_for_cycle(name: str) -> None:
    run, size = SCENARIOS[name]
    recorded = _recorded()[name]
    digest, marks = run(size)
    if digest != recorded["digest"]:
        first = next(
            (k for k, (a, b) in enumerate(zip(marks, recorded["marks"], strict=False)) if a != b), None
        )
        where = (
            f"first difference within cycles {first * 1000}..{(first + 1) * 1000}"
            if first is not None
            else ""
        )
        pytest.fail(f"scenario {name}: outputs differ from the recording {where}")


def main() -> None:
    data = {}
    for name, (run, size) in SCENARIOS.items():
        digest, marks = run(size)
        data[name] = {"size": size, "digest": digest, "marks": marks}
        print(name, digest[:16], file=sys.stderr)
    RECORDED.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
