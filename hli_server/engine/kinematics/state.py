"""The channel's kinematic state while a program is decoded: the data sets, the selection, the active
transformation (docs/kinematics.md).

* The data sets come from the machine file (``trafo[j]``, P-CHAN-00262/00263) at every program start;
  ``V.G.KIN[id].PARAM[i]`` writes change them in program order, for the rest of the program. A
  transformation takes its data when it is switched on (``#TRAFO ON``); a write while it is on counts
  from the next ``#TRAFO ON``.
* ``#KIN ID [id]`` selects a kinematic, ``#KIN ID`` the default P-CHAN-00032; not while a transformation
  is on (the kernel's 20687, https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/252225419.html).
  A tool's ``kin_id`` (P-TOOL-00011) selects like ``#KIN ID`` while no transformation is on and must be the
  active one's while one is (20990).
* An ID without a data set in the machine file is the kernel library's type of that number with every
  parameter 0 (P-CHAN-00263's default), so that the public examples run on a machine that only has
  their axes; the real kernel wants the ID among ``trafo[j].id``. IDs beyond P-CHAN-00032's range
  (1..999) with no data set are illegal: 292005. ID 0 selects no kinematic ("no warning or error").
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from hli_server.engine.kinematics.chain import KinematicError
from hli_server.engine.kinematics.library import ALARM_SIMULATED_AS_IDENTITY, KinematicData, build
from hli_server.engine.kinematics.transform import Transformation

__all__ = [
    "ALARM_ILLEGAL_ID",
    "ALARM_KIN_CHANGE_ACTIVE",
    "ALARM_PARAM_INDEX",
    "ALARM_TOOL_KIN_ID",
    "KinematicState",
]

ALARM_ILLEGAL_ID = 292005
"""Kinematic transformation: illegal kinematic ID (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/
267448715.html)."""
ALARM_KIN_CHANGE_ACTIVE = 20687
"""Kinematic change not allowed during active RTCP/TLC."""
ALARM_TOOL_KIN_ID = 20990
"""The tool's kinematic ID differs from the active transformation's (P-TOOL-00011)."""
ALARM_PARAM_INDEX = 913000
"""Project's own: a ``V.G.KIN[i].PARAM[j]`` outside the data set (j 0..73, i 1..65535)."""
LIBRARY_IDS = range(1, 1000)
"""P-CHAN-00032's data range: the IDs of the kernel's library."""
PARAMS = 74


@dataclass(slots=True)
class KinematicState:
    """See the module's description. ``configured``: the machine file's data sets by ID; ``n_slots``: the
    channel's axes."""

    configured: dict[int, KinematicData]
    default_id: int
    n_slots: int
    data: dict[int, KinematicData] = field(default_factory=dict)
    selected: int = 0
    active: Transformation | None = None
    slots: tuple[int, ...] = ()
    """The channel slot of each axis index (#SET AX changes it)."""
    warnings: list[tuple[int, str]] = field(default_factory=list)
    """Warnings of the last switch-on (alarm, message) for the decoder to raise."""

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Program start and reset: the machine file's data sets, the default selection, nothing active."""
        self.data = {k: d.copy() for k, d in self.configured.items()}
        self.selected = self.default_id
        self.active = None
        self.slots = tuple(range(min(self.n_slots, 6)))

    def select(self, kin_id: int | None) -> None:
        """``#KIN ID``: raises :class:`KinematicError` (20687) while a transformation is on."""
        if self.active is not None:
            raise KinematicError(
                ALARM_KIN_CHANGE_ACTIVE,
                f"#KIN ID while kinematic {self.active.kin_id} is active: program #TRAFO OFF first",
            )
        self.selected = self.default_id if kin_id is None else kin_id

    def tool_kinematic(self, kin_id: int) -> None:
        """A tool with ``kin_id`` (P-TOOL-00011) was selected."""
        if kin_id == 0:
            return
        if self.active is not None:
            if kin_id != self.active.kin_id:
                raise KinematicError(
                    ALARM_TOOL_KIN_ID,
                    f"the tool's kinematic ID {kin_id} (P-TOOL-00011) differs from the active "
                    "transformation's "
                    f"{self.active.kin_id}",
                )
            return
        self.selected = kin_id

    def write(self, kin_id: int, index: int, value: float) -> None:
        """``V.G.KIN[kin_id].PARAM[index] = value``."""
        if not 1 <= kin_id <= 65535 or not 0 <= index < PARAMS:
            raise KinematicError(
                ALARM_PARAM_INDEX,
                f"V.G.KIN[{kin_id}].PARAM[{index}]: kinematic IDs 1..65535, parameters 0..{PARAMS - 1}",
            )
        self.set_of(kin_id).params[index] = value

    def set_of(self, kin_id: int) -> KinematicData:
        data = self.data.get(kin_id)
        if data is None:
            data = self.data[kin_id] = KinematicData(kin_id)
        return data

    def switch_on(self, tool_length: float) -> Transformation | None:
        """``#TRAFO ON``: the selected kinematic as a transformation (None for ID 0: nothing is switched
        on); its warnings in :attr:`warnings`. Raises :class:`KinematicError` where it cannot be built."""
        self.warnings = []
        kin_id = self.selected
        if kin_id == 0:
            return None
        data = self.data.get(kin_id)
        if data is None and kin_id not in LIBRARY_IDS:
            raise KinematicError(
                ALARM_ILLEGAL_ID,
                f"kinematic ID {kin_id}: not among the machine's data sets (trafo[j].id, P-CHAN-00262) and "
                "beyond the library's 1..999",
            )
        data = data or KinematicData(kin_id)
        trafo, identity = build(data, self.slots, tool_length)
        trafo.check(self.n_slots)
        if identity:
            self.warnings.append(
                (
                    ALARM_SIMULATED_AS_IDENTITY,
                    f"kinematic ID {kin_id} (type {data.effective_type}): the public pages do not "
                    "give this type's "
                    "geometry; with every parameter 0 it is simulated as the identity (the tool "
                    "length along Z). "
                    "Describe the machine as Universal Kinematics (type 91) to simulate it "
                    "(docs/kinematics.md)",
                )
            )
        self.active = trafo
        return trafo

    def switch_off(self) -> None:
        self.active = None

    def configure_slots(self, slots: Iterable[int]) -> None:
        """``#SET AX``: the channel slots of the axis indices 0, 1, ... from here on."""
        self.slots = tuple(slots)[:6]
