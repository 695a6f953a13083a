"""The cyclic PLC task and its process image (H-06; C43-10 "cyclic execution like a PLC task")."""

from __future__ import annotations

import asyncio
import logging
import time

import pytest

from hli_server.configuration import load_machine
from plc_clients import (
    AsyncMemoryTransport,
    InputNotReadyError,
    IoImage,
    MemoryImage,
    MemoryTransport,
    ModbusTransport,
    PlcTask,
    TransportError,
    current_image,
)
from plc_clients.task import LATCH_MARGIN
from schemas.layout import Layout, ReadOnlySignalError, SignalValueError, UnknownSignalError, build_layout

pytestmark = pytest.mark.req("H-06")

CMD = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w"
EN = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.enable_w"
STATE = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.state_r"
POS = "gpAx[0]^ipo_state.cmd_pos_r"


@pytest.fixture(scope="module")
def layout() -> Layout:
    return build_layout(load_machine(None))


@pytest.fixture
def image(layout: Layout) -> MemoryImage:
    return MemoryImage(layout)


def test_outputs_are_sent_at_the_end_of_the_cycle_in_write_order_and_only_when_changed(
    image: MemoryImage,
) -> None:
    values = {CMD: 5, EN: True}
    during: list[object] = []

    def program(io: IoImage) -> None:
        io.write(EN, values[EN])  # written first ...
        io.write(CMD, values[CMD])
        io.write(EN, values[EN])  # ... and again: the last write decides the order
        during.append(image.outputs[CMD])

    task = PlcTask(MemoryTransport(image), 0.001, program)
    task.run_cycle()
    assert during == [0]  # nothing is sent while the program runs
    assert [(p, v) for _, p, v in image.writes] == [(CMD, 5), (EN, True)]
    image.writes.clear()
    task.run_cycles(3)
    assert image.writes == []
    values[CMD] = 7
    task.run_cycle()
    assert [(p, v) for _, p, v in image.writes] == [(CMD, 7)]


def test_a_value_written_back_to_what_was_sent_is_not_sent(image: MemoryImage) -> None:
    io = IoImage(MemoryTransport(image))
    io.write(CMD, 3)
    io.delivered(io.outputs_to_send())
    io.write(CMD, 4)
    io.write(CMD, 3)
    assert io.outputs_to_send() == []


def test_wrong_writes_are_refused_at_once(image: MemoryImage) -> None:
    io = IoImage(MemoryTransport(image))
    with pytest.raises(ReadOnlySignalError, match="only the CNC writes it"):
        io.write(STATE, 2)
    with pytest.raises(SignalValueError, match="out of range"):
        io.write(CMD, 2**31)
    with pytest.raises(UnknownSignalError, match="did you mean"):
        io.write("gpAx[0]^ipo_mc_control.dyn_pos_limit_hgh.command_w", 1)
    assert io.outputs_to_send() == []


def test_reads_come_from_the_cycles_input_image(image: MemoryImage) -> None:
    image.set(POS, 1234)
    image.step()
    seen: list[object] = []

    def program(io: IoImage) -> None:
        seen.append(io.read(POS))
        image.set(POS, 9999)  # the CNC moves on during the cycle ...
        image.step()
        seen.append(io.read(POS))  # ... the cycle's image does not
        seen.append(io.cycle)

    PlcTask(MemoryTransport(image), 0.001, program).run_cycle()
    assert seen == [1234, 1234, 1]


def test_a_sync_transport_reads_an_unwatched_input_at_once_and_watches_it(image: MemoryImage) -> None:
    image.set(POS, 42)
    image.step()
    task = PlcTask(MemoryTransport(image, partial=True), 0.001, lambda io: None, watch=[STATE])
    task.run_cycle()
    io = task.image
    assert io.inputs is not None
    assert POS not in io.inputs
    assert STATE in io.inputs
    assert io.read(POS) == 42
    assert POS in io.watch
    task.run_cycle()
    assert io.inputs is not None
    assert POS in io.inputs


async def test_an_asyncio_transport_cannot_read_inside_the_program(image: MemoryImage) -> None:
    got: list[object] = []

    def program(io: IoImage) -> None:
        got.append(io.get(POS, -1))
        with pytest.raises(InputNotReadyError, match="has not written it"):
            io.read(CMD)

    task = PlcTask(AsyncMemoryTransport(image), 0.001, program)
    await task.run_cycle_async()
    with pytest.raises(InputNotReadyError, match="from the next cycle on"):
        task.image.read(POS)
    await task.run_cycle_async()
    assert got == [-1, 0]


def test_outputs_read_back_as_written_and_never_written_ones_from_the_transport(image: MemoryImage) -> None:
    image.outputs[CMD] = 77  # written by another door
    io = IoImage(MemoryTransport(image))
    assert io.read(CMD) == 77
    io.write(CMD, 5)
    assert io.read(CMD) == 5


