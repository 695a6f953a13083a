"""Program levels (N-06, N-07): the units of a program text (``%L name`` local subroutines and the main
part) with their statements compiled once, the open control blocks of a level, what a level skips while
it seeks (a branch, a loop's end, a label), the level itself (:class:`Frame`) - and where a call goes
(:class:`ProgramResolver`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Final

from hli_server.engine.nc.blocks import Block
from hli_server.engine.nc.compiler import Compiler
from hli_server.engine.nc.directives import Host
from hli_server.engine.nc.expr import Ref, Value
from hli_server.engine.nc.language import A_NOT_FOUND
from hli_server.engine.nc.reader import read_block, strip_comments
from hli_server.engine.nc.source import LineTooLongError, ProgramText
from hli_server.engine.nc.statements import Call, ConstBlock, Empty, Stmt
from hli_server.engine.nc.variables import Variable

__all__ = ["Frame", "OpenBlock", "ProgramResolver", "Seek", "Units"]

_STATEMENT_CACHE: Final = 50_000
"""Compiled statements kept per program text (a loop body is compiled once; a CAM file streams)."""
_GLOBAL_UNITS: Final = 64
"""Global subprograms kept compiled (by name) in one program run."""


class Units:
    """The program units of one text: ``%L name`` local subroutines and where the main part begins
    (manual "Subroutine techniques", 206822155), found by scanning the text's ``%`` headers lazily."""

    def __init__(self, text: ProgramText, compiler: Compiler, source: str = "") -> None:
        self.text = text
        self.compiler = compiler
        self.source = source
        """A global subprogram's text as its library gave it (the interpreter reuses these units, and
        the statements compiled in them, while the library gives the same text)."""
        self.cache: dict[int, Stmt] = {}
        self._locals: dict[str, int] = {}
        self._scanned = 0
        self._eof = False
        self.main_start = -1

    def statement(self, line: int, program: str, keep: bool) -> Stmt | Block | None:
        """The statement at ``line``, compiled once; ``keep``: the flow may come back (a loop is open,
        a subroutine is called again), so even a block of constant words is kept. A line of constant
        words (nearly every line of a CAM program) is its :class:`Block` at once."""
        stmt = self.cache.get(line)
        if stmt is None:
            if not keep:
                try:
                    raw_line = self.text.line(line)
                except LineTooLongError:
                    raw_line = None  # read_block explains it
                if raw_line is not None:
                    block = self.compiler.plain_block(raw_line, line, program)
                    if block is not None:
                        return block
            raw = read_block(self.text, line)
            if raw is None:
                return None
            stmt = self.compiler.compile(raw, program)
            if keep or not (isinstance(stmt, (ConstBlock, Empty))):
                if len(self.cache) >= _STATEMENT_CACHE:
                    self.cache.clear()
                self.cache[line] = stmt
        return stmt

    def _scan_line(self, line: int) -> bool:
        try:
            raw = self.text.line(line)
        except LineTooLongError:
            raw = "?"  # no header; the interpreter refuses the line when it gets there
        if raw is None:
            return False
        stripped = raw.lstrip()
        if stripped.startswith("%"):
            rest = stripped[1:]
            local = rest[:1] in ("L", "l") and rest[1:2] in (" ", "\t")
            name = strip_comments(rest[2:] if local else rest).strip()
            key = name.split()[0].upper() if name else ""
            if local:
                self._locals.setdefault(key, line + 1)
            elif self.main_start < 0:
                self.main_start = line + 1
        elif self.main_start < 0 and not self._locals and strip_comments(raw).strip():
            self.main_start = 1  # code before any header: the main program starts at the top
        return True

    def _scan(self, stop: int | None) -> None:
        while not self._eof and (stop is None or self._scanned < stop):
            if not self._scan_line(self._scanned + 1):
                self._eof = True
                return
            self._scanned += 1

    def main(self) -> int:
        """The first line of the main part (after the local subroutines and its ``%name`` header)."""
        while self.main_start < 0 and not self._eof:
            self._scan(self._scanned + 1)
        if self.main_start < 0:
            self.main_start = self._scanned + 1  # only local subroutines: an empty main part
        return self.main_start

    def local(self, name: str) -> int | None:
        """The first line of local subroutine ``name`` (``%L name``), or None."""
        key = name.upper()
        found = self._locals.get(key)
        if found is None and not self._eof:
            self._scan(None)
            found = self._locals.get(key)
        return found


