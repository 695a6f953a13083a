"""What a program that waits is waiting for (N-13): the loop it turns in and the ``V.E.`` variables that loop
reads, for the offline check that stops a program waiting on inputs nobody can change
(:class:`~hli_server.engine.program_check.ProgramCheck`, docs/check.md "A program that waits for the PLC").

And the interpreter's state as one comparable value (:func:`state_of`): a program whose loop turns while
this value, the path and everything it emits stay the same cannot end - its next statements depend on
nothing else.
"""

from __future__ import annotations

from hli_server.engine.external import ExternalVariables
from hli_server.engine.nc.blocks import NcError
from hli_server.engine.nc.expr import KIND_VE, Expr, Value
from hli_server.engine.nc.language import END_OF, LOOPS, OPENING
from hli_server.engine.nc.levels import Frame, OpenBlock
from hli_server.engine.nc.statements import (
    Control,
    Hash,
    Stmt,
    Words,
    word_expressions,
)
from hli_server.engine.nc.variables import Variable

__all__ = ["WaitingLoop", "state_of", "waiting_loop"]

_LOOP_LINES = 10_000
"""Lines of a loop read at most to find what it reads (a loop longer than that is named by its head)."""


class WaitingLoop:
    """The loop a program turns in: ``keyword`` (``WHILE``, ``DO``, ``REPEAT``, ``FOR``, or ``GOTO`` for a
    jump back), its first line and block (``N20`` or ``line 20``), the program it belongs to ("" for the
    main program) and the ``V.E.`` variables it reads (as declared: ``V.E.UserInteraction.Answer``; one not
    declared as written), in order."""

    def __init__(self, keyword: str, line: int, place: str, program: str, variables: list[str]) -> None:
        self.keyword = keyword
        self.line = line
        self.place = place
        self.program = program
        self.variables = variables


def _variables(values: dict[str, Variable]) -> tuple[tuple[str, tuple[Value, ...]], ...]:
    return tuple((name, tuple(var.values)) for name, var in values.items())


def state_of(
    frames: list[Frame],
    params: dict[int, Value],
    arrays: dict[tuple[int, tuple[int, ...]], Value],
    program_vars: dict[str, Variable],
    static_vars: dict[str, Variable],
) -> tuple[object, ...]:
    """Everything a program's next statements may depend on besides where it is: P parameters and arrays,
    V.P., V.S., each level's V.L. and V.CYC. variables and @P values (compared, not hashed: equal means
    equal)."""
    levels = tuple(
        (
            frame.name,
            _variables(frame.locals),
            _variables(frame.cycle_vars),
            tuple(sorted(frame.params.items())) if frame.params is not None else None,
        )
        for frame in frames
    )
    return (
        tuple(sorted(params.items())),
        tuple(sorted(arrays.items())),
        _variables(program_vars),
        _variables(static_vars),
        levels,
    )


def waiting_loop(frames: list[Frame], external: ExternalVariables, channel: int) -> WaitingLoop | None:
    """The innermost loop of the program levels (from the innermost level out) and the ``V.E.`` variables
    its statements read (named as ``external`` declares them for ``channel``): the loop whose head the
    program is about to run again, else the innermost one open; a jump back with ``$GOTO`` is named by the
    statement the program is at. None without a program."""
    if not frames:
        return None
    frame = frames[-1]
    try:
        here = frame.units.statement(frame.line, frame.program, True)
    except NcError:
        here = None
    if isinstance(here, Control) and here.keyword in LOOPS:
        return _loop(frame, OpenBlock(here.keyword, here.first, here.last + 1), external, channel)
    for level in reversed(frames):
        for block in reversed(level.open):
            if block.keyword in LOOPS:
                return _loop(level, block, external, channel)
    if not isinstance(here, Stmt):
        return None
    names = _ve_names(_expressions(here), external, channel)
    return WaitingLoop("GOTO", here.first, here.place, frame.program, names)


def _loop(frame: Frame, block: OpenBlock, external: ExternalVariables, channel: int) -> WaitingLoop:
    head = frame.units.statement(block.start, frame.program, True)
    place = head.place if isinstance(head, Stmt) else f"line {block.start}"
    exprs: list[Expr] = []
    depth = 0
    for line in range(block.start, block.start + _LOOP_LINES):
        try:
            stmt = frame.units.statement(line, frame.program, True)
        except NcError:  # a block that cannot be read ends what is looked at, not the check
            break
        if stmt is None:
            break
        if not isinstance(stmt, Stmt):
            continue  # constant words: they read nothing
        exprs.extend(_expressions(stmt))
        if isinstance(stmt, Control):
            if stmt.keyword in OPENING:
                depth += 1
            elif stmt.keyword in END_OF.values():
                depth -= 1
        if depth <= 0:
            break
    return WaitingLoop(block.keyword, block.start, place, frame.program, _ve_names(exprs, external, channel))


def _expressions(stmt: Stmt) -> list[Expr]:
    if isinstance(stmt, Control):
        return list(stmt.exprs)
    if isinstance(stmt, Hash):
        return list(stmt.args)
    if isinstance(stmt, Words):
        return word_expressions(stmt)
    return []


def _ve_names(exprs: list[Expr], external: ExternalVariables, channel: int) -> list[str]:
    names: dict[str, None] = {}
    for expr in exprs:
        for ref in expr.references():
            if ref.kind == KIND_VE:
                spec = external.spec(ref.name, channel)
                names.setdefault(f"V.E.{spec.name if spec is not None else ref.name}", None)
    return list(names)
