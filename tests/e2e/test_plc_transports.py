"""The PLC-side transports against the real server (H-06; H-01 shared memory, H-03 Modbus, H-04 ADS).

Stepped clock, so that every value is known to the cycle. Sync Modbus calls run in a worker thread:
a blocking client must not wait inside the event loop that serves it.
"""

from __future__ import annotations

import asyncio
import os
import socket
import time
from collections.abc import AsyncIterator
from typing import Any

import pytest

from hli_server.adapters.modbus import ModbusAdapter
from hli_server.configuration import load_machine
from hli_server.runtime import Runtime
from plc_clients import (
    AXIS_REF,
    AdsTransport,
    AsyncAdsTransport,
    AsyncModbusTransport,
    ErrorID,
    MCV_DynPosLimitHigh,
    ModbusTransport,
    PlcTask,
    ShmTransport,
    TransportError,
)

pytestmark = [pytest.mark.req("H-06"), pytest.mark.timeout(60)]

CMD = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w"
EN = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.enable_w"
STATE = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.state_r"
X_POS = "gpAx[0]^ipo_state.cmd_pos_r"
COLL_OFFSET = "gpAx[4]^dyn_coll_mon.coll_offset"  # X2: 200000 (20 mm), FCT-C3 demo pair


def image_name(tag: str) -> str:
    return f"hli_test_plct_{tag}_{os.getpid()}_{time.monotonic_ns() % 1_000_000}"


async def start_runtime(**modbus: Any) -> Runtime:
    rt = Runtime(
        load_machine(None),
        clock="stepped",
        http_port=None,
        image_name=image_name("rt"),
        adapters=[("modbus", {"port": 0, **modbus}), ("ads", {"port": 0})],
    )
    await rt.start()
    return rt


@pytest.fixture
async def runtime() -> AsyncIterator[Runtime]:
    rt = await start_runtime()
    try:
        yield rt
    finally:
        await rt.stop()


def ads_port(rt: Runtime) -> int:
    return int(getattr(rt.adapter("ads"), "port", 0) or 0)


def modbus_port(rt: Runtime) -> int:
    adapter = rt.adapter("modbus")
    assert isinstance(adapter, ModbusAdapter)
    return adapter.port or 0


class Door:
    """One transport with awaitable calls, whatever its kind."""

    def __init__(self, kind: str, transport: Any) -> None:
        self.kind = kind
        self.t = transport

    async def call(self, method: str, *args: Any) -> Any:
        fn = getattr(self.t, method)
        if self.kind.endswith("-sync"):
            return await asyncio.to_thread(fn, *args)
        result = fn(*args)
        return await result if asyncio.iscoroutine(result) else result


async def open_door(kind: str, rt: Runtime, **options: Any) -> Door:
    if kind == "shm":
        return Door(kind, ShmTransport.attach(rt.image.name))
    if kind == "ads":
        return Door(
            kind, await AsyncAdsTransport.connect("127.0.0.1", ads_port(rt), layout=rt.layout, **options)
        )
    if kind == "ads-sync":
        sync_ads = await asyncio.to_thread(
            AdsTransport.connect, "127.0.0.1", ads_port(rt), layout=rt.layout, **options
        )
        return Door(kind, sync_ads)
    if kind == "modbus":
        return Door(
            kind,
            await AsyncModbusTransport.connect("127.0.0.1", modbus_port(rt), layout=rt.layout, **options),
        )
    sync = await asyncio.to_thread(
        ModbusTransport.connect, "127.0.0.1", modbus_port(rt), layout=rt.layout, **options
    )
    return Door(kind, sync)


