"""Checking a program offline through every door that offers it (issue 20, N-10): ``POST /api/check`` over
a real socket (in process, and in ``hli-server run``'s doors process), the pytest plugin's ``hli.check``,
against ``hli-server check``: one engine ``ProgramCheck``, the same report."""

from __future__ import annotations

import json
import random
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from click.testing import CliRunner

from hli_server.cli import main as cli
from hli_server.testing import Harness
from schemas.wire import ProgramState
from tests import fuzz
from tests.integration.servers import http_step, read_banner, start_server, stop_server

HERE = Path(__file__).parent
DRILL = (HERE / "programs_for_the_check" / "DRILL.NC").read_text(encoding="utf-8")
MAIN = """\
%holes
N10 G90 G17 G00 X0 Y0 Z2
#VAR
  V.P.ROWS = 2
#ENDVAR
N20 $FOR P1 = 1, V.P.ROWS
N30   L CYCLE [NAME=DRILL.NC @P1=3 @P2=5 @P3=1.5]
N40   #MSG ["row %d done", P1]
N50 $ENDFOR
N60 M30
"""
BEYOND = "N10 G01 X100 Y50 F6000\nN20 G01 X100 Y800\nN30 M30\n"
ENDLESS = "N10 G01 X1 F6000\nN20 $WHILE 1\nN30 G91 X1\nN40 X-1\nN50 $ENDWHILE\nN60 M30\n"


@pytest.fixture
async def client(hli: Harness) -> AsyncIterator[httpx.AsyncClient]:
    async with httpx.AsyncClient(base_url=hli.http_url, timeout=120) as c:
        yield c


def _without_time(report: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in report.items() if k not in {"elapsed_s", "program", "status", "exit_code"}}


def _cli_report(tmp_path: Path, text: str, *args: str, files: dict[str, str] | None = None) -> dict[str, Any]:
    program = tmp_path / "holes.nc"
    program.write_text(text, encoding="utf-8")
    for name, body in (files or {}).items():
        (tmp_path / name).write_text(body, encoding="utf-8")
    done = CliRunner().invoke(cli, ["check", "--format", "json", *args, str(program)])
    assert done.exit_code in (0, 1, 3), done.output
    report: dict[str, Any] = json.loads(done.stdout)
    return report


@pytest.mark.slow
@pytest.mark.req("N-10", "N-02", "N-06")
async def test_the_api_checks_a_program_with_its_cycle_as_check_does(
    hli: Harness, client: httpx.AsyncClient, tmp_path: Path
) -> None:
    r = await client.post("/api/check", json={"text": MAIN, "name": "holes.nc", "files": {"DRILL.NC": DRILL}})
    assert r.status_code == 200, r.text
    report = r.json()
    assert (report["program"], report["status"], report["exit_code"]) == ("holes.nc", "ok", 0)
    assert report["completed"] is True
    assert report["alarms"] == []
    assert [m["text"] for m in report["messages"]] == ["row 1 done", "row 2 done"]
    assert report["final_position"]["X"] == 10.0
    assert report["final_position"]["Z"] == 2.0
    # the same report as `hli-server check` (the engine's one ProgramCheck), but for the wall-clock time
    cli_report = _cli_report(tmp_path, MAIN, files={"DRILL.NC": DRILL})
    assert _without_time(report) == _without_time(cli_report)
    # the running machine was not touched
    state = (await client.get("/api/state")).json()
    assert state["cycle"] == 0
    assert state["channels"][0]["program_state"] == ProgramState.IDLE


@pytest.mark.slow
@pytest.mark.req("N-10")
async def test_a_text_body_with_query_parameters_and_an_error_alarm(
    client: httpx.AsyncClient, tmp_path: Path
) -> None:
    for geometry in (False, True):
        r = await client.post(
            f"/api/check?name=beyond.nc&geometry_only={str(geometry).lower()}",
            content=BEYOND,
            headers={"content-type": "text/plain"},
        )
        assert r.status_code == 200, r.text
        report = r.json()
        assert (report["status"], report["exit_code"], report["completed"]) == ("stopped", 1, False)
        assert report["mode"] == ("geometry" if geometry else "full")
        errors = [a for a in report["alarms"] if a["severity"] == "error"]
        assert errors, report
        assert (errors[0]["line"], errors[0]["block"]) == (2, "N20")
        args = ("--geometry-only",) if geometry else ()
        assert _without_time(report) == _without_time(_cli_report(tmp_path, BEYOND, *args))


