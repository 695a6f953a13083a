"""Modbus TCP: requests per second and latency of FC 3 reads (H-03), one client and several at once.

Two servers, each in its own process, measured in the same run with the same clients:

* **hli-server**: the runtime with the demo machine, the engine running in real time (T_A = 1 ms,
  every monitor installed, the precise event loop and ``--priority auto`` as ``hli-server run``) and the
  ``modbus`` adapter in the doors process, as ``hli-server run`` serves it (``--in-process``: in the
  engine's process instead); reads come from the live process image.
* **plain pymodbus 3.16**: ``pymodbus.server.ModbusTcpServer`` with a static ``SimDevice``
  datastore (no engine, no image): the reference.

The clients: **one client process** (asyncio, ``asyncio.Protocol`` connections) drives every connection
of a measurement, each connection keeping one request in flight (send, wait for the whole answer, send
the next), so the clients need no cores of their own: 1 connection (a sequential client) and 10 concurrent
ones by default. ``--client-processes`` runs the older variant instead: one raw-socket client process per
connection. The two servers take turns, ``--runs`` times (the order alternating), so that a change of the
machine's load hits both. Printed: requests/s, latency p50/p99 per server and run, the server's CPU per
request, the ratio hli-server / plain per run and its spread over the runs (goals: >= 1.5 with one client,
>= 3 with ten), and **the realtime clock's lateness** in each run of hli-server: idle (no client, the
first ``--seconds`` after start) and under each load, from the runtime's own per-cycle samples (goal: p99
under the ten connections within 1.5x of idle, no cycle dropped).

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
LATENESS_GOAL = 1.5
"""The clock's lateness p99 under the most connections / idle p99, same run (the goal)."""
IN_PROCESS = [False]


# --------------------------------------------------------------------------------------------
# Servers (child processes)
# --------------------------------------------------------------------------------------------


def _serve_hli(conn: Connection) -> None:
    from hli_server.configuration import load_machine
    from hli_server.runtime import Runtime, precise_event_loop

    runtime = Runtime(
        load_machine(None),
        clock="realtime",
        http_port=None,
        image_name=f"hli_bench_modbus_{os.getpid()}",
        adapters=[("modbus", {"port": 0})],
        doors_process=not IN_PROCESS[0],
        priority="auto",  # as hli-server run
    )

    def lateness() -> None:
        """The parent asks for the clock's lateness samples: ``since`` (cycles measured) -> the newer ones."""
        since = conn.recv()
        stats = runtime.stats
        newest = stats.samples()
        wanted = min(len(newest), max(0, stats.measured - since))
        conn.send((stats.measured, array("d", newest[len(newest) - wanted :]).tobytes()))

    def ready(rt: Runtime) -> None:
        door: Any = rt.adapters[0]
        asyncio.get_running_loop().add_reader(conn.fileno(), lateness)
        conn.send(door.port("modbus") if hasattr(door, "doors") else door.port)

    with asyncio.Runner(loop_factory=precise_event_loop) as runner:  # the loop of hli-server run
        runner.run(runtime.serve(ready=ready))
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
# Clients
# --------------------------------------------------------------------------------------------

Outcome = tuple[int, int, bytes, float]
"""answers, exception answers, latencies (``array("Q")`` of ns, as bytes), the client's CPU seconds."""


def _answer_end(buf: bytes | memoryview) -> int:
    """Bytes of the first answer in ``buf`` (by its MBAP length: an exception is shorter); 0: incomplete."""
    if len(buf) < 6:
        return 0
    need = 6 + (buf[4] << 8 | buf[5])
    return need if len(buf) >= need else 0


