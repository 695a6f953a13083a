"""FCT-C14 definitions that must be refused, each with a precise message at the right block.

Where the kernel documents an ID for the case, the definition is refused with it (its diagnosis pages,
docs/alarms.md): 50786 too many points, 120477 intersecting polygon, 50785 a non-linear block in a
POLY contour, 120479 a CIRC whose first block is not linear, 21793 a G function not allowed in the
definition, 21797 more than two axes. The other cases keep the project's 912002.
"""

from __future__ import annotations

import pytest

from schemas.wire import ProgramState

from .helpers import U_AREA, areas, errors, make_machine, only_alarm, run


def refused(program: str, alarm: int = 912002, **machine: object) -> tuple[str, str | None]:
    """Run ``program``; it must abort with ``alarm``; no area may have been defined by it."""
    m = make_machine(**machine)  # type: ignore[arg-type]
    ch = run(m, program + "M30\n")
    assert ch.state == ProgramState.ABORTED
    found = only_alarm(m, alarm)
    assert areas(m).to_json()["areas"] == []
    assert ch.setpoints() == [0.0] * 6  # nothing moved
    return found.message, found.block


@pytest.mark.req("C14-04")
def test_polygon_not_closed() -> None:
    message, block = refused(U_AREA.replace("N130 X-150 Y75", "N130 X-150 Y70"))
    assert block == "N140"
    assert message == (
        "area 3: polygon not closed: first point (-150, 75), last point (-150, 70) "
        "(N20 and N130 must end at the same point)"
    )


@pytest.mark.req("C14-04")
def test_more_than_twenty_motion_blocks() -> None:
    corners = "".join(f"N{100 + k} X{k} Y{(k % 2) * 5 + k * k}\n" for k in range(1, 20))
    program = (
        "#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\nN10 G01 X0 Y0 F100\n"
        + corners
        + "N300 X0 Y0\n#CONTROL AREA END\n"
    )
    # ID 50786 "Maximum number of points allowed for polygon exceeded"
    # (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/258883979.html)
    message, block = refused(program, 50786)
    assert block == "N300"
    assert message == "area 1: more than 20 motion blocks in the definition (N300 is block 21)"


@pytest.mark.req("C14-04")
def test_twenty_motion_blocks_are_allowed() -> None:
    m = make_machine()
    corners = "".join(f"X{k} Y{k * k}\n" for k in range(1, 19))
    program = (
        "#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\nG01 X0 Y0 F100\n"
        + corners
        + "X0 Y0\n#CONTROL AREA END\nM30\n"
    )
    ch = run(m, program)
    assert ch.state == ProgramState.FINISHED
    assert len(areas(m).to_json()["areas"][0]["points"]) == 19


@pytest.mark.req("C14-04")
def test_self_intersecting_polygon() -> None:
    bow_tie = (
        "#CONTROL AREA BEGIN [ID=2 PROT POLY MIN_EXCUR=0 MAX_EXCUR=1]\n"
        "N10 G01 X0 Y0 F100\nN20 X10 Y10\nN30 X10 Y0\nN40 X0 Y10\nN50 X0 Y0\n#CONTROL AREA END\n"
    )
    # ID 120477 "Definition of polygon is invalid. Overlapping is not permitted."
    # (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/264798347.html)
    message, block = refused(bow_tie, 120477)
    assert block is not None
    assert message == (
        "area 2: the polygon intersects itself: edge N10->N20 (0, 0)-(10, 10) "
        "meets edge N30->N40 (10, 0)-(0, 10) at (5, 5)"
    )


@pytest.mark.req("C14-04")
def test_polygon_that_folds_back_on_itself() -> None:
    fold = (
        "#CONTROL AREA BEGIN [ID=2 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\n"
        "N10 G01 X0 Y0 F100\nN20 X10 Y0\nN30 X5 Y0\nN40 X5 Y5\nN50 X0 Y0\n#CONTROL AREA END\n"
    )
    message, _ = refused(fold, 120477)
    assert "intersects itself" in message


@pytest.mark.req("C14-04")
def test_polygon_that_touches_itself_at_a_corner() -> None:
    touch = (
        "#CONTROL AREA BEGIN [ID=2 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\n"
        "N10 G01 X0 Y0 F100\nN20 X10 Y0\nN30 X10 Y10\nN40 X5 Y0\nN50 X0 Y10\nN60 X0 Y0\n#CONTROL AREA END\n"
    )
    message, _ = refused(touch, 120477)
    assert "intersects itself" in message
    assert "at (5, 0)" in message


