"""``/``: the dashboard page (docs/dashboard.md), its script and its style sheet, shipped with the package.

Three files of ``hli_server/adapters/http/static/`` (plain HTML, JavaScript and CSS, SVG drawn by the
script: no build step, nothing fetched from elsewhere), read once and served from memory with headers
that keep the page to itself: a Content-Security-Policy that allows only this server's own scripts,
styles and connections and forbids framing (another site cannot put the operator panel in a frame and
trick clicks onto it), ``nosniff``, and ``no-cache`` so that a new version is picked up at once.
"""

from __future__ import annotations

from functools import cache
from importlib import resources

from fastapi import APIRouter
from fastapi.responses import Response

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


@router.get("/", include_in_schema=False)
async def index() -> Response:
    return _file("index.html")


@router.get("/dashboard.js", include_in_schema=False)
async def script() -> Response:
    return _file("dashboard.js")


@router.get("/dashboard.css", include_in_schema=False)
async def style() -> Response:
    return _file("dashboard.css")
