"""Path checks per second of the work/protection area monitoring (FCT-C14, C14-15) with 20 active areas.

Our check (``first_violation``: exact first entry point of a line or arc, pure Python) is timed against
shapely's ``intersects`` on the same data in the same run, so the figure travels across machines as
a ratio:

* reference 1, per block: for each segment a ``LineString`` is built and ``shapely.intersects`` is
  asked against the 20 areas at once (what a per-block check in Python costs with shapely);
* reference 2, batched: one ``shapely.intersects`` call over all segments x all areas (the best case
  for shapely, which a block-by-block CNC check cannot use).

shapely only answers "does it touch", not "where does it leave the allowed space"; ours answers the
second, harder question. Arcs (no shapely equivalent) are timed on their own.

    .venv/bin/python benchmarks/bench_areas.py [--segments N] [--repeat R]
"""

from __future__ import annotations

import argparse
import math
import random
import time
from collections.abc import Callable

import numpy as np
import shapely
from shapely.geometry import Point as ShapelyPoint
from shapely.geometry import Polygon as ShapelyPolygon

from hli_server.engine.areas import Circle, Group, Polygon, Prism, first_violation
from hli_server.engine.geometry import ArcSegment, LineSegment

N_AREAS = 20


def make_areas(rng: random.Random) -> tuple[list[Group], list[object]]:
    """One 20-corner work polygon (300 x 300 mm) and 19 protection areas (polygons and circles)."""
    work_pts = [
        (150.0 + 140.0 * math.cos(a) * (1.0 + 0.05 * (k % 2)), 150.0 + 140.0 * math.sin(a))
        for k, a in enumerate(2.0 * math.pi * i / 20 for i in range(20))
    ]
    works = [Prism(Polygon(work_pts), 0, 1, 2, -100.0, 100.0, 1, False)]
    shapes: list[object] = [ShapelyPolygon(work_pts)]
    prots: list[Prism] = []
    for k in range(N_AREAS - 1):
        cx, cy = rng.uniform(60, 240), rng.uniform(60, 240)
        if k % 2:
            r = rng.uniform(3, 8)
            prots.append(Prism(Circle(cx, cy, r), 0, 1, 2, -50.0, 50.0, 10 + k, True))
            shapes.append(ShapelyPoint(cx, cy).buffer(r, quad_segs=16))
        else:
            n = rng.randint(5, 12)
            radii = [rng.uniform(3, 8) for _ in range(n)]  # star-shaped around (cx, cy): simple
            pts = [
                (cx + r * math.cos(2 * math.pi * i / n), cy + r * math.sin(2 * math.pi * i / n))
                for i, r in enumerate(radii)
            ]
            prots.append(Prism(Polygon(pts), 0, 1, 2, -50.0, 50.0, 10 + k, True))
            shapes.append(ShapelyPolygon(pts))
    return [Group(frozenset({0, 1, 2}), works, prots)], shapes


def make_lines(rng: random.Random, n: int) -> list[LineSegment]:
    """Short moves (1..20 mm) like a machining program, mostly inside the work area."""
    out = []
    x, y = 150.0, 150.0
    for _ in range(n):
        a = rng.uniform(0, 2 * math.pi)
        d = rng.uniform(1, 20)
        nx, ny = x + d * math.cos(a), y + d * math.sin(a)
        if not (30 < nx < 270 and 30 < ny < 270):
            nx, ny = 150.0, 150.0
        out.append(LineSegment((x, y, 0.0), (nx, ny, 0.0)))
        x, y = nx, ny
    return out


def make_arcs(rng: random.Random, n: int) -> list[ArcSegment]:
    out = []
    for _ in range(n):
        cx, cy = rng.uniform(60, 240), rng.uniform(60, 240)
        r = rng.uniform(1, 20)
        a0 = rng.uniform(0, 2 * math.pi)
        sweep = rng.uniform(-math.pi, math.pi)
        start = (cx + r * math.cos(a0), cy + r * math.sin(a0), 0.0)
        end = (cx + r * math.cos(a0 + sweep), cy + r * math.sin(a0 + sweep), 0.0)
        out.append(ArcSegment(start, end, (0, 1), (cx, cy), r, a0, sweep))
    return out


def best(fn: Callable[[], int], repeat: int) -> tuple[float, int]:
    elapsed = float("inf")
    result = 0
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        elapsed = min(elapsed, time.perf_counter() - t0)
    return elapsed, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--segments", type=int, default=20_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=14)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    groups, shapes = make_areas(rng)
    lines = make_lines(rng, args.segments)
    arcs = make_arcs(rng, args.segments)
    geoms = np.array(shapes, dtype=object)

    def ours_lines() -> int:
        return sum(first_violation(groups, seg) is not None for seg in lines)

    def ours_arcs() -> int:
        return sum(first_violation(groups, seg) is not None for seg in arcs)

    def shapely_per_block() -> int:
        hits = 0
        for seg in lines:
            line = shapely.linestrings([seg.start[:2], seg.end[:2]])
            hits += int(shapely.intersects(geoms, line).any())
        return hits

    coords = np.array([[seg.start[:2], seg.end[:2]] for seg in lines])

    def shapely_batched() -> int:
        all_lines = shapely.linestrings(coords)
        return int(shapely.intersects(all_lines[:, None], geoms[None, :]).any(axis=1).sum())

    n = len(lines)
    t_ours, violations = best(ours_lines, args.repeat)
    t_arcs, arc_violations = best(ours_arcs, args.repeat)
    t_ref, _ = best(shapely_per_block, args.repeat)
    t_batch, _ = best(shapely_batched, args.repeat)
    ours = n / t_ours
    print(f"areas: {N_AREAS} active (1 work polygon of 20 corners, 19 protection polygons/circles)")
    print(f"lines, ours (exact entry point):       {ours:12,.0f} checks/s  ({violations} of {n} violate)")
    arcs_rate = len(arcs) / t_arcs
    print(f"arcs, ours (exact entry point):        {arcs_rate:12,.0f} checks/s  ({arc_violations} violate)")
    print(f"lines, shapely intersects per block:   {n / t_ref:12,.0f} checks/s")
    print(f"lines, shapely intersects batched:     {n / t_batch:12,.0f} checks/s")
    print(f"ratio ours / shapely per block: {ours / (n / t_ref):.2f}")
    print(f"ratio ours / shapely batched:   {ours / (n / t_batch):.3f}")


if __name__ == "__main__":
    main()
