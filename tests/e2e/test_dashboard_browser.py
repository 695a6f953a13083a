"""The dashboard as a person uses it (issue 15): headless Chromium, driven by Playwright, against
``hli-server run`` in its own process (realtime clock, the demo machine).

Debian's ``chromium`` (``/usr/bin/chromium``, or ``HLI_CHROMIUM``) with Playwright's Python package; no
browser is downloaded (``playwright install`` cannot work here). ``.ci/run`` installs ``chromium``;
without it these tests are skipped and say why. Screenshots are kept in ``test-artifacts/`` (or
``HLI_TEST_ARTIFACTS``): ``dashboard-area-violation.png`` after the violation, ``dashboard-reset.png``
after the reset (docs/dashboard.md).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from hli_server.recording.format import read_records
from tests.integration.servers import hli_server_cmd, read_banner, stop_server
from tests.spec_examples import CIRC_PROT_OLD

playwright_api = pytest.importorskip(
    "playwright.sync_api", reason="Playwright's Python package is missing: pip install -e '.[test]'"
)
expect = playwright_api.expect

CHROMIUM = os.environ.get("HLI_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",  # without these Chromium calls home, and this network refuses it
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
ARTIFACTS = Path(
    os.environ.get("HLI_TEST_ARTIFACTS") or Path(__file__).resolve().parents[2] / "test-artifacts"
)
WAIT_MS = 20_000  # a loaded machine (2 shared cores) may be slow; every wait ends as soon as it holds

pytestmark = [
    pytest.mark.slow,
    pytest.mark.timeout(180),
    pytest.mark.skipif(
        not Path(CHROMIUM).exists(),
        reason=f"Debian's chromium is not installed ({CHROMIUM}): apt-get install chromium (.ci/run does)",
    ),
]

# the protection cylinder of FCT-C14's older excerpt: centre (150, 0), radius 50, Z -70..70; the block
# N70 goes through it and is refused before it starts (912001), its entry point is X100 Y0
THROUGH = CIRC_PROT_OLD + "N50 G01 X0 Y0 F30000\nN60 #CONTROL AREA ON [ID4]\nN70 G01 X300 F6000\nN80 M30\n"


def _start(*args: str, log: Path) -> tuple[subprocess.Popen[str], str]:
    with log.open("w") as err:
        proc = subprocess.Popen(
            [*hli_server_cmd(), "run", "--http-port", "0", "--no-modbus", *args],
            stdout=subprocess.PIPE,
            stderr=err,  # the server's log (lateness warnings on a loaded machine) must not fill a pipe
            text=True,
        )
    return proc, read_banner(proc)["url"]


@pytest.fixture(scope="module")
def server() -> Iterator[str]:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    proc, url = _start(log=ARTIFACTS / "dashboard-server.log")
    yield url
    stop_server(proc)


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with playwright_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_FLAGS)
        yield b
        b.close()


@pytest.fixture
def page(browser: Any) -> Iterator[Any]:
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = context.new_page()
    page.set_default_timeout(WAIT_MS)
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    yield page
    context.close()
    assert not errors, f"the page's script failed: {errors}"


def _post(url: str, body: bytes, content_type: str = "text/plain") -> int:
    """A request of the control API from outside the page (as another client); its status."""
    request = urllib.request.Request(url, data=body, method="POST", headers={"content-type": content_type})
    with urllib.request.urlopen(request, timeout=10) as answer:
        status: int = answer.status
        return status


def _open(page: Any, url: str) -> None:
    page.goto(url)
    expect(page.locator("#conn")).to_have_text("live", timeout=WAIT_MS)


def _load_and_start(page: Any, text: str) -> None:
    """Load ``text`` into channel 1 from the page's text field and start it."""
    page.click("#ch1-card details.load summary")
    page.fill("#ch1-text", text)
    page.click("#ch1-load")
    expect(page.locator("#message")).to_contain_text("load program: done")
    page.click("#ch1-start")


def _at_rest(page: Any, axes: str = "XYZ") -> None:
    for axis in axes:
        expect(page.locator(f"#axis-{axis} td.status")).to_contain_text("in position", timeout=WAIT_MS)


