"""The engine: a plain, deterministic CNC model stepped by whole cycles (E-01)."""

from hli_server.engine.alarms import ALARMS, Alarm, AlarmDef, Reaction, Severity
from hli_server.engine.machine import Event, Machine, Monitor

__all__ = ["ALARMS", "Alarm", "AlarmDef", "Event", "Machine", "Monitor", "Reaction", "Severity"]
