"""Recording and replaying through the doors a user has (issue 25, B-02): the HTTP API (start, status,
stop, list, download), ``hli-server run --record`` killed with SIGKILL, and the ``record`` / ``replay``
commands with their exit statuses."""

from __future__ import annotations

import contextlib
import gzip
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from hli_server.recording.format import Records, read_records
from hli_server.testing import Harness
from tests.integration.servers import hli_server_cmd, read_banner, start_server, stop_server

pytestmark = pytest.mark.req("B-02")

PROGRAM = "N10 G01 X40 Y30 F12000\nN20 G01 X0 Y0\nN30 M30\n"


def cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*hli_server_cmd(), *args], capture_output=True, text=True, timeout=120, cwd=cwd, check=False
    )


@pytest.mark.hli(adapters=["http"])
def test_start_and_stop_a_recording_over_http_then_download_and_replay_it(
    hli: Harness, tmp_path: Path
) -> None:
    hli.runtime.session.directory = tmp_path  # what --record-dir sets
    url = hli.http_url
    with httpx.Client(base_url=url, timeout=10) as client:
        assert client.get("/api/recording").json()["recording"] is False
        hli.step(20)
        started = client.post("/api/recording/start", json={"name": "tuesday"})
        assert started.status_code == 201, started.text
        assert started.json()["started_cycle"] == 21
        assert client.post("/api/recording/start", json={}).status_code == 409  # one at a time
        assert client.post("/api/channels/1/program", json={"text": PROGRAM}).status_code in (200, 201)
        assert client.post("/api/channels/1/start").status_code == 202
        hli.step(1500)
        status = client.get("/api/recording").json()
        assert status["recording"] is True
        assert status["cycles"] == 1500
        assert status["name"] == "tuesday.jsonl.gz"
        stopped = client.post("/api/recording/stop")
        assert stopped.status_code == 200
        assert stopped.json()["recording"] is False
        assert client.post("/api/recording/stop").status_code == 409
        listed = client.get("/api/recordings").json()
        assert [r["name"] for r in listed] == ["tuesday.jsonl.gz"]
        download = client.get("/api/recordings/tuesday.jsonl.gz")
        assert download.status_code == 200
        assert download.headers["content-type"] == "application/gzip"
        assert client.get("/api/recordings/..%2Fetc%2Fpasswd").status_code == 404
        assert client.get("/api/recordings/nothing.jsonl.gz").status_code == 404
        assert client.post("/api/recording/start", json={"name": "../evil"}).status_code == 422
    saved = tmp_path / "copy.jsonl.gz"
    saved.write_bytes(download.content)
    ops = [r["op"] for r in read_records(saved) if "op" in r]
    assert ops == ["load_program", "start"]
    report = hli.replay(saved)  # the pytest plugin's one line
    assert report.window_start == 21
    assert report.last_cycle == 1520


def test_hli_replay_fails_readably_on_a_difference(hli: Harness, tmp_path: Path) -> None:
    path = tmp_path / "s.jsonl.gz"
    with hli.record(path):
        hli.operator.load_program(1, PROGRAM)
        hli.operator.start(1)
        hli.step(800)
    hli.replay(path)
    records = list(read_records(path))
    outputs = [e[0] for e in records[0]["outputs"]]
    for r in records:
        if "o" in r and r["c"] > 300:
            r["o"][1] = (
                r["o"][1] + 1 if isinstance(r["o"][1], int) and not isinstance(r["o"][1], bool) else r["o"][1]
            )
            forged_cycle, forged_signal = r["c"], outputs[r["o"][0]]
            break
    with gzip.open(path, "wt") as f:
        f.writelines(json.dumps(r) + "\n" for r in records)
    from hli_server.testing.harness import ReplayFailedError

    with pytest.raises(ReplayFailedError) as info:
        hli.replay(path)
    text = str(info.value)
    assert f"first difference: cycle {forged_cycle}" in text
    assert forged_signal in text
    assert "expected" in text
    assert "got" in text


@pytest.mark.slow
def test_a_killed_server_leaves_a_recording_that_replays_up_to_its_last_flush(tmp_path: Path) -> None:
    record = tmp_path / "killed.jsonl.gz"
    proc = start_server(
        "--http-port", "0", "--no-modbus", "--clock", "realtime", "--record", str(record),
        "--record-flush", "0.1",
    )  # fmt: skip
    try:
        banner = read_banner(proc)
        url = banner["url"]
        assert f"recording to {record}" in "".join(banner.values()) or record.exists()
        assert httpx.post(f"{url}/api/channels/1/program", json={"text": PROGRAM}).status_code in (200, 201)
        assert httpx.post(f"{url}/api/channels/1/start").status_code == 202
        time.sleep(1.5)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
        out = (proc.stdout.read() if proc.stdout else "") + (proc.stderr.read() if proc.stderr else "")
        for name in (
            line.split("shared memory image:")[1].split()[0] for line in out.splitlines() if "image:" in line
        ):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(f"/dev/shm/{name}")
        if "image" in locals().get("banner", {}):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(f"/dev/shm/{banner['image']}")
    info = Records()
    records = list(read_records(record, info))
    assert "end" not in records[-1]  # no clean end: the server was killed
    last = records[-1]["c"]
    assert last > 500
    shown = cli("record", "show", str(record))
    assert shown.returncode == 0, shown.stderr
    assert "NO END LINE" in shown.stdout
    assert "load_program" in shown.stdout
    replayed = cli("replay", str(record))
    assert replayed.returncode == 0, replayed.stdout + replayed.stderr
    assert "PASS" in replayed.stdout


