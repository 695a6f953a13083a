"""The NC language's tables, as data in one place (N-01..N-08): the alarm numbers of the front end, the
bounds of its inputs, the control words and how they nest, the ``#`` commands and the G codes - for each,
whether it is simulated or refused and with which alarm.

Adding a ``#`` command is a row of :data:`HASH_COMMANDS` (its spelling) and its reader in
``nc/hash_parser.py`` (the statement) and handler in ``nc/effects.py`` (what it does when it runs);
adding a G code is its entry in one of the G code tables below and its meaning in the decoder.
docs/nc-language.md lists what is simulated and what stays refused, with the manual's pages.
"""

from __future__ import annotations

import re
from typing import Final

from hli_server.engine.nc import parser as word_parser

# --- alarm numbers (hli_server/engine/alarms.py) -----------------------------------------------------
A_UNKNOWN_WORD: Final = 910100
A_BAD_NUMBER: Final = 910101
A_UNKNOWN_G: Final = 910102
A_TWICE: Final = 910103
A_UNKNOWN_HASH: Final = 910109
A_NOT_SIMULATED: Final = 910110
A_UNKNOWN_AXIS: Final = 910107
A_BAD_N: Final = 910108
A_RANGE: Final = 910111
A_LIMIT: Final = 914020
"""A bounded input over its bound: a line, an expression, a string."""
A_DECLARATION: Final = 914008
A_CONTROL_SYNTAX: Final = 914015
A_COMMENT_OPEN: Final = 914016
# the kernel's IDs (TF5200 diagnosis pages, docs/nc-language.md)
A_IF_EXTRA: Final = 20212
A_ELSE_EXTRA: Final = 20215
A_ELSEIF_EXTRA: Final = 20217
A_ENDIF_EXTRA: Final = 20219
A_DEFAULT_EXTRA: Final = 20224
A_WHILE_EXTRA: Final = 20235
A_ENDWHILE_EXTRA: Final = 20238
A_DO_EXTRA: Final = 20239
A_ENDDO_EXTRA: Final = 20241
A_COND_FIRST: Final = 20593
A_GOTO_CHAR: Final = 20839
A_AFTER_CALL: Final = 21542
A_UNKNOWN_G_FUNCTION: Final = 20131
"""The kernel's "Unknown G function": an implicit call G80..G89 / G800..G839 without a subprogram
assigned (P-CHAN-00160..00169, P-CHAN-00187, ``#FILE NAME [G8xx=..]``; PM 206278923)."""
# the interpreter's: the kernel's (TF5200 diagnosis) and the project's (914xxx)
A_STACK_OVERFLOW: Final = 20360
A_OPEN_VALID: Final = 20375
A_OPEN_INVALID_LOCAL: Final = 21500
A_OPEN_INVALID_MAIN: Final = 21501
A_OPEN_INVALID_GLOBAL: Final = 21502
A_CYCLE_PARAMETER: Final = 21382
A_VE_READ_DENIED: Final = 20097
"""A read of a V.E. variable that is WRITE_ONLY for NC programs (P-EXTV-00006)."""
A_VE_WRITE_DENIED: Final = 20100
"""A write of a V.E. variable that is READ_ONLY for NC programs (P-EXTV-00006)."""
A_UNDECLARED: Final = 914003
A_READ_ONLY: Final = 914004
A_INDEX: Final = 914005
A_NOT_WRITTEN: Final = 914007
A_NOT_FOUND: Final = 914010
A_LABEL: Final = 914013
A_NESTING: Final = 914014
A_STEP: Final = 914021
A_SUB_END: Final = 914030
A_MESSAGE: Final = 914031
A_MAIN_RETURN: Final = 914032
A_DRIVE_READ: Final = 140032
"""Warning: error while reading an ident (``#IDENT RD``; DG 265855883)."""
A_DRIVE_READ_ONLY: Final = 50357
"""SERCOS parameter: datum not changeable (``#IDENT WR``; DG 257826443)."""
A_DWELL_RANGE: Final = 20751
"""``#TIME``: dwell time out of range (DG 252425611)."""
A_HUEMNOS_TOOL: Final = 20861
"""A HÜMNOS tool (sister, variant) only with the corresponding tool management (DG 252795531)."""
A_UNKNOWN_AXIS_NAME: Final = 20797
"""Unknown axis designation in a command that names axes (DG 252577931)."""
A_RT_ID: Final = 22003
"""A realtime cycle without its ID where DEF or SCOPE=GLOBAL needs one (TF5261 562766219)."""
A_APPROXIMATED: Final = 911041
A_CHANNEL_INIT: Final = 21507
"""The kernel's "double programming in #CHANNEL INIT" (DG 254971531): keywords twice or in invalid
combinations."""
VECTOR_LIMITS: Final = ("ACC", "DEC", "RADIAL_ACC", "RADIAL_JERK", "JERK", "TRANS_ACC", "VEL")
"""``#VECTOR LIMIT ON/OFF [..]``'s limits (PM 207477899); ``VEL`` [mm/min] is simulated, the others are
accepted with warning 911041."""
VECTOR_VELOCITY_DEFAULT: Final = 2_000_000_000.0
"""P-CHAN-00090 vector.velocity's default [mm/min]: ``#VECTOR LIMIT ON [VEL]`` without a value."""
"""Warning: a construct that only shapes the path runs approximated within a documented tolerance (once per
program and construct; docs/nc-language.md, "Refusals and approximations")."""
A_MSG_VALUES: Final = 20721
"""#MSG: the number of values does not match the format elements (the kernel's ID 20721)."""
A_MSG_FORMAT: Final = 21232
"""#MSG: an unknown format element (the kernel's ID 21232)."""
A_STRING_LENGTH: Final = 21870
"""A string exceeds its maximum length (the kernel's ID 21870): a #MSG text, or a format element's width
or precision that would make it so."""

