"""The PLC's inputs for an offline check (N-13): ``V.E.`` values set before the program starts, since no PLC
is attached to change them (``hli-server check --set V.E.PLC_READY=1``, ``--set-file FILE``, ``POST
/api/check``'s ``presets``, ``hli.check(presets=...)``; docs/check.md "A program that waits for the PLC").

A preset names a declared ``V.E.`` variable as a program writes it - ``V.E.PLC_READY``, ``V.E.POS[1][2]``
(case does not matter) - with a number or a boolean (a string for a variable that holds one, once V.E.
strings exist). Their text form (``--set``, ``--set-file``) is read by :mod:`hli_server.codecs.presets`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Final

from hli_server.engine.external import ExternalValue, ExternalVariableError, ExternalVariables

__all__ = ["MAX_PRESETS", "PresetError", "PresetValue", "apply_presets"]

PresetValue = bool | int | float | str

_TARGET: Final = re.compile(r"\s*V\.E\.([A-Za-z_][A-Za-z0-9_]*)\s*((?:\[\s*[0-9]+\s*\]\s*)*)$", re.IGNORECASE)
_INDEX: Final = re.compile(r"\[\s*([0-9]+)\s*\]")
MAX_PRESETS: Final = 4096
"""Presets one check takes at most."""


class PresetError(ValueError):
    """A preset that cannot be taken: a variable not declared, an index or a value its type does not hold
    (``str(exc)`` says which and why)."""


def apply_presets(external: ExternalVariables, channel: int, presets: Mapping[str, PresetValue]) -> None:
    """Write ``presets`` into ``external`` as channel ``channel``'s program sees them (its own variable of
    the name, else the global one). :class:`PresetError` before anything is written if one cannot be
    taken."""
    if len(presets) > MAX_PRESETS:
        raise PresetError(f"{len(presets)} presets: at most {MAX_PRESETS}")
    writes: list[tuple[str, ExternalValue, list[int]]] = []
    for target, value in presets.items():
        found = _TARGET.match(target)
        if found is None:
            raise PresetError(f"{target!r}: a preset names a V.E. variable (V.E.NAME or V.E.NAME[i])")
        name = found.group(1)
        index = [int(i) for i in _INDEX.findall(found.group(2))]
        spec = external.spec(name, channel)
        if spec is None:
            raise PresetError(f"V.E.{name} is not declared in the machine file (external_variables)")
        if isinstance(value, str):
            # V.E. variables here are numbers and booleans: a string becomes a value with V.E. STRING
            raise PresetError(f"V.E.{name} is a {spec.type.value}: a string is not a value for it")
        try:
            spec.flat_index(index)
            spec.coerce(value)
        except ExternalVariableError as exc:
            raise PresetError(str(exc)) from None
        writes.append((name, value, index))
    for name, number, index in writes:
        external.write(name, channel, number, index)
