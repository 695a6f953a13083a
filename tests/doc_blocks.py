"""The code blocks of the docs, and the markers that say which of them the tests run (issue 23).

Two kinds of markers, an HTML comment right before a block's fence (the page shows neither):

* named blocks that one test runs in its own way (``tests/integration/test_plugin.py`` runs
  ``test_my_plc.py`` of docs/testing.md)::

      <!-- test_my_plc.py: run as written by tests/integration/test_plugin.py -->

* ``doc-run`` (run by ``tests/integration/test_docs_run.py`` with ``tests/doc_runner.py``, against a
  real server) and ``doc-skip: why`` (a block that is not run, and why: a fragment, a command that
  needs a Docker engine or a PLC, one that runs for an hour). :data:`RUN_OPTIONS` says what a
  ``doc-run`` marker may say; further lines of the comment, each ``$ command``, are run first
  (setup the page does not show)::

      <!-- doc-run: server="--clock stepped" json
      $ curl -s -X POST http://127.0.0.1:8080/api/channels/1/start
      -->

  Text after `` -- `` in the first line is a note for the reader of the Markdown.

In a ``console``-like block, a line ``$ command`` is a command (a line ending in ``\\`` goes on in the
next), and the lines up to the next command are what it prints. :func:`unmarked_blocks` lists the
blocks that hold commands or code and carry no marker: a test keeps that list empty.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "DOCS",
    "RUN_OPTIONS",
    "Command",
    "DocBlock",
    "code_blocks",
    "doc_blocks",
    "marked_block",
    "unmarked_blocks",
]

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
_FENCE = re.compile(r"```python\n(.*?)```", re.DOTALL)
_ANY_FENCE = re.compile(r"^```([\w-]*)[^\n]*\n(.*?)^```[ \t]*$", re.DOTALL | re.MULTILINE)
_COMMENT_END = re.compile(r"<!--(.*?)-->\s*", re.DOTALL)

RUN_OPTIONS = {
    "server": 'start `hli-server run ARGS` first (server="ARGS"; the documented ports), stop it after',
    "broker": "start a Mosquitto broker on 127.0.0.1:1883 first",
    "session": "blocks of one doc with the same session run in order on one server, one shell directory",
    "timeout": "seconds a command may run; then it is interrupted (Ctrl+C) and what it printed is compared",
    "until": "Ctrl+C (SIGINT to its process group) once the command printed this text (a server's banner)",
    "serve": "the block's command is the session's server: started, its banner compared, kept running",
    "background": "the block's commands are started and run (a second terminal) until the session ends",
    "output": "a block of output only: what the session's background commands (if any), else the block "
    "before it printed",
    "status": "the exit status every command of the block must end with (default 0)",
    "json": "whitespace does not count (long JSON wrapped for the page)",
    "numbers": "every number of the expected output stands for any number (timings, counters); "
    "numbers=REGEX: only in the expected lines the regular expression finds",
    "head": "the expected output is the beginning of what the command prints",
    "any-order": "the expected lines in any order (several event sources)",
    "ignore": "a regular expression: printed lines it finds are not compared (a loaded machine's warnings)",
    "python": "a python block: run with the project's interpreter (its expected output: an `output` block)",
    "pytest": "a python block that is a test file: run with pytest (it must pass)",
    "node": "a js block: run with node, ads-client from tests/interop/node (npm ci; else the session skips)",
    "file": "a block that is a file: written as this name into the session's directory, not run",
    "req": "the session's requirement IDs (docs/requirements.md), comma-separated: its test carries them",
}
"""What a ``doc-run`` marker may say (a flag, or ``key=value`` with shell quoting)."""

_NEEDS_MARKER = {"console", "sh", "shell", "bash", "python", "js", "javascript"}


@dataclass
class Command:
    """One ``$ command`` of a block and the lines it is expected to print."""

    text: str
    expected: list[str] = field(default_factory=list)


@dataclass
class DocBlock:
    """A fenced block of a doc, with its marker."""

    doc: Path
    line: int
    lang: str
    body: str
    marker: str | None = None
    """``run``, ``skip``, ``named`` (run by a test of its own), or None."""
    options: dict[str, str] = field(default_factory=dict)
    setup: list[str] = field(default_factory=list)
    reason: str = ""

    @property
    def where(self) -> str:
        return f"{self.doc.relative_to(ROOT)}:{self.line}"

    def commands(self) -> list[Command]:
        """The ``$ command`` lines and the output under each (continuation lines joined)."""
        return parse_commands(self.body)

    @property
    def holds_commands(self) -> bool:
        return any(line.startswith("$ ") for line in self.body.splitlines())


def parse_commands(text: str) -> list[Command]:
    commands: list[Command] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("$ "):
            parts = [line[2:]]
            while parts[-1].endswith("\\") and i + 1 < len(lines):
                i += 1
                parts.append(lines[i])
            commands.append(Command("\n".join(parts)))
        elif commands:
            commands[-1].expected.append(line)
        i += 1
    for command in commands:
        while command.expected and not command.expected[-1].strip():
            command.expected.pop()
    return commands


def _marker(before: str) -> tuple[str | None, dict[str, str], list[str], str]:
    match = _COMMENT_END.fullmatch(before[before.rfind("<!--") :]) if "<!--" in before else None
    if match is None:
        return None, {}, [], ""
    first, *rest = match.group(1).strip().splitlines() or [""]
    head = first.strip()
    setup = [line.strip()[2:] for line in rest if line.strip().startswith("$ ")]
    if head.startswith("doc-skip"):
        return "skip", {}, [], head.partition(":")[2].strip()
    if head.startswith(("doc-run", "doc-output")):
        options: dict[str, str] = {"output": ""} if head.startswith("doc-output") else {}
        for word in shlex.split(head.partition(":")[2].partition(" -- ")[0]):  # " -- ": a note
            key, _, value = word.partition("=")
            if key not in RUN_OPTIONS:
                raise ValueError(f"unknown doc-run option {key!r} (known: {', '.join(RUN_OPTIONS)})")
            options[key] = value
        return "run", options, setup, ""
    if re.match(r"[\w.-]+: run\b", head):
        return "named", {}, [], head
    return None, {}, [], ""


def doc_blocks(doc: Path) -> list[DocBlock]:
    """Every fenced block of ``doc``, with its marker."""
    text = doc.read_text(encoding="utf-8")
    blocks = []
    for match in _ANY_FENCE.finditer(text):
        before = text[: match.start()]
        line = before.count("\n") + 1
        marker, options, setup, reason = _marker(before[-4000:])
        blocks.append(
            DocBlock(
                doc=doc,
                line=line,
                lang=match.group(1),
                body=match.group(2),
                marker=marker,
                options=options,
                setup=setup,
                reason=reason,
            )
        )
    return blocks


def all_docs() -> list[Path]:
    return [ROOT / "README.md", *sorted(DOCS.glob("*.md")), ROOT / "examples" / "README.md"]


def unmarked_blocks() -> list[DocBlock]:
    """Blocks a user would copy (commands, code) that no test runs and no ``doc-skip`` explains."""
    return [
        block
        for doc in all_docs()
        for block in doc_blocks(doc)
        if block.marker is None and (block.lang in _NEEDS_MARKER or block.holds_commands)
    ]


def code_blocks(doc: Path) -> list[str]:
    """Every ``python`` code block of ``doc``, in order."""
    return _FENCE.findall(doc.read_text(encoding="utf-8"))


def marked_block(doc: Path, marker: str) -> str:
    """The first ``python`` code block after the comment ``<!-- {marker}`` in ``doc``."""
    text = doc.read_text(encoding="utf-8")
    start = text.index(f"<!-- {marker}")
    match = _FENCE.search(text, start)
    assert match is not None, f"{doc.name}: no python code block follows the marker {marker!r}"
    return match.group(1)
