"""TF5225 measuring cycles (touch probe) as stand-ins.

Pages: https://infosys.beckhoff.com/content/1033/tf5225_tc3_cnc_cycles_measurement/<id>.html (the ids are
in each :class:`~hli_server.engine.cycles.base.StandIn`'s ``page``; /work/notes/cycles-research.md has the
rest). What the pages leave open - where the simulated workpiece lies when a cycle only says how far to
measure, the order of the moves the pictures show - is the stand-in's decision and docs/cycles.md says it
cycle by cycle:

* a measuring path ``@P4``/``@P5``/``@P6`` ends the default crossover (5 mm, at most half the path) beyond
  the surface the probe is expected to touch;
* a spigot's top lies half the safety clearance ``@P13`` below the height the probe stands at above it;
  where the page gives no measuring height, the lateral points are probed 5 mm below that top;
* a sphere's top is expected where the measuring path ``@P6`` less the crossover ends.

Every result is computed from what the probe latched (not from the simulated workpiece), so a user's probe
signal from the PLC, a feed override or an area that shortens a move change the results as on the machine.
"""

from __future__ import annotations

import math
from collections.abc import Generator, Iterator

from hli_server.engine.cycles.base import Cycle, Output, RunFn, StandIn, fmt, require_distinct
from hli_server.engine.cycles.errors import A_APPROXIMATED, A_INVALID, CycleError
from hli_server.engine.cycles.geometry import fit_circle, frame_angles, sphere_from_ring
from hli_server.engine.cycles.params import Param
from hli_server.engine.cycles.probe import Box, HalfSpace, Hole, Sphere, Spigot, Vec3
from hli_server.engine.nc.blocks import Block

__all__ = ["MEASURING"]

_PAGE = "https://infosys.beckhoff.com/content/1033/tf5225_tc3_cnc_cycles_measurement/"
_CROSSOVER = 5.0
"""The cycles' default crossover range @P33 (mm): the travel beyond the expected edge."""
_BELOW_TOP = 5.0
"""How far below a spigot's top the lateral points are probed where the page gives no height."""

# --- the parameters several cycles share --------------------------------------------------------------
P7 = Param(
    7,
    "zero offset to write: 1..9 (G159=n), 54..59 (G54..G59); absent: measure only; only with G53 active",
    alarm=13408,
    rule="1..6 or 54..59 simulated (7..9, 53: 910110); writing needs G53 at the call (else 14421)",
)
P9 = Param(9, "shift of the result along X", default=0.0)
P10 = Param(10, "shift of the result along Y", default=0.0)
P11 = Param(11, "shift of the result along Z", default=0.0)
P12 = Param(12, "reference angle [deg]: output = computed C - @P12", default=0.0)
P13 = Param(
    13,
    "safety clearance for pre-positioning [mm]",
    default_text="probe diameter (at least 1)",
    check="nonnegative",
)
P33 = Param(33, "crossover range beyond the expected edge [mm]", default=_CROSSOVER, check="nonnegative")
P39 = Param(39, "the coordinate system (#CS) to write, 1..10", required=True, low=1.0, high=10.0, alarm=13448)
P13_OPTIONAL = Param(
    13, "safety clearance for pre-positioning; absent: the whole path at measuring feed", check="nonnegative"
)
P14_FIRST = Param(14, "angle of the 1st point from X+ [deg]", default=0.0)
P15_BETWEEN = Param(15, "angle between the lateral touches [deg]", default=90.0, check="nonzero")
P19_BELOW_TOP = Param(
    19,
    "pre-positioning along Z (relative) to the measuring height",
    default_text="5 mm below the spigot's top",
)
P19_CLEARANCE = Param(
    19,
    "clearance along Z between the measurements (incremental)",
    default_text="back up by the Z pre-positioning",
)
P19_TO_HEIGHT = Param(19, "pre-positioning along Z (incremental, to the measuring height)", required=True)
P22_BEFORE = Param(
    22,
    "pre-positioning along Z before the 1st measurement (incremental); @P20 in the page's example",
    default_text="@P20, else 0",
)
P22_DEPTH = Param(22, "measuring depth (incremental Z)", required=True)
P2_HOLE = Param(2, "hole diameter", required=True, check="positive")
P2_SPIGOT = Param(2, "spigot diameter", required=True, check="positive")
P2_SPIGOT_ESTIMATED = Param(2, "estimated spigot diameter", required=True, check="positive")
P33_SPHERE = Param(33, "crossover range", default_text="@P87/4")
P6_DOWN = Param(6, "measuring path toward -Z", required=True, check="nonzero")
P87_SPHERE = Param(87, "sphere diameter", required=True, check="positive")


def _above(what: str) -> tuple[Param, Param, Param]:
    """@P17..@P19: the pre-positioning above ``what`` (a spigot, a hole)."""
    return (
        Param(17, f"pre-positioning along X above {what} (incremental)", default=0.0),
        Param(18, f"pre-positioning along Y above {what} (incremental)", default=0.0),
        Param(19, f"pre-positioning along Z above {what} (incremental)", default=0.0),
    )


def _path(number: int, axis: str) -> Param:
    return Param(number, f"measuring path along {axis} (incremental, signed)", required=True, check="nonzero")


def safety(c: Cycle) -> float:
    """@P13, by default the probe's diameter; at least 1 mm for the simulated probe of radius 0 (a point),
    which would otherwise pre-position on the very surface."""
    return c.args.num(13, max(2.0 * c.ball, 1.0))


def _fit(c: Cycle, points: list[tuple[float, float]], what: str) -> tuple[tuple[float, float], float]:
    try:
        return fit_circle(points)
    except ValueError:
        raise CycleError(
            A_INVALID,
            f"{c.spec.name}: the touches on the {what} give no circle (check the angles and the probe)",
        ) from None


def _margin(path: float) -> float:
    return min(_CROSSOVER, abs(path) / 2.0)


def _with(p: Vec3, axis: int, value: float) -> Vec3:
    return (value if axis == 0 else p[0], value if axis == 1 else p[1], value if axis == 2 else p[2])


