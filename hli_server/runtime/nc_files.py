"""``#MSG SAVE``: the report files an NC program writes, inside one output directory (N-07).

The engine does no I/O: ``#MSG SAVE`` (and the name ``#FILE NAME [MSG="..."]`` gives the report file)
is an :class:`~schemas.events.NcFileWrite` event, which :class:`NcFileWriter` carries out here, as
the kernel does ("Writing messages to a file (#MSG SAVE)",
https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/207171211.html): the text is
appended to the end of the file (a new line unless ``#MSG SAVE CONTINUE``); a file is never emptied,
delete it before the program starts for a new one.

Every file lies inside the server's NC output directory: ``hli-server run --nc-output-dir DIR``, by
default a directory of its own under the system's temporary directory, ``hli_nc_<pid>_<random>`` (the
``run`` banner names it; made at the first write, so a server that writes nothing leaves nothing
behind; kept after the server stops when a program wrote into it). A name may hold
subdirectories below it (``reports/part.txt``, made as needed). Refused, with warning 919010 in the
program's channel and nothing written:

* a name that leaves the directory: absolute (``/etc/x``, ``C:\\x``), ``..``, a symbolic link on the
  way or at the end;
* anything but a regular file (a named pipe, a device, a socket, a directory: issue 36, finding 2), and a
  file with more than one link (a hard link in the directory to a file elsewhere);
* a write that would make the file larger than :data:`MAX_FILE_BYTES`, or a new file beyond
  :data:`MAX_FILES`;
* a write while :data:`MAX_QUEUED` writes wait for the writer (the disk is slower than the program);
* an unknown mode, or a file system error (named in the warning).

Why it never costs the clock more than an append (issue 36, findings 2 and 3): the event listener runs
inside the cycle and only queues the write (bounded); a thread of its own opens, checks and appends,
never blocking on a file (``O_NONBLOCK``, each directory opened below the last with ``O_NOFOLLOW``, the
file checked on its open descriptor). Its refusals come back to the clock's thread, which raises the
warnings there (:meth:`NcFileWriter.after_cycle`): at most :data:`REPORT_BURST` at once, then one a
second (:data:`REPORT_INTERVAL_S`), each naming how many refusals it stands for; the log says the same,
as often. Under the stepped clock the writes are done on the clock's thread after the cycle that asked for
them (no realtime to keep: a test sees the file, or the warning, after the cycle, the same every run); under
the realtime and the free clock the warning comes a cycle or a few later, with the line and block of the
``#MSG SAVE``.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import secrets
import shutil
import stat
import tempfile
import threading
import time
from collections import deque
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Final

from hli_server.runtime.programs import ProgramNameError, check_program_name
from schemas.events import Event, NcFileWrite

if TYPE_CHECKING:
    from hli_server.engine.machine import Machine

__all__ = [
    "FILE_REFUSED_ALARM",
    "MAX_FILES",
    "MAX_FILE_BYTES",
    "MAX_QUEUED",
    "REPORT_BURST",
    "REPORT_INTERVAL_S",
    "NcFileWriter",
]

log = logging.getLogger(__name__)

MAX_FILE_BYTES: Final = 16 * 1024 * 1024
"""Largest report file a program may write (16 MiB)."""
MAX_FILES: Final = 256
"""Most report files a server writes."""
MAX_QUEUED: Final = 16384
"""Writes that may wait for the writer thread; beyond, a write is refused (the program goes on)."""
REPORT_BURST: Final = 10
"""Refusals reported one by one (a warning and a log line each) before the rate applies."""
REPORT_INTERVAL_S: Final = 1.0
"""Past the burst, at most one warning (and log line) this often, saying how many refusals it stands for."""
SETTLE_S: Final = 2.0
"""How long the server's stop waits for the writer thread before it writes what is left itself."""
FILE_REFUSED_ALARM: Final = 919010
_OPEN_AT_ONCE: Final = 32
"""Files the writer keeps open within one batch."""
_MODES: Final = {"line": "\n", "continue": ""}
_CLOEXEC: Final = getattr(os, "O_CLOEXEC", 0)
_NOFOLLOW: Final = getattr(os, "O_NOFOLLOW", 0)
_DIRECTORY: Final = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | _NOFOLLOW | _CLOEXEC
_FILE: Final = (
    os.O_WRONLY
    | os.O_APPEND
    | os.O_CREAT
    | _NOFOLLOW
    | _CLOEXEC
    | getattr(os, "O_NONBLOCK", 0)  # a named pipe without a reader: ENXIO at once, never a wait
    | getattr(os, "O_NOCTTY", 0)
)
_KINDS: Final = (
    (stat.S_ISFIFO, "a named pipe"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a directory"),
)


class _RefusedError(Exception):
    """A write the writer does not carry out; its text is the reason."""


class NcFileWriter:
    """An event listener of the machine that carries out :class:`NcFileWrite` in ``directory``, off the
    clock's thread (see the module docstring)."""

    def __init__(self, machine: Machine, directory: str | os.PathLike[str] | None = None) -> None:
        """``directory`` is made now when given (OSError when it cannot be); the temporary one at the
        first write."""
        self._machine = machine
        self._given = Path(directory) if directory is not None else None
        self._directory: Path | None = None
        self._temporary = directory is None
        self._made = False
        if not self._temporary:  # the user's directory: made now, so that a wrong one fails at the start
            try:
                self._make()
            except OSError as exc:
                raise OSError(
                    f"NC output directory {self._given}: cannot be made ({exc.strerror or exc})"
                ) from None
        self._files: set[PurePosixPath] = set()
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._queue: deque[NcFileWrite] = deque()
        self._draining = threading.Lock()
        self._closing = False
        self._thread: threading.Thread | None = None
        self._reports: deque[tuple[NcFileWrite, str]] = deque()
        """Refusals to raise as warnings on the clock's thread (the rate limit already applied)."""
        self._tokens = float(REPORT_BURST)
        self._refilled = time.monotonic()
        self._unreported = 0
        self.written = 0
        """Writes carried out."""
        self.refused = 0
        """Writes refused (each counted; reported as warning 919010 within the rate limit)."""

    @property
    def directory(self) -> Path:
        """The output directory: the given one, or ``hli_nc_<pid>_<random>`` in the system's temporary
        directory. Made at the first write (so a server that writes nothing leaves nothing behind)."""
        if self._directory is None:
            if self._given is None:
                name = f"hli_nc_{os.getpid()}_{secrets.token_hex(4)}"
                self._directory = Path(tempfile.gettempdir()).resolve() / name
            else:
                self._directory = self._given.resolve()
        return self._directory

    def _make(self) -> None:
        if self._made:
            return
        if self._temporary:
            self.directory.mkdir(mode=0o700)  # a new name: never a directory someone else made
        else:
            self.directory.mkdir(parents=True, exist_ok=True)
        self._made = True

    def rebind(self, machine: Machine) -> None:
        """Serve ``machine`` from now on (the runtime restarted its machine): the same directory, the
        files written so far stay and count."""
        self._machine = machine

    # --- the clock's thread ------------------------------------------------------------------------
    def __call__(self, event: Event) -> None:
        """The machine's event listener, inside the cycle: queue the write (bounded) and return."""
        if isinstance(event, NcFileWrite):
            self.write(event)

    def write(self, event: NcFileWrite) -> None:
        """Queue ``event`` for the writer thread (woken after the cycle: :meth:`after_cycle`); refused at
        once while :data:`MAX_QUEUED` writes wait."""
        if len(self._queue) >= MAX_QUEUED:
            with self._lock:
                self._refuse_locked(
                    event, f"{MAX_QUEUED} writes wait for the disk (the program writes faster than it takes)"
                )
            return
        self._queue.append(event)  # the writer pops from the other end: no lock needed

    @property
    def active(self) -> bool:
        """Writes wait, or refusals wait to be reported (cheap: asked after every cycle)."""
        return bool(self._queue) or bool(self._reports)

    def after_cycle(self, inline: bool) -> None:
        """On the clock's thread after a cycle that left :attr:`active`: the writes are done here with
        ``inline`` (the stepped clock: deterministic, a test sees the file after the cycle), else by the
        writer thread, woken once for all of them; then the refusals' warnings are raised."""
        if self._queue:
            if inline:
                self._drain()
            else:
                self._wake()
        reports = self._reports
        while reports:
            event, message = reports.popleft()
            self._raise(event, message)

    def _wake(self) -> None:
        """Start the writer thread, or wake it (once per cycle, not per write: it then works while the
        clock's thread waits for the next cycle)."""
        with self._lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="hli-nc-files", daemon=True)
                self._thread.start()
            self._changed.notify_all()

    def _raise(self, event: NcFileWrite, message: str) -> None:
        machine = self._machine
        channel = None
        if event.channel is not None:
            try:
                channel = machine.channel(event.channel)
            except KeyError:
                channel = None
        machine.raise_alarm(FILE_REFUSED_ALARM, channel, message, line=event.line, block=event.block)

    # --- the writer ---------------------------------------------------------------------------------
    def _run(self) -> None:
        """The writer thread: drain the queue whenever woken, until :meth:`close`."""
        while True:
            with self._lock:
                self._changed.wait_for(lambda: bool(self._queue) or self._closing)
                if self._closing and not self._queue:
                    return
            self._drain()

    def _drain(self) -> None:
        """Write what is queued until nothing is (one drainer at a time); the files stay open for that
        batch only (a burst of writes opens each file once; a file replaced between bursts is opened anew)."""
        with self._draining:
            opened: dict[str, int] = {}
            queue = self._queue
            try:
                while queue:
                    self._write(queue.popleft(), opened)
            finally:
                for fd in opened.values():
                    os.close(fd)

    def _write(self, event: NcFileWrite, opened: dict[str, int]) -> None:
        """Append one write (refusals counted and reported, never raised)."""
        try:
            ending = _MODES.get(event.mode)
            if ending is None:
                raise _RefusedError(f"unknown mode {event.mode!r} (line or continue)")
            data = (event.text + ending).encode("utf-8")
            fd = opened.get(event.file)
            if fd is None:
                if len(opened) >= _OPEN_AT_ONCE:
                    for other in opened.values():
                        os.close(other)
                    opened.clear()
                fd = opened[event.file] = self._open(event.file)
            info = os.fstat(fd)  # a link made, or another writer, since it was opened
            if info.st_nlink != 1:
                raise _RefusedError(
                    f"{event.file!r} has {info.st_nlink} links (a hard link to a file elsewhere?); report "
                    "files have one"
                )
            if info.st_size + len(data) > MAX_FILE_BYTES:
                raise _RefusedError(f"{event.file!r} would grow beyond {MAX_FILE_BYTES} bytes")
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
        except (_RefusedError, ProgramNameError, OSError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            with self._lock:
                self._refuse_locked(event, reason)
        except Exception as exc:  # a bug here must not end the writer: the write is refused, logged
            log.exception("#MSG SAVE into %r failed", event.file)
            with self._lock:
                self._refuse_locked(event, f"internal error {exc!r}")
        else:
            self.written += 1

    def _open(self, name: str) -> int:
        """The file ``name`` below the directory, opened to append: each directory opened below the last,
        never following a link (nothing leaves the directory, whatever is renamed meanwhile), never waiting
        (a named pipe without a reader fails at once); then refused unless a regular file of one link."""
        relative = check_program_name(name)
        if relative not in self._files and len(self._files) >= MAX_FILES:
            raise _RefusedError(f"this server has written {MAX_FILES} report files, the most it writes")
        self._make()
        here = os.open(self.directory, _DIRECTORY)
        try:
            for part in relative.parts[:-1]:
                with contextlib.suppress(FileExistsError):
                    os.mkdir(part, 0o755, dir_fd=here)
                try:
                    below = os.open(part, _DIRECTORY, dir_fd=here)
                except OSError as exc:
                    raise _RefusedError(_not_followed(name, part, exc, "directory")) from None
                os.close(here)
                here = below
            try:
                fd = os.open(relative.name, _FILE, 0o644, dir_fd=here)
            except OSError as exc:
                raise _RefusedError(_not_followed(name, relative.name, exc, "file")) from None
        finally:
            os.close(here)
        try:
            mode = os.fstat(fd).st_mode
            for test, kind in _KINDS:
                if test(mode):
                    raise _RefusedError(f"{name!r} is {kind}, not a regular file")
            if not stat.S_ISREG(mode):
                raise _RefusedError(f"{name!r} is not a regular file")
        except BaseException:
            os.close(fd)
            raise
        self._files.add(relative)
        return fd

    # --- refusals: counted always, reported within the rate ------------------------------------------
    def _refuse_locked(self, event: NcFileWrite, reason: str) -> None:
        """Count the refusal; queue its warning if the rate allows, else count it for the next one
        (either thread, with the lock held)."""
        self.refused += 1
        now = time.monotonic()
        self._tokens = min(float(REPORT_BURST), self._tokens + (now - self._refilled) / REPORT_INTERVAL_S)
        self._refilled = now
        if self._tokens < 1.0:
            self._unreported += 1
            return
        self._tokens -= 1.0
        where = f"NC output directory {self.directory}"
        message = f"#MSG SAVE into {event.file!r} not written: {reason} ({where})"
        if self._unreported:
            message += f"; {self._unreported} more writes were refused since the last warning"
            self._unreported = 0
        log.warning("%s", message)
        self._reports.append((event, message))

    def close(self) -> None:
        """At the server's stop: the writes still queued are done, the writer thread ends; a temporary
        directory nothing was written to is removed."""
        with self._lock:
            self._closing = True
            self._changed.notify_all()
            thread = self._thread
        if thread is not None:
            thread.join(SETTLE_S)
        self._drain()
        if self._unreported:
            log.warning(
                "#MSG SAVE: %d more writes were refused since the last warning (%d refused in all)",
                self._unreported,
                self.refused,
            )
            self._unreported = 0
        if self._temporary and self._made and not any(self.directory.iterdir()):
            shutil.rmtree(self.directory, ignore_errors=True)


def _not_followed(name: str, part: str, exc: OSError, what: str) -> str:
    """Why ``part`` of ``name`` could not be opened: a link (``O_NOFOLLOW``), a pipe nobody reads, ..."""
    if exc.errno == errno.ELOOP or (exc.errno == errno.ENOTDIR and what == "directory"):
        return (
            f"{name!r}: {part} is a symbolic link or not a directory; report files are written only as plain "
            "files below the NC output directory"
        )
    if exc.errno == errno.ENXIO:
        return f"{name!r}: {part} is a named pipe or a socket, not a regular file"
    return f"{name!r}: {exc.strerror or exc}"
