"""Hostile recordings (issue 36, finding 6), through the commands a user runs: ``hli-server record show`` and
``hli-server replay``. A recording is input like any other: every line is checked against the header
(``recording/format.py``, ``RecordChecker``) and what the replay will do with it (``replay.py``), and the
answer names the file, the line and the field; the replay runs no further than the recording's own last
cycle. The seeded fuzzer: ``tests/unit/test_fuzz_inputs.py``, ``test_fuzz_recordings_end_in_a_verdict_...``.
"""

from __future__ import annotations

import asyncio
import copy
import json
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from hli_server.configuration import load_machine
from hli_server.recording.format import gzip_member, read_records
from hli_server.recording.tap import RecordingOptions
from hli_server.runtime import Runtime
from tests.integration.servers import hli_server_cmd
from tests.recordings import record_late

pytestmark = [pytest.mark.slow, pytest.mark.req("B-02")]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, Any]]:
    """A real recording's lines: a program with a subprogram loaded and run for 300 cycles."""
    path = tmp_path_factory.mktemp("recorded") / "session.jsonl.gz"

    async def record() -> None:
        options = RecordingOptions(file=path, outputs_every=10)
        async with Runtime(load_machine(None), clock="stepped", http_port=None, recording=options) as rt:
            files = {"UP1.NC": "%UP1\nN10 G01 X5 F6000\nN20 M17\n"}
            rt.operator.load_program(1, "%main\nN10 L UP1.NC\nN20 G01 X10 F6000\nN30 M30\n", "main.nc", files)
            rt.operator.start(1)
            await rt.step(300)

    asyncio.run(record())
    return list(read_records(path))


def _show_and_replay(
    tmp_path: Path, recorded: list[dict[str, Any]], change: Callable[[list[dict[str, Any]]], None]
) -> tuple[Path, subprocess.CompletedProcess[str], subprocess.CompletedProcess[str]]:
    """The recording's lines changed, written, then ``record show`` and ``replay`` of it: no traceback."""
    records = copy.deepcopy(recorded)
    change(records)
    path = tmp_path / "hostile.jsonl.gz"
    path.write_bytes(gzip_member("".join(json.dumps(r) + "\n" for r in records)))
    done = [
        subprocess.run(
            [*hli_server_cmd(), *command, str(path)], capture_output=True, text=True, timeout=120, check=False
        )
        for command in (("record", "show"), ("replay",))
    ]
    for result in done:
        assert "Traceback" not in result.stdout + result.stderr, result.stdout + result.stderr
    return path, done[0], done[1]


def _first(records: list[dict[str, Any]], test: Callable[[dict[str, Any]], bool]) -> int:
    return next(k for k, r in enumerate(records) if k > 0 and test(r))


def _events_text(r: list[dict[str, Any]]) -> None:
    r.insert(5, {"c": 5, "e": "AAAA"})


def _input_index(r: list[dict[str, Any]]) -> None:
    r[_first(r, lambda x: "i" in x)]["i"] = [10**9, 1]


def _load_outside(r: list[dict[str, Any]]) -> None:
    r[_first(r, lambda x: x.get("op") == "load_program")]["args"]["files"] = {"../x.nc": "N10 M30"}


def _cycle_huge(r: list[dict[str, Any]]) -> None:
    r[_first(r, lambda x: "o" in x)]["c"] = 10**13


def _end_huge(r: list[dict[str, Any]]) -> None:
    r[-1]["c"] = 10**13


def _unknown_request(r: list[dict[str, Any]]) -> None:
    r[_first(r, lambda x: "op" in x)]["op"] = "__class__"


@pytest.mark.parametrize(
    ("change", "show", "replay"),
    [
        # the four: a traceback each, or a replay without end
        (_events_text, "line 6: e: a list of events, got 'AAAA'", "line 6: e: a list of events"),
        (_input_index, "i: signal index 1000000000 is not one of the header's", "i: signal index 1000000000"),
        (_cycle_huge, "c: cycle 10000000000000 lies", "c: cycle 10000000000000 lies"),
        (_end_huge, "c: cycle 10000000000000 lies", "c: cycle 10000000000000 lies"),
        (_unknown_request, None, "line 2: op: an operator request this version does not know: '__class__'"),
        (_load_outside, None, None),
    ],
)
def test_a_hostile_recording_ends_in_a_clear_answer_never_a_traceback(
    tmp_path: Path,
    recorded: list[dict[str, Any]],
    change: Callable[[list[dict[str, Any]]], None],
    show: str | None,
    replay: str | None,
) -> None:
    """Before: ``record show`` and ``replay`` ended in a traceback (an event line ``{"c":5,"e":"AAAA"}``, a
    load request with ``../``), an input index of 10^9 raised the internal alarm 919000 and a cycle of
    10^13 ran the replay past any bound. Now each is refused with the file, the line and the field
    (``record show``: exit 2; ``replay``: CANNOT REPLAY, exit 3), before the first cycle runs; a load
    request the replay refuses (``../``) is a difference (exit 1) of that request, not a traceback."""
    began = time.monotonic()
    path, shown, replayed = _show_and_replay(tmp_path, recorded, change)
    took = time.monotonic() - began
    if show is not None:
        assert shown.returncode == 2, shown.stdout + shown.stderr
        assert f"{path}: line " in shown.stderr
        assert show in shown.stderr, shown.stderr
    else:
        assert shown.returncode == 0, shown.stderr
    said = replayed.stdout + replayed.stderr
    if replay is not None:
        assert replayed.returncode == 3, said
        assert "CANNOT REPLAY" in said
        assert f"{path}: line " in said
        assert replay in said, said
    else:
        assert replayed.returncode == 1, said  # a difference, said as one
        assert "operator load_program" in said
    assert took < 30  # the cycle of 10^13 is refused, not run


