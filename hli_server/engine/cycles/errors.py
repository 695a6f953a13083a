"""What a stand-in raises when a call is wrong or a measurement fails: the kernel's error ID and a message.

The interpreter turns a :class:`CycleError` into the alarm of the cycle call's line (the kernel raises a
cycle's errors in the cycle; the program stops at its call).
"""

from __future__ import annotations

from typing import Final

__all__ = [
    "A_APPROXIMATED",
    "A_COLLISION",
    "A_INVALID",
    "A_NOT_SIMULATED",
    "A_NO_WORKPIECE",
    "CycleError",
]

A_NO_WORKPIECE: Final = 13413
"""No probe signal during a measuring move: "No workpiece detected, please check your measuring
section" (TF5225 general page 322102027, P-ERR-13413)."""
A_COLLISION: Final = 13414
"""A probe signal during a positioning move: "Collision on positioning, please check your motion range"
(P-ERR-13414)."""
A_INVALID: Final = 917000
"""A cycle parameter missing or invalid where the diagnosis pages give no ID of their own (project's)."""
A_APPROXIMATED: Final = 917001
"""Warning: a stand-in approximates what the kernel's cycle does with an operator (project's)."""
A_NOT_SIMULATED: Final = 910110
"""A documented cycle whose stand-in is not built (the project's "not simulated")."""


class CycleError(Exception):
    """A cycle refused its parameters or a measurement failed: ``alarm`` is the ID the kernel's cycle
    raises (or the project's where the pages give none), ``message`` says what, which @P and what to do."""

    def __init__(self, alarm: int, message: str, param: int = 0) -> None:
        super().__init__(message)
        self.alarm = alarm
        self.message = message
        self.param = param
        """The @P number concerned, 0 when none."""
