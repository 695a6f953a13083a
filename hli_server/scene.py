"""The picture of a channel's areas and path, as data: one scene for ``check --plot`` and the dashboard.

``hli-server check --plot`` (drawn by :mod:`hli_server.plot` with matplotlib) and the live dashboard
(drawn in the browser from the same JSON, served by the HTTP API) show the same thing because both draw
the scene this module computes; neither does geometry of its own. The module is pure: standard library
and :mod:`schemas` only (no matplotlib, no engine, no runtime, no adapters), so any side can import it.

Why a scene and not a projection: a plain projection of the path on the base plane draws a path that
passes 100 mm above a protection cylinder straight through it (docs/dashboard.md). An area is a prism (FCT-C14
2.3: base region times the height band ``MIN_EXCUR..MAX_EXCUR``), so the scene says for every area
whether the path goes through the prism, passes above or below it, or never comes over its base region,
and where along the path that happens, so a picture can show height: a side view of the height along
the path with the bands of the areas it passes over.

The inputs are what ``check`` has at hand (:func:`build_scene`): the area table JSON
(``AreaMonitor.areas_json`` / ``channel_areas(m, n).to_json()``), the recorded path points (one value
per channel axis), the channel's axis names and main axes, the alarms as ``check --format json``
lists them (the params of 120484 / 120486 / 912000 / 912001 carry the refused block's ``start``,
``end``, ``arc`` and the exact ``intersection``, those of the software limits' 120002 / 120003 the same
with the ``axis`` whose limit the block would cross and the point where it would; those of 50961 / 50962
and an ``ON`` refusal the ``position``), and the point where the axes stopped.

Scene JSON (version 1)
----------------------
Lengths in mm, rounded to the machine's resolution (0.1 µm = 1e-4 mm, :data:`RESOLUTION_MM`).
A *view point* is ``[a, b, h, s]``: the two coordinates of the view's base plane, the height (``null``
when the channel has no height axis), and ``s``, the path length in the base plane from the path's first
point (a side view plots ``h`` over ``s``: the path's footprint unrolled, plunges stay vertical)::

    {
      "scene": 1,
      "channel": 1,                            # or null
      "axes": ["X", "Y", "Z"],                 # the channel's axes
      "view": {"a": "X", "b": "Y", "height": "Z"},   # height: null if the channel has none
      "bounds": {"a": [lo, hi], "b": [lo, hi], "height": [lo, hi] | null, "s": [0, s_end]},
      "areas": [{
          "id": 4, "kind": "PROT" | "WORK", "state": "active" | "inactive" | "defined",
          "shape": "CIRC" | "POLY",
          "axes": ["X", "Y"], "height_axis": "Z", "min": -70.0, "max": 70.0,
          "center": [0.0, 75.0], "radius": 75.0,          # CIRC
          "points": [[x, y], ...],                        # POLY: corners, no closing repetition
          "source": "N20..N30 (lines 2..3)",
          "in_view": true,        # its base plane is the view's (drawn in the top view)
          "band_in_view": true,   # in view and its height axis is the view's (band drawn in the side view)
          "relation": "crosses" | "above" | "below" | "above_and_below" | "apart",
          "spans": [{"from": s0, "to": s1, "relation": "crosses" | "above" | "below" | "above_and_below",
                     "refused": false}],
          "relation_text": "the refused block N70 would enter it; the axes stopped before it"
      }],
      "path": [[[a, b, h, s], ...]],           # polylines of the path the axes travelled
      "refused": null | {"alarm": 912001, "line": 7, "block": "N70", "area": 4, "kind": "PROT",
                         "axis": null, "cause": "area 4",
                         "points": [[a, b, h, s], ...]},  # the refused block (arcs sampled)
      "violation": null | {"alarm": 912001, "area": 4, "kind": "PROT", "axis": null, "cause": "area 4",
                           "point": [a, b, h, s], "position": {"X": -75.0, "Y": 75.0, "Z": 0.0}},
                           # a software limit's refusal (120002/120003): "area" and "kind" null, "axis"
                           # the axis whose limit the block would cross, "point" where it would, "cause"
                           # "the software limit of X (600.0000 mm)"
      "stop": null | [a, b, h, s],             # where the axes came to rest after an error
      "position": null | [a, b, h, s],         # live: where the axes are now (the TCP)
      "ahead": [[a, b, h, s], ...]             # live: the programmed path ahead, from ``position``
    }

``relation`` is over the whole programmed path the check reached: the travelled path and the refused
block. ``crosses``: part of it is inside the prism (over the base region and within the height band,
boundaries included: the engine counts a touch, C14-15); ``above`` / ``below``: it is over the base
region only above / below the band; ``above_and_below``: both, never inside; ``apart``: it never comes
over the base region. ``spans`` are the stretches of ``s`` where the path is over the base region, with
the relation on each (``refused``: the stretch belongs to the refused block); a touch is a span with
``from == to``. ``relation_text`` says it in words for a legend, and says what happened
(:func:`relation_text`): the refused block that would have entered (or left) the area, the axes that
reached it, or how the travelled path meets it. The relation is computed on the recorded points joined
by straight lines (``check`` records every 10th cycle, and arcs every few degrees), so it is a
picture's precision, not the monitor's: the monitor's exact verdict is the alarm.

``position`` and ``ahead`` are the live dashboard's (``check`` leaves them ``null`` and empty): the TCP
and the path the channel has decoded ahead of it (its look-ahead), ``s`` going on from the travelled path's
end. The path ahead is drawn, not related to the areas: the channel checked each of its blocks against the
active areas when it decoded it (C14-15), and a refused block is the ``refused`` entry.

The view is the plane most areas share (the channel's main axes in ``plane`` when there are none);
areas on other axes (X2/Y2, FCT-C14 section 4) have ``in_view`` false and still a relation. The path's
polylines are simplified (points within ``tolerance`` of the drawn line dropped) after the relations
are computed, so long programs give a scene of a size a browser draws.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from schemas.units import INCREMENTS_PER_MM

__all__ = [
    "RELATIONS",
    "RESOLUTION_MM",
    "SCENE_VERSION",
    "build_scene",
    "relation_text",
    "round_mm",
    "round_numbers",
]

SCENE_VERSION = 1
RESOLUTION_MM = 1.0 / INCREMENTS_PER_MM
"""0.1 µm: the resolution of positions at the interface; numbers shown to people are rounded to it."""
_SCALE = float(INCREMENTS_PER_MM)

RELATIONS = ("crosses", "above", "below", "above_and_below", "apart")
"""How the path meets an area's prism, from the most to the least concerning."""

