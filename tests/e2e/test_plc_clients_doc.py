"""The examples of docs/plc-clients.md run as written (H-06, C43-10).

The complete example is taken out of the doc and run as a user would, in its own process, against
``hli-server run`` (realtime clock, free ports) over shared memory and over Modbus TCP with the
layout fetched from the server's HTTP API.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.doc_blocks import DOCS, code_blocks, marked_block

pytestmark = pytest.mark.req("H-06", "C43-10")

DOC = DOCS / "plc-clients.md"


def test_the_twin_example_runs_as_written() -> None:
    (twin,) = [b for b in code_blocks(DOC) if "MemoryImage(build_layout" in b]
    exec(compile(twin, f"{DOC}:twin", "exec"), {})  # its own asserts check it


@pytest.mark.slow
@pytest.mark.parametrize("transport", ["shm", "modbus"])
def test_the_complete_example_runs_against_hli_server_run(
    hli_server_process: dict[str, str], transport: str, tmp_path: Path
) -> None:
    server = hli_server_process
    script = tmp_path / "plc_demo.py"
    script.write_text(marked_block(DOC, "doc-run: session=quick file=plc_demo.py"), encoding="utf-8")
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
