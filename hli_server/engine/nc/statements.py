"""The statements a logical block compiles to (N-01..N-08): what the statement parser makes once and the
interpreter runs as often as the program's flow comes by.

A block of constant words is a :class:`ConstBlock` (the decoder's :class:`Block`, built once); a block
with expressions, assignments, a call or a jump is :class:`Words`; ``$IF`` .. ``$ENDFOR`` and ``#IF``
are :class:`Control`; ``#VAR`` is :class:`VarBlock`; the other ``#`` commands are :class:`Hash`. A block
that cannot be compiled is :class:`Refused`, carrying its alarm: the alarm is raised when the program's
flow reaches the block, not when the block is skipped (a false ``$IF`` branch may hold a construct the
simulator does not model).
"""

from __future__ import annotations

import re
from typing import Final

from hli_server.engine.nc.blocks import Block, NcError
from hli_server.engine.nc.expr import Expr, Ref
from hli_server.engine.nc.language import C_GOTO, CONTROL_WORDS
from hli_server.engine.nc.reader import RawBlock

__all__ = [
    "Assign",
    "Call",
    "ConstBlock",
    "Control",
    "Declaration",
    "Empty",
    "Goto",
    "Hash",
    "Header",
    "ImplicitCall",
    "Item",
    "Refused",
    "Stmt",
    "Technology",
    "VarBlock",
    "Word",
    "Words",
    "control_keyword",
    "word_expressions",
]

_CONTROL_WORD: Final = re.compile(r"\s*(?:/[0-9]*\s*)?(?:N\s*[0-9]+\s*:?\s*)?\$([A-Za-z]+)", re.ASCII)
_HASH_CONDITION: Final = re.compile(r"\s*#\s*(IF|ELSE|ENDIF)\b", re.ASCII | re.IGNORECASE)


def control_keyword(code: str) -> str:
    """The control word a block's code begins with (``IF``, ``#ELSE``), or ""."""
    found = _CONTROL_WORD.match(code)
    if found is not None:
        word = found.group(1).upper()
        return word if word in CONTROL_WORDS and word != C_GOTO else ""
    found = _HASH_CONDITION.match(code)
    return "#" + found.group(1).upper() if found is not None else ""


# --- statements ---------------------------------------------------------------------------------------
class Stmt:
    """A compiled logical block. ``first``/``last`` are its lines, ``number`` its N, ``text`` as written;
    ``label`` is the jump label it defines (``N10`` for ``N10:``, the name for ``[name]``) or None."""

    def __init__(self, raw: RawBlock, number: int | None) -> None:
        self.first = raw.first
        self.last = raw.last
        self.number = number
        self.text = raw.text
        self.label: str | None = None
        self.skip_level = -1
        """The block skip level (``/`` 0, ``/3`` 3), -1 without."""
        self.sync_reads = -1
        """Does it read a synchronous variable (1) or not (0)? -1: not asked yet (the interpreter's)."""

    @property
    def place(self) -> str:
        return f"N{self.number}" if self.number is not None else f"line {self.first}"

    def error(self, alarm: int, message: str) -> NcError:
        return NcError(alarm, self.first, self.place, message)


class Empty(Stmt):
    """A block without code: blank, comments only, a lone N number, ``:`` (the documents' elision)."""


class Header(Stmt):
    """``%name`` (a main program or global subroutine) or ``%L name`` (a local subroutine): where the
    unit before it ends."""

    def __init__(self, raw: RawBlock, local: bool, name: str) -> None:
        super().__init__(raw, None)
        self.local = local
        self.name = name


class ConstBlock(Stmt):
    """A block of constant words: the decoder's :class:`Block`, built once."""

    def __init__(self, raw: RawBlock, block: Block) -> None:
        super().__init__(raw, block.number)
        self.block = block


