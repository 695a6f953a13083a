"""Loading a machine: the TOML machine file and its parameter lists, every error with file:line:key (E-07)."""

from __future__ import annotations

import difflib
import logging
import re
import tomllib
import types
import typing
from importlib import resources
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from hli_server.configuration.errors import ConfigError, ConfigFileError, Origin
from hli_server.configuration.external_lists import parse_external_list
from hli_server.configuration.fields import _field_problem
from hli_server.configuration.files import find_file
from hli_server.configuration.parameter_lists import _display_path, parse_parameter_list
from hli_server.configuration.tables import _LIST_KEY, _PARAMETERS_OF_MODEL, _TABLES, ListKind, Loc
from hli_server.configuration.toml_lines import _TomlLines
from schemas.config import (
    AXIS_PARAMETERS,
    CHANNEL_PARAMETERS,
    MANUAL_PARAMETERS,
    AxisConfig,
    ChannelConfig,
    MachineConfig,
    ParameterIssues,
)

logger = logging.getLogger(__name__)

_EXTERNAL_LIST_KEY = "external_variables_list"
"""Key of a ``[[channels]]`` table: the kernel's list of external variables (P-STUP-00146 ve_var[i])."""
_MAX_LIST_BYTES = 1_000_000


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
        self._global_from_list: dict[int, str] = {}

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
        self._resolve_program_directories()
        self._resolve_cycle_directories()
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
        channels = self.data.get("channels")
        if isinstance(channels, list):
            for index, entry in enumerate(channels):
                if isinstance(entry, dict) and _EXTERNAL_LIST_KEY in entry:
                    self._import_external_list(entry, index)

    def _import_external_list(self, entry: dict[str, Any], index: int) -> None:
        """``external_variables_list = "ch1_ve.lis"`` (P-STUP-00146 ve_var[i]): the kernel's list of
        external variables, appended to ``external_variables`` (N-05)."""
        name = entry.pop(_EXTERNAL_LIST_KEY)
        where = self._origin(("channels", index, _EXTERNAL_LIST_KEY)).where()
        if not isinstance(name, str) or not name:
            self.errors.append(f"{where}: expected a file name (relative to the machine file)")
            return
        number = entry.get("number", 1)
        if not isinstance(number, int):
            return  # the channel's own error says why
        list_path = self.path.parent / name
        display = str(Path(self.display).parent / name)
        try:
            if list_path.stat().st_size > _MAX_LIST_BYTES:
                self.errors.append(f"{where}: {display} is larger than {_MAX_LIST_BYTES} bytes")
                return
            text = list_path.read_text(encoding="utf-8")
        except FileNotFoundError:
            self.errors.append(f"{where}: list of external variables {display} not found")
            return
        except OSError as exc:
            self.errors.append(
                f"{where}: cannot read the list of external variables {display}: {exc.strerror}"
            )
            return
        except UnicodeDecodeError as exc:
            self.errors.append(f"{where}: {display} is not UTF-8 text ({exc.reason})")
            return
        self.files.append(display)
        parsed = parse_external_list(text, source=display, channel=number)
        self.errors.extend(parsed.errors)
        self.warnings.extend(parsed.warnings)
        variables = self.data.setdefault("external_variables", [])
        if not isinstance(variables, list):
            return  # the machine file's own error says why
        for variable, origins in zip(parsed.variables, parsed.origins, strict=True):
            if "channel" not in variable:  # GLOBAL: two channels' lists may both declare it
                same = next(
                    (
                        v
                        for v in variables
                        if isinstance(v, dict)
                        and v.get("channel") is None
                        and str(v.get("name", "")).upper() == variable["name"].upper()
                    ),
                    None,
                )
                if same is not None and self._global_from_list.get(id(same)):
                    if same != variable:
                        self.errors.append(
                            f"{origins['name'].where()}: global V.E.{variable['name']} is declared "
                            f"differently in {self._global_from_list[id(same)]}"
                        )
                    continue
            position = len(variables)
            variables.append(variable)
            if "channel" not in variable:
                self._global_from_list[id(variable)] = origins["name"].where()
            for field_name, origin in origins.items():
                self.origins[("external_variables", position, field_name)] = origin
            self.origins.setdefault(("external_variables", position), origins["name"])
        self._merge_external_structures(parsed.structures, parsed.structure_origins)
        if parsed.init:
            lines = self.data.setdefault("external_init", [])
            if isinstance(lines, list):  # else the machine file's own error says why
                for assignment, origin in parsed.init:
                    self.origins[("external_init", len(lines))] = origin
                    lines.append(assignment)
        if parsed.extended is not None:
            flag, origin = parsed.extended
            given = self.data.get("use_extended_string_var")
            if given is None:
                self.data["use_extended_string_var"] = flag
                self.origins[("use_extended_string_var",)] = origin
            elif given != flag:
                first = self._origin(("use_extended_string_var",)).where()
                self.errors.append(
                    f"{origin.where()}: {flag} differs from {given} ({first}); one STRING length per machine "
                    "here"
                )

    def _merge_external_structures(self, structures: list[dict[str, Any]], origins: list[Origin]) -> None:
        """A list's ``struct[i]`` into ``external_structures``: two lists may define a structure,
        identically."""
        known = self.data.setdefault("external_structures", [])
        if not isinstance(known, list):
            return  # the machine file's own error says why
        for structure, origin in zip(structures, origins, strict=True):
            same = next(
                (
                    k
                    for k in known
                    if isinstance(k, dict) and str(k.get("name", "")).upper() == structure["name"].upper()
                ),
                None,
            )
            if same is not None:
                if same != structure:
                    where = self._origin(("external_structures", known.index(same))).where()
                    self.errors.append(
                        f"{origin.where()}: structure {structure['name']} is declared differently in {where}"
                    )
                continue
            self.origins[("external_structures", len(known))] = origin
            known.append(structure)

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
                # the name without regard to case, as on the kernel's Windows host
                program_path = find_file(self.path.parent / program["path"])
                if not program_path.is_file():
                    where = self._origin(("channels", c_index, "programs", p_index, "path")).where()
                    self.errors.append(f"{where}: program file {program_path} not found")
                program["path"] = str(program_path.resolve())

    def _resolve_program_directories(self) -> None:
        """``program_directories`` are relative to the machine file; each must be a directory (N-02)."""
        directories = self.data.get("program_directories")
        if not isinstance(directories, list):
            return
        for index, entry in enumerate(directories):
            if not isinstance(entry, str) or not entry:
                continue  # the model's own error says why
            path = (self.path.parent / entry).resolve()
            if not path.is_dir():
                where = self._origin(("program_directories", index)).where()
                what = "is not a directory" if path.exists() else "not found"
                self.errors.append(f"{where}: program directory {path} {what}")
            directories[index] = str(path)

    def _resolve_cycle_directories(self) -> None:
        """A channel's ``cycle_directories`` are relative to the machine file; each must be a directory."""
        channels = self.data.get("channels")
        if not isinstance(channels, list):
            return
        for c_index, channel in enumerate(channels):
            directories = channel.get("cycle_directories") if isinstance(channel, dict) else None
            if not isinstance(directories, list):
                continue
            for index, entry in enumerate(directories):
                if not isinstance(entry, str) or not entry:
                    continue  # the model's own error says why
                path = (self.path.parent / entry).resolve()
                if not path.is_dir():
                    where = self._origin(("channels", c_index, "cycle_directories", index)).where()
                    what = "is not a directory" if path.exists() else "not found"
                    self.errors.append(f"{where}: cycle directory {path} {what}")
                directories[index] = str(path)

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
                        target = (*target, issue.field, *issue.at)
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
    if info.path is not None and info.path.rsplit(".", 1)[-1] != info.field
}


def _unknown_key(model: type[BaseModel], key: str, *, list_allowed: bool) -> str:
    """``unknown key (did you mean swe_neg?)``, with a hint for ISG paths written into TOML."""
    candidates = list(model.model_fields)
    if list_allowed:
        candidates.append(_LIST_KEY)
    if model is ChannelConfig:
        candidates.append(_EXTERNAL_LIST_KEY)
    for table in _TABLES.values():
        for info in table[0]:
            if info.path is not None and key in {
                info.path,
                _display_path(info.path, 0).replace("[0]", "[i]"),
            }:
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
