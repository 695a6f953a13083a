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

* ``var[i].name`` (P-EXTV-00001, required), ``.type`` (P-EXTV-00003, default UNS32: an elementary
  type, STRING, VSTRING or a structure of a ``struct[i]``), ``.scope`` (P-EXTV-00004, GLOBAL or
  CHANNEL, default CHANNEL), ``.synchronisation`` (P-EXTV-00005, default TRUE as in the kernel),
  ``.access_rights`` (P-EXTV-00006, default READ_WRITE), ``.array_elements`` (P-EXTV-00007;
  ``.array_size`` of the older syntax, 0 = no array), ``.size`` of a VSTRING (P-EXTV-00008: its bytes
  with the NUL, default 128);
* the structures (P-EXTV-00015 .. 00021): ``struct[i].name`` and per element ``struct[i].element[j].``
  ``name``, ``.type`` (default UNS32), ``.synchronisation`` and ``.access_rights`` (default: the
  variable's), ``.array_elements``, ``.size`` (a VSTRING's); into ``external_structures``;
* ``use_extended_string_var`` (P-EXTV-00022): a STRING of 127 characters instead of 20, for the whole
  machine here (lists that disagree are refused);
* ``number_used_variables`` (P-EXTV-00010; ``anzahl_belegt`` of the older syntax): every ``var[i]``
  must lie below it;
* accepted without effect, with a warning: ``var[i].byte_offset``, ``.index``, ``.size`` (of a type
  other than VSTRING), ``.create_hmi_interface`` and the general ``check_overlapping_variables``,
  ``auto_memory_mode`` (the image places the variables itself, docs/process-image.md);
* ``init`` (P-EXTV-00013, any number of times): the rest of the line is an assignment to a V.E. variable
  run at the machine's start, in the list's order (a ``( ...)`` after it is a comment); into
  ``external_init``, after the machine file's own.

Comments: ``#`` to the end of the line, and a ``( ...)`` after the value (the kernel's own examples
write them so). Every finding names file, line and key.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from hli_server.configuration.errors import Origin
from schemas.external_types import ELEMENTARY_TYPES, STRING_TYPES

__all__ = ["ExternalList", "parse_external_list"]

_VAR_KEY = re.compile(r"^var\[(\d+)\]\.([A-Za-z_]+)$")
_STRUCT_KEY = re.compile(r"^struct\[(\d+)\]\.(?:element\[(\d+)\]\.)?([A-Za-z_]+)$")
_TYPE_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,31}$")
_IGNORED_VAR = ("byte_offset", "index", "size", "create_hmi_interface")
_IGNORED_GENERAL = ("check_overlapping_variables", "auto_memory_mode")
_INIT_KEY = "init"
_EXTENDED_KEY = "use_extended_string_var"
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
    structures: list[dict[str, Any]] = field(default_factory=list)
    """``external_structures`` entries (``struct[i]``), with ``structure_origins[k]`` where each was set."""
    structure_origins: list[Origin] = field(default_factory=list)
    init: list[tuple[str, Origin]] = field(default_factory=list)
    """The ``init`` assignments (P-EXTV-00013), in the list's order."""
    extended: tuple[bool, Origin] | None = None
    """``use_extended_string_var`` where the list sets it."""
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


def _without_comment(text: str) -> str:
    """An NC assignment up to its ``( comment)``: the first ``(`` outside a string."""
    quoted = False
    for at, char in enumerate(text):
        if char == '"':
            quoted = not quoted
        elif char == "(" and not quoted:
            return text[:at]
    return text


