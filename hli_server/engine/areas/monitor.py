"""Work and protection area monitoring of the channels (FCT-C14, C14-01..C14-23).

One :class:`ChannelAreas` per channel is the decoder's area handler (``#CONTROL AREA`` commands and
the contour blocks between BEGIN and END), its path check (every motion block before it is queued),
its measuring-move handler (G100) and the channel's jog guard (manual mode). :class:`AreaMonitor`
wires them into the machine and does what happens per cycle: the probe input, the PLC flag, reset
and the mode-change check.

Decode time and execution time
------------------------------
The decoder runs up to 64 blocks ahead of the path. Each channel therefore keeps two tables:

* ``planned``: the table as it will be when the path reaches the block being decoded. Commands are
  validated and applied to it at decode time, so the path checks of the blocks after an ON see the
  area, and the ON check uses the position where the path will be (C14-11).
* ``effective``: the table as it is now. The same operation is applied to it by the callable the
  handler returns, which the channel runs when the path reaches the block (at standstill there).
  The PLC, the jog guard, the mode-change check and ``channel_areas(...).to_json()`` see it.

At every program start (and after a reset) ``planned`` is copied from ``effective``: commands that
were decoded but never reached (program aborted) did not happen.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from hli_server.engine.areas.geometry import (
    EPS,
    Group,
    Hit,
    first_violation,
    point_at,
    polygon_self_intersection,
)
from hli_server.engine.areas.table import MAX_AREAS, AreaDefinition, AreaEvent, AreaState, AreaTable, Refusal
from hli_server.engine.decoder import DecodeError, MeasuringMove, ModalState
from hli_server.engine.geometry import ArcSegment, LineSegment, Point, Segment
from hli_server.engine.monitors.base import ChannelHooks, MachineView, Monitor
from hli_server.engine.nc.blocks import (
    AreaBegin,
    AreaClear,
    AreaCommand,
    AreaEnd,
    AreaOff,
    AreaOn,
    AreaShape,
    Block,
)
from hli_server.engine.planner import Marker, Motion
from schemas.events import Alarm, AreasChanged, AreaViolation, Measurement
from schemas.units import DISTANCE_LIMIT_MM, increments_from_mm
from schemas.wire import Mode, ProgramState

if TYPE_CHECKING:
    from hli_server.engine.channel import Channel

__all__ = [
    "MAX_CONTOUR_BLOCKS",
    "PROTECTION_MARGIN",
    "VIOLATION_ALARMS",
    "AreaMonitor",
    "ChannelAreas",
    "channel_areas",
]

MAX_CONTOUR_BLOCKS = 20
"""C14-04, FCT-C14 2.3: at most 20 motion blocks in one definition (the start point's block included)."""
CLOSE_TOLERANCE = 1e-6
"""mm: first and last point of a polygon are "identical" within this (project's own)."""
PROTECTION_MARGIN = 1e-3
"""mm: a limited measuring move (P-CHAN-00268 = 1) stops this far before a protection area."""

ALARM_POINT_OUTSIDE_WORK = 120484
ALARM_PATH_LEAVES_WORK = 120486
ALARM_ACTIVE_CLEAR = 120499
ALARM_MANUAL_OUTSIDE_WORK = 50961
ALARM_MANUAL_IN_PROTECTION = 50962
ALARM_MEASURE_LIMIT = 50706
ALARM_POINT_IN_PROTECTION = 912000
ALARM_PATH_ENTERS_PROTECTION = 912001
ALARM_DEFINITION = 912002
COORDINATE_LIMIT = DISTANCE_LIMIT_MM
"""mm: corners, circle extents and height limits of an area lie within +/- this (429496.7294 mm, twice
the range of positions, which the DINT in 0.1 µm bounds). The NC words are range-checked already;
zero offsets and G92 can still add to them. Beyond it no axis can go, and the exact geometry's
boundary tolerance (:data:`~hli_server.engine.areas.geometry.EPS`, 1e-9 mm) would drown in the
floats' resolution; refused as 912002 (issue 12 finding 1)."""
ALARM_COMMAND = 912003
ALARM_MANUAL_STOP = 912004
ALARM_NO_PROBE = 912010
ALARM_NOT_SUPPORTED = 910110

VIOLATION_ALARMS = frozenset(
    {
        ALARM_POINT_OUTSIDE_WORK,
        ALARM_PATH_LEAVES_WORK,
        ALARM_POINT_IN_PROTECTION,
        ALARM_PATH_ENTERS_PROTECTION,
        ALARM_MANUAL_OUTSIDE_WORK,
        ALARM_MANUAL_IN_PROTECTION,
    }
)
"""Alarms that set ``bahn_state.area_mon_violation_detected_r`` (C14-22) until the reset."""

_PLANE_AXES = {17: (0, 1), 18: (2, 0), 19: (1, 2)}
_PLANE_NAMES = {17: "G17", 18: "G18", 19: "G19"}


def _num(v: float) -> str:
    text = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _fmt(names: list[str], point: Point, indices: tuple[int, ...] | None = None) -> str:
    """``(X-150, Y75, Z0)``; names with digits take ``=``: ``(X2=100, Y2=-20, Z2=0)``."""
    ks = indices if indices is not None else range(len(point))
    parts = [
        f"{names[k]}={_num(point[k])}" if names[k][-1].isdigit() else f"{names[k]}{_num(point[k])}"
        for k in ks
    ]
    return "(" + ", ".join(parts) + ")"


def _fmt2(p: tuple[float, float]) -> str:
    return f"({_num(p[0])}, {_num(p[1])})"


def _beyond_limit(points: list[tuple[str, float, float]], lo: float, hi: float) -> str | None:
    """What of an area lies beyond :data:`COORDINATE_LIMIT` (or is not finite), or None."""
    limit = COORDINATE_LIMIT
    why = (
        f"lies beyond +/-{limit:.4f} mm, twice the range of positions (a DINT in 0.1 µm): no axis gets "
        "there; check the zero offset and G92 shift in effect"
    )
    for what, x, y in points:
        if not (-limit <= x <= limit and -limit <= y <= limit):
            return f"{what} {why}"
    for what, h in (("MIN_EXCUR with the offset", lo), ("MAX_EXCUR with the offset", hi)):
        if not -limit <= h <= limit:
            return f"{what} ({_num(h)}) {why}"
    return None


def _ids(ids: list[int]) -> str:
    return ", ".join(str(i) for i in ids)


@dataclass(slots=True)
class _Contour:
    segment: Segment
    block: Block
    plane: int
    motion: int


@dataclass(slots=True)
class _Pending:
    """A definition between BEGIN and END."""

    begin: AreaBegin
    block: Block
    height_axis: str | None
    contour: list[_Contour] = field(default_factory=list)


@dataclass(slots=True)
class _Measuring:
    """The tag of a queued G100 motion and what happened to it."""

    block: Block
    limited: bool
    limit_reason: str
    triggered: bool = False


class ChannelAreas:
    """Area table, area handler, path check, measuring-move handler and jog guard of one channel."""

    def __init__(self, machine: MachineView, channel: Channel) -> None:
        self.machine = machine
        self.channel = channel
        self._manual_mode_setting = channel.config.suppress_workspace_monitoring_manual_mode
        """P-CHAN-00442 (0, 1, 2), read once: the manual-mode checks run every cycle."""
        self._move_limit_warning = machine.config.manual.move_limit_warning
        """P-MANU-00014"""
        self.names = list(channel.axis_names)
        self.planned = AreaTable()
        self.effective = AreaTable()
        self.pending: _Pending | None = None
        self.violation_auto = False
        self.violation_manual = False
        self._stop_warning: tuple[bool, int, tuple[int, int, int]] | None = None
        """A P-MANU-00014 warning due when the braking axes have come to rest (protection, id, axes)."""
        self._blocked_direction: tuple[float, ...] | None = None
        self._blocks_seen: object = None
        self._probe_request = False
        self._probe_prev = False
        self.measurement: dict[str, Any] | None = None
        """The last probe result (C14-23): block, positions in mm, cycle."""

    # --- public views --------------------------------------------------------------------
    def to_json(self, planned: bool = False) -> dict[str, Any]:
        """The area table as ``check`` lists it: ``{"channel", "axes", "areas": [...]}``."""
        table = self.planned if planned else self.effective
        return {"channel": self.channel.number, "axes": list(self.names), "areas": table.to_json()}

    def request_probe(self, on: bool) -> None:
        """The operator's (tests', API's) probe input, OR'ed with ``mc_command.probe_w`` (C14-23)."""
        self._probe_request = on

    def sync_planned(self) -> None:
        """Start of a program: the planned table is the effective one; a half definition is dropped."""
        self.planned = self.effective.copy()
        self.pending = None

    # --- AreaHandler: #CONTROL AREA commands ---------------------------------------------
    def command(
        self, cmd: AreaCommand, block: Block, position: Point, modal: ModalState
    ) -> DecodeError | Callable[[], None] | None:
        if isinstance(cmd, AreaBegin):
            return self._begin(cmd, block, modal)
        if isinstance(cmd, AreaEnd):
            return self._end(block, modal)
        name = type(cmd).__name__.removeprefix("Area").upper()
        if modal.in_area_definition:
            return DecodeError(
                ALARM_COMMAND,
                f"#CONTROL AREA {name} inside the definition of area {self._pending_id()}: "
                "close the definition with #CONTROL AREA END first",
            )
        if isinstance(cmd, AreaOn):
            return self._on(cmd, position)
        if isinstance(cmd, AreaOff):
            return self._off(cmd)
        return self._clear(cmd)

    def _pending_id(self) -> str:
        return str(self.pending.begin.area_id) if self.pending is not None else "?"

    def _begin(self, cmd: AreaBegin, block: Block, modal: ModalState) -> DecodeError | None:
        self.pending = None
        head = f"#CONTROL AREA BEGIN [ID={cmd.area_id}]"
        if cmd.monitor_lvl.upper() != "MCS":
            return DecodeError(
                ALARM_NOT_SUPPORTED,
                f'{head}: MONITOR_LVL="{cmd.monitor_lvl}" is not supported by the simulator '
                '(no multi-stage transformations); use MONITOR_LVL="MCS" or leave it out',
            )
        if cmd.min_excur >= cmd.max_excur:
            return DecodeError(
                ALARM_DEFINITION,
                f"{head}: MIN_EXCUR={_num(cmd.min_excur)} must be less than MAX_EXCUR={_num(cmd.max_excur)}",
            )
        height_axis: str | None = None
        if cmd.excur_ax is not None:
            if cmd.excur_ax not in self.names:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{head}: EXCUR_AX={cmd.excur_ax} is not an axis of channel {self.channel.number} "
                    f"({', '.join(self.names)})",
                )
            height_axis = cmd.excur_ax
        elif cmd.excur_axnr is not None:
            axis = self.machine.axes_by_number.get(cmd.excur_axnr)
            if axis is None or axis.name not in self.names:
                numbers = ", ".join(f"{a.name}={a.number}" for a in self.channel.axes)
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{head}: EXCUR_AXNR={cmd.excur_axnr} is not the logical number of an axis of channel "
                    f"{self.channel.number} ({numbers})",
                )
            height_axis = axis.name
        state = self.planned.state(cmd.area_id)
        if state is not None and isinstance(self.planned.next_state(cmd.area_id, AreaEvent.DEFINE), Refusal):
            return DecodeError(
                ALARM_DEFINITION,
                f"{head}: area {cmd.area_id} is active and cannot be redefined; deactivate it first "
                f"(#CONTROL AREA OFF [ID={cmd.area_id}])",
            )
        if state is None and self.planned.full:
            return DecodeError(
                ALARM_DEFINITION,
                f"{head}: the channel already has {MAX_AREAS} areas "
                f"({_ids(sorted(self.planned.definitions))}); clear one first (#CONTROL AREA CLEAR [ID=n])",
            )
        self.pending = _Pending(cmd, block, height_axis)
        return None

    # --- AreaHandler: contour blocks -------------------------------------------------------
    def contour(self, segment: Segment, block: Block, modal: ModalState) -> DecodeError | None:
        p = self.pending
        if p is None:
            return DecodeError(ALARM_DEFINITION, "contour block outside an area definition")
        area = f"area {p.begin.area_id}"
        if modal.feed is None:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: no feed (F word) active in the contour block; program F before the contour "
                "(C14-03)",
            )
        if not modal.absolute:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: contour positions must be absolute (G90), G91 is active",
            )
        if len(p.contour) >= MAX_CONTOUR_BLOCKS:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: more than {MAX_CONTOUR_BLOCKS} motion blocks in the definition "
                f"({block.label} is block {len(p.contour) + 1})",
            )
        k = len(p.contour)
        is_arc = isinstance(segment, ArcSegment)
        gname = f"G0{modal.motion}"
        if p.begin.shape == AreaShape.POLY:
            if is_arc or modal.motion != 1:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: a POLY contour is made of G01 blocks, {block.label} is {gname}",
                )
        elif k == 0:
            if is_arc or modal.motion != 1:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: a CIRC area starts with a G01 block to the start point of the circle, "
                    f"{block.label} is {gname}",
                )
        elif k == 1:
            if not is_arc:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: the second block of a CIRC area must be the full circle (G02/G03 with "
                    f"I/J/K), {block.label} is {gname}",
                )
        else:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: a CIRC area is a start point and one full circle; "
                f"{block.label} is one block too many",
            )
        p.contour.append(_Contour(segment, block, modal.plane, modal.motion))
        return None

    # --- END: the definition -----------------------------------------------------------------
    def _end(self, block: Block, modal: ModalState) -> DecodeError | Callable[[], None]:
        p = self.pending
        self.pending = None
        if p is None:
            return DecodeError(ALARM_DEFINITION, "#CONTROL AREA END without a definition in progress")
        result = self._build(p, block, modal)
        if isinstance(result, DecodeError):
            return result
        definition = result

        def define(table: AreaTable) -> None:
            table.apply(definition.area_id, AreaEvent.DEFINE, definition)

        return self._commit(define)

    def _axes_of(self, p: _Pending) -> tuple[str, str, str] | DecodeError:
        """The base plane and height axes of a definition (C14-06, C14-07, C14-17)."""
        area = f"area {p.begin.area_id}"
        main = self.channel.config.main_axes
        plane = p.contour[0].plane
        i, j = _PLANE_AXES[plane]
        base = (main[i], main[j])
        third = main[3 - i - j]
        used: list[str] = []
        for c in p.contour:
            for name, _ in c.block.axes:
                if name not in used:
                    used.append(name)
        if all(n in main for n in used):
            wrong = [n for n in used if n not in base]
            if wrong:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: the contour names {', '.join(wrong)}, which is not an axis of the base plane "
                    f"{base[0]}/{base[1]} ({_PLANE_NAMES[plane]}); the height is set by MIN_EXCUR/MAX_EXCUR",
                )
            a, b = base
            height = p.height_axis or third
        else:
            mixed = [n for n in used if n in main]
            if mixed:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: the contour mixes main axes ({', '.join(mixed)}) and additional axes "
                    f"({', '.join(n for n in used if n not in main)})",
                )
            if p.begin.shape == AreaShape.CIRC:
                return DecodeError(
                    ALARM_NOT_SUPPORTED,
                    f"{area}: areas on additional axes ({', '.join(used)}) must be POLY (C14-17); "
                    "CIRC is for the main axes",
                )
            if len(used) != 2:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: an area on additional axes takes exactly two axes in its contour, "
                    f"got {', '.join(used)}",
                )
            first_named = {n for n, _ in p.contour[0].block.axes}
            if set(used) - first_named:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: the start point ({p.contour[0].block.label}) must name both axes "
                    f"{used[0]} and {used[1]}",
                )
            letters = [n.rstrip("0123456789") for n in used]
            suffixes = {n[len(letter) :] for n, letter in zip(used, letters, strict=True)}
            a, b = used[0], used[1]
            in_main_order = letters == [base[0], base[1]] or not all(n in main for n in letters)
            if letters == [base[1], base[0]] or (
                not in_main_order and main.index(letters[0]) > main.index(letters[1])
            ):
                a, b = b, a
            if p.height_axis is not None:
                height = p.height_axis
            else:
                rest = [m for m in main if m not in letters]
                candidate = rest[0] + next(iter(suffixes)) if len(rest) == 1 and len(suffixes) == 1 else ""
                if candidate not in self.names:
                    return DecodeError(
                        ALARM_DEFINITION,
                        f"{area}: no height axis for an area on {a}/{b}: name it with EXCUR_AX=.. "
                        f"(channel axes {', '.join(self.names)})",
                    )
                height = candidate
        if height in (a, b):
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: the height axis {height} (EXCUR_AX/EXCUR_AXNR) is an axis of the base plane "
                f"{a}/{b}",
            )
        return a, b, height

    def _build(self, p: _Pending, end_block: Block, modal: ModalState) -> AreaDefinition | DecodeError:
        begin = p.begin
        area = f"area {begin.area_id}"
        if not p.contour:
            return DecodeError(ALARM_DEFINITION, f"{area}: the definition has no contour blocks")
        axes = self._axes_of(p)
        if isinstance(axes, DecodeError):
            return axes
        a, b, c = (self.names.index(n) for n in axes)
        lo = begin.min_excur + modal.offset(axes[2])
        hi = begin.max_excur + modal.offset(axes[2])
        first, last = p.contour[0].block, p.contour[-1].block
        source = f"{first.label}..{last.label} (lines {first.line}..{last.line})"
        if begin.shape == AreaShape.CIRC:
            if len(p.contour) != 2:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: a CIRC area needs a start point (G01) and one full circle (G02/G03), "
                    f"got {len(p.contour)} motion block(s)",
                )
            arc = p.contour[1].segment
            assert isinstance(arc, ArcSegment)
            if set(arc.plane) != {a, b}:
                return DecodeError(
                    ALARM_DEFINITION, f"{area}: the circle is not in the base plane {axes[0]}/{axes[1]}"
                )
            start2 = (arc.start[a], arc.start[b])
            end2 = (arc.end[a], arc.end[b])
            if abs(abs(arc.sweep) - 2.0 * math.pi) > 1e-9 or math.dist(start2, end2) > CLOSE_TOLERANCE:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: CIRC needs one full circle, {p.contour[1].block.label} ends at {_fmt2(end2)}, "
                    f"not at its start point {_fmt2(start2)}",
                )
            centre = (arc.centre[0], arc.centre[1]) if arc.plane == (a, b) else (arc.centre[1], arc.centre[0])
            far = _beyond_limit(
                [
                    (
                        f"circle extent {_fmt2((centre[0] - arc.radius, centre[1] - arc.radius))}",
                        centre[0] - arc.radius,
                        centre[1] - arc.radius,
                    ),
                    (
                        f"circle extent {_fmt2((centre[0] + arc.radius, centre[1] + arc.radius))}",
                        centre[0] + arc.radius,
                        centre[1] + arc.radius,
                    ),
                ],
                lo,
                hi,
            )
            if far is not None:
                return DecodeError(ALARM_DEFINITION, f"{area}: {far}")
            return AreaDefinition(
                begin.area_id,
                begin.kind,
                begin.shape,
                axes,
                (a, b, c),
                lo,
                hi,
                centre=centre,
                radius=arc.radius,
                source=source,
            )
        pts = [(cb.segment.end[a], cb.segment.end[b]) for cb in p.contour]
        far = _beyond_limit(
            [
                (f"corner {_fmt2(pt)} ({cb.block.label})", pt[0], pt[1])
                for pt, cb in zip(pts, p.contour, strict=True)
            ],
            lo,
            hi,
        )
        if far is not None:
            return DecodeError(ALARM_DEFINITION, f"{area}: {far}")
        if math.dist(pts[0], pts[-1]) > CLOSE_TOLERANCE:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: polygon not closed: first point {_fmt2(pts[0])}, last point {_fmt2(pts[-1])} "
                f"({first.label} and {last.label} must end at the same point)",
            )
        corners: list[tuple[float, float]] = []
        labels: list[str] = []
        for pt, cb in zip(pts[:-1], p.contour[:-1], strict=True):
            if not corners or math.dist(corners[-1], pt) > CLOSE_TOLERANCE:
                corners.append(pt)
                labels.append(cb.block.label)
        if len(corners) < 3:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: a polygon needs at least three different corners, got {len(corners)}",
            )
        crossing = polygon_self_intersection(corners)
        if crossing is not None:
            k, m, meet = crossing
            n = len(corners)

            def edge(e: int) -> str:
                return f"{labels[e]}->{labels[(e + 1) % n]} {_fmt2(corners[e])}-{_fmt2(corners[(e + 1) % n])}"

            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: the polygon intersects itself: edge {edge(k)} meets edge {edge(m)} "
                f"at {_fmt2(meet)}",
            )
        twice_area = sum(
            corners[k][0] * corners[(k + 1) % len(corners)][1]
            - corners[(k + 1) % len(corners)][0] * corners[k][1]
            for k in range(len(corners))
        )
        if abs(twice_area) <= 1e-12:
            return DecodeError(ALARM_DEFINITION, f"{area}: the polygon has no area")
        return AreaDefinition(
            begin.area_id,
            begin.kind,
            begin.shape,
            axes,
            (a, b, c),
            lo,
            hi,
            points=tuple(corners),
            source=source,
        )

    # --- ON / OFF / CLEAR ----------------------------------------------------------------------
    def _unknown(self, name: str, area_id: int) -> DecodeError:
        defined = _ids(sorted(self.planned.definitions)) or "none"
        return DecodeError(
            ALARM_COMMAND,
            f"#CONTROL AREA {name} [ID={area_id}]: area {area_id} is not defined (defined: {defined})",
        )

    def _on(self, cmd: AreaOn, position: Point) -> DecodeError | Callable[[], None] | None:
        t = self.planned
        if cmd.all_ or cmd.area_id is None:
            ids = sorted(t.definitions)
            shown = "ON ALL"
        else:
            if cmd.area_id not in t.definitions:
                return self._unknown("ON", cmd.area_id)
            ids = [cmd.area_id]
            shown = f"ON [ID={cmd.area_id}]"
        new = [i for i in ids if t.state(i) != AreaState.ACTIVE]
        if not new:
            return None
        for group in t.groups_with(new):
            prism = group.verdict(position)
            if prism is not None:
                where = _fmt(self.names, position, (prism.a, prism.b, prism.c))
                if prism.protection:
                    return DecodeError(
                        ALARM_POINT_IN_PROTECTION,
                        f"#CONTROL AREA {shown} refused: the TCP {where} is in or on protection area "
                        f"{prism.area_id}; move out of it before activating (C14-11)",
                        {"position": list(position), "area": prism.area_id},
                    )
                works = _ids(sorted(w.area_id for w in group.works))
                return DecodeError(
                    ALARM_POINT_OUTSIDE_WORK,
                    f"#CONTROL AREA {shown} refused: the TCP {where} is outside the work area(s) {works}; "
                    "move into a work area before activating it (C14-11)",
                    {"position": list(position), "area": prism.area_id},
                )

        def on(table: AreaTable) -> None:
            for i in ids:
                if i in table.definitions:
                    table.apply(i, AreaEvent.ON)

        return self._commit(on)

    def _off(self, cmd: AreaOff) -> DecodeError | Callable[[], None] | None:
        t = self.planned
        if cmd.all_:
            ids = t.active_ids
        elif cmd.area_id is not None:
            if cmd.area_id not in t.definitions:
                return self._unknown("OFF", cmd.area_id)
            ids = [cmd.area_id]
        else:
            last = t.last_activated()
            ids = [last] if last is not None else []
        if not any(t.state(i) == AreaState.ACTIVE for i in ids):
            return None

        def off(table: AreaTable) -> None:
            for i in ids:
                if i in table.definitions:
                    table.apply(i, AreaEvent.OFF)

        return self._commit(off)

    def _clear(self, cmd: AreaClear) -> DecodeError | Callable[[], None] | None:
        t = self.planned
        if cmd.all_ or cmd.area_id is None:
            ids = sorted(t.definitions)
        else:
            if cmd.area_id not in t.definitions:
                return self._unknown("CLEAR", cmd.area_id)
            ids = [cmd.area_id]
        active = [i for i in ids if t.state(i) == AreaState.ACTIVE]
        if not ids:
            return None

        def clear(table: AreaTable) -> None:
            for i in ids:
                if i in table.definitions:
                    table.apply(i, AreaEvent.CLEAR)

        warning = None
        if active:
            warning = (
                f"#CONTROL AREA CLEAR: area(s) {_ids(active)} active and not cleared; "
                f"deactivate first (#CONTROL AREA OFF [ID={active[0]}])"
            )
        return self._commit(clear, warning)

    def _commit(self, op: Callable[[AreaTable], None], warning: str | None = None) -> Callable[[], None]:
        """Apply ``op`` to the planned table now and return the action that applies it to the
        effective table when the path gets there."""
        op(self.planned)

        def run() -> None:
            op(self.effective)
            if warning is not None:
                self.machine.raise_alarm(ALARM_ACTIVE_CLEAR, self.channel, warning, **self._where())
            self.emit_table()

        return run

    def emit_table(self) -> None:
        """Tell the listeners the effective area table (it changed)."""
        m = self.machine
        m.emit(
            AreasChanged(
                cycle=m.cycle,
                time_s=m.cycle * m.t_a,
                channel=self.channel.number,
                areas=tuple(self.effective.to_json()),
            )
        )

    def _where(self) -> dict[str, Any]:
        block = self.channel.current_block
        return {"line": block.line, "block": block.label} if block is not None else {}

    # --- path check (C14-15) ---------------------------------------------------------------
    def path_check(self, segment: Segment, block: Block) -> DecodeError | None:
        groups = self.planned.groups()
        if not groups:
            return None
        hit = first_violation(groups, segment)
        if hit is None:
            return None
        return self._path_error(hit, segment, block)

    def _path_error(self, hit: Hit, segment: Segment, block: Block) -> DecodeError:
        prism = hit.prism
        ks = (prism.a, prism.b, prism.c)
        names = self.names
        params: dict[str, Any] = {
            "axes": list(names),
            "start": list(segment.start),
            "end": list(segment.end),
            "intersection": list(hit.point),
            "area": prism.area_id,
            "kind": "PROT" if prism.protection else "WORK",
        }
        if isinstance(segment, ArcSegment):
            # start and end alone do not say where an arc goes; the picture of the refused block needs it
            i, j = segment.plane
            params["arc"] = {
                "plane": [names[i], names[j]],
                "centre": list(segment.centre),
                "sweep_deg": math.degrees(segment.sweep),
            }
        span = f"{block.label} from {_fmt(names, segment.start, ks)} to {_fmt(names, segment.end, ks)}"
        if hit.point_violation and hit.f == 0.0:
            if prism.protection:
                return DecodeError(
                    ALARM_POINT_IN_PROTECTION,
                    f"start point {_fmt(names, segment.start, ks)} of {block.label} is in or on protection "
                    f"area {prism.area_id}; the block was not started",
                    params,
                )
            works = _ids(self._work_ids(prism))
            return DecodeError(
                ALARM_POINT_OUTSIDE_WORK,
                f"start point {_fmt(names, segment.start, ks)} of {block.label} is outside the work area(s) "
                f"{works}; the block was not started",
                params,
            )
        at = _fmt(names, hit.point, ks)
        if prism.protection:
            return DecodeError(
                ALARM_PATH_ENTERS_PROTECTION,
                f"path {span} touches protection area {prism.area_id} at {at}; the block was not started",
                params,
            )
        return DecodeError(
            ALARM_PATH_LEAVES_WORK,
            f"path {span} leaves the work area(s) {_ids(self._work_ids(prism))} at {at}; "
            "the block was not started",
            params,
        )

    def _work_ids(self, prism: Any) -> list[int]:
        for group in self.planned.groups():
            if prism in group.works:
                return sorted(w.area_id for w in group.works)
        return [prism.area_id]

    # --- G100 (C14-23) -------------------------------------------------------------------------
    def measuring_move(
        self, segment: LineSegment, block: Block, modal: ModalState
    ) -> DecodeError | MeasuringMove:
        length = segment.length
        limited = False
        reason = ""
        if self.channel.config.meas_soft_limit_move_path:
            f_limit = 1.0
            for k, axis in enumerate(self.channel.axes):
                s0, s1 = segment.start[k], segment.end[k]
                if s1 > axis.swe_pos + EPS and s1 > s0:
                    f = max(0.0, (axis.swe_pos - s0) / (s1 - s0))
                    if f < f_limit:
                        f_limit, reason = f, f"the software limit of {axis.name} ({_num(axis.swe_pos)} mm)"
                elif s1 < axis.swe_neg - EPS and s1 < s0:
                    f = max(0.0, (axis.swe_neg - s0) / (s1 - s0))
                    if f < f_limit:
                        f_limit, reason = f, f"the software limit of {axis.name} ({_num(axis.swe_neg)} mm)"
            groups = self.planned.groups()
            hit = first_violation(groups, segment) if groups else None
            if hit is not None and not (hit.point_violation and hit.f == 0.0):
                f = hit.f
                if hit.prism.protection:
                    f = max(0.0, f - PROTECTION_MARGIN / length)
                kind = "protection" if hit.prism.protection else "work"
                if f < f_limit:
                    f_limit, reason = f, f"{kind} area {hit.prism.area_id}"
            if f_limit < 1.0:
                limited = True
                if f_limit * length <= EPS:
                    return DecodeError(
                        ALARM_MEASURE_LIMIT,
                        f"G100 {block.label}: the measuring move cannot start, it is already at {reason}",
                        {"position": list(segment.start)},
                    )
                segment = LineSegment(segment.start, point_at(segment, f_limit))
        tag = _Measuring(block, limited, reason)

        def done() -> None:
            self._measure_done(tag)

        return MeasuringMove(segment, done, tag)

    def _measure_done(self, tag: _Measuring) -> None:
        ch = self.channel
        line, label = tag.block.line, tag.block.label
        if tag.triggered:
            ch.decoder.resume(ch.setpoints())
            return
        pos = _fmt(self.names, tuple(ch.setpoints()))
        if tag.limited:
            self.machine.raise_alarm(
                ALARM_MEASURE_LIMIT,
                ch,
                f"G100 {tag.block.label}: no probe signal before {tag.limit_reason}; stopped at {pos} "
                "(P-CHAN-00268 = 1)",
                params={"position": ch.setpoints()},
                line=line,
                block=label,
            )
        else:
            self.machine.raise_alarm(
                ALARM_NO_PROBE,
                ch,
                f"G100 {tag.block.label}: the measuring move reached its target {pos} without a probe signal",
                params={"position": ch.setpoints()},
                line=line,
                block=label,
            )

    def probe_cycle(self) -> None:
        """Before interpolation: a rising edge of the probe during a measuring move ends it (C14-23)."""
        ch = self.channel
        level = ch.hli.mc_command.probe_w or self._probe_request
        edge = level and not self._probe_prev
        self._probe_prev = level
        if not edge:
            return
        head = ch.planner.current()
        if not isinstance(head, Motion) or not isinstance(head.tag, _Measuring) or head.tag.triggered:
            return
        tag = head.tag
        tag.triggered = True
        self.measurement = {
            "block": tag.block.label,
            "line": tag.block.line,
            "cycle": self.machine.cycle,
            "position": {a.name: a.measured for a in ch.axes},
            "setpoint": {a.name: a.setpoint for a in ch.axes},
        }
        m = self.machine
        m.emit(
            Measurement(
                cycle=m.cycle,
                time_s=m.cycle * m.t_a,
                channel=ch.number,
                block=tag.block.label,
                line=tag.block.line,
                position={a.name: a.measured for a in ch.axes},
                setpoint={a.name: a.setpoint for a in ch.axes},
            )
        )
        # brake to a stop on the remaining path and end the move there
        planner = ch.planner
        v = planner.velocity
        s_stop = min(head.length, planner.position_in_item + v * planner.t_a + v * v / (2.0 * head.accel))
        delta = head.length - s_stop
        if delta <= 0.0:
            return
        seg = head.segment
        head.segment = LineSegment(seg.start, seg.point_at(s_stop))
        head.length = s_stop
        planner.s_queued_end -= delta
        for item in list(planner.queue)[1:]:
            item.s_start -= delta
            if not isinstance(item, Marker):
                break

    # --- manual mode (C14-19..C14-22) --------------------------------------------------------
    def manual_monitoring(self) -> bool:
        """Is the area monitoring effective in manual mode now (P-CHAN-00442, control unit)?"""
        if self._manual_mode_setting == 1:
            return False
        return not self.channel.hli.bahn_mc_control.suppress_area_mon_manual_mode.state_r

    def must_brake(self, channel: Channel, current: Point, stop_point: Point) -> bool:
        """Jog guard: brake when the straight way from ``current`` to where the axes would come to
        rest leaves the allowed space (C14-19).

        Once the guard has stopped a motion it stays latched for that direction: motions that still
        push toward the boundary (positive component along the blocked direction) stay blocked, so
        the axes rest where they stopped instead of creeping up to the boundary in tiny steps; any
        other motion is checked afresh and releases the latch when it is allowed."""
        if not self.manual_monitoring():
            self._release_manual()
            return False
        groups = self.effective.groups()
        if not groups:
            self._release_manual()
            return False
        direction = tuple(b - a for a, b in zip(current, stop_point, strict=True))
        blocked = self._blocked_direction
        if blocked is not None and sum(x * y for x, y in zip(direction, blocked, strict=True)) > 0.0:
            return True
        if math.dist(current, stop_point) <= 0.0:
            prism = next((p for g in groups if (p := g.verdict(current)) is not None), None)
        else:
            hit = first_violation(groups, LineSegment(current, stop_point))
            prism = hit.prism if hit is not None else None
        if prism is None:
            self._release_manual()
            return False
        norm = math.hypot(*direction)
        self._blocked_direction = tuple(x / norm for x in direction) if norm > 0.0 else blocked
        if not self.violation_manual and self._move_limit_warning:
            # P-MANU-00014: said once the axes are at rest, with the place where they stopped
            self._stop_warning = (prism.protection, prism.area_id, (prism.a, prism.b, prism.c))
        self.violation_manual = True
        return True

    def _release_manual(self) -> None:
        self._blocked_direction = None
        self.violation_manual = False

    def mode_check(self) -> bool:
        """Entering manual mode (C14-20, P-CHAN-00442 = 0): the TCP must be in the allowed space."""
        if self._manual_mode_setting != 0 or not self.manual_monitoring():
            return True
        position = tuple(self.channel.setpoints())
        for group in self.effective.groups():
            prism = group.verdict(position)
            if prism is None:
                continue
            where = _fmt(self.names, position, (prism.a, prism.b, prism.c))
            if prism.protection:
                self.machine.raise_alarm(
                    ALARM_MANUAL_IN_PROTECTION,
                    self.channel,
                    f"manual mode refused: the TCP {where} is in or on protection area {prism.area_id} "
                    "(P-CHAN-00442 = 0)",
                    params={"position": list(position), "area": prism.area_id},
                )
            else:
                self.machine.raise_alarm(
                    ALARM_MANUAL_OUTSIDE_WORK,
                    self.channel,
                    f"manual mode refused: the TCP {where} is outside the work area(s) "
                    f"{_ids(sorted(w.area_id for w in group.works))} (P-CHAN-00442 = 0)",
                    params={"position": list(position), "area": prism.area_id},
                )
            return False
        return True

    def allowed(self, point: Point) -> bool:
        """Is ``point`` in the allowed space of the effective table (tests, API)?"""
        return all(g.verdict(point) is None for g in self.effective.groups())

    def groups(self, planned: bool = False) -> list[Group]:
        return (self.planned if planned else self.effective).groups()

    # --- reset and cycle -----------------------------------------------------------------------
    def reset(self) -> None:
        """C14-10: reset deactivates every area; the definitions stay."""
        for table in (self.effective, self.planned):
            for area_id in list(table.states):
                table.apply(area_id, AreaEvent.RESET)
        self.sync_planned()
        self.violation_auto = False
        self._release_manual()
        self.emit_table()

    def before_cycle(self) -> None:
        ch = self.channel
        blocks = ch.decoder.blocks
        if blocks is not self._blocks_seen:
            self._blocks_seen = blocks
            self.sync_planned()
        if ch.mode == Mode.AUTOMATIC:
            self.probe_cycle()
        else:
            self._probe_prev = ch.hli.mc_command.probe_w or self._probe_request

    def after_cycle(self) -> None:
        ch = self.channel
        if self.pending is not None and ch.state == ProgramState.FINISHED:
            begin = self.pending.block
            area_id = self.pending.begin.area_id
            self.pending = None
            self.machine.raise_alarm(
                ALARM_DEFINITION,
                ch,
                f"program ended inside the definition of area {area_id} begun at {begin.label}: "
                "#CONTROL AREA END missing; the area was not defined",
                line=begin.line,
                block=begin.label,
            )
        if self._stop_warning is not None and not any(ch.jog_velocity):
            protection, area_id, ks = self._stop_warning
            self._stop_warning = None
            what = f"{'protection' if protection else 'work'} area {area_id}"
            self.machine.raise_alarm(
                ALARM_MANUAL_STOP,
                ch,
                f"manual motion stopped before {what} at {_fmt(self.names, tuple(ch.setpoints()), ks)} "
                "(P-MANU-00014)",
            )
        ch.hli.bahn_state.area_mon_violation_detected_r = self.violation_auto or (
            ch.mode == Mode.MANUAL and self.violation_manual
        )


