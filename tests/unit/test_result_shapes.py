"""The typed seam's shapes (schemas/results.py, schemas/layout.py) as the HTTP API serves them: a route's
response model validates and serializes the port's answer; that must give back exactly what the port built
(an int stays an int, no key is dropped), or the answer changes with the declaration."""

from __future__ import annotations

import json
from typing import Any

from pydantic import TypeAdapter

from hli_server.runtime.pacing import Clock, PacingStats, summarize_timing
from schemas.layout import Layout, LayoutJson, build_layout
from schemas.results import Timing
from tests.machines import demo_config


def _served(shape: Any, value: object) -> object:
    adapter = TypeAdapter(shape)
    return adapter.dump_python(adapter.validate_python(value), mode="json")


def test_the_layout_is_served_as_built_and_rebuilds_with_its_hash() -> None:
    """The V.E. variables' limits are ints for the integer types (SGN08: -128..127): the hash tells -128 from
    -128.0, so the declared shape must not turn them into floats (``limits: list[int | float]``)."""
    layout = build_layout(demo_config(external=True))
    built = layout.to_dict()
    assert any(s["limits"] for s in built["signals"])
    assert any(isinstance(s["limits"][0], int) for s in built["signals"] if s["limits"])
    served = _served(LayoutJson, built)
    assert json.dumps(served, sort_keys=True) == json.dumps(built, sort_keys=True)
    assert Layout.from_dict(json.loads(json.dumps(served))).hash == layout.hash


def test_the_timing_is_served_as_summarized() -> None:
    stats = PacingStats(0.001, window=100)
    stats.started_at = 0.0
    for k in range(50):
        stats.record(k * 1e-5)
        stats.wakeup(1)
    raw = stats.raw(Clock.REALTIME, 50)
    built = summarize_timing({**raw, "failed_cycles": 2})
    served = _served(Timing, built)
    assert served == json.loads(json.dumps(built))
    assert set(served) == set(built)
    assert built["failed_cycles"] == 2
    assert isinstance(served["t_a_us"], int)
