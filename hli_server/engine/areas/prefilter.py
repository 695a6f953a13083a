"""Which paths of a batch surely keep clear of the active areas (docs/performance.md: ``check
--geometry-only``).

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
  First, and cheaply (one test per path, not per edge): the path's box within the disc inscribed in
  the prism's base region less :data:`MARGIN` (a circle's own; a convex polygon's about its corners'
  mean) and within its height band holds the path, whatever its shape.

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

All the prisms of a group are tested at once, so the cost per batch hardly grows with the number of
areas: a (prisms x paths) box test, then the region tests on the (prism, path) pairs whose boxes meet,
each kind (lines or arcs against circles or polygons) in one numpy pass over its pairs; a polygon's
edges are a row of a table of polygons of about as many edges (padded with copies of an edge, which
change no distance). A group's arrays are built once per group (:func:`_stacks`): the area table
rebuilds its groups only when areas change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hli_server.engine.areas.geometry import Circle, Group, Polygon, Prism

__all__ = ["MARGIN", "PathBatch", "clear_of_areas", "cut_into_chords"]

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
    if groups:
        paths = _swept_boxes(paths)
    for group in groups:
        clear = _group_clear(group, paths, clear)
    return clear


_CARDINAL = np.array([0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi])[:, None]
"""The angles of a circle's extremes: +first axis, +second, -first, -second."""


def cut_into_chords(groups: list[Group], plane: tuple[int, int]) -> bool:
    """Does the exact check cut the arcs of ``plane`` into chords for some group (a prism sees them at
    an angle)? Then an arc costs it hundreds of chords."""
    return any(_stacks(group).plane(plane).chords for group in groups)


def _swept_boxes(p: PathBatch) -> PathBatch:
    """``p`` with each arc's box shrunk from its whole circle to what its path covers: its start, its
    programmed end, the circle's point at the end of the sweep (the end may lie off the circle) and the
    circle's extremes on its sweep (angles within :data:`_ANGLE_TOLERANCE` of it counted as on it).
    The exact check's path, and every chord it cuts an arc into, lies within that box."""
    k = np.flatnonzero(p.arc)
    if not k.shape[0] or p.plane is None:
        return p
    i, j = p.plane
    cx, cy, r = p.centre[0, k], p.centre[1, k], p.radius[k]
    a0, sweep = p.start_angle[k], p.sweep[k]
    a1 = a0 + sweep
    on = _on_sweep(_CARDINAL, a0, sweep)
    lo, hi = p.lo.copy(), p.hi.copy()
    si, sj, ei, ej = p.start[i, k], p.start[j, k], p.end[i, k], p.end[j, k]
    at_i, at_j = cx + r * np.cos(a1), cy + r * np.sin(a1)
    hi[i, k] = np.where(on[0], cx + r, np.maximum(np.maximum(si, ei), at_i))
    hi[j, k] = np.where(on[1], cy + r, np.maximum(np.maximum(sj, ej), at_j))
    lo[i, k] = np.where(on[2], cx - r, np.minimum(np.minimum(si, ei), at_i))
    lo[j, k] = np.where(on[3], cy - r, np.minimum(np.minimum(sj, ej), at_j))
    return PathBatch(p.start, p.end, lo, hi, p.arc, p.plane, p.centre, p.radius, p.start_angle, p.sweep)


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


# --- a group's prisms as arrays ----------------------------------------------------------------------
class _Table:
    """Polygons with about as many edges (``width``: a power of two) and the same ``convex``, one row
    each: their edges (x0, y0, x1, y1) and, for convex ones, half-planes (unit outward normals ``nx``,
    ``ny``; ``line``: the edge's line ``n . p = line``; ``off``: ``line`` less :data:`MARGIN`), a short
    polygon's row filled up with copies of its first edge (``real``: not a copy); a copy changes no
    least distance and no half-plane test, and the even-odd count skips it."""

    __slots__ = ("convex", "line", "nx", "ny", "off", "real", "rows", "width", "x0", "x1", "y0", "y1")

    def __init__(self, convex: bool, width: int, polygons: list[Polygon]) -> None:
        self.convex = convex
        self.width = width
        self.rows = len(polygons)
        shape = (self.rows, width)
        self.x0: Floats = np.zeros(shape)
        self.y0: Floats = np.zeros(shape)
        self.x1: Floats = np.zeros(shape)
        self.y1: Floats = np.zeros(shape)
        self.nx: Floats = np.full(shape, np.nan)
        self.ny: Floats = np.full(shape, np.nan)
        self.off: Floats = np.full(shape, np.nan)
        self.real: Bools = np.zeros(shape, np.bool_)
        for row, poly in enumerate(polygons):
            x0, y0, x1, y1 = _edges(poly)
            n = int(x0.shape[1])
            fill = np.concatenate([np.arange(n), np.zeros(width - n, np.int64)])
            self.x0[row] = x0[0, fill]
            self.y0[row] = y0[0, fill]
            self.x1[row] = x1[0, fill]
            self.y1[row] = y1[0, fill]
            self.real[row, :n] = True
            halves = _half_planes(poly) if convex else None
            if halves is not None:
                nx, ny, off = halves
                self.nx[row] = nx[0, fill]
                self.ny[row] = ny[0, fill]
                self.off[row] = off[0, fill]
        self.line: Floats = self.off + MARGIN


