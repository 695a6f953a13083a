"""The dashboard's door over a real socket (issue 15): the page, the event stream ``/api/live`` and the
scene, with httpx as the client. The browser's view of it is ``tests/e2e/test_dashboard_browser.py``."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import AsyncIterator
from typing import Any

import httpx
import pytest

from hli_server.adapters.host import AccessPolicy
from hli_server.configuration import load_machine
from hli_server.runtime import Runtime
from tests.spec_examples import CIRC_PROT_OLD

THROUGH = CIRC_PROT_OLD + "N50 G01 X0 Y0 F30000\nN60 #CONTROL AREA ON [ID4]\nN70 G01 X300 F6000\nN80 M30\n"


@pytest.fixture
async def runtime() -> AsyncIterator[Runtime]:
    async with Runtime(load_machine(None), clock="stepped", http_port=0) as rt:
        yield rt


class Sse:
    """Messages of an open event stream: ``(event name, JSON data)``."""

    def __init__(self, response: httpx.Response) -> None:
        self._lines = response.aiter_lines()

    async def next(self, timeout: float = 5.0) -> tuple[str, Any]:
        name, data = "message", ""
        async with asyncio.timeout(timeout):
            async for line in self._lines:
                if line.startswith("event: "):
                    name = line[7:]
                elif line.startswith("data: "):
                    data = line[6:]
                elif line == "" and data:
                    return name, json.loads(data)
        raise EOFError("the stream ended")

    async def until(self, name: str, pred: Any = lambda _d: True, timeout: float = 5.0) -> Any:
        deadline = time.monotonic() + timeout
        while True:
            got, data = await self.next(max(deadline - time.monotonic(), 0.01))
            if got == name and pred(data):
                return data


async def test_the_page_is_served_at_the_root_with_its_script_and_style(runtime: Runtime) -> None:
    async with httpx.AsyncClient(base_url=runtime.http_url, timeout=10) as c:
        page = await c.get("/")
        assert page.status_code == 200
        assert page.headers["content-type"].startswith("text/html")
        assert '<script src="/dashboard.js"' in page.text
        assert 'href="/docs"' in page.text
        csp = page.headers["content-security-policy"]
        assert "script-src 'self'" in csp
        assert "frame-ancestors 'none'" in csp
        script = await c.get("/dashboard.js")
        assert script.headers["content-type"].startswith("text/javascript")
        assert "new EventSource(liveUrl())" in script.text
        assert '"/api/live?access_token="' in script.text  # the token reaches the stream (RFC 6750)
        style = await c.get("/dashboard.css")
        assert style.headers["content-type"].startswith("text/css")


def _initial(page: str) -> Any:
    head = '<script type="application/json" id="initial">'
    start = page.index(head) + len(head)
    return json.loads(page[start : page.index("</script>", start)])


async def test_the_page_is_served_with_the_machine_as_it_is_and_the_recent_events(runtime: Runtime) -> None:
    """Issue 23: the page carries what the stream would say first (hello, state, scenes) and the newest
    events of the log, so it is whole before the stream says anything and shows what happened before
    it was opened. Text of a client (a program name) cannot end the data block."""
    name = "before</script><script>alert(1)</script>"
    async with httpx.AsyncClient(base_url=runtime.http_url, timeout=10) as c:
        loaded = await c.post(
            "/api/channels/1/program", params={"name": name}, content="N10 G01 X20 F6000\nN20 M30\n"
        )
        assert loaded.status_code in (200, 202), loaded.text
        await runtime.step(5)
        page = (await c.get("/")).text
        state = (await c.get("/api/state")).json()
    assert page.count("<script") == 2  # the data block and the script: the name ended neither
    initial = _initial(page)
    assert initial["hello"]["machine"] == "demo"
    assert [ch["number"] for ch in initial["hello"]["channels"]] == [1, 2]
    assert initial["state"]["cycle"] == state["cycle"] == 5
    assert initial["state"]["channels"][0]["program"] == name
    assert {a["name"] for a in initial["state"]["axes"]} == set(state["axes"])
    assert [scene["channel"] for scene in initial["scenes"]] == [1, 2]
    loads = [e for e in initial["events"] if e["kind"] == "program_state" and e["data"]["cause"] == "load"]
    assert loads
    assert loads[0]["data"]["program"] == name


async def test_the_page_shows_the_newest_events_only(runtime: Runtime) -> None:
    from hli_server.adapters.http.routers.page import EVENTS_SHOWN

    async with httpx.AsyncClient(base_url=runtime.http_url, timeout=10) as c:
        for i in range(EVENTS_SHOWN + 5):  # an event a load: more than the page shows
            await c.post("/api/channels/1/program", params={"name": f"p{i}"}, content="N10 M30\n")
            await runtime.step(1)
        events = _initial((await c.get("/")).text)["events"]
        latest = (await c.get("/api/events", params={"since": 0, "limit": 1})).json()["latest"]
    assert len(events) == EVENTS_SHOWN
    assert events[-1]["seq"] == latest
    assert [e["seq"] for e in events] == list(range(latest - EVENTS_SHOWN + 1, latest + 1))


async def test_the_stream_says_hello_then_scenes_states_and_events(runtime: Runtime) -> None:
    async with (
        httpx.AsyncClient(base_url=runtime.http_url, timeout=10) as c,
        c.stream("GET", "/api/live") as r,
    ):
        assert r.status_code == 200
        assert r.headers["content-type"].startswith("text/event-stream")
        sse = Sse(r)
        name, hello = await sse.next()
        assert name == "hello"
        assert hello["machine"] == "demo"
        assert hello["clock"] == "stepped"
        assert hello["channels"][0]["programs"][0] == {"number": 1, "name": "square"}
        assert hello["token"] is False
        assert hello["read_only"] is False
        scene = await sse.until("scene")
        assert scene["scene"] == 1
        assert scene["channel"] in (1, 2)
        state = await sse.until("state")
        assert [a["name"] for a in state["axes"]] == ["X", "Y", "Z", "X1", "X2", "Z1"]
        await c.post("/api/channels/1/select", json={"number": 1})
        await c.post("/api/channels/1/start")
        await c.post("/api/step", json={"cycles": 300})
        event = await sse.until(
            "event", lambda e: e["kind"] == "program_state" and e["data"]["cause"] == "start"
        )
        assert event["channel"] == 1
        assert event["data"]["program"] == "square"
        moved = await sse.until("state", lambda s: s["cycle"] == 300)
        x = next(a for a in moved["axes"] if a["name"] == "X")
        assert x["command_mm"] > 1.0
        assert x["moving"] is True
        assert moved["channels"][0]["program_state_name"] == "running"


@pytest.mark.req("C14-14", "C14-15", "E-03")
async def test_a_violation_reaches_the_stream_as_alarm_event_and_scene(runtime: Runtime) -> None:
    async with (
        httpx.AsyncClient(base_url=runtime.http_url, timeout=10) as c,
        c.stream("GET", "/api/live") as r,
    ):
        sse = Sse(r)
        await sse.until("state")
        assert (
            await c.post("/api/channels/1/program", json={"text": THROUGH, "name": "through"})
        ).status_code == 200
        await c.post("/api/channels/1/start")
        await c.post("/api/step", json={"cycles": 2000})
        alarm = await sse.until("event", lambda e: e["kind"] == "alarm")
        assert alarm["data"]["alarm"]["id"] == 912001
        scene = await sse.until("scene", lambda s: s["channel"] == 1 and s["violation"] is not None)
        assert scene["violation"]["position"] == {"X": 100.0, "Y": 0.0, "Z": 0.0}
        assert scene["refused"]["block"] == "N70"
        (area,) = scene["areas"]
        assert (area["id"], area["kind"], area["state"], area["relation"]) == (4, "PROT", "active", "crosses")
        state = await sse.until("state", lambda s: s["alarms"])
        assert [a["id"] for a in state["alarms"]] == [912001]
        assert (await c.get("/api/channels/1/scene")).json() == scene  # the same scene, by request
        await c.post("/api/channels/1/reset")
        await c.post("/api/step", json={"cycles": 2})
        cleared = await sse.until("scene", lambda s: s["channel"] == 1 and s["violation"] is None)
        assert cleared["refused"] is None
        assert (await sse.until("state", lambda s: not s["alarms"]))["alarms"] == []


async def test_streams_beyond_the_bound_get_503_and_a_freed_slot_is_reused() -> None:
    async with (
        Runtime(
            load_machine(None), clock="stepped", adapters=[("http", {"port": 0, "max_streams": 2})]
        ) as rt,
        httpx.AsyncClient(base_url=rt.http_url, timeout=10) as c,
    ):
        async with c.stream("GET", "/api/live") as a, c.stream("GET", "/api/live") as b:
            assert (a.status_code, b.status_code) == (200, 200)
            refused = await c.get("/api/live")
            assert refused.status_code == 503
            assert "2 live streams are open" in refused.json()["detail"]
        for _ in range(100):  # the server notices the closed connections
            async with c.stream("GET", "/api/live") as again:
                if again.status_code == 200:
                    break
            await asyncio.sleep(0.02)
        assert again.status_code == 200


async def test_an_open_stream_outlives_the_idle_timeout() -> None:
    """The door closes connections silent for idle_timeout_s; a stream is a request in progress."""
    async with (
        Runtime(
            load_machine(None), clock="stepped", adapters=[("http", {"port": 0, "idle_timeout_s": 0.3})]
        ) as rt,
        httpx.AsyncClient(base_url=rt.http_url, timeout=10) as c,
        c.stream("GET", "/api/live") as r,
    ):
        sse = Sse(r)
        began = time.monotonic()
        states = 0
        while time.monotonic() - began < 1.2:
            name, _ = await sse.next(timeout=1.0)
            states += name == "state"
        assert states >= 10  # 20 Hz for 1.2 s, through four idle timeouts


async def test_an_open_stream_does_not_hold_the_shutdown() -> None:
    rt = Runtime(
        load_machine(None), clock="realtime", adapters=[("http", {"port": 0, "graceful_timeout_s": 5})]
    )
    await rt.start()
    async with httpx.AsyncClient(base_url=rt.http_url, timeout=10) as c, c.stream("GET", "/api/live") as r:
        sse = Sse(r)
        await sse.until("state")
        began = time.monotonic()
        await rt.stop()
        took = time.monotonic() - began
        ended = False
        for _ in range(100):  # what was on its way, then the end (no time-out)
            try:
                await sse.next(timeout=2.0)
            except EOFError:
                ended = True
                break
        assert ended, "the stream did not end at shutdown"
    assert took < 1.5, f"stopping took {took:.2f} s with a stream open (graceful timeout 5 s)"


async def test_with_a_token_the_page_is_told_and_actions_need_it() -> None:
    policy = AccessPolicy(api_token="s3cret")
    async with (
        Runtime(load_machine(None), clock="stepped", http_port=0, policy=policy) as rt,
        httpx.AsyncClient(base_url=rt.http_url, timeout=10) as c,
    ):
        assert (await c.get("/")).status_code == 200  # reading stays open
        async with c.stream("GET", "/api/live") as r:
            _, hello = await Sse(r).next()
        assert hello["token"] is True
        assert (await c.post("/api/channels/1/start")).status_code == 401
        ok = await c.post("/api/channels/1/start", headers={"authorization": "Bearer s3cret"})
        assert ok.status_code == 202


async def test_program_table_and_collision_pairs(runtime: Runtime) -> None:
    async with httpx.AsyncClient(base_url=runtime.http_url, timeout=10) as c:
        await c.post("/api/step", json={"cycles": 1})  # the pair is monitored from the first cycle (C3-06)
        programs = (await c.get("/api/channels/2/programs")).json()
        assert programs == [{"number": 1, "name": "carriages"}]
        assert (await c.get("/api/channels/9/programs")).status_code == 404
        (pair,) = (await c.get("/api/collision-pairs")).json()
        assert pair["master"] == "X2"
        assert pair["monitoring"] is True
