"""The area state machine as a table (FCT-C14 Abb. 11; C14-09, C14-10, C14-12, C14-13)."""

from __future__ import annotations

import pytest

from hli_server.engine.areas import TRANSITIONS, AreaDefinition, AreaEvent, AreaState, AreaTable, Refusal
from hli_server.engine.nc.blocks import AreaKind, AreaShape


def definition(area_id: int) -> AreaDefinition:
    return AreaDefinition(
        area_id,
        AreaKind.WORK,
        AreaShape.POLY,
        ("X", "Y", "Z"),
        (0, 1, 2),
        -1.0,
        1.0,
        points=((0.0, 0.0), (1.0, 0.0), (1.0, 1.0)),
    )


@pytest.mark.req("C14-09", "C14-10", "C14-12", "C14-13")
def test_every_state_and_event_has_a_row() -> None:
    for state in (None, *AreaState):
        for event in AreaEvent:
            if state is None and event == AreaEvent.RESET:
                continue
            assert (state, event) in TRANSITIONS, (state, event)


@pytest.mark.req("C14-09", "C14-10", "C14-12", "C14-13")
def test_life_of_an_area() -> None:
    t = AreaTable()
    assert t.apply(1, AreaEvent.ON) == Refusal.UNKNOWN_ID
    assert t.apply(1, AreaEvent.DEFINE, definition(1)) is None
    assert t.state(1) == AreaState.DEFINED
    assert t.apply(1, AreaEvent.OFF) is None  # nothing to switch off
    assert t.state(1) == AreaState.DEFINED
    t.apply(1, AreaEvent.ON)
    assert t.state(1) == AreaState.ACTIVE
    assert t.apply(1, AreaEvent.DEFINE, definition(1)) == Refusal.ACTIVE_REDEFINE
    assert t.apply(1, AreaEvent.CLEAR) == Refusal.ACTIVE_CLEAR
    assert t.state(1) == AreaState.ACTIVE
    t.apply(1, AreaEvent.RESET)
    assert t.state(1) == AreaState.INACTIVE
    assert 1 in t.definitions  # a reset keeps the definition
    t.apply(1, AreaEvent.DEFINE, definition(1))
    assert t.state(1) == AreaState.DEFINED
    t.apply(1, AreaEvent.CLEAR)
    assert t.state(1) is None
    assert t.definitions == {}


@pytest.mark.req("C14-12")
def test_bare_off_takes_the_area_activated_last() -> None:
    t = AreaTable()
    for i in (1, 2, 3):
        t.apply(i, AreaEvent.DEFINE, definition(i))
    for i in (3, 1, 2):
        t.apply(i, AreaEvent.ON)
    assert t.last_activated() == 2
    t.apply(2, AreaEvent.OFF)
    assert t.last_activated() == 1


@pytest.mark.req("C14-14")
def test_groups_follow_the_active_areas() -> None:
    t = AreaTable()
    t.apply(1, AreaEvent.DEFINE, definition(1))
    assert t.groups() == []
    t.apply(1, AreaEvent.ON)
    (group,) = t.groups()
    assert [p.area_id for p in group.works] == [1]
    t.apply(1, AreaEvent.OFF)
    assert t.groups() == []
