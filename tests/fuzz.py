"""Seeded input generators for the fuzz tests of NC programs, configuration and fault injection
(issue 12; ``docs/reliability.md`` "NC programs and configuration").

Plain ``random.Random`` with a seed rather than hypothesis: the same generator serves the bounded
runs in the suite (a few seconds each) and ``make soak`` (the same tests with ``HLI_FUZZ_SCALE``
times the examples and, with ``HLI_FUZZ_SEED``, other inputs), and a failure names the seed and the
input, which reproduces it exactly.

Three kinds of NC text: *generated* lines from the grammar the parser knows (every word, every #
command, with values near and beyond each range, long digit strings, junk characters), *mutated*
lines of real programs (the documents' examples and the demo programs: characters deleted, inserted,
doubled, numbers replaced by extreme ones), and *programs* that mix both with moves that stay inside
the demo machine's travel, so that the stepped runs get somewhere.
"""

from __future__ import annotations

import math
import os
import random

from tests.spec_examples import CIRC_PROT, CIRC_PROT_OLD, EXTRA_AXES_AREA, SELECT_EXAMPLES, U_AREA

__all__ = [
    "FUZZ_SCALE",
    "FUZZ_SEED",
    "LANGUAGE_CORPUS",
    "count",
    "expression",
    "fault_values",
    "format_message",
    "language_program",
    "mutate",
    "nc_line",
    "nc_program",
    "seed_for",
]

FUZZ_SCALE = float(os.environ.get("HLI_FUZZ_SCALE", "1"))
"""Multiplies every fuzz test's example count (``make soak`` sets it)."""
FUZZ_SEED = int(os.environ.get("HLI_FUZZ_SEED", "20261123"))
"""The base seed; each test derives its own from it and its name."""


def count(base: int) -> int:
    return max(1, round(base * FUZZ_SCALE))


def seed_for(name: str) -> int:
    """A per-test seed: stable across runs and Python versions (no ``hash()`` randomisation)."""
    return FUZZ_SEED * 1_000_003 + sum((i + 1) * ord(c) for i, c in enumerate(name))


CORPUS = [
    *U_AREA.splitlines(),
    *CIRC_PROT.splitlines(),
    *CIRC_PROT_OLD.splitlines(),
    *EXTRA_AXES_AREA.splitlines(),
    *SELECT_EXAMPLES.splitlines(),
    "N10 G90 G17 G00 X0 Y0 Z0 (square 100 mm x 100 mm, feed 3 m/min)",
    "N20 G01 X100 Y0 F3000",
    "N20 G02 X50 Y0 I-50 J0 F2000 (full circle clockwise; I/J relative to the start, G162)",
    "N10 G90 G01 X1=200 X2=300 F6000",
    "N20 G91 G01 X10 Y-10 F500",
    "N30 G92 X0 Y0",
    "N40 G54 G18 G03 X10 Z10 I5 K5 F800",
    "N50 G100 X50 F300",
    "N60 G60 G01 X5",
    "N70 G161 G02 X10 Y0 I5 J0",
    "N80 M30",
    "N90 : G0 X200 Y0 : G0 U150 V0",
    'N100 #CONTROL AREA BEGIN [ID=7 PROT CIRC MIN_EXCUR=-10 MAX_EXCUR=10 EXCUR_AX=Z MONITOR_LVL="MCS"]',
]

CORPUS_GANTRY = [
    "N10 G90 G01 X1=200 X2=300 F6000 (the carriages approach to 100 mm; the pair's minimum is 20 mm)",
    "N20 Z1=-50",
    "N30 Z1=0",
    "N40 X1=0 X2=500",
    "N50 G01 X1=100 X2=110 F6000 (closer than the minimum distance: 70092)",
    "#CONTROL AREA ON ALL",
    "M30",
]

