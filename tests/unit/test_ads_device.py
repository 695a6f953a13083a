"""The ADS device without sockets: symbols, options, the registry entry, notifications, sums (H-04).

The device (``hli_server/adapters/ads/device.py``) is sans-I/O: frames in, replies out. These tests
feed it frames built with the codec and a real shared-memory image whose CNC->PLC half they publish
themselves; the socket tests are in ``tests/integration/test_ads.py``.
"""

from __future__ import annotations

import os
import struct
import time
from collections.abc import Iterator
from typing import Any

import pytest

from hli_server.adapters.ads import (
    VIEW_GROUP,
    AdsDevice,
    AdsOptions,
    DeviceLimits,
    Session,
    SymbolTable,
    normalize_name,
)
from hli_server.adapters.ads.symbols import MAX_SYMBOL_INFO
from hli_server.adapters.registry import AdapterError, plan_adapters
from hli_server.codecs.ads import (
    AddDeviceNotificationRequest,
    AmsAddress,
    AmsPacket,
    AmsStreamDecoder,
    CommandId,
    DeviceNotification,
    ErrorCode,
    NetId,
    ReadRequest,
    ReadWriteRequest,
    SumRead,
    SumReadItem,
    SymbolEntry,
    WriteRequest,
    decode_response,
    decode_symbol_upload,
    encode_request,
)
from hli_server.configuration import load_machine
from hli_server.image import ProcessImage
from schemas.layout import Direction, Layout, build_layout

pytestmark = pytest.mark.req("H-04")

SERVER = NetId.parse("127.0.0.1.1.1")
CLIENT = AmsAddress(NetId.parse("10.1.2.3.1.1"), 30001)
CMD_LOW = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w"
EN_LOW = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.enable_w"
X_POS = "gpAx[0]^ipo_state.cmd_pos_r"


@pytest.fixture(scope="module")
def layout() -> Layout:
    return build_layout(load_machine(None))


class CountingImage:
    """The image, counting the copies the device takes of the CNC->PLC half."""

    def __init__(self, image: ProcessImage) -> None:
        self._image = image
        self.snapshots = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self._image, name)

    def snapshot(self) -> tuple[int, bytes]:
        self.snapshots += 1
        return self._image.snapshot()


@pytest.fixture
def image(layout: Layout) -> Iterator[ProcessImage]:
    img = ProcessImage.create(layout, name=f"hli_test_adsdev_{os.getpid()}_{time.monotonic_ns() % 10**6}")
    try:
        yield img
    finally:
        img.close()


def publish(image: ProcessImage, cycle: int, **values: Any) -> None:
    layout = image.layout
    image.publish_bytes(layout.pack(Direction.CNC_TO_PLC, values), cycle)


def request(command: int, payload: bytes, port: int = 851, invoke: int = 1) -> AmsPacket:
    frame = encode_request(AmsAddress(SERVER, port), CLIENT, command, invoke, payload)
    (packet,) = list(AmsStreamDecoder().feed(frame))
    assert isinstance(packet, AmsPacket)
    return packet


def answer(device: AdsDevice, session: Session, command: int, payload: bytes, port: int = 851) -> Any:
    reply = device.handle(session, request(command, payload, port))
    assert reply is not None
    (packet,) = list(AmsStreamDecoder().feed(reply))
    assert isinstance(packet, AmsPacket)
    if packet.header.error_code:
        return packet.header.error_code
    return decode_response(command, packet.data)


# ================================================================================================
# Symbols
# ================================================================================================


@pytest.mark.parametrize(
    "spelling",
    [
        "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w",
        "gpAx[0]^.ipo_mc_control.dyn_pos_limit_high.command_w",
        "gpAx[0].ipo_mc_control.dyn_pos_limit_high.command_w",
        "  GPAX[0].IPO_MC_CONTROL.DYN_POS_LIMIT_HIGH.COMMAND_W ",
    ],
)
def test_every_spelling_of_a_symbol_finds_it(layout: Layout, spelling: str) -> None:
    found = SymbolTable(layout).find(spelling)
    assert found is not None
    assert found.signal.st_path == "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w"


def test_names_that_are_no_symbol(layout: Layout) -> None:
    table = SymbolTable(layout)
    for name in (
        "gpAx[0]ipo_state.cmd_pos_r",
        "gpAx[9]^ipo_state.cmd_pos_r",
        "gpAx[0]^^ipo_state.cmd_pos_r",
        "",
    ):
        assert table.find(name) is None, name
    assert normalize_name("MAIN.counter") == "main.counter"  # only the gpCh/gpAx dereference is rewritten


def test_symbol_upload_lists_the_top_level_and_every_entry_fits_pyads_read(layout: Layout) -> None:
    """As TwinCAT's: the upload holds the top-level symbols; their members are in the types (0xF00E)."""
    table = SymbolTable(layout)
    entries = decode_symbol_upload(table.upload)
    n_ch, n_ax = len(layout.channels), len(layout.axes)
    assert [(e.name, e.index_group, e.type_name) for e in entries] == [
        ("gpCh", VIEW_GROUP, f"ARRAY [0..{n_ch - 1}] OF HLI_CH"),
        ("gpAx", VIEW_GROUP, f"ARRAY [0..{n_ax - 1}] OF HLI_AX"),
        ("gpVEGlob", VIEW_GROUP, "HLI_VEGLOB"),  # the demo machine's global V.E. variables (N-05)
    ]
    for s in layout.signals:  # every leaf by name, at its place in the image
        symbol = table.find(s.st_path)
        assert symbol is not None
        info = SymbolEntry.decode(symbol.entry)[0]
        assert (info.name, info.index_group, info.index_offset, info.size, info.type_name) == (
            s.st_path,
            s.image_ads_group,
            s.offset,
            s.size,
            s.type.value,
        )
    assert max(len(symbol.entry) for symbol in table.all_symbols()) <= MAX_SYMBOL_INFO
    assert struct.unpack("<II", table.upload_info) == (len(entries), len(table.upload))


