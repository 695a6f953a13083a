"""NC program parser, syntax only (E-04; C14-02, C14-11..13 and C14-18 for the ``#CONTROL AREA`` commands).

One line of DIN 66025 text becomes one :class:`~hli_server.engine.nc.blocks.Block`, or a numbered
:class:`~hli_server.engine.nc.blocks.NcError` (alarms 910100..910109) that names the line, the block
number and the offending word. Modal meaning (G90/G91, planes, the area definition in progress,
whether an area ID exists, MIN_EXCUR < MAX_EXCUR, ...) is the decoder's business, not the parser's.

Syntax (DIN 66025 as used by the ISG documents FCT-C14 sections 2.4 and 3, and the older
"Arbeits- und Schutzräume definieren" description):

* optional block skip ``/`` and block number ``N<int>`` at the start (``N010`` == ``N10``);
* comments in ``( ... )`` anywhere (not nested; an unclosed ``(`` is alarm 910104) and after ``;``;
* words ``G<int>`` (several), ``M<int>`` (several), ``F``, ``I``/``J``/``K`` (circle centre),
  ``S``/``T``/``D``/``H`` (kept in ``Block.extra``) and axis words in both forms, ``X100``,
  ``X-150``, ``X+.5``, ``X 100`` and ``X2=100``, ``X2 = -100.5`` (a name with digits needs the ``=``;
  ``X2`` alone is axis ``X`` with value 2). Letters are case-insensitive;
* ``#CONTROL AREA BEGIN|START [...]``, ``END``, ``ON``, ``OFF``, ``CLEAR`` (FCT-C14 section 3);
  a BEGIN whose ``]`` is on a later line continues there (:func:`iter_blocks` joins the lines);
* two-path lines ``N050 : G0 X200 Y0 : G0 U150 V0`` (FCT-C14 section 2.4): the first path is the
  block, the further paths go to ``Block.two_path`` for the decoder to refuse (C14-18).

Error messages show the offending word upper-cased (the parser works on the upper-cased code).

Ranges (reliability.md, round 1, finding 1): every number is range-checked where it is read, so that nothing
downstream (geometry, monitors, the DINT fields of the process image) can overflow; a number out of
range is alarm 910111 naming the word and the range. Positions (axis words, MIN_EXCUR, MAX_EXCUR)
must fit a DINT in 0.1 µm (0.0001° rotary): +/-214748.3647; circle centre words I/J/K twice that
(the distance between two such positions); the feed F +/-6e6 mm/min (100 m/s,
``schemas.units.VELOCITY_LIMIT_MM_PER_MIN``); S/T/D/H a DINT; ID 0..999999999, EXCUR_AXNR
1..999999999; G, M and N numbers are whole numbers of at most 9 digits (G must be a known code).

Speed: :func:`iter_blocks` is lazy and meant for multi-million-line programs. A plain motion line
(no comment, ``#``, ``:``, ``/``) costs a ``strip``, an ``upper`` and one ``findall`` over its words,
the N number being read as the first word; everything unusual leaves this fast path, and errors
are explained by a second, slower pass over the bad line only (``benchmarks/bench_parser.py``).
"""

from __future__ import annotations

import dataclasses
import functools
import io
import math
import re
import types
from collections.abc import Callable, Collection, Iterable, Iterator
from typing import NoReturn, Protocol

from hli_server.engine.nc.blocks import (
    AreaBegin,
    AreaClear,
    AreaCommand,
    AreaEnd,
    AreaKind,
    AreaOff,
    AreaOn,
    AreaShape,
    Block,
    NcError,
)
from schemas.units import DINT_MAX, DISTANCE_LIMIT_MM, POSITION_LIMIT_MM, VELOCITY_LIMIT_MM_PER_MIN

__all__ = ["KNOWN_G_CODES", "BlockReader", "iter_blocks", "parse_line", "parse_program"]

# --- alarm numbers (hli_server/engine/alarms.py, group 910xxx) ----------------------------------
_UNKNOWN_WORD = 910100
_BAD_NUMBER = 910101
_UNKNOWN_G = 910102
_TWICE = 910103
_OPEN_COMMENT = 910104
_BAD_AREA = 910105
_G_CONFLICT = 910106
_UNKNOWN_AXIS = 910107
_BAD_N = 910108
_UNKNOWN_HASH = 910109
_OUT_OF_RANGE = 910111

# --- ranges (E-04; reliability.md, round 1, finding 1): the largest magnitude of each word, and why ---
# The hot loop compares each value with two module constants (one chained comparison; it also refuses
# what float() made inf). Old and new parser interleaved in one process, bench_parser's text: no
# measurable cost (new/old 0.99..1.02: the old per-line length test for 300-digit literals is gone).
_POSITION_MAX = POSITION_LIMIT_MM
_POSITION_MIN = -POSITION_LIMIT_MM
_POSITION_RANGE = (
    f"positions must lie within +/-{POSITION_LIMIT_MM:.4f} mm (a DINT in 0.1 µm; rotary axes in 0.0001°)"
)
_CENTRE_MAX = DISTANCE_LIMIT_MM
_CENTRE_RANGE = (
    f"circle centre words I, J, K must lie within +/-{DISTANCE_LIMIT_MM:.4f} mm "
    "(the largest distance between two positions)"
)
_FEED_MAX = VELOCITY_LIMIT_MM_PER_MIN
_FEED_MIN = -VELOCITY_LIMIT_MM_PER_MIN
_FEED_RANGE = f"the feed must lie within +/-{VELOCITY_LIMIT_MM_PER_MIN:.0f} mm/min (100 m/s)"
_EXTRA_MAX = float(DINT_MAX)
_EXTRA_RANGE = f"S, T, D and H must lie within +/-{DINT_MAX} (a DINT)"
_ID_RANGE = (0, 999_999_999)
_AXNR_RANGE = (1, 999_999_999)

