"""The sans-I/O ADS/AMS codec (H-04): framing, the nine commands, symbol services, sum commands.

Golden frames are the exact bytes pyads 3.6 (Beckhoff AdsLib) and Node ads-client 2.1 sent to a
recording listener (``tests/data/ads_golden_frames.json``, made by ``tests/tools/ads_record.py``),
with the listener's hand-built replies, which those clients accepted. Every frame decodes to the
fields the client meant and re-encodes to the same bytes; pyads' own ctypes structures are the
oracle for the symbol entry layout.
"""

from __future__ import annotations

import contextlib
import ctypes
import itertools
import json
import random
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hli_server.codecs.ads import (
    MAX_AMS_LENGTH,
    NEED_DATA,
    AddDeviceNotificationRequest,
    AddDeviceNotificationResponse,
    AdsCodecError,
    AdsDataType,
    AdsError,
    AdsState,
    AmsAddress,
    AmsHeader,
    AmsPacket,
    AmsStreamDecoder,
    AmsStreamError,
    AmsTcpCommand,
    AmsTcpFrame,
    ArrayInfo,
    CommandId,
    DataTypeEntry,
    DataTypeFlag,
    DeleteDeviceNotificationRequest,
    DeleteDeviceNotificationResponse,
    DeviceNotification,
    ErrorCode,
    Frame,
    HandleInfo,
    IndexGroup,
    NetId,
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
    SumRead,
    SumReadItem,
    SumReadWrite,
    SumReadWriteItem,
    SumWrite,
    SumWriteItem,
    SymbolEntry,
    TransmissionMode,
    UploadInfo,
    UploadInfo2,
    WriteControlRequest,
    WriteControlResponse,
    WriteRequest,
    WriteResponse,
    datetime_to_filetime,
    decode_data_type_upload,
    decode_name,
    decode_request,
    decode_response,
    decode_sum_read_reply,
    decode_sum_read_write_reply,
    decode_sum_write_reply,
    decode_symbol_upload,
    encode_error_response,
    encode_handle_reply,
    encode_port_close_reply,
    encode_port_connect_reply,
    encode_request,
    encode_response,
    encode_router_frame,
    encode_sum_read_reply,
    encode_sum_read_write_reply,
    encode_sum_write_reply,
    error_reply_payload,
    filetime_to_datetime,
    filetime_to_unix_ns,
    port_of_port_request,
    unix_ns_to_filetime,
)
from tests.fuzz import count, seed_for

pytestmark = pytest.mark.req("H-04")

GOLDEN_FILE = Path(__file__).parents[1] / "data" / "ads_golden_frames.json"
SERVER = AmsAddress(NetId.parse("127.0.0.1.1.1"), 851)
PYADS_CLIENT = AmsAddress(NetId.parse("10.1.2.3.1.1"), 30001)
NODE_CLIENT = AmsAddress(NetId.parse("192.168.1.60.1.1"), 32750)
NOTIFIED_AT = datetime(2024, 1, 1, tzinfo=UTC)


@dataclass(frozen=True)
class Golden:
    client: str
    label: str
    direction: str
    raw: bytes
    index: int

    @property
    def from_client(self) -> bool:
        return self.direction == "client->server"

    def frame(self) -> Frame:
        frames = list(AmsStreamDecoder().feed(self.raw))
        assert len(frames) == 1, f"{self}: {len(frames)} frames"
        return frames[0]

    def packet(self) -> AmsPacket:
        frame = self.frame()
        assert isinstance(frame, AmsPacket)
        return frame

    def __str__(self) -> str:
        return f"{self.client.split(' (')[0]} {self.label} #{self.index} {self.direction}"


def _load_golden() -> list[Golden]:
    recorded = json.loads(GOLDEN_FILE.read_text())
    frames: list[Golden] = []
    for session in recorded["sessions"]:
        for i, f in enumerate(session["frames"]):
            frames.append(Golden(session["client"], f["label"], f["direction"], bytes.fromhex(f["hex"]), i))
    return frames


GOLDEN = _load_golden()


def golden(client: str, label: str) -> list[Golden]:
    """The frames of one recorded operation, in the order they crossed the wire."""
    found = [g for g in GOLDEN if g.client.startswith(client) and g.label == label]
    assert found, f"no golden frames for {client} {label!r}"
    return found


def typed(g: Golden) -> Any:
    """The frame's payload decoded with the codec, as the side that received it would."""
    packet = g.packet()
    if g.from_client:
        return decode_request(packet.header.command, packet.data)
    if packet.header.command == CommandId.DEVICE_NOTIFICATION:
        return DeviceNotification.decode(packet.data)
    return decode_response(packet.header.command, packet.data)


# --------------------------------------------------------------------------------------------
# Golden frames: every frame decodes and re-encodes to the same bytes
# --------------------------------------------------------------------------------------------


def test_golden_file_covers_both_clients_and_the_operations_of_the_brief() -> None:
    assert len(NOTIFICATIONS) >= 4
    labels = {(g.client.split()[0], g.label) for g in GOLDEN}
    for label in (
        "read",
        "write",
        "read_write",
        "read_by_name",
        "read_list_by_name",
        "add_device_notification",
        "read_device_info",
        "read_state",
    ):
        assert ("pyads", label) in labels
    assert ("Node", "readRaw") in labels
    assert ("Node", "readState (no local NetId: port connect first)") in labels
    assert sum(g.from_client for g in GOLDEN) >= 50


@pytest.mark.parametrize("g", GOLDEN, ids=str)
def test_golden_frame_round_trips(g: Golden) -> None:
    frame = g.frame()
    assert frame.to_bytes() == g.raw
    if isinstance(frame, AmsPacket):
        assert typed(g).encode() == frame.data
        assert frame.header.state_flags == (0x0004 if g.from_client or frame.header.command == 8 else 0x0005)


def _exchanges() -> Iterator[tuple[Golden, Golden]]:
    """(request, reply) pairs: a client frame and the server frame right after it."""
    for request, reply in itertools.pairwise(GOLDEN):
        if request.from_client and not reply.from_client and request.client == reply.client:
            yield request, reply


@pytest.mark.parametrize(("request_", "reply"), list(_exchanges()), ids=str)
def test_codec_builds_every_reply_the_clients_accepted(request_: Golden, reply: Golden) -> None:
    """The recorder built its replies by hand with struct; the codec builds the same bytes."""
    frame = request_.frame()
    if isinstance(frame, AmsTcpFrame):
        port = port_of_port_request(frame)
        if frame.command == AmsTcpCommand.PORT_CONNECT:
            assert encode_port_connect_reply(NetId.parse("192.168.1.50.1.1"), 32905) == reply.raw
        else:
            assert encode_port_close_reply(port) == reply.raw
        return
    assert encode_response(frame.header, typed(reply).encode()) == reply.raw


