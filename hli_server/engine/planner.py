"""Path interpolation with look-ahead (E-05).

The decoder fills a queue of motion items (segments with their velocity and acceleration limits)
and markers (program end, a pending error, an action to run in program order). Each cycle the path
velocity follows

    v_next = min(v + a*T_A, v_programmed * override, sqrt(v_exit^2 + 2 a s_remaining), stop limits)

where v_exit is the highest velocity at the end of the current item from which every later item can
still be reached within its own limits (a backward pass over the queue). The queue's end and every
marker are points of standstill. Feedhold brakes with the channel's feedhold deceleration.

Junctions: the velocity through a corner is limited as in a junction-deviation planner
(``JUNCTION_DEVIATION`` mm); G60 (exact stop) and G00 blocks end in standstill.

Other functions steer the path through ``stop_points``: an absolute path coordinate (mm travelled
since the program start) at which the path must be at rest; the planner brakes with the feedhold
deceleration so that it stops there, exactly: the last cycle's step is cut at the stop point, so the
path neither passes it nor creeps towards it (used by FCT-C43's dynamic limits). ``generation``
counts :meth:`Planner.clear`, so that a function holding path coordinates notices a new path.

G60 (exact stop, FCT-A3 section 2): after a G60 block the next item starts only when
``exact_stop_gate(motion)`` says the axes are in their exact-stop window (the position monitor
installs the gate; without one, the path goes on at once).

Acceleration profiles (``#SLOPE``, P-CHAN-00071, M-01..M-05): the velocities above are the step
profile's. With TRAPEZ, SIN2 or HSC active (:meth:`Planner.set_profile`) the point handed to the
axes is the one at the *filtered* path coordinate (:class:`~hli_server.engine.path.profiles.PathFilter`):
it lags the planned one by half the ramp time, never passes it, and comes to rest where it does.
Where the planned path comes to rest (a marker, a reversal, the end of a G00 or G60 block, a stop
point), it waits until the filtered path is at rest too (:attr:`Planner.at_rest`) before it goes
on: a marker runs with the axes at rest, and a corner passed at velocity 0 stays a stop. A SYNC
marker runs when the planned path passes it (half a ramp time before the axes get there).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from hli_server.engine.geometry import Point, Segment
from hli_server.engine.kinematics.path import SegmentMap
from hli_server.engine.nc.blocks import Block
from hli_server.engine.path.profiles import PathFilter, SlopeProfile

__all__ = ["JUNCTION_DEVIATION", "Dwell", "ExactStopGate", "Marker", "MarkerKind", "Motion", "Planner"]

JUNCTION_DEVIATION = 0.02
"""mm: how far a corner may be cut in thought to bound the corner velocity (project's own)."""


class MarkerKind(StrEnum):
    END = "end"
    """Program end (M30 / M02, or the end of the text: payload ``"eof"``)."""
    ERROR = "error"
    """A refused block: its :class:`~hli_server.engine.decoder.DecodeError` is the payload."""
    ACTION = "action"
    """A callable run in program order when the path reaches it (the path comes to rest there)."""
    SYNC = "sync"
    """A callable run in program order when the path passes it, without stopping there (a ``#MSG SYN``,
    a synchronous ``V.E.`` write: docs/check.md)."""


@dataclass(slots=True)
class Motion:
    segment: Segment
    block: Block
    v_max: float
    """mm/s, programmed feed (or rapid) already limited by the axes."""
    accel: float
    """mm/s², path acceleration the axes allow."""
    rapid: bool = False
    exact_stop: bool = False
    length: float = 0.0
    s_start: float = 0.0
    """Absolute path coordinate of the start (set when queued)."""
    v_junction: float = 0.0
    """Highest velocity at the end of this item given the direction change into the next."""
    v_exit_max: float = 0.0
    """Result of the backward pass."""
    tag: Any = None
    kin: SegmentMap | None = None
    """With a kinematic transformation on: ``segment`` is the tool tip's path and this turns its points
    into axis positions (docs/kinematics.md); None: the segment is the axes' path."""
    gain: float = 1.0
    """The largest ratio of an axis' travel to the path's along this item (above 1 only with a
    transformation: a turning head moves its linear axes farther than the tool tip goes)."""

    def axes_at(self, s: float) -> Point:
        """The axis positions at path coordinate ``s`` of this item (the segment's point, transformed)."""
        kin = self.kin
        if kin is None:
            return self.segment.point_at(s)
        return kin.axes(self.segment.point_at(s), s)

    def axes_start(self) -> Point:
        kin = self.kin
        return self.segment.start if kin is None else kin.axes(self.segment.start, 0.0)

    def axes_end(self) -> Point:
        kin = self.kin
        return self.segment.end if kin is None else kin.axes(self.segment.end, self.length)


@dataclass(slots=True)
class Marker:
    kind: MarkerKind
    block: Block | None
    payload: Any = None
    s_start: float = 0.0


Item = Motion | Marker


class Dwell:
    """The payload of a G04 action marker: the path rests ``seconds`` there (whole cycles)."""

    __slots__ = ("seconds",)

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds

    def __call__(self) -> None:
        """Run by the channel like any action: the planner has started the rest already."""


ExactStopGate = Callable[[Motion], bool]
"""Asked at standstill after a G60 block: may the next item start? (FCT-A3: axes in their window)"""


@dataclass(slots=True)
class Planner:
    t_a: float
    feedhold_decel: float
    queue: deque[Item] = field(default_factory=deque)
    velocity: float = 0.0
    position_in_item: float = 0.0
    s_abs: float = 0.0
    """Path travelled since the program start [mm]."""
    s_queued_end: float = 0.0
    feedhold: bool = False
    override: float = 1.0
    stop_points: dict[str, float] = field(default_factory=dict)
    generation: int = 0
    """Incremented by :meth:`clear`: path coordinates of an older generation mean nothing any more."""
    exact_stop_gate: ExactStopGate | None = None
    """Asked at standstill after a G60 block: may the next item start? (FCT-A3: axes in the window)"""
    profile: SlopeProfile = field(default_factory=SlopeProfile)
    """The active acceleration profile (``#SLOPE``; P-CHAN-00071 at program start)."""
    s_out: float = 0.0
    """Path coordinate of the point handed to the axes (the filtered one; ``s_abs`` under STEP)."""
    v_out: float = 0.0
    """Velocity of the point handed to the axes [mm/s] (the filtered path's)."""
    dwell_remaining: float = 0.0
    """Seconds the path still rests (G04)."""
    _filter: PathFilter | None = None
    _trail: deque[Motion] = field(default_factory=deque)
    """Motions the planned path has left but the filtered one has not (yet)."""
    _exact_stop_pending: Motion | None = None
    _dirty: bool = True
    _motions: int = 0
    """Motion items in the queue, counted as they come and go (the channel asks every cycle)."""
    _geared: int = 0
    """Motion items in the queue (and the profile's trail) with a ``gain`` above 1."""

    # --- filling -------------------------------------------------------------------------
    def clear(self) -> None:
        self.queue.clear()
        self.velocity = 0.0
        self.position_in_item = 0.0
        self.s_abs = 0.0
        self.s_queued_end = 0.0
        self.stop_points.clear()
        self._exact_stop_pending = None
        self.generation += 1
        self._dirty = True
        self._motions = 0
        self._geared = 0
        self._trail.clear()
        self.dwell_remaining = 0.0
        self.s_out = 0.0
        self.v_out = 0.0
        if self._filter is not None:
            self._filter.reset(0.0)

    def start_dwell(self, seconds: float) -> None:
        """G04: the path rests ``seconds`` (whole cycles, rounded) from the next cycle on."""
        self.dwell_remaining = round(seconds / self.t_a) * self.t_a

    def set_profile(self, profile: SlopeProfile) -> None:
        """Make ``profile`` the active acceleration profile. Called at rest (program start, a
        ``#SLOPE`` block, which stops the path): the filter starts on the current point."""
        self.profile = profile
        kernel = profile.kernel(self.t_a)
        if len(kernel) == 1:
            self._filter = None
            self.s_out = self.s_abs
        else:
            self._filter = PathFilter(kernel, self.s_out)

    @property
    def at_rest(self) -> bool:
        """The planned path and the point handed to the axes are both at rest."""
        f = self._filter
        return self.velocity <= 0.0 and (f is None or f.settled)

    def stop_distance(self, decel: float | None = None) -> float:
        """Path the axes still travel when the path brakes with ``decel`` (the feedhold deceleration
        if None) from now, in the active profile: the planned path's ramp plus the filter's lag."""
        a = decel if decel is not None else self.feedhold_decel
        v = self.velocity
        planned = v * v / (2.0 * a) + 0.5 * v * self.t_a if v > 0.0 else 0.0
        return planned + (self.s_abs - self.s_out)

    def push(self, item: Item) -> None:
        if isinstance(item, Motion):
            item.length = item.segment.length
            item.s_start = self.s_queued_end
            self.s_queued_end += item.length
            prev = self._last_motion_before_end()
            if prev is not None:
                prev.v_junction = _junction_velocity(prev, item)
            self._motions += 1
            if item.gain > 1.0:
                self._geared += 1
        else:
            item.s_start = self.s_queued_end
        self.queue.append(item)
        self._dirty = True

    def _last_motion_before_end(self) -> Motion | None:
        """The last motion of the queue, if only SYNC markers follow it (they do not stop the path)."""
        for item in reversed(self.queue):
            if isinstance(item, Motion):
                return item
            if item.kind != MarkerKind.SYNC:
                return None
        return None

    @property
    def motion_items(self) -> int:
        """Motion items queued (the look-ahead's fill level)."""
        return self._motions

    def axis_gain(self, until: float) -> float:
        """The largest :attr:`Motion.gain` of the path from the axes' point to path coordinate ``until``
        (1 where no transformation makes an axis travel farther than the path)."""
        if not self._geared:
            return 1.0
        gain = 1.0
        for item in (*self._trail, *self.queue):
            if isinstance(item, Motion) and item.s_start + item.length >= self.s_out - 1e-9:
                if item.s_start > until:
                    break
                gain = max(gain, item.gain)
        return gain

    @property
    def queued_length(self) -> float:
        """Path still queued ahead of the current position [mm]."""
        return self.s_queued_end - self.s_abs

    def _backward_pass(self) -> None:
        v_next_entry = 0.0
        for item in reversed(self.queue):
            if isinstance(item, Marker):
                if item.kind != MarkerKind.SYNC:
                    v_next_entry = 0.0
                continue
            v_exit = min(item.v_junction, v_next_entry)
            item.v_exit_max = v_exit
            v_next_entry = min(item.v_max, math.sqrt(v_exit * v_exit + 2.0 * item.accel * item.length))
        self._dirty = False

    # --- queries for monitors ------------------------------------------------------------
    def current(self) -> Item | None:
        return self.queue[0] if self.queue else None

    def position_at(self, s_abs: float) -> Point | None:
        """Axis positions of the queued path at absolute path coordinate ``s_abs`` (None beyond the queue)."""
        for item in self.queue:
            if (
                isinstance(item, Motion)
                and item.s_start - 1e-12 <= s_abs <= item.s_start + item.length + 1e-12
            ):
                return item.axes_at(s_abs - item.s_start)
        return None

    def points_at(self, s_values: Sequence[float]) -> list[Point | None]:
        """:meth:`position_at` for ascending ``s_values`` in one walk over the queue."""
        out: list[Point | None] = []
        items = iter(self.queue)
        item = next(items, None)
        for s in s_values:
            while item is not None and (
                not isinstance(item, Motion) or s > item.s_start + item.length + 1e-12
            ):
                item = next(items, None)
            if item is None or s < item.s_start - 1e-12:
                out.append(None)
                continue
            out.append(item.axes_at(s - item.s_start))
        return out

    def next_motion(self) -> Motion | None:
        """The item the path moves on next: the head, past action markers; None if the path is at
        an end or error marker (or the queue is empty), i.e. will not move this cycle."""
        for item in self.queue:
            if isinstance(item, Motion):
                return item
            if item.kind not in (MarkerKind.ACTION, MarkerKind.SYNC):
                return None
        return None

    def next_standstill(self, until: float = math.inf) -> float:
        """Path coordinate of the next point where the planned path comes to rest on its own: the end
        of an item with exit velocity 0 (reversal, G00, G60), a marker, or the end of the queue;
        ``until`` if there is none before it (the search stops there)."""
        if self._dirty:
            self._backward_pass()
        for item in self.queue:
            if item.s_start > until:
                return until
            if isinstance(item, Marker):
                if item.kind == MarkerKind.SYNC:
                    continue
                return max(item.s_start, self.s_abs)
            if item.v_exit_max <= 1e-9:
                return item.s_start + item.length
        return min(self.s_queued_end, until)

    def brake_distance(self, decel: float | None = None) -> float:
        a = decel if decel is not None else self.feedhold_decel
        return self.velocity * self.velocity / (2.0 * a)

    # --- one cycle -----------------------------------------------------------------------
    def step(self) -> tuple[Point | None, list[Marker]]:
        """Advance one cycle. Returns the point for the axes (None if nothing moved) and the markers
        reached in this cycle, in order (see :meth:`_step_planned`); with a jerk-limited profile the
        point is the filtered path's (see the module's description)."""
        f = self._filter
        if f is None:
            before = self.s_abs
            point, reached = self._step_planned()
            self.s_out = self.s_abs
            self.v_out = (self.s_abs - before) / self.t_a if self.s_abs >= before else 0.0
            return point, reached
        held: list[Marker] = []
        if self.velocity <= 0.0 and not f.settled:
            # where the planned path comes to rest (a marker, a reversal, G00/G60 block end, a
            # stop point), the axes come to rest too before it goes on: a corner with velocity
            # 0 stays one, and a marker runs with the axes at rest
            reached = held
        else:
            _, reached = self._step_planned()
        before = self.s_out
        s_f = f.push(self.s_abs)
        self.s_out = s_f
        self.v_out = (s_f - before) / self.t_a
        trail = self._trail
        while trail and trail[0].s_start + trail[0].length < s_f - 1e-9:
            if trail.popleft().gain > 1.0:
                self._geared -= 1
        if s_f == before:
            return None, reached
        return self._point_out(s_f), reached

    def _point_out(self, s: float) -> Point | None:
        for passed in self._trail:
            if passed.s_start - 1e-9 <= s <= passed.s_start + passed.length + 1e-9:
                return passed.axes_at(min(max(s - passed.s_start, 0.0), passed.length))
        for item in self.queue:
            if isinstance(item, Motion) and item.s_start - 1e-9 <= s <= item.s_start + item.length + 1e-9:
                return item.axes_at(min(max(s - item.s_start, 0.0), item.length))
        return None

    def _step_planned(self) -> tuple[Point | None, list[Marker]]:
        """Advance the planned (step-profile) path one cycle. Returns the new path point (None if
        nothing moved) and the markers reached in this cycle, in order. A marker is reached only at
        standstill."""
        if self._dirty:
            self._backward_pass()
        reached: list[Marker] = []
        if self.dwell_remaining > 0.0:
            self.dwell_remaining = max(0.0, self.dwell_remaining - self.t_a)
            if self.dwell_remaining < 0.5 * self.t_a:
                self.dwell_remaining = 0.0
            self.velocity = 0.0
            return None, reached
        pending = self._exact_stop_pending
        if pending is not None:
            # G60: hold at the block end until the axes are in their exact-stop window
            if self.exact_stop_gate is not None and not self.exact_stop_gate(pending):
                self.velocity = 0.0
                return None, reached
            self._exact_stop_pending = None
        # markers at the head are executed at once when the path is at rest there
        while self.queue and isinstance(self.queue[0], Marker):
            marker = self.queue.popleft()
            assert isinstance(marker, Marker)
            reached.append(marker)
            if marker.kind not in (MarkerKind.ACTION, MarkerKind.SYNC):
                return None, reached
            if isinstance(marker.payload, Dwell):
                self.start_dwell(marker.payload.seconds)  # G04: rest from the next cycle on
                return None, reached
        if not self.queue:
            self.velocity = 0.0
            return None, reached
        item = self.queue[0]
        assert isinstance(item, Motion)
        t = self.t_a
        v = self.velocity
        s_rem = item.length - self.position_in_item
        v_exit = item.v_exit_max
        v_limit = _braking_limit(v_exit, item.accel, s_rem, t)
        v_prog = item.v_max * self.override
        d_stop = math.inf
        for s_stop in self.stop_points.values():
            d_stop = min(d_stop, s_stop - self.s_abs)
        if d_stop < math.inf:
            v_limit = min(v_limit, _braking_limit(0.0, self.feedhold_decel, d_stop, t))
        if self.feedhold:
            v_next = max(0.0, v - self.feedhold_decel * t)
        elif v_prog < v:
            v_next = max(v_prog, v - max(item.accel, self.feedhold_decel) * t)
        else:
            # from rest the first cycle's mean velocity of a ramp is a*T/2, then +a*T per cycle
            dv = item.accel * t * (0.5 if v <= 0.0 else 1.0)
            v_next = min(v + dv, v_prog)
        v_next = min(v_next, v_limit)
        ds = v_next * t
        at_stop_point = False
        if ds >= d_stop - 1e-12:
            # the discrete ramp's last step would pass the stop point: cut it there, at rest
            ds = max(d_stop, 0.0)
            at_stop_point = True
        self.velocity = 0.0 if at_stop_point else v_next
        if ds <= 0.0:
            return (item.axes_at(self.position_in_item) if v > 0 else None), reached
        # advance, possibly across junctions
        while True:
            s_rem = item.length - self.position_in_item
            if ds < s_rem - 1e-12:
                self.position_in_item += ds
                self.s_abs += ds
                return item.axes_at(self.position_in_item), reached
            self.s_abs = item.s_start + item.length
            ds -= max(s_rem, 0.0)
            self.queue.popleft()
            if self._filter is not None:
                self._trail.append(item)
            elif item.gain > 1.0:
                self._geared -= 1
            self._motions -= 1
            self.position_in_item = 0.0
            # SYNC markers are passed on the way (their actions run this cycle, in program order)
            while self.queue and isinstance(self.queue[0], Marker) and self.queue[0].kind == MarkerKind.SYNC:
                passed = self.queue.popleft()
                assert isinstance(passed, Marker)
                reached.append(passed)
            nxt = self.queue[0] if self.queue else None
            if not isinstance(nxt, Motion) or item.v_exit_max <= 1e-9:
                self.velocity = 0.0  # standstill at the end of the item
                if item.exact_stop:
                    self._exact_stop_pending = item
                return item.axes_end(), reached
            item = nxt
            if ds <= 1e-12:
                return item.axes_start(), reached


def _braking_limit(v_end: float, accel: float, distance: float, t: float) -> float:
    """Highest velocity for the next cycle from which the discrete ramp (v falls by a*T per cycle)
    still reaches ``v_end`` within ``distance``: v²/(2a) + v*T/2 <= distance + v_end²/(2a)."""
    if distance <= 0.0:
        return min(v_end, 0.0) if v_end <= 0.0 else 0.0
    half = 0.5 * accel * t
    return -half + math.sqrt(half * half + v_end * v_end + 2.0 * accel * distance)


def _junction_velocity(a: Motion, b: Motion) -> float:
    if a.exact_stop or a.rapid or b.rapid:
        return 0.0
    da = a.segment.direction_at(a.length)
    db = b.segment.direction_at(0.0)
    cos_theta = -sum(x * y for x, y in zip(da, db, strict=True))  # angle between -da and db
    v_lim = min(a.v_max, b.v_max)
    if cos_theta < -0.999999:  # straight on
        return v_lim
    if cos_theta > 0.999999:  # reversal
        return 0.0
    sin_half = math.sqrt(max(0.0, 0.5 * (1.0 - cos_theta)))
    accel = min(a.accel, b.accel)
    v = math.sqrt(accel * JUNCTION_DEVIATION * sin_half / (1.0 - sin_half))
    return min(v, v_lim)
