"""The simulated touch probe and the simulated workpiece it touches (TF5225 stand-ins).

A measuring stand-in knows where the workpiece is expected: an edge, a hole, a spigot, a sphere, from its
@P parameters and its start position. The simulated workpiece is that nominal geometry **shifted by the
probe deviation**: a vector per axis (mm) that a test, the PLC or the operator sets (:class:`ProbeDeviation`).
A measuring move (G100) of a stand-in carries where along its line the probe sphere first touches the shifted
workpiece (``Block.probe_touch``); the G100 handler (engine/areas/measuring.py) fires the probe when the
axes get there, so areas, limits, overrides and the PLC's own probe input all act as they would on the real
machine, and the cycle computes its results from what the probe latched.

Geometry: the probe is a sphere of the active D's radius ``r`` whose lowest point is the programmed
position (the probe length runs to the bottom of the sphere: TF5225 general page 322102027), so its centre is
``tip + (0, 0, r)``. Each feature is a solid; the sphere touches it when its centre enters the solid grown by
``r``. ``first_touch`` answers the fraction of a straight move (tip coordinates, main axes) at which that
happens, or None.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = [
    "Box",
    "Feature",
    "HalfSpace",
    "Hole",
    "ProbeDeviation",
    "Sphere",
    "Spigot",
    "Vec3",
    "first_touch",
    "shifted",
]

Vec3 = tuple[float, float, float]
_EPS = 1e-9
_INSIDE = 1e-6
"""A start deeper than this inside the grown solid is already in contact (a probe signal at once)."""


@dataclass(frozen=True, slots=True)
class HalfSpace:
    """Material on the side of the plane through ``point`` opposite its unit ``normal`` (an edge or a
    surface: the normal points out of the material, toward where the probe comes from)."""

    point: Vec3
    normal: Vec3


@dataclass(frozen=True, slots=True)
class Hole:
    """A bore of radius ``radius`` about the vertical axis through ``centre`` (x, y; z unused): material
    everywhere outside it."""

    centre: Vec3
    radius: float


@dataclass(frozen=True, slots=True)
class Spigot:
    """A cylinder of radius ``radius`` about the vertical axis through ``centre`` (x, y), up to ``top``."""

    centre: Vec3
    radius: float
    top: float


@dataclass(frozen=True, slots=True)
class Box:
    """A block with faces parallel to X and Y about ``centre`` (x, y), ``half`` its half lengths (a web:
    a huge half length along the web), up to ``top``. The probe sphere's corners are taken square (the
    grown block is a box): exact on the faces the cycles probe."""

    centre: Vec3
    half: tuple[float, float]
    top: float


@dataclass(frozen=True, slots=True)
class Sphere:
    centre: Vec3
    radius: float


Feature = HalfSpace | Hole | Spigot | Box | Sphere


def shifted(feature: Feature, by: Vec3) -> Feature:
    """The feature moved by ``by`` (the simulated workpiece: the nominal one plus the probe deviation)."""
    dx, dy, dz = by
    if isinstance(feature, HalfSpace):
        p = feature.point
        return HalfSpace((p[0] + dx, p[1] + dy, p[2] + dz), feature.normal)
    if isinstance(feature, Hole):
        c = feature.centre
        return Hole((c[0] + dx, c[1] + dy, c[2] + dz), feature.radius)
    if isinstance(feature, Spigot):
        c = feature.centre
        return Spigot((c[0] + dx, c[1] + dy, c[2] + dz), feature.radius, feature.top + dz)
    if isinstance(feature, Box):
        c = feature.centre
        return Box((c[0] + dx, c[1] + dy, c[2] + dz), feature.half, feature.top + dz)
    c = feature.centre
    return Sphere((c[0] + dx, c[1] + dy, c[2] + dz), feature.radius)


def first_touch(feature: Feature, start: Vec3, end: Vec3, ball: float) -> float | None:
    """The fraction (0 .. 1) of the straight move ``start`` -> ``end`` (the probe's tip, program
    coordinates of the main axes) at which the probe sphere of radius ``ball`` first touches ``feature``;
    0 when it already does at the start; None when it does not touch it on the way."""
    s = (start[0], start[1], start[2] + ball)
    d = (end[0] - start[0], end[1] - start[1], end[2] - start[2])
    length2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    if length2 <= _EPS * _EPS:
        return None
    if isinstance(feature, HalfSpace):
        t = _half_space(feature, s, d, ball)
    elif isinstance(feature, Hole):
        t = _hole(feature, s, d, ball)
    elif isinstance(feature, Spigot):
        t = _spigot(feature, s, d, ball)
    elif isinstance(feature, Box):
        t = _box(feature, s, d, ball)
    else:
        t = _sphere(feature, s, d, ball)
    if t is None or t > 1.0 + _EPS:
        return None
    return max(0.0, t)


def inside(feature: Feature, tip: Vec3, ball: float) -> bool:
    """Is the probe sphere (its lowest point ``tip``) in the feature, deeper than 1 µm (deflected: the
    probe stops a little beyond the touch, braking)?"""
    return (
        first_touch(feature, tip, (tip[0], tip[1], tip[2] + 1.0), ball) == 0.0
        and first_touch(feature, tip, (tip[0], tip[1], tip[2] - 1.0), ball) == 0.0
    )


def _dot(a: Vec3, b: Vec3) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _half_space(f: HalfSpace, s: Vec3, d: Vec3, ball: float) -> float | None:
    n = f.normal
    height = _dot(n, (s[0] - f.point[0], s[1] - f.point[1], s[2] - f.point[2])) - ball
    if height < -_INSIDE:
        return 0.0
    rate = _dot(n, d)
    if rate >= -_EPS:
        return None
    return max(0.0, height) / -rate


def _roots(a: float, b: float, c: float) -> tuple[float, float] | None:
    """The real roots of a t² + b t + c (a > 0), smaller first."""
    disc = b * b - 4.0 * a * c
    if disc < 0.0:
        return None
    q = math.sqrt(disc)
    return (-b - q) / (2.0 * a), (-b + q) / (2.0 * a)


def _hole(f: Hole, s: Vec3, d: Vec3, ball: float) -> float | None:
    reach = f.radius - ball
    if reach <= 0.0:
        return 0.0
    ox, oy = s[0] - f.centre[0], s[1] - f.centre[1]
    dist2 = ox * ox + oy * oy
    if dist2 > (reach + _INSIDE) ** 2:
        return 0.0
    a = d[0] * d[0] + d[1] * d[1]
    if a <= _EPS * _EPS:
        return None
    roots = _roots(a, 2.0 * (ox * d[0] + oy * d[1]), dist2 - reach * reach)
    if roots is None:  # pragma: no cover - a start inside the circle always leaves it
        return None
    t = roots[1]
    return t if t > _EPS else None


def _spigot(f: Spigot, s: Vec3, d: Vec3, ball: float) -> float | None:
    reach = f.radius + ball
    ox, oy = s[0] - f.centre[0], s[1] - f.centre[1]
    top = f.top + ball
    inside_xy = ox * ox + oy * oy < (reach - _INSIDE) ** 2
    if inside_xy and s[2] < top - _INSIDE:
        return 0.0
    best: float | None = None
    a = d[0] * d[0] + d[1] * d[1]
    if a > _EPS * _EPS:
        roots = _roots(a, 2.0 * (ox * d[0] + oy * d[1]), ox * ox + oy * oy - reach * reach)
        if roots is not None and roots[0] >= -_EPS:
            t = max(0.0, roots[0])
            if s[2] + t * d[2] <= top + _EPS:
                best = t
    if d[2] < -_EPS and s[2] >= top - _INSIDE:
        t = (top - s[2]) / d[2]
        x, y = ox + t * d[0], oy + t * d[1]
        if t >= 0.0 and x * x + y * y <= reach * reach and (best is None or t < best):
            best = t
    return best


def _box(f: Box, s: Vec3, d: Vec3, ball: float) -> float | None:
    """Where the centre ``s + t d`` enters the box grown by ``ball`` (slabs; no bottom)."""
    low = (f.centre[0] - f.half[0] - ball, f.centre[1] - f.half[1] - ball, -math.inf)
    high = (f.centre[0] + f.half[0] + ball, f.centre[1] + f.half[1] + ball, f.top + ball)
    inside = all(low[k] + _INSIDE < s[k] < high[k] - _INSIDE for k in range(3))
    if inside:
        return 0.0
    enter, leave = -math.inf, math.inf
    for k in range(3):
        if abs(d[k]) <= _EPS:
            if not low[k] <= s[k] <= high[k]:
                return None
            continue
        t1, t2 = (low[k] - s[k]) / d[k], (high[k] - s[k]) / d[k]
        enter = max(enter, min(t1, t2))
        leave = min(leave, max(t1, t2))
    if enter > leave or leave < 0.0 or enter < -_EPS:
        return None
    return max(0.0, enter)


def _sphere(f: Sphere, s: Vec3, d: Vec3, ball: float) -> float | None:
    reach = f.radius + ball
    o = (s[0] - f.centre[0], s[1] - f.centre[1], s[2] - f.centre[2])
    if math.sqrt(_dot(o, o)) < reach - _INSIDE:
        return 0.0
    c = _dot(o, o) - reach * reach
    roots = _roots(_dot(d, d), 2.0 * _dot(o, d), c)
    if roots is None or roots[0] < -_EPS:
        return None
    return max(0.0, roots[0])


class ProbeDeviation:
    """Where the simulated workpiece is, relative to where the cycles expect it: mm per axis.

    Three doors set it (docs/cycles.md, "The simulated probe"): the PLC through the V.E. variables the
    channel's ``[channels.probe] deviation_variables`` names (``X = "PROBE_DEV_X"``), the HTTP API
    (``PUT /api/channels/{n}/probe/deviation``) and the test harness (``hli.set_probe_deviation``). An axis
    with a V.E. variable takes its value from the variable (the API and the harness write that variable,
    as the PLC would); an axis without one takes the value set through the API or the harness."""

    def __init__(self, variables: Mapping[str, str] | None = None) -> None:
        self.variables: dict[str, str] = {k.upper(): v for k, v in (variables or {}).items()}
        """axis -> V.E. variable name (without ``V.E.``)."""
        self.values: dict[str, float] = {}
        """axis -> mm, for the axes without a V.E. variable."""

    def reset(self) -> None:
        self.values.clear()