NOTIFICATIONS = [
    g
    for g in GOLDEN
    if isinstance(frame := g.frame(), AmsPacket) and frame.header.command == CommandId.DEVICE_NOTIFICATION
]


@pytest.mark.parametrize("g", NOTIFICATIONS, ids=str)
def test_codec_builds_every_notification_the_clients_decoded(g: Golden) -> None:
    """pyads and ads-client decoded these samples to the value and time sent (the recorder checked)."""
    header = g.packet().header
    stamps = typed(g).stamps
    payload = DeviceNotification(stamps).encode()
    assert encode_request(header.target, header.source, CommandId.DEVICE_NOTIFICATION, 0, payload) == g.raw


def test_pyads_read_write_and_read_write() -> None:
    read, read_reply = golden("pyads", "read")
    packet = read.packet()
    assert packet.header.target == SERVER
    assert packet.header.source == PYADS_CLIENT
    assert packet.header.command == CommandId.READ
    assert typed(read) == ReadRequest(0x4020, 8, 2)  # PLCTYPE_INT at %MB8
    assert typed(read_reply) == ReadResponse(0, b"\0\0")
    assert read_reply.packet().header.invoke_id == packet.header.invoke_id

    write = golden("pyads", "write")[0]
    assert typed(write) == WriteRequest(0x4020, 8, struct.pack("<h", 1234))
    read_write = golden("pyads", "read_write")[0]
    assert typed(read_write) == ReadWriteRequest(0x4020, 16, 4, struct.pack("<I", 7))


def test_pyads_invoke_ids_count_up_on_one_connection() -> None:
    ids = [g.packet().header.invoke_id for g in GOLDEN if g.client.startswith("pyads") and g.from_client]
    assert ids == list(range(1, len(ids) + 1))


def test_pyads_read_by_name_takes_a_handle_reads_by_it_and_releases_it() -> None:
    get_handle, handle_reply, read, _, release, _ = golden("pyads", "read_by_name")
    request = typed(get_handle)
    assert request.index_group == IndexGroup.SYM_HANDLE_BY_NAME
    assert request.read_length == 4
    assert decode_name(request.data) == "MAIN.counter"
    assert request.data.endswith(b"\0")
    handle = struct.unpack("<I", typed(handle_reply).data)[0]
    assert typed(read) == ReadRequest(IndexGroup.SYM_VALUE_BY_HANDLE, handle, 4)
    assert typed(release) == WriteRequest(IndexGroup.SYM_RELEASE_HANDLE, 0, struct.pack("<I", handle))
    assert encode_handle_reply(4, HandleInfo(handle, 4, "DINT")) == typed(handle_reply).data


def test_pyads_read_list_by_name_asks_symbol_info_then_one_sum_read() -> None:
    frames = golden("pyads", "read_list_by_name")
    entries = []
    for info_request, info_reply in zip(frames[0:6:2], frames[1:6:2], strict=True):
        request = typed(info_request)
        assert request.index_group == IndexGroup.SYM_INFO_BY_NAME_EX
        assert request.read_length == 798  # every 0xF009 reply must fit in it
        entry, end = SymbolEntry.decode(typed(info_reply).data)
        assert end == len(typed(info_reply).data)
        assert entry.name == decode_name(request.data)
        entries.append(entry)
    assert [(e.name, e.type_name, e.size, e.data_type) for e in entries] == [
        ("MAIN.counter", "DINT", 4, AdsDataType.INT32),
        ("MAIN.speed", "LREAL", 8, AdsDataType.REAL64),
        ("MAIN.flag", "BOOL", 1, AdsDataType.BIT),
    ]
    sum_request, sum_reply = typed(frames[6]), typed(frames[7])
    assert sum_request.index_group == IndexGroup.SUMUP_READ
    sum_read = SumRead.decode(sum_request.index_offset, sum_request.data)
    assert sum_read.items == tuple(SumReadItem(e.index_group, e.index_offset, e.size) for e in entries)
    assert sum_read.reply_length == sum_request.read_length == 4 * 3 + 4 + 8 + 1
    assert sum_read.encode() == sum_request.data
    results = decode_sum_read_reply(sum_read, sum_reply.data)
    assert results == [(0, bytes(4)), (0, bytes(8)), (0, bytes(1))]
    assert encode_sum_read_reply(sum_read, results) == sum_reply.data


def test_pyads_write_list_by_name_is_one_sum_write() -> None:
    request, reply = (typed(g) for g in golden("pyads", "write_list_by_name"))
    assert request.index_group == IndexGroup.SUMUP_WRITE
    assert request.read_length == 4 * 2
    sum_write = SumWrite.decode(request.index_offset, request.data)
    assert sum_write.items == (
        SumWriteItem(0x4040, 0x1000, struct.pack("<i", 3)),
        SumWriteItem(0x4040, 0x1010, b"\x01"),
    )
    assert sum_write.encode() == request.data
    assert decode_sum_write_reply(2, reply.data) == [0, 0]
    assert encode_sum_write_reply([0, 0]) == reply.data


def test_pyads_notifications_on_change_and_cyclic_and_the_sample_pyads_decoded() -> None:
    _, handle_reply, add, add_reply, sample = golden("pyads", "add_device_notification")
    handle = struct.unpack("<I", typed(handle_reply).data)[0]
    assert typed(add) == AddDeviceNotificationRequest(
        IndexGroup.SYM_VALUE_BY_HANDLE, handle, 4, TransmissionMode.SERVER_ON_CHANGE, 0, 0
    )
    notification_handle = typed(add_reply).handle
    sample_packet = sample.packet()
    assert sample_packet.header.command == CommandId.DEVICE_NOTIFICATION
    assert sample_packet.header.target == PYADS_CLIENT
    (stamp,) = typed(sample).stamps
    assert filetime_to_datetime(stamp.timestamp) == NOTIFIED_AT
    assert stamp.samples == (NotificationSample(notification_handle, struct.pack("<i", 4242)),)
    delete = golden("pyads", "del_device_notification")[0]
    assert typed(delete) == DeleteDeviceNotificationRequest(notification_handle)

    cyclic = typed(golden("pyads", "add_device_notification_cyclic")[0])
    assert cyclic.transmission_mode == TransmissionMode.SERVER_CYCLE
    assert cyclic.cycle_time == 1000  # cycle_time=0.1 ms -> 1000 x 100 ns
    assert (cyclic.index_group, cyclic.index_offset, cyclic.length) == (0x4040, 0x1008, 8)


