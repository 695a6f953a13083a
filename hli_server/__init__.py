"""hli_server: a simulated CNC kernel with its PLC interface (HLI).

Importing the package decides, once, whether this process runs the compiled engine or the same
source as pure Python (``hli_server/_compiled.py``; ``HLI_PURE_PYTHON=1`` forces pure Python).
"""

from hli_server._compiled import select as _select_engine

_select_engine()
