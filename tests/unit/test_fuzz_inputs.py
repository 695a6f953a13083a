"""Fuzzing the doors of NC programs, configuration and fault injection (E-04, E-07, A3-05; issue 12).

Bounded and seeded (``tests/fuzz.py``): a few seconds each in the suite; ``make soak`` runs the same
tests with ``HLI_FUZZ_SCALE`` times the examples (``docs/reliability.md``, "NC programs and
configuration"). The oracle everywhere: only the door's own refusal comes out (a numbered NcError,
an alarm of the table, ConfigError, ValueError/KeyError from ``inject_fault``), never another
exception; every value the engine publishes stays finite; and the machine keeps stepping and runs a
good program to its end afterwards.
"""

from __future__ import annotations

import math
import random
import re
import shutil
import time
import traceback
from importlib import resources
from pathlib import Path
from typing import Any

import pytest

from hli_server.commands.check import check_program
from hli_server.configuration import ConfigError, load_machine
from hli_server.engine import Machine
from hli_server.engine.alarms import ALARMS
from hli_server.engine.hli import ProgramState
from hli_server.engine.nc import (
    STATEMENTS_PER_CYCLE,
    Block,
    Compiler,
    Interpreter,
    IterationCapError,
    NcError,
    iter_blocks,
    parse_line,
)
from hli_server.engine.nc.directives import SyncAction
from hli_server.engine.programs import MemoryLibrary
from schemas.config import ExternalVariableConfig, MachineConfig
from tests import fuzz
from tests.unit.engine_helpers import mill_config
from tests.unit.nc_helpers import FakeHost, real

pytestmark = pytest.mark.fuzz

AXES = ("X", "Y", "Z", "X1", "X2", "Z1")
CHANNEL_AXES = {1: ("X", "Y", "Z"), 2: ("X1", "X2", "Z1")}
GOOD = "N10 G90 G01 X10 Y-10 Z5 F20000\nN20 G02 X20 Y0 I5 J5\nN30 G00 X0 Y0 Z0\nN40 M30\n"
RUNNING = (ProgramState.RUNNING, ProgramState.HELD)


@pytest.fixture(scope="module")
def demo() -> MachineConfig:
    return load_machine(None)


def _fail(what: str, seed: int, example: int, text: object) -> str:
    return (
        f"{what} (HLI_FUZZ_SEED={fuzz.FUZZ_SEED}, test seed {seed}, example {example}); input:\n"
        f"{text!r}\n{traceback.format_exc()}"
    )


def _check_nc_error(err: NcError, line: int) -> None:
    assert err.alarm in ALARMS
    assert 910100 <= err.alarm <= 910111
    assert err.line >= line
    assert re.fullmatch(r"line [0-9]+|N[0-9]+", err.block)
    assert err.message


def _finite(machine: Machine) -> bool:
    return all(
        math.isfinite(v)
        for a in machine.axes
        for v in (a.setpoint, a.actual, a.measured, a.drive_velocity, a.following_error)
    )


def _settle(machine: Machine, rounds: int = 20, cycles: int = 5000) -> None:
    """What an operator does until the machine is clear: reset every channel and wait until every
    axis stands in its exact-stop window, brakes on its own no more and no alarm is active; reset
    again while one is. Why each condition: the last bit of a stop ramp can be below the setpoint's
    resolution (a standing setpoint does not end the stop); a cleared ``encoder_stuck`` lets the
    measured position jump to where the real axis ran, and while the loop pulls it back 70021/70022 or
    70082 fire (its stop is released only by the next reset)."""
    for _ in range(rounds):
        for ch in machine.channels:
            ch.request_reset()
        for _ in range(cycles):
            machine.step(1)
            if machine.active_alarms:
                break
            if all(
                a.setpoint_step == 0.0
                and not a.stopping
                and abs(a.following_error) * 10_000 <= a.config.window
                for a in machine.axes
            ):
                return
    active = [a.message for a in machine.active_alarms]
    raise AssertionError(f"the machine is not clear after {rounds} resets: {active}")