def _client(port: int, frame: bytes, answer_size: int, start_at: float, seconds: float) -> Outcome:
    """``--client-processes``: one raw blocking socket, closed loop until ``start_at + seconds``."""
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
    cpu = time.process_time()
    ns = time.perf_counter_ns
    send, recv_into, record = sock.sendall, sock.recv_into, latencies.append
    while True:
        t0 = ns()
        send(frame)
        got = 0
        while not got or not _answer_end(view[:got]):
            n = recv_into(view[got:], answer_size - got)
            if n == 0:
                raise ConnectionError("the server closed the connection")
            got += n
        if buf[7] & 0x80:
            errors += 1
        record(ns() - t0)
        if clock() >= stop_at:
            break
    cpu = time.process_time() - cpu
    sock.close()
    return len(latencies), errors, latencies.tobytes(), cpu


class _Poller(asyncio.Protocol):
    """One connection of the client process: one request in flight, the next sent when its answer is in."""

    def __init__(
        self, frame: bytes, answer_size: int, latencies: array[int], done: asyncio.Future[None]
    ) -> None:
        self.frame = frame
        self.answer_size = answer_size
        self.latencies = latencies
        self.done = done
        self.stop_at = 0
        self.errors = 0
        self.sent_at = 0
        self.buf = b""
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport  # asyncio sets TCP_NODELAY on TCP sockets

    def go(self, stop_at: int) -> None:
        self.stop_at = stop_at
        self.sent_at = time.perf_counter_ns()
        assert self.transport is not None
        self.transport.write(self.frame)

    def data_received(self, data: bytes) -> None:
        buf = self.buf + data if self.buf else data
        end = _answer_end(buf)
        if not end:
            self.buf = buf
            return
        self.buf = buf[end:]
        if buf[7] & 0x80:
            self.errors += 1
        now = time.perf_counter_ns()
        self.latencies.append(now - self.sent_at)
        if now < self.stop_at:
            self.sent_at = now
            assert self.transport is not None
            self.transport.write(self.frame)
        elif not self.done.done():
            self.done.set_result(None)

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.done.done():
            self.done.set_exception(ConnectionError(f"the server closed the connection ({exc})"))


def _drive(
    port: int, connections: int, frame: bytes, answer_size: int, start_at: float, seconds: float
) -> Outcome:
    """The client process: ``connections`` asyncio connections from ``start_at`` for ``seconds``."""

    async def main() -> Outcome:
        loop = asyncio.get_running_loop()
        latencies: array[int] = array("Q")
        pollers: list[_Poller] = []
        for _ in range(connections):
            done: asyncio.Future[None] = loop.create_future()
            _, poller = await loop.create_connection(
                lambda d=done: _Poller(frame, answer_size, latencies, d), "127.0.0.1", port
            )
            pollers.append(poller)
        await asyncio.sleep(max(0.0, start_at - time.perf_counter()))
        stop_at = time.perf_counter_ns() + int(seconds * 1e9)
        cpu = time.process_time()
        for poller in pollers:
            poller.go(stop_at)
        await asyncio.wait_for(asyncio.gather(*(p.done for p in pollers)), seconds + 30)
        cpu = time.process_time() - cpu
        for poller in pollers:
            assert poller.transport is not None
            poller.transport.close()
        return len(latencies), sum(p.errors for p in pollers), latencies.tobytes(), cpu

    return asyncio.run(main())


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
    client_cpu_us: float
    """the clients' CPU time per answer (what bounds the rate where it is the larger)"""

    @property
    def rate(self) -> float:
        return self.answers / self.seconds


def _percentile(data: array[int] | list[float], q: float) -> float:
    """``q``-th percentile of sorted ``data`` (ns or s as stored), nan when empty."""
    if not data:
        return float("nan")
    k = max(0, min(len(data) - 1, int(q / 100 * len(data) + 0.5) - 1))
    return data[k]


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


