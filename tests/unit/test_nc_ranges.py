"""Every number of an NC program is range-checked where it is read (E-04; issue 12 finding 1).

The issue's inputs, quoted: ``N10 G01 X1<305 zeros> F1000`` killed a running server on the next
cycle (OverflowError in the soft-limit monitor), ``G02 X0 Y0 I1<154 zeros> J0 F1`` and
``G03 Z1<155 zeros> X10 Y0 I5 J0 F1`` crashed ``check`` in ``engine/geometry.py``, and an area polygon
with a vertex at Y=1e300 crashed it in ``engine/areas/geometry.py``. Each is now alarm 910111 naming
line, block and range; the machine keeps stepping and runs the next program.
"""

from __future__ import annotations

import json
import math

import pytest
from click.testing import CliRunner

from hli_server.cli import main
from hli_server.engine.alarms import ALARMS
from hli_server.engine.areas import channel_areas
from hli_server.engine.geometry import arc_from_centre
from hli_server.engine.hli import ProgramState
from hli_server.engine.nc import NcError, parse_line
from schemas.config import ZeroOffset
from schemas.units import DISTANCE_LIMIT_MM, POSITION_LIMIT_MM
from tests.unit.engine_helpers import mill, run

AXES = ("X", "Y", "Z", "X2")
OUT_OF_RANGE = 910111

X_1E305 = "N10 G01 X1" + "0" * 305 + " F1000\nN20 M30\n"
"""Issue 12 finding 1: the two-line program that ended a running server."""
ARC_1E154 = "G02 X0 Y0 I1" + "0" * 154 + " J0 F1\n"
HELIX_1E155 = "G03 Z1" + "0" * 155 + " X10 Y0 I5 J0 F1\n"
AREA_Y_1E300 = (
    "N10 #CONTROL AREA BEGIN [ID3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]\n"
    "N20 G01 F1000 G90 X-150 Y75\n"
    "N30 X-50 Y150\n"
    "N40 X50 Y1" + "0" * 300 + "\n"
    "N50 X150 Y75\n"
    "N60 X-150 Y75\n"
    "N70 #CONTROL AREA END\n"
    "N80 #CONTROL AREA ON [ID3]\n"
    "N90 G01 X0 Y100\n"
    "N100 M30\n"
)
ISSUE_PROGRAMS = {
    "x_1e305": (X_1E305, 1, "N10", "X1e305"),
    "arc_1e154": (ARC_1E154, 1, "line 1", "I1e154"),
    "helix_1e155": (HELIX_1E155, 1, "line 1", "Z1e155"),
    "area_y_1e300": (AREA_Y_1E300, 4, "N40", "Y1e300"),
}


def error(text: str) -> NcError:
    with pytest.raises(NcError) as info:
        parse_line(text, 1, AXES)
    return info.value


def test_the_range_alarm_is_in_the_table() -> None:
    assert ALARMS[OUT_OF_RANGE].text == "Number out of range in NC block"


@pytest.mark.req("E-04")
def test_the_issues_program_is_refused_with_line_block_and_range() -> None:
    err = error(X_1E305.splitlines()[0])
    assert (err.alarm, err.line, err.block) == (OUT_OF_RANGE, 1, "N10")
    assert str(err) == (
        "line 1, N10: X1e305 is out of range: positions must lie within +/-214748.3647 mm "
        "(a DINT in 0.1 µm; rotary axes in 0.0001°) [910111]"
    )


# (word, in range, just beyond): the limits follow from the interface (schemas/units.py)
LIMITS = [
    ("X", "214748.3647", "214748.3648"),
    ("X", "-214748.3647", "-214748.3648"),
    ("X2=", "214748.3647", "214748.3648"),
    ("F", "6000000", "6000000.1"),
    ("I", "429496.7294", "429496.7295"),
    ("K", "-429496.7294", "-429496.7295"),
    ("S", "2147483647", "2147483648"),
]


@pytest.mark.req("E-04")
@pytest.mark.parametrize(("prefix", "inside", "beyond"), LIMITS)
def test_each_word_is_accepted_up_to_its_limit_and_refused_beyond(
    prefix: str, inside: str, beyond: str
) -> None:
    block = parse_line(f"N10 {prefix}{inside}", 1, AXES)
    assert block is not None
    values = dict(block.axes) | dict(block.centre) | block.extra | {"F": block.feed}
    assert values[prefix.rstrip("=")] == float(inside)
    err = error(f"N10 {prefix}{beyond}")
    assert (err.alarm, err.block) == (OUT_OF_RANGE, "N10")
    assert f"{prefix}{beyond} is out of range" in err.message


def test_the_limits_are_the_dint_of_the_interface() -> None:
    assert round(POSITION_LIMIT_MM * 10_000) == 2**31 - 1
    assert DISTANCE_LIMIT_MM == 2 * POSITION_LIMIT_MM


AREA = "N10 #CONTROL AREA BEGIN [ID={id} WORK POLY MIN_EXCUR={lo} MAX_EXCUR=50{more}]"


