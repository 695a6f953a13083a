"""The MQTT adapter's options, its place in ``run``'s plan, and its encoding (H-05); no broker needed."""

from __future__ import annotations

import json
import math

import pytest
from click.testing import CliRunner

from hli_server.adapters.mqtt import (
    DEFAULT_PORT,
    DEFAULT_TLS_PORT,
    MqttAdapter,
    MqttOptions,
    topic_safe,
)
from hli_server.adapters.registry import AdapterError, check_options, plan_adapters
from hli_server.cli import main
from hli_server.codecs.event_json import encode_event
from schemas.events import FaultInjected, ModeChanged

pytestmark = pytest.mark.req("H-05")


@pytest.mark.parametrize(
    ("broker", "host", "port"),
    [
        ("127.0.0.1", "127.0.0.1", DEFAULT_PORT),
        ("mqtt:1884", "mqtt", 1884),
        (" broker.example ", "broker.example", DEFAULT_PORT),
        ("[::1]:1884", "::1", 1884),
        ("[::1]", "::1", DEFAULT_PORT),
        ("::1", "::1", DEFAULT_PORT),
    ],
)
def test_broker_host_and_port(broker: str, host: str, port: int) -> None:
    assert MqttOptions(broker=broker).host_port() == (host, port)


def test_tls_changes_the_default_port_and_the_scheme() -> None:
    assert MqttOptions(broker="h", tls=True).host_port() == ("h", DEFAULT_TLS_PORT)
    assert MqttOptions(broker="h", ca_file="ca.pem").use_tls
    assert MqttAdapter(broker="h:1", tls=True).url == "mqtts://h:1"
    assert MqttAdapter(broker="[::1]:1").url == "mqtt://[::1]:1"


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"broker": "h:99999"}, "port '99999' is not a number in 1..65535"),
        ({"broker": ":1883"}, "give a host name"),
        ({"broker": "[::1"}, "IPv6"),
        ({"topic_prefix": "hli/+/"}, "wildcards cannot be published to"),
        ({"key_file": "k.pem"}, "key_file needs cert_file"),
        ({"qos": 3}, "less than or equal to 2"),
        ({"queue_size": 0}, "greater than or equal to 1"),
    ],
)
def test_bad_options_are_refused_with_what_and_where(options: dict[str, object], message: str) -> None:
    with pytest.raises(AdapterError, match="adapter 'mqtt'") as info:
        check_options("mqtt", options)
    assert message in str(info.value)


def test_a_misspelled_option_gets_a_did_you_mean() -> None:
    with pytest.raises(AdapterError, match=r"'brocker' \(did you mean 'broker'\?\)"):
        check_options("mqtt", {"brocker": "h"})


def test_the_prefix_ends_with_a_slash_and_the_machine_name_is_one_level() -> None:
    assert MqttOptions(topic_prefix="farm/cell1").topic_prefix == "farm/cell1/"
    assert MqttOptions(topic_prefix="").topic_prefix == ""
    assert topic_safe("mill #2/left+") == "mill _2_left_"
    assert topic_safe("  ") == "machine"


def test_mqtt_is_not_started_unless_asked() -> None:
    assert "mqtt" not in dict(plan_adapters())
    plan = dict(plan_adapters(aliases={"--mqtt": "broker.local:1884"}))
    assert plan["mqtt"]["broker"] == "broker.local:1884"
    assert plan["mqtt"]["qos"] == 1
    assert {"http", "modbus"} <= set(plan)


def test_the_machine_file_and_adapter_specs_set_the_options() -> None:
    configured = [("mqtt", {"broker": "a:1883", "topic_prefix": "shop/", "qos": 0})]
    assert dict(plan_adapters(configured))["mqtt"]["topic_prefix"] == "shop/"
    plan = dict(plan_adapters(configured, ["mqtt:broker=b:1883,username=1234,queue_size=100"]))
    assert plan["mqtt"]["broker"] == "b:1883"
    assert plan["mqtt"]["username"] == "1234"  # text, though it looks like a number
    assert plan["mqtt"]["queue_size"] == 100
    assert plan["mqtt"]["qos"] == 1  # --adapter replaces the machine file's entry
    assert dict(plan_adapters(configured, aliases={"--mqtt": "c"}))["mqtt"]["broker"] == "c"


def test_the_password_comes_from_the_environment_and_is_never_shown(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HLI_MQTT_PASSWORD", "from-env")
    adapter = MqttAdapter(username="u")
    assert adapter.options.password is not None
    assert adapter.options.password.get_secret_value() == "from-env"
    assert "from-env" not in repr(adapter.options)
    assert MqttAdapter(password="given").options.password.get_secret_value() == "given"  # type: ignore[union-attr]


def test_events_are_compact_json_with_the_envelope_and_without_nan() -> None:
    event = FaultInjected(
        cycle=7,
        time_s=0.007,
        channel=1,
        axis="X",
        faults={"friction": math.nan},
        changed={"friction": math.inf},
    )
    topic, payload = encode_event(event, prefix="hli/demo/", machine="demo", seq=3, wall=0.25)
    assert topic == "hli/demo/ax/X/faults"
    message = json.loads(payload)  # strict JSON: NaN and Infinity became null
    assert message == {
        "machine": "demo",
        "kind": "fault",
        "seq": 3,
        "cycle": 7,
        "time_s": 0.007,
        "wall_time": "1970-01-01T00:00:00.250Z",
        "channel": 1,
        "axis": "X",
        "data": {"axis": "X", "faults": {"friction": None}, "changed": {"friction": None}},
    }
    mode = ModeChanged(cycle=1, time_s=0.001, channel=2, mode="manual", previous="automatic")
    assert encode_event(mode, prefix="", machine="m", seq=1, wall=0)[0] == "ch/2/state"


def test_run_offers_mqtt_and_refuses_a_bad_broker_before_starting() -> None:
    runner = CliRunner()
    assert "--mqtt HOST[:PORT]" in runner.invoke(main, ["run", "--help"]).output
    result = runner.invoke(main, ["run", "--mqtt", "broker:notaport", "--cycles", "1"])
    assert result.exit_code == 2
    assert "broker 'broker:notaport': port 'notaport' is not a number" in result.output
