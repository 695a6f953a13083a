"""What the operator panel shows beyond the snapshot (the dashboard, docs/dashboard.md): the recent trail of
each channel's axes, the programmed path ahead, the live scene, the collision pairs.

The trail is recorded by the runtime after every cycle (:meth:`TrailRecorder.after_cycle`, a cycle
listener), cheaply: every :data:`TRAIL_EVERY` th cycle one sample of the channel's setpoints, and a
sample is kept only where the path turns (a point is dropped while the samples after it stay within
:data:`TRAIL_TOLERANCE` of the line from the last kept point in the direction the path left it,
Reumann-Witkam). A straight move costs two points however long it is, an arc a point every few
millimetres (the chord's sagitta stays below the tolerance), a standstill nothing. The newest
:data:`TRAIL_POINTS` points are kept; a program start begins a new trail.

Setpoints, not actual positions: the trail is where the interpolator led the axes (the programmed path
as travelled); the actual positions with their following error are in the axis table.

The scene is :func:`hli_server.scene.build_scene` on the channel's area table, the trail, the active
alarms of the channel, the position and the path ahead: the same function ``check --plot`` draws, so
the dashboard and the plot share the geometry. It is cached until one of its inputs changes.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, cast

from hli_server.engine.areas.monitor import AreaMonitor
from hli_server.engine.channel import Channel
from hli_server.engine.geometry import ArcSegment
from hli_server.engine.machine import Machine
from hli_server.engine.monitors.collision import CollisionMonitor
from hli_server.engine.planner import Motion
from hli_server.scene import build_scene, round_mm
from schemas.events import AlarmRaised, AlarmsCleared, AreasChanged, Event, ProgramStateChanged
from schemas.results import CollisionPair, ProgramEntry, Scene

__all__ = [
    "AHEAD_POINTS",
    "TRAIL_EVERY",
    "TRAIL_POINTS",
    "TRAIL_TOLERANCE",
    "Trail",
    "TrailRecorder",
    "collision_pairs",
    "live_scene",
    "path_ahead",
    "program_table",
    "scene_key",
]

TRAIL_EVERY = 4
"""Cycles between two samples of the trail (4 ms at T_A = 1 ms: 2 mm at 30 m/min)."""
TRAIL_TOLERANCE = 0.05
"""mm: how far a sample may be from the line the trail follows before a point is kept; on an arc the
drawn chords stay within a quarter of it (0.0125 mm, far below a screen pixel)."""
TRAIL_POINTS = 300
"""Points of the trail kept per channel (the newest); bounds the cost of a scene."""
AHEAD_POINTS = 200
"""Points of the path ahead at most (arcs are sampled within :data:`TRAIL_TOLERANCE`); bounds the cost of
a scene like :data:`TRAIL_POINTS`."""
_ARC_SAMPLES_MAX = 90


class Trail:
    """The recent path of one channel (points with one coordinate per channel axis)."""

    def __init__(self, size: int = TRAIL_POINTS, tolerance: float = TRAIL_TOLERANCE) -> None:
        self.points: deque[tuple[float, ...]] = deque(maxlen=size)
        """Kept points, oldest first; the newest sample (:attr:`last`) follows them."""
        self.last: tuple[float, ...] | None = None
        self.revision = 0
        """Changes whenever a point is kept or the trail is cleared (not for every sample)."""
        self._tol = tolerance
        self._dir: tuple[float, ...] | None = None
        self._along = 0.0

    def restart(self, at: tuple[float, ...]) -> None:
        """A new trail from ``at`` (where the axes are)."""
        self.points.clear()
        self.points.append(at)
        self.last = at
        self._dir = None
        self.revision += 1

    def add(self, p: tuple[float, ...]) -> None:
        """One sample. Kept points: the first, and each where the path leaves the line it followed."""
        last = self.last
        if last is None:
            self.points.append(p)
            self.last = p
            self.revision += 1
            return
        if p == last:
            return  # standstill
        anchor = self.points[-1]
        d = [b - a for a, b in zip(anchor, p, strict=True)]
        if self._dir is None:
            norm = math.sqrt(sum(v * v for v in d))
            if norm <= self._tol:
                self.last = p
                return
            self._dir = tuple(v / norm for v in d)
            self._along = norm
            self.last = p
            return
        along = sum(u * v for u, v in zip(self._dir, d, strict=True))
        off2 = sum(v * v for v in d) - along * along
        if along >= self._along and off2 <= self._tol * self._tol:
            self._along = along
            self.last = p
            return
        # the path turned (or reversed): keep the previous sample, follow the new direction from it
        self.points.append(last)
        self.revision += 1
        self._dir = None
        self.last = last
        self.add(p)

    def polyline(self) -> list[tuple[float, ...]]:
        """The kept points and the newest sample."""
        out = list(self.points)
        if self.last is not None and (not out or out[-1] != self.last):
            out.append(self.last)
        return out


class TrailRecorder:
    """Records a :class:`Trail` per channel after the cycles (a runtime cycle listener) and counts the
    changes of what a channel's scene shows (areas, alarms, program state: :meth:`on_event`)."""

    def __init__(self, machine: Machine, every: int = TRAIL_EVERY) -> None:
        self._every = every
        self.revisions: dict[int, int] = {}
        self.rebind(machine)

    def rebind(self, machine: Machine) -> None:
        """Follow ``machine`` (at start, and when the runtime restarted its machine): new trails; the
        scenes' revisions go on, so that a client that watched the old machine draws the new one."""
        self._m = machine
        self.trails = {ch.number: Trail() for ch in machine.channels}
        self.revisions = {n: self.revisions[n] + 1 if n in self.revisions else 0 for n in self.trails}
        self._channels = [(ch, self.trails[ch.number]) for ch in machine.channels]
        for ch, trail in self._channels:
            trail.restart(tuple(ch.setpoints()))

    def after_cycle(self, cycle: int) -> None:
        if cycle % self._every:
            return
        for ch, trail in self._channels:
            trail.add(tuple([a.setpoint for a in ch.axes]))

    def on_event(self, event: Event) -> None:
        """A program start begins a new trail; areas, alarms and program states change the scene."""
        number = event.channel
        if number not in self.revisions:
            return
        if isinstance(event, ProgramStateChanged):
            if event.cause == "start":  # in the cycle of the start, before the axes move
                self.trails[number].restart(tuple(self._m.channel(number).setpoints()))
            self.revisions[number] += 1
        elif isinstance(event, AreasChanged | AlarmRaised | AlarmsCleared):
            self.revisions[number] += 1