MAX_EXPRESSION_DEPTH: Final = 64
"""Brackets and operators nested deeper than this are alarm 914020 (a bounded recursion)."""
MAX_EXPRESSION_NODES: Final = 2000
"""Operands and operators in one block beyond this are alarm 914020."""
MAX_STRING: Final = 255
"""Characters of a string literal (the kernel's STRING type holds up to 126; messages up to 255)."""
MAX_NAME: Final = 83
"""Characters of a program name in ``L name`` (the manual: "max 83 characters")."""
MAX_VAR_LINES: Final = 10_000
"""Lines of one ``#VAR ... #ENDVAR`` block or one ``#COMMENT`` block before it counts as unclosed."""
MAX_CALL_DEPTH: Final = 20
"""Program levels (main program, subroutines, cycles) nested at most; deeper is ID 20360 (a recursion)."""
MAX_OPEN_BLOCKS: Final = 64
"""Control blocks open at once in one program level (the kernel's limit is not public)."""
MEAS_TYPES: Final = 7
"""Measuring types of ``#MEAS MODE`` (P-CHAN-00057: 1 .. 7)."""
MAX_MESSAGE: Final = 255
"""Characters of a ``#MSG`` text after formatting."""

# --- control keywords ---------------------------------------------------------------------------------
C_IF: Final = "IF"
C_ELSEIF: Final = "ELSEIF"
C_ELSE: Final = "ELSE"
C_ENDIF: Final = "ENDIF"
C_SWITCH: Final = "SWITCH"
C_CASE: Final = "CASE"
C_DEFAULT: Final = "DEFAULT"
C_ENDSWITCH: Final = "ENDSWITCH"
C_WHILE: Final = "WHILE"
C_ENDWHILE: Final = "ENDWHILE"
C_DO: Final = "DO"
C_ENDDO: Final = "ENDDO"
C_REPEAT: Final = "REPEAT"
C_UNTIL: Final = "UNTIL"
C_FOR: Final = "FOR"
C_ENDFOR: Final = "ENDFOR"
C_BREAK: Final = "BREAK"
C_CONTINUE: Final = "CONTINUE"
C_GOTO: Final = "GOTO"
# conditional interpretation #IF / #ELSE / #ENDIF
C_HASH_IF: Final = "#IF"
C_HASH_ELSE: Final = "#ELSE"
C_HASH_ENDIF: Final = "#ENDIF"

