"""The Modbus transports' one body (issue 28 item 1): the blocking and the asyncio transport run the same
sans-I/O core, so they send the same requests in the same order and read the answers the same way
(H-03 snapshot consistency, H-06 the transport protocol). A scripted client stands in for pymodbus."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

import pytest

from hli_server.configuration import load_machine
from plc_clients.transports import CYCLE_SIGNAL, AsyncModbusTransport, ModbusTransport, TransportError
from schemas.layout import MODBUS_SNAPSHOT_REGISTER, Layout, build_layout

pytestmark = pytest.mark.req("H-03", "H-06")


@dataclass
class _Answer:
    bits: list[bool] = field(default_factory=list)
    registers: list[int] = field(default_factory=list)
    exception_code: int = 0

    def isError(self) -> bool:  # noqa: N802 - pymodbus' name
        return self.exception_code != 0


class _ScriptedClient:
    """Answers reads with zeros, logs every call; the snapshot register answers ``snapshot_exception``
    when set (an older server: 0x02)."""

    def __init__(self, snapshot_exception: int = 0) -> None:
        self.log: list[tuple[str, tuple[Any, ...]]] = []
        self.snapshot_exception = snapshot_exception

    def _read(self, name: str, address: int, count: int) -> _Answer:
        self.log.append((name, (address, count)))
        if name in ("read_coils", "read_discrete_inputs"):
            return _Answer(bits=[False] * count)
        regs = [0] * count
        return _Answer(registers=regs)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("read_"):
            return lambda address, count, device_id: self._read(name, address, count)
        if name == "write_register":

            def write_register(address: int, value: int, device_id: int) -> _Answer:
                self.log.append((name, (address, value)))
                if address == MODBUS_SNAPSHOT_REGISTER and self.snapshot_exception:
                    return _Answer(exception_code=self.snapshot_exception)
                return _Answer()

            return write_register
        if name in ("write_coil", "write_registers"):
            return lambda address, value, device_id: self.log.append((name, (address, value))) or _Answer()
        raise AttributeError(name)

    def close(self) -> None:
        pass


class _AsyncScriptedClient(_ScriptedClient):
    def __getattr__(self, name: str) -> Any:
        sync = super().__getattr__(name)

        async def call(*args: Any, **kwargs: Any) -> Any:
            return sync(*args, **kwargs)

        return call


@pytest.fixture(scope="module")
def layout() -> Layout:
    return build_layout(load_machine(None))


def _pair(layout: Layout, snapshot_exception: int = 0) -> tuple[ModbusTransport, AsyncModbusTransport]:
    class Sync(ModbusTransport):
        def _make_client(self, host: str, port: int, timeout: float) -> Any:
            return _ScriptedClient(snapshot_exception)

    class Async(AsyncModbusTransport):
        def _make_client(self, host: str, port: int, timeout: float) -> Any:
            return _AsyncScriptedClient(snapshot_exception)

    return Sync(layout=layout), Async(layout=layout)


async def _run_both(layout: Layout, snapshot_exception: int = 0) -> tuple[list[Any], list[Any]]:
    sync, aio = _pair(layout, snapshot_exception)
    watch = ["gpAx[0]^ipo_state.act_pos_r", "gpAx[1]^ipo_state.act_pos_r", "gpCh[0]^bahn_state.mode_r"]
    s_in = sync.snapshot(watch)
    a_in = await aio.snapshot(watch)
    assert (s_in.cycle, s_in.consistent, dict(s_in.values)) == (
        a_in.cycle,
        a_in.consistent,
        dict(a_in.values),
    )
    assert sync.read("gpAx[0]^ipo_state.act_pos_r") == await aio.read("gpAx[0]^ipo_state.act_pos_r")
    items = [("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w", -5), ("gpCh[0]^mc_command.probe_w", True)]
    sync.write_many(items)
    await aio.write_many(items)
    return sync._client.log, aio._client.log


def test_both_transports_send_the_same_requests_in_the_same_order(layout: Layout) -> None:
    sync_log, async_log = asyncio.run(_run_both(layout))
    assert sync_log == async_log
    # several requests: the snapshot froze first, the single read of an input thawed it
    assert sync_log[0] == ("write_register", (MODBUS_SNAPSHOT_REGISTER, 1))
    assert ("write_register", (MODBUS_SNAPSHOT_REGISTER, 0)) in sync_log
    assert [name for name, _ in sync_log[-2:]] == ["write_registers", "write_coil"]  # in the given order


def test_without_the_snapshot_register_both_read_the_cycle_before_and_after(layout: Layout) -> None:
    sync_log, async_log = asyncio.run(_run_both(layout, snapshot_exception=0x02))
    assert sync_log == async_log
    cycle_address = layout.signal(CYCLE_SIGNAL).modbus_address
    reads_of_cycle = [
        i
        for i, (name, (start, count)) in enumerate(sync_log)
        if name == "read_input_registers" and start <= cycle_address < start + count
    ]
    # the first read holds the cycle counter, and one more after the others
    assert reads_of_cycle[0] == 1  # right after the refused freeze
    assert len(reads_of_cycle) >= 2
    assert sum(1 for name, a in sync_log if a == (MODBUS_SNAPSHOT_REGISTER, 1)) == 1  # asked once, not again


def test_another_exception_of_the_snapshot_register_is_the_callers_error(layout: Layout) -> None:
    sync, aio = _pair(layout, snapshot_exception=0x04)
    with pytest.raises(TransportError, match="0x04") as sync_error:
        sync.snapshot()
    with pytest.raises(TransportError, match="0x04") as async_error:
        asyncio.run(aio.snapshot())
    assert sync_error.value.modbus_exception == async_error.value.modbus_exception == 0x04