_G_CODES = (0, 1, 2, 3, 4, 17, 18, 19, 53, 54, 60, 90, 91, 92, 100, 161, 162, 200, 5, 999)
_LIMITS = ("214748.3647", "-214748.3647", "214748.3648", "-214748.3648", "429496.7294", "429496.7295")
_AXES = ("X", "Y", "Z", "X1", "X2", "Z1", "A", "U", "Q")
_JUNK = "()[];:#/\"=,.+-_ \t$%&*?!\\'`~ßÄ\u0663\xa0\u2212E"


def number(rng: random.Random) -> str:
    """A number as an NC programmer might write it, or as a fuzzer does: near and beyond every range."""
    kind = rng.random()
    if kind < 0.45:
        return f"{rng.uniform(-300, 300):.{rng.randint(0, 4)}f}"
    if kind < 0.6:
        return str(rng.randint(-20, 20))
    if kind < 0.7:
        return rng.choice(_LIMITS)
    if kind < 0.78:
        return rng.choice(("-", "+", "")) + "9" * rng.randint(6, 40) + rng.choice(("", ".5"))
    if kind < 0.83:
        return "1" + "0" * rng.randint(150, 420)  # the overflowing literals
    if kind < 0.9:
        return rng.choice((".5", "-.25", "+1.", "0.000001", "00010", "-0", "6000000", "6000000.1"))
    return f"{rng.uniform(-1e7, 1e7):.3f}"


def _axis_word(rng: random.Random, axes: tuple[str, ...]) -> str:
    name = rng.choice(axes)
    value = number(rng)
    if any(c.isdigit() for c in name) or rng.random() < 0.1:
        return f"{name}{rng.choice(('=', ' = ', '='))}{value}"
    return f"{name}{rng.choice(('', '', ' '))}{value}"


def _area_command(rng: random.Random) -> str:
    keyword = rng.choice(
        ("BEGIN", "START", "END", "ON", "OFF", "CLEAR", "ON ALL", "OFF ALL", "CLEAR ALL", "FOO")
    )
    if keyword in ("BEGIN", "START"):
        options = [
            rng.choice((f"ID={rng.randint(-2, 25)}", f"ID{rng.randint(0, 25)}", "ID=1.5", "ID=" + "9" * 12)),
            rng.choice(("WORK", "PROT", "WORK PROT", "")),
            rng.choice(("POLY", "CIRC", "")),
            f"MIN_EXCUR={number(rng)}",
            f"MAX_EXCUR{rng.choice(('=', ' = '))}{number(rng)}",
            rng.choice(
                ("", "EXCUR_AX=Z", "EXCUR_AX=Q", f"EXCUR_AXNR={rng.randint(-1, 8)}", 'MONITOR_LVL="IMCS"')
            ),
        ]
        rng.shuffle(options)
        body = " ".join(o for o in options if o)
        return f"#CONTROL AREA {keyword} [{body}{rng.choice((']', ']', ']', ''))}"
    if keyword in ("ON", "OFF", "CLEAR") and rng.random() < 0.8:
        return f"#CONTROL AREA {keyword} [ID={rng.randint(0, 22)}]"
    return f"#CONTROL AREA {keyword}"


def nc_line(rng: random.Random, axes: tuple[str, ...] = _AXES) -> str:
    """One generated line: block number, words in any order, comments, # commands, junk."""
    parts: list[str] = []
    if rng.random() < 0.7:
        parts.append(f"N{rng.choice((str(rng.randint(0, 99999)), '010', '9' * 10, '1.5', ''))}")
    if rng.random() < 0.15:
        parts.append(_area_command(rng))
    else:
        for _ in range(rng.randint(0, 7)):
            r = rng.random()
            if r < 0.35:
                parts.append(_axis_word(rng, axes))
            elif r < 0.55:
                parts.append(f"G{rng.choice(_G_CODES)}")
            elif r < 0.65:
                parts.append(f"F{number(rng)}")
            elif r < 0.75:
                parts.append(f"{rng.choice('IJK')}{number(rng)}")
            elif r < 0.8:
                parts.append(f"M{rng.choice(('30', '2', '02', '1.5', '9' * 11, '3'))}")
            elif r < 0.85:
                parts.append(f"{rng.choice('STDH')}{number(rng)}")
            elif r < 0.9:
                parts.append(rng.choice(("(comment)", "(open", "; rest", ")", ":", "/")))
            else:
                parts.append("".join(rng.choice(_JUNK) for _ in range(rng.randint(1, 4))))
    return " ".join(parts)


