"""The integration harness: an in-process hli-server with the stepped clock, for tests (H-07).

:class:`Harness` starts the real server (the :class:`~hli_server.runtime.Runtime` with the engine,
the process image and any adapter) in this process, on free ports, with the stepped clock, and
gives a test what it needs to drive it cycle by cycle::

    with Harness() as hli:                              # the demo machine; Harness("my.toml") for yours
        hli.operator.load_program(1, "N10 G01 X50 F6000\\nN20 M30\\n")
        hli.operator.start(1)
        hli.run_until(lambda: hli.image["gpCh[0]^bahn_state.program_state_r"] == 4, max_cycles=2000)
        assert hli.image["gpAx[0]^ipo_state.cmd_pos_r"] == 500_000

The pytest plugin (:mod:`hli_server.testing.plugin`) hands out a started harness as the ``hli``
fixture and a PLC transport to it as ``plc_transport``.

**Threads.** The server runs its event loop in a thread of its own, as if it were another device:
every door (shared memory, Modbus, ADS, HTTP) answers while the test's thread waits in a blocking
client, and a test may be a plain function or a coroutine. The engine is stepped only from the
server's loop (design.md, point 1): :meth:`Harness.step` hands the request to that loop and waits
for it. Between steps the server does nothing but answer its doors, so the test may read the
machine (``hli.runtime.machine``) directly; requests to the operator panel (``hli.operator``) are
handed to the server's loop like the steps.

**Speed.** :meth:`Harness.run_until` runs whole stretches inside the server's loop: with a PLC task
on a non-blocking transport (shared memory) each cycle is the PLC task's cycle and one engine cycle,
without a thread hand-over. A PLC on a blocking transport (Modbus, ADS: a client waiting for a
socket) runs in the test's thread, one hand-over per cycle.

**Image.** ``image="memory"`` (the default) keeps the process image in a buffer of this process:
no ``/dev/shm`` (the harness runs where shared memory is restricted) and nothing to leak. The PLC's
shared-memory transport reads the same bytes with the same protocol. ``image="shm"`` puts it into
POSIX shared memory, for a PLC in another process.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import inspect
import logging
import os
import threading
import time
from collections import deque
from collections.abc import Callable, Coroutine, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol, TypeVar, cast

from hli_server.testing.transports import open_transport
from schemas.layout import Direction, Layout
from schemas.results import CommFault, ProbeDeviation, ProgramLoaded
from schemas.units import increments_from_mm, mm_from_increments

if TYPE_CHECKING:
    from hli_server.adapters.host import OperatorPort, Value
    from hli_server.adapters.registry import Adapter
    from hli_server.engine.program_check import CheckResult
    from hli_server.runtime import AdapterSpec, Recording, Runtime, RuntimeImage
    from plc_clients.task import PlcTask
    from plc_clients.transports import Transport
    from schemas.config import MachineConfig

__all__ = [
    "CommFaultsView",
    "ConditionNotMetError",
    "Harness",
    "HarnessError",
    "ImageView",
    "ReplayFailedError",
    "SessionRecording",
    "load_machine_spec",
]

logger = logging.getLogger(__name__)

T = TypeVar("T")

REPORT_CYCLES = 8
"""Cycles shown in the report of a condition that never came."""
YIELD_EVERY_S = 0.005
"""A long :meth:`Harness.run_until` lets the server's doors answer at least this often [s]."""

_P2C, _C2P = Direction.PLC_TO_CNC, Direction.CNC_TO_PLC


class HarnessError(RuntimeError):
    """The harness cannot do what was asked (not started, stopped, used from the wrong thread)."""


class ConditionNotMetError(AssertionError):
    """:meth:`Harness.run_until` ran ``max_cycles`` cycles without the condition becoming true.

    An ``AssertionError``: pytest reports it as a failed test, with the report of the last cycles
    (the signals that changed in them, the channels' state, the alarms) as its message."""