def _add(p: Vec3, dx: float, dy: float, dz: float) -> Vec3:
    return (p[0] + dx, p[1] + dy, p[2] + dz)


def probe_edge(c: Cycle, axis: int, path: float) -> Generator[Block, None, float]:
    """Measure a plane face along ``axis`` (0 X, 1 Y, 2 Z) by ``path`` from where the probe is, back to
    the start afterwards; the face's coordinate. The simulated face lies where the path less its margin
    puts the probe's touch."""
    start = c.at
    sign = 1.0 if path > 0.0 else -1.0
    touch_tip = start[axis] + sign * (abs(path) - _margin(path))
    # the face, for the probe sphere's centre path: lateral faces are one radius beyond the centre, a face
    # below the probe is at its tip, one above it a diameter above the tip
    if axis == 2:
        surface = touch_tip if sign < 0.0 else touch_tip + 2.0 * c.ball
    else:
        surface = touch_tip + sign * c.ball
    normal: Vec3 = _with((0.0, 0.0, 0.0), axis, -sign)
    yield from c.measure(
        _with(start, axis, start[axis] + path), HalfSpace(_with(start, axis, surface), normal)
    )
    tip = c.contact()
    yield from c.position(start)
    if axis == 2:
        return tip[2] if sign < 0.0 else tip[2] + 2.0 * c.ball
    return tip[axis] + sign * c.ball


# --- SysMeasWcs1 .. 7: faces -------------------------------------------------------------------------
def _faces(x: bool, y: bool, z: bool) -> RunFn:
    def run(c: Cycle) -> Iterator[Block]:
        a = c.args
        zo = c.zero_offset_target()
        start = c.at
        p4 = a.num(4) if x else 0.0
        p5 = a.num(5) if y else 0.0
        p6 = a.num(6) if z else 0.0
        several = [x, y, z].count(True) > 1
        pre_x = a.num(17, p4) if several and x else 0.0
        pre_y = a.num(18, p5) if several and y else 0.0
        pre_z = a.num(19, p6) if several and z else 0.0
        values: dict[str, float] = {}
        if z:
            # over the top face: beside the lateral faces' probing points
            above = _add(start, pre_x if x else 0.0, pre_y if y else 0.0, 0.0) if several else start
            yield from c.position(above)
            top = yield from probe_edge(c, 2, p6)
            yield from c.position(start)
            values[c.z_axis] = top + a.num(11)
        if x:
            at = _add(start, 0.0, pre_y if y else 0.0, pre_z if z else 0.0) if several else start
            yield from c.position(_with(start, 2, at[2]))
            yield from c.position(at)
            edge = yield from probe_edge(c, 0, p4)
            yield from c.position(_with(start, 2, at[2]))
            yield from c.position(start)
            values[c.x_axis] = edge + a.num(9)
        if y:
            at = _add(start, pre_x if x else 0.0, 0.0, pre_z if z else 0.0) if several else start
            yield from c.position(_with(start, 2, at[2]))
            yield from c.position(at)
            edge = yield from probe_edge(c, 1, p5)
            yield from c.position(_with(start, 2, at[2]))
            yield from c.position(start)
            values[c.y_axis] = edge + a.num(10)
        for name, axis in ((c.x_axis, "X"), (c.y_axis, "Y"), (c.z_axis, "Z")):
            if name in values:
                c.result(f"SysRet{axis}", values[name])
        c.write_zero_offset(zo, values)

    return run


def _faces_spec(number: int, title: str, page: str, x: bool, y: bool, z: bool) -> StandIn:
    params: list[Param] = []
    if x:
        params.append(_path(4, "X"))
    if y:
        params.append(_path(5, "Y"))
    if z:
        params.append(_path(6, "Z"))
    params.append(P7)
    params += [p for p, on in ((P9, x), (P10, y), (P11, z)) if on]
    several = [x, y, z].count(True) > 1
    if several:
        if x:
            params.append(Param(17, "pre-positioning along X (incremental)", default_text="@P4"))
        if y:
            params.append(Param(18, "pre-positioning along Y (incremental)", default_text="@P5"))
        if z:
            params.append(
                Param(
                    19,
                    "pre-positioning along Z before the lateral measurements (incremental)",
                    default_text="@P6",
                )
            )
    outputs = tuple(
        Output(f"SysRet{n}", f"measured {n} value of the workpiece (+ its @P shift)")
        for n, on in (("X", x), ("Y", y), ("Z", z))
        if on
    )
    names = [n for n, on in (("X", x), ("Y", y), ("Z", z)) if on]
    moves = (
        f"probes {', '.join(names)} from the start"
        + (
            ": Z over the top (start + @P17/@P18), the lateral faces below it (start + @P19), each from "
            "beside the corner"
            if several
            else ""
        )
        + "; back to the start after each touch"
    )
    run = _faces(x, y, z)
    return StandIn(
        f"SysMeasWcs{number}.ecy", "TF5225", title, _PAGE + page, tuple(params), outputs, run, moves, True
    )


# --- circles: holes and spigots -------------------------------------------------------------------------
def _angles(count: int, first: float, step: float) -> list[float]:
    return [first + k * step for k in range(count)]


def probe_hole(
    c: Cycle, centre: Vec3, diameter: float, angles: list[float]
) -> Generator[Block, None, tuple[Vec3, float]]:
    """Probe a bore from inside at the current height, one touch per angle, back to ``centre`` after each;
    the measured centre (at the current height) and diameter."""
    a = c.args
    radius = diameter / 2.0
    if c.ball >= radius:
        raise CycleError(
            A_INVALID,
            f"{c.spec.name}: the probe (radius {fmt(c.ball)}) does not fit the hole @P2 = {fmt(diameter)}",
            2,
        )
    crossover = a.num(33)
    clearance = a.num(13, -1.0)
    hole = Hole(centre, radius)
    ring: list[tuple[float, float]] = []
    for angle in angles:
        u = (math.cos(math.radians(angle)), math.sin(math.radians(angle)))
        reach = radius - c.ball
        if clearance >= 0.0:
            pre = max(0.0, reach - clearance)
            yield from c.position(_add(centre, u[0] * pre, u[1] * pre, 0.0))
        far = reach + crossover
        yield from c.measure(_add(centre, u[0] * far, u[1] * far, 0.0), hole)
        tip = c.contact()
        ring.append((tip[0], tip[1]))
        yield from c.position(centre)
    (cx, cy), rho = _fit(c, ring, "hole")
    return (cx, cy, centre[2]), 2.0 * (rho + c.ball)


