"""deploy/kubernetes, checked without a cluster (issue 37, item 6; H-12).

Each overlay is rendered by ``kubectl kustomize`` (offline) and every object is validated against the
Kubernetes JSON schemas of the oldest and the newest version supported here (``kubernetes-validate``, strict:
an unknown field fails). Then what the objects say is checked against the programs they run: each pod's
command goes through ``hli-server run``'s (or ``hli-plc``'s) own option parser, every door beyond loopback is
guarded, the Services' ports are the ports the server listens on, the probes ask ``/api/ready``, the
ConfigMap's machine file is the demo machine. Last, the fleet's pod command runs here, as a local process (on
loopback, with the ConfigMap's files), and the pytest plugin's remote harness drives it with the API token.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from hli_server.adapters.host import AccessPolicy
from hli_server.adapters.registry import door_guards
from hli_server.configuration import load_machine
from hli_server.testing.remote import RemoteHarness
from tests.integration.servers import read_banner, stop_server
from tests.integration.test_docker_compose import parsed, planned

pytestmark = pytest.mark.req("H-12")

ROOT = Path(__file__).resolve().parents[2]
KUBE = ROOT / "deploy" / "kubernetes"
OVERLAYS = {"bench": 2, "fleet": 20}
"""Each overlay and its number of CNCs."""
SCHEMA_VERSIONS = ("1.29.0", "1.37.0")
POD = {"POD_NAME": "cnc-0", "POD_NAMESPACE": "hli-fleet"}
TOKEN = "a-token-for-the-test"


def kubectl() -> str:
    """kubectl (with a kustomize of v4 or later), from PATH or beside this interpreter (``.ci/run`` puts it
    into the venv where the machine has none); skips, saying why, where there is none."""
    found = shutil.which("kubectl") or shutil.which("kubectl", path=str(Path(sys.executable).parent))
    if found is None:
        pytest.skip("kubectl is not installed (.ci/run installs it): the manifests cannot be rendered")
    done = subprocess.run(
        [found, "version", "--client", "-o", "json"], capture_output=True, text=True, timeout=60, check=False
    )
    version = json.loads(done.stdout or "{}").get("kustomizeVersion", "") if done.returncode == 0 else ""
    if not re.match(r"v([4-9]|\d\d)\.", version):
        pytest.skip(f"{found}'s kustomize is {version or 'missing'}: rendering needs kustomize v4 or later")
    return found


@pytest.fixture(scope="module", params=sorted(OVERLAYS))
def overlay(request: pytest.FixtureRequest) -> tuple[str, list[dict[str, Any]]]:
    """(overlay, its objects as ``kubectl kustomize`` renders them)."""
    name: str = request.param
    done = subprocess.run(
        [kubectl(), "kustomize", str(KUBE / "overlays" / name)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "Warning" not in done.stderr, done.stderr  # nothing deprecated
    return name, [doc for doc in yaml.safe_load_all(done.stdout) if doc]


def find(objects: list[dict[str, Any]], kind: str, name: str) -> dict[str, Any]:
    matches = [o for o in objects if o["kind"] == kind and o["metadata"]["name"].startswith(name)]
    assert len(matches) == 1, f"{kind} {name}: {[o['metadata']['name'] for o in matches]}"
    return matches[0]


def container(workload: dict[str, Any]) -> dict[str, Any]:
    containers: list[dict[str, Any]] = workload["spec"]["template"]["spec"]["containers"]
    assert len(containers) == 1
    return containers[0]


def expanded(spec: dict[str, Any], env: dict[str, str]) -> list[str]:
    """The container's args with ``$(VAR)`` expanded as the kubelet does, from ``env`` and the values of
    the container's own ``env``."""
    values = dict(env)
    for item in spec.get("env", []):
        if "value" in item:
            values.setdefault(item["name"], item["value"])
    return [re.sub(r"\$\(([A-Z_]+)\)", lambda m: values[m.group(1)], arg) for arg in spec["args"]]


def server_args(objects: list[dict[str, Any]]) -> list[str]:
    args = expanded(container(find(objects, "StatefulSet", "cnc")), {**POD, "HLI_API_TOKEN": TOKEN})
    assert args[:2] == ["hli-server", "run"], args
    return args[2:]


