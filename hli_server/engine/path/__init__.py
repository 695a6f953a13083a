"""The stages of the path pipeline between the interpreter and the planner (M-10..M-24; see
docs/architecture.md).

programmed block -> tool radius compensation (:mod:`.radius`) -> frames: #ROTATION, #CS, zero offsets,
#ACS, tool length (:mod:`.frames`, :mod:`.tools`) -> contouring (:mod:`.contour`) -> path checks ->
planner with the active acceleration profile (:mod:`.profiles`). Contouring together with a frame, a
tool or radius compensation is refused (910110) for now.
"""

from hli_server.engine.path.contour import Contour, ContourSettings, Piece
from hli_server.engine.path.profiles import PathFilter, SlopeProfile, SlopeType

__all__ = ["Contour", "ContourSettings", "PathFilter", "Piece", "SlopeProfile", "SlopeType"]
