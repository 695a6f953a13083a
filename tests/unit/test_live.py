"""The dashboard's data, without a socket (issue 15): the trail the runtime records, the path ahead, the
live scene (the same function as ``check --plot``), and the live feed's bounds (a slow page loses
events, the cycle never waits; at most ``max_streams`` streams; nothing runs without a stream)."""

from __future__ import annotations

import asyncio
import math
import random
from collections.abc import AsyncIterator

import pytest
from shapely.geometry import LineString, Point

from hli_server.adapters.http.live_feed import LiveFeed, TooManyStreamsError
from hli_server.commands.check import check_program, scene_of
from hli_server.configuration import load_machine
from hli_server.engine import Machine
from hli_server.runtime import Runtime
from hli_server.runtime.dashboard import TRAIL_TOLERANCE, Trail, path_ahead
from schemas.events import ModeChanged
from tests.spec_examples import CIRC_PROT_OLD

# the protection cylinder of FCT-C14's older excerpt (centre (150, 0), radius 50, Z -70..70), and a
# block through it: refused before it starts (912001), the exact entry point at X100
THROUGH = CIRC_PROT_OLD + "N50 G01 X0 Y0 F30000\nN60 #CONTROL AREA ON [ID4]\nN70 G01 X300 F6000\nN80 M30\n"


@pytest.fixture
async def runtime() -> AsyncIterator[Runtime]:
    async with Runtime(load_machine(None), clock="stepped", http_port=None) as rt:
        yield rt


# --- the trail -----------------------------------------------------------------------------------


def test_a_straight_move_keeps_its_ends_and_a_corner() -> None:
    trail = Trail()
    for k in range(101):
        trail.add((k * 1.0, 0.0, 0.0))
    for k in range(1, 51):
        trail.add((100.0, k * 1.0, 0.0))
    assert trail.polyline() == [(0.0, 0.0, 0.0), (100.0, 0.0, 0.0), (100.0, 50.0, 0.0)]


def test_a_reversal_on_the_same_line_is_kept() -> None:
    trail = Trail()
    for k in [*range(51), *range(49, 19, -1)]:
        trail.add((float(k), 0.0, 0.0))
    assert trail.polyline() == [(0.0, 0.0, 0.0), (50.0, 0.0, 0.0), (20.0, 0.0, 0.0)]


def test_a_standstill_adds_nothing_and_changes_no_revision() -> None:
    trail = Trail()
    trail.add((1.0, 2.0, 3.0))
    trail.add((5.0, 2.0, 3.0))
    trail.add((5.0, 9.0, 3.0))
    revision, points = trail.revision, trail.polyline()
    for _ in range(1000):
        trail.add((5.0, 9.0, 3.0))
    assert (trail.revision, trail.polyline()) == (revision, points)


def test_an_arc_is_drawn_within_the_tolerance_with_few_points() -> None:
    """A circle of radius 50 sampled every 0.05 mm: the kept chords stay within the tolerance of every
    sample (the chord's sagitta is about a quarter of it) and there are far fewer points than samples."""
    samples = [
        (50.0 * math.cos(k / 6283 * math.tau), 50.0 * math.sin(k / 6283 * math.tau), 0.0) for k in range(6284)
    ]
    trail = Trail()
    for p in samples:
        trail.add(p)
    kept = trail.polyline()
    assert 30 < len(kept) < 400
    drawn = LineString([(x, y) for x, y, _ in kept])
    assert max(drawn.distance(Point(x, y)) for x, y, _ in samples) <= TRAIL_TOLERANCE


