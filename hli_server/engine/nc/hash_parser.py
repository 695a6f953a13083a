"""The ``#`` commands' statements (N-05..N-08, M-10..M-23): ``#MSG``, ``#FILE NAME``, ``#FLUSH``,
``#MEAS MODE``, ``#SLOPE``, ``#CONTOUR MODE``, ``#HSC``, ``#SPLINE``, ``#CS``/``#ACS``/``#ROTATION`` and the
conditional interpretation ``#IF``/``#ELSE``/``#ENDIF``.

Which ``#`` words exist, and which are simulated or refused with which alarm, is the table
:data:`~hli_server.engine.nc.language.HASH_COMMANDS`; :meth:`HashParser.hash_command` looks the word up
there and hands a simulated one to its reader here (:meth:`HashParser.read_hash`). The interpreter runs the
statements (``nc/effects.py``, ``nc/control_flow.py`` for ``#IF``).
"""

from __future__ import annotations

from collections.abc import Callable

from hli_server.engine.nc import parser as word_parser
from hli_server.engine.nc.expr import Const, Expr
from hli_server.engine.nc.expr_parser import NAME_CHARS, ExpressionParser
from hli_server.engine.nc.language import (
    A_CHANNEL_INIT,
    A_COMMENT_OPEN,
    A_COND_FIRST,
    A_CONTROL_SYNTAX,
    A_LIMIT,
    A_NOT_SIMULATED,
    A_UNKNOWN_HASH,
    AKIMA_TRANSITIONS,
    HASH_COMMANDS,
    IDENT_VALUES,
    IDENT_WORDS,
    IMPLICIT_G_CODES,
    MAX_NAME,
    MSG_OPTIONS,
    RT_OPERATIONS,
    RT_SCOPES,
    SLOPE_TYPES,
    UNKNOWN_HASH_HINT,
    VECTOR_LIMITS,
)
from hli_server.engine.nc.statements import Control, Hash, Stmt

__all__ = ["HashParser"]


