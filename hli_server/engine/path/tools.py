"""Tool data: the tool table of the machine file, D/T words and tool length compensation
(M-14, M-15).

The machine file's channel lists ``tools``: compensation data blocks with a number (the D word that selects
them), optionally the tool number T, a length and a radius (programming manual, "Tool geometry
compensation", https://infosys.beckhoff.com/content/1033/tccncprogramming/15557086347.html). ``D<n>``
selects block n, ``D0`` deselects (length and radius 0). A ``T`` word is accepted and recorded (the tool
change is the PLC's technology function); it does not select geometry data (``D`` does). Where the machine
file has no tool table at all, every D selects zero data (programs written for a real machine without
tool data run as they are); with a table, a D it does not hold is alarm 916001.

Tool length compensation: the length acts in the third main axis of the active plane in + direction
(``#TLAX`` default: G17 Z, G18 Y, G19 X; https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/
304765835.html). The programmed point is the tool tip; the axis goes to tip + length. As with
P-CHAN-00100 = 0 (the kernel's default,
https://infosys.beckhoff.com/content/1033/tf5200_channel_parameter/149123467.html) a new length is taken
into the axis position only at the next block that programs the tool axis absolutely (G90): a D word
alone, or a G91 move, does not move the axis to compensate. The work and protection areas monitor the tool
tip (the tool centre point): the decoder hands them the path less the applied length.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["ToolData", "ToolState"]


@dataclass(frozen=True, slots=True)
class ToolData:
    """One compensation data block [mm]."""

    number: int
    length: float = 0.0
    radius: float = 0.0
    tool: int | None = None
    kin_id: int = 0
    """P-TOOL-00011: the kinematic the tool selects (0: none)."""


@dataclass(slots=True)
class ToolState:
    """The table and what the program selected."""

    table: dict[int, ToolData] = field(default_factory=dict)
    d: int = 0
    t: int | None = None
    applied_length: float = 0.0
    """The length included in the tool axis' position now (mm)."""
    radius_written: float | None = None
    length_written: float | None = None
    """``V.G.WZR`` / ``V.G.WZ_AKT.L`` written by the program: they replace the D block's value until the
    next D word."""

    @property
    def data(self) -> ToolData:
        return self.table.get(self.d, ToolData(0))

    @property
    def length(self) -> float:
        if self.length_written is not None:
            return self.length_written
        return self.data.length if self.d else 0.0

    @property
    def radius(self) -> float:
        if self.radius_written is not None:
            return self.radius_written
        return self.data.radius if self.d else 0.0

    def select(self, d: int) -> str | None:
        """``D<n>``: an error text when the block is not in the table. A machine file without a tool table
        selects zero data (length and radius 0): CAM programs with ``T1 D1 M6`` run unchanged there."""
        if d != 0 and self.table and d not in self.table:
            known = ", ".join(f"D{n}" for n in sorted(self.table)) or "none"
            return (
                f"D{d}: no tool compensation data block {d} in the machine file's tool table (known: {known})"
            )
        self.d = d
        self.radius_written = self.length_written = None
        return None

    def reset(self) -> None:
        self.d = 0
        self.t = None
        self.applied_length = 0.0
        self.radius_written = self.length_written = None
