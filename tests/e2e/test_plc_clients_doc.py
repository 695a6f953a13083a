"""The in-memory twin example of docs/plc-clients.md runs as written (H-06).

The page's complete example (``plc_demo.py`` against ``hli-server run``, over shared memory and over
Modbus TCP with the layout from the HTTP API) is run by the docs runner, session ``quick``
(``tests/integration/test_docs_run.py``), which compares what it prints with the page and carries
H-06 and C43-10.
"""

from __future__ import annotations

import pytest

from tests.doc_blocks import DOCS, code_blocks

pytestmark = pytest.mark.req("H-06")

DOC = DOCS / "plc-clients.md"


def test_the_twin_example_runs_as_written() -> None:
    (twin,) = [b for b in code_blocks(DOC) if "MemoryImage(build_layout" in b]
    exec(compile(twin, f"{DOC}:twin", "exec"), {})  # its own asserts check it
