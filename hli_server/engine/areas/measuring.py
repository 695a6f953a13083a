"""G100 measuring moves and the probe (C14-23, P-CHAN-00268; the kernel's measuring types 1 to 4).

The measuring type is the program's (``ModalState.meas_type``, the kernel's ``#MEAS MODE``) or the
channel's default P-CHAN-00057 ``messtyp``. What each type does, from the kernel's programming manual
(https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/206171147.html and the pages of
types 2, 3, 4 beside it):

=====  ===============================  ===================  ==========================================
type   axes                             feed                 no probe signal by the end of the move
=====  ===============================  ===================  ==========================================
1      at least one                     F word               no error; error 912010 with P-CHAN-00176
2      exactly one                      P-AXIS-00215         error 912010 ("an error message is output")
3      at least one                     F word               no error; G106: on to the target after it
4      at most the three main axes      F word               no error
=====  ===============================  ===================  ==========================================

Every axis the block programs must be a measuring axis, P-AXIS-00118 (else 50059); more axes than the
type allows is 50061; types 5 and 6 (G310) refuse G100 with 20138; type 7 (fixed stop) is not
simulated (910110). A probe signal that is already on when the move starts is 50052.

The measuring offsets: if the probe has not fired by the programmed target, the move may run on by
P-AXIS-00467 ``meas_offset`` (every type but 3) or, for type 2 where that is 0, by P-AXIS-00114
``mess_offset`` (the kernel's page of P-AXIS-00114). Per axis: the move runs on along its direction
as far as no axis passes its own offset. The offsets apply only when the move is not limited
(P-CHAN-00268 = 1 and a target beyond a software limit or area, FCT-C14 6.2: "nur wirksam, wenn die
CNC keine Begrenzung der Messverfahrbewegung ausführt"). The run-on itself stops before a software
limit or an area boundary (project's decision: the target was allowed, the offset must not turn it
into a refused block).

The simulated probe of the built-in cycles (engine/cycles): a stand-in's G100 block carries
``probe_touch``, the fraction of its line at which the probe sphere touches the simulated workpiece. Such a
move measures as type 1 whatever the channel's type (ISG's cycles select their measuring type themselves),
without a run-on and without an error when no signal comes (the cycle raises 13413 itself). The probe fires
when the path passes that point (the setpoints, checked before each interpolation), latching the exact
point; in a geometry check, which does not move the axes, it fires where the move would have touched. A
probe signal from the PLC or the operator during such a move is taken as well. Either way the decoder is
told the fraction of the line at which the signal came (``Decoder.measured``), which the cycle reads.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hli_server.engine.areas.common import (
    ALARM_MEASURE_LIMIT,
    ALARM_NO_PROBE,
    ALARM_NOT_SUPPORTED,
    PROTECTION_MARGIN,
    AreaRole,
    ChannelAreaTables,
    fnum,
    fpoint,
)
from hli_server.engine.areas.geometry import (
    EPS,
    first_violation,
    point_at,
)
from hli_server.engine.decoder import DecodeError, MeasuringMove, ModalState
from hli_server.engine.geometry import LineSegment
from hli_server.engine.nc.blocks import (
    Block,
)
from hli_server.engine.planner import Marker, Motion
from schemas.events import Measurement
from schemas.units import mm_from_increments, mm_per_s_from_um_per_s

if TYPE_CHECKING:
    pass

__all__ = [
    "ALARM_AXIS_COUNT",
    "ALARM_NOT_MEASURING_AXIS",
    "ALARM_PROBE_ALREADY_ON",
    "ALARM_TYPE_NOT_FOR_G100",
    "MeasuringMoves",
]

ALARM_TYPE_NOT_FOR_G100 = 20138
"""G100 is not allowed with the current measuring type (kernel ID)."""
ALARM_NOT_MEASURING_AXIS = 50059
"""Unable to measure with the axis: P-AXIS-00118 not set (kernel ID)."""
ALARM_AXIS_COUNT = 50061
"""Number of programmed axes exceeds the range of the measuring type (kernel ID)."""
ALARM_PROBE_ALREADY_ON = 50052
"""Probe already actuated when the measuring move starts (kernel ID)."""
_ALARM_INVALID = 912011
_MAX_AXES = {2: 1, 4: 3}


@dataclass(slots=True)
class _Measuring:
    """The tag of a queued G100 motion and what happened to it."""

    block: Block
    limited: bool
    limit_reason: str
    measuring_type: int = 1
    to_target: bool = False
    """Type 3 with G106: the move goes on to its target after the probe signal."""
    run_on: float = 0.0
    """mm the move runs past the programmed target (the measuring offsets)."""
    end: tuple[float, ...] = ()
    """Where the move ends without a probe signal (``check --geometry-only`` goes on from there)."""
    triggered: bool = False
    armed: bool = False
    origin: tuple[float, ...] = ()
    """The start of the programmed line (machine coordinates)."""
    direction: tuple[float, ...] = ()
    length: float = 0.0
    """The programmed line's length (before a P-CHAN-00268 limit)."""
    reach: float = 0.0
    """How far the move goes (the line, or its part before a limit)."""
    touch: float | None = None
    """A built-in cycle's move: mm along the line where the simulated workpiece is touched (None: not)."""
    standin: bool = False
    fraction: float | None = None
    """Where along the line the probe signal came (0..1), once it came."""


