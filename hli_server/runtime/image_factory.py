"""Creating the process image the runtime publishes into (H-01).

Two factories: :func:`shared_memory_image` (``/dev/shm/NAME``, the default of ``hli-server run``: a
PLC in another process maps it by name) and :func:`memory_image` (the same format in a buffer of
this process: the pytest harness, H-07, where the PLC runs in the same process and ``/dev/shm`` may
be restricted).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Protocol

from hli_server.adapters.host import ImagePort

if TYPE_CHECKING:
    from hli_server.engine.external import ExternalVariables
    from hli_server.engine.hli import MachineHli
    from hli_server.image import SignalRecorder
    from schemas.config import MachineConfig

__all__ = ["ImageFactory", "RuntimeImage", "memory_image", "shared_memory_image"]


class RuntimeImage(ImagePort, Protocol):
    """What the runtime needs of an image beyond the adapters' :class:`ImagePort`: the cycle's
    latch and publish, start-up and close."""

    def latch_into(self, hli: MachineHli) -> bytes:
        """The PLC->CNC half into the engine; returns the bytes latched."""
        ...

    def publish_from(self, hli: MachineHli, cycle: int, *, commit: bool = True) -> bytearray:
        """The CNC->PLC half out (``commit=False``: packed, not published); returns the packed buffer
        (the cycle as u64, then the half)."""
        ...

    def publish_external(self) -> None:
        """The NC's V.E. writes into their fields without publishing the half (a cycle nobody reads)."""
        ...

    def init_from(self, hli: MachineHli, cycle: int, external: ExternalVariables | None = None) -> None:
        """Start-up: the PLC->CNC half takes the engine's ``_w`` values; the CNC->PLC half is published;
        the V.E. fields take the store's values and are kept in step with it from now on (N-05)."""
        ...

    def close(self) -> None:
        """Mark closed for attached clients, unmap and unlink the segment. Idempotent."""
        ...

    def recorder(self, st_paths: Iterable[str]) -> SignalRecorder:
        """Samples ``st_paths`` after each publish (per-cycle traces, H-07)."""
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


def memory_image(config: MachineConfig, name: str | None) -> RuntimeImage:
    """The image in a buffer of this process (no ``/dev/shm``): for a PLC in the same process."""
    from hli_server.image import ProcessImage
    from schemas.layout import build_layout

    image: RuntimeImage = ProcessImage.in_memory(build_layout(config), name=name)
    return image
