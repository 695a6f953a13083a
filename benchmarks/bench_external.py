"""What the V.E. variables cost the cycle: the image's latch + publish with and without them (N-05).

Per cycle the image keeps the V.E. fields and the engine's store in step (``hli_server/image/external.py``):
one ``unpack_from`` of the V.E. area and one list comparison per side, element-wise work only where
something changed. Measured here, the image in a buffer (no second process), the engine not stepped (its
cost does not change with V.E.):

* the reference: latch + publish of the demo machine's HLI without any V.E. variable, same run;
* the demo's three variables, quiet (nobody writes);
* 1050 elements (the most the Modbus area holds: 350 SGN32 and 700 BOOLEAN), quiet;
* the same 1050 elements with a PLC write and an NC write to different elements in every cycle.

    .venv/bin/python -m benchmarks.bench_external [--cycles N]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

from hli_server.configuration import load_machine
from hli_server.engine.machine import Machine
from hli_server.image import ProcessImage
from schemas.config import ExternalVariableConfig, MachineConfig
from schemas.layout import build_layout

BIG = [
    ExternalVariableConfig(name="COUNTS", type="SGN32", dims=[350], channel=1),
    ExternalVariableConfig(name="FLAGS", type="BOOLEAN", dims=[700]),
]


def _rig(config: MachineConfig) -> tuple[Machine, ProcessImage]:
    machine = Machine(config)
    image = ProcessImage.in_memory(build_layout(config))
    image.init_from(machine.hli, 0, machine.external)
    return machine, image


def _time(cycles: int, one: Callable[[int], None]) -> tuple[float, float]:
    samples = []
    for k in range(cycles):
        start = time.perf_counter_ns()
        one(k)
        samples.append(time.perf_counter_ns() - start)
    samples.sort()
    return statistics.median(samples) / 1000, samples[int(0.99 * len(samples))] / 1000


def measure(config: MachineConfig, cycles: int, *, writes: bool = False) -> tuple[float, float]:
    machine, image = _rig(config)
    hli, store = machine.hli, machine.external
    counts = "gpVECh[0]^COUNTS[{}]"

    def one(k: int) -> None:
        if writes:
            image.write(counts.format(k % 350), k)  # the PLC
        image.latch_into(hli)
        if writes:
            store.write("FLAGS", None, bool(k & 1), (k % 700,))  # the NC
        image.publish_from(hli, k)

    try:
        return _time(cycles, one)
    finally:
        image.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cycles", type=int, default=20_000)
    args = ap.parse_args()
    demo = load_machine(None)
    bare = demo.model_copy(update={"external_variables": []})
    big = demo.model_copy(update={"external_variables": BIG})
    ref = measure(bare, args.cycles)
    rows = [
        ("demo's 3 V.E. variables, quiet", measure(demo, args.cycles)),
        ("1050 V.E. elements, quiet", measure(big, args.cycles)),
        ("1050 V.E. elements, a PLC and an NC write every cycle", measure(big, args.cycles, writes=True)),
    ]
    print(f"reference: latch + publish without V.E.: median {ref[0]:.1f} µs, p99 {ref[1]:.1f} µs")
    for what, (median, p99) in rows:
        print(f"{what}: median {median:.1f} µs, p99 {p99:.1f} µs; ratio (median) {median / ref[0]:.2f}")


if __name__ == "__main__":
    main()
