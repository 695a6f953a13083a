"""``hli-server check``: the offline check a user runs before a program goes to the machine (E-04, E-06)."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from hli_server.cli import main
from tests.spec_examples import U_AREA

GOOD = "N10 G01 X100 Y50 F6000\nN20 G02 X150 Y100 I50 J0\nN30 G01 X0 Y0\nN40 M30\n"
BEYOND_LIMIT = "N10 G01 X100 Y50 F6000\nN20 G01 X100 Y800\nN30 M30\n"
SYNTAX = "N10 G01 X10 F6000\nN20 G01 X20 Q7\nN30 M30\n"


def invoke(tmp_path, program: str, *args: str):
    path = tmp_path / "prog.nc"
    path.write_text(program)
    return CliRunner().invoke(main, ["check", str(path), *args])


@pytest.mark.req("E-04")
@pytest.mark.parametrize("mode", [[], ["--geometry-only"]])
def test_good_program_runs_to_the_end(tmp_path, mode):
    result = invoke(tmp_path, GOOD, "--format", "json", *mode)
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["completed"] is True
    assert report["alarms"] == []
    assert report["final_position"]["X"] == pytest.approx(0.0)
    assert report["blocks"] == 4
    if not mode:
        assert report["cycles"] > 1000


@pytest.mark.req("E-06")
@pytest.mark.parametrize("mode", [[], ["--geometry-only"]])
def test_soft_limit_violation_stops_with_line_and_block(tmp_path, mode):
    result = invoke(tmp_path, BEYOND_LIMIT, "--format", "json", *mode)
    assert result.exit_code == 1
    report = json.loads(result.output)
    assert report["completed"] is False
    (alarm,) = report["alarms"]
    assert alarm["id"] == 911011
    assert alarm["severity"] == "error"
    assert (alarm["line"], alarm["block"]) == (2, "N20")
    assert alarm["params"]["axis"] == "Y"
    # stopped at the start point of the refused block
    assert report["final_position"]["Y"] == pytest.approx(50.0)


@pytest.mark.req("E-04")
def test_syntax_error_is_an_alarm_with_line_and_block(tmp_path):
    result = invoke(tmp_path, SYNTAX)
    assert result.exit_code == 1
    assert "910100" in result.output
    assert "line 2, N20" in result.output


def test_missing_file_and_bad_config_are_usage_errors(tmp_path):
    result = CliRunner().invoke(main, ["check", str(tmp_path / "nope.nc")])
    assert result.exit_code == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("this is [not toml\n")
    prog = tmp_path / "p.nc"
    prog.write_text(GOOD)
    result = CliRunner().invoke(main, ["check", str(prog), "--config", str(bad)])
    assert result.exit_code == 2
    assert "configuration" in result.output


COLLISION = "N10 G01 X1=100 F6000\nN20 X1=490\nN30 M30\n"

AREAS = (
    U_AREA
    + """\
N150 G01 X-100 Y50 F3000
N160 #CONTROL AREA ON [ID3]
N170 G01 X100 Y50
N180 M30
"""
)


@pytest.mark.req("C3-01")
def test_check_stops_the_demo_collision_pair_at_the_right_block(tmp_path):
    result = invoke(tmp_path, COLLISION, "--channel", "2", "--format", "json")
    assert result.exit_code == 1
    report = json.loads(result.output)
    (alarm,) = report["alarms"]
    assert alarm["id"] == 70092
    assert (alarm["line"], alarm["block"]) == (2, "N20")
    # the pair stopped before the minimum distance (20 mm) was reached
    pos = report["final_position"]
    assert pos["X2"] - pos["X1"] >= 20.0


@pytest.mark.req("C14-15")
@pytest.mark.parametrize("mode", [[], ["--geometry-only"]])
def test_check_reports_the_area_violation_and_the_area_table(tmp_path, mode):
    result = invoke(tmp_path, AREAS, "--format", "json", *mode)
    assert result.exit_code == 1
    report = json.loads(result.output)
    (alarm,) = report["alarms"]
    assert alarm["id"] == 120486
    assert (alarm["line"], alarm["block"]) == (16, "N170")
    # the path leaves the U through its inner corner at X-50 Y50
    assert alarm["params"]["intersection"][:2] == pytest.approx([-50.0, 50.0])
    assert report["final_position"]["X"] == pytest.approx(-100.0)
    (area,) = report["areas"]
    assert (area["id"], area["kind"], area["shape"], area["state"]) == (3, "WORK", "POLY", "active")
    assert (area["min"], area["max"]) == (-50.0, 50.0)


@pytest.mark.req("C14-15")
def test_check_plot_draws_areas_and_path(tmp_path):
    out = tmp_path / "plot.svg"
    result = invoke(tmp_path, AREAS, "--plot", str(out))
    assert result.exit_code == 1
    svg = out.read_text()
    assert svg.startswith("<?xml")
    assert "ID3" in svg


@pytest.mark.req("E-04")
@pytest.mark.parametrize("mode", [[], ["--geometry-only"]])
def test_program_without_m30_runs_to_its_end_with_a_warning(tmp_path, mode):
    result = invoke(tmp_path, "N10 G01 X10 F1000\nN20 X20\n", "--format", "json", *mode)
    assert result.exit_code == 0
    report = json.loads(result.output)
    assert report["completed"] is True
    (alarm,) = report["alarms"]
    assert (alarm["id"], alarm["severity"]) == (911005, "warning")
    assert (alarm["line"], alarm["block"]) == (2, "N20")
    assert report["final_position"]["X"] == pytest.approx(20.0)
