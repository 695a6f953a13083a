"""Test data both levels use: a demo-sized machine built in code, and distinct values for every field.

Shared by the unit tests of the layout and the integration tests of the image (a unit test must not
import an integration helper; both import this). Imports ``schemas`` only, so that the spawned
second process of the shared-memory tests can import it too.
"""

from __future__ import annotations

from typing import Any

from schemas.config import AxisConfig, ChannelConfig, MachineConfig
from schemas.layout import Direction, Layout, SignalType

__all__ = ["demo_config", "distinct_values"]


def demo_config(extra_axes: int = 0) -> MachineConfig:
    """The demo-sized machine: channel 1 X/Y/Z, channel 2 the gantry X1/X2 with lift Z1."""
    names = ["X", "Y", "Z", "X1", "X2", "Z1"] + [f"U{k}" for k in range(extra_axes)]
    axes = [AxisConfig(number=n, name=name) for n, name in enumerate(names, start=1)]
    channels = [
        ChannelConfig(number=1, name="mill", axes=["X", "Y", "Z", *names[6:]]),
        ChannelConfig(number=2, name="gantry", axes=["X1", "X2", "Z1"], main_axes=("X1", "X2", "Z1")),
    ]
    return MachineConfig(name="demo", axes=axes, channels=channels)


def distinct_values(layout: Layout, direction: Direction, salt: int) -> dict[str, Any]:
    """A different value for every field of a half (UDINT above DINT_MAX, negative DINT, fractions)."""
    values: dict[str, Any] = {}
    for i, s in enumerate(layout.half(direction)):
        if s.type is SignalType.BOOL:
            values[s.st_path] = (i + salt) % 3 != 0
        elif s.type is SignalType.DINT:
            values[s.st_path] = (-1) ** i * (100_000 * (i + 1) + salt)
        elif s.type is SignalType.UDINT:
            values[s.st_path] = 3_000_000_000 + 1000 * i + salt
        else:
            values[s.st_path] = i + 0.125 + salt
    return values
