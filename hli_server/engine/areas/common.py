"""What the parts of one channel's area monitoring share (FCT-C14): numbers, texts and the two tables.

The parts (each a module of this package) are :class:`~hli_server.engine.areas.definitions.AreaDefinitions`
(``#CONTROL AREA`` commands and contours), :class:`~hli_server.engine.areas.path_check.AreaPathCheck`,
:class:`~hli_server.engine.areas.measuring.MeasuringMoves` (G100) and
:class:`~hli_server.engine.areas.manual.ManualGuard` (jog guard, mode change); each sees the channel's
:class:`ChannelAreaTables` through :class:`AreaRole`. :class:`~hli_server.engine.areas.monitor.ChannelAreas`
puts them together and :class:`~hli_server.engine.areas.monitor.AreaMonitor` wires them into the machine.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from hli_server.engine.areas.geometry import Group
from hli_server.engine.areas.table import AreaTable
from hli_server.engine.geometry import Point, Segment
from hli_server.engine.monitors.base import MachineView
from hli_server.engine.nc.blocks import AreaBegin, Block
from schemas.events import AreasChanged
from schemas.units import DISTANCE_LIMIT_MM

if TYPE_CHECKING:
    from hli_server.engine.channel import Channel

__all__ = [
    "ALARM_ACTIVE_CLEAR",
    "ALARM_ACTIVE_OVERWRITE",
    "ALARM_CIRC_FIRST_NOT_LINEAR",
    "ALARM_COMMAND",
    "ALARM_DEFINITION",
    "ALARM_END_WITHOUT_BEGIN",
    "ALARM_G_IN_DEFINITION",
    "ALARM_ID_RANGE",
    "ALARM_ID_ZERO",
    "ALARM_MANUAL_IN_PROTECTION",
    "ALARM_MANUAL_OUTSIDE_WORK",
    "ALARM_MANUAL_STOP",
    "ALARM_MEASURE_LIMIT",
    "ALARM_NOT_SUPPORTED",
    "ALARM_NO_PROBE",
    "ALARM_PATH_ENTERS_PROTECTION",
    "ALARM_PATH_LEAVES_WORK",
    "ALARM_POINT_IN_PROTECTION",
    "ALARM_POINT_OUTSIDE_WORK",
    "ALARM_POLY_INTERSECTS",
    "ALARM_POLY_NOT_LINEAR",
    "ALARM_POLY_TOO_MANY",
    "ALARM_TOO_MANY_AXES",
    "AREA_ID_MAX",
    "CLOSE_TOLERANCE",
    "COORDINATE_LIMIT",
    "MAX_CONTOUR_BLOCKS",
    "PLANE_AXES",
    "PLANE_NAMES",
    "PROTECTION_MARGIN",
    "VIOLATION_ALARMS",
    "AreaRole",
    "ChannelAreaTables",
    "Contour",
    "PendingDefinition",
    "beyond_limit",
    "fids",
    "fnum",
    "fpair",
    "fpoint",
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
floats' resolution; refused as 912002 (reliability.md, round 1, finding 1)."""
ALARM_COMMAND = 912003
ALARM_MANUAL_STOP = 912004
# the kernel's IDs of #CONTROL AREA errors (its diagnosis pages; docs/alarms.md)
ALARM_ID_RANGE = 21286
"""Control area ID is out of data format (BEGIN)."""
ALARM_END_WITHOUT_BEGIN = 21288
"""Warning: ``#CONTROL AREA END`` without a definition, the command has no effect."""
ALARM_ID_ZERO = 21292
"""Invalid control area ID: the ID in BEGIN is zero."""
ALARM_G_IN_DEFINITION = 21793
"""G function during control area definition not allowed."""
ALARM_TOO_MANY_AXES = 21797
"""Too many axes in the control area definition, at most two."""
ALARM_ACTIVE_OVERWRITE = 50774
"""Area not saved: an active area cannot be overwritten."""
ALARM_POLY_NOT_LINEAR = 50785
"""Only linear motion blocks G00/G01 can define a polygonal control area."""
ALARM_POLY_TOO_MANY = 50786
"""Maximum number of points of a polygonal area exceeded."""
ALARM_POLY_INTERSECTS = 120477
"""Definition of the polygon is invalid: overlapping (its lines intersect)."""
ALARM_CIRC_FIRST_NOT_LINEAR = 120479
"""The first block of a circular area definition must be linear."""
AREA_ID_MAX = 999_999_999
"""Largest area ID (21286's page gives no figure: the NC parser's bound; docs/alarms.md)."""
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

