"""The lines of a program text, a window at a time (``hli_server/engine/nc/source.py``, N-01).

Seeded random texts - line ends ``\\n``, ``\\r\\n`` and a lone ``\\r`` anywhere, characters beyond ASCII,
lines over the limit - read through :class:`ProgramText` with windows of a few characters up to the
megabyte of a run, from a string and from a stream, in order and jumping back: every line is the one
``\\r\\n|\\r|\\n`` splits off, a line over the limit raises :class:`LineTooLongError` with its number, the
window's bytes and line ends are the tokenizer's input for the batch check.
"""

from __future__ import annotations

import io
import random
import re

import numpy as np
import pytest

from hli_server.engine.nc import source as source_module
from hli_server.engine.nc.source import MAX_LINE_CHARS, LineTooLongError, ProgramText
from tests.fuzz import count, seed_for

_PIECES = ("G1 X1", "", "é€", "a" * 7, "\r", "\n", "\r\n", "\n\r", " ", "N10 G01 X-1.5 Y2 F100")


def _expected(text: str) -> list[str]:
    lines = re.split(r"\r\n|\r|\n", text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def _read(program: ProgramText, order: list[int]) -> list[str | tuple[str, int]]:
    out: list[str | tuple[str, int]] = []
    for n in order:
        try:
            line = program.line(n)
        except LineTooLongError as exc:
            out.append(("long", exc.line))
            continue
        assert line is not None
        out.append(line)
    return out


@pytest.mark.req("N-01")
@pytest.mark.fuzz
@pytest.mark.parametrize("seed", range(count(8)))
def test_the_lines_of_random_texts_in_any_window_size(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = random.Random(seed_for("nc_source") + seed)
    for _ in range(40):
        chunk = rng.choice([1, 2, 3, 5, 8, 17, 64, 1 << 20])
        parts = [rng.choice(_PIECES) for _ in range(rng.randint(0, 40))]
        if rng.random() < 0.1:
            chunk = rng.choice([1 << 14, 1 << 20])  # a long line is read on a piece at a time
            parts.insert(
                rng.randint(0, len(parts)), "x" * (MAX_LINE_CHARS + rng.randint(1, 3 * MAX_LINE_CHARS))
            )
        monkeypatch.setattr(source_module, "CHUNK_CHARS", chunk)
        text = "".join(parts)
        lines = _expected(text)
        want: list[str | tuple[str, int]] = [
            ("long", k + 1) if len(line) > MAX_LINE_CHARS else line for k, line in enumerate(lines)
        ]
        if any(isinstance(w, tuple) for w in want):
            # a line far over the limit ends what can be read: compare up to it
            first_long = next(k for k, w in enumerate(want) if isinstance(w, tuple))
            want = want[: first_long + 1]
        for program in (ProgramText(text), ProgramText(io.StringIO(text, newline=""))):
            forward = list(range(1, len(want) + 1))
            assert _read(program, forward) == want, repr(text[:200])
            assert _read(program, forward[::-1]) == want[::-1]
            if not any(isinstance(w, tuple) for w in want):
                assert program.line(len(want) + 1) is None
                assert program.last_line == len(want)


def test_a_window_gives_the_tokenizer_its_bytes_and_line_ends() -> None:
    text = "N10 G01 X1\r\nG02 X2 I1 J0 (é)\rM30\n"
    program = ProgramText(text)
    window = program.window_of(1)
    assert window is not None
    assert window.count == 3
    assert window.data == b"N10 G01 X1\nG02 X2 I1 J0 (\xc3\xa9)\nM30\n"
    assert window.ends.tolist() == np.flatnonzero(np.frombuffer(window.data, np.uint8) == 10).tolist()
    assert [window.line(k) for k in range(3)] == ["N10 G01 X1", "G02 X2 I1 J0 (é)", "M30"]
