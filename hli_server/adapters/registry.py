"""How adapters plug into the runtime (H-03, H-04, H-05 later; the HTTP control API now).

An adapter is a door onto the running machine: the HTTP control API, Modbus TCP, ADS, MQTT. The
runtime starts the adapters in the order they are given after the process image exists and before
the first cycle, and stops them in the reverse order before the image is unlinked.

The contract (:class:`Adapter`)::

    class MyAdapter:
        name = "modbus"
        def __init__(self, *, bind: str, port: int = 502, **more_options) -> None: ...
        async def start(self, runtime: Runtime) -> None: ...   # open sockets, start tasks; raise on failure
        async def stop(self) -> None: ...                      # close everything; safe to call twice
        def endpoints(self) -> list[str]: ...                  # "modbus://127.0.0.1:5020" (for the banner)

Adapters are named in :data:`ADAPTERS` (``name -> "module:factory"``, imported only when used, so a
missing optional dependency of one adapter does not break the others). The factory is called with
``bind=<address>`` and the adapter's options (``--adapter modbus:port=5020`` on the command line, or
``adapter_options`` of :class:`~hli_server.runtime.Runtime`). Registering an adapter is one line
here, or :func:`register_adapter` at run time (plugins, tests).
"""

from __future__ import annotations

import difflib
import importlib
import importlib.util
import inspect
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    from hli_server.runtime import Runtime

__all__ = [
    "ADAPTERS",
    "Adapter",
    "AdapterError",
    "available_adapters",
    "create_adapter",
    "parse_adapter_spec",
    "register_adapter",
]


@runtime_checkable
class Adapter(Protocol):
    """A door onto the running machine, started and stopped by the runtime."""

    name: str

    async def start(self, runtime: Runtime) -> None: ...

    async def stop(self) -> None: ...

    def endpoints(self) -> list[str]:
        """Where it listens, one human-readable line each (printed by ``hli-server run``)."""
        ...


AdapterFactory = Callable[..., Adapter]

ADAPTERS: dict[str, str | AdapterFactory] = {
    "http": "hli_server.adapters.http_api:HttpApiAdapter",
    "modbus": "hli_server.adapters.modbus:ModbusAdapter",
    "ads": "hli_server.adapters.ads:AdsAdapter",
    "mqtt": "hli_server.adapters.mqtt:MqttAdapter",
}
"""Adapter name -> ``"module:factory"`` (imported lazily) or the factory itself."""


class AdapterError(ValueError):
    """An adapter name or option that cannot be used; the message says which and what exists."""


def register_adapter(name: str, factory: str | AdapterFactory) -> None:
    """Add (or replace) an adapter under ``name``."""
    ADAPTERS[name] = factory


def _module_exists(target: str | AdapterFactory) -> bool:
    if not isinstance(target, str):
        return True
    return importlib.util.find_spec(target.split(":", maxsplit=1)[0]) is not None


def available_adapters() -> list[str]:
    """The registered adapters whose module is present in this installation."""
    return sorted(name for name, target in ADAPTERS.items() if _module_exists(target))


def _resolve(name: str) -> AdapterFactory:
    target = ADAPTERS.get(name)
    if target is None or not _module_exists(target):
        raise AdapterError(f"unknown adapter {name!r}; available: {', '.join(available_adapters())}")
    if not isinstance(target, str):
        return target
    module, attr = target.split(":")
    factory: AdapterFactory = getattr(importlib.import_module(module), attr)
    return factory


def create_adapter(name: str, *, bind: str, options: Mapping[str, Any] | None = None) -> Adapter:
    """Build adapter ``name`` with ``bind`` and its ``options``; unknown options are an error."""
    factory = _resolve(name)
    given = dict(options or {})
    accepted = _option_names(factory)
    unknown = sorted(set(given) - accepted) if accepted is not None else []
    if unknown:
        hints = []
        for key in unknown:
            match = difflib.get_close_matches(key, sorted(accepted or []), 1)
            hints.append(f"{key!r} (did you mean {match[0]!r}?)" if match else repr(key))
        raise AdapterError(
            f"adapter {name!r}: unknown option {', '.join(hints)}; "
            f"its options are: {', '.join(sorted(accepted or []))}"
        )
    try:
        return factory(bind=bind, **given)
    except TypeError as exc:
        raise AdapterError(f"adapter {name!r}: bad options {given}: {exc}") from exc


def _option_names(factory: AdapterFactory) -> set[str] | None:
    """The keyword options a factory takes (besides ``bind``); None when it takes any (``**kwargs``)."""
    try:
        params = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):
        return None
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return None
    named = (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return {p.name for p in params if p.kind in named and p.name != "bind"}


def parse_adapter_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"modbus:port=5020,word_order=little"`` -> ``("modbus", {"port": 5020, "word_order": "little"})``.

    Values that look like integers become ``int``, ``true``/``false`` become ``bool``; the rest stay text.
    """
    name, _, rest = spec.partition(":")
    name = name.strip()
    if not name:
        raise AdapterError(f"adapter spec {spec!r}: give a name, e.g. 'modbus' or 'modbus:port=5020'")
    options: dict[str, Any] = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, eq, raw = item.partition("=")
        if not eq or not key.strip():
            raise AdapterError(f"adapter spec {spec!r}: option {item!r} is not key=value")
        options[key.strip()] = _option_value(raw.strip())
    return name, options


def _option_value(raw: str) -> Any:
    lowered = raw.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        return int(raw, 0)
    except ValueError:
        return raw