def test_pyads_device_info_state_and_write_control() -> None:
    assert typed(golden("pyads", "read_device_info")[1]) == ReadDeviceInfoResponse(0, 3, 1, 4024, "Plc30 App")
    assert typed(golden("pyads", "read_state")[0]) == ReadStateRequest()
    assert typed(golden("pyads", "read_state")[1]) == ReadStateResponse(0, AdsState.RUN, 0)
    # pyads sends its data argument (PLCTYPE_INT 0) behind the two states
    assert typed(golden("pyads", "write_control")[0]) == WriteControlRequest(AdsState.RUN, 0, b"\0\0")


def test_node_raw_commands() -> None:
    assert typed(golden("Node", "readRaw")[0]) == ReadRequest(0x4020, 0, 4)
    assert golden("Node", "readRaw")[0].packet().header.source == NODE_CLIENT
    assert golden("Node", "readRaw")[0].packet().header.invoke_id == 0  # ads-client counts from 0
    assert typed(golden("Node", "writeRaw")[0]) == WriteRequest(0x4020, 4, b"\x01\x02\x03\x04")
    assert typed(golden("Node", "readWriteRaw")[0]) == ReadWriteRequest(0x4040, 8, 4, b"\x05\x06\x07\x08")
    assert typed(golden("Node", "writeControl")[0]) == WriteControlRequest(AdsState.RUN, 0)
    assert typed(golden("Node", "readDeviceInfo")[0]) == ReadDeviceInfoRequest()


def test_node_sum_commands() -> None:
    request = typed(golden("Node", "readRawMulti")[0])
    sum_read = SumRead.decode(request.index_offset, request.data)
    assert sum_read.items == (SumReadItem(0x4020, 0, 4), SumReadItem(0x4040, 0x1008, 8))
    assert sum_read.reply_length == request.read_length

    request = typed(golden("Node", "writeRawMulti")[0])
    assert SumWrite.decode(request.index_offset, request.data).items == (
        SumWriteItem(0x4020, 0, b"\x01\x00"),
        SumWriteItem(0x4020, 2, b"\x09"),
    )

    request, reply = (typed(g) for g in golden("Node", "readWriteRawMulti"))
    assert request.index_group == IndexGroup.SUMUP_READWRITE
    sum_rw = SumReadWrite.decode(request.index_offset, request.data)
    assert sum_rw.items == (SumReadWriteItem(0x4040, 1, 2, b"\x01\x02\x03"),)
    assert sum_rw.encode() == request.data
    assert decode_sum_read_write_reply(1, reply.data) == [(0, b"\0\0")]
    assert encode_sum_read_write_reply([(0, b"\0\0")]) == reply.data


def test_node_subscription_and_the_sample_ads_client_decoded() -> None:
    add, add_reply, sample, delete, _ = golden("Node", "subscribeRaw")
    assert typed(add) == AddDeviceNotificationRequest(
        0x4020, 0, 4, TransmissionMode.SERVER_ON_CHANGE, 0, 1_000_000
    )
    (stamp,) = typed(sample).stamps
    assert stamp.samples == (NotificationSample(typed(add_reply).handle, struct.pack("<i", 4242)),)
    assert filetime_to_datetime(stamp.timestamp) == NOTIFIED_AT
    assert typed(delete) == DeleteDeviceNotificationRequest(typed(add_reply).handle)


def test_node_handle_asks_the_extended_reply() -> None:
    get_handle, reply, read, _, release, _ = golden("Node", "createVariableHandle")
    request = typed(get_handle)
    assert request.read_length == 0xFFFFFFFF
    info = HandleInfo.decode(typed(reply).data)
    assert info == HandleInfo(info.handle, 4, "DINT")
    assert encode_handle_reply(request.read_length, info) == typed(reply).data
    assert typed(read) == ReadRequest(IndexGroup.SYM_VALUE_BY_HANDLE, info.handle, 4)
    assert typed(release) == WriteRequest(IndexGroup.SYM_RELEASE_HANDLE, 0, struct.pack("<I", info.handle))


def test_node_symbol_info_upload_info_and_symbol_version() -> None:
    request, reply = (typed(g) for g in golden("Node", "getSymbol"))
    assert request.index_group == IndexGroup.SYM_INFO_BY_NAME_EX
    entry, _ = SymbolEntry.decode(reply.data)
    assert (entry.name, entry.index_group, entry.index_offset) == ("MAIN.counter", 0x4040, 0x1000)

    request, reply = (typed(g) for g in golden("Node", "readPlcUploadInfo"))
    assert request == ReadRequest(IndexGroup.SYM_UPLOAD_INFO2, 0, 64)  # it asks 64, takes 24 as version 2
    assert UploadInfo2.decode(reply.data) == UploadInfo2(3, 300, 2, 200)
    assert typed(golden("Node", "readPlcSymbolVersion")[0]) == ReadRequest(IndexGroup.SYM_VERSION, 0, 1)


def test_node_full_connect_asks_the_system_service_then_watches_state_and_symbol_version() -> None:
    frames = golden("Node", "connect (rawClient: false): system state, ADS state and symbol version watches")
    requests = [g for g in frames if g.from_client]
    first = requests[0].packet()
    assert first.header.target == AmsAddress(SERVER.net_id, 10000)
    assert typed(requests[0]) == ReadRequest(0xF0, 0, 16)
    assert typed(requests[1]).index_group == IndexGroup.DEVICE_DATA
    assert [typed(r).index_group for r in requests if isinstance(typed(r), AddDeviceNotificationRequest)] == [
        IndexGroup.DEVICE_DATA,
        IndexGroup.SYM_VERSION,
    ]


def test_node_without_local_net_id_connects_a_port_first_and_closes_it_last() -> None:
    connect, assigned, read_state, _, close, _ = golden(
        "Node", "readState (no local NetId: port connect first)"
    )
    request = connect.frame()
    assert request == AmsTcpFrame(AmsTcpCommand.PORT_CONNECT, b"\0\0")
    assert port_of_port_request(request) == 0  # any port
    reply = assigned.frame()
    assert isinstance(reply, AmsTcpFrame)
    net_id, port = NetId(reply.data[:6]), struct.unpack("<H", reply.data[6:])[0]
    assert read_state.packet().header.source == AmsAddress(net_id, port)
    assert port_of_port_request(close.frame()) == port
    assert close.frame().command == AmsTcpCommand.PORT_CLOSE


