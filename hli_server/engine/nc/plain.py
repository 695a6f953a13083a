"""Plain motion lines read a chunk at a time with numpy (docs/performance.md: ``check --geometry-only`` as a
batch).

A *plain* line is one the batch geometry check (``hli_server/engine/batch.py``) may decode without the
parser: words only, each a letter immediately followed by its number, separated by blanks (spaces and
tabs), the letters being

* ``N`` (as the first word, up to 9 digits), ``G`` with ``0``..``3`` (``G1``, ``G01``; any other G code is
  not plain), ``F`` (a feed above 0 within the parser's range), ``I``, ``J``, ``K`` (circle centre);
* the channel's axes whose name is one letter (``X``, ``Y``, ``Z``, ``W``), at most once each.

Numbers are the parser's (``[-+]?(digits[.digits] | .digits)``, at most 16 characters, at most 15
digits) within the parser's ranges (:mod:`hli_server.engine.nc.parser`). Letters may be lower case.
Every other line - a comment, ``#CONTROL AREA``, ``M30``, ``G90``, ``X2=5``, ``X 100``, a duplicate
word, a number out of range or malformed, a character of any other kind - is *other*: the caller
hands it to the parser (:class:`~hli_server.engine.nc.parser.BlockReader`), which reads it, or names
its error, exactly as before. A line of blanks only is *empty* (the parser yields no block for it).

The numbers are read as the parser reads them: a decimal with at most 15 digits is its digits as a
whole number (exact in a float) divided by a power of ten up to 1e15 (exact too); IEEE division rounds
that quotient correctly, as ``float()`` rounds the decimal correctly: the same float, bit for bit.

Speed: every step is a numpy operation over the whole chunk (about 40,000 lines in a megabyte); no
Python code runs per line (``benchmarks/bench_check.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from schemas.units import DISTANCE_LIMIT_MM, POSITION_LIMIT_MM, VELOCITY_LIMIT_MM_PER_MIN

__all__ = ["EMPTY", "OTHER", "PLAIN", "PlainChunk", "PlainTokenizer"]

EMPTY = 0
"""A line of blanks only: no block."""
PLAIN = 1
"""A plain motion line: its words are in :attr:`PlainChunk.values`."""
OTHER = 2
"""Any other line: the parser reads it."""

# character classes (bytes.translate maps each byte to one)
_BLANK = 0
_NEWLINE = 1
_DIGIT = 2
_DOT = 3
_SIGN = 4
_LETTER = 5
_BAD = 6

_FIXED_LETTERS = "NGFIJK"
"""The columns of :attr:`PlainChunk.values` before the axes."""
COL_N = 0
COL_G = 1
COL_F = 2
COL_I = 3
COL_J = 4
COL_K = 5

_MAX_CHARS = 16
_MAX_DIGITS = 15
_MAX_N_DIGITS = 9
_POW10 = 10.0 ** np.arange(23)
_POW10_INT = np.array([10**k for k in range(17)], dtype=np.uint64)
_ZEROS = np.uint64(0x3030303030303030)
_DOTS = np.uint64(0x2E2E2E2E2E2E2E2E)
_ONES = np.uint64(0x0101010101010101)
_HIGHS = np.uint64(0x8080808080808080)
_NIBBLES = np.uint64(0xF0F0F0F0F0F0F0F0)

Floats = npt.NDArray[np.float64]
Ints = npt.NDArray[np.int64]
Bools = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class PlainChunk:
    """A chunk of lines: per line its kind, where it is in the chunk's bytes, and the values of a plain
    line's words (NaN where a word is absent; column ``k`` is the letter ``letters[k]``)."""

    kind: npt.NDArray[np.int8]
    starts: Ints
    ends: Ints
    """Byte offsets of each line in the chunk; ``ends`` at its ``\\n``."""
    values: Floats
    """Shape (letters, lines)."""
    letters: str

    @property
    def lines(self) -> int:
        return int(self.kind.shape[0])


