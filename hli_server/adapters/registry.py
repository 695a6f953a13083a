"""The adapters, their options, and the one function that plans what ``run`` starts (H-03..H-05).

An adapter is a door onto the running machine: the HTTP control API, Modbus TCP, ADS, MQTT. The
runtime starts them in order after the process image exists and before the first cycle, and stops
them in reverse order before the image is unlinked. Each is handed the host
(:mod:`hli_server.adapters.host`), never the runtime or the machine.

The contract (:class:`Adapter`)::

    class MyAdapter:
        name = "modbus"
        Options = ModbusOptions                  # a pydantic model: every option, its default, its help
        def __init__(self, *, bind: str, **options) -> None: ...
        async def start(self, host: AdapterHost) -> None: ...  # open sockets, start tasks; raise on failure
        async def stop(self) -> None: ...                      # close everything; safe to call twice
        def endpoints(self) -> list[str]: ...                  # "Modbus TCP: 127.0.0.1:5020" (for the banner)

:data:`ADAPTERS` names each adapter with its class and its options model (``"module:attr"``, imported
only when used, so a missing optional dependency of one adapter does not break the others; the
options modules are light). :data:`CLI_ALIASES` are the documented short flags of ``hli-server run``
(``--http-port`` is ``http:port``). :func:`plan_adapters` decides, in one place, what starts with which
options: the adapters' own defaults, then the machine file's ``[[adapters]]``, then ``--adapter
NAME:KEY=VALUE``, then the aliases.
"""

from __future__ import annotations

import difflib
import importlib
import importlib.util
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from pydantic import BaseModel, ValidationError

if TYPE_CHECKING:
    from hli_server.adapters.host import AccessPolicy, AdapterHost

__all__ = [
    "ADAPTERS",
    "CLI_ALIASES",
    "Adapter",
    "AdapterError",
    "AdapterKind",
    "AdapterOptions",
    "CliAlias",
    "DoorGuard",
    "available_adapters",
    "create_adapter",
    "door_guards",
    "options_model",
    "options_table_markdown",
    "parse_adapter_spec",
    "plan_adapters",
    "register_adapter",
]

logger = logging.getLogger(__name__)


@runtime_checkable
class Adapter(Protocol):
    """A door onto the running machine, started and stopped by the runtime."""

    name: str

    async def start(self, host: AdapterHost) -> None: ...

    async def stop(self) -> None: ...

    def endpoints(self) -> list[str]:
        """Where it listens, one human-readable line each (printed by ``hli-server run``)."""
        ...


@dataclass(frozen=True, slots=True)
class AdapterKind:
    """One registered adapter."""

    name: str
    target: str
    """``"module:Class"`` of the adapter (imported when it is started)."""
    options: str
    """``"module:Model"`` of its options (a light module: ``run --help`` imports it)."""
    default: bool
    """Started by ``hli-server run`` unless switched off (``--no-http``)."""
    summary: str
    image_only: bool = False
    """Serves the process image and nothing else (no operator, no events)."""
    doors: bool = False
    """Can be served from the doors process (``hli-server run --doors-process``, the default): its host's
    operator, events and step reach the engine's process over a socket (``runtime/remote.py``)."""
    label: str = ""
    """How the banner and the messages name it (``Modbus TCP``)."""
    writes: bool = False
    """A client can change the machine through it (``door_guards``)."""
    allowlist: str | None = None
    """The option that holds its allowlist of peer addresses (``allow``), if it has one."""


@dataclass(frozen=True, slots=True)
class CliAlias:
    """A documented short flag of ``hli-server run`` for an adapter option (or a switch)."""

    flag: str
    adapter: str
    option: str | None
    """The option the flag sets; None: a switch that turns the adapter on or off (``switch``)."""
    switch: bool | None = None
    """For a switch: True starts the adapter, False does not start it."""
    kind: type | tuple[str, ...] = int
    """The value's type, or the allowed values (a choice, case-insensitive)."""
    metavar: str = ""
    help: str = ""


