"""What a realtime cycle (``#RT CYCLE .. #RT CYCLE END``, TF5261) may hold here: the check of its body when
it is defined (the channel runs it: ``hli_server/engine/realtime.py``; docs/nc-language.md)."""

from __future__ import annotations

from typing import Final

from hli_server.engine.nc.blocks import NcError
from hli_server.engine.nc.expr import ALARM_EXPRESSION, KIND_RTG, KIND_VE, Ref
from hli_server.engine.nc.statements import Assign, Control, Empty, Stmt, Word, Words

__all__ = ["OVERRIDE_CYCLE", "check_body"]

A_NOT_SIMULATED: Final = 910110
OVERRIDE_CYCLE: Final = "OVERRIDE.VEL.CYCLE"
"""``V.RTG.OVERRIDE.VEL.CYCLE``: the path override a realtime cycle writes (TF5261 444700939)."""


def check_body(body: list[Stmt], place: str) -> NcError | None:
    """The error of a statement a realtime cycle cannot hold here (None: every one is simulated)."""
    depth: list[str] = []
    for stmt in body:
        if isinstance(stmt, Empty):
            continue
        if isinstance(stmt, Control):
            keyword = stmt.keyword
            if keyword == "IF" and stmt.goto is None:
                depth.append(stmt.frequency)
                continue
            if keyword in ("ELSEIF", "ELSE") and depth and not depth[-1]:
                continue
            if keyword == "ENDIF" and depth:
                depth.pop()
                continue
            if keyword in ("ELSEIF", "ELSE") and depth:
                return stmt.error(
                    ALARM_EXPRESSION, f"${keyword} after an $IF {depth[-1]}: a qualified $IF has one branch"
                )
            return stmt.error(
                A_NOT_SIMULATED,
                f"${keyword} in a realtime cycle is not simulated (simulated: $IF [ONCE|EDGE|ALWAYS] .. "
                "$ELSEIF .. $ELSE .. $ENDIF): docs/nc-language.md",
            )
        if isinstance(stmt, Words) and stmt.call is None and stmt.goto is None:
            for item in stmt.items:
                if isinstance(item, Word) and item.letter in ("M", "H"):
                    continue
                if isinstance(item, Assign) and _writable(item.target):
                    continue
                shown = item.text
                return stmt.error(
                    A_NOT_SIMULATED,
                    f"{shown} in a realtime cycle is not simulated (simulated: writes of V.E. variables and "
                    "V.RTG.OVERRIDE.VEL.CYCLE, M and H functions; no axis moves in one here): "
                    "docs/nc-language.md",
                )
            continue
        return stmt.error(
            A_NOT_SIMULATED,
            f"{stmt.text.strip()!r} in a realtime cycle is not simulated (motion, calls, jumps and # "
            "commands in a realtime cycle): docs/nc-language.md",
        )
    if depth:
        return NcError(ALARM_EXPRESSION, 0, place, "#RT CYCLE END with an $IF of the cycle still open")
    return None


def _writable(ref: Ref) -> bool:
    return ref.kind == KIND_VE or (ref.kind == KIND_RTG and ref.name == OVERRIDE_CYCLE)
