"""PLCopen blocks MCV_DynPosLimitLow/High and the control-unit block against the memory twin
(C43-10, H-06, H-02; FCT-C43 3.1.1, 3.2).

The twin (:class:`MemoryImage`) plays the CNC with a small model of the dyn_pos_limit unit that
moves ``state_r`` as the server's engine does (hli_server/engine/monitors/dyn_pos_limit.py:
enable -> 1 ACTIVATION -> next cycle 2 ACTIVE; enable off -> 0); tests set 3/4 themselves. Every
rig cycle is one PLC task cycle followed by one CNC cycle, so the traces are exact.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import pytest

from hli_server.configuration import load_machine
from plc_clients import (
    AXIS_REF,
    AsyncMemoryTransport,
    ControlBoolUnit,
    ControlSgn32Unit,
    ControlUnitBlock,
    DynPosLimitState,
    ErrorID,
    MCV_DynPosLimitHigh,
    MCV_DynPosLimitLow,
    MemoryImage,
    MemoryTransport,
    PlcTask,
    TransportError,
)
from plc_clients.plcopen import OUTPUTS, TRANSITIONS, BlockEvent, Phase
from plc_clients.task import IoImage
from schemas.layout import Layout, build_layout

pytestmark = pytest.mark.req("C43-10", "H-06")

HIGH = "gpAx[0]^ipo_mc_control.dyn_pos_limit_high"
LOW = "gpAx[0]^ipo_mc_control.dyn_pos_limit_low"
X = AXIS_REF(0, "X")
INACTIVE, ACTIVATION, ACTIVE, BRAKING, BRAKE = (int(s) for s in DynPosLimitState)


@pytest.fixture(scope="module")
def layout() -> Layout:
    return build_layout(load_machine(None))


def dyn_limit_cnc(unit: str, *, configured: bool = True) -> Callable[[MemoryImage], None]:
    """The CNC side of one dyn_pos_limit unit, as the engine moves it (FCT-C43 3.1.1, C43-03).

    ``configured=False``: the channel lacks FCT_DYN_POS_LIMIT, state_r stays INACTIVE (C43-01).
    States 3 and 4 are left to the test (it sets them with ``image.set``).
    """

    def model(image: MemoryImage) -> None:
        enabled = bool(image.latched[f"{unit}.enable_w"])
        state = int(image.get(f"{unit}.state_r"))
        if not (configured and enabled):
            new = INACTIVE
        elif state == INACTIVE:
            new = ACTIVATION
        elif state == ACTIVATION:
            new = ACTIVE
        else:
            new = state
        image.set(f"{unit}.state_r", new)

    return model


@dataclass
class Rig:
    """A PLC task with one block on a memory twin; ``cycle()`` = one task cycle + one CNC cycle."""

    image: MemoryImage
    task: PlcTask
    block: Any
    trace: list[tuple[int, int, bool, bool, int]] = field(default_factory=list)

    def cycle(self, count: int = 1, *, cnc: bool = True) -> None:
        for _ in range(count):
            self.task.run_cycle()
            b = self.block
            # the CNC's state: MonitoringState of a dyn_pos_limit block, State of a control-unit block
            state = b.MonitoringState if hasattr(b, "MonitoringState") else b.State
            self.trace.append((self.task.image.cycle, state, b.Valid, b.Error, int(b.ErrorID)))
            if cnc:
                self.image.step()

    def writes(self) -> list[tuple[str, object]]:
        """The PLC's writes since the last call: (field, value)."""
        out = [(path.rsplit(".", 1)[1], v) for _, path, v in self.image.writes]
        self.image.writes.clear()
        return out

    @property
    def unit_state(self) -> int:
        return int(self.image.published[f"{HIGH}.state_r"])


def rig(
    layout: Layout,
    block: Any = None,
    *,
    configured: bool = True,
    units: tuple[str, ...] = (HIGH, LOW),
    **inputs: Any,
) -> Rig:
    image = MemoryImage(layout)
    image.models.extend(dyn_limit_cnc(u, configured=configured) for u in units)
    block = block if block is not None else MCV_DynPosLimitHigh()
    block.set_inputs(**inputs)
    task = PlcTask(MemoryTransport(image), 0.001, block)
    return Rig(image, task, block)


