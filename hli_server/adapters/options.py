"""What every door's options model shares: option names that changed still load for one minor version.

A door's options model derives from :class:`RenamedOptions` and lists its former names in ``RENAMED``
(old name -> new name, or None for an option that has no effect any more). An old name given alone is taken
as the new one with a ``DeprecationWarning`` and a warning in the server's log that names the new option; an
old and a new name given together are refused (a ``ValueError``, which pydantic reports as a validation
error: "'idle_timeout' is the old name of 'idle_timeout_s': give one of them"). The names follow one rule
across the doors: seconds end in ``_s`` and an option means the same on every door (``max_connections``,
``idle_timeout_s``, ...; docs/runtime.md, "Adapters").

Light: importing it imports pydantic and nothing of the doors.
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Mapping
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, model_validator

__all__ = ["RenamedOptions"]

logger = logging.getLogger(__name__)


class RenamedOptions(BaseModel):
    """An options model whose former option names (``RENAMED``) still load, with a warning."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    RENAMED: ClassVar[Mapping[str, str | None]] = {}
    """Old name -> new name (None: the old option has no effect any more)."""
    DOOR: ClassVar[str] = "door"
    """The door's name in the warning (``Modbus option 'idle_timeout' is now 'idle_timeout_s' ...``)."""

    @model_validator(mode="before")
    @classmethod
    def _renamed_options(cls, data: Any) -> Any:  # the raw input, as pydantic hands it: any JSON or object
        if not isinstance(data, Mapping) or not cls.RENAMED.keys() & data.keys():
            return data
        out = dict(data)
        for old, new in cls.RENAMED.items():
            if old not in out:
                continue
            value = out.pop(old)
            if new is None:
                text = f"{cls.DOOR} option {old!r} has no effect any more and goes in the next minor version"
            elif new in out:
                raise ValueError(f"{old!r} is the old name of {new!r}: give one of them")
            else:
                out[new] = value
                text = (
                    f"{cls.DOOR} option {old!r} is now {new!r}; the old name goes in the next minor version"
                )
            warnings.warn(text, DeprecationWarning, stacklevel=2)
            logger.warning("%s", text)
        return out