def probe_spigot(
    c: Cycle, centre: Vec3, diameter: float, angles: list[float], depth: float
) -> Generator[Block, None, tuple[Vec3, float]]:
    """Probe a spigot from outside: for each angle out to beside it above its top, down to the measuring
    height ``centre.z + depth``, a touch toward its axis, back out and up to ``centre``; the measured centre
    and diameter. The simulated spigot's top lies half the safety clearance below ``centre``."""
    a = c.args
    radius = diameter / 2.0
    clearance = safety(c)
    crossover = a.num(33)
    spigot = Spigot(centre, radius, centre[2] - clearance / 2.0)
    if spigot not in c.obstacles:
        c.obstacles.append(spigot)
    ring: list[tuple[float, float]] = []
    for angle in angles:
        u = (math.cos(math.radians(angle)), math.sin(math.radians(angle)))
        out = radius + c.ball + clearance
        above = _add(centre, u[0] * out, u[1] * out, 0.0)
        yield from c.position(above)
        beside = _add(above, 0.0, 0.0, depth)
        yield from c.position(beside)
        near = radius + c.ball - crossover
        yield from c.measure(_add(centre, u[0] * near, u[1] * near, depth), spigot)
        tip = c.contact()
        ring.append((tip[0], tip[1]))
        yield from c.position(beside)
        yield from c.position(above)
    yield from c.position(centre)
    (cx, cy), rho = _fit(c, ring, "spigot")
    return (cx, cy, centre[2]), 2.0 * (rho - c.ball)


def probe_block(
    c: Cycle, centre: Vec3, half: tuple[float, float], axes: tuple[int, ...], depth: float
) -> Generator[Block, None, dict[int, tuple[float, float]]]:
    """A block (or a web) centred under the probe: for each of ``axes`` both faces, each from beside it
    above the top, down by ``depth``, a touch toward the centre, back out and up; per axis the faces'
    coordinates (low, high). The simulated block's top lies half the safety clearance below ``centre``."""
    a = c.args
    clearance = safety(c)
    crossover = a.num(33)
    block = Box(centre, half, centre[2] - clearance / 2.0)
    faces: dict[int, tuple[float, float]] = {}
    for k in axes:
        found: list[float] = []
        for sign in (1.0, -1.0):
            out = half[k] + c.ball + clearance
            above = _with(centre, k, centre[k] + sign * out)
            yield from c.position(above)
            beside = _add(above, 0.0, 0.0, depth)
            yield from c.position(beside)
            near = half[k] + c.ball - crossover
            yield from c.measure(_with(beside, k, centre[k] + sign * near), block)
            tip = c.contact()
            found.append(tip[k] - sign * c.ball)
            yield from c.position(beside)
            yield from c.position(above)
        yield from c.position(centre)
        faces[k] = (found[1], found[0])
    return faces


def _block_run(axes: tuple[int, ...]) -> RunFn:
    """SysMeasWcs14 (a web along Y, its width along X: @P3) and SysMeasWcs29 (an outer rectangle
    @P31 x @P32): the centre and the lengths between the faces."""

    def run(c: Cycle) -> Iterator[Block]:
        a = c.args
        zo = c.zero_offset_target()
        start = c.at
        half = (a.num(31) / 2.0, a.num(32) / 2.0) if len(axes) == 2 else (a.num(3) / 2.0, 1.0e6)
        faces = yield from probe_block(c, start, half, axes, a.num(19))
        values: dict[str, float] = {}
        for k in axes:
            low, high = faces[k]
            name, axis = ((c.x_axis, "X"), (c.y_axis, "Y"))[k]
            middle = (low + high) / 2.0 + a.num(9 + k)
            c.result(f"SysRet{axis}", middle)
            c.result(f"SysRetLength{axis}", high - low)
            values[name] = middle
        c.write_zero_offset(zo, values)

    return run


def _circle_results(c: Cycle, centre: Vec3, diameter: float) -> None:
    a = c.args
    x, y = centre[0] + a.num(9), centre[1] + a.num(10)
    c.result("SysRetX", x)
    c.result("SysRetY", y)
    c.result("SysRetDiameter", diameter)


def _hole_run(points: int, fixed: bool, obstacle: bool) -> RunFn:
    def run(c: Cycle) -> Iterator[Block]:
        a = c.args
        zo = c.zero_offset_target()
        start = c.at
        if fixed:
            angles = _angles(points, 0.0, 360.0 / points)
        elif points == 3:
            angles = [a.num(14), a.num(15), a.num(16)]
            require_distinct(c.spec.name, angles, [14, 15, 16])
        else:
            angles = _angles(points, a.num(14), a.num(15))
        centre = start
        if obstacle:
            centre = _add(start, 0.0, 0.0, a.num(19))
            yield from c.position(centre)
        found, diameter = yield from probe_hole(c, centre, a.num(2), angles)
        if obstacle:
            yield from c.position(start)
        _circle_results(c, found, diameter)
        c.write_zero_offset(zo, {c.x_axis: found[0] + a.num(9), c.y_axis: found[1] + a.num(10)})

    return run