@pytest.fixture(scope="module")
def late(tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, Any]]:
    """A recording started 300 cycles into a program's run: the journal, the snapshot line, its cycles."""
    path = tmp_path_factory.mktemp("late") / "late.jsonl.gz"
    return record_late(path, "N10 G01 X50 F600\nN20 M30\n", 300, 200)


def _snapshot_line(r: list[dict[str, Any]]) -> dict[str, Any]:
    return r[_first(r, lambda x: "snapshot" in x)]


def _second_snapshot(r: list[dict[str, Any]]) -> None:
    line = _snapshot_line(r)
    r.insert(r.index(line) + 1, copy.deepcopy(line))


def _snapshot_cycle(r: list[dict[str, Any]]) -> None:
    line = _snapshot_line(r)
    line["snapshot"]["cycle"] = line["c"] + 1


def _snapshot_objects(r: list[dict[str, Any]]) -> None:
    _snapshot_line(r)["snapshot"]["objects"] = "AAAA"


def _snapshot_external(r: list[dict[str, Any]]) -> None:
    _snapshot_line(r)["external"] = "not base64!"


def _snapshot_code(r: list[dict[str, Any]]) -> None:
    state = _snapshot_line(r)["snapshot"]
    state["objects"][state["root"]["r"]]["state"]["cycle"] = {
        "p": {"fn": "os:system"},
        "a": ["touch /tmp/hli-forged-snapshot-ran"],
        "k": [],
    }


def _snapshot_kinds(r: list[dict[str, Any]]) -> None:
    state = _snapshot_line(r)["snapshot"]
    channels = state["objects"][state["root"]["r"]]["state"]["channels"]["r"]
    state["objects"][channels]["list"] = [None]  # restore() takes it: the engine's types are not checked


def _snapshot_cycle_text(r: list[dict[str, Any]]) -> None:
    state = _snapshot_line(r)["snapshot"]
    state["objects"][state["root"]["r"]]["state"]["cycle"] = "x"


def _announced_none(r: list[dict[str, Any]]) -> None:
    r[0]["snapshot"] = None


@pytest.mark.parametrize(
    ("change", "said", "shown_too"),
    [
        (_second_snapshot, "snapshot: a second snapshot line", True),
        (_snapshot_cycle, "snapshot.cycle: the line's cycle", True),
        (_snapshot_objects, "snapshot.objects: the list of objects", True),
        (_snapshot_external, "external: the V.E. fields' bytes are no base64", True),
        (_announced_none, "snapshot: a snapshot line in a recording whose header announces none", True),
        (
            _snapshot_code,
            "snapshot: the snapshot is malformed: 'os:system' is no function of the engine",
            False,
        ),
        (
            _snapshot_kinds,
            ": snapshot: the ",
            False,
        ),
        (_snapshot_cycle_text, ": snapshot: the ", False),
    ],
)
def test_a_hostile_snapshot_line_ends_in_a_clear_answer_never_code(
    tmp_path: Path,
    late: list[dict[str, Any]],
    change: Callable[[list[dict[str, Any]]], None],
    said: str,
    shown_too: bool,
) -> None:
    """The snapshot line of a recording started in a running server (issue 37, item 2) is input like any
    other: its envelope is checked with every line (``record show`` exit 2, ``replay`` CANNOT REPLAY, with
    file, line and field), and its objects are data the replay's restore reads with engine names only: a
    partial of ``os:system`` is refused with its line, never called; a state of the wrong kinds (which
    restore cannot know: the engine's attributes carry no types at run time) fails the engine's first
    cycle or the runtime's start, and the replay says so with the line, never alarm 919000."""
    path, shown, replayed = _show_and_replay(tmp_path, late, change)
    told = replayed.stdout + replayed.stderr
    assert replayed.returncode == 3, told
    assert "CANNOT REPLAY" in told
    assert f"{path}: line " in told
    assert said in told, told
    if shown_too:
        assert shown.returncode == 2, shown.stdout + shown.stderr
        assert said in shown.stderr, shown.stderr
    else:  # the envelope is whole: what the objects hold is the restore's to refuse
        assert shown.returncode == 0, shown.stderr
        assert "--from-journal" in told
        # the pure engine fails in its first cycle or the runtime's start, the compiled one in restore()
        assert any(e in told for e in ("Error:", "is no function")), told
    assert not Path("/tmp/hli-forged-snapshot-ran").exists()
