"""The NC interpreter: runs a program's statements ahead of the motion and hands the decoder its blocks
(N-01..N-08).

It keeps what the language needs and the decoder does not: the call stack (main program, local and
global subroutines, cycles), the open control blocks of each level, the variables, the jump labels. It
is asked for one output at a time (:meth:`Interpreter.next`):

* a :class:`~hli_server.engine.nc.blocks.Block` for the decoder - the same blocks the word parser
  makes, with every expression evaluated;
* a :class:`Directive` - :data:`PAUSE` (this cycle's budget is spent: go on next cycle),
  :class:`SyncAction` (something to do when the path gets there: a ``#MSG SYN``, a synchronous
  ``V.E.`` write), :class:`FlushStop` (``#FLUSH``: the path stops there), :class:`FlushWait`
  (``#FLUSH WAIT``, or a read of a synchronous ``V.E.`` variable: decoding waits until the path got
  there);
* None at the end of the main program's text (M30/M02 end it earlier, through the decoder).

Errors are :class:`~hli_server.engine.nc.blocks.NcError` with the kernel's ID where its diagnosis
pages give one (docs/nc-language.md lists them), raised from :meth:`Interpreter.next`.

Work per cycle is bounded (docs/check.md, "Bad input"): every statement run or skipped spends one unit of
the budget that :meth:`Interpreter.refill` sets each cycle; a program that computes without moving
goes on in the next cycle instead of stalling the clock. A geometry check, which has no cycles, caps
loop iterations instead (:class:`IterationCapError`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Final, Protocol, TextIO

from hli_server.engine.external import ExternalVariableError, ExternalVariables
from hli_server.engine.nc import parser as word_parser
from hli_server.engine.nc.block_builder import build_block
from hli_server.engine.nc.blocks import Block, NcError
from hli_server.engine.nc.compiler import Compiler
from hli_server.engine.nc.expr import (
    ALARM_DOMAIN,
    ALARM_EXPRESSION,
    ALARM_TYPE,
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
    Env,
    EvalError,
    Expr,
    Ref,
    Value,
    as_number,
    format_value,
)
from hli_server.engine.nc.language import (
    A_CONTROL_SYNTAX,
    A_NOT_SIMULATED,
    A_RANGE,
    C_BREAK,
    C_CASE,
    C_CONTINUE,
    C_DEFAULT,
    C_DO,
    C_ELSE,
    C_ELSEIF,
    C_ENDDO,
    C_ENDFOR,
    C_ENDIF,
    C_ENDSWITCH,
    C_ENDWHILE,
    C_FOR,
    C_HASH_ELSE,
    C_HASH_ENDIF,
    C_HASH_IF,
    C_IF,
    C_REPEAT,
    C_SWITCH,
    C_UNTIL,
    C_WHILE,
)
from hli_server.engine.nc.reader import read_block, strip_comments
from hli_server.engine.nc.source import LineTooLongError, ProgramText
from hli_server.engine.nc.statements import (
    Assign,
    Call,
    ConstBlock,
    Control,
    Empty,
    Goto,
    Hash,
    Header,
    Refused,
    Stmt,
    VarBlock,
    Word,
    Words,
)
from hli_server.engine.nc.variables import P_COUNT, Variable, coerce
from hli_server.engine.programs import ProgramFile

__all__ = [
    "MAX_CALL_DEPTH",
    "PAUSE",
    "STATEMENTS_PER_CYCLE",
    "ContourDirective",
    "CoordinateCommand",
    "Directive",
    "FlushStop",
    "FlushWait",
    "Host",
    "Interpreter",
    "IterationCapError",
    "Slope",
    "SyncAction",
    "ToolWrite",
]

STATEMENTS_PER_CYCLE: Final = 128
"""Statements the interpreter runs or skips in one cycle at most (docs/check.md): 800,000 blocks without
motion take 6,250 cycles, not one cycle of 3.9 s; a ``$WHILE`` without motion runs on, cycle by cycle,
and a reset still stops it."""
MAX_CALL_DEPTH: Final = 20
"""Program levels (main program, subroutines, cycles) nested at most; deeper is ID 20360 (a recursion)."""
MAX_OPEN_BLOCKS: Final = 64
"""Control blocks open at once in one program level (the kernel's limit is not public)."""
MEAS_TYPES: Final = 7
"""Measuring types of ``#MEAS MODE`` (P-CHAN-00057: 1 .. 7)."""
MAX_MESSAGE: Final = 255
"""Characters of a ``#MSG`` text after formatting."""
_STATEMENT_CACHE: Final = 50_000
"""Compiled statements kept per program text (a loop body is compiled once; a CAM file streams)."""
_NO_INDICES: Final[list[float]] = []
"""The indices of a reference without any (never changed)."""
_GLOBAL_UNITS: Final = 64
"""Global subprograms kept compiled (by name) in one program run."""

# --- alarm numbers: the kernel's (TF5200 diagnosis) and the project's (914xxx) -------------------------
A_UNEXPECTED: Final[dict[str, int]] = {
    C_ELSE: 20214,
    C_ELSEIF: 20216,
    C_ENDIF: 20218,
    C_CASE: 20221,
    C_DEFAULT: 20223,
    C_ENDSWITCH: 20225,
    C_ENDFOR: 20232,
    C_ENDWHILE: 20237,
    C_BREAK: 20243,
    C_CONTINUE: 20244,
    C_ENDDO: 914017,
    C_UNTIL: 914017,
    C_HASH_ELSE: 914017,
    C_HASH_ENDIF: 914017,
}
"""A closing or middle control word without its opening one: the kernel's "Unexpected ..." IDs."""
A_STACK_OVERFLOW: Final = 20360
A_OPEN_VALID: Final = 20375
A_OPEN_INVALID_LOCAL: Final = 21500
A_OPEN_INVALID_MAIN: Final = 21501
A_OPEN_INVALID_GLOBAL: Final = 21502
A_CYCLE_PARAMETER: Final = 21382
A_UNDECLARED: Final = 914003
A_READ_ONLY: Final = 914004
A_INDEX: Final = 914005
A_NOT_WRITTEN: Final = 914007
A_DECLARATION: Final = 914008
A_NOT_FOUND: Final = 914010
A_LABEL: Final = 914013
A_NESTING: Final = 914014
A_CONTROL: Final = 914015
A_STEP: Final = 914021
A_SUB_END: Final = 914030
A_MESSAGE: Final = 914031
A_MAIN_RETURN: Final = 914032

_OPENING: Final = frozenset((C_IF, C_SWITCH, C_WHILE, C_DO, C_REPEAT, C_FOR))
_CLOSING: Final[dict[str, str]] = {
    C_ENDIF: C_IF,
    C_ENDSWITCH: C_SWITCH,
    C_ENDWHILE: C_WHILE,
    C_ENDDO: C_DO,
    C_UNTIL: C_REPEAT,
    C_ENDFOR: C_FOR,
}
_END_OF: Final[dict[str, str]] = {v: k for k, v in _CLOSING.items()}
_MIDDLE: Final[dict[str, str]] = {
    C_ELSE: C_IF,
    C_ELSEIF: C_IF,
    C_CASE: C_SWITCH,
    C_DEFAULT: C_SWITCH,
    C_HASH_ELSE: C_HASH_IF,
    C_HASH_ENDIF: C_HASH_IF,
}
_LOOPS: Final = frozenset((C_WHILE, C_DO, C_REPEAT, C_FOR))

_POSITION_RANGE: Final = word_parser._POSITION_RANGE
_CENTRE_RANGE: Final = word_parser._CENTRE_RANGE
_FEED_RANGE: Final = word_parser._FEED_RANGE
_EXTRA_RANGE: Final = word_parser._EXTRA_RANGE


# --- what the interpreter hands out besides blocks ------------------------------------------------------

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


class Directive:
    """An output that is not a block (see the module's description)."""

    def __init__(self, block: Block | None) -> None:
        self.block = block
        """Where in the program (line, N) it was programmed."""


PAUSE: Final = Directive(None)
"""This cycle's budget is spent; ask again next cycle."""


class SyncAction(Directive):
    """``action`` runs when the path passes this point (it does not stop the path)."""

    def __init__(self, block: Block, action: Callable[[], None]) -> None:
        super().__init__(block)
        self.action = action


class FlushStop(Directive):
    """``#FLUSH``: the path comes to rest here; decoding goes on."""


class FlushWait(Directive):
    """``#FLUSH WAIT`` (or a synchronous read): decoding waits until the path is at rest here."""


class MeasMode(Directive):
    """``#MEAS MODE``: the measuring type of the G100 blocks after it (None: the channel's default)."""

    def __init__(self, block: Block, meas_type: int | None) -> None:
        super().__init__(block)
        self.meas_type = meas_type


class Slope(Directive):
    """``#SLOPE [TYPE=..]`` / ``#SLOPE DEFAULT``: the acceleration profile from here on (``profile``:
    0 STEP, 1 TRAPEZ, 2 SIN2, 3 HSC as P-CHAN-00071; None: the channel's default, P-CHAN-00071)."""

    def __init__(self, block: Block, profile: int | None) -> None:
        super().__init__(block)
        self.profile = profile


class CoordinateCommand(Directive):
    """``#CS``, ``#ACS``, ``#ROTATION`` (M-10..M-13): the decoder changes its frames in program order.

    ``kind`` CS, ACS or ROTATION; ``op`` DEF, ON, OFF, ADD, SET, DEL; ``ident`` the (A)CS ID where
    programmed; ``name`` a #CS ADD/SET/DEL name; ``values`` the components [v1, v2, v3, φ1, φ2, φ3];
    ``options`` the #ROTATION values by keyword."""

    def __init__(
        self,
        block: Block,
        kind: str,
        op: str,
        ident: int | None = None,
        name: str | None = None,
        values: tuple[float, ...] = (),
        options: dict[str, float] | None = None,
        all_: bool = False,
    ) -> None:
        super().__init__(block)
        self.kind = kind
        self.op = op
        self.ident = ident
        self.name = name
        self.values = values
        self.options = options or {}
        self.all_ = all_


TOOL_WRITES: Final = {"WZR": "radius", "WZ_AKT.R": "radius", "WZL": "length", "WZ_AKT.L": "length"}
"""V.G. variables a program may write: the active tool's radius and length (M-14)."""


class ToolWrite(Directive):
    """``V.G.WZR = 2`` / ``V.G.WZ_AKT.R``/``.L``: the active tool's radius or length from here on."""

    def __init__(self, block: Block, what: str, value: float) -> None:
        super().__init__(block)
        self.what = what
        self.value = value


class ContourDirective(Directive):
    """``#CONTOUR MODE``, ``#HSC``, ``#SPLINE`` / ``#SET SPLINE`` (M-20..M-23): ``function`` is
    ``"CONTOUR"``, ``"HSC"`` or ``"SPLINE"``; ``on`` True (ON), False (OFF) or None (parameters only);
    ``mode`` the contouring type (``DEV``, ``DIST``, ...), the HSC variant (``OPMODE 1``, ``BSPLINE``) or
    the spline type, None where not programmed; ``values`` the numeric parameters (mm)."""

    def __init__(
        self, block: Block, function: str, on: bool | None, mode: str | None, values: dict[str, float]
    ) -> None:
        super().__init__(block)
        self.function = function
        self.on = on
        self.mode = mode
        self.values = values


CONTOUR_TYPES: Final = ("DEV", "DIST", "AUTO_DEV", "AUTO_VEL", "DIST_SOFT", "DIST_MASTER", "POS", "PTP")
"""The contouring types of ``#CONTOUR MODE`` (tf5200_programming_manual/475147915.html)."""
_CONTOUR_KEYS: Final = frozenset(
    (
        "PATH_DEV",
        "TRACK_DEV",
        "PRE_DIST",
        "POST_DIST",
        "VEL",
        "RELEVANT_PATH",
        "RELEVANT_TRACK",
        "REMAIN_PART",
        "CHECK_JERK",
        "MAX_ANGLE",
        "SYM_DIST",
        "ACC_MAX",
        "ACC_MIN",
        "RAMP_TIME",
        "CONST_VEL",
        "TRACK_DIST",
        "MASTER_AX",
    )
)
_CONTOUR_WORDS: Final = frozenset(("ON", "OFF", "PRE_ACTION", "INTER_ACTION", "POST_ACTION", *CONTOUR_TYPES))
_HSC_KEYS: Final = frozenset(
    (
        "OPMODE",
        "CONTERROR",
        "PATH_DEV",
        "TRACK_DEV",
        "MERGE",
        "AUTO_OFF_PATH",
        "AUTO_OFF_TRACK",
        "AUTO_OFF_G00",
        "AUTO_OFF_G60",
        "MAX_PATH_LENGTH",
        "MAX_ANGLE",
    )
)
_HSC_WORDS: Final = frozenset(("ON", "OFF", "BSPLINE"))
_SPLINE_WORDS: Final = frozenset(("ON", "OFF", "TYPE", "AKIMA", "BSPLINE"))
_DEVIATION_KEYS: Final = frozenset(("PATH_DEV", "CONTERROR"))
A_CORNER_DEVIATION: Final = 120129
"""The kernel's "corner deviation of polynomial contouring smaller than permissible minimum value"
(tf5200_diagnosis/264341387.html)."""


class IterationCapError(Exception):
    """A geometry check ran more loop iterations than its cap (an endless loop, or a cap too low)."""

    def __init__(self, cap: int, line: int, place: str) -> None:
        super().__init__(f"{place}: more than {cap} loop iterations or jumps back; the check stopped here")
        self.cap = cap
        self.line = line
        self.place = place


class Host(Protocol):
    """What the interpreter needs of its channel (the channel implements it; the engine does no I/O)."""

    @property
    def channel_number(self) -> int: ...

    @property
    def external(self) -> ExternalVariables: ...

    def find_program(self, name: str) -> ProgramFile | None:
        """A global subroutine or cycle by the name the program calls it (``machine.programs``)."""
        ...

    def searched(self) -> tuple[str, ...]:
        """Where :meth:`find_program` looks (for the alarm of a program not found)."""
        ...

    def message(self, text: str, save: bool, file: str, program: str, line: int, block: str) -> None:
        """``#MSG`` (``save``: ``#MSG SAVE`` into ``file``): the channel emits the events."""
        ...

    def warn(self, alarm: int, message: str, line: int, block: str) -> None:
        """A warning of the table (the program goes on)."""
        ...

    def axis_value(self, variable: str, axis: str) -> float | None:
        """``V.A.<variable>.<axis>`` in mm, or None where the simulator has no such variable."""
        ...

    def global_value(self, name: str) -> float | None:
        """``V.G.<name>``, or None where the simulator has no such variable."""
        ...

    def axis_name(self, index: int) -> str | None:
        """The channel's axis number ``index`` (``V.A.ABS[0]``), or None."""
        ...


# --- program levels ------------------------------------------------------------------------------------
class _Units:
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


class _Open:
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


_SEEK_BRANCH: Final = 1
"""A false $IF/$ELSEIF: the next $ELSEIF/$ELSE/$ENDIF of this block."""
_SEEK_END: Final = 2
"""Past the end of the block (a false $WHILE/$FOR, a taken $IF's other branches, $BREAK)."""
_SEEK_CASE: Final = 3
"""$SWITCH: the matching $CASE, else $DEFAULT, else $ENDSWITCH."""
_SEEK_CONTINUE: Final = 4
"""$CONTINUE: the loop's closing statement, which then runs."""
_SEEK_HASH: Final = 5
"""A false #IF: its #ELSE or #ENDIF."""
_SEEK_HASH_END: Final = 6
"""A taken #IF's #ELSE branch: its #ENDIF."""
_SEEK_LABEL: Final = 7
"""$GOTO: the label, forward, then from the unit's start."""


class _Seek:
    def __init__(self, mode: int, depth: int, origin: int, label: str = "") -> None:
        self.mode = mode
        self.depth = depth
        self.origin = origin
        self.label = label
        self.wrapped = False
        self.pending: list[_Open] = []
        """$GOTO forward: blocks opened between the jump and the label."""


class _Frame:
    """A program level: a unit of a text, where it is, its open blocks and local variables."""

    def __init__(self, kind: str, units: _Units, name: str, start: int, call: Block | None) -> None:
        self.kind = kind
        """``main``, ``local``, ``global`` or ``cycle``."""
        self.units = units
        self.name = name
        self.start = start
        self.line = start
        self.call = call
        self.open: list[_Open] = []
        self.seek: _Seek | None = None
        self.locals: dict[str, Variable] = {}
        self.cycle_vars: dict[str, Variable] = {}
        self.params: dict[int, float] | None = None
        self.synced = -1
        """The line whose synchronous reads were flushed for (re-run after a #FLUSH WAIT)."""
        self.returning = False
        self.program = "" if kind == "main" else name
        self.keep = kind != "main"
        """Keep every compiled statement: a subroutine is called again."""


# --- the interpreter --------------------------------------------------------------------------------------
class Interpreter(Env):
    """Runs programs for one channel (see the module's description).

    ``budget`` is the statements per cycle (None: unbounded, for a geometry check); ``iteration_cap``
    bounds loop iterations and backward jumps (None: unbounded, for a running machine)."""

    def __init__(
        self,
        compiler: Compiler,
        host: Host,
        *,
        budget: int | None = STATEMENTS_PER_CYCLE,
        iteration_cap: int | None = None,
    ) -> None:
        self.compiler = compiler
        self.host = host
        self.budget = budget
        self.iteration_cap = iteration_cap
        self._left = budget if budget is not None else 0
        self._frames: list[_Frame] = []
        self._pending: deque[Block | Directive] = deque()
        self._ended = True
        self._params: dict[int, Value] = {}
        self._param_arrays: dict[tuple[int, tuple[int, ...]], Value] = {}
        self._program_vars: dict[str, Variable] = {}
        self._static_vars: dict[str, Variable] = {}
        """V.S.: kept across programs and resets (the channel's lifetime)."""
        self._message_file = "message.txt"
        self.iterations = 0
        self.statements = 0
        """Statements run or skipped since the program started (for reports)."""
        self.program_name = ""
        self._globals: dict[str, _Units] = {}
        """Global subprograms and cycles called in this program, compiled once (a pocket calls one
        cycle thousands of times)."""
        self.before_effect: Callable[[], None] | None = None
        """Called before the interpreter does what others see (a message, a warning, a V.E. write) or
        reads the decoder's state (V.A., V.G.): the batch geometry check decodes the blocks it kept first
        (hli_server/engine/batch.py)."""

    # --- program control -------------------------------------------------------------------------------
    def start(self, text: str | TextIO | ProgramText, name: str = "program") -> None:
        """Start the main program ``text`` (P parameters and V.P. variables start empty)."""
        source = text if isinstance(text, ProgramText) else ProgramText(text, name)
        units = _Units(source, self.compiler)
        self.program_name = name
        self._frames = [_Frame("main", units, name, units.main(), None)]
        self._pending.clear()
        self._ended = False
        self._params = {}
        self._param_arrays = {}
        self._program_vars = {}
        self._message_file = "message.txt"
        self.iterations = 0
        self.statements = 0
        self._left = self.budget if self.budget is not None else 0
        self._globals = {}

    def reset(self) -> None:
        """Channel reset: the program is gone; V.S. variables stay."""
        self._frames = []
        self._pending.clear()
        self._ended = True

    def refill(self) -> None:
        """A new cycle: a new budget."""
        if self.budget is not None:
            self._left = self.budget

    @property
    def main_line(self) -> int:
        """The main program's current line (progress of a long check)."""
        return self._frames[0].line if self._frames else 0

    @property
    def depth(self) -> int:
        return len(self._frames)

    @property
    def at_main_level(self) -> bool:
        """Straight on in the main program: no subroutine, no open block, nothing being skipped or
        waiting to be handed out (the batch geometry check may then read plain lines itself)."""
        if len(self._frames) != 1 or self._pending:
            return False
        frame = self._frames[0]
        return not frame.open and frame.seek is None and not frame.returning and not self._ended

    def advance_to(self, line: int) -> None:
        """The batch geometry check ran the main program's lines up to ``line`` (exclusive) itself."""
        self._frames[0].line = line

    def _effect(self) -> None:
        hook = self.before_effect
        if hook is not None:
            hook()

    # --- the loop --------------------------------------------------------------------------------------
    def next(self) -> Block | Directive | None:
        """The next block or directive; None at the end of the main program's text."""
        pending = self._pending
        if pending:
            return pending.popleft()
        if self._ended:
            return None
        try:
            return self._run()
        except NcError as exc:
            self._ended = True
            frame = self._frames[-1] if self._frames else None
            if frame is not None and frame.program and not exc.program:
                exc.program = frame.program
            raise
        except EvalError as exc:  # pragma: no cover - every evaluation is inside a statement
            self._ended = True
            raise NcError(exc.alarm, 0, "line 0", exc.message) from None

    def _run(self) -> Block | Directive | None:
        pending = self._pending
        bounded = self.budget is not None
        while True:
            if bounded:
                if self._left <= 0:
                    return PAUSE
                self._left -= 1
            self.statements += 1
            frame = self._frames[-1]
            if frame.returning:
                self._return(frame)
                if self._ended:
                    return None
                continue
            stmt = frame.units.statement(frame.line, frame.program, frame.keep or bool(frame.open))
            if isinstance(stmt, Block):
                frame.line += 1
                if frame.seek is not None:
                    continue  # constant words: neither a control statement nor a label
                if stmt.m_codes:
                    self._program_flow(frame, stmt)
                return stmt
            if stmt is None or isinstance(stmt, Header):
                self._unit_end(frame, stmt)
                if self._ended:
                    return pending.popleft() if pending else None
                if pending:
                    return pending.popleft()
                continue
            if frame.seek is not None:
                self._seek(frame, stmt)
                continue
            frame.line = stmt.last + 1
            self._execute(frame, stmt)
            if pending:
                return pending.popleft()

    # --- statements ------------------------------------------------------------------------------------
    def _execute(self, frame: _Frame, stmt: Stmt) -> None:
        if isinstance(stmt, ConstBlock):
            block = stmt.block
            self._pending.append(block)
            if block.m_codes:
                self._program_flow(frame, block)
            return
        if isinstance(stmt, Empty):
            return
        if isinstance(stmt, Words):
            self._words(frame, stmt)
            return
        if isinstance(stmt, Control):
            self._control(frame, stmt)
            return
        if isinstance(stmt, Refused):
            keyword = stmt.keyword
            if keyword in A_UNEXPECTED and not self._fits(frame, keyword):
                # as the kernel: a control word where it does not belong is that, whatever follows it
                raise self._unexpected_word(frame, stmt, keyword)
            raise stmt.failure
        if isinstance(stmt, VarBlock):
            self._declare(frame, stmt)
            return
        if isinstance(stmt, Hash):
            self._hash(frame, stmt)
            return
        raise stmt.error(ALARM_EXPRESSION, f"cannot run {stmt.text!r}")  # pragma: no cover

    def _evaluate(self, stmt: Stmt, expr: Expr) -> Value:
        try:
            return expr.evaluate(self)
        except EvalError as exc:
            raise stmt.error(exc.alarm, exc.message) from None

    def _number(self, stmt: Stmt, expr: Expr, what: str) -> float:
        try:
            value = expr.evaluate(self)
            if isinstance(value, float):
                return value
            return as_number(value, what)
        except EvalError as exc:
            raise stmt.error(exc.alarm, exc.message) from None

    def _needs_flush(self, frame: _Frame, stmt: Stmt, exprs: list[Expr]) -> bool:
        """Does the statement read a synchronous variable (V.E. declared synchronous, V.A.ACT_POS)?
        Then decoding first waits for the path (``#FLUSH WAIT``), once, and the statement runs again."""
        if frame.synced == stmt.first or stmt.sync_reads == 0:
            return False
        if stmt.sync_reads < 0:
            stmt.sync_reads = 1 if self._reads_synchronous(exprs) else 0
        return stmt.sync_reads == 1

    def _reads_synchronous(self, exprs: list[Expr]) -> bool:
        external = self.host.external
        for expr in exprs:
            for ref in expr.references():
                if ref.kind == KIND_VE:
                    spec = external.spec(ref.name, self.host.channel_number)
                    if spec is not None and spec.synchronous:
                        return True
                elif ref.kind == KIND_VA and ref.name.startswith("ACT_POS"):
                    return True
        return False

    def _flush_wait(self, frame: _Frame, stmt: Stmt) -> None:
        frame.synced = stmt.first
        frame.line = stmt.first
        self._pending.append(FlushWait(self._place_block(frame, stmt)))

    def _place_block(self, frame: _Frame, stmt: Stmt) -> Block:
        return Block(stmt.first, stmt.number, stmt.text, program=frame.program)

    def _words(self, frame: _Frame, stmt: Words) -> None:
        if stmt.sync_reads != 0 and self._needs_flush(frame, stmt, self._word_exprs(stmt)):
            self._flush_wait(frame, stmt)
            return
        words: list[tuple[Word, float, float | None]] = []
        syncs: list[Callable[[], None]] = []
        for item in stmt.items:
            if isinstance(item, Assign):
                sync = self._assign(frame, stmt, item.target, self._evaluate(stmt, item.value))
                if sync is not None:
                    syncs.append(sync)
            elif isinstance(item, Word):
                value = self._number(stmt, item.value, item.text)
                extra = self._number(stmt, item.extra, item.text) if item.extra is not None else None
                words.append((item, value, extra))
        block: Block | None = None
        if words:
            block = self._build(frame, stmt, words)
            self._pending.append(block)
        if syncs:
            place = block if block is not None else self._place_block(frame, stmt)
            for action in syncs:
                self._pending.append(SyncAction(place, action))
        if block is not None and block.m_codes:
            self._program_flow(frame, block)
            if (frame.returning or self._ended) and (stmt.call is not None or stmt.goto is not None):
                raise stmt.error(A_CONTROL, "a block that ends the program or subroutine calls or jumps")
        if stmt.call is not None:
            place = block if block is not None else self._place_block(frame, stmt)
            self._call(frame, stmt, stmt.call, place)
        elif stmt.goto is not None:
            self._goto(frame, stmt, stmt.goto)

    @staticmethod
    def _word_exprs(stmt: Words) -> list[Expr]:
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
        return exprs

    def _program_flow(self, frame: _Frame, block: Block) -> None:
        """M30/M02 end the program (a subroutine's with a warning), M17/M29 end a subroutine."""
        m = block.m_codes
        line = block.line
        place = block.label
        if 30 in m or 2 in m:
            if frame.kind != "main":
                self._effect()
                self.host.warn(
                    A_SUB_END,
                    f"M{30 if 30 in m else 2:02d} in {frame.kind} subroutine {frame.name}: it ends the whole "
                    "program (end a subroutine with M17 or M29)",
                    line,
                    place,
                )
            for level in self._frames:
                self._warn_open(level, line, place)
            self._ended = True
            return
        if 17 in m or 29 in m:
            if frame.kind == "main":
                raise NcError(
                    A_MAIN_RETURN,
                    line,
                    place,
                    f"M{17 if 17 in m else 29} ends a subroutine; the main program ends with M30 or M02",
                )
            self._warn_open(frame, line, place)
            frame.returning = True

    def _warn_open(self, frame: _Frame, line: int, place: str) -> None:
        """Warning 20375: control blocks still open where a program level ends."""
        if frame.open:
            top = frame.open[-1]
            self._effect()
            self.host.warn(
                A_OPEN_VALID,
                f"{len(frame.open)} control block(s) still open at the end of {frame.kind} program "
                f"{frame.name}: ${top.keyword} of line {top.start} has no "
                f"${_END_OF.get(top.keyword, top.keyword)}",
                line,
                place,
            )

    # --- the block for the decoder ---------------------------------------------------------------------
    def _build(self, frame: _Frame, stmt: Stmt, words: list[tuple[Word, float, float | None]]) -> Block:
        return build_block(stmt.text, stmt.first, stmt.number, words, frame.program)

    # --- variables -------------------------------------------------------------------------------------
    def _indices(self, ref: Ref) -> list[float]:
        if not ref.indices:
            return _NO_INDICES
        return [as_number(i.evaluate(self), f"the index of {ref.text}") for i in ref.indices]

    def _p_number(self, ref: Ref) -> int:
        assert ref.number is not None
        number = as_number(ref.number.evaluate(self), f"the number of {ref.text}")
        for _ in range(ref.depth - 1):
            number = as_number(self._param(number, ref), f"{ref.text}")
        return self._check_p(number, ref)

    def _check_p(self, number: float, ref: Ref) -> int:
        if number != int(number) or not 0 <= number < P_COUNT:
            raise EvalError(
                A_INDEX,
                f"{ref.text}: P{format_value(number)} is not a parameter (P0 .. P{P_COUNT - 1}, "
                "P-CHAN-00517)",
            )
        return int(number)

    def _param(self, number: float, ref: Ref) -> Value:
        p = self._check_p(number, ref)
        value = self._params.get(p)
        if value is None:
            raise EvalError(A_NOT_WRITTEN, f"P{p} is read before it was written or declared ({ref.text})")
        return value

    def _user_var(self, ref: Ref, declare: bool = False) -> Variable | None:
        """The declared V.P./V.L./V.S./V.CYC. variable ``ref`` names, or None."""
        kind = ref.kind
        name = ref.name
        if kind == KIND_VP:
            return self._program_vars.get(name)
        if kind == KIND_VS:
            return self._static_vars.get(name)
        if kind == KIND_VL:
            for frame in reversed(self._frames):
                var = frame.locals.get(name)
                if var is not None:
                    return var
            return None
        if kind == KIND_CYC:
            for frame in reversed(self._frames):
                var = frame.cycle_vars.get(name)
                if var is not None:
                    return var
                if frame.kind == "cycle":
                    return None
            return None
        return None

    def read(self, ref: Ref) -> Value:
        kind = ref.kind
        if kind == KIND_VP and not ref.indices:  # V.P.NAME: the fast path of a scalar
            found_var = self._program_vars.get(ref.name)
            if found_var is not None and not found_var.dims:
                return found_var.values[0]
        fixed = ref.fixed
        if fixed >= 0:  # P3, @P2: a constant number, no index
            if kind == KIND_P and fixed < P_COUNT:
                value = self._params.get(fixed)
                if value is not None:
                    return value
            elif kind == KIND_AT_P:
                params = self._frames[-1].params
                if params is not None:
                    found = params.get(fixed)
                    if found is not None:
                        return found
        if kind in (KIND_P, KIND_PP):
            p = self._p_number(ref)
            if ref.indices:
                key = (p, tuple(int(i) for i in self._indices(ref)))
                value = self._param_arrays.get(key)
                if value is None:
                    raise EvalError(A_NOT_WRITTEN, f"{ref.text} is read before it was written")
                return value
            value = self._params.get(p)
            if value is None:
                raise EvalError(
                    A_NOT_WRITTEN,
                    f"P{p} is read before it was written or declared"
                    + (f" ({ref.text})" if ref.text != f"P{p}" else ""),
                )
            return value
        if kind in (KIND_VP, KIND_VL, KIND_VS, KIND_CYC):
            var = self._user_var(ref)
            if var is None:
                raise EvalError(
                    A_UNDECLARED, f"{ref.text.split('[')[0]} is not declared (declare it in #VAR .. #ENDVAR)"
                )
            return var.get(self._indices(ref))
        if kind == KIND_VE:
            try:
                return float(
                    self.host.external.read(
                        ref.name,
                        self.host.channel_number,
                        [int(i) if i == int(i) else -1 for i in self._indices(ref)],
                    )
                )
            except ExternalVariableError as exc:
                raise EvalError(A_UNDECLARED, str(exc)) from None
        if kind == KIND_AT_P:
            return self._cycle_param(ref)
        if kind == KIND_VA:
            return self._axis_variable(ref)
        if kind == KIND_VG:
            if ref.indices:
                raise EvalError(A_NOT_SIMULATED, f"{ref.text} is not simulated: see docs/nc-language.md")
            self._effect()
            value = self.host.global_value(ref.name)
            if value is None:
                raise EvalError(
                    A_NOT_SIMULATED,
                    f"V.G.{ref.name} is not simulated (V.G.BLOCK_NR, FEEDRATE, FEEDRATE_MODE, I, J, K, "
                    "MASS_MM, MASS_360, WZ_AKT.R/.L/.NR, WZR, WZL, ROT_ACTIVE, ROT_ANGLE, ROT_CENTER1/2 "
                    "are): see docs/nc-language.md",
                )
            return value
        raise EvalError(ALARM_EXPRESSION, f"{ref.text} cannot be read")

    def _axis_variable(self, ref: Ref) -> float:
        name = ref.name
        axis: str | None
        if ref.indices:
            if len(ref.indices) != 1:
                raise EvalError(A_INDEX, f"{ref.text}: one axis index")
            index = self._indices(ref)[0]
            axis = self.host.axis_name(int(index)) if index == int(index) else None
            if axis is None:
                raise EvalError(
                    A_INDEX, f"{ref.text}: no axis with index {format_value(index)} in this channel"
                )
            variable = name
        else:
            variable, _, axis = name.rpartition(".")
            if not variable:
                raise EvalError(
                    A_UNDECLARED, f"{ref.text}: write V.A.<variable>.<axis> or V.A.<variable>[index]"
                )
        self._effect()
        value = self.host.axis_value(variable, axis)
        if value is None:
            raise EvalError(
                A_NOT_SIMULATED,
                f"V.A.{variable}.{axis} is not simulated (V.A.ABS, PROG, ACT_POS, -SWE, +SWE, -SWE_MDS, "
                "+SWE_MDS "
                "of the channel's axes are): see docs/nc-language.md",
            )
        return value

    def _cycle_param(self, ref: Ref) -> float:
        frame = self._frames[-1]
        assert ref.number is not None
        index = int(as_number(ref.number.evaluate(self), ref.text))
        if frame.params is None:
            raise EvalError(
                A_CYCLE_PARAMETER,
                f"{ref.text}: cycle parameters are read and written only in a cycle (L CYCLE [..])",
            )
        value = frame.params.get(index)
        if value is None:
            raise EvalError(
                A_UNDECLARED, f"{ref.text} was not given at the cycle's call (test it with EXIST[{ref.text}])"
            )
        return value

    def exists(self, ref: Ref) -> bool:
        kind = ref.kind
        if kind == KIND_MH:
            return True
        if kind in (KIND_P, KIND_PP):
            try:
                p = self._p_number(ref)
            except EvalError:
                return False
            if ref.indices:
                return (p, tuple(int(i) for i in self._indices(ref))) in self._param_arrays
            return p in self._params
        if kind in (KIND_VP, KIND_VL, KIND_VS, KIND_CYC):
            var = self._user_var(ref)
            if var is None:
                return False
            if not ref.indices:
                return True
            try:
                var.flat(self._indices(ref))
            except EvalError:
                return False
            return True
        if kind == KIND_VE:
            return self.host.external.spec(ref.name, self.host.channel_number) is not None
        if kind == KIND_AT_P:
            frame = self._frames[-1]
            assert ref.number is not None
            index = int(as_number(ref.number.evaluate(self), ref.text))
            return frame.params is not None and index in frame.params
        try:
            self.read(ref)
        except EvalError:
            return False
        return True

    def _assign(self, frame: _Frame, stmt: Stmt, ref: Ref, value: Value) -> Callable[[], None] | None:
        """Write ``value`` to ``ref``; returns the action of a synchronous V.E. write (done when the
        path gets there) or None."""
        kind = ref.kind
        if isinstance(value, float) and math.isfinite(value) and not ref.indices:
            # the fast paths of P3 = .. and V.P.NAME = .. (a REAL64 scalar): what the general path does
            if kind == KIND_P and 0 <= ref.fixed < P_COUNT:
                self._params[ref.fixed] = value
                return None
            if kind == KIND_VP:
                var = self._program_vars.get(ref.name)
                if var is not None and not var.dims and var.type_name == "REAL64":
                    var.values[0] = value
                    return None
        try:
            if kind in (KIND_P, KIND_PP):
                p = self._p_number(ref)
                if ref.indices:
                    key = (p, tuple(int(i) for i in self._indices(ref)))
                    self._param_arrays[key] = coerce(value, "REAL64", 0, ref.text)
                else:
                    self._params[p] = (
                        value if isinstance(value, str) else coerce(value, "REAL64", 0, ref.text)
                    )
                return None
            if kind in (KIND_VP, KIND_VL, KIND_VS, KIND_CYC):
                var = self._user_var(ref)
                if var is None and not ref.indices:
                    # a write creates a scalar REAL64 variable (as in the kernel's own example of
                    # ID 21382: N25 V.L.VAR1=10 without #VAR)
                    var = Variable(ref.text, "REAL64", [], 0)
                    self._scope(frame, ref)[ref.name] = var
                if var is None:
                    raise EvalError(
                        A_UNDECLARED,
                        f"{ref.text.split('[')[0]} is not declared: declare it in #VAR .. #ENDVAR "
                        "before writing it",
                    )
                var.set(self._indices(ref), value)
                return None
            if kind == KIND_VE:
                return self._write_external(ref, value)
            if kind == KIND_AT_P:
                if frame.params is None:
                    raise EvalError(
                        A_CYCLE_PARAMETER,
                        f"{ref.text}: cycle parameters are read and written only in a cycle (L CYCLE [..])",
                    )
                assert ref.number is not None
                index = int(as_number(ref.number.evaluate(self), ref.text))
                frame.params[index] = as_number(value, ref.text)
                return None
            if kind == KIND_VG and not ref.indices and ref.name in TOOL_WRITES:
                number = as_number(value, ref.text)
                self._pending.append(ToolWrite(self._place_block(frame, stmt), TOOL_WRITES[ref.name], number))
                return None
            raise EvalError(A_READ_ONLY, f"{ref.text} is read-only")
        except EvalError as exc:
            raise stmt.error(exc.alarm, exc.message) from None

    def _write_external(self, ref: Ref, value: Value) -> Callable[[], None] | None:
        external = self.host.external
        channel = self.host.channel_number
        spec = external.spec(ref.name, channel)
        if spec is None:
            raise EvalError(
                A_UNDECLARED, f"V.E.{ref.name} is not declared in the machine file (external_variables)"
            )
        number = as_number(value, ref.text)
        index = [int(i) if i == int(i) else -1 for i in self._indices(ref)]
        try:
            spec.flat_index(index)
            spec.coerce(number)
        except ExternalVariableError as exc:
            raise EvalError(A_INDEX, str(exc)) from None
        name = ref.name
        if not spec.synchronous:
            self._effect()
            external.write(name, channel, number, index)
            return None

        def write() -> None:
            external.write(name, channel, number, index)

        return write

    # --- #VAR ------------------------------------------------------------------------------------------
    def _declare(self, frame: _Frame, stmt: VarBlock) -> None:
        for declaration in stmt.declarations:
            ref = declaration.ref
            try:
                init = [self._evaluate(stmt, e) for e in declaration.init]
                if ref.kind == KIND_P:
                    assert ref.number is not None
                    p = self._check_p(as_number(ref.number.evaluate(self), ref.text), ref)
                    if declaration.dims:
                        for k, value in enumerate(init):
                            self._param_arrays[(p, (k,))] = as_number(value, ref.text)
                        continue
                    self._params[p] = init[0] if init else 0.0
                    continue
                var = Variable(ref.text, declaration.type_name, declaration.dims, declaration.string_size)
                if init:
                    if len(init) == 1 and not declaration.dims:
                        var.set([], init[0])
                    elif len(init) > len(var.values):
                        raise EvalError(
                            A_DECLARATION,
                            f"{ref.text}: {len(init)} initial values for {len(var.values)} elements",
                        )
                    else:
                        for k, value in enumerate(init):
                            var.values[k] = coerce(value, var.type_name, var.string_size, ref.text)
                scope = self._scope(frame, ref)
                if ref.name in scope:
                    raise EvalError(A_DECLARATION, f"{ref.text} is declared twice (at this program level)")
                scope[ref.name] = var
            except EvalError as exc:
                raise NcError(exc.alarm, declaration.line, stmt.place, exc.message) from None

    def _contour(self, frame: _Frame, stmt: Hash) -> ContourDirective:
        """Checks and evaluates ``#CONTOUR MODE``, ``#HSC``, ``#SPLINE`` (M-20..M-23)."""
        command = stmt.command
        name = {"CONTOUR MODE": "CONTOUR", "HSC": "HSC", "SPLINE": "SPLINE"}[command]
        words, keys = {
            "CONTOUR": (_CONTOUR_WORDS, _CONTOUR_KEYS),
            "HSC": (_HSC_WORDS, _HSC_KEYS),
            "SPLINE": (_SPLINE_WORDS, frozenset[str]()),
        }[name]
        for word in stmt.options:
            if word not in words:
                known = ", ".join(sorted(words | keys))
                raise stmt.error(A_CONTROL_SYNTAX, f"#{command}: unknown word {word!r} (known: {known})")
        for key in stmt.params:
            if key not in keys:
                known = ", ".join(sorted(words | keys)) or "none"
                raise stmt.error(A_CONTROL_SYNTAX, f"#{command}: unknown parameter {key!r} (known: {known})")
        if "ON" in stmt.options and "OFF" in stmt.options:
            raise stmt.error(A_CONTROL_SYNTAX, f"#{command}: ON and OFF in one command")
        on = True if "ON" in stmt.options else False if "OFF" in stmt.options else None
        values: dict[str, float] = {}
        for key, expr in stmt.params.items():
            value = self._number(stmt, expr, f"{key} of #{command}")
            if key in _DEVIATION_KEYS and value < 0.0:
                raise stmt.error(
                    A_CORNER_DEVIATION,
                    f"#{command}: {key}={format_value(value)} is smaller than the least permitted value 0 "
                    "(a corner deviation in mm)",
                )
            if key in ("PRE_DIST", "POST_DIST") and value < 0.0:
                raise stmt.error(A_RANGE, f"#{command}: {key}={format_value(value)} must not be negative")
            if key in _DEVIATION_KEYS | {"PRE_DIST", "POST_DIST"} and value > word_parser._POSITION_MAX:
                raise stmt.error(A_RANGE, f"#{command}: {key} is out of range: {_POSITION_RANGE}")
            values[key] = value
        mode: str | None = None
        if name == "CONTOUR":
            types = [w for w in stmt.options if w in CONTOUR_TYPES]
            if len(types) > 1:
                raise stmt.error(
                    A_CONTROL_SYNTAX, f"#{command}: two contouring types {types[0]} and {types[1]}"
                )
            mode = types[0] if types else None
        elif name == "HSC":
            if "BSPLINE" in stmt.options:
                mode = "BSPLINE"
            elif "OPMODE" in values:
                opmode = values["OPMODE"]
                if opmode not in (1.0, 2.0):
                    raise stmt.error(
                        A_RANGE, f"#HSC: OPMODE {format_value(opmode)}: the operation modes are 1, 2"
                    )
                mode = f"OPMODE {int(opmode)}"
        else:
            for word in ("AKIMA", "BSPLINE"):
                if word in stmt.options:
                    mode = word
            if "TYPE" in stmt.options and mode is None:
                raise stmt.error(A_CONTROL_SYNTAX, "#SPLINE TYPE: AKIMA or BSPLINE expected")
            if mode is not None and "TYPE" not in stmt.options:
                raise stmt.error(A_CONTROL_SYNTAX, f"#SPLINE {mode}: write #SPLINE TYPE {mode}")
            if mode is None and on is None:
                raise stmt.error(A_CONTROL_SYNTAX, "#SPLINE: ON, OFF or TYPE AKIMA|BSPLINE expected")
        return ContourDirective(self._place_block(frame, stmt), name, on, mode, values)

    def _scope(self, frame: _Frame, ref: Ref) -> dict[str, Variable]:
        if ref.kind == KIND_VP:
            return self._program_vars
        if ref.kind == KIND_VS:
            return self._static_vars
        if ref.kind == KIND_CYC:
            if frame.kind != "cycle":
                raise EvalError(A_DECLARATION, f"{ref.text}: V.CYC. variables are declared in cycles only")
            return frame.cycle_vars
        return frame.locals

    # --- # commands ------------------------------------------------------------------------------------
    def _hash(self, frame: _Frame, stmt: Hash) -> None:
        command = stmt.command
        if command == "FLUSH":
            place = self._place_block(frame, stmt)
            if "WAIT" in stmt.options:
                self._pending.append(FlushWait(place))
            elif "CONTINUE" not in stmt.options:
                self._pending.append(FlushStop(place))
            return
        if command == "MEAS MODE":
            meas_type: int | None = None
            if stmt.args:
                value = self._number(stmt, stmt.args[0], "the measuring type of #MEAS MODE")
                if value != int(value) or not 1 <= value <= MEAS_TYPES:
                    raise stmt.error(
                        A_INDEX,
                        f"#MEAS MODE [{format_value(value)}]: the measuring types are 1 .. {MEAS_TYPES}",
                    )
                meas_type = int(value)
            self._pending.append(MeasMode(self._place_block(frame, stmt), meas_type))
            return
        if command == "SLOPE":
            profile: int | None = None
            for option in stmt.options:
                if option.startswith("TYPE="):
                    profile = ("STEP", "TRAPEZ", "SIN2", "HSC").index(option[5:])
            self._pending.append(Slope(self._place_block(frame, stmt), profile))
            return
        if command.startswith(("CS ", "ACS ", "ROTATION ")):
            kind, op = command.split(" ", 1)
            numbers = [self._number(stmt, a, f"a value of #{command}") for a in stmt.args]
            ident: int | None = None
            name: str | None = None
            rotation: dict[str, float] = {}
            if kind == "ROTATION":
                rotation = dict(zip(stmt.options, numbers, strict=True))
                numbers = []
            elif "ID" in stmt.options:
                value = numbers.pop(0)
                if value != int(value) or value < 1:
                    raise stmt.error(
                        A_INDEX, f"#{command} [{format_value(value)}]: the ID is a whole number >= 1"
                    )
                ident = int(value)
            for option in stmt.options:
                if option.startswith("NAME:"):
                    name = option[5:]
            self._pending.append(
                CoordinateCommand(
                    self._place_block(frame, stmt),
                    kind,
                    op,
                    ident,
                    name,
                    tuple(numbers),
                    rotation,
                    all_="ALL" in stmt.options,
                )
            )
            return
        if command == "FILE NAME":
            self._message_file = stmt.files.get("MSG", self._message_file)
            return
        if command in ("CONTOUR MODE", "HSC", "SPLINE"):
            self._pending.append(self._contour(frame, stmt))
            return
        # MSG
        if self._needs_flush(frame, stmt, stmt.args):
            self._flush_wait(frame, stmt)
            return
        values = [self._evaluate(stmt, a) for a in stmt.args]
        text = self._format(stmt, values)
        save = "SAVE" in stmt.options
        file = self._message_file
        host = self.host
        program = frame.program or self.program_name
        line = stmt.first
        label = stmt.place
        if "SYN" in stmt.options or "SYN_ACK" in stmt.options:

            def emit() -> None:
                self._effect()
                host.message(text, save, file, program, line, label)

            self._pending.append(SyncAction(self._place_block(frame, stmt), emit))
            return
        self._effect()
        host.message(text, save, file, program, line, label)

    def _format(self, stmt: Stmt, values: list[Value]) -> str:
        """The message text: the format string's ``%d``, ``%f``, ``%s``, ... filled in (printf, as the
        manual says)."""
        fmt = values[0]
        if not isinstance(fmt, str):
            raise stmt.error(A_MESSAGE, '#MSG: the message text is a string in quotes: #MSG ["text"]')
        args = values[1:]
        out: list[str] = []
        i = 0
        n = len(fmt)
        used = 0
        while i < n:
            c = fmt[i]
            if c != "%":
                out.append(c)
                i += 1
                continue
            j = i + 1
            while j < n and fmt[j] in "-+ #0":
                j += 1
            while j < n and fmt[j].isdigit():
                j += 1
            if j < n and fmt[j] == ".":
                j += 1
                while j < n and fmt[j].isdigit():
                    j += 1
            while j < n and fmt[j] in "lh":
                j += 1
            if j >= n:
                raise stmt.error(A_MESSAGE, f"#MSG: incomplete format {fmt[i:]!r}")
            conversion = fmt[j]
            spec = fmt[i:j].replace("l", "").replace("h", "")
            if conversion == "%":
                out.append("%")
                i = j + 1
                continue
            if conversion not in "diufFeEgGxXos":
                raise stmt.error(A_MESSAGE, f"#MSG: unknown format {fmt[i : j + 1]!r} (%d, %f, %s, ...)")
            if used >= len(args):
                raise stmt.error(
                    A_MESSAGE, f"#MSG: the text has more formats than values ({len(args)} given)"
                )
            value = args[used]
            used += 1
            if len(spec) > 12:
                raise stmt.error(A_MESSAGE, f"#MSG: format {fmt[i : j + 1]!r} too wide")
            try:
                if conversion == "s":
                    out.append((spec + "s") % (value if isinstance(value, str) else format_value(value)))
                elif isinstance(value, str):
                    raise stmt.error(A_MESSAGE, f"#MSG: {fmt[i : j + 1]!r} needs a number, got a string")
                elif conversion in "diuxXo":
                    conv = "d" if conversion in "iu" else conversion
                    out.append((spec + conv) % math.trunc(value))
                else:
                    out.append((spec + conversion) % value)
            except (ValueError, OverflowError) as exc:
                raise stmt.error(A_MESSAGE, f"#MSG: cannot format {format_value(value)}: {exc}") from None
            i = j + 1
        if used < len(args):
            raise stmt.error(A_MESSAGE, f"#MSG: {len(args)} values for {used} format(s) in the text")
        text = "".join(out)
        if len(text) > MAX_MESSAGE:
            raise stmt.error(914020, f"#MSG: the message has {len(text)} characters, at most {MAX_MESSAGE}")
        return text

    # --- calls -----------------------------------------------------------------------------------------
    def _call(self, frame: _Frame, stmt: Stmt, call: Call, place: Block) -> None:
        if len(self._frames) >= MAX_CALL_DEPTH:
            raise stmt.error(
                A_STACK_OVERFLOW,
                f"{call.text}: more than {MAX_CALL_DEPTH} program levels nested (a recursion without end?)",
            )
        params: dict[int, float] | None = None
        if call.cycle:
            params = {k: self._number(stmt, v, f"@P{k}") for k, v in call.params}
        if call.local:
            units = frame.units
            start = units.local(call.name)
            if start is None:
                raise stmt.error(
                    A_NOT_FOUND,
                    f"local subroutine {call.name} not found: no %L {call.name} in {units.text.name}",
                )
            kind = "cycle" if call.cycle else "local"
            new = _Frame(kind, units, call.name, start, place)
        else:
            found = self.host.find_program(call.name)
            if found is None:
                searched = self.host.searched()
                where = ", ".join(searched) if searched else "no program directory is configured"
                raise stmt.error(
                    A_NOT_FOUND,
                    f"{'cycle' if call.cycle else 'global subroutine'} {call.name} not found; searched: "
                    f"{where}{_OUTSIDE if _leaves_directories(call.name) else ''}",
                )
            units = self._global_units(found.name, found.text)
            kind = "cycle" if call.cycle else "global"
            new = _Frame(kind, units, found.name, units.main(), place)
        new.params = params
        self._frames.append(new)

    def _global_units(self, name: str, text: str) -> _Units:
        """The units of global subprogram ``name``: those of an earlier call while its text is the same
        (the file may have changed on disk or been uploaded again between two calls)."""
        key = name.upper()
        units = self._globals.get(key)
        if units is None or units.source != text:
            if len(self._globals) >= _GLOBAL_UNITS:
                self._globals.clear()
            units = _Units(ProgramText(text, name), self.compiler, text)
            self._globals[key] = units
        return units

    def _return(self, frame: _Frame) -> None:
        self._frames.pop()
        if not self._frames:  # pragma: no cover - the main program never returns
            self._ended = True

    def _unit_end(self, frame: _Frame, stmt: Stmt | None) -> None:
        """The end of a unit's text (or the next ``%`` header)."""
        place_line = frame.line
        place = f"line {place_line}"
        if frame.seek is not None and frame.seek.mode == _SEEK_LABEL:
            self._label_wrap(frame)
            return
        if frame.seek is not None:
            top = frame.open[-1] if frame.open else None
            alarm = {"main": A_OPEN_INVALID_MAIN, "local": A_OPEN_INVALID_LOCAL}.get(
                frame.kind, A_OPEN_INVALID_GLOBAL
            )
            keyword = top.keyword if top is not None else "?"
            raise NcError(
                alarm,
                place_line,
                place,
                f"{len(frame.open)} control block(s) not closed at the end of {frame.kind} program "
                f"{frame.name}: ${keyword}{f' of line {top.start}' if top else ''} has no "
                f"${_END_OF.get(keyword, keyword)} (its branch was not run)",
                {
                    "open": len(frame.open),
                    "keyword": f"${keyword}",
                    "expected": f"${_END_OF.get(keyword, keyword)}",
                },
            )
        self._warn_open(frame, place_line, place)
        if frame.kind == "main":
            self._ended = True
            return
        self._return(frame)

    # --- control flow ----------------------------------------------------------------------------------
    def _truth(self, stmt: Stmt, expr: Expr, what: str) -> bool:
        return self._number(stmt, expr, what) != 0.0

    def _push(self, frame: _Frame, stmt: Control, entry: _Open) -> None:
        if len(frame.open) >= MAX_OPEN_BLOCKS:
            raise stmt.error(A_NESTING, f"more than {MAX_OPEN_BLOCKS} control blocks nested")
        frame.open.append(entry)

    def _top(self, frame: _Frame, stmt: Control, want: str) -> _Open:
        if not frame.open or frame.open[-1].keyword != want:
            raise self._unexpected(frame, stmt)
        return frame.open[-1]

    def _fits(self, frame: _Frame, keyword: str) -> bool:
        """Could ``keyword`` run here: its block is the innermost open one (or, for $BREAK and
        $CONTINUE, a loop or $SWITCH is open)?"""
        if keyword in (C_BREAK, C_CONTINUE):
            kinds = _LOOPS | {C_SWITCH} if keyword == C_BREAK else _LOOPS
            return any(entry.keyword in kinds for entry in frame.open)
        want = _CLOSING.get(keyword) or _MIDDLE.get(keyword)
        return bool(frame.open) and frame.open[-1].keyword == want

    def _unexpected(self, frame: _Frame, stmt: Control) -> NcError:
        return self._unexpected_word(frame, stmt, stmt.keyword)

    def _unexpected_word(self, frame: _Frame, stmt: Stmt, keyword: str) -> NcError:
        current = frame.open[-1] if frame.open else None
        shown = keyword if keyword.startswith("#") else f"${keyword}"
        where = (
            f"the open block is ${current.keyword} of line {current.start}"
            if current is not None
            else "no control block is open"
        )
        return stmt.error(A_UNEXPECTED[keyword], f"unexpected {shown}: {where}")

    def _control(self, frame: _Frame, stmt: Control) -> None:
        keyword = stmt.keyword
        if self._needs_flush(frame, stmt, stmt.exprs):
            self._flush_wait(frame, stmt)
            return
        if keyword == C_IF:
            condition = self._truth(stmt, stmt.exprs[0], "$IF")
            if stmt.goto is not None:
                if condition:
                    self._goto(frame, stmt, stmt.goto)
                return
            entry = _Open(C_IF, stmt.first, stmt.last + 1)
            entry.taken = condition
            self._push(frame, stmt, entry)
            if not condition:
                frame.seek = _Seek(_SEEK_BRANCH, 0, stmt.first)
            return
        if keyword in (C_ELSEIF, C_ELSE):
            self._top(frame, stmt, C_IF)
            frame.seek = _Seek(_SEEK_END, 0, stmt.first)
            return
        if keyword == C_ENDIF:
            self._top(frame, stmt, C_IF)
            frame.open.pop()
            return
        if keyword == C_SWITCH:
            entry = _Open(C_SWITCH, stmt.first, stmt.last + 1)
            entry.value = self._evaluate(stmt, stmt.exprs[0])
            self._push(frame, stmt, entry)
            frame.seek = _Seek(_SEEK_CASE, 0, stmt.first)
            return
        if keyword in (C_CASE, C_DEFAULT):
            self._top(frame, stmt, C_SWITCH)  # reached by falling through: go on
            return
        if keyword == C_ENDSWITCH:
            self._top(frame, stmt, C_SWITCH)
            frame.open.pop()
            return
        if keyword == C_WHILE:
            if self._truth(stmt, stmt.exprs[0], "$WHILE"):
                self._push(frame, stmt, _Open(C_WHILE, stmt.first, stmt.last + 1))
            else:
                self._push(frame, stmt, _Open(C_WHILE, stmt.first, stmt.last + 1))
                frame.seek = _Seek(_SEEK_END, 0, stmt.first)
            return
        if keyword == C_ENDWHILE:
            entry = self._top(frame, stmt, C_WHILE)
            frame.open.pop()
            self._iterate(frame, stmt)
            frame.line = entry.start
            return
        if keyword in (C_DO, C_REPEAT):
            self._push(frame, stmt, _Open(keyword, stmt.first, stmt.last + 1))
            return
        if keyword in (C_ENDDO, C_UNTIL):
            entry = self._top(frame, stmt, C_DO if keyword == C_ENDDO else C_REPEAT)
            condition = self._truth(stmt, stmt.exprs[0], f"${keyword}")
            if condition == (keyword == C_ENDDO):
                self._iterate(frame, stmt)
                frame.line = entry.body
            else:
                frame.open.pop()
            return
        if keyword == C_FOR:
            self._for(frame, stmt)
            return
        if keyword == C_ENDFOR:
            entry = self._top(frame, stmt, C_FOR)
            if not entry.valid or entry.target is None:
                raise stmt.error(A_CONTROL, "$ENDFOR of a $FOR loop entered by a jump: its range is unknown")
            value = self._number(stmt, entry.target, "$FOR's counter") + entry.step
            self._assign(frame, stmt, entry.target, value)
            end = as_number(entry.value, "$FOR")
            if (entry.step > 0 and value <= end) or (entry.step < 0 and value >= end):
                self._iterate(frame, stmt)
                frame.line = entry.body
            else:
                frame.open.pop()
            return
        if keyword in (C_BREAK, C_CONTINUE):
            self._break(frame, stmt)
            return
        if keyword == C_HASH_IF:
            entry = _Open(C_HASH_IF, stmt.first, stmt.last + 1)
            entry.taken = self._truth(stmt, stmt.exprs[0], "#IF")
            self._push(frame, stmt, entry)
            if not entry.taken:
                frame.seek = _Seek(_SEEK_HASH, 0, stmt.first)
            return
        if keyword == C_HASH_ELSE:
            self._top(frame, stmt, C_HASH_IF)
            frame.seek = _Seek(_SEEK_HASH_END, 0, stmt.first)
            return
        if keyword == C_HASH_ENDIF:
            self._top(frame, stmt, C_HASH_IF)
            frame.open.pop()
            return
        raise stmt.error(A_CONTROL, f"${keyword} cannot run here")  # pragma: no cover

    def _for(self, frame: _Frame, stmt: Control) -> None:
        start = self._number(stmt, stmt.exprs[0], "$FOR's start")
        end = self._number(stmt, stmt.exprs[1], "$FOR's end")
        step = self._number(stmt, stmt.exprs[2], "$FOR's step") if len(stmt.exprs) > 2 else 1.0
        if step == 0.0:
            raise stmt.error(A_STEP, "$FOR with step 0: the loop would never end")
        if not (math.isfinite(start) and math.isfinite(end) and math.isfinite(step)):
            raise stmt.error(ALARM_DOMAIN, "$FOR's start, end and step must be finite numbers")
        assert stmt.target is not None
        self._assign(frame, stmt, stmt.target, start)
        entry = _Open(C_FOR, stmt.first, stmt.last + 1)
        entry.value = end
        entry.step = step
        entry.target = stmt.target
        self._push(frame, stmt, entry)
        if (step > 0 and start > end) or (step < 0 and start < end):
            frame.seek = _Seek(_SEEK_END, 0, stmt.first)

    def _iterate(self, frame: _Frame, stmt: Stmt) -> None:
        self.iterations += 1
        cap = self.iteration_cap
        if cap is not None and self.iterations > cap:
            raise IterationCapError(cap, stmt.first, stmt.place)

    def _break(self, frame: _Frame, stmt: Control) -> None:
        """$BREAK leaves the innermost loop or $SWITCH, $CONTINUE goes to the innermost loop's end."""
        keyword = stmt.keyword
        kinds = _LOOPS | {C_SWITCH} if keyword == C_BREAK else _LOOPS
        inner = 0
        for entry in reversed(frame.open):
            if entry.keyword in kinds:
                break
            inner += 1
        else:
            raise stmt.error(
                A_UNEXPECTED[keyword],
                f"unexpected ${keyword}: no {'loop or $SWITCH' if keyword == C_BREAK else 'loop'} is open",
            )
        del frame.open[len(frame.open) - inner :]
        frame.seek = _Seek(_SEEK_END if keyword == C_BREAK else _SEEK_CONTINUE, inner, stmt.first)

    def _goto(self, frame: _Frame, stmt: Stmt, goto: Goto) -> None:
        if goto.target is not None:
            label = goto.target
        else:
            assert goto.number is not None
            value = self._number(stmt, goto.number, "$GOTO N..")
            if value != int(value) or value < 0:
                raise stmt.error(20839, f"$GOTO N{format_value(value)}: a block number is a whole number")
            label = f"N{int(value)}"
        frame.seek = _Seek(_SEEK_LABEL, 0, stmt.first, label)

    def _label_wrap(self, frame: _Frame) -> None:
        """A $GOTO's label was not found after the jump: search from the unit's start (a jump back)."""
        seek = frame.seek
        assert seek is not None
        if seek.wrapped:
            raise NcError(
                A_LABEL,
                seek.origin,
                f"line {seek.origin}",
                f"$GOTO {seek.label}: no jump label "
                f"{seek.label}{':' if seek.label.startswith('N') else ''} in "
                f"{frame.kind} program {frame.name}"
                + (
                    " (a block N.. is a jump target only with ':', N10:)"
                    if seek.label.startswith("N")
                    else ""
                ),
            )
        seek.wrapped = True
        seek.pending = []
        frame.line = frame.start

    # --- skipping --------------------------------------------------------------------------------------
    def _seek(self, frame: _Frame, stmt: Stmt) -> None:
        """Skip ``stmt`` while looking for where the program goes on (the frame's seek)."""
        seek = frame.seek
        assert seek is not None
        frame.line = stmt.last + 1
        mode = seek.mode
        if mode == _SEEK_LABEL:
            self._seek_label(frame, seek, stmt)
            return
        if isinstance(stmt, Refused) and stmt.keyword:
            raise stmt.failure  # a malformed control statement: the structure cannot be followed
        if not isinstance(stmt, Control):
            return
        keyword = stmt.keyword
        if mode in (_SEEK_HASH, _SEEK_HASH_END):
            if keyword == C_HASH_IF:
                seek.depth += 1
            elif keyword == C_HASH_ENDIF:
                if seek.depth == 0:
                    frame.open.pop()
                    frame.seek = None
                else:
                    seek.depth -= 1
            elif keyword == C_HASH_ELSE and seek.depth == 0 and mode == _SEEK_HASH:
                frame.open[-1].taken = True
                frame.seek = None
            return
        if keyword in _OPENING:
            if keyword == C_IF and stmt.goto is not None:
                return
            seek.depth += 1
            return
        closing = _CLOSING.get(keyword)
        if closing is not None:
            if seek.depth > 0:
                seek.depth -= 1
                return
            entry = frame.open[-1] if frame.open else None
            if entry is None or entry.keyword != closing:
                raise self._unexpected(frame, stmt)
            if mode == _SEEK_CONTINUE:
                frame.seek = None
                frame.line = stmt.first  # the loop's closing statement runs
                return
            if mode == _SEEK_CASE and entry.default >= 0:
                frame.seek = None
                frame.line = entry.default  # no $CASE matched: on after $DEFAULT
                return
            frame.open.pop()
            frame.seek = None
            return
        if seek.depth > 0:
            return
        top = frame.open[-1] if frame.open else None
        if mode == _SEEK_BRANCH:
            if keyword == C_ELSEIF:
                assert top is not None
                if self._truth(stmt, stmt.exprs[0], "$ELSEIF"):
                    top.taken = True
                    frame.seek = None
            elif keyword == C_ELSE:
                top_taken = top.taken if top is not None else False
                if not top_taken:
                    assert top is not None
                    top.taken = True
                    frame.seek = None
        elif mode == _SEEK_CASE:
            assert top is not None
            if keyword == C_CASE:
                for expr in stmt.exprs:
                    value = self._evaluate(stmt, expr)
                    if isinstance(value, str) != isinstance(top.value, str):
                        raise stmt.error(
                            ALARM_TYPE,
                            f"$CASE {format_value(value)}: the $SWITCH value is {format_value(top.value)}",
                        )
                    if value == top.value:
                        frame.seek = None
                        return
            elif keyword == C_DEFAULT:
                top.default = stmt.last + 1

    def _seek_label(self, frame: _Frame, seek: _Seek, stmt: Stmt) -> None:
        if stmt.label == seek.label:
            if seek.wrapped:
                # a jump back: the blocks opened at or after the label are left
                while frame.open and frame.open[-1].start >= stmt.first:
                    frame.open.pop()
                self._iterate(frame, stmt)
            else:
                frame.open.extend(seek.pending)
            frame.seek = None
            frame.line = stmt.first
            self._run_label_block(frame, stmt)
            return
        if seek.wrapped or not isinstance(stmt, Control):
            return
        keyword = stmt.keyword
        if keyword in _OPENING and not (keyword == C_IF and stmt.goto is not None):
            entry = _Open(keyword, stmt.first, stmt.last + 1)
            entry.taken = True
            entry.valid = keyword != C_FOR
            seek.pending.append(entry)
            return
        closing = _CLOSING.get(keyword)
        if closing is not None:
            if seek.pending:
                seek.pending.pop()
            elif frame.open and frame.open[-1].keyword == closing:
                frame.open.pop()  # the jump leaves this block

    def _run_label_block(self, frame: _Frame, stmt: Stmt) -> None:
        """The labelled block is where the program goes on: it runs next (``frame.line`` is on it)."""
        return

    # --- (end of seek) ---------------------------------------------------------------------------------


def _round_half_away(value: float) -> int:
    if not math.isfinite(value):
        return -1
    return math.floor(value + 0.5) if value >= 0 else -math.floor(-value + 0.5)
