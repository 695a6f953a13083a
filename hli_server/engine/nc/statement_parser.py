"""The statement parser (N-01..N-08): one logical block's code, read character by character, into its
:class:`~hli_server.engine.nc.statements.Stmt` - a block of words (address words with expressions,
assignments, a subroutine or cycle call, a ``$GOTO``), a control statement (``$IF`` .. ``$ENDFOR``) or a
``#`` command (``nc/hash_parser.py``); and the declarations of a ``#VAR`` block.

The word rules are the word parser's (``nc/parser.py``): ``X2=100`` for an axis whose name has digits,
``M52=-345``, ``G131=50``. Which control words exist and what may follow them is
:mod:`hli_server.engine.nc.language`'s; a call names its program here, the interpreter finds it
(``nc/calls.py``).
"""

from __future__ import annotations

import re
from collections.abc import Collection
from typing import Final

from hli_server.engine.nc import parser as word_parser
from hli_server.engine.nc.expr import (
    ALARM_EXPRESSION,
    FUNCTION_ARITY,
    KIND_CYC,
    KIND_P,
    KIND_PP,
    KIND_VL,
    KIND_VP,
    KIND_VS,
    Const,
    Expr,
    Ref,
)
from hli_server.engine.nc.expr_parser import DIGITS, LETTERS, NAME_CHARS
from hli_server.engine.nc.hash_parser import HashParser
from hli_server.engine.nc.language import (
    A_AFTER_CALL,
    A_BAD_N,
    A_BAD_NUMBER,
    A_CONTROL_SYNTAX,
    A_DECLARATION,
    A_GOTO_CHAR,
    A_LIMIT,
    A_NOT_SIMULATED,
    A_TWICE,
    A_UNKNOWN_AXIS,
    A_UNKNOWN_G,
    A_UNKNOWN_WORD,
    ALONE,
    AXIS_FUNCTIONS,
    C_CASE,
    C_FOR,
    C_GOTO,
    C_IF,
    CONDITION_ONLY,
    CONTROL_WORDS,
    IMPLICIT_G_CODES,
    MAX_IMPLICIT_PARAMETERS,
    MAX_NAME,
    MAX_STRING,
    RT_FREQUENCIES,
    SPINDLE_WORDS,
    VALUE_G_CODES,
)
from hli_server.engine.nc.reader import N_HEAD, RawBlock
from hli_server.engine.nc.statements import (
    Assign,
    Call,
    Control,
    Declaration,
    Empty,
    Goto,
    ImplicitCall,
    Item,
    Stmt,
    Technology,
    Word,
    Words,
)

__all__ = ["ChannelAxes", "StatementParser"]

_PROG_DELIMITERS: Final = frozenset(' \t();"[],#$')
_M_RETURN_BEFORE = re.compile(r"(?:^|[\s])M0*(?:17|29)[ \t]*$")
_IMPLICIT_CALL_BEFORE = re.compile(r"(?:^|[\s])G0*(8[0-9]{1,2})[ \t]*$", re.ASCII)
"""``G80``-``G89``, ``G800``-``G8xx`` right before a ``[``: an implicit subroutine call's parameters."""
"""``M17 [MAIN ..]``: the M17/M29 right before a ``[`` (the parameterised jump)."""
_SPINDLE_NAME = re.compile(r"S[0-9]*", re.ASCII)
"""The main spindle ``S`` (P-CHAN-00053's default name) or another spindle ``S1``, ``S2`` ..."""
_SPINDLE_VALUES: Final = ("REV", "POS", "FEED_LINK", "OVERRIDE", "G136")
"""Spindle-specific words with a value (``REV500``, ``REV=500``, ``POS 45``)."""
_VALUE_NAMES: Final = frozenset(("TRUE", "FALSE", "PI", "EXIST", *FUNCTION_ARITY))
"""Names an address word's value may begin with (``XSIN[30]``, ``FABS[P1]``, ``XPI``)."""


class ChannelAxes:
    """The axes a channel's blocks may name: ``names`` (upper case), ``main`` (the axes of ``@X @Y @Z``)
    and ``single``, the one-letter names written ``X10`` (the batch geometry check's plain lines use the
    same letters)."""

    __slots__ = ("listed", "main", "names", "single")

    def __init__(self, axis_names: Collection[str], main_axes: tuple[str, str, str]) -> None:
        names = [n.strip().upper() for n in axis_names]
        self.names = frozenset(names)
        self.main = main_axes
        self.listed = ", ".join(sorted(names)) or "none"
        """The axes for messages."""
        self.single = frozenset(n for n in names if len(n) == 1 and n not in "GMFNIJKSTDHPLEROQ")


