"""Recording (B-02): the full machine recorded for 10 minutes of machine time: size, overhead, replay speed.

The full machine (``machines/full.toml``: 2 channels, 8 axes, 20 areas, 16 dynamic limits
written by the PLC through the image, 3 collision pairs; a channel's program is started again whenever it
finished) runs in a :class:`~hli_server.runtime.Runtime` on the stepped clock (image in memory, no
doors), in two worker processes side by side: one records the session, one does not. They step in
interleaved slices of ``--slice`` cycles so that load on the host hits both alike; each reports the CPU
time of its process for the slice (the recorder's encoder task runs in the slices too). Then, in the same
run: the recording is replayed (``hli-server replay``'s code) and the bare engine (``Machine.step``, no
image, no runtime) steps the same scenario.

Figures: the file's size (and per hour of machine time), the recorder's cost per cycle in µs, as a share of
T_A, of the runtime's own time per cycle and of the engine's cycle (``Machine.step`` alone: the goal, under
5 %); the replay's speed
against the engine alone and against the runtime without recording.

    .venv/bin/python -m benchmarks.bench_record [--cycles 600000] [--slice 5000] [--outputs-every 100]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).parents[1]
WORKER = r"""
import asyncio, json, sys, time
from pathlib import Path
import hli_server._compiled as compiled
from benchmarks.programs import FULL_MACHINE, pocket_program, shuttle_program
from benchmarks.scenarios import DYN_LIMITS
from hli_server.configuration import load_machine
from hli_server.recording.tap import RecordingOptions
from hli_server.runtime import Runtime, memory_image

record = sys.argv[1] if len(sys.argv) > 1 and sys.argv[1] != "-" else None
PROGRAMS = {1: ("pocket", pocket_program(12)), 2: ("shuttle", shuttle_program(4000))}

async def main():
    config = load_machine(FULL_MACHINE)
    every = int(sys.argv[2]) if len(sys.argv) > 2 else 100
    options = RecordingOptions(file=Path(record), outputs_every=every) if record else None
    rt = Runtime(config, clock="stepped", http_port=None, adapters=[], image_factory=memory_image,
                 recording=options)
    await rt.start()
    for name, (low, high) in DYN_LIMITS.items():  # the PLC sets the 16 dynamic limits through the image
        index = rt.machine.axis(name).index
        unit = f"gpAx[{index}]^ipo_mc_control.dyn_pos_limit_"
        rt.image.write(unit + "low.command_w", round(low * 10_000))
        rt.image.write(unit + "high.command_w", round(high * 10_000))
        rt.image.write(unit + "low.enable_w", True)
        rt.image.write(unit + "high.enable_w", True)
    await rt.step(2)
    # the tap's own time, measured where it is spent (both workers: the plain one keeps the input journal)
    tap = rt.session
    spent = {"cycle_ns": 0, "encode_ns": 0}
    ns = time.perf_counter_ns
    after_cycle, encode = tap.after_cycle, tap._encode
    def timed_after_cycle(cycle, latched, packed):
        t = ns()
        after_cycle(cycle, latched, packed)
        spent["cycle_ns"] += ns() - t
    def timed_encode(limit):
        t = ns()
        encode(limit)
        spent["encode_ns"] += ns() - t
    tap.after_cycle, tap._encode = timed_after_cycle, timed_encode
    import threading
    def writer_cpu():
        total = 0.0
        for th in threading.enumerate():
            if th.name.startswith("hli-record-writer") and th.ident is not None:
                total += time.clock_gettime(time.pthread_getcpuclockid(th.ident))
        return total
    import gc
    gc.collect()
    gc.freeze()  # as `hli-server run` does once it is up (Runtime.serve)
    restarts = 0
    print(json.dumps({"compiled": compiled.ENGINE_COMPILED}), flush=True)
    loop = asyncio.get_running_loop()
    for line in sys.stdin:
        cmd = line.split()
        if cmd[0] == "stop":
            t0, m0 = time.process_time(), time.thread_time()
            writer = writer_cpu()
            await rt.stop()
            print(json.dumps({"cpu": time.process_time() - t0, "main": time.thread_time() - m0,
                              "cycle_s": spent["cycle_ns"] / 1e9, "encode_s": spent["encode_ns"] / 1e9,
                              "writer_s": writer,
                              "restarts": restarts,
                              "alarms": len(rt.machine.active_alarms)}), flush=True)
            return
        cycles = int(cmd[1])
        t0, m0 = time.process_time(), time.thread_time()
        for ch in rt.machine.channels:
            if ch.state.label in ("idle", "finished"):
                name, text = PROGRAMS[ch.number]
                rt.operator.load_program(ch.number, text, name)
                rt.operator.start(ch.number)
                restarts += 1
        await rt.step(cycles)
        await asyncio.sleep(0)
        print(json.dumps({"cpu": time.process_time() - t0, "main": time.thread_time() - m0}), flush=True)

asyncio.run(main())
"""

ENGINE_ALONE = r"""
import json, sys, time
from benchmarks.scenarios import full_machine
from benchmarks.programs import pocket_program, shuttle_program
m = full_machine()
cycles = int(sys.argv[1])
t0 = time.process_time()
done = 0
while done < cycles:
    for ch in m.channels:
        if ch.state.label in ("idle", "finished"):
            ch.load_program(pocket_program(12) if ch.number == 1 else shuttle_program(4000))
            ch.request_start()
    n = min(5000, cycles - done)
    m.step(n)
    done += n
