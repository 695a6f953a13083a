"""Machine configuration: TOML machine files, ISG text parameter lists, the demo machine, the CLI.

E-07 (configuration in the documents' names and units, validated, readable from the text lists);
C3-04 (the collision configuration of FCT-C3 section 3 forms the pairs).
"""

from __future__ import annotations

import json
import math
import re
import textwrap
from importlib import resources
from pathlib import Path

import pytest
from click.testing import CliRunner

from hli_server.commands.config import config as config_command
from hli_server.configuration import (
    ConfigError,
    ConfigFileError,
    demo_machine_path,
    load_machine,
    load_machine_with_warnings,
    parameter_table_markdown,
    parse_parameter_list,
)
from schemas.config import (
    AXIS_PARAMETERS,
    CHANNEL_PARAMETERS,
    MANUAL_PARAMETERS,
    AxisConfig,
    ChannelConfig,
    InterpolatorFunction,
    MachineConfig,
    ManualConfig,
)
from schemas.units import increments_from_mm, mm_per_min_to_mm_per_s, s_from_us
from tests.unit.config_helpers import errors_of, write

DOCS = Path(__file__).resolve().parents[2] / "docs" / "configuration.md"

LATER_CHECKS_NOTE = (
    "note: the checks across the machine (collision pairs, which axes belong to which channel) "
    "run once the findings above are fixed: validate again then"
)


def machine_with_lists(tmp_path: Path, axes: dict[str, str], channels: list[list[str]]) -> Path:
    """A machine file whose axes come from the given lists (axis name -> list text)."""
    parts: list[str] = []
    for name, text in axes.items():
        write(tmp_path, f"{name.lower()}.lis", text)
        parts.append(f'[[axes]]\nname = "{name}"\nparameter_list = "{name.lower()}.lis"\n')
    for number, names in enumerate(channels, 1):
        quoted = ", ".join(f'"{n}"' for n in names)
        main = ", ".join(f'"{n}"' for n in names[:3])
        parts.append(f"[[channels]]\nnumber = {number}\naxes = [{quoted}]\nmain_axes = [{main}]\n")
    return write(tmp_path, "machine.toml", "\n".join(parts))


def helper_axes(*names_and_numbers: tuple[str, int]) -> dict[str, str]:
    return {name: f"kopf.achs_nr {number}\n" for name, number in names_and_numbers}


# --------------------------------------------------------------------------------------------------
# the four examples of FCT-C3 section 3


@pytest.mark.req("E-07", "C3-04")
def test_fct_c3_example_minimum_distance(tmp_path: Path) -> None:
    x1 = """
        kopf.achs_nr      1
        kenngr.achs_mode  0x8001
    """
    x2 = """
        kopf.achs_nr      2
        kenngr.achs_mode  0x8001

        kenngr.coll_check_ax_nr  1
        kenngr.coll_offset      200000
    """
    parsed = parse_parameter_list(textwrap.dedent(x2), "axis", source="x2.lis")
    assert parsed.errors == []
    assert parsed.values == {"number": 2, "achs_mode": 0x8001, "coll_check_ax_nr": 1, "coll_offset": 200000}

    path = machine_with_lists(tmp_path, {"X1": x1, "X2": x2, "Y": "kopf.achs_nr 3\n"}, [["X1", "X2", "Y"]])
    machine = load_machine(path)
    ax1, ax2 = machine.axis("X1"), machine.axis("X2")
    assert (ax1.number, ax1.achs_mode, ax1.collision_monitoring) == (1, 0x8001, True)
    assert (ax2.number, ax2.coll_check_ax_nr, ax2.coll_offset, ax2.collision_monitoring) == (
        2,
        1,
        200000,
        True,
    )
    assert [(m.name, p.name) for m, p in machine.collision_pairs()] == [("X2", "X1")]


@pytest.mark.req("E-07", "C3-04", "C3-05", "C3-09")
def test_fct_c3_example_two_channels_inverted_directions(tmp_path: Path) -> None:
    x1 = """
        kopf.achs_nr          1
        kenngr.achs_mode      0x8001
    """
    x2 = """
        kopf.achs_nr          6
        kenngr.achs_mode      0x8001

        kenngr.coll_check_ax_nr      1
        kenngr.coll_offset          200000
        kenngr.coll_moving_dir_inverted 1
        kenngr.coll_decelerate_chan  1
    """
    axes = {"X1": x1, "X2": x2, **helper_axes(("Y", 2), ("Z", 3), ("Y2", 7), ("Z2", 8))}
    path = machine_with_lists(tmp_path, axes, [["X1", "Y", "Z"], ["X2", "Y2", "Z2"]])
    machine = load_machine(path)
    ax2 = machine.axis("X2")
    assert (ax2.number, ax2.coll_check_ax_nr, ax2.coll_offset) == (6, 1, 200000)
    assert ax2.coll_moving_dir_inverted is True
    assert ax2.coll_decelerate_chan is True
    assert machine.channel_of("X1").number == 1
    assert machine.channel_of("X2").number == 2
    assert [(m.name, p.name) for m, p in machine.collision_pairs()] == [("X2", "X1")]


