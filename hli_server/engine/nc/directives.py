"""What the interpreter hands the decoder besides blocks (:class:`Directive`), and what it asks of its
channel (:class:`Host`; the engine does no I/O).

* :data:`PAUSE` - this cycle's budget is spent: go on next cycle;
* :class:`SyncAction` - something to do when the path gets there (a ``#MSG SYN``, a synchronous ``V.E.``
  write);
* :class:`FlushStop` (``#FLUSH``: the path stops there), :class:`FlushWait` (``#FLUSH WAIT``, or a read of
  a synchronous variable: decoding waits until the path got there);
* :class:`MeasMode`, :class:`Slope`, :class:`CoordinateCommand`, :class:`ToolWrite`,
  :class:`ContourDirective`: settings the decoder takes in program order.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Final, Protocol

from hli_server.engine.external import ExternalVariables
from hli_server.engine.nc.blocks import Block
from hli_server.engine.nc.statements import Stmt
from hli_server.engine.programs import ProgramFile

__all__ = [
    "PAUSE",
    "ChannelInit",
    "ContourDirective",
    "CoordinateCommand",
    "Directive",
    "FlushStop",
    "FlushWait",
    "Host",
    "IterationCapError",
    "MeasMode",
    "Realtime",
    "Slope",
    "SyncAction",
    "ToolWrite",
    "VectorLimit",
]


class Directive:
    """An output that is not a block (see the module's description)."""

    def __init__(self, block: Block | None) -> None:
        self.block = block
        """Where in the program (line, N) it was programmed."""


PAUSE: Final = Directive(None)
"""This cycle's budget is spent; ask again next cycle."""


class SyncAction(Directive):
    """``action`` runs when the path passes this point (it does not stop the path)."""

    def __init__(self, block: Block, action: Callable[[], None]) -> None:
        super().__init__(block)
        self.action = action


class FlushStop(Directive):
    """``#FLUSH``: the path comes to rest here; decoding goes on."""


class FlushWait(Directive):
    """``#FLUSH WAIT`` (or a synchronous read): decoding waits until the path is at rest here."""


class MeasMode(Directive):
    """``#MEAS MODE``: the measuring type of the G100 blocks after it (None: the channel's default)."""

    def __init__(self, block: Block, meas_type: int | None) -> None:
        super().__init__(block)
        self.meas_type = meas_type


class Slope(Directive):
    """``#SLOPE [TYPE=..]`` / ``#SLOPE DEFAULT``: the acceleration profile from here on (``profile``:
    0 STEP, 1 TRAPEZ, 2 SIN2, 3 HSC as P-CHAN-00071; None: the channel's default, P-CHAN-00071)."""

    def __init__(self, block: Block, profile: int | None) -> None:
        super().__init__(block)
        self.profile = profile


class VectorLimit(Directive):
    """``#VECTOR LIMIT ON|OFF [VEL=..]`` (PM 207477899): the path velocity limit [mm/min] of the motion
    blocks after it (None: no limit, OFF), on feed blocks (``feed``) and rapid blocks (``rapid``)."""

    def __init__(self, block: Block, velocity: float | None, feed: bool, rapid: bool) -> None:
        super().__init__(block)
        self.velocity = velocity
        self.feed = feed
        self.rapid = rapid


class ChannelInit(Directive):
    """``#CHANNEL INIT [CMDPOS|ACTPOS ..]`` (PM 206703627, 206709515): decoding waits until the path is at
    rest here, then takes the axes' positions (``axes``; empty: all the channel's) as its own."""

    def __init__(self, block: Block, actual: bool, axes: tuple[str, ...]) -> None:
        super().__init__(block)
        self.actual = actual
        self.axes = axes


class CoordinateCommand(Directive):
    """``#CS``, ``#ACS``, ``#ROTATION`` (M-10..M-13): the decoder changes its frames in program order.

    ``kind`` CS, ACS or ROTATION; ``op`` DEF, ON, OFF, ADD, SET, DEL; ``ident`` the (A)CS ID where
    programmed; ``name`` a #CS ADD/SET/DEL name; ``values`` the components [v1, v2, v3, φ1, φ2, φ3];
    ``options`` the #ROTATION values by keyword."""

    def __init__(
        self,
        block: Block,
        kind: str,
        op: str,
        ident: int | None = None,
        name: str | None = None,
        values: tuple[float, ...] = (),
        options: dict[str, float] | None = None,
        all_: bool = False,
    ) -> None:
        super().__init__(block)
        self.kind = kind
        self.op = op
        self.ident = ident
        self.name = name
        self.values = values
        self.options = options or {}
        self.all_ = all_


class ToolWrite(Directive):
    """``V.G.WZR = 2`` / ``V.G.WZ_AKT.R``/``.L``: the active tool's radius or length from here on."""

    def __init__(self, block: Block, what: str, value: float) -> None:
        super().__init__(block)
        self.what = what
        self.value = value


class ContourDirective(Directive):
    """``#CONTOUR MODE``, ``#HSC``, ``#SPLINE`` / ``#SET SPLINE`` (M-20..M-23): ``function`` is
    ``"CONTOUR"``, ``"HSC"`` or ``"SPLINE"``; ``on`` True (ON), False (OFF) or None (parameters only);
    ``mode`` the contouring type (``DEV``, ``DIST``, ...), the HSC variant (``OPMODE 1``, ``BSPLINE``) or
    the spline type, None where not programmed; ``values`` the numeric parameters (mm)."""

    def __init__(
        self, block: Block, function: str, on: bool | None, mode: str | None, values: dict[str, float]
    ) -> None:
        super().__init__(block)
        self.function = function
        self.on = on
        self.mode = mode
        self.values = values


class Realtime(Directive):
    """``#RT CYCLE`` (TF5261): ``op`` DEFINE (``body`` the cycle's statements; ``start``: it runs at once, not
    ``DEF``), START, HOLD, CONTINUE, ABORT or DELETE; ``ident`` the cycle's ID (None: the one defined last);
    ``scope`` BLOCK, PROG or GLOBAL. The channel runs it when the path passes this point."""

    def __init__(
        self,
        block: Block,
        op: str,
        ident: int | None,
        scope: str = "PROG",
        body: list[Stmt] | None = None,
        start: bool = True,
    ) -> None:
        super().__init__(block)
        self.op = op
        self.ident = ident
        self.scope = scope
        self.body = body or []
        self.start = start


class IterationCapError(Exception):
    """A geometry check ran more loop iterations than its cap (an endless loop, or a cap too low)."""

    def __init__(self, cap: int, line: int, place: str) -> None:
        super().__init__(f"{place}: more than {cap} loop iterations or jumps back; the check stopped here")
        self.cap = cap
        self.line = line
        self.place = place


class Host(Protocol):
    """What the interpreter needs of its channel (the channel implements it; the engine does no I/O)."""

    @property
    def channel_number(self) -> int: ...

    @property
    def external(self) -> ExternalVariables: ...

    def find_program(self, name: str) -> ProgramFile | None:
        """A global subroutine or cycle by the name the program calls it (``machine.programs``)."""
        ...

    def searched(self) -> tuple[str, ...]:
        """Where :meth:`find_program` looks (for the alarm of a program not found)."""
        ...

    def implicit_program(self, g: int) -> str:
        """The global subprogram the channel's parameters assign to the implicit call ``G<g>``
        (P-CHAN-00160..00169 for G80..G89, P-CHAN-00187 for G800..G839; nc/implicit.py), "" for none."""
        ...

    def message(self, text: str, save: bool, file: str, program: str, line: int, block: str) -> None:
        """``#MSG`` (``save``: ``#MSG SAVE`` into ``file``): the channel emits the events."""
        ...

    def warn(self, alarm: int, message: str, line: int, block: str) -> None:
        """A warning of the table (the program goes on)."""
        ...

    def axis_value(self, variable: str, axis: str) -> float | None:
        """``V.A.<variable>.<axis>`` in mm, or None where the simulator has no such variable."""
        ...

    def global_value(self, name: str) -> float | None:
        """``V.G.<name>``, or None where the simulator has no such variable."""
        ...

    def axis_name(self, index: int) -> str | None:
        """The channel's axis number ``index`` (``V.A.ABS[0]``), or None."""
        ...

    def drive_value(self, axis: str, ident: str) -> float | None:
        """The simulated drive's own value of SERCOS ident ``ident`` (``S-0-0002``) for ``axis``, in the
        ident's unit, or None where the simulated drive has none (``#IDENT RD``)."""
        ...

    def find_cycle(self, name: str) -> ProgramFile | None:
        """A cycle's file (``L CYCLE [NAME=..]``): the program libraries (:meth:`find_program`), then the
        channel's ``cycle_directories`` (CY-01)."""
        ...

    def cycle_searched(self) -> tuple[str, ...]:
        """Where :meth:`find_cycle` looks (for the alarm of a cycle not found)."""
        ...

    def stand_in(
        self,
        name: str,
        params: dict[int, float | str],
        results: Callable[[str, float], None],
        line: int,
        block: str,
    ) -> Iterator[Block] | None:
        """The blocks of the built-in stand-in of documented cycle ``name`` (engine/cycles, docs/cycles.md),
        None for any other name. Its errors - and 910110 for a documented cycle without a stand-in - are
        :class:`~hli_server.engine.nc.blocks.NcError` of the call's ``line`` and ``block``; ``results`` writes
        a ``V.CYC.`` output."""
        ...
