"""Arithmetic expressions ``<expr>`` of the NC language: the tree and its evaluation (N-03).

The kernel's programming manual, "Arithmetic expressions <expr>"
(https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/206014219.html): square brackets
group (round parentheses are comments); ``+ - * /``, ``**`` (power), ``MOD``; the numerical functions
``ABS SQR SQRT EXP LN DEXP LOG``; the trigonometric functions in degrees ``SIN COS TAN COT ASIN ACOS
ATAN ATAN2 ACOT``; rounding ``INT FRACT ROUND FLOOR CEIL``; bit operations ``& | ^ INV``; logic
``&& AND || OR XOR NOT``; comparisons ``== != < <= > >=``; the constants ``TRUE FALSE PI``; and
``EXIST[..]``. Functions take their argument in square brackets: ``SIN[30]``, ``ATAN2[1, 1]``.

Values are REAL64 (a Python float) or, where ISG allows strings (string variables, ``#MSG``
arguments, comparisons), a ``str``. A comparison or logical operation gives 1.0 (TRUE) or 0.0 (FALSE).

Precedence, highest first (docs/nc-language.md, "Expressions"): ``**`` (right-associative), unary
``- +``, ``* / MOD``, ``+ -``, ``&``, ``^``, ``|``, comparisons, ``AND &&``, ``XOR``, ``OR ||``: the
order-of-operations rule of the manual, with the bit and logical operators ranked as in C and Python.

Every evaluation error is an :class:`EvalError` with the alarm number and a message that names the
operation and its operands; the interpreter adds the line and block.
"""

from __future__ import annotations

import math
from typing import Final

__all__ = [
    "BinOp",
    "Const",
    "ConstantEnv",
    "EvalError",
    "Expr",
    "Func",
    "Unary",
    "Value",
    "as_number",
    "format_value",
]

Value = float | str

# --- alarm numbers (hli_server/engine/alarms.py, group 914xxx: the NC language) --------------------
ALARM_EXPRESSION: Final = 914000
"""Malformed expression (syntax)."""
ALARM_DIVISION: Final = 914001
"""Division by zero (also MOD 0)."""
ALARM_DOMAIN: Final = 914002
"""A function's argument outside its domain (SQRT of a negative number, LN of 0, ASIN of 2, ...)."""
ALARM_TYPE: Final = 914006
"""A string where a number is needed, or the other way round."""

# operators
OP_ADD: Final = 1
OP_SUB: Final = 2
OP_MUL: Final = 3
OP_DIV: Final = 4
OP_POW: Final = 5
OP_MOD: Final = 6
OP_EQ: Final = 7
OP_NE: Final = 8
OP_LT: Final = 9
OP_LE: Final = 10
OP_GT: Final = 11
OP_GE: Final = 12
OP_AND: Final = 13
OP_OR: Final = 14
OP_XOR: Final = 15
OP_BAND: Final = 16
OP_BOR: Final = 17
OP_BXOR: Final = 18

OPERATOR_TEXT: Final[dict[int, str]] = {
    OP_ADD: "+",
    OP_SUB: "-",
    OP_MUL: "*",
    OP_DIV: "/",
    OP_POW: "**",
    OP_MOD: "MOD",
    OP_EQ: "==",
    OP_NE: "!=",
    OP_LT: "<",
    OP_LE: "<=",
    OP_GT: ">",
    OP_GE: ">=",
    OP_AND: "AND",
    OP_OR: "OR",
    OP_XOR: "XOR",
    OP_BAND: "&",
    OP_BOR: "|",
    OP_BXOR: "^",
}

_BIT_LIMIT = float(2**63)
"""Operands of the bit operations are whole numbers below this magnitude (a 64-bit integer)."""


class EvalError(Exception):
    """An expression that cannot be evaluated: ``alarm`` and a message for people."""

    def __init__(self, alarm: int, message: str) -> None:
        super().__init__(message)
        self.alarm = alarm
        self.message = message


def as_number(value: Value, what: str) -> float:
    """``value`` as a number, or :class:`EvalError` naming ``what`` needed it."""
    if isinstance(value, str):
        raise EvalError(ALARM_TYPE, f"{what} needs a number, got the string {_shown(value)}")
    return value


def _shown(value: str) -> str:
    return repr(value if len(value) <= 32 else value[:29] + "...")


def format_value(value: Value) -> str:
    """A value as the messages show it: ``20``, ``2.5``, ``'text'``."""
    if isinstance(value, str):
        return _shown(value)
    if not math.isfinite(value):
        return str(value)
    if value == int(value) and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.10g}"


