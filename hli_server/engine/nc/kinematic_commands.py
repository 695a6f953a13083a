"""The NC program's kinematic commands, in program order for the decoder (issue 35, docs/kinematics.md).

The interpreter hands these to the decoder like its other directives; the decoder acts on them when it
reaches them (a selection changes what the following blocks mean, so it is decoded in order).
"""

from __future__ import annotations

from hli_server.engine.nc.blocks import Block
from hli_server.engine.nc.directives import Directive

__all__ = [
    "AxisEntry",
    "CaxTrack",
    "CylSelect",
    "KinParamWrite",
    "KinSelect",
    "KinematicCommand",
    "SetAxes",
    "ToolOriCs",
    "TrafoSwitch",
]


class KinematicCommand(Directive):
    """A kinematic command; ``block`` says where it was programmed (line, N)."""


class KinSelect(KinematicCommand):
    """``#KIN ID [<id>]`` (``kin_id``), ``#KIN ID`` alone: the default P-CHAN-00032 (``kin_id`` None)."""

    def __init__(self, block: Block | None, kin_id: int | None) -> None:
        super().__init__(block)
        self.kin_id = kin_id


class TrafoSwitch(KinematicCommand):
    """``#TRAFO ON`` / ``#TRAFO OFF`` (and the older ``#RTCP ON`` / ``OFF``)."""

    def __init__(self, block: Block | None, on: bool) -> None:
        super().__init__(block)
        self.on = on


class KinParamWrite(KinematicCommand):
    """``V.G.KIN[<id>].PARAM[<index>] = <value>``: a parameter of a kinematic data set (P-CHAN-00263 "
    "units)."""

    def __init__(self, block: Block | None, kin_id: int, index: int, value: float) -> None:
        super().__init__(block)
        self.kin_id = kin_id
        self.index = index
        self.value = value


class ToolOriCs(KinematicCommand):
    """``#TOOL ORI CS``: turn the tool to the axis P-CHAN-00188 of the active #CS; ``#TOOL ORI CS OFF``
    (``on`` False) ends it (the orientation stays)."""

    def __init__(self, block: Block | None, on: bool = True) -> None:
        super().__init__(block)
        self.on = on


class CylSelect(KinematicCommand):
    """``#CYL [<1st>, <2nd>, <3rd><radius>]`` (lateral surface, kinematic 15), ``#CYL ORI LATERAL
    [AX1=.. AX2=.. RADIUS=..]`` (tube, kinematic 90; ``lateral``), ``#CYL OFF`` (``axes`` empty)."""

    def __init__(
        self, block: Block | None, axes: tuple[str, ...] = (), radius: float = 0.0, lateral: bool = False
    ) -> None:
        super().__init__(block)
        self.axes = axes
        self.radius = radius
        self.lateral = lateral


class CaxTrack(KinematicCommand):
    """``#CAXTRACK ON [ANGLIMIT=.. OFFSET=.. AX=.. | AXNR=..]`` / ``#CAXTRACK OFF [ANGPOS=..]``."""

    def __init__(
        self,
        block: Block | None,
        on: bool,
        anglimit: float | None = None,
        offset: float = 0.0,
        axis: str | None = None,
        axis_number: int | None = None,
        angpos: float | None = None,
    ) -> None:
        super().__init__(block)
        self.on = on
        self.anglimit = anglimit
        self.offset = offset
        self.axis = axis
        self.axis_number = axis_number
        self.angpos = angpos


class AxisEntry:
    """One ``[<name>, <logical axis number>, <axis index>]`` of ``#SET AX``."""

    __slots__ = ("index", "name", "number")

    def __init__(self, name: str, number: int, index: int) -> None:
        self.name = name
        self.number = number
        self.index = index


class SetAxes(KinematicCommand):
    """``#SET AX [<mode>] [<name>, <number>, <index>] ...``: exactly these axes form the channel's axis
    configuration from here on."""

    def __init__(self, block: Block | None, entries: tuple[AxisEntry, ...], fast: bool = False) -> None:
        super().__init__(block)
        self.entries = entries
        self.fast = fast
