"""Build: the engine compiled with mypyc where it can be, plain Python everywhere else.

Everything about the package is in ``pyproject.toml``; this file only adds the extension modules. The
modules of ``hli_server/engine`` (all but ``_compiled.NOT_COMPILED``) are compiled with mypyc, the way
black and mypy ship themselves, when

* the interpreter is CPython,
* mypyc can be imported (``pyproject.toml`` puts mypy in the build requirements for CPython),
* a C compiler and the Python headers are present (else pip would fail where the same source runs fine),
* and ``HLI_PURE_PYTHON`` is not set (``HLI_PURE_PYTHON=1 pip install -e .`` builds nothing).

Otherwise the package installs as pure Python: the same behaviour, cycle for cycle, only slower
(``tests/unit/test_compiled_engine.py`` runs the recorded scenarios with both). An editable install
(``pip install -e .``, what ``make`` does) builds the modules in place, beside their ``.py`` files; an
edited ``.py`` is then newer than its compiled module, and ``hli_server/_compiled.py`` runs the whole
engine as pure Python until the next ``pip install -e .`` (``make compile``), saying so once.
docs/performance.md, "Compiled engine", has the figures.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

from setuptools import setup

HERE = Path(__file__).parent
ENGINE = HERE / "hli_server" / "engine"


def _compiled_module() -> ModuleType:
    """``hli_server/_compiled.py``, loaded by its path (stdlib only; the package is not importable while
    it is being built): it says what stays Python (``NOT_COMPILED``) and whether this machine can
    compile the rest (``why_not_compilable``), for this build and for the test that checks the install."""
    spec = importlib.util.spec_from_file_location("_hli_compiled", HERE / "hli_server" / "_compiled.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _ext_modules() -> list[object]:
    compiled = _compiled_module()
    why = compiled.why_not_compilable()
    if why is not None:
        print(f"hli-server: engine not compiled ({why}): pure Python", file=sys.stderr)
        return []
    from mypyc.build import mypycify

    sources = sorted(
        str(p.relative_to(HERE)) for p in ENGINE.rglob("*.py") if p.name not in compiled.NOT_COMPILED
    )
    # IEEE results identical to the interpreter's: no fused multiply-add contracted by the compiler
    os.environ["CFLAGS"] = (os.environ.get("CFLAGS", "") + " -ffp-contract=off").strip()
    print(f"hli-server: compiling {len(sources)} engine modules with mypyc", file=sys.stderr)
    # mypy's options come from pyproject.toml; its override for construct is unused here
    # the group's shared library inside the package (hli_server/engine/native__mypyc...so), not at the
    # top level, where an editable install's finder would not see it from another directory
    try:
        return list(
            mypycify(
                ["--no-warn-unused-configs", *sources],
                opt_level="3",
                debug_level="1",
                group_name="hli_server.engine.native",
            )
        )
    except (SystemExit, Exception) as exc:  # mypyc exits on a type error: install pure, say so
        print(f"hli-server: engine not compiled (mypyc failed: {exc!r}): pure Python", file=sys.stderr)
        return []


setup(ext_modules=_ext_modules())
