"""The docs that are generated from code stay in step with it."""

from __future__ import annotations

from pathlib import Path

from hli_server.commands.alarms import alarms_markdown

ROOT = Path(__file__).resolve().parents[2]


def test_alarm_doc_lists_the_alarm_table():
    doc = (ROOT / "docs" / "alarms.md").read_text(encoding="utf-8")
    assert alarms_markdown() in doc, "docs/alarms.md is stale: regenerate with `hli-server alarms`"


def test_api_doc_lists_every_kind_of_event() -> None:
    from hli_server.commands.events import events_markdown

    doc = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    assert events_markdown() in doc, "docs/api.md is stale: paste `hli-server events` between the markers"
