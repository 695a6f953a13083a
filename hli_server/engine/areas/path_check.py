"""The check of every motion block's whole path before it is queued (C14-14, C14-15)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from hli_server.engine.areas.common import (
    ALARM_PATH_ENTERS_PROTECTION,
    ALARM_PATH_LEAVES_WORK,
    ALARM_POINT_IN_PROTECTION,
    ALARM_POINT_OUTSIDE_WORK,
    AreaRole,
    fids,
    fpoint,
)
from hli_server.engine.areas.geometry import (
    Hit,
    first_violation,
)
from hli_server.engine.decoder import DecodeError
from hli_server.engine.geometry import Segment, segment_params
from hli_server.engine.nc.blocks import (
    Block,
)

if TYPE_CHECKING:
    pass

__all__ = ["AreaPathCheck"]


class AreaPathCheck(AreaRole):
    """The path check of one channel: the first violation on the block's path, as an alarm with the block's
    start and end point and the exact intersection point."""

    monitors_tcp = True
    """The areas monitor the tool centre point (the tool tip, less the tool length): M-15."""

    # --- path check (C14-15) ---------------------------------------------------------------
    def path_check(self, segment: Segment, block: Block) -> DecodeError | None:
        """The decoder's path check (a bound method: the batch geometry check recognises it by its
        ``__self__``, ``hli_server/engine/batch.py``)."""
        groups = self.planned.groups()
        if not groups:
            return None
        hit = first_violation(groups, segment)
        if hit is None:
            return None
        return self._path_error(hit, segment, block)

    def _path_error(self, hit: Hit, segment: Segment, block: Block) -> DecodeError:
        prism = hit.prism
        ks = (prism.a, prism.b, prism.c)
        names = self.names
        params = segment_params(
            names,
            segment,
            intersection=list(hit.point),
            area=prism.area_id,
            kind="PROT" if prism.protection else "WORK",
        )
        span = f"{block.label} from {fpoint(names, segment.start, ks)} to {fpoint(names, segment.end, ks)}"
        if hit.point_violation and hit.f == 0.0:
            if prism.protection:
                return DecodeError(
                    ALARM_POINT_IN_PROTECTION,
                    f"start point {fpoint(names, segment.start, ks)} of {block.label} is in or on protection "
                    f"area {prism.area_id}; the block was not started",
                    params,
                )
            works = fids(self._workids_text(prism))
            return DecodeError(
                ALARM_POINT_OUTSIDE_WORK,
                f"start point {fpoint(names, segment.start, ks)} of {block.label} is outside the work "
                f"area(s) {works}; the block was not started",
                params,
            )
        at = fpoint(names, hit.point, ks)
        if prism.protection:
            return DecodeError(
                ALARM_PATH_ENTERS_PROTECTION,
                f"path {span} touches protection area {prism.area_id} at {at}; the block was not started",
                params,
            )
        return DecodeError(
            ALARM_PATH_LEAVES_WORK,
            f"path {span} leaves the work area(s) {fids(self._workids_text(prism))} at {at}; "
            "the block was not started",
            params,
        )

    def _workids_text(self, prism: Any) -> list[int]:
        for group in self.planned.groups():
            if prism in group.works:
                return sorted(w.area_id for w in group.works)
        return [prism.area_id]
