"""FCT-C14 in automatic mode: the documents' example programs, the table, the path checks, the errors."""

from __future__ import annotations

import math

import pytest

from schemas.wire import Mode, ProgramState

from .helpers import (
    CIRC_PROT,
    CIRC_PROT_OLD,
    EXTRA_AXES_AREA,
    TWO_PATH_AREA,
    U_AREA,
    U_AREA_START,
    alarm_ids,
    areas,
    errors,
    make_machine,
    only_alarm,
    run,
    state_of,
)

U_POINTS = [
    [-150.0, 75.0],
    [-50.0, 150.0],
    [50.0, 150.0],
    [150.0, 75.0],
    [150.0, 0.0],
    [50.0, 0.0],
    [50.0, 75.0],
    [-50.0, 75.0],
    [-50.0, 0.0],
    [-150.0, 0.0],
]

INTO_U = "N900 G01 X-100 Y50 F30000\n"
"""From the start position (0, 0, 0), which is outside the U, into its left arm."""


# --- the documents' examples -----------------------------------------------------------------------
@pytest.mark.req("C14-01", "C14-02", "C14-04", "C14-07")
@pytest.mark.parametrize("program", [U_AREA, U_AREA_START], ids=["BEGIN", "START"])
def test_u_shaped_work_area_is_defined_as_documented(program: str) -> None:
    m = make_machine()
    assert areas(m).to_json()["areas"] == []  # C14-01: nothing at start-up
    ch = run(m, program + "M30\n")
    assert ch.state == ProgramState.FINISHED
    assert errors(m) == []
    (entry,) = areas(m).to_json()["areas"]
    assert entry["id"] == 3
    assert entry["kind"] == "WORK"
    assert entry["shape"] == "POLY"
    assert entry["state"] == "defined"
    assert entry["points"] == U_POINTS  # the U, not convex, is valid
    assert (entry["min"], entry["max"]) == (-50.0, 50.0)
    assert entry["axes"] == ["X", "Y"]
    assert entry["height_axis"] == "Z"
    # the contour did not move the axes
    assert ch.setpoints() == [0.0] * 6


@pytest.mark.req("C14-02")
def test_position_after_definition_is_the_real_one() -> None:
    """The contour blocks do not move the axes: the next move starts where the axes are."""
    m = make_machine()
    ch = run(m, "N5 G01 X10 Y20 F30000\n" + U_AREA + "N200 G01 X30\nM30\n")
    assert errors(m) == []
    assert ch.setpoints()[:3] == [30.0, 20.0, 0.0]


@pytest.mark.req("C14-11", "C14-14", "C14-15")
def test_u_area_path_inside_runs_and_leaving_the_notch_aborts_at_the_exact_point() -> None:
    m = make_machine()
    ch = run(
        m,
        U_AREA
        + INTO_U
        + "N160 #CONTROL AREA ON [ID3]\n"
        + "N170 G01 X-100 Y100\nN180 G01 X100 Y100\nN190 G01 X100 Y10\n"
        + "N200 G01 X0 Y10\nN210 G01 X0 Y100\nM30\n",
    )
    assert ch.state == ProgramState.ABORTED
    alarm = only_alarm(m, 120486)
    assert alarm.block == "N200"
    assert alarm.line == U_AREA.count("\n") + 6
    assert alarm.params["start"][:3] == [100.0, 10.0, 0.0]
    assert alarm.params["end"][:3] == [0.0, 10.0, 0.0]
    assert alarm.params["intersection"][:3] == pytest.approx([50.0, 10.0, 0.0], abs=1e-9)
    assert "leaves the work area(s) 3 at (X50, Y10, Z0)" in alarm.message
    # the path stopped at the start point of the violating block
    assert ch.setpoints()[:3] == pytest.approx([100.0, 10.0, 0.0], abs=1e-9)
    assert m.hli.channels[0].bahn_state.area_mon_violation_detected_r
    assert state_of(m, 3) == "active"


