"""The runtime over the real shared memory: clocks, adapters, shutdown, a second process (E-01, H-01, H-02).

Timing assertions are one-sided where the wall clock is involved: the realtime clock never runs
ahead of the wall clock (exact upper bound) and keeps up within a generous lower bound.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

import httpx
import pytest

from hli_server.adapters.registry import AdapterError, create_adapter
from hli_server.configuration import load_machine
from hli_server.runtime import Clock, ClockError, Runtime, RuntimeStateError
from hli_server.runtime.pacing import ThreadClock
from schemas.config import MachineConfig
from schemas.wire import ProgramState
from tests.integration.servers import hli_server_cmd, read_banner, start_server

PROGRAM = "N10 G01 X20 Y10 F6000\nN20 G01 X0 Y0\nN30 M30\n"


@pytest.fixture(scope="module")
def demo() -> MachineConfig:
    return load_machine(None)


def shm_exists(name: str) -> bool:
    return Path("/dev/shm", name).exists()


def unique_name(tag: str) -> str:
    return f"hli_test_{tag}_{os.getpid()}_{time.monotonic_ns() % 1_000_000}"


# --------------------------------------------------------------------------------------------
# Clocks
# --------------------------------------------------------------------------------------------


@pytest.mark.req("E-01", "H-01")
async def test_stepped_clock_advances_only_when_stepped(demo: MachineConfig) -> None:
    async with Runtime(demo, clock="stepped", http_port=None) as rt:
        await asyncio.sleep(0.05)
        assert rt.machine.cycle == 0
        ch = rt.machine.channel(1)
        ch.load_program(PROGRAM, "p")
        ch.request_start()
        assert await rt.step(100) == 100
        x = rt.machine.axis("X")
        assert ch.state == ProgramState.RUNNING
        assert x.setpoint > 0.0
        # the image carries the published cycle and positions (H-01)
        assert rt.image.read("gpAx[0]^ipo_state.cmd_pos_r") == round(x.setpoint * 10_000)
        assert rt.image.read("gpCh[0]^bahn_state.cycle_r") == 100
        await asyncio.sleep(0.02)
        assert rt.machine.cycle == 100


@pytest.mark.req("E-01")
async def test_stepped_runs_are_deterministic_cycle_by_cycle(demo: MachineConfig) -> None:
    """Same configuration, program and inputs: the same CNC->PLC image after every cycle."""

    async def trace() -> list[bytes]:
        async with Runtime(demo, clock="stepped", http_port=None) as rt:
            ch = rt.machine.channel(1)
            ch.load_program(PROGRAM, "p")
            ch.request_start()
            rt.image.write("gpCh[0]^bahn_mc_control.override.command_w", 700)
            out = []
            for k in range(300):
                if k == 100:
                    rt.image.write("gpCh[0]^bahn_mc_control.override.enable_w", True)
                await rt.step(1)
                out.append(rt.image.snapshot()[1])  # type: ignore[attr-defined]
            return out

    first, second = await trace(), await trace()
    assert first == second
    assert first[10] != first[200]


@pytest.mark.req("E-01")
async def test_step_is_refused_outside_the_stepped_clock(demo: MachineConfig) -> None:
    async with Runtime(demo, clock="realtime", http_port=None) as rt:
        with pytest.raises(ClockError, match="stepped clock"):
            await rt.step(1)


async def test_step_before_start_and_after_stop_is_an_error(demo: MachineConfig) -> None:
    rt = Runtime(demo, clock="stepped", http_port=None)
    with pytest.raises(RuntimeStateError):
        await rt.step(1)
    async with rt:
        await rt.step(1)
    with pytest.raises(RuntimeStateError):
        await rt.step(1)


@pytest.mark.req("E-01")
async def test_realtime_clock_follows_the_wall_clock(demo: MachineConfig) -> None:
    async with Runtime(demo, clock="realtime", http_port=None) as rt:
        t0 = time.monotonic()
        c0 = rt.machine.cycle
        await asyncio.sleep(0.4)
        elapsed = time.monotonic() - t0
        ran = rt.machine.cycle - c0
        # never ahead of the wall clock (the first cycle is due one T_A after the start)
        assert ran <= elapsed / rt.t_a + 1
        # and keeping up (loose: a loaded CI machine may drop some cycles)
        assert ran >= 0.5 * elapsed / rt.t_a
        timing = rt.timing()
        assert timing["clock"] == "realtime"
        assert timing["cycles"] == ran
        lateness = timing["lateness_us"]
        assert 0.0 <= lateness["p50"] <= lateness["p99"] <= lateness["max"]


@pytest.mark.req("E-01")
async def test_realtime_catches_up_after_a_late_wakeup(demo: MachineConfig) -> None:
    async with Runtime(demo, clock="realtime", http_port=None, max_catch_up=1000) as rt:
        await asyncio.sleep(0.02)
        time.sleep(0.03)  # block the event loop: 30 cycles fall due at once
        before = rt.machine.cycle
        await asyncio.sleep(0)  # one pass of the loop: the clock runs what is due
        await asyncio.sleep(0.005)
        assert rt.machine.cycle - before >= 25
        timing = rt.timing()
        assert timing["max_catch_up"] >= 25
        assert timing["catch_up_wakeups"] >= 1
        assert timing["slipped_cycles"] == 0
        assert timing["lateness_us"]["max"] >= 25_000


def _held(hold: Callable[[], None]) -> tuple[float, float]:
    """Run ``hold`` on the loop; (its wall time, the part of it this thread waited for a CPU)."""
    thread = ThreadClock()
    try:
        began, at_began = time.monotonic(), thread.read()
        hold()
        return time.monotonic() - began, thread.read()[1] - at_began[1]
    finally:
        thread.close()


@pytest.mark.req("E-01")
@pytest.mark.parametrize("holds", ["computing", "blocked"])
async def test_a_callback_that_holds_the_clocks_loop_is_named_the_cause(
    demo: MachineConfig, holds: str
) -> None:
    """Issue 26: ``GET /api/timing`` names why its worst cycles were late. A callback on the clock's loop
    that computes, or blocks in a system call, for 40 ms is the loop's doing; only the part of it in which
    the thread waited for a CPU (a loaded machine) is the operating system's."""

    def hold() -> None:
        end = time.monotonic() + 0.04
        if holds == "blocked":
            time.sleep(0.04)
        while time.monotonic() < end:
            pass

    async with Runtime(demo, clock="realtime", http_port=None, max_catch_up=1000) as rt:
        await asyncio.sleep(0.05)
        wall, waited = _held(hold)
        await asyncio.sleep(0.02)
        timing = rt.timing()
    worst = timing["worst"][0]
    assert worst["lateness_us"] >= 35_000
    loop = worst["parts_us"].get("loop", 0.0)
    assert loop >= (wall - waited) * 1e6 - 5_000, (wall, waited, worst)  # every moment it ran or blocked
    if waited < wall / 2:  # the machine gave it the CPU most of the time: the loop is the cause
        assert worst["cause"] == "loop", worst
        assert "event loop" in worst["detail"]
    assert timing["lateness_us"]["p999"] <= timing["lateness_us"]["max"]