class _Stack:
    """The work or the protection prisms of a group as arrays, one entry per prism: its axes (rows a,
    b, c), its box bounds with :data:`MARGIN` (protection: grown, apart beyond them; work: shrunk,
    around within them), its circle, or its polygon's table and row in it."""

    __slots__ = (
        "axes",
        "circle",
        "core_r2",
        "core_x",
        "core_y",
        "cx",
        "cy",
        "lower",
        "prisms",
        "r",
        "row",
        "shared",
        "size",
        "table",
        "tables",
        "upper",
    )

    def __init__(self, prisms: list[Prism], protection: bool) -> None:
        m = len(prisms)
        self.prisms = prisms
        self.size = m
        self.axes: Ints = np.array(
            [[q.a for q in prisms], [q.b for q in prisms], [q.c for q in prisms]], np.int64
        ).reshape(3, m)
        self.shared = [int(row[0]) if m and (row == row[0]).all() else -1 for row in self.axes]
        """Per row (a, b, c): the axis every prism has there, or -1."""
        lower = np.zeros((3, m, 1))
        upper = np.zeros((3, m, 1))
        self.circle: Bools = np.zeros(m, np.bool_)
        self.cx: Floats = np.zeros(m)
        self.cy: Floats = np.zeros(m)
        self.r: Floats = np.zeros(m)
        self.table: Ints = np.full(m, -1, np.int64)
        self.row: Ints = np.zeros(m, np.int64)
        self.core_x: Floats = np.zeros((m, 1))
        self.core_y: Floats = np.zeros((m, 1))
        self.core_r2: Floats = np.full((m, 1), -1.0)
        """Per prism a disc inside its base region with :data:`MARGIN` to spare (centre, squared
        radius; -1 where none is known: a polygon that is not convex)."""
        keys: list[tuple[bool, int]] = []
        members: list[list[Polygon]] = []
        for k, q in enumerate(prisms):
            x0, y0, x1, y1 = q.region.bbox
            if protection:
                lower[:, k, 0] = (x0 - MARGIN, y0 - MARGIN, q.lo - MARGIN)
                upper[:, k, 0] = (x1 + MARGIN, y1 + MARGIN, q.hi + MARGIN)
            else:
                lower[:, k, 0] = (x0 + MARGIN, y0 + MARGIN, q.lo + MARGIN)
                upper[:, k, 0] = (x1 - MARGIN, y1 - MARGIN, q.hi - MARGIN)
            region = q.region
            if isinstance(region, Circle):
                self.circle[k] = True
                self.cx[k] = region.cx
                self.cy[k] = region.cy
                self.r[k] = region.r
                self._core(k, region.cx, region.cy, region.r - MARGIN)
                continue
            halves = _half_planes(region)
            if halves is not None:
                # the disc about the corners' mean that every half-plane (less MARGIN) holds
                nx, ny, off = halves
                mx, my = np.mean(np.array(region.points, dtype=np.float64), axis=0)
                self._core(k, float(mx), float(my), float(np.min(off - (nx * mx + ny * my))))
            key = (
                halves is not None,
                1 << (len(region.points) - 1).bit_length(),
            )
            if key not in keys:
                keys.append(key)
                members.append([])
            t = keys.index(key)
            self.table[k] = t
            self.row[k] = len(members[t])
            members[t].append(region)
        self.lower: Floats = lower
        self.upper: Floats = upper
        self.tables = [_Table(key[0], key[1], polygons) for key, polygons in zip(keys, members, strict=True)]

    def _core(self, k: int, x: float, y: float, radius: float) -> None:
        if radius > 0.0:
            self.core_x[k, 0], self.core_y[k, 0], self.core_r2[k, 0] = x, y, radius * radius


