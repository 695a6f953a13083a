"""V.E. variables in the machine file: TOML tables and the kernel's list of external variables (N-05)."""

from __future__ import annotations

import contextlib
import random
from pathlib import Path

import pytest

from hli_server.configuration import ConfigError, load_machine_with_warnings
from hli_server.configuration.external_lists import parse_external_list
from schemas.layout import build_layout
from tests.fuzz import count, mutate, seed_for
from tests.unit.config_helpers import errors_of, write

pytestmark = pytest.mark.req("N-05")

MACHINE = """
    name = "ve"
    [[axes]]
    number = 1
    name = "X"
    [[axes]]
    number = 2
    name = "Y"
    [[axes]]
    number = 3
    name = "Z"
    [[axes]]
    number = 4
    name = "X2"
    [[axes]]
    number = 5
    name = "Y2"
    [[axes]]
    number = 6
    name = "Z2"
    [[channels]]
    number = 1
    axes = ["X", "Y", "Z"]
    external_variables_list = "ch1_ve.lis"
    [[channels]]
    number = 2
    axes = ["X2", "Y2", "Z2"]
    main_axes = ["X2", "Y2", "Z2"]
    {ch2}
    {extra}
"""

# the kernel's own example list (tf5200_external_variables, "Configuration syntax"), comments included
KERNEL_EXAMPLE = """
# ***************************************
# External variables V254
# ****************************************
#
number_used_variables            2
#
var[0].name                      GLOBAL_SWR    (Global VE)
var[0].index                     0
var[0].type                      SGN16
var[0].scope                     GLOBAL
var[0].synchronisation           FALSE
var[0].access_rights             READ_ONLY
var[0].array_size                0
var[0].size                      2    # 2 bytes per element
var[0].create_hmi_interface      FALSE
#
var[1].name                      CHANNEL_WR    (channel VE)
var[1].index                     0
var[1].type                      SGN32
var[1].scope                     CHANNEL
var[1].synchronisation           FALSE
var[1].access_rights             READ_ONLY
var[1].array_size                10
var[1].size                      4    # 4 bytes per element
var[1].create_hmi_interface      FALSE
#
End
"""


def machine(tmp_path: Path, ch1_list: str, *, ch2: str = "", extra: str = "") -> Path:
    write(tmp_path, "ch1_ve.lis", ch1_list)
    return write(tmp_path, "ve.toml", MACHINE.format(ch2=ch2, extra=extra))


def test_the_kernels_example_list_is_read_as_the_kernel_reads_it(tmp_path: Path) -> None:
    config, warnings = load_machine_with_warnings(machine(tmp_path, KERNEL_EXAMPLE))
    first, second = config.external_variables
    assert (first.name, first.type, first.channel, first.synchronous, first.access_rights, first.dims) == (
        "GLOBAL_SWR", "SGN16", None, False, "READ_ONLY", [],
    )  # fmt: skip
    assert (second.name, second.type, second.channel, second.dims) == ("CHANNEL_WR", "SGN32", 1, [10])
    assert any("ch1_ve.lis:8: var[0].index: accepted without effect" in w for w in warnings)
    layout = build_layout(config)
    assert layout.signal("gpVEGlob^GLOBAL_SWR").limits == (-32768, 32767)
    assert layout.signal("gpVECh[0]^CHANNEL_WR[9]").type.value == "DINT"


def test_the_kernels_defaults_apply_to_what_a_list_leaves_out(tmp_path: Path) -> None:
    config, _ = load_machine_with_warnings(machine(tmp_path, "var[0].name COUNTER\n"))
    (var,) = config.external_variables
    # P-EXTV-00003 UNS32, P-EXTV-00004 CHANNEL, P-EXTV-00005 TRUE, P-EXTV-00006 READ_WRITE
    assert (var.type, var.channel, var.synchronous, var.access_rights) == ("UNS32", 1, True, "READ_WRITE")


def test_two_channels_may_declare_the_same_global_variable(tmp_path: Path) -> None:
    lis = "var[0].name SHARED\nvar[0].scope GLOBAL\nvar[0].type REAL64\n"
    write(tmp_path, "ch2_ve.lis", lis)
    config, _ = load_machine_with_warnings(
        machine(tmp_path, lis, ch2='external_variables_list = "ch2_ve.lis"')
    )
    assert [(v.name, v.channel) for v in config.external_variables] == [("SHARED", None)]
    write(tmp_path, "ch2_ve.lis", lis.replace("REAL64", "SGN32"))
    errors = errors_of(machine(tmp_path, lis, ch2='external_variables_list = "ch2_ve.lis"'))
    assert any("ch2_ve.lis:1: var[0].name: global V.E.SHARED is declared differently in" in e for e in errors)


def test_list_and_toml_variables_together(tmp_path: Path) -> None:
    extra = (
        '[[external_variables]]\nname = "MODE"\ntype = "SGN32"\nchannel = 2\ndescription = "machining mode"\n'
    )
    config, _ = load_machine_with_warnings(machine(tmp_path, "var[0].name COUNTER\n", extra=extra))
    assert [(v.name, v.channel) for v in config.external_variables] == [("MODE", 2), ("COUNTER", 1)]
    assert config.external_variables[0].description == "machining mode"