class PlainTokenizer:
    """Reads chunks of lines for one channel; ``axis_letters`` are its axes with a one-letter name
    (the others are written ``X2=..``, which is never plain)."""

    def __init__(self, axis_letters: list[str]) -> None:
        letters = _FIXED_LETTERS + "".join(axis_letters)
        if len(set(letters)) != len(letters) or not all("A" <= c <= "Z" for c in letters):
            raise ValueError(f"plain lines: letters {letters!r} must be distinct upper-case A..Z")
        self.letters = letters
        classes = bytearray([_BAD]) * 256
        classes[ord(" ")] = _BLANK
        classes[ord("\t")] = _BLANK
        classes[ord("\n")] = _NEWLINE
        for d in b"0123456789":
            classes[d] = _DIGIT
        classes[ord(".")] = _DOT
        classes[ord("+")] = _SIGN
        classes[ord("-")] = _SIGN
        column = np.full(256, -1, np.int64)
        for k, letter in enumerate(letters):
            for code in (ord(letter), ord(letter.lower())):
                classes[code] = _LETTER
                column[code] = k
        self._classes = bytes(classes)
        self._column = column
        low = np.full(len(letters), -POSITION_LIMIT_MM)
        high = np.full(len(letters), POSITION_LIMIT_MM)
        for k in (COL_I, COL_J, COL_K):
            low[k], high[k] = -DISTANCE_LIMIT_MM, DISTANCE_LIMIT_MM
        # F: a feed above 0 (F0 and F-5 are the decoder's errors: other lines); N and G: checked apart
        low[COL_F], high[COL_F] = 0.0, VELOCITY_LIMIT_MM_PER_MIN
        low[COL_N], high[COL_N] = -np.inf, np.inf
        low[COL_G], high[COL_G] = -np.inf, np.inf
        self._low = low
        self._high = high

    def tokenize(self, data: bytes, ends: Ints | None = None) -> PlainChunk:
        """Classify and read the lines of ``data``: whole lines, each ending with ``\\n`` (no ``\\r``);
        ``ends``: where the ``\\n`` are, if the caller knows it already."""
        a = np.frombuffer(data, np.uint8)
        n = int(a.shape[0])
        c = np.frombuffer(data.translate(self._classes), np.uint8)
        if ends is None:
            ends = np.flatnonzero(c == _NEWLINE)
        lines = int(ends.shape[0])
        starts = np.empty(lines, np.int64)
        if lines:
            starts[0] = 0
            starts[1:] = ends[:-1] + 1
        letters = self.letters
        values = np.full((len(letters), lines), np.nan)
        kind = np.full(lines, OTHER, np.int8)
        if n == 0:
            return PlainChunk(kind, starts, ends, values, letters)
        other = np.zeros(lines, np.bool_)
        bad = np.flatnonzero(c == _BAD)
        if bad.shape[0]:
            other[np.searchsorted(ends, bad)] = True
        # Terminators (blanks, line ends, letters); the characters between one and the next are a
        # number's. A number must follow a letter at once, and a letter must have one.
        term = np.flatnonzero((c <= _NEWLINE) | (c == _LETTER))
        after = np.empty_like(term)
        after[:-1] = term[1:]
        after[-1] = n
        is_letter = c[term] == _LETTER
        has_number = after > term + 1
        orphan = np.flatnonzero(~is_letter & has_number)
        if orphan.shape[0]:
            other[np.searchsorted(ends, term[orphan] + 1)] = True  # a number after a blank or line end
        if c[0] >= _DIGIT and c[0] <= _SIGN:
            other[0] = True  # a number at the chunk's start, before any terminator
        at = np.flatnonzero(is_letter)
        pos = term[at]
        end = after[at]
        line = np.searchsorted(ends, pos)
        # the number: optional sign, then its body of digits and at most one dot, read eight bytes at a
        # time as little-endian integers (SWAR); words of lines already refused are read too, harmlessly
        start = pos + 1
        signed = c[start] == _SIGN
        negative = a[start] == ord("-")
        body = start + signed
        length = end - body
        padded = data + bytes(16)
        eight = np.ndarray((n + 8,), dtype="<u8", buffer=padded, strides=(1,))
        dot = _first_byte(eight.take(body), _DOTS)
        far = np.flatnonzero((dot == 8) & (length > 8))
        if far.shape[0]:
            dot[far] = 8 + _first_byte(eight.take(body[far] + 8), _DOTS)
        has_dot = dot < length
        whole = np.where(has_dot, dot, length)
        decimals = np.clip(np.where(has_dot, length - dot - 1, 0), 0, 16)
        digits = whole + decimals
        low_count = np.minimum(whole, 8)
        number, ok = _digits(eight.take(body + whole - low_count) - _ZEROS, low_count)
        big = np.flatnonzero(whole > 8)
        if big.shape[0]:
            high, high_ok = _digits(eight.take(body[big]) - _ZEROS, whole[big] - 8)
            number[big] += high * _POW10_INT[8]
            ok[big] &= high_ok
        frac, frac_ok = _digits(eight.take(body + whole + 1) - _ZEROS, np.minimum(decimals, 8))
        mantissa = number * _POW10_INT[decimals] + frac
        value = mantissa.astype(np.float64) / _POW10[decimals]
        value = np.where(negative, -value, value)
        column = self._column[a[pos]]
        plain_integer = ~signed & ~has_dot
        wrong = (
            ~(ok & frac_ok & has_number[at])
            | (end - start > _MAX_CHARS)
            | (whole > 2 * 8)
            | (decimals > 8)
            | (digits < 1)
            | (digits > _MAX_DIGITS)
            | (value < self._low[column])
            | (value > self._high[column])
            | ((column == COL_F) & (value <= 0.0))
        )
        words = int(line.shape[0])
        first_of_line = np.ones(words, np.bool_)
        first_of_line[1:] = line[1:] != line[:-1]
        # N: the first word of its line, a whole number of at most 9 digits; G: 0..3
        is_n = column == COL_N
        wrong |= is_n & (~first_of_line | ~plain_integer | (digits > _MAX_N_DIGITS))
        wrong |= (column == COL_G) & (~plain_integer | (value > 3.0))
        other[line[wrong]] = True
        # each letter once per line: the sum of the letters' bits is their union
        if words:
            firsts = np.flatnonzero(first_of_line)
            bits = np.left_shift(np.int64(1), column)
            twice = np.add.reduceat(bits, firsts) != np.bitwise_or.reduceat(bits, firsts)
            other[line[firsts[twice]]] = True
        good = ~other[line]
        if good.all():
            values[column, line] = value
        else:
            values[column[good], line[good]] = value[good]
        has_words = np.zeros(lines, np.bool_)
        has_words[line] = True
        kind[:] = np.where(other, OTHER, np.where(has_words, PLAIN, EMPTY))
        return PlainChunk(kind, starts, ends, values, letters)


