"""Build: the engine compiled with mypyc where it can be, plain Python everywhere else.

Everything about the package is in ``pyproject.toml``; this file only adds the extension modules. The
modules of ``hli_server/engine`` (all but ``_compiled.NOT_COMPILED``) and the ADS door's request path
(``_compiled.ADS_COMPILED``) are compiled with mypyc, the way black and mypy ship themselves, when

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

**Compiled once per engine source** (issue 37): a compile takes minutes, and the same sources were compiled
again by every install (``make run``'s, ``make test``'s, a user's ``pip install path/to/clone`` into their own
environment). The build keeps what it compiled in a cache directory (:func:`cache_root`: ``HLI_BUILD_CACHE``,
else ``$XDG_CACHE_HOME/hli-server/engine``, else ``~/.cache/hli-server/engine``; ``HLI_BUILD_CACHE=off``
turns it off), under a key (:func:`build_key`) made of everything the compiled code depends on: the sources
mypyc reads (the engine, the ADS adapter and codec, ``schemas``, ``hli_server/__init__.py`` and
``_compiled.py``, this file), the mypy options of ``pyproject.toml``, the versions of the interpreter, mypy,
its runtime library and the libraries whose types the engine uses, the compiler and ``CFLAGS``. An install
whose key is there copies the compiled modules instead of compiling (seconds); any change of the key
compiles anew. mypyc runs only when the extension modules are built (:class:`EngineBuildExt`), not each
time pip asks this file for metadata (three times per install).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import json
import os
import platform
import shutil
import sys
import sysconfig
import tomllib
from pathlib import Path
from types import ModuleType
from typing import Any

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

HERE = Path(__file__).parent
ENGINE = HERE / "hli_server" / "engine"
GROUP = "hli_server.engine.native"
"""The group of the engine's compiled modules (shared library ``hli_server/engine/native__mypyc...so``)."""
ADS_GROUP = "hli_server.adapters.ads.native"
"""The group of the ADS request path's (``hli_server/adapters/ads/native__mypyc...so``): a group of its own,
so that neither calls into the other's shared library."""
KEY_SOURCES = (
    ENGINE,
    HERE / "schemas",
    HERE / "hli_server" / "adapters" / "ads",
    HERE / "hli_server" / "codecs" / "ads",
)
"""The folders whose sources mypyc reads: what it compiles and what that imports with types it relies on."""
CACHE_ENV = "HLI_BUILD_CACHE"
KEEP_BUILDS = 4
"""Compiled builds kept in the cache (the newest; each is some tens of MB)."""
_KEY_DISTRIBUTIONS = ("mypy", "librt", "mypy_extensions", "numpy", "pydantic", "typing_extensions")
"""The build environment's packages whose version is part of the key: mypyc and its runtime library, and
the libraries whose types mypyc reads where the engine uses them."""


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


def cache_root() -> Path | None:
    """Where compiled builds are kept (module docstring), or None where ``HLI_BUILD_CACHE`` turns it off."""
    value = os.environ.get(CACHE_ENV, "").strip()
    if value.lower() in ("0", "off", "no", "false"):
        return None
    if value:
        return Path(value).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "hli-server" / "engine"


