"""Stages of the path pipeline between the interpreter and the planner (issue 24; see
docs/architecture.md): acceleration profiles (``profiles``)."""

from hli_server.engine.path.profiles import PathFilter, SlopeProfile, SlopeType

__all__ = ["PathFilter", "SlopeProfile", "SlopeType"]
