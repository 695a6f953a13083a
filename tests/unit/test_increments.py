"""The engine's conversion to increments is :func:`schemas.units.increments_from_mm`, bit for bit.

``hli_server/engine/increments.py`` rounds without the interpreter's ``round`` (docs/performance.md);
these tests hold it to the definition, the ties included, in whichever engine this process runs (the
compiled one where it is built: ``tests/unit/test_compiled_engine.py`` runs the recorded scenarios in
both).
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hli_server.engine.increments import increments_clamped
from schemas.units import DINT_MAX, DINT_MIN, INCREMENTS_PER_MM, increments_from_mm

TIES = [
    # exactly half an increment: ties go to the even neighbour, as round() does
    0.00005,
    -0.00005,
    0.00015,
    -0.00015,
    0.00025,
    1.23455,
    -1.23455,
    2.5 / INCREMENTS_PER_MM,
    -2.5 / INCREMENTS_PER_MM,
    3.5 / INCREMENTS_PER_MM,
    # the largest values that are not clamped, and the first that are
    214748.36465,
    214748.36475,
    -214748.36475,
    -214748.36485,
    214748.3647,
    -214748.3648,
    # zero, signed zero, the smallest values
    0.0,
    -0.0,
    5e-324,
    -5e-324,
    1e-300,
]


@pytest.mark.parametrize("mm", TIES)
def test_ties_and_bounds_as_the_definition(mm: float) -> None:
    assert increments_clamped(mm) == increments_from_mm(mm)
    assert type(increments_clamped(mm)) is int


def test_half_increments_round_to_the_even_neighbour() -> None:
    for k in range(-2000, 2000):
        mm = (k + 0.5) / INCREMENTS_PER_MM
        # (k + 0.5) / 10000 is not always exactly half an increment as a double: compare with the
        # definition, and check the even rule where the product is exact
        assert increments_clamped(mm) == increments_from_mm(mm)
        if mm * INCREMENTS_PER_MM == k + 0.5:
            assert increments_clamped(mm) % 2 == 0


def test_clamped_far_outside_the_dint() -> None:
    assert increments_clamped(1e300) == DINT_MAX
    assert increments_clamped(-1e300) == DINT_MIN
    assert increments_clamped(3e5) == DINT_MAX
    assert increments_clamped(-3e5) == DINT_MIN


def test_not_a_number_raises_as_round_does() -> None:
    with pytest.raises(ValueError, match="NaN"):
        increments_from_mm(math.nan)
    with pytest.raises(ValueError, match="NaN"):
        increments_clamped(math.nan)


def test_infinite_values_clamp_in_both() -> None:
    assert increments_clamped(math.inf) == increments_from_mm(math.inf) == DINT_MAX
    assert increments_clamped(-math.inf) == increments_from_mm(-math.inf) == DINT_MIN


@given(st.floats(allow_nan=False))
def test_any_value_as_the_definition(mm: float) -> None:
    assert increments_clamped(mm) == increments_from_mm(mm)


@given(st.integers(min_value=DINT_MIN, max_value=DINT_MAX), st.floats(min_value=-1.0, max_value=1.0))
def test_values_near_every_increment_as_the_definition(inc: int, frac: float) -> None:
    mm = (inc + frac) / INCREMENTS_PER_MM
    assert increments_clamped(mm) == increments_from_mm(mm)