class OpenBlock:
    """An open control block of a program level."""

    def __init__(self, keyword: str, start: int, body: int) -> None:
        self.keyword = keyword
        self.start = start
        """Line of the opening statement ($WHILE loops back to it)."""
        self.body = body
        """First line after it ($DO, $REPEAT and $FOR loop back to it)."""
        self.taken = False
        """$IF, #IF: a branch has run (the others are skipped)."""
        self.value: Value = 0.0
        """$SWITCH: the value; $FOR: the end value."""
        self.step = 0.0
        self.target: Ref | None = None
        self.default = -1
        """$SWITCH: the line after its $DEFAULT (-1 if none was passed)."""
        self.valid = True
        """False for a $FOR entered by a jump (its range is unknown)."""


SEEK_BRANCH: Final = 1
"""A false $IF/$ELSEIF: the next $ELSEIF/$ELSE/$ENDIF of this block."""
SEEK_END: Final = 2
"""Past the end of the block (a false $WHILE/$FOR, a taken $IF's other branches, $BREAK)."""
SEEK_CASE: Final = 3
"""$SWITCH: the matching $CASE, else $DEFAULT, else $ENDSWITCH."""
SEEK_CONTINUE: Final = 4
"""$CONTINUE: the loop's closing statement, which then runs."""
SEEK_HASH: Final = 5
"""A false #IF: its #ELSE or #ENDIF."""
SEEK_HASH_END: Final = 6
"""A taken #IF's #ELSE branch: its #ENDIF."""
SEEK_LABEL: Final = 7
"""$GOTO: the label, forward, then from the unit's start."""


class Seek:
    def __init__(self, mode: int, depth: int, origin: int, label: str = "") -> None:
        self.mode = mode
        self.depth = depth
        self.origin = origin
        self.label = label
        self.wrapped = False
        self.pending: list[OpenBlock] = []
        """$GOTO forward: blocks opened between the jump and the label."""


class Frame:
    """A program level: a unit of a text, where it is, its open blocks and local variables."""

    def __init__(self, kind: str, units: Units, name: str, start: int, call: Block | None) -> None:
        self.kind = kind
        """``main``, ``local``, ``global`` or ``cycle``."""
        self.units = units
        self.name = name
        self.start = start
        self.line = start
        self.call = call
        self.open: list[OpenBlock] = []
        self.seek: Seek | None = None
        self.locals: dict[str, Variable] = {}
        self.cycle_vars: dict[str, Variable] = {}
        self.params: dict[int, Value] | None = None
        self.standin: Iterator[Block] | None = None
        """A built-in cycle's blocks (engine/cycles): the level hands them out instead of running a text."""
        self.synced = -1
        """The line whose synchronous reads were flushed for (re-run after a #FLUSH WAIT)."""
        self.returning = False
        self.program = "" if kind == "main" else name
        self.keep = kind != "main"
        """Keep every compiled statement: a subroutine is called again."""


# --- where a call goes -----------------------------------------------------------------------------------
_OUTSIDE = (
    " (a path that is absolute or leaves its directory is never read here: programs are found by name "
    "below the program directories; see docs/nc-language.md)"
)


def _leaves_directories(name: str) -> bool:
    """``D:\\prog\\x.nc``, ``/prog/x.nc``, ``..\\x.nc``: a name the program libraries never follow."""
    unified = name.replace("\\", "/")
    return (
        unified.startswith("/")
        or (len(unified) > 1 and unified[1] == ":" and unified[0].isalpha())
        or ".." in unified.split("/")
    )


