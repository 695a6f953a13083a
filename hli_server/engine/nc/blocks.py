"""Parsed NC blocks: what the parser hands to the decoder (E-04).

The parser is syntax only: it turns one line into one :class:`Block` (or an :class:`NcError`).
Modal meaning (G90/G91, planes, offsets, the area definition in progress) is the decoder's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

from schemas.events import place

__all__ = [
    "AreaBegin",
    "AreaClear",
    "AreaCommand",
    "AreaEnd",
    "AreaKind",
    "AreaOff",
    "AreaOn",
    "AreaShape",
    "Block",
    "NcError",
]


class AreaKind(StrEnum):
    WORK = "WORK"
    PROT = "PROT"


class AreaShape(StrEnum):
    POLY = "POLY"
    CIRC = "CIRC"


@dataclass(frozen=True, slots=True)
class AreaBegin:
    """``#CONTROL AREA BEGIN|START [ID=n WORK|PROT POLY|CIRC MIN_EXCUR=v MAX_EXCUR=v ...]`` (C14-02)."""

    area_id: int
    kind: AreaKind
    shape: AreaShape
    min_excur: float
    max_excur: float
    excur_ax: str | None = None
    excur_axnr: int | None = None
    monitor_lvl: str = "MCS"


@dataclass(frozen=True, slots=True)
class AreaEnd:
    """``#CONTROL AREA END``."""


@dataclass(frozen=True, slots=True)
class AreaOn:
    """``#CONTROL AREA ON [ID=n]`` / ``ON ALL`` (C14-11). ``area_id`` None with ``all_`` True = ALL."""

    area_id: int | None
    all_: bool


@dataclass(frozen=True, slots=True)
class AreaOff:
    """``#CONTROL AREA OFF [ID=n]`` / ``OFF ALL`` / bare ``OFF`` (area activated last) (C14-12)."""

    area_id: int | None
    all_: bool


@dataclass(frozen=True, slots=True)
class AreaClear:
    """``#CONTROL AREA CLEAR [ID=n]`` / ``CLEAR ALL`` (C14-13)."""

    area_id: int | None
    all_: bool


AreaCommand = AreaBegin | AreaEnd | AreaOn | AreaOff | AreaClear


@dataclass(frozen=True, slots=True)
class Block:
    """One NC line.

    ``line`` is the 1-based line number in the program text, ``number`` the N word (None if absent).
    ``axes`` keeps program order; names are upper case (``X``, ``X2``). ``centre`` holds I/J/K.
    ``two_path`` holds the second path of a two-path line (``: G0 X.. : G0 U..``, C14-18), which the
    decoder refuses as not supported.
    """

    line: int
    number: int | None
    text: str
    g_codes: tuple[int, ...] = ()
    m_codes: tuple[int, ...] = ()
    axes: tuple[tuple[str, float], ...] = ()
    centre: tuple[tuple[str, float], ...] = ()
    feed: float | None = None
    area: AreaCommand | None = None
    two_path: tuple[Block, ...] = ()
    extra: dict[str, float] = field(default_factory=dict)
    program: str = ""
    """The subroutine or cycle the block belongs to (``sub.nc``); empty in the main program."""
    probe_touch: float | None = None
    """A built-in cycle's measuring move (``engine/cycles``): the fraction of the line at which the
    simulated probe touches the simulated workpiece (``inf``: it does not); None for a programmed block."""

    @property
    def label(self) -> str:
        """``N130`` or ``line 14`` when the block has no number."""
        return f"N{self.number}" if self.number is not None else f"line {self.line}"

    @property
    def is_empty(self) -> bool:
        return not (
            self.g_codes
            or self.m_codes
            or self.axes
            or self.centre
            or self.feed is not None
            or self.area is not None
            or self.extra
            or self.two_path
        )


class NcError(Exception):
    """A numbered program error with its place: ``line 14, N130: polygon not closed ...``.

    ``program`` names the subroutine or cycle the line belongs to (empty in the main program);
    ``params`` are the alarm's parameters where the kernel's diagnosis page lists some."""

    def __init__(
        self,
        alarm: int,
        line: int,
        block: str,
        message: str,
        params: dict[str, object] | None = None,
        program: str = "",
    ) -> None:
        super().__init__(alarm, line, block, message)
        self.alarm = alarm
        self.line = line
        self.block = block
        self.message = message
        self.params: dict[str, object] = params or {}
        self.program = program

    def __str__(self) -> str:
        where = place(self.line, self.block)
        if self.program:
            where = f"{self.program}, {where}"
        return f"{where}: {self.message} [{self.alarm}]"
