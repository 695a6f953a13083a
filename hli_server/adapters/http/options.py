"""Options of the HTTP control API adapter (light: importing it does not import FastAPI)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["DEFAULT_PORT", "HttpOptions"]

DEFAULT_PORT = 8080


class HttpOptions(BaseModel):
    """``[[adapters]] name = "http"`` / ``--adapter http:KEY=VALUE`` / ``--http-port``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    port: int = Field(default=DEFAULT_PORT, ge=0, le=65535, description="TCP port (0: any free port)")
    graceful_timeout: int = Field(
        default=2, ge=0, le=60, description="seconds open requests get to finish at shutdown"
    )
