"""File names as on the kernel's host (issue 33, item 7): Windows compares them without regard to case."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["find_file"]


def find_file(path: str | os.PathLike[str]) -> Path:
    """``path`` as it is, else the file whose name and directories' names match it without regard to
    case below the deepest directory of it that exists (``Programs/UP1.nc`` for ``programs/up1.nc``);
    the path as given when neither is there (opening it then says so)."""
    file = Path(path)
    if file.exists():
        return file
    missing: list[str] = []
    here = file
    while not here.exists():
        if here.parent == here:
            return file
        missing.append(here.name)
        here = here.parent
    for part in reversed(missing):
        folded = part.casefold()
        try:
            with os.scandir(here) as entries:
                found = next((Path(e.path) for e in entries if e.name.casefold() == folded), None)
        except OSError:
            return file
        if found is None:
            return file
        here = found
    return here if here.is_file() else file
