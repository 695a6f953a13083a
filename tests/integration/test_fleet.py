"""A fleet of CNCs driven by the pytest plugin (issue 37, item 6): ``pytest --hli-url``.

Three ``hli-server run --clock stepped`` processes stand for the fleet's pods (deploy/kubernetes runs the
same command). A user's suite runs in a pytest of its own (pytester, a new process) against them: under
pytest-xdist each worker drives a CNC of its own, which the servers' own event logs prove (every program a
test loads is named after its worker, and each server saw one worker's programs only); a test never meets
what the test before it left on its CNC (the machine is restarted at the start of every test); the docs'
complete test passes against a remote CNC through its Modbus and ADS doors.
"""

from __future__ import annotations

import json
import subprocess
import urllib.request
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from hli_server.adapters.host import ConflictError
from hli_server.testing import ConditionNotMetError, Harness, HarnessError, unavailable
from hli_server.testing.remote import RemoteHarness, worker_url
from tests.doc_blocks import DOCS, marked_block
from tests.integration.servers import read_banner, start_server, stop_server

pytestmark = [pytest.mark.req("H-12"), pytest.mark.slow]

X = "gpAx[0]^ipo_state.cmd_pos_r"
OVERRIDE = "gpCh[0]^bahn_mc_control.override.command_w"


@pytest.fixture(scope="module")
def fleet() -> Iterator[list[str]]:
    """Three CNCs in processes of their own, on free ports of the loopback: their HTTP URLs."""
    procs: list[subprocess.Popen[str]] = []
    try:
        doors = ("--http-port", "0", "--modbus-port", "0", "--ads-port", "0")
        for _ in range(3):
            procs.append(start_server("--clock", "stepped", *doors))
        yield [read_banner(p, timeout=90)["url"] for p in procs]
    finally:
        for p in procs:
            stop_server(p)


def programs_loaded(url: str) -> list[str]:
    """The names of the programs loaded into the CNC at ``url``, from its own event log."""
    with urllib.request.urlopen(f"{url}/api/events?since=0&limit=10000", timeout=10) as response:
        events = json.loads(response.read())["events"]
    loads = [e for e in events if e["kind"] == "program_state" and e["data"]["cause"] == "load"]
    return [e["data"]["program"] for e in loads]


WORKER_SUITE = """
import os

import pytest


@pytest.mark.parametrize("k", range(6))
def test_a_move(hli, k):
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    assert hli.cycle == 0  # restarted for this test
    hli.load_program(1, "N10 G01 X5 F60000\\nN20 M30\\n", name=f"{worker}-{k}")
    hli.operator.start(1)
    hli.run_until(lambda: hli.image["gpCh[0]^bahn_state.program_state_r"] == 4, max_cycles=2000)
    assert hli.image["gpAx[0]^ipo_state.cmd_pos_r"] == 50_000
"""


def test_each_xdist_worker_drives_a_cnc_of_its_own(pytester: pytest.Pytester, fleet: list[str]) -> None:
    before = {url: len(programs_loaded(url)) for url in fleet}
    pytester.makepyfile(test_workers=WORKER_SUITE)
    args = [a for url in fleet for a in ("--hli-url", url)]
    result = pytester.runpytest_subprocess("-n", "2", "-p", "no:cacheprovider", "-p", "no:randomly", *args)
    result.assert_outcomes(passed=6)
    seen = {url: programs_loaded(url)[before[url] :] for url in fleet}
    workers = {url: {name.split("-")[0] for name in names} for url, names in seen.items()}
    assert workers[fleet[0]] == {"gw0"}, seen  # worker gwN takes the N-th CNC
    assert workers[fleet[1]] == {"gw1"}, seen
    assert not seen[fleet[2]], seen  # a third CNC for two workers: nobody's
    assert sum(len(names) for names in seen.values()) == 6


def test_more_workers_than_cncs_is_refused_and_a_pattern_numbers_them() -> None:
    assert worker_url(["http://cnc-{n}.cnc:8080"], "gw7") == "http://cnc-7.cnc:8080"
    assert worker_url(["http://a:1", "http://b:2"], None) == "http://a:1"
    assert worker_url(["http://a:1", "http://b:2"], "gw1") == "http://b:2"
    with pytest.raises(ValueError, match="worker gw2 has no CNC of its own"):
        worker_url(["http://a:1", "http://b:2"], "gw2")


