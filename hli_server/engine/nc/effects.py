"""Effects (N-05, N-08, M-10..M-23): the interpreter's layer that runs the ``#`` commands - what others see
(``#MSG`` now or when the path passes, ``#FILE NAME``) and the directives it hands the decoder.
"""

from __future__ import annotations

import math

from hli_server.engine.nc import parser as word_parser
from hli_server.engine.nc.directives import (
    ContourDirective,
    CoordinateCommand,
    FlushStop,
    FlushWait,
    MeasMode,
    Slope,
    SyncAction,
)
from hli_server.engine.nc.expr import (
    Expr,
    Value,
    format_value,
)
from hli_server.engine.nc.kinematic_commands import (
    AxisEntry,
    CaxTrack,
    CylSelect,
    KinematicCommand,
    KinSelect,
    SetAxes,
    ToolOriCs,
    TrafoSwitch,
)
from hli_server.engine.nc.language import (
    A_CONTROL_SYNTAX,
    A_CORNER_DEVIATION,
    A_INDEX,
    A_MESSAGE,
    A_MSG_FORMAT,
    A_MSG_VALUES,
    A_NOT_SIMULATED,
    A_RANGE,
    A_STRING_LENGTH,
    CONTOUR_KEYS,
    CONTOUR_TYPES,
    CONTOUR_WORDS,
    DEVIATION_KEYS,
    HSC_KEYS,
    HSC_WORDS,
    MAX_MESSAGE,
    MEAS_TYPES,
    SPLINE_WORDS,
)
from hli_server.engine.nc.levels import (
    Frame,
)
from hli_server.engine.nc.statements import (
    Hash,
    Stmt,
)
from hli_server.engine.nc.variable_access import VariableAccess

__all__ = ["Effects"]