@pytest.mark.req("C14-14")
def test_work_area_boundary_may_be_followed() -> None:
    """On the boundary of a work area is inside: a path along its edge is allowed."""
    m = make_machine()
    ch = run(
        m,
        U_AREA
        + INTO_U
        + "#CONTROL AREA ON [ID3]\nG01 X-150 Y0\nG01 X-50 Y0\nG01 X-50 Y75\nG01 X50 Y75\nM30\n",
    )
    assert errors(m) == []
    assert ch.state == ProgramState.FINISHED


@pytest.mark.req("C14-05", "C14-14", "C14-15")
def test_cylindrical_protection_area_of_the_document() -> None:
    m = make_machine()
    ch = run(
        m,
        CIRC_PROT
        + "N100 G01 X-100 Y0 F30000\nN110 #CONTROL AREA ON [ID4]\n"
        + "N120 G01 X-100 Y75\nN130 G01 X100 Y75\nM30\n",
    )
    entry = areas(m).to_json()["areas"][0]
    assert entry["shape"] == "CIRC"
    assert entry["kind"] == "PROT"
    assert entry["center"] == [0.0, 75.0]
    assert entry["radius"] == pytest.approx(75.0)
    assert (entry["min"], entry["max"]) == (-70.0, 70.0)
    assert ch.state == ProgramState.ABORTED
    alarm = only_alarm(m, 912001)
    assert alarm.block == "N130"
    assert alarm.params["intersection"][:3] == pytest.approx([-75.0, 75.0, 0.0], abs=1e-9)
    assert ch.setpoints()[:3] == pytest.approx([-100.0, 75.0, 0.0])


@pytest.mark.req("C14-05", "C14-14")
def test_old_excerpt_circle_and_a_tangent_touch() -> None:
    """001's circle: centre (150, 0), radius 50. A line tangent to it touches it: a violation."""
    m = make_machine()
    run(m, CIRC_PROT_OLD + "#CONTROL AREA ON ALL\nN50 G01 X0 Y50 F30000\nN60 G01 X300 Y50\nM30\n")
    entry = areas(m).to_json()["areas"][0]
    assert entry["center"] == [150.0, 0.0]
    assert entry["radius"] == pytest.approx(50.0)
    alarm = only_alarm(m, 912001)
    assert alarm.block == "N60"
    assert alarm.params["intersection"][:2] == pytest.approx([150.0, 50.0], abs=1e-9)


@pytest.mark.req("C14-06", "C14-14")
def test_protection_area_is_a_cylinder_of_limited_height() -> None:
    """Above MAX_EXCUR the cylinder can be passed; coming down into it is a violation."""
    m = make_machine()
    ch = run(
        m,
        CIRC_PROT
        + "N100 G01 X-100 Y75 Z80 F30000\n#CONTROL AREA ON [ID4]\n"
        + "N120 G01 X100 Y75\nN130 G01 X0 Y75 Z0\nM30\n",
    )
    alarm = only_alarm(m, 912001)
    assert alarm.block == "N130"
    # down from (100, 75, 80) toward the axis: through the mantle at x = 75, where z = 60
    assert alarm.params["intersection"][:3] == pytest.approx([75.0, 75.0, 60.0], abs=1e-9)
    assert ch.setpoints()[:3] == pytest.approx([100.0, 75.0, 80.0])
    # straight down onto the top face: enters at z = 70
    m = make_machine()
    run(m, CIRC_PROT + "G01 X0 Y75 Z80 F30000\n#CONTROL AREA ON [ID4]\nN130 G01 Z0\nM30\n")
    assert only_alarm(m, 912001).params["intersection"][:3] == pytest.approx([0.0, 75.0, 70.0], abs=1e-9)


@pytest.mark.req("C14-06", "C14-15")
def test_height_band_of_a_work_area() -> None:
    m = make_machine()
    run(m, U_AREA + INTO_U + "#CONTROL AREA ON [ID3]\nN50 G01 Z50\nN60 G01 Z60\nM30\n")
    alarm = only_alarm(m, 120486)
    assert alarm.block == "N60"
    assert alarm.params["intersection"][:3] == pytest.approx([-100.0, 50.0, 50.0])


