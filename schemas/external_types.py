"""The data types of the V.E. variables: elementary, STRING, VSTRING and structures (N-05).

The kernel declares an external variable's type with P-EXTV-00003 ``var[i].type``: an elementary type
(BOOLEAN, SGN08 .. UNS32, REAL32, REAL64), STRING, VSTRING or a structure of its own list
(``struct[i].*``, P-EXTV-00015 .. 00021; "Parameterising the memory layout of V.E. variables",
https://infosys.beckhoff.com/content/1033/tf5200_external_variables/307199243.html, and its "Example of
V.E. structures", https://infosys.beckhoff.com/content/1033/tf5200_external_variables/321583243.html):

* **STRING** holds 20 characters (21 bytes with the terminating NUL), or 127 (128 bytes) with
  ``use_extended_string_var`` (P-EXTV-00022; "use_extended_string_var parameter",
  https://infosys.beckhoff.com/content/1033/expextvar/15424430859.html). The kernel reserves 24 bytes for
  the short one; the image here keeps only the string's own bytes (it places the variables itself).
* **VSTRING** has the size its declaration gives, the NUL included (P-EXTV-00008 ``var[i].size``,
  P-EXTV-00021 ``struct[i].element[j].size``: 1 .. 800 bytes, default 128).
* **A structure** has elements of any of these types, arrays too, structures nested; an element inherits
  the variable's synchronisation and access rights unless it sets its own (P-EXTV-00018, P-EXTV-00019).

This module resolves a machine file's declarations into that tree (:func:`resolve_structures`,
:func:`variable_type`) and flattens a variable into its *leaves* (:func:`leaves`): one per elementary or
STRING part, with the array dimensions of every level in between (``V.E.curve[2].point[5].X`` is element
(2, 5) of the leaf ``curve.point.X``). The layout places the leaves' elements in memory order
(``schemas/layout.py``), the engine's store keeps one value list per leaf (``hli_server/engine/external.py``);
both come from this one resolution.

Placement (the project's, as C lays out a struct; docs/process-image.md): a number is aligned to its
size, a STRING to 1 byte; a structure to its most aligned element, its size rounded up to that
alignment, so that every element of an array of structures has the same shape. :class:`Shape` gives
size and alignment in the image's bytes, in Modbus coils and in holding registers.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Final, Protocol

__all__ = [
    "ELEMENTARY_TYPES",
    "ELEMENT_PATH_FORMS",
    "EXTENDED_STRING_SIZE",
    "MAX_NESTING",
    "STRING_SIZE",
    "STRING_TYPES",
    "VSTRING_DEFAULT_SIZE",
    "VSTRING_MAX_SIZE",
    "ElementShape",
    "ExternalLeaf",
    "ExternalShape",
    "ExternalTypeError",
    "Member",
    "Shape",
    "StructureShape",
    "TypeNode",
    "VariableShape",
    "element_path",
    "leaves",
    "machine_types",
    "resolve_structures",
    "string_size",
    "variable_type",
]

ELEMENTARY_TYPES: Final = (
    "BOOLEAN",
    "SGN08",
    "UNS08",
    "SGN16",
    "UNS16",
    "SGN32",
    "UNS32",
    "REAL32",
    "REAL64",
)
STRING_TYPES: Final = ("STRING", "VSTRING")
STRING_SIZE: Final = 21
"""A STRING without ``use_extended_string_var``: 20 characters and the NUL (P-EXTV-00022)."""
EXTENDED_STRING_SIZE: Final = 128
"""A STRING with ``use_extended_string_var``: 127 characters and the NUL (P-EXTV-00022)."""
VSTRING_DEFAULT_SIZE: Final = 128
"""A VSTRING without a size: 127 characters and the NUL (P-EXTV-00008, P-EXTV-00021)."""
VSTRING_MAX_SIZE: Final = 800
"""The largest VSTRING, the NUL included (P-EXTV-00021's range; the kernel's 21788 beyond it)."""
MAX_NESTING: Final = 8
"""Structures nested deeper than this are refused (a bound on the tree; the kernel's pages give none)."""

_NUMBER_BYTES: Final = {
    "BOOLEAN": 1,
    "SGN08": 4,
    "UNS08": 4,
    "SGN16": 4,
    "UNS16": 4,
    "SGN32": 4,
    "UNS32": 4,
    "REAL32": 8,
    "REAL64": 8,
}
"""Bytes of the image field of each elementary type (the image's BOOL, DINT, UDINT, LREAL: layout.py)."""


class ExternalTypeError(ValueError):
    """A declaration that does not resolve: unknown type, a structure that contains itself, too deep."""


# What this module reads of the declarations (schemas/config.py's models are them; the configuration
# imports the layout, which imports this module: neither imports the configuration).


class ElementShape(Protocol):
    """An element of a structure (:class:`~schemas.config.ExternalElementConfig`)."""

    @property
    def name(self) -> str: ...
    @property
    def type(self) -> str: ...
    @property
    def dims(self) -> Sequence[int]: ...
    @property
    def size(self) -> int | None: ...
    @property
    def synchronous(self) -> bool | None: ...
    @property
    def access_rights(self) -> str | None: ...


class StructureShape(Protocol):
    """A structure type (:class:`~schemas.config.ExternalStructureConfig`)."""

    @property
    def name(self) -> str: ...
    @property
    def elements(self) -> Sequence[ElementShape]: ...
    @property
    def description(self) -> str: ...


class VariableShape(Protocol):
    """A V.E. variable (:class:`~schemas.config.ExternalVariableConfig`)."""

    @property
    def name(self) -> str: ...
    @property
    def type(self) -> str: ...
    @property
    def dims(self) -> Sequence[int]: ...
    @property
    def size(self) -> int | None: ...
    @property
    def channel(self) -> int | None: ...
    @property
    def synchronous(self) -> bool: ...
    @property
    def access_rights(self) -> str: ...
    @property
    def description(self) -> str: ...


class ExternalShape(Protocol):
    """A machine's V.E. declarations (:class:`~schemas.config.MachineConfig` has them)."""

    @property
    def external_variables(self) -> Sequence[VariableShape]: ...
    @property
    def external_structures(self) -> Sequence[StructureShape]: ...
    @property
    def use_extended_string_var(self) -> bool: ...


@dataclass(frozen=True, slots=True)
class Shape:
    """Size and alignment of a type in one of the three spaces it occupies."""

    size: int
    align: int

    def place(self, cursor: int, count: int = 1) -> tuple[int, int]:
        """``(start, end)`` of ``count`` of these placed at ``cursor``."""
        start = _round_up(cursor, self.align)
        return start, start + self.size * count


_EMPTY: Final = Shape(0, 1)


@dataclass(frozen=True, slots=True)
class TypeNode:
    """A resolved type: elementary or STRING (``members`` empty) or a structure (``members``)."""

    name: str
    """The kernel's type name (``SGN32``, ``STRING``) or the structure's as declared (``typ_pos``)."""
    string_size: int = 0
    """STRING/VSTRING: bytes with the NUL; 0 otherwise."""
    members: tuple[Member, ...] = ()
    description: str = ""

    @property
    def is_structure(self) -> bool:
        return bool(self.members)

    @property
    def is_string(self) -> bool:
        return self.string_size > 0

    @property
    def image(self) -> Shape:
        """Bytes in the image."""
        if self.members:
            return _struct_shape([(m.type.image, m.count) for m in self.members])
        if self.string_size:
            return Shape(self.string_size, 1)
        size = _NUMBER_BYTES[self.name]
        return Shape(size, size)

    @property
    def coils(self) -> Shape:
        """Modbus coils (the BOOLEAN parts)."""
        if self.members:
            return _struct_shape([(m.type.coils, m.count) for m in self.members])
        return Shape(1, 1) if self.name == "BOOLEAN" else _EMPTY

    @property
    def registers(self) -> Shape:
        """Modbus holding registers (the numbers and strings): 2 per DINT/UDINT at an even address, 4 per
        LREAL at a multiple of 4, a STRING's bytes two to a register."""
        if self.members:
            return _struct_shape([(m.type.registers, m.count) for m in self.members])
        if self.string_size:
            return Shape((self.string_size + 1) // 2, 1)
        if self.name == "BOOLEAN":
            return _EMPTY
        count = _NUMBER_BYTES[self.name] // 2
        return Shape(count, count)


@dataclass(frozen=True, slots=True)
class Member:
    """One element of a structure (``struct[i].element[j].*``)."""

    name: str
    type: TypeNode
    dims: tuple[int, ...] = ()
    synchronous: bool | None = None
    """P-EXTV-00018; None: the variable's (inherited)."""
    access_rights: str | None = None
    """P-EXTV-00019; None: the variable's (inherited)."""

    @property
    def count(self) -> int:
        return math.prod(self.dims) if self.dims else 1


def _round_up(value: int, step: int) -> int:
    return -(-value // step) * step


def _struct_shape(parts: Sequence[tuple[Shape, int]]) -> Shape:
    cursor = 0
    align = 1
    for shape, count in parts:
        _, cursor = shape.place(cursor, count)
        align = max(align, shape.align)
    return Shape(_round_up(cursor, align), align)


def string_size(type_name: str, size: int | None, *, extended: bool) -> int:
    """The bytes (with the NUL) of a STRING or VSTRING; 0 for another type."""
    if type_name == "STRING":
        return EXTENDED_STRING_SIZE if extended else STRING_SIZE
    if type_name == "VSTRING":
        return VSTRING_DEFAULT_SIZE if size is None else size
    return 0


def resolve_structures(structures: Sequence[StructureShape], *, extended: bool) -> dict[str, TypeNode]:
    """The declared structures by upper-case name, resolved; :class:`ExternalTypeError` names every
    element whose type is unknown, a structure that contains itself, nesting deeper than
    :data:`MAX_NESTING`."""
    by_name = {s.name.upper(): s for s in structures}
    done: dict[str, TypeNode] = {}
    problems: list[str] = []

    def resolve(key: str, trail: tuple[str, ...]) -> TypeNode | None:
        if key in done:
            return done[key]
        declared = by_name[key]
        if key in trail:
            cycle = " -> ".join([*(by_name[k].name for k in trail[trail.index(key) :]), declared.name])
            problems.append(f"structure {declared.name} contains itself ({cycle})")
            return None
        if len(trail) >= MAX_NESTING:
            problems.append(
                f"structure {declared.name}: nested {len(trail) + 1} deep, at most {MAX_NESTING} here"
            )
            return None
        members: list[Member] = []
        for element in declared.elements:
            type_name = element.type
            upper = type_name.upper()
            if upper in ELEMENTARY_TYPES or upper in STRING_TYPES:
                node: TypeNode | None = TypeNode(upper, string_size(upper, element.size, extended=extended))
            elif upper in by_name:
                node = resolve(upper, (*trail, key))
            else:
                problems.append(
                    f"structure {declared.name}, element {element.name}: unknown type {type_name!r}"
                    + _hint(type_name, by_name)
                )
                node = None
            if node is None:
                return None
            members.append(
                Member(element.name, node, tuple(element.dims), element.synchronous, element.access_rights)
            )
        resolved = TypeNode(declared.name, 0, tuple(members), declared.description)
        done[key] = resolved
        return resolved

    for key in by_name:
        resolve(key, ())
    if problems:
        raise ExternalTypeError("; ".join(dict.fromkeys(problems)))
    return done


def _hint(type_name: str, structures: Mapping[str, object]) -> str:
    known = {name: name for name in (*ELEMENTARY_TYPES, *STRING_TYPES)}
    known.update({key: getattr(value, "name", key) for key, value in structures.items()})
    close = difflib.get_close_matches(type_name.upper(), known, n=1)
    did = f"; did you mean {known[close[0]]}?" if close else ""
    return f" (an elementary type, STRING, VSTRING or a structure of external_structures){did}"


def variable_type(variable: VariableShape, structures: Mapping[str, TypeNode], *, extended: bool) -> TypeNode:
    """The type of one variable: elementary, STRING/VSTRING or one of ``structures``."""
    upper = variable.type.upper()
    if upper in ELEMENTARY_TYPES or upper in STRING_TYPES:
        return TypeNode(upper, string_size(upper, variable.size, extended=extended))
    found = structures.get(upper)
    if found is None:
        raise ExternalTypeError(
            f"V.E.{variable.name}: unknown type {variable.type!r}" + _hint(variable.type, structures)
        )
    return found


@dataclass(frozen=True, slots=True)
class ExternalLeaf:
    """One elementary or STRING part of a V.E. variable: ``UserInteraction.Message``, ``curve.point.X``.

    ``levels`` are the names from the variable down with each level's array dimensions; ``dims`` all of
    them in a row, so that ``V.E.curve[2].point[5].X`` is the leaf's element ``(2, 5)``. ``structures``
    names the structure type of every level but the last (``("typcurve", "typ_pos")``)."""

    channel: int | None
    levels: tuple[tuple[str, tuple[int, ...]], ...]
    type: str
    """The elementary type's name, or ``STRING`` (a VSTRING too: its size is in ``string_size``)."""
    string_size: int
    synchronous: bool
    access_rights: str
    structures: tuple[str, ...] = ()
    declared: str = ""
    """The type as declared where it differs from ``type``: ``VSTRING``."""

    @property
    def name(self) -> str:
        return ".".join(name for name, _ in self.levels)

    @property
    def dims(self) -> tuple[int, ...]:
        return tuple(d for _, dims in self.levels for d in dims)


def leaves(variable: VariableShape, node: TypeNode) -> Iterator[ExternalLeaf]:
    """The leaves of ``variable`` (of type ``node``) in the order of its elements."""
    yield from _leaves(
        node,
        ((variable.name, tuple(variable.dims)),),
        (),
        variable.channel,
        variable.synchronous,
        variable.access_rights,
    )


def _leaves(
    node: TypeNode,
    levels: tuple[tuple[str, tuple[int, ...]], ...],
    structures: tuple[str, ...],
    channel: int | None,
    synchronous: bool,
    access_rights: str,
) -> Iterator[ExternalLeaf]:
    if not node.members:
        yield ExternalLeaf(
            channel,
            levels,
            "STRING" if node.string_size else node.name,
            node.string_size,
            synchronous,
            access_rights,
            structures,
            "VSTRING" if node.name == "VSTRING" else "",
        )
        return
    for member in node.members:
        yield from _leaves(
            member.type,
            (*levels, (member.name, member.dims)),
            (*structures, node.name),
            channel,
            synchronous if member.synchronous is None else member.synchronous,
            access_rights if member.access_rights is None else member.access_rights,
        )


def machine_types(config: ExternalShape) -> tuple[dict[str, TypeNode], list[TypeNode]]:
    """The resolved structures of ``config`` and the type of each of its ``external_variables`` (in order)."""
    extended = config.use_extended_string_var
    structures = resolve_structures(config.external_structures, extended=extended)
    return structures, [variable_type(v, structures, extended=extended) for v in config.external_variables]


_PATH_LEVEL: Final = r"[A-Za-z_][A-Za-z0-9_]*\s*(?:\[\s*[0-9]+(?:\s*,\s*[0-9]+)*\s*\]\s*)*"
_ELEMENT_PATH: Final = re.compile(rf"\s*V\.E\.({_PATH_LEVEL}(?:\.\s*{_PATH_LEVEL})*)$", re.IGNORECASE)
_PATH_INDEX: Final = re.compile(r"\[([^\]]*)\]")
ELEMENT_PATH_FORMS: Final = "V.E.NAME, V.E.NAME[i], V.E.NAME.ELEMENT"
"""The forms :func:`element_path` reads, for a message that refuses another."""


def element_path(text: str) -> tuple[str, list[int]] | None:
    """A V.E. element as a program or a preset writes it - ``V.E.PLC_READY``, ``V.E.POS[1][2]`` (or
    ``[1, 2]``), ``V.E.UserInteraction.Message``, ``V.E.curve[2].point[5].X`` (any case, blanks around
    the brackets and dots) - as its leaf's name and index: ``("curve.point.X", [2, 5])`` (the indices of
    all levels in a row, as :attr:`ExternalLeaf.dims`). None for a text of another form."""
    found = _ELEMENT_PATH.match(text)
    if found is None:
        return None
    path = found.group(1)
    name = ".".join(level.split("[")[0].strip() for level in path.split("."))
    return name, [int(i) for group in _PATH_INDEX.findall(path) for i in group.split(",")]
