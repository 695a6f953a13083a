"""Software limit switches (E-06, FCT-C14 6.2: P-AXIS-00177 / P-AXIS-00178 / P-AXIS-00179).

The kernel's numbers (its software limit switch description,
https://infosys.beckhoff.com/content/1033/swlimit/15311258251.html):

* Programmed setpoints: every block's whole path (for arcs the extremes on the arc) is checked
  against ``kenngr.swe_neg`` / ``kenngr.swe_pos`` before the block is queued; a violating block is
  not started ("that NC block is not executed", program abort at its start point): 120002 beyond
  the positive, 120003 beyond the negative limit. With P-CHAN-00120 ``soft_limit_tolerance`` = 1 an
  axis the block does not move is checked against the limits widened by ``swe_toleranz`` (the
  parameter page: "the tolerance is only considered if the axis is not programmed or moved").
* Actual positions: every cycle against ``swe_neg - swe_toleranz`` / ``swe_pos + swe_toleranz``;
  beyond them the channel's axes stop at once: 70021 positive, 70022 negative.
* Manual mode: the axes brake early enough to stop at the limit (no error; warning 911013 when
  P-MANU-00014 is set). In manual mode the absolute ACS limits P-AXIS-00492/00493 (both 0: off) and,
  with P-CHAN-00114, the relative offset limits P-AXIS-00137/00138 (from where manual mode was
  selected; both 0: off) narrow the range; P-MANU-00014's warning names the limit that stopped the
  axes ("falls die Handbetriebsbewegung an einer relativen Offsetgrenze (P-AXIS-00137, P-AXIS-00138)
  oder einer absoluten Offsetgrenze (P-AXIS-00492, P-AXIS-00493) stoppt", FCT-C14 6.2).

The limits in effect (``Axis.swe_neg`` / ``swe_pos``) are taken from the axis record (the
configuration, :meth:`~hli_server.engine.axis.Axis.reload_soft_limits`) at start-up, reset, mode
change and axis exchange (P-AXIS-00177/00178 "Anmerkungen"); what an NC program or the operator set
in between (:meth:`~hli_server.engine.axis.Axis.set_soft_limits`, the kernel's G98/G99) holds until
then.
"""

from __future__ import annotations

from typing import Final

from hli_server.engine.axis import Axis
from hli_server.engine.channel import Channel
from hli_server.engine.decoder import DecodeError
from hli_server.engine.geometry import Point, Segment, first_beyond, segment_params
from hli_server.engine.monitors.base import ChannelHooks, MachineView, Monitor
from hli_server.engine.nc.blocks import Block
from schemas.units import increments_from_mm, mm_from_increments
from schemas.wire import Mode

__all__ = [
    "ALARM_ACTUAL_NEGATIVE",
    "ALARM_ACTUAL_POSITIVE",
    "ALARM_MANUAL_LIMIT",
    "ALARM_PROGRAMMED_NEGATIVE",
    "ALARM_PROGRAMMED_POSITIVE",
    "SoftLimitPathCheck",
    "SoftLimits",
]

ALARM_PROGRAMMED_POSITIVE: Final = 120002
ALARM_PROGRAMMED_NEGATIVE: Final = 120003
ALARM_ACTUAL_POSITIVE: Final = 70021
ALARM_ACTUAL_NEGATIVE: Final = 70022
ALARM_MANUAL_LIMIT: Final = 911013

_EPS: Final = 1e-9
_MANUAL: Final = Mode.MANUAL