def _spigot_run(points: int, fixed: bool, depth_param: int, depth_default: bool) -> RunFn:
    def run(c: Cycle) -> Iterator[Block]:
        a = c.args
        zo = c.zero_offset_target()
        start = c.at
        if fixed:
            angles = _angles(points, 0.0, 360.0 / points)
        elif points == 3 and not depth_default:
            angles = [a.num(14), a.num(15), a.num(16)]
            require_distinct(c.spec.name, angles, [14, 15, 16])
        else:
            angles = _angles(points, a.num(14), a.num(15))
        depth = a.num(depth_param) if a.given(depth_param) else -(safety(c) / 2.0 + _BELOW_TOP)
        found, diameter = yield from probe_spigot(c, start, a.num(2), angles, depth)
        _circle_results(c, found, diameter)
        c.write_zero_offset(zo, {c.x_axis: found[0] + a.num(9), c.y_axis: found[1] + a.num(10)})

    return run


_CIRCLE_OUT = (
    Output("SysRetX", "measured centre X (+ @P9)"),
    Output("SysRetY", "measured centre Y (+ @P10)"),
    Output("SysRetDiameter", "measured diameter"),
)
_ANGLES3 = (
    P14_FIRST,
    Param(15, "angle of the 2nd point from X+ [deg]", default=120.0),
    Param(16, "angle of the 3rd point from X+ [deg]", default=240.0),
)
_START_STEP = (
    P14_FIRST,
    Param(15, "incremental angle to the next point [deg]", default=90.0, check="nonzero"),
)
_SPIGOT_START_STEP = (P2_SPIGOT_ESTIMATED, P7, P9, P10, P13, *_START_STEP, P19_BELOW_TOP, P33)
"""SysMeasWcs38 and 39 (one page: three or four points)."""


def _spec(
    name: str,
    title: str,
    page: str,
    params: tuple[Param, ...],
    outputs: tuple[Output, ...],
    run: RunFn,
    moves: str,
) -> StandIn:
    return StandIn(name, "TF5225", title, _PAGE + page, params, outputs, run, moves, True)


# --- SysMeasWcs25/27: angle between a point and a spigot (C) -----------------------------------------
def probe_circle(
    c: Cycle, kind: str, above: Vec3, diameter: float, depth: float
) -> Generator[Block, None, Vec3]:
    """A hole or a spigot centred under ``above``, four points at ``depth`` below it (SysMeasWcs8 / 10);
    the probe back at ``above``; the measured centre."""
    if kind == "spigot":
        found, _ = yield from probe_spigot(c, above, diameter, [0.0, 90.0, 180.0, 270.0], depth)
        return found
    down = _add(above, 0.0, 0.0, depth)
    yield from c.position(down)
    found, _ = yield from probe_hole(c, down, diameter, [0.0, 90.0, 180.0, 270.0])
    yield from c.position(above)
    return found


def _twist(c: Cycle, zo: str | None, first: tuple[float, float], second: tuple[float, float]) -> None:
    angle = math.degrees(math.atan2(second[1] - first[1], second[0] - first[0])) - c.args.num(12)
    c.result("SysRetC", angle)
    _write_twist(c, zo, angle)


def _point_circle(point_axis: int, kind: str) -> RunFn:
    """SysMeasWcs24..27: a point of a face (along Y with @P5: "point in X"; along X with @P4: "point in Y")
    and the centre of a hole or a spigot; the angle of the line from the point to the centre."""

    def run(c: Cycle) -> Iterator[Block]:
        a = c.args
        zo = c.zero_offset_target()
        start = c.at
        depth = a.num(22)
        path = a.num(5) if point_axis == 0 else a.num(4)
        # 1. the point: down by the measuring depth, a touch across, back up
        yield from c.position(_add(start, 0.0, 0.0, depth))
        edge = yield from probe_edge(c, 1 if point_axis == 0 else 0, path)
        yield from c.position(start)
        point = (start[0], edge) if point_axis == 0 else (edge, start[1])
        # 2. above the hole or spigot (@P17/@P18, then @P19), 3. four points round it at the depth
        over = _add(start, a.num(17), a.num(18), 0.0)
        yield from c.position(over)
        above = _add(over, 0.0, 0.0, a.num(19, 0.0))
        yield from c.position(above)
        found = yield from probe_circle(c, kind, above, a.num(2), depth)
        _twist(c, zo, point, (found[0], found[1]))

    return run


def _two_circles(first: str, second: str) -> RunFn:
    """SysMeasWcs21..23: two holes, two spigots, a hole and a spigot; the angle of the line between
    their centres."""

    def run(c: Cycle) -> Iterator[Block]:
        a = c.args
        zo = c.zero_offset_target()
        start = c.at
        depth = a.num(22)
        one = yield from probe_circle(c, first, start, a.num(2), depth)
        over = _add(start, a.num(17), a.num(18), 0.0)
        yield from c.position(over)
        above = _add(over, 0.0, 0.0, a.num(19, 0.0))
        yield from c.position(above)
        two = yield from probe_circle(c, second, above, a.num(29, a.num(2)), depth)
        _twist(c, zo, (one[0], one[1]), (two[0], two[1]))

    return run


def _face_twist(axis: int) -> RunFn:
    """SysMeasWcs19 (a face probed along X at two Y positions) and SysMeasWcs20 (along Y at two X positions):
    the face's twist about Z."""

    def run(c: Cycle) -> Iterator[Block]:
        a = c.args
        zo = c.zero_offset_target()
        start = c.at
        path = a.num(4) if axis == 0 else a.num(5)
        shift = a.num(18) if axis == 0 else a.num(17)
        if shift == 0.0:
            number = 18 if axis == 0 else 17
            raise CycleError(
                A_INVALID, f"{c.spec.name}: @P{number} must not be 0 (the second point's offset)", number
            )
        down = a.num(22, a.num(20, 0.0))
        clear = a.num(19, -down)
        first_at = _add(start, 0.0, 0.0, down)
        yield from c.position(first_at)
        one = yield from probe_edge(c, axis, path)
        yield from c.position(_add(first_at, 0.0, 0.0, clear))
        side = (0.0, shift) if axis == 0 else (shift, 0.0)
        yield from c.position(_add(first_at, side[0], side[1], clear))
        second_at = _add(first_at, side[0], side[1], 0.0)
        yield from c.position(second_at)
        two = yield from probe_edge(c, axis, path)
        yield from c.position(_add(second_at, 0.0, 0.0, clear))
        yield from c.position(_add(start, 0.0, 0.0, clear))
        yield from c.position(start)
        if axis == 0:  # a face along Y turned by C: x = x0 - y tan C
            angle = -math.degrees(math.atan2(two - one, shift))
        else:  # a face along X: y = y0 + x tan C
            angle = math.degrees(math.atan2(two - one, shift))
        angle -= a.num(12)
        c.result("SysRetC", angle)
        _write_twist(c, zo, angle)

    return run