KNOWN_G_CODES: frozenset[int] = frozenset(
    (
        0,
        1,
        2,
        3,
        4,
        17,
        18,
        19,
        25,
        26,
        40,
        41,
        42,
        53,
        54,
        55,
        56,
        57,
        58,
        59,
        60,
        74,
        90,
        91,
        92,
        100,
        161,
        162,
        200,
        201,
        202,
    )
)
"""The G codes the parser accepts (E-04); any other is alarm 910102."""

# G codes of one group exclude each other within a block (alarm 910106).
_G_GROUP: dict[int, str] = {
    **dict.fromkeys((0, 1, 2, 3), "motion (G0/G1/G2/G3)"),
    **dict.fromkeys((17, 18, 19), "plane (G17/G18/G19)"),
    **dict.fromkeys((90, 91), "dimensioning (G90/G91)"),
    **dict.fromkeys((161, 162), "circle centre (G161/G162)"),
    **dict.fromkeys((53, 54, 55, 56, 57, 58, 59), "zero offset (G53..G59)"),
    **dict.fromkeys((200, 201, 202), "manual mode (G200/G201/G202)"),
    **dict.fromkeys((70, 71), "units (G70/G71)"),
    **dict.fromkeys((94, 95), "feed (G94/G95)"),
    **dict.fromkeys((900, 901), "deceleration (G900/G901)"),
    **dict.fromkeys((40, 41, 42), "tool radius compensation (G40/G41/G42)"),
    **dict.fromkeys((25, 26), "radius compensation transition (G25/G26)"),
}

# "1", "01", "001" -> 1: the common spellings of the known codes without int() per word.
_G_BY_TEXT: dict[str, int] = {
    f"{g:0{width}d}": g for g in KNOWN_G_CODES for width in range(1, 5) if len(f"{g:0{width}d}") == width
}

_ADDRESS_LETTERS = frozenset("GMFNIJKSTDH")
"""Letters with a fixed meaning; they are never axis names."""
_AXIS_LETTERS = frozenset("ABCUVWXYZ")
"""DIN 66025 axis addresses: an unconfigured one is an unknown axis (910107), not an unknown word."""
_CENTRE_LETTERS = frozenset("IJK")
_EXTRA_LETTERS = frozenset("STDH")

_NUMBER = r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)"

# Start of a block that left the fast path: optional block skip "/", optional "N<digits>", blanks.
# A malformed N ("N10.5", "N10=3", 10+ digits) does not match and is explained by the word loop.
_HEAD = re.compile(r"\s*+(?:/\s*+)?(?:N\s*+([0-9]{1,9}+)(?![0-9.,=+\-]))?\s*+", re.ASCII)
_TO_END = 1 << 62
"""``endpos`` for "to the end of the string" (findall clamps it)."""

# One word: a letter, optionally "<digits>=" (X2=100) or "=", then the value; anything else,
# including a letter without a value, is one bad character (group 4). The "<digits>=" part is
# possessive: "X2 =" without a value must not fall back to "axis X, value 2" and a stray "=".
_WORD = re.compile(rf"\s*(?:([A-Z])(?:([0-9]+)\s*=|=)?+\s*({_NUMBER})|(\S))", re.ASCII)
# The same for a line without "=" (nearly every line): a third faster without the "<digits>=" part.
_WORD_PLAIN = re.compile(rf"\s*+(?:([A-Z])()\s*+({_NUMBER})|(\S))", re.ASCII)
# What an error message shows for a letter without a readable value.
_BAD_WORD = re.compile(r"[A-Z](?:[0-9]*\s*=\s*)?\S*", re.ASCII)

# #CONTROL AREA option lexemes: string, brackets, "=", number, name, or one bad character.
_AREA_LEX = re.compile(
    rf'\s*(?:"([^"]*)"|(\[)|(\])|(=)|({_NUMBER})(?![A-Z0-9_.])|([A-Z_][A-Z0-9_]*)|(\S))',
    re.ASCII,
)
_HASH_NAME = re.compile(r"#([A-Z0-9_]*)", re.ASCII)
_INT = re.compile(r"[-+]?[0-9]{1,9}", re.ASCII)
_ID_GLUED = re.compile(r"ID([0-9]{1,9})", re.ASCII)
# A continuation line of a wrapped "#CONTROL AREA ... [" must not look like the start of a block.
_NEW_BLOCK = re.compile(r"\s*(?:[/:#]|N\s*[0-9])", re.ASCII | re.IGNORECASE)

_AREA_KEYWORDS = ("BEGIN", "START", "END", "ON", "OFF", "CLEAR")
_BEGIN_OPTIONS = (
    "ID",
    "WORK",
    "PROT",
    "POLY",
    "CIRC",
    "MIN_EXCUR",
    "MAX_EXCUR",
    "EXCUR_AX",
    "EXCUR_AXNR",
    "MONITOR_LVL",
)
_SELECT_OPTIONS = ("ID", "ALL")
_FLAG_OPTIONS = frozenset(("WORK", "PROT", "POLY", "CIRC", "ALL"))
_OPTION_WORDS = frozenset((*_BEGIN_OPTIONS, *_SELECT_OPTIONS))
_MONITOR_LEVELS = ("MCS", "IMCS")