@pytest.mark.req("E-07", "C3-04", "C3-09")
def test_fct_c3_example_different_zero_positions(tmp_path: Path) -> None:
    x1 = """
        kopf.achs_nr      1
        kenngr.achs_mode  0x8001
    """
    x2 = """
        kopf.achs_nr      2
        kenngr.achs_mode  0x8001

        kenngr.coll_check_ax_nr  1
        kenngr.coll_offset       200000
        kenngr.coll_zero_position_offset -1000000
    """
    path = machine_with_lists(tmp_path, {"X1": x1, "X2": x2, "Y": "kopf.achs_nr 3"}, [["X1", "X2", "Y"]])
    ax2 = load_machine(path).axis("X2")
    assert ax2.coll_zero_position_offset == -1_000_000
    assert (ax2.coll_check_ax_nr, ax2.coll_offset) == (1, 200000)


@pytest.mark.req("E-07", "C3-04", "C3-03")
def test_fct_c3_example_two_pairs_tab_separated(tmp_path: Path) -> None:
    # the document prints this example as a table: path and value separated by a tab
    x1 = "kopf.achs_nr\t1\nkenngr.achs_mode\t0x8001\n"
    x2 = (
        "kopf.achs_nr\t2\nkenngr.achs_mode\t0x8001\n\n"
        "kenngr.coll_check_ax_nr\t1\nkenngr.coll_offset\t200000\n"
    )
    x3 = (
        "kopf.achs_nr\t3\nkenngr.achs_mode\t0x8001\n\n"
        "kenngr.coll_check_ax_nr\t2\nkenngr.coll_offset\t300000\n"
    )
    path = machine_with_lists(tmp_path, {"X1": x1, "X2": x2, "X3": x3}, [["X1", "X2", "X3"]])
    machine = load_machine(path)
    pairs = [(m.name, p.name, m.coll_offset) for m, p in machine.collision_pairs()]
    assert pairs == [("X2", "X1", 200000), ("X3", "X2", 300000)]
    assert all(machine.axis(n).collision_monitoring for n in ("X1", "X2", "X3"))


# --------------------------------------------------------------------------------------------------
# list syntax


@pytest.mark.req("E-07")
def test_list_syntax_comments_hex_negative_gear_and_p_stup() -> None:
    text = """
    # header comment

    kopf.achs_nr 7            # trailing comment
    kopf.achs_name X2
    kopf.achs_typ T
    kenngr.achs_mode 0x8001
    kenngr.swe_neg -0x10
    kenngr.swe_pos 123456
    getriebe[0].window 500
    getriebe[0].dynamik.a_max 2500.5
    kenngr.coll_use_a_emergency 1
    """
    parsed = parse_parameter_list(textwrap.dedent(text), "axis")
    assert parsed.errors == []
    assert parsed.values == {
        "number": 7,
        "name": "X2",
        "axis_type": "T",
        "achs_mode": 0x8001,
        "swe_neg": -16,
        "swe_pos": 123456,
        "window": 500,
        "a_max": 2500.5,
        "coll_use_a_emergency": True,
    }
    assert parsed.origins["window"].line == 10


@pytest.mark.req("E-07", "C43-01")
def test_channel_list_sets_interpolator_function_as_fct_c43_writes_it(tmp_path: Path) -> None:
    # FCT-C43 section 2 prints the line wrapped after the `|`
    write(
        tmp_path,
        "ch1.lis",
        """
        configuration.channel[0].interpolator.function FCT_LOOK_AHEAD_STANDARD |
        FCT_DYN_POS_LIMIT
        suppress_workspace_monitoring_manual_mode 2
        meas_soft_limit_move_path 1
        """,
    )
    write(tmp_path, "ch2.lis", "configuration.channel[1].interpolator.function FCT_IPO_DEFAULT\n")
    path = write(
        tmp_path,
        "m.toml",
        """
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
        parameter_list = "ch1.lis"
        [[channels]]
        number = 2
        axes = ["X2", "Y2", "Z2"]
        main_axes = ["X2", "Y2", "Z2"]
        interpolator_function = "FCT_LOOK_AHEAD_STANDARD | FCT_DYN_POS_LIMIT"
        parameter_list = "ch2.lis"
        """,
    )
    machine = load_machine(path)
    ch1, ch2 = machine.channels
    assert ch1.interpolator_function == [
        InterpolatorFunction.FCT_LOOK_AHEAD_STANDARD,
        InterpolatorFunction.FCT_DYN_POS_LIMIT,
    ]
    assert ch1.dyn_pos_limit_enabled
    assert ch1.suppress_workspace_monitoring_manual_mode == 2
    assert ch1.meas_soft_limit_move_path is True
    # the list overrides the table
    assert ch2.interpolator_function == [InterpolatorFunction.FCT_IPO_DEFAULT]
    assert not ch2.dyn_pos_limit_enabled


