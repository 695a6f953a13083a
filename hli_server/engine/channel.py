"""A channel: mode, program, decoder, path interpolation, jog and referencing (E-03, E-05).

Inputs come from two doors, both latched at the start of a cycle: the PLC's HLI fields
(``mc_command``, ``bahn_mc_control``, the axes' ``manual``) and the operator's requests (HTTP API,
CLI, tests: :meth:`Channel.request_start` and friends). Outputs are published into ``bahn_state``
at the end of the cycle.

The program state and the mode are assigned in one place, :mod:`~hli_server.engine.channel_state`
(a table of every transition); this module decides *when* a cause happens (a start edge was
accepted, the path reached M30, an error reaction, ...) and tells the table.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, ClassVar, Final, Protocol, cast

from hli_server.engine.axis import Axis
from hli_server.engine.channel_state import PROGRAM_TRANSITIONS, Cause, ChannelState
from hli_server.engine.cycles import CycleError, MotionState
from hli_server.engine.cycles import run as run_standin
from hli_server.engine.cycles.errors import A_NOT_SIMULATED
from hli_server.engine.decoder import DecodeError, Decoder
from hli_server.engine.external import ExternalVariables
from hli_server.engine.geometry import LineSegment, Point
from hli_server.engine.hli import AxisHli, ChannelHli
from hli_server.engine.increments import increments_clamped
from hli_server.engine.kinematics.configured import data_sets
from hli_server.engine.kinematics.state import KinematicState
from hli_server.engine.kinematics.transform import Transformation
from hli_server.engine.nc.blocks import Block, NcError
from hli_server.engine.nc.compiler import Compiler
from hli_server.engine.nc.directives import Realtime
from hli_server.engine.nc.interpreter import Interpreter
from hli_server.engine.path.profiles import SlopeProfile, SlopeType
from hli_server.engine.path.tools import ToolData
from hli_server.engine.planner import Marker, MarkerKind, Motion, Planner
from hli_server.engine.ports import MachinePort
from hli_server.engine.programs import MemoryLibrary, ProgramFile
from hli_server.engine.realtime import RealtimeCycles, RtCycle
from schemas.config import ChannelConfig
from schemas.events import (
    Alarm,
    ControlUnitChanged,
    HoldChanged,
    ModeChanged,
    NcFileWrite,
    NcMessage,
    ProgramStateChanged,
)
from schemas.units import mm_from_increments, s_from_us
from schemas.wire import HoldSource, Mode, ProgramState

__all__ = ["LOOKAHEAD_ITEMS", "Channel", "ChannelHost", "JogGuard"]

LOOKAHEAD_ITEMS: Final = 64
"""Motion blocks decoded ahead of the interpolator (the look-ahead buffer, P-STUP-00070's size)."""

DRIVE_CYCLE_IDENTS = ("S-0-0001", "S-0-0002")
"""SERCOS idents of the cycle times (µs): NC cycle time TNcyc, communication cycle time tScyc."""

# enum members the cycle uses, as constants (a compiled module reads a Final name directly; any other
# module-level name is a dictionary lookup, an enum member an attribute lookup besides, on every use)
_NO_HOLD: Final = HoldSource.NONE
_FEEDHOLD: Final = HoldSource.FEEDHOLD
_MANUAL: Final = Mode.MANUAL

ALARM_REFUSED = 911021
"""Warning: a command not allowed in this mode or state (the text says which and why)."""
ALARM_NOT_REFERENCED = 911020
ALARM_STILL_BRAKING = 911022
"""Warning: program start refused while the channel's axes still brake (after a reset or a stop)."""


class JogGuard(Protocol):
    """Asked every cycle in manual mode: would the axes, braking from the next cycle on, stop at
    ``stop_point`` in a forbidden place (C14-19, E-06)? ``path`` is (current, stop_point)."""

    def must_brake(self, channel: Channel, current: Point, stop_point: Point) -> bool: ...


class ChannelHost:
    """What the interpreter asks of its channel (:class:`~hli_server.engine.nc.directives.Host`):
    programs, V.E. variables, messages, warnings, and the system variables it simulates (V.A., V.G.)."""

    def __init__(self, channel: Channel) -> None:
        self._channel = channel

    @property
    def channel_number(self) -> int:
        return self._channel.number

    @property
    def external(self) -> ExternalVariables:
        return self._channel.machine.external

    def find_program(self, name: str) -> ProgramFile | None:
        written = self._channel.written.find(name)
        if written is not None:
            return written
        return self._channel.machine.programs.find(name)

    def searched(self) -> tuple[str, ...]:
        return self._channel.machine.programs.searched()

    def find_cycle(self, name: str) -> ProgramFile | None:
        """A cycle's file: the program libraries first (:meth:`find_program`), then the channel's
        ``cycle_directories`` (CY-01)."""
        found = self.find_program(name)
        if found is not None:
            return found
        return self._channel.machine.cycle_library(self._channel.number).find(name)

    def cycle_searched(self) -> tuple[str, ...]:
        return (*self.searched(), *self._channel.machine.cycle_library(self._channel.number).searched())

    def stand_in(
        self,
        name: str,
        params: dict[int, float | str],
        results: Callable[[str, float], None],
        line: int,
        block: str,
    ) -> Iterator[Block] | None:
        """The blocks of the built-in stand-in of cycle ``name`` (engine/cycles), None where no documented
        cycle has the name; :class:`~hli_server.engine.cycles.CycleError` (910110) for one not built.
        ``results`` writes a ``V.CYC.`` output (the interpreter's)."""
        context = LoggedCycleContext(ChannelCycleContext(self._channel, results, line, block))
        try:
            blocks = run_standin(name, params, context, line)
        except CycleError as exc:
            raise _call_error(exc, line, block, name) from None
        return None if blocks is None else StandInRun(name, params, context, line, block, blocks)

    def implicit_program(self, g: int) -> str:
        """P-CHAN-00160..00169 (G80..G89) and P-CHAN-00187 (G800+i) of the channel (nc/implicit.py)."""
        config = self._channel.config
        if 80 <= g <= 89:
            return (
                config.g80_prog_file,
                config.g81_prog_file,
                config.g82_prog_file,
                config.g83_prog_file,
                config.g84_prog_file,
                config.g85_prog_file,
                config.g86_prog_file,
                config.g87_prog_file,
                config.g88_prog_file,
                config.g89_prog_file,
            )[g - 80]
        files = config.g800_prog_file
        return files[g - 800] if 0 <= g - 800 < len(files) else ""

    def message(self, text: str, save: bool, file: str, program: str, line: int, block: str) -> None:
        ch = self._channel
        m = ch.machine
        m.emit(
            NcMessage(
                cycle=m.cycle,
                time_s=m.cycle * ch.t_a,
                channel=ch.number,
                text=text,
                save=save,
                program=program,
                line=line,
                block=block,
            )
        )
        if save:
            m.emit(
                NcFileWrite(
                    cycle=m.cycle,
                    time_s=m.cycle * ch.t_a,
                    channel=ch.number,
                    file=file,
                    text=text,
                    program=program,
                    line=line,
                    block=block,
                )
            )

    def warn(self, alarm: int, message: str, line: int, block: str) -> None:
        ch = self._channel
        ch.machine.raise_alarm(alarm, ch, message, line=line, block=block)

    def axis_name(self, index: int) -> str | None:
        names = self._channel.axis_names
        return names[index] if 0 <= index < len(names) else None

    def drive_value(self, axis: str, ident: str) -> float | None:
        """``#IDENT RD``: the idents the simulated drive has of its own (S-0-0001 the NC cycle time and
        S-0-0002 the communication cycle time, both the channel's cycle time in µs); None for any other."""
        if ident in DRIVE_CYCLE_IDENTS and axis:
            return float(round(self._channel.t_a * 1e6))
        return None

    def axis_value(self, variable: str, axis: str) -> float | None:
        """V.A.: ABS and PROG (the end of the last block, program coordinates), ACT_POS (the axis'
        command position now, after the flush the read causes), the software limits."""
        ch = self._channel
        decoder = ch.decoder
        k = decoder.index.get(axis)
        if k is None:
            return None
        if variable in ("ABS", "PROG"):
            return decoder.program_position()[k]
        if variable == "ACT_POS":
            if decoder.transforms_active:
                setpoints = [a.setpoint for a in ch.axes]
                return decoder.to_program(setpoints, decoder.tools.applied_length)[k]
            return ch.axes[k].setpoint - decoder.modal.offset(axis)
        if variable in ("-SWE", "-SWE_MDS"):
            return ch.axes[k].swe_neg
        if variable in ("+SWE", "+SWE_MDS"):
            return ch.axes[k].swe_pos
        return None

    def global_value(self, name: str) -> float | None:
        """V.G.: BLOCK_NR, FEEDRATE, FEEDRATE_MODE, I, J, K (the last circle's), MASS_MM, MASS_360."""
        decoder = self._channel.decoder
        if name == "BLOCK_NR":
            block = decoder.current_block
            return float(block.number or 0) if block is not None else 0.0
        if name == "FEEDRATE":
            return decoder.modal.feed or 0.0
        if name == "FEEDRATE_MODE":
            return 94.0
        if name in ("MASS_MM", "MASS_360"):
            return 0.0
        if name in ("I", "J", "K"):
            return decoder.last_centre.get(name, 0.0)
        return _tool_and_frame_value(decoder, name)


def _call_error(exc: CycleError, line: int, block: str, program: str) -> NcError:
    """A built-in cycle's error as the alarm of its call's line (the kernel stops the program there)."""
    params: dict[str, object] = {"cycle": program}
    if exc.param:
        params["param"] = exc.param
    return NcError(exc.alarm, line, block, exc.message, params)


class StandInRun:
    """One run of a built-in cycle as the interpreter's level holds it: the iterator of its blocks, each
    :class:`CycleError` as the alarm of the call's line.

    A stand-in is a Python generator (engine/cycles), which a recording's snapshot cannot keep
    (recording/snapshot.py: it is code in the middle of running). This keeps what rebuilds it instead: the
    call (cycle, @P values, line), how many blocks it gave (``taken``) and every answer its context gave
    (:class:`LoggedCycleContext`). A snapshot leaves the generator out (``snapshot_transient``); the
    first block asked for after the restore runs the stand-in again from its start, answering its reads
    from the log and dropping the ``taken`` blocks it already gave (its writes took effect then, the
    snapshot holds them), then goes on live: the same blocks, as the generator is deterministic in what it
    reads (docs/record-replay.md, "A recording started in a running server")."""

    snapshot_transient: ClassVar[tuple[str, ...]] = ("_blocks",)

    def __init__(
        self,
        name: str,
        params: dict[int, float | str],
        context: LoggedCycleContext,
        line: int,
        block: str,
        blocks: Iterator[Block] | None,
    ) -> None:
        self.name = name
        self.params = params
        self.context = context
        self.line = line
        self.block = block
        self.taken = 0
        self.done = False
        self._blocks = blocks

    def __iter__(self) -> StandInRun:
        return self

    def __next__(self) -> Block:
        if self.done:
            raise StopIteration
        try:
            blocks = self._blocks
            if blocks is None:
                blocks = self._rebuild()
            block = next(blocks, None)
        except CycleError as exc:
            self.done = True
            raise _call_error(exc, self.line, self.block, self.name) from None
        if block is None:
            self.done = True
            raise StopIteration
        self.taken += 1
        return block

    def _rebuild(self) -> Iterator[Block]:
        """The stand-in run again up to where the snapshot took it, from the log of its reads."""
        context = self.context
        context.rewind()
        blocks = run_standin(self.name, self.params, context, self.line)
        if blocks is None:  # the name was a documented cycle when it was called: the same engine
            raise CycleError(A_NOT_SIMULATED, f"{self.name}: no stand-in to resume")
        for _ in range(self.taken):
            if next(blocks, None) is None:
                break
        context.go_live()
        self._blocks = blocks
        return blocks


class LoggedCycleContext:
    """A stand-in's :class:`~hli_server.engine.cycles.CycleContext` that logs every answer the channel
    gave it, so that a run rebuilt after a snapshot's restore reads the same (:class:`StandInRun`): while
    it is rebuilt, reads come from the log and writes are dropped (they took effect the first time)."""

    def __init__(self, live: ChannelCycleContext) -> None:
        self.live = live
        self.axis_names: tuple[str, ...] = live.axis_names
        self.main_axes: tuple[str, str, str] = live.main_axes
        self.log: list[Any] = []
        self.replayed = -1
        """While the run is rebuilt: how many answers of the log it was given again; -1: live."""

    def rewind(self) -> None:
        self.replayed = 0

    def go_live(self) -> None:
        self.replayed = -1

    def _read(self, fetch: Callable[[], Any]) -> Any:
        """The logged answer while rebuilding, else the channel's (logged)."""
        if 0 <= self.replayed < len(self.log):
            self.replayed += 1
            return self.log[self.replayed - 1]
        self.replayed = -1  # past the log: live from here
        value = fetch()
        self.log.append(value)
        return value

    def _writes(self) -> bool:
        return self.replayed < 0

    def position(self) -> tuple[float, float, float]:
        return cast(tuple[float, float, float], self._read(self.live.position))

    def plane(self) -> int:
        return cast(int, self._read(self.live.plane))

    def inch(self) -> bool:
        return cast(bool, self._read(self.live.inch))

    def tool_radius(self) -> float:
        return cast(float, self._read(self.live.tool_radius))

    def zero_offset(self) -> str | None:
        return cast("str | None", self._read(self.live.zero_offset))

    def motion_state(self) -> MotionState:
        return cast(MotionState, self._read(self.live.motion_state))

    def measured(self) -> float | None:
        return cast("float | None", self._read(self.live.measured))

    def deviation(self) -> tuple[float, float, float]:
        return cast(tuple[float, float, float], self._read(self.live.deviation))

    def probe_feeds(self) -> tuple[float, float]:
        return cast(tuple[float, float], self._read(self.live.probe_feeds))

    def write_zero_offset(self, name: str, values: Mapping[str, float]) -> None:
        if self._writes():
            self.live.write_zero_offset(name, values)

    def set_result(self, name: str, value: float) -> None:
        if self._writes():
            self.live.set_result(name, value)

    def write_program(self, name: str, text: str) -> None:
        if self._writes():
            self.live.write_program(name, text)

    def warn(self, alarm: int, message: str) -> None:
        if self._writes():
            self.live.warn(alarm, message)


class ChannelCycleContext:
    """What a built-in cycle reads of and writes to its channel (engine/cycles' :class:`CycleContext`):
    the decoder's state in program order (the interpreter runs a stand-in lazily, and decoding waits for a
    measuring move to end), the simulated probe's deviation, the results."""

    def __init__(
        self, channel: Channel, results: Callable[[str, float], None], line: int, block: str
    ) -> None:
        self._channel = channel
        self._results = results
        self._line = line
        self._block = block
        self.axis_names: tuple[str, ...] = tuple(channel.axis_names)
        self.main_axes: tuple[str, str, str] = channel.config.main_axes

    def _main(self, values: Sequence[float]) -> tuple[float, float, float]:
        index = self._channel.decoder.index
        x, y, z = self.main_axes
        return values[index[x]], values[index[y]], values[index[z]]

    def position(self) -> tuple[float, float, float]:
        return self._main(self._channel.decoder.program_position())

    def plane(self) -> int:
        return self._channel.decoder.modal.plane

    def inch(self) -> bool:
        return self._channel.decoder.modal.inch

    def tool_radius(self) -> float:
        return abs(self._channel.decoder.tools.radius)

    def zero_offset(self) -> str | None:
        return self._channel.decoder.modal.zero_offset

    def motion_state(self) -> MotionState:
        modal = self._channel.decoder.modal
        return MotionState(modal.absolute, modal.motion, modal.feed)

    def measured(self) -> float | None:
        return self._channel.decoder.measured

    def deviation(self) -> tuple[float, float, float]:
        values = self._channel.machine.probe_deviation(self._channel.number)
        x, y, z = self.main_axes
        return values.get(x, 0.0), values.get(y, 0.0), values.get(z, 0.0)

    def probe_feeds(self) -> tuple[float, float]:
        probe = self._channel.config.probe
        return probe.measuring_feed, probe.positioning_feed

    def write_zero_offset(self, name: str, values: Mapping[str, float]) -> None:
        self._channel.decoder.modal.zero_offsets.setdefault(name, {}).update(values)

    def set_result(self, name: str, value: float) -> None:
        self._results(name, value)

    def write_program(self, name: str, text: str) -> None:
        self._channel.written.write(name, text)

    def warn(self, alarm: int, message: str) -> None:
        ch = self._channel
        ch.machine.raise_alarm(alarm, ch, message, line=self._line, block=self._block)


def _tool_and_frame_value(decoder: Decoder, name: str) -> float | None:
    """V.G. (M-12, M-14): the active tool's data (WZ_AKT.R/.L/.NR, WZR, WZL) and #ROTATION's (ROT_ACTIVE,
    ROT_ANGLE, ROT_CENTER1, ROT_CENTER2), as the decoder has them at the block being decoded."""
    tools = decoder.tools
    rotation = decoder.frames.rotation
    values: dict[str, float] = {
        "WZ_AKT.R": tools.radius,
        "WZR": tools.radius,
        "WZ_AKT.L": tools.length,
        "WZL": tools.length,
        "WZ_AKT.NR": float(tools.d),
        "ROT_ACTIVE": 1.0 if rotation is not None else 0.0,
        "ROT_ANGLE": rotation[0] if rotation is not None else 0.0,
        "ROT_CENTER1": rotation[1] if rotation is not None else 0.0,
        "ROT_CENTER2": rotation[2] if rotation is not None else 0.0,
    }
    return values.get(name)


class Channel:
    def __init__(
        self,
        machine: MachinePort,
        config: ChannelConfig,
        index: int,
        axes: list[Axis],
        hli: ChannelHli,
        axis_hli: Sequence[AxisHli],
    ) -> None:
        self.machine = machine
        self.config = config
        self.index = index
        self.number = config.number
        self.axes = axes
        self.axis_names = [a.name for a in axes]
        self.hli = hli
        self._axis_hli = [axis_hli[a.index] for a in axes]
        self.t_a = machine.t_a
        self._state = ChannelState(self._program_changed, self._mode_changed)
        self.program_text: str | None = None
        self.program_name = ""
        self.program_number = 0
        zero_offsets: dict[str, dict[str, float]] = {
            str(zo.code): {ax: mm_from_increments(v) for ax, v in zo.offsets.items()}
            for zo in config.zero_offsets
        }
        self.decoder = Decoder(
            self.axis_names,
            config.main_axes,
            {a.name: (a.v_max, a.v_rapid, a.a_max) for a in axes},
            zero_offsets,
            {
                t.number: ToolData(
                    t.number, mm_from_increments(t.length), mm_from_increments(t.radius), t.tool, t.kin_id
                )
                for t in config.tools
            },
            KinematicState(data_sets(config.kinematics), config.kinematik_id, len(axes)),
        )
        self.kinematic: Transformation | None = None
        """The transformation the axes follow now (switched in program order, at rest): the tool tip is
        its forward transformation of the axes (docs/kinematics.md)."""
        self.kinematic_from: tuple[float, ...] = ()
        """The axes where the transformation was last switched (at rest there: the next move's start)."""
        self.decoder.kinematic_handler = self._kinematic_changed
        self.decoder.axis_numbers = [a.config.number for a in axes]
        self.decoder.tracking_axis_number = config.log_number_tracking_axis
        self.decoder.default_feed = config.default_feedrate
        self.decoder.tool_ori_cs = (config.tool_ori_cs_axis, config.tool_ori_cs_mode)
        self.decoder.soft_limits = self._soft_limits  # a method, not a closure: a snapshot keeps it
        self._main_slots = tuple(self.axis_names.index(a) for a in config.main_axes)
        self.compiler = Compiler(self.axis_names, config.main_axes)
        self.written = MemoryLibrary(where="files written by cycles")
        """Program files the channel's cycles wrote (a teach-in's ``CS_BASE_<n>.bcs``): ``L name`` finds
        them before the program directories, as the kernel finds the file a cycle just wrote."""
        self.interpreter = Interpreter(self.compiler, ChannelHost(self))
        self.decoder.warn = ChannelHost(self).warn
        self.decoder.corner_ahead = self.interpreter.corner_ahead
        self.decoder.homing = {a.name: (a.home_position, a.jog_velocity, a.jog_acceleration) for a in axes}
        self.decoder.referenced_handler = self._referenced_by_program
        self.realtime = RealtimeCycles(
            self.number,
            machine.external,
            self._rt_position,
            self._operator_override,
            self._rt_fail,
        )
        """The realtime cycles (``#RT CYCLE``, TF5261): run in every cycle before the path's step."""
        self.decoder.realtime_handler = self._realtime
        """Runs the NC programs of this channel ahead of the motion (N-01..N-08)."""
        self.planner = Planner(t_a=self.t_a, feedhold_decel=config.feedhold_deceleration)
        self.slope_ramp_time = max(
            (
                s_from_us(
                    max(
                        a.config.tr_beschl_ab,
                        a.config.tr_beschl_zu,
                        a.config.tr_brems_ab,
                        a.config.tr_brems_zu,
                    )
                )
                for a in axes
            ),
            default=0.0,
        )
        """The ramp time of the jerk-limited profiles [s]: the longest of the axes' P-AXIS-00195..00198."""
        self.decoder.slope_handler = self.set_slope
        self.decoder.positions_handler = self.axis_positions
        self.decoder.rotary_axes = frozenset(a.name for a in axes if a.rotary)
        self.jog_guards: list[JogGuard] = []
        self.jog_velocity: list[float] = [0.0] * len(axes)
        self.current_block: Block | None = None
        self.aborting = False
        """An error ended the program and the path still brakes to rest."""
        self.monitor_holds = HoldSource.NONE
        """Holds that monitors put on the path this cycle (set before interpolation)."""
        self.hold_source = HoldSource.NONE
        # operator requests (API), latched at the next cycle
        self._req_start = False
        self._req_reset = False
        self._req_mode: int | None = None
        self._req_feedhold: bool | None = None
        self._req_override: int | None = None
        self._req_jog: dict[int, int] = {}
        self._req_reference: set[int] = set()
        self._jog_keys: list[int] = [0] * len(axes)
        self._op_feedhold = False
        self._op_override = 1000
        self._prev_start_w = False
        self._prev_reset_w = False
        self._prev_mode_w: int = Mode.AUTOMATIC
        self._prev_reference_w = [False] * len(axes)
        self.feedhold_active = False
        self.override_permille = 1000
        self.interpolate: Callable[[], None] = self._interpolate
        """One cycle of path, jog or referencing (the machine calls it). An attribute, not a method, so
        that a test can put a failing function in its place where the engine is compiled (mypyc's
        classes refuse to have a method replaced; docs/performance.md)."""

    # --- state ---------------------------------------------------------------------------
    @property
    def state(self) -> ProgramState:
        """The program state (``bahn_state.program_state_r``)."""
        return self._state.program

    @property
    def mode(self) -> Mode:
        """The mode (``bahn_state.mode_r``)."""
        return self._state.mode

    @property
    def program_running(self) -> bool:
        """A program runs (RUNNING or HELD): no other program, no mode change."""
        return self._state.running

    def _program_changed(self, new: ProgramState, previous: ProgramState, cause: Cause) -> None:
        m = self.machine
        m.emit(
            ProgramStateChanged(
                cycle=m.cycle,
                time_s=m.time,
                channel=self.number,
                state=new.label,
                code=int(new),
                previous=previous.label,
                cause=cause.value,
                program=self.program_name,
            )
        )

    def _mode_changed(self, new: Mode, previous: Mode) -> None:
        m = self.machine
        m.emit(
            ModeChanged(
                cycle=m.cycle,
                time_s=m.time,
                channel=self.number,
                mode=new.label,
                previous=previous.label,
            )
        )

    def _refuse(self, message: str, number: int = ALARM_REFUSED) -> Alarm:
        return self.machine.raise_alarm(number, self, message)

    # --- operator requests ---------------------------------------------------------------
    def _soft_limits(self, k: int) -> tuple[float, float]:
        """The software limits in effect of axis ``k`` (the decoder's two-path check asks)."""
        axis = self.axes[k]
        return (axis.swe_neg, axis.swe_pos)

    def load_program(self, text: str, name: str = "program", number: int = 0) -> Alarm | None:
        """Select a program (text). Refused (the alarm is returned) while a program runs."""
        if self.program_running:
            return self._refuse(f"cannot load {name!r}: a program is running ({self.program_name!r})")
        self.program_text = text
        self.program_name = name
        self.program_number = number
        self._state.apply(Cause.LOAD)
        return None

    def request_start(self) -> None:
        self._req_start = True

    def request_reset(self) -> None:
        self._req_reset = True

    def request_mode(self, mode: int) -> None:
        self._req_mode = mode

    def request_feedhold(self, on: bool) -> None:
        self._req_feedhold = on

    def request_override(self, permille: int) -> None:
        self._req_override = max(0, min(1200, permille))

    def request_jog(self, axis: str, direction: int) -> None:
        """direction +1, -1, or 0 (release the key)."""
        self._req_jog[self.axis_names.index(axis)] = max(-1, min(1, direction))

    def request_reference(self, axis: str) -> None:
        """Reference (home) ``axis`` at the next cycle, as a rising edge of ``manual.reference_w``."""
        self._req_reference.add(self.axis_names.index(axis))

    # --- positions -----------------------------------------------------------------------
    def setpoints(self) -> list[float]:
        return [a.setpoint for a in self.axes]

    def tool_tip(self, point: Sequence[float]) -> Point:
        """The tool tip (the TCP the areas monitor) for the axis positions ``point``: the forward
        transformation where one is on (K-05), else less the tool length the decoder has put into the tool
        axis (M-15)."""
        kinematic = self.kinematic
        if kinematic is not None:
            return kinematic.to_tip(point)
        decoder = self.decoder
        if decoder.tools.applied_length == 0.0:
            return tuple(point)
        return decoder.tip_segment(LineSegment(tuple(point), tuple(point))).start

    def axis(self, name: str) -> Axis:
        return self.axes[self.axis_names.index(name)]

    # --- the cycle -----------------------------------------------------------------------
    def latch_inputs(self) -> None:
        hli = self.hli
        cmd = hli.mc_command
        if self._req_reset or (cmd.reset_w and not self._prev_reset_w):
            self.reset()
        self._prev_reset_w = cmd.reset_w
        self._req_reset = False
        mode_req = self._req_mode
        if cmd.mode_w != self._prev_mode_w:
            mode_req = cmd.mode_w
        self._prev_mode_w = cmd.mode_w
        self._req_mode = None
        if mode_req is not None and mode_req != self.mode:
            self.change_mode(mode_req)
        if cmd.program_select_w and cmd.program_select_w != self.program_number:
            self.select_program(cmd.program_select_w)
        start = self._req_start or (cmd.start_w and not self._prev_start_w)
        self._prev_start_w = cmd.start_w
        self._req_start = False
        if start:
            self.start()
        self._latch_references()
        # feedhold and override: control units; the CNC's own request is the operator's
        if self._req_feedhold is not None:
            self._op_feedhold = self._req_feedhold
            self._req_feedhold = None
        if self._req_override is not None:
            self._op_override = self._req_override
            self._req_override = None
        ctl = hli.bahn_mc_control
        ctl.feedhold.request_r = self._op_feedhold
        ctl.override.request_r = self._op_override
        self.feedhold_active = ctl.feedhold.effective()
        self.override_permille = max(0, min(1200, ctl.override.effective()))
        suppress = ctl.suppress_area_mon_manual_mode.effective()
        if (
            ctl.feedhold.state_r != self.feedhold_active
            or ctl.override.state_r != self.override_permille
            or ctl.suppress_area_mon_manual_mode.state_r != suppress
        ):
            self._unit_changed("feedhold", ctl.feedhold.state_r, self.feedhold_active)
            self._unit_changed("override", ctl.override.state_r, self.override_permille)
            self._unit_changed(
                "suppress_area_mon_manual_mode", ctl.suppress_area_mon_manual_mode.state_r, suppress
            )
            ctl.feedhold.state_r = self.feedhold_active
            ctl.override.state_r = self.override_permille
            ctl.suppress_area_mon_manual_mode.state_r = suppress
        for k, direction in self._req_jog.items():
            self._jog_keys[k] = direction
        self._req_jog.clear()
        self.monitor_holds = _NO_HOLD

    def _unit_changed(self, unit: str, previous: int | bool, state: int | bool) -> None:
        if previous == state:
            return
        m = self.machine
        m.emit(
            ControlUnitChanged(
                cycle=m.cycle,
                time_s=m.time,
                channel=self.number,
                unit=f"gpCh[{self.index}]^bahn_mc_control.{unit}",
                state=state,
                previous=previous,
            )
        )

    def select_program(self, number: int) -> Alarm | None:
        """Select program ``number`` of the program table; the refusal alarm, or None."""
        for entry in self.config.programs:
            if entry.number != number:
                continue
            if self.program_running:
                return self._refuse(f"cannot select program {number}: a program is running")
            text = entry.text
            read = self.machine.read_program
            if text is None and read is not None and entry.path is not None:
                try:
                    text = read(entry.path)
                except (OSError, UnicodeDecodeError) as exc:
                    return self._refuse(f"program {number}: cannot read {entry.path}: {exc}")
            if text is None:
                return self._refuse(f"program {number}: no program text for {entry.path}")
            return self.load_program(text, entry.name, number)
        return self._refuse(f"program number {number} is not in the program table")

    def start(self) -> None:
        """A start edge: the program starts when the channel can run it, else a warning says why."""
        if self.mode != Mode.AUTOMATIC:
            self._refuse("program start refused: channel is in manual mode")
            return
        if self.program_running:
            return  # a start while the program runs changes nothing
        if self.machine.channel_has_error(self):
            self._refuse("program start refused: reset the error first")
            return
        if (self.state, Cause.START) not in PROGRAM_TRANSITIONS:
            self._refuse(f"program start refused: the program is {self.state.label}; reset the channel first")
            return
        if self.program_text is None:
            self._refuse("program start refused: no program selected")
            return
        not_referenced = [a.name for a in self.axes if not a.referenced]
        if not_referenced:
            self.machine.raise_alarm(
                ALARM_NOT_REFERENCED,
                self,
                f"program start refused: axes not referenced: {', '.join(not_referenced)}; reference them "
                "first (gpAx[i]^manual.reference_w or POST /api/axes/{name}/reference)",
            )
            return
        still = [a.name for a in self.axes if a.stopping or a.referencing]
        if still:
            self._refuse(
                f"program start refused: axes {', '.join(still)} still brake or reference; start again once "
                "they are at rest (gpAx[i]^ipo_state.moving_r FALSE)",
                ALARM_STILL_BRAKING,
            )
            return
        self.interpreter.start(self.program_text, self.program_name)
        self.realtime.end_program()
        self.planner.clear()
        self.set_slope(None)  # P-CHAN-00071 at every program start (#SLOPE's page)
        self.decoder.start(self.interpreter, self.setpoints())
        self.kinematic = None
        self.aborting = False
        self.current_block = None
        self._state.apply(Cause.START)

    def _kinematic_changed(self, trafo: Transformation | None) -> None:
        """``#TRAFO ON``/``OFF`` reached (the path at rest): the axes follow ``trafo`` from here."""
        self.kinematic = trafo
        item = self.planner.current()
        self.kinematic_from = item.axes_start() if isinstance(item, Motion) else tuple(self.setpoints())

    def axis_positions(self, actual: bool) -> list[float]:
        """The axes' command positions, or their actual positions (``#CHANNEL INIT [ACTPOS]``: the position
        loop's, which a drive fault or the following error can set apart), in machine coordinates."""
        return [a.actual if actual else a.setpoint for a in self.axes]

    def set_slope(self, profile: int | None) -> None:
        """The acceleration profile from now on (``#SLOPE``, M-01..M-03): 0 STEP, 1 TRAPEZ, 2 SIN2,
        3 HSC (simulated as TRAPEZ); None: P-CHAN-00071's, as at program start (``#SLOPE DEFAULT``)."""
        value = self.config.slope_profile if profile is None else profile
        active = SlopeProfile(SlopeType(value), self.slope_ramp_time)
        self.planner.set_profile(active)
        ramp = 0.0 if active.type == SlopeType.STEP else self.slope_ramp_time
        for axis in self.axes:
            axis.slope_ramp = ramp  # independent stops (reset, collision) in the profile too (M-05)

    def reset(self) -> None:
        """E-03: stop motion, clear the channel's errors, reset modal state; hooks for the monitors."""
        for axis in self.axes:
            if axis.referencing:
                axis.cancel_referencing()
            axis.start_independent_stop(axis.a_max, self.t_a)
        self.planner.clear()
        self.decoder.reset_modal()
        self.interpreter.reset()
        self.realtime.end_program()
        self.kinematic = None
        self.aborting = False
        self.jog_velocity = [0.0] * len(self.axes)
        self._jog_keys = [0] * len(self.axes)
        self.current_block = None
        self._state.apply(Cause.RESET)
        for axis in self.axes:
            axis.reload_soft_limits()  # P-AXIS-00177/00178: from the axis record at reset
        self.machine.channel_reset(self)

    def change_mode(self, mode: int) -> None:
        try:
            target = Mode(mode)
        except ValueError:
            self._refuse(f"unknown mode {mode} (0 automatic, 1 manual)")
            return
        if self.program_running:
            self._refuse("mode change refused: a program is running")
            return
        if any(abs(v) > 0 for v in self.jog_velocity):
            self._refuse("mode change refused: axes are jogging")
            return
        if not self.machine.allow_mode_change(self, target):
            return
        if target != self.mode:
            for axis in self.axes:
                axis.reload_soft_limits()  # P-AXIS-00177/00178: from the axis record at a mode change
        self._state.set_mode(target)

    def abort(self) -> None:
        """Program abort (an error reaction): the path brakes with the feedhold deceleration."""
        if self.program_running:
            self.aborting = True
            self._state.apply(Cause.ERROR)

    def hold(self, source: HoldSource) -> None:
        """A monitor holds the path this cycle (call before interpolation, every cycle it holds)."""
        self.monitor_holds |= source

    def _interpolate(self) -> None:
        if self.realtime.cycles:
            self.realtime.run()
        holds = self.monitor_holds
        if self.feedhold_active:  # no Flag union in the common cycle: Python's Flag.__or__ costs a few µs
            holds |= _FEEDHOLD
        self._set_holds(holds)
        if any(a.referencing for a in self.axes):
            self._reference()
        if any(a.stopping for a in self.axes):
            # axes brake on their own (collision, drive error, reset): the path is lost
            self.planner.clear()
            self.abort()
            self.aborting = False
            return
        if self.mode is _MANUAL:
            self._jog()
            return
        if self.aborting:
            self.planner.feedhold = True
            point, _ = self.planner.step()
            self._apply(point)
            if self.planner.at_rest:
                self.planner.clear()
                self.aborting = False
            return
        if not self.program_running:
            return
        self._fill()
        self.planner.feedhold = self.feedhold_active
        self.planner.override = self.override_permille / 1000.0 * self.realtime.override
        point, markers = self.planner.step()
        self._apply(point)
        head = self.planner.current()
        if head is not None and head.block is not None:
            self.current_block = head.block
        for marker in markers:
            self._marker(marker)
        self._state.set_held(bool(holds) and self.planner.at_rest)

    def _set_holds(self, holds: HoldSource) -> None:
        if holds == self.hold_source:
            return
        self.hold_source = holds
        m = self.machine
        m.emit(
            HoldChanged(
                cycle=m.cycle,
                time_s=m.time,
                channel=self.number,
                hold_source=int(holds),
                sources=tuple(holds.labels),
            )
        )

    def _fill(self) -> None:
        """Decode ahead: up to the look-ahead's size, within the interpreter's budget for this cycle
        (docs/check.md: a program that computes without moving goes on next cycle)."""
        self.interpreter.refill()
        decoder = self.decoder
        planner = self.planner
        while planner.motion_items < LOOKAHEAD_ITEMS and not decoder.finished:
            items = decoder.next_items()
            if not items:
                break
            for item in items:
                planner.push(item)

    def _apply(self, point: Point | None) -> None:
        if point is None:
            return
        for axis, value in zip(self.axes, point):  # noqa: B905 compiled: see geometry.py
            axis.setpoint = value

    def _marker(self, marker: Marker) -> None:
        if marker.block is not None:
            self.current_block = marker.block
        if marker.kind in (MarkerKind.ACTION, MarkerKind.SYNC):
            marker.payload()
        elif marker.kind == MarkerKind.END:
            self.warn_missing_program_end(marker)
            self.realtime.end_program()
            self.planner.clear()
            self.kinematic = None  # the program's end deselects the transformation (docs/kinematics.md)
            if self.program_running:
                self._state.apply(Cause.END)
        elif marker.kind == MarkerKind.ERROR:
            self.raise_decode_error(marker)
            self.planner.clear()

    def raise_decode_error(self, marker: Marker) -> None:
        """The alarm an error marker carries, with the line and block of the refused block (or, for
        a line the parser could not read, the place the parser named)."""
        err: DecodeError = marker.payload
        block = marker.block
        line = block.line if block is not None else err.params.get("line")
        label = block.label if block is not None else err.params.get("block")
        params = err.params
        if block is not None and block.program and "program" not in params:
            params = {**params, "program": block.program}
        self.machine.raise_alarm(
            err.alarm, self, err.message, line=line, block=label, params=params, axis=err.axis
        )

    def warn_missing_program_end(self, marker: Marker) -> None:
        """Warning 911005 when the program ran off the end of its text without M30 / M02."""
        if marker.payload == "eof":
            block = marker.block
            self.machine.raise_alarm(
                911005,
                self,
                "program ended at the end of its text without M30 / M02",
                line=block.line if block is not None else None,
                block=block.label if block is not None else None,
            )

    # --- referencing (homing) ------------------------------------------------------------
    def _latch_references(self) -> None:
        for k, hli in enumerate(self._axis_hli):
            level = hli.manual.reference_w
            edge = (level and not self._prev_reference_w[k]) or k in self._req_reference
            self._prev_reference_w[k] = level
            if edge:
                self._begin_reference(self.axes[k])
        self._req_reference.clear()

    def _begin_reference(self, axis: Axis) -> None:
        if self.program_running:
            self._refuse(f"referencing {axis.name} refused: a program is running")
            return
        if axis.stopping or self.jog_velocity[self.axes.index(axis)] != 0.0:
            self._refuse(f"referencing {axis.name} refused: the axis is moving")
            return
        if axis.referencing:
            return
        axis.start_referencing()
        self.machine.referencing_changed(axis.index)

    # --- realtime cycles (#RT CYCLE) -------------------------------------------------------------------
    def _operator_override(self) -> float:
        """The operator's override (0..1) a realtime cycle's override multiplies (a method, not a closure:
        a recording's snapshot keeps it)."""
        return self.override_permille / 1000.0

    def _realtime(self, command: Realtime) -> None:
        """``#RT CYCLE`` reached by the path: a cycle defined (running unless ``DEF``) or managed."""
        if command.op == "DEFINE":
            block = command.block if command.block is not None else Block(0, None, "")
            self.realtime.define(RtCycle(command.ident, command.scope, command.body, block), command.start)
        else:
            self.realtime.manage(command.op, command.ident)

    def _rt_position(self, kind: str, axis: str) -> float | None:
        """V.RTA.<ACS|MCS>.<kind>.<axis> in mm: the command position (ACT_POS, CMD_POS) or the actual one
        (CUR_POS); axis and machine coordinates are the same here (no transformation below the CS)."""
        if axis not in self.axis_names:
            return None
        a = self.axes[self.axis_names.index(axis)]
        return a.actual if kind == "CUR_POS" else a.setpoint

    def _rt_fail(self, error: NcError) -> None:
        self.machine.raise_alarm(error.alarm, self, error.message, line=error.line, block=error.block)

    def _referenced_by_program(self, names: tuple[str, ...]) -> None:
        """A G74 group arrived at its reference positions: its axes are referenced (E-02)."""
        for name in names:
            axis = self.axes[self.axis_names.index(name)]
            axis.referenced = True
            self.machine.referencing_changed(axis.index)

    def _reference(self) -> None:
        for axis in self.axes:
            if axis.referencing and not axis.stopping and axis.advance_referencing(self.t_a):
                self.machine.referencing_changed(axis.index)

    # --- manual mode ---------------------------------------------------------------------
    def _jog(self) -> None:
        """E-05 jog: each axis ramps to its jog velocity while its key is held; guards may brake."""
        t = self.t_a
        req = list(self._jog_keys)
        for k, hli in enumerate(self._axis_hli):
            man = hli.manual
            if man.jog_plus_w != man.jog_minus_w:
                req[k] = 1 if man.jog_plus_w else -1
            if self.axes[k].referencing:
                req[k] = 0
        current = tuple(self.setpoints())
        proposed = list(self.jog_velocity)
        for k, axis in enumerate(self.axes):
            target = req[k] * axis.jog_velocity
            v = proposed[k]
            dv = axis.jog_acceleration * t
            proposed[k] = min(v + dv, target) if target > v else max(v - dv, target)
        # where would the axes come to rest if they began braking after this cycle?
        stop_point = tuple(
            p + v * t + math.copysign(v * v / (2.0 * a.jog_acceleration), v)
            for p, v, a in zip(current, proposed, self.axes, strict=True)
        )
        if any(proposed) and any(g.must_brake(self, current, stop_point) for g in self.jog_guards):
            for k, axis in enumerate(self.axes):
                v = self.jog_velocity[k]
                dv = axis.jog_acceleration * t
                proposed[k] = max(0.0, v - dv) if v > 0 else min(0.0, v + dv)
        self.jog_velocity = proposed
        for axis, v in zip(self.axes, proposed, strict=True):
            axis.setpoint += v * t

    # --- outputs -------------------------------------------------------------------------
    def publish(self, cycle: int) -> None:
        st = self.hli.bahn_state
        st.mode_r = self.mode
        st.program_state_r = self.state
        st.program_number_r = self.program_number
        block = self.current_block
        st.block_nr_r = block.number or 0 if block is not None else 0
        st.line_nr_r = block.line if block is not None else 0
        st.feedhold_active_r = bool(self.hold_source)
        st.hold_source_r = self.hold_source
        st.cycle_r = cycle % (2**31)
        kinematic = self.kinematic
        mi = self._main_slots
        if kinematic is None and self.decoder.tools.applied_length == 0.0:
            # the tool tip is the main axes' point: no transformation, no tool length (the common case,
            # written out: this runs every cycle)
            if st.trafo_active_r:
                st.kin_id_r = 0
                st.trafo_active_r = False
            axes = self.axes
            x, y, z = axes[mi[0]].setpoint, axes[mi[1]].setpoint, axes[mi[2]].setpoint
        else:
            st.kin_id_r = kinematic.kin_id if kinematic is not None else 0
            st.trafo_active_r = kinematic is not None
            tip = self.tool_tip(self.setpoints())
            x, y, z = tip[mi[0]], tip[mi[1]], tip[mi[2]]
        st.tcp_x_r = increments_clamped(x)
        st.tcp_y_r = increments_clamped(y)
        st.tcp_z_r = increments_clamped(z)
