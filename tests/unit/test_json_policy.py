"""One JSON policy for every door (issue 28 item 2): NaN and infinities become null, HTTP and MQTT alike."""

from __future__ import annotations

import json
import math

from hli_server.adapters.http.deps import SafeJSONResponse, json_bytes
from hli_server.codecs.event_json import dumps as mqtt_dumps
from hli_server.codecs.json_policy import dumps_ascii, dumps_utf8, finite


def test_non_finite_numbers_become_null_at_any_depth() -> None:
    value = {"a": math.nan, "b": [1.0, math.inf, (-math.inf, 2)], "c": {"d": "x", "e": 0.5}}
    assert finite(value) == {"a": None, "b": [1.0, None, [None, 2]], "c": {"d": "x", "e": 0.5}}


def test_every_door_writes_the_same_strict_json() -> None:
    value = {"nan": math.nan, "inf": [math.inf], "text": "Ä\ud800"}
    ascii_text = dumps_ascii(value)
    assert ascii_text == json_bytes(value) == SafeJSONResponse(value).body
    assert json.loads(ascii_text) == {"nan": None, "inf": [None], "text": "Ä\ud800"}
    assert b"NaN" not in ascii_text
    assert b"Infinity" not in ascii_text
    mqtt = json.loads(mqtt_dumps({"nan": math.nan, "t": "Ä"}))
    assert mqtt == json.loads(dumps_utf8({"nan": None, "t": "Ä"})) == {"nan": None, "t": "Ä"}


def test_finite_values_are_written_unchanged_and_compact() -> None:
    assert dumps_ascii({"x": 1.5, "y": [1, 2]}) == b'{"x":1.5,"y":[1,2]}'