ADAPTERS: dict[str, AdapterKind] = {
    kind.name: kind
    for kind in (
        AdapterKind(
            "http",
            "hli_server.adapters.http.server:HttpApiAdapter",
            "hli_server.adapters.http.options:HttpOptions",
            default=True,
            summary="the HTTP control API (operator panel, remote control of tests)",
            doors=True,
            label="HTTP control API",
            writes=True,
        ),
        AdapterKind(
            "modbus",
            "hli_server.adapters.modbus:ModbusAdapter",
            "hli_server.adapters.modbus:ModbusOptions",
            default=True,
            summary="Modbus TCP view of the process image (H-03)",
            image_only=True,
            doors=True,
            label="Modbus TCP",
            writes=True,
            allowlist="allow",
        ),
        AdapterKind(
            "ads",
            "hli_server.adapters.ads.server:AdsAdapter",
            "hli_server.adapters.ads.options:AdsOptions",
            default=False,
            summary="ADS over TCP: HLI symbols on AMS port 851, FCT-C3 CNC objects on port 551 (H-04, C3-10)",
            image_only=True,
            doors=True,
            label="ADS",
            writes=True,
            allowlist="allow",
        ),
        AdapterKind(
            "mqtt",
            "hli_server.adapters.mqtt:MqttAdapter",
            "hli_server.adapters.mqtt:MqttOptions",
            default=False,
            summary="MQTT events to a broker, JSON per event kind (H-05; docs/mqtt.md)",
            doors=True,
            label="MQTT",
        ),
    )
}
"""Adapter name -> :class:`AdapterKind`, in the order ``run`` starts the default ones."""

CLI_ALIASES: tuple[CliAlias, ...] = (
    CliAlias(
        "--http-port", "http", "port", metavar="N", help="port of the HTTP control API (0: any free port)"
    ),
    CliAlias("--no-http", "http", None, switch=False, help="do not start the HTTP control API"),
    CliAlias(
        "--modbus-port",
        "modbus",
        "port",
        metavar="N",
        help="port of the Modbus TCP view (H-03; 0: any free port)",
    ),
    CliAlias(
        "--modbus-word-order",
        "modbus",
        "word_order",
        kind=("ABCD", "CDAB"),
        help="Modbus: order of the two registers of a 32-bit value (ABCD: high word first)",
    ),
    CliAlias("--modbus-unit-id", "modbus", "unit_id", metavar="N", help="Modbus unit id"),
    CliAlias("--no-modbus", "modbus", None, switch=False, help="do not start the Modbus TCP server"),
    CliAlias(
        "--ads-port",
        "ads",
        "port",
        metavar="N",
        help="start the ADS server (H-04) on this AMS/TCP port (0: any free port)",
    ),
    CliAlias(
        "--ams-net-id",
        "ads",
        "ams_net_id",
        kind=str,
        metavar="NETID",
        help="start the ADS server with this AMS NetId (the clients' target NetId)",
    ),
    CliAlias(
        "--mqtt",
        "mqtt",
        "broker",
        kind=str,
        metavar="HOST[:PORT]",
        help="publish the events to this MQTT broker (H-05; docs/mqtt.md)",
    ),
)
"""The short flags of ``hli-server run``; each is the same as ``--adapter NAME:OPTION=VALUE``."""


class AdapterError(ValueError):
    """An adapter name or option that cannot be used; the message says which and what exists."""


def register_adapter(kind: AdapterKind) -> None:
    """Add (or replace) an adapter (plugins, tests)."""
    ADAPTERS[kind.name] = kind


def _module_exists(target: str) -> bool:
    return importlib.util.find_spec(target.split(":", maxsplit=1)[0]) is not None


def available_adapters() -> list[str]:
    """The registered adapters whose module is present in this installation."""
    return [name for name, kind in ADAPTERS.items() if _module_exists(kind.target)]


AdapterOptions = dict[str, Any]
"""An adapter's options by name. Their values are arbitrary here (TOML values, ``--adapter`` text converted):
each adapter's own model (:func:`options_model`) says what they are and checks them."""


def _load(target: str) -> Any:  # a class or an options model, by its "module:attr" name
    module, attr = target.split(":")
    return getattr(importlib.import_module(module), attr)


def _kind(name: str) -> AdapterKind:
    kind = ADAPTERS.get(name)
    if kind is None or not _module_exists(kind.target):
        match = difflib.get_close_matches(name, available_adapters(), 1)
        hint = f" (did you mean {match[0]!r}?)" if match else ""
        raise AdapterError(f"unknown adapter {name!r}{hint}; available: {', '.join(available_adapters())}")
    return kind


def options_model(name: str) -> type[BaseModel]:
    """The options model of adapter ``name`` (its fields are its options, with defaults and help)."""
    model: type[BaseModel] = _load(_kind(name).options)
    return model


