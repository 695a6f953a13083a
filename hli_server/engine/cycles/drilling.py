"""TF5293 drilling cycles and drilling patterns as stand-ins.

Pages: https://infosys.beckhoff.com/content/1033/tf5293_tc3_cnc_cycles_millingbase/<id>.html. The drilling
position is where the tool stands at the call (X/Y); the planes are Z values: @P1 the reference plane (the
workpiece surface), @P2 the retraction plane, @P3 the safety clearance above @P1, @P4 the final depth below
@P1. The moves follow the pages' pictures: rapid to the retraction plane and to @P1 + @P3, the infeed at the
feed active at the call (@P132 where the cycle has it), the dwell @P17, the retraction at rapid or at feed
(@P92). A pattern cycle (@P100 = the drilling cycle's name as a string) runs its reference cycle at each
position, with the call's own @P.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

from hli_server.engine.cycles.base import Cycle, StandIn, fmt
from hli_server.engine.cycles.errors import A_INVALID, A_NOT_SIMULATED, CycleError
from hli_server.engine.cycles.geometry import circle_points, line_points
from hli_server.engine.cycles.params import Param
from hli_server.engine.cycles.probe import Vec3
from hli_server.engine.nc.blocks import Block

__all__ = ["DRILLING", "PATTERNS", "drill_depth", "feed_at_call"]

_PAGE = "https://infosys.beckhoff.com/content/1033/tf5293_tc3_cnc_cycles_millingbase/"

P1 = Param(1, "reference plane (absolute Z)", required=True)
P2 = Param(2, "retraction plane (absolute Z)", required=True)
P3 = Param(
    3, "safety clearance above the reference plane (unsigned)", required=True, check="positive", alarm=13100
)
P4 = Param(4, "final drilling depth below the reference plane (unsigned)", required=True, check="positive")
P17 = Param(17, "dwell time at the final depth [s]", default=0.0, check="nonnegative")
P87 = Param(
    87,
    "point angle of the drill [deg]; the tip's length is added to the depth (needs the tool radius)",
    check="positive",
    high=180.0,
    low=0.0,
)


def feed_at_call(c: Cycle) -> float:
    """The feed active at the call (the cycles machine with it where they have no feed parameter)."""
    feed = c.ctx.motion_state().feed
    if feed is None or feed <= 0.0:
        raise CycleError(
            A_INVALID,
            f"{c.spec.name}: no feed is active at the call: program F before the cycle (the infeed uses it)",
        )
    return feed


def drill_depth(c: Cycle) -> float:
    """@P4, plus the drill point's length when @P87 gives its angle (the tool radius must not be 0)."""
    a = c.args
    depth = a.num(4)
    if a.given(87):
        if c.ball <= 0.0:
            raise CycleError(
                A_INVALID,
                f"{c.spec.name}: @P87 (point angle) needs the drill's radius from the tool data; the active "
                "D has radius 0",
                87,
            )
        depth += c.ball / math.tan(math.radians(a.num(87)) / 2.0)
    return depth


def _approach(c: Cycle) -> Iterator[Block]:
    """To the retraction plane, then to the safety clearance above the reference plane (rapid)."""
    a = c.args
    x, y, _ = c.at
    yield from c.rapid((x, y, a.num(2)))
    yield from c.rapid((x, y, a.num(1) + a.num(3)))


def _drill(c: Cycle, depth: float, feed: float) -> Iterator[Block]:
    """Approach, feed to ``depth`` below the reference plane, dwell @P17 there."""
    yield from _approach(c)
    x, y, _ = c.at
    yield from c.feed_move((x, y, c.args.num(1) - depth), feed)
    yield from c.dwell(c.args.num(17))


def _retract(c: Cycle, at_feed: bool, feed: float) -> Iterator[Block]:
    x, y, _ = c.at
    top = (x, y, c.args.num(2))
    if at_feed:
        yield from c.feed_move((x, y, c.args.num(1) + c.args.num(3)), feed)
        yield from c.rapid(top)
    else:
        yield from c.rapid(top)


def _check_planes(c: Cycle) -> None:
    a = c.args
    if a.num(2) < a.num(1) + a.num(3):
        raise CycleError(
            A_INVALID,
            f"{c.spec.name}: the retraction plane @P2 = {fmt(a.num(2))} lies below the reference plane plus "
            f"the safety clearance ({fmt(a.num(1) + a.num(3))})",
            2,
        )


def _center_hole(c: Cycle) -> Iterator[Block]:
    a = c.args
    _check_planes(c)
    if a.num(182) == 1.0:
        raise CycleError(
            A_NOT_SIMULATED, f"{c.spec.name}: @P182 breakthrough detection is not simulated", 182
        )
    feed = feed_at_call(c)
    if a.given(68):
        angle = a.num(87, 90.0)
        depth = a.num(68) / 2.0 / math.tan(math.radians(angle) / 2.0)
    else:
        depth = drill_depth(c)
    yield from _drill(c, depth, feed)
    yield from _retract(c, False, feed)


