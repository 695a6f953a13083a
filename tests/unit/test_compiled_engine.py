"""The compiled and the pure engine give the same outputs, cycle for cycle (issue 16).

``pip install`` compiles the engine with mypyc where it can (``setup.py``); ``HLI_PURE_PYTHON=1`` runs the
same source as plain Python (``hli_server/_compiled.py``). The suite itself runs with whichever engine
the installation has; this test runs the recorded scenarios (``test_recorded_scenarios.py``) in a second
process with the *other* engine, so that both are held to the same recording: every published field,
every event, every cycle. Where the engine is not compiled (no C compiler) it says so and runs the
pure one only, which the suite does anyway.
"""

from __future__ import annotations

import hashlib
import random
import struct
import subprocess
import sys
from pathlib import Path

import pytest

import hli_server._compiled as compiled
from hli_server.adapters.ads import AdsDevice, Session
from hli_server.codecs.ads import (
    AmsAddress,
    AmsPacket,
    AmsStreamDecoder,
    AmsStreamError,
    NetId,
    encode_request,
)
from hli_server.configuration import load_machine
from hli_server.image import ProcessImage
from schemas.layout import Direction, build_layout

ROOT = Path(__file__).parents[2]


def _run_scenarios(pure: bool) -> subprocess.CompletedProcess[str]:
    env = compiled.environment(pure)
    code = (
        "import json, sys\n"
        "import hli_server._compiled as c\n"
        "import tests.unit.test_recorded_scenarios as t\n"
        "rec = t._recorded()\n"
        "bad = [n for n, (run, size) in t.SCENARIOS.items() if run(size)[0] != rec[n]['digest']]\n"
        "print(json.dumps({'compiled': c.ENGINE_COMPILED, 'differ': bad}))\n"
    )
    return _python(code, env, timeout=600)


def _python(code: str, env: dict[str, str], timeout: float) -> subprocess.CompletedProcess[str]:
    """``code`` run by this interpreter in a second process, from the checkout, with ``env``."""
    return subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


@pytest.mark.slow
@pytest.mark.req("E-01")
def test_the_other_engine_gives_the_recorded_outputs_cycle_for_cycle() -> None:
    import json

    other_is_pure = compiled.ENGINE_COMPILED
    done = _run_scenarios(pure=other_is_pure)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    if not other_is_pure and not result["compiled"]:
        pytest.skip("the engine is not compiled here (no C compiler or mypyc at install): pure Python only")
    assert result["compiled"] is (not other_is_pure)
    assert result["differ"] == [], (
        f"{'pure' if other_is_pure else 'compiled'} engine differs in {result['differ']}"
    )


def test_pure_python_can_be_forced_for_debugging() -> None:
    """HLI_PURE_PYTHON=1 loads every engine module, and the ADS request path's, from its .py file
    (breakpoints, profilers)."""
    env = compiled.environment(pure=True)
    code = (
        "import hli_server._compiled as c, hli_server.engine.machine as m, hli_server.engine.nc.parser as p\n"
        "import hli_server.adapters.ads.device as d, hli_server.adapters.ads.data as a\n"
        "print(c.ENGINE_COMPILED, *(x.__file__.endswith('.py') for x in (m, p, d, a)))\n"
    )
    done = _python(code, env, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "True", "True", "True", "True"]


def test_an_install_with_a_c_compiler_compiled_the_engine() -> None:
    """A build that falls back to pure Python says so only in pip's verbose output; the suite says it
    loudly where the machine could have compiled (``why_not_compilable``, which setup.py asks too). It
    once fell back on a fresh machine because numpy, new in the engine, was missing from the build
    requirements (pyproject.toml [build-system]): mypyc type-checks what the engine imports."""
    why = compiled.why_not_compilable()  # what setup.py asks
    if why is not None:
        pytest.skip(f"the engine is pure Python here: {why}")
    built, missing = compiled.stale_modules()
    assert built, (
        "the engine was installed as pure Python although this machine can compile it: run "
        "`.venv/bin/python -m pip install -v --no-deps -e .` and read the lines that start 'hli-server:'"
    )
    assert not [p for p in missing if compiled._compiled_file(p) is None], missing


