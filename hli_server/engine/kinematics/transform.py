"""A kinematic transformation bound to the channel: whole channel points, tool tip <-> axes.

The planner plans the path of the tool tip (RTCP: the programmed contour with the programmed feed); the
point it hands on each cycle goes through :meth:`Transformation.to_axes` to the axes. A channel point is
one value per channel axis (the decoder's axis order). The transformation reads and writes the slots of
its kinematic axis indices (``slots[i]``: the channel slot of kinematic index i; the kernel numbers
them by the axis index of the channel's configuration, ``#SET AX`` changes it): in a *tip point* the
slots of the indices 0, 1, 2 hold the tool tip (X, Y, Z in machine coordinates: program coordinates with
the zero offsets and frames applied), and the slots of the rotary axes hold

* with an RTCP transformation (``mode`` 0, P-CHAN-00287 = 1): the rotary axes' own values, passed on;
* with a complete transformation (``mode`` 14..19, P-CHAN-00288): the two angles of the programming
  mode, in the slots of the rotary axes in index order (the mode's first letter in the lower index);
  :meth:`to_axes` turns them into the orientation and the orientation into the axes' angles.

Every other slot (an axis the kinematic does not contain, e.g. the tube axis U at index 5 in plate
machining, TF5290) is passed on unchanged.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from hli_server.engine.kinematics.chain import Chain, KinematicError
from hli_server.engine.kinematics.modes import mode_angles, mode_orientation

__all__ = ["Transformation"]


@dataclass(frozen=True, slots=True)
class Transformation:
    """The active transformation: kinematic ``kin_id`` with its ``chain`` and the tool's length."""

    kin_id: int
    chain: Chain
    slots: tuple[int, ...]
    """Channel slot of each kinematic axis index."""
    tool_length: float = 0.0
    """mm: the active tool's length, along the tool orientation."""
    mode: int = 0
    """0: RTCP (programmed angles are the axes'); 14..19: complete, the P-CHAN-00288 programming mode."""
    name: str = ""
    """What the kinematic is, for messages and the documentation (e.g. "TF5290 AB head")."""
    scaled_slot: int = -1
    """Lateral surface machining (#CYL): the channel slot of the rotary axis programmed as the surface's
    development in mm; -1: none."""
    scale: float = 1.0
    """Degrees of that rotary axis per mm of the development (180 / (pi R))."""
    scale_offset: float = 0.0
    """Degrees of that axis at development 0 (its angle offset)."""

    @property
    def complete(self) -> bool:
        return self.mode != 0

    def _angle_slots(self) -> tuple[int, int]:
        """The slots of the programmed angles (complete transformation): the rotary axes in index order."""
        indices = sorted(j.index for j in self.chain.rotary)
        return self.slots[indices[0]], self.slots[indices[1]]

    def _kin_values(self, point: Sequence[float]) -> list[float]:
        return [point[s] for s in self.slots]

    def to_axes(self, tip: Sequence[float], hint: Sequence[float] | None = None) -> tuple[float, ...]:
        """A tip point -> the axes' positions. ``hint``: axis positions near the result (the previous
        cycle's, the segment's start): a complete transformation takes the pose nearest to it, each angle
        the shortest way. Raises :class:`KinematicError` where the pose cannot be reached."""
        chain = self.chain
        slots = self.slots
        q = self._kin_values(tip)
        if self.mode:
            s1, s2 = self._angle_slots()
            target = mode_orientation(self.mode, tip[s1], tip[s2])
            h = self._kin_values(hint if hint is not None else tip)
            first, second = chain.rotary
            q[first.index], q[second.index] = chain.solve_orientation(target, h)
        chain.solve_linear(q, (tip[slots[0]], tip[slots[1]], tip[slots[2]]), self.tool_length)
        out = list(tip)
        for joint in chain.joints:
            out[slots[joint.index]] = q[joint.index]
        scaled = self.scaled_slot
        if scaled >= 0:
            out[scaled] = tip[scaled] * self.scale + self.scale_offset
        return tuple(out)

    def to_tip(self, axes: Sequence[float], hint: Sequence[float] | None = None) -> tuple[float, ...]:
        """Axis positions -> the tip point. ``hint``: the programmed angles near the result (a complete
        transformation: the pose of the mode's angles nearest to it; at a pole the free angle keeps it)."""
        chain = self.chain
        slots = self.slots
        q = self._kin_values(axes)
        tip, orientation = chain.forward(q, self.tool_length)
        out = list(axes)
        out[slots[0]], out[slots[1]], out[slots[2]] = tip
        scaled = self.scaled_slot
        if scaled >= 0:
            out[scaled] = (axes[scaled] - self.scale_offset) / self.scale
        if self.mode:
            s1, s2 = self._angle_slots()
            h = hint if hint is not None else axes
            out[s1], out[s2] = mode_angles(self.mode, orientation, h[s1], h[s2])
        return tuple(out)

    def angle_slots(self) -> tuple[tuple[int, float], ...]:
        """The slots whose axes turn, with the degrees of the axis per unit of the tip point's value
        (1 for a rotary axis of the chain, :attr:`scale` for the development of #CYL)."""
        out = [(self.slots[j.index], 1.0) for j in self.chain.rotary]
        if self.scaled_slot >= 0:
            out.append((self.scaled_slot, abs(self.scale)))
        return tuple(out)

    def orientation(self, axes: Sequence[float]) -> tuple[float, float, float]:
        """The tool orientation (unit vector, tip -> holder) at the axis positions ``axes``."""
        return self.chain.orientation(self._kin_values(axes))

    def check(self, n_slots: int) -> None:
        """The chain's own check, and every slot within the channel's ``n_slots`` axes (292040)."""
        self.chain.check()
        needed = max(j.index for j in self.chain.joints)
        if len(self.slots) <= needed or any(
            not 0 <= self.slots[j.index] < n_slots for j in self.chain.joints
        ):
            raise KinematicError(
                292040,
                f"kinematic {self.kin_id} needs the axis indices 0..{needed} in the channel; the channel's "
                f"configuration has {n_slots} axes",
            )
