"""Small builders for engine unit tests: a mill with X/Y/Z and helpers to run programs cycle by cycle."""

from __future__ import annotations

from collections.abc import Callable, Iterator

from hli_server.engine import Machine
from schemas.config import AxisConfig, ChannelConfig, MachineConfig, ManualConfig, ZeroOffset
from schemas.events import Event
from schemas.wire import ProgramState

RUNNING = (ProgramState.RUNNING, ProgramState.HELD)


def mill_config(
    *,
    cycle_time_us: int = 1000,
    swe: tuple[int, int] = (-5_000_000, 5_000_000),
    extra_axes: tuple[str, ...] = (),
    zero_offsets: list[ZeroOffset] | None = None,
    move_limit_warning: bool = False,
    **axis_overrides: object,
) -> MachineConfig:
    names = ("X", "Y", "Z", *extra_axes)
    axes = [
        AxisConfig(number=i + 1, name=n, swe_neg=swe[0], swe_pos=swe[1], **axis_overrides)  # type: ignore[arg-type]
        for i, n in enumerate(names)
    ]
    return MachineConfig(
        cycle_time_us=cycle_time_us,
        axes=axes,
        channels=[ChannelConfig(axes=list(names), zero_offsets=zero_offsets or [])],
        manual=ManualConfig(move_limit_warning=move_limit_warning),
    )


def mill(**kwargs: object) -> Machine:
    return Machine(mill_config(**kwargs))  # type: ignore[arg-type]


def start(machine: Machine, program: str, channel: int = 1) -> None:
    ch = machine.channel(channel)
    ch.load_program(program)
    ch.request_start()
    machine.step(1)


def cycles_until_done(machine: Machine, limit: int = 200_000, channel: int = 1) -> Iterator[int]:
    """Step one cycle at a time while the program runs; yields the cycle number after each step."""
    ch = machine.channel(channel)
    for _ in range(limit):
        if ch.state not in RUNNING:
            return
        machine.step(1)
        yield machine.cycle
    raise AssertionError(f"program still running after {limit} cycles")


def run(
    machine: Machine, program: str, channel: int = 1, each: Callable[[Machine], None] | None = None
) -> None:
    start(machine, program, channel)
    for _ in cycles_until_done(machine, channel=channel):
        if each is not None:
            each(machine)


def record_events(machine: Machine) -> list[Event]:
    """Every event the machine emits from now on, in order (a listener, as the runtime's log is)."""
    seen: list[Event] = []
    machine.event_listeners.append(seen.append)
    return seen


def settle(machine: Machine, cycles: int = 300) -> None:
    machine.step(cycles)


def positions(machine: Machine) -> dict[str, float]:
    return {a.name: round(a.setpoint, 6) for a in machine.axes}
