"""Coordinate frames: program coordinates to machine coordinates (M-10..M-13).

The chain a programmed point of the three main axes goes through, in this order (programming manual,
https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/207442315.html (#ROTATION),
.../208480907.html (#CS), .../208491403.html (#ACS), .../1037259147.html (#CS ADD)):

1. ``#ROTATION ON [ANGLE= CENTER1= CENTER2=]``: contour rotation in the active plane about the centre
   (CENTER1, CENTER2), before every other function; a plane change deselects it.
2. The machining coordinate systems ``#CS``: each active CS is a translation ``v`` and a rotation
   (φ1, φ2, φ3) relative to the one below it (the lowest relative to the workpiece coordinates); rotation
   sequence ZYX (P-CHAN-00394's default): ``R = Rz(φ3) Ry(φ2) Rx(φ1)``, a point ``p`` of the CS is
   ``v + R p`` in the system below. ``#CS ADD [name]`` builds the same kind of stack by name.
3. The zero offsets G54..G59 and G92 (per axis).
4. The fixture systems ``#ACS``: the same as a CS, below the zero offsets (they compensate a skewed
   workpiece or pallet in the machine's coordinates).

Every step is a rigid transform, so lengths, radii and deviations are preserved: a path check in machine
coordinates sees the same shape as programmed. Areas are defined in machine coordinates: the decoder does
not apply this chain to a ``#CONTROL AREA`` definition (FCT-C14 section 2.3).

The frames act on the three main axes (in G17 order: first, second, third); other axes keep their
per-axis zero offset. A frame whose rotation tilts the active plane cannot carry a circle as an arc of the
simulator's geometry (arcs lie in G17/G18/G19 planes): :meth:`FrameStack.keeps_plane` says so, and the
decoder refuses such a circle with alarm 910110 (docs/nc-language.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["MAX_CS", "CsDefinition", "Frame", "FrameStack", "Vec3"]

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]

MAX_CS = 5
"""At most 5 CS (and 5 ACS) definitions are stored at the same time (programming manual, #CS)."""

_IDENTITY: Mat3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _mul(a: Mat3, b: Mat3) -> Mat3:
    return tuple(  # type: ignore[return-value]
        tuple(sum(a[r][k] * b[k][c] for k in range(3)) for c in range(3)) for r in range(3)
    )


def _apply(m: Mat3, p: Vec3) -> Vec3:
    return (
        m[0][0] * p[0] + m[0][1] * p[1] + m[0][2] * p[2],
        m[1][0] * p[0] + m[1][1] * p[1] + m[1][2] * p[2],
        m[2][0] * p[0] + m[2][1] * p[1] + m[2][2] * p[2],
    )


def _transpose(m: Mat3) -> Mat3:
    return ((m[0][0], m[1][0], m[2][0]), (m[0][1], m[1][1], m[2][1]), (m[0][2], m[1][2], m[2][2]))


def _rot(axis: int, degrees: float) -> Mat3:
    """Rotation about axis 0 (X), 1 (Y), 2 (Z), mathematically positive."""
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    if abs(s) < 1e-15:
        s = 0.0
    if abs(c) < 1e-15:
        c = 0.0
    if axis == 0:
        return ((1.0, 0.0, 0.0), (0.0, c, -s), (0.0, s, c))
    if axis == 1:
        return ((c, 0.0, s), (0.0, 1.0, 0.0), (-s, 0.0, c))
    return ((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0))


@dataclass(frozen=True, slots=True)
class Frame:
    """A rigid transform ``p -> R p + t`` from a child system to its parent."""

    rotation: Mat3 = _IDENTITY
    translation: Vec3 = (0.0, 0.0, 0.0)

    @staticmethod
    def from_components(values: tuple[float, ...]) -> Frame:
        """``[v1, v2, v3, φ1, φ2, φ3]`` (missing components 0): ZYX rotation sequence."""
        v = (list(values) + [0.0] * 6)[:6]
        r = _mul(_mul(_rot(2, v[5]), _rot(1, v[4])), _rot(0, v[3]))
        return Frame(r, (v[0], v[1], v[2]))

    def apply(self, p: Vec3) -> Vec3:
        q = _apply(self.rotation, p)
        return (q[0] + self.translation[0], q[1] + self.translation[1], q[2] + self.translation[2])

    def inverse_apply(self, p: Vec3) -> Vec3:
        d = (p[0] - self.translation[0], p[1] - self.translation[1], p[2] - self.translation[2])
        return _apply(_transpose(self.rotation), d)

    @property
    def is_identity(self) -> bool:
        return self.rotation == _IDENTITY and self.translation == (0.0, 0.0, 0.0)


@dataclass(slots=True)
class CsDefinition:
    """A stored (A)CS: its frame and whether it was defined without an ID (gone after its OFF)."""

    frame: Frame
    anonymous: bool = False


@dataclass(slots=True)
class _Systems:
    """The stored definitions and the active stack of one kind (CS or ACS)."""

    kind: str
    defined: dict[int, CsDefinition] = field(default_factory=dict)
    active: list[int] = field(default_factory=list)
    last_defined: int | None = None

    def next_free(self) -> int:
        n = 1
        while n in self.defined:
            n += 1
        return n

    def define(self, cs_id: int | None, values: tuple[float, ...]) -> int | str:
        """Store a definition; returns its ID or an error text (more than :data:`MAX_CS`)."""
        anonymous = cs_id is None
        ident = self.next_free() if cs_id is None else cs_id
        if ident not in self.defined and len(self.defined) >= MAX_CS:
            return f"#{self.kind} DEF: at most {MAX_CS} {self.kind} definitions are stored at a time"
        self.defined[ident] = CsDefinition(Frame.from_components(values), anonymous)
        self.last_defined = ident
        return ident

    def activate(self, cs_id: int | None) -> str | None:
        ident = self.last_defined if cs_id is None else cs_id
        if ident is None or ident not in self.defined:
            return f"#{self.kind} ON{'' if cs_id is None else f' [{cs_id}]'}: the {self.kind} is not defined"
        self.active.append(ident)
        return None

    def deactivate(self, all_: bool) -> None:
        ids = self.active[:] if all_ else self.active[-1:]
        del self.active[len(self.active) - len(ids) :]
        for ident in ids:
            d = self.defined.get(ident)
            if d is not None and d.anonymous and ident not in self.active:
                del self.defined[ident]
                if self.last_defined == ident:
                    self.last_defined = None

    def frames(self) -> list[Frame]:
        """Active frames, lowest first."""
        return [self.defined[i].frame for i in self.active]


@dataclass(slots=True)
class FrameStack:
    """The program's coordinate frames (see the module's description). ``plane`` is the active plane's
    (first, second) main axis index (G17 (0, 1), G18 (2, 0), G19 (1, 2))."""

    cs: _Systems = field(default_factory=lambda: _Systems("CS"))
    acs: _Systems = field(default_factory=lambda: _Systems("ACS"))
    added: list[tuple[str, Frame]] = field(default_factory=list)
    """``#CS ADD`` stack (names, lowest first)."""
    rotation: tuple[float, float, float] | None = None
    """``#ROTATION ON``: angle in degrees, CENTER1, CENTER2."""
    plane: tuple[int, int] = (0, 1)

    @property
    def active(self) -> bool:
        return bool(self.cs.active or self.acs.active or self.added or self.rotation is not None)

    def reset(self) -> None:
        """Program start and reset: nothing active, nothing stored (the kernel's defaults)."""
        self.cs = _Systems("CS")
        self.acs = _Systems("ACS")
        self.added = []
        self.rotation = None

    def add(self, name: str, values: tuple[float, ...]) -> str | None:
        """``#CS ADD [name] [..]``: a new top of the named stack."""
        if name in {"ACS", "IMCS", "MCS"}:
            return f"#CS ADD [{name}]: the names ACS, IMCS and MCS are reserved"
        if any(n == name for n, _ in self.added):
            return f"#CS ADD [{name}]: a CS of that name is already in the stack (change it with #CS SET)"
        if len(self.added) >= MAX_CS:
            return f"#CS ADD: at most {MAX_CS} CS are linked in a stack"
        self.added.append((name, Frame.from_components(values)))
        return None

    def set_added(self, name: str, values: tuple[float, ...]) -> str | None:
        """``#CS SET [name] [..]``: change a CS of the stack."""
        for k, (n, _) in enumerate(self.added):
            if n == name:
                self.added[k] = (n, Frame.from_components(values))
                return None
        return f"#CS SET [{name}]: no CS of that name in the #CS ADD stack"

    def remove_added(self, name: str | None) -> str | None:
        """``#CS DEL [name]`` / ``#CS DEL ALL`` (None)."""
        if name is None:
            self.added = []
            return None
        for k, (n, _) in enumerate(self.added):
            if n == name:
                del self.added[k]
                return None
        return f"#CS DEL [{name}]: no CS of that name in the #CS ADD stack"

    def _rotate(self, p: Vec3, sign: float) -> Vec3:
        if self.rotation is None:
            return p
        angle, c1, c2 = self.rotation
        i, j = self.plane
        a = math.radians(angle) * sign
        c, s = math.cos(a), math.sin(a)
        q = list(p)
        x, y = p[i] - c1, p[j] - c2
        q[i] = c1 + c * x - s * y
        q[j] = c2 + s * x + c * y
        return (q[0], q[1], q[2])

    def _cs_frames(self) -> list[Frame]:
        return [f for _, f in self.added] + self.cs.frames()

    def to_workpiece(self, p: Vec3) -> Vec3:
        """Program coordinates -> workpiece coordinates (rotation, then the CS from the top down)."""
        q = self._rotate(p, 1.0)
        for f in reversed(self._cs_frames()):
            q = f.apply(q)
        return q

    def from_workpiece(self, p: Vec3) -> Vec3:
        q = p
        for f in self._cs_frames():
            q = f.inverse_apply(q)
        return self._rotate(q, -1.0)

    def fixture_to_machine(self, p: Vec3) -> Vec3:
        q = p
        for f in reversed(self.acs.frames()):
            q = f.apply(q)
        return q

    def machine_to_fixture(self, p: Vec3) -> Vec3:
        q = p
        for f in self.acs.frames():
            q = f.inverse_apply(q)
        return q

    def keeps_plane(self, plane: tuple[int, int]) -> int:
        """+1 when every rotation of the chain maps the plane onto itself with its orientation, -1 when
        mirrored (its normal reversed), 0 when the plane is tilted."""
        normal_index = 3 - plane[0] - plane[1]
        m = _IDENTITY
        for f in self._cs_frames() + self.acs.frames():
            m = _mul(m, f.rotation)
        n = m[normal_index][normal_index]
        off = max(abs(m[k][normal_index]) for k in range(3) if k != normal_index)
        if off > 1e-9 or abs(abs(n) - 1.0) > 1e-9:
            return 0
        return 1 if n > 0 else -1
