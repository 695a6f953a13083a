"""The programs of issue 16's benchmarks, generated (``python -m benchmarks.programs --out DIR`` writes them).

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
    "near_area_lines",
    "near_area_lines_rs274",
    "pocket_program",
    "shuttle_program",
]

FULL_MACHINE = Path(__file__).with_name("machines") / "full.toml"
"""The full machine of issue 16 (2 channels, 8 axes, 3 collision pairs, FCT_DYN_POS_LIMIT in both)."""

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
