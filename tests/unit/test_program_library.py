"""Where ``L name`` finds its programs on a running server: the program directories and the files
uploaded with a program (N-02; ``hli_server/runtime/programs.py``). Names that leave their directory
are never read."""

from __future__ import annotations

import os
import random
from pathlib import Path

import pytest

from hli_server.runtime.programs import (
    MAX_UPLOADED_FILES,
    ProgramDirectories,
    ProgramNameError,
    RuntimeLibrary,
    check_program_name,
)
from tests.fuzz import count, seed_for

pytestmark = pytest.mark.req("N-02")


@pytest.fixture
def dirs(tmp_path: Path) -> tuple[Path, Path]:
    first, second = tmp_path / "programs", tmp_path / "cycles"
    (first / "sub").mkdir(parents=True)
    second.mkdir()
    (first / "UP1.NC").write_text("%UP1\nN10 G01 X1 F100\nN20 M17\n", encoding="utf-8")
    (first / "sub" / "drill.nc").write_text("%drill\nM17\n", encoding="utf-8")
    (second / "UP1.NC").write_text("%UP1 second\nM17\n", encoding="utf-8")
    (second / "cycle_x").write_text("%cycle_x\nM17\n", encoding="utf-8")
    return first, second


def test_directories_are_searched_in_order_and_name_what_they_searched(dirs: tuple[Path, Path]) -> None:
    library = ProgramDirectories(dirs)
    found = library.find("UP1.NC")
    assert found is not None
    assert (found.name, found.origin) == ("UP1.NC", str(dirs[0] / "UP1.NC"))
    assert found.text.startswith("%UP1\n")
    cycle = library.find("cycle_x")
    assert cycle is not None
    assert cycle.origin == str(dirs[1] / "cycle_x")
    assert library.find("nothing.nc") is None
    assert library.searched() == (str(dirs[0].resolve()), str(dirs[1].resolve()))


def test_a_name_matches_without_regard_to_case_and_may_name_a_subdirectory(dirs: tuple[Path, Path]) -> None:
    library = ProgramDirectories(dirs)
    lower = library.find("up1.nc")
    assert lower is not None
    assert lower.origin == str(dirs[0] / "UP1.NC")
    for name in ("sub/drill.nc", "SUB/DRILL.NC", "sub\\drill.nc", "./sub/drill.nc"):
        found = library.find(name)
        assert found is not None, name
        assert found.text == "%drill\nM17\n"


@pytest.mark.parametrize(
    ("name", "why"),
    [
        ("../secret.nc", "leaves its directory"),
        ("sub/../../secret.nc", "leaves its directory"),
        ("..\\secret.nc", "leaves its directory"),
        ("/etc/passwd", "is absolute"),
        ("\\\\server\\share\\x.nc", "is absolute"),
        ("C:\\cnc\\x.nc", "is absolute"),
        ("C:x.nc", "is absolute"),
        ("", "1 to 255 characters"),
        ("x" * 256, "1 to 255 characters"),
        ("a\x00b", "control character"),
        (".", "names no file"),
    ],
)
def test_names_that_leave_their_directory_are_refused(name: str, why: str, dirs: tuple[Path, Path]) -> None:
    with pytest.raises(ProgramNameError, match=why):
        check_program_name(name)
    assert ProgramDirectories(dirs).find(name) is None


def test_escapes_are_never_read_even_when_the_file_exists(dirs: tuple[Path, Path], tmp_path: Path) -> None:
    (tmp_path / "secret.nc").write_text("%secret\n", encoding="utf-8")
    library = ProgramDirectories([dirs[0]])
    assert library.find("../secret.nc") is None
    assert library.find(str(tmp_path / "secret.nc")) is None