@pytest.mark.req("C14-17")
def test_additional_axes_example_of_the_document() -> None:
    m = make_machine()
    prog = EXTRA_AXES_AREA + "N500 #CONTROL AREA ON ALL\nN510 G01 X500 Y-300 F30000\n"
    prog += "N520 X2=50 Y2=-20 Z2=10\n"
    ch = run(m, prog + "N1000 M30\n")
    assert errors(m) == []
    assert ch.state == ProgramState.FINISHED
    (entry,) = areas(m).to_json()["areas"]
    assert entry["axes"] == ["X2", "Y2"]
    assert entry["height_axis"] == "Z2"
    assert entry["points"] == [[100.0, 100.0], [-100.0, 100.0], [-100.0, -100.0], [100.0, -100.0]]
    # the main axes are not watched by it, the additional ones are
    ch = run(m, "N10 G01 X2=150 F30000\nM30\n")
    alarm = only_alarm(m, 120486)
    assert alarm.params["intersection"][3:5] == pytest.approx([100.0, -20.0])
    assert ch.state == ProgramState.ABORTED


@pytest.mark.req("C14-18")
def test_two_path_and_imcs_are_refused_as_not_supported() -> None:
    m = make_machine()
    ch = run(m, TWO_PATH_AREA + "M30\n")
    assert ch.state == ProgramState.ABORTED
    alarm = only_alarm(m, 910110)
    assert alarm.block == "N40"
    assert 'MONITOR_LVL="IMCS" is not supported' in alarm.message
    m = make_machine()
    run(m, TWO_PATH_AREA.replace('MONITOR_LVL = "IMCS" ', ""))
    alarm = only_alarm(m, 910110)
    assert alarm.block == "N50"
    assert "two-path" in alarm.message


@pytest.mark.req("C14-18")
def test_monitor_level_mcs_is_accepted() -> None:
    m = make_machine()
    run(m, U_AREA.replace("MAX_EXCUR=50]", 'MAX_EXCUR=50 MONITOR_LVL="MCS"]') + "M30\n")
    assert errors(m) == []
    assert state_of(m, 3) == "defined"


# --- ON / OFF / CLEAR and the table -----------------------------------------------------------------
SQUARE = """#CONTROL AREA BEGIN [ID={id} {kind} POLY MIN_EXCUR=-100 MAX_EXCUR=100]
G01 X{x0} Y{y0} F1000
X{x1}
Y{y1}
X{x0}
Y{y0}
#CONTROL AREA END
"""


def square(area_id: int, x0: float, y0: float, x1: float, y1: float, kind: str = "WORK") -> str:
    return SQUARE.format(id=area_id, kind=kind, x0=x0, y0=y0, x1=x1, y1=y1)


@pytest.mark.req("C14-11", "C14-12")
def test_on_off_forms_of_the_document() -> None:
    m = make_machine()
    defs = square(1, -10, -10, 10, 10) + square(2, -20, -20, 20, 20) + square(3, -30, -30, 30, 30)
    run(m, defs + "#CONTROL AREA ON [ID3]\n#CONTROL AREA ON [ID=1]\nM30\n")
    assert [state_of(m, i) for i in (1, 2, 3)] == ["active", "defined", "active"]
    run(m, "#CONTROL AREA OFF\nM30\n")  # bare OFF: the one activated last
    assert [state_of(m, i) for i in (1, 2, 3)] == ["inactive", "defined", "active"]
    run(m, "#CONTROL AREA ON ALL\nM30\n")
    assert [state_of(m, i) for i in (1, 2, 3)] == ["active", "active", "active"]
    run(m, "#CONTROL AREA OFF [ID3]\nM30\n")
    assert [state_of(m, i) for i in (1, 2, 3)] == ["active", "active", "inactive"]
    run(m, "#CONTROL AREA OFF ALL\nM30\n")
    assert [state_of(m, i) for i in (1, 2, 3)] == ["inactive", "inactive", "inactive"]
    assert errors(m) == []


