"""Demo PLC programs: the worked examples of the function descriptions, as a PLC would run them (H-06).

Each demo is a PLC program for :class:`~plc_clients.task.PlcTask` (``task = PlcTask(transport,
cycle_s, demo, watch=demo.watch)``) that drives one function of the CNC through the HLI and says
what it does, cycle by cycle:

================ ========== ===============================================================
name             document   what the PLC does
================ ========== ===============================================================
``c43-obstacle`` FCT-C43    an obstacle enters the work space (a simulated sensor): the PLC
                            sets ``MCV_DynPosLimitHigh`` on X, the program holds at the limit;
                            the obstacle leaves, the PLC lifts the limit, the program finishes
``c14-manual``   FCT-C14    in manual mode the jog stops at the work area's boundary
                            (``area_mon_violation_detected_r``); the PLC sets the control unit
                            ``suppress_area_mon_manual_mode`` to jog out and back, then lifts it
``c3-collision`` FCT-C3     the PLC reads the collision objects (``dyn_coll_mon``) of the gantry
                            pair X1/X2 and holds the approaching carriages with feedhold before
                            the CNC's own monitor would stop them with error 70092
``ve-mode``      V.E.       the PLC selects ``V.E.MODE`` and releases the program with
                            ``V.E.PLC_READY``; the NC program waits in a ``$WHILE`` loop,
                            branches with ``$IF`` into a subprogram, counts ``V.E.PART_COUNT``
================ ========== ===============================================================

The operator's part (loading the demo's NC program, :attr:`Demo.nc_program`, with the subprograms
it calls, :attr:`Demo.nc_files`, into :attr:`Demo.channel`) is done by whoever runs the demo (the
PLC starts it with a rising edge of ``start_w`` and writes ``program_select_w`` = 0, so that a
selection an earlier PLC left in the image does not replace it): ``hli-plc`` over the HTTP API, a test
through the harness' operator panel. Everything else goes through the PLC's door only, so a demo
behaves the same over shared memory, Modbus and ADS: its decisions depend on the CNC cycle of its
input image (``io.cycle``), never on the wall clock.

``examples/`` runs each demo against the real engine through every transport (the suite runs it);
``hli-plc`` (:mod:`plc_clients.cli`) runs one against a running server.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

if TYPE_CHECKING:
    from plc_clients.task import IoImage

__all__ = ["DEMOS", "Demo", "demo_class"]


class Demo:
    """A demo PLC program: call it once per PLC task cycle with the task's :class:`IoImage`.

    ``done`` turns TRUE when the scenario is over, ``failed`` when it went wrong (the last message
    says why); ``log`` holds ``(CNC cycle, message)`` of everything the demo did, and ``say``
    hands every message to ``printer`` as well (``hli-plc`` prints them).
    """

    name: ClassVar[str]
    document: ClassVar[str]
    summary: ClassVar[str]
    channel: ClassVar[int] = 1
    """The channel (number, 1-based) the operator loads :attr:`nc_program` into."""
    nc_program: ClassVar[str]
    nc_files: ClassVar[dict[str, str]] = {}
    """The subprograms and cycles :attr:`nc_program` calls (``L name``): uploaded with it."""
    watch: tuple[str, ...] = ()

    def __init__(self, printer: Callable[[str], object] | None = None) -> None:
        self.printer = printer
        self.log: list[tuple[int, str]] = []
        self.done = False
        self.failed = False
        self.step = "start"

    def __call__(self, io: IoImage) -> None:
        raise NotImplementedError

    def say(self, io: IoImage, text: str) -> None:
        self.log.append((io.cycle, text))
        if self.printer is not None:
            self.printer(f"[CNC cycle {io.cycle:>6}] {text}")

    def finish(self, io: IoImage, text: str, *, failed: bool = False) -> None:
        self.say(io, text)
        self.done = True
        self.failed = failed

    def messages(self) -> list[str]:
        return [text for _, text in self.log]

    def __repr__(self) -> str:
        return f"{type(self).__name__}(step {self.step!r}, {len(self.log)} messages)"


def _registry() -> dict[str, type[Demo]]:
    from plc_clients.demos.c3_collision import CollisionDemo
    from plc_clients.demos.c14_manual_mode import ManualModeDemo
    from plc_clients.demos.c43_obstacle import ObstacleDemo
    from plc_clients.demos.ve_mode import VeModeDemo

    return {cls.name: cls for cls in (ObstacleDemo, ManualModeDemo, CollisionDemo, VeModeDemo)}


DEMOS: tuple[str, ...] = ("c43-obstacle", "c14-manual", "c3-collision", "ve-mode")
"""The demos' names, in the order of the documents' examples."""


def demo_class(name: str) -> type[Demo]:
    """The demo called ``name`` (KeyError naming the demos that exist)."""
    demos = _registry()
    try:
        return demos[name]
    except KeyError:
        raise KeyError(f"no demo {name!r}; the demos are {', '.join(demos)}") from None
