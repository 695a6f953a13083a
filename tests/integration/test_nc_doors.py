"""What the NC language needs of a running server, through its doors (N-02, N-05, N-07).

* programs with their subprograms: the HTTP upload of several files, the program directories of the
  machine file, ``run --program-dir`` and the pytest plugin, all ending in the machine's library;
* ``#MSG``: the typed event in ``GET /api/events`` (MQTT has its own test of every kind);
* ``#MSG SAVE``: the report file written inside the NC output directory, never elsewhere;
* V.E. variables in ``GET /api/state`` and writable by ST path over HTTP.

The engine's side (the interpreter calling ``machine.programs.find`` and emitting the events) has its
unit tests (tests/unit/test_nc_language.py); here the events are emitted as the engine emits them,
between stepped cycles.
"""

from __future__ import annotations

import os
import textwrap
from collections.abc import AsyncIterator
from pathlib import Path

import httpx
import pytest

from hli_server.runtime.nc_files import MAX_FILE_BYTES
from hli_server.testing import Harness
from schemas.config import ExternalVariableConfig
from schemas.events import NcFileWrite, NcMessage
from tests.integration.servers import http_step as step
from tests.integration.servers import read_banner, start_server, stop_server
from tests.machines import demo_config

MAIN = "%main\nN10 L UP1.NC\nN20 M30\n"
UP1 = "%UP1\nN10 G01 X1 F1000\nN20 M17\n"


@pytest.fixture
async def client(hli: Harness) -> AsyncIterator[httpx.AsyncClient]:
    async with httpx.AsyncClient(base_url=hli.http_url, timeout=10) as c:
        yield c


# --- programs and subprograms (N-02) ---------------------------------------------------------


@pytest.mark.req("N-02")
async def test_a_program_uploads_with_its_subprograms(hli: Harness, client: httpx.AsyncClient) -> None:
    files = {"UP1.NC": UP1, "cycles/drill.nc": "%drill\nM17\n"}
    r = await client.post("/api/channels/1/program", json={"text": MAIN, "name": "main.nc", "files": files})
    assert r.status_code == 200, r.text
    assert r.json()["files"] == ["UP1.NC", "cycles/drill.nc"]
    library = hli.runtime.machine.programs
    found = library.find("up1.nc")
    assert found is not None
    assert (found.text, found.origin) == (UP1, "upload:UP1.NC")
    assert library.find("cycles/drill.nc") is not None
    assert library.searched()[0] == "uploaded files"
    # the next load of the channel brings its own files: the old ones are gone
    r = await client.post("/api/channels/1/program", json={"text": MAIN, "name": "again"})
    assert r.status_code == 200, r.text
    assert library.find("UP1.NC") is None


@pytest.mark.req("N-02")
@pytest.mark.parametrize(
    ("files", "why"),
    [
        ({"../UP1.NC": UP1}, "leaves its directory"),
        ({"/etc/UP1.NC": UP1}, "is absolute"),
        ({"C:\\UP1.NC": UP1}, "is absolute"),
        ({"up1.nc": UP1, "UP1.NC": UP1}, "given twice"),
    ],
)
async def test_an_upload_that_names_a_file_outside_is_refused_whole(
    hli: Harness, client: httpx.AsyncClient, files: dict[str, str], why: str
) -> None:
    r = await client.post("/api/channels/1/program", json={"text": MAIN, "files": files})
    assert r.status_code == 422, r.text
    assert why in r.json()["detail"]
    assert hli.runtime.machine.channel(1).program_name != "program"  # nothing was loaded
    assert hli.runtime.machine.programs.find("UP1.NC") is None


@pytest.mark.req("N-02")
async def test_too_many_files_are_refused_at_the_door(client: httpx.AsyncClient) -> None:
    files = {f"F{i}.NC": "M17\n" for i in range(257)}
    r = await client.post("/api/channels/1/program", json={"text": MAIN, "files": files})
    assert r.status_code == 422