# ================================================================================================
# The state table
# ================================================================================================


def test_the_table_covers_every_phase_and_refuses_unexpected_events() -> None:
    assert set(OUTPUTS) == set(Phase)
    assert OUTPUTS[Phase.VALID] == (True, False)
    assert OUTPUTS[Phase.ERROR] == (False, True)
    for phase in Phase:
        assert TRANSITIONS[(phase, BlockEvent.DISABLE)] is Phase.IDLE
    assert (Phase.IDLE, BlockEvent.IN_EFFECT) not in TRANSITIONS
    assert (Phase.ERROR, BlockEvent.ENABLE) not in TRANSITIONS  # an error is left only by Enable FALSE


def test_enable_writes_command_before_enable_and_goes_valid_once_the_cnc_is_active(layout: Layout) -> None:
    r = rig(layout, Axis=X, Enable=True, Position=500_000)
    r.cycle()
    assert r.writes() == [("command_w", 500_000), ("enable_w", True)]  # H-02: command first
    r.cycle(4)
    # (CNC cycle of the inputs, MonitoringState, Valid, Error, ErrorID), one row per task cycle:
    # the write is delivered after cycle 0's inputs; the inputs of cycle 1 date it, so state_r counts
    # from CNC cycle 1 + LATCH_MARGIN = 3 on (a state left over from an earlier enable cannot count)
    assert r.trace == [
        (0, INACTIVE, False, False, 0),
        (1, ACTIVATION, False, False, 0),
        (2, ACTIVE, False, False, 0),
        (3, ACTIVE, True, False, 0),
        (4, ACTIVE, True, False, 0),
    ]
    assert r.writes() == []  # unchanged outputs are not sent again
    assert r.block.phase is Phase.VALID


def test_monitoring_state_follows_the_cnc_and_valid_holds_while_braking(layout: Layout) -> None:
    r = rig(layout, Axis=X, Enable=True, Position=500_000)
    r.cycle(4)
    seen = []
    for cnc_state in (BRAKING, BRAKING, BRAKE, BRAKE, ACTIVE):
        r.image.set(f"{HIGH}.state_r", cnc_state)
        r.image.step()
        r.cycle(cnc=False)
        seen.append((r.block.MonitoringState, r.block.State, r.block.Valid))
    assert seen == [
        (3, 500_000, True),
        (3, 500_000, True),
        (4, 500_000, True),
        (4, 500_000, True),
        (2, 500_000, True),
    ]


@pytest.mark.req("C43-10")
def test_state_is_the_position_limit_in_effect(layout: Layout) -> None:
    """FCT-C43 3.2.1/3.2.2: ``State : DINT`` "Aktueller Positionsgrenzwert" (the position limit now in
    effect; the kernel's page of the block says the same, https://infosys.beckhoff.com/content/1033/
    tf5200_dynposlimit/192559627487822603.html): the Position the CNC took over, 0 while none is."""
    r = rig(layout, Axis=X, Enable=True, Position=500_000)
    states = []
    for _ in range(4):
        r.cycle()
        states.append((r.block.State, r.block.Valid))
    assert states == [(0, False), (0, False), (0, False), (500_000, True)]
    r.block.Position = 450_000  # C43-07: the PLC moves the limit
    r.cycle()
    assert r.block.State == 500_000  # the CNC has not latched the new one yet: the old one is in effect
    r.cycle(3)
    assert (r.block.State, r.block.Valid) == (450_000, True)
    r.block.Enable = False
    r.cycle()
    assert (r.block.State, r.block.MonitoringState, r.block.Valid) == (0, 0, False)


def test_enable_false_clears_enable_w_and_the_outputs_at_once(layout: Layout) -> None:
    r = rig(layout, Axis=X, Enable=True, Position=500_000)
    r.cycle(5)
    r.writes()
    r.block.Enable = False
    r.cycle()
    assert r.writes() == [("enable_w", False)]  # command_w is left as it was
    assert (r.block.Valid, r.block.State, r.block.Error, r.block.ErrorID) == (False, 0, False, 0)
    assert r.block.phase is Phase.IDLE
    r.cycle(2)
    assert r.unit_state == INACTIVE
    assert r.writes() == []  # nothing more while Enable stays FALSE


