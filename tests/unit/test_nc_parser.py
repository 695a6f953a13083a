"""NC parser, syntax only (E-04; C14-02, C14-11..13 and C14-18 for the #CONTROL AREA commands).

The example programs are the ones of FCT-C14 (sections 2.4, 3.1.1, 3.1.2, 3.2..3.4, 4) and of the
older description "Arbeits- und Schutzräume definieren", copied as printed (comments included).
"""

from __future__ import annotations

import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hli_server.engine.alarms import ALARMS
from hli_server.engine.nc import (
    AreaBegin,
    AreaClear,
    AreaEnd,
    AreaKind,
    AreaOff,
    AreaOn,
    AreaShape,
    Block,
    NcError,
    iter_blocks,
    parse_line,
    parse_program,
)
from hli_server.engine.nc import parser as parser_module
from tests.spec_examples import (
    CIRC_PROT,
    CIRC_PROT_OLD,
    EXTRA_AXES_PROGRAM,
    SELECT_EXAMPLES,
    TWO_PATH_AREA,
    U_AREA,
)

AXES = ("X", "Y", "Z")
AXES_2 = ("X", "Y", "Z", "X2", "Y2", "Z2")


def one(text: str, axes: tuple[str, ...] = AXES, line: int = 1) -> Block:
    block = parse_line(text, line, axes)
    assert block is not None
    return block


def error(text: str, axes: tuple[str, ...] = AXES, line: int = 14) -> NcError:
    with pytest.raises(NcError) as info:
        parse_line(text, line, axes)
    return info.value


# --- the documents' example programs ----------------------------------------------------------------

POLY_U_SHAPE = U_AREA
CIRC_FCT_C14 = CIRC_PROT
CIRC_OLD = CIRC_PROT_OLD
ADDITIONAL_AXES = EXTRA_AXES_PROGRAM
TWO_PATH = TWO_PATH_AREA


@pytest.mark.req("E-04", "C14-02", "C14-04")
def test_poly_u_shape_example_parses():
    blocks = parse_program(POLY_U_SHAPE, AXES)
    assert [b.number for b in blocks] == [10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 120, 130, 140]
    assert [b.line for b in blocks] == list(range(1, 14))
    assert blocks[0].area == AreaBegin(3, AreaKind.WORK, AreaShape.POLY, -50.0, 50.0)
    assert blocks[1].g_codes == (1, 90)
    assert blocks[1].feed == 1000.0
    assert blocks[1].axes == (("X", -150.0), ("Y", 75.0))
    assert blocks[11].axes == (("X", -150.0), ("Y", 75.0))
    assert blocks[11].text == "N130 X-150 Y75 (Endpunkt identisch mit Startpunkt)"
    assert blocks[-1].area == AreaEnd()
    points = [b.axes for b in blocks[1:-1]]
    assert points[5] == (("X", 50.0), ("Y", 0.0))


@pytest.mark.req("E-04", "C14-02", "C14-05")
@pytest.mark.parametrize(
    ("program", "start", "centre"),
    [
        (CIRC_FCT_C14, (("X", 0.0), ("Y", 0.0)), (("I", 0.0), ("J", 75.0))),
        (CIRC_OLD, (("X", 100.0), ("Y", 0.0)), (("I", 50.0), ("J", 0.0))),
    ],
)
def test_circ_examples_parse(
    program: str, start: tuple[tuple[str, float], ...], centre: tuple[tuple[str, float], ...]
):
    begin, first, circle, end = parse_program(program, AXES)
    assert begin.area == AreaBegin(4, AreaKind.PROT, AreaShape.CIRC, -70.0, 70.0)
    assert first.g_codes == (1,)
    assert first.axes == start
    assert first.feed == 10000.0
    assert circle.g_codes == (2, 162)
    assert circle.centre == centre
    assert circle.axes == ()
    assert end.area == AreaEnd()


