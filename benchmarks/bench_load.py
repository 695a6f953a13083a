"""The realtime clock under network load (E-01): PLC pollers, a flood, large reads, dashboards.

One ``hli-server run`` per phase (realtime clock, T_A = 1 ms, the demo machine running a program) in a
process of its own, as users start it (the doors process: Modbus, HTTP and the dashboards' streams served
by a second process, docs/reliability.md); the load comes from this process:

* ``pollers``: ``--pollers`` Modbus TCP clients, each reading 20 input registers every ``--period`` s and
  waiting for its answer; ``flood``: ``--flooders`` clients that pipeline FC 3 requests as fast as the
  socket takes them and read the answers only now and then;
* ``event readers``: ``--readers`` HTTP clients reading ``GET /api/events?since=0&limit=10000`` (the full
  log: about 1.4 MB of JSON per answer) back to back; the log is filled first by a PLC on the shared
  memory that toggles the channels' override and feedhold (four events a cycle);
* ``dashboards``: ``--dashboards`` event streams (``GET /api/live``) that never read what they are sent,
  and one that reads;
* ``everything``: all of it at once;
* the flood and the readers again with ``--no-doors-process`` (every door on the clock's loop), for
  comparison.

The idle phase (no client: what the machine itself costs the clock) runs first *and* last, so that a
machine whose load changed during the run shows itself; the core count and the load average are printed
with every phase. Per phase: the clock's lateness p50 / p99 / p99.9 / max and the cycles dropped (``GET
/api/timing`` at the end; its percentiles cover the newest 60,000 cycles, i.e. the phase), the cycles
later than T_A by cause, and the five worst cycles with their cause (the trace of where late starts come
from: the operating system, garbage collection, other work on the clock's loop, requests served between
cycles, the cycle's own work).

Goals (docs/performance.md, "The clock under load"): on a quiet multi-core machine p99 <= 300 µs idle
and <= 1 ms under 200 pollers plus a flood, max <= 5 ms, no dropped cycle; on a 2-core machine the loaded
p99 at most 1.5x the same run's idle p99. The last lines say which are met.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
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
EVENTS_WANTED = 10_000
"""The event log's size: the readers read all of it in every request."""


def machine_line() -> str:
    load = os.getloadavg()
    return f"{os.cpu_count()} cores, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}"


SERVER_ARGS: list[str] = []
"""Further ``hli-server run`` options for every phase (``--server-args``)."""


