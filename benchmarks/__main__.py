"""``python -m benchmarks [NAME ...] [-- ARGS]``: run the benchmarks (all, or those whose name contains NAME).

Each benchmark prints its figure, the figure of the reference it is compared with (measured in the same
run) and the ratio. ``--list`` shows them; arguments after ``--`` go to every benchmark that runs (e.g.
``python -m benchmarks pacing -- --seconds 60``).
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from pathlib import Path


def _benchmarks() -> list[str]:
    here = Path(__file__).parent
    return sorted(m.name for m in pkgutil.iter_modules([str(here)]) if m.name.startswith("bench_"))


def _summary(name: str) -> str:
    doc = importlib.import_module(f"benchmarks.{name}").__doc__ or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def main() -> None:
    argv = sys.argv[1:]
    passed: list[str] = []
    if "--" in argv:
        cut = argv.index("--")
        argv, passed = argv[:cut], argv[cut + 1 :]
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "names", nargs="*", metavar="NAME", help="run the benchmarks whose name contains NAME"
    )
    parser.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    args = parser.parse_args(argv)
    names = _benchmarks()
    if args.list:
        for name in names:
            print(f"{name.removeprefix('bench_'):12} {_summary(name)}")
        return
    chosen = [n for n in names if not args.names or any(w in n for w in args.names)]
    if not chosen:
        parser.error(f"no benchmark matches {' '.join(args.names)}; see --list")
    for name in chosen:
        print(f"=== {name}", flush=True)
        module = importlib.import_module(f"benchmarks.{name}")
        saved = sys.argv
        sys.argv = [name, *passed]
        try:
            module.main()
        finally:
            sys.argv = saved


if __name__ == "__main__":
    main()