@pytest.mark.req("E-04", "C14-02", "C14-17")
def test_additional_axes_example_parses():
    blocks = parse_program(ADDITIONAL_AXES, AXES_2)
    # the ":" lines elide program text in the document: they are not blocks
    assert [b.number for b in blocks] == [10, 20, 30, 40, 50, 60, 70, 500, 1000]
    assert blocks[0].area == AreaBegin(4, AreaKind.WORK, AreaShape.POLY, -50.0, 50.0)
    assert blocks[1].axes == (("X2", 100.0), ("Y2", 100.0))
    assert blocks[1].g_codes == (1, 90)
    assert blocks[2].axes == (("X2", -100.0),)
    assert blocks[3].axes == (("Y2", -100.0),)
    assert blocks[6].area == AreaEnd()
    assert blocks[7].area == AreaOn(None, all_=True)
    assert blocks[8].m_codes == (30,)
    assert blocks[8].line == 12


@pytest.mark.req("E-04", "C14-11", "C14-12", "C14-13")
def test_on_off_clear_examples_parse():
    areas = [b.area for b in parse_program(SELECT_EXAMPLES, AXES)]
    assert areas == [
        AreaOn(3, all_=False),
        AreaOn(None, all_=True),
        AreaOff(3, all_=False),
        AreaOff(None, all_=False),
        AreaOff(None, all_=True),
        AreaClear(3, all_=False),
        AreaClear(None, all_=True),
    ]


@pytest.mark.req("E-04", "C14-02", "C14-18")
def test_two_path_example_parses_with_wrapped_begin():
    blocks = parse_program(TWO_PATH, AXES)
    assert [b.number for b in blocks] == [40, 50, 60, 70, 80, 90, 100, 110]
    begin = blocks[0]
    assert begin.line == 1  # the wrapped command keeps its first line
    assert begin.area == AreaBegin(1, AreaKind.WORK, AreaShape.POLY, -100.0, 100.0, monitor_lvl="IMCS")
    assert begin.text == (
        'N040 #CONTROL AREA START [ID=1 WORK MONITOR_LVL = "IMCS" POLY MIN_EXCUR = -100 MAX_EXCUR = 100]'
    )
    first = blocks[1]
    assert first.line == 3
    assert first.g_codes == (0,)
    assert first.axes == (("X", 200.0), ("Y", 0.0))
    (second,) = first.two_path
    # the second path names axes the channel does not have: no error here, the decoder refuses it
    assert second.axes == (("U", 150.0), ("V", 0.0))
    assert second.g_codes == (0,)
    assert second.number == 50
    assert blocks[4].two_path[0].axes == (("U", -150.0), ("V", -150.0))
    assert blocks[-1].area == AreaEnd()
    assert not blocks[-1].two_path


# --- words ----------------------------------------------------------------------------------------------


@pytest.mark.req("E-04")
@pytest.mark.parametrize(
    ("text", "axes"),
    [
        ("X100", (("X", 100.0),)),
        ("X-150", (("X", -150.0),)),
        ("X+.5", (("X", 0.5),)),
        ("X 100", (("X", 100.0),)),
        ("X100.", (("X", 100.0),)),
        ("X2=100", (("X2", 100.0),)),
        ("X2 = -100.5", (("X2", -100.5),)),
        ("X2=+.25 Y2 =3", (("X2", 0.25), ("Y2", 3.0))),
        ("X2", (("X", 2.0),)),  # without "=" it is axis X, value 2
        ("X2 Y2=7", (("X", 2.0), ("Y2", 7.0))),
        ("X2=1 X5", (("X2", 1.0), ("X", 5.0))),
        ("G1X10Y20", (("X", 10.0), ("Y", 20.0))),
    ],
)
def test_axis_word_forms(text: str, axes: tuple[tuple[str, float], ...]):
    assert one(text, AXES_2).axes == axes


@pytest.mark.req("E-04")
def test_block_number_skip_and_words():
    block = one("/N010 G00 X1")
    assert block.number == 10
    assert block.label == "N10"
    assert block.g_codes == (0,)
    assert one("N 20 G1 X1").number == 20
    assert one("G1 X1").number is None
    only = one("N30")
    assert only.number == 30
    assert only.is_empty


@pytest.mark.req("E-04")
def test_g00_equals_g0_and_several_g_and_m_codes():
    assert one("G00").g_codes == one("G0").g_codes == (0,)
    assert one("G001 G017 G090 G0161").g_codes == (1, 17, 90, 161)
    assert one("G01 G01 X1").g_codes == (1,)  # the same code twice is no conflict
    assert one("G54 G92 X0 Y0").g_codes == (54, 92)
    assert one("M3 M30 M03").m_codes == (3, 30, 3)