@pytest.mark.req("E-01")
async def test_a_garbage_collection_on_the_clocks_loop_is_named_the_cause(demo: MachineConfig) -> None:
    import gc

    async with Runtime(demo, clock="realtime", http_port=None, max_catch_up=1000) as rt:
        gc.disable()
        try:
            junk = []
            for _ in range(300_000):  # cyclic garbage: only the collector frees it
                node: list[object] = []
                node.append(node)
                junk.append(node)
            del junk, node
            await asyncio.sleep(0.02)
            wall, waited = _held(gc.collect)
        finally:
            gc.enable()
        await asyncio.sleep(0.02)
        timing = rt.timing()
    worst = timing["worst"][0]
    assert timing["gc_collections"][2] >= 1
    assert worst["parts_us"].get("gc", 0.0) >= (wall - waited) * 1e6 - 5_000, (wall, waited, worst)
    if waited < wall / 2:
        assert worst["cause"] == "gc", worst
        assert "garbage collection of generation 2" in worst["detail"]


@pytest.mark.req("E-01")
async def test_realtime_catch_up_is_capped_and_the_slip_reported(
    demo: MachineConfig, caplog: pytest.LogCaptureFixture
) -> None:
    async with Runtime(demo, clock="realtime", http_port=None, max_catch_up=5) as rt:
        await asyncio.sleep(0.02)
        time.sleep(0.06)  # 60 cycles due, only 5 may be caught up
        await asyncio.sleep(0.01)
        timing = rt.timing()
        assert timing["max_catch_up"] == 5
        assert timing["slipped_cycles"] >= 50
        assert "realtime clock ran" in caplog.text
        # simulated time is now behind the wall clock by the dropped cycles
        assert timing["simulated_s"] <= timing["wall_s"] - 50 * rt.t_a


