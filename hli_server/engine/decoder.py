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

import dataclasses
import functools
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

from hli_server.engine.geometry import ArcSegment, LineSegment, Point, Segment, arc_from_centre
from hli_server.engine.kinematics.chain import KinematicError
from hli_server.engine.kinematics.library import build as build_kinematic
from hli_server.engine.kinematics.modes import mode_angles
from hli_server.engine.kinematics.path import AxisPath, SegmentMap, axis_path
from hli_server.engine.kinematics.state import KinematicState
from hli_server.engine.kinematics.tracking import Tracking, track
from hli_server.engine.kinematics.transform import Transformation
from hli_server.engine.kinematics.vectors import sub, unit
from hli_server.engine.nc.blocks import AreaBegin, AreaCommand, AreaEnd, Block, NcError
from hli_server.engine.nc.directives import (
    PAUSE,
    ChannelInit,
    ContourDirective,
    CoordinateCommand,
    Directive,
    FlushStop,
    FlushWait,
    MeasMode,
    Realtime,
    Slope,
    SyncAction,
    ToolWrite,
    VectorLimit,
)
from hli_server.engine.nc.kinematic_commands import (
    CaxTrack,
    CylSelect,
    KinematicCommand,
    KinParamWrite,
    KinSelect,
    SetAxes,
    ToolOriCs,
    TrafoSwitch,
)
from hli_server.engine.path.contour import (
    BSPLINE_PATH_DEV,
    HSC_DEFAULT,
    SPLINE_DEFAULT,
    Contour,
    ContourSettings,
    Piece,
)
from hli_server.engine.path.corners import CHAMFER, ROUNDING, CornerError, CornerRequest
from hli_server.engine.path.frames import FrameStack
from hli_server.engine.path.radius import Element, RadiusCompensation, TrcError
from hli_server.engine.path.tools import ToolData, ToolState
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

ALARM_SIMULATED_AS_DEV = 911040
"""Warning: a contouring type, ``#HSC`` or a spline the simulator does not model is simulated as
contouring with corner deviation (M-23; the project's own number: the kernel has none)."""

ALARM_APPROXIMATED = 911041
"""Warning: a construct approximated within a documented tolerance, once per program."""

ALARM_NO_FEED = 20008
"""The kernel's "feed rate in motion block is 0" (DG 250515083): a feed move without F and without a
default feed (P-CHAN-00099)."""

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


class _Referenced:
    """The action at the end of a G74 group: its axes are referenced."""

    __slots__ = ("axes", "handler")

    def __init__(self, handler: Callable[[tuple[str, ...]], None], axes: tuple[str, ...]) -> None:
        self.handler = handler
        self.axes = axes

    def __call__(self) -> None:
        self.handler(self.axes)


def _tell(
    handler: Callable[[Transformation | None], None] | None, trafo: Transformation | None
) -> Callable[[], None]:
    """The action marker's payload that tells ``handler`` the transformation now in effect (a partial, not
    a closure: a recording's snapshot keeps it, hli_server/recording/snapshot.py)."""
    return _nothing if handler is None else functools.partial(handler, trafo)


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
    vector_velocity: float | None = None
    """mm/min: ``#VECTOR LIMIT ON [VEL=..]``'s path velocity limit (None: none, ``OFF``)."""
    vector_feed: bool = True
    """The limit acts on feed blocks (G01/G02/G03; ``#VECTOR LIMIT``'s FEED, or neither keyword)."""
    vector_rapid: bool = True
    """The limit acts on rapid blocks (G00; RAPID, or neither keyword)."""
    meas_type: int | None = None
    """The measuring type of G100 selected in the program (the kernel's ``#MEAS MODE [n]``); None: the
    channel's default P-CHAN-00057. ``#MEAS MODE`` sets it (the interpreter's ``MeasMode``)."""
    contour: ContourSettings = field(default_factory=ContourSettings)
    """The parameters of ``#CONTOUR MODE [...]`` (polynomial contouring, M-20)."""
    contouring: bool = False
    """G261 / ``#CONTOUR MODE ON`` / G64: every corner is contoured (G260 / ``OFF``: not)."""
    hsc: bool = False
    """``#HSC ON``: every corner is contoured with ``hsc_settings`` (M-22)."""
    hsc_settings: ContourSettings = field(default_factory=lambda: HSC_DEFAULT)
    spline: bool = False
    """``#SPLINE ON`` / G151: simulated as contouring with ``spline_settings`` (M-23)."""
    spline_settings: ContourSettings = field(default_factory=lambda: SPLINE_DEFAULT)

    def blend(self, g_codes: tuple[int, ...]) -> ContourSettings | None:
        """The contouring at the end of a block with these G codes (None: an exact corner)."""
        if self.spline:
            return self.spline_settings
        if self.hsc:
            return self.hsc_settings
        if self.contouring or 61 in g_codes:
            return self.contour
        return None

    def offset(self, axis: str) -> float:
        base = self.zero_offsets.get(self.zero_offset, {}).get(axis, 0.0) if self.zero_offset else 0.0
        return base + self.g92.get(axis, 0.0)


