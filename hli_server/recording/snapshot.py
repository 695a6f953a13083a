"""A snapshot of the engine's state, as data: what a recording started in a running server carries so that
its replay starts where the recording started (docs/record-replay.md, "A recording started in a running
server"; issue 37, item 2).

Why a snapshot: the engine is deterministic, so the inputs from the server's first cycle rebuild the state
at any later cycle (the input journal), but at the cost of every cycle since the server started: a
1-second recording of a server up 7 minutes replayed in 67 s, after a day it would take hours. The
snapshot is the state itself, so the replay's cost is the recording's length.

What it holds: the machine's object graph, from :class:`~hli_server.engine.machine.Machine` down (axes,
channels with their program state and the interpreter's position in the program, the planner's queue,
monitors, areas, alarms, the V.E. store, the HLI objects), written as JSON data, never as code:

* every engine object is its class (by module and name, only classes of ``hli_server.engine`` and
  ``schemas``) and its attributes; lists, dicts, sets and deques are kept with their identity (an object
  two parts of the machine share is shared again after the restore), tuples and the scalars inline;
* the host's parts the machine holds (its event listeners, its program library, its file reader) are
  named, not kept (:data:`EXTERNALS`): the replaying runtime brings its own;
* what cannot be kept as data (a function made at run time, an object of another package) makes
  :func:`capture` raise :class:`SnapshotError` naming where it is: the recorder then falls back to the
  input journal and says why.

Restoring (:func:`restore`) goes into a machine built from the same configuration, in place: the objects the
fresh machine has at the same places (its axes, channels, monitors, ...) take the recorded state, the
others are made anew. An object of the interpreted engine is made without its ``__init__`` and given its
attributes; one the mypyc-compiled engine compiled (a native class, whose constructor always runs
``__init__``) is made through its constructor with the recorded values of the parameters it names, then
given the rest. A snapshot is read as untrusted data: only classes, enums and functions of the engine's and
``schemas``' modules are looked up, methods by names the class defines, and a value of the wrong shape
is :class:`SnapshotRestoreError`.

A snapshot fits the engine that made it: :func:`engine_fingerprint` (a hash of the engine's and
``schemas``' sources) is stored with it, and a replay uses it only where the fingerprint is its own; a
recording replayed by another version starts from the input journal instead (docs/record-replay.md).
"""

from __future__ import annotations

import base64
import dataclasses
import enum
import functools
import hashlib
import importlib
import inspect
import math
import re
import sys
import types
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, Final

import numpy as np

__all__ = [
    "EXTERNALS",
    "SNAPSHOT_VERSION",
    "SnapshotError",
    "SnapshotRestoreError",
    "capture",
    "engine_fingerprint",
    "machine_externals",
    "restore",
]

SNAPSHOT_VERSION: Final = 1
"""The layout of a snapshot (this module's data format, not the engine's classes)."""

_MODULES: Final = ("hli_server.engine.", "schemas.")
"""Where the classes, enums and functions of a snapshot come from (nothing else is looked up)."""

EXTERNALS: Final = ("event_listeners", "programs", "cycle_programs", "read_program")
"""The machine's attributes that belong to its host (the runtime's event log and recorder, its program
library and the channels' cycle directories, its file reader): named in a snapshot, and the replaying
machine keeps its own."""

_NDARRAY_DTYPES: Final = frozenset({"<i8", "<f8", "|b1", "|u1", "<i4", "<u4", "<u8", "<f4"})
"""numpy arrays a snapshot may hold (the program text's line tables): plain numbers only."""

_MAX_DEPTH: Final = 400
"""How deeply values may nest inline (tuples in tuples) before a snapshot is refused as malformed."""

_MAX_PATTERN: Final = 4096
"""The longest regular expression a snapshot holds (the NC front end's patterns of a machine's axes)."""

_PLACEHOLDERS: Final = ("", None, 0, 0.0, False, ())
"""What a compiled class' constructor is given for a parameter that names no attribute of it (its real
value is set from the snapshot right after): the first one the constructor takes."""


class SnapshotError(Exception):
    """The state cannot be kept as data: what, and where in the machine (``machine.channels[0]...``)."""


class SnapshotRestoreError(Exception):
    """A snapshot that this engine cannot restore: malformed, of another layout, or not this engine's."""


@functools.cache
def engine_fingerprint() -> str:
    """A hash of the sources of ``hli_server/engine`` and ``schemas``: a snapshot restores only into the
    engine it was taken from (its classes and their attributes)."""
    digest = hashlib.sha256()
    here = Path(__file__).resolve().parents[1]
    for root in (here / "engine", here.parent / "schemas"):
        for path in sorted(root.rglob("*.py")):
            digest.update(str(path.relative_to(root.parent)).encode())
            digest.update(b"\0")
            digest.update(path.read_bytes())
            digest.update(b"\0")
    return digest.hexdigest()[:32]


