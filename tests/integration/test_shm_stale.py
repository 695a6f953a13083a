"""A segment in the way of the server's image: replaced only when it is a stale HLI image (H-01).

Issue 12 finding 7: ``run --image-name X`` deleted any segment ``X`` in /dev/shm that had no image
header ("removing stale shared memory"), even one of another program; and a stale image whose
recorded PID now belonged to another live process blocked the restart until removed by hand. The
header now records the server's PID with its start time (and PID namespace), see
``hli_server/image/shm.py``. Everything here is real POSIX shared memory with unique names, removed
at the end of each test.
"""

from __future__ import annotations

import os
import secrets
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from hli_server.image import ProcessImage
from hli_server.image.shm import pid_namespace, process_start_ticks
from plc_clients.shm import ImageClient
from schemas import image_format as fmt
from schemas.layout import Layout, build_layout
from tests.machines import demo_config

FOREIGN_BYTES = b"another program's data, not an image " * 100


@pytest.fixture(scope="module")
def layout() -> Layout:
    return build_layout(demo_config())


@pytest.fixture
def segment_name() -> Iterator[str]:
    """A unique name; whatever segment has it at the end of the test is removed."""
    name = f"hli_{os.getpid()}_{secrets.token_hex(3)}_stale"
    yield name
    Path("/dev/shm", name).unlink(missing_ok=True)


@pytest.fixture
def other_process() -> Iterator[int]:
    """A live process that is not an hli-server: the PID a stale image may name after PID reuse."""
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        yield proc.pid
    finally:
        proc.kill()
        proc.wait(timeout=10)


def make_segment(name: str, data: bytes) -> None:
    """A POSIX shared-memory segment as another program makes it (on Linux a file in /dev/shm): not
    through ``multiprocessing``, whose resource tracker would claim it for this process."""
    with Path("/dev/shm", name).open("xb") as f:
        f.write(data)


def segment_bytes(name: str) -> bytes:
    seg = fmt.attach_untracked(name)
    try:
        assert seg.buf is not None
        return bytes(seg.buf)
    finally:
        seg.close()


def image_bytes(layout: Layout, *, pid: int, start: int, pid_ns: int, magic: bytes = fmt.MAGIC) -> bytes:
    """The bytes of an image a server with ``pid`` / ``start`` / ``pid_ns`` left behind."""
    layout_json = layout.to_json(indent=None).encode("utf-8")
    plan = fmt.plan_segment(len(layout_json), layout.p2c_size, layout.c2p_size)
    header = fmt.ImageHeader(
        magic=magic,
        format_version=fmt.FORMAT_VERSION,
        layout_version=layout.version,
        layout_hash=layout.hash,
        header_size=fmt.HEADER_SIZE,
        total_size=plan.total_size,
        plan=plan,
        flags=0,
        publish_count=7,
        cycle=7,
        server_pid=pid,
        server_start=start,
        server_pid_ns=pid_ns,
    )
    data = bytearray(plan.total_size)
    data[: fmt.HEADER_SIZE] = header.pack()
    data[plan.layout_json_offset : plan.layout_json_offset + len(layout_json)] = layout_json
    return bytes(data)


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait(timeout=30)
    return proc.pid


