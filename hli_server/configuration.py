"""Loading the machine configuration: a TOML machine file plus ISG text parameter lists (E-07).

The models and their ranges live in :mod:`schemas.config` (the contract); this module does the I/O:

* :func:`load_machine` reads a machine file (TOML, see ``docs/configuration.md``) or, given ``None``,
  the built-in demo machine ``hli_server/machines/demo.toml``.
* A ``[[axes]]``, ``[[channels]]`` or ``[manual]`` table may name an ISG text parameter list
  (``parameter_list = "x2.lis"``, relative to the machine file) in the form the documents show
  (FCT-C3 section 3, FCT-A3 section 3, FCT-C43 section 3, FCT-C14 section 6)::

      kopf.achs_nr        2
      kenngr.achs_mode    0x8001        # collision monitoring on (FCT-C3)
      getriebe[0].window  500
      configuration.channel[0].interpolator.function FCT_LOOK_AHEAD_STANDARD | FCT_DYN_POS_LIMIT

  Its values override or complete the table's. The paths map to fields through
  :data:`schemas.config.AXIS_PARAMETERS`, :data:`~schemas.config.CHANNEL_PARAMETERS` and
  :data:`~schemas.config.MANUAL_PARAMETERS`.

Every error names file, line and key (``x2.lis:7: kenngr.coll_ofset: unknown parameter (did you mean
kenngr.coll_offset?)``); unknown keys are errors, never dropped; all errors of a file are collected
and raised together as :class:`ConfigError`.
"""

from __future__ import annotations

import difflib
import logging
import re
import tomllib
import types
import typing
from dataclasses import dataclass, field
from enum import Enum
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import annotated_types
from pydantic import BaseModel, ConfigDict, TypeAdapter, ValidationError
from pydantic.fields import FieldInfo

from schemas.config import (
    AXIS_PARAMETERS,
    CHANNEL_PARAMETERS,
    MANUAL_PARAMETERS,
    AdapterEntry,
    AxisConfig,
    ChannelConfig,
    DriveModel,
    MachineConfig,
    ManualConfig,
    ParameterInfo,
    ParameterIssues,
    ProgramEntry,
    ZeroOffset,
)
from schemas.units import DINT_MAX, DINT_MIN, UDINT_MAX, mm_from_increments

__all__ = [
    "ConfigError",
    "ConfigFileError",
    "ListKind",
    "Origin",
    "ParameterList",
    "demo_machine_path",
    "load_machine",
    "load_machine_with_warnings",
    "machine_summary",
    "parameter_table_markdown",
    "parse_parameter_list",
    "read_parameter_list",
]

logger = logging.getLogger(__name__)

ListKind = Literal["axis", "channel", "manual"]
"""Which parameter table a text list is read against."""

Loc = tuple[str | int, ...]
"""A location in the machine data, as pydantic names it: ``("axes", 1, "swe_neg")``."""

_LIST_KEY = "parameter_list"
_TABLES: dict[str, tuple[tuple[ParameterInfo, ...], type[BaseModel]]] = {
    "axis": (AXIS_PARAMETERS, AxisConfig),
    "channel": (CHANNEL_PARAMETERS, ChannelConfig),
    "manual": (MANUAL_PARAMETERS, ManualConfig),
}
_PARAMETERS_OF_MODEL: dict[type[BaseModel], tuple[ParameterInfo, ...]] = {
    AxisConfig: AXIS_PARAMETERS,
    ChannelConfig: CHANNEL_PARAMETERS,
    ManualConfig: MANUAL_PARAMETERS,
}
_KIND_NAMES = {
    "axis": "an axis parameter",
    "channel": "a channel parameter",
    "manual": "a manual-mode parameter",
}
_GEAR_KEY = re.compile(r"^getriebe\[(\d+)\]\.(.+)$")
_CHANNEL_KEY = re.compile(r"^configuration\.channel\[(\d+)\]\.(.+)$")
_INTEGER = re.compile(r"^([+-]?)(?:0[xX]([0-9a-fA-F]+)|([0-9]+))$")
_RANGE_ERRORS = {"greater_than", "greater_than_equal", "less_than", "less_than_equal"}


# --------------------------------------------------------------------------------------------------
# errors and origins


class ConfigError(Exception):
    """The configuration is invalid; ``messages`` holds every finding as ``file:line: key: text``,
    ``notes`` what the user should know besides (printed after them, not counted)."""

    def __init__(self, messages: list[str], notes: list[str] | None = None) -> None:
        self.messages = list(messages)
        self.notes = list(notes or [])
        super().__init__("\n".join([*self.messages, *self.notes]))


