"""The ADS door against the attacks of issue 27 (round two), each through the real door, bounded in time.

* finding 3: a connection trickling a byte at a time must complete its frame within ``frame_timeout_s``
  and does not count as active; a full house closes its least useful connection for a newcomer;
* finding 5: the notification budget is shared per connection, per NetId (and per remote host);
* finding 9: router messages are not answered to clients the allowlist does not admit, and a frame from
  a refused NetId does not swallow the answers to the frames before it.
"""

from __future__ import annotations

import asyncio
import struct

import pytest

from hli_server.codecs.ads import AmsTcpCommand, CommandId, encode_router_frame
from tests.integration.test_ads import F020, X_POS, RawClient, ads, result_of, start_runtime

pytestmark = [pytest.mark.req("H-04"), pytest.mark.timeout(30)]


async def trickle(port: int, frame: bytes, every_s: float) -> RawClient:
    """A connection that sends ``frame`` one byte every ``every_s`` seconds, in the background."""
    client = await RawClient.connect(port)

    async def drip() -> None:
        for b in frame:
            if client.writer.is_closing():
                return
            client.writer.write(bytes([b]))
            try:
                await client.writer.drain()
            except ConnectionError:
                return
            await asyncio.sleep(every_s)

    client.drip = asyncio.get_running_loop().create_task(drip())  # type: ignore[attr-defined]
    return client


async def test_a_trickling_client_must_complete_its_frame_within_the_deadline() -> None:
    rt = await start_runtime(frame_timeout_s=0.6, idle_timeout_s=30)
    try:
        port = ads(rt).port or 0
        honest = await RawClient.connect(port)
        slow = await trickle(port, honest.frame(CommandId.READ_STATE, b""), every_s=0.2)  # 38 bytes: 7.6 s
        assert result_of(await honest.request(CommandId.READ_STATE, b"")) == 0
        assert await slow.closed(3.0)  # closed about 0.6 s after its frame began, never answered
        assert ads(rt).stats.frame_timeouts == 1
        assert result_of(await honest.request(CommandId.READ_STATE, b"")) == 0
        honest.close()
        slow.close()
    finally:
        await rt.stop()


async def test_a_full_house_of_tricklers_makes_room_for_an_honest_client() -> None:
    """The tricklers hold incomplete frames: the newcomer replaces the one holding it the longest, and a
    busy client is never the one closed while a trickler is there."""
    rt = await start_runtime(max_connections=4, frame_timeout_s=20)
    try:
        port = ads(rt).port or 0
        busy = await RawClient.connect(port)
        assert result_of(await busy.request(CommandId.READ_STATE, b"")) == 0
        frame = busy.frame(CommandId.READ_STATE, b"")
        tricklers = []
        for _ in range(3):
            tricklers.append(await trickle(port, frame, every_s=0.5))
            await asyncio.sleep(0.05)
        newcomers = []
        for _ in range(3):  # each replaces a trickler, the oldest incomplete frame first
            newcomer = await RawClient.connect(port)
            assert result_of(await newcomer.request(CommandId.READ_STATE, b"")) == 0
            newcomers.append(newcomer)
        assert [await t.closed(1.0) for t in tricklers] == [True, True, True]
        assert ads(rt).stats.evicted == 3
        assert result_of(await busy.request(CommandId.READ_STATE, b"")) == 0  # the busy one stayed
        for c in [busy, *tricklers, *newcomers]:
            c.close()
    finally:
        await rt.stop()


async def test_the_notification_budget_is_shared_per_net_id() -> None:
    """Issue 27 finding 5: connections of one NetId cannot take the whole budget; another NetId finds room."""
    rt = await start_runtime(max_notifications=4, max_notifications_per_net_id=8, max_notifications_total=16)
    try:
        port = ads(rt).port or 0
        x = rt.layout.signal(X_POS)
        add = struct.pack("<IIIIII16s", F020, x.offset, 4, 4, 0, 0, bytes(16))
        greedy = [await RawClient.connect(port) for _ in range(4)]  # one NetId, four connections
        results = [
            result_of(await c.request(CommandId.ADD_DEVICE_NOTIFICATION, add))
            for c in greedy
            for _ in range(4)
        ]
        assert results.count(0) == 8
        assert results.count(0x716) == 8
        newcomer = await RawClient.connect(port)
        newcomer.source = newcomer.source._replace(net_id=type(newcomer.source.net_id).parse("10.5.5.5.1.1"))
        assert [
            result_of(await newcomer.request(CommandId.ADD_DEVICE_NOTIFICATION, add)) for _ in range(4)
        ] == [0] * 4
        assert ads(rt).device.notification_count == 12
        for c in [*greedy, newcomer]:
            c.close()
    finally:
        await rt.stop()


async def test_router_messages_are_not_answered_outside_the_allowlist() -> None:
    """Issue 27 finding 9: with an allowlist of NetIds that does not admit the server's own, 0x1000 and
    0x1002 reveal nothing: the connection is closed without an answer."""
    rt = await start_runtime(allow="10.9.8.7.1.1")
    try:
        port = ads(rt).port or 0
        for command, body in ((AmsTcpCommand.GET_LOCAL_NETID, b""), (AmsTcpCommand.PORT_CONNECT, b"\0\0")):
            client = await RawClient.connect(port)
            client.writer.write(encode_router_frame(command, body))
            assert await client.closed(2.0)
            assert client.frames == []
            client.close()
        assert ads(rt).stats.refused_router_messages == 2
        admitted = await RawClient.connect(port)  # its NetId is on the list: served
        assert result_of(await admitted.request(CommandId.READ_STATE, b"")) == 0
        admitted.close()
    finally:
        await rt.stop()
    rt = await start_runtime(allow="loopback")  # no NetId restricted: answered, as a local router does
    try:
        client = await RawClient.connect(ads(rt).port or 0)
        client.writer.write(encode_router_frame(AmsTcpCommand.GET_LOCAL_NETID, b""))
        reply = await client.next()
        assert getattr(reply, "command", None) == AmsTcpCommand.GET_LOCAL_NETID
        client.close()
    finally:
        await rt.stop()


async def test_a_refused_net_id_does_not_swallow_the_answers_before_it() -> None:
    """Issue 27 finding 9: allowed frames and then one from a refused NetId in the same write: the
    allowed ones are answered, then the connection is closed."""
    rt = await start_runtime(allow="10.9.8.7.1.1")
    try:
        client = await RawClient.connect(ads(rt).port or 0)
        allowed = client.frame(CommandId.READ_STATE, b"") + client.frame(CommandId.READ_DEVICE_INFO, b"")
        stranger = client.source
        client.source = stranger._replace(net_id=type(stranger.net_id).parse("10.6.6.6.1.1"))
        refused = client.frame(CommandId.READ_STATE, b"")
        client.writer.write(allowed + refused)
        first, second = await client.next(), await client.next()
        assert [getattr(f, "header").command for f in (first, second)] == [  # noqa: B009
            CommandId.READ_STATE,
            CommandId.READ_DEVICE_INFO,
        ]
        assert await client.closed(2.0)
        client.close()
    finally:
        await rt.stop()
