"""Where a key is in a TOML file: tomllib keeps no positions, the messages need them."""

from __future__ import annotations

import re

from hli_server.configuration.tables import Loc


class _TomlLines:
    """Finds the line of a key or table in a TOML text (tomllib keeps no positions).

    Tracks table headers (``[a.b]``, ``[[a]]`` with their array index) and ``key = value`` lines,
    skipping multi-line strings and multi-line arrays/inline tables. Good enough for messages.
    """

    _KEY_PART = re.compile(r"""\s*(?:"((?:[^"\\]|\\.)*)"|'([^']*)'|([A-Za-z0-9_-]+))\s*(?:\.|$)""")

    def __init__(self, text: str) -> None:
        self.lines: dict[Loc, int] = {}
        arrays: dict[tuple[str, ...], int] = {}
        current: Loc = ()
        open_string: str | None = None
        depth = 0
        for number, raw in enumerate(text.splitlines(), 1):
            if open_string is not None or depth > 0:
                open_string, depth = self._scan(raw, open_string, depth)
                continue
            stripped = raw.strip()
            if not stripped or stripped.startswith("#"):
                continue
            if stripped.startswith("[["):
                names = self._split(stripped[2 : stripped.find("]]")])
                key = tuple(names)
                arrays[key] = arrays.get(key, 0) + 1
                for nested in [k for k in arrays if len(k) > len(key) and k[: len(key)] == key]:
                    del arrays[nested]
                current = (*self._resolve(names[:-1], arrays), names[-1], arrays[key] - 1)
                self.lines.setdefault(current[:-1], number)
                self.lines.setdefault(current, number)
            elif stripped.startswith("["):
                names = self._split(stripped[1 : stripped.find("]")])
                current = self._resolve(names, arrays)
                self.lines.setdefault(current, number)
            else:
                key_text, value = self._split_assignment(stripped)
                if key_text is None:
                    continue
                names = self._split(key_text)
                for n in range(1, len(names) + 1):
                    self.lines.setdefault((*current, *names[:n]), number)
                open_string, depth = self._scan(value, None, 0)

    def line_of(self, loc: Loc) -> int:
        for n in range(len(loc), 0, -1):
            line = self.lines.get(loc[:n])
            if line is not None:
                return line
        return 1

    @staticmethod
    def _resolve(names: list[str], arrays: dict[tuple[str, ...], int]) -> Loc:
        path: list[str | int] = []
        for n, name in enumerate(names):
            path.append(name)
            count = arrays.get(tuple(names[: n + 1]))
            if count:
                path.append(count - 1)
        return tuple(path)

    @classmethod
    def _split(cls, key: str) -> list[str]:
        """``a."b.c".d`` -> ``["a", "b.c", "d"]``."""
        return [next(g for g in m.groups() if g is not None) for m in cls._KEY_PART.finditer(key.strip())]

    @staticmethod
    def _split_assignment(line: str) -> tuple[str | None, str]:
        quote: str | None = None
        for n, char in enumerate(line):
            if quote:
                if char == quote:
                    quote = None
            elif char in "\"'":
                quote = char
            elif char == "=":
                return line[:n], line[n + 1 :]
        return None, ""

    @staticmethod
    def _scan(text: str, open_string: str | None, depth: int) -> tuple[str | None, int]:
        n = 0
        while n < len(text):
            if open_string is not None:
                end = text.find(open_string, n)
                if end < 0:
                    return open_string, depth
                n = end + len(open_string)
                open_string = None
                continue
            char = text[n]
            if char == "#":
                break
            if text.startswith('"""', n) or text.startswith("'''", n):
                open_string = text[n : n + 3]
                n += 3
                continue
            if char in "\"'":
                end = n + 1
                while end < len(text) and text[end] != char:
                    end += 2 if char == '"' and text[end] == "\\" else 1
                n = end + 1
                continue
            if char in "[{":
                depth += 1
            elif char in "]}":
                depth -= 1
            n += 1
        return open_string, max(depth, 0)
