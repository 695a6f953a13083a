"""ISG text parameter lists: ``kenngr.achs_mode 0x8001`` lines read against a parameter table (E-07)."""

from __future__ import annotations

import difflib
import typing
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, TypeAdapter, ValidationError

from hli_server.configuration.errors import Origin
from hli_server.configuration.fields import _field_problem
from hli_server.configuration.tables import (
    _CHANNEL_KEY,
    _ELEMENT_KEY,
    _GEAR_KEY,
    _INTEGER,
    _KIND_NAMES,
    _PAREN_COMMENT,
    _TABLES,
    ListKind,
)
from schemas.config import AXIS_PARAMETER_ALIASES


@dataclass
class ParameterList:
    """One text parameter list, read against one parameter table (E-07)."""

    source: str
    values: dict[str, Any] = field(default_factory=dict)
    """field name -> value (already converted and range-checked field by field)."""
    origins: dict[str, Origin] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    failed: set[str] = field(default_factory=set)
    """Fields whose entry was given but could not be used (already reported in ``errors``)."""


def read_parameter_list(path: Path, kind: ListKind, *, channel_index: int | None = None) -> ParameterList:
    """Read an ISG text parameter list from ``path``; ``OSError`` and ``UnicodeDecodeError`` propagate."""
    return parse_parameter_list(
        path.read_text(encoding="utf-8"), kind, source=str(path), channel_index=channel_index
    )


def parse_parameter_list(
    text: str, kind: ListKind, *, source: str = "<list>", channel_index: int | None = None
) -> ParameterList:
    """Parse an ISG text parameter list (E-07; the form of FCT-C3 section 3, FCT-C43 section 3).

    One ``path value`` per line; ``#`` starts a comment (also after a value); blank lines are
    skipped. Numbers are decimal or ``0x`` hex, negative allowed; booleans ``0``/``1``. A value that
    ends in ``|`` continues on the next line (P-STUP-00070 keyword lists wrap so in the documents).

    ``getriebe[i].x`` maps to the same field for every gear stage ``i``: only gear stage 0 is
    simulated. A value given for a stage ``i != 0`` is range-checked; it is used only when the list
    has no stage-0 entry for that parameter, and a warning says so either way.

    ``configuration.channel[i].…`` (P-STUP-00070) must use the list's own channel index when
    ``channel_index`` is given (channel number - 1).
    """
    table, model = _TABLES[kind]
    by_path = {info.path: info for info in table if info.path is not None}
    result = ParameterList(source=source)
    seen: dict[str, int] = {}
    gear_values: dict[str, list[tuple[int, Any, Origin]]] = {}
    indexed: dict[str, dict[int, Any]] = {}
    """``g800_prog_file[3] name`` (the table's path ``g800_prog_file[i]``): field -> index -> value."""
    lines = text.splitlines()
    index = 0
    while index < len(lines):
        line_no = index + 1
        content = _strip_comment(lines[index]).strip()
        index += 1
        if not content:
            continue
        while content.endswith("|") and index < len(lines):
            content = f"{content} {_strip_comment(lines[index]).strip()}"
            index += 1
        key, *rest = content.split(None, 1)
        raw = _PAREN_COMMENT.sub("", rest[0]).strip() if rest else ""
        origin = Origin(source, line_no, key)
        canonical, gear, problem = _canonical_path(key, channel_index)
        if problem:
            result.errors.append(f"{origin.where()}: {problem}")
            continue
        element: int | None = None
        element_key = _ELEMENT_KEY.match(canonical)
        if element_key is not None and f"{element_key[1]}[i]" in by_path:
            canonical, element = f"{element_key[1]}[i]", int(element_key[2])
        if kind == "axis" and canonical in AXIS_PARAMETER_ALIASES:
            replacement = _display_path(AXIS_PARAMETER_ALIASES[canonical], gear)
            result.warnings.append(
                f"{origin.where()}: {key} is this project's old name; the kernel's path is {replacement} "
                "(read as that; write it so, the old name will go)"
            )
            canonical = AXIS_PARAMETER_ALIASES[canonical]
        info = by_path.get(canonical)
        if info is None:
            result.errors.append(f"{origin.where()}: {_unknown_parameter(canonical, gear, kind)}")
            continue
        if key in seen:
            result.errors.append(f"{origin.where()}: given twice (first in line {seen[key]})")
            continue
        seen[key] = line_no
        if not raw:
            result.errors.append(f"{origin.where()}: no value (write `{key} <value>`)")
            result.failed.add(info.field)
            continue
        annotation = model.model_fields[info.field].annotation
        if element is not None:
            annotation = typing.get_args(annotation)[0]
        value, problem = _convert(raw, annotation)
        if problem is None and element is not None:
            limit = _max_items(model, info.field)
            if limit is not None and element >= limit:
                problem = f"index {element} is out of range: 0 .. {limit - 1}"
            else:
                problem = _check_field(model, info.field, [value], raw)
        elif problem is None:
            problem = _check_field(model, info.field, value, raw)
        if problem is not None:
            result.errors.append(f"{origin.where()}: {problem}")
            result.failed.add(info.field)
            continue
        if element is not None:
            indexed.setdefault(info.field, {})[element] = value
            result.origins.setdefault(info.field, origin)
        elif gear is None:
            result.values[info.field] = value
            result.origins[info.field] = origin
        else:
            gear_values.setdefault(info.field, []).append((gear, value, origin))
    for field_name, elements in indexed.items():
        # the entries not given are "" (not assigned: a G8xx of such an index is 20131)
        result.values[field_name] = [elements.get(i, "") for i in range(max(elements) + 1)]
    for field_name, entries in gear_values.items():
        entries.sort(key=lambda e: e[0])
        used_stage, used_value, used_origin = entries[0]
        result.values[field_name] = used_value
        result.origins[field_name] = used_origin
        for stage, _value, origin in entries:
            if stage == 0:
                continue
            if origin is used_origin:
                result.warnings.append(
                    f"{origin.where()}: only gear stage 0 is simulated; this gear stage {stage} value is "
                    "used for it (the list has no getriebe[0] entry)"
                )
            else:
                result.warnings.append(
                    f"{origin.where()}: only gear stage 0 is simulated; this gear stage {stage} value is "
                    f"not used (getriebe[{used_stage}] gives {used_value})"
                )
    return result


