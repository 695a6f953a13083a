"""Numbers of the AMS/ADS protocol: commands, flags, error codes, index groups, states, modes (H-04).

Sources: Beckhoff Information System, "ADS / AMS specification" (TC3 ADS introduction, the
"ADS return codes" table); Beckhoff AdsLib (``AdsDef.h``, ``AmsHeader.h``); the constants of pyads
3.6 (``pyads/constants.py``) and Node ads-client 2.1 (``ads-commons.js``), which agree on every number
listed here. ``../shared/reference/ads.md`` names the ones the server answers with.
"""

from __future__ import annotations

from enum import IntEnum, IntFlag
from typing import Final

__all__ = [
    "AMS_TCP_PORT",
    "BASE_TYPES",
    "REQUEST_FLAGS",
    "RESPONSE_FLAGS",
    "AdsDataType",
    "AdsState",
    "AmsTcpCommand",
    "CommandId",
    "DataTypeFlag",
    "ErrorCode",
    "IndexGroup",
    "StateFlag",
    "SymbolFlag",
    "TransmissionMode",
    "UploadInfoFlag",
    "ads_type_name",
]

AMS_TCP_PORT: Final = 48898
"""The TCP port of an AMS router (TwinCAT, AdsLib and ads-client use it by default)."""


class AmsTcpCommand(IntEnum):
    """The "reserved" u16 that opens every AMS/TCP header: what the rest of the frame is.

    0 is an AMS frame (AMS header + ADS payload); the others are messages to and from the AMS router
    itself, with no AMS header (names as in TwinCAT's ``AMS_TCP_PORT_*``).
    """

    AMS_CMD = 0x0000
    PORT_CLOSE = 0x0001
    """Client -> router: u16 port to release. The router answers with the same command (ads-client waits
    for it, then the TCP connection ends)."""
    PORT_CONNECT = 0x1000
    """Client -> router: u16 port wanted (0 = any). Reply: NetId (6) + port (2) assigned to the client."""
    ROUTER_NOTE = 0x1001
    """Router -> client: u32 router state (0 stop, 1 start, 2 removed)."""
    GET_LOCAL_NETID = 0x1002
    """Asks the router's own NetId; no client we record sends it, ads-client ignores the answer."""


class CommandId(IntEnum):
    """ADS command ids (AMS header ``command``)."""

    INVALID = 0
    READ_DEVICE_INFO = 1
    READ = 2
    WRITE = 3
    READ_STATE = 4
    WRITE_CONTROL = 5
    ADD_DEVICE_NOTIFICATION = 6
    DELETE_DEVICE_NOTIFICATION = 7
    DEVICE_NOTIFICATION = 8
    READ_WRITE = 9


class StateFlag(IntFlag):
    """AMS header ``state flags`` bits."""

    RESPONSE = 0x0001
    NO_RETURN = 0x0002
    ADS_COMMAND = 0x0004
    SYSTEM_COMMAND = 0x0008
    HIGH_PRIORITY = 0x0010
    TIMESTAMP_ADDED = 0x0020
    UDP = 0x0040
    INIT_COMMAND = 0x0080
    BROADCAST = 0x8000


REQUEST_FLAGS: Final = int(StateFlag.ADS_COMMAND)
"""0x0004: an ADS request over TCP (also a DeviceNotification, which the server sends unasked)."""
RESPONSE_FLAGS: Final = int(StateFlag.ADS_COMMAND | StateFlag.RESPONSE)
"""0x0005: an ADS response over TCP."""


class ErrorCode(IntEnum):
    """ADS/AMS return codes: the AMS header's ``error code`` and every response's ``result``.

    0x001..0x01F are global (AMS/router) errors, 0x500.. router errors, 0x700.. device errors (what an
    ADS server answers), 0x740.. errors the client library raises itself. pyads shows them as
    ``ADSError: symbol not found (1808)``.
    """

    NO_ERROR = 0x000
    INTERNAL = 0x001
    TARGET_PORT_NOT_FOUND = 0x006
    """No ADS server on the AMS port addressed (AMS level)."""
    TARGET_MACHINE_NOT_FOUND = 0x007
    """No route to the NetId addressed (AMS level)."""
    UNKNOWN_COMMAND = 0x008
    """Unknown command id (AMS level)."""
    INVALID_AMS_LENGTH = 0x00E
    INVALID_AMS_NET_ID = 0x00F
    GENERAL_DEVICE_ERROR = 0x700
    SERVICE_NOT_SUPPORTED = 0x701
    INVALID_INDEX_GROUP = 0x702
    INVALID_INDEX_OFFSET = 0x703
    READ_WRITE_NOT_PERMITTED = 0x704
    SIZE_WRONG = 0x705
    """"Parameter size not correct": a request whose length does not fit its command or target."""
    INVALID_VALUE = 0x706
    NOT_READY = 0x707
    BUSY = 0x708
    NO_MEMORY = 0x70A
    INVALID_PARAMETER = 0x70B
    NOT_FOUND = 0x70C
    SYNTAX_ERROR = 0x70D
    ALREADY_EXISTS = 0x70F
    SYMBOL_NOT_FOUND = 0x710
    SYMBOL_VERSION_INVALID = 0x711
    INVALID_SERVER_STATE = 0x712
    TRANSMISSION_MODE_NOT_SUPPORTED = 0x713
    NOTIFICATION_HANDLE_INVALID = 0x714
    NOTIFICATION_CLIENT_NOT_REGISTERED = 0x715
    NO_MORE_NOTIFICATION_HANDLES = 0x716
    WATCH_SIZE_TOO_BIG = 0x717
    CLIENT_TIMEOUT = 0x745
    """1861: AdsLib's own "timeout elapsed" (no reply, or a reply it could not match)."""
    CLIENT_INVALID_RESPONSE = 0x754
    """1876: AdsLib's own "invalid response received" (a reply shorter than the command's fixed part)."""


