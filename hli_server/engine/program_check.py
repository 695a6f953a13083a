"""Checking a program offline: the one place that runs a program to its end and collects what happened
(docs/check.md; ``hli-server check``, the HTTP API and the pytest plugin all use :class:`ProgramCheck`).

Two modes:

* full (default): the program runs free in automatic mode on the machine, cycle by cycle, with every
  monitor active, from its start to M30/M02 or the end of its text;
* geometry only: the program is interpreted and every block's whole path is checked (soft limits, work
  and protection areas) without interpolating cycles - the mode for programs of millions of blocks, run
  as a batch where it can be (:mod:`hli_server.engine.batch`). Cycle-based monitors (dynamic limits,
  collision, position monitoring) need cycles and are not evaluated in this mode.

A program that does not end is stopped at a cap and says so (:attr:`CheckResult.capped`): the full check
at ``max_cycles`` cycles, the geometry check, which has no cycles, at ``max_iterations`` loop iterations
and jumps back. The engine does no I/O: the program comes as a string or an open text stream.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any, TextIO

from hli_server.engine.alarms import Alarm, Severity
from hli_server.engine.areas.monitor import AreaMonitor
from hli_server.engine.batch import BatchGeometryCheck, unsupported
from hli_server.engine.channel import Channel
from hli_server.engine.geometry import ArcSegment, Segment
from hli_server.engine.kinematics.transform import Transformation
from hli_server.engine.machine import Machine
from hli_server.engine.nc.directives import IterationCapError
from hli_server.engine.nc.source import ProgramText
from hli_server.engine.planner import Marker, MarkerKind, Motion
from schemas.events import Event, NcMessage
from schemas.wire import ProgramState

__all__ = [
    "ALARM_CYCLE_CAP",
    "ALARM_ITERATION_CAP",
    "DEFAULT_MAX_CYCLES",
    "DEFAULT_MAX_ITERATIONS",
    "CheckResult",
    "ProgramCheck",
]

DEFAULT_MAX_CYCLES = 50_000_000
"""A full check stops here (13.9 h of machine time at 1 ms): a program that has not ended by then does
not end."""
DEFAULT_MAX_ITERATIONS = 1_000_000
"""A geometry check stops after this many loop iterations and jumps back (it has no cycles to count)."""
ALARM_CYCLE_CAP = 914050
"""Warning: the full check reached its cycle cap; the program had not ended."""
ALARM_ITERATION_CAP = 914051
"""Warning: the geometry check reached its cap of loop iterations; the program had not ended."""
_SETTLE_CYCLES = 100_000
"""After an error, cycles the axes get to come to rest before the final position is read."""
_RESOLUTION = 1e4
"""Positions in reports: rounded to 0.1 µm."""


def _round_mm(value: float) -> float:
    if not math.isfinite(value):
        return value
    return round(value * _RESOLUTION) / _RESOLUTION + 0.0


def _round_numbers(value: Any) -> Any:
    if isinstance(value, float):
        return _round_mm(value)
    if isinstance(value, list | tuple):
        return [_round_numbers(v) for v in value]
    if isinstance(value, dict):
        return {k: _round_numbers(v) for k, v in value.items()}
    return value


class CheckResult:
    """What a check found: alarms, messages, the final position, whether the program ran to its end."""

    def __init__(self, machine: Machine, channel: int, mode: str) -> None:
        self.machine = machine
        self.channel = channel
        self.mode = mode
        self.completed = False
        self.blocks = 0
        self.alarms: list[Alarm] = []
        self.messages: list[NcMessage] = []
        self.final_position: dict[str, float] = {}
        self.path: list[tuple[float, ...]] = []
        self.stop_point: tuple[float, ...] | None = None
        self.elapsed_s = 0.0
        self.capped: str | None = None
        """``cycles`` or ``iterations`` when the check stopped at its cap (the program did not end)."""
        self.cap = 0
        self.kinematics = KinematicReport()
        """What the axes and the tool tip did while a kinematic transformation was on (K-06, K-08)."""

    @property
    def stopped_by_error(self) -> bool:
        return any(a.severity == Severity.ERROR for a in self.alarms)

    def areas_json(self) -> list[dict[str, Any]] | None:
        """The channel's area table, when the area monitor is installed (FCT-C14)."""
        machine = self.machine
        if not machine.has_monitor(AreaMonitor):
            return None
        return machine.monitor(AreaMonitor).areas_json(machine.channel(self.channel))

    def to_json(self) -> dict[str, Any]:
        """The JSON report; positions and the floats of alarm params rounded to 0.1 µm (1e-4 mm)."""
        out: dict[str, Any] = {
            "completed": self.completed,
            "mode": self.mode,
            "channel": self.channel,
            "cycles": self.machine.cycle,
            "simulated_time_s": round(self.machine.time, 6),
            "blocks": self.blocks,
            "alarms": [
                {
                    "id": a.number,
                    "severity": str(a.severity),
                    "line": a.line,
                    "block": a.block,
                    "message": a.message,
                    "params": _round_numbers(a.params),
                    "cycle": a.cycle,
                }
                for a in self.alarms
            ],
            "messages": [
                {
                    "cycle": m.cycle,
                    "text": m.text,
                    "save": m.save,
                    "program": m.program,
                    "line": m.line,
                    "block": m.block,
                }
                for m in self.messages
            ],
            "capped": {"by": self.capped, "cap": self.cap} if self.capped is not None else None,
            "final_position": {k: _round_mm(v) for k, v in self.final_position.items()},
            "elapsed_s": round(self.elapsed_s, 3),
        }
        areas = self.areas_json()
        if areas is not None:
            out["areas"] = _round_numbers(areas)
        if self.kinematics.used:
            out["kinematics"] = self.kinematics.to_json(self.machine.channel(self.channel))
        return out


