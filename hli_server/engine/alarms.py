"""The one table of alarms: number, severity, reaction, text, where the number comes from.

The kernel's own numbers are used wherever the kernel documents one (B-04): the numbers the
function descriptions give (FCT-C14: 120484, 120486, 120499, 50961, 50962, 50706; FCT-C3: 70092,
70162; FCT-A3: 70082) and the IDs of the kernel's diagnosis pages (TF5200 / ISG kernel: software
limit switches 120002/120003 and 70021/70022, the ``#CONTROL AREA`` errors 21286, 21288, 21292,
21793, 21797, 50774, 50785, 50786, 120477, 120479, the G100 errors 20138, 50059, 50061, the NC
language's control blocks, subroutines and cycles 20212 .. 21542, docs/nc-language.md). Each such
row names its page (``page``). The project's own numbers live in the 9xxxxx range, grouped by
subject, only where the kernel has none; ``docs/alarms.md`` (generated from this table:
``hli-server alarms``) marks which is which and keeps the old project numbers that kernel IDs
replaced.

Reactions:

* ``PROGRAM_ABORT``: the channel's program is aborted, motion stops with the feedhold deceleration;
* ``AXIS_STOP``: the axes named by the monitor stop at once (with their own deceleration);
* ``REPORT``: warning only, nothing stops.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from schemas.events import Alarm

__all__ = ["ALARMS", "Alarm", "AlarmDef", "Reaction", "Severity", "alarm_def"]
# Alarm (one raised alarm) is a wire record: schemas.events.Alarm, re-exported here.


class Severity(StrEnum):
    ERROR = "error"
    WARNING = "warning"


class Reaction(StrEnum):
    PROGRAM_ABORT = "program_abort"
    AXIS_STOP = "axis_stop"
    REPORT = "report"


_DIAG = "https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/"
"""The kernel's diagnosis pages (TF5200, English); a row's ``page`` is one of them or another kernel page."""
_SLS = "https://infosys.beckhoff.com/content/1033/swlimit/15311258251.html"
"""The kernel's software limit switch description: "message [ID: 120002 or 120003]" for a programmed
position, "(ID: 70021 or 70022)" for an actual position beyond the limit."""
_C14 = "https://infosys.beckhoff.com/content/1033/tf5200_workspace_monitoring/291170571.html"
"""FCT-C14 as the kernel's online help shows it (activating work and protection areas)."""


@dataclass(frozen=True, slots=True)
class AlarmDef:
    number: int
    severity: Severity
    reaction: Reaction
    text: str
    source: str
    """Where the number comes from: the document (``FCT-C14``), the kernel's diagnosis (``kernel``),
    or ``project`` (the project's own number: the kernel documents none for this case)."""
    page: str = ""
    """The kernel's page that documents the number (diagnosis page or function description)."""
    replaces: tuple[int, ...] = ()
    """Project numbers this kernel ID replaced (docs/alarms.md keeps them for users who matched on them)."""

    @property
    def kernel(self) -> bool:
        """The kernel's own number (a document's or a diagnosis page's), not the project's."""
        return not self.source.startswith("project")


def _e(
    number: int,
    text: str,
    source: str,
    reaction: Reaction = Reaction.PROGRAM_ABORT,
    *,
    page: str = "",
    replaces: tuple[int, ...] = (),
) -> AlarmDef:
    return AlarmDef(number, Severity.ERROR, reaction, text, source, page, replaces)


def _w(number: int, text: str, source: str, *, page: str = "", replaces: tuple[int, ...] = ()) -> AlarmDef:
    return AlarmDef(number, Severity.WARNING, Reaction.REPORT, text, source, page, replaces)


