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

A variable of a structure type is stored as its *leaves* (``schemas/external_types.py``): one spec per
elementary or STRING element, named by its path (``UserInteraction.Message``, ``curve.point.X``), with
the array dimensions of every level in a row, so that ``V.E.curve[2].point[5].X`` is element (2, 5) of
the spec ``curve.point.X``. A STRING holds at most ``string_size - 1`` characters of Windows-1252 (the
kernel's STRING: 20, or 127 with ``use_extended_string_var``; a VSTRING its declared size); a longer one
is the kernel's error 21462 ("String for variable too long",
https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/254771339.html).

Lookup (:meth:`ExternalVariables.spec`): a channel's own variable shadows a global one of the same
name. Names are compared case-insensitively, as the kernel's variable names are.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, Final

from schemas.external_types import leaves, machine_types

if TYPE_CHECKING:
    from schemas.config import MachineConfig

__all__ = [
    "ALARM_STRING_LENGTH",
    "ALARM_TYPE",
    "ALARM_UNDECLARED",
    "ALARM_VALUE",
    "MAX_NAME_LENGTH",
    "ExternalType",
    "ExternalValue",
    "ExternalVarSpec",
    "ExternalVariableError",
    "ExternalVariables",
    "external_specs",
]

MAX_NAME_LENGTH = 20
"""The kernel's limit on a V.E. name (tf5200_external_variables: "V.E. Variablen dürfen maximal aus 20
Zeichen bestehen")."""

ExternalValue = bool | int | float | str

STRING_ENCODING: Final = "cp1252"
"""A STRING's characters: Windows-1252, one byte each (the image's STRING fields, schemas/layout.py)."""

