"""What the tests need to see of Linux' scheduler: whether it has EEVDF's custom time slices, and a
thread's slice as it shows it (``se.slice`` in ``/proc/.../sched``)."""

from __future__ import annotations

import os
import re


def custom_slices() -> bool:
    """Linux 6.12+ (EEVDF's custom slices), a scheduler that shows a thread's slice in /proc, and the
    server's requests not turned off (``HLI_NO_LOW_LATENCY``)."""
    found = re.match(r"(\d+)\.(\d+)", os.uname().release)
    new_enough = found is not None and (int(found[1]), int(found[2])) >= (6, 12)
    try:
        shows = "se.slice" in read_sched("/proc/thread-self/sched")
    except OSError:
        shows = False
    return new_enough and shows and not os.environ.get("HLI_NO_LOW_LATENCY")


def read_sched(path: str) -> str:
    with open(path) as f:
        return f.read()


def shown_slice(path: str = "/proc/thread-self/sched") -> int:
    """The slice (ns) of the thread or process whose ``sched`` file is ``path``."""
    line = next(li for li in read_sched(path).splitlines() if li.startswith("se.slice"))
    return int(line.split(":")[1])