def test_random_walks_stay_within_the_tolerance() -> None:
    rng = random.Random(15)
    for _ in range(20):
        samples, p = [], (0.0, 0.0, 0.0)
        heading = rng.uniform(0, math.tau)
        for _ in range(400):
            heading += rng.choice([0.0, 0.0, 0.0, rng.uniform(-0.3, 0.3), rng.uniform(-3, 3)])
            step = rng.uniform(0.0, 2.0)
            p = (
                p[0] + step * math.cos(heading),
                p[1] + step * math.sin(heading),
                p[2] + rng.uniform(-0.1, 0.1),
            )
            samples.append(p)
        trail = Trail(size=10_000)
        for q in samples:
            trail.add(q)
        kept = trail.polyline()
        assert kept[0] == samples[0]
        assert kept[-1] == samples[-1]
        drawn = LineString(kept)  # 3-D distances: shapely measures in the plane, so check each axis pair
        assert max(drawn.distance(Point(q[0], q[1])) for q in samples) <= 2 * TRAIL_TOLERANCE


def test_the_trail_keeps_the_newest_points() -> None:
    trail = Trail(size=10)
    for k in range(100):
        trail.add((float(k), float(k % 2), 0.0))  # a zigzag: every sample is a corner
    assert len(trail.points) == 10
    assert trail.polyline()[-1] == (99.0, 1.0, 0.0)


async def test_the_runtime_records_the_setpoints_and_a_start_begins_a_new_trail(runtime: Runtime) -> None:
    op = runtime.operator
    op.load_program(1, "N10 G01 X50 F30000\nN20 Y40\nN30 M30\n")
    op.start(1)
    await runtime.step(1500)
    first = op.scene(1)["path"][0]
    # a sample every 4 cycles: the corner is where the samples turn, within the trail's tolerance
    assert [p[:2] for p in first] == [
        [0.0, 0.0],
        pytest.approx([50.0, 0.0], abs=TRAIL_TOLERANCE),
        [50.0, 40.0],
    ]
    op.load_program(1, "N10 G01 X0 F30000\nN20 M30\n")
    op.start(1)
    await runtime.step(1500)
    again = op.scene(1)["path"][0]
    assert [p[:2] for p in again] == [[50.0, 40.0], [0.0, 40.0]]


# --- the path ahead and the live scene -------------------------------------------------------------


async def test_the_path_ahead_runs_from_the_tcp_through_the_queued_blocks(runtime: Runtime) -> None:
    op = runtime.operator
    op.load_program(1, "N10 G01 X100 F3000\nN20 G03 X100 Y100 I0 J50\nN30 G01 X0\nN40 M30\n")
    op.start(1)
    await runtime.step(200)
    scene = op.scene(1)
    ahead = scene["ahead"]
    here = scene["position"]
    assert ahead[0] == here
    assert 0.0 < here[0] < 100.0
    assert [100.0, 0.0] in [p[:2] for p in ahead]
    assert ahead[-1][:2] == [0.0, 100.0]
    on_arc = [p for p in ahead if p[0] > 100.0]
    assert len(on_arc) > 10
    for p in on_arc:  # sampled on the circle around (100, 50)
        assert math.hypot(p[0] - 100.0, p[1] - 50.0) == pytest.approx(50.0, abs=1e-3)
    s = [p[3] for p in ahead]
    assert s == sorted(s)
    ch = runtime.machine.channel(1)
    assert len(path_ahead(ch, limit=5)) == 5


@pytest.mark.req("C14-14", "C14-15")
async def test_the_live_scene_shows_what_check_plot_shows(runtime: Runtime) -> None:
    """The dashboard and ``check --plot`` draw the same picture from the same geometry code: the live
    scene of a program that violates an area has the same areas, relations, refused block and violation
    point as the scene ``check --plot`` draws for it."""
    op = runtime.operator
    op.load_program(1, THROUGH)
    op.start(1)
    await runtime.step(3000)
    live = op.scene(1)
    checked = scene_of(check_program(Machine(load_machine(None)), THROUGH, record_path=True))
    assert live["violation"] is not None
    assert live["violation"]["alarm"] == 912001
    assert live["violation"]["position"] == {"X": 100.0, "Y": 0.0, "Z": 0.0}
    for key in ("view", "areas", "refused", "violation"):
        assert live[key] == checked[key], key
    assert live["ahead"] == []  # the refused block was not started: nothing is queued
    op.reset(1)
    await runtime.step(2)
    after = op.scene(1)
    assert after["violation"] is None
    assert after["refused"] is None


