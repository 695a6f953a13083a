"""The compiler (N-01..N-08): a logical block into its statement, once; the interpreter runs it as often as
the program's flow comes by (a loop body is compiled once).

Blocks of constant words only (``N10 G01 X10 Y20 F1000``, nearly every line of a CAM program) take the
word parser of :mod:`hli_server.engine.nc.parser` - the batch geometry check's parser, with its error
messages - and become a ready :class:`~hli_server.engine.nc.blocks.Block` at compile time. Everything
else - expressions, variables, assignments, control statements, calls, ``#`` commands - is read by the
statement parser (``nc/statement_parser.py``), character by character, with the same word rules.

A statement that cannot be compiled is a :class:`~hli_server.engine.nc.statements.Refused` statement
carrying its alarm: the alarm is raised when the program's flow reaches the block, not when the block is
skipped (a false ``$IF`` branch may hold a construct the simulator does not model).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Collection
from typing import Final

from hli_server.engine.nc import parser as word_parser
from hli_server.engine.nc.block_builder import build_block, with_program
from hli_server.engine.nc.blocks import Block, NcError
from hli_server.engine.nc.expr import EvalError
from hli_server.engine.nc.expr_parser import CONSTANT, UPPER, CompileError
from hli_server.engine.nc.language import A_LIMIT, A_UNKNOWN_G
from hli_server.engine.nc.reader import CONTROL_HEAD, RawBlock, leading_number, nc_error
from hli_server.engine.nc.statement_parser import ChannelAxes, StatementParser
from hli_server.engine.nc.statements import (
    ConstBlock,
    Declaration,
    Empty,
    Header,
    Refused,
    Stmt,
    VarBlock,
    Word,
    Words,
)

__all__ = ["Compiler"]

_DWELL: Final = re.compile(r"G0*4(?![0-9.])", re.IGNORECASE)
"""A G04 block: its time may follow G04 directly (``G04 2.5``), which the word parser does not read."""
_SKIP_HEAD: Final = re.compile(r"\s*/\s*([0-9]{0,2})")
_N_LABEL: Final = re.compile(r"\s*N\s*([0-9]{1,9})\s*:", re.ASCII | re.IGNORECASE)
_STRING_LABEL: Final = re.compile(
    r"\s*(?:N\s*([0-9]{1,9})\s*)?\[([^\]\[\"]*)\]\s*:?", re.ASCII | re.IGNORECASE
)
_TO_END: Final = 1 << 62
_CALL_WORD = re.compile(r"(?:^|[\s:])LL?[ \t]", re.IGNORECASE)


class Compiler:
    """Compiles logical blocks for one channel's axes (``axis_names``; ``main_axes`` for ``@X@Y@Z``)."""

    def __init__(self, axis_names: Collection[str], main_axes: tuple[str, str, str]) -> None:
        axes = ChannelAxes(axis_names, main_axes)
        self._axes = axes
        self.axis_names = axes.names
        self.main_axes = main_axes
        self._words = word_parser._LineParser(axes.names)
        self._fast = self._words._words
        letters = "NGMFIJKSTDH" + "".join(sorted(axes.single))
        lower = letters.lower()
        self._plain: Callable[[str], re.Match[str] | None] = re.compile(
            rf"[0-9.+\-\s{letters}{lower}]*", re.ASCII
        ).fullmatch
        self.single_letter_axes = axes.single
        """Axes with a one-letter name written ``X10`` (the batch geometry check's plain lines use the
        same letters)."""

    def plain_block(self, raw: str, line: int, program: str) -> Block | None:
        """The block of a line of constant words (``N10 G01 X10 F1000``, no comment), or None for any
        other line or a line the word parser refuses (the compiler then explains it)."""
        if self._plain(raw) is None or not raw or raw.isspace():
            return None
        try:
            block = self._fast(raw.strip(), raw.translate(UPPER), 0, _TO_END, line, None, True)
        except NcError:
            return None
        return with_program(block, program) if program else block

    # --- entry --------------------------------------------------------------------------------------
    def compile(self, raw: RawBlock, program: str = "") -> Stmt:
        """The statement of ``raw``; ``program`` names the subroutine it belongs to ("" for the main
        program): its blocks carry the name for alarms."""
        code = raw.code
        if not code.strip():
            return Empty(raw, None)
        if raw.var_lines is None and self._plain(code) is not None:
            # the fast path of nearly every CAM line: constant words only (the word parser's own)
            try:
                block = self._fast(raw.text, code.translate(UPPER), 0, _TO_END, raw.first, None, True)
            except NcError as exc:
                if exc.alarm != A_UNKNOWN_G and not _DWELL.search(code):
                    return Refused(raw, leading_number(code), exc)
            else:
                if program:
                    return ConstBlock(raw, with_program(block, program))
                return ConstBlock(raw, block)
        stripped = code.lstrip()
        if stripped.startswith("%"):
            rest = stripped[1:]
            local = rest[:1] in ("L", "l") and rest[1:2] in (" ", "\t")
            name = (rest[2:] if local else rest).strip()
            return Header(raw, local, name.split()[0].upper() if name else "")
        number = leading_number(code)
        try:
            if raw.var_lines is not None:
                return self._var_block(raw, number)
            stmt = self._compile(raw, code)
            if program and isinstance(stmt, ConstBlock):
                stmt.block = with_program(stmt.block, program)
            return stmt
        except NcError as exc:
            return Refused(raw, number, exc)
        except CompileError as compile_error:  # its own name: mypyc types a shared one by the first clause
            return Refused(
                raw, number, nc_error(compile_error.alarm, raw.first, number, compile_error.message)
            )
        except RecursionError:
            return Refused(raw, number, nc_error(A_LIMIT, raw.first, number, "expression nested too deeply"))

    def _compile(self, raw: RawBlock, code: str) -> Stmt:
        skip_level = -1
        head = _SKIP_HEAD.match(code) if "/" in code else None
        if head is not None:
            skip_level = int(head.group(1)) if head.group(1) else 0
            code = code[head.end() :]
        label: str | None = None
        n_label = _N_LABEL.match(code) if ":" in code else None
        if n_label is not None:
            label = f"N{int(n_label.group(1))}"
        elif "[" in code:
            s_label = _STRING_LABEL.match(code)
            if s_label is not None and "=" not in code[s_label.start(2) : s_label.end(2)]:
                after = code[s_label.end() :]
                if not after.strip() or after[:1].isspace() or s_label.group(0).rstrip().endswith(":"):
                    label = "[" + s_label.group(2).strip().upper() + "]"
                    prefix = f"N{s_label.group(1)} " if s_label.group(1) else ""
                    code = prefix + after
        stmt = self._statement(raw, code)
        stmt.label = label
        stmt.skip_level = skip_level
        return stmt

    def _statement(self, raw: RawBlock, code: str) -> Stmt:
        if self._plain(code) is not None or CONTROL_HEAD.match(code) or _two_path(code):
            try:
                block = self._words.parse_code(raw.text, code, raw.first)
            except NcError as exc:
                # a G code the word parser does not know may be one the interpreter takes (G130, G131
                # ...) or refuses by name (MOTION_G_CODES): its own parser decides
                if (exc.alarm != A_UNKNOWN_G and not _DWELL.search(code)) or CONTROL_HEAD.match(code):
                    raise
                return self._parsed(raw, code)
            if block is None:
                return Empty(raw, leading_number(code))
            return ConstBlock(raw, block)
        return self._parsed(raw, code)

    def _parsed(self, raw: RawBlock, code: str) -> Stmt:
        stmt = StatementParser(self._axes, raw, code).parse()
        if (
            isinstance(stmt, Words)
            and stmt.items
            and all(
                isinstance(i, Word)
                and i.letter != "E"  # the interpreter says once that it is approximated
                and i.value.is_constant()
                and (i.extra is None or i.extra.is_constant())
                for i in stmt.items
            )
        ):
            words: list[tuple[Word, float, float | None]] = []
            for item in stmt.items:
                assert isinstance(item, Word)
                try:
                    value = item.value.evaluate(CONSTANT)
                    extra = item.extra.evaluate(CONSTANT) if item.extra is not None else None
                except EvalError:
                    return stmt  # X[1/0]: the interpreter raises it when the block runs, with its place
                if isinstance(value, str) or isinstance(extra, str):
                    return stmt  # the error is the interpreter's, with its message
                words.append((item, value, extra))
            return ConstBlock(raw, build_block(raw.text, raw.first, stmt.number, words, ""))
        return stmt

    # --- #VAR ------------------------------------------------------------------------------------------
    def _var_block(self, raw: RawBlock, number: int | None) -> Stmt:
        declarations: list[Declaration] = []
        assert raw.var_lines is not None
        for line, text in raw.var_lines:
            sub = RawBlock(line, line, text, text, None)
            try:
                declarations.append(StatementParser(self._axes, sub, text).declaration())
            except CompileError as exc:
                raise nc_error(exc.alarm, line, leading_number(text), exc.message) from None
        return VarBlock(raw, number, declarations)


def _two_path(code: str) -> bool:
    """A two-path line (``N50 : G0 X.. : G0 U..``, FCT-C14 2.4) or a lone ``:`` (the word parser's)."""
    if ":" not in code or '"' in code or "[" in code or "=" in code:
        return False
    if _CALL_WORD.search(code) is not None:  # L D:\prog\x.nc: a call whose name holds a ':'
        return False
    return _N_LABEL.match(code) is None or code.count(":") > 1
