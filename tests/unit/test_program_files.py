"""Program files as written on Windows (issue 33, item 7; N-12): UTF-8 with or without a byte order mark,
Windows-1252 and Latin-1 read alike (``hli_server/codecs/nc_text.py``), and names matched without regard
to case, as on the kernel's host - by ``check`` (full and geometry), the program directories, the program
table and the test harness."""

from __future__ import annotations

import codecs
import json
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from hli_server.cli import main
from hli_server.codecs.nc_text import EncodingSniffer, decode_program, program_encoding
from hli_server.runtime.programs import ProgramDirectories, open_program, read_program_file

pytestmark = pytest.mark.req("N-12")

TEXT = "%umlaut\n; Prüfung der Maße: Fräsen – 5 €\nN10 G01 X10 F1000\nN20 M30\n"
"""A comment with what a German shop writes: ü, ß, ä, the en dash and the euro sign (Windows-1252's own
characters at 0x96 and 0x80)."""
LATIN1 = "%umlaut\n; Prüfung der Maße: Fräsen ± 5 °\nN10 G01 X10 F1000\nN20 M30\n"
"""Only characters ISO 8859-1 and Windows-1252 agree on."""


@pytest.mark.parametrize(
    ("data", "encoding", "text"),
    [
        (b"", "utf-8", ""),
        (b"N10 G01 X1\n", "utf-8", "N10 G01 X1\n"),
        (TEXT.encode("utf-8"), "utf-8", TEXT),
        (codecs.BOM_UTF8 + TEXT.encode("utf-8"), "utf-8-sig", TEXT),
        (TEXT.encode("cp1252"), "cp1252", TEXT),
        (LATIN1.encode("latin-1"), "cp1252", LATIN1),
        (TEXT.encode("utf-16"), "utf-16", TEXT),
        (b"; \x81\x8d\x8f\x90\x9d \xfc\n", "latin-1", "; \x81\x8d\x8f\x90\x9d ü\n"),
        (codecs.BOM_UTF8 + TEXT.encode("cp1252"), "cp1252", TEXT),
        (b"; cut \xc3", "cp1252", "; cut Ã"),
    ],
    ids=["empty", "ascii", "utf-8", "bom", "cp1252", "latin-1", "utf-16", "undefined", "bom+1252", "cut"],
)
def test_every_encoding_a_windows_shop_writes_reads_alike(data: bytes, encoding: str, text: str) -> None:
    assert program_encoding(data) == encoding
    assert decode_program(data) == text


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200), st.lists(st.integers(min_value=0, max_value=200), max_size=8))
def test_the_sniffer_fed_in_pieces_names_what_the_whole_names(data: bytes, cuts: list[int]) -> None:
    sniffer = EncodingSniffer()
    at = 0
    for cut in sorted(c for c in cuts if c <= len(data)):
        sniffer.feed(data[at:cut])
        at = cut
    sniffer.feed(data[at:])
    assert sniffer.encoding() == program_encoding(data)
    if sniffer.encoding() != "utf-16":  # a random UTF-16 body may be cut in half: that is an error
        assert decode_program(data) == data[sniffer.skip :].decode(sniffer.encoding())


@pytest.mark.parametrize("encoding", ["utf-8", "utf-8-sig", "cp1252", "utf-16"])
@pytest.mark.parametrize("mode", [[], ["--geometry-only"]])
def test_check_runs_a_program_in_each_encoding(tmp_path: Path, encoding: str, mode: list[str]) -> None:
    program = tmp_path / "umlaut.nc"
    program.write_bytes(TEXT.encode(encoding))
    done = CliRunner().invoke(main, ["check", "--format", "json", *mode, str(program)])
    assert done.exit_code == 0, done.output
    report = json.loads(done.stdout)
    assert report["completed"] is True
    assert report["final_position"]["X"] == 10.0


