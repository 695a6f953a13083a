"""Modbus TCP: requests per second and latency of FC 3 reads (H-03).

Two servers, each in its own process, measured in the same run with the same clients:

* **hli-server**: the runtime with the demo machine, the engine running in real time (T_A = 1 ms,
  every monitor installed) and the ``modbus`` adapter in the doors process, as ``hli-server run`` serves
  it (``--in-process``: in the engine's process instead); reads come from the live process image.
* **plain pymodbus 3.16**: ``pymodbus.server.ModbusTcpServer`` with a static ``SimDevice``
  datastore (no engine, no image): the reference.

Clients are raw sockets in separate processes (pre-built request, one request in flight per
client: send, wait for the whole answer, repeat), 1 client and 10 concurrent clients, a few seconds
each. The two servers take turns, ``--runs`` times (the order alternating), so that a change of the
machine's load hits both; printed: requests/s, latency p50/p99 per server and run, the ratio hli-server /
plain per run and its spread over the runs (goals: >= 1.5 with one client, >= 3 with ten),
plus how the realtime clock fared under the load (lateness, dropped cycles).

    .venv/bin/python -m benchmarks.bench_modbus [--seconds 3] [--clients 1 10] [--count 6] [--runs 3]

Client and servers share the machine's cores: the figures are noisy, the ratios are what to compare.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import signal
import socket
import struct
import time
from array import array
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

from benchmarks._servers import CTX, Server, print_lateness

HOLDING_ADDRESS = 0
"""Channel 1's holding registers: override.command_w, mode_w, program_select_w (6 registers)."""
GOALS = {1: 1.5, 10: 3.0}
"""hli-server / plain pymodbus, requests per second, by number of clients (the goals)."""
IN_PROCESS = [False]


# --------------------------------------------------------------------------------------------
# Servers (child processes)
# --------------------------------------------------------------------------------------------


def _serve_hli(conn: Connection) -> None:
    from hli_server.configuration import load_machine
    from hli_server.runtime import Runtime

    runtime = Runtime(
        load_machine(None),
        clock="realtime",
        http_port=None,
        image_name=f"hli_bench_modbus_{os.getpid()}",
        adapters=[("modbus", {"port": 0})],
        doors_process=not IN_PROCESS[0],
        priority="auto",  # as hli-server run
    )

    def ready(rt: Runtime) -> None:
        door: Any = rt.adapters[0]
        conn.send(door.port("modbus") if hasattr(door, "doors") else door.port)

    asyncio.run(runtime.serve(ready=ready))
    conn.send(runtime.timing())


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _serve_plain(conn: Connection) -> None:
    import logging

    from pymodbus.server import ModbusTcpServer
    from pymodbus.simulator import SimData, SimDevice
    from pymodbus.simulator.simdata import DataType

    logging.getLogger("pymodbus").setLevel(logging.ERROR)
    port = _free_port()
    device = SimDevice(
        id=0, simdata=[SimData(address=0, count=200, values=0x1234, datatype=DataType.REGISTERS)]
    )

    async def main() -> None:
        server = ModbusTcpServer(device, address=("127.0.0.1", port))
        stop = asyncio.Event()
        asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, stop.set)
        task = asyncio.create_task(server.serve_forever())
        for _ in range(200):  # until it accepts connections
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=1):
                break
            await asyncio.sleep(0.01)
        conn.send(port)
        await stop.wait()
        await server.shutdown()
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task

    asyncio.run(main())
    conn.send(None)


# --------------------------------------------------------------------------------------------
# Clients (worker processes)
# --------------------------------------------------------------------------------------------


