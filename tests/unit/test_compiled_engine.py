"""The compiled and the pure engine give the same outputs, cycle for cycle (issue 16).

``pip install`` compiles the engine with mypyc where it can (``setup.py``); ``HLI_PURE_PYTHON=1`` runs the
same source as plain Python (``hli_server/_compiled.py``). The suite itself runs with whichever engine
the installation has; this test runs the recorded scenarios (``test_recorded_scenarios.py``) in a second
process with the *other* engine, so that both are held to the same recording: every published field,
every event, every cycle. Where the engine is not compiled (no C compiler) it says so and runs the
pure one only, which the suite does anyway.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import hli_server._compiled as compiled

ROOT = Path(__file__).parents[2]


def _run_scenarios(pure: bool) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env.pop(compiled.PURE_ENV, None)
    if pure:
        env[compiled.PURE_ENV] = "1"
    code = (
        "import json, sys\n"
        "import hli_server._compiled as c\n"
        "import tests.unit.test_recorded_scenarios as t\n"
        "rec = t._recorded()\n"
        "bad = [n for n, (run, size) in t.SCENARIOS.items() if run(size)[0] != rec[n]['digest']]\n"
        "print(json.dumps({'compiled': c.ENGINE_COMPILED, 'differ': bad}))\n"
    )
    return _python(code, env, timeout=600)


def _python(code: str, env: dict[str, str], timeout: float) -> subprocess.CompletedProcess[str]:
    """``code`` run by this interpreter in a second process, from the checkout, with ``env``."""
    return subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


@pytest.mark.slow
@pytest.mark.req("E-01")
def test_the_other_engine_gives_the_recorded_outputs_cycle_for_cycle() -> None:
    import json

    other_is_pure = compiled.ENGINE_COMPILED
    done = _run_scenarios(pure=other_is_pure)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    if not other_is_pure and not result["compiled"]:
        pytest.skip("the engine is not compiled here (no C compiler or mypyc at install): pure Python only")
    assert result["compiled"] is (not other_is_pure)
    assert result["differ"] == [], (
        f"{'pure' if other_is_pure else 'compiled'} engine differs in {result['differ']}"
    )


def test_pure_python_can_be_forced_for_debugging() -> None:
    """HLI_PURE_PYTHON=1 loads every engine module from its .py file (breakpoints, profilers)."""
    env = dict(os.environ, **{compiled.PURE_ENV: "1"})
    code = (
        "import hli_server._compiled as c, hli_server.engine.machine as m, hli_server.engine.nc.parser as p\n"
        "print(c.ENGINE_COMPILED, m.__file__.endswith('.py'), p.__file__.endswith('.py'))\n"
    )
    done = _python(code, env, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "True", "True"]


def test_an_install_with_a_c_compiler_compiled_the_engine() -> None:
    """A build that falls back to pure Python says so only in pip's verbose output; the suite says it
    loudly where the machine could have compiled (``why_not_compilable``, which setup.py asks too). It
    once fell back on a fresh machine because numpy, new in the engine, was missing from the build
    requirements (pyproject.toml [build-system]): mypyc type-checks what the engine imports."""
    why = compiled.why_not_compilable()  # what setup.py asks
    if why is not None:
        pytest.skip(f"the engine is pure Python here: {why}")
    built, missing = compiled.stale_modules()
    assert built, (
        "the engine was installed as pure Python although this machine can compile it: run "
        "`.venv/bin/python -m pip install -v --no-deps -e .` and read the lines that start 'hli-server:'"
    )
    assert not [p for p in missing if compiled._compiled_file(p) is None], missing


def test_an_edited_engine_source_is_said_where_the_server_starts(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A compiled module older than its source switches the whole engine to pure Python: besides the
    import-time warning, the runtime says so in its log at start and ``run`` in its banner (issue 28)."""
    import asyncio
    import logging

    from hli_server.configuration import load_machine
    from hli_server.runtime import Runtime, memory_image

    monkeypatch.setattr(compiled, "ENGINE_COMPILED", compiled.ENGINE_COMPILED)
    monkeypatch.setattr(compiled, "_STALE_NOTICE", None)
    finders = [f for f in sys.meta_path if not isinstance(f, compiled._PureEngineFinder)]
    monkeypatch.setattr(sys, "meta_path", finders)
    monkeypatch.delenv(compiled.PURE_ENV, raising=False)
    source = compiled._ENGINE_DIR / "axis.py"
    monkeypatch.setattr(compiled, "stale_modules", lambda: ([source.with_suffix(".so")], [source]))
    with pytest.warns(RuntimeWarning, match="older than its source"):
        assert compiled.select() is False
    notice = compiled.stale_notice()
    assert notice is not None
    assert "hli_server/engine/axis.py" in notice
    assert "make compile" in notice

    async def start_and_stop() -> None:
        async with Runtime(
            load_machine(None), clock="stepped", http_port=None, adapters=[], image_factory=memory_image
        ):
            pass

    with caplog.at_level(logging.WARNING, logger="hli_server.runtime.core"):
        asyncio.run(start_and_stop())
    assert "the whole engine runs as pure Python" in caplog.text