@pytest.mark.req("E-04")
def test_feed_centre_and_extra_words():
    block = one("G02 X10 Y0 I5 J0 K-1 F250.5 S1000 T3 D1 H2")
    assert block.feed == 250.5
    assert block.centre == (("I", 5.0), ("J", 0.0), ("K", -1.0))
    assert block.extra == {"S": 1000.0, "T": 3.0, "D": 1.0, "H": 2.0}


@pytest.mark.req("E-04")
def test_lower_case_is_accepted():
    assert one("n10 g01 x12.5 y-3.25 f1000") == Block(
        1, 10, "n10 g01 x12.5 y-3.25 f1000", (1,), (), (("X", 12.5), ("Y", -3.25)), (), 1000.0
    )
    assert one("x2=5", AXES_2).axes == (("X2", 5.0),)
    assert one("#control area on [id3]").area == AreaOn(3, all_=False)
    assert one("g1 x1", ("x", "y")).axes == (("X", 1.0),)  # axis names are case-insensitive too


@pytest.mark.req("E-04")
def test_comments():
    assert parse_line("", 1, AXES) is None
    assert parse_line("   \t ", 1, AXES) is None
    assert parse_line("(only a comment)", 1, AXES) is None
    assert parse_line("; only a comment", 1, AXES) is None
    assert parse_line("/", 1, AXES) is None
    block = one("  N10 G1 (first) X1 (second; with a semicolon) Y2 ; rest (not a comment start")
    assert block.axes == (("X", 1.0), ("Y", 2.0))
    assert block.text == "N10 G1 (first) X1 (second; with a semicolon) Y2 ; rest (not a comment start"
    assert one("X1(comment)Y2").axes == (("X", 1.0), ("Y", 2.0))  # a comment separates words
    assert one("N10 (comment only)").number == 10


@pytest.mark.req("E-04")
def test_iter_blocks_is_lazy_and_counts_lines():
    program = "N10 G1 X1 F100\r\n\r\n(comment)\nN20 X2\rN30 Q1\nN40 X\n"
    blocks = iter_blocks(program, AXES)
    assert next(blocks).number == 10
    second = next(blocks)
    assert (second.number, second.line) == (20, 4)
    with pytest.raises(NcError) as info:
        next(blocks)  # the bad line is reached only now: the blocks before it could already run
    assert (info.value.alarm, info.value.line, info.value.block) == (910100, 5, "N30")


@pytest.mark.req("E-04")
def test_parse_program_is_strict():
    with pytest.raises(NcError) as info:
        parse_program("N10 G1 X1\nN20 G5\n", AXES)
    assert (info.value.alarm, info.value.line, info.value.block) == (910102, 2, "N20")


# --- errors ---------------------------------------------------------------------------------------------