class ConfigFileError(ConfigError):
    """The machine file itself is missing or cannot be read (the CLI exits with 2)."""


@dataclass(frozen=True, slots=True)
class Origin:
    """Where a value was set: file, line and the key as written there."""

    file: str
    line: int
    key: str

    def where(self) -> str:
        return f"{self.file}:{self.line}: {self.key}" if self.key else f"{self.file}:{self.line}"


# --------------------------------------------------------------------------------------------------
# ISG text parameter lists


@dataclass
class ParameterList:
    """One text parameter list, read against one parameter table (E-07)."""

    source: str
    values: dict[str, Any] = field(default_factory=dict)
    """field name -> value (already converted and range-checked field by field)."""
    origins: dict[str, Origin] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    failed: set[str] = field(default_factory=set)
    """Fields whose entry was given but could not be used (already reported in ``errors``)."""


def read_parameter_list(path: Path, kind: ListKind, *, channel_index: int | None = None) -> ParameterList:
    """Read an ISG text parameter list from ``path``; ``OSError`` and ``UnicodeDecodeError`` propagate."""
    return parse_parameter_list(
        path.read_text(encoding="utf-8"), kind, source=str(path), channel_index=channel_index
    )


def parse_parameter_list(
    text: str, kind: ListKind, *, source: str = "<list>", channel_index: int | None = None
) -> ParameterList:
    """Parse an ISG text parameter list (E-07; the form of FCT-C3 section 3, FCT-C43 section 3).

    One ``path value`` per line; ``#`` starts a comment (also after a value); blank lines are
    skipped. Numbers are decimal or ``0x`` hex, negative allowed; booleans ``0``/``1``. A value that
    ends in ``|`` continues on the next line (P-STUP-00070 keyword lists wrap so in the documents).

    ``getriebe[i].x`` maps to the same field for every gear stage ``i``: only gear stage 0 is
    simulated. A value given for a stage ``i != 0`` is range-checked; it is used only when the list
    has no stage-0 entry for that parameter, and a warning says so either way.

    ``configuration.channel[i].…`` (P-STUP-00070) must use the list's own channel index when
    ``channel_index`` is given (channel number - 1).
    """
    table, model = _TABLES[kind]
    by_path = {info.path: info for info in table}
    result = ParameterList(source=source)
    seen: dict[str, int] = {}
    gear_values: dict[str, list[tuple[int, Any, Origin]]] = {}
    lines = text.splitlines()
    index = 0
    while index < len(lines):
        line_no = index + 1
        content = _strip_comment(lines[index]).strip()
        index += 1
        if not content:
            continue
        while content.endswith("|") and index < len(lines):
            content = f"{content} {_strip_comment(lines[index]).strip()}"
            index += 1
        key, *rest = content.split(None, 1)
        raw = rest[0].strip() if rest else ""
        origin = Origin(source, line_no, key)
        canonical, gear, problem = _canonical_path(key, channel_index)
        if problem:
            result.errors.append(f"{origin.where()}: {problem}")
            continue
        info = by_path.get(canonical)
        if info is None:
            result.errors.append(f"{origin.where()}: {_unknown_parameter(canonical, gear, kind)}")
            continue
        if key in seen:
            result.errors.append(f"{origin.where()}: given twice (first in line {seen[key]})")
            continue
        seen[key] = line_no
        if not raw:
            result.errors.append(f"{origin.where()}: no value (write `{key} <value>`)")
            result.failed.add(info.field)
            continue
        value, problem = _convert(raw, model.model_fields[info.field].annotation)
        if problem is None:
            problem = _check_field(model, info.field, value, raw)
        if problem is not None:
            result.errors.append(f"{origin.where()}: {problem}")
            result.failed.add(info.field)
            continue
        if gear is None:
            result.values[info.field] = value
            result.origins[info.field] = origin
        else:
            gear_values.setdefault(info.field, []).append((gear, value, origin))
    for field_name, entries in gear_values.items():
        entries.sort(key=lambda e: e[0])
        used_stage, used_value, used_origin = entries[0]
        result.values[field_name] = used_value
        result.origins[field_name] = used_origin
        for stage, _value, origin in entries:
            if stage == 0:
                continue
            if origin is used_origin:
                result.warnings.append(
                    f"{origin.where()}: only gear stage 0 is simulated; this gear stage {stage} value is "
                    "used for it (the list has no getriebe[0] entry)"
                )
            else:
                result.warnings.append(
                    f"{origin.where()}: only gear stage 0 is simulated; this gear stage {stage} value is "
                    f"not used (getriebe[{used_stage}] gives {used_value})"
                )
    return result


def _strip_comment(line: str) -> str:
    return line.split("#", 1)[0]