def test_a_block_that_was_never_enabled_writes_nothing(layout: Layout) -> None:
    r = rig(layout, Axis=X, Enable=False, Position=500_000)
    r.cycle(3)
    assert r.writes() == []
    assert r.trace[-1] == (2, 0, False, False, 0)


def test_a_new_position_is_written_alone_and_valid_stays(layout: Layout) -> None:
    r = rig(layout, Axis=X, Enable=True, Position=500_000)
    r.cycle(4)
    r.writes()
    r.block.Position = 450_000  # C43-07: the PLC moves the limit
    r.cycle(3)
    assert r.writes() == [("command_w", 450_000)]
    assert all(valid for _, _, valid, _, _ in r.trace[-3:])


def test_low_and_high_drive_their_own_units(layout: Layout) -> None:
    image = MemoryImage(layout)
    y_low = "gpAx[1]^ipo_mc_control.dyn_pos_limit_low"
    image.models += [dyn_limit_cnc(HIGH), dyn_limit_cnc(y_low)]
    low, high = MCV_DynPosLimitLow(), MCV_DynPosLimitHigh()
    y = AXIS_REF(1, "Y")

    def program(io: IoImage) -> None:
        low(Axis=y, Enable=True, Position=-100_000)
        high(Axis=X, Enable=True, Position=900_000)

    task = PlcTask(MemoryTransport(image), 0.001, program)
    for _ in range(5):
        task.run_cycle()
        image.step()
    assert image.outputs[f"{y_low}.command_w"] == -100_000
    assert image.outputs["gpAx[1]^ipo_mc_control.dyn_pos_limit_high.enable_w"] is False
    assert image.outputs[f"{HIGH}.command_w"] == 900_000
    assert image.outputs[f"{LOW}.enable_w"] is False
    assert low.Valid
    assert high.Valid


def test_the_block_can_be_called_with_its_inputs_inside_a_program(layout: Layout) -> None:
    image = MemoryImage(layout)
    image.models.append(dyn_limit_cnc(HIGH))
    fb = MCV_DynPosLimitHigh()
    outputs = []
    task = PlcTask(
        MemoryTransport(image), 0.001, lambda io: outputs.append(fb(Axis=X, Enable=True, Position=1).Valid)
    )
    for _ in range(4):
        task.run_cycle()
        image.step()
    assert outputs == [False, False, False, True]
    assert fb.Position == 1
    fb.set_inputs(Enable=None)  # None keeps the input
    assert fb.Enable is True


def test_a_state_left_over_from_an_earlier_enable_does_not_make_the_block_valid(layout: Layout) -> None:
    r = rig(layout, Axis=X, Enable=True, Position=500_000)
    r.image.models.clear()  # a CNC that still shows ACTIVE from before, whatever the PLC writes
    r.image.set(f"{HIGH}.state_r", ACTIVE)
    r.image.step()
    r.cycle(4)
    assert [row[1:3] for row in r.trace] == [(ACTIVE, False)] * 3 + [(ACTIVE, True)]


# ================================================================================================
# Errors
# ================================================================================================


@pytest.mark.parametrize("axis", [AXIS_REF(6), AXIS_REF(-1), AXIS_REF(99, "X"), 0, None, "X"])
def test_an_axis_that_is_not_in_the_image_is_an_error_and_nothing_is_written(
    layout: Layout, axis: object
) -> None:
    r = rig(layout, Axis=axis, Enable=True, Position=500_000)
    r.cycle(2)
    assert (r.block.Valid, r.block.Error, r.block.ErrorID) == (False, True, ErrorID.AXIS_NOT_IN_IMAGE)
    assert r.block.ErrorID == 0x9101
    assert "Enable FALSE" in r.block.ErrorText
    if isinstance(axis, AXIS_REF):
        assert "axes: 0 X, 1 Y, 2 Z, 3 X1, 4 X2, 5 Z1" in r.block.ErrorText
    r.block.Enable = False
    r.cycle()
    assert r.writes() == []
    assert (r.block.Error, r.block.ErrorID) == (False, 0)