def test_every_object_renders_and_validates_against_the_kubernetes_schemas(
    overlay: tuple[str, list[dict[str, Any]]],
) -> None:
    kubernetes_validate = pytest.importorskip("kubernetes_validate")
    _, objects = overlay
    assert {o["kind"] for o in objects} >= {"StatefulSet", "Service", "ConfigMap", "Deployment"}
    for version in SCHEMA_VERSIONS:
        for obj in objects:
            kubernetes_validate.validate(
                obj, version, strict=True
            )  # raises ValidationError, naming the field
    broken = json.loads(json.dumps(find(objects, "StatefulSet", "cnc")))
    broken["spec"]["template"]["spec"]["containers"][0]["readinesProbe"] = {}  # a typo fails
    with pytest.raises(kubernetes_validate.ValidationError):
        kubernetes_validate.validate(broken, SCHEMA_VERSIONS[-1], strict=True)


def test_a_cnc_is_a_statefulset_with_its_machine_file_from_a_configmap(
    overlay: tuple[str, list[dict[str, Any]]], tmp_path: Path
) -> None:
    name, objects = overlay
    cnc = find(objects, "StatefulSet", "cnc")
    assert cnc["spec"]["replicas"] == OVERLAYS[name]
    headless = find(objects, "Service", cnc["spec"]["serviceName"])
    assert headless["spec"]["clusterIP"] == "None"  # every CNC its own DNS name: cnc-0.cnc, cnc-1.cnc, ...
    pod = cnc["spec"]["template"]["spec"]
    volumes = {v["name"]: v for v in pod["volumes"]}
    mounts = {m["mountPath"]: m for m in container(cnc)["volumeMounts"]}
    machine = mounts["/etc/hli"]
    assert machine["readOnly"]
    configmap = find(objects, "ConfigMap", volumes[machine["name"]]["configMap"]["name"])
    assert (
        configmap["metadata"]["name"] == volumes[machine["name"]]["configMap"]["name"]
    )  # the generated name
    for file, text in configmap["data"].items():
        (tmp_path / file).write_text(text, encoding="utf-8")
    config_path = parsed(server_args(objects))["config_path"]
    assert config_path.parent == Path("/etc/hli")
    loaded = load_machine(tmp_path / config_path.name)
    assert loaded == load_machine(None)


def test_the_services_ports_are_the_servers_and_the_probes_ask_ready(
    overlay: tuple[str, list[dict[str, Any]]],
) -> None:
    _, objects = overlay
    cnc = find(objects, "StatefulSet", "cnc")
    spec = container(cnc)
    named = {p["name"]: p["containerPort"] for p in spec["ports"]}
    doors = planned(parsed(server_args(objects)))
    assert named == {
        "http": doors["http"]["port"],
        "modbus": doors["modbus"]["port"],
        "ads": doors["ads"]["port"],
    }
    service = find(objects, "Service", cnc["spec"]["serviceName"])
    assert {p["name"]: (p["port"], p["targetPort"]) for p in service["spec"]["ports"]} == {
        name: (port, name) for name, port in named.items()
    }
    assert service["spec"]["selector"].items() <= cnc["spec"]["template"]["metadata"]["labels"].items()
    for probe in ("startupProbe", "readinessProbe", "livenessProbe"):
        assert spec[probe]["httpGet"] == {"path": "/api/ready", "port": "http"}, probe


