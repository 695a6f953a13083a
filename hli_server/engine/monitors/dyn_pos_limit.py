"""Dynamic position limits (FCT-C43): a PLC-driven, area-specific feedhold (C43-01..C43-09).

Per axis two SGN32 control units, ``gpAx[i]^ipo_mc_control.dyn_pos_limit_low`` / ``_high``
(C43-02): ``command_w`` is the limit in 0.1 µm (0.0001°), ``enable_w`` switches it on, ``state_r``
shows the state of :data:`TRANSITIONS` (C43-03); ``request_r`` is not supported and stays 0.
Effective only in channels whose P-STUP-00070 names FCT_DYN_POS_LIMIT (C43-01).

Each cycle, before the path is interpolated (FCT-C43 section 2, "Einschränkungen des Verfahrens"):

1. The braking ramp is computed anew (C43-08): from where the path will be after this cycle if
   the current acceleration holds (``v' = v + a*T_A``, at most the programmed feed), braking with the
   channel's feedhold deceleration ``a_fh`` to rest, or to the next point where the planned path
   stops anyway (reversal, G00/G60 end, marker, end of the look-ahead queue). 20 points, evenly
   spaced in time over the braking time, are looked up on the queued path (look-ahead, C43-04).
2. If one of them lies beyond an active limit, braking is due (C43-04, C43-06): the crossing of the
   limit between the last good sample and the first bad one is located on the path, and the
   planner gets a stop point there (``planner.stop_points``). Because the ramp was computed from the
   state one cycle ahead, the crossing is still at least a feedhold braking distance away when it
   is first seen, so the current acceleration holds until the braking point and the path comes to
   rest on the limit. When the crossing is too close for ``a_fh`` (the limit was switched on or
   moved within the braking distance, or the 20 samples missed it before), the stop point is where
   braking with ``a_fh`` from now ends: the limit is overrun - by at most one cycle's travel when
   only the cycle quantisation is to blame, which is the tolerance FCT-C43 gives (limit "+/- 1
   Takt", MCV_DynPosLimitLow: "um die Wegstrecke überfahren werden, die in einem Taktzyklus
   zurückgelegt wird").
3. If the axis is already beyond the limit when it becomes active (or when a new value is adopted)
   and the path moves, it stops at once with the feedhold deceleration (C43-05).
4. The stop point is kept while the limit stays as it is; at rest on it the state is
   ACTIVE_BRAKE. When the PLC lifts (``enable_w`` off) or moves the limit, the stop point is dropped
   and the look-ahead runs again with the new value: the program continues (C43-07).

A limit change is adopted only every P-CHAN-00874 ``dpl_input_cycles`` cycles and only when it
differs from the adopted value by at least P-CHAN-00751 ``dpl_tol_limit_change`` (0.1 µm; 0: any
change). The kernel's defaults (0, 0; its pages) adopt every change at once: 0 and 1 cycles both
mean every cycle.

Acceleration profiles (``#SLOPE``, M-04): with TRAPEZ, SIN2 or HSC the axes follow the planned path
through the profile's filter (:mod:`hli_server.engine.path.profiles`): they lag it and come to rest
where it comes to rest. The ramp is computed each cycle as above on the planned path, whose end is
the end of the axes' jerk-limited ramp; its reach counts from the axes' point (the lag added), and
its 20 samples lie between the axes and that end. So the path stops on the limit in every profile,
and the one-cycle tolerance holds for SIN2 as for STEP (tests/unit/test_motion_mslope_*).

Documented limitations, reproduced (C43-08, C43-09; see docs/monitors.md):

* only 20 samples of the ramp are checked: a contour element that crosses the limit and comes back
  between two samples can be missed, in particular with a long braking distance, and after the limit
  was changed while the program runs;
* manual mode is not monitored at all (jogging passes the limit); the state stays ACTIVE;
* axis polynomials and #CAXTRACK do not exist in this simulator's NC language.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, Final

from hli_server.engine.channel import Channel
from hli_server.engine.hli import ControlUnitSgn32
from hli_server.engine.monitors.base import MachineView, Monitor
from schemas.events import DynPosLimitChanged
from schemas.units import mm_from_increments
from schemas.wire import DynPosLimitState, HoldSource, Mode

if TYPE_CHECKING:
    from hli_server.engine.axis import Axis
    from hli_server.engine.planner import Planner

__all__ = [
    "RAMP_SAMPLES",
    "TRANSITIONS",
    "DplEvent",
    "DynPosLimits",
    "next_state",
]

RAMP_SAMPLES: Final = 20
"""C43-08: points of the braking ramp checked per cycle (FCT-C43 section 2)."""

_EPS: Final = 1e-9
"""mm: positions closer than this to the limit count as on it."""
_BISECT_STEPS: Final = 48


class DplEvent(StrEnum):
    ENABLE = "enable"
    """enable_w set in a channel with FCT_DYN_POS_LIMIT."""
    DISABLE = "disable"
    """enable_w cleared (or the function is not configured)."""
    ADOPTED = "adopted"
    """The commanded limit was taken over: monitoring is on."""
    VIOLATION = "violation"
    """The look-ahead found the limit on the braking ramp (or the axis beyond it): braking."""
    STANDSTILL = "standstill"
    """The path came to rest at the stop point."""
    RELEASE = "release"
    """The stop point was dropped: limit moved, path cleared (reset, program end), manual mode."""


TRANSITIONS: dict[tuple[DynPosLimitState, DplEvent], DynPosLimitState] = {
    (DynPosLimitState.INACTIVE, DplEvent.ENABLE): DynPosLimitState.ACTIVATION,
    (DynPosLimitState.INACTIVE, DplEvent.DISABLE): DynPosLimitState.INACTIVE,
    (DynPosLimitState.ACTIVATION, DplEvent.ADOPTED): DynPosLimitState.ACTIVE,
    (DynPosLimitState.ACTIVATION, DplEvent.DISABLE): DynPosLimitState.INACTIVE,
    (DynPosLimitState.ACTIVE, DplEvent.VIOLATION): DynPosLimitState.ACTIVE_BRAKING,
    (DynPosLimitState.ACTIVE, DplEvent.RELEASE): DynPosLimitState.ACTIVE,
    (DynPosLimitState.ACTIVE, DplEvent.DISABLE): DynPosLimitState.INACTIVE,
    (DynPosLimitState.ACTIVE_BRAKING, DplEvent.STANDSTILL): DynPosLimitState.ACTIVE_BRAKE,
    (DynPosLimitState.ACTIVE_BRAKING, DplEvent.RELEASE): DynPosLimitState.ACTIVE,
    (DynPosLimitState.ACTIVE_BRAKING, DplEvent.DISABLE): DynPosLimitState.INACTIVE,
    (DynPosLimitState.ACTIVE_BRAKE, DplEvent.RELEASE): DynPosLimitState.ACTIVE,
    (DynPosLimitState.ACTIVE_BRAKE, DplEvent.DISABLE): DynPosLimitState.INACTIVE,
}
"""Everything that moves ``state_r`` (C43-03). A PLC sees, cycle by cycle:
0 -(enable)-> 1 -(adopted next cycle)-> 2 -(limit on the ramp)-> 3 -(at rest)-> 4
-(moved: release)-> 2 ... -(lifted)-> 0. When the limit is violated in the cycle it is adopted
(the axis already beyond it, C43-05, or the crossing already on the ramp), ADOPTED and VIOLATION
happen in the same cycle: the image shows 1 -> 3 (2 only lives inside that cycle; the events show
both transitions with the same cycle number)."""


# the states and the enum members the cycle compares with, as constants (a compiled module reads a
# Final name directly; any other module-level name is a dictionary lookup on every use)
_INACTIVE: Final = DynPosLimitState.INACTIVE
_ACTIVATION: Final = DynPosLimitState.ACTIVATION
_ACTIVE: Final = DynPosLimitState.ACTIVE
_BRAKING: Final = DynPosLimitState.ACTIVE_BRAKING
_BRAKE: Final = DynPosLimitState.ACTIVE_BRAKE
_HOLD: Final = HoldSource.DYN_POS_LIMIT
_AUTOMATIC: Final = Mode.AUTOMATIC


def next_state(state: DynPosLimitState, event: DplEvent) -> DynPosLimitState:
    """The one place that decides a state change; an event a state does not expect is a bug."""
    try:
        return TRANSITIONS[(state, event)]
    except KeyError:
        raise RuntimeError(f"dynamic position limit: event {event.value!r} in state {state.name}") from None


@dataclass(slots=True)
class _Limit:
    """One control unit: the low (side -1) or high (side +1) limit of one axis."""

    axis: Axis
    channel: Channel
    k: int
    """Index of the axis in the channel's axis tuple (path points)."""
    side: int
    unit: ControlUnitSgn32
    key: str
    state: DynPosLimitState = DynPosLimitState.INACTIVE
    command: int = 0
    """Adopted limit [0.1 µm]."""
    limit: float = 0.0
    """Adopted limit [mm]."""
    stop_s: float | None = None
    """Path coordinate where the planner must rest because of this limit."""
    generation: int = -1
    check_current: bool = False
    """C43-05 pending: look at where the axis is now (activation or new value)."""

    def beyond(self, position: float, threshold: float) -> bool:
        """Is ``position`` farther into the forbidden zone than ``threshold`` (mm beyond the limit)?"""
        return self.side * (position - self.limit) > threshold + _EPS

    def depth(self, position: float) -> float:
        """How far ``position`` lies in the forbidden zone (<= 0: allowed)."""
        return self.side * (position - self.limit)


