"""Effects (N-05, N-08, M-10..M-23): the interpreter's layer that runs the ``#`` commands - what others see
(``#MSG`` now or when the path passes, ``#FILE NAME``) and the directives it hands the decoder.
"""

from __future__ import annotations

import functools
import math

from hli_server.engine.nc import parser as word_parser
from hli_server.engine.nc.blocks import Block
from hli_server.engine.nc.directives import (
    ChannelInit,
    ContourDirective,
    CoordinateCommand,
    FlushStop,
    FlushWait,
    MeasMode,
    Realtime,
    Slope,
    SyncAction,
    VectorLimit,
)
from hli_server.engine.nc.expr import (
    ALARM_TYPE,
    Expr,
    Ref,
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
    A_CHANNEL_INIT,
    A_CONTROL_SYNTAX,
    A_CORNER_DEVIATION,
    A_DRIVE_READ,
    A_DRIVE_READ_ONLY,
    A_DWELL_RANGE,
    A_HUEMNOS_TOOL,
    A_INDEX,
    A_LIMIT,
    A_MESSAGE,
    A_MSG_FORMAT,
    A_MSG_VALUES,
    A_NOT_SIMULATED,
    A_RANGE,
    A_RT_ID,
    A_STRING_LENGTH,
    A_UNKNOWN_AXIS_NAME,
    CONTOUR_KEYS,
    CONTOUR_TYPES,
    CONTOUR_WORDS,
    DEVIATION_KEYS,
    FILTER_KEYS,
    HSC_KEYS,
    HSC_WORDS,
    MAX_MESSAGE,
    MAX_NAME,
    MEAS_TYPES,
    SPLINE_WORDS,
    VECTOR_LIMITS,
    VECTOR_VELOCITY_DEFAULT,
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

_MAX_DWELL_S = 214748.3647
"""s: the longest dwell (a DINT of 0.1 ms, as a position's range; ID 20751 beyond)."""


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
            if "MSG" in stmt.params:
                file_name = self._evaluate(stmt, stmt.params["MSG"])
                if not isinstance(file_name, str):
                    raise stmt.error(
                        ALARM_TYPE,
                        f"#FILE NAME [MSG=..]: {format_value(file_name)} is no file name (a string)",
                    )
                if not file_name or len(file_name) > MAX_NAME:
                    raise stmt.error(
                        A_LIMIT,
                        f'#FILE NAME [MSG=..]: "{file_name}": a file name has 1 to {MAX_NAME} characters',
                    )
                self._message_file = file_name
            return
        if command in ("CONTOUR MODE", "HSC", "SPLINE"):
            self._pending.append(self._contour(frame, stmt))
            return
        if command in ("KIN ID", "TRAFO", "TOOL ORI CS", "CYL", "CAXTRACK", "SET AX"):
            self._pending.append(self._kinematic(frame, stmt))
            return
        if command == "TIME":
            self._dwell(frame, stmt)
            return
        if command.startswith("TOOL "):
            self._tool(frame, stmt)
            return
        if command.startswith("IDENT "):
            self._ident(frame, stmt)
            return
        if command == "FILTER":
            self._filter(stmt)
            return
        if command == "RT CYCLE":
            self._rt_cycle(frame, stmt)
            return
        if command == "FRC":
            feed = self._number(stmt, stmt.args[0], "the feed of #FRC")
            if not 0.0 < feed <= word_parser._FEED_MAX:
                raise stmt.error(A_RANGE, f"#FRC={format_value(feed)}: {word_parser._FEED_RANGE}")
            self._approximation(
                stmt,
                "#FRC",
                "#FRC (the feed of an inserted chamfer or rounding) is not simulated: the element is "
                "travelled at the G301/G302 block's F or the pre-block's feed; the path is the same "
                "(docs/nc-language.md)",
            )
            return
        if command == "VECTOR LIMIT":
            self._vector_limit(frame, stmt)
            return
        if command == "CHANNEL INIT":
            self._channel_init(frame, stmt)
            return
        if command.startswith(("AKIMA ", "SET ASPLINE")):
            for arg in stmt.args:
                self._number(stmt, arg, f"a component of #{command}")
            self._approximation(
                stmt,
                "#AKIMA",
                f"#{command}: the Akima spline's transition types and tangents are not simulated: the spline "
                "is simulated as contouring with corner deviation 0.2 mm (warning 911040), whose transitions "
                "into and out of it are contoured corners too (docs/nc-language.md)",
            )
            return
        # MSG
        if self._needs_flush(frame, stmt, stmt.args):
            self._flush_wait(frame, stmt)
            return
        values = [self._evaluate(stmt, a) for a in stmt.args]
        text = self._format(stmt, values)
        save = "SAVE" in stmt.options
        file = self._message_file
        program = frame.program or self.program_name
        line = stmt.first
        label = stmt.place
        if "SYN" in stmt.options or "SYN_ACK" in stmt.options:
            # a partial, not a closure: a recording's snapshot keeps it (hli_server/recording/snapshot.py)
            emit = functools.partial(self._emit_message, text, save, file, program, line, label)
            self._pending.append(SyncAction(self._place_block(frame, stmt), emit))
            return
        self._emit_message(text, save, file, program, line, label)

    def _vector_limit(self, frame: Frame, stmt: Hash) -> None:
        """``#VECTOR LIMIT ON|OFF [..]`` (PM 207477899): VEL is simulated (the path velocity of the motion
        blocks after it, on the blocks FEED/RAPID select: neither keyword, both); the other limits shape
        only the ramps and are accepted with warning 911041. ON without a value, ON ALL and a bare ON take
        the channel's default (P-CHAN-00090 vector.velocity); OFF drops the limit."""
        on = stmt.options[0] == "ON"
        words = set(stmt.options[1:])
        bare = not words and not stmt.params
        every = bare or "ALL" in words
        for key, expr in stmt.params.items():
            value = self._number(stmt, expr, f"#VECTOR LIMIT {key}=")
            if not on:
                raise stmt.error(A_CONTROL_SYNTAX, f"#VECTOR LIMIT OFF: {key} takes no value with OFF")
            if not 0.0 < value <= 1e12:
                raise stmt.error(
                    A_RANGE, f"#VECTOR LIMIT {key}={format_value(value)}: a limit is positive, at most 1e12"
                )
        others = [k for k in VECTOR_LIMITS if k != "VEL" and (k in words or k in stmt.params)]
        if others or (every and on):
            self._approximation(
                stmt,
                "#VECTOR LIMIT",
                f"#VECTOR LIMIT {' '.join(others) or 'ALL'}: the path's acceleration, deceleration, jerk and "
                "radial limits are not simulated: the path keeps the axes' own dynamics (VEL is simulated; "
                "docs/nc-language.md)",
            )
        if not (every or "VEL" in words or "VEL" in stmt.params):
            return
        feed = "FEED" in words or "RAPID" not in words
        rapid = "RAPID" in words or "FEED" not in words
        velocity: float | None = None
        if on:
            vel = stmt.params.get("VEL")
            velocity = VECTOR_VELOCITY_DEFAULT if vel is None else self._number(stmt, vel, "VEL")
        self._pending.append(VectorLimit(self._place_block(frame, stmt), velocity, feed, rapid))

    def _channel_init(self, frame: Frame, stmt: Hash) -> None:
        """``#CHANNEL INIT [CMDPOS|ACTPOS ..]``: decoding waits for the path, then takes its axes'
        positions (the decoder's ``ChannelInit``); an axis twice is the kernel's 21507."""
        names = [o[3:] for o in stmt.options if o.startswith("AX:")]
        for arg in stmt.args:
            number = self._whole(stmt, arg, "#CHANNEL INIT AXNR=", 1, 65535)
            name = self.host.axis_name(number - 1)
            if name is None:
                raise stmt.error(A_INDEX, f"#CHANNEL INIT AXNR={number}: no axis {number} in this channel")
            if name in names:
                raise stmt.error(A_CHANNEL_INIT, f"#CHANNEL INIT: axis {name} programmed twice")
            names.append(name)
        for name in names:
            if self.host.axis_value("ABS", name) is None:
                raise stmt.error(
                    A_UNKNOWN_AXIS_NAME, f"#CHANNEL INIT AX={name}: no axis {name} in this channel"
                )
        place = self._place_block(frame, stmt)
        self._pending.append(ChannelInit(place, "ACTPOS" in stmt.options, tuple(names)))

    def _emit_message(self, text: str, save: bool, file: str, program: str, line: int, label: str) -> None:
        self._effect()
        self.host.message(text, save, file, program, line, label)

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

    # --- #TIME, #TOOL, #IDENT ------------------------------------------------------------------------------
    def _dwell(self, frame: Frame, stmt: Hash) -> None:
        """``#TIME <s>`` (PM 206132747): the dwell of ``G04 <s>``, a block the decoder rests for."""
        seconds = self._number(stmt, stmt.args[0], "the dwell time of #TIME")
        if not 0.0 <= seconds <= _MAX_DWELL_S:
            raise stmt.error(
                A_DWELL_RANGE,
                f"#TIME {format_value(seconds)}: the dwell time is 0 .. {_MAX_DWELL_S:g} s",
            )
        first = self.compiler.main_axes[0]
        self._pending.append(
            Block(stmt.first, stmt.number, stmt.text, (4,), axes=((first, seconds),), program=frame.program)
        )

    def _tool(self, frame: Frame, stmt: Hash) -> None:
        """``#TOOL PREP [..]`` is the T word, ``#TOOL DATA [..]`` the D word (PM 208577419): the tool ID's
        basic number selects, a sister or variant other than 0 is the kernel's 20861 (no HÜMNOS tool
        management is simulated). ``#TOOL LIFE READ|REMOVE`` (PM 208592267): no tool life is acquired and no
        tool management is simulated, so nothing is sent: accepted, said once (911041)."""
        command = stmt.command
        ident = [self._number(stmt, a, f"the tool ID of #{command}") for a in stmt.args]
        if command == "TOOL LIFE":
            self._approximation(
                stmt,
                "#TOOL LIFE",
                f"#TOOL LIFE {stmt.options[0]}: no tool life is acquired and no tool management is "
                "simulated; nothing is sent (docs/nc-language.md)",
            )
            return
        if any(v != 0.0 for v in ident[1:]):
            raise stmt.error(
                A_HUEMNOS_TOOL,
                f"#{command} [{', '.join(format_value(v) for v in ident)}]: a sister or variant tool needs a "
                "HÜMNOS tool management; the tool table here is by the basic number only",
            )
        word = "T" if command == "TOOL PREP" else "D"
        self._pending.append(
            Block(stmt.first, stmt.number, stmt.text, extra={word: ident[0]}, program=frame.program)
        )

    def _ident(self, frame: Frame, stmt: Hash) -> None:
        """``#IDENT WR [SYN]``, ``#IDENT RD`` (PM 207347083): drive parameters through the service channel.
        The simulated drive keeps what is written, per axis and ident, as the integer the telegram carries
        (``VAL`` times 10^``DEC`` in ``TYP`` bytes); a read gives that integer / 10^``DEC``. Its own idents
        (the cycle times S-0-0001/S-0-0002) are read-only (the kernel's 50357); an ident it neither has nor
        was given is the kernel's warning 140032 and reads 0. No ident reaches the motion or the monitors
        (the drive model is the machine file's)."""
        command = stmt.command
        numbers = {key: self._number(stmt, expr, f"{key} of #{command}") for key, expr in stmt.params.items()}
        axis = ""
        ident = ""
        for option in stmt.options:
            if option.startswith("AX:"):
                axis = option[3:]
            elif option.startswith("ID:"):
                ident = option[3:]
        if axis and axis not in self.compiler.axis_names:
            raise stmt.error(A_UNKNOWN_AXIS_NAME, f"#{command}: AX={axis} is no axis of this channel")
        if not axis:
            number = numbers["AXNR"]
            if number != int(number) or number < 1:
                raise stmt.error(
                    A_CONTROL_SYNTAX, f"#{command}: AXNR={format_value(number)} is no axis number"
                )
            axis = f"#{int(number)}"
        size = numbers["TYP"]
        decimals = numbers["DEC"]
        if size not in (2.0, 4.0) or decimals != int(decimals) or not 0 <= decimals <= 9:
            raise stmt.error(
                A_CONTROL_SYNTAX,
                f"#{command}: TYP {format_value(size)} DEC {format_value(decimals)}: TYP is 2 or 4 (bytes), "
                "DEC a whole number 0 .. 9",
            )
        mask = (1 << (8 * int(size))) - 1
        scale = 10.0 ** int(decimals)
        key = f"{axis}/{ident}"
        if command == "IDENT WR":
            if self.host.drive_value(axis, ident) is not None:
                raise stmt.error(
                    A_DRIVE_READ_ONLY,
                    f"#IDENT WR: {ident} of axis {axis} is not changeable (read it with #IDENT RD)",
                )
            raw = round(numbers["VAL"] * scale) & mask
            store = self._drive_parameters
            if "SYN" in stmt.options:
                # a partial, not a closure: a recording's snapshot keeps it (hli_server/recording/snapshot.py)
                write = functools.partial(_store, store, key, raw)
                self._pending.append(SyncAction(self._place_block(frame, stmt), write))
            else:
                store[key] = raw
            return
        own = self.host.drive_value(axis, ident)
        if own is not None:
            value = float(round(own) & mask) / scale
        elif key in self._drive_parameters:
            value = float(self._drive_parameters[key] & mask) / scale
        else:
            self._effect()
            self.host.warn(
                A_DRIVE_READ,
                f"#IDENT RD: error while reading ident {ident} of axis {axis}: the simulated drive has no "
                "such value (nor was it written); 0 is read",
                stmt.first,
                stmt.place,
            )
            value = 0.0
        target = stmt.args[0]
        assert isinstance(target, Ref)
        self._assign(frame, stmt, target, value)

    def _filter(self, stmt: Hash) -> None:
        """``#FILTER [ON|OFF] [ORDER=.. ORDER_TIME=.. SHARE=.. AX_DEV=.. FCUT=.. ACC_FACT=.. QUALITY=..]``
        (TF5200 FIR filter, 542033291): the FIR filters of the axes' command values. Approximated: the axes
        follow the planned path unfiltered (said once per program, 911041, at ON); the filtered path departs
        from it in corners by at most AX_DEV where programmed (the kernel's tolerance monitoring), else by
        at most F times the filter's time / 2."""
        for word in stmt.options:
            if word not in ("ON", "OFF"):
                raise stmt.error(A_CONTROL_SYNTAX, f"#FILTER: unknown word {word!r} (ON, OFF)")
        if "ON" in stmt.options and "OFF" in stmt.options:
            raise stmt.error(A_CONTROL_SYNTAX, "#FILTER: ON and OFF in one command")
        values: dict[str, float] = {}
        for key, expr in stmt.params.items():
            if key not in FILTER_KEYS:
                known = ", ".join(sorted(FILTER_KEYS))
                raise stmt.error(A_CONTROL_SYNTAX, f"#FILTER: unknown parameter {key!r} (known: {known})")
            value = self._number(stmt, expr, f"{key} of #FILTER")
            if value < 0.0:
                raise stmt.error(A_RANGE, f"#FILTER: {key}={format_value(value)} must not be negative")
            values[key] = value
        if "ON" in stmt.options:
            bound = (
                f"by at most AX_DEV={format_value(values['AX_DEV'])} mm (the kernel's tolerance monitoring)"
                if values.get("AX_DEV", 0.0) > 0.0
                else "in corners and curves by at most the feed times half the filter's time (ORDER cycles "
                "or ORDER_TIME)"
            )
            self._approximation(
                stmt,
                "#FILTER",
                "#FILTER ON: the FIR filters of the axes' command values are not simulated: the axes follow "
                f"the planned path unfiltered; the kernel's filtered path departs from it {bound} "
                "(docs/nc-language.md)",
            )

    def _rt_cycle(self, frame: Frame, stmt: Hash) -> None:
        """``#RT CYCLE [DEF] [ID= SCOPE= END_ACTION=]`` starts a realtime cycle's definition (its statements
        are collected up to ``#RT CYCLE END``, not run: ``nc/interpreter.py``); ``START``, ``HOLD``,
        ``CONTINUE``, ``ABORT ACTION``, ``DELETE`` manage one when the path passes (TF5261)."""
        ident: int | None = None
        if "ID" in stmt.params:
            value = self._number(stmt, stmt.params["ID"], "the ID of #RT CYCLE")
            if value != int(value) or value < 0:
                raise stmt.error(
                    A_INDEX, f"#RT CYCLE [ID={format_value(value)}]: the ID is a whole number >= 0"
                )
            ident = int(value)
        op = next((o for o in stmt.options if "=" not in o), "")
        place = self._place_block(frame, stmt)
        if op == "END":
            raise stmt.error(A_CONTROL_SYNTAX, "#RT CYCLE END without #RT CYCLE")
        if op in ("", "DEF"):
            scope = next((o[6:] for o in stmt.options if o.startswith("SCOPE=")), "PROG")
            if ident is None and (op == "DEF" or scope == "GLOBAL"):
                raise stmt.error(
                    A_RT_ID, "#RT CYCLE: an ID is needed with DEF or SCOPE=GLOBAL (#RT CYCLE [ID=.. ..])"
                )
            self._rt_body = []
            self._rt_define = Realtime(place, "DEFINE", ident, scope, start=op != "DEF")
            return
        self._pending.append(Realtime(place, op, ident))
        if op == "START" and ident in self._rt_block_scope:
            self._rt_block_scope[ident] = True  # valid for the next block again (TF5261 444677387)


def _store(store: dict[str, int], key: str, value: int) -> None:
    """``#IDENT WR SYN``'s write into the simulated drive's parameters, when the path passes."""
    store[key] = value


def _shorten(element: str) -> str:
    """A format element as a message quotes it: its digits cut short when there are many."""
    return repr(element) if len(element) <= 24 else repr(element[:20] + "..." + element[-1])