def _truth(value: Value, what: str) -> bool:
    return as_number(value, what) != 0.0


def _whole(value: float, what: str) -> int:
    if not -_BIT_LIMIT < value < _BIT_LIMIT:
        raise EvalError(ALARM_DOMAIN, f"{what}: {format_value(value)} is not a 64-bit whole number")
    return int(value)


class Env:
    """What an expression reads: variables (the interpreter implements this)."""

    def read(self, ref: Ref) -> Value:
        raise NotImplementedError

    def exists(self, ref: Ref) -> bool:
        raise NotImplementedError


class ConstantEnv(Env):
    """The environment of a constant expression: it reads no variable."""

    def read(self, ref: Ref) -> Value:
        raise EvalError(ALARM_EXPRESSION, f"{ref.text} in a constant expression")

    def exists(self, ref: Ref) -> bool:
        raise EvalError(ALARM_EXPRESSION, f"{ref.text} in a constant expression")


class Expr:
    """A node of an expression tree."""

    def evaluate(self, env: Env) -> Value:
        raise NotImplementedError

    def is_constant(self) -> bool:
        """True when the value does not depend on any variable (evaluated once, at compile time)."""
        return False

    def references(self) -> list[Ref]:
        """Every variable the expression reads (the interpreter flushes before synchronous ones)."""
        return []


class Const(Expr):
    def __init__(self, value: Value) -> None:
        self.value = value

    def evaluate(self, env: Env) -> Value:
        return self.value

    def is_constant(self) -> bool:
        return True


class Unary(Expr):
    """``-x``, ``+x``."""

    def __init__(self, negate: bool, operand: Expr) -> None:
        self.negate = negate
        self.operand = operand

    def evaluate(self, env: Env) -> Value:
        value = self.operand.evaluate(env)
        if not isinstance(value, float):
            value = as_number(value, "the sign '-'" if self.negate else "the sign '+'")
        return -value if self.negate else value

    def is_constant(self) -> bool:
        return self.operand.is_constant()

    def references(self) -> list[Ref]:
        return self.operand.references()


class BinOp(Expr):
    def __init__(self, op: int, left: Expr, right: Expr) -> None:
        self.op = op
        self.left = left
        self.right = right

    def is_constant(self) -> bool:
        return self.left.is_constant() and self.right.is_constant()

    def references(self) -> list[Ref]:
        return self.left.references() + self.right.references()

    def evaluate(self, env: Env) -> Value:
        op = self.op
        if op == OP_AND:
            return (
                1.0
                if _truth(self.left.evaluate(env), "AND") and _truth(self.right.evaluate(env), "AND")
                else 0.0
            )
        if op == OP_OR:
            return (
                1.0
                if _truth(self.left.evaluate(env), "OR") or _truth(self.right.evaluate(env), "OR")
                else 0.0
            )
        a = self.left.evaluate(env)
        b = self.right.evaluate(env)
        if isinstance(a, float) and isinstance(b, float):
            # the fast path of two numbers: + - * and < <= > >= (what the general path gives)
            if op <= OP_MUL:
                result = a + b if op == OP_ADD else (a - b if op == OP_SUB else a * b)
                if math.isfinite(result):
                    return result
            elif OP_LT <= op <= OP_GE:
                return _ordered(op, a, b)
        if op in (OP_EQ, OP_NE):
            if isinstance(a, str) != isinstance(b, str):
                raise EvalError(
                    ALARM_TYPE,
                    f"cannot compare {format_value(a)} with {format_value(b)}: a string and a number",
                )
            equal = a == b
            return 1.0 if equal == (op == OP_EQ) else 0.0
        if op == OP_ADD and isinstance(a, str) and isinstance(b, str):
            return a + b
        name = OPERATOR_TEXT[op]
        x = as_number(a, f"'{name}'")
        y = as_number(b, f"'{name}'")
        result = _arith(op, x, y)
        if not math.isfinite(result):
            raise EvalError(
                ALARM_DOMAIN, f"{format_value(x)} {name} {format_value(y)} is not a finite number (overflow)"
            )
        return result


def _ordered(op: int, x: float, y: float) -> float:
    """``<``, ``<=``, ``>``, ``>=`` of two numbers: 1.0 or 0.0."""
    if op == OP_LT:
        return 1.0 if x < y else 0.0
    if op == OP_LE:
        return 1.0 if x <= y else 0.0
    if op == OP_GT:
        return 1.0 if x > y else 0.0
    return 1.0 if x >= y else 0.0  # OP_GE