def _write_twist(c: Cycle, zo: str | None, angle: float) -> None:
    if zo is None:
        return
    if "C" not in c.ctx.axis_names:
        c.ctx.warn(
            A_APPROXIMATED,
            f"{c.spec.name}: @P7: the channel has no C axis; the twist {fmt(angle)} deg is measured "
            "(V.CYC.SysRetC) but not written into " + zo,
        )
        return
    c.write_zero_offset(zo, {"C": angle})


# --- spheres, teach-in -------------------------------------------------------------------------------
def probe_sphere(
    c: Cycle, start: Vec3, diameter: float, path: float, first: float, step: float
) -> Generator[Block, None, tuple[Vec3, float]]:
    """A sphere below the probe (TF5225 process 548444427/550151051): a touch on its top, back up, four
    lateral touches at its equator (each from beside it above, down, toward its centre, back), back to the
    start; the measured centre and diameter (:func:`geometry.sphere_from_ring`)."""
    a = c.args
    radius = diameter / 2.0
    crossover = a.num(33, radius / 2.0)
    clearance = safety(c)
    top_tip = start[2] - (abs(path) - _margin(path))
    sphere = Sphere((start[0], start[1], top_tip - radius), radius)
    yield from c.measure(_add(start, 0.0, 0.0, -abs(path)), sphere)
    touched = c.contact()
    yield from c.position(start)
    centre_z = touched[2] - radius
    ring_tip = centre_z - c.ball
    ring: list[tuple[float, float]] = []
    for k in range(4):
        angle = math.radians(first + k * step)
        u = (math.cos(angle), math.sin(angle))
        out = radius + c.ball + clearance
        above = _add(start, u[0] * out, u[1] * out, 0.0)
        yield from c.position(above)
        beside = _with(above, 2, ring_tip)
        yield from c.position(beside)
        near = radius + c.ball - crossover
        yield from c.measure((start[0] + u[0] * near, start[1] + u[1] * near, ring_tip), sphere)
        tip = c.contact()
        ring.append((tip[0], tip[1]))
        yield from c.position(beside)
        yield from c.position(above)
    yield from c.position(start)
    try:
        centre, reach = sphere_from_ring(c.centre_of(touched), ring, ring_tip + c.ball)
    except ValueError:
        raise CycleError(A_INVALID, f"{c.spec.name}: the touches on the sphere give no sphere") from None
    return (centre[0], centre[1], centre[2]), 2.0 * (reach - c.ball)


def _sphere_run(c: Cycle) -> Iterator[Block]:
    a = c.args
    zo = c.zero_offset_target()
    centre, diameter = yield from probe_sphere(c, c.at, a.num(87), a.num(6), a.num(14), a.num(15))
    x, y, z = centre[0] + a.num(9), centre[1] + a.num(10), centre[2] + a.num(11)
    c.result("SysRetX", x)
    c.result("SysRetY", y)
    c.result("SysRetZ", z)
    c.result("SysRetDiameter", diameter)
    c.write_zero_offset(zo, {c.x_axis: x, c.y_axis: y, c.z_axis: z})


def cs_program(number: int, origin: Vec3, angles: Vec3) -> str:
    """The subroutine a teach-in cycle writes, as the pages show it (550177419): ``CS_BASE_<n>.bcs``."""
    values = [*origin, *angles]
    listed = ",".join(fmt(v) for v in values)
    return (
        f"%CS_BASE_{number}.bcs\n#COMMENT BEGIN\n"
        + "".join(f"CS {n} = {fmt(v)}\n" for n, v in zip("XYZABC", values, strict=True))
        + f"#COMMENT END\n#CS DEF [{number}][{listed}]\n#CS ON [{number}]\nM17\n"
    )


def _teach_results(c: Cycle, origin: Vec3, angles: Vec3) -> None:
    for name, value in zip(
        ("SysRetX", "SysRetY", "SysRetZ", "SysRetA", "SysRetB", "SysRetC"), (*origin, *angles), strict=True
    ):
        c.result(name, value)
    number = int(c.args.num(39))
    c.ctx.write_program(f"CS_BASE_{number}.bcs", cs_program(number, origin, angles))


def _shifted(c: Cycle, p: Vec3) -> Vec3:
    a = c.args
    return (p[0] + a.num(9), p[1] + a.num(10), p[2] + a.num(11))


def _cs5_run(c: Cycle) -> Iterator[Block]:
    a = c.args
    _check_cs(c)
    start = c.at
    diameter = a.num(87)
    path = a.num(6)
    starts = [start, _add(start, a.num(41), a.num(43), 0.0), _add(start, a.num(42), a.num(44), 0.0)]
    radius = diameter / 2.0
    nominal: list[Vec3] = []
    measured: list[Vec3] = []
    for at in starts:
        if at != c.at:
            yield from c.position(at)
        top_tip = at[2] - (abs(path) - _margin(path))
        nominal.append((at[0], at[1], top_tip - radius))
        centre, _ = yield from probe_sphere(c, at, diameter, path, a.num(14), a.num(15))
        measured.append(centre)
    yield from c.position(start)
    try:
        angles = frame_angles(nominal, measured)
    except ValueError as exc:
        raise CycleError(A_INVALID, f"{c.spec.name}: the three spheres @P41..@P44 {exc}", 41) from None
    _teach_results(c, _shifted(c, measured[0]), angles)


def _check_cs(c: Cycle) -> None:
    n = c.args.num(39)
    if n != int(n):
        raise CycleError(
            13448,
            f"{c.spec.name}: coordinate system ID @P39 = {fmt(n)} is not defined; 1 to 10 are allowed",
            39,
        )


