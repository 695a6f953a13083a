"""ADS over TCP against real clients (H-04; C3-10 for port 551; issue 12's bar for the door).

Clients: pyads 3.6 (Beckhoff's AdsLib) as a PLC programmer uses it - ``pyads.Connection`` to
127.0.0.1 on the server's port, without a TwinCAT router - and a raw asyncio stream built with the
codec for what pyads cannot send (unknown commands, pipelining, broken frames, floods). pyads calls
block, so they run in a worker thread while the server runs in the test's event loop; the stepped
clock makes every value known to the cycle.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import queue
import random
import struct
import sys
import time
from collections.abc import AsyncIterator, Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import pyads
import pytest

from hli_server.adapters.ads import VIEW_GROUP, AdsAdapter
from hli_server.codecs.ads import (
    AmsAddress,
    AmsPacket,
    AmsStreamDecoder,
    AmsTcpFrame,
    CommandId,
    ErrorCode,
    NetId,
    ReadRequest,
    ReadStateRequest,
    WriteRequest,
    decode_response,
    encode_request,
    encode_router_frame,
)
from hli_server.configuration import load_machine
from hli_server.runtime import Runtime
from plc_clients.ads import close_pyads, open_pyads
from schemas.layout import Direction, build_layout
from schemas.wire import ProgramState
from tests.integration.servers import door_port, read_banner, start_server, stop_server

pytestmark = [pytest.mark.req("H-04"), pytest.mark.timeout(60)]

ROOT = Path(__file__).resolve().parents[2]
SERVER = "127.0.0.1.1.1"
LOCAL = "10.1.2.3.1.1"
CMD_LOW = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w"
EN_LOW = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.enable_w"
STATE_LOW = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.state_r"
HIGH = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high"
X_POS = "gpAx[0]^ipo_state.cmd_pos_r"
MODE = "gpCh[0]^bahn_state.mode_r"
COLL_OFFSET = "gpAx[4]^dyn_coll_mon.coll_offset"
F020, F030 = 0xF020, 0xF030
FUZZ_INPUTS = int(os.environ.get("HLI_ADS_FUZZ_INPUTS", "1500"))
T = TypeVar("T")


def image_name(tag: str) -> str:
    return f"hli_test_ads_{tag}_{os.getpid()}_{time.monotonic_ns() % 1_000_000}"


@pytest.fixture(scope="module", autouse=True)
def _pyads_local_address() -> None:
    """AdsLib's own NetId (one per process): what the server sees as the requests' source."""
    pyads.open_port()
    pyads.set_local_address(LOCAL)
    pyads.close_port()


async def start_runtime(**options: Any) -> Runtime:
    rt = Runtime(
        load_machine(None),
        clock="stepped",
        http_port=None,
        image_name=image_name("rt"),
        adapters=[("ads", {"port": 0, **options})],
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


def ads(rt: Runtime) -> AdsAdapter:
    adapter = rt.adapter("ads")
    assert isinstance(adapter, AdsAdapter)
    return adapter


class Plc:
    """A pyads connection whose blocking calls run in a worker thread (opened and closed as
    ``plc_clients.ads`` does: one AdsLib route per NetId, deleted with the last connection)."""

    def __init__(self, port: int, ams_port: int = 851, timeout_ms: int = 2000) -> None:
        self.address = f"127.0.0.1:{port}"
        self.ams_port = ams_port
        self.timeout_ms = timeout_ms
        self.conn: Any = None

    async def open(self) -> None:
        self.conn = await asyncio.to_thread(
            open_pyads, SERVER, self.ams_port, self.address, self.timeout_ms / 1000
        )

    async def close(self) -> None:
        if self.conn is not None:
            await asyncio.to_thread(close_pyads, self.conn)

    async def __call__(self, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        return await asyncio.to_thread(fn, *args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        method = getattr(self.conn, name)

        async def call(*args: Any, **kwargs: Any) -> Any:
            return await asyncio.to_thread(method, *args, **kwargs)

        return call


@contextlib.asynccontextmanager
async def plc(rt: Runtime, ams_port: int = 851, timeout_ms: int = 2000) -> AsyncIterator[Plc]:
    client = Plc(ads(rt).port or 0, ams_port, timeout_ms)
    await client.open()
    try:
        yield client
    finally:
        await client.close()


async def ads_error(call: Any) -> int:
    """The ADS error code a pyads call raised."""
    with pytest.raises(pyads.ADSError) as info:
        await call
    code: int = info.value.err_code
    return code


# ================================================================================================
# A raw client (what pyads cannot send)
# ================================================================================================


class RawClient:
    """AMS/TCP over an asyncio stream, frames built with the codec."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader = reader
        self.writer = writer
        self.decoder = AmsStreamDecoder(max_ams_length=1 << 20)
        self.frames: list[AmsPacket | AmsTcpFrame] = []
        self.invoke = 0
        self.source = AmsAddress(NetId.parse("10.9.8.7.1.1"), 30000)

    @classmethod
    async def connect(cls, port: int) -> RawClient:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        return cls(reader, writer)

    def frame(self, command: int, payload: bytes, port: int = 851, net_id: str = SERVER) -> bytes:
        self.invoke += 1
        return encode_request(
            AmsAddress(NetId.parse(net_id), port), self.source, command, self.invoke, payload
        )

    async def next(self, timeout: float = 3.0) -> AmsPacket | AmsTcpFrame:
        while not self.frames:
            data = await asyncio.wait_for(self.reader.read(65536), timeout)
            if not data:
                raise ConnectionResetError("the server closed the connection")
            self.frames.extend(self.decoder.feed(data))
        return self.frames.pop(0)

    async def request(self, command: int, payload: bytes, port: int = 851, net_id: str = SERVER) -> AmsPacket:
        self.writer.write(self.frame(command, payload, port, net_id))
        await self.writer.drain()
        while True:  # the reply, past any DeviceNotification the server sent meanwhile
            frame = await self.next()
            assert isinstance(frame, AmsPacket)
            if frame.header.command != CommandId.DEVICE_NOTIFICATION or frame.header.is_response:
                return frame

    async def closed(self, timeout: float = 3.0) -> bool:
        """True when the server closed the connection (EOF or reset) within ``timeout``."""
        try:
            while True:
                data = await asyncio.wait_for(self.reader.read(65536), timeout)
                if not data:
                    return True
        except (ConnectionResetError, BrokenPipeError):
            return True
        except TimeoutError:
            return False

    def close(self) -> None:
        self.writer.close()