def _arith(op: int, x: float, y: float) -> float:
    if op == OP_ADD:
        return x + y
    if op == OP_SUB:
        return x - y
    if op == OP_MUL:
        return x * y
    if op == OP_DIV:
        if y == 0.0:
            raise EvalError(ALARM_DIVISION, f"division by zero: {format_value(x)} / 0")
        return x / y
    if op == OP_POW:
        if x == 0.0 and y < 0.0:
            raise EvalError(ALARM_DIVISION, f"division by zero: 0 ** {format_value(y)}")
        if x < 0.0 and y != int(y):
            raise EvalError(
                ALARM_DOMAIN,
                f"{format_value(x)} ** {format_value(y)}: a negative number to a fractional power",
            )
        try:
            result = math.pow(x, y)
        except OverflowError:
            raise EvalError(ALARM_DOMAIN, f"{format_value(x)} ** {format_value(y)} overflows") from None
        return result
    if op == OP_MOD:
        if y == 0.0:
            raise EvalError(ALARM_DIVISION, f"division by zero: {format_value(x)} MOD 0")
        return math.fmod(x, y)
    if OP_LT <= op <= OP_GE:
        return _ordered(op, x, y)
    if op == OP_XOR:
        return 1.0 if (x != 0.0) != (y != 0.0) else 0.0
    name = OPERATOR_TEXT[op]
    i = _whole(x, f"'{name}'")
    j = _whole(y, f"'{name}'")
    if op == OP_BAND:
        return float(i & j)
    if op == OP_BOR:
        return float(i | j)
    return float(i ^ j)  # OP_BXOR


# --- functions ----------------------------------------------------------------------------------------
FUNCTION_ARITY: Final[dict[str, int]] = {
    "ABS": 1,
    "SQR": 1,
    "SQRT": 1,
    "EXP": 1,
    "LN": 1,
    "DEXP": 1,
    "LOG": 1,
    "SIN": 1,
    "COS": 1,
    "TAN": 1,
    "COT": 1,
    "ASIN": 1,
    "ACOS": 1,
    "ATAN": 1,
    "ATAN2": 2,
    "ACOT": 1,
    "INT": 1,
    "FRACT": 1,
    "ROUND": 1,
    "FLOOR": 1,
    "CEIL": 1,
    "INV": 1,
    "NOT": 1,
}
"""The manual's functions and how many arguments each takes (``ATAN2[y, x]``)."""


def _round_half_away(x: float) -> float:
    return float(math.floor(x + 0.5)) if x >= 0.0 else -float(math.floor(-x + 0.5))


def call_function(name: str, args: list[float]) -> float:
    """Evaluate function ``name`` (upper case) of the manual; degrees for the trigonometric ones."""
    x = args[0]
    if name == "ABS":
        return abs(x)
    if name == "SQR":
        return x * x
    if name == "SQRT":
        if x < 0.0:
            raise EvalError(ALARM_DOMAIN, f"SQRT[{format_value(x)}]: square root of a negative number")
        return math.sqrt(x)
    if name in {"EXP", "DEXP"}:
        try:
            return math.exp(x) if name == "EXP" else math.pow(10.0, x)
        except OverflowError:
            raise EvalError(ALARM_DOMAIN, f"{name}[{format_value(x)}] overflows") from None
    if name in {"LN", "LOG"}:
        if x <= 0.0:
            raise EvalError(ALARM_DOMAIN, f"{name}[{format_value(x)}]: logarithm of a number <= 0")
        return math.log(x) if name == "LN" else math.log10(x)
    if name == "SIN":
        return math.sin(math.radians(x))
    if name == "COS":
        return math.cos(math.radians(x))
    if name == "TAN":
        return math.tan(math.radians(x))
    if name == "COT":
        t = math.tan(math.radians(x))
        if t == 0.0:
            raise EvalError(
                ALARM_DIVISION, f"COT[{format_value(x)}]: the cotangent of this angle is infinite"
            )
        return 1.0 / t
    if name in {"ASIN", "ACOS"}:
        if not -1.0 <= x <= 1.0:
            raise EvalError(ALARM_DOMAIN, f"{name}[{format_value(x)}]: the argument must lie within -1 .. 1")
        return math.degrees(math.asin(x) if name == "ASIN" else math.acos(x))
    if name == "ATAN":
        return math.degrees(math.atan(x))
    if name == "ATAN2":
        return math.degrees(math.atan2(x, args[1]))
    if name == "ACOT":
        return 90.0 - math.degrees(math.atan(x))
    if name == "INT":
        return float(math.trunc(x)) if math.isfinite(x) else x
    if name == "FRACT":
        return x - float(math.trunc(x)) if math.isfinite(x) else math.nan
    if name == "ROUND":
        return _round_half_away(x) if math.isfinite(x) else x
    if name == "FLOOR":
        return float(math.floor(x)) if math.isfinite(x) else x
    if name == "CEIL":
        return float(math.ceil(x)) if math.isfinite(x) else x
    if name == "INV":
        return float(~_whole(x, "INV"))
    if name == "NOT":
        return 0.0 if x != 0.0 else 1.0
    raise EvalError(ALARM_EXPRESSION, f"unknown function {name}")  # pragma: no cover - parser checks


