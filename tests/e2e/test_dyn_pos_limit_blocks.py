"""MCV_DynPosLimitHigh in a PLC task stops a running program at the limit, through every transport
(C43-10, H-06; FCT-C43 3.2 with C43-04/06/07 as the server implements them).

One behaviour, run over each door to the same server (asyncua's ``opc`` fixture is the model):

* ``shm``: :class:`ShmTransport`, the PLC task in the server's event loop;
* ``modbus``: :class:`AsyncModbusTransport` (pymodbus' AsyncModbusTcpClient), same loop;
* ``modbus-sync``: :class:`ModbusTransport` (pymodbus' ModbusTcpClient) in a worker thread,
  playing a PLC that is a separate device (a blocking client cannot share the server's loop);
* ``ads``: :class:`AsyncAdsTransport` (pyads, its calls in worker threads), same loop.

The server is the real one: :class:`Runtime` with the realtime clock (T_A = 1 ms), the demo machine
and the Modbus and ADS adapters on free ports. Its layout reaches the Modbus clients as a JSON file, as
``hli-server map --format json`` writes it.
"""

from __future__ import annotations

import asyncio
import os
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from hli_server.adapters.modbus import ModbusAdapter
from hli_server.configuration import load_machine
from hli_server.runtime import Runtime
from plc_clients import (
    AXIS_REF,
    AsyncAdsTransport,
    AsyncModbusTransport,
    IoImage,
    MCV_DynPosLimitHigh,
    ModbusTransport,
    PlcTask,
    ShmTransport,
)
from schemas.wire import ProgramState

pytestmark = [pytest.mark.req("C43-10", "H-06"), pytest.mark.timeout(60)]

TRANSPORTS = ("shm", "modbus", "modbus-sync", "ads")
UNIT = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high"
X_POS = "gpAx[0]^ipo_state.cmd_pos_r"
X_MOVING = "gpAx[0]^ipo_state.moving_r"
PROGRAM_STATE = "gpCh[0]^bahn_state.program_state_r"
LIMIT = 500_000  # 50 mm in 0.1 µm
TARGET = 2_000_000  # the program moves X toward +200 mm
FEED = 6000.0  # mm/min
CYCLE_TIME_S = 0.004  # the PLC task's cycle


def image_name(tag: str) -> str:
    return f"hli_test_plc_{tag}_{os.getpid()}_{time.monotonic_ns() % 1_000_000}"


@pytest.fixture
async def runtime() -> AsyncIterator[Runtime]:
    rt = Runtime(
        load_machine(None),
        clock="realtime",
        http_port=None,
        image_name=image_name("rt"),
        adapters=[("modbus", {"port": 0}), ("ads", {"port": 0})],
    )
    async with rt:
        yield rt


@dataclass
class Plc:
    """A PLC on one transport: runs a :class:`PlcTask` until a condition, bounded in time."""

    kind: str
    transport: Any
    closers: list[Callable[[], Any]] = field(default_factory=list)

    async def run(self, task: PlcTask, until: Callable[[], bool], timeout_s: float) -> None:
        if self.kind == "modbus-sync":
            await asyncio.to_thread(task.run, until=until, timeout_s=timeout_s)
        else:
            await task.run_async(until=until, timeout_s=timeout_s)


@pytest.fixture(params=TRANSPORTS)
async def plc(request: pytest.FixtureRequest, runtime: Runtime, tmp_path: Path) -> AsyncIterator[Plc]:
    kind: str = request.param
    layout_file = tmp_path / "layout.json"
    layout_file.write_text(runtime.layout.to_json(), encoding="utf-8")  # `hli-server map --format json`
    adapter = runtime.adapter("modbus")
    assert isinstance(adapter, ModbusAdapter)
    port = adapter.port or 0
    if kind == "shm":
        shm = ShmTransport.attach(runtime.image.name)
        yield Plc(kind, shm)
        shm.close()
    elif kind == "ads":
        ads_port = int(getattr(runtime.adapter("ads"), "port", 0) or 0)
        ads = await AsyncAdsTransport.connect("127.0.0.1", ads_port, layout=layout_file)
        yield Plc(kind, ads)
        await ads.close()
    elif kind == "modbus":
        amb = await AsyncModbusTransport.connect("127.0.0.1", port, layout=layout_file)
        yield Plc(kind, amb)
        await amb.close()
    else:
        mb = await asyncio.to_thread(ModbusTransport.connect, "127.0.0.1", port, layout=layout_file)
        yield Plc(kind, mb)
        await asyncio.to_thread(mb.close)


