"""ADS/TCP: reads per second and latency with one pyads client (H-04).

The server under test and its references, each in its own process, measured in the same run:

* **hli-server**: ``hli-server run`` with the demo machine, the engine running in real time (T_A = 1 ms,
  every monitor installed), ADS served by the doors process as ``run`` does by default; reads come
  from the live process image. ``--in-process`` serves ADS from the engine's process instead (the
  runtime's event loop, ``--no-doors-process``).
* **pyads.testserver**: ``AdsTestServer`` with an ``AdvancedHandler`` holding one DINT variable at
  the same index group/offset and name: the reference (no engine).
* the **floors**, which answer every request with a canned reply (no decoding): one on the door's own
  transport stack (an ``asyncio.Protocol`` on the doors process' loop, ``runtime.event_loop``: the
  reference of the goal "within 5 % of a canned-reply server", since it differs from the door only in
  what the door does per request; its process asks the scheduler for the doors' time slice too,
  ``runtime.pacing.DOORS_SLICE_NS``), **the same floor again** (the control: two identical servers, whose
  ratio says what the run can resolve), and one with a blocking thread per connection (``sendall`` right
  after ``recv``: what the pyads client itself allows, shown for comparison, a different stack).

The client is pyads 3.6 (Beckhoff's AdsLib), one call in flight:

* raw reads: ``Connection.read(group, offset, PLCTYPE_DINT)`` (one round trip each);
* read_by_name: ``Connection.read_by_name(name, PLCTYPE_DINT)`` (handle, read, release: three
  round trips each, as pyads does it).

``--method bursts`` (the default): per round and mode, one client process holds a connection to every
server (each server has an AMS NetId of its own: AdsLib routes by NetId) and measures them in bursts
taken in turn (100 raw reads or 33 read_by_name calls, a few milliseconds), the order shifted by one
every turn and every other turn backwards, until each server was measured for ``--seconds``: where the
scheduler puts the client, what the engine's process and the host do meanwhile, every server gets its
share of it. ``--method rounds``: a fresh client process per server and round (one second each), as
the benchmark measured before the fourth session of issue 38: on the 2-core benchmark host the
scheduler places each client process anew, a round trip takes about 26 µs within one CPU and 100-150 µs
across the two, and two identical servers measured this way differ by up to 12 % in a run
(docs/performance.md, "fourth session").

Printed: calls/s, latency p50/p99 per server and mode, the CPU time the serving process spent per call
(user + system from ``/proc``, the client excluded), the ratio hli-server / reference (the goal: >= 1.0x
on both) and hli-server / floor (goal: within 5 %, >= 0.95), the control's ratio, and how the realtime
clock fared under the load.

    .venv/bin/python -m benchmarks.bench_ads [--seconds 2] [--rounds 2] [--runs 3] [--method bursts]

``--placement same`` (or ``cross``) pins the client and each serving process (never the engine's);
``--client socket`` replaces pyads with a plain blocking socket (the servers' share of a round trip).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import functools
import os
import signal
import socket
import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from typing import Any

from benchmarks._servers import CTX, Server, print_lateness

GOAL = 1.0
"""hli-server / pyads.testserver, raw reads and read_by_name (the goal)."""
FLOOR_GOAL = 0.95
"""hli-server / the canned-reply floor: within 5 % (the goal)."""
SYMBOL = "gpAx[0]^ipo_state.cmd_pos_r"
"""A DINT of the CNC->PLC half; the reference holds a variable of the same name and address."""
SERVER_NET_ID = "127.0.0.1.1.1"


def _address() -> tuple[int, int]:
    from hli_server.configuration import load_machine
    from schemas.layout import build_layout

    s = build_layout(load_machine(None)).signal(SYMBOL)
    return s.image_ads_group, s.offset


# --------------------------------------------------------------------------------------------
# Servers (child processes)
# --------------------------------------------------------------------------------------------


CLOCK = ["realtime"]


def _serve_hli(conn: Connection) -> None:
    from hli_server.configuration import load_machine
    from hli_server.runtime import Runtime, precise_event_loop

    runtime = Runtime(
        load_machine(None),
        clock=CLOCK[0],
        http_port=None,
        image_name=f"hli_bench_ads_{os.getpid()}",
        adapters=[("ads", {"port": 0})],
    )

    def ready(rt: Runtime) -> None:
        conn.send(getattr(rt.adapter("ads"), "port"))  # noqa: B009 - the ADS adapter's attribute

    with asyncio.Runner(loop_factory=precise_event_loop) as runner:
        runner.run(runtime.serve(ready=ready))
    report = runtime.timing()
    adapter: Any = runtime.adapters[0]
    report["ads"] = {"requests": adapter.device.stats.requests, **adapter.stats.as_dict()}
    conn.send(report)


def _serve_hli_run(conn: Connection) -> None:
    """``hli-server run`` as a user starts it: the engine in real time, ADS served by the doors process."""
    import json
    import subprocess
    import sys
    import urllib.request
    from pathlib import Path

    cli = str(Path(sys.executable).parent / "hli-server")
    args = ["run", "--http-port", "0", "--no-modbus", "--ads-port", "0", "--doors-process"]
    args += ["--clock", CLOCK[0], "--image-name", f"hli_bench_ads_{os.getpid()}"]
    proc = subprocess.Popen([cli, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    url, port = "", 0
    for line in proc.stdout:
        if "HTTP control API:" in line:
            url = line.split("HTTP control API:")[1].split()[0]
        if line.strip().startswith("ADS (AMS/TCP):"):
            port = int(line.split(": ", 1)[1].split(maxsplit=1)[0].rsplit(":", 1)[1])
        if "stop with" in line:
            break
    if not port:
        proc.kill()
        raise RuntimeError(f"hli-server run printed no ADS port: {proc.stderr.read() if proc.stderr else ''}")
    stop = [False]
    signal.signal(signal.SIGTERM, lambda *_: stop.__setitem__(0, True))
    conn.send(port)
    while not stop[0]:
        time.sleep(0.05)
    report = None
    with (
        contextlib.suppress(OSError, ValueError),
        urllib.request.urlopen(url + "/api/timing", timeout=10) as r,
    ):
        report = json.loads(r.read())
    proc.terminate()
    proc.wait(15)
    conn.send(report)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _serve_testserver(conn: Connection) -> None:
    import pyads
    from pyads.testserver import AdsTestServer
    from pyads.testserver.advanced_handler import AdvancedHandler, PLCVariable

    group, offset = _address()
    handler = AdvancedHandler()
    handler.add_variable(PLCVariable(SYMBOL, 123_456, pyads.constants.ADST_INT32, "DINT", group, offset))
    port = _free_port()
    server = AdsTestServer(handler=handler, ip_address="127.0.0.1", port=port, logging=False)
    stop = [False]
    signal.signal(signal.SIGTERM, lambda *_: stop.__setitem__(0, True))
    server.start()
    for _ in range(200):  # until it accepts connections
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=1):
            break
        time.sleep(0.01)
    conn.send(port)
    while not stop[0]:
        time.sleep(0.05)
    with contextlib.suppress(Exception):
        server.stop()
    conn.send(None)


def _serve_floor(conn: Connection) -> None:
    """The client's floor: a blocking socket per connection answering every request with a canned
    reply of the right size, no decoding beyond the length (what no real server can beat)."""
    import struct
    import threading

    def serve(sock: socket.socket) -> None:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        buf = b""
        while True:
            data = sock.recv(65536)
            if not data:
                return
            buf += data
            while len(buf) >= 38 and len(buf) >= 6 + struct.unpack_from("<I", buf, 2)[0]:
                n = 6 + struct.unpack_from("<I", buf, 2)[0]
                frame, buf = buf[:n], buf[n:]
                sock.sendall(_canned_reply(frame))

    listener = socket.create_server(("127.0.0.1", 0))
    conn.send(listener.getsockname()[1])

    def accept() -> None:
        while True:
            client, _ = listener.accept()
            threading.Thread(target=serve, args=(client,), daemon=True).start()

    threading.Thread(target=accept, daemon=True).start()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    stop.wait()
    conn.send(None)


def _canned_reply(frame: bytes) -> bytes:
    """The floor's answer to one AMS/TCP frame: a reply of the right size, nothing decoded beyond it."""
    import struct

    command, invoke = struct.unpack_from("<H", frame, 22)[0], frame[34:38]
    if command in {2, 9}:  # Read, ReadWrite (a handle): result, length, data
        size = struct.unpack_from("<I", frame, 46)[0]
        payload = struct.pack("<II", 0, size) + bytes(size)
    else:
        payload = bytes(4)
    header = frame[14:22] + frame[6:14] + frame[22:24] + b"\x05\x00"
    header += struct.pack("<II", len(payload), 0) + invoke
    return struct.pack("<HI", 0, 32 + len(payload)) + header + payload