async def test_an_unchanged_scene_is_not_computed_again(runtime: Runtime) -> None:
    op = runtime.operator
    first = op.scene(1)
    await runtime.step(100)
    assert op.scene(1) is first  # nothing moved, nothing changed
    op.load_program(1, "N10 G01 X10 F30000\nN20 M30\n")
    op.start(1)
    await runtime.step(300)
    assert op.scene(1) is not first


# --- the live feed ----------------------------------------------------------------------------------


async def test_a_slow_page_loses_events_and_the_cycle_does_not_wait(runtime: Runtime) -> None:
    feed = LiveFeed(runtime.host, queue_size=5)
    slow = feed.open()
    fast = feed.open()
    for k in range(12):  # what the machine emits inside a cycle
        runtime.machine.emit(ModeChanged(cycle=k, time_s=0.0, channel=1, mode="manual", previous="automatic"))
        chunk = fast._take()  # the fast page reads after every event
        assert chunk.count(b"event: event") == 1
    assert len(slow.events) == 5
    assert (slow.dropped, fast.dropped, feed.dropped) == (7, 0, 7)
    chunk = await slow.next_chunk()
    assert chunk is not None
    assert chunk.count(b"event: event") == 5
    assert b'event: dropped\ndata: {"dropped":7}' in chunk
    await feed.close()


async def test_streams_are_bounded_and_nothing_runs_without_one(runtime: Runtime) -> None:
    listeners = runtime.event_log._listeners
    before = len(listeners)
    feed = LiveFeed(runtime.host, max_streams=2)
    a, b = feed.open(), feed.open()
    assert len(listeners) == before + 1
    with pytest.raises(TooManyStreamsError, match="2 live streams are open"):
        feed.open()
    feed.release(a)
    c = feed.open()  # a slot came free
    feed.release(b)
    feed.release(c)
    assert len(listeners) == before  # no listener in the cycle
    await asyncio.sleep(0)
    assert feed._task is None
    await feed.close()
    with pytest.raises(RuntimeError, match="stopping"):
        feed.open()


@pytest.mark.req("H-02")
async def test_the_state_carries_axes_limits_pairs_and_alarms(runtime: Runtime) -> None:
    image = runtime.host.image
    image.write("gpAx[0]^ipo_mc_control.dyn_pos_limit_high.command_w", 1_000_000)
    image.write("gpAx[0]^ipo_mc_control.dyn_pos_limit_high.enable_w", True)
    runtime.operator.override(1, 500)
    await runtime.step(5)
    state = LiveFeed(runtime.host).state()
    x = next(a for a in state["axes"] if a["name"] == "X")
    assert x["dyn_pos_limit"]["high"]["enabled"] is True
    assert x["dyn_pos_limit"]["high"]["limit_mm"] == pytest.approx(100.0)
    assert x["dyn_pos_limit"]["high"]["state_name"] == "ACTIVE"
    assert x["dyn_pos_limit"]["low"]["state_name"] == "INACTIVE"
    assert state["channels"][0]["override_percent"] == 50.0
    (pair,) = state["pairs"]
    assert (pair["master"], pair["partner"], pair["distance"], pair["min_distance"]) == (
        "X2",
        "X1",
        500.0,
        20.0,
    )
    assert state["alarms"] == []


async def test_a_scene_that_cannot_be_computed_leaves_the_rest_of_the_page(
    runtime: Runtime, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def broken(number: int) -> dict:
        raise ValueError(f"channel {number}: a bug")

    monkeypatch.setattr(runtime.operator, "scene", broken)
    feed = LiveFeed(runtime.host)
    stream = feed.open()
    chunk = stream._take()
    assert b"event: state" in chunk
    assert b"event: scene" not in chunk
    feed._tick(1e9)
    feed._tick(2e9)
    assert b"event: state" in stream._take()
    failures = [r for r in caplog.records if "cannot be computed" in r.getMessage()]
    assert len(failures) == 2  # once per channel, not once per tick
    await feed.close()
