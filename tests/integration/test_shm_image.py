"""The shared-memory process image with a second process (H-01, H-02, H-08).

Everything here goes through real POSIX shared memory; the second process is spawned (a fresh
interpreter that imports only ``schemas`` and ``plc_clients``) or, where the resource tracker
matters, started as an independent ``python -c``.
"""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
import textwrap
import time
from multiprocessing import shared_memory
from pathlib import Path

import pytest

from hli_server.engine.hli import AxisHli, ChannelHli, MachineHli
from hli_server.image import ProcessImage, engine_value, set_engine_value
from plc_clients.shm import ImageClient
from schemas import image_format as fmt
from schemas.layout import Direction, ReadOnlySignalError, SignalValueError, build_layout
from tests.integration import _shm_children as children
from tests.machines import demo_config, distinct_values

P2C, C2P = Direction.PLC_TO_CNC, Direction.CNC_TO_PLC
SPAWN = multiprocessing.get_context("spawn")
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def layout():
    return build_layout(demo_config())


@pytest.fixture
def image(layout):
    with ProcessImage.create(layout) as img:
        yield img


def _machine(layout) -> MachineHli:
    return MachineHli(channels=[ChannelHli() for _ in layout.channels], axes=[AxisHli() for _ in layout.axes])


def _dev_shm(name: str) -> Path:
    return Path("/dev/shm") / name


# --- byte for byte through a second process ------------------------------------------------------


@pytest.mark.req("H-01", "H-08")
def test_every_field_written_through_the_layout_reads_back_byte_for_byte_in_a_second_process(layout, image):
    machine = _machine(layout)
    c2p_values = distinct_values(layout, C2P, salt=1)
    for s in layout.half(C2P):
        set_engine_value(machine, s, c2p_values[s.st_path])
    image.publish_from(machine, cycle=4242)
    p2c_values = distinct_values(layout, P2C, salt=2)
    for st_path, value in p2c_values.items():
        image.write(st_path, value)
    plc_writes = distinct_values(layout, P2C, salt=5)

    parent, child = SPAWN.Pipe()
    proc = SPAWN.Process(target=children.read_everything, args=(image.name, child, plc_writes))
    proc.start()
    try:
        assert parent.poll(60), "the second process did not answer"
        seen = parent.recv()
        # every field by ST path, as the map names it
        assert seen["hash"] == layout.hash
        assert seen["values"] == {**c2p_values, **p2c_values}
        assert seen["snapshot"] == c2p_values
        assert seen["cycle"] == 4242
        # the raw halves are the bytes the layout's construct description builds
        assert seen["c2p"] == layout.construct(C2P).build(c2p_values)
        assert seen["p2c"] == layout.construct(P2C).build(p2c_values)
        # and the other way: the second process writes every PLC->CNC field, the engine latches them
        assert parent.poll(60)
        assert parent.recv() == "written"
    finally:
        proc.join(30)
    assert proc.exitcode == 0
    image.latch_into(machine)
    assert {s.st_path: engine_value(machine, s) for s in layout.half(P2C)} == plc_writes
    assert image.read_half(P2C) == layout.construct(P2C).build(plc_writes)


# --- no torn CNC->PLC snapshot -----------------------------------------------------------------------


def _uniform_setter(layout, machine):
    """(parent object, attribute, type) of every CNC->PLC field, resolved once."""
    out = []
    for s in layout.half(C2P):
        head, _, leaf = s.path.rpartition(".")
        obj = (machine.channels if s.st_path.startswith("gpCh") else machine.axes)[s.index]
        for part in head.split("."):
            obj = getattr(obj, part)
        out.append((obj, leaf, s.type))
    return out