@pytest.mark.req("C14-04")
def test_polygon_without_area() -> None:
    line = (
        "#CONTROL AREA BEGIN [ID=2 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\n"
        "N10 G01 X0 Y0 F100\nN20 X10 Y0\nN30 X0 Y0\n#CONTROL AREA END\n"
    )
    message, _ = refused(line)
    assert message == "area 2: a polygon needs at least three different corners, got 2"


@pytest.mark.req("C14-04")
def test_polygon_with_a_circle_block() -> None:
    program = (
        "#CONTROL AREA BEGIN [ID=2 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\n"
        "N10 G01 X0 Y0 F100\nN20 G02 X10 Y0 I5 J0\n#CONTROL AREA END\n"
    )
    # ID 50785 "Only linear motion blocks G00/G01 can be used to define polygonal control areas"
    # (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/258879627.html)
    message, block = refused(program, 50785)
    assert block == "N20"
    assert message == "area 2: a POLY contour is made of linear blocks (G00/G01), N20 is G02"


@pytest.mark.req("C14-04")
def test_a_polygon_may_be_written_with_g00_blocks() -> None:
    """The kernel's page of 50785 allows G00 and G01 in a POLY contour."""
    m = make_machine()
    program = (
        "#CONTROL AREA BEGIN [ID=2 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\n"
        "N10 G00 X0 Y0 F100\nN20 X10 Y0\nN30 G01 X10 Y10\nN40 G00 X0 Y0\n#CONTROL AREA END\nM30\n"
    )
    ch = run(m, program)
    assert ch.state == ProgramState.FINISHED
    assert areas(m).to_json()["areas"][0]["points"] == [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]


@pytest.mark.req("C14-05")
def test_circ_not_a_full_circle() -> None:
    program = (
        "#CONTROL AREA BEGIN [ID=4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]\n"
        "N20 G01 X0 Y0 F10000\nN30 G02 X75 Y75 I0 J75\n#CONTROL AREA END\n"
    )
    message, block = refused(program)
    assert block == "line 4"
    assert message == (
        "area 4: CIRC needs one full circle, N30 ends at (75, 75), not at its start point (0, 0)"
    )


@pytest.mark.req("C14-05")
def test_circ_whose_first_block_is_not_linear() -> None:
    # ID 120479 "The first block at the start of a circular area definition must be linear."
    # (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/264807051.html)
    program = "#CONTROL AREA BEGIN [ID=4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]\nN20 G02 X0 Y0 I0 J75 F100\n"
    message, block = refused(program + "N90 #CONTROL AREA END\n", 120479)
    assert message == (
        "area 4: a CIRC area starts with a linear block (G01) to the start point of the circle, N20 is G02"
    )
    assert block == "N20"


@pytest.mark.req("C14-05")
@pytest.mark.parametrize(
    ("contour", "expected", "at"),
    [
        (
            "N20 G01 X0 Y0 F100\nN30 G01 X10\n",
            "area 4: the second block of a CIRC area must be the full circle (G02/G03 with I/J/K), "
            "N30 is G01",
            "N30",
        ),
        (
            "N20 G01 X0 Y0 F100\nN30 G02 I0 J75\nN40 G01 X1\n",
            "area 4: a CIRC area is a start point and one full circle; N40 is one block too many",
            "N40",
        ),
        (
            "N20 G01 X0 Y0 F100\n",
            "area 4: a CIRC area needs a start point (G01) and one full circle (G02/G03), "
            "got 1 motion block(s)",
            "N90",
        ),
    ],
)
def test_circ_block_structure(contour: str, expected: str, at: str) -> None:
    program = "#CONTROL AREA BEGIN [ID=4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]\n" + contour
    message, block = refused(program + "N90 #CONTROL AREA END\n")
    assert message == expected
    assert block == at


@pytest.mark.req("C14-03")
def test_no_feed_in_the_definition() -> None:
    message, block = refused(U_AREA.replace("G01 F1000 G90", "G01 G90"))
    assert block == "N20"
    assert "no feed (F word) active" in message


@pytest.mark.req("C14-03")
def test_incremental_positions_in_the_definition() -> None:
    # G91 programmed in the definition: ID 21793 "G function during control area definition not allowed"
    # (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/256046475.html)
    message, block = refused(U_AREA.replace("N40 X50 Y150", "N40 G91 X100 Y0"), 21793)
    assert block == "N40"
    assert message == (
        "area 3: G91 is not allowed in a control area definition (N40): contour positions are absolute (G90)"
    )
    # G91 still in effect from before BEGIN: the project's 912002
    message, block = refused("G91\n" + U_AREA.replace("G01 F1000 G90", "G01 F1000"))
    assert block == "N20"
    assert message == "area 3: contour positions must be absolute (G90), G91 is active"


