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
from schemas.layout import Layout, Scope, Signal, SignalValueError

__all__ = ["ExternalSync"]

log = logging.getLogger(__name__)


class _Variable:
    """One variable of the store (a leaf of a structured one) with its elements' signals."""

    __slots__ = ("elements", "seen", "spec", "values")

    def __init__(self, spec: ExternalVarSpec, values: list[ExternalValue]) -> None:
        self.spec = spec
        self.values = values
        """The store's live list (``ExternalVariables.values``)."""
        self.seen = list(values)
        """The values the image and the store last agreed on."""
        self.elements = [-1] * spec.size
        """flat index -> the element's signal (its index in :attr:`ExternalSync.signals`); a structured
        variable's leaves interleave in the image, so they are not one run."""


class ExternalSync:
    """Latches the PLC's writes of V.E. fields into the store and publishes the NC's into the fields."""

    def __init__(self, layout: Layout, p2c_offset: int) -> None:
        self.signals: tuple[Signal, ...] = layout.external_signals
        if not self.signals:
            raise ValueError("the layout has no V.E. variables")
        self._layout = layout
        self._p2c = p2c_offset
        self._start = self.signals[0].offset
        """Byte offset of the V.E. area in the PLC->CNC half."""
        self._end = max(s.offset + s.size for s in self.signals)
        self._element_of_byte = [-1] * (self._end - self._start)
        for k, s in enumerate(self.signals):
            for b in range(s.offset - self._start, s.offset - self._start + s.size):
                self._element_of_byte[b] = k
        self._formats = [struct.Struct("<" + s.struct_char) for s in self.signals]
        self._raw = bytearray(self._end - self._start)
        """The V.E. area's bytes as the image last saw or wrote them."""
        self._store: ExternalVariables | None = None
        self._variables: list[_Variable] = []
        self._slot: list[tuple[_Variable, int]] = []
        """element (signal index) -> (its variable, its flat index)"""
        self.refused = 0
        """PLC values the store refused (outside the kernel type, NaN, a STRING too long), counted."""

    # --- binding ---------------------------------------------------------------------------
    def _bind(self, store: ExternalVariables) -> None:
        """Match the layout's elements with the store's variables (the same machine file made both)."""
        variables: dict[tuple[int | None, str], _Variable] = {}
        slot: list[tuple[_Variable, int]] = []
        for k, signal in enumerate(self.signals):
            name, index = signal.external_element
            channel = None if signal.scope is Scope.VE_GLOBAL else self._layout.channels[signal.index].number
            spec = store.spec(name, channel)
            try:
                if spec is None or spec.channel != channel:
                    raise ExternalVariableError(f"V.E.{name} is not in the store")
                flat = spec.flat_index(index)
            except ExternalVariableError as exc:
                where = "the global area" if channel is None else f"channel {channel}"
                raise ValueError(
                    f"{signal.st_path} of {where}: the engine's store and the image layout differ ({exc}); "
                    "build both from the same machine file"
                ) from None
            key = (channel, spec.name.upper())
            variable = variables.get(key)
            if variable is None:
                variable = variables[key] = _Variable(spec, store.values(spec))
            variable.elements[flat] = k
            slot.append((variable, flat))
        missing = [v.spec.path for v in variables.values() if -1 in v.elements]
        if missing or len(variables) != len(store):
            raise ValueError(
                "the engine's store and the image layout differ "
                f"({', '.join(missing) or 'other variables'}); build both from the same machine file"
            )
        self._store = store
        self._variables = list(variables.values())
        self._slot = slot

    def _store_field(self, buf: memoryview, k: int, value: ExternalValue) -> None:
        """One store into element ``k``'s field, and its bytes in :attr:`_raw`."""
        signal = self.signals[k]
        fmt.write_field(buf, self._p2c, signal, value)
        at = signal.offset - self._start
        self._formats[k].pack_into(self._raw, at, signal.encode(value))

    # --- the cycle -------------------------------------------------------------------------
    def init(self, buf: memoryview, store: ExternalVariables) -> None:
        """Start-up: every field takes the store's value."""
        self._bind(store)
        for variable in self._variables:
            for flat, value in enumerate(variable.values):
                self._store_field(buf, variable.elements[flat], value)
            variable.seen = list(variable.values)

    def latch(self, half: bytes, buf: memoryview) -> None:
        """The PLC's writes into the store. ``half`` is the latch's copy of the PLC->CNC half;
        corrections go to ``buf``, the image. Quiet cycles cost one comparison of the area's bytes."""
        if self._store is None:
            return
        raw = half[self._start : self._end]
        if raw == self._raw:
            return
        changed = int.from_bytes(raw, "little") ^ int.from_bytes(self._raw, "little")
        self._raw[:] = raw
        element_of_byte = self._element_of_byte
        while changed:
            low = changed & -changed
            byte = (low.bit_length() - 1) >> 3
            k = element_of_byte[byte]
            if k < 0:  # padding between fields: nothing to take
                changed &= ~((1 << ((byte + 1) * 8)) - 1)
                continue
            signal = self.signals[k]
            end = signal.offset - self._start + signal.size
            changed &= ~((1 << (end * 8)) - 1)  # this element done
            self._take(buf, k, self._formats[k].unpack_from(raw, signal.offset - self._start)[0])

    def _take(self, buf: memoryview, k: int, raw: bool | int | float | bytes) -> None:
        variable, flat = self._slot[k]
        shown: object = raw
        try:
            value = self.signals[k].decode(raw)
            shown = value
            taken = variable.spec.coerce(value)
        except (ExternalVariableError, SignalValueError) as exc:
            self.refused += 1
            kept = variable.values[flat]
            log.warning(
                "%s: the PLC wrote %r, refused (%s); the field keeps %r",
                self.signals[k].st_path,
                shown,
                exc,
                kept,
            )
            self._store_field(buf, k, kept)
            return
        variable.values[flat] = taken
        variable.seen[flat] = taken

    def publish(self, buf: memoryview) -> None:
        """The NC's writes of the step into the fields (one store per changed element). Quiet cycles
        cost one list comparison per variable."""
        for variable in self._variables:
            values = variable.values
            seen = variable.seen
            if values == seen:
                continue
            elements = variable.elements
            for flat, value in enumerate(values):
                if value != seen[flat]:
                    self._store_field(buf, elements[flat], value)
            variable.seen = list(values)

    @property
    def raw(self) -> bytes:
        """The V.E. fields' bytes as this sync last took or stored them (what the next latch compares the
        PLC's half with): part of the state a recording's snapshot carries (docs/record-replay.md)."""
        return bytes(self._raw)

    @raw.setter
    def raw(self, value: bytes) -> None:
        if len(value) != len(self._raw):
            raise ValueError(f"the V.E. fields span {len(self._raw)} bytes, not {len(value)}")
        self._raw[:] = value

    def values(self) -> dict[str, Any]:
        """ST path -> value as the store holds it (diagnostics and tests)."""
        out: dict[str, Any] = {}
        for k, (variable, flat) in enumerate(self._slot):
            out[self.signals[k].st_path] = variable.values[flat]
        return out
