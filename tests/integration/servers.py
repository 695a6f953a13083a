"""`hli-server run` as a separate process, for the tests that need the real command line."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx

__all__ = ["DOORS", "door_port", "hli_server_cmd", "http_step", "read_banner", "start_server", "stop_server"]

DOORS = ("HTTP control API", "Modbus TCP", "ADS (AMS/TCP)", "ADS (UDP)", "MQTT")
"""The doors' names as the banner starts their lines."""


def hli_server_cmd() -> list[str]:
    """The installed console script next to this interpreter (the venv's)."""
    return [str(Path(sys.executable).parent / "hli-server")]


def start_server(*args: str, env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    """``hli-server run ARGS`` (``env``: variables set for it besides this process' environment)."""
    return subprocess.Popen(
        [*hli_server_cmd(), "run", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, **env} if env else None,
    )


def read_banner(proc: subprocess.Popen[str], timeout: float = 20.0) -> dict[str, str]:
    """The banner lines up to 'stop with ...': the HTTP URL (``url``), the image name (``image``) and
    each door's whole line under its name (``"Modbus TCP"``: ``door_port`` reads its port)."""
    assert proc.stdout is not None
    found: dict[str, str] = {}
    deadline = time.monotonic() + timeout
    lines = []
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if "HTTP control API:" in line:
            found["url"] = line.split("HTTP control API:")[1].split()[0]
        if "shared memory image:" in line:
            found["image"] = line.split("shared memory image:")[1].split()[0]
        for door in DOORS:
            if line.strip().startswith(door + ":"):
                found[door] = line.strip()
        if "stop with" in line:
            found["text"] = "".join(lines)
            return found
    stderr = proc.stderr.read() if proc.stderr and proc.poll() is not None else ""
    raise AssertionError(f"no banner from hli-server run: {''.join(lines)} {stderr}")


def stop_server(proc: subprocess.Popen[str], timeout: float = 10.0) -> None:
    """SIGTERM, then wait; kill if it does not stop."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout)


def door_port(line: str) -> int:
    """The port of a door's banner line: ``Modbus TCP: 127.0.0.1:5020  (...)`` -> 5020."""
    return int(line.split(": ", 1)[1].split(maxsplit=1)[0].rsplit(":", 1)[1])


async def http_step(client: httpx.AsyncClient, cycles: int) -> dict[str, Any]:
    """``POST /api/step`` on a stepped clock: ``cycles`` cycles; the reply's body."""
    r = await client.post("/api/step", json={"cycles": cycles})
    assert r.status_code == 200, r.text
    body: dict[str, Any] = r.json()
    return body