def options_table_markdown(name: str) -> str:
    """The options of adapter ``name`` as a Markdown table (option, default, range, meaning), from its options
    model, and its former option names (docs/api.md has the HTTP door's: a test keeps it current)."""
    model = options_model(name)
    lines = ["| option | default | range | meaning |", "|---|---|---|---|"]
    for field_name, info in model.model_fields.items():
        if info.default_factory is not None:
            default = repr(info.default_factory()).replace("'", '"')  # type: ignore[call-arg]
        elif info.is_required():
            default = "required"
        else:
            default = "none" if info.default is None else str(info.default)
        low = high = None
        for bound in info.metadata:
            low = getattr(bound, "ge", getattr(bound, "gt", low))
            high = getattr(bound, "le", getattr(bound, "lt", high))
        span = f"{low} .. {high}" if low is not None and high is not None else "-"
        lines.append(f"| `{field_name}` | {default} | {span} | {info.description or ''} |")
    renamed: Mapping[str, str | None] = getattr(model, "RENAMED", {})
    if renamed:
        former = ", ".join(
            f"`{old}` (now `{new}`)" if new is not None else f"`{old}` (no effect)"
            for old, new in renamed.items()
        )
        lines += [
            "",
            "Former names, still loaded with a DeprecationWarning and a warning in the log until the next "
            f"minor version (an old and a new name together are refused): {former}.",
        ]
    return "\n".join(lines) + "\n"


def check_options(name: str, options: Mapping[str, Any]) -> AdapterOptions:
    """``options`` validated by the adapter's model (defaults filled in), or AdapterError saying what
    is wrong, with a did-you-mean for misspelled options and the list of the adapter's options."""
    model = options_model(name)
    known = sorted(model.model_fields)
    renamed = getattr(model, "RENAMED", {})  # former names: the model takes them, with a warning
    unknown = sorted(set(options) - set(known) - set(renamed))
    if unknown:
        hints = []
        for key in unknown:
            match = difflib.get_close_matches(key, known, 1)
            hints.append(f"{key!r} (did you mean {match[0]!r}?)" if match else repr(key))
        raise AdapterError(
            f"adapter {name!r}: unknown option {', '.join(hints)}; its options are: {', '.join(known)}"
        )
    try:
        return model.model_validate(dict(options)).model_dump()
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']} (got {_shown(e['loc'], e.get('input'))!r})"
            for e in exc.errors()
        )
        raise AdapterError(f"adapter {name!r}: {problems}") from None


def _shown(loc: Sequence[int | str], value: object) -> object:
    """What an error may quote of an option's value: never a password (a log is read by others)."""
    if any("password" in str(part) for part in loc):
        return "***"
    if isinstance(value, Mapping):
        return {k: "***" if "password" in str(k) else v for k, v in value.items()}
    return value


def create_adapter(name: str, *, bind: str, options: Mapping[str, Any] | None = None) -> Adapter:
    """Build adapter ``name`` with ``bind`` and its ``options`` (checked first: unknown or bad
    options are an :class:`AdapterError`)."""
    checked = check_options(name, options or {})
    cls = _load(_kind(name).target)
    adapter: Adapter = cls(bind=bind, **checked)
    return adapter


def plan_adapters(
    configured: Sequence[tuple[str, Mapping[str, Any]]] = (),
    specs: Sequence[str] = (),
    aliases: Mapping[str, Any] | None = None,
) -> list[tuple[str, AdapterOptions]]:
    """What ``hli-server run`` starts, in order, with which options (each checked by its model).

    1. every adapter whose kind is ``default`` (HTTP, Modbus), with its own defaults;
    2. the machine file's ``[[adapters]]`` (``configured``), in the file's order, add or replace by name;
    3. ``--adapter NAME:KEY=VALUE`` (``specs``) replace an entry of the same name, or add one;
    4. the short flags (``aliases``: flag -> value, None or absent = not given) set one option of
       their adapter, adding it if needed; a switch off (``--no-modbus``) removes it.
    """
    plan: dict[str, AdapterOptions] = {name: {} for name, kind in ADAPTERS.items() if kind.default}
    for name, options in configured:
        _kind(name)
        plan[name] = dict(options)
    for spec in specs:
        name, options = parse_adapter_spec(spec)
        _kind(name)
        for key in options:
            if "password" in key and not key.endswith("_file"):
                logger.warning(
                    "--adapter %s:%s=... shows the password to every user of this computer (ps): give it in "
                    "a file, the environment or the machine file instead (docs/ads.md, docs/mqtt.md)",
                    name,
                    key,
                )
        plan[name] = options
    for alias in CLI_ALIASES:
        value = (aliases or {}).get(alias.flag)
        if value is None or value is False:
            continue
        if alias.option is None:
            if alias.switch:
                plan.setdefault(alias.adapter, {})
            else:
                plan.pop(alias.adapter, None)
            continue
        if alias.adapter in ADAPTERS and _module_exists(ADAPTERS[alias.adapter].target):
            plan.setdefault(alias.adapter, {})[alias.option] = value
    return [(name, check_options(name, options)) for name, options in plan.items()]


