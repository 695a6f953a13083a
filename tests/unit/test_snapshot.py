"""The snapshot of the engine's state a recording started in a running server carries (issue 37, item 2;
``hli_server/recording/snapshot.py``): taken, written as JSON, read back into a machine built from the
same configuration, the machine goes on exactly as the one it was taken from; a malformed or hostile
snapshot is refused with a reason, never executed."""

from __future__ import annotations

import copy
import json
from typing import Any

import pytest

from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.recording.snapshot import (
    SnapshotError,
    SnapshotRestoreError,
    capture,
    engine_fingerprint,
    restore,
)
from schemas.events import Event
from tests.spec_examples import CIRC_PROT_OLD
from tests.unit.test_cycles_programs import SPIGOT

# a loop with a local variable, an arc, an active protection area beside the path, a message, a V.E. write
PROGRAM = (
    CIRC_PROT_OLD
    + "N50 G01 X0 Y-100 Z0 F6000\n"
    + "N60 #CONTROL AREA ON [ID4]\n"
    + "N70 $FOR P1 = 1, 50, 1\n"
    + '#MSG["pass %d", P1]\n'
    + "N80   G01 X[40 + P1] Y-100\n"
    + "N90   G02 X[40 + P1] Y-80 I0 J10\n"
    + "N100  G01 X0 Y-80\n"
    + "N110  V.E.MODE = V.E.MODE + 1\n"
    + "N112  V.E.PART_COUNT = P1\n"  # synchronous: written when the path gets there
    + '#MSG SYN["reached %d", P1]\n'
    + "N114  #SLOPE [TYPE=TRAPEZ]\n"
    + "N120 $ENDFOR\n"
    + "N130 M30\n"
)


def machine() -> tuple[Machine, list[Event]]:
    m = Machine(load_machine(None))
    events: list[Event] = []
    m.event_listeners.append(events.append)
    return m, events


def running(cycles: int) -> tuple[Machine, list[Event]]:
    m, events = machine()
    ch = m.channel(1)
    ch.load_program(PROGRAM, "busy")
    ch.request_start()
    m.axis("Y").faults.gain_factor = 0.95
    m.step(cycles)
    return m, events


def as_json(data: dict[str, Any]) -> dict[str, Any]:
    """What a recording holds: the snapshot through JSON text."""
    out: dict[str, Any] = json.loads(json.dumps(data, allow_nan=False))
    return out


@pytest.mark.req("E-01", "B-02")
@pytest.mark.parametrize("cycles", [1, 700, 2300])
def test_a_restored_machine_goes_on_exactly_as_the_one_it_was_taken_from(cycles: int) -> None:
    live, live_events = running(cycles)
    taken = as_json(capture(live))
    assert taken["cycle"] == cycles
    assert taken["fingerprint"] == engine_fingerprint()
    twin, twin_events = machine()
    restore(taken, twin)
    assert as_json(capture(twin)) == taken  # the same state, object for object
    live_events.clear()
    for _ in range(20):
        live.step(150)
        twin.step(150)
        assert capture(twin) == capture(live), f"the machines differ at cycle {live.cycle}"
    assert [e.to_json() for e in twin_events] == [e.to_json() for e in live_events]
    assert any(e.kind == "nc_message" for e in live_events)


def test_what_waits_in_the_look_ahead_is_kept_whenever_the_snapshot_is_taken() -> None:
    """The actions the path runs when it gets there (a synchronous V.E. write, ``#MSG SYN``, ``#SLOPE``,
    an area command) wait in the planner's queue as marker payloads: kept at any cycle, and run by the
    restored machine as by the live one."""
    from plc_clients.demos.ve_mode import CONTOUR, POCKET
    from plc_clients.demos.ve_mode import PROGRAM as VE_MODE

    live, _ = running(0)
    kinds: set[str] = set()
    for _ in range(60):
        live.step(50)
        taken = capture(live)  # never SnapshotError
        kinds |= {o.get("obj", "") for o in taken["objects"]}
    assert "hli_server.engine.planner:Marker" in kinds
    demo, _ = machine()
    demo.programs = _Library({"pocket.nc": POCKET, "contour.nc": CONTOUR})
    demo.channel(1).load_program(VE_MODE, "ve_mode")
    demo.channel(1).request_start()
    demo.external.write("PLC_READY", None, True)
    for _ in range(40):
        demo.step(100)
        capture(demo)


