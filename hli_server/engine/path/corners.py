"""Chamfers and roundings: the corner between two motion blocks replaced by a line or an arc of the
programmed size (G301/G302, issue 33).

The programming manual ("Inserting chamfers and roundings (G301/G302)", PM 206609163; the examples PM
206615051 and 206621707):

* G301 inserts a straight line with the same angle of inclination to both neighbouring contour elements.
  The I word is the distance from the programmed corner to each end of the chamfer, measured along a line
  and as the chord on an arc ("if one or both the contour elements are arcs, this distance is considered
  as chord length");
* G302 inserts an arc of radius I that passes tangentially into both elements; its centre is the
  intersection of the two equidistants at distance I, on the side that keeps the programmed contour as far
  as possible (the inside of the corner);
* no rounding at a tangential transition; a size that would reverse the direction of an element (a
  chamfer or rounding longer than the element) is an error.

Here the corner is computed exactly for lines in any direction and for lines and arcs (circles, not
helices) in one plane: the inserted element is a :class:`~hli_server.engine.geometry.LineSegment` or an
:class:`~hli_server.engine.geometry.ArcSegment`, so the path checks and the planner see the corner as it is
travelled. A rounding between two lines that span more than one coordinate plane (a corner in space) is
an arc in their own plane: it is emitted as chords through support points no more than
:data:`CHORD_TOLERANCE` from the arc, as the contouring curves are (``path/contour.py`` uses the
same).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Final

from hli_server.engine.geometry import ArcSegment, LineSegment, Point, Segment, arc_from_centre, sub_segment
from hli_server.engine.nc.blocks import Block

__all__ = [
    "CHAMFER",
    "CHORD_TOLERANCE",
    "ROUNDING",
    "TANGENTIAL",
    "CornerError",
    "CornerRequest",
    "insert_corner",
]

CHAMFER: Final = 301
ROUNDING: Final = 302
A_REVERSAL: Final = 916003
"""The inserted element would reverse an element's direction (the kernel's ID is not public)."""
A_NOT_SIMULATED: Final = 910110
TANGENTIAL: Final = 1e-6
"""rad: a turn smaller than this is tangential: no corner element is inserted, no contouring curve."""
_EPS: Final = 1e-9
CHORD_TOLERANCE: Final = 0.005
"""mm: the most a chord departs from the curve it stands for: a rounding in space, a contouring curve
(project's own, 5 µm)."""
_TAU: Final = 2.0 * math.pi


@dataclass(frozen=True, slots=True)
class CornerRequest:
    """A chamfer (``kind`` 301) or rounding (302) of ``size`` mm at the end of the held motion, asked for
    by ``block``; ``feed`` (mm/min) is the inserted element's, None for the pre-block's."""

    kind: int
    size: float
    feed: float | None
    block: Block


class CornerError(Exception):
    """The corner cannot be inserted: ``alarm`` and the message."""

    def __init__(self, alarm: int, message: str) -> None:
        super().__init__(message)
        self.alarm = alarm
        self.message = message


def _unit(v: list[float]) -> list[float]:
    n = math.sqrt(sum(x * x for x in v))
    return v if n <= 0.0 else [x / n for x in v]


def _what(kind: int) -> str:
    return "chamfer (G301)" if kind == CHAMFER else "rounding (G302)"


def insert_corner(
    pre: Segment, post: Segment, kind: int, size: float
) -> tuple[Segment, list[Segment], Segment] | None:
    """The pre-block shortened, the inserted element(s) and the post-block shortened; None where the
    transition is tangential (nothing to insert). Raises :class:`CornerError`."""
    if isinstance(pre, LineSegment) and isinstance(post, LineSegment):
        return _lines(pre, post, kind, size)
    return _planar(pre, post, kind, size)


# --- two lines, in any direction -----------------------------------------------------------------------
def _lines(
    pre: LineSegment, post: LineSegment, kind: int, size: float
) -> tuple[Segment, list[Segment], Segment] | None:
    c = pre.end
    u = _unit([b - a for a, b in zip(pre.start, pre.end, strict=True)])
    v = _unit([b - a for a, b in zip(post.start, post.end, strict=True)])
    cos_turn = max(-1.0, min(1.0, sum(a * b for a, b in zip(u, v, strict=True))))
    turn = math.acos(cos_turn)
    if turn < TANGENTIAL:
        return None
    if turn > math.pi - TANGENTIAL:
        raise CornerError(
            A_REVERSAL, f"{_what(kind)} at a reversal of the direction: no corner to insert into"
        )
    d = size if kind == CHAMFER else size * math.tan(turn / 2.0)
    _fits(d, pre.length, post.length, kind, size)
    p1 = tuple(ck - d * uk for ck, uk in zip(c, u, strict=True))
    p2 = tuple(ck + d * vk for ck, vk in zip(c, v, strict=True))
    head = LineSegment(pre.start, p1)
    tail = LineSegment(p2, post.end)
    if kind == CHAMFER:
        return head, [LineSegment(p1, p2)], tail
    moving = [k for k in range(len(c)) if abs(u[k]) > 1e-12 or abs(v[k]) > 1e-12]
    if len(moving) == 2:
        i, j = moving
        cross = u[i] * v[j] - u[j] * v[i]
        side = 1.0 if cross > 0.0 else -1.0
        centre = (p1[i] - side * size * u[j], p1[j] + side * size * u[i])
        arc, _ = arc_from_centre(p1, p2, (i, j), centre, clockwise=side < 0.0)
        return head, [arc], tail
    return head, _chords_in_space(c, u, v, p1, p2, size, turn), tail


def _chords_in_space(
    c: Point, u: list[float], v: list[float], p1: Point, p2: Point, radius: float, turn: float
) -> list[Segment]:
    """The rounding arc in the plane of two lines (a corner in space) as chords."""
    w = _unit([b - a for a, b in zip(u, v, strict=True)])
    distance = radius / math.cos(turn / 2.0)
    q = [ck + distance * wk for ck, wk in zip(c, w, strict=True)]
    a = [pk - qk for pk, qk in zip(p1, q, strict=True)]
    b = [pk - qk for pk, qk in zip(p2, q, strict=True)]
    phi = turn  # the arc's central angle is the turn of the path
    step = 2.0 * math.acos(max(-1.0, 1.0 - CHORD_TOLERANCE / radius)) if radius > CHORD_TOLERANCE else phi
    n = max(2, math.ceil(phi / max(step, 1e-6)))
    sin_phi = math.sin(phi)
    points: list[Point] = [p1]
    for k in range(1, n):
        t = k / n
        fa, fb = math.sin((1.0 - t) * phi) / sin_phi, math.sin(t * phi) / sin_phi
        points.append(tuple(qk + fa * ak + fb * bk for qk, ak, bk in zip(q, a, b, strict=True)))
    points.append(p2)
    return [LineSegment(s, e) for s, e in itertools.pairwise(points)]


def _fits(d: float, pre_length: float, post_length: float, kind: int, size: float) -> None:
    if d > pre_length + _EPS or d > post_length + _EPS:
        raise CornerError(
            A_REVERSAL,
            f"{_what(kind)} I{size:g}: the inserted element needs {d:.4f} mm of each block, the blocks have "
            f"{pre_length:.4f} and {post_length:.4f} mm (the direction of an element would reverse)",
        )


# --- lines and circles in one plane ----------------------------------------------------------------------
def _plane_of(pre: Segment, post: Segment, kind: int) -> tuple[int, int]:
    plane: tuple[int, int] | None = None
    for seg in (pre, post):
        if isinstance(seg, ArcSegment):
            i, j = seg.plane
            if any(
                abs(b - a) > 1e-9
                for k, (a, b) in enumerate(zip(seg.start, seg.end, strict=True))
                if k not in (i, j)
            ):
                raise CornerError(A_NOT_SIMULATED, f"a {_what(kind)} at a helix is not simulated")
            if plane is not None and set(plane) != {i, j}:
                raise CornerError(
                    A_NOT_SIMULATED, f"a {_what(kind)} between circles of two planes is not simulated"
                )
            plane = (i, j)
    assert plane is not None
    for seg in (pre, post):
        if isinstance(seg, LineSegment):
            moved = [k for k, (a, b) in enumerate(zip(seg.start, seg.end, strict=True)) if abs(b - a) > 1e-9]
            if any(k not in plane for k in moved):
                raise CornerError(
                    A_NOT_SIMULATED,
                    f"a {_what(kind)} between a circle and a line out of its plane is not simulated",
                )
    return plane


def _tangent(seg: Segment, s: float, plane: tuple[int, int]) -> tuple[float, float]:
    d = seg.direction_at(s)
    x, y = d[plane[0]], d[plane[1]]
    n = math.hypot(x, y)
    return (x / n, y / n) if n > 0.0 else (0.0, 0.0)


def _planar(
    pre: Segment, post: Segment, kind: int, size: float
) -> tuple[Segment, list[Segment], Segment] | None:
    i, j = _plane_of(pre, post, kind)
    c = pre.end
    t1 = _tangent(pre, pre.length, (i, j))
    t2 = _tangent(post, 0.0, (i, j))
    cross = t1[0] * t2[1] - t1[1] * t2[0]
    turn = math.atan2(abs(cross), t1[0] * t2[0] + t1[1] * t2[1])
    if turn < TANGENTIAL:
        return None
    if turn > math.pi - TANGENTIAL:
        raise CornerError(
            A_REVERSAL, f"{_what(kind)} at a reversal of the direction: no corner to insert into"
        )
    if kind == CHAMFER:
        s1 = pre.length - _along(pre, size, kind)
        s2 = _along(post, size, kind)
    else:
        side = 1.0 if cross > 0.0 else -1.0
        s1, s2, centre = _rounding(pre, post, (i, j), side, size, kind)
    if s1 < -_EPS or s2 > post.length + _EPS:
        _fits(max(pre.length - s1, s2), pre.length, post.length, kind, size)
    s1 = max(s1, 0.0)
    s2 = min(s2, post.length)
    p1 = pre.point_at(s1)
    p2 = post.point_at(s2)
    head = _part(pre, 0.0, s1)
    tail = _part(post, s2, post.length)
    if kind == CHAMFER:
        return head, [LineSegment(p1, p2)], tail
    p1 = _with(c, (i, j), (p1[i], p1[j]))
    p2 = _with(c, (i, j), (p2[i], p2[j]))
    arc, _ = arc_from_centre(p1, p2, (i, j), centre, clockwise=cross < 0.0)
    return head, [arc], tail


def _with(base: Point, plane: tuple[int, int], xy: tuple[float, float]) -> Point:
    out = list(base)
    out[plane[0]], out[plane[1]] = xy
    return tuple(out)


def _along(seg: Segment, chord: float, kind: int) -> float:
    """The path distance that a chord ``chord`` from the segment's end (or start) covers."""
    if isinstance(seg, LineSegment):
        return chord
    if chord > 2.0 * seg.radius + _EPS:
        raise CornerError(
            A_REVERSAL,
            f"{_what(kind)} I{chord:g}: the chord is longer than the circle's diameter "
            f"{2.0 * seg.radius:.4f} mm",
        )
    phi = 2.0 * math.asin(min(1.0, chord / (2.0 * seg.radius)))
    return seg.radius * phi * seg.length / seg.arc_length


def _part(seg: Segment, s0: float, s1: float) -> Segment:
    if s1 - s0 <= 1e-12:
        p = seg.point_at(s0)
        return LineSegment(p, p)
    return sub_segment(seg, s0, s1)


def _offset(
    seg: Segment, plane: tuple[int, int], side: float, size: float, kind: int
) -> tuple[str, tuple[float, ...]]:
    """The equidistant at ``size`` on the side ``side`` (+1 left of the travel direction): a line
    ("L", (px, py, tx, ty)) or a circle ("C", (mx, my, r))."""
    i, j = plane
    if isinstance(seg, LineSegment):
        tx, ty = _tangent(seg, 0.0, plane)
        nx, ny = -ty * side, tx * side
        return "L", (seg.start[i] + size * nx, seg.start[j] + size * ny, tx, ty)
    ccw = seg.sweep > 0.0
    radius = seg.radius - side * size if ccw else seg.radius + side * size
    if radius <= _EPS:
        raise CornerError(
            A_REVERSAL,
            f"{_what(kind)} I{size:g}: larger than the circle's radius {seg.radius:.4f} mm it rounds into",
        )
    return "C", (seg.centre[0], seg.centre[1], radius)


def _intersections(
    a: tuple[str, tuple[float, ...]], b: tuple[str, tuple[float, ...]]
) -> list[tuple[float, float]]:
    if a[0] == "C" and b[0] == "L":
        a, b = b, a
    if a[0] == "L" and b[0] == "L":
        px, py, tx, ty = a[1]
        qx, qy, sx, sy = b[1]
        den = tx * sy - ty * sx
        if abs(den) < 1e-15:
            return []
        lam = ((qx - px) * sy - (qy - py) * sx) / den
        return [(px + lam * tx, py + lam * ty)]
    if a[0] == "L":
        px, py, tx, ty = a[1]
        mx, my, r = b[1]
        fx, fy = px - mx, py - my
        bq = fx * tx + fy * ty
        cq = fx * fx + fy * fy - r * r
        disc = bq * bq - cq
        if disc < -1e-12:
            return []
        root = math.sqrt(max(disc, 0.0))
        return [(px + lam * tx, py + lam * ty) for lam in (-bq - root, -bq + root)]
    m1x, m1y, r1 = a[1]
    m2x, m2y, r2 = b[1]
    d = math.hypot(m2x - m1x, m2y - m1y)
    if d < 1e-12 or d > r1 + r2 + 1e-9 or d < abs(r1 - r2) - 1e-9:
        return []
    along = (r1 * r1 - r2 * r2 + d * d) / (2.0 * d)
    h = math.sqrt(max(r1 * r1 - along * along, 0.0))
    ex, ey = (m2x - m1x) / d, (m2y - m1y) / d
    bx, by = m1x + along * ex, m1y + along * ey
    return [(bx - h * ey, by + h * ex), (bx + h * ey, by - h * ex)]


def _foot(seg: Segment, plane: tuple[int, int], q: tuple[float, float]) -> tuple[float, float]:
    """The path distance of the point of ``seg`` nearest to ``q`` (unclamped for lines), and its distance
    from ``q``."""
    i, j = plane
    if isinstance(seg, LineSegment):
        tx, ty = _tangent(seg, 0.0, plane)
        dx, dy = q[0] - seg.start[i], q[1] - seg.start[j]
        s = dx * tx + dy * ty
        return s, abs(dx * ty - dy * tx)
    angle = math.atan2(q[1] - seg.centre[1], q[0] - seg.centre[0])
    if seg.sweep >= 0.0:
        frac = ((angle - seg.start_angle) % _TAU) / seg.sweep
    else:
        frac = ((seg.start_angle - angle) % _TAU) / -seg.sweep
    if frac > 1.0 + 1e-9:
        frac = frac - _TAU / abs(seg.sweep)  # just before the start: negative, so it fails the range check
    distance = abs(math.hypot(q[0] - seg.centre[0], q[1] - seg.centre[1]) - seg.radius)
    return frac * seg.length, distance


def _rounding(
    pre: Segment, post: Segment, plane: tuple[int, int], side: float, size: float, kind: int
) -> tuple[float, float, tuple[float, float]]:
    """The rounding's tangent points (path distances on the pre- and post-block) and its centre: the
    intersection of the equidistants nearest to the corner whose feet lie on both elements."""
    i, j = plane
    c = (pre.end[i], pre.end[j])
    candidates = _intersections(_offset(pre, plane, side, size, kind), _offset(post, plane, side, size, kind))
    best: tuple[float, float, tuple[float, float]] | None = None
    best_distance = math.inf
    for q in candidates:
        s1, _ = _foot(pre, plane, q)
        s2, _ = _foot(post, plane, q)
        if not (-_EPS <= s1 <= pre.length + _EPS and -_EPS <= s2 <= post.length + _EPS):
            continue
        distance = math.hypot(q[0] - c[0], q[1] - c[1])
        if distance < best_distance:
            best, best_distance = (s1, s2, q), distance
    if best is None:
        raise CornerError(
            A_REVERSAL,
            f"{_what(kind)} I{size:g}: no arc of this radius touches both elements (the direction of an "
            "element would reverse)",
        )
    return best
