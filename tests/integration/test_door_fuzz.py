"""Fuzzing the doors a client reaches over a socket or the shared memory (issue 12): HTTP, Modbus, the image.

Each fuzzer is seeded (``tests/fuzz.py``: ``HLI_FUZZ_SEED``) and bounded (a few seconds in ``make test``;
``make soak`` multiplies the counts with ``HLI_FUZZ_SCALE``). The bar for every input: the server neither
crashes nor answers 500 / Modbus exception 0x04 (an unexpected fault), the cycle never fails, and an input
the door refuses leaves the machine as it was (the PLC->CNC half of the image, the loaded program, the
injected faults). After the run a plain client is still served and the clock still steps.
(ADS: ``tests/integration/test_ads.py``; NC programs and configuration files:
``tests/unit/test_fuzz_inputs.py``.)
"""

from __future__ import annotations

import json
import random
import struct
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from hli_server.configuration import load_machine
from hli_server.runtime import Runtime
from plc_clients.shm import ImageClient
from schemas.layout import Direction
from tests.fuzz import count, seed_for

pytestmark = [pytest.mark.fuzz]

PROGRAM = "N10 G01 X5 Y5 F6000\nN20 M30\n"
ST_PATHS = [
    "gpCh[0]^bahn_mc_control.override.command_w",
    "gpCh[0]^bahn_mc_control.override.enable_w",
    "gpCh[0].bahn_state.program_state_r",
    "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w",
    "gpAx[0].ipo_mc_control.dyn_pos_limit_high.enable_w",
    "gpAx[9]^ipo_state.act_pos_r",
    "gpCh[0]^mc_command.mode_w",
    "nope",
    "gpAx[0]^..x",
    "gpCh[%5E]",
]


def _value(rng: random.Random) -> Any:
    """A JSON value a fuzzer sends: every type, the edges of every range, the numbers JSON cannot hold."""
    kind = rng.randrange(12)
    if kind == 0:
        return rng.choice([0, 1, -1, 2**31 - 1, -(2**31), 2**31, 2**63, -(2**64), 10**400])
    if kind == 1:
        return rng.choice([0.0, -0.0, 1e-300, 1e300, 120.0, 120.1, -0.1])
    if kind == 2:
        return rng.choice([True, False, None])
    if kind == 3:
        return rng.choice(["", "X", "manual", "automatic", "\ud800", "x" * 300, "1e400", "NaN", "Y1"])
    if kind == 4:
        return [_value(rng) for _ in range(rng.randrange(3))]
    if kind == 5:
        return {rng.choice(["on", "percent", "axis", "cycles", "value", "x"]): _value(rng)}
    return rng.randint(-5, 5)


def _body(rng: random.Random) -> tuple[str, dict[str, str]]:
    """A request body: mostly JSON objects with the endpoints' field names, sometimes not JSON at all."""
    kind = rng.randrange(10)
    headers = {"content-type": "application/json"}
    if kind == 0:
        return "".join(
            rng.choice('{}[]":,0123456789eE+-.NaInfity \\u') for _ in range(rng.randrange(40))
        ), headers
    if kind == 1:
        return rng.choice(["NaN", "Infinity", "-Infinity", "1e400", '"\\ud800"', "[]", "null"]), headers
    if kind == 2:
        return PROGRAM if rng.random() < 0.5 else "N10 G01 X1e400 F1\n", {"content-type": "text/plain"}
    fields = [
        "on",
        "percent",
        "mode",
        "axis",
        "direction",
        "cycles",
        "trace",
        "value",
        "number",
        "text",
        "name",
    ]
    fields += ["friction", "gain_factor", "encoder_drift", "encoder_stuck", "drive_error", "extra"]
    fields += ["swe_neg", "swe_pos", "swe_toleranz"]
    obj = {rng.choice(fields): _value(rng) for _ in range(rng.randrange(4))}
    text = json.dumps(obj, allow_nan=True)
    return text, headers


def _request(rng: random.Random) -> tuple[str, str]:
    channel = rng.choice(["1", "2", "0", "3", "-1", "x", "99999999999999999999"])
    axis = rng.choice(["X", "Y", "Z1", "Q", "x", "%F0%9F", "X" * 50])
    return rng.choice(
        [
            ("POST", f"/api/channels/{channel}/program"),
            ("POST", f"/api/channels/{channel}/select"),
            ("POST", f"/api/channels/{channel}/start"),
            ("POST", f"/api/channels/{channel}/feedhold"),
            ("POST", f"/api/channels/{channel}/mode"),
            ("POST", f"/api/channels/{channel}/override"),
            ("POST", f"/api/channels/{channel}/jog"),
            ("POST", f"/api/channels/{channel}/probe"),
            ("GET", f"/api/channels/{channel}/areas"),
            ("POST", f"/api/axes/{axis}/faults"),
            ("DELETE", f"/api/axes/{axis}/faults"),
            ("POST", f"/api/axes/{axis}/reference"),
            ("GET", f"/api/axes/{axis}/soft-limits"),
            ("PUT", f"/api/axes/{axis}/soft-limits"),
            ("PUT", f"/api/axes/{axis}/record"),
            ("POST", "/api/step"),
            ("GET", "/api/state"),
            ("GET", f"/api/events?since={rng.choice(['0', '-1', 'x', '99999999999999999999999'])}"),
            ("GET", f"/api/image/{rng.choice(ST_PATHS)}"),
            ("PUT", f"/api/image/{rng.choice(ST_PATHS)}"),
            ("PATCH", "/api/state"),
            ("GET", "/api/" + "a/" * rng.randrange(20)),
        ]
    )


