"""The expression parser (N-02, N-03): a block's code read character by character into the expression
trees of :mod:`hli_server.engine.nc.expr` - numbers, strings, operators by precedence, functions,
``EXIST[..]``, parameters (``P1``, ``PP1``, ``P[expr]``, ``@P1``) and variables (``V.P.``, ``V.L.``,
``V.S.``, ``V.E.``, ``V.A.``, ``V.G.``, ``V.CYC.``).

:class:`ExpressionParser` holds the scanner the statement parsers build on (``nc/hash_parser.py``,
``nc/statement_parser.py``): the case-folded copy ``u`` of the code keeps the indices of the code, so
strings keep their case. A value of an address word ends at a blank outside brackets (``X P1 * 2`` is
not one value); a whole expression (after ``=``, in a condition) may hold blanks.
"""

from __future__ import annotations

from typing import Final, NoReturn

from hli_server.engine.nc import parser as word_parser
from hli_server.engine.nc.expr import (
    ALARM_EXPRESSION,
    FUNCTION_ARITY,
    KIND_AT_P,
    KIND_CYC,
    KIND_MH,
    KIND_P,
    KIND_PP,
    KIND_RTA,
    KIND_RTG,
    KIND_VA,
    KIND_VE,
    KIND_VG,
    KIND_VL,
    KIND_VP,
    KIND_VS,
    OP_ADD,
    OP_AND,
    OP_BAND,
    OP_BOR,
    OP_BXOR,
    OP_DIV,
    OP_EQ,
    OP_GE,
    OP_GT,
    OP_LE,
    OP_LT,
    OP_MOD,
    OP_MUL,
    OP_NE,
    OP_OR,
    OP_POW,
    OP_SUB,
    OP_XOR,
    BinOp,
    Const,
    ConstantEnv,
    EvalError,
    Exist,
    Expr,
    Func,
    Ref,
    Unary,
)
from hli_server.engine.nc.language import (
    A_BAD_NUMBER,
    A_LIMIT,
    A_NOT_SIMULATED,
    A_RANGE,
    MAX_EXPRESSION_DEPTH,
    MAX_EXPRESSION_NODES,
    MAX_STRING,
)
from hli_server.engine.nc.reader import RawBlock, nc_error
from schemas.external_types import MAX_NESTING

UPPER_LETTERS = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZ")
"""The letters a member name after an index starts with (``V.G.KIN[90].PARAM[0]``)."""

__all__ = [
    "CONSTANT",
    "DIGITS",
    "LETTERS",
    "NAME_CHARS",
    "UPPER",
    "CompileError",
    "ExpressionParser",
    "parse_expression",
]

CONSTANT: Final = ConstantEnv()
UPPER: Final = str.maketrans("abcdefghijklmnopqrstuvwxyz", "ABCDEFGHIJKLMNOPQRSTUVWXYZ")
"""ASCII letters to upper case, every other character kept: indices stay aligned with the text."""
NAME_CHARS: Final = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_")
DIGITS: Final = frozenset("0123456789")
MAX_EXTERNAL_INDICES: Final = 4 * (MAX_NESTING + 1)
"""Indices of one V.E. element: 4 per level, the variable and its structures nested 8 deep."""
LETTERS: Final = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZ")


class CompileError(Exception):
    """A compile error inside the scanner (turned into an NcError with the block's place)."""

    def __init__(self, alarm: int, message: str) -> None:
        super().__init__(message)
        self.alarm = alarm
        self.message = message


