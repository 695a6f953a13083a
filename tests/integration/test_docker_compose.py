"""The docker-compose test bench (H-09), checked without a Docker engine.

``docker-compose.yml`` and the ``Dockerfile`` are parsed; each server's command goes through
``hli-server run``'s own option parser and ``plan_adapters`` (so a flag that does not exist, or a port
that does not match what is published, fails here), the PLC's through ``hli-plc``'s; the commands are
console scripts of the package; the machine file of the second CNC validates; the health checks run
locally against a server and a broker the test starts; Debian's docker-compose 1.29 reads the file.
With a Docker engine, ``tests/integration/test_docker_bench.py`` builds and runs all of it.
"""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import click
import pytest
import yaml

from hli_server.adapters.mqtt import MqttOptions
from hli_server.adapters.registry import ADAPTERS, CLI_ALIASES, plan_adapters
from hli_server.commands.run import run as run_command
from hli_server.configuration import load_machine
from hli_server.runtime import Runtime
from tests.integration._mosquitto import Mosquitto, missing_tools, tool

pytestmark = pytest.mark.req("H-09")

ROOT = Path(__file__).resolve().parents[2]
COMPOSE = ROOT / "docker-compose.yml"
SERVERS = ("cnc1", "cnc2")
ADS_FLAGS = ("--ads-port", "--ams-net-id")


@pytest.fixture(scope="module")
def compose() -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(COMPOSE.read_text(encoding="utf-8"))
    return data


@pytest.fixture(scope="module")
def scripts() -> dict[str, str]:
    with (ROOT / "pyproject.toml").open("rb") as f:
        found: dict[str, str] = tomllib.load(f)["project"]["scripts"]
    return found


def dockerfile() -> list[tuple[str, str]]:
    """``(INSTRUCTION, arguments)`` with continuation lines joined and comments dropped."""
    text = (ROOT / "Dockerfile").read_text(encoding="utf-8")
    joined = text.replace("\\\n", " ")
    out = []
    for line in joined.splitlines():
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            word, _, rest = stripped.partition(" ")
            out.append((word.upper(), rest.strip()))
    return out


def run_args(service: dict[str, Any]) -> list[str]:
    command = service["command"]
    assert command[:2] == ["hli-server", "run"], command
    args = list(command[2:])
    if "ads" not in ADAPTERS:  # the ADS adapter lands with its own branch: check the rest meanwhile
        for flag in ADS_FLAGS:
            while flag in args:
                i = args.index(flag)
                del args[i : i + 2]
    return args


def parsed(args: list[str]) -> dict[str, Any]:
    """``hli-server run ARGS`` parsed by the command itself (unknown flags and bad values raise)."""
    with run_command.make_context("run", list(args)) as ctx:
        return dict(ctx.params)