def _runs_to_the_end(machine: Machine, program: str = GOOD) -> bool:
    ch = machine.channel(1)
    ch.load_program(program, "good")
    ch.request_start()
    machine.step(1)
    for _ in range(20_000):
        if ch.state not in RUNNING:
            break
        machine.step(1)
    return ch.state == ProgramState.FINISHED and not machine.active_alarms


# --- the parser ------------------------------------------------------------------------------------


@pytest.mark.req("E-04")
def test_fuzz_parser_lines_raise_only_numbered_nc_errors() -> None:
    seed = fuzz.seed_for("parser-lines")
    rng = random.Random(seed)
    refused = 0
    for example in range(fuzz.count(40_000)):
        text = fuzz.nc_line(rng) if example % 2 else fuzz.mutate(rng, rng.choice(fuzz.CORPUS))
        try:
            block = parse_line(text, 7, AXES)
        except NcError as err:
            _check_nc_error(err, 7)
            refused += 1
            continue
        except Exception:  # the fuzzer's whole point: anything else is a finding
            pytest.fail(_fail("parse_line raised something else than NcError", seed, example, text))
        if block is not None:
            values = [v for _, v in block.axes] + [v for _, v in block.centre] + list(block.extra.values())
            assert all(math.isfinite(v) for v in values), text
            assert all(abs(v) <= 214748.3647 for _, v in block.axes), text
    total = fuzz.count(40_000)
    print(f"parser: {total} lines, {refused} refused with a numbered NcError, {total - refused} parsed")
    assert 0 < refused < total  # both outcomes occur: the generator reaches both sides


@pytest.mark.req("E-04")
def test_fuzz_parser_programs_stop_at_a_numbered_error() -> None:
    seed = fuzz.seed_for("parser-programs")
    rng = random.Random(seed)
    refused = blocks = 0
    for example in range(fuzz.count(5000)):
        text = fuzz.nc_program(rng, wild=0.3)
        try:
            for _ in iter_blocks(text, AXES):
                blocks += 1
        except NcError as err:
            _check_nc_error(err, 1)
            refused += 1
        except Exception:
            pytest.fail(_fail("iter_blocks raised something else than NcError", seed, example, text))
    print(f"parser: {fuzz.count(5000)} programs, {blocks} blocks, {refused} stopped at a numbered NcError")


# --- the decoder: `hli-server check --geometry-only` offline ---------------------------------------


@pytest.mark.req("E-04")
def test_fuzz_check_geometry_only_reports_alarms_and_never_raises(demo: MachineConfig) -> None:
    seed = fuzz.seed_for("check-geometry")
    rng = random.Random(seed)
    alarms_seen: set[int] = set()
    completed = blocks = 0
    for example in range(fuzz.count(1500)):
        channel = rng.choice((1, 1, 2))
        text = fuzz.nc_program(rng, CHANNEL_AXES[channel])
        machine = Machine(demo)
        try:
            result = check_program(machine, text, channel=channel, geometry_only=True)
        except Exception:
            pytest.fail(_fail("check_program raised", seed, example, text))
        assert all(a.number in ALARMS for a in result.alarms)
        assert all(math.isfinite(v) for v in result.final_position.values()), text
        alarms_seen.update(a.number for a in result.alarms)
        completed += result.completed
        blocks += result.blocks
    print(
        f"check --geometry-only: {fuzz.count(1500)} programs, {blocks} blocks, {completed} ran to the end, "
        f"{len(alarms_seen)} different alarms: {sorted(alarms_seen)}"
    )
    assert {910111, 120002} <= alarms_seen or fuzz.FUZZ_SCALE < 1


# --- stepped engine runs, with fault injection ---------------------------------------------------------


