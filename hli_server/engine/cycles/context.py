"""What a running stand-in needs of its channel (the channel's interpreter host implements it).

Positions are program coordinates of the channel's three main axes (the probe's or the tool's tip), read
from the decoder in program order: the interpreter runs a stand-in lazily, one block at a time, and a
measuring move (G100) stops decoding until the move has ended, so what a stand-in reads after it is what
the machine did.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

from hli_server.engine.cycles.probe import Vec3

__all__ = ["CycleContext", "MotionState"]


class MotionState:
    """The caller's modal motion state, restored when the stand-in returns: G90/G91, G00..G03, F."""

    __slots__ = ("absolute", "feed", "motion")

    def __init__(self, absolute: bool, motion: int, feed: float | None) -> None:
        self.absolute = absolute
        self.motion = motion
        self.feed = feed


class CycleContext(Protocol):
    @property
    def axis_names(self) -> tuple[str, ...]:
        """The channel's axes (the parser's axis names)."""
        ...

    @property
    def main_axes(self) -> tuple[str, str, str]:
        """The first, second and third main axis (G17: X, Y, Z)."""
        ...

    def position(self) -> Vec3:
        """Where the tip is now in program coordinates (end of the last decoded block)."""
        ...

    def plane(self) -> int:
        """The active plane: 17, 18 or 19."""
        ...

    def inch(self) -> bool:
        """G70 is active (the stand-ins program in mm)."""
        ...

    def tool_radius(self) -> float:
        """The active D's radius [mm] (the probe sphere's radius of a touch probe)."""
        ...

    def zero_offset(self) -> str | None:
        """The active zero offset (``G54`` .. ``G59``), None with G53."""
        ...

    def motion_state(self) -> MotionState: ...

    def measured(self) -> float | None:
        """The last measuring move: the fraction of its line at which the probe signal came (the latched
        position), None when it ended without one."""
        ...

    def deviation(self) -> Vec3:
        """The simulated workpiece's deviation along the main axes [mm] (engine/cycles/probe.py)."""
        ...

    def probe_feeds(self) -> tuple[float, float]:
        """The touch probe's measuring and positioning feeds [mm/min] (the kernel's
        SysCalibConfigTouchprobe.nc; the machine file's ``[channels.probe]``)."""
        ...

    def write_zero_offset(self, name: str, values: Mapping[str, float]) -> None:
        """Write axis values [mm] into zero offset ``name`` (``G54`` .. ``G59``)."""
        ...

    def set_result(self, name: str, value: float) -> None:
        """``V.CYC.<name> = value``: the caller's variable where it declared one, else the cycle's own."""
        ...

    def write_program(self, name: str, text: str) -> None:
        """A program file the cycle writes (``CS_BASE_2.bcs``): ``L name`` finds it from now on."""
        ...

    def warn(self, alarm: int, message: str) -> None: ...