def mutate(rng: random.Random, line: str) -> str:
    """A few random edits of ``line``: delete, insert, double, swap, replace a number."""
    chars = list(line)
    for _ in range(rng.randint(1, 4)):
        op = rng.random()
        at = rng.randint(0, len(chars)) if chars else 0
        if op < 0.25 and chars:
            del chars[min(at, len(chars) - 1)]
        elif op < 0.5:
            chars.insert(at, rng.choice(_JUNK + "0123456789XYZGNMFIJ"))
        elif op < 0.65 and chars:
            i = min(at, len(chars) - 1)
            chars[i:i] = chars[i : i + rng.randint(1, 6)]
        elif op < 0.8 and len(chars) > 1:
            i = rng.randrange(len(chars) - 1)
            chars[i], chars[i + 1] = chars[i + 1], chars[i]
        else:
            digits = [i for i, c in enumerate(chars) if c.isdigit()]
            if digits:
                i = rng.choice(digits)
                chars[i : i + 1] = list(number(rng).lstrip("+"))
    return "".join(chars)


def _word(name: str, value: float) -> str:
    return f"{name}={value:.3f}" if name[-1].isdigit() else f"{name}{value:.3f}"


def _safe_move(rng: random.Random, axes: tuple[str, str, str]) -> str:
    """A short move near the origin of the demo machine's channel (axes = its three main axes)."""
    a, b, c = axes
    feed = f" F{rng.choice((2000, 6000, 20000))}" if rng.random() < 0.5 else ""
    g = rng.choice(("G00", "G01", "G01", "G02", "G03"))
    if g in ("G02", "G03") and rng.random() < 0.9:
        # an arc whose end lies on its circle: incremental, centre relative to the start (G162), in
        # one of the three planes (G17: first/second axis with I/J, G18: third/first with K/I, ...)
        plane, (p, q), (wp, wq) = rng.choice(
            (("G17", (a, b), ("I", "J")), ("G18", (c, a), ("K", "I")), ("G19", (b, c), ("J", "K")))
        )
        i, j = rng.uniform(-20, 20), rng.uniform(-20, 20)
        r, a0 = math.hypot(i, j), math.atan2(-j, -i)
        turn = rng.uniform(0.1, 6.2) * (-1 if g == "G02" else 1)
        dx, dy = r * math.cos(a0 + turn) + i, r * math.sin(a0 + turn) + j
        return f"G91 G162 {plane} {g} {_word(p, dx)} {_word(q, dy)} {wp}{i:.6f} {wq}{j:.6f}{feed}\nG90 G17"
    words = f"{g} {_word(a, rng.uniform(-40, 40))} {_word(b, rng.uniform(-40, 40))}"
    if rng.random() < 0.3:
        words += f" {_word(c, rng.uniform(-30, 10))}"
    if g in ("G02", "G03"):
        words += f" I{rng.uniform(-20, 20):.3f} J{rng.uniform(-20, 20):.3f}"
    return words + feed


def _modal_line(rng: random.Random, axes: tuple[str, str, str]) -> str:
    """Valid words that change the modal state: planes, G91, G92, offsets, G60, G100, G161/G162."""
    a, b, _ = axes
    return rng.choice(
        (
            f"G91 G01 {_word(a, rng.uniform(-20, 20))} F3000",
            "G90",
            f"G92 {_word(a, rng.uniform(-50, 50))}",
            rng.choice(("G54", "G55", "G53", "G17", "G18", "G19", "G161", "G162")),
            f"G60 G01 {_word(b, rng.uniform(-20, 20))} F6000",
            f"G100 {_word(a, rng.uniform(-30, 30))} F600",
            f"G01 {_word(a, rng.uniform(-700, 700))} F30000",  # may pass a software limit
        )
    )


