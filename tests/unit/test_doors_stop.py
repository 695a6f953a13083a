"""The doors process serves until it is told to stop (``runtime/doors.py`` ``_until_stopped``): the parent's
word and the end of its pipe wake it through the loop, with no thread polling the pipe."""

from __future__ import annotations

import asyncio
import multiprocessing
import threading

import pytest

from hli_server.runtime import doors


def _run(gone: list[bool], act: str) -> tuple[bool, int]:
    """Run ``_until_stopped`` on a fresh pipe, do ``act`` from the loop once it waits; whether it returned
    and how many threads the process had while it waited."""
    parent, child = multiprocessing.Pipe()
    threads: list[int] = []

    async def main() -> bool:
        terminated = asyncio.Event()
        task = asyncio.create_task(doors._until_stopped(child, terminated, lambda: gone[0]))
        await asyncio.sleep(0.05)
        threads.append(threading.active_count())
        assert not task.done()  # nothing said yet: it serves on
        if act == "stop":
            parent.send(("stop", None))
        elif act == "close":
            parent.close()  # what the parent's death does to its end
        elif act == "sigterm":
            terminated.set()
        elif act == "gone":
            gone[0] = True
        await asyncio.wait_for(task, doors.WATCH_S * 3)
        return task.done()

    try:
        return asyncio.run(main()), threads[0]
    finally:
        child.close()
        if act != "close":
            parent.close()


@pytest.mark.parametrize("act", ["stop", "close", "sigterm", "gone"])
def test_the_doors_stop_when_told_and_no_thread_watches_the_pipe(act: str) -> None:
    before = threading.active_count()
    done, threads = _run([False], act)
    assert done
    assert threads == before  # the loop watches the pipe: no executor thread was started for it


def test_a_word_from_the_parent_ends_the_wait_at_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Not at the next look: with a look a minute away, the word still ends it (the pipe's readiness
    wakes the loop)."""
    monkeypatch.setattr(doors, "WATCH_S", 60.0)

    async def main() -> bool:
        parent, child = multiprocessing.Pipe()
        task = asyncio.create_task(doors._until_stopped(child, asyncio.Event(), lambda: False))
        await asyncio.sleep(0.01)
        parent.send(("stop", None))
        try:
            await asyncio.wait_for(task, 10.0)
        finally:
            child.close()
            parent.close()
        return task.done()

    assert asyncio.run(main())
