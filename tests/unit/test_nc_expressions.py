"""The expression evaluator against Python's own arithmetic and math, where their meanings agree (N-03).

Operators: ``+ - * / **``, comparisons and ``AND``/``OR`` mean what Python's do, with the same precedence
(the manual's order-of-operations rule; ``**`` binds tighter than a unary minus on its left, as in
Python); generated expressions without brackets test the precedence, with brackets the grouping. The
trigonometric functions are in degrees (``SIN[30]`` = 0.5), ``MOD`` is C's ``fmod``, ``ROUND`` rounds
half away from zero (docs/nc-language.md).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hli_server.engine.nc import NcError
from hli_server.engine.nc.expr import ConstantEnv, EvalError
from hli_server.engine.nc.expr_parser import parse_expression

ENV = ConstantEnv()
NUMBERS = st.one_of(
    st.integers(min_value=0, max_value=1000).map(str),
    st.decimals(min_value=0, max_value=1000, places=3, allow_nan=False, allow_infinity=False).map(
        lambda d: f"{d:.3f}"
    ),
)
ARITH = st.sampled_from(["+", "-", "*", "/", "**"])
COMPARE = st.sampled_from(["==", "!=", "<", ">", "<=", ">="])


def plain(value: float) -> str:
    """``value`` written without an exponent (the NC language has none), read back as the same float."""
    text = np.format_float_positional(value, unique=True, trim="-")
    assert float(text) == value
    return text if value >= 0 else f"[{text}]"


def isg(text: str) -> float | str:
    """The value of ``text``, or ``"error"`` where the evaluator refuses it (division by zero, ...)."""
    try:
        value = parse_expression(text).evaluate(ENV)
    except EvalError:
        return "error"
    assert isinstance(value, float)
    return value


def python(text: str) -> float | str:
    """Python's value of the generated arithmetic, in floating point as the kernel computes: integer
    literals as floats, so that a tower such as ``7 ** 3 ** 3 ** 3`` overflows at once instead of making
    Python build an exact integer of billions of digits (in C, where no time-out reaches it)."""
    text = re.sub(r"(?<![\d.])(\d+)(?![\d.])", r"\1.0", text)
    try:
        value = eval(text, {"__builtins__": {}}, {})  # generated arithmetic only
    except (ZeroDivisionError, OverflowError):
        return "error"
    if isinstance(value, complex) or not math.isfinite(value):
        return "error"
    return float(value)


@st.composite
def flat(draw: st.DrawFn, size: int = 6) -> str:
    """Numbers and operators without brackets: the precedence decides; at most one comparison."""
    parts = [draw(NUMBERS)]
    compared = False
    for _ in range(draw(st.integers(0, size))):
        if not compared and draw(st.booleans()) and draw(st.integers(0, 3)) == 0:
            parts.append(draw(COMPARE))
            compared = True
        else:
            op = draw(ARITH)
            if op == "**":
                parts.append("**")
                parts.append(draw(st.sampled_from(["0", "1", "2", "3", "0.5"])))
                continue
            parts.append(op)
        if draw(st.integers(0, 5)) == 0:
            parts.append("-" + draw(NUMBERS))
        else:
            parts.append(draw(NUMBERS))
    return " ".join(parts)


@st.composite
def nested(draw: st.DrawFn, depth: int = 3) -> str:
    if depth == 0 or draw(st.integers(0, 2)) == 0:
        return draw(NUMBERS)
    left = draw(nested(depth - 1))
    right = draw(nested(depth - 1))
    op = draw(st.sampled_from(["+", "-", "*", "/"]))
    return f"[{left} {op} {right}]"


@pytest.mark.req("N-03")
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(text=flat())
def test_precedence_and_arithmetic_as_pythons(text):
    expected = python(text)
    got = isg(text)
    if expected == "error" or got == "error":
        assert got == expected, text
        return
    assert got == pytest.approx(expected, rel=1e-12, abs=1e-12), text


@pytest.mark.req("N-03")
@settings(max_examples=300, deadline=None)
@given(text=nested())
def test_brackets_group_as_parentheses_do(text):
    expected = python(text.replace("[", "(").replace("]", ")"))
    got = isg(text)
    if expected == "error" or got == "error":
        assert got == expected, text
        return
    assert got == expected, text


@pytest.mark.req("N-03")
@settings(max_examples=300, deadline=None)
@given(
    a=st.floats(min_value=-1e6, max_value=1e6, allow_nan=False),
    b=st.floats(min_value=-1e3, max_value=1e3, allow_nan=False),
)
def test_functions_against_math(a, b):
    def value(text: str) -> float:
        result = parse_expression(text).evaluate(ENV)
        assert isinstance(result, float)
        return result

    x, y = plain(a), plain(b)
    assert value(f"ABS[{x}]") == abs(a)
    assert value(f"SQR[{y}]") == b * b
    assert value(f"SIN[{x}]") == math.sin(math.radians(a))
    assert value(f"COS[{x}]") == math.cos(math.radians(a))
    assert value(f"ATAN[{x}]") == math.degrees(math.atan(a))
    assert value(f"ATAN2[{x}, {y}]") == math.degrees(math.atan2(a, b))
    assert value(f"INT[{x}]") == math.trunc(a)
    assert value(f"FLOOR[{x}]") == math.floor(a)
    assert value(f"CEIL[{x}]") == math.ceil(a)
    assert value(f"FRACT[{x}]") == a - math.trunc(a)
    assert value(f"EXP[{y}]") == math.exp(b) if b < 700 else True
    if a >= 0:
        assert value(f"SQRT[{x}]") == math.sqrt(a)
    if a > 0:
        assert value(f"LN[{x}]") == math.log(a)
        assert value(f"LOG[{x}]") == math.log10(a)
    if -1 <= b / 1000 <= 1:
        assert value(f"ASIN[{plain(b / 1000)}]") == math.degrees(math.asin(b / 1000))
        assert value(f"ACOS[{plain(b / 1000)}]") == math.degrees(math.acos(b / 1000))
    if b != 0:
        assert value(f"{x} MOD {y}") == math.fmod(a, b)
        if math.isfinite(a / b):
            assert value(f"{x} / {y}") == a / b
        else:  # a tiny divisor: the quotient overflows, an alarm, not inf
            with pytest.raises(EvalError):
                value(f"{x} / {y}")
    assert value(f"ROUND[{x}]") == (math.floor(a + 0.5) if a >= 0 else -math.floor(-a + 0.5))


@pytest.mark.req("N-03")
@settings(max_examples=200, deadline=None)
@given(i=st.integers(min_value=-(2**40), max_value=2**40), j=st.integers(min_value=-(2**40), max_value=2**40))
def test_bit_operations_against_pythons_integers(i, j):
    assert parse_expression(f"[{i}] & [{j}]".replace("[-", "[0-")).evaluate(ENV) == float(i & j)
    assert parse_expression(f"[{i}] | [{j}]".replace("[-", "[0-")).evaluate(ENV) == float(i | j)
    assert parse_expression(f"[{i}] ^ [{j}]".replace("[-", "[0-")).evaluate(ENV) == float(i ^ j)
    assert parse_expression(f"INV[{i}]").evaluate(ENV) == float(~i)


@pytest.mark.req("N-03")
def test_logic_follows_python_with_true_as_one():
    for a in (0, 1, 2):
        for b in (0, 1, 3):
            assert parse_expression(f"{a} AND {b}").evaluate(ENV) == float(bool(a and b))
            assert parse_expression(f"{a} OR {b}").evaluate(ENV) == float(bool(a or b))
            assert parse_expression(f"{a} XOR {b}").evaluate(ENV) == float(bool(a) != bool(b))
            assert parse_expression(f"NOT[{a}] || {b} && {a}").evaluate(ENV) == float(
                (not a) or bool(b and a)
            )


@pytest.mark.req("N-03")
def test_a_malformed_expression_is_an_nc_error():
    for text in ("1 +", "[1", "SIN 30", "1 2", "", "**2"):
        with pytest.raises(NcError):
            parse_expression(text)
