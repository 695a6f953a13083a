"""Recording a session and replaying it (issue 25, B-02): the runtime on the stepped clock, an image in
memory, the recording in a temporary file; every test replays what it recorded."""

from __future__ import annotations

import dataclasses
import gzip
import json
import struct
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from hli_server.configuration import load_machine
from hli_server.image import ProcessImage
from hli_server.recording.format import FORMAT_VERSION, RecordingError, Records, read_header, read_records
from hli_server.recording.inspect import summarize, write_csv, write_plot, write_vcd
from hli_server.recording.tap import RecordingOptions
from hli_server.replay import Verdict, replay
from hli_server.runtime import Runtime, memory_image
from schemas.config import MachineConfig, ProgramEntry
from tests.spec_examples import CIRC_PROT_OLD

pytestmark = pytest.mark.req("B-02")

PROGRAM = "N10 G01 X50 Y20 F6000\nN20 G02 X70 Y40 I10 J10\nN30 G01 X0 Y0\nN40 M30\n"
OVERRIDE = "gpCh[0]^bahn_mc_control.override.command_w"
OVERRIDE_ENABLE = "gpCh[0]^bahn_mc_control.override.enable_w"
CMD_X = "gpAx[0]^ipo_state.cmd_pos_r"


def demo() -> MachineConfig:
    return load_machine(None)


@pytest.fixture
async def runtime() -> AsyncIterator[Runtime]:
    async with Runtime(
        demo(), clock="stepped", http_port=None, adapters=[], image_factory=memory_image
    ) as rt:
        yield rt


async def scenario(rt: Runtime, path: Path, *, lead: int = 0) -> None:
    """``lead`` cycles with a PLC input before the recording starts, then a program with an override
    change in the middle and a refused request."""
    rt.image.write(OVERRIDE, 500)
    rt.image.write(OVERRIDE_ENABLE, True)
    await rt.step(lead)
    rt.session.start(path)
    rt.operator.load_program(1, PROGRAM, "part")
    rt.operator.start(1)
    await rt.step(400)
    rt.image.write(OVERRIDE, 1000)
    await rt.step(1500)
    with pytest.raises(Exception, match="outside"):
        rt.operator.override(1, 5000)  # refused: recorded with its refusal
    await rt.step(200)
    rt.session.stop()


async def test_a_recorded_session_replays_cycle_for_cycle(runtime: Runtime, tmp_path: Path) -> None:
    path = tmp_path / "s.jsonl.gz"
    await scenario(runtime, path)
    header = read_header(path)
    assert header["format_version"] == FORMAT_VERSION
    assert header["window_start"] == 1
    assert header["config"]["name"] == "demo"
    records = list(read_records(path))
    assert records[-1]["end"] == "stopped"
    ops = [r for r in records if "op" in r]
    assert [r["op"] for r in ops] == ["load_program", "start", "override"]
    assert ops[0]["args"]["text"] == PROGRAM  # the program's text travels with the recording
    assert ops[2]["error"].startswith("InvalidRequestError")
    inputs = [entry[0] for entry in header["inputs"]]
    changed = [r for r in records if "i" in r]
    assert len(changed) == 2  # the first cycle (every signal) and the override's change
    assert changed[1]["c"] == 401
    assert inputs[changed[1]["i"][0]] == OVERRIDE
    assert changed[1]["i"][1] == 1000

    report = await replay(path)
    assert report.verdict is Verdict.PASS, report.text()
    assert report.last_cycle == 2100
    assert report.exit_status == 0


def _rewrite(path: Path, change: Any) -> Path:
    """The recording with ``change(record)`` applied to each line (one gzip member; a forged file)."""
    out = path.with_name("forged.jsonl.gz")
    records = [change(r) for r in read_records(path)]
    with gzip.open(out, "wt", encoding="ascii") as f:
        for r in records:
            if r is not None:  # None: the line left out
                f.write(json.dumps(r) + "\n")
    return out


