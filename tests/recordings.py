"""Recordings both levels use (a unit test must not import an integration helper; both import this)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from hli_server.configuration import load_machine
from hli_server.recording.format import read_records
from hli_server.runtime import Runtime


def record_late(path: Path, program: str, lead: int, cycles: int) -> list[dict[str, Any]]:
    """The lines of a recording started ``lead`` cycles into ``program``'s run on the demo machine (a
    stepped runtime) and stopped ``cycles`` later: the input journal, the snapshot line, its own cycles."""

    async def record() -> None:
        async with Runtime(load_machine(None), clock="stepped", http_port=None) as rt:
            rt.operator.load_program(1, program, "late.nc")
            rt.operator.start(1)
            await rt.step(lead)
            rt.session.start(path)
            await rt.step(cycles)
            rt.session.stop()

    asyncio.run(record())
    return list(read_records(path))
