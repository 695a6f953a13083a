"""Interoperability with a second, independent ADS client: Node's ``ads-client`` (H-04, issue 22).

ads-client 2.x (npm, pinned by ``tests/interop/node/package-lock.json``, installed by ``make test``
and ``make test-fast`` with ``npm ci``) against the real server (realtime clock, the demo machine):
with its default settings, as a user connects it to a TwinCAT (``defaults.js``: system service,
structures, writes, subscriptions, symbols), and in raw mode by index group/offset (``interop.js``).
Skipped, with the reason, where Node or the package is missing: ``cd tests/interop/node && npm ci``
installs it.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import os
import shutil
import struct
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from hli_server.configuration import load_machine
from hli_server.runtime import Runtime

NODE_DIR = Path(__file__).parent / "node"
NODE = shutil.which("node")
MISSING = (
    "node is not installed (apt-get install nodejs)"
    if NODE is None
    else "ads-client is not installed: cd tests/interop/node && npm ci"
    if not (NODE_DIR / "node_modules" / "ads-client" / "package.json").is_file()
    else None
)

pytestmark = [
    pytest.mark.req("H-04"),
    pytest.mark.timeout(60),
    pytest.mark.skipif(MISSING is not None, reason=MISSING or ""),
]

CMD_LOW = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w"
CYCLE = "gpCh[0]^bahn_state.cycle_r"


@pytest.fixture
async def runtime() -> AsyncIterator[Runtime]:
    rt = Runtime(
        load_machine(None),
        clock="realtime",
        http_port=None,
        image_name=f"hli_test_node_{os.getpid()}_{time.monotonic_ns() % 1_000_000}",
        adapters=[("ads", {"port": 0})],
    )
    async with rt:
        yield rt


async def node(
    rt: Runtime, job: dict[str, Any] | list[dict[str, Any]], script: str = "interop.js"
) -> dict[str, Any]:
    assert NODE is not None
    port = getattr(rt.adapter("ads"), "port")  # noqa: B009 - the ADS adapter's attribute
    proc = await asyncio.create_subprocess_exec(
        NODE,
        script,
        str(port),
        json.dumps(job),
        cwd=NODE_DIR,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    out, err = await asyncio.wait_for(proc.communicate(), 30)
    assert proc.returncode == 0, err.decode()
    result: dict[str, Any] = json.loads(out.decode().strip().splitlines()[-1])
    return result


async def test_ads_client_reads_and_writes_by_group_and_offset(runtime: Runtime) -> None:
    layout = runtime.layout
    cmd = layout.signal(CMD_LOW)
    coll = (5 << 16) | 0x0246  # X2's coll_offset at its kernel address, which is port 551's
    x2_coll = layout.signal("gpAx[4]^dyn_coll_mon.coll_offset")
    result = await node(
        runtime,
        {
            "write": [0xF030, cmd.offset, struct.pack("<i", -98_765).hex()],
            "read": [0xF020, x2_coll.offset, 4],
            "error": [0x120300, coll, 4],
        },
    )
    assert runtime.image.read(CMD_LOW) == -98_765
    assert struct.unpack("<I", bytes.fromhex(result["read"]))[0] == 200_000
    assert result["error"] == 0x702  # group 0x120300 lives on port 551, not on 851
    assert result["localAmsNetId"] == "192.168.1.60.1.1"


async def test_ads_client_without_a_local_net_id_gets_one_from_the_server_and_subscribes(
    runtime: Runtime,
) -> None:
    """rawClient without localAmsNetId: ads-client sends 0x1000 port connect first and takes the
    server's NetId and port; its subscription to cycle_r (cyclic, 10 ms) delivers rising cycles."""
    cycle = runtime.layout.signal(CYCLE)
    result = await node(runtime, {"router": True, "subscribe": [0xF020, cycle.offset, 4, 10], "samples": 4})
    assert result["localAmsNetId"] == "127.0.0.1.1.1"
    assert result["localAdsPort"] >= 32768
    cycles = [struct.unpack("<I", bytes.fromhex(s["hex"]))[0] for s in result["samples"]]
    assert len(cycles) == 4
    assert all(b > a for a, b in itertools.pairwise(cycles)), cycles
    for _ in range(250):  # ads-client unsubscribed and disconnected: nothing is left behind
        if getattr(runtime.adapter("ads"), "connection_count") == 0:  # noqa: B009
            break
        await asyncio.sleep(0.02)
    assert getattr(runtime.adapter("ads"), "device").notification_count == 0  # noqa: B009


UNIT = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low"