class AreaMonitor(Monitor):
    """FCT-C14 for every channel of the machine."""

    def __init__(self, machine: MachineView) -> None:
        self.machine = machine
        self.channels: dict[int, ChannelAreas] = {
            ch.number: ChannelAreas(machine, ch) for ch in machine.channels
        }

    def channel_hooks(self, channel: Channel) -> ChannelHooks:
        handler = self.channels[channel.number]
        return ChannelHooks(
            path_check=handler.path_check,
            jog_guard=handler,
            area_handler=handler,
            measure_handler=handler,
        )

    def handler(self, channel_number: int) -> ChannelAreas:
        return self.channels[channel_number]

    def areas_json(self, channel: Channel) -> list[dict[str, Any]]:
        """The channel's area table (effective states) as ``check`` lists it: ``[{"id", "kind",
        "shape", "state", "points" | "center"/"radius", "min", "max", "axes", "height_axis"}]``."""
        return self.channels[channel.number].effective.to_json()

    def on_alarm(self, alarm: Alarm) -> None:
        """C14-22: a violation alarm sets ``area_mon_violation_detected_r`` until the reset; it is
        also told as an :class:`~schemas.events.AreaViolation` with its block and points."""
        if alarm.number not in VIOLATION_ALARMS or not alarm.channel:
            return
        self.channels[alarm.channel].violation_auto = True
        p = alarm.params

        def point(key: str) -> tuple[int, ...] | None:
            value = p.get(key)
            return tuple(increments_from_mm(v) for v in value) if isinstance(value, list | tuple) else None

        m = self.machine
        axes = p.get("axes")
        m.emit(
            AreaViolation(
                cycle=m.cycle,
                time_s=m.cycle * m.t_a,
                channel=alarm.channel,
                alarm=alarm.number,
                area=p.get("area"),
                area_kind=p.get("kind"),
                line=alarm.line,
                block=alarm.block,
                axes=tuple(axes) if isinstance(axes, list) else tuple(self.channels[alarm.channel].names),
                start=point("start"),
                end=point("end"),
                point=point("intersection") or point("position"),
            )
        )

    def before_interpolation(self) -> None:
        for handler in self.channels.values():
            handler.before_cycle()

    def after_interpolation(self) -> None:
        for handler in self.channels.values():
            handler.after_cycle()

    def on_reset(self, channel: Channel) -> None:
        self.channels[channel.number].reset()

    def allow_mode_change(self, channel: Channel, mode: Mode) -> bool:
        handler = self.channels[channel.number]
        if mode == Mode.MANUAL:
            return handler.mode_check()
        handler._release_manual()
        return True


def channel_areas(machine: MachineView, channel: int = 1) -> ChannelAreas:
    """The area monitoring of one channel (by its number): ``channel_areas(m, 1).to_json()``."""
    return machine.monitor(AreaMonitor).handler(channel)
