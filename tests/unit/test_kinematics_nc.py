"""Kinematic transformations from NC program text (issue 35): ``#KIN ID``, ``#TRAFO``, ``V.G.KIN[i]``
writes, ``#CAXTRACK``, ``#SET AX``, ``#CYL``, ``#TOOL ORI CS`` read by the interpreter and run by ``check``
(full and geometry) on the shipped five-axis machine file (``hli_server/machines/five_axis.toml``: a CA
head, ID 5, with its A axis 150 mm above the tool's fixing point; D1 is 100 mm long).

The programs are this project's own, written after the manuals' examples (docs/kinematics.md)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from hli_server.cli import main
from hli_server.commands.check import check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.engine.program_check import CheckResult
from schemas.wire import ProgramState

FIVE_AXIS = Path(__file__).parents[2] / "hli_server" / "machines" / "five_axis.toml"
MODES = [False, True]
"""Full check, geometry check."""

RTCP = """\
N10 D1
N20 G01 X0 Y0 Z0 C0 A0 F2000
N30 #KIN ID[5]
N40 #TRAFO ON
N50 G01 A30
N60 G01 X50 Z10
N70 #TRAFO OFF
N80 M30
"""
ARM_MM = 250.0
"""Tool tip to the A axis: the 100 mm tool plus the head's 150 mm."""


def check(text: str, geometry_only: bool, *, record: bool = False) -> CheckResult:
    return check_program(
        Machine(load_machine(FIVE_AXIS)), text, geometry_only=geometry_only, record_path=record
    )


def errors(result: CheckResult) -> list[tuple[int, int | None]]:
    return [(a.number, a.line) for a in result.alarms if a.severity == "error"]


@pytest.mark.req("K-04")
@pytest.mark.req("K-06")
@pytest.mark.parametrize("geometry_only", MODES)
def test_rtcp_program_keeps_the_tool_tip_and_reports_both_paths(geometry_only: bool) -> None:
    """A30 with RTCP on: the tip stays at X0 Y0 Z0, the axes swing Y and Z round the A axis 250 mm away;
    then the tip goes to X50 Z10. The report names the kinematic, the axes' and the tip's ranges."""
    result = check(RTCP, geometry_only)
    assert result.completed, errors(result)
    assert errors(result) == []
    drop = ARM_MM * (1.0 - math.cos(math.radians(30.0)))
    end = result.final_position
    assert (end["X"], end["Y"], end["Z"], end["A"]) == pytest.approx(
        (50.0, -125.0, 100.0 - drop + 10.0, 30.0)
    )
    report = result.to_json()["kinematics"]
    assert report["used"] == [{"id": 5, "name": "Universal Kinematics (5 axes)"}]
    assert report["tool_tip_range"] == {"X": [0.0, 50.0], "Y": [0.0, 0.0], "Z": [0.0, 10.0]}
    assert report["final_tool_tip"] == {"X": 50.0, "Y": 0.0, "Z": 10.0}
    assert report["axis_range"]["A"] == [0.0, 30.0]
    assert report["axis_range"]["Y"] == pytest.approx([-125.0, 0.0], abs=1e-3)
    assert report["axis_range"]["Z"][1] == pytest.approx(100.0)


def test_without_a_transformation_the_report_has_no_kinematics() -> None:
    result = check("N10 G01 X10 F1000\nM30\n", True)
    assert "kinematics" not in result.to_json()


@pytest.mark.req("K-06")
def test_check_text_report_and_plot_show_the_tool_path(tmp_path: Path) -> None:
    program = tmp_path / "rtcp.nc"
    program.write_text(RTCP)
    picture = tmp_path / "rtcp.svg"
    result = CliRunner().invoke(
        main, ["check", str(program), "--config", str(FIVE_AXIS), "--geometry-only", "--plot", str(picture)]
    )
    assert result.exit_code == 0, result.output
    assert "kinematic transformation: ID 5 (Universal Kinematics (5 axes))" in result.output
    assert "tool tip (TCP, mm): X 0..50, Y 0..0, Z 0..10" in result.output
    assert picture.stat().st_size > 0
    recorded = check(RTCP, True, record=True)
    assert recorded.kinematics.tool_path[-1][:3] == pytest.approx((50.0, 0.0, 10.0))
    assert recorded.path[-1][:3] != pytest.approx((50.0, 0.0, 10.0))  # the axes' path is another


@pytest.mark.req("K-03")
@pytest.mark.parametrize(
    "write",
    ["V.G.KIN[5].PARAM[41] = 2500000", "V.G.KIN[5].AXIS[4].POINT[2] = 2500000"],
    ids=["PARAM", "named"],
)
def test_param_writes_move_the_pivot(write: str) -> None:
    """The A axis' point written to 250 mm (0.1 µm units): the arm is 350 mm, A30 swings Y to -175."""
    program = (
        f"{write}\nN10 D1\nN20 G01 X0 Y0 Z0 C0 A0 F2000\nN30 #KIN ID[5]\nN40 #TRAFO ON\nN50 A30\nN60 M30\n"
    )
    result = check(program, True)
    assert errors(result) == []
    assert result.final_position["Y"] == pytest.approx(-175.0)


