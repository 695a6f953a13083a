"""Logical blocks (N-01): a program's lines, their comments removed, joined into the blocks the statement
parser reads.

A program is read one *logical block* at a time (:func:`read_block`): a line, with its comments removed,
joined with the lines that continue it (a ``\\`` at the end of a line; a ``#CONTROL AREA ... [`` wrapped
over several lines; ``#VAR ... #ENDVAR``; ``#COMMENT BEGIN ... #COMMENT END``).

Comments (programming manual, "Comments"): ``( ... )`` anywhere, nested, and an unclosed ``(`` runs to
the end of the line; ``;`` to the end of the line; neither inside a string ``"..."``.
"""

from __future__ import annotations

import re
from typing import Final

from hli_server.engine.nc import parser as word_parser
from hli_server.engine.nc.blocks import NcError
from hli_server.engine.nc.language import (
    A_COMMENT_OPEN,
    A_CONTROL_SYNTAX,
    A_DECLARATION,
    A_LIMIT,
    MAX_VAR_LINES,
)
from hli_server.engine.nc.source import MAX_LINE_CHARS, LineTooLongError, ProgramText

__all__ = ["CONTROL_HEAD", "N_HEAD", "RawBlock", "leading_number", "nc_error", "read_block", "strip_comments"]

CONTROL_HEAD: Final = re.compile(r"\s*(?:N\s*[0-9]{1,9}\s*)?#\s*CONTROL\b", re.ASCII | re.IGNORECASE)
_COMMENT_BEGIN: Final = re.compile(r"\s*(?:N\s*[0-9]+\s*)?#\s*COMMENT\s+BEGIN\b", re.ASCII | re.IGNORECASE)
_COMMENT_END: Final = re.compile(r"\s*(?:N\s*[0-9]+\s*)?#\s*COMMENT\s+END\b", re.ASCII | re.IGNORECASE)
_VAR_BEGIN: Final = re.compile(r"\s*(?:N\s*[0-9]+\s*)?#\s*VAR\s*$", re.ASCII | re.IGNORECASE)
_VAR_END: Final = re.compile(r"\s*(?:N\s*[0-9]+\s*)?#\s*ENDVAR\s*$", re.ASCII | re.IGNORECASE)
_NEW_BLOCK: Final = re.compile(r"\s*(?:[/:#]|N\s*[0-9])", re.ASCII | re.IGNORECASE)
N_HEAD: Final = re.compile(r"\s*N\s*([0-9]{1,9})(?![0-9.,=+\-])", re.ASCII | re.IGNORECASE)


# --- comments and logical blocks -----------------------------------------------------------------------
def strip_comments(raw: str) -> str:
    """``raw`` without its comments (each replaced by a blank); strings ``"..."`` are kept as written.

    ``( ... )`` nests; an unclosed ``(`` and a ``;`` run to the end of the line."""
    if "(" not in raw and ";" not in raw:
        return raw
    out: list[str] = []
    i = 0
    n = len(raw)
    start = 0
    while i < n:
        c = raw[i]
        if c == '"':
            close = raw.find('"', i + 1)
            i = n if close < 0 else close + 1
            continue
        if c == ";":
            out.append(raw[start:i])
            return " ".join(out)
        if c == "(":
            out.append(raw[start:i])
            depth = 1
            i += 1
            while i < n and depth:
                d = raw[i]
                if d == "(":
                    depth += 1
                elif d == ")":
                    depth -= 1
                i += 1
            start = i
            continue
        i += 1
    out.append(raw[start:])
    return " ".join(out)


class RawBlock:
    """One logical block: its lines ``first .. last``, its comment-free ``code`` and its ``text`` (the
    lines as written, joined by blanks). ``var_lines`` holds the declarations of a ``#VAR`` block."""

    __slots__ = ("code", "first", "last", "text", "var_lines")

    def __init__(
        self, first: int, last: int, code: str, text: str, var_lines: list[tuple[int, str]] | None
    ) -> None:
        self.first = first
        self.last = last
        self.code = code
        self.text = text
        self.var_lines = var_lines


def nc_error(alarm: int, line: int, number: int | None, message: str) -> NcError:
    return NcError(alarm, line, f"N{number}" if number is not None else f"line {line}", message)


def leading_number(code: str) -> int | None:
    head = N_HEAD.match(code)
    return int(head.group(1)) if head is not None else None


def _line(source: ProgramText, number: int) -> str | None:
    try:
        return source.line(number)
    except LineTooLongError as exc:
        raise nc_error(
            A_LIMIT,
            number,
            None,
            f"line {number} has {exc.length} characters or more: a line has at most {MAX_LINE_CHARS}",
        ) from None


