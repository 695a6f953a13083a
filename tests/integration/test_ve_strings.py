"""V.E. STRING variables and structures through each door with the clients PLC programmers use (N-05).

The e2e test (tests/e2e/test_external_variables.py) carries values both ways through ``plc_clients``; here
each door is met by its own ordinary client, which checks nothing before it sends: pyads as a TwinCAT
programmer calls it (``read_by_name`` of a STRING and of a structure's member, ``read_structure_by_name``,
``write_by_name``, ``get_symbol``), pymodbus with raw registers (both word orders) and the HTTP image API.
The machine is the test machine with its V.E. variables (``tests.machines``): ``gpVEGlob^TEACH_FILE_NAME``
a STRING(20), ``gpVECh[0]^UserInteraction`` a structure ``UserInteractionType`` (Message STRING(20),
Answer DINT, Done BOOL), ``gpVECh[1]^NOTES`` two VSTRINGs of 9 bytes.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import Any

import httpx
import pyads
import pytest
from pymodbus.client import ModbusTcpClient

from hli_server.testing import Harness
from plc_clients.ads import close_pyads, open_pyads
from schemas.config import (
    ExternalElementConfig,
    ExternalStructureConfig,
    ExternalVariableConfig,
    MachineConfig,
)
from tests.machines import demo_config

pytestmark = [pytest.mark.req("N-05"), pytest.mark.timeout(60)]

TEACH = "gpVEGlob^TEACH_FILE_NAME"
MESSAGE = "gpVECh[0]^UserInteraction.Message"
USER_INTERACTION = "gpVECh[0]^UserInteraction"


@pytest.fixture
def hli_machine() -> MachineConfig:
    return demo_config(external=True)


@pytest.fixture
def plc(hli: Harness) -> Iterator[Any]:
    conn = open_pyads("127.0.0.1.1.1", 851, f"127.0.0.1:{hli.port('ads')}")
    try:
        yield conn
    finally:
        close_pyads(conn)


@pytest.mark.req("H-04")
def test_pyads_reads_and_writes_a_string_and_a_structures_member_by_name(hli: Harness, plc: Any) -> None:
    store = hli.runtime.machine.external
    store.write("TEACH_FILE_NAME", None, "teach_0815.dat")
    store.write("UserInteraction.Message", 1, "Camera at A1 - OK?")
    store.write("UserInteraction.Answer", 1, -3)
    hli.step(1)
    assert plc.read_by_name(TEACH, pyads.PLCTYPE_STRING) == "teach_0815.dat"
    assert plc.read_by_name(MESSAGE, pyads.PLCTYPE_STRING) == "Camera at A1 - OK?"
    assert plc.read_by_name("gpVECh[0].UserInteraction.Answer", pyads.PLCTYPE_DINT) == -3
    symbol = plc.get_symbol(MESSAGE)
    assert (symbol.symbol_type, symbol.index_group) == ("STRING(20)", 0xF030)
    assert symbol.read() == "Camera at A1 - OK?"
    structure = (
        ("Message", pyads.PLCTYPE_STRING, 1, 20),
        ("Answer", pyads.PLCTYPE_DINT, 1),
        ("Done", pyads.PLCTYPE_BOOL, 1),
    )
    assert plc.read_structure_by_name(USER_INTERACTION, structure) == {
        "Message": "Camera at A1 - OK?",
        "Answer": -3,
        "Done": False,
    }
    assert plc.get_symbol(USER_INTERACTION).symbol_type == "UserInteractionType"
    plc.write_by_name(TEACH, "robot.tch", pyads.PLCTYPE_STRING)  # pyads sends the text and one NUL
    plc.write_by_name("gpVECh[0]^UserInteraction.Done", True, pyads.PLCTYPE_BOOL)
    hli.step(1)
    assert store.read("TEACH_FILE_NAME", None) == "robot.tch"
    assert store.read("UserInteraction.Done", 1) is True
    assert plc.read_by_name(TEACH, pyads.PLCTYPE_STRING) == "robot.tch"  # the rest of the field is NUL


@pytest.mark.req("H-04")
def test_the_ads_door_refuses_a_string_without_its_nul(hli: Harness, plc: Any) -> None:
    field = hli.layout.signal(TEACH)
    with pytest.raises(pyads.ADSError) as info:  # 21 characters into a STRING(20): no room for the NUL
        plc.write(0xF030, field.offset, b"x" * 21, pyads.PLCTYPE_BYTE * 21)
    assert info.value.err_code == 0x706
    with pytest.raises(pyads.ADSError) as info:
        plc.write_by_name(TEACH, "x" * 21, pyads.PLCTYPE_STRING)  # by handle: 22 bytes for 21
    assert info.value.err_code == 0x705
    plc.write(0xF030, field.offset, b"ok".ljust(21, b"\0"), pyads.PLCTYPE_BYTE * 21)
    hli.step(1)
    assert hli.runtime.machine.external.read("TEACH_FILE_NAME", None) == "ok"


@pytest.mark.req("H-03")
@pytest.mark.parametrize("word_order", ["ABCD", "CDAB"])
def test_modbus_carries_a_string_two_characters_to_a_register(
    word_order: str, hli_machine: MachineConfig
) -> None:
    with Harness(hli_machine, adapters=[("modbus", {"word_order": word_order})]) as hli:
        field = hli.layout.signal(TEACH)
        assert field.modbus_count == 11
        client = ModbusTcpClient("127.0.0.1", port=hli.port("modbus"), timeout=2, retries=0)
        assert client.connect()
        try:
            hli.runtime.machine.external.write("TEACH_FILE_NAME", None, "ABC")
            hli.step(1)
            read = client.read_holding_registers(field.modbus_address, count=11)
            assert read.registers == [0x4142, 0x4300] + [0] * 9  # whatever the word order
            words = list(struct.unpack(">11H", b"teach.dat".ljust(22, b"\0")))
            assert not client.write_registers(field.modbus_address, words).isError()
            hli.step(1)
            assert hli.runtime.machine.external.read("TEACH_FILE_NAME", None) == "teach.dat"
            # 21 characters leave no NUL in the field's 21 bytes: exception 0x03, nothing written
            full = list(struct.unpack(">11H", b"y" * 22))
            refused = client.write_registers(field.modbus_address, full)
            assert refused.isError()
            assert refused.exception_code == 0x03
            # a string is read and written whole: a range that cuts it is 0x02
            cut = client.write_register(field.modbus_address + 3, 0x4142)
            assert cut.isError()
            assert cut.exception_code == 0x02
            # its neighbour of the structure, a DINT, keeps the word order
            answer = hli.layout.signal("gpVECh[0]^UserInteraction.Answer")
            hli.runtime.machine.external.write("UserInteraction.Answer", 1, 100_000)
            hli.step(1)
            regs = client.read_holding_registers(answer.modbus_address, count=2).registers
            assert regs == ([0x0001, 0x86A0] if word_order == "ABCD" else [0x86A0, 0x0001])
            hli.step(1)
            assert hli.runtime.machine.external.read("TEACH_FILE_NAME", None) == "teach.dat"
        finally:
            client.close()


@pytest.mark.req("H-05")
def test_the_http_image_api_reads_and_writes_strings_and_members(hli: Harness) -> None:
    with httpx.Client(base_url=hli.http_url, timeout=10) as client:
        r = client.put("/api/image/gpVECh[0].UserInteraction.Message", json={"value": "Load part"})
        assert r.status_code == 200, r.text
        assert r.json()["st_path"] == MESSAGE
        r = client.put("/api/image/gpVEGlob.TEACH_FILE_NAME", json={"value": "x" * 21})
        assert r.status_code == 422
        assert "holds at most 20" in r.json()["detail"]
        r = client.put("/api/image/gpVEGlob.TEACH_FILE_NAME", json={"value": 5})
        assert r.status_code == 422
        hli.step(1)
        assert hli.runtime.machine.external.read("UserInteraction.Message", 1) == "Load part"
        r = client.get("/api/image/gpVECh[0].UserInteraction.Message")
        assert r.status_code == 200, r.text
        assert r.json()["value"] == "Load part"
        external = {v["name"]: v for v in client.get("/api/state").json()["external"]}
        assert external["V.E.UserInteraction.Message"] == {
            "name": "V.E.UserInteraction.Message",
            "channel": 1,
            "symbol": MESSAGE,
            "type": "STRING",
            "dims": [],
            "value": "Load part",
        }
        assert external["V.E.TRACK.LABEL"]["symbol"] == "gpVECh[1]^TRACK[].LABEL"
        assert external["V.E.NOTES"]["type"] == "VSTRING"


@pytest.mark.req("H-07")
def test_a_trace_holds_a_strings_text_cycle_by_cycle(hli: Harness) -> None:
    with hli.trace(TEACH, "gpVECh[0]^UserInteraction.Answer") as recording:
        hli.image[TEACH] = "a.dat"
        hli.step(2)
        hli.runtime.machine.external.write("TEACH_FILE_NAME", None, "Zürich €.dat")
        hli.step(2)
    trace = recording.trace()
    assert trace[TEACH].tolist() == ["a.dat", "a.dat", "Zürich €.dat", "Zürich €.dat"]
    assert trace.at(trace.cycles[-1])[TEACH] == "Zürich €.dat"
    assert b'"Z\\u00fcrich \\u20ac.dat"' in b"".join(trace.json_chunks())


@pytest.mark.req("B-02")
def test_a_session_with_string_writes_records_and_replays(hli: Harness, tmp_path: Any) -> None:
    """The PLC's STRING writes are inputs like any: recorded as their text (format 3) and written back
    byte for byte by the replay, which then agrees cycle for cycle."""
    from hli_server.recording.format import read_records

    path = tmp_path / "strings.jsonl.gz"
    with hli.record(path, outputs_every=1):
        hli.image[TEACH] = "teach_0815.dat"
        hli.step(2)
        hli.image[MESSAGE] = "Zürich"
        hli.image["gpVECh[1]^NOTES[1]"] = ""
        hli.step(2)
    records = list(read_records(path))
    header = records[0]
    kinds = dict(map(tuple, header["inputs"]))
    assert kinds[TEACH] == "STRING(20)"
    index = [p for p, _ in header["inputs"]].index(TEACH)
    texts = [
        r["i"][k + 1] for r in records if "i" in r for k in range(0, len(r["i"]), 2) if r["i"][k] == index
    ]
    assert ["teach_0815.dat"] in texts
    report = hli.replay(path)
    assert report.verdict.name == "PASS"


HMI_PROGRAM = """\
N10 G90 G01 X10 F6000
N20 V.E.UserInteraction.Message = "Camera at A1 - trigger imaging, then click OK"
N30 G01 X20
N40 V.E.UserInteraction.Message = "Camera at B3 - trigger imaging, then click OK"
N50 G01 X30
N60 V.E.UserInteraction.Message = ""
N70 M30
"""


def test_an_hmi_message_a_program_writes_reaches_the_plc_when_the_path_gets_there() -> None:
    """RegenHU's programs tell the operator what to do through a structure with a STRING: declared
    synchronous, each message reaches the PLC (here through the image, as an HMI reads it) when the path
    has reached its block, not when the block is decoded ahead of the motion."""
    config = demo_config().model_copy(
        update={
            "external_structures": [
                ExternalStructureConfig(
                    name="UserInteractionType",
                    elements=[ExternalElementConfig(name="Message", type="VSTRING")],
                )
            ],
            "external_variables": [
                ExternalVariableConfig(name="UserInteraction", type="UserInteractionType", synchronous=True)
            ],
        }
    )
    message, x = "gpVEGlob^UserInteraction.Message", "gpAx[0]^ipo_state.cmd_pos_r"
    with Harness(config) as hli:
        for axis in range(len(config.axes)):
            hli.image[f"gpAx[{axis}]^manual.reference_w"] = True
        hli.run_until(lambda: all(hli.image[f"gpAx[{a}]^ipo_state.referenced_r"] for a in range(3)), 50_000)
        hli.load_program(1, HMI_PROGRAM)
        with hli.trace(message, x) as recording:
            hli.operator.start(1)
            hli.run_until(lambda: hli.image["gpCh[0]^bahn_state.program_state_r"] == 4, 20_000)
    trace = recording.trace()
    texts, positions = trace[message].tolist(), trace[x].tolist()
    seen = [t for k, t in enumerate(texts) if k == 0 or t != texts[k - 1]]
    assert seen == [
        "",
        "Camera at A1 - trigger imaging, then click OK",
        "Camera at B3 - trigger imaging, then click OK",
        "",
    ]
    first_a1 = texts.index(seen[1])
    first_b3 = texts.index(seen[2])
    assert positions[first_a1] == pytest.approx(100_000, abs=10)  # X at 10 mm (0.1 um) when A1 shows
    assert positions[first_b3] == pytest.approx(200_000, abs=10)
