"""The integration harness (H-07): the server in-process with the stepped clock, and its pytest plugin.

* :class:`Harness` (``harness.py``): start the real server in this process, step it, drive a PLC
  task with it in lock-step, read and write the image by ST path, record per-cycle traces;
* ``plugin.py``: the pytest plugin (``hli`` and ``plc_transport`` fixtures), registered by the
  package's ``pytest11`` entry point;
* ``transports.py``: the PLC doors by name (shared memory, Modbus, ADS), a small registry;
* ``report.py``: the report of a condition that never came;
* ``remote.py``: :class:`~hli_server.testing.remote.RemoteHarness`, the same calls for a server that runs
  elsewhere (``pytest --hli-url``: a fleet of CNCs, docs/testing.md).

docs/testing.md shows a complete test.
"""

from hli_server.testing.harness import (
    CommFaultsView,
    ConditionNotMetError,
    Harness,
    HarnessError,
    ImageView,
    ReplayFailedError,
    SessionRecording,
    load_machine_spec,
)
from hli_server.testing.transports import (
    TRANSPORTS,
    TransportKind,
    open_transport,
    register_transport,
    transport_names,
    unavailable,
)

__all__ = [
    "TRANSPORTS",
    "CommFaultsView",
    "ConditionNotMetError",
    "Harness",
    "HarnessError",
    "ImageView",
    "ReplayFailedError",
    "SessionRecording",
    "TransportKind",
    "load_machine_spec",
    "open_transport",
    "register_transport",
    "transport_names",
    "unavailable",
]
