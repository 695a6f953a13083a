"""The engine's one conversion from mm (or °) to interface increments, every cycle.

:func:`schemas.units.increments_from_mm` is the definition: rounded to the nearest (ties to even, as
Python's ``round`` rounds), clamped to a DINT. :func:`increments_clamped` computes exactly that without
calling the interpreter's ``round`` (a builtin looked up by name, its ``__round__`` found on the type and
bound, an object built for the result: 37 % of the compiled cycle on the benchmark machine, 32 of them a
cycle on an 8-axis machine; docs/performance.md). ``tests/unit/test_increments.py`` holds the two to each
other, ties included.

How: adding and subtracting 1.5 * 2**52 to a double below 2**51 in magnitude leaves the nearest
integer, ties to even (IEEE 754 round-to-nearest, the default mode, the one the interpreter's arithmetic
and the compiled module's both use; setup.py compiles with ``-ffp-contract=off`` and no fast-math, so the
C compiler keeps the two operations). The DINT range lies well inside 2**51: values beyond it are
clamped before they are rounded, as the definition clamps them (an infinite value too); not a number
raises ValueError as ``round`` does.
"""

from __future__ import annotations

from typing import Final

from schemas.units import DINT_MAX, DINT_MIN, INCREMENTS_PER_MM

__all__ = ["increments_clamped"]

_TIES_TO_EVEN: Final = 6755399441055744.0
"""1.5 * 2**52."""
# the definition's constants as Final names (a compiled module reads a Final name directly, an imported
# one through the module's dictionary on every use)
_PER_MM: Final = float(INCREMENTS_PER_MM)
"""The product is the same double with the int or the float."""
_DINT_MAX: Final = DINT_MAX
_DINT_MIN: Final = DINT_MIN
_HIGH: Final = float(DINT_MAX)
_LOW: Final = float(DINT_MIN)


def increments_clamped(mm: float) -> int:
    """mm (or °) -> 0.1 µm (0.0001°), rounded to the nearest, ties to even, clamped to a DINT:
    :func:`schemas.units.increments_from_mm`, bit for bit."""
    x = mm * _PER_MM
    if x >= _HIGH:
        return _DINT_MAX
    if x <= _LOW:
        return _DINT_MIN
    return int((x + _TIES_TO_EVEN) - _TIES_TO_EVEN)