_PLANES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}
"""G17/G18/G19: indices into the main axes of the base plane's first, second and the height axis."""
_TOL = 1e-7
"""mm: on a boundary or a band plane within this (below the resolution; the engine uses 1e-9)."""
_ARC_STEP = math.radians(2.0)
"""Refused arcs are drawn with a point every 2° (sagitta 0.015 % of the radius)."""
_SIMPLIFY = 1e-4
"""Default simplification tolerance of the path, relative to the diagonal of the scene's bounds."""


def round_mm(value: float) -> float:
    """``value`` (mm) rounded to the resolution, 0.1 µm: ``100.00000000000001`` -> ``100.0``,
    ``7.105427357601002e-15`` -> ``0.0`` (and never ``-0.0``).

    ``round(value * 10**4) / 10**4`` is the double nearest to the rounded decimal, as ``round(value, 4)``
    is, at a fifth of its cost (a live scene rounds thousands of numbers between two cycles)."""
    if not math.isfinite(value):
        return value
    return round(value * _SCALE) / _SCALE + 0.0


def round_numbers(value: Any) -> Any:
    """Every float in a JSON-like value (dicts, lists, tuples) rounded with :func:`round_mm`; ints,
    strings and the rest unchanged. For alarm params: their floats are lengths in mm (the ints are
    0.1 µm increments or counts), so the resolution is the right precision for all of them."""
    if isinstance(value, float):
        return round_mm(value)
    if isinstance(value, list | tuple):
        return [round_numbers(v) for v in value]
    if isinstance(value, dict | Mapping):
        return {k: round_numbers(v) for k, v in value.items()}
    return value


