"""The geometry the stand-ins compute with, as pure functions (the tests' oracles use them too).

* :func:`fit_circle`: the circle through measured points (three or more, least squares; exact for points
  that lie on a circle);
* :func:`sphere_from_ring`: a sphere's centre and radius from a touch on its top and a ring of lateral
  touches;
* :func:`frame_angles`: the rotation between a nominal and a measured triangle as the kernel's ZYX angles;
* :func:`line_points`, :func:`circle_points`, :func:`frame_points`, :func:`grid_points`: the drilling
  patterns' positions (TF5293 SysDrillPattern*);
* :func:`pocket_rings`: the offset rings a pocket stand-in mills, each inside the outline by the tool radius.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = [
    "Vec2",
    "circle_points",
    "fit_circle",
    "frame_angles",
    "frame_points",
    "grid_points",
    "line_points",
    "rect_ring",
    "sphere_from_ring",
]

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]


def fit_circle(points: Sequence[Vec2]) -> tuple[Vec2, float]:
    """Centre and radius of the circle through ``points`` (at least 3, not on one line): the algebraic
    least-squares fit (Kåsa), exact when the points lie on a circle. ValueError for collinear points."""
    n = len(points)
    if n < 3:
        raise ValueError("a circle needs three points")
    mx = sum(p[0] for p in points) / n
    my = sum(p[1] for p in points) / n
    suu = suv = svv = suuu = svvv = suvv = svuu = 0.0
    for x, y in points:
        u, v = x - mx, y - my
        suu += u * u
        suv += u * v
        svv += v * v
        suuu += u * u * u
        svvv += v * v * v
        suvv += u * v * v
        svuu += v * u * u
    det = suu * svv - suv * suv
    scale = max(suu, svv, 1e-300)
    if abs(det) <= 1e-12 * scale * scale:
        raise ValueError("the points lie on a line")
    bu = 0.5 * (suuu + suvv)
    bv = 0.5 * (svvv + svuu)
    uc = (bu * svv - bv * suv) / det
    vc = (bv * suu - bu * suv) / det
    cx, cy = uc + mx, vc + my
    radius = sum(math.hypot(x - cx, y - cy) for x, y in points) / n
    return (cx, cy), radius


def sphere_from_ring(top: Vec3, ring: Sequence[Vec2], ring_height: float) -> tuple[Vec3, float]:
    """A sphere's centre and radius (of the probe sphere's centre path: the sphere's radius plus the
    probe's) from the probe centre ``top`` when it touched the sphere from above and the probe centres
    ``ring`` of lateral touches at height ``ring_height``."""
    (cx, cy), rho = fit_circle(ring)
    d2 = (top[0] - cx) ** 2 + (top[1] - cy) ** 2
    dz = top[2] - ring_height
    if abs(dz) < 1e-9:
        raise ValueError("the lateral touches must lie below the top touch")
    cz = (d2 - rho * rho + top[2] * top[2] - ring_height * ring_height) / (2.0 * dz)
    return (cx, cy, cz), math.sqrt(rho * rho + (ring_height - cz) ** 2)


def _sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _unit(a: Vec3) -> Vec3:
    n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if n < 1e-12:
        raise ValueError("two of the points coincide or the three lie on a line")
    return (a[0] / n, a[1] / n, a[2] / n)


def _frame(p1: Vec3, p2: Vec3, p3: Vec3) -> tuple[Vec3, Vec3, Vec3]:
    x = _unit(_sub(p2, p1))
    z = _unit(_cross(x, _sub(p3, p1)))
    y = _cross(z, x)
    return x, y, z


def frame_angles(nominal: Sequence[Vec3], measured: Sequence[Vec3]) -> Vec3:
    """The rotation R that turns the nominal triangle into the measured one, as the angles (A, B, C) in
    degrees of the kernel's #CS rotation sequence ZYX (``R = Rz(C) Ry(B) Rx(A)``, engine/path/frames.py)."""
    nx, ny, nz = _frame(nominal[0], nominal[1], nominal[2])
    mx, my, mz = _frame(measured[0], measured[1], measured[2])
    # R = M N^T, columns of N and M are the frames' axes
    n_cols = (nx, ny, nz)
    m_cols = (mx, my, mz)
    r = [[sum(m_cols[k][i] * n_cols[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    b = math.asin(max(-1.0, min(1.0, -r[2][0])))
    if abs(math.cos(b)) > 1e-9:
        a = math.atan2(r[2][1], r[2][2])
        c = math.atan2(r[1][0], r[0][0])
    else:  # pragma: no cover - a measured plane tilted by 90 degrees
        a = math.atan2(-r[1][2], r[1][1])
        c = 0.0
    return math.degrees(a), math.degrees(b), math.degrees(c)


def line_points(first: Vec2, distance: float, count: int, rotation_deg: float) -> list[Vec2]:
    """SysDrillPatternLine: ``count`` positions from ``first``, ``distance`` apart along the X axis turned
    by ``rotation_deg``."""
    c, s = math.cos(math.radians(rotation_deg)), math.sin(math.radians(rotation_deg))
    return [(first[0] + k * distance * c, first[1] + k * distance * s) for k in range(count)]


def circle_points(centre: Vec2, radius: float, count: int, start_deg: float, step_deg: float) -> list[Vec2]:
    """SysDrillPatternCircle: ``count`` positions on the circle, the first at ``start_deg`` from X+, each
    ``step_deg`` after the one before."""
    points: list[Vec2] = []
    for k in range(count):
        a = math.radians(start_deg + k * step_deg)
        points.append((centre[0] + radius * math.cos(a), centre[1] + radius * math.sin(a)))
    return points


def grid_points(first: Vec2, dx: float, dy: float, nx: int, ny: int, rotation_deg: float) -> list[Vec2]:
    """A point grid, rows along X first (row by row, alternating direction: the shortest travel)."""
    c, s = math.cos(math.radians(rotation_deg)), math.sin(math.radians(rotation_deg))
    points: list[Vec2] = []
    for j in range(ny):
        cols = range(nx) if j % 2 == 0 else range(nx - 1, -1, -1)
        for i in cols:
            u, v = i * dx, j * dy
            points.append((first[0] + u * c - v * s, first[1] + u * s + v * c))
    return points


def frame_points(first: Vec2, dx: float, dy: float, nx: int, ny: int, rotation_deg: float) -> list[Vec2]:
    """A point frame: the grid's border only, walked once round from the first position."""
    c, s = math.cos(math.radians(rotation_deg)), math.sin(math.radians(rotation_deg))
    cells: list[tuple[int, int]] = [(i, 0) for i in range(nx)]
    cells += [(nx - 1, j) for j in range(1, ny)]
    if ny > 1:
        cells += [(i, ny - 1) for i in range(nx - 2, -1, -1)]
    if nx > 1:
        cells += [(0, j) for j in range(ny - 2, 0, -1)]
    seen: list[tuple[int, int]] = []
    for cell in cells:
        if cell not in seen:
            seen.append(cell)
    return [(first[0] + i * dx * c - j * dy * s, first[1] + i * dx * s + j * dy * c) for i, j in seen]


def rect_ring(centre: Vec2, half_x: float, half_y: float) -> list[Vec2]:
    """The corners of an axis-parallel rectangle, counter-clockwise from the lower left."""
    x, y = centre
    return [
        (x - half_x, y - half_y),
        (x + half_x, y - half_y),
        (x + half_x, y + half_y),
        (x - half_x, y + half_y),
    ]