class IndexGroup(IntEnum):
    """Reserved index groups of the symbol server (the ones the HLI server answers, ADS issue)."""

    SYM_HANDLE_BY_NAME = 0xF003
    """ReadWrite: name (NUL-terminated) in, u32 handle out (see ``symbols.encode_handle_reply``)."""
    SYM_VALUE_BY_NAME = 0xF004
    SYM_VALUE_BY_HANDLE = 0xF005
    """Read/Write/notifications: index offset = handle."""
    SYM_RELEASE_HANDLE = 0xF006
    """Write: u32 handle."""
    SYM_INFO_BY_NAME = 0xF007
    SYM_VERSION = 0xF008
    """Read: u8 symbol version (clients watch it with a notification and re-read symbols on change)."""
    SYM_INFO_BY_NAME_EX = 0xF009
    """ReadWrite: name in, one AdsSymbolEntry out."""
    SYM_UPLOAD = 0xF00B
    """Read: every AdsSymbolEntry, back to back."""
    SYM_UPLOAD_INFO = 0xF00C
    """Read: 8 bytes (symbol count, symbol bytes)."""
    SYM_DT_UPLOAD = 0xF00E
    """Read: every AdsDatatypeEntry, back to back."""
    SYM_UPLOAD_INFO2 = 0xF00F
    """Read: 24 bytes (64 from newer TwinCAT 3.1 builds on); see ``symbols.UploadInfo2``."""
    DATA_TYPE_INFO_BY_NAME_EX = 0xF011
    """ReadWrite: type name in, one AdsDatatypeEntry out."""
    SUMUP_READ = 0xF080
    """ReadWrite: index offset = count; see ``symbols.SumRead``."""
    SUMUP_WRITE = 0xF081
    SUMUP_READWRITE = 0xF082
    DEVICE_DATA = 0xF100
    """ADS state (offset 0) of the device; ads-client watches it with a notification after connect."""


class AdsState(IntEnum):
    """ADS state (ReadState, WriteControl); a running PLC reports RUN."""

    INVALID = 0
    IDLE = 1
    RESET = 2
    INIT = 3
    START = 4
    RUN = 5
    STOP = 6
    SAVE_CONFIG = 7
    LOAD_CONFIG = 8
    POWER_FAILURE = 9
    POWER_GOOD = 10
    ERROR = 11
    SHUTDOWN = 12
    SUSPEND = 13
    RESUME = 14
    CONFIG = 15
    RECONFIG = 16


class TransmissionMode(IntEnum):
    """AddDeviceNotification ``transmission mode`` (pyads ``ADSTRANS_*``, ads-client ``ADS_TRANS_MODE``)."""

    NO_TRANSMISSION = 0
    CLIENT_CYCLE = 1
    CLIENT_ON_CHANGE = 2
    SERVER_CYCLE = 3
    """Send every ``cycle time`` (pyads ADSTRANS_SERVERCYCLE)."""
    SERVER_ON_CHANGE = 4
    """Send when the value changed, checked every ``cycle time`` (pyads ADSTRANS_SERVERONCHA)."""
    SERVER_CYCLE_IN_CONTEXT = 5
    SERVER_ON_CHANGE_IN_CONTEXT = 6


class AdsDataType(IntEnum):
    """``ADST_*``: the data type field of symbol and data-type entries."""

    VOID = 0
    INT16 = 2
    INT32 = 3
    REAL32 = 4
    REAL64 = 5
    INT8 = 16
    UINT8 = 17
    UINT16 = 18
    UINT32 = 19
    INT64 = 20
    UINT64 = 21
    STRING = 30
    WSTRING = 31
    REAL80 = 32
    BIT = 33
    BIGTYPE = 65
    """Structures, arrays of structures, function blocks."""