@pytest.mark.req("E-07")
def test_channel_index_of_p_stup_must_match_the_channel() -> None:
    parsed = parse_parameter_list(
        "configuration.channel[1].interpolator.function FCT_DYN_POS_LIMIT\n",
        "channel",
        source="ch1.lis",
        channel_index=0,
    )
    assert parsed.errors == [
        "ch1.lis:1: configuration.channel[1].interpolator.function: this list belongs to channel 1: "
        "write configuration.channel[0].interpolator.function (index = channel number - 1)"
    ]


@pytest.mark.req("E-07")
def test_gear_stages_other_than_zero_are_reported() -> None:
    text = "getriebe[1].window 900\ngetriebe[0].window 400\ngetriebe[2].position_settling_time 5000\n"
    parsed = parse_parameter_list(text, "axis", source="x.lis")
    assert parsed.errors == []
    assert parsed.values == {"window": 400, "position_settling_time_us": 5000}
    assert parsed.warnings == [
        "x.lis:1: getriebe[1].window: only gear stage 0 is simulated; this gear stage 1 value is not used "
        "(getriebe[0] gives 400)",
        "x.lis:3: getriebe[2].position_settling_time: only gear stage 0 is simulated; this gear stage 2 "
        "value is used for it (the list has no getriebe[0] entry)",
    ]


@pytest.mark.req("E-07")
def test_list_value_errors_name_file_line_and_key() -> None:
    text = """
    kopf.achs_nr
    kenngr.achs_mode 0x80G1
    kenngr.coll_decelerate_chan 2
    kenngr.swe_neg 100 200
    kenngr.swe_pos 5
    kenngr.swe_pos 6
    getriebe[3].window -1
    meas_soft_limit_move_path 1
    """
    parsed = parse_parameter_list(textwrap.dedent(text).lstrip("\n"), "axis", source="a.lis")
    assert parsed.errors == [
        "a.lis:1: kopf.achs_nr: no value (write `kopf.achs_nr <value>`)",
        "a.lis:2: kenngr.achs_mode: '0x80G1' is not an integer (decimal or 0x hex)",
        "a.lis:3: kenngr.coll_decelerate_chan: '2' is not a boolean (write 0 or 1)",
        "a.lis:4: kenngr.swe_neg: unexpected text after the value: '100 200'",
        "a.lis:6: kenngr.swe_pos: given twice (first in line 5)",
        "a.lis:7: getriebe[3].window: -1 is out of range: P-AXIS-00236 allows 0 ≤ value ≤ MAX(SGN32)",
        "a.lis:8: meas_soft_limit_move_path: unknown axis parameter: meas_soft_limit_move_path is a "
        "channel parameter",
    ]


@pytest.mark.req("E-07", "C14-19")
def test_manual_list_sets_p_manu_00014(tmp_path: Path) -> None:
    write(tmp_path, "manual.lis", "move_limit_warning 1   # P-MANU-00014\n")
    path = write(
        tmp_path,
        "m.toml",
        """
        [manual]
        move_limit_warning = false
        parameter_list = "manual.lis"
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
        """,
    )
    assert load_machine(path).manual.move_limit_warning is True


# --------------------------------------------------------------------------------------------------
# unknown keys and range violations


@pytest.mark.req("E-07")
def test_unknown_list_key_is_reported_with_file_line_and_suggestion(tmp_path: Path) -> None:
    x2 = """
        kopf.achs_nr 2
        kenngr.achs_mode 0x8001
        kenngr.coll_check_ax_nr 1

        # minimum distance
        kenngr.coll_ofset 200000
    """
    path = machine_with_lists(
        tmp_path, {"X1": "kopf.achs_nr 1\nkenngr.achs_mode 0x8001", "X2": x2, "Y": "kopf.achs_nr 3"}, []
    )
    path.write_text(
        path.read_text() + '[[channels]]\naxes = ["X1", "X2", "Y"]\nmain_axes = ["X1", "X2", "Y"]\n'
    )
    messages = errors_of(path)
    expected = (
        f"{tmp_path / 'x2.lis'}:6: kenngr.coll_ofset: unknown parameter (did you mean kenngr.coll_offset?)"
    )
    assert expected in messages


@pytest.mark.req("E-07")
def test_unknown_toml_keys_are_reported_with_line(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "m.toml",
        """
        name = "t"
        cycle_tme_us = 1000

        [[axes]]
        number = 1
        name = "X"
        swe_ng = -5
        achs_nr = 3
        "kenngr.swe_pos" = 5

        [axes.drive]
        feedforward = 0.5

        [[axis]]
        name = "Y"

        [[channels]]
        axes = ["X"]
        main_axes = ["X", "X", "X"]
        """,
    )
    messages = errors_of(path)
    assert messages == [
        f"{path}:2: cycle_tme_us: unknown key (did you mean cycle_time_us?)",
        f"{path}:7: axes[0].swe_ng: axis X: unknown key (did you mean swe_neg?)",
        f"{path}:8: axes[0].achs_nr: axis X: unknown key (the documents' achs_nr is called number here)",
        f"{path}:9: axes[0].kenngr.swe_pos: axis X: unknown key: kenngr.swe_pos is an ISG text-list path; "
        "in the machine file write `swe_pos = ...`, or put the line in a parameter list",
        f"{path}:12: axes[0].drive.feedforward: axis X: unknown key (did you mean feed_forward?)",
        f"{path}:14: axis: unknown key (did you mean axes?)",
        f"{path}:19: channels[0].main_axes: channel 1: the three main axes must differ, got ['X', 'X', 'X']",
    ]


