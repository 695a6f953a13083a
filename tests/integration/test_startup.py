"""Start-up of ``hli-server run``: readiness that tells the truth, a clean stop at any moment (issue 23).

* ``GET /api/ready`` answers 503 until every door asked for listens (the Modbus and ADS doors run in a
  process of their own and listen a moment after the HTTP API), 200 from then on, 503 while stopping;
* SIGTERM (``docker stop``, an orchestrator) and Ctrl+C (SIGINT to the whole process group, the doors
  process included) at seeded random moments of the start-up: the server ends promptly with exit code
  0, prints no traceback and no warning, and leaves nothing behind: no process of its group, no shared
  memory. A signal before the command has begun (Python still importing) ends it at once: exit code
  143 (SIGTERM), nothing printed, nothing made yet.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from hli_server.configuration import load_machine
from hli_server.runtime import Runtime

pytestmark = pytest.mark.req("H-10")

CLI = str(Path(sys.executable).parent / "hli-server")
SEED = int(os.environ.get("HLI_FUZZ_SEED", "23"))
SIGNALS = max(4, round(5 * float(os.environ.get("HLI_FUZZ_SCALE", "1"))))
"""Server starts the signal test interrupts: five in the suite, more under ``make soak``."""


def _ready(url: str) -> tuple[int, dict[str, object]]:
    try:
        with urllib.request.urlopen(url + "/api/ready", timeout=2) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


async def test_ready_only_when_every_door_listens_and_not_while_stopping() -> None:
    """In-process, no doors process: the readiness the HTTP route reports follows the runtime."""
    rt = Runtime(load_machine(None), clock="stepped", http_port=0, adapters=[("http", {"port": 0}), "modbus"])
    before = rt.readiness()
    assert not before.ready
    assert before.state == "starting"
    assert dict(before.doors) == {"http": False, "modbus": False}
    async with rt:
        now = rt.readiness()
        assert now.ready
        assert now.to_json() == {
            "ready": True,
            "state": "running",
            "doors": {"http": True, "modbus": True},
            "waiting_for": [],
            "ports": {name: getattr(rt.adapter(name), "port") for name in ("http", "modbus")},  # noqa: B009
        }
        rt.request_stop()
        assert not rt.readiness().ready
        assert rt.readiness().state == "stopping"
    assert rt.readiness().state == "stopping"


@pytest.mark.slow
def test_the_health_check_waits_for_the_doors_process() -> None:
    """``hli-server run`` with Modbus and ADS in the doors process: /api/ready is polled from the first
    moment the HTTP API answers; every answer before the banner names the doors not yet listening,
    and once it says ready, Modbus and ADS accept connections."""
    import socket

    name = f"hli_test_ready_{os.getpid()}"
    proc = subprocess.Popen(
        [
            CLI,
            "run",
            "--image-name",
            name,
            "--http-port",
            "0",
            "--modbus-port",
            "0",
            "--ads-port",
            "0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        # the HTTP port is in the banner only after start-up: find it from the process' listening socket
        url = _wait_http_url(proc.pid, timeout=30)
        answers = []
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            status, body = _ready(url)
            answers.append((status, body))
            if status == 200:
                break
        assert answers[-1][0] == 200, answers[-3:]
        ready = answers[-1][1]
        assert ready["doors"] == {"http": True, "modbus": True, "ads": True}, ready
        for status, body in answers[:-1]:
            assert status == 503
            assert body["ready"] is False
            assert body["waiting_for"] or body["state"] == "starting", body
        assert proc.stdout is not None
        banner = _read_until(proc.stdout, "stop with")
        ports = [int(line.split("127.0.0.1:")[1].split()[0]) for line in banner if "TCP" in line]
        assert len(ports) == 2, banner
        for port in ports:
            with socket.create_connection(("127.0.0.1", port), timeout=5):
                pass
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    assert "Traceback" not in err


def _wait_http_url(pid: int, timeout: float) -> str:
    """The URL of the HTTP API of process ``pid`` as soon as it listens (from /proc/net/tcp and the socket
    inodes of the process and its children: the HTTP API is served by the doors process; the banner
    comes only after the whole start-up). Of the listening ports, the one that answers HTTP."""
    deadline = time.monotonic() + timeout
    tried: set[int] = set()
    while time.monotonic() < deadline:
        inodes = set()
        pids = [pid]
        with contextlib.suppress(OSError):
            pids += [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
        for owner in pids:
            try:
                for fd in os.listdir(f"/proc/{owner}/fd"):
                    target = os.readlink(f"/proc/{owner}/fd/{fd}")
                    if target.startswith("socket:["):
                        inodes.add(target[8:-1])
            except OSError:
                pass
        for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] == "0A" and fields[9] in inodes:  # LISTEN
                port = int(fields[1].split(":")[1], 16)
                if port in tried:
                    continue
                url = f"http://127.0.0.1:{port}"
                try:
                    _ready(url)
                except (OSError, ValueError):  # not the HTTP API (Modbus, ADS)
                    tried.add(port)
                    continue
                return url
        time.sleep(0.005)  # the moment the socket listens: bounded by the deadline above
    pytest.fail(f"process {pid} did not listen within {timeout} s")


def _read_until(stream: object, marker: str, timeout: float = 30) -> list[str]:
    lines: list[str] = []
    deadline = time.monotonic() + timeout
    for line in stream:  # type: ignore[attr-defined]
        lines.append(line)
        if marker in line or time.monotonic() > deadline:
            break
    return lines


def _group_alive(pgid: int, grace: float) -> list[str]:
    """Processes of process group ``pgid`` (zombies excluded) still alive after ``grace`` seconds (the
    multiprocessing resource tracker ends a moment after the last process that used it), as
    ``"pid: command line"``."""
    deadline = time.monotonic() + grace
    while True:
        alive = []
        for entry in os.listdir("/proc"):
            if not entry.isdigit():
                continue
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
                cmdline = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            fields = stat.rsplit(")", 1)[1].split()
            if int(fields[2]) == pgid and fields[0] != "Z":
                alive.append(f"{entry}: {cmdline[:200]}")
        if not alive or time.monotonic() > deadline:
            return alive
        time.sleep(0.05)  # until the group has ended, bounded by the grace above


def _signal_masks(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/status") as f:
            return " ".join(line.strip() for line in f if line.startswith(("SigBlk", "SigIgn", "SigCgt")))
    except OSError:
        return "(no /proc)"


def _wait_for_exec(pid: int) -> None:
    """Until the child runs the command (its command line is no longer this process'), at most 10 s. A
    signal sent between ``fork`` and ``exec`` meets the handlers inherited from this process: Python's
    SIGINT handler only notes it in memory that ``exec`` throws away, so the server would never see it
    (seen once under the whole suite's load, where the fork of a pytest worker took more than 0.16 s)."""
    try:
        with open("/proc/self/cmdline", "rb") as f:
            own = f.read()
    except OSError:
        return  # not Linux: nothing to wait with
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                if f.read() != own:
                    return
        except OSError:
            return  # it has ended already
        time.sleep(0.001)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_signal_at_any_moment_of_start_up_stops_the_server_cleanly() -> None:
    rng = random.Random(SEED)
    # how long a start takes here, to spread the signals over it (and a little past it)
    began = time.monotonic()
    calibration = subprocess.run(
        [CLI, "run", "--http-port", "0", "--modbus-port", "0", "--ads-port", "0", "--cycles", "0"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    start_up = time.monotonic() - began
    assert calibration.returncode == 0, calibration.stderr
    outcomes = []
    for i in range(SIGNALS):
        delay = rng.uniform(0.0, start_up * 1.2)
        sig = signal.SIGTERM if i % 2 == 0 else signal.SIGINT
        name = f"hli_test_sig_{os.getpid()}_{i}"
        # the child starts as from a shell: SIGINT not ignored (an ignored SIGINT is inherited through exec,
        # and Python then installs no KeyboardInterrupt for it: a Ctrl+C before `run` takes the signal over
        # would be lost whatever the server does)
        inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            ports = ["--http-port", "0", "--modbus-port", "0", "--ads-port", "0"]
            command = ["run", "--image-name", name, *ports]
            proc = subprocess.Popen(
                [CLI, *command],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                start_new_session=True,  # its own process group: Ctrl+C reaches the doors process too
            )
        finally:
            signal.signal(signal.SIGINT, inherited if inherited is not None else signal.SIG_DFL)
        _wait_for_exec(proc.pid)
        time.sleep(delay)  # the moment of the signal, seeded, from the exec of the command
        if sig is signal.SIGINT:
            os.killpg(proc.pid, sig)  # a terminal's Ctrl+C
        else:
            proc.send_signal(sig)  # docker stop, an orchestrator
        try:
            out, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            masks = _signal_masks(proc.pid)
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
            pytest.fail(
                f"{sig.name} after {delay:.2f} s: not stopped within 30 s (the parent's SIGINT handler was "
                f"{inherited!r}; the server's {masks})\n{out}\n{err}"
            )
        left = _group_alive(proc.pid, grace=5.0)
        shm_left = Path(f"/dev/shm/{name}").exists()
        for pid in left:  # leave nothing behind even when failing
            os.kill(int(pid.split(":")[0]), signal.SIGKILL)
        if shm_left:
            Path(f"/dev/shm/{name}").unlink()
        where = f"{sig.name} after {delay:.2f} s (start-up {start_up:.2f} s): exit {proc.returncode}"
        outcomes.append(f"{where}: {out.strip().splitlines()[-1:] if out.strip() else 'before the command'}")
        assert not left, f"{where}: processes left {left}"
        assert not shm_left, f"{where}: /dev/shm/{name} left"
        assert "Traceback" not in err, f"{where}\n{err}"
        assert "leaked" not in err, f"{where}\n{err}"
        if proc.returncode == -signal.SIGTERM:  # before `run` took the signal over: nothing made yet
            assert not out, f"{where}\n{out}"
        elif proc.returncode == 1 and sig is signal.SIGINT:  # Ctrl+C while click loads the command
            assert err.strip() == "Aborted!", f"{where}\n{err}"
        else:
            assert proc.returncode == 0, f"{where}\n{out}\n{err}"
            assert "hli-server: stop" in out, f"{where}\n{out}"
    print("\n".join(outcomes))