class _Ramp:
    """The braking ramp of one channel in one cycle (C43-08): from (s1, v1), one cycle ahead, with
    deceleration ``a`` for ``t_brake``. Its 20 points are computed and looked up on first use."""

    __slots__ = ("_planner", "_samples", "a", "reach", "s0", "s1", "t_brake", "v0", "v1")

    def __init__(
        self, planner: Planner, s0: float, v0: float, s1: float, v1: float, a: float, t_brake: float
    ) -> None:
        self._planner = planner
        self.s0, self.v0, self.s1, self.v1, self.a, self.t_brake = s0, v0, s1, v1, a, t_brake
        reach = s1 + v1 * t_brake - 0.5 * a * t_brake * t_brake - s0 + (planner.s_abs - planner.s_out)
        self.reach = reach * planner.axis_gain(s0 + reach)
        """How far the ramp reaches from where the axes are: no axis can travel farther than this. With a
        jerk-limited profile (M-04) the axes lag the planned path by the profile's filter; their ramp ends
        where the planned one ends, so it reaches that much farther. With a kinematic transformation an
        axis can travel farther than the tool tip's path (``axis_gain``, K-05)."""
        self._samples: list[tuple[float, tuple[float, ...]]] | None = None

    @property
    def path(self) -> list[float]:
        """Path coordinates of the samples, evenly spaced in time, in path order."""
        if self.t_brake <= 0.0:
            return [self.s0 + self.reach]
        step = self.t_brake / RAMP_SAMPLES
        s1, v1, half_a = self.s1, self.v1, 0.5 * self.a
        return [s1 + v1 * (i * step) - half_a * (i * step) ** 2 for i in range(1, RAMP_SAMPLES + 1)]

    @property
    def samples(self) -> list[tuple[float, tuple[float, ...]]]:
        """(path coordinate, point) of the sampled ramp, in path order."""
        if self._samples is None:
            path = self.path
            points = self._planner.points_at(path)
            self._samples = [(s, p) for s, p in zip(path, points) if p is not None]  # noqa: B905 compiled: see geometry.py
        return self._samples