def _extreme_line(rng: random.Random, axes: tuple[str, str, str]) -> str:
    """Words at the edge of their ranges, which the parser accepts: what is left for the decoder,
    the geometry and the monitors to survive (huge arcs, shifts, feeds, area extents)."""
    a, b = (f"{n}=" if n[-1].isdigit() else n for n in axes[:2])
    edge = rng.choice(("214748.3647", "-214748.3647", "214748", "-0.0001", "0.0001"))
    centre = rng.choice(("429496.7294", "-429496.7294", "0.0001", "214748.3647"))
    return rng.choice(
        (
            f"G92 {a}{edge}",
            f"G01 {a}{edge} F{rng.choice(('6000000', '0.0001', '1'))}",
            f"G02 {a}0 {b}0 I{centre} J{centre}",
            f"G03 I{centre} F6000000",
            f"G91 G01 {a}{edge} F6000000",
            "G54 G01 F6000000",
            f"#CONTROL AREA BEGIN [ID={rng.randint(0, 25)} PROT POLY MIN_EXCUR=-214748.3647 "
            f"MAX_EXCUR={edge}]",
            f"G01 {a}{edge} {b}{edge}",
            "#CONTROL AREA END",
            "#CONTROL AREA ON ALL",
            "S2147483647 T-2147483647 M999999999",
        )
    )


def nc_program(rng: random.Random, axes: tuple[str, str, str] = ("X", "Y", "Z"), wild: float = 0.08) -> str:
    """1..14 lines, mostly valid so that programs get somewhere: moves, modal changes, whole area
    definitions of the documents; a share ``wild`` of the lines is generated or mutated."""
    lines: list[str] = ["N1 G90 F6000"] if rng.random() < 0.7 else []
    for _ in range(rng.randint(1, 12)):
        r = rng.random()
        if r < wild / 2:
            lines.append(nc_line(rng, (*axes, "Q")))
        elif r < wild:
            lines.append(mutate(rng, rng.choice(CORPUS)))
        elif r < wild + 0.06:
            lines.append(_extreme_line(rng, axes))
        elif r < 0.55:
            lines.append(_safe_move(rng, axes))
        elif r < 0.72:
            lines.append(_modal_line(rng, axes))
        elif r < 0.85 and axes == ("X", "Y", "Z"):
            area = rng.choice((U_AREA, CIRC_PROT, CIRC_PROT_OLD))
            lines.extend(area.splitlines())
            lines.append(rng.choice(("#CONTROL AREA ON ALL", "#CONTROL AREA ON [ID3]", "#CONTROL AREA OFF")))
        else:
            lines.append(rng.choice(CORPUS if axes == ("X", "Y", "Z") else CORPUS_GANTRY))
    if rng.random() < 0.8:
        lines.append("M30")
    return "\n".join(lines) + rng.choice(("\n", "", "\r\n"))


