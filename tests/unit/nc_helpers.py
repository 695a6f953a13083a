"""Running NC programs through the interpreter alone (no machine) for the language's unit tests."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field

from hli_server.engine.external import ExternalType, ExternalVariables, ExternalVarSpec
from hli_server.engine.nc import Block, Compiler, Interpreter, NcError
from hli_server.engine.nc.directives import Directive, FlushStop, FlushWait, SyncAction
from hli_server.engine.programs import MemoryLibrary, ProgramFile

AXES = ("X", "Y", "Z")


class FakeHost:
    """The interpreter's host: a library in memory, V.E. variables, and what the program says."""

    def __init__(
        self,
        files: Mapping[str, str] | None = None,
        external: list[ExternalVarSpec] | None = None,
        axes: tuple[str, ...] = AXES,
        implicit: Mapping[int, str] | None = None,
    ) -> None:
        self.channel_number = 1
        self.implicit = dict(implicit or {})
        """G code -> program: the channel's P-CHAN-00160..00169 / P-CHAN-00187."""
        self.external = ExternalVariables(external or [])
        self.library = MemoryLibrary(files or {})
        self.messages: list[tuple[str, bool, str, str, int, str]] = []
        self.warnings: list[tuple[int, str, int, str]] = []
        self.axes = axes
        self.position = dict.fromkeys(axes, 0.0)

    def find_program(self, name: str) -> ProgramFile | None:
        return self.library.find(name)

    def searched(self) -> tuple[str, ...]:
        return self.library.searched()

    def implicit_program(self, g: int) -> str:
        return self.implicit.get(g, "")

    def message(self, text: str, save: bool, file: str, program: str, line: int, block: str) -> None:
        self.messages.append((text, save, file, program, line, block))

    def warn(self, alarm: int, message: str, line: int, block: str) -> None:
        self.warnings.append((alarm, message, line, block))

    def axis_value(self, variable: str, axis: str) -> float | None:
        if axis not in self.position:
            return None
        if variable in ("ABS", "PROG", "ACT_POS"):
            return self.position[axis]
        if variable in ("-SWE", "-SWE_MDS"):
            return -500.0
        if variable in ("+SWE", "+SWE_MDS"):
            return 500.0
        return None

    def global_value(self, name: str) -> float | None:
        return {"BLOCK_NR": 0.0, "FEEDRATE": 0.0}.get(name)

    def axis_name(self, index: int) -> str | None:
        return self.axes[index] if 0 <= index < len(self.axes) else None

    def drive_value(self, axis: str, ident: str) -> float | None:
        return 1000.0 if ident in ("S-0-0001", "S-0-0002") else None

    def find_cycle(self, name: str) -> ProgramFile | None:
        return self.library.find(name)

    def cycle_searched(self) -> tuple[str, ...]:
        return self.library.searched()

    def stand_in(
        self,
        name: str,
        params: dict[int, float | str],
        results: Callable[[str, float], None],
        line: int,
        block: str,
    ) -> Iterator[Block] | None:
        return None  # the interpreter alone has no built-in cycles (tests/unit/test_cycles_programs.py has)


@dataclass
class Run:
    """What a program produced: blocks (in order), directives, the error that stopped it, messages."""

    blocks: list[Block] = field(default_factory=list)
    outputs: list[Block | Directive] = field(default_factory=list)
    error: NcError | None = None
    host: FakeHost = field(default_factory=FakeHost)
    ended: bool = False

    @property
    def axes(self) -> list[dict[str, float]]:
        """The axis words of each block with axis words."""
        return [dict(b.axes) for b in self.blocks if b.axes]

    def values(self, axis: str = "X") -> list[float]:
        return [dict(b.axes)[axis] for b in self.blocks if axis in dict(b.axes)]

    @property
    def alarm(self) -> int | None:
        return self.error.alarm if self.error is not None else None

    @property
    def warnings(self) -> list[int]:
        return [w[0] for w in self.host.warnings]

    @property
    def messages(self) -> list[str]:
        return [m[0] for m in self.host.messages]


def interpret(
    text: str,
    files: Mapping[str, str] | None = None,
    external: list[ExternalVarSpec] | None = None,
    *,
    limit: int = 100_000,
    host: FakeHost | None = None,
    interpreter: Interpreter | None = None,
) -> Run:
    """Run ``text`` through an interpreter (unbounded budget) to M30/M02, the end of its text or an
    error; directives' actions (a synchronous write, a #MSG SYN) run at once, as in a geometry check."""
    host = host if host is not None else FakeHost(files, external)
    it = interpreter or Interpreter(Compiler(host.axes, ("X", "Y", "Z")), host, budget=None)
    it.start(text, "main")
    run = Run(host=host)
    for _ in range(limit):
        try:
            out = it.next()
        except NcError as exc:
            run.error = exc
            return run
        if out is None:
            run.ended = True
            return run
        run.outputs.append(out)
        if isinstance(out, Block):
            run.blocks.append(out)
            if 30 in out.m_codes or 2 in out.m_codes:
                run.ended = True
                return run
        elif isinstance(out, SyncAction):
            out.action()
    raise AssertionError(f"program still running after {limit} outputs")


def error(text: str, files: Mapping[str, str] | None = None) -> NcError:
    run = interpret(text, files)
    assert run.error is not None, f"no error; blocks: {run.blocks}"
    return run.error


def real(
    name: str, channel: int | None = None, dims: tuple[int, ...] = (), synchronous: bool = False
) -> ExternalVarSpec:
    return ExternalVarSpec(name, ExternalType.REAL64, dims, channel, synchronous)


__all__ = ["AXES", "FakeHost", "FlushStop", "FlushWait", "Run", "SyncAction", "error", "interpret", "real"]