def _client(
    port: int, frame: bytes, answer_size: int, start_at: float, seconds: float
) -> tuple[int, int, bytes]:
    """Closed loop until ``start_at + seconds``: (answers, exception answers, latencies in ns)."""
    sock = socket.create_connection(("127.0.0.1", port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    buf = bytearray(answer_size)
    view = memoryview(buf)
    latencies = array("Q")
    errors = 0
    clock = time.perf_counter
    while clock() < start_at:
        time.sleep(0.001)
    stop_at = start_at + seconds
    ns = time.perf_counter_ns
    send, recv_into, record = sock.sendall, sock.recv_into, latencies.append
    while True:
        t0 = ns()
        send(frame)
        got = recv_into(view, answer_size)
        need = answer_size
        while got < need:
            if got == 0:
                raise ConnectionError("the server closed the connection")
            if got >= 6:
                need = 6 + (buf[4] << 8 | buf[5])  # MBAP length: an exception answer is shorter
                if got >= need:
                    break
            n = recv_into(view[got:], need - got)
            if n == 0:
                raise ConnectionError("the server closed the connection")
            got += n
        if buf[7] & 0x80:
            errors += 1
        record(ns() - t0)
        if clock() >= stop_at:
            break
    sock.close()
    return len(latencies), errors, latencies.tobytes()


@dataclass
class Result:
    server: str
    clients: int
    seconds: float
    answers: int
    errors: int
    p50_us: float
    p99_us: float
    cpu_us: float
    """server CPU time per answer, less what the server burns idle (the engine's cycles)"""

    @property
    def rate(self) -> float:
        return self.answers / self.seconds


def _percentile(data: array[int], q: float) -> float:
    if not data:
        return float("nan")
    k = max(0, min(len(data) - 1, int(q / 100 * len(data) + 0.5) - 1))
    return data[k] / 1000


def _cpu_seconds(pid: int) -> float:
    """utime + stime of a process and of its children that run (the doors process; Linux /proc)."""
    total = 0.0
    pids = [pid]
    with contextlib.suppress(OSError), open(f"/proc/{pid}/task/{pid}/children") as f:
        pids += [int(c) for c in f.read().split()]
    for p in pids:
        with contextlib.suppress(OSError), open(f"/proc/{p}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def _sleep_until(t: float) -> None:
    delay = t - time.perf_counter()
    if delay > 0:
        time.sleep(delay)


def measure(server: Server, clients: int, seconds: float, count: int) -> Result:
    frame = struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, HOLDING_ADDRESS, count)
    answer_size = 9 + 2 * count
    pid = server.process.pid
    idle_from, idle_cpu = time.perf_counter(), _cpu_seconds(pid)
    with ProcessPoolExecutor(max_workers=clients, mp_context=CTX) as pool:
        start_at = time.perf_counter() + 0.5 + 0.05 * clients  # every client connected and waiting
        futures = [
            pool.submit(_client, server.port, frame, answer_size, start_at, seconds) for _ in range(clients)
        ]
        _sleep_until(start_at - 0.1)
        idle_rate = (_cpu_seconds(pid) - idle_cpu) / (time.perf_counter() - idle_from)
        _sleep_until(start_at)
        cpu_start = _cpu_seconds(pid)
        _sleep_until(start_at + seconds)
        busy_cpu = _cpu_seconds(pid) - cpu_start - idle_rate * seconds
        outcomes = [f.result(timeout=seconds + 60) for f in futures]
    latencies: array[int] = array("Q")
    answers = errors = 0
    for n, e, raw in outcomes:
        answers += n
        errors += e
        latencies.frombytes(raw)
    ordered = array("Q", sorted(latencies))
    return Result(
        server.name,
        clients,
        seconds,
        answers,
        errors,
        _percentile(ordered, 50),
        _percentile(ordered, 99),
        1e6 * busy_cpu / answers if answers else float("nan"),
    )


# --------------------------------------------------------------------------------------------


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="length of each run [s]")
    parser.add_argument("--clients", type=int, nargs="+", default=[1, 10], help="concurrent clients per run")
    parser.add_argument("--count", type=int, default=6, help="registers per FC 3 read (1..6)")
    parser.add_argument("--runs", type=int, default=3, help="turns of each server (the spread of the ratio)")
    parser.add_argument(
        "--in-process", action="store_true", help="Modbus in the engine's process (--no-doors-process)"
    )
    args = parser.parse_args()
    if not 1 <= args.count <= 6:
        parser.error("--count: the demo machine's channel block has 6 holding registers at address 0")
    IN_PROCESS[0] = args.in_process
    load = os.getloadavg()
    where = "in the engine's process" if args.in_process else "in the doors process (as hli-server run)"
    print(
        f"FC 3 read of {args.count} holding registers at address {HOLDING_ADDRESS}, raw-socket clients "
        f"(one request in flight each), {args.seconds:g} s per run, {args.runs} runs; {os.cpu_count()} cores "
        f"shared, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; hli-server's Modbus {where}"
    )
    labels = {
        "hli-server": "hli-server modbus adapter (engine realtime)",
        "plain pymodbus": "plain pymodbus 3.16 server (static data)",
    }
    print(
        f"{'run':>3} {'server':<44} {'clients':>7} {'req/s':>9} {'p50 us':>8} {'p99 us':>8} "
        f"{'CPU us/req':>10} {'errors':>6}"
    )
    ratios: dict[int, list[float]] = {c: [] for c in args.clients}
    timing: Any = None
    servers = (("hli-server", _serve_hli), ("plain pymodbus", _serve_plain))
    for run in range(args.runs):
        results: dict[tuple[str, int], Result] = {}
        for name, target in servers if run % 2 == 0 else tuple(reversed(servers)):
            server = Server.start(name, target)
            try:
                for clients in args.clients:
                    r = results[name, clients] = measure(server, clients, args.seconds, args.count)
                    print(
                        f"{run + 1:>3} {labels[name]:<44} {clients:>7} {r.rate:>9.0f} {r.p50_us:>8.1f} "
                        f"{r.p99_us:>8.1f} {r.cpu_us:>10.1f} {r.errors:>6}",
                        flush=True,
                    )
            finally:
                report = server.stop()
            if name == "hli-server":
                timing = report
        for clients in args.clients:
            ours, plain = results["hli-server", clients], results["plain pymodbus", clients]
            ratios[clients].append(ours.rate / plain.rate if plain.rate else float("inf"))
    for clients, values in ratios.items():
        goal = GOALS.get(clients, GOALS[1])
        ordered = sorted(values)
        low, median, high = ordered[0], ordered[len(ordered) // 2], ordered[-1]
        verdict = "every run meets" if low >= goal else "the median meets" if median >= goal else "MISSES"
        print(
            f"ratio hli-server / plain, {clients} client(s): {', '.join(f'{v:.2f}x' for v in values)} "
            f"(min {low:.2f}x, median {median:.2f}x, max {high:.2f}x; {verdict} the goal >= {goal}x)"
        )
    print_lateness(timing)


if __name__ == "__main__":
    main()
