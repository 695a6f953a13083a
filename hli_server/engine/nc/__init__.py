"""NC programs: the language's front end (source, syntax, expressions, interpreter; N-01..N-08), the
word parser of constant blocks and the blocks the decoder takes (E-04)."""

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
from hli_server.engine.nc.compiler import Compiler
from hli_server.engine.nc.directives import IterationCapError
from hli_server.engine.nc.interpreter import Interpreter
from hli_server.engine.nc.parser import KNOWN_G_CODES, iter_blocks, parse_line, parse_program
from hli_server.engine.nc.source import ProgramText
from hli_server.engine.nc.state import STATEMENTS_PER_CYCLE

__all__ = [
    "KNOWN_G_CODES",
    "STATEMENTS_PER_CYCLE",
    "AreaBegin",
    "AreaClear",
    "AreaCommand",
    "AreaEnd",
    "AreaKind",
    "AreaOff",
    "AreaOn",
    "AreaShape",
    "Block",
    "Compiler",
    "Interpreter",
    "IterationCapError",
    "NcError",
    "ProgramText",
    "iter_blocks",
    "parse_line",
    "parse_program",
]