def _state(rt: Runtime) -> tuple[bytes, str | None, list[dict[str, Any]], list[tuple[float, ...]]]:
    """What a refused request must not change: the PLC->CNC half, the programs, the faults, the
    software limits (in effect and in the axis record)."""
    m = rt.machine
    return (
        rt.image.read_half(Direction.PLC_TO_CNC),
        m.channel(1).program_text,
        [a.faults.as_dict() for a in m.axes],
        [
            (a.swe_neg, a.swe_pos, a.swe_tol, a.config.swe_neg, a.config.swe_pos, a.config.swe_toleranz)
            for a in m.axes
        ],
    )


@pytest.fixture
async def http_runtime() -> Iterator[Runtime]:  # type: ignore[misc]
    async with Runtime(load_machine(None), clock="stepped", adapters=[("http", {"port": 0})]) as rt:
        yield rt


@pytest.mark.req("H-01", "H-02")
async def test_fuzz_the_http_door_no_500_and_refusals_change_nothing(http_runtime: Runtime) -> None:
    rt = http_runtime
    rng = random.Random(seed_for("http-door"))
    statuses: dict[int, int] = {}
    async with httpx.AsyncClient(base_url=rt.http_url, timeout=10) as c:
        for i in range(count(1500)):
            method, path = _request(rng)
            body, headers = _body(rng) if method in ("POST", "PUT", "PATCH") else ("", {})
            before = _state(rt)
            r = await c.request(method, path, content=body.encode("utf-8", "surrogatepass"), headers=headers)
            statuses[r.status_code] = statuses.get(r.status_code, 0) + 1
            assert r.status_code < 500, (i, method, path, body, r.text)
            if r.headers.get("content-type", "").startswith("application/json"):
                json.loads(r.text)  # every answer is JSON a client can read
            if r.status_code >= 400:
                assert _state(rt) == before, (i, method, path, body, r.status_code)
            if i % 100 == 99:  # the machine goes on: reset what the fuzzer started, step
                for ch in (1, 2):
                    rt.operator.reset(ch)
                await rt.step(5)
        assert (await c.get("/api/state")).status_code == 200
    assert rt.timing()["failed_cycles"] == 0
    assert statuses.get(422, 0) > 0  # the fuzzer reached the validation, not only 404s