def _first_byte(x: npt.NDArray[np.uint64], byte: np.uint64) -> Ints:
    """Index (0..7) of the first byte of each ``x`` (little-endian) equal to ``byte``'s, 8 if none: the
    zero-byte test ``(y - 0x01..) & ~y & 0x80..`` is exact at the lowest zero byte of ``y = x ^ byte``;
    the bits below its lowest mark number 8 k + 7 for byte k (64 where there is none)."""
    y = x ^ byte
    found = (y - _ONES) & ~y & _HIGHS
    below = ~found & (found - np.uint64(1))
    index: Ints = (np.bitwise_count(below) >> 3).astype(np.int64)
    return index


def _digits(x: npt.NDArray[np.uint64], count: Ints) -> tuple[npt.NDArray[np.uint64], Bools]:
    """The first ``count`` (0..8) bytes of ``x`` (characters less ``'0'``, little-endian) as a decimal
    number, and whether they are all digits (SWAR, as simdjson's ``parse_eight_digits``): shifted to
    the top, the bytes beyond ``count`` drop out and leading zero bytes come in."""
    shift = (8 - np.minimum(count, 8)).astype(np.uint64) * np.uint64(8)
    kept = np.where(count > 0, x << np.minimum(shift, np.uint64(56)), np.uint64(0))
    ok: Bools = (kept & _NIBBLES) == 0
    v = ((kept & np.uint64(0x0F0F0F0F0F0F0F0F)) * np.uint64(2561)) >> np.uint64(8)
    v = ((v & np.uint64(0x00FF00FF00FF00FF)) * np.uint64(6553601)) >> np.uint64(16)
    v = (((v & np.uint64(0x0000FFFF0000FFFF)) * np.uint64(42949672960001)) >> np.uint64(32)) & np.uint64(
        0xFFFFFFFF
    )
    return v, ok
