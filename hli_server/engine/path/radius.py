"""Tool radius compensation G40/G41/G42 (M-16..M-18).

Works in program coordinates, in the active plane, before the frames (docs/nc-language.md "Tools").
Programming manual: "Tool radius compensation (TRC)"
https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/207729163.html, "Generate compensation
blocks" .../207816715.html, "Limits of TRC" .../207844107.html; error IDs from the diagnosis pages.

What is modelled:

- G41 (tool left of the contour) / G42 (right) with the radius of the selected D block; G40 deselects.
- Approach (indirect selection, G139, the kernel's default): the first motion block after G41/G42 runs from
  the uncompensated start point to the compensated start of the contour (the corner of its own equidistant
  with the next block's). It must be a line: a circle there is ID 90008.
- Departure: the block with G40 runs from the compensated end of the previous block (the corner with the
  departure line's equidistant) to the programmed, uncompensated end point. A circle there is refused.
- Corners: inner corners (the tool on the inside) end both equidistants at their intersection; outer
  corners get the transition the manual names: G25 (default) straight lines: up to a 90° change of direction
  the equidistants are extended to their intersection, beyond it two extension points joined by one line
  (the tool then departs from the corner by at most r·√2); G26 an arc of radius r about the corner (the tool
  stays at exactly r).
- Errors: a circle whose equidistant radius would be zero or negative (tool radius >= contour radius on the
  inside): ID 90017; two circles whose equidistants do not meet: ID 90031; a compensated block that would
  run against its programmed direction (the tool path crosses itself, a contour violation): 916000.
- The stage holds one block back (the corner needs the next block). A block that must empty it (M function,
  #FLUSH, a # command, an area command, the program's end) ends the held block perpendicular to its end
  point; the next block then starts with a line to its compensated start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from hli_server.engine.path.contour import ContourSettings

__all__ = [
    "A_CONTOUR_VIOLATION",
    "A_RADIUS_CIRCLE_CIRCLE",
    "A_RADIUS_TOO_LARGE",
    "A_SELECT_IN_CIRCLE",
    "Element",
    "RadiusCompensation",
    "TrcError",
]

A_SELECT_IN_CIRCLE = 90008
A_RADIUS_TOO_LARGE = 90017
A_RADIUS_CIRCLE_CIRCLE = 90031
A_CONTOUR_VIOLATION = 916000
_EPS = 1e-9
_CHECKED = frozenset({"block", "approach", "departure"})
"""The kinds of compensated elements the gouge check tests against their programmed direction."""

V2 = tuple[float, float]


class TrcError(Exception):
    def __init__(self, alarm: int, message: str, block: Any = None) -> None:
        super().__init__(message)
        self.alarm = alarm
        self.message = message
        self.block = block


@dataclass(frozen=True, slots=True)
class Element:
    """A path element in program coordinates (all axes); ``centre`` (plane coordinates) for a circle."""

    start: tuple[float, ...]
    end: tuple[float, ...]
    block: Any
    rapid: bool = False
    centre: V2 | None = None
    cw: bool = False
    kind: str = "block"
    """``block`` (programmed), ``approach``, ``departure``, ``transition``, ``connect``."""
    feed: float | None = None
    """mm/min: the path feed of the element's block (taken when the block is decoded: a held block keeps
    its own feed when the next block programs another)."""
    blend: ContourSettings | None = None
    """The contouring at the element's end (the block's, when it was decoded; None: an exact corner)."""
    length: float = 0.0
    """mm: the tool length in the tool axis's position at the element's end (the block's)."""


def _part(of: Element, start: tuple[float, ...], end: tuple[float, ...], kind: str) -> Element:
    """A straight element the compensation inserts for ``of``'s block (with its feed, contouring, tool)."""
    return replace(of, start=start, end=end, centre=None, cw=False, kind=kind)


def _sub(a: V2, b: V2) -> V2:
    return (a[0] - b[0], a[1] - b[1])


def _unit(v: V2) -> V2:
    n = math.hypot(v[0], v[1])
    return (v[0] / n, v[1] / n) if n > _EPS else (0.0, 0.0)


def _cross(a: V2, b: V2) -> float:
    return a[0] * b[1] - a[1] * b[0]


def _dot(a: V2, b: V2) -> float:
    return a[0] * b[0] + a[1] * b[1]


class RadiusCompensation:
    """The TRC stage: :meth:`push` an element, get the compensated ones ready; :meth:`flush` empties it."""

    def __init__(self) -> None:
        self.side = 0
        """+1 G41, -1 G42, 0 G40."""
        self.radius = 0.0
        self.transition = 25
        self.plane: tuple[int, int] = (0, 1)
        self._held: Element | None = None
        """The last compensated element; its end is not final."""
        self._held_prog: Element | None = None
        self._last_out: tuple[float, ...] | None = None
        self._selecting = False
        self._change = 0
        """A contour change G41 <-> G42 waiting for its block (a deselection and a selection)."""

    @property
    def active(self) -> bool:
        return self.side != 0 or self._held is not None

    def reset(self) -> None:
        """Reset and program start: G40, G25, nothing held."""
        self.side = 0
        self.radius = 0.0
        self.transition = 25
        self._held = self._held_prog = None
        self._last_out = None
        self._selecting = False
        self._change = 0

    def select(self, side: int, radius: float, plane: tuple[int, int]) -> None:
        if radius < 0:  # a negative radius changes the side (programming manual, TRC)
            side = -side
        self.radius = abs(radius)
        self.plane = plane
        if self.side not in (0, side):
            # contour change: the held block ends as on deselection, the next one is an approach
            self._change = side
            return
        if side != self.side:
            self._selecting = side != 0 and self.side == 0
        self.side = side

    # --- geometry in the plane ----------------------------------------------------------------------------
    def _p(self, point: tuple[float, ...]) -> V2:
        i, j = self.plane
        return (point[i], point[j])

    def _with(self, point: tuple[float, ...], p: V2) -> tuple[float, ...]:
        i, j = self.plane
        q = list(point)
        q[i], q[j] = p
        return tuple(q)

    def _tangent(self, e: Element, at_end: bool) -> V2:
        if e.centre is None:
            return _unit(_sub(self._p(e.end), self._p(e.start)))
        u = _unit(_sub(self._p(e.end if at_end else e.start), e.centre))
        return (u[1], -u[0]) if e.cw else (-u[1], u[0])

    def _offset(self, e: Element) -> Element:
        """The equidistant of ``e`` at distance r on the compensation side."""
        r = self.radius * self.side
        if e.centre is None:
            t = self._tangent(e, False)
            n = (-t[1] * r, t[0] * r)
            s, d = self._p(e.start), self._p(e.end)
            return replace(
                e,
                start=self._with(e.start, (s[0] + n[0], s[1] + n[1])),
                end=self._with(e.end, (d[0] + n[0], d[1] + n[1])),
            )
        c = e.centre
        big_r = math.hypot(*_sub(self._p(e.start), c))
        new_r = big_r + (r if e.cw else -r)
        if new_r <= 1e-6:
            raise TrcError(
                A_RADIUS_TOO_LARGE,
                f"tool radius {self.radius:g} mm is greater than or equal to the circle's radius {big_r:g} mm"
                " "
                "on the inside of the contour",
                e.block,
            )
        us, ue = _unit(_sub(self._p(e.start), c)), _unit(_sub(self._p(e.end), c))
        return replace(
            e,
            start=self._with(e.start, (c[0] + new_r * us[0], c[1] + new_r * us[1])),
            end=self._with(e.end, (c[0] + new_r * ue[0], c[1] + new_r * ue[1])),
        )

    def _intersect(self, a: Element, b: Element, near: V2) -> V2 | None:
        """Intersection of the (offset) geometries of a and b nearest to ``near``."""
        if a.centre is None and b.centre is None:
            p, q = self._p(a.start), self._p(b.start)
            r, s = _sub(self._p(a.end), p), _sub(self._p(b.end), q)
            den = _cross(r, s)
            if abs(den) < _EPS:
                return None
            t = _cross(_sub(q, p), s) / den
            return (p[0] + t * r[0], p[1] + t * r[1])
        if a.centre is not None and b.centre is not None:
            return self._circles(a, b, near)
        line, arc = (a, b) if a.centre is None else (b, a)
        assert arc.centre is not None
        c = arc.centre
        rad = math.hypot(*_sub(self._p(arc.start), c))
        p = self._p(line.start)
        d = _unit(_sub(self._p(line.end), p))
        f = _sub(p, c)
        bq = _dot(f, d)
        disc = bq * bq - (_dot(f, f) - rad * rad)
        if disc < 0:
            return None
        root = math.sqrt(disc)
        cands = [(p[0] + t * d[0], p[1] + t * d[1]) for t in (-bq - root, -bq + root)]
        return min(cands, key=lambda x: math.hypot(*_sub(x, near)))

    def _circles(self, a: Element, b: Element, near: V2) -> V2 | None:
        assert a.centre is not None
        assert b.centre is not None
        c1, c2 = a.centre, b.centre
        r1 = math.hypot(*_sub(self._p(a.end), c1))
        r2 = math.hypot(*_sub(self._p(b.start), c2))
        d = math.hypot(*_sub(c2, c1))
        if d < _EPS or d > r1 + r2 + 1e-9 or d < abs(r1 - r2) - 1e-9:
            return None
        x = (d * d + r1 * r1 - r2 * r2) / (2 * d)
        h = math.sqrt(max(r1 * r1 - x * x, 0.0))
        u = _unit(_sub(c2, c1))
        m = (c1[0] + x * u[0], c1[1] + x * u[1])
        cands = [(m[0] - h * u[1], m[1] + h * u[0]), (m[0] + h * u[1], m[1] - h * u[0])]
        return min(cands, key=lambda p: math.hypot(*_sub(p, near)))

    def _check_direction(self, prog: Element, comp: Element) -> None:
        """The gouge check (PM 207844107, "Limits of TRC"): a compensated line must keep its programmed
        direction, else the tool would cut into the contour (a slot narrower than the tool, a block
        shorter than the corner needs, an approach or a departure too short for the radius). Checked for
        each element once both its corners are known: its own block and its two neighbours, the kernel's
        window of three relevant blocks."""
        if prog.centre is not None or comp.kind not in _CHECKED:
            return
        t = self._tangent(prog, False)
        if _dot(_sub(self._p(comp.end), self._p(comp.start)), t) < -1e-9:
            what = {"approach": "approach block", "departure": "departure block (G40)"}.get(
                comp.kind, "block"
            )
            raise TrcError(
                A_CONTOUR_VIOLATION,
                f"tool radius compensation: with radius {self.radius:g} mm the compensated path of this "
                f"{what} runs against its programmed direction (the tool would cut into the contour: "
                "contour violation)",
                prog.block,
            )

    def _corner(self, a: Element, b: Element, corner: V2, a_prog: Element, b_prog: Element) -> list[Element]:
        """Fix a's end and b's start at the programmed corner; returns [a, transitions..., b]."""
        t1 = self._tangent(a_prog, True)
        t2 = self._tangent(b_prog, False)
        cross, dot = _cross(t1, t2), _dot(t1, t2)
        ae, bs = self._p(a.end), self._p(b.start)
        if abs(cross) < 1e-9 and dot > 0:  # tangent
            return [replace(a, end=self._with(a.end, bs)), b]
        inner = self.side * cross > 0
        if inner:
            p = self._intersect(a, b, ((ae[0] + bs[0]) / 2, (ae[1] + bs[1]) / 2))
            if p is None:
                if a.centre is not None and b.centre is not None:
                    raise TrcError(
                        A_RADIUS_CIRCLE_CIRCLE,
                        f"tool radius {self.radius:g} mm: the compensated circles do not intersect",
                        b.block,
                    )
                raise TrcError(
                    A_CONTOUR_VIOLATION,
                    f"tool radius {self.radius:g} mm: the compensated blocks do not intersect "
                    "(contour violation)",
                    b.block,
                )
            a2 = replace(a, end=self._with(a.end, p))
            b2 = replace(b, start=self._with(b.start, p))
            self._check_direction(a_prog, a2)
            self._check_direction(b_prog, b2)
            if a2.centre is not None:
                self._check_arc(a_prog, a2, at_end=True)
            if b2.centre is not None:
                self._check_arc(b_prog, b2, at_end=False)
            return [a2, b2]
        # outer corner: a transition
        mid = a.end
        if self.transition == 26:
            arc = replace(b, start=mid, end=b.start, centre=corner, cw=self.side > 0, kind="transition")
            return [a, arc, b]
        delta = math.acos(max(-1.0, min(1.0, dot)))
        if delta <= math.pi / 2 + 1e-12 and a.centre is None and b.centre is None:
            k = self.radius * math.tan(delta / 2)
            p = (ae[0] + k * t1[0], ae[1] + k * t1[1])
            return [replace(a, end=self._with(a.end, p)), replace(b, start=self._with(b.start, p))]
        if delta <= math.pi / 2 + 1e-12:
            k = self.radius * math.tan(delta / 2)
            p = (ae[0] + k * t1[0], ae[1] + k * t1[1])
            pt = self._with(a.end, p)
            return [
                a,
                _part(b, a.end, pt, "transition"),
                _part(b, pt, b.start, "transition"),
                b,
            ]
        k = self.radius * math.tan(delta / 4)
        pa = self._with(a.end, (ae[0] + k * t1[0], ae[1] + k * t1[1]))
        pb = self._with(b.start, (bs[0] - k * t2[0], bs[1] - k * t2[1]))
        out: list[Element] = []
        if a.centre is None:
            out.append(replace(a, end=pa))
        else:
            out += [a, _part(b, a.end, pa, "transition")]
        out.append(_part(b, pa, pb, "transition"))
        if b.centre is None:
            out.append(replace(b, start=pb))
        else:
            out += [_part(b, pb, b.start, "transition"), b]
        return out

    def _check_arc(self, prog: Element, comp: Element, at_end: bool) -> None:
        """A trimmed circle must keep its sense (the intersection lies on the compensated arc)."""
        assert prog.centre is not None
        assert comp.centre is not None
        c = comp.centre
        a0 = math.atan2(*reversed(_sub(self._p(prog.start), c)))
        a1 = math.atan2(*reversed(_sub(self._p(prog.end), c)))
        sweep = (a0 - a1) if prog.cw else (a1 - a0)
        sweep %= 2 * math.pi
        if sweep < 1e-12:
            sweep = 2 * math.pi
        p = self._p(comp.end if at_end else comp.start)
        ap = math.atan2(p[1] - c[1], p[0] - c[0])
        part = ((a0 - ap) if prog.cw else (ap - a0)) % (2 * math.pi)
        if part > sweep + 1e-9 and part < 2 * math.pi - 1e-6:
            raise TrcError(
                A_CONTOUR_VIOLATION,
                f"tool radius {self.radius:g} mm: the compensated circle vanishes at the corner "
                "(the tool path crosses itself: contour violation)",
                prog.block,
            )

    # --- the stage ----------------------------------------------------------------------------------------
    def push(self, e: Element, deselect: bool = False) -> list[Element]:
        """A programmed element while TRC is active (or the block that deselects it with G40)."""
        out: list[Element] = []
        if self._change and not deselect:
            out += self.flush()
            self.side, self._change = self._change, 0
            self._selecting = True
        flat = e.centre is None and math.hypot(*_sub(self._p(e.end), self._p(e.start))) < 1e-9
        if flat and self.side != 0 and not deselect:
            # no motion in the plane (a Z feed, a zero move): not relevant for the compensation; the held
            # block ends perpendicular and this one moves from there (the other axes only)
            out = self.flush()
            if self._last_out is None:
                return [e]
            end = self._with(e.end, self._p(self._last_out))
            out.append(_part(e, self._last_out, end, "block"))
            self._last_out = end
            return out
        if deselect or self.side == 0:
            if self._held is None:
                if self._last_out is not None and e.centre is None:
                    # deselection right after a non-relevant block: from where the tool is
                    start, self._last_out = self._last_out, None
                    return [replace(e, start=start, kind="departure")]
                return [e]
            if e.centre is not None:
                raise TrcError(
                    A_SELECT_IN_CIRCLE,
                    "deselection of tool radius compensation (G40) in a circular block: program a line",
                    e.block,
                )
            assert self._held_prog is not None
            # the departure line's equidistant gives the corner; its end is the programmed end point
            dep_off = self._offset(e)
            pair = self._corner(self._held, dep_off, self._p(e.start), self._held_prog, e)
            out += pair[:-1]
            departure = replace(pair[-1], end=e.end, kind="departure")
            self._check_direction(e, departure)
            out.append(departure)
            self._held = self._held_prog = None
            self._last_out = e.end
            self.side = 0
            return out
        if self._selecting:
            if e.centre is not None:
                raise TrcError(
                    A_SELECT_IN_CIRCLE,
                    "selection of tool radius compensation (G41/G42): the first block after it must be a "
                    "line",
                    e.block,
                )
            self._selecting = False
            off = self._offset(e)
            start = self._last_out if self._last_out is not None else e.start
            self._held = replace(off, start=start, kind="approach")
            self._held_prog = e
            return out
        off = self._offset(e)
        if self._held is None:
            if self._last_out is not None and self._last_out != off.start:
                out.append(_part(e, self._last_out, off.start, "connect"))
            self._check_direction(e, off)
            self._held, self._held_prog = off, e
            return out
        assert self._held_prog is not None
        pair = self._corner(self._held, off, self._p(e.start), self._held_prog, e)
        out += pair[:-1]
        self._held, self._held_prog = pair[-1], e
        return out

    def flush(self) -> list[Element]:
        """Empty the stage: the held element ends perpendicular to its programmed end."""
        if self._held is None:
            return []
        out = [self._held]
        self._last_out = self._held.end
        self._held = self._held_prog = None
        if self.side == 0:
            self._last_out = None
        return out

    def moved_to(self, point: tuple[float, ...]) -> None:
        """The path continued from ``point`` without the stage (e.g. after G40): the next start."""
        self._last_out = point if self.side != 0 else None
