"""``hli-server check``: the offline check a user runs before a program goes to the machine (E-04, E-06)."""

from __future__ import annotations

import io
import json
import math
import re
import sys

import pytest
from click.testing import CliRunner

from hli_server.cli import main
from hli_server.commands.check import _Progress, check_program
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.plot import supported_formats
from tests.spec_examples import CIRC_PROT, U_AREA

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
    assert alarm["id"] == 120002
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
def test_check_plot_draws_areas_path_refused_block_and_violation(tmp_path):
    out = tmp_path / "plot.svg"
    result = invoke(tmp_path, AREAS, "--plot", str(out))
    assert result.exit_code == 1
    svg = out.read_text()
    assert svg.startswith("<?xml")
    assert "ID3" in svg
    assert "refused block N170 (line 16, alarm 120486)" in svg
    assert "violation (X-50, Y50, Z0), area 3" in svg
    assert "side view" in svg
    assert result.stderr == f"plot written: {out}\n"


# what each format's file starts with (raw/rgba: bare pixels, no signature)
MAGIC = {
    "eps": [b"%!PS-Adobe"],
    "ps": [b"%!PS-Adobe"],
    "pdf": [b"%PDF-"],
    "png": [b"\x89PNG\r\n\x1a\n"],
    "svg": [b"<?xml"],
    "svgz": [b"\x1f\x8b"],
    "jpg": [b"\xff\xd8\xff"],
    "jpeg": [b"\xff\xd8\xff"],
    "gif": [b"GIF87a", b"GIF89a"],
    "tif": [b"II*\x00", b"MM\x00*"],
    "tiff": [b"II*\x00", b"MM\x00*"],
    "webp": [b"RIFF"],
    "pgf": [b"%% Creator: Matplotlib"],
}


def _writable_here(fmt: str) -> bool:
    """pgf needs the TeX system matplotlib is configured for; every other listed format must work."""
    if fmt != "pgf":
        return True
    import shutil

    import matplotlib

    return shutil.which(matplotlib.rcParams["pgf.texsystem"]) is not None


@pytest.mark.parametrize("fmt", sorted(supported_formats()))
def test_check_plot_writes_every_format_matplotlib_lists(tmp_path, fmt):
    out = tmp_path / f"plot.{fmt}"
    result = invoke(tmp_path, AREAS, "--geometry-only", "--plot", str(out))
    if not _writable_here(fmt):
        # refused before the run with the reason, not a traceback after it
        assert result.exit_code == 2
        assert f"cannot write .{fmt} on this installation" in result.stderr
        assert not out.exists()
        return
    assert result.exit_code == 1, result.output  # the program leaves the U (120486)
    data = out.read_bytes()
    assert len(data) > 100
    if fmt in MAGIC:
        assert any(data.startswith(m) for m in MAGIC[fmt]), data[:16]
    if fmt == "webp":
        assert data[8:12] == b"WEBP"
    if fmt == "avif":
        assert data[4:12] == b"ftypavif"
    if fmt in ("raw", "rgba"):
        assert len(data) % 4 == 0  # RGBA pixels
    assert f"plot written: {out}" in result.stderr


@pytest.fixture
def no_run(monkeypatch):
    """Fails the test if the check starts: refusals must come before any cycle runs."""

    def refuse(*args, **kwargs):
        raise AssertionError("the check ran although --plot should have been refused first")

    monkeypatch.setattr("hli_server.commands.check.check_program", refuse)


@pytest.mark.usefixtures("no_run")
def test_an_unknown_plot_suffix_is_a_usage_error_before_the_run(tmp_path):
    result = invoke(tmp_path, AREAS, "--plot", str(tmp_path / "plot.doc"))
    assert result.exit_code == 2
    assert "matplotlib does not write .doc files" in result.stderr
    for listed in (".pdf", ".svg", ".png", ".eps", ".ps"):
        assert listed in result.stderr
    assert result.stdout == ""


@pytest.mark.usefixtures("no_run")
def test_a_plot_without_suffix_is_a_usage_error_before_the_run(tmp_path):
    result = invoke(tmp_path, AREAS, "--plot", str(tmp_path / "plot"))
    assert result.exit_code == 2
    assert "no file suffix" in result.stderr


@pytest.mark.usefixtures("no_run")
def test_an_unwritable_plot_place_is_a_usage_error_before_the_run(tmp_path):
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("a file where a directory should be")
    result = invoke(tmp_path, AREAS, "--plot", str(blocker / "plot.pdf"))
    assert result.exit_code == 2
    assert "is not a writable directory" in result.stderr