def measure(server: Server, clients: int, seconds: float, count: int, processes: bool) -> Result:
    frame = struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, HOLDING_ADDRESS, count)
    answer_size = 9 + 2 * count
    pid = server.process.pid
    idle_from, idle_cpu = time.perf_counter(), _cpu_seconds(pid)
    workers = clients if processes else 1
    with ProcessPoolExecutor(max_workers=workers, mp_context=CTX) as pool:
        start_at = time.perf_counter() + 0.5 + 0.05 * clients  # every client connected and waiting
        if processes:
            futures = [
                pool.submit(_client, server.port, frame, answer_size, start_at, seconds)
                for _ in range(clients)
            ]
        else:
            futures = [pool.submit(_drive, server.port, clients, frame, answer_size, start_at, seconds)]
        _sleep_until(start_at - 0.1)
        idle_rate = (_cpu_seconds(pid) - idle_cpu) / (time.perf_counter() - idle_from)
        _sleep_until(start_at)
        cpu_start = _cpu_seconds(pid)
        _sleep_until(start_at + seconds)
        busy_cpu = _cpu_seconds(pid) - cpu_start - idle_rate * seconds
        outcomes = [f.result(timeout=seconds + 60) for f in futures]
    latencies: array[int] = array("Q")
    answers = errors = 0
    client_cpu = 0.0
    for n, e, raw, cpu in outcomes:
        answers += n
        errors += e
        client_cpu += cpu
        latencies.frombytes(raw)
    ordered = array("Q", sorted(latencies))
    return Result(
        server.name,
        clients,
        seconds,
        answers,
        errors,
        _percentile(ordered, 50) / 1000,
        _percentile(ordered, 99) / 1000,
        1e6 * busy_cpu / answers if answers else float("nan"),
        1e6 * client_cpu / answers if answers else float("nan"),
    )


# --------------------------------------------------------------------------------------------
# The clock's lateness, phase by phase (hli-server only)
# --------------------------------------------------------------------------------------------


@dataclass
class Lateness:
    phase: str
    cycles: int
    p50_us: float
    p99_us: float
    max_us: float

    @classmethod
    def of(cls, phase: str, samples: list[float]) -> Lateness:
        data = sorted(samples)
        return cls(
            phase,
            len(data),
            1e6 * _percentile(data, 50),
            1e6 * _percentile(data, 99),
            1e6 * data[-1] if data else float("nan"),
        )


class ClockProbe:
    """Asks the hli-server process for its clock's lateness samples since the last call (one phase's)."""

    def __init__(self, server: Server) -> None:
        self.server = server
        self.measured = 0

    def take(self, phase: str) -> Lateness:
        self.server.conn.send(self.measured)
        if not self.server.conn.poll(15):
            raise RuntimeError("hli-server did not send its lateness samples")
        self.measured, raw = self.server.conn.recv()
        samples = array("d")
        samples.frombytes(raw)
        return Lateness.of(phase, samples.tolist())