class _Fail(Protocol):
    """``fail(message)`` of one #CONTROL AREA command: raises its 910105 error (or ``alarm``)."""

    def __call__(self, message: str, alarm: int = _BAD_AREA) -> NoReturn: ...


# --- errors --------------------------------------------------------------------------------------
def _fail(alarm: int, line: int, number: int | None, message: str) -> NoReturn:
    raise NcError(alarm, line, f"N{number}" if number is not None else f"line {line}", message)


def _short(word: str) -> str:
    """A word as shown in a message: long junk is cut, not echoed in full."""
    return word if len(word) <= 32 else word[:29] + "..."


def _word_at(u: str, start: int, end: int) -> str:
    """The text from ``start`` to the next blank (at most to ``end``): the offending word."""
    stop = start
    while stop < end and not u[stop].isspace():
        stop += 1
    return _short(u[start:stop] or u[start : start + 1])


def _twice(what: str, prefix: str, first: float, again: str, line: int, number: int | None) -> NoReturn:
    _fail(
        _TWICE,
        line,
        number,
        f"{what} programmed twice ({prefix}{first:g} and {prefix}{_short(again)}): once per block",
    )


def _ranged(prefix: str, text: str, limit: float, why: str, line: int, number: int | None) -> float:
    """The value of a rare word (I/J/K, S/T/D/H), range-checked; the hot words inline the same."""
    value = float(text)
    if not -limit <= value <= limit:
        _out_of_range(prefix, text, why, line, number)
    return value


def _leading_number(code: str) -> int | None:
    """The N number of a line that failed before its words were read (for the error's label)."""
    head = _HEAD.match(code.upper())
    digits = head.group(1) if head is not None else None
    return int(digits) if digits is not None else None


def _shown_number(prefix: str, text: str) -> str:
    """A word with a number as a message shows it: as written, or compact (``X1e305``) when long."""
    if len(text) <= 20:
        return prefix + text
    value = float(text)
    if math.isfinite(value):
        return prefix + f"{value:.6g}".replace("e+", "e")
    digits = sum(c.isdigit() for c in text)
    return f"{prefix}{text[:12]}... ({digits} digits)"


def _out_of_range(prefix: str, text: str, why: str, line: int, number: int | None) -> NoReturn:
    """Alarm 910111: ``X1e305 is out of range: positions must lie within ...`` (E-04)."""
    _fail(_OUT_OF_RANGE, line, number, f"{_shown_number(prefix, text)} is out of range: {why}")


def _unclosed_comment(text: str, code: str, open_at: int, line: int) -> NoReturn:
    _fail(
        _OPEN_COMMENT,
        line,
        _leading_number(code),
        f"comment not closed: {_short(text[open_at:])!r} has no ')'; close it or use ';'",
    )


def _strip_comments(s: str) -> tuple[str, int]:
    """Remove ``( ... )`` and ``; ...`` comments. Returns the code and the position of an unclosed
    ``(`` (-1 if every comment is closed); a comment separates words like a blank."""
    if "(" not in s and ";" not in s:
        return s, -1
    parts: list[str] = []
    i = 0
    while True:
        p = s.find("(", i)
        q = s.find(";", i)
        if q != -1 and (p == -1 or q < p):
            parts.append(s[i:q])
            return " ".join(parts), -1
        if p == -1:
            parts.append(s[i:])
            return " ".join(parts), -1
        parts.append(s[i:p])
        e = s.find(")", p + 1)
        if e == -1:
            return " ".join(parts), p
        i = e + 1


_BLOCK_FIELDS = (
    "line",
    "number",
    "text",
    "g_codes",
    "m_codes",
    "axes",
    "centre",
    "feed",
    "area",
    "two_path",
    "extra",
    "program",
)


def _block_maker() -> Callable[
    [
        int,
        int | None,
        str,
        tuple[int, ...],
        tuple[int, ...],
        tuple[tuple[str, float], ...],
        tuple[tuple[str, float], ...],
        float | None,
        dict[str, float],
    ],
    Block,
]:
    """A constructor for word blocks (no area, no second path) that is twice as fast as ``Block()``.

    The frozen dataclass ``__init__`` assigns each of its 11 fields through ``object.__setattr__``,
    which was a third of the parser's time per simple line; the slots' own descriptors do the same
    assignment directly (the instance stays frozen: ``__setattr__`` still refuses). Used only while
    ``Block`` is a slots dataclass with exactly these fields and no ``__post_init__``; otherwise this
    is the ordinary constructor (a unit test compares the two).
    """
    fields_match = tuple(f.name for f in dataclasses.fields(Block)) == _BLOCK_FIELDS
    slotted = all(isinstance(getattr(Block, n, None), types.MemberDescriptorType) for n in _BLOCK_FIELDS)
    if not (fields_match and slotted) or hasattr(Block, "__post_init__"):
        return lambda line, number, text, g, m, axes, centre, feed, extra: Block(  # pragma: no cover
            line, number, text, g, m, axes, centre, feed, None, (), extra, ""
        )
    new = object.__new__
    s_line, s_number, s_text, s_g, s_m, s_axes, s_centre, s_feed, s_area, s_two, s_extra, s_program = (
        getattr(Block, name).__set__ for name in _BLOCK_FIELDS
    )

    def make(
        line: int,
        number: int | None,
        text: str,
        g: tuple[int, ...],
        m: tuple[int, ...],
        axes: tuple[tuple[str, float], ...],
        centre: tuple[tuple[str, float], ...],
        feed: float | None,
        extra: dict[str, float],
    ) -> Block:
        block: Block = new(Block)
        s_line(block, line)
        s_number(block, number)
        s_text(block, text)
        s_g(block, g)
        s_m(block, m)
        s_axes(block, axes)
        s_centre(block, centre)
        s_feed(block, feed)
        s_area(block, None)
        s_two(block, ())
        s_extra(block, extra)
        s_program(block, "")
        return block

    return make


