"""Runs the ``doc-run`` blocks of one session of a doc, as a user would, against a real server (issue 23).

``python -m tests.doc_runner`` reads a session (JSON on stdin: the server's arguments, a broker or not,
the blocks' commands) and prints what each command printed and its exit status (JSON on stdout).
``tests/integration/test_docs_run.py`` starts it inside a network and mount namespace of its own
(``unshare --net --mount``, with a /dev/shm of its own), so that the server, the broker and the commands
use the documented ports (8080, 5020, 48898, 1883) and image names (hli_demo) as written, and no two
sessions, test workers or other servers on the machine ever meet.

The commands run as written, in one ``bash`` per block (a variable set by one command is seen by the
next), in a scratch directory, with the project's interpreter's ``bin`` first on ``PATH``. Two
rewrites, both of the set-up and not of what is shown: ``.venv/bin/`` is that ``bin`` (the suite may
run from another virtual environment), and ``make run ARGS="..."`` is ``hli-server run ...`` (what
``make run`` runs once the virtual environment exists). A command with a ``timeout`` is interrupted
with SIGINT (Ctrl+C) after it, and what it printed until then is its output; with ``until``, as soon as
it has printed that text (a server's banner), or after the timeout. Background commands run
until the session's blocks are done, then get SIGINT.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

BIN = Path(sys.executable).parent
NODE_MODULES = Path(__file__).resolve().parent / "interop" / "node" / "node_modules"
"""Node's ads-client for the js blocks (``npm ci`` in tests/interop/node, as ``.ci/run`` does)."""
_MARK = "@@doc-run@@"


def rewrite(command: str) -> str:
    """The two set-up rewrites of the module docstring."""
    command = re.sub(r"(?<![\w/.])\.venv/bin/", f"{BIN}/", command)  # the relative path a user types

    def make_run(match: re.Match[str]) -> str:
        args = match.group(2) if match.group(2) is not None else ""
        return f"{BIN}/hli-server run {args}".rstrip()

    return re.sub(r'make run( ARGS="([^"]*)")?', make_run, command)


def _lo_up() -> None:
    """The namespace's loopback starts down: up with it (SIOCSIFFLAGS, as ``ip link set lo up``)."""
    import fcntl
    import struct

    siocgifflags, siocsifflags, iff_up = 0x8913, 0x8914, 0x1
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        request = struct.pack("16sh14x", b"lo", 0)
        flags = struct.unpack("16sh14x", fcntl.ioctl(s, siocgifflags, request))[1]
        fcntl.ioctl(s, siocsifflags, struct.pack("16sh14x", b"lo", flags | iff_up))


def _wait_port(port: int, timeout: float, proc: subprocess.Popen[Any] | None = None) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            raise RuntimeError(f"the process for port {port} ended: exit {proc.returncode}")
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=0.5):
            return
        time.sleep(0.05)
    raise RuntimeError(f"nothing listens on 127.0.0.1:{port} after {timeout} s")


def _broker(work: Path) -> subprocess.Popen[bytes]:
    import getpass

    conf = work / "mosquitto.conf"
    conf.write_text(
        f"user {getpass.getuser()}\nlistener 1883 127.0.0.1\nallow_anonymous true\npersistence false\n",
        encoding="utf-8",
    )
    mosquitto = next(
        (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()), "mosquitto"
    )
    quiet = subprocess.DEVNULL
    proc = subprocess.Popen([mosquitto, "-c", str(conf)], stdout=quiet, stderr=quiet)
    _wait_port(1883, 10, proc)
    return proc


def _server(args: str, work: Path) -> tuple[subprocess.Popen[str], Path]:
    log = work / "server.log"
    with log.open("w", encoding="utf-8") as out:
        proc = subprocess.Popen(
            [str(BIN / "hli-server"), "run", *shlex.split(args)],
            stdout=out,
            stderr=subprocess.STDOUT,
            text=True,
            cwd=work,
        )
    deadline = time.monotonic() + 60
    while "stop with" not in log.read_text(encoding="utf-8"):
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"hli-server run {args}: no banner\n{log.read_text(encoding='utf-8')}")
        time.sleep(0.05)
    return proc, log


def _script(commands: list[str], timeout: float | None, work: Path) -> str:
    """One bash for the commands, each followed by a marker line with its exit status."""
    lines = ["exec 2>&1", f"cd {shlex.quote(str(work))}"]
    for command in commands:
        command = rewrite(command)
        if timeout is not None:
            # the command as Ctrl+C would end it: SIGINT after the timeout (KILL 10 s later)
            command = f"timeout -s INT -k 10 {timeout} bash -c {shlex.quote(command)}"
        lines.append(command)
        lines.append(f'printf "\\n{_MARK} %s\\n" "$?"')
    return "\n".join(lines) + "\n"


def _split(output: str, count: int) -> list[tuple[str, int]]:
    """(output, exit status) of each of ``count`` commands; -1: the command did not end (the block's
    shell was killed)."""
    parts = output.split(f"\n{_MARK} ")
    found = []
    for k in range(count):
        if k >= len(parts):
            found.append(("", -1))
            continue
        text = parts[0] if k == 0 else parts[k].partition("\n")[2]
        status = int(parts[k + 1].partition("\n")[0]) if k + 1 < len(parts) else -1
        found.append((text.strip("\n"), status))
    return found


def _start(
    command: str, env: dict[str, str], work: Path, out: Any = subprocess.PIPE
) -> subprocess.Popen[bytes]:
    """``command`` in a process group of its own (so that Ctrl+C reaches all of it)."""
    return subprocess.Popen(
        ["bash", "-c", rewrite(command)],
        stdout=out,
        stderr=subprocess.STDOUT,
        env=env,
        cwd=work,
        start_new_session=True,
    )