@dataclass
class Observed:
    """What the PLC program saw, cycle by cycle (as a PLC would log it)."""

    states: list[int] = field(default_factory=list)
    valid: bool = False
    state: int = 0
    x: int = 0
    moving: bool = True
    program_state: int = 0

    def state_path(self) -> list[int]:
        """The states in the order seen, without repeats."""
        path: list[int] = []
        for s in self.states:
            if not path or path[-1] != s:
                path.append(s)
        return path


async def test_dyn_pos_limit_high_stops_x_at_the_limit_and_lifting_it_lets_the_program_finish(
    runtime: Runtime, plc: Plc
) -> None:
    x_axis = AXIS_REF.by_name(plc.transport.layout, "X")
    limit = MCV_DynPosLimitHigh()
    seen = Observed()
    enable = [True]

    def program(io: IoImage) -> None:
        limit(Axis=x_axis, Enable=enable[0], Position=LIMIT)
        seen.states.append(int(limit.State))
        seen.valid, seen.state = limit.Valid, int(limit.State)
        seen.x = int(io.read(X_POS))
        seen.moving = bool(io.read(X_MOVING))
        seen.program_state = int(io.read(PROGRAM_STATE))

    task = PlcTask(
        plc.transport,
        CYCLE_TIME_S,
        program,
        watch=[X_POS, X_MOVING, PROGRAM_STATE],
        name=f"plc-{plc.kind}",
    )

    # 1. the block sets the limit; the CNC reports it in effect
    await plc.run(task, until=lambda: seen.valid, timeout_s=3)
    assert not limit.Error, limit.ErrorText
    assert seen.state == 2  # HLI_DYNPL_STATE_ACTIVE
    unit = runtime.machine.hli.axes[0].ipo_mc_control.dyn_pos_limit_high
    assert (unit.enable_w, unit.command_w) == (True, LIMIT)

    # 2. a program moves X toward +200 mm; the limit holds it at 50 mm
    channel = runtime.machine.channel(1)
    channel.load_program(f"N10 G90 G01 X{TARGET / 10_000:g} F{FEED:g}\nN20 M30\n", "toward_200")
    channel.request_start()
    seen.states.clear()
    await plc.run(task, until=lambda: seen.state == 4 and not seen.moving, timeout_s=5)
    assert seen.valid
    path = seen.state_path()
    assert path[-3:] == [2, 3, 4], f"state_r seen by the block: {path}"  # ACTIVE, BRAKING, BRAKE
    one_cycle = FEED / 60.0 * runtime.t_a * 10_000  # travel of one CNC cycle at F, in 0.1 µm
    assert LIMIT - one_cycle <= seen.x <= LIMIT + one_cycle  # C43-06 / FCT-C43 3.2: at most one cycle
    assert seen.program_state in (ProgramState.RUNNING, ProgramState.HELD)  # held, not finished

    # it stays there while the limit is in effect
    stopped_at = seen.x
    cycles_before = task.stats.cycles
    await plc.run(task, until=lambda: task.stats.cycles >= cycles_before + 25, timeout_s=3)
    assert seen.x == stopped_at
    assert (seen.state, seen.valid) == (4, True)

    # 3. Enable FALSE lifts the limit: the program continues to its end (C43-07)
    enable[0] = False
    await plc.run(
        task, until=lambda: seen.program_state == ProgramState.FINISHED and seen.x == TARGET, timeout_s=6
    )
    assert (limit.Valid, limit.State, limit.Error, limit.ErrorID) == (False, 0, False, 0)
    assert unit.enable_w is False
    assert unit.state_r == 0
    assert task.stats.input_faults == task.stats.output_faults == 0
