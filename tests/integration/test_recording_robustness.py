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
    records = copy.deepcopy(recorded)
    change(records)
    path = tmp_path / "hostile.jsonl.gz"
    path.write_bytes(gzip_member("".join(json.dumps(r) + "\n" for r in records)))
    shown = subprocess.run(
        [*hli_server_cmd(), "record", "show", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    began = time.monotonic()
    replayed = subprocess.run(
        [*hli_server_cmd(), "replay", str(path)], capture_output=True, text=True, timeout=60, check=False
    )
    took = time.monotonic() - began
    for result in (shown, replayed):
        assert "Traceback" not in result.stdout + result.stderr, result.stdout + result.stderr
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
