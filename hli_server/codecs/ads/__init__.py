"""ADS/AMS over TCP, sans-I/O: bytes in, typed frames and payloads out, and back (H-04, ADS issue).

No sockets, no asyncio, no clock: the ADS server adapter is a thin loop around this package, which
can be fuzzed and tested without a network (design.md, point 5; conventions: h11's
``receive_data``/``next_event``, pymodbus' drawn layouts, our ``codecs/modbus_frames.py``). It imports
only the standard library.

One request's way through the server::

    bytes from the socket
      -> AmsStreamDecoder.feed(data)            frames.py:   AmsPacket(header, data) | AmsTcpFrame
      -> decode_request(header.command, data)   commands.py: ReadRequest, WriteRequest, ...
      -> the server serves it; symbol services parse the ReadWrite data with symbols.py
         (decode_name, SumRead.decode, ...) and build their read data (SymbolEntry.encode, ...)
      -> ReadResponse(result, data).encode()    commands.py
      -> encode_response(header, payload)       frames.py:   bytes to the socket

Layouts: the AMS/TCP and AMS headers are drawn in :mod:`.frames`, the nine command payloads in
:mod:`.commands`, the symbol services, upload infos and sum commands in :mod:`.symbols`.

Errors (all :class:`AdsCodecError`, nothing else escapes for any input):

* :class:`AmsStreamError`: the stream cannot be delimited any more (length out of range, a reserved
  word that is no AMS/TCP command, AMS and AMS/TCP lengths disagreeing): answer what came before,
  then close the connection.
* :class:`AdsError`: one frame's payload cannot be served; ``.code`` is the ADS error code to answer
  with (0x701 service not supported, 0x705 size wrong, ...), raised where the problem is found. Put
  it in the command's result with :func:`error_reply_payload` (AdsLib needs the fixed part of
  Read/ReadWrite replies even on error), or in the AMS header with :func:`encode_error_response`
  for AMS-level errors (0x6 unknown port).

Bytes recorded from pyads 3.6 (Beckhoff AdsLib) and Node ads-client 2.1 are in
``tests/data/ads_golden_frames.json`` (re-record with ``tests/tools/ads_record.py``); the unit tests
decode each and re-encode it to the same bytes.
"""

from hli_server.codecs.ads.commands import (
    AddDeviceNotificationRequest,
    AddDeviceNotificationResponse,
    DeleteDeviceNotificationRequest,
    DeleteDeviceNotificationResponse,
    DeviceNotification,
    NotificationSample,
    NotificationStamp,
    ReadDeviceInfoRequest,
    ReadDeviceInfoResponse,
    ReadRequest,
    ReadResponse,
    ReadStateRequest,
    ReadStateResponse,
    ReadWriteRequest,
    ReadWriteResponse,
    Request,
    Response,
    WriteControlRequest,
    WriteControlResponse,
    WriteRequest,
    WriteResponse,
    decode_request,
    decode_response,
    encode_notification,
    error_reply_payload,
)
from hli_server.codecs.ads.constants import (
    AMS_TCP_PORT,
    BASE_TYPES,
    REQUEST_FLAGS,
    RESPONSE_FLAGS,
    AdsDataType,
    AdsState,
    AmsTcpCommand,
    CommandId,
    DataTypeFlag,
    ErrorCode,
    IndexGroup,
    StateFlag,
    SymbolFlag,
    TransmissionMode,
    UploadInfoFlag,
    ads_type_name,
)
from hli_server.codecs.ads.errors import AdsCodecError, AdsError, AmsStreamError
from hli_server.codecs.ads.frames import (
    AMS_HEADER_SIZE,
    AMS_TCP_HEADER_SIZE,
    MAX_ADS_PAYLOAD,
    MAX_AMS_LENGTH,
    MAX_ROUTER_LENGTH,
    NEED_DATA,
    AmsAddress,
    AmsHeader,
    AmsPacket,
    AmsStreamDecoder,
    AmsTcpFrame,
    Frame,
    NeedData,
    NetId,
    OversizeAmsFrame,
    encode_error_response,
    encode_port_close_reply,
    encode_port_connect_reply,
    encode_request,
    encode_response,
    encode_router_frame,
    port_of_port_request,
)
from hli_server.codecs.ads.symbols import (
    FILETIME_UNIX_EPOCH,
    ArrayInfo,
    DataTypeEntry,
    HandleInfo,
    SumRead,
    SumReadItem,
    SumReadWrite,
    SumReadWriteItem,
    SumWrite,
    SumWriteItem,
    SymbolEntry,
    UploadInfo,
    UploadInfo2,
    datetime_to_filetime,
    decode_data_type_upload,
    decode_name,
    decode_sum_read_reply,
    decode_sum_read_write_reply,
    decode_sum_write_reply,
    decode_symbol_upload,
    encode_handle_reply,
    encode_sum_read_reply,
    encode_sum_read_write_reply,
    encode_sum_write_reply,
    filetime_to_datetime,
    filetime_to_unix_ns,
    unix_ns_to_filetime,
)

