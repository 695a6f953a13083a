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


def test_the_requirement_list_has_every_id_once_in_order() -> None:
    import re

    doc = (ROOT / "docs" / "requirements.md").read_text(encoding="utf-8")
    ids = re.findall(r"^- ((?:E|C14|C43|C3|A3|H|N|B)-\d+) ", doc, flags=re.MULTILINE)
    expected = (
        [f"E-{i:02d}" for i in range(1, 8)]
        + [f"C14-{i:02d}" for i in range(1, 24)]
        + [f"C43-{i:02d}" for i in range(1, 11)]
        + [f"C3-{i:02d}" for i in range(1, 11)]
        + [f"A3-{i:02d}" for i in range(1, 6)]
        + [f"H-{i:02d}" for i in range(1, 13)]
        + [f"N-{i:02d}" for i in range(1, 14)]
        + [f"B-{i:02d}" for i in range(1, 5)]
    )
    assert ids == expected


def test_ads_doc_describes_every_option() -> None:
    from hli_server.adapters.ads import AdsOptions

    doc = (ROOT / "docs" / "ads.md").read_text(encoding="utf-8")
    missing = [name for name in AdsOptions.model_fields if f"`{name}`" not in doc]
    assert not missing, f"docs/ads.md does not describe the ADS options {missing}"


def test_mqtt_doc_lists_every_topic_and_option() -> None:
    from hli_server.adapters.mqtt import MqttOptions
    from hli_server.commands.events import mqtt_markdown

    doc = (ROOT / "docs" / "mqtt.md").read_text(encoding="utf-8")
    assert mqtt_markdown() in doc, "docs/mqtt.md is stale: paste `hli-server events --mqtt` in its markers"
    missing = [name for name in MqttOptions.model_fields if f"`{name}`" not in doc]
    assert not missing, f"docs/mqtt.md does not describe the MQTT options {missing}"


def test_the_readme_tour_shows_the_program_the_example_runs() -> None:
    """The README's program with a loop, a subprogram and V.E. variables is the one
    examples/test_ve_mode.py runs through every door (N-05)."""
    from plc_clients.demos.ve_mode import POCKET, PROGRAM

    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert f"```\n{PROGRAM}```" in readme, "README.md's tour program differs from demos/ve_mode.py"
    assert f"```\n{POCKET}```" in readme, "README.md's pocket.nc differs from plc_clients/demos/ve_mode.py"


def test_the_plc_clients_doc_names_every_demo() -> None:
    """Issue 37, item 5: ``hli-plc``'s DEMO row and its introduction name every demo it runs."""
    import re

    from plc_clients.demos import DEMOS

    doc = (ROOT / "docs" / "plc-clients.md").read_text(encoding="utf-8")
    row = re.search(r"^\| `DEMO` \| (.*) \|$", doc, flags=re.MULTILINE)
    assert row is not None, "docs/plc-clients.md has no DEMO row in hli-plc's options"
    assert re.findall(r"`([a-z][a-z0-9-]*)`", row.group(1)) == list(DEMOS)
    intro = doc[doc.index("## `hli-plc`") : doc.index("<!-- doc-run", doc.index("## `hli-plc`"))]
    missing = [name for name in DEMOS if f"`{name}`" not in intro]
    assert not missing, f"docs/plc-clients.md's hli-plc section does not introduce {missing}"


def test_what_make_run_writes_into_a_checkout_is_ignored_by_git() -> None:
    """Issue 37, item 2: a recording started from the API or the dashboard of ``make run`` goes to
    ``./recordings`` (the default ``--record-dir``), which showed as untracked in a checkout."""
    import shutil
    import subprocess

    if shutil.which("git") is None or not (ROOT / ".git").exists():
        import pytest

        pytest.skip("not a git checkout")
    for path in ("recordings/session-20260101-120000.jsonl.gz", "test-artifacts/dashboard-reset.png"):
        done = subprocess.run(["git", "check-ignore", "-q", path], cwd=ROOT, check=False)
        assert done.returncode == 0, f"{path} is not ignored by .gitignore"


def test_the_cycle_doc_lists_every_cycle() -> None:
    from hli_server.commands.cycles import cycles_markdown

    doc = (ROOT / "docs" / "cycles.md").read_text(encoding="utf-8")
    assert cycles_markdown() in doc, "docs/cycles.md is stale: paste `hli-server cycles` between its markers"
