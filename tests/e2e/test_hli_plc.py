"""``hli-plc``: the demo PLC programs against a running ``hli-server run``, over any transport (H-06).

The demos are the worked examples of FCT-C43, FCT-C14 and FCT-C3 (``plc_clients.demos``); here they
run as docker-compose will run them: the console command in its own process, the server in another,
realtime clock, the operator's NC program loaded over the HTTP API.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from plc_clients.cli import main

pytestmark = pytest.mark.req("H-06")

HLI_PLC = str(Path(sys.executable).parent / "hli-plc")


def test_list_names_every_demo(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == ["c43-obstacle", "c14-manual", "c3-collision", "ve-mode"]
    assert "FCT-C43" in lines[0]
    assert main([]) == 2  # no demo: the list, and the usage exit code


def test_usage_errors_exit_2_with_what_to_do(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["c43-obstacle", "--no-load", "--transport", "shm"]) == 2
    assert "--transport shm needs --image NAME" in capsys.readouterr().err
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["c43-obstacle", "--http", f"http://127.0.0.1:{port}", "--transport", "modbus"]) == 2
    assert f"cannot fetch the layout from http://127.0.0.1:{port}/api/layout" in capsys.readouterr().err
    assert main(["c43-obstacle", "--no-load", "--image", "hli_nobody_here", "--wait", "0"]) == 2
    assert "no shared memory 'hli_nobody_here'" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.req("C43-10", "C14-22", "C3-10")
@pytest.mark.parametrize(
    ("demo", "transport", "steps"),
    [
        (
            "c43-obstacle",
            "shm",
            ["program started", "obstacle entered", "X stopped at the limit", "obstacle left"],
        ),
        ("c14-manual", "modbus", ["work area", "manual mode", "X stopped before the boundary", "suppress"]),
        ("c3-collision", "shm", ["program started", "feedhold", "carriages at rest"]),
        pytest.param(
            "ve-mode",
            "modbus",
            ["program started with V.E.MODE = 1", "V.E.PLC_READY = TRUE", "part 3 done", "program finished"],
            marks=pytest.mark.req("N-05"),
        ),
    ],
    ids=["c43-shm", "c14-modbus", "c3-shm", "ve-modbus"],
)
def test_hli_plc_runs_a_demo_against_hli_server_run(
    hli_server_process: dict[str, str], demo: str, transport: str, steps: list[str]
) -> None:
    server = hli_server_process
    host, port = server["modbus"].rsplit(":", 1)
    where = ["--image", server["image"]] if transport == "shm" else ["--host", host, "--port", port]
    done = subprocess.run(
        [HLI_PLC, demo, "--transport", transport, *where, "--http", server["http"], "--timeout", "60"],
        capture_output=True,
        text=True,
        timeout=90,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    said = [line.split("] ", 1)[1] for line in done.stdout.splitlines() if line.startswith("[CNC cycle")]
    for step in steps:
        assert any(text.startswith(step) for text in said), (step, done.stdout)
    assert done.stdout.splitlines()[-1].startswith("hli-plc: done:")


def _get(url: str) -> dict[str, object]:
    with urllib.request.urlopen(url, timeout=5) as response:
        answer: dict[str, object] = json.loads(response.read())
        return answer


@pytest.mark.slow
def test_hli_plc_checks_its_transport_before_it_changes_the_machine(
    hli_server_process: dict[str, str],
) -> None:
    """A PLC that cannot reach the CNC over its door leaves the machine as it was: no reset, no program
    loaded (issue 23). The HTTP API answers; the Modbus port is one where nothing listens."""
    server = hli_server_process
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        closed = str(s.getsockname()[1])
    before = _get(server["http"] + "/api/events?since=0")["latest"]
    program = _get(server["http"] + "/api/state")["channels"][0]["program"]  # type: ignore[index]
    done = subprocess.run(
        [HLI_PLC, "c43-obstacle", "--transport", "modbus", "--port", closed, "--http", server["http"]],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2, done.stdout + done.stderr
    assert "hli-plc:" in done.stderr
    assert "loaded" not in done.stdout
    after = _get(server["http"] + "/api/events?since=0")
    assert after["latest"] == before, after  # no reset, no load: no event at all
    assert _get(server["http"] + "/api/state")["channels"][0]["program"] == program  # type: ignore[index]


@pytest.mark.slow
def test_hli_plc_repeats_until_sigterm_and_stops_cleanly(hli_server_process: dict[str, str]) -> None:
    """``--repeat`` (the compose bench's PLC) runs the demo again and again; SIGTERM, which a
    container's first process would otherwise ignore, stops it with exit code 0."""
    server = hli_server_process
    host, port = server["modbus"].rsplit(":", 1)
    proc = subprocess.Popen(
        [
            HLI_PLC,
            "c43-obstacle",
            "--transport",
            "modbus",
            "--host",
            host,
            "--port",
            port,
            "--http",
            server["http"],
            "--repeat",
            "--pause",
            "0.1",
            "--timeout",
            "60",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        deadline = time.monotonic() + 60
        seen = []
        for line in proc.stdout:
            seen.append(line)
            if "(run 2)" in line or time.monotonic() > deadline:
                break
        assert any(line.startswith("hli-plc: done:") for line in seen), "".join(seen)
        assert "(run 2)" in seen[-1], "".join(seen)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=15)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert "hli-plc: stopped (SIGTERM)" in err
    assert "Traceback" not in err
