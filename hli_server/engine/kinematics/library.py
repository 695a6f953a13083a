"""The kinematic types the simulator knows, built from a kinematic data set (P-CHAN-00262, P-CHAN-00263).

A data set is what the channel parameters ``trafo[j].*`` hold (and ``V.G.KIN[id].PARAM[i]`` writes
change): the kinematic ID, the kinematic type (P-CHAN-00829; 0: the type is the ID,
https://infosys.beckhoff.com/content/1033/tf5240_kinematic_transformation/893485323.html) and the
parameters ``param[0..73]`` in the kernel's units (0.1 µm, 0.0001°). The types:

* **91, Universal Kinematics** (TF5240 universal kinematic): the chain described axis by axis; the
  parameters in the layout of ``V.G.KIN[91].PARAM[i]`` (".../882078603.html": ZERO_ORIENTATION =
  PARAM[0..2], ZERO_POSITION = PARAM[3..5], NUMBER_OF_AXES = PARAM[6], AXIS[k].TYPE = PARAM[7 + 7k],
  AXIS[k].ORIENTATION = PARAM[8 + 7k .. 10 + 7k], AXIS[k].POINT = PARAM[11 + 7k .. 13 + 7k]) plus the
  chain order (P-CHAN-00290), the programming mode (P-CHAN-00288) and the angle transformation
  (P-CHAN-00287: 1 RTCP, 0 complete). Heads (AB, BA, CA, AC, BC, CB fork heads), rotary/tilting
  tables and any head/table combination are chains of this kind.
* **90, TF5290 orientation head** (CNC Cutting Plus, ".../tf5290_cnc_cutting_plus/297533579.html"):
  HD1..HD18 = param[0..17]; HD13 (param[12]) the head: 0 AB, 1 BA, 2 CA, 4 CB (8 CA cardanic, 9 AU, 10 BV
  are refused: their geometry is not on the public pages); HD14 (param[13]) 0: program the head's angles
  (RTCP), 1: program virtual C-A angles (complete, CA mode).
* **any other type with every parameter 0**: its geometry is not on the public pages, but with all its
  offsets 0 the tool tip is where the axes put it: simulated as the identity (the tool length along Z, as
  without a transformation), said so by warning 913001. With a parameter set it is refused (910110).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from hli_server.engine.kinematics.chain import (
    ALARM_AXIS_CONFIGURATION,
    ALARM_MODE_UNSUPPORTED,
    Chain,
    Joint,
    KinematicError,
)
from hli_server.engine.kinematics.modes import MODES
from hli_server.engine.kinematics.transform import Transformation
from hli_server.engine.kinematics.vectors import Vec3, add, norm, unit

__all__ = [
    "ALARM_NOT_SIMULATED",
    "ALARM_SIMULATED_AS_IDENTITY",
    "LATERAL",
    "TUBE",
    "TUBE_HEADS",
    "UNIVERSAL",
    "KinematicData",
    "build",
    "universal_params",
]

UNIVERSAL = 91
TUBE = 90
LATERAL = 15
"""KIN_TYP_15, lateral surface (#CYL): X, Y, Z as they are; the decoder adds the development of the rotary
axis (https://infosys.beckhoff.com/content/1033/tf5240_kinematic_transformation/1272858251.html; of its
parameters only HD2, the angle offset of the rotary axis, is simulated)."""
ALARM_NOT_SIMULATED = 910110
ALARM_SIMULATED_AS_IDENTITY = 913001
"""Warning (project's own number): a kinematic type whose geometry the public pages do not give runs
as the identity because all its parameters are 0."""

TUBE_HEADS: dict[int, str] = {0: "AB", 1: "BA", 2: "CA", 4: "CB"}
"""TF5290 HD13 -> the head's rotary axes in chain order (the first one nearer the machine)."""
_TUBE_REFUSED: dict[int, str] = {8: "CA cardanic head", 9: "AU kinematics", 10: "BV kinematics"}
_DIRECTION: dict[str, Vec3] = {"A": (1.0, 0.0, 0.0), "B": (0.0, 1.0, 0.0), "C": (0.0, 0.0, 1.0)}
_LENGTH = 1e-4
"""mm per unit of a length parameter (0.1 µm)."""
_ANGLE = 1e-4
"""Degrees per unit of an angle parameter (0.0001°)."""


@dataclass(slots=True)
class KinematicData:
    """One kinematic data set (``trafo[j]``): what the machine file gives and the program changes."""

    kin_id: int
    kin_type: int = 0
    """P-CHAN-00829; 0: the type is the ID."""
    params: dict[int, float] = field(default_factory=dict)
    """P-CHAN-00263 ``param[i]`` in the kernel's units (0.1 µm, 0.0001°; dimensionless for flags and the
    direction vectors of the Universal Kinematics)."""
    chain: tuple[int, ...] = ()
    """P-CHAN-00290 (Universal Kinematics): the axis indices in chain order; empty: 0 .. n-1."""
    programming_mode: int = 0
    """P-CHAN-00288 (Universal Kinematics)."""
    rtcp: int = 0
    """P-CHAN-00287 (Universal Kinematics): 1 RTCP, 0 complete transformation."""

    @property
    def effective_type(self) -> int:
        return self.kin_type or self.kin_id

    def copy(self) -> KinematicData:
        return KinematicData(
            self.kin_id, self.kin_type, dict(self.params), self.chain, self.programming_mode, self.rtcp
        )


def universal_params(
    zero_orientation: Sequence[float],
    zero_position: Sequence[float],
    axes: Sequence[tuple[int, Sequence[float], Sequence[float]]],
) -> dict[int, float]:
    """The ``PARAM[i]`` layout of the Universal Kinematics from its named parts (positions in 0.1 µm):
    ``axes`` (type 1 linear / 2 rotary, orientation, point) by axis index."""
    p: dict[int, float] = {}
    for i in range(3):
        p[i] = float(zero_orientation[i])
        p[3 + i] = float(zero_position[i])
    p[6] = float(len(axes))
    for k, (kind, orientation, point) in enumerate(axes):
        base = 7 + 7 * k
        p[base] = float(kind)
        for i in range(3):
            p[base + 1 + i] = float(orientation[i])
            p[base + 4 + i] = float(point[i])
    return p


def build(data: KinematicData, slots: tuple[int, ...], tool_length: float) -> tuple[Transformation, bool]:
    """The transformation of ``data`` bound to the channel ``slots``; the flag says it is the identity
    stand-in (warning 911050). Raises :class:`KinematicError` for a data set that describes no usable
    kinematic (the kernel's 2920xx) or a type the simulator does not model (910110)."""
    kind = data.effective_type
    if kind == UNIVERSAL:
        return _universal(data, slots, tool_length), False
    if kind == TUBE:
        return _tube_head(data, slots, tool_length), False
    if kind == LATERAL:
        return Transformation(data.kin_id, _identity(), slots[:3], tool_length, 0, "tool on X, Y, Z"), False
    if any(v != 0.0 for v in data.params.values()):
        raise KinematicError(
            ALARM_NOT_SIMULATED,
            f"kinematic ID {data.kin_id}: type {kind} is not simulated with parameters set (its "
            "geometry is not "
            "in the public documents); describe the machine as Universal Kinematics (type 91, "
            "docs/kinematics.md)",
        )
    name = f"kinematic type {kind} (identity: all parameters 0)"
    return Transformation(data.kin_id, _identity(), slots[:3], tool_length, 0, name), True


def _identity() -> Chain:
    """X, Y, Z and nothing else: the tool tip is the axes' point less the tool length along Z."""
    return Chain(
        (
            Joint(0, False, (1.0, 0.0, 0.0)),
            Joint(1, False, (0.0, 1.0, 0.0)),
            Joint(2, False, (0.0, 0.0, 1.0)),
        ),
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 1.0),
    )


def _vec(p: Mapping[int, float], start: int, unit_value: float = 1.0) -> Vec3:
    return (
        p.get(start, 0.0) * unit_value,
        p.get(start + 1, 0.0) * unit_value,
        p.get(start + 2, 0.0) * unit_value,
    )


def _universal(data: KinematicData, slots: tuple[int, ...], tool_length: float) -> Transformation:
    p = data.params
    n = int(p.get(6, 0.0))
    if not 3 <= n <= 6 or n > len(slots):
        raise KinematicError(
            ALARM_AXIS_CONFIGURATION,
            f"Universal Kinematics ID {data.kin_id}: NUMBER_OF_AXES {n} (P-CHAN-00289 3..6, at most the "
            f"channel's {len(slots)} axes)",
        )
    zero_orientation = _vec(p, 0)
    if norm(zero_orientation) == 0.0:
        raise KinematicError(
            ALARM_AXIS_CONFIGURATION,
            f"Universal Kinematics ID {data.kin_id}: ZERO_ORIENTATION is the zero vector",
        )
    joints: dict[int, Joint] = {}
    for k in range(n):
        base = 7 + 7 * k
        kind = int(p.get(base, 0.0))
        direction = _vec(p, base + 1)
        if kind not in (1, 2) or norm(direction) == 0.0:
            raise KinematicError(
                ALARM_AXIS_CONFIGURATION,
                f"Universal Kinematics ID {data.kin_id}: AXIS[{k}] needs TYPE 1 (linear) or 2 "
                "(rotary) and an "
                f"ORIENTATION that is not the zero vector (P-CHAN-00291, P-CHAN-00292), got {kind}, "
                f"{direction}",
            )
        joints[k] = Joint(k, kind == 2, unit(direction), _vec(p, base + 4, _LENGTH))
    order = data.chain or tuple(range(n))
    if sorted(order) != list(range(n)):
        raise KinematicError(
            ALARM_AXIS_CONFIGURATION,
            f"Universal Kinematics ID {data.kin_id}: the chain {list(order)} (P-CHAN-00290) must name "
            "each axis "
            f"index 0..{n - 1} once",
        )
    chain = Chain(tuple(joints[k] for k in order), _vec(p, 3, _LENGTH), unit(zero_orientation))
    mode = 0
    if data.rtcp != 1:
        if data.programming_mode not in MODES:
            raise KinematicError(
                ALARM_MODE_UNSUPPORTED,
                f"Universal Kinematics ID {data.kin_id}: the complete transformation (P-CHAN-00287 = 0) is "
                f"simulated with the angle modes 14..19 of P-CHAN-00288, got {data.programming_mode}; point-"
                "vector (10), direct (12) and conformal (13) programming are not simulated",
            )
        mode = data.programming_mode
    trafo = Transformation(
        data.kin_id, chain, slots[:n], tool_length, mode, f"Universal Kinematics ({n} axes)"
    )
    trafo.check(len(slots))
    if mode and len(chain.rotary) != 2:
        raise KinematicError(
            ALARM_MODE_UNSUPPORTED,
            f"Universal Kinematics ID {data.kin_id}: the complete transformation needs two rotary "
            "axes, the chain "
            f"has {len(chain.rotary)}",
        )
    return trafo


def _tube_head(data: KinematicData, slots: tuple[int, ...], tool_length: float) -> Transformation:
    p = data.params
    structure = int(p.get(12, 0.0))
    if structure in _TUBE_REFUSED:
        raise KinematicError(
            ALARM_NOT_SIMULATED,
            f"kinematic ID {data.kin_id} (TF5290): HD13 = {structure} ({_TUBE_REFUSED[structure]}) is "
            "not simulated; "
            "the AB, BA, CA and CB heads (HD13 0, 1, 2, 4) are",
        )
    letters = TUBE_HEADS.get(structure)
    if letters is None:
        raise KinematicError(
            ALARM_AXIS_CONFIGURATION,
            f"kinematic ID {data.kin_id} (TF5290): HD13 = {structure} is no head structure "
            "(0 AB, 1 BA, 2 CA, 4 CB)",
        )
    if len(slots) < 5:
        raise KinematicError(
            ALARM_AXIS_CONFIGURATION,
            f"kinematic ID {data.kin_id} (TF5290 {letters} head) needs the axes X, Y, Z and the "
            "head's two rotary "
            f"axes on the axis indices 0..4; the channel has {len(slots)} axes",
        )
    fixing: Vec3 = (p.get(1, 0.0) * _LENGTH, p.get(2, 0.0) * _LENGTH, -p.get(0, 0.0) * _LENGTH)
    first_point = _vec(p, 6, _LENGTH)
    second_point = add(first_point, _vec(p, 3, _LENGTH))
    signs = (-1.0 if p.get(14, 0.0) else 1.0, -1.0 if p.get(15, 0.0) else 1.0)
    offsets = (p.get(16, 0.0) * _ANGLE, p.get(17, 0.0) * _ANGLE)
    chain = Chain(
        (
            Joint(0, False, (1.0, 0.0, 0.0)),
            Joint(1, False, (0.0, 1.0, 0.0)),
            Joint(2, False, (0.0, 0.0, 1.0)),
            Joint(3, True, _DIRECTION[letters[0]], first_point, signs[0], offsets[0]),
            Joint(4, True, _DIRECTION[letters[1]], second_point, signs[1], offsets[1]),
        ),
        add(second_point, fixing),
        (0.0, 0.0, 1.0),
    )
    programming = int(p.get(13, 0.0))
    mode = 17 if programming == 1 and structure in (0, 1) else 0
    name = f"TF5290 {letters} head" + (", CA programming" if mode else "")
    return Transformation(data.kin_id, chain, slots[:5], tool_length, mode, name)
