"""TF5293 milling cycles (rectangular and circular pockets) as stand-ins.

Pages: https://infosys.beckhoff.com/content/1033/tf5293_tc3_cnc_cycles_millingbase/547222411.html
(SysMillRectangularPocket) and .../547174283.html (SysMillCircularPocket). The pocket's centre is where the
tool stands at the call (the pages' examples position there first). Per depth level (at most @P5 deep, the
last one at the pocket's depth less the base allowance @P15): a vertical plunge at the centre at the Z feed
@P21, then rings from the centre outward, each at most @P6 wider than the one before, the last at the
outline less the tool radius and the edge allowance @P16 (:func:`pocket_rings`: the tool stays inside the
pocket, a property test checks it). Finishing (@P31 = 2 or 3) mills the outline itself at the finishing feeds
at the full depth. Down milling (@P30 = 0, the default) goes round counter-clockwise, up milling clockwise.
The tool returns to the centre at the retraction plane @P2.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

from hli_server.engine.cycles.base import Cycle, StandIn, fmt
from hli_server.engine.cycles.drilling import feed_at_call
from hli_server.engine.cycles.errors import A_INVALID, CycleError
from hli_server.engine.cycles.params import Param
from hli_server.engine.cycles.probe import Vec3
from hli_server.engine.nc.blocks import Block

__all__ = ["MILLING", "depth_levels", "pocket_rings"]

_PAGE = "https://infosys.beckhoff.com/content/1033/tf5293_tc3_cnc_cycles_millingbase/"


def pocket_rings(final: float, step: float) -> list[float]:
    """The offsets of the rings a pocket is cleared with, from the centre out: each at most ``step`` beyond
    the one before, the last exactly ``final`` (0 < step; final >= 0)."""
    if final <= 1e-12:
        return [0.0]
    count = max(1, math.ceil(final / step - 1e-9))
    return [final * k / count for k in range(1, count + 1)]


def depth_levels(top: float, bottom: float, step: float) -> list[float]:
    """The Z of each level from ``top`` down to ``bottom`` (each at most ``step`` below the one before)."""
    total = top - bottom
    if total <= 1e-12:
        return [bottom]
    count = max(1, math.ceil(total / step - 1e-9))
    return [top - total * k / count for k in range(1, count + 1)]


_MODE = Param(
    31,
    "machining mode",
    default=1.0,
    words=(("Roughing", 1.0), ("Finishing", 2.0), ("Roughing+Finishing", 3.0)),
    choices=(1.0, 2.0, 3.0),
    alarm=13166,
)
_DIRECTION = Param(
    30,
    "machining direction",
    default=0.0,
    words=(("ClimbMilling", 0.0), ("UpCutMilling", 1.0)),
    choices=(0.0, 1.0),
)
_COMMON = (
    Param(1, "reference plane (absolute Z)", required=True),
    Param(2, "retraction plane (absolute Z)", required=True),
    Param(3, "safety clearance in Z above the reference plane", required=True, check="positive", alarm=13100),
    Param(4, "depth below the reference plane", required=True, check="positive"),
    Param(5, "maximum infeed in Z", required=True, check="positive", alarm=13103),
    Param(6, "maximum infeed in XY (at most 2 x the tool radius)", required=True, check="positive"),
    Param(15, "finishing allowance at the base", default=0.0, check="nonnegative"),
    Param(16, "finishing allowance at the edge", default=0.0, check="nonnegative"),
    Param(20, "roughing feed in XY [mm/min]", default_text="the feed at the call", check="positive"),
    Param(21, "roughing feed in Z [mm/min]", default_text="@P20", check="positive"),
    Param(22, "finishing feed in XY [mm/min]", default_text="@P20", check="positive"),
    Param(23, "finishing feed in Z [mm/min]", default_text="@P22", check="positive"),
    _DIRECTION,
    _MODE,
    Param(32, "infeed in Z 1 vertical, 2 helical (helical: vertical here)", default=1.0, choices=(1.0, 2.0)),
)


class _Pocket:
    def __init__(self, c: Cycle) -> None:
        a = c.args
        self.c = c
        self.top = a.num(1)
        self.retract = a.num(2)
        self.safe = a.num(1) + a.num(3)
        self.bottom = a.num(1) - a.num(4)
        if self.retract < self.safe:
            raise CycleError(
                A_INVALID,
                f"{c.spec.name}: the retraction plane @P2 = {fmt(self.retract)} lies below the reference "
                f"plane plus the safety clearance ({fmt(self.safe)})",
                2,
            )
        self.step_z = a.num(5)
        self.step_xy = a.num(6)
        radius = c.ball
        if radius > 0.0 and self.step_xy > 2.0 * radius + 1e-9:
            raise CycleError(
                A_INVALID,
                f"{c.spec.name}: maximum infeed in XY @P6 = {fmt(self.step_xy)} is more than the tool "
                f"diameter ({fmt(2.0 * radius)})",
                6,
            )
        self.feed_xy = a.num(20, feed_at_call(c) if not a.given(20) else 0.0)
        self.feed_z = a.num(21, self.feed_xy)
        self.finish_xy = a.num(22, self.feed_xy)
        self.finish_z = a.num(23, self.finish_xy)
        self.mode = int(a.num(31))
        self.ccw = a.num(30) == 0.0
        self.base = a.num(15)
        self.edge = a.num(16)
        self.centre: Vec3 = c.at

    def levels(self) -> list[float]:
        floor = self.bottom + (self.base if self.mode == 3 else 0.0)
        return depth_levels(self.top, floor, self.step_z)


def _rect_ring(
    c: Cycle, centre: Vec3, hx: float, hy: float, z: float, ccw: bool, feed: float
) -> Iterator[Block]:
    x, y, _ = centre
    if hx <= 1e-12 and hy <= 1e-12:
        return
    corners = [(x + hx, y - hy), (x + hx, y + hy), (x - hx, y + hy), (x - hx, y - hy)]
    if not ccw:
        corners = [(x + hx, y + hy), (x + hx, y - hy), (x - hx, y - hy), (x - hx, y + hy)]
    start = (x + hx, y)
    yield from c.feed_move((start[0], start[1], z), feed)
    for px, py in corners:
        yield from c.feed_move((px, py, z), feed)
    yield from c.feed_move((start[0], start[1], z), feed)


def _rect_pocket(c: Cycle) -> Iterator[Block]:
    a = c.args
    p = _Pocket(c)
    length, width = a.num(72), a.num(73)
    r = c.ball
    final_x = length / 2.0 - r - p.edge
    final_y = width / 2.0 - r - p.edge
    if final_x < -1e-9 or final_y < -1e-9:
        raise CycleError(
            A_INVALID,
            f"{c.spec.name}: the tool (radius {fmt(r)}) and the edge allowance do not fit the pocket "
            f"{fmt(length)} x {fmt(width)}",
            72,
        )
    final_x, final_y = max(0.0, final_x), max(0.0, final_y)
    x, y, _ = p.centre
    yield from c.rapid((x, y, p.retract))
    yield from c.rapid((x, y, p.safe))
    big = max(final_x, final_y)
    for z in p.levels() if p.mode != 2 else []:
        yield from c.feed_move((x, y, z), p.feed_z)
        for ring in pocket_rings(big, p.step_xy):
            f = ring / big if big > 0.0 else 0.0
            yield from _rect_ring(c, p.centre, final_x * f, final_y * f, z, p.ccw, p.feed_xy)
        yield from c.feed_move((x, y, z), p.feed_xy)
    if p.mode in (2, 3):
        hx, hy = length / 2.0 - r, width / 2.0 - r
        yield from c.feed_move((x, y, p.bottom), p.finish_z)
        yield from _rect_ring(c, p.centre, max(0.0, hx), max(0.0, hy), p.bottom, p.ccw, p.finish_xy)
        yield from c.feed_move((x, y, p.bottom), p.finish_xy)
    yield from c.rapid((x, y, p.safe))
    yield from c.rapid((x, y, p.retract))


def _circle_ring(c: Cycle, centre: Vec3, radius: float, z: float, ccw: bool, feed: float) -> Iterator[Block]:
    if radius <= 1e-12:
        return
    x, y, _ = centre
    yield from c.feed_move((x + radius, y, z), feed)
    yield from c.arc((x - radius, y, z), centre, not ccw, feed)
    yield from c.arc((x + radius, y, z), centre, not ccw, feed)


def _circ_pocket(c: Cycle) -> Iterator[Block]:
    a = c.args
    p = _Pocket(c)
    diameter = a.num(68)
    r = c.ball
    final = diameter / 2.0 - r - p.edge
    if final < -1e-9:
        raise CycleError(
            14327,
            f"{c.spec.name}: pocket diameter @P68 = {fmt(diameter)} is smaller than the tool "
            f"({fmt(2.0 * r)}) and the edge allowance",
            68,
        )
    final = max(0.0, final)
    x, y, _ = p.centre
    yield from c.rapid((x, y, p.retract))
    yield from c.rapid((x, y, p.safe))
    for z in p.levels() if p.mode != 2 else []:
        yield from c.feed_move((x, y, z), p.feed_z)
        for ring in pocket_rings(final, p.step_xy):
            yield from _circle_ring(c, p.centre, ring, z, p.ccw, p.feed_xy)
        yield from c.feed_move((x, y, z), p.feed_xy)
    if p.mode in (2, 3):
        yield from c.feed_move((x, y, p.bottom), p.finish_z)
        yield from _circle_ring(c, p.centre, max(0.0, diameter / 2.0 - r), p.bottom, p.ccw, p.finish_xy)
        yield from c.feed_move((x, y, p.bottom), p.finish_xy)
    yield from c.rapid((x, y, p.safe))
    yield from c.rapid((x, y, p.retract))


MILLING: tuple[StandIn, ...] = (
    StandIn(
        "SysMillRectangularPocket.ecy",
        "TF5293",
        "Mill a rectangular pocket",
        _PAGE + "547222411.html",
        (
            *_COMMON,
            Param(72, "length of the pocket in X", required=True, check="positive"),
            Param(73, "width of the pocket in Y", required=True, check="positive"),
        ),
        (),
        _rect_pocket,
        "centred on the position at the call: per level (<= @P5) a plunge at the centre and rings outward "
        "(<= @P6 apart) to the outline less the tool radius and @P16; finishing at the outline; back to @P2",
    ),
    StandIn(
        "SysMillCircularPocket.ecy",
        "TF5293",
        "Mill a circular pocket",
        _PAGE + "547174283.html",
        (*_COMMON, Param(68, "pocket diameter", required=True, check="positive", alarm=14327)),
        (),
        _circ_pocket,
        "centred on the position at the call: per level a plunge at the centre and full circles outward (<= "
        "@P6 apart); finishing at the outline; back to @P2",
    ),
)
