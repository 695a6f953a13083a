"""The report of a condition that never came (:meth:`Harness.run_until`, H-07).

A failing scenario test should say what the machine did, not only that it did not do what was
expected. The harness keeps both halves of the image of the last few cycles (two copies per cycle);
when the condition is still false after ``max_cycles``, this module decodes them into a table: one
row per signal that changed in those cycles (plus the channels' program state and error, and the
signals the test asked to ``show``), one column per cycle, then the active alarms and the PLC task's
faults::

    condition not met within 300 cycles (cycles 1..300):
        hli.run_until(lambda: limit.State == 4, max_cycles=300, plc=task)
    the last 8 cycles: the channels' state and the signals that changed
      cycle                                      293      294      295  ...
      gpCh[0]^bahn_state.program_state_r     running  running  running  ...
      gpAx[0]^ipo_state.cmd_pos_r             291000   292000   293000  ...
    active alarms: none
    PLC task: 300 cycles, 0 input faults, 0 output faults
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from schemas.layout import Direction, Layout, Signal
from schemas.wire import ProgramState

if TYPE_CHECKING:
    from plc_clients.task import PlcTask

__all__ = ["MAX_ROWS", "cycle_report", "format_value", "frames_report"]

MAX_ROWS = 24
"""Rows of changed signals shown; the others are named after the table."""

_P2C, _C2P = Direction.PLC_TO_CNC, Direction.CNC_TO_PLC


def format_value(signal: Signal | None, value: object) -> str:
    if isinstance(value, bool):
        return "TRUE" if value else "FALSE"
    if isinstance(value, float):
        return f"{value:.6g}"
    if signal is not None and signal.st_path.endswith("program_state_r") and isinstance(value, int):
        try:
            return ProgramState(value).name.lower()
        except ValueError:
            return str(value)
    return str(value)


def cycle_report(
    *,
    what: str,
    max_cycles: int,
    first_cycle: int,
    layout: Layout,
    history: Sequence[tuple[int, bytes, bytes]],
    show: Sequence[Signal] = (),
    alarms: Sequence[Mapping[str, Any]] = (),
    plc: PlcTask | None = None,
) -> str:
    """The report (see the module docstring); ``history`` holds ``(cycle, CNC->PLC, PLC->CNC)``."""
    frames = [
        (cycle, {**layout.unpack(_C2P, c2p), **layout.unpack(_P2C, p2c)}) for cycle, c2p, p2c in history
    ]
    return frames_report(
        what=what,
        max_cycles=max_cycles,
        first_cycle=first_cycle,
        layout=layout,
        frames=frames,
        show=show,
        alarms=alarms,
        plc=plc,
    )


def frames_report(
    *,
    what: str,
    max_cycles: int,
    first_cycle: int,
    layout: Layout,
    frames: Sequence[tuple[int, Mapping[str, Any]]],
    show: Sequence[Signal] = (),
    alarms: Sequence[Mapping[str, Any]] = (),
    plc: PlcTask | None = None,
) -> str:
    """The report of :func:`cycle_report` from the signals' values of the last cycles (``(cycle, {ST path:
    value})``; a remote CNC's harness knows only the signals it traced)."""
    last = first_cycle + max_cycles - 1
    lines = [f"condition not met within {max_cycles} cycles (cycles {first_cycle}..{last}):", f"    {what}"]
    if frames:
        lines.append(f"the last {len(frames)} cycles: the channels' state and the signals that changed")
        lines.extend(_table(layout, frames, show))
    if alarms:
        lines.append("active alarms:")
        lines.extend(
            f"  {a.get('id')} ({a.get('severity')}, {_where(a)}): {a.get('message', '')}" for a in alarms
        )
    else:
        lines.append("active alarms: none")
    if plc is not None:
        st = plc.stats
        text = (
            f"PLC task {plc.name!r}: {st.cycles} cycles, {st.input_faults} input faults, "
            f"{st.output_faults} output faults"
        )
        if st.last_fault:
            text += f" (last: {st.last_fault})"
        lines.append(text)
    return "\n".join(lines)


def _where(alarm: Mapping[str, Any]) -> str:
    parts = []
    if alarm.get("channel") is not None:
        parts.append(f"channel {alarm['channel']}")
    if alarm.get("axis"):
        parts.append(f"axis {alarm['axis']}")
    return ", ".join(parts) or "machine"


def _table(
    layout: Layout, history: Sequence[tuple[int, Mapping[str, Any]]], show: Sequence[Signal]
) -> list[str]:
    frames = [values for _cycle, values in history]
    fixed: list[Signal] = []
    for index in range(len(layout.channels)):
        for leaf in ("program_state_r", "error_id_r"):
            path = f"gpCh[{index}]^bahn_state.{leaf}"
            if path in layout and path in frames[0]:
                fixed.append(layout.signal(path))
    rows = list(dict.fromkeys([*fixed, *(s for s in show if s.st_path in frames[0])]))
    changed = [
        s
        for s in layout.signals
        if s not in rows
        and s.st_path in frames[0]
        and not s.st_path.endswith("cycle_r")
        and any(f[s.st_path] != frames[0][s.st_path] for f in frames[1:])
    ]
    hidden = changed[MAX_ROWS:]
    rows += changed[:MAX_ROWS]
    header = ["cycle", *(str(cycle) for cycle, _ in history)]
    body = [[s.st_path, *(format_value(s, f[s.st_path]) for f in frames)] for s in rows]
    widths = [max(len(r[k]) for r in [header, *body]) for k in range(len(header))]
    out = []
    for r in [header, *body]:
        cells = [r[0].ljust(widths[0])] + [c.rjust(w) for c, w in zip(r[1:], widths[1:], strict=True)]
        out.append("  " + "  ".join(cells))
    if len(history) > 1 and not changed:
        out.append("  (no other signal changed in these cycles: the machine stands still)")
    if hidden:
        out.append(f"  ... and {len(hidden)} more that changed: {', '.join(s.st_path for s in hidden)}")
    return out