CONTROL_WORDS: Final = frozenset(
    (
        C_IF,
        C_ELSEIF,
        C_ELSE,
        C_ENDIF,
        C_SWITCH,
        C_CASE,
        C_DEFAULT,
        C_ENDSWITCH,
        C_WHILE,
        C_ENDWHILE,
        C_DO,
        C_ENDDO,
        C_REPEAT,
        C_UNTIL,
        C_FOR,
        C_ENDFOR,
        C_BREAK,
        C_CONTINUE,
        C_GOTO,
    )
)
ALONE: Final[dict[str, int]] = {
    C_ELSE: A_ELSE_EXTRA,
    C_ENDIF: A_ENDIF_EXTRA,
    C_DEFAULT: A_DEFAULT_EXTRA,
    C_ENDWHILE: A_ENDWHILE_EXTRA,
    C_DO: A_DO_EXTRA,
    C_ENDSWITCH: A_CONTROL_SYNTAX,
    C_REPEAT: A_CONTROL_SYNTAX,
    C_ENDFOR: A_CONTROL_SYNTAX,
    C_BREAK: A_CONTROL_SYNTAX,
    C_CONTINUE: A_CONTROL_SYNTAX,
}
"""Control words that stand alone in their block, and the kernel's ID when something follows."""
CONDITION_ONLY: Final[dict[str, int]] = {
    C_IF: A_IF_EXTRA,
    C_ELSEIF: A_ELSEIF_EXTRA,
    C_WHILE: A_WHILE_EXTRA,
    C_ENDDO: A_ENDDO_EXTRA,
    C_UNTIL: A_CONTROL_SYNTAX,
    C_CASE: A_CONTROL_SYNTAX,
    C_SWITCH: A_CONTROL_SYNTAX,
}
"""Control words followed by their condition (or value) only."""
OPENING: Final = frozenset((C_IF, C_SWITCH, C_WHILE, C_DO, C_REPEAT, C_FOR))
"""Control words that open a control block."""
CLOSING: Final[dict[str, str]] = {
    C_ENDIF: C_IF,
    C_ENDSWITCH: C_SWITCH,
    C_ENDWHILE: C_WHILE,
    C_ENDDO: C_DO,
    C_UNTIL: C_REPEAT,
    C_ENDFOR: C_FOR,
}
"""Control words that close a block, and the word that opened it."""
END_OF: Final[dict[str, str]] = {v: k for k, v in CLOSING.items()}
MIDDLE: Final[dict[str, str]] = {
    C_ELSE: C_IF,
    C_ELSEIF: C_IF,
    C_CASE: C_SWITCH,
    C_DEFAULT: C_SWITCH,
    C_HASH_ELSE: C_HASH_IF,
    C_HASH_ENDIF: C_HASH_IF,
}
"""Control words inside a block, and the word that opened it."""
LOOPS: Final = frozenset((C_WHILE, C_DO, C_REPEAT, C_FOR))
A_UNEXPECTED: Final[dict[str, int]] = {
    C_ELSE: 20214,
    C_ELSEIF: 20216,
    C_ENDIF: 20218,
    C_CASE: 20221,
    C_DEFAULT: 20223,
    C_ENDSWITCH: 20225,
    C_ENDFOR: 20232,
    C_ENDWHILE: 20237,
    C_BREAK: 20243,
    C_CONTINUE: 20244,
    C_ENDDO: 914017,
    C_UNTIL: 914017,
    C_HASH_ELSE: 914017,
    C_HASH_ENDIF: 914017,
}
"""A closing or middle control word without its opening one: the kernel's "Unexpected ..." IDs."""