@pytest.mark.req("C14-03", "C14-23")
def test_g100_inside_the_definition() -> None:
    message, block = refused(U_AREA.replace("N40 X50 Y150", "N40 G100 X50 Y150"), 21793)
    assert block == "N40"
    assert message == "G100 is not allowed inside a control area definition"


@pytest.mark.req("C14-06")
def test_min_excur_not_below_max_excur() -> None:
    message, block = refused(U_AREA.replace("MIN_EXCUR=-50", "MIN_EXCUR=50"))
    assert block == "N10"
    assert message == "#CONTROL AREA BEGIN [ID=3]: MIN_EXCUR=50 must be less than MAX_EXCUR=50"


@pytest.mark.req("C14-06")
@pytest.mark.parametrize(
    ("option", "expected"),
    [
        ("EXCUR_AX=A", "EXCUR_AX=A is not an axis of channel 1 (X, Y, Z, X2, Y2, Z2)"),
        (
            "EXCUR_AXNR=42",
            "EXCUR_AXNR=42 is not the logical number of an axis of channel 1 "
            "(X=1, Y=2, Z=3, X2=4, Y2=5, Z2=6)",
        ),
    ],
)
def test_unknown_height_axis(option: str, expected: str) -> None:
    message, _ = refused(U_AREA.replace("MAX_EXCUR=50]", f"MAX_EXCUR=50 {option}]"))
    assert message == f"#CONTROL AREA BEGIN [ID=3]: {expected}"


@pytest.mark.req("C14-06", "C14-07")
def test_height_axis_in_the_base_plane() -> None:
    message, _ = refused(U_AREA.replace("MAX_EXCUR=50]", "MAX_EXCUR=50 EXCUR_AX=Y]"))
    assert message == "area 3: the height axis Y (EXCUR_AX/EXCUR_AXNR) is an axis of the base plane X/Y"


@pytest.mark.req("C14-07")
def test_contour_naming_the_third_axis() -> None:
    # three axes: ID 21797 "Too many axes in control area definition. Maximum two allowed." (its page's
    # own example, https://infosys.beckhoff.com/content/1031/tf5200_diagnosis/256063883.html)
    message, _ = refused(U_AREA.replace("N30 X-50 Y150", "N30 X-50 Y150 Z3"), 21797)
    assert message.startswith(
        "area 3: the contour names 3 axes (X, Y, Z); a control area is defined with at most two"
    )
    # two axes, one not of the base plane: the project's 912002
    xz = (
        "#CONTROL AREA BEGIN [ID=3 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\n"
        "G01 X0 Z0 F100\nX10\nZ10\nX0 Z0\n#CONTROL AREA END\n"
    )
    message, _ = refused(xz)
    assert message.startswith("area 3: the contour names Z, which is not an axis of the base plane X/Y (G17)")


@pytest.mark.req("C14-02")
def test_second_begin_before_end() -> None:
    second = "N140 #CONTROL AREA BEGIN [ID=5 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]"
    program = U_AREA.replace("N140 #CONTROL AREA END", second)
    message, block = refused(program)
    assert block == "N140"
    assert "BEGIN before the previous definition was closed by END" in message


@pytest.mark.req("C14-02")
def test_program_end_inside_a_definition() -> None:
    program = U_AREA.replace("N140 #CONTROL AREA END\n", "")
    m = make_machine()
    run(m, program + "M30\n")
    alarm = only_alarm(m, 912002)
    assert alarm.block == "N10"
    assert alarm.message == (
        "program ended inside the definition of area 3 begun at N10: #CONTROL AREA END missing; "
        "the area was not defined"
    )
    assert areas(m).to_json()["areas"] == []


@pytest.mark.req("C14-11")
def test_on_inside_a_definition() -> None:
    program = U_AREA.replace("N60 X150 Y0", "N60 #CONTROL AREA ON ALL")
    message, block = refused(program, 912003)
    assert block == "N60"
    assert message == (
        "#CONTROL AREA ON inside the definition of area 3: close the definition with #CONTROL AREA END first"
    )


