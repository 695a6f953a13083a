"""The realtime clock under network load (issue 12): 200 polling PLC clients plus a flooding one.

One ``hli-server run`` (realtime clock, T_A = 1 ms, the demo machine running a program) in a process of
its own; the load comes from another process (this one): ``--pollers`` Modbus TCP clients, each reading
20 input registers every ``--period`` seconds and waiting for its answer, plus ``--flooders`` clients
that pipeline FC 3 requests as fast as the socket takes them and read the answers only now and then.
Each phase is a fresh server; the phases run in one go, so that the machine's load hits them alike:

* ``idle``: no client (the reference: what the machine itself costs the clock);
* ``pollers``: the polling clients;
* ``pollers + flood``: the polling clients and the flooders;
* the last two again with ``hli-server run --doors-process`` (Modbus served by a second process attached
  to the shared memory, docs/reliability.md).

Per phase: the clock's lateness p50 / p99 / max and the cycles dropped (``GET /api/timing`` at the end;
its percentiles cover the newest 60,000 cycles, i.e. the phase), the pollers' answer time p50 / p99.
The goal of issue 12: lateness p99 at or below 2 ms and no dropped cycle under 200 pollers and a flood.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import struct
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any

__all__ = ["main"]

PROGRAM = "".join(
    f"N{10 * (i + 1)} G01 X{100 if i % 2 == 0 else 0} Y{50 if i % 4 < 2 else -50} F9000\n" for i in range(400)
)


def _server(seconds: float, doors_process: bool) -> tuple[subprocess.Popen[str], str, int]:
    cli = str(Path(sys.executable).parent / "hli-server")
    extra = ["--doors-process"] if doors_process else ["--no-doors-process"]
    proc = subprocess.Popen(
        [
            cli,
            "run",
            "--http-port",
            "0",
            "--modbus-port",
            "0",
            "--cycles",
            str(int((seconds + 30) * 1000)),
            *extra,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    url, port = "", 0
    assert proc.stdout is not None
    while True:
        line = proc.stdout.readline()
        if not line:
            raise RuntimeError(f"hli-server run ended: {proc.stderr.read() if proc.stderr else ''}")
        if "HTTP control API:" in line:
            url = line.split("HTTP control API:")[1].split()[0]
        if "Modbus TCP:" in line:
            port = int(line.split("Modbus TCP:")[1].split()[0].rsplit(":", 1)[1])
        if "stop with" in line:
            return proc, url, port


def _http(url: str, path: str, body: str | None = None) -> Any:
    data = body.encode() if body is not None else None
    request = urllib.request.Request(url + path, data=data, method="POST" if data is not None else "GET")
    if data is not None:
        request.add_header("content-type", "text/plain")
    with urllib.request.urlopen(request, timeout=10) as r:
        return json.loads(r.read() or b"null")


async def _poller(port: int, period: float, stop: asyncio.Event, latencies: list[float]) -> None:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    tid = 0
    try:
        while not stop.is_set():
            tid = (tid + 1) & 0xFFFF
            began = time.perf_counter()
            writer.write(struct.pack(">HHHBBHH", tid, 0, 6, 1, 4, 2000, 20))
            head = await reader.readexactly(7)
            await reader.readexactly(struct.unpack(">H", head[4:6])[0] - 1)
            latencies.append(time.perf_counter() - began)
            await asyncio.sleep(period)
    finally:
        writer.close()


async def _flooder(port: int, stop: asyncio.Event, sent: list[int]) -> None:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    burst = struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, 0, 2) * 1000
    try:
        while not stop.is_set():
            writer.write(burst)
            sent[0] += 1000
            try:
                await asyncio.wait_for(writer.drain(), 0.05)
            except TimeoutError:
                with_data = reader._buffer
                with_data.clear()
                await asyncio.sleep(0.005)
    finally:
        writer.transport.abort()


async def _phase(port: int, pollers: int, flooders: int, seconds: float, period: float) -> dict[str, Any]:
    stop = asyncio.Event()
    latencies: list[float] = []
    sent = [0]
    tasks = [asyncio.create_task(_poller(port, period, stop, latencies)) for _ in range(pollers)]
    tasks += [asyncio.create_task(_flooder(port, stop, sent)) for _ in range(flooders)]
    await asyncio.sleep(seconds)
    stop.set()
    await asyncio.gather(*tasks, return_exceptions=True)
    latencies.sort()

    def q(p: float) -> float | None:
        return latencies[min(len(latencies) - 1, int(p * len(latencies)))] * 1e3 if latencies else None

    return {"polls": len(latencies), "poll_p50_ms": q(0.5), "poll_p99_ms": q(0.99), "flood_sent": sent[0]}


def run(
    name: str, pollers: int, flooders: int, seconds: float, period: float, doors_process: bool = False
) -> dict[str, Any]:
    proc, url, port = _server(seconds, doors_process)
    try:
        _http(url, "/api/channels/1/program", PROGRAM)
        _http(url, "/api/channels/1/start", "")
        time.sleep(0.5)
        before = _http(url, "/api/timing")
        load = asyncio.run(_phase(port, pollers, flooders, seconds, period))
        after = _http(url, "/api/timing")
    finally:
        proc.terminate()
        proc.wait(15)
    late = after["lateness_us"] or {}
    return {
        "phase": name,
        "p50_us": late.get("p50"),
        "p99_us": late.get("p99"),
        "max_us": late.get("max"),
        "dropped": after["slipped_cycles"] - before["slipped_cycles"],
        "cycles": after["cycles"] - before["cycles"],
        **load,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=10.0, help="length of each phase")
    parser.add_argument("--pollers", type=int, default=200)
    parser.add_argument("--flooders", type=int, default=1)
    parser.add_argument("--period", type=float, default=0.1, help="seconds between a poller's requests")
    args = parser.parse_args()
    n, f, secs, period = args.pollers, args.flooders, args.seconds, args.period
    rows = [
        run("idle", 0, 0, secs, period),
        run(f"{n} pollers", n, 0, secs, period),
        run(f"{n} pollers + {f} flooding", n, f, secs, period),
        run(f"{n} pollers, doors process", n, 0, secs, period, doors_process=True),
        run(f"{n} pollers + {f} flooding, doors proc.", n, f, secs, period, doors_process=True),
    ]
    head = f"{'phase':34} {'lateness p50':>12} {'p99':>9} {'max':>9} {'dropped':>8}"
    print(f"{head} {'polls':>7} {'poll p50':>9} {'poll p99':>9}")
    for r in rows:
        poll50 = f"{r['poll_p50_ms']:.2f} ms" if r["poll_p50_ms"] is not None else "-"
        poll99 = f"{r['poll_p99_ms']:.2f} ms" if r["poll_p99_ms"] is not None else "-"
        late = f"{r['p50_us']:>9.0f} µs {r['p99_us']:>6.0f} µs {r['max_us']:>6.0f} µs {r['dropped']:>8}"
        print(f"{r['phase']:34} {late} {r['polls']:>7} {poll50:>9} {poll99:>9}")
    idle = rows[0]
    for loaded in (rows[2], rows[4]):
        met = loaded["p99_us"] <= 2000 and loaded["dropped"] == 0
        print(
            f"{loaded['phase']}: p99 lateness / idle {loaded['p99_us'] / idle['p99_us']:.2f}x; "
            f"goal (issue 12): p99 <= 2000 µs and no dropped cycle: {'met' if met else 'not met'}"
        )


if __name__ == "__main__":
    main()