def _canonical_path(key: str, channel_index: int | None) -> tuple[str, int | None, str | None]:
    """``getriebe[3].window`` -> (``getriebe[0].window``, 3, None); channel indices are checked."""
    match = _GEAR_KEY.match(key)
    if match:
        return f"getriebe[0].{match[2]}", int(match[1]), None
    match = _CHANNEL_KEY.match(key)
    if match:
        index = int(match[1])
        if channel_index is not None and index != channel_index:
            return (
                key,
                None,
                f"this list belongs to channel {channel_index + 1}: write "
                f"configuration.channel[{channel_index}].{match[2]} (index = channel number - 1)",
            )
        return f"configuration.channel[0].{match[2]}", None, None
    return key, None, None


def _display_path(path: str, gear: int | None = None) -> str:
    if gear is not None and path.startswith("getriebe[0]."):
        return f"getriebe[{gear}]." + path.removeprefix("getriebe[0].")
    return path


def _unknown_parameter(canonical: str, gear: int | None, kind: str) -> str:
    for other_kind, (table, _model) in _TABLES.items():
        if other_kind != kind and any(info.path == canonical for info in table):
            return f"unknown {kind} parameter: {_display_path(canonical, gear)} is {_KIND_NAMES[other_kind]}"
    table, _model = _TABLES[kind]
    close = difflib.get_close_matches(canonical, [info.path for info in table], n=1, cutoff=0.6)
    hint = f" (did you mean {_display_path(close[0], gear)}?)" if close else ""
    return f"unknown parameter{hint}"


def _convert(raw: str, annotation: Any) -> tuple[Any, str | None]:
    """A list value as the field's type: int (decimal/0x hex), bool (0/1), float, str, keywords."""
    if typing.get_origin(annotation) is list:
        parts = [p.strip() for p in raw.split("|")]
        if any(not p for p in parts):
            return None, f"{raw!r}: empty keyword in a `A | B` list"
        return parts, None
    if " " in raw or "\t" in raw:
        return None, f"unexpected text after the value: {raw!r}"
    if annotation is bool:
        lowered = raw.lower()
        if lowered in {"0", "false"}:
            return False, None
        if lowered in {"1", "true"}:
            return True, None
        return None, f"{raw!r} is not a boolean (write 0 or 1)"
    if annotation is int:
        number = _parse_int(raw)
        if number is None:
            return None, f"{raw!r} is not an integer (decimal or 0x hex)"
        return number, None
    if annotation is float:
        number = _parse_int(raw)
        if number is not None:
            return float(number), None
        try:
            return float(raw), None
        except ValueError:
            return None, f"{raw!r} is not a number"
    if len(raw) >= 2 and raw[0] == raw[-1] == '"':
        raw = raw[1:-1]
    return raw, None


def _parse_int(raw: str) -> int | None:
    match = _INTEGER.match(raw)
    if not match:
        return None
    number = int(match[2], 16) if match[2] is not None else int(match[3], 10)
    return -number if match[1] == "-" else number


@cache
def _field_adapter(model: type[BaseModel], field_name: str) -> TypeAdapter[Any]:
    info = model.model_fields[field_name]
    annotated: Any = typing.Annotated[info.annotation, info]
    # the models refuse inf and NaN (schemas.config); a field checked alone must too
    return TypeAdapter(annotated, config=ConfigDict(allow_inf_nan=False))


def _check_field(model: type[BaseModel], field_name: str, value: Any, written: str) -> str | None:
    """Validate one value against its field alone (type and range); ``None`` when it is fine."""
    try:
        _field_adapter(model, field_name).validate_python(value)
    except ValidationError as exc:
        err = exc.errors()[0]
        return _field_problem(model, field_name, err, written)
    return None


# --------------------------------------------------------------------------------------------------
# messages for field errors


def _pid(model: type[BaseModel], field_name: str) -> str | None:
    for info in _PARAMETERS_OF_MODEL.get(model, ()):
        if info.field == field_name:
            return info.pid
    return None


def _bound_text(field_name: str, value: Any) -> str:
    if field_name == "achs_mode" and isinstance(value, int):
        return f"0x{value:08X}"
    names = {DINT_MIN: "MIN(SGN32)", DINT_MAX: "MAX(SGN32)", UDINT_MAX: "MAX(UNS32)"}
    if isinstance(value, int) and not isinstance(value, bool) and value in names:
        return names[value]
    if isinstance(value, float):
        return str(int(value)) if value.is_integer() and abs(value) < 1e15 else f"{value:g}"
    return str(value)


