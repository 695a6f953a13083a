"""Build: the engine compiled with mypyc where it can be, plain Python everywhere else (issue 16).

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

import os
import platform
import shutil
import sys
import sysconfig
from pathlib import Path

from setuptools import setup

HERE = Path(__file__).parent
ENGINE = HERE / "hli_server" / "engine"


def _why_not_compiled() -> str | None:
    if os.environ.get("HLI_PURE_PYTHON", "") not in ("", "0"):
        return "HLI_PURE_PYTHON is set"
    if platform.python_implementation() != "CPython":
        return f"{platform.python_implementation()} is not CPython"
    compiler = (sysconfig.get_config_var("CC") or "cc").split()[0]
    if shutil.which(compiler) is None:
        return f"no C compiler ({compiler})"
    include = sysconfig.get_paths().get("include") or ""
    if not (Path(include) / "Python.h").exists():
        return f"no Python headers (Python.h in {include})"
    try:
        import mypyc.build  # noqa: F401
    except ImportError:
        return "mypyc is not installed"
    return None


def _not_compiled() -> tuple[str, ...]:
    """The engine files that stay Python, as ``hli_server/_compiled.py`` lists them (read from the
    file: the package is not importable while it is being built)."""
    import ast

    tree = ast.parse((HERE / "hli_server" / "_compiled.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "NOT_COMPILED" for t in node.targets
        ):
            value = ast.literal_eval(node.value)
            assert isinstance(value, tuple)
            return value
    raise RuntimeError("hli_server/_compiled.py: NOT_COMPILED not found")


def _ext_modules() -> list[object]:
    why = _why_not_compiled()
    if why is not None:
        print(f"hli-server: engine not compiled ({why}): pure Python", file=sys.stderr)
        return []
    from mypyc.build import mypycify

    sources = sorted(str(p.relative_to(HERE)) for p in ENGINE.rglob("*.py") if p.name not in _not_compiled())
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