# (line text, alarm, word the message must name); each is checked with and without an N number
ERRORS = [
    # 910100 unknown word
    ("G1 Q5", 910100, "Q5"),
    ("G1 R50", 910100, "R50"),
    ("G1 X1 HELLO", 910100, "HELLO"),
    ("G1 X1 $", 910100, "$"),
    ("G1 X1 )", 910100, ")"),
    ("G1 #CONTROL AREA END", 910100, "#CONTROL"),
    ("G1 XABC", 910100, "XABC"),
    # 910101 malformed number
    ("G1 X1.2.3", 910101, "X1.2.3"),
    ("G1 X1,5", 910101, "X1,5"),
    ("G1 X", 910101, "X"),
    ("G1 X.", 910101, "X."),
    ("G1 X-", 910101, "X-"),
    ("G1 X2=", 910101, "X2="),
    ("G1 X2 = Y1", 910101, "X2 ="),
    ("G1.5 X1", 910101, "G1.5"),
    ("G-1", 910101, "G-1"),
    ("M1.5", 910101, "M1.5"),
    ("X" + "9" * 400, 910111, "X999"),
    # 910102 unknown G code
    ("G5 X1", 910102, "G5"),
    ("G999", 910102, "G999"),
    ("G" + "1" * 5000, 910102, "G111"),
    # 910103 programmed twice
    ("G1 X1 Y2 X3", 910103, "X1 and X3"),
    ("X2=1 X2=4", 910103, "X2=1 and X2=4"),
    ("G1 X1 F100 F200", 910103, "F100 and F200"),
    ("G2 I1 I2", 910103, "I1 and I2"),
    ("S100 S200", 910103, "S100 and S200"),
    # 910104 comment not closed
    ("G1 X1 (comment", 910104, "(comment"),
    # 910105 #CONTROL AREA
    ("#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=1]", 910105, "MAX_EXCUR"),
    ("#CONTROL AREA BEGIN [WORK POLY MIN_EXCUR=1 MAX_EXCUR=2]", 910105, "ID=n"),
    ("#CONTROL AREA BEGIN [ID=1 POLY MIN_EXCUR=1 MAX_EXCUR=2]", 910105, "WORK|PROT"),
    ("#CONTROL AREA BEGIN [ID=1 WORK MIN_EXCUR=1 MAX_EXCUR=2]", 910105, "POLY|CIRC"),
    ("#CONTROL AREA BEGIN [ID=1 WORK POLY MAX_EXCUR=2]", 910105, "MIN_EXCUR"),
    ("#CONTROL AREA BEGIN [ID=1 WORK PROT POLY MIN_EXCUR=1 MAX_EXCUR=2]", 910105, "WORK and PROT"),
    ("#CONTROL AREA BEGIN [ID=1 WORK POLY CIRC MIN_EXCUR=1 MAX_EXCUR=2]", 910105, "POLY and CIRC"),
    ("#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=1 MAX_EXCUR=2 FOO]", 910105, "FOO"),
    ("#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=1 MAX_EXCUR=2 ALL]", 910105, "ALL"),
    ("#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=1 MAX_EXCUR=2", 910105, "'[' not closed"),
    ("#CONTROL AREA BEGIN ID=1 WORK POLY MIN_EXCUR=1 MAX_EXCUR=2]", 910105, "'['"),
    ("#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=1 MAX_EXCUR=2] X", 910105, "'X' after ']'"),
    ("#CONTROL AREA BEGIN [ID=1 [WORK] POLY MIN_EXCUR=1 MAX_EXCUR=2]", 910105, "nest"),
    ("#CONTROL AREA BEGIN", 910105, "options missing"),
    ("#CONTROL AREA BEGIN [ID=1 ID=2 WORK POLY MIN_EXCUR=1 MAX_EXCUR=2]", 910105, "ID given twice"),
    ("#CONTROL AREA BEGIN [ID=1.5 WORK POLY MIN_EXCUR=1 MAX_EXCUR=2]", 910105, "ID=1.5"),
    ("#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR= MAX_EXCUR=2]", 910105, "value of MIN_EXCUR"),
    ("#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=A MAX_EXCUR=2]", 910105, "MIN_EXCUR=A"),
    (
        "#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=1 MAX_EXCUR=2 EXCUR_AX=Z EXCUR_AXNR=3]",
        910105,
        "EXCUR_AX and EXCUR_AXNR",
    ),
    ("#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=1 MAX_EXCUR=2 MONITOR_LVL=WCS]", 910105, "WCS"),
    ('#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=1 MAX_EXCUR=2 MONITOR_LVL="MCS]', 910105, "quote"),
    ("#CONTROL AREA ON", 910105, "ID or ALL missing"),
    ("#CONTROL AREA ON [WORK]", 910105, "WORK"),
    ("#CONTROL AREA ON [ID=3 ALL]", 910105, "ID and ALL"),
    ("#CONTROL AREA ON ALL]", 910105, "']' without '['"),
    ("#CONTROL AREA CLEAR", 910105, "ID or ALL missing"),
    ("#CONTROL AREA END [ID=3]", 910105, "END takes no options"),
    ("#CONTROL AREA FOO", 910105, "FOO"),
    ("#CONTROL AREA", 910105, "nothing"),
    # 910106 conflicting G codes
    ("G90 G91 X1", 910106, "G90 and G91"),
    ("G0 G1 X1", 910106, "G0 and G1"),
    ("G02 G03 I1", 910106, "G2 and G3"),
    ("G17 G19", 910106, "G17 and G19"),
    ("G161 G162", 910106, "G161 and G162"),
    ("G54 G55", 910106, "G54 and G55"),
    # 910107 unknown axis
    ("G1 A5", 910107, "A5"),
    ("G1 X9=5", 910107, "X9=5"),
    ("G1 U1", 910107, "U1"),
    # 910109 unknown # command
    ("#FOO", 910109, "#FOO"),
    ("#CONTROL FOO", 910109, "#CONTROL FOO"),
    ("#CS ON", 910109, "#CS"),
]


