"""Implicit subprogram calls (N-11; PM 206278923 "Implicit subroutine calls (G80-G89/G800..)"): the
interpreter's layer that runs ``G803`` or ``G805[10.0, 9.7, 2.5]`` as a call of the global subprogram
assigned to the G code, as the last action of its block.

Which program a G code calls: the name ``#FILE NAME [G805="..."]`` gave in this program run, else the
channel's parameter (P-CHAN-00160..00169 ``g80_prog_file`` .. ``g89_prog_file`` for G80..G89, P-CHAN-00187
``g800_prog_file[i]`` for G800+i; ``Host.implicit_program``). Neither: the kernel's 20131 "Unknown G
function". The names of ``#FILE NAME`` hold until the program ends; every program start begins with the
channel's parameters again.

A call without values is a global subroutine call (``L name``); values in brackets make it a cycle call:
the subprogram reads them as ``@P1``, ``@P2``, ... (a gap ``, ,`` leaves its ``@P`` unset: ``EXIST[@P2]``
is false). Where the program is found, or 914010, is :class:`~hli_server.engine.nc.levels.ProgramResolver`'s,
as for every call.
"""

from __future__ import annotations

from hli_server.engine.nc.blocks import Block
from hli_server.engine.nc.calls import ProgramLevels
from hli_server.engine.nc.language import A_UNKNOWN_G_FUNCTION
from hli_server.engine.nc.levels import Frame
from hli_server.engine.nc.statements import Call, ImplicitCall, Stmt

__all__ = ["ImplicitCalls", "implicit_parameter"]


def implicit_parameter(g: int) -> str:
    """The channel parameter that assigns G code ``g``'s subprogram (for messages and the docs)."""
    if 80 <= g <= 89:
        return f"P-CHAN-0016{g - 80} g{g}_prog_file"
    return f"P-CHAN-00187 g800_prog_file[{g - 800}]"


class ImplicitCalls(ProgramLevels):
    """Runs the implicit calls G80..G89 and G800..G839 (see the module's description)."""

    def _implicit_call(self, frame: Frame, stmt: Stmt, item: ImplicitCall, place: Block) -> None:
        g = item.g
        name = self._implicit_names.get(g) or self.host.implicit_program(g)
        if not name:
            raise stmt.error(
                A_UNKNOWN_G_FUNCTION,
                f"unknown G function G{g}: no subprogram is assigned to it (the channel parameter "
                f'{implicit_parameter(g)}, or #FILE NAME [G{g}="name"] in the program)',
            )
        self._call(frame, stmt, Call(item.text, False, name, item.bracket, item.params), place)