class SymbolFlag(IntFlag):
    """u16 flags of an AdsSymbolEntry (ads-client ``ADS_SYMBOL_FLAGS``)."""

    PERSISTENT = 0x0001
    BIT_VALUE = 0x0002
    REFERENCE_TO = 0x0004
    TYPE_GUID = 0x0008
    """A 16-byte type GUID follows the array infos."""
    TCCOM_INTERFACE_PTR = 0x0010
    READ_ONLY = 0x0020
    ITF_METHOD_ACCESS = 0x0040
    METHOD_DEREF = 0x0080
    CONTEXT_MASK = 0x0F00
    ATTRIBUTES = 0x1000
    """u16 count + attributes follow (after the GUID)."""
    STATIC = 0x2000
    INIT_ON_RESET = 0x4000
    EXTENDED_FLAGS = 0x8000
    """A u32 of extended flags follows (after the attributes)."""


class DataTypeFlag(IntFlag):
    """u32 flags of an AdsDatatypeEntry (``ADSDATATYPEFLAG_*``, ads-client ``ADS_DATA_TYPE_FLAGS``)."""

    DATA_TYPE = 0x0000_0001
    """The entry is a type (upload 0xF00E, query 0xF011)."""
    DATA_ITEM = 0x0000_0002
    """The entry is a sub item (a member of a struct)."""
    REFERENCE_TO = 0x0000_0004
    METHOD_DEREF = 0x0000_0008
    OVERSAMPLE = 0x0000_0010
    BIT_VALUES = 0x0000_0020
    PROP_ITEM = 0x0000_0040
    TYPE_GUID = 0x0000_0080
    PERSISTENT = 0x0000_0100
    COPY_MASK = 0x0000_0200
    TCCOM_INTERFACE_PTR = 0x0000_0400
    METHOD_INFOS = 0x0000_0800
    ATTRIBUTES = 0x0000_1000
    ENUM_INFOS = 0x0000_2000
    ALIGNED = 0x0001_0000
    STATIC = 0x0002_0000
    SOFTWARE_PROTECTION_LEVELS = 0x0004_0000
    IGNORE_PERSIST = 0x0008_0000
    ANY_SIZE_ARRAY = 0x0010_0000
    PERSISTENT_DATA_TYPE = 0x0020_0000
    INIT_ON_RESET = 0x0040_0000
    PLC_POINTER_TYPE = 0x0080_0000
    REFACTOR_INFO = 0x0100_0000
    HIDE_SUB_ITEMS = 0x0200_0000
    INCOMPLETE = 0x0400_0000
    CONTAINS_ONLINE_CHANGE_PTR_REF = 0x0800_0000
    DEREF_TYPE_ITEM = 0x1000_0000
    EXTENDED_ENUM_INFOS = 0x2000_0000
    EXTENDED_FLAGS = 0x8000_0000


class UploadInfoFlag(IntFlag):
    """u32 flags of the 64-byte upload info (0xF00F of newer TwinCAT 3.1 builds)."""

    IS_64_BIT_PLATFORM = 0x1
    INCLUDES_BASE_TYPES = 0x2
    UTF8_ENCODED_STRING_DATA = 0x4


BASE_TYPES: Final[dict[str, tuple[AdsDataType, int]]] = {
    "BOOL": (AdsDataType.BIT, 1),
    "BYTE": (AdsDataType.UINT8, 1),
    "USINT": (AdsDataType.UINT8, 1),
    "SINT": (AdsDataType.INT8, 1),
    "WORD": (AdsDataType.UINT16, 2),
    "UINT": (AdsDataType.UINT16, 2),
    "INT": (AdsDataType.INT16, 2),
    "DWORD": (AdsDataType.UINT32, 4),
    "UDINT": (AdsDataType.UINT32, 4),
    "DINT": (AdsDataType.INT32, 4),
    "LWORD": (AdsDataType.UINT64, 8),
    "ULINT": (AdsDataType.UINT64, 8),
    "LINT": (AdsDataType.INT64, 8),
    "REAL": (AdsDataType.REAL32, 4),
    "LREAL": (AdsDataType.REAL64, 8),
}
"""IEC 61131-3 elementary types (the names TwinCAT's symbols carry) and their ADS data type ids and sizes."""

_KERNEL_TYPE_NAMES: Final = {
    "BOOLEAN": "BOOL",
    "SGN08": "SINT",
    "UNS08": "USINT",
    "SGN16": "INT",
    "UNS16": "UINT",
    "SGN32": "DINT",
    "UNS32": "UDINT",
    "REAL32": "REAL",
    "REAL64": "LREAL",
}
"""The kernel's type names (V.E. variables, P-CHAN lists) and the IEC names a TwinCAT symbol has for them."""


def ads_type_name(name: str) -> str:
    """The IEC name an ADS symbol carries for a type name of the layout (``SGN32`` -> ``DINT``)."""
    upper = name.upper()
    return _KERNEL_TYPE_NAMES.get(upper, upper)