def _range_text(model: type[BaseModel], field_name: str) -> str:
    """The documented range of a field, from its constraints (``0 ≤ value ≤ 2``)."""
    info = model.model_fields[field_name]
    low = high = ""
    for meta in info.metadata:
        if isinstance(meta, annotated_types.Ge):
            low = f"{_bound_text(field_name, meta.ge)} ≤ "
        elif isinstance(meta, annotated_types.Gt):
            low = f"{_bound_text(field_name, meta.gt)} < "
        elif isinstance(meta, annotated_types.Le):
            high = f" ≤ {_bound_text(field_name, meta.le)}"
        elif isinstance(meta, annotated_types.Lt):
            high = f" < {_bound_text(field_name, meta.lt)}"
    if low or high:
        return f"{low}value{high}"
    return ""


def _field_problem(model: type[BaseModel], field_name: str, err: Any, written: Any) -> str:
    pid = _pid(model, field_name)
    label = pid or field_name
    if err["type"] in _RANGE_ERRORS:
        return f"{written} is out of range: {label} allows {_range_text(model, field_name)}"
    if err["type"] == "finite_number":  # inf, nan (TOML and the lists can write them)
        allowed = _range_text(model, field_name) or "a finite number"
        return f"{written} is not a finite number: {label} allows {allowed}"
    msg = str(err["msg"])
    msg = msg[:1].lower() + msg[1:]
    return f"invalid value {written!r}: {msg}" + (f" ({pid})" if pid else "")


# --------------------------------------------------------------------------------------------------
# where a key is in a TOML file


class _TomlLines:
    """Finds the line of a key or table in a TOML text (tomllib keeps no positions).

    Tracks table headers (``[a.b]``, ``[[a]]`` with their array index) and ``key = value`` lines,
    skipping multi-line strings and multi-line arrays/inline tables. Good enough for messages.
    """

    _KEY_PART = re.compile(r"""\s*(?:"((?:[^"\\]|\\.)*)"|'([^']*)'|([A-Za-z0-9_-]+))\s*(?:\.|$)""")

    def __init__(self, text: str) -> None:
        self.lines: dict[Loc, int] = {}
        arrays: dict[tuple[str, ...], int] = {}
        current: Loc = ()
        open_string: str | None = None
        depth = 0
        for number, raw in enumerate(text.splitlines(), 1):
            if open_string is not None or depth > 0:
                open_string, depth = self._scan(raw, open_string, depth)
                continue
            stripped = raw.strip()
            if not stripped or stripped.startswith("#"):
                continue
            if stripped.startswith("[["):
                names = self._split(stripped[2 : stripped.find("]]")])
                key = tuple(names)
                arrays[key] = arrays.get(key, 0) + 1
                for nested in [k for k in arrays if len(k) > len(key) and k[: len(key)] == key]:
                    del arrays[nested]
                current = (*self._resolve(names[:-1], arrays), names[-1], arrays[key] - 1)
                self.lines.setdefault(current[:-1], number)
                self.lines.setdefault(current, number)
            elif stripped.startswith("["):
                names = self._split(stripped[1 : stripped.find("]")])
                current = self._resolve(names, arrays)
                self.lines.setdefault(current, number)
            else:
                key_text, value = self._split_assignment(stripped)
                if key_text is None:
                    continue
                names = self._split(key_text)
                for n in range(1, len(names) + 1):
                    self.lines.setdefault((*current, *names[:n]), number)
                open_string, depth = self._scan(value, None, 0)

    def line_of(self, loc: Loc) -> int:
        for n in range(len(loc), 0, -1):
            line = self.lines.get(loc[:n])
            if line is not None:
                return line
        return 1

    @staticmethod
    def _resolve(names: list[str], arrays: dict[tuple[str, ...], int]) -> Loc:
        path: list[str | int] = []
        for n, name in enumerate(names):
            path.append(name)
            count = arrays.get(tuple(names[: n + 1]))
            if count:
                path.append(count - 1)
        return tuple(path)

    @classmethod
    def _split(cls, key: str) -> list[str]:
        """``a."b.c".d`` -> ``["a", "b.c", "d"]``."""
        return [next(g for g in m.groups() if g is not None) for m in cls._KEY_PART.finditer(key.strip())]

    @staticmethod
    def _split_assignment(line: str) -> tuple[str | None, str]:
        quote: str | None = None
        for n, char in enumerate(line):
            if quote:
                if char == quote:
                    quote = None
            elif char in "\"'":
                quote = char
            elif char == "=":
                return line[:n], line[n + 1 :]
        return None, ""

    @staticmethod
    def _scan(text: str, open_string: str | None, depth: int) -> tuple[str | None, int]:
        n = 0
        while n < len(text):
            if open_string is not None:
                end = text.find(open_string, n)
                if end < 0:
                    return open_string, depth
                n = end + len(open_string)
                open_string = None
                continue
            char = text[n]
            if char == "#":
                break
            if text.startswith('"""', n) or text.startswith("'''", n):
                open_string = text[n : n + 3]
                n += 3
                continue
            if char in "\"'":
                end = n + 1
                while end < len(text) and text[end] != char:
                    end += 2 if char == '"' and text[end] == "\\" else 1
                n = end + 1
                continue
            if char in "[{":
                depth += 1
            elif char in "]}":
                depth -= 1
            n += 1
        return open_string, max(depth, 0)


