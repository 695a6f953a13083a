"""Built-in stand-ins for ISG's cycle packages: TF5225 measuring (touch probe) and TF5293 drilling/milling.

A cycle call ``L CYCLE [NAME=SysMeasWcs27.ecy @P2=..]`` runs the user's own file where one is found (the
program directories, then the channel's ``cycle_directories``, as the kernel's path list). Where none is,
the interpreter asks :func:`find` and runs the stand-in: it checks the @P parameters as the cycle's page
documents them (:mod:`.params`, the kernel's error IDs), moves as the page's pictures describe and writes the
``V.CYC.SysRet*`` results; a documented cycle without a stand-in is refused naming it (910110).

Why Python and not NC files shipped with the package (docs/cycles.md, "How the stand-ins are written"):

* validation: each parameter's rule and the kernel's ID for it are one table row (:class:`~.params.Param`),
  which also writes docs/cycles.md; NC files would need ``#ERROR`` and a copy of every rule in NC;
* the probe's result flows back: a measuring move is a ``G100`` block that carries where the simulated
  workpiece is touched (``Block.probe_touch``); the generator reads the latched position after the move
  (decoding waits for a measuring move to end), so a PLC probe signal, an area or a soft limit that stops
  the move change the result as on the machine;
* oracles: the geometry (circle fits, pattern positions, pocket rings) is plain functions
  (:mod:`.geometry`) the tests call too; a test runs a stand-in without a machine through a fake context;
* the moves are NC text read by the normal block parser, so the decoder, every path check (software limits,
  work and protection areas, collision monitoring) and the planner see them like programmed blocks.

The package is pure engine code: no I/O; what it needs of the channel is the :class:`CycleContext`
protocol, which the channel implements.
"""

from hli_server.engine.cycles.base import Cycle, Output, StandIn
from hli_server.engine.cycles.catalog import BUILT, NOT_BUILT, NotBuilt, find, run
from hli_server.engine.cycles.context import CycleContext, MotionState
from hli_server.engine.cycles.errors import A_APPROXIMATED, A_COLLISION, A_INVALID, A_NO_WORKPIECE, CycleError
from hli_server.engine.cycles.params import Param, ParamValue
from hli_server.engine.cycles.probe import ProbeDeviation

__all__ = [
    "A_APPROXIMATED",
    "A_COLLISION",
    "A_INVALID",
    "A_NO_WORKPIECE",
    "BUILT",
    "NOT_BUILT",
    "Cycle",
    "CycleContext",
    "CycleError",
    "MotionState",
    "NotBuilt",
    "Output",
    "Param",
    "ParamValue",
    "ProbeDeviation",
    "StandIn",
    "find",
    "run",
]
