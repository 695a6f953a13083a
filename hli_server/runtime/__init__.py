"""The runtime: pacing the engine (stepped / real time / free), its image, its adapters (E-01, H-01).

``Runtime`` (``core.py``) ties the pieces together: ``pacing.py`` (clocks and their statistics),
``events.py`` (the event log), ``image.py`` (creating the process image), ``programs.py`` (program
files) and ``host.py`` (the door the adapters get: image, operator panel, events, step).
"""

from hli_server.adapters.host import LoggedEvent
from hli_server.runtime.core import AdapterSpec, Recording, Runtime, RuntimeHost, RuntimeStateError
from hli_server.runtime.event_log import EVENT_LOG, EventLog
from hli_server.runtime.image_factory import ImageFactory, RuntimeImage, memory_image, shared_memory_image
from hli_server.runtime.operator_panel import OperatorPanel
from hli_server.runtime.pacing import Clock, ClockError, PacingStats, precise_event_loop

__all__ = [
    "EVENT_LOG",
    "AdapterSpec",
    "Clock",
    "ClockError",
    "EventLog",
    "ImageFactory",
    "LoggedEvent",
    "OperatorPanel",
    "PacingStats",
    "Recording",
    "Runtime",
    "RuntimeHost",
    "RuntimeImage",
    "RuntimeStateError",
    "memory_image",
    "precise_event_loop",
    "shared_memory_image",
]
