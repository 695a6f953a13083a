"""NC programs: parser (syntax) and blocks (E-04)."""

from hli_server.engine.nc.blocks import (
    AreaBegin,
    AreaClear,
    AreaCommand,
    AreaEnd,
    AreaKind,
    AreaOff,
    AreaOn,
    AreaShape,
    Block,
    NcError,
)

__all__ = [
    "AreaBegin",
    "AreaClear",
    "AreaCommand",
    "AreaEnd",
    "AreaKind",
    "AreaOff",
    "AreaOn",
    "AreaShape",
    "Block",
    "NcError",
]
