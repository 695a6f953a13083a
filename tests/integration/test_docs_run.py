"""The docs, executed (issue 23): every command and every expected output of README.md and docs/*.md
that a user would copy is run against a real server, so that the docs cannot drift.

The blocks to run carry a ``doc-run`` marker (``tests/doc_blocks.py`` says what it may say); each
session of them runs in ``tests/doc_runner.py`` inside a network and mount namespace of its own
(``unshare --net --mount``, a /dev/shm of its own), with ``hli-server run`` (and a Mosquitto broker
where asked) on the documented ports. What a command prints must match the lines under it in the doc:
``...`` stands for any text in a line, a line ``...`` for any lines; runs of blanks count as one; the
marker's ``json``, ``numbers``, ``head``, ``any-order``, ``ignore`` loosen it where the doc says so.
Every block that holds commands or code and is not run says why (``doc-skip: ...``), or names the test
that runs it: :func:`test_every_block_is_run_or_says_why_not`.

Without ``unshare`` and namespaces (root, or unprivileged user namespaces) the sessions skip, saying so.
"""

from __future__ import annotations

import functools
import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from typing import Any

import pytest

from tests.doc_blocks import ROOT, DocBlock, all_docs, doc_blocks, unmarked_blocks

pytestmark = pytest.mark.req("H-11")

NUMBER = r"-?\d+(?:\.\d+)?(?:[eE][+-]?\d+)?"


@dataclass
class Session:
    """Blocks of one doc that run in order on one server (``session=NAME``, else one block)."""

    name: str
    blocks: list[DocBlock] = field(default_factory=list)
    outputs: list[DocBlock] = field(default_factory=list)

    @property
    def first(self) -> DocBlock:
        return self.blocks[0]

    def spec(self) -> dict[str, Any]:
        options = self.first.options
        blocks = []
        for block in self.blocks:
            o = block.options
            blocks.append(
                {
                    "commands": [c.text for c in block.commands()],
                    "setup": block.setup,
                    "timeout": float(o["timeout"]) if "timeout" in o else None,
                    "until": o.get("until"),
                    "background": "background" in o,
                    "serve": "serve" in o,
                    "python": block.body if "python" in o else None,
                    "pytest": block.body if "pytest" in o else None,
                    "file": o.get("file"),
                    "node": block.body if "node" in o else None,
                    "text": block.body,
                }
            )
        return {"server": options.get("server"), "broker": "broker" in options, "blocks": blocks}


def sessions() -> list[Session]:
    found: list[Session] = []
    for doc in all_docs():
        named: dict[str, Session] = {}
        last: Session | None = None
        for block in doc_blocks(doc):
            if block.marker != "run":
                continue
            if "output" in block.options:
                assert last is not None, f"{block.where}: an output block before any block it belongs to"
                last.outputs.append(block)
                continue
            name = block.options.get("session")
            if name is not None and name in named:
                named[name].blocks.append(block)
                last = named[name]
                continue
            last = Session(f"{doc.relative_to(ROOT)}:{block.line}" + (f"[{name}]" if name else ""), [block])
            found.append(last)
            if name is not None:
                named[name] = last
    return found