# --- the NC language (issue 20): expressions, variables, control flow, calls, # commands -------------------
LANGUAGE_CORPUS = [
    "P1 = 10 P2 = 30",
    "N10 G01 X P1*SIN[P2] Y[P1 + 2] F6000",
    "$IF P1 == 10",
    "$ELSEIF P1 > 3",
    "$ELSE",
    "$ENDIF",
    "$WHILE P1 > 0",
    "P1 = P1 - 1",
    "$ENDWHILE",
    "$FOR P3 = 1, 3, 1",
    "$ENDFOR",
    "$DO",
    "$ENDDO P1 < 0",
    "$REPEAT",
    "$UNTIL P1 <= 0",
    "$SWITCH P1",
    "$CASE 1",
    "$DEFAULT",
    "$BREAK",
    "$CONTINUE",
    "$ENDSWITCH",
    "N20: X[V.P.A]",
    "$GOTO N20",
    "$GOTO [end]",
    "[end]",
    "#VAR",
    "V.P.A : REAL64 = 1.5",
    "V.L.B[3] = [1, 2, 3]",
    "#ENDVAR",
    "V.P.A = V.P.A * 2",
    "LL SUB",
    "L sub.nc",
    "L CYCLE [NAME=cyc.ecy @P1=5 @P2=P1]",
    '#MSG ["value %d, %.3f", P1, V.P.A]',
    '#MSG SAVE ["saved"]',
    '#FILE NAME [MSG="out.txt"]',
    "#FLUSH",
    "#FLUSH WAIT",
    "#IF P1 == 1",
    "#ELSE",
    "#ENDIF",
    "#COMMENT BEGIN",
    "#COMMENT END",
    "M200=40 G231=50",
    "V.E.COUNT = V.E.COUNT + 1",
    "X[V.A.ABS.X + 1]",
    "N30 G01 X10 \\",
    "(a (nested) comment) X1",
    "M17",
    "M30",
    "%L SUB",
    "%MAIN",
]
_FUNCTIONS = (
    "ABS",
    "SQR",
    "SQRT",
    "EXP",
    "LN",
    "SIN",
    "COS",
    "TAN",
    "ASIN",
    "ATAN2",
    "INT",
    "ROUND",
    "INV",
    "NOT",
)
_OPERATORS = (
    "+",
    "-",
    "*",
    "/",
    "**",
    " MOD ",
    "==",
    "!=",
    "<",
    ">=",
    " AND ",
    " OR ",
    " XOR ",
    "&",
    "|",
    "^",
)


def expression(rng: random.Random, depth: int = 3) -> str:
    """A random expression: numbers near and beyond every range, parameters, variables, functions,
    every operator, brackets (sometimes unbalanced)."""
    r = rng.random()
    if depth <= 0 or r < 0.3:
        return rng.choice(
            (number(rng), f"P{rng.randint(0, 12)}", "V.P.A", "V.L.B[1]", "@P1", "TRUE", "PI", '"s"')
        )
    if r < 0.5:
        name = rng.choice(_FUNCTIONS)
        args = expression(rng, depth - 1) + (f", {expression(rng, depth - 1)}" if name == "ATAN2" else "")
        return f"{name}[{args}]"
    if r < 0.6:
        return f"[{expression(rng, depth - 1)}{rng.choice(('', '', ']'))}"
    if r < 0.65:
        return f"-{expression(rng, depth - 1)}"
    return f"{expression(rng, depth - 1)} {rng.choice(_OPERATORS)} {expression(rng, depth - 1)}"


def language_line(rng: random.Random) -> str:
    """One line of the language: a corpus line, mutated or not, or a statement with a random
    expression."""
    r = rng.random()
    if r < 0.4:
        return rng.choice(LANGUAGE_CORPUS)
    if r < 0.55:
        return mutate(rng, rng.choice(LANGUAGE_CORPUS))
    e = expression(rng)
    return rng.choice(
        (
            f"P{rng.randint(0, 12)} = {e}",
            f"G01 X[{e}] F6000",
            f"$IF {e}",
            f"$WHILE {e}",
            f"$FOR P{rng.randint(1, 9)} = {e}, {expression(rng, 1)}, {expression(rng, 1)}",
            f'#MSG ["%d %s", {e}, {expression(rng, 1)}]',
            f"V.P.A = {e}",
            f"M[{e}] H{e}",
            f"$SWITCH {e}",
            f"$CASE {e}",
            f"$GOTO N[{e}]",
            nc_line(rng),
        )
    )


def language_program(rng: random.Random) -> str:
    """1..25 lines of the language, often with the blocks it needs closed, so that runs get somewhere."""
    lines: list[str] = (
        ["#VAR", "V.P.A = 1", "V.L.B[3] = [1, 2, 3]", "#ENDVAR", "P1 = 3"] if rng.random() < 0.7 else []
    )
    for _ in range(rng.randint(1, 25)):
        lines.append(language_line(rng))
    if rng.random() < 0.8:
        lines.append("M30")
    return "\n".join(lines) + "\n"


