"""Monitoring functions, each a :class:`~hli_server.engine.monitors.base.Monitor` in a module of its own.

``hli_server.engine.machine.DEFAULT_MONITORS`` lists the ones a machine gets, in the order they run
(work and protection areas live in ``hli_server.engine.areas``).
"""

from hli_server.engine.monitors.base import ChannelHooks, MachineView, Monitor, MonitorFactory

__all__ = ["ChannelHooks", "MachineView", "Monitor", "MonitorFactory"]