@functools.lru_cache(maxsize=1)
def _demo_machine() -> MachineConfig:
    from hli_server.configuration import load_machine

    return load_machine(None)


def _relative_to(path: Path, base: Path | None) -> Path:
    """``path``, or ``base / path`` for a relative path that exists there (the test file's directory)."""
    if not path.is_absolute() and base is not None and (base / path).exists():
        return base / path
    return path


ProgramFiles = Mapping[str, str | os.PathLike[str]] | Iterable[str | os.PathLike[str]]
"""Subprograms of :meth:`Harness.load_program`: paths (found by ``L`` under their file name), or
``{name: text or path}``."""


def program_files(
    program: str | os.PathLike[str], files: ProgramFiles, name: str | None, base: Path | None
) -> tuple[str, str, dict[str, str], list[Path]]:
    """(text, name, uploaded files, the program file's directory if it is one) of a program given as NC text
    or a path (relative to ``base``, the test file's directory) and its subprograms."""
    from hli_server.runtime.programs import find_file, read_program_file

    # files are read as the server reads them: UTF-8 or Windows-1252, names without regard to case (N-12)
    directories: list[Path] = []
    if isinstance(program, os.PathLike):
        path = find_file(_relative_to(Path(program), base))
        text, name = read_program_file(path), name or path.name
        directories.append(path.parent)
    else:
        text, name = program, name or "program"
    uploads: dict[str, str] = {}
    items = files.items() if isinstance(files, Mapping) else ((None, f) for f in files)
    for key, value in items:
        if isinstance(value, os.PathLike) or key is None:
            file = find_file(_relative_to(Path(os.fspath(value)), base))
            uploads[key or file.name] = read_program_file(file)
        else:
            uploads[key] = value
    return text, name, uploads, directories


def load_machine_spec(machine: Any, base: Path | None = None) -> MachineConfig:
    """A :class:`MachineConfig` from a configuration, a machine file (relative paths against
    ``base``, else the working directory) or None (the built-in demo machine, loaded once)."""
    from hli_server.configuration import load_machine
    from schemas.config import MachineConfig

    if machine is None:
        return _demo_machine()
    if isinstance(machine, MachineConfig):
        return machine
    path = Path(os.fspath(machine))
    if not path.is_absolute() and base is not None and (base / path).exists():
        path = base / path
    return load_machine(path)


class ImageView:
    """The process image by ST path, as the test sees it: ``hli.image[path]``, ``hli.image[path] = v``.

    Reads give CNC->PLC fields from the newest publish and PLC->CNC fields as they are now; a write
    (PLC->CNC fields only, H-02) is latched at the start of the next cycle, as a PLC's is."""

    def __init__(self, image: RuntimeImage) -> None:
        self._image = image

    @property
    def layout(self) -> Layout:
        return self._image.layout

    @property
    def name(self) -> str:
        return self._image.name

    def __getitem__(self, st_path: str) -> Value:
        return self._image.read(st_path)

    def __setitem__(self, st_path: str, value: Value) -> None:
        self._image.write(st_path, value)

    def read(self, st_path: str) -> Value:
        return self._image.read(st_path)

    def write(self, st_path: str, value: Value) -> None:
        self._image.write(st_path, value)

    def snapshot(self) -> dict[str, Value]:
        """Every CNC->PLC field of the newest publish (and ``"cycle"``: its cycle)."""
        cycle, data = self._image.snapshot()
        values: dict[str, Value] = self._image.layout.unpack(_C2P, data)
        values["cycle"] = cycle
        return values

    def outputs(self) -> dict[str, Value]:
        """Every PLC->CNC field as it is now."""
        values: dict[str, Value] = self._image.layout.unpack(_P2C, self._image.read_half(_P2C))
        return values

    def __repr__(self) -> str:
        return f"ImageView({self._image.name!r})"


class ReplayFailedError(AssertionError):
    """:meth:`Harness.replay` found a difference, or cannot replay the recording: the message is the
    replay's report (the first difference with its cycle, signal, expected and actual value)."""

    def __init__(self, report: Any) -> None:
        super().__init__(report.text())
        self.report = report