@pytest.mark.req("H-01", "H-03", "H-04")
@pytest.mark.parametrize("kind", ["shm", "modbus", "modbus-sync", "ads", "ads-sync"])
async def test_snapshot_write_and_read_through_every_transport(runtime: Runtime, kind: str) -> None:
    door = await open_door(kind, runtime)
    try:
        await runtime.step(7)
        inputs = await door.call("snapshot", [X_POS, STATE, EN])
        assert inputs.cycle == runtime.cycle == 7
        assert inputs.consistent  # nothing is published between the requests with a stepped clock
        assert inputs[STATE] == 0
        assert EN not in inputs
        assert inputs[X_POS] == runtime.image.read(X_POS)
        await door.call("write_many", [(CMD, -123_456), (EN, True)])
        assert await door.call("read", CMD) == -123_456
        assert await door.call("read", EN) is True
        unit = runtime.machine.hli.axes[0].ipo_mc_control.dyn_pos_limit_low
        assert (unit.command_w, unit.enable_w) == (0, False)  # latched at the next cycle
        await runtime.step(2)
        assert (unit.command_w, unit.enable_w) == (-123_456, True)
        assert await door.call("read", STATE) == 2  # ACTIVATION, then ACTIVE
        await door.call("write", EN, False)
        await runtime.step(1)
        assert unit.enable_w is False
        full = await door.call("snapshot", None)
        assert full[COLL_OFFSET] == 200_000
        assert len(full.values) == len(runtime.layout.half(runtime.layout.signal(STATE).direction))
    finally:
        await door.call("close")


@pytest.mark.req("H-03")
async def test_modbus_word_order_cdab_and_unit_id_must_match_the_server() -> None:
    rt = await start_runtime(word_order="CDAB", unit_id=9)
    try:
        door = await open_door("modbus", rt, word_order="cdab", unit_id=9)
        await door.call("write", CMD, -2)
        await rt.step(1)
        assert rt.machine.hli.axes[0].ipo_mc_control.dyn_pos_limit_low.command_w == -2
        assert await door.call("read", COLL_OFFSET) == 200_000
        await door.call("close")
        wrong_unit = await open_door("modbus", rt, word_order="cdab", unit_id=1)
        with pytest.raises(TransportError, match="0x0B") as info:
            await wrong_unit.call("read", COLL_OFFSET)
        assert info.value.modbus_exception == 0x0B
        await wrong_unit.call("close")
    finally:
        await rt.stop()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port  # nothing listens there once the socket is closed


async def test_no_server_is_a_transport_error(runtime: Runtime) -> None:
    port = free_port()
    with pytest.raises(TransportError, match=f"127.0.0.1:{port}.*hli-server run"):
        await AsyncModbusTransport.connect("127.0.0.1", port, layout=runtime.layout, timeout=1)
    with pytest.raises(TransportError, match="connecting failed"):
        await asyncio.to_thread(ModbusTransport.connect, "127.0.0.1", port, layout=runtime.layout, timeout=1)
    with pytest.raises(TransportError, match="is the server running"):
        ShmTransport.attach(image_name("nobody"))


@pytest.mark.req("C43-10")
@pytest.mark.parametrize("kind", ["shm", "modbus", "ads"])
async def test_a_server_that_goes_away_makes_the_block_report_a_transport_failure(kind: str) -> None:
    rt = await start_runtime()
    try:
        door = await open_door(kind, rt, **({"timeout": 0.5} if kind != "shm" else {}))
        block = MCV_DynPosLimitHigh()
        block.set_inputs(Axis=AXIS_REF(0, "X"), Enable=True, Position=300_000)
        task = PlcTask(door.t, 0.001, block)
        for _ in range(5):
            await task.run_cycle_async()
            await rt.step(1)
        assert block.Valid
        await rt.stop()
        await task.run_cycle_async()
        assert (block.Valid, block.Error, block.ErrorID) == (False, True, ErrorID.TRANSPORT_FAILURE)
        assert task.stats.input_faults == 1
        expected = {
            "shm": "the server closed the image",
            "modbus": "Modbus TCP 127.0.0.1",
            "ads": "ADS 127.0.0.1",
        }[kind]
        assert expected in block.ErrorText
        await door.call("close")
    finally:
        await rt.stop()