class HashParser(ExpressionParser):
    """Reads a ``#`` command's statement (the statement parser, ``nc/statement_parser.py``, builds on it)."""

    def hash_command(self) -> Stmt:
        start = self.pos
        self.pos += 1
        self.blanks()
        name = self.name()
        rule = HASH_COMMANDS.get(name)
        if rule is None:
            raise self.failure(
                A_UNKNOWN_HASH, f"unknown # command #{word_parser._short(name)}; {UNKNOWN_HASH_HINT}"
            )
        for form in rule.forms:
            if not form:
                return self.read_hash(name, start)
            if self.keyword(form):
                return self.read_hash(f"{name} {form}", start)
        raise self.failure(rule.alarm, rule.message)

    def next_entry(self, what: str, separators: str = ",") -> bool:
        """Inside ``[..]``: past blanks and separators to the next entry (True), or past the closing
        ``]`` (False); the end of the block first is 914015."""
        while True:
            self.blanks()
            c = self.peek()
            if c == "]":
                self.pos += 1
                return False
            if c and c in separators:
                self.pos += 1
                continue
            if not c:
                self.fail(A_CONTROL_SYNTAX, f"{what} [: ']' missing")
            return True

    def bracket_value(self) -> Expr:
        """A value inside ``[..]``: an expression up to the next blank (``ID=17 SCOPE=..``)."""
        saved = self.depth
        self.depth = 0
        try:
            return self.expression(stop_at_blank=True)
        finally:
            self.depth = saved

    def read_hash(self, command: str, start: int) -> Stmt:
        """The statement of a simulated ``command`` (a form of :data:`HASH_COMMANDS`): its reader."""
        if command in ("IF", "ELSE", "ENDIF"):
            return self.conditional(command, start)
        if command == "MSG":
            return self.message()
        if command in ("FILE", "FILENAME"):
            return self.file_name(named=command == "FILENAME")
        if command == "FLUSH":
            return self.flush()
        if command == "MEAS MODE":
            return self.meas_mode()
        if command == "SLOPE":
            return self.slope()
        if command in ("CONTOUR MODE", "HSC", "SPLINE"):
            return self.motion_options(command)
        if command == "SET SPLINE":
            return self.motion_options("SPLINE")  # the older spelling of #SPLINE ON/OFF (207209611)
        if command == "SET SPLINETYPE":
            return self.motion_options("SPLINE", prefix=["TYPE"])
        if command in ("CS", "ACS", "ROTATION"):
            return self.coordinates(command)
        if command in ("KIN ID", "TRAFO", "RTCP", "TOOL ORI", "CYL", "CAXTRACK", "SET AX"):
            return self.kinematic(command)
        if command == "TIME":
            return self.dwell()
        if command in ("TOOL PREP", "TOOL DATA", "TOOL LIFE"):
            return self.tool(command)
        if command in ("IDENT WR", "IDENT RD"):
            return self.ident(command)
        if command == "FILTER":
            return self.motion_options("FILTER")
        if command == "RT CYCLE":
            return self.rt_cycle()
        if command == "FRC":
            self.expect("=", "after #FRC (#FRC=<feed>)")
            args = [self.expression(stop_at_blank=True)]
            if not self.at_end():
                self.fail(A_CONTROL_SYNTAX, f"{self.word_at(self.pos)!r} after #FRC=..")
            return Hash(self.raw, self.number, "FRC", [], args)
        if command in ("AKIMA TRANS", "AKIMA STARTVECTOR", "AKIMA ENDVECTOR", "SET ASPLINE"):
            return self.akima(command)
        if command == "VECTOR LIMIT":
            return self.vector_limit()
        if command in ("VECTORVEL", "VECTORACC"):
            return self.vector_old(command)
        if command == "CHANNEL INIT":
            return self.channel_init()
        if command == "COMMENT":
            self.fail(
                A_COMMENT_OPEN,
                "#COMMENT END without #COMMENT BEGIN"
                if self.keyword("END")
                else "#COMMENT: BEGIN or END expected",
            )
        raise AssertionError(f"#{command}: simulated in HASH_COMMANDS, but no reader")  # pragma: no cover

    def conditional(self, name: str, start: int) -> Stmt:
        """``#IF <condition>``, ``#ELSE``, ``#ENDIF`` (conditional interpretation)."""
        if self.number is not None or start != len(self.u) - len(self.u.lstrip()):
            self.fail(
                A_COND_FIRST,
                f"#{name} must stand at the very start of its block, without a block number",
            )
        keyword = "#" + name
        exprs: list[Expr] = []
        if name == "IF":
            if self.at_end():
                self.fail(A_CONTROL_SYNTAX, "#IF without its condition")
            exprs.append(self.expression(stop_at_blank=False))
        if not self.at_end():
            self.fail(A_CONTROL_SYNTAX, f"{self.word_at(self.pos)!r} after #{name}")
        return Control(self.raw, self.number, keyword, exprs)

    def dwell(self) -> Stmt:
        """``#TIME <time>`` (PM 206132747): dwell time in seconds, direct or parameterised."""
        if self.at_end():
            self.fail(A_CONTROL_SYNTAX, "#TIME without its time: #TIME <seconds>")
        args = [self.expression(stop_at_blank=False)]
        if not self.at_end():
            self.fail(A_CONTROL_SYNTAX, f"{self.word_at(self.pos)!r} after #TIME's time")
        return Hash(self.raw, self.number, "TIME", [], args)

    def tool(self, command: str) -> Stmt:
        """``#TOOL PREP [<basic> [, <sister> [, <variant>]]]``, ``#TOOL DATA [..]`` (PM 208577419),
        ``#TOOL LIFE READ [..]``, ``#TOOL LIFE REMOVE`` (PM 208592267): ``args`` the tool ID (a gap is 0),
        ``options`` ``READ`` or ``REMOVE`` for ``#TOOL LIFE``."""
        options: list[str] = []
        if command == "TOOL LIFE":
            word = next((w for w in ("READ", "REMOVE") if self.keyword(w)), None)
            if word is None:
                self.fail(A_CONTROL_SYNTAX, "#TOOL LIFE: READ [<basic>, ..] or REMOVE expected")
            options.append(word)
        args: list[Expr] = []
        if options != ["REMOVE"]:
            self.blanks()
            at = self.pos
            self.expect("[", f"after #{command}")
            self.blanks()
            if self.peek() in (",", "]"):
                self.fail(A_CONTROL_SYNTAX, f"#{command} [<basic> ..]: the basic tool number is mandatory")
            self.pos = at
            args = self.components(f"#{command}")
            if len(args) > 3:
                self.fail(
                    A_CONTROL_SYNTAX,
                    f"#{command} [<basic> [, <sister> [, <variant>]]]: at most three values, "
                    f"{len(args)} given",
                )
        if not self.at_end():
            self.fail(A_CONTROL_SYNTAX, f"{self.word_at(self.pos)!r} after #{command} [..]")
        return Hash(self.raw, self.number, command, options, args)

    def rt_cycle(self) -> Stmt:
        """``#RT CYCLE [DEF] [ID=.. SCOPE=BLOCK|PROG|GLOBAL END_ACTION=..]``, ``#RT CYCLE END``, ``#RT CYCLE
        START|HOLD|CONTINUE|ABORT ACTION|DELETE [ID=..]`` (TF5261 562766219, 444681483): ``options`` the
        keyword (``DEF``, ``END``, ``START`` ..) and ``SCOPE=..``, ``END_ACTION=..``; ``params`` the ID."""
        options: list[str] = []
        word = next((w for w in RT_OPERATIONS if self.keyword(w)), None)
        if word is not None:
            options.append(word)
            if word == "ABORT" and not self.keyword("ACTION"):
                self.fail(A_CONTROL_SYNTAX, "#RT CYCLE ABORT ACTION [ID=..]")
        params: dict[str, Expr] = {}
        self.blanks()
        if self.peek() == "[":
            self.pos += 1
            while self.next_entry("#RT CYCLE"):
                key = self.name()
                self.blanks()
                self.expect("=", f"after #RT CYCLE [{key or self.word_at(self.pos)}")
                self.blanks()
                if key == "ID" and "ID" not in params:
                    params["ID"] = self.bracket_value()
                elif key in ("SCOPE", "END_ACTION") and not any(o.startswith(key + "=") for o in options):
                    ident = self.name()
                    allowed = RT_SCOPES if key == "SCOPE" else ("MOVE_ABORT", "MOVE_CONT")
                    if ident not in allowed:
                        self.fail(A_CONTROL_SYNTAX, f"#RT CYCLE [{key}={ident}]: {', '.join(allowed)}")
                    options.append(f"{key}={ident}")
                else:
                    self.fail(
                        A_CONTROL_SYNTAX, f"#RT CYCLE [..]: {key!r}: ID=, SCOPE=, END_ACTION= (each once)"
                    )
        if not self.at_end():
            self.fail(A_CONTROL_SYNTAX, f"{self.word_at(self.pos)!r} after #RT CYCLE")
        return Hash(self.raw, self.number, "RT CYCLE", options, [], params=params)

    def akima(self, command: str) -> Stmt:
        """``#AKIMA TRANS [START=<type> END=<type>]`` (PM 207222923), ``#AKIMA STARTVECTOR {<axis>..}``,
        ``#AKIMA ENDVECTOR {<axis>..}`` (PM 207229579, 207237003) and the older ``#SET ASPLINE ..``: the
        transition types and tangents of the Akima spline. ``options`` the types (``START=USER``) and the
        tangent's axes, ``args`` its components."""
        options: list[str] = []
        args: list[Expr] = []
        if command == "AKIMA TRANS":
            self.blanks()
            if self.peek() == "[":
                self.pos += 1
                while self.next_entry("#AKIMA TRANS"):
                    key = self.name()
                    if key not in ("START", "END") or any(o.startswith(key + "=") for o in options):
                        self.fail(A_CONTROL_SYNTAX, "#AKIMA TRANS [START=<type> END=<type>] (each once)")
                    self.expect("=", f"after #AKIMA TRANS [{key}")
                    self.blanks()
                    kind = self.name()
                    if kind not in AKIMA_TRANSITIONS:
                        self.fail(
                            A_CONTROL_SYNTAX,
                            f"#AKIMA TRANS [{key}={kind}]: the types are "
                            + ", ".join(sorted(AKIMA_TRANSITIONS)),
                        )
                    options.append(f"{key}={kind}")
        elif command in ("AKIMA STARTVECTOR", "AKIMA ENDVECTOR"):
            while not self.at_end():
                at = self.pos
                axis = self.name()
                if not axis or not axis[0].isalpha():
                    self.fail(
                        A_CONTROL_SYNTAX, f"#{command}: unexpected {self.word_at(at)!r} (<axis><value>)"
                    )
                self.blanks()
                if self.peek() == "=":
                    self.pos += 1
                elif axis[-1].isdigit():
                    # X1: the axis X and its component 1 (a name with digits takes '=': X2=1)
                    letters = axis.rstrip("0123456789")
                    options.append(letters)
                    args.append(Const(float(axis[len(letters) :])))
                    continue
                options.append(axis)
                args.append(self.expression(stop_at_blank=True))
            if not args:
                self.fail(A_CONTROL_SYNTAX, f"#{command} without the tangent's components (X1 Y1 Z0)")
        else:  # #SET ASPLINE MODE [..] | STARTTANG [..] | ZIELTANG [..]: the older spellings, read whole
            self.pos = self.n
        if not self.at_end():
            self.fail(A_CONTROL_SYNTAX, f"{self.word_at(self.pos)!r} after #{command}")
        return Hash(self.raw, self.number, command, options, args)

    def ident(self, command: str) -> Stmt:
        """``#IDENT WR [SYN] [AX=<axis> | AXNR=.. ID=<ident> VAL=.. TYP=.. DEC=.. SERC|CAN [NO_WAIT]]``,
        ``#IDENT RD [AX=.. ID=.. P=<variable> TYP=.. DEC=.. SERC|CAN]`` (PM 207352971, 207365515,
        207359627): ``options`` the keywords, ``AX:<axis>`` and ``ID:<ident>``; ``params`` AXNR, VAL, TYP,
        DEC; ``args`` the variable of RD."""
        options: list[str] = []
        if command == "IDENT WR" and self.keyword("SYN"):
            options.append("SYN")
        self.expect("[", f"after #{command}")
        self.depth += 1
        params: dict[str, Expr] = {}
        args: list[Expr] = []
        while self.next_entry(f"#{command}"):
            at = self.pos
            key = self.name()
            if key in IDENT_WORDS:
                if key in options:
                    self.fail(A_CONTROL_SYNTAX, f"#{command}: {key} given twice")
                options.append(key)
                continue
            if key not in IDENT_VALUES:
                self.fail(
                    A_CONTROL_SYNTAX,
                    f"#{command}: unexpected {self.word_at(at)!r} (AX=, AXNR=, ID=, VAL=, P=, TYP=, DEC=, "
                    "SERC, CAN, NO_WAIT)",
                )
            if key in params or any(o.startswith(key + ":") for o in options) or (key == "P" and args):
                self.fail(A_CONTROL_SYNTAX, f"#{command}: {key} given twice")
            self.blanks()
            if self.peek() == "=":
                self.pos += 1
                self.blanks()
            if key in ("AX", "ID"):
                begin = self.pos
                while self.pos < self.n and self.u[self.pos] not in " \t,]":
                    self.pos += 1
                word = self.u[begin : self.pos]
                if not word:
                    self.fail(A_CONTROL_SYNTAX, f"#{command}: {key} without its value")
                options.append(f"{key}:{word}")
            elif key == "P":
                if command != "IDENT RD":
                    self.fail(A_CONTROL_SYNTAX, "#IDENT WR: P=<variable> belongs to #IDENT RD")
                c = self.peek()
                if c == "V" and self.peek(1) == ".":
                    args.append(self.variable())
                elif c == "P":
                    args.append(self.parameter())
                else:
                    self.fail(A_CONTROL_SYNTAX, "#IDENT RD: P=<variable> (P1, V.P.NAME, V.L.NAME, V.S.NAME)")
            else:
                if self.at_end() or self.peek() in ("]", ","):
                    self.fail(A_CONTROL_SYNTAX, f"#{command}: {key} without its value")
                params[key] = self.bracket_value()
        self.depth -= 1
        missing = [k for k in ("ID", "TYP", "DEC") if k not in params and f"{k}:" not in " ".join(options)]
        if not any(o.startswith("AX:") for o in options) and "AXNR" not in params:
            missing.insert(0, "AX|AXNR")
        if command == "IDENT WR" and "VAL" not in params:
            missing.append("VAL")
        if command == "IDENT RD" and not args:
            missing.append("P")
        if not ("SERC" in options or "CAN" in options):
            missing.append("SERC|CAN")
        if missing:
            self.fail(A_CONTROL_SYNTAX, f"#{command} [..]: {', '.join(missing)} missing")
        if not self.at_end():
            self.fail(A_CONTROL_SYNTAX, f"{self.word_at(self.pos)!r} after #{command} [..]")
        return Hash(self.raw, self.number, command, options, args, params=params)

    def flush(self) -> Stmt:
        """``#FLUSH``, ``#FLUSH WAIT``, ``#FLUSH CONTINUE``."""
        options: list[str] = []
        for word in ("WAIT", "CONTINUE"):
            if self.keyword(word):
                options.append(word)
        if not self.at_end():
            self.fail(A_CONTROL_SYNTAX, f"#FLUSH: unexpected {self.word_at(self.pos)!r} (WAIT, CONTINUE)")
        return Hash(self.raw, self.number, "FLUSH", options, [])

    def message(self) -> Stmt:
        """``#MSG [SAVE] [SYN|SYN_ACK|ACK] [receiver] ["format", args]`` (207145355, 207171211)."""
        options: list[str] = []
        progress = True
        while progress:
            progress = False
            for word in MSG_OPTIONS:
                if self.keyword(word):
                    if word in options:
                        self.fail(A_CONTROL_SYNTAX, f"#MSG: {word} given twice")
                    options.append(word)
                    progress = True
        if "INFO" in options:
            self.fail(
                A_NOT_SIMULATED,
                "#MSG INFO (message information for a receiver) is not simulated: see docs/nc-language.md",
            )
        self.expect("[", "before the message text")
        self.depth += 1
        self.blanks()
        args = [self.expression(stop_at_blank=False)]
        while True:
            self.blanks()
            if self.peek() == ",":
                self.pos += 1
                args.append(self.expression(stop_at_blank=False))
                continue
            break
        self.expect("]", "after the message and its values")
        self.depth -= 1
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after #MSG [..]: a message stands alone in its block",
            )
        return Hash(self.raw, self.number, "MSG", options, args)

    def coordinates(self, name: str) -> Stmt:
        """``#CS|#ACS DEF|ON [[<id>]] [[v1,v2,v3,φ1,φ2,φ3]]``, ``#CS|#ACS OFF [ALL]``, ``#CS ADD|SET [<name>]
        [..]``, ``#CS DEL [<name>]|ALL``, ``#ROTATION ON [[ANGLE= CENTER1= CENTER2=]]``, ``#ROTATION OFF``
        (programming manual 208480907, 208491403, 1037259147, 1048407819, 207442315). The Hash's command is
        ``"CS ON"`` etc.; ``options`` holds ``ALL``, ``ID`` (the first bracket is the ID), a ``#CS ADD`` name,
        or the #ROTATION keywords in the order of ``args``."""
        ops: tuple[str, ...] = ("DEF", "ON", "OFF", "ADD", "SET", "DEL")
        if name == "ROTATION":
            ops = ("ON", "OFF")
        elif name == "ACS":
            ops = ("DEF", "ON", "OFF")
        op = next((o for o in ops if self.keyword(o)), None)
        if op is None:
            rest = self.word_at(self.pos) if self.pos < self.n else "nothing"
            self.fail(
                A_NOT_SIMULATED,
                f"#{name} {rest}: simulated are #{name} " + "/".join(ops) + " (docs/nc-language.md)",
            )
        options: list[str] = []
        args: list[Expr] = []
        if name == "ROTATION":
            if op == "ON" and not self.at_end():
                self.expect("[", "after #ROTATION ON")
                self.depth += 1
                while True:
                    self.blanks()
                    if self.peek() == "]":
                        self.pos += 1
                        break
                    key = self.name()
                    if key not in ("ANGLE", "CENTER1", "CENTER2") or key in options:
                        self.fail(
                            A_CONTROL_SYNTAX,
                            f"#ROTATION ON [..]: {key or self.word_at(self.pos)!r}: "
                            "ANGLE=, CENTER1=, CENTER2= (each once)",
                        )
                    self.blanks()
                    if self.peek() == "=":
                        self.pos += 1
                    options.append(key)
                    args.append(self.expression(stop_at_blank=True))
                self.depth -= 1
        elif op == "OFF":
            if self.keyword("ALL"):
                options.append("ALL")
        elif op in ("ADD", "SET", "DEL"):
            if op == "DEL" and self.keyword("ALL"):
                options.append("ALL")
            else:
                self.expect("[", f"after #CS {op}")
                self.blanks()
                cs_name = self.name()
                if not cs_name or len(cs_name) > 8:
                    self.fail(A_CONTROL_SYNTAX, f"#CS {op} [<name>]: a name of 1 to 8 characters")
                self.expect("]", f"after #CS {op} [<name>")
                options.append("NAME:" + cs_name)
                if op != "DEL":
                    args = self.components(f"#CS {op}")
        else:
            self.blanks()
            if self.peek() == "[":
                first = self.components(f"#{name} {op}")
                self.blanks()
                if self.peek() == "[":
                    if len(first) != 1:
                        self.fail(A_CONTROL_SYNTAX, f"#{name} {op} [<id>] [..]: the ID is one value")
                    options.append("ID")
                    args = first + self.components(f"#{name} {op}")
                elif len(first) == 1:
                    options.append("ID")
                    args = first
                else:
                    args = first
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after #{name} {op}: the command stands alone in its block",
            )
        return Hash(self.raw, self.number, f"{name} {op}", options, args)

    # --- kinematic transformations (issue 35, docs/kinematics.md) -----------------------------------------
    def kinematic(self, command: str) -> Stmt:
        """``#KIN ID [[<id>]]``, ``#TRAFO ON|OFF`` (``#RTCP ON|OFF``), ``#TOOL ORI CS [OFF]``, ``#CYL ..``,
        ``#CAXTRACK ON|OFF [..]``, ``#SET AX [FAST] [<name>, <number>, <index>] ..``: the statement whose
        ``options`` and ``args``/``params`` ``nc/effects.py`` turns into the decoder's kinematic commands."""
        options: list[str] = []
        args: list[Expr] = []
        params: dict[str, Expr] = {}
        if command == "KIN ID":
            self.blanks()
            if self.peek() == "[":
                self.pos += 1
                self.depth += 1
                args.append(self.expression(stop_at_blank=False))
                self.expect("]", "after #KIN ID [<id>")
                self.depth -= 1
        elif command in ("TRAFO", "RTCP"):
            word = next((w for w in ("ON", "OFF") if self.keyword(w)), None)
            if word is None:
                self.fail(
                    A_NOT_SIMULATED,
                    f"#{command} {self.word_at(self.pos) if self.pos < self.n else ''}: simulated are "
                    f"#{command} "
                    "ON and OFF (multi-step transformations are not): see docs/nc-language.md",
                )
            options.append(word)
            command = "TRAFO"
        elif command == "TOOL ORI":
            if not self.keyword("CS"):
                self.fail(
                    A_NOT_SIMULATED, "#TOOL ORI: only #TOOL ORI CS is simulated: see docs/nc-language.md"
                )
            command = "TOOL ORI CS"
            if self.keyword("OFF"):
                options.append("OFF")
        elif command == "CYL":
            self.cylinder(options, params)
        elif command == "CAXTRACK":
            self.caxtrack(options, params)
        else:
            self.set_axes(options, args)
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after #{command}: the command stands alone in its block",
            )
        return Hash(self.raw, self.number, command, options, args, params=params)

    def _bracket_entries(self, what: str, read: Callable[[str], None]) -> None:
        """``[KEY=value KEY value, FLAG ..]``: ``read(key)`` reads each entry's value after its key."""
        self.expect("[", f"after {what}")
        self.depth += 1
        while True:
            self.blanks()
            if self.peek() == "]":
                self.pos += 1
                break
            if self.peek() == ",":
                self.pos += 1
                continue
            key = self.name()
            if not key:
                got = self.word_at(self.pos) if self.pos < self.n else "the end of the block"
                self.fail(A_CONTROL_SYNTAX, f"{what} [..]: unexpected {got!r}")
            read(key)
        self.depth -= 1

    def _key_value(self, what: str, key: str, params: dict[str, Expr]) -> None:
        """``KEY=<expr>`` or ``KEY <expr>`` (the older spelling, ``ANGLIMIT 1``)."""
        if key in params:
            self.fail(A_CONTROL_SYNTAX, f"{what}: {key} given twice")
        self.blanks()
        if self.peek() == "=":
            self.pos += 1
            self.blanks()
        if self.at_end() or self.peek() in ("]", ","):
            self.fail(A_CONTROL_SYNTAX, f"{what}: {key} without a value")
        params[key] = self.expression(stop_at_blank=True)

    def _axis_name(self, what: str) -> str:
        self.blanks()
        if self.peek() == "=":
            self.pos += 1
            self.blanks()
        name = self.name()
        if not name:
            self.fail(A_CONTROL_SYNTAX, f"{what}: an axis name expected")
        return name

    def cylinder(self, options: list[str], params: dict[str, Expr]) -> None:
        """``#CYL OFF``; ``#CYL [<1st>, <2nd>, <3rd><radius>]`` (kinematic 15); ``#CYL ORI LATERAL
        [AX1=.. AX2=.. | AXNR1=.. AXNR2=.. RADIUS=..]`` (kinematic 90). ``options``: ``OFF``, ``LATERAL``,
        ``AX:<name>`` in order; ``params``: ``RADIUS``, ``AXNR1``, ``AXNR2``."""
        if self.keyword("OFF"):
            options.append("OFF")
            return
        if self.keyword("ORI"):
            if not self.keyword("LATERAL"):
                self.fail(
                    A_NOT_SIMULATED,
                    "#CYL ORI: only #CYL ORI LATERAL [..] is simulated: see docs/nc-language.md",
                )
            options.append("LATERAL")
            names: dict[str, str] = {}

            def read(key: str) -> None:
                if key in ("AX1", "AX2"):
                    names[key] = self._axis_name(f"#CYL ORI LATERAL [{key}")
                elif key in ("AXNR1", "AXNR2", "RADIUS"):
                    self._key_value("#CYL ORI LATERAL", key, params)
                else:
                    self.fail(
                        A_CONTROL_SYNTAX,
                        f"#CYL ORI LATERAL [..]: {key}: AX1=, AX2= (or AXNR1=, AXNR2=), RADIUS=",
                    )

            self._bracket_entries("#CYL ORI LATERAL", read)
            options.extend(f"AX:{names[k]}" for k in ("AX1", "AX2") if k in names)
            return
        self.expect("[", "after #CYL: #CYL [<1st axis>, <2nd axis>, <3rd axis><radius>] or #CYL OFF")
        self.depth += 1
        self.blanks()
        if self.keyword("RADIUS"):
            self.fail(
                A_NOT_SIMULATED,
                "#CYL [RADIUS=.. LIMIT=..] (the round tube projection, kinematic 78) is not simulated: see "
                "docs/kinematics.md",
            )
        for k in range(3):
            self.blanks()
            if k < 2:
                name = self.name()
            else:  # <3rd axis><radius>: the name's letters, then the radius (``Z35``, ``Z=35``, ``Z[R]``)
                start = self.pos
                while self.pos < self.n and self.u[self.pos].isalpha():
                    self.pos += 1
                name = self.u[start : self.pos]
                self.blanks()
                if self.peek() == "=":
                    self.pos += 1
                    self.blanks()
            if not name:
                self.fail(
                    A_CONTROL_SYNTAX, "#CYL [..]: three axis names, the third with the reference radius"
                )
            options.append(f"AX:{name}")
            self.blanks()
            if k < 2:
                self.expect(",", f"after #CYL's axis {name}")
        params["RADIUS"] = self.expression(stop_at_blank=False)
        self.expect("]", "after #CYL [..")
        self.depth -= 1

    def caxtrack(self, options: list[str], params: dict[str, Expr]) -> None:
        """``#CAXTRACK ON [ANGLIMIT=.. OFFSET=.. AX=<name> | AXNR=.. ..]``, ``#CAXTRACK OFF [ANGPOS=..]``."""
        on = self.keyword("ON")
        if not on and not self.keyword("OFF"):
            self.fail(A_CONTROL_SYNTAX, "#CAXTRACK: ON or OFF expected")
        options.append("ON" if on else "OFF")
        self.blanks()
        if self.at_end():
            return
        keys = ("ANGLIMIT", "OFFSET", "AXNR", "OPTALIGN", "ROTMODE", "SCALEFACT") if on else ("ANGPOS",)

        def read(key: str) -> None:
            if on and key == "AX":
                options.append("AX:" + self._axis_name("#CAXTRACK ON [AX"))
            elif on and key == "START_STROKE":
                options.append(key)
            elif key in keys:
                self._key_value(f"#CAXTRACK {options[0]}", key, params)
            else:
                self.fail(A_CONTROL_SYNTAX, f"#CAXTRACK {options[0]} [..]: {key}: " + ", ".join(keys))

        self._bracket_entries(f"#CAXTRACK {options[0]}", read)

    def set_axes(self, options: list[str], args: list[Expr]) -> None:
        """``#SET AX [FAST] [<name>, <number>, <index>] ..``: ``options`` the names (``AX:<name>``) and
        ``FAST``; ``args`` each entry's number and index expressions."""
        if self.keyword("FAST"):
            options.append("FAST")
        while True:
            self.blanks()
            if self.at_end():
                break
            self.expect("[", "around an axis of #SET AX [<name>, <number>, <index>]")
            self.depth += 1
            self.blanks()
            name = self.name()
            if not name or name[0] not in "ABCQUVWXYZ":
                self.fail(
                    A_CONTROL_SYNTAX,
                    "#SET AX [<name>, ..]: an axis name starts with A, B, C, Q, U, V, W, X, Y or Z",
                )
            options.append(f"AX:{name}")
            for what in ("logical axis number", "axis index"):
                self.expect(",", f"before the {what} of #SET AX [{name}, ..]")
                args.append(self.expression(stop_at_blank=False))
            self.blanks()
            if self.peek() == ",":
                self.fail(
                    A_NOT_SIMULATED,
                    f"#SET AX [{name}, ..]: the axis' options are not simulated: see docs/kinematics.md",
                )
            self.expect("]", f"after #SET AX [{name}, <number>, <index>")
            self.depth -= 1
        if not any(o.startswith("AX:") for o in options):
            self.fail(A_CONTROL_SYNTAX, "#SET AX without its axes [<name>, <number>, <index>]")

    def components(self, what: str) -> list[Expr]:
        """``[a, , c]``: up to six values, a gap is 0."""
        self.expect("[", f"after {what}")
        self.depth += 1
        out: list[Expr] = []
        while True:
            self.blanks()
            if self.peek() in (",", "]"):
                out.append(Const(0.0))
            else:
                out.append(self.expression(stop_at_blank=False))
            self.blanks()
            if self.peek() == ",":
                self.pos += 1
                continue
            self.expect("]", f"after the values of {what}")
            break
        self.depth -= 1
        if len(out) > 6:
            self.fail(
                A_CONTROL_SYNTAX, f"{what} [..]: at most 6 values (v1, v2, v3, φ1, φ2, φ3), got {len(out)}"
            )
        return out

    def meas_mode(self) -> Stmt:
        """``#MEAS MODE [ [<meas_type>] ]`` (207084683): the measuring type of G100 from here to the
        program's end; without a value the channel's default (P-CHAN-00057)."""
        self.blanks()
        args: list[Expr] = []
        if self.peek() == "[":
            self.pos += 1
            self.depth += 1
            self.blanks()
            args.append(self.expression(stop_at_blank=False))
            self.blanks()
            self.expect("]", "after #MEAS MODE [<type>")
            self.depth -= 1
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after #MEAS MODE: #MEAS MODE [<type>] stands alone in its block",
            )
        return Hash(self.raw, self.number, "MEAS MODE", [], args)

    def slope(self) -> Stmt:
        """``#SLOPE [TYPE=<ident> [NO_OPT=..]]`` and ``#SLOPE DEFAULT`` (207190411): the acceleration
        profile of the path from here on. ``options`` holds ``TYPE=<ident>`` (STEP, TRAPEZ, SIN2,
        HSC), ``NO_OPT=<0|1>`` or ``DEFAULT``."""
        options: list[str] = []
        if self.keyword("DEFAULT"):
            options.append("DEFAULT")
        else:
            self.expect("[", "after #SLOPE: #SLOPE [TYPE=STEP|TRAPEZ|SIN2|HSC] or #SLOPE DEFAULT")
            self.depth += 1
            while True:
                self.blanks()
                if self.peek() == "]":
                    self.pos += 1
                    self.depth -= 1
                    break
                if self.peek() == ",":
                    self.pos += 1
                    continue
                if self.keyword("TYPE"):
                    self.expect("=", "after #SLOPE [TYPE")
                    self.blanks()
                    start = self.pos
                    while self.pos < self.n and self.u[self.pos] in NAME_CHARS:
                        self.pos += 1
                    ident = self.u[start : self.pos]
                    if ident not in SLOPE_TYPES:
                        self.fail(
                            A_CONTROL_SYNTAX,
                            f"#SLOPE [TYPE={ident}]: the profiles are {', '.join(SLOPE_TYPES)}",
                        )
                    options.append(f"TYPE={ident}")
                elif self.keyword("NO_OPT"):
                    self.expect("=", "after #SLOPE [.. NO_OPT")
                    self.blanks()
                    if self.peek() not in ("0", "1") or (self.peek(1) not in ("", " ", "\t", "]", ",")):
                        self.fail(A_CONTROL_SYNTAX, "#SLOPE [.. NO_OPT=<0|1>]: 0 or 1")
                    options.append(f"NO_OPT={self.peek()}")
                    self.pos += 1
                else:
                    got = self.word_at(self.pos) if self.pos < self.n else "the end of the block"
                    self.fail(A_CONTROL_SYNTAX, f"#SLOPE [..]: unexpected {got!r} (TYPE=.., NO_OPT=..)")
            if not any(o.startswith("TYPE=") for o in options):
                self.fail(A_CONTROL_SYNTAX, "#SLOPE [..] without TYPE=STEP|TRAPEZ|SIN2|HSC")
        if not self.at_end():
            self.fail(
                A_CONTROL_SYNTAX,
                f"{self.word_at(self.pos)!r} after #SLOPE: #SLOPE [..] stands alone in its block",
            )
        return Hash(self.raw, self.number, "SLOPE", options, [])

    def motion_options(self, command: str, prefix: list[str] | None = None) -> Stmt:
        """``#CONTOUR MODE [ON|OFF] [<type> KEY=<expr> ...]``, ``#HSC [ON|OFF] [OPMODE 1 CONTERROR 0.1]``,
        ``#SPLINE ON|OFF|TYPE AKIMA``: the words (``options``) and the values (``params``), checked and
        evaluated by the interpreter. A value follows ``=`` or, inside the brackets, a blank (``#HSC``'s
        ``OPMODE 1``); commas between the entries are allowed (the manual's ``[DEV, PATH_DEV=5]``)."""
        options: list[str] = list(prefix or [])
        params: dict[str, Expr] = {}
        inside = False
        while True:
            self.blanks()
            if self.at_end():
                break
            char = self.peek()
            if char == "[" and not inside:
                self.pos += 1
                inside = True
                continue
            if char == "]" and inside:
                self.pos += 1
                inside = False
                continue
            if char == "," and inside:
                self.pos += 1
                continue
            start = self.pos
            key = self.name()
            if not key:
                self.fail(A_CONTROL_SYNTAX, f"#{command}: unexpected {self.word_at(start)!r}")
            if key in params or key in options:
                self.fail(A_CONTROL_SYNTAX, f"#{command}: {key} given twice")
            self.blanks()
            nxt = self.peek()
            if nxt == "=" or (inside and nxt != "" and (nxt.isdigit() or nxt in "+-.")):
                if nxt == "=":
                    self.pos += 1
                    self.blanks()
                if self.at_end() or self.peek() in ("]", ","):
                    self.fail(A_CONTROL_SYNTAX, f"#{command}: {key}= without a value")
                saved = self.depth
                self.depth = 0
                try:
                    # inside the brackets a value is a whole expression, blanks and all (the manual's
                    # ``[DEV, PATH_DEV = V.G.WZ_AKT.R / 100]``); it ends at a word that is no operator
                    params[key] = self.expression(stop_at_blank=not inside)
                finally:
                    self.depth = saved
            else:
                options.append(key)
        if inside:
            self.fail(A_CONTROL_SYNTAX, f"#{command}: ']' missing")
        return Hash(self.raw, self.number, command, options, [], params=params)

    def vector_limit(self) -> Stmt:
        """``#VECTOR LIMIT ON|OFF [ [ACC=..] [DEC=..] [RADIAL_ACC=..] [RADIAL_JERK=..] [JERK=..]
        [TRANS_ACC=..] [VEL=..] [FEED] [RAPID] ]``, ``#VECTOR LIMIT ON|OFF ALL`` (PM 207477899): a limit
        with its value, or without one (the channel parameter's default)."""
        stmt = self.motion_options("VECTOR LIMIT")
        assert isinstance(stmt, Hash)
        words = [w for w in stmt.options if w not in ("ON", "OFF")]
        switch = [w for w in stmt.options if w in ("ON", "OFF")]
        if len(switch) != 1 or stmt.options[0] not in ("ON", "OFF"):
            self.fail(A_CONTROL_SYNTAX, "#VECTOR LIMIT: ON or OFF expected (#VECTOR LIMIT ON [VEL=..])")
        known = (*VECTOR_LIMITS, "FEED", "RAPID", "ALL")
        for key in [*words, *stmt.params]:
            if key not in known:
                self.fail(
                    A_CONTROL_SYNTAX,
                    f"#VECTOR LIMIT: unknown keyword {key!r} (ACC, DEC, RADIAL_ACC, RADIAL_JERK, JERK, "
                    "TRANS_ACC, VEL, FEED, RAPID, ALL)",
                )
        for key in stmt.params:
            if key in ("FEED", "RAPID", "ALL"):
                self.fail(A_CONTROL_SYNTAX, f"#VECTOR LIMIT: {key} takes no value")
        if "ALL" in words and (len(words) > 1 or stmt.params):
            self.fail(A_CONTROL_SYNTAX, "#VECTOR LIMIT ON|OFF ALL stands alone")
        return stmt

    def vector_old(self, command: str) -> Stmt:
        """The older ``#VECTORVEL ON``, ``#VECTORVEL [5000] ON``, ``#VECTORVEL ON [5000]``, ``#VECTORVEL OFF``
        and ``#VECTORACC ..`` likewise (PM 207477899: replaced by ``#VECTOR LIMIT``, still accepted): read
        as ``#VECTOR LIMIT ON|OFF [VEL=..]`` / ``[ACC=..]``."""
        key = "VEL" if command == "VECTORVEL" else "ACC"
        switch = ""
        value: Expr | None = None
        while True:
            self.blanks()
            if self.at_end():
                break
            if self.peek() == "[" and value is None:
                self.pos += 1
                self.blanks()
                value = self.bracket_value()
                self.blanks()
                self.expect("]", f"after the value of #{command} [..]")
                continue
            start = self.pos
            word = self.name()
            if word in ("ON", "OFF") and not switch:
                switch = word
                continue
            self.fail(A_CONTROL_SYNTAX, f"#{command}: unexpected {self.word_at(start)!r} (ON [<value>], OFF)")
        if not switch:
            self.fail(A_CONTROL_SYNTAX, f"#{command}: ON or OFF expected")
        params: dict[str, Expr] = {key: value} if value is not None else {}
        options = [switch] if value is not None else [switch, key]
        return Hash(self.raw, self.number, "VECTOR LIMIT", options, [], params=params)

    def channel_init(self) -> Stmt:
        """``#CHANNEL INIT [CMDPOS|ACTPOS { AX=<name> | AXNR=.. } ]`` (PM 206703627, 206709515): alone in
        its block; a keyword twice or CMDPOS with ACTPOS is the kernel's 21507."""
        self.blanks()
        self.expect("[", "after #CHANNEL INIT (#CHANNEL INIT [CMDPOS])")
        options: list[str] = []
        args: list[Expr] = []
        axes: list[str] = []
        while self.next_entry("#CHANNEL INIT"):
            start = self.pos
            key = self.name()
            if key in ("CMDPOS", "ACTPOS"):
                if options:
                    self.fail(
                        A_CHANNEL_INIT, f"#CHANNEL INIT: {key} after {options[0]} (one of CMDPOS, ACTPOS)"
                    )
                options.append(key)
                continue
            if key not in ("AX", "AXNR"):
                self.fail(
                    A_CONTROL_SYNTAX,
                    f"#CHANNEL INIT: unexpected {self.word_at(start)!r} (CMDPOS, ACTPOS, AX=<name>, AXNR=..)",
                )
            if not options:
                self.fail(A_CHANNEL_INIT, f"#CHANNEL INIT: {key} before CMDPOS or ACTPOS")
            self.blanks()
            self.expect("=", f"after {key} ({key}=..)")
            self.blanks()
            if key == "AX":
                axis = self.name()
                if not axis:
                    self.fail(A_CONTROL_SYNTAX, "#CHANNEL INIT: AX= without an axis name")
                if axis in axes:
                    self.fail(A_CHANNEL_INIT, f"#CHANNEL INIT: axis {axis} programmed twice")
                axes.append(axis)
            else:
                args.append(self.bracket_value())
        if not options:
            self.fail(A_CONTROL_SYNTAX, "#CHANNEL INIT [..]: CMDPOS or ACTPOS expected")
        if not self.at_end():
            self.fail(
                A_CHANNEL_INIT, f"#CHANNEL INIT must stand alone in its block: {self.word_at(self.pos)!r}"
            )
        return Hash(self.raw, self.number, "CHANNEL INIT", options + [f"AX:{a}" for a in axes], args)

    def file_name(self, named: bool = False) -> Stmt:
        """``#FILE NAME [MSG="report.txt" G803="safe.nc"]`` (207504523; older ``#FILENAME``): the file
        ``#MSG SAVE`` writes to, the programs of the implicit calls G80..G89 / G800..G839 (PM 206278923)."""
        if not named and not self.keyword("NAME"):
            rest = self.word_at(self.pos) if self.pos < self.n else ""
            self.fail(
                A_NOT_SIMULATED,
                f"#FILE {rest}: only #FILE NAME is simulated (the engine does no file operations): "
                "see docs/nc-language.md",
            )
        self.expect("[", "after #FILE NAME")
        files: dict[str, str] = {}
        variables: dict[str, Expr] = {}
        while True:
            self.blanks()
            if self.peek() == "]":
                self.pos += 1
                break
            if self.pos >= self.n:
                self.fail(A_CONTROL_SYNTAX, "#FILE NAME [: ']' missing")
            key = self.name()
            if not key:
                self.fail(A_CONTROL_SYNTAX, f"#FILE NAME: unexpected {self.word_at(self.pos)!r}")
            self.blanks()
            if self.peek() == "=":
                self.pos += 1
                self.blanks()
            if key == "MSG" and self.peek() == "V" and self.peek(1) == ".":
                # MSG=V.E.TEACH_FILE_NAME: the name in a string variable, read when the command runs
                variables[key] = self.variable()
                continue
            if self.peek() != '"':
                self.fail(
                    A_CONTROL_SYNTAX,
                    f'#FILE NAME: {key}= needs a file name in quotes ({key}="name") or a string variable',
                )
            close = self.code.find('"', self.pos + 1)
            if close < 0:
                self.fail(A_CONTROL_SYNTAX, "#FILE NAME: quote not closed")
            value = self.code[self.pos + 1 : close]
            self.pos = close + 1
            implicit = key[:1] == "G" and key[1:].isdigit() and int(key[1:]) in IMPLICIT_G_CODES
            if key != "MSG" and not implicit:
                self.fail(
                    A_NOT_SIMULATED,
                    f"#FILE NAME [{key}=..]: not simulated; MSG= (the file of #MSG SAVE) and G80..G89, "
                    "G800..G839 (the programs of the implicit calls) are",
                )
            if not value or len(value) > MAX_NAME:
                self.fail(A_LIMIT, f'#FILE NAME [{key}=".."]: a file name has 1 to {MAX_NAME} characters')
            files[key] = value
        if not self.at_end():
            self.fail(A_CONTROL_SYNTAX, f"{self.word_at(self.pos)!r} after #FILE NAME [..]")
        return Hash(self.raw, self.number, "FILE NAME", [], [], files, params=variables)