class StatementParser(HashParser):
    """Reads one block's code into its statement (:meth:`parse`) or one ``#VAR`` line into its
    declaration (:meth:`declaration`)."""

    def __init__(self, axes: ChannelAxes, raw: RawBlock, code: str) -> None:
        super().__init__(raw, code)
        self.c = axes

    # --- the block -------------------------------------------------------------------------------------
    def parse(self) -> Stmt:
        head = N_HEAD.match(self.u)
        if head is not None:
            self.number = int(head.group(1))
            self.pos = head.end()
            self.blanks()
            if self.peek() == ":":
                self.pos += 1
        self.blanks()
        if self.pos >= self.n:
            return Empty(self.raw, self.number)
        c = self.u[self.pos]
        if c == "$":
            return self.control()
        if c == "#":
            return self.hash_command()
        items = self.items()
        return Words(self.raw, self.number, items)

    def items(self) -> list[Item]:
        items: list[Item] = []
        seen_call: Call | None = None
        implicit: ImplicitCall | None = None
        while not self.at_end():
            start = self.pos
            if seen_call is not None:
                self.fail(
                    A_AFTER_CALL,
                    f"{self.word_at(start)!r} after the call {seen_call.text!r}: nothing may follow a "
                    "subroutine or cycle call in its block; program it before the call",
                )
            item = self.item()
            if isinstance(item, Call):
                seen_call = item
            if implicit is not None and isinstance(item, (Call, Goto, ImplicitCall)):
                self.fail(
                    A_TWICE if isinstance(item, ImplicitCall) else A_AFTER_CALL,
                    f"{item.text!r} in the block of the implicit call {implicit.text!r}: a block calls one "
                    "subprogram or jumps, as its last action (G80..G89 and G800..G839 are one G group)",
                )
            if isinstance(item, ImplicitCall):
                implicit = item  # an L call or a $GOTO before it already ended the block
            items.append(item)
            if (
                isinstance(item, Word)
                and item.letter == "G"
                and isinstance(item.value, Const)
                and item.value.value == 4.0
            ):
                dwell = self.dwell_time()
                if dwell is not None:
                    items.append(dwell)
            if isinstance(item, Goto) and not self.at_end():
                self.fail(
                    A_GOTO_CHAR,
                    f"{self.word_at(self.pos)!r} after {item.text!r}: the jump is the last action "
                    "of its block",
                )
        return items

    def dwell_time(self) -> Word | None:
        """``G04 2.5``, ``G04 P1``, ``G04 V.L.TIME`` (PM 206132747): the time written directly after G04,
        read as the first main axis' word (``G04 X2.5``), as the kernel treats both (M-09)."""
        self.blanks()
        if self.at_end():
            return None
        c, d = self.peek(), self.peek(1)
        if c in "0123456789." or (c == "P" and (d in DIGITS or d in "P[")) or (c == "V" and d == "."):
            start = self.pos
            expr = self.expression(stop_at_blank=True)
            return Word(self.u[start : self.pos], "AXIS", self.c.main[0], expr)
        return None

    def item(self) -> Item:
        u = self.u
        start = self.pos
        c = u[start]
        if c == "$":
            if self.keyword("$GOTO"):
                return self.goto(start)
            word = self.word_at(start)
            self.fail(
                A_CONTROL_SYNTAX,
                f"{word} must stand at the start of its block (only $GOTO may follow other commands)",
            )
        if c == "#":
            self.fail(
                A_UNKNOWN_WORD, f"unexpected {self.word_at(start)!r}: a # command stands alone in its block"
            )
        if c == '"':
            self.fail(
                A_NOT_SIMULATED,
                f"macros ({self.word_at(start)}) are not simulated: see docs/nc-language.md",
            )
        if c == "@":
            return self.at_word(start)
        if (c == "[" or u.startswith(("MAIN", "JUMPS", "N"), start)) and _M_RETURN_BEFORE.search(
            u, 0, start
        ) is not None:
            self.fail(
                A_NOT_SIMULATED,
                f"the parameterised jump of M17/M29 ({u[start:].strip()}: PM 206781707) is not "
                "simulated: see docs/nc-language.md",
            )
        before = _IMPLICIT_CALL_BEFORE.search(u, 0, start) if c == "[" else None
        if before is not None:  # G840[..]: brackets after a G code that no implicit call answers to
            self.fail(
                A_UNKNOWN_G,
                f"G{before[1]}[..]: only G80..G89 and G800..G839 are implicit subroutine calls with values "
                "(PM 206278923)",
            )
        if c == "[":
            self.fail(
                A_UNKNOWN_WORD,
                f"unexpected {self.word_at(start)!r}: a label [name] stands at the block's start",
            )
        if c == ")":
            self.fail(A_UNKNOWN_WORD, "')' without '(': comments are written ( ... )")
        if c not in LETTERS:
            self.fail(A_UNKNOWN_WORD, f"unexpected {self.word_at(start)!r}")
        if c == "V" and self.peek(1) == "." and self.peek(2) in LETTERS:
            ref = self.variable()
            return self.assignment(start, ref)
        if c == "P" and (self.peek(1) in DIGITS or self.peek(1) in ("P", "[")):
            ref = self.parameter()
            return self.assignment(start, ref)
        if c == "L" and (
            self.peek(1) in (" ", "\t", "") or (self.peek(1) == "L" and self.peek(2) in (" ", "\t", ""))
        ):
            return self.call(start)
        if c == "L" and self.peek(1) not in LETTERS and self.peek(1) != "":
            return self.call(start)
        if c == "G":
            implicit = self.implicit_call(start)
            if implicit is not None:
                return implicit
        if c == "N":
            word = self.word_at(start)
            if self.number is None and not u[:start].strip() and self.peek(1) in ("P", "[", "V"):
                return self.block_number(start)
            if self.number is not None:
                self.fail(A_BAD_N, f"second block number {word}: N stands once, at the start of the block")
            self.fail(A_BAD_N, f"block number {word} must stand at the start of the block")
        technology = self.technology(start)
        if technology is not None:
            return technology
        return self.address(start)

    def block_number(self, start: int) -> Word:
        """``NP123``, ``N[P1*100]``, ``NV.L.N`` (PM 206817035: "the block number can be programmed using
        general mathematical expressions ... rounded off internally and converted into an integer")."""
        self.pos = start + 1
        return Word(self.word_at(start), "N", "N", self.word_value(start))

    # --- axis- and spindle-specific syntax -----------------------------------------------------------
    def technology(self, start: int) -> Item | None:
        """``<axis>[<function> ..]`` (PM 5252363631026771979) and ``<spindle>[..]`` (PM 208178187,
        208317067); None where the bracket is an expression (``X[P1+2]``, ``S[P2*10]``)."""
        u = self.u
        p = start
        while p < self.n and u[p] in NAME_CHARS and u[p] != "_":
            p += 1
        if p >= self.n or u[p] != "[":
            return None
        name = u[start:p]
        q = p + 1
        while q < self.n and u[q] in (" ", "\t"):
            q += 1
        r = q
        while r < self.n and u[r] in NAME_CHARS:
            r += 1
        first = u[q:r]
        spindle = _SPINDLE_NAME.fullmatch(name) is not None and name not in self.c.names
        if name in self.c.names:
            if first in AXIS_FUNCTIONS or first.startswith("MC_"):
                what = AXIS_FUNCTIONS.get(first, "PLCopen motion of a path axis")
                self.fail(
                    A_NOT_SIMULATED,
                    f"{name}[{first} ..]: {what} is not simulated: the axis would leave the path the "
                    "monitors check (docs/nc-language.md, axis-specific syntax)",
                )
            if first[:1] in "MH" and first[1:].isdigit():
                # X[M54=..]: the axis' own M and H functions, accepted as every M/H function is here
                functions = self.spindle(start, name, p + 1)
                return Technology(functions.text, name, [], functions.params, [])
            return None
        if not spindle or not (
            first in SPINDLE_WORDS or first.startswith("MC_") or (first[:1] in "MH" and first[1:].isdigit())
        ):
            return None
        return self.spindle(start, name, p + 1)

    def spindle(self, start: int, name: str, body: int) -> Technology:
        """``S[M3 REV500 M19 POS45 H20]``, ``S2[M4 REV5000]``, ``S1[MC_MoveVelocity Velocity=1333 ..]``: the
        main spindle's M3/M4/M5 and REV become the block's words (the speed G95 multiplies with); the rest
        is kept as a :class:`Technology` item, accepted without effect."""
        self.pos = body
        self.depth += 1
        words: list[str] = []
        params: dict[str, Expr] = {}
        main: list[Word] = []
        while self.next_entry(name, ",\\"):
            c = self.peek()
            at = self.pos
            key = next((k for k in _SPINDLE_VALUES if self.u.startswith(k, at)), None)
            if key is not None and self.peek(len(key)) not in LETTERS and self.peek(len(key)) != "_":
                self.pos += len(key)
                self.blanks()
                if self.peek() == "=":
                    self.pos += 1
                value = self.spindle_value(name, key)
                if key == "REV" and name == "S":
                    main.append(Word(self.u[at : self.pos], "S", "S", value))
                    continue
                params[key] = value
                words.append(key)
                continue
            if c in "MH" and self.peek(1) in DIGITS:
                self.pos += 1
                begin = self.pos
                while self.peek() in DIGITS:
                    self.pos += 1
                code = Const(float(int(self.u[begin : self.pos])))
                self.blanks()
                if self.peek() == "=" and self.peek(1) != "=":
                    self.pos += 1
                    params[f"{self.u[at:begin]}{int(code.value)}="] = self.spindle_value(name, c)
                elif name == "S" and c == "M" and code.value in (3.0, 4.0, 5.0):
                    main.append(Word(self.u[at : self.pos].strip(), "M", "M", code))
                    continue
                words.append(self.u[at : self.pos].strip())
                continue
            key = self.name()
            if not key:
                self.fail(A_CONTROL_SYNTAX, f"{name}[..]: unexpected {self.word_at(at)!r}")
            self.blanks()
            if self.peek() == "=" and self.peek(1) != "=":
                self.pos += 1
                params[key] = self.spindle_value(name, key)
                continue
            words.append(key)
        self.depth -= 1
        return Technology(self.u[start : self.pos], name, words, params, main)

    def spindle_value(self, name: str, key: str) -> Expr:
        self.blanks()
        if self.at_end() or self.peek() in ("]", ","):
            self.fail(A_CONTROL_SYNTAX, f"{name}[.. {key}]: the value is missing")
        return self.bracket_value()

    # --- address words -----------------------------------------------------------------------------------
    def address(self, start: int) -> Word:
        u = self.u
        # a name with digits before "=": X2=100, M52=-345, G131=50
        p = start + 1
        while p < self.n and u[p] in NAME_CHARS and u[p] not in "_":
            p += 1
        q = p
        while q < self.n and u[q] in (" ", "\t"):
            q += 1
        if p - start > 1 and q < self.n and u[q] == "=" and u[q + 1 : q + 2] != "=":
            full = u[start:p]
            self.pos = q + 1
            return self.named_word(start, full)
        letter = u[start]
        self.pos = start + 1
        if letter == "=" or (self.peek() == "=" and self.peek(1) != "="):
            self.pos += 1
        if letter in "GMH":
            return self.function_word(start, letter)
        if letter == "R" and "R" not in self.c.single:
            # the circle's radius (G02/G03 X.. Y.. R.., M-08)
            return Word(self.word_at(start), "R", "R", self.word_value(start))
        if letter == "E":
            # the feed at block end (PM 206811147): only the velocity at the block's end; approximated
            return Word(self.word_at(start), "E", "E", self.word_value(start))
        if letter in "FSTDIJK":
            return Word(self.word_at(start), letter, letter, self.word_value(start))
        if letter in self.c.single:
            return Word(self.word_at(start), "AXIS", letter, self.word_value(start))
        word = self.word_at(start)
        if letter in "ABCUVWXYZ":
            self.fail(
                A_UNKNOWN_AXIS,
                f"unknown axis name {letter} in {word!r} (axes of this channel: {self.c.listed})",
            )
        raise self.failure(
            A_UNKNOWN_WORD,
            f"unknown word {word!r}: use N, G, M, H, F, S, T, D, I, J, K, P, V., L, $, # or an axis "
            f"({self.c.listed})",
        )

    def named_word(self, start: int, full: str) -> Word:
        """``X2=100`` (an axis whose name has digits), ``M52=-345``, ``H5=..``, ``G131=50``."""
        letter = full[0]
        if letter in "MH" and full[1:].isdigit():
            value = Const(float(int(full[1:])))
            return Word(self.word_at(start), letter, letter, value, self.word_value(start))
        if letter == "G" and full[1:].isdigit():
            g = int(full[1:])
            if g not in VALUE_G_CODES:
                self.fail(
                    A_UNKNOWN_G,
                    f"{full}=..: G{g} takes no value (G functions with a value: "
                    f"{', '.join(f'G{c}' for c in sorted(VALUE_G_CODES))})",
                )
            return Word(self.word_at(start), "G", "G", Const(float(g)), self.word_value(start))
        if full in self.c.names:
            return Word(self.word_at(start), "AXIS", full, self.word_value(start))
        if letter == "N":
            self.fail(A_BAD_N, f"malformed block number {self.word_at(start)!r}: write N<digits>")
        if letter in "ABCUVWXYZ" or len(full) > 1:
            self.fail(
                A_UNKNOWN_AXIS,
                f"unknown axis name {full} in {self.word_at(start)!r} (axes of this channel: "
                f"{self.c.listed})",
            )
        raise self.failure(A_UNKNOWN_WORD, f"unknown word {self.word_at(start)!r}")

    def function_word(self, start: int, letter: str) -> Word:
        """G, M, H: a whole number (``G01``, ``M30``) or an expression (``MP10``), M/H with an optional
        additional value (``M52=-345``)."""
        self.blanks()
        if letter == "G":
            p = self.pos
            while p < self.n and self.u[p] in DIGITS:
                p += 1
            digits = self.u[self.pos : p]
            if digits and (p >= self.n or self.u[p] not in "."):
                self.pos = p
                stripped = digits.lstrip("0") or "0"
                g = int(stripped) if len(stripped) <= 4 else -1
                return Word(self.word_at(start), "G", "G", Const(float(g)))
        value = self.word_value(start)
        extra: Expr | None = None
        if letter != "G" and self.peek() == "=" and self.peek(1) != "=":
            self.pos += 1
            extra = self.word_value(start)
        return Word(self.word_at(start), letter, letter, value, extra)

    def word_value(self, start: int) -> Expr:
        """The value of an address word: a number, or an expression (``XP1*SIN[P2*30]``), read up to the
        next blank outside brackets; blanks after the address are allowed (``X 100``)."""
        self.blanks()
        if self.pos >= self.n:
            word = self.word_at(start)
            self.fail(A_BAD_NUMBER, f"{word!r}: {word[0]} needs a number ({word[0]}100, {word[0]}-2.5)")
        c = self.u[self.pos]
        if c in "0123456789.":
            at = self.pos
            number = self.number_literal()
            if number is not None and (
                self.pos >= self.n
                or self.u[self.pos] in " \t"
                or self.u[self.pos] in LETTERS
                or self.u[self.pos] in "#$@"
            ):
                return Const(number)
            self.pos = at
        elif c in LETTERS and not self.value_name():
            word = self.word_at(start)
            self.fail(
                A_UNKNOWN_WORD,
                f"unknown word {word!r}: {word[0]} takes a number or an expression (a parameter P1, a "
                "variable V.P.NAME, a function SIN[..], or [..])",
            )
        return self.expression(stop_at_blank=True)

    def value_name(self) -> bool:
        """Does the value at the position begin as a value may (``P1``, ``PP2``, ``P[..]``, ``V.``, a
        function, ``TRUE``, ``PI`` ...)? ``FOO`` is no F word but an unknown word."""
        c, d = self.peek(), self.peek(1)
        if (c == "P" and (d in DIGITS or d in ("P", "["))) or (c == "V" and d == "."):
            return True
        p = self.pos
        while p < self.n and self.u[p] in NAME_CHARS:
            p += 1
        return self.u[self.pos : p] in _VALUE_NAMES

    def at_word(self, start: int) -> Item:
        """``@P1=..`` (a cycle parameter) and the cycle's axes ``@X @Y @Z`` / centre ``@I @J @K``."""
        if self.peek(1) == "P" and self.peek(2) in DIGITS:
            ref = self.primary_ref()
            return self.assignment(start, ref)
        letter = self.peek(1)
        if letter in "XYZ":
            self.pos += 2
            axis = self.c.main["XYZ".index(letter)]
            return Word(self.word_at(start), "AXIS", axis, self.word_value(start))
        if letter in "IJK":
            self.pos += 2
            return Word(self.word_at(start), letter, letter, self.word_value(start))
        if letter == "S":
            self.fail(
                A_NOT_SIMULATED, "@S (the main spindle in a cycle) is not simulated: see docs/nc-language.md"
            )
        raise self.failure(
            A_UNKNOWN_WORD, f"unexpected {self.word_at(start)!r}: @P.., @X, @Y, @Z, @I, @J, @K in cycles"
        )

    def assignment(self, start: int, ref: Ref) -> Assign:
        self.blanks()
        if self.peek() != "=" or self.peek(1) == "=":
            shown = ref.text
            if ref.kind in (KIND_P, KIND_PP):
                self.fail(
                    ALARM_EXPRESSION,
                    f"{shown} without a value: a parameter in a block is assigned ({shown} = 10); "
                    f"as an axis value write X{shown} or X[{shown}]",
                )
            self.fail(
                ALARM_EXPRESSION,
                f"{shown} without a value: a variable in a block is assigned ({shown} = 10); "
                f"as an axis value write X{shown}",
            )
        self.pos += 1
        value = self.expression(stop_at_blank=False)
        return Assign(self.u[start : self.pos].strip(), ref, value)

    # --- calls -------------------------------------------------------------------------------------------
    def implicit_call(self, start: int) -> ImplicitCall | None:
        """``G803``, ``G805[10.0, 9.7, , 2.5]`` (PM 206278923 "Implicit subroutine calls"): the call of the
        subprogram assigned to G80..G89 / G800..G839, with up to 50 values (REAL expressions) in brackets,
        a gap marked by ``, ,``; None for any other G word."""
        u = self.u
        p = start + 1
        while p < self.n and u[p] in DIGITS:
            p += 1
        digits = u[start + 1 : p]
        if not digits or len(digits) > 5 or (p < self.n and u[p] in ".="):
            return None
        g = int(digits)
        if g not in IMPLICIT_G_CODES:
            return None
        self.pos = p
        self.blanks()
        params: list[tuple[int, Expr]] = []
        bracket = self.peek() == "["
        if bracket:
            self.pos += 1
            self.depth += 1
            number = 1
            while True:
                self.blanks()
                c = self.peek()
                if c == "]" and number == 1 and not params:
                    self.pos += 1
                    break
                if c not in (",", "]"):
                    if self.pos >= self.n:
                        self.fail(A_CONTROL_SYNTAX, f"G{g}[: ']' missing after the values")
                    if number > MAX_IMPLICIT_PARAMETERS:
                        self.fail(
                            A_LIMIT,
                            f"G{g}[..]: more than {MAX_IMPLICIT_PARAMETERS} values (PM 206278923: at most "
                            f"{MAX_IMPLICIT_PARAMETERS})",
                        )
                    params.append((number, self.expression(stop_at_blank=False)))
                    self.blanks()
                    c = self.peek()
                if c == ",":
                    self.pos += 1
                    number += 1
                    continue
                if c == "]":
                    self.pos += 1
                    break
                got = repr(self.word_at(self.pos)) if self.pos < self.n else "the end of the block"
                self.fail(A_CONTROL_SYNTAX, f"G{g}[..]: expected ',' or ']' after value {number}, got {got}")
            self.depth -= 1
        return ImplicitCall(u[start : self.pos].strip(), g, params, bracket)

    def call(self, start: int) -> Call:
        local = self.u.startswith("LL", start) and self.peek(2) in (" ", "\t", "")
        self.pos = start + (2 if local else 1)
        self.blanks()
        if self.keyword("CYCLE"):
            return self.cycle_call(start, local)
        u = self.u
        if self.peek() == '"':
            close = self.code.find('"', self.pos + 1)
            if close < 0:
                self.fail(A_UNKNOWN_WORD, f"{self.word_at(start)}: quote not closed")
            name = self.code[self.pos + 1 : close]
            self.pos = close + 1
        elif u.startswith("V.E.", self.pos):  # the name in a V.E. STRING (PM 15556852875)
            variable = self.variable()
            return Call(u[start : self.pos].strip(), local, "", False, [], variable)
        else:
            begin = self.pos
            while self.pos < self.n and self.code[self.pos] not in _PROG_DELIMITERS:
                self.pos += 1
            name = self.code[begin : self.pos]
        if not name:
            self.fail(A_CONTROL_SYNTAX, f"{'LL' if local else 'L'} without a program name")
        if name.upper() == "SEQUENCE":
            self.fail(
                A_NOT_SIMULATED,
                "L SEQUENCE (calling block sequences) is not simulated: see docs/nc-language.md",
            )
        if len(name) > MAX_NAME:
            self.fail(
                A_LIMIT, f"program name {word_parser._short(name)!r} is longer than {MAX_NAME} characters"
            )
        return Call(u[start : self.pos].strip(), local, name, False, [])

    def cycle_call(self, start: int, local: bool) -> Call:
        """``L CYCLE [NAME=<cycle> @P1=<expr> ...]`` (manual "Cycles as global or local subroutines")."""
        self.expect("[", "after CYCLE")
        self.depth += 1
        name = ""
        params: list[tuple[int, Expr]] = []
        seen: set[int] = set()
        while True:
            self.blanks()
            if self.peek() == "]":
                self.pos += 1
                break
            if self.pos >= self.n:
                self.fail(A_CONTROL_SYNTAX, "L CYCLE [: ']' missing after the cycle's parameters")
            if self.keyword("NAME"):
                self.expect("=", "after NAME")
                self.blanks()
                begin = self.pos
                if self.peek() == '"':
                    close = self.code.find('"', begin + 1)
                    if close < 0:
                        self.fail(A_CONTROL_SYNTAX, 'L CYCLE: NAME=" quote not closed')
                    name = self.code[begin + 1 : close]
                    self.pos = close + 1
                else:
                    while self.pos < self.n and self.code[self.pos] not in _PROG_DELIMITERS:
                        self.pos += 1
                    name = self.code[begin : self.pos]
                continue
            for word in ("MODAL_MOVE", "MODAL_BLOCK", "MODAL"):
                if self.keyword(word):
                    self.fail(
                        A_NOT_SIMULATED,
                        f"L CYCLE [{word}]: modal cycle calls are not simulated: see docs/nc-language.md",
                    )
            if self.peek() == "@" and self.peek(1) == "P":
                self.pos += 2
                at = self.pos
                while self.pos < self.n and self.u[self.pos] in DIGITS:
                    self.pos += 1
                if at == self.pos or self.pos - at > 9:
                    self.fail(A_CONTROL_SYNTAX, f"L CYCLE: malformed parameter {self.word_at(at - 2)!r}")
                index = int(self.u[at : self.pos])
                if index in seen:
                    self.fail(A_TWICE, f"L CYCLE: @P{index} given twice")
                seen.add(index)
                self.expect("=", f"after @P{index}")
                params.append((index, self.expression(stop_at_blank=False)))
                continue
            self.fail(A_CONTROL_SYNTAX, f"L CYCLE: unexpected {self.word_at(self.pos)!r} (NAME=.., @P1=..)")
        self.depth -= 1
        if not name:
            self.fail(A_CONTROL_SYNTAX, "L CYCLE [..]: NAME=<cycle> missing")
        if len(name) > MAX_NAME:
            self.fail(
                A_LIMIT, f"cycle name {word_parser._short(name)!r} is longer than {MAX_NAME} characters"
            )
        return Call(self.u[start : self.pos].strip(), local, name, True, params)

    def goto(self, start: int) -> Goto:
        """``$GOTO N<expr>`` or ``$GOTO [name]`` (manual "The $GOTO statement", 206915851)."""
        self.blanks()
        c = self.peek()
        if c == "[":
            close = self.u.find("]", self.pos)
            if close < 0:
                self.fail(A_GOTO_CHAR, "$GOTO [: ']' missing after the label's name")
            name = self.u[self.pos + 1 : close].strip()
            self.pos = close + 1
            return Goto(self.u[start : self.pos], "[" + name + "]", None)
        if c == "N":
            self.pos += 1
            number = self.word_value(start)
            return Goto(self.u[start : self.pos], None, number)
        got = repr(c) if c else "nothing"
        raise self.failure(A_GOTO_CHAR, f"$GOTO followed by {got}: write $GOTO N<number> or $GOTO [label]")

    # --- control statements --------------------------------------------------------------------------------
    def control(self) -> Stmt:
        start = self.pos
        self.pos += 1
        keyword = self.name()
        if keyword not in CONTROL_WORDS:
            self.fail(
                A_CONTROL_SYNTAX,
                f"unknown control statement ${word_parser._short(keyword)}; the kernel's are "
                + " ".join(f"${w}" for w in sorted(CONTROL_WORDS)),
            )
        raw = self.raw
        if keyword == C_GOTO:
            self.pos = start
            items = self.items()
            return Words(raw, self.number, items)
        if keyword in ALONE:
            if not self.at_end():
                alarm = ALONE[keyword]
                self.fail(
                    alarm,
                    f"{self.word_at(self.pos)!r} after ${keyword}: ${keyword} must be programmed alone in "
                    "its block; move the rest to the next block",
                )
            return Control(raw, self.number, keyword, [])
        if keyword == C_FOR:
            return self.for_loop()
        frequency = ""
        if keyword == C_IF:
            frequency = next((w for w in RT_FREQUENCIES if self.keyword(w)), "")
            if frequency:
                self.blanks()
                if self.peek() == "=" and self.peek(1) != "=":
                    self.pos += 1  # $IF ONCE = <cond>: the page's "[ONCE | EDGE | ALWAYS]=.."
        # a condition (or the $CASE values)
        if self.at_end():
            what = "value" if keyword == C_CASE else "condition"
            self.fail(A_CONTROL_SYNTAX, f"${keyword} without its {what}")
        exprs = [self.expression(stop_at_blank=False)]
        if keyword == C_CASE:
            while self.peek() == ",":
                self.pos += 1
                exprs.append(self.expression(stop_at_blank=False))
        goto: Goto | None = None
        if not self.at_end():
            if keyword == C_IF and self.u.startswith("$GOTO", self.pos):
                at = self.pos
                self.keyword("$GOTO")
                goto = self.goto(at)
                if not self.at_end():
                    self.fail(
                        A_GOTO_CHAR,
                        f"{self.word_at(self.pos)!r} after {goto.text!r}: the jump is the last action",
                    )
            else:
                alarm = CONDITION_ONLY.get(keyword, A_CONTROL_SYNTAX)
                self.fail(
                    alarm,
                    f"{self.word_at(self.pos)!r} after ${keyword}'s "
                    f"{'value' if keyword == C_CASE else 'condition'}: "
                    f"only the {'value' if keyword == C_CASE else 'condition'} may follow ${keyword}; "
                    "move the rest to the next block",
                )
        return Control(raw, self.number, keyword, exprs, goto=goto, frequency=frequency)

    def for_loop(self) -> Stmt:
        """``$FOR P1 = <start>, <end>, <step>`` (manual "Counting loop", 206929163)."""
        self.blanks()
        start = self.pos
        c = self.peek()
        if c == "P":
            target = self.parameter()
        elif c == "V" and self.peek(1) == ".":
            target = self.variable()
        else:
            got = repr(self.word_at(start)) if start < self.n else "nothing"
            self.fail(A_CONTROL_SYNTAX, f"$FOR needs a counter (P1 or V.P.NAME), got {got}")
        self.expect("=", "after $FOR's counter")
        exprs = [self.expression(stop_at_blank=False)]
        while self.peek() == ",":
            self.pos += 1
            exprs.append(self.expression(stop_at_blank=False))
        if len(exprs) not in (2, 3):
            self.fail(
                A_CONTROL_SYNTAX,
                f"$FOR {target.text} = <start>, <end>, <step>: {len(exprs)} value(s) given",
            )
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after $FOR: only its counter and range may follow it",
            )
        return Control(self.raw, self.number, C_FOR, exprs, target=target)

    # --- declarations (#VAR) --------------------------------------------------------------------------
    def declaration(self) -> Declaration:
        """``V.P.NAME[3][6] : UNS32 = [..]``, ``V.L.TEXT : STRING[20] = "x"``, ``P10 = 5``, ``P100[50]``."""
        head = N_HEAD.match(self.u)
        if head is not None:
            self.pos = head.end()
        self.blanks()
        start = self.pos
        c = self.peek()
        dims: list[int] = []
        if c == "V" and self.peek(1) == ".":
            self.pos += 2
            area = self.name()
            if area not in ("P", "L", "S", "CYC") or self.peek() != ".":
                self.fail(
                    A_DECLARATION,
                    f"{self.word_at(start)}: only V.P., V.L., V.S. and V.CYC. variables are declared in #VAR",
                )
            self.pos += 1
            name = self.var_name()
            kind = {"P": KIND_VP, "L": KIND_VL, "S": KIND_VS, "CYC": KIND_CYC}[area]
            ref = Ref(kind, name, [], text=f"V.{area}.{name}")
        elif c == "P" and self.peek(1) in DIGITS:
            self.pos += 1
            number = self.number_literal()
            if number is None or number != int(number):
                self.fail(A_DECLARATION, f"{self.word_at(start)}: a parameter is P<number>")
            ref = Ref(KIND_P, "", [], Const(number), 1, f"P{int(number)}")
        else:
            self.fail(
                A_DECLARATION,
                f"unexpected {self.word_at(start)!r} in #VAR: declare V.P.NAME, V.L.NAME, V.S.NAME or P1",
            )
        while self.peek() == "[":
            self.pos += 1
            self.blanks()
            size = self.number_literal()
            self.blanks()
            if size is None or size != int(size) or not 1 <= size <= 1_000_000 or self.peek() != "]":
                self.fail(
                    A_DECLARATION, f"{ref.text}: an array dimension is a whole number 1..1000000 in [ ]"
                )
            self.pos += 1
            dims.append(int(size))
            if len(dims) > 4:
                self.fail(A_DECLARATION, f"{ref.text}: at most 4 array dimensions")
        type_name = "REAL64"
        string_size = 0
        self.blanks()
        if self.peek() == ":":
            self.pos += 1
            self.blanks()
            type_name = self.name()
            if type_name == "REAL":
                type_name = "REAL64"
            if type_name not in (
                "BOOLEAN",
                "SGN08",
                "UNS08",
                "SGN16",
                "UNS16",
                "SGN32",
                "UNS32",
                "REAL32",
                "REAL64",
                "STRING",
            ):
                self.fail(
                    A_DECLARATION,
                    f"{ref.text}: unknown type {word_parser._short(type_name)!r} (BOOLEAN, SGN08, "
                    "UNS08, SGN16, "
                    "UNS16, SGN32, UNS32, REAL32, REAL64, STRING[n])",
                )
            if type_name == "STRING":
                self.expect("[", "after STRING (STRING[20])")
                self.blanks()
                size = self.number_literal()
                self.blanks()
                if size is None or size != int(size) or not 1 <= size <= MAX_STRING or self.peek() != "]":
                    self.fail(A_DECLARATION, f"{ref.text}: STRING[n] with n from 1 to {MAX_STRING}")
                self.pos += 1
                string_size = int(size)
        init: list[Expr] = []
        self.blanks()
        if self.peek() == "=":
            self.pos += 1
            self.blanks()
            if self.peek() == "[" and dims:
                self.pos += 1
                self.depth += 1
                while True:
                    init.append(self.expression(stop_at_blank=False))
                    self.blanks()
                    if self.peek() == ",":
                        self.pos += 1
                        continue
                    break
                self.expect("]", "after the initial values")
                self.depth -= 1
            else:
                init.append(self.expression(stop_at_blank=False))
        if not self.at_end():
            self.fail(
                A_DECLARATION, f"unexpected {self.word_at(self.pos)!r} in the declaration of {ref.text}"
            )
        return Declaration(self.raw.first, ref, dims, type_name, string_size, init)