# ================================================================================================
# Options and the registry
# ================================================================================================


def test_allowlist_entries() -> None:
    allow = AdsOptions(allow="loopback 10.0.0.0/8;192.168.1.50.1.1").allowlist()
    assert allow.allows_ip("127.0.0.5")
    assert allow.allows_ip("::1")
    assert allow.allows_ip("10.4.5.6")
    assert not allow.allows_ip("192.168.1.50")
    assert allow.allows_net_id(bytes(NetId.parse("192.168.1.50.1.1")))
    assert not allow.allows_net_id(bytes(NetId.parse("192.168.1.51.1.1")))
    everybody = AdsOptions(allow=[]).allowlist()
    assert everybody.allows_ip("203.0.113.9")
    assert everybody.allows_net_id(b"\x01" * 6)
    only_net_ids = AdsOptions(allow=["5.6.7.8.1.1"]).allowlist()
    assert only_net_ids.allows_ip("203.0.113.9")  # no IP entries: any peer, but only that NetId
    assert AdsOptions().allowlist().allows_ip("127.0.0.1")
    assert not AdsOptions().allowlist().allows_ip("192.0.2.1")  # default: loopback only


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"allow": "example.org"}, "neither an AMS NetId"),
        ({"ams_net_id": "127.0.0.1"}, "six numbers"),
        ({"port": 70000}, "less than or equal to 65535"),
    ],
)
def test_bad_options_say_what_is_wrong(options: dict[str, Any], message: str) -> None:
    with pytest.raises(AdapterError, match=message):
        plan_adapters([("ads", options)])


def test_ads_is_planned_by_flag_by_spec_and_by_machine_file() -> None:
    assert "ads" not in dict(plan_adapters())  # not started unless asked for
    by_flag = dict(plan_adapters(aliases={"--ads-port": 0, "--ams-net-id": "10.0.0.1.1.1"}))
    assert (by_flag["ads"]["port"], by_flag["ads"]["ams_net_id"]) == (0, "10.0.0.1.1.1")
    assert dict(plan_adapters(specs=["ads"]))["ads"]["port"] == 48898
    configured = dict(plan_adapters([("ads", {"port": 1234, "allow": "loopback 10.1.2.3.1.1"})]))
    assert configured["ads"]["allow"] == ["loopback", "10.1.2.3.1.1"]


# ================================================================================================
# The device
# ================================================================================================


def make_device(image: Any, **limits: Any) -> AdsDevice:
    return AdsDevice(image, SERVER, t_a_us=1000, limits=DeviceLimits(**limits))


def test_a_refused_raw_write_changes_nothing(image: ProcessImage, layout: Layout) -> None:
    device, session = make_device(image), Session()
    cmd, en = layout.signal(CMD_LOW), layout.signal(EN_LOW)
    assert cmd.offset == en.offset + 4  # enable_w (BOOL, 3 bytes of padding), then command_w (DINT)
    before = image.read_half(Direction.PLC_TO_CNC)
    data = b"\x02\x00\x00\x00" + struct.pack("<i", 1234)  # a BOOL byte of 2, then a valid DINT
    reply = answer(device, session, CommandId.WRITE, WriteRequest(0xF030, en.offset, data).encode())
    assert reply.result == ErrorCode.INVALID_VALUE
    assert image.read_half(Direction.PLC_TO_CNC) == before
    ok = answer(
        device, session, CommandId.WRITE, WriteRequest(0xF030, en.offset, b"\x01" + data[1:]).encode()
    )
    assert ok.result == 0
    assert (image.read(CMD_LOW), image.read(EN_LOW)) == (1234, True)


def test_sum_read_answers_each_sub_read(image: ProcessImage, layout: Layout) -> None:
    publish(image, 3, **{X_POS: -42})
    device, session = make_device(image, max_sum_items=3), Session()
    x = layout.signal(X_POS)
    items = (SumReadItem(0xF020, x.offset, 4), SumReadItem(0x4020, 0, 4), SumReadItem(0xF020, 1 << 20, 2))
    sub = SumRead(items)
    reply = answer(
        device,
        session,
        CommandId.READ_WRITE,
        ReadWriteRequest(0xF080, 3, sub.reply_length, sub.encode()).encode(),
    )
    assert reply.result == 0
    codes = struct.unpack_from("<3I", reply.data)
    assert codes == (0, 0x702, 0x703)
    assert struct.unpack_from("<i", reply.data, 12)[0] == -42
    too_many = SumRead(items + items[:1])
    reply = answer(
        device,
        session,
        CommandId.READ_WRITE,
        ReadWriteRequest(0xF080, 4, too_many.reply_length, too_many.encode()).encode(),
    )
    assert reply.result == ErrorCode.SIZE_WRONG


def add(device: AdsDevice, session: Session, payload: AddDeviceNotificationRequest, port: int = 851) -> Any:
    return answer(device, session, CommandId.ADD_DEVICE_NOTIFICATION, payload.encode(), port)