@pytest.mark.req("E-01", "K-04")
def test_a_machine_with_a_kinematic_transformation_on_is_restored_mid_move() -> None:
    """The CA head of the kinematics tests with #TRAFO ON (RTCP) while the head turns: the transformation
    in effect, the planner's action markers of #TRAFO ON/OFF and the decoder's software-limit check are
    kept, and the restored machine moves the axes as the live one does."""
    from tests.unit.test_kinematics_engine import machine as ca_machine

    program = "D1\nG90 G01 X10 Y20 Z30 C0 A0 F3000\n#TRAFO ON\nG01 X10 Y20 Z30 A90\nC90\n#TRAFO OFF\nM30\n"
    for cycles in (150, 900, 2500):
        live = ca_machine()
        live.channel(1).load_program(program, "ca")
        live.channel(1).request_start()
        live.step(cycles)
        twin = ca_machine()
        restore(as_json(capture(live)), twin)
        for _ in range(10):
            live.step(200)
            twin.step(200)
            assert capture(twin) == capture(live), f"the machines differ at cycle {live.cycle}"
        assert not [a for a in live.alarm_history if a.severity == "error"]


class _Library:
    """The subprograms of the ve-mode demo (the runtime's library is the host's: named in a snapshot)."""

    def __init__(self, files: dict[str, str]) -> None:
        self.files = files

    def find(self, name: str) -> Any:
        from hli_server.engine.programs import ProgramFile

        text = self.files.get(name)
        return None if text is None else ProgramFile(name, text, "test")

    def searched(self) -> tuple[str, ...]:
        return ("test",)


def test_the_host_parts_stay_the_restoring_machines_own() -> None:
    live, _ = running(500)
    twin, twin_events = machine()
    listeners, programs = twin.event_listeners, twin.programs
    restore(as_json(capture(live)), twin)
    assert twin.event_listeners is listeners
    assert twin.programs is programs
    twin.step(3000)
    assert twin_events  # its own listener hears the restored machine


def test_what_cannot_be_kept_as_data_is_named_with_its_place() -> None:
    live, _ = running(10)
    live.channel(2).decoder.path_checks.append(lambda segment, block: None)
    with pytest.raises(
        SnapshotError, match=r"machine\.channels\[1\]\.decoder\.path_checks\[\d+\]: the function"
    ):
        capture(live)


def _root_state(data: dict[str, Any]) -> dict[str, Any]:
    state: dict[str, Any] = data["objects"][data["root"]["r"]]["state"]
    return state


@pytest.mark.parametrize(
    ("forge", "message"),
    [
        (lambda d: _root_state(d).__setitem__("cycle", {"fn": "os:system"}), "no function of the engine"),
        (lambda d: _root_state(d).__setitem__("cycle", {"fn": "builtins:eval"}), "no function of the engine"),
        # what an engine module imported, reached through it: a module, another package's function, a
        # method through its class, a partial of a class
        (lambda d: _root_state(d).__setitem__("cycle", {"g": "hli_server.engine.machine:math"}), "no table"),
        (
            lambda d: _root_state(d).__setitem__("cycle", {"g": "hli_server.engine.cycles.base:dataclass"}),
            "no table",
        ),
        (
            lambda d: _root_state(d).__setitem__("cycle", {"fn": "hli_server.engine.machine:Machine.step"}),
            "no function of the engine",
        ),
        (
            lambda d: _root_state(d).__setitem__(
                "cycle", {"p": {"c": "hli_server.engine.machine:Machine"}, "a": [], "k": []}
            ),
            "a partial of no method or function",
        ),
        (lambda d: _root_state(d).__setitem__("cycle", {"g": "subprocess:Popen"}), "no module of the engine"),
        (
            lambda d: _root_state(d).__setitem__("cycle", {"c": "hli_server.engine.machine:__class__"}),
            "no name",
        ),
        (lambda d: _root_state(d).__setitem__("cycle", {"r": 10**9}), "a reference to object"),
        (lambda d: _root_state(d).__setitem__("__class__", 1), "attributes"),
        (lambda d: _root_state(d).__setitem__("cycle", {"t": [{"t": []}] * 3, "x": 1}), "a value"),
        (
            lambda d: d["objects"].__setitem__(d["root"]["r"], {"obj": "os:system", "state": {}}),
            "of a os:system",
        ),
        (lambda d: d.__setitem__("fingerprint", "0" * 32), "another engine"),
        (lambda d: d.__setitem__("snapshot", 99), "layout 99"),
    ],
)
def test_a_malformed_or_hostile_snapshot_is_refused_with_a_reason(forge: Any, message: str) -> None:
    live, _ = running(300)
    data = copy.deepcopy(as_json(capture(live)))
    forge(data)
    twin, _ = machine()
    with pytest.raises(SnapshotRestoreError, match=message):
        restore(data, twin)


