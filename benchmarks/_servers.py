"""A server under test in a process of its own, for the benchmarks that measure a door from outside."""

from __future__ import annotations

import atexit
import multiprocessing as mp
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

__all__ = ["CTX", "Server", "print_lateness"]

CTX = mp.get_context("fork")
"""Fork: the server process starts in milliseconds with what the benchmark imported already."""


@dataclass
class Server:
    """``target(conn)`` runs the server, sends its port on ``conn``, and on SIGTERM what it reports."""

    name: str
    process: Any
    conn: Connection
    port: int

    @classmethod
    def start(cls, name: str, target: Callable[[Connection], None]) -> Server:
        parent, child = CTX.Pipe()
        # not a daemon: a server may start a process of its own (the doors process of hli-server run);
        # a server left behind by a benchmark that failed is ended on exit instead
        process = CTX.Process(target=target, args=(child,), daemon=False)
        process.start()
        atexit.register(_end, process)
        if not parent.poll(30):
            process.kill()
            raise RuntimeError(f"{name}: the server did not start within 30 s")
        return cls(name, process, parent, parent.recv())

    def stop(self) -> Any:
        """SIGTERM, then what the server reports on its way out (the runtime's timing)."""
        self.process.terminate()
        report = self.conn.recv() if self.conn.poll(15) else None
        self.process.join(15)
        if self.process.is_alive():
            self.process.kill()
        return report


def _end(process: Any) -> None:
    if process.is_alive():
        process.kill()
        process.join(5)


def print_lateness(timing: dict[str, Any] | None) -> None:
    """One line on how the realtime clock fared under the load (the runtime's ``/api/timing``)."""
    if not timing or not timing.get("lateness_us"):
        return
    lateness = timing["lateness_us"]
    print(
        f"engine under the load: {timing['cycles']} cycles in {timing['wall_s']:.1f} s, lateness "
        f"p50 {lateness['p50']:.0f} us, p99 {lateness['p99']:.0f} us, max {lateness['max']:.0f} us, "
        f"{timing['slipped_cycles']} cycles dropped"
    )
