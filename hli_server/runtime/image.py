"""Creating the process image the runtime publishes into (H-01)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from hli_server.adapters.host import ImagePort

if TYPE_CHECKING:
    from hli_server.engine.hli import MachineHli
    from schemas.config import MachineConfig

__all__ = ["ImageFactory", "RuntimeImage", "shared_memory_image"]


class RuntimeImage(ImagePort, Protocol):
    """What the runtime needs of an image beyond the adapters' :class:`ImagePort`: the cycle's
    latch and publish, start-up and close."""

    def latch_into(self, hli: MachineHli) -> None: ...

    def publish_from(self, hli: MachineHli, cycle: int) -> None: ...

    def init_from(self, hli: MachineHli, cycle: int) -> None:
        """Start-up: the PLC->CNC half takes the engine's ``_w`` values; the CNC->PLC half is published."""
        ...

    def close(self) -> None:
        """Mark closed for attached clients, unmap and unlink the segment. Idempotent."""
        ...


ImageFactory = Callable[["MachineConfig", "str | None"], RuntimeImage]
"""``(config, name or None) -> image``; the image exists when this returns. ``None``: a unique name."""


def shared_memory_image(config: MachineConfig, name: str | None) -> RuntimeImage:
    """The default: a POSIX shared-memory segment (``/dev/shm/NAME``) with the machine's layout."""
    from hli_server.image import ProcessImage
    from schemas.layout import build_layout

    # replace_stale: a segment left by a crashed server of the same name is replaced; the image of a
    # running server never is (ProcessImage.create checks its pid)
    image: RuntimeImage = ProcessImage.create(build_layout(config), name=name, replace_stale=True)
    return image