def result_of(packet: AmsPacket) -> int:
    """The reply's error: the AMS header's, else the payload's result."""
    if packet.header.error_code:
        return packet.header.error_code
    code: int = struct.unpack_from("<I", packet.data)[0]
    return code


# ================================================================================================
# pyads: by name, by address, handles, sum commands, symbol info
# ================================================================================================


async def test_read_and_write_by_name_in_every_spelling(runtime: Runtime) -> None:
    async with plc(runtime) as c:
        await c.write_by_name(CMD_LOW, -123_456, pyads.PLCTYPE_DINT)
        await c.write_by_name("gpAx[0].ipo_mc_control.dyn_pos_limit_low.enable_w", True, pyads.PLCTYPE_BOOL)
        assert await c.read_by_name("gpAx[0]^.ipo_mc_control.dyn_pos_limit_low.command_w") == -123_456
        assert await c.read_by_name(
            "GPAX[0].IPO_MC_CONTROL.DYN_POS_LIMIT_LOW.COMMAND_W", pyads.PLCTYPE_DINT
        ) == (-123_456)
        unit = runtime.machine.hli.axes[0].ipo_mc_control.dyn_pos_limit_low
        assert (unit.command_w, unit.enable_w) == (0, False)  # latched at the next cycle
        await runtime.step(2)
        assert (unit.command_w, unit.enable_w) == (-123_456, True)
        assert await c.read_by_name(STATE_LOW) == 2  # HLI_DYNPL_STATE_ACTIVE, from the newest publish
        assert await c.read_by_name(COLL_OFFSET) == 200_000
        assert await c.read_by_name("gpAx[4]^dyn_coll_mon.deceleration") == 2000.0


async def test_read_and_write_by_group_and_offset(runtime: Runtime) -> None:
    layout = runtime.layout
    cmd, en = layout.signal(CMD_LOW), layout.signal(EN_LOW)
    async with plc(runtime) as c:
        await c.write(F030, cmd.offset, -7, pyads.PLCTYPE_DINT)
        await c.write(F030, en.offset, True, pyads.PLCTYPE_BOOL)
        assert runtime.image.read(CMD_LOW) == -7
        assert await c.read(F030, cmd.offset, pyads.PLCTYPE_DINT) == -7
        await runtime.step(3)
        x = layout.signal(X_POS)
        assert await c.read(F020, x.offset, pyads.PLCTYPE_DINT) == runtime.image.read(X_POS)
        state = layout.signal(STATE_LOW)
        assert await c.read(F020, state.offset, pyads.PLCTYPE_UDINT) == 2
        # a raw read of a whole half is the image's bytes of the newest publish
        half = await c.read(F020, 0, pyads.PLCTYPE_BYTE * layout.c2p_size, return_ctypes=True)
        assert bytes(half) == runtime.image.snapshot()[1]
        # a raw write of several fields (padding included) in one request
        block = runtime.image.read_half(Direction.PLC_TO_CNC)[cmd.offset - 4 : cmd.offset + 8]
        patched = bytearray(block)
        patched[4:8] = struct.pack("<i", 99)
        await c.write(F030, cmd.offset - 4, bytes(patched), pyads.PLCTYPE_BYTE * 12)
        assert runtime.image.read(CMD_LOW) == 99


async def test_handles_are_per_connection_and_released(runtime: Runtime) -> None:
    async with plc(runtime) as c:
        handle = await c.get_handle(CMD_LOW)
        await c.write_by_name("", 4321, pyads.PLCTYPE_DINT, handle=handle)
        assert await c.read_by_name("", pyads.PLCTYPE_DINT, handle=handle) == 4321
        assert runtime.image.read(CMD_LOW) == 4321
        second = await c.get_handle(X_POS)
        assert second != handle
        # another TCP connection has no such handle (pyads' Connections of one process share one socket)
        raw = await RawClient.connect(ads(runtime).port or 0)
        reply = await raw.request(CommandId.READ, ReadRequest(0xF005, handle, 4).encode())
        assert result_of(reply) == 0x710
        raw.close()
        await c.release_handle(handle)
        assert await ads_error(c.read_by_name("", pyads.PLCTYPE_DINT, handle=handle)) == 0x710
        assert await ads_error(c.get_handle("gpAx[0]^no_such.symbol")) == 0x710
        await c.release_handle(second)


async def test_read_and_write_lists_by_name_use_sum_commands(runtime: Runtime) -> None:
    async with plc(runtime) as c:
        await c.write_list_by_name({CMD_LOW: -55, EN_LOW: True, f"{HIGH}.command_w": 77})
        assert runtime.image.read(f"{HIGH}.command_w") == 77
        await runtime.step(2)
        values = await c.read_list_by_name(
            [CMD_LOW, STATE_LOW, COLL_OFFSET, MODE, "gpAx[4]^dyn_coll_mon.active"]
        )
        assert values == {
            CMD_LOW: -55,
            STATE_LOW: 2,
            COLL_OFFSET: 200_000,
            MODE: runtime.image.read(MODE),
            "gpAx[4]^dyn_coll_mon.active": True,
        }
    assert ads(runtime).device.stats.requests > 0