_new_block = _block_maker()


def _check_g_codes(g_codes: list[int], line: int, number: int | None) -> list[int]:
    """Several G codes in one block (E-04): one per group (910106); the same code twice is kept once."""
    seen: dict[str, int] = {}
    unique: list[int] = []
    for g in g_codes:
        if g in unique:
            continue
        group = _G_GROUP.get(g)
        if group is not None:
            other = seen.setdefault(group, g)
            if other != g:
                _fail(
                    _G_CONFLICT,
                    line,
                    number,
                    f"G{other} and G{g} in one block: both are {group}; program only one",
                )
        unique.append(g)
    return unique


class _LineParser:
    """Parses lines against one set of axis names (built once per program in :func:`iter_blocks`)."""

    __slots__ = ("_axes", "_axis_list", "_findall")

    def __init__(self, axis_names: Collection[str]) -> None:
        names = frozenset(name.strip().upper() for name in axis_names)
        # Single-letter words G, M, F, ... keep their meaning even if an axis were so named.
        self._axes: frozenset[str] = frozenset(n for n in names if n not in _ADDRESS_LETTERS)
        self._axis_list = ", ".join(sorted(names)) or "none"
        self._findall = _WORD_PLAIN.findall

    # --- entry points --------------------------------------------------------------------------
    def parse(self, text: str, line: int) -> Block | None:
        stripped = text.strip()
        if not stripped:
            return None
        if "(" in stripped or ";" in stripped or "#" in stripped or ":" in stripped or "/" in stripped:
            code, open_at = _strip_comments(stripped)
            if open_at >= 0:
                _unclosed_comment(stripped, code, open_at, line)
            return self.parse_code(stripped, code, line)
        # the fast path: nothing but words (the N number is read as the first word)
        return self._words(stripped, stripped.upper(), 0, _TO_END, line, None, True)

    def parse_code(self, text: str, code: str, line: int) -> Block | None:
        """Parse comment-free ``code`` (block skip, N, then ``#`` command, two paths or words);
        ``text`` is what the block shows (the original line)."""
        u = code.upper()
        head = _HEAD.match(u)
        assert head is not None  # every part of _HEAD is optional: it always matches
        digits = head.group(1)
        number = int(digits) if digits is not None else None
        pos = head.end()
        if pos >= len(u):  # nothing but a block number, a "/" or blanks (comments are gone already)
            return Block(line, number, text) if number is not None else None
        if u[pos] == "#":
            return Block(line, number, text, area=self._hash_command(u, pos, line, number))
        if ":" in u:
            return self._two_path(text, u, pos, line, number)
        # number None: a malformed N ("N10.5") is left to the word loop, which explains it
        return self._words(text, u, pos, _TO_END, line, number, number is None)

    # --- words -------------------------------------------------------------------------------
    def _words(
        self,
        text: str,
        u: str,
        pos: int,
        end: int,
        line: int,
        number: int | None,
        n_first: bool,
        lenient: bool = False,
    ) -> Block:
        """The word loop, the hot path (E-04). ``n_first`` allows the block number as the first word;
        ``lenient`` accepts any axis-like word (a second path, C14-18)."""
        axes = self._axes if not lenient else _AXIS_LETTERS
        g_codes: list[int] = []
        m_codes: list[int] | None = None  # rare words: their containers only when needed
        axis_words: dict[str, float] = {}
        centre: dict[str, float] | None = None
        extra: dict[str, float] | None = None
        feed: float | None = None
        findall = self._findall if "=" not in u else _WORD.findall
        for letter, idx, num, bad in findall(u, pos, end):
            if bad:
                self._diagnose(u, pos, end, line, number, lenient)
            if idx:
                name = letter + idx
                if name not in axes and not (lenient and letter not in _ADDRESS_LETTERS):
                    self._unknown_axis(name, f"{name}={num}", line, number, lenient)
                if name in axis_words:
                    _twice(f"axis {name}", f"{name}=", axis_words[name], num, line, number)
                value = float(num)
                if not _POSITION_MIN <= value <= _POSITION_MAX:
                    _out_of_range(f"{name}=", num, _POSITION_RANGE, line, number)
                axis_words[name] = value
            elif letter == "G":
                g = _G_BY_TEXT.get(num)
                g_codes.append(g if g is not None else self._g_value(num, line, number))
            elif letter in axes:
                if letter in axis_words:
                    _twice(f"axis {letter}", letter, axis_words[letter], num, line, number)
                value = float(num)
                if not _POSITION_MIN <= value <= _POSITION_MAX:
                    _out_of_range(letter, num, _POSITION_RANGE, line, number)
                axis_words[letter] = value
            elif letter == "F":
                if feed is not None:
                    _twice("feed", "F", feed, num, line, number)
                feed = float(num)
                if not _FEED_MIN <= feed <= _FEED_MAX:
                    _out_of_range("F", num, _FEED_RANGE, line, number)
            elif letter == "N":
                if (
                    not n_first
                    or number is not None
                    or g_codes
                    or m_codes is not None
                    or axis_words
                    or feed is not None
                    or centre is not None
                    or extra is not None
                ):
                    self._misplaced_n(letter + num, line, number)
                number = int(num) if num.isdigit() and len(num) <= 9 else self._block_number(num, line)
            elif letter == "M":
                if not num.isdigit() or len(num) > 9:
                    _fail(
                        _BAD_NUMBER, line, number, f"M{_short(num)}: an M function takes a whole number (M30)"
                    )
                if m_codes is None:
                    m_codes = []
                m_codes.append(int(num))
            elif letter in _CENTRE_LETTERS:
                if centre is None:
                    centre = {}
                elif letter in centre:
                    _twice(f"circle centre {letter}", letter, centre[letter], num, line, number)
                centre[letter] = _ranged(letter, num, _CENTRE_MAX, _CENTRE_RANGE, line, number)
            elif letter in _EXTRA_LETTERS:
                if extra is None:
                    extra = {}
                elif letter in extra:
                    _twice(letter, letter, extra[letter], num, line, number)
                extra[letter] = _ranged(letter, num, _EXTRA_MAX, _EXTRA_RANGE, line, number)
            else:
                self._unknown_axis(letter, letter + num, line, number, lenient)
        if len(g_codes) > 1:
            g_codes = _check_g_codes(g_codes, line, number)
        return _new_block(
            line,
            number,
            text,
            tuple(g_codes),
            tuple(m_codes) if m_codes is not None else (),
            tuple(axis_words.items()),
            tuple(centre.items()) if centre else (),
            feed,
            extra if extra is not None else {},
        )

    def _g_value(self, num: str, line: int, number: int | None) -> int:
        if not num.isdigit():
            _fail(_BAD_NUMBER, line, number, f"G{_short(num)}: a G code takes a whole number (G1, G01)")
        stripped = num.lstrip("0") or "0"
        g = int(stripped) if len(stripped) <= 4 else -1
        if g not in KNOWN_G_CODES:
            known = " ".join(f"G{c}" for c in sorted(KNOWN_G_CODES))
            _fail(_UNKNOWN_G, line, number, f"unknown G code G{_short(num)}; supported: {known}")
        return g

    def _block_number(self, num: str, line: int) -> NoReturn:
        if not num.isdigit():
            _fail(_BAD_N, line, None, f"malformed block number {_short('N' + num)!r}: write N<digits>")
        _fail(_BAD_N, line, None, f"block number {_short('N' + num)!r} too long (9 digits at most)")

    def _misplaced_n(self, word: str, line: int, number: int | None) -> NoReturn:
        if number is not None:
            _fail(
                _BAD_N,
                line,
                number,
                f"second block number {_short(word)}: N stands once, at the start of the block",
            )
        _fail(_BAD_N, line, number, f"block number {_short(word)} must stand at the start of the block")

    def _unknown_axis(self, name: str, word: str, line: int, number: int | None, lenient: bool) -> NoReturn:
        letter = name[0]
        word = _short(word)
        if letter == "N":  # "N10=5"
            _fail(_BAD_N, line, number, f"malformed block number {word!r}: write N<digits>")
        if letter in _ADDRESS_LETTERS or (len(name) == 1 and letter not in _AXIS_LETTERS):
            _fail(
                _UNKNOWN_WORD,
                line,
                number,
                f"unknown word {word!r}: use N, G, M, F, I, J, K, S, T, D, H or an axis ({self._axis_list})",
            )
        where = "not an axis name" if lenient else f"axes of this channel: {self._axis_list}"
        _fail(_UNKNOWN_AXIS, line, number, f"unknown axis name {name} in {word!r} ({where})")

    def _diagnose(self, u: str, pos: int, end: int, line: int, number: int | None, lenient: bool) -> NoReturn:
        """Explain the first word the fast loop could not read (a lexical error). Always raises.

        Words before it were fine, except that the loop may have read the block number from them:
        it is taken again here for the error's label."""
        end = min(end, len(u))
        prev_end = -1  # end of the previous word's value, to spot junk glued to it
        prev_start = pos
        prev_letter = ""
        for m in _WORD.finditer(u, pos, end):
            letter, _, num, bad = m.groups()
            if bad is not None:
                at = m.start(4)
                if "A" <= bad <= "Z":  # a letter without a value
                    self._no_value(u, at, end, line, number, lenient)
                if bad == "#":
                    _fail(
                        _UNKNOWN_WORD,
                        line,
                        number,
                        f"unexpected {_word_at(u, at, end)!r}: a # command stands alone in its block",
                    )
                if bad == ")":
                    _fail(_UNKNOWN_WORD, line, number, "')' without '(': comments are written ( ... )")
                if at == prev_end:
                    word = _word_at(u, prev_start, end)
                    if prev_letter == "N":
                        _fail(_BAD_N, line, None, f"malformed block number {word!r}: write N<digits>")
                    _fail(_BAD_NUMBER, line, number, f"malformed number in {word!r}")
                _fail(_UNKNOWN_WORD, line, number, f"unexpected {_word_at(u, at, end)!r}")
            if letter == "N" and number is None and num.isdigit() and len(num) <= 9:
                number = int(num)  # the label, as the fast loop had it
            prev_end = m.end(3)
            prev_start = m.start(1)
            prev_letter = letter
        # The fast loop saw a problem, so this is not reached; be loud if it ever is.
        _fail(_UNKNOWN_WORD, line, number, f"cannot read {_short(u[pos:end].strip())!r}")  # pragma: no cover

    def _no_value(self, u: str, at: int, end: int, line: int, number: int | None, lenient: bool) -> NoReturn:
        """A letter the word regex could not give a value: ``X``, ``X.``, ``X2 =``, ``HELLO``, ``NX``."""
        found = _BAD_WORD.match(u, at, end)
        word = _short(found.group().strip() if found is not None else u[at])
        letter = u[at]
        if letter == "N":
            _fail(_BAD_N, line, number, f"malformed block number {word!r}: write N<digits>")
        if re.search(r"(?:^[A-Z]|=)\s*[-+]?(?:INF|INFINITY|NAN)$", word):
            _fail(_BAD_NUMBER, line, number, f"{word!r}: not a finite number; write digits ({letter}100)")
        if "=" in word:
            _fail(_BAD_NUMBER, line, number, f"{word!r}: value after '=' missing or malformed")
        if at + 1 < end and u[at + 1].isalpha():  # "HELLO", "XABC"
            _fail(_UNKNOWN_WORD, line, number, f"unknown word {word!r}")
        if not (letter in _ADDRESS_LETTERS or letter in (_AXIS_LETTERS if lenient else self._axes)):
            self._unknown_axis(letter, word, line, number, lenient)
        _fail(_BAD_NUMBER, line, number, f"{word!r}: {letter} needs a number ({letter}100, {letter}-2.5)")

    # --- two-path lines (C14-18) ---------------------------------------------------------------
    def _two_path(self, text: str, u: str, pos: int, line: int, number: int | None) -> Block | None:
        """``: G0 X200 Y0 : G0 U150 V0`` (FCT-C14 section 2.4): first path = the block, the others go to
        ``two_path`` and may name axes of the other path (any axis-like word is accepted there)."""
        bounds: list[tuple[int, int]] = []
        start = pos
        while True:
            colon = u.find(":", start)
            stop = colon if colon != -1 else len(u)
            if u[start:stop].strip():  # an empty path: the usual leading ":", or ":" alone
                bounds.append((start, stop))
            if colon == -1:
                break
            start = colon + 1
        if not bounds:  # a lone ":" (the documents use it to elide lines)
            return Block(line, number, text) if number is not None else None
        (a, b), *others = bounds
        block = self._words(text, u, a, b, line, number, number is None and a == pos)
        subs = tuple(self._words(u[a:b].strip(), u, a, b, line, block.number, False, True) for a, b in others)
        if not subs:
            return block
        return Block(
            block.line,
            block.number,
            block.text,
            block.g_codes,
            block.m_codes,
            block.axes,
            block.centre,
            block.feed,
            None,
            subs,
            block.extra,
        )

    # --- # commands (FCT-C14 section 3) ----------------------------------------------------------
    def _hash_command(self, u: str, pos: int, line: int, number: int | None) -> AreaCommand:
        name_match = _HASH_NAME.match(u, pos)
        assert name_match is not None  # u[pos] == "#"
        name = name_match.group(1)
        lexemes = _area_lexemes(u, name_match.end())
        if name != "CONTROL" or not lexemes or lexemes[0] != ("W", "AREA"):
            shown = f"#{name}" + (f" {lexemes[0][1]}" if name == "CONTROL" and lexemes else "")
            _fail(
                _UNKNOWN_HASH,
                line,
                number,
                f"unknown # command {_short(shown)}; supported: #CONTROL AREA BEGIN|START|END|ON|OFF|CLEAR",
            )
        if len(lexemes) < 2 or lexemes[1][0] != "W" or lexemes[1][1] not in _AREA_KEYWORDS:
            got = f" {_short(lexemes[1][1])!r}" if len(lexemes) > 1 else " nothing"
            _fail(
                _BAD_AREA,
                line,
                number,
                f"#CONTROL AREA: expected BEGIN, START, END, ON, OFF or CLEAR, got{got}",
            )
        keyword = lexemes[1][1]
        return _area_command(keyword, lexemes[2:], line, number)


