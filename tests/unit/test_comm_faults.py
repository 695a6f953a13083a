"""The communication-fault policy (issue 25, B-03) without sockets: what a fault matches, how it ends,
the mirror of the doors process, and a connection's gate on a transport that records what it is told."""

from __future__ import annotations

import asyncio
import struct
import time
from typing import Any

import pytest
from pydantic import ValidationError

from hli_server.adapters.faults import MAX_ACTIVE, CommFaults, Door, FaultError, FaultSpec
from hli_server.codecs.ads import AmsHeader, AmsPacket, NetId
from hli_server.codecs.modbus_frames import Frame

pytestmark = pytest.mark.req("B-03")


class FakeTransport:
    def __init__(self) -> None:
        self.written: list[tuple[float, bytes]] = []
        self.aborted = False

    def write(self, data: bytes) -> None:
        self.written.append((time.monotonic(), data))

    def abort(self) -> None:
        self.aborted = True

    def close(self) -> None:
        self.aborted = True

    def is_closing(self) -> bool:
        return self.aborted

    def get_write_buffer_size(self) -> int:
        return 0


def read_holding(address: int, count: int = 2) -> Frame:
    return Frame(7, 0, 1, struct.pack(">BHH", 3, address, count))


def ads_read(group: int, offset: int) -> AmsPacket:
    header = AmsHeader(
        target_net_id=NetId.parse("127.0.0.1.1.1"),
        target_port=851,
        source_net_id=NetId.parse("10.1.2.3.1.1"),
        source_port=30000,
        command=2,
        state_flags=4,
        data_length=12,
        error_code=0,
        invoke_id=9,
    )
    return AmsPacket(header, struct.pack("<III", group, offset, 4))


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"kind": "delay", "door": "modbus", "count": 1}, "give delay_ms"),
        ({"kind": "delay", "door": "shm", "delay_ms": 5, "count": 1}, "not of shm"),
        ({"kind": "stall", "cycles": 5, "count": 2}, "give cycles"),
        ({"kind": "disconnect", "count": 2}, "duration_ms or cycles"),
        ({"kind": "drop", "door": "ads", "after": 1, "table": "coils"}, "only delay and error"),
        ({"kind": "error", "door": "ads", "code": 5, "table": "coils", "count": 1}, "Modbus table"),
        ({"kind": "error", "door": "modbus", "code": 2, "index_group": 1, "count": 1}, "only ADS"),
        ({"kind": "error", "door": "modbus", "code": 2, "first": 5, "count": 1}, "both first and last"),
        ({"kind": "error", "door": "modbus", "code": 2, "first": 5, "last": 4, "count": 1}, "before first"),
        ({"kind": "error", "door": "modbus", "code": 2, "first": 0, "last": 70000, "count": 1}, "0..65535"),
        ({"kind": "delay", "door": "ads", "delay_ms": 5, "count": 1, "cycles": 3}, "one end"),
        ({"kind": "delay", "door": "ads", "delay_ms": 10_001, "count": 1}, "less than or equal"),
        ({"kind": "error", "door": "ads", "code": 0, "count": 1}, "greater than or equal"),
        ({"kind": "delay", "door": "ads", "delay_ms": 5, "count": 1, "extra": 1}, "Extra inputs"),
    ],
)
def test_a_fault_that_makes_no_sense_is_refused_with_a_reason(spec: dict[str, Any], message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        FaultSpec.model_validate(spec)


def test_a_modbus_error_matches_its_address_range_and_table_and_ends_after_its_count() -> None:
    faults = CommFaults()
    faults.add({"kind": "error", "door": "modbus", "code": 4, "first": 10, "last": 11,
                "table": "holding_registers",
                "count": 2})  # fmt: skip
    gate = faults.gate(Door.MODBUS, FakeTransport())
    assert gate.modbus(read_holding(12)) is None
    assert gate.modbus(read_holding(8, 2)) is None  # 8..9
    assert gate.modbus(Frame(1, 0, 1, struct.pack(">BHH", 4, 10, 1))) is None  # input registers: other table
    assert gate.modbus(read_holding(9, 2)) == struct.pack(">HHHBBB", 7, 0, 3, 1, 0x83, 4)  # 9..10 overlaps
    assert faults.table()[0]["left"] == 1
    assert gate.modbus(Frame(8, 0, 1, struct.pack(">BHH", 6, 11, 5))) is not None  # FC 6 to 11
    assert faults.table() == []
    assert faults.history[-1]["reason"] == "count"
    assert gate.modbus(read_holding(10)) is None


def test_an_ads_error_matches_its_index_group_and_offsets() -> None:
    faults = CommFaults()
    faults.add({"kind": "error", "door": "ads", "code": 0x745, "index_group": 0xF020, "first": 0, "last": 7,
                "duration_ms": 60_000})  # fmt: skip
    gate = faults.gate(Door.ADS, FakeTransport())
    assert gate.ads(ads_read(0xF030, 0)) is None
    assert gate.ads(ads_read(0xF020, 8)) is None
    reply = gate.ads(ads_read(0xF020, 4))
    assert reply is not None
    assert struct.pack("<I", 0x745) in reply
    assert faults.gate(Door.MODBUS, FakeTransport()).modbus(read_holding(0)) is None  # another door


def test_a_connection_is_dropped_after_n_requests_and_only_as_many_as_asked() -> None:
    faults = CommFaults()
    faults.add({"kind": "drop", "door": "modbus", "after": 2, "count": 2})
    a, b = FakeTransport(), FakeTransport()
    gate_a, gate_b = faults.gate(Door.MODBUS, a), faults.gate(Door.MODBUS, b)
    assert gate_a.modbus(read_holding(0)) is None
    assert gate_a.modbus(read_holding(0)) is None
    assert gate_b.modbus(read_holding(0)) is None
    assert gate_a.modbus(read_holding(0)) == b""
    assert a.aborted
    gate_a.transport.write(b"late")
    assert a.written == []  # nothing goes out on a dropped connection
    assert gate_b.modbus(read_holding(0)) is None
    assert gate_b.modbus(read_holding(0)) == b""
    assert faults.table() == []


async def test_delayed_answers_keep_their_order_and_come_after_the_delay() -> None:
    faults = CommFaults()
    faults.add({"kind": "delay", "door": "ads", "delay_ms": 80, "count": 1})
    raw = FakeTransport()
    gate = faults.gate(Door.ADS, raw)
    began = time.monotonic()
    assert gate.ads(ads_read(0xF020, 0)) is None  # served, its answer held
    gate.transport.write(b"first")
    assert gate.ads(ads_read(0xF020, 0)) is None  # the count was 1: not delayed itself ...
    gate.transport.write(b"second")  # ... but it cannot overtake the first
    assert raw.written == []
    assert gate.transport.get_write_buffer_size() == len(b"firstsecond")
    await asyncio.sleep(0.2)
    assert b"".join(d for _, d in raw.written) == b"firstsecond"
    assert raw.written[0][0] - began >= 0.08


def test_a_stall_counts_cycles_and_other_faults_end_after_their_cycles() -> None:
    cycle = [100]
    faults = CommFaults(lambda: cycle[0])
    faults.add({"kind": "stall", "cycles": 3})
    faults.add({"kind": "delay", "door": "modbus", "delay_ms": 5, "cycles": 2})
    stalled = []
    for c in range(101, 106):
        cycle[0] = c
        stalled.append(faults.publish_stalled(c))
    assert stalled == [True, True, True, False, False]
    assert faults.table() == []
    assert [h["reason"] for h in faults.history if h["fault"] == "end"] == ["cycles", "cycles"]


def test_a_duration_ends_a_fault_even_without_a_loop_to_time_it() -> None:
    faults = CommFaults()
    faults.add({"kind": "disconnect", "duration_ms": 30})
    assert faults.door_down(Door.MQTT)
    time.sleep(0.05)
    assert not faults.door_down(Door.MQTT)
    assert faults.history[-1]["reason"] == "duration"


def test_the_mirror_of_the_doors_process_keeps_its_counts_and_reports_its_ends() -> None:
    owner, mirror = CommFaults(), CommFaults()
    ended: list[dict[str, Any]] = []
    mirror.subscribe(lambda change: ended.append(change) if change["fault"] == "end" else None)
    fault = owner.add({"kind": "error", "door": "modbus", "code": 2, "count": 3})
    mirror.load(owner.export())
    gate = mirror.gate(Door.MODBUS, FakeTransport())
    assert gate.modbus(read_holding(0)) is not None
    mirror.load(owner.export())  # the owner sends its table again (another fault changed)
    assert mirror.table()[0]["used"] == 1
    gate.modbus(read_holding(0))
    gate.modbus(read_holding(0))
    assert ended == [{"fault": "end", "id": fault.id, "reason": "count"}]


def test_at_most_max_active_faults_and_a_reset_ends_them_all() -> None:
    faults = CommFaults()
    for _ in range(MAX_ACTIVE):
        faults.add({"kind": "delay", "door": "modbus", "delay_ms": 1, "count": 5})
    with pytest.raises(FaultError, match="in effect already"):
        faults.add({"kind": "delay", "door": "modbus", "delay_ms": 1, "count": 5})
    assert faults.reset() == MAX_ACTIVE
    assert not faults.active
    with pytest.raises(FaultError, match="no communication fault 99"):
        faults.end(99)