def _reaming(c: Cycle) -> Iterator[Block]:
    a = c.args
    _check_planes(c)
    feed = feed_at_call(c)
    yield from _drill(c, a.num(4), feed)
    yield from _retract(c, a.num(92) == 1.0, feed)


def _boring(c: Cycle) -> Iterator[Block]:
    a = c.args
    _check_planes(c)
    feed = feed_at_call(c)
    yield from _drill(c, a.num(4), feed)
    x, y, bottom_z = c.at
    mode = a.num(92)
    if mode == 2.0:
        angle = math.radians(a.num(62))
        r = a.num(93)
        aside: Vec3 = (x + r * math.cos(angle), y + r * math.sin(angle), bottom_z + a.num(94))
        yield from c.rapid(aside)
        yield from c.rapid((aside[0], aside[1], a.num(2)))
        yield from c.rapid((x, y, a.num(2)))
    else:
        yield from _retract(c, mode == 1.0, feed)


def _deep_hole(c: Cycle) -> Iterator[Block]:
    a = c.args
    _check_planes(c)
    depth = drill_depth(c)
    if a.given(11):
        count = a.num(11)
        if count != int(count) or count < 1.0:
            raise CycleError(
                13103,
                f"{c.spec.name}: number of infeeds @P11 = {fmt(count)} is not defined: a whole number >= 1",
                11,
            )
        step = depth / count
        first = step
    elif a.given(10):
        step = a.num(10)
        first = step
    else:
        raise CycleError(
            13103,
            f"{c.spec.name}: number of infeeds not defined: pass @P11 (number of infeeds) or @P10 (infeed "
            f"depth)",
            11,
        )
    feed = a.num(132, feed_at_call(c))
    first_feed = a.num(172, feed)
    chip_breaking = a.num(31) == 1.0
    back = a.num(61)
    top = a.num(1)
    yield from _approach(c)
    x, y, _ = c.at
    reached = top
    target = top - min(first, depth)
    n = 0
    while True:
        n += 1
        yield from c.feed_move((x, y, target), first_feed if n == 1 else feed)
        reached = target
        if reached <= top - depth + 1e-9:
            break
        if chip_breaking:
            yield from c.rapid((x, y, reached + back))
        else:
            yield from c.rapid((x, y, top + a.num(3)))
            yield from c.rapid((x, y, reached + back))
        target = max(top - depth, reached - step)
        if n > 10_000:
            raise CycleError(A_INVALID, f"{c.spec.name}: more than 10000 infeeds: @P10/@P11 too small", 10)
    yield from c.dwell(a.num(17))
    yield from _retract(c, a.num(92) == 1.0, feed)


_BASE = (P1, P2, P3, P4)

DRILLING: tuple[StandIn, ...] = (
    StandIn(
        "SysDrillCenterHole.ecy",
        "TF5293",
        "Centring and simple drilling",
        _PAGE + "519264779.html",
        (
            *_BASE,
            P17,
            Param(68, "centring diameter (then @P4 is not used)", check="positive"),
            Param(
                87, "point angle of the drill [deg]", default_text="90", check="positive", high=180.0, low=0.0
            ),
            Param(182, "breakthrough detection 0 off, 1 on (not simulated)", default=0.0, choices=(0.0, 1.0)),
        ),
        (),
        _center_hole,
        "rapid to @P2 and to @P1+@P3, feed to the depth, dwell @P17, rapid back to @P2",
    ),
    StandIn(
        "SysDrillDeepHole.ecy",
        "TF5293",
        "Deep hole drilling",
        _PAGE + "519370635.html",
        (
            *_BASE,
            Param(31, "machining mode 1 chip breaking, 2 chip evacuation", required=True, choices=(1.0, 2.0)),
            Param(
                61,
                "return clearance (chip breaking) / holding distance (evacuation)",
                required=True,
                check="nonnegative",
                alarm=13105,
            ),
            Param(10, "infeed depth (when @P11 is not given)", check="positive"),
            Param(11, "number of infeeds (13103 when neither @P10 nor @P11)", check="positive"),
            P17,
            P87,
            Param(92, "retraction 0 rapid, 1 at feed", default=0.0, choices=(0.0, 1.0)),
            Param(132, "infeed feed [mm/min]", default_text="the feed at the call", check="positive"),
            Param(172, "feed of the first infeed [mm/min]", default_text="@P132", check="positive"),
        ),
        (),
        _deep_hole,
        "infeeds of @P4/@P11 (or @P10): after each back by @P61 (chip breaking) or out to @P1+@P3 and back "
        "to @P61 above the last depth (evacuation); dwell, retract",
    ),
    StandIn(
        "SysDrillReaming.ecy",
        "TF5293",
        "Reaming",
        _PAGE + "519532299.html",
        (*_BASE, P17, Param(92, "retraction 0 rapid, 1 at feed", default=1.0, choices=(0.0, 1.0))),
        (),
        _reaming,
        "rapid to @P2 and @P1+@P3, feed to the depth, dwell, back at feed (@P92 = 1) or rapid",
    ),
    StandIn(
        "SysDrillBoring.ecy",
        "TF5293",
        "Boring (finish drilling)",
        _PAGE + "519213579.html",
        (
            *_BASE,
            P17,
            Param(
                62, "0 position of the spindle [deg] (direction of the radial return clearance)", default=0.0
            ),
            Param(
                92,
                "retraction 0 rapid, 1 at feed, 2 oriented + return clearance, 3 spindle stopped",
                default=0.0,
                choices=(0.0, 1.0, 2.0, 3.0),
            ),
            Param(93, "radial return clearance (@P92 = 2)", default=0.0, check="nonnegative"),
            Param(94, "axial return clearance", default=0.0, check="nonnegative"),
        ),
        (),
        _boring,
        "rapid to @P2 and @P1+@P3, feed to the depth, dwell; retract rapid, at feed, or (@P92 = 2) first "
        "@P93 sideways toward @P62 and @P94 up",
    ),
)

