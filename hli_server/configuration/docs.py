"""The one-line machine summary and the parameter table of docs/configuration.md."""

from __future__ import annotations

import re
from enum import Enum

from pydantic import BaseModel
from pydantic.fields import FieldInfo

from hli_server.configuration.fields import _range_text
from hli_server.configuration.tables import _PARAMETERS_OF_MODEL
from schemas.config import (
    EXTERNAL_ELEMENT_PARAMETERS,
    EXTERNAL_STRUCTURE_PARAMETERS,
    EXTERNAL_VARIABLE_PARAMETERS,
    KINEMATIC_AXIS_PARAMETERS,
    KINEMATIC_PARAMETERS,
    MACHINE_EXTERNAL_PARAMETERS,
    TOOL_PARAMETERS,
    AdapterEntry,
    AxisConfig,
    ChannelConfig,
    DriveModel,
    ExternalElementConfig,
    ExternalStructureConfig,
    ExternalVariableConfig,
    KinematicAxis,
    KinematicEntry,
    MachineConfig,
    ManualConfig,
    ParameterInfo,
    ProbeConfig,
    ProgramEntry,
    ToolEntry,
    ZeroOffset,
)
from schemas.units import mm_from_increments


def machine_summary(config: MachineConfig) -> str:
    """One line about the machine, for ``hli-server config validate``."""
    channels = "; ".join(f"channel {ch.number} {ch.name!r}: {' '.join(ch.axes)}" for ch in config.channels)
    pairs = config.collision_pairs()
    pair_text = ", ".join(
        f"{m.name}-{p.name} {mm_from_increments(max(m.coll_offset, p.coll_offset)):g} mm" for m, p in pairs
    )
    return (
        f"machine {config.name!r}, cycle {config.cycle_time_us} µs, "
        f"{_count(len(config.axes), 'axis', 'axes')}, "
        f"{_count(len(config.channels), 'channel', 'channels')} ({channels}), "
        f"{_count(len(pairs), 'collision pair', 'collision pairs')}" + (f" ({pair_text})" if pairs else "")
    )


