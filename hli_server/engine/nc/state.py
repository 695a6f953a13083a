"""The interpreter's state and its hand-back (N-01..N-08): the program levels and the outputs not yet handed
out, the variables' stores, evaluating an expression in a statement's name, ``#FLUSH WAIT`` before a
statement that reads a synchronous variable, the iteration cap of a geometry check, and what the batch
geometry check asks (``at_main_level``, ``advance_to``, ``before_effect``: engine/batch.py).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Final

from hli_server.engine.nc.blocks import Block
from hli_server.engine.nc.compiler import Compiler
from hli_server.engine.nc.directives import (
    Directive,
    FlushWait,
    Host,
    IterationCapError,
    Realtime,
)
from hli_server.engine.nc.expr import (
    KIND_VA,
    KIND_VE,
    Env,
    EvalError,
    Expr,
    Value,
    as_number,
)
from hli_server.engine.nc.language import A_APPROXIMATED
from hli_server.engine.nc.levels import (
    Frame,
    ProgramResolver,
)
from hli_server.engine.nc.statements import (
    Stmt,
)
from hli_server.engine.nc.variables import Variable

__all__ = ["STATEMENTS_PER_CYCLE", "InterpreterState"]

STATEMENTS_PER_CYCLE: Final = 128
"""Statements the interpreter runs or skips in one cycle at most (docs/check.md): 800,000 blocks without
motion take 6,250 cycles, not one cycle of 3.9 s; a ``$WHILE`` without motion runs on, cycle by cycle,
and a reset still stops it."""


class InterpreterState(Env):
    """The interpreter's state (the first of its layers, see ``nc/interpreter.py``): the program levels,
    the outputs not yet handed out, the variables; the helpers every layer uses; the hand-back to the
    batch geometry check.

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
        self._frames: list[Frame] = []
        self._pending: deque[Block | Directive] = deque()
        self._ended = True
        self._params: dict[int, Value] = {}
        self._param_arrays: dict[tuple[int, tuple[int, ...]], Value] = {}
        self._program_vars: dict[str, Variable] = {}
        self._static_vars: dict[str, Variable] = {}
        self._drive_parameters: dict[str, int] = {}
        """``#IDENT WR``: what the simulated drives were given (axis/ident -> the telegram's integer); they
        keep it across programs, as a drive does."""
        """V.S.: kept across programs and resets (the channel's lifetime)."""
        self._message_file = "message.txt"
        self._rt_body: list[Stmt] | None = None
        """The statements of the realtime cycle being defined (``#RT CYCLE`` .. ``#RT CYCLE END``) or None."""
        self._rt_define: Realtime | None = None
        """The definition those statements go to."""
        self._rt_block_scope: dict[int | None, bool] = {}
        """Realtime cycles valid for the next block (SCOPE=BLOCK): ID -> defined with DEF (then held after
        the block, else deleted)."""
        self._approximated: set[str] = set()
        """Constructs approximated in this program and already said so (warning 911041, once each)."""
        self._implicit_names: dict[int, str] = {}
        """G code -> the subprogram ``#FILE NAME [G8xx=".."]`` assigned in this run (nc/implicit.py)."""
        self.iterations = 0
        self.statements = 0
        """Statements run or skipped since the program started (for reports)."""
        self.program_name = ""
        self._resolver = ProgramResolver(compiler, host)
        """Where a call goes (nc/levels.py)."""
        self.before_effect: Callable[[], None] | None = None
        """Called before the interpreter does what others see (a message, a warning, a V.E. write) or
        reads the decoder's state (V.A., V.G.): the batch geometry check decodes the blocks it kept first
        (hli_server/engine/batch.py)."""

    # --- hand-back to the batch geometry check (engine/batch.py) ------------------------------------------
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

    def _approximation(self, stmt: Stmt, key: str, message: str) -> None:
        """Warning 911041 (a construct approximated within a documented tolerance), once per program and
        ``key``."""
        if key in self._approximated:
            return
        self._approximated.add(key)
        self._effect()
        self.host.warn(A_APPROXIMATED, message, stmt.first, stmt.place)

    def _effect(self) -> None:
        hook = self.before_effect
        if hook is not None:
            hook()

    # --- evaluating -----------------------------------------------------------------------------------
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

    # --- flush: a synchronous read waits for the path --------------------------------------------------
    def _needs_flush(self, frame: Frame, stmt: Stmt, exprs: list[Expr]) -> bool:
        """Does the statement read a synchronous variable (V.E. declared synchronous, V.A.ACT_POS)?
        Then decoding first waits for the path (``#FLUSH WAIT``), once, and the statement runs again.
        Every run of the statement waits (a loop's every pass): the run after the wait takes the mark
        (``frame.synced``) away, so that the next run sees what the path did since, a synchronous
        V.E. write of the pass before included (issue 33: a count in a loop read its stale value)."""
        if stmt.sync_reads == 0:
            return False
        if frame.synced == stmt.first:
            frame.synced = -1
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

    def _flush_wait(self, frame: Frame, stmt: Stmt) -> None:
        frame.synced = stmt.first
        frame.line = stmt.first
        self._pending.append(FlushWait(self._place_block(frame, stmt)))

    def _place_block(self, frame: Frame, stmt: Stmt) -> Block:
        return Block(stmt.first, stmt.number, stmt.text, program=frame.program)

    def _iterate(self, frame: Frame, stmt: Stmt) -> None:
        self.iterations += 1
        cap = self.iteration_cap
        if cap is not None and self.iterations > cap:
            raise IterationCapError(cap, stmt.first, stmt.place)
