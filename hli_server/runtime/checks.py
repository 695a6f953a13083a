"""Checking a program for a running server (``POST /api/check``) and for the test harness (``hli.check``).

The check itself is the engine's :class:`~hli_server.engine.program_check.ProgramCheck`, the same one
``hli-server check`` runs: :func:`run_check` builds a fresh :class:`~hli_server.engine.Machine` of the
server's machine file (its own axes, areas, V.E. variables at their initial values: the running machine
is never touched), finds subprograms among the files sent with the program, then in the server's program
directories (:class:`~hli_server.runtime.programs.RuntimeLibrary`), and runs the program to its end or
its cap.

:class:`ProgramChecker` runs checks for the HTTP door in a worker process of its own (started at the
first check, kept):
a check of millions of cycles computes there, so the realtime clock and the doors never wait for it and
never compete with it for the interpreter's lock. One check runs at a time; a few more wait their turn
(:data:`MAX_WAITING`, beyond that 503). Each has a wall-clock limit besides its caps in cycles and
iterations: past it the worker is ended and the answer says so (504); the next check starts a new one.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import subprocess
import sys
from collections.abc import Mapping, Sequence
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Any, cast

from hli_server.adapters.host import (
    CHECK_MAX_CYCLES,
    CHECK_MAX_ITERATIONS,
    CHECK_MAX_TIMEOUT_S,
    CHECK_TIMEOUT_S,
    CheckTimeoutError,
    InvalidRequestError,
    NotFoundError,
    UnavailableError,
)
from hli_server.runtime.programs import RuntimeLibrary, cycle_libraries
from schemas.results import CheckReport

if TYPE_CHECKING:
    from hli_server.engine.program_check import CheckResult
    from schemas.config import MachineConfig

__all__ = [
    "MAX_TIMEOUT_S",
    "MAX_WAITING",
    "ProgramChecker",
    "check_report",
    "run_check",
]

MAX_TIMEOUT_S = CHECK_MAX_TIMEOUT_S
_START_TIMEOUT_S = 60.0
MAX_WAITING = 4
"""Checks that may wait while one runs; one more is refused (503)."""


def _exit_code(result: CheckResult) -> int:
    """``hli-server check``'s exit code for ``result``: 0 ran to the end, 1 an error alarm stopped it (or it
    did not end), 3 stopped at its cap."""
    if result.stopped_by_error:
        return 1
    if result.capped is not None:
        return 3
    return 0 if result.completed else 1


def check_report(result: CheckResult, program: str) -> CheckReport:
    """The JSON report of ``hli-server check --format json`` with the program's name and the verdict:
    ``status`` is ``ok``, ``stopped`` (an error alarm, or the program did not end) or ``capped`` (at its
    cap, or waiting on inputs nobody changes: ``capped.by``), and
    ``exit_code`` is what ``check`` would exit with."""
    code = _exit_code(result)
    report = {
        "program": program,
        "status": {0: "ok", 1: "stopped", 3: "capped"}[code],
        "exit_code": code,
        "areas": None,  # a machine without areas: the key is there, null
        **result.to_json(),
    }
    return cast(CheckReport, report)


def run_check(
    config: MachineConfig,
    text: str,
    *,
    directories: Sequence[str | os.PathLike[str]] = (),
    files: Mapping[str, str] | None = None,
    name: str = "program",
    channel: int = 1,
    geometry_only: bool = False,
    max_cycles: int = CHECK_MAX_CYCLES,
    max_iterations: int = CHECK_MAX_ITERATIONS,
    record_path: bool = False,
    presets: Mapping[str, bool | int | float | str] | None = None,
) -> CheckResult:
    """Check ``text`` on a fresh machine of ``config`` with the engine's ProgramCheck.

    ``files`` (name -> text) are found by ``L name`` first, then ``directories`` in order; ``presets``
    are V.E. values before the start (``check --set``). :class:`InvalidRequestError` for a bad file name,
    too many files or a preset that cannot be taken, :class:`NotFoundError` for a channel the machine
    does not have."""
    from hli_server.engine import Machine
    from hli_server.engine.presets import PresetError
    from hli_server.engine.program_check import ProgramCheck

    library = RuntimeLibrary(directories)
    try:
        library.set_uploads(0, files or {})
    except ValueError as exc:
        raise InvalidRequestError(str(exc)) from None
    numbers = [c.number for c in config.channels]
    if channel not in numbers:
        raise NotFoundError(f"no channel {channel} (the machine has {', '.join(map(str, numbers))})")
    machine = Machine(config, programs=library, cycle_programs=cycle_libraries(config))
    check = ProgramCheck(
        machine,
        channel,
        geometry_only=geometry_only,
        max_cycles=max_cycles,
        max_iterations=max_iterations,
        record_path=record_path,
        name=name,
        presets=presets,
    )
    try:
        return check.run(text)
    except PresetError as exc:
        raise InvalidRequestError(f"presets: {exc}") from None


# --- the worker process ---------------------------------------------------------------------------
class _Pipes:
    """Two one-way :class:`Connection` ends as one (send on one pipe, receive on the other). What crosses is
    ``Any`` here (a request's dictionary, a ``(kind, payload)`` answer); :meth:`ProgramChecker.check` types it
    (:class:`~schemas.results.CheckReport`)."""

    def __init__(self, inbound: Connection, outbound: Connection) -> None:
        self.inbound, self.outbound = inbound, outbound

    def send(self, obj: Any) -> None:
        self.outbound.send(obj)

    def recv(self) -> Any:
        return self.inbound.recv()

    def poll(self, timeout: float) -> bool:
        return self.inbound.poll(timeout)

    def close(self) -> None:
        self.inbound.close()
        self.outbound.close()


_WORKER_MAIN = (
    "import sys; from hli_server.runtime.checks import worker_main; worker_main(*map(int, sys.argv[1:3]))"
)


def worker_main(inbound_fd: int, outbound_fd: int) -> None:
    """The checker's process: the configuration first, then one request at a time, the report or the
    error back; ends when the server closes its pipe."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(OSError):
        os.nice(5)  # the clock's process first
    conn = _Pipes(Connection(inbound_fd, writable=False), Connection(outbound_fd, readable=False))
    try:
        config, directories = conn.recv()
    except (EOFError, OSError):
        return
    import hli_server.engine.program_check  # noqa: F401  (imported before saying ready: not in a check's time)

    conn.send(("ready", os.getpid()))
    while True:
        try:
            request: dict[str, Any] = conn.recv()
        except (EOFError, OSError):
            return
        try:
            result = run_check(config, directories=directories, **request)
            answer: tuple[str, Any] = ("ok", check_report(result, request.get("name", "program")))
        except (InvalidRequestError, NotFoundError) as exc:
            answer = (type(exc).__name__, str(exc))
        except Exception as exc:  # a bug of ours: the answer says it, the worker serves on
            answer = ("error", f"{type(exc).__name__}: {exc}")
        try:
            conn.send(answer)
        except (OSError, ValueError):
            return


_ERRORS: dict[str, type[Exception]] = {
    "InvalidRequestError": InvalidRequestError,
    "NotFoundError": NotFoundError,
}


class ProgramChecker:
    """Runs :func:`run_check` in a worker process for a server (the ``CheckPort`` of the adapters' host)."""

    def __init__(self, config: MachineConfig, directories: Sequence[str | os.PathLike[str]] = ()) -> None:
        self.config = config
        self.directories = tuple(str(d) for d in directories)
        self._process: subprocess.Popen[bytes] | None = None
        self._conn: _Pipes | None = None
        self._lock = asyncio.Lock()
        self._waiting = 0
        self.checks = 0
        """Checks answered (tests, statistics)."""

    @property
    def worker_pid(self) -> int | None:
        process = self._process
        return process.pid if process is not None and process.poll() is None else None

    def _ensure_worker(self) -> _Pipes:
        if self._process is not None and self._process.poll() is None and self._conn is not None:
            return self._conn
        self._end_worker()
        # a process of its own (not a multiprocessing child: the doors process, itself a daemonic child,
        # may not have those), talking over two pipes with multiprocessing's framing
        from_parent, to_child = os.pipe()  # (read end, write end)
        from_child, to_parent = os.pipe()
        try:
            process = subprocess.Popen(
                [sys.executable, "-c", _WORKER_MAIN, str(from_parent), str(to_parent)],
                pass_fds=(from_parent, to_parent),
                stdin=subprocess.DEVNULL,
                start_new_session=True,  # a Ctrl+C of the terminal reaches the server, which ends it
            )
        except OSError as exc:
            for fd in (to_child, from_parent, from_child, to_parent):
                os.close(fd)
            raise UnavailableError(f"the checker's worker process did not start: {exc}") from None
        os.close(from_parent)
        os.close(to_parent)
        ours = _Pipes(Connection(from_child, writable=False), Connection(to_child, readable=False))
        self._process, self._conn = process, ours
        ours.send((self.config, self.directories))
        # the worker's start (imports) does not count against a check's wall-clock limit
        if not ours.poll(_START_TIMEOUT_S):
            self._end_worker()
            raise UnavailableError(f"the checker's worker process did not start in {_START_TIMEOUT_S:g} s")
        try:
            ours.recv()
        except (EOFError, OSError):
            self._end_worker()
            raise UnavailableError("the checker's worker process ended while it started") from None
        return ours

    def _end_worker(self) -> None:
        process, conn = self._process, self._conn
        self._process = self._conn = None
        if conn is not None:
            conn.close()
        if process is not None:
            if process.poll() is None:
                process.kill()
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(5.0)

    async def check(
        self,
        text: str,
        *,
        name: str = "program",
        files: Mapping[str, str] | None = None,
        channel: int = 1,
        geometry_only: bool = False,
        max_cycles: int = CHECK_MAX_CYCLES,
        max_iterations: int = CHECK_MAX_ITERATIONS,
        timeout_s: float = CHECK_TIMEOUT_S,
        presets: Mapping[str, bool | int | float | str] | None = None,
    ) -> CheckReport:
        """The report of ``text`` (:func:`check_report`). Errors: InvalidRequestError, NotFoundError (the
        request), UnavailableError (too many checks waiting), CheckTimeoutError (the wall-clock limit)."""
        numbers = [c.number for c in self.config.channels]
        if channel not in numbers:
            raise NotFoundError(f"no channel {channel} (the machine has {', '.join(map(str, numbers))})")
        try:
            RuntimeLibrary.check_uploads(files or {})
        except ValueError as exc:
            raise InvalidRequestError(str(exc)) from None
        if self._waiting >= MAX_WAITING + 1:
            raise UnavailableError(
                f"the checker is busy: one check runs and {MAX_WAITING} wait; try again when one has answered"
            )
        request = {
            "text": text,
            "name": name,
            "files": dict(files or {}),
            "channel": channel,
            "geometry_only": geometry_only,
            "max_cycles": max_cycles,
            "max_iterations": max_iterations,
            "presets": dict(presets or {}),
        }
        self._waiting += 1
        try:
            async with self._lock:
                return await self._ask(request, timeout_s)
        finally:
            self._waiting -= 1

    async def _ask(self, request: dict[str, Any], timeout_s: float) -> CheckReport:
        loop = asyncio.get_running_loop()
        conn = await loop.run_in_executor(None, self._ensure_worker)
        await loop.run_in_executor(None, conn.send, request)
        try:
            answered = await loop.run_in_executor(None, conn.poll, timeout_s)
        except (OSError, EOFError):
            answered = False
        if not answered:
            await loop.run_in_executor(None, self._end_worker)
            raise CheckTimeoutError(
                f"the check of {request['name']!r} did not finish in {timeout_s:g} s of wall-clock time and "
                "was ended; lower max_cycles / max_iterations, or raise timeout_s (at most "
                f"{MAX_TIMEOUT_S:g} s), or run `hli-server check` where it may take its time"
            )
        try:
            kind, payload = conn.recv()
        except (OSError, EOFError):
            await loop.run_in_executor(None, self._end_worker)
            raise UnavailableError("the checker's worker process ended during the check") from None
        self.checks += 1
        if kind == "ok":
            report: CheckReport = payload
            return report
        if kind in _ERRORS:
            raise _ERRORS[kind](payload)
        raise UnavailableError(f"the check failed: {payload}")

    async def close(self) -> None:
        """End the worker process (idempotent)."""
        await asyncio.get_running_loop().run_in_executor(None, self._end_worker)