class _Stacks:
    """A group's prisms as arrays (built once per group: a group is rebuilt when its areas change),
    and per plane of the arcs how its prisms see them."""

    __slots__ = ("planes", "prots", "works")

    def __init__(self, group: Group) -> None:
        self.prots = _Stack(group.prots, protection=True)
        self.works = _Stack(group.works, protection=False)
        self.planes: dict[tuple[int, int] | None, _Plane] = {}

    def plane(self, plane: tuple[int, int] | None) -> _Plane:
        seen = self.planes.get(plane)
        if seen is None:
            seen = _Plane(self, plane)
            self.planes[plane] = seen
        return seen


class _Plane:
    """How the prisms of a group see the arcs of one plane, per stack (protection, work), as
    :class:`_Relations`; ``chords``: some prism of the group sees them at an angle, and the exact
    check cuts them into chords for every prism of the group (``geometry._pieces``)."""

    __slots__ = ("chords", "prot", "work")

    def __init__(self, stacks: _Stacks, plane: tuple[int, int] | None) -> None:
        relations = [_relation(q, plane) for q in stacks.prots.prisms + stacks.works.prisms]
        self.chords = _MIXED in relations
        self.prot = _Relations(stacks.prots, plane)
        self.work = _Relations(stacks.works, plane)


class _Relations:
    """Per prism of a stack, how it sees the arcs of one plane: as lines from start to end
    (``linear``: the plane has none of the prism's axes), as arcs (``circle``: the plane is the
    prism's base plane; ``swap`` where the prism's axes are (j, i)), or at an angle (``mixed``; then
    ``a_in``/``b_in``: the prism's first/second base axis is one of the plane's)."""

    __slots__ = ("a_in", "b_in", "circle", "linear", "mixed", "swap")

    def __init__(self, stack: _Stack, plane: tuple[int, int] | None) -> None:
        rel = [_relation(q, plane) for q in stack.prisms]
        i, j = plane if plane is not None else (-1, -1)
        m = stack.size

        def flags(values: list[bool]) -> Bools:
            return np.array(values, np.bool_).reshape(m)

        self.linear = flags([x == _LINEAR for x in rel])
        self.circle = flags([x == _CIRCLE for x in rel])
        self.mixed = flags([x == _MIXED for x in rel])
        self.swap = flags([x == _CIRCLE and q.a != i for x, q in zip(rel, stack.prisms, strict=True)])
        self.a_in = flags([q.a in (i, j) for q in stack.prisms])
        self.b_in = flags([q.b in (i, j) for q in stack.prisms])


_STACKS: dict[int, tuple[Group, _Stacks]] = {}


def _stacks(group: Group) -> _Stacks:
    """The group's arrays, cached per group (the entry holds the group: its id is not reused)."""
    cached = _STACKS.get(id(group))
    if cached is not None and cached[0] is group:
        return cached[1]
    stacks = _Stacks(group)
    if len(_STACKS) > 64:
        _STACKS.clear()
    _STACKS[id(group)] = (group, stacks)
    return stacks


# --- the test ----------------------------------------------------------------------------------------
def _group_clear(group: Group, p: PathBatch, clear: Bools) -> Bools:
    """``clear`` less the paths that might fail the group's check. All prisms of the group at once: a
    (prisms x paths) box test, then the region tests on the (prism, path) pairs whose boxes meet."""
    stacks = _stacks(group)
    plane = stacks.plane(p.plane)
    ok = clear.copy()
    prots = stacks.prots
    if prots.size:
        prism, path = _box_pairs(prots, p, ok, protection=True)
        if path.shape[0]:
            apart = _pairs(prots, p, prism, path, plane.prot, plane.chords, True)
            ok[path[~apart]] = False
    works = stacks.works
    if works.size:
        # arcs the exact check cuts into chords are never cleared inside a work area
        inside = _in_cores(works, p, ok & ~p.arc if plane.chords else ok)
        rest = ok & ~inside
        prism, path = _box_pairs(works, p, rest, protection=False)
        if path.shape[0]:
            held = _pairs(works, p, prism, path, plane.work, plane.chords, False)
            inside[path[held]] = True
        ok &= inside
    return ok