@pytest.mark.req("C14-13")
def test_clear_forms_and_clearing_an_active_area_warns() -> None:
    m = make_machine()
    defs = square(1, -10, -10, 10, 10) + square(2, -20, -20, 20, 20) + square(3, -30, -30, 30, 30)
    run(m, defs + "#CONTROL AREA ON [ID2]\n#CONTROL AREA CLEAR [ID3]\nM30\n")
    assert [state_of(m, i) for i in (1, 2, 3)] == ["defined", "active", None]
    ch = run(m, "N10 #CONTROL AREA CLEAR [ID2]\nN20 G01 X1 F30000\nM30\n")
    warning = only_alarm(m, 120499)
    assert warning.severity == "warning"
    assert warning.block == "N10"
    assert ch.state == ProgramState.FINISHED  # only a warning
    assert state_of(m, 2) == "active"
    run(m, "#CONTROL AREA CLEAR ALL\nM30\n")
    assert [state_of(m, i) for i in (1, 2, 3)] == [None, "active", None]
    assert alarm_ids(m).count(120499) == 2
    run(m, "#CONTROL AREA OFF ALL\n#CONTROL AREA CLEAR ALL\nM30\n")
    assert areas(m).to_json()["areas"] == []


@pytest.mark.req("C14-08", "C14-13")
def test_at_most_twenty_areas_and_clear_frees_a_slot() -> None:
    m = make_machine()
    ch = run(m, "".join(square(i, -i, -i, i, i) for i in range(1, 21)) + "M30\n")
    assert ch.state == ProgramState.FINISHED
    assert len(areas(m).to_json()["areas"]) == 20
    ch = run(m, "N10 G01 X1 F30000\n" + square(21, -5, -5, 5, 5) + "M30\n")
    assert ch.state == ProgramState.ABORTED
    alarm = only_alarm(m, 912002)
    assert "already has 20 areas" in alarm.message
    m.channel(1).request_reset()
    m.step(1)
    ch = run(m, "#CONTROL AREA CLEAR [ID=7]\n" + square(21, -5, -5, 5, 5) + "M30\n")
    assert ch.state == ProgramState.FINISHED
    assert state_of(m, 21) == "defined"
    assert state_of(m, 7) is None


@pytest.mark.req("C14-09")
def test_overwrite_only_while_not_active() -> None:
    m = make_machine()
    run(m, square(1, -10, -10, 10, 10) + square(1, -40, -40, 40, 40) + "M30\n")
    assert areas(m).to_json()["areas"][0]["points"][0] == [-40.0, -40.0]
    run(m, "#CONTROL AREA ON [ID1]\n#CONTROL AREA OFF [ID1]\n" + square(1, -5, -5, 5, 5) + "M30\n")
    entry = areas(m).to_json()["areas"][0]
    assert entry["points"][0] == [-5.0, -5.0]
    assert entry["state"] == "defined"
    ch = run(m, "#CONTROL AREA ON [ID1]\nN50 " + square(1, -9, -9, 9, 9) + "M30\n")
    assert ch.state == ProgramState.ABORTED
    # ID 50774 "Area not saved / active area cannot be overwritten", the kernel's page's own example
    # (https://infosys.beckhoff.com/content/1033/tf5200_diagnosis/258831755.html)
    alarm = only_alarm(m, 50774)
    assert alarm.block == "N50"
    assert "area 1 is active and cannot be overwritten, the area is not saved" in alarm.message
    assert alarm.params == {"id": 1}
    assert areas(m).to_json()["areas"][0]["points"][0] == [-5.0, -5.0]


