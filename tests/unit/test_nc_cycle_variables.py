"""V.CYC. variables outside cycles and string cycle parameters (issue 33 item 2; PM 486123531 "Cycle
variables (V.CYC.)", 486171019 "Validity and visibility"): a V.CYC. variable is declared in any program level,
is seen there and in every level it calls, the most local declaration wins, and it is deleted when its
level returns. Beckhoff's measuring examples declare the cycles' outputs so in the main program."""

from __future__ import annotations

import pytest

from tests.unit.nc_helpers import interpret


def xs(text: str, files: dict[str, str] | None = None) -> list[float]:
    run = interpret(text, files)
    assert run.error is None, run.error
    return run.values("X")


@pytest.mark.req("N-04", "CY-05")
def test_the_main_program_declares_what_a_cycle_writes() -> None:
    cycle = "V.CYC.SysRetX = @P2 * 2\nM17\n"
    assert xs(
        "#VAR\n  V.CYC.SysRetX\n#ENDVAR\nL CYCLE [NAME=c.ecy @P2=21]\nX[V.CYC.SysRetX]\nM30\n",
        {"c.ecy": cycle},
    ) == [42.0]


@pytest.mark.req("N-04")
def test_a_subroutine_sees_the_callers_and_its_own_goes_with_it() -> None:
    sub = "X[V.CYC.A]\nV.CYC.A = V.CYC.A + 1\n#VAR\n  V.CYC.Own = 7\n#ENDVAR\nX[V.CYC.Own]\nM17\n"
    assert xs("#VAR\n  V.CYC.A = 1\n#ENDVAR\nL sub.nc\nX[V.CYC.A]\nM30\n", {"sub.nc": sub}) == [1.0, 7.0, 2.0]
    run = interpret("L sub.nc\nX[V.CYC.Own]\nM30\n", {"sub.nc": "#VAR\n  V.CYC.Own = 7\n#ENDVAR\nM17\n"})
    assert run.error is not None
    assert run.error.alarm == 914003  # deleted when its level returned


@pytest.mark.req("N-04")
def test_the_most_local_declaration_wins() -> None:
    cycle = "#VAR\n  V.CYC.A = 5\n#ENDVAR\nV.CYC.A = V.CYC.A + 1\nX[V.CYC.A]\nM17\n"
    assert xs("#VAR\n  V.CYC.A = 1\n#ENDVAR\nL CYCLE [NAME=c.ecy]\nX[V.CYC.A]\nM30\n", {"c.ecy": cycle}) == [
        6.0,
        1.0,
    ]


@pytest.mark.req("N-02", "CY-02")
def test_a_cycle_parameter_may_be_a_string() -> None:
    cycle = '$IF @P31 == "Roughing"\n  X1\n$ELSE\n  X2\n$ENDIF\n@P31 = "Finishing"\nM17\n'
    assert xs(
        'L CYCLE [NAME=c.ecy @P31="Roughing"]\nL CYCLE [NAME=c.ecy @P31="Other"]\nM30\n', {"c.ecy": cycle}
    ) == [
        1.0,
        2.0,
    ]