class MeasuringMoves(AreaRole):
    """The decoder's measuring-move handler of one channel, and its probe input."""

    def __init__(self, tables: ChannelAreaTables) -> None:
        super().__init__(tables)
        self._probe_request = False
        self._probe_prev = False
        self.measurement: dict[str, Any] | None = None
        """The last probe result (C14-23): block, positions in mm, cycle."""

    def follow_probe(self) -> None:
        """Outside automatic mode: track the probe level, so that no stale edge fires later."""
        self._probe_prev = self.channel.hli.mc_command.probe_w or self._probe_request

    def request_probe(self, on: bool) -> None:
        """The operator's (tests', API's) probe input, OR'ed with ``mc_command.probe_w`` (C14-23)."""
        self._probe_request = on

    # --- G100 (C14-23) -------------------------------------------------------------------------
    def measuring_move(
        self, segment: LineSegment, block: Block, modal: ModalState
    ) -> DecodeError | MeasuringMove:
        ch = self.channel
        standin = block.probe_touch is not None
        default = modal.meas_type if modal.meas_type is not None else ch.config.messtyp
        mtype = 1 if standin else default
        refused = self._check(block, mtype, modal)
        if isinstance(refused, DecodeError):
            return refused
        feed = refused
        length = segment.length
        programmed = segment
        limited = False
        reason = ""
        if ch.config.meas_soft_limit_move_path:
            f_limit, reason = self._limit(segment, length)
            if f_limit < 1.0:
                limited = True
                if f_limit * length <= EPS:
                    return DecodeError(
                        ALARM_MEASURE_LIMIT,
                        f"G100 {block.label}: the measuring move cannot start, it is already at {reason}",
                        {"position": list(segment.start)},
                    )
                segment = LineSegment(segment.start, point_at(segment, f_limit))
        run_on = 0.0
        reach = segment.length
        if not limited and mtype != 3 and not standin:
            segment, run_on = self._run_on(segment, mtype)
        touch_at = block.probe_touch
        tag = _Measuring(
            block,
            limited,
            reason,
            measuring_type=mtype,
            to_target=mtype == 3 and 106 in block.g_codes,
            run_on=run_on,
            end=segment.end,
            origin=programmed.start,
            direction=tuple((e - a) / length for a, e in zip(programmed.start, programmed.end, strict=True)),
            length=length,
            reach=reach,
            touch=touch_at * length if touch_at is not None and math.isfinite(touch_at) else None,
            standin=standin,
        )

        # a partial, not a closure: a recording's snapshot keeps it (hli_server/recording/snapshot.py)
        return MeasuringMove(segment, functools.partial(self._measure_done, tag), tag, feed=feed)

    def _check(self, block: Block, mtype: int, modal: ModalState) -> DecodeError | float | None:
        """The measuring type's rules for the block; the measuring feed of type 2 [mm/min] (None:
        the programmed F)."""
        head = f"G100 {block.label}"
        if mtype in (5, 6):
            return DecodeError(
                ALARM_TYPE_NOT_FOR_G100,
                f"{head}: G100 is not allowed with measuring type {mtype} (G310, interruptible measuring); "
                "select type 1..4 (P-CHAN-00057 messtyp)",
                {"type": mtype},
            )
        if mtype == 7:
            return DecodeError(
                ALARM_NOT_SUPPORTED,
                f"{head}: measuring type 7 (measuring by moving to a fixed stop) is not supported by the "
                "simulator; select type 1..4 (P-CHAN-00057 messtyp)",
                {"type": mtype},
            )
        by_name = {a.name: a for a in self.channel.axes}
        programmed = list(dict.fromkeys(name for name, _ in block.axes))
        for name in programmed:
            axis = by_name[name]
            if not axis.config.messachse:
                return DecodeError(
                    ALARM_NOT_MEASURING_AXIS,
                    f"{head}: axis {name} is not a measuring axis; set P-AXIS-00118 kenngr.messachse 1 "
                    "(TOML messachse = true) for every axis a G100 block programs",
                    {"axis": name, "axis_number": axis.number},
                    axis=name,
                )
        limit = _MAX_AXES.get(mtype)
        if limit is not None and len(programmed) > limit:
            return DecodeError(
                ALARM_AXIS_COUNT,
                f"{head}: {len(programmed)} axes programmed ({', '.join(programmed)}); measuring type "
                f"{mtype} takes at most {limit}",
                {"count": len(programmed), "limit": limit, "type": mtype},
            )
        if mtype == 4:
            main = self.channel.config.main_axes
            others = [n for n in programmed if n not in main]
            if others:
                return DecodeError(
                    _ALARM_INVALID,
                    f"{head}: measuring type 4 measures with the main axes {'/'.join(main)} only, "
                    f"{', '.join(others)} is not one",
                    {"axes": others, "type": mtype},
                )
        if mtype == 2:
            axis = by_name[programmed[0]]
            return mm_per_s_from_um_per_s(axis.config.vb_messen) * 60.0
        if modal.feed is None:
            return DecodeError(911000, f"{head}: no feed (F word) programmed for the measuring move")
        return None

    def _limit(self, segment: LineSegment, length: float) -> tuple[float, str]:
        """P-CHAN-00268: how far (fraction) the line may go before a software limit or an area."""
        f_limit = 1.0
        reason = ""
        for k, axis in enumerate(self.channel.axes):
            s0, s1 = segment.start[k], segment.end[k]
            if s1 > axis.swe_pos + EPS and s1 > s0:
                f = max(0.0, (axis.swe_pos - s0) / (s1 - s0))
                if f < f_limit:
                    f_limit, reason = f, f"the software limit of {axis.name} ({fnum(axis.swe_pos)} mm)"
            elif s1 < axis.swe_neg - EPS and s1 < s0:
                f = max(0.0, (axis.swe_neg - s0) / (s1 - s0))
                if f < f_limit:
                    f_limit, reason = f, f"the software limit of {axis.name} ({fnum(axis.swe_neg)} mm)"
        groups = self.planned.groups()
        hit = first_violation(groups, segment) if groups else None
        if hit is not None and not (hit.point_violation and hit.f == 0.0):
            f = hit.f
            if hit.prism.protection:
                f = max(0.0, f - PROTECTION_MARGIN / length)
            kind = "protection" if hit.prism.protection else "work"
            if f < f_limit:
                f_limit, reason = f, f"{kind} area {hit.prism.area_id}"
        return f_limit, reason

    def _run_on(self, segment: LineSegment, mtype: int) -> tuple[LineSegment, float]:
        """The measuring offsets (P-AXIS-00467, type 2 also P-AXIS-00114): the line extended past the
        target, no axis beyond its offset, stopped before a software limit or an area boundary."""
        length = segment.length
        extension = math.inf
        for k, axis in enumerate(self.channel.axes):
            share = abs(segment.end[k] - segment.start[k]) / length
            if share <= 1e-12:
                continue
            offset = axis.config.meas_offset
            if mtype == 2 and offset == 0:
                offset = axis.config.mess_offset
            extension = min(extension, mm_from_increments(offset) / share)
        if not math.isfinite(extension) or extension <= EPS:
            return segment, 0.0
        direction = [(e - s) / length for s, e in zip(segment.start, segment.end, strict=True)]
        far = tuple(e + d * extension for e, d in zip(segment.end, direction, strict=True))
        beyond = LineSegment(segment.end, far)
        f, _ = self._limit(beyond, extension)
        extension *= f
        if extension <= EPS:
            return segment, 0.0
        end = tuple(e + d * extension for e, d in zip(segment.end, direction, strict=True))
        return LineSegment(segment.start, end), extension

    def _measure_done(self, tag: _Measuring) -> None:
        ch = self.channel
        line, label = tag.block.line, tag.block.label
        if tag.triggered:
            ch.decoder.resume(ch.setpoints(), tag.fraction)
            return
        if tag.touch is not None and tag.touch <= tag.reach + EPS:
            # the simulated probe touched on the way: a geometry check (the axes did not move) or a touch at
            # the very end of the move (the path reached the marker before the probe check saw it)
            point = self._latch(tag, tag.touch)
            ch.decoder.resume(list(point) if not tag.armed else ch.setpoints(), tag.fraction)
            return
        pos = fpoint(self.names, tuple(ch.setpoints()))
        if tag.limited:
            self.machine.raise_alarm(
                ALARM_MEASURE_LIMIT,
                ch,
                f"G100 {tag.block.label}: no probe signal before {tag.limit_reason}; stopped at {pos} "
                "(P-CHAN-00268 = 1)",
                params={"position": ch.setpoints()},
                line=line,
                block=label,
            )
            return
        error = tag.measuring_type == 2 or (tag.measuring_type == 1 and ch.config.meas_error_no_signal)
        if not error or tag.standin:
            # types 1 (P-CHAN-00176 = 0), 3 and 4: the measurement did not take place, the program goes on
            # from the end of the move (where the axes stand; a geometry check did not move them)
            ch.decoder.resume(list(tag.end))
            return
        why = "measuring type 2" if tag.measuring_type == 2 else "measuring type 1 with P-CHAN-00176 = 1"
        run_on = f" and its run-on of {fnum(tag.run_on)} mm (measuring offset)" if tag.run_on else ""
        self.machine.raise_alarm(
            ALARM_NO_PROBE,
            ch,
            f"G100 {tag.block.label}: the measuring move reached its target{run_on} without a probe signal, "
            f"ended at {pos} ({why})",
            params={"position": ch.setpoints(), "type": tag.measuring_type},
            line=line,
            block=label,
        )

    def _latch(self, tag: _Measuring, along: float) -> tuple[float, ...]:
        """The simulated probe fires ``along`` mm along the line: the exact point is latched."""
        point = tuple(o + d * along for o, d in zip(tag.origin, tag.direction, strict=True))
        self._record(tag, dict(zip(self.names, point, strict=True)), along)
        return point

    def _record(self, tag: _Measuring, position: dict[str, float], along: float) -> None:
        """A probe signal during ``tag``'s move (C14-23): the measurement, its event, the fraction."""
        ch = self.channel
        tag.triggered = True
        tag.fraction = max(0.0, along / tag.length) if tag.length > 0.0 else 0.0
        self.measurement = {
            "block": tag.block.label,
            "line": tag.block.line,
            "cycle": self.machine.cycle,
            "position": position,
            "setpoint": {a.name: a.setpoint for a in ch.axes},
            "measuring_type": tag.measuring_type,
        }
        m = self.machine
        m.emit(
            Measurement(
                cycle=m.cycle,
                time_s=m.time,
                channel=ch.number,
                block=tag.block.label,
                line=tag.block.line,
                position=position,
                setpoint={a.name: a.setpoint for a in ch.axes},
            )
        )

    def probe_cycle(self) -> None:
        """Before interpolation: a rising edge of the probe during a measuring move ends it (C14-23)."""
        ch = self.channel
        level = ch.hli.mc_command.probe_w or self._probe_request
        edge = level and not self._probe_prev
        self._probe_prev = level
        head = ch.planner.current()
        if not isinstance(head, Motion) or not isinstance(head.tag, _Measuring) or head.tag.triggered:
            return
        tag = head.tag
        if not tag.armed:
            tag.armed = True
            if level and not edge:
                self.machine.raise_alarm(
                    ALARM_PROBE_ALREADY_ON,
                    ch,
                    f"G100 {tag.block.label}: the probe signal is already on when the measuring move "
                    "starts; release it (mc_command.probe_w, the probe input) before G100",
                    params={"block": tag.block.label},
                    line=tag.block.line,
                    block=tag.block.label,
                )
                return
        touched = False
        if not edge and tag.touch is not None:
            progress = sum(
                (a.setpoint - o) * d
                for a, o, d in zip(ch.axes, tag.origin, tag.direction)  # noqa: B905 compiled: see geometry.py
            )
            touched = progress >= tag.touch - EPS
        if not edge and not touched:
            return
        if touched:
            assert tag.touch is not None
            self._latch(tag, tag.touch)
        else:
            along = sum(
                (a.measured - o) * d
                for a, o, d in zip(ch.axes, tag.origin, tag.direction)  # noqa: B905 compiled: see geometry.py
            )
            self._record(tag, {a.name: a.measured for a in ch.axes}, along)
        if tag.to_target:
            return  # type 3 with G106: on to the target (FCT's "Weiterfahrt bis zum Zielpunkt")
        # brake to a stop on the remaining path and end the move there
        planner = ch.planner
        v = planner.velocity
        s_stop = min(head.length, planner.position_in_item + v * planner.t_a + v * v / (2.0 * head.accel))
        delta = head.length - s_stop
        if delta <= 0.0:
            return
        seg = head.segment
        head.segment = LineSegment(seg.start, seg.point_at(s_stop))
        head.length = s_stop
        planner.s_queued_end -= delta
        for item in list(planner.queue)[1:]:
            item.s_start -= delta
            if not isinstance(item, Marker):
                break
