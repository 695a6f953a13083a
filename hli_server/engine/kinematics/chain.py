"""A serial kinematic chain: the forward and the inverse transformation of a machine's axes (TF5240).

The model is the one of the Universal Kinematics (kinematic ID 91, TF5240 "Universal kinematic",
https://infosys.beckhoff.com/content/1033/tf5240_universal_kinematic/278674827.html): every axis of the
chain is described in one coordinate system (the PCS) in the machine's zero position, a linear axis by
its direction, a rotary axis by its direction and a point on it; the tool rests at ``zero_position`` and
points along ``zero_orientation`` when all axes are 0. The axes are listed in the order of the
kinematic chain, from the workpiece to the tool tip (P-CHAN-00290): on a head machine X, Y, Z, C, A; on
a machine with a rotary table C, A, X, Y, Z, where the direction of an axis on the workpiece side is
reversed (".../278732555.html"). The position of the tool tip relative to the workpiece is then

    tip = E_0(q_0) E_1(q_1) ... E_n-1(q_n-1) zero_position

with ``E_k`` the translation along the direction of a linear axis by its value, or the rotation of a
rotary axis about its line by its angle (the product of exponentials of the axes' screws). The tool
orientation is the product of the rotations applied to ``zero_orientation``. The orientation vector
points from the tool tip towards the tool holder (``zero_orientation`` [0, 0, 1]: "the tool points in Z
direction").

For given angles of the rotary axes the tip is an affine function of the linear axes' values, so the
inverse of an RTCP transformation (programmed tip and angles -> axis values) solves a 3x3 linear
system; no iteration. The complete transformation (an orientation -> two rotary angles) is the two-axis
rotation problem: at most two solutions (the two poses), one where the orientation is on the edge of
what the head reaches, and none beyond it (the kernel's ID 292004, "Illegal argument for ACOS").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from hli_server.engine.kinematics.vectors import (
    IDENTITY,
    Mat3,
    Vec3,
    add,
    apply,
    cross,
    dot,
    matmul,
    norm,
    rotation,
    scale,
    solve3,
    sub,
)

__all__ = [
    "ALARM_ACOS",
    "ALARM_AXIS_CONFIGURATION",
    "ALARM_MODE_UNSUPPORTED",
    "ALARM_SINGULAR",
    "Chain",
    "Joint",
    "KinematicError",
    "wrap_near",
]

ALARM_ACOS = 292004
"""Kinematic transformation: illegal argument for ACOS - an orientation the head cannot reach
(https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/267444363.html)."""
ALARM_SINGULAR = 292016
"""Kinematic transformation: singular matrix
(https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/267496587.html)."""
ALARM_AXIS_CONFIGURATION = 292040
"""Kinematic transformation: invalid axis configuration
(https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/267579275.html)."""
ALARM_MODE_UNSUPPORTED = 292045
"""Selected orientation mode or rotation sequence unsupported by the transformation
(https://infosys.beckhoff.com/content/1033/tf5200_trafo_interface/441093515.html)."""

_POLE = 1e-9
"""Below this length of the projection of the orientation onto the plane normal to a rotary axis the
orientation lies on the axis: the axis' angle is free (a singular position, the pole)."""


class KinematicError(Exception):
    """A transformation that cannot be computed: the kernel's alarm number and a message."""

    def __init__(self, alarm: int, message: str) -> None:
        super().__init__(message)
        self.alarm = alarm
        self.message = message


@dataclass(frozen=True, slots=True)
class Joint:
    """One axis of the chain. ``index`` is its kinematic axis index (the channel's axis index 0..5 in the
    kernel's convention: X, Y, Z at 0, 1, 2). A rotary axis turns by ``sign * value + offset`` degrees
    about ``direction`` (a unit vector) through ``point``; a linear axis moves by ``value`` along it."""

    index: int
    rotary: bool
    direction: Vec3
    point: Vec3 = (0.0, 0.0, 0.0)
    sign: float = 1.0
    offset: float = 0.0

    def angle(self, value: float) -> float:
        return self.sign * value + self.offset

    def value(self, angle: float) -> float:
        return (angle - self.offset) / self.sign


@dataclass(frozen=True, slots=True)
class Chain:
    """A serial chain (see the module's description). ``joints`` in chain order, workpiece side first."""

    joints: tuple[Joint, ...]
    zero_position: Vec3
    zero_orientation: Vec3

    @property
    def linear(self) -> tuple[Joint, ...]:
        return tuple(j for j in self.joints if not j.rotary)

    @property
    def rotary(self) -> tuple[Joint, ...]:
        """The rotary axes in chain order (the one nearest the workpiece first)."""
        return tuple(j for j in self.joints if j.rotary)

    def check(self) -> None:
        """Three linear axes on the kinematic indices 0, 1, 2 (the tip's X, Y, Z) and at most three rotary
        axes, each index once; else the kernel's 292040."""
        indices = sorted(j.index for j in self.joints)
        lin = sorted(j.index for j in self.linear)
        if lin != [0, 1, 2] or len(set(indices)) != len(indices) or len(self.rotary) > 3:
            raise KinematicError(
                ALARM_AXIS_CONFIGURATION,
                "the kinematic chain needs three linear axes on the axis indices 0, 1, 2 and at most three "
                f"rotary axes, each index once; got linear {lin}, all {indices}",
            )
        for j in self.joints:
            if abs(norm(j.direction) - 1.0) > 1e-9:
                raise KinematicError(
                    ALARM_AXIS_CONFIGURATION,
                    f"axis index {j.index}: direction {j.direction} is not a unit vector",
                )

    # --- forward ----------------------------------------------------------------------------------
    def _pose(self, q: Sequence[float], tool: Vec3) -> tuple[Vec3, Mat3, list[Vec3]]:
        """The tip for the axis values ``q`` (by kinematic index) with the linear axes' values taken as
        given, the total rotation, and the base-frame direction of each linear axis (chain order): the
        columns of the affine map from the linear axes' values to the tip."""
        r: Mat3 = IDENTITY
        t: Vec3 = (0.0, 0.0, 0.0)
        columns: list[Vec3] = []
        for joint in self.joints:
            if joint.rotary:
                rk = rotation(joint.direction, joint.angle(q[joint.index]))
                c = joint.point
                t = add(t, apply(r, sub(c, apply(rk, c))))
                r = matmul(r, rk)
            else:
                d = apply(r, joint.direction)
                columns.append(d)
                t = add(t, scale(d, q[joint.index]))
        return add(apply(r, tool), t), r, columns

    def forward(self, q: Sequence[float], tool_length: float = 0.0) -> tuple[Vec3, Vec3]:
        """Axis values (by kinematic index) -> the tool tip and the tool orientation (unit vector)."""
        tip, r, _ = self._pose(q, self.tool_point(tool_length))
        return tip, apply(r, self.zero_orientation)

    def tool_point(self, tool_length: float) -> Vec3:
        """The tip in the zero position with a tool of ``tool_length``: that far from ``zero_position``
        against the orientation (the orientation points from the tip to the holder)."""
        return sub(self.zero_position, scale(self.zero_orientation, tool_length))

    def orientation(self, q: Sequence[float]) -> Vec3:
        r: Mat3 = IDENTITY
        for joint in self.joints:
            if joint.rotary:
                r = matmul(r, rotation(joint.direction, joint.angle(q[joint.index])))
        return apply(r, self.zero_orientation)

    # --- inverse ----------------------------------------------------------------------------------
    def solve_linear(self, q: list[float], tip: Vec3, tool_length: float = 0.0) -> None:
        """Set the linear axes' values in ``q`` (the rotary ones given) so that the tool tip is at ``tip``:
        the RTCP transformation's inverse. 292016 where the linear axes do not span the space."""
        lin = self.linear
        for joint in lin:
            q[joint.index] = 0.0
        base, _, columns = self._pose(q, self.tool_point(tool_length))
        x = solve3(columns[0], columns[1], columns[2], sub(tip, base))
        if x is None:
            raise KinematicError(
                ALARM_SINGULAR, "the linear axes of the kinematic chain do not span the space"
            )
        for joint, value in zip(lin, x, strict=True):
            q[joint.index] = value

    def poses(self, target: Vec3, hint: Sequence[float]) -> list[tuple[float, float]]:
        """Every pose (the two rotary axes' values, chain order) that turns the tool to ``target``, each
        angle the shortest way from the hint, in the order of :func:`two_axis_angles` (pose 1, pose 2)."""
        first, second = self.rotary
        h1, h2 = hint[first.index], hint[second.index]
        return [
            (wrap_near(first.value(a1), h1, first.sign), wrap_near(second.value(a2), h2, second.sign))
            for a1, a2 in two_axis_angles(
                first.direction,
                second.direction,
                self.zero_orientation,
                target,
                first.angle(h1),
                second.angle(h2),
            )
        ]

    def solve_orientation(self, target: Vec3, hint: Sequence[float]) -> tuple[float, float]:
        """The values of the two rotary axes (chain order) that turn the tool to ``target`` (a unit vector):
        of the (at most) two poses the one nearest to the values ``hint`` (by kinematic index), each angle
        taken the shortest way from the hint (P-CHAN-00189 "shortest way"). At a pole (``target`` on the
        first axis) the first axis keeps its hint. 292004 where no pose reaches ``target``."""
        rot = self.rotary
        if len(rot) != 2:
            raise KinematicError(
                ALARM_MODE_UNSUPPORTED,
                f"an orientation needs exactly two rotary axes in the chain, it has {len(rot)}: program the "
                "axes' angles (RTCP, P-CHAN-00287 = 1)",
            )
        h1, h2 = hint[rot[0].index], hint[rot[1].index]
        best: tuple[float, float] | None = None
        best_cost = math.inf
        for v1, v2 in self.poses(target, hint):
            cost = abs(v1 - h1) + abs(v2 - h2)
            if cost < best_cost - 1e-12:
                best, best_cost = (v1, v2), cost
        if best is None:
            raise KinematicError(
                ALARM_ACOS,
                f"the tool orientation ({target[0]:.6g}, {target[1]:.6g}, {target[2]:.6g}) "
                "is out of the head's reach",
            )
        return best


def wrap_near(value: float, near: float, sign: float = 1.0) -> float:
    """``value`` plus the multiple of 360° / |sign| nearest to ``near`` (an angle taken the shortest way)."""
    period = 360.0 / abs(sign)
    return value + period * round((near - value) / period)


def _angle_about(axis: Vec3, frm: Vec3, to: Vec3) -> float | None:
    """The angle [deg] that turns ``frm`` into ``to`` about the unit ``axis`` (both with the same component
    along it); None if either lies on the axis (any angle does)."""
    f = sub(frm, scale(axis, dot(axis, frm)))
    t = sub(to, scale(axis, dot(axis, to)))
    if norm(f) < _POLE or norm(t) < _POLE:
        return None
    return math.degrees(math.atan2(dot(axis, cross(f, t)), dot(f, t)))


def two_axis_angles(
    u1: Vec3, u2: Vec3, v: Vec3, w: Vec3, hint1: float, hint2: float
) -> list[tuple[float, float]]:
    """The angles (a1, a2) [deg] with ``R(u1, a1) R(u2, a2) v = w`` (unit vectors; Paden-Kahan's
    subproblem 2): ``x = R(u2, a2) v`` must lie as far from ``u1`` as ``w`` does, ``|x - u1| = |w - u1|``,
    which fixes a2 up to its two poses; a1 then turns x into w. Two solutions, one on the edge of the
    reach, none beyond it. Where an angle is free (a vector on its axis) the hint is taken.

    The distance is taken from the vectors' difference, not from a dot product: near the pole (w close
    to u1) a tilt of 1e-6° changes a cosine by 1e-16, below double precision, but the difference by
    1.7e-8 (a property test found the 10 % error the cosine gave)."""
    c = dot(u1, u2)
    out: list[tuple[float, float]] = []
    if abs(abs(c) - 1.0) < 1e-12:
        # parallel axes: one rotation about the common axis; the components must agree
        if abs(c * dot(u2, v) - dot(u1, w)) > 1e-9:
            return out
        total = _angle_about(u1, v, w)
        if total is None:
            return [(hint1, hint2)]
        return [(total - c * hint2, hint2)]
    v_par = scale(u2, dot(u2, v))
    v_perp = sub(v, v_par)
    n_perp = cross(u2, v_perp)
    y = sub(u1, v_par)
    y_par = dot(u2, y)
    y_perp = sub(y, scale(u2, y_par))
    d = sub(w, u1)
    d2 = dot(d, d)
    rv, ry = norm(v_perp), norm(y_perp)
    k = rv * ry
    # P cos(a2) + Q sin(a2) = K cos(a2 - phi) = K - (d² - (|v_perp| - |y_perp|)² - y_par²) / 2
    gap = 0.5 * (d2 - (rv - ry) * (rv - ry) - y_par * y_par)
    if k < _POLE:
        # v on u2 (a2 turns nothing) or u1 - v_par on u2: reachable only if the distance already fits
        if abs(gap) > 1e-9:
            return out
        x = v
        a1 = _angle_about(u1, x, w)
        return [(hint1 if a1 is None else a1, hint2)]
    half = gap / (2.0 * k)
    if half < -1e-12 or half > 1.0 + 1e-12:
        return out
    delta = math.degrees(2.0 * math.asin(math.sqrt(min(max(half, 0.0), 1.0))))
    phi = math.degrees(math.atan2(dot(n_perp, y), dot(v_perp, y)))
    for a2 in (phi + delta, phi - delta) if delta > 1e-12 else (phi,):
        x = apply(rotation(u2, a2), v)
        a1 = _angle_about(u1, x, w)
        out.append((hint1 if a1 is None else a1, a2))
    return out