async def test_symbol_info_and_upload(runtime: Runtime) -> None:
    layout = runtime.layout
    async with plc(runtime) as c:
        symbol = await c(c.conn.get_symbol, COLL_OFFSET)
        s = layout.signal(COLL_OFFSET)
        assert (symbol.index_group, symbol.index_offset, symbol.symbol_type) == (F020, s.offset, "UDINT")
        assert "distance between the axes" in symbol.comment
        assert await c(symbol.read) == 200_000
        everything = await c.get_all_symbols()  # the top level, as TwinCAT's upload
        assert [(x.name, x.symbol_type) for x in everything] == [
            ("gpCh", f"ARRAY [0..{len(layout.channels) - 1}] OF HLI_CH"),
            ("gpAx", f"ARRAY [0..{len(layout.axes) - 1}] OF HLI_AX"),
            ("gpVEGlob", "HLI_VEGLOB"),  # the demo machine's global V.E. variables (N-05)
        ]
        cmd_low = await c(c.conn.get_symbol, CMD_LOW)
        cmd = layout.signal(CMD_LOW)
        assert (cmd_low.index_group, cmd_low.index_offset) == (F030, cmd.offset)
        assert (await c(c.conn.get_symbol, "gpAx[0]^ipo_state.referenced_r")).symbol_type == "BOOL"
        unit = await c(c.conn.get_symbol, "gpAx[0]^ipo_mc_control.dyn_pos_limit_low")
        assert (unit.symbol_type, unit.index_group) == ("MC_CONTROL_SGN32_UNIT", VIEW_GROUP)
        # every entry fits pyads' 798-byte symbol info read
        for name in [layout.signals[0].st_path, layout.signals[-1].st_path]:
            info = await c(pyads.pyads_ex.adsGetSymbolInfo, c.conn._port, c.conn._adr, name)
            assert info.entryLength <= 798


async def test_device_info_state_and_write_control(runtime: Runtime) -> None:
    async with plc(runtime) as c, plc(runtime, 551) as geo:
        name, version = await c.read_device_info()
        assert name == "Plc30 App"  # what a TwinCAT 3 PLC runtime calls itself
        assert (version.version, version.revision, version.build) == (3, 1, 4024)
        assert await c.read_state() == (pyads.ADSSTATE_RUN, 0)
        assert (await geo.read_device_info())[0] == "HLI-Server GEO"
        assert await geo.read_state() == (pyads.ADSSTATE_RUN, 0)
        await c.write_control(pyads.ADSSTATE_RUN, 0, 0, pyads.PLCTYPE_INT)
        assert await ads_error(c.write_control(pyads.ADSSTATE_STOP, 0, 0, pyads.PLCTYPE_INT)) == 0x701
        assert await c.read_state() == (pyads.ADSSTATE_RUN, 0)


async def test_every_refusal_has_its_ads_error_code(runtime: Runtime) -> None:
    layout = runtime.layout
    x = layout.signal(X_POS)
    before = runtime.image.read_half(Direction.PLC_TO_CNC)
    async with plc(runtime) as c, plc(runtime, 551) as geo:
        # 0x704: a write to a _r value (by name, by handle, by address) and any write on port 551
        assert await ads_error(c.write_by_name(X_POS, 5, pyads.PLCTYPE_DINT)) == 0x704
        assert await ads_error(c.write(F020, x.offset, 5, pyads.PLCTYPE_DINT)) == 0x704
        coll = (5 << 16) | 0x0246
        assert await ads_error(geo.write(0x120300, coll, 5, pyads.PLCTYPE_UDINT)) == 0x704
        # 0x702 unknown index group, 0x703 unknown offset (port 851 and 551)
        assert await ads_error(c.read(0x4020, 0, pyads.PLCTYPE_DINT)) == 0x702
        assert await ads_error(geo.read(0x120301, coll, pyads.PLCTYPE_UDINT)) == 0x702
        assert await ads_error(geo.read(0x120300, (9 << 16) | 0x0246, pyads.PLCTYPE_UDINT)) == 0x703
        assert await ads_error(c.read(F020, layout.c2p_size + 4, pyads.PLCTYPE_DINT)) == 0x703
        cmd = layout.signal(CMD_LOW)
        assert (
            await ads_error(c.write(F030, cmd.offset + 1, 5, pyads.PLCTYPE_DINT)) == 0x703
        )  # inside a field
        # 0x705 wrong size
        assert await ads_error(geo.read(0x120300, coll, pyads.PLCTYPE_INT)) == 0x705
        assert await ads_error(c.read_by_name(CMD_LOW, pyads.PLCTYPE_INT)) == 0x705
        assert await ads_error(c.write(F030, cmd.offset, 5, pyads.PLCTYPE_INT)) == 0x705  # ends inside
        assert await ads_error(c.read(F020, layout.c2p_size - 2, pyads.PLCTYPE_DINT)) == 0x705
        # 0x706 a value the field cannot take (a BOOL byte of 2)
        assert await ads_error(c.write(F030, layout.signal(EN_LOW).offset, 2, pyads.PLCTYPE_BYTE)) == 0x706
        # 0x710 unknown symbol
        assert await ads_error(c.read_by_name("gpAx[99]^ipo_state.cmd_pos_r", pyads.PLCTYPE_DINT)) == 0x710
    # AMS 0x6: nothing on port 999
    async with plc(runtime, 999) as nowhere:
        assert await ads_error(nowhere.read_state()) == 0x6
    # 0x701: a command id that is no request (pyads cannot send one)
    raw = await RawClient.connect(ads(runtime).port or 0)
    try:
        for command in (0, 8, 10, 0x1234):
            reply = await raw.request(command, b"")
            assert (reply.header.command, reply.header.invoke_id) == (command, raw.invoke)
            assert result_of(reply) == 0x701
        # AMS 0x7: another NetId than the server's
        reply = await raw.request(CommandId.READ_STATE, b"", net_id="192.168.0.1.1.1")
        assert reply.header.error_code == ErrorCode.TARGET_MACHINE_NOT_FOUND
    finally:
        raw.close()
    assert runtime.image.read_half(Direction.PLC_TO_CNC) == before  # no refused request wrote anything


