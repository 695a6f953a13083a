"""Test data both levels use: a demo-sized machine built in code, and distinct values for every field.

Shared by the unit tests of the layout and the integration tests of the image (a unit test must not
import an integration helper; both import this). Imports ``schemas`` only, so that the spawned
second process of the shared-memory tests can import it too.
"""

from __future__ import annotations

from typing import Any

from schemas.config import (
    AxisConfig,
    ChannelConfig,
    ExternalElementConfig,
    ExternalStructureConfig,
    ExternalVariableConfig,
    MachineConfig,
)
from schemas.layout import Direction, Layout, SignalType

__all__ = ["EXTERNAL_STRUCTURES", "EXTERNAL_VARIABLES", "demo_config", "distinct_values"]


EXTERNAL_VARIABLES: tuple[ExternalVariableConfig, ...] = (
    ExternalVariableConfig(name="PLC_READY", type="BOOLEAN", description="the PLC is ready"),
    ExternalVariableConfig(name="S8", type="SGN08"),
    ExternalVariableConfig(name="U8", type="UNS08", dims=[3]),
    ExternalVariableConfig(name="S16", type="SGN16", channel=1),
    ExternalVariableConfig(name="U16", type="UNS16", channel=1),
    ExternalVariableConfig(name="PART_COUNT", type="SGN32", channel=1),
    ExternalVariableConfig(name="U32", type="UNS32", channel=1),
    ExternalVariableConfig(name="R32", type="REAL32", dims=[2], channel=2),
    ExternalVariableConfig(name="POS", type="REAL64", dims=[2, 3], channel=2),
    ExternalVariableConfig(name="FLAGS", type="BOOLEAN", dims=[4], channel=2),
    ExternalVariableConfig(name="TEACH_FILE_NAME", type="STRING", description="the robot's teach file"),
    ExternalVariableConfig(name="UserInteraction", type="UserInteractionType", channel=1),
    ExternalVariableConfig(name="NOTES", type="VSTRING", size=9, dims=[2], channel=2),
    ExternalVariableConfig(name="TRACK", type="Point", dims=[2], channel=2),
)
"""One V.E. variable of every kernel type, global and in both channels, scalars and arrays (N-05):
the elementary types, STRING, VSTRING, a structure with a STRING (as RegenHU's HMI message) and an
array of structures."""

EXTERNAL_STRUCTURES: tuple[ExternalStructureConfig, ...] = (
    ExternalStructureConfig(
        name="UserInteractionType",
        elements=[
            ExternalElementConfig(name="Message", type="STRING"),
            ExternalElementConfig(name="Answer", type="SGN32"),
            ExternalElementConfig(name="Done", type="BOOLEAN"),
        ],
    ),
    ExternalStructureConfig(
        name="Point",
        elements=[
            ExternalElementConfig(name="X", type="REAL64"),
            ExternalElementConfig(name="VALID", type="BOOLEAN"),
            ExternalElementConfig(name="LABEL", type="VSTRING", size=6),
        ],
    ),
)


def demo_config(extra_axes: int = 0, *, external: bool = False) -> MachineConfig:
    """The demo-sized machine: channel 1 X/Y/Z, channel 2 the gantry X1/X2 with lift Z1; with
    ``external``, the V.E. variables of :data:`EXTERNAL_VARIABLES`."""
    names = ["X", "Y", "Z", "X1", "X2", "Z1"] + [f"U{k}" for k in range(extra_axes)]
    axes = [AxisConfig(number=n, name=name) for n, name in enumerate(names, start=1)]
    channels = [
        ChannelConfig(number=1, name="mill", axes=["X", "Y", "Z", *names[6:]]),
        ChannelConfig(number=2, name="gantry", axes=["X1", "X2", "Z1"], main_axes=("X1", "X2", "Z1")),
    ]
    variables = list(EXTERNAL_VARIABLES) if external else []
    structures = list(EXTERNAL_STRUCTURES) if external else []
    return MachineConfig(
        name="demo",
        axes=axes,
        channels=channels,
        external_variables=variables,
        external_structures=structures,
    )


def distinct_values(layout: Layout, direction: Direction, salt: int) -> dict[str, Any]:
    """A different value for every field of a half (UDINT above DINT_MAX, negative DINT, fractions)."""
    values: dict[str, Any] = {}
    for i, s in enumerate(layout.half(direction)):
        if s.type is SignalType.BOOL:
            values[s.st_path] = (i + salt) % 3 != 0
        elif s.type is SignalType.STRING:
            values[s.st_path] = f"s{i}.{salt}"[: s.string_size - 1]
        elif s.limits is not None and s.type is not SignalType.LREAL:  # a V.E. SGN08 .. UNS16
            low, high = int(s.limits[0]), int(s.limits[1])
            values[s.st_path] = low + (37 * i + salt) % (high - low + 1)
        elif s.type is SignalType.DINT:
            values[s.st_path] = (-1) ** i * (100_000 * (i + 1) + salt)
        elif s.type is SignalType.UDINT:
            values[s.st_path] = 3_000_000_000 + 1000 * i + salt
        else:
            values[s.st_path] = i + 0.125 + salt
    return values
