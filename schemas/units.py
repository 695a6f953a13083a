"""Interface units, converted in one place.

The documents' units at the interface (configuration, process image, wire):

* positions: 0.1 µm for translatory axes, 0.0001° for rotary axes, as DINT (SGN32);
* times: µs;
* accelerations: mm/s² (°/s² rotary), as the documents give a_max and the C3-10 deceleration;
* velocities in the configuration: mm/min (the unit an NC programmer writes with F) for the project's
  own keys, µm/s where a kernel parameter gives that unit (P-AXIS-00215 ``vb_messen``).

Inside the engine positions are floats in mm (or °) and time in s. Both position units share the
factor 10 000 per mm (or per °), so one pair of functions serves translatory and rotary axes.
"""

from __future__ import annotations

__all__ = [
    "ACCELERATION_LIMIT",
    "DINT_MAX",
    "DINT_MIN",
    "DISTANCE_LIMIT_MM",
    "INCREMENTS_PER_MM",
    "POSITION_LIMIT_MM",
    "UDINT_MAX",
    "VELOCITY_LIMIT_MM_PER_MIN",
    "increments_from_mm",
    "mm_from_increments",
    "mm_per_min_to_mm_per_s",
    "mm_per_s_from_um_per_s",
    "s_from_us",
    "us_from_s",
]

INCREMENTS_PER_MM = 10_000
"""0.1 µm per increment (0.0001° for rotary axes): 10 000 increments per mm (per °)."""

DINT_MIN = -(2**31)
DINT_MAX = 2**31 - 1
UDINT_MAX = 2**32 - 1

# --- the ranges every number that enters must lie in (E-04, E-07; reliability.md, round 1, finding 1) ---
POSITION_LIMIT_MM = DINT_MAX / INCREMENTS_PER_MM
"""214748.3647 mm (or °): the largest position the interface can carry, a DINT in 0.1 µm (0.0001°).
NC positions, MIN_EXCUR/MAX_EXCUR and configured positions lie within +/- this."""

DISTANCE_LIMIT_MM = 2 * POSITION_LIMIT_MM
"""429496.7294 mm: the largest distance between two positions within :data:`POSITION_LIMIT_MM`;
the bound of the circle centre words I/J/K (relative to the start point under G162)."""

VELOCITY_LIMIT_MM_PER_MIN = 6_000_000.0
"""100 m/s: upper bound of every velocity (configured v_max and the like, the NC feed F).

Why: the actual velocity reaches the PLC as ``ipo_state.velocity_r``, a DINT in 0.1 µm/s, which
holds 214 748 mm/s; the drive model saturates at twice the axis' v_max (``engine/axis.py``), so
v_max must stay below 107 374 mm/s (6.44e6 mm/min). Rounded down to 100 m/s, some ten times what
the fastest linear-motor machines reach."""

ACCELERATION_LIMIT = 1_000_000.0
"""mm/s² (about 100 g): upper bound of every configured acceleration. No interface field limits
it; it is far above any machine axis and keeps every derived quantity (braking distances, ramp
times) finite and meaningful."""


def increments_from_mm(value_mm: float) -> int:
    """mm (or °) -> interface increments (0.1 µm or 0.0001°), rounded to the nearest (ties to even, as
    ``round`` rounds), clamped to DINT. Clamped before it is rounded, so that a value whose product
    overflows to infinity clamps too (``round`` raises there); not a number raises ValueError.
    (The engine's cycle computes the same without ``round``: ``hli_server/engine/increments.py``.)"""
    inc = value_mm * INCREMENTS_PER_MM
    if inc >= DINT_MAX:
        return DINT_MAX
    if inc <= DINT_MIN:
        return DINT_MIN
    return round(inc)


def mm_from_increments(value_inc: int | float) -> float:
    """Interface increments (0.1 µm or 0.0001°) -> mm (or °)."""
    return float(value_inc) / INCREMENTS_PER_MM


def s_from_us(value_us: int | float) -> float:
    return float(value_us) * 1e-6


def us_from_s(value_s: float) -> int:
    return round(value_s * 1e6)


def mm_per_min_to_mm_per_s(value: float) -> float:
    return value / 60.0


def mm_per_s_from_um_per_s(value: int | float) -> float:
    """µm/s (0.001°/s rotary), the kernel's unit of axis velocities such as P-AXIS-00215, -> mm/s (°/s)."""
    return float(value) / 1000.0
