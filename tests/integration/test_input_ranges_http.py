"""Issue 12 findings 1 and 2 through the real door: the HTTP control API of a running server.

Finding 1: ``N10 G01 X1<305 zeros> F1000`` loaded and started, and the next cycle ended the server
(OverflowError in the soft-limit monitor). Now the program stops with alarm 910111 and the clock goes
on, stepped and in real time. Finding 2 (``{"encoder_drift": 1e308}``) is refused by the engine
(``Machine.inject_fault``, which the HTTP door's operator panel calls) with 422, and nothing changes.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from typing import Any

import httpx
import pytest

from hli_server.configuration import load_machine
from hli_server.engine.hli import ProgramState
from hli_server.runtime import Runtime
from tests.integration.servers import http_step as step

X_1E305 = "N10 G01 X1" + "0" * 305 + " F1000\nN20 M30\n"
GOOD = "N10 G01 X20 F6000\nN20 M30\n"


@pytest.fixture
async def runtime() -> AsyncIterator[Runtime]:
    async with Runtime(load_machine(None), clock="stepped", http_port=0) as rt:
        yield rt


@pytest.fixture
async def client(runtime: Runtime) -> AsyncIterator[httpx.AsyncClient]:
    async with httpx.AsyncClient(base_url=runtime.http_url, timeout=10) as c:
        yield c


async def load_and_start(client: httpx.AsyncClient, text: str) -> None:
    r = await client.post("/api/channels/1/program", json={"text": text, "name": "issue12"})
    assert r.status_code == 200, r.text
    assert (await client.post("/api/channels/1/start")).status_code == 202


@pytest.mark.req("E-04")
async def test_the_issues_program_is_an_alarm_and_the_stepped_server_goes_on(
    client: httpx.AsyncClient,
) -> None:
    await load_and_start(client, X_1E305)
    assert (await step(client, 5))["cycle"] == 5
    alarms = (await client.get("/api/alarms")).json()
    (alarm,) = alarms["active"]
    assert (alarm["id"], alarm["line"], alarm["block"]) == (910111, 1, "N10")
    assert alarm["message"].startswith("X1e305 is out of range: positions must lie within +/-214748.3647 mm")
    assert (await step(client, 1000))["cycle"] == 1005
    assert (await client.post("/api/channels/1/reset")).status_code == 202
    await step(client, 1)
    await load_and_start(client, GOOD)
    await step(client, 2000)
    state = (await client.get("/api/state")).json()
    assert state["channels"][0]["program_state"] == ProgramState.FINISHED
    assert state["axes"]["X"]["setpoint_mm"] == pytest.approx(20.0)


@pytest.mark.req("E-04")
async def test_the_issues_program_does_not_end_a_realtime_server() -> None:
    async with (
        Runtime(load_machine(None), clock="realtime", http_port=0) as rt,
        httpx.AsyncClient(base_url=rt.http_url, timeout=10) as client,
    ):
        await load_and_start(client, X_1E305)
        deadline = time.monotonic() + 10.0
        active: list[dict[str, Any]] = []
        while not active and time.monotonic() < deadline:
            await asyncio.sleep(0.01)  # polling for the alarm, bounded by the deadline
            active = (await client.get("/api/alarms")).json()["active"]
        assert [a["id"] for a in active] == [910111]
        first = (await client.get("/api/state")).json()["cycle"]
        while (await client.get("/api/state")).json()["cycle"] < first + 200 and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        assert (await client.get("/api/state")).json()["cycle"] >= first + 200  # the clock kept going


@pytest.mark.req("A3-05")
async def test_the_issues_encoder_drift_is_refused_at_the_http_door(client: httpx.AsyncClient) -> None:
    r = await client.post("/api/axes/X/faults", json={"encoder_drift": 1e308})
    assert r.status_code == 422
    assert "encoder_drift" in r.text
    assert (await step(client, 10))["cycle"] == 10
    assert (await client.get("/api/axes/X/faults")).json()["encoder_drift"] == 0.0
