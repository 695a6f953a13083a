"""Compiled or pure engine: which one this process runs (docs/performance.md "Compiled engine").

``pip install`` compiles the modules of ``hli_server/engine`` and the ADS door's request path
(:data:`ADS_COMPILED`) with mypyc where a C compiler and the Python headers are present (``setup.py``);
the same source runs as plain Python everywhere else. The compiled modules (``*.so`` beside the ``.py``
files) take precedence on import, so this module decides, once, before the first of them is imported
(``hli_server/__init__.py`` calls :func:`select`):

* ``HLI_PURE_PYTHON=1`` (any value but empty or ``0``): pure Python, for debugging (breakpoints,
  tracebacks with lines, profilers that see every function);
* a compiled module older than its source (an editable install whose ``.py`` was edited after the build:
  the ``.so`` would run the old code), or a source without its compiled module: pure Python for the
  whole engine and the ADS request path, with one warning that says which file and how to rebuild. All
  or nothing: a pure class cannot inherit from a compiled one, a compiled module calls the compiled
  classes of its group directly, and a half-compiled build would be neither tested nor measured.

Pure Python is chosen by a finder ahead of the standard ones that loads ``hli_server.engine.*`` and the
modules of :data:`ADS_COMPILED` from the ``.py`` files. :data:`ENGINE_COMPILED` tells which runs
(a recording's header, the benchmarks, the differential tests in ``tests/unit/test_compiled_engine.py``).
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import os
import platform
import shutil
import sys
import sysconfig
import warnings
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

__all__ = [
    "ADS_COMPILED",
    "ENGINE_COMPILED",
    "NOT_COMPILED",
    "PURE_ENV",
    "compiled_sources",
    "environment",
    "select",
    "stale_modules",
    "stale_notice",
    "why_not_compilable",
]

PURE_ENV = "HLI_PURE_PYTHON"
"""Set to 1 to run the engine as pure Python although it is compiled."""


def environment(pure: bool) -> dict[str, str]:
    """This process' environment for a child that runs the pure build (:data:`PURE_ENV` set) or the compiled
    one (unset): the tests and benchmarks that compare the two."""
    env = dict(os.environ)
    env.pop(PURE_ENV, None)
    if pure:
        env[PURE_ENV] = "1"
    return env


NOT_COMPILED = ("__init__.py", "blocks.py")
"""Engine files that stay Python where the engine is compiled (``setup.py`` reads this): the packages'
``__init__``, and ``nc/blocks.py``, whose frozen ``Block`` a compiled module builds through the
dataclass' interpreted ``__init__`` (15% of a geometry check); as a plain slots class the parser builds
it through its slot descriptors, twice as fast (``nc/parser.py``, ``_block_maker``)."""

ADS_COMPILED = ("data.py", "device.py", "session.py", "sums.py", "symbols.py")
"""The modules of ``hli_server/adapters/ads`` compiled with the engine: the ADS door's request path (the
device's dispatch, the port tables, the data, symbol and sum services), what every request of a PLC's
polling runs through. The transport (``server.py``, an ``asyncio.Protocol``), the notifications and the
rarely asked services stay Python (compiling the transport measured within the benchmark's noise). The
device answers a raw read 1.3x, a read_by_name 1.4-1.5x as fast compiled
(``benchmarks/bench_ads_device.py``; docs/performance.md, "Compiled engine")."""

_ENGINE = "hli_server.engine"
_ENGINE_DIR = Path(__file__).with_name("engine")
_ADS = "hli_server.adapters.ads"
_ADS_DIR = Path(__file__).parent / "adapters" / "ads"
_ADS_MODULES = frozenset(f"{_ADS}.{name.removesuffix('.py')}" for name in ADS_COMPILED)

ENGINE_COMPILED = False
"""True when this process runs the mypyc-compiled modules, the engine and the ADS request path (set by
:func:`select`)."""


def compiled_sources() -> list[Path]:
    """The sources mypyc compiles (``setup.py`` reads this): the engine's modules but
    :data:`NOT_COMPILED`, then those of :data:`ADS_COMPILED`."""
    engine = [p for p in sorted(_ENGINE_DIR.rglob("*.py")) if p.name not in NOT_COMPILED]
    return engine + [_ADS_DIR / name for name in ADS_COMPILED]


def why_not_compilable() -> str | None:
    """Why ``pip install`` here builds the engine as pure Python (``setup.py`` asks this, loading this
    file by its path: stdlib only), or None where it compiles it: CPython, a C compiler, the Python
    headers, ``HLI_PURE_PYTHON`` not set, and mypyc importable."""
    if os.environ.get(PURE_ENV, "") not in ("", "0"):
        return f"{PURE_ENV} is set"
    if platform.python_implementation() != "CPython":
        return f"{platform.python_implementation()} is not CPython"
    compiler = (sysconfig.get_config_var("CC") or "cc").split()[0]
    if shutil.which(compiler) is None:
        return f"no C compiler ({compiler})"
    include = sysconfig.get_paths().get("include") or ""
    if not (Path(include) / "Python.h").exists():
        return f"no Python headers (Python.h in {include})"
    try:
        import mypyc.build  # noqa: F401 - only where a build is asked about
    except ImportError:
        return "mypyc is not installed"
    return None


def _compiled_file(source: Path) -> Path | None:
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        candidate = source.with_name(source.stem + suffix)
        if candidate.exists():
            return candidate
    return None


def stale_modules() -> tuple[list[Path], list[Path]]:
    """(compiled modules, sources whose compiled module is missing or older than the source).

    The age is compared only in a source checkout (an editable install: ``.git`` beside the package),
    where sources are edited after the build; an installed wheel is left as installed (pip does not keep
    the build's file times, so a ``.py`` may be unpacked after its ``.so``)."""
    compiled: list[Path] = []
    checkout = (_ENGINE_DIR.parent.parent / ".git").exists()
    stale: list[Path] = []
    for source in compiled_sources():
        built = _compiled_file(source)
        if built is None:
            stale.append(source)
            continue
        compiled.append(built)
        if checkout and built.stat().st_mtime < source.stat().st_mtime:
            stale.append(source)
    return compiled, stale


class _PureEngineFinder(importlib.abc.MetaPathFinder):
    """Finds ``hli_server.engine``, its modules and those of :data:`ADS_COMPILED` as ``.py`` files (never
    the compiled ones)."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname != _ENGINE and not fullname.startswith(_ENGINE + ".") and fullname not in _ADS_MODULES:
            return None
        leaf = fullname.rpartition(".")[2]
        for entry in path or ():
            base = Path(entry) / leaf
            init = base / "__init__.py"
            if init.is_file():
                return importlib.util.spec_from_file_location(
                    fullname, init, submodule_search_locations=[str(base)]
                )
            module = base.with_suffix(".py")
            if module.is_file():
                return importlib.util.spec_from_file_location(fullname, module)
        return None


_STALE_NOTICE: str | None = None


def stale_notice() -> str | None:
    """Why this process runs the engine as pure Python although it is compiled (an edited source), or None.
    ``hli-server run`` prints it in its banner and a :class:`~hli_server.runtime.Runtime` logs it at start, so
    that the switch is said where the server starts, not only as an import-time warning."""
    return _STALE_NOTICE


def select() -> bool:
    """Decide compiled or pure for this process (before any compiled module is imported)."""
    global ENGINE_COMPILED  # noqa: PLW0603 - decided once per process, read by everyone after
    if any(isinstance(f, _PureEngineFinder) for f in sys.meta_path):
        return ENGINE_COMPILED
    compiled, stale = stale_modules()
    forced = os.environ.get(PURE_ENV, "") not in ("", "0")
    if compiled and stale and not forced:
        global _STALE_NOTICE  # noqa: PLW0603 - decided with ENGINE_COMPILED
        shown = ", ".join(str(p.relative_to(_ENGINE_DIR.parent.parent)) for p in stale[:3])
        more = f" and {len(stale) - 3} more" if len(stale) > 3 else ""
        _STALE_NOTICE = (
            f"the compiled engine is older than its source ({shown}{more}): the whole engine and the ADS "
            "request path run as pure Python (slower). Rebuild it with `make compile` (or "
            f"`pip install -e .`), or set {PURE_ENV}=1 to choose pure Python"
        )
        warnings.warn(f"hli_server: {_STALE_NOTICE}", RuntimeWarning, stacklevel=2)
    ENGINE_COMPILED = bool(compiled) and not stale and not forced
    if compiled and not ENGINE_COMPILED:
        sys.meta_path.insert(0, _PureEngineFinder())
    return ENGINE_COMPILED
