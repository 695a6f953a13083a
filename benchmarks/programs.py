"""The benchmarks' programs, generated (``python -m benchmarks.programs --out DIR`` writes them).

* :func:`area_header`: defines and activates 20 areas in channel 1 of ``machines/full.toml``: one work
  polygon (an octagon, circumradius 280 mm) and 19 protection areas on a ring of radius 180 mm around
  the origin, circles (radius 12 mm) and squares (20 mm) in turn; height band Z -100..100 mm.
* :func:`pocket_program`: the full machine's channel 1: the areas, then a pocket of 200 x 120 mm milled
  over 12 depth levels, each a zig-zag of lines joined by G02/G03 half circles and a finishing pass
  with G03 corners; the fourth axis W moves with every plunge.
* :func:`shuttle_program`: the full machine's channel 2: the four carriages shuttle about their homes
  (0, 300, 600, 900 mm) in different phases, at most 100 mm from home: the neighbours never come
  closer than 100 mm (minimum 20 mm), and now and then some carriages rest while others move.
* :func:`near_area_lines`: the program of ``check --geometry-only`` (P2): lines and arcs that run close
  to the 20 areas without touching them - around every protection circle on an arc 0.5..2 mm off it,
  along every side of every protection square and round its corners on arcs (the exact offset curve),
  along the work polygon's edges 0.5..2 mm inside; streamed line by line, as long as asked.
  :func:`near_area_lines_rs274` gives the same moves in LinuxCNC's dialect without the areas (the
  reference ``rs274`` interprets them, docs/performance.md).
* :func:`near_area_arcs`: a program of mostly arcs close to the same 20 areas (the hard case): rings of
  G02/G03 round every protection circle 0.5..2 mm off it (a whole circle, then twelve arcs one way and
  eight the other a little farther out, over the +-180 degree seam) and twelve short chords hugging it;
  round every protection square its offset curve (sides and quarter arcs about the corners), arcs along
  its sides whose chord keeps well off but whose bulge comes close, small whole circles off its
  corners; travel between the areas on arcs about the origin; then the same areas from the side in
  G18 and G19 (arcs in the XZ and YZ planes whose whole circle would reach into an area but whose
  sweep does not) and near the work polygon's edges. Every other tour with absolute centres (G161).
  :func:`near_area_arcs_rs274` gives the same moves in LinuxCNC's dialect (G90.1/G91.1 for G161/G162).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Iterator
from pathlib import Path

__all__ = [
    "FULL_MACHINE",
    "PROTECTIONS",
    "WORK_POLYGON",
    "area_header",
    "near_area_arcs",
    "near_area_arcs_rs274",
    "near_area_lines",
    "near_area_lines_rs274",
    "pocket_program",
    "shuttle_program",
    "write_lines",
]

FULL_MACHINE = Path(__file__).with_name("machines") / "full.toml"
"""The full machine (2 channels, 8 axes, 3 collision pairs, FCT_DYN_POS_LIMIT in both)."""

WORK_RADIUS = 280.0
WORK_POLYGON = [
    (
        WORK_RADIUS * math.cos(math.pi / 8 + k * math.pi / 4),
        WORK_RADIUS * math.sin(math.pi / 8 + k * math.pi / 4),
    )
    for k in range(8)
]
"""The work area's corners (an octagon), counter-clockwise."""
RING = 180.0
CIRCLE_R = 12.0
SQUARE_HALF = 10.0
PROTECTIONS: list[tuple[str, float, float, float]] = [
    (
        "CIRC" if k % 2 == 0 else "POLY",
        RING * math.cos(2 * math.pi * k / 19),
        RING * math.sin(2 * math.pi * k / 19),
        CIRCLE_R if k % 2 == 0 else SQUARE_HALF,
    )
    for k in range(19)
]
"""(shape, centre x, centre y, radius or half side) of the 19 protection areas."""