@pytest.mark.req("E-04")
@pytest.mark.parametrize(("text", "alarm", "word"), ERRORS)
def test_error_names_alarm_line_block_and_word(text: str, alarm: int, word: str):
    assert alarm in ALARMS
    without = error(text, AXES_2, line=14)
    assert (without.alarm, without.line, without.block) == (alarm, 14, "line 14")
    assert word in without.message, without.message
    assert word in str(without)
    with_n = error(f"N130 {text}", AXES_2, line=7)
    assert (with_n.alarm, with_n.line, with_n.block) == (alarm, 7, "N130")
    assert word in with_n.message, with_n.message
    assert str(with_n).startswith("line 7, N130: ")


MALFORMED_N = [
    ("N10.5 G1", "N10.5"),
    ("NX G1", "NX"),
    ("N G1", "N"),
    ("N-5 G1", "N-5"),
    ("N10-5 G1", "N10-5"),
    ("N10=5", "N10=5"),
    ("N" + "1" * 12 + " G1", "N111"),
    ("/N.5", "N.5"),
    ("N10.5 #CONTROL AREA END", "N10.5"),
]


@pytest.mark.req("E-04")
@pytest.mark.parametrize(("text", "word"), MALFORMED_N)
def test_malformed_block_number(text: str, word: str):
    err = error(text)
    assert (err.alarm, err.line, err.block) == (910108, 14, "line 14")
    assert word in err.message


@pytest.mark.req("E-04")
def test_misplaced_block_number():
    err = error("N5 G1 N6")
    assert (err.alarm, err.block) == (910108, "N5")
    assert "N6" in err.message
    err = error("G1 N6")
    assert (err.alarm, err.block) == (910108, "line 14")
    assert "N6" in err.message
    assert "start of the block" in err.message


@pytest.mark.req("E-04")
def test_error_label_uses_n_even_when_comment_is_open():
    err = error("N0130 G1 X1 (unclosed")
    assert (err.alarm, err.block) == (910104, "N130")


@pytest.mark.req("E-04")
def test_long_junk_is_cut_in_messages():
    err = error("G1 Q" + "7" * 1000)
    assert err.alarm == 910100
    assert len(err.message) < 200


# --- #CONTROL AREA forms -----------------------------------------------------------------------------


@pytest.mark.req("E-04", "C14-02")
@pytest.mark.parametrize(
    "options",
    [
        "ID=3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50",
        "ID3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50",
        "ID 3 WORK POLY MIN_EXCUR -50 MAX_EXCUR 50",  # the older "ID <expr>" form
        " ID = 3  POLY  WORK MAX_EXCUR = 50.0 MIN_EXCUR = -50 ",
        "id=3 work poly min_excur=-50 max_excur=+50",
    ],
)
def test_begin_option_forms(options: str):
    for keyword in ("BEGIN", "START"):
        assert one(f"#CONTROL AREA {keyword} [{options}]").area == AreaBegin(
            3, AreaKind.WORK, AreaShape.POLY, -50.0, 50.0
        )