def planned(params: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """What ``run`` would start with these parameters (no machine file adapters)."""
    aliases = {
        a.flag: params.get("alias_" + a.flag.removeprefix("--").replace("-", "_")) for a in CLI_ALIASES
    }
    return dict(plan_adapters((), params["adapter_specs"], aliases))


def published(service: dict[str, Any]) -> dict[int, tuple[str, int]]:
    """container port -> (host address, host port), from ``ports: ["127.0.0.1:8080:8080"]``; a host
    port given as ``${VAR:-8080}`` is its default."""
    out = {}
    for entry in service.get("ports", []):
        entry = re.sub(r"\$\{[A-Z0-9_]+:-(\d+)\}", r"\1", str(entry))
        host_ip, host_port, container = entry.rsplit(":", 2)
        out[int(container)] = (host_ip, int(host_port))
    return out


# --------------------------------------------------------------------------------------------
# The compose file
# --------------------------------------------------------------------------------------------


def test_the_bench_has_a_broker_two_servers_and_a_plc(compose: dict[str, Any]) -> None:
    services = compose["services"]
    assert set(services) == {"mqtt", "cnc1", "cnc2", "plc"}
    assert services["mqtt"]["image"].startswith("eclipse-mosquitto:2")
    for name in (*SERVERS, "plc"):
        assert services[name]["build"] == "."
        assert services[name]["image"] == "hli-server:latest"
    for name in SERVERS:
        assert services[name]["depends_on"]["mqtt"]["condition"] == "service_healthy"
    assert services["plc"]["depends_on"]["cnc1"]["condition"] == "service_healthy"
    conf = (ROOT / "docker" / "mosquitto.conf").read_text(encoding="utf-8")
    assert "listener 1883" in conf
    assert services["mqtt"]["volumes"] == ["./docker/mosquitto.conf:/mosquitto/config/mosquitto.conf:ro"]


@pytest.mark.parametrize("name", SERVERS)
def test_each_server_runs_realtime_and_publishes_its_doors_on_loopback(
    compose: dict[str, Any], scripts: dict[str, str], name: str
) -> None:
    service = compose["services"][name]
    assert service["command"][0] in scripts
    params = parsed(run_args(service))
    assert params["clock"] == "realtime"
    assert params["bind"] == "0.0.0.0"  # inside the container; published on the host's loopback below
    plan = planned(params)
    doors = {plan["http"]["port"], plan["modbus"]["port"]} | (
        {plan["ads"]["port"]} if "ads" in plan else set()
    )
    ports = published(service)
    assert set(ports) == doors | ({48898} if "ads" not in ADAPTERS else set())
    assert all(host_ip == "127.0.0.1" for host_ip, _ in ports.values())
    # the image's health check asks the HTTP port the server listens on
    assert f"127.0.0.1:{plan['http']['port']}/" in " ".join(service["healthcheck"]["test"])
    # events go to the compose broker, on the port it listens on
    host, port = MqttOptions(broker=plan["mqtt"]["broker"]).host_port()
    assert host in compose["services"]
    assert (port, ("127.0.0.1", 1883)) in published(compose["services"][host]).items()


def test_the_servers_differ_in_host_ports_and_machine_names(compose: dict[str, Any]) -> None:
    host_ports = [
        hp for name in compose["services"] for _, hp in published(compose["services"][name]).values()
    ]
    assert len(host_ports) == len(set(host_ports)), f"a host port is published twice: {sorted(host_ports)}"
    names = []
    for name in SERVERS:
        service = compose["services"][name]
        config = parsed(run_args(service))["config_path"]
        if config is None:
            names.append(load_machine(None).name)
            continue
        mounts = dict(reversed(v.removesuffix(":ro").split(":", 1)) for v in service["volumes"])
        local = ROOT / mounts[str(config)]
        assert local.is_file(), f"{name}: {config} is mounted from {local}, which does not exist"
        names.append(load_machine(local).name)
    assert len(set(names)) == len(names), f"each CNC needs its own machine name (its MQTT topics): {names}"


def test_the_servers_publish_ads_on_48898(compose: dict[str, Any]) -> None:
    if "ads" not in ADAPTERS:
        pytest.skip("--ads-port comes with the ADS adapter's branch (hli_server/adapters/ads); not here yet")
    for name in SERVERS:
        plan = planned(parsed(run_args(compose["services"][name])))
        assert plan["ads"]["port"] == 48898
        assert 48898 in published(compose["services"][name])


def test_the_plc_acts_on_a_server_over_modbus(compose: dict[str, Any], scripts: dict[str, str]) -> None:
    """The PLC's command through ``hli-plc``'s own parser: a demo, Modbus to cnc1's port, the operator's
    part over cnc1's HTTP API by its service name (which cnc1 admits: --allow-host), again and again."""
    from plc_clients.cli import _parser

    command = compose["services"]["plc"]["command"]
    assert command[0] == "hli-plc"
    assert scripts[command[0]].startswith("plc_clients")
    args = _parser().parse_args(command[1:])
    assert args.demo == "c43-obstacle"
    assert args.repeat
    target = compose["services"][args.host]
    assert args.transport == "modbus"
    assert args.port == planned(parsed(run_args(target)))["modbus"]["port"]
    assert args.http == f"http://{args.host}:{planned(parsed(run_args(target)))['http']['port']}"
    assert args.host in parsed(run_args(target))["allow_hosts"]


def test_the_file_suits_both_compose_generations(compose: dict[str, Any]) -> None:
    """No top-level ``name:`` (docker-compose 1.29 rejects it); where Debian's docker-compose is
    installed, it reads the file (``config`` needs no engine)."""
    assert "name" not in compose
    assert "version" not in compose  # the Compose Specification, read by 1.27+ and v2
    legacy = shutil.which("docker-compose")
    if legacy is None:
        pytest.skip("docker-compose (1.x) is not installed: the file was checked by its keys only")
    done = subprocess.run(
        [legacy, "--file", str(COMPOSE), "config", "--quiet"],
        check=False,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr


# --------------------------------------------------------------------------------------------
# The Dockerfile
# --------------------------------------------------------------------------------------------


def test_the_dockerfile_builds_the_package_and_runs_the_server(
    compose: dict[str, Any], scripts: dict[str, str]
) -> None:
    steps = dockerfile()
    assert steps[0][0] == "FROM"
    assert steps[0][1].startswith("python:3.11")
    copies = [shlex.split(args) for word, args in steps if word == "COPY"]
    sources = {s for words in copies if not words[0].startswith("--from") for s in words[:-1]}
    for source in sources:
        assert (ROOT / source).exists(), f"the Dockerfile copies {source}, which is not in the repository"
    # setup.py compiles the engine (mypyc): without it the image would run the engine as pure Python
    assert {"schemas", "hli_server", "plc_clients", "pyproject.toml", "setup.py"} <= sources
    assert any(word == "RUN" and "pip wheel" in args and args.endswith(" .") for word, args in steps)
    assert any(word == "RUN" and "ENGINE_COMPILED" in args for word, args in steps)
    exposed = {int(p) for word, args in steps if word == "EXPOSE" for p in args.split()}
    for name in SERVERS:
        assert set(published(compose["services"][name])) <= exposed
    cmd = next(json_list(args) for word, args in steps if word == "CMD")
    assert cmd[0] in scripts
    parsed(cmd[2:])  # the default command's flags exist
    (health,) = [args for word, args in steps if word == "HEALTHCHECK"]
    assert json_list(health.split("CMD", 1)[1]) == compose["services"]["cnc1"]["healthcheck"]["test"][1:]


def json_list(text: str) -> list[str]:
    import json

    value = json.loads(text.strip())
    assert isinstance(value, list), text
    return value


# --------------------------------------------------------------------------------------------
# The health checks, run here
# --------------------------------------------------------------------------------------------


def localized(test: list[str], executables: dict[str, str], text: dict[str, str]) -> list[str]:
    """A compose health check (``["CMD", ...]``) as it runs here: its programs by their local path,
    addresses replaced (the test's servers listen on free ports)."""
    assert test[0] == "CMD"
    command = [executables.get(part, part) for part in test[1:]]
    for old, new in text.items():
        command = [part.replace(old, new) for part in command]
    return command


async def test_the_server_health_check_passes_against_a_running_server(compose: dict[str, Any]) -> None:
    test = compose["services"]["cnc1"]["healthcheck"]["test"]
    async with Runtime(load_machine(None), clock="realtime", http_port=0) as rt:
        port = rt.http_url.rsplit(":", 1)[1]
        command = localized(test, {"python": sys.executable}, {"127.0.0.1:8080": f"127.0.0.1:{port}"})
        proc = await _run(command)
    assert proc.returncode == 0, proc.stderr
    down = await _run(command)  # the server is gone: the check fails
    assert down.returncode != 0


async def _run(command: list[str]) -> subprocess.CompletedProcess[str]:
    import asyncio

    proc = await asyncio.create_subprocess_exec(
        *command, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE
    )
    out, err = await asyncio.wait_for(proc.communicate(), 30)
    return subprocess.CompletedProcess(command, proc.returncode or 0, out.decode(), err.decode())


def test_the_broker_health_check_passes_against_mosquitto(compose: dict[str, Any], tmp_path: Path) -> None:
    reason = missing_tools("mosquitto", "mosquitto_sub")
    if reason:
        pytest.skip(reason)
    test = [part.replace("$$", "$") for part in compose["services"]["mqtt"]["healthcheck"]["test"]]
    broker = Mosquitto(tmp_path)
    broker.start()
    try:
        command = localized(test, {"mosquitto_sub": str(tool("mosquitto_sub"))}, {"1883": str(broker.port)})
        proc = subprocess.run(command, check=False, capture_output=True, text=True, timeout=30)
    finally:
        broker.stop()
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().split()[0].isdigit()  # $SYS/broker/uptime: "12 seconds"


def test_click_is_what_parses_the_commands() -> None:
    """The check above is only as good as the parser: an unknown flag must fail it."""
    with pytest.raises(click.UsageError, match="--no-such-flag"):
        parsed(["--no-such-flag"])
