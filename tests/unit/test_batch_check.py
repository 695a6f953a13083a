"""The batch geometry check against the exact one (issue 16, P2; ``hli_server/engine/batch.py``).

``check --geometry-only`` decodes plain motion lines many at a time and sends only the blocks it cannot
clear to the exact decoder. These tests hold it to the exact path (``HLI_BATCH_CHECK=0``, block by
block): on random programs (hypothesis, derandomized: seeded and bounded) mixing plain moves, arcs in
three planes, G90/G91, G92, G54, G161, feeds, block numbers, comments, area definitions, activation and
deactivation mid-program, moves aimed at area boundaries (grazing), soft limits and syntax errors, the
two give the same report: the same alarms in the same order with the same numbers, messages, line and
block numbers and parameters (points bit for bit), the same completed flag, block count, final
position and area table. Then the edges one by one, and the tokenizer of plain lines against the parser.
"""

from __future__ import annotations

import math
import os
import random
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from hli_server.commands.check import BATCH_ENV, CheckResult, batch_in_use, check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.engine import batch as batch_module
from hli_server.engine.alarms import Severity
from hli_server.engine.areas.geometry import Circle, Group, Polygon, Prism, first_violation
from hli_server.engine.areas.prefilter import PathBatch, clear_of_areas
from hli_server.engine.batch import BatchGeometryCheck
from hli_server.engine.geometry import ArcSegment, LineSegment, Segment, arc_from_centre
from hli_server.engine.monitors.base import ChannelHooks, Monitor
from hli_server.engine.nc import NcError, parse_line
from hli_server.engine.nc import source as source_module
from hli_server.engine.nc.plain import EMPTY, PLAIN, PlainTokenizer
from schemas.config import MachineConfig, ZeroOffset

AXES = ("X", "Y", "Z")


@pytest.fixture(scope="module")
def config() -> MachineConfig:
    """The demo machine (soft limits X/Y +/-600, Z +/-200 mm) with a zero offset G54 in channel 1."""
    demo = load_machine(None)
    g54 = ZeroOffset(code="G54", offsets={"X": 123_456, "Y": -98_765, "Z": 5_000})
    ch1 = demo.channels[0].model_copy(update={"zero_offsets": [g54]})
    return demo.model_copy(update={"channels": [ch1, *demo.channels[1:]]})


@contextmanager
def _batch_settings(exact: bool, chunk: int | None = None, small: int | None = None) -> Iterator[None]:
    saved = (
        os.environ.get(BATCH_ENV),
        source_module.CHUNK_CHARS,
        batch_module.SMALL_RUN,
        batch_module.SMALL_RUN_PER_AREA,
    )
    os.environ[BATCH_ENV] = "0" if exact else "1"
    if chunk is not None:
        source_module.CHUNK_CHARS = chunk
    if small is not None:
        batch_module.SMALL_RUN = small
        batch_module.SMALL_RUN_PER_AREA = 0
    try:
        yield
    finally:
        if saved[0] is None:
            os.environ.pop(BATCH_ENV, None)
        else:
            os.environ[BATCH_ENV] = saved[0]
        source_module.CHUNK_CHARS, batch_module.SMALL_RUN, batch_module.SMALL_RUN_PER_AREA = saved[1:]


def run(
    config: MachineConfig, text: str, exact: bool, chunk: int | None = None, small: int | None = None
) -> CheckResult:
    with _batch_settings(exact, chunk, small):
        return check_program(Machine(config), text, geometry_only=True)


def report(result: CheckResult) -> dict[str, Any]:
    """Everything a check reports, unrounded (points as the engine computed them)."""
    return {
        "completed": result.completed,
        "blocks": result.blocks,
        "alarms": [
            (a.number, str(a.severity), a.line, a.block, a.message, repr(a.params), a.axis)
            for a in result.alarms
        ],
        "final": [(k, repr(v)) for k, v in result.final_position.items()],
        "areas": repr(result.to_json().get("areas")),
    }


def assert_same(
    config: MachineConfig, text: str, chunk: int | None = None, small: int | None = None
) -> CheckResult:
    exact = run(config, text, exact=True)
    batched = run(config, text, exact=False, chunk=chunk, small=small)
    assert report(batched) == report(exact), text
    return batched


def _count_batched(
    config: MachineConfig, text: str, chunk: int = 1 << 20, small: int | None = 16
) -> tuple[int, int]:
    """Blocks the batch decoded itself and blocks it gave the exact decoder (``small=None``: the
    module's thresholds, with their share per active area)."""
    machine = Machine(config)
    with _batch_settings(False, chunk, small):
        checker = BatchGeometryCheck(machine.channel(1))
        for items in checker.items(text):
            for item in items:
                if getattr(item, "kind", None) is not None and item.kind.name == "ACTION":
                    item.payload()
    return checker.batched_blocks, checker.exact_blocks


# --- random programs --------------------------------------------------------------------------------
def _f(v: float) -> str:
    text = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


_PLANES = {17: ((0, 1), "IJ"), 18: ((2, 0), "KI"), 19: ((1, 2), "JK")}