class Refused(Stmt):
    """A block that cannot run: its alarm is raised when the program's flow reaches it. ``keyword``
    is the control word it begins with (``$ELSE G1 X1``: ``ELSE``), if any: a control statement's
    error is raised even while its branch is skipped (the interpreter must know the program's
    structure)."""

    def __init__(self, raw: RawBlock, number: int | None, failure: NcError) -> None:
        super().__init__(raw, number)
        self.failure = failure
        self.keyword = control_keyword(raw.code)


class Item:
    """One part of a block of words: a word, an assignment, a call, a jump."""

    def __init__(self, text: str) -> None:
        self.text = text
        """As written (upper case), for messages."""


class Word(Item):
    """An address word: ``letter`` is G, M, H, F, S, T, D, I, J, K or ``AXIS`` (then ``name`` is the
    axis); ``value`` its value; ``extra`` the additional value of ``M52=-345`` / ``G131=50``."""

    def __init__(self, text: str, letter: str, name: str, value: Expr, extra: Expr | None = None) -> None:
        super().__init__(text)
        self.letter = letter
        self.name = name
        self.value = value
        self.extra = extra


class Assign(Item):
    def __init__(self, text: str, target: Ref, value: Expr) -> None:
        super().__init__(text)
        self.target = target
        self.value = value


class Technology(Item):
    """Spindle-specific syntax the path does not depend on (PM 208178187, 208317067): ``S[M19 POS45]``,
    ``S2[M4 REV5000]``, ``S1[MC_MoveVelocity Velocity=1333 Direction=1]``. ``target`` is the spindle's
    name, ``words`` its keywords and M/H functions in order, ``params`` the values by keyword (``REV``,
    ``VELOCITY``, ...), evaluated and accepted without effect. ``main`` holds the main spindle's ``M3``/
    ``M4``/``M5`` and ``REV`` as the block's ``M`` and ``S`` words (the speed G95 multiplies with)."""

    def __init__(
        self, text: str, target: str, words: list[str], params: dict[str, Expr], main: list[Word]
    ) -> None:
        super().__init__(text)
        self.target = target
        self.words = words
        self.params = params
        self.main = main


class Call(Item):
    """``L name`` (global), ``LL name`` (local), ``L CYCLE [NAME=.. @P1=..]`` (``cycle``): the last
    item of its block. ``params`` are the cycle's ``@P`` numbers and values. ``L V.E.name`` and ``LL
    V.E.name`` name the program by a V.E. STRING (``variable``; ``name`` is empty until the call runs:
    :meth:`named`)."""

    def __init__(
        self,
        text: str,
        local: bool,
        name: str,
        cycle: bool,
        params: list[tuple[int, Expr]],
        variable: Expr | None = None,
    ) -> None:
        super().__init__(text)
        self.local = local
        self.name = name
        self.cycle = cycle
        self.params = params
        self.variable = variable

    def named(self, name: str) -> Call:
        """This call of the program ``name`` (what ``L V.E.name`` calls when it runs)."""
        return Call(self.text, self.local, name, self.cycle, self.params)


class ImplicitCall(Item):
    """``G803``, ``G805[10.0, 9.7, , 2.5]``: the implicit call of the subprogram assigned to ``g``
    (PM 206278923; nc/implicit.py), at the end of its block. ``params`` are the values in brackets as
    ``@P`` numbers (a gap ``, ,`` leaves its number out); with values the call is a cycle call."""

    def __init__(self, text: str, g: int, params: list[tuple[int, Expr]], bracket: bool) -> None:
        super().__init__(text)
        self.g = g
        self.params = params
        self.bracket = bracket
        """Values in brackets were programmed (``G805[]`` too): the call is a cycle call."""


class Goto(Item):
    """``$GOTO N<expr>`` (``target`` None, ``number`` the expression) or ``$GOTO [name]``."""

    def __init__(self, text: str, target: str | None, number: Expr | None) -> None:
        super().__init__(text)
        self.target = target
        self.number = number


