"""The lines of one NC program text, by number, a window at a time (N-01, flat memory, docs/performance.md).

The interpreter reads a program line by line, and jumps: a loop goes back to its head, ``$GOTO`` goes
to a label before or after, ``LL name`` to a local subroutine anywhere in the file. A text held in
memory allows that trivially; ``check --geometry-only`` streams a file of millions of lines and keeps
its memory flat. :class:`ProgramText` serves both the same way: it reads the text in windows of about
a megabyte of whole lines, keeps a few of them, and remembers where each window began (a position the
stream can seek back to), so any line can be read again without the whole text in memory.

``\\n``, ``\\r\\n`` and a lone ``\\r`` all end a line, as the parser's file iteration with
``newline=""`` splits them. A line longer than :data:`MAX_LINE_CHARS` is refused (an NC block of that
size is not a program, and a bounded line bounds everything downstream).
"""

from __future__ import annotations

import bisect
from typing import TextIO

import numpy as np
import numpy.typing as npt

__all__ = ["CHUNK_CHARS", "MAX_LINE_CHARS", "LineTooLongError", "ProgramText", "Window"]

CHUNK_CHARS = 1 << 20
"""Characters read at a time (about 40,000 lines of a CAM program)."""
MAX_LINE_CHARS = 1 << 16
"""The longest line read (65,536 characters); a longer one is :class:`LineTooLongError`."""
_KEPT_WINDOWS = 4
"""Windows kept in memory: the current one, and a few a loop or a local subroutine may return to."""
_SPLIT_AFTER = 256
"""Lines of a window read one by one before it is split into a list of lines (cheaper from then on)."""
_NEWLINE = ord("\n")

Ints = npt.NDArray[np.int64]


class LineTooLongError(ValueError):
    """A line of more than :data:`MAX_LINE_CHARS` characters (its number in ``line``)."""

    def __init__(self, line: int, length: int) -> None:
        super().__init__(f"line {line} has more than {MAX_LINE_CHARS} characters ({length} or more)")
        self.line = line
        self.length = length


class _StringStream:
    """A string read like a text stream, without copying it (``io.StringIO`` copies the whole text:
    150 ms for a program of 16 MB, in the cycle the program starts)."""

    def __init__(self, text: str) -> None:
        self._text = text
        self._pos = 0

    def read(self, size: int = -1) -> str:
        start = self._pos
        end = len(self._text) if size < 0 else min(start + size, len(self._text))
        self._pos = end
        return self._text[start:end]

    def tell(self) -> int:
        return self._pos

    def seek(self, position: int, whence: int = 0) -> int:
        self._pos = max(0, min(position, len(self._text)))
        return self._pos

    def seekable(self) -> bool:
        return True


class Window:
    """Whole lines ``first .. first + count - 1``: their text (each line ending in ``\\n``), its UTF-8
    bytes and where each line ends in them.

    The batch geometry check hands :attr:`data` and :attr:`ends` to its tokenizer as they are; the
    interpreter reads single lines. A window is split into a list of lines only once it is read line by
    line (more than :data:`_SPLIT_AFTER` lines of it): a CAM program's window, whose plain lines the
    batch reads, is never split (docs/performance.md, "The NC language")."""

    __slots__ = ("_lines", "_reads", "ascii", "count", "data", "ends", "first", "long_lines", "text")

    def __init__(self, first: int, text: str, long_lines: dict[int, int] | None = None) -> None:
        self.first = first
        self.text = text
        """The lines, each ending in ``\\n`` (line ends normalized)."""
        data = text.encode("utf-8", "surrogatepass")
        self.data = data
        self.ascii = len(data) == len(text)
        """Byte offsets are character offsets."""
        ends: Ints = np.flatnonzero(np.frombuffer(data, np.uint8) == _NEWLINE)
        self.ends = ends
        """Offset of each line's ``\\n`` in :attr:`data`."""
        self.count = int(ends.shape[0])
        self.long_lines: dict[int, int] = {} if long_lines is None else long_lines
        """Line number -> length of the lines over the limit (reading one raises LineTooLongError)."""
        if self.count and long_lines is None:
            lengths = np.diff(ends, prepend=-1) - 1
            for k in np.flatnonzero(lengths > MAX_LINE_CHARS).tolist():  # rare: bytes >= characters
                length = len(self._slice(k))
                if length > MAX_LINE_CHARS:
                    self.long_lines[first + k] = length
        self._lines: list[str] | None = None
        self._reads = 0

    def _slice(self, k: int) -> str:
        end = int(self.ends[k])
        start = int(self.ends[k - 1]) + 1 if k else 0
        if self.ascii:
            return self.text[start:end]
        return self.data[start:end].decode("utf-8", "surrogatepass")

    def line(self, k: int) -> str:
        """Line ``first + k`` (``0 <= k < count``) without its line end."""
        lines = self._lines
        if lines is not None:
            return lines[k]
        self._reads += 1
        if self._reads > _SPLIT_AFTER:
            lines = self.text.split("\n")
            lines.pop()  # after the last line end
            self._lines = lines
            return lines[k]
        return self._slice(k)


