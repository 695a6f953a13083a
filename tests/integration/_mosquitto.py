"""A real Mosquitto broker for the MQTT tests and the benchmark (H-05).

:class:`Mosquitto` writes a config into a directory of its own, starts Debian's ``mosquitto`` on a
free loopback port, waits until it accepts connections, and stops it (SIGTERM, then SIGKILL).
:func:`make_certificates` makes a throw-away CA, a server certificate for 127.0.0.1/localhost and a
client certificate with ``openssl``; :func:`make_password_file` uses ``mosquitto_passwd``. Each tool
that is missing is a skip reason (:func:`missing_tools`), never a failure.
"""

from __future__ import annotations

import contextlib
import getpass
import shutil
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "Certificates",
    "Mosquitto",
    "free_port",
    "make_certificates",
    "make_password_file",
    "missing_tools",
    "tool",
]

_SBIN = ("/usr/sbin", "/usr/local/sbin", "/sbin")


def tool(name: str) -> str | None:
    """Path of ``name`` on PATH or in an sbin directory (``mosquitto`` lives in /usr/sbin)."""
    found = shutil.which(name)
    if found:
        return found
    for directory in _SBIN:
        candidate = Path(directory) / name
        if candidate.is_file():
            return str(candidate)
    return None


def missing_tools(*names: str) -> str | None:
    """A skip reason naming the missing tools and how to get them, or None when all are there."""
    missing = [n for n in names if tool(n) is None]
    if not missing:
        return None
    packages = sorted(
        {
            "mosquitto" if n in ("mosquitto", "mosquitto_passwd") else "openssl" if n == "openssl" else n
            for n in missing
        }
    )
    return f"{', '.join(missing)} not installed (apt-get install {' '.join(packages)}; .ci/run installs them)"


def free_port() -> int:
    """A loopback port that was free a moment ago (the broker binds it right after)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@dataclass
class Certificates:
    ca: Path
    server_cert: Path
    server_key: Path
    client_cert: Path
    client_key: Path


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=30)


def make_certificates(directory: Path) -> Certificates:
    """A self-signed CA and two certificates it signed (EC P-256, valid one day)."""
    directory.mkdir(parents=True, exist_ok=True)
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    _openssl(
        "req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.pem", "-days", "1", "-subj", "/CN=hli test CA",
        "-addext", "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign,cRLSign",
        cwd=directory,
    )  # fmt: skip
    for name, cn, usage in (
        ("server", "localhost", "serverAuth\nsubjectAltName=IP:127.0.0.1,DNS:localhost"),
        ("client", "hli-client", "clientAuth"),
    ):
        (directory / f"{name}.ext").write_text(
            "basicConstraints=CA:FALSE\nkeyUsage=critical,digitalSignature,keyEncipherment\n"
            "authorityKeyIdentifier=keyid,issuer\nsubjectKeyIdentifier=hash\n"
            f"extendedKeyUsage={usage}\n",
            encoding="ascii",
        )
        _openssl(
            "req", *ec, "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={cn}", cwd=directory
        )
        _openssl(
            "x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
            "-out", f"{name}.pem", "-days", "1", "-extfile", f"{name}.ext", cwd=directory,
        )  # fmt: skip
    return Certificates(
        ca=directory / "ca.pem",
        server_cert=directory / "server.pem",
        server_key=directory / "server.key",
        client_cert=directory / "client.pem",
        client_key=directory / "client.key",
    )


def make_password_file(path: Path, users: dict[str, str]) -> Path:
    passwd = tool("mosquitto_passwd")
    assert passwd is not None, missing_tools("mosquitto_passwd")
    first = True
    for user, password in users.items():
        args = [passwd, "-b", *(["-c"] if first else []), str(path), user, password]
        subprocess.run(args, check=True, capture_output=True, timeout=30)
        first = False
    return path


@dataclass
class Mosquitto:
    """One broker process. ``port``: a plain listener; ``tls_port`` (with ``certificates``): a TLS
    listener that requires a client certificate; ``passwords``: user -> password (then no anonymous
    clients); ``persistence``: keep sessions and queued messages across :meth:`restart`."""

    directory: Path
    port: int = 0
    passwords: dict[str, str] = field(default_factory=dict)
    certificates: Certificates | None = None
    tls_port: int = 0
    persistence: bool = False
    process: subprocess.Popen[bytes] | None = None

    def __post_init__(self) -> None:
        self.directory.mkdir(parents=True, exist_ok=True)
        self.port = self.port or free_port()
        if self.certificates is not None:
            self.tls_port = self.tls_port or free_port()
        self.config = self.directory / "mosquitto.conf"
        self.log = self.directory / "mosquitto.log"
        lines = [
            f"user {getpass.getuser()}",  # as root: stay root (the files are ours), else no effect
            f"persistence {'true' if self.persistence else 'false'}",
            f"persistence_location {self.directory}/",
            "max_queued_messages 0",  # unlimited: the restart test queues for a persistent session
            f"log_dest file {self.log}",
            "log_type error",
            "log_type warning",
            "log_type notice",
            "log_type information",
            f"listener {self.port} 127.0.0.1",
        ]
        if self.passwords:
            lines += [
                "allow_anonymous false",
                f"password_file {make_password_file(self.directory / 'passwords', self.passwords)}",
            ]
        else:
            lines.append("allow_anonymous true")
        if self.certificates is not None:
            c = self.certificates
            lines += [
                f"listener {self.tls_port} 127.0.0.1",
                f"cafile {c.ca}",
                f"certfile {c.server_cert}",
                f"keyfile {c.server_key}",
                "require_certificate true",
            ]
        self.config.write_text("\n".join(lines) + "\n", encoding="utf-8")

    def start(self, timeout: float = 10.0) -> None:
        binary = tool("mosquitto")
        assert binary is not None, missing_tools("mosquitto")
        self.process = subprocess.Popen(
            [binary, "-c", str(self.config)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )
        deadline = time.monotonic() + timeout
        ports = [self.port] + ([self.tls_port] if self.tls_port else [])
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                err = self.process.stderr.read().decode(errors="replace") if self.process.stderr else ""
                log = self.log.read_text(errors="replace") if self.log.exists() else ""
                raise RuntimeError(f"mosquitto exited with {self.process.returncode}: {err}{log}")
            if all(_accepts(p) for p in ports):
                return
            time.sleep(0.02)
        self.stop()
        raise RuntimeError(f"mosquitto did not listen on {ports} within {timeout} s; log: {self.log}")

    def stop(self) -> None:
        process, self.process = self.process, None
        if process is None:
            return
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=10)
        if process.stderr is not None:
            process.stderr.close()

    def restart(self) -> None:
        self.stop()
        self.start()

    def log_text(self) -> str:
        return self.log.read_text(errors="replace") if self.log.exists() else ""


def _accepts(port: int) -> bool:
    with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=0.2):
        return True
    return False