@functools.cache
def _namespace_command() -> list[str] | str:
    """The command that runs the runner in a network namespace of its own, or why there is none."""
    unshare = shutil.which("unshare")
    if unshare is None:
        return "unshare (util-linux) is not installed"
    command = [unshare, "--net", "--mount"] + ([] if os.geteuid() == 0 else ["--map-root-user"])
    probe = subprocess.run(
        [*command, "mount", "-t", "tmpfs", "tmpfs", "/dev/shm"],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    if probe.returncode != 0:
        return f"no network namespace here ({' '.join(command)}: {probe.stderr.strip()[:200]})"
    return [*command, sys.executable, "-m", "tests.doc_runner"]


# --------------------------------------------------------------------------------------------
# Matching what a command printed with the lines of the doc
# --------------------------------------------------------------------------------------------


def _blanks(line: str) -> str:
    """Runs of blanks (spaces, tabs: a tool's column alignment) count as one."""
    return re.sub(r"[ \t]+", " ", line).rstrip()


def _line_pattern(line: str, numbers: bool) -> re.Pattern[str]:
    out = []
    for part in re.split(r"(\.\.\.)", line):
        if part == "...":
            out.append(".*?")
        elif numbers:
            pieces = re.split(f"({NUMBER})", part)
            out.extend(NUMBER if k % 2 else re.escape(p) for k, p in enumerate(pieces))
        else:
            out.append(re.escape(part))
    return re.compile("".join(out), re.DOTALL)


def mismatch(expected: list[str], actual: str, options: dict[str, str]) -> str | None:
    """None when ``actual`` is what ``expected`` shows (the rules of the module docstring), else why."""
    loose = options.get("numbers")  # a flag: every line; a regular expression: the lines it finds

    def numbers(line: str) -> bool:
        return loose is not None and (loose == "" or re.search(loose, line) is not None)

    if "ignore" in options:
        noise = re.compile(options["ignore"])
        actual = "\n".join(line for line in actual.splitlines() if not noise.search(line))
    if "json" in options:
        want = "".join("".join(expected).split())
        have = "".join(actual.split())
        if _line_pattern(want, loose is not None).fullmatch(have):
            return None
        return f"expected (whitespace dropped):\n{want}\ngot:\n{have}"
    lines = [_blanks(line) for line in actual.strip("\n").splitlines()]
    want_lines = [_blanks(line) for line in expected]
    if "any-order" in options:
        left = list(lines)
        for want in want_lines:
            pattern = _line_pattern(want, numbers(want))
            hit = next((k for k, line in enumerate(left) if pattern.fullmatch(line)), None)
            if hit is None:
                return f"no line like {want!r} in:\n" + "\n".join(lines)
            del left[hit]
        return None
    if "head" in options:
        want_lines = [*want_lines, "..."]
    patterns = [None if w.strip() == "..." else _line_pattern(w, numbers(w)) for w in want_lines]

    @functools.cache
    def fits(i: int, j: int) -> bool:
        if i == len(patterns):
            return j == len(lines)
        pattern = patterns[i]
        if pattern is None:
            return any(fits(i + 1, k) for k in range(j, len(lines) + 1))
        return j < len(lines) and bool(pattern.fullmatch(lines[j])) and fits(i + 1, j + 1)

    if fits(0, 0):
        return None
    return "expected:\n" + "\n".join(want_lines) + "\ngot:\n" + "\n".join(lines)


def test_the_matcher_is_strict_where_the_doc_is_exact() -> None:
    assert mismatch(["[16]:   3094"], "[16]: \t3094\n", {}) is None
    assert mismatch(["[16]:   3094"], "[16]:   3095", {}) is not None
    assert mismatch(["[16]:   3094"], "[16]:   3095", {"numbers": ""}) is None
    assert mismatch(["x 1", "7 cycles"], "x 1\n9 cycles", {"numbers": "cycles"}) is None
    assert mismatch(["x 1", "7 cycles"], "x 2\n9 cycles", {"numbers": "cycles"}) is not None
    assert mismatch(["a ... c"], "a bbb c", {}) is None
    assert mismatch(["a", "...", "d"], "a\nb\nc\nd", {}) is None
    assert mismatch(["a", "d"], "a\nb\nd", {}) is not None
    assert mismatch(["a"], "a\nb", {"head": ""}) is None
    assert mismatch(['{"a":1,', ' "b":[...]}'], '{"a":1,"b":[2, 3]}', {"json": ""}) is None
    assert mismatch(["b", "a"], "a\nx\nb", {"any-order": ""}) is None
    assert mismatch(["b", "b"], "a\nb", {"any-order": ""}) is not None
    assert mismatch(["a", "b"], "a\nWARNING: late\nb", {"ignore": "^WARNING"}) is None


# --------------------------------------------------------------------------------------------
# The docs
# --------------------------------------------------------------------------------------------


def test_every_block_is_run_or_says_why_not() -> None:
    """A block a user would copy (commands, code) is run by this module, by a test it names, or says
    why it is not (``<!-- doc-skip: ... -->``)."""
    unmarked = [f"{b.where} ({b.lang or 'plain'})" for b in unmarked_blocks()]
    assert not unmarked, "blocks that no test runs and that do not say why:\n" + "\n".join(unmarked)
    skipped = [b for doc in all_docs() for b in doc_blocks(doc) if b.marker == "skip"]
    assert all(b.reason for b in skipped), [b.where for b in skipped if not b.reason]


def _with_requirements(session: Session) -> Any:
    """The session as a parameter carrying the requirement IDs its blocks name (``req=H-06,C43-10``)."""
    ids = [r for b in session.blocks for r in b.options.get("req", "").split(",") if r]
    return pytest.param(session, id=session.name, marks=[pytest.mark.req(*ids)] if ids else [])


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize("session", [_with_requirements(s) for s in sessions()])
def test_the_doc_runs_as_written(session: Session) -> None:
    command = _namespace_command()
    if isinstance(command, str):
        pytest.skip(command)
    if any("node" in b.options for b in session.blocks):
        from tests.doc_runner import NODE_MODULES

        if shutil.which("node") is None or not (NODE_MODULES / "ads-client").is_dir():
            pytest.skip("Node or its ads-client is missing (npm ci in tests/interop/node; .ci/run does)")
    done = subprocess.run(
        command,
        input=json.dumps(session.spec()),
        capture_output=True,
        text=True,
        timeout=280,
        check=False,
        cwd=ROOT,
    )
    assert done.returncode == 0, f"the runner failed:\n{done.stdout[-3000:]}\n{done.stderr[-5000:]}"
    result = json.loads(done.stdout)
    problems = []
    printed_in_background = []
    printed_by: dict[int, str] = {}
    for block, ran in zip(session.blocks, result["blocks"], strict=True):
        printed_by[block.line] = "\n".join(text for text, _ in ran["outputs"])
        options = block.options
        problems.extend(f"{block.where}: its set-up failed:\n{text}" for text in ran["setup_failed"])
        want_status = int(options.get("status", "0"))
        commands = block.commands() if not {"python", "pytest", "node"} & set(options) else []
        for k, (text, status) in enumerate(ran["outputs"]):
            shown = commands[k].text if commands else "(the python block)"
            where = f"{block.where}: $ {shown}"
            if "background" in options:
                printed_in_background.append(text)
            # interrupted as asked (timeout, a second terminal, a server): `timeout` reports 124, a
            # program stopped by Ctrl+C 130 or 0; the output is what counts
            interrupted = {"timeout", "background", "until", "serve"} & set(options)
            if status != want_status and not (interrupted and status in (124, 130, 0, -2)):
                problems.append(f"{where}\nexit status {status}, not {want_status}:\n{text}")
                continue
            expected = commands[k].expected if commands else []
            if expected:
                why = mismatch(expected, text, options)
                if why is not None:
                    problems.append(f"{where}\n{why}")
    for out_block in session.outputs:
        before = max(b.line for b in session.blocks if b.line < out_block.line)
        printed = "\n".join(printed_in_background) if printed_in_background else printed_by[before]
        why = mismatch(out_block.body.splitlines(), printed, out_block.options)
        if why is not None:
            problems.append(f"{out_block.where} (what the background commands printed)\n{why}")
    assert not problems, "\n\n".join(problems) + f"\n\nthe server's log:\n{done.stderr[-3000:]}"
