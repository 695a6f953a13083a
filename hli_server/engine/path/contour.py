"""Polynomial contouring: the corner between two motion blocks replaced by a smooth transition
(M-20..M-24).

The kernel's polynomial contouring (G61 non-modal, G261/G260 modal, ``#CONTOUR MODE [...]``;
programming manual "Polynomial contouring (G61/G261/G260)",
https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/206307595.html) shortens the
pre-block and the post-block by their *corner distances* and inserts a contouring curve between the
two new end points. The simulator's curve (docs/nc-language.md, "Contouring"):

* one polynomial of degree 4 (a quartic Bézier curve) in all axes of the channel, with the control
  points ``P0 = A``, ``P1 = A + d_pre/2 * t_A``, ``P2 = C``, ``P3 = B - d_post/2 * t_B``, ``P4 = B``:
  ``A`` and ``B`` are the points at the corner distances ``d_pre`` before and ``d_post`` after the
  programmed corner ``C``, ``t_A`` and ``t_B`` the path directions there. The curve leaves and rejoins
  the path with the path's direction; between two lines ``P0, P1, P2`` and ``P2, P3, P4`` are collinear,
  so the curvature is zero at both ends as well (curvature-continuous, as the manual's two quartics
  are). Between a line and an arc, or two arcs, the direction is continuous, the curvature is not;
* contouring with corner deviation (``DEV``, the kernel's default type): the corner distance is
  chosen so that the *corner deviation* (the distance of the curve's interim point ``t = 1/2`` from
  ``C``, the manual's definition, tf5200_programming_manual/475073291.html) is ``PATH_DEV`` less the
  chord tolerance; for two lines with the turning angle ``theta`` that is
  ``d = 8 * dev / (3 sin(theta/2))`` (the interim point is ``C + 3 d (t_B - t_A) / 16``); both
  distances are limited symmetrically to half the block
  length (tf5200_programming_manual/475164939.html). Then the whole curve is measured against the
  programmed path (its distance from the pre-block's tail and the post-block's head) and ``d`` is
  reduced until no point departs by more than ``PATH_DEV``: the bound holds for arcs too;
* contouring with corner distance (``DIST``, ``PRE_DIST``/``POST_DIST``): the distances as programmed,
  limited to half the block length (equal distances symmetrically, different ones each on its own,
  tf5200_programming_manual/475180811.html); no deviation bound (the manual has none);
* the other types (``AUTO_DEV``, ``AUTO_VEL``, ``DIST_SOFT``, ``DIST_MASTER``, ``POS``, ``PTP``), ``#HSC``
  and ``#SPLINE`` are simulated as ``DEV`` with their deviation (the decoder reports it, see
  :class:`ContourSettings.simulated_as`).

Segmentation (FCT-C14 section 2.3: "with polynomial contouring the path is first segmented and then the
single points are checked"): the curve is emitted as straight lines through support points whose chords
depart from the curve by at most :data:`CHORD_TOLERANCE` (or a twentieth of the deviation, the smaller).
Everything after this stage (path checks of areas and soft limits, the planner, the picture) sees
ordinary line segments: the area checks test exactly the path the axes then follow.

No contouring (the corner is kept, as the kernel suppresses it, 475086859): where either block is a
rapid (G00: it ends in exact stop in this simulator), an exact-stop block (G60), a measuring move, or
where the transition is tangential or a reversal; and where the tool length in the axis position changes
along either block (``Piece.tip_start``/``tip_end``: the support points then carry one length).

In the chain (docs/nc-language.md, "The chained path"), the pieces come from the radius compensation and
the frames: compensated segments in machine coordinates, each with its block's feed, contouring and tool
length.

Interface: :meth:`Contour.push` takes a :class:`Piece` (a segment in machine coordinates with its block
and its contouring request) and returns the pieces ready for the path checks; a piece that asks for
contouring at its end is held back until the next one arrives. :meth:`Contour.flush` returns the held
piece unchanged (a marker, an area command, an error or the program's end comes next), :meth:`reset`
drops it.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from typing import Final

from hli_server.engine.geometry import LineSegment, Point, Segment, sub_segment
from hli_server.engine.nc.blocks import Block
from hli_server.engine.path.corners import (
    A_NOT_SIMULATED,
    CHORD_TOLERANCE,
    TANGENTIAL,
    CornerError,
    CornerRequest,
    insert_corner,
)

__all__ = [
    "BSPLINE_PATH_DEV",
    "CHORD_TOLERANCE",
    "DEFAULT_SETTINGS",
    "HSC_DEFAULT",
    "MODES",
    "SPLINE_DEFAULT",
    "Contour",
    "ContourSettings",
    "Piece",
    "corner_departure",
    "distance_to_path",
    "sub_segment",
]

MAX_SUPPORT_POINTS: Final = 32
"""Most chords per contouring curve (project's own)."""
_MIN_SUPPORT_POINTS: Final = 4
_KEEP: Final = 1e-6
"""mm: what a shortened block keeps at least (its direction stays defined for the next corner)."""
_SAMPLES: Final = 32
"""Samples of the curve (and of a programmed arc) when the departure is measured."""

MODES: Final = ("DEV", "DIST", "AUTO_DEV", "AUTO_VEL", "DIST_SOFT", "DIST_MASTER", "POS", "PTP")
"""The contouring types of ``#CONTOUR MODE``; DEV and DIST are modelled, the others simulated as DEV."""


@dataclass(frozen=True, slots=True)
class ContourSettings:
    """The parameters of one contouring (``#CONTOUR MODE``, ``#HSC``, ``#SPLINE``), mm."""

    mode: str = "DEV"
    path_dev: float = 1.0
    """PATH_DEV, default 1 mm (tf5200_programming_manual/475164939.html)."""
    pre_dist: float = 1.0
    """PRE_DIST of DIST, default 1 mm (475180811)."""
    post_dist: float = 1.0
    """POST_DIST of DIST, default 1 mm."""
    simulated_as: str | None = None
    """Set where a type or function the simulator does not model is simulated as DEV: what it was."""


DEFAULT_SETTINGS: Final = ContourSettings()
HSC_DEFAULT: Final = ContourSettings(path_dev=0.1, simulated_as="#HSC")
"""``#HSC ON`` without parameters: OPMODE 1, CONTERROR 0.1 mm (tf5200_programming_manual/207278475.html)."""
BSPLINE_PATH_DEV: Final = 0.2
"""mm: PATH_DEV of ``#HSC [BSPLINE]`` and of the simulated splines: P-CHAN-00122's default 2000 x 0.1 µm."""
SPLINE_DEFAULT: Final = ContourSettings(
    path_dev=BSPLINE_PATH_DEV, simulated_as="spline interpolation (#SPLINE)"
)
"""``#SPLINE ON``: simulated as DEV with the B spline's default deviation 0.2 mm (P-CHAN-00122: 2000 x
0.1 µm)."""


@dataclass(frozen=True, slots=True)
class Piece:
    """A motion in machine coordinates on its way to the path checks and the planner."""

    segment: Segment
    block: Block
    rapid: bool = False
    exact_stop: bool = False
    feed: float | None = None
    """mm/min, the block's feed (the transition is travelled with the pre-block's)."""
    blend: ContourSettings | None = None
    """Contour the corner at this piece's end with these settings (None: exact corner)."""
    full_length: float = 0.0
    """The programmed block's length (the corner distances are limited to half of it)."""
    transition: bool = False
    """A chord of a contouring curve."""
    tip_start: float = 0.0
    """mm: the tool length in the tool axis's position at the segment's start (the area checks see the
    segment less it: the tool tip); :attr:`tip_end` at its end. A corner is contoured only where the
    length is the same along both blocks (the curve's support points then carry that one length)."""
    tip_end: float = 0.0
    hold: bool = False
    """Held back for a chamfer or rounding (G301/G302) at its end that the next block asks for
    (:meth:`Contour.request_corner`; ``hli_server/engine/path/corners.py``)."""


# --- geometry helpers ---------------------------------------------------------------------------------
def _bezier(ctrl: list[Point], t: float) -> Point:
    u = 1.0 - t
    w = (u**4, 4 * u**3 * t, 6 * u * u * t * t, 4 * u * t**3, t**4)
    n = len(ctrl[0])
    return tuple(sum(w[k] * ctrl[k][i] for k in range(5)) for i in range(n))


def _point_line_distance(p: Point, a: Point, b: Point) -> float:
    den = 0.0
    dot = 0.0
    for pk, ak, bk in zip(p, a, b, strict=True):
        d = bk - ak
        den += d * d
        dot += (pk - ak) * d
    t = 0.0 if den <= 0.0 else min(max(dot / den, 0.0), 1.0)
    total = 0.0
    for pk, ak, bk in zip(p, a, b, strict=True):
        e = pk - (ak + t * (bk - ak))
        total += e * e
    return math.sqrt(total)


def _polyline(segment: Segment) -> list[Point]:
    if isinstance(segment, LineSegment):
        return [segment.start, segment.end]
    n = _SAMPLES * 2
    return [segment.point_at(segment.length * k / n) for k in range(n + 1)]


def distance_to_path(p: Point, path: list[Segment]) -> float:
    """Distance of ``p`` from the programmed ``path``: exact for lines and arcs in their plane, helices
    by 64 chords (their sagitta is below r * 1.2e-3 * sweep², negligible at contouring's deviations)."""
    return min(_segment_distance(p, segment) for segment in path)


def _segment_distance(p: Point, segment: Segment) -> float:
    if isinstance(segment, LineSegment):
        return _point_line_distance(p, segment.start, segment.end)
    i, j = segment.plane
    rest = [k for k in range(len(p)) if k not in (i, j)]
    if any(abs(segment.end[k] - segment.start[k]) > 1e-12 for k in rest):  # a helix
        return min(_point_line_distance(p, a, b) for a, b in itertools.pairwise(_polyline(segment)))
    dx, dy = p[i] - segment.centre[0], p[j] - segment.centre[1]
    if _on_sweep(math.atan2(dy, dx), segment.start_angle, segment.sweep):
        flat = abs(math.hypot(dx, dy) - segment.radius)
        return math.hypot(flat, *(p[k] - segment.start[k] for k in rest))
    return min(math.dist(p, segment.start), math.dist(p, segment.end))


def _on_sweep(angle: float, start: float, sweep: float) -> bool:
    tau = 2.0 * math.pi
    if abs(sweep) >= tau - 1e-12:
        return True
    if sweep >= 0:
        return (angle - start) % tau <= sweep
    return (start - angle) % tau <= -sweep


def corner_departure(curve: list[Point], path: list[Segment]) -> float:
    """The largest distance of the points ``curve`` from the programmed ``path``."""
    return max(distance_to_path(p, path) for p in curve)


def _unit(v: Point) -> Point:
    n = math.sqrt(sum(x * x for x in v))
    return v if n <= 0.0 else tuple(x / n for x in v)


# --- the stage ---------------------------------------------------------------------------------------
class Contour:
    """Holds back a piece that asks for contouring at its end; blends it with the next one."""

    def __init__(self) -> None:
        self._held: Piece | None = None
        self._corner: CornerRequest | None = None
        self.corners = 0
        """Corners contoured since the last reset (diagnostics, benchmarks)."""

    @property
    def holding(self) -> bool:
        return self._held is not None

    @property
    def held_piece(self) -> Piece | None:
        return self._held

    @property
    def holding_for_corner(self) -> bool:
        """A piece is held for a chamfer or rounding the next block may ask for."""
        return self._held is not None and self._held.hold

    @property
    def corner_requested(self) -> bool:
        return self._corner is not None

    def request_corner(self, request: CornerRequest) -> None:
        """G301/G302 (PM 206609163): insert a chamfer or rounding between the held piece and the next one
        (a later request before the next motion replaces this one)."""
        self._corner = request

    def reset(self) -> None:
        self._held = None
        self._corner = None

    def flush(self) -> list[Piece]:
        """The held piece as it is (a marker, an area command, an error or the program's end comes next;
        a chamfer or rounding asked for has no post-block and is dropped)."""
        held, self._held = self._held, None
        self._corner = None
        return [] if held is None else [held]

    def push(self, piece: Piece) -> list[Piece]:
        if piece.full_length <= 0.0:
            piece = replace(piece, full_length=piece.segment.length)
        out: list[Piece] = []
        pre = self._held
        self._held = None
        request = self._corner
        self._corner = None
        if pre is not None:
            corner: tuple[Piece, list[Piece], Piece] | None = None
            if request is not None:
                corner = self._insert(pre, piece, request)
            elif not (
                pre.blend is None
                or piece.rapid
                or piece.exact_stop
                or not (pre.tip_start == pre.tip_end == piece.tip_start == piece.tip_end)
            ):
                corner = self._blend(pre, piece, pre.blend)
                if corner is not None:
                    self.corners += 1
            if corner is None:
                out.append(pre)
            else:
                head, middle, piece = corner
                out.append(head)
                out.extend(middle)
        if (piece.blend is not None and not piece.rapid and not piece.exact_stop) or piece.hold:
            self._held = piece
        else:
            out.append(piece)
        return out

    # --- a chamfer or rounding (G301/G302) -------------------------------------------------------------
    @staticmethod
    def _insert(pre: Piece, post: Piece, request: CornerRequest) -> tuple[Piece, list[Piece], Piece] | None:
        """The corner between ``pre`` and ``post`` replaced by the chamfer or rounding of ``request``
        (the inserted element is the G301/G302 block's, travelled at its feed or the pre-block's and, after
        a rapid, at rapid); None at a tangential transition. Raises :class:`CornerError`."""
        if not (pre.tip_start == pre.tip_end == post.tip_start == post.tip_end):
            raise CornerError(
                A_NOT_SIMULATED,
                "a chamfer or rounding (G301/G302) where the tool length in the axis position changes is not "
                "simulated: program the tool axis before the corner",
            )
        result = insert_corner(pre.segment, post.segment, request.kind, request.size)
        if result is None:
            return None
        head_segment, middle, tail_segment = result
        head = replace(pre, segment=head_segment, blend=None, hold=False, exact_stop=False)
        feed = pre.feed if request.feed is None else request.feed
        pieces = [
            Piece(
                segment=segment,
                block=request.block,
                rapid=pre.rapid,
                exact_stop=pre.exact_stop,
                feed=None if pre.rapid else feed,
                full_length=segment.length,
                tip_start=pre.tip_end,
                tip_end=pre.tip_end,
            )
            for segment in middle
        ]
        return head, pieces, replace(post, segment=tail_segment)

    # --- one corner ------------------------------------------------------------------------------------
    def _blend(
        self, pre: Piece, post: Piece, settings: ContourSettings
    ) -> tuple[Piece, list[Piece], Piece] | None:
        s_pre, s_post = pre.segment, post.segment
        l_pre, l_post = s_pre.length, s_post.length
        if l_pre <= 1e-9 or l_post <= 1e-9:
            return None
        t_in = _unit(s_pre.direction_at(l_pre))
        t_out = _unit(s_post.direction_at(0.0))
        cos_turn = max(-1.0, min(1.0, sum(a * b for a, b in zip(t_in, t_out, strict=True))))
        turn = math.acos(cos_turn)
        if turn < TANGENTIAL or turn > math.pi - TANGENTIAL:
            return None  # tangential, or a reversal: the kernel does not contour (475086859)
        # half the block, less a nanometre: a block shortened at both ends keeps a remainder (and its
        # direction) for the next corner
        half_pre = min(0.5 * pre.full_length, l_pre) - _KEEP
        half_post = min(0.5 * post.full_length, l_post) - _KEEP
        if half_pre <= 0.0 or half_post <= 0.0:
            return None
        if settings.mode == "DIST":
            d_pre, d_post = settings.pre_dist, settings.post_dist
            if d_pre <= 0.0 or d_post <= 0.0:
                return None
            if math.isclose(d_pre, d_post):
                d_pre = d_post = min(d_pre, half_pre, half_post)
            else:
                d_pre, d_post = min(d_pre, half_pre), min(d_post, half_post)
            chords = self._curve(s_pre, s_post, d_pre, d_post, settings.path_dev)
        else:
            dev = settings.path_dev
            if dev <= 0.0:
                return None
            chord_tol = min(CHORD_TOLERANCE, dev / 20.0)
            target = dev - chord_tol
            d = 8.0 * target / (3.0 * math.sin(turn / 2.0))
            d = min(d, half_pre, half_post)
            chords = []
            both_lines = isinstance(s_pre, LineSegment) and isinstance(s_post, LineSegment)
            for _ in range(60):
                chords = self._curve(s_pre, s_post, d, d, dev)
                if both_lines:
                    # exact by construction: the interim point is the curve's farthest point from the
                    # corner (symmetric, convex), at ``target``; the chords sag by less than the margin
                    break
                # the support points and the chords' middles against the programmed path, and the
                # interim point (t = 1/2, the middle support point) against the corner
                probes = chords + [
                    tuple(0.5 * (x + y) for x, y in zip(p, q, strict=True))
                    for p, q in itertools.pairwise(chords)
                ]
                programmed = [sub_segment(s_pre, l_pre - d, l_pre), sub_segment(s_post, 0.0, d)]
                worst = max(
                    corner_departure(probes, programmed), math.dist(chords[len(chords) // 2], s_pre.end)
                )
                if worst <= dev * (1.0 - 1e-9):
                    break
                d *= max(0.5, min(0.98, target / worst))
            else:  # pragma: no cover - the loop converges in a few steps
                return None
            d_pre = d_post = d
        head = replace(pre, segment=sub_segment(s_pre, 0.0, l_pre - d_pre), blend=None)
        tail = replace(post, segment=sub_segment(s_post, d_post, l_post))
        pieces = [
            Piece(
                segment=LineSegment(a, b),
                block=pre.block,
                rapid=False,
                feed=pre.feed,
                full_length=math.dist(a, b),
                transition=True,
                tip_start=pre.tip_end,
                tip_end=pre.tip_end,
            )
            for a, b in itertools.pairwise(chords)
            if math.dist(a, b) > 1e-12
        ]
        return head, pieces, tail

    @staticmethod
    def _curve(s_pre: Segment, s_post: Segment, d_pre: float, d_post: float, dev: float) -> list[Point]:
        """The support points of the curve from ``d_pre`` before to ``d_post`` after the corner
        (an odd count: the middle one is the interim point ``t = 1/2``)."""
        l_pre = s_pre.length
        a = s_pre.point_at(l_pre - d_pre)
        b = s_post.point_at(d_post)
        c = s_pre.end
        t_a = _unit(s_pre.direction_at(l_pre - d_pre))
        t_b = _unit(s_post.direction_at(d_post))
        ctrl = [
            a,
            tuple(x + 0.5 * d_pre * t for x, t in zip(a, t_a, strict=True)),
            c,
            tuple(x - 0.5 * d_post * t for x, t in zip(b, t_b, strict=True)),
            b,
        ]
        # chord count from the curvature bound of the control polygon: sagitta ~ k h^2 / 8
        tol = min(CHORD_TOLERANCE, max(dev, 1e-6) / 20.0)
        second = max(
            math.dist(
                tuple(p0 - 2 * p1 + p2 for p0, p1, p2 in zip(*triple, strict=True)), tuple(0.0 for _ in a)
            )
            for triple in (ctrl[0:3], ctrl[1:4], ctrl[2:5])
        )
        # |B''| <= 12 * max second difference; a chord over dt sags at most |B''| dt^2 / 8
        dt = math.sqrt(8.0 * tol / max(12.0 * second, 1e-12))
        n = min(MAX_SUPPORT_POINTS, max(_MIN_SUPPORT_POINTS, math.ceil(1.0 / dt)))
        if n % 2:
            n += 1
        return [ctrl[0], *(_bezier(ctrl, k / n) for k in range(1, n)), ctrl[4]]