# --- #CONTROL AREA options ---------------------------------------------------------------------------
def _area_lexemes(u: str, pos: int) -> list[tuple[str, str]]:
    """Lexemes as (kind, text): S string, [ ], =, # number, W name, ? bad character."""
    out: list[tuple[str, str]] = []
    for string, lbr, rbr, eq, num, word, bad in _AREA_LEX.findall(u, pos):
        if word:
            out.append(("W", word))
        elif num:
            out.append(("#", num))
        elif eq:
            out.append(("=", eq))
        elif lbr:
            out.append(("[", lbr))
        elif rbr:
            out.append(("]", rbr))
        elif bad:
            out.append(("?", bad))
        else:
            out.append(("S", string))
    return out


def _area_command(keyword: str, lexemes: list[tuple[str, str]], line: int, number: int | None) -> AreaCommand:
    """C14-02 (BEGIN/START, END), C14-11 (ON), C14-12 (OFF), C14-13 (CLEAR)."""
    shown = f"#CONTROL AREA {keyword}"

    def fail(message: str, alarm: int = _BAD_AREA) -> NoReturn:
        _fail(alarm, line, number, f"{shown}: {message}")

    if keyword == "END":
        if lexemes:
            fail(f"unexpected {lexemes[0][1]!r}: END takes no options")
        return AreaEnd()
    # brackets: "[ options ]"; optional for ON/OFF/CLEAR (the documents write "ON ALL")
    if lexemes and lexemes[0][0] == "[":
        closing = [i for i, (kind, _) in enumerate(lexemes) if kind == "]"]
        if not closing:
            fail("'[' not closed: add ']' after the options")
        close = closing[0]
        if any(kind == "[" for kind, _ in lexemes[1:close]):
            fail("unexpected '[': brackets do not nest, one [ ... ] per command")
        if close != len(lexemes) - 1:
            fail(f"unexpected {lexemes[close + 1][1]!r} after ']'")
        body = lexemes[1:close]
    elif keyword in ("BEGIN", "START"):
        if not lexemes:
            fail("options missing: write [ID=n WORK|PROT POLY|CIRC MIN_EXCUR=.. MAX_EXCUR=..]")
        fail(f"expected '[' before the options, got {lexemes[0][1]!r}")
    else:
        body = lexemes
    allowed = _BEGIN_OPTIONS if keyword in ("BEGIN", "START") else _SELECT_OPTIONS
    options = _read_options(body, allowed, fail)

    if keyword in ("BEGIN", "START"):
        return _area_begin(options, fail)
    area_id = options.get("ID")
    all_ = "ALL" in options
    if area_id is not None and all_:
        fail("ID and ALL both given: select one area or ALL")
    if keyword in ("ON", "CLEAR") and area_id is None and not all_:
        fail("ID or ALL missing: write [ID=n] or ALL")
    selected = int(area_id) if area_id is not None else None
    if keyword == "ON":
        return AreaOn(selected, all_)
    if keyword == "OFF":
        return AreaOff(selected, all_)
    return AreaClear(selected, all_)


