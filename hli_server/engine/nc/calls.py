"""Program levels and calls (N-07): the interpreter's layer that pushes a program level for ``L``, ``LL`` and
``L CYCLE [..]`` (the program a call names is found by :class:`~hli_server.engine.nc.levels.ProgramResolver`)
and pops it at M17/M29 or the end of its text; M30/M02 end the program.
"""

from __future__ import annotations

from hli_server.engine.nc.blocks import Block, NcError
from hli_server.engine.nc.control_flow import ControlFlow
from hli_server.engine.nc.expr import ALARM_TYPE as A_TYPE
from hli_server.engine.nc.expr import Expr, Value, format_value
from hli_server.engine.nc.language import (
    A_CONTROL_SYNTAX,
    A_LIMIT,
    A_MAIN_RETURN,
    A_OPEN_INVALID_GLOBAL,
    A_OPEN_INVALID_LOCAL,
    A_OPEN_INVALID_MAIN,
    A_OPEN_VALID,
    A_STACK_OVERFLOW,
    A_SUB_END,
    END_OF,
    MAX_CALL_DEPTH,
    MAX_NAME,
)
from hli_server.engine.nc.levels import (
    SEEK_LABEL,
    Frame,
)
from hli_server.engine.nc.statements import (
    Call,
    Stmt,
)

__all__ = ["ProgramLevels"]


class ProgramLevels(ControlFlow):
    """Starts and ends program levels (N-07): a call (where it goes is :class:`ProgramResolver`'s), the
    end of a unit's text, M17/M29 (the end of a subroutine) and M30/M02 (the end of the program)."""

    # --- calls -----------------------------------------------------------------------------------------

    def _call(self, frame: Frame, stmt: Stmt, call: Call, place: Block) -> None:
        if len(self._frames) >= MAX_CALL_DEPTH:
            raise stmt.error(
                A_STACK_OVERFLOW,
                f"{call.text}: more than {MAX_CALL_DEPTH} program levels nested (a recursion without end?)",
            )
        params: dict[int, Value] | None = None
        if call.cycle:  # a number or a string (``@P31 = "Roughing"``, ``@P100 = "SysDrillDeepHole"``)
            params = {k: self._evaluate(stmt, v) for k, v in call.params}
        if call.variable is not None:
            call = call.named(self._program_name(stmt, call, call.variable))
        new = self._resolver.resolve(call, stmt, frame, place, params, self.set_cycle_result)
        new.params = params
        self._frames.append(new)

    def _program_name(self, stmt: Stmt, call: Call, variable: Expr) -> str:
        """The program ``L V.E.name`` names: the V.E. STRING's text, blanks around it dropped."""
        value = self._evaluate(stmt, variable)
        if not isinstance(value, str):
            raise stmt.error(
                A_TYPE,
                f"{call.text}: the program's name comes from a V.E. STRING; this one holds the number "
                f"{format_value(value)}",
            )
        name = value.strip()
        if not name:
            raise stmt.error(
                A_CONTROL_SYNTAX, f"{call.text}: the V.E. STRING that names the program is empty"
            )
        if len(name) > MAX_NAME:
            raise stmt.error(A_LIMIT, f"{call.text}: a program name has at most {MAX_NAME} characters")
        return name

    def _return(self, frame: Frame) -> None:
        self._frames.pop()
        if not self._frames:  # pragma: no cover - the main program never returns
            self._ended = True

    def _unit_end(self, frame: Frame, stmt: Stmt | None) -> None:
        """The end of a unit's text (or the next ``%`` header)."""
        place_line = frame.line
        place = f"line {place_line}"
        if frame.seek is not None and frame.seek.mode == SEEK_LABEL:
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
                f"${END_OF.get(keyword, keyword)} (its branch was not run)",
                {
                    "open": len(frame.open),
                    "keyword": f"${keyword}",
                    "expected": f"${END_OF.get(keyword, keyword)}",
                },
            )
        self._warn_open(frame, place_line, place)
        if frame.kind == "main":
            self._ended = True
            return
        self._return(frame)

    def _program_flow(self, frame: Frame, block: Block) -> None:
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

    def _warn_open(self, frame: Frame, line: int, place: str) -> None:
        """Warning 20375: control blocks still open where a program level ends."""
        if frame.open:
            top = frame.open[-1]
            self._effect()
            self.host.warn(
                A_OPEN_VALID,
                f"{len(frame.open)} control block(s) still open at the end of {frame.kind} program "
                f"{frame.name}: ${top.keyword} of line {top.start} has no "
                f"${END_OF.get(top.keyword, top.keyword)}",
                line,
                place,
            )
