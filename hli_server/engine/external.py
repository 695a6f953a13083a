"""External variables ``V.E.<name>``: the values an NC program and the PLC share (N-05).

The kernel's programming manual ("External variables (V.E) (#INIT V.E.)",
https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/207988747.html) and the HLI
description ("External variables / V.E. variables",
https://infosys.beckhoff.com/content/1033/tccnchliinterface/15691384715.html): each channel has an
area of its own, and one global area serves every channel; a name has at most 20 characters; the
configured variables start at zero after start-up.

This module is the engine's store: the NC program reads and writes it through the interpreter, the
process image latches the PLC's writes into it and publishes it (``hli_server/image``). It knows no
bytes and no addresses: the layout (``schemas/layout.py``) places the variables in the image.

Lookup (:meth:`ExternalVariables.spec`): a channel's own variable shadows a global one of the same
name. Names are compared case-insensitively, as the kernel's variable names are.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from enum import StrEnum

__all__ = [
    "MAX_NAME_LENGTH",
    "ExternalType",
    "ExternalValue",
    "ExternalVarSpec",
    "ExternalVariableError",
    "ExternalVariables",
]

MAX_NAME_LENGTH = 20
"""The kernel's limit on a V.E. name (tf5200_external_variables: "V.E. Variablen dürfen maximal aus 20
Zeichen bestehen")."""

ExternalValue = bool | int | float


class ExternalType(StrEnum):
    """The data types a V.E. variable may have here (the kernel's names)."""

    BOOLEAN = "BOOLEAN"
    SGN08 = "SGN08"
    UNS08 = "UNS08"
    SGN16 = "SGN16"
    UNS16 = "UNS16"
    SGN32 = "SGN32"
    UNS32 = "UNS32"
    REAL32 = "REAL32"
    REAL64 = "REAL64"


_INT_RANGES: dict[ExternalType, tuple[int, int]] = {
    ExternalType.SGN08: (-(2**7), 2**7 - 1),
    ExternalType.UNS08: (0, 2**8 - 1),
    ExternalType.SGN16: (-(2**15), 2**15 - 1),
    ExternalType.UNS16: (0, 2**16 - 1),
    ExternalType.SGN32: (-(2**31), 2**31 - 1),
    ExternalType.UNS32: (0, 2**32 - 1),
}
_REAL32_MAX = 3.4028234663852886e38


class ExternalVariableError(ValueError):
    """A read or write the store refuses: unknown name, bad index, value out of the type's range.
    ``str(exc)`` says what and which variable; the interpreter turns it into an alarm with line and block."""


@dataclass(frozen=True, slots=True)
class ExternalVarSpec:
    """One configured variable. ``dims`` are the array dimensions (``()`` for a scalar; indices run
    from 0 to dim - 1 as in the NC program's ``V.E.name[i]``); ``channel`` None is the global area."""

    name: str
    type: ExternalType
    dims: tuple[int, ...] = ()
    channel: int | None = None
    synchronous: bool = False
    """Read by the interpolator rather than the decoder: reading it empties the channel first (the
    manual: "Reading a synchronous V.E. variable causes the NC channel to be flushed")."""
    access_rights: str = "READ_WRITE"
    """P-EXTV-00006: ``READ_WRITE``, ``READ_ONLY`` or ``WRITE_ONLY``, for NC programs only (the PLC may
    always read and write; the kernel's 20097 for a read of a write-only variable)."""

    @property
    def size(self) -> int:
        return math.prod(self.dims) if self.dims else 1

    @property
    def path(self) -> str:
        """The name an NC program and the docs use: ``V.E.name``."""
        return f"V.E.{self.name}"

    def flat_index(self, index: Sequence[int]) -> int:
        if len(index) != len(self.dims):
            want = "no index" if not self.dims else f"{len(self.dims)} index(es)"
            raise ExternalVariableError(f"{self.path}: takes {want}, got {len(index)}")
        flat = 0
        for i, (value, dim) in enumerate(zip(index, self.dims, strict=True)):
            if not 0 <= value < dim:
                raise ExternalVariableError(f"{self.path}: index {i + 1} is {value}, allowed 0 to {dim - 1}")
            flat = flat * dim + value
        return flat

    def coerce(self, value: ExternalValue) -> ExternalValue:
        """``value`` as this type stores it, or :class:`ExternalVariableError`."""
        if isinstance(value, float) and not math.isfinite(value):
            raise ExternalVariableError(f"{self.path}: {value} is not a number a {self.type} can hold")
        if self.type is ExternalType.BOOLEAN:
            return bool(value)
        if self.type in (ExternalType.REAL32, ExternalType.REAL64):
            real = float(value)
            if self.type is ExternalType.REAL32 and abs(real) > _REAL32_MAX:
                raise ExternalVariableError(f"{self.path}: {real} is beyond the range of REAL32")
            return real
        low, high = _INT_RANGES[self.type]
        number = int(value)  # the kernel truncates a real assigned to an integer variable
        if not low <= number <= high:
            raise ExternalVariableError(f"{self.path}: {value} is outside {low} .. {high} ({self.type})")
        return number

    def zero(self) -> ExternalValue:
        if self.type is ExternalType.BOOLEAN:
            return False
        if self.type in (ExternalType.REAL32, ExternalType.REAL64):
            return 0.0
        return 0


