"""Axis collision monitoring (FCT-C3): pairs of slides on one rail must keep a minimum distance.

Configuration (C3-04, FCT-C3 sections 2 and 4): bit 0x8000 of P-AXIS-00015 ``kenngr.achs_mode`` on
both axes; on the master axis P-AXIS-00043 ``coll_check_ax_nr`` (the partner's logical number) and
P-AXIS-00045 ``coll_offset`` (minimum distance, 0.1 µm). The older form, both axes naming each
other, is accepted; where their two coll_offset values differ the larger applies and warning 70162
is raised once at machine start. Several pairs, also chains (X1-X2, X2-X3), are independent (C3-03).

Distance (C3-09, FCT-C3 Abb. 4 and 6), in the master axis' coordinates::

    x_M   = setpoint of the master axis
    x_P^M = coll_zero_position_offset + sigma * setpoint of the partner     (sigma = -1 if
                                                                             coll_moving_dir_inverted)
    d     = |x_M - x_P^M|

P-AXIS-00262 and P-AXIS-00263 are read from the master axis (the axis that names the partner; in
the older two-sided form the axis listed first in the configuration).

Each cycle (C3-01, C3-08), after the setpoints of the cycle are computed and before they reach the
drives, for every pair whose two axes are referenced (C3-06)::

    v_t     = (setpoint_n - setpoint_n-1) / T_A                  per axis
    s_brake = v_t^2 / (2 a_coll)                                 a_coll = a_max, or a_emergency
              (+ |v_t| * t_r / 2 with a jerk-limited profile,   with P-AXIS-00267 (C3-07)
               M-05: the stop builds a_coll up over t_r)
    stop if d - s_brake(master, if it moves toward the partner)
              - s_brake(partner, if it moves toward the master) < coll_offset

An axis that moves away from its partner cannot reduce the distance while it brakes, so its braking
distance is not subtracted (otherwise two slides travelling side by side at speed, or a pair moving
apart after a collision stop, would trip). On a trip the setpoints of this cycle are not given to
the drives: both axes brake, each on its own ramp with its a_coll, from the setpoints and velocities
of the previous cycle, which passed the check - so the pair comes to rest no closer than
coll_offset (C3-01; the stop generally leaves the programmed contour). The other axes of the
channel(s) brake on their own with a_emergency, the programs are aborted, and P-ERR-70092 is raised
in the channel of each axis, with the block that was running.

After reset (C3-02) the pair is latched until it has been moved apart: a motion block that would
bring it closer than the distance at which it came to rest is refused before it starts (913000),
and jogging towards each other brakes at once. The latch ends when the pair is at rest farther apart
than that distance.

P-AXIS-00044 ``coll_decelerate_chan`` (C3-05): when the axes of a pair are in different channels
and one reports a drive error, the other channel is stopped too (911030 there).

The CNC objects of FCT-C3 4.3 (C3-10) are kept in ``machine.hli.axes[i].dyn_coll_mon`` every cycle;
``coll_offset`` (0x..0246, "Distanz zwischen Kollisionsachsen") is the minimum distance in effect, the
pair's P-AXIS-00045, not the current distance (the decision and its reasons: docs/monitors.md);
the layout table (``schemas/layout.py``, ``dyn_coll_mon.*``) is the one list of them with their ADS
addresses (port 551, index group 0x120300, offset ``(A_ID << 16) | element``), and the ADS adapter
serves them from the process image like every other signal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from hli_server.engine.channel import Channel
from hli_server.engine.decoder import DecodeError
from hli_server.engine.geometry import LineSegment, Point, Segment
from hli_server.engine.monitors.base import ChannelHooks, MachineView, Monitor
from hli_server.engine.nc.blocks import Block
from schemas.events import CollisionStop
from schemas.units import INCREMENTS_PER_MM, increments_from_mm, mm_from_increments

if TYPE_CHECKING:
    from hli_server.engine.axis import Axis

__all__ = ["CollisionMonitor", "CollisionPair", "MoveApartCheck"]

_EPS: Final = 1e-9
_ARC_SAMPLES: Final = 64
_INCREMENTS_PER_MM: Final = float(INCREMENTS_PER_MM)
"""The CNC objects' velocity and braking distance are REAL in increments (C3-10)."""