class _Writer:
    """Writes a random program and tracks what it needs for the next line (program coordinates)."""

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        self.lines: list[str] = []
        self.p = [0.0, 0.0, 0.0]
        self.absolute = True
        self.plane = 17
        self.centre_absolute = False
        self.next_id = 1
        self.areas: list[tuple[int, str, str, tuple[float, ...]]] = []
        self.n = 0
        self.motion = 1

    def word_line(self, words: list[str]) -> None:
        rng = self.rng
        if rng.random() < 0.2:
            self.n += rng.randint(1, 20)
            words = [f"N{self.n}", *words]
        sep = rng.choice((" ", " ", " ", "  ", "\t"))
        text = sep.join(words)
        if rng.random() < 0.05:
            text = text.lower()
        if rng.random() < 0.05:
            text = " " + text + " "
        self.lines.append(text)

    def axis_words(self, target: list[float], which: tuple[int, ...]) -> list[str]:
        out = []
        for k in which:
            value = target[k] if self.absolute else target[k] - self.p[k]
            out.append(f"{AXES[k]}{_f(value)}")
        return out

    def point(self) -> list[float]:
        rng = self.rng
        r = rng.random()
        if r < 0.02 and self.areas:
            # on an area's boundary: a corner, or a point of its circle (a graze, a touch)
            _, _, shape, geo = rng.choice(self.areas)
            if shape == "CIRC":
                cx, cy, rad = geo
                t = rng.choice((0.0, 0.5, 1.0, 1.5)) * math.pi
                return [cx + rad * math.cos(t), cy + rad * math.sin(t), self.p[2]]
            xs, ys = geo[0::2], geo[1::2]
            k = rng.randrange(len(xs))
            return [xs[k], ys[k], self.p[2]]
        if r > 0.997:  # now and then beyond a software limit
            return [rng.uniform(-700, 700), rng.uniform(-700, 700), self.p[2]]
        # a random walk: long runs of moves that pass near the areas now and then
        step = rng.choice((2.0, 15.0, 40.0))
        z = self.p[2] if rng.random() < 0.8 else rng.uniform(-40.0, 40.0)
        x = min(130.0, max(-130.0, self.p[0] + rng.uniform(-step, step)))
        y = min(130.0, max(-130.0, self.p[1] + rng.uniform(-step, step)))
        return [x, y, z]

    def move(self) -> None:
        rng = self.rng
        if rng.random() < 0.7:
            target = self.point()
            target = [float(_f(v)) for v in target]
            which = tuple(k for k in range(3) if target[k] != self.p[k] or rng.random() < 0.3) or (0,)
            g = rng.choice(("G01", "G01", "G00", "G1", "", "", ""))
            if not g and self.motion > 1:
                g = "G01"
            self.motion = {"G00": 0, "": self.motion}.get(g, 1)
            words = ([g] if g else []) + self.axis_words(target, which)
            if rng.random() < 0.15:
                words.append(f"F{rng.choice((500, 2000, 6000))}")
            for k in which:
                self.p[k] = target[k]
            self.word_line(words)
            return
        (a, b), centre_words = _PLANES[self.plane]
        radius = rng.uniform(0.5, 30.0) if rng.random() < 0.95 else rng.uniform(30.0, 200.0)
        phi = rng.uniform(0.0, 2.0 * math.pi)
        cx = self.p[a] - radius * math.cos(phi)
        cy = self.p[b] - radius * math.sin(phi)
        turn = rng.uniform(0.05, 2.0 * math.pi) * rng.choice((1, -1))
        end = list(self.p)
        end[a] = float(_f(cx + radius * math.cos(phi + turn)))
        end[b] = float(_f(cy + radius * math.sin(phi + turn)))
        if rng.random() < 0.005:
            end[a] += 0.05  # off the circle: the decoder's error
        if rng.random() < 0.1:
            end = list(self.p)  # a whole circle
        self.motion = 2 if turn < 0 else 3
        words = ["G02" if turn < 0 else "G03", *self.axis_words(end, (a, b))]
        if self.centre_absolute:
            words += [f"{centre_words[0]}{_f(cx)}", f"{centre_words[1]}{_f(cy)}"]
        else:
            words += [f"{centre_words[0]}{_f(cx - self.p[a])}", f"{centre_words[1]}{_f(cy - self.p[b])}"]
        self.p = end
        self.word_line(words)

    def run(self) -> None:
        for _ in range(self.rng.randint(4, 60)):
            self.move()

    def areas_piece(self) -> None:
        rng = self.rng
        self.lines.append("G90")
        self.absolute = True
        for _ in range(rng.randint(1, 3)):
            area_id = self.next_id
            self.next_id += 1
            kind = "WORK" if rng.random() < 0.25 else "PROT"
            shape = rng.choice(("POLY", "POLY", "CIRC"))
            lo, hi = (
                (-100, 100) if kind == "WORK" else rng.choice(((-100, 100), (-100, 100), (-10, 10), (0, 50)))
            )
            self.lines.append(
                f"#CONTROL AREA BEGIN [ID={area_id} {kind} {shape} MIN_EXCUR={lo} MAX_EXCUR={hi}]"
            )
            size = 140.0 if kind == "WORK" else rng.uniform(3.0, 30.0)
            cx, cy = (0.0, 0.0) if kind == "WORK" else (rng.uniform(-100, 100), rng.uniform(-100, 100))
            cx, cy, size = float(_f(cx)), float(_f(cy)), float(_f(size))
            self.motion = 2 if shape == "CIRC" else 1  # the contour's last block sets the modal motion
            if shape == "CIRC":
                self.lines += [f"G01 X{_f(cx + size)} Y{_f(cy)}", f"G02 I{_f(-size)} J0"]
                geo: tuple[float, ...] = (cx, cy, size)
            else:
                if rng.random() < 0.3:  # an L: not convex
                    pts = [(-1, -1), (1, -1), (1, 0), (0, 0), (0, 1), (-1, 1)]
                elif rng.random() < 0.3:
                    pts = [(-1, -1), (1, -1), (0, 1)]
                else:
                    pts = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
                corners = [(float(_f(cx + sx * size)), float(_f(cy + sy * size))) for sx, sy in pts]
                self.lines += [f"G01 X{_f(x)} Y{_f(y)}" for x, y in [*corners, corners[0]]]
                geo = tuple(v for c in corners for v in c)
            self.lines.append("#CONTROL AREA END")
            self.areas.append((area_id, kind, shape, geo))
        self.lines.append(rng.choice(("#CONTROL AREA ON ALL", f"#CONTROL AREA ON [ID={self.next_id - 1}]")))

    def modal(self) -> None:
        rng = self.rng
        choice = rng.randrange(9)
        if choice == 0:
            self.absolute = not self.absolute
            self.lines.append("G90" if self.absolute else "G91")
        elif choice == 1:
            self.plane = rng.choice((17, 17, 18, 19))
            self.lines.append(f"G{self.plane}")
        elif choice == 2:
            value = float(_f(rng.uniform(-30, 30)))
            self.lines.append(f"G92 X{_f(value)}")
            self.p[0] = value
        elif choice == 3:
            self.lines.append(rng.choice(("G54", "G53")))
            self.p = [float("nan")] * 3  # program coordinates unknown: absolute moves settle them
            self.lines.append("G90 G01 X0 Y0 Z0")
            self.p = [0.0, 0.0, 0.0]
            self.absolute = True
        elif choice == 4:
            self.centre_absolute = not self.centre_absolute
            self.lines.append("G161" if self.centre_absolute else "G162")
        elif choice == 5:
            self.lines.append(f"F{rng.choice((100, 3000, 20000))}")
        elif choice == 6 and self.areas:
            area_id = rng.choice(self.areas)[0]
            self.lines.append(
                rng.choice(
                    (
                        f"#CONTROL AREA OFF [ID={area_id}]",
                        f"#CONTROL AREA ON [ID={area_id}]",
                        "#CONTROL AREA OFF",
                        "#CONTROL AREA ON ALL",
                    )
                )
            )
        elif choice == 7:
            self.lines.append(
                rng.choice(
                    ("(a comment)", "; a note", "", "   ", "N5", "G01 X1 (inline)", " (c) (d) ; e", "(open")
                )
            )
            if self.lines[-1].startswith("G01"):
                self.p[0] = 1.0 if self.absolute else self.p[0] + 1.0
        else:
            self.lines.append(rng.choice(("G01 X1.2.3", "G01 X", "G1 Q5", "N10 N20", "G01 X99999999")))


@st.composite
def programs(draw: st.DrawFn) -> str:
    seed = draw(st.integers(0, 2**32 - 1))
    pieces = draw(st.lists(st.sampled_from("aarrrrrrmmm"), min_size=1, max_size=10))
    w = _Writer(random.Random(seed))
    w.lines.append(w.rng.choice(("G90 G17 G01 X0 Y0 Z0 F6000", "N1 G90 F3000", "G01 X0 Y0 F6000")))
    for piece in pieces:
        if piece == "a":
            w.areas_piece()
        elif piece == "r":
            w.run()
        elif piece == "m" and w.rng.random() < 0.85:
            w.modal()
        elif piece == "m":
            w.lines.append(w.rng.choice(("G01 X1.2.3", "M30", "G01 X700 Y0")))
    if w.rng.random() < 0.7:
        w.lines.append("M30")
    return "\n".join(w.lines) + w.rng.choice(("\n", "", "\r\n"))