# --------------------------------------------------------------------------------------------------
# loading a machine


def demo_machine_path() -> Path:
    """The packaged demo machine file (``hli_server/machines/demo.toml``)."""
    root = resources.files("hli_server.machines")
    path = Path(str(root)) / "demo.toml"
    if not path.is_file():
        raise ConfigFileError([f"{path}: the packaged demo machine is missing (broken installation?)"])
    return path


def load_machine(path: Path | None) -> MachineConfig:
    """The machine configuration from ``path``, or the built-in demo machine for ``None`` (E-07).

    Warnings (e.g. a gear stage other than 0 in a list) are logged; :func:`load_machine_with_warnings`
    returns them instead. Raises :class:`ConfigError` (:class:`ConfigFileError` when the file cannot
    be read) with every finding.
    """
    config, warnings = load_machine_with_warnings(path)
    for warning in warnings:
        logger.warning("%s", warning)
    return config


def load_machine_with_warnings(path: Path | None) -> tuple[MachineConfig, list[str]]:
    """As :func:`load_machine`, returning ``(config, warnings)``."""
    if path is None:
        path = demo_machine_path()
    return _Loader(Path(path)).load()


class _Loader:
    def __init__(self, path: Path) -> None:
        self.path = path
        self.display = str(path)
        self.errors: list[str] = []
        self.single_value_errors = False
        self.warnings: list[str] = []
        self.origins: dict[Loc, Origin] = {}
        self.failed: set[Loc] = set()
        self.toml = _TomlLines("")
        self.data: dict[str, Any] = {}
        self.files = [self.display]

    def load(self) -> tuple[MachineConfig, list[str]]:
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise ConfigFileError([f"{self.display}: machine file not found"]) from None
        except IsADirectoryError:
            raise ConfigFileError([f"{self.display}: is a directory, not a machine file"]) from None
        except OSError as exc:
            raise ConfigFileError([f"{self.display}: cannot read the machine file: {exc.strerror}"]) from None
        except UnicodeDecodeError as exc:
            raise ConfigError(
                [f"{self.display}: not UTF-8 text ({exc.reason} at byte {exc.start})"]
            ) from None
        try:
            self.data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            match = re.search(r"\(at line (\d+), column \d+\)", str(exc))
            line = match[1] if match else "1"
            raise ConfigError([f"{self.display}:{line}: TOML syntax error: {exc}"]) from None
        self.toml = _TomlLines(text)
        self._import_lists()
        self._resolve_program_paths()
        config: MachineConfig | None = None
        try:
            config = MachineConfig.model_validate(self.data)
        except ValidationError as exc:
            self._translate(exc)
        if self.errors or config is None:
            notes = []
            if self.single_value_errors:
                notes.append(
                    "note: the checks across the machine (collision pairs, which axes belong to which "
                    "channel) run once the findings above are fixed: validate again then"
                )
            raise ConfigError(sorted(self.errors, key=self._file_order), notes)
        self._machine_warnings(config)
        return config, self.warnings

    def _file_order(self, message: str) -> tuple[int, int]:
        """Messages of the machine file first, then those of each list in the order they are named."""
        for rank, name in enumerate(self.files):
            if message.startswith(f"{name}:"):
                line = message[len(name) + 1 :].split(":", 1)[0]
                return rank, int(line) if line.isdigit() else 0
        return len(self.files), 0

    # -- parameter lists ---------------------------------------------------------------------

    def _import_lists(self) -> None:
        sections: tuple[tuple[str, ListKind], ...] = (("axes", "axis"), ("channels", "channel"))
        for section, kind in sections:
            entries = self.data.get(section)
            if isinstance(entries, list):
                for index, entry in enumerate(entries):
                    if isinstance(entry, dict):
                        self._import_list(entry, (section, index), kind)
        manual = self.data.get("manual")
        if isinstance(manual, dict):
            self._import_list(manual, ("manual",), "manual")

    def _import_list(self, entry: dict[str, Any], loc: Loc, kind: ListKind) -> None:
        if _LIST_KEY not in entry:
            return
        name = entry.pop(_LIST_KEY)
        where = self._origin((*loc, _LIST_KEY)).where()
        if not isinstance(name, str) or not name:
            self.errors.append(f"{where}: expected a file name (relative to the machine file)")
            return
        list_path = self.path.parent / name
        display = str(Path(self.display).parent / name)
        channel_index = None
        if kind == "channel":
            number = entry.get("number", 1)
            channel_index = number - 1 if isinstance(number, int) else None
        try:
            text = list_path.read_text(encoding="utf-8")
        except FileNotFoundError:
            self.errors.append(f"{where}: parameter list {display} not found")
            return
        except OSError as exc:
            self.errors.append(f"{where}: cannot read parameter list {display}: {exc.strerror}")
            return
        except UnicodeDecodeError as exc:
            self.errors.append(f"{where}: parameter list {display} is not UTF-8 text ({exc.reason})")
            return
        self.files.append(display)
        plist = parse_parameter_list(text, kind, source=display, channel_index=channel_index)
        self.errors.extend(plist.errors)
        self.warnings.extend(plist.warnings)
        for field_name, value in plist.values.items():
            entry[field_name] = value
            self.origins[(*loc, field_name)] = plist.origins[field_name]
        self.failed.update((*loc, f) for f in plist.failed)

    def _resolve_program_paths(self) -> None:
        """``[[channels.programs]] path`` is relative to the machine file; the file must exist."""
        channels = self.data.get("channels")
        if not isinstance(channels, list):
            return
        for c_index, channel in enumerate(channels):
            programs = channel.get("programs") if isinstance(channel, dict) else None
            if not isinstance(programs, list):
                continue
            for p_index, program in enumerate(programs):
                if not isinstance(program, dict) or not isinstance(program.get("path"), str):
                    continue
                program_path = self.path.parent / program["path"]
                if not program_path.is_file():
                    where = self._origin(("channels", c_index, "programs", p_index, "path")).where()
                    self.errors.append(f"{where}: program file {program_path} not found")
                program["path"] = str(program_path.resolve())

    # -- locations ---------------------------------------------------------------------------

    def _origin(self, loc: Loc) -> Origin:
        """The list entry that set ``loc`` (or an enclosing field), else the TOML line."""
        for n in range(len(loc), 0, -1):
            origin = self.origins.get(loc[:n])
            if origin is not None:
                return origin
        return Origin(self.display, self.toml.line_of(loc), _dotted(loc))

    def _is_failed(self, loc: Loc) -> bool:
        return any(loc[:n] in self.failed for n in range(1, len(loc) + 1))

    def _index_of(self, section: str, match: str, value: Any, default: Any = None) -> int | None:
        entries = self.data.get(section)
        if not isinstance(entries, list):
            return None
        for index, entry in enumerate(entries):
            if isinstance(entry, dict) and entry.get(match, default) == value:
                return index
        return None

    # -- pydantic errors -> file:line: key: text ---------------------------------------------

    def _translate(self, exc: ValidationError) -> None:
        # an error below the top level means the machine-wide checks (collision pairs, channel
        # axes) did not run: pydantic runs a model's own checks only when all its fields are valid
        self.single_value_errors = any(tuple(err["loc"]) != () for err in exc.errors())
        found: list[tuple[Origin, str]] = []
        for err in exc.errors():
            loc: Loc = tuple(err["loc"])
            error = err.get("ctx", {}).get("error")
            if err["type"] == "value_error" and isinstance(error, ParameterIssues):
                for issue in error.issues:
                    target = loc
                    if issue.axis is not None:
                        index = self._index_of("axes", "name", issue.axis)
                        target = ("axes", index) if index is not None else loc
                    elif issue.channel is not None:
                        index = self._index_of("channels", "number", issue.channel, default=1)
                        target = ("channels", index) if index is not None else loc
                    if issue.field is not None:
                        target = (*target, issue.field)
                    found.append((self._origin(target), issue.message))
                continue
            if self._is_failed(loc):
                continue
            found.append((self._origin(loc), self._message(loc, err)))
        for origin, message in found:
            self.errors.append(f"{origin.where()}: {message}")

    def _message(self, loc: Loc, err: Any) -> str:
        model, field_name = _field_at(loc)
        context = self._context(loc)
        if err["type"] == "extra_forbidden":
            return context + _unknown_key(model, str(loc[-1]), list_allowed=model in _PARAMETERS_OF_MODEL)
        if err["type"] == "missing":
            hint = ""
            if model is AxisConfig and field_name == "number":
                hint = " (give `number` here or kopf.achs_nr in the axis' parameter list)"
            elif model is AxisConfig and field_name == "name":
                hint = " (give `name` here or kopf.achs_name in the axis' parameter list)"
            return f"{context}required, not given{hint}"
        if err["type"] == "value_error":
            return context + str(err["msg"]).removeprefix("Value error, ")
        if field_name is None:
            return context + str(err["msg"])
        written = self._written(loc, err.get("input"))
        return context + _field_problem(model, field_name, err, written)

    def _written(self, loc: Loc, value: Any) -> Any:
        if loc and loc[-1] == "achs_mode" and isinstance(value, int):
            return f"0x{value:X}"
        return value

    def _context(self, loc: Loc) -> str:
        if len(loc) >= 2 and loc[0] == "axes" and isinstance(loc[1], int):
            entries = self.data.get("axes")
            if isinstance(entries, list) and isinstance(entries[loc[1]], dict):
                name = entries[loc[1]].get("name")
                if isinstance(name, str):
                    return f"axis {name}: "
        if len(loc) >= 2 and loc[0] == "channels" and isinstance(loc[1], int):
            entries = self.data.get("channels")
            if isinstance(entries, list) and isinstance(entries[loc[1]], dict):
                return f"channel {entries[loc[1]].get('number', 1)}: "
        return ""

    # -- warnings ----------------------------------------------------------------------------

    def _axis_origin(self, config: MachineConfig, axis: AxisConfig, field_name: str) -> str:
        index = next(i for i, a in enumerate(config.axes) if a is axis)
        return self._origin(("axes", index, field_name)).where()

    def _machine_warnings(self, config: MachineConfig) -> None:
        """Findings that are allowed but probably not meant (E-07; FCT-C3 section 2, FCT-A3 section 2)."""
        in_pair: set[str] = set()
        for master, partner in config.collision_pairs():
            in_pair.update((master.name, partner.name))
            if (
                partner.coll_check_ax_nr == master.number
                and master.coll_offset != partner.coll_offset
                and min(master.coll_offset, partner.coll_offset) > 1
            ):
                larger = max(master.coll_offset, partner.coll_offset)
                self.warnings.append(
                    f"{self._axis_origin(config, master, 'coll_offset')}: axes {master.name}/{partner.name} "
                    "name each other (older two-sided configuration) with different P-AXIS-00045 "
                    f"coll_offset ({master.coll_offset}, {partner.coll_offset}): the larger ({larger}) "
                    "applies and the engine raises warning 70162"
                )
        for axis in config.axes:
            if axis.collision_monitoring and axis.name not in in_pair:
                self.warnings.append(
                    f"{self._axis_origin(config, axis, 'achs_mode')}: axis {axis.name} has bit 0x8000 "
                    "(collision monitoring) in P-AXIS-00015 but no axis names it in P-AXIS-00043 "
                    "coll_check_ax_nr and it names none: nothing is monitored"
                )
            if axis.window < 3 * axis.drive.standstill_noise:
                self.warnings.append(
                    f"{self._axis_origin(config, axis, 'window')}: axis {axis.name}: P-AXIS-00236 window "
                    f"({axis.window}) is less than 3 x the standstill noise ({axis.drive.standstill_noise}); "
                    "FCT-A3 recommends window >= 3 x the standstill following error"
                )
        owned = {name for ch in config.channels for name in ch.axes}
        for axis in config.axes:
            if axis.name not in owned:
                self.warnings.append(
                    f"{self._axis_origin(config, axis, 'name')}: axis {axis.name} belongs to no channel "
                    "and cannot be moved"
                )


