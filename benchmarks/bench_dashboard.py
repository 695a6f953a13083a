"""The dashboard's cost to the cycle: realtime lateness with the page closed, then open.

``hli-server run`` in its own process (realtime clock at T_A = 1 ms, the select loop, the demo machine)
runs a long program of lines and arcs next to an active protection area, so that the page has a moving
TCP, a growing trail, a path ahead and an area to draw. In one run of that server:

1. page closed for ``--seconds``: ``GET /api/timing`` (its percentiles cover the newest 60,000 cycles,
   i.e. the last 60 s: with ``--seconds 60`` each reading covers exactly its own phase);
2. ``--pages`` event streams ``/api/live`` read by plain clients in this process: what serving them
   costs the server, without a browser on the machine;
3. ``--pages`` dashboards open in headless Chromium (Debian's, driven by Playwright) for ``--seconds``,
   with the event stream live at 20 Hz: ``GET /api/timing`` again.

Per phase: lateness p50 / p99 (its window), the cycles late by more than T_A and the cycles dropped
(counted in the phase), and the server process' CPU time per wall second. The maximum is the whole
run's: a larger one after a phase is that phase's. Chromium runs on the same (2-core) machine, so phase 3
also shows what a browser next to the server costs it.

Reference: the same server in the same run with the page closed.

    .venv/bin/python -m benchmarks.bench_dashboard [--seconds 60] [--pages 1]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

from benchmarks.bench_engine import long_program

AREA = (
    "N1 #CONTROL AREA BEGIN [ID4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]\n"
    "N2 G01 X110 Y0 F6000\n"
    "N3 G02 G162 I40 J0\n"
    "N4 #CONTROL AREA END\n"
    "N5 #CONTROL AREA ON [ID4]\n"
)
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def _get(url: str) -> Any:
    with urllib.request.urlopen(url, timeout=30) as answer:
        return json.loads(answer.read())


def _post(url: str, body: bytes, content_type: str) -> Any:
    req = urllib.request.Request(url, data=body, method="POST", headers={"content-type": content_type})
    with urllib.request.urlopen(req, timeout=60) as answer:
        return json.loads(answer.read())


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _chromium_cpu_s() -> float:
    """CPU time of every Chromium process on the machine (the browser and its renderers)."""
    total = 0.0
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            if b"chromium" not in (proc / "cmdline").read_bytes().split(b"\0")[0]:
                continue
            total += _cpu_s(int(proc.name))
        except OSError:
            continue
    return total


def _phase(url: str, pid: int, seconds: float, before: dict[str, Any]) -> dict[str, Any]:
    cpu0, browser0, t0 = _cpu_s(pid), _chromium_cpu_s(), time.monotonic()
    time.sleep(seconds)
    cpu1, browser1, t1 = _cpu_s(pid), _chromium_cpu_s(), time.monotonic()
    timing = _get(f"{url}/api/timing")
    lat = timing["lateness_us"]
    return {
        "timing": timing,
        "p50_us": lat["p50"],
        "p99_us": lat["p99"],
        "max_us": lat["max"],
        "late": timing["late_cycles"] - before.get("late_cycles", 0),
        "dropped": timing["slipped_cycles"] - before.get("slipped_cycles", 0),
        "cycles": timing["cycles"] - before.get("cycles", 0),
        "cpu": (cpu1 - cpu0) / (t1 - t0),
        "browser_cpu": (browser1 - browser0) / (t1 - t0),
    }


def _read_stream(url: str, stop: threading.Event, counts: list[int], k: int) -> None:
    with urllib.request.urlopen(f"{url}/api/live", timeout=30) as stream:
        for line in stream:
            if line.startswith(b"event: state"):
                counts[k] += 1
            if stop.is_set():
                return


def _line(name: str, r: dict[str, Any]) -> str:
    return (
        f"{name:12} lateness p50 {r['p50_us']:8.0f} µs, p99 {r['p99_us']:8.0f} µs,"
        f" max (run) {r['max_us'] / 1000:6.1f} ms;"
        f" late > T_A {r['late']:6d} of {r['cycles']} cycles, dropped {r['dropped']:5d};"
        f" server CPU {r['cpu'] * 100:5.1f} %"
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--seconds", type=float, default=60.0, help="length of each phase (60: its own window)"
    )
    parser.add_argument("--pages", type=int, default=1, help="dashboards open in phase 2")
    args = parser.parse_args()
    chromium = os.environ.get("HLI_CHROMIUM") or shutil.which("chromium")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        print("skipped: Playwright's Python package is missing (pip install -e '.[test]')")
        return
    if chromium is None:
        print("skipped: Debian's chromium is not installed (apt-get install chromium)")
        return
    server = Path(sys.executable).parent / "hli-server"
    proc = subprocess.Popen(
        [str(server), "run", "--http-port", "0", "--no-modbus"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        url = ""
        assert proc.stdout is not None
        for line in proc.stdout:
            if "HTTP control API:" in line:
                url = line.split("HTTP control API:")[1].split()[0]
            if "stop with" in line:
                break
        program = AREA + long_program(20_000)
        _post(f"{url}/api/channels/1/program?name=bench", program.encode(), "text/plain")
        _post(f"{url}/api/channels/1/start", b"", "application/json")
        time.sleep(2.0)  # the program runs; the start-up is not measured
        closed = _phase(url, proc.pid, args.seconds, _get(f"{url}/api/timing"))
        # the event streams alone (plain readers in this process): what serving them costs the server
        stop = threading.Event()
        counts = [0] * args.pages
        readers = [
            threading.Thread(target=_read_stream, args=(url, stop, counts, k)) for k in range(args.pages)
        ]
        for reader in readers:
            reader.start()
        time.sleep(1.0)
        streams = _phase(url, proc.pid, args.seconds, _get(f"{url}/api/timing"))
        stop.set()
        for reader in readers:
            reader.join(10)
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=FLAGS)
            pages = []
            for _ in range(args.pages):
                page = browser.new_page(viewport={"width": 1400, "height": 1000})
                page.goto(url)
                page.wait_for_function("() => document.querySelector('#conn').textContent === 'live'")
                pages.append(page)
            time.sleep(1.0)  # the browser's start is not measured
            opened = _phase(url, proc.pid, args.seconds, _get(f"{url}/api/timing"))
            lost = pages[0].evaluate("() => document.querySelector('#dropped').textContent")
            browser.close()
    finally:
        proc.terminate()
        proc.wait(10)
    print(f"server: {url}, {args.seconds:g} s per phase, program running, T_A 1 ms")
    print(_line("page closed", closed))
    print(_line(f"{args.pages} stream(s)", streams) + f"; states received {min(counts) / args.seconds:.1f}/s")
    print(
        _line(f"{args.pages} page(s)", opened)
        + f"; Chromium CPU {opened['browser_cpu'] * 100:.1f} %; events lost by the page: {lost}"
    )
    ratio = opened["p99_us"] / closed["p99_us"] if closed["p99_us"] else float("nan")
    print(
        f"figure: p99 lateness with the page open {opened['p99_us']:.0f} µs; reference (page closed, "
        f"same run) {closed['p99_us']:.0f} µs; ratio {ratio:.2f}"
    )


if __name__ == "__main__":
    main()