def test_a_write_to_an_unknown_member_is_refused() -> None:
    result = check("V.G.KIN[5].SOMETHING[1] = 2\nM30\n", True)
    assert errors(result)[0][1] == 1


@pytest.mark.req("K-03")
@pytest.mark.parametrize(
    ("program", "alarm", "line"),
    [
        ("#KIN ID[5]\n#TRAFO ON\n#KIN ID[7]\nM30\n", 20687, 3),
        ("D1\nG01 X0 Y0 Z0 F100\n#KIN ID[5]\n#TRAFO ON\nD2\nM30\n", 20990, 5),
        ("#KIN ID[5]\n#TRAFO ON\n#SET AX [X, 1, 0]\nM30\n", 20683, 3),
        ("#SET AX [X, 1, 0] [X, 2, 1]\nM30\n", 21256, 1),
        ("#SET AX [X, 1, 0] [Y, 2, 0]\nM30\n", 21257, 1),
        ("#SET AX [X, 1, 0] [Y, 1, 1]\nM30\n", 21258, 1),
        ("#CAXTRACK ON [ANGLIMIT=400]\nM30\n", 21135, 1),
    ],
)
def test_the_kernels_errors_from_program_text(program: str, alarm: int, line: int) -> None:
    for geometry_only in MODES:
        assert errors(check(program, geometry_only))[:1] == [(alarm, line)]


@pytest.mark.parametrize(
    "program",
    [
        "#TRAFO\nM30\n",
        "#TRAFO ON X\nM30\n",
        "#KIN ID[5\nM30\n",
        "#CAXTRACK\nM30\n",
        "#CAXTRACK ON [OPTALIGN=1]\nM30\n",
        "#CAXTRACK ON [START_STROKE]\nM30\n",
        "#CAXTRACK ON [SCALEFACT=2]\nM30\n",
        "#SET AX\nM30\n",
        "#CYL [RADIUS=20 LIMIT=1]\nM30\n",
        "#TOOL ORI\nM30\n",
    ],
)
def test_malformed_commands_stop_at_their_line(program: str) -> None:
    result = check(program, True)
    assert not result.completed
    assert errors(result)[0][1] == 1


def test_warning_21250_caxtrack_still_on_at_the_end() -> None:
    result = check("#CAXTRACK ON\nG01 X10 F1000\nM30\n", True)
    assert result.completed
    assert 21250 in [a.number for a in result.alarms]


TUBE = """\
%tube
V.G.KIN[90].PARAM[0] = 800000 (* HD1: 80 mm from the B axis to the fixing point *)
V.G.KIN[90].PARAM[12] = 0 (* HD13: AB head *)
V.G.KIN[90].PARAM[13] = 1 (* HD14: program virtual C-A angles *)
N10 #KIN ID[90]
N20 G01 X0 Y0 Z0 A0 C0 F3000
N30 #TRAFO ON
N40 G01 X0 Y0 Z0 C0 A30
N50 #CAXTRACK ON [ANGLIMIT 1]
N60 G261
N70 G01 G91 X40
N80 G90 G02 J-20
N90 G01 G91 X40
N100 G260
N110 #CAXTRACK OFF
N120 #TRAFO OFF
N130 M30
"""


@pytest.mark.req("K-02")
@pytest.mark.req("K-04")
@pytest.mark.parametrize("geometry_only", MODES)
def test_tube_head_with_caxtrack_runs_and_keeps_the_tool_tip_on_the_path(geometry_only: bool) -> None:
    """The TF5290 AB head programmed in virtual C-A angles (HD14 = 1) with #CAXTRACK: the tool leans 30°
    across the direction of motion (virtual A30), the virtual C follows the tangent (the circle turns it a
    full turn). The tool tip ends where the program's path ends (X80 Y0: the circle is closed); the head's
    axes are on the indices 3 and 4 (named C and A in this machine file, as the corpus program's
    ``#SET AX`` names them): at the end, moving along +X, the lean is the AB head's A (about X) alone."""
    result = check(TUBE, geometry_only)
    assert errors(result) == [], result.alarms
    assert result.completed
    report = result.to_json()["kinematics"]
    assert report["used"] == [{"id": 90, "name": "TF5290 AB head, CA programming"}]
    assert report["final_tool_tip"] == pytest.approx({"X": 80.0, "Y": 0.0, "Z": 0.0}, abs=1e-3)
    assert report["tool_tip_range"]["Y"] == pytest.approx([-40.0, 0.0], abs=1e-3)
    assert report["axis_range"]["C"] == pytest.approx([-30.0, 30.0], abs=1e-3)  # the lean turns round
    end = result.final_position
    assert (end["C"], end["A"]) == pytest.approx((30.0, 0.0), abs=1e-9)
    # the tip 80 mm below the B axis, leaning 30° about X: the axes stand off the tip
    assert (end["X"], end["Y"], end["Z"]) == pytest.approx((80.0, -40.0, 80.0 * math.cos(math.radians(30.0))))