@pytest.mark.slow
@pytest.mark.req("N-10", "N-08")
async def test_an_endless_loop_stops_at_its_cap_with_status_capped(client: httpx.AsyncClient) -> None:
    r = await client.post("/api/check", json={"text": ENDLESS, "max_cycles": 3000})
    assert r.status_code == 200, r.text
    report = r.json()
    assert (report["status"], report["exit_code"]) == ("capped", 3)
    assert report["capped"] == {"by": "cycles", "cap": 3000}
    assert report["cycles"] == 3000
    assert [a["id"] for a in report["alarms"]] == [914050]
    r = await client.post("/api/check", json={"text": ENDLESS, "geometry_only": True, "max_iterations": 500})
    report = r.json()
    assert (report["status"], report["capped"]) == ("capped", {"by": "iterations", "cap": 500})
    assert [a["id"] for a in report["alarms"]] == [914051]


@pytest.mark.slow
@pytest.mark.req("N-10")
async def test_bad_requests_are_refused_with_a_reason_and_the_next_is_served(
    client: httpx.AsyncClient,
) -> None:
    r = await client.post("/api/check", json={"text": MAIN, "channel": 9})
    assert r.status_code == 404
    assert "no channel 9" in r.json()["detail"]
    r = await client.post("/api/check", json={"text": MAIN, "files": {"../DRILL.NC": DRILL}})
    assert r.status_code == 422
    assert ".." in r.json()["detail"]
    r = await client.post("/api/check", content="  \n", headers={"content-type": "text/plain"})
    assert r.status_code == 422
    r = await client.post("/api/check", json={"text": MAIN, "max_cycles": 0})
    assert r.status_code == 422
    r = await client.post("/api/check", json={"text": MAIN, "unknown": 1})
    assert r.status_code == 422
    # a missing subprogram is the program's alarm, not a refused request: it names what was searched
    r = await client.post("/api/check", json={"text": MAIN})
    assert r.status_code == 200
    report = r.json()
    assert report["status"] == "stopped"
    missing = report["alarms"][0]
    assert missing["id"] == 914010
    assert "DRILL.NC" in missing["message"]
    r = await client.post("/api/check", json={"text": MAIN, "files": {"DRILL.NC": DRILL}})
    assert r.json()["status"] == "ok"


@pytest.mark.slow
@pytest.mark.req("N-10", "N-08")
async def test_a_check_past_its_wall_clock_limit_is_ended_and_the_checker_serves_on(
    hli: Harness, client: httpx.AsyncClient
) -> None:
    r = await client.post("/api/check", json={"text": MAIN, "files": {"DRILL.NC": DRILL}})
    assert r.status_code == 200
    first = hli.runtime.checker.worker_pid
    assert first is not None
    r = await client.post("/api/check", json={"text": ENDLESS, "max_cycles": 50_000_000, "timeout_s": 1})
    assert r.status_code == 504, r.text
    assert "did not finish in 1 s" in r.json()["detail"]
    assert hli.runtime.checker.worker_pid is None  # ended
    r = await client.post("/api/check", json={"text": MAIN, "files": {"DRILL.NC": DRILL}})
    assert r.status_code == 200
    assert r.json()["status"] == "ok"
    assert hli.runtime.checker.worker_pid not in (None, first)


@pytest.mark.req("N-10")
async def test_the_api_documents_the_check_and_its_typed_report(client: httpx.AsyncClient) -> None:
    spec = (await client.get("/openapi.json")).json()
    post = spec["paths"]["/api/check"]["post"]
    assert set(post["requestBody"]["content"]) == {"application/json", "text/plain"}
    ref = post["responses"]["200"]["content"]["application/json"]["schema"]["$ref"]
    assert ref.endswith("/CheckReport")
    report = spec["components"]["schemas"]["CheckReport"]
    assert {"status", "exit_code", "alarms", "messages", "capped", "final_position"} <= set(
        report["properties"]
    )


# --- the pytest plugin ------------------------------------------------------------------------------------
@pytest.mark.req("N-10", "N-02")
@pytest.mark.hli(program_dirs="programs_for_the_check")
def test_the_plugin_checks_with_the_program_directories_of_the_test(hli: Harness, tmp_path: Path) -> None:
    result = hli.check(MAIN, name="holes.nc")  # DRILL.NC from the marker's directory
    assert result.completed, [a.message for a in result.alarms]
    assert [m.text for m in result.messages] == ["row 1 done", "row 2 done"]
    assert result.final_position["X"] == pytest.approx(10.0)
    assert hli.cycle == 0  # the harness' machine did not run
    assert _without_time(result.to_json()) == _without_time(
        _cli_report(tmp_path, MAIN, files={"DRILL.NC": DRILL})
    )
    stopped = hli.check(BEYOND, geometry_only=True)
    assert stopped.stopped_by_error
    assert [(a.line, a.block) for a in stopped.alarms if a.severity == "error"][:1] == [(2, "N20")]
    capped = hli.check(ENDLESS, max_cycles=2000)
    assert (capped.capped, capped.cap) == ("cycles", 2000)


