"""Three-vectors and rigid motions of the kinematic chains: plain tuples of floats (mypyc compiles them
to unboxed arithmetic; no numpy in the per-cycle path)."""

from __future__ import annotations

import math

__all__ = [
    "IDENTITY",
    "Mat3",
    "Vec3",
    "add",
    "apply",
    "cross",
    "dot",
    "matmul",
    "norm",
    "rotation",
    "scale",
    "solve3",
    "sub",
    "unit",
]

Vec3 = tuple[float, float, float]
Mat3 = tuple[float, float, float, float, float, float, float, float, float]
"""Row-major 3x3 matrix."""

IDENTITY: Mat3 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


def add(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def scale(a: Vec3, k: float) -> Vec3:
    return (a[0] * k, a[1] * k, a[2] * k)


def dot(a: Vec3, b: Vec3) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def norm(a: Vec3) -> float:
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def unit(a: Vec3) -> Vec3:
    """``a`` scaled to length 1 (the caller makes sure it is not the zero vector)."""
    n = norm(a)
    return (a[0] / n, a[1] / n, a[2] / n)


def apply(m: Mat3, v: Vec3) -> Vec3:
    return (
        m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
        m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
        m[6] * v[0] + m[7] * v[1] + m[8] * v[2],
    )


def matmul(a: Mat3, b: Mat3) -> Mat3:
    return (
        a[0] * b[0] + a[1] * b[3] + a[2] * b[6],
        a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
        a[0] * b[2] + a[1] * b[5] + a[2] * b[8],
        a[3] * b[0] + a[4] * b[3] + a[5] * b[6],
        a[3] * b[1] + a[4] * b[4] + a[5] * b[7],
        a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
        a[6] * b[0] + a[7] * b[3] + a[8] * b[6],
        a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
        a[6] * b[2] + a[7] * b[5] + a[8] * b[8],
    )


def rotation(axis: Vec3, degrees: float) -> Mat3:
    """The rotation by ``degrees`` about the unit vector ``axis``, mathematically positive (right hand)."""
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    k = 1.0 - c
    x, y, z = axis
    return (
        c + x * x * k,
        x * y * k - z * s,
        x * z * k + y * s,
        y * x * k + z * s,
        c + y * y * k,
        y * z * k - x * s,
        z * x * k - y * s,
        z * y * k + x * s,
        c + z * z * k,
    )


def solve3(c0: Vec3, c1: Vec3, c2: Vec3, rhs: Vec3) -> Vec3 | None:
    """The x with ``x0 c0 + x1 c1 + x2 c2 = rhs`` (Cramer's rule); None if the columns are (nearly) linearly
    dependent: the determinant below 1e-9 of the product of their lengths."""
    det = dot(c0, cross(c1, c2))
    size = norm(c0) * norm(c1) * norm(c2)
    if size == 0.0 or abs(det) <= 1e-9 * size:
        return None
    return (
        dot(rhs, cross(c1, c2)) / det,
        dot(c0, cross(rhs, c2)) / det,
        dot(c0, cross(c1, rhs)) / det,
    )