# --- regions of a base plane ----------------------------------------------------------------------
class _Region:
    """An area's base region (polygon or circle) with the two questions the relation needs."""

    def __init__(self, area: Mapping[str, Any]) -> None:
        self.circle: tuple[float, float, float] | None = None
        self.points: list[tuple[float, float]] = []
        if area.get("shape") == "CIRC":
            cx, cy = area["center"]
            self.circle = (float(cx), float(cy), float(area["radius"]))
        else:
            self.points = [(float(x), float(y)) for x, y in area["points"]]
            if len(self.points) < 3:
                raise ValueError(f"area {area.get('id')}: a POLY area needs 3 corners, got {self.points}")
        if self.circle is not None:
            cx, cy, r = self.circle
            box = (cx - r, cy - r, cx + r, cy + r)
        else:
            xs = [x for x, _ in self.points]
            ys = [y for _, y in self.points]
            box = (min(xs), min(ys), max(xs), max(ys))
        self.box = (box[0] - _TOL, box[1] - _TOL, box[2] + _TOL, box[3] + _TOL)
        """The region's bounding box, widened by the tolerance: a segment outside it is never over it."""

    def far_from(self, p: tuple[float, float], q: tuple[float, float]) -> bool:
        """Is the segment P->Q certainly not over the region (its bounding box misses the region's)?
        The cheap test that keeps a long path's scene fast (most segments are far from most areas)."""
        x0, y0, x1, y1 = self.box
        return max(p[0], q[0]) < x0 or min(p[0], q[0]) > x1 or max(p[1], q[1]) < y0 or min(p[1], q[1]) > y1

    def contains(self, x: float, y: float) -> bool:
        """Inside or on the boundary (within :data:`_TOL`)."""
        if self.circle is not None:
            cx, cy, r = self.circle
            return math.hypot(x - cx, y - cy) <= r + _TOL
        pts = self.points
        n = len(pts)
        inside = False
        for k in range(n):
            (x0, y0), (x1, y1) = pts[k], pts[(k + 1) % n]
            if _point_segment_distance(x, y, x0, y0, x1, y1) <= _TOL:
                return True
            if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
                inside = not inside
        return inside

    def crossings(self, px: float, py: float, qx: float, qy: float) -> list[float]:
        """Parameters t in [0, 1] of ``P + t (Q - P)`` where the segment meets the boundary."""
        dx, dy = qx - px, qy - py
        dd = dx * dx + dy * dy
        out: list[float] = []
        if dd == 0.0:
            return out
        if self.circle is not None:
            cx, cy, r = self.circle
            fx, fy = px - cx, py - cy
            b = fx * dx + fy * dy
            c = fx * fx + fy * fy - r * r
            disc = b * b - dd * c
            if disc < 0.0:
                # a tangent computed a hair outside still touches: keep the closest approach
                t = -b / dd
                if math.hypot(fx + t * dx, fy + t * dy) <= r + _TOL:
                    out.append(t)
            else:
                root = math.sqrt(disc)
                out += [(-b - root) / dd, (-b + root) / dd]
            return [min(max(t, 0.0), 1.0) for t in out if -1e-12 <= t <= 1.0 + 1e-12]
        pts = self.points
        n = len(pts)
        for k in range(n):
            (x0, y0), (x1, y1) = pts[k], pts[(k + 1) % n]
            ex, ey = x1 - x0, y1 - y0
            den = dx * ey - dy * ex
            wx, wy = x0 - px, y0 - py
            if abs(den) > 1e-15 * math.sqrt(dd) * math.hypot(ex, ey):
                t = (wx * ey - wy * ex) / den
                u = (wx * dy - wy * dx) / den
                if -1e-12 <= t <= 1.0 + 1e-12 and -1e-12 <= u <= 1.0 + 1e-12:
                    out.append(min(max(t, 0.0), 1.0))
            elif abs(wx * dy - wy * dx) <= _TOL * math.sqrt(dd):
                # collinear: the overlap's ends
                for vx, vy in ((x0, y0), (x1, y1)):
                    t = ((vx - px) * dx + (vy - py) * dy) / dd
                    if 0.0 <= t <= 1.0:
                        out.append(t)
        return out


