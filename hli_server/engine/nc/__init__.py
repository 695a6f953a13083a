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
from hli_server.engine.nc.parser import KNOWN_G_CODES, iter_blocks, parse_line, parse_program

__all__ = [
    "KNOWN_G_CODES",
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
    "iter_blocks",
    "parse_line",
    "parse_program",
]