@pytest.mark.parametrize(
    ("lines", "expected"),
    [
        (
            "var[0].name S\nvar[0].type VECTOR_T\n",
            "ch1_ve.lis:2: var[0].type: V.E.S: unknown type 'VECTOR_T'",
        ),
        ("var[0].name S\nvar[0].type 7UP\n", "ch1_ve.lis:2: var[0].type: '7UP' is no type"),
        ("struct[0].name VECTOR_T\n", "ch1_ve.lis:1: struct[0].name: struct[0] VECTOR_T has no elements"),
        ("struct[0].element[0].name X\n", "ch1_ve.lis:1: struct[0] has no struct[0].name"),
        (
            "struct[0].name T\nstruct[0].element[0].type SGN32\n",
            "ch1_ve.lis:2: struct[0].element[0] has no struct[0].element[0].name",
        ),
        (
            "struct[0].name T\nstruct[0].element[0].name X\nstruct[0].element[0].colour RED\n",
            "ch1_ve.lis:3: struct[0].element[0].colour: unknown parameter of struct[0].element[0]",
        ),
        (
            "struct[0].name T\nstruct[0].element[0].name X\nstruct[0].element[0].type U\n"
            "struct[1].name U\nstruct[1].element[0].name Y\nstruct[1].element[0].type T\n",
            "structure T contains itself (T -> U -> T)",
        ),
        (
            "struct[0].name T\nstruct[0].element[0].name X\nstruct[0].element[0].type REAL46\n",
            "structure T, element X: unknown type 'REAL46'",
        ),
        (
            "var[0].name S\nvar[0].type VSTRING\nvar[0].size 801\n",
            "ch1_ve.lis:3: var[0].size: 801 is out of range",
        ),
        (
            "use_extended_string_var SOMETIMES\n",
            "ch1_ve.lis:1: use_extended_string_var: 'SOMETIMES' is not TRUE",
        ),
        (
            "var[0].name LONG\nvar[0].type VSTRING\nvar[0].size 800\nvar[0].array_elements 2\n",
            "need 800 Modbus holding registers for their numbers and strings",
        ),
        ("var[0].type SGN32\n", "ch1_ve.lis:1: var[0] has no var[0].name"),
        ("var[0].name A\nvar[0].scope LOCAL\n", "'LOCAL': the scope is GLOBAL or CHANNEL"),
        ("var[0].name A\nvar[0].synchronisation MAYBE\n", "'MAYBE' is not TRUE or FALSE"),
        ("var[0].name A\nvar[0].access_rights ALL\n", "'ALL': use READ_WRITE, READ_ONLY or WRITE_ONLY"),
        ("var[0].name A\nvar[0].colour RED\n", "ch1_ve.lis:2: var[0].colour: unknown parameter of var[0]"),
        ("var[0].name A\nvar[0].name B\n", "ch1_ve.lis:2: var[0].name: given twice (first in line 1)"),
        ("var[215].name A\n", "var[215]: the kernel numbers them 0 to 214"),
        ("number_used_variables 1\nvar[1].name A\n", "var[1] lies beyond number_used_variables 1"),
        ("var[0].name A\nvar[0].array_elements many\n", "'many' is not a number of elements"),
        ("var[0].name 1A\n", "ch1_ve.lis:1: var[0].name: invalid value '1A'"),
        ("var[0].name A\nvar[1].name a\n", "V.E.a is declared twice in channel 1's area"),
        (
            "var[0].name BIG\nvar[0].type REAL64\nvar[0].array_elements 200\n",
            "need 800 Modbus holding registers",
        ),
        ("flux_capacitor 1\n", "ch1_ve.lis:1: flux_capacitor: unknown entry"),
    ],
)
def test_every_mistake_names_file_line_and_key(tmp_path: Path, lines: str, expected: str) -> None:
    errors = errors_of(machine(tmp_path, lines))
    assert any(expected in e for e in errors), errors


# the kernel's example of V.E. structures (tf5200_external_variables 321583243), cut to one curve: a
# structure with an array of structures and a STRING, extended strings
KERNEL_STRUCTURES = """
use_extended_string_var                        1
struct[0].name                                  typcurve
struct[0].element[0].name                       point
struct[0].element[0].type                       typ_pos
struct[0].element[0].array_elements             12
struct[0].element[1].name                       curve_name
struct[0].element[1].type                       STRING
struct[1].name                                  typ_pos
struct[1].element[0].name                       X
struct[1].element[0].type                       REAL64
struct[1].element[1].name                       Y
struct[1].element[1].type                       REAL64
struct[1].element[2].name                       Z
struct[1].element[2].type                       REAL64
struct[1].element[3].name                       pos_is_valid
struct[1].element[3].type                       BOOLEAN
var[0].name                                     curve
var[0].type                                     typcurve
var[0].scope                                    GLOBAL
var[1].name                                     TEXT
var[1].type                                     STRING
var[1].array_elements                           2
var[2].name                                     NOTE
var[2].type                                     VSTRING
var[2].size                                     41
"""


