"""The doors process (``hli-server run``'s default, issue 12): Modbus and ADS served by a second process
attached to the shared memory, so that network load does not compete with the cycle."""

from __future__ import annotations

import os
import signal
import struct
import time

import httpx
import pytest

from hli_server.runtime.pacing import DOORS_SLICE_NS
from plc_clients.ads import AdsTransport
from schemas.layout import Layout
from tests.integration.servers import door_port, read_banner, start_server, stop_server
from tests.scheduler import custom_slices, shown_slice

pytestmark = [pytest.mark.slow]


def _pid_of(line: str) -> int:
    return int(line.rsplit("pid ", 1)[1].rstrip("]"))


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def _modbus_write_register(port: int, address: int, value: int) -> bytes:
    import socket

    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        pdu = struct.pack(">BHHB", 16, address, 2, 4) + struct.pack(">i", value)
        s.sendall(struct.pack(">HHHB", 1, 0, len(pdu) + 1, 1) + pdu)
        head = s.recv(7)
        return s.recv(struct.unpack(">H", head[4:6])[0] - 1)


@pytest.mark.req("H-03", "H-04", "E-01")
def test_run_serves_modbus_and_ads_from_the_doors_process_and_stops_it_cleanly() -> None:
    proc = start_server("--http-port", "0", "--modbus-port", "0", "--ads-port", "0")
    try:
        banner = read_banner(proc)
        url = banner["url"]
        modbus_port = door_port(banner["Modbus TCP"])
        ads_port = door_port(banner["ADS (AMS/TCP)"])
        doors = _pid_of(banner["Modbus TCP"])
        assert doors == _pid_of(banner["ADS (AMS/TCP)"]) != proc.pid
        layout = Layout.from_dict(httpx.get(url + "/api/layout", timeout=5).json())
        command = layout.signal("gpCh[0]^bahn_mc_control.override.command_w")
        answer = _modbus_write_register(modbus_port, command.modbus_address, 430)
        assert answer[0] == 16  # written (no exception)
        r = httpx.get(url + "/api/image/gpCh[0].bahn_mc_control.override.command_w", timeout=5)
        assert r.json()["value"] == 430  # the engine's process sees the doors process' write
        ads = AdsTransport.connect("127.0.0.1", ads_port, layout=layout)
        try:
            first = ads.read("gpCh[0]^bahn_state.cycle_r")
            time.sleep(0.05)
            assert ads.read("gpCh[0]^bahn_state.cycle_r") > first  # live: the engine's publishes
            assert ads.read("gpCh[0]^bahn_mc_control.override.command_w") == 430
        finally:
            ads.close()
    finally:
        stop_server(proc)
    assert proc.returncode == 0
    deadline = time.monotonic() + 10
    while _alive(doors) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(doors)


@pytest.mark.req("H-03")
def test_the_doors_process_ends_when_the_server_is_killed() -> None:
    proc = start_server("--http-port", "0", "--modbus-port", "0")
    try:
        banner = read_banner(proc)
        doors = _pid_of(banner["Modbus TCP"])
        # the banner says which process serves the doors (run's default differs from Runtime's) and what
        # the operating system granted it
        line = next(li for li in banner["text"].splitlines() if "network doors:" in li)
        assert f"network doors: served by a second process (pid {doors}" in line
        if custom_slices():
            assert f"(pid {doors}, time slice 6 ms)" in line
            # the doors' main thread, as the scheduler shows it
            assert shown_slice(f"/proc/{doors}/sched") == DOORS_SLICE_NS
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        deadline = time.monotonic() + 10
        while _alive(doors) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(doors)  # no orphan serving a dead image
    finally:
        stop_server(proc)


@pytest.mark.req("H-03")
def test_no_doors_process_serves_modbus_in_the_engines_process() -> None:
    proc = start_server("--http-port", "0", "--modbus-port", "0", "--no-doors-process")
    try:
        banner = read_banner(proc)
        assert "doors process" not in banner["Modbus TCP"]
        assert "network doors: served in the clock's process" in banner["text"]
    finally:
        stop_server(proc)


@pytest.mark.req("H-01", "E-01")
def test_the_http_api_runs_in_the_doors_process_and_reaches_the_engine() -> None:
    """Issue 26: the HTTP API and the dashboard's streams are served off the clock's loop, by the doors
    process, which reaches the engine's operator panel and events over its link (``runtime/remote.py``)."""
    proc = start_server("--http-port", "0", "--modbus-port", "0")
    try:
        banner = read_banner(proc)
        url = banner["url"]
        doors = _pid_of(banner["HTTP control API"])
        assert doors == _pid_of(banner["Modbus TCP"]) != proc.pid
        r = httpx.post(url + "/api/channels/1/program", content="N10 G01 X20 F6000\nN20 M30\n", timeout=10)
        assert r.status_code == 200
        assert httpx.post(url + "/api/channels/1/start", timeout=10).status_code == 202
        deadline = time.monotonic() + 20
        kinds: list[str] = []
        while "finished" not in kinds and time.monotonic() < deadline:
            time.sleep(0.1)
            events = httpx.get(url + "/api/events?since=0", timeout=10).json()["events"]
            kinds = [e["data"].get("state", "") for e in events if e["kind"] == "program_state"]
        assert kinds[:3] == ["idle", "running", "finished"]  # load, start, end: the engine's events, in order
        state = httpx.get(url + "/api/state", timeout=10).json()
        assert state["channels"][0]["program_state_name"] == "finished"
        timing = httpx.get(url + "/api/timing", timeout=10).json()
        assert timing["clock"] == "realtime"
        assert timing["cycles"] > 200
        assert {"p50", "p99", "p999", "max"} <= set(timing["lateness_us"])
    finally:
        stop_server(proc)
    assert proc.returncode == 0
