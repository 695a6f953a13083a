"""Control flow (N-06): the interpreter's layer that decides where a program goes on - the control blocks
open in a program level, their branches and loops, ``$GOTO``'s labels, and the statements skipped on the
way. Which control word closes which is ``nc/language.py``'s (``CLOSING``, ``MIDDLE``, ``LOOPS``).
"""

from __future__ import annotations

import math

from hli_server.engine.nc.blocks import NcError
from hli_server.engine.nc.effects import Effects
from hli_server.engine.nc.expr import (
    ALARM_DOMAIN,
    ALARM_TYPE,
    Expr,
    as_number,
    format_value,
)
from hli_server.engine.nc.language import (
    A_CONTROL_SYNTAX,
    A_LABEL,
    A_NESTING,
    A_STEP,
    A_UNEXPECTED,
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
    CLOSING,
    LOOPS,
    MAX_OPEN_BLOCKS,
    MIDDLE,
    OPENING,
)
from hli_server.engine.nc.levels import (
    SEEK_BRANCH,
    SEEK_CASE,
    SEEK_CONTINUE,
    SEEK_END,
    SEEK_HASH,
    SEEK_HASH_END,
    SEEK_LABEL,
    Frame,
    OpenBlock,
    Seek,
)
from hli_server.engine.nc.statements import (
    Control,
    Goto,
    Refused,
    Stmt,
)

__all__ = ["ControlFlow"]