@pytest.mark.req("E-01")
async def test_free_clock_runs_faster_than_real_time_and_stays_responsive(demo: MachineConfig) -> None:
    async with Runtime(demo, clock="free", http_port=None) as rt:
        t0 = time.monotonic()
        # the loop stays responsive: short sleeps return promptly while the engine runs
        for _ in range(20):
            s0 = time.monotonic()
            await asyncio.sleep(0.001)
            assert time.monotonic() - s0 < 0.25
        elapsed = time.monotonic() - t0
        assert rt.machine.cycle > elapsed / rt.t_a


@pytest.mark.req("E-01")
@pytest.mark.parametrize("clock", ["realtime", "free"])
async def test_stop_after_cycles_is_exact(demo: MachineConfig, clock: str) -> None:
    rt = Runtime(demo, clock=clock, http_port=None, stop_after_cycles=120)
    await asyncio.wait_for(rt.serve(install_signal_handlers=False), timeout=10)
    assert rt.machine.cycle == 120
    assert rt.stopped


async def test_wait_cycle(demo: MachineConfig) -> None:
    async with Runtime(demo, clock="stepped", http_port=None) as rt:
        waiter = asyncio.create_task(rt.wait_cycle(10))
        await rt.step(5)
        await asyncio.sleep(0)
        assert not waiter.done()
        await rt.step(5)
        assert await asyncio.wait_for(waiter, 1) == 10


def test_unknown_clock_is_refused(demo: MachineConfig) -> None:
    with pytest.raises(ValueError, match="unknown clock 'fast'"):
        Runtime(demo, clock="fast")
    assert Clock("stepped") is Clock.STEPPED


@pytest.mark.req("E-01")
async def test_a_failing_cycle_does_not_end_the_server(demo: MachineConfig) -> None:
    """Issue 12: a failure inside a cycle never ends the server: the channels take alarm 919000 (their
    axes stop), the failed cycles are counted, the clock goes on, and a reset brings the machine back."""
    async with Runtime(demo, clock="stepped", http_port=None) as rt:
        ch = rt.machine.channel(1)
        working = ch.interpolate

        def broken() -> None:
            raise ZeroDivisionError("monitor bug")

        ch.interpolate = broken  # type: ignore[method-assign]
        await rt.step(50)
        assert rt.cycle == 50
        assert rt.timing()["failed_cycles"] == 50
        raised = [(a.number, a.channel) for a in rt.machine.active_alarms]
        assert raised == [(919000, 1), (919000, 2)]  # once per channel, not once per failed cycle
        assert rt.image.read("gpCh[0]^bahn_state.error_id_r") == 919000
        assert rt.image.read("gpCh[0]^bahn_state.cycle_r") == 50  # the image is still published
        ch.interpolate = working  # type: ignore[method-assign]
        rt.operator.reset(1)
        rt.operator.reset(2)
        rt.operator.load_program(1, "N10 G01 X5 F6000\nN20 M30\n")
        await rt.step(2)
        rt.operator.start(1)
        await rt.step(400)
        assert not rt.machine.active_alarms
        assert rt.image.read("gpCh[0]^bahn_state.program_state_r") == ProgramState.FINISHED


