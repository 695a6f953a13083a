"""The shared-memory process image seen from a second process (H-01).

1. Operations per second of a PLC process on the image (``plc_clients.shm.ImageClient``): single-field
   writes, single-field reads (consistent CNC->PLC read), whole consistent snapshots. Reference, same
   run, same process, same bytes: a bare ``struct.pack_into`` / ``unpack_from`` on the mapped segment
   (the least any access can cost); printed as a ratio.
2. Latency from a PLC write to the engine using it, in cycles: the PLC writes a new feed-override
   command (enable_w set), then polls until ``state_r`` shows it; latency = published cycle that shows
   it - newest published cycle at the write. Reference: 1 cycle (latched at the start of the next
   cycle, published at its end); realtime clock, T_A = 1 ms.

    .venv/bin/python -m benchmarks.bench_image [--seconds S] [--samples N]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import subprocess
import sys
from pathlib import Path

from hli_server.configuration import load_machine
from hli_server.runtime import Runtime

ROOT = Path(__file__).resolve().parents[1]

CLIENT = r"""
import json, struct, sys, time
from plc_clients.shm import ImageClient

name, seconds, samples = sys.argv[1], float(sys.argv[2]), int(sys.argv[3])
unit = "gpCh[0]^bahn_mc_control.override"
result = {}
with ImageClient.attach(name, timeout=5.0) as plc:
    def rate(fn):
        n = 0
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            for _ in range(1000):
                fn()
            n += 1000
        return n / seconds
    w_sig = plc.signal(unit + ".command_w")
    r_path = "gpAx[0]^ipo_state.cmd_pos_r"
    result["write"] = rate(lambda: plc.write(unit + ".command_w", 1000))
    result["read"] = rate(lambda: plc.read(r_path))
    result["snapshot"] = rate(plc.snapshot)
    # reference: bare struct access on the same mapping
    buf = plc._buf
    off = plc.plan.p2c_offset + w_sig.offset
    st = struct.Struct("<i")
    result["raw_write"] = rate(lambda: st.pack_into(buf, off, 1000))
    result["raw_read"] = rate(lambda: st.unpack_from(buf, off))
    # latency in cycles
    plc.write(unit + ".command_w", 1000)
    plc.write(unit + ".enable_w", True)
    time.sleep(0.05)
    lat = []
    for i in range(samples):
        value = 500 + (i % 2) * 100
        plc.write(unit + ".command_w", value)
        written = plc.cycle
        deadline = time.monotonic() + 1.0
        while True:
            snap = plc.snapshot()
            if snap[unit + ".state_r"] == value:
                lat.append(snap.cycle - written)
                break
            if time.monotonic() > deadline:
                lat.append(None)
                break
        time.sleep(0.003)
    result["latency"] = lat
print(json.dumps(result))
"""


async def run(seconds: float, samples: int) -> dict[str, object]:
    config = load_machine(None)
    async with Runtime(config, clock="realtime", http_port=None) as rt:
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            CLIENT,
            rt.image.name,
            str(seconds),
            str(samples),
            stdout=subprocess.PIPE,
            cwd=ROOT,
        )
        out, _ = await asyncio.wait_for(proc.communicate(), timeout=60 + 6 * seconds + samples * 0.1)
    result: dict[str, object] = json.loads(out)
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=1.0, help="per operation kind")
    ap.add_argument("--samples", type=int, default=300, help="latency samples")
    args = ap.parse_args()
    r = asyncio.run(run(args.seconds, args.samples))
    write, read, snap = float(r["write"]), float(r["read"]), float(r["snapshot"])  # type: ignore[arg-type]
    raw_w, raw_r = float(r["raw_write"]), float(r["raw_read"])  # type: ignore[arg-type]
    print(f"image write (one field, second process): {write:,.0f} ops/s")
    print(f"reference: bare struct.pack_into: {raw_w:,.0f} ops/s; ratio {write / raw_w:.2f}")
    print(f"image read (one field, consistent): {read:,.0f} ops/s")
    print(f"reference: bare struct.unpack_from: {raw_r:,.0f} ops/s; ratio {read / raw_r:.2f}")
    print(f"image snapshot (all CNC->PLC fields, consistent): {snap:,.0f} ops/s")
    lat = [x for x in r["latency"] if x is not None]  # type: ignore[attr-defined]
    missed = len(r["latency"]) - len(lat)  # type: ignore[arg-type]
    lat.sort()
    p50 = statistics.median(lat)
    p99 = lat[min(len(lat) - 1, int(0.99 * len(lat)))]
    print(
        f"latency PLC write -> engine uses it (published): p50 {p50} cycles, p99 {p99}, max {lat[-1]} "
        f"({len(lat)} samples, {missed} missed)"
    )
    print(f"reference: 1 cycle (latched at the next cycle's start); ratio p50/reference {p50 / 1:.1f}")


if __name__ == "__main__":
    main()