def test_symbol_entry_layout_matches_pyads_ctypes_structure() -> None:
    """pyads reads 0xF009 replies into its ``SAdsSymbolEntry``; it must find our fields there."""
    from pyads.structs import SAdsSymbolEntry

    entry = SymbolEntry(
        0x4040, 0x1234, 8, AdsDataType.REAL64, "GVL.gpAx[0].pos_r", "LREAL", "position, 0.1 um", flags=0x20
    )
    raw = entry.encode()
    assert len(raw) <= 798
    parsed = SAdsSymbolEntry.from_buffer_copy(raw.ljust(ctypes.sizeof(SAdsSymbolEntry), b"\0"))
    assert parsed.entryLength == len(raw)
    assert (parsed.iGroup, parsed.iOffs, parsed.size, parsed.dataType) == (0x4040, 0x1234, 8, 5)
    assert (parsed.name, parsed.symbol_type, parsed.comment) == (entry.name, "LREAL", entry.comment)
    assert parsed.flags == 0x20  # pyads reads flags and array dim as one u32: dims 0 keep it equal


# --------------------------------------------------------------------------------------------
# Incremental feeding
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("g", GOLDEN, ids=str)
def test_a_golden_frame_split_at_every_byte_is_reassembled(g: Golden) -> None:
    for cut in range(len(g.raw) + 1):
        decoder = AmsStreamDecoder()
        first = list(decoder.feed(g.raw[:cut]))
        second = list(decoder.feed(g.raw[cut:]))
        assert first + second == [g.frame()], f"cut at {cut}"
        assert (first == []) == (cut < len(g.raw))
        assert decoder.pending == 0


def test_all_golden_frames_in_one_read_and_byte_by_byte() -> None:
    stream = b"".join(g.raw for g in GOLDEN)
    expected = [g.frame() for g in GOLDEN]
    assert list(AmsStreamDecoder().feed(stream)) == expected
    decoder = AmsStreamDecoder()
    got: list[Frame] = []
    for i in range(len(stream)):
        got.extend(decoder.feed(stream[i : i + 1]))
    assert got == expected


def test_h11_style_receive_data_and_next_frame() -> None:
    read, write = golden("pyads", "read")[0], golden("pyads", "write")[0]
    decoder = AmsStreamDecoder()
    assert decoder.next_frame() is NEED_DATA
    decoder.receive_data(read.raw + write.raw[:10])
    assert decoder.next_frame() == read.frame()
    assert decoder.next_frame() is NEED_DATA
    assert decoder.pending == 10
    decoder.receive_data(write.raw[10:])
    assert decoder.next_frame() == write.frame()
    assert decoder.next_frame() is NEED_DATA
    assert decoder.pending == 0


# --------------------------------------------------------------------------------------------
# A broken stream: the codec's own error, frames before the damage still handed out
# --------------------------------------------------------------------------------------------


def _ams(length: int, data_length: int | None = None, reserved: int = 0) -> bytes:
    header = struct.pack("<HI", reserved, length)
    ams = (
        bytes(SERVER.net_id) + struct.pack("<H", 851) + bytes(PYADS_CLIENT.net_id) + struct.pack("<H", 30001)
    )
    dl = length - 32 if data_length is None else data_length
    return header + ams + struct.pack("<HHIII", 2, 4, dl, 0, 1) + bytes(max(0, length - 32))


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        (struct.pack("<HI", 0, 31) + bytes(31), "outside 32..65584"),
        (struct.pack("<HI", 0, MAX_AMS_LENGTH + 1), "outside 32..65584"),
        (struct.pack("<HI", 0, 0xFFFFFFFF), "outside 32..65584"),
        (struct.pack("<HI", 0x1000, 2000), "above 1024 for router message 0x1000 (PORT_CONNECT)"),
        (struct.pack("<HI", 0x4745, 0x2F205445), "0x4745 at stream byte"),  # "GET / HTTP" is not AMS/TCP
        (_ams(44, data_length=40), "announces 40 data bytes, its AMS/TCP length 44 leaves 12"),
    ],
)
def test_undelimitable_frames_break_the_stream_after_the_good_ones(bad: bytes, message: str) -> None:
    good = golden("pyads", "read")[0]
    decoder = AmsStreamDecoder()
    frames = decoder.feed(good.raw + bad)
    assert next(frames) == good.frame()
    with pytest.raises(AmsStreamError, match="cannot be resynchronised; close the connection") as caught:
        next(frames)
    assert message in str(caught.value)
    assert f"stream byte {len(good.raw)}" in str(caught.value)
    assert decoder.broken is not None
    with pytest.raises(AmsStreamError):
        list(decoder.feed(good.raw))  # broken for good


def test_a_huge_length_is_refused_before_its_body_arrives() -> None:
    """Bounded buffering: 6 header bytes are enough to refuse a 4 GiB frame."""
    with pytest.raises(AmsStreamError, match="4294967295"):
        list(AmsStreamDecoder().feed(struct.pack("<HI", 0, 0xFFFFFFFF)))


def test_the_limit_is_configurable_and_holds_exactly() -> None:
    decoder = AmsStreamDecoder(max_ams_length=32 + 12)
    (packet,) = decoder.feed(_ams(44))
    assert isinstance(packet, AmsPacket)
    assert packet.data == bytes(12)
    with pytest.raises(AmsStreamError, match=r"outside 32\.\.44"):
        list(decoder.feed(_ams(45)))


# --------------------------------------------------------------------------------------------
# Payload errors: answerable, carrying the ADS code
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("command", "payload"),
    [
        (CommandId.READ_DEVICE_INFO, b"\0"),
        (CommandId.READ, bytes(11)),
        (CommandId.READ, bytes(13)),
        (CommandId.WRITE, bytes(11)),
        (CommandId.WRITE, struct.pack("<III", 1, 2, 4) + bytes(3)),
        (CommandId.WRITE, struct.pack("<III", 1, 2, 4) + bytes(5)),
        (CommandId.READ_STATE, b"\0\0\0\0"),
        (CommandId.WRITE_CONTROL, bytes(7)),
        (CommandId.WRITE_CONTROL, struct.pack("<HHI", 5, 0, 2)),
        (CommandId.ADD_DEVICE_NOTIFICATION, bytes(39)),
        (CommandId.ADD_DEVICE_NOTIFICATION, bytes(41)),
        (CommandId.DELETE_DEVICE_NOTIFICATION, bytes(3)),
        (CommandId.READ_WRITE, bytes(15)),
        (CommandId.READ_WRITE, struct.pack("<IIII", 0xF003, 0, 4, 13) + b"MAIN.counter"),
    ],
)
def test_a_request_of_the_wrong_size_is_answered_size_wrong(command: CommandId, payload: bytes) -> None:
    with pytest.raises(AdsError) as caught:
        decode_request(command, payload)
    assert caught.value.code == ErrorCode.SIZE_WRONG
    assert command.name in str(caught.value)
    assert "(ADS error 0x705 SIZE_WRONG)" in str(caught.value)


