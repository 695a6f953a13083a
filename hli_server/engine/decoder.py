"""The decoder: modal NC state, machine coordinates, and the items for the planner (E-04, E-05).

It pulls parsed blocks lazily, keeps the modal state (G0/G1/G2/G3, G90/G91, G17/G18/G19,
G161/G162, G54..G59, G92, F), turns motion blocks into segments in machine coordinates (MCS = program
coordinates + zero offset + G92 shift) and runs every path check before a block is queued: a block
that fails a check is never queued; an error marker takes its place, so the path stops at the
block's start point and the alarm is raised there (C14-15, E-06).

Blocks between ``#CONTROL AREA BEGIN`` and ``END`` describe a contour: they go to the area handler
and do not move the axes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

from hli_server.engine.geometry import LineSegment, Point, Segment, arc_from_centre
from hli_server.engine.nc.blocks import AreaBegin, AreaCommand, AreaEnd, Block, NcError
from hli_server.engine.nc.interpreter import (
    PAUSE,
    Directive,
    FlushStop,
    FlushWait,
    MeasMode,
    Slope,
    SyncAction,
)
from hli_server.engine.planner import Dwell, Marker, MarkerKind, Motion

__all__ = [
    "AreaHandler",
    "BlockFeed",
    "DecodeError",
    "Decoder",
    "MeasureHandler",
    "MeasuringMove",
    "ModalState",
    "PathCheck",
]

ARC_RADIUS_TOLERANCE = 0.01
"""mm: allowed difference of start and end radius of a programmed circle (project's own)."""


@dataclass(frozen=True, slots=True)
class DecodeError:
    """What an error marker carries: the alarm number, its text and its parameters."""

    alarm: int
    message: str
    params: dict[str, Any] = field(default_factory=dict)
    axis: str | None = None


class BlockFeed(Protocol):
    """Where the decoder's blocks come from: the interpreter (:class:`~hli_server.engine.nc.interpreter.
    Interpreter`), or blocks already parsed. ``next`` gives a block, a directive, or None at the end of
    the program's text; it raises :class:`NcError` for a block that cannot run."""

    def next(self) -> Block | Directive | None: ...


class _Blocks:
    """A feed of blocks already parsed (an iterator, as the parser's ``iter_blocks`` gives)."""

    def __init__(self, blocks: Iterator[Block]) -> None:
        self._blocks = blocks

    def next(self) -> Block | Directive | None:
        return next(self._blocks, None)


def _nothing() -> None:
    """The action of a ``#FLUSH`` marker: the path stops there, nothing else happens."""


class PathCheck(Protocol):
    """A check of a whole block path before it is queued (soft limits, areas)."""

    def __call__(self, segment: Segment, block: Block) -> DecodeError | None: ...


class AreaHandler(Protocol):
    """Receives the ``#CONTROL AREA`` commands and the contour blocks between BEGIN and END (FCT-C14).

    ``command`` returns an error, or None; it may return a callable that the channel runs in
    program order (at execution time) for effects a PLC must see then."""

    def command(
        self, cmd: AreaCommand, block: Block, position: Point, modal: ModalState
    ) -> DecodeError | Callable[[], None] | None: ...

    def contour(self, segment: Segment, block: Block, modal: ModalState) -> DecodeError | None: ...


@dataclass(frozen=True, slots=True)
class MeasuringMove:
    """What a :class:`MeasureHandler` makes of a G100 block: the (possibly shortened) line to move,
    a tag the monitor recognises the queued motion by, and the action run when the move is over.
    The decoder decodes nothing after the block until ``done`` calls :meth:`Decoder.resume`."""

    segment: LineSegment
    done: Callable[[], None]
    tag: Any = None
    feed: float | None = None
    """mm/min: the measuring feed when it is not the programmed F (measuring type 2: P-AXIS-00215)."""


class MeasureHandler(Protocol):
    """Receives G100 measuring moves (C14-23, P-CHAN-00268)."""

    def measuring_move(
        self, segment: LineSegment, block: Block, modal: ModalState
    ) -> DecodeError | MeasuringMove: ...


@dataclass(slots=True)
class ModalState:
    motion: int = 1
    absolute: bool = True
    plane: int = 17
    centre_absolute: bool = False
    feed: float | None = None
    """mm/min"""
    zero_offset: str | None = None
    zero_offsets: dict[str, dict[str, float]] = field(default_factory=dict)
    """G54..G59 -> axis -> mm"""
    g92: dict[str, float] = field(default_factory=dict)
    in_area_definition: bool = False
    accel_weight_feed: float = 1.0
    """G131 (acceleration weighting of G01/G02/G03, a fraction; the manual's percent / 100)."""
    accel_weight_rapid: float = 1.0
    """G231 (acceleration weighting of G00)."""
    axis_accel_weight_feed: dict[str, float] = field(default_factory=dict)
    """G130 <axis><percent>: per axis, for G01/G02/G03."""
    axis_accel_weight_rapid: dict[str, float] = field(default_factory=dict)
    """G230 <axis><percent>: per axis, for G00."""
    inch: bool = False
    """G70 (inch) / G71 (metric, the initial state): path and coordinate values in inch (M-06)."""
    feed_per_rev: bool = False
    """G95 (feed per revolution) / G94 (feed per minute, the initial state) (M-07)."""
    feed_rev: float | None = None
    """mm/rev: the F word programmed under G95 (kept apart from G94's, as the kernel does)."""
    spindle_speed: float = 0.0
    """rpm: the last S word (the command spindle speed G95 multiplies with)."""
    spindle_on: bool = False
    """M3/M4 turn the main spindle on, M5 off (G95 needs it turning: the kernel's ID 60131)."""
    meas_type: int | None = None
    """The measuring type of G100 selected in the program (the kernel's ``#MEAS MODE [n]``); None: the
    channel's default P-CHAN-00057. ``#MEAS MODE`` sets it (the interpreter's ``MeasMode``)."""

    def offset(self, axis: str) -> float:
        base = self.zero_offsets.get(self.zero_offset, {}).get(axis, 0.0) if self.zero_offset else 0.0
        return base + self.g92.get(axis, 0.0)


_PLANE_AXES = {17: (0, 1), 18: (2, 0), 19: (1, 2)}
"""Indices into the main axes (first, second, third) of the plane's first and second axis."""
_CENTRE_WORDS = {0: "I", 1: "J", 2: "K"}
"""Circle centre word for the first, second, third main axis."""


class Decoder:
    """Turns blocks into planner items. ``axes`` is the channel's axis order (names)."""

    def __init__(
        self,
        axes: list[str],
        main_axes: tuple[str, str, str],
        axis_limits: dict[str, tuple[float, float, float]],
        zero_offsets: dict[str, dict[str, float]],
    ) -> None:
        self.axes = axes
        self.index = {a: i for i, a in enumerate(axes)}
        self.main = main_axes
        self.axis_limits = axis_limits
        """axis -> (v_max mm/s, v_rapid mm/s, a_max mm/s²)"""
        self.modal = ModalState(zero_offsets=zero_offsets)
        self.position: list[float] = [0.0] * len(axes)
        self.blocks: BlockFeed | None = None
        self.finished = False
        self.waiting = False
        """Decoding waits for the path (``#FLUSH WAIT``) until the marker's action is run."""
        self.path_checks: list[PathCheck] = []
        self.area_handler: AreaHandler | None = None
        self.measure_handler: MeasureHandler | None = None
        self.current_block: Block | None = None
        self._position_before_area: list[float] | None = None
        self.blocks_decoded = 0
        self.rotary_axes: frozenset[str] = frozenset()
        """Axes in degrees: G70 does not scale them."""
        self.slope_handler: Callable[[int | None], None] | None = None
        """Switches the acceleration profile (``#SLOPE``: 0..3 as P-CHAN-00071, None: the default)."""
        self.last_centre: dict[str, float] = {}
        """I, J, K of the last circle programmed (V.G.I, V.G.J, V.G.K)."""

    # --- program control -----------------------------------------------------------------
    def start(self, blocks: BlockFeed | Iterator[Block], position: list[float]) -> None:
        """Decode from ``blocks`` (the interpreter, or parsed blocks) starting at ``position``."""
        self.blocks = _Blocks(blocks) if isinstance(blocks, Iterator) else blocks
        self.position = list(position)
        self.finished = False
        self.waiting = False
        self.blocks_decoded = 0
        self.modal.in_area_definition = False

    def resume(self, position: list[float]) -> None:
        """Continue decoding from ``position`` (after a measuring move stopped where the probe fired)."""
        self.position = list(position)
        self.finished = False

    def reset_modal(self) -> None:
        """Reset: modal state back to its defaults, G92 cleared (zero offset table kept)."""
        self.modal = ModalState(zero_offsets=self.modal.zero_offsets)
        self.blocks = None
        self.finished = True
        self.waiting = False

    def next_items(self) -> list[Motion | Marker]:
        """Decode until at least one item is produced, the program ends, or the feed pauses (its
        budget for this cycle is spent, or it waits for the path): then the list is empty."""
        if self.finished or self.waiting or self.blocks is None:
            return []
        feed = self.blocks
        while True:
            try:
                out = feed.next()
            except NcError as exc:
                return self.syntax_error(exc)
            if out is None:
                return self.end_of_program()
            if isinstance(out, Block):
                items = self.decode_block(out)
                if items:
                    return items
                continue
            return self.directive(out)

    def directive(self, out: Directive) -> list[Motion | Marker]:
        """The planner's item for an interpreter's directive (see :mod:`hli_server.engine.nc.interpreter`)."""
        if out is PAUSE:
            return []
        block = out.block
        if block is not None:
            self.current_block = block
        if isinstance(out, SyncAction):
            return [Marker(MarkerKind.SYNC, block, payload=out.action)]
        if isinstance(out, FlushWait):
            self.waiting = True
            return [Marker(MarkerKind.ACTION, block, payload=self._end_wait)]
        if isinstance(out, FlushStop):
            return [Marker(MarkerKind.ACTION, block, payload=_nothing)]
        if isinstance(out, Slope):
            # #SLOPE (M-02): the path comes to rest here and the axes with it, then the profile
            # changes (the filter of the new profile starts at rest; docs/nc-language.md)
            handler = self.slope_handler
            if handler is None:
                return []
            profile = out.profile
            return [Marker(MarkerKind.ACTION, block, payload=lambda: handler(profile))]
        if isinstance(out, MeasMode):
            self.modal.meas_type = out.meas_type  # modal, decoded in order (the G100 blocks after it)
            return []
        return []  # pragma: no cover - every directive is handled above

    def _end_wait(self) -> None:
        """The path reached a ``#FLUSH WAIT``: decoding goes on."""
        self.waiting = False

    # --- the steps of next_items, also driven one by one by the batch geometry check -------------
    def decode_block(self, block: Block) -> list[Motion | Marker]:
        """Decode one parsed block (the per-block step of :meth:`next_items`); an error or the program's
        end (M30/M02) finishes decoding."""
        self.current_block = block
        self.blocks_decoded += 1
        items = self._decode(block)
        if items and any(
            isinstance(i, Marker) and i.kind in (MarkerKind.ERROR, MarkerKind.END) for i in items
        ):
            self.finished = True
        return items

    def end_of_program(self) -> list[Motion | Marker]:
        """The text ended (without M30/M02 when decoding gets here): the end marker of the last block."""
        self.finished = True
        return [Marker(MarkerKind.END, self.current_block, payload="eof")]

    def syntax_error(self, exc: NcError) -> list[Motion | Marker]:
        """A line the parser could not read: the error marker with the place the parser named."""
        self.finished = True
        params: dict[str, Any] = {"line": exc.line, "block": exc.block, **exc.params}
        if exc.program:
            params["program"] = exc.program
        return [Marker(MarkerKind.ERROR, None, payload=DecodeError(exc.alarm, exc.message, params))]

    # --- one block -------------------------------------------------------------------------
    def _error(self, block: Block, alarm: int, message: str, **params: Any) -> list[Motion | Marker]:
        return [Marker(MarkerKind.ERROR, block, payload=DecodeError(alarm, message, params))]

    def _decode(self, block: Block) -> list[Motion | Marker]:
        m = self.modal
        if block.two_path:
            return self._error(block, 910110, "two-path programming (': G0 ... : G0 ...') is not supported")
        if 70 in block.g_codes:
            m.inch = True  # the new unit applies to this block already (M-06)
        elif 71 in block.g_codes:
            m.inch = False
        if 4 in block.g_codes:
            return self._dwell(block)  # before G70's scaling: the time is in seconds
        if m.inch:
            block = _block_in_mm(block, self.rotary_axes)
        if 95 in block.g_codes:
            m.feed_per_rev = True
        elif 94 in block.g_codes:
            m.feed_per_rev = False
        speed = block.extra.get("S")
        if speed is not None:
            m.spindle_speed = abs(speed)
        for code in block.m_codes:
            if code in (3, 4):
                m.spindle_on = True
            elif code == 5:
                m.spindle_on = False
        items: list[Motion | Marker] = []
        if block.area is not None:
            return self._area(block, block.area)
        measuring = False
        for g in block.g_codes:
            if g in (0, 1, 2, 3):
                m.motion = g
            elif g == 90:
                m.absolute = True
            elif g == 91:
                m.absolute = False
            elif g in (17, 18, 19):
                m.plane = g
            elif g == 161:
                m.centre_absolute = True
            elif g == 162:
                m.centre_absolute = False
            elif 54 <= g <= 59:
                m.zero_offset = f"G{g}"
            elif g == 53:
                m.zero_offset = None
            elif g == 100 and self.measure_handler is not None:
                measuring = True
            elif g in (130, 131, 230, 231, 132, 133, 134, 233, 333, 334, 338, 339):
                self._weighting(g, block)
            elif g in (100, 200, 201, 202):
                return self._error(block, 910110, f"G{g} is not supported in this block context")
        if block.feed is not None:
            if block.feed <= 0:
                return self._error(block, 911000, f"feed F{block.feed:g} must be positive")
            if m.feed_per_rev:
                m.feed_rev = block.feed
            else:
                m.feed = block.feed
        if 92 in block.g_codes:
            # G92: the current position gets the programmed program coordinates
            for name, value in block.axes:
                i = self.index[name]
                base = m.zero_offsets.get(m.zero_offset, {}).get(name, 0.0) if m.zero_offset else 0.0
                m.g92[name] = self.position[i] - base - value
            return items
        if measuring:
            return self._measuring_move(block)
        moves = bool(block.axes) or (m.motion in (2, 3) and bool(block.centre))
        if moves:
            result = self._motion(block)
            if isinstance(result, list):
                return result
            items.append(result)
        for code in block.m_codes:
            if code in (2, 30):
                items.append(Marker(MarkerKind.END, block, payload=f"M{code:02d}"))
        return items

    def _dwell(self, block: Block) -> list[Motion | Marker]:
        """``G04 <first main axis><s>`` (M-09, PM 206132747): the path rests for the time, then goes on
        (the axes at rest first). The time by the first main axis only; another axis in the block is the
        kernel's 20685 (refused here, where the kernel warns and goes on); the bare-number form
        ``G04 2.5``, ``G04 P1`` and the spindle form ``G04 S10`` are not simulated (910110)."""
        first = self.main[0]
        others = [name for name, _ in block.axes if name != first]
        if others:
            return self._error(
                block,
                20685,
                f"G04 with the axes {', '.join(others)}: the dwell time takes the first main axis only",
            )
        seconds = dict(block.axes).get(first)
        if seconds is None:
            return self._error(
                block,
                910110,
                f"G04 without {first}<seconds>: only G04 {first}<s> is simulated "
                "(not G04 <s>, G04 P.., G04 S..)",
            )
        if seconds < 0.0:
            return self._error(block, 911000, f"G04 {first}{seconds:g}: a dwell time is not negative")
        return [Marker(MarkerKind.ACTION, block, payload=Dwell(seconds))]

    def _weighting(self, g: int, block: Block) -> None:
        """G130/G131/G230/G231: acceleration weighting in percent of the axes' acceleration (manual
        "Acceleration weighting", 206590731; above 100 % is taken as 100 %: the simulator knows one
        acceleration per axis). G132..G339 (ramp times, feedhold): accepted, no effect (the simulator's
        profile has no jerk): docs/nc-language.md."""
        m = self.modal
        if g in {131, 231}:
            weight = min(max(block.extra.get(f"G{g}", 100.0), 0.0), 100.0) / 100.0
            if g == 131:
                m.accel_weight_feed = weight
            else:
                m.accel_weight_rapid = weight
        elif g in {130, 230}:
            weights = m.axis_accel_weight_feed if g == 130 else m.axis_accel_weight_rapid
            weights.clear()  # "all axes not programmed are set to 100 %"
            for key, value in block.extra.items():
                if key.startswith("W:"):
                    weights[key[2:]] = min(max(value, 0.0), 100.0) / 100.0

    def _target(self, block: Block) -> list[float]:
        m = self.modal
        target = list(self.position)
        for name, value in block.axes:
            i = self.index[name]
            if m.absolute:
                target[i] = value + m.offset(name)
            else:
                target[i] += value
        return target

    def _motion(self, block: Block) -> Motion | list[Motion | Marker]:
        m = self.modal
        start = tuple(self.position)
        target = self._target(block)
        segment: Segment
        if m.motion in (0, 1):
            segment = LineSegment(start, tuple(target))
        else:
            plane = _PLANE_AXES[m.plane]
            first, second = self.main[plane[0]], self.main[plane[1]]
            i, j = self.index[first], self.index[second]
            cw = m.motion == 2
            words = dict(block.centre)
            self.last_centre = words
            wi, wj = _CENTRE_WORDS[plane[0]], _CENTRE_WORDS[plane[1]]
            radius = block.extra.get("R")
            if radius is not None:
                if wi in words or wj in words:
                    return self._error(
                        block,
                        911002,
                        f"circle G0{m.motion} with both R and a centre ({wi}/{wj}): program one",
                    )
                found = _centre_from_radius((start[i], start[j]), (target[i], target[j]), radius, cw)
                if isinstance(found, str):
                    return self._error(block, 911001, f"circle G0{m.motion} R{radius:g}: {found}")
                words = {wi: found[0] - start[i], wj: found[1] - start[j]}
                self.last_centre = words
            if wi not in words and wj not in words:
                return self._error(block, 911002, f"circle G0{m.motion} without centre ({wi}/{wj})")
            ci_val, cj_val = words.get(wi, 0.0), words.get(wj, 0.0)
            if m.centre_absolute and radius is None:
                centre = (ci_val + m.offset(first), cj_val + m.offset(second))
            else:
                centre = (start[i] + ci_val, start[j] + cj_val)
            arc, mismatch = arc_from_centre(start, tuple(target), (i, j), centre, cw)
            if arc.radius <= 1e-9:
                return self._error(block, 911001, "circle with radius 0")
            if mismatch > ARC_RADIUS_TOLERANCE:
                return self._error(
                    block,
                    911001,
                    f"circle end point not on the circle: start radius {arc.radius:.4f} mm, "
                    f"end radius differs by {mismatch:.4f} mm",
                )
            segment = arc
        if m.in_area_definition:
            if self.area_handler is not None:
                err = self.area_handler.contour(segment, block, m)
                if err is not None:
                    return [Marker(MarkerKind.ERROR, block, payload=err)]
            self.position = target
            return []
        if segment.length <= 1e-12:
            self.position = target
            return []
        rapid = m.motion == 0
        if not rapid:
            if m.feed_per_rev:
                if m.feed_rev is None:
                    return self._error(block, 911000, "G95: no feed per revolution (F word) programmed")
                if not m.spindle_on or m.spindle_speed <= 0.0:
                    return self._error(
                        block,
                        60131,
                        "G95 feed per revolution with the spindle stopped: program M3/M4 and S first",
                    )
            elif m.feed is None:
                return self._error(block, 911000, "no feed (F word) programmed for a feed move")
        for check in self.path_checks:
            err = check(segment, block)
            if err is not None:
                return [Marker(MarkerKind.ERROR, block, payload=err)]
        v_max, accel = self._limits(segment, rapid)
        self.position = target
        return Motion(
            segment=segment,
            block=block,
            v_max=v_max,
            accel=accel,
            rapid=rapid,
            exact_stop=60 in block.g_codes,
        )

    def _measuring_move(self, block: Block) -> list[Motion | Marker]:
        """G100 (C14-23): a linear feed move toward the target, then decoding waits for its end."""
        assert self.measure_handler is not None
        if not block.axes:
            return self._error(block, 912011, "G100 measuring move without a target position")
        if self.modal.in_area_definition:
            return self._error(block, 21793, "G100 is not allowed inside a control area definition")
        segment = LineSegment(tuple(self.position), tuple(self._target(block)))
        if segment.length <= 1e-12:
            return self._error(block, 912011, "G100 measuring move: the target is the current position")
        result = self.measure_handler.measuring_move(segment, block, self.modal)
        if isinstance(result, DecodeError):
            return [Marker(MarkerKind.ERROR, block, payload=result)]
        for check in self.path_checks:
            err = check(result.segment, block)
            if err is not None:
                return [Marker(MarkerKind.ERROR, block, payload=err)]
        v_max, accel = self._limits(result.segment, rapid=False, feed=result.feed)
        motion = Motion(
            segment=result.segment, block=block, v_max=v_max, accel=accel, exact_stop=True, tag=result.tag
        )
        self.finished = True  # until result.done resumes from where the move ended
        return [motion, Marker(MarkerKind.ACTION, block, payload=result.done)]

    def _limits(self, segment: Segment, rapid: bool, feed: float | None = None) -> tuple[float, float]:
        """Path velocity and acceleration the axes allow along the segment (mm/s, mm/s²); ``feed``
        (mm/min) instead of the programmed F where given."""
        length = segment.length
        v = math.inf if rapid else (feed if feed is not None else self.path_feed()) / 60.0
        a = math.inf
        if isinstance(segment, LineSegment):
            for k, name in enumerate(self.axes):
                share = abs(segment.end[k] - segment.start[k]) / length
                if share <= 1e-12:
                    continue
                v_ax, v_rapid, a_ax = self.axis_limits[name]
                v = min(v, (v_rapid if rapid else v_ax) / share)
                a = min(a, a_ax / share)
        else:
            i, j = segment.plane
            for k, name in enumerate(self.axes):
                moving = k in (i, j) or abs(segment.end[k] - segment.start[k]) > 1e-12
                if not moving:
                    continue
                v_ax, v_rapid, a_ax = self.axis_limits[name]
                v = min(v, v_rapid if rapid else v_ax)
                a = min(a, a_ax)
            # share the acceleration between tangential and centripetal parts
            a *= 0.5
            v = min(v, math.sqrt(a * segment.radius))
        if math.isinf(a):
            a = 1000.0
        return v, a * self._weight(segment, rapid)

    def path_feed(self) -> float:
        """mm/min: the programmed path feed; under G95 F [mm/rev] times S [rpm] (the manual's
        example: F1.5 at S1200 is 1800 mm/min; the override of a real spindle is not simulated)."""
        m = self.modal
        if m.feed_per_rev:
            return (m.feed_rev or 0.0) * m.spindle_speed if m.spindle_on else 0.0
        return m.feed or 0.0

    def _weight(self, segment: Segment, rapid: bool) -> float:
        """The acceleration weighting of G130/G131 (feed) or G230/G231 (rapid) for this segment."""
        m = self.modal
        weight = m.accel_weight_rapid if rapid else m.accel_weight_feed
        per_axis = m.axis_accel_weight_rapid if rapid else m.axis_accel_weight_feed
        if per_axis:
            for k, name in enumerate(self.axes):
                w = per_axis.get(name)
                if w is not None and abs(segment.end[k] - segment.start[k]) > 1e-12:
                    weight = min(weight, w)
        return max(weight, 1e-3)

    def _area(self, block: Block, cmd: AreaCommand) -> list[Motion | Marker]:
        m = self.modal
        if isinstance(cmd, AreaBegin):
            if m.in_area_definition:
                return self._error(
                    block, 912002, "#CONTROL AREA BEGIN before the previous definition was closed by END"
                )
            m.in_area_definition = True
            # the contour blocks do not move the axes: END puts the position back
            self._position_before_area = list(self.position)
        elif isinstance(cmd, AreaEnd) and m.in_area_definition:
            # (an END without BEGIN goes to the area handler: the kernel's warning 21288, no effect)
            m.in_area_definition = False
            if self._position_before_area is not None:
                self.position = self._position_before_area
                self._position_before_area = None
        if self.area_handler is None:
            return self._error(block, 910110, "#CONTROL AREA: work and protection areas are not configured")
        result = self.area_handler.command(cmd, block, tuple(self.position), m)
        if isinstance(result, DecodeError):
            return [Marker(MarkerKind.ERROR, block, payload=result)]
        if result is not None:
            return [Marker(MarkerKind.ACTION, block, payload=result)]
        return []


INCH = 25.4
"""mm per inch (G70)."""


def _block_in_mm(block: Block, rotary: frozenset[str]) -> Block:
    """The block's path and coordinate values from inch to mm (G70, M-06: "acts on all path and
    coordinate values", programming manual 206272267): axis words (not rotary axes), I/J/K, R, the
    feed (F in inch/min, inch/rev as the G95 page's "[mm/rev, inch/rev]"), and an area's MIN_EXCUR /
    MAX_EXCUR ("in [mm, inch]", FCT-C14 2.4)."""
    area = block.area
    if isinstance(area, AreaBegin):
        area = replace(area, min_excur=area.min_excur * INCH, max_excur=area.max_excur * INCH)
    extra = block.extra
    if "R" in extra:
        extra = {**extra, "R": extra["R"] * INCH}
    return replace(
        block,
        axes=tuple((name, value if name in rotary else value * INCH) for name, value in block.axes),
        centre=tuple((word, value * INCH) for word, value in block.centre),
        feed=block.feed * INCH if block.feed is not None else None,
        area=area,
        extra=extra,
    )


def _centre_from_radius(
    start: tuple[float, float], end: tuple[float, float], radius: float, cw: bool
) -> tuple[float, float] | str:
    """The centre of a circle programmed by its radius (M-08): R > 0 the arc of at most 180°, R < 0
    the one of more than 180° (programming manual, circular interpolation with radius); the centre
    lies right of the chord for a short G02 arc, left for a short G03 arc. A message if there is none."""
    dx, dy = end[0] - start[0], end[1] - start[1]
    chord = math.hypot(dx, dy)
    r = abs(radius)
    if chord <= 1e-9:
        return "start and end point coincide: a full circle needs its centre (I/J/K)"
    if r <= 1e-9:
        return "radius 0"
    if chord > 2.0 * r + ARC_RADIUS_TOLERANCE:
        return f"the end point is {chord:.4f} mm away, farther than the diameter {2 * r:.4f} mm"
    h = math.sqrt(max(0.0, r * r - 0.25 * chord * chord))
    mx, my = start[0] + 0.5 * dx, start[1] + 0.5 * dy
    # unit normal left of the chord
    nx, ny = -dy / chord, dx / chord
    left = (not cw) == (radius > 0)
    sign = 1.0 if left else -1.0
    return (mx + sign * h * nx, my + sign * h * ny)