@dataclass(slots=True)
class CollisionPair:
    """One monitored pair (C3-04). Positions in mm in the master axis' coordinates."""

    master: Axis
    partner: Axis
    offset: float
    """Minimum distance [mm] (the larger coll_offset of the two axes)."""
    offset_inc: int
    zero: float
    """P-AXIS-00263 of the master [mm]: the partner's zero point in master coordinates."""
    sign: float
    """-1 with P-AXIS-00262 on the master, else +1."""
    decelerate_chan: bool
    monitoring: bool = False
    """Both axes referenced (C3-06) in the last cycle."""
    tripped: bool = False
    """Stopped by this monitor; until reset."""
    latched: bool = False
    """After reset: may only move apart (C3-02)."""
    d_ref: float = math.inf
    """Closest distance since the trip [mm]: a latched pair may not get closer than this."""
    drive_error_seen: bool = False

    @property
    def label(self) -> str:
        return f"{self.master.name}/{self.partner.name}"

    def gap(self, x_master: float, x_partner: float) -> float:
        """Signed distance in master coordinates; |gap| is the distance d."""
        return x_master - (self.zero + self.sign * x_partner)


class CollisionMonitor(Monitor):
    """FCT-C3 (C3-01..C3-10) for every configured pair."""

    def __init__(self, machine: MachineView) -> None:
        self.machine = machine
        self._t_a = machine.t_a
        """The cycle time [s], read once (a compiled module reads a protocol's attributes through the
        interpreter)."""
        self.pairs: list[CollisionPair] = []
        by_number = machine.axes_by_number
        for master_cfg, partner_cfg in machine.config.collision_pairs():
            master, partner = by_number[master_cfg.number], by_number[partner_cfg.number]
            offset_inc = max(master_cfg.coll_offset, partner_cfg.coll_offset)
            self.pairs.append(
                CollisionPair(
                    master=master,
                    partner=partner,
                    offset=mm_from_increments(offset_inc),
                    offset_inc=offset_inc,
                    zero=mm_from_increments(master_cfg.coll_zero_position_offset),
                    sign=-1.0 if master_cfg.coll_moving_dir_inverted else 1.0,
                    decelerate_chan=master_cfg.coll_decelerate_chan or partner_cfg.coll_decelerate_chan,
                )
            )
            two_sided = partner_cfg.coll_check_ax_nr == master_cfg.number
            if two_sided and master_cfg.coll_offset != partner_cfg.coll_offset:
                machine.raise_alarm(
                    70162,
                    machine.channels[master.channel],
                    f"axes {master.name}/{partner.name} name each other as collision partners (older "
                    f"configuration) with different P-AXIS-00045 coll_offset {master_cfg.coll_offset} and "
                    f"{partner_cfg.coll_offset}: the larger, {offset_inc} (0.1 µm), applies. Give both the "
                    "same value, or configure the pair on the master axis only",
                    axis=f"{master.name}/{partner.name}",
                    params={
                        "offsets": [master_cfg.coll_offset, partner_cfg.coll_offset],
                        "applied": offset_inc,
                    },
                )
        self._pairs_of: dict[int, list[CollisionPair]] = {}
        for pair in self.pairs:
            for ax in (pair.master, pair.partner):
                self._pairs_of.setdefault(ax.index, []).append(pair)
        self._a_coll: dict[int, float] = {}
        self._reported_offset: dict[int, int] = {}
        for index, pairs in self._pairs_of.items():
            axis = machine.axes[index]
            use_emergency = axis.config.coll_use_a_emergency or any(
                p.master.config.coll_use_a_emergency for p in pairs
            )
            self._a_coll[index] = axis.a_emergency if use_emergency else axis.a_max
            own = [p for p in pairs if p.master is axis]
            self._reported_offset[index] = (own or pairs)[0].offset_inc
        self._last_step: dict[int, float] = dict.fromkeys(self._pairs_of, 0.0)
        self._rows = [
            (
                machine.axes[index],
                machine.hli.axes[index].dyn_coll_mon,
                self._a_coll[index],
                self._reported_offset[index],
                tuple((p.master, p.partner) for p in pairs),
            )
            for index, pairs in self._pairs_of.items()
        ]
        self._publish()

    def channel_hooks(self, channel: Channel) -> ChannelHooks:
        if any(channel.index in (p.master.channel, p.partner.channel) for p in self.pairs):
            return ChannelHooks(path_check=MoveApartCheck(self, channel), jog_guard=_MoveApartGuard(self))
        return ChannelHooks()

    def a_coll(self, axis: Axis) -> float:
        """C3-07: the deceleration for braking distance and stop of ``axis``."""
        return self._a_coll[axis.index]

    # --- the cycle -----------------------------------------------------------------------
    def after_interpolation(self) -> None:
        t = self._t_a
        for pair in self.pairs:
            self._drive_errors(pair)
            m, p = pair.master, pair.partner
            active = m.referenced and p.referenced
            newly_active = active and not pair.monitoring
            pair.monitoring = active
            if not active:
                continue
            g = pair.gap(m.setpoint, p.setpoint)
            d = abs(g)
            if pair.tripped or pair.latched:
                pair.d_ref = min(pair.d_ref, d)
                if pair.latched and _at_rest(m) and _at_rest(p) and d > pair.d_ref + 1e-6:
                    pair.latched = False  # moved apart (C3-02)
            if pair.tripped:
                continue
            v_m = m.setpoint_step / t
            v_p = p.setpoint_step / t
            direction = 1.0 if g >= 0.0 else -1.0
            toward_m = direction * v_m < 0.0
            toward_p = direction * pair.sign * v_p > 0.0
            brake = (m.stop_distance(v_m, self.a_coll(m)) if toward_m else 0.0) + (
                p.stop_distance(v_p, self.a_coll(p)) if toward_p else 0.0
            )
            if d - brake < pair.offset - _EPS and (toward_m or toward_p or newly_active):
                self._trip(pair, d, brake)
        self._publish()  # also keeps this cycle's setpoint steps for the next cycle's trip

    def on_reset(self, channel: Channel) -> None:
        for pair in self.pairs:
            if pair.tripped and channel.index in (pair.master.channel, pair.partner.channel):
                pair.tripped = False
                pair.latched = True

    # --- pieces --------------------------------------------------------------------------
    def _trip(self, pair: CollisionPair, d: float, brake: float) -> None:
        """C3-01: both axes brake on their own from the last checked setpoints; 70092."""
        machine = self.machine
        t = machine.t_a
        pair.tripped = True
        pair.latched = False
        for axis in (pair.master, pair.partner):
            a_coll = self.a_coll(axis)
            if axis.stopping:
                axis.start_independent_stop(a_coll, t)
                continue
            # this cycle's setpoint is withheld: brake from the previous cycle's state
            axis.setpoint = axis.prev_setpoint
            axis.stopping = True
            axis.stop_velocity = self._last_step[axis.index] / t
            axis.stop_deceleration = a_coll
            axis.stop_elapsed = 0.0
            axis.advance_independent_stop(t)
        channels = sorted({pair.master.channel, pair.partner.channel})
        for index in channels:
            ch = machine.channels[index]
            for axis in ch.axes:
                if not axis.stopping:
                    axis.start_independent_stop(axis.a_emergency, t)
        # where the pair is now (after withholding this cycle's setpoints); the closest it gets
        # while braking is tracked each cycle
        pair.d_ref = abs(pair.gap(pair.master.setpoint, pair.partner.setpoint))
        for index in channels:
            ch = machine.channels[index]
            block = ch.current_block
            machine.raise_alarm(
                70092,
                ch,
                f"axes {pair.label}: distance {d:.4f} mm less braking distance {brake:.4f} mm is below the "
                f"minimum distance {pair.offset:.4f} mm (P-AXIS-00045): both axes stopped. Reset, then move "
                "the axes apart",
                line=block.line if block is not None else None,
                block=block.label if block is not None else None,
                axis=pair.label,
                params={
                    "master": pair.master.name,
                    "partner": pair.partner.name,
                    "distance": increments_from_mm(d),
                    "brake_dist": increments_from_mm(brake),
                    "coll_offset": pair.offset_inc,
                },
            )
        machine.emit(
            CollisionStop(
                cycle=machine.cycle,
                time_s=machine.time,
                channel=machine.channels[pair.master.channel].number,
                master=pair.master.name,
                partner=pair.partner.name,
                distance=increments_from_mm(d),
                brake_dist=increments_from_mm(brake),
                coll_offset=pair.offset_inc,
            )
        )

    def _drive_errors(self, pair: CollisionPair) -> None:
        """C3-05: a drive error of one axis of a two-channel pair stops the other channel too."""
        m, p = pair.master, pair.partner
        faulty = m if m.faults.drive_error else p if p.faults.drive_error else None
        if faulty is None:
            pair.drive_error_seen = False
            return
        if pair.drive_error_seen or not pair.decelerate_chan:
            return
        pair.drive_error_seen = True
        other = p if faulty is m else m
        if other.channel == faulty.channel:
            return  # the drive error stops the axis' own channel anyway
        ch = self.machine.channels[other.channel]
        self.machine.raise_alarm(
            911030,
            ch,
            f"drive error of axis {faulty.name} (channel {self.machine.channels[faulty.channel].number}), "
            f"collision partner of {other.name}: channel {ch.number} stopped (P-AXIS-00044 "
            "coll_decelerate_chan). Remove the cause, then reset both channels",
            axis=faulty.name,
            params={"axis": faulty.name, "partner": other.name},
        )
        for axis in ch.axes:
            axis.start_independent_stop(axis.a_emergency, self.machine.t_a)

    def _publish(self) -> None:
        """C3-10: the CNC objects of every collision axis."""
        t = self._t_a
        for axis, obj, a, offset, members in self._rows:
            v = (axis.setpoint - axis.prev_setpoint) / t
            obj.active = any(m.referenced and p.referenced for m, p in members)
            obj.velocity = v * _INCREMENTS_PER_MM
            obj.brake_dist = axis.stop_distance(v, a) * _INCREMENTS_PER_MM
            obj.coll_offset = offset
            obj.deceleration = a
            self._last_step[axis.index] = axis.setpoint - axis.prev_setpoint

    # --- C3-02: after reset only apart --------------------------------------------------
    def latched_pairs(self, channel: Channel) -> list[CollisionPair]:
        return [p for p in self.pairs if p.latched and channel.index in (p.master.channel, p.partner.channel)]