_BY_NAME = {s.name.casefold().removesuffix(".ecy"): s for s in DRILLING}


def _reference(c: Cycle) -> StandIn:
    name = c.args.text(100)
    if name is None:
        raise CycleError(
            14346,
            f"{c.spec.name}: reference cycle is not defined or incorrect: @P100 must name the drilling cycle "
            f"as a string",
            100,
        )
    spec = _BY_NAME.get(name.strip().casefold().removesuffix(".ecy"))
    if spec is None:
        known = ", ".join(s.name.removesuffix(".ecy") for s in DRILLING)
        raise CycleError(
            14346,
            f'{c.spec.name}: reference cycle is not defined or incorrect: @P100 = "{name}"; '
            f"the stand-in patterns run {known}",
            100,
        )
    return spec


def _run_pattern(c: Cycle, points: list[tuple[float, float]]) -> Iterator[Block]:
    ref = _reference(c)
    probe = c.nested(ref)  # checks the reference cycle's @P before the first move
    retract = probe.args.num(2)
    for x, y in points:
        x0, y0, _ = c.at
        yield from c.rapid((x0, y0, retract))
        yield from c.rapid((x, y, retract))
        sub = c.nested(ref)
        yield from ref.run(sub)
        c.at = sub.at


def _count(c: Cycle, number: int) -> int:
    n = c.args.num(number)
    if n != int(n) or n < 1.0:
        raise CycleError(
            A_INVALID,
            f"{c.spec.name}: number of positions @P{number} = {fmt(n)}: a whole number >= 1",
            number,
        )
    return int(n)


def _pattern_line(c: Cycle) -> Iterator[Block]:
    a = c.args
    first = (a.num(101, c.at[0]), a.num(102, c.at[1]))
    yield from _run_pattern(c, line_points(first, a.num(104), _count(c, 107), a.num(109)))


def _pattern_circle(c: Cycle) -> Iterator[Block]:
    a = c.args
    n = _count(c, 107)
    centre = (a.num(101, c.at[0]), a.num(102, c.at[1]))
    yield from _run_pattern(c, circle_points(centre, a.num(111), n, a.num(112), a.num(113, 360.0 / n)))


_REF = Param(
    100,
    'the drilling cycle to run at each position, a string ("SysDrillDeepHole")',
    required=True,
    text=True,
    alarm=14346,
)

PATTERNS: tuple[StandIn, ...] = (
    StandIn(
        "SysDrillPatternLine.ecy",
        "TF5293",
        "Drilling a row of holes",
        _PAGE + "894374027.html",
        (
            _REF,
            Param(104, "distance between the positions along X (incremental)", required=True),
            Param(107, "number of positions", required=True, check="positive"),
            Param(101, "X of the first position (absolute)", default_text="the position at the call"),
            Param(102, "Y of the first position (absolute)", default_text="the position at the call"),
            Param(109, "rotation of the row from X+ [deg]", default=0.0),
        ),
        (),
        _pattern_line,
        "for each position: rapid to the reference cycle's @P2, to the position, the reference cycle",
    ),
    StandIn(
        "SysDrillPatternCircle.ecy",
        "TF5293",
        "Drilling a hole circle",
        _PAGE + "894384779.html",
        (
            _REF,
            Param(107, "number of positions", required=True, check="positive"),
            Param(111, "circle radius", required=True, check="positive"),
            Param(101, "X of the centre (absolute)", default_text="the position at the call"),
            Param(102, "Y of the centre (absolute)", default_text="the position at the call"),
            Param(112, "angle of the first position from X+ [deg]", default=0.0),
            Param(113, "incremental angle [deg]", default_text="360 / @P107"),
        ),
        (),
        _pattern_circle,
        "for each position on the circle: rapid to the reference cycle's @P2, to the position, the reference "
        "cycle",
    ),
)