@pytest.mark.req("C14-17")
def test_additional_axes_rules() -> None:
    mixed = (
        "#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\n"
        "G01 X0 Y2=0 F100\nX10\nY2=10\nX0 Y2=0\n#CONTROL AREA END\n"
    )
    message, _ = refused(mixed)
    assert message == "area 1: the contour mixes main axes (X) and additional axes (Y2)"
    three = mixed.replace("X10\n", "X2=10\n")
    message, _ = refused(three, 21797)
    assert message.startswith("area 1: the contour names 3 axes (X, Y2, X2)")
    circ = "#CONTROL AREA BEGIN [ID=1 PROT CIRC MIN_EXCUR=0 MAX_EXCUR=1]\nG01 X2=0 Y2=0 F100\nG02 I10 J0\n"
    message, _ = refused(circ + "#CONTROL AREA END\n", 910110)
    assert message.startswith("area 1: areas on additional axes (X2, Y2) must be POLY (C14-17)")
    one_axis_start = (
        "#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\n"
        "N5 G01 X2=0 F100\nY2=10\nX2=10\nX2=0 Y2=0\n#CONTROL AREA END\n"
    )
    message, _ = refused(one_axis_start)
    assert message == "area 1: the start point (N5) must name both axes X2 and Y2"


@pytest.mark.req("C14-17")
def test_additional_axes_without_a_height_axis() -> None:
    program = (
        "#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=0 MAX_EXCUR=1]\n"
        "G01 X2=0 Y2=0 F100\nX2=10\nY2=10\nX2=0 Y2=0\n#CONTROL AREA END\n"
    )
    m = make_machine(axes=("X", "Y", "Z", "X2", "Y2"))
    ch = run(m, program + "M30\n")
    assert ch.state == ProgramState.ABORTED
    alarm = only_alarm(m, 912002)
    assert alarm.message == (
        "area 1: no height axis for an area on X2/Y2: name it with EXCUR_AX=.. (channel axes X, Y, Z, X2, Y2)"
    )
    m = make_machine(axes=("X", "Y", "Z", "X2", "Y2"))
    ch = run(m, program.replace("MAX_EXCUR=1]", "MAX_EXCUR=1 EXCUR_AX=Z]") + "M30\n")
    assert ch.state == ProgramState.FINISHED
    assert areas(m).to_json()["areas"][0]["height_axis"] == "Z"


# --- the area ID (issue 21: the kernel's 21292 and 21286) ----------------------------------------


@pytest.mark.req("C14-02")
@pytest.mark.parametrize("written", ["ID0", "ID=0", "ID = 0"])
def test_area_id_zero_is_invalid(written: str) -> None:
    """ID 21292 "Invalid Control-Area-ID programmed": "the area number identifier in the command
    #CONTROL AREA BEGIN[...] is assigned the value zero"
    (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/254083723.html). Accepted before."""
    program = U_AREA.replace("[ID3 ", f"[{written} ")
    message, block = refused(program, 21292)
    assert block == "N10"
    assert (
        message
        == "#CONTROL AREA BEGIN [ID=0]: invalid control area ID 0; an area ID is a whole number 1..999999999"
    )


@pytest.mark.req("C14-02")
@pytest.mark.parametrize("area_id", [-1, 1_000_000_000])
def test_area_id_out_of_range(area_id: int) -> None:
    """ID 21286 "Control area ID is out of data format", with the lower and upper limit as parameters
    (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/254057611.html). The NC parser's bound
    stops such an ID before; the area handler checks it too (an ID from an expression or a variable)."""
    from hli_server.engine.areas.definitions import AreaDefinitions
    from hli_server.engine.decoder import DecodeError, ModalState
    from hli_server.engine.nc.blocks import AreaBegin, AreaKind, AreaShape, Block

    m = make_machine()
    handler = AreaDefinitions(areas(m).tables)
    begin = AreaBegin(area_id, AreaKind.WORK, AreaShape.POLY, 0.0, 1.0)
    result = handler.command(begin, Block(1, 10, "N10"), (0.0,) * 6, ModalState())
    assert isinstance(result, DecodeError)
    assert result.alarm == 21286
    assert result.params == {"id": area_id, "lower": 1, "upper": 999_999_999}
    assert f"[ID={area_id}]: the control area ID is out of range 1..999999999" in result.message


@pytest.mark.req("C14-02")
def test_end_without_begin_is_a_warning_and_has_no_effect() -> None:
    """ID 21288 "No corresponding control area definition. Command has no effect": #CONTROL AREA END is
    ignored (https://infosys.beckhoff.com/content/1031/tf5200_diagnosis/254066315.html)."""
    m = make_machine()
    ch = run(m, "N10 G01 X10 F1000\nN20 #CONTROL AREA END\nN30 X20\nM30\n")
    assert ch.state == ProgramState.FINISHED
    assert ch.setpoints()[0] == 20.0
    warning = only_alarm(m, 21288)
    assert (warning.severity, warning.block, warning.line) == ("warning", "N20", 2)
    assert errors(m) == []