class SessionRecording:
    """A recording of the harness' session (:meth:`Harness.record`); stopped by :meth:`stop` or at the
    end of a ``with`` block (and when the harness stops)."""

    def __init__(self, harness: Harness, path: Path) -> None:
        self._harness = harness
        self.path = path

    def stop(self) -> Path:
        runtime = self._harness.runtime
        if runtime.session.recording:
            self._harness._call_soon(runtime.session.stop)
        return self.path

    def __enter__(self) -> SessionRecording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class CommFaultsView:
    """The communication faults of the harness' server (docs/record-replay.md, ``hli.comm_faults``): each
    call is handed to the server's loop. ``with hli.comm_faults.fault(kind="delay", door="modbus",
    delay_ms=50, count=3): ...`` ends the fault at the end of the block."""

    def __init__(self, harness: Harness) -> None:
        self._harness = harness

    def add(self, **spec: Any) -> CommFault:
        """Set a fault (the fields of ``POST /api/comm/faults``); returns it with its ``id``."""
        faults = self._harness.runtime.comm_faults
        result: CommFault = self._harness._call_soon(lambda: faults.add(spec).to_json())
        return result

    def end(self, fault_id: int) -> None:
        faults = self._harness.runtime.comm_faults
        self._harness._call_soon(lambda: faults.end(fault_id, "api"))

    def reset(self) -> int:
        faults = self._harness.runtime.comm_faults
        ended: int = self._harness._call_soon(lambda: faults.reset("reset"))
        return ended

    def table(self) -> list[CommFault]:
        faults = self._harness.runtime.comm_faults
        table: list[CommFault] = self._harness._call_soon(faults.table)
        return table

    @contextlib.contextmanager
    def fault(self, **spec: Any) -> Iterator[CommFault]:
        fault = self.add(**spec)
        try:
            yield fault
        finally:
            with contextlib.suppress(Exception):  # ended by itself already
                if any(f["id"] == fault["id"] for f in self.table()):
                    self.end(fault["id"])


class _OperatorInLoop:
    """The operator panel with every call handed to the server's loop (a thin proxy)."""

    def __init__(self, harness: Harness, operator: OperatorPort) -> None:
        self._harness = harness
        self._operator = operator

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._operator, name)
        if not callable(attr):
            return attr

        @functools.wraps(attr)
        def call(*args: Any, **kwargs: Any) -> Any:
            return self._harness._call_soon(functools.partial(attr, *args, **kwargs))

        return call

    def __repr__(self) -> str:
        return f"<operator panel of {self._harness!r}>"


class _ProbePort(Protocol):
    """The operator panel's calls of the simulated probe (in-process or over HTTP)."""

    def probe_deviation(self, channel: int) -> ProbeDeviation: ...

    def set_probe_deviation(self, channel: int, values: dict[str, int]) -> ProbeDeviation: ...


