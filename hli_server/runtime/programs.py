"""Program files: the runtime reads them for the engine, which does no I/O itself."""

from __future__ import annotations

from pathlib import Path

__all__ = ["MAX_PROGRAM_BYTES", "read_program_file"]

MAX_PROGRAM_BYTES = 64 * 1024 * 1024
"""Largest program file selected through the program table (64 MiB); larger ones are refused."""


def read_program_file(path: str) -> str:
    """Program table entries given by ``path`` (absolute after loading the configuration) are read
    when the PLC or the operator selects them. OSError or UnicodeDecodeError on failure."""
    file = Path(path)
    size = file.stat().st_size
    if size > MAX_PROGRAM_BYTES:
        raise OSError(f"{path}: {size} bytes, more than the {MAX_PROGRAM_BYTES} bytes a program may have")
    return file.read_text(encoding="utf-8")