@pytest.mark.req("C14-15", "E-06")
@pytest.mark.fuzz
@settings(max_examples=120, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(text=programs(), chunk=st.sampled_from((1 << 20, 300, 97)), small=st.sampled_from((1, 4, 16)))
def test_batch_and_exact_report_the_same_on_random_programs(
    config: MachineConfig, text: str, chunk: int, small: int
) -> None:
    result = assert_same(config, text, chunk=chunk, small=small)
    event(f"first alarm: {[a.number for a in result.alarms][:1]}")
    event(f"blocks: {'<50' if result.blocks < 50 else '<200' if result.blocks < 200 else '>=200'}")


def test_random_programs_are_mostly_batched(config: MachineConfig) -> None:
    """The differential test above would prove little if the batch handed everything to the exact path."""
    batched = exact = 0
    rng = random.Random(16)
    for _ in range(30):
        w = _Writer(rng)
        w.lines.append("G90 G17 G01 X0 Y0 Z0 F6000")
        w.areas_piece()
        for _ in range(4):
            w.run()
        b, e = _count_batched(config, "\n".join(w.lines), small=4)
        batched += b
        exact += e
    assert batched > exact, (batched, exact)


# --- the edges, one by one --------------------------------------------------------------------------
AREAS = """G90 G17 G01 X0 Y0 Z0 F6000
#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]
G01 X-200 Y-200
X200 Y-200
X200 Y200
X-200 Y200
X-200 Y-200
#CONTROL AREA END
#CONTROL AREA BEGIN [ID=2 PROT CIRC MIN_EXCUR=-100 MAX_EXCUR=100]
G01 X60 Y0
G02 I-10 J0
#CONTROL AREA END
#CONTROL AREA BEGIN [ID=3 PROT POLY MIN_EXCUR=-100 MAX_EXCUR=100]
G01 X-80 Y-20
X-60 Y-20
X-60 Y20
X-80 Y20
X-80 Y-20
#CONTROL AREA END
#CONTROL AREA ON ALL
"""


def _zigzag(n: int, x0: float = -30.0, x1: float = 30.0) -> list[str]:
    """Moves clear of every area of AREAS (between the square and the circle)."""
    return [f"G01 X{_f(x0 if k % 2 else x1)} Y{_f(-40.0 + (k % 80))}" for k in range(n)]


@pytest.mark.req("C14-15")
@pytest.mark.parametrize(
    ("before", "move", "alarm"),
    [
        ("G01 X50 Y30", "G01 X50 Y10", 912001),  # onto the top of the protection circle: a touch
        ("G01 X60 Y30", "G01 X60 Y-30", 912001),  # tangent to it
        ("G01 X60.00001 Y30", "G01 X60.00001 Y-30", None),  # 10 nm beside it
        ("G01 X-60 Y60", "G01 X-60 Y20", 912001),  # onto the square's corner
        ("G01 X-59.99999 Y60", "G01 X-59.99999 Y-60", None),  # 10 nm beside its edge, all along
        ("G01 X0 Y0", "G01 X200 Y0", 912001),  # through the circle
        ("G01 X0 Y0", "G00 X-70 Y0", 912001),  # into the square
        ("G01 X0 Y150", "G01 X200 Y150", None),  # to the work area's edge: a work area may be touched
        ("G01 X0 Y150", "G01 X200.0001 Y150", 120486),  # just beyond it
    ],
)
def test_a_block_that_grazes_an_area_mid_chunk(
    config: MachineConfig, before: str, move: str, alarm: int | None
) -> None:
    text = AREAS + "\n".join([*_zigzag(500), before, move, *_zigzag(500), "M30"]) + "\n"
    result = assert_same(config, text)
    assert [a.number for a in result.alarms if a.severity == Severity.ERROR] == ([alarm] if alarm else [])
    batched, _ = _count_batched(config, text)
    assert batched >= 500


@pytest.mark.req("C14-15")
@pytest.mark.parametrize(
    ("arc", "alarm"),
    [
        # from (62, 5) to (62, -5): the chord misses the circle (centre (50, 0), radius 10) ...
        ("G03 X62 Y-5 I4 J-5", 912001),  # ... the arc about (66, 0) bulges into it
        ("G02 X62 Y-5 I4 J-5", None),  # the other way round it stays right of the chord
        ("G03 X62 Y-5 I5.25 J-5", 912001),  # about (67.25, 0): touches it at (60, 0)
        ("G03 X62 Y-5 I5.26 J-5", None),  # 2.8 µm off
    ],
)
def test_arcs_whose_chord_misses_an_area_but_not_the_arc(
    config: MachineConfig, arc: str, alarm: int | None
) -> None:
    approach = ["G01 X30 Y30", "G01 X62 Y30", "G01 X62 Y5"]  # round the circle, not through it
    text = (
        AREAS
        + "\n".join([*_zigzag(200), *approach, arc, "G01 X62 Y30", "G01 X30 Y30", *_zigzag(200), "M30"])
        + "\n"
    )
    result = assert_same(config, text)
    assert [a.number for a in result.alarms if a.severity == Severity.ERROR] == ([alarm] if alarm else [])


@pytest.mark.req("C14-15", "C14-11")
def test_a_violation_deep_in_a_long_program_and_an_area_activated_mid_chunk(config: MachineConfig) -> None:
    body = _zigzag(30_000)
    body[20_000:20_000] = ["#CONTROL AREA OFF [ID=2]", "G01 X55 Y0", "G01 X0 Y0", "#CONTROL AREA ON [ID=2]"]
    body[25_000:25_000] = ["N777 G01 X45 Y0"]
    text = AREAS + "\n".join([*body, "M30"]) + "\n"
    result = assert_same(config, text)
    (alarm,) = [a for a in result.alarms if a.severity == Severity.ERROR]
    assert (alarm.number, alarm.line, alarm.block) == (912001, AREAS.count("\n") + 25_001, "N777")
    assert result.final_position["X"] == -30.0  # the refused block's start


@pytest.mark.req("E-04", "C14-15")
def test_incremental_moves_sum_as_the_decoder_sums_them(config: MachineConfig) -> None:
    steps = [f"G01 X{_f(0.1 * ((k % 7) - 3))} Y{_f(0.3 if k % 2 else -0.3)}" for k in range(3000)]
    text = "G90 G01 X0 Y0 Z0 F6000\nG91\n" + "\n".join(steps) + "\nG90\nM30\n"
    exact = run(config, text, exact=True)
    result = assert_same(config, text)
    assert result.final_position == exact.final_position  # the same floats, rounding included


def test_comment_lines_do_not_cut_a_stretch(config: MachineConfig) -> None:
    body: list[str] = []
    for k, line in enumerate(_zigzag(600)):
        body.append(line)
        if k % 3 == 0:
            body.append(("(comment)", "; a note", "  (two) (comments) ; and a note")[k % 9 // 3])
    text = AREAS + "\n".join([*body, "G01 X0 Y-300", "M30"]) + "\n"
    result = assert_same(config, text)
    assert [a.number for a in result.alarms] == [120486]  # the last move leaves the work area
    batched, exact = _count_batched(config, text, small=None)
    assert batched >= 590, (batched, exact)


def test_short_stretches_among_areas_are_decoded_block_by_block(config: MachineConfig) -> None:
    """The batch's set-up costs per stretch (a little more with each active area): with 3 areas active,
    a stretch shorter than SMALL_RUN + 3 * SMALL_RUN_PER_AREA plain lines between two other lines is
    not batched."""
    n = batch_module.SMALL_RUN + 3 * batch_module.SMALL_RUN_PER_AREA

    def program(stretch: int) -> str:
        body: list[str] = []
        for _ in range(10):
            body += [*_zigzag(stretch), "M08"]
        return AREAS + "\n".join([*body, "M30"]) + "\n"

    short, long = program(n - 1), program(n)
    assert_same(config, short)
    assert_same(config, long)
    assert _count_batched(config, short, small=None)[0] == 0
    assert _count_batched(config, long, small=None)[0] >= 10 * (n - 2)


@pytest.mark.req("E-04")
@pytest.mark.parametrize(
    "bad", ["G01 X1.2.3", "G01 X", "N12 G01 Q5", "N12 N13 X1", "G01 X214748.3648", "G01 X1 X2"]
)
def test_a_syntax_error_mid_chunk_is_the_parsers_error_with_line_and_block(
    config: MachineConfig, bad: str
) -> None:
    text = "G90 G01 X0 Y0 F6000\n" + "\n".join([*_zigzag(700), bad, *_zigzag(700), "M30"]) + "\n"
    result = assert_same(config, text)
    (alarm,) = result.alarms
    assert alarm.line == 702
    assert alarm.block == ("N12" if bad.startswith("N12") else "line 702")
    assert 910100 <= alarm.number <= 910111
    assert result.blocks == 701


@pytest.mark.req("E-04", "C14-02")
@pytest.mark.parametrize("ending", ["\n", "\r\n", "\r"])
@pytest.mark.parametrize("chunk", [1 << 20, 64, 7])
def test_line_ends_chunk_borders_and_a_wrapped_area_command(
    config: MachineConfig, ending: str, chunk: int
) -> None:
    """The lines a chunk is cut into are the parser's, whatever ends them; a ``#CONTROL AREA BEGIN [``
    wrapped over lines continues across a chunk's border."""
    lines = [
        "G90 G01 X0 Y0 Z0 F6000",
        *_zigzag(40),
        "#CONTROL AREA BEGIN [ID=5 PROT POLY MIN_EXCUR",
        "= -100 MAX_EXCUR=100]",
        "G01 X-20 Y100",
        "X20 Y100",
        "X20 Y120",
        "X-20 Y120",
        "X-20 Y100",
        "#CONTROL AREA END",
        "#CONTROL AREA ON ALL",
        "",
        "(comment)",
        *_zigzag(40),
        "G01 X0 Y110",
        "M30",
    ]
    text = ending.join(lines) + ending
    result = assert_same(config, text, chunk=chunk, small=4)
    assert [a.number for a in result.alarms] == [912001]


@pytest.mark.req("E-04")
def test_a_program_without_m30_ends_with_the_last_blocks_warning(config: MachineConfig) -> None:
    text = "G90 G01 X0 Y0 F6000\n" + "\n".join(_zigzag(100)) + "\nN99 G01 X1 Y1\n\n(trailing comment)\n"
    result = assert_same(config, text)
    (warning,) = result.alarms
    assert (warning.number, warning.line, warning.block) == (911005, 102, "N99")


@pytest.mark.req("E-06")
def test_soft_limits_mid_chunk(config: MachineConfig) -> None:
    for move, alarm in (
        ("G01 X600 Y0", None),
        ("G01 X600.0001 Y0", 120002),
        ("G02 X0 Y0 I0 J-300", None),  # a whole circle down to the limit
        ("G02 X0 Y0 I0 J-300.0001", 120003),
        ("G03 X0 Y0 I300.0001 J0", 120002),
    ):
        text = "G90 G01 X0 Y0 F6000\n" + "\n".join([*_zigzag(100), "G01 X0 Y0", move, *_zigzag(100), "M30"])
        result = assert_same(config, text)
        assert [a.number for a in result.alarms] == ([alarm] if alarm else []), move


def test_a_path_check_the_batch_does_not_know_means_block_by_block(config: MachineConfig) -> None:
    class Watcher(Monitor):
        def __init__(self, machine: Any) -> None:
            self.seen = 0

        def channel_hooks(self, channel: Any) -> ChannelHooks:
            def check(segment: Any, block: Any) -> None:
                self.seen += 1

            return ChannelHooks(path_check=check)

    from hli_server.engine.machine import DEFAULT_MONITORS

    machine = Machine(config, monitors=(*DEFAULT_MONITORS, Watcher))
    assert not batch_in_use(machine, 1, record_path=False)
    text = "G90 G01 X0 Y0 F6000\n" + "\n".join(_zigzag(50)) + "\nM30\n"
    result = check_program(machine, text, geometry_only=True)
    assert result.completed
    assert machine.monitor(Watcher).seen == 50  # every move (the first block does not move)


def test_plot_and_env_switch_use_the_exact_path(config: MachineConfig) -> None:
    machine = Machine(config)
    assert batch_in_use(machine, 1, record_path=False)
    assert not batch_in_use(machine, 1, record_path=True)
    with _batch_settings(exact=True):
        assert not batch_in_use(machine, 1, record_path=False)


TWO_WORKS = """G90 G17 G01 X0 Y0 Z0 F6000
#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]
G01 X-200 Y-200
X30 Y-200
X30 Y200
X-200 Y200
X-200 Y-200
#CONTROL AREA END
#CONTROL AREA BEGIN [ID=2 WORK CIRC MIN_EXCUR=-100 MAX_EXCUR=100]
G01 X210 Y0
G02 I-100 J0
#CONTROL AREA END
#CONTROL AREA BEGIN [ID=3 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]
G01 X-300 Y300
X300 Y300
X300 Y350
X-300 Y350
X-300 Y300
#CONTROL AREA END
#CONTROL AREA BEGIN [ID=4 PROT POLY MIN_EXCUR=-100 MAX_EXCUR=100]
G01 X150 Y50
X170 Y50
X170 Y55
X160 Y55
X160 Y60
X150 Y60
X150 Y50
#CONTROL AREA END
#CONTROL AREA BEGIN [ID=5 PROT CIRC MIN_EXCUR=-100 MAX_EXCUR=100]
G01 X-90 Y100
G02 I-10 J0
#CONTROL AREA END
#CONTROL AREA ON ALL
"""


@pytest.mark.req("C14-15")
@pytest.mark.parametrize(
    ("moves", "alarm"),
    [
        (["G01 X120 Y20"], None),  # in the circle only (the second work area)
        (["G01 X0 Y20", "G01 X-100 Y20"], None),  # through both into the square only (the first)
        (["G01 X-100 Y20", "G02 X-100 Y-20 I0 J-20"], None),  # an arc in the square
        (["G01 X120 Y20", "G03 X120 Y20 I0 J10"], None),  # a whole circle in the circle
        (["G01 X140 Y20", "G03 X140 Y20 I0 J20"], 912001),  # ... through the L
        (["G01 X0 Y250"], 120486),  # out of all three
        (["G01 X155 Y40", "G01 X155 Y49.99999"], None),  # 10 nm below the L
        (["G01 X155 Y40", "G01 X155 Y50"], 912001),  # onto its edge
        (["G01 X145 Y40", "G02 X165 Y40 I10 J0"], 912001),  # an arc up to its edge (tangent)
        (["G01 X145 Y39.99", "G02 X165 Y39.99 I10 J0"], None),  # 10 µm below it
        (["G01 X-100 Y20", "G01 X-100 Y89"], None),  # 1 mm below the protection circle
        (["G01 X-100 Y20", "G01 X-115 Y85", "G03 X-85 Y85 I15 J0"], None),  # an arc below it
        (["G01 X-100 Y20", "G01 X-115 Y85", "G02 X-85 Y85 I15 J0"], 912001),  # over the top: into it
    ],
)
def test_several_work_areas_and_mixed_protections(
    config: MachineConfig, moves: list[str], alarm: int | None
) -> None:
    """The prefilter tests all areas of a group at once: a path is held by any one of the work areas
    (a square, a circle, a band), protections of both shapes (an L, a circle) are all tested."""
    zigzag = [f"G01 X{_f(60.0 if k % 2 else 140.0)} Y{_f(-40.0 + (k % 80))}" for k in range(300)]
    text = TWO_WORKS + "\n".join([*zigzag, "G01 X100 Y20", *moves, *zigzag, "M30"]) + "\n"
    result = assert_same(config, text)
    assert [a.number for a in result.alarms if a.severity == Severity.ERROR] == ([alarm] if alarm else [])
    batched, _ = _count_batched(config, text)
    assert batched >= 290  # the zigzag is in the circle only: cleared by the second work area


# --- arcs near the areas, one by one (issue 26) ------------------------------------------------------
_CENTRE_LETTER = {"X": "I", "Y": "J", "Z": "K"}
_PLANE_OF = {17: (0, 1), 18: (2, 0), 19: (1, 2)}


def _area_groups(config: MachineConfig, areas: str) -> list[Group]:
    """The active area groups after ``areas`` (as the batch hands them to the prefilter)."""
    machine = Machine(config)
    checker = BatchGeometryCheck(machine.channel(1))
    for items in checker.items(areas):
        for item in items:
            if getattr(item, "kind", None) is not None and item.kind.name == "ACTION":
                item.payload()
    groups, _ = checker._checks()
    return groups


def _arc_text(
    g: str, start: dict[str, float], end: dict[str, float], centre: dict[str, float], absolute: bool
) -> str:
    words = [g, *(f"{k}{_f(v)}" for k, v in end.items())]
    for axis, c in centre.items():
        words.append(f"{_CENTRE_LETTER[axis]}{_f(c if absolute else c - start[axis])}")
    return " ".join(words)


def _arc_segment(
    plane: int, g: str, start: dict[str, float], end: dict[str, float], centre: dict[str, float]
) -> ArcSegment:
    """The arc as the decoder builds it (machine coordinates: no offset in AREAS)."""
    p0 = tuple(start[a] for a in AXES)
    p1 = tuple(end.get(a, start[a]) for a in AXES)
    i, j = _PLANE_OF[plane]
    arc, mismatch = arc_from_centre(p0, p1, (i, j), (centre[AXES[i]], centre[AXES[j]]), g == "G02")
    assert mismatch < 1e-3
    return arc


# (name, approach points X/Y from (0, 30) at Z0 then Z, plane, G, end, centre, leave points, alarm, cleared)
# the circle of AREAS: centre (50, 0), radius 10; the square: x -80..-60, y -20..20; the work area +-200
_Points = list[tuple[float, float]]
_NearArc = tuple[
    str, _Points, float, int, str, dict[str, float], dict[str, float], _Points, int | None, bool | None
]
_NEAR_ARCS: list[_NearArc] = [
    # rings about the circle
    (
        "ring 0.1 µm off the circle",
        [(62, 30), (60.0001, 0)],
        0,
        17,
        "G02",
        {"X": 60.0001, "Y": 0},
        {"X": 50, "Y": 0},
        [(62, 30)],
        None,
        True,
    ),
    (
        "circle inside touching it",
        [(62, 30), (61, 0)],
        0,
        17,
        "G02",
        {"X": 61, "Y": 0},
        {"X": 50.5, "Y": 0},
        [(62, 30)],
        912001,
        False,
    ),
    (
        "its quarter away from the touch",
        [(62, 30), (61, 0)],
        0,
        17,
        "G03",
        {"X": 50.5, "Y": 10.5},
        {"X": 50.5, "Y": 0},
        [(50.5, 30)],
        None,
        True,
    ),
    # about (53, 0), radius 13: inside tangent to the circle at (40, 0), the angle pi (the seam)
    (
        "over the seam onto the touch",
        [(41, 30), (41, 5)],
        0,
        17,
        "G03",
        {"X": 41, "Y": -5},
        {"X": 53, "Y": 0},
        [(30, -5), (30, 30)],
        912001,
        False,
    ),
    (
        "the long way round it",
        [(41, 30), (41, 5)],
        0,
        17,
        "G02",
        {"X": 41, "Y": -5},
        {"X": 53, "Y": 0},
        [(30, -5), (30, 30)],
        None,
        True,
    ),
    (
        "over the seam 0.8 µm off",
        [(41, 30), (41, 5)],
        0,
        17,
        "G03",
        {"X": 41, "Y": -5},
        {"X": 52.99, "Y": 0},
        [(30, -5), (30, 30)],
        None,
        True,
    ),
    (
        "over the seam 10 µm in",
        [(41, 30), (41, 5)],
        0,
        17,
        "G03",
        {"X": 41, "Y": -5},
        {"X": 53.0001, "Y": 0},
        [(30, -5), (30, 30)],
        912001,
        False,
    ),
    # the square's right edge x = -60
    (
        "whole circle tangent to the edge",
        [(-50, 30), (-50, 0)],
        0,
        17,
        "G02",
        {"X": -50, "Y": 0},
        {"X": -55, "Y": 0},
        [(-50, 30)],
        912001,
        False,
    ),
    (
        "whole circle 10 µm off the edge",
        [(-49.99, 30), (-49.99, 0)],
        0,
        17,
        "G02",
        {"X": -49.99, "Y": 0},
        {"X": -54.99, "Y": 0},
        [(-49.99, 30)],
        None,
        True,
    ),
    (
        "its half away from the edge",
        [(-50, 30), (-50, -5), (-55, -5)],
        0,
        17,
        "G03",
        {"X": -55, "Y": 5},
        {"X": -55, "Y": 0},
        [(-50, 5), (-50, 30)],
        None,
        True,
    ),
    # from (-58, 15) to (-58, -15): the chord 2 mm off the edge, the arc bulging onto it
    (
        "chord off, bulge on the edge",
        [(-58, 30), (-58, 15)],
        0,
        17,
        "G03",
        {"X": -58, "Y": -15},
        {"X": -2.75, "Y": 0},
        [(-50, -15), (-50, 30)],
        912001,
        False,
    ),
    (
        "chord off, bulge 9 µm off",
        [(-57.99, 30), (-57.99, 15)],
        0,
        17,
        "G03",
        {"X": -57.99, "Y": -15},
        {"X": -2.75, "Y": 0},
        [(-50, -15), (-50, 30)],
        None,
        True,
    ),
    # tiny arcs (radius 1 µm) 0.5 µm off the edge: the half away from it, the half onto it
    (
        "tiny arc off the edge",
        [(-59.9995, 30), (-59.9995, 4.999)],
        0,
        17,
        "G03",
        {"X": -59.9995, "Y": 5.001},
        {"X": -59.9995, "Y": 5},
        [(-59.9995, 30)],
        None,
        True,
    ),
    (
        "tiny arc into the square",
        [(-59.9995, 30), (-59.9995, 4.999)],
        0,
        17,
        "G02",
        {"X": -59.9995, "Y": 5.001},
        {"X": -59.9995, "Y": 5},
        [(-59.9995, 30)],
        912001,
        False,
    ),
    # the work area (+-200): a large arc whose whole circle leaves it, one whose sweep does
    (
        "large arc in the work area",
        [(120, 100)],
        0,
        17,
        "G03",
        {"X": -120, "Y": 100},
        {"X": 0, "Y": -250},
        [(0, 30)],
        None,
        True,
    ),
    (
        "large arc out of it",
        [(195, 150)],
        0,
        17,
        "G03",
        {"X": -195, "Y": 150},
        {"X": 0, "Y": -200},
        [(0, 30)],
        120486,
        False,
    ),
    # G18 beside the circle (y = 0, x = 60.5): a half circle up, bulging away (its whole circle reaches
    # into the circle) and the same towards it; a helix across the base plane (y moves: not a segment)
    (
        "G18 half circle away",
        [(62, 30), (60.5, 0)],
        -5,
        18,
        "G02",
        {"X": 60.5, "Z": 5},
        {"X": 60.5, "Z": 0},
        [(62, 30)],
        None,
        True,
    ),
    (
        "G18 half circle into it",
        [(62, 30), (60.5, 0)],
        -5,
        18,
        "G03",
        {"X": 60.5, "Z": 5},
        {"X": 60.5, "Z": 0},
        [(62, 30)],
        912001,
        False,
    ),
    (
        "G18 helix across the base",
        [(62, 30), (60.5, 0)],
        -5,
        18,
        "G02",
        {"X": 60.5, "Y": 1, "Z": 5},
        {"X": 60.5, "Z": 0},
        [(62, 30)],
        None,
        None,
    ),
    # G19 above the square (x = -70, y = 20.5)
    (
        "G19 half circle away",
        [(-70, 30), (-70, 20.5)],
        -5,
        19,
        "G03",
        {"Y": 20.5, "Z": 5},
        {"Y": 20.5, "Z": 0},
        [(-70, 30)],
        None,
        True,
    ),
    (
        "G19 half circle into it",
        [(-70, 30), (-70, 20.5)],
        -5,
        19,
        "G02",
        {"Y": 20.5, "Z": 5},
        {"Y": 20.5, "Z": 0},
        [(-70, 30)],
        912001,
        False,
    ),
]


@pytest.mark.req("C14-15")
@pytest.mark.parametrize("absolute", [False, True], ids=["G162", "G161"])
@pytest.mark.parametrize(
    ("approach", "z", "plane", "g", "end", "centre", "leave", "alarm", "cleared"),
    [case[1:] for case in _NEAR_ARCS],
    ids=[case[0] for case in _NEAR_ARCS],
)
def test_arcs_near_the_areas(
    config: MachineConfig,
    absolute: bool,
    approach: list[tuple[float, float]],
    z: float,
    plane: int,
    g: str,
    end: dict[str, float],
    centre: dict[str, float],
    leave: list[tuple[float, float]],
    alarm: int | None,
    cleared: bool | None,
) -> None:
    """Arcs tangent to circles and polygon edges, whole circles, tiny arcs, arcs over the +-180 degree
    seam, arcs whose chord keeps off but whose bulge does not, large arcs in a work area, G18/G19 arcs
    beside G17 areas, with relative and absolute centres: the batch reports what the exact path
    reports (the alarm on the arc's own line), and the prefilter clears the arc alone exactly where
    it keeps off (an alarm: never)."""
    start = {"X": approach[-1][0], "Y": approach[-1][1], "Z": float(z)}
    arc = _arc_text(g, start, end, centre, absolute)
    lines = [*_zigzag(200), "G01 X0 Y30", *(f"G01 X{_f(x)} Y{_f(y)}" for x, y in approach), f"G01 Z{_f(z)}"]
    lines += ["G161" if absolute else "G162", f"G{plane}", arc, "G17 G162", "G01 Z0"]
    lines += [f"G01 X{_f(x)} Y{_f(y)}" for x, y in [*leave, (0, 30)]] + [*_zigzag(200), "M30"]
    text = AREAS + "\n".join(lines) + "\n"
    result = assert_same(config, text)
    errors = [a for a in result.alarms if a.severity == Severity.ERROR]
    assert [a.number for a in errors] == ([alarm] if alarm else [])
    if alarm:
        assert errors[0].line == AREAS.count("\n") + lines.index(arc) + 1
    if cleared is not None:
        segment = _arc_segment(plane, g, start, end, centre)
        groups = _area_groups(config, AREAS)
        assert bool(clear_of_areas(groups, _path_batch([segment], segment.plane))[0]) is cleared
        if alarm:
            assert first_violation(groups, segment) is not None


def _prism(rng: random.Random, axes: tuple[int, int, int], protection: bool) -> Prism:
    a, b, c = axes
    if protection:
        cx, cy, size = rng.uniform(-60, 60), rng.uniform(-60, 60), rng.uniform(2, 25)
        lo, hi = rng.choice(((-100.0, 100.0), (-10.0, 10.0), (0.0, 50.0)))
    else:
        cx, cy, size = rng.uniform(-10, 10), rng.uniform(-10, 10), rng.uniform(50, 120)
        lo, hi = -100.0, 100.0
    if rng.random() < 0.35:
        region: Circle | Polygon = Circle(cx, cy, size)
    else:
        shape = rng.choice(
            (
                [(-1, -1), (1, -1), (1, 1), (-1, 1)],
                [(-1, 1), (1, 1), (1, -1), (-1, -1)],  # clockwise
                [(-1, -1), (1, -1), (1, 0), (0, 0), (0, 1), (-1, 1)],  # an L
                [(-1, -1), (1, -1), (0, 1)],
                [(math.cos(k * math.pi / 6), math.sin(k * math.pi / 6)) for k in range(12)],
            )
        )
        region = Polygon([(cx + size * x, cy + size * y) for x, y in shape])
    return Prism(region, a, b, c, lo, hi, protection=protection)


def _random_groups(rng: random.Random) -> list[Group]:
    """A group on X, Y, Z (its prisms mostly on one base plane, some turned or with swapped axes) and
    now and then one on Z, U, V (five axes: X Y Z U V)."""
    groups = []
    for orders in ([(0, 1, 2), (1, 0, 2), (2, 0, 1), (1, 2, 0)], [(3, 4, 2)]):
        if orders[0][0] == 3 and rng.random() < 0.5:
            continue
        usual = rng.choice(orders)

        def axes(
            orders: list[tuple[int, int, int]] = orders, usual: tuple[int, int, int] = usual
        ) -> tuple[int, int, int]:
            return usual if rng.random() < 0.85 else rng.choice(orders)

        works = [_prism(rng, axes(), False) for _ in range(rng.choice((0, 1, 2, 3)))]
        prots = [_prism(rng, axes(), True) for _ in range(rng.randint(0, 10))]
        groups.append(Group(frozenset(orders[0]), works, prots))
    return groups


def _random_paths(
    rng: random.Random, groups: list[Group], plane: tuple[int, int] | None, n: int
) -> list[Segment]:
    """A random walk of lines and arcs in ``plane`` (G17 or G18 and the like), now and then to an
    area's corner or a point of its circle, or just beside it (grazing)."""
    corners = [
        (q.a, q.b, x, y)
        for g in groups
        for q in g.works + g.prots
        for x, y in (
            q.region.points if isinstance(q.region, Polygon) else [(q.region.cx + q.region.r, q.region.cy)]
        )
    ]
    out: list[Segment] = []
    p = [rng.uniform(-50, 50) for _ in range(5)]
    for _ in range(n):
        start = tuple(p)
        end = [v + rng.uniform(-1, 1) * rng.choice((0.5, 5.0, 30.0)) for v in p]
        if rng.random() < 0.8:
            end[2] = p[2]
        if rng.random() < 0.1 and corners:
            a, b, x, y = rng.choice(corners)
            end[a], end[b] = x + rng.choice((0.0, 2e-5, -2e-5, 1e-3)), y + rng.choice((0.0, 2e-5, -1e-3))
        if plane is not None and rng.random() < 0.4:
            i, j = plane
            r = rng.uniform(0.5, 30.0)
            phi = rng.uniform(0.0, 2.0 * math.pi)
            cx, cy = start[i] - r * math.cos(phi), start[j] - r * math.sin(phi)
            sweep = rng.uniform(0.05, 2.0 * math.pi) * rng.choice((1, -1))
            end[i], end[j] = cx + r * math.cos(phi + sweep), cy + r * math.sin(phi + sweep)
            radius = math.hypot(start[i] - cx, start[j] - cy)
            a0 = math.atan2(start[j] - cy, start[i] - cx)
            out.append(ArcSegment(start, tuple(end), plane, (cx, cy), radius, a0, sweep))
        else:
            out.append(LineSegment(start, tuple(end)))
        p = end
    return out


def _path_batch(paths: list[Segment], plane: tuple[int, int] | None) -> PathBatch:
    """The paths as the batch hands them to the prefilter (an arc's box: its whole circle)."""
    start = np.array([s.start for s in paths]).T
    end = np.array([s.end for s in paths]).T
    lo, hi = np.minimum(start, end), np.maximum(start, end)
    n = len(paths)
    arc = np.array([isinstance(s, ArcSegment) for s in paths])
    centre, radius, a0, sweep = np.zeros((2, n)), np.zeros(n), np.zeros(n), np.full(n, 2.0 * math.pi)
    for k, s in enumerate(paths):
        if isinstance(s, ArcSegment):
            centre[:, k] = s.centre
            radius[k], a0[k], sweep[k] = s.radius, s.start_angle, s.sweep
            for axis, c in zip(s.plane, s.centre, strict=True):
                lo[axis, k], hi[axis, k] = min(lo[axis, k], c - s.radius), max(hi[axis, k], c + s.radius)
    return PathBatch(start, end, lo, hi, arc, plane, centre, radius, a0, sweep)


_ARC_PLANES = [None, (0, 1), (2, 0), (1, 2), (1, 0), (3, 4)]


@pytest.mark.req("C14-15")
@settings(max_examples=120, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), plane=st.sampled_from(_ARC_PLANES))
def test_the_prefilter_clears_only_paths_the_exact_check_passes(
    seed: int, plane: tuple[int, int] | None
) -> None:
    """All the areas of a group at once, in two groups: every path the prefilter clears has no
    violation in the exact check (lines, arcs in and across the prisms' base planes, grazing)."""
    rng = random.Random(seed)
    groups = _random_groups(rng)
    paths = _random_paths(rng, groups, plane, 200)
    clear = clear_of_areas(groups, _path_batch(paths, plane))
    for k in np.flatnonzero(clear).tolist():
        assert first_violation(groups, paths[k]) is None, (k, paths[k])
    event(f"cleared: {int(clear.sum()) // 50 * 25}%+")


def test_the_prefilter_clears_most_allowed_paths_of_random_groups() -> None:
    """... and the test above is not empty: most paths the exact check allows are cleared, arcs too."""
    allowed = cleared = arcs_cleared = 0
    for seed in range(20):
        rng = random.Random(seed)
        groups = _random_groups(rng)
        plane = _ARC_PLANES[seed % len(_ARC_PLANES)]
        paths = _random_paths(rng, groups, plane, 200)
        clear = clear_of_areas(groups, _path_batch(paths, plane))
        for k, path in enumerate(paths):
            if first_violation(groups, path) is None:
                allowed += 1
                cleared += bool(clear[k])
                arcs_cleared += bool(clear[k]) and isinstance(path, ArcSegment)
    assert cleared > 0.8 * allowed, (cleared, allowed)
    assert arcs_cleared > 100, arcs_cleared


def _near_arcs(rng: random.Random, groups: list[Group], plane: tuple[int, int], n: int) -> list[Segment]:
    """Arcs in ``plane`` placed on the areas' boundaries (issue 26): about a point at ``rho + delta``
    from a circle's centre or from a point of a polygon's edge along its normal (``delta`` 0 - a touch -,
    10 nm in or out, a little more, half a millimetre), with sweeps through the touching angle or
    away from it, whole circles, tiny radii (1 µm), large ones (up to 400 mm), sweeps over the +-180
    degree seam; for prisms that see the plane at an angle, arcs whose whole circle reaches into the
    prism while their sweep stays beside it. Each arc is reached by a line from the last point."""
    i, j = plane
    prisms = [q for g in groups for q in g.works + g.prots]
    out: list[Segment] = []
    if not prisms:
        return out
    p = [rng.uniform(-50, 50) for _ in range(5)]
    for _ in range(n):
        q = rng.choice(prisms)
        rho = rng.choice((1e-3, 0.5, 3.0, 20.0, rng.uniform(50.0, 400.0)))
        delta = rng.choice((0.0, 1e-5, -1e-5, 2e-5, 1e-3, -1e-3, 0.5))
        region = q.region
        if {q.a, q.b} == {i, j} or rng.random() < 0.5:
            # a point of the boundary and the outward direction there, in the prism's base plane
            if isinstance(region, Circle):
                t = rng.uniform(-math.pi, math.pi)
                ux, uy = math.cos(t), math.sin(t)
                bx, by = region.cx + region.r * ux, region.cy + region.r * uy
            else:
                pts = region.points
                k = rng.randrange(len(pts))
                (x0, y0), (x1, y1) = pts[k], pts[(k + 1) % len(pts)]
                f = rng.choice((0.0, 0.5, 1.0, rng.random()))
                bx, by = x0 + (x1 - x0) * f, y0 + (y1 - y0) * f
                length = math.hypot(x1 - x0, y1 - y0) or 1.0
                ux, uy = (y1 - y0) / length, -(x1 - x0) / length
                if rng.random() < 0.5:
                    ux, uy = -ux, -uy  # either side: the polygon may turn either way
            centre = [0.0] * 5
            centre[q.a], centre[q.b] = bx + ux * (rho + delta), by + uy * (rho + delta)
            centre[q.c] = p[q.c]
            touch = math.atan2(-uy, -ux) if q.a == i else math.atan2(-ux, -uy)
        else:
            # beside the prism along one of the plane's axes that is one of its base axes
            base = i if i in (q.a, q.b) else j
            x0, y0, x1, y1 = region.bbox
            lo_, hi_ = (x0, x1) if base == q.a else (y0, y1)
            centre = list(p)
            centre[base] = rng.choice((lo_ - rho - delta, hi_ + rho + delta, (lo_ + hi_) / 2.0))
            touch = rng.uniform(-math.pi, math.pi)
        cx, cy = centre[i], centre[j]
        kind = rng.random()
        if kind < 0.15:
            a0, sweep = rng.uniform(-math.pi, math.pi), rng.choice((2.0, -2.0)) * math.pi
        elif kind < 0.3:
            u = rng.uniform(0.0, 0.5)  # over the seam, either way
            a0, sweep = (math.pi - u, rng.uniform(u + 0.01, u + 1.5))
            if rng.random() < 0.5:
                a0, sweep = -a0, -sweep
        elif kind < 0.65:
            a0 = touch - rng.uniform(0.05, 1.0)  # through the touching angle
            sweep = rng.uniform(0.1, 2.5)
            if rng.random() < 0.5:
                a0, sweep = a0 + sweep, -sweep
        else:
            a0 = touch + rng.uniform(0.3, 2.0)  # beside it
            sweep = rng.choice((1, -1)) * rng.uniform(0.05, 2.0)
        start = list(p)
        start[i], start[j] = cx + rho * math.cos(a0), cy + rho * math.sin(a0)
        if rng.random() < 0.5:
            for k in range(5):
                if k not in (i, j):
                    start[k] = centre[k]
        out.append(LineSegment(tuple(p), tuple(start)))
        end = list(start)
        if abs(abs(sweep) - 2.0 * math.pi) > 1e-12:
            end[i], end[j] = cx + rho * math.cos(a0 + sweep), cy + rho * math.sin(a0 + sweep)
        if rng.random() < 0.2:
            k = rng.choice([k for k in range(5) if k not in (i, j)])
            end[k] += rng.choice((1e-3, 5.0))  # a helix
        a_start = math.atan2(start[j] - cy, start[i] - cx)
        out.append(ArcSegment(tuple(start), tuple(end), plane, (cx, cy), rho, a_start, sweep))
        p = end
    return out


@pytest.mark.req("C14-15")
@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), plane=st.sampled_from([(0, 1), (1, 0), (2, 0), (1, 2), (3, 4)]))
def test_the_prefilter_clears_only_arcs_the_exact_check_passes(seed: int, plane: tuple[int, int]) -> None:
    """Arcs on and beside the areas' boundaries (:func:`_near_arcs`): every arc the prefilter clears
    has no violation in the exact check."""
    rng = random.Random(seed)
    groups = _random_groups(rng)
    paths = _near_arcs(rng, groups, plane, 60)
    clear = clear_of_areas(groups, _path_batch(paths, plane))
    for k in np.flatnonzero(clear).tolist():
        assert first_violation(groups, paths[k]) is None, (k, paths[k])
    arcs = [k for k, s in enumerate(paths) if isinstance(s, ArcSegment)]
    event(f"arcs cleared: {int(clear[arcs].sum()) * 4 // max(len(arcs), 1) * 25}%+")