async def test_a_different_output_is_reported_with_cycle_signal_expected_and_actual(
    runtime: Runtime, tmp_path: Path
) -> None:
    path = tmp_path / "s.jsonl.gz"
    await scenario(runtime, path)
    index = [e[0] for e in read_header(path)["outputs"]].index(CMD_X)
    forged_at: list[tuple[int, int]] = []

    def forge(record: dict[str, Any]) -> dict[str, Any]:
        flat = record.get("o")
        if flat and record["c"] >= 700 and not forged_at and index in flat[0::2]:
            k = flat[0::2].index(index) * 2
            forged_at.append((record["c"], flat[k + 1]))
            flat[k + 1] += 7
        return record

    forged = _rewrite(path, forge)
    cycle, value = forged_at[0]
    report = await replay(forged)
    assert report.verdict is Verdict.DIFFER
    first = report.first
    assert first is not None
    assert (first.cycle, first.signal, first.expected, first.actual) == (cycle, CMD_X, value + 7, value)
    assert report.exit_status == 1
    assert f"cycle {cycle}" in report.text()
    assert CMD_X in report.text()

    # all differences: the forged value is expected until the next recorded change of the signal
    every = await replay(forged, all_differences=True)
    assert every.counts[CMD_X][0] >= 1
    assert every.counts[CMD_X][1] == cycle
    # --signals: the other outputs only, no difference; --until before the forgery: none either
    assert (await replay(forged, signals=["gpAx[1]^*"])).verdict is Verdict.PASS
    assert (await replay(forged, until=cycle - 1)).verdict is Verdict.PASS


async def test_a_change_in_the_engine_shows_up(runtime: Runtime, tmp_path: Path) -> None:
    path = tmp_path / "s.jsonl.gz"
    await scenario(runtime, path)

    def softer_drive(machine: Any) -> None:
        axis = machine.axis("X")
        axis.drive = dataclasses.replace(axis.drive, kv=axis.drive.kv * 0.8)

    report = await replay(path, prepare=softer_drive)
    assert report.verdict is Verdict.DIFFER
    assert report.first is not None
    assert report.first.signal.startswith("gpAx[0]^")


async def test_a_recording_started_in_a_running_server_replays_from_its_input_journal(
    runtime: Runtime, tmp_path: Path
) -> None:
    path = tmp_path / "late.jsonl.gz"
    runtime.operator.load_program(1, "N10 G01 X30 F30000\nN20 M30\n", "first")
    runtime.operator.start(1)
    await scenario(runtime, path, lead=900)  # the first program's inputs are in the journal only
    header = read_header(path)
    assert header["window_start"] == 901
    assert header["journal"]["complete"] is True
    report = await replay(path)
    assert report.verdict is Verdict.PASS, report.text()
    assert report.window_start == 901
    assert (report.started_from, report.cycles) == ("snapshot", report.cycles_compared)

    # the same as a recording of format version 2 (no snapshot): from its journal, as before, with a note
    def version_2(record: dict[str, Any]) -> dict[str, Any] | None:
        if record.get("record") == "header":
            record["format_version"] = 2
            del record["snapshot"], record["snapshot_note"]
        return None if "snapshot" in record else record

    old = await replay(_rewrite(path, version_2))
    assert old.verdict is Verdict.PASS, old.text()
    assert (old.started_from, old.first_cycle, old.cycles) == ("journal", 1, old.last_cycle)
    assert old.cycles_compared == old.last_cycle - 900
    assert any("holds no snapshot" in note and "900 cycles before" in note for note in old.notes)


async def test_a_dropped_journal_leaves_a_late_recording_its_snapshot(tmp_path: Path) -> None:
    """Past the journal's limit a recording started late still replays from its snapshot; only a replay
    that must start from the journal (another engine, or asked to) cannot."""
    options = RecordingOptions(journal_limit=64)  # bytes: the first member passes it
    async with Runtime(
        demo(), clock="stepped", http_port=None, adapters=[], image_factory=memory_image, recording=options
    ) as rt:
        rt.operator.load_program(1, PROGRAM, "part")
        await rt.step(10)
        rt.session.flush()
        rt.session._flush_journal_text()
        assert rt.session.journal_lost_at is not None
        path = tmp_path / "late.jsonl.gz"
        rt.session.start(path)
        await rt.step(10)
        rt.session.stop()
    report = await replay(path)
    assert report.verdict is Verdict.PASS, report.text()
    assert report.started_from == "snapshot"
    from_journal = await replay(path, from_journal=True)
    assert from_journal.verdict is Verdict.CANNOT
    assert from_journal.reason is not None
    assert "journal" in from_journal.reason
    assert from_journal.exit_status == 3
    assert "not replayable there" in summarize(path).text()