_TABLE: tuple[AlarmDef, ...] = (
    # --- the documents' numbers -------------------------------------------------------------
    _e(120484, "Point outside the work area", "FCT-C14", page=_DIAG + "264828811.html"),
    _e(120486, "Path leaves the work area", "FCT-C14", page=_C14),
    _w(120499, "Active work/protection area cannot be cleared", "FCT-C14", page=_C14),
    _e(50961, "Manual mode selected outside the work area", "FCT-C14 (P-CHAN-00442)", page=_C14),
    _e(50962, "Manual mode selected inside a protection area", "FCT-C14 (P-CHAN-00442)", page=_C14),
    _e(
        50706,
        "Measuring move reached the end of the travel range without a probe signal",
        "FCT-C14 (P-CHAN-00268)",
        page="https://infosys.beckhoff.com/content/1033/tf5200_workspace_monitoring/291160331.html",
    ),
    _e(
        70092,
        "Axis collision monitoring: minimum distance of the pair violated",
        "FCT-C3",
        Reaction.AXIS_STOP,
        page="https://infosys.beckhoff.com/content/1033/tf5200_axis_collision_mon/286688651.html",
    ),
    _w(
        70162,
        "Axis collision monitoring: the two coll_offset values differ, the larger applies",
        "FCT-C3",
        page=_DIAG + "260159115.html",
    ),
    _e(
        70082,
        "Axis did not reach the exact-stop window within the settling time",
        "FCT-A3",
        Reaction.AXIS_STOP,
        page="https://infosys.beckhoff.com/content/1033/tf5200_axis_position_monitoring/92801291.html",
    ),
    # --- the kernel's diagnosis pages: software limit switches (E-06) --------------------------
    _e(
        120002,
        "Programmed position beyond the positive software limit switch",
        "kernel",
        page=_SLS,
        replaces=(911011,),
    ),
    _e(
        120003,
        "Programmed position beyond the negative software limit switch",
        "kernel",
        page=_SLS,
        replaces=(911010,),
    ),
    _e(
        70021,
        "Positive software limit switch actuated: actual position beyond it plus P-AXIS-00179",
        "kernel",
        Reaction.AXIS_STOP,
        page="https://www.isg-stuttgart.de/fileadmin/kernel/kernel-html/en-GB/259906699.html",
        replaces=(911012,),
    ),
    _e(
        70022,
        "Negative software limit switch actuated: actual position beyond it minus P-AXIS-00179",
        "kernel",
        Reaction.AXIS_STOP,
        page=_SLS,
        replaces=(911012,),
    ),
    # --- the kernel's diagnosis pages: #CONTROL AREA (FCT-C14) --------------------------------
    _e(
        21286,
        "Control area ID is out of data format",
        "kernel",
        page=_DIAG + "254057611.html",
        replaces=(912002,),
    ),
    _w(
        21288,
        "#CONTROL AREA END without a definition: the command has no effect",
        "kernel",
        page="https://infosys.beckhoff.com/content/1031/tf5200_diagnosis/254066315.html",
        replaces=(912002,),
    ),
    _e(21292, "Invalid control area ID programmed (ID 0)", "kernel", page=_DIAG + "254083723.html"),
    _e(
        21793,
        "G function not allowed during a control area definition",
        "kernel",
        page=_DIAG + "256046475.html",
        replaces=(912002,),
    ),
    _e(
        21797,
        "Too many axes in the control area definition, at most two allowed",
        "kernel",
        page="https://infosys.beckhoff.com/content/1031/tf5200_diagnosis/256063883.html",
        replaces=(912002,),
    ),
    _e(
        50774,
        "Area not saved: an active area cannot be overwritten",
        "kernel",
        page=_DIAG + "258831755.html",
        replaces=(912002,),
    ),
    _e(
        50785,
        "Only linear motion blocks G00/G01 can define a polygonal control area",
        "kernel",
        page=_DIAG + "258879627.html",
        replaces=(912002,),
    ),
    _e(
        50786,
        "Maximum number of points allowed for a polygonal control area exceeded",
        "kernel",
        page=_DIAG + "258883979.html",
        replaces=(912002,),
    ),
    _e(
        120129,
        "Corner deviation of polynomial contouring smaller than permissible minimum value",
        "kernel",
        page=_DIAG + "264341387.html",
    ),
    _e(
        120477,
        "Definition of the polygon is invalid: its lines intersect",
        "kernel",
        page=_DIAG + "264798347.html",
        replaces=(912002,),
    ),
    _e(
        120479,
        "The first block of a circular area definition must be linear",
        "kernel",
        page=_DIAG + "264807051.html",
        replaces=(912002,),
    ),
    # --- the kernel's diagnosis pages: G100 measuring moves (C14-23) --------------------------
    _e(
        20131,
        "Unknown G function (an implicit call G80..G89 / G800..G839 without a subprogram assigned)",
        "kernel",
        page="https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/206278923.html",
    ),
    _e(
        21507,
        "Double programming in #CHANNEL INIT (keywords twice or in invalid combinations)",
        "kernel",
        page=_DIAG + "254971531.html",
    ),
    _e(20138, "G100 is not allowed with the current measuring type", "kernel", page=_DIAG + "250906763.html"),
    _w(
        20685,
        "Dwell time programmed with additional axes (G04 takes the first main axis only)",
        "kernel",
        page=_DIAG + "252216715.html",
    ),
    _e(
        20014,
        "Dwell time is not programmed with the coordinate of the first main axis",
        "kernel",
        page=_DIAG + "250536843.html",
    ),
    _e(
        20007,
        "Spindle speed is 0",
        "kernel",
        page="https://infosys.beckhoff.com/content/1033/tccncdiagnosis/15651573131.html",
    ),
    _e(
        20751,
        "Dwell time (#TIME) out of range of permissible values",
        "kernel",
        page=_DIAG + "252425611.html",
    ),
    _e(
        22003,
        "Realtime cycle without its ID (needed with DEF or SCOPE=GLOBAL)",
        "kernel",
        page="https://infosys.beckhoff.com/content/1033/tf5261_realtime_cycles/562766219.html",
    ),
    _e(20008, "Feed rate in motion block is 0", "kernel", page=_DIAG + "250515083.html"),
    # --- the kernel's IDs: chamfers and roundings (G301/G302) ----------------------------------
    _e(20012, "Radius or bevel is 0 in G301/G302", "kernel", page=_DIAG + "250528139.html"),
    _e(
        20130,
        "Double-programmed chamfer/rounding selection (G301 and G302 in one block)",
        "kernel",
        page=_DIAG + "250885003.html",
    ),
    _w(
        20351,
        "No primary motion block for chamfer/rounding available",
        "kernel",
        page=_DIAG + "251381131.html",
    ),
    _w(20701, "Double programmed G301/G302 without motion block", "kernel", page=_DIAG + "252268939.html"),
    _e(20800, "Chamfer value is out of data format", "kernel", page=_DIAG + "252590987.html"),
    # --- the kernel's IDs: tools and drive parameters (#TOOL, #IDENT) --------------------------
    _e(
        20861,
        "HUEMNOS tool only allowed with the corresponding tool management",
        "kernel",
        page=_DIAG + "252795531.html",
    ),
    _e(
        20797,
        "Unknown axis designation respectively character not allowed",
        "kernel",
        page=_DIAG + "252577931.html",
    ),
    _e(50357, "SERCOS parameter: datum not changeable", "kernel", page=_DIAG + "257826443.html"),
    _w(140032, "Error while reading ident", "kernel", page=_DIAG + "265855883.html"),
    _e(
        60131,
        "Feedrate per revolution with the spindle stopped (G95 without M3/M4 and S)",
        "kernel",
        page=_DIAG + "259219083.html",
    ),
    _e(
        50059,
        "Unable to measure with the axis: it is not a measuring axis (P-AXIS-00118)",
        "kernel",
        page=_DIAG + "257565323.html",
        replaces=(912011,),
    ),
    _e(
        50061,
        "Number of programmed axes exceeds the range of the measuring type",
        "kernel",
        page=_DIAG + "257574027.html",
        replaces=(912011,),
    ),
    _e(
        50052,
        "Probe already actuated when the measuring move starts",
        "kernel",
        page=_DIAG + "257543563.html",
    ),
    # --- the NC language: the kernel's IDs (TF5200 diagnosis pages; docs/nc-language.md) ----------------
    _e(20212, "After 'IF' only the condition is permissible", "kernel", page=_DIAG + "251115659.html"),
    _e(
        20214,
        "Unexpected ELSE: does not match the current control block",
        "kernel",
        page=_DIAG + "251124363.html",
    ),
    _e(
        20215,
        "'ELSE' must be programmed exclusively in the NC block",
        "kernel",
        page=_DIAG + "251128715.html",
    ),
    _e(
        20216,
        "Unexpected ELSEIF: does not match the current control block",
        "kernel",
        page=_DIAG + "251133067.html",
    ),
    _e(20217, "After 'ELSEIF' only the condition is permissible", "kernel", page=_DIAG + "251137419.html"),
    _e(
        20218,
        "Unexpected ENDIF: does not match the current control block",
        "kernel",
        page=_DIAG + "251141771.html",
    ),
    _e(
        20219,
        "'ENDIF' must be programmed exclusively in the NC block",
        "kernel",
        page=_DIAG + "251146123.html",
    ),
    _e(
        20221,
        "Unexpected CASE: does not match the current control block",
        "kernel",
        page=_DIAG + "251154827.html",
    ),
    _e(
        20223,
        "Unexpected DEFAULT: does not match the current control block",
        "kernel",
        page=_DIAG + "251163531.html",
    ),
    _e(
        20224,
        "'DEFAULT' must be programmed exclusively in the NC block",
        "kernel",
        page=_DIAG + "251167883.html",
    ),
    _e(
        20225,
        "Unexpected ENDSWITCH: does not match the current control block",
        "kernel",
        page=_DIAG + "251172235.html",
    ),
    _e(
        20232,
        "Unexpected ENDFOR: does not match the current control block",
        "kernel",
        page=_DIAG + "251202699.html",
    ),
    _e(20235, "After 'WHILE' only the condition is permissible", "kernel", page=_DIAG + "251215755.html"),
    _e(
        20721,
        "Number of parameters and the number of format specifiers do not match (#MSG)",
        "kernel",
        page=_DIAG + "252329867.html",
    ),
    _e(21232, "Unknown format string (#MSG)", "kernel", page=_DIAG + "253866123.html"),
    _e(21870, "String exceeds the maximum length", "kernel", page=_DIAG + "256359819.html"),
    _e(
        20237,
        "Unexpected ENDWHILE: does not match the current control block",
        "kernel",
        page=_DIAG + "251224459.html",
    ),
    _e(
        20238,
        "'ENDWHILE' must be programmed exclusively in the NC block",
        "kernel",
        page=_DIAG + "251228811.html",
    ),
    _e(20239, "'DO' must be programmed exclusively in the NC block", "kernel", page=_DIAG + "251233163.html"),
    _e(20241, "After 'ENDDO' only the condition is permissible", "kernel", page=_DIAG + "251241867.html"),
    _e(20243, "Unexpected BREAK: no valid open control block", "kernel", page=_DIAG + "251250571.html"),
    _e(20244, "Unexpected CONTINUE: no valid open control block", "kernel", page=_DIAG + "251254923.html"),
    _e(20360, "Stack overflow of subroutines (call depth exceeded)", "kernel", page=_DIAG + "251402891.html"),
    _w(20375, "Valid control blocks still open at program end", "kernel", page=_DIAG + "251459467.html"),
    _e(
        20593,
        "Conditional interpretation (#IF/#ELSE/#ENDIF) has to be the first command in the block",
        "kernel",
        page=_DIAG + "251929483.html",
    ),
    _e(20839, "The character after $GOTO is not permitted", "kernel", page=_DIAG + "252734603.html"),
    _e(21382, "Impermissible write/read access to cycle parameters", "kernel", page=_DIAG + "254440587.html"),
    _e(
        20097,
        "Variable read not permitted (a V.E. variable WRITE_ONLY for the NC)",
        "kernel",
        page=_DIAG + "250750091.html",
    ),
    _e(
        20100,
        "Write access to variable denied (a V.E. variable READ_ONLY for the NC)",
        "kernel",
        page=_DIAG + "250758795.html",
    ),
    _e(21462, "String for variable too long", "kernel", page=_DIAG + "254771339.html"),
    _w(
        21840,
        "External variable could not be initialised (P-EXTV-00013 init; the variable is set to 0)",
        "kernel",
        page=_DIAG + "256229259.html",
    ),
    _w(
        21841,
        "Variable for initialisation of external variables not permitted (only V.E.; the variable is 0)",
        "kernel",
        page=_DIAG + "256233611.html",
    ),
    _e(
        21500,
        "Invalid control blocks pending at local subroutine end",
        "kernel",
        page=_DIAG + "254941067.html",
    ),
    _e(21501, "Invalid control blocks pending at main program end", "kernel", page=_DIAG + "254945419.html"),
    _e(
        21502,
        "Invalid control blocks pending at global subroutine end",
        "kernel",
        page=_DIAG + "254949771.html",
    ),
    _e(
        21542,
        "No further NC commands allowed after a subroutine or cycle call",
        "kernel",
        page=_DIAG + "255123851.html",
    ),
    # --- the kernel's IDs: kinematic transformations (issue 35, docs/kinematics.md) ---------
    _e(
        292004, "Kinematic transformation: illegal argument for ACOS", "kernel", page=_DIAG + "267444363.html"
    ),
    _e(292005, "Kinematic transformation: illegal kinematic ID", "kernel", page=_DIAG + "267448715.html"),
    _e(
        292006,
        "Kinematic transformation: transformation not available",
        "kernel",
        page=_DIAG + "267453067.html",
    ),
    _e(292016, "Kinematic transformation: singular matrix", "kernel", page=_DIAG + "267496587.html"),
    _e(
        292040,
        "Kinematic transformation: invalid axis configuration programmed",
        "kernel",
        page=_DIAG + "267579275.html",
    ),
    _e(
        292045,
        "Selected orientation mode or rotation sequence unsupported by the transformation",
        "kernel",
        page="https://infosys.beckhoff.com/content/1033/tf5200_trafo_interface/441093515.html",
    ),
    _e(20687, "Kinematic change not allowed during active RTCP/TLC", "kernel", page=_DIAG + "252225419.html"),
    _e(
        20990,
        "The tool's kinematic ID differs from the active transformation's (P-TOOL-00011)",
        "kernel",
        page="https://infosys.beckhoff.com/content/1031/tf5200_tool_data/104788875.html",
    ),
    _e(20683, "Axis exchange not allowed with active RTCP/TLC", "kernel", page=_DIAG + "252208011.html"),
    _e(20312, "The requested logical axis is unknown", "kernel", page=_DIAG + "251350667.html"),
    _e(21256, "Multiple use of the same axis name", "kernel", page=_DIAG + "253966219.html"),
    _e(21257, "Multiple use of the same axis index", "kernel", page=_DIAG + "253970571.html"),
    _e(21258, "Multiple use of the same logical axis number", "kernel", page=_DIAG + "253974923.html"),
    _w(
        21250,
        "Active axis tracking (#CAXTRACK) at program end",
        "kernel",
        page="https://infosys.beckhoff.com/content/1033/tccncdiagnosis/15651584395.html",
    ),
    _e(21135, "Parameter of axis tracking is out of data format", "kernel", page=_DIAG + "253548427.html"),
    _e(120626, "Tracking axis on main axis index", "kernel", page=_DIAG + "265237899.html"),
    # --- project's own: kinematic transformations (913xxx) ----------------------------------
    _e(913000, "V.G.KIN write outside a kinematic data set", "project (K-01)"),
    _w(913001, "Kinematic type without public geometry simulated as the identity", "project (K-02)"),
    # --- project's own: NC program syntax (910xxx) ------------------------------------------
    _e(910100, "Unknown word in NC block", "project"),
    _e(910101, "Malformed number in NC block", "project"),
    _e(910102, "Unknown or unsupported G code", "project"),
    _e(910103, "Word programmed twice in one block", "project"),
    _e(910104, "Comment not closed", "project"),
    _e(910105, "Malformed #CONTROL AREA command", "project"),
    _e(910106, "Conflicting G codes in one block", "project"),
    _e(910107, "Unknown axis name", "project"),
    _e(910108, "Malformed block number", "project"),
    _e(910109, "Unknown # command", "project"),
    _e(910110, "Not supported by the simulator", "project"),
    _e(910111, "Number out of range in NC block", "project (E-04)"),
    # --- project's own: decoder and motion (911xxx) -----------------------------------------
    _e(911000, "No feed programmed for a feed move", "project"),
    _e(911001, "Circle: centre or radius inconsistent", "project"),
    _e(911002, "Circle: no centre programmed", "project"),
    _e(911003, "Axis not in the active plane or not a main axis", "project"),
    _w(911005, "Program ended without M30 / M02", "project"),
    _w(
        911013,
        "Manual motion stopped at a software limit or a manual mode limit",
        "project (E-06, P-MANU-00014)",
    ),
    _w(911020, "Program start refused: axes not referenced (reference them first)", "project"),
    _w(911021, "Command not allowed in this mode or state", "project"),
    _w(911022, "Program start refused: the axes still brake (after a reset or a stop)", "project"),
    _e(911030, "Drive error", "project", Reaction.AXIS_STOP),
    _w(
        911040,
        "Contouring, #HSC or spline type simulated as contouring with corner deviation",
        "project (M-23)",
    ),
    _w(
        911041,
        "Construct approximated within a documented tolerance (once per program; docs/nc-language.md)",
        "project (issue 33)",
    ),
    # --- project's own: work and protection areas (912xxx) ----------------------------------
    _e(912000, "Point inside a protection area", "project (FCT-C14)"),
    _e(912001, "Path enters a protection area", "project (FCT-C14)"),
    _e(912002, "Area definition invalid", "project (FCT-C14)"),
    _e(912003, "Area command invalid", "project (FCT-C14)"),
    _w(912004, "Manual motion stopped at a work/protection area boundary", "project (FCT-C14, P-MANU-00014)"),
    _e(912010, "Measuring move (G100) ended without a probe signal", "project (FCT-C14, C14-23)"),
    _e(912011, "Measuring move (G100) invalid", "project (FCT-C14, C14-23)"),
    # --- the kernel's IDs: coordinate systems and tool radius compensation (M-10..M-18) ----
    _e(20821, "(A)CS not defined", "kernel", page=_DIAG + "252664971.html"),
    _e(20676, "Invalid angle", "kernel", page=_DIAG + "252190603.html"),
    _e(
        90008,
        "Selection of tool radius compensation within circular motion block",
        "kernel",
        page=_DIAG + "261625739.html",
    ),
    _e(90017, "Tool radius greater or equal to contour radius", "kernel", page=_DIAG + "261660555.html"),
    _e(
        90031,
        "Tool radius exceeds range at channel block sequence circle-circle",
        "kernel",
        page=_DIAG + "261686667.html",
    ),
    # --- project's own: coordinate systems and tools (916xxx) ----------------------------------
    _e(
        916000, "Tool radius compensation: contour violation (the tool path crosses itself)", "project (M-18)"
    ),
    _e(916001, "Tool compensation data (D) not in the tool table", "project (M-14)"),
    _e(916002, "Coordinate system command invalid (#CS, #ACS, #CS ADD/SET/DEL)", "project (M-10)"),
    _e(
        916003,
        "Chamfer/rounding (G301/G302) would reverse the direction of a contour element",
        "project (issue 33)",
    ),
    # --- project's own: axis collision and position monitoring (913xxx) ----------------------
    _e(913000, "Collision pair may only move apart after a collision stop", "project (FCT-C3, C3-02)"),
    # --- project's own: the NC language where the kernel's ID is not public (914xxx) -----------
    _e(914000, "Malformed expression or statement", "project (N-03)"),
    _e(914001, "Division by zero", "project (N-03)"),
    _e(914002, "Value outside the domain of the operation or the range of the type", "project (N-03)"),
    _e(914003, "Variable not declared, or not given", "project (N-04)"),
    _e(914004, "Variable is read-only", "project (N-04)"),
    _e(914005, "Index or parameter number out of range", "project (N-04)"),
    _e(914006, "A string where a number is needed, or the other way round", "project (N-03)"),
    _e(914007, "P parameter read before it was written", "project (N-04)"),
    _e(914008, "Malformed declaration (#VAR)", "project (N-04)"),
    _e(914010, "Subroutine or cycle not found", "project (N-02)"),
    _e(914013, "Jump label of $GOTO not found", "project (N-06)"),
    _e(914014, "Control blocks nested too deeply", "project (N-06)"),
    _e(914015, "Malformed control statement", "project (N-06)"),
    _e(914016, "#COMMENT BEGIN without #COMMENT END", "project (N-01)"),
    _e(
        914017, "Unexpected ENDDO, UNTIL, #ELSE or #ENDIF: does not match the current block", "project (N-06)"
    ),
    _e(914020, "NC input over its bound (line, expression, string, message)", "project (N-08)"),
    _e(914021, "Counting loop with step 0", "project (N-06)"),
    _w(914030, "M30/M02 in a subroutine ends the whole program", "project (N-01)"),
    _e(914031, "Malformed #MSG text or values", "project (N-07)"),
    _e(914032, "M17/M29 in the main program (it ends with M30 or M02)", "project (N-01)"),
    _w(914050, "Check stopped at its cycle cap: the program did not end", "project (N-10)"),
    _w(
        914051,
        "Geometry check stopped at its cap of loop iterations: the program did not end",
        "project (N-10)",
    ),
    _w(
        914052,
        "Check stopped a program that waits on inputs nobody can change (no PLC attached)",
        "project (N-13)",
    ),
    # --- the built-in cycles (TF5225 measuring, TF5293 drilling/milling; docs/cycles.md) -------
    _e(
        13100,
        "Cycle: safety clearance not defined",
        "kernel",
        page="https://infosys.beckhoff.com/content/1033/cnccycles/15423613707.html",
    ),
    _e(
        13103,
        "Cycle: number of infeeds not defined",
        "kernel",
        page="https://infosys.beckhoff.com/content/1033/tccncdiagnosis/15651570059.html",
    ),
    _e(
        13105,
        "Cycle: retraction travel / holding distance not defined",
        "kernel",
        page="https://infosys.beckhoff.com/content/1033/tccncdiagnosis/15651570059.html",
    ),
    _e(13166, "Cycle: unknown machining mode", "kernel", page=_DIAG + "249731723.html"),
    _e(
        13408,
        "Measuring cycle: zero offset @P7 not or incorrectly defined (1-9, 53-59)",
        "kernel",
        page=_DIAG + "250206091.html",
    ),
    _e(
        13413,
        "Measuring cycle: no workpiece detected, please check your measuring section",
        "kernel",
        page="https://infosys.beckhoff.com/content/1033/tf5225_tc3_cnc_cycles_measurement/322102027.html",
    ),
    _e(
        13414,
        "Measuring cycle: collision on positioning, please check your motion range",
        "kernel",
        page="https://infosys.beckhoff.com/content/1033/tf5225_tc3_cnc_cycles_measurement/322102027.html",
    ),
    _e(
        13448,
        "Measuring cycle: coordinate system ID @P39 not defined (1..10)",
        "kernel",
        page=_DIAG + "518889739.html",
    ),
    _e(14327, "Cycle: pocket diameter not or incorrectly defined", "kernel", page=_DIAG + "539967243.html"),
    _e(14346, "Cycle: reference cycle not defined or incorrect", "kernel", page=_DIAG + "800081419.html"),
    _e(
        14421,
        "Cycle: changing an active zero offset (G54-G59) not permitted",
        "kernel",
        page=_DIAG + "1208284683.html",
    ),
    _e(
        917000, "Cycle parameter missing or invalid (no ID of its own on the cycle's page)", "project (CY-02)"
    ),
    _w(
        917001,
        "A built-in cycle approximates what the kernel's cycle does (a dialogue, a missing axis)",
        "project (CY-04)",
    ),
    # --- project's own: the simulator itself (919xxx) -----------------------------------------
    _e(919000, "Internal error: a cycle failed; the axes were stopped", "project", Reaction.AXIS_STOP),
    _w(
        919010,
        "#MSG SAVE: report file not written (its name leaves the NC output directory, it is no regular file "
        "of one link, or a bound is reached)",
        "project (N-07)",
    ),
)

ALARMS: dict[int, AlarmDef] = {a.number: a for a in _TABLE}


def alarm_def(number: int) -> AlarmDef:
    return ALARMS[number]