def test_an_axis_name_that_differs_from_the_image_is_an_error(layout: Layout) -> None:
    r = rig(layout, Axis=AXIS_REF(1, "X"), Enable=True, Position=500_000)
    r.cycle()
    assert r.block.ErrorID == ErrorID.AXIS_NAME_MISMATCH
    assert "gpAx[1] is 'Y'" in r.block.ErrorText
    assert r.writes() == []
    assert AXIS_REF.by_name(layout, "Y") == AXIS_REF(1, "Y")
    with pytest.raises(KeyError, match="axes: X, Y, Z, X1, X2, Z1"):
        AXIS_REF.by_name(layout, "Q")


@pytest.mark.parametrize("position", [2**31, -(2**31) - 1, 1.5, True, "500000", None])
def test_a_position_out_of_dint_range_at_the_rising_edge_is_an_error(
    layout: Layout, position: object
) -> None:
    block = MCV_DynPosLimitHigh()
    block.Position = position  # type: ignore[assignment]
    r = rig(layout, block, Axis=X, Enable=True)
    r.cycle()
    assert (r.block.Error, r.block.ErrorID) == (True, ErrorID.POSITION_OUT_OF_RANGE)
    assert r.writes() == []


def test_the_dint_limits_themselves_are_accepted(layout: Layout) -> None:
    for position in (2**31 - 1, -(2**31)):
        r = rig(layout, Axis=X, Enable=True, Position=position)
        r.cycle()
        assert not r.block.Error
        assert r.writes()[0] == ("command_w", position)


def test_a_bad_position_while_valid_keeps_the_limit_and_latches_until_enable_false(layout: Layout) -> None:
    r = rig(layout, Axis=X, Enable=True, Position=500_000)
    r.cycle(4)
    r.writes()
    r.block.Position = 2**40
    r.cycle(3)
    assert (r.block.Valid, r.block.Error, r.block.ErrorID) == (False, True, ErrorID.POSITION_OUT_OF_RANGE)
    assert r.block.MonitoringState == ACTIVE  # the CNC's state is still shown
    assert r.block.State == 500_000  # and the limit, which stays in effect
    assert r.writes() == []  # the active limit stays: an error does not lift it
    assert r.image.outputs[f"{HIGH}.enable_w"] is True
    r.block.Position = 500_000  # a good value alone does not clear the latched error
    r.cycle()
    assert r.block.Error
    r.block.Enable = False
    r.cycle()
    assert r.writes() == [("enable_w", False)]
    assert not r.block.Error


def test_a_transport_failure_of_the_inputs_is_an_error_until_enable_false(layout: Layout) -> None:
    r = rig(layout, Axis=X, Enable=True, Position=500_000)
    r.cycle(4)
    r.image.fault = TransportError("connection reset by peer")
    r.cycle(cnc=False)
    assert (r.block.Valid, r.block.Error, r.block.ErrorID) == (False, True, ErrorID.TRANSPORT_FAILURE)
    assert "connection reset by peer" in r.block.ErrorText
    assert r.task.stats.input_faults == 1
    r.image.fault = None
    r.cycle(2)
    assert r.block.ErrorID == ErrorID.TRANSPORT_FAILURE  # latched
    r.block.Enable = False
    r.cycle(2)
    r.block.Enable = True
    r.cycle(5)
    assert (r.block.Valid, r.block.Error) == (True, False)


def test_outputs_that_could_not_be_written_are_an_error_and_are_sent_again(layout: Layout) -> None:
    image = MemoryImage(layout)
    image.models.append(dyn_limit_cnc(HIGH))
    fb = MCV_DynPosLimitHigh()
    broken = [True]

    def program(io: IoImage) -> None:
        fb(Axis=X, Enable=True, Position=500_000)
        if broken[0]:
            image.fault = TransportError("write timed out")  # the snapshot worked, the write fails

    task = PlcTask(MemoryTransport(image), 0.001, program)
    task.run_cycle()
    assert task.stats.output_faults == 1
    assert image.outputs[f"{HIGH}.enable_w"] is False
    image.fault = None
    broken[0] = False
    task.run_cycle()
    assert (fb.Error, fb.ErrorID) == (True, ErrorID.TRANSPORT_FAILURE)
    assert "write timed out" in fb.ErrorText
    # the block is in error, but what it wrote before was still pending and is delivered now
    assert image.outputs[f"{HIGH}.command_w"] == 500_000
    assert image.outputs[f"{HIGH}.enable_w"] is True
    assert [p.rsplit(".", 1)[1] for _, p, _ in image.writes] == ["command_w", "enable_w"]