def _f(v: float) -> str:
    text = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def area_header() -> str:
    """Define and activate the 20 areas (FCT-C14), then go to the pocket's corner above the part."""
    out = ["#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]"]
    pts = [*WORK_POLYGON, WORK_POLYGON[0]]
    out.append(f"G01 G90 F1000 X{_f(pts[0][0])} Y{_f(pts[0][1])}")
    out += [f"X{_f(x)} Y{_f(y)}" for x, y in pts[1:]]
    out.append("#CONTROL AREA END")
    for k, (shape, cx, cy, size) in enumerate(PROTECTIONS):
        out.append(f"#CONTROL AREA BEGIN [ID={k + 2} PROT {shape} MIN_EXCUR=-100 MAX_EXCUR=100]")
        if shape == "CIRC":
            out += [f"G01 X{_f(cx + size)} Y{_f(cy)}", f"G02 I{_f(-size)} J0"]
        else:
            corners = [(-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1)]
            out += [f"G01 X{_f(cx + sx * size)} Y{_f(cy + sy * size)}" for sx, sy in corners]
        out.append("#CONTROL AREA END")
    out.append("#CONTROL AREA ON ALL")
    return "\n".join(out) + "\n"


POCKET_X = 100.0
POCKET_Y = 60.0
STEP = 5.0


def _pocket_level(depth: float, w: float) -> list[str]:
    """One depth level: plunge (W moves too), zig-zag of lines joined by half circles, finishing pass."""
    x0, x1 = -POCKET_X + 5.0, POCKET_X - 5.0
    out = [
        "G00 Z5",
        f"G00 X{_f(x0)} Y{_f(-POCKET_Y + 5.0)}",
        f"G01 Z{_f(depth)} W{_f(w)} F1000",
        "F6000",
    ]
    y = -POCKET_Y + 5.0
    half = STEP / 2.0
    forward = True
    while y + STEP <= POCKET_Y - 5.0 + 1e-9:
        if forward:
            out.append(f"G01 X{_f(x1)}")
            out.append(f"G03 X{_f(x1)} Y{_f(y + STEP)} I0 J{_f(half)}")
        else:
            out.append(f"G01 X{_f(x0)}")
            out.append(f"G02 X{_f(x0)} Y{_f(y + STEP)} I0 J{_f(half)}")
        forward = not forward
        y += STEP
    out.append(f"G01 X{_f(x1 if forward else x0)}")
    # finishing pass: a rectangle with G03 corners of radius 5 mm, counter-clockwise
    r = 5.0
    xa, xb, ya, yb = -POCKET_X, POCKET_X, -POCKET_Y, POCKET_Y
    out += [
        f"G01 X{_f(xa + r)} Y{_f(ya)}",
        f"X{_f(xb - r)}",
        f"G03 X{_f(xb)} Y{_f(ya + r)} I0 J{_f(r)}",
        f"G01 Y{_f(yb - r)}",
        f"G03 X{_f(xb - r)} Y{_f(yb)} I{_f(-r)} J0",
        f"G01 X{_f(xa + r)}",
        f"G03 X{_f(xa)} Y{_f(yb - r)} I0 J{_f(-r)}",
        f"G01 Y{_f(ya + r)}",
        f"G03 X{_f(xa + r)} Y{_f(ya)} I{_f(r)} J0",
    ]
    return out


def pocket_program(levels: int = 12) -> str:
    """Channel 1 of the full machine: the 20 areas, then the pocket over ``levels`` depth levels."""
    out = [area_header().rstrip("\n"), "G90 G17 G00 Z5 W0"]
    for k in range(1, levels + 1):
        out += _pocket_level(-1.0 * k, 2.0 * k)
    out += ["G00 Z5", "G00 X0 Y0 W0", "M30"]
    return "\n".join(out) + "\n"


HOMES = (0.0, 300.0, 600.0, 900.0)


def shuttle_program(blocks: int = 4000) -> str:
    """Channel 2 of the full machine: the carriages X1..X4 shuttle about their homes."""
    out = ["G90 G01 F6000"]
    for n in range(blocks):
        words = []
        for k, home in enumerate(HOMES):
            if (n + k) % 5 == 4:
                continue  # this carriage rests for a block
            offset = 100.0 * math.sin(0.7 * n + 1.3 * k) * (0.4 + 0.6 * ((n * (k + 3)) % 7) / 6.0)
            words.append(f"X{k + 1}={_f(home + offset)}")
        feed = 3000 + 1000 * (n % 5)
        out.append(" ".join(words) + f" F{feed}")
    out.append("M30")
    return "\n".join(out) + "\n"