class ProgramResolver:
    """Where a call goes (``L name``, ``LL name``, ``L CYCLE [NAME=..]``; manual "Subroutine techniques",
    206822155): the one place the program a call names is found, or alarm 914010 raised.

    A local subroutine (``LL``) is a ``%L name`` unit of the calling text; a global subroutine or a cycle
    is a file of the machine's program libraries (``Host.find_program``), compiled once per program run
    while the library gives the same text. A cycle's file is looked for in the channel's
    ``cycle_directories`` too (``Host.find_cycle``); where none has it, the built-in stand-in of a documented
    TF5225/TF5293 cycle runs (``Host.stand_in``, engine/cycles, docs/cycles.md)."""

    def __init__(self, compiler: Compiler, host: Host) -> None:
        self.compiler = compiler
        self.host = host
        self._globals: dict[str, Units] = {}
        """Global subprograms and cycles called in this program, compiled once (a pocket calls one
        cycle thousands of times)."""

    def clear(self) -> None:
        """A new program run: the global subprograms are looked up again."""
        self._globals = {}

    def resolve(
        self,
        call: Call,
        stmt: Stmt,
        caller: Frame,
        place: Block,
        params: dict[int, Value] | None = None,
        results: Callable[[str, float], None] | None = None,
    ) -> Frame:
        """The program level ``call`` (in ``stmt`` of level ``caller``) starts; ``place`` is the calling
        block; a cycle's ``params`` and where its built-in stand-in writes its ``V.CYC.`` results. Raises
        :class:`NcError` 914010 for a program not found."""
        if call.local:
            units = caller.units
            start = units.local(call.name)
            if start is None:
                raise stmt.error(
                    A_NOT_FOUND,
                    f"local subroutine {call.name} not found: no %L {call.name} in {units.text.name}",
                )
            return Frame("cycle" if call.cycle else "local", units, call.name, start, place)
        found = self.host.find_cycle(call.name) if call.cycle else self.host.find_program(call.name)
        if found is None and call.cycle and results is not None:
            blocks = self.host.stand_in(call.name, dict(params or {}), results, place.line, place.label)
            if blocks is not None:
                level = Frame("cycle", caller.units, call.name, caller.line, place)
                level.standin = blocks
                return level
        if found is None:
            searched = self.host.cycle_searched() if call.cycle else self.host.searched()
            where = ", ".join(searched) if searched else "no program directory is configured"
            raise stmt.error(
                A_NOT_FOUND,
                f"{'cycle' if call.cycle else 'global subroutine'} {call.name} not found; searched: "
                f"{where}{_OUTSIDE if _leaves_directories(call.name) else ''}"
                f"{self._extension_hint(call.name)}",
            )
        units = self._global_units(found.name, found.text)
        return Frame("cycle" if call.cycle else "global", units, found.name, units.main(), place)

    def _extension_hint(self, name: str) -> str:
        """A name without an extension whose ``.nc`` file is there: the kernel calls a global subroutine
        by its complete file name, extension included (manual "Global subroutines", 206834699), so
        ``L up1`` does not find ``UP1.nc`` there either; the alarm says what to write."""
        if "." in name.replace("\\", "/").rsplit("/", 1)[-1]:
            return ""
        found = self.host.find_program(name + ".nc")
        if found is None:
            return ""
        file = found.origin.replace("\\", "/").rsplit("/", 1)[-1].removeprefix("upload:")
        return (
            f"; {file} is there: a global subroutine is called by its complete file name, extension "
            f"included (L {name}.nc)"
        )

    def _global_units(self, name: str, text: str) -> Units:
        """The units of global subprogram ``name``: those of an earlier call while its text is the same
        (the file may have changed on disk or been uploaded again between two calls)."""
        key = name.upper()
        units = self._globals.get(key)
        if units is None or units.source != text:
            if len(self._globals) >= _GLOBAL_UNITS:
                self._globals.clear()
            units = Units(ProgramText(text, name), self.compiler, text)
            self._globals[key] = units
        return units
