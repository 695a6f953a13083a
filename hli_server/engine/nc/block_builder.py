"""The block builder (E-04): the decoder's :class:`~hli_server.engine.nc.blocks.Block` from a block's
evaluated words, with the word parser's rules - used by the compiler for a block whose expressions are
constant and by the interpreter for every other block of words, each time it runs.
"""

from __future__ import annotations

import math

from hli_server.engine.nc import parser as word_parser
from hli_server.engine.nc.blocks import Block
from hli_server.engine.nc.language import (
    A_BAD_N,
    A_BAD_NUMBER,
    A_NOT_SIMULATED,
    A_RANGE,
    A_UNKNOWN_G,
    AXIS_VALUE_G_CODES,
    KNOWN_G,
    MOTION_G_CODES,
    VALUE_G_CODES,
)
from hli_server.engine.nc.statements import Word

__all__ = ["build_block", "with_program"]


def with_program(block: Block, program: str) -> Block:
    """``block`` as a block of subroutine ``program``."""
    return Block(
        block.line,
        block.number,
        block.text,
        block.g_codes,
        block.m_codes,
        block.axes,
        block.centre,
        block.feed,
        block.area,
        block.two_path,
        block.extra,
        program,
    )


def build_block(
    text: str,
    line: int,
    number: int | None,
    words: list[tuple[Word, float, float | None]],
    program: str,
) -> Block:
    """The decoder's :class:`Block` from evaluated words, with the word parser's rules (E-04): known G
    codes, one G per group, a word once per block, the ranges of positions, feeds, centres and S/T/D/H
    (alarms 910101..910111); the motion functions not simulated refused by name (910110)."""
    g_codes: list[int] = []
    m_codes: list[int] = []
    axes: dict[str, float] = {}
    centre: dict[str, float] = {}
    extra: dict[str, float] = {}
    feed: float | None = None
    weights = False
    for w, v, _ in words:
        if w.letter == "G" and v == int(v) and int(v) in AXIS_VALUE_G_CODES:
            weights = True
            break
    for word, value, more in words:
        letter = word.letter
        if letter == "AXIS":
            name = word.name
            if weights:
                extra[f"W:{name}"] = value
                continue
            if name in axes:
                word_parser._twice(
                    f"axis {name}",
                    name if len(name) == 1 else name + "=",
                    axes[name],
                    _shown(value),
                    line,
                    number,
                )
            if not -word_parser._POSITION_MAX <= value <= word_parser._POSITION_MAX:
                word_parser._fail(
                    A_RANGE, line, number, f"{word.text} is out of range: {word_parser._POSITION_RANGE}"
                )
            axes[name] = value
        elif letter == "G":
            if value != int(value) or value < 0:
                word_parser._fail(
                    A_BAD_NUMBER, line, number, f"{word.text}: a G code takes a whole number (G1, G01)"
                )
            g = int(value)
            if g in MOTION_G_CODES:
                word_parser._fail(
                    A_NOT_SIMULATED,
                    line,
                    number,
                    f"G{g}: {MOTION_G_CODES[g]} is not simulated (N-08): see docs/nc-language.md",
                )
            if g not in KNOWN_G:
                known = " ".join(f"G{c}" for c in sorted(KNOWN_G))
                word_parser._fail(A_UNKNOWN_G, line, number, f"unknown G code G{g}; supported: {known}")
            if g in VALUE_G_CODES:
                if more is None:
                    word_parser._fail(A_BAD_NUMBER, line, number, f"G{g} takes a value: G{g}=<percent>")
                extra[f"G{g}"] = more
            g_codes.append(g)
        elif letter in {"M", "H"}:
            code = math.floor(value + 0.5) if value >= 0 else -1
            if not 0 <= code <= 999_999_999:
                word_parser._fail(
                    A_BAD_NUMBER,
                    line,
                    number,
                    f"{word.text}: an {letter} function is a whole number 0 .. 999999999, got "
                    f"{_shown(value)}",
                )
            if letter == "M":
                m_codes.append(int(code))
            elif "H" not in extra:
                extra["H"] = float(code)
        elif letter == "N":
            # N<expr> (PM 206817035): "rounded off internally and converted into an integer"
            shown = math.floor(value + 0.5) if math.isfinite(value) else -1
            if not 0 <= shown <= 999_999_999:
                word_parser._fail(
                    A_BAD_N, line, number, f"{word.text} = {_shown(value)}: a block number is 0 .. 999999999"
                )
            number = int(shown)
        elif letter == "F":
            if feed is not None:
                word_parser._twice("feed", "F", feed, _shown(value), line, number)
            if not word_parser._FEED_MIN <= value <= word_parser._FEED_MAX:
                word_parser._fail(
                    A_RANGE, line, number, f"F{_shown(value)} is out of range: {word_parser._FEED_RANGE}"
                )
            feed = value
        elif letter == "R":
            if "R" in extra:
                word_parser._twice("circle radius", "R", extra["R"], _shown(value), line, number)
            if not -word_parser._CENTRE_MAX <= value <= word_parser._CENTRE_MAX:
                word_parser._fail(
                    A_RANGE, line, number, f"R{_shown(value)} is out of range: {word_parser._CENTRE_RANGE}"
                )
            extra["R"] = value
        elif letter in ("I", "J", "K"):
            if letter in centre:
                word_parser._twice(
                    f"circle centre {letter}", letter, centre[letter], _shown(value), line, number
                )
            if not -word_parser._CENTRE_MAX <= value <= word_parser._CENTRE_MAX:
                word_parser._fail(
                    A_RANGE,
                    line,
                    number,
                    f"{letter}{_shown(value)} is out of range: {word_parser._CENTRE_RANGE}",
                )
            centre[letter] = value
        else:  # S, T, D
            if letter in extra:
                word_parser._twice(letter, letter, extra[letter], _shown(value), line, number)
            if not -word_parser._EXTRA_MAX <= value <= word_parser._EXTRA_MAX:
                word_parser._fail(
                    A_RANGE,
                    line,
                    number,
                    f"{letter}{_shown(value)} is out of range: {word_parser._EXTRA_RANGE}",
                )
            extra[letter] = value
    if len(g_codes) > 1:
        g_codes = word_parser._check_g_codes(g_codes, line, number)
    return Block(
        line,
        number,
        text,
        tuple(g_codes),
        tuple(m_codes),
        tuple(axes.items()),
        tuple(centre.items()),
        feed,
        None,
        (),
        extra,
        program,
    )


def _shown(value: float) -> str:
    if math.isfinite(value) and value == int(value) and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.10g}"