def test_the_prefilter_clears_most_arcs_beside_the_areas() -> None:
    """... and it is not empty: of the arcs the exact check passes, most are cleared - those in the
    prisms' base plane and those in a plane that sees them at an angle (G18 arcs beside G17 areas)."""
    for planes in ([(0, 1), (1, 0)], [(2, 0), (1, 2)]):
        allowed = cleared = 0
        for seed in range(30):
            rng = random.Random(seed)
            groups = [g for g in _random_groups(rng) if g.axes == frozenset((0, 1, 2))]
            for g in groups:  # every prism on X/Y, height Z
                for q in g.works + g.prots:
                    q.a, q.b, q.c = 0, 1, 2
            groups = [Group(g.axes, g.works, g.prots) for g in groups]
            plane = planes[seed % 2]
            paths = _near_arcs(rng, groups, plane, 60)
            clear = clear_of_areas(groups, _path_batch(paths, plane))
            for k, path in enumerate(paths):
                if isinstance(path, ArcSegment) and first_violation(groups, path) is None:
                    allowed += 1
                    cleared += bool(clear[k])
        assert cleared > 0.6 * allowed, (planes, cleared, allowed)


@pytest.mark.req("C14-15")
@pytest.mark.parametrize("shape", ["circle", "12-gon", "triangle", "square"])
def test_a_work_areas_core_disc_clears_only_paths_inside(shape: str) -> None:
    """A path whose box lies within the disc inscribed in a convex work area (or its circle), less
    MARGIN, is cleared without a region test. The disc touches the edges: short lines and arcs at its
    radius times 1 - 1e-9 .. 1 + 1e-6 and at the height band's ends graze the area; every cleared one
    passes the exact check, and those well inside the disc are cleared."""
    from hli_server.engine.areas import prefilter

    size, cx, cy = 80.0, 7.0, -3.0
    if shape == "circle":
        region: Circle | Polygon = Circle(cx, cy, size)
        touch = [k * math.pi / 8 for k in range(16)]
    else:
        corners = {
            "12-gon": [(math.cos(k * math.pi / 6), math.sin(k * math.pi / 6)) for k in range(12)],
            "triangle": [(-1.0, -1.0), (1.0, -1.0), (0.0, 1.0)],
            "square": [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)],  # clockwise
        }[shape]
        region = Polygon([(cx + size * x, cy + size * y) for x, y in corners])
        touch = [k * math.pi / 16 for k in range(32)]
    group = Group(frozenset((0, 1, 2)), [Prism(region, 0, 1, 2, -50.0, 50.0, protection=False)], [])
    core = prefilter._stacks(group).works
    ox, oy, radius = float(core.core_x[0, 0]), float(core.core_y[0, 0]), math.sqrt(float(core.core_r2[0, 0]))
    paths: list[Segment] = []
    deep: list[int] = []
    for phi in touch:
        ux, uy = math.cos(phi), math.sin(phi)
        for scale in (0.5, 1.0 - 1e-9, 1.0 + 1e-9, 1.0 + 1e-6):
            rho = radius * scale
            px, py = ox + rho * ux, oy + rho * uy
            for z0, z1 in ((0.0, 0.0), (-50.0 + 2e-5, 10.0), (0.0, 50.0 - 1e-7), (0.0, 50.0 + 1e-7)):
                if scale == 0.5 and z0 == 0.0 and z1 == 0.0:
                    deep.append(len(paths))
                paths.append(LineSegment((px - 5.0 * ux, py - 5.0 * uy, z0, 0, 0), (px, py, z1, 0, 0)))
        # an arc of radius 2 inside the disc that reaches its rim at phi
        r = 2.0 * (1.0 - 1e-9)
        centre = (ox + (radius - r) * ux, oy + (radius - r) * uy)
        start = (centre[0] - r * uy, centre[1] + r * ux, 0.0, 0, 0)
        end = (centre[0] + r * uy, centre[1] - r * ux, 0.0, 0, 0)
        a0 = math.atan2(start[1] - centre[1], start[0] - centre[0])
        paths.append(ArcSegment(start, end, (0, 1), centre, r, a0, -math.pi))
    batch = prefilter._swept_boxes(_path_batch(paths, (0, 1)))
    in_core = prefilter._in_cores(core, batch, np.ones(len(paths), np.bool_))
    clear = clear_of_areas([group], _path_batch(paths, (0, 1)))
    for k in np.flatnonzero(clear).tolist():
        assert first_violation([group], paths[k]) is None, (k, paths[k])
    assert in_core[deep].all()
    assert clear[deep].all()
    assert not in_core.all()  # the paths beyond the rim or the band are left to the region tests


