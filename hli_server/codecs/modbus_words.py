"""Modbus word order: how a 32- or 64-bit value lies in 16-bit registers (H-03), for both sides.

The server's Modbus view (``hli_server.adapters.modbus``) and the PLC-side transports
(``plc_clients``) import this module, so that the word order exists once. No I/O, standard library.

* ``ABCD`` (the default): the most significant word first, each word big-endian (pymodbus and most
  devices). DINT -2 = 0xFFFFFFFE is ``[0xFFFF, 0xFFFE]``; 100000 = 0x000186A0 is ``[0x0001, 0x86A0]``.
* ``CDAB``: the least significant word first (Schneider style, mbpoll's default). DINT -2 is
  ``[0xFFFE, 0xFFFF]``; an LREAL's four words are fully reversed.

Register data is the bytes of the registers as they travel (each register big-endian).

A V.E. STRING (N-05) is its bytes two to a register, in the order of the characters: register k holds
bytes 2k (high byte) and 2k + 1 (low byte), as pymodbus' string payloads and most devices lay text out;
the word order does not apply to it. ``"AB"`` of a STRING(3) is ``[0x4142, 0x0000]``.
"""

from __future__ import annotations

import struct
from array import array
from collections.abc import Sequence
from typing import Final

__all__ = [
    "WORD_ORDERS",
    "check_word_order",
    "decode_value",
    "encode_value",
    "registers",
    "swap_words",
    "text_data",
    "text_registers",
    "value",
]

WORD_ORDERS: Final = ("ABCD", "CDAB")


def check_word_order(word_order: str) -> str:
    """``word_order`` in upper case, or ValueError naming the allowed ones."""
    order = str(word_order).upper()
    if order not in WORD_ORDERS:
        raise ValueError(f"Modbus word order {word_order!r}: use one of {', '.join(WORD_ORDERS)}")
    return order


def swap_words(data: bytes) -> bytes:
    """Swap the two bytes of every 16-bit word: little-endian value bytes <-> CDAB register data."""
    words = array("H", data)
    words.byteswap()
    return words.tobytes()


def encode_value(struct_char: str, value: int | float, word_order: str) -> bytes:
    """The register data of one value (``struct_char``: ``i`` DINT, ``I`` UDINT, ``d`` LREAL)."""
    if word_order == "ABCD":
        return struct.pack(">" + struct_char, value)
    return swap_words(struct.pack("<" + struct_char, value))


def decode_value(struct_char: str, data: bytes, word_order: str) -> int | float:
    """One value from its register data."""
    if word_order == "ABCD":
        result: int | float = struct.unpack(">" + struct_char, data)[0]
    else:
        result = struct.unpack("<" + struct_char, swap_words(data))[0]
    return result


def text_registers(data: bytes, count: int) -> list[int]:
    """The ``count`` registers of a STRING's bytes (NUL-padded to them), two characters to a register."""
    return list(struct.unpack(f">{count}H", data.ljust(2 * count, b"\0")))


def text_data(words: Sequence[int]) -> bytes:
    """The bytes of a STRING's registers (all of them: the field is the first ``size`` bytes)."""
    return struct.pack(f">{len(words)}H", *words)


def registers(struct_char: str, value: int | float, word_order: str) -> list[int]:
    """The registers (16-bit integers, in address order) of one value."""
    data = encode_value(struct_char, value, word_order)
    return list(struct.unpack(f">{len(data) // 2}H", data))


def value(struct_char: str, words: Sequence[int], word_order: str) -> int | float:
    """One value from its registers (16-bit integers, in address order)."""
    return decode_value(struct_char, struct.pack(f">{len(words)}H", *words), word_order)