def _in_cores(st: _Stack, p: PathBatch, ok: Bools) -> Bools:
    """The paths among ``ok`` whose box lies within some work prism's core disc (:attr:`_Stack.core_r2`)
    and height band (less MARGIN): inside that prism whatever their shape, for a path lies within its
    box - no region test (a path inside the disc is more than MARGIN from every edge)."""
    far: list[Floats] = []
    for row, centre in ((0, st.core_x), (1, st.core_y)):
        lo, hi = _box_rows(st, p, row)
        far.append(np.maximum(np.abs(lo - centre), np.abs(hi - centre)))
    lo, hi = _box_rows(st, p, 2)
    within: Bools = (
        (far[0] * far[0] + far[1] * far[1] < st.core_r2) & (lo >= st.lower[2]) & (hi <= st.upper[2])
    )
    held: Bools = ok & within.any(axis=0)
    return held


def _box_rows(st: _Stack, p: PathBatch, row: int) -> tuple[Floats, Floats]:
    """The paths' box bounds on the prisms' axis of ``row`` (a, b, c): the row as it is where every prism
    has that axis (no copy per prism), else one row per prism."""
    axis = st.shared[row]
    if axis >= 0:
        return p.lo[axis], p.hi[axis]
    axes = st.axes[row]
    return p.lo[axes], p.hi[axes]


def _box_pairs(st: _Stack, p: PathBatch, ok: Bools, protection: bool) -> tuple[Ints, Ints]:
    """The (prism, path) pairs, among the paths still ``ok``, that the box test leaves to the region
    tests: protection - the boxes meet (the prism's grown by MARGIN); work - the path's box lies within
    the prism's (shrunk by MARGIN). Where the prisms share their axes, each row of the paths' boxes is
    compared as it is (no copy per prism)."""
    n = ok.shape[0]
    hit = ok
    for row in range(3):
        lo, hi = _box_rows(st, p, row)
        if protection:
            hit = hit & (lo <= st.upper[row]) & (hi >= st.lower[row])
        else:
            hit = hit & (lo >= st.lower[row]) & (hi <= st.upper[row])
    flat: Ints = np.flatnonzero(hit)
    prism: Ints = flat // n
    return prism, flat - prism * n


def _pairs(
    st: _Stack, p: PathBatch, prism: Ints, path: Ints, rel: _Relations, chords: bool, protection: bool
) -> Bools:
    """For (prism, path) pairs whose boxes meet: protection - the path keeps off the prism's region;
    work - the path lies inside it; in the prism's base plane, with :data:`MARGIN`. False where not
    sure: an arc that the prism sees in its base plane while another prism of the group sees it at an
    angle (the exact check's chords are not tested), an arc the prism sees at an angle whose
    projection is not a segment.

    An arc that the prism sees at an angle (a G18 arc against a G17 area) is cut into chords by the
    exact check, and every chord lies within the arc's box (:func:`_swept_boxes`). Projected onto the
    prism's base plane, that box is a segment - from the box's low to its high end along the base axis
    that is one of the arc's plane, where the other base axis does not move (no helix across the
    base) - or, where neither base axis is one of the plane's, the line from start to end (those axes
    move linearly along the arc). Such segments are tested as lines (the height is the box test's)."""
    result = np.zeros(prism.shape[0], np.bool_)
    arcs = p.arc[path]
    plane = p.plane
    a, b = _axis(st, 0, prism), _axis(st, 1, prism)
    # segments in the prism's base plane: lines, arcs whose plane has none of the prism's axes (a line
    # from start to end for it), arcs it sees at an angle (projected)
    segment = ~arcs | rel.linear[prism]
    mixed = arcs & rel.mixed[prism] if plane is not None else None
    candidates = segment if mixed is None or not mixed.any() else segment | mixed
    k = np.flatnonzero(candidates)
    if k.shape[0]:
        # gathered for the candidate pairs only (arcs in the prism's base plane are tested as arcs)
        pk, qk = prism[k], path[k]
        ak, bk = _sub(a, k), _sub(b, k)
        sx, sy, ex, ey = _at(p.start, ak, qk), _at(p.start, bk, qk), _at(p.end, ak, qk), _at(p.end, bk, qk)
        chosen = segment[k]
        if mixed is not None and candidates is not segment:
            mk = mixed[k]
            a_in, b_in = rel.a_in[pk] & mk, rel.b_in[pk] & mk
            sx = np.where(a_in, _at(p.lo, ak, qk), sx)
            ex = np.where(a_in, _at(p.hi, ak, qk), ex)
            sy = np.where(b_in, _at(p.lo, bk, qk), sy)
            ey = np.where(b_in, _at(p.hi, bk, qk), ey)
            chosen = chosen | (mk & ((a_in & (sy == ey)) | (b_in & (sx == ex)) | (~a_in & ~b_in)))
        if not chosen.all():
            c = np.flatnonzero(chosen)
            k, pk, sx, sy, ex, ey = k[c], pk[c], sx[c], sy[c], ex[c], ey[c]
        if k.shape[0]:
            result[k] = _segments(st, pk, st.circle[pk], sx, sy, ex, ey, protection)
    if plane is not None and not chords:
        as_arc = arcs & rel.circle[prism]
        if as_arc.any():
            round_ = st.circle[prism]
            k = np.flatnonzero(as_arc & round_)
            if k.shape[0]:
                result[k] = _arc_circle(st, p, plane, prism[k], path[k], rel.swap[prism[k]], protection)
            k = np.flatnonzero(as_arc & ~round_)
            if k.shape[0]:
                result[k] = _arc_polygon(st, p, plane, prism[k], path[k], rel.swap[prism[k]], protection)
    return result