@pytest.mark.req("N-10")
def test_the_plugin_checks_a_program_file_with_its_neighbours(hli: Harness, tmp_path: Path) -> None:
    (tmp_path / "DRILL.NC").write_text(DRILL, encoding="utf-8")
    main = tmp_path / "holes.nc"
    main.write_text(MAIN, encoding="utf-8")
    result = hli.check(main)
    assert result.completed
    assert result.to_json()["blocks"] > 0
    with pytest.raises(Exception, match="no channel 7"):
        hli.check(main, channel=7)


# --- the PLC's inputs: presets, and a program that waits on them (N-13) ------------------------------------
WAITS = (
    "N10 G90 G00 X0 Y0 Z0\nN20 $WHILE V.E.PLC_READY == 0\nN30 $ENDWHILE\n"
    "N40 $IF V.E.MODE == 2\nN50 G01 X20 F6000\nN60 $ELSE\nN70 G01 X10 F6000\nN80 $ENDIF\nN90 M30\n"
)


@pytest.mark.slow
@pytest.mark.req("N-13", "N-10")
async def test_presets_through_every_door_give_the_same_report(
    hli: Harness, client: httpx.AsyncClient, tmp_path: Path
) -> None:
    # without the PLC's values the program waits: stopped within seconds, naming the variable
    r = await client.post("/api/check", json={"text": WAITS})
    report = r.json()
    assert (report["status"], report["exit_code"], report["capped"]["by"]) == ("capped", 3, "waiting")
    (alarm,) = report["alarms"]
    assert (alarm["id"], alarm["line"], alarm["block"]) == (914052, 2, "N20")
    assert "V.E.PLC_READY" in alarm["message"]
    waiting = hli.check(WAITS)
    assert waiting.capped == "waiting"
    # with them it runs, the same through JSON, a text body with ?set=, the plugin and the command
    presets = {"V.E.PLC_READY": True, "V.E.MODE": 2}
    r = await client.post("/api/check", json={"text": WAITS, "presets": presets})
    json_report = r.json()
    assert (json_report["status"], json_report["final_position"]["X"]) == ("ok", 20.0)
    r = await client.post(
        "/api/check?set=V.E.PLC_READY=TRUE&set=V.E.MODE=2",
        content=WAITS,
        headers={"content-type": "text/plain"},
    )
    assert _without_time(r.json()) == _without_time(json_report)
    plugin = hli.check(WAITS, presets=presets)
    assert _without_time(plugin.to_json()) == _without_time(json_report)
    cli = _cli_report(tmp_path, WAITS, "--set", "V.E.PLC_READY=TRUE", "--set", "V.E.MODE=2")
    assert _without_time(cli) == _without_time(json_report)
    # a preset that cannot be taken is a refused request, and the next is served
    r = await client.post("/api/check", json={"text": WAITS, "presets": {"V.E.NOPE": 1}})
    assert r.status_code == 422
    assert "V.E.NOPE is not declared" in r.json()["detail"]
    r = await client.post("/api/check?set=V.E.MODE", content=WAITS, headers={"content-type": "text/plain"})
    assert r.status_code == 422
    r = await client.post("/api/check", json={"text": WAITS, "presets": {"V.E.MODE": [1]}})
    assert r.status_code == 422
    with pytest.raises(Exception, match=r"V\.E\.NOPE is not declared"):
        hli.check(WAITS, presets={"V.E.NOPE": 1})
    assert hli.check(WAITS, presets=presets).completed


@pytest.mark.req("N-12")
async def test_a_windows_1252_program_is_read_by_every_door(
    hli: Harness, client: httpx.AsyncClient, tmp_path: Path
) -> None:
    text = "%umlaut\n; Prüfung: Fräsen – 5 €\nN10 G01 X10 F6000\nN20 M30\n"
    (tmp_path / "UMLAUT.NC").write_bytes(text.encode("cp1252"))
    assert hli.check(tmp_path / "umlaut.nc").completed  # the name without regard to case, the bytes as cp1252
    r = await client.post("/api/check", content=text.encode("cp1252"), headers={"content-type": "text/plain"})
    assert r.json()["status"] == "ok"
    r = await client.post(
        "/api/channels/1/program?name=umlaut",
        content=b"\xef\xbb\xbf" + text.encode("utf-8"),
        headers={"content-type": "text/plain"},
    )
    assert r.status_code == 200, r.text