class Words(Stmt):
    """A block of words, assignments, a call and/or a jump, evaluated when it runs."""

    def __init__(self, raw: RawBlock, number: int | None, items: list[Item]) -> None:
        super().__init__(raw, number)
        self.items = items
        self.call: Call | None = None
        self.goto: Goto | None = None
        self.implicit: ImplicitCall | None = None
        for item in items:
            if isinstance(item, Call):
                self.call = item
            elif isinstance(item, Goto):
                self.goto = item
            elif isinstance(item, ImplicitCall):
                self.implicit = item


def word_expressions(stmt: Words) -> list[Expr]:
    """Every expression a block of words evaluates: word values, assignments (and their targets'
    indices), a call's parameters."""
    exprs: list[Expr] = []
    for item in stmt.items:
        if isinstance(item, Word):
            exprs.append(item.value)
            if item.extra is not None:
                exprs.append(item.extra)
        elif isinstance(item, Assign):
            exprs.append(item.value)
            exprs.extend(item.target.indices)
        elif isinstance(item, Call):
            exprs.extend(v for _, v in item.params)
            if item.variable is not None:  # L V.E.name: a synchronous V.E. is read after the flush
                exprs.append(item.variable)
        elif isinstance(item, ImplicitCall):
            exprs.extend(v for _, v in item.params)
        elif isinstance(item, Technology):
            exprs.extend(item.params.values())
            exprs.extend(w.value for w in item.main)
    return exprs


class Control(Stmt):
    """A control statement: ``keyword`` (``IF``, ``ENDWHILE``, ... or ``#IF`` for conditional
    interpretation) with its expressions: the condition, the ``$SWITCH`` value, the ``$CASE`` values,
    ``$FOR``'s start, end and step. ``target`` is ``$FOR``'s counter; ``goto`` the jump of
    ``$IF cond $GOTO ..``; ``frequency`` the qualifier of ``$IF ONCE ..``."""

    def __init__(
        self,
        raw: RawBlock,
        number: int | None,
        keyword: str,
        exprs: list[Expr],
        target: Ref | None = None,
        goto: Goto | None = None,
        frequency: str = "",
    ) -> None:
        super().__init__(raw, number)
        self.keyword = keyword
        self.exprs = exprs
        self.target = target
        self.goto = goto
        self.frequency = frequency
        """``$IF ONCE|EDGE|ALWAYS``: the qualifier of an $IF of a realtime cycle (TF5261), else ""."""


class Declaration:
    """One declaration of a ``#VAR`` block: ``V.P.NAME[2][3] : UNS32 = [..]`` or ``P10 = 5``."""

    def __init__(
        self,
        line: int,
        ref: Ref,
        dims: list[int],
        type_name: str,
        string_size: int,
        init: list[Expr],
    ) -> None:
        self.line = line
        self.ref = ref
        self.dims = dims
        self.type_name = type_name
        self.string_size = string_size
        self.init = init


class VarBlock(Stmt):
    def __init__(self, raw: RawBlock, number: int | None, declarations: list[Declaration]) -> None:
        super().__init__(raw, number)
        self.declarations = declarations


class Hash(Stmt):
    """``#MSG``, ``#FILE NAME``, ``#FLUSH``, ``#MEAS MODE``: ``command`` with its options.

    ``#MSG``: ``options`` holds the mode and receiver words (``SAVE``, ``SYN``, ``HMI``, ...), ``args``
    the format string and its values. ``#FILE NAME``: ``files`` maps ``MSG`` to its file name.
    ``#FLUSH``: ``options`` holds ``WAIT`` or ``CONTINUE``. ``#MEAS MODE``: ``args`` holds the
    measuring type, or nothing (the channel's default)."""

    def __init__(
        self,
        raw: RawBlock,
        number: int | None,
        command: str,
        options: list[str],
        args: list[Expr],
        files: dict[str, str] | None = None,
        params: dict[str, Expr] | None = None,
    ) -> None:
        super().__init__(raw, number)
        self.command = command
        self.options = options
        self.args = args
        self.files = files or {}
        self.params = params or {}
        """``#CONTOUR MODE``, ``#HSC``, ``#SPLINE``: KEY -> value expression."""