@pytest.mark.req("C14-14", "C14-15", "E-03")
def test_an_operator_starts_the_demo_program_sees_a_violation_and_resets(server: str, page: Any) -> None:
    p = page
    _open(p, server)
    tcp = p.locator("#tcp-1")
    expect(tcp).to_have_attribute("data-a", re.compile(r"."))
    before = [float(tcp.get_attribute("data-a")), float(tcp.get_attribute("data-b"))]

    # the demo program: the square of the program table, selected and started from the page
    p.select_option("#ch1-program", "1")
    p.click("#ch1-select")
    expect(p.locator("#message")).to_contain_text("select program 1: done")
    p.click("#ch1-start")
    expect(p.locator("#ch1-state")).to_have_text("running")
    expect(p.locator("#ch1-progname")).to_have_text("square")
    # the TCP moves on the picture (more than 5 mm), and the trail follows it
    p.wait_for_function(
        "([a, b]) => { const t = document.querySelector('#tcp-1');"
        " return Math.hypot(t.dataset.a - a, t.dataset.b - b) > 5; }",
        arg=before,
    )
    expect(p.locator("#ch1-tail")).to_have_attribute("points", re.compile(r"\d+.*,.* \d"))
    # the block running now (the realtime clock goes on while the page is asked: any of the program's)
    expect(p.locator("#ch1-block")).to_have_text(re.compile(r"^\s*N[1-9]\d* \(line [1-9]\d*\)\s*$"))
    p.click("#ch1-reset")
    expect(p.locator("#ch1-state")).not_to_have_text("running")
    _at_rest(p)

    # a program whose block N70 goes through an active protection area
    _load_and_start(p, THROUGH)
    alarm = p.locator("#alarms li[data-alarm='912001']")
    expect(alarm).to_contain_text("touches protection area 4")
    expect(alarm).to_contain_text("N70")
    expect(p.locator("#ch1-state")).to_have_text("aborted")
    area = p.locator("#ch1-top .area[data-area='4']")
    expect(area).to_have_attribute("data-state", "active")
    expect(area).to_have_attribute("data-relation", "crosses")
    expect(p.locator("#ch1-violation")).to_have_count(1)
    expect(p.locator("#ch1-refused")).to_have_count(1)
    legend = p.locator("#ch1-legend")
    expect(legend).to_contain_text("refused block N70")
    expect(legend).to_contain_text("violation at X100.0000 Y0.0000 Z0.0000, area 4 (alarm 912001)")
    # what happened (issue 23): the block was refused before it entered the cylinder
    expect(legend).to_contain_text(
        "ID4 PROT active, Z -70..70: the refused block N70 would enter it; the axes stopped before it"
    )
    expect(legend).not_to_contain_text("path goes through it")
    expect(p.locator("#events")).to_contain_text("area_violation")
    p.screenshot(path=str(ARTIFACTS / "dashboard-area-violation.png"), full_page=True)

    # reset: the alarm goes, the refused block and the violation point with it; the area stays (E-03)
    p.click("#ch1-reset")
    expect(p.locator("#alarms li[data-alarm]")).to_have_count(0)
    expect(p.locator("#alarms")).to_contain_text("no active alarm")
    expect(p.locator("#ch1-violation")).to_have_count(0)
    expect(p.locator("#ch1-refused")).to_have_count(0)
    expect(area).to_have_attribute("data-state", "inactive")  # deactivated, not deleted
    expect(p.locator("#alarm-history li[data-alarm='912001']")).to_have_count(1)
    p.screenshot(path=str(ARTIFACTS / "dashboard-reset.png"), full_page=True)


@pytest.mark.req("E-05")
def test_mode_jog_override_feedhold_and_faults_from_the_page(server: str, page: Any) -> None:
    p = page
    _open(p, server)
    p.click("#ch1-reset")
    _at_rest(p)
    # manual mode, jog Y+ while the key is held
    p.click("#ch1-manual")
    expect(p.locator("#ch1-mode")).to_have_text("manual")
    y0 = float(p.locator("#axis-Y td.command").text_content())
    key = p.locator("#ch1-jog-Yplus")
    key.hover()
    p.mouse.down()
    p.wait_for_function(
        "y0 => Number(document.querySelector('#axis-Y td.command').textContent) > y0 + 2", arg=y0
    )
    p.mouse.up()
    expect(p.locator("#message")).to_contain_text("jog Y released")
    _at_rest(p, "Y")
    p.click("#ch1-auto")
    expect(p.locator("#ch1-mode")).to_have_text("automatic")

    # override 50 %, then the circle with a feedhold and its release
    p.locator("#ch1-override").fill("50")
    expect(p.locator("#ch1-override-state")).to_have_text("50 %")
    p.select_option("#ch1-program", "2")
    p.click("#ch1-select")
    expect(p.locator("#message")).to_contain_text("select program 2: done")
    p.click("#ch1-start")
    expect(p.locator("#ch1-state")).to_have_text("running")
    p.click("#ch1-feedhold")
    expect(p.locator("#ch1-state")).to_have_text("held")
    expect(p.locator("#ch1-holds")).to_have_text("feedhold")
    p.click("#ch1-feedhold")
    expect(p.locator("#ch1-state")).to_have_text("running")

    # a drive error on X (A3-05): the axis shows it, an alarm comes, reset and clear end it
    p.click("#axis-X button:has-text('drive error')")
    expect(p.locator("#axis-X td.status")).to_contain_text("ERROR")
    expect(p.locator("#alarms li.error")).not_to_have_count(0)
    p.click("#axis-X button:has-text('clear')")
    p.click("#ch1-reset")
    expect(p.locator("#axis-X td.status")).not_to_contain_text("ERROR")
    expect(p.locator("#alarms")).to_contain_text("no active alarm")
    p.locator("#ch1-override").fill("100")
    expect(p.locator("#ch1-override-state")).to_have_text("100 %")


