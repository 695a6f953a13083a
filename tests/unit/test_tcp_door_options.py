"""One options model for the TCP doors (issue 28 item 5): Modbus and ADS share the names ``port``,
``max_connections``, ``idle_timeout_s``, ``frame_timeout_s`` and ``allow``; the names they used before are
accepted with a DeprecationWarning (and a log line) for one minor version."""

from __future__ import annotations

import logging

import pytest
from pydantic import ValidationError

from hli_server.adapters.ads import AdsOptions
from hli_server.adapters.modbus import ModbusAdapter, ModbusOptions
from hli_server.adapters.tcp import TcpDoorOptions

SHARED = {"port", "max_connections", "idle_timeout_s", "frame_timeout_s", "allow"}


@pytest.mark.parametrize("model", [ModbusOptions, AdsOptions])
def test_every_tcp_door_has_the_shared_names(model: type[TcpDoorOptions]) -> None:
    assert issubclass(model, TcpDoorOptions)
    assert set(TcpDoorOptions.model_fields) == SHARED
    assert model.model_fields.keys() >= SHARED
    options = model.model_validate({"idle_timeout_s": 60, "frame_timeout_s": 1.5, "max_connections": 4})
    assert (options.idle_timeout_s, options.frame_timeout_s, options.max_connections) == (60, 1.5, 4)


@pytest.mark.parametrize(
    ("old", "new", "value"),
    [("idle_timeout", "idle_timeout_s", 30.0), ("frame_timeout", "frame_timeout_s", 1.0)],
)
def test_the_old_modbus_names_still_load_with_a_deprecation_warning(
    old: str, new: str, value: float, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING), pytest.warns(DeprecationWarning, match=f"'{old}' is now '{new}'"):
        options = ModbusOptions.model_validate({old: value})
    assert getattr(options, new) == value
    assert f"'{old}' is now '{new}'" in caplog.text  # the operator sees it in the server's log too
    with pytest.warns(DeprecationWarning, match=f"'{old}' is now '{new}'"):
        adapter = ModbusAdapter(**{old: value})
    assert getattr(adapter.options, new) == value


@pytest.mark.parametrize(
    ("model", "old"), [(ModbusOptions, "evict_after"), (AdsOptions, "evict_idle_after_s")]
)
def test_an_old_option_without_effect_loads_with_a_deprecation_warning(
    model: type[TcpDoorOptions], old: str
) -> None:
    with pytest.warns(DeprecationWarning, match=f"'{old}' has no effect"):
        options = model.model_validate({old: 5.0})
    assert options == model()


def test_an_old_and_a_new_name_together_are_refused() -> None:
    with pytest.raises(ValidationError, match="old name of 'idle_timeout_s'"):
        ModbusOptions.model_validate({"idle_timeout": 1, "idle_timeout_s": 2})


def test_an_unknown_name_is_still_refused() -> None:
    with pytest.raises(ValidationError, match="idle_timeout_ms"):
        AdsOptions.model_validate({"idle_timeout_ms": 1})
