"""Program files: the runtime reads them for the engine, which does no I/O itself (N-02).

Two things live here:

* :func:`read_program_file`: a program table entry given by path, read when the PLC or the operator
  selects it;
* :class:`ProgramDirectories` and :class:`RuntimeLibrary`: where the engine finds the global
  subprograms and cycles a program calls (``L name``, ``L CYCLE [NAME=...]``; the engine's
  :class:`~hli_server.engine.programs.ProgramLibrary` protocol). A running server searches, in order,
  the files uploaded with the programs (``POST /api/channels/{n}/program`` with ``files``, the pytest
  plugin's ``hli.load_program(..., files=...)``), then the program directories: those of
  ``hli-server run --program-dir`` (in the order given), then the machine file's
  ``program_directories``.

What a name may be: a file name, or a path below a directory (``cycles/drill.nc``). A name that
leaves its directory (``..``, an absolute path, a drive letter, a symbolic link that points out of it)
is never read: :meth:`ProgramDirectories.find` answers None (the interpreter's alarm names every
directory searched) and logs why. A file larger than :data:`MAX_PROGRAM_BYTES` is refused the same
way. A name matches exactly, else without regard to case (the kernel's program directories are on
Windows), and so does a program table entry's path. Text is UTF-8 (with or without a byte order mark)
or Windows-1252 / Latin-1, read alike (:mod:`hli_server.codecs.nc_text`: an old program with umlauts
in its comments runs).

Files are read when the interpreter asks and kept (by path, size and modification time) until they
change, so a program that calls a cycle a thousand times reads it once.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Final, TextIO

from hli_server.codecs.nc_text import EncodingSniffer, decode_program
from hli_server.configuration.files import find_file
from hli_server.engine.programs import ProgramFile
from schemas.config import MachineConfig

__all__ = [
    "MAX_PROGRAM_BYTES",
    "MAX_UPLOADED_FILES",
    "ProgramDirectories",
    "ProgramNameError",
    "RuntimeLibrary",
    "check_program_name",
    "cycle_libraries",
    "find_file",
    "open_program",
    "read_program_file",
]

log = logging.getLogger(__name__)

MAX_PROGRAM_BYTES = 64 * 1024 * 1024
"""Largest program file the server reads (64 MiB): a table entry, a subprogram, an uploaded file."""
MAX_UPLOADED_FILES: Final = 256
"""Most files uploaded with one program (the main program not counted)."""
MAX_NAME_LENGTH: Final = 255
_CACHE_FILES: Final = 256


class ProgramNameError(ValueError):
    """A program name that is no plain file name below a program directory (says what and why)."""


def read_program_file(path: str | os.PathLike[str]) -> str:
    """A program file, read whole: program table entries given by ``path`` (absolute after loading the
    configuration) when the PLC or the operator selects them, and a program a command or a test names.
    The name matches without regard to case where it does not match exactly (:func:`find_file`); UTF-8
    or Windows-1252 (:func:`~hli_server.codecs.nc_text.decode_program`). OSError on failure."""
    file = find_file(path)
    size = file.stat().st_size
    if size > MAX_PROGRAM_BYTES:
        raise OSError(f"{path}: {size} bytes, more than the {MAX_PROGRAM_BYTES} bytes a program may have")
    return decode_program(file.read_bytes())


def open_program(path: str | os.PathLike[str]) -> TextIO:
    """A program file opened as text to stream (``check --geometry-only`` of millions of lines, memory
    flat): one binary pass finds its encoding (:class:`~hli_server.codecs.nc_text.EncodingSniffer`),
    then it is opened with it, line ends untranslated (``newline=""``, as :class:`ProgramText` reads
    them). OSError on failure."""
    file = find_file(path)
    sniffer = EncodingSniffer()
    with file.open("rb") as raw:
        while chunk := raw.read(1 << 20):
            sniffer.feed(chunk)
    stream = file.open(encoding=sniffer.encoding(), newline="")
    if sniffer.skip:
        stream.read(sniffer.skip)  # a UTF-8 byte order mark before Windows-1252 text: one byte a character
    return stream


def check_program_name(name: str) -> PurePosixPath:
    """``name`` as a relative path that stays below its directory, or :class:`ProgramNameError`.

    Refused: empty or too long names, NUL and other control characters, absolute paths (``/x``,
    ``\\x``, ``C:x``), ``..`` anywhere. ``\\`` separates like ``/`` (programs written on Windows)."""
    if not name or len(name) > MAX_NAME_LENGTH:
        raise ProgramNameError(f"program name {name[:40]!r}: 1 to {MAX_NAME_LENGTH} characters")
    if any(ord(c) < 32 or c == "\x7f" for c in name):
        raise ProgramNameError(f"program name {name!r} holds a control character")
    windows = PureWindowsPath(name)
    if windows.drive or windows.root or name.startswith(("/", "\\")):
        raise ProgramNameError(f"program name {name!r} is absolute: name a file below a program directory")
    parts = PurePosixPath(name.replace("\\", "/")).parts
    if any(part == ".." for part in parts):
        raise ProgramNameError(f"program name {name!r} leaves its directory ('..')")
    clean = [part for part in parts if part != "."]
    if not clean:
        raise ProgramNameError(f"program name {name!r} names no file")
    return PurePosixPath(*clean)


class ProgramDirectories:
    """Finds programs by name in directories, in order (the kernel's program paths)."""

    def __init__(
        self, directories: Iterable[str | os.PathLike[str]], *, max_bytes: int = MAX_PROGRAM_BYTES
    ) -> None:
        # each directory once, in the order first given (the program's own may be given again)
        self.directories: tuple[Path, ...] = tuple(dict.fromkeys(Path(d).resolve() for d in directories))
        self.max_bytes = max_bytes
        self._cache: dict[Path, tuple[int, int, str]] = {}

    def searched(self) -> tuple[str, ...]:
        return tuple(str(d) for d in self.directories)

    def find(self, name: str) -> ProgramFile | None:
        try:
            relative = check_program_name(name)
        except ProgramNameError as exc:
            log.warning("%s; not searched", exc)
            return None
        for directory in self.directories:
            path = self._match(directory, relative)
            if path is None:
                continue
            text = self._read(directory, path, name)
            if text is not None:
                return ProgramFile(name, text, str(path))
        return None

    @staticmethod
    def _match(directory: Path, relative: PurePosixPath) -> Path | None:
        """The file of ``relative`` in ``directory``: exact, else each part without regard to case."""
        found = find_file(directory.joinpath(*relative.parts))
        return found if found.is_file() else None

    def _read(self, directory: Path, path: Path, name: str) -> str | None:
        try:
            real = path.resolve(strict=True)
        except OSError:
            return None
        if not real.is_relative_to(directory):
            log.warning(
                "program %r: %s points outside the program directory %s; not read", name, path, directory
            )
            return None
        try:
            stat = real.stat()
            if stat.st_size > self.max_bytes:
                log.warning(
                    "program %r: %s has %d bytes, more than the %d a program may have; not read",
                    name,
                    real,
                    stat.st_size,
                    self.max_bytes,
                )
                return None
            cached = self._cache.get(real)
            if cached is not None and cached[:2] == (stat.st_size, stat.st_mtime_ns):
                return cached[2]
            with real.open("rb") as file:
                data = file.read(self.max_bytes + 1)
        except OSError as exc:
            log.warning("program %r: cannot read %s: %s", name, real, exc.strerror or exc)
            return None
        if len(data) > self.max_bytes:  # grew since the stat
            return None
        try:
            text = decode_program(data)
        except UnicodeDecodeError as exc:  # a UTF-16 file cut short
            log.warning("program %r: %s cannot be read as text: %s", name, real, exc)
            return None
        if len(self._cache) >= _CACHE_FILES:
            self._cache.clear()
        self._cache[real] = (stat.st_size, stat.st_mtime_ns, text)
        return text


class RuntimeLibrary:
    """The server's :class:`~hli_server.engine.programs.ProgramLibrary`: the files uploaded with each
    channel's program, newest upload first, then the program directories."""

    def __init__(self, directories: Sequence[str | os.PathLike[str]] = ()) -> None:
        self.directories = ProgramDirectories(directories)
        self._uploads: dict[int, dict[str, str]] = {}
        """channel -> file name -> text (the files of the channel's last upload)"""
        self._order: list[int] = []
        """channels, the newest upload last"""

    def clear_uploads(self) -> None:
        """Forget every channel's uploaded files (the machine was restarted)."""
        self._uploads.clear()
        self._order.clear()

    def set_uploads(self, channel: int, files: Mapping[str, str]) -> None:
        """The files uploaded with channel ``channel``'s program; they replace its previous ones.
        Every name is checked (:class:`ProgramNameError`), at most :data:`MAX_UPLOADED_FILES`, each
        at most :data:`MAX_PROGRAM_BYTES` bytes (ValueError saying which)."""
        checked = self.check_uploads(files)
        self._uploads[channel] = checked
        if channel in self._order:
            self._order.remove(channel)
        self._order.append(channel)

    @staticmethod
    def check_uploads(files: Mapping[str, str]) -> dict[str, str]:
        """The files as :meth:`set_uploads` keeps them (names normalised), or ValueError; changes nothing."""
        if len(files) > MAX_UPLOADED_FILES:
            raise ValueError(f"{len(files)} files: at most {MAX_UPLOADED_FILES} may come with one program")
        checked: dict[str, str] = {}
        for name, text in files.items():
            key = str(check_program_name(name))
            if len(text.encode("utf-8")) > MAX_PROGRAM_BYTES:
                raise ValueError(f"file {name!r}: more than the {MAX_PROGRAM_BYTES} bytes a program may have")
            if key.casefold() in {k.casefold() for k in checked}:
                raise ValueError(f"file {name!r} is given twice (names are compared without regard to case)")
            checked[key] = text
        return checked

    def uploads(self, channel: int) -> dict[str, str]:
        return dict(self._uploads.get(channel, {}))

    def find(self, name: str) -> ProgramFile | None:
        if self._uploads:
            try:
                key = str(check_program_name(name))
            except ProgramNameError:
                key = ""
            if key:
                for channel in reversed(self._order):
                    files = self._uploads[channel]
                    text = files.get(key)
                    found = key
                    if text is None:
                        found = next((k for k in files if k.casefold() == key.casefold()), "")
                        text = files.get(found)
                    if text is not None:
                        return ProgramFile(name, text, f"upload:{found}")
        return self.directories.find(name)

    def searched(self) -> tuple[str, ...]:
        uploaded = ("uploaded files",) if any(self._uploads.values()) else ()
        return uploaded + self.directories.searched()


def cycle_libraries(config: MachineConfig) -> dict[int, ProgramDirectories]:
    """Per channel, its ``cycle_directories`` (the machine file's, resolved by the loader): where a cycle
    call looks after the program directories, before a built-in stand-in (docs/cycles.md)."""
    return {ch.number: ProgramDirectories(ch.cycle_directories) for ch in config.channels}