@pytest.mark.slow
@pytest.mark.req("H-01")
@pytest.mark.parametrize("writer", ["publish_from", "field_by_field", "no_protocol"])
def test_a_concurrent_reader_never_sees_a_half_written_cycle(layout, image, writer):
    """The writer publishes cycles in which every field equals the cycle number as fast as it can;
    a reader in another process checks that every snapshot is one uniform cycle.

    ``field_by_field`` writes each field into the shared buffer separately inside the seqlock
    (about 100x longer than the one memcpy of ``publish_from``). ``no_protocol`` is the control
    that shows the check has teeth: the same writes straight into the buffer readers use, without
    the sequence counter, must be caught as torn snapshots."""
    machine = _machine(layout)
    setters = _uniform_setter(layout, machine)
    half = layout.half(C2P)
    buf = image._shm.buf
    parent, child = SPAWN.Pipe()
    reader = SPAWN.Process(target=children.torn_reader, args=(image.name, child, 5_000, 15.0))
    reader.start()
    try:
        assert parent.poll(60)
        assert parent.recv() == "ready"
        cycle = 0
        deadline = time.monotonic() + 30.0
        while not parent.poll() and time.monotonic() < deadline:
            cycle += 1
            if writer == "publish_from":
                for obj, leaf, sig_type in setters:
                    setattr(obj, leaf, children.uniform_value(sig_type, cycle))
                image.publish_from(machine, cycle)
                continue
            if writer == "field_by_field":
                b, data_offset = image._begin_publish()
            else:
                data_offset = image.plan.c2p_data_offset(0)  # what a reader takes, seq left even
            fmt.write_u64(buf, data_offset - 8, cycle)
            for s in half:
                fmt.write_field(buf, data_offset, s, children.uniform_value(s.type, cycle))
            if writer == "field_by_field":
                image._end_publish(b, cycle)
        assert parent.poll(30), "the reader did not finish"
        result = parent.recv()
    finally:
        reader.join(30)
    assert reader.exitcode == 0
    if writer == "no_protocol":
        assert result["torn"] > 0, result
        return
    assert result["torn"] == 0, result["first_torn"]
    # the reader really raced the writer: many snapshots of many different cycles
    assert result["snapshots"] >= 1000, result
    assert result["cycles"] >= 100, result
    assert cycle > result["cycles"]


@pytest.mark.req("H-01")
def test_a_reader_falls_back_to_the_previous_cycle_while_a_buffer_is_rewritten(layout, image):
    """Deterministic version of the race: the newest buffer is being rewritten when the reader
    arrives (the reader lagged a whole cycle); it takes the other, complete one."""
    machine = _machine(layout)
    for cycle in (1, 2):
        machine.channels[0].bahn_state.cycle_r = cycle
        image.publish_from(machine, cycle)
    buf = image._shm.buf
    b, data_offset = image._begin_publish()  # publish 3 into buffer 1 (holds cycle 1): seq odd
    buf[data_offset : data_offset + 16] = b"\xff" * 16  # half-written garbage
    fmt.write_u64(buf, fmt.OFF_PUBLISH_COUNT, 3)  # as if the reader had seen count 3 already
    with ImageClient.attach(image.name) as client:
        snap = client.snapshot()
        assert snap.cycle == 2
        assert snap["gpCh[0]^bahn_state.cycle_r"] == 2
        assert client.read("gpCh[0]^bahn_state.cycle_r") == 2
        # a writer stuck mid-publish in both buffers: the reader gives up with a clear error
        other = image.plan.c2p_offsets[b ^ 1]
        fmt.write_u64(buf, other, fmt.read_u64(buf, other) + 1)
        with pytest.raises(fmt.ImageBusyError, match="no consistent CNC->PLC snapshot"):
            client.snapshot()


# --- H-02: _r fields are the CNC's ---------------------------------------------------------------------


@pytest.mark.req("H-02")
def test_writes_to_cnc_fields_are_refused_on_every_door(layout, image):
    machine = _machine(layout)
    image.publish_from(machine, 1)
    before = image.snapshot()
    with ImageClient.attach(image.name) as client:
        for s in layout.half(C2P):
            with pytest.raises(ReadOnlySignalError, match=r"CNC->PLC: only the CNC writes it \(H-02\)"):
                client.write(s.st_path, 1 if s.type.value != "LREAL" else 1.0)
            with pytest.raises(ReadOnlySignalError):
                image.write(s.st_path, 1)
        # a batch with one _r field writes nothing
        with pytest.raises(ReadOnlySignalError):
            client.write_many(
                {
                    "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w": 123,
                    "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.state_r": 2,
                }
            )
        assert client.read("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w") == 0
        # bad values are refused too, with the field named
        with pytest.raises(SignalValueError, match=r"gpAx\[0\]\^ipo_mc_control.dyn_pos_limit_low.command_w"):
            client.write("gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w", 2**31)
        assert client.snapshot().data == before[1]