# --- the # commands -----------------------------------------------------------------------------------
KERNEL_HASH_COMMANDS: Final = frozenset(
    (
        "ACS",
        "ADD",
        "AKIMA",
        "ANG",
        "AX",
        "BACKWARD",
        "BCS",
        "BLOCKSEARCH",
        "CACHE",
        "CALL",
        "CAX",
        "CAXTRACK",
        "CHANNEL",
        "CHF",
        "CHR",
        "CLEAR",
        "COMMAND",
        "CONTOUR",
        "CORNER",
        "CS",
        "CYL",
        "DELETE",
        "DEL",
        "DIST",
        "DISTANCE",
        "DISABLE",
        "DRIVE",
        "DYNAMIC",
        "ECS",
        "EDGE",
        "EDM",
        "ENABLE",
        "ERROR",
        "EXPL",
        "EXPORT",
        "EXTCOMP",
        "FACE",
        "FF",
        "FGROUP",
        "FILTER",
        "FREE",
        "FRC",
        "GANTRY",
        "GEAR",
        "GET",
        "HANDWHEEL",
        "HSC",
        "IDENT",
        "INIT",
        "JOG",
        "KIN",
        "LAH",
        "LOAD",
        "LOCK",
        "UNLOCK",
        "LIMIT",
        "MACHINE",
        "MAIN",
        "MANUAL",
        "MCS",
        "MEAS",
        "NIBBLE",
        "OPTIONAL",
        "ORI",
        "OTC",
        "OVERRIDE",
        "PSET",
        "PRESET",
        "PTP",
        "PUNCH",
        "PUT",
        "RETAIN",
        "RND",
        "ROTATION",
        "RT",
        "SAVE",
        "SCALE",
        "SEGMENTATION",
        "SET",
        "SIGNAL",
        "SINGLE",
        "SLOPE",
        "SPLINE",
        "STOP",
        "STROKE",
        "SUPPRESS",
        "SYNC",
        "TANGFEED",
        "TIME",
        "TIMER",
        "TLAX",
        "TLC",
        "TOOL",
        "TRACK",
        "TRAFO",
        "TRANSFORM",
        "TRANSVELMIN",
        "TRC",
        "TURN",
        "VECTOR",
        "VIB",
        "VOLCOMP",
        "WAIT",
        "WCS",
    )
)
"""``#`` commands of the kernel (the programming manual's command overview, as ISG's editor lists them);
any of them that the simulator does not model is refused by name with alarm 910110, any other ``#``
word with 910109."""
MOTION_FUNCTIONS: Final[dict[str, str]] = {
    "TRC": "tool radius compensation options (#TRC)",
}
"""Motion functions not simulated (N-08): refused by name with 910110 (docs/nc-language.md)."""
REFUSED_HASH: Final[dict[str, str]] = {}
"""Refused with their own message (M-26): docs/nc-language.md says what simulating them
would take."""


class HashRule:
    """How the front end handles one ``#`` command: ``forms`` are the spellings it simulates (``""``: the
    command word alone, ``#MSG``; ``"MODE"``: ``#MEAS MODE``), read by ``nc/hash_parser.py`` and run by
    ``nc/effects.py``; any other spelling is refused with ``alarm`` and ``message``."""

    __slots__ = ("alarm", "forms", "message")

    def __init__(self, forms: tuple[str, ...], alarm: int, message: str) -> None:
        self.forms = forms
        self.alarm = alarm
        self.message = message


def _kernel(name: str, forms: tuple[str, ...] = ()) -> HashRule:
    """A command of the kernel: refused by name with 910110 (but for the ``forms`` simulated)."""
    return HashRule(
        forms,
        A_NOT_SIMULATED,
        f"#{name} is a command of the kernel this simulator does not model: see docs/nc-language.md",
    )


_ALONE_FORM: Final = ("",)
_SIMULATED: Final = HashRule(_ALONE_FORM, 0, "")