__all__ = [
    "AMS_HEADER_SIZE",
    "AMS_TCP_HEADER_SIZE",
    "AMS_TCP_PORT",
    "BASE_TYPES",
    "FILETIME_UNIX_EPOCH",
    "MAX_ADS_PAYLOAD",
    "MAX_AMS_LENGTH",
    "MAX_ROUTER_LENGTH",
    "NEED_DATA",
    "REQUEST_FLAGS",
    "RESPONSE_FLAGS",
    "AddDeviceNotificationRequest",
    "AddDeviceNotificationResponse",
    "AdsCodecError",
    "AdsDataType",
    "AdsError",
    "AdsState",
    "AmsAddress",
    "AmsHeader",
    "AmsPacket",
    "AmsStreamDecoder",
    "AmsStreamError",
    "AmsTcpCommand",
    "AmsTcpFrame",
    "ArrayInfo",
    "CommandId",
    "DataTypeEntry",
    "DataTypeFlag",
    "DeleteDeviceNotificationRequest",
    "DeleteDeviceNotificationResponse",
    "DeviceNotification",
    "ErrorCode",
    "Frame",
    "HandleInfo",
    "IndexGroup",
    "NeedData",
    "NetId",
    "NotificationSample",
    "NotificationStamp",
    "OversizeAmsFrame",
    "ReadDeviceInfoRequest",
    "ReadDeviceInfoResponse",
    "ReadRequest",
    "ReadResponse",
    "ReadStateRequest",
    "ReadStateResponse",
    "ReadWriteRequest",
    "ReadWriteResponse",
    "Request",
    "Response",
    "StateFlag",
    "SumRead",
    "SumReadItem",
    "SumReadWrite",
    "SumReadWriteItem",
    "SumWrite",
    "SumWriteItem",
    "SymbolEntry",
    "SymbolFlag",
    "TransmissionMode",
    "UploadInfo",
    "UploadInfo2",
    "UploadInfoFlag",
    "WriteControlRequest",
    "WriteControlResponse",
    "WriteRequest",
    "WriteResponse",
    "ads_type_name",
    "datetime_to_filetime",
    "decode_data_type_upload",
    "decode_name",
    "decode_request",
    "decode_response",
    "decode_sum_read_reply",
    "decode_sum_read_write_reply",
    "decode_sum_write_reply",
    "decode_symbol_upload",
    "encode_error_response",
    "encode_handle_reply",
    "encode_notification",
    "encode_port_close_reply",
    "encode_port_connect_reply",
    "encode_request",
    "encode_response",
    "encode_router_frame",
    "encode_sum_read_reply",
    "encode_sum_read_write_reply",
    "encode_sum_write_reply",
    "error_reply_payload",
    "filetime_to_datetime",
    "filetime_to_unix_ns",
    "port_of_port_request",
    "unix_ns_to_filetime",
]
