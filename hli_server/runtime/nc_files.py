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
* a write that would make the file larger than :data:`MAX_FILE_BYTES`, or a new file beyond
  :data:`MAX_FILES`;
* an unknown mode, or a file system error (named in the warning).

The write happens inside the cycle (an append of one line to a local file, tens of microseconds);
the bounds keep a program that writes in a loop from filling the disk.
"""

from __future__ import annotations

import logging
import os
import secrets
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Final

from hli_server.runtime.programs import ProgramNameError, check_program_name
from schemas.events import Event, NcFileWrite

if TYPE_CHECKING:
    from hli_server.engine.machine import Machine

__all__ = ["FILE_REFUSED_ALARM", "MAX_FILES", "MAX_FILE_BYTES", "NcFileWriter"]

log = logging.getLogger(__name__)

MAX_FILE_BYTES: Final = 16 * 1024 * 1024
"""Largest report file a program may write (16 MiB)."""
MAX_FILES: Final = 256
"""Most report files a server writes."""
FILE_REFUSED_ALARM: Final = 919010
_MODES: Final = {"line": "\n", "continue": ""}
_FLAGS: Final = (
    os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
)


class NcFileWriter:
    """An event listener of the machine that carries out :class:`NcFileWrite` in ``directory``."""

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
        self._sizes: dict[Path, int] = {}
        self.written = 0
        """Writes carried out."""
        self.refused = 0
        """Writes refused (each raised warning 919010)."""

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

    def __call__(self, event: Event) -> None:
        if isinstance(event, NcFileWrite):
            self.write(event)

    def write(self, event: NcFileWrite) -> Path | None:
        """Append ``event.text`` to its file; the path written, or None when refused (warning 919010)."""
        try:
            self._make()
            path = self._path(event.file)
            ending = _MODES.get(event.mode)
            if ending is None:
                raise ProgramNameError(f"unknown mode {event.mode!r} (line or continue)")
            data = (event.text + ending).encode("utf-8")
            size = self._sizes.get(path)
            if size is None:
                if len(self._sizes) >= MAX_FILES:
                    raise ProgramNameError(
                        f"this server has written {MAX_FILES} report files, the most it writes"
                    )
                size = path.stat().st_size if path.exists() else 0
            if size + len(data) > MAX_FILE_BYTES:
                raise ProgramNameError(f"{path.name} would grow beyond {MAX_FILE_BYTES} bytes")
            path.parent.mkdir(parents=True, exist_ok=True)
            self._inside(path.parent.resolve(), event.file)
            fd = os.open(path, _FLAGS, 0o644)
            try:
                os.write(fd, data)
            finally:
                os.close(fd)
        except (ProgramNameError, OSError) as exc:
            self._refuse(event, exc)
            return None
        self._sizes[path] = size + len(data)
        self.written += 1
        return path

    def _path(self, name: str) -> Path:
        relative = check_program_name(name)
        path = self.directory.joinpath(*relative.parts)
        here = self.directory
        for part in relative.parts:  # no symbolic link on the way, nor at the end
            here = here / part
            if here.is_symlink():
                raise ProgramNameError(
                    f"{name!r}: {here} is a symbolic link; report files are written only as plain files"
                )
        self._inside(path.parent.resolve() if path.parent.exists() else self.directory, name)
        return path

    def _inside(self, real_parent: Path, name: str) -> None:
        if not real_parent.is_relative_to(self.directory):
            raise ProgramNameError(f"{name!r} leaves the NC output directory {self.directory}")

    def _refuse(self, event: NcFileWrite, exc: Exception) -> None:
        self.refused += 1
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        message = (
            f"#MSG SAVE into {event.file!r} not written: {reason} (NC output directory {self.directory})"
        )
        log.warning("%s", message)
        machine = self._machine
        channel = None
        if event.channel is not None:
            try:
                channel = machine.channel(event.channel)
            except KeyError:
                channel = None
        machine.raise_alarm(FILE_REFUSED_ALARM, channel, message, line=event.line, block=event.block)

    def close(self) -> None:
        """At the server's stop: a temporary directory nothing was written to is removed."""
        if self._temporary and self._made and not any(self.directory.iterdir()):
            shutil.rmtree(self.directory, ignore_errors=True)
