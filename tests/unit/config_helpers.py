"""Machine files for the configuration tests: write one, and read the findings its loading reports."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from hli_server.configuration import ConfigError, load_machine

__all__ = ["errors_of", "write"]


def write(directory: Path, name: str, text: str) -> Path:
    path = directory / name
    path.write_text(textwrap.dedent(text).lstrip("\n"), encoding="utf-8")
    return path


def errors_of(path: Path) -> list[str]:
    with pytest.raises(ConfigError) as info:
        load_machine(path)
    return info.value.messages