@pytest.mark.parametrize("command", [0, 8, 10, 0xFFFF])
def test_a_command_that_is_no_request_is_answered_service_not_supported(command: int) -> None:
    with pytest.raises(AdsError) as caught:
        decode_request(command, b"")
    assert caught.value.code == ErrorCode.SERVICE_NOT_SUPPORTED
    assert f"ADS command {command}" in str(caught.value)


def test_error_replies_keep_the_fixed_part_of_each_command() -> None:
    """AdsLib waits for 8 bytes from Read and ReadWrite even on error (reference note)."""
    assert error_reply_payload(CommandId.READ, 0x710) == struct.pack("<II", 0x710, 0)
    assert error_reply_payload(CommandId.READ_WRITE, 0x705) == struct.pack("<II", 0x705, 0)
    assert error_reply_payload(CommandId.WRITE, 0x704) == struct.pack("<I", 0x704)
    assert error_reply_payload(CommandId.ADD_DEVICE_NOTIFICATION, 0x713) == struct.pack("<II", 0x713, 0)
    assert decode_response(CommandId.READ, error_reply_payload(CommandId.READ, 0x702)) == ReadResponse(0x702)
    assert decode_response(CommandId.READ_DEVICE_INFO, error_reply_payload(1, 0x701)).result == 0x701
    assert decode_response(CommandId.READ_STATE, error_reply_payload(4, 0x701)).result == 0x701
    assert error_reply_payload(42, 0x701) == struct.pack("<I", 0x701)


def test_an_ams_level_error_travels_in_the_header_with_no_payload() -> None:
    request = golden("pyads", "read")[0].packet()
    reply = list(
        AmsStreamDecoder().feed(encode_error_response(request.header, ErrorCode.TARGET_PORT_NOT_FOUND))
    )
    (packet,) = reply
    assert isinstance(packet, AmsPacket)
    assert packet.data == b""
    assert packet.header.error_code == 0x6
    assert packet.header.target == request.header.source
    assert packet.header.source == request.header.target
    assert packet.header.invoke_id == request.header.invoke_id
    assert packet.header.is_response


def test_a_device_notification_from_the_server_is_a_request_to_the_client() -> None:
    stamps = (NotificationStamp(unix_ns_to_filetime(0), (NotificationSample(7, b"\x01\x02"),)),)
    raw = encode_request(
        PYADS_CLIENT, SERVER, CommandId.DEVICE_NOTIFICATION, 0, DeviceNotification(stamps).encode()
    )
    (packet,) = AmsStreamDecoder().feed(raw)
    assert isinstance(packet, AmsPacket)
    assert packet.header.state_flags == 0x0004
    assert not packet.header.is_response
    assert DeviceNotification.decode(packet.data).stamps == stamps


def test_symbol_names_decode_up_to_the_nul_and_tolerate_odd_bytes() -> None:
    assert decode_name(b"MAIN.counter\0") == "MAIN.counter"
    assert decode_name(b"MAIN.counter") == "MAIN.counter"
    assert decode_name(b"a\0b") == "a"
    assert decode_name(b"\x81x\0") == "\ufffdx"  # not Windows-1252: matches no symbol -> 0x710


def test_net_id_parse_and_format() -> None:
    net_id = NetId.parse("127.0.0.1.1.1")
    assert bytes(net_id) == b"\x7f\0\0\x01\x01\x01"
    assert str(net_id) == "127.0.0.1.1.1"
    assert repr(net_id) == "NetId('127.0.0.1.1.1')"
    assert str(AmsAddress(net_id, 851)) == "127.0.0.1.1.1:851"
    for bad in ("127.0.0.1.1", "127.0.0.1.1.256", "a.b.c.d.e.f", "", "1.2.3.4.5.6.7"):
        with pytest.raises(ValueError, match="is not six numbers"):
            NetId.parse(bad)
    with pytest.raises(ValueError, match="6 octets"):
        NetId(b"\x01\x02")


def test_filetime_conversions() -> None:
    assert datetime_to_filetime(NOTIFIED_AT) == 133_485_408_000_000_000
    assert datetime_to_filetime(NOTIFIED_AT.replace(tzinfo=None)) == 133_485_408_000_000_000  # naive = UTC
    assert filetime_to_datetime(116_444_736_000_000_000) == datetime(1970, 1, 1, tzinfo=UTC)
    assert unix_ns_to_filetime(1_500) == 116_444_736_000_000_015
    assert filetime_to_unix_ns(116_444_736_000_000_015) == 1_500


def test_data_type_entries_for_a_base_type_and_a_simple_struct() -> None:
    lreal = DataTypeEntry.base("LREAL", AdsDataType.REAL64, 8)
    pos = DataTypeEntry.struct(
        "ST_Pos",
        16,
        [
            DataTypeEntry.item("x", "LREAL", AdsDataType.REAL64, 8, 0),
            DataTypeEntry.item("y", "LREAL", AdsDataType.REAL64, 8, 8),
        ],
    )
    upload = lreal.encode() + pos.encode()
    assert decode_data_type_upload(upload) == (lreal, pos)
    raw = pos.encode()
    # the head as ads-client's parseAdsResponseDataType reads it (behind the entry length)
    version, _, _, size, offset, data_type, flags = struct.unpack_from("<7I", raw, 4)
    n_name, n_type, n_comment, dims, n_items = struct.unpack_from("<5H", raw, 32)
    assert (version, size, offset, data_type, flags) == (
        1,
        16,
        0,
        AdsDataType.BIGTYPE,
        DataTypeFlag.DATA_TYPE,
    )
    assert (n_name, n_type, n_comment, dims, n_items) == (6, 0, 0, 0, 2)
    assert raw[42:51] == b"ST_Pos\0\0\0"
    item_length = struct.unpack_from("<I", raw, 51)[0]
    item, end = DataTypeEntry.decode(raw, 51)
    assert end == 51 + item_length
    assert (item.name, item.type_name, item.offset, item.flags) == ("x", "LREAL", 0, DataTypeFlag.DATA_ITEM)


def test_nested_data_types_deeper_than_the_limit_are_refused_not_recursed() -> None:
    entry = DataTypeEntry.base("DINT", AdsDataType.INT32, 4)
    for level in range(40):
        entry = DataTypeEntry.struct(f"T{level}", 4, [entry])
    with pytest.raises(AdsError, match="nested deeper than 32"):
        DataTypeEntry.decode(entry.encode())


def test_upload_info_sizes() -> None:
    assert UploadInfo(3, 300).encode() == struct.pack("<II", 3, 300)
    info = UploadInfo2(3, 300, 2, 200, encoding_code_page=65001, flags=0x6)
    assert len(info.encode()) == 24
    assert len(info.encode(64)) == 64
    assert UploadInfo2.decode(info.encode(64)) == info
    assert UploadInfo2.decode(info.encode()) == UploadInfo2(3, 300, 2, 200)
    with pytest.raises(ValueError, match="24 or 64"):
        info.encode(32)