class Effects(VariableAccess):
    """Runs the ``#`` commands (N-05, N-08, M-10..M-23): ``#MSG`` (the channel's message events),
    ``#FILE NAME``, ``#FLUSH``, and the directives of ``#MEAS MODE``, ``#SLOPE``, ``#CS``/``#ACS``/
    ``#ROTATION``, ``#CONTOUR MODE``/``#HSC``/``#SPLINE`` (which ``#`` commands exist is
    ``nc/language.py``'s ``HASH_COMMANDS``)."""

    # --- kinematic transformations (issue 35, docs/kinematics.md) -------------------------------------------
    def _whole(self, stmt: Hash, expr: Expr, what: str, low: int, high: int) -> int:
        value = self._number(stmt, expr, what)
        if value != int(value) or not low <= value <= high:
            raise stmt.error(A_INDEX, f"{what} {format_value(value)}: a whole number {low} .. {high}")
        return int(value)

    def _kinematic(self, frame: Frame, stmt: Hash) -> KinematicCommand:
        """The decoder's command of ``#KIN ID``, ``#TRAFO``, ``#TOOL ORI CS``, ``#CYL``, ``#CAXTRACK``,
        ``#SET AX`` (:mod:`hli_server.engine.nc.kinematic_commands`), its values evaluated."""
        place = self._place_block(frame, stmt)
        command, options = stmt.command, stmt.options
        names = [o[3:] for o in options if o.startswith("AX:")]
        params = {k: self._number(stmt, e, f"#{command} {k}") for k, e in stmt.params.items()}
        if command == "KIN ID":
            kin_id = self._whole(stmt, stmt.args[0], "#KIN ID", 0, 65535) if stmt.args else None
            return KinSelect(place, kin_id)
        if command == "TRAFO":
            return TrafoSwitch(place, "ON" in options)
        if command == "TOOL ORI CS":
            return ToolOriCs(place, "OFF" not in options)
        if command == "CYL":
            if "OFF" in options:
                return CylSelect(place)
            if "LATERAL" in options:
                for k, key in enumerate(("AXNR1", "AXNR2")):
                    if key in params:
                        logical = self._whole(stmt, stmt.params[key], f"#CYL ORI LATERAL {key}", 1, 65535)
                        names.insert(k, f"#{logical}")  # the decoder knows the axis of the number
                if len(names) != 2 or "RADIUS" not in params:
                    raise stmt.error(
                        A_CONTROL_SYNTAX,
                        "#CYL ORI LATERAL [AX1=.. AX2=.. RADIUS=..]: both axes and the radius",
                    )
            return CylSelect(place, tuple(names), params.get("RADIUS", 0.0), lateral="LATERAL" in options)
        if command == "CAXTRACK":
            if "OFF" in options:
                return CaxTrack(place, False, angpos=params.get("ANGPOS"))
            unsimulated: list[str] = [k for k in ("OPTALIGN", "ROTMODE") if k in params]
            unsimulated += ["SCALEFACT"] if params.get("SCALEFACT", 1.0) != 1.0 else []
            unsimulated += ["START_STROKE"] if "START_STROKE" in options else []
            if unsimulated:
                raise stmt.error(
                    A_NOT_SIMULATED,
                    f"#CAXTRACK ON [{', '.join(unsimulated)}] is not simulated (ANGLIMIT, OFFSET, AX, AXNR "
                    "are): see docs/kinematics.md",
                )
            axnr = stmt.params.get("AXNR")
            return CaxTrack(
                place,
                True,
                anglimit=params.get("ANGLIMIT"),
                offset=params.get("OFFSET", 0.0),
                axis=names[0] if names else None,
                axis_number=self._whole(stmt, axnr, "#CAXTRACK AXNR", 1, 65535) if axnr is not None else None,
            )
        entries = []
        for k, name in enumerate(names):
            number = self._whole(stmt, stmt.args[2 * k], f"#SET AX [{name}, <number>", 1, 65535)
            index = self._whole(stmt, stmt.args[2 * k + 1], f"#SET AX [{name}, {number}, <index>", 0, 31)
            entries.append(AxisEntry(name, number, index))
        return SetAxes(place, tuple(entries), fast="FAST" in options)

    # --- # commands ------------------------------------------------------------------------------------
    def _hash(self, frame: Frame, stmt: Hash) -> None:
        command = stmt.command
        if command == "FLUSH":
            place = self._place_block(frame, stmt)
            if "WAIT" in stmt.options:
                self._pending.append(FlushWait(place))
            elif "CONTINUE" not in stmt.options:
                self._pending.append(FlushStop(place))
            return
        if command == "MEAS MODE":
            meas_type: int | None = None
            if stmt.args:
                value = self._number(stmt, stmt.args[0], "the measuring type of #MEAS MODE")
                if value != int(value) or not 1 <= value <= MEAS_TYPES:
                    raise stmt.error(
                        A_INDEX,
                        f"#MEAS MODE [{format_value(value)}]: the measuring types are 1 .. {MEAS_TYPES}",
                    )
                meas_type = int(value)
            self._pending.append(MeasMode(self._place_block(frame, stmt), meas_type))
            return
        if command == "SLOPE":
            profile: int | None = None
            for option in stmt.options:
                if option.startswith("TYPE="):
                    profile = ("STEP", "TRAPEZ", "SIN2", "HSC").index(option[5:])
            self._pending.append(Slope(self._place_block(frame, stmt), profile))
            return
        if command.startswith(("CS ", "ACS ", "ROTATION ")):
            kind, op = command.split(" ", 1)
            numbers = [self._number(stmt, a, f"a value of #{command}") for a in stmt.args]
            ident: int | None = None
            name: str | None = None
            rotation: dict[str, float] = {}
            if kind == "ROTATION":
                rotation = dict(zip(stmt.options, numbers, strict=True))
                numbers = []
            elif "ID" in stmt.options:
                value = numbers.pop(0)
                if value != int(value) or value < 1:
                    raise stmt.error(
                        A_INDEX, f"#{command} [{format_value(value)}]: the ID is a whole number >= 1"
                    )
                ident = int(value)
            for option in stmt.options:
                if option.startswith("NAME:"):
                    name = option[5:]
            self._pending.append(
                CoordinateCommand(
                    self._place_block(frame, stmt),
                    kind,
                    op,
                    ident,
                    name,
                    tuple(numbers),
                    rotation,
                    all_="ALL" in stmt.options,
                )
            )
            return
        if command == "FILE NAME":
            for key, name in stmt.files.items():
                if key == "MSG":
                    self._message_file = name
                else:  # G80..G89, G800..G839: the program of the implicit call (nc/implicit.py)
                    self._implicit_names[int(key[1:])] = name
            return
        if command in ("CONTOUR MODE", "HSC", "SPLINE"):
            self._pending.append(self._contour(frame, stmt))
            return
        if command in ("KIN ID", "TRAFO", "TOOL ORI CS", "CYL", "CAXTRACK", "SET AX"):
            self._pending.append(self._kinematic(frame, stmt))
            return
        # MSG
        if self._needs_flush(frame, stmt, stmt.args):
            self._flush_wait(frame, stmt)
            return
        values = [self._evaluate(stmt, a) for a in stmt.args]
        text = self._format(stmt, values)
        save = "SAVE" in stmt.options
        file = self._message_file
        host = self.host
        program = frame.program or self.program_name
        line = stmt.first
        label = stmt.place
        if "SYN" in stmt.options or "SYN_ACK" in stmt.options:

            def emit() -> None:
                self._effect()
                host.message(text, save, file, program, line, label)

            self._pending.append(SyncAction(self._place_block(frame, stmt), emit))
            return
        self._effect()
        host.message(text, save, file, program, line, label)

    def _format(self, stmt: Stmt, values: list[Value]) -> str:
        """The message text: the format string's ``%d``, ``%f``, ``%s``, ... filled in (printf, as the
        manual says), at most :data:`MAX_MESSAGE` characters.

        Bounded before anything is built (issue 36, finding 1: ``%.300000000f`` built 300 MB inside the
        cycle): a width, or a precision that fixes the digits (all but ``%g`` and ``%s``, whose precision
        only cuts), beyond :data:`MAX_MESSAGE` is refused at once, and so is the text as soon as it grows
        beyond it (the kernel's 21870, "String exceeds the maximum length"); each element then costs at
        most a few hundred characters."""
        fmt = values[0]
        if not isinstance(fmt, str):
            raise stmt.error(A_MESSAGE, '#MSG: the message text is a string in quotes: #MSG ["text"]')
        args = values[1:]
        out: list[str] = []
        length = 0
        i = 0
        n = len(fmt)
        used = 0
        while i < n:
            j = fmt.find("%", i)
            if j != i:  # the text up to the next element, as it is
                literal = fmt[i:] if j < 0 else fmt[i:j]
                out.append(literal)
                length += len(literal)
                if j < 0:
                    break
            i = j
            j = i + 1
            while j < n and fmt[j] in "-+ #0":
                j += 1
            digits = j
            while j < n and fmt[j].isdigit():
                j += 1
            width = int(fmt[digits:j]) if j > digits else 0
            spec = fmt[i:j]  # flags and width
            precision = 0
            if j < n and fmt[j] == ".":
                j += 1
                digits = j
                while j < n and fmt[j].isdigit():
                    j += 1
                precision = int(fmt[digits:j]) if j > digits else 0
            while j < n and fmt[j] in "lh":
                j += 1
            if j >= n:
                raise stmt.error(A_MSG_FORMAT, f"#MSG: incomplete format {fmt[i:]!r} (%d, %f, %s, ...)")
            conversion = fmt[j]
            element = fmt[i : j + 1]
            if "." in element:
                # %g: a precision beyond the bound gives the same text as the bound where that fits
                cut = min(precision, MAX_MESSAGE) if conversion in "gG" else precision
                spec += f".{cut}"
            if conversion == "%":
                out.append("%")
                length += 1
                i = j + 1
                continue
            if conversion not in "diufFeEgGxXos":
                raise stmt.error(A_MSG_FORMAT, f"#MSG: unknown format {element!r} (%d, %f, %s, ...)")
            fixed = 0 if conversion in "gGs" else precision  # %g and %s: the precision only cuts
            if max(width, fixed) > MAX_MESSAGE:
                raise stmt.error(
                    A_STRING_LENGTH,
                    f"#MSG: format {_shorten(element)} asks for {max(width, fixed)} characters; a message "
                    f"has at most {MAX_MESSAGE}",
                )
            if used >= len(args):
                raise stmt.error(
                    A_MSG_VALUES, f"#MSG: the text has more formats than values ({len(args)} given)"
                )
            value = args[used]
            used += 1
            try:
                if conversion == "s":
                    piece = (spec + "s") % (value if isinstance(value, str) else format_value(value))
                elif isinstance(value, str):
                    raise stmt.error(A_MESSAGE, f"#MSG: {element!r} needs a number, got a string")
                elif conversion in "diuxXo":
                    conv = "d" if conversion in "iu" else conversion
                    piece = (spec + conv) % math.trunc(value)
                else:
                    piece = (spec + conversion) % value
            except (ValueError, OverflowError) as exc:
                raise stmt.error(A_MESSAGE, f"#MSG: cannot format {format_value(value)}: {exc}") from None
            out.append(piece)
            length += len(piece)
            if length > MAX_MESSAGE:
                break  # said below, without formatting the rest
            i = j + 1
        if length > MAX_MESSAGE:
            raise stmt.error(A_STRING_LENGTH, f"#MSG: the message grows beyond {MAX_MESSAGE} characters")
        if used < len(args):
            raise stmt.error(A_MSG_VALUES, f"#MSG: {len(args)} values for {used} format(s) in the text")
        return "".join(out)

    def _contour(self, frame: Frame, stmt: Hash) -> ContourDirective:
        """Checks and evaluates ``#CONTOUR MODE``, ``#HSC``, ``#SPLINE`` (M-20..M-23)."""
        command = stmt.command
        name = {"CONTOUR MODE": "CONTOUR", "HSC": "HSC", "SPLINE": "SPLINE"}[command]
        words, keys = {
            "CONTOUR": (CONTOUR_WORDS, CONTOUR_KEYS),
            "HSC": (HSC_WORDS, HSC_KEYS),
            "SPLINE": (SPLINE_WORDS, frozenset[str]()),
        }[name]
        for word in stmt.options:
            if word not in words:
                known = ", ".join(sorted(words | keys))
                raise stmt.error(A_CONTROL_SYNTAX, f"#{command}: unknown word {word!r} (known: {known})")
        for key in stmt.params:
            if key not in keys:
                known = ", ".join(sorted(words | keys)) or "none"
                raise stmt.error(A_CONTROL_SYNTAX, f"#{command}: unknown parameter {key!r} (known: {known})")
        if "ON" in stmt.options and "OFF" in stmt.options:
            raise stmt.error(A_CONTROL_SYNTAX, f"#{command}: ON and OFF in one command")
        on = True if "ON" in stmt.options else False if "OFF" in stmt.options else None
        values: dict[str, float] = {}
        for key, expr in stmt.params.items():
            value = self._number(stmt, expr, f"{key} of #{command}")
            if key in DEVIATION_KEYS and value < 0.0:
                raise stmt.error(
                    A_CORNER_DEVIATION,
                    f"#{command}: {key}={format_value(value)} is smaller than the least permitted value 0 "
                    "(a corner deviation in mm)",
                )
            if key in ("PRE_DIST", "POST_DIST") and value < 0.0:
                raise stmt.error(A_RANGE, f"#{command}: {key}={format_value(value)} must not be negative")
            if key in DEVIATION_KEYS | {"PRE_DIST", "POST_DIST"} and value > word_parser._POSITION_MAX:
                raise stmt.error(A_RANGE, f"#{command}: {key} is out of range: {word_parser._POSITION_RANGE}")
            values[key] = value
        mode: str | None = None
        if name == "CONTOUR":
            types = [w for w in stmt.options if w in CONTOUR_TYPES]
            if len(types) > 1:
                raise stmt.error(
                    A_CONTROL_SYNTAX, f"#{command}: two contouring types {types[0]} and {types[1]}"
                )
            mode = types[0] if types else None
        elif name == "HSC":
            if "BSPLINE" in stmt.options:
                mode = "BSPLINE"
            elif "OPMODE" in values:
                opmode = values["OPMODE"]
                if opmode not in (1.0, 2.0):
                    raise stmt.error(
                        A_RANGE, f"#HSC: OPMODE {format_value(opmode)}: the operation modes are 1, 2"
                    )
                mode = f"OPMODE {int(opmode)}"
        else:
            for word in ("AKIMA", "BSPLINE"):
                if word in stmt.options:
                    mode = word
            if "TYPE" in stmt.options and mode is None:
                raise stmt.error(A_CONTROL_SYNTAX, "#SPLINE TYPE: AKIMA or BSPLINE expected")
            if mode is not None and "TYPE" not in stmt.options:
                raise stmt.error(A_CONTROL_SYNTAX, f"#SPLINE {mode}: write #SPLINE TYPE {mode}")
            if mode is None and on is None:
                raise stmt.error(A_CONTROL_SYNTAX, "#SPLINE: ON, OFF or TYPE AKIMA|BSPLINE expected")
        return ContourDirective(self._place_block(frame, stmt), name, on, mode, values)


def _shorten(element: str) -> str:
    """A format element as a message quotes it: its digits cut short when there are many."""
    return repr(element) if len(element) <= 24 else repr(element[:20] + "..." + element[-1])
