"""The NC language's syntax: logical blocks, comments, expressions and statements (N-01..N-08).

A program is read one *logical block* at a time (:func:`read_block`): a line, with its comments removed,
joined with the lines that continue it (a ``\\`` at the end of a line; a ``#CONTROL AREA ... [`` wrapped
over several lines; ``#VAR ... #ENDVAR``; ``#COMMENT BEGIN ... #COMMENT END``). :class:`Compiler` turns
a logical block into one :class:`Stmt`, once; the interpreter runs it as often as the program's flow
comes by (a loop body is compiled once).

Comments (programming manual, "Comments"): ``( ... )`` anywhere, nested, and an unclosed ``(`` runs to
the end of the line; ``;`` to the end of the line; neither inside a string ``"..."``.

Blocks of constant words only (``N10 G01 X10 Y20 F1000``, nearly every line of a CAM program) take the
word parser of :mod:`hli_server.engine.nc.parser` - the batch geometry check's parser, with its error
messages - and become a ready :class:`~hli_server.engine.nc.blocks.Block` at compile time. Everything
else - expressions, variables, assignments, control statements, calls, ``#`` commands - is read here,
character by character, with the same word rules (``X2=100`` for an axis whose name has digits).

A statement that cannot be compiled is a :class:`Refused` statement carrying its alarm: the alarm is
raised when the program's flow reaches the block, not when the block is skipped (a false ``$IF``
branch may hold a construct the simulator does not model).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Collection
from typing import Final, NoReturn

from hli_server.engine.nc import parser as word_parser
from hli_server.engine.nc.blocks import Block, NcError
from hli_server.engine.nc.expr import (
    ALARM_EXPRESSION,
    FUNCTION_ARITY,
    KIND_AT_P,
    KIND_CYC,
    KIND_MH,
    KIND_P,
    KIND_PP,
    KIND_VA,
    KIND_VE,
    KIND_VG,
    KIND_VL,
    KIND_VP,
    KIND_VS,
    OP_ADD,
    OP_AND,
    OP_BAND,
    OP_BOR,
    OP_BXOR,
    OP_DIV,
    OP_EQ,
    OP_GE,
    OP_GT,
    OP_LE,
    OP_LT,
    OP_MOD,
    OP_MUL,
    OP_NE,
    OP_OR,
    OP_POW,
    OP_SUB,
    OP_XOR,
    BinOp,
    Const,
    ConstantEnv,
    EvalError,
    Exist,
    Expr,
    Func,
    Ref,
    Unary,
)
from hli_server.engine.nc.source import MAX_LINE_CHARS, LineTooLongError, ProgramText

__all__ = [
    "Assign",
    "Call",
    "Compiler",
    "ConstBlock",
    "Control",
    "Declaration",
    "Goto",
    "Hash",
    "Header",
    "RawBlock",
    "Refused",
    "Stmt",
    "Word",
    "Words",
    "build_block",
    "parse_expression",
    "read_block",
    "strip_comments",
]

# --- alarm numbers (hli_server/engine/alarms.py) -----------------------------------------------------
A_UNKNOWN_WORD: Final = 910100
A_BAD_NUMBER: Final = 910101
A_UNKNOWN_G: Final = 910102
A_TWICE: Final = 910103
A_UNKNOWN_HASH: Final = 910109
A_NOT_SIMULATED: Final = 910110
A_UNKNOWN_AXIS: Final = 910107
A_BAD_N: Final = 910108
A_RANGE: Final = 910111
A_LIMIT: Final = 914020
"""A bounded input over its bound: a line, an expression, a string."""
A_DECLARATION: Final = 914008
A_CONTROL_SYNTAX: Final = 914015
A_COMMENT_OPEN: Final = 914016
# the kernel's IDs (TF5200 diagnosis pages, docs/nc-language.md)
A_IF_EXTRA: Final = 20212
A_ELSE_EXTRA: Final = 20215
A_ELSEIF_EXTRA: Final = 20217
A_ENDIF_EXTRA: Final = 20219
A_DEFAULT_EXTRA: Final = 20224
A_WHILE_EXTRA: Final = 20235
A_ENDWHILE_EXTRA: Final = 20238
A_DO_EXTRA: Final = 20239
A_ENDDO_EXTRA: Final = 20241
A_COND_FIRST: Final = 20593
A_GOTO_CHAR: Final = 20839
A_AFTER_CALL: Final = 21542

MAX_EXPRESSION_DEPTH: Final = 64
"""Brackets and operators nested deeper than this are alarm 914020 (a bounded recursion)."""
MAX_EXPRESSION_NODES: Final = 2000
"""Operands and operators in one block beyond this are alarm 914020."""
MAX_STRING: Final = 255
"""Characters of a string literal (the kernel's STRING type holds up to 126; messages up to 255)."""
MAX_NAME: Final = 83
"""Characters of a program name in ``L name`` (the manual: "max 83 characters")."""
MAX_VAR_LINES: Final = 10_000
"""Lines of one ``#VAR ... #ENDVAR`` block or one ``#COMMENT`` block before it counts as unclosed."""

# --- control keywords ---------------------------------------------------------------------------------
C_IF: Final = "IF"
C_ELSEIF: Final = "ELSEIF"
C_ELSE: Final = "ELSE"
C_ENDIF: Final = "ENDIF"
C_SWITCH: Final = "SWITCH"
C_CASE: Final = "CASE"
C_DEFAULT: Final = "DEFAULT"
C_ENDSWITCH: Final = "ENDSWITCH"
C_WHILE: Final = "WHILE"
C_ENDWHILE: Final = "ENDWHILE"
C_DO: Final = "DO"
C_ENDDO: Final = "ENDDO"
C_REPEAT: Final = "REPEAT"
C_UNTIL: Final = "UNTIL"
C_FOR: Final = "FOR"
C_ENDFOR: Final = "ENDFOR"
C_BREAK: Final = "BREAK"
C_CONTINUE: Final = "CONTINUE"
C_GOTO: Final = "GOTO"
# conditional interpretation #IF / #ELSE / #ENDIF
C_HASH_IF: Final = "#IF"
C_HASH_ELSE: Final = "#ELSE"
C_HASH_ENDIF: Final = "#ENDIF"

CONTROL_WORDS: Final = frozenset(
    (
        C_IF,
        C_ELSEIF,
        C_ELSE,
        C_ENDIF,
        C_SWITCH,
        C_CASE,
        C_DEFAULT,
        C_ENDSWITCH,
        C_WHILE,
        C_ENDWHILE,
        C_DO,
        C_ENDDO,
        C_REPEAT,
        C_UNTIL,
        C_FOR,
        C_ENDFOR,
        C_BREAK,
        C_CONTINUE,
        C_GOTO,
    )
)
_ALONE: Final[dict[str, int]] = {
    C_ELSE: A_ELSE_EXTRA,
    C_ENDIF: A_ENDIF_EXTRA,
    C_DEFAULT: A_DEFAULT_EXTRA,
    C_ENDWHILE: A_ENDWHILE_EXTRA,
    C_DO: A_DO_EXTRA,
    C_ENDSWITCH: A_CONTROL_SYNTAX,
    C_REPEAT: A_CONTROL_SYNTAX,
    C_ENDFOR: A_CONTROL_SYNTAX,
    C_BREAK: A_CONTROL_SYNTAX,
    C_CONTINUE: A_CONTROL_SYNTAX,
}
"""Control words that stand alone in their block, and the kernel's ID when something follows."""
_CONDITION_ONLY: Final[dict[str, int]] = {
    C_IF: A_IF_EXTRA,
    C_ELSEIF: A_ELSEIF_EXTRA,
    C_WHILE: A_WHILE_EXTRA,
    C_ENDDO: A_ENDDO_EXTRA,
    C_UNTIL: A_CONTROL_SYNTAX,
    C_CASE: A_CONTROL_SYNTAX,
    C_SWITCH: A_CONTROL_SYNTAX,
}
"""Control words followed by their condition (or value) only."""

# --- the # commands -----------------------------------------------------------------------------------
KERNEL_HASH_COMMANDS: Final = frozenset(
    (
        "ACS",
        "ADD",
        "AKIMA",
        "ANG",
        "AX",
        "BACKWARD",
        "BCS",
        "BLOCKSEARCH",
        "CACHE",
        "CALL",
        "CAX",
        "CAXTRACK",
        "CHANNEL",
        "CHF",
        "CHR",
        "CLEAR",
        "COMMAND",
        "CONTOUR",
        "CORNER",
        "CS",
        "CYL",
        "DELETE",
        "DEL",
        "DIST",
        "DISTANCE",
        "DISABLE",
        "DRIVE",
        "DYNAMIC",
        "ECS",
        "EDGE",
        "EDM",
        "ENABLE",
        "ERROR",
        "EXPL",
        "EXPORT",
        "EXTCOMP",
        "FACE",
        "FF",
        "FGROUP",
        "FILTER",
        "FREE",
        "FRC",
        "GANTRY",
        "GEAR",
        "GET",
        "HANDWHEEL",
        "HSC",
        "IDENT",
        "INIT",
        "JOG",
        "KIN",
        "LAH",
        "LOAD",
        "LOCK",
        "UNLOCK",
        "LIMIT",
        "MACHINE",
        "MAIN",
        "MANUAL",
        "MCS",
        "MEAS",
        "NIBBLE",
        "OPTIONAL",
        "ORI",
        "OTC",
        "OVERRIDE",
        "PSET",
        "PRESET",
        "PTP",
        "PUNCH",
        "PUT",
        "RETAIN",
        "RND",
        "ROTATION",
        "RT",
        "SAVE",
        "SCALE",
        "SEGMENTATION",
        "SET",
        "SIGNAL",
        "SINGLE",
        "SLOPE",
        "SPLINE",
        "STOP",
        "STROKE",
        "SUPPRESS",
        "SYNC",
        "TANGFEED",
        "TIME",
        "TIMER",
        "TLAX",
        "TLC",
        "TOOL",
        "TRACK",
        "TRAFO",
        "TRANSFORM",
        "TRANSVELMIN",
        "TRC",
        "TURN",
        "VECTOR",
        "VIB",
        "VOLCOMP",
        "WAIT",
        "WCS",
    )
)
"""``#`` commands of the kernel (the programming manual's command overview, as ISG's editor lists them);
any of them that the simulator does not model is refused by name with alarm 910110, any other ``#``
word with 910109."""
SLOPE_TYPES: Final = ("STEP", "TRAPEZ", "SIN2", "HSC")
"""``#SLOPE [TYPE=<ident>]``'s profiles (P-CHAN-00071's 0..3)."""
MOTION_FUNCTIONS: Final[dict[str, str]] = {
    "TRC": "tool radius compensation options (#TRC)",
}
"""Motion functions not simulated (N-08): refused by name with 910110 (docs/nc-language.md)."""
MOTION_G_CODES: Final[dict[int, str]] = {
    5: "tangential TRC selection/deselection",
    138: "direct TRC selection/deselection",
    141: "TRC contour masking",
    236: "direct TRC selection/deselection on the path",
    237: "perpendicular TRC selection/deselection",
    238: "TRC selection at an inside corner",
    239: "TRC selection/deselection without a block",
}
"""G codes of motion functions not simulated (N-08), refused by name with 910110."""
VALUE_G_CODES: Final = frozenset((131, 231, 133, 134, 233, 334, 339))
"""G functions programmed with a value, ``G131=50`` (acceleration and ramp-time weightings)."""
AXIS_VALUE_G_CODES: Final = frozenset((130, 230, 132, 333, 338))
"""G functions whose axis words are weightings, ``G130 X70`` (not motion)."""
EXTRA_G_CODES: Final = VALUE_G_CODES | AXIS_VALUE_G_CODES
"""The weighting G codes the interpreter accepts beyond the word parser's (docs/nc-language.md)."""
_DWELL: Final = re.compile(r"G0*4(?![0-9.])", re.IGNORECASE)
"""A G04 block: its time may follow G04 directly (``G04 2.5``), which the word parser does not read."""
UNIT_G_CODES: Final = frozenset((8, 9, 70, 71, 94, 95, 900, 901))
"""Units and words (M-06..M-09): G70/G71 inch/metric, G94/G95 feed per minute /
per revolution, G08/G09/G900/G901 acceleration at block start / deceleration at block end."""
CONTOUR_G_CODES: Final = frozenset((61, 64, 150, 151, 260, 261))
"""Polynomial contouring G61/G261/G260 (G64 as G261), spline interpolation G151/G150 (simulated as
contouring): M-20..M-23, docs/nc-language.md "Contouring"."""
INITIAL_STATE_G_CODES: Final = frozenset((139, 140))
"""G139 (indirect TRC selection/deselection, PM 207729163) and G140 (no contour masking, PM 206480651):
the kernel's initial states, the ones simulated; programmed, they change nothing."""
KNOWN_G: Final = (
    word_parser.KNOWN_G_CODES | EXTRA_G_CODES | UNIT_G_CODES | CONTOUR_G_CODES | INITIAL_STATE_G_CODES
)
REFUSED_HASH: Final[dict[str, str]] = {
    "KIN": "kinematic transformations (#KIN)",
    "TRAFO": "kinematic transformations (#TRAFO)",
}
"""Refused with their own message (M-26): docs/nc-language.md says what simulating them
would take."""

_CONSTANT: Final = ConstantEnv()
_UPPER: Final = str.maketrans("abcdefghijklmnopqrstuvwxyz", "ABCDEFGHIJKLMNOPQRSTUVWXYZ")
"""ASCII letters to upper case, every other character kept: indices stay aligned with the text."""
_NAME_CHARS: Final = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_")
_DIGITS: Final = frozenset("0123456789")
_LETTERS: Final = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZ")
_PROG_DELIMITERS: Final = frozenset(' \t();"[],#$')
_SKIP_HEAD: Final = re.compile(r"\s*/\s*([0-9]{0,2})")
_N_LABEL: Final = re.compile(r"\s*N\s*([0-9]{1,9})\s*:", re.ASCII | re.IGNORECASE)
_STRING_LABEL: Final = re.compile(
    r"\s*(?:N\s*([0-9]{1,9})\s*)?\[([^\]\[\"]*)\]\s*:?", re.ASCII | re.IGNORECASE
)
_CONTROL_HEAD: Final = re.compile(r"\s*(?:N\s*[0-9]{1,9}\s*)?#\s*CONTROL\b", re.ASCII | re.IGNORECASE)
_COMMENT_BEGIN: Final = re.compile(r"\s*(?:N\s*[0-9]+\s*)?#\s*COMMENT\s+BEGIN\b", re.ASCII | re.IGNORECASE)
_COMMENT_END: Final = re.compile(r"\s*(?:N\s*[0-9]+\s*)?#\s*COMMENT\s+END\b", re.ASCII | re.IGNORECASE)
_VAR_BEGIN: Final = re.compile(r"\s*(?:N\s*[0-9]+\s*)?#\s*VAR\s*$", re.ASCII | re.IGNORECASE)
_VAR_END: Final = re.compile(r"\s*(?:N\s*[0-9]+\s*)?#\s*ENDVAR\s*$", re.ASCII | re.IGNORECASE)
_NEW_BLOCK: Final = re.compile(r"\s*(?:[/:#]|N\s*[0-9])", re.ASCII | re.IGNORECASE)
_N_HEAD: Final = re.compile(r"\s*N\s*([0-9]{1,9})(?![0-9.,=+\-])", re.ASCII | re.IGNORECASE)


# --- comments and logical blocks -----------------------------------------------------------------------
def strip_comments(raw: str) -> str:
    """``raw`` without its comments (each replaced by a blank); strings ``"..."`` are kept as written.

    ``( ... )`` nests; an unclosed ``(`` and a ``;`` run to the end of the line."""
    if "(" not in raw and ";" not in raw:
        return raw
    out: list[str] = []
    i = 0
    n = len(raw)
    start = 0
    while i < n:
        c = raw[i]
        if c == '"':
            close = raw.find('"', i + 1)
            i = n if close < 0 else close + 1
            continue
        if c == ";":
            out.append(raw[start:i])
            return " ".join(out)
        if c == "(":
            out.append(raw[start:i])
            depth = 1
            i += 1
            while i < n and depth:
                d = raw[i]
                if d == "(":
                    depth += 1
                elif d == ")":
                    depth -= 1
                i += 1
            start = i
            continue
        i += 1
    out.append(raw[start:])
    return " ".join(out)


class RawBlock:
    """One logical block: its lines ``first .. last``, its comment-free ``code`` and its ``text`` (the
    lines as written, joined by blanks). ``var_lines`` holds the declarations of a ``#VAR`` block."""

    __slots__ = ("code", "first", "last", "text", "var_lines")

    def __init__(
        self, first: int, last: int, code: str, text: str, var_lines: list[tuple[int, str]] | None
    ) -> None:
        self.first = first
        self.last = last
        self.code = code
        self.text = text
        self.var_lines = var_lines


def _nc_error(alarm: int, line: int, number: int | None, message: str) -> NcError:
    return NcError(alarm, line, f"N{number}" if number is not None else f"line {line}", message)


def _leading_number(code: str) -> int | None:
    head = _N_HEAD.match(code)
    return int(head.group(1)) if head is not None else None


def _line(source: ProgramText, number: int) -> str | None:
    try:
        return source.line(number)
    except LineTooLongError as exc:
        raise _nc_error(
            A_LIMIT,
            number,
            None,
            f"line {number} has {exc.length} characters or more: a line has at most {MAX_LINE_CHARS}",
        ) from None


def read_block(source: ProgramText, first: int) -> RawBlock | None:
    """The logical block starting at line ``first`` (None past the end of the text).

    Raises :class:`NcError` for a block that cannot be delimited: a ``\\`` continuation, a wrapped
    ``#CONTROL AREA`` or a ``#VAR`` / ``#COMMENT`` block that runs off the end of the text."""
    raw = _line(source, first)
    if raw is None:
        return None
    code = strip_comments(raw)
    stripped = code.strip()
    if not stripped:
        return RawBlock(first, first, "", raw.strip(), None)
    last = first
    texts = [raw.strip()]
    if stripped.endswith("\\"):
        codes = [stripped[:-1]]
        while True:
            nxt = _line(source, last + 1)
            if nxt is None:
                raise _nc_error(
                    A_CONTROL_SYNTAX,
                    first,
                    _leading_number(code),
                    "'\\' at the end of the last line: the block continues on no line",
                )
            last += 1
            texts.append(nxt.strip())
            piece = strip_comments(nxt).strip()
            if not piece.endswith("\\"):
                codes.append(piece)
                break
            codes.append(piece[:-1])
        code = " ".join(codes)
        return RawBlock(first, last, code, " ".join(texts), None)
    if "#" in stripped:
        if _COMMENT_BEGIN.match(stripped):
            return _comment_block(source, first, raw)
        if _VAR_BEGIN.match(stripped):
            return _var_block(source, first, raw, code)
        if "[" in stripped and stripped.count("[") > stripped.count("]") and _CONTROL_HEAD.match(stripped):
            return _wrapped_control(source, first, raw, code)
    return RawBlock(first, first, code, texts[0], None)


def _comment_block(source: ProgramText, first: int, raw: str) -> RawBlock:
    """``#COMMENT BEGIN`` .. ``#COMMENT END`` (manual "Cross-block comments", 207049867): no code."""
    number = first
    while True:
        number += 1
        nxt = _line(source, number)
        if nxt is None or number - first > MAX_VAR_LINES:
            raise _nc_error(
                A_COMMENT_OPEN, first, _leading_number(raw), "#COMMENT BEGIN without #COMMENT END"
            )
        if _COMMENT_END.match(strip_comments(nxt)):
            return RawBlock(first, number, "", raw.strip(), None)


def _var_block(source: ProgramText, first: int, raw: str, code: str) -> RawBlock:
    """``#VAR`` .. ``#ENDVAR``: the declarations with their line numbers (``\\`` continues one)."""
    lines: list[tuple[int, str]] = []
    number = first
    pending: tuple[int, str] | None = None
    while True:
        number += 1
        nxt = _line(source, number)
        if nxt is None or number - first > MAX_VAR_LINES:
            raise _nc_error(A_DECLARATION, first, _leading_number(code), "#VAR without #ENDVAR")
        piece = strip_comments(nxt).strip()
        if pending is not None:
            joined = pending[1] + " " + piece
            if piece.endswith("\\"):
                pending = (pending[0], joined[:-1])
                continue
            lines.append((pending[0], joined))
            pending = None
            continue
        if _VAR_END.match(piece):
            return RawBlock(first, number, code, raw.strip(), lines)
        if not piece:
            continue
        if piece.endswith("\\"):
            pending = (number, piece[:-1])
            continue
        lines.append((number, piece))


def _wrapped_control(source: ProgramText, first: int, raw: str, code: str) -> RawBlock:
    """A ``#CONTROL AREA ... [`` whose ``]`` is on a later line (FCT-C14 section 2.4 wraps it)."""
    texts = [raw.strip()]
    codes = [code.strip()]
    number = first
    while "]" not in codes[-1]:
        nxt = _line(source, number + 1)
        if nxt is None:
            raise _nc_error(
                word_parser._BAD_AREA,
                first,
                _leading_number(code),
                "'[' not closed: no ']' before the end of the program; close the option list with ']'",
            )
        piece_code = strip_comments(nxt).strip()
        if not piece_code:
            number += 1
            continue
        if _NEW_BLOCK.match(piece_code) or "[" in piece_code:
            raise _nc_error(
                word_parser._BAD_AREA,
                first,
                _leading_number(code),
                f"'[' not closed: no ']' before line {number + 1} ({word_parser._short(nxt.strip())!r}); "
                "close the option list with ']'",
            )
        number += 1
        texts.append(nxt.strip())
        codes.append(piece_code)
    return RawBlock(first, number, " ".join(codes), " ".join(texts), None)


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
        self.keyword = _control_keyword(raw.code)


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


class Call(Item):
    """``L name`` (global), ``LL name`` (local), ``L CYCLE [NAME=.. @P1=..]`` (``cycle``): the last
    item of its block. ``params`` are the cycle's ``@P`` numbers and values."""

    def __init__(
        self, text: str, local: bool, name: str, cycle: bool, params: list[tuple[int, Expr]]
    ) -> None:
        super().__init__(text)
        self.local = local
        self.name = name
        self.cycle = cycle
        self.params = params


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
        for item in items:
            if isinstance(item, Call):
                self.call = item
            elif isinstance(item, Goto):
                self.goto = item


class Control(Stmt):
    """A control statement: ``keyword`` (``IF``, ``ENDWHILE``, ... or ``#IF`` for conditional
    interpretation) with its expressions: the condition, the ``$SWITCH`` value, the ``$CASE`` values,
    ``$FOR``'s start, end and step. ``target`` is ``$FOR``'s counter; ``goto`` the jump of
    ``$IF cond $GOTO ..``."""

    def __init__(
        self,
        raw: RawBlock,
        number: int | None,
        keyword: str,
        exprs: list[Expr],
        target: Ref | None = None,
        goto: Goto | None = None,
    ) -> None:
        super().__init__(raw, number)
        self.keyword = keyword
        self.exprs = exprs
        self.target = target
        self.goto = goto


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


# --- the compiler --------------------------------------------------------------------------------------
class _CompileError(Exception):
    """A compile error inside the scanner (turned into an NcError with the block's place)."""

    def __init__(self, alarm: int, message: str) -> None:
        super().__init__(message)
        self.alarm = alarm
        self.message = message


class Compiler:
    """Compiles logical blocks for one channel's axes (``axis_names``; ``main_axes`` for ``@X@Y@Z``)."""

    def __init__(self, axis_names: Collection[str], main_axes: tuple[str, str, str]) -> None:
        names = [n.strip().upper() for n in axis_names]
        self.axis_names = frozenset(names)
        self.main_axes = main_axes
        self._axis_list = ", ".join(sorted(names)) or "none"
        self._words = word_parser._LineParser(names)
        self._fast = self._words._words
        single = sorted(n for n in names if len(n) == 1 and n not in "GMFNIJKSTDHPLEROQ")
        letters = "NGMFIJKSTDH" + "".join(single)
        lower = letters.lower()
        self._plain: Callable[[str], re.Match[str] | None] = re.compile(
            rf"[0-9.+\-\s{letters}{lower}]*", re.ASCII
        ).fullmatch
        self._single_axes = frozenset(single)
        self.single_letter_axes = self._single_axes
        """Axes with a one-letter name written ``X10`` (the batch geometry check's plain lines use the
        same letters)."""

    def plain_block(self, raw: str, line: int, program: str) -> Block | None:
        """The block of a line of constant words (``N10 G01 X10 F1000``, no comment), or None for any
        other line or a line the word parser refuses (the compiler then explains it)."""
        if self._plain(raw) is None or not raw or raw.isspace():
            return None
        try:
            block = self._fast(raw.strip(), raw.translate(_UPPER), 0, _TO_END, line, None, True)
        except NcError:
            return None
        return _with_program(block, program) if program else block

    # --- entry --------------------------------------------------------------------------------------
    def compile(self, raw: RawBlock, program: str = "") -> Stmt:
        """The statement of ``raw``; ``program`` names the subroutine it belongs to ("" for the main
        program): its blocks carry the name for alarms."""
        code = raw.code
        if not code.strip():
            return Empty(raw, None)
        if raw.var_lines is None and self._plain(code) is not None:
            # the fast path of nearly every CAM line: constant words only (the word parser's own)
            try:
                block = self._fast(raw.text, code.translate(_UPPER), 0, _TO_END, raw.first, None, True)
            except NcError as exc:
                if exc.alarm != A_UNKNOWN_G and not _DWELL.search(code):
                    return Refused(raw, _leading_number(code), exc)
            else:
                if program:
                    return ConstBlock(raw, _with_program(block, program))
                return ConstBlock(raw, block)
        stripped = code.lstrip()
        if stripped.startswith("%"):
            rest = stripped[1:]
            local = rest[:1] in ("L", "l") and rest[1:2] in (" ", "\t")
            name = (rest[2:] if local else rest).strip()
            return Header(raw, local, name.split()[0].upper() if name else "")
        number = _leading_number(code)
        try:
            if raw.var_lines is not None:
                return self._var_block(raw, number)
            stmt = self._compile(raw, code)
            if program and isinstance(stmt, ConstBlock):
                stmt.block = _with_program(stmt.block, program)
            return stmt
        except NcError as exc:
            return Refused(raw, number, exc)
        except _CompileError as exc:
            return Refused(raw, number, _nc_error(exc.alarm, raw.first, number, exc.message))
        except RecursionError:
            return Refused(raw, number, _nc_error(A_LIMIT, raw.first, number, "expression nested too deeply"))

    def _compile(self, raw: RawBlock, code: str) -> Stmt:
        skip_level = -1
        head = _SKIP_HEAD.match(code) if "/" in code else None
        if head is not None:
            skip_level = int(head.group(1)) if head.group(1) else 0
            code = code[head.end() :]
        label: str | None = None
        n_label = _N_LABEL.match(code) if ":" in code else None
        if n_label is not None:
            label = f"N{int(n_label.group(1))}"
        elif "[" in code:
            s_label = _STRING_LABEL.match(code)
            if s_label is not None and "=" not in code[s_label.start(2) : s_label.end(2)]:
                after = code[s_label.end() :]
                if not after.strip() or after[:1].isspace() or s_label.group(0).rstrip().endswith(":"):
                    label = "[" + s_label.group(2).strip().upper() + "]"
                    prefix = f"N{s_label.group(1)} " if s_label.group(1) else ""
                    code = prefix + after
        stmt = self._statement(raw, code)
        stmt.label = label
        stmt.skip_level = skip_level
        return stmt

    def _statement(self, raw: RawBlock, code: str) -> Stmt:
        if self._plain(code) is not None or _CONTROL_HEAD.match(code) or _two_path(code):
            try:
                block = self._words.parse_code(raw.text, code, raw.first)
            except NcError as exc:
                # a G code the word parser does not know may be one the interpreter takes (G130, G131
                # ...) or refuses by name (MOTION_G_CODES): its own parser decides
                if (exc.alarm != A_UNKNOWN_G and not _DWELL.search(code)) or _CONTROL_HEAD.match(code):
                    raise
                return self._parsed(raw, code)
            if block is None:
                return Empty(raw, _leading_number(code))
            return ConstBlock(raw, block)
        return self._parsed(raw, code)

    def _parsed(self, raw: RawBlock, code: str) -> Stmt:
        stmt = _BlockParser(self, raw, code).parse()
        if (
            isinstance(stmt, Words)
            and stmt.items
            and all(
                isinstance(i, Word) and i.value.is_constant() and (i.extra is None or i.extra.is_constant())
                for i in stmt.items
            )
        ):
            words: list[tuple[Word, float, float | None]] = []
            for item in stmt.items:
                assert isinstance(item, Word)
                try:
                    value = item.value.evaluate(_CONSTANT)
                    extra = item.extra.evaluate(_CONSTANT) if item.extra is not None else None
                except EvalError:
                    return stmt  # X[1/0]: the interpreter raises it when the block runs, with its place
                if isinstance(value, str) or isinstance(extra, str):
                    return stmt  # the error is the interpreter's, with its message
                words.append((item, value, extra))
            return ConstBlock(raw, build_block(raw.text, raw.first, stmt.number, words, ""))
        return stmt

    # --- #VAR ------------------------------------------------------------------------------------------
    def _var_block(self, raw: RawBlock, number: int | None) -> Stmt:
        declarations: list[Declaration] = []
        assert raw.var_lines is not None
        for line, text in raw.var_lines:
            sub = RawBlock(line, line, text, text, None)
            try:
                declarations.append(_BlockParser(self, sub, text).declaration())
            except _CompileError as exc:
                raise _nc_error(exc.alarm, line, _leading_number(text), exc.message) from None
        return VarBlock(raw, number, declarations)


_CONTROL_WORD: Final = re.compile(r"\s*(?:/[0-9]*\s*)?(?:N\s*[0-9]+\s*:?\s*)?\$([A-Za-z]+)", re.ASCII)
_HASH_CONDITION: Final = re.compile(r"\s*#\s*(IF|ELSE|ENDIF)\b", re.ASCII | re.IGNORECASE)


def _control_keyword(code: str) -> str:
    """The control word a block's code begins with (``IF``, ``#ELSE``), or ""."""
    found = _CONTROL_WORD.match(code)
    if found is not None:
        word = found.group(1).upper()
        return word if word in CONTROL_WORDS and word != C_GOTO else ""
    found = _HASH_CONDITION.match(code)
    return "#" + found.group(1).upper() if found is not None else ""


_TO_END: Final = 1 << 62


def _with_program(block: Block, program: str) -> Block:
    """``block`` as a block of subroutine ``program``."""
    return Block(
        block.line,
        block.number,
        block.text,
        block.g_codes,
        block.m_codes,
        block.axes,
        block.centre,
        block.feed,
        block.area,
        block.two_path,
        block.extra,
        program,
    )


def _two_path(code: str) -> bool:
    """A two-path line (``N50 : G0 X.. : G0 U..``, FCT-C14 2.4) or a lone ``:`` (the word parser's)."""
    if ":" not in code or '"' in code or "[" in code or "=" in code:
        return False
    if _CALL_WORD.search(code) is not None:  # L D:\prog\x.nc: a call whose name holds a ':'
        return False
    return _N_LABEL.match(code) is None or code.count(":") > 1


_M_RETURN_BEFORE = re.compile(r"(?:^|[\s])M0*(?:17|29)[ \t]*$")
"""``M17 [MAIN ..]``: the M17/M29 right before a ``[`` (the parameterised jump)."""
_CALL_WORD = re.compile(r"(?:^|[\s:])LL?[ \t]", re.IGNORECASE)


class _BlockParser:
    """Reads one block's code, character by character (the case-folded copy ``u`` keeps the indices of
    the code, so strings keep their case)."""

    def __init__(self, compiler: Compiler, raw: RawBlock, code: str) -> None:
        self.c = compiler
        self.raw = raw
        self.code = code
        self.u = code.translate(_UPPER)
        self.pos = 0
        self.n = len(code)
        self.depth = 0
        self.nodes = 0
        self.number: int | None = None

    # --- low level -------------------------------------------------------------------------------------
    def fail(self, alarm: int, message: str) -> NoReturn:
        raise _CompileError(alarm, message)

    def failure(self, alarm: int, message: str) -> _CompileError:
        """The error to raise (for a function whose last statement raises it)."""
        return _CompileError(alarm, message)

    def blanks(self) -> None:
        u = self.u
        n = self.n
        pos = self.pos
        while pos < n and (u[pos] == " " or u[pos] == "\t"):
            pos += 1
        self.pos = pos

    def at_end(self) -> bool:
        self.blanks()
        return self.pos >= self.n

    def peek(self, k: int = 0) -> str:
        p = self.pos + k
        return self.u[p] if p < self.n else ""

    def word_at(self, start: int) -> str:
        stop = start
        u = self.u
        while stop < self.n and not u[stop].isspace():
            stop += 1
        return word_parser._short(u[start:stop] or u[start : start + 1])

    def name(self) -> str:
        """An identifier: letters, digits, ``_`` (upper case)."""
        start = self.pos
        u = self.u
        while self.pos < self.n and u[self.pos] in _NAME_CHARS:
            self.pos += 1
        return u[start : self.pos]

    def keyword(self, word: str) -> bool:
        """Is ``word`` next (and not the start of a longer name)? Consumes it if so."""
        self.blanks()
        end = self.pos + len(word)
        if self.u.startswith(word, self.pos) and (end >= self.n or self.u[end] not in _NAME_CHARS):
            self.pos = end
            return True
        return False

    def expect(self, char: str, what: str) -> None:
        self.blanks()
        if self.peek() != char:
            got = f"{self.word_at(self.pos)!r}" if self.pos < self.n else "the end of the block"
            self.fail(ALARM_EXPRESSION, f"expected {char!r} {what}, got {got}")
        self.pos += 1

    def number_literal(self) -> float | None:
        """A number as the word parser reads it (``12``, ``12.5``, ``.5``, ``12.``); None if none here."""
        u = self.u
        start = self.pos
        p = start
        while p < self.n and u[p] in _DIGITS:
            p += 1
        if p < self.n and u[p] == ".":
            p += 1
            while p < self.n and u[p] in _DIGITS:
                p += 1
        text = u[start:p]
        if not text or text == ".":
            return None
        if p < self.n and u[p] == ".":
            self.fail(A_BAD_NUMBER, f"malformed number in {self.word_at(start)!r}")
        self.pos = p
        value = float(text)
        if value > 1e300:
            self.fail(A_RANGE, f"{word_parser._shown_number('', text)} is out of range: too large a number")
        return value

    # --- the block -------------------------------------------------------------------------------------
    def parse(self) -> Stmt:
        head = _N_HEAD.match(self.u)
        if head is not None:
            self.number = int(head.group(1))
            self.pos = head.end()
            self.blanks()
            if self.peek() == ":":
                self.pos += 1
        self.blanks()
        if self.pos >= self.n:
            return Empty(self.raw, self.number)
        c = self.u[self.pos]
        if c == "$":
            return self.control()
        if c == "#":
            return self.hash_command()
        items = self.items()
        return Words(self.raw, self.number, items)

    def items(self) -> list[Item]:
        items: list[Item] = []
        seen_call: Call | None = None
        while not self.at_end():
            start = self.pos
            if seen_call is not None:
                self.fail(
                    A_AFTER_CALL,
                    f"{self.word_at(start)!r} after the call {seen_call.text!r}: nothing may follow a "
                    "subroutine or cycle call in its block; program it before the call",
                )
            item = self.item()
            if isinstance(item, Call):
                seen_call = item
            items.append(item)
            if (
                isinstance(item, Word)
                and item.letter == "G"
                and isinstance(item.value, Const)
                and item.value.value == 4.0
            ):
                dwell = self.dwell_time()
                if dwell is not None:
                    items.append(dwell)
            if isinstance(item, Goto) and not self.at_end():
                self.fail(
                    A_GOTO_CHAR,
                    f"{self.word_at(self.pos)!r} after {item.text!r}: the jump is the last action "
                    "of its block",
                )
        return items

    def dwell_time(self) -> Word | None:
        """``G04 2.5``, ``G04 P1``, ``G04 V.L.TIME`` (PM 206132747): the time written directly after G04,
        read as the first main axis' word (``G04 X2.5``), as the kernel treats both (M-09)."""
        self.blanks()
        if self.at_end():
            return None
        c, d = self.peek(), self.peek(1)
        if c in "0123456789." or (c == "P" and (d in _DIGITS or d in "P[")) or (c == "V" and d == "."):
            start = self.pos
            expr = self.expression(stop_at_blank=True)
            return Word(self.u[start : self.pos], "AXIS", self.c.main_axes[0], expr)
        return None

    def item(self) -> Item:
        u = self.u
        start = self.pos
        c = u[start]
        if c == "$":
            if self.keyword("$GOTO"):
                return self.goto(start)
            word = self.word_at(start)
            self.fail(
                A_CONTROL_SYNTAX,
                f"{word} must stand at the start of its block (only $GOTO may follow other commands)",
            )
        if c == "#":
            self.fail(
                A_UNKNOWN_WORD, f"unexpected {self.word_at(start)!r}: a # command stands alone in its block"
            )
        if c == '"':
            self.fail(
                A_NOT_SIMULATED,
                f"macros ({self.word_at(start)}) are not simulated: see docs/nc-language.md",
            )
        if c == "@":
            return self.at_word(start)
        if (c == "[" or u.startswith(("MAIN", "JUMPS", "N"), start)) and _M_RETURN_BEFORE.search(
            u, 0, start
        ) is not None:
            self.fail(
                A_NOT_SIMULATED,
                f"the parameterised jump of M17/M29 ({u[start:].strip()}: PM 206781707) is not "
                "simulated: see docs/nc-language.md",
            )
        if c == "[":
            self.fail(
                A_UNKNOWN_WORD,
                f"unexpected {self.word_at(start)!r}: a label [name] stands at the block's start",
            )
        if c == ")":
            self.fail(A_UNKNOWN_WORD, "')' without '(': comments are written ( ... )")
        if c not in _LETTERS:
            self.fail(A_UNKNOWN_WORD, f"unexpected {self.word_at(start)!r}")
        if c == "V" and self.peek(1) == "." and self.peek(2) in _LETTERS:
            ref = self.variable()
            return self.assignment(start, ref)
        if c == "P" and (self.peek(1) in _DIGITS or self.peek(1) in ("P", "[")):
            ref = self.parameter()
            return self.assignment(start, ref)
        if c == "L" and (
            self.peek(1) in (" ", "\t", "") or (self.peek(1) == "L" and self.peek(2) in (" ", "\t", ""))
        ):
            return self.call(start)
        if c == "L" and self.peek(1) not in _LETTERS and self.peek(1) != "":
            return self.call(start)
        if c == "N":
            word = self.word_at(start)
            if self.number is not None:
                self.fail(A_BAD_N, f"second block number {word}: N stands once, at the start of the block")
            self.fail(A_BAD_N, f"block number {word} must stand at the start of the block")
        return self.address(start)

    # --- address words -----------------------------------------------------------------------------------
    def address(self, start: int) -> Word:
        u = self.u
        # a name with digits before "=": X2=100, M52=-345, G131=50
        p = start + 1
        while p < self.n and u[p] in _NAME_CHARS and u[p] not in "_":
            p += 1
        q = p
        while q < self.n and u[q] in (" ", "\t"):
            q += 1
        if p - start > 1 and q < self.n and u[q] == "=" and u[q + 1 : q + 2] != "=":
            full = u[start:p]
            self.pos = q + 1
            return self.named_word(start, full)
        letter = u[start]
        self.pos = start + 1
        if letter == "=" or (self.peek() == "=" and self.peek(1) != "="):
            self.pos += 1
        if letter in "GMH":
            return self.function_word(start, letter)
        if letter == "R" and "R" not in self.c._single_axes:
            # the circle's radius (G02/G03 X.. Y.. R.., M-08)
            return Word(self.word_at(start), "R", "R", self.word_value(start))
        if letter == "E":
            self.fail(
                A_NOT_SIMULATED,
                f"{self.word_at(start)}: the feed at block end (E) is not simulated: see docs/nc-language.md",
            )
        if letter in "FSTDIJK":
            return Word(self.word_at(start), letter, letter, self.word_value(start))
        if letter in self.c._single_axes:
            return Word(self.word_at(start), "AXIS", letter, self.word_value(start))
        word = self.word_at(start)
        if letter in "ABCUVWXYZ":
            self.fail(
                A_UNKNOWN_AXIS,
                f"unknown axis name {letter} in {word!r} (axes of this channel: {self.c._axis_list})",
            )
        raise self.failure(
            A_UNKNOWN_WORD,
            f"unknown word {word!r}: use N, G, M, H, F, S, T, D, I, J, K, P, V., L, $, # or an axis "
            f"({self.c._axis_list})",
        )

    def named_word(self, start: int, full: str) -> Word:
        """``X2=100`` (an axis whose name has digits), ``M52=-345``, ``H5=..``, ``G131=50``."""
        letter = full[0]
        if letter in "MH" and full[1:].isdigit():
            value = Const(float(int(full[1:])))
            return Word(self.word_at(start), letter, letter, value, self.word_value(start))
        if letter == "G" and full[1:].isdigit():
            g = int(full[1:])
            if g not in VALUE_G_CODES:
                self.fail(
                    A_UNKNOWN_G,
                    f"{full}=..: G{g} takes no value (G functions with a value: "
                    f"{', '.join(f'G{c}' for c in sorted(VALUE_G_CODES))})",
                )
            return Word(self.word_at(start), "G", "G", Const(float(g)), self.word_value(start))
        if full in self.c.axis_names:
            return Word(self.word_at(start), "AXIS", full, self.word_value(start))
        if letter == "N":
            self.fail(A_BAD_N, f"malformed block number {self.word_at(start)!r}: write N<digits>")
        if letter in "ABCUVWXYZ" or len(full) > 1:
            self.fail(
                A_UNKNOWN_AXIS,
                f"unknown axis name {full} in {self.word_at(start)!r} (axes of this channel: "
                f"{self.c._axis_list})",
            )
        raise self.failure(A_UNKNOWN_WORD, f"unknown word {self.word_at(start)!r}")

    def function_word(self, start: int, letter: str) -> Word:
        """G, M, H: a whole number (``G01``, ``M30``) or an expression (``MP10``), M/H with an optional
        additional value (``M52=-345``)."""
        self.blanks()
        if letter == "G":
            p = self.pos
            while p < self.n and self.u[p] in _DIGITS:
                p += 1
            digits = self.u[self.pos : p]
            if digits and (p >= self.n or self.u[p] not in "."):
                self.pos = p
                stripped = digits.lstrip("0") or "0"
                g = int(stripped) if len(stripped) <= 4 else -1
                return Word(self.word_at(start), "G", "G", Const(float(g)))
        value = self.word_value(start)
        extra: Expr | None = None
        if letter != "G" and self.peek() == "=" and self.peek(1) != "=":
            self.pos += 1
            extra = self.word_value(start)
        return Word(self.word_at(start), letter, letter, value, extra)

    def word_value(self, start: int) -> Expr:
        """The value of an address word: a number, or an expression (``XP1*SIN[P2*30]``), read up to the
        next blank outside brackets; blanks after the address are allowed (``X 100``)."""
        self.blanks()
        if self.pos >= self.n:
            word = self.word_at(start)
            self.fail(A_BAD_NUMBER, f"{word!r}: {word[0]} needs a number ({word[0]}100, {word[0]}-2.5)")
        c = self.u[self.pos]
        if c in "0123456789.":
            at = self.pos
            number = self.number_literal()
            if number is not None and (
                self.pos >= self.n
                or self.u[self.pos] in " \t"
                or self.u[self.pos] in _LETTERS
                or self.u[self.pos] in "#$@"
            ):
                return Const(number)
            self.pos = at
        return self.expression(stop_at_blank=True)

    def at_word(self, start: int) -> Item:
        """``@P1=..`` (a cycle parameter) and the cycle's axes ``@X @Y @Z`` / centre ``@I @J @K``."""
        if self.peek(1) == "P" and self.peek(2) in _DIGITS:
            ref = self.primary_ref()
            return self.assignment(start, ref)
        letter = self.peek(1)
        if letter in "XYZ":
            self.pos += 2
            axis = self.c.main_axes["XYZ".index(letter)]
            return Word(self.word_at(start), "AXIS", axis, self.word_value(start))
        if letter in "IJK":
            self.pos += 2
            return Word(self.word_at(start), letter, letter, self.word_value(start))
        if letter == "S":
            self.fail(
                A_NOT_SIMULATED, "@S (the main spindle in a cycle) is not simulated: see docs/nc-language.md"
            )
        raise self.failure(
            A_UNKNOWN_WORD, f"unexpected {self.word_at(start)!r}: @P.., @X, @Y, @Z, @I, @J, @K in cycles"
        )

    def assignment(self, start: int, ref: Ref) -> Assign:
        self.blanks()
        if self.peek() != "=" or self.peek(1) == "=":
            shown = ref.text
            if ref.kind in (KIND_P, KIND_PP):
                self.fail(
                    ALARM_EXPRESSION,
                    f"{shown} without a value: a parameter in a block is assigned ({shown} = 10); "
                    f"as an axis value write X{shown} or X[{shown}]",
                )
            self.fail(
                ALARM_EXPRESSION,
                f"{shown} without a value: a variable in a block is assigned ({shown} = 10); "
                f"as an axis value write X{shown}",
            )
        self.pos += 1
        value = self.expression(stop_at_blank=False)
        return Assign(self.u[start : self.pos].strip(), ref, value)

    # --- calls -------------------------------------------------------------------------------------------
    def call(self, start: int) -> Call:
        local = self.u.startswith("LL", start) and self.peek(2) in (" ", "\t", "")
        self.pos = start + (2 if local else 1)
        self.blanks()
        if self.keyword("CYCLE"):
            return self.cycle_call(start, local)
        u = self.u
        if self.peek() == '"':
            close = self.code.find('"', self.pos + 1)
            if close < 0:
                self.fail(A_UNKNOWN_WORD, f"{self.word_at(start)}: quote not closed")
            name = self.code[self.pos + 1 : close]
            self.pos = close + 1
        else:
            if u.startswith("V.E.", self.pos):
                self.fail(
                    A_NOT_SIMULATED,
                    f"{self.word_at(start)}: calls by the name in a V.E. string variable are not simulated "
                    "(V.E. variables here are numbers): see docs/nc-language.md",
                )
            begin = self.pos
            while self.pos < self.n and self.code[self.pos] not in _PROG_DELIMITERS:
                self.pos += 1
            name = self.code[begin : self.pos]
        if not name:
            self.fail(A_CONTROL_SYNTAX, f"{'LL' if local else 'L'} without a program name")
        if name.upper() == "SEQUENCE":
            self.fail(
                A_NOT_SIMULATED,
                "L SEQUENCE (calling block sequences) is not simulated: see docs/nc-language.md",
            )
        if len(name) > MAX_NAME:
            self.fail(
                A_LIMIT, f"program name {word_parser._short(name)!r} is longer than {MAX_NAME} characters"
            )
        return Call(u[start : self.pos].strip(), local, name, False, [])

    def cycle_call(self, start: int, local: bool) -> Call:
        """``L CYCLE [NAME=<cycle> @P1=<expr> ...]`` (manual "Cycles as global or local subroutines")."""
        self.expect("[", "after CYCLE")
        self.depth += 1
        name = ""
        params: list[tuple[int, Expr]] = []
        seen: set[int] = set()
        while True:
            self.blanks()
            if self.peek() == "]":
                self.pos += 1
                break
            if self.pos >= self.n:
                self.fail(A_CONTROL_SYNTAX, "L CYCLE [: ']' missing after the cycle's parameters")
            if self.keyword("NAME"):
                self.expect("=", "after NAME")
                self.blanks()
                begin = self.pos
                if self.peek() == '"':
                    close = self.code.find('"', begin + 1)
                    if close < 0:
                        self.fail(A_CONTROL_SYNTAX, 'L CYCLE: NAME=" quote not closed')
                    name = self.code[begin + 1 : close]
                    self.pos = close + 1
                else:
                    while self.pos < self.n and self.code[self.pos] not in _PROG_DELIMITERS:
                        self.pos += 1
                    name = self.code[begin : self.pos]
                continue
            for word in ("MODAL_MOVE", "MODAL_BLOCK", "MODAL"):
                if self.keyword(word):
                    self.fail(
                        A_NOT_SIMULATED,
                        f"L CYCLE [{word}]: modal cycle calls are not simulated: see docs/nc-language.md",
                    )
            if self.peek() == "@" and self.peek(1) == "P":
                self.pos += 2
                at = self.pos
                while self.pos < self.n and self.u[self.pos] in _DIGITS:
                    self.pos += 1
                if at == self.pos or self.pos - at > 9:
                    self.fail(A_CONTROL_SYNTAX, f"L CYCLE: malformed parameter {self.word_at(at - 2)!r}")
                index = int(self.u[at : self.pos])
                if index in seen:
                    self.fail(A_TWICE, f"L CYCLE: @P{index} given twice")
                seen.add(index)
                self.expect("=", f"after @P{index}")
                params.append((index, self.expression(stop_at_blank=False)))
                continue
            self.fail(A_CONTROL_SYNTAX, f"L CYCLE: unexpected {self.word_at(self.pos)!r} (NAME=.., @P1=..)")
        self.depth -= 1
        if not name:
            self.fail(A_CONTROL_SYNTAX, "L CYCLE [..]: NAME=<cycle> missing")
        if len(name) > MAX_NAME:
            self.fail(
                A_LIMIT, f"cycle name {word_parser._short(name)!r} is longer than {MAX_NAME} characters"
            )
        return Call(self.u[start : self.pos].strip(), local, name, True, params)

    def goto(self, start: int) -> Goto:
        """``$GOTO N<expr>`` or ``$GOTO [name]`` (manual "The $GOTO statement", 206915851)."""
        self.blanks()
        c = self.peek()
        if c == "[":
            close = self.u.find("]", self.pos)
            if close < 0:
                self.fail(A_GOTO_CHAR, "$GOTO [: ']' missing after the label's name")
            name = self.u[self.pos + 1 : close].strip()
            self.pos = close + 1
            return Goto(self.u[start : self.pos], "[" + name + "]", None)
        if c == "N":
            self.pos += 1
            number = self.word_value(start)
            return Goto(self.u[start : self.pos], None, number)
        got = repr(c) if c else "nothing"
        raise self.failure(A_GOTO_CHAR, f"$GOTO followed by {got}: write $GOTO N<number> or $GOTO [label]")

    # --- control statements --------------------------------------------------------------------------------
    def control(self) -> Stmt:
        start = self.pos
        self.pos += 1
        keyword = self.name()
        if keyword not in CONTROL_WORDS:
            self.fail(
                A_CONTROL_SYNTAX,
                f"unknown control statement ${word_parser._short(keyword)}; the kernel's are "
                + " ".join(f"${w}" for w in sorted(CONTROL_WORDS)),
            )
        raw = self.raw
        if keyword == C_GOTO:
            self.pos = start
            items = self.items()
            return Words(raw, self.number, items)
        if keyword in _ALONE:
            if not self.at_end():
                alarm = _ALONE[keyword]
                self.fail(
                    alarm,
                    f"{self.word_at(self.pos)!r} after ${keyword}: ${keyword} must be programmed alone in "
                    "its block; move the rest to the next block",
                )
            return Control(raw, self.number, keyword, [])
        if keyword == C_FOR:
            return self.for_loop()
        # a condition (or the $CASE values)
        if self.at_end():
            what = "value" if keyword == C_CASE else "condition"
            self.fail(A_CONTROL_SYNTAX, f"${keyword} without its {what}")
        exprs = [self.expression(stop_at_blank=False)]
        if keyword == C_CASE:
            while self.peek() == ",":
                self.pos += 1
                exprs.append(self.expression(stop_at_blank=False))
        goto: Goto | None = None
        if not self.at_end():
            if keyword == C_IF and self.u.startswith("$GOTO", self.pos):
                at = self.pos
                self.keyword("$GOTO")
                goto = self.goto(at)
                if not self.at_end():
                    self.fail(
                        A_GOTO_CHAR,
                        f"{self.word_at(self.pos)!r} after {goto.text!r}: the jump is the last action",
                    )
            else:
                alarm = _CONDITION_ONLY.get(keyword, A_CONTROL_SYNTAX)
                self.fail(
                    alarm,
                    f"{self.word_at(self.pos)!r} after ${keyword}'s "
                    f"{'value' if keyword == C_CASE else 'condition'}: "
                    f"only the {'value' if keyword == C_CASE else 'condition'} may follow ${keyword}; "
                    "move the rest to the next block",
                )
        return Control(raw, self.number, keyword, exprs, goto=goto)

    def for_loop(self) -> Stmt:
        """``$FOR P1 = <start>, <end>, <step>`` (manual "Counting loop", 206929163)."""
        self.blanks()
        start = self.pos
        c = self.peek()
        if c == "P":
            target = self.parameter()
        elif c == "V" and self.peek(1) == ".":
            target = self.variable()
        else:
            got = repr(self.word_at(start)) if start < self.n else "nothing"
            self.fail(A_CONTROL_SYNTAX, f"$FOR needs a counter (P1 or V.P.NAME), got {got}")
        self.expect("=", "after $FOR's counter")
        exprs = [self.expression(stop_at_blank=False)]
        while self.peek() == ",":
            self.pos += 1
            exprs.append(self.expression(stop_at_blank=False))
        if len(exprs) not in (2, 3):
            self.fail(
                A_CONTROL_SYNTAX,
                f"$FOR {target.text} = <start>, <end>, <step>: {len(exprs)} value(s) given",
            )
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after $FOR: only its counter and range may follow it",
            )
        return Control(self.raw, self.number, C_FOR, exprs, target=target)

    # --- # commands -------------------------------------------------------------------------------------
    def hash_command(self) -> Stmt:
        start = self.pos
        self.pos += 1
        self.blanks()
        name = self.name()
        raw = self.raw
        if name in ("IF", "ELSE", "ENDIF"):
            if self.number is not None or start != len(self.u) - len(self.u.lstrip()):
                self.fail(
                    A_COND_FIRST,
                    f"#{name} must stand at the very start of its block, without a block number",
                )
            keyword = "#" + name
            exprs: list[Expr] = []
            if name == "IF":
                if self.at_end():
                    self.fail(A_CONTROL_SYNTAX, "#IF without its condition")
                exprs.append(self.expression(stop_at_blank=False))
            if not self.at_end():
                self.fail(A_CONTROL_SYNTAX, f"{self.word_at(self.pos)!r} after #{name}")
            return Control(raw, self.number, keyword, exprs)
        if name == "MSG":
            return self.message()
        if name in {"FILE", "FILENAME"}:
            return self.file_name(named=name == "FILENAME")
        if name == "FLUSH":
            options: list[str] = []
            for word in ("WAIT", "CONTINUE"):
                if self.keyword(word):
                    options.append(word)
            if not self.at_end():
                self.fail(A_CONTROL_SYNTAX, f"#FLUSH: unexpected {self.word_at(self.pos)!r} (WAIT, CONTINUE)")
            return Hash(raw, self.number, "FLUSH", options, [])
        if name == "MEAS" and self.keyword("MODE"):
            return self.meas_mode()
        if name == "SLOPE":
            return self.slope()
        if name == "CONTOUR" and self.keyword("MODE"):
            return self.motion_options("CONTOUR MODE")
        if name in ("HSC", "SPLINE"):
            return self.motion_options(name)
        if name == "SET" and self.keyword("SPLINE"):
            return self.motion_options("SPLINE")  # the older spelling of #SPLINE ON/OFF (207209611)
        if name == "SET" and self.keyword("SPLINETYPE"):
            return self.motion_options("SPLINE", prefix=["TYPE"])
        if name in REFUSED_HASH:
            self.fail(
                A_NOT_SIMULATED,
                f"#{name}: {REFUSED_HASH[name]} are not simulated (the areas are monitored on the TCP in "
                "machine coordinates of cartesian main axes only): docs/nc-language.md, "
                '"What stays refused"',
            )
        if name == "ENDVAR":
            self.fail(A_DECLARATION, "#ENDVAR without #VAR")
        if name == "VAR":
            self.fail(
                A_DECLARATION, "#VAR must stand alone on its line; the declarations follow on the next lines"
            )
        if name == "COMMENT":
            self.fail(
                A_COMMENT_OPEN,
                "#COMMENT END without #COMMENT BEGIN"
                if self.keyword("END")
                else "#COMMENT: BEGIN or END expected",
            )
        if name in ("CS", "ACS", "ROTATION"):
            return self.coordinates(name)
        if name in MOTION_FUNCTIONS:
            self.fail(
                A_NOT_SIMULATED,
                f"#{name}: {MOTION_FUNCTIONS[name]} is not simulated (N-08): see docs/nc-language.md",
            )
        if name in KERNEL_HASH_COMMANDS:
            self.fail(
                A_NOT_SIMULATED,
                f"#{name} is a command of the kernel this simulator does not model: see docs/nc-language.md",
            )
        raise self.failure(
            A_UNKNOWN_HASH,
            f"unknown # command #{word_parser._short(name)}; the commands simulated here: #CONTROL AREA, "
            "#VAR/#ENDVAR, #MSG, #FILE NAME, #FLUSH, #IF/#ELSE/#ENDIF, #COMMENT BEGIN/END "
            "(docs/nc-language.md)",
        )

    def message(self) -> Stmt:
        """``#MSG [SAVE] [SYN|SYN_ACK|ACK] [receiver] ["format", args]`` (207145355, 207171211)."""
        options: list[str] = []
        words = (
            "SAVE",
            "EXCLUSIVE",
            "INFO",
            "SYN_ACK",
            "SYN",
            "ACK",
            "ISG_DIAG_BED",
            "DIAG",
            "HMI",
            "PLC",
            "EVENT_LOGGER",
        )
        progress = True
        while progress:
            progress = False
            for word in words:
                if self.keyword(word):
                    if word in options:
                        self.fail(A_CONTROL_SYNTAX, f"#MSG: {word} given twice")
                    options.append(word)
                    progress = True
        if "INFO" in options:
            self.fail(
                A_NOT_SIMULATED,
                "#MSG INFO (message information for a receiver) is not simulated: see docs/nc-language.md",
            )
        self.expect("[", "before the message text")
        self.depth += 1
        self.blanks()
        args = [self.expression(stop_at_blank=False)]
        while True:
            self.blanks()
            if self.peek() == ",":
                self.pos += 1
                args.append(self.expression(stop_at_blank=False))
                continue
            break
        self.expect("]", "after the message and its values")
        self.depth -= 1
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after #MSG [..]: a message stands alone in its block",
            )
        return Hash(self.raw, self.number, "MSG", options, args)

    def coordinates(self, name: str) -> Stmt:
        """``#CS|#ACS DEF|ON [[<id>]] [[v1,v2,v3,φ1,φ2,φ3]]``, ``#CS|#ACS OFF [ALL]``, ``#CS ADD|SET [<name>]
        [..]``, ``#CS DEL [<name>]|ALL``, ``#ROTATION ON [[ANGLE= CENTER1= CENTER2=]]``, ``#ROTATION OFF``
        (programming manual 208480907, 208491403, 1037259147, 1048407819, 207442315). The Hash's command is
        ``"CS ON"`` etc.; ``options`` holds ``ALL``, ``ID`` (the first bracket is the ID), a ``#CS ADD`` name,
        or the #ROTATION keywords in the order of ``args``."""
        ops: tuple[str, ...] = ("DEF", "ON", "OFF", "ADD", "SET", "DEL")
        if name == "ROTATION":
            ops = ("ON", "OFF")
        elif name == "ACS":
            ops = ("DEF", "ON", "OFF")
        op = next((o for o in ops if self.keyword(o)), None)
        if op is None:
            rest = self.word_at(self.pos) if self.pos < self.n else "nothing"
            self.fail(
                A_NOT_SIMULATED,
                f"#{name} {rest}: simulated are #{name} " + "/".join(ops) + " (docs/nc-language.md)",
            )
        options: list[str] = []
        args: list[Expr] = []
        if name == "ROTATION":
            if op == "ON" and not self.at_end():
                self.expect("[", "after #ROTATION ON")
                self.depth += 1
                while True:
                    self.blanks()
                    if self.peek() == "]":
                        self.pos += 1
                        break
                    key = self.name()
                    if key not in ("ANGLE", "CENTER1", "CENTER2") or key in options:
                        self.fail(
                            A_CONTROL_SYNTAX,
                            f"#ROTATION ON [..]: {key or self.word_at(self.pos)!r}: "
                            "ANGLE=, CENTER1=, CENTER2= (each once)",
                        )
                    self.blanks()
                    if self.peek() == "=":
                        self.pos += 1
                    options.append(key)
                    args.append(self.expression(stop_at_blank=True))
                self.depth -= 1
        elif op == "OFF":
            if self.keyword("ALL"):
                options.append("ALL")
        elif op in ("ADD", "SET", "DEL"):
            if op == "DEL" and self.keyword("ALL"):
                options.append("ALL")
            else:
                self.expect("[", f"after #CS {op}")
                self.blanks()
                cs_name = self.name()
                if not cs_name or len(cs_name) > 8:
                    self.fail(A_CONTROL_SYNTAX, f"#CS {op} [<name>]: a name of 1 to 8 characters")
                self.expect("]", f"after #CS {op} [<name>")
                options.append("NAME:" + cs_name)
                if op != "DEL":
                    args = self.components(f"#CS {op}")
        else:
            self.blanks()
            if self.peek() == "[":
                first = self.components(f"#{name} {op}")
                self.blanks()
                if self.peek() == "[":
                    if len(first) != 1:
                        self.fail(A_CONTROL_SYNTAX, f"#{name} {op} [<id>] [..]: the ID is one value")
                    options.append("ID")
                    args = first + self.components(f"#{name} {op}")
                elif len(first) == 1:
                    options.append("ID")
                    args = first
                else:
                    args = first
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after #{name} {op}: the command stands alone in its block",
            )
        return Hash(self.raw, self.number, f"{name} {op}", options, args)

    def components(self, what: str) -> list[Expr]:
        """``[a, , c]``: up to six values, a gap is 0."""
        self.expect("[", f"after {what}")
        self.depth += 1
        out: list[Expr] = []
        while True:
            self.blanks()
            if self.peek() in (",", "]"):
                out.append(Const(0.0))
            else:
                out.append(self.expression(stop_at_blank=False))
            self.blanks()
            if self.peek() == ",":
                self.pos += 1
                continue
            self.expect("]", f"after the values of {what}")
            break
        self.depth -= 1
        if len(out) > 6:
            self.fail(
                A_CONTROL_SYNTAX, f"{what} [..]: at most 6 values (v1, v2, v3, φ1, φ2, φ3), got {len(out)}"
            )
        return out

    def meas_mode(self) -> Stmt:
        """``#MEAS MODE [ [<meas_type>] ]`` (207084683): the measuring type of G100 from here to the
        program's end; without a value the channel's default (P-CHAN-00057)."""
        self.blanks()
        args: list[Expr] = []
        if self.peek() == "[":
            self.pos += 1
            self.depth += 1
            self.blanks()
            args.append(self.expression(stop_at_blank=False))
            self.blanks()
            self.expect("]", "after #MEAS MODE [<type>")
            self.depth -= 1
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after #MEAS MODE: #MEAS MODE [<type>] stands alone in its block",
            )
        return Hash(self.raw, self.number, "MEAS MODE", [], args)

    def slope(self) -> Stmt:
        """``#SLOPE [TYPE=<ident> [NO_OPT=..]]`` and ``#SLOPE DEFAULT`` (207190411): the acceleration
        profile of the path from here on. ``options`` holds ``TYPE=<ident>`` (STEP, TRAPEZ, SIN2,
        HSC), ``NO_OPT=<0|1>`` or ``DEFAULT``."""
        options: list[str] = []
        if self.keyword("DEFAULT"):
            options.append("DEFAULT")
        else:
            self.expect("[", "after #SLOPE: #SLOPE [TYPE=STEP|TRAPEZ|SIN2|HSC] or #SLOPE DEFAULT")
            self.depth += 1
            while True:
                self.blanks()
                if self.peek() == "]":
                    self.pos += 1
                    self.depth -= 1
                    break
                if self.peek() == ",":
                    self.pos += 1
                    continue
                if self.keyword("TYPE"):
                    self.expect("=", "after #SLOPE [TYPE")
                    self.blanks()
                    start = self.pos
                    while self.pos < self.n and self.u[self.pos] in _NAME_CHARS:
                        self.pos += 1
                    ident = self.u[start : self.pos]
                    if ident not in SLOPE_TYPES:
                        self.fail(
                            A_CONTROL_SYNTAX,
                            f"#SLOPE [TYPE={ident}]: the profiles are {', '.join(SLOPE_TYPES)}",
                        )
                    options.append(f"TYPE={ident}")
                elif self.keyword("NO_OPT"):
                    self.expect("=", "after #SLOPE [.. NO_OPT")
                    self.blanks()
                    if self.peek() not in ("0", "1") or (self.peek(1) not in ("", " ", "\t", "]", ",")):
                        self.fail(A_CONTROL_SYNTAX, "#SLOPE [.. NO_OPT=<0|1>]: 0 or 1")
                    options.append(f"NO_OPT={self.peek()}")
                    self.pos += 1
                else:
                    got = self.word_at(self.pos) if self.pos < self.n else "the end of the block"
                    self.fail(A_CONTROL_SYNTAX, f"#SLOPE [..]: unexpected {got!r} (TYPE=.., NO_OPT=..)")
            if not any(o.startswith("TYPE=") for o in options):
                self.fail(A_CONTROL_SYNTAX, "#SLOPE [..] without TYPE=STEP|TRAPEZ|SIN2|HSC")
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after #SLOPE: #SLOPE [..] stands alone in its block",
            )
        return Hash(self.raw, self.number, "SLOPE", options, [])

    def motion_options(self, command: str, prefix: list[str] | None = None) -> Stmt:
        """``#CONTOUR MODE [ON|OFF] [<type> KEY=<expr> ...]``, ``#HSC [ON|OFF] [OPMODE 1 CONTERROR 0.1]``,
        ``#SPLINE ON|OFF|TYPE AKIMA``: the words (``options``) and the values (``params``), checked and
        evaluated by the interpreter. A value follows ``=`` or, inside the brackets, a blank (``#HSC``'s
        ``OPMODE 1``); commas between the entries are allowed (the manual's ``[DEV, PATH_DEV=5]``)."""
        options: list[str] = list(prefix or [])
        params: dict[str, Expr] = {}
        inside = False
        while True:
            self.blanks()
            if self.at_end():
                break
            char = self.peek()
            if char == "[" and not inside:
                self.pos += 1
                inside = True
                continue
            if char == "]" and inside:
                self.pos += 1
                inside = False
                continue
            if char == "," and inside:
                self.pos += 1
                continue
            start = self.pos
            key = self.name()
            if not key:
                self.fail(A_CONTROL_SYNTAX, f"#{command}: unexpected {self.word_at(start)!r}")
            if key in params or key in options:
                self.fail(A_CONTROL_SYNTAX, f"#{command}: {key} given twice")
            self.blanks()
            nxt = self.peek()
            if nxt == "=" or (inside and nxt != "" and (nxt.isdigit() or nxt in "+-.")):
                if nxt == "=":
                    self.pos += 1
                    self.blanks()
                if self.at_end() or self.peek() in ("]", ","):
                    self.fail(A_CONTROL_SYNTAX, f"#{command}: {key}= without a value")
                saved = self.depth
                self.depth = 0
                try:
                    # inside the brackets a value is a whole expression, blanks and all (the manual's
                    # ``[DEV, PATH_DEV = V.G.WZ_AKT.R / 100]``); it ends at a word that is no operator
                    params[key] = self.expression(stop_at_blank=not inside)
                finally:
                    self.depth = saved
            else:
                options.append(key)
        if inside:
            self.fail(A_CONTROL_SYNTAX, f"#{command}: ']' missing")
        return Hash(self.raw, self.number, command, options, [], params=params)

    def file_name(self, named: bool = False) -> Stmt:
        """``#FILE NAME [MSG="report.txt"]`` (207504523; older ``#FILENAME``): the file ``#MSG SAVE``
        writes to."""
        if not named and not self.keyword("NAME"):
            rest = self.word_at(self.pos) if self.pos < self.n else ""
            self.fail(
                A_NOT_SIMULATED,
                f"#FILE {rest}: only #FILE NAME is simulated (the engine does no file operations): "
                "see docs/nc-language.md",
            )
        self.expect("[", "after #FILE NAME")
        files: dict[str, str] = {}
        while True:
            self.blanks()
            if self.peek() == "]":
                self.pos += 1
                break
            if self.pos >= self.n:
                self.fail(A_CONTROL_SYNTAX, "#FILE NAME [: ']' missing")
            key = self.name()
            if not key:
                self.fail(A_CONTROL_SYNTAX, f"#FILE NAME: unexpected {self.word_at(self.pos)!r}")
            self.blanks()
            if self.peek() == "=":
                self.pos += 1
                self.blanks()
            if self.peek() != '"':
                self.fail(A_CONTROL_SYNTAX, f'#FILE NAME: {key}= needs a file name in quotes ({key}="name")')
            close = self.code.find('"', self.pos + 1)
            if close < 0:
                self.fail(A_CONTROL_SYNTAX, "#FILE NAME: quote not closed")
            value = self.code[self.pos + 1 : close]
            self.pos = close + 1
            if key != "MSG":
                self.fail(
                    A_NOT_SIMULATED,
                    f"#FILE NAME [{key}=..]: implicit subroutine calls are not simulated; only MSG= (the "
                    "file of #MSG SAVE) is",
                )
            if not value or len(value) > MAX_NAME:
                self.fail(A_LIMIT, f'#FILE NAME [MSG=".."]: a file name has 1 to {MAX_NAME} characters')
            files[key] = value
        if not self.at_end():
            self.fail(A_CONTROL_SYNTAX, f"{self.word_at(self.pos)!r} after #FILE NAME [..]")
        return Hash(self.raw, self.number, "FILE NAME", [], [], files)

    # --- declarations (#VAR) --------------------------------------------------------------------------
    def declaration(self) -> Declaration:
        """``V.P.NAME[3][6] : UNS32 = [..]``, ``V.L.TEXT : STRING[20] = "x"``, ``P10 = 5``, ``P100[50]``."""
        head = _N_HEAD.match(self.u)
        if head is not None:
            self.pos = head.end()
        self.blanks()
        start = self.pos
        c = self.peek()
        dims: list[int] = []
        if c == "V" and self.peek(1) == ".":
            self.pos += 2
            area = self.name()
            if area not in ("P", "L", "S", "CYC") or self.peek() != ".":
                self.fail(
                    A_DECLARATION,
                    f"{self.word_at(start)}: only V.P., V.L., V.S. and V.CYC. variables are declared in #VAR",
                )
            self.pos += 1
            name = self.var_name()
            kind = {"P": KIND_VP, "L": KIND_VL, "S": KIND_VS, "CYC": KIND_CYC}[area]
            ref = Ref(kind, name, [], text=f"V.{area}.{name}")
        elif c == "P" and self.peek(1) in _DIGITS:
            self.pos += 1
            number = self.number_literal()
            if number is None or number != int(number):
                self.fail(A_DECLARATION, f"{self.word_at(start)}: a parameter is P<number>")
            ref = Ref(KIND_P, "", [], Const(number), 1, f"P{int(number)}")
        else:
            self.fail(
                A_DECLARATION,
                f"unexpected {self.word_at(start)!r} in #VAR: declare V.P.NAME, V.L.NAME, V.S.NAME or P1",
            )
        while self.peek() == "[":
            self.pos += 1
            self.blanks()
            size = self.number_literal()
            self.blanks()
            if size is None or size != int(size) or not 1 <= size <= 1_000_000 or self.peek() != "]":
                self.fail(
                    A_DECLARATION, f"{ref.text}: an array dimension is a whole number 1..1000000 in [ ]"
                )
            self.pos += 1
            dims.append(int(size))
            if len(dims) > 4:
                self.fail(A_DECLARATION, f"{ref.text}: at most 4 array dimensions")
        type_name = "REAL64"
        string_size = 0
        self.blanks()
        if self.peek() == ":":
            self.pos += 1
            self.blanks()
            type_name = self.name()
            if type_name == "REAL":
                type_name = "REAL64"
            if type_name not in (
                "BOOLEAN",
                "SGN08",
                "UNS08",
                "SGN16",
                "UNS16",
                "SGN32",
                "UNS32",
                "REAL32",
                "REAL64",
                "STRING",
            ):
                self.fail(
                    A_DECLARATION,
                    f"{ref.text}: unknown type {word_parser._short(type_name)!r} (BOOLEAN, SGN08, "
                    "UNS08, SGN16, "
                    "UNS16, SGN32, UNS32, REAL32, REAL64, STRING[n])",
                )
            if type_name == "STRING":
                self.expect("[", "after STRING (STRING[20])")
                self.blanks()
                size = self.number_literal()
                self.blanks()
                if size is None or size != int(size) or not 1 <= size <= MAX_STRING or self.peek() != "]":
                    self.fail(A_DECLARATION, f"{ref.text}: STRING[n] with n from 1 to {MAX_STRING}")
                self.pos += 1
                string_size = int(size)
        init: list[Expr] = []
        self.blanks()
        if self.peek() == "=":
            self.pos += 1
            self.blanks()
            if self.peek() == "[" and dims:
                self.pos += 1
                self.depth += 1
                while True:
                    init.append(self.expression(stop_at_blank=False))
                    self.blanks()
                    if self.peek() == ",":
                        self.pos += 1
                        continue
                    break
                self.expect("]", "after the initial values")
                self.depth -= 1
            else:
                init.append(self.expression(stop_at_blank=False))
        if not self.at_end():
            self.fail(
                A_DECLARATION, f"unexpected {self.word_at(self.pos)!r} in the declaration of {ref.text}"
            )
        return Declaration(self.raw.first, ref, dims, type_name, string_size, init)

    # --- expressions --------------------------------------------------------------------------------------
    def expression(self, stop_at_blank: bool) -> Expr:
        saved = self.depth
        if not stop_at_blank:
            self.depth += 1  # blanks are allowed between the operands of a whole expression
        try:
            return self.or_()
        finally:
            self.depth = saved

    def skip(self) -> None:
        """Blanks between tokens: inside brackets, or in an expression that is not a word value."""
        if self.depth > 0:
            self.blanks()

    def count(self) -> None:
        self.nodes += 1
        if self.nodes > MAX_EXPRESSION_NODES:
            self.fail(A_LIMIT, f"the block's expressions have more than {MAX_EXPRESSION_NODES} operands")

    def op_keyword(self, word: str) -> bool:
        self.skip()
        end = self.pos + len(word)
        if self.u.startswith(word, self.pos) and (end >= self.n or self.u[end] not in _NAME_CHARS):
            # "MOD", "AND" ... glued to a name before them would not be reached here
            self.pos = end
            return True
        return False

    def op(self, text: str) -> bool:
        self.skip()
        if self.u.startswith(text, self.pos):
            self.pos += len(text)
            return True
        return False

    def or_(self) -> Expr:
        left = self.xor_()
        while self.op("||") or self.op_keyword("OR"):
            self.count()
            left = BinOp(OP_OR, left, self.xor_())
        return left

    def xor_(self) -> Expr:
        left = self.and_()
        while self.op_keyword("XOR"):
            self.count()
            left = BinOp(OP_XOR, left, self.and_())
        return left

    def and_(self) -> Expr:
        left = self.compare()
        while self.op("&&") or self.op_keyword("AND"):
            self.count()
            left = BinOp(OP_AND, left, self.compare())
        return left

    def compare(self) -> Expr:
        left = self.bor()
        while True:
            self.skip()
            u = self.u
            p = self.pos
            two = u[p : p + 2]
            if two in ("==", "!=", "<=", ">=", "<>"):
                self.pos += 2
                op = {"==": OP_EQ, "!=": OP_NE, "<>": OP_NE, "<=": OP_LE, ">=": OP_GE}[two]
            elif two[:1] in ("<", ">"):
                self.pos += 1
                op = OP_LT if two[:1] == "<" else OP_GT
            elif two[:1] == "=" and self.depth > 0:
                self.fail(
                    ALARM_EXPRESSION,
                    f"'=' in a condition: compare with '==' ({self.word_at(max(p - 8, 0))!r})",
                )
            else:
                return left
            self.count()
            left = BinOp(op, left, self.bor())

    def bor(self) -> Expr:
        left = self.bxor()
        while True:
            self.skip()
            if self.u.startswith("|", self.pos) and not self.u.startswith("||", self.pos):
                self.pos += 1
                self.count()
                left = BinOp(OP_BOR, left, self.bxor())
            else:
                return left

    def bxor(self) -> Expr:
        left = self.band()
        while self.op("^"):
            self.count()
            left = BinOp(OP_BXOR, left, self.band())
        return left

    def band(self) -> Expr:
        left = self.additive()
        while True:
            self.skip()
            if self.u.startswith("&", self.pos) and not self.u.startswith("&&", self.pos):
                self.pos += 1
                self.count()
                left = BinOp(OP_BAND, left, self.additive())
            else:
                return left

    def additive(self) -> Expr:
        left = self.term()
        while True:
            self.skip()
            c = self.peek()
            if c in {"+", "-"}:
                self.pos += 1
                self.count()
                left = BinOp(OP_ADD if c == "+" else OP_SUB, left, self.term())
            else:
                return left

    def term(self) -> Expr:
        left = self.unary()
        while True:
            self.skip()
            c = self.peek()
            if c == "*" and self.peek(1) != "*":
                self.pos += 1
                op = OP_MUL
            elif c == "/":
                self.pos += 1
                op = OP_DIV
            elif self.op_keyword("MOD"):
                op = OP_MOD
            else:
                return left
            self.count()
            left = BinOp(op, left, self.unary())

    def unary(self) -> Expr:
        self.skip()
        c = self.peek()
        if c in {"-", "+"}:
            self.pos += 1
            self.count()
            self.depth_guard()
            operand = self.unary()
            if isinstance(operand, Const) and not isinstance(operand.value, str):
                return Const(-operand.value if c == "-" else operand.value)
            return Unary(c == "-", operand)
        return self.power()

    def power(self) -> Expr:
        base = self.primary()
        self.skip()
        if self.u.startswith("**", self.pos):
            self.pos += 2
            self.count()
            self.depth_guard()
            return BinOp(OP_POW, base, self.unary())
        return base

    def depth_guard(self) -> None:
        if self.nodes > MAX_EXPRESSION_NODES:
            self.fail(A_LIMIT, f"the block's expressions have more than {MAX_EXPRESSION_NODES} operands")

    def primary(self) -> Expr:
        self.skip()
        self.count()
        u = self.u
        if self.pos >= self.n:
            self.fail(ALARM_EXPRESSION, "value missing at the end of the block")
        c = u[self.pos]
        if c in _DIGITS or c == ".":
            at = self.pos
            number = self.number_literal()
            if number is None:
                self.fail(A_BAD_NUMBER, f"malformed number in {self.word_at(at)!r}")
            return Const(number)
        if c == "[":
            return self.bracket()
        if c == '"':
            close = self.code.find('"', self.pos + 1)
            if close < 0:
                self.fail(
                    ALARM_EXPRESSION, f"string not closed: {self.word_at(self.pos)!r} has no closing '\"'"
                )
            text = self.code[self.pos + 1 : close]
            if len(text) > MAX_STRING:
                self.fail(A_LIMIT, f"a string has at most {MAX_STRING} characters ({len(text)} given)")
            self.pos = close + 1
            return Const(text)
        if c == "@" or (c == "P" and (self.peek(1) in _DIGITS or self.peek(1) in ("P", "["))):
            return self.primary_ref()
        if c == "V" and self.peek(1) == "." and self.peek(2) in _LETTERS:
            return self.variable()
        if c in _LETTERS:
            start = self.pos
            name = self.name()
            if name in ("TRUE", "FALSE", "PI"):
                return Const(1.0 if name == "TRUE" else 0.0 if name == "FALSE" else 3.141592653589793)
            if name == "EXIST":
                return self.exist(start)
            if name in FUNCTION_ARITY:
                return self.function(start, name)
            if (name[:1] in ("M", "H") and name[1:].isdigit()) or name in ("REV", "POS"):
                raise self.failure(
                    A_NOT_SIMULATED,
                    f"axis- or spindle-specific technology words ({name} in [..], X[M54=..], S[REV ..]) "
                    "are not simulated: see docs/nc-language.md",
                )
            self.fail(
                ALARM_EXPRESSION,
                f"unknown name {word_parser._short(name)!r} in an expression (a variable is P1, V.P.NAME, "
                "V.E.NAME ...; functions are SIN[..], SQRT[..], ...)",
            )
        if c == "]":
            self.fail(ALARM_EXPRESSION, "']' without '['")
        raise self.failure(ALARM_EXPRESSION, f"unexpected {self.word_at(self.pos)!r} where a value belongs")

    def bracket(self) -> Expr:
        self.pos += 1
        self.depth += 1
        if self.depth > MAX_EXPRESSION_DEPTH:
            self.fail(A_LIMIT, f"brackets nested deeper than {MAX_EXPRESSION_DEPTH}")
        inner = self.or_()
        self.blanks()
        if self.peek() != "]":
            got = repr(self.word_at(self.pos)) if self.pos < self.n else "the end of the block"
            self.fail(ALARM_EXPRESSION, f"']' missing: got {got}")
        self.pos += 1
        self.depth -= 1
        return inner

    def function(self, start: int, name: str) -> Expr:
        self.blanks()
        if self.peek() != "[":
            self.fail(ALARM_EXPRESSION, f"{name} needs its argument in brackets: {name}[..]")
        self.pos += 1
        self.depth += 1
        if self.depth > MAX_EXPRESSION_DEPTH:
            self.fail(A_LIMIT, f"brackets nested deeper than {MAX_EXPRESSION_DEPTH}")
        args = [self.or_()]
        while True:
            self.blanks()
            if self.peek() == ",":
                self.pos += 1
                args.append(self.or_())
                continue
            break
        self.blanks()
        if self.peek() != "]":
            self.fail(ALARM_EXPRESSION, f"{name}[..: ']' missing")
        self.pos += 1
        self.depth -= 1
        arity = FUNCTION_ARITY[name]
        if len(args) != arity:
            self.fail(ALARM_EXPRESSION, f"{name} takes {arity} argument(s), {len(args)} given")
        func = Func(name, args)
        if func.is_constant():
            # a constant function is evaluated once, here (its errors are the block's)
            try:
                return Const(func.evaluate(_CONSTANT))
            except EvalError as exc:
                self.fail(exc.alarm, exc.message)
        return func

    def exist(self, start: int) -> Expr:
        self.blanks()
        if self.peek() != "[":
            self.fail(ALARM_EXPRESSION, "EXIST needs its argument in brackets: EXIST[V.P.NAME]")
        self.pos += 1
        self.depth += 1
        self.blanks()
        c = self.peek()
        if c in ("M", "H") and self.peek(1) in _DIGITS:
            self.pos += 1
            begin = self.pos
            while self.pos < self.n and self.u[self.pos] in _DIGITS:
                self.pos += 1
            ref = Ref(KIND_MH, c + self.u[begin : self.pos], [], text=c + self.u[begin : self.pos])
        elif c in {"P", "@"}:
            ref = self.primary_ref()
        elif c == "V" and self.peek(1) == ".":
            ref = self.variable()
        else:
            self.fail(
                ALARM_EXPRESSION,
                f"EXIST[..] takes a variable, a parameter or M/H function, got {self.word_at(self.pos)!r}",
            )
        self.expect("]", "after EXIST's variable")
        self.depth -= 1
        return Exist(ref)

    # --- variables ------------------------------------------------------------------------------------------
    def var_name(self) -> str:
        start = self.pos
        u = self.u
        while self.pos < self.n and (
            u[self.pos] in _NAME_CHARS
            or (u[self.pos] == "." and self.pos + 1 < self.n and u[self.pos + 1] in _NAME_CHARS)
        ):
            self.pos += 1
        name = u[start : self.pos]
        if not name:
            self.fail(ALARM_EXPRESSION, f"variable name missing in {self.word_at(start - 2)!r}")
        return name

    def indices(self) -> list[Expr]:
        out: list[Expr] = []
        while self.peek() == "[":
            self.pos += 1
            self.depth += 1
            out.append(self.or_())
            self.blanks()
            if self.peek() != "]":
                self.fail(ALARM_EXPRESSION, "']' missing after an index")
            self.pos += 1
            self.depth -= 1
            if len(out) > 4:
                self.fail(ALARM_EXPRESSION, "more than 4 indices")
        return out

    def variable(self) -> Ref:
        """``V.P.NAME[i]..``, ``V.L.``, ``V.S.``, ``V.E.``, ``V.A.ABS.X`` / ``V.A.ABS[0]``, ``V.G.NAME``,
        ``V.CYC.``."""
        start = self.pos
        self.pos += 2
        area = self.name()
        if self.peek() != ".":
            self.fail(ALARM_EXPRESSION, f"malformed variable {self.word_at(start)!r}")
        self.pos += 1
        kinds = {
            "P": KIND_VP,
            "L": KIND_VL,
            "S": KIND_VS,
            "E": KIND_VE,
            "A": KIND_VA,
            "G": KIND_VG,
            "CYC": KIND_CYC,
        }
        kind = kinds.get(area)
        if kind is None:
            self.fail(
                A_NOT_SIMULATED,
                f"V.{area}. variables are not simulated (V.P., V.L., V.S., V.E., V.CYC., a subset of "
                "V.A. and "
                "V.G.): see docs/nc-language.md",
            )
        sign = ""
        if kind == KIND_VA and self.peek() in ("+", "-"):
            sign = self.peek()  # V.A.+SWE.X, V.A.-SWE.X: the software limits
            self.pos += 1
        name = sign + self.var_name()
        indices = self.indices()
        return Ref(kind, name, indices, text=self.u[start : self.pos])

    def parameter(self) -> Ref:
        """``P1``, ``P[expr]``, ``PP1`` (indirect), ``P100[5]`` (an array element)."""
        start = self.pos
        depth = 0
        u = self.u
        while self.peek() == "P":
            self.pos += 1
            depth += 1
        if depth > 8:
            self.fail(ALARM_EXPRESSION, f"{self.word_at(start)}: indirection deeper than 8")
        number: Expr
        if self.peek() == "[":
            number = self.bracket()
        else:
            at = self.pos
            while self.pos < self.n and u[self.pos] in _DIGITS:
                self.pos += 1
            digits = u[at : self.pos]
            if not digits or len(digits) > 9:
                self.fail(A_BAD_NUMBER, f"malformed parameter {self.word_at(start)!r}: write P<number>")
            number = Const(float(int(digits)))
        indices = self.indices()
        kind = KIND_P if depth == 1 else KIND_PP
        return Ref(kind, "", indices, number, depth, u[start : self.pos])

    def primary_ref(self) -> Ref:
        if self.peek() == "@":
            start = self.pos
            if self.peek(1) != "P" or self.peek(2) not in _DIGITS:
                self.fail(
                    ALARM_EXPRESSION, f"unexpected {self.word_at(start)!r}: a cycle parameter is @P<number>"
                )
            self.pos += 2
            at = self.pos
            while self.pos < self.n and self.u[self.pos] in _DIGITS:
                self.pos += 1
            digits = self.u[at : self.pos]
            if len(digits) > 9:
                self.fail(A_BAD_NUMBER, f"malformed cycle parameter {self.word_at(start)!r}")
            return Ref(KIND_AT_P, "", [], Const(float(int(digits))), 1, self.u[start : self.pos])
        return self.parameter()


