"""Path segments of the channel's axes in machine coordinates (mm / °).

A segment covers all axes of a channel: a point is a tuple with one coordinate per channel axis,
in the channel's axis order. Lines move every axis linearly; arcs move two plane axes on a circle
and the others linearly (helix).

``zip`` without ``strict=True`` where the cycle pairs coordinates (``# noqa: B905`` there, here and in the
monitors): the points and segments of a channel hold one coordinate per axis by construction, and mypyc
compiles a plain ``zip`` loop into C, but ``zip(..., strict=True)`` into a call of the interpreter's
``zip`` (an object, an iterator and a tuple per pair: 5 % of the compiled cycle in ``point_at`` alone;
docs/performance.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "ArcSegment",
    "LineSegment",
    "Point",
    "Segment",
    "arc_from_centre",
    "first_beyond",
    "segment_params",
    "sub_segment",
]

Point = tuple[float, ...]

_TAU = 2.0 * math.pi


@dataclass(frozen=True, slots=True)
class LineSegment:
    start: Point
    end: Point
    length: float = field(init=False, repr=False, compare=False)
    """Path length [mm], computed once: the interpolator asks for it every cycle (docs/performance.md)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "length", math.dist(self.start, self.end))

    def point_at(self, s: float) -> Point:
        """Point at path distance ``s`` from the start (clamped to the segment)."""
        length = self.length
        if length <= 0.0:
            return self.end
        f = min(max(s / length, 0.0), 1.0)
        return tuple([a + (b - a) * f for a, b in zip(self.start, self.end)])  # noqa: B905 compiled: see geometry.py

    def direction_at(self, s: float) -> Point:
        length = self.length
        if length <= 0.0:
            return tuple(0.0 for _ in self.start)
        return tuple((b - a) / length for a, b in zip(self.start, self.end))  # noqa: B905 compiled: see geometry.py

    def axis_extent(self, index: int) -> tuple[float, float]:
        a, b = self.start[index], self.end[index]
        return (min(a, b), max(a, b))


@dataclass(frozen=True, slots=True)
class ArcSegment:
    """Circle (or helix) in the plane of axes ``plane`` = (first, second) index.

    ``sweep`` is signed: positive counter-clockwise seen from the positive third axis (G03),
    negative clockwise (G02); a full circle has |sweep| = 2π.
    """

    start: Point
    end: Point
    plane: tuple[int, int]
    centre: tuple[float, float]
    radius: float
    start_angle: float
    sweep: float
    length: float = field(init=False, repr=False, compare=False)
    """Path length of the helix: hypot of the arc length and the linear axes' travel, computed once.
    ``hypot`` rather than a sum of squares: it stays finite for every finite result (a square of
    1e155 overflowed, reliability.md, round 1, finding 1)."""

    def __post_init__(self) -> None:
        i, j = self.plane
        length = math.hypot(
            self.arc_length,
            *(b - a for k, (a, b) in enumerate(zip(self.start, self.end, strict=True)) if k not in (i, j)),
        )
        object.__setattr__(self, "length", length)

    @property
    def arc_length(self) -> float:
        return abs(self.sweep) * self.radius

    def point_at(self, s: float) -> Point:
        length = self.length
        f = 1.0 if length <= 0.0 else min(max(s / length, 0.0), 1.0)
        if f >= 1.0:
            return self.end
        i, j = self.plane
        angle = self.start_angle + self.sweep * f
        p = [a + (b - a) * f for a, b in zip(self.start, self.end)]  # noqa: B905 compiled: see geometry.py
        p[i] = self.centre[0] + self.radius * math.cos(angle)
        p[j] = self.centre[1] + self.radius * math.sin(angle)
        return tuple(p)

    def direction_at(self, s: float) -> Point:
        length = self.length
        if length <= 0.0:
            return tuple(0.0 for _ in self.start)
        f = min(max(s / length, 0.0), 1.0)
        i, j = self.plane
        angle = self.start_angle + self.sweep * f
        d = [(b - a) / length for a, b in zip(self.start, self.end)]  # noqa: B905 compiled: see geometry.py
        k = self.sweep * self.radius / length
        d[i] = -math.sin(angle) * k
        d[j] = math.cos(angle) * k
        return tuple(d)

    def axis_extent(self, index: int) -> tuple[float, float]:
        """Min and max of one axis over the whole arc (the arc's extremes count, E-06)."""
        i, j = self.plane
        lo = min(self.start[index], self.end[index])
        hi = max(self.start[index], self.end[index])
        if index not in (i, j):
            return (lo, hi)
        c = self.centre[0] if index == i else self.centre[1]
        # extremes at angles where cos (first axis) or sin (second axis) is +-1
        candidates = (0.0, math.pi) if index == i else (math.pi / 2, 3 * math.pi / 2)
        for cand in candidates:
            if _angle_on_sweep(cand, self.start_angle, self.sweep):
                v = c + self.radius * (math.cos(cand) if index == i else math.sin(cand))
                lo, hi = min(lo, v), max(hi, v)
        return (lo, hi)


