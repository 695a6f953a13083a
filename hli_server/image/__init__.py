"""The process image: shared memory or a buffer, latch/publish, projection engine <-> image (H-01, H-02).

Imports run ``image -> engine -> schemas``; adapters use the image, never the engine.
"""

from hli_server.image.projection import Projection, compile_projection, engine_value, set_engine_value
from hli_server.image.shm import (
    IMAGE_NAME_PREFIX,
    ProcessImage,
    SignalRecorder,
    default_image_name,
    open_image_names,
)

__all__ = [
    "IMAGE_NAME_PREFIX",
    "ProcessImage",
    "Projection",
    "SignalRecorder",
    "compile_projection",
    "default_image_name",
    "engine_value",
    "open_image_names",
    "set_engine_value",
]