async def test_program_files_the_engine_reads_are_recorded_and_served_to_the_replay(tmp_path: Path) -> None:
    program = tmp_path / "part.nc"
    program.write_text(PROGRAM, encoding="utf-8")
    base = demo()
    channels = list(base.channels)
    channels[0] = channels[0].model_copy(
        update={"programs": [ProgramEntry(number=7, name="part", path=str(program))]}
    )
    config = base.model_copy(update={"channels": channels})
    path = tmp_path / "file.jsonl.gz"
    async with Runtime(
        config,
        clock="stepped",
        http_port=None,
        adapters=[],
        image_factory=memory_image,
        recording=RecordingOptions(file=path),
    ) as rt:
        rt.image.write("gpCh[0]^mc_command.program_select_w", 7)  # the PLC selects it
        await rt.step(2)
        rt.operator.start(1)
        await rt.step(2000)
    program.write_text("N10 G01 X-50 F6000\nN20 M30\n", encoding="utf-8")  # the file changed since
    files = [r for r in read_records(path) if "file" in r]
    assert [(r["file"], r["text"]) for r in files] == [(str(program), PROGRAM)]
    report = await replay(path)
    assert report.verdict is Verdict.PASS, report.text()


async def test_a_given_configuration_must_equal_the_recorded_one(runtime: Runtime, tmp_path: Path) -> None:
    path = tmp_path / "s.jsonl.gz"
    await scenario(runtime, path)
    same = await replay(path, config=demo())
    assert same.verdict is Verdict.PASS
    other = demo().model_copy(update={"cycle_time_us": 2000})
    report = await replay(path, config=other)
    assert report.verdict is Verdict.CANNOT
    assert report.reason is not None
    assert "configuration mismatch" in report.reason
    assert "cycle_time_us" in report.reason


async def test_version_mismatch_replays_with_a_note_or_refuses_with_same_version(
    runtime: Runtime, tmp_path: Path
) -> None:
    path = tmp_path / "s.jsonl.gz"
    await scenario(runtime, path)

    def older(record: dict[str, Any]) -> dict[str, Any]:
        if record.get("record") == "header":
            record["server"]["version"] = "0.0.1"
        return record

    forged = _rewrite(path, older)
    report = await replay(forged)
    assert report.verdict is Verdict.PASS
    assert "versions differ" in report.text()
    strict = await replay(forged, same_version=True)
    assert strict.verdict is Verdict.CANNOT
    assert strict.reason is not None
    assert "version mismatch" in strict.reason
    assert "0.0.1" in strict.reason


async def test_what_is_no_recording_cannot_be_replayed(tmp_path: Path) -> None:
    plain = tmp_path / "x.jsonl.gz"
    with gzip.open(plain, "wt") as f:
        f.write('{"hello": 1}\n')
    report = await replay(plain)
    assert report.verdict is Verdict.CANNOT
    assert "not an hli-server recording" in (report.reason or "")
    newer = tmp_path / "n.jsonl.gz"
    with gzip.open(newer, "wt") as f:
        f.write(json.dumps({"record": "header", "format": "hli-recording", "format_version": 99}) + "\n")
    report = await replay(newer)
    assert report.verdict is Verdict.CANNOT
    assert "newer" in (report.reason or "")
    junk = tmp_path / "j.jsonl.gz"
    junk.write_bytes(b"not gzip at all")
    assert (await replay(junk)).verdict is Verdict.CANNOT