def test_a_symbolic_link_out_of_the_directory_is_not_followed(
    dirs: tuple[Path, Path], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.nc").write_text("%secret\n", encoding="utf-8")
    os.symlink(outside / "secret.nc", dirs[0] / "link.nc")
    os.symlink(outside, dirs[0] / "linkdir")
    os.symlink(dirs[0] / "UP1.NC", dirs[0] / "inside.nc")  # a link that stays inside is fine
    library = ProgramDirectories([dirs[0]])
    assert library.find("link.nc") is None
    assert library.find("linkdir/secret.nc") is None
    assert "points outside the program directory" in caplog.text
    inside = library.find("inside.nc")
    assert inside is not None
    assert inside.text.startswith("%UP1")


def test_a_file_larger_than_the_bound_is_not_read(
    dirs: tuple[Path, Path], caplog: pytest.LogCaptureFixture
) -> None:
    (dirs[0] / "big.nc").write_bytes(b"N10 G01 X1 F100\n" * 100)
    library = ProgramDirectories([dirs[0]], max_bytes=1000)
    assert library.find("big.nc") is None
    assert "more than the 1000 a program may have" in caplog.text


def test_a_windows_1252_program_keeps_its_bytes(dirs: tuple[Path, Path]) -> None:
    (dirs[0] / "umlaut.nc").write_bytes("%umlaut\n(Fräsen)\nM17\n".encode("cp1252"))
    found = ProgramDirectories([dirs[0]]).find("umlaut.nc")
    assert found is not None
    assert "(Fräsen)" in found.text


def test_a_changed_file_is_read_again(dirs: tuple[Path, Path]) -> None:
    library = ProgramDirectories([dirs[0]])
    first = library.find("UP1.NC")
    path = dirs[0] / "UP1.NC"
    path.write_text("%UP1 changed, and longer\nM17\n", encoding="utf-8")
    os.utime(path, ns=(path.stat().st_atime_ns, path.stat().st_mtime_ns + 1_000_000))
    second = library.find("UP1.NC")
    assert first is not None
    assert second is not None
    assert second.text.startswith("%UP1 changed")


def test_uploads_come_first_newest_upload_first(dirs: tuple[Path, Path]) -> None:
    library = RuntimeLibrary(dirs)
    library.set_uploads(1, {"UP1.NC": "%UP1 uploaded\nM17\n"})
    found = library.find("up1.nc")
    assert found is not None
    assert (found.text, found.origin) == ("%UP1 uploaded\nM17\n", "upload:UP1.NC")
    library.set_uploads(2, {"UP1.NC": "%UP1 channel 2\nM17\n"})
    newest = library.find("UP1.NC")
    assert newest is not None
    assert newest.text == "%UP1 channel 2\nM17\n"
    assert library.searched()[0] == "uploaded files"
    library.set_uploads(1, {})
    library.set_uploads(2, {})
    from_disk = library.find("UP1.NC")
    assert from_disk is not None
    assert from_disk.origin == str(dirs[0] / "UP1.NC")
    assert "uploaded files" not in library.searched()


@pytest.mark.parametrize(
    ("files", "why"),
    [
        ({"../x.nc": "M17"}, "leaves its directory"),
        ({"/x.nc": "M17"}, "is absolute"),
        ({"a.nc": "M17", "A.NC": "M17"}, "given twice"),
        ({f"f{i}": "M17" for i in range(MAX_UPLOADED_FILES + 1)}, "at most 256"),
    ],
)
def test_uploads_are_checked_before_anything_changes(files: dict[str, str], why: str) -> None:
    library = RuntimeLibrary()
    library.set_uploads(1, {"keep.nc": "M17"})
    with pytest.raises(ValueError, match=why):
        library.set_uploads(1, files)
    assert library.uploads(1) == {"keep.nc": "M17"}


@pytest.mark.fuzz
def test_random_names_never_escape(dirs: tuple[Path, Path], tmp_path: Path) -> None:
    (tmp_path / "secret.nc").write_text("%secret\n", encoding="utf-8")
    rng = random.Random(seed_for("program_names"))
    parts = ["..", ".", "sub", "UP1.NC", "secret.nc", "/", "\\", "C:", "programs", "~", "%2e%2e", "\x00", ""]
    library = RuntimeLibrary([dirs[0]])
    for _ in range(count(2000)):
        name = "".join(rng.choice(parts) + rng.choice(["/", "\\", ""]) for _ in range(rng.randint(1, 6)))
        found = library.find(name)
        if found is not None:
            assert Path(found.origin).resolve().is_relative_to(dirs[0].resolve()), (name, found.origin)
            assert "%secret" not in found.text


def test_the_machine_files_program_directories_are_relative_to_it(tmp_path: Path) -> None:
    from hli_server.configuration import ConfigError, load_machine
    from tests.unit.config_helpers import write

    (tmp_path / "nc").mkdir()
    base = """
        program_directories = ["nc", "{missing}"]
        [[axes]]
        number = 1
        name = "X"
        [[axes]]
        number = 2
        name = "Y"
        [[axes]]
        number = 3
        name = "Z"
        [[channels]]
        axes = ["X", "Y", "Z"]
    """
    with pytest.raises(ConfigError) as refused:
        load_machine(write(tmp_path, "m.toml", base.format(missing="gone")))
    assert any(
        "m.toml:1: program_directories[1]: program directory" in m and "gone not found" in m
        for m in refused.value.messages
    ), refused.value.messages
    config = load_machine(write(tmp_path, "m.toml", base.format(missing="nc")))
    assert config.program_directories == [str((tmp_path / "nc").resolve())] * 2