def test_the_pod_command_guards_every_door_beyond_loopback(overlay: tuple[str, list[dict[str, Any]]]) -> None:
    """The server refuses to start on 0.0.0.0 with an unguarded door: none is (HTTP by the token from the
    Secret, Modbus and ADS by their allowlists); the pod's DNS names are allowed Host headers."""
    name, objects = overlay
    params = parsed(server_args(objects))
    assert params["bind"] == "0.0.0.0"
    assert not params["insecure"]
    token = next(
        e for e in container(find(objects, "StatefulSet", "cnc"))["env"] if e["name"] == "HLI_API_TOKEN"
    )
    assert token["valueFrom"]["secretKeyRef"] == {"name": "hli-api-token", "key": "token"}
    policy = AccessPolicy(api_token=TOKEN, allowed_hosts=params["allow_hosts"])
    adapters = planned(params)
    assert [g.label for g in door_guards(list(adapters.items()), policy) if not g.guarded] == []
    assert "cnc-0.cnc.hli-fleet.svc.cluster.local" in params["allow_hosts"]
    assert "cnc-0.cnc" in params["allow_hosts"]
    assert adapters["mqtt"]["broker"] == "mqtt:1883"
    assert adapters["mqtt"]["topic_prefix"] == "hli/cnc-0/"  # one topic tree per CNC, not per machine file
    assert params["clock"] == ("stepped" if name == "fleet" else "realtime")
    mqtt = find(objects, "Service", "mqtt")
    assert [p["port"] for p in mqtt["spec"]["ports"]] == [1883]


def test_the_bench_runs_the_demo_plc_on_cnc_0(overlay: tuple[str, list[dict[str, Any]]]) -> None:
    from plc_clients.cli import _parser

    name, objects = overlay
    plcs = [o for o in objects if o["kind"] == "Deployment" and o["metadata"]["name"] == "plc"]
    if name != "bench":
        assert not plcs  # the fleet's CNCs are driven by the tests
        return
    spec = container(plcs[0])
    assert spec["args"][0] == "hli-plc"
    args = _parser().parse_args(spec["args"][1:])
    server = parsed(server_args(objects))
    assert args.transport == "modbus"
    assert args.host == "cnc-0.cnc"
    assert args.host in server["allow_hosts"]
    assert args.port == planned(server)["modbus"]["port"]
    assert args.http == f"http://cnc-0.cnc:{planned(server)['http']['port']}"
    assert {e["name"] for e in spec["env"]} == {"HLI_API_TOKEN"}  # the operator's part over HTTP needs it


@pytest.fixture
def fleet_pod(tmp_path: Path) -> Iterator[str]:
    """The fleet's pod command as a local process: the ConfigMap's files in a directory here, on loopback
    and free ports (the rest as the pod has it); its HTTP URL."""
    done = subprocess.run(
        [kubectl(), "kustomize", str(KUBE / "overlays" / "fleet")],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    objects = [doc for doc in yaml.safe_load_all(done.stdout) if doc]
    for file, text in find(objects, "ConfigMap", "cnc-machine")["data"].items():
        (tmp_path / file).write_text(text, encoding="utf-8")
    args = server_args(objects)
    local = {"--bind": "127.0.0.1", "--http-port": "0", "--modbus-port": "0", "--ads-port": "0"}
    for i, arg in enumerate(args[:-1]):
        if arg in local:
            args[i + 1] = local[arg]
        elif arg == "--config":
            args[i + 1] = str(tmp_path / Path(args[i + 1]).name)
    env = {**os.environ, "HLI_API_TOKEN": TOKEN}
    proc = subprocess.Popen(
        [str(Path(sys.executable).parent / "hli-server"), "run", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    try:
        yield read_banner(proc, timeout=90)["url"]
    finally:
        stop_server(proc)


@pytest.mark.slow
def test_the_fleets_pod_command_runs_and_the_remote_harness_drives_it(fleet_pod: str) -> None:
    url = fleet_pod
    pod_host = "cnc-0.cnc.hli-fleet.svc.cluster.local"
    assert httpx.get(f"{url}/api/ready", headers={"Host": pod_host}).status_code == 200
    assert httpx.get(f"{url}/api/ready", headers={"Host": "evil.example"}).status_code == 421
    assert httpx.post(f"{url}/api/machine/restart").status_code == 401  # changes need the token
    with RemoteHarness(url, token=TOKEN) as hli:
        assert hli.machine["clock"] == "stepped"
        assert set(hli.ports) >= {"http", "modbus", "ads"}
        hli.operator.load_program(1, "N10 G01 X20 F60000\nN20 M30\n")
        hli.operator.start(1)
        hli.run_until(lambda: hli.image["gpCh[0]^bahn_state.program_state_r"] == 4, max_cycles=3000)
        assert hli.image["gpAx[0]^ipo_state.cmd_pos_r"] == 200_000