def fault_values(rng: random.Random) -> dict[str, object]:
    """1..3 fault fields; each value in its range (at the edges too) seven times in ten, else far
    beyond it, not finite, or of the wrong type (the demo axes' v_max is 500 or 250 mm/s)."""
    valid: dict[str, tuple[object, ...]] = {
        "friction": (0.0, 0.5, 5.0, 30.0, 250.0, 0),
        "gain_factor": (1e-9, 0.05, 0.5, 1.0, 10.0, 100.0, 3),
        "encoder_drift": (0.0, -5.0, 5.0, 100.0, -250.0, 250.0),
        "encoder_stuck": (True, False),
        "drive_error": (True, False),
    }
    invalid: tuple[object, ...] = (
        -1.0, 100.5, 500.1, -500.1, 1e308, -1e308, float("inf"), float("-inf"), float("nan"), "5", None, 1,
    )  # fmt: skip
    fields = rng.sample(list(valid), rng.randint(1, 3))
    return {name: rng.choice(valid[name] if rng.random() < 0.7 else invalid) for name in fields}


_FORMAT_TEXT = "abc XYZ 0123 -+.,:;_/|=()<>!?#*&"
_CONVERSIONS = "diufFeEgGxXos"
_NUMBER_DIGITS = (1, 2, 3, 9, 10, 20, 60)


def _format_number(rng: random.Random) -> str:
    """A width or precision: small, at the 255 bound, or far beyond it (digits up to 60)."""
    pick = rng.random()
    if pick < 0.5:
        return str(rng.randrange(0, 20))
    if pick < 0.65:
        return str(rng.choice((254, 255, 256, 300)))
    if pick < 0.9:
        return str(10 ** rng.randrange(3, 10) - rng.randrange(0, 2))
    return "".join(rng.choice("0123456789") for _ in range(rng.choice(_NUMBER_DIGITS)))


def _format_element(rng: random.Random) -> str:
    element = "%" + "".join(rng.choice("-+ #0") for _ in range(rng.choice((0, 0, 1, 2, 5))))
    if rng.random() < 0.5:
        element += _format_number(rng)
    if rng.random() < 0.5:
        element += "." + (_format_number(rng) if rng.random() < 0.9 else "")
    element += rng.choice(("", "", "l", "h", "ll"))
    return element + (rng.choice(_CONVERSIONS) if rng.random() < 0.9 else rng.choice("%qkZc$ "))


def _format_value(rng: random.Random) -> str:
    return rng.choice(
        (
            str(rng.randrange(-1000, 1000)),
            f"{rng.uniform(-1e6, 1e6):.6f}",
            "EXP[709]",
            "-EXP[709]",
            "EXP[-744]",
            "EXP[-700]",
            "0",
            "1/3",
            '"text"',
            '""',
            '"' + "s" * rng.randrange(0, 120) + '"',
        )
    )


def format_message(rng: random.Random) -> str:
    """A ``#MSG`` block with a format string of text and elements (flags, widths and precisions from 0
    to 60 digits, every conversion and unknown ones, an element cut short at the end) and a number of
    values that matches the elements, or not (issue 36, finding 1)."""
    parts: list[str] = []
    elements = 0
    for _ in range(rng.randrange(1, 8)):
        if rng.random() < 0.4:
            parts.append("".join(rng.choice(_FORMAT_TEXT) for _ in range(rng.randrange(1, 30))))
        else:
            parts.append(_format_element(rng))
            elements += 1
    if rng.random() < 0.05:
        parts.append("%" + rng.choice(("", "5", ".", "-0")))  # cut short
    text = "".join(parts)[:255]
    values = elements + rng.choice((0, 0, 0, 0, 0, 0, -1, 1, 2))
    args = "".join(", " + _format_value(rng) for _ in range(max(0, values)))
    mode = rng.choice(("", "", "SAVE ", "SYN "))
    return f'N10 #MSG {mode}["{text}"{args}]'