def _count(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"


_SECTIONS: tuple[tuple[str, type[BaseModel], frozenset[str]], ...] = (
    ("Machine (top level)", MachineConfig, frozenset({"axes", "channels", "manual", "adapters"})),
    ("Axis `[[axes]]`", AxisConfig, frozenset({"drive"})),
    ("Drive model `[axes.drive]` (project's own, E-02)", DriveModel, frozenset()),
    (
        "Channel `[[channels]]`",
        ChannelConfig,
        frozenset({"zero_offsets", "tools", "programs", "kinematics", "probe"}),
    ),
    ("Simulated touch probe `[channels.probe]` (project's own; docs/cycles.md)", ProbeConfig, frozenset()),
    ("Zero offsets `[[channels.zero_offsets]]`", ZeroOffset, frozenset()),
    (
        "Kinematic data sets `[[channels.kinematics]]` (trafo[j], K-01, [kinematics.md](kinematics.md))",
        KinematicEntry,
        frozenset({"axes"}),
    ),
    (
        "Universal Kinematics axes `axes = [{...}]` of a data set (P-CHAN-00291..00293)",
        KinematicAxis,
        frozenset(),
    ),
    ("Tool table `[[channels.tools]]` (D blocks, M-14)", ToolEntry, frozenset()),
    ("Programs `[[channels.programs]]` (project's own program table)", ProgramEntry, frozenset()),
    ("Manual mode `[manual]`", ManualConfig, frozenset()),
    ("Adapters `[[adapters]]` (project's own; `hli-server run`)", AdapterEntry, frozenset()),
    ("V.E. variables `[[external_variables]]` (N-05)", ExternalVariableConfig, frozenset()),
    ("V.E. structures `[[external_structures]]` (N-05)", ExternalStructureConfig, frozenset()),
    ("Elements of a V.E. structure `elements = [{...}]` (N-05)", ExternalElementConfig, frozenset()),
)
_LIST_PATHS: dict[type[BaseModel], tuple[ParameterInfo, ...]] = {
    ExternalVariableConfig: EXTERNAL_VARIABLE_PARAMETERS,
    ExternalStructureConfig: EXTERNAL_STRUCTURE_PARAMETERS,
    ExternalElementConfig: EXTERNAL_ELEMENT_PARAMETERS,
    MachineConfig: MACHINE_EXTERNAL_PARAMETERS,
    KinematicEntry: KINEMATIC_PARAMETERS,
    KinematicAxis: KINEMATIC_AXIS_PARAMETERS,
    ToolEntry: TOOL_PARAMETERS,
}
"""Fields that come from a list of their own (not a parameter list of the table's kind)."""

_RANGE_NOTES: dict[tuple[type[BaseModel], str], str] = {
    (ExternalVariableConfig, "name"): "`[A-Za-z_][A-Za-z0-9_]{0,19}`, unique in its area (any case)",
    (ExternalVariableConfig, "type"): "BOOLEAN, SGN08, UNS08, SGN16, UNS16, SGN32, UNS32, REAL32, REAL64, "
    "STRING, VSTRING, or the name of an `[[external_structures]]`",
    (ExternalVariableConfig, "dims"): "at most 4 dimensions of 1..65535; all V.E. elements fit the Modbus "
    "area 1200..1899",
    (ExternalVariableConfig, "size"): "VSTRING only: 1 ≤ value ≤ 800 (the NUL included)",
    (ExternalVariableConfig, "access_rights"): "READ_WRITE, READ_ONLY, WRITE_ONLY",
    (ExternalStructureConfig, "name"): "`[A-Za-z_][A-Za-z0-9_]{0,31}`, unique (any case), no kernel type's",
    (ExternalStructureConfig, "elements"): "1 to 256 elements, unique names (any case); no structure "
    "containing itself, nested at most 8 deep",
    (ExternalElementConfig, "name"): "`[A-Za-z_][A-Za-z0-9_]{0,19}`",
    (ExternalElementConfig, "type"): "as a variable's `type`",
    (ExternalElementConfig, "dims"): "at most 4 dimensions of 1..65535",
    (ExternalElementConfig, "size"): "VSTRING only: 1 ≤ value ≤ 800 (the NUL included)",
    (ExternalElementConfig, "synchronous"): "0/1; none: the variable's",
    (ExternalElementConfig, "access_rights"): "READ_WRITE, READ_ONLY, WRITE_ONLY; none: the variable's",
    (AxisConfig, "name"): "`[A-Z][A-Z0-9]{0,7}`, unique",
    (AxisConfig, "number"): "1 ≤ value ≤ MAX(UNS32), unique",
    (AxisConfig, "axis_type"): "T or R",
    (AxisConfig, "swe_neg"): "MIN(SGN32) < value < swe_pos",
    (AxisConfig, "swe_pos"): "swe_neg < value < MAX(SGN32)",
    (AxisConfig, "coll_check_ax_nr"): "0 (none) or 1 ≤ value < MAX(UNS32): a logical axis number; "
    "both axes need bit 0x8000 in achs_mode",
    (AxisConfig, "coll_offset"): "0 (none) or 1 < value < MAX(UNS32)",
    (AxisConfig, "achs_mode"): "0x00000001 ≤ value ≤ 0x10000000; bit 0x8000: collision monitoring",
    (AxisConfig, "a_emergency"): "0 (a_max applies) or 1 ≤ value ≤ 2*a_max",
    (AxisConfig, "acs_limit_neg"): "swe_neg ≤ value ≤ swe_pos, less than acs_limit_pos; both 0: off",
    (AxisConfig, "acs_limit_pos"): "swe_neg ≤ value ≤ swe_pos, greater than acs_limit_neg; both 0: off",
    (AxisConfig, "vb_messen"): "1 ≤ value ≤ the axis' v_max (P-AXIS-00212)",
    (ChannelConfig, "messtyp"): "1 ≤ value ≤ 7; G100 takes 1..4",
    (ChannelConfig, "axes"): "names of `[[axes]]`; each axis in one channel",
    (ChannelConfig, "main_axes"): "three different axes of the channel",
    **{
        (ChannelConfig, f"g8{k}_prog_file"): f'a file name, at most 83 characters; "": none (G8{k}: 20131)'
        for k in range(10)
    },
    (ChannelConfig, "g800_prog_file"): "up to 40 file names (G800..G839), each at most 83 characters; "
    '"": none',
    (ChannelConfig, "interpolator_function"): "keywords FCT_IPO_DEFAULT, FCT_LOOK_AHEAD_STANDARD, "
    "FCT_DYN_POS_LIMIT; a list or `A | B`",
    (ChannelConfig, "cycle_directories"): "directories (relative to the machine file), at most 64",
    (ProbeConfig, "deviation_variables"): "axis of the channel -> a declared numeric scalar V.E. variable",
    (ZeroOffset, "code"): "G54 … G59, each once per channel",
    (ZeroOffset, "offsets"): "axis name -> offset [0.1 µm], axes of the channel",
    (ProgramEntry, "number"): "1 ≤ value ≤ 65535, unique in the channel",
    (ProgramEntry, "text"): "exactly one of text / path",
    (ProgramEntry, "path"): "exactly one of text / path (relative to the machine file)",
}


def _unit_of(model: type[BaseModel], field_name: str, info: FieldInfo) -> str:
    for pinfo in _PARAMETERS_OF_MODEL.get(model, ()):
        if pinfo.field == field_name:
            return pinfo.unit
    if info.annotation is bool:
        return "0/1"
    match = re.search(r"\[([^\]]+)\]", info.description or "")
    return match[1] if match else "-"


def _default_text(model: type[BaseModel], field_name: str, info: FieldInfo) -> str:
    if info.is_required():
        return "required"
    value = info.get_default(call_default_factory=True)
    if field_name == "achs_mode" and isinstance(value, int):
        return f"0x{value:08X}"
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, Enum):
        return str(value.value)
    if isinstance(value, list | tuple):
        return " | ".join(str(v.value if isinstance(v, Enum) else v) for v in value) or "(none)"
    if isinstance(value, BaseModel):
        return "(table)"
    if value is None:
        return "(none)"
    if value == "":
        return '""'
    return str(value)