HASH_COMMANDS: Final[dict[str, HashRule]] = {
    **{name: _kernel(name) for name in KERNEL_HASH_COMMANDS},
    **{
        name: HashRule(
            (), A_NOT_SIMULATED, f"#{name}: {what} is not simulated (N-08): see docs/nc-language.md"
        )
        for name, what in MOTION_FUNCTIONS.items()
    },
    **{
        name: HashRule(
            (),
            A_NOT_SIMULATED,
            f"#{name}: {what} are not simulated (the areas are monitored on the TCP in machine coordinates "
            'of cartesian main axes only): docs/nc-language.md, "What stays refused"',
        )
        for name, what in REFUSED_HASH.items()
    },
    # conditional interpretation (the interpreter's control flow)
    "IF": _SIMULATED,
    "ELSE": _SIMULATED,
    "ENDIF": _SIMULATED,
    # effects (nc/effects.py) and directives for the decoder
    "MSG": _SIMULATED,
    "FILE": _SIMULATED,
    "FILENAME": _SIMULATED,
    "FLUSH": _SIMULATED,
    "MEAS": _kernel("MEAS", ("MODE",)),
    "SLOPE": _SIMULATED,
    "CONTOUR": _kernel("CONTOUR", ("MODE",)),
    "HSC": _SIMULATED,
    "SPLINE": _SIMULATED,
    "SET": _kernel("SET", ("SPLINETYPE", "SPLINE", "ASPLINE", "AX")),
    "CS": _SIMULATED,
    "ACS": _SIMULATED,
    "ROTATION": _SIMULATED,
    "TIME": _SIMULATED,
    "AKIMA": _kernel("AKIMA", ("TRANS", "STARTVECTOR", "ENDVECTOR")),
    "FILTER": _SIMULATED,
    "RT": _kernel("RT", ("CYCLE",)),
    "FRC": _SIMULATED,
    "VECTOR": _kernel("VECTOR", ("LIMIT",)),
    "VECTORVEL": _SIMULATED,
    "VECTORACC": _SIMULATED,
    "CHANNEL": _kernel("CHANNEL", ("INIT",)),
    "IDENT": _kernel("IDENT", ("WR", "RD")),
    # kinematic transformations (issue 35, docs/kinematics.md): directives for the decoder
    "KIN": _kernel("KIN", ("ID",)),
    "TRAFO": _SIMULATED,
    "RTCP": _SIMULATED,
    "TOOL": _kernel("TOOL", ("PREP", "DATA", "LIFE", "ORI")),
    "CYL": _SIMULATED,
    "CAXTRACK": _SIMULATED,
    # the logical-block reader's (nc/reader.py): met here only where they are misplaced
    "VAR": HashRule(
        (), A_DECLARATION, "#VAR must stand alone on its line; the declarations follow on the next lines"
    ),
    "ENDVAR": HashRule((), A_DECLARATION, "#ENDVAR without #VAR"),
    "COMMENT": _SIMULATED,
}
"""Every ``#`` word the front end knows, by its first word (``#CONTROL AREA`` is the word parser's,
``nc/parser.py``); any other is alarm 910109."""
CORNER_AHEAD: Final = re.compile(r"(?<![A-Z0-9_.])G0*30[12](?![0-9.])")
"""A line that asks for a chamfer or rounding (G301/G302): the motion before it is held back for it."""
CORNER_LOOK_AHEAD: Final = 16
"""Lines the interpreter looks past for a G301/G302 after a motion block: blank, comment, control (``$..``)
and ``#`` command lines (the flow may not go there: holding the motion back is harmless, it only waits for
the next one)."""
CORNER_PASSES: Final = re.compile(r"\s*(?:/[0-9]*\s*)?(?:N\s*[0-9]+\s*:?\s*)?[$#]", re.ASCII | re.IGNORECASE)
"""A control statement or ``#`` command line the look-ahead for G301/G302 passes."""
RT_FREQUENCIES: Final = ("ONCE", "EDGE", "ALWAYS")
"""The qualifiers of a realtime cycle's ``$IF`` (TF5261 444686091)."""
RT_OPERATIONS: Final = ("DEF", "END", "START", "HOLD", "CONTINUE", "ABORT", "DELETE")
"""``#RT CYCLE``'s keywords (TF5261 562766219, 444681483)."""
RT_SCOPES: Final = ("BLOCK", "PROG", "GLOBAL")
FILTER_KEYS: Final = frozenset(("ORDER", "ORDER_TIME", "SHARE", "AX_DEV", "FCUT", "ACC_FACT", "QUALITY"))
"""``#FILTER [ON|OFF] [ORDER=.. ..]``'s parameters (TF5200 FIR filter, 542033291)."""
AKIMA_TRANSITIONS: Final = frozenset(("AUTO", "TANGENTIAL", "USER"))
"""``#AKIMA TRANS [START=.. END=..]``'s transition types (PM 207222923)."""
IDENT_WORDS: Final = frozenset(("SYN", "NO_WAIT", "SERC", "CAN"))
"""``#IDENT WR|RD [..]``'s keywords (PM 207352971, 207359627, 207365515): synchronised, no waiting, the
drive type."""
IDENT_VALUES: Final = frozenset(("AX", "AXNR", "ID", "VAL", "TYP", "DEC", "P"))
"""``#IDENT``'s entries with a value (``AX=X`` or ``AX X``, ``ID S-0-0104``, ``VAL 655.35``, ``P=P1``)."""
_SHOWN_AS: Final = {"FILE": "#FILE NAME", "COMMENT": "#COMMENT BEGIN/END"}
"""How 910109's list writes the commands whose word alone is not how they are written."""