def samples(session: Session) -> list[tuple[AmsPacket, DeviceNotification]]:
    out = []
    for frame in session.sent:
        (packet,) = list(AmsStreamDecoder().feed(frame))
        assert isinstance(packet, AmsPacket)
        out.append((packet, DeviceNotification.decode(packet.data)))
    session.sent.clear()
    return out


def test_notification_samples_come_from_the_address_subscribed_to(
    image: ProcessImage, layout: Layout
) -> None:
    publish(image, 0, **{"gpAx[4]^dyn_coll_mon.coll_offset": 200_000})
    device, session = make_device(image), Session()
    reply = add(
        device, session, AddDeviceNotificationRequest(0x120300, (5 << 16) | 0x0246, 4, 4, 0, 0), port=551
    )
    assert reply.result == 0
    session.flush()  # without a loop, queued samples go out when flushed
    ((packet, notification),) = samples(session)  # the first sample
    assert packet.header.command == CommandId.DEVICE_NOTIFICATION
    assert packet.header.state_flags == 0x0004
    assert (packet.header.source_net_id, packet.header.source_port) == (
        SERVER,
        551,
    )  # AdsLib dispatches by it
    assert (packet.header.target_net_id, packet.header.target_port) == CLIENT
    ((sample,),) = [stamp.samples for stamp in notification.stamps]
    assert (sample.handle, struct.unpack("<I", sample.data)[0]) == (reply.handle, 200_000)


def test_the_cycle_takes_one_copy_per_cycle_and_only_when_something_is_due(
    image: ProcessImage, layout: Layout
) -> None:
    counting = CountingImage(image)
    device = make_device(
        counting, max_notifications=600, max_notifications_per_net_id=600, max_notifications_total=600
    )
    x = layout.signal(X_POS)
    for cycle in range(1, 4):
        device.on_cycle(cycle)
    assert counting.snapshots == 0  # no notification: the cycle callback returns at once
    sessions = [Session() for _ in range(3)]
    for session in sessions:
        for _ in range(200):  # on change, checked every cycle (cycle time 0)
            assert (
                add(device, session, AddDeviceNotificationRequest(0xF020, x.offset, 4, 4, 0, 0)).result == 0
            )
        session.flush()  # the first samples
        session.sent.clear()
    counting.snapshots = 0
    for cycle in range(4, 14):
        publish(image, cycle, **{X_POS: cycle * 10})
        device.on_cycle(cycle)
        for session in sessions:
            session.flush()
    assert counting.snapshots == 10  # one copy per cycle for 600 notifications
    got = samples(sessions[0])
    assert len(got) == 10  # one frame per cycle per connection, 200 samples in it
    assert [sum(len(s.samples) for s in n.stamps) for _, n in got] == [200] * 10


def test_a_client_that_does_not_read_is_skipped_and_gets_the_newest_value_after(
    image: ProcessImage, layout: Layout
) -> None:
    device = make_device(image)
    full = [False]
    session = Session(backlogged=lambda: full[0])
    x = layout.signal(X_POS)
    add(device, session, AddDeviceNotificationRequest(0xF020, x.offset, 4, 4, 0, 0))
    session.flush()
    session.sent.clear()
    full[0] = True
    for cycle in range(1, 6):
        publish(image, cycle, **{X_POS: cycle})
        device.on_cycle(cycle)
    assert session.sent == []
    assert not session.has_pending
    assert device.stats.samples_skipped == 5
    full[0] = False
    device.on_cycle(6)  # cycle 5's publish is the newest
    session.flush()
    ((_, notification),) = samples(session)
    assert struct.unpack("<i", notification.stamps[0].samples[0].data)[0] == 5


def test_cycle_time_in_100ns_becomes_whole_cycles(image: ProcessImage, layout: Layout) -> None:
    device, session = make_device(image), Session()
    x = layout.signal(X_POS)
    add(device, session, AddDeviceNotificationRequest(0xF020, x.offset, 4, 3, 0, 100_000))  # cyclic 10 ms
    session.flush()
    session.sent.clear()
    for cycle in range(1, 31):
        device.on_cycle(cycle)
        session.flush()
    assert len(samples(session)) == 3  # cycles 10, 20, 30


def test_notification_refusals(image: ProcessImage, layout: Layout) -> None:
    device = make_device(image, max_notifications=2, max_notifications_total=3)
    x = layout.signal(X_POS)
    one, two = Session(), Session()
    watch = AddDeviceNotificationRequest(0xF020, x.offset, 4, 4, 0, 0)
    assert add(device, one, AddDeviceNotificationRequest(0xF020, x.offset, 4, 1, 0, 0)).result == 0x713
    assert add(device, one, AddDeviceNotificationRequest(0xF020, x.offset, 0, 4, 0, 0)).result == 0x705
    assert add(device, one, AddDeviceNotificationRequest(0x4020, 0, 4, 4, 0, 0)).result == 0x702
    handles = [add(device, one, watch).handle for _ in range(2)]
    assert len(set(handles)) == 2
    assert add(device, one, watch).result == 0x716  # max_notifications
    assert add(device, two, watch).result == 0
    assert add(device, two, watch).result == 0x716  # max_notifications_total
    delete = struct.pack("<I", 0xDEAD)
    assert answer(device, one, CommandId.DELETE_DEVICE_NOTIFICATION, delete).result == 0x714
    device.close_session(one)
    assert device.notification_count == 1
    assert add(device, two, watch).result == 0


