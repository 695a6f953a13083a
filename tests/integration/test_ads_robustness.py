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


# --- round three (issue 36, finding 9): every edge request is answered ----------------------------------


_GROUPS = (0, 0x4020, 0xF003, 0xF005, 0xF006, 0xF008, 0xF020, 0xF021, 0xF030, 0xF031, 0xF080, 0xF081, 0xF082,
           0xF083, 0xF100, 0x120300, 0xFFFFFFFF)  # fmt: skip
_EDGES = (0, 1, 4, 0x7FFFFFFF, 0xFFFFFFFF)


def _edge_requests() -> list[tuple[int, int, bytes]]:
    """(port, command, payload): every command of a device with index groups of every service, offsets and
    lengths at their edges (0, 1, 4, 2^31 - 1, 2^32 - 1), on ports 851, 551 and 10000."""
    out: list[tuple[int, int, bytes]] = []
    for port in (851, 551, 10000):
        for g in _GROUPS:
            for o in _EDGES:
                for n in _EDGES:
                    short = min(n, 12)
                    out += [
                        (port, CommandId.READ, struct.pack("<III", g, o, n)),
                        (port, CommandId.WRITE, struct.pack("<III", g, o, min(n, 8)) + b"\x01" * min(n, 8)),
                        (port, CommandId.WRITE, struct.pack("<III", g, o, n)),
                        (port, CommandId.READ_WRITE, struct.pack("<IIII", g, o, n, short) + bytes(short)),
                        (port, CommandId.READ_WRITE, struct.pack("<IIII", g, o, 4, n)),
                        (
                            port,
                            CommandId.ADD_DEVICE_NOTIFICATION,
                            struct.pack("<IIIIII16x", g, o, n, 4, 0, 10000),
                        ),
                    ]
            out.append((port, CommandId.DELETE_DEVICE_NOTIFICATION, struct.pack("<I", g)))
        out += [(port, CommandId.READ_STATE, b""), (port, CommandId.READ_DEVICE_INFO, b"")]
    return out


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_every_edge_request_gets_an_answer_or_its_connection_is_closed() -> None:
    """Before: 14 of 31,104 edge requests got no answer at all: a notification of the symbol version or the
    device state 0x7FFFFFFF or 0xFFFFFFFF bytes long built a sample of 2 or 4 GB (seconds, and a probe of
    ours grew past 6 GB); with the server's address space bounded to 1 GiB here, those 20 requests failed
    inside it (0x700). Now each of these 7,000 requests is answered with its own code (0x705 for those
    lengths), none closes its connection, and the server answers the next client."""
    import resource
    import subprocess

    from tests.integration.servers import door_port, hli_server_cmd, read_banner, stop_server

    proc = subprocess.Popen(
        [*hli_server_cmd(), "run", "--clock", "stepped", "--no-http", "--no-modbus", "--ads-port", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    resource.prlimit(proc.pid, resource.RLIMIT_AS, (1 << 30, 1 << 30))  # its doors process inherits it
    requests = _edge_requests()
    silent: list[tuple[int, int, str]] = []
    codes: dict[int, int] = {}

    async def sweep(port: int) -> None:
        for k in range(0, len(requests), 50):  # 50 pipelined on a connection of their own
            client = await RawClient.connect(port)
            waiting = {}
            for target, command, payload in requests[k : k + 50]:
                client.writer.write(client.frame(command, payload, target))
                waiting[client.invoke] = (target, command, payload.hex()[:32])
            await client.writer.drain()
            try:
                while waiting:
                    frame = await client.next(timeout=3.0)
                    if frame.header.is_response and waiting.pop(frame.header.invoke_id, None) is not None:
                        code = result_of(frame) if frame.header.error_code or len(frame.data) >= 4 else 0
                        codes[code] = codes.get(code, 0) + 1
            except TimeoutError:
                silent.extend(waiting.values())
            finally:
                client.close()
        last = await RawClient.connect(port)
        assert result_of(await last.request(CommandId.READ_STATE, b"")) == 0
        last.close()

    try:
        banner = read_banner(proc, timeout=60)
        asyncio.run(sweep(door_port(banner["ADS (AMS/TCP)"])))
    finally:
        stop_server(proc)
    assert not silent, silent[:20]
    assert sum(codes.values()) == len(requests)  # every one answered on its open connection
    assert codes.get(0x700, 0) == 0, codes  # none failed inside the server (before: 20, out of memory)
    assert codes.get(0x705, 0) > 0


async def _add_many(client: RawClient, payload: bytes, count: int) -> list[int]:
    """``count`` AddDeviceNotification pipelined on one connection; their results in order."""
    invokes = []
    for _ in range(count):
        client.writer.write(client.frame(CommandId.ADD_DEVICE_NOTIFICATION, payload))
        invokes.append(client.invoke)
    await client.writer.drain()
    results: dict[int, int] = {}
    while len(results) < count:
        frame = await client.next(timeout=10.0)
        if frame.header.is_response and frame.header.command == CommandId.ADD_DEVICE_NOTIFICATION:
            results[frame.header.invoke_id] = result_of(frame)
    return [results[k] for k in invokes]


@pytest.mark.timeout(60)
async def test_a_newcomer_gets_its_share_of_a_full_notification_budget_and_the_hog_pays() -> None:
    """Round two's probe again: eight loopback clients (eight NetIds; loopback peers are not bounded per
    host) hold 256 notifications each, the server's 2,048. Before: a ninth, honest client got 0x716 for
    every one. Now it is served up to its share (2,048 / 9 = 227): each of its notifications takes the
    newest of the NetId holding the most; beyond its share it gets 0x716 like anybody."""
    rt = await start_runtime()
    clients: list[RawClient] = []
    try:
        port = ads(rt).port or 0
        x = rt.layout.signal(X_POS)
        add = struct.pack("<IIIIII16s", F020, x.offset, 4, 4, 0, 0, bytes(16))
        for k in range(9):
            client = await RawClient.connect(port)
            client.source = client.source._replace(
                net_id=type(client.source.net_id).parse(f"10.7.7.{k + 1}.1.1")
            )
            clients.append(client)
        for hog in clients[:8]:
            assert await _add_many(hog, add, 256) == [0] * 256
        device = ads(rt).device
        assert device.notification_count == 2048
        newcomer = await _add_many(clients[8], add, 256)
        assert newcomer[:227] == [0] * 227
        assert set(newcomer[227:]) == {0x716}
        assert device.notification_count == 2048
        assert device.stats.notifications_evicted == 227
    finally:
        for client in clients:
            client.close()
        await rt.stop()


async def test_a_flood_of_oversize_sum_commands_is_answered_not_reset() -> None:
    """Before: a sum write of 500 items of 200 bytes (100 KB, more than the 64 KiB frame the door takes)
    closed the connection without an ADS error code, and so did a flood of them. Now each is answered 0x705
    (its bytes dropped as they arrive, never held) and the connection goes on serving."""
    rt = await start_runtime()
    client = await RawClient.connect(ads(rt).port or 0)
    try:
        items = b"".join(struct.pack("<III", F020, 0, 200) for _ in range(500)) + bytes(200) * 500
        sum_write = struct.pack("<IIII", 0xF081, 500, 500 * 4, len(items)) + items
        assert len(sum_write) > 100_000
        for _ in range(50):
            client.writer.write(client.frame(CommandId.READ_WRITE, sum_write))
        await client.writer.drain()
        results = [result_of(await client.next(timeout=10.0)) for _ in range(50)]  # type: ignore[arg-type]
        assert results == [0x705] * 50
        x = rt.layout.signal(X_POS)
        read = await client.request(CommandId.READ, struct.pack("<III", F020, x.offset, 4))
        assert result_of(read) == 0  # the same connection, still served
        assert ads(rt).stats.broken_streams == 0
    finally:
        client.close()
        await rt.stop()
