"""The compose bench and the image, with a real Docker engine (H-09, issue 23).

Builds the image from the project's own ``Dockerfile``, brings ``docker-compose.yml`` up with the
compose this machine has (``docker compose`` v2, else Debian's ``docker-compose`` 1.29), waits for the
health checks (``/api/ready``: every door listens) and proves through the ports published on the host,
127.0.0.1 only:

* both CNCs answer HTTP, Modbus and ADS, each as its own machine;
* the demo PLC (service ``plc``) drives cnc1: a dynamic position limit of X reaches state 2 or more;
* the broker carries both machines' events;
* ``docker run`` of the image with the command of docs/docker.md answers, and stops cleanly;

then takes everything down and checks that no container, network or volume of the test is left.

It needs a Docker engine and the base images (``python:3.11-slim``, ``eclipse-mosquitto:2``: pulled,
or the stand-ins of ``docker/stand-in-images.sh``); without them it skips, saying why. ``.ci/run``
starts ``dockerd`` where it can, makes the base images and builds the image once before the suite, so
that the build here is a cache hit. Every step is bounded in time.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import shlex
import shutil
import socket
import struct
import subprocess
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from hli_server.codecs.ads import (
    AmsAddress,
    AmsPacket,
    AmsStreamDecoder,
    CommandId,
    NetId,
    decode_response,
    encode_request,
)
from schemas.layout import Layout

pytestmark = [
    pytest.mark.docker,
    pytest.mark.slow,
    pytest.mark.req("H-09", "H-10"),
    pytest.mark.timeout(1500),
]

ROOT = Path(__file__).resolve().parents[2]
COMPOSE_FILE = ROOT / "docker-compose.yml"
DOCKER_DOC = ROOT / "docs" / "docker.md"
BASE_IMAGES = ("python:3.11-slim", "eclipse-mosquitto:2")
IMAGE = "hli-server:latest"
# the compose file's host ports, by the variables that move them (docker-compose.yml)
PORT_VARS = {
    "HLI_MQTT_PORT": 1883,
    "HLI_CNC1_HTTP_PORT": 8080,
    "HLI_CNC1_MODBUS_PORT": 5020,
    "HLI_CNC1_ADS_PORT": 48898,
    "HLI_CNC2_HTTP_PORT": 8081,
    "HLI_CNC2_MODBUS_PORT": 5021,
    "HLI_CNC2_ADS_PORT": 48899,
}
CYCLE = "gpCh[0]^bahn_state.cycle_r"
DPL_HIGH_X = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.state_r"
BUILD_S = 1200
UP_S = 180
HEALTHY_S = 120


# --------------------------------------------------------------------------------------------
# The engine, the compose command, free ports
# --------------------------------------------------------------------------------------------


def _run(
    args: list[str], timeout: float, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(args, capture_output=True, text=True, timeout=timeout, check=False, env=env)


def _compose_command(docker: str) -> list[str] | None:
    """``docker compose`` (v2) where the plugin is there, else ``docker-compose`` (1.27+)."""
    if _run([docker, "compose", "version"], 30).returncode == 0:
        return [docker, "compose"]
    legacy = shutil.which("docker-compose")
    if legacy is not None and _run([legacy, "version"], 30).returncode == 0:
        return [legacy]
    return None


@pytest.fixture(scope="module")
def docker() -> str:
    docker = shutil.which("docker")
    if docker is None:
        pytest.skip(
            "no docker command here: the bench test needs a Docker engine (.ci/run starts dockerd as root)"
        )
    info = _run([docker, "info", "--format", "{{.ServerVersion}}"], 30)
    if info.returncode != 0:
        pytest.skip(f"no Docker engine answers (`docker info`: {info.stderr.strip()[:200]})")
    missing = [image for image in BASE_IMAGES if _run([docker, "image", "inspect", image], 30).returncode]
    if missing:
        pytest.skip(
            f"base images missing: {', '.join(missing)} (no registry reachable?): "
            "run docker/stand-in-images.sh"
        )
    return docker


def _free_ports(count: int) -> list[int]:
    """Ports nothing listens on now (bound and released together, so they are distinct)."""
    with contextlib.ExitStack() as stack:
        socks = [stack.enter_context(socket.socket()) for _ in range(count)]
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]


def _project_resources(docker: str, project: str) -> dict[str, list[str]]:
    """Containers, networks and volumes labelled with the compose project (what ``down`` removes)."""
    label = f"label=com.docker.compose.project={project}"
    found = {}
    for kind, args in (
        ("containers", ["ps", "-a", "-q", "--filter", label]),
        ("networks", ["network", "ls", "-q", "--filter", label]),
        ("volumes", ["volume", "ls", "-q", "--filter", label]),
    ):
        found[kind] = _run([docker, *args], 60).stdout.split()
    return found


# --------------------------------------------------------------------------------------------
# Clients: HTTP, Modbus, ADS, MQTT
# --------------------------------------------------------------------------------------------


def _http(url: str, body: str | None = None, content_type: str = "text/plain") -> tuple[int, Any]:
    data = None if body is None else body.encode("utf-8")
    request = urllib.request.Request(url, data=data, method="GET" if body is None else "POST")
    request.add_header("content-type", content_type)
    try:
        with urllib.request.urlopen(request, timeout=5) as response:
            return response.status, json.loads(response.read() or b"null")
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"null")


def _wait(what: str, check: Any, timeout: float, every: float = 0.5) -> Any:
    """Poll ``check()`` until it returns something true; fail naming ``what`` and the last answer."""
    deadline = time.monotonic() + timeout
    last: Any = None
    while time.monotonic() < deadline:
        try:
            last = check()
        except (OSError, ValueError) as exc:  # not listening yet, a reset while it starts
            last = exc
        else:
            if last:
                return last
        time.sleep(every)  # polling a container from outside: bounded by the deadline above
    pytest.fail(f"{what}: not within {timeout:.0f} s (last: {last!r})")


def _modbus_cycle(port: int, layout: Layout) -> int:
    from pymodbus.client import ModbusTcpClient

    signal = layout.signal(CYCLE)
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=3)
    try:
        assert client.connect(), f"Modbus: no connection to 127.0.0.1:{port}"
        answer = client.read_input_registers(signal.modbus_address, count=2)
        assert not answer.isError(), answer
        high, low = answer.registers
        return (high << 16) | low  # ABCD
    finally:
        client.close()


def _ads_cycle(port: int, layout: Layout) -> tuple[int, int]:
    """ReadState and a Read of the cycle counter over raw AMS/TCP: (ADS state, cycle)."""
    signal = layout.signal(CYCLE)
    target = AmsAddress(NetId.parse("127.0.0.1.1.1"), 851)
    source = AmsAddress(NetId.parse("10.23.0.1.1.1"), 32905)
    decoder = AmsStreamDecoder()
    answers: list[Any] = []
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        requests = [
            (CommandId.READ_STATE, b""),
            (CommandId.READ, struct.pack("<III", signal.ads_group, signal.ads_offset, 4)),
        ]
        for invoke, (command, payload) in enumerate(requests, start=1):
            sock.sendall(encode_request(target, source, command, invoke, payload))
            frames: list[Any] = []
            while not frames:
                data = sock.recv(65536)
                assert data, f"ADS: 127.0.0.1:{port} closed the connection"
                frames.extend(decoder.feed(data))
            packet = frames[0]
            assert isinstance(packet, AmsPacket), packet
            assert packet.header.error_code == 0, f"ADS error {packet.header.error_code:#x}"
            answers.append(decode_response(command, packet.data))
    state, read = answers
    assert state.result == 0, answers
    assert read.result == 0, answers
    return state.ads_state, struct.unpack("<I", read.data)[0]


async def _mqtt_messages(
    port: int, topics: list[str], want: Any, timeout: float, trigger: Any = None
) -> list[tuple[str, str]]:
    """What the broker delivers on ``topics`` until ``want(seen)``; ``trigger()`` runs (in a thread)
    once the subscriptions stand."""
    import aiomqtt

    seen: list[tuple[str, str]] = []
    async with aiomqtt.Client("127.0.0.1", port, identifier=f"hli-bench-test-{os.getpid()}") as client:
        for topic in topics:
            await client.subscribe(topic, qos=1)
        if trigger is not None:
            await asyncio.to_thread(trigger)
        async with asyncio.timeout(timeout):
            async for message in client.messages:
                payload = message.payload
                text = payload.decode("utf-8") if isinstance(payload, bytes | bytearray) else str(payload)
                seen.append((str(message.topic), text))
                if want(seen):
                    break
    return seen


# --------------------------------------------------------------------------------------------
# The bench
# --------------------------------------------------------------------------------------------


class Bench:
    """One compose project on free host ports; ``down()`` removes it."""

    def __init__(self, docker: str, compose: list[str]) -> None:
        self.docker = docker
        self.project = f"hli-bench-test-{os.getpid()}"
        self.ports = dict(zip(PORT_VARS, _free_ports(len(PORT_VARS)), strict=True))
        self.env = {**os.environ, **{name: str(port) for name, port in self.ports.items()}}
        self.base = [*compose, "--project-name", self.project, "--file", str(COMPOSE_FILE)]

    def compose(self, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
        return _run([*self.base, *args], timeout, env=self.env)

    def container(self, service: str) -> str:
        ids = self.compose("ps", "-q", service).stdout.split()
        assert len(ids) == 1, f"{service}: containers {ids}"
        return ids[0]

    def inspect(self, container: str) -> dict[str, Any]:
        found = json.loads(_run([self.docker, "inspect", container], 60).stdout)
        assert isinstance(found, list)
        assert len(found) == 1
        info: dict[str, Any] = found[0]
        return info

    def health(self, service: str) -> str:
        state = self.inspect(self.container(service))["State"]
        return str(state.get("Health", {}).get("Status", state["Status"]))

    def logs(self) -> str:
        return self.compose("logs", "--no-color", timeout=60).stdout[-6000:]

    def down(self) -> subprocess.CompletedProcess[str]:
        return self.compose("down", "--volumes", "--remove-orphans", "--timeout", "15", timeout=300)


@contextlib.contextmanager
def bench_up(docker: str) -> Iterator[Bench]:
    """The bench built, up and healthy; down and checked gone afterwards, whatever happened."""
    compose = _compose_command(docker)
    if compose is None:
        pytest.skip("no compose here: neither `docker compose` (v2) nor `docker-compose` (1.27+) answers")
    b = Bench(docker, compose)
    try:
        build = b.compose("build", timeout=BUILD_S)
        assert build.returncode == 0, build.stdout[-4000:] + build.stderr[-4000:]
        up = b.compose("up", "--detach", timeout=UP_S)
        assert up.returncode == 0, up.stdout[-3000:] + up.stderr[-3000:]
        for service in ("mqtt", "cnc1", "cnc2"):
            health = _wait(
                f"{service} healthy",
                lambda s=service: b.health(s) in ("healthy", "unhealthy", "exited") and b.health(s),
                HEALTHY_S,
                every=1.0,
            )
            assert health == "healthy", f"{service} is {health}:\n{b.logs()}"
        yield b
    finally:
        down = b.down()
        left = _project_resources(docker, b.project)
        assert down.returncode == 0, down.stderr[-3000:]
        assert left == {"containers": [], "networks": [], "volumes": []}, left


def _url(bench: Bench, cnc: str) -> str:
    return f"http://127.0.0.1:{bench.ports[f'HLI_{cnc.upper()}_HTTP_PORT']}"


def test_the_bench_and_the_image_with_a_real_docker_engine(docker: str) -> None:
    """One test, its steps in order (one bench for all of them, on one xdist worker)."""
    with bench_up(docker) as bench:
        every_port_is_published_on_loopback_only(bench)
        for cnc, machine in (("cnc1", "demo"), ("cnc2", "cnc2")):
            cnc_answers_http_modbus_and_ads(bench, cnc, machine)
        the_demo_plc_drives_cnc1(bench)
        the_broker_carries_both_machines_events(bench)
        the_servers_stop_cleanly_with_the_bench(bench)
    docker_run_with_the_documented_command_answers(docker)


def every_port_is_published_on_loopback_only(bench: Bench) -> None:
    for service in ("mqtt", "cnc1", "cnc2"):
        bindings = bench.inspect(bench.container(service))["NetworkSettings"]["Ports"]
        published = [b for entries in bindings.values() if entries for b in entries]
        assert published, f"{service} publishes nothing"
        assert {b["HostIp"] for b in published} == {"127.0.0.1"}, (service, bindings)
    plc_ports = bench.inspect(bench.container("plc"))["NetworkSettings"]["Ports"] or {}
    assert not any(plc_ports.values()), plc_ports  # the image's ports exposed, none published


def cnc_answers_http_modbus_and_ads(bench: Bench, cnc: str, machine: str) -> None:
    url = _url(bench, cnc)
    status, ready = _http(url + "/api/ready")
    assert status == 200, ready
    assert ready["ready"], ready
    assert set(ready["doors"]) >= {"http", "modbus", "ads", "mqtt"}, ready
    status, layout_json = _http(url + "/api/layout")
    assert status == 200
    layout = Layout.from_json(json.dumps(layout_json).encode())
    assert layout.machine == machine
    modbus_port = bench.ports[f"HLI_{cnc.upper()}_MODBUS_PORT"]
    first = _modbus_cycle(modbus_port, layout)
    ads_state, ads_cycle = _ads_cycle(bench.ports[f"HLI_{cnc.upper()}_ADS_PORT"], layout)
    assert ads_state == 5  # ADSSTATE_RUN
    assert ads_cycle >= first > 0, (cnc, first, ads_cycle)  # both doors read the one image
    # the realtime clock runs: the counter grows
    _wait(f"{cnc}'s cycle counter to grow", lambda: _modbus_cycle(modbus_port, layout) > ads_cycle, 10)


def the_demo_plc_drives_cnc1(bench: Bench) -> None:
    """The plc service runs FCT-C43's obstacle demo over Modbus again and again: its
    MCV_DynPosLimitHigh makes the limit of X active (state 2 ACTIVE or more: braking, brake)."""
    url = _url(bench, "cnc1") + "/api/image/" + urllib.request.quote(DPL_HIGH_X)

    def limit_state() -> int:
        status, answer = _http(url)
        assert status == 200, answer
        value: int = answer["value"]
        return value if value >= 2 else 0

    _wait(f"cnc1's {DPL_HIGH_X} >= 2 (the demo PLC)", limit_state, 90, every=0.05)
    plc_logs = bench.compose("logs", "--no-color", "plc", timeout=60).stdout
    assert "hli-plc: c43-obstacle" in plc_logs, plc_logs[-3000:]


def the_broker_carries_both_machines_events(bench: Bench) -> None:
    """Both machines' status (retained), cnc1's dynamic limits (the demo PLC), and an event of cnc2
    (nothing drives it: a program loaded over its HTTP API changes its program state)."""

    def load_on_cnc2() -> None:
        status, answer = _http(
            _url(bench, "cnc2") + "/api/channels/1/program?name=bench", "N10 G01 X10 F6000\nN20 M30\n"
        )
        assert status in (200, 202), answer

    def complete(seen: list[tuple[str, str]]) -> bool:
        topics = {topic for topic, _ in seen}
        return {"hli/demo/status", "hli/cnc2/status", "hli/cnc2/ch/1/state"} <= topics and any(
            t.startswith("hli/demo/ax/") for t in topics
        )

    seen = asyncio.run(
        _mqtt_messages(
            bench.ports["HLI_MQTT_PORT"],
            ["hli/+/status", "hli/cnc2/ch/1/state", "hli/demo/ax/+/dyn_pos_limit"],
            complete,
            timeout=90,
            trigger=load_on_cnc2,
        )
    )
    status_of = {topic: text for topic, text in seen if topic.endswith("/status")}
    assert status_of == {"hli/demo/status": "online", "hli/cnc2/status": "online"}, seen
    limits = [json.loads(text) for topic, text in seen if topic.startswith("hli/demo/ax/")]
    assert all(m["machine"] == "demo" and m["kind"] == "dyn_pos_limit" for m in limits), limits
    states = [json.loads(text) for topic, text in seen if topic == "hli/cnc2/ch/1/state"]
    assert any(m["machine"] == "cnc2" and m["data"]["program"] == "bench" for m in states), states


def the_servers_stop_cleanly_with_the_bench(bench: Bench) -> None:
    """``compose stop`` sends SIGTERM: the servers and the PLC stop with exit code 0, no traceback."""
    containers = {service: bench.container(service) for service in ("cnc1", "cnc2", "plc")}
    stop = bench.compose("stop", "--timeout", "20", timeout=120)
    assert stop.returncode == 0, stop.stderr
    for service, container in containers.items():
        state = bench.inspect(container)["State"]
        logs = _run([bench.docker, "logs", container], 60)
        assert state["ExitCode"] == 0, (service, state, logs.stdout[-2000:], logs.stderr[-2000:])
        assert "Traceback" not in logs.stdout + logs.stderr, logs.stderr[-3000:]
        if service != "plc":
            assert "hli-server: stopped at cycle" in logs.stdout, logs.stdout[-2000:]


# --------------------------------------------------------------------------------------------
# The image alone, with the command of docs/docker.md
# --------------------------------------------------------------------------------------------


def documented_docker_run() -> list[str]:
    """The first ``docker run`` of docs/docker.md's section "The image", as a user copies it."""
    text = DOCKER_DOC.read_text(encoding="utf-8")
    section = text[text.index("## The image") :]
    line = next(line for line in section.splitlines() if line.startswith("$ docker run "))
    return shlex.split(line.removeprefix("$ ").split("#", 1)[0])