@pytest.mark.req("E-04", "A3-05")
def test_fuzz_stepped_runs_keep_the_machine_stepping(demo: MachineConfig) -> None:
    """Programs run cycle by cycle on one machine (areas, offsets and faults carry over from one to
    the next, as on a server); faults are injected between them. After each: reset, the axes come to
    rest; every tenth and at the end a good program must run to its end."""
    seed = fuzz.seed_for("stepped")
    rng = random.Random(seed)
    machine = Machine(demo)
    refused_faults = injected = 0
    alarms_seen: set[int] = set()
    for example in range(fuzz.count(100)):
        channel = rng.choice((1, 1, 2))
        text = fuzz.nc_program(rng, CHANNEL_AXES[channel])
        ch = machine.channel(channel)
        try:
            if rng.random() < 0.4:
                axis = rng.choice(("X", "Y", "Z", "X1", "X2", "Q"))
                injected += 1
                try:
                    machine.inject_fault(axis, **fuzz.fault_values(rng))  # type: ignore[arg-type]
                except (ValueError, KeyError):
                    refused_faults += 1
            ch.load_program(text, f"fuzz{example}")
            ch.request_start()
            for _ in range(rng.randint(1, 1500)):
                machine.step(1)
                if ch.state not in RUNNING:
                    break
            assert _finite(machine), "a value went inf/nan"
            assert all(a.number in ALARMS for a in machine.alarm_history)
            alarms_seen.update(a.number for a in machine.alarm_history)
            for name in ("X", "Y", "Z", "X1", "X2", "Z1"):
                machine.inject_fault(name)  # clears: the drive must be sound again for the good program
            _settle(machine)
            if example % 10 == 9:
                assert _runs_to_the_end(machine), [a.message for a in machine.alarm_history][-3:]
                _settle(machine)
        except Exception:
            pytest.fail(_fail("a stepped run failed", seed, example, text))
    print(
        f"stepped: {fuzz.count(100)} programs, {machine.cycle} cycles, {injected} fault injections "
        f"({refused_faults} refused), alarms {sorted(alarms_seen)}"
    )
    assert refused_faults > 0
    assert _runs_to_the_end(machine)


# --- the configuration loader ----------------------------------------------------------------------------


def _demo_files(directory: Path) -> dict[str, str]:
    files = {}
    for name in ("demo.toml", "demo_ch1.lis", "demo_x1.lis", "demo_x2.lis"):
        text = resources.files("hli_server.machines").joinpath(name).read_text(encoding="utf-8")
        files[name] = text
        (directory / name).write_text(text, encoding="utf-8")
    return files


_CONFIG_VALUES = (
    "inf",
    "nan",
    "-inf",
    "1e400",
    "-1",
    "0",
    "0x7FFFFFFF",
    "2147483648",
    "1e9",
    '"x"',
    "[]",
    "",
)


@pytest.mark.req("E-07")
def test_fuzz_configuration_files_raise_only_config_errors(tmp_path: Path) -> None:
    """Mutated demo machine files and parameter lists (values replaced by extremes, lines edited)."""
    seed = fuzz.seed_for("config")
    rng = random.Random(seed)
    originals = _demo_files(tmp_path)
    loaded = refused = 0
    for example in range(fuzz.count(150)):
        name = rng.choice(list(originals))
        lines = originals[name].splitlines()
        for _ in range(rng.randint(1, 3)):
            k = rng.randrange(len(lines))
            if rng.random() < 0.6 and ("=" in lines[k] or name.endswith(".lis")):
                sep = "=" if name.endswith(".toml") else " "
                key = lines[k].split(sep, 1)[0].rstrip()
                lines[k] = f"{key}{' = ' if sep == '=' else ' '}{rng.choice(_CONFIG_VALUES)}"
            else:
                lines[k] = fuzz.mutate(rng, lines[k])
        (tmp_path / name).write_text("\n".join(lines) + "\n", encoding="utf-8")
        try:
            config = load_machine(tmp_path / "demo.toml")
        except ConfigError as err:
            messages = err.messages
            refused += 1
            if not messages:
                pytest.fail(_fail("a ConfigError without a message", seed, example, "\n".join(lines)))
        except Exception:
            pytest.fail(_fail(f"load_machine raised ({name})", seed, example, "\n".join(lines)))
        else:
            loaded += 1
            machine = Machine(config)
            machine.step(20)
            assert _finite(machine)
        finally:
            (tmp_path / name).write_text(originals[name], encoding="utf-8")
    print(
        f"configuration: {fuzz.count(150)} mutated files, {refused} refused with ConfigError, {loaded} loaded"
    )
    assert loaded > 0
    assert refused > 0
    shutil.rmtree(tmp_path, ignore_errors=True)