class ControlFlow(Effects):
    """Runs the control statements (N-06): ``$IF``/``$ELSEIF``/``$ELSE``, ``$SWITCH``/``$CASE``/
    ``$DEFAULT``, ``$WHILE``, ``$DO``/``$ENDDO``, ``$REPEAT``/``$UNTIL``, ``$FOR``, ``$BREAK``/``$CONTINUE``,
    ``$GOTO`` and ``#IF``/``#ELSE``/``#ENDIF``; and skips what a false branch, a finished loop or a jump
    passes over (:meth:`_seek`)."""

    # --- control flow ----------------------------------------------------------------------------------
    def _truth(self, stmt: Stmt, expr: Expr, what: str) -> bool:
        return self._number(stmt, expr, what) != 0.0

    def _push(self, frame: Frame, stmt: Control, entry: OpenBlock) -> None:
        if len(frame.open) >= MAX_OPEN_BLOCKS:
            raise stmt.error(A_NESTING, f"more than {MAX_OPEN_BLOCKS} control blocks nested")
        frame.open.append(entry)

    def _top(self, frame: Frame, stmt: Control, want: str) -> OpenBlock:
        if not frame.open or frame.open[-1].keyword != want:
            raise self._unexpected(frame, stmt)
        return frame.open[-1]

    def _fits(self, frame: Frame, keyword: str) -> bool:
        """Could ``keyword`` run here: its block is the innermost open one (or, for $BREAK and
        $CONTINUE, a loop or $SWITCH is open)?"""
        if keyword in (C_BREAK, C_CONTINUE):
            kinds = LOOPS | {C_SWITCH} if keyword == C_BREAK else LOOPS
            return any(entry.keyword in kinds for entry in frame.open)
        want = CLOSING.get(keyword) or MIDDLE.get(keyword)
        return bool(frame.open) and frame.open[-1].keyword == want

    def _unexpected(self, frame: Frame, stmt: Control) -> NcError:
        return self._unexpected_word(frame, stmt, stmt.keyword)

    def _unexpected_word(self, frame: Frame, stmt: Stmt, keyword: str) -> NcError:
        current = frame.open[-1] if frame.open else None
        shown = keyword if keyword.startswith("#") else f"${keyword}"
        where = (
            f"the open block is ${current.keyword} of line {current.start}"
            if current is not None
            else "no control block is open"
        )
        return stmt.error(A_UNEXPECTED[keyword], f"unexpected {shown}: {where}")

    def _control(self, frame: Frame, stmt: Control) -> None:
        keyword = stmt.keyword
        if self._needs_flush(frame, stmt, stmt.exprs):
            self._flush_wait(frame, stmt)
            return
        if keyword == C_IF:
            if stmt.frequency:
                raise stmt.error(
                    A_CONTROL_SYNTAX,
                    f"$IF {stmt.frequency}: the qualifiers ONCE, EDGE, ALWAYS belong to an $IF of a realtime "
                    "cycle (#RT CYCLE .. #RT CYCLE END)",
                )
            condition = self._truth(stmt, stmt.exprs[0], "$IF")
            if stmt.goto is not None:
                if condition:
                    self._goto(frame, stmt, stmt.goto)
                return
            entry = OpenBlock(C_IF, stmt.first, stmt.last + 1)
            entry.taken = condition
            self._push(frame, stmt, entry)
            if not condition:
                frame.seek = Seek(SEEK_BRANCH, 0, stmt.first)
            return
        if keyword in (C_ELSEIF, C_ELSE):
            self._top(frame, stmt, C_IF)
            frame.seek = Seek(SEEK_END, 0, stmt.first)
            return
        if keyword == C_ENDIF:
            self._top(frame, stmt, C_IF)
            frame.open.pop()
            return
        if keyword == C_SWITCH:
            entry = OpenBlock(C_SWITCH, stmt.first, stmt.last + 1)
            entry.value = self._evaluate(stmt, stmt.exprs[0])
            self._push(frame, stmt, entry)
            frame.seek = Seek(SEEK_CASE, 0, stmt.first)
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
                self._push(frame, stmt, OpenBlock(C_WHILE, stmt.first, stmt.last + 1))
            else:
                self._push(frame, stmt, OpenBlock(C_WHILE, stmt.first, stmt.last + 1))
                frame.seek = Seek(SEEK_END, 0, stmt.first)
            return
        if keyword == C_ENDWHILE:
            entry = self._top(frame, stmt, C_WHILE)
            self._iterate(frame, stmt)  # the loop still open if the cap stops it here (nc/waiting.py)
            frame.open.pop()
            frame.line = entry.start
            return
        if keyword in (C_DO, C_REPEAT):
            self._push(frame, stmt, OpenBlock(keyword, stmt.first, stmt.last + 1))
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
                raise stmt.error(
                    A_CONTROL_SYNTAX, "$ENDFOR of a $FOR loop entered by a jump: its range is unknown"
                )
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
            entry = OpenBlock(C_HASH_IF, stmt.first, stmt.last + 1)
            entry.taken = self._truth(stmt, stmt.exprs[0], "#IF")
            self._push(frame, stmt, entry)
            if not entry.taken:
                frame.seek = Seek(SEEK_HASH, 0, stmt.first)
            return
        if keyword == C_HASH_ELSE:
            self._top(frame, stmt, C_HASH_IF)
            frame.seek = Seek(SEEK_HASH_END, 0, stmt.first)
            return
        if keyword == C_HASH_ENDIF:
            self._top(frame, stmt, C_HASH_IF)
            frame.open.pop()
            return
        raise stmt.error(A_CONTROL_SYNTAX, f"${keyword} cannot run here")  # pragma: no cover

    def _for(self, frame: Frame, stmt: Control) -> None:
        start = self._number(stmt, stmt.exprs[0], "$FOR's start")
        end = self._number(stmt, stmt.exprs[1], "$FOR's end")
        step = self._number(stmt, stmt.exprs[2], "$FOR's step") if len(stmt.exprs) > 2 else 1.0
        if step == 0.0:
            raise stmt.error(A_STEP, "$FOR with step 0: the loop would never end")
        if not (math.isfinite(start) and math.isfinite(end) and math.isfinite(step)):
            raise stmt.error(ALARM_DOMAIN, "$FOR's start, end and step must be finite numbers")
        assert stmt.target is not None
        self._assign(frame, stmt, stmt.target, start)
        entry = OpenBlock(C_FOR, stmt.first, stmt.last + 1)
        entry.value = end
        entry.step = step
        entry.target = stmt.target
        self._push(frame, stmt, entry)
        if (step > 0 and start > end) or (step < 0 and start < end):
            frame.seek = Seek(SEEK_END, 0, stmt.first)

    def _break(self, frame: Frame, stmt: Control) -> None:
        """$BREAK leaves the innermost loop or $SWITCH, $CONTINUE goes to the innermost loop's end."""
        keyword = stmt.keyword
        kinds = LOOPS | {C_SWITCH} if keyword == C_BREAK else LOOPS
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
        frame.seek = Seek(SEEK_END if keyword == C_BREAK else SEEK_CONTINUE, inner, stmt.first)

    def _goto(self, frame: Frame, stmt: Stmt, goto: Goto) -> None:
        if goto.target is not None:
            label = goto.target
        else:
            assert goto.number is not None
            value = self._number(stmt, goto.number, "$GOTO N..")
            if value != int(value) or value < 0:
                raise stmt.error(20839, f"$GOTO N{format_value(value)}: a block number is a whole number")
            label = f"N{int(value)}"
        frame.seek = Seek(SEEK_LABEL, 0, stmt.first, label)

    def _label_wrap(self, frame: Frame) -> None:
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
    def _seek(self, frame: Frame, stmt: Stmt) -> None:
        """Skip ``stmt`` while looking for where the program goes on (the frame's seek)."""
        seek = frame.seek
        assert seek is not None
        frame.line = stmt.last + 1
        mode = seek.mode
        if mode == SEEK_LABEL:
            self._seek_label(frame, seek, stmt)
            return
        if isinstance(stmt, Refused) and stmt.keyword:
            raise stmt.failure  # a malformed control statement: the structure cannot be followed
        if not isinstance(stmt, Control):
            return
        keyword = stmt.keyword
        if mode in (SEEK_HASH, SEEK_HASH_END):
            if keyword == C_HASH_IF:
                seek.depth += 1
            elif keyword == C_HASH_ENDIF:
                if seek.depth == 0:
                    frame.open.pop()
                    frame.seek = None
                else:
                    seek.depth -= 1
            elif keyword == C_HASH_ELSE and seek.depth == 0 and mode == SEEK_HASH:
                frame.open[-1].taken = True
                frame.seek = None
            return
        if keyword in OPENING:
            if keyword == C_IF and stmt.goto is not None:
                return
            seek.depth += 1
            return
        closing = CLOSING.get(keyword)
        if closing is not None:
            if seek.depth > 0:
                seek.depth -= 1
                return
            entry = frame.open[-1] if frame.open else None
            if entry is None or entry.keyword != closing:
                raise self._unexpected(frame, stmt)
            if mode == SEEK_CONTINUE:
                frame.seek = None
                frame.line = stmt.first  # the loop's closing statement runs
                return
            if mode == SEEK_CASE and entry.default >= 0:
                frame.seek = None
                frame.line = entry.default  # no $CASE matched: on after $DEFAULT
                return
            frame.open.pop()
            frame.seek = None
            return
        if seek.depth > 0:
            return
        top = frame.open[-1] if frame.open else None
        if mode == SEEK_BRANCH:
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
        elif mode == SEEK_CASE:
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

    def _seek_label(self, frame: Frame, seek: Seek, stmt: Stmt) -> None:
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
        if keyword in OPENING and not (keyword == C_IF and stmt.goto is not None):
            entry = OpenBlock(keyword, stmt.first, stmt.last + 1)
            entry.taken = True
            entry.valid = keyword != C_FOR
            seek.pending.append(entry)
            return
        closing = CLOSING.get(keyword)
        if closing is not None:
            if seek.pending:
                seek.pending.pop()
            elif frame.open and frame.open[-1].keyword == closing:
                frame.open.pop()  # the jump leaves this block

    def _run_label_block(self, frame: Frame, stmt: Stmt) -> None:
        """The labelled block is where the program goes on: it runs next (``frame.line`` is on it)."""
        return