@pytest.mark.req("E-04", "C14-02", "C14-06", "C14-18")
def test_begin_optional_options():
    area = one(
        '#CONTROL AREA BEGIN [ID=2 PROT CIRC MIN_EXCUR=0 MAX_EXCUR=10 EXCUR_AX=X2 MONITOR_LVL="IMCS"]'
    ).area
    assert area == AreaBegin(2, AreaKind.PROT, AreaShape.CIRC, 0.0, 10.0, excur_ax="X2", monitor_lvl="IMCS")
    area = one(
        "#CONTROL AREA BEGIN [ID=2 PROT CIRC MIN_EXCUR=0 MAX_EXCUR=10 EXCUR_AXNR = 5 MONITOR_LVL=mcs]"
    ).area
    assert area == AreaBegin(2, AreaKind.PROT, AreaShape.CIRC, 0.0, 10.0, excur_axnr=5, monitor_lvl="MCS")
    # MIN >= MAX and unknown IDs are the decoder's checks, not syntax
    area = one("#CONTROL AREA BEGIN [ID=99 WORK POLY MIN_EXCUR=10 MAX_EXCUR=-10]").area
    assert isinstance(area, AreaBegin)
    assert (area.area_id, area.min_excur, area.max_excur) == (99, 10.0, -10.0)


@pytest.mark.req("E-04", "C14-11", "C14-12", "C14-13")
@pytest.mark.parametrize(
    ("text", "area"),
    [
        ("#CONTROL AREA ON [ID=3]", AreaOn(3, all_=False)),
        ("#CONTROL AREA ON [ID3]", AreaOn(3, all_=False)),
        ("#CONTROL AREA ON [ ID = 3 ]", AreaOn(3, all_=False)),
        ("#CONTROL AREA ON ALL", AreaOn(None, all_=True)),
        ("#CONTROL AREA ON [ALL]", AreaOn(None, all_=True)),
        ("#CONTROL AREA OFF [ID=3]", AreaOff(3, all_=False)),
        ("#CONTROL AREA OFF ALL", AreaOff(None, all_=True)),
        ("#CONTROL AREA OFF", AreaOff(None, all_=False)),
        ("#CONTROL AREA OFF []", AreaOff(None, all_=False)),
        ("#CONTROL AREA CLEAR [ID=3]", AreaClear(3, all_=False)),
        ("#CONTROL AREA CLEAR ALL", AreaClear(None, all_=True)),
        ("N20 #CONTROL   AREA   END  ; done", AreaEnd()),
    ],
)
def test_select_forms(text: str, area: object):
    assert one(text).area == area


@pytest.mark.req("E-04", "C14-02")
def test_wrapped_begin_needs_iter_blocks():
    line = '#CONTROL AREA START [ID=1 WORK MONITOR_LVL = "IMCS" POLY MIN_EXCUR'
    err = error(line)
    assert err.alarm == 910105
    assert "'[' not closed" in err.message
    program = "\n".join(
        [
            "N10 G1 X0 F100",
            f"{line} (comment)",
            "; a comment line",
            "  = -100 ; tail",
            " MAX_EXCUR = 100] (end)",
            "N20 X1",
        ]
    )
    blocks = parse_program(program, AXES)
    assert [(b.number, b.line) for b in blocks] == [(10, 1), (None, 2), (20, 6)]
    assert blocks[1].area == AreaBegin(1, AreaKind.WORK, AreaShape.POLY, -100.0, 100.0, monitor_lvl="IMCS")


@pytest.mark.req("E-04", "C14-02")
@pytest.mark.parametrize(
    ("program", "where"),
    [
        ("N10 #CONTROL AREA BEGIN [ID=1 WORK POLY\nMIN_EXCUR=1\n", "end of the program"),
        ("N10 #CONTROL AREA BEGIN [ID=1 WORK POLY\nMIN_EXCUR=1\nN20 G1 X1\n", "line 3"),
        ("N10 #CONTROL AREA BEGIN [ID=1 WORK POLY\n#CONTROL AREA END\n", "line 2"),
        ("N10 #CONTROL AREA BEGIN [ID=1 WORK POLY\nMIN_EXCUR=1 [MAX_EXCUR=2]\n", "line 2"),
    ],
)
def test_unclosed_wrapped_begin(program: str, where: str):
    with pytest.raises(NcError) as info:
        parse_program(program, AXES)
    err = info.value
    assert (err.alarm, err.line, err.block) == (910105, 1, "N10")
    assert where in err.message


@pytest.mark.req("E-04")
def test_unclosed_comment_in_a_continuation_line():
    with pytest.raises(NcError) as info:
        parse_program("#CONTROL AREA BEGIN [ID=1 WORK POLY\nMIN_EXCUR=1 (oops\n", AXES)
    assert (info.value.alarm, info.value.line) == (910104, 2)