# --------------------------------------------------------------------------------------------
# Image life cycle, adapters, events
# --------------------------------------------------------------------------------------------


@pytest.mark.req("H-01")
async def test_image_exists_while_running_and_is_unlinked_after(demo: MachineConfig) -> None:
    name = unique_name("life")
    async with Runtime(demo, clock="stepped", http_port=None, image_name=name) as rt:
        assert rt.image.name == name
        assert shm_exists(name)
    assert not shm_exists(name)
    with pytest.raises(RuntimeStateError):
        _ = rt.image


class Recorder:
    def __init__(self, name: str, log: list[str], fail: bool = False) -> None:
        self.name = name
        self.log = log
        self.fail = fail
        self.image_seen: str | None = None

    async def start(self, runtime: Runtime) -> None:
        self.image_seen = runtime.image.name
        self.log.append(f"start {self.name}")
        if self.fail:
            raise OSError(f"{self.name}: address already in use")

    async def stop(self) -> None:
        self.log.append(f"stop {self.name}")

    def endpoints(self) -> list[str]:
        return [f"{self.name}: nowhere"]


async def test_adapters_start_in_order_and_stop_in_reverse(demo: MachineConfig) -> None:
    log: list[str] = []
    a, b = Recorder("a", log), Recorder("b", log)
    async with Runtime(demo, clock="stepped", adapters=[a, b]) as rt:
        assert a.image_seen == rt.image.name  # the image exists before the adapters start
        assert rt.endpoints()[1:] == ["a: nowhere", "b: nowhere"]
        assert rt.adapter("b") is b
    assert log == ["start a", "start b", "stop b", "stop a"]


async def test_a_failing_adapter_undoes_the_start(demo: MachineConfig) -> None:
    log: list[str] = []
    name = unique_name("fail")
    rt = Runtime(
        demo, clock="stepped", image_name=name, adapters=[Recorder("a", log), Recorder("b", log, fail=True)]
    )
    with pytest.raises(OSError, match="address already in use"):
        await rt.start()
    assert log == ["start a", "start b", "stop a"]
    assert not shm_exists(name)


async def test_adapters_by_registered_name(demo: MachineConfig) -> None:
    async with Runtime(demo, clock="stepped", adapters=[("http", {"port": 0})]) as rt:
        assert rt.http_url.startswith("http://127.0.0.1:")


def test_a_misspelled_adapter_option_names_the_options() -> None:
    with pytest.raises(
        AdapterError, match=r"unknown option 'prot' \(did you mean 'port'\?\); its options are: .*port"
    ):
        create_adapter("modbus", bind="127.0.0.1", options={"prot": 0})


async def test_events_are_logged_with_sequence_numbers_and_listeners_called(demo: MachineConfig) -> None:
    seen: list[str] = []
    async with Runtime(demo, clock="stepped", http_port=None) as rt:
        rt.add_event_listener(lambda e: seen.append(e.kind))
        ch = rt.machine.channel(1)
        ch.load_program(PROGRAM, "p")
        ch.request_start()
        await rt.step(1)
        ch.request_mode(1)  # refused while running: an alarm event
        await rt.step(1)
        events, latest = rt.events_since(0)
        assert [e.seq for e in events] == list(range(1, latest + 1))
        assert events[0].event.kind == "program_state"
        later, _ = rt.events_since(events[0].seq)
        assert later == events[1:]
        assert "alarm" in seen