# --------------------------------------------------------------------------------------------
# Round trips for every message type (hypothesis)
# --------------------------------------------------------------------------------------------

u8 = st.integers(0, 0xFF)
u16 = st.integers(0, 0xFFFF)
u32 = st.integers(0, 0xFFFF_FFFF)
blob = st.binary(max_size=64)
text = st.text(st.characters(codec="cp1252", exclude_characters="\0"), max_size=40)

requests = st.one_of(
    st.builds(ReadDeviceInfoRequest),
    st.builds(ReadRequest, u32, u32, u32),
    st.builds(WriteRequest, u32, u32, blob),
    st.builds(ReadStateRequest),
    st.builds(WriteControlRequest, u16, u16, blob),
    st.builds(AddDeviceNotificationRequest, u32, u32, u32, u32, u32, u32),
    st.builds(DeleteDeviceNotificationRequest, u32),
    st.builds(ReadWriteRequest, u32, u32, u32, blob),
)
responses = st.one_of(
    st.builds(
        ReadDeviceInfoResponse,
        u32,
        u8,
        u8,
        u16,
        st.text(st.characters(codec="ascii", exclude_characters="\0"), max_size=16),
    ),
    st.builds(ReadResponse, u32, blob),
    st.builds(WriteResponse, u32),
    st.builds(ReadStateResponse, u32, u16, u16),
    st.builds(WriteControlResponse, u32),
    st.builds(AddDeviceNotificationResponse, u32, u32),
    st.builds(DeleteDeviceNotificationResponse, u32),
    st.builds(ReadWriteResponse, u32, blob),
)
net_ids = st.binary(min_size=6, max_size=6).map(NetId)
headers = st.builds(AmsHeader, net_ids, u16, net_ids, u16, u16, u16, st.just(0), u32, u32)
arrays = st.lists(st.builds(ArrayInfo, st.integers(-(2**31), 2**31 - 1), u32), max_size=3).map(tuple)
symbols = st.builds(SymbolEntry, u32, u32, u32, u32, text, text, text, u16, arrays, blob)
data_types = st.recursive(
    st.builds(DataTypeEntry, text, text, u32, u32, u32, u32, text, arrays, st.just(()), u32, u32, u32, blob),
    lambda children: st.builds(
        DataTypeEntry, text, text, u32, u32, u32, u32, text, arrays, st.lists(children, max_size=3).map(tuple)
    ),
    max_leaves=8,
)
samples = st.builds(NotificationSample, u32, blob)
stamps = st.builds(NotificationStamp, st.integers(0, 2**64 - 1), st.lists(samples, max_size=4).map(tuple))


@settings(max_examples=300, deadline=None)
@given(requests)
def test_every_request_round_trips(request: Any) -> None:
    assert decode_request(request.command, request.encode()) == request


@settings(max_examples=300, deadline=None)
@given(responses)
def test_every_response_round_trips(response: Any) -> None:
    assert decode_response(response.command, response.encode()) == response


@settings(max_examples=100, deadline=None)
@given(st.lists(stamps, max_size=4).map(tuple))
def test_device_notification_round_trips(stamps_: tuple[NotificationStamp, ...]) -> None:
    assert DeviceNotification.decode(DeviceNotification(stamps_).encode()) == DeviceNotification(stamps_)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(headers, blob), min_size=1, max_size=5), st.integers(1, 50))
def test_ams_frames_round_trip_through_the_stream_decoder(
    packets: list[tuple[AmsHeader, bytes]], chunk: int
) -> None:
    frames = [AmsPacket(header._replace(data_length=len(data)), data) for header, data in packets]
    stream = b"".join(f.to_bytes() for f in frames)
    decoder = AmsStreamDecoder()
    got = [f for i in range(0, len(stream), chunk) for f in decoder.feed(stream[i : i + chunk])]
    assert got == frames


@settings(max_examples=100, deadline=None)
@given(headers, blob, u32)
def test_a_response_swaps_the_addresses_and_echoes_command_and_invoke_id(
    header: AmsHeader, payload: bytes, error: int
) -> None:
    (reply,) = AmsStreamDecoder().feed(encode_response(header, payload, error))
    assert isinstance(reply, AmsPacket)
    assert reply.header.target == header.source
    assert reply.header.source == header.target
    assert (reply.header.command, reply.header.invoke_id) == (header.command, header.invoke_id)
    assert (reply.header.state_flags, reply.header.error_code, reply.data) == (0x0005, error, payload)


@settings(max_examples=200, deadline=None)
@given(st.lists(symbols, max_size=4))
def test_symbol_entries_and_uploads_round_trip(entries: list[SymbolEntry]) -> None:
    assert decode_symbol_upload(b"".join(e.encode() for e in entries)) == tuple(entries)


@settings(max_examples=200, deadline=None)
@given(st.lists(data_types, max_size=3))
def test_data_type_entries_and_uploads_round_trip(entries: list[DataTypeEntry]) -> None:
    assert decode_data_type_upload(b"".join(e.encode() for e in entries)) == tuple(entries)


@settings(max_examples=100, deadline=None)
@given(st.lists(u32, min_size=9, max_size=9))
def test_upload_infos_round_trip(n: list[int]) -> None:
    assert UploadInfo.decode(UploadInfo(n[0], n[1]).encode()) == UploadInfo(n[0], n[1])
    info = UploadInfo2(*n)
    assert UploadInfo2.decode(info.encode(64)) == info
    assert UploadInfo2.decode(info.encode(24)) == UploadInfo2(*n[:6])


@settings(max_examples=100, deadline=None)
@given(st.builds(HandleInfo, u32, u32, text, u32), u32)
def test_handle_replies_round_trip(info: HandleInfo, read_length: int) -> None:
    assert HandleInfo.decode(info.encode()) == info
    reply = encode_handle_reply(read_length, info)
    assert reply == (info.encode() if read_length >= len(info.encode()) else struct.pack("<I", info.handle))


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.tuples(st.builds(SumReadItem, u32, u32, st.integers(0, 16)), u32, blob), max_size=6),
    st.lists(st.tuples(st.builds(SumWriteItem, u32, u32, blob), u32), max_size=6),
    st.lists(st.tuples(st.builds(SumReadWriteItem, u32, u32, u32, blob), u32, blob), max_size=6),
)
def test_sum_commands_round_trip(
    reads: list[tuple[SumReadItem, int, bytes]],
    writes: list[tuple[SumWriteItem, int]],
    read_writes: list[tuple[SumReadWriteItem, int, bytes]],
) -> None:
    sum_read = SumRead(tuple(item for item, _, _ in reads))
    assert SumRead.decode(len(reads), sum_read.encode()) == sum_read
    reply = encode_sum_read_reply(sum_read, [(code, data) for _, code, data in reads])
    assert len(reply) == sum_read.reply_length
    expected = [(code, data[: item.length].ljust(item.length, b"\0")) for item, code, data in reads]
    assert decode_sum_read_reply(sum_read, reply) == expected

    sum_write = SumWrite(tuple(item for item, _ in writes))
    assert SumWrite.decode(len(writes), sum_write.encode()) == sum_write
    codes = [code for _, code in writes]
    assert decode_sum_write_reply(len(codes), encode_sum_write_reply(codes)) == codes

    sum_rw = SumReadWrite(tuple(item for item, _, _ in read_writes))
    assert SumReadWrite.decode(len(read_writes), sum_rw.encode()) == sum_rw
    results = [(code, data) for _, code, data in read_writes]
    assert decode_sum_read_write_reply(len(results), encode_sum_read_write_reply(results)) == results


