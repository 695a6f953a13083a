"""Self-defined variables and P parameters of the NC language (N-04).

The programming manual: "Parameters and parameter calculation (P)" (206872331), "Indirect parameters"
(206884875), "Global, valid up to end of main program (V.P.)" (207966475), "Local, valid throughout
subroutine (V.L.)" (207981323), "Global, valid throughout main program (V.S.)" (207973899).

* ``P<n>``: created by ``#VAR`` or by the first write; one table per main program, cleared at program
  start (P-CHAN-00067 = 0, its default); numbers 0 to :data:`P_COUNT` - 1 (P-CHAN-00517, default 1000).
  ``PP<n>`` reads the parameter whose number ``P<n>`` holds; ``P<n>[i]`` are parameter arrays.
* ``V.P.``: declared in ``#VAR``, valid to the end of the main program (cleared at program start).
* ``V.L.``: declared in ``#VAR``, valid at the declaring program level and the subroutines it calls;
  deleted when that level returns; a lower level may declare the same name again (shadowing).
* ``V.S.``: declared in ``#VAR``, kept across programs and resets (the channel's lifetime).
* ``V.CYC.``: like ``V.L.``, for cycles.

A variable has a type (``REAL64`` by default, ``BOOLEAN``, ``SGN08`` .. ``UNS32``, ``REAL32``,
``STRING[n]``) and up to 4 array dimensions; a value assigned is converted to the type (a real to an
integer type truncates, as the kernel does) or refused when out of the type's range.
"""

from __future__ import annotations

import math
from typing import Final

from hli_server.engine.nc.expr import ALARM_TYPE, EvalError, Value, format_value

__all__ = ["P_COUNT", "Variable", "coerce"]

P_COUNT: Final = 1000
"""P parameters of a channel (P-CHAN-00517's default): P0 .. P999."""
MAX_ELEMENTS: Final = 1_000_000
"""Elements of one array variable (a bound on memory)."""
ALARM_UNDECLARED: Final = 914003
ALARM_INDEX: Final = 914005

_INT_RANGES: Final[dict[str, tuple[int, int]]] = {
    "SGN08": (-(2**7), 2**7 - 1),
    "UNS08": (0, 2**8 - 1),
    "SGN16": (-(2**15), 2**15 - 1),
    "UNS16": (0, 2**16 - 1),
    "SGN32": (-(2**31), 2**31 - 1),
    "UNS32": (0, 2**32 - 1),
}
_REAL32_MAX: Final = 3.4028234663852886e38


def coerce(value: Value, type_name: str, string_size: int, what: str) -> Value:
    """``value`` as a variable of ``type_name`` holds it, or :class:`EvalError` naming ``what``."""
    if type_name == "STRING":
        if not isinstance(value, str):
            raise EvalError(ALARM_TYPE, f"{what} is a STRING: {format_value(value)} is a number")
        if len(value) > string_size:  # the kernel's "String for variable too long" (V.E. STRINGs too)
            raise EvalError(21462, f"{what} holds at most {string_size} characters, {len(value)} given")
        return value
    if isinstance(value, str):
        raise EvalError(ALARM_TYPE, f"{what} is a number ({type_name}): {format_value(value)} is a string")
    if not math.isfinite(value):
        raise EvalError(914002, f"{what}: {value} is not a finite number")
    if type_name == "REAL64":
        return value
    if type_name == "BOOLEAN":
        return 1.0 if value != 0.0 else 0.0
    if type_name == "REAL32":
        if abs(value) > _REAL32_MAX:
            raise EvalError(914002, f"{what}: {format_value(value)} is beyond the range of REAL32")
        return value
    low, high = _INT_RANGES[type_name]
    number = math.trunc(value)
    if not low <= number <= high:
        raise EvalError(914002, f"{what}: {format_value(value)} is outside {low} .. {high} ({type_name})")
    return float(number)


class Variable:
    """A declared variable: its type, dimensions and values (flat, row-major)."""

    def __init__(self, text: str, type_name: str, dims: list[int], string_size: int) -> None:
        self.text = text
        """The name as programmed (``V.P.VAR_1``)."""
        self.type_name = type_name
        self.dims = dims
        self.string_size = string_size
        size = 1
        for d in dims:
            size *= d
        if size > MAX_ELEMENTS:
            raise EvalError(914008, f"{text}: {size} elements, more than {MAX_ELEMENTS}")
        zero: Value = "" if type_name == "STRING" else 0.0
        self.values: list[Value] = [zero] * size

    def flat(self, indices: list[float]) -> int:
        dims = self.dims
        if not dims and not indices:
            return 0
        if len(indices) != len(dims):
            want = "no index" if not dims else f"{len(dims)} index(es)"
            raise EvalError(ALARM_INDEX, f"{self.text} takes {want}, {len(indices)} given")
        flat = 0
        for k, (value, dim) in enumerate(zip(indices, dims, strict=True)):
            if value != int(value) or not 0 <= value < dim:
                raise EvalError(
                    ALARM_INDEX,
                    f"{self.text}: index {k + 1} is {format_value(value)}, allowed 0 to {dim - 1}",
                )
            flat = flat * dim + int(value)
        return flat

    def get(self, indices: list[float]) -> Value:
        return self.values[self.flat(indices)]

    def set(self, indices: list[float], value: Value) -> None:
        self.values[self.flat(indices)] = coerce(value, self.type_name, self.string_size, self.text)
