"""The stages of the path pipeline between the interpreter and the planner (issue 24; see
docs/architecture.md).

programmed block -> tool radius compensation (:mod:`.radius`) -> frames: #ROTATION, #CS, zero offsets,
#ACS, tool length (:mod:`.frames`, :mod:`.tools`) -> path checks -> planner with the active acceleration
profile (:mod:`.profiles`).
"""

from hli_server.engine.path.profiles import PathFilter, SlopeProfile, SlopeType

__all__ = ["PathFilter", "SlopeProfile", "SlopeType"]