class SoftLimits(Monitor):
    def __init__(self, machine: MachineView) -> None:
        self.machine = machine
        # the machine's parts as lists of this module's types: the cycle iterates them without the
        # interpreter (a compiled module reads a protocol's attributes through it)
        self._axes: list[Axis] = list(machine.axes)
        self._channels: list[Channel] = list(machine.channels)
        self._tripped: set[str] = set()
        self._warned: dict[str, int] = {}
        """Axes whose stop at a limit P-MANU-00014 has reported: +1 above, -1 below."""
        self._warn = machine.config.manual.move_limit_warning
        # manual mode limits per axis index, read once (the cycle reads no pydantic model):
        # P-AXIS-00492/00493 absolute ACS limits, P-AXIS-00137/00138 relative offset limits [mm]
        self._acs: dict[int, tuple[float, float]] = {}
        self._offsets: dict[int, tuple[float, float]] = {}
        for axis in machine.axes:
            cfg = axis.config
            if (cfg.acs_limit_neg, cfg.acs_limit_pos) != (0, 0):
                self._acs[axis.index] = (
                    mm_from_increments(cfg.acs_limit_neg),
                    mm_from_increments(cfg.acs_limit_pos),
                )
            if (cfg.offsetgrenze_neg, cfg.offsetgrenze_pos) != (0, 0):
                self._offsets[axis.index] = (
                    mm_from_increments(cfg.offsetgrenze_neg),
                    mm_from_increments(cfg.offsetgrenze_pos),
                )
        self._with_offsets = {
            ch.index: ch.config.rel_offset_limits_std_manual_mode for ch in machine.channels
        }
        """P-CHAN-00114: the relative offset limits apply in manual mode G200 (the only one here)."""
        self._mode = {ch.index: ch.mode for ch in machine.channels}
        self._origin: dict[int, list[float]] = {
            ch.index: ch.setpoints() for ch in machine.channels if ch.mode == Mode.MANUAL
        }
        """Per channel: the axes' positions when manual mode was selected (where the offsets count from)."""

    def channel_hooks(self, channel: Channel) -> ChannelHooks:
        return ChannelHooks(path_check=SoftLimitPathCheck(channel), jog_guard=self)

    # --- manual mode ---------------------------------------------------------------------
    def before_interpolation(self) -> None:
        """Note where the axes stood when manual mode was selected (P-AXIS-00137/00138 count from there)."""
        for ch in self._channels:
            mode = ch.mode
            if mode != self._mode[ch.index]:
                self._mode[ch.index] = mode
                if mode is _MANUAL:
                    self._origin[ch.index] = ch.setpoints()

    def manual_range(self, channel: Channel, k: int) -> tuple[float, float, str, str]:
        """Where axis ``k`` of ``channel`` may go in manual mode [mm], and what limits it below and
        above: the software limits in effect, the ACS limits (P-AXIS-00492/00493, both 0: off), the
        relative offset limits (P-AXIS-00137/00138 from where manual mode was selected, with
        P-CHAN-00114; both 0: off)."""
        axis = channel.axes[k]
        lo, hi = axis.swe_neg, axis.swe_pos
        why_lo, why_hi = (
            "the negative software limit (P-AXIS-00177)",
            "the positive software limit (P-AXIS-00178)",
        )
        acs = self._acs.get(axis.index)
        if acs is not None:
            if acs[0] > lo:
                lo, why_lo = acs[0], "the negative ACS limit in manual mode (P-AXIS-00492)"
            if acs[1] < hi:
                hi, why_hi = acs[1], "the positive ACS limit in manual mode (P-AXIS-00493)"
        offsets = self._offsets.get(axis.index)
        origin = self._origin.get(channel.index)
        if offsets is not None and origin is not None and self._with_offsets[channel.index]:
            start = origin[k]
            if start + offsets[0] > lo:
                lo = start + offsets[0]
                why_lo = (
                    f"the negative offset limit (P-AXIS-00137, {-offsets[0]:g} mm from {start:g} mm, where "
                    "manual mode was selected)"
                )
            if start + offsets[1] < hi:
                hi = start + offsets[1]
                why_hi = (
                    f"the positive offset limit (P-AXIS-00138, {offsets[1]:g} mm from {start:g} mm, where "
                    "manual mode was selected)"
                )
        return lo, hi, why_lo, why_hi

    # --- jog guard -----------------------------------------------------------------------
    def must_brake(self, channel: Channel, current: Point, stop_point: Point) -> bool:
        brake = False
        for k, (axis, p0, p1) in enumerate(zip(channel.axes, current, stop_point, strict=True)):
            lo, hi, why_lo, why_hi = self.manual_range(channel, k)
            if (p1 > hi and p1 > p0) or (p1 < lo and p1 < p0):
                brake = True
                side = 1 if p1 > hi else -1
                # once per stop: the axis creeps up to the limit in the cycles after, and only a motion
                # away from it (or the next stop at the other limit) arms the warning again
                if self._warn and self._warned.get(axis.name) != side:
                    self._warned[axis.name] = side
                    why, where = (why_hi, hi) if p1 > hi else (why_lo, lo)
                    self.machine.raise_alarm(
                        ALARM_MANUAL_LIMIT,
                        channel,
                        f"axis {axis.name}: manual motion stopped at {why}, {where:.4f} mm (P-MANU-00014)",
                        axis=axis.name,
                        params={"axis": axis.name, "limit": increments_from_mm(where)},
                    )
            elif (p1 - p0) * self._warned.get(axis.name, 0) < 0.0:
                del self._warned[axis.name]
        return brake

    # --- actual positions ----------------------------------------------------------------
    def after_interpolation(self) -> None:
        machine = self.machine
        for axis in self._axes:
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
            positive = pos > hi
            limit = axis.swe_pos if positive else axis.swe_neg
            machine.raise_alarm(
                ALARM_ACTUAL_POSITIVE if positive else ALARM_ACTUAL_NEGATIVE,
                channel,
                f"axis {axis.name}: actual position {pos:.4f} mm beyond the "
                f"{'positive' if positive else 'negative'} software limit {limit:.4f} mm "
                f"{'+' if positive else '-'} swe_toleranz {axis.swe_tol:.4f} mm (P-AXIS-00179)",
                axis=axis.name,
                params={
                    "axis": axis.name,
                    "axis_number": axis.number,
                    "position": increments_from_mm(pos),
                    "limit": increments_from_mm(limit),
                },
            )
            for ax in channel.axes:
                ax.start_independent_stop(ax.a_emergency, machine.t_a)
            channel.abort()


