"""Every documented TF5225/TF5293 cycle: the stand-ins built, and the ones not built (refused naming them).

:func:`find` is what the interpreter asks once the user's own files (program directories, the channel's
``cycle_directories``) have no file of the name: a :class:`~hli_server.engine.cycles.base.StandIn` to run, a
:class:`NotBuilt` to refuse with 910110 naming the cycle, or None (an unknown cycle: 914010, not found).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass

from hli_server.engine.cycles.base import Cycle, StandIn
from hli_server.engine.cycles.context import CycleContext
from hli_server.engine.cycles.drilling import DRILLING, PATTERNS
from hli_server.engine.cycles.errors import A_NOT_SIMULATED, CycleError
from hli_server.engine.cycles.measuring import MEASURING
from hli_server.engine.cycles.milling import MILLING
from hli_server.engine.cycles.params import ParamValue
from hli_server.engine.nc.blocks import Block

__all__ = ["BUILT", "NOT_BUILT", "NotBuilt", "find", "run"]

_MEAS = "https://infosys.beckhoff.com/content/1033/tf5225_tc3_cnc_cycles_measurement/"
_MILL = "https://infosys.beckhoff.com/content/1033/tf5293_tc3_cnc_cycles_millingbase/"


@dataclass(frozen=True, slots=True)
class NotBuilt:
    """A documented cycle without a stand-in."""

    name: str
    package: str
    title: str
    page: str


BUILT: tuple[StandIn, ...] = (*MEASURING, *DRILLING, *PATTERNS, *MILLING)

NOT_BUILT: tuple[NotBuilt, ...] = (
    NotBuilt("SysMeasWcs30.ecy", "TF5225", "Centre point across 4 drilled holes", _MEAS + "303737611.html"),
    NotBuilt("SysMeasWcs31.ecy", "TF5225", "Centre point of a hole circle", _MEAS + "303746443.html"),
    NotBuilt("SysMeasWcs35.ecy", "TF5225", "Measuring any outer corner", _MEAS + "548364555.html"),
    NotBuilt("SysMeasCs3.ecy", "TF5225", "Automatic teach-in", _MEAS + "312267531.html"),
    NotBuilt("SysMeasCs4.ecy", "TF5225", "Align a plane", _MEAS + "550051723.html"),
    NotBuilt("SysMeasLaserTool.ecy", "TF5225", "Measure a tool with a laser", _MEAS + "323203211.html"),
    NotBuilt(
        "SysMeasLaserToolBreak.ecy", "TF5225", "Tool breakage check with a laser", _MEAS + "323076875.html"
    ),
    NotBuilt("SysDrillHelicalMilling.ecy", "TF5293", "Helical drill milling", _MILL + "519474699.html"),
    NotBuilt("SysDrillThreadMilling.ecy", "TF5293", "Drill thread milling", _MILL + "519637899.html"),
    NotBuilt("SysDrillTapping.ecy", "TF5293", "Thread tapping", _MILL + "519339659.html"),
    NotBuilt("SysDrillPatternFrame.ecy", "TF5293", "Drilling a point frame", _MILL + "894407051.html"),
    NotBuilt("SysDrillPatternGrid.ecy", "TF5293", "Drilling a point grid", _MILL + "894393227.html"),
    NotBuilt("SysDrillPatternArbitrary.ecy", "TF5293", "Drilling at any positions", _MILL + "961610251.html"),
    NotBuilt("SysMillRectangularSpigot.ecy", "TF5293", "Mill a rectangular spigot", _MILL + "546302859.html"),
    NotBuilt("SysMillCircularSpigot.ecy", "TF5293", "Mill a circular spigot", _MILL + "546184587.html"),
    NotBuilt(
        "SysMillCircumferentialSlot.ecy",
        "TF5293",
        "Mill slots arranged in a circle",
        _MILL + "547415819.html",
    ),
    NotBuilt("SysMillFace.ecy", "TF5293", "Face milling", _MILL + "528160139.html"),
    NotBuilt("SysMillContourPocket.ecy", "TF5293", "Mill a contour pocket", _MILL + "780306315.html"),
    NotBuilt("SysMillContourSpigot.ecy", "TF5293", "Mill a contour spigot", _MILL + "780692747.html"),
    NotBuilt("SysMillContourPath.ecy", "TF5293", "Path milling", _MILL + "781073419.html"),
)


def _key(name: str) -> str:
    key = name.strip().strip('"').casefold()
    return key if key.endswith(".ecy") else key + ".ecy"


_INDEX: dict[str, StandIn | NotBuilt] = {}
for _built in BUILT:
    _INDEX[_key(_built.name)] = _built
for _missing in NOT_BUILT:
    _INDEX[_key(_missing.name)] = _missing


def find(name: str) -> StandIn | NotBuilt | None:
    """The documented cycle the call names (``SysMeasWcs27.ecy``; case-insensitive, the kernel's host is
    Windows; the extension may be left out), or None."""
    return _INDEX.get(_key(name))


def run(
    name: str, params: Mapping[int, ParamValue], ctx: CycleContext, line: int, call_text: str = ""
) -> Iterator[Block] | None:
    """The blocks of a stand-in's run (parameters checked when the first block is asked for); None when
    no documented cycle has the name; :class:`CycleError` (910110) for one without a stand-in."""
    found = find(name)
    if found is None:
        return None
    if isinstance(found, NotBuilt):
        raise CycleError(
            A_NOT_SIMULATED,
            f"{found.name} ({found.package}, {found.title}) has no built-in stand-in in the simulator: put "
            f"the cycle file into a program directory or the channel's cycle_directories ({found.page})",
        )
    return Cycle(found, params, ctx, line, call_text).blocks()
