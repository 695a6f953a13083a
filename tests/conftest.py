"""Shared test configuration.

Every test that proves a requirement carries its IDs: ``@pytest.mark.req("C14-11")`` (the list:
docs/requirements.md).
"""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

# Property tests draw the same examples on every run of the suite (a failure in CI is a change, not a new
# draw); HLI_HYPOTHESIS_PROFILE=explore draws new ones each run (docs/reliability.md, `make soak`).
settings.register_profile("suite", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HLI_HYPOTHESIS_PROFILE", "suite"))

pytest_plugins = ["pytester"]  # the plugin's own tests run a user's suite (tests/integration/test_plugin.py)

_DEV_SHM = Path("/dev/shm")


def _our_segments() -> set[str]:
    """Shared-memory segments named after this process (the default image names, ``hli_<pid>_...``)."""
    if not _DEV_SHM.is_dir():  # pragma: no cover - not Linux
        return set()
    marker = f"hli_{os.getpid()}_"
    return {p.name for p in _DEV_SHM.iterdir() if p.name.startswith(marker)}


@pytest.fixture(autouse=True)
def _no_leaked_shared_memory():
    """No process image created by a test outlives it (H-01): every one is closed and unlinked; no
    harness' server thread outlives it either (H-07).

    Images belong to function-scoped fixtures; one kept by a module-scoped fixture is reported here.
    """
    before = _our_segments()
    yield
    shm_module = sys.modules.get("hli_server.image.shm")
    still_open = sorted(shm_module.open_image_names()) if shm_module is not None else []
    for name in still_open:  # close them, so that one leak does not fail every later test
        shm_module._open_images[name].close()
    left = sorted(_our_segments() - before)
    servers = [t.name for t in threading.enumerate() if t.name == "hli-harness-server"]
    assert not still_open, f"process images not closed by the test: {still_open}"
    assert not left, f"shared memory left in /dev/shm by the test: {left}"
    assert not servers, "a test harness (hli_server.testing.Harness) was not stopped: use it with `with`"


# --------------------------------------------------------------------------------------------
# The order: modules with slow tests first, so that pytest-xdist starts the long ones early and the
# many short unit tests fill both workers to the end (no worker idles while the other ends a 20 s test)
# --------------------------------------------------------------------------------------------


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A stable sort: each module stays in one piece and in its order (module fixtures are set up once),
    the modules that hold a test marked ``slow`` before the others: under ``make test`` xdist hands out
    two tests at a time in this order (``--maxschedchunk 2``), so every worker starts on the long ones
    and the short unit tests fill the end."""
    slow_modules = {item.module.__name__ for item in items if item.module and item.get_closest_marker("slow")}
    items.sort(key=lambda item: 0 if item.module and item.module.__name__ in slow_modules else 1)


# --------------------------------------------------------------------------------------------
# Requirement coverage: which IDs of docs/requirements.md the collected tests prove
# --------------------------------------------------------------------------------------------

_REQ_IDS: dict[str, int] = {}
_REQ_PATTERN = r"^- ((?:E|C14|C43|C3|A3|H|N|B|M|K|CY|LT)-\d+) "


def pytest_collection_finish(session: pytest.Session) -> None:
    for item in session.items:  # after -k / -m deselection
        for mark in item.iter_markers("req"):
            for req_id in mark.args:
                _REQ_IDS[req_id] = _REQ_IDS.get(req_id, 0) + 1


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Under pytest-xdist (``make test``) each worker collects the whole suite: it hands its counts to
    the controller, which prints the summary."""
    workeroutput = getattr(session.config, "workeroutput", None)
    if workeroutput is not None:
        workeroutput["req_ids"] = dict(_REQ_IDS)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node: Any, error: object) -> None:
    ids = getattr(node, "workeroutput", {}).get("req_ids")
    if ids and not _REQ_IDS:  # every worker collected the same items: one worker's counts
        _REQ_IDS.update(ids)


def _known_requirements() -> list[str]:
    """The IDs of the project's own requirement list, docs/requirements.md (in every clone)."""
    import re

    spec = Path(__file__).resolve().parents[1] / "docs" / "requirements.md"
    if not spec.is_file():
        return []
    return re.findall(_REQ_PATTERN, spec.read_text(encoding="utf-8"), flags=re.MULTILINE)


def _whole_suite(config: pytest.Config, deselected: int) -> bool:
    """Whether this run collected the whole suite: no paths but the configured ``testpaths`` (or the
    root), nothing deselected (``-k``, ``-m``, ``--lf``, ``--deselect``). Only then does a requirement
    that no collected test carries lack a test."""
    if deselected or config.option.keyword or config.option.markexpr or config.getoption("lf", False):
        return False
    root = config.rootpath
    chosen = {(root / arg.split("::", 1)[0]).resolve() for arg in config.args}
    configured = {(root / path).resolve() for path in config.getini("testpaths")}
    return chosen in (configured, {root.resolve()})


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    if not _REQ_IDS:
        return
    known = _known_requirements()
    unknown = sorted(set(_REQ_IDS) - set(known)) if known else []
    missing = [r for r in known if r not in _REQ_IDS]
    tr = terminalreporter
    tr.section("requirements")
    tr.write_line(f"{len(_REQ_IDS)} requirement IDs carried by {sum(_REQ_IDS.values())} test marks")
    if known and _whole_suite(tr.config, len(tr.stats.get("deselected", []))):
        tr.write_line(f"not yet proven by a test: {', '.join(missing) if missing else 'none'}")
    elif known:
        tr.write_line(
            f"a part of the suite: {len(known) - len(missing)} of {len(known)} requirement IDs carried here "
            "(a run of the whole suite lists those no test proves)"
        )
    if unknown:
        tr.write_line(f"marks with IDs not in docs/requirements.md: {', '.join(unknown)}")
