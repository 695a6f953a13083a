"""The pytest plugin as a user meets it (H-07): a test file and nothing else, in a pytest of its own.

Each test writes a user's suite into a fresh directory (pytester) and runs it in a new pytest
process: no conftest.py, no pyproject.toml of ours, only the installed package with its ``pytest11``
entry point. The docs' complete test runs as written; a small suite runs under pytest-xdist with
two workers, and no server of one test shares a port or an image with one running at the same time.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hli_server.testing import unavailable
from tests.doc_blocks import DOCS, marked_block

pytestmark = pytest.mark.req("H-07")

ROOT = Path(__file__).resolve().parents[2]


def doc_test_source() -> str:
    return marked_block(DOCS / "testing.md", "doc-run: session=plugin file=test_my_plc.py")


def doors() -> tuple[int, int]:
    """(doors that run, doors skipped) of the plc_transport fixture in this installation."""
    names = ["shm", "modbus", "ads"]
    missing = sum(1 for name in names if unavailable(name) is not None)
    return len(names) - missing, missing


@pytest.mark.slow
def test_the_complete_test_of_the_docs_passes_as_written(pytester: pytest.Pytester) -> None:
    source = doc_test_source()
    assert len([line for line in source.splitlines() if line.strip()]) <= 14  # "about ten lines"
    pytester.makepyfile(test_my_plc=source)
    result = pytester.runpytest_subprocess("-v", "-p", "no:cacheprovider")
    run, skipped = doors()
    result.assert_outcomes(passed=run, skipped=skipped)
    result.stdout.fnmatch_lines(["*test_the_limit_holds_x_at_50_mm?shm? PASSED*"])


@pytest.mark.slow
def test_a_failing_user_test_shows_the_report_of_the_last_cycles(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(
        test_stuck="""
        def test_x_never_gets_there(hli):
            hli.operator.load_program(1, "N10 G01 X5 F6000\\nN20 M30\\n")
            hli.operator.start(1)
            hli.run_until(lambda: hli.image["gpAx[0]^ipo_state.cmd_pos_r"] > 100_000, max_cycles=500)
        """
    )
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider")
    result.assert_outcomes(failed=1)
    out = result.stdout.str()
    for line in (
        "ConditionNotMetError: condition not met within 500 cycles (cycles 1..500):",
        'hli.run_until(lambda: hli.image["gpAx[0]^ipo_state.cmd_pos_r"] > 100_000, max_cycles=500)',
        "(no other signal changed in these cycles: the machine stands still)",
        "active alarms: none",
    ):
        assert line in out
    assert "harness.py" not in out  # the report, not the harness' own frames


@pytest.mark.slow
def test_the_machine_comes_from_the_ini_option_and_a_bad_marker_is_a_usage_error(
    pytester: pytest.Pytester,
) -> None:
    (pytester.path / "machines").mkdir()
    (pytester.path / "machines" / "mill3.toml").write_text(
        (ROOT / "tests" / "data" / "mill3.toml").read_text(encoding="utf-8"), encoding="utf-8"
    )
    pytester.makeini("[pytest]\nhli_machine = machines/mill3.toml\n")
    pytester.makepyfile(
        test_machine="""
        import pytest

        def test_ini_machine(hli):
            assert hli.layout.machine == "mill3"

        @pytest.mark.hli(machine=None)
        def test_marker_without_machine_keeps_the_ini_one(hli):
            assert hli.layout.machine == "mill3"

        @pytest.mark.hli("mill3.toml")
        def test_positional_marker(hli):
            pass
        """
    )
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider")
    result.assert_outcomes(passed=2, errors=1)
    result.stdout.fnmatch_lines(["*write @pytest.mark.hli(machine=..., image=..., adapters=...) with names*"])


USER_SUITE = """
import glob, json, os, time

import pytest

OUT = os.environ["HLI_XDIST_OUT"]
WORKER = os.environ.get("PYTEST_XDIST_WORKER", "main")
first_test = [True]


def other_worker_running():
    for path in glob.glob(os.path.join(OUT, "*.json")):
        with open(path) as f:
            record = json.load(f)
        if record["worker"] != WORKER and not os.path.exists(path[: -len(".json")] + ".end"):
            return True
    return False


def record(hli, name):
    path = os.path.join(OUT, f"{name}-{os.getpid()}.json")
    with open(path + ".tmp", "w") as out:  # then renamed: the other worker never reads half a file
        json.dump(
            {
                "test": name,
                "worker": WORKER,
                "pid": os.getpid(),
                "image": hli.image.name,
                "modbus": hli.port("modbus"),
                "http": hli.http_url,
                "start": time.monotonic(),
            },
            out,
        )
    os.replace(path + ".tmp", path)
    if first_test[0]:  # each worker's first server waits for one of the other's: both alive at once
        first_test[0] = False
        deadline = time.monotonic() + 60
        while not other_worker_running():
            assert time.monotonic() < deadline, "the other worker never started a test"
            time.sleep(0.01)


@pytest.mark.parametrize("k", range(4))
def test_scenario(hli, plc_transport, k):
    name = f"scenario{k}-{plc_transport.__class__.__name__}"
    record(hli, name)
    hli.operator.load_program(1, "N10 G01 X%d F6000\\nN20 M30\\n" % (k + 1))
    hli.operator.start(1)
    hli.run_until(lambda: hli.image["gpCh[0]^bahn_state.program_state_r"] == 4, max_cycles=2000)
    assert plc_transport.snapshot().values["gpAx[0]^ipo_state.cmd_pos_r"] == (k + 1) * 10_000
    with open(os.path.join(OUT, f"{name}-{os.getpid()}.end"), "w") as f:
        f.write(str(time.monotonic()))
"""


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_a_users_suite_runs_under_xdist_with_its_own_ports_and_images(
    pytester: pytest.Pytester, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "records"
    out.mkdir()
    monkeypatch.setenv("HLI_XDIST_OUT", str(out))
    pytester.makepyfile(test_suite=USER_SUITE)
    result = pytester.runpytest_subprocess("-n", "2", "-p", "no:cacheprovider")
    run, skipped = doors()
    result.assert_outcomes(passed=4 * run, skipped=4 * skipped)
    records = []
    for path in out.glob("*.json"):
        record = json.loads(path.read_text(encoding="utf-8"))
        record["end"] = float(path.with_suffix(".end").read_text(encoding="utf-8"))
        records.append(record)
    assert len(records) == 4 * run
    assert {r["worker"] for r in records} == {"gw0", "gw1"}  # two workers really ran
    assert len({r["image"] for r in records}) == len(records)  # an image of its own, always
    at_once = [
        (a, b)
        for a in records
        for b in records
        if a["worker"] < b["worker"] and a["start"] < b["end"] and b["start"] < a["end"]
    ]
    assert at_once, "the two workers never ran a test at the same time"
    for a, b in at_once:  # servers alive at the same time never share a port
        assert a["modbus"] != b["modbus"]
        assert a["http"] != b["http"]
