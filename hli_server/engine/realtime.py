"""Realtime cycles (``#RT CYCLE``, TF5261; issue 33): a program's statements that run through completely in
every CNC cycle, in parallel to the path, to react to realtime influences.

The kernel's pages (https://infosys.beckhoff.com/content/1033/tf5261_realtime_cycles/): a cycle is defined
between ``#RT CYCLE [DEF] [ID=.. SCOPE=BLOCK|PROG|GLOBAL END_ACTION=..]`` and ``#RT CYCLE END`` (562766219),
valid for the next block, the main program or beyond it (444675851); managed with ``#RT CYCLE START |
HOLD | CONTINUE | ABORT ACTION | DELETE [ID=..]`` (444681483); its ``$IF`` may be qualified ``ONCE``, ``EDGE``
or ``ALWAYS`` (444686091); it reads the realtime variables ``V.RTA.`` (axes) and ``V.RTG.`` (channel) and
writes the path override ``V.RTG.OVERRIDE.VEL.CYCLE`` (444700939, 444701963).

What is simulated here (the body is checked when the cycle is defined; anything else in it is refused by
name with 910110, docs/nc-language.md): ``$IF`` (plain, with ``$ELSEIF``/``$ELSE``, or ``ONCE``/``EDGE``/
``ALWAYS``) .. ``$ENDIF``; assignments to ``V.E.`` variables (the PLC sees them in the cycle they are
written) and to ``V.RTG.OVERRIDE.VEL.CYCLE`` (0..100 %: it scales the path velocity with the operator's
override); M and H functions (accepted, as everywhere here); expressions of constants, ``V.E.``,
``V.RTA.ACS|MCS.ACT_POS|CUR_POS|CMD_POS.<axis>`` and ``V.RTG.OVERRIDE.VEL.CYCLE|TOTAL``. None of it moves
an axis: independent axis motions, spindles and ``#`` commands in a realtime cycle are the refused part.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

from hli_server.engine.external import ExternalVariableError, ExternalVariables
from hli_server.engine.nc.blocks import Block, NcError
from hli_server.engine.nc.expr import (
    KIND_RTA,
    KIND_RTG,
    KIND_VE,
    Env,
    EvalError,
    Ref,
    Value,
    as_number,
)
from hli_server.engine.nc.rt_cycles import OVERRIDE_CYCLE
from hli_server.engine.nc.statements import Assign, Control, Stmt, Words

__all__ = ["RealtimeCycles", "RtCycle"]

A_NOT_SIMULATED: Final = 910110
A_UNDECLARED: Final = 914003
OVERRIDE_TOTAL: Final = "OVERRIDE.VEL.TOTAL"
_POSITIONS: Final = frozenset(
    f"{system}.{kind}" for system in ("ACS", "MCS") for kind in ("ACT_POS", "CUR_POS", "CMD_POS")
)
"""The axis variables ``V.RTA.<system>.<kind>.<axis>`` simulated (TF5261 444701963)."""


class RtCycle:
    """One realtime cycle: its statements and the state of its qualified ``$IF``s."""

    def __init__(self, ident: int | None, scope: str, body: list[Stmt], block: Block) -> None:
        self.ident = ident
        self.scope = scope
        self.body = body
        self.block = block
        """Where it was defined (the alarms of its statements name their own lines)."""
        self.running = False
        self.fired: dict[int, bool] = {}
        """ONCE: has the branch run; EDGE: the condition's last value; ALWAYS: latched (by statement)."""
        self.jumps = _jumps(body)


def _jumps(body: list[Stmt]) -> dict[int, int]:
    """For each $IF/$ELSEIF/$ELSE: the index of the next branch or $ENDIF; for each branch's end: $ENDIF."""
    jumps: dict[int, int] = {}
    stack: list[list[int]] = []
    for k, stmt in enumerate(body):
        if not isinstance(stmt, Control):
            continue
        if stmt.keyword == "IF":
            stack.append([k])
        elif stmt.keyword in ("ELSEIF", "ELSE"):
            stack[-1].append(k)
        elif stmt.keyword == "ENDIF":
            branches = stack.pop()
            for here, following in zip(branches, [*branches[1:], k], strict=True):
                jumps[here] = following
            for here in branches[1:]:
                jumps[-here] = k  # the end of the branch before ``here`` goes on after $ENDIF
    return jumps


class _Env(Env):
    """What a realtime cycle's expression reads: V.E., V.RTA., V.RTG. and nothing else."""

    def __init__(self, cycles: RealtimeCycles) -> None:
        self.cycles = cycles

    def read(self, ref: Ref) -> Value:
        cycles = self.cycles
        kind = ref.kind
        if kind == KIND_VE:
            try:
                indices = [int(as_number(i.evaluate(self), ref.text)) for i in ref.indices]
                value = cycles.external.read(ref.name, cycles.channel, indices)
                return value if isinstance(value, str) else float(value)
            except ExternalVariableError as exc:
                raise EvalError(A_UNDECLARED, str(exc)) from None
        if kind == KIND_RTG:
            if ref.name == OVERRIDE_CYCLE:
                return cycles.override * 100.0
            if ref.name == OVERRIDE_TOTAL:
                return cycles.override * cycles.operator_override() * 100.0
        if kind == KIND_RTA:
            variable, _, axis = ref.name.rpartition(".")
            if variable in _POSITIONS:
                position = cycles.axis_position(variable.split(".")[1], axis)
                if position is not None:
                    return position
        raise EvalError(
            A_NOT_SIMULATED,
            f"{ref.text} is not simulated in a realtime cycle (V.E., "
            "V.RTA.ACS|MCS.ACT_POS|CUR_POS|CMD_POS.<axis>, V.RTG.OVERRIDE.VEL.CYCLE|TOTAL): "
            "docs/nc-language.md",
        )

    def exists(self, ref: Ref) -> bool:
        try:
            self.read(ref)
        except EvalError:
            return False
        return True