def _dotted(loc: Loc) -> str:
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else part)
    return text


def _submodel(annotation: Any) -> type[BaseModel] | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    origin = typing.get_origin(annotation)
    if origin in (list, tuple, dict, typing.Union, types.UnionType):
        for arg in typing.get_args(annotation):
            sub = _submodel(arg)
            if sub is not None:
                return sub
    return None


def _field_at(loc: Loc) -> tuple[type[BaseModel], str | None]:
    """The model and field a pydantic location points at (``("axes", 0, "drive", "kv")``)."""
    model: type[BaseModel] = MachineConfig
    field_name: str | None = None
    n = 0
    while n < len(loc):
        part = loc[n]
        if not isinstance(part, str) or part not in model.model_fields:
            return model, None
        field_name = part
        n += 1
        sub = _submodel(model.model_fields[part].annotation)
        if sub is None:
            break
        if n < len(loc) and isinstance(loc[n], int):
            n += 1
        if n < len(loc):
            model, field_name = sub, None
    return model, field_name


_TOML_NAME_OF_PATH: dict[str, str] = {
    info.path.rsplit(".", 1)[-1]: info.field
    for table in (AXIS_PARAMETERS, CHANNEL_PARAMETERS, MANUAL_PARAMETERS)
    for info in table
    if info.path.rsplit(".", 1)[-1] != info.field
}