def test_the_kernels_structure_example_is_read_and_placed(tmp_path: Path) -> None:
    config, warnings = load_machine_with_warnings(machine(tmp_path, KERNEL_STRUCTURES))
    assert not warnings
    assert config.use_extended_string_var
    assert [s.name for s in config.external_structures] == ["typcurve", "typ_pos"]
    curve, text, note = config.external_variables
    assert (curve.type, curve.channel, text.type, text.dims, note.type, note.size) == (
        "typcurve", None, "STRING", [2], "VSTRING", 41,
    )  # fmt: skip
    layout = build_layout(config)
    name = layout.signal("gpVEGlob^curve.curve_name")
    assert (name.type_name, name.size, name.structures) == ("STRING(127)", 128, ("typcurve",))
    x = layout.signal("gpVEGlob^curve.point[11].X")
    assert (x.type.value, x.structures, x.external_element) == (
        "LREAL",
        ("typcurve", "typ_pos"),
        ("curve.point.X", (11,)),
    )
    assert layout.signal("gpVECh[0]^TEXT[1]").type_name == "STRING(127)"
    assert layout.signal("gpVECh[0]^NOTE").type_name == "STRING(40)"
    # 12 points of 3 LREAL and a BOOL (32 bytes each), then the string: the structure is one block
    assert name.offset - layout.signal("gpVEGlob^curve.point[0].X").offset == 12 * 32


def test_two_lists_share_a_structure_and_the_string_length(tmp_path: Path) -> None:
    lis = (
        "use_extended_string_var 1\nstruct[0].name T\nstruct[0].element[0].name A\n"
        "var[0].name V\nvar[0].type T\n"
    )
    write(tmp_path, "ch2_ve.lis", lis)
    config, _ = load_machine_with_warnings(
        machine(tmp_path, lis, ch2='external_variables_list = "ch2_ve.lis"')
    )
    assert [s.name for s in config.external_structures] == ["T"]
    write(tmp_path, "ch2_ve.lis", lis.replace("element[0].name A", "element[0].name B"))
    errors = errors_of(machine(tmp_path, lis, ch2='external_variables_list = "ch2_ve.lis"'))
    assert any("ch2_ve.lis:2: struct[0].name: structure T is declared differently in" in e for e in errors), (
        errors
    )
    write(tmp_path, "ch2_ve.lis", lis.replace("use_extended_string_var 1", "use_extended_string_var 0"))
    errors = errors_of(machine(tmp_path, lis, ch2='external_variables_list = "ch2_ve.lis"'))
    assert any("ch2_ve.lis:1: use_extended_string_var: False differs from True" in e for e in errors), errors


def test_structures_in_the_machine_file(tmp_path: Path) -> None:
    extra = """
        [[external_structures]]
        name = "UserInteractionType"
        elements = [
            { name = "Message", type = "string" },
            { name = "Answer", type = "SGN32", synchronous = true },
        ]
        [[external_variables]]
        name = "UserInteraction"
        type = "UserInteractionType"
    """
    path = write(
        tmp_path,
        "ve.toml",
        MACHINE.format(ch2="", extra=extra).replace('external_variables_list = "ch1_ve.lis"', ""),
    )
    config, _ = load_machine_with_warnings(path)
    (structure,) = config.external_structures
    assert [(e.name, e.type, e.synchronous) for e in structure.elements] == [
        ("Message", "STRING", None), ("Answer", "SGN32", True),
    ]  # fmt: skip
    layout = build_layout(config)
    assert layout.signal("gpVEGlob^UserInteraction.Message").type_name == "STRING(20)"
    bad = extra.replace('type = "UserInteractionType"', 'type = "UserInteractonType"')
    path.write_text(MACHINE.format(ch2="", extra=bad).replace('external_variables_list = "ch1_ve.lis"', ""))
    errors = errors_of(path)
    assert any("did you mean UserInteractionType?" in e and "external_variables" in e for e in errors), errors


def test_a_missing_list_is_named_where_the_machine_file_names_it(tmp_path: Path) -> None:
    path = write(tmp_path, "ve.toml", MACHINE.format(ch2="", extra=""))
    errors = errors_of(path)
    assert any("ve.toml:" in e and "list of external variables" in e and "not found" in e for e in errors), (
        errors
    )


@pytest.mark.fuzz
def test_random_lists_never_crash_the_reader_nor_the_loader(tmp_path: Path) -> None:
    rng = random.Random(seed_for("external_lists"))
    lines = KERNEL_EXAMPLE.splitlines()
    for k in range(count(200)):
        text = "\n".join(mutate(rng, line) if rng.random() < 0.3 else line for line in lines)
        result = parse_external_list(text, source="f.lis", channel=1)
        assert all(isinstance(v["name"], str) for v in result.variables), text
        if k % 20 == 0:  # through the whole loader too
            path = machine(tmp_path, text)
            with contextlib.suppress(ConfigError):  # a ConfigError or a machine, nothing else
                load_machine_with_warnings(path)