class ExternalVariables:
    """The values of every configured V.E. variable, all zero at start (as after the kernel's start-up)."""

    def __init__(self, specs: Sequence[ExternalVarSpec] = ()) -> None:
        self._specs: dict[tuple[int | None, str], ExternalVarSpec] = {}
        self._values: dict[tuple[int | None, str], list[ExternalValue]] = {}
        for spec in specs:
            key = (spec.channel, spec.name.upper())
            if key in self._specs:
                where = "global" if spec.channel is None else f"channel {spec.channel}"
                raise ExternalVariableError(f"{spec.path} is declared twice ({where})")
            if not spec.name or len(spec.name) > MAX_NAME_LENGTH:
                raise ExternalVariableError(f"{spec.path}: a name has 1 to {MAX_NAME_LENGTH} characters")
            self._specs[key] = spec
            self._values[key] = [spec.zero()] * spec.size

    def __iter__(self) -> Iterator[ExternalVarSpec]:
        return iter(self._specs.values())

    def __len__(self) -> int:
        return len(self._specs)

    def spec(self, name: str, channel: int | None) -> ExternalVarSpec | None:
        """The variable an NC program of ``channel`` means by ``V.E.name``: the channel's own, else the
        global one, else None. ``channel`` None asks for the global area only."""
        key = name.upper()
        if channel is not None:
            own = self._specs.get((channel, key))
            if own is not None:
                return own
        return self._specs.get((None, key))

    def _slot(self, name: str, channel: int | None) -> tuple[ExternalVarSpec, list[ExternalValue]]:
        spec = self.spec(name, channel)
        if spec is None:
            raise ExternalVariableError(f"V.E.{name} is not declared in the machine file")
        return spec, self._values[(spec.channel, spec.name.upper())]

    def read(self, name: str, channel: int | None, index: Sequence[int] = ()) -> ExternalValue:
        spec, values = self._slot(name, channel)
        return values[spec.flat_index(index)]

    def write(self, name: str, channel: int | None, value: ExternalValue, index: Sequence[int] = ()) -> None:
        spec, values = self._slot(name, channel)
        values[spec.flat_index(index)] = spec.coerce(value)

    def values(self, spec: ExternalVarSpec) -> list[ExternalValue]:
        """The live list of ``spec``'s values (flat, row-major): the image projection copies through it."""
        return self._values[(spec.channel, spec.name.upper())]

    def reset(self) -> None:
        """Every variable back to zero (the kernel's start-up; ``#INIT V.E.`` re-initialises from the NC)."""
        for key, spec in self._specs.items():
            self._values[key][:] = [spec.zero()] * spec.size
