"""The examples of docs/plc-clients.md run as written (H-06, C43-10).

The complete example is taken out of the doc and run as a user would, in its own process, against
``hli-server run`` (realtime clock, free ports) over shared memory and over Modbus TCP with the
layout fetched from the server's HTTP API.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytestmark = pytest.mark.req("H-06", "C43-10")

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "plc-clients.md"
MARKER = "<!-- plc_demo.py:"


def doc_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.DOTALL)


def example_source() -> str:
    text = DOC.read_text(encoding="utf-8")
    start = text.index(MARKER)
    match = re.compile(r"```python\n(.*?)```", re.DOTALL).search(text, start)
    assert match is not None, "the complete example's code block follows its marker"
    return match.group(1)


def test_the_twin_example_runs_as_written() -> None:
    (twin,) = [b for b in doc_blocks() if "MemoryImage(build_layout" in b]
    exec(compile(twin, f"{DOC}:twin", "exec"), {})  # its own asserts check it


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, str]]:
    name = f"hli_test_doc_{os.getpid()}_{time.monotonic_ns() % 1_000_000}"
    cli = str(Path(sys.executable).parent / "hli-server")
    log = tmp_path_factory.mktemp("server") / "server.log"
    with log.open("w", encoding="utf-8") as out:  # a file, not a pipe nobody drains
        proc = subprocess.Popen(
            [cli, "run", "--image-name", name, "--modbus-port", "0", "--http-port", "0"],
            stdout=out,
            stderr=subprocess.STDOUT,
            text=True,
        )
    try:
        found: dict[str, str] = {"image": name}
        deadline = time.monotonic() + 20
        banner = ""
        while "stop with" not in banner:
            assert proc.poll() is None, f"hli-server run ended before its banner: {banner}"
            assert time.monotonic() < deadline, f"no banner within 20 s: {banner}"
            time.sleep(0.05)  # polls the log for the banner; the wait is bounded above
            banner = log.read_text(encoding="utf-8")
        for line in banner.splitlines():
            if "HTTP control API:" in line:
                found["http"] = line.split("HTTP control API:")[1].split()[0]
            if "Modbus TCP:" in line:
                found["modbus"] = line.split("Modbus TCP:")[1].split()[0]
        assert {"http", "modbus"} <= set(found), f"banner incomplete: {banner}"
        yield found
    finally:
        proc.terminate()
        proc.wait(timeout=15)
    assert proc.returncode == 0, log.read_text(encoding="utf-8")


@pytest.mark.slow
@pytest.mark.parametrize("transport", ["shm", "modbus"])
def test_the_complete_example_runs_against_hli_server_run(
    server: dict[str, str], transport: str, tmp_path: Path
) -> None:
    script = tmp_path / "plc_demo.py"
    script.write_text(example_source(), encoding="utf-8")
    where = server["image"] if transport == "shm" else server["modbus"]
    args = [sys.executable, str(script), transport, where, "--hold", "0.3", "--layout", server["http"]]
    done = subprocess.run(args, capture_output=True, text=True, timeout=60, cwd=tmp_path, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert lines[:3] == [
        "X held at 50.000 mm (limit 50 mm)",
        "limit lifted: the program continues",
        "program finished, X at 0.000 mm",
    ], done.stdout + done.stderr
    assert re.fullmatch(r"\d+ cycles, \d+ overruns", lines[3])