# --- the NC language (issue 20): expressions, variables, control flow, calls --------------------------
LANGUAGE_FILES = {
    "sub.nc": "P5 = P5 + 1\nG91 G01 X1 F6000\nG90\nM17\n",
    "cyc.ecy": "$IF EXIST[@P2]\nX[@P1 + @P2]\n$ENDIF\nM17\n",
}


def _language_host() -> FakeHost:
    return FakeHost(LANGUAGE_FILES, [real("COUNT"), real("SYNC", synchronous=True)])


MSG_REFUSALS = {20721, 21232, 21870, 914031, 914020}
"""What a #MSG may be refused with: values and elements that do not match, an unknown element, a text (or a
width or precision) beyond 255 characters, a value the element cannot take, a literal beyond 255."""


@pytest.mark.req("N-07", "N-08")
def test_fuzz_msg_format_strings_are_bounded_and_refused_with_their_ids() -> None:
    """Format strings with every flag, widths and precisions from none to 60 digits, every conversion and
    unknown ones, matching and mismatching values (issue 36, finding 1): a message of at most 255
    characters comes out, or a refusal of :data:`MSG_REFUSALS` with its line and block; no example takes
    longer than 0.25 s (a width that is formatted before it is bounded takes seconds and hundreds of MB)."""
    seed = fuzz.seed_for("msg-formats")
    rng = random.Random(seed)
    said = refused = 0
    seen: set[int] = set()
    longest = 0.0
    for example in range(fuzz.count(3000)):
        block = fuzz.format_message(rng)
        host = FakeHost()
        it = Interpreter(Compiler(("X", "Y", "Z"), ("X", "Y", "Z")), host, budget=None, iteration_cap=100)
        began = time.perf_counter()
        try:
            it.start(block + "\nM30\n", "fuzz")
            for _ in range(10):
                out = it.next()
                if out is None or (isinstance(out, Block) and 30 in out.m_codes):
                    break
                if isinstance(out, SyncAction):  # a #MSG SYN waits for the path: it passes now
                    out.action()
        except NcError as err:
            refused += 1
            seen.add(err.alarm)
            if err.alarm not in MSG_REFUSALS | {914000, 910100} or not err.message or err.block != "N10":
                pytest.fail(_fail(f"bad NcError {err!r}", seed, example, block))
        except Exception:
            pytest.fail(_fail("the interpreter raised", seed, example, block))
        took = time.perf_counter() - began
        longest = max(longest, took)
        if took > 0.25:
            pytest.fail(_fail(f"took {took:.2f} s", seed, example, block))
        for text, *_ in host.messages:
            said += 1
            if len(text) > 255:
                pytest.fail(_fail(f"a message of {len(text)} characters", seed, example, block))
    print(
        f"#MSG formats: {fuzz.count(3000)} blocks, {said} messages, {refused} refused ({sorted(seen)}), "
        f"longest {longest * 1e3:.1f} ms"
    )
    assert {20721, 21232, 21870} <= seen or fuzz.FUZZ_SCALE < 1
    assert said > fuzz.count(3000) // 10 or fuzz.FUZZ_SCALE < 1