def machine_externals(machine: Any) -> dict[str, Any]:
    """The host's parts of ``machine`` (:data:`EXTERNALS`), by name."""
    return {name: getattr(machine, name) for name in EXTERNALS}


# --------------------------------------------------------------------------------------------
# capture
# --------------------------------------------------------------------------------------------


def _name_of(kind: type | Callable[..., Any]) -> str:
    return f"{kind.__module__}:{kind.__qualname__}"


def _ours(module: str | None) -> bool:
    return module is not None and module.startswith(_MODULES)


def _is_native(kind: type) -> bool:
    """A class compiled by mypyc (its attributes are listed in ``__mypyc_attrs__``)."""
    return "__mypyc_attrs__" in kind.__dict__ or any("__mypyc_attrs__" in k.__dict__ for k in kind.__mro__)


def _attributes(obj: Any) -> dict[str, Any]:
    """The instance's attributes: a compiled class' own ``__getstate__`` (its attributes by name), else
    ``__dict__`` and the slots of every class of its MRO that are set."""
    kind = type(obj)
    if _is_native(kind):
        state = obj.__getstate__()  # mypyc's: every attribute that is defined
        if not isinstance(state, dict):
            raise TypeError(f"{_name_of(kind)}.__getstate__ gave {type(state).__name__}, not a dict")
        return dict(state)
    out: dict[str, Any] = dict(getattr(obj, "__dict__", {}))
    for klass in kind.__mro__:
        slots = klass.__dict__.get("__slots__", ())
        for slot in (slots,) if isinstance(slots, str) else slots:
            if slot in ("__dict__", "__weakref__") or slot in out:
                continue
            try:
                out[slot] = object.__getattribute__(obj, slot)
            except AttributeError:
                continue
    return out


def _module_globals() -> dict[int, str]:
    """The objects the engine's and schemas' modules hold at their top level (tables, compiled patterns,
    shared constants), by identity: a snapshot names them (``{"g": "module:NAME"}``) instead of copying
    them, and the replay takes its own module's object."""
    out: dict[int, str] = {}
    for module_name, module in list(sys.modules.items()):
        if module is None or not _ours(module_name + "."):
            continue
        for name, value in vars(module).items():
            if (
                name.startswith("__")
                or value is None
                or isinstance(
                    value, bool | int | float | str | bytes | type | types.ModuleType | types.FunctionType
                )
                or (callable(value) and not _ours(type(value).__module__))  # what restore refuses as "g"
            ):
                continue
            out.setdefault(id(value), f"{module_name}:{name}")
    return out


