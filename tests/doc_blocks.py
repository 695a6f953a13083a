"""The code blocks of the docs that tests run as written (docs/plc-clients.md, docs/testing.md).

A block to run is marked in the Markdown by an HTML comment that names it, right before its fence::

    <!-- test_my_plc.py: run as written by tests/integration/test_plugin.py -->
    ```python
    ...
"""

from __future__ import annotations

import re
from pathlib import Path

__all__ = ["DOCS", "code_blocks", "marked_block"]

DOCS = Path(__file__).resolve().parents[1] / "docs"
_FENCE = re.compile(r"```python\n(.*?)```", re.DOTALL)


def code_blocks(doc: Path) -> list[str]:
    """Every ``python`` code block of ``doc``, in order."""
    return _FENCE.findall(doc.read_text(encoding="utf-8"))


def marked_block(doc: Path, marker: str) -> str:
    """The first ``python`` code block after the comment ``<!-- {marker}`` in ``doc``."""
    text = doc.read_text(encoding="utf-8")
    start = text.index(f"<!-- {marker}")
    match = _FENCE.search(text, start)
    assert match is not None, f"{doc.name}: no python code block follows the marker {marker!r}"
    return match.group(1)
