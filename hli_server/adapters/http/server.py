"""The HTTP adapter: serves :func:`~hli_server.adapters.http.app.create_app` with uvicorn.

It is served *inside the runtime's event loop* (``uvicorn.Server.serve()`` as a task on a socket the
adapter binds itself); the runtime owns the signals. Every handler is ``async def``: a plain ``def``
handler would run in a worker thread and touch the machine from outside the loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Generator

import uvicorn

from hli_server.adapters.host import AdapterHost
from hli_server.adapters.http.app import create_app
from hli_server.adapters.http.live_feed import LiveFeed
from hli_server.adapters.http.options import HttpOptions
from hli_server.adapters.http.protocol import abort_stalled, bounded_protocol

__all__ = ["HttpApiAdapter"]

logger = logging.getLogger(__name__)


#: how often the server's loop looks at its state (uvicorn's own loop: ten times a second)
TICK_S = 1.0


class _Server(uvicorn.Server):
    """uvicorn without its own signal handling (the runtime owns SIGINT/SIGTERM), and with its main loop
    woken once a second instead of ten times: what uvicorn does on a tick (the ``Date`` header renewed once
    a second, the look at ``should_exit``) needs no more, and :meth:`exit_soon` wakes it at once. An idle
    server's doors process then wakes a few times a second (docs/performance.md)."""

    def __init__(self, config: uvicorn.Config) -> None:
        super().__init__(config)
        self._exit_asked = asyncio.Event()

    @contextlib.contextmanager
    def capture_signals(self) -> Generator[None, None, None]:
        yield

    async def main_loop(self) -> None:
        counter = 0
        should_exit = await self.on_tick(counter)
        while not should_exit:
            # uvicorn counts tenths of a second and renews the Date header at every tenth count
            counter = (counter + 10) % 864000
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._exit_asked.wait(), TICK_S)
            should_exit = await self.on_tick(counter)

    def exit_soon(self) -> None:
        """Stop serving (uvicorn's graceful shutdown follows), now rather than at the next tick."""
        self.should_exit = True
        self._exit_asked.set()


class HttpApiAdapter:
    """Serves the control API on ``bind:port`` (0 = a free port; :attr:`port` tells which)."""

    name = "http"
    Options = HttpOptions

    def __init__(self, *, bind: str = "127.0.0.1", **options: object) -> None:
        self.options = HttpOptions.model_validate(options)
        self.bind = bind
        self.requested_port = self.options.port
        self.port: int | None = None
        self.graceful_timeout_s = self.options.graceful_timeout_s
        self._server: _Server | None = None
        self._task: asyncio.Task[None] | None = None
        self._socket: socket.socket | None = None
        self._live: LiveFeed | None = None

    @property
    def url(self) -> str:
        if self.port is None:
            raise RuntimeError("the HTTP API is not listening (start it first)")
        host = f"[{self.bind}]" if ":" in self.bind else self.bind
        return f"http://{host}:{self.port}"

    def endpoints(self) -> list[str]:
        if self.port is None:
            return ["HTTP control API: not listening"]
        return [f"HTTP control API: {self.url}  (OpenAPI: {self.url}/docs)"]

    async def start(self, host: AdapterHost) -> None:
        self._socket = sock = _listen(self.bind, self.requested_port)
        self.port = sock.getsockname()[1]
        options = self.options
        app = create_app(
            host,
            max_body_bytes=options.max_body_bytes,
            max_streams=options.max_streams,
            live_rate_hz=options.live_rate_hz,
        )
        self._live = app.state.live
        config = uvicorn.Config(
            app,
            log_config=None,
            access_log=False,
            lifespan="off",
            ws="none",
            http=bounded_protocol(
                options.max_connections,
                options.idle_timeout_s,
                options.request_timeout_s,
                options.write_timeout_s,
            ),
            timeout_keep_alive=options.keep_alive_s,
            timeout_graceful_shutdown=self.graceful_timeout_s,
        )
        self._server = server = _Server(config)
        self._task = task = asyncio.create_task(server.serve(sockets=[sock]), name="hli-http-api")
        while not server.started:
            if task.done():
                sock.close()
                task.result()  # raises what went wrong
                raise RuntimeError(f"HTTP control API on {self.bind}:{self.port} stopped during start-up")
            await asyncio.sleep(0.005)

    async def stop(self) -> None:
        server, task = self._server, self._task
        self._server = self._task = None
        if self._live is not None:
            # end the dashboards' event streams first: an open stream would hold the graceful shutdown;
            # a client that does not read what it was sent would hold it too: it is dropped
            await self._live.close()
            self._live = None
        if server is not None:
            abort_stalled(server.server_state.connections)
        if server is not None and task is not None:
            server.exit_soon()
            try:
                await asyncio.wait_for(asyncio.shield(task), self.graceful_timeout_s + 3.0)
            except TimeoutError:
                logger.warning("HTTP control API did not stop in time; closing its connections")
                server.force_exit = True
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
        if self._socket is not None:
            self._socket.close()
            self._socket = None
        self.port = None


def _listen(bind: str, port: int) -> socket.socket:
    try:
        infos = socket.getaddrinfo(bind, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise OSError(f"HTTP control API: cannot resolve bind address {bind!r}: {exc.strerror}") from None
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(128)
    except OSError as exc:
        sock.close()
        raise OSError(
            exc.errno,
            f"HTTP control API: cannot listen on {bind}:{port}: {exc.strerror}; "
            "choose another --http-port (0 = any free port) or --bind address",
        ) from None
    sock.setblocking(False)
    return sock
