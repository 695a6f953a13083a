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
and jumps back. A full check stops sooner a program that waits on inputs nobody can change (N-13): no PLC
is attached, so a loop that turns while nothing moves, nothing is emitted and no variable changes
(``$WHILE V.E.PLC_READY == 0``) would turn until the cap; after :data:`WAIT_CYCLES` such cycles it stops
with warning :data:`ALARM_WAITING`, naming the loop and the ``V.E.`` variables it reads
(``capped.by == "waiting"``). ``presets`` give those inputs before the start (``engine/presets.py``). The
engine does no I/O: the program comes as a string or an open text stream.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
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
from hli_server.engine.nc.waiting import WaitingLoop
from hli_server.engine.planner import Marker, MarkerKind, Motion
from hli_server.engine.presets import PresetValue, apply_presets
from schemas.events import Event, NcMessage
from schemas.wire import ProgramState

__all__ = [
    "ALARM_CYCLE_CAP",
    "ALARM_ITERATION_CAP",
    "ALARM_WAITING",
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
ALARM_WAITING = 914052
"""Warning: the full check stopped a program that waits on inputs nobody can change (N-13)."""
WAIT_SAMPLE_CYCLES = 1000
"""Cycles between two looks at whether the program still makes progress."""
WAIT_CYCLES = 3 * WAIT_SAMPLE_CYCLES
"""A program whose loop turns this many cycles while nothing moves, nothing is emitted and no variable
changes is waiting on inputs nobody can change (3 s of machine time at 1 ms; a fraction of a second of
the check's): it cannot end, since its next statements depend on nothing else."""
WAIT_MIN_ITERATIONS = 100
"""Loop iterations (or jumps back) between two looks for the loop to count as turning (a loop that reads
a synchronous variable waits a cycle per iteration)."""
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
        """``cycles`` or ``iterations`` when the check stopped at its cap, ``waiting`` when it stopped a
        program waiting on inputs nobody can change (the program did not end)."""
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
    ``progress(line, blocks, cycles)`` is called now and then with the main program's line, the blocks
    decoded and the cycles run; ``presets`` are ``V.E.`` values written before the program starts
    (``engine/presets.py``: :class:`~hli_server.engine.presets.PresetError` from :meth:`run` for one that
    cannot be taken)."""

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
        progress: Callable[[int, int, int], None] | None = None,
        name: str = "check",
        presets: Mapping[str, PresetValue] | None = None,
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
        self.presets = dict(presets or {})

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
        apply_presets(machine.external, ch.number, self.presets)
        # a machine that has not run a cycle: its history is its start's (P-EXTV-00013 init's warnings)
        history_start = 0 if machine.cycle == 0 else len(machine.alarm_history)
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
        watch = _WaitWatch(machine, ch, result)
        stuck = False
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
                countdown = WAIT_SAMPLE_CYCLES
                if progress is not None:
                    progress(ch.interpreter.main_line, ch.decoder.blocks_decoded, machine.cycle)
                if watch.stuck():
                    stuck = True
                    break
        if stuck:
            self._waiting(ch, result, ch.interpreter.waiting_loop(), watch.since)
        elif ch.state in running:
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

    def _waiting(self, ch: Channel, result: CheckResult, loop: WaitingLoop | None, since: int) -> None:
        """Stop a program that waits on inputs nobody can change: warning 914052 at its loop."""
        machine = self.machine
        result.capped = "waiting"
        result.cap = machine.cycle
        still = machine.cycle - since
        program = f" of {loop.program}" if loop is not None and loop.program else ""
        if loop is not None and loop.variables:
            names = ", ".join(loop.variables)
            sets = " ".join(f"--set {n}=<value>" for n in loop.variables)
            them = "them" if len(loop.variables) > 1 else "it"
            what = (
                f"the program waits on {names}: its {_loop_name(loop.keyword)} at {loop.place}{program} "
                f"reads {them} and turned {still} cycles with nothing moving and nothing changing; no PLC "
                f"is attached to an offline check to change {them}: give the PLC's values ({sets}, or "
                "--set-file)"
            )
        elif loop is not None:
            what = (
                f"the program does not end: its {_loop_name(loop.keyword)} at {loop.place}{program} turned "
                f"{still} cycles with nothing moving, nothing emitted and no variable changing"
            )
        else:  # pragma: no cover - a program that turns without an open loop jumps back ($GOTO)
            what = f"the program does not end: it turned {still} cycles with nothing moving or changing"
        machine.raise_alarm(
            ALARM_WAITING,
            ch,
            what,
            line=loop.line if loop is not None else None,
            block=loop.place if loop is not None else None,
            params={"variables": loop.variables if loop is not None else [], "cycles": still},
        )

    # --- geometry ---------------------------------------------------------------------------------
    def _geometry(self, ch: Channel, text: str | TextIO, result: CheckResult) -> None:
        decoder = ch.decoder
        interpreter = ch.interpreter
        source = ProgramText(text, self.name)
        ch.program_name = self.name
        progress = self.progress
        # #CHANNEL INIT: the axes do not move here; the path's end the decoder keeps is where they would
        # be (their command positions once the path is at rest)
        positions, decoder.positions_handler = decoder.positions_handler, None
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
                        progress(batch.line, decoder.blocks_decoded, 0)
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
            loop = ch.interpreter.waiting_loop()
            inputs = ""
            if loop is not None and loop.variables:
                names = ", ".join(loop.variables)
                inputs = (
                    f"; its {_loop_name(loop.keyword)} at {loop.place} reads {names}, which no PLC changes "
                    f"in an offline check: give the PLC's values with --set {loop.variables[0]}=<value>"
                )
            self.machine.raise_alarm(
                ALARM_ITERATION_CAP,
                ch,
                f"the geometry check stopped after {cap.cap} loop iterations and jumps back: the program "
                f"had not ended (an endless loop?); raise --max-iterations if it should have{inputs}",
                line=cap.line,
                block=cap.place,
                params={"variables": loop.variables} if loop is not None and loop.variables else None,
            )
        finally:
            decoder.positions_handler = positions
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
                progress(ch.interpreter.main_line, decoder.blocks_decoded, 0)

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


def _loop_name(keyword: str) -> str:
    return "jump back" if keyword == "GOTO" else f"${keyword} loop"


class _WaitWatch:
    """Looks, every :data:`WAIT_SAMPLE_CYCLES`, whether a running program makes progress: its loop turns
    (iterations or jumps back) while the path rests, no block is decoded, nothing is emitted (an alarm, a
    message), and neither its variables nor the ``V.E.`` values change. :meth:`stuck` after
    :data:`WAIT_CYCLES` of that. Deterministic: cycles, not time."""

    def __init__(self, machine: Machine, ch: Channel, result: CheckResult) -> None:
        self.machine = machine
        self.ch = ch
        self.result = result
        self.last: tuple[object, ...] | None = None
        self.iterations = 0
        self.since = -1
        """The cycle from which nothing changed (-1: something did at the last look)."""

    def stuck(self) -> bool:
        ch = self.ch
        machine = self.machine
        planner = ch.planner
        interpreter = ch.interpreter
        history = machine.alarm_history
        turning = interpreter.iterations - self.iterations >= WAIT_MIN_ITERATIONS
        self.iterations = interpreter.iterations
        resting = (
            ch.state == ProgramState.RUNNING
            and planner.current() is None
            and planner.at_rest
            and all(a.setpoint_step == 0.0 for a in ch.axes)
        )
        if not (turning and resting):
            self.last = None
            self.since = -1
            return False
        external = machine.external
        now = (
            ch.decoder.blocks_decoded,
            len(history),
            id(history[-1]) if history else 0,
            len(self.result.messages),
            interpreter.state(),
            tuple(tuple(external.values(spec)) for spec in external),
        )
        if now != self.last:
            self.last = now
            self.since = machine.cycle
            return False
        return machine.cycle - self.since >= WAIT_CYCLES