def _max_items(model: type[BaseModel], field_name: str) -> int | None:
    """The most elements a list field takes (its ``max_length``), None without a bound."""
    for meta in model.model_fields[field_name].metadata:
        limit = getattr(meta, "max_length", None)
        if isinstance(limit, int):
            return limit
    return None


def _strip_comment(line: str) -> str:
    return line.split("#", 1)[0]


def _canonical_path(key: str, channel_index: int | None) -> tuple[str, int | None, str | None]:
    """``getriebe[3].window`` -> (``getriebe[0].window``, 3, None); channel indices are checked."""
    match = _GEAR_KEY.match(key)
    if match:
        return f"getriebe[0].{match[2]}", int(match[1]), None
    match = _CHANNEL_KEY.match(key)
    if match:
        index = int(match[1])
        if channel_index is not None and index != channel_index:
            return (
                key,
                None,
                f"this list belongs to channel {channel_index + 1}: write "
                f"configuration.channel[{channel_index}].{match[2]} (index = channel number - 1)",
            )
        return f"configuration.channel[0].{match[2]}", None, None
    return key, None, None


def _display_path(path: str, gear: int | None = None) -> str:
    if gear is not None and path.startswith("getriebe[0]."):
        return f"getriebe[{gear}]." + path.removeprefix("getriebe[0].")
    return path


def _unknown_parameter(canonical: str, gear: int | None, kind: str) -> str:
    for other_kind, (table, _model) in _TABLES.items():
        if other_kind != kind and any(info.path is not None and info.path == canonical for info in table):
            return f"unknown {kind} parameter: {_display_path(canonical, gear)} is {_KIND_NAMES[other_kind]}"
    table, _model = _TABLES[kind]
    paths = [info.path for info in table if info.path is not None]
    close = difflib.get_close_matches(canonical, paths, n=1, cutoff=0.6)
    hint = f" (did you mean {_display_path(close[0], gear)}?)" if close else ""
    return f"unknown parameter{hint}"


def _convert(raw: str, annotation: Any) -> tuple[Any, str | None]:
    """A list value as the field's type: int (decimal/0x hex), bool (0/1), float, str, keywords."""
    if typing.get_origin(annotation) is typing.Annotated:
        annotation = typing.get_args(annotation)[0]
    if typing.get_origin(annotation) is list:
        parts = [p.strip() for p in raw.split("|")]
        if any(not p for p in parts):
            return None, f"{raw!r}: empty keyword in a `A | B` list"
        return parts, None
    if annotation is str and len(raw) >= 2 and raw[0] == raw[-1] == '"':
        return raw[1:-1], None  # a name in quotes may hold blanks
    if " " in raw or "\t" in raw:
        return None, f"unexpected text after the value: {raw!r}"
    if annotation is bool:
        lowered = raw.lower()
        if lowered in {"0", "false"}:
            return False, None
        if lowered in {"1", "true"}:
            return True, None
        return None, f"{raw!r} is not a boolean (write 0 or 1)"
    if annotation is int:
        number = _parse_int(raw)
        if number is None:
            return None, f"{raw!r} is not an integer (decimal or 0x hex)"
        return number, None
    if annotation is float:
        number = _parse_int(raw)
        if number is not None:
            return float(number), None
        try:
            return float(raw), None
        except ValueError:
            return None, f"{raw!r} is not a number"
    if len(raw) >= 2 and raw[0] == raw[-1] == '"':
        raw = raw[1:-1]
    return raw, None


def _parse_int(raw: str) -> int | None:
    match = _INTEGER.match(raw)
    if not match:
        return None
    number = int(match[2], 16) if match[2] is not None else int(match[3], 10)
    return -number if match[1] == "-" else number


@cache
def _field_adapter(model: type[BaseModel], field_name: str) -> TypeAdapter[Any]:
    info = model.model_fields[field_name]
    annotated: Any = typing.Annotated[info.annotation, info]
    # the models refuse inf and NaN (schemas.config); a field checked alone must too
    return TypeAdapter(annotated, config=ConfigDict(allow_inf_nan=False))


def _check_field(model: type[BaseModel], field_name: str, value: Any, written: str) -> str | None:
    """Validate one value against its field alone (type and range); ``None`` when it is fine."""
    try:
        _field_adapter(model, field_name).validate_python(value)
    except ValidationError as exc:
        err = exc.errors()[0]
        return _field_problem(model, field_name, err, written)
    return None
