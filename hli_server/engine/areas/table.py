"""The area table of one channel and the state machine of one area (C14-01, C14-08..13; FCT-C14 Abb. 11).

Everything that changes an area's state lives here, as a table (the h11 way): ``TRANSITIONS`` maps
(state, event) to the next state, or to a refusal that the caller turns into an error or a warning.
``None`` as a state means "not defined".

::

    state \\ event   DEFINE        ON        OFF        CLEAR              RESET
    (none)          defined       error     error      error              -
    defined         defined       active    defined    (none)             defined
    active          error         active    inactive   active + 120499    inactive
    inactive        defined       active    inactive   (none)             inactive

DEFINE overwrites a defined or inactive area (C14-09). ON of an active area and OFF of an area that
is not active change nothing. RESET (channel reset, C14-10) deactivates; program end is no event.
At most :data:`MAX_AREAS` areas per channel (C14-08).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from hli_server.engine.areas.geometry import Circle, Group, Polygon, Prism
from hli_server.engine.nc.blocks import AreaKind, AreaShape

__all__ = [
    "MAX_AREAS",
    "TRANSITIONS",
    "AreaDefinition",
    "AreaEvent",
    "AreaState",
    "AreaTable",
    "Refusal",
]

MAX_AREAS = 20
"""C14-08, FCT-C14 2.3: "Die Anzahl der Arbeits- oder Schutzräume ist auf 20 begrenzt"."""


class AreaState(StrEnum):
    DEFINED = "defined"
    ACTIVE = "active"
    INACTIVE = "inactive"


class AreaEvent(StrEnum):
    DEFINE = "define"
    ON = "on"
    OFF = "off"
    CLEAR = "clear"
    RESET = "reset"


class Refusal(StrEnum):
    UNKNOWN_ID = "unknown_id"
    """ON/OFF/CLEAR of an ID that is not defined: error."""
    ACTIVE_REDEFINE = "active_redefine"
    """DEFINE of an active area: error (C14-09)."""
    ACTIVE_CLEAR = "active_clear"
    """CLEAR of an active area: warning 120499, the area stays (C14-13)."""


_D, _A, _I = AreaState.DEFINED, AreaState.ACTIVE, AreaState.INACTIVE

TRANSITIONS: dict[tuple[AreaState | None, AreaEvent], AreaState | Refusal | None] = {
    (None, AreaEvent.DEFINE): _D,
    (None, AreaEvent.ON): Refusal.UNKNOWN_ID,
    (None, AreaEvent.OFF): Refusal.UNKNOWN_ID,
    (None, AreaEvent.CLEAR): Refusal.UNKNOWN_ID,
    (_D, AreaEvent.DEFINE): _D,
    (_D, AreaEvent.ON): _A,
    (_D, AreaEvent.OFF): _D,
    (_D, AreaEvent.CLEAR): None,
    (_D, AreaEvent.RESET): _D,
    (_A, AreaEvent.DEFINE): Refusal.ACTIVE_REDEFINE,
    (_A, AreaEvent.ON): _A,
    (_A, AreaEvent.OFF): _I,
    (_A, AreaEvent.CLEAR): Refusal.ACTIVE_CLEAR,
    (_A, AreaEvent.RESET): _I,
    (_I, AreaEvent.DEFINE): _D,
    (_I, AreaEvent.ON): _A,
    (_I, AreaEvent.OFF): _I,
    (_I, AreaEvent.CLEAR): None,
    (_I, AreaEvent.RESET): _I,
}


@dataclass(frozen=True, slots=True)
class AreaDefinition:
    """One defined area, in machine coordinates (mm) with zero offsets applied (C14-16).

    ``axes`` = (first base axis, second base axis, height axis) by name, ``indices`` the same as
    indices into the channel's axis order. ``points`` are the polygon's corners without the closing
    repetition; a circle has ``centre`` and ``radius``."""

    area_id: int
    kind: AreaKind
    shape: AreaShape
    axes: tuple[str, str, str]
    indices: tuple[int, int, int]
    lo: float
    hi: float
    points: tuple[tuple[float, float], ...] = ()
    centre: tuple[float, float] = (0.0, 0.0)
    radius: float = 0.0
    source: str = ""
    """Where it was defined: ``N10..N140 (line 1..14)``."""
    prism: Prism = field(init=False, compare=False, repr=False)

    def __post_init__(self) -> None:
        region = (
            Polygon(list(self.points))
            if self.shape == AreaShape.POLY
            else Circle(self.centre[0], self.centre[1], self.radius)
        )
        a, b, c = self.indices
        prism = Prism(region, a, b, c, self.lo, self.hi, self.area_id, self.kind == AreaKind.PROT)
        object.__setattr__(self, "prism", prism)

    def to_json(self, state: AreaState) -> dict[str, Any]:
        out: dict[str, Any] = {
            "id": self.area_id,
            "kind": str(self.kind),
            "shape": str(self.shape),
            "state": str(state),
            "axes": [self.axes[0], self.axes[1]],
            "height_axis": self.axes[2],
        }
        if self.shape == AreaShape.POLY:
            out["points"] = [[x, y] for x, y in self.points]
        else:
            out["center"] = [self.centre[0], self.centre[1]]
            out["radius"] = self.radius
        out["min"] = self.lo
        out["max"] = self.hi
        out["source"] = self.source
        return out


@dataclass(slots=True)
class AreaTable:
    """The areas of one channel with their states. ``version`` changes with every change, so that
    the allowed space built from the active areas can be cached."""

    definitions: dict[int, AreaDefinition] = field(default_factory=dict)
    states: dict[int, AreaState] = field(default_factory=dict)
    activation_order: list[int] = field(default_factory=list)
    """IDs in the order they were activated (bare OFF deactivates the last, C14-12)."""
    version: int = 0
    _groups: list[Group] = field(default_factory=list)
    _groups_version: int = -1

    def copy(self) -> AreaTable:
        return AreaTable(
            definitions=dict(self.definitions),
            states=dict(self.states),
            activation_order=list(self.activation_order),
            version=self.version + 1,
        )

    def state(self, area_id: int) -> AreaState | None:
        return self.states.get(area_id)

    @property
    def full(self) -> bool:
        return len(self.definitions) >= MAX_AREAS

    @property
    def active_ids(self) -> list[int]:
        return [i for i in sorted(self.states) if self.states[i] == AreaState.ACTIVE]

    def next_state(self, area_id: int, event: AreaEvent) -> AreaState | Refusal | None:
        return TRANSITIONS[(self.states.get(area_id), event)]

    def apply(
        self, area_id: int, event: AreaEvent, definition: AreaDefinition | None = None
    ) -> Refusal | None:
        """Apply one event to one area. Refusals leave the table as it was."""
        old = self.states.get(area_id)
        if old is None and event == AreaEvent.RESET:
            return None
        new = TRANSITIONS[(old, event)]
        if isinstance(new, Refusal):
            return new
        if event == AreaEvent.DEFINE:
            assert definition is not None
            self.definitions[area_id] = definition
        if new is None:
            self.definitions.pop(area_id, None)
            self.states.pop(area_id, None)
        else:
            self.states[area_id] = new
        if new == AreaState.ACTIVE and old != AreaState.ACTIVE:
            self.activation_order.append(area_id)
        elif new != AreaState.ACTIVE and area_id in self.activation_order:
            self.activation_order.remove(area_id)
        if new != old or event == AreaEvent.DEFINE:
            self.version += 1
        return None

    def last_activated(self) -> int | None:
        return self.activation_order[-1] if self.activation_order else None

    def groups(self) -> list[Group]:
        """The active areas, grouped by the three axes they watch (C14-14, C14-17)."""
        if self._groups_version != self.version:
            by_axes: dict[frozenset[int], tuple[list[Prism], list[Prism]]] = {}
            for area_id in self.active_ids:
                d = self.definitions[area_id]
                works, prots = by_axes.setdefault(frozenset(d.indices), ([], []))
                (prots if d.kind == AreaKind.PROT else works).append(d.prism)
            # a Group is built from complete lists (it indexes their boxes once)
            self._groups = [Group(key, works, prots) for key, (works, prots) in by_axes.items()]
            self._groups_version = self.version
        return self._groups

    def groups_with(self, extra_active: list[int]) -> list[Group]:
        """The groups as they would be with ``extra_active`` activated too (the ON check, C14-11)."""
        trial = copy.copy(self)
        trial.states = dict(self.states)
        trial._groups_version = -1
        for area_id in extra_active:
            trial.states[area_id] = AreaState.ACTIVE
        return trial.groups()

    def to_json(self) -> list[dict[str, Any]]:
        return [self.definitions[i].to_json(self.states[i]) for i in sorted(self.definitions)]