def _unknown_key(model: type[BaseModel], key: str, *, list_allowed: bool) -> str:
    """``unknown key (did you mean swe_neg?)``, with a hint for ISG paths written into TOML."""
    candidates = list(model.model_fields)
    if list_allowed:
        candidates.append(_LIST_KEY)
    for table in _TABLES.values():
        for info in table[0]:
            if key in {info.path, _display_path(info.path, 0).replace("[0]", "[i]")}:
                return (
                    f"unknown key: {key} is an ISG text-list path; in the machine file write "
                    f"`{info.field} = ...`, or put the line in a parameter list"
                )
    last = key.rsplit(".", 1)[-1]
    if last in _TOML_NAME_OF_PATH and _TOML_NAME_OF_PATH[last] in model.model_fields:
        return f"unknown key (the documents' {last} is called {_TOML_NAME_OF_PATH[last]} here)"
    close = difflib.get_close_matches(key, candidates, n=1, cutoff=0.6)
    if close:
        return f"unknown key (did you mean {close[0]}?)"
    return f"unknown key (allowed here: {', '.join(sorted(candidates))})"


# --------------------------------------------------------------------------------------------------
# summary and the parameter table for the docs


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
    ("Channel `[[channels]]`", ChannelConfig, frozenset({"zero_offsets", "programs"})),
    ("Zero offsets `[[channels.zero_offsets]]`", ZeroOffset, frozenset()),
    ("Programs `[[channels.programs]]` (project's own program table)", ProgramEntry, frozenset()),
    ("Manual mode `[manual]`", ManualConfig, frozenset()),
    ("Adapters `[[adapters]]` (project's own; `hli-server run`)", AdapterEntry, frozenset()),
)