def _read_until(proc: subprocess.Popen[bytes], until: str, timeout: float) -> bytes:
    """What ``proc`` prints until it printed ``until``, ended, or ``timeout`` passed."""
    import selectors

    assert proc.stdout is not None
    out = b""
    deadline = time.monotonic() + timeout
    with selectors.DefaultSelector() as sel:
        sel.register(proc.stdout, selectors.EVENT_READ)
        while until.encode() not in out and time.monotonic() < deadline:
            if sel.select(timeout=0.1):
                chunk = os.read(proc.stdout.fileno(), 65536)
                if not chunk:
                    break
                out += chunk
    return out


def _interrupt(proc: subprocess.Popen[bytes]) -> bytes:
    """Ctrl+C: SIGINT to the process group; what it prints until it ends (SIGKILL after 30 s)."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGINT)
    try:
        rest, _ = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        rest, _ = proc.communicate()
    return rest or b""


def _text(data: bytes) -> str:
    return data.decode("utf-8", "replace").strip("\n")


def run_session(session: dict[str, Any]) -> dict[str, Any]:
    work = Path(tempfile.mkdtemp(prefix="hli-doc-run-"))
    procs: list[subprocess.Popen[Any]] = []
    serving: list[subprocess.Popen[bytes]] = []
    background: list[tuple[list[tuple[str, int]], int, subprocess.Popen[bytes], Path]] = []
    results: list[dict[str, Any]] = []
    server_log: Path | None = None
    env = {
        **os.environ,
        "PATH": f"{BIN}:{os.environ.get('PATH', '')}",
        "HOME": str(work),
        "COLUMNS": "100",
        "NODE_PATH": str(NODE_MODULES),
    }
    try:
        if session.get("lo_up", True):
            _lo_up()
            # a /dev/shm of the session's own: the documented image names (hli_demo) never meet
            # another session's, another test's or another server's on this machine
            subprocess.run(
                ["mount", "-t", "tmpfs", "-o", "size=64m", "tmpfs", "/dev/shm"], check=True, timeout=30
            )
        if session.get("broker"):
            procs.append(_broker(work))
        if session.get("server") is not None:
            proc, server_log = _server(session["server"], work)
            procs.append(proc)
        for block in session["blocks"]:  # the session's files first: a command may use a later one
            if block.get("file"):
                (work / block["file"]).write_text(block["text"], encoding="utf-8")
        for n, block in enumerate(session["blocks"]):
            setup = block.get("setup", [])
            commands = list(block["commands"])
            if block.get("python") is not None:
                script = work / f"block{n}.py"
                script.write_text(block["python"], encoding="utf-8")
                commands = [f"{BIN}/python {script}"]
            if block.get("pytest") is not None:
                script = work / f"test_doc_block{n}.py"
                script.write_text(block["pytest"], encoding="utf-8")
                commands = [f"{BIN}/python -m pytest -q -p no:cacheprovider -p no:randomly {script.name}"]
            if block.get("node") is not None:
                script = work / f"block{n}.js"
                script.write_text(block["node"], encoding="utf-8")
                commands = [f"node {script.name}"]
            if block.get("file"):
                commands = []
            timeout = block.get("timeout")
            failed_setup = []
            if setup:
                ran = _split(_bash(_script(setup, None, work), env, len(setup)), len(setup))
                failed_setup = [f"$ {c}\n{t}" for c, (t, status) in zip(setup, ran, strict=True) if status]
            outputs: list[tuple[str, int]] = []
            if block.get("serve"):  # the session's server, started by the doc's own command
                for command in commands:
                    proc = _start(command, env, work)
                    serving.append(proc)
                    outputs.append((_text(_read_until(proc, "stop with", timeout or 60.0)), 0))
            elif block.get("background"):  # a second terminal: runs until the session's end
                for k, command in enumerate(commands):
                    out = work / f"background-{n}-{k}.out"
                    with out.open("wb") as sink:
                        background.append((outputs, k, _start(command, env, work, sink), out))
                    outputs.append(("", -1))
                time.sleep(float(block.get("settle", 1.0)))  # subscribed before the next block acts
            elif not commands:
                pass
            elif block.get("until") is not None:
                for command in commands:
                    proc = _start(command, env, work)
                    head = _read_until(proc, block["until"], timeout or 60.0)
                    rest = _interrupt(proc)
                    outputs.append((_text(head + rest), proc.returncode))
            else:
                text = _script(commands, timeout, work)
                outputs = _split(_bash(text, env, len(commands) * (30 + (timeout or 0))), len(commands))
            results.append({"outputs": outputs, "setup_failed": failed_setup})
        if background:
            time.sleep(float(session.get("settle", 1.5)))  # the last events reach the subscribers
            for outputs, k, proc, out in background:
                _interrupt(proc)
                outputs[k] = (_text(out.read_bytes()), proc.returncode)
        return {"blocks": results}
    finally:
        for proc in serving:
            if proc.poll() is None:
                _interrupt(proc)
        for proc in reversed(procs):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(15)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        if server_log is not None and server_log.exists():
            sys.stderr.write(server_log.read_text(encoding="utf-8", errors="replace")[-4000:])


def _bash(script: str, env: dict[str, str], timeout: float) -> str:
    done = subprocess.run(
        ["bash", "-c", script],
        capture_output=True,
        text=True,
        env=env,
        timeout=60 + timeout,
        check=False,
        errors="replace",
    )
    return done.stdout


def main() -> int:
    session = json.loads(sys.stdin.read())
    print(json.dumps(run_session(session)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
