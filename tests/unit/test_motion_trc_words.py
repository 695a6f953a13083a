"""The TRC words around G40/G41/G42 (M-16) and a value after '=' inside #CONTOUR MODE's brackets.

G139 (indirect selection, PM 207729163) and G140 (no contour masking, PM 206480651) are the kernel's
initial states, the ones simulated: programmed, they change nothing. The other selection methods and
contour masking run approximated by them, with warning 911041 once per program (issue 33). Inside the brackets
of ``#CONTOUR MODE [..]`` a value is a whole expression, blanks and all, as the manual writes it.
"""

from __future__ import annotations

import pytest

from tests.unit.test_motion_mchain import decode, machine

pytestmark = pytest.mark.req("M-16")

SQUARE = "N20 G41 G01 X10 Y0\nN30 X30\nN40 Y20\nN50 X10\nN60 G40 Y-10\nN70 M30\n"


def test_g139_and_g140_are_the_initial_states_and_change_nothing() -> None:
    plain, plain_errors, _ = decode("N10 D1 G17 G90 G01 F3000\n" + SQUARE)
    stated, stated_errors, _ = decode("N10 D1 G17 G90 G139 G140 G01 F3000\n" + SQUARE)
    assert plain_errors == []
    assert stated_errors == []
    assert stated == plain


@pytest.mark.req("LT-08")
@pytest.mark.parametrize("g", [5, 138, 141, 236, 237, 238, 239])
def test_the_other_trc_modes_run_as_g139_with_one_warning(g: int) -> None:
    """Issue 33: the selection methods only shape the approach and departure (within the tool radius) and
    contour masking only matters where a violation would stop the program: approximated, said once."""
    plain, plain_errors, _ = decode("N10 D1 G17 G90 G01 F3000\n" + SQUARE)
    m = machine()
    other, errs, _ = decode(f"N10 D1 G17 G90 G01 F3000\nN15 G{g:02d}\n" + SQUARE, m)
    assert errs == plain_errors == []
    assert other == plain
    warnings = [a for a in m.alarm_history if a.number == 911041]
    assert len(warnings) == 1
    assert warnings[0].message.startswith(f"G{g} ")


@pytest.mark.req("M-20")
def test_a_contour_mode_value_is_a_whole_expression_inside_the_brackets() -> None:
    m = machine()
    _, errs, _ = decode(
        "N05 D1 V.G.WZ_AKT.R = 5\nN10 #CONTOUR MODE [DEV, PATH_DEV = V.G.WZ_AKT.R / 100]\n"
        "N20 G261 G01 X10 Y0 F3000\nN30 Y10\nN40 M30\n",
        m,
    )
    assert errs == []
    assert m.channel(1).decoder.modal.contour.path_dev == pytest.approx(0.05)
