"""A tool-tip segment and the path its axes take (docs/kinematics.md, "Where the transformation sits").

The decoder hands the planner segments of the tool tip; each carries a :class:`SegmentMap`, which turns the
point of path coordinate ``s`` into axis positions exactly (the transformation's inverse, every cycle).
For the checks before a block is queued and for the velocity the axes allow, :func:`axis_path` gives the
axes' path as segments:

* where the rotary axes stand still and the chain's linear axes are the machine's X, Y, Z ahead of every
  rotary axis (a head), the axes' path is the tip's path shifted by a constant: exact, lines and arcs;
* otherwise it is sampled: a support point at least every :data:`MAX_ROTARY_STEP` degrees of the rotary
  axes (the axes' own angles, so a complete transformation near its pole gets the points it needs) and
  every :data:`MAX_ARC_STEP` degrees of a circle, joined by lines. Between two support points the axes'
  path bows by at most ``r (1 - cos(step / 2))`` for an arm of length r: 2.4 µm per metre at 0.25°.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

from hli_server.engine.geometry import ArcSegment, LineSegment, Point, Segment
from hli_server.engine.kinematics.chain import KinematicError
from hli_server.engine.kinematics.transform import Transformation

__all__ = ["MAX_ARC_STEP", "MAX_ROTARY_STEP", "MAX_SAMPLES", "AxisPath", "SegmentMap", "axis_path"]

MAX_ROTARY_STEP = 0.25
"""Degrees of a rotary axis between two support points of a sampled axes' path."""
MAX_ARC_STEP = 2.0
"""Degrees of a circle (of the tip's path) between two support points of a sampled axes' path."""
MAX_SAMPLES = 20_000
"""Support points of one block at most: beyond it a rotary axis turns so far within the block (or flips
at a pole) that the block is refused (292016: the kernel's error of a singular axis position)."""


@dataclass(frozen=True, slots=True)
class SegmentMap:
    """Tip point of a queued segment -> axis positions. A complete transformation takes its pose from the
    support points the decoder computed (``anchors`` at path coordinates ``anchor_s``), so that every
    cycle and every look-ahead gets the same, continuous one."""

    trafo: Transformation
    anchor_s: tuple[float, ...] = ()
    anchors: tuple[Point, ...] = ()
    segments: tuple[Segment, ...] = ()
    """The axes' path (:attr:`AxisPath.segments`), for the reports of a geometry check."""
    shift: Point = ()
    """Axes minus tip where that is a constant along the segment (:attr:`AxisPath.shift`)."""

    def axes(self, p: Point, s: float) -> Point:
        shift = self.shift
        if shift:
            return tuple([a + b for a, b in zip(p, shift, strict=True)])
        trafo = self.trafo
        if not trafo.mode:
            return trafo.to_axes(p)
        return trafo.to_axes(p, self._hint(s))

    def _hint(self, s: float) -> Point:
        ss = self.anchor_s
        # the nearest anchor at or before s (a binary search)
        lo, hi = 0, len(ss) - 1
        while lo < hi:
            mid = (lo + hi + 1) // 2
            if ss[mid] <= s:
                lo = mid
            else:
                hi = mid - 1
        return self.anchors[lo]


@dataclass(frozen=True, slots=True)
class AxisPath:
    """The axes' path of one tip segment: ``segments`` in axis coordinates, the axis positions at its end,
    and the support points (path coordinate, axis positions) a complete transformation needs."""

    segments: tuple[Segment, ...]
    end: Point
    anchor_s: tuple[float, ...]
    anchors: tuple[Point, ...]
    shift: Point = ()
    """Where the head's angles stand still: the constant the axes stand off the tip by (exact); else
    empty."""


def _translation_only(trafo: Transformation) -> bool:
    """The linear axes are X, Y, Z (unit directions on the indices 0, 1, 2) ahead of every rotary axis
    in the chain: with the angles fixed the tip and the axes differ by a constant vector."""
    seen_rotary = False
    for joint in trafo.chain.joints:
        if joint.rotary:
            seen_rotary = True
        elif seen_rotary or joint.direction[joint.index] != 1.0:
            return False
    return True


def axis_path(trafo: Transformation, segment: Segment, start_axes: Sequence[float]) -> AxisPath:
    """The axes' path of the tip ``segment`` that starts with the axes at ``start_axes``. Raises
    :class:`KinematicError` where a point cannot be reached (292004) or the axes would have to jump
    (292016)."""
    angles = trafo.angle_slots()
    rotary = tuple(k for k, _ in angles)
    still = all(segment.start[k] == segment.end[k] for k in rotary)
    if still and _translation_only(trafo):
        first = trafo.to_axes(segment.start, start_axes)
        shift = [a - p for a, p in zip(first, segment.start, strict=True)]
        moved: Segment
        end = tuple(p + d for p, d in zip(segment.end, shift, strict=True))
        if isinstance(segment, LineSegment):
            moved = LineSegment(first, end)
        else:
            i, j = segment.plane
            moved = ArcSegment(
                first,
                end,
                segment.plane,
                (segment.centre[0] + shift[i], segment.centre[1] + shift[j]),
                segment.radius,
                segment.start_angle,
                segment.sweep,
            )
        return AxisPath((moved,), end, (0.0,), (first,), tuple(shift))
    length = segment.length
    travel = max((abs(segment.end[k] - segment.start[k]) * gear for k, gear in angles), default=0.0)
    steps = max(1, math.ceil(travel / MAX_ROTARY_STEP))
    if isinstance(segment, ArcSegment):
        steps = max(steps, math.ceil(math.degrees(abs(segment.sweep)) / MAX_ARC_STEP))
    s_values = [length * k / steps for k in range(steps + 1)]
    points: list[Point] = [trafo.to_axes(segment.start, start_axes)]
    s_done: list[float] = [0.0]
    k = 1
    while k < len(s_values):
        s = s_values[k]
        prev = points[-1]
        nxt = trafo.to_axes(segment.point_at(s), prev)
        jump = max((abs(nxt[r] - prev[r]) for r in rotary), default=0.0)
        if jump > MAX_ROTARY_STEP * 1.5:
            # the axes turn faster than the tip's angles (a complete transformation near its pole): a
            # support point halfway; where halving no longer helps the axes would jump (a pose flip)
            if s - s_done[-1] <= max(length, 1.0) * 1e-9 or len(s_values) > MAX_SAMPLES:
                raise KinematicError(
                    292016,
                    "the rotary axes would have to jump (a singular position, the pole of the head, "
                    "within the "
                    "block): program the orientation past it in smaller steps or through another pose",
                )
            s_values.insert(k, 0.5 * (s_done[-1] + s))
            continue
        points.append(nxt)
        s_done.append(s)
        k += 1
    segments = tuple(LineSegment(a, b) for a, b in itertools.pairwise(points))
    return AxisPath(segments, points[-1], tuple(s_done), tuple(points))
