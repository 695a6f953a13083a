"""The text form of the PLC's inputs for an offline check (N-13): ``check --set V.E.NAME=VALUE``, a file of
them (``--set-file``), ``POST /api/check?set=...``. What they do is the engine's
(:mod:`hli_server.engine.presets`).

A preset names a ``V.E.`` variable as a program writes it - ``V.E.PLC_READY``, ``V.E.POS[1][2]``,
``V.E.UserInteraction.Message`` (any case) - and gives a number (``1``, ``-2.5``, ``1e3``), a boolean
(``TRUE``/``FALSE``, any case) or a string in double quotes (``"text"``, for a STRING). A file has one
``V.E.NAME = VALUE`` per line; ``#`` or ``;`` outside a string begins a comment, blank lines are skipped.
Sans I/O.
"""

from __future__ import annotations

import math
import re
from typing import Final

from schemas.external_types import ELEMENT_PATH_FORMS, element_path

__all__ = ["PresetSyntaxError", "parse_preset", "parse_preset_file", "parse_preset_value"]

_NUMBER: Final = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?$")


class PresetSyntaxError(ValueError):
    """A preset's text that is no ``V.E.NAME=VALUE`` (``str(exc)`` says why, with the file's line)."""


def parse_preset_value(text: str) -> bool | int | float | str:
    """``1``, ``-2.5``, ``TRUE``/``FALSE`` (any case), ``"text"``."""
    raw = text.strip()
    if len(raw) >= 2 and raw[0] == raw[-1] == '"':
        return raw[1:-1]
    upper = raw.upper()
    if upper == "TRUE":
        return True
    if upper == "FALSE":
        return False
    if _NUMBER.match(raw) is None:
        raise PresetSyntaxError(
            f"{raw!r} is no value: write a number, TRUE, FALSE or a string in double quotes"
        )
    if "." in raw or "e" in raw or "E" in raw:
        value = float(raw)
        if not math.isfinite(value):
            raise PresetSyntaxError(f"{raw!r} is out of range")
        return value
    return int(raw)


def parse_preset(text: str) -> tuple[str, bool | int | float | str]:
    """``V.E.NAME=value`` (``--set``) -> (``V.E.NAME``, value)."""
    target, sep, value = text.partition("=")
    if not sep or not value.strip():
        raise PresetSyntaxError(f"{text!r}: write V.E.NAME=value (V.E.PLC_READY=1)")
    if element_path(target) is None:
        raise PresetSyntaxError(f"{target.strip()!r}: a preset names a V.E. variable ({ELEMENT_PATH_FORMS})")
    return target.strip(), parse_preset_value(value)


def parse_preset_file(text: str, source: str) -> dict[str, bool | int | float | str]:
    """A file of presets (``--set-file``): ``V.E.NAME = value`` per line, ``#``/``;`` comments."""
    presets: dict[str, bool | int | float | str] = {}
    for number, line in enumerate(text.splitlines(), 1):
        content = _without_comment(line).strip()
        if not content:
            continue
        try:
            name, value = parse_preset(content)
        except PresetSyntaxError as exc:
            raise PresetSyntaxError(f"{source}:{number}: {exc}") from None
        presets[name] = value
    return presets


def _without_comment(line: str) -> str:
    quoted = False
    for k, c in enumerate(line):
        if c == '"':
            quoted = not quoted
        elif c in "#;" and not quoted:
            return line[:k]
    return line