# ================================================================================================
# Device notifications
# ================================================================================================


async def test_a_notification_reaches_a_separate_process(runtime: Runtime) -> None:
    """pyads in another process subscribes; each write through the image reaches it at the next cycle."""
    port = ads(runtime).port
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "tests.integration._ads_children",
        str(port),
        CMD_LOW,
        "3",
        cwd=ROOT,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    assert proc.stdout is not None
    try:
        line = await asyncio.wait_for(proc.stdout.readline(), 15)
        assert line.strip() == b"ready", line
        samples = [json.loads(await asyncio.wait_for(proc.stdout.readline(), 5))]  # the first sample: 0
        for value in (1111, -2222):
            runtime.image.write(CMD_LOW, value)
            await runtime.step(1)
            samples.append(json.loads(await asyncio.wait_for(proc.stdout.readline(), 5)))
        assert [s["value"] for s in samples] == [0, 1111, -2222]
        assert len({s["handle"] for s in samples}) == 1
        assert await asyncio.wait_for(proc.wait(), 10) == 0
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    for _ in range(100):  # the child closed its connection: everything it held is released
        if ads(runtime).device.notification_count == 0 and ads(runtime).connection_count == 0:
            break
        await asyncio.sleep(0.02)
    assert ads(runtime).device.notification_count == 0
    assert ads(runtime).connection_count == 0


@pytest.mark.req("B-01")
async def test_notifications_on_change_and_cyclic_with_distinct_handles(runtime: Runtime) -> None:
    received: queue.Queue[tuple[str, int, Any]] = queue.Queue()
    async with plc(runtime) as c, plc(runtime, 551) as geo:

        def callback(name: str, plc_type: Any, conn: Any) -> Any:
            def on_sample(notification: Any, _: str) -> None:
                handle, _stamp, value = conn.parse_notification(notification, plc_type)
                received.put((name, handle, value))

            return on_sample

        change = pyads.NotificationAttrib(4, trans_mode=pyads.ADSTRANS_SERVERONCHA, cycle_time=0)
        cyclic = pyads.NotificationAttrib(4, trans_mode=pyads.ADSTRANS_SERVERCYCLE, cycle_time=10)  # ms
        h_cmd = await c.add_device_notification(CMD_LOW, change, callback("cmd", pyads.PLCTYPE_DINT, c.conn))
        h_high = await c.add_device_notification(
            f"{HIGH}.command_w", change, callback("high", pyads.PLCTYPE_DINT, c.conn)
        )
        h_coll = await geo.add_device_notification(
            (0x120300, (5 << 16) | 0x0246), cyclic, callback("coll", pyads.PLCTYPE_UDINT, geo.conn)
        )
        assert len({h_cmd[0], h_high[0]}) == 2  # pyads issues #326/#471: one handle per variable

        async def take(n: int) -> list[tuple[str, int, Any]]:
            out = []
            for _ in range(n):
                out.append(await asyncio.to_thread(received.get, True, 3))
            return out

        first = await take(3)  # every notification's first sample, whatever its mode
        assert sorted((name, value) for name, _, value in first) == [
            ("cmd", 0),
            ("coll", 200_000),
            ("high", 0),
        ]
        runtime.image.write(CMD_LOW, 5)
        await runtime.step(10)  # cmd changed once, high did not; coll every 10 ms = 10 cycles
        samples = await take(2)
        assert sorted((name, value) for name, _, value in samples) == [("cmd", 5), ("coll", 200_000)]
        with pytest.raises(queue.Empty):
            received.get(timeout=0.1)
        await runtime.step(20)  # two more cyclic samples, caught up in one frame of two stamps
        assert [name for name, _, _ in await take(2)] == ["coll", "coll"]
        with pytest.raises(queue.Empty):
            received.get(timeout=0.1)
        await c.del_device_notification(*h_cmd)
        await c.del_device_notification(*h_high)
        await geo.del_device_notification(*h_coll)
        assert ads(runtime).device.notification_count == 0
        runtime.image.write(CMD_LOW, 6)
        await runtime.step(20)
        with pytest.raises(queue.Empty):
            received.get(timeout=0.1)


async def test_notifications_are_released_when_the_client_goes_away(runtime: Runtime) -> None:
    raw = await RawClient.connect(ads(runtime).port or 0)
    x = runtime.layout.signal(X_POS)
    payload = struct.pack("<IIIIII16s", F020, x.offset, 4, 3, 0, 10_000, bytes(16))  # cyclic, 1 ms
    for _ in range(5):
        reply = await raw.request(CommandId.ADD_DEVICE_NOTIFICATION, payload)
        assert result_of(reply) == 0
    assert ads(runtime).device.notification_count == 5
    raw.close()
    for _ in range(100):
        if ads(runtime).device.notification_count == 0:
            break
        await asyncio.sleep(0.01)
    assert ads(runtime).device.notification_count == 0
    await runtime.step(5)  # nothing is sampled for a closed connection


# ================================================================================================
# The machine through ADS: a dynamic position limit, the collision objects on port 551
# ================================================================================================


