"""Software limit switches (E-06, FCT-C14 6.2: P-AXIS-00177 / P-AXIS-00178 / P-AXIS-00179).

* Programmed setpoints: every block's whole path (for arcs the extremes on the arc) is checked
  against ``kenngr.swe_neg`` / ``kenngr.swe_pos`` before the block is queued; a violating block is
  not started (911010 / 911011, program abort at its start point).
* Actual positions: every cycle against ``swe_neg - swe_toleranz`` / ``swe_pos + swe_toleranz``;
  beyond them the channel's axes stop at once (911012).
* Jog: the axes brake early enough to stop at the limit (no error; warning 911013 when
  P-MANU-00014 is set).
"""

from __future__ import annotations

from hli_server.engine.channel import Channel
from hli_server.engine.decoder import DecodeError
from hli_server.engine.geometry import Point, Segment
from hli_server.engine.monitors.base import ChannelHooks, MachineView, Monitor
from hli_server.engine.nc.blocks import Block
from schemas.units import increments_from_mm

__all__ = ["SoftLimitPathCheck", "SoftLimits"]

_EPS = 1e-9


class SoftLimits(Monitor):
    def __init__(self, machine: MachineView) -> None:
        self.machine = machine
        self._tripped: set[str] = set()
        self._warned: set[str] = set()
        self._warn = machine.config.manual.move_limit_warning

    def channel_hooks(self, channel: Channel) -> ChannelHooks:
        return ChannelHooks(path_check=SoftLimitPathCheck(channel), jog_guard=self)

    # --- jog guard -----------------------------------------------------------------------
    def must_brake(self, channel: Channel, current: Point, stop_point: Point) -> bool:
        brake = False
        for axis, p0, p1 in zip(channel.axes, current, stop_point, strict=True):
            if (p1 > axis.swe_pos and p1 > p0) or (p1 < axis.swe_neg and p1 < p0):
                brake = True
                if self._warn and axis.name not in self._warned:
                    self._warned.add(axis.name)
                    self.machine.raise_alarm(
                        911013,
                        channel,
                        f"axis {axis.name}: jog stopped at the software limit",
                        axis=axis.name,
                    )
            else:
                self._warned.discard(axis.name)
        return brake

    # --- actual positions ----------------------------------------------------------------
    def after_interpolation(self) -> None:
        machine = self.machine
        for axis in machine.axes:
            if not axis.referenced:
                continue
            pos = axis.measured
            lo, hi = axis.swe_neg - axis.swe_tol, axis.swe_pos + axis.swe_tol
            if lo - _EPS <= pos <= hi + _EPS:
                self._tripped.discard(axis.name)
                continue
            if axis.name in self._tripped:
                continue
            self._tripped.add(axis.name)
            channel = machine.channels[axis.channel]
            machine.raise_alarm(
                911012,
                channel,
                f"axis {axis.name}: actual position {pos:.4f} mm beyond the software limit "
                f"[{lo:.4f}, {hi:.4f}] mm (swe_toleranz included)",
                axis=axis.name,
                params={"axis": axis.name, "position": increments_from_mm(pos)},
            )
            for ax in channel.axes:
                ax.start_independent_stop(ax.a_emergency, machine.t_a)
            channel.abort()


class SoftLimitPathCheck:
    """The per-block check of programmed positions for one channel (the batch geometry check reads its
    channel's limits: ``hli_server/engine/batch.py``)."""

    def __init__(self, channel: Channel) -> None:
        self.channel = channel

    def __call__(self, segment: Segment, block: Block) -> DecodeError | None:
        for k, axis in enumerate(self.channel.axes):
            lo, hi = segment.axis_extent(k)
            if lo < axis.swe_neg - _EPS:
                return DecodeError(
                    911010,
                    f"axis {axis.name}: programmed path reaches {lo:.4f} mm, beyond the negative software "
                    f"limit {axis.swe_neg:.4f} mm (P-AXIS-00177)",
                    {"axis": axis.name, "position": increments_from_mm(lo), "limit": axis.config.swe_neg},
                    axis=axis.name,
                )
            if hi > axis.swe_pos + _EPS:
                return DecodeError(
                    911011,
                    f"axis {axis.name}: programmed path reaches {hi:.4f} mm, beyond the positive software "
                    f"limit {axis.swe_pos:.4f} mm (P-AXIS-00178)",
                    {"axis": axis.name, "position": increments_from_mm(hi), "limit": axis.config.swe_pos},
                    axis=axis.name,
                )
        return None