def docker_run_with_the_documented_command_answers(docker: str) -> None:
    command = documented_docker_run()
    assert command[:3] == ["docker", "run", "--rm"], command
    assert command[-1] == "hli-server", command
    name = f"hli-run-test-{os.getpid()}"
    # the same command on free host ports, detached and named so that the test can stop it
    host_ports: dict[int, int] = {}
    args: list[str] = []
    for i, arg in enumerate(command[3:-1], start=3):
        match = re.fullmatch(r"127\.0\.0\.1:(\d+):(\d+)", arg)
        if match and command[i - 1] == "-p":
            free = _free_ports(1)[0]
            host_ports[int(match.group(2))] = free
            arg = f"127.0.0.1:{free}:{match.group(2)}"
        args.append(arg)
    assert set(host_ports) >= {8080, 5020}, command
    run = _run([docker, "run", "--rm", "--detach", "--name", name, *args, IMAGE], 120)
    try:
        assert run.returncode == 0, run.stderr
        url = f"http://127.0.0.1:{host_ports[8080]}"
        _wait("the documented docker run ready", lambda: _http(url + "/api/ready")[0] == 200, 60)
        _, layout_json = _http(url + "/api/layout")
        layout = Layout.from_json(json.dumps(layout_json).encode())
        assert _modbus_cycle(host_ports[5020], layout) > 0
        if 48898 in host_ports:
            assert _ads_cycle(host_ports[48898], layout)[0] == 5
        health = _wait(
            "the image's HEALTHCHECK",
            lambda: (
                _run([docker, "inspect", "-f", "{{.State.Health.Status}}", name], 30).stdout.strip()
                in ("healthy", "unhealthy")
                and _run([docker, "inspect", "-f", "{{.State.Health.Status}}", name], 30).stdout.strip()
            ),
            60,
            every=1.0,
        )
        assert health == "healthy"
        logs_before_stop = _run([docker, "logs", name], 30).stdout
        stop = _run([docker, "stop", "--time", "20", name], 60)
        assert stop.returncode == 0, stop.stderr
        assert "stop with Ctrl+C or SIGTERM" in logs_before_stop
    finally:
        _run([docker, "rm", "--force", name], 60)
    # `docker run --rm` removes the stopped container itself; while that removal is under way,
    # `docker rm --force` answers "removal already in progress" and `ps -a` still lists it for a moment.
    # The container must be gone, not merely going: poll for it, bounded.
    _wait(
        "the container removed after docker stop",
        lambda: _run([docker, "ps", "-a", "-q", "--filter", f"name={name}"], 30).stdout.strip() == "",
        30,
    )
