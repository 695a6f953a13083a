"""A stand-in's description (:class:`StandIn`) and one run of it (:class:`Cycle`).

A stand-in's ``run`` is a generator: it yields the :class:`~hli_server.engine.nc.blocks.Block` s the
interpreter hands the decoder, one at a time, as the decoder asks. Each is NC text read by the normal
block parser (``G01 G90 X10 Y20 F500``), so the decoder converts it, the path checks (software limits,
areas, collision monitoring) check it and the planner moves it like any programmed block. A measuring
move is a ``G100`` block that carries where the simulated workpiece is touched (``Block.probe_touch``);
after yielding it the generator reads what the probe latched (:meth:`Cycle.contact`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass

from hli_server.engine.cycles.context import CycleContext
from hli_server.engine.cycles.errors import (
    A_COLLISION,
    A_INVALID,
    A_NO_WORKPIECE,
    A_NOT_SIMULATED,
    CycleError,
)
from hli_server.engine.cycles.params import Args, Param, ParamValue, check_params
from hli_server.engine.cycles.probe import Box, Feature, Sphere, Spigot, Vec3, first_touch, inside, shifted
from hli_server.engine.nc.blocks import Block
from hli_server.engine.nc.parser import parse_line

__all__ = ["Cycle", "Output", "RunFn", "StandIn", "fmt", "require_distinct"]

_NO_CONTACT = math.inf
"""``Block.probe_touch`` of a measuring move that misses the simulated workpiece."""


@dataclass(frozen=True, slots=True)
class Output:
    """A ``V.CYC.`` variable the cycle writes, as its page lists it."""

    name: str
    meaning: str


RunFn = Callable[["Cycle"], Iterator[Block]]
"""A stand-in's generator: the blocks of one run."""


@dataclass(frozen=True, slots=True)
class StandIn:
    """A documented cycle the simulator runs without its file: name, package, the page it follows, its
    parameter table, its outputs and the generator that runs it. ``moves`` says in a sentence what it does
    (docs/cycles.md)."""

    name: str
    package: str
    title: str
    page: str
    params: tuple[Param, ...]
    outputs: tuple[Output, ...]
    run: RunFn
    moves: str = ""
    measuring: bool = False
    """A TF5225 cycle: it needs a touch probe (a D with a radius is not required: radius 0 is a point)."""


def fmt(value: float) -> str:
    """A number as NC text, to 1 nm (the parser reads no exponents)."""
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


