"""``#VECTOR LIMIT ON/OFF`` (PM 207477899 "Adapt path dynamic limit values") and ``#CHANNEL INIT
[CMDPOS|ACTPOS]`` (PM 206703627, 206709515; the kernel's 21507, DG 254971531): through the interpreter
alone, then on a machine (the path velocity, the positions taken after the path came to rest)."""

from __future__ import annotations

import pytest

from hli_server.engine.nc.directives import ChannelInit, VectorLimit
from tests.unit.engine_helpers import cycles_until_done, mill, record_events, start
from tests.unit.nc_helpers import error, interpret

pytestmark = pytest.mark.req("N-08")


def vector(text: str) -> list[VectorLimit]:
    done = interpret(text + "\nM30\n")
    assert done.error is None, done.error
    return [o for o in done.outputs if isinstance(o, VectorLimit)]


@pytest.mark.parametrize(
    ("command", "velocity", "feed", "rapid"),
    [
        ("#VECTOR LIMIT ON [VEL=12500]", 12500.0, True, True),
        ("#VECTOR LIMIT ON [VEL = 100 * 5 FEED]", 500.0, True, False),
        ("#VECTOR LIMIT ON [VEL=300, RAPID]", 300.0, False, True),
        ("#VECTOR LIMIT ON [VEL FEED RAPID]", 2_000_000_000.0, True, True),  # P-CHAN-00090's default
        ("#VECTOR LIMIT OFF [VEL]", None, True, True),
        ("#VECTOR LIMIT OFF ALL", None, True, True),
        ("#VECTOR LIMIT OFF", None, True, True),
    ],
)
def test_vel_is_handed_to_the_decoder(command: str, velocity: float | None, feed: bool, rapid: bool) -> None:
    (limit,) = vector(command)
    assert (limit.velocity, limit.feed, limit.rapid) == (velocity, feed, rapid)


@pytest.mark.parametrize(
    "command",
    ["#VECTOR LIMIT ON [ACC=1000 DEC=2000 JERK=5]", "#VECTOR LIMIT ON ALL", "#VECTOR LIMIT ON [RADIAL_ACC]"],
)
def test_the_other_limits_are_accepted_with_one_warning(command: str) -> None:
    done = interpret(f"{command}\n{command}\nG01 X1 F100\nM30\n")
    assert done.error is None
    assert done.warnings.count(911041) == 1
    assert done.axes == [{"X": 1.0}]


def test_acc_alone_leaves_vel_as_it_was() -> None:
    assert vector("#VECTOR LIMIT ON [ACC=1000]") == []
    assert len(vector("#VECTOR LIMIT ON [ACC=1000 VEL=50]")) == 1


@pytest.mark.parametrize(
    ("command", "alarm", "says"),
    [
        ("#VECTOR LIMIT [VEL=5]", 914015, "ON or OFF"),
        ("#VECTOR LIMIT ON [SPEED=5]", 914015, "unknown keyword 'SPEED'"),
        ("#VECTOR LIMIT ON [VEL=5 VEL=6]", 914015, "twice"),
        ("#VECTOR LIMIT ON [FEED=1]", 914015, "FEED takes no value"),
        ("#VECTOR LIMIT ON ALL [VEL=5]", 914015, "ALL stands alone"),
        ("#VECTOR LIMIT OFF [VEL=5]", 914015, "takes no value with OFF"),
        ("#VECTOR LIMIT ON [VEL=0]", 910111, "positive"),
        ("#VECTOR LIMIT ON [VEL=-3]", 910111, "positive"),
        ("#VECTOR ON", 910110, "#VECTOR"),
    ],
)
def test_vector_limit_errors(command: str, alarm: int, says: str) -> None:
    exc = error(f"G01 X1 F100\n{command}\nM30\n")
    assert (exc.alarm, exc.line) == (alarm, 2)
    assert says in exc.message


def channel_init(text: str) -> list[ChannelInit]:
    done = interpret(text + "\nM30\n")
    assert done.error is None, done.error
    return [o for o in done.outputs if isinstance(o, ChannelInit)]


@pytest.mark.parametrize(
    ("command", "actual", "axes"),
    [
        ("N20 #CHANNEL INIT [CMDPOS]", False, ()),
        ("#CHANNEL INIT [ACTPOS]", True, ()),
        ("#CHANNEL INIT [ACTPOS AX=X AX=Y]", True, ("X", "Y")),
        ("#CHANNEL INIT [CMDPOS AXNR=3]", False, ("Z",)),
        ("#CHANNEL INIT [ CMDPOS, AX=Y ]", False, ("Y",)),
    ],
)
def test_channel_init_is_handed_to_the_decoder(command: str, actual: bool, axes: tuple[str, ...]) -> None:
    (init,) = channel_init(command)
    assert (init.actual, init.axes) == (actual, axes)