def _read_options(
    body: list[tuple[str, str]], allowed: tuple[str, ...], fail: _Fail
) -> dict[str, str | float | int]:
    options: dict[str, str | float | int] = {}
    i = 0
    n = len(body)
    while i < n:
        kind, text = body[i]
        i += 1
        if kind != "W":
            if kind == "[":
                fail("unexpected '[': brackets do not nest, one [ ... ] per command")
            if kind == "]":
                fail("']' without '['")
            if kind == "?":
                _bad_character(text, fail)
            fail(f"unexpected {text!r}: expected an option ({' '.join(allowed)})")
        key = text
        glued = _ID_GLUED.fullmatch(key)
        value: str | None = None
        if glued is not None:  # ID3, the older form of ID=3
            key, value = "ID", glued.group(1)
        if key not in allowed:
            fail(f"unknown option {text!r}; allowed here: {' '.join(allowed)}")
        if key in options:
            fail(f"option {key} given twice")
        if key in _FLAG_OPTIONS:
            options[key] = key
            continue
        if value is None:
            if i < n and body[i][0] == "=":
                i += 1
            if i < n and body[i][0] == "?":
                _bad_character(body[i][1], fail)
            if i >= n or body[i][0] not in ("#", "W", "S") or body[i][1] in _OPTION_WORDS:
                fail(f"value of {key} missing: write {key}=<value>")
            value = body[i][1]
            value_kind = body[i][0]
            i += 1
        else:
            value_kind = "#"
        options[key] = _option_value(key, value, value_kind, fail)
    return options