LEAK_SUITE = """
import pytest

X = "gpAx[0]^ipo_state.cmd_pos_r"
OVERRIDE = "gpCh[0]^bahn_mc_control.override.command_w"


def test_1_leaves_a_mess(hli):
    hli.load_program(1, "N10 G01 X50 F60000\\nN20 G01 X80\\nN30 M30\\n", files={"UP1.NC": "N10 M17\\n"})
    hli.operator.start(1)
    hli.run_until(lambda: hli.image[X] >= 500_000, max_cycles=3000)
    hli.image[OVERRIDE] = 300
    hli.operator.set_soft_limits("Y", swe_pos=1_000)
    hli.operator.inject_faults("Z", friction=0.5, drive_error=True)
    hli.comm_faults.add(kind="delay", door="modbus", delay_ms=5, duration_ms=600_000)
    hli.step(3)
    state = hli.operator.snapshot()
    assert state["channels"][0]["program_state_name"] == "aborted"  # the drive error stopped it
    assert state["alarms"]


def test_2_finds_the_machine_as_the_file_starts_it(hli):
    assert hli.cycle == 0
    assert hli.image[X] == 0
    assert hli.image[OVERRIDE] == 0
    state = hli.operator.snapshot()
    assert state["channels"][0]["program_state_name"] == "idle"
    assert state["channels"][0]["program"] == ""
    assert state["alarms"] == []
    limits = hli.operator.soft_limits("Y")
    assert limits["in_effect"] == limits["record"]
    faults = hli.operator.faults("Z")
    assert (faults["friction"], faults["drive_error"]) == (0.0, False)
    assert hli.comm_faults.table() == []
    hli.step(5)
    assert hli.image[X] == 0  # nothing moves: no program was left running
"""


def test_a_test_never_meets_what_the_test_before_it_left(pytester: pytest.Pytester, fleet: list[str]) -> None:
    pytester.makepyfile(test_leak=LEAK_SUITE)
    result = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", "-p", "no:randomly", "--hli-url", fleet[2]
    )
    result.assert_outcomes(passed=2)


def test_the_complete_test_of_the_docs_passes_against_a_remote_cnc(
    pytester: pytest.Pytester, fleet: list[str]
) -> None:
    """The same test file as in-process: the network doors run, the shared-memory one is skipped (the
    image is in the CNC's memory), saying so."""
    source = marked_block(DOCS / "testing.md", "doc-run: session=plugin file=test_my_plc.py")
    pytester.makepyfile(test_my_plc=source)
    result = pytester.runpytest_subprocess("-v", "-rs", "-p", "no:cacheprovider", "--hli-url", fleet[2])
    network = [d for d in ("modbus", "ads") if unavailable(d) is None]
    result.assert_outcomes(passed=len(network), skipped=3 - len(network))
    result.stdout.fnmatch_lines(["*the shm door: the CNC at http://127.0.0.1:* is remote*"])
    for door in network:
        result.stdout.fnmatch_lines([f"*test_the_limit_holds_x_at_50_mm?{door}? PASSED*"])


def test_the_remote_harness_traces_reports_and_raises_as_the_in_process_one(fleet: list[str]) -> None:
    with RemoteHarness(fleet[2]) as hli:
        hli.load_program(1, "N10 G01 X10 F60000\nN20 M30\n")
        hli.operator.start(1)
        with hli.trace(X, "gpCh[0]^bahn_state.program_state_r") as recording:
            hli.step(20)
            ran = hli.run_until(lambda: hli.image[X] >= 100_000, max_cycles=2000)
        trace = recording.trace()
        assert trace.cycles == list(range(1, 21 + ran))  # every cycle, the long step's and the single ones
        assert trace[X][-1] == 100_000
        assert (trace[X][1:] >= trace[X][:-1]).all()
        with pytest.raises(ConflictError):  # a program runs (the same error as in-process)
            hli.operator.load_program(1, "N10 M30\n")
        with pytest.raises(ConditionNotMetError) as failed:
            hli.run_until(lambda: hli.image[X] < 0, max_cycles=30, show=["gpAx[1]^ipo_state.cmd_pos_r"])
        report = str(failed.value)
        assert "condition not met within 30 cycles" in report
        assert "gpAx[1]^ipo_state.cmd_pos_r" in report
        assert hli.image.snapshot()["cycle"] == hli.cycle


