"""Interface units, converted in one place.

The documents' units at the interface (configuration, process image, wire):

* positions: 0.1 µm for translatory axes, 0.0001° for rotary axes, as DINT (SGN32);
* times: µs;
* accelerations: mm/s² (°/s² rotary), as the documents give a_max and the C3-10 deceleration;
* velocities in the configuration: mm/min (the unit an NC programmer writes with F).

Inside the engine positions are floats in mm (or °) and time in s. Both position units share the
factor 10 000 per mm (or per °), so one pair of functions serves translatory and rotary axes.
"""

from __future__ import annotations

__all__ = [
    "DINT_MAX",
    "DINT_MIN",
    "INCREMENTS_PER_MM",
    "UDINT_MAX",
    "increments_from_mm",
    "mm_from_increments",
    "mm_per_min_to_mm_per_s",
    "s_from_us",
    "us_from_s",
]

INCREMENTS_PER_MM = 10_000
"""0.1 µm per increment (0.0001° for rotary axes): 10 000 increments per mm (per °)."""

DINT_MIN = -(2**31)
DINT_MAX = 2**31 - 1
UDINT_MAX = 2**32 - 1


def increments_from_mm(value_mm: float) -> int:
    """mm (or °) -> interface increments (0.1 µm or 0.0001°), rounded to the nearest, clamped to DINT."""
    inc = round(value_mm * INCREMENTS_PER_MM)
    return max(DINT_MIN, min(DINT_MAX, inc))


def mm_from_increments(value_inc: int | float) -> float:
    """Interface increments (0.1 µm or 0.0001°) -> mm (or °)."""
    return float(value_inc) / INCREMENTS_PER_MM


def s_from_us(value_us: int | float) -> float:
    return float(value_us) * 1e-6


def us_from_s(value_s: float) -> int:
    return round(value_s * 1e6)


def mm_per_min_to_mm_per_s(value: float) -> float:
    return value / 60.0