def _bad_character(text: str, fail: _Fail) -> NoReturn:
    fail(f"unexpected character {text!r}" + (": quote not closed" if text == '"' else ""))


def _option_value(key: str, value: str, kind: str, fail: _Fail) -> str | float | int:
    if key in ("ID", "EXCUR_AXNR"):
        if kind != "#" or not _INT.fullmatch(value):
            fail(f"{key}={_short(value)} is not a whole number (expressions are not supported)")
        whole = int(value)
        low, high = _ID_RANGE if key == "ID" else _AXNR_RANGE
        if not low <= whole <= high:
            what = "an area ID" if key == "ID" else "a logical axis number"
            fail(f"{key}={value} is out of range: {what} is a whole number {low}..{high}", _OUT_OF_RANGE)
        return whole
    if key in ("MIN_EXCUR", "MAX_EXCUR"):
        if kind != "#":
            fail(f"{key}={_short(value)} is not a number (expressions are not supported)")
        number = float(value)
        if not -_POSITION_MAX <= number <= _POSITION_MAX:
            fail(f"{_shown_number(key + '=', value)} is out of range: {_POSITION_RANGE}", _OUT_OF_RANGE)
        return number
    if key == "EXCUR_AX":
        name = value.strip()
        if not re.fullmatch(r"[A-Z][A-Z0-9_]*", name, re.ASCII):
            fail(f"EXCUR_AX={value!r} is not an axis name")
        return name
    # MONITOR_LVL
    level = value.strip()
    if kind == "#" or level not in _MONITOR_LEVELS:
        fail(f'MONITOR_LVL={value!r}: expected "MCS" or "IMCS"')
    return level


def _area_begin(options: dict[str, str | float | int], fail: _Fail) -> AreaBegin:
    for a, b in (("WORK", "PROT"), ("POLY", "CIRC")):
        if a in options and b in options:
            fail(f"{a} and {b} both given: choose one")
    missing = [
        label
        for label, present in (
            ("ID=n", "ID" in options),
            ("WORK|PROT", "WORK" in options or "PROT" in options),
            ("POLY|CIRC", "POLY" in options or "CIRC" in options),
            ("MIN_EXCUR=..", "MIN_EXCUR" in options),
            ("MAX_EXCUR=..", "MAX_EXCUR" in options),
        )
        if not present
    ]
    if missing:
        fail(f"mandatory option(s) missing: {' '.join(missing)}")
    if "EXCUR_AX" in options and "EXCUR_AXNR" in options:
        fail("EXCUR_AX and EXCUR_AXNR both given: name the axis or give its number, not both")
    excur_ax = options.get("EXCUR_AX")
    excur_axnr = options.get("EXCUR_AXNR")
    return AreaBegin(
        area_id=int(options["ID"]),
        kind=AreaKind.WORK if "WORK" in options else AreaKind.PROT,
        shape=AreaShape.POLY if "POLY" in options else AreaShape.CIRC,
        min_excur=float(options["MIN_EXCUR"]),
        max_excur=float(options["MAX_EXCUR"]),
        excur_ax=str(excur_ax) if excur_ax is not None else None,
        excur_axnr=int(excur_axnr) if excur_axnr is not None else None,
        monitor_lvl=str(options.get("MONITOR_LVL", "MCS")),
    )


