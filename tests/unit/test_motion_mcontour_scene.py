"""The picture of the blended path (issue 24 item 3, M-24): ``check --plot``'s scene and the dashboard's
live scene (trail and path ahead) draw the contoured corner, not the programmed one."""

from __future__ import annotations

import itertools
import math
from collections.abc import AsyncIterator

import pytest

from hli_server.commands.check import check_program, scene_of
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.runtime import Runtime
from hli_server.runtime.dashboard import TRAIL_TOLERANCE

PROGRAM = (
    "N10 G01 X0 Y0 F3000\nN20 #CONTOUR MODE [DEV PATH_DEV=5]\nN30 G261 X100\nN40 Y100\nN50 G260 X0\nN60 M30\n"
)
CORNER = (100.0, 0.0)


def _cut(points: list[list[float]]) -> float:
    """How close the drawn polyline comes to the programmed corner (distance to its segments)."""
    best = math.inf
    for p, q in itertools.pairwise(points):
        (ax, ay), (bx, by) = p[:2], q[:2]
        dx, dy = bx - ax, by - ay
        den = dx * dx + dy * dy
        t = 0.0 if den == 0 else min(1.0, max(0.0, ((CORNER[0] - ax) * dx + (CORNER[1] - ay) * dy) / den))
        best = min(best, math.hypot(ax + t * dx - CORNER[0], ay + t * dy - CORNER[1]))
    return best


@pytest.fixture
async def runtime() -> AsyncIterator[Runtime]:
    async with Runtime(load_machine(None), clock="stepped", http_port=None) as rt:
        yield rt


@pytest.mark.req("M-24")
def test_check_plot_scene_draws_the_blended_corner() -> None:
    scene = scene_of(check_program(Machine(load_machine(None)), PROGRAM, record_path=True))
    (line,) = scene["path"]
    assert 4.5 < _cut(line) <= 5.0 + 1e-3  # PATH_DEV 5: the corner is cut, by at most 5 mm
    assert line[-1][:2] == [0.0, 100.0]


@pytest.mark.req("M-24")
async def test_the_dashboard_draws_the_blended_corner_ahead_and_behind(runtime: Runtime) -> None:
    op = runtime.operator
    op.load_program(1, PROGRAM)
    op.start(1)
    await runtime.step(300)
    ahead = op.scene(1)["ahead"]
    assert 4.5 < _cut(ahead) <= 5.0 + 1e-3  # the look-ahead holds the transition's support points
    await runtime.step(8000)
    trail = op.scene(1)["path"][0]
    assert 4.5 < _cut(trail) <= 5.0 + TRAIL_TOLERANCE  # the travelled trail (simplified) went round it
