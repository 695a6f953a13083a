"""docs/ads.md's steps of a TwinCAT user, run as written against ``hli-server run`` (H-04, issue 22).

The server is started as the document starts it (``--ads-port 48898``, AddRoute credentials), on a
loopback address of its own (127.x.y.z: pyads always sends AddRoute and discovery to UDP port 48899,
so each run needs its own address); the blocks run in fresh processes (AdsLib keeps one router per
process) with the server's address put where the document says 127.0.0.1.
"""

from __future__ import annotations

import os
import random
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.doc_blocks import DOCS, marked_block
from tests.integration.servers import read_banner, start_server, stop_server

pytestmark = [
    pytest.mark.req("H-04", "B-01"),
    pytest.mark.slow,
    pytest.mark.timeout(120),
    pytest.mark.skipif(
        not sys.platform.startswith("linux"), reason="binds 127.x.y.z (Linux answers all of 127/8)"
    ),
]

ADS_MD = DOCS / "ads.md"
NODE_DIR = Path(__file__).resolve().parents[1] / "interop" / "node"


@pytest.fixture(scope="module")
def server() -> Iterator[str]:
    rng = random.Random()
    for _ in range(10):
        address = f"127.{rng.randrange(1, 255)}.{rng.randrange(256)}.{rng.randrange(1, 255)}"
        proc = start_server(
            *("--bind", address, "--http-port", "0", "--no-modbus", "--ads-port", "48898"),
            *("--adapter", "ads:route_user=Administrator"),
            *("--image-name", f"hli_test_adsdoc_{os.getpid()}_{time.monotonic_ns() % 10**6}"),
            env={"HLI_ADS_ROUTE_PASSWORD": "1"},  # as docs/ads.md, step 1
        )
        try:
            banner = read_banner(proc)
        except AssertionError:
            stop_server(proc)
            continue  # the address was taken by a test beside this one
        try:
            assert banner["ADS (UDP)"].startswith(f"ADS (UDP): {address}:48899")
            yield address
        finally:
            stop_server(proc)
        return
    pytest.skip("no free 127.x.y.z:48898 found")


def run_block(code: str) -> str:
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_discover_add_a_route_and_connect_pyads_as_the_document_says(server: str) -> None:
    found = run_block(marked_block(ADS_MD, "discover").replace('"127.0.0.1"', f'"{server}"'))
    assert found.strip() == "127.0.0.1.1.1"
    add = marked_block(ADS_MD, "add_route").replace(
        '"127.0.0.1", "Administrator"', f'"{server}", "Administrator"'
    )
    assert run_block(add).strip() == "True"
    lines = run_block(
        marked_block(ADS_MD, "pyads").replace("127.0.0.1:48898", f"{server}:48898")
    ).splitlines()
    assert lines[0] == "(5, 0)"
    int(lines[1])  # a position
    assert "('enable_w', True), ('command_w', -500000)" in lines[2]
    # issue 37, item 5: read after the cycle that latched the write, the CNC's state of the unit
    assert "('state_r', 2)" in lines[2], lines[2]


@pytest.mark.skipif(
    shutil.which("node") is None or not (NODE_DIR / "node_modules" / "ads-client").is_dir(),
    reason="node or ads-client missing: cd tests/interop/node && npm ci",
)
def test_the_ads_client_block_runs_as_written(server: str, tmp_path: Path) -> None:
    text = ADS_MD.read_text(encoding="utf-8")
    start = text.index("<!-- ads_client")
    code = text[text.index("```js\n", start) + 6 : text.index("```\n", text.index("```js\n", start) + 6)]
    code = code.replace("targetAdsPort: 851 }", f"targetAdsPort: 851, routerAddress: '{server}' }}")
    script = tmp_path / "block.js"
    script.write_text(code)
    env = {**os.environ, "NODE_PATH": str(NODE_DIR / "node_modules")}
    done = subprocess.run(
        ["node", str(script)], capture_output=True, text=True, timeout=60, env=env, check=False
    )
    assert done.returncode == 0, done.stderr
    assert "command_w:" in done.stdout
    assert "'DINT'" in done.stdout or '"DINT"' in done.stdout