def _segments(
    st: _Stack,
    prism: Ints,
    round_: Bools,
    sx: Floats,
    sy: Floats,
    ex: Floats,
    ey: Floats,
    protection: bool,
) -> Bools:
    """Segments (in each prism's base plane) against circle and polygon prisms."""
    result = np.zeros(prism.shape[0], np.bool_)
    k = np.flatnonzero(round_)
    if k.shape[0]:
        result[k] = _line_circle(st, prism[k], sx[k], sy[k], ex[k], ey[k], protection)
    k = np.flatnonzero(~round_)
    if k.shape[0]:
        result[k] = _line_polygon(st, prism[k], sx[k], sy[k], ex[k], ey[k], protection)
    return result


def _axis(st: _Stack, row: int, prism: Ints) -> int | Ints:
    """The prisms' axis of ``row`` (a, b, c): one number where they share it, else one per pair."""
    shared = st.shared[row]
    if shared >= 0:
        return shared
    axes: Ints = st.axes[row, prism]
    return axes


def _sub(axis: int | Ints, k: Ints) -> int | Ints:
    if isinstance(axis, int):
        return axis
    taken: Ints = axis[k]
    return taken


def _at(values: Floats, axis: int | Ints, path: Ints) -> Floats:
    """``values[axis, path]``: a row taken where the axis is shared (a third of the cost)."""
    taken: Floats = values[axis].take(path) if isinstance(axis, int) else values[axis, path]
    return taken


def _by_table(st: _Stack, prism: Ints) -> list[tuple[Ints, _Table, Ints]]:
    """The pairs of polygon prisms split by table: (the pairs, the table, each pair's row in it)."""
    if len(st.tables) == 1:
        return [(np.arange(prism.shape[0]), st.tables[0], st.row[prism])]
    which = st.table[prism]
    parts: list[tuple[Ints, _Table, Ints]] = []
    for t, table in enumerate(st.tables):
        k = np.flatnonzero(which == t)
        if k.shape[0]:
            parts.append((k, table, st.row[prism[k]]))
    return parts


def _take(values: Floats, rows: Ints, table: _Table) -> Floats:
    """The rows of the pairs (a table of one polygon: its row, broadcast)."""
    if table.rows == 1:
        return values
    taken: Floats = values[rows]
    return taken


def _edge_rows(table: _Table, rows: Ints) -> tuple[Floats, Floats, Floats, Floats]:
    return (
        _take(table.x0, rows, table),
        _take(table.y0, rows, table),
        _take(table.x1, rows, table),
        _take(table.y1, rows, table),
    )


# --- lines -------------------------------------------------------------------------------------------
def _line_circle(
    st: _Stack, prism: Ints, sx: Floats, sy: Floats, ex: Floats, ey: Floats, protection: bool
) -> Bools:
    cx, cy, r = st.cx[prism], st.cy[prism], st.r[prism]
    if protection:
        apart: Bools = _point_segment(cx, cy, sx, sy, ex, ey) > r + MARGIN
        return apart
    limit = r - MARGIN
    within: Bools = (_norm(sx - cx, sy - cy) < limit) & (_norm(ex - cx, ey - cy) < limit)
    return within