class DynPosLimits(Monitor):
    """FCT-C43 for every axis of the machine (C43-01..C43-09)."""

    def __init__(self, machine: MachineView) -> None:
        self.machine = machine
        self._by_channel: list[list[_Limit]] = []
        for ch in machine.channels:
            limits: list[_Limit] = []
            for k, axis in enumerate(ch.axes):
                ctl = machine.hli.axes[axis.index].ipo_mc_control
                for side, unit in ((-1, ctl.dyn_pos_limit_low), (1, ctl.dyn_pos_limit_high)):
                    name = "high" if side > 0 else "low"
                    unit.request_r = 0  # not supported (FCT-C43 3.1.1)
                    limits.append(_Limit(axis, ch, k, side, unit, f"dyn_pos_limit_{name}:{axis.name}"))
            self._by_channel.append(limits)
        # C43-01: only channels with FCT_DYN_POS_LIMIT; elsewhere the units stay INACTIVE
        self._effective = [
            (ch, limits)
            for ch, limits in zip(machine.channels, self._by_channel, strict=True)
            if ch.config.dyn_pos_limit_enabled
        ]
        # P-CHAN-00874 / P-CHAN-00751 per channel, read once (the cycle reads no pydantic model)
        self._adoption = {
            ch.index: (max(1, ch.config.dpl_input_cycles), max(1, ch.config.dpl_tol_limit_change))
            for ch in machine.channels
        }

    # --- the cycle -----------------------------------------------------------------------
    def before_interpolation(self) -> None:
        for ch, limits in self._effective:
            planner = ch.planner
            monitoring: bool | None = None
            ramp: _Ramp | None = None
            ramp_done = False
            for lim in limits:
                unit = lim.unit
                state = lim.state
                if not unit.enable_w:
                    if state is not _INACTIVE:
                        self._drop_stop(lim, planner)
                        self._fire(lim, DplEvent.DISABLE)
                    continue
                if state is _INACTIVE:
                    self._fire(lim, DplEvent.ENABLE)
                    continue
                if state is _ACTIVATION:
                    self._adopt(lim, unit.command_w)
                    self._fire(lim, DplEvent.ADOPTED)
                elif unit.command_w != lim.command and self._change_due(lim, ch, unit.command_w):
                    self._adopt(lim, unit.command_w)
                    self._release(lim, planner)
                if lim.generation != planner.generation:
                    lim.generation = planner.generation
                    lim.stop_s = None
                    if lim.state is _BRAKING or lim.state is _BRAKE:
                        self._fire(lim, DplEvent.RELEASE)
                if monitoring is None:
                    monitoring = _path_monitored(ch)  # C43-09
                if not monitoring:
                    self._release(lim, planner)
                    lim.check_current = False
                    continue
                if lim.stop_s is not None:
                    planner.stop_points[lim.key] = lim.stop_s
                    continue  # held until the limit is moved or lifted (C43-07)
                if not ramp_done:
                    ramp = _braking_ramp(planner)
                    ramp_done = True
                stop_s = self._look_ahead(lim, planner, ramp)
                if stop_s is not None:
                    planner.stop_points[lim.key] = stop_s
            if any(lim.stop_s is not None for lim in limits):
                ch.hold(_HOLD)  # "ein bereichsspezifischer Feedhold" (FCT-C43)

    def after_interpolation(self) -> None:
        for ch, limits in self._effective:
            planner = ch.planner
            for lim in limits:
                if lim.stop_s is None:
                    continue
                if lim.generation != planner.generation:
                    # the path was cleared this cycle (program end, abort, axes stopped on their own)
                    lim.stop_s = None
                    lim.generation = planner.generation
                    self._fire(lim, DplEvent.RELEASE)
                elif lim.state is _BRAKING and planner.at_rest and planner.s_abs >= lim.stop_s - _EPS:
                    self._fire(lim, DplEvent.STANDSTILL)

    # --- pieces --------------------------------------------------------------------------
    def _adopt(self, lim: _Limit, command: int) -> None:
        lim.command = command
        lim.limit = mm_from_increments(command)
        lim.check_current = True

    def _change_due(self, lim: _Limit, ch: Channel, command: int) -> bool:
        """P-CHAN-00874 / P-CHAN-00751: is a new command value taken over in this cycle?"""
        every, tolerance = self._adoption[ch.index]
        if self.machine.cycle % every != 0:
            return False
        return abs(command - lim.command) >= tolerance

    def _release(self, lim: _Limit, planner: Planner) -> None:
        if lim.stop_s is not None or lim.state in (
            DynPosLimitState.ACTIVE_BRAKING,
            DynPosLimitState.ACTIVE_BRAKE,
        ):
            self._drop_stop(lim, planner)
            self._fire(lim, DplEvent.RELEASE)

    def _drop_stop(self, lim: _Limit, planner: Planner) -> None:
        lim.stop_s = None
        planner.stop_points.pop(lim.key, None)

    def _brake(self, lim: _Limit, stop_s: float) -> float:
        lim.stop_s = stop_s
        self._fire(lim, DplEvent.VIOLATION)
        return stop_s

    def _look_ahead(self, lim: _Limit, planner: Planner, ramp: _Ramp | None) -> float | None:
        """C43-04..C43-06 for one limit: the stop point when braking is due (also kept in ``lim.stop_s``)."""
        check_current, lim.check_current = lim.check_current, False
        if ramp is None:
            return None  # the path does not move this cycle
        s0, v0 = ramp.s0, ramp.v0
        a_fh = planner.feedhold_decel
        depth0 = lim.side * (lim.axis.setpoint - lim.limit)
        if check_current and depth0 > _EPS and v0 > 0.0:
            # C43-05: already in the forbidden zone when the limit becomes active: stop at once
            return self._brake(lim, s0 + _feedhold_distance(v0, a_fh, planner.t_a))
        if -depth0 > ramp.reach + _EPS:
            return None  # out of reach before the ramp ends: no sample can hit (saves the lookup)
        # beyond the limit already (e.g. at rest there): only going deeper is a violation
        threshold = max(0.0, depth0)
        s_good = s0
        for s_k, point in ramp.samples:
            if lim.beyond(point[lim.k], threshold):
                crossing = _first_bad(
                    planner.position_at, lim.k, lambda x: lim.beyond(x, threshold), s_good, s_k
                )
                return self._brake(lim, max(crossing, s0 + _feedhold_distance(v0, a_fh, planner.t_a)))
            s_good = s_k
        return None

    def _fire(self, lim: _Limit, event: DplEvent) -> None:
        new = next_state(lim.state, event)
        if new == lim.state:
            return
        lim.state = new
        lim.unit.state_r = int(new)
        m = self.machine
        m.emit(
            DynPosLimitChanged(
                cycle=m.cycle,
                time_s=m.time,
                channel=lim.channel.number,
                axis=lim.axis.name,
                side="high" if lim.side > 0 else "low",
                state=int(new),
                state_name=new.name,
                limit=lim.command,
            )
        )

    # --- for tests and tools ------------------------------------------------------------
    def state(self, axis: str, side: str) -> DynPosLimitState:
        """Current state of ``axis``' ``"low"`` or ``"high"`` limit."""
        for limits in self._by_channel:
            for lim in limits:
                if lim.axis.name == axis and (lim.side > 0) == (side == "high"):
                    return lim.state
        raise KeyError(f"no dynamic position limit {side!r} for axis {axis!r}")