@pytest.mark.req("N-02")
async def test_a_refused_load_keeps_the_uploads(hli: Harness, client: httpx.AsyncClient) -> None:
    r = await client.post(
        "/api/channels/1/program", json={"text": "N10 G01 X50 F600\nN20 M30\n", "files": {"UP1.NC": UP1}}
    )
    assert r.status_code == 200, r.text
    assert (await client.post("/api/channels/1/start")).status_code == 202
    await step(client, 5)
    r = await client.post("/api/channels/1/program", json={"text": MAIN, "files": {"OTHER.NC": "M17\n"}})
    assert r.status_code == 409
    found = hli.runtime.machine.programs.find("UP1.NC")
    assert found is not None
    assert found.text == UP1


@pytest.mark.req("N-02")
def test_the_machine_files_program_directories_and_the_plugins_come_together(tmp_path: Path) -> None:
    machine_dir, cli_dir = tmp_path / "machine_programs", tmp_path / "mine"
    machine_dir.mkdir()
    cli_dir.mkdir()
    (machine_dir / "UP1.NC").write_text("%UP1 of the machine\nM17\n", encoding="utf-8")
    (machine_dir / "CYCLE_A").write_text("%CYCLE_A\nM17\n", encoding="utf-8")
    (cli_dir / "UP1.NC").write_text("%UP1 of the test\nM17\n", encoding="utf-8")
    config = demo_config().model_copy(update={"program_directories": [str(machine_dir)]})
    with Harness(config, program_dirs=[cli_dir]) as hli:
        library = hli.runtime.machine.programs
        assert library.searched() == (str(cli_dir.resolve()), str(machine_dir.resolve()))
        up1, cycle = library.find("UP1.NC"), library.find("CYCLE_A")
        assert up1 is not None
        assert cycle is not None
        assert up1.text.startswith("%UP1 of the test")  # the explicit directory first
        main = tmp_path / "main.nc"
        main.write_text(MAIN, encoding="utf-8")
        sub = tmp_path / "UP1.NC"
        sub.write_text(UP1, encoding="utf-8")
        answer = hli.load_program(1, main, files=[sub])
        assert (answer["program"], answer["files"]) == ("main.nc", ["UP1.NC"])
        assert hli.runtime.machine.channel(1).program_name == "main.nc"
        uploaded = library.find("UP1.NC")
        assert uploaded is not None
        assert uploaded.text == UP1  # the upload before the directories


@pytest.mark.req("N-02")
@pytest.mark.hli(program_dirs="programs_for_the_plugin")
def test_the_plugin_marker_points_at_directories_next_to_the_test(hli: Harness) -> None:
    here = Path(__file__).parent / "programs_for_the_plugin"
    assert hli.runtime.machine.programs.searched() == (str(here.resolve()),)
    found = hli.runtime.machine.programs.find("UP_PLUGIN.NC")
    assert found is not None
    assert found.text.startswith("%UP_PLUGIN")


@pytest.mark.slow
@pytest.mark.req("N-02", "N-07")
def test_run_takes_program_dirs_and_an_output_directory_and_says_so(tmp_path: Path) -> None:
    out, programs = tmp_path / "out", tmp_path / "programs"
    programs.mkdir()
    proc = start_server(
        "--clock", "stepped", "--http-port", "0", "--program-dir", str(programs), "--nc-output-dir", str(out)
    )
    try:
        banner = read_banner(proc)
        text = banner["text"]
        assert f"NC output directory (#MSG SAVE report files): {out.resolve()}" in text
        assert f"program directories (L name): {programs.resolve()}" in text
    finally:
        stop_server(proc)
    assert out.is_dir()


# --- #MSG (N-07) -----------------------------------------------------------------------------


@pytest.mark.req("N-07", "H-05")
async def test_an_nc_message_reaches_the_event_log(hli: Harness, client: httpx.AsyncClient) -> None:
    await step(client, 3)
    hli.runtime.machine.emit(
        NcMessage(
            cycle=3, time_s=0.003, channel=1, text="part 7 done", program="main.nc", line=9, block="N90"
        )
    )
    events = (await client.get("/api/events?since=0")).json()["events"]
    (message,) = [e for e in events if e["kind"] == "nc_message"]
    assert message["channel"] == 1
    assert message["data"] == {
        "text": "part 7 done", "save": False, "program": "main.nc", "line": 9, "block": "N90",
    }  # fmt: skip


