"""Shared test configuration.

Every test that proves a requirement carries its IDs: ``@pytest.mark.req("C14-11")``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

_DEV_SHM = Path("/dev/shm")


def _our_segments() -> set[str]:
    """Shared-memory segments named after this process (the default image names, ``hli_<pid>_...``)."""
    if not _DEV_SHM.is_dir():  # pragma: no cover - not Linux
        return set()
    marker = f"hli_{os.getpid()}_"
    return {p.name for p in _DEV_SHM.iterdir() if p.name.startswith(marker)}


@pytest.fixture(autouse=True)
def _no_leaked_shared_memory():
    """No process image created by a test outlives it (H-01): every one is closed and unlinked.

    Images belong to function-scoped fixtures; one kept by a module-scoped fixture is reported here.
    """
    before = _our_segments()
    yield
    shm_module = sys.modules.get("hli_server.image.shm")
    still_open = sorted(shm_module.open_image_names()) if shm_module is not None else []
    for name in still_open:  # close them, so that one leak does not fail every later test
        shm_module._open_images[name].close()
    left = sorted(_our_segments() - before)
    assert not still_open, f"process images not closed by the test: {still_open}"
    assert not left, f"shared memory left in /dev/shm by the test: {left}"
