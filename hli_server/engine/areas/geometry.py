"""Exact geometry of work and protection areas (C14-04..07, C14-14, C14-15; FCT-C14 section 2.3).

An area is a prism: a closed region of its base plane (a simple polygon or a circle) times the height
band ``[lo, hi]`` along its third axis. Points and paths are the channel's: tuples with one coordinate
per channel axis; a :class:`Prism` knows which three of them are its own (``a``, ``b`` base plane,
``c`` height).

The path check is exact for lines and for arcs in the area's base plane (helices included: the
height is linear along them): every parameter ``f`` in [0, 1] where the path meets a boundary of an
area is computed analytically (segment/segment, segment/circle, circle/circle, height planes), the
path between two such events is on one side of every boundary, so it is classified by its midpoint;
the events themselves are classified as points (a touch counts). The first forbidden event or
interval gives the exact entry point. Arcs that cross the base plane of an area at an angle (an arc
in G18 checked against a G17 area) project to a sinusoid; those are cut into chords whose sagitta
is at most :data:`CHORD_TOLERANCE` ("other curves by segmentation", FCT-C14 Abb. 6).

Boundary rules (FCT-C14 2.3): a work area may be touched from inside (on its boundary is inside), a
protection area may never be touched (on its boundary is a violation). "On" means within
:data:`EPS` of the boundary. Pure Python on purpose: no I/O, no shapely (shapely is the test oracle).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from hli_server.engine.geometry import ArcSegment, LineSegment, Point, Segment

__all__ = [
    "CHORD_TOLERANCE",
    "EPS",
    "INSIDE",
    "ON",
    "OUTSIDE",
    "Circle",
    "Group",
    "Hit",
    "Polygon",
    "Prism",
    "Region",
    "first_violation",
    "point_at",
    "polygon_self_intersection",
]

EPS = 1e-9
"""mm: a point this close to a boundary is on it (project's own)."""
_EPS2 = EPS * EPS
CHORD_TOLERANCE = 1e-4
"""mm: largest sagitta of the chords used for arcs that are not in an area's base plane."""
_MAX_CHORDS = 20_000
_TAU = 2.0 * math.pi

INSIDE = 1
ON = 0
OUTSIDE = -1


# --- angles --------------------------------------------------------------------------------------
def _angle_to_f(theta: float, a0: float, sweep: float, r: float) -> float | None:
    """Path parameter of the arc point at angle ``theta`` (None if the arc does not pass there)."""
    tol = EPS / r + 1e-12
    delta = (theta - a0) % _TAU if sweep >= 0.0 else (a0 - theta) % _TAU
    s = abs(sweep)
    if delta <= s + tol:
        return min(delta / s, 1.0) if s > 0.0 else 0.0
    if delta >= _TAU - tol:
        return 0.0
    return None


def _clamp01(f: float) -> float:
    return 0.0 if f < 0.0 else (1.0 if f > 1.0 else f)


# --- regions of the base plane -------------------------------------------------------------------
class Polygon:
    """A simple polygon (need not be convex), vertices without the closing repetition."""

    __slots__ = ("bbox", "edges", "near", "points")

    def __init__(self, points: list[tuple[float, float]]) -> None:
        self.points = tuple(points)
        n = len(points)
        pairs = [(points[k], points[(k + 1) % n]) for k in range(n)]
        # (x0, y0, dx, dy, |d|², |d|, y1); products, not ``** 2``, which raises OverflowError where a
        # product is inf (the area handler refuses such coordinates before they get here, docs/reliability.md)
        self.edges = tuple(
            (x0, y0, dx, dy, dx * dx + dy * dy, math.hypot(dx, dy), y1)
            for (x0, y0), (x1, y1) in pairs
            for dx, dy in ((x1 - x0, y1 - y0),)
        )
        # each edge's box grown by EPS: only a point inside it can be on the edge
        self.near = tuple(
            (min(x0, x1) - EPS, max(x0, x1) + EPS, min(y0, y1) - EPS, max(y0, y1) + EPS)
            for (x0, y0), (x1, y1) in pairs
        )
        xs = [p[0] for p in points]
        ys = [p[1] for p in points]
        self.bbox = (min(xs), min(ys), max(xs), max(ys))

    def classify(self, x: float, y: float) -> int:
        x0, y0, x1, y1 = self.bbox
        if x < x0 - EPS or x > x1 + EPS or y < y0 - EPS or y > y1 + EPS:
            return OUTSIDE
        inside = False
        for (ex, ey, dx, dy, l2, _, ey1), (nx0, nx1, ny0, ny1) in zip(self.edges, self.near, strict=True):
            if nx0 <= x <= nx1 and ny0 <= y <= ny1:
                wx, wy = x - ex, y - ey
                t = (wx * dx + wy * dy) / l2
                t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
                px, py = wx - t * dx, wy - t * dy
                if px * px + py * py <= _EPS2:
                    return ON
            if (ey > y) != (ey1 > y) and x < ex + (y - ey) * dx / dy:
                inside = not inside
        return INSIDE if inside else OUTSIDE

    def line_events(self, ax: float, ay: float, dx: float, dy: float, out: list[float]) -> None:
        """Parameters f of ``A + f*D`` (f in [0, 1]) where the path meets the boundary."""
        dd = dx * dx + dy * dy
        dlen = math.sqrt(dd)
        tf = EPS / dlen
        eps_d = EPS * dlen
        qx, qy = ax + dx, ay + dy
        sx0, sx1 = (ax, qx) if ax <= qx else (qx, ax)
        sy0, sy1 = (ay, qy) if ay <= qy else (qy, ay)
        for (ex, ey, gx, gy, _, glen, _), (nx0, nx1, ny0, ny1) in zip(self.edges, self.near, strict=True):
            if sx1 < nx0 or sx0 > nx1 or sy1 < ny0 or sy0 > ny1:
                continue  # boxes apart: the edge is farther than EPS from the path
            wx, wy = ex - ax, ey - ay
            den = dx * gy - dy * gx
            cross = wx * dy - wy * dx  # |cross| / |D|: distance of the corner from the path's line
            if abs(den) > 1e-12 * dlen * glen:
                f = (wx * gy - wy * gx) / den
                if -tf <= f <= 1.0 + tf:
                    g = cross / den
                    tg = EPS / glen
                    if -tg <= g <= 1.0 + tg:
                        out.append(_clamp01(f))
            elif abs(cross) <= eps_d:
                # collinear: the overlap's two ends
                f0 = (wx * dx + wy * dy) / dd
                f1 = ((wx + gx) * dx + (wy + gy) * dy) / dd
                lo, hi = (f0, f1) if f0 <= f1 else (f1, f0)
                if hi >= -tf and lo <= 1.0 + tf:
                    out.append(_clamp01(lo))
                    out.append(_clamp01(hi))
            # a corner that the path passes within EPS (a touch at a corner, at any angle)
            if abs(cross) <= eps_d:
                t = (wx * dx + wy * dy) / dd
                if 0.0 <= t <= 1.0:
                    out.append(t)

    def arc_events(self, cx: float, cy: float, r: float, a0: float, sweep: float, out: list[float]) -> None:
        sx0, sx1, sy0, sy1 = cx - r, cx + r, cy - r, cy + r
        for (ex, ey, gx, gy, gg, glen, _), (nx0, nx1, ny0, ny1) in zip(self.edges, self.near, strict=True):
            if sx1 < nx0 or sx0 > nx1 or sy1 < ny0 or sy0 > ny1:
                continue  # the edge is farther than EPS from the whole circle
            t0 = ((cx - ex) * gx + (cy - ey) * gy) / gg
            fx, fy = ex + t0 * gx, ey + t0 * gy
            d = math.hypot(cx - fx, cy - fy)
            if d > r + EPS:
                pass
            else:
                tg = EPS / glen
                if d >= r - EPS:
                    candidates: tuple[float, ...] = (t0,)
                else:
                    dg = math.sqrt(r * r - d * d) / glen
                    candidates = (t0 - dg, t0 + dg)
                for g in candidates:
                    if -tg <= g <= 1.0 + tg:
                        px, py = ex + g * gx, ey + g * gy
                        f = _angle_to_f(math.atan2(py - cy, px - cx), a0, sweep, r)
                        if f is not None:
                            out.append(f)
            # vertex on the circle (within EPS)
            if abs(math.hypot(ex - cx, ey - cy) - r) <= EPS:
                f = _angle_to_f(math.atan2(ey - cy, ex - cx), a0, sweep, r)
                if f is not None:
                    out.append(f)


class Circle:
    """A full circle (the base of a CIRC area)."""

    __slots__ = ("bbox", "cx", "cy", "r")

    def __init__(self, cx: float, cy: float, r: float) -> None:
        self.cx, self.cy, self.r = cx, cy, r
        self.bbox = (cx - r, cy - r, cx + r, cy + r)

    def classify(self, x: float, y: float) -> int:
        d = math.hypot(x - self.cx, y - self.cy)
        if d > self.r + EPS:
            return OUTSIDE
        if d >= self.r - EPS:
            return ON
        return INSIDE

    def line_events(self, ax: float, ay: float, dx: float, dy: float, out: list[float]) -> None:
        dd = dx * dx + dy * dy
        dlen = math.sqrt(dd)
        t0 = ((self.cx - ax) * dx + (self.cy - ay) * dy) / dd
        d = math.hypot(ax + t0 * dx - self.cx, ay + t0 * dy - self.cy)
        r = self.r
        if d > r + EPS:
            return
        tf = EPS / dlen
        if d >= r - EPS:
            candidates: tuple[float, ...] = (t0,)
        else:
            h = math.sqrt(r * r - d * d) / dlen
            candidates = (t0 - h, t0 + h)
        for f in candidates:
            if -tf <= f <= 1.0 + tf:
                out.append(_clamp01(f))

    def arc_events(self, cx: float, cy: float, r: float, a0: float, sweep: float, out: list[float]) -> None:
        ux, uy = self.cx - cx, self.cy - cy
        d = math.hypot(ux, uy)
        r2 = self.r
        if d <= EPS:
            return  # concentric: on the boundary everywhere or nowhere; classification tells
        if d > r + r2 + EPS or d < abs(r - r2) - EPS:
            return
        phi = math.atan2(uy, ux)
        if abs(d - (r + r2)) <= EPS:
            thetas: tuple[float, ...] = (phi,)
        elif abs(d - abs(r - r2)) <= EPS:
            thetas = (phi,) if r >= r2 else (phi + math.pi,)
        else:
            cos_delta = (d * d + r * r - r2 * r2) / (2.0 * d * r)
            delta = math.acos(max(-1.0, min(1.0, cos_delta)))
            thetas = (phi - delta, phi + delta)
        for theta in thetas:
            f = _angle_to_f(theta, a0, sweep, r)
            if f is not None:
                out.append(f)


Region = Polygon | Circle


# --- prisms and paths ----------------------------------------------------------------------------
_REL_CIRCLE = 0
_REL_LINEAR = 1
_REL_MIXED = 2


@dataclass(slots=True, eq=False)
class Prism:
    """One area in 3D: ``region`` in the plane of channel axes (a, b), height band on axis c."""

    region: Region
    a: int
    b: int
    c: int
    lo: float
    hi: float
    area_id: int = 0
    protection: bool = False

    def classify(self, p: Point) -> int:
        h = p[self.c]
        if h < self.lo - EPS or h > self.hi + EPS:
            return OUTSIDE
        base = self.region.classify(p[self.a], p[self.b])
        if base == OUTSIDE:
            return OUTSIDE
        if base == ON or h <= self.lo + EPS or h >= self.hi - EPS:
            return ON
        return INSIDE

    def relation(self, arc: ArcSegment) -> int:
        i, j = arc.plane
        if {i, j} == {self.a, self.b}:
            return _REL_CIRCLE
        if i not in (self.a, self.b, self.c) and j not in (self.a, self.b, self.c):
            return _REL_LINEAR
        return _REL_MIXED

    def _height_events(self, h0: float, h1: float, out: list[float]) -> None:
        dh = h1 - h0
        if dh != 0.0:
            for level in (self.lo, self.hi):
                f = (level - h0) / dh
                if 0.0 <= f <= 1.0:
                    out.append(f)

    def events(self, seg: Segment, out: list[float]) -> bool:
        """Append the boundary events of ``seg``; False when the path's box misses the prism (then
        the prism is OUTSIDE along the whole path). Arcs must not be MIXED (see :func:`_pieces`)."""
        a, b, c = self.a, self.b, self.c
        s, e = seg.start, seg.end
        h0, h1 = s[c], e[c]
        if (h0 < self.lo - EPS and h1 < self.lo - EPS) or (h0 > self.hi + EPS and h1 > self.hi + EPS):
            return False
        bx0, by0, bx1, by1 = self.region.bbox
        if isinstance(seg, ArcSegment) and self.relation(seg) == _REL_CIRCLE:
            cx, cy, a0, sweep = _arc_in_plane(seg, a, b)
            r = seg.radius
            if cx + r < bx0 - EPS or cx - r > bx1 + EPS or cy + r < by0 - EPS or cy - r > by1 + EPS:
                return False
            self.region.arc_events(cx, cy, r, a0, sweep, out)
        else:
            ax, ay, qx, qy = s[a], s[b], e[a], e[b]
            if (
                max(ax, qx) < bx0 - EPS
                or min(ax, qx) > bx1 + EPS
                or max(ay, qy) < by0 - EPS
                or min(ay, qy) > by1 + EPS
            ):
                return False
            dx, dy = qx - ax, qy - ay
            if dx * dx + dy * dy > 0.0:
                self.region.line_events(ax, ay, dx, dy, out)
        self._height_events(h0, h1, out)
        return True


def _arc_in_plane(arc: ArcSegment, a: int, b: int) -> tuple[float, float, float, float]:
    """Centre, start angle and sweep of ``arc`` in the (a, b) coordinates of a prism."""
    if arc.plane == (a, b):
        return arc.centre[0], arc.centre[1], arc.start_angle, arc.sweep
    # swapped axes: (u, v) = (x_j, x_i) -> angle pi/2 - theta, direction reversed
    return arc.centre[1], arc.centre[0], math.pi / 2.0 - arc.start_angle, -arc.sweep


def point_at(seg: Segment, f: float) -> Point:
    """Point of the path at parameter ``f`` in [0, 1] (arcs: angle and linear axes both linear in f)."""
    s, e = seg.start, seg.end
    if isinstance(seg, LineSegment):
        return tuple(x + (y - x) * f for x, y in zip(s, e))  # noqa: B905 compiled: see geometry.py
    if f >= 1.0:
        return e
    i, j = seg.plane
    angle = seg.start_angle + seg.sweep * f
    p = [x + (y - x) * f for x, y in zip(s, e)]  # noqa: B905 compiled: see geometry.py
    p[i] = seg.centre[0] + seg.radius * math.cos(angle)
    p[j] = seg.centre[1] + seg.radius * math.sin(angle)
    return tuple(p)


def _chords(arc: ArcSegment) -> list[LineSegment]:
    ratio = 1.0 - CHORD_TOLERANCE / arc.radius
    step = 2.0 * math.acos(ratio) if ratio > -1.0 else math.pi
    n = max(1, min(_MAX_CHORDS, math.ceil(abs(arc.sweep) / step)))
    pts = [point_at(arc, k / n) for k in range(n + 1)]
    return [LineSegment(pts[k], pts[k + 1]) for k in range(n)]


_Box = tuple[Prism, int, int, int, float, float, float, float, float, float]
"""A prism with its axes and its box grown by EPS: (prism, a, b, c, x0, x1, y0, y1, h0, h1)."""


def _box_of(q: Prism) -> _Box:
    x0, y0, x1, y1 = q.region.bbox
    return (q, q.a, q.b, q.c, x0 - EPS, x1 + EPS, y0 - EPS, y1 + EPS, q.lo - EPS, q.hi + EPS)


def _segment_box(seg: Segment) -> tuple[Point, Point]:
    """Per channel axis the range the path covers (arcs: their full circle in the plane, conservative)."""
    s, e = seg.start, seg.end
    lo = tuple(map(min, s, e))
    hi = tuple(map(max, s, e))
    if isinstance(seg, ArcSegment):
        i, j = seg.plane
        r = seg.radius
        lo_l, hi_l = list(lo), list(hi)
        lo_l[i], hi_l[i] = seg.centre[0] - r, seg.centre[0] + r
        lo_l[j], hi_l[j] = seg.centre[1] - r, seg.centre[1] + r
        return tuple(lo_l), tuple(hi_l)
    return lo, hi


def _candidates(boxes: list[_Box], lo: Point, hi: Point) -> list[Prism]:
    """The prisms whose box the path's box meets (the others are OUTSIDE along the whole path)."""
    return [
        q
        for q, a, b, c, x0, x1, y0, y1, h0, h1 in boxes
        if not (hi[a] < x0 or lo[a] > x1 or hi[b] < y0 or lo[b] > y1 or hi[c] < h0 or lo[c] > h1)
    ]


@dataclass(slots=True)
class Group:
    """The active areas that watch one set of three axes: their allowed space is the union of the
    work prisms (everything if there is none) minus the protection prisms (C14-14). Build it from
    complete lists: the prisms' boxes are indexed once, at construction."""

    axes: frozenset[int]
    works: list[Prism]
    prots: list[Prism]
    work_boxes: list[_Box] = field(init=False, repr=False)
    prot_boxes: list[_Box] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.work_boxes = [_box_of(q) for q in self.works]
        self.prot_boxes = [_box_of(q) for q in self.prots]

    def verdict(self, p: Point) -> Prism | None:
        """None if ``p`` is allowed; else the violated prism (a protection prism first; for "outside
        every work area" the first work prism)."""
        for q in self.prots:
            if q.classify(p) != OUTSIDE:
                return q
        if self.works:
            for w in self.works:
                if w.classify(p) != OUTSIDE:
                    return None
            return self.works[0]
        return None


@dataclass(frozen=True, slots=True)
class Hit:
    """The first violation along a path: parameter ``f``, its point, the violated prism, and whether
    a single point is forbidden (``point``: a touch, or the start itself) or the path beyond it."""

    f: float
    point: Point
    prism: Prism
    point_violation: bool


def _piece_violation(group: Group, seg: Segment) -> tuple[float, Prism, bool] | None:
    events: list[float] = []
    live_works: list[Prism] = []
    live_prots: list[Prism] = []
    lo, hi = _segment_box(seg)
    for q in _candidates(group.prot_boxes, lo, hi):
        if q.events(seg, events):
            live_prots.append(q)
    works_needed = bool(group.works)
    mid: Point | None = None
    for w in _candidates(group.work_boxes, lo, hi):
        n_before = len(events)
        if w.events(seg, events):
            if len(events) == n_before:
                mid = mid or point_at(seg, 0.5)
                inside_all_along = w.classify(mid) == INSIDE
            else:
                inside_all_along = False
            if inside_all_along:
                # strictly inside this work prism all along: the work areas are satisfied
                works_needed = False
                del events[n_before:]
                live_works.clear()
                break
            live_works.append(w)
    if not live_prots and not works_needed:
        return None
    if works_needed and not live_works:
        return 0.0, group.works[0], True  # outside every work area all along
    events.sort()
    points = [0.0]
    for f in events:
        if f - points[-1] > 1e-12:
            points.append(f)
    if 1.0 - points[-1] > 1e-12:
        points.append(1.0)
    else:
        points[-1] = 1.0

    def bad(p: Point) -> Prism | None:
        for q in live_prots:
            if q.classify(p) != OUTSIDE:
                return q
        if works_needed:
            for w in live_works:
                if w.classify(p) != OUTSIDE:
                    return None
            return live_works[0]
        return None

    last = len(points) - 1
    for k, f in enumerate(points):
        at_point = bad(point_at(seg, f))
        if at_point is not None:
            return f, at_point, True
        if k < last:
            beyond = bad(point_at(seg, 0.5 * (f + points[k + 1])))
            if beyond is not None:
                return f, beyond, False
    return None


def _pieces(group: Group, seg: Segment) -> list[LineSegment] | None:
    """Chords for an arc that some prism of the group sees at an angle; None if exact is possible."""
    if isinstance(seg, ArcSegment):
        for q in group.works + group.prots:
            if q.relation(seg) == _REL_MIXED:
                return _chords(seg)
    return None


def _group_violation(group: Group, seg: Segment) -> Hit | None:
    pieces = _pieces(group, seg)
    if pieces is None:
        found = _piece_violation(group, seg)
        if found is None:
            return None
        f, prism, point_violation = found
        return Hit(f, point_at(seg, f), prism, point_violation)
    n = len(pieces)
    for k, piece in enumerate(pieces):
        found = _piece_violation(group, piece)
        if found is not None:
            f, prism, point_violation = found
            return Hit((k + f) / n, point_at(piece, f), prism, point_violation)
    return None


def first_violation(groups: list[Group], seg: Segment) -> Hit | None:
    """The first point of ``seg`` (in path order) that leaves the allowed space, or None (C14-15)."""
    best: Hit | None = None
    for group in groups:
        hit = _group_violation(group, seg)
        if hit is None:
            continue
        if (
            best is None
            or hit.f < best.f - 1e-12
            or (abs(hit.f - best.f) <= 1e-12 and hit.prism.protection and not best.prism.protection)
        ):
            best = hit
    return best


# --- validation of a polygon contour -------------------------------------------------------------
def _orient(ax: float, ay: float, bx: float, by: float, cx: float, cy: float) -> float:
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


def _segments_meet(
    p: tuple[float, float], q: tuple[float, float], r: tuple[float, float], s: tuple[float, float]
) -> tuple[float, float] | None:
    """A common point of segments pq and rs (touching included), or None."""
    d1 = _orient(r[0], r[1], s[0], s[1], p[0], p[1])
    d2 = _orient(r[0], r[1], s[0], s[1], q[0], q[1])
    d3 = _orient(p[0], p[1], q[0], q[1], r[0], r[1])
    d4 = _orient(p[0], p[1], q[0], q[1], s[0], s[1])
    largest = max(1.0, *(abs(v) for pt in (p, q, r, s) for v in pt))
    scale = largest * largest  # not ** 2: that raises OverflowError (docs/reliability.md)
    tol = 1e-12 * scale
    if ((d1 > tol and d2 < -tol) or (d1 < -tol and d2 > tol)) and (
        (d3 > tol and d4 < -tol) or (d3 < -tol and d4 > tol)
    ):
        t = d1 / (d1 - d2)
        return (p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]))

    def on_segment(a: tuple[float, float], b: tuple[float, float], c: tuple[float, float], d: float) -> bool:
        return (
            abs(d) <= tol
            and min(a[0], b[0]) - EPS <= c[0] <= max(a[0], b[0]) + EPS
            and min(a[1], b[1]) - EPS <= c[1] <= max(a[1], b[1]) + EPS
        )

    if on_segment(r, s, p, d1):
        return p
    if on_segment(r, s, q, d2):
        return q
    if on_segment(p, q, r, d3):
        return r
    if on_segment(p, q, s, d4):
        return s
    return None