def parse_external_list(text: str, *, source: str, channel: int) -> ExternalList:
    """Read one list of external variables of channel ``channel`` (its CHANNEL variables)."""
    result = ExternalList(source)
    records: dict[int, dict[str, tuple[str, Origin]]] = {}
    structs: dict[int, dict[int | None, dict[str, tuple[str, Origin]]]] = {}
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
        if key.lower() == _INIT_KEY:  # may occur several times
            assignment = _without_comment(content[len(key) :]).strip()
            if assignment:
                result.init.append((assignment, origin))
            else:
                result.errors.append(f"{origin.where()}: no assignment (write `init V.E.NAME = <value>`)")
            continue
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
        struct_match = _STRUCT_KEY.match(key)
        if struct_match:
            index, element = int(struct_match[1]), struct_match[2]
            if max(index, int(element or 0)) > _MAX_INDEX:
                result.errors.append(f"{origin.where()}: the kernel numbers them 0 to {_MAX_INDEX}")
                continue
            structs.setdefault(index, {}).setdefault(None if element is None else int(element), {})[
                struct_match[3]
            ] = (raw, origin)
            continue
        if key == _EXTENDED_KEY:
            flag = _bool(raw)
            if flag is None:
                result.errors.append(f"{origin.where()}: {raw!r} is not TRUE or FALSE")
            else:
                result.extended = (flag, origin)
            continue
        if key in _IGNORED_GENERAL:
            result.warnings.append(
                f"{origin.where()}: accepted without effect here (the image places the variables itself)"
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
    for index in sorted(structs):
        structure = _structure(index, structs[index], result)
        if structure is not None:
            result.structures.append(structure[0])
            result.structure_origins.append(structure[1])
    return result


def _type_entry(raw: str, where: str, result: ExternalList) -> str | None:
    """A ``.type`` value: the kernel's names in upper case, a structure's name as written."""
    if not _TYPE_NAME.match(raw):
        result.errors.append(
            f"{where}: {raw!r} is no type: an elementary type (BOOLEAN, SGN08 .. UNS32, REAL32, REAL64), "
            "STRING, VSTRING or the name of a struct[i]"
        )
        return None
    upper = raw.upper()
    return upper if upper in ELEMENTARY_TYPES or upper in STRING_TYPES else raw


def _array_entry(raw: str, where: str, result: ExternalList) -> list[int] | None:
    if not raw.isdigit():
        result.errors.append(f"{where}: {raw!r} is not a number of elements")
        return None
    return [int(raw)] if int(raw) > 0 else []


def _size_entry(raw: str, where: str, result: ExternalList) -> int | None:
    if not raw.isdigit():
        result.errors.append(f"{where}: {raw!r} is not a size in bytes")
        return None
    return int(raw)


def _structure(
    index: int, entries: dict[int | None, dict[str, tuple[str, Origin]]], result: ExternalList
) -> tuple[dict[str, Any], Origin] | None:
    """One ``struct[i]`` as an ``external_structures`` entry (None when it is refused)."""
    own = entries.get(None, {})
    first = min((o for e in entries.values() for _, o in e.values()), key=lambda o: o.line)
    ok = True
    for key, (_, origin) in own.items():
        if key != "name":
            result.errors.append(f"{origin.where()}: unknown parameter of struct[{index}]")
            ok = False
    if "name" not in own:
        result.errors.append(f"{first.file}:{first.line}: struct[{index}] has no struct[{index}].name")
        return None
    name, origin = own["name"]
    elements: list[dict[str, Any]] = []
    for number in sorted(k for k in entries if k is not None):
        element = _structure_element(index, number, entries[number], result)
        if element is None:
            ok = False
        else:
            elements.append(element)
    if not elements and ok:
        result.errors.append(f"{origin.where()}: struct[{index}] {name} has no elements")
        ok = False
    return ({"name": name, "elements": elements}, origin) if ok else None


def _structure_element(
    index: int, number: int, entries: dict[str, tuple[str, Origin]], result: ExternalList
) -> dict[str, Any] | None:
    label = f"struct[{index}].element[{number}]"
    if "name" not in entries:
        first = min((o for _, o in entries.values()), key=lambda o: o.line)
        result.errors.append(f"{first.file}:{first.line}: {label} has no {label}.name")
        return None
    element: dict[str, Any] = {"name": entries["name"][0], "type": "UNS32"}
    ok = True
    for key, (raw, origin) in entries.items():
        where = origin.where()
        value: Any
        if key == "name":
            continue
        if key == "type":
            value = _type_entry(raw, where, result)
        elif key == "synchronisation":
            value = _bool(raw)
            if value is None:
                result.errors.append(f"{where}: {raw!r} is not TRUE or FALSE")
        elif key == "access_rights":
            value = raw.upper() if raw.upper() in _ACCESS else None
            if value is None:
                result.errors.append(f"{where}: {raw!r}: use READ_WRITE, READ_ONLY or WRITE_ONLY")
        elif key == "array_elements":
            value = _array_entry(raw, where, result)
        elif key == "size":
            value = _size_entry(raw, where, result)
        else:
            result.errors.append(f"{where}: unknown parameter of {label}")
            value = None
        if value is None:
            ok = False
            continue
        element[_ELEMENT_FIELDS.get(key, key)] = value
    if ok and "size" in element and element["type"] != "VSTRING":
        result.warnings.append(
            f"{entries['size'][1].where()}: accepted without effect here (a size is a VSTRING's length)"
        )
        del element["size"]
    return element if ok else None


_ACCESS = ("READ_WRITE", "READ_ONLY", "WRITE_ONLY")
_ELEMENT_FIELDS = {"synchronisation": "synchronous", "array_elements": "dims"}


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
            typed = _type_entry(raw, where, result)
            if typed is None:
                ok = False
            else:
                variable["type"], origins["type"] = typed, origin
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
            dims = _array_entry(raw, where, result)
            if dims is None:
                ok = False
            elif dims:
                variable["dims"], origins["dims"] = dims, origin
        elif key == "size" and entries.get("type", ("",))[0].upper() == "VSTRING":
            size = _size_entry(raw, where, result)
            if size is None:
                ok = False
            else:
                variable["size"], origins["size"] = size, origin
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