def test_samples_queued_between_two_turns_of_the_loop_are_bounded(
    image: ProcessImage, layout: Layout
) -> None:
    """A long ``step(n)`` runs many cycles before the loop turns and the samples are written."""
    from hli_server.adapters.ads.device import MAX_PENDING_SAMPLES

    device, session = make_device(image), Session()
    x = layout.signal(X_POS)
    add(device, session, AddDeviceNotificationRequest(0xF020, x.offset, 4, 3, 0, 0))  # cyclic, every cycle
    for cycle in range(1, MAX_PENDING_SAMPLES + 100):
        device.on_cycle(cycle)
    assert session.pending_samples == MAX_PENDING_SAMPLES
    assert device.stats.samples_skipped > 0
    session.flush()
    assert session.pending_samples == 0
    device.on_cycle(MAX_PENDING_SAMPLES + 100)
    assert session.pending_samples == 1


def test_upload_infos_data_types_and_symbol_version(image: ProcessImage, layout: Layout) -> None:
    from hli_server.codecs.ads import UploadInfo2, decode_data_type_upload

    device, session = make_device(image), Session()
    info24 = answer(device, session, CommandId.READ, ReadRequest(0xF00F, 0, 24).encode())
    info64 = answer(device, session, CommandId.READ, ReadRequest(0xF00F, 0, 64).encode())
    assert (len(info24.data), len(info64.data)) == (24, 64)  # ads-client asks 64, older clients 24
    info = UploadInfo2.decode(info64.data)
    assert info.symbol_count == 3  # gpCh, gpAx, gpVEGlob (the demo machine's V.E. variables)
    types = answer(device, session, CommandId.READ, ReadRequest(0xF00E, 0, info.data_type_length).encode())
    names = [t.name for t in decode_data_type_upload(types.data)]
    assert names[:4] == ["BOOL", "DINT", "UDINT", "LREAL"]
    assert {"MC_CONTROL_BOOL_UNIT", "MC_CONTROL_SGN32_UNIT", "HLI_AX", "HLI_CH"} <= set(names)
    assert len(names) == info.data_type_count
    dint = answer(
        device, session, CommandId.READ_WRITE, ReadWriteRequest(0xF011, 0, 0xFFFF, b"dint\0").encode()
    )
    assert (dint.result, decode_data_type_upload(dint.data)[0].size) == (0, 4)
    unknown = ReadWriteRequest(0xF011, 0, 0xFFFF, b"ST_Axis\0").encode()
    assert answer(device, session, CommandId.READ_WRITE, unknown).result == 0x710
    version = answer(device, session, CommandId.READ, ReadRequest(0xF008, 0, 1).encode())
    assert version.data == b"\x01"
    short = answer(device, session, CommandId.READ, ReadRequest(0xF00C, 0, 4).encode())
    assert short.result == 0x705  # the 8-byte upload info does not fit a 4-byte read


# ================================================================================================
# Structures and arrays (issue 22)
# ================================================================================================

UNIT_LOW = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low"
STATE_LOW = f"{UNIT_LOW}.state_r"


@pytest.mark.req("B-01")
def test_control_units_are_their_kernel_structures(layout: Layout) -> None:
    """FCT-C43 3.1.1: dyn_pos_limit_low is an MC_CONTROL_SGN32_UNIT, members in the kernel's order."""
    from hli_server.codecs.ads import DataTypeEntry

    table = SymbolTable(layout)
    unit = table.find(UNIT_LOW)
    assert unit is not None
    assert (unit.type_name, unit.size, unit.index_group, unit.signal) == (
        "MC_CONTROL_SGN32_UNIT",
        13,
        VIEW_GROUP,
        None,
    )
    entry = table.data_type("mc_control_sgn32_unit")
    assert entry is not None
    decoded, _ = DataTypeEntry.decode(entry)
    assert [(i.name, i.type_name, i.offset, i.size) for i in decoded.sub_items] == [
        ("request_r", "DINT", 0, 4),
        ("enable_w", "BOOL", 4, 1),
        ("command_w", "DINT", 5, 4),
        ("state_r", "DINT", 9, 4),
    ]
    feedhold = table.find("gpCh[0]^bahn_mc_control.feedhold")
    assert feedhold is not None
    assert (feedhold.type_name, feedhold.size) == ("MC_CONTROL_BOOL_UNIT", 4)
    axes = table.find("gpAx")
    assert axes is not None
    assert axes.type_name == f"ARRAY [0..{len(layout.axes) - 1}] OF HLI_AX"
    array = table.data_type("ARRAY [0..5]  OF  hli_ax")  # spaces and case as a client may send them
    assert array is not None
    decoded, _ = DataTypeEntry.decode(array)
    assert (decoded.type_name, decoded.array_dims[0].lower_bound, decoded.array_dims[0].elements) == (
        "HLI_AX",
        0,
        6,
    )
    assert table.find("gpAx[0]") is table.find("gpAx[0]^")  # the pointer and what it points to


@pytest.mark.req("B-01")
def test_a_structure_is_read_from_both_halves(image: ProcessImage, layout: Layout) -> None:
    device, session = make_device(image), Session()
    image.write(CMD_LOW, -1234)
    image.write(EN_LOW, True)
    publish(image, 3, **{STATE_LOW: 2})
    unit = device.symbols.find(UNIT_LOW)
    assert unit is not None
    raw = answer(device, session, CommandId.READ, ReadRequest(VIEW_GROUP, unit.index_offset, 13).encode())
    assert raw.result == 0
    assert struct.unpack("<i?ii", raw.data) == (0, True, -1234, 2)  # pack mode 1, as pyads reads it
    by_name = answer(
        device, session, CommandId.READ_WRITE, ReadWriteRequest(0xF004, 0, 13, UNIT_LOW.encode()).encode()
    )
    assert by_name.data == raw.data


