"""The classic programming modes of the orientation: two angles -> a tool orientation and back.

TF5240 "Classic programming modes" (https://infosys.beckhoff.com/content/1033/tf5240_universal_kinematic/
278765451.html): in CA mode (17) the orientation is the forward transformation of the chain XYZCA with
the tool in [0, 0, 0], the tool orientation [0, 0, 1] and every axis through the origin; AC, AB, BA, BC, CB
by analogy, "the tool zero orientation is always the orientation of the first rotary axis mentioned".
The numbers are those of P-CHAN-00288 (https://infosys.beckhoff.com/content/1033/tf5200_channel_parameter/
149257611.html): 14 AB, 15 BA, 16 AC, 17 CA, 18 BC, 19 CB (the page lists 19 as "BC" twice; 19 is CB).
"""

from __future__ import annotations

from hli_server.engine.kinematics.chain import two_axis_angles, wrap_near
from hli_server.engine.kinematics.vectors import Vec3, apply, matmul, rotation

__all__ = ["MODES", "mode_angles", "mode_name", "mode_orientation"]

_DIRECTION: dict[str, Vec3] = {"A": (1.0, 0.0, 0.0), "B": (0.0, 1.0, 0.0), "C": (0.0, 0.0, 1.0)}

MODES: dict[int, str] = {14: "AB", 15: "BA", 16: "AC", 17: "CA", 18: "BC", 19: "CB"}
"""P-CHAN-00288 programming modes with two angles -> the axis letters in chain order."""


def mode_name(mode: int) -> str:
    return MODES[mode]


def _axes(mode: int) -> tuple[Vec3, Vec3]:
    letters = MODES[mode]
    return _DIRECTION[letters[0]], _DIRECTION[letters[1]]


def mode_orientation(mode: int, first: float, second: float) -> Vec3:
    """The tool orientation of the programmed angles [deg] (the first and second letter of the mode)."""
    u1, u2 = _axes(mode)
    return apply(matmul(rotation(u1, first), rotation(u2, second)), u1)


def mode_angles(mode: int, orientation: Vec3, hint_first: float, hint_second: float) -> tuple[float, float]:
    """The programmed angles of ``orientation`` in ``mode``: the pose nearest to the hints, each angle the
    shortest way from its hint; at the pole (orientation along the first axis) the first keeps its hint."""
    u1, u2 = _axes(mode)
    best = (hint_first, hint_second)
    best_cost = float("inf")
    for a1, a2 in two_axis_angles(u1, u2, u1, orientation, hint_first, hint_second):
        v1, v2 = wrap_near(a1, hint_first), wrap_near(a2, hint_second)
        cost = abs(v1 - hint_first) + abs(v2 - hint_second)
        if cost < best_cost - 1e-12:
            best, best_cost = (v1, v2), cost
    return best