def build_key() -> str:
    """The key of this build in the cache: a hash of everything the compiled modules depend on."""
    digest = hashlib.sha256()
    files = {path for folder in KEY_SOURCES for path in folder.rglob("*.py")}
    files |= {HERE / "hli_server" / "__init__.py", HERE / "hli_server" / "_compiled.py", HERE / "setup.py"}
    for path in sorted(files):
        digest.update(path.relative_to(HERE).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    with (HERE / "pyproject.toml").open("rb") as f:
        mypy_options = tomllib.load(f).get("tool", {}).get("mypy", {})
    versions = {}
    for name in _KEY_DISTRIBUTIONS:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    build = {
        "mypy_options": mypy_options,
        "versions": versions,
        "python": sys.version,
        "ext_suffix": sysconfig.get_config_var("EXT_SUFFIX"),
        "machine": platform.machine(),
        "cc": sysconfig.get_config_var("CC"),
        "cflags": os.environ.get("CFLAGS", ""),
    }
    digest.update(json.dumps(build, sort_keys=True).encode())
    return digest.hexdigest()[:32]


def _cached(entry: Path) -> dict[str, str] | None:
    """The modules of a cached build (extension name -> file in ``entry``), None if it is not whole."""
    try:
        modules = json.loads((entry / "modules.json").read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(modules, dict) or not all((entry / str(f)).is_file() for f in modules.values()):
        return None
    return {str(k): str(v) for k, v in modules.items()}


def _mypyc_extensions() -> list[Any]:
    """The engine's modules and the ADS request path's, compiled by mypyc (its type check and C code now,
    the C compiler in ``build_ext``); [] where mypyc fails (a type error: the package installs as pure
    Python, saying so)."""
    compiled = _compiled_module()
    from mypyc.build import mypycify

    sources = [str(p.relative_to(HERE)) for p in compiled.compiled_sources()]
    engine = [s for s in sources if s.startswith("hli_server/engine/")]
    ads = [s for s in sources if s not in engine]
    # IEEE results identical to the interpreter's: no fused multiply-add contracted by the compiler
    os.environ["CFLAGS"] = (os.environ.get("CFLAGS", "") + " -ffp-contract=off").strip()
    print(
        f"hli-server: compiling {len(engine)} engine modules and {len(ads)} of the ADS door with mypyc",
        file=sys.stderr,
    )
    # mypy's options come from pyproject.toml; its override for construct is unused here
    # each group's shared library inside the package (hli_server/engine/native__mypyc...so), not at the
    # top level, where an editable install's finder would not see it from another directory
    try:
        return list(
            mypycify(
                ["--no-warn-unused-configs", *sources],
                opt_level="3",
                debug_level="1",
                separate=[(engine, GROUP), (ads, ADS_GROUP)],
            )
        )
    except (SystemExit, Exception) as exc:  # mypyc exits on a type error: install pure, say so
        print(f"hli-server: engine not compiled (mypyc failed: {exc!r}): pure Python", file=sys.stderr)
        return []


_BUILDS = frozenset(
    {"build", "build_ext", "bdist_wheel", "editable_wheel", "bdist", "bdist_egg", "install", "develop"}
)


def _building() -> bool:
    """Whether this run of setup.py builds (``bdist_wheel``, ``editable_wheel``, ``build_ext``, ...). pip
    first asks it for metadata in runs of their own (``egg_info``, ``dist_info``), where the file list of
    ``sdist`` finalizes ``build_ext`` too: there the engine is neither looked up nor compiled."""
    return any(arg in _BUILDS for arg in sys.argv[1:])


class EngineBuildExt(build_ext):
    """``build_ext`` for the engine: the compiled modules from the cache when their key is there, else
    compiled by mypyc and put into the cache. The extensions are decided here, when the command runs."""

    def finalize_options(self) -> None:
        # decided once per build, on the distribution (setuptools may make this command anew)
        dist: Any = self.distribution
        if not hasattr(dist, "hli_engine"):
            entry: Path | None = None
            hit: dict[str, str] | None = None
            root = cache_root()
            if dist.ext_modules and _building():
                if root is not None:
                    entry = root / build_key()
                    hit = _cached(entry)
                if hit is not None:
                    print(f"hli-server: the compiled engine from the build cache ({entry})", file=sys.stderr)
                    dist.ext_modules = [Extension(name, sources=[]) for name in sorted(hit)]
                else:
                    dist.ext_modules = _mypyc_extensions()
            dist.hli_engine = (entry, hit)
        self._entry, self._hit = dist.hli_engine
        self._built: dict[str, Path] = {}
        super().finalize_options()

    def build_extension(self, ext: Any) -> None:
        target = Path(self.get_ext_fullpath(ext.name))
        if self._hit is not None and self._entry is not None:
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(self._entry / self._hit[ext.name], target)
            return
        super().build_extension(ext)
        self._built[ext.name] = target

    def run(self) -> None:
        super().run()
        if self._hit is None and self._entry is not None and self._built:
            self._store(self._entry)

    def _store(self, entry: Path) -> None:
        """Put the modules just compiled into the cache (whole or not at all: written beside, then
        renamed), and keep only the newest :data:`KEEP_BUILDS` builds. A cache that cannot be written
        costs the next install a compile, nothing else."""
        part = entry.with_name(f"{entry.name}.part-{os.getpid()}")
        try:
            part.mkdir(parents=True, exist_ok=True)
            for (
                name,
                built,
            ) in self._built.items():  # by module name: two subpackages' modules may share a file name
                shutil.copyfile(built, part / f"{name}.so")
            (part / "modules.json").write_text(json.dumps({name: f"{name}.so" for name in self._built}))
            try:
                part.rename(entry)
            except OSError:  # another build put the same key there meanwhile
                shutil.rmtree(part, ignore_errors=True)
            builds = sorted(
                (p for p in entry.parent.iterdir() if p.is_dir() and ".part-" not in p.name),
                key=lambda p: p.stat().st_mtime,
                reverse=True,
            )
            for old in builds[KEEP_BUILDS:]:
                shutil.rmtree(old, ignore_errors=True)
            print(f"hli-server: the compiled engine is kept in the build cache ({entry})", file=sys.stderr)
        except OSError as exc:
            shutil.rmtree(part, ignore_errors=True)
            print(f"hli-server: the build cache {entry.parent} cannot be written ({exc})", file=sys.stderr)


def _ext_modules() -> list[Any]:
    """One extension that stands for the engine's (decided by :class:`EngineBuildExt` when it runs: from
    the cache or compiled), or none where this machine cannot compile."""
    why = _compiled_module().why_not_compilable()
    if why is not None:
        print(f"hli-server: engine not compiled ({why}): pure Python", file=sys.stderr)
        return []
    return [Extension(f"{GROUP}__mypyc", sources=[])]


if __name__ == "__main__":  # pip's build backend runs this file as the main module; tests import it
    setup(ext_modules=_ext_modules(), cmdclass={"build_ext": EngineBuildExt})