class Func(Expr):
    """``NAME[arg]`` or ``NAME[arg, arg]``."""

    def __init__(self, name: str, args: list[Expr]) -> None:
        self.name = name
        self.args = args

    def is_constant(self) -> bool:
        return all(a.is_constant() for a in self.args)

    def references(self) -> list[Ref]:
        out: list[Ref] = []
        for a in self.args:
            out.extend(a.references())
        return out

    def evaluate(self, env: Env) -> Value:
        values = [as_number(a.evaluate(env), f"{self.name}[..]") for a in self.args]
        if not all(math.isfinite(v) for v in values):
            raise EvalError(ALARM_DOMAIN, f"{self.name}[..] of a number that is not finite")
        try:
            result = call_function(self.name, values)
        except (ValueError, OverflowError) as exc:
            shown = ", ".join(format_value(v) for v in values)
            raise EvalError(ALARM_DOMAIN, f"{self.name}[{shown}]: {exc}") from None
        if math.isnan(result) or math.isinf(result):
            raise EvalError(
                ALARM_DOMAIN,
                f"{self.name}[{', '.join(format_value(v) for v in values)}] is not a finite number",
            )
        return result


class Exist(Expr):
    """``EXIST[variable]``: TRUE if the variable (or P parameter) exists."""

    def __init__(self, ref: Ref) -> None:
        self.ref = ref

    def evaluate(self, env: Env) -> Value:
        return 1.0 if env.exists(self.ref) else 0.0


# --- variable references ---------------------------------------------------------------------------
KIND_P: Final = "P"
KIND_PP: Final = "PP"
KIND_VP: Final = "V.P."
KIND_VL: Final = "V.L."
KIND_VS: Final = "V.S."
KIND_VE: Final = "V.E."
KIND_VA: Final = "V.A."
KIND_VG: Final = "V.G."
KIND_CYC: Final = "V.CYC."
KIND_RTA: Final = "V.RTA."
"""Realtime variables of the axes (``V.RTA.ACS.ACT_POS.X``, TF5261): read in realtime cycles."""
KIND_RTG: Final = "V.RTG."
"""Realtime variables of the channel (``V.RTG.OVERRIDE.VEL.CYCLE``, TF5261)."""
KIND_AT_P: Final = "@P"
KIND_MH: Final = "M/H"
"""``EXIST[M80]``: an M or H function (``name`` is ``M80``)."""


class Ref(Expr):
    """A variable as the program names it.

    ``kind`` is one of the ``KIND_*`` prefixes; ``name`` the rest upper-cased (``VAR_1``, ``ABS.X``,
    for P parameters the number's expression is in ``number``); ``indices`` the array subscripts;
    ``depth`` counts the P's of an indirect parameter (``PP1`` = 2)."""

    def __init__(
        self,
        kind: str,
        name: str,
        indices: list[Expr],
        number: Expr | None = None,
        depth: int = 1,
        text: str = "",
    ) -> None:
        self.kind = kind
        self.name = name
        self.indices = indices
        self.number = number
        self.depth = depth
        self.text = text
        """The reference as written (upper case), for messages."""
        self.fixed = -1
        """A direct P parameter's or cycle parameter's number where it is a constant (``P3``,
        ``@P2``) and no index follows: the interpreter's fast path; -1 otherwise."""
        if depth == 1 and not indices and isinstance(number, Const) and isinstance(number.value, float):
            n = number.value
            if n == int(n) and 0 <= n < 1_000_000_000:
                self.fixed = int(n)

    def evaluate(self, env: Env) -> Value:
        return env.read(self)

    def references(self) -> list[Ref]:
        out: list[Ref] = [self]
        for i in self.indices:
            out.extend(i.references())
        if self.number is not None:
            out.extend(self.number.references())
        return out