# --- the tokenizer of plain lines against the parser ------------------------------------------------
_DECIMAL = st.tuples(st.floats(-300000, 300000, allow_nan=False), st.integers(0, 9))
_NUM = st.one_of(
    _DECIMAL.map(lambda t: f"{t[0]:.{t[1]}f}"),
    st.integers(-1000, 1000).map(str),
    st.sampled_from(
        ["0", "-0", "+5", ".5", "-.25", "5.", "007", "0000000000000001", "214748.3647", "214748.3648",
         "-214748.3647", "429496.7294", "429496.7295", "1.2.3", "--1", "+-1", "-", ".", "", "1e5",
         "123456789012345", "1234567890123456", "12345678.9012345", "6000000", "6000000.1", "9" * 17,
         "123456789", "123456789.5", "0.12345678", "0.123456789", "99999999", "100000000", "1.", "+.5",
         "0.00000001", "12345678901.2345", "-999999999"]
    ),
)  # fmt: skip
_WORD = st.tuples(st.sampled_from("NGFIJKXYZWMXYZXYZ"), st.sampled_from(["", "", "", " ", "="]), _NUM).map(
    lambda t: t[0] + t[1] + t[2]
)
_LINE = st.tuples(
    st.lists(_WORD, max_size=6),
    st.sampled_from([" ", " ", "  ", "\t", ""]),
    st.sampled_from(["", "", "", " ", "\t", "(c)", ";x", "#", "/", ":", "\xa0", "\x0b"]),
    st.booleans(),
).map(lambda t: (t[1].join(t[0]) + t[2]).lower() if t[3] else t[1].join(t[0]) + t[2])


