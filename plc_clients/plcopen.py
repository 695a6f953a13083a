"""PLCopen function blocks over the HLI: MCV_DynPosLimitLow/High and a generic control-unit block
(C43-10, H-06, H-02; FCT-C43 sections 3.1.1 and 3.2).

IEC 61131-3 semantics: a block is an instance with inputs, outputs and memory; calling it
(``fb(Enable=True, Position=500_000)`` or setting ``fb.Enable`` and calling ``fb.execute()``) runs
one cycle of it on the current PLC task's process image (:class:`~plc_clients.task.IoImage`): it
reads the CNC->PLC fields of this cycle's input image and writes its outputs into the task's
output image, which the task sends at the end of the cycle. Inputs keep their values between
calls (an input not passed to ``__call__`` keeps the one it had).

MCV_DynPosLimitLow / MCV_DynPosLimitHigh (FCT-C43 3.2.1, 3.2.2)
================================================================

=========== ============ ====================================================================
VAR_IN_OUT  Axis         :class:`AXIS_REF`: index into ``gpAx[]`` (+ optional name, checked)
VAR_INPUT   Enable       BOOL: TRUE writes the limit to the HLI
VAR_INPUT   Position     DINT: the limit in 0.1 µm (rotary 0.0001°)
VAR_OUTPUT  Valid        BOOL: the CNC reports the limit in effect
VAR_OUTPUT  State        DINT: the position limit in effect, 0.1 µm (0 while not Valid; see below)
VAR_OUTPUT  Error        BOOL
VAR_OUTPUT  ErrorID      WORD: :class:`ErrorID`
(extension) MonitoringState DINT: ``state_r`` of the control unit, HLI_DYNPL_STATE_* (FCT-C43 3.1.1)
(extension) ErrorText    STRING: what went wrong, where, what to do (empty without error)
=========== ============ ====================================================================

The block drives the SGN32 control unit ``gpAx[Axis.index]^ipo_mc_control.dyn_pos_limit_low``
(``_high``), FCT-C43 3.1.1 (C43-02).

Decisions where the document leaves room:

* **State.** FCT-C43 3.2 gives ``State : DINT`` as "Aktueller Positionsgrenzwert", the position
  limit now in effect (docs/alarms.md: the document is followed to the letter). With Valid TRUE ("Ist TRUE,
  wenn die Sollwertvorgabe aktiviert ist") a limit is in effect, and it is the one the CNC took over:
  the ``command_w`` this block wrote and the CNC latched (the CNC offers no other read-back,
  ``request_r`` "wird derzeit nicht unterstützt", 3.1.1). So ``State`` is that value, in the unit of
  ``Position`` (0.1 µm, rotary 0.0001°); while the CNC has not yet latched a new ``Position``, the
  limit in effect is still the one before, and ``State`` says so. Without Valid no limit of this
  block is in effect and ``State`` is 0 (as PLCopen resets outputs; ``Valid`` tells a limit of 0 from
  none). An error latched while the limit stays in effect (see Errors) leaves ``State`` showing it
  as long as the CNC reports the monitoring on. The CNC adopts a moved limit only as
  P-CHAN-00874/00751 allow (docs/monitors.md): a change smaller than P-CHAN-00751 is latched but not
  taken over.
* **MonitoringState** (an output of our own, after ErrorID, like ErrorText): ``state_r`` of the
  control unit, the state of the monitoring, 0 INACTIVE, 1 ACTIVATION, 2 ACTIVE, 3 ACTIVE_BRAKING,
  4 ACTIVE_BRAKE (:class:`DynPosLimitState`, C43-03), which an earlier version gave as ``State``.
* **Valid** ("TRUE, wenn die Sollwertvorgabe aktiviert ist") is TRUE once the CNC reports the
  monitoring switched on: ``state_r`` >= 2 (ACTIVE, ACTIVE_BRAKING, ACTIVE_BRAKE). ACTIVATION (1)
  is the transition "until the monitoring of the axis position is activated" (3.1.1), so not yet
  Valid. A ``state_r`` counts only from an input image published after the CNC latched this
  block's ``enable_w`` (:meth:`IoImage.latched <plc_clients.task.IoImage.latched>`), so a state
  left over from an earlier enable never makes the block Valid. Valid does not drop while a new
  ``Position`` is taken over (the CNC gives no read-back of the value in effect).
* **Write order.** ``command_w`` before ``enable_w`` in the same cycle, so the CNC never latches
  an enable with an old limit (H-02, docs/process-image.md). While Enable is TRUE every change of
  ``Position`` is written (the PLC moves the limit, C43-07).
* **Errors** are latched until Enable goes FALSE (PLCopen's rule for Enable-type blocks). An error
  does not lift a limit that is in effect (lifting it could let the axis run into the obstacle the
  limit guards): only Enable FALSE clears ``enable_w``.
* **Axis** is taken at the rising edge of Enable; a change while Enable is TRUE takes effect at
  the next rising edge.
* **Activation timeout.** If the CNC does not report the limit in effect within
  ``activation_timeout_cycles`` CNC cycles (default 100) after the rising edge, the block errs
  with ACTIVATION_TIMEOUT: typically FCT_DYN_POS_LIMIT is missing in P-STUP-00070 of the axis'
  channel (C43-01; the CNC then leaves ``state_r`` at INACTIVE) or the axis is in no channel.
  The time is counted in CNC cycles (the input image's cycle), not task cycles, so a PLC task that
  runs faster than the CNC, or a stepped server that is not being stepped, never times out.
  If the CNC drops to INACTIVE later while Enable is TRUE (another PLC door cleared ``enable_w``,
  the server restarted) for as long, the block errs with LIMIT_LOST.

State table (:data:`TRANSITIONS`, :data:`OUTPUTS`; the rows are checked in this order every call)::

    Enable phase          condition                                -> phase  HLI writes / ErrorID
    ------ -------------- ---------------------------------------- -------- ---------------------------
    FALSE  any            the block had set enable_w               IDLE     enable_w := FALSE
    FALSE  any            otherwise                                IDLE     -
    TRUE   ERROR          -                                        ERROR    - (an active limit stays)
    TRUE   IDLE           Axis no AXIS_REF or not in the image     ERROR    AXIS_NOT_IN_IMAGE
    TRUE   IDLE           Axis.name differs from the image's       ERROR    AXIS_NAME_MISMATCH
    TRUE   not ERROR      transport failure (inputs, last outputs) ERROR    TRANSPORT_FAILURE
    TRUE   not ERROR      Position not a DINT                      ERROR    POSITION_OUT_OF_RANGE
    TRUE   IDLE           rising edge                              WAITING  command_w := Position,
                                                                            then enable_w := TRUE
    TRUE   WAITING/VALID  state_r >= 2 and enable_w latched        VALID    command_w := Position
    TRUE   VALID          otherwise                                WAITING  command_w := Position
    TRUE   WAITING        otherwise, deadline reached              ERROR    ACTIVATION_TIMEOUT
                                                                            (LIMIT_LOST if it was VALID)
    TRUE   WAITING        otherwise                                WAITING  command_w := Position

    phase    Valid  Error  State                      MonitoringState         ErrorID
    IDLE     FALSE  FALSE  0                          0                       0
    WAITING  FALSE  FALSE  0                          state_r                 0
    VALID    TRUE   FALSE  command_w the CNC latched  state_r                 0
    ERROR    FALSE  TRUE   the latched command_w      state_r (0 if unknown)  the error's
                           while enable_w stays set and state_r >= 2, else 0

"command_w := Position" is written to the task's output image every cycle; the task sends it only
when it changed.
Entering WAITING (rising edge, or VALID -> WAITING) sets the deadline to the input image's cycle
plus ``activation_timeout_cycles``.

ControlUnitBlock (H-02)
=======================

Any MC_CONTROL_BOOL_UNIT or MC_CONTROL_SGN32_UNIT by ST path (``gpCh[0]^bahn_mc_control.feedhold``,
``gpCh[0]^bahn_mc_control.override``, ...): inputs Enable, Command; outputs Valid, Request
(``request_r``), State (``state_r``), Error, ErrorID. With Enable TRUE it writes ``command_w`` then
``enable_w``; Valid is TRUE once the CNC has latched both (the control unit's contract: "with
enable_w set the CNC uses command_w"; what ``state_r`` means differs per unit, so it is passed
through, not interpreted). Same phases, same error latching; :class:`ControlBoolUnit` and
:class:`ControlSgn32Unit` insist on their unit type.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass
from enum import IntEnum, StrEnum
from typing import Any, ClassVar, Final, Self

from plc_clients.task import InputNotReadyError, IoImage, current_image
from plc_clients.transports import TransportError, Value
from schemas.layout import Layout, SignalType
from schemas.units import DINT_MAX, DINT_MIN

__all__ = [
    "AXIS_REF",
    "DEFAULT_ACTIVATION_TIMEOUT_CYCLES",
    "HLI_DYNPL_STATE_ACTIVATION",
    "HLI_DYNPL_STATE_ACTIVE",
    "HLI_DYNPL_STATE_ACTIVE_BRAKE",
    "HLI_DYNPL_STATE_ACTIVE_BRAKING",
    "HLI_DYNPL_STATE_INACTIVE",
    "OUTPUTS",
    "TRANSITIONS",
    "BlockEvent",
    "ControlBoolUnit",
    "ControlSgn32Unit",
    "ControlUnitBlock",
    "DynPosLimitState",
    "ErrorID",
    "FunctionBlock",
    "MCV_DynPosLimitHigh",
    "MCV_DynPosLimitLow",
    "Phase",
]

DEFAULT_ACTIVATION_TIMEOUT_CYCLES: Final = 100
"""CNC cycles the CNC has to report a dynamic limit in effect (the server needs 2)."""


class DynPosLimitState(IntEnum):
    """``state_r`` of the dyn_pos_limit control units, HLI_DYNPL_STATE_* (FCT-C43 3.1.1, C43-03)."""

    INACTIVE = 0
    ACTIVATION = 1
    ACTIVE = 2
    ACTIVE_BRAKING = 3
    ACTIVE_BRAKE = 4


HLI_DYNPL_STATE_INACTIVE: Final = DynPosLimitState.INACTIVE
HLI_DYNPL_STATE_ACTIVATION: Final = DynPosLimitState.ACTIVATION
HLI_DYNPL_STATE_ACTIVE: Final = DynPosLimitState.ACTIVE
HLI_DYNPL_STATE_ACTIVE_BRAKING: Final = DynPosLimitState.ACTIVE_BRAKING
HLI_DYNPL_STATE_ACTIVE_BRAKE: Final = DynPosLimitState.ACTIVE_BRAKE


class ErrorID(IntEnum):
    """``ErrorID`` (WORD) of the blocks in this module (project's own numbers, 0x91xx)."""

    NO_ERROR = 0x0000
    AXIS_NOT_IN_IMAGE = 0x9101
    """Axis is no AXIS_REF, or its index has no dyn_pos_limit unit in the image."""
    AXIS_NAME_MISMATCH = 0x9102
    """AXIS_REF.name differs from the name of the image's axis at that index."""
    POSITION_OUT_OF_RANGE = 0x9103
    """Position is not an integer in [DINT_MIN, DINT_MAX] (0.1 µm)."""
    TRANSPORT_FAILURE = 0x9104
    """The input image could not be read, or the outputs could not be written."""
    ACTIVATION_TIMEOUT = 0x9105
    """The CNC did not report the limit in effect in time (FCT_DYN_POS_LIMIT missing, C43-01)."""
    LIMIT_LOST = 0x9106
    """The CNC reported the limit INACTIVE for as long while Enable stayed TRUE."""
    UNIT_NOT_IN_IMAGE = 0x9107
    """ControlUnitBlock: no control unit (request_r, enable_w, command_w, state_r) at that ST path."""
    UNIT_TYPE_MISMATCH = 0x9108
    """ControlBoolUnit / ControlSgn32Unit on a unit of the other type."""
    COMMAND_OUT_OF_RANGE = 0x9109
    """ControlUnitBlock: Command does not fit the unit (BOOL, or DINT range)."""


# --------------------------------------------------------------------------------------------
# The state table (everything that moves a block's phase lives here)
# --------------------------------------------------------------------------------------------


class Phase(IntEnum):
    IDLE = 0
    """Enable FALSE: outputs cleared."""
    WAITING = 1
    """Enabled, the CNC does not (yet) report the command in effect."""
    VALID = 2
    """Enabled and in effect."""
    ERROR = 3
    """Latched until Enable FALSE."""


class BlockEvent(StrEnum):
    ENABLE = "enable"
    """Rising edge of Enable with a good Axis and Position: the command is written."""
    DISABLE = "disable"
    """Enable FALSE."""
    IN_EFFECT = "in_effect"
    """The CNC reports the command in effect."""
    NOT_IN_EFFECT = "not_in_effect"
    """It does not (yet), deadline not reached."""
    TIMEOUT = "timeout"
    """It does not, and the deadline is reached."""
    FAULT = "fault"
    """A bad input or a transport failure."""


_I, _W, _V, _E = Phase
TRANSITIONS: Final[dict[tuple[Phase, BlockEvent], Phase]] = {
    **{(p, BlockEvent.DISABLE): _I for p in Phase},
    (_I, BlockEvent.ENABLE): _W,
    (_I, BlockEvent.FAULT): _E,
    (_W, BlockEvent.IN_EFFECT): _V,
    (_W, BlockEvent.NOT_IN_EFFECT): _W,
    (_W, BlockEvent.TIMEOUT): _E,
    (_W, BlockEvent.FAULT): _E,
    (_V, BlockEvent.IN_EFFECT): _V,
    (_V, BlockEvent.NOT_IN_EFFECT): _W,
    (_V, BlockEvent.FAULT): _E,
}
"""(phase, event) -> phase. An event a phase does not expect is a bug (RuntimeError)."""

OUTPUTS: Final[dict[Phase, tuple[bool, bool]]] = {
    _I: (False, False),
    _W: (False, False),
    _V: (True, False),
    _E: (False, True),
}
"""phase -> (Valid, Error)."""


def _next(phase: Phase, event: BlockEvent) -> Phase:
    try:
        return TRANSITIONS[(phase, event)]
    except KeyError:
        raise RuntimeError(f"function block: event {event.value!r} in phase {phase.name}") from None


# --------------------------------------------------------------------------------------------
# AXIS_REF and the base block
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class AXIS_REF:  # noqa: N801 - the PLCopen type name
    """Axis reference (PLCopen): the axis' index in ``gpAx[]`` and, optionally, its name.

    A name is checked against the image's axis at that index when a block binds it.
    """

    index: int
    name: str | None = None

    @classmethod
    def by_name(cls, layout: Layout, name: str) -> AXIS_REF:
        """The reference of the axis called ``name`` in ``layout`` (``transport.layout``)."""
        for axis in layout.axes:
            if axis.name == name:
                return cls(axis.index, axis.name)
        names = ", ".join(a.name for a in layout.axes)
        raise KeyError(f"no axis {name!r} in the image of machine {layout.machine!r} (axes: {names})")

    def __str__(self) -> str:
        return f"gpAx[{self.index}]" + (f" ({self.name})" if self.name else "")


class FunctionBlock:
    """IEC 61131-3 function block: inputs, outputs, memory; one call = one cycle.

    Subclasses list their variables in ``VAR_IN_OUT``, ``VAR_INPUT`` and ``VAR_OUTPUT`` and
    implement :meth:`cycle`. ``fb(**inputs)`` sets the given inputs and runs :meth:`execute`.
    """

    VAR_IN_OUT: ClassVar[tuple[str, ...]] = ()
    VAR_INPUT: ClassVar[tuple[str, ...]] = ()
    VAR_OUTPUT: ClassVar[tuple[str, ...]] = ()

    def __init__(self, *, name: str | None = None) -> None:
        self.name = name or type(self).__name__

    def set_inputs(self, **inputs: Any) -> None:
        """Assign VAR_INPUT / VAR_IN_OUT variables; ``None`` keeps the current value."""
        allowed = self.VAR_IN_OUT + self.VAR_INPUT
        for key, value in inputs.items():
            if key not in allowed:
                raise TypeError(f"{self.name}: no input {key!r} (inputs: {', '.join(allowed)})")
            if value is not None:
                setattr(self, key, value)

    def __call__(self, **inputs: Any) -> Self:
        self.set_inputs(**inputs)
        return self.execute()

    def execute(self, io: IoImage | None = None) -> Self:
        """Run one cycle on ``io``, by default the image of the PLC task cycle running now."""
        image = io if io is not None else current_image()
        if image is None:
            raise RuntimeError(
                f"{self.name} was called outside a PLC task cycle: call it from the program of a "
                "PlcTask (plc_clients.task), or pass the task's image: execute(task.image)"
            )
        self.cycle(image)
        return self

    def cycle(self, io: IoImage) -> None:
        raise NotImplementedError

    def outputs(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.VAR_OUTPUT}

    def __repr__(self) -> str:
        outs = ", ".join(f"{k}={v!r}" for k, v in self.outputs().items())
        return f"{self.name}({outs})"


class _EnableBlock(FunctionBlock):
    """Enable-type block on one control unit: phases, error latching, the write discipline."""

    VAR_OUTPUT: ClassVar[tuple[str, ...]] = ("Valid", "State", "Error", "ErrorID")

    def __init__(self, *, name: str | None = None) -> None:
        super().__init__(name=name)
        self.Enable: bool = False
        self.Valid: bool = False
        self.State: Value = 0
        self.Error: bool = False
        self.ErrorID: int = ErrorID.NO_ERROR
        self.ErrorText: str = ""
        self.phase = Phase.IDLE
        self._unit: str | None = None
        """ST path of the bound control unit (without the field)."""
        self._armed = False
        """This block set enable_w TRUE (and must clear it at Enable FALSE)."""

    # --- phase and outputs ---------------------------------------------------------------------
    def _go(self, event: BlockEvent) -> None:
        self.phase = _next(self.phase, event)
        self.Valid, self.Error = OUTPUTS[self.phase]
        if self.phase is not Phase.ERROR:
            self.ErrorID = ErrorID.NO_ERROR
            self.ErrorText = ""

    def _fail(self, event: BlockEvent, error: ErrorID, text: str) -> None:
        self._go(event)
        self.ErrorID = error
        self.ErrorText = f"{self.name}: {text}"

    def _disable(self, io: IoImage) -> None:
        if self._armed and self._unit is not None:
            io.write(f"{self._unit}.enable_w", False)
        self._armed = False
        self._go(BlockEvent.DISABLE)
        self.State = 0
        self._reset_extra_outputs()

    def _reset_extra_outputs(self) -> None:
        return None

    def _read_state(self, io: IoImage, field: str = "state_r") -> Value | None:
        """A CNC->PLC field of the unit, None when not available this cycle."""
        if self._unit is None:
            return None
        try:
            return io.read(f"{self._unit}.{field}")
        except (InputNotReadyError, TransportError):
            return None

    def cycle(self, io: IoImage) -> None:
        if not self.Enable:
            self._disable(io)
            return
        if self.phase is Phase.ERROR:
            self._refresh(io)
            return
        rising = self.phase is Phase.IDLE
        if rising:
            problem = self._bind(io.layout)
            if problem is not None:
                self._unit = None
                self._fail(BlockEvent.FAULT, *problem)
                return
        fault = io.fault
        if fault is not None:
            self._refresh(io)
            self._fail(BlockEvent.FAULT, ErrorID.TRANSPORT_FAILURE, f"transport failure: {fault}; {_RESET}")
            return
        command = self._command()
        if isinstance(command, tuple):
            self._refresh(io)
            self._fail(BlockEvent.FAULT, *command)
            return
        unit = self._unit
        assert unit is not None
        self._before_write(io)
        io.write(f"{unit}.command_w", command)  # command before enable (H-02)
        io.write(f"{unit}.enable_w", True)
        self._armed = True
        if rising:
            self._go(BlockEvent.ENABLE)
            self._entered_waiting(io)
        self._refresh(io)
        self._evaluate(io)

    def _refresh(self, io: IoImage) -> None:
        """Outputs that follow the CNC (State, Request)."""
        state = self._read_state(io)
        if state is not None:
            self.State = state

    def _entered_waiting(self, io: IoImage) -> None:
        return None

    def _before_write(self, io: IoImage) -> None:
        """This cycle's command is about to be written: what the CNC latched of the last one is known now."""
        return

    # --- per block -------------------------------------------------------------------------------
    def _bind(self, layout: Layout) -> tuple[ErrorID, str] | None:
        raise NotImplementedError

    def _command(self) -> Value | tuple[ErrorID, str]:
        raise NotImplementedError

    def _evaluate(self, io: IoImage) -> None:
        raise NotImplementedError


_RESET: Final = "set Enable FALSE to reset the block"


# --------------------------------------------------------------------------------------------
# MCV_DynPosLimitLow / MCV_DynPosLimitHigh
# --------------------------------------------------------------------------------------------


class _DynPosLimit(_EnableBlock):
    """MCV_DynPosLimitLow/High (C43-10, FCT-C43 3.2): see the module docstring's state table."""

    SIDE: ClassVar[str] = ""
    VAR_IN_OUT: ClassVar[tuple[str, ...]] = ("Axis",)
    VAR_INPUT: ClassVar[tuple[str, ...]] = ("Enable", "Position")
    VAR_OUTPUT: ClassVar[tuple[str, ...]] = ("Valid", "State", "Error", "ErrorID", "MonitoringState")

    def __init__(
        self, *, name: str | None = None, activation_timeout_cycles: int = DEFAULT_ACTIVATION_TIMEOUT_CYCLES
    ) -> None:
        super().__init__(name=name)
        if activation_timeout_cycles < 1:
            raise ValueError(f"activation_timeout_cycles must be >= 1, got {activation_timeout_cycles}")
        self.Axis: AXIS_REF | None = None
        self.Position: int = 0
        self.activation_timeout_cycles = activation_timeout_cycles
        self.MonitoringState: Value = 0
        """``state_r`` of the control unit (HLI_DYNPL_STATE_*): the state of the monitoring."""
        self.bound_axis: AXIS_REF | None = None
        """The Axis taken at the rising edge of Enable."""
        self._deadline = 0
        self._was_valid = False
        self._latched_command: int | None = None
        """The ``command_w`` the CNC has latched (the limit in effect while Valid)."""

    def __call__(  # type: ignore[override]
        self,
        *,
        Axis: AXIS_REF | None = None,  # noqa: N803 - the PLCopen names
        Enable: bool | None = None,  # noqa: N803
        Position: int | None = None,  # noqa: N803
    ) -> Self:
        self.set_inputs(Axis=Axis, Enable=Enable, Position=Position)
        return self.execute()

    def _bind(self, layout: Layout) -> tuple[ErrorID, str] | None:
        axis = self.Axis
        if not isinstance(axis, AXIS_REF):
            return ErrorID.AXIS_NOT_IN_IMAGE, f"Axis must be an AXIS_REF, got {axis!r}; {_RESET}"
        unit = f"gpAx[{axis.index}]^ipo_mc_control.dyn_pos_limit_{self.SIDE}"
        names = ", ".join(f"{a.index} {a.name}" for a in layout.axes)
        if not all(f"{unit}.{f}" in layout for f in ("enable_w", "command_w", "state_r")):
            return ErrorID.AXIS_NOT_IN_IMAGE, (
                f"Axis {axis} is not in the image of machine {layout.machine!r} (axes: {names}); "
                f"use the index of an existing axis, then {_RESET}"
            )
        actual = layout.axes[axis.index].name if 0 <= axis.index < len(layout.axes) else None
        if axis.name is not None and actual != axis.name:
            return ErrorID.AXIS_NAME_MISMATCH, (
                f"Axis {axis}: the image's axis gpAx[{axis.index}] is {actual!r} (axes: {names}); "
                f"fix the AXIS_REF, then {_RESET}"
            )
        self.bound_axis = axis
        self._unit = unit
        return None

    def _command(self) -> Value | tuple[ErrorID, str]:
        position = self.Position
        try:
            value = operator.index(position) if not isinstance(position, bool) else None
        except TypeError:
            value = None
        if value is None or not DINT_MIN <= value <= DINT_MAX:
            return ErrorID.POSITION_OUT_OF_RANGE, (
                f"Position {position!r} is not a DINT in 0.1 µm [{DINT_MIN}, {DINT_MAX}] "
                f"(an active limit stays as it was); {_RESET}"
            )
        return value

    def _entered_waiting(self, io: IoImage) -> None:
        self._deadline = io.cycle + self.activation_timeout_cycles

    def _before_write(self, io: IoImage) -> None:
        path = f"{self._unit}.command_w"
        if io.latched(path):
            self._latched_command = int(io.read(path))

    def _refresh(self, io: IoImage) -> None:
        """MonitoringState follows the CNC's ``state_r``; State is set after the phase (:meth:`cycle`)."""
        state = self._read_state(io)
        if state is not None:
            self.MonitoringState = state

    def cycle(self, io: IoImage) -> None:
        super().cycle(io)
        latched = self._latched_command
        monitoring = int(self.MonitoringState) >= DynPosLimitState.ACTIVE
        if latched is not None and self._armed and (self.phase is Phase.VALID or monitoring):
            self.State = latched
        else:
            self.State = 0

    def _reset_extra_outputs(self) -> None:
        self.MonitoringState = 0
        self._latched_command = None

    def _evaluate(self, io: IoImage) -> None:
        unit = self._unit
        assert unit is not None
        state = self._read_state(io)
        in_effect = (
            state is not None and int(state) >= DynPosLimitState.ACTIVE and io.latched(f"{unit}.enable_w")
        )
        if in_effect:
            if self.phase is Phase.WAITING:
                self._was_valid = True
            self._go(BlockEvent.IN_EFFECT)
            return
        if self.phase is Phase.VALID:
            self._go(BlockEvent.NOT_IN_EFFECT)
            self._deadline = io.cycle + self.activation_timeout_cycles
            return
        if io.cycle >= self._deadline:
            n = self.activation_timeout_cycles
            if self._was_valid:
                self._fail(
                    BlockEvent.TIMEOUT,
                    ErrorID.LIMIT_LOST,
                    f"the CNC reports {unit} as {_state_name(state)} for {n} CNC cycles although this "
                    "block enabled it: another PLC door cleared enable_w, or the server restarted; "
                    f"{_RESET}",
                )
            else:
                self._fail(
                    BlockEvent.TIMEOUT,
                    ErrorID.ACTIVATION_TIMEOUT,
                    f"the CNC did not activate {unit} within {n} CNC cycles (state_r "
                    f"{_state_name(state)}): is FCT_DYN_POS_LIMIT in P-STUP-00070 "
                    "(configuration.channel[i].interpolator.function) of the axis' channel, and is the "
                    f"axis in a channel? {_RESET}",
                )
            return
        self._go(BlockEvent.NOT_IN_EFFECT)

    def _disable(self, io: IoImage) -> None:
        super()._disable(io)
        self._was_valid = False


def _state_name(state: Value | None) -> str:
    if state is None:
        return "not read"
    try:
        return f"{int(state)} {DynPosLimitState(int(state)).name}"
    except ValueError:
        return str(state)


class MCV_DynPosLimitLow(_DynPosLimit):  # noqa: N801 - the PLCopen name
    """The axis must not go below ``Position`` (FCT-C43 3.2.1): ``dyn_pos_limit_low``."""

    SIDE: ClassVar[str] = "low"


class MCV_DynPosLimitHigh(_DynPosLimit):  # noqa: N801 - the PLCopen name
    """The axis must not go above ``Position`` (FCT-C43 3.2.2): ``dyn_pos_limit_high``."""

    SIDE: ClassVar[str] = "high"


# --------------------------------------------------------------------------------------------
# The generic control unit block (H-02)
# --------------------------------------------------------------------------------------------

_UNIT_FIELDS: Final = ("request_r", "enable_w", "command_w", "state_r")


class ControlUnitBlock(_EnableBlock):
    """Any MC_CONTROL_BOOL_UNIT / MC_CONTROL_SGN32_UNIT by the ST path of the unit (H-02).

    ``unit``: ``gpCh[0]^bahn_mc_control.feedhold`` (the four fields are below it). Valid: the CNC
    has latched this block's ``enable_w`` and ``command_w`` (it drops while a new Command is
    taken over). Request and State pass ``request_r`` / ``state_r`` through.
    """

    VAR_INPUT: ClassVar[tuple[str, ...]] = ("Enable", "Command")
    VAR_OUTPUT: ClassVar[tuple[str, ...]] = ("Valid", "Request", "State", "Error", "ErrorID")
    KIND: ClassVar[SignalType | None] = None
    """The unit type this class insists on (None: either)."""

    def __init__(self, unit: str, *, name: str | None = None) -> None:
        super().__init__(name=name or f"{type(self).__name__}({unit})")
        self.unit = unit.rstrip(".")
        self.Command: Value = False if self.KIND is SignalType.BOOL else 0
        self.Request: Value = 0
        self.kind: SignalType | None = None
        """The bound unit's type (BOOL or DINT)."""

    def __call__(  # type: ignore[override]
        self,
        *,
        Enable: bool | None = None,  # noqa: N803 - PLCopen style names
        Command: Value | None = None,  # noqa: N803
    ) -> Self:
        self.set_inputs(Enable=Enable, Command=Command)
        return self.execute()

    def _bind(self, layout: Layout) -> tuple[ErrorID, str] | None:
        missing = [f for f in _UNIT_FIELDS if f"{self.unit}.{f}" not in layout]
        if missing:
            return ErrorID.UNIT_NOT_IN_IMAGE, (
                f"no control unit {self.unit!r} in the image of machine {layout.machine!r} "
                f"(missing {', '.join(missing)}; `hli-server map` lists the units); {_RESET}"
            )
        kind = layout.signal(f"{self.unit}.command_w").type
        if kind not in (SignalType.BOOL, SignalType.DINT):
            return ErrorID.UNIT_TYPE_MISMATCH, f"{self.unit} is a {kind} unit, not BOOL or SGN32; {_RESET}"
        if self.KIND is not None and kind is not self.KIND:
            want = "MC_CONTROL_BOOL_UNIT" if self.KIND is SignalType.BOOL else "MC_CONTROL_SGN32_UNIT"
            return ErrorID.UNIT_TYPE_MISMATCH, (
                f"{self.unit} is not a {want} (its command_w is {kind}); use "
                f"{'ControlSgn32Unit' if kind is SignalType.DINT else 'ControlBoolUnit'}; {_RESET}"
            )
        self.kind = kind
        self._unit = self.unit
        return None

    def _command(self) -> Value | tuple[ErrorID, str]:
        c: Any = self.Command
        if self.kind is SignalType.BOOL:
            if isinstance(c, bool) or (isinstance(c, int) and c in (0, 1)):
                return bool(c)
            return ErrorID.COMMAND_OUT_OF_RANGE, f"Command {c!r} is not a BOOL for {self.unit}; {_RESET}"
        try:
            value = operator.index(c) if not isinstance(c, bool) else None
        except TypeError:
            value = None
        if value is None or not DINT_MIN <= value <= DINT_MAX:
            return ErrorID.COMMAND_OUT_OF_RANGE, (
                f"Command {c!r} is not a DINT [{DINT_MIN}, {DINT_MAX}] for {self.unit}; {_RESET}"
            )
        return value

    def _refresh(self, io: IoImage) -> None:
        super()._refresh(io)
        request = self._read_state(io, "request_r")
        if request is not None:
            self.Request = request

    def _reset_extra_outputs(self) -> None:
        self.Request = 0

    def _evaluate(self, io: IoImage) -> None:
        unit = self.unit
        latched = io.latched(f"{unit}.enable_w") and io.latched(f"{unit}.command_w")
        self._go(BlockEvent.IN_EFFECT if latched else BlockEvent.NOT_IN_EFFECT)


class ControlBoolUnit(ControlUnitBlock):
    """MC_CONTROL_BOOL_UNIT (Command BOOL), e.g. ``gpCh[0]^bahn_mc_control.feedhold``."""

    KIND: ClassVar[SignalType | None] = SignalType.BOOL


class ControlSgn32Unit(ControlUnitBlock):
    """MC_CONTROL_SGN32_UNIT (Command DINT), e.g. ``gpCh[0]^bahn_mc_control.override`` (0.1 %)."""

    KIND: ClassVar[SignalType | None] = SignalType.DINT