def test_no_activation_within_the_timeout_is_an_error_naming_fct_dyn_pos_limit(layout: Layout) -> None:
    r = rig(layout, MCV_DynPosLimitHigh(activation_timeout_cycles=10), configured=False)
    r.block.set_inputs(Axis=X, Enable=True, Position=500_000)
    r.cycle(10)
    assert not r.block.Error  # inputs of CNC cycles 0..9: the deadline is cycle 0 + 10
    r.cycle()
    assert (r.block.Error, r.block.ErrorID, r.block.MonitoringState) == (
        True,
        ErrorID.ACTIVATION_TIMEOUT,
        INACTIVE,
    )
    assert r.block.State == 0  # no limit in effect
    assert "FCT_DYN_POS_LIMIT" in r.block.ErrorText
    assert "P-STUP-00070" in r.block.ErrorText
    assert r.image.outputs[f"{HIGH}.enable_w"] is True  # left as it is until Enable FALSE


def test_the_timeout_counts_cnc_cycles_not_task_cycles(layout: Layout) -> None:
    r = rig(layout, MCV_DynPosLimitHigh(activation_timeout_cycles=10), configured=False)
    r.block.set_inputs(Axis=X, Enable=True, Position=500_000)
    r.cycle(50, cnc=False)  # a task faster than the CNC, or a stepped server nobody steps
    assert not r.block.Error
    r.image.step(10)
    r.cycle(cnc=False)
    assert r.block.ErrorID == ErrorID.ACTIVATION_TIMEOUT


def test_the_cnc_dropping_the_limit_while_enabled_is_an_error_after_the_timeout(layout: Layout) -> None:
    r = rig(layout, MCV_DynPosLimitHigh(activation_timeout_cycles=5))
    r.block.set_inputs(Axis=X, Enable=True, Position=500_000)
    r.cycle(4)
    assert r.block.Valid
    other_door = MemoryTransport(r.image)
    other_door.write(f"{HIGH}.enable_w", False)  # someone else clears enable_w
    r.cycle(2)
    assert (r.block.Valid, r.block.Error, r.block.MonitoringState) == (
        False,
        False,
        INACTIVE,
    )  # waiting, grace
    assert r.block.State == 0
    r.cycle(5)
    assert (r.block.Error, r.block.ErrorID) == (True, ErrorID.LIMIT_LOST)
    assert "another PLC door" in r.block.ErrorText


async def test_an_input_that_an_asyncio_transport_has_not_read_yet_is_no_input(layout: Layout) -> None:
    image = MemoryImage(layout)
    image.set(f"{HIGH}.state_r", ACTIVE)  # would be visible at once if the snapshot held it
    image.step()
    fb = MCV_DynPosLimitHigh()
    fb.set_inputs(Axis=X, Enable=True, Position=500_000)
    task = PlcTask(AsyncMemoryTransport(image), 0.001, fb)
    await task.run_cycle_async()
    assert (fb.MonitoringState, fb.Valid, fb.Error) == (0, False, False)  # not in the input image yet
    assert f"{HIGH}.state_r" in task.image.watch  # ... from the next cycle on
    await task.run_cycle_async()
    assert fb.MonitoringState == ACTIVE
    assert image.outputs[f"{HIGH}.enable_w"] is True