ALARM_UNDECLARED: Final = 914003
"""An undeclared V.E. name, or a structure's element it does not have."""
ALARM_VALUE: Final = 914005
"""An index out of bounds, a number out of the type's range."""
ALARM_TYPE: Final = 914006
"""A string for a number, a number for a STRING, a character a STRING cannot hold."""
ALARM_STRING_LENGTH: Final = 21462
"""The kernel's "String for variable too long" (tf5200_diagnosis 254771339)."""


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
    STRING = "STRING"
    """STRING and VSTRING: text of at most ``string_size - 1`` characters."""


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
    ``str(exc)`` says what and which variable; ``alarm`` is the alarm the interpreter raises for it
    (with line and block)."""

    def __init__(self, message: str, alarm: int = ALARM_VALUE) -> None:
        super().__init__(message)
        self.alarm = alarm


@dataclass(frozen=True, slots=True)
class ExternalVarSpec:
    """One configured variable, or one leaf of a structured one. ``dims`` are the array dimensions
    (``()`` for a scalar; indices run from 0 to dim - 1 as in the NC program's ``V.E.name[i]``), of
    every level in a row for a leaf; ``channel`` None is the global area."""

    name: str
    """``MODE``; a leaf's path without indices: ``curve.point.X``."""
    type: ExternalType
    dims: tuple[int, ...] = ()
    channel: int | None = None
    synchronous: bool = False
    """Read by the interpolator rather than the decoder: reading it empties the channel first (the
    manual: "Reading a synchronous V.E. variable causes the NC channel to be flushed")."""
    access_rights: str = "READ_WRITE"
    """P-EXTV-00006: ``READ_WRITE``, ``READ_ONLY`` or ``WRITE_ONLY``, for NC programs only (the PLC may
    always read and write; the kernel's 20097 for a read of a write-only variable)."""
    string_size: int = 0
    """A STRING's bytes with the terminating NUL (21, 128, a VSTRING's size); 0 for the others."""
    levels: tuple[tuple[str, int], ...] = ()
    """A leaf of a structure: each level's name and how many of ``dims`` it has
    (``(("curve", 1), ("point", 1), ("X", 0))``); empty for a variable of its own (one level)."""
    type_name: str = ""
    """The declared type (``VSTRING``, ``typ_pos``: :attr:`declared`), where it is not ``type``."""

    @property
    def size(self) -> int:
        return math.prod(self.dims) if self.dims else 1

    @property
    def path(self) -> str:
        """The name an NC program and the docs use: ``V.E.name``, ``V.E.curve[].point[].X``."""
        if not self.levels:
            return f"V.E.{self.name}"
        return "V.E." + ".".join(name + ("[]" if count else "") for name, count in self.levels)

    @property
    def declared(self) -> str:
        """The type as declared: ``SGN32``, ``STRING``, ``VSTRING``."""
        return self.type_name or self.type.value

    def element_path(self, index: Sequence[int]) -> str:
        """``V.E.curve[2].point[5].X`` of the leaf's element ``(2, 5)``."""
        levels = self.levels or ((self.name, len(self.dims)),)
        parts: list[str] = []
        at = 0
        for name, count in levels:
            own = index[at : at + count]
            at += count
            parts.append(name + (f"[{','.join(str(i) for i in own)}]" if count else ""))
        return "V.E." + ".".join(parts)

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
        if self.type is ExternalType.STRING:
            return self._coerce_string(value)
        if isinstance(value, str):
            raise ExternalVariableError(
                f"{self.path} is a number ({self.type}): {_shown(value)} is a string", ALARM_TYPE
            )
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

    def _coerce_string(self, value: ExternalValue) -> str:
        if not isinstance(value, str):
            raise ExternalVariableError(
                f'{self.path} is a {self.declared}: {value!r} is a number (write a string, "...")',
                ALARM_TYPE,
            )
        most = self.string_size - 1
        if len(value) > most:
            raise ExternalVariableError(
                f"{self.path} holds at most {most} characters ({self.declared}), {len(value)} given: "
                f"{_shown(value)}",
                ALARM_STRING_LENGTH,
            )
        try:
            value.encode(STRING_ENCODING)
        except UnicodeEncodeError as exc:
            raise ExternalVariableError(
                f"{self.path}: {value[exc.start : exc.end]!r} is no Windows-1252 character (a "
                f"{self.declared} holds Windows-1252 text)",
                ALARM_TYPE,
            ) from None
        if "\0" in value:
            raise ExternalVariableError(f"{self.path}: a {self.declared} ends at its first NUL", ALARM_TYPE)
        return value

    def zero(self) -> ExternalValue:
        if self.type is ExternalType.BOOLEAN:
            return False
        if self.type in (ExternalType.REAL32, ExternalType.REAL64):
            return 0.0
        if self.type is ExternalType.STRING:
            return ""
        return 0


def _shown(text: str) -> str:
    return repr(text if len(text) <= 32 else text[:29] + "...")


class ExternalVariables:
    """The values of every configured V.E. variable, all zero at start (as after the kernel's start-up)."""

    def __init__(self, specs: Sequence[ExternalVarSpec] = ()) -> None:
        self._specs: dict[tuple[int | None, str], ExternalVarSpec] = {}
        self._values: dict[tuple[int | None, str], list[ExternalValue]] = {}
        self._structures: dict[tuple[int | None, str], dict[str, str]] = {}
        """(area, upper-case path of a structure level) -> its elements (upper case -> as declared)"""
        self._declared: dict[tuple[int | None, str], str] = {}
        """(area, upper-case path of a structure level) -> the path as declared"""
        for spec in specs:
            key = (spec.channel, spec.name.upper())
            if key in self._specs:
                where = "global" if spec.channel is None else f"channel {spec.channel}"
                raise ExternalVariableError(f"{spec.path} is declared twice ({where})")
            names = spec.name.split(".")
            if any(not part or len(part) > MAX_NAME_LENGTH for part in names):
                raise ExternalVariableError(f"{spec.path}: a name has 1 to {MAX_NAME_LENGTH} characters")
            if spec.type is ExternalType.STRING and spec.string_size < 1:
                raise ExternalVariableError(f"{spec.path}: a STRING has a size of at least 1 byte")
            for depth in range(1, len(names)):
                path = ".".join(names[:depth])
                level = (spec.channel, path.upper())
                self._structures.setdefault(level, {})[names[depth].upper()] = names[depth]
                self._declared[level] = path
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

    def elements(self, name: str, channel: int | None) -> list[str] | None:
        """The element names of the structure ``V.E.name`` (``UserInteraction`` -> ``["Message",
        "Answer"]``), as ``channel``'s programs see it; None when ``name`` is no structure."""
        level = self._level(name, channel)
        return None if level is None else list(self._structures[level].values())

    def _level(self, name: str, channel: int | None) -> tuple[int | None, str] | None:
        key = name.upper()
        if channel is not None and (channel, key) in self._structures:
            return channel, key
        return (None, key) if (None, key) in self._structures else None

    def unknown(self, name: str, channel: int | None) -> ExternalVariableError:
        """The error for ``V.E.name``, which :meth:`spec` does not know: a structure without an element
        named, an element the structure does not have, or an undeclared name (with a did-you-mean)."""
        level = self._level(name, channel)
        if level is not None:
            members = list(self._structures[level].values())
            declared = self._declared[level]
            return ExternalVariableError(
                f"V.E.{declared} is a structure: name one of its elements ({', '.join(members)}), "
                f"e.g. V.E.{declared}.{members[0]}",
                ALARM_UNDECLARED,
            )
        head, dot, last = name.rpartition(".")
        level = self._level(head, channel) if dot else None
        if level is not None:
            members = list(self._structures[level].values())
            close = difflib.get_close_matches(last.upper(), [m.upper() for m in members], n=1)
            hint = "".join(f"; did you mean {m}?" for m in members if close and m.upper() == close[0])
            return ExternalVariableError(
                f"V.E.{self._declared[level]} has no element {last} "
                f"(its elements: {', '.join(members)}){hint}",
                ALARM_UNDECLARED,
            )
        known = {spec.name.split(".")[0].upper(): spec.name.split(".")[0] for spec in self._specs.values()}
        close = difflib.get_close_matches(name.split(".", maxsplit=1)[0].upper(), list(known), n=1)
        hint = f"; did you mean V.E.{known[close[0]]}?" if close else ""
        return ExternalVariableError(
            f"V.E.{name} is not declared in the machine file{hint}", ALARM_UNDECLARED
        )

    def _slot(self, name: str, channel: int | None) -> tuple[ExternalVarSpec, list[ExternalValue]]:
        spec = self.spec(name, channel)
        if spec is None:
            raise self.unknown(name, channel)
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


def external_specs(config: MachineConfig) -> list[ExternalVarSpec]:
    """The specs of a machine file's V.E. variables: one per variable, one per leaf of a structured one
    (schemas/external_types.py), in declaration order."""
    _, types = machine_types(config)
    specs: list[ExternalVarSpec] = []
    for variable, node in zip(config.external_variables, types, strict=True):
        for leaf in leaves(variable, node):
            structured = len(leaf.levels) > 1
            specs.append(
                ExternalVarSpec(
                    leaf.name,
                    ExternalType(leaf.type),
                    leaf.dims,
                    leaf.channel,
                    leaf.synchronous,
                    leaf.access_rights,
                    leaf.string_size,
                    tuple((name, len(dims)) for name, dims in leaf.levels) if structured else (),
                    leaf.declared,
                )
            )
    return specs