def test_fuzz_interpreter_raises_only_numbered_nc_errors() -> None:
    """Every language program ends (M30, its text's end, the iteration cap) or stops at a numbered
    NcError of the alarm table with its place; nothing else comes out of the interpreter."""
    seed = fuzz.seed_for("language-interpreter")
    rng = random.Random(seed)
    ended = refused = capped = 0
    seen: set[int] = set()
    for example in range(fuzz.count(3000)):
        text = fuzz.language_program(rng)
        host = _language_host()
        it = Interpreter(Compiler(("X", "Y", "Z"), ("X", "Y", "Z")), host, budget=None, iteration_cap=2000)
        try:
            it.start(text, "fuzz")
            for _ in range(5000):
                out = it.next()
                if out is None or (isinstance(out, Block) and (30 in out.m_codes or 2 in out.m_codes)):
                    break
            ended += 1
        except NcError as err:
            refused += 1
            seen.add(err.alarm)
            if (
                err.alarm not in ALARMS
                or not err.message
                or not re.fullmatch(r"line [0-9]+|N[0-9]+", err.block)
            ):
                pytest.fail(_fail(f"bad NcError {err!r}", seed, example, text))
        except IterationCapError:
            capped += 1
        except Exception:
            pytest.fail(_fail("the interpreter raised", seed, example, text))
    print(
        f"language: {fuzz.count(3000)} programs, {ended} ran, {refused} refused, {capped} capped, "
        f"{len(seen)} alarm numbers"
    )
    assert len(seen) > 10 or fuzz.FUZZ_SCALE < 1


def test_fuzz_language_programs_on_the_machine_and_in_check() -> None:
    """check (both modes) and a running machine: alarms of the table only, finite positions, the
    machine keeps stepping, no cycle runs more statements than the budget, a good program after."""
    seed = fuzz.seed_for("language-machine")
    rng = random.Random(seed)
    config = mill_config().model_copy(
        update={
            "external_variables": [
                ExternalVariableConfig(name="COUNT"),
                ExternalVariableConfig(name="SYNC", synchronous=True),
            ]
        }
    )
    for example in range(fuzz.count(150)):
        text = fuzz.language_program(rng)
        try:
            for geometry_only in (True, False):
                machine = Machine(config, programs=MemoryLibrary(LANGUAGE_FILES))
                result = check_program(
                    machine, text, geometry_only=geometry_only, max_cycles=20_000, max_iterations=2000
                )
                assert all(a.number in ALARMS for a in result.alarms)
                assert all(math.isfinite(v) for v in result.final_position.values())
            machine = Machine(config, programs=MemoryLibrary(LANGUAGE_FILES))
            ch = machine.channel(1)
            ch.load_program(text, "fuzz")
            ch.request_start()
            for _ in range(300):
                before = ch.interpreter.statements
                machine.step(1)
                assert ch.interpreter.statements - before <= STATEMENTS_PER_CYCLE
            assert _finite(machine)
            ch.request_reset()
            machine.step(200)
            ch.load_program(GOOD, "good")
            ch.request_start()
            for _ in range(20_000):
                machine.step(1)
                if ch.state not in RUNNING:
                    break
            assert ch.state == ProgramState.FINISHED, machine.active_alarms
        except Exception:
            pytest.fail(_fail("language program on the machine", seed, example, text))


# --- recordings (issue 36, finding 6): a recording is input like any other ---------------------------------


_HOSTILE = (
    "AAAA", "", -1, 10**9, 10**13, 2**63, -(2**63), 1.5, True, None, [], {}, [1], {"a": 1}, "NaN", "../x",
    "/etc/passwd", [10**9, 1], [0, "x"], [0], {"kind": 5}, [{"kind": "alarm", "data": "x"}],
)  # fmt: skip