@pytest.mark.req("E-04")
@settings(max_examples=400, deadline=None, derandomize=True)
@given(lines=st.lists(_LINE, min_size=1, max_size=8))
def test_a_plain_line_reads_as_the_parser_reads_it(lines: list[str]) -> None:
    tokenizer = PlainTokenizer(["X", "Y", "Z", "W"])
    chunk = tokenizer.tokenize(("\n".join(lines) + "\n").encode())
    assert chunk.lines == len(lines)
    for k, line in enumerate(lines):
        kind = int(chunk.kind[k])
        try:
            block = parse_line(line, 1, ["X", "Y", "Z", "W"])
        except NcError:
            assert kind != PLAIN, line
            continue
        if kind == EMPTY:
            assert block is None, line
        if kind != PLAIN:
            continue
        assert block is not None
        words = {
            tokenizer.letters[c]: float(chunk.values[c, k])
            for c in range(len(tokenizer.letters))
            if not np.isnan(chunk.values[c, k])
        }
        expected: dict[str, float] = dict(block.axes)
        expected.update(dict(block.centre))
        if block.feed is not None:
            expected["F"] = block.feed
        if block.number is not None:
            expected["N"] = float(block.number)
        if block.g_codes:
            (g,) = block.g_codes
            expected["G"] = float(g)
        assert block.m_codes == ()
        assert not block.extra
        assert block.area is None
        assert {k: (v, math.copysign(1.0, v)) for k, v in words.items()} == {
            k: (v, math.copysign(1.0, v)) for k, v in expected.items()
        }, line


@pytest.mark.req("E-04")
def test_the_lines_of_a_cam_program_are_plain() -> None:
    tokenizer = PlainTokenizer(["X", "Y", "Z"])
    lines = [
        "G01 X-227.6015 Y-136.6805",
        "G02 X1 Y2 I-12 J0",
        "N10 G0 Z5",
        "x1y2z3",
        "F6000",
        "G03X1.5Y.5I1J0F200",
        "   ",
    ]
    chunk = tokenizer.tokenize(("\n".join(lines) + "\n").encode())
    assert chunk.kind.tolist() == [PLAIN] * 6 + [EMPTY]