# --------------------------------------------------------------------------------------------
# A second process on the shared memory (H-01, H-02)
# --------------------------------------------------------------------------------------------

PLC_SCRIPT = r"""
import json, sys, time
from plc_clients.shm import ImageClient

name, unit, value, timeout = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
with ImageClient.attach(name, timeout=5.0) as plc:
    before = plc.snapshot()[unit + ".state_r"]
    plc.write(unit + ".command_w", value)
    plc.write(unit + ".enable_w", True)           # arms the unit: written last
    written_at = plc.cycle                        # newest publish once the write is complete
    deadline = time.monotonic() + timeout
    while True:
        snap = plc.snapshot()
        if snap[unit + ".state_r"] != before:
            break
        if time.monotonic() > deadline:
            print(json.dumps({"error": "no change", "before": before, "cycle": snap.cycle}))
            sys.exit(1)
        time.sleep(0.0001)
    print(json.dumps({"before": before, "after": snap[unit + ".state_r"],
                      "written_at": written_at, "seen_at": snap.cycle}))
"""


async def run_plc(name: str, unit: str, value: int, timeout: float = 5.0) -> dict[str, Any]:
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-c",
        PLC_SCRIPT,
        name,
        unit,
        str(value),
        str(timeout),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=Path(__file__).resolve().parents[2],
    )
    out, err = await asyncio.wait_for(proc.communicate(), timeout=timeout + 20)
    assert proc.returncode == 0, f"PLC process failed: {out.decode()} {err.decode()}"
    result: dict[str, Any] = json.loads(out)
    return result


@pytest.mark.req("H-01", "H-02", "E-01")
async def test_second_process_writes_a_control_unit_and_sees_state_r_within_two_cycles(
    demo: MachineConfig,
) -> None:
    """A PLC process attaches to the image by name, writes command_w then enable_w of the feed
    override unit, and sees state_r follow within two published cycles (realtime clock)."""
    async with Runtime(demo, clock="realtime", http_port=None, image_name=unique_name("plc")) as rt:
        unit = rt.machine.hli.channels[0].bahn_mc_control.override
        first_changed = changed_at(rt, lambda: unit.state_r == 420)
        result = await run_plc(rt.image.name, "gpCh[0]^bahn_mc_control.override", 420)
        assert result["before"] == 1000
        assert result["after"] == 420
        # the first cycle that published the new state: at most two after the write
        assert first_changed[0] - result["written_at"] <= 2
        assert result["seen_at"] >= first_changed[0]


def changed_at(rt: Runtime, condition: Callable[[], bool]) -> list[int]:
    """Records the first published cycle for which ``condition`` holds (the client process may
    miss cycles when the clock catches up several at once, so the server side records it)."""
    first: list[int] = []

    def listener(cycle: int) -> None:
        if not first and condition():
            first.append(cycle)

    rt.on_cycle(listener)
    return first


@pytest.mark.req("H-01", "H-02", "C43-03")
async def test_second_process_writes_dyn_pos_limit_and_sees_state_r_within_two_cycles(
    demo: MachineConfig,
) -> None:
    """Issue 5, done when: a second process writes a dyn_pos_limit command and sees state_r change
    within two cycles in realtime mode, through the shared memory."""
    async with Runtime(demo, clock="realtime", http_port=None, image_name=unique_name("dpl")) as rt:
        unit = rt.machine.hli.axes[0].ipo_mc_control.dyn_pos_limit_low
        first_changed = changed_at(rt, lambda: unit.state_r != 0)
        result = await run_plc(rt.image.name, "gpAx[0]^ipo_mc_control.dyn_pos_limit_low", -1_000_000)
        assert result["before"] == 0
        assert result["after"] != 0
        assert first_changed[0] - result["written_at"] <= 2


