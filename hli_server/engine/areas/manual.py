"""Manual mode: the jog guard, the mode-change check and P-MANU-00014 (C14-19..C14-22, P-CHAN-00442)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from hli_server.engine.areas.common import (
    ALARM_MANUAL_IN_PROTECTION,
    ALARM_MANUAL_OUTSIDE_WORK,
    ALARM_MANUAL_STOP,
    AreaRole,
    ChannelAreaTables,
    fids,
    fpoint,
)
from hli_server.engine.areas.geometry import (
    first_violation,
)
from hli_server.engine.geometry import LineSegment, Point

if TYPE_CHECKING:
    from hli_server.engine.channel import Channel

__all__ = ["ManualGuard"]


class ManualGuard(AreaRole):
    """The jog guard and the manual-mode checks of one channel."""

    def __init__(self, tables: ChannelAreaTables) -> None:
        super().__init__(tables)
        self._manual_mode_setting = self.channel.config.suppress_workspace_monitoring_manual_mode
        """P-CHAN-00442 (0, 1, 2), read once: the manual-mode checks run every cycle."""
        self._move_limit_warning = self.machine.config.manual.move_limit_warning
        """P-MANU-00014"""
        self._stop_warning: tuple[bool, int, tuple[int, int, int]] | None = None
        """A P-MANU-00014 warning due when the braking axes have come to rest (protection, id, axes)."""
        self._blocked_direction: tuple[float, ...] | None = None

    def announce_stop(self) -> None:
        """P-MANU-00014: the warning, once the axes a boundary stopped are at rest, with where they are."""
        ch = self.channel
        if self._stop_warning is None or any(ch.jog_velocity):
            return
        protection, area_id, ks = self._stop_warning
        self._stop_warning = None
        what = f"{'protection' if protection else 'work'} area {area_id}"
        self.machine.raise_alarm(
            ALARM_MANUAL_STOP,
            ch,
            f"manual motion stopped before {what} at {fpoint(self.names, tuple(ch.setpoints()), ks)} "
            "(P-MANU-00014)",
        )

    # --- manual mode (C14-19..C14-22) --------------------------------------------------------
    def manual_monitoring(self) -> bool:
        """Is the area monitoring effective in manual mode now (P-CHAN-00442, control unit)?"""
        if self._manual_mode_setting == 1:
            return False
        return not self.channel.hli.bahn_mc_control.suppress_area_mon_manual_mode.state_r

    def must_brake(self, channel: Channel, current: Point, stop_point: Point) -> bool:
        """Jog guard: brake when the straight way from ``current`` to where the axes would come to
        rest leaves the allowed space (C14-19).

        Once the guard has stopped a motion it stays latched for that direction: motions that still
        push toward the boundary (positive component along the blocked direction) stay blocked, so
        the axes rest where they stopped instead of creeping up to the boundary in tiny steps; any
        other motion is checked afresh and releases the latch when it is allowed."""
        if not self.manual_monitoring():
            self._release_manual()
            return False
        groups = self.effective.groups()
        if not groups:
            self._release_manual()
            return False
        current, stop_point = channel.tool_tip(current), channel.tool_tip(stop_point)
        direction = tuple(b - a for a, b in zip(current, stop_point, strict=True))
        blocked = self._blocked_direction
        if blocked is not None and sum(x * y for x, y in zip(direction, blocked, strict=True)) > 0.0:
            return True
        if math.dist(current, stop_point) <= 0.0:
            prism = next((p for g in groups if (p := g.verdict(current)) is not None), None)
        else:
            hit = first_violation(groups, LineSegment(current, stop_point))
            prism = hit.prism if hit is not None else None
        if prism is None:
            self._release_manual()
            return False
        norm = math.hypot(*direction)
        self._blocked_direction = tuple(x / norm for x in direction) if norm > 0.0 else blocked
        if not self.violation_manual and self._move_limit_warning:
            # P-MANU-00014: said once the axes are at rest, with the place where they stopped
            self._stop_warning = (prism.protection, prism.area_id, (prism.a, prism.b, prism.c))
        self.violation_manual = True
        return True

    def _release_manual(self) -> None:
        self._blocked_direction = None
        self.violation_manual = False

    def mode_check(self) -> bool:
        """Entering manual mode (C14-20, P-CHAN-00442 = 0): the TCP must be in the allowed space."""
        if self._manual_mode_setting != 0 or not self.manual_monitoring():
            return True
        position = self.channel.tool_tip(self.channel.setpoints())
        for group in self.effective.groups():
            prism = group.verdict(position)
            if prism is None:
                continue
            where = fpoint(self.names, position, (prism.a, prism.b, prism.c))
            if prism.protection:
                self.machine.raise_alarm(
                    ALARM_MANUAL_IN_PROTECTION,
                    self.channel,
                    f"manual mode refused: the TCP {where} is in or on protection area {prism.area_id} "
                    "(P-CHAN-00442 = 0)",
                    params={"position": list(position), "area": prism.area_id},
                )
            else:
                self.machine.raise_alarm(
                    ALARM_MANUAL_OUTSIDE_WORK,
                    self.channel,
                    f"manual mode refused: the TCP {where} is outside the work area(s) "
                    f"{fids(sorted(w.area_id for w in group.works))} (P-CHAN-00442 = 0)",
                    params={"position": list(position), "area": prism.area_id},
                )
            return False
        return True