def _line_polygon(
    st: _Stack, prism: Ints, sx: Floats, sy: Floats, ex: Floats, ey: Floats, protection: bool
) -> Bools:
    result = np.zeros(prism.shape[0], np.bool_)
    for k, table, rows in _by_table(st, prism):
        x, y = sx[k][:, None], sy[k][:, None]
        u, v = ex[k][:, None], ey[k][:, None]
        if table.convex:
            nx, ny = _take(table.nx, rows, table), _take(table.ny, rows, table)
            if protection:
                result[k] = _separated(x, y, u, v, nx, ny, _take(table.line, rows, table), table, rows)
                continue
            # convex work polygon: the segment lies inside with the margin when both ends do
            off = _take(table.off, rows, table)
            start_in = np.all(x * nx + y * ny < off, axis=1)
            end_in = np.all(u * nx + v * ny < off, axis=1)
            result[k] = start_in & end_in
            continue
        x0, y0, x1, y1 = _edge_rows(table, rows)
        apart = _segment_segment(x, y, u, v, x0, y0, x1, y1).min(axis=1) > MARGIN
        inside = _inside(x0, y0, x1, y1, _take_real(table, rows), x, y)
        result[k] = apart & (~inside if protection else inside)
    return result


def _separated(
    x: Floats,
    y: Floats,
    u: Floats,
    v: Floats,
    nx: Floats,
    ny: Floats,
    line: Floats,
    table: _Table,
    rows: Ints,
) -> Bools:
    """Segments (x, y)-(u, v) more than :data:`MARGIN` apart from convex polygons, by separating axes:
    an edge's outward normal with both ends more than MARGIN beyond its line, or the segment's normal
    with every corner more than MARGIN to one side. A gap along a unit axis is no more than the
    distance, so a separated segment keeps more than MARGIN off (a segment that passes a corner at
    a slant by little more than MARGIN may not be separated: then the exact check decides)."""
    limit = line + MARGIN
    beyond = np.any((x * nx + y * ny > limit) & (u * nx + v * ny > limit), axis=1)
    dx, dy = u - x, v - y
    length = _norm(dx, dy)
    safe = np.where(length > 0.0, length, 1.0)
    side = (_take(table.x0, rows, table) - x) * (-dy / safe) + (_take(table.y0, rows, table) - y) * (
        dx / safe
    )
    aside = (length[:, 0] > 0.0) & ((side.min(axis=1) > MARGIN) | (side.max(axis=1) < -MARGIN))
    separated: Bools = beyond | aside
    return separated


def _take_real(table: _Table, rows: Ints) -> Bools:
    if table.rows == 1:
        return table.real
    taken: Bools = table.real[rows]
    return taken


# --- arcs --------------------------------------------------------------------------------------------
def _arc_circle(
    st: _Stack, p: PathBatch, plane: tuple[int, int], prism: Ints, path: Ints, swap: Bools, protection: bool
) -> Bools:
    """Arcs in the base plane of circle prisms (the circle in the arcs' plane coordinates). First the
    arc's whole circle (protection: every point of it is ``|d - r|`` or more from the prism's centre;
    work: ``d + r`` or less); where that does not decide, the arc with its sweep: the point nearest to
    (protection) or farthest from (work) the prism's centre is where the ray from the arc's centre
    towards (away from) it meets the arc, if it does, else an end of the arc. The programmed end
    counts too (it may lie off the circle)."""
    i, j = plane
    px = np.where(swap, st.cy[prism], st.cx[prism])
    py = np.where(swap, st.cx[prism], st.cy[prism])
    cx, cy, r = p.centre[0, path], p.centre[1, path], p.radius[path]
    dx, dy = px - cx, py - cy
    d = _norm(dx, dy)
    to_end = _norm(px - p.end[i, path], py - p.end[j, path])
    radius = st.r[prism]
    if protection:
        limit = radius + MARGIN
        ok: Bools = (np.abs(d - r) > limit) & (to_end > limit)
    else:
        limit = radius - MARGIN
        ok = (d + r < limit) & (to_end < limit)
    k = np.flatnonzero(~ok & (to_end > limit if protection else to_end < limit))
    if k.shape[0]:
        ok[k] = _arc_circle_swept(p, path[k], px[k], py[k], d[k], limit[k], protection)
    return ok


