"""The integration harness (H-07) through its own fixtures: ``hli``, ``hli_machine``, ``plc_transport``.

The plugin's own tests use the plugin: every test here takes the fixtures a user takes. What the
harness promises: the stepped clock (nothing runs between steps), exact stepping, the operator
panel and the image by ST path, ``run_until`` with its report, per-cycle traces as arrays, doors on
free ports, a clean stop, and an image that needs no ``/dev/shm``.
"""

from __future__ import annotations

import socket
from pathlib import Path

import httpx
import numpy as np
import pytest

from hli_server.configuration import load_machine
from hli_server.testing import (
    TRANSPORTS,
    ConditionNotMetError,
    Harness,
    HarnessError,
    TransportKind,
    open_transport,
    unavailable,
)
from plc_clients import AsyncModbusTransport, ShmTransport, TransportError
from schemas.layout import ReadOnlySignalError, UnknownSignalError
from schemas.wire import ProgramState

pytestmark = pytest.mark.req("H-07")

X = "gpAx[0]^ipo_state.cmd_pos_r"
CYCLE = "gpCh[0]^bahn_state.cycle_r"
PROGRAM_STATE = "gpCh[0]^bahn_state.program_state_r"
OVERRIDE = "gpCh[0]^bahn_mc_control.override"
PROBE = "gpCh[0]^mc_command.probe_w"
SHORT_PROGRAM = "N10 G01 X5 F6000\nN20 M30\n"
MILL3 = Path(__file__).resolve().parents[1] / "data" / "mill3.toml"


def test_the_clock_runs_only_when_stepped_and_steps_exactly(hli) -> None:
    assert (hli.cycle, hli.image[CYCLE]) == (0, 0)
    hli.operator.load_program(1, SHORT_PROGRAM)
    hli.operator.start(1)
    assert hli.cycle == 0  # requests do not run cycles
    assert hli.step(7) == 7
    assert (hli.cycle, hli.image[CYCLE], hli.runtime.machine.cycle) == (7, 7, 7)
    assert hli.step() == 8
    assert hli.t_a == 0.001


def test_operator_requests_are_latched_at_the_next_cycle(hli) -> None:
    hli.operator.load_program(1, SHORT_PROGRAM)
    accepted = hli.operator.start(1)
    assert (accepted.cycle, accepted.effective_cycle) == (0, 1)
    assert hli.image[PROGRAM_STATE] == ProgramState.IDLE
    hli.step(1)
    assert hli.image[PROGRAM_STATE] == ProgramState.RUNNING
    assert hli.operator.snapshot()["channels"][0]["program_state_name"] == "running"


def test_the_image_by_st_path(hli) -> None:
    hli.image[f"{OVERRIDE}.command_w"] = 500
    hli.image[f"{OVERRIDE}.enable_w"] = True
    assert hli.image[f"{OVERRIDE}.state_r"] == 1000  # latched at the next cycle, not before
    hli.step(1)
    assert hli.image[f"{OVERRIDE}.state_r"] == 500
    assert hli.image.outputs()[f"{OVERRIDE}.enable_w"] is True
    assert hli.image.snapshot()["cycle"] == 1
    with pytest.raises(ReadOnlySignalError):
        hli.image[f"{OVERRIDE}.state_r"] = 700
    with pytest.raises(UnknownSignalError, match="did you mean"):
        hli.image["gpAx[0]^ipo_state.cmd_pos"]


def test_run_until_returns_the_cycles_it_ran(hli) -> None:
    assert hli.run_until(lambda: True, max_cycles=100) == 0  # true already: no cycle
    hli.operator.load_program(1, SHORT_PROGRAM)
    hli.operator.start(1)
    ran = hli.run_until(lambda: hli.image[PROGRAM_STATE] == ProgramState.FINISHED, max_cycles=1000)
    assert 50 < ran < 1000
    assert hli.cycle == ran
    assert hli.image[X] == 50_000