class KinematicReport:
    """While a transformation is on: the kinematics used, each axis' range and the tool tip's (in a full
    check every cycle's setpoints; in a geometry check every block's support points), the tool tip's path
    for the picture, and where the tool tip ended."""

    def __init__(self) -> None:
        self.used: dict[int, str] = {}
        self.axes: dict[int, tuple[float, float]] = {}
        """Slot -> (min, max) of the axis while a transformation was on."""
        self.tip: dict[int, tuple[float, float]] = {}
        """Main-axis slot -> (min, max) of the tool tip."""
        self.tool_path: list[tuple[float, ...]] = []
        self.final_tip: tuple[float, ...] | None = None

    def add(
        self, kin_id: int, name: str, axes: tuple[float, ...], tip: tuple[float, ...], main: tuple[int, ...]
    ) -> None:
        self.used.setdefault(kin_id, name)
        self.see_axes(axes)
        self.see_tip(tip, main)

    def see_axes(self, axes: tuple[float, ...]) -> None:
        ranges = self.axes
        for k, v in enumerate(axes):
            lo, hi = ranges.get(k, (v, v))
            if v < lo:
                ranges[k] = (v, hi)
            elif v > hi or k not in ranges:
                ranges[k] = (lo, v)

    def see_tip(self, tip: tuple[float, ...], main: tuple[int, ...]) -> None:
        ranges = self.tip
        for k in main:
            v = tip[k]
            lo, hi = ranges.get(k, (v, v))
            if v < lo:
                ranges[k] = (v, hi)
            elif v > hi or k not in ranges:
                ranges[k] = (lo, v)
        self.final_tip = tip

    def to_json(self, ch: Channel) -> dict[str, Any]:
        names = ch.axis_names
        main = [names.index(a) for a in ch.config.main_axes]
        return {
            "used": [{"id": k, "name": n} for k, n in sorted(self.used.items())],
            "axis_range": {
                names[k]: [_round_mm(lo), _round_mm(hi)] for k, (lo, hi) in sorted(self.axes.items())
            },
            "tool_tip_range": {
                names[k]: [_round_mm(lo), _round_mm(hi)] for k, (lo, hi) in sorted(self.tip.items())
            },
            "final_tool_tip": (
                {names[k]: _round_mm(self.final_tip[k]) for k in main} if self.final_tip is not None else None
            ),
        }


_ARC_CHORD_MM = 0.01
"""Largest sagitta of the chords an arc is recorded with in a geometry check's path (a picture's
precision), with at most :data:`_ARC_MAX_POINTS` points per arc."""
_ARC_MAX_POINTS = 90


def segment_points(segment: Segment) -> list[tuple[float, ...]]:
    """A block's path for the picture: the end of a line; an arc (helix) every few degrees, so the
    picture does not draw its chord (the path check itself is exact, C14-15)."""
    if not isinstance(segment, ArcSegment) or segment.radius <= _ARC_CHORD_MM:
        return [segment.end]
    step = 2.0 * math.acos(1.0 - _ARC_CHORD_MM / segment.radius)
    n = min(_ARC_MAX_POINTS, max(2, math.ceil(abs(segment.sweep) / step)))
    length = segment.length
    return [segment.point_at(length * k / n) for k in range(1, n + 1)]


