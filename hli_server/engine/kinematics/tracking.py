"""Tangential tracking of an axis, ``#CAXTRACK`` (programming manual, "Automatic axis tracking",
https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/207450507.html).

The tracking axis (``AX=``/``AXNR=``, else P-CHAN-00095) turns so that it stays tangential to the path in
the main plane, plus ``OFFSET``. Along a line the angle is the line's direction; along a circle it turns
with the circle (the tangent's angle grows linearly with the circle's angle, so a linear interpolation of
the axis over the arc is exact). At a transition that is not tangential: a change up to ``ANGLIMIT`` is
made within the block (the axis turns from the previous angle while the block runs), a larger one by a
block of its own inserted before it, in which only the tracking axis turns, the path at rest. The axis
takes the shortest way (an angle is continued from the previous one, not reduced to ±180°).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from hli_server.engine.geometry import ArcSegment, LineSegment, Point, Segment

__all__ = ["Tracking", "track"]


@dataclass(frozen=True, slots=True)
class Tracking:
    """An active ``#CAXTRACK``: the channel slot of the tracking axis, the plane slots (first, second main
    axis), ``ANGLIMIT`` and ``OFFSET`` [deg]."""

    slot: int
    plane: tuple[int, int]
    anglimit: float = 0.0
    offset: float = 0.0


def _direction_deg(segment: Segment, plane: tuple[int, int], s: float) -> float | None:
    d = segment.direction_at(s)
    i, j = plane
    if abs(d[i]) <= 1e-12 and abs(d[j]) <= 1e-12:
        return None
    return math.degrees(math.atan2(d[j], d[i]))


def _near(angle: float, previous: float) -> float:
    return angle + 360.0 * round((previous - angle) / 360.0)


def _with(point: Point, slot: int, value: float) -> Point:
    p = list(point)
    p[slot] = value
    return tuple(p)


def track(tracking: Tracking, segment: Segment) -> tuple[LineSegment | None, Segment]:
    """The segment with the tracking axis following its tangent, and the block inserted before it where
    the angle changes by more than ``ANGLIMIT`` (None where it does not). The tracking axis' value at the
    segment's start is the previous angle. A segment that does not move in the plane keeps the angle."""
    slot = tracking.slot
    previous = segment.start[slot]
    first = _direction_deg(segment, tracking.plane, 0.0)
    if first is None:
        return None, replace(segment, end=_with(segment.end, slot, previous))
    start_angle = _near(first + tracking.offset, previous)
    inserted: LineSegment | None = None
    begin = previous
    if abs(start_angle - previous) > tracking.anglimit + 1e-9:
        inserted = LineSegment(segment.start, _with(segment.start, slot, start_angle))
        begin = start_angle
    if isinstance(segment, ArcSegment) and segment.plane == tracking.plane:
        end_angle = start_angle + math.degrees(segment.sweep)
    else:
        last = _direction_deg(segment, tracking.plane, segment.length)
        end_angle = start_angle if last is None else _near(last + tracking.offset, start_angle)
    tracked = replace(
        segment, start=_with(segment.start, slot, begin), end=_with(segment.end, slot, end_angle)
    )
    return inserted, tracked