def _arc_circle_swept(
    p: PathBatch, path: Ints, px: Floats, py: Floats, d: Floats, limit: Floats, protection: bool
) -> Bools:
    cx, cy, r = p.centre[0, path], p.centre[1, path], p.radius[path]
    a0, sweep = p.start_angle[path], p.sweep[path]
    a1 = a0 + sweep
    dx, dy = px - cx, py - cy
    ends = np.minimum if protection else np.maximum
    at_ends = ends(
        _norm(dx - r * np.cos(a0), dy - r * np.sin(a0)), _norm(dx - r * np.cos(a1), dy - r * np.sin(a1))
    )
    if protection:
        towards = _on_sweep(np.arctan2(dy, dx), a0, sweep)
        nearest = np.where(towards, np.minimum(np.abs(d - r), at_ends), at_ends)
        apart: Bools = nearest > limit
        return apart
    away = _on_sweep(np.arctan2(-dy, -dx), a0, sweep)
    farthest = np.where(away, np.maximum(d + r, at_ends), at_ends)
    within: Bools = farthest < limit
    return within


def _arc_polygon(
    st: _Stack, p: PathBatch, plane: tuple[int, int], prism: Ints, path: Ints, swap: Bools, protection: bool
) -> Bools:
    """Arcs in the base plane of polygon prisms (the edges in the arcs' plane coordinates)."""
    i, j = plane
    a, b = _axis(st, 0, prism), _axis(st, 1, prism)
    result = np.zeros(prism.shape[0], np.bool_)
    for k, table, rows in _by_table(st, prism):
        pk = path[k]
        cx, cy, r = p.centre[0, pk][:, None], p.centre[1, pk][:, None], p.radius[pk][:, None]
        ex, ey = p.end[i, pk][:, None], p.end[j, pk][:, None]
        flip = swap[k][:, None]
        swapped = bool(flip.any())
        if table.convex and not protection:
            # convex work polygon: inside every half-plane with the margin - the arc's farthest point
            # along each normal (the circle's, where the normal's direction is on the sweep, else an
            # end of the arc), its start and its programmed end
            nx, ny, off = (
                _take(table.nx, rows, table),
                _take(table.ny, rows, table),
                _take(table.off, rows, table),
            )
            if swapped:
                nx, ny = np.where(flip, ny, nx), np.where(flip, nx, ny)
            centre = cx * nx + cy * ny
            end_in = np.all(ex * nx + ey * ny < off, axis=1)
            held = end_in & np.all(centre + r < off, axis=1)
            # where the whole circle is not inside: the arc, with its sweep
            again = np.flatnonzero(end_in & ~held)
            if again.shape[0]:
                held[again] = _arc_half_planes(p, pk[again], centre[again], r[again], nx, ny, off, again)
            result[k] = held
            continue
        x0, y0, x1, y1 = _edge_rows(table, rows)
        qx0, qy0, qx1, qy1 = x0, y0, x1, y1
        if swapped:
            qx0, qy0 = np.where(flip, y0, x0), np.where(flip, x0, y0)
            qx1, qy1 = np.where(flip, y1, x1), np.where(flip, x1, y1)
        to_arc = _arc_segment(cx, cy, r, p.start_angle[pk][:, None], p.sweep[pk][:, None], qx0, qy0, qx1, qy1)
        to_end = _point_segment(ex, ey, qx0, qy0, qx1, qy1)
        apart = (to_arc.min(axis=1) > MARGIN) & (to_end.min(axis=1) > MARGIN)
        # start and end inside: in the prism's own coordinates, with its own edges (a convex polygon:
        # outside where beyond an edge's line; the points are more than MARGIN from every edge here)
        ak, bk = _sub(a, k), _sub(b, k)
        s_a, s_b = _at(p.start, ak, pk)[:, None], _at(p.start, bk, pk)[:, None]
        e_a, e_b = _at(p.end, ak, pk)[:, None], _at(p.end, bk, pk)[:, None]
        if table.convex:
            hx, hy, line = (
                _take(table.nx, rows, table),
                _take(table.ny, rows, table),
                _take(table.line, rows, table),
            )
            inside_start = np.all(s_a * hx + s_b * hy < line, axis=1)
            inside_end = np.all(e_a * hx + e_b * hy < line, axis=1)
        else:
            real = _take_real(table, rows)
            inside_start = _inside(x0, y0, x1, y1, real, s_a, s_b)
            inside_end = _inside(x0, y0, x1, y1, real, e_a, e_b)
        held = ~inside_start & ~inside_end if protection else inside_start & inside_end
        result[k] = apart & held
    return result


