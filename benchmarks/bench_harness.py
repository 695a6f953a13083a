"""The integration harness (H-07): scenario cycles per second, PLC and CNC in lock-step.

1. 10,000 cycles of the demo machine running a long program, each cycle one cycle of a PLC task
   (``MCV_DynPosLimitHigh`` on X and the feed-override control unit, over the shared-memory
   transport) and one engine cycle, driven by ``Harness.run_until`` (H-07; the goal: under 2 s). Twice:
   the harness' default image (a buffer of the process) and the image in ``/dev/shm``.
   Reference, same run, same program: the bare engine stepping 10,000 cycles (``Machine.step``),
   what no harness can beat; the ratio is the harness' cost on top.
2. The same scenario with the PLC on the Modbus transport (a blocking client in the test's
   thread: two thread hand-overs and the Modbus round trips per cycle), for comparison.
3. The HTTP control API, cycle-exact: ``POST /api/step`` with ``trace`` (four signals, every cycle
   in one answer) against the way it had to be done before, one step request and four image reads
   per cycle (about 7 ms a cycle).

    .venv/bin/python -m benchmarks.bench_harness [--cycles N]
"""

from __future__ import annotations

import argparse
import time
import urllib.parse
from typing import Any

import httpx

from benchmarks.bench_engine import long_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.testing import Harness
from plc_clients import AXIS_REF, ControlSgn32Unit, IoImage, MCV_DynPosLimitHigh, PlcTask

PROGRAM = long_program(20_000)
TRACED = (
    "gpAx[0]^ipo_state.cmd_pos_r",
    "gpAx[1]^ipo_state.cmd_pos_r",
    "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.state_r",
    "gpCh[0]^bahn_state.program_state_r",
)


def engine_alone(cycles: int) -> float:
    machine = Machine(load_machine(None))
    channel = machine.channel(1)
    channel.load_program(PROGRAM, "bench")
    channel.request_start()
    machine.step(1)
    began = time.perf_counter()
    for _ in range(cycles):
        machine.step(1)
    return time.perf_counter() - began


def plc_program() -> Any:
    limit = MCV_DynPosLimitHigh()
    override = ControlSgn32Unit("gpCh[0]^bahn_mc_control.override")
    x = AXIS_REF(0, "X")

    def program(io: IoImage) -> None:
        limit(Axis=x, Enable=True, Position=1_800_000)  # 180 mm: outside the program's path
        override(Enable=True, Command=1000)
        io.read("gpAx[0]^ipo_state.cmd_pos_r")

    return program


def harness_run(cycles: int, image: str, transport: str) -> tuple[float, int]:
    with Harness(image=image) as hli:  # type: ignore[arg-type]
        task = PlcTask(hli.transport(transport), 0.001, plc_program(), watch=["gpAx[0]^ipo_state.cmd_pos_r"])
        hli.operator.load_program(1, PROGRAM)
        hli.operator.start(1)
        hli.step(1)
        end = hli.cycle + cycles
        began = time.perf_counter()
        hli.run_until(lambda: hli.cycle >= end, max_cycles=cycles, plc=task)
        elapsed = time.perf_counter() - began
        assert task.stats.input_faults == task.stats.output_faults == 0
        return elapsed, task.stats.cycles


def http_runs(traced_cycles: int, polled_cycles: int) -> tuple[float, float]:
    """Seconds per cycle: POST /api/step with trace, and step + image reads per cycle."""
    with Harness() as hli:
        hli.operator.load_program(1, PROGRAM)
        hli.operator.start(1)
        with httpx.Client(base_url=hli.http_url, timeout=30) as client:
            began = time.perf_counter()
            answer = client.post("/api/step", json={"cycles": traced_cycles, "trace": list(TRACED)})
            traced = (time.perf_counter() - began) / traced_cycles
            assert answer.status_code == 200, answer.text
            assert len(answer.json()["trace"]["cycles"]) == traced_cycles
            paths = ["/api/image/" + urllib.parse.quote(p, safe="[]") for p in TRACED]
            began = time.perf_counter()
            for _ in range(polled_cycles):
                client.post("/api/step", json={"cycles": 1})
                for path in paths:
                    client.get(path).raise_for_status()
            polled = (time.perf_counter() - began) / polled_cycles
    return traced, polled


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=10_000, help="cycles of each harness run")
    args = ap.parse_args()
    n = args.cycles
    reference = engine_alone(n)
    memory, plc_cycles = harness_run(n, "memory", "shm")
    shm, _ = harness_run(n, "shm", "shm")
    modbus, _ = harness_run(min(n, 2_000), "memory", "modbus")
    modbus_n = min(n, 2_000)
    traced, polled = http_runs(5_000, 100)
    print(f"harness: {n:,} cycles, PLC task over shared memory ({plc_cycles:,} PLC cycles): {memory:.2f} s")
    print(f"harness: the same with the image in /dev/shm: {shm:.2f} s")
    print(f"reference: the bare engine stepping {n:,} cycles: {reference:.2f} s")
    print(f"ratio: {memory / reference:.2f}x the engine's time (memory image), {shm / reference:.2f}x (shm)")
    per_cycle = modbus / modbus_n * 1e3
    print(
        f"harness, PLC task over Modbus TCP: {modbus_n / modbus:,.0f} cycles/s ({per_cycle:.2f} ms a cycle)"
    )
    print(
        f"HTTP: POST /api/step with a trace of {len(TRACED)} signals: {traced * 1e6:,.0f} µs a cycle; "
        f"reference: a step request and {len(TRACED)} image reads per cycle: {polled * 1e3:.2f} ms a cycle; "
        f"ratio {polled / traced:,.0f}x"
    )


if __name__ == "__main__":
    main()