def test_run_until_reports_the_last_cycles_when_the_condition_never_comes(hli) -> None:
    hli.operator.load_program(1, "N10 G01 X1 F6000\nN20 M30\n")
    hli.operator.start(1)
    hli.step(2)
    with pytest.raises(ConditionNotMetError) as failure:
        hli.run_until(lambda: hli.image[X] > 200_000, max_cycles=20, show=[f"{OVERRIDE}.state_r"])
    report = str(failure.value)
    assert report.startswith("condition not met within 20 cycles (cycles 3..22):")
    assert "hli.run_until(lambda: hli.image[X] > 200_000, max_cycles=20" in report  # the test's own line
    lines = report.splitlines()
    assert "the last 8 cycles: the channels' state and the signals that changed" in lines
    header = next(line for line in lines if line.strip().startswith("cycle "))
    assert header.split()[1:] == [str(c) for c in range(15, 23)]
    x_row = next(line for line in lines if line.strip().startswith(X)).split()
    assert len(x_row) == 9  # the signal and eight values: X moved in these cycles
    assert [int(v) for v in x_row[1:]] == sorted(int(v) for v in x_row[1:])
    assert any(line.strip().startswith(f"{OVERRIDE}.state_r") for line in lines)  # show=
    assert any(line.strip().startswith(f"{PROGRAM_STATE}  ") and "running" in line for line in lines)
    assert lines[-1] == "active alarms: none"


def test_the_report_lists_the_active_alarms(hli) -> None:
    hli.operator.load_program(1, "N10 G01 X1 F6000\nN20 G01 X700\nN30 M30\n")  # X700: past the soft limit
    hli.operator.start(1)
    with pytest.raises(ConditionNotMetError) as failure:
        hli.run_until(lambda: hli.image[PROGRAM_STATE] == ProgramState.FINISHED, max_cycles=200)
    lines = str(failure.value).splitlines()
    alarms = lines[lines.index("active alarms:") + 1 :]
    assert len(alarms) == 1
    assert alarms[0].startswith("  120002 (error, channel 1, axis X): axis X: programmed path reaches 700")
    assert any(line.strip().startswith(PROGRAM_STATE) and line.endswith("aborted") for line in lines)


def test_run_until_names_a_condition_given_by_name_or_what(hli) -> None:
    def never() -> bool:
        return False

    with pytest.raises(ConditionNotMetError, match=r"never\(\)"):
        hli.run_until(never, max_cycles=2)
    with pytest.raises(ConditionNotMetError, match="X reaches the obstacle"):
        hli.run_until(never, max_cycles=2, what="X reaches the obstacle")


def test_trace_records_chosen_signals_every_cycle_as_arrays(hli) -> None:
    hli.operator.load_program(1, SHORT_PROGRAM)
    hli.operator.start(1)
    seen = []
    with hli.trace(X, PROBE, PROGRAM_STATE) as recording:
        for k in range(20):
            if k == 10:
                hli.image[PROBE] = True
            hli.step(1)
            seen.append(hli.image[X])
        hli.run_until(lambda: hli.image[PROGRAM_STATE] == ProgramState.FINISHED, max_cycles=1000)
    hli.step(5)  # after the recording: not in the trace
    trace = recording.trace()
    assert trace.cycles == list(range(1, len(trace) + 1))
    assert trace.cycles[-1] == hli.cycle - 5
    x = trace[X]
    assert x.dtype == np.int32
    assert x[:20].tolist() == seen
    assert x[-1] == 50_000
    assert np.all(np.diff(x) >= 0)
    probe = trace[PROBE]  # a PLC->CNC signal: as the cycle latched it
    assert probe.dtype == np.bool_
    assert probe.tolist()[:12] == [False] * 10 + [True] * 2
    assert trace.at(3)[PROGRAM_STATE] == ProgramState.RUNNING
    with pytest.raises(KeyError, match="was not traced"):
        trace["gpAx[1]^ipo_state.cmd_pos_r"]
    with pytest.raises(UnknownSignalError):
        hli.trace("gpAx[0]^no_such_signal")


def test_a_step_from_inside_a_condition_is_refused(hli) -> None:
    with pytest.raises(HarnessError, match="from inside a condition"):
        hli.run_until(lambda: hli.step(1), max_cycles=3)
    assert hli.step(1) == 1  # the harness still works


def test_doors_open_once_on_free_ports(hli) -> None:
    modbus = hli.serve("modbus")
    assert hli.serve("modbus") is modbus
    assert hli.port("modbus") > 0
    answer = httpx.get(hli.http_url + "/api/state", timeout=10).json()
    assert (answer["clock"], answer["cycle"]) == ("stepped", 0)
    assert sorted(a.name for a in hli.runtime.adapters) == ["http", "modbus"]