@pytest.mark.req("B-01")
def test_a_whole_structure_write_sets_the_w_members_and_leaves_the_r_members_to_the_cnc(
    image: ProcessImage, layout: Layout
) -> None:
    device, session = make_device(image), Session()
    publish(image, 3, **{STATE_LOW: 2})
    unit = device.symbols.find(UNIT_LOW)
    assert unit is not None
    write = WriteRequest(VIEW_GROUP, unit.index_offset, struct.pack("<i?ii", 77, True, 300_000, 99)).encode()
    assert answer(device, session, CommandId.WRITE, write).result == 0
    assert (image.read(CMD_LOW), image.read(EN_LOW)) == (300_000, True)
    assert image.read(STATE_LOW) == 2  # the CNC's value: the written 99 is ignored
    # by handle, as pyads' write_structure_by_name does
    handle = answer(
        device, session, CommandId.READ_WRITE, ReadWriteRequest(0xF003, 0, 4, UNIT_LOW.encode()).encode()
    )
    h = struct.unpack("<I", handle.data)[0]
    by_handle = WriteRequest(0xF005, h, struct.pack("<i?ii", 0, False, -5, 0)).encode()
    assert answer(device, session, CommandId.WRITE, by_handle).result == 0
    assert (image.read(CMD_LOW), image.read(EN_LOW)) == (-5, False)


@pytest.mark.req("B-01")
def test_structure_writes_that_cannot_be_taken_change_nothing(image: ProcessImage, layout: Layout) -> None:
    device, session = make_device(image), Session()
    unit = device.symbols.find(UNIT_LOW)
    state = device.symbols.find("gpAx[0]^ipo_state")
    assert unit is not None
    assert state is not None
    before = image.read_half(Direction.PLC_TO_CNC)
    cases = [
        (
            unit.index_offset,
            struct.pack("<i?ii", 0, True, 1, 0)[:12],
            ErrorCode.SIZE_WRONG,
        ),  # ends in a field
        (unit.index_offset + 1, bytes(4), ErrorCode.INVALID_INDEX_OFFSET),  # starts inside request_r
        (unit.index_offset, struct.pack("<iBii", 0, 2, 1, 0), ErrorCode.INVALID_VALUE),  # a BOOL byte of 2
        (state.index_offset, bytes(state.size), ErrorCode.READ_WRITE_NOT_PERMITTED),  # only _r members
    ]
    for offset, data, code in cases:
        reply = answer(device, session, CommandId.WRITE, WriteRequest(VIEW_GROUP, offset, data).encode())
        assert reply.result == code, (offset, data)
    assert image.read_half(Direction.PLC_TO_CNC) == before
    read_only = AdsDevice(image, SERVER, read_only=True)
    write = WriteRequest(VIEW_GROUP, unit.index_offset, struct.pack("<i?ii", 0, True, 1, 0)).encode()
    assert answer(read_only, session, CommandId.WRITE, write).result == ErrorCode.READ_WRITE_NOT_PERMITTED
    assert image.read_half(Direction.PLC_TO_CNC) == before


@pytest.mark.req("B-01")
def test_a_notification_on_a_structure_sends_the_whole_structure(image: ProcessImage, layout: Layout) -> None:
    device, session = make_device(image), Session()
    unit = device.symbols.find(UNIT_LOW)
    assert unit is not None
    reply = add(device, session, AddDeviceNotificationRequest(VIEW_GROUP, unit.index_offset, 13, 4, 0, 0))
    assert reply.result == 0
    session.flush()
    samples(session)
    publish(image, 1, **{STATE_LOW: 3})  # a _r member changes: the structure changed
    device.on_cycle(1)
    session.flush()
    ((_, notification),) = samples(session)
    assert struct.unpack("<i?ii", notification.stamps[0].samples[0].data) == (0, False, 0, 3)