_RANGE_NOTES: dict[tuple[type[BaseModel], str], str] = {
    (AxisConfig, "name"): "`[A-Z][A-Z0-9]{0,7}`, unique",
    (AxisConfig, "number"): "1 ≤ value ≤ MAX(UNS32), unique",
    (AxisConfig, "axis_type"): "T or R",
    (AxisConfig, "swe_neg"): "MIN(SGN32) < value < swe_pos",
    (AxisConfig, "swe_pos"): "swe_neg < value < MAX(SGN32)",
    (AxisConfig, "coll_check_ax_nr"): "0 (none) or 1 ≤ value < MAX(UNS32): a logical axis number; "
    "both axes need bit 0x8000 in achs_mode",
    (AxisConfig, "coll_offset"): "0 (none) or 1 < value < MAX(UNS32)",
    (AxisConfig, "achs_mode"): "0x00000001 ≤ value ≤ 0x10000000; bit 0x8000: collision monitoring",
    (ChannelConfig, "axes"): "names of `[[axes]]`; each axis in one channel",
    (ChannelConfig, "main_axes"): "three different axes of the channel",
    (ChannelConfig, "interpolator_function"): "keywords FCT_IPO_DEFAULT, FCT_LOOK_AHEAD_STANDARD, "
    "FCT_DYN_POS_LIMIT; a list or `A | B`",
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
    return str(value)


def _meaning(info: FieldInfo) -> str:
    text = info.description or ""
    text = re.sub(r"^P-[A-Z]{4}-\d{5}\s*", "", text)
    text = re.sub(r"\s*\[[^\]]+\]", "", text)
    return text.strip() or "-"


def parameter_table_markdown() -> str:
    """Every configuration parameter: key, P-ID, ISG path, unit, default, range (docs/configuration.md)."""
    out: list[str] = []
    for title, model, skip in _SECTIONS:
        paths = {info.field: info for info in _PARAMETERS_OF_MODEL.get(model, ())}
        out += [
            f"### {title}",
            "",
            "| TOML key | P-ID | ISG text-list path | unit | default | range | meaning |",
            "|---|---|---|---|---|---|---|",
        ]
        for name, info in model.model_fields.items():
            if name in skip:
                continue
            pinfo = paths.get(name)
            pid = (pinfo.pid or "-") if pinfo else "project's own"
            path = f"`{pinfo.path.replace('[0]', '[i]')}`" if pinfo else "-"
            range_text = _RANGE_NOTES.get((model, name)) or _range_text(model, name) or "-"
            if info.annotation is bool:
                range_text = "0/1"
            cells = (
                f"`{name}`",
                pid,
                path,
                _unit_of(model, name, info),
                _default_text(model, name, info),
                range_text,
                _meaning(info),
            )
            out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        out.append("")
    return "\n".join(out)