@pytest.mark.req("E-07", "E-06")
def test_swe_neg_not_below_swe_pos(tmp_path: Path) -> None:
    write(tmp_path, "y.lis", "kopf.achs_nr 2\nkenngr.swe_neg 5000   # above swe_pos\nkenngr.swe_pos 4000\n")
    path = write(
        tmp_path,
        "m.toml",
        """
        [[axes]]
        number = 1
        name = "X"
        swe_neg = 100
        swe_pos = 100
        [[axes]]
        name = "Y"
        parameter_list = "y.lis"
        [[axes]]
        number = 3
        name = "Z"
        [[channels]]
        axes = ["X", "Y", "Z"]
        """,
    )
    assert errors_of(path) == [
        f"{path}:4: axes[0].swe_neg: axis X: P-AXIS-00177 swe_neg (100) must be less than "
        "P-AXIS-00178 swe_pos (100)",
        f"{tmp_path / 'y.lis'}:2: kenngr.swe_neg: axis Y: P-AXIS-00177 swe_neg (5000) must be less than "
        "P-AXIS-00178 swe_pos (4000)",
    ]


def _pair_machine(tmp_path: Path, x1: str, x2: str, extra: str = "") -> Path:
    write(tmp_path, "x1.lis", x1)
    write(tmp_path, "x2.lis", x2)
    return write(
        tmp_path,
        "m.toml",
        f"""
        [[axes]]
        name = "X1"
        parameter_list = "x1.lis"
        [[axes]]
        name = "X2"
        parameter_list = "x2.lis"
        [[axes]]
        number = 3
        name = "Y"
        {extra}
        [[channels]]
        axes = ["X1", "X2", "Y"]
        main_axes = ["X1", "X2", "Y"]
        """,
    )


@pytest.mark.req("E-07", "C3-04")
def test_coll_offset_one_is_refused(tmp_path: Path) -> None:
    path = _pair_machine(
        tmp_path,
        "kopf.achs_nr 1\nkenngr.achs_mode 0x8001\n",
        "kopf.achs_nr 2\nkenngr.achs_mode 0x8001\nkenngr.coll_check_ax_nr 1\nkenngr.coll_offset 1\n",
    )
    assert errors_of(path) == [
        f"{tmp_path / 'x2.lis'}:4: kenngr.coll_offset: axis X2: P-AXIS-00045 coll_offset must be 0 (none) "
        "or > 1 (1 < coll_offset)"
    ]


@pytest.mark.req("E-07", "C3-04")
def test_collision_pair_without_bit_0x8000(tmp_path: Path) -> None:
    path = _pair_machine(
        tmp_path,
        "kopf.achs_nr 1\nkenngr.achs_mode 0x0001   # the bit is missing here\n",
        "kopf.achs_nr 2\nkenngr.achs_mode 0x8001\nkenngr.coll_check_ax_nr 1\nkenngr.coll_offset 200000\n",
    )
    assert errors_of(path) == [
        f"{tmp_path / 'x1.lis'}:2: kenngr.achs_mode: axes X2/X1: a collision pair needs bit 0x8000 in "
        "P-AXIS-00015 kenngr.achs_mode of both axes; axis X1 has 0x1 (set 0x8001)"
    ]


@pytest.mark.req("E-07", "C3-04")
def test_collision_partner_must_exist(tmp_path: Path) -> None:
    path = _pair_machine(
        tmp_path,
        "kopf.achs_nr 1\nkenngr.achs_mode 0x8001\n",
        "kopf.achs_nr 2\nkenngr.achs_mode 0x8001\nkenngr.coll_check_ax_nr 9\nkenngr.coll_offset 200000\n",
    )
    assert errors_of(path) == [
        f"{tmp_path / 'x2.lis'}:3: kenngr.coll_check_ax_nr: axis X2: P-AXIS-00043 coll_check_ax_nr 9 is no "
        "logical axis number (numbers: [1, 2, 3])"
    ]


@pytest.mark.req("E-07", "C3-04")
def test_two_sided_pair_with_different_offsets_warns_70162(tmp_path: Path) -> None:
    path = _pair_machine(
        tmp_path,
        "kopf.achs_nr 1\nkenngr.achs_mode 0x8001\nkenngr.coll_check_ax_nr 2\nkenngr.coll_offset 150000\n",
        "kopf.achs_nr 2\nkenngr.achs_mode 0x8001\nkenngr.coll_check_ax_nr 1\nkenngr.coll_offset 200000\n",
    )
    machine, warnings = load_machine_with_warnings(path)
    assert len(machine.collision_pairs()) == 1
    assert len(warnings) == 1
    assert "older two-sided configuration" in warnings[0]
    assert "the larger (200000) applies" in warnings[0]
    assert "70162" in warnings[0]


