"""Keep a session as a regression test: record it once, replay it in every later run (issue 25).

The scenario is FCT-C43's obstacle (``plc_clients.demos.c43_obstacle``): the PLC limits X while a
sensor reports an obstacle, the NC program holds at the limit and finishes once the PLC lifted it.
``hli.record(path)`` keeps every input the CNC took (the PLC's writes as latched, the operator's
requests with the program text) at their cycles, the events, and the outputs sampled every 100 cycles
(``outputs_every=1``: every cycle). ``hli.replay(path)`` runs the same
machine on the recorded inputs and fails, with the first difference, when an output is not what it was.

In a project the recording is made once (on a test bench, or by ``hli-server run --record`` when the
machine "did something odd on Tuesday") and kept beside the tests; the test is then the last line
alone. Here the test records it first, then shows that a change in the engine (a softer position loop
on X, as a changed drive model would give) does not go unnoticed.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from hli_server.testing import Harness, ReplayFailedError
from plc_clients import PlcTask
from plc_clients.demos.c43_obstacle import ObstacleDemo

pytestmark = pytest.mark.req("B-02", "H-07")


@pytest.fixture
def recording(hli: Harness, tmp_path: Path) -> Path:
    """The obstacle scenario over shared memory, recorded."""
    path = tmp_path / "obstacle.jsonl.gz"
    demo = ObstacleDemo(limit=500_000)
    with hli.record(path):
        hli.operator.load_program(demo.channel, demo.nc_program)
        task = PlcTask(hli.transport("shm"), 0.001, demo, watch=demo.watch)
        hli.run_until(lambda: demo.done, max_cycles=3000, plc=task)
    assert not demo.failed, demo.log
    return path


def test_the_recorded_obstacle_replays_cycle_for_cycle(hli: Harness, recording: Path) -> None:
    hli.replay(recording)  # the regression test: one line


def test_a_change_in_the_engine_shows_up_as_the_first_difference(hli: Harness, recording: Path) -> None:
    def softer_position_loop(machine: object) -> None:
        axis = machine.axis("X")  # type: ignore[attr-defined]
        axis.drive = dataclasses.replace(axis.drive, kv=axis.drive.kv * 0.7)

    with pytest.raises(ReplayFailedError) as failed:
        hli.replay(recording, prepare=softer_position_loop)
    first = failed.value.report.first
    assert first is not None
    assert first.signal.startswith("gpAx[0]^ipo_state.")
    assert "first difference: cycle" in str(failed.value)  # ... with its cycle, expected and actual value