def _serve_floor_asyncio(conn: Connection) -> None:
    """The floor on the door's own transport stack: the canned replies of :func:`_serve_floor` from an
    ``asyncio.Protocol`` on the loop the doors process serves on (``lean_event_loop``: asyncio's selector
    loop, its turn as Python 3.13 has it;
    asyncio sets TCP_NODELAY on every TCP transport, as the thread floor does by hand), in a process that
    asks the scheduler for the doors process' time slice as the doors do (``DOORS_SLICE_NS``: a floor
    without it would measure the slice, not the door). What the door's Python costs above the stack is the
    gap to this floor."""
    import struct

    from hli_server.runtime.pacing import DOORS_SLICE_NS, ask_for_time_slice

    ask_for_time_slice(DOORS_SLICE_NS)

    class Canned(asyncio.Protocol):
        def connection_made(self, transport: asyncio.BaseTransport) -> None:
            assert isinstance(transport, asyncio.Transport)
            self.transport = transport
            self.buf = b""

        def data_received(self, data: bytes) -> None:
            buf = self.buf + data
            out = []
            while len(buf) >= 38 and len(buf) >= 6 + struct.unpack_from("<I", buf, 2)[0]:
                n = 6 + struct.unpack_from("<I", buf, 2)[0]
                out.append(_canned_reply(buf[:n]))
                buf = buf[n:]
            self.buf = buf
            if out:
                self.transport.write(b"".join(out))

    async def main() -> None:
        loop = asyncio.get_running_loop()
        stop = asyncio.Event()
        loop.add_signal_handler(signal.SIGTERM, stop.set)
        server = await loop.create_server(Canned, "127.0.0.1", 0)
        conn.send(server.sockets[0].getsockname()[1])
        await stop.wait()
        server.close()

    from hli_server.runtime.event_loop import lean_event_loop

    with asyncio.Runner(loop_factory=lean_event_loop) as runner:
        runner.run(main())
    conn.send(None)