@pytest.mark.req("C14-10")
def test_reset_deactivates_program_end_does_not_definitions_survive() -> None:
    m = make_machine()
    run(m, square(1, -10, -10, 10, 10) + CIRC_PROT_OLD + "#CONTROL AREA ON ALL\nM30\n")
    assert [state_of(m, i) for i in (1, 4)] == ["active", "active"]
    # program end: still active, and the next program is still monitored
    run(m, "N10 G01 X20 F30000\nM30\n")
    assert only_alarm(m, 120486).block == "N10"
    ch = m.channel(1)
    ch.request_reset()
    m.step(1)
    assert [state_of(m, i) for i in (1, 4)] == ["inactive", "inactive"]
    assert not m.hli.channels[0].bahn_state.area_mon_violation_detected_r
    ch = run(m, "N10 G01 X20 F30000\n#CONTROL AREA ON [ID4]\nM30\n")
    assert ch.state == ProgramState.FINISHED
    assert [state_of(m, i) for i in (1, 4)] == ["inactive", "active"]


@pytest.mark.req("C14-11")
def test_on_outside_the_work_area_is_refused_and_nothing_is_activated() -> None:
    m = make_machine()
    ch = run(m, U_AREA + "N150 #CONTROL AREA ON [ID3]\nN160 G01 X1 F30000\nM30\n")
    assert ch.state == ProgramState.ABORTED
    alarm = only_alarm(m, 120484)
    assert alarm.block == "N150"
    assert "outside the work area(s) 3" in alarm.message
    assert state_of(m, 3) == "defined"
    assert ch.setpoints()[0] == 0.0


@pytest.mark.req("C14-11")
def test_on_inside_a_protection_area_is_refused() -> None:
    m = make_machine()
    ch = run(m, CIRC_PROT + "N50 G01 X0 Y75 F30000\nN60 #CONTROL AREA ON ALL\nM30\n")
    alarm = only_alarm(m, 912000)
    assert alarm.block == "N60"
    assert state_of(m, 4) == "defined"
    assert ch.state == ProgramState.ABORTED
    # on its boundary is a touch: refused too
    m = make_machine()
    run(m, CIRC_PROT + "N50 G01 X75 Y75 F30000\nN60 #CONTROL AREA ON [ID4]\nM30\n")
    assert only_alarm(m, 912000).block == "N60"


@pytest.mark.req("C14-11")
def test_on_is_checked_against_the_union_of_all_active_work_areas() -> None:
    m = make_machine()
    ch = run(
        m,
        square(1, -10, -10, 10, 10)
        + square(2, 100, 100, 110, 110)
        + "#CONTROL AREA ON [ID1]\nN40 #CONTROL AREA ON [ID2]\nM30\n",
    )
    assert ch.state == ProgramState.FINISHED
    assert [state_of(m, i) for i in (1, 2)] == ["active", "active"]


@pytest.mark.req("C14-11", "C14-12", "C14-13")
def test_commands_with_unknown_ids_are_errors() -> None:
    for cmd, name in (("ON [ID=9]", "ON"), ("OFF [ID9]", "OFF"), ("CLEAR [ID=9]", "CLEAR")):
        m = make_machine()
        ch = run(m, square(1, -10, -10, 10, 10) + f"N77 #CONTROL AREA {cmd}\nM30\n")
        assert ch.state == ProgramState.ABORTED
        alarm = only_alarm(m, 912003)
        assert alarm.block == "N77"
        assert alarm.message == f"#CONTROL AREA {name} [ID=9]: area 9 is not defined (defined: 1)"


# --- path checks ----------------------------------------------------------------------------------
@pytest.mark.req("C14-14")
def test_overlapping_work_areas_act_as_their_union() -> None:
    """FCT-C14 Abb. 7: a small work area joins two others; the move from 1 to 2 through it is allowed."""
    m = make_machine()
    defs = square(1, -100, -50, -20, 50) + square(2, 20, -50, 100, 50) + square(3, -30, -5, 30, 5)
    ch = run(m, defs + "#CONTROL AREA ON ALL\nN10 G01 X80 F30000\nN20 G01 X-80\nN30 G01 X-80 Y40\nM30\n")
    assert errors(m) == []
    assert ch.state == ProgramState.FINISHED
    ch = run(m, "N40 G01 X80 Y40\nM30\n")
    alarm = only_alarm(m, 120486)
    assert alarm.block == "N40"
    assert alarm.params["intersection"][:2] == pytest.approx([-20.0, 40.0])


