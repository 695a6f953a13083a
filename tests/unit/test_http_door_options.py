"""The HTTP door's option names follow the TCP doors' (docs/runtime.md, "Adapters"): seconds end in ``_s``,
the same names mean the same on every door; the names used before still load with a DeprecationWarning
and a log line for one minor version, through the model, a machine file's ``[[adapters]]`` and
``--adapter http:KEY=VALUE``; an old and a new name together are refused with a message that names both."""

from __future__ import annotations

import logging
import re
from importlib import resources
from pathlib import Path

import pytest
from pydantic import ValidationError

from hli_server.adapters.http.options import HttpOptions
from hli_server.adapters.modbus import ModbusOptions
from hli_server.adapters.options import RenamedOptions
from hli_server.adapters.registry import AdapterError, check_options, options_table_markdown, plan_adapters
from hli_server.adapters.tcp import TcpDoorOptions
from hli_server.configuration import load_machine

RENAMED = [
    ("graceful_timeout", "graceful_timeout_s", 7),
    ("idle_timeout", "idle_timeout_s", 12.5),
    ("request_timeout", "request_timeout_s", 3.0),
    ("write_timeout", "write_timeout_s", 4.0),
    ("keep_alive", "keep_alive_s", 9),
]


def test_the_http_door_names_seconds_as_the_tcp_doors_do() -> None:
    fields = set(HttpOptions.model_fields)
    seconds = {name for name, f in HttpOptions.model_fields.items() if "seconds" in (f.description or "")}
    assert seconds == {
        "graceful_timeout_s",
        "idle_timeout_s",
        "request_timeout_s",
        "write_timeout_s",
        "keep_alive_s",
    }
    assert all(name.endswith("_s") for name in seconds)
    shared = set(TcpDoorOptions.model_fields) - {
        "frame_timeout_s",
        "allow",
    }  # HTTP: request_timeout_s, policy
    assert shared <= fields
    assert issubclass(HttpOptions, RenamedOptions)
    assert issubclass(TcpDoorOptions, RenamedOptions)  # one mechanism for every door


@pytest.mark.parametrize(("old", "new", "value"), RENAMED)
def test_a_new_name_loads_without_a_warning(
    old: str, new: str, value: float, recwarn: pytest.WarningsRecorder
) -> None:
    options = HttpOptions.model_validate({new: value})
    assert getattr(options, new) == value
    assert not [w for w in recwarn if issubclass(w.category, DeprecationWarning)]
    assert old not in HttpOptions.model_fields


@pytest.mark.parametrize(("old", "new", "value"), RENAMED)
def test_an_old_name_loads_with_a_deprecation_warning_and_a_log_line(
    old: str, new: str, value: float, caplog: pytest.LogCaptureFixture
) -> None:
    with (
        caplog.at_level(logging.WARNING),
        pytest.warns(DeprecationWarning, match=f"HTTP option '{old}' is now '{new}'"),
    ):
        options = HttpOptions.model_validate({old: value})
    assert getattr(options, new) == value
    assert options == HttpOptions.model_validate({new: value})
    assert f"'{old}' is now '{new}'; the old name goes in the next minor version" in caplog.text


@pytest.mark.parametrize(("old", "new", "value"), RENAMED)
def test_an_old_and_a_new_name_together_are_refused(old: str, new: str, value: float) -> None:
    with pytest.raises(ValidationError, match=f"'{old}' is the old name of '{new}': give one of them"):
        HttpOptions.model_validate({old: value, new: value})


def test_the_adapter_option_cli_takes_old_names_with_a_warning_and_refuses_both() -> None:
    """``--adapter http:KEY=VALUE`` goes through the registry's check (which refuses the names it does not
    know)."""
    with pytest.warns(DeprecationWarning, match="'request_timeout' is now 'request_timeout_s'"):
        plan = dict(plan_adapters(specs=["http:port=0,request_timeout=2,write_timeout_s=3"]))
    assert plan["http"]["request_timeout_s"] == 2
    assert plan["http"]["write_timeout_s"] == 3
    assert "request_timeout" not in plan["http"]
    with pytest.raises(
        AdapterError, match="'idle_timeout' is the old name of 'idle_timeout_s': give one of them"
    ):
        plan_adapters(specs=["http:idle_timeout=1,idle_timeout_s=2"])
    with pytest.raises(
        AdapterError, match=r"unknown option 'idle_timeout_ms' \(did you mean 'idle_timeout_s'\?\)"
    ):
        check_options("http", {"idle_timeout_ms": 1})


def test_the_old_modbus_names_load_through_the_registry_too() -> None:
    """The TCP doors' former names (``ModbusOptions.RENAMED``, ``AdsOptions.RENAMED``) reach the model from a
    machine file and the CLI (before, the registry refused them as unknown options)."""
    with pytest.warns(DeprecationWarning, match="'idle_timeout' is now 'idle_timeout_s'"):
        assert check_options("modbus", {"idle_timeout": 30})["idle_timeout_s"] == 30
    with pytest.warns(DeprecationWarning, match="'evict_idle_after_s' has no effect"):
        check_options("ads", {"evict_idle_after_s": 5})
    assert "idle_timeout" in ModbusOptions.RENAMED


def test_a_machine_file_with_the_old_http_names_loads_with_a_warning(tmp_path: Path) -> None:
    machines = resources.files("hli_server.machines")
    for entry in machines.iterdir():
        if entry.name.endswith((".toml", ".lis")):
            (tmp_path / entry.name).write_text(entry.read_text(encoding="utf-8"), encoding="utf-8")
    machine = tmp_path / "demo.toml"
    with machine.open("a", encoding="utf-8") as f:
        f.write(
            '\n[[adapters]]\nname = "http"\noptions = { port = 0, keep_alive = 9, graceful_timeout_s = 1 }\n'
        )
    config = load_machine(machine)
    configured = [(a.name, dict(a.options)) for a in config.adapters]
    with pytest.warns(DeprecationWarning, match="'keep_alive' is now 'keep_alive_s'"):
        plan = dict(plan_adapters(configured))
    assert plan["http"]["keep_alive_s"] == 9
    assert plan["http"]["graceful_timeout_s"] == 1


def test_the_docs_list_the_http_door_options_as_the_model_has_them() -> None:
    """docs/api.md, "Options of the door", is generated from the model
    (``options_table_markdown("http")``)."""
    doc = (Path(__file__).resolve().parents[2] / "docs" / "api.md").read_text(encoding="utf-8")
    match = re.search(
        r"<!-- BEGIN GENERATED: http options -->\n(.*)<!-- END GENERATED: http options -->", doc, re.S
    )
    assert match, "docs/api.md lost its generated HTTP options markers"
    assert match[1] == options_table_markdown("http"), (
        "docs/api.md is out of date: paste hli_server.adapters.registry.options_table_markdown('http') "
        "between the GENERATED markers"
    )
    for old, new in HttpOptions.RENAMED.items():
        assert f"`{old}` (now `{new}`)" in match[1]