@dataclass(frozen=True, slots=True)
class DoorGuard:
    """What keeps strangers from changing the machine through one door (``door_guards``)."""

    door: str
    label: str
    guarded: bool
    how: str
    """what guards it, or that nothing does (the banner's ``access`` lines)"""
    fix: str = ""
    """for an unguarded door: how to guard it"""


def _restricts_addresses(entries: Sequence[str]) -> bool:
    """Whether an ``allow`` list lets in only some peer addresses (loopback or networks, none of them
    every address); AMS NetIds do not count: a client sends whichever it likes."""
    import ipaddress

    some = False
    for entry in entries:
        text = entry.strip().lower()
        parts = text.split(".")
        if len(parts) == 6 and all(p.isdecimal() for p in parts):
            continue  # an AMS NetId
        if text == "loopback":
            some = True
            continue
        try:
            if ipaddress.ip_network(text, strict=False).prefixlen == 0:
                return False
        except ValueError:
            continue
        some = True
    return some


def door_guards(plan: Sequence[tuple[str, Mapping[str, Any]]], policy: AccessPolicy) -> list[DoorGuard]:
    """For each planned door through which a client can change the machine: what guards it
    (docs/reliability.md, finding 8). The API token guards the HTTP door (its changes and the event log);
    Modbus and ADS are guarded by an allowlist that lets in only some peer addresses (their ``allow``); any
    door by being read-only (``--read-only``, ``--read-only-door NAME``). MQTT only publishes."""
    out = []
    for name, options in plan:
        kind = ADAPTERS.get(name)
        if kind is None or not kind.writes:
            continue
        label = kind.label or name
        if policy.for_door(name).read_only:
            out.append(DoorGuard(name, label, True, "read-only: it accepts no write"))
            continue
        if name == "http":
            if policy.api_token:
                guard = "changes, the event log and the recordings need the API token"
                out.append(DoorGuard(name, label, True, guard))
            else:
                out.append(
                    DoorGuard(
                        name,
                        label,
                        False,
                        "no token: anyone who reaches it can change the machine",
                        "give --api-token TOKEN (or HLI_API_TOKEN), or --read-only-door http",
                    )
                )
            continue
        entries = [str(e) for e in options.get(kind.allowlist or "", []) or []]
        if kind.allowlist and _restricts_addresses(entries):
            out.append(DoorGuard(name, label, True, f"clients from {', '.join(entries)} only"))
        else:
            whom = f"its allowlist ({', '.join(entries)}) names no addresses" if entries else "no allowlist"
            out.append(
                DoorGuard(
                    name,
                    label,
                    False,
                    f"{whom}: anyone who reaches it can write the PLC's half of the image",
                    f"give --adapter {name}:{kind.allowlist}=ADDRESSES (your PLCs' IP addresses or networks, "
                    f"e.g. 10.0.0.0/8), or --read-only-door {name}",
                )
            )
    return out


def parse_adapter_spec(spec: str) -> tuple[str, AdapterOptions]:
    """``"modbus:port=5020,word_order=CDAB"`` -> ``("modbus", {"port": 5020, "word_order": "CDAB"})``.

    Values that look like integers become ``int``, ``true``/``false`` become ``bool``; the rest stay text.
    """
    name, _, rest = spec.partition(":")
    name = name.strip()
    if not name:
        raise AdapterError(f"adapter spec {spec!r}: give a name, e.g. 'modbus' or 'modbus:port=5020'")
    options: AdapterOptions = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, eq, raw = item.partition("=")
        if not eq or not key.strip():
            raise AdapterError(f"adapter spec {spec!r}: option {item!r} is not key=value")
        options[key.strip()] = _option_value(raw.strip())
    return name, options


def _option_value(raw: str) -> bool | int | str:
    lowered = raw.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        return int(raw, 0)
    except ValueError:
        return raw