# --- public API ----------------------------------------------------------------------------------
def parse_line(text: str, line: int, axis_names: Collection[str]) -> Block | None:
    """Parse one NC line (E-04). None for an empty or comment-only line.

    Raises :class:`NcError` (alarms 910100..910109) for malformed input; its ``block`` is ``N130``
    when the line has a readable N number, else ``line <n>``. A ``#CONTROL AREA ... [`` without its
    ``]`` is an error here; :func:`iter_blocks` joins such wrapped lines first.
    """
    return _parser_for(frozenset(axis_names)).parse(text, line)


@functools.lru_cache(maxsize=32)
def _parser_for(axis_names: frozenset[str]) -> _LineParser:
    """parse_line is called line by line by some callers: build the parser once per axis set."""
    return _LineParser(axis_names)


def iter_blocks(text: str | Iterable[str], axis_names: Collection[str]) -> Iterator[Block]:
    """Blocks of a program, lazily, line by line (E-04). ``text`` is the program's text, or its lines
    (an open text file: ``check`` streams a program of any length with flat memory, docs/performance.md).

    Raises :class:`NcError` when it reaches a malformed line, so the blocks before it can already
    run. A ``#CONTROL AREA`` command whose ``[`` is not closed on its line continues on the next
    lines until ``]`` (FCT-C14 section 2.4 wraps ``MIN_EXCUR`` / ``= -100``); the block gets the
    first line's number and the joined lines as text. A continuation stops (alarm 910105) at a line
    that starts a new block (``N<digits>``, ``#``, ``/``, ``:``) or opens another ``[``.
    """
    parser = _LineParser(axis_names)
    words = parser._words
    # lazy; "\n", "\r\n" and "\r" all end a line (a file is opened with newline="" by its reader)
    lines: Iterator[str] = iter(io.StringIO(text, newline="")) if isinstance(text, str) else iter(text)
    line = 0
    for raw in lines:
        line += 1
        stripped = raw.strip()
        if not stripped:
            continue
        # the fast path of _LineParser.parse, inlined: nothing but words (N is read as the first word)
        if not ("(" in stripped or ";" in stripped or "#" in stripped or ":" in stripped or "/" in stripped):
            yield words(stripped, stripped.upper(), 0, _TO_END, line, None, True)
            continue
        block, line = _read_stripped(parser, stripped, line, lines)
        if block is not None:
            yield block


class BlockReader:
    """The parser of :func:`iter_blocks` for a caller that hands it the lines one by one: the batch
    geometry check (``hli_server/engine/batch.py``, docs/performance.md) reads plain motion lines itself and
    gives every other line to :meth:`read`, which parses it exactly as :func:`iter_blocks` does."""

    __slots__ = ("_parser",)

    def __init__(self, axis_names: Collection[str]) -> None:
        self._parser = _LineParser(axis_names)

    def read(self, raw: str, line: int, more: Iterator[str]) -> tuple[Block | None, int]:
        """The block of ``raw``, line number ``line`` (None for a blank or comment-only line), and the
        number of the last line used: a wrapped ``#CONTROL AREA ... [`` continues on lines taken from
        ``more``. Raises :class:`NcError` as :func:`iter_blocks` does."""
        stripped = raw.strip()
        if not stripped:
            return None, line
        return _read_stripped(self._parser, stripped, line, more)


def _read_stripped(
    parser: _LineParser, stripped: str, line: int, lines: Iterator[str]
) -> tuple[Block | None, int]:
    """One non-blank line that left the fast path of :func:`iter_blocks` (comments, ``#``, ``:``, ``/``):
    its block, or None, and the number of the last line used (a wrapped ``#CONTROL AREA`` takes more)."""
    if "#" in stripped and "[" in stripped:
        code, open_at = _strip_comments(stripped)
        if open_at < 0 and code.count("[") > code.count("]") and "#CONTROL" in code.upper():
            first_line = line
            texts = [stripped]
            codes = [code]
            while "]" not in codes[-1]:
                nxt = next(lines, "")
                if not nxt:
                    _continuation_failed(code, first_line, "the end of the program")
                line += 1
                piece = nxt.strip()
                piece_code, piece_open = _strip_comments(piece)
                if piece_open >= 0:
                    _unclosed_comment(piece, piece_code, piece_open, line)
                if not piece_code.strip():
                    continue
                if _NEW_BLOCK.match(piece_code) or "[" in piece_code:
                    _continuation_failed(code, first_line, f"line {line} ({_short(piece)!r})")
                texts.append(piece)
                codes.append(piece_code)
            return parser.parse_code(" ".join(texts), " ".join(codes), first_line), line
    return parser.parse(stripped, line), line


def _continuation_failed(code: str, line: int, where: str) -> NoReturn:
    _fail(
        _BAD_AREA,
        line,
        _leading_number(code),
        f"'[' not closed: no ']' before {where}; close the option list with ']'",
    )


def parse_program(text: str, axis_names: Collection[str]) -> list[Block]:
    """All blocks of a program; raises :class:`NcError` at the first malformed line (E-04)."""
    return list(iter_blocks(text, axis_names))