def test_a_server_on_the_realtime_clock_is_refused_with_the_reason() -> None:
    """The harness steps its CNC: a CNC on the realtime clock is refused, and so is its restart."""
    proc = start_server("--clock", "realtime", "--http-port", "0", "--no-modbus")
    try:
        url = read_banner(proc, timeout=90)["url"]
        with pytest.raises(HarnessError, match=r"runs the realtime clock.*--clock stepped"):
            RemoteHarness(url, timeout_s=20).start()
        refused = httpx.post(f"{url}/api/machine/restart")
        assert refused.status_code == 409
        assert "needs the stepped clock" in refused.json()["detail"]
    finally:
        stop_server(proc)


# --------------------------------------------------------------------------------------------
# POST /api/machine/restart, in-process
# --------------------------------------------------------------------------------------------


def test_a_restart_powers_the_machine_off_and_on_between_two_steps() -> None:
    with Harness(adapters=["http"]) as hli, httpx.Client(base_url=hli.http_url) as client:
        hli.load_program(1, "N10 G01 X50 F60000\nN20 M30\n", files={"UP1.NC": "N10 M17\n"})
        hli.operator.start(1)
        hli.run_until(lambda: hli.image[X] >= 500_000, max_cycles=3000)
        hli.image[OVERRIDE] = 250
        hli.comm_faults.add(kind="delay", door="modbus", delay_ms=5, duration_ms=600_000)
        old = hli.runtime.machine
        answer = client.post("/api/machine/restart")
        assert answer.status_code == 200, answer.text
        assert answer.json() == {"cycle": 0, "time_s": 0.0}
        assert hli.runtime.machine is not old
        assert hli.cycle == 0
        assert hli.image[X] == 0
        assert hli.image[OVERRIDE] == 0
        assert hli.comm_faults.table() == []
        assert hli.runtime.programs.uploads(1) == {}
        assert hli.runtime.session.journal_bytes == 0
        state: dict[str, Any] = client.get("/api/state").json()
        assert state["cycle"] == 0
        assert state["channels"][0]["program"] == ""
        hli.step(10)  # the new machine runs, its events reach the log
        hli.load_program(1, "N10 G01 X1 F6000\nN20 M30\n", name="after")
        events = client.get("/api/events", params={"since": 0}).json()["events"]
        assert [e["data"]["program"] for e in events if e["kind"] == "program_state"][-1] == "after"


def test_a_restart_is_refused_while_recording(tmp_path: Any) -> None:
    with Harness(adapters=["http"]) as hli, httpx.Client(base_url=hli.http_url) as client:
        with hli.record(tmp_path / "r.jsonl.gz"):
            refused = client.post("/api/machine/restart")
            assert refused.status_code == 409
            assert "a recording runs" in refused.json()["detail"]
        assert client.post("/api/machine/restart").status_code == 200


def test_a_recording_made_after_a_restart_replays(tmp_path: Any) -> None:
    """The input journal begins anew with the new machine: a recording started later replays from the new
    machine's first cycle and passes (one that carried the old machine's inputs would not)."""
    with Harness(adapters=["http"]) as hli, httpx.Client(base_url=hli.http_url) as client:
        hli.load_program(1, "N10 G01 X30 F60000\nN20 M30\n")
        hli.operator.start(1)
        hli.step(200)
        hli.image[OVERRIDE] = 500
        hli.step(10)
        assert client.post("/api/machine/restart").status_code == 200
        hli.load_program(1, "N10 G01 Y20 F30000\nN20 G01 X-10\nN30 M30\n")
        hli.operator.start(1)
        hli.step(50)
        with hli.record(tmp_path / "after.jsonl.gz", outputs_every=1):
            hli.step(400)
        assert hli.replay(tmp_path / "after.jsonl.gz").verdict.name == "PASS"