class Cycle:
    """One run of a stand-in: the validated parameters, the channel's context, the blocks it makes."""

    def __init__(
        self,
        spec: StandIn,
        params: Mapping[int, ParamValue],
        ctx: CycleContext,
        line: int,
        call_text: str = "",
    ) -> None:
        self.spec = spec
        self.ctx = ctx
        self.line = line
        self.call_text = call_text
        self.args: Args = check_params(spec.name, spec.params, params)
        self.x_axis, self.y_axis, self.z_axis = ctx.main_axes
        self.at: Vec3 = (0.0, 0.0, 0.0)
        self.ball = 0.0
        self.measuring_feed = 0.0
        self.positioning_feed = 0.0
        self.obstacles: list[Feature] = []
        """The simulated workpiece's features known so far (nominal): positioning moves that would run
        into them (shifted by the deviation) are made measuring moves and stop with 13414."""
        self._last_probe: tuple[Vec3, Vec3] | None = None
        self.blocks_made = 0

    # --- running ---------------------------------------------------------------------------------
    def blocks(self) -> Iterator[Block]:
        """The stand-in's blocks, then the block that restores the caller's G90/G91, G00/G01 and F."""
        ctx = self.ctx
        if ctx.plane() != 17:
            raise CycleError(
                A_NOT_SIMULATED,
                f"{self.spec.name}: the stand-in works in the G17 plane; G{ctx.plane()} is active "
                "(select G17 before the call, or use your own cycle file)",
            )
        if ctx.inch():
            raise CycleError(
                A_NOT_SIMULATED,
                f"{self.spec.name}: the stand-in programs in mm; G70 (inch) is active at the call "
                "(select G71)",
            )
        state = ctx.motion_state()
        self.at = ctx.position()
        self.ball = ctx.tool_radius()
        self.measuring_feed, self.positioning_feed = ctx.probe_feeds()
        yield from self.spec.run(self)
        restore = [
            f"G{state.motion:02d}" if state.motion in (0, 1) else "G01",
            "G90" if state.absolute else "G91",
        ]
        if state.feed is not None and state.feed > 0.0:
            restore.append(f"F{fmt(state.feed)}")
        yield self._parse(" ".join(restore))

    def nested(self, spec: StandIn) -> Cycle:
        """A run of ``spec`` inside this one, with this call's @P (a pattern cycle's reference cycle): it
        checks them against its own table and goes on from where this run is."""
        sub = Cycle(spec, self.args.passed(), self.ctx, self.line, self.call_text)
        sub.at = self.at
        sub.ball = self.ball
        sub.measuring_feed, sub.positioning_feed = self.measuring_feed, self.positioning_feed
        return sub

    def _parse(self, text: str) -> Block:
        block = parse_line(text, self.line, self.ctx.axis_names)
        assert block is not None
        self.blocks_made += 1
        return dataclasses.replace(block, program=self.spec.name)

    def _words(self, target: Vec3) -> str:
        names = (self.x_axis, self.y_axis, self.z_axis)
        words = [
            (name if len(name) == 1 else f"{name}=") + fmt(value)
            for name, value, now in zip(names, target, self.at, strict=True)
            if abs(value - now) > 1e-9
        ]
        return " ".join(words)

    @staticmethod
    def _round(p: Vec3) -> Vec3:
        """A target as the block's text will hold it (to 1 nm): the probe's contact is computed on the
        line the block really programs."""
        return (round(p[0], 6), round(p[1], 6), round(p[2], 6))

    def rapid(self, target: Vec3) -> Iterator[Block]:
        """A positioning move at rapid traverse (G00); near the workpiece a measuring stand-in positions
        at its positioning feed instead, watching for a collision (:meth:`position`)."""
        if self.spec.measuring:
            yield from self.position(target)
            return
        words = self._words(target)
        if words:
            yield self._parse(f"G00 G90 {words}")
            self.at = target

    def feed_move(self, target: Vec3, feed: float) -> Iterator[Block]:
        """A cutting move (G01) at ``feed`` mm/min."""
        words = self._words(target)
        if words:
            yield self._parse(f"G01 G90 {words} F{fmt(feed)}")
            self.at = target

    def arc(self, target: Vec3, centre: Vec3, clockwise: bool, feed: float) -> Iterator[Block]:
        """A circle in the G17 plane about ``centre`` (I/J relative to the start, the kernel's default)."""
        i, j = centre[0] - self.at[0], centre[1] - self.at[1]
        words = self._words(target)
        yield self._parse(
            f"{'G02' if clockwise else 'G03'} G90 {words} I{fmt(i)} J{fmt(j)} F{fmt(feed)}".replace("  ", " ")
        )
        self.at = target

    def dwell(self, seconds: float) -> Iterator[Block]:
        if seconds > 0.0:  # the time by the first main axis (PM 206132747)
            yield self._parse(
                f"G04 {self.x_axis if len(self.x_axis) == 1 else self.x_axis + '='}{fmt(seconds)}"
            )

    def position(self, target: Vec3) -> Iterator[Block]:
        """A positioning move of a measuring cycle (positioning feed). Where it would run into the
        simulated workpiece it is a measuring move, and a probe signal on it is error 13414."""
        target = self._round(target)
        if self._words(target) == "":
            return
        touch = self._touch(self.at, target)
        if touch is None:
            yield self._parse(f"G01 G90 {self._words(target)} F{fmt(self.positioning_feed)}")
            self.at = target
            return
        start = self.at
        yield self._measure_block(target, touch, self.positioning_feed)
        measured = self.ctx.measured()
        self.at = self.ctx.position()
        if measured is not None:
            hit = _lerp(start, target, measured)
            raise CycleError(
                A_COLLISION,
                f"{self.spec.name}: collision on positioning, please check your motion range: the probe "
                f"touched the workpiece at X{fmt(hit[0])} Y{fmt(hit[1])} Z{fmt(hit[2])} on the way to "
                f"X{fmt(target[0])} Y{fmt(target[1])} Z{fmt(target[2])}",
            )

    def measure(self, target: Vec3, feature: Feature) -> Iterator[Block]:
        """A measuring move (G100, measuring feed) toward ``target``; ``feature`` is what the simulated
        probe touches. :meth:`contact` then tells where the probe signal came."""
        start = self.at
        target = self._round(target)
        touch = first_touch(shifted(feature, self.ctx.deviation()), start, target, self.ball)
        if isinstance(feature, Spigot | Box | Sphere) and feature not in self.obstacles:
            # bounded solids only: a face or a bore has no known top, the stand-in cannot tell whether a
            # move above it would hit it
            self.obstacles.append(feature)
        yield self._measure_block(target, touch if touch is not None else _NO_CONTACT, self.measuring_feed)
        self._last_probe = (start, target)
        self.at = self.ctx.position()

    def _measure_block(self, target: Vec3, touch: float, feed: float) -> Block:
        block = self._parse(f"G100 G90 {self._words(target)} F{fmt(feed)}")
        return dataclasses.replace(block, probe_touch=touch)

    def contact(self) -> Vec3:
        """The tip's position where the probe signal of the last measuring move came; no signal is
        error 13413 (the kernel's cycles stop there)."""
        assert self._last_probe is not None
        start, target = self._last_probe
        fraction = self.ctx.measured()
        if fraction is None:
            raise CycleError(
                A_NO_WORKPIECE,
                f"{self.spec.name}: no workpiece detected, please check your measuring section: the "
                f"measuring move from X{fmt(start[0])} Y{fmt(start[1])} Z{fmt(start[2])} to "
                f"X{fmt(target[0])} Y{fmt(target[1])} Z{fmt(target[2])} ended without a probe signal",
            )
        return _lerp(start, target, fraction)

    def centre_of(self, tip: Vec3) -> Vec3:
        """The probe sphere's centre for a tip position."""
        return (tip[0], tip[1], tip[2] + self.ball)

    def _touch(self, start: Vec3, target: Vec3) -> float | None:
        dev = self.ctx.deviation()
        best: float | None = None
        for feature in self.obstacles:
            moved = shifted(feature, dev)
            if inside(moved, start, self.ball):
                continue  # still deflected from the last touch: the move leaves the workpiece
            t = first_touch(moved, start, target, self.ball)
            if t is not None and (best is None or t < best):
                best = t
        return best

    # --- results -----------------------------------------------------------------------------------
    def result(self, name: str, value: float) -> None:
        self.ctx.set_result(name, value)

    def zero_offset_target(self) -> str | None:
        """@P7 checked (13408, 14421): the zero offset to write (``G54``..``G59``), None without @P7."""
        if not self.args.given(7):
            return None
        number = self.args.num(7)
        if number != int(number) or not (1 <= number <= 9 or 53 <= number <= 59):
            raise CycleError(
                13408,
                f"{self.spec.name}: zero offset is not defined or incorrectly defined @P7 = {fmt(number)}; "
                "values 1-9 and 53-59 are allowed",
                7,
            )
        n = int(number)
        if n == 53 or 7 <= n <= 9:
            raise CycleError(
                A_NOT_SIMULATED,
                f"{self.spec.name}: @P7 = {n}: only G54..G59 (1..6, 54..59) are simulated zero offsets",
                7,
            )
        name = f"G{n if n >= 54 else 53 + n}"
        active = self.ctx.zero_offset()
        if active is not None:
            raise CycleError(
                14421,
                f"{self.spec.name}: changing an active zero offset ({active}) is not permitted: writing "
                f"{name} "
                "(@P7) needs G53 active at the cycle call",
                7,
            )
        return name

    def write_zero_offset(self, name: str | None, values: Mapping[str, float]) -> None:
        if name is not None:
            self.ctx.write_zero_offset(name, values)


def _lerp(a: Vec3, b: Vec3, f: float) -> Vec3:
    return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))


def require_distinct(cycle: str, angles: Sequence[float], params: Sequence[int]) -> None:
    """The measuring angles must differ (SysMeasWcs9/11: "Die Winkel 1-3 müssen unterschiedlich sein")."""
    seen: list[float] = []
    for angle, number in zip(angles, params, strict=True):
        a = angle % 360.0
        if any(abs(a - b) < 1e-9 or abs(abs(a - b) - 360.0) < 1e-9 for b in seen):
            raise CycleError(
                A_INVALID,
                f"{cycle}: the measuring angles must differ; @P{number} = {fmt(angle)} repeats one",
                number,
            )
        seen.append(a)