@pytest.mark.req("C14-14")
def test_protection_dominates_a_work_area_it_lies_in() -> None:
    m = make_machine()
    prog = (
        square(1, -100, -100, 100, 100)
        + square(2, -10, -10, 10, 10, "PROT")
        + "G01 X-50 Y0 F30000\n#CONTROL AREA ON ALL\nN50 G01 X50\nM30\n"
    )
    run(m, prog)
    alarm = only_alarm(m, 912001)
    assert alarm.block == "N50"
    assert alarm.params["intersection"][:2] == pytest.approx([-10.0, 0.0])
    assert alarm.params["area"] == 2
    assert alarm.params["kind"] == "PROT"


@pytest.mark.req("C14-14")
def test_touching_a_protection_corner_is_a_violation() -> None:
    m = make_machine()
    prog = square(2, 0, 0, 10, 10, "PROT") + "G01 X-10 Y10 F30000\n#CONTROL AREA ON ALL\n"
    prog += "N50 G01 X10 Y-10\nM30\n"
    run(m, prog)
    alarm = only_alarm(m, 912001)
    assert alarm.params["intersection"][:2] == pytest.approx([0.0, 0.0], abs=1e-9)


@pytest.mark.req("C14-15")
def test_arc_leaving_a_work_area_gives_the_exact_point() -> None:
    """A G02 from (0, 0) around (25, 0) would reach x = 50; the work area ends at x = 40."""
    m = make_machine()
    prog = square(1, -10, -30, 40, 30) + "#CONTROL AREA ON ALL\nN50 G02 X50 Y0 I25 J0 F30000\nM30\n"
    ch = run(m, prog)
    alarm = only_alarm(m, 120486)
    assert alarm.block == "N50"
    x = 40.0
    y = math.sqrt(25.0**2 - (x - 25.0) ** 2)  # clockwise from (0,0) over the top
    assert alarm.params["intersection"][:2] == pytest.approx([x, y], abs=1e-9)
    assert ch.setpoints()[:2] == [0.0, 0.0]


@pytest.mark.req("C14-15")
def test_arc_that_bulges_through_a_protection_area_between_safe_end_points() -> None:
    m = make_machine()
    prog = (
        square(5, -5, 20, 5, 30, "PROT")
        + "G01 X-25 Y0 F30000\n#CONTROL AREA ON ALL\nN50 G02 X25 Y0 I25 J0\nM30\n"
    )
    run(m, prog)
    alarm = only_alarm(m, 912001)
    ix, iy = alarm.params["intersection"][:2]
    assert math.hypot(ix, iy) == pytest.approx(25.0, abs=1e-9)
    assert ix == pytest.approx(-5.0, abs=1e-9)


@pytest.mark.req("C14-15")
def test_helix_in_the_base_plane_is_checked_exactly() -> None:
    """A helix around (0, 0), radius 100, climbing 140 mm over half a turn, enters the cylinder
    (centre (0, 75), radius 75, height -70..70) where the two circles meet, at the height it has there."""
    m = make_machine()
    prog = CIRC_PROT + "G01 X100 Y0 Z0 F30000\n#CONTROL AREA ON ALL\n"
    prog += "N50 G03 X-100 Y0 Z140 I-100 J0\nM30\n"
    run(m, prog)
    alarm = only_alarm(m, 912001)
    assert alarm.block == "N50"
    a = (75.0**2 + 100.0**2 - 75.0**2) / (2 * 75.0)
    theta = math.atan2(a, math.sqrt(100.0**2 - a * a))
    expected = [100.0 * math.cos(theta), 100.0 * math.sin(theta), 140.0 * theta / math.pi]
    assert alarm.params["intersection"][:3] == pytest.approx(expected, abs=1e-9)