def _point_segment_distance(x: float, y: float, x0: float, y0: float, x1: float, y1: float) -> float:
    dx, dy = x1 - x0, y1 - y0
    dd = dx * dx + dy * dy
    t = 0.0 if dd == 0.0 else min(max(((x - x0) * dx + (y - y0) * dy) / dd, 0.0), 1.0)
    return math.hypot(x - x0 - t * dx, y - y0 - t * dy)


def _footprint_intervals(
    region: _Region, p: tuple[float, float], q: tuple[float, float]
) -> list[list[float]]:
    """The parameter intervals of the segment P->Q that are over the region (touches: [t, t])."""
    ts = sorted({0.0, 1.0, *region.crossings(p[0], p[1], q[0], q[1])})
    dx, dy = q[0] - p[0], q[1] - p[1]

    def over(t: float) -> bool:
        return region.contains(p[0] + t * dx, p[1] + t * dy)

    pieces: list[list[float]] = []
    for k, t in enumerate(ts):
        if over(t):
            pieces.append([t, t])
        if k + 1 < len(ts) and over(0.5 * (t + ts[k + 1])):
            pieces.append([t, ts[k + 1]])
    merged: list[list[float]] = []
    for lo, hi in pieces:
        if merged and lo <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    return merged


def _band_relation(h0: float, h1: float, lo: float, hi: float) -> str:
    if max(h0, h1) < lo - _TOL:
        return "below"
    if min(h0, h1) > hi + _TOL:
        return "above"
    return "crosses"


_RELATION_TEXT = {
    "crosses": "path goes through it",
    "crosses WORK": "path in it",
    "above": "path passes above",
    "below": "path passes below",
    "above_and_below": "path passes above and below",
    "apart": "path never over it",
}


def relation_text(
    area: Mapping[str, Any], refused: Mapping[str, Any] | None, violation: Mapping[str, Any] | None
) -> str:
    """What the legend says of ``area`` (a scene's area with its ``spans``): what happened there.

    The area whose check refused a block: the block would have entered it (a protection area) or left it
    (a work area), and the axes stopped before (FCT-C14: the block is refused before it starts). An area
    the axes reached without a refused block (jog, a measured violation): they reached it. Otherwise how
    the travelled path meets it, and whether the refused block would have crossed it as well."""
    kind = area.get("kind")
    if refused is not None and refused.get("area") == area.get("id"):
        block = refused.get("block") or (f"of line {refused['line']}" if refused.get("line") else "")
        what = f"the refused block {block}".rstrip()
        if kind == "WORK":
            return f"{what} would leave it; the axes stopped inside"
        return f"{what} would enter it; the axes stopped before it"
    if violation is not None and refused is None and violation.get("area") == area.get("id"):
        return "the axes reached its boundary" if kind == "WORK" else "the axes reached it"
    spans = area.get("spans") or []
    travelled = _combine(sp["relation"] for sp in spans if not sp.get("refused"))
    text = _RELATION_TEXT.get(f"{travelled} {kind}") or _RELATION_TEXT[travelled]
    if travelled != "crosses" and any(sp.get("refused") and sp["relation"] == "crosses" for sp in spans):
        text += "; the refused block would cross it"
    return text


def _combine(relations: Iterable[str]) -> str:
    seen = set(relations)
    if not seen:
        return "apart"
    if "crosses" in seen:
        return "crosses"
    if "above_and_below" in seen or {"above", "below"} <= seen:
        return "above_and_below"
    return "above" if "above" in seen else "below"


# --- the path -----------------------------------------------------------------------------------------
class _Piece:
    """A polyline of channel points with its path length ``s`` in the view's base plane per point."""

    def __init__(self, points: list[tuple[float, ...]], s0: float, ia: int, ib: int, refused: bool) -> None:
        self.points = points
        self.refused = refused
        self.s = [s0]
        for prev, cur in itertools.pairwise(points):
            self.s.append(self.s[-1] + math.hypot(cur[ia] - prev[ia], cur[ib] - prev[ib]))

    @property
    def s_end(self) -> float:
        return self.s[-1]