def _near_tour(tour: int) -> Iterator[tuple[str, tuple[float, ...]]]:
    """One tour of moves near every area: ("L", (x, y)) lines, ("A", (x, y, i, j, cw)) arcs; Z stays.

    Each protection area is visited from a point on the way to it from the origin (100 mm out) and
    left back to it; the clearance changes from tour to tour (0.5..2 mm)."""
    clearance = 0.5 + 1.5 * ((tour * 7) % 11) / 10.0
    for shape, cx, cy, size in PROTECTIONS:
        ux, uy = cx / RING, cy / RING  # outward
        tx, ty = -uy, ux  # along the ring, counter-clockwise
        via = (100.0 * ux, 100.0 * uy)
        yield "L", via
        if shape == "CIRC":
            rr = size + clearance
            # in towards the circle, then round its inner half on an arc ``clearance`` off it, back
            px, py = cx - tx * rr, cy - ty * rr
            yield "L", (px - ux * 10.0, py - uy * 10.0)
            yield "L", (px, py)
            ex, ey = cx + tx * rr, cy + ty * rr
            # from -t round -u to +t: clockwise seen from +Z (u x t = +z)
            yield "A", (ex, ey, cx - px, cy - py, 1.0)
            yield "L", (ex - ux * 10.0, ey - uy * 10.0)
        else:
            c = clearance
            # along the side facing the origin (in y), round the corner on an arc of radius
            # ``clearance`` about it (the exact offset curve), up the next side, and the same way back
            side = -1.0 if cy > 0 else 1.0
            yy = cy + side * (size + c)
            xl, xr = cx - size, cx + size
            corner_y = cy + side * size
            turn_left = side < 0  # moving +x below the square, turning up towards it
            yield "L", (xl - 10.0, yy)
            yield "L", (xr, yy)
            yield "A", (xr + c, corner_y, 0.0, corner_y - yy, 0.0 if turn_left else 1.0)
            yield "L", (xr + c, cy)
            yield "L", (xr + c, corner_y)
            yield "A", (xr, yy, -c, 0.0, 1.0 if turn_left else 0.0)
            yield "L", (xl - 10.0, yy)
        yield "L", via
    # along the work polygon's edges, ``clearance`` inside; out and back in through a gap of the ring
    gap = math.pi / 19.0
    yield "L", (100.0 * math.cos(gap), 100.0 * math.sin(gap))
    yield "L", (250.0 * math.cos(gap), 250.0 * math.sin(gap))
    for k in range(8):
        (ax, ay), (bx, by) = WORK_POLYGON[k], WORK_POLYGON[(k + 1) % 8]
        mx, my = 0.5 * (ax + bx), 0.5 * (ay + by)
        norm = math.hypot(mx, my)
        nx, ny = mx / norm, my / norm
        for t in (0.2, 0.8):
            yield "L", (ax + (bx - ax) * t - nx * clearance, ay + (by - ay) * t - ny * clearance)
    yield "L", (250.0 * math.cos(gap), 250.0 * math.sin(gap))
    yield "L", (100.0 * math.cos(gap), 100.0 * math.sin(gap))


def _near_moves(blocks: int) -> Iterator[tuple[str, tuple[float, ...]]]:
    made = 0
    tour = 0
    while True:
        for move in _near_tour(tour):
            if made >= blocks:
                return
            yield move
            made += 1
        tour += 1


def _near_move_lines(blocks: int) -> Iterator[str]:
    """The near-area program's moves, written alike in both dialects (G01, G02/G03 with I/J)."""
    for kind, v in _near_moves(blocks):
        if kind == "L":
            yield f"G01 X{_f(v[0])} Y{_f(v[1])}"
        else:
            yield f"G0{2 if v[4] else 3} X{_f(v[0])} Y{_f(v[1])} I{_f(v[2])} J{_f(v[3])}"