class ProgramText:
    """Random access to the lines of one program text (a ``str``, or a seekable text stream).

    ``name`` is how alarms and messages name the program. Line numbers start at 1; :meth:`line`
    returns None past the last line. A stream that cannot seek is read whole into memory first."""

    def __init__(self, text: str | TextIO, name: str = "program") -> None:
        self.name = name
        stream: TextIO | _StringStream
        if isinstance(text, str):
            stream = _StringStream(text)
        elif text.seekable():
            stream = text
        else:
            stream = _StringStream(text.read())
        self._stream = stream
        base = stream.tell()
        # per window: (stream position to seek to, characters to skip after it, first line)
        self._starts: list[tuple[int, int, int]] = [(base, 0, 1)]
        self._firsts: list[int] = [1]
        self._windows: dict[int, Window] = {}
        self._order: list[int] = []
        self._last_line: int | None = None
        """The number of the last line, once the end of the text was read."""
        self._current: Window | None = None
        """The window read last (a program is mostly read line after line)."""

    @property
    def last_line(self) -> int | None:
        """The number of lines, once the end of the text has been read (None before)."""
        return self._last_line

    def line(self, number: int) -> str | None:
        """Line ``number`` without its line end, or None past the end of the text."""
        window = self._current
        if window is not None:
            k = number - window.first
            if 0 <= k < window.count and not window.long_lines:
                return window.line(k)
        window = self.window_of(number)
        if window is None:
            return None
        if window.long_lines and number in window.long_lines:
            raise LineTooLongError(number, window.long_lines[number])
        return window.line(number - window.first)

    def window_of(self, number: int) -> Window | None:
        """The window holding line ``number`` (None past the end of the text)."""
        if number < 1:
            return None
        last = self._last_line
        if last is not None and number > last:
            return None
        k = bisect.bisect_right(self._firsts, number) - 1
        while True:
            window = self._load(k)
            if number < window.first + window.count:
                self._current = window
                return window
            if self._last_line is not None and k + 1 >= len(self._starts):
                return None
            k += 1

    # --- reading ---------------------------------------------------------------------------------
    def _load(self, k: int) -> Window:
        cached = self._windows.get(k)
        if cached is not None:
            return cached
        position, skip, first = self._starts[k]
        stream = self._stream
        stream.seek(position)
        if skip:
            stream.read(skip)
        base = stream.tell()
        chunk = CHUNK_CHARS
        data = stream.read(chunk)
        at_end = len(data) < chunk
        cut = len(data)
        has_cr = "\r" in data
        if not at_end and not has_cr:
            # the common case: no "\r" in the piece, so it ends after its last "\n" (no look further)
            cut = data.rfind("\n") + 1
        while not at_end and (has_cr or cut == 0):
            # a line end "\r" may be the first half of "\r\n": look one character further
            more = stream.read(1)
            if not more:
                at_end = True
                cut = len(data)
                break
            probe = data + more
            cut = max(probe.rfind("\n", 0, len(data)), probe.rfind("\r", 0, len(data) - 1)) + 1
            if cut > 0:
                break
            # no line end in the whole piece: a long line; read on (up to a bound)
            data = probe
            if len(data) > 2 * MAX_LINE_CHARS:
                # far over the limit: served as the last line (reading it raises LineTooLongError);
                # nothing after it can run anyway
                window = Window(first, "\n", {first: len(data)})
                if k + 1 == len(self._starts):
                    self._last_line = first
                self._keep(k, window)
                return window
            piece = stream.read(chunk)
            at_end = len(piece) < chunk
            data += piece
            if at_end:
                cut = len(data)
        text = data if cut == len(data) else data[:cut]
        if (has_cr or len(data) > chunk) and "\r" in text:  # data grew over a long line: look again
            text = text.replace("\r\n", "\n").replace("\r", "\n")
        if text and not text.endswith("\n"):
            text += "\n"  # the last line of the text without its line end
        window = Window(first, text)
        lines = window.count
        if k + 1 == len(self._starts):
            if at_end:
                self._last_line = first + lines - 1
            else:
                self._starts.append((base, cut, first + lines))
                self._firsts.append(first + lines)
        self._keep(k, window)
        return window

    def _keep(self, k: int, window: Window) -> None:
        self._windows[k] = window
        self._order.append(k)
        while len(self._order) > _KEPT_WINDOWS:
            old = self._order.pop(0)
            if old != k and old not in self._order:
                self._windows.pop(old, None)