class SoftLimitPathCheck:
    """The per-block check of programmed positions for one channel (the batch geometry check reads its
    channel's limits: ``hli_server/engine/batch.py``)."""

    def __init__(self, channel: Channel) -> None:
        self.channel = channel
        self._with_tolerance = channel.config.soft_limit_tolerance
        """P-CHAN-00120, read once (a block's check reads no pydantic model)."""

    def __call__(self, segment: Segment, block: Block) -> DecodeError | None:
        with_tolerance = self._with_tolerance
        for k, axis in enumerate(self.channel.axes):
            lo, hi = segment.axis_extent(k)
            tol = 0.0
            if with_tolerance and lo == hi and segment.start[k] == segment.end[k]:
                tol = axis.swe_tol  # P-CHAN-00120: an axis the block does not move
            if lo < axis.swe_neg - tol - _EPS:
                return self._refused(segment, k, lo, axis.swe_neg, tol, positive=False)
            if hi > axis.swe_pos + tol + _EPS:
                return self._refused(segment, k, hi, axis.swe_pos, tol, positive=True)
        return None

    def _refused(
        self, segment: Segment, k: int, reach: float, limit: float, tol: float, *, positive: bool
    ) -> DecodeError:
        """The alarm of a block whose path reaches ``reach`` beyond ``limit`` on axis ``k``: the axis and
        the numbers, and the block's path with the point where it would cross the limit (``start``,
        ``end``, ``arc``, ``intersection``), so that ``check --plot`` and the dashboard draw the refused
        block as they draw an area's (``hli_server/scene.py``)."""
        axis = self.channel.axes[k]
        side = "positive" if positive else "negative"
        crossing = first_beyond(segment, k, limit + tol if positive else limit - tol, positive)
        return DecodeError(
            ALARM_PROGRAMMED_POSITIVE if positive else ALARM_PROGRAMMED_NEGATIVE,
            f"axis {axis.name}: programmed path reaches {reach:.4f} mm, beyond the {side} software limit "
            f"{limit:.4f} mm (P-AXIS-{'00178' if positive else '00177'})" + _tolerance_note(tol),
            segment_params(
                self.channel.axis_names,
                segment,
                axis=axis.name,
                axis_number=axis.number,
                position=increments_from_mm(reach),
                limit=increments_from_mm(limit),
                intersection=list(crossing),
            ),
            axis=axis.name,
        )


def _tolerance_note(tol: float) -> str:
    return f" + swe_toleranz {tol:.4f} mm (P-CHAN-00120, the axis does not move)" if tol else ""