@pytest.mark.req("H-04", "C43-02", "C43-03", "C43-04")
async def test_dyn_pos_limit_set_over_ads_stops_the_axis(runtime: Runtime) -> None:
    limit = 300_000  # 30 mm in 0.1 µm
    async with plc(runtime) as c:
        await c.write_by_name(f"{HIGH}.command_w", limit, pyads.PLCTYPE_DINT)  # command_w first (H-02)
        await c.write_by_name(f"{HIGH}.enable_w", True, pyads.PLCTYPE_BOOL)
        await runtime.step(5)
        assert await c.read_by_name(f"{HIGH}.state_r", pyads.PLCTYPE_UDINT) == 2  # ACTIVE
        channel = runtime.machine.channel(1)
        channel.load_program("N10 G01 X100 F6000\nN20 M30\n", "p")
        channel.request_start()
        await runtime.step(3000)  # 3 s: without the limit X would reach 100 mm long before
        x = await c.read_by_name(X_POS, pyads.PLCTYPE_DINT)
        one_cycle = 6000 / 60 * runtime.t_a * 10_000
        assert limit - one_cycle <= x <= limit + one_cycle  # C43-06: passed by at most one cycle
        assert await c.read_by_name(f"{HIGH}.state_r", pyads.PLCTYPE_UDINT) == 4  # ACTIVE_BRAKE
        assert await c.read_by_name("gpAx[0]^ipo_state.moving_r", pyads.PLCTYPE_BOOL) is False
        assert channel.state != ProgramState.FINISHED
        # C43-07: lifted over ADS, the program continues to its end
        await c.write_by_name(f"{HIGH}.enable_w", False, pyads.PLCTYPE_BOOL)
        await runtime.step(3000)
        assert await c.read_by_name(X_POS, pyads.PLCTYPE_DINT) == 1_000_000


@pytest.mark.req("H-04", "C3-10", "C3-08", "C3-07")
async def test_collision_objects_on_port_551_follow_fct_c3_while_the_pair_moves(runtime: Runtime) -> None:
    machine = runtime.machine
    x1, x2 = machine.axes_by_name["X1"], machine.axes_by_name["X2"]
    layout = runtime.layout
    a_id = {a.name: a.number for a in layout.axes}
    channel = machine.channel(2)
    assert channel.select_program(1) is None  # "carriages": X1 -> 200, X2 -> 300 at F6000
    channel.request_start()
    await runtime.step(400)  # accelerating, then at feed
    t_a = machine.t_a
    async with plc(runtime, 551) as geo:
        for axis in (x1, x2):
            offset = a_id[axis.name] << 16
            active = await geo.read(0x120300, offset | 0x0234, pyads.PLCTYPE_BOOL)
            velocity = await geo.read(0x120300, offset | 0x0244, pyads.PLCTYPE_LREAL)
            brake = await geo.read(0x120300, offset | 0x0245, pyads.PLCTYPE_LREAL)
            coll_offset = await geo.read(0x120300, offset | 0x0246, pyads.PLCTYPE_UDINT)
            deceleration = await geo.read(0x120300, offset | 0x0247, pyads.PLCTYPE_LREAL)
            # C3-08: v_t = (setpoint_n - setpoint_n-1) / T_A; s_brake = v_t^2 / (2 a_coll) (units: 0.1 µm)
            v_t = (axis.setpoint - axis.prev_setpoint) / t_a  # mm/s
            a_coll = axis.a_max  # C3-07: the demo pair does not use a_emergency
            assert abs(v_t) > 50.0  # the carriages are moving
            assert active is True
            assert velocity == pytest.approx(v_t * 10_000, rel=1e-12)
            assert brake == pytest.approx(v_t * v_t / (2 * a_coll) * 10_000, rel=1e-12)
            assert coll_offset == 200_000
            assert deceleration == a_coll == 2000.0
        z1 = a_id["Z1"] << 16
        assert await geo.read(0x120300, z1 | 0x0234, pyads.PLCTYPE_BOOL) is False  # no pair


# ================================================================================================
# Routes, router messages, framing
# ================================================================================================


async def test_route_allowlist_closes_the_connection_of_an_unknown_client() -> None:
    for allow, admitted in (("10.1.2.3.1.1", True), ("10.1.2.4.1.1", False), ("192.0.2.1", False)):
        rt = await start_runtime(allow=allow)
        try:
            client = Plc(ads(rt).port or 0, timeout_ms=500)
            try:
                await client.open()
                if admitted:
                    assert await client.read_state() == (pyads.ADSSTATE_RUN, 0)
                else:
                    assert await ads_error(client.read_state()) == 1861  # as without a route
            finally:
                with contextlib.suppress(pyads.ADSError):
                    await client.close()
            assert ads(rt).stats.refused_route == (0 if admitted else 1), allow
        finally:
            await rt.stop()


async def test_router_messages_and_pipelined_requests(runtime: Runtime) -> None:
    raw = await RawClient.connect(ads(runtime).port or 0)
    try:
        raw.writer.write(encode_router_frame(0x1000, b"\x00\x00"))  # port connect, any port
        reply = await raw.next()
        assert isinstance(reply, AmsTcpFrame)
        assert reply.command == 0x1000
        assert reply.data[:6] == bytes(NetId.parse(SERVER))
        assert struct.unpack("<H", reply.data[6:])[0] >= 32768
        raw.writer.write(encode_router_frame(0x1002, b""))
        assert await raw.next() == AmsTcpFrame(0x1002, bytes(NetId.parse(SERVER)))
        # 40 requests in one write, the last one split over two writes: 40 answers in order
        x = runtime.layout.signal(COLL_OFFSET)
        frames = b"".join(
            raw.frame(CommandId.READ, ReadRequest(F020, x.offset, 4).encode()) for _ in range(40)
        )
        raw.writer.write(frames[:-10])
        await raw.writer.drain()
        await asyncio.sleep(0.02)
        raw.writer.write(frames[-10:])
        invokes = []
        for _ in range(40):
            packet = await raw.next()
            assert isinstance(packet, AmsPacket)
            assert decode_response(CommandId.READ, packet.data).data == struct.pack("<I", 200_000)  # type: ignore[union-attr]
            invokes.append(packet.header.invoke_id)
        assert invokes == list(range(raw.invoke - 39, raw.invoke + 1))
        raw.writer.write(encode_router_frame(0x0001, struct.pack("<H", 30000)))  # port close
        assert await raw.next() == AmsTcpFrame(0x0001, struct.pack("<H", 30000))
    finally:
        raw.close()


