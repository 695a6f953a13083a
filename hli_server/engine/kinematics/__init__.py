"""Kinematic transformations (TF5240, TF5290): the machine's axes <-> the tool tip (docs/kinematics.md).

:mod:`.chain` the serial chain (forward, and the inverse of RTCP and complete transformations),
:mod:`.modes` the programming modes of the orientation, :mod:`.transform` a transformation bound to the
channel's axes, :mod:`.library` the kinematic types built from a data set (P-CHAN-00262/00263).
"""

from hli_server.engine.kinematics.chain import Chain, Joint, KinematicError
from hli_server.engine.kinematics.library import KinematicData, build, universal_params
from hli_server.engine.kinematics.modes import MODES, mode_angles, mode_orientation
from hli_server.engine.kinematics.transform import Transformation

__all__ = [
    "MODES",
    "Chain",
    "Joint",
    "KinematicData",
    "KinematicError",
    "Transformation",
    "build",
    "mode_angles",
    "mode_orientation",
    "universal_params",
]