def _spans(
    area: Mapping[str, Any], names: Sequence[str], pieces: list[_Piece]
) -> list[dict[str, Any]] | None:
    """Where along the path (s) it is over the area's base region, with the band relation there."""
    try:
        ia, ib = (names.index(n) for n in area["axes"])
        ic = names.index(area["height_axis"]) if area.get("height_axis") in names else None
    except ValueError:
        return None  # the area watches axes the path does not have
    region = _Region(area)
    lo, hi = float(area["min"]), float(area["max"])
    spans: list[dict[str, Any]] = []
    for piece in pieces:
        pts, ss = piece.points, piece.s
        if len(pts) == 1:
            pts, ss = [pts[0], pts[0]], [ss[0], ss[0]]
        for k in range(len(pts) - 1):
            p, q = pts[k], pts[k + 1]
            if region.far_from((p[ia], p[ib]), (q[ia], q[ib])):
                continue
            for t0, t1 in _footprint_intervals(region, (p[ia], p[ib]), (q[ia], q[ib])):
                if ic is None:
                    relation = "crosses"  # no height axis recorded: over the region is in it
                else:
                    h0 = p[ic] + t0 * (q[ic] - p[ic])
                    h1 = p[ic] + t1 * (q[ic] - p[ic])
                    relation = _band_relation(h0, h1, lo, hi)
                s0 = ss[k] + t0 * (ss[k + 1] - ss[k])
                s1 = ss[k] + t1 * (ss[k + 1] - ss[k])
                last = spans[-1] if spans else None
                if last is not None and last["refused"] == piece.refused and s0 <= last["to"] + _TOL:
                    last["to"] = max(last["to"], s1)
                    last["relation"] = _combine((last["relation"], relation))
                else:
                    spans.append({"from": s0, "to": s1, "relation": relation, "refused": piece.refused})
    return spans


def _arc_points(
    start: Sequence[float], end: Sequence[float], names: Sequence[str], arc: Mapping[str, Any]
) -> list[tuple[float, ...]]:
    """The refused arc (or helix) as points: the plane axes on the circle, the others linear."""
    i, j = (names.index(n) for n in arc["plane"])
    cx, cy = (float(v) for v in arc["centre"])
    sweep = math.radians(float(arc["sweep_deg"]))
    r = math.hypot(start[i] - cx, start[j] - cy)
    a0 = math.atan2(start[j] - cy, start[i] - cx)
    n = max(2, math.ceil(abs(sweep) / _ARC_STEP))
    out = []
    for k in range(n + 1):
        f = k / n
        p = [s + (e - s) * f for s, e in zip(start, end, strict=True)]
        if 0 < k < n:
            p[i] = cx + r * math.cos(a0 + sweep * f)
            p[j] = cy + r * math.sin(a0 + sweep * f)
        out.append(tuple(p))
    return out


def _violation(alarms: Iterable[Mapping[str, Any]]) -> Mapping[str, Any] | None:
    """The first alarm that names a refused block (``intersection``) or a position in the wrong place."""
    for alarm in alarms:
        params = alarm.get("params") or {}
        if "intersection" in params or ("position" in params and "area" in params):
            return alarm
    return None


def _cause(params: Mapping[str, Any]) -> str:
    """What refused the block, in words for a legend: the area, or the software limit of an axis."""
    if params.get("area") is not None:
        return f"area {params['area']}"
    limit = params.get("limit")
    if params.get("axis") is not None and isinstance(limit, int | float):
        return f"the software limit of {params['axis']} ({limit / _SCALE:.4f} mm)"
    return "the alarm"


def _nearest_s(piece: _Piece, point: Sequence[float], ia: int, ib: int) -> float:
    """``s`` of the point of the polyline closest to ``point`` in the base plane."""
    best, best_s = math.inf, piece.s[0]
    pts = piece.points
    if len(pts) == 1:
        return piece.s[0]
    x, y = point[ia], point[ib]
    for k in range(len(pts) - 1):
        (x0, y0), (x1, y1) = (pts[k][ia], pts[k][ib]), (pts[k + 1][ia], pts[k + 1][ib])
        dx, dy = x1 - x0, y1 - y0
        dd = dx * dx + dy * dy
        t = 0.0 if dd == 0.0 else min(max(((x - x0) * dx + (y - y0) * dy) / dd, 0.0), 1.0)
        d = math.hypot(x - x0 - t * dx, y - y0 - t * dy)
        if d < best:
            best, best_s = d, piece.s[k] + t * (piece.s[k + 1] - piece.s[k])
    return best_s


