"""The asyncio loop the servers run on: asyncio's own, with Python 3.13's cheaper turn on 3.11 and 3.12.

Every turn of asyncio's loop works out how long it may wait for I/O: with a timer pending (and a server
always has one: the doors' idle watch, uvicorn's tick, the realtime clock's next cycle) 3.11 and 3.12 do it
with ``min(max(0, when - self.time()), MAXIMUM_SELECT_TIMEOUT)``, two builtin calls that cost as much as
the rest of the turn's bookkeeping. A request/reply door turns the loop once per request: on the 2-core
benchmark host a pending 1 s timer made a canned-reply ADS server 3-7 % slower than the same server with no
timer (``bench_ads``'s floor; docs/performance.md, "Speed, round three, third session"), of which this
computation is a part. Python 3.13 computes the same timeout with two comparisons;
:class:`LeanSelectorEventLoop` is asyncio's ``SelectorEventLoop`` with that turn on the versions before it,
and asyncio's own loop, unchanged, from 3.13 on. Behaviour is asyncio's: the same timers, the same order,
the same clamping to ``MAXIMUM_SELECT_TIMEOUT``.
"""

from __future__ import annotations

import asyncio
import heapq
import selectors
import sys
from asyncio import base_events
from asyncio.log import logger as asyncio_logger
from typing import Any

__all__ = ["LeanSelectorEventLoop", "lean_event_loop"]

_MIN_SCHEDULED = base_events._MIN_SCHEDULED_TIMER_HANDLES  # type: ignore[attr-defined]
_MIN_CANCELLED_FRACTION = base_events._MIN_CANCELLED_TIMER_HANDLES_FRACTION  # type: ignore[attr-defined]
_MAX_TIMEOUT = base_events.MAXIMUM_SELECT_TIMEOUT  # type: ignore[attr-defined]

BACKPORTED = sys.version_info < (3, 13)
"""Whether :class:`LeanSelectorEventLoop` replaces asyncio's turn (3.11, 3.12) or is asyncio's (3.13 on)."""


class LeanSelectorEventLoop(asyncio.SelectorEventLoop):
    """``asyncio.SelectorEventLoop`` whose turn computes the I/O timeout as Python 3.13 does (module
    docstring); on 3.13 and later it is asyncio's loop as it is."""

    if BACKPORTED:

        def _run_once(self) -> None:
            # asyncio.base_events.BaseEventLoop._run_once of CPython 3.13, which differs from 3.11's and
            # 3.12's in the timeout's computation only
            loop: Any = self
            sched_count = len(loop._scheduled)
            if (
                sched_count > _MIN_SCHEDULED
                and loop._timer_cancelled_count / sched_count > _MIN_CANCELLED_FRACTION
            ):
                # remove the cancelled timers when there are many of them
                new_scheduled = []
                for handle in loop._scheduled:
                    if handle._cancelled:
                        handle._scheduled = False
                    else:
                        new_scheduled.append(handle)
                heapq.heapify(new_scheduled)
                loop._scheduled = new_scheduled
                loop._timer_cancelled_count = 0
            else:
                # remove the cancelled timers at the head of the queue
                while loop._scheduled and loop._scheduled[0]._cancelled:
                    loop._timer_cancelled_count -= 1
                    handle = heapq.heappop(loop._scheduled)
                    handle._scheduled = False

            timeout = None
            if loop._ready or loop._stopping:
                timeout = 0
            elif loop._scheduled:
                # compute the desired timeout (3.13: two comparisons instead of min(max(...)))
                timeout = loop._scheduled[0]._when - self.time()
                if timeout > _MAX_TIMEOUT:
                    timeout = _MAX_TIMEOUT
                elif timeout < 0:
                    timeout = 0

            event_list = loop._selector.select(timeout)
            loop._process_events(event_list)
            event_list = None  # break cycles when an exception occurs

            # handle the timers that are due
            end_time = self.time() + loop._clock_resolution
            while loop._scheduled:
                handle = loop._scheduled[0]
                if handle._when >= end_time:
                    break
                handle = heapq.heappop(loop._scheduled)
                handle._scheduled = False
                loop._ready.append(handle)

            # run the callbacks ready now (those they schedule wait for the next turn)
            ntodo = len(loop._ready)
            for _ in range(ntodo):
                handle = loop._ready.popleft()
                if handle._cancelled:
                    continue
                if loop._debug:
                    try:
                        loop._current_handle = handle
                        t0 = self.time()
                        handle._run()
                        dt = self.time() - t0
                        if dt >= self.slow_callback_duration:
                            asyncio_logger.warning(
                                "Executing %s took %.3f seconds",
                                base_events._format_handle(handle),  # type: ignore[attr-defined]
                                dt,
                            )
                    finally:
                        loop._current_handle = None
                else:
                    handle._run()
            handle = None  # break cycles when an exception occurs


def lean_event_loop(selector: selectors.BaseSelector | None = None) -> asyncio.AbstractEventLoop:
    """A :class:`LeanSelectorEventLoop` on ``selector`` (default: the platform's, as asyncio's)."""
    return LeanSelectorEventLoop(selector)