def test_deep_nesting_is_refused_not_a_crash() -> None:
    live, _ = running(50)
    data = as_json(capture(live))
    value: dict[str, Any] = {"t": []}
    for _ in range(5000):
        value = {"t": [value]}
    _root_state(data)["cycle"] = value
    twin, _ = machine()
    with pytest.raises(SnapshotRestoreError, match="nested"):
        restore(data, twin)


# a drilling cycle, then a measuring cycle whose later moves depend on where the probe touched
CYCLES = (
    "T2 D2\nG00 X0 Y0 Z50\nG91 G01 F777\n"
    "L CYCLE [NAME=SysDrillCenterHole.ecy @P1=0 @P2=20 @P3=2 @P4=5]\nG90\n"
    + SPIGOT.replace("M30\n", "").replace("G53\n", "G53\nG00 Z50\n")
    + "V.E.MARK = 1\nM30\n"
)


@pytest.mark.req("E-01", "CY-05")
def test_a_machine_is_restored_while_a_built_in_cycle_runs() -> None:
    """A built-in cycle's stand-in is a Python generator, which no snapshot can hold: the channel keeps
    the call and the answers its context gave instead, and the restored machine runs the stand-in again
    up to where it was (its reads from the log, its writes left out) and goes on exactly as the live one:
    the same moves, the same measured result in V.CYC. and V.E., whatever the cycle the snapshot is of."""
    from tests.unit.test_cycles_programs import config

    def cycles_machine() -> tuple[Machine, list[Event]]:
        m = Machine(config())
        m.set_probe_deviation(1, {"X": 0.3, "Y": -0.125})
        events: list[Event] = []
        m.event_listeners.append(events.append)
        return m, events

    probe, _ = cycles_machine()
    probe.channel(1).load_program(CYCLES, "cycles")
    probe.channel(1).request_start()
    inside: list[int] = []  # cycles at which a stand-in runs, spread over both cycles
    while not probe.external.read("MARK", 1) and probe.cycle < 200_000:
        probe.step(250)
        if any(f.standin is not None for f in probe.channel(1).interpreter._frames):
            inside.append(probe.cycle)
    assert probe.external.read("MARK", 1), "the program did not end"
    assert len(inside) >= 4
    for at in (inside[1], inside[len(inside) // 2], inside[-2]):
        live, live_events = cycles_machine()
        live.channel(1).load_program(CYCLES, "cycles")
        live.channel(1).request_start()
        live.step(at)
        taken = as_json(capture(live))  # no SnapshotError: the generator is left out
        twin, twin_events = cycles_machine()
        restore(taken, twin)
        live_events.clear()
        while not live.external.read("MARK", 1) and live.cycle < 200_000:
            live.step(500)
            twin.step(500)
            assert capture(twin) == capture(live), f"the machines differ at cycle {live.cycle} (from {at})"
        assert [e.to_json() for e in twin_events] == [e.to_json() for e in live_events]
        assert twin.external.read("MEAS_X", 1) == pytest.approx(50.3, abs=1e-4)
        assert not [a for a in twin.alarm_history if a.severity == "error"]