def _record(path: list[tuple[float, ...]], point: tuple[float, ...]) -> None:
    """Append ``point`` unless the axes stand where the last one was (dwell, waiting at a marker)."""
    if not path or path[-1] != point:
        path.append(point)


class ProgramCheck:
    """Runs (``geometry_only``: interprets and path-checks) a program on ``machine``'s channel ``channel``.

    ``batch``: a geometry check may run as a batch (:mod:`hli_server.engine.batch`) where the channel's
    path checks allow it; ``record_path`` keeps the path for a picture (every 10th cycle's setpoints in
    a full check, every block's end, arcs every few degrees, in a geometry check; it turns the batch off);
    ``progress(line, blocks)`` is called now and then with the main program's line and the blocks
    decoded."""

    def __init__(
        self,
        machine: Machine,
        channel: int = 1,
        *,
        geometry_only: bool = False,
        max_cycles: int = DEFAULT_MAX_CYCLES,
        max_iterations: int = DEFAULT_MAX_ITERATIONS,
        record_path: bool = False,
        batch: bool = True,
        progress: Callable[[int, int], None] | None = None,
        name: str = "check",
    ) -> None:
        self.machine = machine
        self.channel = channel
        self.geometry_only = geometry_only
        self.max_cycles = max_cycles
        self.max_iterations = max_iterations
        self.record_path = record_path
        self.batch = batch
        self.progress = progress
        self.name = name

    def batch_in_use(self) -> bool:
        """Does a geometry check of this channel run as a batch? Not with ``record_path`` (a picture draws
        every block's path), not with a path check the batch does not know (a user's monitor)."""
        return (
            self.geometry_only
            and self.batch
            and not self.record_path
            and unsupported(self.machine.channel(self.channel)) is None
        )

    def run(self, text: str | TextIO) -> CheckResult:
        """Run ``text`` (a string, or an open text stream: a geometry check streams it with flat memory,
        a full check reads it whole) and collect the result."""
        began = time.perf_counter()
        machine = self.machine
        result = CheckResult(machine, self.channel, "geometry" if self.geometry_only else "full")
        ch = machine.channel(self.channel)
        history_start = len(machine.alarm_history)
        if self.record_path:
            result.path.append(tuple(ch.setpoints()))

        def listen(event: Event) -> None:
            if isinstance(event, NcMessage) and event.channel == ch.number:
                result.messages.append(event)

        machine.event_listeners.append(listen)
        try:
            if self.geometry_only:
                self._geometry(ch, text, result)
            else:
                self._full(ch, text, result)
        finally:
            machine.event_listeners.remove(listen)
        result.alarms = list(machine.alarm_history)[history_start:]
        if result.stopped_by_error or result.capped is not None:
            result.completed = False
        if result.stopped_by_error:
            result.stop_point = tuple(
                result.final_position[n] for n in ch.axis_names if n in result.final_position
            )
        result.elapsed_s = time.perf_counter() - began
        return result

    # --- full -------------------------------------------------------------------------------------
    def _full(self, ch: Channel, text: str | TextIO, result: CheckResult) -> None:
        machine = self.machine
        ch.load_program(text if isinstance(text, str) else text.read(), self.name)
        ch.request_start()
        step = machine.step
        running = (ProgramState.RUNNING, ProgramState.HELD)
        record = self.record_path
        progress = self.progress
        step(1)
        countdown = 0
        kin_report = result.kinematics
        main = tuple(ch.axis_names.index(a) for a in ch.config.main_axes)
        switched: Transformation | None = None
        while ch.state in running and machine.cycle < self.max_cycles:
            step(1)
            if record and machine.cycle % 10 == 0:
                _record(result.path, tuple(ch.setpoints()))
                if ch.kinematic is not None:
                    _record(kin_report.tool_path, ch.tool_tip(ch.setpoints()))
            kinematic = ch.kinematic
            if kinematic is not None:
                if kinematic is not switched:  # switched on: the axes at rest where it was
                    switched = kinematic
                    start = ch.kinematic_from
                    kin_report.add(kinematic.kin_id, kinematic.name, start, kinematic.to_tip(start), main)
                axes = tuple(ch.setpoints())
                kin_report.add(kinematic.kin_id, kinematic.name, axes, kinematic.to_tip(axes), main)
            countdown -= 1
            if countdown <= 0:
                countdown = 1000
                if progress is not None:
                    progress(ch.interpreter.main_line, ch.decoder.blocks_decoded)
        if ch.state in running:
            result.capped = "cycles"
            result.cap = self.max_cycles
            machine.raise_alarm(
                ALARM_CYCLE_CAP,
                ch,
                f"the check stopped at its cap of {self.max_cycles} cycles: the program had not ended "
                f"(main program line {ch.interpreter.main_line}); raise --max-cycles if it should have",
                line=ch.current_block.line if ch.current_block is not None else None,
                block=ch.current_block.label if ch.current_block is not None else None,
            )
        else:
            # let the axes come to rest after an abort
            for _ in range(_SETTLE_CYCLES):
                if all(a.setpoint_step == 0.0 for a in ch.axes):
                    break
                step(1)
            result.completed = ch.state == ProgramState.FINISHED
        result.blocks = ch.decoder.blocks_decoded
        result.final_position = {a.name: a.setpoint for a in ch.axes}
        if record:
            _record(result.path, tuple(ch.setpoints()))

    # --- geometry ---------------------------------------------------------------------------------
    def _geometry(self, ch: Channel, text: str | TextIO, result: CheckResult) -> None:
        decoder = ch.decoder
        interpreter = ch.interpreter
        source = ProgramText(text, self.name)
        ch.program_name = self.name
        progress = self.progress
        try:
            if self.batch_in_use():
                batch = BatchGeometryCheck(ch)
                countdown = 0
                for items in batch.items(source, iteration_cap=self.max_iterations):
                    for item in items:
                        if isinstance(item, Marker):
                            self._marker(ch, item, result)
                        elif item.kin is not None:
                            self._kinematic_motion(ch, item, result, False)
                    countdown -= 1
                    if progress is not None and countdown <= 0:
                        countdown = 256
                        progress(batch.line, decoder.blocks_decoded)
            else:
                saved = (interpreter.budget, interpreter.iteration_cap)
                interpreter.budget = None
                interpreter.iteration_cap = self.max_iterations
                try:
                    self._exact(ch, source, result)
                finally:
                    interpreter.budget, interpreter.iteration_cap = saved
        except IterationCapError as cap:
            result.capped = "iterations"
            result.cap = cap.cap
            self.machine.raise_alarm(
                ALARM_ITERATION_CAP,
                ch,
                f"the geometry check stopped after {cap.cap} loop iterations and jumps back: the program "
                "had not ended (an endless loop?); raise --max-iterations if it should have",
                line=cap.line,
                block=cap.place,
            )
        result.blocks = decoder.blocks_decoded
        result.final_position = dict(zip(ch.axis_names, decoder.position, strict=True))

    def _exact(self, ch: Channel, source: ProgramText, result: CheckResult) -> None:
        decoder = ch.decoder
        ch.interpreter.start(source, source.name)
        decoder.start(ch.interpreter, ch.setpoints())
        record = self.record_path
        progress = self.progress
        motions = 0
        next_update = 4096
        while not decoder.finished:
            items = decoder.next_items()
            for item in items:
                if isinstance(item, Motion):
                    motions += 1
                    if item.kin is not None:
                        self._kinematic_motion(ch, item, result, record)
                    elif record:
                        result.path.extend(segment_points(item.segment))
                elif isinstance(item, Marker):
                    self._marker(ch, item, result)
            if progress is not None and motions >= next_update:
                next_update = motions + 4096
                progress(ch.interpreter.main_line, decoder.blocks_decoded)

    @staticmethod
    def _kinematic_motion(ch: Channel, item: Motion, result: CheckResult, record: bool) -> None:
        """A transformed block of a geometry check: its tool tip's path and its axes' path (the one the
        decoder checked: exact where the head's angles stand still, else its support points)."""
        kin = item.kin
        assert kin is not None
        report = result.kinematics
        report.used.setdefault(kin.trafo.kin_id, kin.trafo.name)
        main = tuple(ch.axis_names.index(a) for a in ch.config.main_axes)
        segments = kin.segments
        report.see_axes(segments[0].start if segments else item.axes_start())
        for seg in segments:
            for p in segment_points(seg):
                report.see_axes(p)
                if record:
                    result.path.append(p)
        if not segments:
            report.see_axes(item.axes_end())
        tips = segment_points(item.segment)
        report.see_tip(item.segment.start, main)
        for t in tips:
            report.see_tip(t, main)
        if record:
            report.tool_path.extend(tips)

    @staticmethod
    def _marker(ch: Channel, item: Marker, result: CheckResult) -> None:
        """A marker of a geometry check: without cycles, the path is at every marker at once."""
        if item.kind in (MarkerKind.ACTION, MarkerKind.SYNC):
            item.payload()
        elif item.kind == MarkerKind.END:
            ch.warn_missing_program_end(item)
            result.completed = True
        elif item.kind == MarkerKind.ERROR:
            ch.raise_decode_error(item)
