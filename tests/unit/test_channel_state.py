"""The channel's program state and mode (issue 9): the table, every row, and a property test that the
state a PLC reads always agrees with the events and that no program moves without a start edge."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from hli_server.engine import Machine
from hli_server.engine.channel_state import (
    MODE_TRANSITIONS,
    PROGRAM_TRANSITIONS,
    Cause,
    ChannelState,
    StateTransitionError,
    next_program_state,
)
from schemas.events import AlarmRaised, Event, ModeChanged, ProgramStateChanged
from schemas.wire import Mode, ProgramState
from tests.unit.engine_helpers import mill, record_events

IDLE, R, H, A, F = (
    ProgramState.IDLE,
    ProgramState.RUNNING,
    ProgramState.HELD,
    ProgramState.ABORTED,
    ProgramState.FINISHED,
)


def test_every_state_is_reachable_and_every_row_is_a_transition() -> None:
    reachable = {IDLE} | set(PROGRAM_TRANSITIONS.values())
    assert reachable == set(ProgramState)
    for (state, cause), new in PROGRAM_TRANSITIONS.items():
        assert next_program_state(state, cause) == new
    for state in ProgramState:
        assert next_program_state(state, Cause.RESET) == IDLE  # reset from everywhere
    with pytest.raises(StateTransitionError, match="ABORTED: no transition on 'start'"):
        next_program_state(A, Cause.START)
    with pytest.raises(StateTransitionError):
        next_program_state(IDLE, Cause.END)
    assert set(MODE_TRANSITIONS) == {(Mode.AUTOMATIC, Mode.MANUAL), (Mode.MANUAL, Mode.AUTOMATIC)}


@pytest.mark.parametrize(("state", "cause"), sorted(PROGRAM_TRANSITIONS, key=lambda k: (k[0], k[1].value)))
def test_each_row_of_the_table_notifies_with_state_previous_and_cause(
    state: ProgramState, cause: Cause
) -> None:
    """Drive the state machine into ``state`` along the table, then apply the row's cause."""
    seen: list[tuple[ProgramState, ProgramState, Cause]] = []
    machine = ChannelState(lambda new, old, why: seen.append((new, old, why)), lambda new, old: None)
    path = {IDLE: [], R: [Cause.START], H: [Cause.START, Cause.HOLD], A: [Cause.START, Cause.ERROR]}
    path[F] = [Cause.START, Cause.END]
    for step in path[state]:
        machine.apply(step)
    assert machine.program == state
    seen.clear()
    machine.apply(cause)
    assert seen == [(PROGRAM_TRANSITIONS[(state, cause)], state, cause)]
    assert machine.program == PROGRAM_TRANSITIONS[(state, cause)]


def test_mode_changes_only_without_a_running_program() -> None:
    modes: list[tuple[Mode, Mode]] = []
    machine = ChannelState(lambda *_: None, lambda new, old: modes.append((new, old)))
    machine.set_mode(Mode.MANUAL)
    machine.set_mode(Mode.MANUAL)  # no change, no notification
    machine.set_mode(Mode.AUTOMATIC)
    assert modes == [(Mode.MANUAL, Mode.AUTOMATIC), (Mode.AUTOMATIC, Mode.MANUAL)]
    machine.apply(Cause.START)
    with pytest.raises(StateTransitionError, match="while a program runs"):
        machine.set_mode(Mode.MANUAL)


# --------------------------------------------------------------------------------------------
# On a machine: the causes happen for real
# --------------------------------------------------------------------------------------------

PROGRAM = "N10 G01 X20 F3000\nN20 G01 X0\nN30 M30\n"


def program_states(events: list[Event]) -> list[tuple[str, str]]:
    return [(e.state, e.cause) for e in events if isinstance(e, ProgramStateChanged)]


def test_a_machine_walks_the_table_start_hold_release_end() -> None:
    m = mill()
    events = record_events(m)
    ch = m.channel(1)
    ch.load_program(PROGRAM)
    ch.request_start()
    m.step(100)
    ch.request_feedhold(True)
    m.step(2000)
    assert ch.state == H
    ch.request_feedhold(False)
    m.step(20_000)
    assert ch.state == F
    assert program_states(events) == [
        ("idle", "load"),
        ("running", "start"),
        ("held", "hold"),
        ("running", "release"),
        ("finished", "end"),
    ]


