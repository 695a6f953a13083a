import pytest

from schemas.units import DINT_MAX, DINT_MIN, increments_from_mm, mm_from_increments


@pytest.mark.req("E-07")
def test_position_increments_are_tenths_of_a_micrometre():
    assert increments_from_mm(1.0) == 10_000
    assert increments_from_mm(-150.0) == -1_500_000
    assert mm_from_increments(200_000) == pytest.approx(20.0)


def test_increments_clamp_to_dint():
    assert increments_from_mm(1e12) == DINT_MAX
    assert increments_from_mm(-1e12) == DINT_MIN