# --- through `hli-server run`: the doors process ----------------------------------------------------------
@pytest.mark.slow
@pytest.mark.req("N-10")
def test_hli_server_run_checks_in_its_doors_process(tmp_path: Path) -> None:
    (tmp_path / "DRILL.NC").write_text(DRILL, encoding="utf-8")
    proc = start_server("--clock", "stepped", "--http-port", "0", "--program-dir", str(tmp_path))
    try:
        url = read_banner(proc)["url"]
        with httpx.Client(base_url=url, timeout=120) as client:
            r = client.post("/api/check", json={"text": MAIN, "name": "holes"})
            assert r.status_code == 200, r.text
            assert r.json()["status"] == "ok"
            assert [m["text"] for m in r.json()["messages"]] == ["row 1 done", "row 2 done"]
            assert client.get("/api/state").json()["cycle"] == 0
    finally:
        stop_server(proc)


@pytest.mark.slow
# --- bad input: the server is never hung -------------------------------------------------------------------
@pytest.mark.req("N-08")
async def test_a_while_without_motion_does_not_hang_the_server(client: httpx.AsyncClient) -> None:
    text = "N10 P1 = 0\nN20 $WHILE 1\nN30 P1 = P1 + 1\nN40 $ENDWHILE\nN50 M30\n"
    r = await client.post(
        "/api/channels/1/program?name=spin", content=text, headers={"content-type": "text/plain"}
    )
    assert r.status_code == 200, r.text
    assert (await client.post("/api/channels/1/start")).status_code == 202
    assert (await http_step(client, 300))["cycle"] == 300  # every cycle came back, 128 statements each
    state = (await client.get("/api/state")).json()
    assert state["channels"][0]["program_state"] == ProgramState.RUNNING
    assert (await client.post("/api/channels/1/reset")).status_code == 202
    await http_step(client, 5)
    state = (await client.get("/api/state")).json()
    assert state["channels"][0]["program_state"] != ProgramState.RUNNING
    # and a check of the same program stops at its cap, the server answering meanwhile
    r = await client.post("/api/check", json={"text": text, "max_cycles": 1000})
    assert (r.json()["status"], r.json()["capped"]) == ("capped", {"by": "cycles", "cap": 1000})


@pytest.mark.slow
@pytest.mark.fuzz
@pytest.mark.req("N-08", "N-10")
async def test_fuzz_the_check_endpoint_answers_every_request(client: httpx.AsyncClient) -> None:
    """Bounded and seeded: random language programs, mutated lines and mutated request bodies; every
    answer is a report or a refusal with a reason, and the next request is served."""
    rng = random.Random(fuzz.seed_for("api-check"))
    statuses: dict[int, int] = {}
    for example in range(fuzz.count(30)):
        kind = example % 3
        if kind == 0:
            body: Any = {"text": fuzz.language_program(rng), "geometry_only": True, "max_iterations": 2000}
            r = await client.post("/api/check", json=body)
        elif kind == 1:
            lines = [fuzz.mutate(rng, fuzz.nc_line(rng)) for _ in range(rng.randint(1, 20))]
            body = {"text": "\n".join(lines) + "\n", "max_cycles": 20_000, "files": {"A.NC": "M17\n"}}
            r = await client.post("/api/check", json=body)
        else:
            raw = json.dumps({"text": MAIN, "max_cycles": 1000, "channel": 1})
            r = await client.post(
                "/api/check",
                content=fuzz.mutate(rng, raw).encode(),
                headers={"content-type": "application/json"},
            )
        statuses[r.status_code] = statuses.get(r.status_code, 0) + 1
        assert r.status_code in (200, 404, 422), (r.status_code, r.text, body if kind < 2 else "")
        if r.status_code == 200:
            report = r.json()
            assert report["status"] in ("ok", "stopped", "capped")
            assert all(isinstance(a["id"], int) and a["id"] > 0 for a in report["alarms"])
        else:
            assert r.json()["detail"]
    print(f"POST /api/check: {fuzz.count(30)} requests, answers {statuses}")
    r = await client.post("/api/check", json={"text": MAIN, "files": {"DRILL.NC": DRILL}})
    assert r.json()["status"] == "ok"
