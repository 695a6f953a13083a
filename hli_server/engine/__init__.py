"""The engine: a plain, deterministic CNC model stepped by whole cycles (E-01)."""

from hli_server.engine.alarms import ALARMS, Alarm, AlarmDef, Reaction, Severity
from hli_server.engine.machine import Machine
from hli_server.engine.monitors.base import Monitor

__all__ = ["ALARMS", "Alarm", "AlarmDef", "Machine", "Monitor", "Reaction", "Severity"]