# --- #MSG SAVE: report files (N-07) ------------------------------------------------------------


@pytest.mark.req("N-07", "H-05")
def test_a_report_write_event_names_the_program_line_and_block_that_wrote(tmp_path: Path) -> None:
    """``nc_file_write`` carries the program, line and block of its ``#MSG SAVE``, as ``nc_message`` does
    (issue 37, item 4: it carried ``"program": ""`` and no line or block), in a subprogram its own name."""
    program = '%main\nN10 #MSG SAVE ["first"]\nN20 L UP1.NC\nN30 M30\n'
    files = {"UP1.NC": '%UP1\nN10 #MSG SAVE ["in the subprogram"]\nN20 M17\n'}
    with Harness(nc_output_dir=tmp_path) as hli:
        hli.load_program(1, program, name="main.nc", files=files)
        hli.operator.start(1)
        finished = lambda: hli.operator.snapshot()["channels"][0]["program_state_name"] == "finished"  # noqa: E731
        hli.run_until(finished, 2000)
        events, _ = hli.runtime.events_since(0, 1000)
        writes = [e.event for e in events if isinstance(e.event, NcFileWrite)]
        messages = [e.event for e in events if isinstance(e.event, NcMessage)]
    assert [(w.program, w.line, w.block, w.text) for w in writes] == [
        ("main.nc", 2, "N10", "first"),
        ("UP1.NC", 2, "N10", "in the subprogram"),
    ]
    assert [(m.program, m.line, m.block) for m in messages] == [(w.program, w.line, w.block) for w in writes]
    assert (tmp_path / "message.txt").read_text() == "first\nin the subprogram\n"


def _write(hli: Harness, file: str, text: str, mode: str = "line") -> None:
    """A write as the channel emits it, then a cycle: the stepped clock's cycle waits for its writes."""
    hli.runtime.machine.emit(
        NcFileWrite(
            cycle=hli.cycle, time_s=0.0, channel=1, file=file, text=text, mode=mode, line=4, block="N40"
        )
    )
    hli.step(1)


@pytest.mark.req("N-07")
def test_report_files_are_written_inside_the_output_directory(tmp_path: Path) -> None:
    with Harness(nc_output_dir=tmp_path / "reports") as hli:
        assert hli.nc_files == (tmp_path / "reports").resolve()
        _write(hli, "message.txt", "Homing executed")
        _write(hli, "prog_flow.txt", "Workpiece No. 1 ", mode="continue")
        _write(hli, "prog_flow.txt", "OK")
        _write(hli, "sub/deep.txt", "below")
        assert (hli.nc_files / "message.txt").read_text() == "Homing executed\n"
        assert (hli.nc_files / "prog_flow.txt").read_text() == "Workpiece No. 1 OK\n"
        assert (hli.nc_files / "sub" / "deep.txt").read_text() == "below\n"
        assert hli.runtime.nc_files.refused == 0
        assert not hli.runtime.machine.alarm_history


@pytest.mark.req("N-07")
@pytest.mark.parametrize(
    "name", ["../escape.txt", "/tmp/escape.txt", "sub/../../escape.txt", "C:\\escape.txt"]
)
def test_a_report_file_outside_the_directory_is_refused_with_a_warning(tmp_path: Path, name: str) -> None:
    with Harness(nc_output_dir=tmp_path / "reports") as hli:
        _write(hli, name, "must not land")
        (alarm,) = hli.runtime.machine.alarm_history
        assert (alarm.number, alarm.severity, alarm.channel, alarm.line, alarm.block) == (
            919010, "warning", 1, 4, "N40",
        )  # fmt: skip
        assert repr(name) in alarm.message
        assert not hli.runtime.machine.active_alarms  # a warning: the program goes on
    assert not (tmp_path / "escape.txt").exists()
    assert not Path("/tmp/escape.txt").exists() or "must not land" not in Path("/tmp/escape.txt").read_text()


