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

The interpreter is built in layers, one class each, each on the one before (one chain, as mypyc compiles
it, no indirection per statement):

* ``nc/state.py`` (:class:`~hli_server.engine.nc.state.InterpreterState`): the state, evaluation,
  ``#FLUSH WAIT`` before a synchronous read, the hand-back to the batch geometry check;
* ``nc/variable_access.py``: ``P``, ``V.P.``/``V.L.``/``V.S.``/``V.CYC.``, ``V.E.``, ``V.A.``, ``V.G.``,
  ``@P``, ``#VAR``;
* ``nc/effects.py``: the ``#`` commands (``#MSG``, ``#FILE NAME``, the directives);
* ``nc/control_flow.py``: ``$IF`` .. ``$ENDFOR``, ``$GOTO``, ``#IF``, and skipping;
* ``nc/calls.py``: program levels (``L``, ``LL``, ``L CYCLE``; ``nc/levels.py`` finds the program a call
  names), M17/M29/M30/M02;
* ``nc/implicit.py``: the implicit calls G80..G89 / G800..G839 (the program their channel parameter or
  ``#FILE NAME [G8xx=..]`` assigns);
* here: the loop that hands out blocks and directives, and the blocks of words.

Work per cycle is bounded (docs/check.md, "Bad input"): every statement run or skipped spends one unit of
the budget that :meth:`Interpreter.refill` sets each cycle; a program that computes without moving
goes on in the next cycle instead of stalling the clock. A geometry check, which has no cycles, caps
loop iterations instead (:class:`IterationCapError`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TextIO

from hli_server.engine.nc.block_builder import build_block
from hli_server.engine.nc.blocks import Block, NcError
from hli_server.engine.nc.directives import (
    PAUSE,
    Directive,
    Realtime,
    SyncAction,
)
from hli_server.engine.nc.expr import (
    ALARM_EXPRESSION,
    EvalError,
)
from hli_server.engine.nc.implicit import ImplicitCalls
from hli_server.engine.nc.language import (
    A_CONTROL_SYNTAX,
    A_UNEXPECTED,
    CORNER_AHEAD,
    CORNER_LOOK_AHEAD,
    CORNER_PASSES,
)
from hli_server.engine.nc.levels import (
    Frame,
    Units,
)
from hli_server.engine.nc.reader import strip_comments
from hli_server.engine.nc.rt_cycles import check_body
from hli_server.engine.nc.source import LineTooLongError, ProgramText
from hli_server.engine.nc.state import STATEMENTS_PER_CYCLE
from hli_server.engine.nc.statements import (
    Assign,
    ConstBlock,
    Control,
    Empty,
    Hash,
    Header,
    Refused,
    Stmt,
    Technology,
    VarBlock,
    Word,
    Words,
    word_expressions,
)
from hli_server.engine.nc.waiting import WaitingLoop, state_of, waiting_loop

__all__ = ["STATEMENTS_PER_CYCLE", "Interpreter"]


class Interpreter(ImplicitCalls):
    """Runs programs for one channel (see the module's description).

    ``budget`` is the statements per cycle (None: unbounded, for a geometry check); ``iteration_cap``
    bounds loop iterations and backward jumps (None: unbounded, for a running machine)."""

    # --- program control -------------------------------------------------------------------------------
    def start(self, text: str | TextIO | ProgramText, name: str = "program") -> None:
        """Start the main program ``text`` (P parameters and V.P. variables start empty)."""
        source = text if isinstance(text, ProgramText) else ProgramText(text, name)
        units = Units(source, self.compiler)
        self.program_name = name
        self._frames = [Frame("main", units, name, units.main(), None)]
        self._pending.clear()
        self._ended = False
        self._params = {}
        self._param_arrays = {}
        self._program_vars = {}
        self._message_file = "message.txt"
        self._approximated.clear()
        self._rt_body = None
        self._rt_define = None
        self._rt_block_scope.clear()
        self._implicit_names = {}
        self.iterations = 0
        self.statements = 0
        self._left = self.budget if self.budget is not None else 0
        self._resolver.clear()

    def reset(self) -> None:
        """Channel reset: the program is gone; V.S. variables stay."""
        self._frames = []
        self._pending.clear()
        self._ended = True

    def corner_ahead(self, block: Block) -> bool:
        """Does the next line of ``block``'s program (past blank, comment, control and ``#`` command lines)
        ask for a chamfer or rounding (G301/G302)? The decoder then holds the block's motion back for it: the
        kernel's decoder reads ahead; this one is asked for one block at a time."""
        if not self._frames:
            return False
        frame = self._frames[-1]
        if frame.program != block.program:
            return False
        text = frame.units.text
        for k in range(block.line + 1, block.line + 1 + CORNER_LOOK_AHEAD):
            try:
                raw = text.line(k)
            except LineTooLongError:
                return False
            if raw is None:
                return False
            if "30" not in raw and "$" not in raw and "#" not in raw and "(" not in raw and ";" not in raw:
                if raw.strip():
                    return False  # a line of words without a G30x (nearly every line): the fast answer
                continue
            code = strip_comments(raw)
            if code.strip() and CORNER_PASSES.match(code) is None:
                return "30" in code and CORNER_AHEAD.search(code.upper()) is not None
        return False

    def state(self) -> tuple[object, ...]:
        """The variables' values, comparable (``nc/waiting.py``): a loop that turns while they stay the
        same, with nothing moving or emitted, cannot end."""
        return state_of(self._frames, self._params, self._param_arrays, self._program_vars, self._static_vars)

    def waiting_loop(self) -> WaitingLoop | None:
        """The loop the program turns in now and the ``V.E.`` variables it reads (``nc/waiting.py``)."""
        return waiting_loop(self._frames, self.host.external, self.host.channel_number)

    def refill(self) -> None:
        """A new cycle: a new budget."""
        if self.budget is not None:
            self._left = self.budget

    # --- the loop --------------------------------------------------------------------------------------
    def next(self) -> Block | Directive | None:
        """The next block or directive; None at the end of the main program's text."""
        pending = self._pending
        out: Block | Directive | None
        if pending:
            out = pending.popleft()
        elif self._ended:
            return None
        else:
            try:
                out = self._run()
            except NcError as exc:
                self._ended = True
                frame = self._frames[-1] if self._frames else None
                if frame is not None and frame.program and not exc.program:
                    exc.program = frame.program
                raise
            except EvalError as eval_error:  # pragma: no cover - every evaluation is inside a statement
                self._ended = True
                raise NcError(eval_error.alarm, 0, "line 0", eval_error.message) from None
        if self._rt_block_scope and isinstance(out, Block) and out.axes:
            self._rt_after_block(out)
        return out

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
            if frame.standin is not None:
                # a built-in cycle reads the decoder's state: the batch check decodes what it kept first
                self._effect()
                block = next(frame.standin, None)
                if block is None:
                    frame.returning = True
                    continue
                return block
            stmt = frame.units.statement(frame.line, frame.program, frame.keep or bool(frame.open))
            if self._rt_body is not None:
                self._rt_collect(frame, stmt)
                if pending:
                    return pending.popleft()
                continue
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

    # --- realtime cycles (#RT CYCLE, TF5261) ------------------------------------------------------------
    def _rt_collect(self, frame: Frame, stmt: Stmt | Block | None) -> None:
        """A statement between ``#RT CYCLE`` and ``#RT CYCLE END``: kept for the cycle, not run. A block of
        M/H functions only is accepted (no effect); motion in a realtime cycle is refused by name."""
        body = self._rt_body
        definition = self._rt_define
        assert body is not None
        assert definition is not None
        if stmt is None or isinstance(stmt, Header):
            raise NcError(
                A_CONTROL_SYNTAX, frame.line, f"line {frame.line}", "#RT CYCLE without its #RT CYCLE END"
            )
        if isinstance(stmt, (Block, ConstBlock)):
            block = stmt if isinstance(stmt, Block) else stmt.block
            frame.line = block.line + 1 if isinstance(stmt, Block) else stmt.last + 1
            if (
                block.axes
                or block.centre
                or block.feed is not None
                or block.g_codes
                or block.area is not None
            ):
                raise NcError(
                    910110,
                    block.line,
                    block.label,
                    f"{block.text.strip()!r}: motion in a realtime cycle (an independent axis motion) is not "
                    "simulated: docs/nc-language.md",
                )
            return
        frame.line = stmt.last + 1
        if isinstance(stmt, Refused):
            raise stmt.failure
        if isinstance(stmt, Hash) and stmt.command == "RT CYCLE" and "END" in stmt.options:
            self._rt_body = None
            self._rt_define = None
            error = check_body(body, stmt.place)
            if error is not None:
                raise error
            definition.body = body
            self._pending.append(definition)
            if definition.scope == "BLOCK":
                self._rt_block_scope[definition.ident] = not definition.start
            return
        body.append(stmt)

    def _rt_after_block(self, block: Block) -> None:
        """A motion block was handed out: the realtime cycles valid for it (SCOPE=BLOCK) end after it."""
        for ident, defined in list(self._rt_block_scope.items()):
            self._pending.appendleft(Realtime(block, "HOLD" if defined else "DELETE", ident))
            if not defined:
                del self._rt_block_scope[ident]

    # --- statements ------------------------------------------------------------------------------------
    def _execute(self, frame: Frame, stmt: Stmt) -> None:
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

    def _words(self, frame: Frame, stmt: Words) -> None:
        if stmt.sync_reads != 0 and self._needs_flush(frame, stmt, word_expressions(stmt)):
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
            elif isinstance(item, Technology):
                self._technology(stmt, item, words)
        if any(w.letter == "E" for w, _, _ in words):
            words = [w for w in words if w[0].letter != "E"]
            self._approximation(
                stmt,
                "E",
                "E (the feed at the block's end) is not simulated: the path keeps the block's F up to the "
                "look-ahead's braking; only the velocity near the block's end differs, not the path "
                "(docs/nc-language.md)",
            )
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
            if (frame.returning or self._ended) and (
                stmt.call is not None or stmt.goto is not None or stmt.implicit is not None
            ):
                raise stmt.error(
                    A_CONTROL_SYNTAX, "a block that ends the program or subroutine calls or jumps"
                )
        if stmt.call is not None:
            place = block if block is not None else self._place_block(frame, stmt)
            self._call(frame, stmt, stmt.call, place)
        elif stmt.implicit is not None:
            place = block if block is not None else self._place_block(frame, stmt)
            self._implicit_call(frame, stmt, stmt.implicit, place)
        elif stmt.goto is not None:
            self._goto(frame, stmt, stmt.goto)

    def _technology(
        self, stmt: Stmt, item: Technology, words: list[tuple[Word, float, float | None]]
    ) -> None:
        """``S[M3 REV500 ..]``, ``S1[MC_MoveVelocity ..]`` (PM 208178187, 208317067): the main spindle's
        M3/M4/M5 and REV are the block's words; the rest is evaluated (its errors are the block's) and
        accepted without effect, said once per program and spindle (warning 911041)."""
        for word in item.main:
            words.append((word, self._number(stmt, word.value, word.text), None))
        for expr in item.params.values():
            self._evaluate(stmt, expr)
        if item.words:
            self._approximation(
                stmt,
                f"spindle {item.target}",
                f"{item.target}[{' '.join(item.words)}]: spindle-specific commands are accepted without "
                "effect (no spindle is simulated but the main spindle's speed for G95; spindles are not "
                "monitored): docs/nc-language.md",
            )

    # --- the block for the decoder ---------------------------------------------------------------------
    def _build(self, frame: Frame, stmt: Stmt, words: list[tuple[Word, float, float | None]]) -> Block:
        return build_block(stmt.text, stmt.first, stmt.number, words, frame.program)