class _Encoder:
    def __init__(self, externals: Mapping[str, Any]) -> None:
        self.externals = {id(value): name for name, value in externals.items() if value is not None}
        self.globals = _module_globals()
        self.keep_alive = list(externals.values())
        self.index: dict[int, int] = {}
        self.objects: list[Any] = []
        self.where: list[tuple[int, str]] = []
        """per object: (the object that holds it, and under what) for the paths of error messages"""
        self.queue: deque[tuple[int, Any]] = deque()
        self.held: list[Any] = []  # what is in the table stays alive until the end (ids stay unique)

    def path(self, parent: int, key: str) -> str:
        parts = [key]
        while parent >= 0:
            parent, key = self.where[parent]
            parts.append(key)
        return "".join(reversed(parts))

    def table(self, obj: Any, parent: int, key: str) -> dict[str, int]:
        at = self.index.get(id(obj))
        if at is None:
            at = len(self.objects)
            self.index[id(obj)] = at
            self.objects.append(None)
            self.where.append((parent, key))
            self.held.append(obj)
            self.queue.append((at, obj))
        return {"r": at}

    def value(self, obj: Any, parent: int, key: str, depth: int = 0) -> Any:
        if depth > _MAX_DEPTH:
            raise SnapshotError(f"{self.path(parent, key)}: values nested more than {_MAX_DEPTH} deep")
        name = self.externals.get(id(obj))
        if name is not None:
            return {"x": name}
        if obj is None or type(obj) is str or type(obj) is bool or type(obj) is int:
            return obj
        name = self.globals.get(id(obj))
        if name is not None and not isinstance(obj, enum.Enum):
            return {"g": name}
        if type(obj) is float:
            if math.isfinite(obj):
                return obj
            return {"f": "nan" if math.isnan(obj) else ("inf" if obj > 0 else "-inf")}
        if isinstance(obj, enum.Enum):
            kind = type(obj)
            if not _ours(kind.__module__):
                raise SnapshotError(
                    f"{self.path(parent, key)}: an enum of {kind.__module__} ({kind.__name__})"
                )
            value = obj.value
            if not isinstance(value, int | str):
                raise SnapshotError(
                    f"{self.path(parent, key)}: {_name_of(kind)}.{obj.name} is no number or text"
                )
            return {"e": _name_of(kind), "v": value}
        if type(obj) is tuple:
            return {"t": [self.value(v, parent, f"{key}[{k}]", depth + 1) for k, v in enumerate(obj)]}
        if type(obj) is frozenset:
            return {"fs": _sorted([self.value(v, parent, f"{key}{{}}", depth + 1) for v in obj])}
        if type(obj) is bytes:
            return {"b": base64.b64encode(obj).decode("ascii")}
        if isinstance(obj, re.Pattern):
            if not isinstance(obj.pattern, str) or len(obj.pattern) > _MAX_PATTERN:
                raise SnapshotError(f"{self.path(parent, key)}: a regular expression of bytes or too long")
            return {"re": obj.pattern, "flags": obj.flags}
        if isinstance(obj, type):
            if not _ours(obj.__module__):
                raise SnapshotError(
                    f"{self.path(parent, key)}: the class {obj.__module__}.{obj.__qualname__}"
                )
            return {"c": _name_of(obj)}
        if type(obj) is functools.partial:  # an action the engine hands the planner, with its arguments
            where = f"{key}.func"
            return {
                "p": self.value(obj.func, parent, where, depth + 1),
                "a": [self.value(v, parent, f"{key}.args[{k}]", depth + 1) for k, v in enumerate(obj.args)],
                "k": [
                    [k, self.value(v, parent, f"{key}.keywords[{k!r}]", depth + 1)]
                    for k, v in obj.keywords.items()
                ],
            }
        if isinstance(obj, types.MethodType | types.BuiltinMethodType) and not isinstance(
            obj.__self__, types.ModuleType
        ):
            return {"m": self.value(obj.__self__, parent, f"{key}.__self__", depth + 1), "n": obj.__name__}
        if isinstance(obj, types.FunctionType | types.BuiltinFunctionType):
            module = getattr(obj, "__module__", None)
            qual = getattr(obj, "__qualname__", "")
            if module is None or not module.startswith(_MODULES[0]) or "<" in qual or "." in qual:
                raise SnapshotError(
                    f"{self.path(parent, key)}: the function {module}.{qual} (a function made at run time or "
                    "of another package cannot be kept as data)"
                )
            return {"fn": f"{module}:{qual}"}
        kind = type(obj)
        if kind in (list, dict, set, deque, bytearray, np.ndarray) or _ours(kind.__module__):
            return self.table(obj, parent, key)
        raise SnapshotError(f"{self.path(parent, key)}: an object of {kind.__module__}.{kind.__qualname__}")

    def entry(self, at: int, obj: Any) -> Any:
        kind = type(obj)
        if kind is list:
            return {"list": [self.value(v, at, f"[{k}]") for k, v in enumerate(obj)]}
        if kind is deque:
            return {"deque": [self.value(v, at, f"[{k}]") for k, v in enumerate(obj)], "maxlen": obj.maxlen}
        if kind is dict:
            return {
                "dict": [
                    [self.value(k, at, f"[{k!r}]"), self.value(v, at, f"[{k!r}]")] for k, v in obj.items()
                ]
            }
        if kind is set:
            return {"set": _sorted([self.value(v, at, "{}") for v in obj])}
        if kind is bytearray:
            return {"bytearray": base64.b64encode(bytes(obj)).decode("ascii")}
        if kind is np.ndarray:
            dtype = obj.dtype.str
            if dtype not in _NDARRAY_DTYPES or obj.dtype.hasobject:
                raise SnapshotError(f"{self.path(at, '')}: a numpy array of {obj.dtype}")
            return {
                "ndarray": dtype,
                "shape": list(obj.shape),
                "data": base64.b64encode(np.ascontiguousarray(obj).tobytes()).decode("ascii"),
            }
        try:
            state = _attributes(obj)
        except Exception as exc:
            raise SnapshotError(f"{self.path(at, '')}: the attributes of {_name_of(kind)}: {exc}") from None
        for name in getattr(kind, "snapshot_transient", ()):  # rebuilt by the object after a restore
            if name in state:
                state[name] = None
        return {"obj": _name_of(kind), "state": {k: self.value(v, at, f".{k}") for k, v in state.items()}}

    def run(self) -> None:
        while self.queue:
            at, obj = self.queue.popleft()
            self.objects[at] = self.entry(at, obj)