@pytest.mark.req("B-01")
async def test_ads_client_with_its_default_settings_connects_as_to_a_twincat(runtime: Runtime) -> None:
    """Issue 22: ads-client's defaults (no rawClient, no local NetId) connect; readValue of a control unit
    gives the structure, writeValue of it sets the _w members and leaves the _r members to the CNC,
    subscribeValue and getSymbol work by ST path, and nothing is left after disconnect."""
    image = runtime.image
    cycle = runtime.layout.signal(CYCLE)
    result = await node(
        runtime,
        [
            {"op": "readValue", "path": UNIT},
            {
                "op": "writeValue",
                "path": UNIT,
                "value": {"request_r": 7, "enable_w": True, "command_w": -1234, "state_r": 99},
            },
            {"op": "readValue", "path": UNIT.replace("]^", "].")},
            {"op": "writeValue", "path": f"{UNIT}.command_w", "value": 555},
            {"op": "getSymbol", "path": CYCLE},
            {"op": "getDataType", "name": "MC_CONTROL_SGN32_UNIT"},
            {"op": "subscribeValue", "path": CYCLE, "samples": 3, "cycleTime": 10, "sendOnChange": False},
            {"op": "readValue", "path": "gpAx"},
            {"op": "writeValue", "path": f"{UNIT}.state_r", "value": 1},
        ],
        script="defaults.js",
    )
    conn = result["connection"]
    assert conn["tcSystemState"]["adsState"] == 5  # RUN, read on port 10000
    assert (conn["tcSystemState"]["version"], conn["tcSystemState"]["build"]) == (3, 4024)
    assert conn["plcRuntimeState"]["adsState"] == 5
    assert conn["deviceInfo"]["deviceName"] == "Plc30 App"
    assert (conn["uploadInfo"]["symbolCount"], conn["symbolVersion"]) == (3, 1)  # gpCh, gpAx, gpVEGlob
    read, written, reread, leaf, symbol, unit_type, subscribed, axes, refused = result["results"]
    assert (read["type"], read["size"]) == ("MC_CONTROL_SGN32_UNIT", 13)
    assert list(read["value"]) == ["request_r", "enable_w", "command_w", "state_r"]  # the kernel's order
    assert "error" not in written, written
    assert reread["value"]["command_w"] == -1234
    assert reread["value"]["enable_w"] is True
    assert reread["value"]["request_r"] == 0  # the CNC's, not the 7 written
    assert reread["value"]["state_r"] != 99
    assert image.read(f"{UNIT}.command_w") == 555
    assert "error" not in leaf, leaf
    assert (symbol["type"], symbol["indexGroup"], symbol["indexOffset"]) == ("UDINT", 0xF020, cycle.offset)
    assert "ReadOnly" in symbol["flags"]
    assert unit_type["subItems"] == [
        ["request_r", "DINT", 0, 4],
        ["enable_w", "BOOL", 4, 1],
        ["command_w", "DINT", 5, 4],
        ["state_r", "DINT", 9, 4],
    ]
    values = [s["value"] for s in subscribed["samples"]]
    assert len(values) == 3
    assert all(b > a for a, b in itertools.pairwise(values)), values
    assert len(axes["value"]) == len(runtime.layout.axes)
    assert axes["value"][0]["ipo_mc_control"]["dyn_pos_limit_low"]["command_w"] == 555
    assert refused["adsError"] == 0x704  # a _r field by name: only the CNC writes it
    adapter: Any = runtime.adapter("ads")
    for _ in range(250):  # ads-client unsubscribed everything and disconnected
        if adapter.connection_count == 0:
            break
        await asyncio.sleep(0.02)
    assert (adapter.connection_count, adapter.device.notification_count) == (0, 0)


@pytest.mark.req("N-05")
async def test_ads_client_reads_and_writes_v_e_strings_and_structures() -> None:
    """A second client on the V.E. STRING and structure symbols (issue 33): ads-client reads the types
    from 0xF011 (``STRING(20)``, ``UserInteractionType`` with its members, ``ARRAY [0..1] OF Point``),
    decodes the strings, and writes a string (one too long it cuts itself) and a whole structure."""
    from tests.machines import demo_config

    rt = Runtime(
        demo_config(external=True),
        clock="realtime",
        http_port=None,
        image_name=f"hli_test_node_ve_{os.getpid()}_{time.monotonic_ns() % 1_000_000}",
        adapters=[("ads", {"port": 0})],
    )
    async with rt:
        store = rt.machine.external
        store.write("UserInteraction.Message", 1, "Camera at A1 - OK?")
        store.write("TRACK.LABEL", 2, "P2", (1,))
        result = await node(
            rt,
            [
                {"op": "readValue", "path": "gpVECh[0]^UserInteraction"},
                {"op": "getDataType", "name": "UserInteractionType"},
                {"op": "writeValue", "path": "gpVEGlob^TEACH_FILE_NAME", "value": "teach_0815.dat"},
                {"op": "readValue", "path": "gpVECh[1]^TRACK"},
                {
                    "op": "writeValue",
                    "path": "gpVECh[0]^UserInteraction",
                    "value": {"Message": "Load part", "Answer": 7, "Done": True},
                },
                {"op": "writeValue", "path": "gpVEGlob^TEACH_FILE_NAME", "value": "x" * 21},
            ],
            script="defaults.js",
        )
        read, ui_type, written, track, whole, too_long = result["results"]
        assert read["type"] == "UserInteractionType"
        assert read["value"] == {"Message": "Camera at A1 - OK?", "Answer": 0, "Done": False}
        assert ui_type["subItems"] == [
            ["Message", "STRING(20)", 0, 21],
            ["Answer", "DINT", 21, 4],
            ["Done", "BOOL", 25, 1],
        ]
        assert "error" not in written, written
        assert [p["LABEL"] for p in track["value"]] == ["", "P2"]
        assert "error" not in whole, whole
        assert "error" not in too_long  # ads-client cuts a text to the STRING(20), as TwinCAT does
        for _ in range(100):  # the realtime clock latches the writes within a cycle or two
            if store.read("UserInteraction.Answer", 1) == 7:
                break
            await asyncio.sleep(0.01)
        assert store.read("TEACH_FILE_NAME", 1) == "x" * 20
        assert (store.read("UserInteraction.Message", 1), store.read("UserInteraction.Done", 1)) == (
            "Load part",
            True,
        )
