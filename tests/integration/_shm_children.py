"""Code that runs in the second process of the shared-memory tests (spawned, so importable).

It imports ``schemas`` and ``plc_clients`` only, as a real PLC-side process would.
"""

from __future__ import annotations

import time
from typing import Any

from schemas.layout import Direction, SignalType


def uniform_value(sig_type: SignalType, cycle: int) -> Any:
    """The value every field has in cycle ``cycle`` of the torn-read test."""
    if sig_type is SignalType.BOOL:
        return bool(cycle & 1)
    if sig_type is SignalType.LREAL:
        return float(cycle)
    return cycle


def read_everything(name: str, conn: Any, write_values: dict[str, Any] | None = None) -> None:
    """Attach, send every field (by ST path) and both raw halves; then write ``write_values``."""
    from plc_clients.shm import ImageClient

    with ImageClient.attach(name) as client:
        values = {s.st_path: client.read(s.st_path) for s in client.layout.signals}
        conn.send(
            {
                "hash": client.layout.hash,
                "values": values,
                "p2c": client.raw(Direction.PLC_TO_CNC),
                "c2p": client.raw(Direction.CNC_TO_PLC),
                "snapshot": client.snapshot().as_dict(),
                "cycle": client.snapshot().cycle,
            }
        )
        if write_values is not None:
            for st_path, value in write_values.items():
                client.write(st_path, value)
            conn.send("written")
    conn.close()


def torn_reader(name: str, conn: Any, max_snapshots: int, max_seconds: float, min_cycles: int = 100) -> None:
    """Take snapshots while the parent publishes; count any that is not one uniform cycle.

    Reads at least ``max_snapshots`` snapshots covering ``min_cycles`` distinct cycles (on a loaded
    machine that takes longer), or until ``max_seconds`` have passed."""
    from plc_clients.shm import ImageClient

    with ImageClient.attach(name, timeout=5.0) as client:
        layout = client.layout
        half = layout.half(Direction.CNC_TO_PLC)
        conn.send("ready")
        snapshots = torn = 0
        cycles: set[int] = set()
        first_torn: dict[str, Any] | None = None
        deadline = time.monotonic() + max_seconds
        while (snapshots < max_snapshots or len(cycles) < min_cycles) and time.monotonic() < deadline:
            snap = client.snapshot()
            values = layout.struct(Direction.CNC_TO_PLC).unpack(snap.data)
            snapshots += 1
            cycles.add(snap.cycle)
            expected = [uniform_value(s.type, snap.cycle) for s in half]
            if list(values) != expected:
                torn += 1
                if first_torn is None:
                    first_torn = {
                        "cycle": snap.cycle,
                        "wrong": [
                            (s.st_path, v) for s, v, e in zip(half, values, expected, strict=True) if v != e
                        ][:5],
                    }
        conn.send({"snapshots": snapshots, "torn": torn, "cycles": len(cycles), "first_torn": first_torn})
    conn.close()