@settings(max_examples=100, deadline=None)
@given(st.binary(min_size=6, max_size=6))
def test_net_ids_round_trip_through_text(octets: bytes) -> None:
    assert NetId.parse(str(NetId(octets))) == octets


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**63))
def test_filetime_round_trips_through_unix_ns(filetime: int) -> None:
    assert unix_ns_to_filetime(filetime_to_unix_ns(filetime)) == filetime


# --------------------------------------------------------------------------------------------
# Fuzz: random and mutated bytes raise nothing but the codec's own error (bounded, seeded)
# --------------------------------------------------------------------------------------------


def _payload_decoders(data: bytes) -> list[Callable[[], object]]:
    count = data[0] if data else 0
    return [
        *(lambda c=c: decode_request(c, data) for c in range(11)),
        *(lambda c=c: decode_response(c, data) for c in range(11)),
        lambda: DeviceNotification.decode(data),
        lambda: decode_symbol_upload(data),
        lambda: decode_data_type_upload(data),
        lambda: SymbolEntry.decode(data),
        lambda: UploadInfo.decode(data),
        lambda: UploadInfo2.decode(data),
        lambda: HandleInfo.decode(data),
        lambda: SumRead.decode(count, data),
        lambda: SumWrite.decode(count, data),
        lambda: SumReadWrite.decode(count, data),
        lambda: decode_sum_write_reply(count, data),
        lambda: decode_sum_read_write_reply(count, data),
        lambda: decode_name(data),
        lambda: port_of_port_request(AmsTcpFrame(AmsTcpCommand.PORT_CONNECT, data)),
    ]


def _survive(stream_chunks: list[bytes]) -> int:
    """Feed the chunks, decode every frame's payload every way; only AdsCodecError may escape."""
    decoder = AmsStreamDecoder()
    seen = 0
    try:
        for chunk in stream_chunks:
            for frame in decoder.feed(chunk):
                seen += 1
                for decode in _payload_decoders(frame.data):
                    with contextlib.suppress(AdsCodecError):
                        decode()
    except AdsCodecError:
        pass
    return seen


@settings(max_examples=400, deadline=None, derandomize=True)
@given(st.lists(st.binary(max_size=120), max_size=6))
def test_random_bytes_never_raise_anything_else(chunks: list[bytes]) -> None:
    _survive(chunks)


@settings(max_examples=400, deadline=None, derandomize=True)
@given(st.binary(max_size=300))
def test_random_payloads_never_raise_anything_else(data: bytes) -> None:
    for decode in _payload_decoders(data):
        with contextlib.suppress(AdsCodecError):
            decode()


def test_mutated_golden_frames_never_raise_anything_else() -> None:
    rng = random.Random(20240101)
    raws = [g.raw for g in GOLDEN]
    decoded = 0
    for _ in range(3000):
        raw = bytearray(rng.choice(raws))
        for _ in range(rng.randint(1, 4)):
            mutation = rng.randrange(4)
            pos = rng.randrange(len(raw) + 1)
            if mutation == 0 and pos < len(raw):
                raw[pos] = rng.randrange(256)
            elif mutation == 1:
                del raw[pos:]
            elif mutation == 2:
                raw[pos:pos] = rng.randbytes(rng.randint(1, 8))
            elif pos + 4 <= len(raw):
                raw[pos : pos + 4] = struct.pack("<I", rng.choice([0, 1, 0xFF, 0xFFFF, 0xFFFFFFFF, len(raw)]))
        mutated = bytes(raw)
        cut = rng.randrange(len(mutated) + 1)
        decoded += _survive([mutated[:cut], mutated[cut:], rng.choice(raws)])
    assert decoded > 1000  # many mutants still frame: their payloads went through every decoder


# ================================================================================================
# ADS over UDP (issue 22): the bytes pyads sends, decoded
# ================================================================================================


def _pyads_datagram(monkeypatch: pytest.MonkeyPatch, call: Callable[[], Any], reply: bytes) -> bytes:
    """The datagram pyads' own code builds (its socket replaced by a recorder answering ``reply``)."""
    import pyads

    sent: list[bytes] = []

    def record(ip_address: str, message: bytes, expected_return_length: int) -> tuple[bytes, tuple[str, int]]:
        sent.append(message)
        return reply[:expected_return_length], (ip_address, 48899)

    monkeypatch.setattr(pyads.pyads_ex, "send_raw_udp_message", record)
    call()
    (datagram,) = sent
    return datagram