# --------------------------------------------------------------------------------------------
# `hli-server run` as a process
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.req("H-01", "E-01")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_run_process_shuts_down_cleanly_on_signal(sig: signal.Signals) -> None:
    name = unique_name("sig")
    proc = start_server("--http-port", "0", "--modbus-port", "0", "--image-name", name)
    try:
        banner = read_banner(proc)
        assert banner["image"] == name
        assert shm_exists(name)
        state = httpx.get(banner["url"] + "/api/state", timeout=5).json()
        assert state["clock"] == "realtime"
        port = int(banner["url"].rsplit(":", 1)[1])
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=15)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert "stopped at cycle" in out
    assert not shm_exists(name)
    with pytest.raises(ConnectionRefusedError), socket.create_connection(("127.0.0.1", port), timeout=1):
        pass


@pytest.mark.slow
@pytest.mark.req("E-01")
@pytest.mark.parametrize(
    ("clock", "event_loop"), [("free", "select"), ("realtime", "select"), ("realtime", "default")]
)
def test_run_with_cycles_stops_by_itself(clock: str, event_loop: str) -> None:
    result = subprocess.run(
        [
            *hli_server_cmd(),
            "run",
            "--http-port",
            "0",
            "--modbus-port",
            "0",
            "--clock",
            clock,
            "--event-loop",
            event_loop,
            "--cycles",
            "300",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert f"clock: {clock} (T_A = 1000 µs, event loop: {event_loop}" in result.stdout
    if clock == "realtime":
        assert "priority: realtime (SCHED_FIFO 10)" in result.stdout or "priority: normal (realtime not" in (
            result.stdout
        )  # --priority auto: what the operating system granted
    assert "stopped at cycle 300 " in result.stdout
    if clock == "realtime":
        assert "lateness p50" in result.stdout


@pytest.mark.slow
def test_run_reports_a_port_in_use_with_exit_2() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        result = subprocess.run(
            [*hli_server_cmd(), "run", "--http-port", str(port), "--modbus-port", "0"],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    assert result.returncode == 2
    assert f"cannot listen on 127.0.0.1:{port}" in result.stderr
    assert "Traceback" not in result.stderr


def test_run_reports_a_bad_config_with_exit_2(tmp_path: Path) -> None:
    result = subprocess.run(
        [*hli_server_cmd(), "run", "--config", str(tmp_path / "missing.toml"), "--modbus-port", "0"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 2
    assert "missing.toml" in result.stderr


@pytest.mark.slow
@pytest.mark.req("E-07", "H-03")
def test_run_starts_the_adapters_the_machine_file_names(tmp_path: Path) -> None:
    """``[[adapters]]`` in the machine file: Modbus with the file's options; an --adapter of the
    same name replaces the entry."""
    demo = resources.files("hli_server.machines").joinpath("demo.toml").read_text(encoding="utf-8")
    machine = tmp_path / "machine.toml"
    lists = resources.files("hli_server.machines")
    for entry in lists.iterdir():
        if entry.name.endswith(".lis"):
            (tmp_path / entry.name).write_text(entry.read_text(encoding="utf-8"), encoding="utf-8")
    machine.write_text(
        demo + '\n[[adapters]]\nname = "modbus"\noptions = { port = 0, word_order = "CDAB", unit_id = 7 }\n',
        encoding="utf-8",
    )

    def run(*extra: str) -> str:
        result = subprocess.run(
            [
                *hli_server_cmd(),
                "run",
                "--config",
                str(machine),
                "--http-port",
                "0",
                "--cycles",
                "50",
                *extra,
            ],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert result.returncode == 0, result.stderr
        return result.stdout

    out = run()
    assert "unit id 7, 32-bit word order CDAB" in out
    out = run("--adapter", "modbus:port=0,word_order=ABCD")
    assert "word order ABCD" in out
    assert "unit id 7" not in out
    assert "Modbus" not in run("--no-modbus")