def _meaning(info: FieldInfo) -> str:
    text = info.description or ""
    text = re.sub(r"^P-[A-Z]{4}-\d{5}\s*", "", text)
    text = re.sub(r"\s*\[[^\]]+\]", "", text)
    return text.strip() or "-"


def _kernel_column(pinfo: ParameterInfo | None) -> str:
    if pinfo is None or pinfo.pid is None:
        return "-"
    if pinfo.page.startswith("http"):
        return f"[page]({pinfo.page})"
    return pinfo.page or "-"


def parameter_table_markdown() -> str:
    """Every configuration parameter: key, P-ID, ISG path, unit, default, range, the kernel's page
    (docs/configuration.md). The default is the kernel's wherever the row has no note; the notes
    below a section say where and why ours differs (docs/alarms.md)."""
    out: list[str] = []
    for title, model, skip in _SECTIONS:
        known = _PARAMETERS_OF_MODEL.get(model, ()) or _LIST_PATHS.get(model, ())
        paths = {info.field: info for info in known}
        out += [
            f"### {title}",
            "",
            "| TOML key | P-ID | ISG text-list path | unit | default | range | kernel | meaning |",
            "|---|---|---|---|---|---|---|---|",
        ]
        notes: list[str] = []
        for name, info in model.model_fields.items():
            if name in skip:
                continue
            pinfo = paths.get(name)
            pid = (pinfo.pid or "-") if pinfo else "project's own"
            if pinfo is None:
                path = "-"
            elif pinfo.path is None:
                path = "(none known)"
            else:
                path = f"`{pinfo.path.replace('[0]', '[i]')}`"
            if pinfo and name == "channel" and model is ExternalVariableConfig:
                path += " (CHANNEL: the list's channel; GLOBAL: none)"
            range_text = _RANGE_NOTES.get((model, name)) or _range_text(model, name) or "-"
            if info.annotation is bool:
                range_text = "0/1"
            default = _default_text(model, name, info)
            if pinfo is not None and pinfo.note:
                default += " (note)"
                notes.append(f"* `{name}` ({pinfo.pid}): {pinfo.note}.")
            cells = (
                f"`{name}`",
                pid,
                path,
                _unit_of(model, name, info),
                default,
                range_text,
                _kernel_column(pinfo),
                _meaning(info),
            )
            out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        out.append("")
        if notes:
            out += ["Where this differs from the kernel's page:", "", *notes, ""]
    return "\n".join(out)