@pytest.mark.req("K-04")
def test_cyl_and_tool_ori_cs_from_program_text() -> None:
    """#CYL [X, C, Z35] (C in mm of the development) and #TOOL ORI CS under #CS ON [.. 30° about X]."""
    cyl = check(
        "N10 G01 X0 Y0 Z35 C0 A0 F1000\nN20 #CYL [X, C, Z35]\nN30 G01 X5 C10\nN40 #CYL OFF\nM30\n", True
    )
    assert errors(cyl) == []
    assert cyl.final_position["C"] == pytest.approx(10.0 * 180.0 / (35.0 * math.pi), abs=1e-4)
    ori = check(
        "N10 D1\nN20 G01 X0 Y0 Z0 C0 A0 F1000\nN30 #KIN ID[5]\nN40 #TRAFO ON\n"
        "N50 #CS ON [0, 0, 0, 30, 0, 0]\nN60 #TOOL ORI CS\nN70 #CS OFF\nN80 #TRAFO OFF\nM30\n",
        True,
    )
    assert errors(ori) == []
    assert ori.final_position["A"] == pytest.approx(30.0)
    assert ori.to_json()["kinematics"]["final_tool_tip"] == pytest.approx({"X": 0.0, "Y": 0.0, "Z": 0.0})


@pytest.mark.req("K-07")
def test_the_image_shows_the_active_kinematic_and_the_tool_tip() -> None:
    """BahnState: kin_id_r / trafo_active_r while the transformation is on, tcp_*_r the tool tip (0.1 µm)
    while the axes stand elsewhere; 0 / False again after #TRAFO OFF."""
    m = Machine(load_machine(FIVE_AXIS))
    ch = m.channel(1)
    ch.load_program(RTCP.replace("N70 #TRAFO OFF\n", "N65 G04 X0.5\nN70 #TRAFO OFF\n"), "rtcp")
    ch.request_start()
    seen = None
    for _ in range(20_000):
        m.step(1)
        st = ch.hli.bahn_state
        if st.trafo_active_r and ch.current_block is not None and ch.current_block.number == 65:
            seen = (st.kin_id_r, st.tcp_x_r, st.tcp_y_r, st.tcp_z_r, ch.axes[1].setpoint)
        if ch.state not in (ProgramState.RUNNING, ProgramState.HELD):
            break
    assert seen is not None
    assert seen[:4] == (5, 500_000, 0, 100_000)
    assert seen[4] == pytest.approx(-125.0)
    st = ch.hli.bahn_state
    assert (st.kin_id_r, st.trafo_active_r) == (0, False)


def test_check_json_carries_the_kinematics(tmp_path: Path) -> None:
    program = tmp_path / "rtcp.nc"
    program.write_text(RTCP)
    result = CliRunner().invoke(main, ["check", str(program), "--config", str(FIVE_AXIS), "--format", "json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["kinematics"]["final_tool_tip"] == {"X": 50.0, "Y": 0.0, "Z": 10.0}


@pytest.mark.req("K-08")
@pytest.mark.parametrize("geometry_only", MODES)
def test_a_manual_style_program_without_feed_runs_on_the_default_feed(geometry_only: bool) -> None:
    """As the manual's short #TRAFO examples: no F word, no M30; the machine's P-CHAN-00099 gives the
    feed, the end of the text ends the program (warning 911005)."""
    result = check("N1 #KIN ID[5]\nN2 #TRAFO ON\nN3 X40 Y-20 A0\nN4 Z5 C90\nN5 #TRAFO OFF\n", geometry_only)
    assert errors(result) == []
    assert result.completed
    assert 911005 in [a.number for a in result.alarms]
    assert result.to_json()["kinematics"]["final_tool_tip"] == {"X": 40.0, "Y": -20.0, "Z": 5.0}


@pytest.mark.req("K-09")
def test_the_benchmarks_programs_run_with_and_without_the_transformation() -> None:
    """``benchmarks/bench_kinematics.py``'s programs, small: the tilted head's tip follows the same path
    with #TRAFO ON as the axes without it, in about the same machining time (the tip's feed: the axes
    may slow it where they would travel faster than allowed)."""
    from benchmarks.bench_engine import long_program
    from benchmarks.bench_kinematics import _geometry, _run_to_end, plain, transformed, turning

    text = long_program(12)
    plain_cycles, _ = _run_to_end(plain(text))
    cycles, _ = _run_to_end(transformed(text))
    assert plain_cycles * 0.95 <= cycles <= plain_cycles * 1.5
    for make in (lambda t: t, turning):
        assert (
            _geometry(transformed(make(text)), exact=False)[1] == _geometry(plain(make(text)), exact=True)[1]
        )
