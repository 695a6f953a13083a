"""The requirement summary at the end of a pytest run (tests/conftest.py, issue 23): "not yet proven"
is said only of a run of the whole suite; a part of it (a file, ``-k``, ``-m``) only counts."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from tests.conftest import _whole_suite

ROOT = Path(__file__).resolve().parents[2]


def config(*args: str, keyword: str = "", markexpr: str = "", lf: bool = False) -> pytest.Config:
    fake: pytest.Config = SimpleNamespace(  # type: ignore[assignment]
        rootpath=ROOT,
        args=list(args),
        option=SimpleNamespace(keyword=keyword, markexpr=markexpr),
        getoption=lambda name, default=None: lf if name == "lf" else default,
        getini=lambda name: ["tests", "examples"] if name == "testpaths" else [],
    )
    return fake


def test_a_run_of_the_configured_testpaths_is_the_whole_suite() -> None:
    assert _whole_suite(config("tests", "examples"), deselected=0)
    assert _whole_suite(config(str(ROOT)), deselected=0)


@pytest.mark.parametrize(
    "part",
    [
        config("tests/unit/test_units.py"),
        config("tests"),
        config("tests", "examples", keyword="modbus"),
        config("tests", "examples", markexpr="not slow"),
        config("tests", "examples", lf=True),
    ],
    ids=["a file", "one directory", "-k", "-m", "--lf"],
)
def test_a_part_of_the_suite_is_not(part: pytest.Config) -> None:
    assert not _whole_suite(part, deselected=0)


def test_deselected_tests_make_a_part() -> None:
    assert not _whole_suite(config("tests", "examples"), deselected=3)
