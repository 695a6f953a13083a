"""Messages for a value a field refuses: the range it allows, in the documents' words (E-07)."""

from __future__ import annotations

from typing import Any

import annotated_types
from pydantic import BaseModel

from hli_server.configuration.tables import _PARAMETERS_OF_MODEL, _RANGE_ERRORS
from schemas.units import DINT_MAX, DINT_MIN, UDINT_MAX


def _pid(model: type[BaseModel], field_name: str) -> str | None:
    for info in _PARAMETERS_OF_MODEL.get(model, ()):
        if info.field == field_name:
            return info.pid
    return None


def _bound_text(field_name: str, value: Any) -> str:
    if field_name == "achs_mode" and isinstance(value, int):
        return f"0x{value:08X}"
    names = {DINT_MIN: "MIN(SGN32)", DINT_MAX: "MAX(SGN32)", UDINT_MAX: "MAX(UNS32)"}
    if isinstance(value, int) and not isinstance(value, bool) and value in names:
        return names[value]
    if isinstance(value, float):
        return str(int(value)) if value.is_integer() and abs(value) < 1e15 else f"{value:g}"
    return str(value)


def _range_text(model: type[BaseModel], field_name: str) -> str:
    """The documented range of a field, from its constraints (``0 ≤ value ≤ 2``)."""
    info = model.model_fields[field_name]
    low = high = ""
    for meta in info.metadata:
        if isinstance(meta, annotated_types.Ge):
            low = f"{_bound_text(field_name, meta.ge)} ≤ "
        elif isinstance(meta, annotated_types.Gt):
            low = f"{_bound_text(field_name, meta.gt)} < "
        elif isinstance(meta, annotated_types.Le):
            high = f" ≤ {_bound_text(field_name, meta.le)}"
        elif isinstance(meta, annotated_types.Lt):
            high = f" < {_bound_text(field_name, meta.lt)}"
    if low or high:
        return f"{low}value{high}"
    return ""


def _field_problem(model: type[BaseModel], field_name: str, err: Any, written: Any) -> str:
    pid = _pid(model, field_name)
    label = pid or field_name
    if err["type"] in _RANGE_ERRORS:
        return f"{written} is out of range: {label} allows {_range_text(model, field_name)}"
    if err["type"] == "finite_number":  # inf, nan (TOML and the lists can write them)
        allowed = _range_text(model, field_name) or "a finite number"
        return f"{written} is not a finite number: {label} allows {allowed}"
    msg = str(err["msg"])
    msg = msg[:1].lower() + msg[1:]
    return f"invalid value {written!r}: {msg}" + (f" ({pid})" if pid else "")
