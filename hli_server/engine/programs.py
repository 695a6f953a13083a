"""Where a program finds the programs it calls (``L name``, ``L CYCLE [NAME=...]``, N-02).

The engine does no I/O: it asks a :class:`ProgramLibrary` for a program by the name the NC program
wrote, and the runtime hands it one that reads the program directories (the machine file,
``--program-dir``) and the files uploaded with a program. :class:`MemoryLibrary` serves files held in
memory (uploads, tests); it is also the default of a :class:`~hli_server.engine.machine.Machine`:
empty, so that every global call is an alarm naming what was searched.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

__all__ = ["MemoryLibrary", "ProgramFile", "ProgramLibrary"]


@dataclass(frozen=True, slots=True)
class ProgramFile:
    """A program found by a library: the name it was found by, its text and where it came from
    (a path, or ``upload:name``), for alarms and reports."""

    name: str
    text: str
    origin: str


class ProgramLibrary(Protocol):
    """Finds global subprograms and cycles by the name an NC program calls them by."""

    def find(self, name: str) -> ProgramFile | None:
        """The program ``name`` (as programmed, e.g. ``UP1.NC`` or ``cycle_x``), or None."""
        ...

    def searched(self) -> tuple[str, ...]:
        """Where :meth:`find` looks, in order (directories, ``uploaded files``): the alarm of a
        program that is not found names every one."""
        ...


class MemoryLibrary:
    """Programs held in memory, by file name. A name matches exactly, else case-insensitively."""

    def __init__(self, files: Mapping[str, str] | None = None, where: str = "uploaded files") -> None:
        self._files = dict(files or {})
        self._folded = {name.casefold(): name for name in self._files}
        self._where = where

    def find(self, name: str) -> ProgramFile | None:
        key = name if name in self._files else self._folded.get(name.casefold())
        if key is None:
            return None
        return ProgramFile(key, self._files[key], f"upload:{key}")

    def searched(self) -> tuple[str, ...]:
        return (self._where,) if self._files else ()

    def write(self, name: str, text: str) -> None:
        """Add or replace file ``name`` (a file of the same name in another case is replaced)."""
        old = self._folded.get(name.casefold())
        if old is not None:
            del self._files[old]
        self._files[name] = text
        self._folded[name.casefold()] = name
