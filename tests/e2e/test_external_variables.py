"""V.E. variables through every PLC door (N-05): shared memory, Modbus, ADS.

The server runs in-process (the plugin's ``hli``, stepped clock) on a machine that declares one V.E.
variable of every kernel type (``tests.machines.EXTERNAL_VARIABLES``). The NC's side is the engine's
store, written between cycles as an NC program's assignment writes it; the PLC's side is each
transport of ``plc_clients``. A value goes both ways and the last writer wins.
"""

from __future__ import annotations

import pytest

from hli_server.testing import Harness
from plc_clients import Transport, TransportError
from schemas.config import ExternalVariableConfig, MachineConfig
from tests.machines import demo_config

pytestmark = [pytest.mark.req("N-05"), pytest.mark.timeout(60)]


@pytest.fixture
def hli_machine() -> MachineConfig:
    return demo_config(external=True)


def test_plc_and_nc_share_the_variables_through_every_door(hli: Harness, plc_transport: Transport) -> None:
    store = hli.runtime.machine.external
    plc_transport.write("gpVECh[0]^PART_COUNT", 41)
    plc_transport.write("gpVEGlob^PLC_READY", True)
    plc_transport.write("gpVECh[1]^POS[1,2]", -2.25)
    hli.step(1)
    assert store.read("PART_COUNT", 1) == 41
    assert store.read("PLC_READY", 1) is True  # the global area, seen from channel 1
    assert store.read("POS", 2, (1, 2)) == -2.25
    store.write("PART_COUNT", 1, 42)  # the NC counts the part
    store.write("FLAGS", 2, True, (2,))
    hli.step(1)
    assert plc_transport.read("gpVECh[0]^PART_COUNT") == 42
    assert plc_transport.read("gpVECh[1]^FLAGS[2]") is True
    assert plc_transport.read("gpVECh[1]^FLAGS[1]") is False
    plc_transport.write("gpVECh[0]^PART_COUNT", 0)  # the PLC takes the count back: last writer wins
    hli.step(1)
    assert store.read("PART_COUNT", 1) == 0


def test_every_kernel_type_through_every_door(hli: Harness, plc_transport: Transport) -> None:
    cases = {
        "gpVEGlob^S8": -128,
        "gpVEGlob^U8[2]": 255,
        "gpVECh[0]^S16": -32768,
        "gpVECh[0]^U16": 65535,
        "gpVECh[0]^U32": 2**32 - 1,
        "gpVECh[1]^R32[1]": -1.5,
    }
    plc_transport.write_many(cases.items())
    hli.step(1)
    store = hli.runtime.machine.external
    assert store.read("S8", None) == -128
    assert store.read("U8", None, (2,)) == 255
    assert store.read("S16", 1) == -32768
    assert store.read("U16", 1) == 65535
    assert store.read("U32", 1) == 2**32 - 1
    assert store.read("R32", 2, (1,)) == -1.5
    store.write("S8", None, 127)
    store.write("S16", 1, -2)
    hli.step(1)
    assert plc_transport.read("gpVEGlob^S8") == 127
    assert plc_transport.read("gpVECh[0]^S16") == -2


def test_every_door_refuses_a_value_the_kernel_type_cannot_hold(
    hli: Harness, plc_transport: Transport
) -> None:
    with pytest.raises((TransportError, ValueError), match=r"out of range|exception|refused"):
        plc_transport.write("gpVEGlob^S8", 200)
    hli.step(1)
    assert hli.runtime.machine.external.read("S8", None) == 0
    assert plc_transport.read("gpVEGlob^S8") == 0


def test_a_channel_variable_shadows_a_global_one_of_the_same_name() -> None:
    base = demo_config()
    config = base.model_copy(
        update={
            "external_variables": [
                ExternalVariableConfig(name="MODE", type="SGN32"),
                ExternalVariableConfig(name="MODE", type="SGN32", channel=2),
            ]
        }
    )
    with Harness(config) as hli:
        hli.image["gpVEGlob^MODE"] = 1
        hli.image["gpVECh[1]^MODE"] = 2
        hli.step(1)
        store = hli.runtime.machine.external
        assert (store.read("MODE", 1), store.read("MODE", 2), store.read("MODE", None)) == (1, 2, 1)


def test_strings_and_structures_through_every_door(hli: Harness, plc_transport: Transport) -> None:
    """RegenHU's HMI message (a structure with a STRING), ISG's teach file name (a STRING), an array of
    VSTRINGs and an array of structures: both ways, through shared memory, Modbus and ADS."""
    store = hli.runtime.machine.external
    plc_transport.write("gpVEGlob^TEACH_FILE_NAME", "teach_0815.dat")
    plc_transport.write_many(
        [("gpVECh[1]^NOTES[1]", "Zürich"), ("gpVECh[1]^TRACK[1].LABEL", "P2"), ("gpVECh[1]^TRACK[1].X", 2.5)]
    )
    plc_transport.write("gpVECh[0]^UserInteraction.Answer", 1)
    hli.step(1)
    assert store.read("TEACH_FILE_NAME", 1) == "teach_0815.dat"
    assert store.read("NOTES", 2, (1,)) == "Zürich"
    assert (store.read("TRACK.LABEL", 2, (1,)), store.read("TRACK.X", 2, (1,))) == ("P2", 2.5)
    assert store.read("UserInteraction.Answer", 1) == 1
    store.write("UserInteraction.Message", 1, "Camera at A1 - OK?")  # 18 of the 20 characters
    store.write("TEACH_FILE_NAME", None, "")
    hli.step(1)
    assert plc_transport.read("gpVECh[0]^UserInteraction.Message") == "Camera at A1 - OK?"
    assert plc_transport.read("gpVEGlob^TEACH_FILE_NAME") == ""
    assert plc_transport.read("gpVECh[1]^NOTES[0]") == ""


def test_every_door_refuses_a_string_longer_than_its_variable(hli: Harness, plc_transport: Transport) -> None:
    plc_transport.write("gpVECh[1]^NOTES[0]", "12345678")  # a VSTRING of 9 bytes: 8 characters
    with pytest.raises((TransportError, ValueError), match=r"at most 8|exception|refused"):
        plc_transport.write("gpVECh[1]^NOTES[0]", "123456789")
    hli.step(1)
    assert hli.runtime.machine.external.read("NOTES", 2, (0,)) == "12345678"
    assert plc_transport.read("gpVECh[1]^NOTES[0]") == "12345678"
