"""The process image in a buffer (H-01, H-07): the same format and protocol as in shared memory.

``ProcessImage.in_memory`` keeps the segment in a ``bytearray`` of this process; ``ImageClient.over``
attaches to it with the checks ``attach`` makes by name. No ``/dev/shm``, no second process: the
byte layout is checked against the layout's construct description, as the shared-memory tests do.
``SignalRecorder`` samples chosen signals of each publish (per-cycle traces).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from hli_server.engine.hli import AxisHli, ChannelHli, MachineHli
from hli_server.image import ProcessImage, open_image_names, set_engine_value
from plc_clients import ImageClient, ShmTransport, TransportError
from schemas import image_format as fmt
from schemas.layout import Direction, Layout, ReadOnlySignalError, UnknownSignalError, build_layout
from tests.machines import demo_config, distinct_values

pytestmark = pytest.mark.req("H-01", "H-07")

P2C, C2P = Direction.PLC_TO_CNC, Direction.CNC_TO_PLC
X = "gpAx[0]^ipo_state.cmd_pos_r"
ENABLE = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.enable_w"
COMMAND = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low.command_w"


@pytest.fixture(scope="module")
def layout() -> Layout:
    return build_layout(demo_config())


def machine_of(layout: Layout) -> MachineHli:
    return MachineHli(channels=[ChannelHli() for _ in layout.channels], axes=[AxisHli() for _ in layout.axes])


def test_a_memory_image_is_the_same_segment_without_dev_shm(layout: Layout) -> None:
    with ProcessImage.in_memory(layout, name="hli_mem_test") as image:
        assert (image.name, image.backing) == ("hli_mem_test", "memory")
        assert "hli_mem_test" in open_image_names()  # tracked like a shared-memory image
        assert not Path("/dev/shm/hli_mem_test").exists()
        header = fmt.read_header(image.buffer, image.name)
        assert (header.magic, header.layout_hash, header.server_pid) == (fmt.MAGIC, layout.hash, os.getpid())
        machine = machine_of(layout)
        c2p = distinct_values(layout, C2P, salt=1)
        for s in layout.half(C2P):
            set_engine_value(machine, s, c2p[s.st_path])
        image.publish_from(machine, cycle=77)
        client = ImageClient.over(image.buffer, name=image.name, expect=layout)
        snap = client.snapshot()
        assert (snap.cycle, snap.as_dict()) == (77, c2p)
        assert client.raw(C2P) == layout.construct(C2P).build(c2p)
        client.write(COMMAND, -12_345)
        client.write(ENABLE, True)
        image.latch_into(machine)
        assert machine.axes[0].ipo_mc_control.dyn_pos_limit_low.command_w == -12_345
        with pytest.raises(ReadOnlySignalError):
            client.write(X, 1)
    assert "hli_mem_test" not in open_image_names()


def test_a_client_of_a_memory_image_sees_the_server_close_it(layout: Layout) -> None:
    image = ProcessImage.in_memory(layout)
    transport = ShmTransport.over(image.buffer, name=image.name)
    assert transport.snapshot().cycle == 0
    image.close()
    assert transport.client.server_closed
    with pytest.raises(TransportError, match="the server closed the image"):
        transport.snapshot()
    with pytest.raises(ValueError, match="released"):
        image.read(X)
    transport.close()


def test_a_client_refuses_a_buffer_of_another_layout(layout: Layout) -> None:
    other = build_layout(demo_config(extra_axes=1))
    with ProcessImage.in_memory(layout) as image:
        with pytest.raises(fmt.ImageMismatchError, match="layout hash"):
            ImageClient.over(image.buffer, expect=other)
        with pytest.raises(fmt.ImageNotReadyError):
            ImageClient.over(bytearray(len(image.buffer)))


def test_the_recorder_keeps_both_halves_of_every_publish(layout: Layout) -> None:
    with ProcessImage.in_memory(layout) as image:
        machine = machine_of(layout)
        recorder = image.recorder([ENABLE, X, "gpCh[1]^bahn_state.cycle_r", COMMAND])
        for cycle in range(1, 6):
            machine.axes[0].ipo_state.cmd_pos_r = cycle * 100
            machine.channels[1].bahn_state.cycle_r = cycle
            if cycle == 3:
                image.write(COMMAND, -7)
                image.write(ENABLE, True)
            image.publish_from(machine, cycle)
            recorder.sample()
        cycles, values = recorder.columns()  # numpy arrays, packed (issue 27, finding 9)
        assert cycles.tolist() == [1, 2, 3, 4, 5]
        assert list(values) == [ENABLE, X, "gpCh[1]^bahn_state.cycle_r", COMMAND]  # the order asked for
        assert values[X].tolist() == [100, 200, 300, 400, 500]
        assert values["gpCh[1]^bahn_state.cycle_r"].tolist() == [1, 2, 3, 4, 5]
        assert values[ENABLE].tolist() == [False, False, True, True, True]
        assert values[COMMAND].tolist() == [0, 0, -7, -7, -7]
        assert str(values[X].dtype) == "int32"
        assert str(values[ENABLE].dtype) == "bool"
        assert len(recorder) == 5
        with pytest.raises(UnknownSignalError):
            image.recorder(["gpAx[0]^no_such_field"])
        with pytest.raises(ValueError, match="each signal once"):
            image.recorder([X, X])
        empty_cycles, empty = image.recorder([X]).columns()
        assert len(empty_cycles) == 0
        assert list(empty) == [X]
        assert len(empty[X]) == 0
