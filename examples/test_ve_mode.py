"""V.E. variables, tested through every PLC door: the PLC selects what a running NC program does.

The PLC program is ``plc_clients.demos.ve_mode.VeModeDemo`` (``hli-plc ve-mode`` runs it against a
live server). The NC program waits in a ``$WHILE`` loop until the PLC sets ``V.E.PLC_READY``, then
machines three parts: ``$IF V.E.MODE == 1`` calls the subprogram ``pocket.nc``, else ``contour.nc``
(both uploaded with the program), counts each in ``V.E.PART_COUNT`` and writes "part N done" into
its report file with ``#MSG SAVE``. The PLC writes ``MODE`` and ``PLC_READY`` and reads ``PART_COUNT``
through its door; the test checks what the machine did.
"""

from __future__ import annotations

import numpy as np
import pytest

from hli_server.testing import Harness
from plc_clients import PlcTask
from plc_clients.demos.ve_mode import VeModeDemo

pytestmark = pytest.mark.req("N-05", "N-06", "N-02", "N-07", "H-06", "H-07")

X, Z = "gpAx[0]^ipo_state.cmd_pos_r", "gpAx[2]^ipo_state.cmd_pos_r"
PROGRAM_STATE = "gpCh[0]^bahn_state.program_state_r"
FINISHED = 4
RELEASE_AFTER = 200  # CNC cycles the program waits for the PLC


def run(hli: Harness, transport: object, mode: int) -> tuple[VeModeDemo, object]:
    """The operator loads the program with its subprograms; the PLC does the rest."""
    demo = VeModeDemo(mode=mode, release_after=RELEASE_AFTER)
    hli.load_program(demo.channel, demo.nc_program, files=demo.nc_files, name="ve_mode.nc")
    task = PlcTask(transport, 0.001, demo, watch=demo.watch)
    with hli.trace(X, Z, PROGRAM_STATE, "gpVEGlob^PART_COUNT") as recording:
        hli.run_until(lambda: demo.done, max_cycles=8000, plc=task)
    return demo, recording.trace()


def test_the_plc_selects_the_pocket_and_the_program_counts_three_parts(
    hli: Harness, plc_transport: object
) -> None:
    demo, trace = run(hli, plc_transport, mode=1)
    assert not demo.failed, demo.log
    x, z, state = trace[X], trace[Z], trace[PROGRAM_STATE]
    count = trace["gpVEGlob^PART_COUNT"]
    # the program runs, but does not move while it waits for V.E.PLC_READY
    waiting = np.flatnonzero(state == 1)[: RELEASE_AFTER - 5]
    assert len(waiting) > 100
    assert np.all(x[waiting] == 0)
    # the pocket goes 2 mm deep (Z -20000 in 0.1 µm), once per part; the contour would not
    assert z.min() == -20_000
    # PART_COUNT counts 1, 2, 3 and the PLC saw each
    assert np.unique(count).tolist() == [0, 1, 2, 3]
    assert [t for _, t in demo.log if t.startswith("part")] == [
        f"part {n} done (V.E.PART_COUNT = {n})" for n in (1, 2, 3)
    ]
    assert (state[-1], x[-1], hli.runtime.machine.external.read("PART_COUNT", None)) == (FINISHED, 0, 3)
    # #MSG SAVE wrote into the server's NC output directory (the kernel's default file name), each
    # line after its time stamp
    lines = (hli.nc_files / "message.txt").read_text(encoding="utf-8").splitlines()
    assert len(lines) == 3
    assert all(line.endswith(f"part {n} done") for line, n in zip(lines, (1, 2, 3), strict=True)), lines


@pytest.mark.parametrize("plc_transport", ["shm"], indirect=True)
def test_with_the_contour_selected_the_program_takes_the_other_branch(
    hli: Harness, plc_transport: object
) -> None:
    demo, trace = run(hli, plc_transport, mode=2)
    assert not demo.failed, demo.log
    assert trace[Z].min() == 0  # no pocket: Z never goes down
    assert trace[X].max() > 3 * 30 * 10_000  # the third part's circle reaches beyond X = 90 mm
    assert hli.runtime.machine.external.read("PART_COUNT", None) == 3


@pytest.mark.parametrize("plc_transport", ["shm"], indirect=True)
def test_run_again_the_plc_counts_the_new_runs_parts_from_zero(hli: Harness, plc_transport: object) -> None:
    """Issue 37, item 5: ``hli-plc ve-mode`` run twice reported "6 parts": the variable keeps the first
    run's count. The program sets ``V.E.PART_COUNT`` = 0 at its start; the PLC reports from its release on."""
    first, _ = run(hli, plc_transport, mode=1)
    assert first.log[-1][1] == "program finished: 3 parts", first.log
    second, _ = run(hli, plc_transport, mode=2)
    assert not second.failed, second.log
    assert [t for _, t in second.log if t.startswith("part")] == [
        f"part {n} done (V.E.PART_COUNT = {n})" for n in (1, 2, 3)
    ]
    assert second.log[-1][1] == "program finished: 3 parts"
    assert hli.runtime.machine.external.read("PART_COUNT", None) == 3