class RealtimeCycles:
    """A channel's realtime cycles: defined and managed in program order (:meth:`command`), run in every
    cycle (:meth:`run`) before the path takes its step; ``override`` is ``V.RTG.OVERRIDE.VEL.CYCLE`` / 100."""

    def __init__(
        self,
        channel: int,
        external: ExternalVariables,
        axis_position: Callable[[str, str], float | None],
        operator_override: Callable[[], float],
        fail: Callable[[NcError], None],
    ) -> None:
        self.channel = channel
        self.external = external
        self.axis_position = axis_position
        """(ACT_POS | CUR_POS | CMD_POS, axis) -> mm, or None for an axis the channel has not."""
        self.operator_override = operator_override
        self.fail = fail
        """Raises a cycle's runtime error (the channel's alarm); the cycle is deleted."""
        self.cycles: list[RtCycle] = []
        self.override = 1.0
        self._env = _Env(self)

    # --- management ---------------------------------------------------------------------------------
    def define(self, cycle: RtCycle, start: bool) -> None:
        """``#RT CYCLE [..] .. #RT CYCLE END``: the cycle (replacing one of its ID), running now or, with
        ``DEF``, from its ``#RT CYCLE START``."""
        self.cycles = [c for c in self.cycles if cycle.ident is None or c.ident != cycle.ident]
        self.cycles.append(cycle)
        cycle.running = start

    def manage(self, op: str, ident: int | None) -> None:
        """``#RT CYCLE START | HOLD | CONTINUE | ABORT ACTION | DELETE [ID=..]`` (TF5261 444681483): START
        runs it with its $IF states new, HOLD stops its runs keeping them, CONTINUE runs it again, DELETE
        removes it; ABORT ACTION aborts its motions and actions, of which it starts none here."""
        for cycle in self._named(ident):
            if op == "START":
                cycle.running = True
                cycle.fired.clear()
            elif op == "HOLD":
                cycle.running = False
            elif op == "CONTINUE":
                cycle.running = True
            elif op == "DELETE":
                self.cycles.remove(cycle)

    def _named(self, ident: int | None) -> list[RtCycle]:
        if ident is None:
            return self.cycles[-1:]
        return [c for c in self.cycles if c.ident == ident]

    def end_program(self) -> None:
        """The main program ended (or a reset): its BLOCK and PROG cycles are deleted, GLOBAL ones stay."""
        self.cycles = [c for c in self.cycles if c.scope == "GLOBAL"]
        if not any(c.running for c in self.cycles):
            self.override = 1.0

    # --- every cycle ------------------------------------------------------------------------------------
    def run(self) -> None:
        for cycle in list(self.cycles):
            if not cycle.running:
                continue
            try:
                self._run(cycle)
            except EvalError as exc:
                self.cycles.remove(cycle)
                self.fail(
                    NcError(exc.alarm, cycle.block.line, cycle.block.label, f"#RT CYCLE: {exc.message}")
                )
            except (
                ExternalVariableError
            ) as store_error:  # its own name: mypyc types a shared one by the first
                self.cycles.remove(cycle)
                self.fail(
                    NcError(A_UNDECLARED, cycle.block.line, cycle.block.label, f"#RT CYCLE: {store_error}")
                )

    def _run(self, cycle: RtCycle) -> None:
        body = cycle.body
        env = self._env
        k = 0
        n = len(body)
        while k < n:
            stmt = body[k]
            if isinstance(stmt, Control):
                if stmt.keyword in ("ELSEIF", "ELSE"):
                    k = cycle.jumps[-k] + 1  # reached from the branch before it: that one was taken
                elif stmt.keyword == "ENDIF":
                    k += 1
                else:
                    k = self._branch(cycle, k)
                continue
            if isinstance(stmt, Words):
                for item in stmt.items:
                    if isinstance(item, Assign):
                        self._write(item.target, item.value.evaluate(env))
            k += 1

    def _branch(self, cycle: RtCycle, k: int) -> int:
        """The $IF at ``k`` (and its $ELSEIFs): where the flow goes on."""
        body = cycle.body
        while True:
            stmt = body[k]
            assert isinstance(stmt, Control)
            condition = as_number(stmt.exprs[0].evaluate(self._env), stmt.text) != 0.0
            if stmt.frequency:
                condition = _qualified(cycle, k, stmt.frequency, condition)
            if condition:
                return k + 1
            following = cycle.jumps[k]
            nxt = body[following]
            if isinstance(nxt, Control) and nxt.keyword == "ELSEIF":
                k = following
                continue
            return following + 1  # into the $ELSE branch, or past $ENDIF

    def _write(self, ref: Ref, value: Value) -> None:
        if ref.kind == KIND_RTG:
            percent = as_number(value, ref.text)
            self.override = min(max(percent, 0.0), 100.0) / 100.0
            return
        indices = [int(as_number(i.evaluate(self._env), ref.text)) for i in ref.indices]
        self.external.write(ref.name, self.channel, value, indices)


def _qualified(cycle: RtCycle, k: int, frequency: str, condition: bool) -> bool:
    """ONCE: the first time the condition holds, never again; EDGE: each change FALSE -> TRUE; ALWAYS:
    from the first time it holds, every cycle (TF5261 444686091)."""
    seen = cycle.fired.get(k, False)
    if frequency == "ONCE":
        if condition and not seen:
            cycle.fired[k] = True
            return True
        return False
    if frequency == "EDGE":
        cycle.fired[k] = condition
        return condition and not seen
    if condition:
        cycle.fired[k] = True
    return cycle.fired.get(k, False)
