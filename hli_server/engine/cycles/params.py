"""The @P parameters of a cycle as its page documents them, and their validation.

A :class:`Param` row carries what the cycle's "Parameters" page says: required or optional, the default,
the meaning, and what the cycle checks with which of the kernel's error IDs (``alarm``; the project's
917000 where the diagnosis pages give none). ``docs/cycles.md`` is written from these rows, so the table a
user reads is the table the stand-in checks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from hli_server.engine.cycles.errors import A_INVALID, CycleError

__all__ = ["Args", "Param", "ParamValue", "check_params"]

ParamValue = float | str
"""An @P value as the call passes it: a number, or a string (``@P31 = "Roughing"``)."""

_POSITIVE = "positive"
_NONZERO = "nonzero"
_NONNEGATIVE = "nonnegative"


@dataclass(frozen=True, slots=True)
class Param:
    """One @P of a cycle.

    ``check``: ``"positive"`` (> 0), ``"nonzero"``, ``"nonnegative"`` or empty; ``choices``: the allowed
    values; ``words``: the strings the page allows for a number (``"Roughing"`` = 1); ``low``/``high``: a
    range (inclusive); ``alarm``: the kernel's ID for this parameter missing or invalid (0: 917000)."""

    number: int
    meaning: str
    required: bool = False
    default: float | None = None
    default_text: str = ""
    """The documented default where it is not a number (``"probe diameter"``, ``"@P4"``)."""
    check: str = ""
    choices: tuple[float, ...] = ()
    words: tuple[tuple[str, float], ...] = ()
    low: float | None = None
    high: float | None = None
    alarm: int = 0
    text: bool = False
    """A string parameter (a reference cycle's name, ``@P100 = "SysDrillDeepHole"``)."""
    rule: str = ""
    """What the cycle checks beyond the fields above, for docs/cycles.md."""

    @property
    def default_doc(self) -> str:
        """The default as docs/cycles.md shows it."""
        if self.default_text:
            return self.default_text
        if self.default is None:
            return "-"
        return _fmt(self.default)

    @property
    def rule_doc(self) -> str:
        """What the stand-in checks, for docs/cycles.md."""
        parts: list[str] = []
        if self.check:
            parts.append({_POSITIVE: "> 0", _NONZERO: "not 0", _NONNEGATIVE: ">= 0"}[self.check])
        if self.choices:
            parts.append("one of " + ", ".join(_fmt(c) for c in self.choices))
        if self.words:
            parts.append(" or ".join(f'"{w}" ({_fmt(v)})' for w, v in self.words))
        if self.low is not None and self.high is not None:
            parts.append(f"{_fmt(self.low)} .. {_fmt(self.high)}")
        if self.text:
            parts.append("a string")
        if self.rule:
            parts.append(self.rule)
        return "; ".join(parts) if parts else "-"


def _fmt(value: float) -> str:
    return str(int(value)) if value == int(value) and abs(value) < 1e15 else repr(value)


class Args:
    """The validated values of one call: what was passed, by @P number, with the defaults of the table."""

    def __init__(self, cycle: str, table: Sequence[Param], values: Mapping[int, ParamValue]) -> None:
        self.cycle = cycle
        self._rows = {p.number: p for p in table}
        self._values: dict[int, ParamValue] = dict(values)

    def given(self, number: int) -> bool:
        """Was @P<number> programmed at the call (``EXIST[@Pn]`` in the kernel's cycles)?"""
        return number in self._values

    def get(self, number: int) -> float | None:
        """The number @P<number> was given, its table default, or None."""
        value = self._values.get(number)
        if value is None:
            row = self._rows.get(number)
            return row.default if row is not None else None
        if isinstance(value, str):
            row = self._rows[number]
            return _word(row, value, self.cycle)
        return value

    def num(self, number: int, default: float | None = None) -> float:
        """@P<number> as a number: given, else ``default``, else the table's default."""
        if number in self._values:
            value = self.get(number)
            assert value is not None
            return value
        if default is not None:
            return default
        row_default = self.get(number)
        if row_default is None:  # pragma: no cover - a stand-in asks only for what its table defaults
            raise CycleError(A_INVALID, f"{self.cycle}: @P{number} not given and no default", number)
        return row_default

    def text(self, number: int) -> str | None:
        value = self._values.get(number)
        return value if isinstance(value, str) else None

    def passed(self) -> dict[int, ParamValue]:
        """Every @P of the call as passed (a pattern cycle hands them on to its reference cycle)."""
        return dict(self._values)


def _word(row: Param, value: str, cycle: str) -> float:
    for word, number in row.words:
        if value.strip().casefold() == word.casefold():
            return number
    allowed = " or ".join(f'"{w}"' for w, _ in row.words) or "a number"
    raise CycleError(
        row.alarm or A_INVALID,
        f'{cycle}: @P{row.number} ({row.meaning}) = "{value}": expected {allowed}',
        row.number,
    )


def check_params(cycle: str, table: Sequence[Param], values: Mapping[int, ParamValue]) -> Args:
    """The call's @P checked against the cycle's table (each row's rule, the kernel's ID where the page
    gives one); the :class:`Args` to run with. Parameters the table does not list are kept (a pattern
    cycle passes them to its reference cycle) and not checked."""
    for row in table:
        value = values.get(row.number)
        what = f"{cycle}: @P{row.number} ({row.meaning})"
        alarm = row.alarm or A_INVALID
        if value is None:
            if row.required:
                raise CycleError(
                    alarm,
                    f"{what} is required: pass it in the call L CYCLE [... @P{row.number}=..]",
                    row.number,
                )
            continue
        if row.text:
            if not isinstance(value, str) or not value.strip():
                raise CycleError(alarm, f"{what} must be a string, got {value!r}", row.number)
            continue
        number = _word(row, value, cycle) if isinstance(value, str) else value
        if not math.isfinite(number):  # pragma: no cover - the interpreter's numbers are finite
            raise CycleError(alarm, f"{what} = {number} is not a number", row.number)
        shown = _fmt(number)
        if row.check == _POSITIVE and number <= 0.0:
            raise CycleError(alarm, f"{what} = {shown}: must be greater than 0", row.number)
        if row.check == _NONZERO and number == 0.0:
            raise CycleError(alarm, f"{what} = 0: must not be 0", row.number)
        if row.check == _NONNEGATIVE and number < 0.0:
            raise CycleError(alarm, f"{what} = {shown}: must not be negative", row.number)
        if row.choices and number not in row.choices:
            allowed = ", ".join(_fmt(c) for c in row.choices)
            raise CycleError(alarm, f"{what} = {shown}: allowed are {allowed}", row.number)
        if row.low is not None and row.high is not None and not row.low <= number <= row.high:
            raise CycleError(
                alarm, f"{what} = {shown}: allowed are {_fmt(row.low)} .. {_fmt(row.high)}", row.number
            )
    return Args(cycle, table, values)