# --- two paths ------------------------------------------------------------------------------------------


@pytest.mark.req("E-04", "C14-18")
def test_two_path_forms():
    block = one("N10 G1 X1 : G1 U2 W3=4")
    assert block.axes == (("X", 1.0),)
    assert block.two_path[0].axes == (("U", 2.0), ("W3", 4.0))
    assert block.two_path[0].text == "G1 U2 W3=4"
    assert one(": G0 X1 :").two_path == ()  # an empty second path is nothing
    assert parse_line(":", 1, AXES) is None
    # the first path is checked against the channel's axes, the second only for syntax
    assert error("N10 : G0 U1 : G0 X1").alarm == 910107
    err = error("N10 : G0 X1 : G0 U1.2.3")
    assert (err.alarm, err.block) == (910101, "N10")
    assert error("N10 : G0 X1 : G0 Q1").alarm == 910100
    assert error("N10 : G0 X1 : N20 G0 U1").alarm == 910108


# --- properties -----------------------------------------------------------------------------------------

NC_ALPHABET = 'NGMFXYZUVABIJKSTDHQRnxg0123456789 \t.+-=()[];:#/"_,ECONTRLAWKPIDBSU'
NC_TOKENS = st.sampled_from(
    [
        *("N10", "G01", "G1", "G90", "G91", "X", "X2", "=", "X2=", "Y-", "-", ".", "5", "(", ")", ";", ":"),
        *("#CONTROL AREA ", "BEGIN", "START", "ON", "OFF", "CLEAR", "END", "ALL", "[", "]", "ID", "ID3"),
        *("WORK", "PROT", "POLY", "CIRC", "MIN_EXCUR", "MAX_EXCUR", "EXCUR_AX", "EXCUR_AXNR", "MONITOR_LVL"),
        *('"IMCS"', "MCS", " ", "F100", "I5", "M30", "S", "T1", "9" * 320, "ß", "\u0663", "\xa0", "/", "\n"),
    ]
)
NC_TEXT = st.one_of(st.text(NC_ALPHABET, max_size=40), st.lists(NC_TOKENS, max_size=14).map("".join))


@pytest.mark.req("E-04")
@settings(max_examples=400, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(NC_TEXT)
def test_parse_line_raises_only_nc_error(text: str):
    caught: NcError | None = None
    try:
        block = parse_line(text, 3, AXES_2)
    except NcError as err:
        caught = err
    if caught is not None:
        assert 910100 <= caught.alarm <= 910111
        assert caught.alarm in ALARMS
        assert caught.line == 3
        assert re.fullmatch(r"line 3|N[0-9]+", caught.block)
        assert caught.message
    elif block is not None and block.area is None and not block.two_path:
        # a block's text parses to the same block again
        assert parse_line(block.text, 3, AXES_2) == block


@pytest.mark.req("E-04")
@settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(st.lists(NC_TEXT, max_size=6).map("\n".join))
def test_iter_blocks_raises_only_nc_error(program: str):
    blocks: list[Block] = []
    caught: NcError | None = None
    try:
        blocks.extend(iter_blocks(program, AXES))
    except NcError as err:
        caught = err
    assert all(isinstance(block, Block) for block in blocks)
    if caught is not None:
        assert 910100 <= caught.alarm <= 910111


@settings(max_examples=300, deadline=None)
@given(NC_TEXT)
def test_plain_word_regex_equals_full_one_without_equals(text: str):
    """The fast regex for lines without '=' reads exactly what the full one reads."""
    upper = text.upper().replace("=", "")
    assert parser_module._WORD_PLAIN.findall(upper) == parser_module._WORD.findall(upper)


def test_fast_block_constructor_equals_dataclass_init():
    fast = parser_module._new_block(
        7, 70, "N70 X1", (1,), (30,), (("X", 1.0),), (("I", 2.0),), 5.0, {"S": 1.0}
    )
    slow = Block(7, 70, "N70 X1", (1,), (30,), (("X", 1.0),), (("I", 2.0),), 5.0, None, (), {"S": 1.0})
    assert fast == slow
    assert hash(fast.axes) == hash(slow.axes)
    with pytest.raises(AttributeError):
        fast.line = 8  # type: ignore[misc]  # still frozen