def read_block(source: ProgramText, first: int) -> RawBlock | None:
    """The logical block starting at line ``first`` (None past the end of the text).

    Raises :class:`NcError` for a block that cannot be delimited: a ``\\`` continuation, a wrapped
    ``#CONTROL AREA`` or a ``#VAR`` / ``#COMMENT`` block that runs off the end of the text."""
    raw = _line(source, first)
    if raw is None:
        return None
    code = strip_comments(raw)
    stripped = code.strip()
    if not stripped:
        return RawBlock(first, first, "", raw.strip(), None)
    last = first
    texts = [raw.strip()]
    if stripped.endswith("\\"):
        codes = [stripped[:-1]]
        while True:
            nxt = _line(source, last + 1)
            if nxt is None:
                raise nc_error(
                    A_CONTROL_SYNTAX,
                    first,
                    leading_number(code),
                    "'\\' at the end of the last line: the block continues on no line",
                )
            last += 1
            texts.append(nxt.strip())
            piece = strip_comments(nxt).strip()
            if not piece.endswith("\\"):
                codes.append(piece)
                break
            codes.append(piece[:-1])
        code = " ".join(codes)
        return RawBlock(first, last, code, " ".join(texts), None)
    if "#" in stripped:
        if _COMMENT_BEGIN.match(stripped):
            return _comment_block(source, first, raw)
        if _VAR_BEGIN.match(stripped):
            return _var_block(source, first, raw, code)
        if "[" in stripped and stripped.count("[") > stripped.count("]") and CONTROL_HEAD.match(stripped):
            return _wrapped_control(source, first, raw, code)
    return RawBlock(first, first, code, texts[0], None)


def _comment_block(source: ProgramText, first: int, raw: str) -> RawBlock:
    """``#COMMENT BEGIN`` .. ``#COMMENT END`` (manual "Cross-block comments", 207049867): no code."""
    number = first
    while True:
        number += 1
        nxt = _line(source, number)
        if nxt is None or number - first > MAX_VAR_LINES:
            raise nc_error(A_COMMENT_OPEN, first, leading_number(raw), "#COMMENT BEGIN without #COMMENT END")
        if _COMMENT_END.match(strip_comments(nxt)):
            return RawBlock(first, number, "", raw.strip(), None)


def _var_block(source: ProgramText, first: int, raw: str, code: str) -> RawBlock:
    """``#VAR`` .. ``#ENDVAR``: the declarations with their line numbers (``\\`` continues one)."""
    lines: list[tuple[int, str]] = []
    number = first
    pending: tuple[int, str] | None = None
    while True:
        number += 1
        nxt = _line(source, number)
        if nxt is None or number - first > MAX_VAR_LINES:
            raise nc_error(A_DECLARATION, first, leading_number(code), "#VAR without #ENDVAR")
        piece = strip_comments(nxt).strip()
        if pending is not None:
            joined = pending[1] + " " + piece
            if piece.endswith("\\"):
                pending = (pending[0], joined[:-1])
                continue
            lines.append((pending[0], joined))
            pending = None
            continue
        if _VAR_END.match(piece):
            return RawBlock(first, number, code, raw.strip(), lines)
        if not piece:
            continue
        if piece.endswith("\\"):
            pending = (number, piece[:-1])
            continue
        lines.append((number, piece))


def _wrapped_control(source: ProgramText, first: int, raw: str, code: str) -> RawBlock:
    """A ``#CONTROL AREA ... [`` whose ``]`` is on a later line (FCT-C14 section 2.4 wraps it)."""
    texts = [raw.strip()]
    codes = [code.strip()]
    number = first
    while "]" not in codes[-1]:
        nxt = _line(source, number + 1)
        if nxt is None:
            raise nc_error(
                word_parser._BAD_AREA,
                first,
                leading_number(code),
                "'[' not closed: no ']' before the end of the program; close the option list with ']'",
            )
        piece_code = strip_comments(nxt).strip()
        if not piece_code:
            number += 1
            continue
        if _NEW_BLOCK.match(piece_code) or "[" in piece_code:
            raise nc_error(
                word_parser._BAD_AREA,
                first,
                leading_number(code),
                f"'[' not closed: no ']' before line {number + 1} ({word_parser._short(nxt.strip())!r}); "
                "close the option list with ']'",
            )
        number += 1
        texts.append(nxt.strip())
        codes.append(piece_code)
    return RawBlock(first, number, " ".join(codes), " ".join(texts), None)