def _at_rest(axis: Axis) -> bool:
    return axis.setpoint_step == 0.0 and not axis.stopping


def _coordinate(channel: Channel, axis: Axis, point: Point) -> float:
    """The axis' coordinate in a path point of ``channel``, or its setpoint if it is not in it."""
    if axis.channel == channel.index:
        return point[channel.axes.index(axis)]
    return axis.setpoint


class MoveApartCheck:
    """C3-02 path check: while a pair is latched, a block may not bring it closer than it stopped."""

    def __init__(self, monitor: CollisionMonitor, channel: Channel) -> None:
        self.monitor = monitor
        self.channel = channel

    def __call__(self, segment: Segment, block: Block) -> DecodeError | None:
        for pair in self.monitor.latched_pairs(self.channel):
            closest = self._closest(pair, segment)
            if closest < pair.d_ref - 1e-6:
                return DecodeError(
                    913000,
                    f"axes {pair.label}: after the collision stop the pair may only move apart; this block "
                    f"brings it to {closest:.4f} mm, closer than {pair.d_ref:.4f} mm where it stopped "
                    f"(minimum distance {pair.offset:.4f} mm). Move the axes apart first",
                    {
                        "master": pair.master.name,
                        "partner": pair.partner.name,
                        "distance": increments_from_mm(closest),
                        "stopped_at": increments_from_mm(pair.d_ref),
                    },
                    axis=pair.label,
                )
        return None

    def _closest(self, pair: CollisionPair, segment: Segment) -> float:
        ch = self.channel

        def gap(point: Point) -> float:
            return pair.gap(_coordinate(ch, pair.master, point), _coordinate(ch, pair.partner, point))

        if isinstance(segment, LineSegment):
            g0, g1 = gap(segment.start), gap(segment.end)
            return 0.0 if g0 * g1 < 0.0 else min(abs(g0), abs(g1))
        length = segment.length
        gaps = [gap(segment.point_at(length * i / _ARC_SAMPLES)) for i in range(_ARC_SAMPLES + 1)]
        if min(gaps) < 0.0 < max(gaps):
            return 0.0
        return min(abs(g) for g in gaps)


class _MoveApartGuard:
    """C3-02 jog guard: jogging a latched pair towards each other brakes at once."""

    def __init__(self, monitor: CollisionMonitor) -> None:
        self.monitor = monitor

    def must_brake(self, channel: Channel, current: Point, stop_point: Point) -> bool:
        for pair in self.monitor.latched_pairs(channel):
            d_now = abs(
                pair.gap(
                    _coordinate(channel, pair.master, current), _coordinate(channel, pair.partner, current)
                )
            )
            d_stop = abs(
                pair.gap(
                    _coordinate(channel, pair.master, stop_point),
                    _coordinate(channel, pair.partner, stop_point),
                )
            )
            if d_stop < d_now - 1e-12 and d_stop < pair.d_ref - _EPS:
                return True
        return False