_TRC_METHODS: dict[int, str] = {
    **dict.fromkeys(
        (5, 138, 236, 237, 238, 239),
        "is simulated as the indirect selection G139: the approach and departure blocks differ from the "
        "kernel's within the tool radius (the compensated contour between them is the same); a G40 without a "
        "motion block ends at the last equidistant point, as G239 does",
    ),
    141: "(contour masking) is not simulated: a contour violation stops the program with 916000 where the "
    "kernel would leave the violating blocks out",
}
"""The TRC selection methods and contour masking, approximated (warning 911041, docs/nc-language.md)."""

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
        tools: dict[int, ToolData] | None = None,
        kinematics: KinematicState | None = None,
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
        self.measured: float | None = None
        """The last measuring move: the fraction of its line where the probe signal came (the latched
        position), None when it ended without one (a built-in cycle reads it, engine/cycles)."""
        self.current_block: Block | None = None
        self._position_before_area: list[float] | None = None
        self.blocks_decoded = 0
        self.rotary_axes: frozenset[str] = frozenset()
        """Axes in degrees: G70 does not scale them."""
        self.positions_handler: Callable[[bool], list[float]] | None = None
        """The axes' command positions (False) or actual positions (True), machine coordinates
        (``#CHANNEL INIT``)."""
        self.slope_handler: Callable[[int | None], None] | None = None
        """Switches the acceleration profile (``#SLOPE``: 0..3 as P-CHAN-00071, None: the default)."""
        self.last_centre: dict[str, float] = {}
        """I, J, K of the last circle programmed (V.G.I, V.G.J, V.G.K)."""
        self.frames = FrameStack()
        """#ROTATION, #CS, #CS ADD, #ACS (:mod:`hli_server.engine.path.frames`)."""
        self.tools = ToolState(dict(tools or {}))
        """Tool table, D/T, the tool length in the axis positions (:mod:`hli_server.engine.path.tools`)."""
        self.trc = RadiusCompensation()
        """G40/G41/G42 (:mod:`hli_server.engine.path.radius`)."""
        self._main_index = tuple(self.index[a] for a in main_axes)
        self._trc_prog: list[float] | None = None
        """The programmed end point (program coordinates) while the radius compensation holds a block."""
        self._position_length = 0.0
        """The tool length included in :attr:`position` (the end of the last element emitted)."""
        self.contour = Contour()
        """Polynomial contouring (M-20): may hold the last motion back to blend it with the next."""
        self.warn: Callable[[int, str, int, str], None] | None = None
        """Raises a warning of the table (alarm, message, line, block): the channel sets it."""
        self.corner_ahead: Callable[[Block], bool] | None = None
        """Does the block after this one ask for a chamfer or rounding (G301/G302)? Then its motion is held
        back for it (the interpreter looks at the program's next line: :meth:`Interpreter.corner_ahead`)."""
        self.corner_size: float | None = None
        """The I word of G301/G302: "the I word remains stored" (PM 206609163)."""
        self.motion_unheld = False
        """The last motion went to the path without being held for a chamfer or rounding (no flush point
        since): a G301/G302 now comes too late for it (the batch geometry check sets it too)."""
        self._approximations: set[str] = set()
        """Constructs approximated in this program and said so (warning 911041 once each)."""
        self.homing: dict[str, tuple[float, float, float]] = {}
        """axis -> (reference position mm, homing velocity mm/s, acceleration mm/s²): G74 (the channel's
        axes' reference positions, their jog velocity and acceleration: the project's homing model)."""
        self.referenced_handler: Callable[[tuple[str, ...]], None] | None = None
        """Called when a G74 group has arrived at its reference positions (the channel marks them
        referenced)."""
        self.realtime_handler: Callable[[Realtime], None] | None = None
        """Defines and manages the channel's realtime cycles (``#RT CYCLE``) when the path passes."""
        self.kin = kinematics if kinematics is not None else KinematicState({}, 0, len(axes))
        """The kinematic data sets, the selection and the active transformation (docs/kinematics.md)."""
        self.kin_axes: Point = ()
        """With a transformation on: the axis positions at :attr:`position` (the tip's)."""
        self.kinematic_handler: Callable[[Transformation | None], None] | None = None
        """Told in program order (at rest) when a transformation goes on or off: the channel sets it."""
        self.axis_numbers: list[int] = []
        """The logical axis number of each slot (#SET AX, #CAXTRACK AXNR=): the channel sets them."""
        self.tracking_axis_number = 0
        """P-CHAN-00095: the #CAXTRACK axis when the command names none (0: the axis named C)."""
        self.tool_ori_cs = (0, 0)
        """P-CHAN-00188 (axis), P-CHAN-00189 (pose) of #TOOL ORI CS."""
        self.soft_limits: Callable[[int], tuple[float, float]] | None = None
        """The software limits in effect of a slot's axis (#TOOL ORI CS's pose, P-CHAN-00189 = 2)."""
        self.cax: Tracking | None = None
        """An active #CAXTRACK."""
        self.default_feed = 0.0
        """P-CHAN-00099: the feed [mm/min] at program start while no F is programmed (0: none)."""
        self.cyl = False
        """The transformation on was selected by #CYL (ends with #CYL OFF)."""
        self._default_axes = (list(axes), main_axes, dict(axis_limits), self.rotary_axes)

    # --- program control -----------------------------------------------------------------
    def start(self, blocks: BlockFeed | Iterator[Block], position: list[float]) -> None:
        """Decode from ``blocks`` (the interpreter, or parsed blocks) starting at ``position``."""
        self.blocks = _Blocks(blocks) if isinstance(blocks, Iterator) else blocks
        self.position = list(position)
        if self.modal.feed is None and self.default_feed > 0.0:
            self.modal.feed = self.default_feed  # P-CHAN-00099: the F of a program start without one
        self.modal.vector_velocity = None  # #VECTOR LIMIT is the program's (a new one starts without)
        self.corner_size = None
        self.motion_unheld = False
        self._approximations.clear()
        self.finished = False
        self.waiting = False
        self.blocks_decoded = 0
        self.modal.in_area_definition = False
        self.frames.reset()
        self.frames.plane = _PLANE_AXES[self.modal.plane]
        self.tools.reset()
        self.trc.reset()
        self._trc_prog = None
        self._position_length = 0.0
        self.contour.reset()
        self._reset_kinematics()

    def resume(self, position: list[float], measured: float | None = None) -> None:
        """Continue decoding from ``position`` after a measuring move; ``measured``: where along its line the
        probe signal came (None: none came)."""
        self.position = list(position)
        self.measured = measured
        self.finished = False

    def reset_modal(self) -> None:
        """Reset: modal state back to its defaults, G92 cleared (zero offset table kept)."""
        self.modal = ModalState(zero_offsets=self.modal.zero_offsets)
        self.frames.reset()
        self.tools.reset()
        self.trc.reset()
        self._trc_prog = None
        self._position_length = 0.0
        self.contour.reset()
        self._reset_kinematics()
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
        """The planner's item for an interpreter's directive (see :mod:`hli_server.engine.nc.directives`).

        ``#MEAS MODE`` and ``#CONTOUR MODE``/``#HSC``/``#SPLINE`` only set modal state: the blocks held
        back by the radius compensation and the contouring keep their corner (they took their own
        settings when they were decoded). Every other directive is a flush point: the stages are emptied
        in pipeline order (:meth:`_flushed`) before it takes effect."""
        if out is PAUSE:
            return []
        block = out.block
        if block is not None:
            self.current_block = block
        if isinstance(out, MeasMode):
            self.modal.meas_type = out.meas_type  # modal, decoded in order (the G100 blocks after it)
            return []
        if isinstance(out, ContourDirective):
            self._contour_directive(out)
            return []
        if isinstance(out, KinParamWrite):
            return self._kin_error(out, lambda: self.kin.write(out.kin_id, out.index, out.value))
        items = self._flushed([])
        if isinstance(out, KinematicCommand):
            return items if self.finished else items + self._kinematic(out)
        if self.finished:
            return items  # a held block failed its path check: its error ends decoding
        if isinstance(out, ToolWrite):
            if out.what == "radius":
                self.tools.radius_written = out.value
                if self.trc.side != 0:
                    self.trc.radius = abs(out.value)
            else:
                self.tools.length_written = out.value
            return items
        if isinstance(out, CoordinateCommand):
            error = self._coordinates(out)
            if error is not None:
                return [*items, Marker(MarkerKind.ERROR, block, payload=error)]
            return items
        if isinstance(out, SyncAction):
            return [*items, Marker(MarkerKind.SYNC, block, payload=out.action)]
        if isinstance(out, Realtime):
            realtime = self.realtime_handler
            if realtime is None:
                return items
            return [*items, Marker(MarkerKind.SYNC, block, payload=functools.partial(realtime, out))]
        if isinstance(out, FlushWait):
            self.waiting = True
            return [*items, Marker(MarkerKind.ACTION, block, payload=self._end_wait)]
        if isinstance(out, FlushStop):
            return [*items, Marker(MarkerKind.ACTION, block, payload=_nothing)]
        if isinstance(out, VectorLimit):
            m = self.modal
            m.vector_velocity, m.vector_feed, m.vector_rapid = out.velocity, out.feed, out.rapid
            return items
        if isinstance(out, ChannelInit):
            # #CHANNEL INIT: decoding waits for the path, then takes the axes' positions as its own
            self.waiting = True
            take = functools.partial(self._channel_init, out.actual, out.axes)
            return [*items, Marker(MarkerKind.ACTION, block, payload=take)]
        if isinstance(out, Slope):
            # #SLOPE (M-02): the path comes to rest here and the axes with it, then the profile
            # changes (the filter of the new profile starts at rest; docs/nc-language.md)
            handler = self.slope_handler
            if handler is None:
                return items
            profile = out.profile
            # a partial, not a closure: a recording's snapshot keeps it (hli_server/recording/snapshot.py)
            return [*items, Marker(MarkerKind.ACTION, block, payload=functools.partial(handler, profile))]
        return items  # pragma: no cover - every directive is handled above

    # --- kinematic transformations (docs/kinematics.md) ---------------------------------------------
    def _reset_kinematics(self) -> None:
        """Program start and reset: the data sets and the selection of the machine file, no transformation,
        no tracking, the channel's own axis configuration (#SET AX undone)."""
        self.kin.reset()
        self.cax = None
        self.cyl = False
        axes, main, limits, rotary = self._default_axes
        if self.axes != axes or self.main != main:
            self._configure(list(axes), main, dict(limits), rotary)

    def _configure(
        self,
        axes: list[str],
        main: tuple[str, str, str],
        limits: dict[str, tuple[float, float, float]],
        rotary: frozenset[str],
    ) -> None:
        self.axes = axes
        self.index = {a: i for i, a in enumerate(axes)}
        self.axis_limits = limits
        self.rotary_axes = rotary
        self._set_main(main)

    def _set_main(self, main: tuple[str, str, str]) -> None:
        self.main = main
        self._main_index = tuple(self.index[a] for a in main)

    def _kin_error(self, cmd: KinematicCommand, act: Callable[[], None]) -> list[Motion | Marker]:
        """Run ``act``; the error marker of a :class:`KinematicError` it raises (decoding ends)."""
        try:
            act()
        except KinematicError as exc:
            self.finished = True
            return [Marker(MarkerKind.ERROR, cmd.block, payload=DecodeError(exc.alarm, exc.message))]
        return []

    def _kinematic(self, cmd: KinematicCommand) -> list[Motion | Marker]:
        """A kinematic command at a flush point (the stages are empty)."""
        if isinstance(cmd, KinSelect):
            return self._kin_error(cmd, lambda: self.kin.select(cmd.kin_id))
        if isinstance(cmd, TrafoSwitch):
            if self.cyl:
                return self._error_at(cmd.block, 20687, "#TRAFO while #CYL is on: program #CYL OFF first")
            return self._trafo(cmd)
        if isinstance(cmd, CaxTrack):
            return self._caxtrack(cmd)
        if isinstance(cmd, SetAxes):
            return self._set_axes(cmd)
        if isinstance(cmd, ToolOriCs):
            return self._tool_ori_cs(cmd)
        if isinstance(cmd, CylSelect):
            return self._cylinder(cmd)
        return self._error_at(cmd.block, 910110, f"{type(cmd).__name__} is not simulated")  # pragma: no cover

    def _error_at(self, block: Block | None, alarm: int, message: str) -> list[Motion | Marker]:
        self.finished = True
        return [Marker(MarkerKind.ERROR, block, payload=DecodeError(alarm, message))]

    def _set_axes(self, cmd: SetAxes) -> list[Motion | Marker]:
        """``#SET AX``: exactly the programmed axes form the channel's configuration, by name, logical number
        and axis index (the kernel's errors 21256/21257/21258 for a name, index or number twice, 20312 for an
        unknown number, 20683 with a transformation on). The axes keep their positions; an axis left out
        cannot be programmed; the axis indices 0, 1, 2 are the main axes and the kinematic's indices follow
        the new order."""
        block = cmd.block
        if self.kin.active is not None:
            return self._error_at(
                block, 20683, "#SET AX while a kinematic transformation is on: #TRAFO OFF first"
            )
        entries = cmd.entries
        for attr, alarm, what in (
            ("name", 21256, "axis name"),
            ("index", 21257, "axis index"),
            ("number", 21258, "logical axis number"),
        ):
            values = [getattr(e, attr) for e in entries]
            twice = sorted({v for v in values if values.count(v) > 1})
            if twice:
                return self._error_at(block, alarm, f"#SET AX: {what} {twice[0]} programmed twice")
        slot_of = {n: k for k, n in enumerate(self.axis_numbers)}
        unknown = [e.number for e in entries if e.number not in slot_of]
        if unknown:
            return self._error_at(
                block, 20312, f"#SET AX: logical axis number {unknown[0]} is not an axis of the channel"
            )
        ordered = sorted(entries, key=lambda e: e.index)
        if [e.index for e in ordered[:3]] != [0, 1, 2]:
            return self._error_at(
                block, 21257, "#SET AX: the axis indices 0, 1, 2 (the main axes) must be programmed"
            )
        limits_of_slot = [self.axis_limits[name] for name in self.axes]
        rotary_slots = {k for k, name in enumerate(self.axes) if name in self.rotary_axes}
        names = [f"#{n}" for n in self.axis_numbers]  # not in the configuration: cannot be programmed
        for e in entries:
            names[slot_of[e.number]] = e.name
        self._configure(
            names,
            (ordered[0].name, ordered[1].name, ordered[2].name),
            {name: limits_of_slot[k] for k, name in enumerate(names)},
            frozenset(names[k] for k in rotary_slots),
        )
        self.kin.configure_slots(slot_of[e.number] for e in ordered)
        return []

    def _caxtrack(self, cmd: CaxTrack) -> list[Motion | Marker]:
        """``#CAXTRACK ON [...]`` / ``OFF [ANGPOS=..]`` (:mod:`hli_server.engine.kinematics.tracking`)."""
        block = cmd.block
        if not cmd.on:
            items: list[Motion | Marker] = []
            cax = self.cax
            self.cax = None
            if cax is not None and cmd.angpos is not None:
                end = list(self.position)
                end[cax.slot] = cmd.angpos
                items = self._rotation(block, end)
            return items
        for name, value in (("ANGLIMIT", cmd.anglimit), ("OFFSET", cmd.offset)):
            if value is not None and not -360.0 <= value <= 360.0:
                return self._error_at(block, 21135, f"#CAXTRACK {name}={value:g} outside -360..360°")
        if cmd.axis is not None:
            slot = self.index.get(cmd.axis)
        else:
            number = cmd.axis_number or self.tracking_axis_number
            slot = (
                (self.axis_numbers.index(number) if number in self.axis_numbers else None)
                if number
                else self.index.get("C")
            )
        if slot is None:
            return self._error_at(
                block, 20312, "#CAXTRACK: no tracking axis (AX=, AXNR=, P-CHAN-00095 or an axis named C)"
            )
        if slot in self._main_index:
            return self._error_at(
                block, 120626, f"#CAXTRACK: the tracking axis {self.axes[slot]} is a main axis"
            )
        plane = _PLANE_AXES[self.modal.plane]
        self.cax = Tracking(
            slot,
            (self._main_index[plane[0]], self._main_index[plane[1]]),
            abs(cmd.anglimit or 0.0),
            cmd.offset,
        )
        return []

    def _rotation(self, block: Block | None, end: list[float]) -> list[Motion | Marker]:
        """A block of its own that turns axes while the tip rests (#CAXTRACK, #TOOL ORI CS): at rapid."""
        start = tuple(self.position)
        if block is None or math.dist(start, end) <= 1e-12:
            self.position = end
            return []
        piece = Piece(segment=LineSegment(start, tuple(end)), block=block, rapid=True)
        items = self._emit_pieces(self.contour.push(piece))
        if not (items and isinstance(items[-1], Marker)):
            self.position = end
        return items

    def _tracked(self, segment: Segment, block: Block) -> tuple[list[Motion | Marker], Segment]:
        """With #CAXTRACK on: the inserted turning block's items (if any) and the segment with the tracking
        axis following its tangent."""
        cax = self.cax
        if cax is None:
            return [], segment
        inserted, tracked = track(cax, segment)
        if inserted is None:
            return [], tracked
        return self._rotation(block, list(inserted.end)), tracked

    def _tool_ori_cs(self, cmd: ToolOriCs) -> list[Motion | Marker]:
        """``#TOOL ORI CS``: the rotary axes turn the tool onto the axis P-CHAN-00188 of the active #CS (the
        selected kinematic, on or not), in the pose P-CHAN-00189 chooses; with RTCP on the tip rests, else
        only the rotary axes move. 292006 for a kinematic without two rotary axes."""
        block = cmd.block
        if not cmd.on:
            return []
        trafo = self.kin.active
        if trafo is None:
            try:
                data = self.kin.data.get(self.kin.selected) or self.kin.set_of(self.kin.selected)
                trafo, _ = build_kinematic(data, self.kin.slots, self.tools.length)
            except KinematicError as exc:
                return self._error_at(block, exc.alarm, exc.message)
        chain = trafo.chain
        if len(chain.rotary) != 2:
            return self._error_at(
                block,
                292006,
                f"#TOOL ORI CS: kinematic {trafo.kin_id} has no two rotary axes to turn the tool",
            )
        axis = (
            (0.0, 0.0, 1.0)
            if self.tool_ori_cs[0] in (0, 3)
            else ((1.0, 0.0, 0.0) if self.tool_ori_cs[0] == 1 else (0.0, 1.0, 0.0))
        )
        zero = self.frames.fixture_to_machine(self.frames.to_workpiece((0.0, 0.0, 0.0)))
        tip = self.frames.fixture_to_machine(self.frames.to_workpiece(axis))
        target = unit(sub(tip, zero))
        axes_now = tuple(self.kin_axes) if self.kin.active is not None else tuple(self.position)
        try:
            values = self._pose(trafo, target, axes_now)
        except KinematicError as exc:
            return self._error_at(block, exc.alarm, exc.message)
        end = list(self.position)
        first, second = chain.rotary
        s1, s2 = trafo.slots[first.index], trafo.slots[second.index]
        if self.kin.active is not None and trafo.mode:
            a1, a2 = sorted((s1, s2))
            end[a1], end[a2] = mode_angles(trafo.mode, target, self.position[a1], self.position[a2])
        else:
            end[s1], end[s2] = values
        return self._rotation(block, end)

    def _pose(
        self, trafo: Transformation, target: tuple[float, float, float], axes: Sequence[float]
    ) -> tuple[float, float]:
        """The rotary axes' values for ``target`` by P-CHAN-00189: 0/1 the nearer pose (shortest way), 2 the
        one within the software limits first, 3/4 the first/second solution."""
        chain = trafo.chain
        first, second = chain.rotary
        q = [axes[s] for s in trafo.slots]
        mode = self.tool_ori_cs[1]
        if mode in (0, 1):
            return chain.solve_orientation(target, q)
        poses = chain.poses(target, q)
        if not poses:
            return chain.solve_orientation(target, q)  # raises 292004
        if mode == 2 and self.soft_limits is not None:
            s1, s2 = trafo.slots[first.index], trafo.slots[second.index]
            lo1, hi1 = self.soft_limits(s1)
            lo2, hi2 = self.soft_limits(s2)
            inside = [p for p in poses if lo1 <= p[0] <= hi1 and lo2 <= p[1] <= hi2]
            if inside:
                poses = inside
            return min(poses, key=lambda p: abs(p[0] - q[first.index]) + abs(p[1] - q[second.index]))
        return poses[0] if mode == 3 or len(poses) == 1 else poses[1]

    def _cylinder(self, cmd: CylSelect) -> list[Motion | Marker]:
        """``#CYL [..]`` (kinematic 15) / ``#CYL ORI LATERAL [..]`` (kinematic 90) / ``#CYL OFF``: the
        development of the rotary axis is programmed in mm (degrees = mm * 180 / (pi R)); the main axes
        are the ones named."""
        block = cmd.block
        if not cmd.axes:
            if not self.cyl:
                return []
            items = self._trafo(TrafoSwitch(block, False))
            self.cyl = False
            main = self._default_axes[1]
            self._set_main(main if all(a in self.index for a in main) else self.main)
            return items
        if self.kin.active is not None:
            return self._error_at(block, 20687, "#CYL while a transformation is on: program #TRAFO OFF first")
        # AXNR1=/AXNR2= name their axes by the logical number ("#<number>")
        names = tuple(
            self.axes[self.axis_numbers.index(int(a[1:]))]
            if a.startswith("#") and a[1:].isdigit() and int(a[1:]) in self.axis_numbers
            else a
            for a in cmd.axes
        )
        missing = [a for a in names if a not in self.index]
        if missing:
            return self._error_at(block, 910107, f"#CYL: {missing[0]} is not an axis of the channel")
        rotary = [a for a in names[:2] if a in self.rotary_axes]
        if len(rotary) != 1 or cmd.radius <= 0.0:
            return self._error_at(
                block,
                292040,
                "#CYL: one of the first two axes must be the rotary axis, and a radius above 0 is needed",
            )
        kin_id = 90 if cmd.lateral else 15
        data = self.kin.data.get(kin_id) or self.kin.set_of(kin_id)
        try:
            trafo, _ = build_kinematic(data, self.kin.slots, self.tools.length)
        except KinematicError as exc:
            return self._error_at(block, exc.alarm, exc.message)
        offset = (
            0.0 if cmd.lateral else data.params.get(1, 0.0) * 1e-4
        )  # HD2: angle offset of the rotary axis
        trafo = dataclasses.replace(
            trafo,
            kin_id=kin_id,
            scaled_slot=self.index[rotary[0]],
            scale=180.0 / (math.pi * cmd.radius),
            scale_offset=offset,
            name=("TF5290 tube, " if cmd.lateral else "lateral surface, ") + trafo.name,
        )
        third = names[2] if len(names) > 2 else self.main[2]
        self._set_main((names[0], names[1], third))
        axes_now = tuple(self.position)
        self.kin.active = trafo
        self.kin.selected = kin_id
        self.cyl = True
        self.kin_axes = axes_now
        self.position = list(trafo.to_tip(axes_now, axes_now))
        handler = self.kinematic_handler
        return [Marker(MarkerKind.ACTION, block, payload=_tell(handler, trafo))]

    def _trafo(self, cmd: TrafoSwitch) -> list[Motion | Marker]:
        """``#TRAFO ON``: the selected kinematic with the tool's length; the decoder's position becomes the
        tool tip's. ``#TRAFO OFF``: back to the axes. Either is a point where the path rests (an action
        marker tells the channel, in program order)."""
        kin = self.kin
        handler = self.kinematic_handler
        if cmd.on:
            if kin.active is not None:
                return []
            axes = tuple(self.position)
            trafo: Transformation | None = None
            try:
                trafo = kin.switch_on(self.tools.length)
                if trafo is not None:
                    self.position = list(trafo.to_tip(axes, axes))
            except KinematicError as exc:
                kin.switch_off()
                return self._error_at(cmd.block, exc.alarm, exc.message)
            if trafo is None:
                return []  # kinematic ID 0: "no kinematic is enabled, no warning or error"
            block = cmd.block
            if self.warn is not None and block is not None:
                for alarm, message in kin.warnings:
                    self.warn(alarm, message, block.line, block.label)
            self.kin_axes = axes
            active = trafo
            return [Marker(MarkerKind.ACTION, block, payload=_tell(handler, active))]
        if kin.active is None:
            return []
        self._kin_off()
        return [Marker(MarkerKind.ACTION, cmd.block, payload=_tell(handler, None))]

    def _kin_off(self) -> None:
        """The transformation off: the decoder's position is the axes' again, the tool length applied."""
        self.kin.switch_off()
        self.position = list(self.kin_axes)
        self.tools.applied_length = self._position_length = self.tools.length

    def _kin_pieces(self, piece: Piece, trafo: Transformation) -> Motion | Marker:
        """A tip segment with the transformation on: its axes' path (:func:`axis_path`) is what the
        checks of the axes see (software limits, collision), the tip what the areas see (``monitors_tcp``);
        the velocity is what the axes allow along the axes' path."""
        block = piece.block
        try:
            path = axis_path(trafo, piece.segment, self.kin_axes)
        except KinematicError as exc:
            return Marker(MarkerKind.ERROR, block, payload=DecodeError(exc.alarm, exc.message))
        for check in self.path_checks:
            if getattr(getattr(check, "__self__", check), "monitors_tcp", False):
                err = check(piece.segment, block)
            else:
                err = next((e for e in (check(seg, block) for seg in path.segments) if e is not None), None)
            if err is not None:
                return Marker(MarkerKind.ERROR, block, payload=err)
        v_max, accel, gain = self._kin_limits(piece, path)
        self.kin_axes = path.end
        return Motion(
            segment=piece.segment,
            block=block,
            v_max=v_max,
            accel=accel,
            rapid=piece.rapid,
            exact_stop=piece.exact_stop,
            kin=(
                SegmentMap(trafo, path.anchor_s, path.anchors, path.segments, path.shift)
                if trafo.mode
                else SegmentMap(trafo, segments=path.segments, shift=path.shift)
            ),
            gain=gain,
        )

    def _kin_limits(self, piece: Piece, path: AxisPath) -> tuple[float, float, float]:
        """Path velocity and acceleration [mm/s, mm/s²]: the tip path's own limits, and for every axis its
        v_max (rapid) and a_max over the largest ratio of its travel to the tip's along the axes' path (that
        ratio's largest is the third value, :attr:`Motion.gain`)."""
        v, a = self._limits(piece.segment, piece.rapid, feed=piece.feed)
        if len(path.segments) == 1 and path.segments[0].length == piece.segment.length:
            return v, a, 1.0  # a shifted copy of the tip's path: the same ratios
        gain = 1.0
        ss, pts = path.anchor_s, path.anchors
        for k, name in enumerate(self.axes):
            share = 0.0
            for n in range(1, len(ss)):
                ds = ss[n] - ss[n - 1]
                if ds > 0.0:
                    share = max(share, abs(pts[n][k] - pts[n - 1][k]) / ds)
            if share <= 1e-12:
                continue
            gain = max(gain, share)
            v_ax, v_rapid, a_ax = self.axis_limits[name]
            v = min(v, (v_rapid if piece.rapid else v_ax) / share)
            a = min(a, a_ax / share * self._weight(piece.segment, piece.rapid))
        return v, a, gain

    def _end_wait(self) -> None:
        """The path reached a ``#FLUSH WAIT``: decoding goes on."""
        self.waiting = False

    def _channel_init(self, actual: bool, axes: tuple[str, ...]) -> None:
        """The path reached a ``#CHANNEL INIT``: the axes' command (or actual) positions become the
        decoder's (all the channel's axes where none is named), then decoding goes on."""
        handler = self.positions_handler
        if handler is not None and not self.transforms_active and self.kin.active is None:
            positions = handler(actual)
            for k, name in enumerate(self.axes):
                if not axes or name in axes:
                    self.position[k] = positions[k]
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
        items = self._flushed([Marker(MarkerKind.END, self.current_block, payload="eof")])
        self.finished = True
        return items

    def syntax_error(self, exc: NcError) -> list[Motion | Marker]:
        """A line the parser could not read: the error marker with the place the parser named."""
        params: dict[str, Any] = {"line": exc.line, "block": exc.block, **exc.params}
        if exc.program:
            params["program"] = exc.program
        items = self._flushed(
            [Marker(MarkerKind.ERROR, None, payload=DecodeError(exc.alarm, exc.message, params))]
        )
        self.finished = True
        return items

    # --- one block -------------------------------------------------------------------------
    def _error(self, block: Block, alarm: int, message: str, **params: Any) -> list[Motion | Marker]:
        return [Marker(MarkerKind.ERROR, block, payload=DecodeError(alarm, message, params))]

    def _decode(self, block: Block) -> list[Motion | Marker]:
        before: list[Motion | Marker] = []
        if self.trc.active and self._changes_frame(block):
            # a zero offset, G92 or a plane change: the block the compensation holds is finished in the
            # frame it was programmed in (it ends perpendicular to its end point)
            before = self._trc_flush()
            if before and isinstance(before[-1], Marker):
                return before
        items = before + self._decode_block(block)
        if items and self.contour.holding and isinstance(items[-1], Marker):
            # a marker of this block (an error, an area command, the program's end, a G100 move) comes
            # after the held motion: the corner before it is not contoured
            first = next(k for k, item in enumerate(items) if isinstance(item, Marker))
            if not any(isinstance(item, Motion) for item in items[first:]):
                return items[:first] + self._flushed(items[first:])
        return items

    def _changes_frame(self, block: Block) -> bool:
        """The block programs G92, another zero offset (G53..G59) or another plane (G17/G18/G19)."""
        m = self.modal
        for g in block.g_codes:
            if g == 92 or (g in (17, 18, 19) and g != m.plane):
                return True
            if g == 53 and m.zero_offset is not None:
                return True
            if 54 <= g <= 59 and m.zero_offset != f"G{g}":
                return True
        return False

    def _flushed(self, items: list[Motion | Marker]) -> list[Motion | Marker]:
        """A flush point: the stages emptied in pipeline order (the radius compensation's held block
        through the frames into the contouring stage, then the contouring stage's held piece), then
        ``items``; if a held motion fails its check, its error marker replaces ``items`` (decoding ends)."""
        out: list[Motion | Marker] = []
        self.motion_unheld = False
        if self.trc.active:
            out = self._trc_flush()
            if out and isinstance(out[-1], Marker):
                self.finished = True
                return out
        if self.contour.holding:
            out += self._emit_pieces(self.contour.flush())
            if out and isinstance(out[-1], Marker):
                self.finished = True
                return out
        return out + items

    def _contour_directive(self, out: ContourDirective) -> None:
        """``#CONTOUR MODE``, ``#HSC``, ``#SPLINE`` (M-20, M-22, M-23): modal, in program order. A type the
        simulator does not model is simulated as DEV, and said so by warning 911040 (never silently)."""
        m = self.modal
        v = out.values
        if out.function == "CONTOUR":
            mode = out.mode or m.contour.mode
            m.contour = replace(
                m.contour,
                mode=mode,
                path_dev=v.get("PATH_DEV", m.contour.path_dev),
                pre_dist=v.get("PRE_DIST", m.contour.pre_dist),
                post_dist=v.get("POST_DIST", m.contour.post_dist),
                simulated_as=None if mode in ("DEV", "DIST") else f"#CONTOUR MODE [{mode}]",
            )
            if out.on is not None:
                m.contouring = out.on
            settings = m.contour
            announce = out.mode is not None and settings.simulated_as is not None
        elif out.function == "HSC":
            deviation = v.get("PATH_DEV" if out.mode == "BSPLINE" else "CONTERROR")
            if deviation is None and out.mode == "BSPLINE":
                deviation = BSPLINE_PATH_DEV
            mode = out.mode or m.hsc_settings.simulated_as or "#HSC"
            m.hsc_settings = replace(
                m.hsc_settings,
                path_dev=m.hsc_settings.path_dev if deviation is None else deviation,
                simulated_as=f"#HSC [{out.mode}]" if out.mode else m.hsc_settings.simulated_as,
            )
            if out.on is not None:
                m.hsc = out.on
            settings = m.hsc_settings
            announce = bool(out.on)
        else:
            if out.mode is not None:
                m.spline_settings = replace(m.spline_settings, simulated_as=f"#SPLINE TYPE {out.mode}")
            if out.on is not None:
                m.spline = out.on
            settings = m.spline_settings
            announce = bool(out.on)
        if announce and out.block is not None:
            self._announce(settings, out.block)

    def _approximated(self, block: Block, key: str, what: str) -> None:
        """Warning 911041 once per program and ``key``: a construct that only shapes the path, approximated
        within the tolerance ``what`` says (docs/nc-language.md, "Refusals and approximations")."""
        if key in self._approximations or self.warn is None:
            return
        self._approximations.add(key)
        self.warn(ALARM_APPROXIMATED, f"{key} {what} (docs/nc-language.md)", block.line, block.label)

    def _announce(self, settings: ContourSettings, block: Block) -> None:
        """Warning 911040: ``settings.simulated_as`` is simulated as contouring with corner deviation."""
        if self.warn is not None:
            self.warn(
                ALARM_SIMULATED_AS_DEV,
                f"{settings.simulated_as} is simulated as polynomial contouring with corner deviation "
                f"PATH_DEV={settings.path_dev:g} mm (docs/nc-language.md, Contouring)",
                block.line,
                f"N{block.number}" if block.number is not None else f"line {block.line}",
            )

    def _decode_block(self, block: Block) -> list[Motion | Marker]:
        m = self.modal
        if block.two_path:
            return self._error(
                block,
                910110,
                "two-path programming (': G0 ... : G0 ...') is not supported: docs/nc-language.md says what "
                "simulating it would take",
            )
        if 70 in block.g_codes:
            m.inch = True  # the new unit applies to this block already (M-06)
        elif 71 in block.g_codes:
            m.inch = False
        if 4 in block.g_codes:
            return self._dwell(block)  # before G70's scaling: the time is in seconds
        if 74 in block.g_codes:
            return self._homing(block)  # the values are the order, not positions
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
                if g != m.plane and self.frames.rotation is not None:
                    self.frames.rotation = None  # a plane change deselects #ROTATION (programming manual)
                m.plane = g
                self.frames.plane = _PLANE_AXES[g]
            elif g in (25, 26):
                self.trc.transition = g
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
            elif g in (261, 64):
                m.contouring = True
            elif g == 260:
                m.contouring = False
            elif g == 151:
                m.spline = True
                self._announce(m.spline_settings, block)
            elif g == 150:
                m.spline = False
            elif g in (100, 200, 201, 202):
                return self._error(block, 910110, f"G{g} is not supported in this block context")
            elif g in _TRC_METHODS:
                self._approximated(block, f"G{g}", _TRC_METHODS[g])
        tool_error = self._tool_words(block)
        if tool_error is not None:
            return tool_error
        if block.feed is not None:
            if block.feed <= 0:
                return self._error(block, 911000, f"feed F{block.feed:g} must be positive")
            if m.feed_per_rev:
                m.feed_rev = block.feed
            else:
                m.feed = block.feed
        corner: CornerRequest | None = None
        if CHAMFER in block.g_codes or ROUNDING in block.g_codes:
            found = self._corner_request(block)
            if isinstance(found, list):
                return found
            corner = found
        if 92 in block.g_codes and self.transforms_active:
            self._g92_framed(block)
            return items
        if 92 in block.g_codes:
            # G92: the current position gets the programmed program coordinates
            for name, value in block.axes:
                i = self.index[name]
                base = m.zero_offsets.get(m.zero_offset, {}).get(name, 0.0) if m.zero_offset else 0.0
                m.g92[name] = self.position[i] - base - value
            return items
        if measuring:
            # a corner held back is not contoured into a measuring move: the stages are emptied first
            before = self._flushed([])
            if self.finished:
                return before
            return before + self._measuring_move(block)
        moves = bool(block.axes) or (m.motion in (2, 3) and bool(block.centre) and corner is None)
        if corner is not None and not moves:
            return self._corner_between(block, corner)
        if moves and (self.transforms_active or 40 in block.g_codes) and not m.in_area_definition:
            # radius compensation -> frames and tool length -> contouring -> checks (M-30)
            items = self._motion_framed(block)
            if items and isinstance(items[-1], Marker):
                return items
        elif moves:
            items.extend(self._motion(block))
            if items and isinstance(items[-1], Marker) and items[-1].kind is MarkerKind.ERROR:
                return items
        elif 40 in block.g_codes and self.trc.active:
            items = self._trc_flush()
            self.trc.side = 0
            self._trc_prog = None
            if items and isinstance(items[-1], Marker):
                return items
        if corner is not None and self.contour.holding_for_corner:
            self.contour.request_corner(corner)  # at the end of this block's own motion
        ends: list[Motion | Marker] = [
            Marker(MarkerKind.END, block, payload=f"M{code:02d}") for code in block.m_codes if code in (2, 30)
        ]
        if ends:
            if self.cax is not None and self.warn is not None:
                self.warn(
                    21250,
                    "#CAXTRACK is still on at the program's end: program #CAXTRACK OFF",
                    block.line,
                    block.label,
                )
            # the program's end: every stage emptied first (an error of a held block replaces the end)
            out = items + self._flushed(ends)
            if self.kin.active is not None:
                self._kin_off()  # the end deselects the transformation: the position is the axes' again
            return out
        # another M function is a "non-relevant block" to the compensation and the contouring: both keep
        # their corner across it (PM 207844107; it has no effect on the path here)
        return items

    def _dwell(self, block: Block) -> list[Motion | Marker]:
        """``G04 <first main axis><s>``, ``G04 <s>``, ``G04 S<revolutions>`` (M-09, PM 206132747): the path
        rests for the time, then goes on (the axes at rest first). The time by the first main axis (the
        interpreter reads ``G04 2.5`` and ``G04 P1`` so); another axis besides it is the kernel's warning
        20685 (the program goes on), another axis alone its 20014 (DG 250536843); revolutions of the main
        spindle last ``60 * S / speed`` seconds at the spindle's programmed speed (none: 20007)."""
        first = self.main[0]
        others = [name for name, _ in block.axes if name != first]
        seconds = dict(block.axes).get(first)
        if seconds is None and others:
            return self._error(
                block,
                20014,
                f"G04 {others[0]}..: the dwell time is programmed with the first main axis ({first}), "
                f"not with {others[0]}",
            )
        if others and self.warn is not None:
            self.warn(
                20685,
                f"G04 with the axes {', '.join(others)}: the dwell time takes the first main axis only "
                f"({first}); the others are ignored",
                block.line,
                block.label,
            )
        revolutions = block.extra.get("S")
        if seconds is None and revolutions is not None:
            m = self.modal
            if not m.spindle_on or m.spindle_speed <= 0.0:
                return self._error(
                    block,
                    20007,
                    f"G04 S{revolutions:g}: a dwell in spindle revolutions needs the spindle turning "
                    "(M3/M4 with S)",
                )
            seconds = 60.0 * revolutions / m.spindle_speed
        if seconds is None:
            return self._error(
                block, 20014, f"G04 without its time: write G04 {first}<s>, G04 <s> or G04 S<revolutions>"
            )
        if seconds < 0.0:
            return self._error(block, 911000, f"G04 {first}{seconds:g}: a dwell time is not negative")
        return [Marker(MarkerKind.ACTION, block, payload=Dwell(seconds))]

    def _homing(self, block: Block) -> list[Motion | Marker]:
        """``G74 X2 Y3 Z1`` (PM 206138635): programmable homing. The values give the order (equal values
        together); each group moves to its reference positions (P-AXIS reference point here: the axis'
        ``reference_position``, else its start position) in machine coordinates, as one line with the
        axes' homing velocity and acceleration (the jog values: the project's homing model), and is
        referenced at its end. The moves go through every path check and are travelled like any block, so
        the monitors see them. ``G74 S..`` (a spindle) has no effect here. A flush point; with the radius
        compensation active: not simulated (910110)."""
        if self.trc.active:
            return self._error(
                block, 910110, "G74 with tool radius compensation active is not simulated: G40 first"
            )
        if block.axes and any(name not in self.homing for name, _ in block.axes):
            missing = [name for name, _ in block.axes if name not in self.homing]
            return self._error(block, 910110, f"G74: no reference point known for {', '.join(missing)}")
        items = self._flushed([])
        if self.finished:
            return items
        order = sorted({value for _, value in block.axes})
        for rank in order:
            group = tuple(name for name, value in block.axes if value == rank)
            start = tuple(self.position)
            target = list(start)
            for name in group:
                target[self.index[name]] = self.homing[name][0]
            segment = LineSegment(start, tuple(target))
            if segment.length > 1e-12:
                err = self._check(segment, block)
                if err is not None:
                    return [*items, Marker(MarkerKind.ERROR, block, payload=err)]
                v = a = math.inf
                for name in group:
                    k = self.index[name]
                    share = abs(target[k] - start[k]) / segment.length
                    if share > 1e-12:
                        v = min(v, self.homing[name][1] / share)
                        a = min(a, self.homing[name][2] / share)
                items.append(Motion(segment=segment, block=block, v_max=v, accel=a, exact_stop=True))
                self.position = target
            handler = self.referenced_handler
            if handler is not None:
                items.append(Marker(MarkerKind.ACTION, block, payload=_Referenced(handler, group)))
        if self.axes[self._main_index[self._tool_axis()]] in dict(block.axes):
            self.tools.applied_length = 0.0  # the tool axis is at its reference: no tool length in it
            self._position_length = 0.0
        return items

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

    def _motion(self, block: Block) -> list[Motion | Marker]:
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
            checked = self._checked_arc(block, start, tuple(target), (i, j), centre, cw)
            if isinstance(checked, list):
                return checked
            segment = checked
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
            feed_error = self._feed_error(block)
            if feed_error is not None:
                return feed_error
        before: list[Motion | Marker] = []
        if self.cax is not None:
            before, segment = self._tracked(segment, block)
            if before and isinstance(before[-1], Marker):
                return before
            target = list(segment.end)
        hold = self._corner_next(block)
        self.motion_unheld = not hold
        piece = Piece(
            segment=segment,
            block=block,
            rapid=rapid,
            exact_stop=60 in block.g_codes,
            feed=None if rapid else self.path_feed(),
            blend=None if rapid else m.blend(block.g_codes),
            hold=hold,
        )
        items = before + self._push(piece)
        if not (items and isinstance(items[-1], Marker)):
            self.position = target
            self._position_length = 0.0
        return items

    def _feed_error(self, block: Block) -> list[Motion | Marker] | None:
        """The error of a feed move without a usable feed (no F; G95 without F or a turning spindle)."""
        m = self.modal
        if m.feed_per_rev:
            if m.feed_rev is None:
                return self._error(
                    block, ALARM_NO_FEED, "G95: feed rate 0: no feed per revolution (F word) programmed"
                )
            if not m.spindle_on or m.spindle_speed <= 0.0:
                return self._error(
                    block,
                    60131,
                    "G95 feed per revolution with the spindle stopped: program M3/M4 and S first",
                )
        elif m.feed is None:
            return self._error(
                block,
                ALARM_NO_FEED,
                "feed rate 0: no feed (F word) programmed for a feed move, and no default feed "
                "(P-CHAN-00099 prog_start.feedrate)",
            )
        return None

    def _push(self, piece: Piece) -> list[Motion | Marker]:
        """``piece`` through the contouring stage (contouring, chamfers and roundings) to the path checks;
        a chamfer or rounding that cannot be inserted is the error of its G301/G302 block, and the path
        stops where the held pre-block starts."""
        held = self.contour.held_piece
        try:
            pieces = self.contour.push(piece)
        except CornerError as exc:
            self.contour.reset()
            if held is not None:
                self.position = list(held.segment.start)
            return [Marker(MarkerKind.ERROR, piece.block, payload=DecodeError(exc.alarm, exc.message))]
        return self._emit_pieces(pieces)

    # --- chamfers and roundings (G301/G302, PM 206609163) ---------------------------------------------
    def _corner_next(self, block: Block) -> bool:
        """Is this block's motion held back for a chamfer or rounding at its end?"""
        if CHAMFER in block.g_codes or ROUNDING in block.g_codes:
            return True
        ahead = self.corner_ahead
        return ahead is not None and ahead(block)

    def _corner_request(self, block: Block) -> CornerRequest | list[Motion | Marker]:
        """G301/G302 with its I word (stored: a later G301/G302 may leave it out; PM 206609163): the
        kernel's 20130 (both in one block), 20012 (no I, or I0), 20800 (a negative I); with the radius
        compensation active: not simulated (910110)."""
        kinds = [g for g in block.g_codes if g in (CHAMFER, ROUNDING)]
        if len(kinds) > 1:
            return self._error(block, 20130, "G301 and G302 in one block: a chamfer or a rounding")
        kind = kinds[0]
        size = dict(block.centre).get("I")
        if size is not None and not (self.modal.motion in (2, 3) and block.axes):
            self.corner_size = size
        size = self.corner_size
        if size is None or size == 0.0:
            return self._error(
                block, 20012, f"G{kind} without its size: program I<mm> (not 0) with the first G301/G302"
            )
        if size < 0.0:
            return self._error(block, 20800, f"G{kind} I{size:g}: the size is out of range (0 < I)")
        if self.trc.active:
            return self._error(
                block,
                910110,
                f"G{kind} with tool radius compensation active is not simulated: the kernel inserts the "
                "element in the programmed contour, before the compensation (docs/nc-language.md)",
            )
        feed = None if block.feed is None else self.path_feed()
        return CornerRequest(kind, size, feed, block)

    def _corner_between(self, block: Block, corner: CornerRequest) -> list[Motion | Marker]:
        """A G301/G302 block without motion: the element goes between the held motion and the next one.
        Without a motion before it: the kernel's warning 20351; a second one before the next motion: its
        warning 20701 (the second counts). A motion that went to the path unheld (the look-ahead did not
        see this block: a call or a jump between): not simulated (910110)."""
        place = block.label
        if not self.contour.holding_for_corner:
            if self.motion_unheld:
                return self._error(
                    block,
                    910110,
                    f"G{corner.kind} after the motion it belongs to was handed to the path: write G301/G302 "
                    "in the line right after the motion block (not after a call or a jump)",
                )
            if self.warn is not None:
                self.warn(
                    20351,
                    f"G{corner.kind}: no motion block before it to insert the element after",
                    block.line,
                    place,
                )
            return []
        if self.contour.corner_requested and self.warn is not None:
            self.warn(
                20701,
                f"G{corner.kind}: a G301/G302 without a motion block since the last one",
                block.line,
                place,
            )
        self.contour.request_corner(corner)
        return []

    def _emit_pieces(self, pieces: list[Piece]) -> list[Motion | Marker]:
        """The path checks and the planner's items for the pieces the contouring stage gives out; the
        first piece that fails a check is replaced by its error marker and the rest dropped."""
        items: list[Motion | Marker] = []
        trafo = self.kin.active
        for piece in pieces:
            if piece.segment.length <= 1e-12:
                continue
            if trafo is not None:
                item = self._kin_pieces(piece, trafo)
                items.append(item)
                if isinstance(item, Marker):
                    self.contour.reset()
                    self.position = list(piece.segment.start)
                    return items
                continue
            err = self._check(piece.segment, piece.block, piece.tip_start, piece.tip_end)
            if err is not None:
                self.contour.reset()
                self.position = list(piece.segment.start)  # the path stops where the piece starts
                items.append(Marker(MarkerKind.ERROR, piece.block, payload=err))
                return items
            v_max, accel = self._limits(piece.segment, piece.rapid, feed=piece.feed)
            items.append(
                Motion(
                    segment=piece.segment,
                    block=piece.block,
                    v_max=v_max,
                    accel=accel,
                    rapid=piece.rapid,
                    exact_stop=piece.exact_stop,
                )
            )
        return items

    # --- frames, tools, radius compensation (M-10..M-18; hli_server/engine/path) -----------------------
    @property
    def transforms_active(self) -> bool:
        """A frame, a tool or the radius compensation is active: blocks take the framed path."""
        return (
            self.frames.active
            or self.tools.d != 0
            or self.tools.applied_length != 0.0
            or self.tools.length_written is not None
            or self.trc.active
            or self._trc_prog is not None
            or self.kin.active is not None
        )

    def _tool_axis(self) -> int:
        """Index into the main axes of the tool axis: the plane's third main axis (#TLAX default)."""
        return {17: 2, 18: 1, 19: 0}[self.modal.plane]

    def to_machine(self, prog: list[float] | tuple[float, ...], length: float) -> list[float]:
        """Program coordinates -> axis positions: #ROTATION, #CS, zero offsets, #ACS, tool length."""
        m = self.modal
        out = list(prog)
        mi = self._main_index
        for k, name in enumerate(self.axes):
            if k not in mi:
                out[k] = prog[k] + m.offset(name)
        w = self.frames.to_workpiece((prog[mi[0]], prog[mi[1]], prog[mi[2]]))
        z = (w[0] + m.offset(self.main[0]), w[1] + m.offset(self.main[1]), w[2] + m.offset(self.main[2]))
        mach = self.frames.fixture_to_machine(z)
        for a in range(3):
            out[mi[a]] = mach[a]
        if self.kin.active is None:  # with a transformation the tool length is the kinematic's
            out[mi[self._tool_axis()]] += length
        return out

    def to_program(self, pos: list[float] | tuple[float, ...], length: float) -> list[float]:
        """Axis positions -> program coordinates (the inverse of :meth:`to_machine`)."""
        m = self.modal
        out = list(pos)
        mi = self._main_index
        for k, name in enumerate(self.axes):
            if k not in mi:
                out[k] = pos[k] - m.offset(name)
        q = [pos[mi[0]], pos[mi[1]], pos[mi[2]]]
        if self.kin.active is None:
            q[self._tool_axis()] -= length
        z = self.frames.machine_to_fixture((q[0], q[1], q[2]))
        w = (z[0] - m.offset(self.main[0]), z[1] - m.offset(self.main[1]), z[2] - m.offset(self.main[2]))
        p = self.frames.from_workpiece(w)
        for a in range(3):
            out[mi[a]] = p[a]
        return out

    def program_position(self) -> list[float]:
        """The programmed end point of the last block in program coordinates (V.A.PROG / V.A.ABS)."""
        if self._trc_prog is not None:
            return list(self._trc_prog)
        if not self.transforms_active:
            return [p - self.modal.offset(a) for p, a in zip(self.position, self.axes, strict=True)]
        return self.to_program(self.position, self.tools.applied_length)

    def _tool_words(self, block: Block) -> list[Motion | Marker] | None:
        """D, T, G40/G41/G42 of a block (before its motion)."""
        t = block.extra.get("T")
        if t is not None:
            self.tools.t = int(t)
        d = block.extra.get("D")
        if d is not None:
            if d != int(d) or d < 0:
                return self._error(
                    block, 916001, f"D{d:g}: the D word takes a tool data block number 0, 1, 2, ..."
                )
            length = self.tools.length
            err = self.tools.select(int(d))
            if err is not None:
                return self._error(block, 916001, err, d=int(d))
            try:
                self.kin.tool_kinematic(self.tools.data.kin_id)  # P-TOOL-00011
            except KinematicError as exc:
                return self._error(block, exc.alarm, exc.message)
            if self.kin.active is not None and self.tools.length != length:
                return self._error(
                    block,
                    910110,
                    f"D{d:g} changes the tool length while kinematic {self.kin.active.kin_id} is on: "
                    "not simulated; "
                    "select the tool before #TRAFO ON (docs/kinematics.md)",
                )
            if self.trc.side != 0:
                self.trc.radius = abs(self.tools.radius)
        sides = [g for g in block.g_codes if g in (41, 42)]
        if sides:
            if self.modal.in_area_definition:
                return self._error(block, 21793, "G41/G42 are not allowed inside a control area definition")
            side = 1 if sides[0] == 41 else -1
            self.trc.select(side, self.tools.radius, _PLANE_AXES[self.modal.plane])
            if self._trc_prog is None:
                self._trc_prog = self.program_position()
        return None

    def _g92_framed(self, block: Block) -> None:
        """G92 with frames active: the current point gets the programmed coordinates (all frames kept)."""
        m = self.modal
        length = self.tools.applied_length if self.kin.active is None else 0.0
        prog = self.to_program(self.position, length)
        for name, value in block.axes:
            prog[self.index[name]] = value
        mi = self._main_index
        q = [self.position[mi[0]], self.position[mi[1]], self.position[mi[2]]]
        q[self._tool_axis()] -= length
        fixture = self.frames.machine_to_fixture((q[0], q[1], q[2]))
        w = self.frames.to_workpiece((prog[mi[0]], prog[mi[1]], prog[mi[2]]))
        for a in range(3):
            name = self.main[a]
            base = m.zero_offsets.get(m.zero_offset, {}).get(name, 0.0) if m.zero_offset else 0.0
            m.g92[name] = fixture[a] - w[a] - base
        for name, value in block.axes:
            k = self.index[name]
            if k not in mi:
                base = m.zero_offsets.get(m.zero_offset, {}).get(name, 0.0) if m.zero_offset else 0.0
                m.g92[name] = self.position[k] - base - value

    def _coordinates(self, cmd: CoordinateCommand) -> DecodeError | None:
        """#CS / #ACS / #CS ADD|SET|DEL / #ROTATION: the frames change; the axes do not move."""
        f = self.frames
        kind, op = cmd.kind, cmd.op
        if kind == "ROTATION":
            if op == "ON":
                o = cmd.options
                f.rotation = (o.get("ANGLE", 0.0), o.get("CENTER1", 0.0), o.get("CENTER2", 0.0))
            else:
                f.rotation = None
            return None
        bad = [v for v in cmd.values[3:6] if not -360.0 <= v <= 360.0]
        if bad:
            return DecodeError(
                20676,
                f"#{kind} {op}: rotation angle {bad[0]:g}° outside -360° .. 360°",
                {"value": bad[0], "lower": -360, "upper": 360},
            )
        if op == "ADD":
            err = f.add(cmd.name or "", cmd.values)
        elif op == "SET":
            err = f.set_added(cmd.name or "", cmd.values)
        elif op == "DEL":
            err = f.remove_added(cmd.name)
        else:
            systems = f.cs if kind == "CS" else f.acs
            err = None
            if op in ("DEF", "ON") and cmd.values:
                ident = systems.define(cmd.ident, cmd.values)
                if isinstance(ident, str):
                    return DecodeError(916002, ident)
                if op == "ON":
                    err = systems.activate(ident)
            elif op == "ON":
                err = systems.activate(cmd.ident)
                if err is not None:
                    return DecodeError(20821, err, {"value": cmd.ident or 0})
            elif op == "DEF":
                err = f"#{kind} DEF without its components [v1, v2, v3, φ1, φ2, φ3]"
            elif op == "OFF":
                systems.deactivate(all_=cmd.all_)
        return DecodeError(916002, err) if err is not None else None

    def _trc_flush(self) -> list[Motion | Marker]:
        """Empty the radius compensation's held block (before a marker, a directive, the end)."""
        if not self.trc.active:
            return []
        elements = self.trc.flush()
        if self.trc.side == 0:
            self._trc_prog = None
        return self._emit(elements)

    def _checked_arc(
        self,
        block: Block,
        start: tuple[float, ...],
        end: tuple[float, ...],
        plane: tuple[int, int],
        centre: tuple[float, float],
        cw: bool,
    ) -> ArcSegment | list[Motion | Marker]:
        """The circle from ``start`` to ``end`` around ``centre``, or the error of a circle with radius 0 or
        an end point off the circle (911001): the one check of the plain and the framed path."""
        arc, mismatch = arc_from_centre(start, end, plane, centre, cw)
        if arc.radius <= 1e-9:
            return self._error(block, 911001, "circle with radius 0")
        if mismatch > ARC_RADIUS_TOLERANCE:
            return self._error(
                block,
                911001,
                f"circle end point not on the circle: start radius {arc.radius:.4f} mm, "
                f"end radius differs by {mismatch:.4f} mm",
            )
        return arc

    def _motion_framed(self, block: Block) -> list[Motion | Marker]:
        """A motion block with frames, tools or radius compensation active (program coordinates ->
        radius compensation -> frames -> checks)."""
        m = self.modal
        prog_start = self.program_position()
        prog_end = list(prog_start)
        length = self.tools.applied_length
        tool_axis = self._main_index[self._tool_axis()]
        for name, value in block.axes:
            i = self.index[name]
            if m.absolute:
                prog_end[i] = value
                if i == tool_axis:
                    length = self.tools.length
            else:
                prog_end[i] += value
        centre: tuple[float, float] | None = None
        cw = m.motion == 2
        if m.motion in (2, 3):
            plane = _PLANE_AXES[m.plane]
            first, second = self.main[plane[0]], self.main[plane[1]]
            i, j = self.index[first], self.index[second]
            words = dict(block.centre)
            self.last_centre = words
            wi, wj = _CENTRE_WORDS[plane[0]], _CENTRE_WORDS[plane[1]]
            if wi not in words and wj not in words:
                return self._error(block, 911002, f"circle G0{m.motion} without centre ({wi}/{wj})")
            ci_val, cj_val = words.get(wi, 0.0), words.get(wj, 0.0)
            centre = (
                (ci_val, cj_val) if m.centre_absolute else (prog_start[i] + ci_val, prog_start[j] + cj_val)
            )
            checked = self._checked_arc(block, tuple(prog_start), tuple(prog_end), (i, j), centre, cw)
            if isinstance(checked, list):
                return checked
        rapid = m.motion == 0
        if not rapid:
            feed_error = self._feed_error(block)
            if feed_error is not None:
                return feed_error
        element = Element(
            tuple(prog_start),
            tuple(prog_end),
            block,
            rapid,
            centre,
            cw,
            feed=None if rapid else self.path_feed(),
            blend=None if rapid else m.blend(block.g_codes),
            length=length,
        )
        deselect = 40 in block.g_codes
        if self.trc.active or deselect:
            plane_idx = _PLANE_AXES[m.plane]
            self.trc.plane = (self.index[self.main[plane_idx[0]]], self.index[self.main[plane_idx[1]]])
            try:
                elements = self.trc.push(element, deselect=deselect)
            except TrcError as exc:
                return self._error(block, exc.alarm, exc.message)
            self._trc_prog = prog_end if self.trc.active else None
        else:
            elements = [element]
        self.tools.applied_length = length
        items = self._emit(elements)
        if not elements and not self.trc.active:
            self.position = self.to_machine(prog_end, length)
            self._position_length = length
        return items

    def _emit(self, elements: list[Element]) -> list[Motion | Marker]:
        """Compensated elements (program coordinates) -> machine segments (frames, the tool length of each
        element) -> the contouring stage -> the path checks and the planner's items (:meth:`_emit_pieces`).
        The stages are rigid, so the contouring stage blends the compensated path in machine coordinates
        with the deviation it was programmed with (M-30)."""
        items: list[Motion | Marker] = []
        for e in elements:
            block = e.block
            start = tuple(self.position)
            end = tuple(self.to_machine(e.end, e.length))
            segment: Segment
            if e.centre is None:
                segment = LineSegment(start, end)
            else:
                plane = _PLANE_AXES[self.modal.plane]
                i, j = self.index[self.main[plane[0]]], self.index[self.main[plane[1]]]
                sense = self.frames.keeps_plane(plane)
                if sense == 0:
                    items.append(
                        Marker(
                            MarkerKind.ERROR,
                            block,
                            payload=DecodeError(
                                910110,
                                "a circle in a coordinate system tilted against the plane is not simulated "
                                "(docs/nc-language.md)",
                            ),
                        )
                    )
                    return items
                c_prog = list(e.start)
                c_prog[i], c_prog[j] = e.centre
                c_m = self.to_machine(c_prog, e.length)
                cw = e.cw if sense > 0 else not e.cw
                segment, _ = arc_from_centre(start, end, (i, j), (c_m[i], c_m[j]), cw)
            if self.cax is not None and segment.length > 1e-12:
                inserted, segment = self._tracked(segment, block)
                items += inserted
                if items and isinstance(items[-1], Marker):
                    return items
                end = segment.end
            length_at_start = self._position_length
            self.position = list(end)
            self._position_length = e.length
            if segment.length <= 1e-12:
                continue
            hold = not self.trc.active and self._corner_next(block)
            self.motion_unheld = not hold
            piece = Piece(
                segment=segment,
                block=block,
                rapid=e.rapid,
                exact_stop=60 in block.g_codes,
                feed=e.feed,
                blend=e.blend,
                tip_start=length_at_start,
                tip_end=e.length,
                hold=hold,
            )
            items += self._push(piece)
            if items and isinstance(items[-1], Marker):
                return items
        return items

    def tip_segment(
        self, segment: Segment, length_at_start: float | None = None, length_at_end: float | None = None
    ) -> Segment:
        """The path of the tool tip (the monitored tool centre point): the segment less the tool length
        (``length_at_start``/``length_at_end``: the lengths in the end points' axis positions where they
        differ from the one applied now, as for a piece the contouring stage held back)."""
        length = self.tools.applied_length if length_at_end is None else length_at_end
        l0 = length if length_at_start is None else length_at_start
        if (length == 0.0 and l0 == 0.0) or self.kin.active is not None:
            return segment
        k = self._main_index[self._tool_axis()]

        def shift(p: Point, by: float) -> Point:
            q = list(p)
            q[k] -= by
            return tuple(q)

        if isinstance(segment, LineSegment):
            return LineSegment(shift(segment.start, l0), shift(segment.end, length))
        return dataclasses.replace(segment, start=shift(segment.start, l0), end=shift(segment.end, length))

    def _check(
        self,
        segment: Segment,
        block: Block,
        length_at_start: float | None = None,
        length_at_end: float | None = None,
    ) -> DecodeError | None:
        """Every path check; the area checks see the tool tip (``monitors_tcp``)."""
        tip = self.tip_segment(segment, length_at_start, length_at_end)
        for check in self.path_checks:
            tcp = getattr(getattr(check, "__self__", check), "monitors_tcp", False)
            err = check(tip if tcp else segment, block)
            if err is not None:
                return err
        return None

    def _measuring_move(self, block: Block) -> list[Motion | Marker]:
        """G100 (C14-23): a linear feed move toward the target, then decoding waits for its end."""
        assert self.measure_handler is not None
        if not block.axes:
            return self._error(block, 912011, "G100 measuring move without a target position")
        if self.modal.in_area_definition:
            return self._error(block, 21793, "G100 is not allowed inside a control area definition")
        if self.trc.active:
            return self._error(
                block, 910110, "G100 with tool radius compensation active is not simulated: program G40 first"
            )
        if self.kin.active is not None:
            return self._error(
                block,
                910110,
                "G100 with a kinematic transformation on is not simulated: program #TRAFO OFF first",
            )
        target = self._target(block)
        if self.transforms_active:
            prog = self.program_position()
            length = self.tools.applied_length
            for name, value in block.axes:
                i = self.index[name]
                prog[i] = value if self.modal.absolute else prog[i] + value
            target = self.to_machine(prog, length)
        segment = LineSegment(tuple(self.position), tuple(target))
        if segment.length <= 1e-12:
            return self._error(block, 912011, "G100 measuring move: the target is the current position")
        result = self.measure_handler.measuring_move(segment, block, self.modal)
        if isinstance(result, DecodeError):
            return [Marker(MarkerKind.ERROR, block, payload=result)]
        err = self._check(result.segment, block)
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
        m = self.modal
        if m.vector_velocity is not None and (m.vector_rapid if rapid else m.vector_feed):
            v = min(v, m.vector_velocity / 60.0)  # #VECTOR LIMIT ON [VEL=..] (PM 207477899)
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
        """An area command is a flush point: the held blocks first, then the command (FCT-C14 2.3)."""
        before = self._flushed([])
        if self.finished:
            return before
        return before + self._area_command(block, cmd)

    def _area_command(self, block: Block, cmd: AreaCommand) -> list[Motion | Marker]:
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
        # the areas see the tool tip (the ON check tests where the tool is: C14-11)
        point = tuple(self.position)
        if self.tools.applied_length != 0.0:
            point = self.tip_segment(LineSegment(point, point)).start
        result = self.area_handler.command(cmd, block, point, m)
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
