"""The kernel's list of external variables (``var[i].name ...``) read into ``external_variables`` (N-05).

The kernel declares the V.E. variables of a channel in a text list named by the start-up parameter
P-STUP-00146 ``ve_var[i]`` ("Name of the list file for external variables",
https://infosys.beckhoff.com/content/1033/tf5200_startup_list/123614347.html); its entries are the
P-EXTV parameters ("Parameterising the memory layout of V.E. variables",
https://infosys.beckhoff.com/content/1033/tf5200_external_variables/307199243.html)::

    number_used_variables            2
    var[0].name                      PLC_READY        (global V.E.)
    var[0].type                      BOOLEAN
    var[0].scope                     GLOBAL
    var[0].synchronisation           FALSE
    var[1].name                      PART_COUNT
    var[1].type                      SGN32
    var[1].scope                     CHANNEL
    var[1].access_rights             READ_WRITE
    var[1].array_elements            10

A ``[[channels]]`` table of the machine file names such a list with ``external_variables_list``; its
CHANNEL variables belong to that channel, its GLOBAL ones to the global area (two channels' lists may
both declare a global variable, identically). What is read:

* ``var[i].name`` (P-EXTV-00001, required), ``.type`` (P-EXTV-00003, default UNS32),
  ``.scope`` (P-EXTV-00004, GLOBAL or CHANNEL, default CHANNEL), ``.synchronisation`` (P-EXTV-00005,
  default TRUE as in the kernel), ``.access_rights`` (P-EXTV-00006, default READ_WRITE),
  ``.array_elements`` (P-EXTV-00007; ``.array_size`` of the older syntax, 0 = no array);
* ``number_used_variables`` (P-EXTV-00010; ``anzahl_belegt`` of the older syntax): every ``var[i]``
  must lie below it;
* accepted without effect, with a warning: ``var[i].byte_offset``, ``.index``, ``.size``,
  ``.create_hmi_interface`` and the general ``check_overlapping_variables``, ``auto_memory_mode``,
  ``init``, ``use_extended_string_var`` (the image places the variables itself,
  docs/process-image.md);
* refused by name: the type STRING and user-defined types, the ``struct[i].*`` type definitions (not
  simulated, docs/configuration.md).

Comments: ``#`` to the end of the line, and a ``( ...)`` after the value (the kernel's own examples
write them so). Every finding names file, line and key.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from hli_server.configuration.errors import Origin

__all__ = ["ExternalList", "parse_external_list"]

_VAR_KEY = re.compile(r"^var\[(\d+)\]\.([A-Za-z_]+)$")
_TYPES = ("BOOLEAN", "SGN08", "UNS08", "SGN16", "UNS16", "SGN32", "UNS32", "REAL32", "REAL64")
_NOT_SIMULATED_TYPES = ("STRING", "VSTRING")
_IGNORED_VAR = ("byte_offset", "index", "size", "create_hmi_interface")
_IGNORED_GENERAL = ("check_overlapping_variables", "auto_memory_mode", "init", "use_extended_string_var")
_COUNT_KEYS = ("number_used_variables", "anzahl_belegt")
_MAX_INDEX = 214
"""``var[i]``, i = 0 .. 214 (the kernel's range)."""
_MAX_LINES = 20_000


@dataclass
class ExternalList:
    """The variables of one list, as ``external_variables`` entries, with where each came from."""

    source: str
    variables: list[dict[str, Any]] = field(default_factory=list)
    origins: list[dict[str, Origin]] = field(default_factory=list)
    """Per variable: field name -> where it was set (``name`` always)."""
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def _bool(raw: str) -> bool | None:
    lowered = raw.lower()
    if lowered in ("true", "1"):
        return True
    if lowered in ("false", "0"):
        return False
    return None


def _value(content: str) -> tuple[str, str]:
    """``key value (comment)`` -> (key, value): the first word after the key is the value."""
    key, _, rest = content.partition(" ")
    if "\t" in key:
        key, _, more = key.partition("\t")
        rest = f"{more} {rest}"
    rest = rest.strip()
    if rest.startswith('"'):
        end = rest.find('"', 1)
        return key, rest[1:end] if end > 0 else rest[1:]
    return key, rest.split(None, 1)[0] if rest else ""


def parse_external_list(text: str, *, source: str, channel: int) -> ExternalList:
    """Read one list of external variables of channel ``channel`` (its CHANNEL variables)."""
    result = ExternalList(source)
    records: dict[int, dict[str, tuple[str, Origin]]] = {}
    count: tuple[int, Origin] | None = None
    seen: dict[str, int] = {}
    lines = text.splitlines()
    if len(lines) > _MAX_LINES:
        result.errors.append(
            f"{source}: {len(lines)} lines; a list of external variables has at most {_MAX_LINES}"
        )
        return result
    for line_no, line in enumerate(lines, 1):
        content = line.split("#", 1)[0].strip()
        if not content:
            continue
        key, raw = _value(content)
        origin = Origin(source, line_no, key)
        if key in seen:
            result.errors.append(f"{origin.where()}: given twice (first in line {seen[key]})")
            continue
        seen[key] = line_no
        if key.lower() in ("end", "ende"):
            break
        if not raw:
            result.errors.append(f"{origin.where()}: no value (write `{key} <value>`)")
            continue
        match = _VAR_KEY.match(key)
        if match:
            index, name = int(match[1]), match[2]
            if index > _MAX_INDEX:
                result.errors.append(
                    f"{origin.where()}: var[{index}]: the kernel numbers them 0 to {_MAX_INDEX}"
                )
                continue
            records.setdefault(index, {})[name] = (raw, origin)
            continue
        if key in _COUNT_KEYS:
            if not raw.isdigit():
                result.errors.append(f"{origin.where()}: {raw!r} is not a count")
            else:
                count = (int(raw), origin)
            continue
        if key in _IGNORED_GENERAL:
            result.warnings.append(
                f"{origin.where()}: accepted without effect here (the image places the variables itself)"
            )
            continue
        if key.startswith("struct["):
            result.errors.append(
                f"{origin.where()}: V.E. structures (user-defined types, P-EXTV-00015..21) are not "
                "simulated; declare elementary variables (docs/configuration.md)"
            )
            continue
        result.errors.append(f"{origin.where()}: unknown entry of a list of external variables")
    for index in sorted(records):
        variable = _record(index, records[index], channel, result)
        if variable is None:
            continue
        if count is not None and index >= count[0]:
            result.errors.append(
                f"{variable[1]['name'].where()}: var[{index}] lies beyond number_used_variables "
                f"{count[0]} ({count[1].where()}); it would not be configured"
            )
            continue
        result.variables.append(variable[0])
        result.origins.append(variable[1])
    return result


def _record(
    index: int, entries: dict[str, tuple[str, Origin]], channel: int, result: ExternalList
) -> tuple[dict[str, Any], dict[str, Origin]] | None:
    """One ``var[i]`` as an ``external_variables`` entry (None when it is refused)."""
    if "name" not in entries:
        first = min(entries.values(), key=lambda e: e[1].line)[1]
        result.errors.append(f"{first.file}:{first.line}: var[{index}] has no var[{index}].name")
        return None
    variable: dict[str, Any] = {"name": entries["name"][0], "type": "UNS32", "synchronous": True}
    origins: dict[str, Origin] = {"name": entries["name"][1]}
    ok = True
    scope = "CHANNEL"
    for key, (raw, origin) in entries.items():
        where = origin.where()
        if key == "name":
            continue
        if key == "type":
            typed = raw.upper()
            if typed in _TYPES:
                variable["type"], origins["type"] = typed, origin
            elif typed in _NOT_SIMULATED_TYPES:
                result.errors.append(
                    f"{where}: V.E. variables of type {typed} are not simulated (docs/configuration.md)"
                )
                ok = False
            else:
                result.errors.append(
                    f"{where}: {raw!r}: user-defined V.E. types are not simulated; use one of "
                    f"{', '.join(_TYPES)}"
                )
                ok = False
        elif key == "scope":
            if raw.upper() not in ("GLOBAL", "CHANNEL"):
                result.errors.append(f"{where}: {raw!r}: the scope is GLOBAL or CHANNEL")
                ok = False
            scope = raw.upper()
            origins["channel"] = origin
        elif key == "synchronisation":
            flag = _bool(raw)
            if flag is None:
                result.errors.append(f"{where}: {raw!r} is not TRUE or FALSE")
                ok = False
            else:
                variable["synchronous"], origins["synchronous"] = flag, origin
        elif key == "access_rights":
            if raw.upper() not in ("READ_WRITE", "READ_ONLY", "WRITE_ONLY"):
                result.errors.append(f"{where}: {raw!r}: use READ_WRITE, READ_ONLY or WRITE_ONLY")
                ok = False
            else:
                variable["access_rights"], origins["access_rights"] = raw.upper(), origin
        elif key in ("array_elements", "array_size"):
            if not raw.isdigit():
                result.errors.append(f"{where}: {raw!r} is not a number of elements")
                ok = False
            elif int(raw) > 0:
                variable["dims"], origins["dims"] = [int(raw)], origin
        elif key in _IGNORED_VAR:
            result.warnings.append(
                f"{where}: accepted without effect here (the image places the variables itself)"
            )
        else:
            result.errors.append(f"{where}: unknown parameter of var[{index}]")
            ok = False
    if scope == "CHANNEL":
        variable["channel"] = channel
    return (variable, origins) if ok else None