@pytest.mark.req("H-02")
def test_the_plc_writes_command_and_enable_and_the_engine_sees_them_at_the_latch(layout, image):
    machine = _machine(layout)
    unit = "gpAx[3]^ipo_mc_control.dyn_pos_limit_high"
    with ImageClient.attach(image.name, expect=layout) as client:
        client.write(f"{unit}.command_w", 1_234_567)
        client.write(f"{unit}.enable_w", True)
        assert machine.axes[3].ipo_mc_control.dyn_pos_limit_high.enable_w is False  # not before the latch
        image.latch_into(machine)
        dpl = machine.axes[3].ipo_mc_control.dyn_pos_limit_high
        assert (dpl.enable_w, dpl.command_w, dpl.effective()) == (True, 1_234_567, 1_234_567)
        dpl.state_r = 2
        image.publish_from(machine, 7)
        assert client.read(f"{unit}.state_r") == 2
        assert client.cycle == 7
        assert client.publish_count == 1


@pytest.mark.req("H-02")
def test_a_latch_assigns_the_half_only_when_it_changed_or_the_engine_is_another(layout, image):
    """Only the projection writes the engine's ``_w`` fields: a latch of the bytes latched last into the same
    engine assigns nothing (a quiet PLC costs one comparison, docs/performance.md); a changed byte assigns
    the whole half; another engine, or an image set up again (init_from), is assigned in full."""
    machine = _machine(layout)
    image.init_from(machine)
    unit = "gpAx[3]^ipo_mc_control.dyn_pos_limit_high"
    image.write(f"{unit}.command_w", 1_234_567)
    assert image.latch_into(machine) == image.latch_into(machine)
    dpl = machine.axes[3].ipo_mc_control.dyn_pos_limit_high
    assert dpl.command_w == 1_234_567
    dpl.command_w = 5  # behind the image's back: no door does this
    image.latch_into(machine)
    assert dpl.command_w == 5  # the same half again: not assigned
    image.write("gpCh[0]^mc_command.mode_w", 1)  # any change: the whole half
    image.latch_into(machine)
    assert (dpl.command_w, machine.channels[0].mc_command.mode_w) == (1_234_567, 1)
    other = _machine(layout)
    image.latch_into(other)
    assert other.axes[3].ipo_mc_control.dyn_pos_limit_high.command_w == 1_234_567
    dpl.command_w = 5
    image.latch_into(machine)  # latched into `other` last: assigned in full
    assert dpl.command_w == 1_234_567
    dpl.command_w = 9
    image.init_from(machine)  # the image takes the engine's values (9), and the next latch assigns them
    image.latch_into(machine)
    assert image.read(f"{unit}.command_w") == dpl.command_w == 9


@pytest.mark.req("H-01")
def test_raw_writes_into_the_plc_half_check_every_value_first(layout, image):
    s = layout.signal("gpCh[0]^bahn_mc_control.override.enable_w")
    t = layout.signal("gpCh[0]^bahn_mc_control.override.command_w")
    data = bytearray(t.offset + 4 - s.offset)
    data[0] = 1
    data[t.offset - s.offset :] = (500).to_bytes(4, "little", signed=True)
    image.write_bytes(s.offset, bytes(data))
    assert (image.read(s.st_path), image.read(t.st_path)) == (True, 500)
    data[0] = 7
    data[t.offset - s.offset :] = (600).to_bytes(4, "little", signed=True)
    with pytest.raises(SignalValueError, match="BOOL byte must be 0 or 1"):
        image.write_bytes(s.offset, bytes(data))
    assert image.read(t.st_path) == 500  # nothing written


# --- checks on attach -------------------------------------------------------------------------------------


