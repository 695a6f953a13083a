"""The HTTP door's uvicorn loop looks at its state once a second (``adapters/http/server.py``, ``TICK_S``),
not ten times: what a tick does still happens (the ``Date`` header), and a stop does not wait for the
next tick."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
import uvicorn

from hli_server.adapters.http import server as http_server


async def _hello(scope: dict[str, Any], receive: Any, send: Any) -> None:
    await send(
        {
            "type": "http.response.start",
            "status": 200,
            "headers": [(b"content-type", b"text/plain"), (b"content-length", b"5")],
        }
    )
    await send({"type": "http.response.body", "body": b"hello"})


async def _get(port: int) -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(b"GET / HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
    await writer.drain()
    answer = await asyncio.wait_for(reader.read(), 10.0)
    writer.close()
    await writer.wait_closed()
    return answer


def test_the_server_answers_with_a_date_and_stops_at_once_though_its_tick_is_a_minute(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(http_server, "TICK_S", 60.0)

    async def main() -> tuple[bytes, bool]:
        config = uvicorn.Config(_hello, log_config=None, access_log=False, lifespan="off", ws="none")
        server = http_server._Server(config)
        sock = http_server._listen("127.0.0.1", 0)
        task = asyncio.create_task(server.serve(sockets=[sock]))
        try:
            while not server.started:
                assert not task.done()
                await asyncio.sleep(0.005)
            answer = await _get(sock.getsockname()[1])
            server.exit_soon()
            await asyncio.wait_for(task, 10.0)  # the tick is a minute away: exit_soon woke the loop
            return answer, task.done()
        finally:
            task.cancel()
            sock.close()

    answer, stopped = asyncio.run(main())
    head = answer.split(b"\r\n\r\n", 1)[0].lower()
    assert head.startswith(b"http/1.1 200")
    assert b"\r\ndate: " in head  # renewed by the tick uvicorn takes at its start
    assert answer.endswith(b"hello")
    assert stopped