def _sorted(values: list[Any]) -> list[Any]:
    """Set elements in a stable order (the same state gives the same snapshot)."""
    try:
        return sorted(values)
    except TypeError:
        return sorted(values, key=repr)


def capture(machine: Any, externals: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The machine's state as JSON data (module docstring). Raises :class:`SnapshotError` for what cannot
    be kept. Call it between two cycles: it reads the machine as it is."""
    externals = machine_externals(machine) if externals is None else externals
    encoder = _Encoder(externals)
    root = encoder.value(machine, -1, "machine")
    if not isinstance(root, dict) or "r" not in root:
        raise SnapshotError(f"the machine is no object of the engine: {type(machine).__name__}")
    encoder.run()
    return {
        "snapshot": SNAPSHOT_VERSION,
        "fingerprint": engine_fingerprint(),
        "cycle": int(getattr(machine, "cycle", 0)),
        "root": root,
        "objects": encoder.objects,
    }


# --------------------------------------------------------------------------------------------
# restore
# --------------------------------------------------------------------------------------------


def _bad(message: str) -> SnapshotRestoreError:
    return SnapshotRestoreError(f"the snapshot is malformed: {message}")


@functools.cache
def _lookup(name: str) -> Any:
    """``module:Qual.name`` of the engine's or schemas' modules, nothing else."""
    if not isinstance(name, str) or name.count(":") != 1:
        raise _bad(f"{str(name)[:80]!r} is no module:name")
    module_name, qualname = name.split(":")
    if not _ours(module_name + ".") and not _ours(module_name):
        raise SnapshotRestoreError(f"the snapshot names {module_name!r}, which is no module of the engine")
    parts = qualname.split(".")
    if not all(p.isidentifier() and not p.startswith("__") for p in parts) or not all(
        p.isidentifier() for p in module_name.split(".")
    ):
        raise _bad(f"{name[:80]!r} is no name of a class or function")
    try:
        found: Any = importlib.import_module(module_name)
        for part in parts:
            found = getattr(found, part)
    except (ImportError, AttributeError) as exc:
        raise SnapshotRestoreError(f"this engine has no {name}: {exc}") from None
    return found


def _function(name: Any) -> Any:
    """A function the engine's modules define at their top level (``module:name``; what a planner's
    action calls): no method reached through a class, no function of another package a module imported."""
    if not isinstance(name, str) or not name.startswith(_MODULES[0]) or "." in name.partition(":")[2]:
        raise _bad(f"{str(name)[:80]!r} is no function of the engine")
    found = _lookup(name)
    if (
        not isinstance(found, types.FunctionType | types.BuiltinFunctionType)
        or getattr(found, "__module__", None) != name.partition(":")[0]
    ):
        raise _bad(f"{name[:80]} is no function of the engine")
    return found


def _class(name: str) -> type:
    found = _lookup(name)
    if not isinstance(found, type) or not _ours(found.__module__) or issubclass(found, BaseException):
        raise _bad(f"{name} is not a class of the engine")
    return found


class _Restorer:
    def __init__(self, data: Mapping[str, Any], externals: Mapping[str, Any]) -> None:
        objects = data.get("objects")
        if not isinstance(objects, list):
            raise _bad("no list of objects")
        self.objects: list[Any] = objects
        self.externals = externals
        self.made: dict[int, Any] = {}
        self.filled: set[int] = set()
        self.filling: set[int] = set()
        self.building: set[int] = set()

    # --- the pieces of an entry ----------------------------------------------------------------
    def entry(self, n: Any) -> dict[str, Any]:
        if type(n) is not int or not 0 <= n < len(self.objects):
            raise _bad(f"a reference to object {str(n)[:40]} (there are {len(self.objects)})")
        entry = self.objects[n]
        if not isinstance(entry, dict):
            raise _bad(f"object {n} is {type(entry).__name__}, not an object")
        return entry

    def state_of(self, n: int) -> dict[str, Any]:
        state = self.entry(n).get("state")
        if not isinstance(state, dict) or not all(
            (isinstance(k, str) and k.isidentifier() and not (k.startswith("__") and k.endswith("__")))
            or k in _PYDANTIC_SLOTS
            for k in state
        ):
            raise _bad(f"object {n}'s attributes")
        return state

    # --- in place: the fresh machine's objects at the same places ---------------------------------
    def claim(self, root_ref: Any, root: Any) -> None:
        """Map the snapshot's objects onto the fresh machine's objects at the same places (same class),
        from the root down, each object once."""
        if not (isinstance(root_ref, dict) and set(root_ref) == {"r"}):
            raise _bad("the root is no object reference")
        n = root_ref["r"]
        entry = self.entry(n)
        if entry.get("obj") != _name_of(type(root)):
            raise SnapshotRestoreError(
                f"the snapshot is of a {entry.get('obj')}, the replay's machine is a {_name_of(type(root))}"
            )
        self.made[n] = root
        taken = {id(root)} | set(_module_globals())  # what the modules hold is never written into
        todo: deque[tuple[int, Any]] = deque([(n, root)])
        while todo:
            n, existing = todo.popleft()
            for ref, there in self._places(n, existing):
                if ref["r"] in self.made:
                    continue
                m = ref["r"]
                if there is None or id(there) in taken or not self._same_kind(self.entry(m), there):
                    continue
                self.made[m] = there
                taken.add(id(there))
                todo.append((m, there))

    def _places(self, n: int, existing: Any) -> Iterator[tuple[dict[str, int], Any]]:
        """(reference, the fresh machine's object in its place) for what object ``n`` holds."""
        entry = self.entry(n)
        if "obj" in entry:
            for key, value in self.state_of(n).items():
                try:
                    there = object.__getattribute__(existing, key)
                except AttributeError:
                    continue
                yield from _pairs(value, there)
        elif "list" in entry or "deque" in entry:
            items = entry.get("list", entry.get("deque"))
            if isinstance(items, list) and isinstance(existing, list | deque):
                for value, there in zip(items, list(existing), strict=False):
                    yield from _pairs(value, there)
        elif "dict" in entry and isinstance(existing, dict):
            for pair in entry["dict"] if isinstance(entry["dict"], list) else ():
                if isinstance(pair, list) and len(pair) == 2 and _plain_key(pair[0]):
                    key = self.value(pair[0])
                    if key in existing:
                        yield from _pairs(pair[1], existing[key])

    @staticmethod
    def _same_kind(entry: dict[str, Any], existing: Any) -> bool:
        kind = type(existing)
        if "obj" in entry:  # a frozen one is made anew: its state is its constructor's
            return bool(entry["obj"] == _name_of(kind)) and not _frozen(kind)
        return (
            ("list" in entry and kind is list)
            or ("dict" in entry and kind is dict)
            or ("set" in entry and kind is set)
            or ("deque" in entry and kind is deque and existing.maxlen == entry.get("maxlen"))
        )

    # --- values ------------------------------------------------------------------------------
    def value(self, v: Any, depth: int = 0) -> Any:
        if v is None or isinstance(v, bool | int | float | str):
            return v
        if depth > _MAX_DEPTH:
            raise _bad(f"values nested more than {_MAX_DEPTH} deep")
        if not isinstance(v, dict) or not v:
            raise _bad(f"a value {str(v)[:60]}")
        if "r" in v and len(v) == 1:
            return self.get(v["r"])
        if "t" in v and len(v) == 1 and isinstance(v["t"], list):
            return tuple(self.value(x, depth + 1) for x in v["t"])
        if "fs" in v and len(v) == 1 and isinstance(v["fs"], list):
            return frozenset(self.value(x, depth + 1) for x in v["fs"])
        if "f" in v and len(v) == 1 and v["f"] in ("nan", "inf", "-inf"):
            return float(v["f"])
        if "b" in v and len(v) == 1 and isinstance(v["b"], str):
            return base64.b64decode(v["b"], validate=True)
        if "x" in v and len(v) == 1:
            if v["x"] not in self.externals:
                raise _bad(f"a part of the host {str(v['x'])[:40]!r}")
            return self.externals[v["x"]]
        if "e" in v and set(v) == {"e", "v"}:
            kind = _class(v["e"])
            if not issubclass(kind, enum.Enum) or not isinstance(v["v"], int | str):
                raise _bad(f"the enum value {str(v)[:80]}")
            try:
                return kind(v["v"])  # by value: an IntFlag's combination has no member name
            except ValueError:
                raise _bad(f"the enum value {str(v)[:80]}") from None
        if "c" in v and len(v) == 1:
            return _class(v["c"])
        if "g" in v and len(v) == 1:
            name = v["g"]
            if not isinstance(name, str) or "." in name.partition(":")[2]:
                raise _bad(f"a module's object {str(name)[:80]!r}")
            found = _lookup(name)
            if isinstance(found, types.ModuleType | type) or (
                callable(found) and not _ours(type(found).__module__)
            ):  # a module or a function a module imported (os, a class, eval...) is no table of its own
                raise _bad(f"{name[:80]} is no table or constant of the engine")
            return found
        if "fn" in v and len(v) == 1:
            return _function(v["fn"])
        if "re" in v and set(v) == {"re", "flags"}:
            if not isinstance(v["re"], str) or len(v["re"]) > _MAX_PATTERN or type(v["flags"]) is not int:
                raise _bad("a regular expression")
            try:
                return re.compile(v["re"], v["flags"])
            except (re.error, ValueError) as exc:
                raise _bad(f"a regular expression: {exc}") from None
        if "m" in v and set(v) == {"m", "n"}:
            return self.method(self.value(v["m"], depth + 1), v["n"])
        if set(v) == {"p", "a", "k"} and isinstance(v["a"], list) and isinstance(v["k"], list):
            kind = v["p"]
            if not isinstance(kind, dict) or not ({"fn"} == set(kind) or {"m", "n"} == set(kind)):
                raise _bad("a partial of no method or function of the engine")
            func = self.value(kind, depth + 1)
            if not all(isinstance(kv, list) and len(kv) == 2 and isinstance(kv[0], str) for kv in v["k"]):
                raise _bad("a partial's keywords")
            args = [self.value(x, depth + 1) for x in v["a"]]
            return functools.partial(func, *args, **{k: self.value(x, depth + 1) for k, x in v["k"]})
        raise _bad(f"a value {str(v)[:80]}")

    @staticmethod
    def method(owner: Any, name: Any) -> Any:
        if not isinstance(name, str) or not name.isidentifier() or name.startswith("__"):
            raise _bad(f"a method name {str(name)[:40]!r}")
        kind = type(owner)
        if kind in (list, dict, set, deque) or isinstance(owner, re.Pattern):
            return getattr(owner, name)
        if not _ours(kind.__module__):
            raise _bad(f"a method of {kind.__name__}")
        member = inspect.getattr_static(owner, name, None)
        if member is None or not (
            inspect.isfunction(member) or inspect.ismethoddescriptor(member) or callable(member)
        ):
            raise _bad(f"{kind.__name__} has no method {name}")
        return getattr(owner, name)

    # --- objects -----------------------------------------------------------------------------
    def get(self, n: Any) -> Any:
        """Object ``n``: made (perhaps not yet filled), or made now."""
        made = self.made.get(n, _MISSING) if type(n) is int else _MISSING
        if made is not _MISSING:
            return made
        entry = self.entry(n)
        if "list" in entry:
            obj: Any = []
        elif "dict" in entry:
            obj = {}
        elif "set" in entry:
            obj = set()
        elif "deque" in entry:
            maxlen = entry.get("maxlen")
            if maxlen is not None and (type(maxlen) is not int or maxlen < 0):
                raise _bad(f"object {n}'s maxlen")
            obj = deque(maxlen=maxlen)
        elif "bytearray" in entry:
            obj = bytearray(base64.b64decode(entry["bytearray"], validate=True))
            self.filled.add(n)
        elif "ndarray" in entry:
            obj = self.array(n, entry)
            self.filled.add(n)
        elif "obj" in entry:
            obj = self.instance(n, _class(entry["obj"]))
        else:
            raise _bad(f"object {n} of no known kind")
        self.made[n] = obj
        return obj

    @staticmethod
    def array(n: int, entry: dict[str, Any]) -> Any:
        dtype, shape, data = entry.get("ndarray"), entry.get("shape"), entry.get("data")
        if dtype not in _NDARRAY_DTYPES or not isinstance(shape, list) or not isinstance(data, str):
            raise _bad(f"the numpy array {n}")
        if not all(type(d) is int and d >= 0 for d in shape):
            raise _bad(f"the shape of numpy array {n}")
        raw = base64.b64decode(data, validate=True)
        array = np.frombuffer(raw, dtype=np.dtype(dtype))
        if array.size != math.prod(shape):
            raise _bad(f"numpy array {n} holds {array.size} values, not {shape}")
        return array.reshape(shape).copy()

    def instance(self, n: int, kind: type) -> Any:
        if not _is_native(kind):
            maker: Any = kind  # an interpreted class: made without __init__, given its state later
            return maker.__new__(kind)
        if not _frozen(kind):
            setup = _native_setup(kind)
            if setup is not None:
                return setup(kind)  # a compiled class, allocated without __init__; its state follows
        # a frozen compiled dataclass (or no allocator): its constructor, with the recorded values it names
        if n in self.building:
            raise SnapshotRestoreError(
                f"object {n} ({kind.__qualname__}) is needed to build itself: the snapshot cannot be restored"
            )
        self.building.add(n)
        state = self.state_of(n)
        try:
            obj = self.construct(kind, state)
        finally:
            self.building.discard(n)
        if _frozen(kind):
            self.filled.add(n)  # everything it holds was its constructor's
            self.adopt(obj, kind, state)
        return obj

    def adopt(self, obj: Any, kind: type, state: dict[str, Any]) -> None:
        """A frozen object's members its constructor made (``field(init=False)``, e.g. an area's prism)
        are the recorded objects other places refer to: the same instance, not an equal copy."""
        if not dataclasses.is_dataclass(kind):
            return
        for f in dataclasses.fields(kind):
            ref = state.get(f.name)
            if f.init or not (isinstance(ref, dict) and set(ref) == {"r"} and type(ref["r"]) is int):
                continue
            m = ref["r"]
            if m in self.made:
                object.__setattr__(obj, f.name, self.made[m])
            else:
                made = getattr(obj, f.name)
                if not self._same_kind(self.entry(m), made):
                    raise _bad(
                        f"object {m} is no {type(made).__qualname__} (the {f.name} of a {kind.__qualname__})"
                    )
                self.made[m] = made

    def construct(self, kind: type, state: dict[str, Any]) -> Any:
        if dataclasses.is_dataclass(kind):
            names = [f.name for f in dataclasses.fields(kind) if f.init]
            args = {name: self.ready(state[name]) for name in names if name in state}
            try:
                return kind(**args)
            except Exception as exc:
                raise SnapshotRestoreError(f"cannot rebuild {kind.__qualname__}: {exc}") from None
        try:
            parameters = list(inspect.signature(kind).parameters.values())
        except (TypeError, ValueError):
            raise SnapshotRestoreError(
                f"cannot rebuild {kind.__qualname__}: its constructor is unknown"
            ) from None
        given: dict[str, Any] = {}
        open_: list[str] = []
        for p in parameters:
            if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                continue
            if p.name in state:
                given[p.name] = self.ready(state[p.name])
            elif p.default is p.empty:
                open_.append(p.name)
        last: Exception | None = None
        for placeholder in _PLACEHOLDERS:
            try:
                return kind(**given, **dict.fromkeys(open_, placeholder))
            except Exception as exc:
                last = exc
                if not open_:
                    break
        raise SnapshotRestoreError(f"cannot rebuild {kind.__qualname__}: {last}")

    def ready(self, v: Any) -> Any:
        """A value a constructor is given: its objects filled first (a constructor may read them)."""
        value = self.value(v)
        for ref in _refs(v):
            self.fill(ref)
        return value

    def fill(self, n: int) -> None:
        if n in self.filled or n in self.filling:
            return
        self.filling.add(n)
        obj = self.get(n)
        entry = self.entry(n)
        if "list" in entry or "deque" in entry:
            items = entry.get("list", entry.get("deque"))
            if not isinstance(items, list):
                raise _bad(f"object {n}'s items")
            obj.clear()
            obj.extend(self.value(x) for x in items)
        elif "dict" in entry:
            pairs = entry["dict"]
            if not isinstance(pairs, list) or not all(isinstance(p, list) and len(p) == 2 for p in pairs):
                raise _bad(f"object {n}'s pairs")
            obj.clear()
            for key, value in pairs:
                obj[self.value(key)] = self.value(value)
        elif "set" in entry:
            items = entry["set"]
            if not isinstance(items, list):
                raise _bad(f"object {n}'s items")
            obj.clear()
            obj.update(self.value(x) for x in items)
        elif "obj" in entry:
            self.set_state(n, obj)
        self.filled.add(n)
        self.filling.discard(n)

    def set_state(self, n: int, obj: Any) -> None:
        kind = type(obj)
        state = {k: self.value(v) for k, v in self.state_of(n).items()}
        if _is_native(kind):
            if _frozen(kind):
                return
            kind.__setstate__(obj, state)  # mypyc's: every attribute by name
            return
        if hasattr(obj, "__dict__"):
            obj.__dict__.clear()  # an object the fresh machine had: nothing of its own stays
        for key, value in state.items():
            object.__setattr__(obj, key, value)


_SETUP: Final = "__internal_mypyc_setup"


@functools.cache
def _native_setup(kind: type) -> Callable[[type], Any] | None:
    """The allocator of a class mypyc compiled: what its ``__new__`` calls before ``__init__`` (mypyc
    lists it first among the class' methods as ``__internal_mypyc_setup``; a C function of one argument,
    the type). An instance made by it has its class defaults and no ``__init__`` run, as an interpreted
    class' ``__new__`` gives; the snapshot's attributes then go in by mypyc's ``__setstate__``. None where
    this CPython or mypyc lays it out otherwise (the constructor is used then)."""
    if sys.implementation.name != "cpython" or not (3, 10) <= sys.version_info[:2] <= (3, 14):
        return None
    for klass in kind.__mro__:
        descriptor = klass.__dict__.get(_SETUP)
        if descriptor is None:
            continue
        if type(descriptor).__name__ != "method_descriptor":
            return None
        import ctypes

        word = ctypes.sizeof(ctypes.c_void_p)
        # PyMethodDescrObject: PyObject_HEAD (2 words), d_type, d_name, d_qualname, then d_method
        method_def = ctypes.c_void_p.from_address(id(descriptor) + 5 * word).value
        if not method_def:
            return None
        name = ctypes.c_char_p.from_address(method_def).value  # PyMethodDef: ml_name, ml_meth, ...
        function = ctypes.c_void_p.from_address(method_def + word).value
        if name != _SETUP.encode() or not function:
            return None
        setup: Callable[[type], Any] = ctypes.PYFUNCTYPE(ctypes.py_object, ctypes.py_object)(function)
        return setup
    return None


_MISSING: Final = object()
_PYDANTIC_SLOTS: Final = frozenset({"__pydantic_fields_set__", "__pydantic_extra__", "__pydantic_private__"})


def _frozen(kind: type) -> bool:
    params = getattr(kind, "__dataclass_params__", None)
    return bool(params is not None and params.frozen)


def _plain_key(v: Any) -> bool:
    """A dict key the fresh machine's dict can be looked up with before any object is made."""
    if v is None or isinstance(v, bool | int | float | str):
        return True
    if isinstance(v, dict) and set(v) == {"t"} and isinstance(v["t"], list):
        return all(_plain_key(x) for x in v["t"])
    return isinstance(v, dict) and (set(v) == {"e", "v"} or set(v) == {"c"})


def _pairs(value: Any, there: Any, depth: int = 0) -> Iterator[tuple[dict[str, int], Any]]:
    """The references inside an attribute's recorded value, each with what the fresh machine holds in its
    place: the value itself, a tuple's items, a bound method's object."""
    if not isinstance(value, dict) or depth > _MAX_DEPTH:
        return
    if set(value) == {"r"} and type(value["r"]) is int:
        yield value, there
    elif set(value) == {"t"} and isinstance(value["t"], list) and type(there) is tuple:
        for item, other in zip(value["t"], there, strict=False):
            yield from _pairs(item, other, depth + 1)
    elif set(value) == {"m", "n"} and hasattr(there, "__self__"):
        yield from _pairs(value["m"], there.__self__, depth + 1)


def _refs(v: Any) -> Iterator[int]:
    """The object references inside an inline value."""
    if isinstance(v, dict):
        if set(v) == {"r"} and type(v["r"]) is int:
            yield v["r"]
            return
        for inner in v.values():
            yield from _refs(inner)
    elif isinstance(v, list):
        for inner in v:
            yield from _refs(inner)


def restore(data: Mapping[str, Any], machine: Any, externals: Mapping[str, Any] | None = None) -> None:
    """Put the state of ``data`` (:func:`capture`'s) into ``machine``, a machine built from the same
    configuration that has run no cycle: its objects at the same places take the recorded state, the
    others are made anew, the host's parts (:data:`EXTERNALS`) stay the machine's own.
    :class:`SnapshotRestoreError` when the snapshot is malformed or not of this engine."""
    if not isinstance(data, Mapping) or data.get("snapshot") != SNAPSHOT_VERSION:
        raise SnapshotRestoreError(
            f"a snapshot of layout {data.get('snapshot') if isinstance(data, Mapping) else None!r}; this "
            f"hli-server reads layout {SNAPSHOT_VERSION}"
        )
    if data.get("fingerprint") != engine_fingerprint():
        raise SnapshotRestoreError(
            "the snapshot was taken by another engine (its sources differ from this one's)"
        )
    externals = machine_externals(machine) if externals is None else externals
    restorer = _Restorer(data, externals)
    try:
        restorer.claim(data.get("root"), machine)
        for n in range(len(restorer.objects)):
            restorer.get(n)
        for n in range(len(restorer.objects)):
            restorer.fill(n)
    except SnapshotRestoreError:
        raise
    except RecursionError:
        raise SnapshotRestoreError("the snapshot's objects nest too deeply to be restored") from None
    except Exception as exc:  # a value of the wrong type for an attribute, ...
        raise SnapshotRestoreError(
            f"the snapshot does not fit this engine: {type(exc).__name__}: {exc}"
        ) from None