LOOPING = "N10 $FOR P1 = 1, 100000\nN20 G01 X40 Y30 F12000\nN30 G01 X0 Y0\nN40 $ENDFOR\nN50 M30\n"
DRILLING = "G00 X0 Y0 Z50\nG01 F300\nL CYCLE [NAME=SysDrillCenterHole.ecy @P1=0 @P2=20 @P3=2 @P4=40]\nM30\n"
"""A built-in cycle's stand-in (a Python generator in the engine) at work for about 9 s from line 3."""


@pytest.mark.slow
@pytest.mark.req("E-01")
@pytest.mark.parametrize(("program", "line"), [(LOOPING, None), (DRILLING, 3)], ids=["loop", "cycle"])
def test_a_recording_started_from_the_api_in_a_running_server_replays_only_its_own_cycles(
    tmp_path: Path, program: str, line: int | None
) -> None:
    """Issue 37, item 2, as the issue found it: ``hli-server run`` (realtime clock, the doors in their own
    process) has run a while with a program when a recording is started through the API; the replay runs
    the recording's cycles from its snapshot, not the server's uptime, and says so. Also while a built-in
    cycle runs (its stand-in is rebuilt from the call and what it read, engine/channel.py StandInRun)."""
    proc = start_server(
        "--http-port", "0", "--no-modbus", "--clock", "realtime", "--record-dir", str(tmp_path)
    )
    try:
        url = read_banner(proc)["url"]
        assert httpx.post(f"{url}/api/channels/1/program", json={"text": program}).status_code in (200, 201)
        assert httpx.post(f"{url}/api/channels/1/start").status_code == 202
        deadline = time.monotonic() + 30
        while True:  # the server's uptime: 2 s of cycles, the program (the cycle) at work
            state = httpx.get(f"{url}/api/state").json()
            if state["cycle"] >= 2000 and (line is None or state["channels"][0]["line"] == line):
                break
            assert time.monotonic() < deadline, state["channels"][0]
            time.sleep(0.1)
        started = httpx.post(f"{url}/api/recording/start", json={"name": "late"})
        assert started.status_code == 201, started.text
        window = started.json()["started_cycle"]
        time.sleep(1.0)
        stopped = httpx.post(f"{url}/api/recording/stop").json()
    finally:
        stop_server(proc)
    recorded = stopped["cycles"]
    replayed = cli("replay", str(tmp_path / "late.jsonl.gz"), "--report", str(tmp_path / "r.json"))
    assert replayed.returncode == 0, replayed.stdout + replayed.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["started_from"] == "snapshot"
    assert report["first_cycle"] == window > 2000
    assert report["cycles_replayed"] == report["cycles_compared"] >= recorded - 1
    assert f"cycles replayed from the snapshot of cycle {window - 1:,}" in replayed.stdout


@pytest.mark.slow
def test_the_commands_replay_record_show_and_export(tmp_path: Path) -> None:
    record = tmp_path / "free.jsonl.gz"
    program = tmp_path / "part.nc"
    program.write_text(PROGRAM, encoding="utf-8")
    done = cli(
        "run", "--no-http", "--no-modbus", "--clock", "free", "--cycles", "3000", "--record", str(record),
        "--record-outputs-every", "10",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert f"recording to {record} from cycle 1" in done.stdout
    with gzip.open(record, "rt", encoding="ascii") as f:
        assert json.loads(f.readline())["outputs_every"] == 10
    shown = cli("record", "show", str(record), "--format", "json")
    assert shown.returncode == 0
    summary = json.loads(shown.stdout)
    assert summary["end"] == "server stopped"
    assert summary["last_cycle"] == 3000
    ok = cli("replay", str(record), "--until", "2.5s", "--report", str(tmp_path / "r.json"))
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert json.loads((tmp_path / "r.json").read_text())["last_cycle"] == 2500
    machines = Path(sys.modules["hli_server"].__file__).parent / "machines"  # type: ignore[arg-type]
    for lis in machines.glob("*.lis"):
        (tmp_path / lis.name).write_bytes(lis.read_bytes())
    other = tmp_path / "other.toml"
    other.write_text(
        (machines / "demo.toml").read_text(encoding="utf-8").replace('name = "demo"', 'name = "other"', 1),
        encoding="utf-8",
    )
    mismatch = cli("replay", str(record), "--config", str(other))
    assert mismatch.returncode == 3, mismatch.stdout + mismatch.stderr
    assert "configuration mismatch" in mismatch.stderr
    assert "name" in mismatch.stderr
    nothing = tmp_path / "nothing.jsonl.gz"
    nothing.write_bytes(gzip.compress(b'{"a": 1}\n'))
    assert cli("replay", str(nothing)).returncode == 3
    csv_out = cli("record", "export", str(record), "--csv", "-", "-s", "gpCh[0]^bahn_state.*")
    assert csv_out.returncode == 0
    assert csv_out.stdout.startswith("cycle,time_s,gpCh[0]^bahn_state.")
    vcd = tmp_path / "out.vcd"
    png = tmp_path / "out.pdf"
    exported = cli(
        "record", "export", str(record), "--vcd", str(vcd), "--plot", str(png),
        "-s", "gpCh[0]^bahn_state.*state_r", "-s", "gpCh[0]^bahn_state.*_id_r",
        "-s", "gpCh[0]^bahn_state.tcp_?_r",
    )  # fmt: skip
    assert exported.returncode == 0, exported.stderr
    assert "$enddefinitions" in vcd.read_text()
    assert png.read_bytes()[:4] == b"%PDF"
    assert cli("record", "export", str(record)).returncode == 2
