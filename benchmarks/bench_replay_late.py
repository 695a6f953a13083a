"""Replaying a recording started late (issue 37): a 1-second recording of a server up N minutes.

The demo machine runs a program of lines and arcs in a loop for ``--minutes`` of machine time on the
stepped clock (a :class:`~hli_server.runtime.Runtime`, image in memory, no doors), its PLC changing the
override every 5 s; then a recording of ``--cycles`` cycles is started and stopped, as ``POST
/api/recording/start`` does in a running server. The recording is replayed twice with ``hli-server
replay``'s code: from its snapshot (format 4, the default) and from its input journal (``--from-journal``:
what every replay of a late recording did before, cycle 1 on). Figures: what the snapshot cost the pause
between two cycles, the file's size, and each replay's wall time with the cycles it ran.

    .venv/bin/python -m benchmarks.bench_replay_late [--minutes 7] [--cycles 1000]
"""

from __future__ import annotations

import argparse
import asyncio
import tempfile
import time
from pathlib import Path

from hli_server import _compiled
from hli_server.configuration import load_machine
from hli_server.replay import replay
from hli_server.runtime import Runtime, memory_image

PROGRAM = """%loop
N10 G90 G17 G01 X0 Y0 Z0 F6000
N20 $FOR P1 = 1, 1000000, 1
N30   G01 X50 Y0
N40   G02 X50 Y20 I0 J10
N50   G01 X0 Y20
N60   G01 X0 Y0
N70 $ENDFOR
N80 M30
"""
OVERRIDE = "gpCh[0]^bahn_mc_control.override"


async def run(minutes: float, cycles: int) -> None:
    uptime = int(minutes * 60_000)
    path = Path(tempfile.mkdtemp()) / "late.jsonl.gz"
    async with Runtime(
        load_machine(None), clock="stepped", http_port=None, adapters=[], image_factory=memory_image
    ) as rt:
        rt.image.write(OVERRIDE + ".enable_w", True)
        rt.operator.load_program(1, PROGRAM, "loop")
        rt.operator.start(1)
        began = time.perf_counter()
        for k in range(0, uptime, 5000):
            rt.image.write(OVERRIDE + ".command_w", 900 if (k // 5000) % 2 else 1000)
            await rt.step(min(5000, uptime - k))
        stepped = time.perf_counter() - began
        print(f"uptime: {uptime:,} cycles ({minutes:g} min at 1 ms), stepped in {stepped:.1f} s")
        rt.session.start(path)
        print(f"snapshot of cycle {uptime:,}: {rt.session.snapshot_s * 1000:.1f} ms between two cycles")
        await rt.step(cycles)
        rt.session.stop()
    print(f"recording: {cycles:,} cycles, {path.stat().st_size:,} bytes")
    for from_journal in (False, True):
        report = await replay(path, from_journal=from_journal)
        print(
            f"replay from the {report.started_from}: {report.verdict}, {report.cycles:,} cycles replayed, "
            f"{report.cycles_compared:,} compared, {report.wall_s:.2f} s"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=7.0, help="uptime before the recording starts")
    parser.add_argument("--cycles", type=int, default=1000, help="cycles recorded")
    args = parser.parse_args()
    print(f"engine: {'compiled' if _compiled.ENGINE_COMPILED else 'pure Python'}")
    asyncio.run(run(args.minutes, args.cycles))


if __name__ == "__main__":
    main()
