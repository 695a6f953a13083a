"""The engine is compiled once per engine source (issue 37, item 1).

``make run`` installs the package (compiling the engine, minutes); ``make test`` then adds the test extras
without building the package again; an install of the same sources anywhere else on the machine (a user's
``pip install path/to/clone``, ``make compile`` after a change elsewhere) takes the compiled modules from
the build cache (``setup.py``: ``HLI_BUILD_CACHE``, ``~/.cache/hli-server/engine``), under a key that any
change of what the compiled code depends on changes.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

from hli_server import _compiled

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ("setup.py", "pyproject.toml", "README.md", "schemas", "hli_server", "plc_clients")


def make_dry_run(venv: Path, target: str) -> list[str]:
    """The commands ``make`` would run for ``target`` of the venv ``venv`` (``make -n``)."""
    done = subprocess.run(
        ["make", "-n", "-C", str(ROOT), f"VENV={venv}", str(venv / target)],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    return [line for line in done.stdout.splitlines() if "pip install" in line]


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_the_test_set_up_after_make_run_does_not_build_the_package_again(tmp_path: Path) -> None:
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").touch()
    # a fresh clone: the package is built once (the runtime's install), the test extras come on top
    fresh = make_dry_run(venv, ".installed-test")
    assert [line for line in fresh if " -e " in line] == [f"{venv}/bin/python -m pip install --quiet -e ."]
    # after `make run`: the test set-up installs the extras alone
    (venv / ".installed-runtime").touch()
    after_run = make_dry_run(venv, ".installed-test")
    assert after_run == [f"{venv}/bin/python -m pip install --quiet -r {venv}/test-requirements.txt"]


def load_setup(tree: Path) -> ModuleType:
    """``setup.py`` of ``tree`` as a module (its ``setup()`` runs only as the main module)."""
    spec = importlib.util.spec_from_file_location(f"hli_setup_{abs(hash(tree))}", tree / "setup.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def copy_sources(target: Path) -> Path:
    """The files a build reads, without compiled modules or caches."""
    target.mkdir(parents=True)
    ignore = shutil.ignore_patterns("*.so", "__pycache__", "*.egg-info")
    for name in SOURCES:
        source = ROOT / name
        if source.is_dir():
            shutil.copytree(source, target / name, ignore=ignore)
        else:
            shutil.copy2(source, target / name)
    return target


def test_the_key_changes_with_every_engine_source_and_nothing_else(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    tree = copy_sources(tmp_path / "src")
    setup = load_setup(tree)
    key = setup.build_key()
    assert load_setup(tree).build_key() == key  # stable
    (tree / "README.md").write_text("another README\n", encoding="utf-8")
    (tree / "plc_clients" / "cli.py").write_text("# not read by mypyc\n", encoding="utf-8")
    http = tree / "hli_server" / "adapters" / "http" / "server.py"  # another door: not read by mypyc
    http.write_text(http.read_text(encoding="utf-8") + "\n# an edit\n", encoding="utf-8")
    assert setup.build_key() == key
    engine = tree / "hli_server" / "engine" / "machine.py"
    engine.write_text(engine.read_text(encoding="utf-8") + "\n# an edit\n", encoding="utf-8")
    assert setup.build_key() != key
    edited = setup.build_key()
    schema = tree / "schemas" / "config.py"
    schema.write_text(schema.read_text(encoding="utf-8") + "\n# an edit\n", encoding="utf-8")
    assert setup.build_key() != edited
    edited = setup.build_key()
    codec = tree / "hli_server" / "codecs" / "ads" / "frames.py"  # read by mypyc for the ADS request path
    codec.write_text(codec.read_text(encoding="utf-8") + "\n# an edit\n", encoding="utf-8")
    assert setup.build_key() != edited
    edited = setup.build_key()
    monkeypatch.setenv("CFLAGS", "-O0")
    assert setup.build_key() not in (key, edited)
    monkeypatch.setenv("HLI_BUILD_CACHE", "off")
    assert setup.cache_root() is None
    monkeypatch.setenv("HLI_BUILD_CACHE", str(tmp_path / "cache"))
    assert setup.cache_root() == tmp_path / "cache"


@pytest.mark.slow
def test_a_build_of_the_same_sources_takes_the_compiled_engine_from_the_cache(tmp_path: Path) -> None:
    """The build of ``setup.py`` (``build_ext``, what pip's build runs) of a copy of these sources finds
    their compiled modules in the cache and copies them instead of compiling (no mypyc, no C compiler)."""
    why = _compiled.why_not_compilable()
    compiled, stale = _compiled.stale_modules()
    if why is not None or not compiled or stale:
        pytest.skip(f"the engine is not compiled here ({why or 'an edited or missing module'})")
    tree = copy_sources(tmp_path / "src")
    setup = load_setup(tree)
    entry = tmp_path / "cache" / setup.build_key()
    entry.mkdir(parents=True)
    root = _compiled._ENGINE_DIR.parent.parent
    groups = [*_compiled._ENGINE_DIR.glob("native__mypyc*.so"), *_compiled._ADS_DIR.glob("native__mypyc*.so")]
    assert len(groups) == 2, groups  # the engine's shared library and the ADS request path's
    modules = {}
    for built in compiled + sorted(groups):
        name = ".".join(built.relative_to(root).with_suffix("").with_suffix("").parts)
        shutil.copyfile(built, entry / f"{name}.so")
        modules[name] = f"{name}.so"
    (entry / "modules.json").write_text(json.dumps(modules), encoding="utf-8")
    env = {**os.environ, "HLI_BUILD_CACHE": str(tmp_path / "cache"), "CC": "false-compiler-not-used"}
    done = subprocess.run(
        [sys.executable, "setup.py", "build_ext", "--build-lib", str(tmp_path / "out")],
        cwd=tree,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "the compiled engine from the build cache" in done.stderr
    assert "compiling" not in done.stderr
    for name, file in modules.items():
        out = next((tmp_path / "out").glob(name.replace(".", "/") + ".*.so"))
        assert out.read_bytes() == (entry / file).read_bytes(), name