def polygon_self_intersection(
    points: list[tuple[float, float]],
) -> tuple[int, int, tuple[float, float]] | None:
    """Edges k and m (edge k runs from point k to point k+1, closing edge included) that cross or
    touch other than at their shared corner, with a common point; None for a simple polygon."""
    n = len(points)
    edges = [(points[k], points[(k + 1) % n]) for k in range(n)]
    for k in range(n):
        p, q = edges[k]
        for m in range(k + 1, n):
            r, s = edges[m]
            if m == k + 1 or (k == 0 and m == n - 1):
                # neighbours share one corner; they must not fold back onto each other
                shared = q if m == k + 1 else p
                other_k = p if m == k + 1 else q
                other_m = s if m == k + 1 else r
                if abs(_orient(*shared, *other_k, *other_m)) <= 1e-12 * max(
                    1.0, math.dist(shared, other_k) * math.dist(shared, other_m)
                ):
                    ux, uy = other_k[0] - shared[0], other_k[1] - shared[1]
                    vx, vy = other_m[0] - shared[0], other_m[1] - shared[1]
                    if ux * vx + uy * vy > 0.0:
                        nearer = (
                            other_k if math.dist(shared, other_k) < math.dist(shared, other_m) else other_m
                        )
                        return k, m, nearer
                continue
            meet = _segments_meet(p, q, r, s)
            if meet is not None:
                return k, m, meet
    return None
