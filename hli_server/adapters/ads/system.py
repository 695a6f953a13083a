"""Device info, state and control on every port, and the TwinCAT system service on AMS port 10000 (H-04).

A client that connects "as to a TwinCAT" asks the system service first: Node ``ads-client`` with its
default settings reads the extended system state (Read of index group 0xF0 = 240, offset 0, 16 bytes,
on port 10000) and falls back to ReadState on port 10000; it polls that every second afterwards and
reports the connection lost when the state is not RUN (``connectToTarget()`` ... ``readTcSystemState()``
failed is what it says when nothing answers). TwinCAT XAE and ``AdsInfo`` ask ReadDeviceInfo there.

Port 10000 answers:

* ReadState: RUN (5), device state 0;
* ReadDeviceInfo: ``TwinCAT System``, version :data:`TWINCAT_VERSION` (3.1.4024);
* Read 0xF0, offset 0: the extended state, 16 bytes: ADS state u16, device state u16, restart index
  u16 (changes when the server restarts: ads-client then reconnects), version u8, revision u8,
  build u16, platform u8, OS type u8, flags u16, reserved 2;
* WriteControl to RUN (the state it is in); to any other state 0x701: the simulated CNC stays in RUN.

ReadDeviceInfo of the other ports: 851 ``Plc30 App`` (what a TwinCAT 3 PLC runtime calls itself),
551 ``HLI-Server GEO``, each with the same version; ReadState RUN everywhere.
"""

from __future__ import annotations

import struct
import time
from typing import TYPE_CHECKING, Final

from hli_server.codecs.ads import (
    AdsError,
    AdsState,
    ErrorCode,
    ReadDeviceInfoResponse,
    ReadStateResponse,
    WriteControlRequest,
    WriteControlResponse,
)

if TYPE_CHECKING:
    from hli_server.adapters.ads.session import PortTable, Session
    from hli_server.codecs.ads import AmsHeader

__all__ = [
    "GROUP_SYSTEM_STATE",
    "SYSTEM_SERVICE_PORT",
    "TWINCAT_VERSION",
    "SystemService",
]

SYSTEM_SERVICE_PORT: Final = 10000
GROUP_SYSTEM_STATE: Final = 0xF0
"""Port 10000: the extended system state (ads-client ``readTcSystemExtendedState``)."""
TWINCAT_VERSION: Final = (3, 1, 4024)
"""The TwinCAT version the server answers as (device info, extended state, the UDP discovery answer)."""

_EXTENDED_STATE: Final = struct.Struct("<HHHBBHBBH2s")


class SystemService:
    """ReadDeviceInfo, ReadState, WriteControl (every port) and the extended state (port 10000)."""

    def __init__(self) -> None:
        self.restart_index = int(time.time()) & 0xFFFF
        major, minor, build = TWINCAT_VERSION
        self._extended = _EXTENDED_STATE.pack(
            AdsState.RUN, 0, self.restart_index, major, minor, build, 0, 0, 0, b"\0\0"
        )
        self._state = ReadStateResponse(0, AdsState.RUN, 0).encode()
        self._infos: dict[str, bytes] = {}

    # --- commands: (session, port table, header, payload) -> reply payload ------------------------
    def read_device_info(self, session: Session, table: PortTable, header: AmsHeader, data: bytes) -> bytes:
        if data:
            raise AdsError(ErrorCode.SIZE_WRONG, f"ReadDeviceInfo carries no data, got {len(data)} bytes")
        reply = self._infos.get(table.name)
        if reply is None:
            major, minor, build = TWINCAT_VERSION
            reply = self._infos[table.name] = ReadDeviceInfoResponse(
                0, major, minor, build, table.name
            ).encode()
        return reply

    def read_state(self, session: Session, table: PortTable, header: AmsHeader, data: bytes) -> bytes:
        if data:
            raise AdsError(ErrorCode.SIZE_WRONG, f"ReadState carries no data, got {len(data)} bytes")
        return self._state

    def write_control(self, session: Session, table: PortTable, header: AmsHeader, data: bytes) -> bytes:
        request = WriteControlRequest.decode(data)
        if request.ads_state != AdsState.RUN:
            name = AdsState(request.ads_state).name if request.ads_state in set(AdsState) else "unknown"
            raise AdsError(
                ErrorCode.SERVICE_NOT_SUPPORTED,
                f"WriteControl to ADS state {request.ads_state} ({name}): the simulated CNC stays in "
                "RUN; stop it with SIGTERM / Ctrl+C of `hli-server run`",
            )
        return WriteControlResponse(0).encode()

    # --- reads ------------------------------------------------------------------------------------
    def extended_state(self, session: Session, offset: int, length: int) -> bytes:
        if offset != 0:
            raise AdsError(
                ErrorCode.INVALID_INDEX_OFFSET, f"port 10000 group 0xF0 has offset 0 only, not {offset}"
            )
        if length < len(self._extended):
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"the extended system state is {len(self._extended)} bytes, read {length}",
            )
        return self._extended
