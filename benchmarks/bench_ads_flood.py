"""ADS door under a flood: the engine's lateness and an honest client's latency (H-04).

Each phase starts a fresh server process (the runtime with the demo machine, realtime clock,
T_A = 1 ms, the ``ads`` adapter with its default limits, the event loop ``hli-server run`` uses)
and runs for ``--seconds``:

* ``idle``: nobody connected (the machine's own lateness, the baseline);
* ``honest``: one pyads client reading one DINT in a loop;
* ``flood, never reads``: the honest client, plus a raw client that pipelines reads of the whole
  CNC->PLC half as fast as it can write and never reads an answer;
* ``flood, pipelined``: the honest client, plus a raw client that keeps 64 reads of the whole
  CNC->PLC half in flight and reads the answers as fast as it can (the most work one client can ask).

Printed per phase: the runtime's lateness p50/p99/max and dropped cycles (``GET /api/timing``'s
figures), the honest client's calls/s and p50/p99, the requests the server answered in all and
what the flooder read of them.

    .venv/bin/python -m benchmarks.bench_ads_flood [--seconds 5]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import socket
import struct
import time
from array import array
from multiprocessing.connection import Connection
from typing import Any

from benchmarks._servers import CTX, Server
from benchmarks.bench_ads import SYMBOL, _address, _serve_hli

HALF_GROUP = 0xF020


def _read_frame(invoke: int, group: int, offset: int, length: int) -> bytes:
    payload = struct.pack("<III", group, offset, length)
    header = bytes((127, 0, 0, 1, 1, 1)) + struct.pack("<H", 851) + bytes((10, 9, 9, 9, 1, 1))
    header += struct.pack("<HHHIII", 30000, 2, 4, len(payload), 0, invoke)
    return struct.pack("<HI", 0, 32 + len(payload)) + header + payload


def _c2p_size() -> int:
    from hli_server.configuration import load_machine
    from schemas.layout import build_layout

    return build_layout(load_machine(None)).c2p_size


def _flood(conn: Connection, port: int, mode: str, seconds: float) -> None:
    """Raw flooder; reports (requests written to its socket, answers read, bytes written)."""
    size = _c2p_size()
    chunk = b"".join(_read_frame(i, HALF_GROUP, 0, size) for i in range(64))
    answer = 38 + 8 + size
    sock = socket.create_connection(("127.0.0.1", port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    stop_at = time.perf_counter() + seconds
    sent = answers = sent_bytes = 0
    if mode == "never reads":
        sock.settimeout(0.2)
        while time.perf_counter() < stop_at:
            try:
                n = sock.send(chunk)
            except TimeoutError:
                continue  # the server stopped reading us: our send buffer is full
            sent_bytes += n
        sent = sent_bytes // len(chunk[: len(chunk) // 64])
    else:
        buf = bytearray(answer * 64)
        view = memoryview(buf)
        while time.perf_counter() < stop_at:
            sock.sendall(chunk)
            sent += 64
            sent_bytes += len(chunk)
            need = answer * 64
            got = 0
            while got < need:
                n = sock.recv_into(view[got:], need - got)
                if n == 0:
                    raise ConnectionError("the server closed the flooder's connection")
                got += n
            answers += 64
    with contextlib.suppress(OSError):
        sock.close()
    conn.send((sent, answers, sent_bytes))


def _honest(conn: Connection, port: int, seconds: float) -> None:
    import pyads

    group, offset = _address()
    pyads.open_port()
    pyads.set_local_address("10.1.2.3.1.1")
    pyads.close_port()
    plc = pyads.Connection("127.0.0.1.1.1", 851, f"127.0.0.1:{port}")
    plc.open()
    plc.set_timeout(5000)
    latencies = array("Q")
    errors = 0
    stop_at = time.perf_counter() + seconds
    while time.perf_counter() < stop_at:
        t0 = time.perf_counter_ns()
        try:
            plc.read(group, offset, pyads.PLCTYPE_DINT)
        except pyads.ADSError:
            errors += 1
        latencies.append(time.perf_counter_ns() - t0)
        time.sleep(0.0005)  # a polling HMI/PLC, not a benchmark loop
    plc.close()
    conn.send((latencies.tobytes(), errors))


def _start(target: Any, *args: Any) -> tuple[Any, Connection]:
    parent, child = CTX.Pipe()
    process = CTX.Process(target=target, args=(child, *args), daemon=True)
    process.start()
    return process, parent


def _percentile(data: list[int], q: float) -> float:
    if not data:
        return float("nan")
    k = max(0, min(len(data) - 1, int(q / 100 * len(data) + 0.5) - 1))
    return data[k] / 1000


def phase(name: str, seconds: float) -> dict[str, Any]:
    server = Server.start("hli-server", _serve_hli)
    out: dict[str, Any] = {"phase": name}
    try:
        time.sleep(0.5)  # start-up behind us
        jobs = []
        if name != "idle":
            jobs.append(("honest", *_start(_honest, server.port, seconds)))
        if name.startswith("flood"):
            mode = name.split(", ", 1)[1]
            jobs.append(("flood", *_start(_flood, server.port, mode, seconds)))
        if name == "idle":
            time.sleep(seconds)
        for kind, process, pipe in jobs:
            if pipe.poll(seconds + 30):
                result = pipe.recv()
                if kind == "honest":
                    raw, errors = result
                    lat = array("Q")
                    lat.frombytes(raw)
                    ordered = sorted(lat)
                    out["honest"] = (
                        len(ordered) / seconds,
                        _percentile(ordered, 50),
                        _percentile(ordered, 99),
                        errors,
                    )
                else:
                    out["flood"] = result
            process.join(10)
    finally:
        out["timing"] = server.stop()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="length of each phase [s]")
    args = parser.parse_args()
    print(
        f"ADS door, realtime clock T_A = 1 ms, default limits; {args.seconds:g} s per phase, "
        f"{os.cpu_count()} CPUs shared; honest client: pyads raw read of {SYMBOL} every 0.5 ms"
    )
    print(
        f"{'phase':<20} {'late p50 us':>11} {'p99 us':>8} {'max us':>8} {'dropped':>7} "
        f"{'honest/s':>8} {'p50 us':>8} {'p99 us':>8}  flooder"
    )
    for name in ("idle", "honest", "flood, never reads", "flood, pipelined"):
        r = phase(name, args.seconds)
        t = r["timing"] or {}
        late = t.get("lateness_us") or {}
        honest = r.get("honest")
        h = (
            f"{honest[0]:>8.0f} {honest[1]:>8.1f} {honest[2]:>8.1f}"
            if honest
            else f"{'-':>8} {'-':>8} {'-':>8}"
        )
        flood = r.get("flood")
        door = t.get("ads") or {}
        f = (
            f"server answered {door.get('requests', 0)} requests"
            + (f", the flooder read {flood[1]}" if flood else "")
            + f"; longest turn of the door {door.get('longest_turn_us', 0)} us, "
            f"{door.get('turns_over_1ms', 0)} of {door.get('turns', 0)} turns over 1 ms"
        )
        print(
            f"{name:<20} {late.get('p50', float('nan')):>11.0f} {late.get('p99', float('nan')):>8.0f} "
            f"{late.get('max', float('nan')):>8.0f} {t.get('slipped_cycles', '?'):>7} {h}  {f}"
        )


if __name__ == "__main__":
    main()
