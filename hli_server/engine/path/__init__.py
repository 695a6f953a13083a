"""The stages of the path pipeline between the interpreter's blocks and the path checks (issue 24):
contouring (:mod:`hli_server.engine.path.contour`)."""

from hli_server.engine.path.contour import Contour, ContourSettings, Piece

__all__ = ["Contour", "ContourSettings", "Piece"]
