"""PLC-side clients of the HLI process image (H-06): transports, the cyclic task, PLCopen blocks.

Imports ``schemas`` only, never ``hli_server`` (an import-linter contract): PLC logic written with
these modules runs against any server that serves the same layout.

* :mod:`plc_clients.transports`: :class:`ShmTransport`, :class:`ModbusTransport`,
  :class:`AsyncModbusTransport`, the in-memory twin :class:`MemoryImage` / :class:`MemoryTransport`;
* :mod:`plc_clients.ads`: :class:`AdsTransport`, :class:`AsyncAdsTransport` (pyads, H-04);
* :mod:`plc_clients.task`: :class:`PlcTask` (read inputs, run the program, write outputs);
* :mod:`plc_clients.plcopen`: :class:`MCV_DynPosLimitLow`, :class:`MCV_DynPosLimitHigh`,
  :class:`ControlUnitBlock` and its BOOL / SGN32 variants, :class:`AXIS_REF`;
* :mod:`plc_clients.shm`: the low-level shared-memory handle :class:`ImageClient` (by name, or over
  a buffer of a server in the same process);
* :mod:`plc_clients.demos`: the documents' examples as PLC programs, and :mod:`plc_clients.cli`,
  ``hli-plc``, which runs them against a running server.

See docs/plc-clients.md.
"""

from plc_clients.plcopen import (
    AXIS_REF,
    ControlBoolUnit,
    ControlSgn32Unit,
    ControlUnitBlock,
    DynPosLimitState,
    ErrorID,
    FunctionBlock,
    MCV_DynPosLimitHigh,
    MCV_DynPosLimitLow,
)
from plc_clients.shm import ImageClient
from plc_clients.task import InputNotReadyError, IoImage, PlcTask, TaskStats, current_image
from plc_clients.transports import (
    AsyncMemoryTransport,
    AsyncModbusTransport,
    AsyncTransport,
    Inputs,
    MemoryImage,
    MemoryTransport,
    ModbusTransport,
    ShmTransport,
    Transport,
    TransportError,
    load_layout,
)
from plc_clients.transports.ads import AdsTransport, AdsTransportError, AsyncAdsTransport

__all__ = [
    "AXIS_REF",
    "AdsTransport",
    "AdsTransportError",
    "AsyncAdsTransport",
    "AsyncMemoryTransport",
    "AsyncModbusTransport",
    "AsyncTransport",
    "ControlBoolUnit",
    "ControlSgn32Unit",
    "ControlUnitBlock",
    "DynPosLimitState",
    "ErrorID",
    "FunctionBlock",
    "ImageClient",
    "InputNotReadyError",
    "Inputs",
    "IoImage",
    "MCV_DynPosLimitHigh",
    "MCV_DynPosLimitLow",
    "MemoryImage",
    "MemoryTransport",
    "ModbusTransport",
    "PlcTask",
    "ShmTransport",
    "TaskStats",
    "Transport",
    "TransportError",
    "current_image",
    "load_layout",
]