print(json.dumps({"cpu": time.process_time() - t0}))
"""


class Worker:
    def __init__(self, record: str | None, every: int = 100) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-c", WORKER, record or "-", str(every)],
            cwd=ROOT,
            env=dict(os.environ),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        self.compiled = bool(json.loads(self.proc.stdout.readline())["compiled"])

    def ask(self, line: str) -> dict[str, float]:
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        reply: dict[str, float] = json.loads(self.proc.stdout.readline())
        return reply


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cycles", type=int, default=600_000, help="machine time in cycles (600,000 = 10 min)")
    ap.add_argument("--slice", type=int, default=5000)
    ap.add_argument("--keep", type=Path, default=None, help="keep the recording here")
    ap.add_argument(
        "--outputs-every",
        type=int,
        default=100,
        help="the recording samples the outputs every N cycles (--record-outputs-every; 1: every cycle)",
    )
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = args.keep or Path(tmp) / "full.jsonl.gz"
        path.unlink(missing_ok=True)
        plain, recording = Worker(None), Worker(str(path), args.outputs_every)
        cpu = {"plain": 0.0, "record": 0.0, "record_main": 0.0}
        done = 0
        began = time.perf_counter()
        while done < args.cycles:
            n = min(args.slice, args.cycles - done)
            cpu["plain"] += plain.ask(f"step {n}")["cpu"]
            answer = recording.ask(f"step {n}")
            cpu["record"] += answer["cpu"]
            cpu["record_main"] += answer["main"]
            done += n
        end_plain = plain.ask("stop")
        end_record = recording.ask("stop")
        cpu["record"] += end_record["cpu"]  # the last encoding and flush
        cpu["record_main"] += end_record["main"]
        wall = time.perf_counter() - began
        size = path.stat().st_size

        from hli_server.replay import replay_sync

        t0 = time.process_time()
        report = replay_sync(path)
        replay_cpu = time.process_time() - t0
        alone = json.loads(
            subprocess.run(
                [sys.executable, "-c", ENGINE_ALONE, str(args.cycles)],
                cwd=ROOT,
                capture_output=True,
                text=True,
                check=True,
            ).stdout
        )["cpu"]

    engine = "compiled" if recording.compiled else "pure Python"
    cycles = args.cycles
    t_a_us = 1000.0
    per_plain = cpu["plain"] / cycles * 1e6
    per_record = cpu["record"] / cycles * 1e6
    per_record_main = cpu["record_main"] / cycles * 1e6
    overhead = per_record - per_plain
    overhead_main = per_record_main - per_plain
    hours = cycles * t_a_us / 1e6 / 3600
    per_engine = alone / cycles * 1e6
    print(
        f"engine: {engine}; {cycles:,} cycles = {cycles / 60_000:.1f} min of machine time; "
        f"wall {wall:.0f} s; "
        f"outputs sampled every {args.outputs_every} cycles"
    )
    print(
        f"program restarts: {end_record['restarts']:.0f}; "
        f"active alarms at the end: {end_record['alarms']:.0f}"
    )
    print(f"recording: {size / 1e6:.2f} MB = {size / 1e6 / hours:.1f} MB per hour of machine time")
    print(
        f"runtime without recording: {per_plain:.1f} µs/cycle CPU; "
        f"with recording: {per_record:.1f} µs/cycle; "
        f"overhead {overhead:.2f} µs/cycle = {overhead / t_a_us * 100:.2f} % of T_A (goal < 5 %), "
        f"{overhead / per_plain * 100:.1f} % of the runtime's own time per cycle (CPU of all threads)"
    )
    print(
        f"the engine's cycle (Machine.step alone, same scenario): {per_engine:.1f} µs; record overhead / "
        f"engine cycle: {overhead / per_engine * 100:.1f} % (goal < 5 %: "
        f"{'met' if overhead / per_engine < 0.05 else 'MISSED'})"
    )
    print(
        f"of it on the event loop's thread (the cycle, the encoder; not the writer thread's compression): "
        f"{overhead_main:.2f} µs/cycle = {overhead_main / t_a_us * 100:.2f} % of T_A, "
        f"{overhead_main / per_plain * 100:.1f} % of the runtime's time per cycle"
    )
    tap = {k: (end_record[k] - end_plain[k]) / cycles * 1e6 for k in ("cycle_s", "encode_s")}
    writer_us = end_record["writer_s"] / cycles * 1e6
    direct = tap["cycle_s"] + tap["encode_s"] + writer_us
    print(
        f"measured in the tap (recording - journal only, wall time of the calls): in the cycle "
        f"{tap['cycle_s']:.3f} µs/cycle, encoder {tap['encode_s']:.3f} µs/cycle, writer thread CPU "
        f"{writer_us:.3f} µs/cycle: {direct:.2f} µs/cycle = {direct / per_engine * 100:.1f} % of the "
        f"engine's cycle; the cycle's own share: {tap['cycle_s'] / per_engine * 100:.1f} %"
    )
    print(
        f"replay: {report.verdict} in {replay_cpu:.1f} s CPU = {cycles / replay_cpu:,.0f} cycles/s; "
        f"engine alone (Machine.step, same scenario): {cycles / alone:,.0f} cycles/s; "
        f"runtime without recording: {cycles / cpu['plain']:,.0f} cycles/s"
    )
    print(
        f"ratio replay / engine alone: {alone / replay_cpu:.2f}; replay / runtime without recording: "
        f"{cpu['plain'] / replay_cpu:.2f}"
    )
    if end_plain.get("alarms"):
        print(f"WARNING: {end_plain['alarms']:.0f} alarms active at the end")
    if report.verdict != "pass":
        print("WARNING: " + report.text())


if __name__ == "__main__":
    main()
