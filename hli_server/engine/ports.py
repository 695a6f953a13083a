"""What a channel and the monitors need of their machine: a small protocol at the bottom of the engine.

The machine (``machine.py``) builds the channels and the monitors and implements this protocol;
channels and monitors know only the protocol, so nothing below ``machine.py`` imports it and the
engine has no import cycles (checked by ``make lint``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from hli_server.engine.external import ExternalVariables
from hli_server.engine.programs import ProgramLibrary
from schemas.events import Alarm, Event
from schemas.wire import Mode

__all__ = ["ChannelRef", "MachinePort"]


class ChannelRef(Protocol):
    """Anything that names a channel: a :class:`~hli_server.engine.channel.Channel`."""

    @property
    def number(self) -> int: ...


class MachinePort(Protocol):
    """The machine as a channel or a monitor sees it."""

    @property
    def cycle(self) -> int: ...

    @property
    def t_a(self) -> float: ...

    @property
    def time(self) -> float:
        """Simulated time [s] of this cycle, exact to the µs (what events report)."""
        ...

    @property
    def read_program(self) -> Callable[[str], str] | None: ...

    @property
    def programs(self) -> ProgramLibrary:
        """Where ``L name`` finds global subprograms and cycles (N-02)."""
        ...

    @property
    def external(self) -> ExternalVariables:
        """The ``V.E.`` variables shared with the PLC (N-05)."""
        ...

    def cycle_library(self, channel: int) -> ProgramLibrary:
        """Where channel ``channel``'s cycle calls look after ``programs`` (its ``cycle_directories``)."""
        ...

    def probe_deviation(self, channel: int = 1) -> dict[str, float]:
        """The simulated workpiece's deviation per axis of the channel [mm] (docs/cycles.md)."""
        ...

    def raise_alarm(
        self,
        number: int,
        channel: ChannelRef | None,
        message: str,
        *,
        line: int | None = None,
        block: str | None = None,
        params: dict[str, Any] | None = None,
        axis: str | None = None,
    ) -> Alarm:
        """Raise an alarm of the table in ``channel`` and apply its reaction."""
        ...

    def emit(self, event: Event) -> None:
        """Hand an event to the listeners (runtime log, MQTT, tests)."""
        ...

    def channel_has_error(self, channel: ChannelRef) -> bool: ...

    def channel_reset(self, channel: ChannelRef) -> None:
        """The channel was reset: clear its alarms, tell the monitors (E-03)."""
        ...

    def allow_mode_change(self, channel: ChannelRef, mode: Mode) -> bool:
        """The monitors' veto of a mode change (each raises its own alarm)."""
        ...

    def referencing_changed(self, axis_index: int) -> None:
        """An axis began or finished referencing (homing)."""
        ...