def near_area_lines(blocks: int, with_areas: bool = True) -> Iterator[str]:
    """The near-area program, line by line (``blocks`` motion blocks after the header)."""
    if with_areas:
        yield from area_header().splitlines()
    yield "G90 G17 G01 X0 Y0 Z-5 F6000"
    yield from _near_move_lines(blocks)
    yield "M30"


def interleaved(lines: Iterator[str], every: int, extra: str) -> Iterator[str]:
    """``lines`` with ``extra`` after every ``every``-th motion line (a comment, an M code): what a CAM
    program's other lines do to the batch geometry check's stretches of plain lines."""
    motions = 0
    for line in lines:
        yield line
        if line.startswith(("G01 X", "G02 X", "G03 X")):
            motions += 1
            if motions % every == 0:
                yield extra


def near_area_lines_rs274(blocks: int) -> Iterator[str]:
    """The same moves in LinuxCNC's dialect (no areas: rs274 has none), for ``rs274 -g``."""
    yield "G21 G90 G17 G94 G40 G49 G80"
    yield "G01 X0 Y0 Z-5 F6000"
    yield from _near_move_lines(blocks)
    yield "M2"


# --- mostly arcs ----------------------------------------------------------------------------------
_PLANE_AXES = {17: (0, 1), 18: (2, 0), 19: (1, 2)}
"""A plane's first and second axis (X=0, Y=1, Z=2), as the decoder's: G18 is Z-X, G19 Y-Z."""
_AXIS = "XYZ"
_CENTRE = "IJK"
TRAVEL = 150.0
"""Radius of the travel arcs between the areas (about the origin, inside the ring of areas)."""


class _ArcWriter:
    """Writes moves (rounded to 0.1 µm as the lines say) and tracks the position the lines reach."""

    def __init__(self, dialect: str) -> None:
        self.dialect = dialect
        self.p = [0.0, 0.0, -5.0]
        self.plane = 17
        self.centre_absolute = False

    def mode(self, code: int) -> str:
        if code in (17, 18, 19):
            self.plane = code
            return f"G{code}"
        self.centre_absolute = code == 161
        if self.dialect == "rs274":
            return "G90.1" if self.centre_absolute else "G91.1"
        return f"G{code}"

    def line(self, x: float | None = None, y: float | None = None, z: float | None = None) -> str:
        """A line to the point (the axes given); "" where it would not move (no block)."""
        words = []
        for k, v in enumerate((x, y, z)):
            if v is not None and float(_f(v)) != self.p[k]:
                text = _f(v)
                self.p[k] = float(text)
                words.append(f"{_AXIS[k]}{text}")
        return "G01 " + " ".join(words) if words else ""

    def arc(self, centre: tuple[float, float], a0: float, sweep: float) -> str:
        """An arc in the current plane about ``centre`` (plane coordinates) from the current position
        (which is at angle ``a0``) over ``sweep`` (positive: counter-clockwise, G03); the end is the
        start for a whole circle."""
        i, j = _PLANE_AXES[self.plane]
        start = list(self.p)
        r = math.hypot(start[i] - centre[0], start[j] - centre[1])
        if abs(abs(sweep) - 2.0 * math.pi) < 1e-12:
            end_i, end_j = _f(start[i]), _f(start[j])
        else:
            end_i = _f(centre[0] + r * math.cos(a0 + sweep))
            end_j = _f(centre[1] + r * math.sin(a0 + sweep))
        ends = {i: end_i, j: end_j}
        words = [f"G0{3 if sweep > 0 else 2}"]
        words += [f"{_AXIS[k]}{ends[k]}" for k in sorted(ends)]
        for k, c in sorted(zip((i, j), centre, strict=True)):
            words.append(f"{_CENTRE[k]}{_f(c if self.centre_absolute else c - start[k])}")
        self.p[i], self.p[j] = float(end_i), float(end_j)
        return " ".join(words)

    def arc_from(self, centre: tuple[float, float], sweep: float) -> str:
        """An arc from the current position about ``centre`` over ``sweep``."""
        i, j = _PLANE_AXES[self.plane]
        a0 = math.atan2(self.p[j] - centre[1], self.p[i] - centre[0])
        return self.arc(centre, a0, sweep)


