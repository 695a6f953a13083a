"""The monitoring functions a machine gets by default, in the order they run each cycle."""

from __future__ import annotations

from hli_server.engine.areas.monitor import AreaMonitor
from hli_server.engine.monitors.base import MonitorFactory
from hli_server.engine.monitors.collision import CollisionMonitor
from hli_server.engine.monitors.dyn_pos_limit import DynPosLimits
from hli_server.engine.monitors.position import PositionMonitor
from hli_server.engine.monitors.soft_limits import SoftLimits

__all__ = ["DEFAULT_MONITORS"]

DEFAULT_MONITORS: tuple[MonitorFactory, ...] = (
    SoftLimits,  # E-06
    AreaMonitor,  # FCT-C14
    DynPosLimits,  # FCT-C43
    CollisionMonitor,  # FCT-C3
    PositionMonitor,  # FCT-A3
)
"""Soft limits first (a block beyond them is refused before the areas look at it), then the areas,
the dynamic limits (before interpolation: they steer the path), collision and position monitoring."""
