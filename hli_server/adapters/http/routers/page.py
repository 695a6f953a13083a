"""``/``: the dashboard page (docs/dashboard.md), its script and its style sheet, shipped with the package.

Three files of ``hli_server/adapters/http/static/`` (plain HTML, JavaScript and CSS, SVG drawn by the
script: no build step, nothing fetched from elsewhere), read once and served from memory with headers
that keep the page to itself: a Content-Security-Policy that allows only this server's own scripts,
styles and connections and forbids framing (another site cannot put the operator panel in a frame and
trick clicks onto it), ``nosniff``, and ``no-cache`` so that a new version is picked up at once.

The page is served with the machine as it is at that moment (docs/dashboard.md): the ``hello``, ``state`` and
``scene`` messages of the live stream, the newest events of the event log and the recorder's status (what
``GET /api/recording`` answers: a recording started with ``--record`` shows at once), as JSON in a data block
(``<script type="application/json" id="initial">``, which runs nothing and so passes the policy). The
script draws them before the page's load event, so the page is whole at once (a screenshot, a slow
stream) and shows what happened before it was opened; the stream then carries it on.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from importlib import resources
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import Response

from hli_server.adapters.host import LoggedEvent
from hli_server.adapters.http.deps import json_bytes
from hli_server.adapters.http.live_feed import LiveFeed
from schemas.results import RecorderStatus

__all__ = ["PAGE_FILES", "router"]

router = APIRouter(tags=["dashboard"])

PAGE_FILES = {
    "index.html": "text/html; charset=utf-8",
    "dashboard.js": "text/javascript; charset=utf-8",
    "dashboard.css": "text/css; charset=utf-8",
}

_HEADERS = {
    "content-security-policy": (
        "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
        "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'"
    ),
    "x-content-type-options": "nosniff",
    "x-frame-options": "DENY",
    "referrer-policy": "no-referrer",
    "cache-control": "no-cache",
}


@cache
def _read(name: str) -> bytes:
    return (resources.files("hli_server.adapters.http") / "static" / name).read_bytes()


def _file(name: str) -> Response:
    return Response(_read(name), media_type=PAGE_FILES[name], headers=_HEADERS)


EVENTS_SHOWN = 200
"""The newest events the page is served with (its list keeps as many)."""

_INITIAL_MARK = b"<!-- initial state -->"


def _initial(feed: LiveFeed, events_allowed: bool = True) -> dict[str, Any]:
    """``events_allowed``: whether the request may read the event log (with a token set: only a holder of
    it, reliability.md, round 2, finding 8; the page then asks for the token and its stream brings the
    events)."""
    host = feed.host
    scenes = []
    for number in host.operator.channel_numbers():
        try:
            scenes.append(host.operator.scene(number))
        except Exception:  # the stream says so (once); the page goes without this picture
            continue
    events: Sequence[LoggedEvent] = []
    if events_allowed:
        _, latest = host.events.since(0, 1)
        events, _ = host.events.since(max(0, latest - EVENTS_SHOWN), EVENTS_SHOWN)
    recording: RecorderStatus | None
    try:
        recording = host.recorder.status()
    except Exception:  # the page polls /api/recording and says what it gets
        recording = None
    return {
        "hello": feed.hello_body(events=events_allowed),
        "state": feed.state(),
        "scenes": scenes,
        "events": [event.to_json() for event in events],
        "recording": recording,
    }


@router.get("/", include_in_schema=False)
async def index(request: Request) -> Response:
    feed: LiveFeed = request.app.state.live
    # JSON inside HTML: "<" escaped, so that no text of an event can end the data block
    events_allowed = bool(getattr(request.state, "hli_token", True))
    data = json_bytes(_initial(feed, events_allowed)).replace(b"<", b"\\u003c")
    block = b'<script type="application/json" id="initial">' + data + b"</script>"
    page = _read("index.html").replace(_INITIAL_MARK, block, 1)
    return Response(page, media_type=PAGE_FILES["index.html"], headers=_HEADERS)


@router.get("/dashboard.js", include_in_schema=False)
async def script() -> Response:
    return _file("dashboard.js")


@router.get("/dashboard.css", include_in_schema=False)
async def style() -> Response:
    return _file("dashboard.css")