class _Area:
    """A protection area of the ring, for routing moves round it: a circle (radius ``size``) or a
    square (half side ``size``) about (cx, cy)."""

    def __init__(self, shape: str, cx: float, cy: float, size: float) -> None:
        self.circle = shape == "CIRC"
        self.cx, self.cy, self.size = cx, cy, size

    def distance(self, ax: float, ay: float, bx: float, by: float) -> float:
        """Least distance from the segment (a, b) to the area (0 where it enters it)."""
        if self.circle:
            return _point_segment(self.cx, self.cy, ax, ay, bx, by) - self.size
        x0, x1 = self.cx - self.size, self.cx + self.size
        y0, y1 = self.cy - self.size, self.cy + self.size
        # the segment enters the box if a point of it at one of the slab limits lies in the box
        for t in _slab_params(ax, bx, x0, x1) + _slab_params(ay, by, y0, y1) + [0.0, 1.0]:
            px, py = ax + (bx - ax) * t, ay + (by - ay) * t
            if x0 <= px <= x1 and y0 <= py <= y1:
                return 0.0
        ends = [
            math.hypot(max(x0 - px, 0.0, px - x1), max(y0 - py, 0.0, py - y1))
            for px, py in ((ax, ay), (bx, by))
        ]
        corners = [_point_segment(qx, qy, ax, ay, bx, by) for qx in (x0, x1) for qy in (y0, y1)]
        return min(ends + corners)

    def extent(self) -> float:
        """The farthest point of the area from its centre."""
        return self.size * (1.0 if self.circle else math.sqrt(2.0))


def _slab_params(a: float, b: float, lo: float, hi: float) -> list[float]:
    if a == b:
        return []
    return [t for t in ((lo - a) / (b - a), (hi - a) / (b - a)) if 0.0 <= t <= 1.0]


