"""What a monitoring function is, and the machine as it sees it.

A monitor declares everything it plugs into in one place, and the machine does the wiring
(``Machine(config, monitors=...)``):

* per cycle: :meth:`Monitor.before_interpolation` (look-ahead that steers the path, FCT-C43),
  :meth:`Monitor.after_interpolation` (checks of this cycle's setpoints: soft limits, areas,
  collision), :meth:`Monitor.after_position_loop` (checks of this cycle's actual positions: FCT-A3);
  the machine calls only the hooks a monitor overrides;
* per channel, :meth:`Monitor.channel_hooks` returns a :class:`ChannelHooks`: a path check run on
  every block before it is queued, a jog guard asked every cycle in manual mode, the decoder's area
  and measuring-move handlers, the planner's G60 gate;
* reactions: :meth:`Monitor.on_reset`, :meth:`Monitor.allow_mode_change` (a veto raises its own
  alarm), :meth:`Monitor.on_alarm` (every alarm raised, typed).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, TypeVar

from mypy_extensions import mypyc_attr

from hli_server.engine.channel import Channel, JogGuard
from hli_server.engine.decoder import AreaHandler, MeasureHandler, PathCheck
from hli_server.engine.planner import ExactStopGate
from hli_server.engine.ports import MachinePort
from schemas.events import Alarm
from schemas.wire import Mode

if TYPE_CHECKING:
    from hli_server.engine.axis import Axis
    from hli_server.engine.hli import MachineHli
    from schemas.config import MachineConfig

__all__ = ["ChannelHooks", "MachineView", "Monitor", "MonitorFactory"]

M = TypeVar("M", bound="Monitor")


@dataclass(frozen=True, slots=True)
class ChannelHooks:
    """What a monitor plugs into one channel (all optional)."""

    path_check: PathCheck | None = None
    jog_guard: JogGuard | None = None
    area_handler: AreaHandler | None = None
    measure_handler: MeasureHandler | None = None
    exact_stop_gate: ExactStopGate | None = None


NO_HOOKS = ChannelHooks()


class MachineView(MachinePort, Protocol):
    """The machine as a monitor sees it: its parts and the :class:`MachinePort` services."""

    @property
    def config(self) -> MachineConfig: ...

    @property
    def axes(self) -> Sequence[Axis]: ...

    @property
    def axes_by_number(self) -> dict[int, Axis]: ...

    @property
    def channels(self) -> Sequence[Channel]: ...

    @property
    def hli(self) -> MachineHli: ...

    def monitor(self, kind: type[M]) -> M:
        """Another installed monitor, by its class (LookupError if it is not installed)."""
        ...


@mypyc_attr(allow_interpreted_subclasses=True)
class Monitor:
    """A monitoring function. Subclasses override what they need; the defaults do nothing."""

    def channel_hooks(self, channel: Channel) -> ChannelHooks:
        return NO_HOOKS

    def before_interpolation(self) -> None:
        return None

    def after_interpolation(self) -> None:
        return None

    def after_position_loop(self) -> None:
        return None

    def on_reset(self, channel: Channel) -> None:
        return None

    def allow_mode_change(self, channel: Channel, mode: Mode) -> bool:
        return True

    def on_alarm(self, alarm: Alarm) -> None:
        return None


class MonitorFactory(Protocol):
    """A monitor class (or any callable) that builds the monitor for a machine."""

    def __call__(self, machine: MachineView) -> Monitor: ...