def run_server(name: str, *args: str) -> subprocess.CompletedProcess[str]:
    """``hli-server run`` for a few cycles on the image name, no network doors."""
    cmd = [str(Path(sys.executable).parent / "hli-server"), "run", "--image-name", name]
    return subprocess.run(
        [*cmd, "--no-http", "--no-modbus", "--cycles", "20", *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


# --- what the server writes -------------------------------------------------------------------------


@pytest.mark.req("H-01")
def test_the_header_names_the_server_by_pid_start_time_and_namespace(layout: Layout) -> None:
    with ProcessImage.create(layout) as image, ImageClient.attach(image.name) as client:
        header = client.header
        assert header.server_pid == os.getpid()
        assert header.server_start == process_start_ticks(os.getpid()) > 0
        assert header.server_pid_ns == pid_namespace() > 0
        parsed = fmt.header_construct().parse(segment_bytes(image.name)[: fmt.HEADER_SIZE])  # type: ignore[attr-defined]
        assert (parsed.server_start, parsed.server_pid_ns) == (header.server_start, header.server_pid_ns)


def test_process_start_ticks_tells_processes_apart(other_process: int) -> None:
    assert process_start_ticks(other_process) >= process_start_ticks(os.getpid()) > 0
    assert process_start_ticks(dead_pid()) == 0


# --- segments that are not ours are never touched ---------------------------------------------------


@pytest.mark.req("H-01")
@pytest.mark.parametrize(
    "data",
    [FOREIGN_BYTES, bytes(4096), b"x" * 64, b"HLI-IMG\x00" + bytes(200)],
    ids=["text", "zeros", "small", "magic-only"],
)
def test_a_segment_without_an_image_header_is_refused_and_left_alone(
    layout: Layout, segment_name: str, data: bytes
) -> None:
    make_segment(segment_name, data)
    with pytest.raises(FileExistsError) as info:
        ProcessImage.create(layout, segment_name, replace_stale=True)
    message = str(info.value)
    assert f"shared memory {segment_name!r} exists and is not an HLI process image" in message
    assert f"remove /dev/shm/{segment_name} yourself if you know it is unused" in message
    assert segment_bytes(segment_name)[: len(data)] == data


@pytest.mark.req("H-01")
def test_run_refuses_an_image_name_taken_by_another_program(segment_name: str) -> None:
    """The real door: ``hli-server run --image-name X`` (the issue's command)."""
    make_segment(segment_name, FOREIGN_BYTES)
    done = run_server(segment_name)
    assert done.returncode == 2, done.stderr
    assert f"shared memory {segment_name!r} exists and is not an HLI process image" in done.stderr
    assert "removing stale" not in done.stderr
    assert segment_bytes(segment_name) == FOREIGN_BYTES


@pytest.mark.req("H-01")
def test_an_image_of_a_server_in_another_pid_namespace_is_left_alone(
    layout: Layout, segment_name: str, other_process: int
) -> None:
    data = image_bytes(layout, pid=other_process, start=1, pid_ns=pid_namespace() + 1)
    make_segment(segment_name, data)
    with pytest.raises(FileExistsError, match="another PID namespace"):
        ProcessImage.create(layout, segment_name, replace_stale=True)
    assert segment_bytes(segment_name) == data


# --- stale images are replaced ----------------------------------------------------------------------


@pytest.mark.req("H-01")
def test_a_stale_image_whose_pid_now_belongs_to_another_process_is_replaced(
    layout: Layout, segment_name: str, other_process: int
) -> None:
    """The PID is alive, but the process that has it started later than the one that wrote the image."""
    reused = image_bytes(
        layout, pid=other_process, start=process_start_ticks(other_process) - 1, pid_ns=pid_namespace()
    )
    make_segment(segment_name, reused)
    with ProcessImage.create(layout, segment_name, replace_stale=True) as fresh:
        with ImageClient.attach(segment_name, expect=layout) as client:
            assert client.header.server_pid == os.getpid()
            assert client.publish_count == 0
        assert fresh.name == segment_name


@pytest.mark.req("H-01")
def test_run_replaces_a_stale_image_whose_pid_was_reused(segment_name: str, other_process: int) -> None:
    layout = build_layout(demo_config())
    make_segment(
        segment_name,
        image_bytes(layout, pid=other_process, start=process_start_ticks(other_process) - 1, pid_ns=0),
    )
    done = run_server(segment_name)
    assert done.returncode == 0, done.stderr
    assert f"replacing the stale process image {segment_name}" in done.stderr
    assert not Path("/dev/shm", segment_name).exists()  # the server unlinked its own image at exit


@pytest.mark.req("H-01")
@pytest.mark.parametrize(
    "writer",
    [
        lambda: (dead_pid(), 0),  # an older header without the start time: a dead PID still decides
        lambda: (dead_pid(), 12345),
    ],
    ids=["no-start-time", "dead-pid"],
)
@pytest.mark.parametrize("magic", [fmt.MAGIC, bytes(8)], ids=["ready", "died-while-starting"])
def test_a_stale_image_of_a_dead_server_is_replaced(
    layout: Layout, segment_name: str, writer: Callable[[], tuple[int, int]], magic: bytes
) -> None:
    pid, start = writer()
    make_segment(segment_name, image_bytes(layout, pid=pid, start=start, pid_ns=pid_namespace(), magic=magic))
    with (
        ProcessImage.create(layout, segment_name, replace_stale=True),
        ImageClient.attach(segment_name, expect=layout) as client,
    ):
        assert client.header.server_pid == os.getpid()


@pytest.mark.req("H-01")
def test_the_image_of_a_live_writer_is_not_replaced(
    layout: Layout, segment_name: str, other_process: int
) -> None:
    """Same PID and start time: the process that wrote the image still runs."""
    data = image_bytes(layout, pid=other_process, start=process_start_ticks(other_process), pid_ns=0)
    make_segment(segment_name, data)
    with pytest.raises(FileExistsError, match=f"the image of the running server pid {other_process}"):
        ProcessImage.create(layout, segment_name, replace_stale=True)
    assert segment_bytes(segment_name) == data