@pytest.mark.req("N-07")
def test_a_symbolic_link_in_the_output_directory_is_not_followed(tmp_path: Path) -> None:
    reports, outside = tmp_path / "reports", tmp_path / "outside"
    reports.mkdir()
    outside.mkdir()
    os.symlink(outside, reports / "link")
    os.symlink(outside / "target.txt", reports / "file.txt")
    with Harness(nc_output_dir=reports) as hli:
        _write(hli, "link/x.txt", "no")
        _write(hli, "file.txt", "no")
        assert [a.number for a in hli.runtime.machine.alarm_history] == [919010, 919010]
    assert list(outside.iterdir()) == []


@pytest.mark.req("N-07")
def test_only_regular_files_of_one_link_are_written(tmp_path: Path) -> None:
    """A named pipe (read or not), a hard link to a file elsewhere, a directory: refused with 919010, never
    waited for (issue 36, finding 2; the realtime server's test is in test_nc_robustness.py)."""
    reports, outside = tmp_path / "reports", tmp_path / "outside.txt"
    reports.mkdir()
    os.mkfifo(reports / "pipe.txt")
    os.mkfifo(reports / "read.txt")
    outside.write_text("theirs\n")
    os.link(outside, reports / "linked.txt")
    (reports / "dir.txt").mkdir()
    reader = os.open(reports / "read.txt", os.O_RDONLY | os.O_NONBLOCK)
    try:
        with Harness(nc_output_dir=reports) as hli:
            for name in ("pipe.txt", "read.txt", "linked.txt", "dir.txt", "fine.txt"):
                _write(hli, name, "x")
            messages = [a.message for a in hli.runtime.machine.alarm_history]
            assert hli.runtime.nc_files.refused == 4
            assert hli.runtime.nc_files.written == 1
    finally:
        os.close(reader)
    assert len(messages) == 4
    assert "'pipe.txt': pipe.txt is a named pipe" in messages[0]
    assert "'read.txt' is a named pipe, not a regular file" in messages[1]
    assert "'linked.txt' has 2 links" in messages[2]
    assert "dir.txt" in messages[3]
    assert outside.read_text() == "theirs\n"
    assert (reports / "fine.txt").read_text() == "x\n"