async def test_an_async_test_uses_the_same_fixture(hli) -> None:
    """The server runs in a thread of its own: an asyncio client in the test's loop talks to it."""
    transport = await AsyncModbusTransport.connect("127.0.0.1", hli.port("modbus"), layout=hli.layout)
    try:
        hli.step(3)
        inputs = await transport.snapshot([X, PROGRAM_STATE])
        assert inputs.cycle == 3
    finally:
        await transport.close()


def test_the_image_needs_no_dev_shm(hli) -> None:
    assert hli.runtime.image.backing == "memory"  # type: ignore[attr-defined]
    assert not Path("/dev/shm", hli.image.name).exists()
    assert hli.runtime.endpoints()[0].startswith("memory image: hli_")


@pytest.mark.hli(image="shm")
def test_the_marker_puts_the_image_into_dev_shm(hli) -> None:
    assert Path("/dev/shm", hli.image.name).exists()
    with hli.transport("shm") as transport:
        hli.step(2)
        assert transport.snapshot().cycle == 2


@pytest.mark.hli(machine="../data/mill3.toml")
def test_the_marker_names_the_machine_file(hli) -> None:
    assert hli.layout.machine == "mill3"
    assert hli.t_a == 0.002
    assert [a.name for a in hli.layout.axes] == ["X", "Y", "Z"]


@pytest.mark.parametrize("hli_machine", [MILL3, load_machine(MILL3)], ids=["file", "config"])
def test_the_hli_machine_fixture_can_be_parametrized(hli) -> None:
    assert hli.layout.machine == "mill3"


def test_the_harness_stops_cleanly() -> None:
    with Harness(adapters=["modbus"]) as hli:
        port = hli.port("modbus")
        own = hli.transport("shm")  # closed by the harness
        transport = ShmTransport.over(hli.runtime.image.buffer)  # the test's own: sees the server go
        image = hli.image
        hli.step(3)
    assert own.client._closed
    assert hli._thread is not None
    assert not hli._thread.is_alive()
    with pytest.raises(ConnectionRefusedError), socket.create_connection(("127.0.0.1", port), timeout=2):
        pass
    with pytest.raises(TransportError, match="closed"):
        transport.snapshot()
    with pytest.raises(ValueError, match="released"):
        image.read(X)
    with pytest.raises(HarnessError, match="does not run"):
        hli.step(1)


def test_a_misspelt_machine_option_of_the_harness_is_refused() -> None:
    with pytest.raises(ValueError, match="image='tmpfs'"):
        Harness(image="tmpfs")  # type: ignore[arg-type]


def test_the_doors_registry_says_why_a_door_is_missing(hli, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(
        TRANSPORTS,
        "canopen",
        TransportKind(
            "canopen", "a fieldbus", lambda h: h.transport("shm"), requires=("no_such_module_hli",)
        ),
    )
    assert unavailable("canopen") == (
        "the canopen transport needs no_such_module_hli, which this installation does not have"
    )
    with pytest.raises(LookupError, match="no_such_module_hli"):
        open_transport(hli, "canopen")
    assert "registered: shm, modbus" in (unavailable("profibus") or "")
    monkeypatch.setitem(
        TRANSPORTS, "canopen", TransportKind("canopen", "a fieldbus", lambda h: h.transport("shm"))
    )
    assert unavailable("canopen") is None
    assert open_transport(hli, "canopen").layout.hash == hli.layout.hash


def test_the_ads_door_is_skipped_with_its_reason_until_it_exists() -> None:
    reason = unavailable("ads")
    try:
        import plc_clients.ads  # type: ignore[import-not-found]  # noqa: F401
    except ImportError:
        assert reason is not None
        assert "plc_clients.ads" in reason
    else:  # pragma: no cover - once the ADS transport is merged
        assert reason is None or "adapter 'ads'" in reason


def test_a_door_that_cannot_open_fails_the_start_and_leaves_nothing_running() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        harness = Harness(adapters=[("modbus", {"port": port})])
        with pytest.raises(OSError, match=f"cannot listen on 127.0.0.1:{port}"):
            harness.start()
    assert harness._thread is not None
    assert not harness._thread.is_alive()
    harness.stop()  # nothing left to stop: no error
    with pytest.raises(HarnessError, match="does not run"):
        harness.step(1)
