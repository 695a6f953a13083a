"""The ADS device's CPU time per request, compiled and pure Python, in one run (H-04, issue 38).

The ADS door's request path (``hli_server/_compiled.py``: ``ADS_COMPILED``) is compiled with the engine.
This measures what that buys where the door's own time is all there is: the device answering frames in
a loop, no socket, no event loop, hot caches. Per request, best of ``--repeat``:

* ``raw read``: a Read of one DINT of the CNC->PLC half (``pyads`` ``Connection.read``);
* ``read_by_name``: the three requests of ``pyads`` ``read_by_name`` (handle by name, read by handle,
  release), counted as one call;
* ``sum read``: a sum read (0xF080) of ten DINTs of both halves;
* ``write``: a Write of one DINT of the PLC->CNC half (a ``_w`` field).

The reference is the same device run as pure Python (``HLI_PURE_PYTHON=1``). Each build runs in
processes of its own, ``--turns`` of each taken in turn (compiled, pure, compiled, ...: a slow phase of a
shared host falls on both); printed: µs per request of each, the best of all its turns, and pure /
compiled. Where nothing is compiled here (no C compiler at install), both columns are pure Python and it
says so.

    .venv/bin/python -m benchmarks.bench_ads_device [--turns 3] [--repeat 5] [--seconds 0.5]
"""

from __future__ import annotations

import argparse
import json
import struct
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SYMBOL = "gpAx[0]^ipo_state.cmd_pos_r"
WRITTEN = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w"
MODES = ("raw read", "read_by_name", "sum read", "write")


def measure(repeat: int, seconds: float) -> dict[str, object]:
    """µs per request of each mode, best of ``repeat``, in this process (compiled or pure as it runs)."""
    import hli_server._compiled as compiled
    from hli_server.adapters.ads import AdsDevice, Session
    from hli_server.codecs.ads import AmsAddress, CommandId, NetId, encode_request
    from hli_server.configuration import load_machine
    from hli_server.image import ProcessImage
    from schemas.layout import Direction, build_layout

    layout = build_layout(load_machine(None))
    image = ProcessImage.in_memory(layout, name="bench_ads_device")
    try:
        image.publish_bytes(layout.pack(Direction.CNC_TO_PLC, {SYMBOL: 123456}), 1)
        server = NetId.parse("127.0.0.1.1.1")
        client = AmsAddress(NetId.parse("10.1.2.3.1.1"), 30001)
        source = bytes(client.net_id)
        device = AdsDevice(image, server)
        session = Session()
        position, written = layout.signal(SYMBOL), layout.signal(WRITTEN)

        def frame(command: int, payload: bytes) -> bytes:
            return encode_request(AmsAddress(server, 851), client, command, 1, payload)

        raw = frame(CommandId.READ, struct.pack("<III", 0xF020, position.offset, 4))
        name = SYMBOL.encode() + b"\0"
        get = frame(CommandId.READ_WRITE, struct.pack("<IIII", 0xF003, 0, 4, len(name)) + name)
        by_handle = bytearray(frame(CommandId.READ, struct.pack("<III", 0xF005, 0, 4)))
        release = bytearray(frame(CommandId.WRITE, struct.pack("<III", 0xF006, 0, 4) + bytes(4)))
        items = [(0xF020, position.offset), (0xF030, written.offset)] * 5
        heads = b"".join(struct.pack("<III", group, offset, 4) for group, offset in items)
        sum_read = frame(CommandId.READ_WRITE, struct.pack("<IIII", 0xF080, 10, 80, len(heads)) + heads)
        write = frame(CommandId.WRITE, struct.pack("<IIIi", 0xF030, written.offset, 4, 250000))
        handle_frame = device.handle_frame

        def read_by_name() -> None:
            reply = handle_frame(session, get, source)
            assert reply is not None
            by_handle[42:46] = release[50:54] = reply[-4:]  # the index offset, the released handle
            handle_frame(session, bytes(by_handle), source)
            handle_frame(session, bytes(release), source)

        calls: dict[str, Callable[[], object]] = {
            "raw read": lambda: handle_frame(session, raw, source),
            "read_by_name": read_by_name,
            "sum read": lambda: handle_frame(session, sum_read, source),
            "write": lambda: handle_frame(session, write, source),
        }
        for call in calls.values():  # every reply is one the device answers without an error
            call()
        assert device.stats.errors == {}, device.stats.errors
        best: dict[str, float] = {}
        for mode, call in calls.items():
            n = 1000
            for _ in range(repeat):
                while True:
                    t0 = time.perf_counter()
                    for _ in range(n):
                        call()
                    elapsed = time.perf_counter() - t0
                    if elapsed >= seconds / 4:
                        break
                    n *= 2
                best[mode] = min(best.get(mode, float("inf")), elapsed / n * 1e6)
        assert device.stats.errors == {}, device.stats.errors
        return {"compiled": compiled.ENGINE_COMPILED, "us": best}
    finally:
        image.close()


def _in_process(pure: bool, repeat: int, seconds: float) -> dict[str, object]:
    from hli_server._compiled import environment

    code = (
        "import json, sys\n"
        "from benchmarks.bench_ads_device import measure\n"
        f"print(json.dumps(measure({repeat}, {seconds})))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env=environment(pure),
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    result: dict[str, object] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=0.5, help="per mode and repetition (about)")
    parser.add_argument("--turns", type=int, default=3, help="processes of each build, taken in turn")
    args = parser.parse_args()
    best: dict[bool, dict[str, float]] = {False: {}, True: {}}
    compiled = False
    for _ in range(args.turns):
        for pure in (False, True):
            result = _in_process(pure, args.repeat, args.seconds)
            compiled = compiled or (not pure and bool(result["compiled"]))
            us = result["us"]
            assert isinstance(us, dict)
            for mode in MODES:
                best[pure][mode] = min(best[pure].get(mode, float("inf")), float(us[mode]))
    if not compiled:
        print("nothing is compiled here (no C compiler or mypyc at install): both columns are pure Python")
    print(f"{'request':<14} {'compiled':>10} {'pure Python':>12} {'pure / compiled':>16}")
    for mode in MODES:
        b, p = best[False][mode], best[True][mode]
        print(f"{mode:<14} {b:>8.2f} µs {p:>9.2f} µs {p / b:>15.2f}x")


if __name__ == "__main__":
    main()
