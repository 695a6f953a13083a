"""The HTTP control API over a real socket: uvicorn on port 0 inside the runtime's loop, httpx as
the client, the stepped clock for exact cycles (E-01, H-01, H-02, H-07).

The server is the harness' (the ``hli`` fixture of the project's pytest plugin) with its HTTP door.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from hli_server.configuration import load_machine
from hli_server.runtime import Runtime
from hli_server.runtime.pacing import CAUSES
from hli_server.testing import Harness
from schemas.config import MachineConfig, ProgramEntry
from schemas.wire import HoldSource, ProgramState
from tests.integration.servers import http_step as step

PROGRAM = "N10 G01 X20 Y10 F6000\nN20 G01 X0 Y0\nN30 M30\n"
OVERRIDE = "gpCh[0]^bahn_mc_control.override"


@pytest.fixture
async def client(hli: Harness) -> AsyncIterator[httpx.AsyncClient]:
    async with httpx.AsyncClient(base_url=hli.http_url, timeout=10) as c:
        yield c


def url_path(st_path: str) -> str:
    return "/api/image/" + st_path.replace("^", "%5E")


# --------------------------------------------------------------------------------------------


@pytest.mark.req("E-01")
async def test_server_listens_on_the_port_it_was_given(hli: Harness, client: httpx.AsyncClient) -> None:
    port = int(hli.http_url.rsplit(":", 1)[1])
    assert port > 0
    r = await client.get("/api/state")
    assert r.status_code == 200
    state = r.json()
    assert state["cycle"] == 0
    assert state["clock"] == "stepped"
    assert [c["number"] for c in state["channels"]] == [1, 2]
    assert "X" in state["axes"]


@pytest.mark.req("E-01", "E-04")
async def test_load_program_start_step_and_see_positions_change(client: httpx.AsyncClient) -> None:
    r = await client.post(
        "/api/channels/1/program?name=zigzag", content=PROGRAM, headers={"content-type": "text/plain"}
    )
    assert r.status_code == 200, r.text
    assert r.json()["lines"] == 3
    r = await client.post("/api/channels/1/start")
    assert r.status_code == 202
    assert r.json() == {"channel": 1, "request": "start", "cycle": 0, "effective_cycle": 1}
    assert (await step(client, 100))["cycle"] == 100
    state = (await client.get("/api/state")).json()
    ch1 = state["channels"][0]
    assert ch1["program"] == "zigzag"
    assert ch1["program_state"] == ProgramState.RUNNING
    x = state["axes"]["X"]["setpoint_mm"]
    assert x > 0.0
    # the same position through the image (0.1 µm)
    r = await client.get(url_path("gpAx[0]^ipo_state.cmd_pos_r"))
    assert r.status_code == 200
    assert r.json()["value"] == round(x * 10_000)
    await step(client, 100)
    later = (await client.get("/api/state")).json()["axes"]["X"]["setpoint_mm"]
    assert later > x


async def test_time_is_the_cycle_exact_to_the_microsecond(client: httpx.AsyncClient) -> None:
    """Issue 23: ``/api/step`` answered ``"time_s": 0.013000000000000001``; the time of a cycle is
    cycle x T_A, shown as the decimal it is (T_A is whole µs), in the answers and the events."""
    r = await client.post("/api/step", json={"cycles": 13})
    assert r.text.endswith('"time_s":0.013}'), r.text
    for cycles in (1, 2, 3, 7, 11, 29, 97, 1001):
        answer = await client.post("/api/step", json={"cycles": cycles})
        body = answer.json()
        assert body["time_s"] == round(body["cycle"] / 1000, 6)
        assert len(repr(body["time_s"]).split(".")[1]) <= 6, body
    await client.post(
        "/api/channels/1/program", content="N10 G01 X1 F6000\n", headers={"content-type": "text/plain"}
    )
    await client.post("/api/channels/1/start")
    await step(client, 3)
    events = (await client.get("/api/events")).json()["events"]
    assert events
    for event in events:
        assert event["time_s"] == round(event["cycle"] / 1000, 6)


async def test_program_as_json_and_refused_while_running(client: httpx.AsyncClient) -> None:
    r = await client.post("/api/channels/1/program", json={"text": PROGRAM, "name": "json"})
    assert r.status_code == 200
    assert r.json()["program"] == "json"
    await client.post("/api/channels/1/start")
    await step(client, 5)
    r = await client.post("/api/channels/1/program", json={"text": PROGRAM})
    assert r.status_code == 409
    assert "reset the channel" in r.json()["detail"]


async def test_program_body_errors_are_422(client: httpx.AsyncClient) -> None:
    r = await client.post("/api/channels/1/program", json={"txt": PROGRAM})
    assert r.status_code == 422
    locs = [e["loc"] for e in r.json()["detail"]]
    assert ["text"] in locs
    assert ["txt"] in locs
    r = await client.post("/api/channels/1/program", content="  \n", headers={"content-type": "text/plain"})
    assert r.status_code == 422
    assert "empty program" in r.json()["detail"]


async def test_select_a_program_of_the_table_and_run_it(client: httpx.AsyncClient) -> None:
    r = await client.post("/api/channels/1/select", json={"number": 2})
    assert r.status_code == 200
    assert r.json()["program"] == "circle"
    await client.post("/api/channels/1/start")
    await step(client, 50)
    ch1 = (await client.get("/api/state")).json()["channels"][0]
    assert ch1["program"] == "circle"
    assert ch1["program_state"] == ProgramState.RUNNING
    r = await client.post("/api/channels/1/select", json={"number": 99})
    assert r.status_code == 404
    assert "not in the program table" in r.json()["detail"]


async def test_feedhold_holds_the_path_and_releases_it(client: httpx.AsyncClient) -> None:
    await client.post("/api/channels/1/program", json={"text": PROGRAM})
    await client.post("/api/channels/1/start")
    await step(client, 50)
    r = await client.post("/api/channels/1/feedhold", json={"on": True})
    assert r.status_code == 202
    await step(client, 300)
    held = (await client.get("/api/state")).json()
    assert held["channels"][0]["program_state"] == ProgramState.HELD
    await step(client, 10)
    assert (await client.get("/api/state")).json()["axes"]["X"]["setpoint_mm"] == held["axes"]["X"][
        "setpoint_mm"
    ]
    await client.post("/api/channels/1/feedhold", json={"on": False})
    await step(client, 20)
    assert (await client.get("/api/state")).json()["channels"][0]["program_state"] == ProgramState.RUNNING
    r = await client.post("/api/channels/1/feedhold", json={"on": "yes"})
    assert r.status_code == 422


async def test_override_is_latched_into_the_control_unit(client: httpx.AsyncClient) -> None:
    r = await client.post("/api/channels/1/override", json={"percent": 55.5})
    assert r.status_code == 202
    await step(client, 1)
    assert (await client.get(url_path(OVERRIDE + ".request_r"))).json()["value"] == 555
    assert (await client.get(url_path(OVERRIDE + ".state_r"))).json()["value"] == 555
    assert (await client.post("/api/channels/1/override", json={"percent": 130})).status_code == 422


async def test_manual_mode_and_jog(client: httpx.AsyncClient) -> None:
    r = await client.post("/api/channels/1/mode", json={"mode": "manual"})
    assert r.status_code == 202
    await step(client, 1)
    assert (await client.get("/api/state")).json()["channels"][0]["mode"] == "manual"
    r = await client.post("/api/channels/1/jog", json={"axis": "Y", "direction": -1})
    assert r.status_code == 202
    assert r.json()["request"] == "jog Y-"
    await step(client, 200)
    assert (await client.get("/api/state")).json()["axes"]["Y"]["setpoint_mm"] < -1.0
    r = await client.post("/api/channels/1/jog", json={"axis": "Y", "direction": 0})
    assert r.json()["request"] == "jog Y released"
    # the bare string is accepted too
    assert (await client.post("/api/channels/1/mode", json="automatic")).status_code == 202
    r = await client.post("/api/channels/1/jog", json={"axis": "X1", "direction": 1})
    assert r.status_code == 404
    assert "its axes are X, Y, Z" in r.json()["detail"]
    assert (await client.post("/api/channels/1/jog", json={"axis": "X", "direction": 2})).status_code == 422
    assert (await client.post("/api/channels/1/mode", json={"mode": "auto"})).status_code == 422


async def test_reset_clears_the_channel(client: httpx.AsyncClient) -> None:
    await client.post("/api/channels/1/program", json={"text": PROGRAM})
    await client.post("/api/channels/1/start")
    await step(client, 20)
    assert (await client.post("/api/channels/1/reset")).status_code == 202
    await step(client, 1)
    assert (await client.get("/api/state")).json()["channels"][0]["program_state"] == ProgramState.IDLE


async def test_unknown_channel_is_404(client: httpx.AsyncClient) -> None:
    r = await client.post("/api/channels/7/start")
    assert r.status_code == 404
    assert r.json()["detail"] == "no channel 7; the machine has channels 1, 2"


@pytest.mark.req("E-01")
async def test_step_validation(client: httpx.AsyncClient) -> None:
    assert (await client.post("/api/step", json={"cycles": 0})).status_code == 422
    assert (await client.post("/api/step", json={"cycles": 5, "extra": 1})).status_code == 422
    r = await client.post("/api/step")  # no body: one cycle
    assert r.status_code == 200
    assert r.json()["cycle"] == 1


@pytest.mark.req("E-01")
async def test_step_outside_the_stepped_clock_is_409() -> None:
    async with (
        Runtime(load_machine(None), clock="realtime", http_port=0) as rt,
        httpx.AsyncClient(base_url=rt.http_url) as c,
    ):
        r = await c.post("/api/step", json={"cycles": 1})
        assert r.status_code == 409
        assert "stepped clock" in r.json()["detail"]
        timing = (await c.get("/api/timing")).json()
        assert timing["clock"] == "realtime"
        assert set(timing["lateness_us"] or {}) <= {"p50", "p99", "p999", "max"}
        assert len(timing["worst"]) <= 5
        assert all(w["cause"] in CAUSES for w in timing["worst"])


# --------------------------------------------------------------------------------------------
# The image by ST path (H-01, H-02)
# --------------------------------------------------------------------------------------------


@pytest.mark.req("H-01", "H-02")
async def test_image_write_command_and_enable_then_state_follows(client: httpx.AsyncClient) -> None:
    r = await client.put(url_path(OVERRIDE + ".command_w"), json={"value": 250})
    assert r.status_code == 200, r.text
    assert r.json()["effective_cycle"] == 1
    await step(client, 1)
    # not enabled: the CNC keeps its own request
    assert (await client.get(url_path(OVERRIDE + ".state_r"))).json()["value"] == 1000
    await client.put(url_path(OVERRIDE + ".enable_w"), json={"value": True})
    assert (await client.get(url_path(OVERRIDE + ".enable_w"))).json()["value"] is True
    await step(client, 1)
    field = (await client.get(url_path(OVERRIDE + ".state_r"))).json()
    assert field["value"] == 250
    assert field["access"] == "read"
    assert field["cycle"] == 2


@pytest.mark.req("H-02")
async def test_image_write_to_an_r_field_is_403(client: httpx.AsyncClient) -> None:
    r = await client.put(url_path(OVERRIDE + ".state_r"), json={"value": 1})
    assert r.status_code == 403
    assert "only the CNC writes it" in r.json()["detail"]


async def test_image_unknown_path_is_404_and_bad_value_422(client: httpx.AsyncClient) -> None:
    r = await client.get(url_path("gpAx[0]^ipo_state.act_pos"))
    assert r.status_code == 404
    assert "act_pos_r" in r.json()["detail"]  # the closest names are suggested
    assert (await client.put(url_path("gpAx[99]^manual.jog_plus_w"), json={"value": True})).status_code == 404
    r = await client.put(url_path(OVERRIDE + ".command_w"), json={"value": 1.5})
    assert r.status_code == 422
    assert "integer" in r.json()["detail"]
    r = await client.put(url_path(OVERRIDE + ".command_w"), json={"value": 2**31})
    assert r.status_code == 422
    assert (await client.put(url_path(OVERRIDE + ".command_w"), json={})).status_code == 422
    # strings are no numbers and no booleans, whatever they spell
    assert (await client.put(url_path(OVERRIDE + ".command_w"), json={"value": "300"})).status_code == 422
    assert (await client.put(url_path(OVERRIDE + ".enable_w"), json={"value": "yes"})).status_code == 422
    assert (await client.get(url_path(OVERRIDE + ".enable_w"))).json()["value"] is False
    assert (await client.put(url_path(OVERRIDE + ".enable_w"), json={"value": 1})).status_code == 200


async def test_image_path_with_a_dot_instead_of_the_caret(client: httpx.AsyncClient) -> None:
    r = await client.get("/api/image/gpAx[1].ipo_state.referenced_r")
    assert r.status_code == 200
    assert r.json()["st_path"] == "gpAx[1]^ipo_state.referenced_r"
    assert r.json()["value"] is True


async def test_layout_is_served(hli: Harness, client: httpx.AsyncClient) -> None:
    layout = (await client.get("/api/layout")).json()
    assert layout["layout_hash"] == hli.layout.hash
    assert any(s["st_path"] == OVERRIDE + ".command_w" for s in layout["signals"])


# --------------------------------------------------------------------------------------------
# Faults, alarms, events, OpenAPI
# --------------------------------------------------------------------------------------------


@pytest.mark.req("A3-05")
async def test_fault_injection(hli: Harness, client: httpx.AsyncClient) -> None:
    r = await client.post("/api/axes/X/faults", json={"friction": 0.5, "encoder_stuck": True})
    assert r.status_code == 200
    assert r.json()["friction"] == 0.5
    assert r.json()["gain_factor"] == 1.0
    assert hli.runtime.machine.axis("X").faults.encoder_stuck is True
    r = await client.post("/api/axes/X/faults", json={"gain_factor": 0.5})
    assert r.json()["friction"] == 0.5  # omitted fields keep their value
    assert (await client.get("/api/axes/X/faults")).json()["gain_factor"] == 0.5
    r = await client.delete("/api/axes/X/faults")
    assert r.json() == {
        "axis": "X",
        "friction": 0.0,
        "gain_factor": 1.0,
        "encoder_stuck": False,
        "encoder_drift": 0.0,
        "drive_error": False,
    }
    assert (await client.post("/api/axes/X/faults", json={"gain_factor": 0})).status_code == 422
    assert (await client.post("/api/axes/X/faults", json={"drive_eror": True})).status_code == 422
    r = await client.post("/api/axes/Q/faults", json={"friction": 1})
    assert r.status_code == 404
    assert "X, Y, Z, X1, X2, Z1" in r.json()["detail"]


@pytest.mark.req("E-06", "B-04")
async def test_soft_limits_in_effect_and_in_the_axis_record(hli: Harness, client: httpx.AsyncClient) -> None:
    """P-AXIS-00177/00178 "Anmerkungen": the limits are taken from the axis record at reset and mode
    change (FCT-C14 6.2); in between the limits in effect may differ (the kernel's G98/G99)."""
    r = await client.get("/api/axes/X/soft-limits")
    demo = {"swe_neg": -6_000_000, "swe_pos": 6_000_000, "swe_toleranz": 1_000}
    assert r.json() == {"axis": "X", "in_effect": demo, "record": demo}
    r = await client.put("/api/axes/X/soft-limits", json={"swe_pos": 1_000_000})
    assert r.status_code == 200
    assert r.json()["in_effect"]["swe_pos"] == 1_000_000
    assert r.json()["record"]["swe_pos"] == 6_000_000
    r = await client.put("/api/axes/X/record", json={"swe_neg": -2_000_000})
    assert (r.json()["in_effect"]["swe_neg"], r.json()["record"]["swe_neg"]) == (-6_000_000, -2_000_000)
    await client.post("/api/channels/1/reset")
    await step(client, 2)
    r = await client.get("/api/axes/X/soft-limits")
    assert r.json()["in_effect"] == {"swe_neg": -2_000_000, "swe_pos": 6_000_000, "swe_toleranz": 1_000}
    assert hli.runtime.machine.axis("X").swe_pos == 600.0
    assert (await client.put("/api/axes/X/soft-limits", json={"swe_neg": 7_000_000})).status_code == 422
    r = await client.put("/api/axes/X/record", json={"swe_pos": -3_000_000})
    assert r.status_code == 422
    assert "swe_neg" in r.json()["detail"]
    assert (await client.put("/api/axes/X/record", json={"a_max": 5})).status_code == 422
    assert (await client.put("/api/axes/Q/record", json={"swe_pos": 5})).status_code == 404


async def test_faults_take_effect_in_the_position_loop(client: httpx.AsyncClient) -> None:
    await client.post("/api/axes/Y/faults", json={"encoder_drift": 10.0})
    await step(client, 100)
    y = (await client.get("/api/state")).json()["axes"]["Y"]
    assert y["setpoint_mm"] == 0.0
    assert y["actual_mm"] != 0.0  # the loop follows the drifting encoder


async def test_alarms_and_events(client: httpx.AsyncClient) -> None:
    await client.post("/api/channels/1/start")  # no program: refused with a warning
    await step(client, 1)
    alarms = (await client.get("/api/alarms")).json()
    assert alarms["active"] == []
    assert alarms["history"][-1]["id"] == 911021
    assert "no program selected" in alarms["history"][-1]["message"]
    events = (await client.get("/api/events")).json()
    assert events["events"][-1]["kind"] == "alarm"
    assert events["latest"] == events["next"] >= 1
    again = (await client.get("/api/events", params={"since": events["next"]})).json()
    assert again["events"] == []
    assert (await client.get("/api/events", params={"since": -1})).status_code == 422


async def test_openapi_is_published(client: httpx.AsyncClient) -> None:
    spec = (await client.get("/openapi.json")).json()
    paths = spec["paths"]
    for path in (
        "/api/state",
        "/api/channels/{number}/program",
        "/api/channels/{number}/start",
        "/api/step",
        "/api/axes/{name}/faults",
        "/api/alarms",
        "/api/events",
        "/api/image/{st_path}",
        "/api/timing",
    ):
        assert path in paths, path
    content = paths["/api/channels/{number}/program"]["post"]["requestBody"]["content"]
    assert set(content) == {"text/plain", "application/json"}
    assert (await client.get("/docs")).status_code == 200


@pytest.fixture
def program_file(tmp_path: Path) -> Path:
    nc = tmp_path / "file.nc"
    nc.write_text(PROGRAM, encoding="utf-8")
    return nc


@pytest.fixture
def hli_machine(request: pytest.FixtureRequest) -> MachineConfig | None:
    """The demo machine; with a program table entry read from a file for the test that asks for it."""
    if "program_file" not in request.fixturenames:
        return None
    config = load_machine(None).model_copy(deep=True)
    path = request.getfixturevalue("program_file")
    config.channels[0].programs.append(ProgramEntry(number=7, name="from file", path=str(path)))
    return config


async def test_select_a_program_given_by_path_reads_the_file(
    hli: Harness, client: httpx.AsyncClient, program_file: Path
) -> None:
    """Program table entries with ``path`` are read by the runtime when selected (the engine does no I/O)."""
    r = await client.post("/api/channels/1/select", json={"number": 7})
    assert r.status_code == 200, r.text
    assert hli.runtime.machine.channel(1).program_text == PROGRAM
    await client.post("/api/channels/1/start")
    await step(client, 50)
    assert hli.runtime.machine.axis("X").setpoint > 0.0


# --------------------------------------------------------------------------------------------
# Per-cycle traces (H-07)
# --------------------------------------------------------------------------------------------

TRACED = ["gpAx[0].ipo_state.cmd_pos_r", "gpCh[0]^bahn_state.program_state_r", f"{OVERRIDE}.enable_w"]


@pytest.mark.req("H-07")
async def test_step_with_a_trace_returns_the_signals_in_every_cycle(
    hli: Harness, client: httpx.AsyncClient
) -> None:
    await client.post("/api/channels/1/program", json={"text": PROGRAM})
    await client.post("/api/channels/1/start")
    await step(client, 3)
    await client.put(url_path(f"{OVERRIDE}.command_w"), json={"value": 900})
    await client.put(url_path(f"{OVERRIDE}.enable_w"), json={"value": True})
    with hli.trace("gpAx[0]^ipo_state.cmd_pos_r", f"{OVERRIDE}.enable_w") as recording:
        r = await client.post("/api/step", json={"cycles": 40, "trace": TRACED})
    assert r.status_code == 200, r.text
    body = r.json()
    assert (body["cycles"], body["cycle"]) == (40, 43)
    trace = body["trace"]
    x, state, enabled = (trace["values"][p] for p in ("gpAx[0]^ipo_state.cmd_pos_r", *TRACED[1:]))
    assert trace["signals"] == ["gpAx[0]^ipo_state.cmd_pos_r", *TRACED[1:]]  # the dot spelling normalised
    assert trace["cycles"] == list(range(4, 44))
    assert len(x) == len(state) == len(enabled) == 40
    assert x == sorted(x)
    assert x[-1] > x[0] > 0
    assert set(state) == {ProgramState.RUNNING}
    assert enabled == [True] * 40  # a PLC->CNC field: as each cycle latched it
    # the same cycles as the harness recorded them
    recorded = recording.trace()
    assert recorded.cycles == trace["cycles"]
    assert recorded["gpAx[0]^ipo_state.cmd_pos_r"].tolist() == x


@pytest.mark.req("H-07")
async def test_a_trace_of_an_unknown_signal_or_too_many_values_runs_no_cycle(
    client: httpx.AsyncClient,
) -> None:
    r = await client.post("/api/step", json={"cycles": 5, "trace": ["gpAx[0]^ipo_state.cmd_posr"]})
    assert r.status_code == 404
    assert "did you mean gpAx[0]^ipo_state.cmd_pos_r" in r.json()["detail"]
    r = await client.post("/api/step", json={"cycles": 1_000_000, "trace": TRACED})
    assert r.status_code == 422
    assert "more than the 2,000,000 one answer may carry" in r.text
    r = await client.post("/api/step", json={"cycles": 1, "trace": ["gpAx[0]^ipo_state.cmd_pos_r"] * 65})
    assert r.status_code == 422
    assert (await client.get("/api/state")).json()["cycle"] == 0


# --------------------------------------------------------------------------------------------
# The channel's states, as a PLC reads them from the image and an operator from the API (issue 9)
# --------------------------------------------------------------------------------------------

PROGRAM_STATE = "gpCh[0]^bahn_state.program_state_r"


async def image_value(client: httpx.AsyncClient, st_path: str) -> Any:
    r = await client.get(url_path(st_path))
    assert r.status_code == 200, r.text
    return r.json()["value"]


async def channel_state(client: httpx.AsyncClient) -> dict[str, Any]:
    channels: list[dict[str, Any]] = (await client.get("/api/state")).json()["channels"]
    return channels[0]


@pytest.mark.req("E-04", "E-06", "H-01")
async def test_an_error_abort_reads_aborted_until_reset_and_a_new_program_loads(
    client: httpx.AsyncClient,
) -> None:
    """Issue 9, defect 1: after a soft-limit error the program reads 3 (aborted), not 1, in the image
    and in the API; a new program is accepted; the reset brings 0."""
    program = "N10 G01 X10 F6000\nN20 X700\nN30 M30\n"  # X700 lies beyond the software limit (600 mm)
    assert (await client.post("/api/channels/1/program", content=program)).status_code == 200
    await client.post("/api/channels/1/start")
    await step(client, 3000)
    assert await image_value(client, PROGRAM_STATE) == ProgramState.ABORTED
    assert await image_value(client, "gpCh[0]^bahn_state.error_id_r") == 120002
    state = await channel_state(client)
    assert (state["program_state"], state["program_state_name"]) == (3, "aborted")
    r = await client.post("/api/channels/1/program", content="N10 G01 X5 F6000\nN20 M30\n")
    assert r.status_code == 200, r.text  # no "a program is running"
    assert await image_value(client, PROGRAM_STATE) == ProgramState.ABORTED  # published next cycle
    await client.post("/api/channels/1/reset")
    await step(client, 1)
    assert await image_value(client, PROGRAM_STATE) == ProgramState.IDLE
    events = (await client.get("/api/events")).json()["events"]
    states = [(e["data"]["state"], e["data"]["cause"]) for e in events if e["kind"] == "program_state"]
    assert states == [
        ("idle", "load"),
        ("running", "start"),
        ("aborted", "error"),
        ("idle", "load"),
        ("idle", "reset"),
    ]


@pytest.mark.req("E-03", "E-04", "H-01")
async def test_a_start_while_the_reset_still_brakes_is_refused_and_nothing_restarts_by_itself(
    client: httpx.AsyncClient,
) -> None:
    """Issue 9, defect 2: reset while moving, start one cycle later: the start is refused with warning
    911022 (the axes still brake), the program state stays 0, and X never moves again by itself."""
    await client.post("/api/channels/1/program", content="N10 G01 X300 F12000\nN20 M30\n")
    await client.post("/api/channels/1/start")
    await step(client, 500)
    assert await image_value(client, "gpAx[0]^ipo_state.moving_r") is True
    await client.post("/api/channels/1/reset")
    await step(client, 1)
    await client.post("/api/channels/1/start")
    await step(client, 1)
    assert await image_value(client, PROGRAM_STATE) == ProgramState.IDLE
    assert await image_value(client, "gpCh[0]^bahn_state.warning_id_r") == 911022
    history = (await client.get("/api/alarms")).json()["history"]
    assert history[-1]["id"] == 911022
    assert "still brake" in history[-1]["message"]
    await step(client, 300)
    x_at_rest = await image_value(client, "gpAx[0]^ipo_state.cmd_pos_r")
    await step(client, 300)
    assert await image_value(client, PROGRAM_STATE) == ProgramState.IDLE
    assert await image_value(client, "gpAx[0]^ipo_state.cmd_pos_r") == x_at_rest  # nothing restarted
    await client.post("/api/channels/1/start")  # at rest now: the start is taken
    await step(client, 2)
    assert await image_value(client, PROGRAM_STATE) == ProgramState.RUNNING


@pytest.mark.req("C43-04", "C43-07", "E-05", "H-01")
async def test_a_dynamic_limit_hold_is_visible_at_the_channel(client: httpx.AsyncClient) -> None:
    """Issue 9, defect 3: while a dynamic position limit holds the path, the channel reads HELD (2),
    feedhold_active_r TRUE and hold_source_r = 0x2 (dyn_pos_limit); lifting it continues the program."""
    unit = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high"
    await client.put(url_path(f"{unit}.command_w"), json={"value": 500_000})  # 50 mm
    await client.put(url_path(f"{unit}.enable_w"), json={"value": True})
    await client.post("/api/channels/1/program", content="N10 G01 X100 F6000\nN20 M30\n")
    await client.post("/api/channels/1/start")
    await step(client, 2000)
    assert await image_value(client, f"{unit}.state_r") == 4  # ACTIVE_BRAKE
    assert await image_value(client, PROGRAM_STATE) == ProgramState.HELD
    assert await image_value(client, "gpCh[0]^bahn_state.feedhold_active_r") is True
    assert await image_value(client, "gpCh[0]^bahn_state.hold_source_r") == HoldSource.DYN_POS_LIMIT
    state = await channel_state(client)
    assert (state["program_state_name"], state["holds"]) == ("held", ["dyn_pos_limit"])
    await client.put(url_path(f"{unit}.enable_w"), json={"value": False})
    await step(client, 3000)
    assert await image_value(client, PROGRAM_STATE) == ProgramState.FINISHED
    assert await image_value(client, "gpCh[0]^bahn_state.hold_source_r") == 0
    events = (await client.get("/api/events")).json()["events"]
    holds = [e["data"]["sources"] for e in events if e["kind"] == "hold"]
    assert holds == [["dyn_pos_limit"], []]


@pytest.mark.req("E-02", "C3-06", "H-01")
async def test_referencing_through_the_api_and_the_image_starts_collision_monitoring(tmp_path: Path) -> None:
    """An unreferenced collision pair: programs are refused (911020), FCT-C3 monitoring is off; the
    operator references X1 (HTTP), the PLC X2 (manual.reference_w); monitoring starts in the cycle the
    second axis is referenced."""
    config = load_machine(None)
    homes = {"X1": -500_000, "X2": 5_200_000}  # the reference marks: 50 mm and 20 mm from the start
    axes = [
        a.model_copy(update={"referenced": False, "reference_position": homes[a.name]})
        if a.name in homes
        else a
        for a in config.axes
    ]
    config = config.model_copy(update={"axes": axes})
    async with (
        Runtime(config, clock="stepped", http_port=0) as rt,
        httpx.AsyncClient(base_url=rt.http_url, timeout=10) as c,
    ):
        x1 = next(i for i, a in enumerate(config.axes) if a.name == "X1")
        x2 = next(i for i, a in enumerate(config.axes) if a.name == "X2")
        await c.post("/api/channels/2/program", content="N10 G01 X1=10 F6000\nN20 M30\n")
        await c.post("/api/channels/2/start")
        await step(c, 1)
        assert (await c.get("/api/alarms")).json()["history"][-1]["id"] == 911020
        assert await image_value(c, "gpCh[1]^bahn_state.program_state_r") == ProgramState.IDLE
        active = f"gpAx[{x2}]^dyn_coll_mon.active"
        assert await image_value(c, active) is False
        r = await c.post("/api/axes/X1/reference")
        assert r.status_code == 202, r.text
        await step(c, 1)
        assert await image_value(c, f"gpAx[{x1}]^ipo_state.referencing_r") is True
        await c.put(url_path(f"gpAx[{x2}]^manual.reference_w"), json={"value": True})
        seen: list[tuple[int, bool, bool, bool]] = []

        def watch(cycle: int) -> None:
            m = rt.machine
            seen.append(
                (cycle, m.axis("X1").referenced, m.axis("X2").referenced, m.hli.axes[x2].dyn_coll_mon.active)
            )

        rt.on_cycle(watch)
        await step(c, 3000)
        both = next(cycle for cycle, r1, r2, _ in seen if r1 and r2)
        first_active = next(cycle for cycle, _, _, on in seen if on)
        assert first_active == both  # monitoring starts in the cycle both are referenced (C3-06)
        assert all(not on for cycle, _, _, on in seen if cycle < both)
        assert await image_value(c, f"gpAx[{x1}]^ipo_state.referenced_r") is True
        events = (await c.get("/api/events")).json()["events"]
        refs = [(e["data"]["axis"], e["data"]["state"]) for e in events if e["kind"] == "reference"]
        assert sorted(refs) == sorted(
            [("X1", "referencing"), ("X1", "referenced"), ("X2", "referencing"), ("X2", "referenced")]
        )
        await c.post("/api/channels/2/start")
        await step(c, 2)
        assert await image_value(c, "gpCh[1]^bahn_state.program_state_r") == ProgramState.RUNNING


async def test_openapi_says_what_the_state_routes_answer(client: httpx.AsyncClient) -> None:
    """The typed seam (schemas/results.py): each route's answer is a named schema in the OpenAPI description,
    with its fields, and the answer served has them."""
    spec = (await client.get("/openapi.json")).json()
    schemas = spec["components"]["schemas"]

    def answer(path: str, method: str = "get") -> dict[str, Any]:
        ok: dict[str, Any] = spec["paths"][path][method]["responses"]["200"]["content"]["application/json"]
        return ok["schema"]

    for path, method, name in (
        ("/api/state", "get", "MachineState"),
        ("/api/alarms", "get", "AlarmList"),
        ("/api/axes/{name}/faults", "get", "AxisFaults"),
        ("/api/axes/{name}/faults", "post", "AxisFaults"),
        ("/api/axes/{name}/soft-limits", "get", "SoftLimits"),
        ("/api/channels/{number}/areas", "get", "AreaTable"),
        ("/api/channels/{number}/scene", "get", "Scene"),
        ("/api/channels/{number}/program", "post", "ProgramLoaded"),
        ("/api/axes/{name}/soft-limits", "put", "SoftLimits"),
    ):
        assert answer(path, method)["$ref"].endswith("/" + name), (path, method)
    assert answer("/api/collision-pairs")["items"]["$ref"].endswith("/CollisionPair")
    assert answer("/api/channels/{number}/programs")["items"]["$ref"].endswith("/ProgramEntry")
    state = schemas["MachineState"]
    assert {"cycle", "time_s", "channels", "axes", "alarms"} <= set(state["required"])
    assert {"external", "clock"} <= set(state["properties"])
    assert set(schemas["AlarmJson"]["properties"]) >= {"id", "severity", "message", "line", "block", "axis"}
    served = (await client.get("/api/state")).json()
    assert set(state["properties"]) <= set(served)  # nothing declared is missing, nothing served is dropped
    assert set(served["axes"]["X"]) == set(schemas["AxisState"]["properties"])
    faults = (await client.get("/api/axes/X/faults")).json()
    assert set(faults) == set(schemas["AxisFaults"]["properties"])


async def test_openapi_says_what_the_timing_image_recording_and_fault_routes_answer(
    hli: Harness, client: httpx.AsyncClient, tmp_path: Path
) -> None:
    """The typed seam, the rest (schemas/results.py, schemas/layout.py): ``/api/timing``, ``/api/ready``, the
    image by ST path and its layout, the recorder's routes and the communication faults each name their
    answer's schema in the OpenAPI description, with its fields; the answers served have exactly those
    fields (none declared and missing, none served and dropped)."""
    hli.runtime.session.directory = tmp_path  # what --record-dir sets
    spec = (await client.get("/openapi.json")).json()
    schemas = spec["components"]["schemas"]

    def answer(path: str, method: str = "get", status: str = "200") -> dict[str, Any]:
        ok: dict[str, Any] = spec["paths"][path][method]["responses"][status]["content"]["application/json"]
        return ok["schema"]

    def fields(name: str) -> set[str]:
        return set(schemas[name]["properties"])

    def required(name: str) -> set[str]:
        return set(schemas[name].get("required", ()))

    for path, method, status, name in (
        ("/api/timing", "get", "200", "Timing"),
        ("/api/ready", "get", "200", "ReadinessJson"),
        ("/api/ready", "get", "503", "ReadinessJson"),
        ("/api/layout", "get", "200", "LayoutJson"),
        ("/api/image/{st_path}", "get", "200", "ImageField"),
        ("/api/image/{st_path}", "put", "200", "ImageField"),
        ("/api/recording", "get", "200", "RecorderStatus"),
        ("/api/recording/start", "post", "201", "RecorderStatus"),
        ("/api/recording/stop", "post", "200", "RecorderStatus"),
        ("/api/comm/faults", "get", "200", "CommFaultTable"),
        ("/api/comm/faults", "post", "201", "CommFault"),
        ("/api/comm/faults/{fault_id}", "delete", "200", "CommFault"),
        ("/api/comm/faults", "delete", "200", "CommFaultsEnded"),
    ):
        assert answer(path, method, status)["$ref"].endswith("/" + name), (path, method, status)
    assert answer("/api/recordings")["items"]["$ref"].endswith("/RecordingFile")

    hli.step(5)
    timing = (await client.get("/api/timing")).json()
    assert set(timing) == fields("Timing") == required("Timing")
    assert fields("Timing") >= {"lateness_us", "worst", "late_causes", "failed_cycles", "rate"}
    assert fields("SlowCycleJson") == {"cycle", "lateness_us", "cause", "detail", "parts_us", "at_s"}
    assert fields("Lateness") == {"p50", "p99", "p999", "max"}
    ready = await client.get("/api/ready")
    assert set(ready.json()) == fields("ReadinessJson") == {"ready", "state", "doors", "waiting_for", "ports"}

    layout = (await client.get("/api/layout")).json()
    assert set(layout) == fields("LayoutJson")
    assert set(layout["signals"][0]) == fields("LayoutSignal")
    assert set(layout["channels"][0]) == fields("LayoutChannel")
    assert set(layout["axes"][0]) == fields("LayoutAxis")
    path = "gpCh[0]^bahn_mc_control.override.command_w"
    read = (await client.get(f"/api/image/{path}")).json()
    assert set(read) == fields("ImageField") - {"effective_cycle"} == required("ImageField")
    written = (await client.put(f"/api/image/{path}", json={"value": 500})).json()
    assert set(written) == fields("ImageField")
    assert written["value"] == 500
    assert isinstance(written["value"], int)

    status = (await client.get("/api/recording")).json()
    assert set(status) == fields("RecorderStatus") == required("RecorderStatus")
    started = await client.post("/api/recording/start", json={"name": "typed"})
    assert started.status_code == 201, started.text
    hli.step(3)
    assert set((await client.post("/api/recording/stop")).json()) == fields("RecorderStatus")
    listed = (await client.get("/api/recordings")).json()
    assert [set(entry) for entry in listed] == [fields("RecordingFile")]

    fault = await client.post(
        "/api/comm/faults", json={"kind": "delay", "door": "modbus", "delay_ms": 5, "count": 3}
    )
    assert fault.status_code == 201, fault.text
    body = fault.json()
    assert required("CommFault") <= set(body) <= fields("CommFault")
    assert body["delay_ms"] == 5
    assert "code" not in body
    assert set(schemas["CommFault"]["properties"]["kind"]["enum"]) == {
        "delay",
        "drop",
        "error",
        "stall",
        "disconnect",
    }
    table = (await client.get("/api/comm/faults")).json()
    assert set(table) == fields("CommFaultTable")
    assert [entry["id"] for entry in table["faults"]] == [body["id"]]
    assert required("CommFaultLogged") <= set(table["history"][-1]) <= fields("CommFaultLogged")
    ended = (await client.delete(f"/api/comm/faults/{body['id']}")).json()
    assert ended["id"] == body["id"]
    assert required("CommFault") <= set(ended)
    assert (await client.delete("/api/comm/faults")).json() == {"ended": 0}


MEASURE_SPIGOT = """
G53
G00 X50 Y20 Z10
#VAR
  V.CYC.SysRetX
  V.CYC.SysRetY
#ENDVAR
L CYCLE [NAME=SysMeasWcs39.ecy @P2=20 @P13=4 @P33=5]
#MSG ["spigot at X%.4f Y%.4f", V.CYC.SysRetX, V.CYC.SysRetY]
M30
"""


@pytest.mark.req("CY-04")
async def test_the_probe_deviation_through_the_api_moves_the_measured_spigot(
    hli: Harness, client: httpx.AsyncClient
) -> None:
    """docs/cycles.md: the simulated workpiece's deviation set through the HTTP API (0.1 µm) is what a
    built-in measuring cycle finds; the harness reads the same deviation (mm)."""
    r = await client.put("/api/channels/1/probe/deviation", json={"deviation": {"X": 2500, "Y": -1000}})
    assert r.status_code == 200, r.text
    assert r.json() == {"channel": 1, "deviation": {"X": 2500, "Y": -1000, "Z": 0}, "variables": {}}
    assert (await client.get("/api/channels/1/probe/deviation")).json()["deviation"]["X"] == 2500
    assert hli.probe_deviation() == {"X": 0.25, "Y": -0.1, "Z": 0.0}
    no_axis = await client.put("/api/channels/1/probe/deviation", json={"deviation": {"Q": 1}})
    assert no_axis.status_code == 404
    too_far = await client.put("/api/channels/1/probe/deviation", json={"deviation": {"X": 200_000_000}})
    assert too_far.status_code == 422
    assert (await client.put("/api/channels/1/probe/deviation", json={"deviation": {}})).status_code == 422
    r = await client.post(
        "/api/channels/1/program?name=spigot", content=MEASURE_SPIGOT, headers={"content-type": "text/plain"}
    )
    assert r.status_code == 200, r.text
    await client.post("/api/channels/1/start")
    for _ in range(200):
        await step(client, 1000)
        if (await client.get("/api/state")).json()["channels"][0]["program_state"] == ProgramState.FINISHED:
            break
    events = (await client.get("/api/events?limit=1000")).json()["events"]
    texts = [e["data"]["text"] for e in events if e["kind"] == "nc_message"]
    assert texts == ["spigot at X50.2500 Y19.9000"], [e for e in events if e["kind"] == "alarm"]
    assert any(e["kind"] == "measurement" for e in events)