class ExpressionParser:
    """Reads expressions from one block's code, character by character (the case-folded copy ``u`` keeps
    the indices of the code, so strings keep their case)."""

    def __init__(self, raw: RawBlock, code: str) -> None:
        self.raw = raw
        self.code = code
        self.u = code.translate(UPPER)
        self.pos = 0
        self.n = len(code)
        self.depth = 0
        self.nodes = 0
        self.number: int | None = None
        """The block's N (read by the statement parser)."""

    # --- low level -------------------------------------------------------------------------------------
    def fail(self, alarm: int, message: str) -> NoReturn:
        raise CompileError(alarm, message)

    def failure(self, alarm: int, message: str) -> CompileError:
        """The error to raise (for a function whose last statement raises it)."""
        return CompileError(alarm, message)

    def blanks(self) -> None:
        u = self.u
        n = self.n
        pos = self.pos
        while pos < n and (u[pos] == " " or u[pos] == "\t"):
            pos += 1
        self.pos = pos

    def at_end(self) -> bool:
        self.blanks()
        return self.pos >= self.n

    def peek(self, k: int = 0) -> str:
        p = self.pos + k
        return self.u[p] if p < self.n else ""

    def word_at(self, start: int) -> str:
        stop = start
        u = self.u
        while stop < self.n and not u[stop].isspace():
            stop += 1
        return word_parser._short(u[start:stop] or u[start : start + 1])

    def name(self) -> str:
        """An identifier: letters, digits, ``_`` (upper case)."""
        start = self.pos
        u = self.u
        while self.pos < self.n and u[self.pos] in NAME_CHARS:
            self.pos += 1
        return u[start : self.pos]

    def keyword(self, word: str) -> bool:
        """Is ``word`` next (and not the start of a longer name)? Consumes it if so."""
        self.blanks()
        end = self.pos + len(word)
        if self.u.startswith(word, self.pos) and (end >= self.n or self.u[end] not in NAME_CHARS):
            self.pos = end
            return True
        return False

    def expect(self, char: str, what: str) -> None:
        self.blanks()
        if self.peek() != char:
            got = f"{self.word_at(self.pos)!r}" if self.pos < self.n else "the end of the block"
            self.fail(ALARM_EXPRESSION, f"expected {char!r} {what}, got {got}")
        self.pos += 1

    def number_literal(self) -> float | None:
        """A number as the word parser reads it (``12``, ``12.5``, ``.5``, ``12.``); None if none here."""
        u = self.u
        start = self.pos
        p = start
        while p < self.n and u[p] in DIGITS:
            p += 1
        if p < self.n and u[p] == ".":
            p += 1
            while p < self.n and u[p] in DIGITS:
                p += 1
        text = u[start:p]
        if not text or text == ".":
            return None
        if p < self.n and u[p] == ".":
            self.fail(A_BAD_NUMBER, f"malformed number in {self.word_at(start)!r}")
        self.pos = p
        value = float(text)
        if value > 1e300:
            self.fail(A_RANGE, f"{word_parser._shown_number('', text)} is out of range: too large a number")
        return value

    # --- expressions --------------------------------------------------------------------------------------
    def expression(self, stop_at_blank: bool) -> Expr:
        saved = self.depth
        if not stop_at_blank:
            self.depth += 1  # blanks are allowed between the operands of a whole expression
        try:
            return self.or_()
        finally:
            self.depth = saved

    def skip(self) -> None:
        """Blanks between tokens: inside brackets, or in an expression that is not a word value."""
        if self.depth > 0:
            self.blanks()

    def count(self) -> None:
        self.nodes += 1
        if self.nodes > MAX_EXPRESSION_NODES:
            self.fail(A_LIMIT, f"the block's expressions have more than {MAX_EXPRESSION_NODES} operands")

    def op_keyword(self, word: str) -> bool:
        self.skip()
        end = self.pos + len(word)
        if self.u.startswith(word, self.pos) and (end >= self.n or self.u[end] not in NAME_CHARS):
            # "MOD", "AND" ... glued to a name before them would not be reached here
            self.pos = end
            return True
        return False

    def op(self, text: str) -> bool:
        self.skip()
        if self.u.startswith(text, self.pos):
            self.pos += len(text)
            return True
        return False

    def or_(self) -> Expr:
        left = self.xor_()
        while self.op("||") or self.op_keyword("OR"):
            self.count()
            left = BinOp(OP_OR, left, self.xor_())
        return left

    def xor_(self) -> Expr:
        left = self.and_()
        while self.op_keyword("XOR"):
            self.count()
            left = BinOp(OP_XOR, left, self.and_())
        return left

    def and_(self) -> Expr:
        left = self.compare()
        while self.op("&&") or self.op_keyword("AND"):
            self.count()
            left = BinOp(OP_AND, left, self.compare())
        return left

    def compare(self) -> Expr:
        left = self.bor()
        while True:
            self.skip()
            u = self.u
            p = self.pos
            two = u[p : p + 2]
            if two in ("==", "!=", "<=", ">=", "<>"):
                self.pos += 2
                op = {"==": OP_EQ, "!=": OP_NE, "<>": OP_NE, "<=": OP_LE, ">=": OP_GE}[two]
            elif two[:1] in ("<", ">"):
                self.pos += 1
                op = OP_LT if two[:1] == "<" else OP_GT
            elif two[:1] == "=" and self.depth > 0:
                self.fail(
                    ALARM_EXPRESSION,
                    f"'=' in a condition: compare with '==' ({self.word_at(max(p - 8, 0))!r})",
                )
            else:
                return left
            self.count()
            left = BinOp(op, left, self.bor())

    def bor(self) -> Expr:
        left = self.bxor()
        while True:
            self.skip()
            if self.u.startswith("|", self.pos) and not self.u.startswith("||", self.pos):
                self.pos += 1
                self.count()
                left = BinOp(OP_BOR, left, self.bxor())
            else:
                return left

    def bxor(self) -> Expr:
        left = self.band()
        while self.op("^"):
            self.count()
            left = BinOp(OP_BXOR, left, self.band())
        return left

    def band(self) -> Expr:
        left = self.additive()
        while True:
            self.skip()
            if self.u.startswith("&", self.pos) and not self.u.startswith("&&", self.pos):
                self.pos += 1
                self.count()
                left = BinOp(OP_BAND, left, self.additive())
            else:
                return left

    def additive(self) -> Expr:
        left = self.term()
        while True:
            self.skip()
            c = self.peek()
            if c in {"+", "-"}:
                self.pos += 1
                self.count()
                left = BinOp(OP_ADD if c == "+" else OP_SUB, left, self.term())
            else:
                return left

    def term(self) -> Expr:
        left = self.unary()
        while True:
            self.skip()
            c = self.peek()
            if c == "*" and self.peek(1) != "*":
                self.pos += 1
                op = OP_MUL
            elif c == "/":
                self.pos += 1
                op = OP_DIV
            elif self.op_keyword("MOD"):
                op = OP_MOD
            else:
                return left
            self.count()
            left = BinOp(op, left, self.unary())

    def unary(self) -> Expr:
        self.skip()
        c = self.peek()
        if c in {"-", "+"}:
            self.pos += 1
            self.count()
            self.depth_guard()
            operand = self.unary()
            if isinstance(operand, Const) and not isinstance(operand.value, str):
                return Const(-operand.value if c == "-" else operand.value)
            return Unary(c == "-", operand)
        return self.power()

    def power(self) -> Expr:
        base = self.primary()
        self.skip()
        if self.u.startswith("**", self.pos):
            self.pos += 2
            self.count()
            self.depth_guard()
            return BinOp(OP_POW, base, self.unary())
        return base

    def depth_guard(self) -> None:
        if self.nodes > MAX_EXPRESSION_NODES:
            self.fail(A_LIMIT, f"the block's expressions have more than {MAX_EXPRESSION_NODES} operands")

    def primary(self) -> Expr:
        self.skip()
        self.count()
        u = self.u
        if self.pos >= self.n:
            self.fail(ALARM_EXPRESSION, "value missing at the end of the block")
        c = u[self.pos]
        if c in DIGITS or c == ".":
            at = self.pos
            number = self.number_literal()
            if number is None:
                self.fail(A_BAD_NUMBER, f"malformed number in {self.word_at(at)!r}")
            return Const(number)
        if c == "[":
            return self.bracket()
        if c == '"':
            close = self.code.find('"', self.pos + 1)
            if close < 0:
                self.fail(
                    ALARM_EXPRESSION, f"string not closed: {self.word_at(self.pos)!r} has no closing '\"'"
                )
            text = self.code[self.pos + 1 : close]
            if len(text) > MAX_STRING:
                self.fail(A_LIMIT, f"a string has at most {MAX_STRING} characters ({len(text)} given)")
            self.pos = close + 1
            return Const(text)
        if c == "@" or (c == "P" and (self.peek(1) in DIGITS or self.peek(1) in ("P", "["))):
            return self.primary_ref()
        if c == "V" and self.peek(1) == "." and self.peek(2) in LETTERS:
            return self.variable()
        if c in LETTERS:
            start = self.pos
            name = self.name()
            if name in ("TRUE", "FALSE", "PI"):
                return Const(1.0 if name == "TRUE" else 0.0 if name == "FALSE" else 3.141592653589793)
            if name == "EXIST":
                return self.exist(start)
            if name in FUNCTION_ARITY:
                return self.function(start, name)
            if (name[:1] in ("M", "H") and name[1:].isdigit()) or name in ("REV", "POS"):
                raise self.failure(
                    A_NOT_SIMULATED,
                    f"axis- or spindle-specific technology words ({name} in [..], X[M54=..], S[REV ..]) "
                    "are not simulated: see docs/nc-language.md",
                )
            self.fail(
                ALARM_EXPRESSION,
                f"unknown name {word_parser._short(name)!r} in an expression (a variable is P1, V.P.NAME, "
                "V.E.NAME ...; functions are SIN[..], SQRT[..], ...)",
            )
        if c == "]":
            self.fail(ALARM_EXPRESSION, "']' without '['")
        raise self.failure(ALARM_EXPRESSION, f"unexpected {self.word_at(self.pos)!r} where a value belongs")

    def bracket(self) -> Expr:
        self.pos += 1
        self.depth += 1
        if self.depth > MAX_EXPRESSION_DEPTH:
            self.fail(A_LIMIT, f"brackets nested deeper than {MAX_EXPRESSION_DEPTH}")
        inner = self.or_()
        self.blanks()
        if self.peek() != "]":
            got = repr(self.word_at(self.pos)) if self.pos < self.n else "the end of the block"
            self.fail(ALARM_EXPRESSION, f"']' missing: got {got}")
        self.pos += 1
        self.depth -= 1
        return inner

    def function(self, start: int, name: str) -> Expr:
        self.blanks()
        if self.peek() != "[":
            self.fail(ALARM_EXPRESSION, f"{name} needs its argument in brackets: {name}[..]")
        self.pos += 1
        self.depth += 1
        if self.depth > MAX_EXPRESSION_DEPTH:
            self.fail(A_LIMIT, f"brackets nested deeper than {MAX_EXPRESSION_DEPTH}")
        args = [self.or_()]
        while True:
            self.blanks()
            if self.peek() == ",":
                self.pos += 1
                args.append(self.or_())
                continue
            break
        self.blanks()
        if self.peek() != "]":
            self.fail(ALARM_EXPRESSION, f"{name}[..: ']' missing")
        self.pos += 1
        self.depth -= 1
        arity = FUNCTION_ARITY[name]
        if len(args) != arity:
            self.fail(ALARM_EXPRESSION, f"{name} takes {arity} argument(s), {len(args)} given")
        func = Func(name, args)
        if func.is_constant():
            # a constant function is evaluated once, here (its errors are the block's)
            try:
                return Const(func.evaluate(CONSTANT))
            except EvalError as exc:
                self.fail(exc.alarm, exc.message)
        return func

    def exist(self, start: int) -> Expr:
        self.blanks()
        if self.peek() != "[":
            self.fail(ALARM_EXPRESSION, "EXIST needs its argument in brackets: EXIST[V.P.NAME]")
        self.pos += 1
        self.depth += 1
        self.blanks()
        c = self.peek()
        if c in ("M", "H") and self.peek(1) in DIGITS:
            self.pos += 1
            begin = self.pos
            while self.pos < self.n and self.u[self.pos] in DIGITS:
                self.pos += 1
            ref = Ref(KIND_MH, c + self.u[begin : self.pos], [], text=c + self.u[begin : self.pos])
        elif c in {"P", "@"}:
            ref = self.primary_ref()
        elif c == "V" and self.peek(1) == ".":
            ref = self.variable()
        else:
            self.fail(
                ALARM_EXPRESSION,
                f"EXIST[..] takes a variable, a parameter or M/H function, got {self.word_at(self.pos)!r}",
            )
        self.expect("]", "after EXIST's variable")
        self.depth -= 1
        return Exist(ref)

    # --- variables ------------------------------------------------------------------------------------------
    def var_name(self) -> str:
        start = self.pos
        u = self.u
        while self.pos < self.n and (
            u[self.pos] in NAME_CHARS
            or (u[self.pos] == "." and self.pos + 1 < self.n and u[self.pos + 1] in NAME_CHARS)
        ):
            self.pos += 1
        name = u[start : self.pos]
        if not name:
            self.fail(ALARM_EXPRESSION, f"variable name missing in {self.word_at(start - 2)!r}")
        return name

    def indices(self) -> list[Expr]:
        out: list[Expr] = []
        while self.peek() == "[":
            self.pos += 1
            self.depth += 1
            out.append(self.or_())
            self.blanks()
            if self.peek() != "]":
                self.fail(ALARM_EXPRESSION, "']' missing after an index")
            self.pos += 1
            self.depth -= 1
            if len(out) > 4:
                self.fail(ALARM_EXPRESSION, "more than 4 indices")
        return out

    def variable(self) -> Ref:
        """``V.P.NAME[i]..``, ``V.L.``, ``V.S.``, ``V.E.``, ``V.A.ABS.X`` / ``V.A.ABS[0]``, ``V.G.NAME``,
        ``V.CYC.``."""
        start = self.pos
        self.pos += 2
        area = self.name()
        if self.peek() != ".":
            self.fail(ALARM_EXPRESSION, f"malformed variable {self.word_at(start)!r}")
        self.pos += 1
        kinds = {
            "P": KIND_VP,
            "L": KIND_VL,
            "S": KIND_VS,
            "E": KIND_VE,
            "A": KIND_VA,
            "G": KIND_VG,
            "CYC": KIND_CYC,
            "RTA": KIND_RTA,
            "RTG": KIND_RTG,
        }
        kind = kinds.get(area)
        if kind is None:
            self.fail(
                A_NOT_SIMULATED,
                f"V.{area}. variables are not simulated (V.P., V.L., V.S., V.E., V.CYC., a subset of "
                "V.A. and "
                "V.G.): see docs/nc-language.md",
            )
        sign = ""
        if kind == KIND_VA and self.peek() in ("+", "-"):
            sign = self.peek()  # V.A.+SWE.X, V.A.-SWE.X: the software limits
            self.pos += 1
        name = sign + self.var_name()
        indices = self.indices()
        if kind == KIND_VE:  # a structure's element after an array's index: V.E.curve[2].point[5].X
            while indices and self.peek() == "." and self.peek(1) in NAME_CHARS:
                self.pos += 1
                name += "." + self.var_name()
                more = self.indices()
                if len(indices) + len(more) > MAX_EXTERNAL_INDICES:
                    self.fail(ALARM_EXPRESSION, f"more than {MAX_EXTERNAL_INDICES} indices")
                indices += more
        while kind == KIND_VG and indices and self.peek() == "." and self.peek(1) in UPPER_LETTERS:
            # V.G.KIN[90].PARAM[12], V.G.KIN[91].AXIS[0].ORIENTATION[1]: a member after an index
            self.pos += 1
            name += "." + self.var_name()
            indices += self.indices()
        return Ref(kind, name, indices, text=self.u[start : self.pos])

    def parameter(self) -> Ref:
        """``P1``, ``P[expr]``, ``PP1`` (indirect), ``P100[5]`` (an array element)."""
        start = self.pos
        depth = 0
        u = self.u
        while self.peek() == "P":
            self.pos += 1
            depth += 1
        if depth > 8:
            self.fail(ALARM_EXPRESSION, f"{self.word_at(start)}: indirection deeper than 8")
        number: Expr
        if self.peek() == "[":
            number = self.bracket()
        else:
            at = self.pos
            while self.pos < self.n and u[self.pos] in DIGITS:
                self.pos += 1
            digits = u[at : self.pos]
            if not digits or len(digits) > 9:
                self.fail(A_BAD_NUMBER, f"malformed parameter {self.word_at(start)!r}: write P<number>")
            number = Const(float(int(digits)))
        indices = self.indices()
        kind = KIND_P if depth == 1 else KIND_PP
        return Ref(kind, "", indices, number, depth, u[start : self.pos])

    def primary_ref(self) -> Ref:
        if self.peek() == "@":
            start = self.pos
            if self.peek(1) != "P" or self.peek(2) not in DIGITS:
                self.fail(
                    ALARM_EXPRESSION, f"unexpected {self.word_at(start)!r}: a cycle parameter is @P<number>"
                )
            self.pos += 2
            at = self.pos
            while self.pos < self.n and self.u[self.pos] in DIGITS:
                self.pos += 1
            digits = self.u[at : self.pos]
            if len(digits) > 9:
                self.fail(A_BAD_NUMBER, f"malformed cycle parameter {self.word_at(start)!r}")
            return Ref(KIND_AT_P, "", [], Const(float(int(digits))), 1, self.u[start : self.pos])
        return self.parameter()


def parse_expression(text: str) -> Expr:
    """``text`` as one expression (blanks allowed, as after ``P1 =``); :class:`NcError` if it is not
    one. For tools and tests: programs are compiled block by block (``nc/compiler.py``)."""
    raw = RawBlock(1, 1, text, text, None)
    parser = ExpressionParser(raw, text)
    try:
        expr = parser.expression(stop_at_blank=False)
        if not parser.at_end():
            raise parser.failure(
                ALARM_EXPRESSION, f"unexpected {parser.word_at(parser.pos)!r} after the expression"
            )
    except CompileError as exc:
        raise nc_error(exc.alarm, 1, None, exc.message) from None
    return expr
