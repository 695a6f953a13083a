"""G100 measuring moves and the probe (C14-23, P-CHAN-00268)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hli_server.engine.areas.common import (
    ALARM_MEASURE_LIMIT,
    ALARM_NO_PROBE,
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

if TYPE_CHECKING:
    pass

__all__ = ["MeasuringMoves"]


@dataclass(slots=True)
class _Measuring:
    """The tag of a queued G100 motion and what happened to it."""

    block: Block
    limited: bool
    limit_reason: str
    triggered: bool = False


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
        length = segment.length
        limited = False
        reason = ""
        if self.channel.config.meas_soft_limit_move_path:
            f_limit = 1.0
            for k, axis in enumerate(self.channel.axes):
                s0, s1 = segment.start[k], segment.end[k]
                if s1 > axis.swe_pos + EPS and s1 > s0:
                    f = max(0.0, (axis.swe_pos - s0) / (s1 - s0))
                    if f < f_limit:
                        f_limit, reason = (
                            f,
                            f"the software limit of {axis.name} ({fnum(axis.swe_pos)} mm)",
                        )
                elif s1 < axis.swe_neg - EPS and s1 < s0:
                    f = max(0.0, (axis.swe_neg - s0) / (s1 - s0))
                    if f < f_limit:
                        f_limit, reason = (
                            f,
                            f"the software limit of {axis.name} ({fnum(axis.swe_neg)} mm)",
                        )
            groups = self.planned.groups()
            hit = first_violation(groups, segment) if groups else None
            if hit is not None and not (hit.point_violation and hit.f == 0.0):
                f = hit.f
                if hit.prism.protection:
                    f = max(0.0, f - PROTECTION_MARGIN / length)
                kind = "protection" if hit.prism.protection else "work"
                if f < f_limit:
                    f_limit, reason = f, f"{kind} area {hit.prism.area_id}"
            if f_limit < 1.0:
                limited = True
                if f_limit * length <= EPS:
                    return DecodeError(
                        ALARM_MEASURE_LIMIT,
                        f"G100 {block.label}: the measuring move cannot start, it is already at {reason}",
                        {"position": list(segment.start)},
                    )
                segment = LineSegment(segment.start, point_at(segment, f_limit))
        tag = _Measuring(block, limited, reason)

        def done() -> None:
            self._measure_done(tag)

        return MeasuringMove(segment, done, tag)

    def _measure_done(self, tag: _Measuring) -> None:
        ch = self.channel
        line, label = tag.block.line, tag.block.label
        if tag.triggered:
            ch.decoder.resume(ch.setpoints())
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
        else:
            self.machine.raise_alarm(
                ALARM_NO_PROBE,
                ch,
                f"G100 {tag.block.label}: the measuring move reached its target {pos} without a probe signal",
                params={"position": ch.setpoints()},
                line=line,
                block=label,
            )

    def probe_cycle(self) -> None:
        """Before interpolation: a rising edge of the probe during a measuring move ends it (C14-23)."""
        ch = self.channel
        level = ch.hli.mc_command.probe_w or self._probe_request
        edge = level and not self._probe_prev
        self._probe_prev = level
        if not edge:
            return
        head = ch.planner.current()
        if not isinstance(head, Motion) or not isinstance(head.tag, _Measuring) or head.tag.triggered:
            return
        tag = head.tag
        tag.triggered = True
        self.measurement = {
            "block": tag.block.label,
            "line": tag.block.line,
            "cycle": self.machine.cycle,
            "position": {a.name: a.measured for a in ch.axes},
            "setpoint": {a.name: a.setpoint for a in ch.axes},
        }
        m = self.machine
        m.emit(
            Measurement(
                cycle=m.cycle,
                time_s=m.time,
                channel=ch.number,
                block=tag.block.label,
                line=tag.block.line,
                position={a.name: a.measured for a in ch.axes},
                setpoint={a.name: a.setpoint for a in ch.axes},
            )
        )
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