@pytest.mark.req("E-07", "C14-20")
def test_p_chan_00442_out_of_range(tmp_path: Path) -> None:
    write(tmp_path, "ch.lis", "# P-CHAN-00442\nsuppress_workspace_monitoring_manual_mode 3\n")
    path = write(
        tmp_path,
        "m.toml",
        """
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
        suppress_workspace_monitoring_manual_mode = 3
        [[channels]]
        number = 2
        axes = ["Q"]
        main_axes = ["Q", "Q", "Q"]
        """,
    )
    messages = errors_of(path)
    assert messages[0] == (
        f"{path}:12: channels[0].suppress_workspace_monitoring_manual_mode: channel 1: 3 is out of range: "
        "P-CHAN-00442 allows 0 ≤ value ≤ 2"
    )
    parsed = parse_parameter_list((tmp_path / "ch.lis").read_text(), "channel", source="ch.lis")
    assert parsed.errors == [
        "ch.lis:2: suppress_workspace_monitoring_manual_mode: 3 is out of range: P-CHAN-00442 allows "
        "0 ≤ value ≤ 2"
    ]


@pytest.mark.req("E-07")
@pytest.mark.parametrize(("written", "line"), [("0", "0"), ("0x10000001", "0x10000001")])
def test_achs_mode_out_of_range(tmp_path: Path, written: str, line: str) -> None:
    write(tmp_path, "x.lis", f"kopf.achs_nr 1\nkenngr.achs_mode {written}\n")
    parsed = parse_parameter_list((tmp_path / "x.lis").read_text(), "axis", source="x.lis")
    assert parsed.errors == [
        f"x.lis:2: kenngr.achs_mode: {line} is out of range: P-AXIS-00015 allows "
        "0x00000001 ≤ value ≤ 0x10000000"
    ]


@pytest.mark.req("E-07")
def test_all_errors_are_collected_and_defaults_point_at_the_table(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "m.toml",
        """
        [[axes]]
        name = "X"
        swe_neg = 200_000_000

        [[axes]]
        number = 2
        name = "y"

        [[channels]]
        number = 13
        axes = ["X"]
        main_axes = ["X", "X", "X"]
        """,
    )
    messages = errors_of(path)
    assert messages == [
        f"{path}:1: axes[0].number: axis X: required, not given (give `number` here or kopf.achs_nr in "
        "the axis' parameter list)",
        f"{path}:7: axes[1].name: axis y: invalid value 'y': string should match pattern "
        "'^[A-Z][A-Z0-9]{0,7}$'",
        f"{path}:10: channels[0].number: channel 13: 13 is out of range: number allows 1 ≤ value ≤ 12",
    ]


@pytest.mark.req("E-07")
def test_toml_syntax_error_missing_list_and_missing_file(tmp_path: Path) -> None:
    bad = write(tmp_path, "bad.toml", '[[axes]]\nname = "X"\nnumber = = 1\n')
    assert errors_of(bad) == [
        f"{bad}:3: TOML syntax error: Invalid value (at line 3, column 10)",
    ]
    missing_list = write(
        tmp_path,
        "m.toml",
        '[[axes]]\nnumber = 1\nname = "X"\nparameter_list = "nowhere.lis"\n[[channels]]\naxes = ["X"]\n',
    )
    messages = errors_of(missing_list)
    assert (
        messages[0]
        == f"{missing_list}:4: axes[0].parameter_list: parameter list {tmp_path / 'nowhere.lis'} not found"
    )
    with pytest.raises(ConfigFileError) as info:
        load_machine(tmp_path / "absent.toml")
    assert info.value.messages == [f"{tmp_path / 'absent.toml'}: machine file not found"]


@pytest.mark.req("E-07")
def test_lines_are_found_after_multiline_program_text(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "m.toml",
        """
        [[axes]]
        number = 1
        name = "X"
        [[channels]]
        axes = ["X"]
        main_axes = ["X", "X", "X"]
        [[channels.programs]]
        number = 1
        name = "p"
        text = '''
        N10 G01 X2=100 F100
        [[axes]]
        N20 M30
        '''
        [[channels.programs]]
        number = 2
        name = "q"
        path = "missing.nc"
        """,
    )
    messages = errors_of(path)
    assert messages == [
        f"{path}:6: channels[0].main_axes: channel 1: the three main axes must differ, got ['X', 'X', 'X']",
        f"{path}:18: channels[0].programs[1].path: program file {tmp_path / 'missing.nc'} not found",
    ]


# --------------------------------------------------------------------------------------------------
# the demo machine


