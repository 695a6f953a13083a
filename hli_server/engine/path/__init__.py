"""The stages of the path pipeline between the interpreter and the planner (issue 24).

programmed block -> tool radius compensation (:mod:`.radius`) -> frames: #ROTATION, #CS, zero offsets,
#ACS, tool length (:mod:`.frames`, :mod:`.tools`) -> path checks -> planner.
"""
