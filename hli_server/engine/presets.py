"""The PLC's inputs for an offline check (N-13): ``V.E.`` values set before the program starts, since no PLC
is attached to change them (``hli-server check --set V.E.PLC_READY=1``, ``--set-file FILE``, ``POST
/api/check``'s ``presets``, ``hli.check(presets=...)``; docs/check.md "A program that waits for the PLC").

A preset names a declared ``V.E.`` variable as a program writes it - ``V.E.PLC_READY``, ``V.E.POS[1][2]``,
``V.E.UserInteraction.Message`` (case does not matter) - with a number, a boolean or, for a STRING, a
string. Their text form (``--set``, ``--set-file``) is read by :mod:`hli_server.codecs.presets`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final

from hli_server.engine.external import ExternalValue, ExternalVariableError, ExternalVariables
from schemas.external_types import ELEMENT_PATH_FORMS, element_path

__all__ = ["MAX_PRESETS", "PresetError", "PresetValue", "apply_presets"]

PresetValue = bool | int | float | str

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
        found = element_path(target)
        if found is None:
            raise PresetError(f"{target!r}: a preset names a V.E. variable ({ELEMENT_PATH_FORMS})")
        name, index = found
        spec = external.spec(name, channel)
        if spec is None:
            raise PresetError(str(external.unknown(name, channel)))
        try:
            spec.flat_index(index)
            spec.coerce(value)
        except ExternalVariableError as exc:
            raise PresetError(str(exc)) from None
        writes.append((name, value, index))
    for name, checked, index in writes:
        external.write(name, channel, checked, index)