def test_a_block_outside_a_task_and_unknown_inputs_are_refused(layout: Layout) -> None:
    fb = MCV_DynPosLimitHigh()
    with pytest.raises(RuntimeError, match="outside a PLC task cycle"):
        fb(Axis=X, Enable=True, Position=1)
    with pytest.raises(TypeError, match="no input 'Velocity'"):
        fb.set_inputs(Velocity=3)
    with pytest.raises(ValueError, match="activation_timeout_cycles"):
        MCV_DynPosLimitHigh(activation_timeout_cycles=0)
    image = MemoryImage(layout)
    task = PlcTask(MemoryTransport(image), 0.001, lambda io: None)
    fb.execute(task.image)  # an explicit image works outside the program (sent by the next cycle)
    assert task.image.outputs_to_send()[-1] == (f"{HIGH}.enable_w", True)
    assert "Valid=False" in repr(fb)


# ================================================================================================
# The generic control-unit block (H-02)
# ================================================================================================

FEEDHOLD = "gpCh[0]^bahn_mc_control.feedhold"
OVERRIDE = "gpCh[0]^bahn_mc_control.override"


def unit_rig(layout: Layout, block: ControlUnitBlock, **inputs: Any) -> Rig:
    return rig(layout, block, units=(), **inputs)


@pytest.mark.req("H-02")
def test_control_unit_block_bool_writes_command_then_enable_and_is_valid_once_latched(layout: Layout) -> None:
    r = unit_rig(layout, ControlBoolUnit(FEEDHOLD), Enable=True, Command=True)
    r.image.set(f"{FEEDHOLD}.request_r", False)
    r.image.set(f"{FEEDHOLD}.state_r", True)
    r.cycle()
    assert r.writes() == [("command_w", True), ("enable_w", True)]
    r.cycle(3)
    assert [row[2] for row in r.trace] == [False, False, False, True]
    assert (r.block.Request, r.block.State) == (False, True)
    r.block.Command = False  # a new command: Valid drops until the CNC has latched it
    r.cycle()
    assert r.writes() == [("command_w", False)]
    assert not r.block.Valid
    r.cycle(3)
    assert r.block.Valid
    r.block.Enable = False
    r.cycle()
    assert r.writes() == [("enable_w", False)]
    assert (r.block.Valid, r.block.Request, r.block.State) == (False, 0, 0)


@pytest.mark.req("H-02")
def test_control_unit_block_sgn32_and_the_generic_block_take_the_units_type(layout: Layout) -> None:
    r = unit_rig(layout, ControlSgn32Unit(OVERRIDE), Enable=True, Command=500)
    r.cycle(4)
    assert r.image.outputs[f"{OVERRIDE}.command_w"] == 500
    assert r.block.Valid
    generic = unit_rig(layout, ControlUnitBlock(FEEDHOLD + "."), Enable=True, Command=1)
    generic.cycle()
    assert generic.block.kind is not None
    assert generic.block.kind.value == "BOOL"
    assert generic.image.outputs[f"{FEEDHOLD}.command_w"] is True


@pytest.mark.req("H-02")
@pytest.mark.parametrize(
    ("block", "command", "error"),
    [
        (ControlBoolUnit("gpCh[0]^bahn_mc_control.no_such_unit"), True, ErrorID.UNIT_NOT_IN_IMAGE),
        (ControlBoolUnit("gpCh[0]^bahn_state.mode_r"), True, ErrorID.UNIT_NOT_IN_IMAGE),
        (ControlBoolUnit(OVERRIDE), True, ErrorID.UNIT_TYPE_MISMATCH),
        (ControlSgn32Unit(FEEDHOLD), 1, ErrorID.UNIT_TYPE_MISMATCH),
        (ControlSgn32Unit(OVERRIDE), 2**31, ErrorID.COMMAND_OUT_OF_RANGE),
        (ControlSgn32Unit(OVERRIDE), 1.0, ErrorID.COMMAND_OUT_OF_RANGE),
        (ControlBoolUnit(FEEDHOLD), 2, ErrorID.COMMAND_OUT_OF_RANGE),
    ],
)
def test_control_unit_block_errors(
    layout: Layout, block: ControlUnitBlock, command: object, error: ErrorID
) -> None:
    r = unit_rig(layout, block, Enable=True)
    block.Command = command  # type: ignore[assignment]
    r.cycle(2)
    assert (block.Valid, block.Error, block.ErrorID) == (False, True, error)
    assert r.writes() == []
    block.Enable = False
    r.cycle()
    assert (block.Error, block.ErrorID) == (False, ErrorID.NO_ERROR)