def _cs1_run(c: Cycle) -> Iterator[Block]:
    _check_cs(c)
    c.ctx.warn(
        A_APPROXIMATED,
        f"{c.spec.name}: manual teach-in is an operator's dialogue on the kernel; the stand-in takes the "
        f"tool tip's position at the call (plus the probe deviation) as the taught origin and no rotation",
    )
    dev = c.ctx.deviation()
    origin = (c.at[0] + dev[0], c.at[1] + dev[1], c.at[2] + dev[2])
    _teach_results(c, origin, (0.0, 0.0, 0.0))
    nothing: list[Block] = []
    yield from nothing


def _cs2_run(c: Cycle) -> Iterator[Block]:
    a = c.args
    _check_cs(c)
    z = yield from probe_edge(c, 2, -abs(a.num(6)))
    x = yield from probe_edge(c, 0, a.num(4))
    y = yield from probe_edge(c, 1, a.num(5))
    _teach_results(c, _shifted(c, (x, y, z)), (a.num(14), a.num(15), a.num(16)))


# --- calibration in a ring ------------------------------------------------------------------------------
def _calib_ring(c: Cycle) -> Iterator[Block]:
    a = c.args
    start = c.at
    diameter = a.num(2)
    crossover = a.num(33, diameter / 2.0)
    radius = diameter / 2.0
    ring = Hole(start, radius)
    points: list[tuple[float, float]] = []
    for k in range(4):
        angle = math.radians(a.num(14) + k * a.num(15))
        u = (math.cos(angle), math.sin(angle))
        far = radius - c.ball + crossover
        yield from c.measure(_add(start, u[0] * far, u[1] * far, 0.0), ring)
        tip = c.contact()
        points.append((tip[0], tip[1]))
        yield from c.position(start)
    _, rho = _fit(c, points, "ring")
    c.result("SysRetToolRadius", radius - rho)
    c.result("SysRetOffsetX", 0.0)
    c.result("SysRetOffsetY", 0.0)


# --- the table ---------------------------------------------------------------------------------------
_FACE = "measured value of the workpiece"