def _path_monitored(ch: Channel) -> bool:
    """C43-09: only a running program in automatic mode is looked ahead on."""
    return (
        ch.mode is _AUTOMATIC
        and ch.program_running
        and not ch.aborting
        and not any(a.stopping for a in ch.axes)
    )


def _feedhold_distance(v: float, a: float, t: float) -> float:
    """Path travelled when the planner brakes with ``a`` from this cycle on (v falls by a*T per
    cycle, starting now): the stop point that makes the planner's discrete ramp do exactly that."""
    return max(0.0, v * v / (2.0 * a) - 0.5 * v * t)


def _braking_ramp(planner: Planner) -> _Ramp | None:
    """C43-08: the braking ramp from one cycle ahead (its samples: :attr:`_Ramp.samples`)."""
    motion = planner.next_motion()
    if motion is None:
        return None
    t = planner.t_a
    a = planner.feedhold_decel
    s0, v0 = planner.s_abs, planner.velocity
    # the current acceleration holds for one more cycle (at most up to the programmed feed)
    v1 = min(v0 + motion.accel * t, max(v0, motion.v_max * planner.override))
    if v1 <= 0.0:
        return None
    s1 = s0 + v1 * t
    s_rest = planner.next_standstill(until=s1 + v1 * v1 / (2.0 * a))
    if s1 >= s_rest:  # the planned path stops within this cycle: one point, where it stops
        return _Ramp(planner, s0, v0, s_rest, 0.0, a, 0.0)
    room = s_rest - s1
    if v1 * v1 / (2.0 * a) <= room:
        t_brake = v1 / a
    else:  # the planned path stops first: the ramp ends there
        t_brake = (v1 - math.sqrt(max(0.0, v1 * v1 - 2.0 * a * room))) / a
    return _Ramp(planner, s0, v0, s1, v1, a, t_brake)


def _first_bad(
    position_at: Callable[[float], tuple[float, ...] | None],
    k: int,
    bad: Callable[[float], bool],
    s_good: float,
    s_bad: float,
) -> float:
    """Locate the limit crossing between a good and a bad path coordinate; returns the good side."""
    lo, hi = s_good, s_bad
    for _ in range(_BISECT_STEPS):
        if hi - lo <= 1e-10:
            break
        mid = 0.5 * (lo + hi)
        point = position_at(mid)
        if point is None or bad(point[k]):
            hi = mid
        else:
            lo = mid
    return lo