class _Programs:
    """``load_program``, ``check`` and the simulated probe's deviation, the same for the in-process harness
    and the remote one (``remote.py``): each says how a program is loaded, which machine a check runs on
    and which operator panel it talks to."""

    _base: Path | None

    def _probe_port(self) -> _ProbePort:
        raise NotImplementedError

    def set_probe_deviation(self, channel: int = 1, **axes_mm: float) -> dict[str, float]:
        """Where the simulated workpiece of the built-in measuring cycles lies off its nominal position,
        per axis in mm (``hli.set_probe_deviation(X=0.2, Y=-0.1)``; docs/cycles.md). An axis that the machine
        file gives a V.E. variable has that variable written, as the PLC would. Returns the deviation now."""
        values = {k: increments_from_mm(v) for k, v in axes_mm.items()}
        self._probe_port().set_probe_deviation(channel, values)
        return self.probe_deviation(channel)

    def probe_deviation(self, channel: int = 1) -> dict[str, float]:
        """The simulated workpiece's deviation per axis [mm]."""
        raw = self._probe_port().probe_deviation(channel)["deviation"]
        return {k: mm_from_increments(v) for k, v in raw.items()}

    def _load(self, channel: int, text: str, name: str, files: dict[str, str]) -> ProgramLoaded:
        raise NotImplementedError

    def _check_machine(self) -> tuple[MachineConfig, list[str | os.PathLike[str]]]:
        """The configuration a check runs on, and the program directories after the program's own."""
        raise NotImplementedError

    def load_program(
        self,
        channel: int,
        program: str | os.PathLike[str],
        *,
        files: ProgramFiles = (),
        name: str | None = None,
    ) -> ProgramLoaded:
        """Load a program into ``channel`` with the subprograms and cycles it calls.

        ``program`` is NC text, or the path of a program file (a :class:`~pathlib.Path`, relative to
        the test file's directory for the plugin's ``hli``). ``files`` are its subprograms: paths
        (found by ``L`` under their file name), or ``{name: text or path}``. They are found before the
        program directories, as files uploaded with the program (``POST /api/channels/{n}/program``).
        Raises the operator's errors (a program runs: ConflictError; a name with ``..``:
        InvalidRequestError)."""
        text, name, uploads, _ = program_files(program, files, name, self._base)
        return self._load(channel, text, name, uploads)

    def check(
        self,
        program: str | os.PathLike[str],
        *,
        files: ProgramFiles = (),
        name: str | None = None,
        channel: int = 1,
        geometry_only: bool = False,
        max_cycles: int = 10_000_000,
        max_iterations: int = 1_000_000,
        record_path: bool = False,
        presets: Mapping[str, bool | int | float | str] | None = None,
    ) -> CheckResult:
        """Check a program offline, as ``hli-server check`` and ``POST /api/check`` do: the engine's
        :class:`~hli_server.engine.program_check.ProgramCheck` on a fresh machine of this server's machine
        file (the running machine, its programs and V.E. variables are not touched; no cycle is stepped).

        ``program`` and ``files`` as for :meth:`load_program`; subprograms are found among ``files``, then
        in the directory of a program given by path, then in the server's program directories. Returns
        the :class:`~hli_server.engine.program_check.CheckResult`: ``completed``, ``alarms`` (each with
        ``number``, ``line``, ``block``, ``message``), ``messages`` (``#MSG``), ``final_position``,
        ``capped``; ``to_json()`` is ``check --format json``'s report. ``presets`` are V.E. values before
        the start, as the PLC would give them (``{"V.E.PLC_READY": True}``; ``check --set``; a preset that
        cannot be taken raises InvalidRequestError); a program that waits on inputs nobody changes stops
        within seconds with ``capped == "waiting"`` and warning 914052."""
        from hli_server.runtime.checks import run_check

        text, name, uploads, directories = program_files(program, files, name, self._base)
        config, searched = self._check_machine()
        return run_check(
            config,
            text,
            directories=[*directories, *searched],
            files=uploads,
            name=name,
            channel=channel,
            geometry_only=geometry_only,
            max_cycles=max_cycles,
            max_iterations=max_iterations,
            record_path=record_path,
            presets=presets,
        )