def test_with_an_api_token_the_page_asks_for_it_once(browser: Any, tmp_path: Path) -> None:
    proc, url = _start("--api-token", "s3cret-token", log=tmp_path / "server.log")
    try:
        context = browser.new_context()
        p = context.new_page()
        p.set_default_timeout(WAIT_MS)
        _open(p, url)
        form = p.locator("#token-form")
        expect(form).to_be_visible()  # hello said the server needs one
        p.fill("#token", "wrong")
        p.click("#token-save")
        expect(form).to_be_hidden()
        p.click("#ch1-select")
        expect(form).to_be_visible()  # 401: asked again, the action kept
        expect(p.locator("#message")).to_contain_text("the token was refused")
        p.fill("#token", "s3cret-token")
        p.click("#token-save")
        expect(p.locator("#message")).to_contain_text("select program 1: done")  # the kept action, retried
        p.click("#ch1-start")
        expect(p.locator("#ch1-state")).to_have_text("running")
        p.click("#ch1-reset")
        expect(p.locator("#ch1-state")).not_to_have_text("running")
        context.close()
    finally:
        stop_server(proc)


def test_a_plain_headless_chromium_sees_the_state_and_the_events_of_before(server: str) -> None:
    """Issue 23: the page is whole at its load event, drawn from what it was served with, before the
    stream says anything: ``chromium --headless --dump-dom`` (which, like ``--screenshot``, takes the
    page at its load event) shows the mode, the program, the axes with their positions, and the event
    of a program loaded before the page was opened. The screenshot is kept as an artifact."""
    status = _post(f"{server}/api/channels/1/program?name=before-the-page", b"N10 G01 X5 F6000\nN20 M30\n")
    assert status in (200, 202)
    dom = subprocess.run(
        [CHROMIUM, *CHROMIUM_FLAGS, "--dump-dom", server + "/"],
        capture_output=True,
        text=True,
        timeout=90,
        check=False,
    ).stdout
    assert 'id="ch1-mode">automatic<' in dom, dom[:3000]
    assert 'id="ch1-progname">before-the-page<' in dom
    for axis in "XYZ":
        row = re.search(rf'<tr id="axis-{axis}">.*?</tr>', dom)
        assert row is not None, f"no row of axis {axis}"
        assert re.search(r'<td class="command">-?\d+\.\d{3}</td>', row.group(0)), row.group(0)
        assert "referenced" in row.group(0)
    assert re.search(r'<li class="event program_state">.*?cause=load program=before-the-page', dom)
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shot = ARTIFACTS / "dashboard-plain-screenshot.png"
    subprocess.run(
        [CHROMIUM, *CHROMIUM_FLAGS, f"--screenshot={shot}", "--window-size=1400,1000", server + "/"],
        capture_output=True,
        timeout=90,
        check=False,
    )
    assert shot.is_file()
    assert shot.stat().st_size > 10_000  # a drawn page, not a blank one


@pytest.mark.req("B-02")
def test_the_record_button_records_the_session_into_the_recording_directory(
    browser: Any, tmp_path: Path
) -> None:
    proc, url = _start("--record-dir", str(tmp_path), log=tmp_path / "server.log")
    try:
        context = browser.new_context()
        p = context.new_page()
        p.set_default_timeout(WAIT_MS)
        _open(p, url)
        button = p.locator("#record")
        expect(button).to_have_text("● Record")
        expect(p.locator("#record-status")).to_have_text("not recording")
        button.click()
        expect(button).to_have_text("■ Stop recording")
        expect(p.locator("#record-status")).to_contain_text("recording session-")
        p.click("#ch1-select")
        p.click("#ch1-start")
        expect(p.locator("#ch1-state")).to_have_text("running")
        button.click()
        expect(button).to_have_text("● Record")
        expect(p.locator("#message")).to_contain_text("hli-server replay FILE replays it")
        context.close()
    finally:
        stop_server(proc)
    files = list(tmp_path.glob("session-*.jsonl.gz"))
    assert len(files) == 1
    ops = [r["op"] for r in read_records(files[0]) if "op" in r]
    assert ops == ["select_program", "start"]


