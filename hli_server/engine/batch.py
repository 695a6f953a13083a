"""``check --geometry-only`` as a batch: plain motion lines decoded and checked many at a time
(docs/performance.md).

The exact geometry check decodes a program block by block (:meth:`Decoder.next_items`): parse the line,
update the modal state, build the segment, run every path check (soft limits, work and protection areas).
It stays the authority. This module gets the same result faster for the lines that make up nearly all
of a CAM program:

1. The channel's interpreter (:mod:`hli_server.engine.nc.interpreter`) runs the program, one statement
   at a time. Whenever it goes straight on in the main program (no subroutine, no open control block,
   nothing being skipped), the lines ahead of it are read a window of about a megabyte at a time and
   :class:`~hli_server.engine.nc.plain.PlainTokenizer` classifies them with numpy - *plain* (words N,
   G0..G3, F, I/J/K and one-letter axes), *empty*, or *other* - and reads the plain lines' numbers, bit for
   bit as the parser does.
2. Every *other* line (comments, ``#`` commands, control statements, variables, calls, M codes, G90/G91,
   ``X2=..``, anything unusual or wrong) goes to the interpreter, and what it gives to the decoder,
   exactly as in a run (but see 4.); so do plain lines inside loops and subroutines (the interpreter runs
   them), plain lines while an area is being defined, plain lines under G70 (inch) or G95 (feed per
   revolution), and short stretches of plain lines (fewer than :data:`SMALL_RUN` plus
   :data:`SMALL_RUN_PER_AREA` for each active area). A line with only a comment does not end a stretch.
3. A stretch of plain lines ahead of the interpreter is decoded at once: the modal motion and feed, the
   targets (G90 with the zero offset, G91 summed in program order: the same floats), the segments' boxes;
   then the blocks that might fail a check are picked, conservatively: a line shorter than 1 µm (the
   decoder may drop it), a move without feed, an arc without centre, with radius below 1 µm or ends off
   the circle by nearly the tolerance, a path within :data:`~hli_server.engine.areas.prefilter.MARGIN` of a
   soft limit, a path the area prefilter (:mod:`hli_server.engine.areas.prefilter`) cannot clear. Those
   blocks - and only those - are parsed and decoded exactly, in order, with the decoder's state set to
   what it is before them; every other block only moves the position, which is committed at the
   stretch's end. The interpreter then goes on after the stretch. While contouring is on (M-20..M-23,
   docs/nc-language.md "Contouring") every line is decoded exactly: the transitions are segments of
   their own.
4. The blocks the interpreter builds - in loops, subroutines and cycles (``G91 X[@P3 * V.P.DIR]``), or
   from an *other* line of the main program - that only move (G0..G3, G90/G91, axes, I/J/K, a positive F,
   an M17/M29; :meth:`_Rows.takes`) are kept, their end points computed as the decoder computes them,
   and checked as a stretch of plain lines is (3.) when the interpreter gives anything else (a block with
   other words, a directive, the end) or is back before plain lines of the main program. Before the
   interpreter does what others see or reads the decoder's state - a ``#MSG``, a warning, a V.E. write,
   V.A./V.G. (:attr:`Interpreter.before_effect`) - and before an error or the iteration cap is reported,
   the kept blocks are checked first; if one fails, the check ends there, before that statement, as the
   exact path would (``tests/unit/test_batch_language.py``).

An error stops at the same block with the same alarm, because the block that raises it is decoded
exactly; a block the batch clears cannot fail a check. ``tests/unit/test_batch_check.py`` and
``tests/unit/test_batch_language.py`` hold the batch to the exact path on random programs (same alarms,
points, line and block numbers, messages, final position).

The batch runs only where it knows every path check of the channel (soft limits, areas, the collision
check while no pair is latched); with any other check installed (a user's monitor), ``check`` decodes
block by block (:func:`unsupported`).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Iterator
from typing import TextIO

import numpy as np
import numpy.typing as npt

from hli_server.engine.areas.geometry import Group
from hli_server.engine.areas.path_check import AreaPathCheck
from hli_server.engine.areas.prefilter import MARGIN, PathBatch, clear_of_areas, cut_into_chords
from hli_server.engine.channel import Channel
from hli_server.engine.decoder import Decoder, PathCheck
from hli_server.engine.monitors.collision import MoveApartCheck
from hli_server.engine.monitors.soft_limits import SoftLimitPathCheck
from hli_server.engine.nc.blocks import Block, NcError
from hli_server.engine.nc.directives import PAUSE
from hli_server.engine.nc.language import CORNER_AHEAD
from hli_server.engine.nc.parser import BlockReader
from hli_server.engine.nc.plain import COL_F, COL_G, COL_I, EMPTY, OTHER, PLAIN, PlainChunk, PlainTokenizer
from hli_server.engine.nc.reader import strip_comments
from hli_server.engine.nc.source import LineTooLongError, ProgramText, Window
from hli_server.engine.planner import Marker, Motion

__all__ = ["SMALL_RUN", "SMALL_RUN_PER_AREA", "BatchGeometryCheck", "unsupported"]

SMALL_RUN = 26
"""Fewer plain lines than this between two other lines are decoded one by one: numpy's set-up per
stretch would cost more than it saves (the measurements behind the number: docs/performance.md, "Batch
thresholds")."""
SMALL_RUN_PER_AREA = 1
"""... and this many more for each active area: the area prefilter tests all areas of a group in a few
numpy passes, so its set-up per stretch hardly grows with their number (docs/performance.md, "Batch
thresholds")."""

STEP_STATEMENTS = 4096
"""Statements the interpreter runs for the batch before it hands back (progress), where it runs on."""
ROWS_KEPT = 40_000
"""The most blocks of loops and subroutines kept before they are checked (memory stays flat under a loop
that only moves: about a window of plain lines)."""

_TAU = 2.0 * math.pi
_PLANE_AXES = {17: (0, 1), 18: (2, 0), 19: (1, 2)}
"""As the decoder's: indices into the main axes of the plane's first and second axis."""
_NO_LINES: Iterator[str] = iter(())

Floats = npt.NDArray[np.float64]
Ints = npt.NDArray[np.int64]
Bools = npt.NDArray[np.bool_]
Item = Motion | Marker


def unsupported(channel: Channel) -> str | None:
    """Why the batch cannot check this channel's programs (a path check it does not know), or None."""
    for check in channel.decoder.path_checks:
        if not isinstance(check, SoftLimitPathCheck | MoveApartCheck) and _area_check(check) is None:
            name = getattr(check, "__qualname__", type(check).__name__)
            return f"path check {name} is not known to the batch check"
    return None


def _area_check(check: PathCheck) -> AreaPathCheck | None:
    """The area check whose bound method ``check`` is (the hook the area monitor installs), or None."""
    owner = getattr(check, "__self__", None)
    return owner if isinstance(owner, AreaPathCheck) else None


class _Chunk:
    """One window of whole lines: their kinds and words, the lines themselves, the *other* lines."""

    __slots__ = ("first_line", "others", "plain", "window")

    def __init__(self, window: Window, plain: PlainChunk, first_line: int) -> None:
        self.window = window
        self.plain = plain
        self.first_line = first_line
        """Line number of the chunk's first line."""
        self.others: list[int] = np.flatnonzero(plain.kind == OTHER).tolist()

    @property
    def lines(self) -> int:
        return self.plain.lines

    def raw(self, k: int) -> str:
        """Line ``k`` as the parser is given it."""
        return self.window.line(k)


class _StoppedError(Exception):
    """A kept block failed its check while the interpreter was in the middle of a statement: the check
    ends there, as the exact path would have ended before the statement."""


_ROW_G_CODES = frozenset((0, 1, 2, 3, 90, 91))
_CORNER_G_CODES = frozenset((301, 302))
"""Chamfers and roundings: the motion before them is held back for the corner (the exact decoder's)."""
_ROW_M_CODES = frozenset((17, 29))


class _Rows:
    """Blocks built by the interpreter that only move (a loop's or a subroutine's ``G91 X[..] Y[..]``),
    kept to be checked as a batch: per block its end point (as :meth:`Decoder._target` computes it, the
    same floats), the modal motion, feed and G90/G91 after it, whether an axis is given, its I/J/K.
    Everything is computed from the decoder's state when the first block is kept; nothing else can
    change that state before they are flushed (any other block or directive flushes them first)."""

    __slots__ = (
        "_abs",
        "_feed",
        "_motion",
        "_position",
        "absolute",
        "blocks",
        "centre",
        "decoder",
        "ends",
        "feed",
        "motion",
        "offsets",
        "origin",
        "present",
    )

    def __init__(self, decoder: Decoder) -> None:
        self.decoder = decoder
        self.blocks: list[Block] = []
        self.ends: list[list[float]] = []
        self.motion: list[float] = []
        self.feed: list[float] = []
        self.absolute: list[bool] = []
        self.present: list[bool] = []
        self.centre: list[tuple[float, float, float]] = []
        self.origin: list[float] = []
        self.offsets: dict[str, float] = {}
        self._position: list[float] = []
        self._motion = 0
        self._feed = math.nan
        self._abs = True

    def clear(self) -> None:
        self.blocks = []
        self.ends = []
        self.motion = []
        self.feed = []
        self.absolute = []
        self.present = []
        self.centre = []

    def takes(self, block: Block) -> bool:
        """Does ``block`` only move (G0..G3, G90/G91, axes, I/J/K, a positive F, an M17/M29 that ends a
        subroutine), so that the batch can check it?"""
        if block.extra or block.area is not None or block.two_path:
            return False
        for g in block.g_codes:
            if g not in _ROW_G_CODES:
                return False
        for m in block.m_codes:
            if m not in _ROW_M_CODES:
                return False
        feed = block.feed
        if feed is not None and not feed > 0.0:
            return False
        index = self.decoder.index
        for name, _ in block.axes:  # noqa: SIM110 (a loop: cheaper than all() over a generator)
            if name not in index:
                return False
        return True

    def add(self, block: Block, decoder: Decoder) -> None:
        """Keep ``block``: its row, from the state after the blocks kept before it."""
        if not self.blocks:
            modal = decoder.modal
            self.origin = list(decoder.position)
            self._position = self.origin
            self._motion = modal.motion
            self._feed = modal.feed if modal.feed is not None else math.nan
            self._abs = modal.absolute
            self.offsets = {}
        for g in block.g_codes:
            if g <= 3:
                self._motion = g
            elif g == 90:
                self._abs = True
            else:
                self._abs = False
        if block.feed is not None:
            self._feed = block.feed
        target = list(self._position)
        if block.axes:
            index = decoder.index
            absolute = self._abs
            for name, value in block.axes:
                i = index[name]
                if absolute:
                    offset = self.offsets.get(name)
                    if offset is None:
                        offset = decoder.modal.offset(name)
                        self.offsets[name] = offset
                    target[i] = value + offset
                else:
                    target[i] += value
        self._position = target
        self.blocks.append(block)
        self.ends.append(target)
        self.motion.append(float(self._motion))
        self.feed.append(self._feed)
        self.absolute.append(self._abs)
        self.present.append(bool(block.axes))
        ci = cj = ck = math.nan
        for letter, value in block.centre:
            if letter == "I":
                ci = value
            elif letter == "J":
                cj = value
            elif letter == "K":
                ck = value
        self.centre.append((ci, cj, ck))


class BatchGeometryCheck:
    """Decodes a program for ``check --geometry-only`` on ``channel`` (see the module's description).

    The channel's interpreter runs the program; while it goes straight on in the main program
    (:attr:`Interpreter.at_main_level`), the plain lines ahead of it are decoded here, many at a time,
    and the blocks it builds that only move are kept and checked many at a time too. :meth:`items`
    yields what the exact decoder would have yielded (motions, markers,
    errors), in program order, and an empty list now and then (progress); the caller handles them as it
    handles :meth:`Decoder.next_items` (running action markers at once). :attr:`line` is the main
    program's line reached."""

    def __init__(self, channel: Channel) -> None:
        why = unsupported(channel)
        if why is not None:
            raise ValueError(f"batch geometry check: {why}")
        self.channel = channel
        self.decoder: Decoder = channel.decoder
        decoder = self.decoder
        self._reader = BlockReader(channel.axis_names)
        single = channel.compiler.single_letter_axes
        letters = [name.upper() for name in decoder.axes if name.upper() in single]
        self._tokenizer = PlainTokenizer(letters)
        column = {letter: 6 + k for k, letter in enumerate(letters)}
        self._axis_column: list[int] = [column.get(name.upper(), -1) for name in decoder.axes]
        self._chunk: _Chunk | None = None
        self._source: ProgramText | None = None
        self._rows = _Rows(decoder)
        """Blocks the interpreter built in loops and subroutines, kept to be checked as a batch."""
        self._outbox: list[list[Item]] = []
        """What the decoder gave for kept blocks flushed in the middle of a statement (yielded next)."""
        self.line = 0
        self.batched_blocks = 0
        """Blocks the batch decoded without the exact decoder (for the tests and the benchmark)."""
        self.exact_blocks = 0

    # --- the program -----------------------------------------------------------------------------
    def items(
        self, text: str | TextIO | ProgramText, *, iteration_cap: int | None = None
    ) -> Iterator[list[Item]]:
        decoder = self.decoder
        interpreter = self.channel.interpreter
        source = text if isinstance(text, ProgramText) else ProgramText(text, self.channel.program_name)
        interpreter.start(source, source.name)
        decoder.start(interpreter, self.channel.setpoints())
        saved = (interpreter.budget, interpreter.iteration_cap)
        interpreter.budget = 1  # one statement at a time: back here whenever it goes straight on (the
        # kept blocks' loop in _step lifts it while it runs)
        interpreter.iteration_cap = iteration_cap
        self._chunk = None
        self._source = source
        self._rows.clear()
        interpreter.before_effect = self._before_effect
        try:
            while not self._finished():
                if interpreter.at_main_level:
                    line = interpreter.main_line
                    chunk = self._chunk_at(source, line)
                    if chunk is not None:
                        i = line - chunk.first_line
                        at = bisect.bisect_left(chunk.others, i)
                        o = chunk.others[at] if at < len(chunk.others) else chunk.lines
                        if o > i:
                            if self._rows.blocks:
                                yield from self._flush_rows()
                                continue
                            yield from self._plain_lines(chunk, i, o)
                            if self._finished():
                                return
                            interpreter.advance_to(chunk.first_line + o)
                            self.line = chunk.first_line + o
                            if o >= chunk.lines:
                                yield []
                            continue
                yield from self._step()
                self.line = interpreter.main_line
        finally:
            interpreter.before_effect = None
            interpreter.budget, interpreter.iteration_cap = saved
            self._rows.clear()
            self._outbox.clear()

    # --- what the interpreter runs: blocks of loops and subroutines ------------------------------------
    def _step(self) -> Iterator[list[Item]]:
        """Statements of the interpreter up to its next block or directive that is not kept, or until it is
        back in the main program. A block it builds that only moves (:meth:`_Rows.takes`) is kept in
        :attr:`_rows` and checked with the next ones as a batch; anything else first flushes them, then
        goes to the decoder as :meth:`Decoder.next_items` would hand it."""
        decoder = self.decoder
        interpreter = self.channel.interpreter
        rows = self._rows
        if decoder.waiting or not self._rows_allowed():
            interpreter.refill()
            if rows.blocks:
                yield from self._flush_rows()
                return
            if not decoder.waiting:
                self.exact_blocks += 1
            yield decoder.next_items()
            return
        # no pause after each statement here: the interpreter returns at its next block or directive, or
        # after STEP_STATEMENTS statements (the caller's progress goes on under a loop that only computes)
        interpreter.budget = STEP_STATEMENTS
        interpreter.refill()
        try:
            while True:
                try:
                    out = interpreter.next()
                except _StoppedError:
                    yield from self._drain()
                    return
                except NcError as exc:
                    yield from self._drain()
                    yield from self._flush_rows()
                    if not decoder.finished:
                        yield decoder.syntax_error(exc)
                    return
                except Exception:
                    # the iteration cap: the blocks before it are checked first (one may fail)
                    yield from self._drain()
                    yield from self._flush_rows()
                    if decoder.finished:
                        return
                    raise
                if self._outbox:
                    yield from self._drain()
                if out is PAUSE:
                    yield []
                    return
                if isinstance(out, Block) and rows.takes(out):
                    rows.add(out, decoder)
                    if interpreter.at_main_level:
                        return
                    if len(rows.blocks) >= ROWS_KEPT:
                        yield from self._flush_rows()
                        if decoder.finished:
                            return
                    continue
                break
        finally:
            interpreter.budget = 1
        if rows.blocks:
            corner = isinstance(out, Block) and not _CORNER_G_CODES.isdisjoint(out.g_codes)
            yield from self._flush_rows(exact_last=corner)
            if decoder.finished:
                return
        if out is None:
            yield decoder.end_of_program()
        elif isinstance(out, Block):
            self.exact_blocks += 1
            yield decoder.decode_block(out)
        else:
            yield decoder.directive(out)

    def _rows_allowed(self) -> bool:
        """May blocks be kept for a batch: the decoder's state is one the batch knows (as for plain lines:
        no contouring, no area being defined, no G70/G95, no frame, tool or compensation)."""
        decoder = self.decoder
        modal = decoder.modal
        return not (
            decoder.contour.holding
            or modal.blend(()) is not None
            or modal.in_area_definition
            or modal.inch
            or modal.feed_per_rev
            or decoder.transforms_active
        )

    def _drain(self) -> Iterator[list[Item]]:
        outbox = self._outbox
        while outbox:
            yield outbox.pop(0)

    def _before_effect(self) -> None:
        """The interpreter is about to do what others see or to read the decoder's state (a message, a
        warning, a V.E. write, V.A./V.G.): the kept blocks are decoded first, as the exact path would have;
        if one of them fails, the statement does not run (:class:`_StoppedError`)."""
        if not self._rows.blocks:
            return
        self._outbox.extend(self._flush_rows())
        if self.decoder.finished:
            raise _StoppedError

    def _flush_rows(self, exact_last: bool = False) -> Iterator[list[Item]]:
        """The kept blocks: one by one if few, else as a batch; ``exact_last``: the last one through the exact
        decoder in any case (a G301/G302 follows it: its motion is held back for the corner)."""
        rows = self._rows
        if exact_last and rows.blocks:
            last = rows.blocks[-1]
            rows.blocks.pop()
            rows.ends.pop()
            rows.motion.pop()
            rows.feed.pop()
            rows.absolute.pop()
            rows.present.pop()
            rows.centre.pop()
            yield from self._flush_rows()
            if not self.decoder.finished:
                self.exact_blocks += 1
                yield self.decoder.decode_block(last)
            return
        blocks = rows.blocks
        count = len(blocks)
        if not count:
            return
        decoder = self.decoder
        groups, all_exact = self._checks()
        areas = sum(len(g.works) + len(g.prots) for g in groups)
        if count < SMALL_RUN + SMALL_RUN_PER_AREA * areas or all_exact:
            kept = list(blocks)
            rows.clear()
            for block in kept:
                self.exact_blocks += 1
                yield decoder.decode_block(block)
                if decoder.finished:
                    return
            return
        n_axes = len(decoder.axes)
        start = np.empty((n_axes, count))
        start[:, 0] = rows.origin
        end = np.array(rows.ends).T.reshape(n_axes, count)
        start[:, 1:] = end[:, :-1]
        motion = np.array(rows.motion, np.float64)
        feed = np.array(rows.feed, np.float64)
        present = np.array(rows.present, np.bool_)
        centre = np.array(rows.centre, np.float64).T.reshape(3, count)
        absolute = rows.absolute[:]
        kept = list(blocks)
        rows.clear()
        yield from self._settle(
            start, end, present, motion, feed, centre, groups, False, kept.__getitem__, None, absolute
        )
        if not decoder.finished:
            decoder.current_block = kept[-1]
            decoder.motion_unheld = True

    def _finished(self) -> bool:
        return self.decoder.finished

    def _chunk_at(self, source: ProgramText, line: int) -> _Chunk | None:
        """The chunk of lines holding ``line`` (None past the end of the text)."""
        chunk = self._chunk
        if chunk is not None and chunk.first_line <= line < chunk.first_line + chunk.lines:
            return chunk
        window = source.window_of(line)
        if window is None or not window.count:
            return None
        # the window's own bytes and line ends: no decoding, splitting or encoding again here
        plain = self._tokenizer.tokenize(window.data, window.ends)
        for long_line in window.long_lines:
            plain.kind[long_line - window.first] = OTHER  # the interpreter refuses it (LineTooLongError)
        chunk = _Chunk(window, plain, window.first)
        self._comments_as_blank(chunk)
        self._chunk = chunk
        return chunk

    def _comments_as_blank(self, chunk: _Chunk) -> None:
        """A line with only a comment gives no block: it does not end a stretch of plain lines (a CAM
        program's comments would otherwise cut it into stretches too short to batch)."""
        kept: list[int] = []
        for k in chunk.others:
            raw = chunk.raw(k)
            if raw.lstrip()[:1] in ("(", ";") and not strip_comments(raw).strip():
                chunk.plain.kind[k] = EMPTY
                continue
            kept.append(k)
        chunk.others = kept

    def _exact(self, chunk: _Chunk, k: int) -> Block:
        block, _ = self._reader.read(chunk.raw(k), chunk.first_line + k, _NO_LINES)
        assert block is not None  # a plain line always has a word
        return block

    # --- plain lines -------------------------------------------------------------------------------
    def _plain_lines(self, chunk: _Chunk, i: int, o: int) -> Iterator[list[Item]]:
        """Lines ``i`` to ``o`` (exclusive) of the chunk: plain or empty. Where the line after them asks for
        a chamfer or rounding (G301/G302), the last of them goes to the exact decoder: its motion is held
        back for the corner (docs/nc-language.md, "Chamfers and roundings")."""
        idx = i + np.flatnonzero(chunk.plain.kind[i:o] == PLAIN)
        after = chunk.raw(o) if o < chunk.lines else self._source_line(chunk.first_line + o)
        if idx.shape[0] and _corner_line(after):
            yield from self._plain_run(chunk, idx[:-1])
            if self.decoder.finished:
                return
            k = int(idx[-1])
            self.line = chunk.first_line + k
            self.exact_blocks += 1
            yield self.decoder.decode_block(self._exact(chunk, k))
            return
        yield from self._plain_run(chunk, idx)

    def _source_line(self, line: int) -> str:
        """The program's line ``line`` ("" past its end or where it cannot be read)."""
        source = self._source
        if source is None:
            return ""
        try:
            return source.line(line) or ""
        except LineTooLongError:
            return ""

    def _plain_run(self, chunk: _Chunk, idx: Ints) -> Iterator[list[Item]]:
        """The plain lines ``idx`` of the chunk, batched where they may be."""
        count = int(idx.shape[0])
        if count == 0:
            return
        decoder = self.decoder
        groups, all_exact = self._checks()
        areas = sum(len(g.works) + len(g.prots) for g in groups)
        # with contouring on (or a corner held for it) every block goes through the contouring stage: the
        # transitions are new segments the batch does not know (a plain line cannot switch it: G61,
        # G260, G261, #CONTOUR MODE ... are not plain)
        contouring = decoder.contour.holding or decoder.modal.blend(()) is not None
        short = count < SMALL_RUN + SMALL_RUN_PER_AREA * areas and not self._chords(chunk, idx, groups)
        modal = decoder.modal
        # G70 (inch) and G95 (feed per revolution, M-06/M-07), and #CS/#ROTATION/tool compensation
        # (transforms_active): the exact decoder scales, transforms and checks them
        if (
            contouring
            or modal.in_area_definition
            or short
            or modal.inch
            or modal.feed_per_rev
            or decoder.transforms_active
        ):
            for k in idx.tolist():
                self.line = chunk.first_line + k
                self.exact_blocks += 1
                yield decoder.decode_block(self._exact(chunk, k))
                if decoder.finished:
                    return
            return
        yield from self._batch(chunk, idx, groups, all_exact)
        decoder.motion_unheld = True  # a G301/G302 after these comes too late (the exact decoder's rule)

    def _chords(self, chunk: _Chunk, idx: Ints, groups: list[Group]) -> bool:
        """Has the stretch arcs that the exact check cuts into chords (a G18 arc among G17 areas)? Each
        costs it hundreds of chords: a short stretch with one is batched all the same."""
        plane = self._plane()
        if plane is None or not cut_into_chords(groups, plane):
            return False
        motion = _fill(chunk.plain.values[COL_G, idx], float(self.decoder.modal.motion))
        return bool((motion >= 2.0).any())

    def _batch(self, chunk: _Chunk, idx: Ints, groups: list[Group], all_exact: bool) -> Iterator[list[Item]]:
        decoder = self.decoder
        modal = decoder.modal
        count = int(idx.shape[0])
        values = chunk.plain.values[:, idx]
        with np.errstate(all="ignore"):
            motion = _fill(values[COL_G], float(modal.motion))
            feed = _fill(values[COL_F], modal.feed if modal.feed is not None else math.nan)
            start, end, present = self._targets(values, count)
        first_line = chunk.first_line

        def exact_block(k: int) -> Block:
            return self._exact(chunk, int(idx[k]))

        def line_of(k: int) -> int:
            return first_line + int(idx[k])

        yield from self._settle(
            start,
            end,
            present,
            motion,
            feed,
            values[COL_I : COL_I + 3],
            groups,
            all_exact,
            exact_block,
            line_of,
            None,
        )
        if decoder.finished:
            return
        self.line = first_line + int(idx[count - 1])

    def _settle(
        self,
        start: Floats,
        end: Floats,
        present: Bools,
        motion: Floats,
        feed: Floats,
        centre_words: Floats,
        groups: list[Group],
        all_exact: bool,
        exact_block: Callable[[int], Block],
        line_of: Callable[[int], int] | None,
        absolute: list[bool] | None,
    ) -> Iterator[list[Item]]:
        """Checks ``count`` blocks at once (rows: start and end points, whether an axis is given, the
        modal motion and feed after each, the I/J/K words): the blocks that might fail go to the exact
        decoder (``exact_block(k)`` is block ``k``; ``line_of(k)`` its main program line, None: leave
        :attr:`line` alone), with the decoder's state set to what it is before them; the others only
        move the position. ``absolute``: G90 (True) or G91 after each block, where blocks change it."""
        decoder = self.decoder
        modal = decoder.modal
        count = int(motion.shape[0])
        with np.errstate(all="ignore"):
            arc = motion >= 2.0
            centre_given = ~np.isnan(centre_words).all(axis=0)
            moving = present | (arc & centre_given)
            arc &= moving
            # blocks the exact decoder must see: no feed, too short to be sure it is a move
            exact = moving & (motion != 0.0) & np.isnan(feed)
            d = end - start
            exact |= moving & ~arc & ((d * d).sum(axis=0) < 1e-12)
            lo = np.minimum(start, end)
            hi = np.maximum(start, end)
            arcs = self._arcs(centre_words, motion, start, end, arc, exact, lo, hi)
            exact |= self._outside_limits(lo, hi) & moving
            if all_exact:
                exact |= moving
            sel = np.flatnonzero(moving & ~exact)
            if groups and sel.shape[0]:
                centre, radius, a0, sweep = arcs
                paths = PathBatch(
                    start[:, sel],
                    end[:, sel],
                    lo[:, sel],
                    hi[:, sel],
                    arc[sel],
                    self._plane(),
                    centre[:, sel],
                    radius[sel],
                    a0[sel],
                    sweep[sel],
                )
                exact[sel[~clear_of_areas(groups, paths)]] = True
        flagged: list[int] = np.flatnonzero(exact).tolist()
        last = -1
        for k in flagged:
            decoder.blocks_decoded += k - last - 1
            self.batched_blocks += k - last - 1
            decoder.position = start[:, k].tolist()
            if k > 0:
                modal.motion = int(motion[k - 1])
                before = float(feed[k - 1])
                modal.feed = None if math.isnan(before) else before
                if absolute is not None:
                    modal.absolute = absolute[k - 1]
            if line_of is not None:
                self.line = line_of(k)
            self.exact_blocks += 1
            items = decoder.decode_block(exact_block(k))
            if not decoder.finished and (
                decoder.position != end[:, k].tolist()
                or modal.motion != int(motion[k])
                or (absolute is not None and modal.absolute != absolute[k])
            ):
                raise RuntimeError(
                    f"batch geometry check out of step with the decoder at line {self.line}: "
                    f"{decoder.position} != {end[:, k].tolist()} (a bug; HLI_BATCH_CHECK=0 checks block by "
                    "block)"
                )
            yield items
            if decoder.finished:
                return
            last = k
        decoder.blocks_decoded += count - 1 - last
        self.batched_blocks += count - 1 - last
        decoder.position = end[:, count - 1].tolist()
        modal.motion = int(motion[count - 1])
        final_feed = float(feed[count - 1])
        modal.feed = None if math.isnan(final_feed) else final_feed
        if absolute is not None:
            modal.absolute = absolute[count - 1]
        arcs_at = np.flatnonzero(arc)
        if arcs_at.shape[0] and int(arcs_at[-1]) > last:
            # V.G.I/J/K read the last circle's centre words, as the decoder keeps them
            words = centre_words[:, int(arcs_at[-1])].tolist()
            decoder.last_centre = {c: v for c, v in zip("IJK", words, strict=True) if not math.isnan(v)}
        if last != count - 1 and line_of is not None:
            decoder.current_block = exact_block(count - 1)

    def _targets(self, values: Floats, count: int) -> tuple[Floats, Floats, Bools]:
        """Start and end points (one row per channel axis) and whether any axis word is given."""
        decoder = self.decoder
        modal = decoder.modal
        n_axes = len(decoder.axes)
        start = np.empty((n_axes, count))
        end = np.empty((n_axes, count))
        present = np.zeros(count, np.bool_)
        for k, name in enumerate(decoder.axes):
            p0 = decoder.position[k]
            col = self._axis_column[k]
            if col < 0:
                end[k] = p0
            else:
                v = values[col]
                given = ~np.isnan(v)
                present |= given
                if modal.absolute:
                    end[k] = _fill(v + modal.offset(name), p0)
                else:
                    # the decoder adds word by word: a running sum in program order; -0.0 adds nothing
                    steps = np.empty(count + 1)
                    steps[0] = p0
                    steps[1:] = np.where(given, v, -0.0)
                    end[k] = np.cumsum(steps)[1:]
            start[k, 0] = p0
            start[k, 1:] = end[k, :-1]
        return start, end, present

    def _plane(self) -> tuple[int, int] | None:
        """Channel indices of the arcs' plane axes (None if the channel lacks one of them)."""
        decoder = self.decoder
        first, second = _PLANE_AXES[decoder.modal.plane]
        i = decoder.index.get(decoder.main[first])
        j = decoder.index.get(decoder.main[second])
        return (i, j) if i is not None and j is not None else None

    def _arcs(
        self,
        centre_words: Floats,
        motion: Floats,
        start: Floats,
        end: Floats,
        arc: Bools,
        exact: Bools,
        lo: Floats,
        hi: Floats,
    ) -> tuple[Floats, Floats, Floats, Floats]:
        """Centre, radius, start angle and sweep of the arcs (the prefilter's); marks the arcs the exact
        decoder must see in ``exact`` and widens ``lo``/``hi`` to each arc's whole circle."""
        count = motion.shape[0]
        centre = np.zeros((2, count))
        radius = np.zeros(count)
        a0 = np.zeros(count)
        sweep = np.full(count, _TAU)
        if not arc.any():
            return centre, radius, a0, sweep
        plane = self._plane()
        if plane is None:
            exact |= arc
            return centre, radius, a0, sweep
        decoder = self.decoder
        modal = decoder.modal
        first, second = _PLANE_AXES[modal.plane]
        i, j = plane
        wi, wj = centre_words[first], centre_words[second]
        given = ~np.isnan(wi) | ~np.isnan(wj)
        exact |= arc & ~given
        ci = np.where(np.isnan(wi), 0.0, wi)
        cj = np.where(np.isnan(wj), 0.0, wj)
        if modal.centre_absolute:
            cx = ci + modal.offset(decoder.main[first])
            cy = cj + modal.offset(decoder.main[second])
        else:
            cx = start[i] + ci
            cy = start[j] + cj
        r0 = np.hypot(start[i] - cx, start[j] - cy)
        r1 = np.hypot(end[i] - cx, end[j] - cy)
        # the decoder refuses radius 0 and ends off the circle by more than 0.01 mm: let it decide
        exact |= arc & ((r0 < 1e-6) | (np.abs(r1 - r0) > 0.01 - 1e-6))
        reach = np.maximum(r0, r1)
        lo[i] = np.where(arc, np.minimum(lo[i], cx - reach), lo[i])
        hi[i] = np.where(arc, np.maximum(hi[i], cx + reach), hi[i])
        lo[j] = np.where(arc, np.minimum(lo[j], cy - reach), lo[j])
        hi[j] = np.where(arc, np.maximum(hi[j], cy + reach), hi[j])
        b0 = np.arctan2(start[j] - cy, start[i] - cx)
        b1 = np.arctan2(end[j] - cy, end[i] - cx)
        cw = motion == 2.0
        turn = np.where(cw, -((b0 - b1) % _TAU), (b1 - b0) % _TAU)
        span = np.abs(end[i] - start[i]) + np.abs(end[j] - start[j])
        scale = 1.0 + np.abs(start[i]) + np.abs(start[j])
        unsure = (np.abs(turn) < 1e-6) | (np.abs(turn) > _TAU - 1e-6) | (span <= 1e-6 * scale)
        turn = np.where(unsure, np.where(cw, -_TAU, _TAU), turn)
        centre[0] = cx
        centre[1] = cy
        return centre, r0, b0, turn

    def _outside_limits(self, lo: Floats, hi: Floats) -> Bools:
        """Paths whose box comes within MARGIN of a software limit (the exact check decides)."""
        near = np.zeros(lo.shape[1], np.bool_)
        for check in self.decoder.path_checks:
            if isinstance(check, SoftLimitPathCheck):
                for k, axis in enumerate(check.channel.axes):
                    near |= (lo[k] < axis.swe_neg + MARGIN) | (hi[k] > axis.swe_pos - MARGIN)
        return near

    def _checks(self) -> tuple[list[Group], bool]:
        """The active area groups of the channel's area checks (planned table), and whether every
        block must be checked exactly (a collision pair latched: its check is not batched)."""
        groups: list[Group] = []
        all_exact = False
        for check in self.decoder.path_checks:
            areas = _area_check(check)
            if areas is not None:
                groups.extend(areas.planned.groups())
            elif isinstance(check, MoveApartCheck):
                all_exact = all_exact or bool(check.monitor.latched_pairs(check.channel))
        return groups, all_exact


def _corner_line(raw: str) -> bool:
    """Does the line ask for a chamfer or rounding (G301/G302)?"""
    return "30" in raw and CORNER_AHEAD.search(strip_comments(raw).upper()) is not None


def _fill(values: Floats, initial: float) -> Floats:
    """Each value, or the last one given before it (NaN: not given), or ``initial`` (a modal word)."""
    given = ~np.isnan(values)
    at = np.where(given, np.arange(values.shape[0]), -1)
    np.maximum.accumulate(at, out=at)
    result: Floats = np.where(at >= 0, values[at], initial)
    return result
