"""Projection between the engine's HLI objects and the bytes of the image halves (H-01).

The layout knows every signal's engine path (``axes[1].ipo_mc_control.dyn_pos_limit_low.command_w``
below ``MachineHli``). Walking those paths with ``getattr`` for ~200 signals every 1 ms cycle costs
more than the rest of the image work together, so the projection is compiled once per layout into
two straight-line functions per half, in the way ``dataclasses`` and ``namedtuple`` compile their
methods:

* ``pack(machine, pack_into, buffer, offset, *head)`` reads every field of the half from the engine
  objects and packs them with one ``struct.pack_into`` call;
* ``unpack(machine, values)`` assigns a tuple of decoded values to the engine objects with one
  tuple assignment.

Paths come from the layout table and are checked to be plain identifiers before any code is made.
The generated source is kept (``Projection.source``) for reading and debugging.
"""

from __future__ import annotations

import operator
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from hli_server.engine.hli import MachineHli
from schemas.layout import Direction, Layout, Scope, Signal, SignalValueError

__all__ = ["Projection", "compile_projection", "diagnose", "engine_value", "set_engine_value"]

PackFn = Callable[..., None]
UnpackFn = Callable[[MachineHli, Sequence[Any]], None]


@dataclass(frozen=True, slots=True)
class Projection:
    """Compiled accessors for one layout; ``pack[d]`` and ``unpack[d]`` per half."""

    pack: dict[Direction, PackFn]
    unpack: dict[Direction, UnpackFn]
    source: str


def _check_identifier(part: str, signal: Signal) -> str:
    if not part.isidentifier() or part.startswith("__"):
        raise ValueError(f"{signal.st_path}: {part!r} is not a plain attribute name")
    return part


def _parents(signals: Sequence[Signal]) -> tuple[list[str], dict[str, str], list[str]]:
    """Local variable per distinct parent object, and the expression of each field."""
    lines: list[str] = []
    names: dict[str, str] = {}
    fields: list[str] = []
    for s in signals:
        *head, leaf = [_check_identifier(p, s) for p in s.path.split(".")]
        container = "_ch" if s.scope is Scope.CHANNEL else "_ax"
        key = f"{container}[{int(s.index)}]" + "".join(f".{h}" for h in head)
        var = names.get(key)
        if var is None:
            var = names[key] = f"_p{len(names)}"
            lines.append(f"    {var} = {key}")
        fields.append(f"{var}.{leaf}")
    return lines, names, fields


def compile_projection(layout: Layout) -> Projection:
    """Generate and compile the pack/unpack functions of both halves of ``layout``."""
    chunks: list[str] = []
    for d in Direction:
        signals = layout.hli_half(d)  # the V.E. area is the store's (hli_server/image/external.py)
        lines, _, fields = _parents(signals)
        prolog = ["    _ch = machine.channels", "    _ax = machine.axes", *lines]
        args = ",\n        ".join(fields) if fields else ""
        chunks.append(
            "\n".join(
                [
                    f"def pack_{d.value}(machine, pack_into, buffer, offset, *head):",
                    *prolog,
                    f"    pack_into(buffer, offset, *head,\n        {args})" if fields else "    pass",
                ]
            )
        )
        targets = ",\n        ".join(fields)
        chunks.append(
            "\n".join(
                [
                    f"def unpack_{d.value}(machine, values):",
                    *prolog,
                    f"    (\n        {targets},\n    ) = values" if fields else "    pass",
                ]
            )
        )
    source = "\n\n\n".join(chunks) + "\n"
    namespace: dict[str, Any] = {}
    exec(compile(source, f"<hli-projection {layout.hash[:12]}>", "exec"), namespace)
    return Projection(
        pack={d: namespace[f"pack_{d.value}"] for d in Direction},
        unpack={d: namespace[f"unpack_{d.value}"] for d in Direction},
        source=source,
    )


def engine_value(machine: MachineHli, signal: Signal) -> Any:
    """The engine's value of one signal, walking the path (slow; for diagnostics and tests)."""
    container = machine.channels if signal.scope is Scope.CHANNEL else machine.axes
    obj: Any = container[signal.index]
    for part in signal.path.split("."):
        obj = getattr(obj, part)
    return obj


def set_engine_value(machine: MachineHli, signal: Signal, value: Any) -> None:
    """Set one signal on the engine objects (slow; for tests)."""
    container = machine.channels if signal.scope is Scope.CHANNEL else machine.axes
    head, _, leaf = signal.path.rpartition(".")
    parent: Any = operator.attrgetter(head)(container[signal.index]) if head else container[signal.index]
    setattr(parent, leaf, value)


def diagnose(layout: Layout, machine: MachineHli, direction: Direction, exc: BaseException) -> Exception:
    """Turn a failed pack into an error that names the signal and the bad value."""
    counts = (len(machine.channels), len(machine.axes))
    if counts[0] < len(layout.channels) or counts[1] < len(layout.axes):
        return ValueError(
            f"the engine has {counts[0]} channels and {counts[1]} axes, the image layout "
            f"{len(layout.channels)} and {len(layout.axes)}: build both from the same configuration"
        )
    for s in layout.hli_half(direction):
        try:
            value = engine_value(machine, s)
        except AttributeError as err:
            return AttributeError(f"{s.st_path}: the engine object has no {s.engine_path} ({err})")
        try:
            s.coerce(value)
        except SignalValueError as err:
            return SignalValueError(f"{err} (the engine's value at {s.engine_path})")
    return exc if isinstance(exc, Exception) else RuntimeError(str(exc))