def _point_segment(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:
    dx, dy = bx - ax, by - ay
    l2 = dx * dx + dy * dy
    t = 0.0 if l2 == 0.0 else min(max(((px - ax) * dx + (py - ay) * dy) / l2, 0.0), 1.0)
    return math.hypot(px - ax - t * dx, py - ay - t * dy)


def _route(w: _ArcWriter, area: _Area, x: float, y: float, c: float) -> Iterator[str]:
    """Lines from the current point to (x, y) that keep off ``area``: straight where the straight line
    keeps 0.4 ``c`` off it, else out along the ray from its centre, round it on waypoints (16 about
    it, their chords 4 mm + ``c`` off), and in along the target's ray."""
    ax, ay = w.p[0], w.p[1]
    if area.distance(ax, ay, x, y) >= 0.4 * c:
        yield w.line(x, y)
        return
    step = math.pi / 8.0
    rho = (area.extent() + c + 4.0) / math.cos(step / 2.0)
    alpha = math.atan2(ay - area.cy, ax - area.cx)
    beta = math.atan2(y - area.cy, x - area.cx)
    yield w.line(area.cx + rho * math.cos(alpha), area.cy + rho * math.sin(alpha))
    ka, kb = round(alpha / step), round(beta / step)
    turn = (kb - ka) % 16
    if turn > 8:
        turn -= 16
    for n in range(abs(turn) + 1):
        k = ka + (n if turn >= 0 else -n)
        yield w.line(area.cx + rho * math.cos(k * step), area.cy + rho * math.sin(k * step))
    yield w.line(area.cx + rho * math.cos(beta), area.cy + rho * math.sin(beta))
    yield w.line(x, y)


def _round_circle(w: _ArcWriter, area: _Area, c: float) -> Iterator[str]:
    """Rings of arcs and a ring of short chords about a protection circle (G17), ``c`` off it."""
    cx, cy, size = area.cx, area.cy, area.size
    ux, uy = cx / RING, cy / RING
    rr = size + c
    yield w.line(cx - ux * rr, cy - uy * rr)
    yield w.arc_from((cx, cy), -2.0 * math.pi)  # a whole circle, clockwise
    for _ in range(24):  # 24 arcs of 15 degrees, counter-clockwise: the whole way round
        yield w.arc_from((cx, cy), math.pi / 12.0)
    r2 = rr + 0.5
    yield w.line(cx - ux * r2, cy - uy * r2)
    for _ in range(16):  # 16 of 22.5 degrees, clockwise, a little farther out
        yield w.arc_from((cx, cy), -math.pi / 8.0)
    # twelve chords whose middles are ``c`` off the circle (their ends a little farther)
    corner = rr / math.cos(math.pi / 12.0)
    base = math.atan2(-uy, -ux)
    for k in range(13):
        t = base + k * math.pi / 6.0
        yield w.line(cx + corner * math.cos(t), cy + corner * math.sin(t))


_OUTWARD = [(0.0, -1.0), (1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)]
"""A square's sides in counter-clockwise order (bottom, right, top, left) by their outward normal;
side k ends at corner k."""


def _round_square(w: _ArcWriter, area: _Area, c: float) -> Iterator[str]:
    """About a protection square (G17): its offset curve ``c`` off it (sides and quarter arcs about the
    corners) counter-clockwise, and clockwise 0.5 mm farther out with arcs for sides; an arc along each
    side whose chord keeps ``c`` + 1 mm off but whose bulge comes ``c`` close; a small whole circle off
    each corner, ``c`` from it."""
    cx, cy, size = area.cx, area.cy, area.size
    corners = [(cx + size, cy - size), (cx + size, cy + size), (cx - size, cy + size), (cx - size, cy - size)]
    # start with the side that faces the current point
    k0 = max(range(4), key=lambda k: _OUTWARD[k][0] * (w.p[0] - cx) + _OUTWARD[k][1] * (w.p[1] - cy))
    kx, ky = corners[k0]
    yield from _route(w, area, kx + _OUTWARD[k0][0] * c, ky + _OUTWARD[k0][1] * c, c)
    for n in range(4):
        k = (k0 + n) % 4
        kx, ky = corners[k]
        yield w.line(kx + _OUTWARD[k][0] * c, ky + _OUTWARD[k][1] * c)
        yield w.arc_from((kx, ky), math.pi / 2.0)
    # clockwise 0.5 mm farther out: the corners' quarter arcs joined by arcs along the sides that
    # bulge away from the square by 0.5 mm (their whole circles reach deep into it)
    far = c + 0.5
    bulge = 0.5
    r_side = (size * size + bulge * bulge) / (2.0 * bulge)
    kx, ky = corners[(k0 + 3) % 4]
    yield w.line(kx + _OUTWARD[k0][0] * far, ky + _OUTWARD[k0][1] * far)
    for n in range(3, -1, -1):
        k = (k0 + n) % 4
        kx, ky = corners[k]
        yield w.arc_from((kx, ky), -math.pi / 2.0)
        nx, ny = _OUTWARD[k]
        tx, ty = -ny, nx
        mx, my = kx - tx * size + nx * far, ky - ty * size + ny * far  # the chord's middle
        yield w.arc_from(
            (mx - nx * (r_side - bulge), my - ny * (r_side - bulge)), -2.0 * math.asin(size / r_side)
        )
    # along each side an arc of sagitta 1 mm: its chord c + 1 off, its middle c off
    sag = 1.0
    r = (size * size + sag * sag) / (2.0 * sag)
    for n in range(4):
        k = (k0 + n) % 4
        kx, ky = corners[k]
        nx, ny = _OUTWARD[k]
        tx, ty = -ny, nx
        mx, my = kx - tx * size, ky - ty * size
        d = c + sag
        yield from _route(w, area, mx + nx * d - tx * size, my + ny * d - ty * size, c)
        yield w.arc_from((mx + nx * (c + r), my + ny * (c + r)), -2.0 * math.asin(size / r))
        yield w.line(mx + nx * (c + 4.0), my + ny * (c + 4.0))
    # whole circles of radius 2 off the corners, ``c`` from them
    for n in range(4):
        k = (k0 + n) % 4
        kx, ky = corners[k]
        dx = 1.0 if kx > cx else -1.0
        dy = 1.0 if ky > cy else -1.0
        s = (c + 2.0) / math.sqrt(2.0)
        ox, oy = kx + dx * s, ky + dy * s
        yield from _route(w, area, ox + dx * 2.0, oy, c)
        yield w.arc_from((ox, oy), 2.0 * math.pi if n % 2 else -2.0 * math.pi)


def _travel(w: _ArcWriter, to_angle: float) -> Iterator[str]:
    """On the travel circle to ``to_angle``, counter-clockwise (once a tour over the +-180 degree seam)."""
    a0 = math.atan2(w.p[1], w.p[0])
    sweep = (to_angle - a0) % (2.0 * math.pi)
    if sweep > 1e-6:
        yield w.arc_from((0.0, 0.0), sweep)


def _vertical(
    w: _ArcWriter, plane: int, x0: float, across: float, outward: float, approach: Iterator[str]
) -> Iterator[str]:
    """Arcs in G18 (``plane`` 18: X is their axis in the areas' base plane) or G19 (Y), at ``x0`` on
    that axis beside an area that lies on the other side of ``outward``, at ``across`` on the other
    base axis (``approach`` brings the tool there): a half circle up and back bulging away from the
    area (its whole circle would reach into it) three times over, an arc over the plane's +-180 degree
    seam, a whole circle whose nearest point is ``x0``. Z stays within -15..3."""
    u = 0 if plane == 18 else 1  # the arcs' axis in the base plane

    def at(value: float, z: float) -> str:
        coords: list[float | None] = [None, None, z]
        coords[u] = value
        coords[1 - u] = across
        return w.line(*coords)

    def centre(value: float, z: float) -> tuple[float, float]:
        return (z, value) if plane == 18 else (value, z)  # plane coordinates: G18 (Z, X), G19 (Y, Z)

    yield from approach
    yield at(x0, -15.0)
    # three half circles up from z -15 to z 3 bulging away from the area (a wave), and back down
    sign = 1.0 if plane == 18 else -1.0
    for z in (-12.0, -6.0, 0.0):
        yield w.arc_from(centre(x0, z), -sign * outward * math.pi)
    for z in (0.0, -6.0, -12.0):
        yield w.arc_from(centre(x0, z), sign * outward * math.pi)
    r = 4.0
    if plane == 18:
        # G18's angle pi is -Z: a quarter about it, leaning away from the area
        lean = r * math.sqrt(0.5)
        cv, cz = x0 + outward * lean, -10.0
        a0 = 0.75 * math.pi if outward > 0 else -0.75 * math.pi
        yield at(cv + r * math.sin(a0), cz + r * math.cos(a0))
        yield w.arc(centre(cv, cz), a0, 0.5 * math.pi * outward)
    else:
        # G19's angle pi is -Y: a half circle through it, on the side away from the area
        cv, cz = (x0 + r if outward > 0 else x0), -10.0
        yield at(cv, cz + r)
        yield w.arc(centre(cv, cz), 0.5 * math.pi, math.pi)
    yield at(x0, -5.0)
    yield w.arc_from(centre(x0 + outward * 3.0, -5.0), 2.0 * math.pi if outward > 0 else -2.0 * math.pi)
    yield at(x0 + outward * 8.0, -5.0)


_GAP = math.pi / 19.0
"""Half the angle between two areas of the ring: a gap to pass through it."""


def _near_arc_tour(w: _ArcWriter, tour: int) -> Iterator[str]:
    """One tour: round every area in G17 on arcs (absolute centres on odd tours), then beside every
    area in G18 and in G19, and beside the work polygon's edges."""
    clearance = 0.5 + 1.5 * ((tour * 7) % 11) / 10.0
    areas = [_Area(*p) for p in PROTECTIONS]
    if tour % 2:
        yield w.mode(161)
    for area in areas:
        angle = math.atan2(area.cy, area.cx)
        yield from _travel(w, angle)
        if area.circle:
            yield from _round_circle(w, area, clearance)
        else:
            yield from _round_square(w, area, clearance)
        yield from _route(w, area, TRAVEL * math.cos(angle), TRAVEL * math.sin(angle), clearance)
    if tour % 2:
        yield w.mode(162)
    apothem = WORK_RADIUS * math.cos(math.pi / 8.0)
    for plane in (18, 19):
        yield w.mode(plane)
        u = 0 if plane == 18 else 1
        for area in areas:
            angle = math.atan2(area.cy, area.cx)
            yield w.line(TRAVEL * math.cos(angle), TRAVEL * math.sin(angle))
            centre = (area.cx, area.cy)
            outward = -1.0 if centre[u] > 0 else 1.0  # the side that faces the origin
            x0 = centre[u] + outward * (area.size + clearance)
            target = [0.0, 0.0]
            target[u], target[1 - u] = x0, centre[1 - u]
            approach = _route(w, area, target[0], target[1], clearance)
            yield from _vertical(w, plane, x0, centre[1 - u], outward, approach)
            yield from _route(w, area, TRAVEL * math.cos(angle), TRAVEL * math.sin(angle), clearance)
        # beside the work polygon's edge at 0 degrees (G18: x = apothem) or 90 degrees (G19: y = apothem),
        # out through the gap between the two areas next to it and back
        gap = _GAP if plane == 18 else 9.0 * _GAP
        yield w.line(TRAVEL * math.cos(gap), TRAVEL * math.sin(gap))
        yield w.line(250.0 * math.cos(gap), 250.0 * math.sin(gap))
        for across in (60.0, 0.0, -60.0):
            x0 = apothem - clearance
            yield from _vertical(w, plane, x0, across, -1.0, iter(()))
        yield w.line(250.0 * math.cos(gap), 250.0 * math.sin(gap))
        yield w.line(TRAVEL * math.cos(gap), TRAVEL * math.sin(gap))
    yield w.mode(17)


def _near_arc_lines(blocks: int, dialect: str) -> Iterator[str]:
    """``blocks`` motion blocks of the arc program (plus its plane and centre mode lines), in a dialect."""
    w = _ArcWriter(dialect)
    yield w.line(TRAVEL, 0.0, -5.0)
    made = 1
    tour = 0
    while True:
        for text in _near_arc_tour(w, tour):
            if not text:
                continue
            if not text.startswith(("G01", "G02", "G03")):
                yield text
                continue
            if made >= blocks:
                if w.plane != 17:
                    yield w.mode(17)
                if w.centre_absolute:
                    yield w.mode(162)
                return
            yield text
            made += 1
        tour += 1


def near_area_arcs(blocks: int, with_areas: bool = True) -> Iterator[str]:
    """The mostly-arcs program near the 20 areas, line by line: ``blocks`` motion blocks after the
    header, and the plane and centre mode lines among them."""
    if with_areas:
        yield from area_header().splitlines()
    yield "G90 G17 G162 G01 X0 Y0 Z-5 F6000"
    yield from _near_arc_lines(blocks, "isg")
    yield "M30"


def near_area_arcs_rs274(blocks: int) -> Iterator[str]:
    """The same moves in LinuxCNC's dialect (no areas; G90.1/G91.1 for G161/G162), for ``rs274 -g``."""
    yield "G21 G90 G17 G91.1 G94 G40 G49 G80"
    yield "G01 X0 Y0 Z-5 F6000"
    yield from _near_arc_lines(blocks, "rs274")
    yield "M2"


def write_lines(path: Path, lines: Iterator[str]) -> int:
    """Write ``lines`` to ``path`` (streamed); returns the number of lines."""
    n = 0
    with path.open("w", encoding="utf-8", buffering=1 << 20) as f:
        for line in lines:
            f.write(line)
            f.write("\n")
            n += 1
    return n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="directory for the program files")
    ap.add_argument("--blocks", type=int, default=1_000_000, help="motion blocks of the near-area program")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "pocket.nc").write_text(pocket_program(), encoding="utf-8")
    (args.out / "shuttle.nc").write_text(shuttle_program(), encoding="utf-8")
    n = write_lines(args.out / "near_areas.nc", near_area_lines(args.blocks))
    m = write_lines(args.out / "near_areas_plain.nc", near_area_lines(args.blocks, with_areas=False))
    r = write_lines(args.out / "near_areas_rs274.ngc", near_area_lines_rs274(args.blocks))
    print(
        f"wrote {args.out}: pocket.nc, shuttle.nc, near_areas.nc ({n} lines), near_areas_plain.nc ({m}), "
        f"near_areas_rs274.ngc ({r})"
    )


if __name__ == "__main__":
    main()