@pytest.mark.req("E-07")
def test_demo_machine_loads_through_the_lists_and_meets_its_requirements() -> None:
    machine, warnings = load_machine_with_warnings(None)
    assert warnings == []
    demo_dir = demo_machine_path().parent
    for name in ("demo_x1.lis", "demo_x2.lis", "demo_ch1.lis"):
        assert (demo_dir / name).is_file()
        assert f'parameter_list = "{name}"' in demo_machine_path().read_text(encoding="utf-8")

    ch1 = machine.channels[0]
    assert (ch1.number, ch1.axes, ch1.main_axes) == (1, ["X", "Y", "Z"], ("X", "Y", "Z"))
    assert ch1.dyn_pos_limit_enabled
    for name in ("X", "Y"):
        axis = machine.axis(name)
        assert axis.swe_neg <= increments_from_mm(-500)
        assert axis.swe_pos >= increments_from_mm(500)
    z = machine.axis("Z")
    assert z.swe_neg <= increments_from_mm(-200)
    assert z.swe_pos >= increments_from_mm(200)
    for name in ("X", "Y", "Z"):
        assert machine.axis(name).referenced
        assert machine.axis(name).start_position == 0

    assert 2 <= len(ch1.programs) + len(machine.channels[1].programs) <= 3
    assert {p.name for p in ch1.programs} == {"square", "circle"}
    assert all(p.text and "M30" in p.text for ch in machine.channels for p in ch.programs)


@pytest.mark.req("E-07", "C3-04", "C3-06")
def test_demo_collision_pair_as_in_fct_c3_first_example() -> None:
    machine = load_machine(None)
    gantry = machine.channels[1]
    assert (gantry.number, gantry.name) == (2, "gantry")
    assert set(gantry.axes) == {"X1", "X2", "Z1"}
    x1, x2 = machine.axis("X1"), machine.axis("X2")
    assert x1.achs_mode == x2.achs_mode == 0x8001
    assert (x2.coll_check_ax_nr, x2.coll_offset) == (x1.number, 200000)
    assert [(m.name, p.name) for m, p in machine.collision_pairs()] == [("X2", "X1")]
    assert x1.referenced
    assert x2.referenced
    # far apart at start, inside their travel
    assert x2.start_position - x1.start_position >= increments_from_mm(400) > x2.coll_offset
    for axis in (x1, x2):
        assert axis.swe_neg < axis.start_position < axis.swe_pos


@pytest.mark.req("E-07", "A3-03")
def test_demo_drive_settles_within_the_position_window_in_time() -> None:
    """The demo's drive model: steady following error ~ v (1 - ff) / kv; decay ~ exp(-kv t).

    Conservative bound: the setpoint stops dead at v_max (a real stop brakes first and settles
    much sooner); the error must still decay into the window within P-AXIS-00532.
    """
    machine = load_machine(None)
    for axis in machine.axes:
        assert axis.window == 500
        assert axis.position_settling_time_us == 100_000
        assert axis.window >= 3 * axis.drive.standstill_noise
        v = mm_per_min_to_mm_per_s(axis.v_max)
        following_error_mm = v * (1.0 - axis.drive.feed_forward) / axis.drive.kv
        assert 0.1 < following_error_mm < 5.0  # realistic: visible, but a machine would run so
        window_mm = axis.window / 10_000
        settle_s = math.log(following_error_mm / window_mm) / axis.drive.kv
        settle_s += s_from_us(axis.drive.time_constant_us)
        assert settle_s < s_from_us(axis.position_settling_time_us)


# --------------------------------------------------------------------------------------------------
# the CLI


@pytest.mark.req("E-07")
def test_cli_validate_exit_codes(tmp_path: Path) -> None:
    runner = CliRunner()
    ok = runner.invoke(config_command, ["validate", str(demo_machine_path())])
    assert ok.exit_code == 0, ok.output
    assert ok.stdout.startswith("OK: ")
    assert "6 axes" in ok.stdout
    assert "1 collision pair" in ok.stdout

    write(tmp_path, "x.lis", "kopf.achs_nr 1\nkenngr.coll_ofset 5\n")
    bad = write(
        tmp_path,
        "bad.toml",
        '[[axes]]\nname = "X"\nparameter_list = "x.lis"\n'
        '[[channels]]\naxes = ["X"]\nmain_axes = ["X", "X", "Z"]\n',
    )
    invalid = runner.invoke(config_command, ["validate", str(bad)])
    assert invalid.exit_code == 1
    assert invalid.stdout == ""
    lines = invalid.stderr.splitlines()
    assert (
        f"{tmp_path / 'x.lis'}:2: kenngr.coll_ofset: unknown parameter (did you mean kenngr.coll_offset?)"
        in lines
    )
    assert any(line.startswith(f"{bad}:6: channels[0].main_axes:") for line in lines)
    # the findings, the note that the machine-wide checks follow, and the count of the findings
    assert lines[-2] == LATER_CHECKS_NOTE
    assert lines[-1] == f"{len(lines) - 2} errors: configuration is invalid"

    missing = runner.invoke(config_command, ["validate", str(tmp_path / "nope.toml")])
    assert missing.exit_code == 2
    assert "machine file not found" in missing.stderr

    directory = runner.invoke(config_command, ["validate", str(tmp_path)])
    assert directory.exit_code == 2