def _simplify(points: list[list[float | None]], tolerance: float) -> list[list[float | None]]:
    """Ramer-Douglas-Peucker on (a, b, h), after dropping points within ``tolerance`` of the last kept
    one (which bounds the work for densely recorded paths). The ends are always kept."""
    if len(points) <= 2 or tolerance <= 0.0:
        return points

    def xyz(p: list[float | None]) -> tuple[float, float, float]:
        return (float(p[0] or 0.0), float(p[1] or 0.0), float(p[2] or 0.0))

    coords = [xyz(points[0])]
    index = [0]
    for k in range(1, len(points) - 1):
        c = xyz(points[k])
        if math.dist(c, coords[-1]) > tolerance:
            coords.append(c)
            index.append(k)
    coords.append(xyz(points[-1]))
    index.append(len(points) - 1)
    keep = [False] * len(coords)
    keep[0] = keep[-1] = True
    stack = [(0, len(coords) - 1)]
    while stack:
        first, last = stack.pop()
        if last - first < 2:
            continue
        a, b = coords[first], coords[last]
        ab = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
        ab2 = ab[0] ** 2 + ab[1] ** 2 + ab[2] ** 2
        worst, at = -1.0, first
        for k in range(first + 1, last):
            c = coords[k]
            ac = (c[0] - a[0], c[1] - a[1], c[2] - a[2])
            t = (
                0.0
                if ab2 == 0.0
                else min(max((ac[0] * ab[0] + ac[1] * ab[1] + ac[2] * ab[2]) / ab2, 0.0), 1.0)
            )
            d = math.dist(c, (a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]))
            if d > worst:
                worst, at = d, k
        if worst > tolerance:
            keep[at] = True
            stack += [(first, at), (at, last)]
    return [points[index[k]] for k in range(len(coords)) if keep[k]]