# --------------------------------------------------------------------------------------------
# The client (a fresh process per run: AdsLib keeps one route per NetId per process)
# --------------------------------------------------------------------------------------------


def _pyads_call(plc: Any, mode: str) -> Any:
    """One call of ``mode`` on an open pyads ``Connection``: a raw read (one round trip) or
    read_by_name (handle, read, release: three, as pyads does it)."""
    import pyads

    group, offset = _address()
    dint = pyads.PLCTYPE_DINT
    if mode == "raw":
        return lambda: plc.read(group, offset, dint)
    return lambda: plc.read_by_name(SYMBOL, dint)


def _pyads_open(net_id: str, port: int) -> Any:
    """A pyads ``Connection`` to the server on ``port`` as AMS NetId ``net_id`` (AdsLib routes by NetId:
    one process reaches several servers where each has a NetId of its own)."""
    import pyads

    pyads.open_port()
    pyads.set_local_address("10.1.2.3.1.1")
    pyads.close_port()
    plc = pyads.Connection(net_id, 851, f"127.0.0.1:{port}")
    plc.open()
    plc.set_timeout(2000)
    return plc


def _socket_call(port: int, net_id: str, mode: str) -> tuple[Any, socket.socket]:
    """The same calls from a plain blocking socket (one send, one reply read per request): the
    server's round trip without AdsLib's threads, to tell the server's share from the client's."""
    import struct

    from hli_server.codecs.ads import (
        AmsAddress,
        CommandId,
        NetId,
        ReadRequest,
        ReadWriteRequest,
        WriteRequest,
        encode_request,
    )

    group, offset = _address()
    target, source = AmsAddress(NetId.parse(net_id), 851), AmsAddress(NetId.parse("10.1.2.3.1.1"), 30001)
    sock = socket.create_connection(("127.0.0.1", port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def exchange(command: int, payload: bytes) -> bytes:
        sock.sendall(encode_request(target, source, command, 1, payload))
        head = b""
        while len(head) < 6:
            head += sock.recv(6 - len(head))
        size = struct.unpack_from("<I", head, 2)[0]
        body = b""
        while len(body) < size:
            body += sock.recv(size - len(body))
        return body

    raw_read = ReadRequest(group, offset, 4).encode()
    get_handle = ReadWriteRequest(0xF003, 0, 4, SYMBOL.encode() + b"\0").encode()

    def call() -> None:
        if mode == "raw":
            exchange(CommandId.READ, raw_read)
            return
        handle = struct.unpack_from("<I", exchange(CommandId.READ_WRITE, get_handle), 40)[0]
        exchange(CommandId.READ, ReadRequest(0xF005, handle, 4).encode())
        exchange(CommandId.WRITE, WriteRequest(0xF006, 0, struct.pack("<I", handle)).encode())

    return call, sock


def _connect(net_id: str, port: int, mode: str) -> tuple[Any, Callable[[], None]]:
    """One call of ``mode`` to the server on ``port`` from the ``--client`` (pyads or a plain socket),
    and how to close its connection."""
    if CLIENT[0] == "pyads":
        plc = _pyads_open(net_id, port)
        return _pyads_call(plc, mode), plc.close
    call, sock = _socket_call(port, net_id, mode)
    return call, sock.close


def _client(port: int, mode: str, seconds: float) -> tuple[int, bytes]:
    """``--method rounds``: one server for ``seconds``, from this (fresh) process."""
    call, closing = _connect(SERVER_NET_ID, port, mode)
    for _ in range(200):  # warm up
        call()
    latencies = array("Q")
    ns = time.perf_counter_ns
    record = latencies.append
    stop_at = time.perf_counter() + seconds
    clock = time.perf_counter
    while clock() < stop_at:
        t0 = ns()
        call()
        record(ns() - t0)
    closing()
    return len(latencies), latencies.tobytes()


@dataclass(frozen=True)
class Target:
    """A server as the burst client reaches it: its AMS NetId, port and the processes whose CPU is its."""

    name: str
    net_id: str
    port: int
    pids: tuple[int, ...]


BURST = 100
"""``--method bursts``: raw reads per burst (a few milliseconds on the benchmark host); read_by_name's
bursts have a third as many calls (three round trips each)."""


def _client_bursts(
    targets: list[Target], mode: str, seconds: float, burst: int
) -> dict[str, tuple[int, float, float, bytes]]:
    """``--method bursts``: every server from this one process, one connection each, in bursts of
    ``burst`` calls taken in turn (the order shifted every turn) until each was measured for
    ``seconds``: whatever the scheduler and the machine do meanwhile, every server gets its share of it.
    Per server: calls, seconds measured, CPU seconds of its serving processes during its bursts, and the
    latencies (ns)."""
    calls: dict[str, Any] = {}
    closers = []
    for t in targets:
        calls[t.name], close = _connect(t.net_id, t.port, mode)
        closers.append(close)
    for t in targets:
        for _ in range(200):  # warm up
            calls[t.name]()
    latencies = {t.name: array("Q") for t in targets}
    measured = dict.fromkeys(calls, 0.0)
    cpu = dict.fromkeys(calls, 0.0)
    ns = time.perf_counter_ns
    turn = 0
    while min(measured.values()) < seconds:
        # every server in every position of the turn as often as the others: the order turns by one each
        # time, and every other turn runs backwards
        shift = turn % len(targets)
        order = targets[shift:] + targets[:shift]
        if turn % 2:
            order.reverse()
        turn += 1
        for t in order:
            call, record = calls[t.name], latencies[t.name].append
            cpu_before = _cpu_s(list(t.pids))
            began = ns()
            for _ in range(burst):
                t0 = ns()
                call()
                record(ns() - t0)
            measured[t.name] += (ns() - began) * 1e-9
            cpu[t.name] += _cpu_s(list(t.pids)) - cpu_before
    for close in closers:
        close()
    return {
        t.name: (len(latencies[t.name]), measured[t.name], cpu[t.name], latencies[t.name].tobytes())
        for t in targets
    }


CLIENT = ["pyads"]


def _client_process(conn: Connection, work: Callable[[], Any], cpu: int | None) -> None:
    if cpu is not None:  # before pyads starts AdsLib's threads: they inherit it
        os.sched_setaffinity(0, {cpu})
    conn.send(work())


PLACEMENTS = {"free": (None, None), "same": (0, 0), "cross": (0, 1)}
"""``--placement``: the CPU of the client and of each serving process (None: the scheduler's choice)."""


def _pin(pid: int, cpu: int) -> None:
    """Every thread of ``pid`` on ``cpu`` (threads it starts later inherit it)."""
    for task in os.listdir(f"/proc/{pid}/task"):
        with contextlib.suppress(OSError):
            os.sched_setaffinity(int(task), {cpu})


def _run_client(work: Callable[[], Any], seconds: float, cpu: int | None = None) -> Any:
    """``work()`` (a client's measurement) in a fresh process (AdsLib's router is per process), its
    result."""
    parent, child = CTX.Pipe()
    process = CTX.Process(target=_client_process, args=(child, work, cpu), daemon=True)
    process.start()
    try:
        if not parent.poll(seconds + 60):
            raise RuntimeError(f"the {CLIENT[0]} client did not finish")
        return parent.recv()
    finally:
        process.join(10)
        if process.is_alive():
            process.kill()


def _descendants(pid: int) -> list[int]:
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
            if ppid == pid:
                found.append(int(entry))
    return found + [d for child in found for d in _descendants(child)]


def _serving_pids(name: str, pid: int, in_process: bool) -> list[int]:
    """The processes whose CPU time is the server's: hli-server's doors process (not the engine's, which
    runs beside it in every mode), or the whole process of the reference and the floor."""
    if name != "hli-server" or in_process:
        return [pid]
    doors = []
    for child in _descendants(pid):
        try:
            with open(f"/proc/{child}/cmdline", "rb") as f:
                if b"spawn_main" in f.read():
                    doors.append(child)
        except OSError:
            continue
    return doors or [pid]


def _cpu_s(pids: list[int]) -> float:
    total = 0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += int(fields[11]) + int(fields[12])
        except (OSError, ValueError, IndexError):
            continue
    return total / os.sysconf("SC_CLK_TCK")


@dataclass
class Result:
    seconds: float = 0.0
    calls: int = 0
    cpu_s: float = 0.0
    latencies: array[int] = field(default_factory=lambda: array("Q"))

    @property
    def rate(self) -> float:
        return self.calls / self.seconds if self.seconds else 0.0

    def percentile(self, q: float) -> float:
        data = sorted(self.latencies)
        if not data:
            return float("nan")
        k = max(0, min(len(data) - 1, int(q / 100 * len(data) + 0.5) - 1))
        return data[k] / 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="length of each run [s]")
    parser.add_argument("--rounds", type=int, default=2, help="interleaved rounds per server and mode")
    parser.add_argument(
        "--runs", type=int, default=1, help="whole runs (fresh servers); the worst is the figure"
    )
    parser.add_argument(
        "--clock",
        choices=["realtime", "stepped"],
        default="realtime",
        help="clock of the hli-server: realtime (the engine runs; the goal) or stepped (the door alone)",
    )
    parser.add_argument(
        "--in-process",
        action="store_true",
        help="serve ADS from the engine's process (--no-doors-process), not from run's doors process",
    )
    parser.add_argument(
        "--client",
        choices=["pyads", "socket"],
        default="pyads",
        help="pyads (the goal's client) or a plain blocking socket (the servers' share of a round trip)",
    )
    parser.add_argument(
        "--method",
        choices=["bursts", "rounds"],
        default="bursts",
        help="bursts: one client process per round reaches every server, in bursts taken in turn (every "
        "server shares what the machine does meanwhile); rounds: a fresh client process per server and round "
        "(each placed anew by the scheduler: 10-30 %% of run-to-run spread on the 2-core host)",
    )
    parser.add_argument(
        "--burst",
        type=int,
        default=BURST,
        help="--method bursts: raw reads per burst (read_by_name: a third as many calls)",
    )
    parser.add_argument(
        "--placement",
        choices=sorted(PLACEMENTS),
        default="free",
        help="free: the scheduler places client and servers (the goal's figure); same: the client and each "
        "serving process pinned to CPU 0; cross: the client on CPU 0, the servers on CPU 1 (the engine's "
        "process is never pinned). On the 2-core benchmark host a round trip between two CPUs costs several "
        "times one on one CPU, and where the scheduler puts each process moves a run's figures by 10-30 %%",
    )
    args = parser.parse_args()
    if args.placement != "free" and not hasattr(os, "sched_setaffinity"):
        parser.error("--placement same|cross needs os.sched_setaffinity (Linux)")
    if args.placement == "cross" and len(os.sched_getaffinity(0)) < 2:
        parser.error("--placement cross needs two CPUs")
    CLOCK[0] = args.clock
    CLIENT[0] = args.client
    group, offset = _address()
    print(
        f"{'one pyads ' + __import__('pyads').__version__ if args.client == 'pyads' else 'one plain socket'} "
        f"client, one call in flight; raw read of a DINT at "
        f"0x{group:X}/{offset} and read_by_name({SYMBOL!r}); {args.rounds} x {args.seconds:g} s per server "
        f"and mode, interleaved ({args.method}); {os.cpu_count()} CPUs shared; placement {args.placement}"
    )
    if args.client == "socket" and args.placement == "free":
        print(
            "note: a plain socket client is one thread: each server's process stays on the CPU the scheduler "
            "gave it, the client's or the other, and two identical servers can differ by 10-30 % (the "
            "control says by how much); --placement same holds it equal"
        )
    worst: dict[str, list[tuple[float, float, float, float, float]]] = {"raw": [], "by_name": []}
    timing: Any = None
    for run in range(args.runs):
        if args.runs > 1:
            print(f"--- run {run + 1} of {args.runs}", flush=True)
        timing = _one_run(args)
        for mode, figures in timing.pop("_ratios").items():
            worst[mode].append(figures)
    if args.runs > 1:
        for mode, runs in worst.items():
            rate_ref, rate_floor = min(r[0] for r in runs), min(r[1] for r in runs)
            p50_ref, p50_floor = min(r[2] for r in runs), min(r[3] for r in runs)
            spread = max(abs(1 - r[4]) for r in runs)
            print(
                f"{mode}, worst of {args.runs} runs: hli-server / pyads.testserver {rate_ref:.2f}x "
                f"({'meets' if rate_ref >= GOAL else 'MISSES'} the goal >= {GOAL:g}x), hli-server / floor "
                f"{rate_floor:.2f} ({'meets' if rate_floor >= FLOOR_GOAL else 'MISSES'} the goal >= "
                f"{FLOOR_GOAL:g}); by the median round trip (what the machine's stalls disturb least): "
                f"{p50_ref:.2f}x and {p50_floor:.2f}; the control (floor copy / floor) within "
                f"{spread * 100:.1f} % of 1 in every run"
            )
    print_lateness(timing)


def _one_run(args: argparse.Namespace) -> Any:
    """One run: the servers started, ``args.rounds`` rounds, the table and the ratios printed; returns
    the hli-server's timing report with ``_ratios``: mode -> (calls/s / reference, calls/s / floor, the
    same two by the median round trip, the control: floor copy / floor)."""
    servers = {"hli-server": Server.start("hli-server", _serve_hli if args.in_process else _serve_hli_run)}
    servers["pyads.testserver"] = Server.start("pyads.testserver", _serve_testserver)
    servers["floor"] = Server.start("floor", _serve_floor_asyncio)
    servers["floor-copy"] = Server.start("floor-copy", _serve_floor_asyncio)
    servers["floor-thread"] = Server.start("floor-thread", _serve_floor)
    results = {(s, m): Result() for s in servers for m in ("raw", "by_name")}
    pids = {
        name: _serving_pids(name, server.process.pid, args.in_process) for name, server in servers.items()
    }
    client_cpu, server_cpu = PLACEMENTS[args.placement]
    if server_cpu is not None:  # the serving processes only: the engine's stays where the scheduler puts it
        for serving in pids.values():
            for pid in serving:
                _pin(pid, server_cpu)
    # the hli-server answers its own NetId; the others answer any: each gets one of its own, so that one
    # pyads process (AdsLib routes by NetId) reaches them all
    targets = [
        Target(
            name,
            SERVER_NET_ID if name == "hli-server" else f"127.0.0.{i + 1}.1.1",
            srv.port,
            tuple(pids[name]),
        )
        for i, (name, srv) in enumerate(servers.items())
    ]
    timing: Any = None
    try:
        for _ in range(args.rounds):
            for mode in ("raw", "by_name"):
                if args.method == "bursts":
                    burst = max(1, args.burst if mode == "raw" else args.burst // 3)
                    measured = _run_client(
                        functools.partial(_client_bursts, targets, mode, args.seconds, burst),
                        args.seconds * len(targets),
                        client_cpu,
                    )
                    for name, (calls, seconds, cpu_s, raw) in measured.items():
                        r = results[name, mode]
                        r.cpu_s += cpu_s
                        r.seconds += seconds
                        r.calls += calls
                        r.latencies.frombytes(raw)
                    continue
                for name, server in servers.items():
                    cpu_before = _cpu_s(pids[name])
                    calls, raw = _run_client(
                        functools.partial(_client, server.port, mode, args.seconds),
                        args.seconds,
                        client_cpu,
                    )
                    r = results[name, mode]
                    r.cpu_s += _cpu_s(pids[name]) - cpu_before
                    r.seconds += args.seconds
                    r.calls += calls
                    r.latencies.frombytes(raw)
    finally:
        timing = servers["hli-server"].stop()
        for name, server in servers.items():
            if name != "hli-server":
                server.stop()

    labels = {
        "hli-server": f"hli-server {'in-process' if args.in_process else 'doors proc.'}, engine "
        f"{'realtime' if args.clock == 'realtime' else 'idle'}",
        "pyads.testserver": "pyads.testserver + AdvancedHandler",
        "floor": "floor: canned replies, asyncio (same stack)",
        "floor-copy": "the same floor again (the control)",
        "floor-thread": "floor: canned replies, blocking thread",
    }
    print(f"{'server':<42} {'mode':<8} {'calls/s':>9} {'p50 us':>8} {'p99 us':>8} {'CPU us/call':>12}")
    for (name, mode), r in results.items():
        cpu = r.cpu_s / r.calls * 1e6 if r.calls else float("nan")
        print(
            f"{labels[name]:<42} {mode:<8} {r.rate:>9.0f} {r.percentile(50):>8.1f} {r.percentile(99):>8.1f}"
            f" {cpu:>12.1f}"
        )
    ratios = {}
    for mode in ("raw", "by_name"):
        ours, ref = results["hli-server", mode], results["pyads.testserver", mode]
        floor, thread = results["floor", mode], results["floor-thread", mode]
        copy = results["floor-copy", mode]
        control = copy.rate / floor.rate if floor.rate else 0.0
        ratio = ours.rate / ref.rate if ref.rate else float("inf")
        to_floor = ours.rate / floor.rate if floor.rate else 0.0
        to_thread = ours.rate / thread.rate if thread.rate else 0.0
        print(
            f"{mode}: hli-server / pyads.testserver {ratio:.2f}x "
            f"({'meets' if ratio >= GOAL else 'MISSES'} the goal >= {GOAL:g}x); "
            f"hli-server / floor {to_floor:.2f} ({'meets' if to_floor >= FLOOR_GOAL else 'MISSES'} the goal "
            f">= {FLOOR_GOAL:g}); pyads.testserver / floor {ref.rate / floor.rate if floor.rate else 0:.2f}; "
            f"hli-server / thread floor {to_thread:.2f}, asyncio floor / thread floor "
            f"{floor.rate / thread.rate if thread.rate else 0:.2f}"
        )
        print(  # the median round trip: what a shared machine's stalls (the p99s) disturb least
            f"{mode}: median round trip hli-server {ours.percentile(50):.1f} us, pyads.testserver "
            f"{ref.percentile(50):.1f} us, asyncio floor {floor.percentile(50):.1f} us, thread floor "
            f"{thread.percentile(50):.1f} us: hli-server - asyncio floor "
            f"{ours.percentile(50) - floor.percentile(50):+.1f} us"
        )
        print(  # two identical servers: what this run's method resolves
            f"{mode}: control: floor copy / floor {control:.3f} (two identical servers: the ratios above are "
            f"good to about {abs(1 - control) * 100:.1f} %)"
        )
        ratios[mode] = (
            ratio,
            to_floor,
            ref.percentile(50) / ours.percentile(50),
            floor.percentile(50) / ours.percentile(50),
            control,
        )
    report = dict(timing or {})
    report["_ratios"] = ratios
    return report


if __name__ == "__main__":
    main()