@pytest.mark.req("E-07")
def test_cli_show_prints_the_effective_configuration_as_json(tmp_path: Path) -> None:
    runner = CliRunner()
    demo = runner.invoke(config_command, ["show"])
    assert demo.exit_code == 0, demo.output
    data = json.loads(demo.stdout)
    assert MachineConfig.model_validate(data) == load_machine(None)
    x2 = next(a for a in data["axes"] if a["name"] == "X2")
    assert x2["coll_offset"] == 200000  # from demo_x2.lis

    write(tmp_path, "x.lis", "kenngr.swe_pos 42\n")
    path = write(
        tmp_path,
        "m.toml",
        '[[axes]]\nnumber = 1\nname = "X"\nparameter_list = "x.lis"\n[[channels]]\naxes = ["X"]\n'
        'main_axes = ["X", "X", "X"]\n',
    )
    failing = runner.invoke(config_command, ["show", str(path)])
    assert failing.exit_code == 1
    path.write_text(path.read_text().replace('main_axes = ["X", "X", "X"]\n', ""))
    path.write_text(path.read_text().replace('axes = ["X"]', 'axes = ["X", "Y", "Z"]'))
    path.write_text(path.read_text() + '[[axes]]\nnumber = 2\nname = "Y"\n[[axes]]\nnumber = 3\nname = "Z"\n')
    shown = runner.invoke(config_command, ["show", str(path)])
    assert shown.exit_code == 0, shown.output
    assert json.loads(shown.stdout)["axes"][0]["swe_pos"] == 42


# --------------------------------------------------------------------------------------------------
# the documentation


def _generated_section(doc: str) -> str:
    match = re.search(
        r"<!-- BEGIN GENERATED: parameter table -->\n(.*)<!-- END GENERATED: parameter table -->", doc, re.S
    )
    assert match, "docs/configuration.md lost its generated parameter table markers"
    return match[1]


@pytest.mark.req("E-07")
def test_docs_parameter_table_is_current_and_complete() -> None:
    doc = DOCS.read_text(encoding="utf-8")
    assert _generated_section(doc) == parameter_table_markdown(), (
        "docs/configuration.md is out of date: paste the output of `hli-server config parameters` "
        "between the GENERATED markers"
    )
    for info in (*AXIS_PARAMETERS, *CHANNEL_PARAMETERS, *MANUAL_PARAMETERS):
        if info.path is not None:
            assert f"`{info.path.replace('[0]', '[i]')}`" in doc
        assert f"`{info.field}`" in doc
        if info.pid:
            assert info.pid in doc
            # issue 21: every kernel parameter names the page (or document section) it comes from
            assert info.page, f"{info.pid} has no kernel page"
            assert (f"[page]({info.page})" if info.page.startswith("https://") else info.page) in doc
    runner = CliRunner()
    printed = runner.invoke(config_command, ["parameters"])
    assert printed.exit_code == 0
    assert printed.stdout == parameter_table_markdown()


@pytest.mark.req("E-07")
def test_docs_full_example_loads(tmp_path: Path) -> None:
    doc = DOCS.read_text(encoding="utf-8")
    example = re.search(r"```toml\n(.*?)```", doc, re.S)
    assert example
    path = tmp_path / "machine.toml"
    path.write_text(example[1], encoding="utf-8")
    machine = load_machine(path)
    assert [a.name for a in machine.axes] == ["X", "Y", "Z", "X1", "X2", "Z1"]
    assert machine.channels[0].dyn_pos_limit_enabled
    assert machine.channels[0].zero_offsets[0].offsets["X"] == 1_000_000
    assert [(m.name, p.name) for m, p in machine.collision_pairs()] == [("X2", "X1")]


@pytest.mark.req("E-07", "C3-04")
def test_machine_wide_checks_follow_once_single_values_are_fixed(tmp_path: Path) -> None:
    """pydantic checks across the machine only when every value is valid: the user is told so."""
    machines = resources.files("hli_server.machines")
    for entry in machines.iterdir():
        if entry.name.endswith((".lis", ".toml")):
            (tmp_path / entry.name).write_text(entry.read_text(encoding="utf-8"), encoding="utf-8")
    x1 = tmp_path / "demo_x1.lis"
    x1.write_text(re.sub(r"kenngr\.achs_mode\s+\S+", "kenngr.achs_mode 0x0001", x1.read_text()))
    machine = tmp_path / "demo.toml"
    text = machine.read_text()
    machine.write_text(text.replace("swe_neg = -2_000_000", "swe_neg = 2_000_000", 1))
    with pytest.raises(ConfigError) as first:
        load_machine(machine)
    assert [m for m in first.value.messages if "swe_neg" in m]
    assert not [m for m in first.value.messages if "0x8000" in m]
    assert first.value.notes == [LATER_CHECKS_NOTE]
    machine.write_text(text)
    with pytest.raises(ConfigError) as second:
        load_machine(machine)
    (message,) = second.value.messages
    assert "demo_x1.lis" in message
    assert "0x8000" in message
    assert second.value.notes == []