MEASURING: tuple[StandIn, ...] = (
    _faces_spec(1, "Measure in X axis", "303455883.html", True, False, False),
    _faces_spec(2, "Measure in Y axis", "349450763.html", False, True, False),
    _faces_spec(3, "Measure in Z axis (by analogy with SysMeasWcs1)", "322102027.html", False, False, True),
    _faces_spec(4, "Measure in X and Y axes", "303480843.html", True, True, False),
    _faces_spec(5, "Measure in X and Z axes", "303491467.html", True, False, True),
    _faces_spec(
        6, "Measure in Y and Z axes (by analogy with SysMeasWcs5)", "322102027.html", False, True, True
    ),
    _faces_spec(7, "Measure in X, Y and Z axes", "303507595.html", True, True, True),
    _spec(
        "SysMeasWcs8.ecy",
        "Inner diameter with 4 points",
        "304402827.html",
        (
            P2_HOLE,
            P7,
            P9,
            P10,
            P13_OPTIONAL,
            P33,
        ),
        _CIRCLE_OUT,
        _hole_run(4, True, False),
        "inside the hole at the measuring height: four touches outward at 0/90/180/270 deg, back to the "
        "centre after each",
    ),
    _spec(
        "SysMeasWcs9.ecy",
        "Inner diameter with 3 points",
        "303525259.html",
        (
            P2_HOLE,
            P7,
            P9,
            P10,
            P13_OPTIONAL,
            *_ANGLES3,
            P33,
        ),
        _CIRCLE_OUT,
        _hole_run(3, False, False),
        "inside the hole: three touches outward at @P14/@P15/@P16 (must differ), back to the centre after "
        "each",
    ),
    _spec(
        "SysMeasWcs10.ecy",
        "Outer diameter with 4 points",
        "303535627.html",
        (
            P2_SPIGOT,
            P19_TO_HEIGHT,
            P7,
            P9,
            P10,
            P13,
            P33,
        ),
        _CIRCLE_OUT,
        _spigot_run(4, True, 19, False),
        "centrally above the spigot: for 0/90/180/270 deg out beside it, down by @P19, a touch toward its "
        "axis, back out and up",
    ),
    _spec(
        "SysMeasWcs11.ecy",
        "Outer diameter with 3 points",
        "303542923.html",
        (
            P2_SPIGOT,
            P19_TO_HEIGHT,
            P7,
            P9,
            P10,
            P13,
            *_ANGLES3,
            P33,
        ),
        _CIRCLE_OUT,
        _spigot_run(3, False, 19, False),
        "as SysMeasWcs10 with three points at @P14/@P15/@P16",
    ),
    _spec(
        "SysMeasWcs14.ecy",
        "Measure web in X axis",
        "303582859.html",
        (
            Param(3, "web width (along X)", required=True, check="positive"),
            P19_TO_HEIGHT,
            P7,
            P9,
            P13,
            P33,
        ),
        (
            Output("SysRetX", "centre of the web in X (+ @P9)"),
            Output("SysRetLengthX", "measured width of the web"),
        ),
        _block_run((0,)),
        "centrally above the web: for X+ and X- out beside it, down by @P19, a touch toward its middle, back "
        "out and up",
    ),
    _spec(
        "SysMeasWcs18.ecy",
        "Inner diameter with 4 points and obstacle",
        "303554827.html",
        (
            P2_HOLE,
            Param(19, "pre-positioning along Z into the hole (incremental)", required=True),
            P7,
            P9,
            P10,
            P13_OPTIONAL,
            P33,
        ),
        _CIRCLE_OUT,
        _hole_run(4, True, True),
        "above the hole: down by @P19, four touches outward, back up",
    ),
    _spec(
        "SysMeasWcs19.ecy",
        "Measure angle in X axis (C axis)",
        "303619723.html",
        (
            _path(4, "X"),
            Param(18, "offset along Y of the 2nd point (incremental)", required=True, check="nonzero"),
            P7,
            P12,
            P19_CLEARANCE,
            P22_BEFORE,
        ),
        (Output("SysRetC", "twist of the face about Z, less @P12 [deg]"),),
        _face_twist(0),
        "down (@P22/@P20), a touch along X, up (@P19), over by @P18 along Y, down, a touch along X, back to "
        "the start",
    ),
    _spec(
        "SysMeasWcs20.ecy",
        "Measure angle in Y axis (C axis)",
        "303625483.html",
        (
            _path(5, "Y"),
            Param(17, "offset along X of the 2nd point (incremental)", required=True, check="nonzero"),
            P7,
            P12,
            P19_CLEARANCE,
            P22_BEFORE,
        ),
        (Output("SysRetC", "twist of the face about Z, less @P12 [deg]"),),
        _face_twist(1),
        "down (@P22/@P20), a touch along Y, up (@P19), over by @P17 along X, down, a touch along Y, back to "
        "the start",
    ),
    _spec(
        "SysMeasWcs21.ecy",
        "Measure angle between 2 drilled holes (C axis)",
        "303630091.html",
        (
            Param(2, "diameter of the 1st hole", required=True, check="positive"),
            P22_DEPTH,
            P7,
            P12,
            P13,
            Param(17, "pre-positioning along X to the 2nd hole (incremental)", default=0.0),
            Param(18, "pre-positioning along Y to the 2nd hole (incremental)", default=0.0),
            Param(19, "pre-positioning along Z above the 2nd hole (incremental)", default=0.0),
            Param(29, "diameter of the 2nd hole", default_text="@P2", check="positive"),
            P33,
        ),
        (Output("SysRetC", "angle of the line between the centres to X+, less @P12 [deg]"),),
        _two_circles("hole", "hole"),
        "centrally above the 1st hole: down by @P22, four points, up; by @P17/@P18/@P19 to above the 2nd; "
        "the same",
    ),
    _spec(
        "SysMeasWcs22.ecy",
        "Measure angle between pins (C axis)",
        "303643147.html",
        (
            Param(2, "diameter of the 1st spigot", required=True, check="positive"),
            P22_DEPTH,
            P7,
            P12,
            P13,
            *_above("the 2nd spigot"),
            Param(29, "diameter of the 2nd spigot", default_text="@P2", check="positive"),
            P33,
        ),
        (Output("SysRetC", "angle of the line between the centres to X+, less @P12 [deg]"),),
        _two_circles("spigot", "spigot"),
        "centrally above the 1st spigot: four points at @P22 below; by @P17/@P18/@P19 to above the 2nd; the "
        "same",
    ),
    _spec(
        "SysMeasWcs23.ecy",
        "Measure angle between drilled hole and spigot (C axis)",
        "303651979.html",
        (
            P2_HOLE,
            P22_DEPTH,
            Param(29, "spigot diameter", required=True, check="positive"),
            P7,
            P12,
            P13,
            *_above("the spigot"),
            P33,
        ),
        (Output("SysRetC", "angle of the line hole -> spigot to X+, less @P12 [deg]"),),
        _two_circles("hole", "spigot"),
        "centrally above the hole: down by @P22, four points, up; by @P17/@P18/@P19 above the spigot; four "
        "points round it",
    ),
    _spec(
        "SysMeasWcs24.ecy",
        "Measure angle between point in Y and drilled hole (C axis)",
        "303663883.html",
        (
            P2_HOLE,
            _path(4, "X"),
            P22_DEPTH,
            P7,
            P12,
            P13,
            *_above("the hole"),
            P33,
        ),
        (Output("SysRetC", "angle of the line point -> hole centre to X+, less @P12 [deg]"),),
        _point_circle(1, "hole"),
        "down by @P22, a touch along X (@P4), up; by @P17/@P18/@P19 above the hole; down by @P22, four "
        "points",
    ),
    _spec(
        "SysMeasWcs26.ecy",
        "Measure angle between point in X and drilled hole (C axis)",
        "303660811.html",
        (
            P2_HOLE,
            _path(5, "Y"),
            P22_DEPTH,
            P7,
            P12,
            P13,
            *_above("the hole"),
            P33,
        ),
        (Output("SysRetC", "angle of the line point -> hole centre to X+, less @P12 [deg]"),),
        _point_circle(0, "hole"),
        "down by @P22, a touch along Y (@P5), up; by @P17/@P18/@P19 above the hole; down by @P22, four "
        "points",
    ),
    _spec(
        "SysMeasWcs25.ecy",
        "Measure angle between point in Y and spigot (C axis)",
        "303669643.html",
        (
            P2_SPIGOT,
            _path(4, "X"),
            P22_DEPTH,
            P7,
            P12,
            P13,
            *_above("the spigot"),
            P33,
        ),
        (Output("SysRetC", "angle of the line point -> spigot centre to X+, less @P12 [deg]"),),
        _point_circle(1, "spigot"),
        "down by @P22, a touch along X (@P4), up; by @P17/@P18/@P19 above the spigot; four points round it "
        "at depth @P22",
    ),
    _spec(
        "SysMeasWcs27.ecy",
        "Measure angle between point in X and spigot (C axis)",
        "303687307.html",
        (
            P2_SPIGOT,
            _path(5, "Y"),
            P22_DEPTH,
            P7,
            P12,
            P13,
            *_above("the spigot"),
            P33,
        ),
        (Output("SysRetC", "angle of the line point -> spigot centre to X+, less @P12 [deg]"),),
        _point_circle(0, "spigot"),
        "down by @P22, a touch along Y (@P5), up; by @P17/@P18/@P19 above the spigot; four points round it "
        "at depth @P22",
    ),
    _spec(
        "SysMeasWcs29.ecy",
        "Outer rectangle",
        "303727243.html",
        (
            Param(31, "length of the block along X", required=True, check="positive"),
            Param(32, "length of the block along Y", required=True, check="positive"),
            P19_TO_HEIGHT,
            P7,
            P9,
            P10,
            P13,
            P33,
        ),
        (
            Output("SysRetX", "centre X (+ @P9)"),
            Output("SysRetY", "centre Y (+ @P10)"),
            Output("SysRetLengthX", "measured length along X"),
            Output("SysRetLengthY", "measured length along Y"),
        ),
        _block_run((0, 1)),
        "centrally above the block: for X+, X-, Y+, Y- out beside it, down by @P19, a touch toward its "
        "middle, back out and up",
    ),
    _spec(
        "SysMeasWcs36.ecy",
        "Measure a hole (start and incremental angle)",
        "547900555.html",
        (
            Param(2, "estimated hole diameter", required=True, check="positive"),
            P7,
            P9,
            P10,
            Param(13, "safety clearance for pre-positioning", check="nonnegative"),
            *_START_STEP,
            P33,
        ),
        _CIRCLE_OUT,
        _hole_run(4, False, False),
        "inside the hole: four touches outward from @P14 in steps of @P15",
    ),
    _spec(
        "SysMeasWcs38.ecy",
        "Measure a spigot with 3 points (start and incremental angle)",
        "548093579.html",
        _SPIGOT_START_STEP,
        _CIRCLE_OUT,
        _spigot_run(3, False, 19, True),
        "centrally above the spigot: three points from @P14 in steps of @P15 (out, down, toward the axis, "
        "back)",
    ),
    _spec(
        "SysMeasWcs39.ecy",
        "Measure a spigot with 4 points (start and incremental angle)",
        "548093579.html",
        _SPIGOT_START_STEP,
        _CIRCLE_OUT,
        _spigot_run(4, False, 19, True),
        "centrally above the spigot: four points from @P14 in steps of @P15 (out, down, toward the axis, "
        "back)",
    ),
    _spec(
        "SysMeasWcs40.ecy",
        "Measure a sphere",
        "536041483.html",
        (
            Param(6, "measuring path toward -Z (positive)", required=True, check="positive"),
            P87_SPHERE,
            P7,
            P9,
            P10,
            P11,
            P13,
            Param(14, "probing angle of the 1st lateral touch from X+ [deg]", default=0.0),
            P15_BETWEEN,
            P33_SPHERE,
            Param(
                64, "approach 0 linear, 1 circular (circular: linear here)", default=0.0, choices=(0.0, 1.0)
            ),
            Param(
                88,
                "repeat at the equator 1 yes, 2 no (the stand-in's lateral touches are at the equator "
                "already)",
                default=2.0,
                choices=(1.0, 2.0),
            ),
        ),
        (
            Output("SysRetX", "centre X (+ @P9)"),
            Output("SysRetY", "centre Y (+ @P10)"),
            Output("SysRetZ", "centre Z (+ @P11)"),
            Output("SysRetDiameter", "measured diameter"),
        ),
        _sphere_run,
        "centrally above the sphere: a touch on its top, back up; four lateral touches at its equator; back "
        "to the start",
    ),
    _spec(
        "SysMeasCs1.ecy",
        "Manual teach-in",
        "312248075.html",
        (P39,),
        tuple(Output(f"SysRet{n}", "origin / angle of the coordinate system written") for n in "XYZABC"),
        _cs1_run,
        "no motion: an operator's dialogue on the kernel; the tip's position at the call is the taught "
        "origin (warning 917001); writes CS_BASE_<@P39>.bcs",
    ),
    _spec(
        "SysMeasCs2.ecy",
        "Semi-automatic teach-in",
        "312258443.html",
        (
            _path(4, "X"),
            _path(5, "Y"),
            P6_DOWN,
            P39,
            P9,
            P10,
            P11,
            Param(14, "basic setting of the A axis [deg]", default=0.0),
            Param(15, "basic setting of the B axis [deg]", default=0.0),
            Param(16, "basic setting of the C axis [deg]", default=0.0),
        ),
        tuple(Output(f"SysRet{n}", "origin / angle of the coordinate system written") for n in "XYZABC"),
        _cs2_run,
        "from the start: a touch down (@P6), along X (@P4), along Y (@P5), back to the start after each; "
        "writes CS_BASE_<@P39>.bcs",
    ),
    _spec(
        "SysMeasCs5.ecy",
        "Teach-in with 3 spheres",
        "550151051.html",
        (
            P6_DOWN,
            P39,
            Param(41, "X of the 2nd pre-position, relative to the start", required=True),
            Param(42, "X of the 3rd pre-position, relative to the start", required=True),
            Param(43, "Y of the 2nd pre-position, relative to the start", required=True),
            Param(44, "Y of the 3rd pre-position, relative to the start", required=True),
            P87_SPHERE,
            P9,
            P10,
            P11,
            P13,
            Param(14, "probing angle of the 1st lateral touch [deg]", default=0.0),
            P15_BETWEEN,
            P33_SPHERE,
        ),
        tuple(
            Output(f"SysRet{n}", "origin (1st sphere) / rotation (nominal -> measured triangle, ZYX)")
            for n in "XYZABC"
        ),
        _cs5_run,
        "each sphere as SysMeasWcs40 (top, four at the equator), moving at constant Z to the 2nd (@P41/@P43) "
        "and 3rd (@P42/@P44) pre-position; back to the start; writes CS_BASE_<@P39>.bcs",
    ),
    _spec(
        "SysCalibTouchprobe1.ecy",
        "Calibrate the touch probe in a ring",
        "535422603.html",
        (
            Param(2, "inner diameter of the ring", required=True, check="positive"),
            Param(14, "probing angle of the 1st touch from X+ [deg]", default=0.0),
            Param(15, "angle between the touches [deg]", default=90.0, check="nonzero"),
            Param(33, "crossover range", default_text="@P2/2"),
        ),
        (
            Output("SysRetToolRadius", "effective radius of the probe sphere"),
            Output("SysRetOffsetX", "shift of the probe head along X (0: the simulated probe has none)"),
            Output("SysRetOffsetY", "shift of the probe head along Y (0)"),
        ),
        _calib_ring,
        "centrally in the ring at the measuring height: four touches outward from @P14 in steps of @P15, "
        "back to the centre after each",
    ),
)