@pytest.mark.parametrize("mode", [[], ["--geometry-only"]])
def test_a_message_keeps_its_umlauts(tmp_path: Path, mode: list[str]) -> None:
    program = tmp_path / "msg.nc"
    program.write_bytes('N10 #MSG ["Prüfung läuft"]\nN20 M30\n'.encode("cp1252"))
    done = CliRunner().invoke(main, ["check", "--format", "json", *mode, str(program)])
    assert done.exit_code == 0, done.output
    assert [m["text"] for m in json.loads(done.stdout)["messages"]] == ["Prüfung läuft"]


def test_a_streamed_file_with_a_mark_before_windows_1252_loses_only_the_mark(tmp_path: Path) -> None:
    path = tmp_path / "x.nc"
    path.write_bytes(codecs.BOM_UTF8 + TEXT.encode("cp1252"))
    with open_program(path) as stream:
        assert stream.read() == TEXT
    assert read_program_file(path) == TEXT


@pytest.mark.parametrize("mode", [[], ["--geometry-only"]])
def test_names_match_without_regard_to_case(tmp_path: Path, mode: list[str]) -> None:
    subs = tmp_path / "subs"
    subs.mkdir()
    (subs / "UP1.nc").write_bytes("%UP1\n(Kühlung an)\nN10 G01 X20 F1000\nN20 M17\n".encode("cp1252"))
    (tmp_path / "Main.NC").write_text("N10 L up1.NC\nN20 M30\n", encoding="utf-8")
    # the program as the user types it, the subprogram as the program writes it
    done = CliRunner().invoke(
        main, ["check", "--format", "json", *mode, "--program-dir", str(subs), str(tmp_path / "main.nc")]
    )
    assert done.exit_code == 0, done.output
    assert json.loads(done.stdout)["final_position"]["X"] == 20.0


def test_a_name_without_its_extension_is_not_found_and_the_alarm_says_what_to_write(tmp_path: Path) -> None:
    """The kernel calls a global subroutine by its complete file name (manual "Global subroutines",
    206834699): ``L up1`` is not ``UP1.nc`` there either; the alarm names the file and the call to write."""
    (tmp_path / "UP1.nc").write_text("N10 G01 X20 F1000\nN20 M17\n", encoding="utf-8")
    (tmp_path / "main.nc").write_text("N10 L up1\nN20 M30\n", encoding="utf-8")
    done = CliRunner().invoke(main, ["check", "--format", "json", str(tmp_path / "main.nc")])
    assert done.exit_code == 1
    (alarm,) = json.loads(done.stdout)["alarms"]
    assert alarm["id"] == 914010
    assert "UP1.nc is there" in alarm["message"]
    assert "complete file name" in alarm["message"]
    assert "(L up1.nc)" in alarm["message"]


def test_each_program_directory_is_searched_and_named_once(tmp_path: Path) -> None:
    library = ProgramDirectories([tmp_path, tmp_path / ".", tmp_path])
    assert library.searched() == (str(tmp_path.resolve()),)


def test_a_program_table_entry_is_found_without_regard_to_case(tmp_path: Path) -> None:
    (tmp_path / "PART.NC").write_bytes(TEXT.encode("cp1252"))
    assert read_program_file(tmp_path / "part.nc") == TEXT
    with pytest.raises(FileNotFoundError):
        read_program_file(tmp_path / "other.nc")


def test_a_machine_files_program_path_matches_without_regard_to_case(tmp_path: Path) -> None:
    from hli_server.configuration import load_machine

    (tmp_path / "Programs").mkdir()
    (tmp_path / "Programs" / "PART.NC").write_bytes(TEXT.encode("cp1252"))
    # a machine of the tests' own, with a program table entry that names its file in other case
    machine = (Path(__file__).parents[1] / "data" / "implicit_calls" / "machine.toml").read_text(
        encoding="utf-8"
    )
    machine += '\n[[channels.programs]]\nnumber = 1\nname = "part"\npath = "programs/part.nc"\n'
    (tmp_path / "machine.toml").write_text(machine, encoding="utf-8")
    try:
        config = load_machine(tmp_path / "machine.toml")
    except Exception as exc:  # the test machine itself must load: say why it did not
        pytest.fail(f"machine file: {exc}")
    (entry,) = config.channels[0].programs
    assert entry.path is not None
    assert read_program_file(entry.path) == TEXT