def _simulated_spellings() -> str:
    """Every spelling :data:`HASH_COMMANDS` simulates, sorted (the table's order follows a set's, which
    changes from one process to the next), after the word parser's and the reader's own (``#CONTROL AREA``,
    ``#VAR``)."""
    shown = sorted(
        f"#{name} {form}" if form else _SHOWN_AS.get(name, f"#{name}")
        for name, rule in HASH_COMMANDS.items()
        for form in rule.forms
    )
    return ", ".join(["#CONTROL AREA", "#VAR/#ENDVAR", *shown])


UNKNOWN_HASH_HINT: Final = f"the commands simulated here: {_simulated_spellings()} (docs/nc-language.md)"
"""910109's list, made from the table, so that a command simulated later is named too (issue 37)."""
SLOPE_TYPES: Final = ("STEP", "TRAPEZ", "SIN2", "HSC")
"""``#SLOPE [TYPE=<ident>]``'s profiles (P-CHAN-00071's 0..3)."""
MSG_OPTIONS: Final = (
    "SAVE",
    "EXCLUSIVE",
    "INFO",
    "SYN_ACK",
    "SYN",
    "ACK",
    "ISG_DIAG_BED",
    "DIAG",
    "HMI",
    "PLC",
    "EVENT_LOGGER",
)
"""``#MSG``'s mode and receiver words (207145355, 207171211), in the order they are tried."""
TOOL_WRITES: Final = {"WZR": "radius", "WZ_AKT.R": "radius", "WZL": "length", "WZ_AKT.L": "length"}
"""V.G. variables a program may write: the active tool's radius and length (M-14)."""
CONTOUR_TYPES: Final = ("DEV", "DIST", "AUTO_DEV", "AUTO_VEL", "DIST_SOFT", "DIST_MASTER", "POS", "PTP")
"""The contouring types of ``#CONTOUR MODE`` (tf5200_programming_manual/475147915.html)."""
CONTOUR_KEYS: Final = frozenset(
    (
        "PATH_DEV",
        "TRACK_DEV",
        "PRE_DIST",
        "POST_DIST",
        "VEL",
        "RELEVANT_PATH",
        "RELEVANT_TRACK",
        "REMAIN_PART",
        "CHECK_JERK",
        "MAX_ANGLE",
        "SYM_DIST",
        "ACC_MAX",
        "ACC_MIN",
        "RAMP_TIME",
        "CONST_VEL",
        "TRACK_DIST",
        "MASTER_AX",
    )
)
CONTOUR_WORDS: Final = frozenset(("ON", "OFF", "PRE_ACTION", "INTER_ACTION", "POST_ACTION", *CONTOUR_TYPES))
HSC_KEYS: Final = frozenset(
    (
        "OPMODE",
        "CONTERROR",
        "PATH_DEV",
        "TRACK_DEV",
        "MERGE",
        "AUTO_OFF_PATH",
        "AUTO_OFF_TRACK",
        "AUTO_OFF_G00",
        "AUTO_OFF_G60",
        "MAX_PATH_LENGTH",
        "MAX_ANGLE",
    )
)
HSC_WORDS: Final = frozenset(("ON", "OFF", "BSPLINE"))
SPLINE_WORDS: Final = frozenset(("ON", "OFF", "TYPE", "AKIMA", "BSPLINE"))
DEVIATION_KEYS: Final = frozenset(("PATH_DEV", "CONTERROR"))
A_CORNER_DEVIATION: Final = 120129
"""The kernel's "corner deviation of polynomial contouring smaller than permissible minimum value"
(tf5200_diagnosis/264341387.html)."""