def _area_list(areas: Mapping[str, Any] | Iterable[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    if isinstance(areas, Mapping):
        return list(areas.get("areas", []))
    return list(areas)


def _choose_view(
    areas: list[Mapping[str, Any]], names: Sequence[str], main_axes: Sequence[str], plane: int
) -> tuple[str, str, str | None]:
    if plane not in _PLANES:
        raise ValueError(f"plane must be 17, 18 or 19 (G17/G18/G19), got {plane}")
    ka, kb, kc = _PLANES[plane]
    if len(main_axes) != 3:
        raise ValueError(f"main_axes must name three axes, got {list(main_axes)}")
    default = (main_axes[ka], main_axes[kb], main_axes[kc])
    views = Counter(
        (a["axes"][0], a["axes"][1], a.get("height_axis"))
        for a in areas
        if a["axes"][0] in names and a["axes"][1] in names
    )
    if views:
        best = max(views.values())
        candidates = [v for v, n in views.items() if n == best]
        a, b, h = default if default in candidates else candidates[0]
    else:
        a, b, h = default
    return a, b, (h if h in names else None)


def build_scene(
    areas: Mapping[str, Any] | Iterable[Mapping[str, Any]],
    path: Sequence[Sequence[float]],
    *,
    axis_names: Sequence[str],
    main_axes: Sequence[str],
    plane: int = 17,
    alarms: Iterable[Mapping[str, Any]] = (),
    stop: Sequence[float] | None = None,
    channel: int | None = None,
    tolerance: float | None = None,
    position: Sequence[float] | None = None,
    ahead: Sequence[Sequence[float]] = (),
    tool_path: Sequence[Sequence[float]] = (),
) -> dict[str, Any]:
    """The scene (module docstring) of a channel's areas and the path it travelled.

    ``areas``: the area table JSON (the ``"areas"`` list or the whole table). ``path``: the recorded
    points, one value per axis of ``axis_names``. ``main_axes`` and ``plane`` (17/18/19) give the view
    when no area does. ``alarms``: as ``check --format json`` lists them; the first whose params carry
    an ``intersection`` (or a ``position`` and an ``area``) gives the refused block and the violation
    point. ``stop``: where the axes came to rest (all axes). ``tolerance``: mm the drawn path may deviate
    from the recorded one (default 1e-4 of the scene's diagonal; 0 keeps every point). ``position`` (all
    axes) and ``ahead`` (points, all axes) are the live dashboard's: the TCP now and the path decoded
    ahead of it (drawn from ``position``; not related to the areas, see the module docstring).
    ``tool_path``: with a kinematic transformation on, the tool tip's path (all axes' slots, the main axes
    the tip's) beside the axes' ``path`` (K-06); the scene has ``"tool_path"`` only when it is given."""
    names = list(axis_names)
    width = len(names)
    table = _area_list(areas)
    for k, p in enumerate(path):
        if len(p) != width:
            raise ValueError(f"path point {k} has {len(p)} coordinates, the channel has {width} axes {names}")
    if stop is not None and len(stop) != width:
        raise ValueError(f"stop point has {len(stop)} coordinates, the channel has {width} axes {names}")
    if position is not None and len(position) != width:
        raise ValueError(f"position has {len(position)} coordinates, the channel has {width} axes {names}")
    for k, p in enumerate(ahead):
        if len(p) != width:
            raise ValueError(
                f"point {k} ahead has {len(p)} coordinates, the channel has {width} axes {names}"
            )
    va, vb, vh = _choose_view(table, names, main_axes, plane)
    ia, ib = names.index(va), names.index(vb)
    ih = names.index(vh) if vh is not None else None

    pieces: list[_Piece] = []
    travelled = [tuple(float(v) for v in p) for p in path]
    if travelled:
        pieces.append(_Piece(travelled, 0.0, ia, ib, refused=False))
    s_end = pieces[0].s_end if pieces else 0.0

    refused: dict[str, Any] | None = None
    violation: dict[str, Any] | None = None
    alarm = _violation(alarms)
    refused_piece: _Piece | None = None
    if alarm is not None:
        params = alarm["params"]
        if "intersection" in params and "start" in params and "end" in params:
            start = [float(v) for v in params["start"]]
            end = [float(v) for v in params["end"]]
            arc = params.get("arc")
            points = _arc_points(start, end, names, arc) if arc else [tuple(start), tuple(end)]
            refused_piece = _Piece(points, s_end, ia, ib, refused=True)
            pieces.append(refused_piece)
            where = [float(v) for v in params["intersection"]]
        else:
            where = [float(v) for v in params["position"]]
        if len(where) == width:
            s_at = _nearest_s(refused_piece, where, ia, ib) if refused_piece is not None else s_end
            violation = {
                "alarm": alarm.get("id"),
                "area": params.get("area"),
                "kind": params.get("kind"),
                "axis": params.get("axis"),
                "cause": _cause(params),
                "point": [where[ia], where[ib], where[ih] if ih is not None else None, s_at],
                "position": dict(zip(names, where, strict=True)),
            }

    def view(p: Sequence[float], s: float) -> list[float | None]:
        return [p[ia], p[ib], p[ih] if ih is not None else None, s]

    if refused_piece is not None and alarm is not None:
        params = alarm["params"]
        refused = {
            "alarm": alarm.get("id"),
            "line": alarm.get("line"),
            "block": alarm.get("block"),
            "area": params.get("area"),
            "kind": params.get("kind"),
            "axis": params.get("axis"),
            "cause": _cause(params),
            "points": [view(p, s) for p, s in zip(refused_piece.points, refused_piece.s, strict=True)],
        }

    stop_view: list[float | None] | None = None
    if stop is not None:
        s_stop = s_end
        if travelled and math.dist(stop, travelled[-1]) > 1e-3:
            s_stop = _nearest_s(pieces[0], stop, ia, ib)
        stop_view = view([float(v) for v in stop], s_stop)

    out_areas: list[dict[str, Any]] = []
    for area in table:
        entry = dict(area)
        in_view = list(area["axes"]) == [va, vb]
        entry["in_view"] = in_view
        entry["band_in_view"] = in_view and vh is not None and area.get("height_axis") == vh
        spans = _spans(area, names, pieces)
        entry["spans"] = spans or []
        entry["relation"] = _combine(sp["relation"] for sp in spans) if spans is not None else "apart"
        out_areas.append(entry)
    for entry in out_areas:
        entry["relation_text"] = relation_text(entry, refused, violation)

    position_view: list[float | None] | None = None
    ahead_view: list[list[float | None]] = []
    if position is not None or ahead:
        here = tuple(float(v) for v in (position if position is not None else ahead[0]))
        s_here = s_end + (
            math.hypot(here[ia] - travelled[-1][ia], here[ib] - travelled[-1][ib]) if travelled else 0.0
        )
        if position is not None:
            position_view = view(here, s_here)
        if ahead:
            piece = _Piece(
                [here, *(tuple(float(v) for v in p) for p in ahead)], s_here, ia, ib, refused=False
            )
            ahead_view = [view(p, s) for p, s in zip(piece.points, piece.s, strict=True)]

    path_view = [view(p, s) for p, s in zip(travelled, pieces[0].s, strict=True)] if travelled else []
    s_end_total = pieces[-1].s_end if pieces else 0.0
    if ahead_view:
        s_end_total = max(s_end_total, float(ahead_view[-1][3] or 0.0))
    bounds = _bounds(
        out_areas,
        path_view + ahead_view + ([position_view] if position_view is not None else []),
        refused,
        violation,
        stop_view,
        s_end_total=s_end_total,
    )
    if tolerance is None:
        (a0, a1), (b0, b1) = bounds["a"], bounds["b"]
        h0, h1 = bounds["height"] or (0.0, 0.0)
        tolerance = _SIMPLIFY * math.dist((a0, b0, h0), (a1, b1, h1))
    polylines = [_simplify(path_view, tolerance)] if path_view else []
    tool_view = [[p[ia], p[ib], p[ih] if ih is not None else None, 0.0] for p in tool_path]
    scene = {
        "scene": SCENE_VERSION,
        "channel": channel,
        "axes": names,
        "view": {"a": va, "b": vb, "height": vh},
        "bounds": bounds,
        "areas": out_areas,
        "path": polylines,
        "refused": refused,
        "violation": violation,
        "stop": stop_view,
        "position": position_view,
        "ahead": _simplify(ahead_view, tolerance),
    }
    if tool_view:
        scene["tool_path"] = _simplify(tool_view, tolerance)
    result: dict[str, Any] = round_numbers(scene)
    return result


def _bounds(
    areas: list[dict[str, Any]],
    path: list[list[float | None]],
    refused: Mapping[str, Any] | None,
    violation: Mapping[str, Any] | None,
    stop: list[float | None] | None,
    *,
    s_end_total: float,
) -> dict[str, Any]:
    a_vals: list[float] = []
    b_vals: list[float] = []
    h_vals: list[float] = []
    for area in areas:
        if not area["in_view"]:
            continue
        if area.get("shape") == "CIRC":
            (cx, cy), r = area["center"], area["radius"]
            a_vals += [cx - r, cx + r]
            b_vals += [cy - r, cy + r]
        else:
            a_vals += [p[0] for p in area["points"]]
            b_vals += [p[1] for p in area["points"]]
        if area["band_in_view"] and area["spans"]:
            h_vals += [area["min"], area["max"]]
    points = list(path)
    if refused is not None:
        points += refused["points"]
    if violation is not None:
        points.append(violation["point"])
    if stop is not None:
        points.append(stop)
    for p in points:
        a_vals.append(float(p[0] or 0.0))
        b_vals.append(float(p[1] or 0.0))
        if p[2] is not None:
            h_vals.append(p[2])
    if not a_vals:
        a_vals = b_vals = [0.0]
    return {
        "a": [min(a_vals), max(a_vals)],
        "b": [min(b_vals), max(b_vals)],
        "height": [min(h_vals), max(h_vals)] if h_vals else None,
        "s": [0.0, s_end_total],
    }