@pytest.mark.req("N-05")
def test_the_v_e_variables_show_what_the_plc_wrote(server: str, page: Any) -> None:
    """The demo machine's V.E. variables in their table; a PLC's write (over HTTP, as an image write)
    shows on the page within a few state messages."""
    p = page
    _open(p, server)
    row = p.locator("#external tr[data-variable='V.E.MODE']")
    expect(row).to_contain_text("global")
    expect(row).to_contain_text("SGN32")
    expect(row).to_contain_text("gpVEGlob^MODE")
    expect(p.locator("#external tr[data-variable='V.E.PLC_READY']")).to_contain_text("global")
    answer = p.request.put(f"{server}/api/image/gpVEGlob.MODE", data={"value": 2})
    assert answer.ok, answer.text()
    expect(row.locator("td.value")).to_have_text("2")
    answer = p.request.put(f"{server}/api/image/gpVEGlob.MODE", data={"value": 0})
    assert answer.ok, answer.text()
    expect(row.locator("td.value")).to_have_text("0")


@pytest.mark.req("N-07")
def test_an_nc_message_shows_on_the_page(server: str, page: Any) -> None:
    p = page
    _open(p, server)
    p.click("#ch1-reset")
    _load_and_start(p, '%msg\nN10 #MSG["hello from the NC"]\nN20 M30\n')
    expect(p.locator("#nc-messages li").first).to_contain_text("hello from the NC", timeout=5_000)


@pytest.mark.req("B-02", "E-05")
def test_the_first_paint_shows_the_recording_and_the_override_in_effect(browser: Any, tmp_path: Path) -> None:
    """Issue 37, item 3: drawn from what the page was served with alone (the stream and the recorder's
    status are held back, as a slow network or a screenshot at the load event sees it), the page shows
    the recording ``--record`` runs, the override in effect (40 %, set through the API before the page
    was opened) on the slider, and says the picture is the served one rather than "connecting…"."""
    record = tmp_path / "run.jsonl.gz"
    proc, url = _start("--record", str(record), log=tmp_path / "server.log")
    try:
        assert _post(f"{url}/api/channels/1/override", b'{"percent": 40}', "application/json") == 202
        # in effect once the clock latched it (the next cycle): the CNC's state of the override unit says so
        state = f"{url}/api/image/gpCh[0].bahn_mc_control.override.state_r"
        deadline = time.monotonic() + 20
        while json.load(urllib.request.urlopen(state, timeout=10))["value"] != 400:
            assert time.monotonic() < deadline, "the override of 40 % never came into effect"
            time.sleep(0.02)
        context = browser.new_context()
        p = context.new_page()
        p.set_default_timeout(WAIT_MS)
        held: list[Any] = []  # the stream's and the recorder's requests, never answered: a slow network

        def hold(route: Any) -> None:  # (Playwright takes no bound method of a builtin)
            held.append(route)

        p.route(re.compile(r".*/api/(live|recording)(\?.*)?$"), hold)
        p.goto(url)
        expect(p.locator("#ch1-override-state")).to_have_text("40 %")
        expect(p.locator("#ch1-override")).to_have_value("40")
        expect(p.locator("#ch1-override-value")).to_have_text("40 %")
        expect(p.locator("#record")).to_have_text("■ Stop recording")
        expect(p.locator("#record-status")).to_contain_text("recording run")
        expect(p.locator("#conn")).to_contain_text("as served at cycle")
        assert held  # the page did ask for them
        context.close()
    finally:
        stop_server(proc)


@pytest.mark.req("E-06", "C14-14")
def test_a_software_limit_refusal_draws_the_refused_block_and_where_it_crosses(
    server: str, page: Any
) -> None:
    """Issue 37, item 3: X's software limit is 600 mm (the demo machine); N20 would cross it at
    X600 Y83.3333 and is refused before it starts (120002): the page draws the refused block and the
    crossing point as it does an area's refusal, and names the limit in the legend."""
    p = page
    _open(p, server)
    p.click("#ch1-reset")
    _at_rest(p)
    _load_and_start(p, "N10 G01 X100 Y0 F30000\nN20 X700 Y100\nN30 M30\n")
    expect(p.locator("#alarms li[data-alarm='120002']")).to_contain_text("N20")
    expect(p.locator("#ch1-state")).to_have_text("aborted")
    expect(p.locator("#ch1-refused")).to_have_count(1)
    expect(p.locator("#ch1-violation")).to_have_count(1)
    legend = p.locator("#ch1-legend")
    expect(legend).to_contain_text(
        "refused block N20 (line 2, alarm 120002, the software limit of X (600.0000 mm))"
    )
    expect(legend).to_contain_text(
        "violation at X600.0000 Y83.3333 Z0.0000, the software limit of X (600.0000 mm) (alarm 120002)"
    )
    p.click("#ch1-reset")
    expect(p.locator("#ch1-refused")).to_have_count(0)
    expect(p.locator("#ch1-violation")).to_have_count(0)