def test_an_edited_engine_source_is_said_where_the_server_starts(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A compiled module older than its source switches the whole engine to pure Python: besides the
    import-time warning, the runtime says so in its log at start and ``run`` in its banner (issue 28)."""
    import asyncio
    import logging

    from hli_server.configuration import load_machine
    from hli_server.runtime import Runtime, memory_image

    monkeypatch.setattr(compiled, "ENGINE_COMPILED", compiled.ENGINE_COMPILED)
    monkeypatch.setattr(compiled, "_STALE_NOTICE", None)
    finders = [f for f in sys.meta_path if not isinstance(f, compiled._PureEngineFinder)]
    monkeypatch.setattr(sys, "meta_path", finders)
    monkeypatch.delenv(compiled.PURE_ENV, raising=False)
    source = compiled._ENGINE_DIR / "axis.py"
    monkeypatch.setattr(compiled, "stale_modules", lambda: ([source.with_suffix(".so")], [source]))
    with pytest.warns(RuntimeWarning, match="older than its source"):
        assert compiled.select() is False
    notice = compiled.stale_notice()
    assert notice is not None
    assert "hli_server/engine/axis.py" in notice
    assert "make compile" in notice

    async def start_and_stop() -> None:
        async with Runtime(
            load_machine(None), clock="stepped", http_port=None, adapters=[], image_factory=memory_image
        ):
            pass

    with caplog.at_level(logging.WARNING, logger="hli_server.runtime.core"):
        asyncio.run(start_and_stop())
    assert "the whole engine and the ADS request path run as pure Python" in caplog.text


# ------------------------------------------------------------------------------------------------
# The ADS request path (hli_server/adapters/ads, _compiled.ADS_COMPILED) is compiled with the engine
# ------------------------------------------------------------------------------------------------

ADS_SYMBOLS = (
    "gpAx[0]^ipo_state.cmd_pos_r",
    "gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w",
    "GPAX[0].IPO_MC_CONTROL.DYN_POS_LIMIT_LOW.ENABLE_W",
    "gpAx[0]^ipo_mc_control.dyn_pos_limit_high",
    "gpAx[1]^ipo_state",
    "no_such_symbol",
    "gpAx[99]^ipo_state.cmd_pos_r",
    "",
)
"""Names the exchange asks: fields, structures, other spellings, unknown ones."""


def ads_exchange_digest(frames: int = 3000, seed: int = 7) -> str:
    """The replies of an ADS device to a fixed exchange of requests, and the image and counters after
    it, as one digest: well-formed requests of every command the door serves (handles, values by name,
    the halves, the view, sums, port 551, unknown groups and ports) and mutated ones, each answered the
    way the connection answers it (``handle_frame``, else decoded and ``handle``)."""
    layout = build_layout(load_machine(None))
    image = ProcessImage.in_memory(layout, name="ads_exchange")
    try:
        return _exchange(image, frames, random.Random(seed))
    finally:
        image.close()


def _exchange(image: ProcessImage, frames: int, rng: random.Random) -> str:
    layout = image.layout
    server = NetId.parse("127.0.0.1.1.1")
    client = AmsAddress(NetId.parse("10.1.2.3.1.1"), 30001)
    device = AdsDevice(image, server)
    session = Session()
    position = layout.signal(ADS_SYMBOLS[0])
    command_w = layout.signal(ADS_SYMBOLS[1])
    enable_w = layout.signal("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.enable_w")
    geo = [s for s in layout.signals if s.ads_port == 551]
    groups = (0xF020, 0xF030, 0x4040, 0xF003, 0xF004, 0xF005, 0xF006, 0xF080, 0xF081, 0xF082, 0x120300, 0x7)
    handles: list[int] = [0, 0x1000_0001]
    digest = hashlib.sha256()
    u32x3, u32x4 = struct.Struct("<III"), struct.Struct("<IIII")

    def by_name(group: int, read_length: int) -> tuple[int, int, bytes]:
        name = rng.choice(ADS_SYMBOLS[:5]).encode() + b"\0"
        return 851, 9, u32x4.pack(group, 0, read_length, len(name)) + name

    def well_formed() -> tuple[int, int, bytes]:
        """(port, command, payload) of a request a PLC's polling sends."""
        pick = rng.randrange(12)
        if pick == 0:
            return 851, 2, u32x3.pack(0xF020, position.offset, 4)
        if pick == 1:
            return 851, 2, u32x3.pack(0xF030, command_w.offset, 4)
        if pick == 2:
            return 851, 3, u32x3.pack(0xF030, command_w.offset, 4) + rng.randbytes(4)
        if pick == 3:
            return 851, 3, u32x3.pack(0xF030, enable_w.offset, 1) + bytes((rng.choice((0, 1, 1, 2)),))
        if pick == 4:
            return by_name(0xF003, rng.choice((4, 4, 64)))
        if pick == 5:
            return 851, 2, u32x3.pack(0xF005, handles[-1], rng.choice((4, 4, 8)))
        if pick == 6:
            return 851, 3, u32x3.pack(0xF006, 0, 4) + struct.pack("<I", rng.choice(handles[-3:]))
        if pick == 7:
            return by_name(0xF004, 4)
        if pick == 8:
            items = u32x3.pack(0xF020, position.offset, 4) + u32x3.pack(0xF030, command_w.offset, 4)
            return 851, 9, u32x4.pack(0xF080, 2, 2 * 4 + 8, len(items)) + items
        if pick == 9:
            return 851, 2, u32x3.pack(0x4040, rng.choice((0, 4, 8)), rng.choice((4, 16, 64)))
        if pick == 10:
            signal = rng.choice(geo)
            return 551, 2, u32x3.pack(0x120300, signal.ads_offset, signal.size)
        return rng.choice((851, 10000)), rng.choice((1, 4)), b""

    def anything(command: int) -> bytes:
        group = rng.choice(groups)
        name = rng.choice(ADS_SYMBOLS).encode() + b"\0"
        if command == 9:  # ReadWrite: by name, sums, anything
            if group in (0xF080, 0xF081, 0xF082):
                items = rng.randint(0, 3)
                head = b"".join(u32x3.pack(0xF020, position.offset, 4) for _ in range(items))
                return u32x4.pack(group, items, 12 * items + rng.choice((0, 4, 8)), len(head)) + head
            return u32x4.pack(group, 0, rng.choice((4, 8, 64, 1024)), len(name)) + name
        offset = rng.choice((0, position.offset, rng.choice(handles), rng.randrange(1 << 20)))
        size = rng.choice((0, 1, 4, 8, 12, 1024))
        if command == 3:  # Write
            data = struct.pack("<I", rng.choice(handles)) if group == 0xF006 else rng.randbytes(size)
            return u32x3.pack(group, offset, len(data)) + data
        return u32x3.pack(group, offset, size)

    for n in range(frames):
        if n % 7 == 0:
            image.publish_bytes(layout.pack(Direction.CNC_TO_PLC, {ADS_SYMBOLS[0]: n * 1000 - 5}), n)
        if rng.random() < 0.6:
            port, command, payload = well_formed()
        else:
            command = rng.choice((2, 2, 3, 9, 9, 1, 4, 6, 0, 8))
            port = rng.choice((851, 851, 851, 551, 10000, 7))
            payload = anything(command)
        frame = bytearray(encode_request(AmsAddress(server, port), client, command, n, payload))
        if rng.random() < 0.1:  # a mutated frame
            for _ in range(rng.randint(1, 3)):
                frame[rng.randrange(len(frame))] = rng.randrange(256)
        reply = device.handle_frame(session, bytes(frame), bytes(client.net_id))
        if reply is None:
            try:
                packets = list(AmsStreamDecoder().feed(bytes(frame)))
            except AmsStreamError as exc:  # the stream error is part of what is compared
                reply = str(exc).encode()
            else:
                replies = [device.handle(session, p) for p in packets if isinstance(p, AmsPacket)]
                reply = b"|".join(r or b"-" for r in replies)
        digest.update(len(reply).to_bytes(4, "little") + reply)
        if command == 9 and len(reply) >= 50 and reply[38:42] == bytes(4):  # a handle, maybe
            handles.append(struct.unpack_from("<I", reply, 46)[0])
    digest.update(image.read_half(Direction.PLC_TO_CNC))
    stats = device.stats
    digest.update(repr((stats.requests, sorted(stats.errors.items()), stats.failures)).encode())
    digest.update(repr(sorted(session.handles)).encode())
    return digest.hexdigest()


@pytest.mark.req("H-04")
def test_the_other_build_of_the_ads_request_path_gives_the_same_replies() -> None:
    """The compiled ADS request path and the pure one answer the same exchange with the same bytes and
    leave the same image and counters (the ADS tests run with whichever the installation has)."""
    import json

    other_is_pure = compiled.ENGINE_COMPILED
    env = compiled.environment(other_is_pure)
    code = (
        "import json\n"
        "import hli_server._compiled as c\n"
        "import hli_server.adapters.ads.device as d\n"
        "import tests.unit.test_compiled_engine as t\n"
        "digest = t.ads_exchange_digest()\n"
        "print(json.dumps({'compiled': c.ENGINE_COMPILED, 'file': d.__file__, 'digest': digest}))\n"
    )
    done = _python(code, env, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    other = json.loads(done.stdout.strip().splitlines()[-1])
    if not other_is_pure and not other["compiled"]:
        pytest.skip("nothing is compiled here (no C compiler or mypyc at install): pure Python only")
    assert other["compiled"] is (not other_is_pure)
    assert other["file"].endswith(".py") is other_is_pure  # the device module of the other build ran
    assert other["digest"] == ads_exchange_digest()
