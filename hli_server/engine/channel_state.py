"""The channel's program state and mode: every transition, and what causes it, in one table (E-03, E-04).

Like h11's ``_state.py``: everything that changes ``bahn_state.program_state_r`` or ``mode_r`` lives
here. :class:`ChannelState` is the only writer of both; the channel calls :meth:`ChannelState.apply`
with a :class:`Cause`, and a transition the table does not list raises :class:`StateTransitionError`
(a bug, never a user error: the channel checks the user's request first and refuses it with an alarm).

Program states (``schemas.wire.ProgramState``) and their causes::

    IDLE ------ start ------> RUNNING <-- release --- HELD
      ^  \\                    |   |  \\-- hold ------->  |
      |   load                end  error               | end / error
      |                        v    v                  v
      |                   FINISHED  ABORTED  <---------+
      +------ reset (from every state), load (from IDLE, FINISHED, ABORTED) ---+

* ``start``: a start edge (``mc_command.start_w`` rising, or the operator's start) that the channel
  accepted: automatic mode, a program selected, no error pending, every axis referenced and at rest.
* ``hold``: the path rests because of a hold (``HoldSource``: the feedhold control unit, a dynamic
  position limit). ``release``: the hold was lifted and the path moves again.
* ``end``: the path reached M30 / M02 or the end of the program text.
* ``error``: an alarm whose reaction aborts the program (an area violation, a soft limit, a syntax
  error, a collision stop, ...). The axes brake to rest after it; the state is ABORTED at once.
* ``reset``: the channel reset (``mc_command.reset_w`` rising, or the operator's): back to IDLE.
* ``load``: a program was selected or loaded while none runs.

Modes (``schemas.wire.Mode``): AUTOMATIC <-> MANUAL, allowed only while no program runs (IDLE,
FINISHED, ABORTED) and no axis jogs; the monitors may veto (FCT-C14: manual mode entered outside the
work area). A refused change is an alarm, never a transition.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import StrEnum
from typing import Final

from mypy_extensions import mypyc_attr

from schemas.wire import Mode, ProgramState

__all__ = [
    "MODE_TRANSITIONS",
    "PROGRAM_TRANSITIONS",
    "Cause",
    "ChannelState",
    "StateTransitionError",
    "next_program_state",
]


class Cause(StrEnum):
    """What moves the program state (see the module docstring)."""

    LOAD = "load"
    START = "start"
    HOLD = "hold"
    RELEASE = "release"
    END = "end"
    ERROR = "error"
    RESET = "reset"


@mypyc_attr(native_class=False)  # mypyc compiles no subclass of RuntimeError (docs/performance.md)
class StateTransitionError(RuntimeError):
    """A transition the table does not list: a bug in the engine."""


# Final: a compiled module reads these directly (any other module-level name is a dictionary lookup)
_I: Final = ProgramState.IDLE
_R: Final = ProgramState.RUNNING
_H: Final = ProgramState.HELD
_A: Final = ProgramState.ABORTED
_F: Final = ProgramState.FINISHED

PROGRAM_TRANSITIONS: dict[tuple[ProgramState, Cause], ProgramState] = {
    (_I, Cause.LOAD): _I,
    (_F, Cause.LOAD): _I,
    (_A, Cause.LOAD): _I,
    (_I, Cause.START): _R,
    (_F, Cause.START): _R,
    (_R, Cause.HOLD): _H,
    (_H, Cause.RELEASE): _R,
    (_R, Cause.END): _F,
    (_H, Cause.END): _F,
    (_R, Cause.ERROR): _A,
    (_H, Cause.ERROR): _A,
    (_I, Cause.RESET): _I,
    (_R, Cause.RESET): _I,
    (_H, Cause.RESET): _I,
    (_A, Cause.RESET): _I,
    (_F, Cause.RESET): _I,
}
"""Every program-state transition (E-04). ABORTED leaves only by reset (or a new program): an error
is pending, so a start is refused until the reset clears it."""

MODE_TRANSITIONS: frozenset[tuple[Mode, Mode]] = frozenset(
    {(Mode.AUTOMATIC, Mode.MANUAL), (Mode.MANUAL, Mode.AUTOMATIC)}
)
"""Every mode change (E-03); each needs a channel without a running program (:data:`PROGRAM_IDLE`)."""

PROGRAM_ACTIVE: frozenset[ProgramState] = frozenset({_R, _H})
"""States in which a program runs: no mode change, no other program, no start."""


def next_program_state(state: ProgramState, cause: Cause) -> ProgramState:
    """The one place that decides a program-state change."""
    try:
        return PROGRAM_TRANSITIONS[(state, cause)]
    except KeyError:
        raise StateTransitionError(f"program state {state.name}: no transition on {cause.value!r}") from None


ProgramListener = Callable[[ProgramState, ProgramState, Cause], None]
ModeListener = Callable[[Mode, Mode], None]


class ChannelState:
    """The program state and mode of one channel; the only place that assigns them.

    ``on_program(new, previous, cause)`` and ``on_mode(new, previous)`` are called after every
    change (the channel turns them into events); a cause that leaves the state as it is (``load`` in
    IDLE, ``reset`` in IDLE) calls ``on_program`` too, because the cause itself is news (a reset)."""

    __slots__ = ("_mode", "_on_mode", "_on_program", "_program")

    def __init__(self, on_program: ProgramListener, on_mode: ModeListener) -> None:
        self._program = ProgramState.IDLE
        self._mode = Mode.AUTOMATIC
        self._on_program = on_program
        self._on_mode = on_mode

    @property
    def program(self) -> ProgramState:
        return self._program

    @property
    def mode(self) -> Mode:
        return self._mode

    @property
    def running(self) -> bool:
        """A program runs (RUNNING or HELD): :data:`PROGRAM_ACTIVE`, asked every cycle."""
        program = self._program
        return program is _R or program is _H

    def apply(self, cause: Cause) -> ProgramState:
        previous = self._program
        self._program = new = next_program_state(previous, cause)
        self._on_program(new, previous, cause)
        return new

    def set_held(self, held: bool) -> None:
        """RUNNING <-> HELD as the path rests under a hold or moves again; nothing in other states."""
        if held and self._program is _R:
            self.apply(Cause.HOLD)
        elif not held and self._program is _H:
            self.apply(Cause.RELEASE)

    def set_mode(self, mode: Mode) -> None:
        previous = self._mode
        if mode is previous:
            return
        if (previous, mode) not in MODE_TRANSITIONS:
            raise StateTransitionError(f"mode {previous.name} -> {mode.name} is not a transition")
        if self.running:
            raise StateTransitionError(f"mode change to {mode.name} while a program runs")
        self._mode = mode
        self._on_mode(mode, previous)