async def test_a_broken_stream_closes_only_that_connection(runtime: Runtime) -> None:
    port = ads(runtime).port or 0
    bad = await RawClient.connect(port)
    good = await RawClient.connect(port)
    try:
        bad.writer.write(b"\x34\x12\x00\x00\x00\x00garbage")  # reserved word 0x1234: not AMS/TCP
        assert await bad.closed()
        reply = await good.request(CommandId.READ_STATE, ReadStateRequest().encode())
        assert result_of(reply) == 0
    finally:
        bad.close()
        good.close()
    assert ads(runtime).stats.broken_streams == 1


# ================================================================================================
# Robustness (issue 12's bar): many clients, idle clients, floods, fuzz
# ================================================================================================


async def test_256_clients_at_once() -> None:
    rt = await start_runtime()
    clients: list[RawClient] = []
    try:
        port = ads(rt).port or 0
        clients = list(await asyncio.gather(*(RawClient.connect(port) for _ in range(256))))
        replies = await asyncio.gather(*(c.request(CommandId.READ_STATE, b"") for c in clients))
        assert all(result_of(r) == 0 for r in replies)
        assert ads(rt).connection_count == 256
    finally:
        for c in clients:
            c.close()
        await rt.stop()


async def test_idle_clients_are_closed_and_never_lock_out_a_new_one() -> None:
    rt = await start_runtime(max_connections=4, idle_timeout_s=0.4)
    try:
        port = ads(rt).port or 0
        idle = [await RawClient.connect(port) for _ in range(4)]
        await asyncio.sleep(0.15)
        newcomer = await RawClient.connect(port)  # all slots taken: the longest-idle one makes room
        assert result_of(await newcomer.request(CommandId.READ_STATE, b"")) == 0
        assert ads(rt).stats.evicted == 1
        assert await idle[0].closed(1.0)
        assert all([await c.closed(1.5) for c in idle[1:]])  # idle_timeout_s
        assert ads(rt).stats.idle_closed >= 3
        for c in [*idle, newcomer]:
            c.close()
    finally:
        await rt.stop()


async def test_a_client_that_only_watches_notifications_is_not_idle() -> None:
    rt = await start_runtime(idle_timeout_s=0.2)
    try:
        port = ads(rt).port or 0
        watcher, idle = await RawClient.connect(port), await RawClient.connect(port)
        x = rt.layout.signal(X_POS)
        payload = struct.pack("<IIIIII16s", F020, x.offset, 4, 4, 0, 0, bytes(16))  # on change: silent
        assert result_of(await watcher.request(CommandId.ADD_DEVICE_NOTIFICATION, payload)) == 0
        assert result_of(await idle.request(CommandId.READ_STATE, b"")) == 0
        assert await idle.closed(2.0)
        assert result_of(await watcher.request(CommandId.READ_STATE, b"")) == 0
        watcher.close()
        idle.close()
    finally:
        await rt.stop()


@pytest.mark.req("H-04")
async def test_a_full_house_of_busy_clients_makes_room_for_a_newcomer() -> None:
    """Issue 27, finding 3: a newcomer is never refused; the connection whose last request is oldest goes."""
    rt = await start_runtime(max_connections=3)
    try:
        port = ads(rt).port or 0
        busy = [await RawClient.connect(port) for _ in range(3)]
        for c in busy:  # busy[0] asked first, so its last request is the oldest
            assert result_of(await c.request(CommandId.READ_STATE, b"")) == 0
            await asyncio.sleep(0.02)
        late = await RawClient.connect(port)
        assert result_of(await late.request(CommandId.READ_STATE, b"")) == 0
        assert await busy[0].closed(2.0)
        assert ads(rt).stats.evicted == 1
        for c in busy[1:]:
            assert result_of(await c.request(CommandId.READ_STATE, b"")) == 0
        for c in [*busy, late]:
            c.close()
    finally:
        await rt.stop()


async def test_a_flooding_client_that_never_reads_is_bounded_and_others_are_served() -> None:
    rt = await start_runtime(max_queued_output=16 * 1024)
    try:
        port = ads(rt).port or 0
        layout = rt.layout
        flood_reader, flood = await asyncio.open_connection("127.0.0.1", port)
        raw = RawClient(flood_reader, flood)
        request = raw.frame(CommandId.READ, ReadRequest(F020, 0, layout.c2p_size).encode())
        chunk = request * 200
        sent = 0
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(1.0):
                while sent < 20_000_000:
                    flood.write(chunk)
                    await flood.drain()  # blocks once the server stops reading this client
                    sent += len(chunk)
        assert sent < 20_000_000  # the server stopped reading the flood
        other = await RawClient.connect(port)
        started = time.perf_counter()
        for _ in range(20):
            assert result_of(await other.request(CommandId.READ_STATE, b"")) == 0
        assert time.perf_counter() - started < 1.0
        await rt.step(100)  # the clock is not held up either
        assert ads(rt).stats.paused_reading >= 1
        # what the server holds for the flooder is bounded: queued answers by the high-water mark
        # plus one turn, buffered requests by one read of the socket plus one frame
        reply = 38 + 8 + layout.c2p_size
        for connection in ads(rt)._slots:
            transport = connection._transport
            assert transport is not None
            assert transport.get_write_buffer_size() <= 16 * 1024 + 32 * reply
            assert connection._decoder.pending <= 256 * 1024 + 65_584
        other.close()
        flood.close()
    finally:
        await rt.stop()


