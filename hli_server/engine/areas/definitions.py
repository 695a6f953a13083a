"""The ``#CONTROL AREA`` commands and the contour blocks between BEGIN and END (FCT-C14 2.x, C14-02..C14-13).

The decoder's area handler (:class:`~hli_server.engine.decoder.AreaHandler`): commands are validated
and applied to the *planned* table at decode time, and the same operation is returned as an action
the channel runs in program order, which applies it to the *effective* table (module docstring of
:mod:`~hli_server.engine.areas.monitor`)."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from hli_server.engine.areas.common import (
    ALARM_ACTIVE_CLEAR,
    ALARM_ACTIVE_OVERWRITE,
    ALARM_CIRC_FIRST_NOT_LINEAR,
    ALARM_COMMAND,
    ALARM_DEFINITION,
    ALARM_END_WITHOUT_BEGIN,
    ALARM_G_IN_DEFINITION,
    ALARM_ID_RANGE,
    ALARM_ID_ZERO,
    ALARM_NOT_SUPPORTED,
    ALARM_POINT_IN_PROTECTION,
    ALARM_POINT_OUTSIDE_WORK,
    ALARM_POLY_INTERSECTS,
    ALARM_POLY_NOT_LINEAR,
    ALARM_POLY_TOO_MANY,
    ALARM_TOO_MANY_AXES,
    AREA_ID_MAX,
    CLOSE_TOLERANCE,
    MAX_CONTOUR_BLOCKS,
    PLANE_AXES,
    PLANE_NAMES,
    AreaRole,
    Contour,
    PendingDefinition,
    beyond_limit,
    fids,
    fnum,
    fpair,
    fpoint,
)
from hli_server.engine.areas.geometry import (
    polygon_self_intersection,
)
from hli_server.engine.areas.table import MAX_AREAS, AreaDefinition, AreaEvent, AreaState, AreaTable, Refusal
from hli_server.engine.decoder import DecodeError, ModalState
from hli_server.engine.geometry import ArcSegment, Point, Segment
from hli_server.engine.nc.blocks import (
    AreaBegin,
    AreaClear,
    AreaCommand,
    AreaEnd,
    AreaOff,
    AreaOn,
    AreaShape,
    Block,
)

if TYPE_CHECKING:
    pass

__all__ = ["AreaDefinitions"]


class AreaDefinitions(AreaRole):
    """Definitions, ON, OFF and CLEAR of one channel (the decoder's area handler)."""

    # --- AreaHandler: #CONTROL AREA commands ---------------------------------------------
    def command(
        self, cmd: AreaCommand, block: Block, position: Point, modal: ModalState
    ) -> DecodeError | Callable[[], None] | None:
        if isinstance(cmd, AreaBegin):
            return self._begin(cmd, block, modal)
        if isinstance(cmd, AreaEnd):
            return self._end(block, modal)
        name = type(cmd).__name__.removeprefix("Area").upper()
        if modal.in_area_definition:
            return DecodeError(
                ALARM_COMMAND,
                f"#CONTROL AREA {name} inside the definition of area {self._pending_id()}: "
                "close the definition with #CONTROL AREA END first",
            )
        if isinstance(cmd, AreaOn):
            return self._on(cmd, position)
        if isinstance(cmd, AreaOff):
            return self._off(cmd)
        return self._clear(cmd)

    def _pending_id(self) -> str:
        return str(self.pending.begin.area_id) if self.pending is not None else "?"

    def _begin(self, cmd: AreaBegin, block: Block, modal: ModalState) -> DecodeError | None:
        self.pending = None
        head = f"#CONTROL AREA BEGIN [ID={cmd.area_id}]"
        if cmd.area_id == 0:
            return DecodeError(
                ALARM_ID_ZERO,
                f"{head}: invalid control area ID 0; an area ID is a whole number 1..{AREA_ID_MAX}",
                {"id": 0},
            )
        if not 1 <= cmd.area_id <= AREA_ID_MAX:
            return DecodeError(
                ALARM_ID_RANGE,
                f"{head}: the control area ID is out of range 1..{AREA_ID_MAX}",
                {"id": cmd.area_id, "lower": 1, "upper": AREA_ID_MAX},
            )
        if cmd.monitor_lvl.upper() != "MCS":
            return DecodeError(
                ALARM_NOT_SUPPORTED,
                f'{head}: MONITOR_LVL="{cmd.monitor_lvl}" is not supported by the simulator '
                '(no multi-stage transformations); use MONITOR_LVL="MCS" or leave it out '
                '(docs/nc-language.md, "What stays refused")',
            )
        if cmd.min_excur >= cmd.max_excur:
            return DecodeError(
                ALARM_DEFINITION,
                f"{head}: MIN_EXCUR={fnum(cmd.min_excur)} must be less than MAX_EXCUR={fnum(cmd.max_excur)}",
            )
        height_axis: str | None = None
        if cmd.excur_ax is not None:
            if cmd.excur_ax not in self.names:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{head}: EXCUR_AX={cmd.excur_ax} is not an axis of channel {self.channel.number} "
                    f"({', '.join(self.names)})",
                )
            height_axis = cmd.excur_ax
        elif cmd.excur_axnr is not None:
            axis = self.machine.axes_by_number.get(cmd.excur_axnr)
            if axis is None or axis.name not in self.names:
                numbers = ", ".join(f"{a.name}={a.number}" for a in self.channel.axes)
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{head}: EXCUR_AXNR={cmd.excur_axnr} is not the logical number of an axis of channel "
                    f"{self.channel.number} ({numbers})",
                )
            height_axis = axis.name
        state = self.planned.state(cmd.area_id)
        if state is not None and isinstance(self.planned.next_state(cmd.area_id, AreaEvent.DEFINE), Refusal):
            return DecodeError(
                ALARM_ACTIVE_OVERWRITE,
                f"{head}: area {cmd.area_id} is active and cannot be overwritten, the area is not saved; "
                f"deactivate it first (#CONTROL AREA OFF [ID={cmd.area_id}])",
                {"id": cmd.area_id},
            )
        if state is None and self.planned.full:
            return DecodeError(
                ALARM_DEFINITION,
                f"{head}: the channel already has {MAX_AREAS} areas "
                f"({fids(sorted(self.planned.definitions))}); clear one first (#CONTROL AREA CLEAR [ID=n])",
            )
        self.pending = PendingDefinition(cmd, block, height_axis)
        return None

    # --- AreaHandler: contour blocks -------------------------------------------------------
    def contour(self, segment: Segment, block: Block, modal: ModalState) -> DecodeError | None:
        p = self.pending
        if p is None:
            return DecodeError(ALARM_DEFINITION, "contour block outside an area definition")
        area = f"area {p.begin.area_id}"
        if modal.feed is None:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: no feed (F word) active in the contour block; program F before the contour "
                "(C14-03)",
            )
        if 91 in block.g_codes:
            return DecodeError(
                ALARM_G_IN_DEFINITION,
                f"{area}: G91 is not allowed in a control area definition ({block.label}): contour "
                "positions are absolute (G90)",
                {"id": p.begin.area_id, "g": 91},
            )
        if not modal.absolute:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: contour positions must be absolute (G90), G91 is active",
            )
        if len(p.contour) >= MAX_CONTOUR_BLOCKS:
            return DecodeError(
                ALARM_POLY_TOO_MANY if p.begin.shape == AreaShape.POLY else ALARM_DEFINITION,
                f"{area}: more than {MAX_CONTOUR_BLOCKS} motion blocks in the definition "
                f"({block.label} is block {len(p.contour) + 1})",
                {"id": p.begin.area_id, "limit": MAX_CONTOUR_BLOCKS, "count": len(p.contour) + 1},
            )
        k = len(p.contour)
        is_arc = isinstance(segment, ArcSegment)
        gname = f"G0{modal.motion}"
        if p.begin.shape == AreaShape.POLY:
            if is_arc or modal.motion not in (0, 1):
                return DecodeError(
                    ALARM_POLY_NOT_LINEAR,
                    f"{area}: a POLY contour is made of linear blocks (G00/G01), {block.label} is {gname}",
                    {"id": p.begin.area_id, "motion": modal.motion},
                )
        elif k == 0:
            if is_arc or modal.motion not in (0, 1):
                return DecodeError(
                    ALARM_CIRC_FIRST_NOT_LINEAR,
                    f"{area}: a CIRC area starts with a linear block (G01) to the start point of the "
                    f"circle, {block.label} is {gname}",
                    {"id": p.begin.area_id, "motion": modal.motion},
                )
        elif k == 1:
            if not is_arc:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: the second block of a CIRC area must be the full circle (G02/G03 with "
                    f"I/J/K), {block.label} is {gname}",
                )
        else:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: a CIRC area is a start point and one full circle; "
                f"{block.label} is one block too many",
            )
        p.contour.append(Contour(segment, block, modal.plane, modal.motion))
        return None

    # --- END: the definition -----------------------------------------------------------------
    def _end(self, block: Block, modal: ModalState) -> DecodeError | Callable[[], None]:
        p = self.pending
        self.pending = None
        if p is None:
            # ID 21288: "no definition of a control area belongs to it, the command has no effect"
            return functools.partial(self._end_without_begin, block)
        result = self._build(p, block, modal)
        if isinstance(result, DecodeError):
            return result
        return self._commit(functools.partial(_define, result))

    def _end_without_begin(self, block: Block) -> None:
        self.machine.raise_alarm(
            ALARM_END_WITHOUT_BEGIN,
            self.channel,
            f"#CONTROL AREA END ({block.label}) without #CONTROL AREA BEGIN: the command has no "
            "effect; a definition begins with #CONTROL AREA BEGIN [...] and ends with END",
            line=block.line,
            block=block.label,
        )

    def _axes_of(self, p: PendingDefinition) -> tuple[str, str, str] | DecodeError:
        """The base plane and height axes of a definition (C14-06, C14-07, C14-17)."""
        area = f"area {p.begin.area_id}"
        main = self.channel.config.main_axes
        plane = p.contour[0].plane
        i, j = PLANE_AXES[plane]
        base = (main[i], main[j])
        third = main[3 - i - j]
        used: list[str] = []
        for c in p.contour:
            for name, _ in c.block.axes:
                if name not in used:
                    used.append(name)
        if len(used) > 2:
            return DecodeError(
                ALARM_TOO_MANY_AXES,
                f"{area}: the contour names {len(used)} axes ({', '.join(used)}); a control area is "
                "defined with at most two (its base plane), the height is set by MIN_EXCUR/MAX_EXCUR",
                {"id": p.begin.area_id, "axes": list(used), "limit": 2},
            )
        if all(n in main for n in used):
            wrong = [n for n in used if n not in base]
            if wrong:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: the contour names {', '.join(wrong)}, which is not an axis of the base plane "
                    f"{base[0]}/{base[1]} ({PLANE_NAMES[plane]}); the height is set by MIN_EXCUR/MAX_EXCUR",
                )
            a, b = base
            height = p.height_axis or third
        else:
            mixed = [n for n in used if n in main]
            if mixed:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: the contour mixes main axes ({', '.join(mixed)}) and additional axes "
                    f"({', '.join(n for n in used if n not in main)})",
                )
            if p.begin.shape == AreaShape.CIRC:
                return DecodeError(
                    ALARM_NOT_SUPPORTED,
                    f"{area}: areas on additional axes ({', '.join(used)}) must be POLY (C14-17); "
                    "CIRC is for the main axes",
                )
            if len(used) != 2:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: an area on additional axes takes exactly two axes in its contour, "
                    f"got {', '.join(used)}",
                )
            first_named = {n for n, _ in p.contour[0].block.axes}
            if set(used) - first_named:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: the start point ({p.contour[0].block.label}) must name both axes "
                    f"{used[0]} and {used[1]}",
                )
            letters = [n.rstrip("0123456789") for n in used]
            suffixes = {n[len(letter) :] for n, letter in zip(used, letters, strict=True)}
            a, b = used[0], used[1]
            in_main_order = letters == [base[0], base[1]] or not all(n in main for n in letters)
            if letters == [base[1], base[0]] or (
                not in_main_order and main.index(letters[0]) > main.index(letters[1])
            ):
                a, b = b, a
            if p.height_axis is not None:
                height = p.height_axis
            else:
                rest = [m for m in main if m not in letters]
                candidate = rest[0] + next(iter(suffixes)) if len(rest) == 1 and len(suffixes) == 1 else ""
                if candidate not in self.names:
                    return DecodeError(
                        ALARM_DEFINITION,
                        f"{area}: no height axis for an area on {a}/{b}: name it with EXCUR_AX=.. "
                        f"(channel axes {', '.join(self.names)})",
                    )
                height = candidate
        if height in (a, b):
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: the height axis {height} (EXCUR_AX/EXCUR_AXNR) is an axis of the base plane "
                f"{a}/{b}",
            )
        return a, b, height

    def _build(
        self, p: PendingDefinition, end_block: Block, modal: ModalState
    ) -> AreaDefinition | DecodeError:
        begin = p.begin
        area = f"area {begin.area_id}"
        if not p.contour:
            return DecodeError(ALARM_DEFINITION, f"{area}: the definition has no contour blocks")
        axes = self._axes_of(p)
        if isinstance(axes, DecodeError):
            return axes
        a, b, c = (self.names.index(n) for n in axes)
        lo = begin.min_excur + modal.offset(axes[2])
        hi = begin.max_excur + modal.offset(axes[2])
        first, last = p.contour[0].block, p.contour[-1].block
        source = f"{first.label}..{last.label} (lines {first.line}..{last.line})"
        if begin.shape == AreaShape.CIRC:
            if len(p.contour) != 2:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: a CIRC area needs a start point (G01) and one full circle (G02/G03), "
                    f"got {len(p.contour)} motion block(s)",
                )
            arc = p.contour[1].segment
            assert isinstance(arc, ArcSegment)
            if set(arc.plane) != {a, b}:
                return DecodeError(
                    ALARM_DEFINITION, f"{area}: the circle is not in the base plane {axes[0]}/{axes[1]}"
                )
            start2 = (arc.start[a], arc.start[b])
            end2 = (arc.end[a], arc.end[b])
            if abs(abs(arc.sweep) - 2.0 * math.pi) > 1e-9 or math.dist(start2, end2) > CLOSE_TOLERANCE:
                return DecodeError(
                    ALARM_DEFINITION,
                    f"{area}: CIRC needs one full circle, {p.contour[1].block.label} ends at {fpair(end2)}, "
                    f"not at its start point {fpair(start2)}",
                )
            centre = (arc.centre[0], arc.centre[1]) if arc.plane == (a, b) else (arc.centre[1], arc.centre[0])
            far = beyond_limit(
                [
                    (
                        f"circle extent {fpair((centre[0] - arc.radius, centre[1] - arc.radius))}",
                        centre[0] - arc.radius,
                        centre[1] - arc.radius,
                    ),
                    (
                        f"circle extent {fpair((centre[0] + arc.radius, centre[1] + arc.radius))}",
                        centre[0] + arc.radius,
                        centre[1] + arc.radius,
                    ),
                ],
                lo,
                hi,
            )
            if far is not None:
                return DecodeError(ALARM_DEFINITION, f"{area}: {far}")
            return AreaDefinition(
                begin.area_id,
                begin.kind,
                begin.shape,
                axes,
                (a, b, c),
                lo,
                hi,
                centre=centre,
                radius=arc.radius,
                source=source,
            )
        pts = [(cb.segment.end[a], cb.segment.end[b]) for cb in p.contour]
        far = beyond_limit(
            [
                (f"corner {fpair(pt)} ({cb.block.label})", pt[0], pt[1])
                for pt, cb in zip(pts, p.contour, strict=True)
            ],
            lo,
            hi,
        )
        if far is not None:
            return DecodeError(ALARM_DEFINITION, f"{area}: {far}")
        if math.dist(pts[0], pts[-1]) > CLOSE_TOLERANCE:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: polygon not closed: first point {fpair(pts[0])}, last point {fpair(pts[-1])} "
                f"({first.label} and {last.label} must end at the same point)",
            )
        corners: list[tuple[float, float]] = []
        labels: list[str] = []
        for pt, cb in zip(pts[:-1], p.contour[:-1], strict=True):
            if not corners or math.dist(corners[-1], pt) > CLOSE_TOLERANCE:
                corners.append(pt)
                labels.append(cb.block.label)
        if len(corners) < 3:
            return DecodeError(
                ALARM_DEFINITION,
                f"{area}: a polygon needs at least three different corners, got {len(corners)}",
            )
        crossing = polygon_self_intersection(corners)
        if crossing is not None:
            k, m, meet = crossing
            n = len(corners)

            def edge(e: int) -> str:
                return f"{labels[e]}->{labels[(e + 1) % n]} {fpair(corners[e])}-{fpair(corners[(e + 1) % n])}"

            return DecodeError(
                ALARM_POLY_INTERSECTS,
                f"{area}: the polygon intersects itself: edge {edge(k)} meets edge {edge(m)} "
                f"at {fpair(meet)}",
                {"id": begin.area_id, "intersection": list(meet)},
            )
        twice_area = sum(
            corners[k][0] * corners[(k + 1) % len(corners)][1]
            - corners[(k + 1) % len(corners)][0] * corners[k][1]
            for k in range(len(corners))
        )
        if abs(twice_area) <= 1e-12:
            return DecodeError(ALARM_DEFINITION, f"{area}: the polygon has no area")
        return AreaDefinition(
            begin.area_id,
            begin.kind,
            begin.shape,
            axes,
            (a, b, c),
            lo,
            hi,
            points=tuple(corners),
            source=source,
        )

    # --- ON / OFF / CLEAR ----------------------------------------------------------------------
    def _unknown(self, name: str, area_id: int) -> DecodeError:
        defined = fids(sorted(self.planned.definitions)) or "none"
        return DecodeError(
            ALARM_COMMAND,
            f"#CONTROL AREA {name} [ID={area_id}]: area {area_id} is not defined (defined: {defined})",
        )

    def _on(self, cmd: AreaOn, position: Point) -> DecodeError | Callable[[], None] | None:
        t = self.planned
        if cmd.all_ or cmd.area_id is None:
            ids = sorted(t.definitions)
            shown = "ON ALL"
        else:
            if cmd.area_id not in t.definitions:
                return self._unknown("ON", cmd.area_id)
            ids = [cmd.area_id]
            shown = f"ON [ID={cmd.area_id}]"
        new = [i for i in ids if t.state(i) != AreaState.ACTIVE]
        if not new:
            return None
        for group in t.groups_with(new):
            prism = group.verdict(position)
            if prism is not None:
                where = fpoint(self.names, position, (prism.a, prism.b, prism.c))
                if prism.protection:
                    return DecodeError(
                        ALARM_POINT_IN_PROTECTION,
                        f"#CONTROL AREA {shown} refused: the TCP {where} is in or on protection area "
                        f"{prism.area_id}; move out of it before activating (C14-11)",
                        {"position": list(position), "area": prism.area_id},
                    )
                works = fids(sorted(w.area_id for w in group.works))
                return DecodeError(
                    ALARM_POINT_OUTSIDE_WORK,
                    f"#CONTROL AREA {shown} refused: the TCP {where} is outside the work area(s) {works}; "
                    "move into a work area before activating it (C14-11)",
                    {"position": list(position), "area": prism.area_id},
                )

        return self._commit(functools.partial(_apply, AreaEvent.ON, ids))

    def _off(self, cmd: AreaOff) -> DecodeError | Callable[[], None] | None:
        t = self.planned
        if cmd.all_:
            ids = t.active_ids
        elif cmd.area_id is not None:
            if cmd.area_id not in t.definitions:
                return self._unknown("OFF", cmd.area_id)
            ids = [cmd.area_id]
        else:
            last = t.last_activated()
            ids = [last] if last is not None else []
        if not any(t.state(i) == AreaState.ACTIVE for i in ids):
            return None

        return self._commit(functools.partial(_apply, AreaEvent.OFF, ids))

    def _clear(self, cmd: AreaClear) -> DecodeError | Callable[[], None] | None:
        t = self.planned
        if cmd.all_ or cmd.area_id is None:
            ids = sorted(t.definitions)
        else:
            if cmd.area_id not in t.definitions:
                return self._unknown("CLEAR", cmd.area_id)
            ids = [cmd.area_id]
        active = [i for i in ids if t.state(i) == AreaState.ACTIVE]
        if not ids:
            return None

        clear = functools.partial(_apply, AreaEvent.CLEAR, ids)
        warning = None
        if active:
            warning = (
                f"#CONTROL AREA CLEAR: area(s) {fids(active)} active and not cleared; "
                f"deactivate first (#CONTROL AREA OFF [ID={active[0]}])"
            )
        return self._commit(clear, warning)

    def _commit(self, op: Callable[[AreaTable], None], warning: str | None = None) -> Callable[[], None]:
        """Apply ``op`` to the planned table now and return the action that applies it to the
        effective table when the path gets there (a planner marker's payload: ``op`` and the action are
        partials of plain functions and methods, not closures, so that a recording's snapshot keeps a
        command the path has not reached yet, hli_server/recording/snapshot.py)."""
        op(self.planned)
        return functools.partial(self._run_committed, op, warning)

    def _run_committed(self, op: Callable[[AreaTable], None], warning: str | None) -> None:
        op(self.effective)
        if warning is not None:
            self.machine.raise_alarm(ALARM_ACTIVE_CLEAR, self.channel, warning, **self._where())
        self.emit_table()


def _define(definition: AreaDefinition, table: AreaTable) -> None:
    """``#CONTROL AREA END``: the definition into ``table``."""
    table.apply(definition.area_id, AreaEvent.DEFINE, definition)


def _apply(event: AreaEvent, ids: list[int], table: AreaTable) -> None:
    """``#CONTROL AREA ON/OFF/CLEAR``: ``event`` to the areas ``ids`` that ``table`` defines."""
    for i in ids:
        if i in table.definitions:
            table.apply(i, event)