@pytest.mark.req("C14-15")
def test_arc_at_an_angle_to_the_base_plane_is_segmented() -> None:
    """An arc in G18 (Z/X) against a G17 area: checked by chords (sagitta <= 0.1 µm)."""
    m = make_machine()
    prog = U_AREA + INTO_U + "#CONTROL AREA ON ALL\nN50 G18 G02 X-40 Z0 I30 K0\nM30\n"
    run(m, prog)
    alarm = only_alarm(m, 120486)
    assert alarm.block == "N50"
    # the circle around (X-70, Z0), radius 30, dips to Z = -30 and leaves the U's arm at X = -50
    z = -math.sqrt(30.0**2 - 20.0**2)
    assert alarm.params["intersection"][:3] == pytest.approx([-50.0, 50.0, z], abs=1e-4)


@pytest.mark.req("C14-16")
def test_zero_offsets_apply_to_areas_and_paths() -> None:
    m = make_machine(
        zero_offsets=[{"code": "G54", "offsets": {"X": 1_000_000, "Z": 100_000}}],  # X +100 mm, Z +10 mm
    )
    run(m, "G54\n" + square(1, -10, -10, 10, 10) + "M30\n")
    entry = areas(m).to_json()["areas"][0]
    assert entry["points"][0] == [90.0, -10.0]
    assert (entry["min"], entry["max"]) == (-90.0, 110.0)
    ch = run(m, "G54 G01 X0 Y0 F30000\n#CONTROL AREA ON [ID1]\nN30 G92 X0\nN40 G01 X15\nM30\n")
    alarm = only_alarm(m, 120486)
    assert alarm.block == "N40"
    assert alarm.params["intersection"][:2] == pytest.approx([110.0, 0.0])
    assert ch.setpoints()[0] == pytest.approx(100.0)


@pytest.mark.req("C14-07")
def test_g18_base_plane_is_z_x_with_height_along_y() -> None:
    m = make_machine()
    prog = (
        "G18\n#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=-100 MAX_EXCUR=100]\n"
        "G01 Z-20 X-10 F1000\nZ20\nX10\nZ-20\nX-10\n#CONTROL AREA END\n"
    )
    run(m, prog + "M30\n")
    entry = areas(m).to_json()["areas"][0]
    assert entry["axes"] == ["Z", "X"]
    assert entry["height_axis"] == "Y"
    assert [-20.0, -10.0] in entry["points"]
    run(m, "#CONTROL AREA ON ALL\nN10 G01 Y99 F30000\nN20 G01 Y101\nM30\n")
    assert only_alarm(m, 120486).block == "N20"


@pytest.mark.req("C14-06")
def test_excur_ax_and_excur_axnr_name_the_height_axis() -> None:
    m = make_machine()
    run(m, square(1, -10, -10, 10, 10).replace("MAX_EXCUR=100]", "MAX_EXCUR=100 EXCUR_AX=Z2]") + "M30\n")
    assert areas(m).to_json()["areas"][0]["height_axis"] == "Z2"
    run(m, square(2, -10, -10, 10, 10).replace("MAX_EXCUR=100]", "MAX_EXCUR=100 EXCUR_AXNR=5]") + "M30\n")
    assert areas(m).to_json()["areas"][1]["height_axis"] == "Y2"  # axis number 5 is Y2
    run(m, "#CONTROL AREA ON [ID1]\nN10 G01 Z500 F30000\nN20 G01 Z2=101\nM30\n")
    assert only_alarm(m, 120486).block == "N20"