@pytest.mark.req("E-04", "C14-02")
@pytest.mark.parametrize(
    ("fields", "shown"),
    [
        ({"lo": "-214748.3648"}, "MIN_EXCUR=-214748.3648 is out of range"),
        ({"lo": "-1" + "0" * 400}, "MIN_EXCUR=-10000000000... (401 digits) is out of range"),
        ({"id": "-1"}, "ID=-1 is out of range: an area ID is a whole number 0..999999999"),
        ({"more": " EXCUR_AXNR=0"}, "EXCUR_AXNR=0 is out of range: a logical axis number"),
    ],
)
def test_area_options_are_range_checked(fields: dict[str, str], shown: str) -> None:
    text = AREA.format(**({"id": "3", "lo": "-50", "more": ""} | fields))
    err = error(text)
    assert (err.alarm, err.block) == (OUT_OF_RANGE, "N10")
    assert shown in err.message
    assert parse_line(AREA.format(id="0", lo="-214748.3647", more=" EXCUR_AXNR=3"), 1, AXES) is not None


@pytest.mark.req("E-04")
@pytest.mark.parametrize(
    ("text", "alarm"),
    [
        ("G1 XINF", 910101),
        ("G1 X=NAN", 910101),
        ("G1 X2=-INFINITY", 910101),
        ("G1 Xnan", 910101),
        ("G1 X1e5", 910100),  # exponents are no DIN 66025 number: E is an unknown word
        ("#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=INF MAX_EXCUR=2]", 910105),
        ("#CONTROL AREA BEGIN [ID=1 WORK POLY MIN_EXCUR=-1 MAX_EXCUR=NAN]", 910105),
    ],
)
def test_nan_and_inf_literals_are_refused(text: str, alarm: int) -> None:
    err = error(f"N10 {text}")
    assert (err.alarm, err.block) == (alarm, "N10")


# --- the issue's programs through the real door: `hli-server check` ---------------------------------


@pytest.mark.req("E-04")
@pytest.mark.parametrize("mode", [[], ["--geometry-only"]], ids=["full", "geometry"])
@pytest.mark.parametrize("name", list(ISSUE_PROGRAMS))
def test_check_refuses_the_issues_programs_with_a_numbered_error(
    tmp_path, name: str, mode: list[str]
) -> None:
    program, line, block, word = ISSUE_PROGRAMS[name]
    path = tmp_path / "prog.nc"
    path.write_text(program)
    result = CliRunner().invoke(main, ["check", str(path), "--format", "json", *mode])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    assert result.exit_code == 1, result.output
    (alarm,) = json.loads(result.output)["alarms"]
    assert (alarm["id"], alarm["line"], alarm["block"]) == (OUT_OF_RANGE, line, block)
    assert alarm["message"].startswith(f"{word} is out of range")


@pytest.mark.req("E-04")
def test_a_running_machine_takes_the_error_and_runs_the_next_program() -> None:
    """Finding 1 on the engine a server steps: the program stops with 910111, cycles go on."""
    machine = mill()
    ch = machine.channel(1)
    ch.load_program(X_1E305, "issue12")
    ch.request_start()
    machine.step(1)
    assert ch.state == ProgramState.ABORTED
    (alarm,) = machine.active_alarms
    assert (alarm.number, alarm.line, alarm.block) == (OUT_OF_RANGE, 1, "N10")
    machine.step(100)
    assert [a.setpoint for a in ch.axes] == [0.0, 0.0, 0.0]
    assert all(math.isfinite(a.measured) for a in ch.axes)
    assert [a.number for a in machine.active_alarms] == [OUT_OF_RANGE]
    ch.request_reset()
    machine.step(2)
    run(machine, "N10 G01 X5 F6000\nN20 M30\n")
    assert ch.state == ProgramState.FINISHED
    assert ch.axes[0].setpoint == pytest.approx(5.0)


# --- what in-range words can still make: derived values stay finite -----------------------------------


@pytest.mark.req("E-04")
def test_the_largest_arc_in_range_has_a_finite_radius_and_length() -> None:
    """From one end of the range to the other with the centre as far as I/J allow: finite numbers."""
    p = POSITION_LIMIT_MM
    arc, _ = arc_from_centre((-p, -p, -p), (-p, -p, p), (0, 1), (-p + DISTANCE_LIMIT_MM, -p), True)
    assert arc.radius == pytest.approx(DISTANCE_LIMIT_MM)
    assert math.isfinite(arc.length)
    assert arc.length > arc.arc_length
    # hypot, not a sum of squares: finite wherever the result is (this overflowed before)
    huge, _ = arc_from_centre((0.0, 0.0, 0.0), (0.0, 0.0, 1e155), (0, 1), (1e154, 0.0), False)
    assert math.isfinite(huge.length)


@pytest.mark.req("E-04", "C14-02")
def test_an_area_pushed_beyond_the_range_by_offsets_is_refused() -> None:
    """In-range words plus a zero offset and a G92 shift: the corner is refused by name (912002)."""
    machine = mill(zero_offsets=[ZeroOffset(code="G54", offsets={"Y": 2_000_000_000})])
    channel_areas(machine)
    program = (
        "N5 G92 Y-200000\n"
        "N6 G54\n"
        "N10 #CONTROL AREA BEGIN [ID3 PROT POLY MIN_EXCUR=-50 MAX_EXCUR=50]\n"
        "N20 G01 F1000 X-150 Y0\n"
        "N30 X0 Y40000\n"
        "N40 X150 Y0\n"
        "N50 X-150 Y0\n"
        "N60 #CONTROL AREA END\n"
        "N70 M30\n"
    )
    ch = machine.channel(1)
    run(machine, program)
    assert ch.state == ProgramState.ABORTED
    (alarm,) = machine.active_alarms
    assert (alarm.number, alarm.block) == (912002, "N60")
    assert "corner (0, 440000) (N30) lies beyond +/-429496.7294 mm" in alarm.message