def _mutations(rng: random.Random, valid: list[bytes]) -> Iterator[bytes]:
    """Random bytes, valid frames with flipped bytes, fields set to extremes, truncated, duplicated."""
    while True:
        kind = rng.randrange(5)
        base = bytearray(rng.choice(valid))
        if kind == 0:
            yield rng.randbytes(rng.randrange(1, 80))
        elif kind == 1:
            for _ in range(rng.randrange(1, 4)):
                base[rng.randrange(len(base))] = rng.randrange(256)
            yield bytes(base)
        elif kind == 2 and len(base) > 38:
            pos = 38 + 4 * rng.randrange((len(base) - 38) // 4)
            base[pos : pos + 4] = rng.choice([b"\xff\xff\xff\xff", b"\x00\x00\x00\x00", b"\x00\x00\x00\x80"])
            yield bytes(base)
        elif kind == 3:
            yield bytes(base[: rng.randrange(1, len(base))])
        else:
            yield bytes(base) * 2


@pytest.mark.req("H-04")
async def test_fuzz_random_and_mutated_frames_never_crash_and_refusals_change_nothing(
    runtime: Runtime,
) -> None:
    """Seeded and bounded: 1500 inputs over real sockets (``HLI_ADS_FUZZ_INPUTS`` for a soak), one
    connection each. After each, the PLC->CNC half changed only by a write the server acknowledged;
    every 100 inputs the server still answers a well-formed request and the clock still runs."""
    rng = random.Random(20261123)
    layout = runtime.layout
    port = ads(runtime).port or 0
    proto = RawClient(None, None)  # type: ignore[arg-type]
    cmd, en = layout.signal(CMD_LOW), layout.signal(EN_LOW)
    unit = ads(runtime).device.symbols.find(HIGH)
    assert unit is not None
    valid = [
        proto.frame(CommandId.READ, ReadRequest(F020, 0, 16).encode()),
        proto.frame(CommandId.READ, ReadRequest(0x120300, (5 << 16) | 0x0246, 4).encode(), port=551),
        proto.frame(CommandId.WRITE, WriteRequest(F030, cmd.offset, struct.pack("<i", 7)).encode()),
        proto.frame(CommandId.WRITE, WriteRequest(F030, en.offset, b"\x01").encode()),
        proto.frame(
            CommandId.READ_WRITE,
            struct.pack("<IIII", 0xF003, 0, 4, len(CMD_LOW) + 1) + CMD_LOW.encode() + b"\0",
        ),
        proto.frame(
            CommandId.READ_WRITE, struct.pack("<IIII", 0xF080, 1, 8, 12) + struct.pack("<III", F020, 0, 4)
        ),
        proto.frame(
            CommandId.ADD_DEVICE_NOTIFICATION, struct.pack("<IIIIII16s", F020, 0, 4, 4, 0, 0, bytes(16))
        ),
        proto.frame(CommandId.READ_STATE, b""),
        encode_router_frame(0x1000, b"\x00\x00"),
        # issue 22: structures, the system service, types
        proto.frame(CommandId.READ, ReadRequest(VIEW_GROUP, unit.index_offset, unit.size).encode()),
        proto.frame(
            CommandId.WRITE,
            WriteRequest(VIEW_GROUP, unit.index_offset, struct.pack("<i?ii", 1, True, 9, 1)).encode(),
        ),
        proto.frame(CommandId.READ, ReadRequest(0xF0, 0, 16).encode(), port=10000),
        proto.frame(CommandId.READ_DEVICE_INFO, b"", port=10000),
        proto.frame(
            CommandId.READ_WRITE,
            struct.pack("<IIII", 0xF009, 0, 0xFFFF, len(unit.name) + 1) + unit.name.encode() + b"\0",
        ),
        proto.frame(
            CommandId.READ_WRITE, struct.pack("<IIII", 0xF011, 0, 0xFFFF, 22) + b"MC_CONTROL_SGN32_UNIT\0"
        ),
        proto.frame(
            CommandId.ADD_DEVICE_NOTIFICATION,
            struct.pack("<IIIIII16s", VIEW_GROUP, unit.index_offset, unit.size, 3, 10_000, 10_000, bytes(16)),
        ),
    ]
    expected = runtime.image.read_half(Direction.PLC_TO_CNC)
    closed_by_server = 0
    for n, data in enumerate(_mutations(rng, valid)):
        if n == FUZZ_INPUTS:
            break
        # one connection per input: send it, half-close, and read every answer until the server closes
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(data)
        writer.write_eof()
        received = b""
        with contextlib.suppress(ConnectionError):
            async with asyncio.timeout(3):
                while chunk := await reader.read(65536):
                    received += chunk
        writer.close()
        acknowledged_write = False
        decoder = AmsStreamDecoder()
        for frame in decoder.feed(received):
            if isinstance(frame, AmsPacket) and frame.header.command in (3, 9) and result_of(frame) == 0:
                acknowledged_write = True
        half = runtime.image.read_half(Direction.PLC_TO_CNC)
        if not acknowledged_write:
            assert half == expected, f"input {n} ({data.hex()}) changed the image without being acknowledged"
        expected = half
        if decoder.pending or not received:
            closed_by_server += 1
        if n % 100 == 99:  # now and then: the server still serves, the clock still runs
            probe = await RawClient.connect(port)
            assert result_of(await probe.request(CommandId.READ_STATE, b"")) == 0
            probe.close()
            await runtime.step(1)
    stats = ads(runtime).device.stats
    assert stats.failures == 0  # no request ended in an unexpected exception
    assert stats.requests > FUZZ_INPUTS // 3  # many inputs were frames the server decoded and answered
    assert ads(runtime).stats.broken_streams > FUZZ_INPUTS // 15  # others broke the stream and were closed
    door = ads(runtime).stats.as_dict()
    print(f"fuzz: {n} inputs, {stats.requests} requests answered, errors {stats.errors}, {door}")


# ================================================================================================
# `hli-server run` serves ADS
# ================================================================================================


async def test_run_serves_ads_on_a_free_port_printed_in_the_banner() -> None:
    proc = start_server(
        "--no-http",
        "--no-modbus",
        "--ads-port",
        "0",
        "--ams-net-id",
        "127.0.0.1.1.1",
        "--image-name",
        image_name("run"),
    )
    try:
        line = read_banner(proc)["ADS (AMS/TCP)"]
        assert "AMS NetId 127.0.0.1.1.1" in line
        port = door_port(line)
        client = Plc(port)
        await client.open()
        try:
            first = await client.read_by_name("gpCh[0]^bahn_state.cycle_r", pyads.PLCTYPE_UDINT)
            await asyncio.sleep(0.05)
            second = await client.read_by_name("gpCh[0]^bahn_state.cycle_r", pyads.PLCTYPE_UDINT)
            assert 0 <= first < second  # the realtime clock runs; reads are live
        finally:
            await client.close()
    finally:
        stop_server(proc)
    assert proc.returncode == 0


def test_layout_names_every_symbol_once() -> None:
    """The symbol table is the layout's: no two ST paths collide in the accepted spellings."""
    from hli_server.adapters.ads.symbols import SymbolTable

    layout = build_layout(load_machine(None))
    table = SymbolTable(layout)
    assert table.leaf_count == len(layout.signals)
    for s in layout.signals:
        found = table.find(s.st_path.replace("]^", "]."))
        assert found is not None
        assert found.signal is s


async def test_the_ads_transport_checks_its_layout_against_the_server(runtime: Runtime) -> None:
    """plc_clients.AdsTransport asks the symbol info of every signal (0xF082 of 0xF009) on connect."""
    from dataclasses import replace

    from plc_clients.ads import AdsTransport
    from schemas.layout import Layout, LayoutError, SignalType

    layout = runtime.layout
    port = ads(runtime).port or 0
    transport = await asyncio.to_thread(AdsTransport.connect, "127.0.0.1", port, layout=layout)
    await asyncio.to_thread(transport.close)
    sizes = {d: layout.size(d) for d in Direction}
    renamed = {layout.signals[0].st_path: {"st_path": "gpCh[0]^bahn_state.bogus_r"}}
    retyped = {X_POS: {"type": SignalType.UDINT}}
    for changes, message in (
        (renamed, r"no symbol gpCh\[0\]\^bahn_state.bogus_r"),
        (retyped, r"the layout is not the server's: here \('gpAx\[0\]\^ipo_state.cmd_pos_r', .*'UDINT'\)"),
    ):
        signals = [replace(s, **changes.get(s.st_path, {})) for s in layout.signals]
        other = Layout(
            machine="other", channels=layout.channels, axes=layout.axes, signals=signals, sizes=sizes
        )
        with pytest.raises(LayoutError, match=message):
            await asyncio.to_thread(AdsTransport.connect, "127.0.0.1", port, layout=other)


UNIT_DEF = (
    ("request_r", pyads.PLCTYPE_DINT, 1),
    ("enable_w", pyads.PLCTYPE_BOOL, 1),
    ("command_w", pyads.PLCTYPE_DINT, 1),
    ("state_r", pyads.PLCTYPE_DINT, 1),
)
"""MC_CONTROL_SGN32_UNIT as pyads' structure definition: the kernel's members in the kernel's order."""


@pytest.mark.req("B-01")
async def test_pyads_reads_and_writes_a_control_unit_as_a_structure(runtime: Runtime) -> None:
    """Issue 22: read_structure_by_name works; a whole-structure write sets the _w members and leaves
    the _r members to the CNC (docs/ads.md, Structures)."""
    low = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low"
    async with plc(runtime) as c:
        assert await c.read_structure_by_name(low, UNIT_DEF) == {
            "request_r": 0,
            "enable_w": False,
            "command_w": 0,
            "state_r": 0,
        }
        value = {"request_r": 7, "enable_w": True, "command_w": -100_000, "state_r": 99}
        await c.write_structure_by_name(low, value, UNIT_DEF)
        await runtime.step(2)
        unit = await c.read_structure_by_name(low.replace("]^", "]."), UNIT_DEF)
        assert (unit["enable_w"], unit["command_w"]) == (True, -100_000)
        assert unit["request_r"] == 0  # not supported by the kernel: always 0, whatever was written
        assert unit["state_r"] == runtime.image.read(STATE_LOW) != 99  # the CNC's monitoring state
        # a whole axis as one structure: the array element, with every unit inside
        size = ads(runtime).device.symbols.find("gpAx[0]").size  # type: ignore[union-attr]
        axis = await c.read_by_name("gpAx[0]", pyads.PLCTYPE_BYTE * size)
        assert len(axis) == size
        with pytest.raises(pyads.ADSError) as info:  # the size of the structure, or 0x705
            await c.read_structure_by_name(low, UNIT_DEF[:3])
        assert info.value.err_code == 0x705
