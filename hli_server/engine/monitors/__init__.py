"""Monitoring functions, each a :class:`~hli_server.engine.machine.Monitor` in a module of its own.

``install_default_monitors`` wires every monitor into a new machine, in the order they run.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hli_server.engine.machine import Machine

__all__ = ["install_default_monitors"]


def install_default_monitors(machine: Machine) -> None:
    from hli_server.engine.areas.monitor import AreaMonitor
    from hli_server.engine.monitors.soft_limits import SoftLimits

    machine.monitors.append(SoftLimits(machine))
    machine.monitors.append(AreaMonitor(machine))
    from hli_server.engine.monitors.dyn_pos_limit import DynPosLimits

    machine.monitors.append(DynPosLimits(machine))
    from hli_server.engine.monitors.collision import CollisionMonitor

    machine.monitors.append(CollisionMonitor(machine))
    from hli_server.engine.monitors.position import PositionMonitor

    machine.monitors.append(PositionMonitor(machine))