def _extended_layout(base: Layout) -> Layout:
    """The demo layout and signals a later layout may add (V.E. variables): a global table of four DINTs
    and a flag, and a variable only channel 1 has."""
    from dataclasses import replace

    from schemas.layout import Layout as LayoutClass

    p2c, c2p = Direction.PLC_TO_CNC, Direction.CNC_TO_PLC
    dint_w = base.signal(CMD_LOW)
    dint_r = base.signal(X_POS)
    sizes = {p2c: base.size(p2c), c2p: base.size(c2p)}
    extra = []
    address = 60_000
    for path, template in [
        *((f"gVE.table[{i}]", dint_w) for i in range(4)),
        ("gVE.flag", base.signal(EN_LOW)),
        ("gpCh[0]^v_e.counter", dint_r),
    ]:
        d = template.direction
        offset = -(-sizes[d] // template.size) * template.size
        sizes[d] = offset + template.size
        extra.append(
            replace(
                template, name=path, st_path=path, offset=offset, modbus_address=address, ads_offset=offset
            )
        )
        address += 4
    return LayoutClass(
        machine="extended",
        channels=base.channels,
        axes=base.axes,
        signals=[*base.signals, *extra],
        sizes=sizes,
    )


@pytest.mark.req("B-01")
def test_signals_a_later_layout_adds_become_symbols_and_members_without_a_change(
    image: ProcessImage, layout: Layout
) -> None:
    """The tree is read off the ST paths: V.E. variables (another issue) appear as every other signal."""
    from hli_server.codecs.ads import DataTypeEntry

    table = SymbolTable(_extended_layout(layout))
    names = [(s.name, s.type_name) for s in table.symbols]
    # channel 1 has a member channel 2 lacks: they are no array any more, each is a symbol of its own
    assert ("gpCh[0]", "HLI_CH") in names
    assert ("gpCh[1]", "HLI_CH_2") in names
    assert ("gVE", "HLI_VE") in names
    ve_table = table.find("gve.TABLE")
    assert ve_table is not None
    assert (ve_table.type_name, ve_table.size) == ("ARRAY [0..3] OF DINT", 16)
    element = table.find("gVE.table[2]")
    assert element is not None
    assert element.signal is not None
    assert element.signal.st_path == "gVE.table[2]"
    entry = table.data_type("HLI_VE")
    assert entry is not None
    assert [i.name for i in DataTypeEntry.decode(entry)[0].sub_items] == ["table", "flag"]
    counter = table.find("gpCh[0]^v_e.counter")
    assert counter is not None
    assert counter.index_group == 0xF020


@pytest.mark.req("B-01")
def test_port_10000_answers_as_the_twincat_system_service(image: ProcessImage) -> None:
    """What Node ads-client reads first with its defaults (extended state, 0xF0) and what TwinCAT asks."""
    device, session = make_device(image), Session()
    state = answer(device, session, CommandId.READ_STATE, b"", port=10000)
    assert (state.result, state.ads_state, state.device_state) == (0, 5, 0)
    info = answer(device, session, CommandId.READ_DEVICE_INFO, b"", port=10000)
    assert (info.name, info.major, info.minor, info.build) == ("TwinCAT System", 3, 1, 4024)
    extended = answer(device, session, CommandId.READ, ReadRequest(0xF0, 0, 16).encode(), port=10000)
    ads_state, _dev, restart, major, minor, build = struct.unpack_from("<HHHBBH", extended.data)
    assert (extended.result, len(extended.data), ads_state, major, minor, build) == (0, 16, 5, 3, 1, 4024)
    assert restart == device.system.restart_index
    unknown = answer(device, session, CommandId.READ, ReadRequest(0xF020, 0, 4).encode(), port=10000)
    assert unknown.result == ErrorCode.INVALID_INDEX_GROUP
    assert answer(device, session, CommandId.READ_STATE, b"", port=852) == ErrorCode.TARGET_PORT_NOT_FOUND


def test_the_dispatch_tables_answer_every_command_and_refuse_from_the_tables(image: ProcessImage) -> None:
    from hli_server.adapters.ads.device import COMMANDS

    device, session = make_device(image), Session()
    assert set(COMMANDS) == {1, 2, 3, 4, 5, 6, 7, 9}
    assert all(callable(getattr(device, method)) for method in COMMANDS.values())
    for command in (0, 8, 10, 0xFFFF):  # no request: 0x701
        reply = device.handle(session, request(command, b""))
        assert reply is not None
        assert struct.unpack_from("<I", reply, 38)[0] == 0x701
    # a group the port serves with another command: 0x701; one it does not know: 0x702
    assert answer(device, session, CommandId.READ, ReadRequest(0xF003, 0, 4).encode()).result == 0x701
    assert answer(device, session, CommandId.WRITE, WriteRequest(0xF009, 0, b"x").encode()).result == 0x701
    assert (
        answer(device, session, CommandId.READ_WRITE, ReadWriteRequest(0xF020, 0, 4, b"").encode()).result
        == 0x701
    )
    assert answer(device, session, CommandId.READ, ReadRequest(0x1234, 0, 4).encode()).result == 0x702
    assert (
        answer(device, session, CommandId.WRITE, WriteRequest(0x120300, 0, b"x").encode(), port=551).result
        == 0x704
    )


@pytest.mark.req("B-01")
def test_max_delay_batches_samples_of_several_cycles_in_one_frame(
    image: ProcessImage, layout: Layout
) -> None:
    """TwinCAT's nMaxDelay: samples of several cycles go out in one DeviceNotification, a stamp each."""
    timers: list[tuple[float, Any]] = []
    device = AdsDevice(image, SERVER, call_later=lambda delay, fn: timers.append((delay, fn)))
    session = Session()
    x = layout.signal(X_POS)
    # cyclic every cycle, max delay 5 ms (in 100 ns)
    add(device, session, AddDeviceNotificationRequest(0xF020, x.offset, 4, 3, 50_000, 0))
    delay, first = timers.pop(0)  # the first sample follows the add response
    first()
    session.flush()
    samples(session)
    for cycle in range(1, 4):
        publish(image, cycle, **{X_POS: cycle})
        device.on_cycle(cycle)
    assert session.pending_samples == 3
    assert session.sent == []  # held
    ((delay, send),) = timers
    assert delay == pytest.approx(0.005)
    send()
    session.flush()
    ((_, notification),) = samples(session)
    assert [struct.unpack("<i", s.samples[0].data)[0] for s in notification.stamps] == [1, 2, 3]


def test_a_deleted_notification_sends_nothing_more_and_per_host_budgets(
    image: ProcessImage, layout: Layout
) -> None:
    device = make_device(image, max_notifications_per_host=2)
    x = layout.signal(X_POS)
    remote, local = Session(remote_host="192.0.2.7"), Session()
    watch = AddDeviceNotificationRequest(0xF020, x.offset, 4, 3, 0, 0)
    handles = [add(device, remote, watch).handle for _ in range(2)]
    assert add(device, remote, watch).result == 0x716  # max_notifications_per_host
    assert [add(device, local, watch).result for _ in range(3)] == [0, 0, 0]  # loopback: not per host
    remote.flush()
    samples(remote)
    device.on_cycle(1)  # both queued
    answer(device, remote, CommandId.DELETE_DEVICE_NOTIFICATION, struct.pack("<I", handles[0]))
    remote.flush()
    ((_, notification),) = samples(remote)
    assert [s.handle for st in notification.stamps for s in st.samples] == [handles[1]]


@pytest.mark.req("B-01")
def test_routes_admit_their_net_id_from_their_address_and_survive_in_their_file(tmp_path: Any) -> None:
    from hli_server.adapters.ads import Routes

    file = tmp_path / "sub" / "routes.json"
    allow = AdsOptions(allow="loopback 192.168.1.50.1.1").allowlist()
    routes = Routes(allow, bytes(SERVER), str(file), max_routes=2)
    remote = NetId.parse("10.1.1.1.1.1")
    assert not routes.admits_ip("192.0.2.10")
    routes.add("pc", remote, "pc.example", frozenset({"192.0.2.10"}))
    assert routes.admits_ip("192.0.2.10")
    assert routes.admits(bytes(remote), "::ffff:192.0.2.10")
    assert not routes.admits(bytes(remote), "192.0.2.11")  # its NetId from elsewhere
    assert not routes.admits(bytes(NetId.parse("10.1.1.2.1.1")), "192.0.2.10")  # another NetId from there
    assert routes.admits(bytes(NetId.parse("192.168.1.50.1.1")), "127.0.0.1")  # the allowlist still counts
    routes.add("pc2", remote, "192.0.2.20", frozenset({"192.0.2.20"}))  # the same NetId: replaced
    assert len(routes) == 1
    assert not routes.admits_ip("192.0.2.10")
    routes.add("b", NetId.parse("10.2.2.2.1.1"), "192.0.2.30", frozenset({"192.0.2.30"}))
    with pytest.raises(ValueError, match="max_routes"):
        routes.add("c", NetId.parse("10.3.3.3.1.1"), "192.0.2.40", frozenset({"192.0.2.40"}))
    again = Routes(allow, bytes(SERVER), str(file))
    assert [(r.name, str(r.net_id), sorted(r.ips)) for r in again.routes] == [
        ("pc2", "10.1.1.1.1.1", ["192.0.2.20"]),
        ("b", "10.2.2.2.1.1", ["192.0.2.30"]),
    ]
    # router messages: answered unless the allowlist names NetIds and not the server's
    assert not routes.answers_router_messages("127.0.0.1")
    assert Routes(AdsOptions(allow="loopback").allowlist(), bytes(SERVER)).answers_router_messages(
        "127.0.0.1"
    )
    assert Routes(AdsOptions(allow=[str(SERVER)]).allowlist(), bytes(SERVER)).answers_router_messages(
        "127.0.0.1"
    )


def test_the_kernels_type_names_are_served_as_their_iec_names() -> None:
    """A V.E. variable of the kernel's type SGN16 is an INT symbol for ADS clients (and pyads' types)."""
    from hli_server.adapters.ads.symbols import ads_data_type
    from hli_server.codecs.ads import AdsDataType, ads_type_name

    assert [ads_type_name(n) for n in ("BOOLEAN", "SGN08", "UNS16", "SGN32", "REAL64", "dint")] == [
        "BOOL",
        "SINT",
        "UINT",
        "DINT",
        "LREAL",
        "DINT",
    ]
    assert ads_data_type("SGN16") == (AdsDataType.INT16, 2)
    assert ads_data_type("REAL32") == (AdsDataType.REAL32, 4)
    assert ads_data_type("STRING(80)") == (AdsDataType.STRING, 81)  # a V.E. STRING (issue 33)
    assert ads_data_type("string(20)") == (AdsDataType.STRING, 21)
    with pytest.raises(ValueError, match="no IEC base type"):
        ads_data_type("WSTRING(80)")


# ================================================================================================
# The fast path of one frame (AdsDevice.handle_frame, issue 22 item 5)
# ================================================================================================


def _fast_cases(layout: Layout) -> list[bytes]:
    c2p = layout.signal(X_POS)
    p2c = layout.signal(CMD_LOW)
    get_handle = ReadWriteRequest(0xF003, 0, 4, X_POS.encode() + b"\0").encode()
    frames = [
        ReadRequest(c2p.image_ads_group, c2p.offset, 4).encode(),
        ReadRequest(c2p.image_ads_group, 10**6, 4).encode(),  # beyond the half: 0x703
        ReadRequest(c2p.image_ads_group, c2p.offset, 10**6).encode(),  # past its end: 0x705
        ReadRequest(0x1234, 0, 4).encode(),  # no such group
        WriteRequest(p2c.image_ads_group, p2c.offset, struct.pack("<i", 1234)).encode(),
        WriteRequest(p2c.image_ads_group, p2c.offset, b"\x01").encode(),  # wrong size
        get_handle,
        ReadWriteRequest(0xF003, 0, 4, b"no.such.symbol\0").encode(),
    ]
    out = [encode_request(AmsAddress(SERVER, 851), CLIENT, CommandId.READ, 7, f) for f in frames[:4]]
    out += [encode_request(AmsAddress(SERVER, 851), CLIENT, CommandId.WRITE, 8, f) for f in frames[4:6]]
    out += [encode_request(AmsAddress(SERVER, 851), CLIENT, CommandId.READ_WRITE, 9, f) for f in frames[6:]]
    handle = 0x1000_0001  # the first handle of a session: read by it, then released (pyads' read_by_name)
    by_handle = [ReadRequest(0xF005, handle, 4).encode(), ReadRequest(0xF005, handle, 8).encode()]
    out += [encode_request(AmsAddress(SERVER, 851), CLIENT, CommandId.READ, 10, f) for f in by_handle]
    release = WriteRequest(0xF006, 0, struct.pack("<I", handle)).encode()
    out.append(encode_request(AmsAddress(SERVER, 851), CLIENT, CommandId.WRITE, 11, release))
    again = encode_request(AmsAddress(SERVER, 851), CLIENT, CommandId.WRITE, 12, release)  # released: 0x710
    out.append(again)
    short = ReadWriteRequest(0xF003, 0, 2, X_POS.encode() + b"\0").encode()  # a handle in 2 bytes: 0x705
    out.append(encode_request(AmsAddress(SERVER, 851), CLIENT, CommandId.READ_WRITE, 13, short))
    for group in (c2p.image_ads_group, 0xF005):  # the polling groups on port 551: its table answers
        read = ReadRequest(group, c2p.offset, 4).encode()
        out.append(encode_request(AmsAddress(SERVER, 551), CLIENT, CommandId.READ, 14, read))
    out.append(encode_request(AmsAddress(SERVER, 551), CLIENT, CommandId.WRITE, 15, release))
    out.append(encode_request(AmsAddress(SERVER, 551), CLIENT, CommandId.READ_WRITE, 16, get_handle))
    out.append(encode_request(AmsAddress(SERVER, 9999), CLIENT, CommandId.READ, 1, frames[0]))  # no port
    out.append(
        encode_request(AmsAddress(NetId.parse("1.2.3.4.5.6"), 851), CLIENT, CommandId.READ, 1, frames[0])
    )
    out.append(encode_request(AmsAddress(SERVER, 851), CLIENT, CommandId.READ_STATE, 1, b""))  # not fast
    out.append(encode_request(AmsAddress(SERVER, 851), CLIENT, CommandId.READ, 1, frames[0][:8]))  # short
    return out


def test_the_fast_path_calls_the_polling_groups_the_port_table_would(image: ProcessImage) -> None:
    """``handle_frame`` calls the services of a PLC's polling on port 851 straight (a raw read of the
    CNC->PLC half, pyads' ``read_by_name``: a handle, a read by it, its release): they must be the
    methods port 851's table maps those groups to."""
    from hli_server.adapters.ads import device as device_module

    device = AdsDevice(image, SERVER)
    table, data = device.ports[851], device.data
    assert table.read[device_module._C2P_GROUP] == data.read_c2p
    assert table.read[device_module._BY_HANDLE] == data.read_by_handle
    assert table.read_write[device_module._HANDLE_BY_NAME] == data.handle_by_name
    assert table.write[device_module._RELEASE_HANDLE] == data.release_handle
    assert table.refuse_writes is None


@pytest.mark.fuzz
def test_the_fast_path_answers_exactly_as_handle_or_leaves_the_frame_to_it(image: ProcessImage) -> None:
    """Every frame the fast path answers gets the reply ``handle`` gives the decoded frame (the
    errors included, and the same counters); what it leaves (None) are the frames ``handle`` must see.
    Seeded mutations of each case (flipped bytes, cut or extended frames) keep that true."""
    import random

    from tests.fuzz import count, seed_for

    publish(image, 5, **{X_POS: 4242})
    fast, slow = AdsDevice(image, SERVER), AdsDevice(image, SERVER)
    fast_session, slow_session = Session(), Session()
    cases = _fast_cases(image.layout)
    rng = random.Random(seed_for("ads_fast_path"))
    mutated = []
    for _ in range(count(400)):
        frame = bytearray(rng.choice(cases))
        for _ in range(rng.randint(1, 3)):
            what = rng.random()
            if what < 0.6:
                frame[rng.randrange(len(frame))] = rng.randrange(256)
            elif what < 0.8:
                del frame[rng.randrange(len(frame)) :]
            else:
                frame += bytes(rng.randint(1, 8))
        mutated.append(bytes(frame))
    answered = left = 0
    for frame in [*cases, *mutated]:
        reply = fast.handle_frame(fast_session, frame, CLIENT.net_id) if len(frame) >= 38 else None
        decoder = AmsStreamDecoder()
        try:
            packets = list(decoder.feed(frame))
        except Exception:
            packets = []
        if reply is None:
            left += 1
            for packet in packets:  # the slow path's answer, on both devices (their states stay alike)
                if isinstance(packet, AmsPacket):
                    fast.handle(fast_session, packet)
                    slow.handle(slow_session, packet)
            continue
        answered += 1
        assert len(packets) == 1, frame.hex()
        assert isinstance(packets[0], AmsPacket), frame.hex()
        assert reply == slow.handle(slow_session, packets[0]), frame.hex()
    assert answered >= 8
    assert left >= 4
    assert fast.stats.requests == slow.stats.requests
    assert fast_session.handles.keys() == slow_session.handles.keys()