@pytest.mark.req("B-01")
def test_udp_add_route_as_pyads_sends_it_and_our_answers_as_pyads_reads_them(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import pyads

    from hli_server.codecs.ads.udp import AddRouteRequest, UdpService, decode_udp, encode_add_route_reply

    server = NetId.parse("192.168.7.8.1.1")
    ok = encode_add_route_reply(decode_udp(_add_route_bytes()), server, 0)
    refused = encode_add_route_reply(decode_udp(_add_route_bytes()), server, 0x704)
    assert len(ok) == 32  # pyads reads 32 bytes
    results: list[bool] = []
    datagram = _pyads_datagram(
        monkeypatch,
        lambda: results.append(
            pyads.pyads_ex.adsAddRouteToPLC(
                "10.1.2.3.1.1", "10.1.2.3", "192.168.7.8", "Administrator", "1", "route-a"
            )
        ),
        ok,
    )
    assert results == [True]
    message = decode_udp(datagram)
    assert (message.service, str(message.net_id), message.port) == (
        UdpService.ADD_ROUTE,
        "10.1.2.3.1.1",
        10000,
    )
    route = AddRouteRequest.from_message(message)
    assert (route.route_name, str(route.net_id), route.address, route.user, route.password) == (
        "route-a",
        "10.1.2.3.1.1",
        "10.1.2.3",
        "Administrator",
        "1",
    )
    # AdsLib's AddRemoteRoute reads the status tag: 0x704 is what TwinCAT answers wrong credentials
    assert struct.unpack_from("<HHI", refused, 24) == (1, 4, 0x704)


def _add_route_bytes() -> bytes:
    from hli_server.codecs.ads.udp import UdpMessage, UdpService, UdpTag, encode_udp

    tags = ((UdpTag.NET_ID, bytes(NetId.parse("10.1.2.3.1.1"))), (UdpTag.COMPUTER_NAME, b"10.1.2.3\0"))
    return encode_udp(UdpMessage(0, UdpService.ADD_ROUTE, NetId.parse("10.1.2.3.1.1"), 10000, tags))


@pytest.mark.req("B-01")
def test_udp_discovery_as_pyads_sends_it_and_reads_our_answer(monkeypatch: pytest.MonkeyPatch) -> None:
    import pyads

    from hli_server.codecs.ads.udp import (
        UdpService,
        UdpTag,
        decode_udp,
        encode_discovery_reply,
        os_version_tag,
    )

    server = NetId.parse("5.6.7.8.1.1")
    probe = decode_udp(_discovery_bytes())
    reply = encode_discovery_reply(probe, server, "cnc-sim", (3, 1, 4024), os_version_tag(0, 0, 0, 0, "x"))
    found: list[str] = []
    datagram = _pyads_datagram(
        monkeypatch, lambda: found.append(pyads.pyads_ex.adsGetNetIdForPLC("10.0.0.9")), reply
    )
    assert found == ["5.6.7.8.1.1"]
    message = decode_udp(datagram)
    assert (message.service, message.tags, message.port) == (UdpService.SERVER_INFO, (), 10000)
    answer = decode_udp(reply)
    assert answer.tag(UdpTag.COMPUTER_NAME) == b"cnc-sim\0"
    assert answer.tag(UdpTag.TC_VERSION) == bytes([3, 1]) + (4024).to_bytes(2, "little")


def _discovery_bytes() -> bytes:
    from hli_server.codecs.ads.udp import UdpMessage, UdpService, encode_udp

    return encode_udp(UdpMessage(0, UdpService.SERVER_INFO, NetId(b"\x01" * 6), 10000))


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"\x03\x66\x14\x71", "header alone"),
        (b"\x00" * 24, "cookie"),
        (struct.pack("<III6sHI", 0x71146603, 0, 1, bytes(6), 10000, 65), "65 tags"),
        (struct.pack("<III6sHI", 0x71146603, 0, 1, bytes(6), 10000, 1) + b"\x05\x00", "its header runs past"),
        (
            struct.pack("<III6sHIHH", 0x71146603, 0, 1, bytes(6), 10000, 1, 5, 9) + b"abc",
            "runs past the datagram",
        ),
    ],
)
def test_udp_datagrams_that_do_not_parse_say_why(data: bytes, message: str) -> None:
    from hli_server.codecs.ads.udp import decode_udp

    with pytest.raises(AdsCodecError, match=message):
        decode_udp(data)


@pytest.mark.fuzz
def test_fuzz_udp_decoding_raises_only_its_own_error() -> None:
    from hli_server.codecs.ads.udp import AddRouteRequest, decode_udp

    rng = random.Random(seed_for("ads_udp_codec"))
    valid = [_add_route_bytes(), _discovery_bytes()]
    for _ in range(count(20_000)):
        data = bytearray(rng.choice(valid))
        for _ in range(rng.randint(0, 4)):
            if data:
                data[rng.randrange(len(data))] = rng.randrange(256)
        if rng.random() < 0.3:
            data = data[: rng.randrange(len(data) + 1)]
        with contextlib.suppress(AdsCodecError):
            message = decode_udp(bytes(data))
            with contextlib.suppress(AdsCodecError):
                AddRouteRequest.from_message(message)


def test_single_frame_is_the_decoders_shortcut_for_one_request_in_flight() -> None:
    """What ``next_frame`` gives for a read that is exactly one AMS frame, and None for anything else."""
    target, source = (
        AmsAddress(NetId.parse("127.0.0.1.1.1"), 851),
        AmsAddress(NetId.parse("10.1.2.3.1.1"), 30000),
    )
    frame = encode_request(target, source, 2, 7, ReadRequest(0xF020, 4, 4).encode())
    decoder = AmsStreamDecoder()
    packet = decoder.single_frame(frame)
    assert packet == next(AmsStreamDecoder().feed(frame))
    assert decoder.pending == 0
    for other in (frame * 2, frame[:-1], frame + b"\0", encode_router_frame(0x1000, b"\0\0")):
        assert AmsStreamDecoder().single_frame(other) is None
    bad_length = bytearray(frame)
    bad_length[26] ^= 1  # the AMS header's data length disagrees: left to next_frame, which breaks
    assert AmsStreamDecoder().single_frame(bytes(bad_length)) is None
    busy = AmsStreamDecoder()
    busy.receive_data(frame[:10])  # something is buffered: the frame must go through the buffer
    assert busy.single_frame(frame) is None


def test_an_oversize_frame_is_handed_out_as_its_header_and_its_bytes_dropped() -> None:
    """With ``max_skipped_length`` (the server's) an AMS frame above the limit yields its header once 38
    bytes are in, its body is dropped as it arrives however it is split, and the next frame is intact."""
    from hli_server.codecs.ads import NEED_DATA, AmsStreamDecoder, OversizeAmsFrame

    big = encode_request(
        AmsAddress(NetId.parse("1.2.3.4.1.1"), 851), AmsAddress(NetId.parse("5.6.7.8.1.1"), 30000), 9, 7,
        bytes(100_000),
    )  # fmt: skip
    small = encode_request(
        AmsAddress(NetId.parse("1.2.3.4.1.1"), 851), AmsAddress(NetId.parse("5.6.7.8.1.1"), 30000), 2, 8,
        bytes(12),
    )  # fmt: skip
    stream = big + small
    for size in (1, 37, 38, 4096, len(stream)):
        decoder = AmsStreamDecoder(max_skipped_length=1 << 20)
        frames = []
        for k in range(0, len(stream), size):
            frames += list(decoder.feed(stream[k : k + size]))
            assert decoder.pending <= 65_584 + size  # never the whole oversize frame
        assert isinstance(frames[0], OversizeAmsFrame)
        assert frames[0].header.invoke_id == 7
        assert frames[0].length == len(big) - 6
        assert [f.header.invoke_id for f in frames[1:]] == [8]  # type: ignore[union-attr]
        assert decoder.next_frame() is NEED_DATA
    with pytest.raises(AmsStreamError):  # without it (a client's decoder): as before, the stream breaks
        list(AmsStreamDecoder().feed(big))
