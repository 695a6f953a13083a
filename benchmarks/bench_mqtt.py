"""MQTT events (H-05): events/s the adapter delivers to a local Mosquitto, and the cycle's lateness.

1. Throughput: ``--events`` events pushed into the runtime's event feed at once (a stepped runtime,
   so no cycle competes); the time until the broker has acknowledged the last one (QoS 1; QoS 0:
   written to the socket). Reference, same run, same broker: aiomqtt publishing the same encoded
   messages with the same window of acknowledgements in flight, i.e. the library's own ceiling.
2. Lateness of the realtime clock (T_A = 1 ms, ``select`` loop) for ``--seconds`` with an event every
   millisecond: without MQTT, with a live broker, with no broker at all (connection refused).

Needs Debian's ``mosquitto`` (skipped with a note otherwise); the broker is started on a free port by
the test suite's helper (``tests/integration/_mosquitto.py``).

    .venv/bin/python -m benchmarks mqtt [-- --events 20000 --seconds 5]
"""

from __future__ import annotations

import argparse
import asyncio
import socket
import tempfile
import time
from pathlib import Path
from typing import Any

from hli_server.adapters.mqtt import WINDOW, MqttAdapter
from hli_server.codecs.event_json import encode_event
from hli_server.configuration import load_machine
from hli_server.runtime import Runtime, precise_event_loop
from schemas.events import FaultInjected
from tests.integration._mosquitto import Mosquitto, missing_tools


def sample(i: int) -> FaultInjected:
    return FaultInjected(
        cycle=i,
        time_s=i * 0.001,
        channel=1,
        axis="X",
        faults={"friction": 0.001 * i},
        changed={"friction": 0.001 * i},
    )


async def adapter_throughput(port: int, count: int, qos: int) -> float:
    adapter = MqttAdapter(broker=f"127.0.0.1:{port}", qos=qos, queue_size=count, snapshot=False)
    async with Runtime(load_machine(None), clock="stepped", http_port=None, adapters=[adapter]) as rt:
        await adapter.wait_connected(10)
        started = time.perf_counter()
        for i in range(count):
            rt.event_log(sample(i))
        while adapter.published < count:
            await asyncio.sleep(0.001)
        return count / (time.perf_counter() - started)


async def aiomqtt_throughput(port: int, count: int, qos: int) -> float:
    import aiomqtt

    messages = [
        encode_event(sample(i), prefix="bench/", machine="demo", seq=i, wall=0.0) for i in range(count)
    ]
    nodelay = ((socket.IPPROTO_TCP, socket.TCP_NODELAY, 1),)
    async with aiomqtt.Client(
        "127.0.0.1", port, max_inflight_messages=WINDOW, socket_options=nodelay
    ) as client:
        client.pending_calls_threshold = 2 * WINDOW  # no warning for the window it is given
        started = time.perf_counter()
        for first in range(0, count, WINDOW):
            await asyncio.gather(
                *(client.publish(t, p, qos=qos) for t, p in messages[first : first + WINDOW])
            )
        return count / (time.perf_counter() - started)


async def lateness(port: int | None, seconds: float) -> dict[str, Any]:
    adapters = [MqttAdapter(broker=f"127.0.0.1:{port}", reconnect_max_s=1.0)] if port else []
    async with Runtime(load_machine(None), clock="realtime", http_port=None, adapters=adapters) as rt:
        deadline = time.monotonic() + seconds
        i = 0
        while time.monotonic() < deadline:
            i += 1
            rt.event_log(sample(i))
            await asyncio.sleep(0.001)
        timing = rt.timing()
        stats = adapters[0].stats() if adapters else {}
    return {**timing["lateness_us"], "slipped": timing["slipped_cycles"], "events": i, **stats}


def closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port


def main() -> None:
    parser = argparse.ArgumentParser(prog="bench_mqtt", description=__doc__)
    parser.add_argument("--events", type=int, default=20_000)
    parser.add_argument("--seconds", type=float, default=5.0)
    args = parser.parse_args()
    reason = missing_tools("mosquitto")
    if reason:
        print(f"skipped: {reason}")
        return
    with tempfile.TemporaryDirectory() as tmp:
        for label, extra in (
            ("Mosquitto's defaults", ""),
            ("set_tcp_nodelay true", "set_tcp_nodelay true\n"),
        ):
            broker = Mosquitto(Path(tmp) / label.replace(" ", "_"))
            broker.config.write_text(broker.config.read_text() + extra)
            broker.start()
            try:
                for qos in (1, 0):
                    ours = asyncio.run(adapter_throughput(broker.port, args.events, qos))
                    ref = asyncio.run(aiomqtt_throughput(broker.port, args.events, qos))
                    print(
                        f"broker with {label}, QoS {qos}: adapter {ours:,.0f} events/s; aiomqtt alone, same "
                        f"messages, windows of {WINDOW}: {ref:,.0f} msg/s; ratio {ours / ref:.2f}"
                    )
                if extra:
                    continue
                for what, port in (
                    ("no MQTT", None),
                    ("live broker", broker.port),
                    ("no broker", closed_port()),
                ):
                    with asyncio.Runner(loop_factory=precise_event_loop) as runner:
                        r = runner.run(lateness(port, args.seconds))
                    more = f"; published {r['published']:,}, dropped {r['dropped']:,}" if port else ""
                    print(
                        f"realtime, an event per ms, {what}: lateness p50 {r['p50']:,.0f} us, "
                        f"p99 {r['p99']:,.0f} us, max {r['max']:,.0f} us, {r['slipped']} cycles dropped "
                        f"({r['events']:,} events{more})"
                    )
            finally:
                broker.stop()


if __name__ == "__main__":
    main()
