"""The machine file's kinematic data sets (``[[channels.kinematics]]``, schemas.config) as the engine's
:class:`~hli_server.engine.kinematics.library.KinematicData` (read once when the channel is built)."""

from __future__ import annotations

from collections.abc import Sequence

from hli_server.engine.kinematics.library import KinematicData, universal_params
from schemas.config import KinematicEntry

__all__ = ["data_sets"]


def data_sets(entries: Sequence[KinematicEntry]) -> dict[int, KinematicData]:
    """By kinematic ID: the parameters as ``param[]`` (the named Universal Kinematics fields laid out as
    ``V.G.KIN[91].PARAM[i]``)."""
    out: dict[int, KinematicData] = {}
    for e in entries:
        params = {k: float(v) for k, v in e.param.items()}
        if e.axes or e.zero_orientation is not None or e.zero_position is not None:
            params.update(
                universal_params(
                    e.zero_orientation or (0.0, 0.0, 1.0),
                    e.zero_position or (0.0, 0.0, 0.0),
                    [(a.type, a.orientation, a.point) for a in e.axes],
                )
            )
        out[e.id] = KinematicData(e.id, e.type, params, tuple(e.chain), e.programming_mode, e.rtcp)
    return out