def _adu(tid: int, unit: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


@pytest.mark.req("H-03")
async def test_fuzz_the_modbus_door_mutated_requests_never_fault_and_refusals_change_nothing() -> None:
    import asyncio

    rng = random.Random(seed_for("modbus-door"))
    async with Runtime(load_machine(None), clock="stepped", adapters=[("modbus", {"port": 0})]) as rt:
        port: int = rt.adapter("modbus").port  # type: ignore[attr-defined]
        layout = rt.layout
        holding = [s for s in layout if s.modbus_table.value == "holding_register"]
        valid = [
            struct.pack(">BHH", 3, holding[0].modbus_address, 2),
            struct.pack(">BHH", 4, 0, 10),
            struct.pack(">BHH", 1, 0, 8),
            struct.pack(">BHH", 5, 0, 0xFF00),
            struct.pack(">BHHB", 16, holding[0].modbus_address, 2, 4) + struct.pack(">i", 12345),
            struct.pack(">BHHHHB", 23, 0, 2, holding[0].modbus_address, 2, 4) + struct.pack(">i", -5),
            struct.pack(">BHHB", 15, 0, 3, 1) + b"\x05",
        ]
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        answered = 0
        try:
            for i in range(count(3000)):
                pdu = bytearray(rng.choice(valid))
                for _ in range(rng.randint(1, 3)):
                    pdu[rng.randrange(len(pdu))] = rng.randrange(256)
                if rng.random() < 0.2:
                    pdu = pdu[: rng.randrange(1, len(pdu) + 1)]
                before = rt.image.read_half(Direction.PLC_TO_CNC)
                writer.write(_adu(i & 0xFFFF, rng.choice([1, 1, 1, 0, 255]), bytes(pdu)))
                head = await asyncio.wait_for(reader.readexactly(7), 5)
                (length,) = struct.unpack(">H", head[4:6])
                answer = await reader.readexactly(length - 1)
                answered += 1
                if answer[0] & 0x80:  # an exception: nothing was written
                    assert answer[1] != 0x04, (i, bytes(pdu).hex())  # never "server device failure"
                    assert rt.image.read_half(Direction.PLC_TO_CNC) == before, (i, bytes(pdu).hex())
                if i % 500 == 499:
                    await rt.step(2)
        finally:
            writer.close()
        assert answered == count(3000)
        assert rt.adapter("modbus").server.stats.exceptions.get(4, 0) == 0  # type: ignore[attr-defined]
        assert rt.timing()["failed_cycles"] == 0


@pytest.mark.req("H-01", "H-02")
async def test_fuzz_the_shared_memory_random_plc_outputs_never_fail_a_cycle() -> None:
    """A PLC writes whatever it likes into its half of the image (every field, any value of its type,
    BOOL bytes other than 0/1 by a raw memcpy): the engine latches it every cycle and never fails; bad
    requests (unknown modes or programs) are refused with alarms, and a reset brings the channels back."""
    rng = random.Random(seed_for("shm-door"))
    async with Runtime(load_machine(None), clock="stepped", http_port=None) as rt:
        client = ImageClient.attach(rt.image.name)
        try:
            p2c = [s for s in rt.layout if s.plc_writable]
            for i in range(count(400)):
                for s in rng.sample(p2c, rng.randint(1, 8)):
                    if s.type.value == "BOOL" and rng.random() < 0.3:
                        # a PLC in C writes the byte itself: any value, not only 0 and 1
                        client._buf[client.plan.p2c_offset + s.offset] = rng.randrange(256)
                        continue
                    if s.type.value == "BOOL":
                        value: Any = rng.random() < 0.5
                    elif s.type.value == "DINT":
                        value = rng.choice([0, 1, -1, 2**31 - 1, -(2**31), rng.randint(-(2**31), 2**31 - 1)])
                    else:
                        value = rng.choice([0, 1, 2, 2**32 - 1, rng.randint(0, 2**32 - 1)])
                    client.write(s.st_path, value)
                await rt.step(rng.randint(1, 20))
                if i % 50 == 49:
                    for ch in (1, 2):
                        rt.operator.reset(ch)
                    await rt.step(200)
            assert rt.timing()["failed_cycles"] == 0
            assert rt.image.read("gpCh[0]^bahn_state.cycle_r") == rt.machine.cycle
        finally:
            client.close()


@pytest.mark.req("N-05", "H-01", "H-03")
async def test_fuzz_v_e_strings_raw_bytes_and_registers_never_fail_a_cycle() -> None:
    """A PLC stores any bytes into the V.E. STRING fields (shared memory: no NUL, bytes Windows-1252 has no
    character for) and writes any registers over them (Modbus FC 16): the latch takes only what a STRING
    holds, the store's texts stay valid, Modbus refuses with 0x02/0x03 and never 0x04, no cycle fails."""
    import asyncio

    from tests.machines import demo_config

    rng = random.Random(seed_for("ve-strings"))
    async with Runtime(demo_config(external=True), clock="stepped", adapters=[("modbus", {"port": 0})]) as rt:
        port: int = rt.adapter("modbus").port  # type: ignore[attr-defined]
        strings = [s for s in rt.layout.external_signals if s.type.value == "STRING"]
        specs = {s.st_path: s.external_element for s in strings}
        client = ImageClient.attach(rt.image.name)
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        try:
            for i in range(count(600)):
                s = rng.choice(strings)
                if rng.random() < 0.5:
                    raw = bytes(rng.randrange(256) for _ in range(s.size))
                    if rng.random() < 0.5:
                        raw = raw[: rng.randrange(s.size)].ljust(s.size, b"\0")
                    start = client.plan.p2c_offset + s.offset
                    client._buf[start : start + s.size] = raw
                else:
                    count_ = rng.randint(1, s.modbus_count + 1)
                    data = bytes(rng.randrange(256) for _ in range(2 * count_))
                    pdu = (
                        struct.pack(">BHHB", 16, s.modbus_address + rng.choice([0, 0, 1]), count_, len(data))
                        + data
                    )
                    writer.write(_adu(i & 0xFFFF, 1, pdu))
                    head = await asyncio.wait_for(reader.readexactly(7), 5)
                    (length,) = struct.unpack(">H", head[4:6])
                    answer = await reader.readexactly(length - 1)
                    if answer[0] & 0x80:
                        assert answer[1] in (0x02, 0x03), (i, pdu.hex())
                await rt.step(1)
                for path, (name, index) in specs.items():
                    signal = rt.layout.signal(path)
                    channel = (
                        None if signal.scope.value == "ve_global" else rt.layout.channels[signal.index].number
                    )
                    text = rt.machine.external.read(name, channel, index)
                    assert isinstance(text, str)
                    assert len(text.encode("cp1252")) < signal.size, (path, text)
            assert rt.timing()["failed_cycles"] == 0
            assert rt.adapter("modbus").server.stats.exceptions.get(4, 0) == 0  # type: ignore[attr-defined]
        finally:
            writer.close()
            client.close()
