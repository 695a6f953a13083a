"""The PLC-side transports against the real server (H-06; H-01 shared memory, H-03 Modbus).

Every door through the project's own pytest plugin: ``hli`` (the server in-process, stepped clock,
so that every value is known to the cycle) and ``plc_transport`` (one run per door). The asyncio
Modbus transport, the realtime clock and a server that goes away have tests of their own below.
"""

from __future__ import annotations

import asyncio
import socket
import threading

import pytest

from hli_server.configuration import load_machine
from hli_server.runtime import Runtime
from hli_server.testing import Harness
from plc_clients import (
    AXIS_REF,
    AsyncModbusTransport,
    ErrorID,
    MCV_DynPosLimitHigh,
    ModbusTransport,
    PlcTask,
    ShmTransport,
    Transport,
    TransportError,
)

pytestmark = [pytest.mark.req("H-06"), pytest.mark.timeout(60)]

CMD = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w"
EN = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.enable_w"
STATE = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.state_r"
X_POS = "gpAx[0]^ipo_state.cmd_pos_r"
COLL_OFFSET = "gpAx[4]^dyn_coll_mon.coll_offset"  # X2: 200000 (20 mm), FCT-C3 demo pair
CH1_CYCLE, CH2_CYCLE = "gpCh[0]^bahn_state.cycle_r", "gpCh[1]^bahn_state.cycle_r"


@pytest.mark.req("H-01", "H-03")
def test_snapshot_write_and_read_through_every_transport(hli: Harness, plc_transport: Transport) -> None:
    hli.step(7)
    inputs = plc_transport.snapshot([X_POS, STATE, EN, CH2_CYCLE])
    assert inputs.cycle == hli.cycle == 7
    assert inputs.consistent
    assert inputs[STATE] == 0
    assert inputs[CH2_CYCLE] == 7
    assert EN not in inputs
    assert inputs[X_POS] == hli.image[X_POS]
    plc_transport.write_many([(CMD, -123_456), (EN, True)])
    assert plc_transport.read(CMD) == -123_456
    assert plc_transport.read(EN) is True
    unit = hli.runtime.machine.hli.axes[0].ipo_mc_control.dyn_pos_limit_low
    assert (unit.command_w, unit.enable_w) == (0, False)  # latched at the next cycle
    hli.step(2)
    assert (unit.command_w, unit.enable_w) == (-123_456, True)
    assert plc_transport.read(STATE) == 2  # ACTIVATION, then ACTIVE
    plc_transport.write(EN, False)
    hli.step(1)
    assert unit.enable_w is False
    full = plc_transport.snapshot(None)
    assert full[COLL_OFFSET] == 200_000
    assert len(full.values) == len(hli.layout.half(hli.layout.signal(STATE).direction))


async def test_the_asyncio_modbus_transport(hli: Harness) -> None:
    transport = await AsyncModbusTransport.connect("127.0.0.1", hli.port("modbus"), layout=hli.layout)
    try:
        hli.step(4)
        inputs = await transport.snapshot([X_POS, STATE, CH2_CYCLE])
        assert (inputs.cycle, inputs.consistent, inputs[CH2_CYCLE]) == (4, True, 4)
        await transport.write_many([(CMD, -5), (EN, True)])
        hli.step(2)
        assert await transport.read(STATE) == 2
        assert await transport.read(CMD) == -5
    finally:
        await transport.close()


@pytest.mark.req("H-03")
@pytest.mark.hli(adapters=[("modbus", {"word_order": "CDAB", "unit_id": 9})])
def test_modbus_word_order_cdab_and_unit_id_must_match_the_server(hli: Harness) -> None:
    transport = hli.transport("modbus")  # takes the door's word order and unit id
    assert transport.codec.word_order == "CDAB"  # type: ignore[attr-defined]
    transport.write(CMD, -2)
    hli.step(1)
    assert hli.runtime.machine.hli.axes[0].ipo_mc_control.dyn_pos_limit_low.command_w == -2
    assert transport.read(COLL_OFFSET) == 200_000
    with (
        ModbusTransport.connect(
            "127.0.0.1", hli.port("modbus"), layout=hli.layout, word_order="CDAB"
        ) as wrong,
        pytest.raises(TransportError, match="0x0B") as info,
    ):
        wrong.read(COLL_OFFSET)
    assert info.value.modbus_exception == 0x0B


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port  # nothing listens there once the socket is closed


async def test_no_server_is_a_transport_error(hli: Harness) -> None:
    port = free_port()
    with pytest.raises(TransportError, match=f"127.0.0.1:{port}.*hli-server run"):
        await AsyncModbusTransport.connect("127.0.0.1", port, layout=hli.layout, timeout=1)
    with pytest.raises(TransportError, match="connecting failed"):
        ModbusTransport.connect("127.0.0.1", port, layout=hli.layout, timeout=1)
    with pytest.raises(TransportError, match="is the server running"):
        ShmTransport.attach(f"hli_nobody_{port}")


@pytest.mark.req("C43-10")
def test_a_server_that_goes_away_makes_the_block_report_a_transport_failure(
    hli: Harness, plc_transport: Transport
) -> None:
    block = MCV_DynPosLimitHigh()
    block.set_inputs(Axis=AXIS_REF(0, "X"), Enable=True, Position=300_000)
    task = PlcTask(plc_transport, 0.001, block)
    hli.run_until(lambda: block.Valid, max_cycles=10, plc=task)
    hli.stop()
    task.run_cycle()
    assert (block.Valid, block.Error, block.ErrorID) == (False, True, ErrorID.TRANSPORT_FAILURE)
    assert task.stats.input_faults == 1
    expected = {ShmTransport: "the server closed the image", ModbusTransport: "Modbus TCP 127.0.0.1"}
    assert expected.get(type(plc_transport), "") in block.ErrorText


@pytest.mark.req("H-03")
@pytest.mark.timeout(60)
async def test_modbus_snapshots_are_one_cycle_while_the_clock_runs() -> None:
    """Realtime clock: a snapshot of many requests spans several CNC cycles, yet every value in it
    comes from one publish (the snapshot register): both channels' cycle counters agree."""
    watch = [f"gpAx[{i}]^ipo_state.{f}" for i in range(6) for f in ("cmd_pos_r", "moving_r")]
    watch += [CH1_CYCLE, CH2_CYCLE]
    async with Runtime(
        load_machine(None), clock="realtime", http_port=None, adapters=[("modbus", {"port": 0})]
    ) as rt:
        port = rt.adapter("modbus").port  # type: ignore[attr-defined]
        rt.operator.load_program(1, "N10 G01 X500 F3000\nN20 M30\n")
        rt.operator.start(1)
        ready = threading.Event()

        def plc() -> list[tuple[bool, int, int, int]]:
            with ModbusTransport.connect("127.0.0.1", port, layout=rt.layout) as transport:
                assert len(transport._plan(watch)) > 5  # many requests: several CNC cycles
                ready.set()
                out = []
                for _ in range(100):
                    inputs = transport.snapshot(watch)
                    out.append(
                        (inputs.consistent, inputs.cycle, int(inputs[CH1_CYCLE]), int(inputs[CH2_CYCLE]))
                    )
                return out

        snapshots = await asyncio.to_thread(plc)
        assert ready.is_set()
        first_cycle, last_cycle = snapshots[0][1], snapshots[-1][1]
    assert last_cycle - first_cycle >= 20  # the clock ran meanwhile
    assert all(consistent and ch1 == ch2 == cycle for consistent, cycle, ch1, ch2 in snapshots)