# --- axis- and spindle-specific syntax (``X[INDP_SYN ..]``, ``S[M3 REV500]``, ``S1[MC_MoveVelocity ..]``) ---
AXIS_FUNCTIONS: Final[dict[str, str]] = {
    "INDP_SYN": "synchronous independent axis motion",
    "INDP_ASYN": "asynchronous independent axis motion",
    "INDP": "independent axis motion (realtime cycles)",
    "OSC": "oscillating axis motion",
    "COMP": "axis compensation",
    "DIST_CTRL": "distance control",
    "OVERRIDE": "programmable axis override",
    "DYNAMIC": "programmable acceleration overload",
    "LIFT": "lifting/lowering an axis",
    "LIFT_START": "lifting an axis",
    "LIFT_END": "lowering an axis",
    "SYNC": "synchronising an axis in coordinated motion",
    "POLY": "axis polynomial",
}
"""The additional axis-specific functions ``<axis>[<function> ..]`` (PM 5252363631026771979): each moves an
axis of the path apart from the path, or changes its dynamics, so the monitors would answer for another
motion if it were approximated: refused by name with 910110 (docs/nc-language.md)."""
SPINDLE_WORDS: Final = frozenset(
    (
        "REV",
        "POS",
        "G74",
        "G167",
        "CALLAX",
        "PUTAX",
        "GET_DYNAMIC_DATA",
        "GET_DYNAMIK_DATA",
        "G130",
        "G135",
        "G136",
        "G137",
        "FEED_LINK",
        "OVERRIDE",
    )
)
"""Words of the spindle-specific syntax ``<spindle>[..]`` besides M/H functions and the PLCopen commands
``MC_..`` (PM 208178187, 208317067)."""

# --- G codes ---------------------------------------------------------------------------------------------
MOTION_G_CODES: Final[dict[int, str]] = {}
"""G codes of motion functions not simulated (N-08), refused by name with 910110 (none left: the TRC
selection methods and contour masking are approximated, :data:`TRC_G_CODES`)."""
TRC_G_CODES: Final[dict[int, str]] = {
    5: "tangential TRC selection/deselection",
    138: "direct TRC selection/deselection",
    141: "TRC contour masking",
    236: "direct TRC selection/deselection on the path",
    237: "perpendicular TRC selection/deselection",
    238: "TRC selection at an inside corner",
    239: "TRC selection/deselection without a block",
}
"""The TRC selection methods and contour masking (PM 207729163, 206480651): approximated by the indirect
selection G139 and no masking, with warning 911041 once per program (docs/nc-language.md)."""
VALUE_G_CODES: Final = frozenset((131, 231, 133, 134, 233, 334, 339))
"""G functions programmed with a value, ``G131=50`` (acceleration and ramp-time weightings)."""
AXIS_VALUE_G_CODES: Final = frozenset((130, 230, 132, 333, 338))
"""G functions whose axis words are weightings, ``G130 X70`` (not motion)."""
EXTRA_G_CODES: Final = VALUE_G_CODES | AXIS_VALUE_G_CODES
"""The weighting G codes the interpreter accepts beyond the word parser's (docs/nc-language.md)."""
UNIT_G_CODES: Final = frozenset((8, 9, 70, 71, 94, 95, 900, 901))
"""Units and words (M-06..M-09): G70/G71 inch/metric, G94/G95 feed per minute /
per revolution, G08/G09/G900/G901 acceleration at block start / deceleration at block end."""
CONTOUR_G_CODES: Final = frozenset((61, 64, 150, 151, 260, 261))
"""Polynomial contouring G61/G261/G260 (G64 as G261), spline interpolation G151/G150 (simulated as
contouring): M-20..M-23, docs/nc-language.md "Contouring"."""
INITIAL_STATE_G_CODES: Final = frozenset((139, 140))
"""G139 (indirect TRC selection/deselection, PM 207729163) and G140 (no contour masking, PM 206480651):
the kernel's initial states, the ones simulated; programmed, they change nothing."""
CORNER_G_CODES: Final = frozenset((301, 302))
"""Chamfers and roundings G301/G302 (PM 206609163): an element of the I word's size inserted in the corner
(``hli_server/engine/path/corners.py``)."""
KNOWN_G: Final = (
    word_parser.KNOWN_G_CODES
    | EXTRA_G_CODES
    | UNIT_G_CODES
    | CONTOUR_G_CODES
    | INITIAL_STATE_G_CODES
    | CORNER_G_CODES
    | frozenset(TRC_G_CODES)
)
"""Every G code simulated: the word parser's (``nc/parser.py``, ``KNOWN_G_CODES``) and the ones above."""
IMPLICIT_G_CODES: Final = frozenset(range(80, 90)) | frozenset(range(800, 840))
"""Implicit subprogram calls (PM 206278923 "Implicit subroutine calls"; N-11): G80..G89 and G800..G839 call
the global subprogram the channel assigns to them (nc/implicit.py)."""
MAX_IMPLICIT_PARAMETERS: Final = 50
"""Values in the brackets of an implicit call, ``G805[v1, v2, , v4]`` (PM 206278923: "a maximum of 50")."""