# --------------------------------------------------------------------------------------------


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="length of each run [s]")
    parser.add_argument(
        "--clients", type=int, nargs="+", default=[1, 10], help="concurrent connections per measurement"
    )
    parser.add_argument("--count", type=int, default=6, help="registers per FC 3 read (1..6)")
    parser.add_argument("--runs", type=int, default=3, help="turns of each server (the spread of the ratio)")
    parser.add_argument(
        "--in-process", action="store_true", help="Modbus in the engine's process (--no-doors-process)"
    )
    parser.add_argument(
        "--client-processes",
        action="store_true",
        help="one raw-socket client process per connection instead of one asyncio process for all",
    )
    args = parser.parse_args()
    if not 1 <= args.count <= 6:
        parser.error("--count: the demo machine's channel block has 6 holding registers at address 0")
    IN_PROCESS[0] = args.in_process
    load = os.getloadavg()
    where = "in the engine's process" if args.in_process else "in the doors process (as hli-server run)"
    how = (
        "one raw-socket client process per connection"
        if args.client_processes
        else "one asyncio client process for all connections"
    )
    print(
        f"FC 3 read of {args.count} holding registers at address {HOLDING_ADDRESS}, {how} (one request in "
        f"flight each), {args.seconds:g} s per run, {args.runs} runs; {os.cpu_count()} cores shared, load "
        f"average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; hli-server's Modbus {where}"
    )
    labels = {
        "hli-server": "hli-server modbus adapter (engine realtime)",
        "plain pymodbus": "plain pymodbus 3.16 server (static data)",
    }
    print(
        f"{'run':>3} {'server':<44} {'clients':>7} {'req/s':>9} {'p50 us':>8} {'p99 us':>8} "
        f"{'CPU us/req':>10} {'client CPU':>10} {'errors':>6}"
    )
    ratios: dict[int, list[float]] = {c: [] for c in args.clients}
    clock_ratios: list[float] = []
    clock_lines: list[str] = []
    timing: Any = None
    servers = (("hli-server", _serve_hli), ("plain pymodbus", _serve_plain))
    for run in range(args.runs):
        results: dict[tuple[str, int], Result] = {}
        for name, target in servers if run % 2 == 0 else tuple(reversed(servers)):
            server = Server.start(name, target)
            probe = ClockProbe(server) if name == "hli-server" else None
            phases: list[Lateness] = []
            try:
                if probe is not None:
                    probe.take("start")
                    time.sleep(args.seconds)
                    phases.append(probe.take("idle"))
                for clients in args.clients:
                    r = results[name, clients] = measure(
                        server, clients, args.seconds, args.count, args.client_processes
                    )
                    if probe is not None:
                        phases.append(probe.take(f"{clients} conn."))
                    print(
                        f"{run + 1:>3} {labels[name]:<44} {clients:>7} {r.rate:>9.0f} {r.p50_us:>8.1f} "
                        f"{r.p99_us:>8.1f} {r.cpu_us:>10.1f} {r.client_cpu_us:>10.1f} {r.errors:>6}",
                        flush=True,
                    )
            finally:
                report = server.stop()
            if probe is not None:
                timing = report
                idle, loaded = phases[0], phases[-1]
                clock_ratios.append(loaded.p99_us / idle.p99_us if idle.p99_us else float("inf"))
                clock_lines.append(
                    f"{run + 1:>3} clock lateness p50 / p99 / max [us]: "
                    + "; ".join(f"{p.phase} {p.p50_us:.0f} / {p.p99_us:.0f} / {p.max_us:.0f}" for p in phases)
                    + f"; p99 {loaded.phase} / idle {clock_ratios[-1]:.2f}x"
                )
                print(clock_lines[-1], flush=True)
        for clients in args.clients:
            ours, plain = results["hli-server", clients], results["plain pymodbus", clients]
            ratios[clients].append(ours.rate / plain.rate if plain.rate else float("inf"))
    for clients, values in ratios.items():
        goal = GOALS.get(clients, GOALS[1])
        print(f"ratio hli-server / plain, {clients} client(s): {_spread(values, goal, lower=False)}")
    print(
        f"clock lateness p99 under {args.clients[-1]} connection(s) / idle, per run: "
        f"{_spread(clock_ratios, LATENESS_GOAL, lower=True)}"
    )
    print_lateness(timing)


def _spread(values: list[float], goal: float, *, lower: bool) -> str:
    """The values of the runs, their min / median / max and whether every run, the median or none meets
    the goal (``>= goal``, or ``<= goal`` when ``lower``)."""
    ordered = sorted(values)
    low, median, high = ordered[0], ordered[len(ordered) // 2], ordered[-1]
    worst = high if lower else low
    meets = (lambda v: v <= goal) if lower else (lambda v: v >= goal)
    verdict = "every run meets" if meets(worst) else "the median meets" if meets(median) else "MISSES"
    return (
        f"{', '.join(f'{v:.2f}x' for v in values)} (min {low:.2f}x, median {median:.2f}x, max {high:.2f}x; "
        f"{verdict} the goal {'<=' if lower else '>='} {goal}x)"
    )


if __name__ == "__main__":
    main()