def test_a_failed_input_image_raises_on_read_and_is_counted(image: MemoryImage) -> None:
    errors: list[str] = []

    def program(io: IoImage) -> None:
        try:
            io.read(POS)
        except TransportError as exc:
            errors.append(str(exc))
        assert io.fault is not None

    image.fault = TransportError("cable unplugged")
    task = PlcTask(MemoryTransport(image), 0.001, program)
    task.run_cycle()
    assert errors == ["cable unplugged"]
    assert (task.stats.input_faults, task.stats.last_fault) == (1, "cable unplugged")


def test_latched_waits_for_an_input_image_published_after_the_cnc_latched_the_write(
    image: MemoryImage,
) -> None:
    task = PlcTask(MemoryTransport(image), 0.001, lambda io: io.write(EN, True))
    io = task.image
    assert not io.latched(EN)
    task.run_cycle()  # inputs of CNC cycle 0, the write is delivered afterwards
    history = []
    for _ in range(LATCH_MARGIN + 1):
        image.step()
        task.run_cycle()
        history.append((io.cycle, io.latched(EN)))
    assert history == [(1, False), (2, False), (3, True)]


def test_current_image_is_the_tasks_inside_the_program_only(image: MemoryImage) -> None:
    inside: list[object] = []
    task = PlcTask(MemoryTransport(image), 0.001, lambda io: inside.append(current_image()))
    task.run_cycle()
    assert inside == [task.image]
    assert current_image() is None


def test_program_forms_and_bad_arguments(image: MemoryImage) -> None:
    class Block:
        def __init__(self) -> None:
            self.runs = 0

        def execute(self) -> None:
            self.runs += 1

    a, b = Block(), Block()
    PlcTask(MemoryTransport(image), 0.001, [a, b]).run_cycles(2)
    PlcTask(MemoryTransport(image), 0.001, a).run_cycle()
    assert (a.runs, b.runs) == (3, 2)
    with pytest.raises(TypeError, match="not a function block"):
        PlcTask(MemoryTransport(image), 0.001, [a, 3])  # type: ignore[list-item]
    with pytest.raises(TypeError, match="program must be"):
        PlcTask(MemoryTransport(image), 0.001, 3)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="cycle_time_s"):
        PlcTask(MemoryTransport(image), 0, a)


async def test_sync_and_async_runners_refuse_the_wrong_transport(image: MemoryImage, layout: Layout) -> None:
    with pytest.raises(TypeError, match="run_cycle_async"):
        PlcTask(AsyncMemoryTransport(image), 0.001, lambda io: None).run_cycle()
    blocking = ModbusTransport("127.0.0.1", 1, layout=layout)  # not connected: nothing is sent
    with pytest.raises(TypeError, match="blocks on the network"):
        await PlcTask(blocking, 0.001, lambda io: None).run_cycle_async()
    blocking.close()


def test_run_is_paced_and_stops_after_cycles_or_a_condition(image: MemoryImage) -> None:
    task = PlcTask(MemoryTransport(image), 0.002, lambda io: None)
    t0 = time.monotonic()
    assert task.run(cycles=5) == 5
    assert time.monotonic() - t0 >= 4 * 0.002  # four waits between five cycles
    assert task.stats.cycles == 5
    assert task.run(until=lambda: task.stats.cycles >= 8) == 3
    with pytest.raises(TimeoutError, match="within the timeout"):
        task.run(until=lambda: False, timeout_s=0.02)


def test_overruns_are_counted_reported_and_the_missed_ticks_skipped(
    image: MemoryImage, caplog: pytest.LogCaptureFixture
) -> None:
    late: list[float] = []

    def slow(io: IoImage) -> None:
        time.sleep(0.0035)  # the program itself is slower than the 1 ms cycle

    task = PlcTask(MemoryTransport(image), 0.001, slow, name="slow", on_overrun=lambda t, s: late.append(s))
    with caplog.at_level(logging.WARNING, logger="plc_clients.task"):
        task.run(cycles=3)
    assert task.stats.overruns == 3
    assert len(late) == 3
    assert min(late) > 0.001
    assert task.stats.skipped_ticks >= 2 * 3  # at least two ticks pass during each 3.5 ms cycle
    assert task.stats.max_exec_s > 0.0035
    assert any("slow: cycle 1 took" in r.getMessage() for r in caplog.records)  # logged once a second


async def test_the_asyncio_runner_and_start_stop(image: MemoryImage) -> None:
    def cnc_follows(io: IoImage) -> None:
        image.step()  # the twin's CNC runs one cycle per task cycle here

    task = PlcTask(AsyncMemoryTransport(image), 0.001, cnc_follows)
    assert await task.run_async(cycles=3) == 3
    runner = task.start()
    with pytest.raises(RuntimeError, match="running already"):
        task.start()
    while task.stats.cycles < 6:
        await asyncio.sleep(0.001)
    task.stop()
    await task.wait_stopped()
    assert runner.done()
    assert runner.result() >= 3
    assert image.cycle == task.stats.cycles