@pytest.mark.req("H-01")
def test_attach_checks_magic_version_and_hash_with_clear_errors(layout, image):
    other = build_layout(demo_config(extra_axes=1))
    with pytest.raises(fmt.ImageMismatchError, match="another machine configuration"):
        ImageClient.attach(image.name, expect=other)
    with ImageClient.attach(image.name, expect=layout.hash) as client:
        assert client.layout.hash == layout.hash
    buf = image._shm.buf
    saved = bytes(buf[: fmt.HEADER_SIZE])
    try:
        buf[12:16] = (99).to_bytes(4, "little")  # layout version
        with pytest.raises(fmt.ImageMismatchError, match="layout version 99"):
            ImageClient.attach(image.name)
        buf[: fmt.HEADER_SIZE] = saved
        buf[16] ^= 0xFF  # header hash no longer that of the stored layout
        with pytest.raises(fmt.ImageMismatchError, match="does not match the stored layout"):
            ImageClient.attach(image.name)
        buf[: fmt.HEADER_SIZE] = saved
        buf[0:8] = b"NOTIMAGE"
        with pytest.raises(fmt.ImageMismatchError, match="not an HLI process image"):
            ImageClient.attach(image.name)
        buf[0:8] = bytes(8)
        with pytest.raises(fmt.ImageNotReadyError, match="still starting"):
            ImageClient.attach(image.name)
    finally:
        buf[: fmt.HEADER_SIZE] = saved
    with ImageClient.attach(image.name) as client:
        assert client.header.layout_hash == layout.hash


@pytest.mark.req("H-01")
def test_header_struct_and_construct_agree(layout, image):
    raw = bytes(image._shm.buf[: fmt.HEADER_SIZE])
    parsed = fmt.header_construct().parse(raw)
    header = fmt.read_header(raw, image.name, segment_size=image.plan.total_size)
    assert parsed.magic == fmt.MAGIC
    assert parsed.layout_hash.hex() == header.layout_hash == layout.hash
    assert (parsed.p2c_offset, parsed.c2p_offset_1, parsed.server_pid) == (
        image.plan.p2c_offset,
        image.plan.c2p_offsets[1],
        os.getpid(),
    )
    assert fmt.header_construct().build(parsed) == raw


# --- life cycle ---------------------------------------------------------------------------------------------


@pytest.mark.req("H-01")
def test_close_unlinks_the_segment_and_tells_attached_clients(layout):
    image = ProcessImage.create(layout)
    name = image.name
    assert _dev_shm(name).exists()
    client = ImageClient.attach(name)
    assert not client.server_closed
    image.close()
    image.close()  # idempotent
    assert not _dev_shm(name).exists()
    assert client.server_closed  # the mapping stays valid until the client closes
    client.close()
    with pytest.raises(FileNotFoundError, match="is the server running"):
        ImageClient.attach(name)
    with pytest.raises(FileNotFoundError):
        shared_memory.SharedMemory(name=name)


@pytest.mark.req("H-01")
def test_an_attaching_process_neither_unlinks_the_image_nor_warns(layout, image):
    """An independent interpreter (its own resource tracker) attaches, reads, exits."""
    code = textwrap.dedent(
        f"""
        from plc_clients.shm import ImageClient
        with ImageClient.attach({image.name!r}) as c:
            print(c.snapshot().cycle, c.read("gpCh[0]^mc_command.mode_w"))
        """
    )
    image.write("gpCh[0]^mc_command.mode_w", 1)
    image.publish_from(_machine(layout), 5)
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["5", "1"]
    assert "resource_tracker" not in done.stderr, done.stderr
    assert "leaked" not in done.stderr, done.stderr
    assert _dev_shm(image.name).exists()
    with ImageClient.attach(image.name) as client:
        assert client.read("gpCh[0]^mc_command.mode_w") == 1


