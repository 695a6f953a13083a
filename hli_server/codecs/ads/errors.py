"""The codec's errors: one base, one for a broken stream, one carrying the ADS code to answer (H-04).

Errors that travel over the wire carry their wire code from where they are raised (conventions,
habit 7): :class:`AdsError` is raised deep in a payload decoder with the code the server answers with.
"""

from __future__ import annotations

from hli_server.codecs.ads.constants import ErrorCode

__all__ = ["AdsCodecError", "AdsError", "AmsStreamError"]


class AdsCodecError(Exception):
    """Anything this codec refuses. Fed any bytes, the codec raises nothing else."""


class AmsStreamError(AdsCodecError):
    """The byte stream cannot be delimited any more: close the connection (after answering the frames
    that came before the damage)."""


class AdsError(AdsCodecError):
    """A well-delimited frame whose payload cannot be served; ``code`` is the ADS error to answer with."""

    def __init__(self, code: ErrorCode, message: str) -> None:
        super().__init__(message)
        self.code = code

    def __str__(self) -> str:
        return f"{self.args[0]} (ADS error 0x{int(self.code):X} {self.code.name})"