async def test_a_crash_leaves_everything_up_to_the_last_flush_readable(
    runtime: Runtime, tmp_path: Path
) -> None:
    path = tmp_path / "crash.jsonl.gz"
    runtime.session.start(path)
    runtime.operator.load_program(1, PROGRAM, "part")
    runtime.operator.start(1)
    await runtime.step(600)
    runtime.session.flush()  # one complete member up to here
    flushed = path.stat().st_size
    await runtime.step(600)
    runtime.session.flush()
    data = path.read_bytes()
    # the server dies while writing its next member: half of it reached the disk
    path.write_bytes(data + data[flushed : flushed + (len(data) - flushed) // 2][:200])
    info = Records()
    records = list(read_records(path, info))
    assert info.truncated is not None
    assert "incomplete" in info.truncated
    assert "end" not in records[-1]
    # the outputs are sampled every 100 cycles from the window's first (format 2): the last line flushed
    # is the sample of cycle 1101 (the program runs, its outputs change)
    assert records[-1]["c"] == 1101
    report = await replay(path)
    assert report.verdict is Verdict.PASS, report.text()
    assert report.last_cycle == 1101
    assert any("incomplete" in n for n in report.notes)
    # a file cut inside its header's member is no recording (yet)
    path.write_bytes(data[:30])
    with pytest.raises(RecordingError, match="no complete header"):
        list(read_records(path))


async def test_a_stalled_publish_is_recorded_and_replayed(runtime: Runtime, tmp_path: Path) -> None:
    path = tmp_path / "stall.jsonl.gz"
    runtime.session.start(path)
    runtime.operator.load_program(1, PROGRAM, "part")
    runtime.operator.start(1)
    await runtime.step(100)
    before = runtime.image.snapshot()[0]
    runtime.comm_faults.add({"kind": "stall", "cycles": 50})
    await runtime.step(30)
    assert runtime.image.snapshot()[0] == before  # the PLC sees the old cycle
    await runtime.step(30)
    assert runtime.image.snapshot()[0] == runtime.machine.cycle  # published again
    runtime.session.stop()
    faults = [r for r in read_records(path) if "fault" in r]
    assert [(r["fault"], r["c"]) for r in faults] == [("set", 101), ("end", 151)]
    assert (await replay(path)).verdict is Verdict.PASS


async def test_record_show_counts_what_is_in_a_recording(runtime: Runtime, tmp_path: Path) -> None:
    path = tmp_path / "s.jsonl.gz"
    await scenario(runtime, path)
    summary = summarize(path)
    assert summary.end == "stopped"
    assert summary.truncated is None
    assert summary.last_cycle == 2100
    assert summary.duration_s() == pytest.approx(2.1)
    assert OVERRIDE in summary.inputs
    assert summary.inputs[OVERRIDE][1] == 401
    assert CMD_X in summary.outputs
    assert "gpCh[0]^bahn_state.cycle_r" not in summary.outputs  # counts the cycles: not stored
    assert summary.programs[0]["name"] == "part"
    assert [o["op"] for o in summary.operator] == ["load_program", "start", "override"]
    assert summary.events["program_state"] >= 2
    text = summary.text()
    assert "part" in text
    assert OVERRIDE in text


async def test_exports_csv_vcd_and_a_plot(runtime: Runtime, tmp_path: Path) -> None:
    path = tmp_path / "s.jsonl.gz"
    await scenario(runtime, path)
    csv_file = tmp_path / "s.csv"
    with open(csv_file, "w", encoding="utf-8") as out:
        rows = write_csv(path, out, [CMD_X, OVERRIDE])
    lines = csv_file.read_text().splitlines()
    assert lines[0] == f"cycle,time_s,{OVERRIDE},{CMD_X}"
    assert len(lines) == rows + 1
    last = lines[-1].split(",")
    assert int(last[2]) == 1000
    assert int(last[3]) == runtime.image.read(CMD_X)

    from vcd.reader import TokenKind, tokenize

    vcd_file = tmp_path / "s.vcd"
    with open(vcd_file, "w", encoding="ascii") as out:
        changes = write_vcd(path, out, ["gpAx[0]^*", OVERRIDE])
    with open(vcd_file, "rb") as f:
        tokens = list(tokenize(f))
    names = {t.var.reference for t in tokens if t.kind is TokenKind.VAR}
    assert {"cmd_pos_r", "command_w"} <= names
    kinds = (TokenKind.CHANGE_SCALAR, TokenKind.CHANGE_VECTOR, TokenKind.CHANGE_REAL)
    variables = sum(1 for t in tokens if t.kind is TokenKind.VAR)
    assert changes <= sum(1 for t in tokens if t.kind in kinds) <= changes + variables  # + $dumpvars
    timescale = next(t for t in tokens if t.kind is TokenKind.TIMESCALE).timescale
    assert (int(timescale.magnitude), str(timescale.unit.value)) == (1, "us")
    stamps = [t.time_change for t in tokens if t.kind is TokenKind.CHANGE_TIME]
    assert all(s % 1000 == 0 for s in stamps)
    assert stamps[-1] <= 2100 * 1000

    png = tmp_path / "s.png"
    assert write_plot(path, png, [CMD_X, OVERRIDE]) == 2
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(RecordingError, match="no recorded signal"):
        write_plot(path, tmp_path / "x.png", ["nothing*"])


async def test_recording_refuses_a_second_start_and_an_existing_file(
    runtime: Runtime, tmp_path: Path
) -> None:
    path = tmp_path / "s.jsonl.gz"
    runtime.session.start(path)
    with pytest.raises(RecordingError, match="runs already"):
        runtime.session.start(tmp_path / "t.jsonl.gz")
    runtime.session.stop()
    with pytest.raises(RecordingError, match="exists already"):
        runtime.session.start(path)
    with pytest.raises(RecordingError, match="no recording runs"):
        runtime.session.stop()


async def test_a_full_recording_is_closed_and_the_server_goes_on(tmp_path: Path) -> None:
    path = tmp_path / "full.jsonl.gz"
    options = RecordingOptions(file=path, max_bytes=4096)
    async with Runtime(
        demo(), clock="stepped", http_port=None, adapters=[], image_factory=memory_image, recording=options
    ) as rt:
        rt.operator.load_program(1, PROGRAM, "part")
        rt.operator.start(1)
        for _ in range(40):
            await rt.step(100)
            rt.session.flush()
        assert not rt.session.recording
        assert rt.session.error is not None
        assert "limit" in rt.session.error
        assert rt.machine.cycle == 4000
    records = list(read_records(path))
    assert records[-1]["end"] == "full"
    assert path.stat().st_size <= 4096 + 200


def test_the_in_cycle_work_is_a_comparison_and_an_append() -> None:
    """The tap keeps raw bytes in the cycle; a cycle whose halves did not change adds nothing."""
    from hli_server.recording.tap import SessionTap

    tap = SessionTap(demo())
    tap._recording_out = True
    tap._last_in = b"\x00" * 4
    tap._last_out = bytearray(b"\x01" * 4)
    tap.after_cycle(5, b"\x00" * 4, bytearray(struct.pack("<Q", 5) + b"\x01" * 4))
    assert tap._pending == []
    tap.after_cycle(6, b"\x00\x00\x00\x01", bytearray(struct.pack("<Q", 6) + b"\x01" * 4))
    assert [(kind, cycle) for kind, cycle, _ in tap._pending] == [(0, 6)]


async def test_subprograms_the_library_found_are_recorded_and_found_again_by_the_replay(
    tmp_path: Path,
) -> None:
    from hli_server.engine.programs import MemoryLibrary
    from hli_server.replay import Feeder, ReplayReport

    path = tmp_path / "sub.jsonl.gz"
    async with Runtime(
        demo(), clock="stepped", http_port=None, adapters=[], image_factory=memory_image
    ) as rt:
        rt.machine.programs.inner = MemoryLibrary({"UP1.NC": "%UP1\nN10 G01 X5 F600\nM17\n"})  # type: ignore[attr-defined]
        rt.session.start(path)
        await rt.step(3)
        # what the interpreter does for `L UP1.NC` and `L MISSING.NC`
        assert rt.machine.programs.find("up1.nc") is not None
        assert rt.machine.programs.find("MISSING.NC") is None
        await rt.step(3)
        rt.session.stop()
    finds = [r for r in read_records(path) if "program_file" in r]
    assert [(r["program_file"], r["found"]) for r in finds] == [("up1.nc", "UP1.NC"), ("MISSING.NC", None)]
    assert finds[0]["text"].startswith("%UP1")
    assert finds[1]["searched"] == ["uploaded files"]
    records = read_records(path)
    header = next(records)
    feeder = Feeder(header, records, Records(), ReplayReport(path=str(path)), signals=None, events=True,
                    all_differences=False, max_differences=10, until=None)  # fmt: skip
    for record in read_records(path):
        if "program_file" in record:
            feeder.library_finds.setdefault(record["program_file"], __import__("collections").deque()).append(
                record
            )
    found = feeder.find("up1.nc")
    assert found is not None
    assert found.text.startswith("%UP1")
    assert found.origin == "upload:UP1.NC"
    assert feeder.find("MISSING.NC") is None
    assert feeder.searched() == ("uploaded files",)
    assert (await replay(path)).verdict is Verdict.PASS


async def test_software_limits_set_by_the_operator_are_inputs_of_the_recording(
    runtime: Runtime, tmp_path: Path
) -> None:
    path = tmp_path / "limits.jsonl.gz"
    runtime.session.start(path)
    runtime.operator.set_soft_limits("X", swe_pos=300_000)  # 30 mm in effect: the program is refused
    runtime.operator.update_axis_record("Y", swe_neg=-10_000_000)
    runtime.operator.load_program(1, PROGRAM, "part")
    runtime.operator.start(1)
    await runtime.step(800)
    runtime.session.stop()
    ops = [(r["op"], r["args"]) for r in read_records(path) if "op" in r]
    assert ops[0] == ("set_soft_limits", {"axis": "X", "swe_pos": 300_000})
    assert ops[1] == ("update_axis_record", {"axis": "Y", "swe_neg": -10_000_000})
    assert summarize(path).alarm_count >= 1
    assert (await replay(path)).verdict is Verdict.PASS

    def no_limit(record: dict[str, Any]) -> dict[str, Any]:  # a harmless request in its place
        if record.get("op") == "set_soft_limits":
            return {**record, "op": "reset", "args": {"channel": 2}}
        return record

    report = await replay(_rewrite(path, no_limit))
    assert report.verdict is Verdict.DIFFER  # without the limit the program runs: the outputs differ


async def _recorded(tmp_path: Path, every: int) -> Path:
    path = tmp_path / f"every{every}.jsonl.gz"
    async with Runtime(
        demo(),
        clock="stepped",
        http_port=None,
        adapters=[],
        image_factory=memory_image,
        recording=RecordingOptions(directory=tmp_path, outputs_every=every),
    ) as rt:
        await scenario(rt, path)
    return path


def _output_cycles(path: Path) -> list[int]:
    return [r["c"] for r in read_records(path) if "o" in r]


async def test_the_outputs_are_sampled_every_n_cycles_and_the_events_kept_at_their_cycle(
    tmp_path: Path,
) -> None:
    """Format 2: the outputs every ``outputs_every`` cycles from the window's first (and the last cycle),
    the inputs and events at their own cycle; 1 stores every cycle that changed (format 1's way)."""
    sampled = await _recorded(tmp_path, 100)
    assert read_header(sampled)["outputs_every"] == 100
    cycles = _output_cycles(sampled)
    assert cycles[0] == 1
    assert all((c - 1) % 100 == 0 for c in cycles[:-1])
    assert cycles[-1] == 2100  # the recording's last cycle is a sample as well
    every = await _recorded(tmp_path, 1)
    events = [(r["c"], r["e"]) for r in read_records(sampled) if "e" in r]
    assert events
    assert events == [(r["c"], r["e"]) for r in read_records(every) if "e" in r]  # at their own cycle
    assert len(_output_cycles(every)) > 10 * len(cycles)  # the axes move: nearly every cycle
    assert sampled.stat().st_size * 5 < every.stat().st_size
    for path in (sampled, every):
        report = await replay(path)
        assert report.verdict is Verdict.PASS, report.text()
        assert report.last_cycle == 2100


async def test_a_difference_between_two_samples_shows_at_the_next_sample(tmp_path: Path) -> None:
    """The replay compares the outputs at the samples: a forged sample is found at its cycle, with the
    signal, the expected and the actual value; and a version 1 file (no ``outputs_every``) is compared at
    every cycle."""
    path = await _recorded(tmp_path, 100)
    index = [e[0] for e in read_header(path)["outputs"]].index(CMD_X)
    forged_at: list[int] = []

    def forge(record: dict[str, Any]) -> dict[str, Any]:
        flat = record.get("o")
        if flat and record["c"] >= 700 and not forged_at and index in flat[0::2]:
            k = flat[0::2].index(index) * 2
            forged_at.append(record["c"])
            flat[k + 1] += 7
        return record

    report = await replay(_rewrite(path, forge))
    assert report.verdict is Verdict.DIFFER
    assert report.first is not None
    assert (report.first.cycle, report.first.signal) == (forged_at[0], CMD_X)
    assert forged_at[0] % 100 == 1

    def version_1(record: dict[str, Any]) -> dict[str, Any]:
        if record.get("record") == "header":
            record = {k: v for k, v in record.items() if k != "outputs_every"}
            record["format_version"] = 1
        return record

    # read as version 1, the samples alone look like outputs that stood still between them
    old = await replay(_rewrite(path, version_1))
    assert old.verdict is Verdict.DIFFER
    assert old.first is not None
    assert old.first.cycle == 2


async def test_the_replay_packs_the_outputs_only_where_it_compares_them_and_the_events_of_every_cycle(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Between two samples nobody reads a replay's CNC->PLC half: the runtime packs it only at the cycles
    the replay compares (docs/performance.md, issue 38): the samples of the grid, and the cycles with
    events (a record of events carries the outputs of its cycle); an event forged off the grid is found
    at its own cycle."""
    path = await _recorded(tmp_path, 7)
    samples = _output_cycles(path)
    packed_at: list[int] = []
    publish_from = ProcessImage.publish_from

    def counting(self: ProcessImage, machine: Any, cycle: int, *, commit: bool = True) -> bytearray:
        packed_at.append(cycle)
        return publish_from(self, machine, cycle, commit=commit)

    monkeypatch.setattr(ProcessImage, "publish_from", counting)
    report = await replay(path)
    assert report.verdict is Verdict.PASS, report.text()
    assert report.last_cycle == 2100
    grid = {c for c in range(1, 2101) if (c - 1) % 7 == 0}
    assert set(samples) <= grid | {2100} | {r["c"] for r in read_records(path) if "e" in r}
    assert set(packed_at) == {0} | grid | set(samples)  # 0: the start-up's publish; nothing between
    monkeypatch.undo()

    off_grid = [r["c"] for r in read_records(path) if "e" in r and (r["c"] - 1) % 7]
    assert off_grid, "the scenario has events off the grid of samples"
    forged_at = off_grid[-1]

    def forge(record: dict[str, Any]) -> dict[str, Any]:
        if record.get("c") == forged_at and "e" in record:
            record["e"] = record["e"][1:]  # one event the engine raises is missing from the recording
        return record

    forged = await replay(_rewrite(path, forge))
    assert forged.verdict is Verdict.DIFFER
    assert forged.first is not None
    assert (forged.first.cycle, forged.first.signal) == (forged_at, "events")


# --------------------------------------------------------------------------------------------
# a recording started in a running server: its snapshot (issue 37, item 2)
# --------------------------------------------------------------------------------------------

# a program that keeps the machine busy: an active protection cylinder (centre (150, 0), radius 50) beside
# the path, a loop whose counter and a PLC-written V.E. variable steer it, arcs
BUSY = (
    CIRC_PROT_OLD
    + "N50 G01 X0 Y-100 Z0 F6000\n"
    + "N60 #CONTROL AREA ON [ID4]\n"
    + "N70 $FOR P1 = 1, 1000, 1\n"
    + "N80   P2 = V.E.MODE * 3 + P1 / 10\n"
    + "N90   G01 X[40 + P2] Y-100\n"
    + "N100  G02 X[40 + P2] Y-80 I0 J10\n"
    + "N110  G01 X0 Y-80\n"
    + "N120  G01 X0 Y-100\n"
    + "N130 $ENDFOR\n"
    + "N140 M30\n"
)
DPL_HIGH = "gpAx[1]^ipo_mc_control.dyn_pos_limit_high"


async def busy(rt: Runtime, lead: int) -> None:
    """The machine at work for ``lead`` cycles: the program above, the override, a dynamic position limit
    and a V.E. variable the PLC wrote, a fault injected into X's drive."""
    rt.image.write(OVERRIDE, 700)
    rt.image.write(OVERRIDE_ENABLE, True)
    rt.image.write("gpVEGlob^MODE", 2)
    rt.image.write(DPL_HIGH + ".command_w", 500_000)  # Y <= 50 mm: never reached, monitored all along
    rt.image.write(DPL_HIGH + ".enable_w", True)
    rt.operator.inject_faults("X", gain_factor=0.9)
    rt.operator.load_program(1, BUSY, "busy")
    rt.operator.start(1)
    await rt.step(lead)


@pytest.mark.req("E-01")
async def test_a_recording_started_late_replays_its_own_cycles_from_its_snapshot(
    runtime: Runtime, tmp_path: Path
) -> None:
    """A recording started 6,000 cycles into a run carries the machine's state there: the replay runs its
    1,000 cycles, not 7,000, and the report counts the cycles replayed and compared apart (before: the
    replay ran the server's whole input journal, and its cycles/s mixed the two counts)."""
    path = tmp_path / "late.jsonl.gz"
    await busy(runtime, 6000)
    assert runtime.machine.channel(1).state == 1  # running: mid-loop, mid-block
    runtime.session.start(path)
    await runtime.step(300)
    runtime.image.write(OVERRIDE, 1000)
    runtime.image.write("gpVEGlob^MODE", 3)
    await runtime.step(700)
    runtime.session.stop()
    header = read_header(path)
    assert header["format_version"] == FORMAT_VERSION == 4
    assert header["snapshot"]["cycle"] == 6000
    assert header["snapshot_note"] is None
    report = await replay(path)
    assert report.verdict is Verdict.PASS, report.text()
    assert (report.started_from, report.first_cycle, report.last_cycle) == ("snapshot", 6001, 7000)
    assert (report.cycles, report.cycles_compared) == (1000, 1000)
    assert "1,000 cycles compared (cycles 6,001..7,000" in report.text()
    assert "1,000 cycles replayed from the snapshot of cycle 6,000 in" in report.text()
    assert report.to_json()["cycles_replayed"] == 1000
    # the same recording from the input journal: every cycle since the server's first, compared alike
    journal = await replay(path, from_journal=True)
    assert journal.verdict is Verdict.PASS, journal.text()
    assert (journal.started_from, journal.cycles, journal.cycles_compared) == ("journal", 7000, 1000)
    assert "7,000 cycles replayed from the input journal (cycles 1..7,000)" in journal.text()
    assert "starts from: the snapshot of cycle 6,000" in summarize(path).text()


@pytest.mark.req("E-01")
async def test_the_snapshot_holds_what_the_next_cycles_depend_on(runtime: Runtime, tmp_path: Path) -> None:
    """A change in the engine after the snapshot shows up in the replay (the snapshot is state, not the
    outputs): with X's drive made softer before the first replayed cycle, X's actual position differs."""
    path = tmp_path / "late.jsonl.gz"
    await busy(runtime, 3000)
    runtime.session.start(path, outputs_every=1)
    await runtime.step(500)
    runtime.session.stop()
    assert (await replay(path)).verdict is Verdict.PASS

    def softer(machine: Any) -> None:
        axis = machine.axis("X")
        axis.drive = dataclasses.replace(axis.drive, kv=axis.drive.kv * 0.5)

    report = await replay(path, prepare=softer)
    assert report.verdict is Verdict.DIFFER
    assert report.started_from == "snapshot"
    assert report.first is not None
    assert report.first.cycle <= 3010


async def test_a_state_that_cannot_be_kept_leaves_the_replay_the_journal_and_says_why(
    runtime: Runtime, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A path check installed at run time as a lambda (a function made at run time) cannot be kept as
    data: the recording says so, names where it is, and the replay runs the journal from cycle 1."""
    path = tmp_path / "late.jsonl.gz"
    runtime.machine.channel(2).decoder.path_checks.append(lambda segment, block: None)
    await busy(runtime, 800)
    runtime.session.start(path)
    await runtime.step(200)
    runtime.session.stop()
    header = read_header(path)
    assert header["snapshot"] is None
    assert "machine.channels[1].decoder.path_checks[" in header["snapshot_note"]
    assert "<lambda>" in header["snapshot_note"]
    assert "a replay runs the input journal from cycle 1" in caplog.text
    assert "starts from: the input journal, cycle 1 (no snapshot (" in summarize(path).text()
    report = await replay(path)
    assert report.verdict is Verdict.PASS, report.text()
    assert (report.started_from, report.cycles, report.cycles_compared) == ("journal", 1000, 200)
    assert any(
        "the recording holds no snapshot" in note and "800 cycles before" in note for note in report.notes
    )


async def test_a_snapshot_of_another_engine_leaves_the_replay_the_journal_a_forged_one_is_refused(
    runtime: Runtime, tmp_path: Path
) -> None:
    path = tmp_path / "late.jsonl.gz"
    await busy(runtime, 800)
    runtime.session.start(path)
    await runtime.step(200)
    runtime.session.stop()

    def other_engine(record: dict[str, Any]) -> dict[str, Any]:
        if record.get("record") == "header":
            record["snapshot"]["fingerprint"] = "0" * 32
        return record

    report = await replay(_rewrite(path, other_engine))
    assert report.verdict is Verdict.PASS, report.text()
    assert report.started_from == "journal"
    assert any("snapshot is of another engine" in note for note in report.notes)

    def hostile(record: dict[str, Any]) -> dict[str, Any]:
        if "snapshot" in record and isinstance(record["snapshot"], dict) and "objects" in record["snapshot"]:
            root = record["snapshot"]["objects"][record["snapshot"]["root"]["r"]]
            root["state"]["cycle"] = {"fn": "os:system"}
        return record

    # the fingerprint is this engine's: a snapshot it cannot restore is damaged or forged, refused with
    # the file, the line and the field (never run, never a traceback); the journal is the user's choice
    forged = _rewrite(path, hostile)
    report = await replay(forged)
    assert report.verdict is Verdict.CANNOT, report.text()
    for said in (f"{forged}: line ", ": snapshot: ", "'os:system' is no function", "--from-journal"):
        assert said in report.reason, report.reason
    report = await replay(forged, from_journal=True)
    assert report.verdict is Verdict.PASS, report.text()
    assert report.started_from == "journal"


async def test_a_stall_in_effect_when_the_recording_starts_goes_on_in_the_replay(
    runtime: Runtime, tmp_path: Path
) -> None:
    path = tmp_path / "stall.jsonl.gz"
    await busy(runtime, 500)
    runtime.comm_faults.add({"kind": "stall", "cycles": 300})
    await runtime.step(100)
    runtime.session.start(path)
    await runtime.step(400)
    runtime.session.stop()
    (snapshot,) = [r for r in read_records(path) if "snapshot" in r and r.get("record") != "header"]
    assert [f["spec"]["cycles"] for f in snapshot["faults"]] == [200]  # what is left of it at cycle 600
    assert (await replay(path)).verdict is Verdict.PASS
