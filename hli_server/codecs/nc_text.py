"""The text of an NC program file, from its bytes (issue 33, item 7): files as shops write them.

The kernel reads its program files on Windows. A program written there is UTF-8 (with or without the
byte order mark Notepad puts first) or, in an older or German shop, Windows-1252: ``; Prüfung`` with
``ü`` as the single byte 0xFC. Both are read here alike, so that an umlaut in a comment never refuses
a program:

* a UTF-8 byte order mark: UTF-8, the mark dropped (``utf-8-sig``);
* a UTF-16 byte order mark (Notepad's "Unicode"): UTF-16;
* bytes that are valid UTF-8 (plain ASCII is): UTF-8;
* anything else: Windows-1252; the five bytes Windows-1252 leaves undefined (0x81, 0x8D, 0x8F, 0x90,
  0x9D) make it ISO 8859-1 (Latin-1) instead, which gives every byte a character. The two agree on
  every byte but 0x80..0x9F (``€``, ``„``, ``–``, ...: Windows-1252's printable characters there).

Sans I/O, as the other codecs: :func:`decode_program` takes the whole file's bytes; a file streamed
(``check --geometry-only`` of millions of lines) is fed to an :class:`EncodingSniffer` a piece at a time
first, and then opened with the encoding it names.
"""

from __future__ import annotations

import codecs
from typing import Final

__all__ = ["EncodingSniffer", "decode_program", "program_encoding"]

UTF8_BOM: Final = codecs.BOM_UTF8
_UTF16_BOMS: Final = (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)
_CP1252_UNDEFINED: Final = frozenset(b"\x81\x8d\x8f\x90\x9d")
_UNDEFINED_TABLE: Final = bytes(range(256)).translate(None, bytes(_CP1252_UNDEFINED))
"""Every byte but the five Windows-1252 leaves undefined: ``data.translate(None, ...)`` keeps those."""


class EncodingSniffer:
    """Finds the encoding of a program fed piece by piece (:meth:`feed`), in one pass with flat memory;
    :meth:`encoding` names it for :func:`open` (``utf-8``, ``utf-8-sig``, ``utf-16``, ``cp1252`` or
    ``latin-1``)."""

    def __init__(self) -> None:
        self._head = b""
        self._bom: str | None = None
        self._started = False
        self._utf8 = codecs.getincrementaldecoder("utf-8")()
        self._valid_utf8 = True
        self._cp1252 = True

    def feed(self, data: bytes) -> None:
        if not self._started:
            self._head += data
            if len(self._head) < 3 and data:
                return  # too short to tell a byte order mark yet
            self._started = True
            data, self._head = self._head, b""
            if data.startswith(UTF8_BOM):
                self._bom = "utf-8-sig"
                data = data[len(UTF8_BOM) :]
            elif data.startswith(_UTF16_BOMS):
                self._bom = "utf-16"
                return
        elif self._bom == "utf-16":
            return
        if self._valid_utf8:
            try:
                self._utf8.decode(data)
            except UnicodeDecodeError:
                self._valid_utf8 = False
        if self._cp1252 and data.translate(None, _UNDEFINED_TABLE):
            self._cp1252 = False

    def encoding(self) -> str:
        """The encoding of everything fed (the end of the file: a UTF-8 sequence cut off there is not
        UTF-8)."""
        if not self._started:
            self.feed(b"")
        if self._bom == "utf-16":
            return "utf-16"
        if self._valid_utf8:
            try:
                self._utf8.decode(b"", final=True)
            except UnicodeDecodeError:
                self._valid_utf8 = False
        if self._valid_utf8:
            return self._bom or "utf-8"
        return "cp1252" if self._cp1252 else "latin-1"

    @property
    def skip(self) -> int:
        """Bytes to skip before decoding with :meth:`encoding`: a UTF-8 byte order mark before bytes that
        are not UTF-8 (``utf-8-sig`` and ``utf-16`` drop their mark themselves)."""
        return len(UTF8_BOM) if self._bom == "utf-8-sig" and not self._valid_utf8 else 0


def program_encoding(data: bytes) -> str:
    """The encoding of a whole program's bytes (see the module's description)."""
    sniffer = EncodingSniffer()
    sniffer.feed(data)
    return sniffer.encoding()


def decode_program(data: bytes) -> str:
    """A program's text from its file's bytes: UTF-8 (a byte order mark dropped), UTF-16 with its mark,
    else Windows-1252 / Latin-1 (see the module's description). Never fails on a byte of a one-byte
    encoding; a UTF-16 file cut in half raises UnicodeDecodeError."""
    sniffer = EncodingSniffer()
    sniffer.feed(data)
    encoding = sniffer.encoding()
    return data[sniffer.skip :].decode(encoding)
