"""Transports: how PLC logic in Python reaches the process image (H-06).

One small protocol, several implementations (python-can's interface registry and its ``virtual``
bus are the model):

================================ ========================= ========================================= ======
transport                        door                      consistency of :meth:`snapshot`           module
================================ ========================= ========================================= ======
:class:`ShmTransport`            shared memory (H-01)      one publish of the whole CNC->PLC half    shm
:class:`ModbusTransport`         Modbus TCP, sync (H-03)   per request; see below                    modbus
:class:`AsyncModbusTransport`    Modbus TCP, asyncio       per request; see below                    modbus
:class:`AdsTransport`            ADS over TCP (H-04)       one publish (one ADS Read)                ads
:class:`AsyncAdsTransport`       ADS, asyncio              one publish (one ADS Read)                ads
:class:`MemoryTransport`         :class:`MemoryImage`      one publish of the twin (unit tests)      memory
================================ ========================= ========================================= ======

One module per door (python-can's one module per interface), the protocol and what they share in
``base``; each door's protocol logic exists once: the Modbus transports share a sans-I/O core driven by a
blocking and an asyncio loop (``modbus``'s docstring says why), the asyncio ADS and memory transports run
the synchronous one's calls.

The protocol (:class:`Transport`; :class:`AsyncTransport` has the same methods as coroutines):

* ``layout``: the :class:`~schemas.layout.Layout` of the image (every ST path and address);
* ``snapshot(watch=None) -> Inputs``: the PLC's input image for one task cycle: the CNC->PLC
  values (all of them, or at least those in ``watch``) and ``cycle``, the CNC cycle they were
  published in (a monotonic count; over Modbus the unwrapped ``gpCh[0]^bahn_state.cycle_r``);
* ``read(st_path)``, ``write(st_path, value)``, ``write_many(items)`` (in the given order: write
  the field that arms the others last, ``command_w`` before ``enable_w``, H-02);
* ``close()``.

Failures of the door (no server, connection lost, a Modbus exception answer, the server closed
the image) raise :class:`TransportError`. Mistakes in the caller's code (an unknown ST path, a write
to a ``_r`` field, a value the field cannot hold) raise the layout's own errors
(:class:`~schemas.layout.UnknownSignalError`, :class:`~schemas.layout.ReadOnlySignalError`,
:class:`~schemas.layout.SignalValueError`) before anything is sent.

**Where the Modbus transports get the layout.** Modbus carries no description of the map, so the
client must be given the same layout the server runs. ``layout=`` takes a
:class:`~schemas.layout.Layout`, the path of a JSON file written by
``hli-server map --format json > layout.json``, or the URL of the server's HTTP API
(``http://127.0.0.1:8080``, which serves ``GET /api/layout``); :func:`load_layout` does the
loading. The shared-memory transport needs none of this: the image carries its own layout and
hash. A layout of another machine gives wrong addresses without any error on the wire - take it
from the server you talk to.

**Consistency over Modbus.** Modbus has no atomic read of several tables: each request is
answered from one publish of the CNC->PLC half (the server serves it without yielding), but two
requests may fall into two CNC cycles. :meth:`ModbusTransport.snapshot` reads only what is
watched (fewest requests, :mod:`plc_clients.modbus_codec`). When that takes more than one request
it first writes 1 to the server's snapshot register (holding register
:data:`~schemas.layout.MODBUS_SNAPSHOT_REGISTER`): the server then answers this connection's reads
of inputs from one copy of the newest publish, so the whole snapshot is one CNC cycle
(:attr:`Inputs.consistent` is True) for one request more. A later single read of an input
(:meth:`read`) writes 0 first (live values again). Against a server without the register (it
answers 0x02) the transport reads ``cycle_r`` before and after instead, and ``consistent`` says
whether both came from the same publish. With the default ``watch=None`` it reads the whole half
(22 requests on the demo machine): pass the inputs the program reads (the PLC task learns them,
:class:`~plc_clients.task.PlcTask`).

Imports ``schemas``, the sans-I/O ADS codec (``hli_server.codecs``), pyads, and pymodbus' clients (lazily,
in the Modbus transports); never the server.
"""

from __future__ import annotations

from plc_clients.transports.ads import AdsTransport, AdsTransportError, AsyncAdsTransport
from plc_clients.transports.base import (
    CYCLE_R_MODULUS,
    CYCLE_SIGNAL,
    AsyncTransport,
    Inputs,
    Transport,
    TransportError,
    Value,
    load_layout,
)
from plc_clients.transports.memory import AsyncMemoryTransport, MemoryImage, MemoryTransport
from plc_clients.transports.modbus import AsyncModbusTransport, ModbusTransport
from plc_clients.transports.shm import ShmTransport

__all__ = [
    "CYCLE_R_MODULUS",
    "CYCLE_SIGNAL",
    "AdsTransport",
    "AdsTransportError",
    "AsyncAdsTransport",
    "AsyncMemoryTransport",
    "AsyncModbusTransport",
    "AsyncTransport",
    "Inputs",
    "MemoryImage",
    "MemoryTransport",
    "ModbusTransport",
    "ShmTransport",
    "Transport",
    "TransportError",
    "Value",
    "load_layout",
]
