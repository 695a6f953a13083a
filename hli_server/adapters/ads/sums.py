"""Sum commands: many reads, writes or read-writes in one ReadWrite (0xF080, 0xF081, 0xF082; H-04).

Each sub-request is served as if it came alone, through the same port table (so a sum read of symbols
by handle, of the halves and of the view all work), and gets its own result; the sum command itself
fails only when its frame does (a count above ``max_sum_items`` (TwinCAT's limit: 500) or a length
that does not fit: 0x705). Sub-writes are performed in the order given; a refused one changes nothing
and the others go on. Layouts: :mod:`hli_server.codecs.ads.symbols`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hli_server.codecs.ads import (
    AdsError,
    ErrorCode,
    SumRead,
    SumReadWrite,
    SumWrite,
    encode_sum_read_reply,
    encode_sum_read_write_reply,
    encode_sum_write_reply,
)

if TYPE_CHECKING:
    from hli_server.adapters.ads.session import DeviceStats, PortTable, Session

__all__ = ["SumService"]


class SumService:
    def __init__(self, stats: DeviceStats, max_items: int) -> None:
        self.stats = stats
        self.max_items = max_items

    def _count(self, count: int, what: str) -> None:
        if count > self.max_items:
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"{what} of {count} sub-requests: at most {self.max_items} per sum command",
            )

    def read(self, session: Session, table: PortTable, count: int, read_length: int, data: bytes) -> bytes:
        self._count(count, "sum read 0xF080")
        request = SumRead.decode(count, data)
        if read_length < request.reply_length:
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"sum read of {count}: the reply is {request.reply_length} bytes, read length {read_length}",
            )
        stats = self.stats
        results: list[tuple[int, bytes]] = []
        for item in request.items:
            try:
                results.append(
                    (0, table.read_group(session, item.index_group, item.index_offset, item.length))
                )
            except AdsError as exc:
                stats.count_error(exc.code)
                results.append((int(exc.code), b""))
        return encode_sum_read_reply(request, results)

    def write(self, session: Session, table: PortTable, count: int, read_length: int, data: bytes) -> bytes:
        self._count(count, "sum write 0xF081")
        request = SumWrite.decode(count, data)
        if read_length < 4 * count:
            raise AdsError(ErrorCode.SIZE_WRONG, f"sum write of {count}: the reply is {4 * count} bytes")
        stats = self.stats
        results: list[int] = []
        for item in request.items:
            try:
                table.write_group(session, item.index_group, item.index_offset, item.data)
                results.append(0)
            except AdsError as exc:
                stats.count_error(exc.code)
                results.append(int(exc.code))
        return encode_sum_write_reply(results)

    def read_write(
        self, session: Session, table: PortTable, count: int, read_length: int, data: bytes
    ) -> bytes:
        self._count(count, "sum read/write 0xF082")
        request = SumReadWrite.decode(count, data)
        stats = self.stats
        results: list[tuple[int, bytes]] = []
        for item in request.items:
            try:
                value = table.read_write_group(
                    session, item.index_group, item.index_offset, item.read_length, item.data
                )
                results.append((0, value))
            except AdsError as exc:
                stats.count_error(exc.code)
                results.append((int(exc.code), b""))
        reply = encode_sum_read_write_reply(results)
        if read_length < len(reply):
            raise AdsError(
                ErrorCode.SIZE_WRONG,
                f"sum read/write of {count}: the reply is {len(reply)} bytes, read length {read_length}",
            )
        return reply