PLANE_AXES = {17: (0, 1), 18: (2, 0), 19: (1, 2)}
PLANE_NAMES = {17: "G17", 18: "G18", 19: "G19"}


def fnum(v: float) -> str:
    text = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def fpoint(names: list[str], point: Point, indices: tuple[int, ...] | None = None) -> str:
    """``(X-150, Y75, Z0)``; names with digits take ``=``: ``(X2=100, Y2=-20, Z2=0)``."""
    ks = indices if indices is not None else range(len(point))
    parts = [
        f"{names[k]}={fnum(point[k])}" if names[k][-1].isdigit() else f"{names[k]}{fnum(point[k])}"
        for k in ks
    ]
    return "(" + ", ".join(parts) + ")"


def fpair(p: tuple[float, float]) -> str:
    return f"({fnum(p[0])}, {fnum(p[1])})"


def beyond_limit(points: list[tuple[str, float, float]], lo: float, hi: float) -> str | None:
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
            return f"{what} ({fnum(h)}) {why}"
    return None


def fids(ids: list[int]) -> str:
    return ", ".join(str(i) for i in ids)


@dataclass(slots=True)
class Contour:
    segment: Segment
    block: Block
    plane: int
    motion: int


@dataclass(slots=True)
class PendingDefinition:
    """A definition between BEGIN and END."""

    begin: AreaBegin
    block: Block
    height_axis: str | None
    contour: list[Contour] = field(default_factory=list)


class ChannelAreaTables:
    """The state one channel's area monitoring shares: the *planned* table (as it will be when the path
    reaches the block being decoded), the *effective* one (as it is now), the definition in progress,
    and the violation flags the PLC sees (C14-22)."""

    def __init__(self, machine: MachineView, channel: Channel) -> None:
        self.machine = machine
        self.channel = channel
        self.names = list(channel.axis_names)
        self.planned = AreaTable()
        self.effective = AreaTable()
        self.pending: PendingDefinition | None = None
        self.violation_auto = False
        self.violation_manual = False

    # --- public views --------------------------------------------------------------------
    def to_json(self, planned: bool = False) -> dict[str, Any]:
        """The area table as ``check`` lists it: ``{"channel", "axes", "areas": [...]}``."""
        table = self.planned if planned else self.effective
        return {"channel": self.channel.number, "axes": list(self.names), "areas": table.to_json()}

    def sync_planned(self) -> None:
        """Start of a program: the planned table is the effective one; a half definition is dropped."""
        self.planned = self.effective.copy()
        self.pending = None

    def emit_table(self) -> None:
        """Tell the listeners the effective area table (it changed)."""
        m = self.machine
        m.emit(
            AreasChanged(
                cycle=m.cycle,
                time_s=m.time,
                channel=self.channel.number,
                areas=tuple(self.effective.to_json()),
            )
        )

    def where(self) -> dict[str, Any]:
        block = self.channel.current_block
        return {"line": block.line, "block": block.label} if block is not None else {}

    def allowed(self, point: Point) -> bool:
        """Is ``point`` in the allowed space of the effective table (tests, API)?"""
        return all(g.verdict(point) is None for g in self.effective.groups())

    def groups(self, planned: bool = False) -> list[Group]:
        return (self.planned if planned else self.effective).groups()


class AreaRole:
    """A part of one channel's area monitoring: it sees the channel's :class:`ChannelAreaTables`."""

    def __init__(self, tables: ChannelAreaTables) -> None:
        self.tables = tables
        self.machine = tables.machine
        self.channel = tables.channel
        self.names = tables.names

    @property
    def planned(self) -> AreaTable:
        return self.tables.planned

    @property
    def effective(self) -> AreaTable:
        return self.tables.effective

    @property
    def pending(self) -> PendingDefinition | None:
        return self.tables.pending

    @pending.setter
    def pending(self, value: PendingDefinition | None) -> None:
        self.tables.pending = value

    @property
    def violation_manual(self) -> bool:
        return self.tables.violation_manual

    @violation_manual.setter
    def violation_manual(self, value: bool) -> None:
        self.tables.violation_manual = value

    def emit_table(self) -> None:
        self.tables.emit_table()

    def _where(self) -> dict[str, Any]:
        return self.tables.where()