@pytest.mark.parametrize(
    ("command", "alarm", "says"),
    [
        ("#CHANNEL INIT [CMDPOS CMDPOS]", 21507, "CMDPOS after CMDPOS"),
        ("#CHANNEL INIT [CMDPOS ACTPOS]", 21507, "one of CMDPOS, ACTPOS"),
        ("#CHANNEL INIT [ACTPOS AX=X AX=X]", 21507, "axis X programmed twice"),
        ("#CHANNEL INIT [ACTPOS AX=X AXNR=1]", 21507, "axis X programmed twice"),
        ("#CHANNEL INIT [AX=X CMDPOS]", 21507, "before CMDPOS"),
        ("#CHANNEL INIT [CMDPOS] X10", 21507, "alone in its block"),
        ("#CHANNEL INIT [ ]", 914015, "CMDPOS or ACTPOS expected"),
        ("#CHANNEL INIT CMDPOS", 914000, "expected '['"),
        ("#CHANNEL INIT [CMDPOS", 914015, "']' missing"),
        ("#CHANNEL INIT [CMDPOS AX=Q]", 20797, "no axis Q"),
        ("#CHANNEL INIT [CMDPOS AXNR=9]", 914005, "no axis 9"),
        ("#CHANNEL SET [M_PRE_OUTPUT]", 910110, "#CHANNEL"),
    ],
)
def test_channel_init_errors(command: str, alarm: int, says: str) -> None:
    exc = error(f"G01 X1 F100\n{command}\nM30\n")
    assert exc.line == 2
    assert says in exc.message
    assert exc.alarm == alarm


# --- on a machine ----------------------------------------------------------------------------------------
def peak_speeds(program: str) -> list[float]:
    """The peak X speed [mm/min] of each motion between rests, as the axis' setpoints show it."""
    machine = mill()
    start(machine, program)
    t_a = machine.channel(1).t_a
    last = machine.axes[0].setpoint
    peaks: list[float] = []
    moving = False
    for _ in cycles_until_done(machine):
        x = machine.axes[0].setpoint
        v = abs(x - last) / t_a * 60.0
        last = x
        if v > 1e-6:
            if not moving:
                peaks.append(0.0)
            moving = True
            peaks[-1] = max(peaks[-1], v)
        else:
            moving = False
    return peaks


def test_vel_caps_the_path_velocity_until_off() -> None:
    peaks = peak_speeds(
        "G01 X20 F3000\nG04 X0.1\n#VECTOR LIMIT ON [VEL=600]\nX40\nG04 X0.1\n"
        "#VECTOR LIMIT OFF [VEL]\nX60\nM30\n"
    )
    assert len(peaks) == 3
    assert peaks[0] == pytest.approx(3000.0, rel=1e-3)
    assert peaks[1] == pytest.approx(600.0, rel=1e-3)
    assert peaks[2] == pytest.approx(3000.0, rel=1e-3)


def test_vel_acts_on_rapid_blocks_unless_feed_alone_is_named() -> None:
    capped = peak_speeds("#VECTOR LIMIT ON [VEL=900]\nG00 X30\nM30\n")
    feed_only = peak_speeds("#VECTOR LIMIT ON [VEL=900 FEED]\nG00 X30\nM30\n")
    assert capped[0] == pytest.approx(900.0, rel=1e-3)
    assert feed_only[0] > 1000.0
    rapid_only = peak_speeds("#VECTOR LIMIT ON [VEL=900 RAPID]\nG01 X30 F3000\nM30\n")
    assert rapid_only[0] == pytest.approx(3000.0, rel=1e-3)


def test_channel_init_reads_after_the_path_came_to_rest() -> None:
    machine = mill()
    events = record_events(machine)
    seen: list[float] = []
    start(machine, 'G01 X12.5 F3000\n#CHANNEL INIT [CMDPOS]\n#MSG ["X=%.3f", V.A.ABS.X]\nG91 X1\nM30\n')
    for _ in cycles_until_done(machine):
        if any(getattr(e, "text", "") == "X=12.500" for e in events) and not seen:
            seen.append(machine.axes[0].setpoint)
    assert seen == [pytest.approx(12.5, abs=0.01)]  # the message came when the axis had arrived (before: X0)
    assert machine.axes[0].setpoint == pytest.approx(13.5)  # and G91 goes on from there


@pytest.mark.parametrize(
    ("command", "velocity"),
    [
        ("#VECTORVEL ON", 2_000_000_000.0),
        ("#VECTORVEL [5000] ON", 5000.0),
        ("#VECTORVEL ON [5000]", 5000.0),
        ("#VECTORVEL OFF", None),
    ],
)
def test_the_older_vectorvel_is_vector_limit_vel(command: str, velocity: float | None) -> None:
    (limit,) = vector(command)
    assert (limit.velocity, limit.feed, limit.rapid) == (velocity, True, True)


def test_the_older_vectoracc_is_accepted_with_the_warning() -> None:
    done = interpret("#VECTORACC ON [2700000]\n#VECTORACC OFF\nM30\n")
    assert done.error is None
    assert done.warnings == [911041]
    exc = error("G01 X1 F100\n#VECTORVEL [5000]\nM30\n")
    assert (exc.alarm, exc.line) == (914015, 2)