def _mutate_recording(rng: random.Random, records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """A recording with a few lines changed: a field's value replaced by a hostile one, a field dropped, a
    line inserted, doubled or moved, the header's lists and numbers broken."""
    import copy

    out = copy.deepcopy(records)
    for _ in range(rng.randint(1, 3)):
        k = rng.randrange(len(out))
        record = out[k]
        choice = rng.random()
        if choice < 0.55 and record:
            key = rng.choice(sorted(record))
            if key in ("record", "format", "format_version") and rng.random() < 0.8:
                continue  # a broken header is refused at once: keep most examples past it
            record[key] = rng.choice(_HOSTILE)
        elif choice < 0.65 and record:
            record.pop(rng.choice(sorted(record)))
        elif choice < 0.75 and k > 0:
            out.insert(
                k,
                {
                    "c": out[k].get("c", 1),
                    rng.choice(("i", "o", "e", "op", "fault", "zz")): rng.choice(_HOSTILE),
                },
            )
        elif choice < 0.85 and k > 0:
            out.insert(rng.randrange(1, len(out)), copy.deepcopy(record))
        elif k > 0 and "i" in record and isinstance(record["i"], list) and record["i"]:
            record["i"][rng.randrange(len(record["i"]))] = rng.choice(_HOSTILE)
        elif k > 0 and record.get("op") == "load_program" and isinstance(record.get("args"), dict):
            record["args"][rng.choice(("name", "files", "text", "channel", "extra"))] = rng.choice(_HOSTILE)
    return out


@pytest.mark.req("B-02")
def test_fuzz_recordings_end_in_a_verdict_or_a_clear_error(tmp_path: Path) -> None:
    """Recordings with lines changed (values of every kind where another belongs, huge cycles and indices,
    fields dropped, lines inserted and moved, load requests with ``..`` and absolute names): ``record
    show`` raises nothing but :class:`RecordingError` naming the file and line, ``replay`` returns its
    report (PASS, DIFFER or CANNOT with the reason) and never runs past the recording's own last cycle."""
    import asyncio
    import gzip
    import json as _json

    from hli_server.recording.format import RecordingError, gzip_member, read_records
    from hli_server.recording.inspect import summarize
    from hli_server.recording.tap import RecordingOptions
    from hli_server.replay import Verdict, replay
    from hli_server.runtime import Runtime

    base = tmp_path / "base.jsonl.gz"

    async def record() -> None:
        options = RecordingOptions(file=base, outputs_every=10)
        async with Runtime(load_machine(None), clock="stepped", http_port=None, recording=options) as rt:
            rt.operator.load_program(1, "%main\nN10 L UP1.NC\nN20 G01 X10 F6000\nN30 M30\n", "main.nc",
                                     {"UP1.NC": "%UP1\nN10 G01 X5 F6000\nN20 M17\n"})  # fmt: skip
            rt.operator.start(1)
            await rt.step(300)

    asyncio.run(record())
    records = list(read_records(base))
    assert gzip.decompress(base.read_bytes())
    seed = fuzz.seed_for("recordings")
    rng = random.Random(seed)
    verdicts: dict[str, int] = {}
    shown_refused = 0
    for example in range(fuzz.count(120)):
        mutant = _mutate_recording(rng, records)
        changed = [(k, m) for k, (m, r) in enumerate(zip(mutant, records, strict=False)) if m != r][:3]
        path = tmp_path / f"m{example % 4}.jsonl.gz"
        path.write_bytes(gzip_member("".join(_json.dumps(r, default=str) + "\n" for r in mutant)))
        try:
            summarize(path)
        except RecordingError as exc:
            shown_refused += 1
            if str(path) not in str(exc):
                pytest.fail(_fail(f"an error without its file: {exc}", seed, example, changed))
        except Exception:
            pytest.fail(_fail("record show raised", seed, example, changed))
        try:
            report = asyncio.run(replay(path))
        except Exception:
            pytest.fail(_fail("replay raised", seed, example, changed))
        verdicts[str(report.verdict)] = verdicts.get(str(report.verdict), 0) + 1
        if report.verdict is Verdict.CANNOT and not report.reason:
            pytest.fail(_fail("CANNOT without a reason", seed, example, changed))
        if report.last_cycle > 10_000:
            pytest.fail(_fail(f"replayed to cycle {report.last_cycle}", seed, example, changed))
    print(f"recordings: {fuzz.count(120)} mutants, record show refused {shown_refused}, replay {verdicts}")
    assert verdicts.get(str(Verdict.CANNOT), 0) > 0 or fuzz.FUZZ_SCALE < 1


_HOSTILE_SNAPSHOT = (
    *_HOSTILE, {"r": 10**9}, {"r": -1}, {"fn": "os:system"}, {"g": "hli_server.engine.machine:math"},
    {"c": "builtins:object"}, {"e": "hli_server.engine.channel_state:ChannelState", "v": 99},
    {"p": {"fn": "builtins:eval"}, "a": ["1"], "k": []}, {"t": [{"t": [{"r": 0}]}]}, {"f": "nan"},
    {"m": {"r": 0}, "n": "__init__"}, {"x": "nothing"}, {"b": "!!"},
)  # fmt: skip


@pytest.mark.req("B-02")
def test_fuzz_snapshots_end_in_a_verdict_or_a_clear_error(tmp_path: Path) -> None:
    """The snapshot of a recording started in a running server (issue 37, item 2) with its objects
    changed: attributes given values of every kind (references out of range, names of other modules, a
    partial of ``eval``, enums out of range, hostile scalars), entries dropped or replaced: ``replay``
    returns its report, never raises; a CANNOT says why with the file and the snapshot's line."""
    import asyncio
    import copy
    import json as _json

    from hli_server.recording.format import gzip_member
    from hli_server.replay import Verdict, replay
    from tests.recordings import record_late

    program = "N10 $FOR P1 = 1, 50\nN20 G01 X[P1] F6000\nN30 $ENDFOR\nN40 M30\n"
    records = record_late(tmp_path / "late.jsonl.gz", program, 300, 100)
    at = next(k for k, r in enumerate(records) if k > 0 and "snapshot" in r)
    seed = fuzz.seed_for("snapshots")
    rng = random.Random(seed)
    verdicts: dict[str, int] = {}
    for example in range(fuzz.count(40)):
        mutant = copy.deepcopy(records)
        objects = mutant[at]["snapshot"]["objects"]
        changed = []
        for _ in range(rng.randint(1, 3)):
            k = rng.randrange(len(objects))
            entry = objects[k]
            state = entry.get("state")
            if isinstance(state, dict) and state and rng.random() < 0.8:
                key = rng.choice(sorted(state))
                state[key] = rng.choice(_HOSTILE_SNAPSHOT)
                changed.append((k, key, state[key]))
            else:
                objects[k] = rng.choice(_HOSTILE_SNAPSHOT)
                changed.append((k, objects[k]))
        path = tmp_path / f"s{example % 4}.jsonl.gz"
        path.write_bytes(gzip_member("".join(_json.dumps(r) + "\n" for r in mutant)))
        try:
            report = asyncio.run(replay(path))
        except Exception:
            pytest.fail(_fail("replay raised", seed, example, changed))
        verdicts[str(report.verdict)] = verdicts.get(str(report.verdict), 0) + 1
        if report.verdict is Verdict.CANNOT and f"{path}: line {at + 1}: snapshot" not in report.reason:
            pytest.fail(_fail(f"CANNOT without the snapshot's line: {report.reason}", seed, example, changed))
        if report.last_cycle > 1_000:
            pytest.fail(_fail(f"replayed to cycle {report.last_cycle}", seed, example, changed))
    print(f"snapshots: {fuzz.count(40)} mutants, replay {verdicts}")
    assert verdicts.get(str(Verdict.CANNOT), 0) > 0 or fuzz.FUZZ_SCALE < 1