def _server(seconds: float, doors_process: bool) -> tuple[subprocess.Popen[str], str, int, str]:
    cli = str(Path(sys.executable).parent / "hli-server")
    extra = ["--doors-process"] if doors_process else ["--no-doors-process"]
    extra += SERVER_ARGS
    proc = subprocess.Popen(
        [
            cli,
            "run",
            "--http-port",
            "0",
            "--modbus-port",
            "0",
            "--cycles",
            str(int((seconds + 60) * 1000)),
            *extra,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    url, port, image = "", 0, ""
    assert proc.stdout is not None
    while True:
        line = proc.stdout.readline()
        if not line:
            raise RuntimeError(f"hli-server run ended: {proc.stderr.read() if proc.stderr else ''}")
        if "HTTP control API:" in line:
            url = line.split("HTTP control API:")[1].split()[0]
        if "Modbus TCP:" in line:
            port = int(line.split("Modbus TCP:")[1].split()[0].rsplit(":", 1)[1])
        if "shared memory image:" in line:
            image = line.split("shared memory image:")[1].split()[0]
        if "stop with" in line:
            return proc, url, port, image


def _http(url: str, path: str, body: str | None = None) -> Any:
    data = body.encode() if body is not None else None
    request = urllib.request.Request(url + path, data=data, method="POST" if data is not None else "GET")
    if data is not None:
        request.add_header("content-type", "text/plain")
    with urllib.request.urlopen(request, timeout=30) as r:
        return json.loads(r.read() or b"null")


def fill_event_log(image: str, url: str, wanted: int = EVENTS_WANTED) -> int:
    """A PLC on the shared memory toggles both channels' override and feedhold until the log holds
    ``wanted`` events; returns how many there are."""
    from plc_clients.shm import ImageClient

    with ImageClient.attach(image, timeout=5.0) as plc:
        for ch in (0, 1):
            plc.write(f"gpCh[{ch}]^bahn_mc_control.override.enable_w", True)
            plc.write(f"gpCh[{ch}]^bahn_mc_control.feedhold.enable_w", True)
        flip = False
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            latest = _http(url, "/api/events?since=0&limit=1")["latest"]
            if latest >= wanted:
                break
            for _ in range(200):
                flip = not flip
                for ch in (0, 1):
                    plc.write(f"gpCh[{ch}]^bahn_mc_control.override.command_w", 600 if flip else 500)
                    plc.write(f"gpCh[{ch}]^bahn_mc_control.feedhold.command_w", flip)
                time.sleep(0.0011)
        for ch in (0, 1):
            plc.write(f"gpCh[{ch}]^bahn_mc_control.feedhold.command_w", False)
    return int(_http(url, "/api/events?since=0&limit=1")["latest"])


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
                with_data = reader._buffer  # type: ignore[attr-defined]
                with_data.clear()
                await asyncio.sleep(0.005)
    finally:
        writer.transport.abort()


async def _http_get(host: str, port: int, path: str) -> tuple[int, int]:
    """One GET on a fresh connection; (status, body bytes)."""
    reader, writer = await asyncio.open_connection(host, port)
    try:
        writer.write(f"GET {path} HTTP/1.1\r\nhost: {host}:{port}\r\nconnection: close\r\n\r\n".encode())
        data = await reader.read()
    finally:
        writer.close()
    head, _, body = data.partition(b"\r\n\r\n")
    return int(head.split()[1]), len(body)


async def _reader(url: str, stop: asyncio.Event, got: list[int]) -> None:
    host, port = url.removeprefix("http://").rsplit(":", 1)
    while not stop.is_set():
        status, size = await _http_get(host, int(port), "/api/events?since=0&limit=10000")
        if status == 200:
            got[0] += 1
            got[1] += size


async def _dashboard(url: str, stop: asyncio.Event, reads: bool, got: list[int]) -> None:
    host, port = url.removeprefix("http://").rsplit(":", 1)
    reader, writer = await asyncio.open_connection(host, int(port))
    writer.write(f"GET /api/live HTTP/1.1\r\nhost: {host}:{port}\r\n\r\n".encode())
    try:
        while not stop.is_set():
            if reads:
                chunk = await reader.read(65536)
                if not chunk:
                    return
                got[2] += len(chunk)
            else:
                await asyncio.sleep(0.1)  # never reads: the server's buffers fill
    finally:
        writer.transport.abort()


async def _phase(url: str, port: int, seconds: float, period: float, load: dict[str, int]) -> dict[str, Any]:
    stop = asyncio.Event()
    latencies: list[float] = []
    sent = [0]
    got = [0, 0, 0]
    tasks = [
        asyncio.create_task(_poller(port, period, stop, latencies)) for _ in range(load.get("pollers", 0))
    ]
    tasks += [asyncio.create_task(_flooder(port, stop, sent)) for _ in range(load.get("flooders", 0))]
    tasks += [asyncio.create_task(_reader(url, stop, got)) for _ in range(load.get("readers", 0))]
    dashboards = load.get("dashboards", 0)
    tasks += [asyncio.create_task(_dashboard(url, stop, i == 0, got)) for i in range(dashboards)]
    await asyncio.sleep(seconds)
    stop.set()
    if tasks:
        await asyncio.wait(tasks, timeout=10)
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    latencies.sort()

    def q(p: float) -> float | None:
        return latencies[min(len(latencies) - 1, int(p * len(latencies)))] * 1e3 if latencies else None

    return {
        "polls": len(latencies),
        "poll_p50_ms": q(0.5),
        "poll_p99_ms": q(0.99),
        "flood_sent": sent[0],
        "reads": got[0],
        "read_mb": got[1] / 1e6,
        "stream_kb": got[2] / 1e3,
    }


def run(
    name: str, seconds: float, period: float, load: dict[str, int], doors_process: bool = True
) -> dict[str, Any]:
    before_load = machine_line()
    proc, url, port, image = _server(seconds, doors_process)
    try:
        events = fill_event_log(image, url) if load.get("readers") else None
        _http(url, "/api/channels/1/program", PROGRAM)
        _http(url, "/api/channels/1/start", "")
        time.sleep(0.5)
        before = _http(url, "/api/timing")
        result = asyncio.run(_phase(url, port, seconds, period, load))
        after = _http(url, "/api/timing")
    finally:
        proc.terminate()
        proc.wait(15)
    late = after["lateness_us"] or {}
    return {
        "phase": name,
        "p50_us": late.get("p50"),
        "p99_us": late.get("p99"),
        "p999_us": late.get("p999"),
        "max_us": late.get("max"),
        "dropped": after["slipped_cycles"] - before["slipped_cycles"],
        "cycles": after["cycles"] - before["cycles"],
        "late_causes": after.get("late_causes", {}),
        "worst": after.get("worst", []),
        "events": events,
        "machine": f"{before_load} -> {machine_line().split(', ', 1)[1]}",
        **result,
    }


def print_row(r: dict[str, Any]) -> None:
    poll = f"{r['poll_p50_ms']:.2f} / {r['poll_p99_ms']:.2f} ms" if r["poll_p50_ms"] is not None else "-"
    figures = (r["p50_us"], r["p99_us"], r["p999_us"], r["max_us"])
    late = " ".join(f"{v:>8.0f}" for v in figures) + f" µs {r['dropped']:>6}"
    print(f"{r['phase']:40} {late}  {poll:>18}", flush=True)


def print_causes(r: dict[str, Any]) -> None:
    causes = ", ".join(f"{k} {v}" for k, v in r["late_causes"].items()) or "none"
    extra = []
    if r["reads"]:
        extra.append(f"{r['reads']} event-log reads ({r['read_mb']:.0f} MB; log of {r['events']} events)")
    if r["stream_kb"]:
        extra.append(f"the reading dashboard got {r['stream_kb']:.0f} kB")
    if r["flood_sent"]:
        extra.append(f"flood sent {r['flood_sent']:,} requests")
    print(
        f"    {r['machine']}; cycles later than T_A by cause: {causes}"
        + (f"; {'; '.join(extra)}" if extra else "")
    )
    for w in r["worst"]:
        late = w["lateness_us"] / 1e3
        print(f"      cycle {w['cycle']:>6} at {w['at_s']:6.2f} s: {late:7.2f} ms late: {w['detail']}")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=8.0, help="length of each phase")
    parser.add_argument("--pollers", type=int, default=200)
    parser.add_argument("--flooders", type=int, default=1)
    parser.add_argument("--readers", type=int, default=4, help="clients reading the whole event log")
    parser.add_argument(
        "--dashboards", type=int, default=16, help="event streams (one reads, the rest never)"
    )
    parser.add_argument("--period", type=float, default=0.1, help="seconds between a poller's requests")
    parser.add_argument("--quick", action="store_true", help="idle, pollers + flood, everything, idle only")
    parser.add_argument(
        "--server-args", default="", help="more `hli-server run` options, e.g. '--priority realtime'"
    )
    args = parser.parse_args()
    SERVER_ARGS.extend(args.server_args.split())
    n, f, secs, period = args.pollers, args.flooders, args.seconds, args.period
    poll = {"pollers": n}
    flood = {"pollers": n, "flooders": f}
    readers = {"readers": args.readers}
    dashboards = {"dashboards": args.dashboards}
    everything = {**flood, **readers, **dashboards}
    plan: list[tuple[str, dict[str, int], bool]] = [("idle (first)", {}, True)]
    if not args.quick:
        plan.append((f"{n} pollers", poll, True))
    plan.append((f"{n} pollers + {f} flooding", flood, True))
    if not args.quick:
        plan += [
            (f"{args.readers} event-log readers", readers, True),
            (f"{args.dashboards} dashboards ({args.dashboards - 1} never read)", dashboards, True),
        ]
    plan.append(("everything at once", everything, True))
    if not args.quick:
        plan += [
            (f"{n} pollers + {f} flooding, no doors proc.", flood, False),
            (f"{args.readers} event-log readers, no doors proc.", readers, False),
        ]
    plan.append(("idle (last)", {}, True))
    print(
        f"machine: {machine_line()}; python {sys.version.split()[0]}; {secs:g} s per phase; "
        f"server options: {' '.join(SERVER_ARGS) or 'the defaults'}",
        flush=True,
    )
    print(
        f"{'phase':40} {'late p50':>8} {'p99':>8} {'p99.9':>8} {'max':>8}    {'dropped':>6}  "
        f"{'poll p50 / p99':>18}"
    )
    rows = []
    for name, load, doors in plan:
        row = run(name, secs, period, load, doors_process=doors)
        rows.append(row)
        print_row(row)
        print_causes(row)
    idle = [r for r in rows if r["phase"].startswith("idle")]
    idle_p99 = sum(r["p99_us"] for r in idle) / len(idle)
    print(
        f"idle p99 (first / last): {idle[0]['p99_us']:.0f} / {idle[-1]['p99_us']:.0f} µs, "
        f"mean {idle_p99:.0f} µs"
    )
    for r in rows:
        if r["phase"].startswith("idle"):
            continue
        ratio = r["p99_us"] / idle_p99
        met = ratio <= 1.5 and r["dropped"] == 0
        print(
            f"{r['phase']}: p99 {ratio:.2f}x the idle p99, {r['dropped']} dropped; "
            f"2-core goal (<= 1.5x, none dropped): {'met' if met else 'not met'}"
        )
    loaded = next(r for r in rows if r["phase"] == f"{n} pollers + {f} flooding")
    quiet = (
        idle_p99 <= 300 and loaded["p99_us"] <= 1000 and loaded["max_us"] <= 5000 and loaded["dropped"] == 0
    )
    print(
        "quiet multi-core goal (idle p99 <= 300 µs; pollers + flood p99 <= 1 ms, max <= 5 ms, none dropped): "
        f"{'met' if quiet else 'not met'} on this machine ({machine_line()})"
    )


if __name__ == "__main__":
    main()