def parse_expression(text: str) -> Expr:
    """``text`` as one expression (blanks allowed, as after ``P1 =``); :class:`NcError` if it is not
    one. For tools and tests: programs are compiled block by block (:class:`Compiler`)."""
    raw = RawBlock(1, 1, text, text, None)
    parser = _BlockParser(Compiler((), ("X", "Y", "Z")), raw, text)
    try:
        expr = parser.expression(stop_at_blank=False)
        if not parser.at_end():
            raise parser.failure(
                ALARM_EXPRESSION, f"unexpected {parser.word_at(parser.pos)!r} after the expression"
            )
    except _CompileError as exc:
        raise _nc_error(exc.alarm, 1, None, exc.message) from None
    return expr


# --- the decoder's block from evaluated words ----------------------------------------------------------
def build_block(
    text: str,
    line: int,
    number: int | None,
    words: list[tuple[Word, float, float | None]],
    program: str,
) -> Block:
    """The decoder's :class:`Block` from evaluated words, with the word parser's rules (E-04): known G
    codes, one G per group, a word once per block, the ranges of positions, feeds, centres and S/T/D/H
    (alarms 910101..910111); the motion functions not simulated refused by name (910110)."""
    g_codes: list[int] = []
    m_codes: list[int] = []
    axes: dict[str, float] = {}
    centre: dict[str, float] = {}
    extra: dict[str, float] = {}
    feed: float | None = None
    weights = False
    for w, v, _ in words:
        if w.letter == "G" and v == int(v) and int(v) in AXIS_VALUE_G_CODES:
            weights = True
            break
    for word, value, more in words:
        letter = word.letter
        if letter == "AXIS":
            name = word.name
            if weights:
                extra[f"W:{name}"] = value
                continue
            if name in axes:
                word_parser._twice(
                    f"axis {name}",
                    name if len(name) == 1 else name + "=",
                    axes[name],
                    _shown(value),
                    line,
                    number,
                )
            if not -word_parser._POSITION_MAX <= value <= word_parser._POSITION_MAX:
                word_parser._fail(
                    A_RANGE, line, number, f"{word.text} is out of range: {word_parser._POSITION_RANGE}"
                )
            axes[name] = value
        elif letter == "G":
            if value != int(value) or value < 0:
                word_parser._fail(
                    A_BAD_NUMBER, line, number, f"{word.text}: a G code takes a whole number (G1, G01)"
                )
            g = int(value)
            if g in MOTION_G_CODES:
                word_parser._fail(
                    A_NOT_SIMULATED,
                    line,
                    number,
                    f"G{g}: {MOTION_G_CODES[g]} is not simulated (N-08): see docs/nc-language.md",
                )
            if g not in KNOWN_G:
                known = " ".join(f"G{c}" for c in sorted(KNOWN_G))
                word_parser._fail(A_UNKNOWN_G, line, number, f"unknown G code G{g}; supported: {known}")
            if g in VALUE_G_CODES:
                if more is None:
                    word_parser._fail(A_BAD_NUMBER, line, number, f"G{g} takes a value: G{g}=<percent>")
                extra[f"G{g}"] = more
            g_codes.append(g)
        elif letter in {"M", "H"}:
            code = math.floor(value + 0.5) if value >= 0 else -1
            if not 0 <= code <= 999_999_999:
                word_parser._fail(
                    A_BAD_NUMBER,
                    line,
                    number,
                    f"{word.text}: an {letter} function is a whole number 0 .. 999999999, got "
                    f"{_shown(value)}",
                )
            if letter == "M":
                m_codes.append(int(code))
            elif "H" not in extra:
                extra["H"] = float(code)
        elif letter == "F":
            if feed is not None:
                word_parser._twice("feed", "F", feed, _shown(value), line, number)
            if not word_parser._FEED_MIN <= value <= word_parser._FEED_MAX:
                word_parser._fail(
                    A_RANGE, line, number, f"F{_shown(value)} is out of range: {word_parser._FEED_RANGE}"
                )
            feed = value
        elif letter == "R":
            if "R" in extra:
                word_parser._twice("circle radius", "R", extra["R"], _shown(value), line, number)
            if not -word_parser._CENTRE_MAX <= value <= word_parser._CENTRE_MAX:
                word_parser._fail(
                    A_RANGE, line, number, f"R{_shown(value)} is out of range: {word_parser._CENTRE_RANGE}"
                )
            extra["R"] = value
        elif letter in ("I", "J", "K"):
            if letter in centre:
                word_parser._twice(
                    f"circle centre {letter}", letter, centre[letter], _shown(value), line, number
                )
            if not -word_parser._CENTRE_MAX <= value <= word_parser._CENTRE_MAX:
                word_parser._fail(
                    A_RANGE,
                    line,
                    number,
                    f"{letter}{_shown(value)} is out of range: {word_parser._CENTRE_RANGE}",
                )
            centre[letter] = value
        else:  # S, T, D
            if letter in extra:
                word_parser._twice(letter, letter, extra[letter], _shown(value), line, number)
            if not -word_parser._EXTRA_MAX <= value <= word_parser._EXTRA_MAX:
                word_parser._fail(
                    A_RANGE,
                    line,
                    number,
                    f"{letter}{_shown(value)} is out of range: {word_parser._EXTRA_RANGE}",
                )
            extra[letter] = value
    if len(g_codes) > 1:
        g_codes = word_parser._check_g_codes(g_codes, line, number)
    return Block(
        line,
        number,
        text,
        tuple(g_codes),
        tuple(m_codes),
        tuple(axes.items()),
        tuple(centre.items()),
        feed,
        None,
        (),
        extra,
        program,
    )


def _shown(value: float) -> str:
    if math.isfinite(value) and value == int(value) and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.10g}"
