"""``hli-plc``: the demo PLC programs against a running ``hli-server run``, over any transport (H-06).

The demos are the worked examples of FCT-C43, FCT-C14 and FCT-C3 (``plc_clients.demos``); here they
run as docker-compose will run them: the console command in its own process, the server in another,
realtime clock, the operator's NC program loaded over the HTTP API.
"""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import pytest

from plc_clients.cli import main

pytestmark = pytest.mark.req("H-06")

HLI_PLC = str(Path(sys.executable).parent / "hli-plc")
NEEDS_INTERPRETER = "needs the NC interpreter (nc branch)"


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
    assert main(["c43-obstacle", "--http", f"http://127.0.0.1:{port}", "--image", "hli_nobody"]) == 2
    assert f"no HTTP API at http://127.0.0.1:{port}" in capsys.readouterr().err
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
            marks=[pytest.mark.req("N-05"), pytest.mark.xfail(strict=True, reason=NEEDS_INTERPRETER)],
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