@pytest.mark.req("C14-21")
def test_violation_sets_the_plc_flag_until_reset() -> None:
    m = make_machine()
    ch = run(m, square(1, -10, -10, 10, 10) + "#CONTROL AREA ON [ID1]\nN10 G01 X5 F30000\nN20 G01 X20\nM30\n")
    flag = m.hli.channels[0].bahn_state
    assert flag.area_mon_violation_detected_r
    assert flag.error_id_r == 120486
    ch.request_reset()
    m.step(1)
    assert not flag.area_mon_violation_detected_r


@pytest.mark.req("C14-11", "C14-15")
def test_activation_takes_effect_when_the_path_reaches_it() -> None:
    """The decoder reads ahead; the PLC-visible table changes when the path reaches the ON."""
    m = make_machine()
    run(m, square(1, -100, -100, 100, 100) + "M30\n")
    ch = m.channel(1)
    ch.load_program("N10 G01 X90 F6000\nN20 #CONTROL AREA ON [ID1]\nN30 G01 X0\nM30\n")
    ch.request_start()
    m.step(20)
    assert ch.state == ProgramState.RUNNING
    assert areas(m).planned.state(1) == "active"  # decoded
    assert state_of(m, 1) == "defined"  # not yet reached
    while ch.state == ProgramState.RUNNING:
        m.step(1)
    assert state_of(m, 1) == "active"


@pytest.mark.req("C14-11", "C14-10")
def test_an_on_that_was_decoded_but_never_reached_did_not_happen() -> None:
    m = make_machine()
    run(m, square(1, -100, -100, 100, 100) + "M30\n")
    ch = m.channel(1)
    ch.load_program("N10 G01 X90 F6000\nN20 #CONTROL AREA ON [ID1]\nN30 G01 X0\nM30\n")
    ch.request_start()
    m.step(20)
    ch.request_reset()
    m.step(1)
    run(m, "N10 G01 X0 F30000\nN20 G01 X500\nM30\n")  # the area is not active: no alarm
    assert errors(m) == []
    assert state_of(m, 1) == "defined"


@pytest.mark.req("C14-15", "C14-22")
def test_start_point_outside_gives_120484() -> None:
    """Jogged out of the work area with the monitoring suppressed, the next block cannot start."""
    m = make_machine()
    run(m, square(1, -10, -10, 10, 10) + "G01 X5 F30000\n#CONTROL AREA ON ALL\nM30\n")
    ch = m.channel(1)
    ch.request_mode(Mode.MANUAL)
    unit = m.hli.channels[0].bahn_mc_control.suppress_area_mon_manual_mode
    unit.enable_w = unit.command_w = True
    ch.request_jog("X", +1)
    while ch.axis("X").setpoint < 20.0:
        m.step(1)
    ch.request_jog("X", 0)
    m.step(200)
    ch.request_mode(Mode.AUTOMATIC)
    m.step(1)
    x = ch.axis("X").setpoint
    run(m, "N10 G01 X0 F30000\nM30\n")
    alarm = only_alarm(m, 120484)
    assert alarm.block == "N10"
    assert f"start point (X{x:.4f}".rstrip("0") in alarm.message
    assert "of N10 is outside the work area(s) 1" in alarm.message


@pytest.mark.req("C14-17", "C14-15")
def test_arc_of_the_main_axes_with_a_linear_additional_axis() -> None:
    """For an area on X2/Y2/Z2 an XY circle with X2 moving along is a straight line: exact too."""
    m = make_machine()
    run(m, EXTRA_AXES_AREA + "#CONTROL AREA ON ALL\nM30\n")
    run(m, "N10 G02 X10 Y0 I5 J0 X2=150 F30000\nM30\n")
    alarm = only_alarm(m, 120486)
    assert alarm.block == "N10"
    p = alarm.params["intersection"]
    assert p[3] == pytest.approx(100.0, abs=1e-9)
    angle = math.pi - math.pi * (100.0 / 150.0)  # clockwise from 180° over the top
    assert p[:2] == pytest.approx([5.0 + 5.0 * math.cos(angle), 5.0 * math.sin(angle)], abs=1e-9)
    assert "(X2=100, Y2=0, Z2=0)" in alarm.message
