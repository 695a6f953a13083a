"""Work and protection area monitoring, FCT-C14 (C14-01..C14-23).

* :mod:`~hli_server.engine.areas.geometry`: exact 2D/3D geometry (lines, arcs, polygons, circles,
  height band) and the first violation along a path;
* :mod:`~hli_server.engine.areas.table`: the per-channel area table and the state machine as a table;
* :mod:`~hli_server.engine.areas.monitor`: the monitor, the decoder's area handler, the path check,
  the jog guard, the mode-change check and the G100 measuring move.
"""

from hli_server.engine.areas.geometry import (
    EPS,
    INSIDE,
    ON,
    OUTSIDE,
    Circle,
    Group,
    Hit,
    Polygon,
    Prism,
    first_violation,
    point_at,
    polygon_self_intersection,
)
from hli_server.engine.areas.monitor import AreaMonitor, ChannelAreas, channel_areas
from hli_server.engine.areas.table import (
    MAX_AREAS,
    TRANSITIONS,
    AreaDefinition,
    AreaEvent,
    AreaState,
    AreaTable,
    Refusal,
)

__all__ = [
    "EPS",
    "INSIDE",
    "MAX_AREAS",
    "ON",
    "OUTSIDE",
    "TRANSITIONS",
    "AreaDefinition",
    "AreaEvent",
    "AreaMonitor",
    "AreaState",
    "AreaTable",
    "ChannelAreas",
    "Circle",
    "Group",
    "Hit",
    "Polygon",
    "Prism",
    "Refusal",
    "channel_areas",
    "first_violation",
    "point_at",
    "polygon_self_intersection",
]
