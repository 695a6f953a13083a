"""The V.E. variables' initial values at controller start (P-EXTV-00013 ``init``).

The kernel's page "Initialisation at CNC start (P-EXTV-00013)"
(https://infosys.beckhoff.com/content/1033/tf5200_external_variables/112479371.html): behind the keyword
``init`` the configuration list of the external variables holds an assignment as an NC program writes it
(``init V.E.var1_real64 = 1234.5``); the keyword may occur several times, the assignments run in the
order of the list, once at controller start (not when a program starts); the value may use arithmetic,
string operations and other V.E. variables, nothing else.

The machine file's ``external_init`` is that list, one assignment a string. :func:`run_external_init`
evaluates it with the NC language's own expression parser and evaluator and writes the store. A line
that fails does not stop the start (the kernel's class-2 reaction): its variable is set to 0 and the
machine raises a warning,

- 21841 "Variable for initialisation of external variables not permitted" for any variable but V.E.
  (a P parameter, V.A., V.G., ...) in the line (tf5200_diagnosis 256233611),
- 21840 "External variable could not be initialised" for any other failure: a malformed line, an
  undeclared variable, a value its type cannot hold, a division by zero (tf5200_diagnosis 256229259);
  the message names the cause, as the kernel's preceding message does.

Both carry the variable and the line (the 1-based entry of ``external_init``) in their parameters.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from hli_server.engine.external import ExternalVariableError, ExternalVariables
from hli_server.engine.nc.expr import ALARM_EXPRESSION, KIND_VE, Env, EvalError, Expr, Ref, Value, as_number
from hli_server.engine.nc.expr_parser import CompileError, ExpressionParser
from hli_server.engine.nc.reader import RawBlock

__all__ = ["ALARM_INIT_FAILED", "ALARM_INIT_NOT_PERMITTED", "InitFailure", "run_external_init"]

ALARM_INIT_FAILED: Final = 21840
"""The kernel's "External variable could not be initialised" (the variable is set to 0)."""
ALARM_INIT_NOT_PERMITTED: Final = 21841
"""The kernel's "Variable for initialisation of external variables not permitted" (only V.E.)."""


@dataclass(frozen=True, slots=True)
class InitFailure:
    """One ``external_init`` line that failed: the alarm to raise and what it says."""

    alarm: int
    variable: str
    """The variable the line assigns, as written (``V.E.TEACH_FILE_NAME``), or the text before ``=``."""
    line: int
    """The 1-based entry of ``external_init`` (the kernel's line of the configuration file)."""
    message: str


class _InitEnv(Env):
    """Reads V.E. variables from the store; any other variable is the kernel's 21841."""

    def __init__(self, store: ExternalVariables) -> None:
        self.store = store

    def read(self, ref: Ref) -> Value:
        name, channel, index = _resolve(self.store, ref, self)
        try:
            value = self.store.read(name, channel, index)
        except ExternalVariableError as exc:
            raise EvalError(exc.alarm, str(exc)) from None
        return value if isinstance(value, str) else float(value)

    def exists(self, ref: Ref) -> bool:
        if ref.kind != KIND_VE:
            raise _not_permitted(ref)
        return _area(self.store, ref.name) is not None


def _not_permitted(ref: Ref) -> EvalError:
    return EvalError(
        ALARM_INIT_NOT_PERMITTED,
        f"{ref.text}: only V.E. variables may be used in an initialisation (P-EXTV-00013)",
    )


def _area(store: ExternalVariables, name: str) -> tuple[int | None] | None:
    """The area of ``V.E.name``: the global one, else the one channel that declares it; None if no area
    (or more than one channel) does."""
    spec = store.spec(name, None)
    if spec is not None:
        return (None,)
    channels = {s.channel for s in store if s.channel is not None and s.name.upper() == name.upper()}
    return (channels.pop(),) if len(channels) == 1 else None


def _resolve(store: ExternalVariables, ref: Ref, env: Env) -> tuple[str, int | None, list[int]]:
    if ref.kind != KIND_VE:
        raise _not_permitted(ref)
    area = _area(store, ref.name)
    if area is None:
        unknown = store.unknown(ref.name, None)
        raise EvalError(unknown.alarm, str(unknown))
    index: list[int] = []
    for expr in ref.indices:
        value = as_number(expr.evaluate(env), f"the index of {ref.text}")
        index.append(int(value) if value == int(value) else -1)
    return ref.name, area[0], index


def _parse(text: str) -> tuple[Ref, Expr]:
    """``V.E.name[i] = expr`` as the variable and the expression; CompileError if it is not that."""
    raw = RawBlock(1, 1, text, text, None)
    parser = ExpressionParser(raw, text)
    parser.blanks()
    if not (parser.peek() == "V" and parser.peek(1) == "."):
        raise parser.failure(ALARM_EXPRESSION, f"an assignment to a V.E. variable expected: {text!r}")
    target = parser.variable()
    parser.expect("=", f"after {target.text}")
    expr = parser.expression(stop_at_blank=False)
    if not parser.at_end():
        raise parser.failure(
            ALARM_EXPRESSION, f"unexpected {parser.word_at(parser.pos)!r} after the expression"
        )
    return target, expr


def _target_text(text: str) -> str:
    return text.split("=", 1)[0].strip()[:40] or text[:40]


def run_external_init(store: ExternalVariables, lines: Sequence[str]) -> list[InitFailure]:
    """Run the ``external_init`` assignments in order on ``store``; the lines that failed (their
    variables set to 0 where the line names one the store has)."""
    env = _InitEnv(store)
    failures: list[InitFailure] = []
    for number, text in enumerate(lines, start=1):
        target: Ref | None = None
        try:
            target, expr = _parse(text)
            name, channel, index = _resolve(store, target, env)
            value = expr.evaluate(env)
            store.write(name, channel, value, index)
            continue
        # one name per clause: mypyc types a name shared by except clauses as the first clause's class
        except CompileError as compile_error:
            alarm, cause = compile_error.alarm, compile_error.message
        except EvalError as eval_error:
            alarm, cause = eval_error.alarm, eval_error.message
        except ExternalVariableError as store_error:
            alarm, cause = store_error.alarm, str(store_error)
        variable = target.text if target is not None else _target_text(text)
        failures.append(
            InitFailure(
                ALARM_INIT_NOT_PERMITTED if alarm == ALARM_INIT_NOT_PERMITTED else ALARM_INIT_FAILED,
                variable,
                number,
                f"external_init line {number} ({text!r}): {cause} [{alarm}]",
            )
        )
        if target is not None:
            _zero(store, target, env)
    return failures


def _zero(store: ExternalVariables, target: Ref, env: Env) -> None:
    """The kernel's reaction: the variable the failed line assigns is 0 (where it names one)."""
    try:
        name, channel, index = _resolve(store, target, env)
        spec = store.spec(name, channel)
        if spec is not None:
            store.write(name, channel, spec.zero(), index)
    except (EvalError, ExternalVariableError):
        pass
