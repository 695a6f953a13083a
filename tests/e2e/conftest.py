"""``hli-server run`` as a user starts it, for the end-to-end tests of the PLC side (H-06).

One server per test module (realtime clock, free ports, an image name of its own); its banner says
where it listens. Tests that share it must not depend on each other's leftovers: every PLC program
here starts by putting the outputs it relies on where it needs them.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def hli_server_process(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, str]]:
    """``hli-server run`` in a process of its own: ``{"image", "http", "modbus"}`` from its banner."""
    name = f"hli_test_e2e_{os.getpid()}_{time.monotonic_ns() % 1_000_000}"
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
