"""The project's one JSON policy, for every door that writes JSON (HTTP answers, the live stream, MQTT).

JSON has no NaN and no infinities: strict parsers (JavaScript's ``JSON.parse``, Go's, Rust's serde)
refuse the ``NaN`` that Python's :func:`json.dumps` writes by default. Every non-finite float becomes
``null``, as JavaScript's ``JSON.stringify`` and pydantic's ``ser_json_inf_nan`` default write it;
tuples become lists. A reader that needs to tell "no value" from "not a number" reads the schema: a field
that may be non-finite says so in its description.
"""

from __future__ import annotations

import json
import math
from typing import Any

__all__ = ["dumps_ascii", "dumps_utf8", "finite"]


def finite(value: Any) -> Any:
    """``value`` with every NaN or infinity (at any depth of dicts, lists and tuples) replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    return value


def _dumps(obj: Any, *, ascii_only: bool) -> str:
    try:
        return json.dumps(obj, separators=(",", ":"), ensure_ascii=ascii_only, allow_nan=False)
    except ValueError:  # a non-finite float somewhere: walk the value once (the rare case)
        return json.dumps(finite(obj), separators=(",", ":"), ensure_ascii=ascii_only, allow_nan=False)


def dumps_ascii(obj: Any) -> bytes:
    """Compact JSON, escaped to ASCII (a lone surrogate in a client's string cannot break it)."""
    return _dumps(obj, ascii_only=True).encode("ascii")


def dumps_utf8(obj: Any) -> bytes:
    """Compact JSON, UTF-8."""
    return _dumps(obj, ascii_only=False).encode("utf-8")