def test_an_error_while_held_aborts_and_only_a_reset_or_a_new_program_leaves_aborted() -> None:
    m = mill()
    events = record_events(m)
    ch = m.channel(1)
    ch.load_program(PROGRAM)
    ch.request_start()
    m.step(100)
    ch.request_feedhold(True)
    m.step(2000)
    assert ch.state == H
    m.inject_fault("X", drive_error=True)  # 911030: the axes stop on their own, the path is lost
    m.step(5)
    assert ch.state == A
    ch.request_start()
    m.step(1)
    assert ch.state == A  # an error is pending: the start is refused, the state stays
    assert m.alarm_history[-1].number == 911021
    ch.request_reset()
    m.step(500)
    assert ch.state == IDLE
    assert program_states(events)[-3:] == [("held", "hold"), ("aborted", "error"), ("idle", "reset")]


@st.composite
def actions(draw: st.DrawFn) -> list[tuple[str, int]]:
    kinds = ["start", "reset", "feedhold_on", "feedhold_off", "load", "fault", "manual", "automatic", "step"]
    return draw(
        st.lists(
            st.tuples(st.sampled_from(kinds), st.integers(min_value=1, max_value=400)),
            min_size=1,
            max_size=14,
        )
    )


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(sequence=actions())
@example(sequence=[("load", 1), ("start", 1), ("step", 50), ("reset", 1), ("start", 1), ("step", 300)])
@example(sequence=[("load", 1), ("start", 1), ("step", 200), ("feedhold_on", 1), ("step", 300), ("reset", 1)])
def test_property_the_state_a_plc_reads_agrees_with_the_events_and_nothing_moves_without_a_start(
    sequence: list[tuple[str, int]],
) -> None:
    m: Machine = mill()
    events = record_events(m)
    ch = m.channel(1)
    bahn = m.hli.channels[0].bahn_state
    starts_requested = 0
    for kind, cycles in sequence:
        if kind == "start":
            ch.request_start()
            starts_requested += 1
        elif kind == "reset":
            ch.request_reset()
        elif kind == "feedhold_on":
            ch.request_feedhold(True)
        elif kind == "feedhold_off":
            ch.request_feedhold(False)
        elif kind == "load":
            ch.load_program(PROGRAM if cycles % 2 else "N10 G01 X5 Y5 F6000\nN20 X700\nN30 M30\n")
        elif kind == "fault":
            m.inject_fault("Y", drive_error=True)
        elif kind == "manual":
            ch.request_mode(Mode.MANUAL)
        elif kind == "automatic":
            ch.request_mode(Mode.AUTOMATIC)
        run = cycles if kind == "step" else 1
        for _ in range(run):
            before = [abs(a.setpoint_step) for a in ch.axes]
            state_before = ch.state
            n_events = len(events)
            m.step(1)
            new = events[n_events:]
            # the image shows what the table says, and what the last event said
            assert bahn.program_state_r == ch.state
            assert bahn.mode_r == ch.mode
            changes = [e for e in new if isinstance(e, ProgramStateChanged)]
            if changes:
                assert changes[-1].code == ch.state
            modes = [e for e in new if isinstance(e, ModeChanged)]
            if modes:
                assert modes[-1].mode == ch.mode.label
            # an abort always comes with its error alarm, in the same cycle (never silently)
            if any(e.cause == "error" for e in changes):
                assert any(isinstance(e, AlarmRaised) and e.alarm.severity == "error" for e in new), new
            # no program moves without a start edge: outside RUNNING/HELD an axis only brakes
            started = any(e.cause == "start" for e in changes)
            idle_throughout = state_before not in (R, H) and ch.state not in (R, H)
            if not started and idle_throughout and ch.mode == Mode.AUTOMATIC:
                after = [abs(a.setpoint_step) for a in ch.axes]
                assert all(b <= a + 1e-9 for a, b in zip(before, after, strict=True)), (kind, before, after)
    # every transition to running was a start the test asked for
    to_running = [e for e in events if isinstance(e, ProgramStateChanged) and e.state == "running"]
    assert all(e.cause in ("start", "release") for e in to_running)
    assert sum(e.cause == "start" for e in to_running) <= starts_requested