def _arc_half_planes(
    p: PathBatch, path: Ints, centre: Floats, r: Floats, nx: Floats, ny: Floats, off: Floats, rows: Ints
) -> Bools:
    """Arcs inside every half-plane with the margin: the arc's farthest point along each normal is the
    circle's where the normal's direction is on the sweep, else an end of the arc (``centre``: the
    centre's projections; ``nx``, ``ny``, ``off``: the half-planes, of these ``rows`` unless shared)."""
    nx, ny, off = (h if h.shape[0] == 1 else h[rows] for h in (nx, ny, off))
    a0, sweep = p.start_angle[path][:, None], p.sweep[path][:, None]
    a1 = a0 + sweep
    reach = np.maximum(np.cos(a0) * nx + np.sin(a0) * ny, np.cos(a1) * nx + np.sin(a1) * ny)
    reach = np.where(_on_sweep(np.arctan2(ny, nx), a0, sweep), 1.0, reach)
    inside: Bools = np.all(centre + r * reach < off, axis=1)
    return inside


def _on_sweep(angle: Floats, a0: Floats, sweep: Floats) -> Bools:
    """Is ``angle`` on the arc (within :data:`_ANGLE_TOLERANCE`)? Whole circles: always."""
    delta = np.where(sweep >= 0.0, angle - a0, a0 - angle)
    delta = delta - _TAU * np.floor(delta * (1.0 / _TAU))  # in [0, TAU] (as ``%``, cheaper)
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
    ends = np.stack((a0, a1))
    best = _point_segment(cx + r * np.cos(ends), cy + r * np.sin(ends), qx0, qy0, qx1, qy1).min(axis=0)
    ux, uy = qx1 - qx0, qy1 - qy0
    l2 = ux * ux + uy * uy
    safe = np.where(l2 > 0.0, l2, 1.0)
    t = np.where(l2 > 0.0, ((cx - qx0) * ux + (cy - qy0) * uy) / safe, 0.0)
    fx, fy = qx0 + t * ux, qy0 + t * uy
    df = _norm(fx - cx, fy - cy)
    h = np.sqrt(np.maximum(r * r - df * df, 0.0) / safe)
    tt = np.stack((t - h, t + h))
    # the angles of the segment's ends, its foot point and where its line crosses the circle, at once
    dx = np.concatenate((np.stack((qx0, qx1)) - cx, (fx - cx)[None], qx0 + tt * ux - cx))
    dy = np.concatenate((np.stack((qy0, qy1)) - cy, (fy - cy)[None], qy0 + tt * uy - cy))
    on = _on_sweep(np.arctan2(dy, dx), a0, sweep)
    dq = _norm(dx[:2], dy[:2])
    best = np.minimum(best, np.where(on[:2] | (dq <= 1e-12), np.abs(dq - r), inf).min(axis=0))
    foot_on = (t >= 0.0) & (t <= 1.0) & (on[2] | (df <= 1e-12))
    best = np.minimum(best, np.where(foot_on, np.abs(df - r), inf))
    crossing = (df < r) & (l2 > 0.0)
    hit = crossing & ((tt >= -1e-9) & (tt <= 1.0 + 1e-9) & on[3:]).any(axis=0)
    result: Floats = np.where(hit, 0.0, best)
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


def _norm(dx: Floats, dy: Floats) -> Floats:
    """``hypot`` at a third of its cost: the coordinates the parser accepts cannot overflow a square."""
    result: Floats = np.sqrt(dx * dx + dy * dy)
    return result


def _point_segment(
    px: Floats | float, py: Floats | float, ax: Floats, ay: Floats, bx: Floats, by: Floats
) -> Floats:
    dx, dy = bx - ax, by - ay
    l2 = dx * dx + dy * dy
    safe = np.where(l2 > 0.0, l2, 1.0)
    t = np.clip(np.where(l2 > 0.0, ((px - ax) * dx + (py - ay) * dy) / safe, 0.0), 0.0, 1.0)
    result: Floats = _norm(px - (ax + t * dx), py - (ay + t * dy))
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


def _inside(x0: Floats, y0: Floats, x1: Floats, y1: Floats, real: Bools, px: Floats, py: Floats) -> Bools:
    """Even-odd rule (as ``Polygon.classify``), one row per point, its polygon's edges across (those
    not ``real`` skipped); only asked for points farther than MARGIN from every edge."""
    straddles = (y0 > py) != (y1 > py)
    dy = np.where(straddles, y1 - y0, 1.0)
    crossings = straddles & (px < x0 + (py - y0) * (x1 - x0) / dy) & real
    result: Bools = (crossings.sum(axis=1) % 2) == 1
    return result