def path_ahead(ch: Channel, limit: int = AHEAD_POINTS) -> list[tuple[float, ...]]:
    """The path the channel has decoded and not yet travelled (its look-ahead), from the current
    position: the ends of the queued lines, arcs sampled within :data:`TRAIL_TOLERANCE`."""
    planner = ch.planner
    out: list[tuple[float, ...]] = []
    first = True
    for item in planner.queue:
        if not isinstance(item, Motion):
            continue
        seg = item.segment
        s0 = planner.position_in_item if first else 0.0
        first = False
        if isinstance(seg, ArcSegment) and seg.radius > 0.0:
            half_angle = math.acos(max(-1.0, 1.0 - TRAIL_TOLERANCE / seg.radius))
            n = min(_ARC_SAMPLES_MAX, max(2, math.ceil(abs(seg.sweep) / max(2.0 * half_angle, 1e-6))))
            length = seg.length
            out += [item.axes_at(s0 + (length - s0) * k / n) for k in range(1, n + 1)]
        elif item.kin is not None:
            # a transformed block: the axes' path (the trail is the axes'), a point every 16th of it
            length = item.length
            out += [item.axes_at(s0 + (length - s0) * k / 16) for k in range(1, 17)]
        else:
            out.append(seg.end)
        if len(out) >= limit:
            return out[:limit]
    return out


def live_scene(machine: Machine, recorder: TrailRecorder, number: int) -> Scene:
    """The scene (:mod:`hli_server.scene`) of channel ``number`` now."""
    ch = machine.channel(number)
    areas: list[dict[str, Any]] = []
    if machine.has_monitor(AreaMonitor):
        areas = machine.monitor(AreaMonitor).areas_json(ch)
    alarms = [a.to_json() for a in machine.active_alarms if a.channel == number]
    scene = build_scene(
        areas,
        recorder.trails[number].polyline(),
        axis_names=ch.axis_names,
        main_axes=ch.config.main_axes,
        alarms=alarms,
        channel=number,
        position=ch.setpoints(),
        ahead=path_ahead(ch),
        tolerance=0.0,  # the trail is simplified as it is recorded, the path ahead sampled within it
    )
    return cast(Scene, scene)


def scene_key(machine: Machine, recorder: TrailRecorder, number: int) -> tuple[object, ...]:
    """Changes whenever the channel's scene would: trail, position, areas, alarms, program state,
    look-ahead."""
    planner = machine.channel(number).planner
    head = planner.queue[0] if planner.queue else None
    trail = recorder.trails[number]
    return (
        trail.revision,
        trail.last,
        recorder.revisions[number],
        planner.generation,
        planner.s_queued_end,
        id(head),
    )


def collision_pairs(machine: Machine) -> list[CollisionPair]:
    """The FCT-C3 pairs now, lengths in mm: distance ``d`` in the master's coordinates, the minimum
    distance (coll_offset), each axis' braking distance with its collision deceleration (C3-07), and
    whether the pair is monitored (both referenced, C3-06), stopped (P-ERR-70092) or latched (C3-02)."""
    if not machine.has_monitor(CollisionMonitor):
        return []
    monitor = machine.monitor(CollisionMonitor)
    t = machine.t_a
    out: list[CollisionPair] = []
    for pair in monitor.pairs:
        m, p = pair.master, pair.partner

        def brake(axis: Any) -> float:
            v = axis.setpoint_step / t
            return float(v * v / (2.0 * monitor.a_coll(axis)))

        out.append(
            {
                "master": m.name,
                "partner": p.name,
                "distance": round_mm(abs(pair.gap(m.setpoint, p.setpoint))),
                "min_distance": round_mm(pair.offset),
                "brake_master": round_mm(brake(m)),
                "brake_partner": round_mm(brake(p)),
                "monitoring": pair.monitoring,
                "stopped": pair.tripped,
                "latched": pair.latched,
            }
        )
    return out


def program_table(ch: Channel) -> list[ProgramEntry]:
    return [{"number": p.number, "name": p.name} for p in ch.config.programs]
