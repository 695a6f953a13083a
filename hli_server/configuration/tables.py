"""Which parameter table a text list or a model field belongs to (the ISG names of schemas.config)."""

from __future__ import annotations

import re
from typing import Literal

from pydantic import BaseModel

from schemas.config import (
    AXIS_PARAMETERS,
    CHANNEL_PARAMETERS,
    MANUAL_PARAMETERS,
    AxisConfig,
    ChannelConfig,
    ManualConfig,
    ParameterInfo,
)

ListKind = Literal["axis", "channel", "manual"]
"""Which parameter table a text list is read against."""

Loc = tuple[str | int, ...]
"""A location in the machine data, as pydantic names it: ``("axes", 1, "swe_neg")``."""

_LIST_KEY = "parameter_list"
_TABLES: dict[str, tuple[tuple[ParameterInfo, ...], type[BaseModel]]] = {
    "axis": (AXIS_PARAMETERS, AxisConfig),
    "channel": (CHANNEL_PARAMETERS, ChannelConfig),
    "manual": (MANUAL_PARAMETERS, ManualConfig),
}
_PARAMETERS_OF_MODEL: dict[type[BaseModel], tuple[ParameterInfo, ...]] = {
    AxisConfig: AXIS_PARAMETERS,
    ChannelConfig: CHANNEL_PARAMETERS,
    ManualConfig: MANUAL_PARAMETERS,
}
_KIND_NAMES = {
    "axis": "an axis parameter",
    "channel": "a channel parameter",
    "manual": "a manual-mode parameter",
}
_GEAR_KEY = re.compile(r"^getriebe\[(\d+)\]\.(.+)$")
_CHANNEL_KEY = re.compile(r"^configuration\.channel\[(\d+)\]\.(.+)$")
_ELEMENT_KEY = re.compile(r"^([a-z0-9_]+)\[(\d{1,4})\]$")
"""An element of an indexed parameter: ``g800_prog_file[3]`` (the table's path ``g800_prog_file[i]``)."""
_PAREN_COMMENT = re.compile(r"\s+\([^()]*\)\s*$")
"""A comment in parentheses after a value, as the kernel's lists write one (``G800.nc (UP at G800)``)."""
_INTEGER = re.compile(r"^([+-]?)(?:0[xX]([0-9a-fA-F]+)|([0-9]+))$")
_RANGE_ERRORS = {"greater_than", "greater_than_equal", "less_than", "less_than_equal"}