@pytest.mark.req("E-04")
@pytest.mark.parametrize("fmt", ["text", "json"])
def test_the_report_is_printed_even_when_the_plot_fails(tmp_path, monkeypatch, fmt):
    def broken(*args, **kwargs):
        raise OSError("No space left on device")

    monkeypatch.setattr("hli_server.plot.plot_scene", broken)
    out = tmp_path / "plot.pdf"
    result = invoke(tmp_path, AREAS, "--format", fmt, "--plot", str(out))
    assert result.exit_code == 1  # the check's verdict (120486), not the plot's
    if fmt == "json":
        assert json.loads(result.stdout)["alarms"][0]["id"] == 120486
    else:
        assert "error 120486: line 16, N170" in result.stdout
    assert "error: plot not written" in result.stderr
    assert "No space left on device" in result.stderr
    assert "plot written:" not in result.stderr
    assert "Traceback" not in result.output


def test_a_good_program_keeps_exit_0_and_json_stdout_with_a_plot(tmp_path):
    out = tmp_path / "plot.pdf"
    result = invoke(tmp_path, GOOD, "--format", "json", "--plot", str(out))
    assert result.exit_code == 0
    assert json.loads(result.stdout)["completed"] is True
    assert out.read_bytes().startswith(b"%PDF-")
    assert result.stderr == f"plot written: {out}\n"


# programs whose reports carried float noise before (issue 15): the intersection of an arc with the
# U's inner edge was 75.00000000000001; G91 steps of 0.1 left Z at -1.1102230246251565e-16 and the
# final position at -0.0
NOISY_ARC = (
    U_AREA + "N150 G01 X-100 Y50 F3000\nN160 #CONTROL AREA ON [ID3]\nN170 G02 X0 Y50 I50 J0\nN180 M30\n"
)
NOISY_STEPS = (
    CIRC_PROT
    + "N50 G01 X-100 Y75 Z0 F3000\nN60 #CONTROL AREA ON [ID4]\nN65 G91\n"
    + "N70 G01 Z0.1\n" * 10
    + "N75 Z-1\nN76 X200\nN80 M30\n"
)


def _floats(value):
    if isinstance(value, float):
        yield value
    elif isinstance(value, dict):
        for v in value.values():
            yield from _floats(v)
    elif isinstance(value, list):
        for v in value:
            yield from _floats(v)


@pytest.mark.req("C14-15")
@pytest.mark.parametrize("mode", [[], ["--geometry-only"]])
def test_no_float_noise_in_the_json_report(tmp_path, mode):
    arc = json.loads(invoke(tmp_path, NOISY_ARC, "--format", "json", *mode).stdout)
    (alarm,) = arc["alarms"]
    assert alarm["params"]["intersection"] == [-6.6987, 75.0, 0.0]
    assert alarm["params"]["arc"] == {"plane": ["X", "Y"], "centre": [-50.0, 50.0], "sweep_deg": -180.0}
    steps_text = invoke(tmp_path, NOISY_STEPS, "--format", "json", *mode).stdout
    steps = json.loads(steps_text)
    (alarm,) = steps["alarms"]
    assert alarm["params"]["start"] == [-100.0, 75.0, 0.0]
    assert alarm["params"]["intersection"] == [-75.0, 75.0, 0.0]
    assert "e-" not in steps_text
    for report in (arc, steps):
        values = [v for k, v in report.items() if k not in ("elapsed_s", "simulated_time_s")]
        numbers = list(_floats(values))
        assert numbers
        assert all(round(v, 4) == v for v in numbers)
        assert all(math.copysign(1.0, v) > 0 for v in numbers if v == 0.0)  # no -0.0


def test_no_float_noise_in_the_text_report(tmp_path):
    text = invoke(tmp_path, NOISY_STEPS).stdout
    assert '"start": [-100.0, 75.0, 0.0]' in text
    assert "e-16" not in text
    assert "Z=0.0000" in text
    assert "-0.0000" not in text
    text = invoke(tmp_path, NOISY_ARC).stdout
    assert "75.00000000000001" not in text
    assert '"intersection": [-6.6987, 75.0, 0.0]' in text
    assert "ID3 WORK POLY active, X/Y plane, height Z -50..50" in text


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


# about 10 000 cycles: several updates of the meter (one every 1000 cycles)
LONG = "N10 G01 F6000 X0\n" + "".join(f"N{20 + k} X{(k % 2) * 100}\n" for k in range(10)) + "N999 M30\n"


@pytest.mark.req("E-04")
def test_progress_on_a_terminal_shows_rate_and_time_left(monkeypatch):
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    monkeypatch.setattr(_Progress, "refresh_s", 0.0)  # every update redraws, however fast the machine
    result = check_program(Machine(load_machine(None)), LONG, progress=True)
    assert result.completed
    shown = terminal.getvalue()
    assert "checking" in shown
    assert "lines/s" in shown
    assert "blocks/s" in shown
    assert re.search(r"\[\d\d:\d\d<\d\d:\d\d", shown), shown[-300:]  # elapsed<left


def test_no_progress_when_stderr_is_not_a_terminal(monkeypatch):
    captured = io.StringIO()
    monkeypatch.setattr(sys, "stderr", captured)
    check_program(Machine(load_machine(None)), LONG, progress=True)
    assert captured.getvalue() == ""


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