@pytest.mark.req("H-01")
def test_a_refused_second_server_leaves_the_running_servers_image_alone(layout, image):
    """Another process asks to replace the running server's image, is refused, and exits: the
    segment must survive it (its resource tracker must not unlink what it only looked at)."""
    code = textwrap.dedent(
        f"""
        import sys
        from hli_server.image import ProcessImage
        from schemas.layout import build_layout
        from tests.machines import demo_config
        try:
            ProcessImage.create(build_layout(demo_config()), {image.name!r}, replace_stale=True)
        except FileExistsError as exc:
            print(exc)
            sys.exit(3)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 3, done.stderr
    assert "running server pid" in done.stdout
    assert "leaked" not in done.stderr, done.stderr
    assert _dev_shm(image.name).exists()
    with ImageClient.attach(image.name, expect=layout) as client:
        assert client.layout.hash == layout.hash


@pytest.mark.req("H-01")
def test_an_existing_segment_is_not_taken_over_unless_it_is_stale(layout, image):
    """The running server's image is never replaced; stale images and segments that are no image
    at all: tests/integration/test_shm_stale.py (issue 12 finding 7)."""
    with pytest.raises(FileExistsError, match="exists already"):
        ProcessImage.create(layout, image.name)
    with pytest.raises(FileExistsError, match="running server pid"):
        ProcessImage.create(layout, image.name, replace_stale=True)


def test_image_names_are_checked(layout):
    with pytest.raises(ValueError, match="image name 'a/b'"):
        ProcessImage.create(layout, "a/b")


# --- the engine side ---------------------------------------------------------------------------------------


@pytest.mark.req("H-01")
def test_a_bad_engine_value_is_named_and_the_image_keeps_the_last_cycle(layout, image):
    machine = _machine(layout)
    image.publish_from(machine, 1)
    machine.axes[2].ipo_state.cmd_pos_r = 2**40
    with pytest.raises(
        SignalValueError, match=r"gpAx\[2\]\^ipo_state.cmd_pos_r: 1099511627776 is out of range"
    ):
        image.publish_from(machine, 2)
    assert image.snapshot()[0] == 1
    short = MachineHli(channels=[ChannelHli()], axes=[AxisHli()])
    with pytest.raises(ValueError, match="build both from the same configuration"):
        image.publish_from(short, 3)
    with pytest.raises(ValueError, match="build both from the same configuration"):
        image.latch_into(short)


@pytest.mark.req("H-01")
def test_init_from_takes_the_engines_plc_values_and_publishes(layout, image):
    machine = _machine(layout)
    machine.channels[1].mc_command.mode_w = 1
    machine.channels[1].bahn_mc_control.override.state_r = 1000
    image.init_from(machine)
    assert image.read("gpCh[1]^mc_command.mode_w") == 1
    assert image.read("gpCh[1]^bahn_mc_control.override.state_r") == 1000
    assert image.publish_count == 1


@pytest.mark.req("H-01", "E-01")
def test_latch_and_publish_fit_easily_in_a_1_ms_cycle(layout, image, capsys):
    """The demo-sized machine (2 channels, 6 axes): median of latch+publish well below T_A."""
    machine = _machine(layout)
    samples = []
    for cycle in range(3000):
        t0 = time.perf_counter_ns()
        image.latch_into(machine)
        image.publish_from(machine, cycle)
        samples.append(time.perf_counter_ns() - t0)
    samples.sort()
    median_us = samples[len(samples) // 2] / 1000
    with capsys.disabled():
        print(
            f"\nlatch+publish, {len(layout)} signals: "
            f"median {median_us:.1f} µs, p99 {samples[-30] / 1000:.1f} µs"
        )
    assert median_us < 500, "latch+publish take half of a 1 ms cycle"


def test_the_doors_attached_image_reads_the_publish_counter_and_the_cycle_as_the_format_does(layout, image):
    """The doors process reads the two counters through a 64-bit view of the header (one load each):
    the same values as the format's reader, publish after publish, and the view does not keep the mapping
    from closing."""
    from hli_server.runtime.doors import AttachedImage

    attached = AttachedImage.attach(image.name, timeout=5.0)
    try:
        half = bytes(layout.size(C2P))
        seen = []
        counters = [attached.publish_counter(), image.publish_counter()]  # what the doors ask per request
        for cycle in (1, 2, 7, 2**40 + 3):
            image.publish_bytes(half, cycle)
            seen.append((attached.cycle, attached.publish_count))
            assert attached.cycle == fmt.read_u64(attached._buf, fmt.OFF_CYCLE) == cycle
            assert attached.publish_count == fmt.read_u64(attached._buf, fmt.OFF_PUBLISH_COUNT)
            assert attached.publish_count == image.publish_count
            assert [counter() for counter in counters] == [image.publish_count] * 2
        assert [c for c, _ in seen] == [1, 2, 7, 2**40 + 3]
        assert len({p for _, p in seen}) == 4  # each publish counted
    finally:
        attached.close()  # raised BufferError while a view of the mapping was held
    assert attached.closed  # detached: said without reading the mapping that is gone
