"""The V.E. variables in the process image: one shared field per element, two writers (N-05).

In the kernel, the PLC and the NC channel share the memory of the external variables
(``gpVECh[i]^``, ``gpVEGlob^``; "External variables / V.E. variables",
https://infosys.beckhoff.com/content/1033/tf5200_hli_interface/174843915.html): whoever stores last
wins. Here the fields live in the PLC->CNC half (after the axis blocks, ``schemas/layout.py``), where
every PLC door writes them, and the engine keeps its own store (``machine.external``,
``hli_server/engine/external.py``, handed to ``ProcessImage.init_from``) that NC programs read and
write. :class:`ExternalSync` keeps the two in step, once per cycle, with the cycle's latch and publish:

* **latch** (before the step): every field whose value differs from what the image last saw there
  was written by a PLC; its value goes into the store. The doors refuse a value outside the kernel
  type's range (``Signal.limits``); a PLC on shared memory that stores one all the same (a NaN, 40000
  in an SGN16) is not taken: the field gets the store's value back and a warning is logged.
* **publish** (after the step): every element the NC changed in the step (the store differs from what
  the image last gave it or took from it) is stored into its field, one single store per element.

So the rule is *last writer wins*, with the NC's writes landing at the end of their cycle and the
PLC's writes reaching the NC at the start of the next: a PLC write that lands between a cycle's latch
and its publish, to an element the NC writes in that same cycle, is overwritten by the NC's value (the
NC stored last); a PLC write to any other element, or in any other moment, is taken at the next latch.
Writing the value a field already holds is no change and is not seen as one. docs/process-image.md
documents the rule; tests/unit/test_external_image.py races the two writers.

Cost per cycle: one ``unpack_from`` of the V.E. area and one list comparison per side; element by
element work only where something changed.
"""

from __future__ import annotations

import itertools
import logging
import struct
from typing import Any

from hli_server.engine.external import (
    ExternalValue,
    ExternalVariableError,
    ExternalVariables,
    ExternalVarSpec,
)
from schemas import image_format as fmt
from schemas.layout import Layout, Scope, Signal

__all__ = ["ExternalSync"]

log = logging.getLogger(__name__)


class ExternalSync:
    """Latches the PLC's writes of V.E. fields into the store and publishes the NC's into the fields."""

    def __init__(self, layout: Layout, p2c_offset: int) -> None:
        self.signals: tuple[Signal, ...] = layout.external_signals
        if not self.signals:
            raise ValueError("the layout has no V.E. variables")
        self._layout = layout
        self._p2c = p2c_offset
        start = self.signals[0].offset
        parts = ["<"]
        cursor = start
        for s in self.signals:
            if s.offset > cursor:
                parts.append(f"{s.offset - cursor}x")
            parts.append(s.type.struct_char)
            cursor = s.offset + s.size
        self._unpack_from = struct.Struct("".join(parts)).unpack_from
        self._area = start
        """Byte offset of the V.E. area in the PLC->CNC half."""
        self._store: ExternalVariables | None = None
        self._specs: list[ExternalVarSpec] = []
        self._slots: list[tuple[list[ExternalValue], int, ExternalVarSpec]] = []
        self._field_seen: list[ExternalValue] = []
        self._store_seen: list[ExternalValue] = []
        self.refused = 0
        """PLC values the store refused (NaN, infinity), counted."""

    # --- binding ---------------------------------------------------------------------------
    def _bind(self, store: ExternalVariables) -> None:
        """Match the layout's elements with the store's variables (the same machine file made both)."""
        specs: list[ExternalVarSpec] = []
        slots: list[tuple[list[ExternalValue], int, ExternalVarSpec]] = []
        for (scope, index, name), group in itertools.groupby(
            self.signals, key=lambda s: (s.scope, s.index, s.external_element[0])
        ):
            members = list(group)
            channel = None if scope is Scope.VE_GLOBAL else self._layout.channels[index].number
            spec = store.spec(name, channel)
            if spec is None or spec.channel != channel or spec.size != len(members):
                where = "the global area" if channel is None else f"channel {channel}"
                raise ValueError(
                    f"V.E.{name} of {where}: the engine's store and the image layout differ; build both "
                    "from the same machine file"
                )
            values = store.values(spec)
            specs.append(spec)
            slots += [(values, k, spec) for k in range(spec.size)]
        self._store = store
        self._specs = specs
        self._slots = slots

    def _gather(self) -> list[ExternalValue]:
        assert self._store is not None
        store = self._store
        return list(itertools.chain.from_iterable(store.values(spec) for spec in self._specs))

    # --- the cycle -------------------------------------------------------------------------
    def init(self, buf: memoryview, store: ExternalVariables) -> None:
        """Start-up: every field takes the store's value."""
        self._bind(store)
        current = self._gather()
        for signal, value in zip(self.signals, current, strict=True):
            fmt.write_field(buf, self._p2c, signal, value)
        self._store_seen = current
        self._field_seen = list(current)

    def latch(self, half: bytes, buf: memoryview) -> None:
        """The PLC's writes into the store. ``half`` is the latch's copy of the PLC->CNC half;
        corrections go to ``buf``, the image."""
        if self._store is None:
            return
        fields = self._unpack_from(half, self._area)
        seen = self._field_seen
        if list(fields) == seen:
            return
        store_seen = self._store_seen
        for k, value in enumerate(fields):
            if value == seen[k]:
                continue
            values, flat, spec = self._slots[k]
            signal = self.signals[k]
            try:
                taken = spec.coerce(value)
            except ExternalVariableError as exc:
                self.refused += 1
                log.warning(
                    "%s: the PLC wrote %r, refused (%s); the field keeps %r",
                    signal.st_path,
                    value,
                    exc,
                    values[flat],
                )
                taken = values[flat]
                fmt.write_field(buf, self._p2c, signal, taken)
                seen[k] = taken
                store_seen[k] = taken
                continue
            values[flat] = taken
            store_seen[k] = taken
            seen[k] = value

    def publish(self, buf: memoryview) -> None:
        """The NC's writes of the step into the fields (one store per changed element)."""
        if self._store is None:
            return
        current = self._gather()
        seen = self._store_seen
        if current == seen:
            return
        field_seen = self._field_seen
        for k, value in enumerate(current):
            if value == seen[k]:
                continue
            signal = self.signals[k]
            fmt.write_field(buf, self._p2c, signal, value)
            field_seen[k] = value
        self._store_seen = current

    def values(self) -> dict[str, Any]:
        """ST path -> value as the store holds it (diagnostics and tests)."""
        current = self._gather() if self._store is not None else [None] * len(self.signals)
        return {s.st_path: v for s, v in zip(self.signals, current, strict=True)}