# The kernel's defaults, as its parameter pages give them (issue 21, B-04). Each line was read on the
# page that ParameterInfo.page links (docs/configuration.md, column "kernel"); the function
# descriptions' parameter sections (FCT-C3 4.2, FCT-C14 6.2, FCT-C43 3, FCT-A3 3.2) say the same.
KERNEL_DEFAULTS: dict[str, object] = {
    "P-AXIS-00003": 0,  # a_emergency; 0: a_max is used
    "P-AXIS-00008": 1000,
    "P-AXIS-00015": 0x00000001,
    "P-AXIS-00195": 50_000,  # ramp times of the non-linear slopes (their pages, 117617803 ...)
    "P-AXIS-00196": 50_000,
    "P-AXIS-00197": 50_000,
    "P-AXIS-00198": 50_000,
    "P-CHAN-00071": 0,  # STEP
    "P-AXIS-00043": 0,
    "P-AXIS-00044": 0,
    "P-AXIS-00045": 0,
    "P-AXIS-00114": 0,
    "P-AXIS-00118": 0,
    "P-AXIS-00137": -1_000_000,
    "P-AXIS-00138": 1_000_000,
    "P-AXIS-00151": 1_000_000,
    "P-AXIS-00177": -100_000_000,
    "P-AXIS-00178": 100_000_000,
    "P-AXIS-00179": 1000,
    "P-AXIS-00215": 16666,
    "P-AXIS-00236": 500,
    "P-AXIS-00262": 0,
    "P-AXIS-00263": 0,
    "P-AXIS-00267": 0,
    "P-AXIS-00492": 0,
    "P-AXIS-00493": 0,
    "P-AXIS-00532": -1,
    "P-CHAN-00114": 0,
    "P-CHAN-00120": 0,
    # g80_prog_file .. g89_prog_file, g800_prog_file[i]: "Default value *", "the default value of the variable
    # is an empty string" (tf5200_channel_parameter 149417611, 149419147)
    **{f"P-CHAN-0016{k}": "" for k in range(10)},
    "P-CHAN-00187": [],
    "P-CHAN-00176": 0,
    "P-CHAN-00268": 0,
    "P-CHAN-00442": 0,
    "P-CHAN-00751": 0,
    "P-CHAN-00874": 0,
    "P-CHAN-00099": 0.0,
    "P-CHAN-00032": 0,  # kinematik_id (issue 35: the trafo interface page, "Default value 0")
    "P-CHAN-00095": 0,
    "P-CHAN-00188": 0,
    "P-CHAN-00189": 0,
    "P-STUP-00070": ["FCT_IPO_DEFAULT"],
    "P-MANU-00014": 0,
}


@pytest.mark.req("E-07", "B-04")
def test_every_parameter_default_is_the_kernels_or_says_why_not() -> None:
    """Each parameter with a P-ID defaults to the value its kernel page gives; where it does not (or the
    page gives none), its ParameterInfo.note says why, and docs/configuration.md shows the note."""
    models = (
        (AXIS_PARAMETERS, AxisConfig),
        (CHANNEL_PARAMETERS, ChannelConfig),
        (MANUAL_PARAMETERS, ManualConfig),
    )
    seen = set()
    for table, model in models:
        for info in table:
            if info.pid is None:
                continue
            seen.add(info.pid)
            ours = model.model_fields[info.field].get_default(call_default_factory=True)
            if info.pid not in KERNEL_DEFAULTS:
                assert info.note, f"{info.pid}: no kernel default known and no note why ours is {ours!r}"
                continue
            expected = KERNEL_DEFAULTS[info.pid]
            if isinstance(ours, list):
                ours = [str(v.value) if hasattr(v, "value") else v for v in ours]
            assert ours == expected, f"{info.pid} {info.field}: default {ours!r}, the kernel's {expected!r}"
    assert set(KERNEL_DEFAULTS) <= seen


@pytest.mark.req("E-07", "B-04")
def test_p_axis_00151_has_the_kernels_path_and_the_old_one_still_reads() -> None:
    """P-AXIS-00151's path is ``getriebe[i].pos_einschw_zeit`` (its page, https://infosys.beckhoff.com/
    content/1033/tf5200_axis_parameter/117751051.html); this project once read it as
    ``getriebe[i].settling_time``: a list that still says so is read, with a warning."""
    from hli_server.configuration.parameter_lists import parse_parameter_list

    new = parse_parameter_list("getriebe[0].pos_einschw_zeit 250000\n", "axis", source="x.lis")
    assert (new.values, new.warnings, new.errors) == ({"settling_time_legacy_us": 250_000}, [], [])
    old = parse_parameter_list("getriebe[2].settling_time 250000\n", "axis", source="x.lis")
    assert old.values == {"settling_time_legacy_us": 250_000}
    assert old.errors == []
    assert any(
        "getriebe[2].settling_time is this project's old name; "
        "the kernel's path is getriebe[2].pos_einschw_zeit" in w
        for w in old.warnings
    )
