"""A context that runs a stand-in without a machine: it moves where each block goes (G90 absolute, as the
stand-ins program) and answers measuring moves from ``Block.probe_touch`` as the G100 handler would."""

from __future__ import annotations

import math
from collections.abc import Mapping

from hli_server.engine.cycles import MotionState, find
from hli_server.engine.cycles.base import Cycle, StandIn
from hli_server.engine.cycles.params import ParamValue
from hli_server.engine.nc.blocks import Block

Vec3 = tuple[float, float, float]


class FakeContext:
    axis_names = ("X", "Y", "Z")
    main_axes = ("X", "Y", "Z")

    def __init__(
        self,
        start: Vec3 = (0.0, 0.0, 0.0),
        radius: float = 0.0,
        deviation: Vec3 = (0.0, 0.0, 0.0),
        feed: float | None = 1000.0,
        zero_offset: str | None = None,
    ) -> None:
        self.at = start
        self.radius = radius
        self.dev = deviation
        self.feed = feed
        self.active_offset = zero_offset
        self.last: float | None = None
        self.blocks: list[Block] = []
        self.path: list[tuple[Vec3, Vec3, Block]] = []
        self.results: dict[str, float] = {}
        self.offsets: dict[str, dict[str, float]] = {}
        self.programs: dict[str, str] = {}
        self.warnings: list[tuple[int, str]] = []

    # --- CycleContext ---
    def position(self) -> Vec3:
        return self.at

    def plane(self) -> int:
        return 17

    def inch(self) -> bool:
        return False

    def tool_radius(self) -> float:
        return self.radius

    def zero_offset(self) -> str | None:
        return self.active_offset

    def motion_state(self) -> MotionState:
        return MotionState(True, 1, self.feed)

    def measured(self) -> float | None:
        return self.last

    def deviation(self) -> Vec3:
        return self.dev

    def probe_feeds(self) -> tuple[float, float]:
        return 100.0, 1000.0

    def write_zero_offset(self, name: str, values: Mapping[str, float]) -> None:
        self.offsets.setdefault(name, {}).update(values)

    def set_result(self, name: str, value: float) -> None:
        self.results[name] = value

    def write_program(self, name: str, text: str) -> None:
        self.programs[name] = text

    def warn(self, alarm: int, message: str) -> None:
        self.warnings.append((alarm, message))

    # --- the machine ---
    def apply(self, block: Block) -> None:
        self.blocks.append(block)
        if 4 in block.g_codes:  # a dwell: its X is the time
            return
        target = list(self.at)
        for name, value in block.axes:
            target[("X", "Y", "Z").index(name)] = value
        end: Vec3 = (target[0], target[1], target[2])
        start = self.at
        if 100 in block.g_codes:
            touch = block.probe_touch
            if touch is not None and touch <= 1.0:
                end = tuple(s + touch * (e - s) for s, e in zip(start, end, strict=True))  # type: ignore[assignment]
                self.last = touch
            else:
                self.last = None
        if block.axes:
            self.path.append((start, end, block))
        self.at = end


def run_standin(name: str, params: Mapping[int, ParamValue], ctx: FakeContext, line: int = 1) -> FakeContext:
    spec = find(name)
    assert isinstance(spec, StandIn), name
    for block in Cycle(spec, params, ctx, line).blocks():
        ctx.apply(block)
    return ctx


def close(a: float, b: float, tol: float = 1e-5) -> bool:
    return math.isclose(a, b, abs_tol=tol)