def _angle_on_sweep(angle: float, start: float, sweep: float) -> bool:
    if abs(sweep) >= _TAU - 1e-12:
        return True
    if sweep >= 0:
        return (angle - start) % _TAU <= sweep
    return (start - angle) % _TAU <= -sweep


Segment = LineSegment | ArcSegment


def arc_from_centre(
    start: Point, end: Point, plane: tuple[int, int], centre: tuple[float, float], clockwise: bool
) -> tuple[ArcSegment, float]:
    """Build an arc; returns it and the radius mismatch |r_end - r_start| (the caller judges it)."""
    i, j = plane
    r0 = math.hypot(start[i] - centre[0], start[j] - centre[1])
    r1 = math.hypot(end[i] - centre[0], end[j] - centre[1])
    a0 = math.atan2(start[j] - centre[1], start[i] - centre[0])
    a1 = math.atan2(end[j] - centre[1], end[i] - centre[0])
    full = math.isclose(start[i], end[i], abs_tol=1e-9) and math.isclose(start[j], end[j], abs_tol=1e-9)
    if clockwise:
        sweep = -((a0 - a1) % _TAU)
        if full or sweep == 0.0:
            sweep = -_TAU
    else:
        sweep = (a1 - a0) % _TAU
        if full or sweep == 0.0:
            sweep = _TAU
    return ArcSegment(start, end, plane, centre, r0, a0, sweep), abs(r1 - r0)


def sub_segment(segment: Segment, s0: float, s1: float) -> Segment:
    """The part of ``segment`` between the path distances ``s0`` and ``s1`` (0 <= s0 < s1 <= length)."""
    length = segment.length
    if isinstance(segment, LineSegment):
        start = segment.start if s0 <= 0.0 else segment.point_at(s0)
        end = segment.end if s1 >= length else segment.point_at(s1)
        return LineSegment(start, end)
    f0 = 0.0 if length <= 0.0 else s0 / length
    f1 = 1.0 if length <= 0.0 else s1 / length
    start = segment.start if s0 <= 0.0 else segment.point_at(s0)
    end = segment.end if s1 >= length else segment.point_at(s1)
    return ArcSegment(
        start,
        end,
        segment.plane,
        segment.centre,
        segment.radius,
        segment.start_angle + segment.sweep * f0,
        segment.sweep * (f1 - f0),
    )


def first_beyond(segment: Segment, index: int, limit: float, above: bool) -> Point:
    """The first point of ``segment`` at which axis ``index`` reaches ``limit`` on its way beyond it
    (``above``: to values greater than ``limit``, else smaller): where a refused block would have crossed
    a software limit. The start point when it lies there already; the end point when the axis never gets
    there (the caller asks only for a segment whose extent goes beyond)."""
    start = segment.start[index]
    if (start >= limit) if above else (start <= limit):
        return segment.start
    if isinstance(segment, LineSegment) or index not in segment.plane:
        end = segment.end[index]
        f = 1.0 if end == start else min(max((limit - start) / (end - start), 0.0), 1.0)
        return segment.point_at(f * segment.length)
    # a plane axis of an arc: the angles at which the circle meets the limit, the first on the sweep
    i, _ = segment.plane
    centre = segment.centre[0] if index == i else segment.centre[1]
    q = (limit - centre) / segment.radius if segment.radius > 0.0 else 2.0
    if abs(q) > 1.0:
        return segment.end
    # the first axis: cos(angle) = q; the second: sin(angle) = q
    angles = (math.acos(q), -math.acos(q)) if index == i else (math.asin(q), math.pi - math.asin(q))
    sweep = segment.sweep
    best = 1.0
    for angle in angles:
        turn = (angle - segment.start_angle) % _TAU if sweep >= 0.0 else (segment.start_angle - angle) % _TAU
        if turn <= abs(sweep):
            best = min(best, turn / abs(sweep))
    return segment.point_at(best * segment.length)


def segment_params(names: list[str] | tuple[str, ...], segment: Segment, **more: Any) -> dict[str, Any]:
    """A refused block's path as an alarm's parameters (``axes``, ``start``, ``end``, then ``more`` and,
    for an arc, ``arc`` with its plane, centre and sweep): what ``check`` and the dashboard draw the block
    from (``hli_server/scene.py``); start and end alone do not say where an arc goes."""
    params: dict[str, Any] = {"axes": list(names), "start": list(segment.start), "end": list(segment.end)}
    params.update(more)
    if isinstance(segment, ArcSegment):
        i, j = segment.plane
        params["arc"] = {
            "plane": [names[i], names[j]],
            "centre": list(segment.centre),
            "sweep_deg": math.degrees(segment.sweep),
        }
    return params
