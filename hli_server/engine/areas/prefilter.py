"""Which paths of a batch surely keep clear of the active areas (issue 16: ``check --geometry-only``).

The exact path check (:mod:`hli_server.engine.areas.geometry`, C14-15) is the authority. This module only
answers, for many blocks at once with numpy, "this path cannot violate any active area" - conservatively:
a path it does not clear goes to the exact check, which decides. A path is cleared when, for every group
of active areas (C14-14),

* every protection prism is apart from it: their boxes are apart (the path's box: a line's ends, an arc's
  whole circle in its plane), or the path keeps more than :data:`MARGIN` off the protection area's base
  region (a circle: the distance from its centre; a polygon: the distance to every edge and the start
  point outside it);
* and, where the group has work prisms, one of them contains the path with :data:`MARGIN` to spare: its
  height band and box around the path's box, and the path more than :data:`MARGIN` inside its base region
  (a circle: both ends or the arc's whole circle inside; a polygon: no edge within :data:`MARGIN` of the
  path and its start (and an arc's end) inside).

Why that is enough: the exact check finds an event only where the path comes within
:data:`~hli_server.engine.areas.geometry.EPS` (1e-9 mm) of a boundary, and classifies the pieces between
events; a path farther than :data:`MARGIN` (1e-5 mm, ten thousand times EPS and far above the floats'
rounding at any coordinate the parser accepts) from every boundary, outside every protection region and
inside a work region has no event and every piece allowed.

Arcs are exact where the exact check treats them as arcs (in the base plane of a prism: the distance
from a polygon edge to an arc uses its sweep); an arc that some prism of its group sees at an angle is
cut into chords by the exact check: such an arc is cleared only by boxes apart (the chords lie inside
the arc's box) and never inside a work area. The path of an arc is the exact check's: the circle
through its start (its radius) from the start angle over the sweep, and its programmed end point, which
may lie off that circle by the decoder's tolerance (0.01 mm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hli_server.engine.areas.geometry import Circle, Group, Polygon, Prism

__all__ = ["MARGIN", "PathBatch", "clear_of_areas"]

MARGIN = 1e-5
"""mm: a path this far from every boundary is decided without the exact check (project's own)."""
_ANGLE_TOLERANCE = 1e-6
"""rad: an angle this close to an arc's sweep counts as on it (more candidates: conservative)."""
_TAU = 2.0 * math.pi

Floats = npt.NDArray[np.float64]
Bools = npt.NDArray[np.bool_]
Ints = npt.NDArray[np.int64]

_CIRCLE = 0
_LINEAR = 1
_MIXED = 2


@dataclass(frozen=True, slots=True)
class PathBatch:
    """The paths of many motion blocks, one column per block, in machine coordinates (mm).

    ``start``, ``end``, ``lo``, ``hi`` have one row per channel axis; ``lo``/``hi`` are each path's box
    (an arc's whole circle in its plane). Where ``arc`` is set: ``centre`` (2 rows, plane coordinates),
    ``radius`` (at the start), ``start_angle`` and the signed ``sweep`` (2 pi for a whole circle, and
    wherever the direction is not sure) in the arcs' ``plane`` (channel axis indices)."""

    start: Floats
    end: Floats
    lo: Floats
    hi: Floats
    arc: Bools
    plane: tuple[int, int] | None
    centre: Floats
    radius: Floats
    start_angle: Floats
    sweep: Floats


def clear_of_areas(groups: list[Group], paths: PathBatch) -> Bools:
    """True for each path that surely passes the exact path check of every group."""
    clear = np.ones(paths.arc.shape[0], np.bool_)
    for group in groups:
        clear &= _group_clear(group, paths)
    return clear


def _relation(q: Prism, plane: tuple[int, int] | None) -> int:
    """How the arcs' plane meets the prism (as ``Prism.relation`` for one arc)."""
    if plane is None:
        return _LINEAR
    i, j = plane
    if {i, j} == {q.a, q.b}:
        return _CIRCLE
    if i not in (q.a, q.b, q.c) and j not in (q.a, q.b, q.c):
        return _LINEAR
    return _MIXED


def _group_clear(group: Group, p: PathBatch) -> Bools:
    n = p.arc.shape[0]
    ok = np.ones(n, np.bool_)
    # an arc seen at an angle by any prism of the group is cut into chords for all of them (geometry._pieces)
    chords = any(_relation(q, p.plane) == _MIXED for q in group.works + group.prots)
    for q in group.prots:
        x0, y0, x1, y1 = q.region.bbox
        a, b, c = q.a, q.b, q.c
        near = (
            (p.lo[a] <= x1 + MARGIN)
            & (p.hi[a] >= x0 - MARGIN)
            & (p.lo[b] <= y1 + MARGIN)
            & (p.hi[b] >= y0 - MARGIN)
            & (p.lo[c] <= q.hi + MARGIN)
            & (p.hi[c] >= q.lo - MARGIN)
        )
        cand = np.flatnonzero(near & ok)
        if cand.shape[0]:
            ok[cand[~_region_test(q, p, cand, chords, protection=True)]] = False
    if group.works:
        inside = np.zeros(n, np.bool_)
        for w in group.works:
            x0, y0, x1, y1 = w.region.bbox
            a, b, c = w.a, w.b, w.c
            within = (
                (p.lo[c] >= w.lo + MARGIN)
                & (p.hi[c] <= w.hi - MARGIN)
                & (p.lo[a] >= x0 + MARGIN)
                & (p.hi[a] <= x1 - MARGIN)
                & (p.lo[b] >= y0 + MARGIN)
                & (p.hi[b] <= y1 - MARGIN)
            )
            cand = np.flatnonzero(within & ok & ~inside)
            if cand.shape[0]:
                inside[cand[_region_test(w, p, cand, chords, protection=False)]] = True
        ok &= inside
    return ok


def _region_test(q: Prism, p: PathBatch, cand: Ints, chords: bool, protection: bool) -> Bools:
    """For the paths ``cand`` whose box meets the prism's: protection - the path keeps off the region;
    work - the path lies inside it; in the base plane, with :data:`MARGIN`. False where not sure."""
    result = np.zeros(cand.shape[0], np.bool_)
    rel = _relation(q, p.plane)
    arcs = p.arc[cand]
    as_line = ~arcs if rel != _LINEAR else np.ones(cand.shape[0], np.bool_)
    if as_line.any():
        k = cand[as_line]
        sx, sy, ex, ey = p.start[q.a, k], p.start[q.b, k], p.end[q.a, k], p.end[q.b, k]
        result[as_line] = _line_test(q.region, sx, sy, ex, ey, protection)
    if rel == _CIRCLE and not chords:
        as_arc = arcs
        if as_arc.any():
            assert p.plane is not None
            k = cand[as_arc]
            i, j = p.plane
            # the region in the arcs' plane coordinates (swapped where the prism's axes are (j, i))
            swap = (q.a, q.b) != (i, j)
            result[as_arc] = _arc_test(
                q.region,
                swap,
                p.centre[0, k],
                p.centre[1, k],
                p.radius[k],
                p.start_angle[k],
                p.sweep[k],
                p.start[i, k],
                p.start[j, k],
                p.end[i, k],
                p.end[j, k],
                protection,
            )
    return result


# --- lines -------------------------------------------------------------------------------------------
def _line_test(
    region: Polygon | Circle, sx: Floats, sy: Floats, ex: Floats, ey: Floats, protection: bool
) -> Bools:
    if isinstance(region, Circle):
        if protection:
            apart: Bools = _point_segment(region.cx, region.cy, sx, sy, ex, ey) > region.r + MARGIN
            return apart
        limit = region.r - MARGIN
        within: Bools = (np.hypot(sx - region.cx, sy - region.cy) < limit) & (
            np.hypot(ex - region.cx, ey - region.cy) < limit
        )
        return within
    if not protection:
        halves = _half_planes(region)
        if halves is not None:
            # convex: the segment lies inside with the margin when both ends do
            nx, ny, off = halves
            start_in = np.all(sx[:, None] * nx + sy[:, None] * ny < off, axis=1)
            end_in = np.all(ex[:, None] * nx + ey[:, None] * ny < off, axis=1)
            both: Bools = np.logical_and(start_in, end_in)
            return both
    qx0, qy0, qx1, qy1 = _edges(region)
    s = (sx[:, None], sy[:, None], ex[:, None], ey[:, None])
    apart = _segment_segment(*s, qx0, qy0, qx1, qy1).min(axis=1) > MARGIN
    inside = _inside(region, sx, sy)
    return apart & (~inside if protection else inside)


# --- arcs --------------------------------------------------------------------------------------------
def _arc_test(
    region: Polygon | Circle,
    swap: bool,
    cx: Floats,
    cy: Floats,
    r: Floats,
    a0: Floats,
    sweep: Floats,
    sx: Floats,
    sy: Floats,
    ex: Floats,
    ey: Floats,
    protection: bool,
) -> Bools:
    if isinstance(region, Circle):
        px, py = (region.cy, region.cx) if swap else (region.cx, region.cy)
        d = np.hypot(px - cx, py - cy)
        to_end = np.hypot(px - ex, py - ey)
        if protection:
            # every point of the circle through the start is |d - r| or more from the centre
            off_circle: Bools = (np.abs(d - r) > region.r + MARGIN) & (to_end > region.r + MARGIN)
            return off_circle
        limit = region.r - MARGIN
        in_circle: Bools = (d + r < limit) & (to_end < limit)
        return in_circle
    if not protection:
        halves = _half_planes(region)
        if halves is not None:
            # convex: the arc's whole circle and its end inside with the margin
            nx, ny, off = halves
            if swap:
                nx, ny = ny, nx
            reach = cx[:, None] * nx + cy[:, None] * ny + r[:, None]
            circle_in = np.all(reach < off, axis=1)
            end_in = np.all(ex[:, None] * nx + ey[:, None] * ny < off, axis=1)
            all_in: Bools = np.logical_and(circle_in, end_in)
            return all_in
    qx0, qy0, qx1, qy1 = _edges(region)
    if swap:
        qx0, qy0, qx1, qy1 = qy0, qx0, qy1, qx1
    col = (cx[:, None], cy[:, None], r[:, None], a0[:, None], sweep[:, None])
    apart = (_arc_segment(*col, qx0, qy0, qx1, qy1).min(axis=1) > MARGIN) & (
        _point_segment(ex[:, None], ey[:, None], qx0, qy0, qx1, qy1).min(axis=1) > MARGIN
    )
    inside_start = _inside(region, sy, sx) if swap else _inside(region, sx, sy)
    inside_end = _inside(region, ey, ex) if swap else _inside(region, ex, ey)
    result: Bools = apart & (~inside_start & ~inside_end if protection else inside_start & inside_end)
    return result


def _on_sweep(angle: Floats, a0: Floats, sweep: Floats) -> Bools:
    """Is ``angle`` on the arc (within :data:`_ANGLE_TOLERANCE`)? Whole circles: always."""
    delta = np.where(sweep >= 0.0, angle - a0, a0 - angle) % _TAU
    span = np.abs(sweep)
    return (
        (span >= _TAU - _ANGLE_TOLERANCE)
        | (delta <= span + _ANGLE_TOLERANCE)
        | (delta >= _TAU - _ANGLE_TOLERANCE)
    )


def _arc_segment(
    cx: Floats,
    cy: Floats,
    r: Floats,
    a0: Floats,
    sweep: Floats,
    qx0: Floats,
    qy0: Floats,
    qx1: Floats,
    qy1: Floats,
) -> Floats:
    """Least distance between arcs and segments (broadcast): every place the least distance can be -
    an arc's end to the segment, a segment's end to the arc, the segment's foot point from the centre,
    where the segment's line crosses the circle - with angles near the arc counted as on it."""
    a1 = a0 + sweep
    inf = np.inf
    best = np.minimum(
        _point_segment(cx + r * np.cos(a0), cy + r * np.sin(a0), qx0, qy0, qx1, qy1),
        _point_segment(cx + r * np.cos(a1), cy + r * np.sin(a1), qx0, qy0, qx1, qy1),
    )
    for qx, qy in ((qx0, qy0), (qx1, qy1)):
        dq = np.hypot(qx - cx, qy - cy)
        on = _on_sweep(np.arctan2(qy - cy, qx - cx), a0, sweep) | (dq <= 1e-12)
        best = np.minimum(best, np.where(on, np.abs(dq - r), inf))
    ux, uy = qx1 - qx0, qy1 - qy0
    l2 = ux * ux + uy * uy
    safe = np.where(l2 > 0.0, l2, 1.0)
    t = np.where(l2 > 0.0, ((cx - qx0) * ux + (cy - qy0) * uy) / safe, 0.0)
    fx, fy = qx0 + t * ux, qy0 + t * uy
    df = np.hypot(fx - cx, fy - cy)
    foot_on = (t >= 0.0) & (t <= 1.0) & (_on_sweep(np.arctan2(fy - cy, fx - cx), a0, sweep) | (df <= 1e-12))
    best = np.minimum(best, np.where(foot_on, np.abs(df - r), inf))
    h = np.sqrt(np.maximum(r * r - df * df, 0.0) / safe)
    crossing = (df < r) & (l2 > 0.0)
    for tt in (t - h, t + h):
        xx, yy = qx0 + tt * ux, qy0 + tt * uy
        hit = (
            crossing & (tt >= -1e-9) & (tt <= 1.0 + 1e-9) & _on_sweep(np.arctan2(yy - cy, xx - cx), a0, sweep)
        )
        best = np.where(hit, 0.0, best)
    result: Floats = best
    return result


# --- plane helpers -----------------------------------------------------------------------------------
_EDGES: dict[int, tuple[Polygon, tuple[Floats, Floats, Floats, Floats]]] = {}


def _edges(poly: Polygon) -> tuple[Floats, Floats, Floats, Floats]:
    """The polygon's edges as four rows (x0, y0, x1, y1), cached per polygon."""
    cached = _EDGES.get(id(poly))
    if cached is not None and cached[0] is poly:
        return cached[1]
    pts = np.array(poly.points, dtype=np.float64)
    nxt = np.roll(pts, -1, axis=0)
    edges = (pts[None, :, 0], pts[None, :, 1], nxt[None, :, 0], nxt[None, :, 1])
    if len(_EDGES) > 256:
        _EDGES.clear()
    _EDGES[id(poly)] = (poly, edges)
    return edges


_HALVES: dict[int, tuple[Polygon, tuple[Floats, Floats, Floats] | None]] = {}


def _half_planes(poly: Polygon) -> tuple[Floats, Floats, Floats] | None:
    """A convex polygon as half-planes ``n . p < off`` (unit outward normals, offsets less
    :data:`MARGIN`): a point meeting all of them is inside, farther than MARGIN from every edge.
    None for a polygon that is not strictly convex. Cached per polygon."""
    cached = _HALVES.get(id(poly))
    if cached is not None and cached[0] is poly:
        return cached[1]
    pts = np.array(poly.points, dtype=np.float64)
    nxt = np.roll(pts, -1, axis=0)
    after = np.roll(pts, -2, axis=0)
    d = nxt - pts
    turn = d[:, 0] * (after[:, 1] - nxt[:, 1]) - d[:, 1] * (after[:, 0] - nxt[:, 0])
    length = np.hypot(d[:, 0], d[:, 1])
    halves: tuple[Floats, Floats, Floats] | None = None
    if (length > 0.0).all() and ((turn > 0.0).all() or (turn < 0.0).all()):
        sign = 1.0 if turn[0] > 0.0 else -1.0  # counter-clockwise: the inside is left of each edge
        nx = sign * d[:, 1] / length
        ny = -sign * d[:, 0] / length
        off = nx * pts[:, 0] + ny * pts[:, 1] - MARGIN
        halves = (nx[None, :], ny[None, :], off[None, :])
    if len(_HALVES) > 256:
        _HALVES.clear()
    _HALVES[id(poly)] = (poly, halves)
    return halves


def _point_segment(
    px: Floats | float, py: Floats | float, ax: Floats, ay: Floats, bx: Floats, by: Floats
) -> Floats:
    dx, dy = bx - ax, by - ay
    l2 = dx * dx + dy * dy
    safe = np.where(l2 > 0.0, l2, 1.0)
    t = np.clip(np.where(l2 > 0.0, ((px - ax) * dx + (py - ay) * dy) / safe, 0.0), 0.0, 1.0)
    result: Floats = np.hypot(px - (ax + t * dx), py - (ay + t * dy))
    return result


def _segment_segment(
    ax: Floats, ay: Floats, bx: Floats, by: Floats, cx: Floats, cy: Floats, dx: Floats, dy: Floats
) -> Floats:
    """Distance between segments AB and CD (broadcast): 0 where they cross, else the least distance of
    an end to the other segment."""
    ux, uy, vx, vy = bx - ax, by - ay, dx - cx, dy - cy
    o1 = ux * (cy - ay) - uy * (cx - ax)
    o2 = ux * (dy - ay) - uy * (dx - ax)
    o3 = vx * (ay - cy) - vy * (ax - cx)
    o4 = vx * (by - cy) - vy * (bx - cx)
    crossing = (o1 * o2 < 0.0) & (o3 * o4 < 0.0)
    d = np.minimum(
        np.minimum(_point_segment(ax, ay, cx, cy, dx, dy), _point_segment(bx, by, cx, cy, dx, dy)),
        np.minimum(_point_segment(cx, cy, ax, ay, bx, by), _point_segment(dx, dy, ax, ay, bx, by)),
    )
    result: Floats = np.where(crossing, 0.0, d)
    return result


def _inside(poly: Polygon, x: Floats, y: Floats) -> Bools:
    """Even-odd rule (as ``Polygon.classify``); only asked for points farther than MARGIN from every edge."""
    x0, y0, x1, y1 = _edges(poly)
    px, py = x[:, None], y[:, None]
    straddles = (y0 > py) != (y1 > py)
    dy = np.where(straddles, y1 - y0, 1.0)
    crossings = straddles & (px < x0 + (py - y0) * (x1 - x0) / dy)
    result: Bools = (crossings.sum(axis=1) % 2) == 1
    return result
