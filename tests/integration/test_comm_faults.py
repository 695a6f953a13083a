"""Faults in the PLC's communication on demand (issue 25, B-03), through the real doors: a raw Modbus
TCP client and pyads against the in-process server (``hli.comm_faults``), the HTTP API against
``hli-server run`` with its doors in their own process, and a real Mosquitto broker for MQTT."""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import struct
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from hli_server.configuration import load_machine
from hli_server.recording.format import read_records
from hli_server.testing import Harness
from tests.integration.servers import door_port, read_banner, start_server, stop_server

pytestmark = pytest.mark.req("B-03")

HOLDING = 0  # the first holding register of the demo machine's map (a PLC->CNC DINT)


class RawModbus:
    """A Modbus TCP client that shows what came back (or that nothing did)."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        self.tid = 0

    def close(self) -> None:
        self.sock.close()

    def request(self, pdu: bytes, timeout: float = 5.0) -> bytes:
        self.tid += 1
        self.sock.settimeout(timeout)
        self.sock.sendall(struct.pack(">HHHB", self.tid, 0, len(pdu) + 1, 1) + pdu)
        head = self._exactly(7)
        tid, _, length, _ = struct.unpack(">HHHB", head)
        assert tid == self.tid
        return self._exactly(length - 1)

    def read_holding(self, address: int, count: int = 2, timeout: float = 5.0) -> bytes:
        return self.request(struct.pack(">BHH", 3, address, count), timeout)

    def _exactly(self, n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = self.sock.recv(n - len(data))
            if not chunk:
                raise ConnectionResetError("the server closed the connection")
            data += chunk
        return data


@pytest.fixture
def modbus(hli: Harness) -> Iterator[RawModbus]:
    client = RawModbus(hli.port("modbus"))
    yield client
    client.close()


def test_a_modbus_exception_for_an_address_range_then_the_answers_again(
    hli: Harness, modbus: RawModbus
) -> None:
    fault = hli.comm_faults.add(kind="error", door="modbus", code=4, first=HOLDING, last=HOLDING + 1, count=2)
    assert fault["left"] == 2
    assert modbus.read_holding(HOLDING) == bytes([0x83, 0x04])  # server device failure, as asked
    assert modbus.read_holding(100)[0] == 3  # outside the range: answered
    assert modbus.read_holding(HOLDING) == bytes([0x83, 0x04])
    assert hli.comm_faults.table() == []  # the count is used up: the fault ended
    assert modbus.read_holding(HOLDING)[0] == 3


def test_modbus_answers_delayed_by_n_ms(hli: Harness, modbus: RawModbus) -> None:
    with hli.comm_faults.fault(kind="delay", door="modbus", delay_ms=150, duration_ms=10_000):
        began = time.perf_counter()
        answer = modbus.read_holding(HOLDING)
        delayed = time.perf_counter() - began
    assert answer[0] == 3  # the answer itself, only later
    assert delayed >= 0.15
    assert hli.comm_faults.table() == []  # ended by the block
    assert modbus.read_holding(HOLDING)[0] == 3


def test_a_modbus_connection_dropped_after_n_requests(hli: Harness, modbus: RawModbus) -> None:
    hli.comm_faults.add(kind="drop", door="modbus", after=3)
    for _ in range(3):
        assert modbus.read_holding(HOLDING)[0] == 3
    with pytest.raises((ConnectionResetError, TimeoutError, OSError)):
        modbus.read_holding(HOLDING, timeout=2)
    assert hli.comm_faults.table() == []  # one connection dropped: done
    again = RawModbus(hli.port("modbus"))
    try:
        assert again.read_holding(HOLDING)[0] == 3  # a new connection is served
    finally:
        again.close()


def test_ads_error_code_and_delay_for_pyads(hli: Harness) -> None:
    pyads = pytest.importorskip("pyads")
    from plc_clients.ads import close_pyads, open_pyads

    port = hli.port("ads")
    conn = open_pyads("127.0.0.1.1.1", 851, f"127.0.0.1:{port}", 3.0)
    try:
        signal = hli.layout.signal("gpCh[0]^bahn_state.mode_r")
        read = lambda: conn.read(0xF020, signal.ads_offset, pyads.PLCTYPE_DINT)  # noqa: E731
        read()
        hli.comm_faults.add(kind="error", door="ads", code=0x745, index_group=0xF020, count=1)
        with pytest.raises(pyads.ADSError) as info:
            read()
        assert info.value.err_code == 0x745
        read()  # the count was one
        hli.comm_faults.add(kind="delay", door="ads", delay_ms=200, count=2)
        began = time.perf_counter()
        read()
        read()
        assert time.perf_counter() - began >= 0.4
    finally:
        close_pyads(conn)


def test_a_stalled_publish_shows_the_plc_a_stale_cycle_counter(hli: Harness) -> None:
    plc = hli.transport("shm")
    hli.step(10)
    hli.comm_faults.add(kind="stall", cycles=20)
    hli.step(15)
    assert plc.snapshot().cycle == 10  # type: ignore[attr-defined]
    assert hli.cycle == 25
    hli.step(10)
    assert plc.snapshot().cycle == 35  # type: ignore[attr-defined]


def test_faults_are_bounded_and_refused_with_reasons(hli: Harness) -> None:
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="delay_ms"):
        hli.comm_faults.add(kind="delay", door="modbus", delay_ms=60_000, count=1)
    with pytest.raises(ValidationError, match="give the door"):
        hli.comm_faults.add(kind="error", code=4, count=1)
    with pytest.raises(ValidationError, match="Modbus exception code"):
        hli.comm_faults.add(kind="error", door="modbus", code=99, count=1)
    with pytest.raises(ValidationError, match="one end"):
        hli.comm_faults.add(kind="delay", door="ads", delay_ms=5)
    for _ in range(16):
        hli.comm_faults.add(kind="delay", door="ads", delay_ms=5, count=1)
    from hli_server.adapters.faults import FaultError

    with pytest.raises(FaultError, match="16 faults"):
        hli.comm_faults.add(kind="delay", door="ads", delay_ms=5, count=1)
    assert hli.comm_faults.reset() == 16


# --------------------------------------------------------------------------------------------
# hli-server run: the HTTP API, the doors in their own process, a recording of it all
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_the_http_api_sets_faults_for_the_doors_process_and_the_recording_keeps_them(tmp_path: Path) -> None:
    record = tmp_path / "run.jsonl.gz"
    proc = start_server(
        "--http-port", "0", "--modbus-port", "0", "--clock", "realtime", "--record", str(record),
        "--record-flush", "0.2",
    )  # fmt: skip
    try:
        banner = read_banner(proc)
        url = banner["url"]
        assert "doors process" in banner["Modbus TCP"]
        port = door_port(banner["Modbus TCP"])
        client = RawModbus(port)
        try:
            assert client.read_holding(HOLDING)[0] == 3
            answer = httpx.post(
                f"{url}/api/comm/faults",
                json={"kind": "error", "door": "modbus", "code": 2, "first": 0, "last": 9, "count": 3},
            )
            assert answer.status_code == 201, answer.text
            fault_id = answer.json()["id"]
            deadline = time.monotonic() + 5
            while client.read_holding(HOLDING) != bytes([0x83, 0x02]):  # the mirror gets there
                assert time.monotonic() < deadline
                time.sleep(0.02)
            client.read_holding(HOLDING)
            client.read_holding(HOLDING)
            # used up in the doors process: it tells the server, which ends it
            deadline = time.monotonic() + 5
            while httpx.get(f"{url}/api/comm/faults").json()["faults"]:
                assert time.monotonic() < deadline
                time.sleep(0.05)
            assert client.read_holding(HOLDING)[0] == 3
            history = httpx.get(f"{url}/api/comm/faults").json()["history"]
            assert {"fault": "end", "id": fault_id, "reason": "count"}.items() <= history[-1].items()
            bad = httpx.post(f"{url}/api/comm/faults", json={"kind": "stall"})
            assert bad.status_code == 422
            assert "cycles" in bad.text
            assert httpx.delete(f"{url}/api/comm/faults/999").status_code == 404
        finally:
            client.close()
        status = httpx.get(f"{url}/api/recording").json()
        assert status["recording"] is True
        assert status["file"] == str(record)
    finally:
        stop_server(proc)
    faults = [r for r in read_records(record) if "fault" in r]
    assert [r["fault"] for r in faults] == ["set", "end"]
    assert faults[1]["reason"] == "count"


# --------------------------------------------------------------------------------------------
# MQTT: the adapter disconnected (a real broker)
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
async def test_the_mqtt_adapter_disconnected_on_demand_the_broker_sends_the_will(tmp_path: Path) -> None:
    import aiomqtt

    from hli_server.adapters.mqtt import MqttAdapter
    from hli_server.runtime import Runtime, memory_image
    from tests.integration._mosquitto import Mosquitto, missing_tools

    reason = missing_tools("mosquitto")
    if reason:
        pytest.skip(reason)
    broker = Mosquitto(tmp_path / "mosquitto")
    broker.start()
    statuses: list[str] = []
    try:
        adapter = MqttAdapter(broker=f"127.0.0.1:{broker.port}", snapshot=False)

        async def watch() -> None:
            async with aiomqtt.Client("127.0.0.1", broker.port) as client:
                await client.subscribe("hli/demo/status", qos=1)
                async for message in client.messages:
                    statuses.append(bytes(message.payload).decode())  # type: ignore[arg-type]

        watcher = asyncio.create_task(watch())
        async with Runtime(
            load_machine(None),
            clock="stepped",
            http_port=None,
            adapters=[adapter],
            image_factory=memory_image,
        ) as rt:
            await _until(lambda: statuses[-1:] == ["online"])
            rt.comm_faults.add({"kind": "disconnect", "duration_ms": 1500})
            await _until(lambda: statuses[-1:] == ["offline"])  # the Will: the link was cut, not closed
            assert not adapter.connected
            await rt.step(5)  # events while away are queued
            await _until(lambda: statuses[-1:] == ["online"], timeout=10)
            assert rt.comm_faults.table() == []
            assert adapter.connects == 2
        watcher.cancel()
        with contextlib.suppress(asyncio.CancelledError, aiomqtt.MqttError):
            await watcher
    finally:
        broker.stop()


async def _until(done: Any, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, "timed out"
        await asyncio.sleep(0.02)


# --------------------------------------------------------------------------------------------
# fuzzed through the API
# --------------------------------------------------------------------------------------------


def _random_fault(rng: Any) -> dict[str, Any]:
    keys = ["kind", "door", "delay_ms", "after", "code", "first", "last", "table", "index_group",
            "duration_ms", "cycles", "count", "bogus"]  # fmt: skip
    values: list[Any] = [
        "delay", "drop", "error", "stall", "disconnect", "modbus", "ads", "shm", "mqtt", "nope",
        0, 1, 2, 4, 11, 99, -1, 65535, 65536, 2**32, 2**63, 10_000, 10_001, 3_600_000, 1e308,
        float("nan"), None, True, "3", [], {}, "coils", "holding_registers",
    ]  # fmt: skip
    valid: list[dict[str, Any]] = [
        {"kind": "delay", "door": "modbus", "delay_ms": 5, "count": 3},
        {"kind": "drop", "door": "ads", "after": 10},
        {"kind": "error", "door": "modbus", "code": 2, "first": 0, "last": 9, "duration_ms": 50},
        {"kind": "error", "door": "ads", "code": 0x745, "index_group": 0xF020, "cycles": 5},
        {"kind": "stall", "cycles": 3},
        {"kind": "disconnect", "duration_ms": 20},
    ]
    body = dict(rng.choice(valid))
    for _ in range(rng.choice((0, 0, 1, 2, 3))):  # a valid fault, or one with a few fields changed
        key = rng.choice(keys)
        if rng.random() < 0.2:
            body.pop(key, None)
        else:
            body[key] = rng.choice(values)
    return body


@pytest.mark.fuzz
def test_fuzzed_faults_through_the_http_api_never_break_the_server(hli: Harness) -> None:
    import random

    from tests.fuzz import count, seed_for

    rng = random.Random(seed_for("comm_faults_http"))
    url = hli.http_url
    modbus = RawModbus(hli.port("modbus"))
    statuses: dict[int, int] = {}
    try:
        with httpx.Client(base_url=url, timeout=10) as client:
            for _ in range(count(300)):
                body = _random_fault(rng)
                answer = client.post(
                    "/api/comm/faults",
                    content=json.dumps(body, allow_nan=True),
                    headers={"content-type": "application/json"},
                )
                statuses[answer.status_code] = statuses.get(answer.status_code, 0) + 1
                assert answer.status_code in (201, 409, 422), (body, answer.text)
                if rng.random() < 0.3:
                    client.delete("/api/comm/faults")
            assert client.delete("/api/comm/faults").status_code == 200
            assert client.get("/api/comm/faults").json()["faults"] == []
        hli.step(100)
        assert modbus.read_holding(HOLDING)[0] == 3  # the doors serve as before
    finally:
        modbus.close()
    assert statuses.get(201, 0) > 0
    assert statuses.get(422, 0) > 0