class Harness(_Programs):
    """An in-process hli-server with the stepped clock (H-07); see the module docstring.

    ``machine``: a :class:`MachineConfig`, a machine file or None (the demo machine). ``image``:
    ``"memory"`` (default) or ``"shm"``. ``adapters``: doors to open at start (``"http"``,
    ``("modbus", {"word_order": "CDAB"})``; ports default to free ones); :meth:`serve` opens more
    later. ``timeout_s`` bounds every hand-over to the server (a hung server fails the test instead
    of hanging it).
    """

    def __init__(
        self,
        machine: Any = None,
        *,
        image: Literal["memory", "shm"] = "memory",
        image_name: str | None = None,
        adapters: Iterable[AdapterSpec] = (),
        bind: str = "127.0.0.1",
        base: Path | None = None,
        timeout_s: float = 120.0,
        program_dirs: Iterable[str | os.PathLike[str]] = (),
        nc_output_dir: str | os.PathLike[str] | None = None,
    ) -> None:
        if image not in ("memory", "shm"):
            raise ValueError(f"image={image!r}: use 'memory' (a buffer of this process) or 'shm' (/dev/shm)")
        self.config = load_machine_spec(machine, base)
        self._base = base
        self.image_kind = image
        self.image_name = image_name
        self.bind = bind
        self.timeout_s = timeout_s
        self._adapter_specs = [_with_free_port(spec) for spec in adapters]
        self.program_dirs = [_relative_to(Path(os.fspath(d)), base) for d in program_dirs]
        """Where ``L name`` finds global subprograms (N-02), before the machine file's directories."""
        self.nc_output_dir = nc_output_dir
        """Where ``#MSG SAVE`` writes (N-07); None: a temporary directory (``hli.nc_output_dir``)."""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._runtime: Runtime | None = None
        self._image: ImageView | None = None
        self._operator: _OperatorInLoop | None = None
        self._transports: list[Transport] = []
        self._stopped = False

    # --- life cycle ---------------------------------------------------------------------------
    def start(self) -> Harness:
        """Start the server thread, the runtime and the adapters; returns ``self``."""
        if self._loop is not None:
            raise HarnessError("the harness was started already; make a new Harness to run again")
        loop = asyncio.new_event_loop()
        self._loop = loop
        ready = threading.Event()

        def serve() -> None:
            asyncio.set_event_loop(loop)
            loop.call_soon(ready.set)
            loop.run_forever()

        self._thread = threading.Thread(target=serve, name="hli-harness-server", daemon=True)
        self._thread.start()
        ready.wait(self.timeout_s)
        try:
            self._runtime = self._call(self._start_runtime())
        except BaseException:  # the runtime undid its own start; end the thread too
            self._stopped = True
            self._shutdown_loop()
            raise
        image = self._runtime.image
        self._image = ImageView(image)
        self._operator = _OperatorInLoop(self, self._runtime.operator)
        logger.info("harness started: %s", "; ".join(self._runtime.endpoints()))
        return self

    async def _start_runtime(self) -> Runtime:
        from hli_server.runtime import Runtime, memory_image, shared_memory_image

        runtime = Runtime(
            self.config,
            clock="stepped",
            bind=self.bind,
            http_port=None,
            image_name=self.image_name,
            adapters=self._adapter_specs,
            image_factory=memory_image if self.image_kind == "memory" else shared_memory_image,
            program_dirs=self.program_dirs,
            nc_output_dir=self.nc_output_dir,
        )
        await runtime.start()
        return runtime

    def stop(self) -> None:
        """Close the transports it opened, stop the runtime (adapters, image), end the thread."""
        if self._stopped:
            return
        self._stopped = True
        errors: list[BaseException] = []
        for transport in reversed(self._transports):
            try:
                transport.close()
            except Exception as exc:  # every door is closed, whatever one of them does
                errors.append(exc)
        self._transports.clear()
        if self._runtime is not None and self._loop is not None:
            try:
                self._call(self._runtime.stop())
            except BaseException as exc:
                errors.append(exc)
        self._shutdown_loop()
        if errors:
            raise errors[0]

    def _shutdown_loop(self) -> None:
        loop, thread = self._loop, self._thread
        if loop is None or thread is None or loop.is_closed():
            return
        loop.call_soon_threadsafe(loop.stop)
        thread.join(self.timeout_s)
        if thread.is_alive():  # pragma: no cover - a hung server
            raise HarnessError(f"the server thread did not end within {self.timeout_s} s")
        loop.run_until_complete(loop.shutdown_asyncgens())
        loop.close()

    def __enter__(self) -> Harness:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def __repr__(self) -> str:
        state = "stopped" if self._stopped else f"cycle {self.cycle}" if self._runtime else "new"
        return f"Harness({self.config.name!r}, {self.image_kind} image, {state})"

    # --- hand-over to the server's loop ------------------------------------------------------------
    def _in_server_thread(self) -> bool:
        return threading.current_thread() is self._thread

    def _loop_or_raise(self) -> asyncio.AbstractEventLoop:
        if self._loop is None or self._stopped:
            raise HarnessError("the harness does not run (start() it, or it was stopped)")
        return self._loop

    def _call(self, coro: Coroutine[Any, Any, T]) -> T:
        """Run ``coro`` in the server's loop and wait for its result (bounded by ``timeout_s``)."""
        loop = self._loop
        if loop is None:
            coro.close()
            raise HarnessError("the harness does not run (start() it, or it was stopped)")
        if self._in_server_thread():
            coro.close()
            raise HarnessError(
                "step() and run_until() cannot be called from inside a condition or a PLC program "
                "that the harness is running (they run in the server's thread)"
            )
        future = asyncio.run_coroutine_threadsafe(coro, loop)
        try:
            return future.result(self.timeout_s)
        except TimeoutError:
            future.cancel()
            raise HarnessError(
                f"the server did not answer within {self.timeout_s} s (a hung cycle or adapter?)"
            ) from None

    def _call_soon(self, fn: Callable[[], T]) -> T:
        """Call ``fn`` in the server's loop (directly when already there) and return its result."""
        if self._in_server_thread():
            return fn()

        async def run() -> T:
            return fn()

        return self._call(run())

    # --- what the test sees ------------------------------------------------------------------------
    @property
    def runtime(self) -> Runtime:
        """The server itself: read it between steps; change the machine through :attr:`operator`."""
        if self._runtime is None:
            raise HarnessError("the harness is not started (use it as a context manager, or start())")
        return self._runtime

    @property
    def layout(self) -> Layout:
        return self.runtime.image.layout

    @property
    def cycle(self) -> int:
        """The machine's cycle counter (cycles run so far)."""
        return self.runtime.machine.cycle

    @property
    def t_a(self) -> float:
        """The interpolation cycle time [s]."""
        return self.runtime.t_a

    @property
    def image(self) -> ImageView:
        """The process image by ST path (``hli.image["gpAx[0]^ipo_state.cmd_pos_r"]``)."""
        if self._image is None:
            raise HarnessError("the harness is not started")
        return self._image

    @property
    def operator(self) -> OperatorPort:
        """The operator panel (load/select/start/reset/feedhold/mode/jog/override/reference/faults/
        snapshot/alarms): what the HTTP API offers, without HTTP. Requests are latched by the
        channel at the next cycle."""
        if self._operator is None:
            raise HarnessError("the harness is not started")
        return cast("OperatorPort", self._operator)

    def _probe_port(self) -> _ProbePort:
        return self.operator

    def step(self, cycles: int = 1) -> int:
        """Run ``cycles`` cycles now; returns the machine's cycle counter."""
        self._loop_or_raise()
        return self._call(self.runtime.step(cycles))

    def trace(self, *signals: str) -> Recording:
        """Record ``signals`` (ST paths) in every cycle from now on, until the recording's
        ``stop()`` or the end of a ``with`` block; ``recording.trace()[path]`` is a numpy array."""
        self._loop_or_raise()
        return self._call_soon(lambda: self.runtime.record(signals))

    # --- recording and replay (docs/record-replay.md) ----------------------------------------------
    def record(
        self, path: str | os.PathLike[str], *, overwrite: bool = True, outputs_every: int | None = None
    ) -> SessionRecording:
        """Record this session into ``path`` (gzip JSON Lines, docs/record-replay.md) from the next cycle
        on, with every input since the first cycle; ``with hli.record(p): ...`` or ``.stop()``. The
        outputs are sampled every ``outputs_every`` cycles (None: the server's setting, 100 by default;
        1: every cycle, for a replay that names the exact cycle of a difference)."""
        self._loop_or_raise()
        target = Path(os.fspath(path))
        runtime = self.runtime
        self._call_soon(
            lambda: runtime.session.start(
                target, origin="pytest", overwrite=overwrite, outputs_every=outputs_every
            )
        )
        return SessionRecording(self, target)

    def replay(self, path: str | os.PathLike[str], **options: Any) -> Any:
        """Replay a recording as a test: raises :class:`ReplayFailedError` (an AssertionError, with the
        report: the first difference's cycle, signal, expected and actual value) unless it passes;
        returns the :class:`~hli_server.replay.ReplayReport`. Options: ``until``, ``signals``,
        ``events``, ``all_differences``, ``config``, ``same_version``, ``from_journal`` (as ``hli-server
        replay``). The
        replay runs on a machine of its own, built from the recording; this harness' machine is left
        as it is."""
        __tracebackhide__ = True
        from hli_server.replay import Verdict, replay

        self._loop_or_raise()
        report = self._call(replay(Path(os.fspath(path)), **options))
        if report.verdict is not Verdict.PASS:
            raise ReplayFailedError(report)
        return report

    @property
    def comm_faults(self) -> CommFaultsView:
        """Faults in the PLC's communication on demand (docs/record-replay.md)."""
        return CommFaultsView(self)

    # --- programs (N-02, N-07): load_program and check of _Programs -------------------------------
    def _load(self, channel: int, text: str, name: str, files: dict[str, str]) -> ProgramLoaded:
        return self.operator.load_program(channel, text, name, files)

    def _check_machine(self) -> tuple[MachineConfig, list[str | os.PathLike[str]]]:
        return self.runtime.config, list(self.runtime.checker.directories)

    @property
    def nc_files(self) -> Path:
        """The directory where this server's ``#MSG SAVE`` writes its report files."""
        return self.runtime.nc_files.directory

    # --- doors ------------------------------------------------------------------------------------
    def serve(self, adapter: str, **options: Any) -> Adapter:
        """Open a door (``"modbus"``, ``"http"``, ``"ads"``) if it is not open yet, on a free port
        unless ``port`` is given; returns the adapter (``adapter.port``, ``adapter.endpoints()``)."""
        self._loop_or_raise()
        for running in self.runtime.adapters:
            if running.name == adapter:
                return running
        spec: AdapterSpec = _with_free_port((adapter, options))
        return self._call(self.runtime.start_adapter(spec))

    @property
    def http_url(self) -> str:
        """The HTTP control API's base URL (opens the door on first use)."""
        url: str = getattr(self.serve("http"), "url")  # noqa: B009 - the HTTP adapter's own attribute
        return url

    def port(self, adapter: str) -> int:
        """The TCP port a door listens on (opens it on first use)."""
        port = getattr(self.serve(adapter), "port", None)
        if not isinstance(port, int):
            raise HarnessError(f"adapter {adapter!r} does not listen on a TCP port")
        return port

    def transport(self, kind: str = "shm") -> Transport:
        """A PLC-side transport to this server (``plc_clients``): ``"shm"``, ``"modbus"``, ``"ads"``
        or any registered one (:mod:`hli_server.testing.transports`). Closed when the harness stops."""
        self._loop_or_raise()
        transport = open_transport(self, kind)
        self._transports.append(transport)
        return transport

    # --- running until something happens -------------------------------------------------------------
    def run_until(
        self,
        condition: Callable[[], object],
        max_cycles: int,
        *,
        plc: PlcTask | None = None,
        show: Sequence[str] = (),
        what: str | None = None,
    ) -> int:
        """Run cycles until ``condition()`` is true; returns the cycles run (0 if it is true already).

        With ``plc``, every cycle is one cycle of the PLC task (inputs, program, outputs) followed by
        one CNC cycle, so that PLC and CNC run in lock-step. ``condition`` is checked after each
        cycle. When it is still false after ``max_cycles`` cycles, :class:`ConditionNotMetError`
        reports the last cycles: the signals that changed in them (and those in ``show``), the
        channels' program state, the active alarms and the PLC task's faults. ``what`` names the
        condition in that report (default: the source line of the call).
        """
        __tracebackhide__ = True  # pytest shows the test's line and the report, not this method
        self._loop_or_raise()
        if max_cycles < 0:
            raise ValueError(f"max_cycles must be >= 0, got {max_cycles}")
        if plc is not None and plc.is_async:
            raise TypeError(
                "run_until drives the PLC task synchronously: give it a synchronous transport "
                "(hli.transport(...) or the plc_transport fixture), not an asyncio one"
            )
        history: deque[tuple[int, bytes, bytes]] = deque(maxlen=REPORT_CYCLES)
        start = self.cycle
        if plc is not None and getattr(plc.transport, "blocking", False):
            ran = self._run_until_here(condition, max_cycles, plc, history)
        else:
            ran = self._call(self._run_until_in_loop(condition, max_cycles, plc, history))
        if ran is None:
            shown = [self.layout.signal(path) for path in show]
            raise ConditionNotMetError(self._report(condition, what, max_cycles, start, history, plc, shown))
        return ran

    def _keep(self, history: deque[tuple[int, bytes, bytes]]) -> None:
        image = self.runtime.image
        cycle, c2p = image.snapshot()
        history.append((cycle, c2p, image.read_half(_P2C)))

    async def _run_until_in_loop(
        self,
        condition: Callable[[], object],
        max_cycles: int,
        plc: PlcTask | None,
        history: deque[tuple[int, bytes, bytes]],
    ) -> int | None:
        if condition():
            return 0
        step = self.runtime.step
        clock = time.monotonic
        next_yield = clock() + YIELD_EVERY_S
        for ran in range(1, max_cycles + 1):
            if plc is not None:
                plc.run_cycle()
            await step(1)
            self._keep(history)
            if condition():
                return ran
            if clock() >= next_yield:
                await asyncio.sleep(0)  # the doors answer (an HTTP client watching, a second PLC)
                next_yield = clock() + YIELD_EVERY_S
        return None

    def _run_until_here(
        self,
        condition: Callable[[], object],
        max_cycles: int,
        plc: PlcTask,
        history: deque[tuple[int, bytes, bytes]],
    ) -> int | None:
        if condition():
            return 0
        for ran in range(1, max_cycles + 1):
            plc.run_cycle()
            self.step(1)
            self._keep(history)
            if condition():
                return ran
        return None

    def _report(
        self,
        condition: Callable[[], object],
        what: str | None,
        max_cycles: int,
        start: int,
        history: deque[tuple[int, bytes, bytes]],
        plc: PlcTask | None,
        show: Sequence[Any],
    ) -> str:
        from hli_server.testing.report import cycle_report

        return cycle_report(
            what=what or describe(condition),
            max_cycles=max_cycles,
            first_cycle=start + 1,
            layout=self.layout,
            history=list(history),
            show=show,
            alarms=self._call_soon(lambda: self.runtime.operator.alarms(history=0))["active"],
            plc=plc,
        )


def describe(condition: Callable[[], object]) -> str:
    """The condition as the test wrote it: the source of a lambda's call line, else its name."""
    name = getattr(condition, "__name__", None)
    if name and name != "<lambda>":
        return f"{name}()"
    try:
        lines, _ = inspect.getsourcelines(condition)
    except (OSError, TypeError):
        return repr(condition)
    text = " ".join(line.strip() for line in lines)
    return text if len(text) <= 200 else text[:197] + "..."


def _with_free_port(spec: Any) -> Any:
    """Network adapters listen on a free port unless the test names one (design: tests bind 0)."""
    if isinstance(spec, str):
        return (spec, {"port": 0}) if spec in ("http", "modbus", "ads") else spec
    if isinstance(spec, tuple):
        name, options = spec
        if name in ("http", "modbus", "ads") and "port" not in options:
            return (name, {**options, "port": 0})
    return spec