@pytest.mark.req("N-07")
def test_a_report_file_stops_growing_at_its_bound(tmp_path: Path) -> None:
    with Harness(nc_output_dir=tmp_path) as hli:
        big = "x" * (MAX_FILE_BYTES // 2)
        _write(hli, "big.txt", big)
        _write(hli, "big.txt", big)  # one byte too many with the two line ends
        assert (tmp_path / "big.txt").stat().st_size == len(big) + 1
        (alarm,) = hli.runtime.machine.alarm_history
        assert "would grow beyond" in alarm.message


@pytest.mark.req("N-07")
def test_the_default_output_directory_is_temporary_and_removed_when_empty() -> None:
    with Harness() as hli:
        directory = hli.nc_files
        assert directory.name.startswith(f"hli_nc_{os.getpid()}_")
        assert not directory.exists()  # made at the first write: a server that writes none leaves none
        _write(hli, "gone.txt", "")
        assert directory.is_dir()
        assert oct(directory.stat().st_mode & 0o777) == "0o700"
        (directory / "gone.txt").unlink()
    assert not directory.exists()  # empty at the stop: removed
    with Harness() as hli:
        _write(hli, "kept.txt", "kept")
        kept = hli.nc_files
    assert (kept / "kept.txt").read_text() == "kept\n"  # what a program wrote is not thrown away
    (kept / "kept.txt").unlink()
    kept.rmdir()


# --- V.E. variables over HTTP (N-05) ------------------------------------------------------------


VE_MACHINE = demo_config().model_copy(
    update={
        "external_variables": [
            ExternalVariableConfig(name="MODE", type="SGN16", channel=1, description="machining mode"),
            ExternalVariableConfig(name="READY", type="BOOLEAN"),
            ExternalVariableConfig(name="POS", type="REAL64", dims=[2], channel=2),
        ]
    }
)


@pytest.mark.req("N-05")
@pytest.mark.hli(machine=VE_MACHINE)
async def test_v_e_variables_are_in_the_state_and_writable_by_st_path(hli: Harness) -> None:
    async with httpx.AsyncClient(base_url=hli.http_url, timeout=10) as client:
        r = await client.put("/api/image/gpVECh[0].MODE", json={"value": 2})
        assert r.status_code == 200, r.text
        assert r.json()["st_path"] == "gpVECh[0]^MODE"
        r = await client.put("/api/image/gpVEGlob.READY", json={"value": True})
        assert r.status_code == 200, r.text
        r = await client.put("/api/image/gpVECh[0].MODE", json={"value": 40_000})
        assert r.status_code == 422
        assert "out of range for the V.E. variable" in r.json()["detail"]
        await step(client, 1)
        hli.runtime.machine.external.write("POS", 2, 1.5, (1,))
        state = (await client.get("/api/state")).json()
        assert state["external"] == [
            {"name": "V.E.MODE", "channel": 1, "symbol": "gpVECh[0]^MODE", "type": "SGN16",
             "dims": [], "value": 2},
            {"name": "V.E.READY", "channel": None, "symbol": "gpVEGlob^READY", "type": "BOOLEAN",
             "dims": [], "value": True},
            {"name": "V.E.POS", "channel": 2, "symbol": "gpVECh[1]^POS", "type": "REAL64",
             "dims": [2], "value": [0.0, 1.5]},
        ]  # fmt: skip


def test_the_plugins_program_directory_is_part_of_the_repository() -> None:
    """The directory the plugin test reads is part of the repository."""
    here = Path(__file__).parent / "programs_for_the_plugin" / "UP_PLUGIN.NC"
    assert here.read_text(encoding="utf-8") == textwrap.dedent("""\
        %UP_PLUGIN
        N10 G01 X1 F1000
        N20 M17
    """)


@pytest.mark.req("N-05", "H-04")
def test_the_ads_door_finds_a_v_e_symbol_by_its_exact_name() -> None:
    from hli_server.adapters.ads.symbols import SymbolTable
    from schemas.layout import build_layout

    table = SymbolTable(build_layout(demo_config(external=True)))
    for name in ("gpVECh[0]^S16", "gpvech[0]^s16", "gpVEGlob^S8", "gpVECh[1]^POS[1,2]"):
        found = table.find(name)
        assert found is not None, name


@pytest.mark.req("N-05", "H-04")
def test_the_ads_door_accepts_the_plc_spellings_of_a_v_e_symbol() -> None:
    from hli_server.adapters.ads.symbols import SymbolTable
    from schemas.layout import build_layout

    table = SymbolTable(build_layout(demo_config(external=True)))
    for spelling in ("gpVECh[0].S16", "gpVECh[0]^.S16", "gpVEGlob.S8", "gpVEGlob^.S8"):
        assert table.find(spelling) is not None, spelling


@pytest.mark.req("N-05", "N-02", "B-02")
def test_a_session_with_v_e_writes_and_uploaded_subprograms_records_and_replays(
    hli: Harness, tmp_path: Path
) -> None:
    """The PLC's V.E. writes are inputs like any PLC->CNC field, the files uploaded with a program are
    part of the operator's request: a recording of both replays (issue 25's recorder)."""
    from hli_server.recording.format import read_records

    path = tmp_path / "ve.jsonl.gz"
    with hli.record(path):
        hli.image["gpVEGlob^MODE"] = 2
        hli.step(3)
        hli.load_program(1, "N10 G01 X5 F6000\nN20 M30\n", files={"UP1.NC": UP1})
        hli.operator.start(1)
        hli.image["gpVEGlob^PART_COUNT"] = 7
        hli.step(400)
    assert hli.runtime.machine.external.read("MODE", None) == 2
    records = list(read_records(path))
    (load,) = [r for r in records if r.get("op") == "load_program"]
    assert load["args"]["files"] == {"UP1.NC": UP1}
    report = hli.replay(path)
    assert report.verdict.name == "PASS"
