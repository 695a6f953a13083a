"""MQTT events to a broker (H-05): every typed event of ``schemas.events`` as JSON on its topic.

MQTT only listens (design.md, point 2): the adapter subscribes to the host's event feed and publishes
what the machine tells; it never writes the image and never calls the operator port except to read
the snapshot. The topics below a prefix (default ``hli/<machine>/``, see docs/mqtt.md, generated from
the schema)::

    <prefix>status          retained  "online" / "offline" (the Will: "offline" when the server vanishes)
    <prefix>snapshot        retained  JSON: the channels' states and the active alarms, now
    <prefix>dropped                   JSON: how many events the bounded queue dropped, and which
    <prefix><Event.topic()>           JSON: one event (``alarms``, ``ch/1/state``, ``ax/X/dyn_pos_limit``)

An event's message::

    {"machine": "demo", "kind": "mode", "seq": 17, "cycle": 1203, "time_s": 1.203,
     "wall_time": "2025-05-01T09:30:12.345Z", "channel": 1, "axis": null, "data": {...payload}}

``seq`` numbers the events this adapter took from the feed, from 1, without gaps: a gap is a drop
(reported on ``<prefix>dropped``), a repeated ``seq`` a redelivery after a reconnect (see below).
``wall_time`` is when the event happened (not when it was published), UTC.

**The cycle never waits on the broker** (the bar for every door). The feed calls
:meth:`MqttAdapter._on_event` inside the cycle: it appends ``(seq, wall time, event)`` to a bounded
deque and returns; no await, no lock, no encoding. A client task of its own takes the events off the
deque, encodes them and publishes them, up to :data:`WINDOW` at once, and takes them off for good only
when the broker has acknowledged them (QoS 1 and 2; QoS 0 has no acknowledgement and may lose what was
in the socket when the connection broke). While the broker is away the task reconnects with
exponential backoff (from :data:`RECONNECT_MIN_S` up to ``reconnect_max_s``); the deque keeps the
newest ``queue_size`` events, drops the oldest beyond, counts them and, once connected again,
publishes the count on ``<prefix>dropped`` and logs it. Events that were in flight when the connection
broke are published again after the reconnect: delivery is at least once, ``seq`` tells repeats.

Options (the machine file's ``[[adapters]] name = "mqtt"``, ``--adapter mqtt:KEY=VALUE``, or
``hli-server run --mqtt HOST[:PORT]``): :class:`MqttOptions`. The password can come from the
environment variable ``HLI_MQTT_PASSWORD`` instead of the command line (where ``ps`` shows it).

aiomqtt (2.x; 3.0 is a rewrite) is imported here only, and only when the client starts, so that
``hli-server run --help`` stays light.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import os
import random
import secrets
import socket
import ssl
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, TypedDict, cast

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SecretStr,
    ValidationError,
    field_validator,
    model_validator,
)

from hli_server.adapters.faults import CommFaults, Door
from hli_server.codecs.event_json import (
    DROPPED_TOPIC,
    SNAPSHOT_TOPIC,
    STATUS_TOPIC,
    dumps,
    encode_event,
    wall_time_text,
)
from schemas.events import Event
from schemas.results import CommFaultChange

if TYPE_CHECKING:
    import aiomqtt

    from hli_server.adapters.host import AdapterHost

__all__ = [
    "DEFAULT_PORT",
    "DEFAULT_TLS_PORT",
    "STATE_KINDS",
    "MqttAdapter",
    "MqttOptions",
    "MqttStats",
    "topic_safe",
]

logger = logging.getLogger(__name__)

DEFAULT_PORT: Final = 1883
DEFAULT_TLS_PORT: Final = 8883
STATE_KINDS: Final = frozenset({"program_state", "mode", "hold", "control_unit", "alarm", "alarms_cleared"})
"""Event kinds after which the retained snapshot is published again."""
WINDOW: Final = 64
"""Publishes in flight at once, each waiting for its acknowledgement (a sliding window). A broker that
delays its acknowledgements (Mosquitto without ``set_tcp_nodelay``: Nagle against the client's
delayed ACK, ~40 ms) allows about a window per 40 ms; docs/mqtt.md has the figures."""
YIELD_EVERY: Final = 8
"""Publishes started before the pump yields to the event loop, so that a burst (the queue after a
reconnect) never holds the clock's timer for more than a few hundred microseconds."""
RECONNECT_MIN_S: Final = 0.1
SNAPSHOT_INTERVAL_S: Final = 0.25
"""The retained snapshot is published at most this often (and once the queue is drained)."""
DROP_REPORT_INTERVAL_S: Final = 1.0
"""While connected, drops (a broker slower than the events) are reported at most this often."""
STOP_FLUSH_S: Final = 2.0
"""At shutdown the queued events get this long to reach the broker before ``offline`` is published."""
STILL_AWAY_LOG_S: Final = 60.0
"""While the broker stays away, a warning repeats at most this often (each failure is logged at debug)."""
PASSWORD_ENV: Final = "HLI_MQTT_PASSWORD"
OPERATION_TIMEOUT_S: Final = 5.0
"""Default of ``timeout_s``: the longest wait for the broker's CONNACK or a PUBACK before the connection
is given up and retried. It is also how long a broker that closes the connection before its CONNACK
costs: aiomqtt 2.x notices such a close only by this time-out."""


def topic_safe(name: str) -> str:
    """``name`` as one topic level: the wildcards ``+``/``#``, ``/`` and NUL become ``_``."""
    cleaned = "".join("_" if c in "+#/\x00" else c for c in name.strip())
    return cleaned or "machine"


# --------------------------------------------------------------------------------------------
# Options
# --------------------------------------------------------------------------------------------


def _split_broker(text: str) -> tuple[str, int | None]:
    """``"host"``, ``"host:1883"``, ``"[::1]:1883"``, ``"::1"`` -> (host, port or None)."""
    text = text.strip()
    if text.startswith("["):
        host, sep, rest = text[1:].partition("]")
        if not sep or (rest and not rest.startswith(":")):
            raise ValueError(f"broker {text!r}: write an IPv6 address as [ADDR] or [ADDR]:PORT")
        port_text = rest[1:] if rest else ""
    elif text.count(":") == 1:
        host, _, port_text = text.partition(":")
    else:  # a name, an IPv4 address, or a bare IPv6 address
        host, port_text = text, ""
    if not host:
        raise ValueError(f"broker {text!r}: give a host name or address, e.g. 127.0.0.1 or mqtt:1883")
    if not port_text:
        return host, None
    if not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise ValueError(f"broker {text!r}: port {port_text!r} is not a number in 1..65535")
    return host, int(port_text)


class MqttOptions(BaseModel):
    """``[[adapters]] name = "mqtt"`` / ``--adapter mqtt:KEY=VALUE`` / ``--mqtt HOST[:PORT]`` (H-05)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    broker: str = Field(
        default=f"127.0.0.1:{DEFAULT_PORT}",
        description=f"HOST[:PORT] of the broker (port {DEFAULT_PORT}, or {DEFAULT_TLS_PORT} with TLS)",
    )
    client_id: str | None = Field(
        default=None, description="MQTT client id (default: hli-<machine>-<random>, unique per process)"
    )
    username: str | None = Field(default=None, description="user name for the broker")
    password: SecretStr | None = Field(
        default=None, description=f"password for the broker (or the environment variable {PASSWORD_ENV})"
    )
    tls: bool = Field(default=False, description="connect with TLS (implied by ca_file or cert_file)")
    ca_file: str | None = Field(
        default=None, description="PEM file of the CA that signed the broker's certificate (TLS)"
    )
    cert_file: str | None = Field(default=None, description="PEM file of the client certificate (TLS)")
    key_file: str | None = Field(
        default=None, description="PEM file of the client certificate's key (if not in cert_file)"
    )
    qos: int = Field(
        default=1, ge=0, le=2, description="QoS of every message (0 may lose events when the broker drops)"
    )
    topic_prefix: str | None = Field(
        default=None, description="prefix of every topic (default: hli/<machine>/)"
    )
    queue_size: int = Field(
        default=10_000, ge=1, le=1_000_000, description="events kept while the broker is away (newest)"
    )
    keepalive: int = Field(default=30, ge=5, le=3600, description="MQTT keepalive [s]")
    reconnect_max_s: float = Field(
        default=10.0, ge=RECONNECT_MIN_S, le=3600.0, description="longest wait between reconnects [s]"
    )
    timeout_s: float = Field(
        default=OPERATION_TIMEOUT_S,
        ge=0.1,
        le=600.0,
        description="longest wait for the broker's CONNACK or a PUBACK before the connection is retried [s]",
    )
    snapshot: bool = Field(default=True, description="publish the retained snapshot of the channel states")

    @field_validator("client_id", "username", "topic_prefix", "password", "broker", mode="before")
    @classmethod
    def _text(cls, value: object) -> object:
        # `--adapter mqtt:username=1234` parses the value as an integer; these are text
        return str(value) if isinstance(value, int) and not isinstance(value, bool) else value

    @field_validator("broker")
    @classmethod
    def _broker(cls, value: str) -> str:
        _split_broker(value)
        return value.strip()

    @field_validator("topic_prefix")
    @classmethod
    def _prefix(cls, value: str | None) -> str | None:
        if value is None:
            return None
        bad = sorted({c for c in value if c in "+#\x00"})
        if bad:
            raise ValueError(
                f"topic prefix {value!r} contains {' '.join(bad)}: wildcards cannot be published to"
            )
        return value if value == "" or value.endswith("/") else value + "/"

    @model_validator(mode="after")
    def _files(self) -> MqttOptions:
        if self.key_file is not None and self.cert_file is None:
            raise ValueError("key_file needs cert_file (the client certificate it belongs to)")
        return self

    @property
    def use_tls(self) -> bool:
        return self.tls or self.ca_file is not None or self.cert_file is not None

    def host_port(self) -> tuple[str, int]:
        host, port = _split_broker(self.broker)
        return host, port if port is not None else (DEFAULT_TLS_PORT if self.use_tls else DEFAULT_PORT)


# --------------------------------------------------------------------------------------------
# The adapter
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Queued:
    seq: int
    wall: float
    event: Event


class _BrokerGoneError(Exception):
    """The connection to the broker ended (detected by the watcher task)."""


class MqttStats(TypedDict):
    """:meth:`MqttAdapter.stats`: the adapter's counters since it started."""

    connected: bool
    published: int
    queued: int
    inflight: int
    dropped: int
    unencodable: int
    connects: int
    connect_failures: int
    seq: int
    last_error: str | None


class MqttAdapter:
    """Publishes the machine's events to an MQTT broker (H-05); a client, it listens on nothing.

    ``bind`` is accepted for the adapter contract and not used. :meth:`stats` tells what was
    published, queued and dropped (tests, benchmarks); :meth:`wait_connected` waits for the broker.
    """

    name = "mqtt"

    Options = MqttOptions

    def __init__(self, *, bind: str = "127.0.0.1", **options: object) -> None:
        if options.get("password") is None and os.environ.get(PASSWORD_ENV):
            options["password"] = os.environ[PASSWORD_ENV]
        try:
            self.options = MqttOptions.model_validate(options)
        except ValidationError as exc:
            first = exc.errors()[0]
            where = ".".join(str(p) for p in first["loc"]) or "options"
            got = "***" if where == "password" else repr(first.get("input"))
            raise ValueError(f"MQTT adapter: {where}: {first['msg']} (got {got})") from None
        del bind
        self.host_name, self.port = self.options.host_port()
        self.qos = self.options.qos
        self.bound = self.options.queue_size
        self.machine = "machine"
        self.prefix = self.options.topic_prefix or "hli/machine/"
        self.client_id = self.options.client_id or ""
        self._host: AdapterHost | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread = threading.get_ident()
        self._tls: ssl.SSLContext | None = None
        self._pending: deque[_Queued] = deque()
        self._inflight: dict[int, _Queued] = {}
        """Published, not yet acknowledged, by seq (in the order they were sent)."""
        self._wakeup = asyncio.Event()
        self._stop_requested = asyncio.Event()
        self._faults = CommFaults()
        """The communication faults (docs/record-replay.md): a ``disconnect`` fault cuts the broker
        connection."""
        self._cut = asyncio.Event()
        self._unsubscribe_faults: Any = lambda: None
        self._task: asyncio.Task[None] | None = None
        self._unsubscribe: Any = None
        self._seq = 0
        self._connected = False
        self._connected_event = asyncio.Event()
        self._snapshot_due = False
        self._last_snapshot = -math.inf
        # counters (stats())
        self.published = 0
        self.dropped = 0
        self.unencodable = 0
        self.connects = 0
        self.connect_failures = 0
        self._unreported_drops = 0
        self._drop_first_seq = 0
        self._drop_last_seq = 0
        self._last_drop_report = -math.inf
        self._away_since: float | None = None
        self._last_away_log = -math.inf
        self.last_error: str | None = None
        self.library_said: str | None = None
        """The last warning of paho/aiomqtt (the reason behind a bare time-out)."""

    # --- what the runtime and the tests see ---------------------------------------------------
    @property
    def url(self) -> str:
        scheme = "mqtts" if self.options.use_tls else "mqtt"
        host = f"[{self.host_name}]" if ":" in self.host_name else self.host_name
        return f"{scheme}://{host}:{self.port}"

    @property
    def connected(self) -> bool:
        return self._connected

    def endpoints(self) -> list[str]:
        state = (
            "connected" if self._connected else f"connecting ({self.last_error})" if self.last_error else ""
        )
        return [
            f"MQTT: events to {self.url} under {self.prefix} (QoS {self.qos}, queue {self.bound}"
            + (f"; {state})" if state else ")")
        ]

    def stats(self) -> MqttStats:
        """Counters: published, queued (waiting + in flight), dropped, unencodable, connects."""
        return {
            "connected": self._connected,
            "published": self.published,
            "queued": len(self._pending) + len(self._inflight),
            "inflight": len(self._inflight),
            "dropped": self.dropped,
            "unencodable": self.unencodable,
            "connects": self.connects,
            "connect_failures": self.connect_failures,
            "seq": self._seq,
            "last_error": self.last_error,
        }

    async def wait_connected(self, timeout: float | None = None) -> None:
        """Until the adapter is connected to the broker (TimeoutError after ``timeout`` s)."""
        await asyncio.wait_for(self._connected_event.wait(), timeout)

    # --- life cycle ------------------------------------------------------------------------------
    async def start(self, host: AdapterHost) -> None:
        """Check the TLS files, subscribe to the events, start the client task. Never waits for the
        broker: an absent broker is logged and retried, the server runs on."""
        self._host = host
        self.machine = host.operator.machine_name
        if self.options.topic_prefix is None:
            self.prefix = f"hli/{topic_safe(self.machine)}/"
        if not self.client_id:
            self.client_id = f"hli-{topic_safe(self.machine)}-{secrets.token_hex(4)}"
        if self.options.use_tls:
            self._tls = self._tls_context()
        self._loop = asyncio.get_running_loop()
        self._loop_thread = threading.get_ident()
        self._unsubscribe = host.events.subscribe(self._on_event)
        self._faults = host.faults
        self._unsubscribe_faults = host.faults.subscribe(self._on_fault)
        self._task = asyncio.create_task(self._run(), name=f"hli-mqtt-{self.machine}")
        logger.info("MQTT: publishing events of %s to %s under %s", self.machine, self.url, self.prefix)

    async def stop(self) -> None:
        """Flush what is queued (up to :data:`STOP_FLUSH_S`), publish ``offline``, disconnect.
        Safe to call twice."""
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
            self._unsubscribe_faults()
        task, self._task = self._task, None
        if task is None:
            return
        self._stop_requested.set()
        self._wakeup.set()
        try:
            await asyncio.wait_for(asyncio.shield(task), STOP_FLUSH_S + 1.0)
        except TimeoutError:
            pass
        except Exception:
            logger.exception("MQTT: the client task failed")
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
        left = len(self._pending) + len(self._inflight)
        if left:
            logger.warning(
                "MQTT: %d events not published at shutdown: the broker %s was %s",
                left,
                self.url,
                "too slow" if self._connected else "away",
            )
        self._connected = False
        self._connected_event.clear()

    def _tls_context(self) -> ssl.SSLContext:
        o = self.options
        for what, path in (("ca_file", o.ca_file), ("cert_file", o.cert_file), ("key_file", o.key_file)):
            if path is not None and not Path(path).is_file():
                raise ValueError(f"MQTT adapter: {what} {path!r}: no such file; give the PEM file's path")
        try:
            context = ssl.create_default_context(cafile=o.ca_file)
            if o.cert_file is not None:
                context.load_cert_chain(o.cert_file, o.key_file)
        except (ssl.SSLError, OSError) as exc:
            raise ValueError(f"MQTT adapter: cannot load the TLS files: {exc}") from None
        return context

    # --- inside the cycle -----------------------------------------------------------------------
    def _on_event(self, event: Event) -> None:
        """The event feed's listener, called inside the cycle: queue and return (never blocks).

        An event emitted in another thread (an operator request made there) is handed to the event
        loop's thread first, in order; the queue is only ever touched there."""
        if threading.get_ident() != self._loop_thread and self._loop is not None:
            self._loop.call_soon_threadsafe(self._queue, event, time.time())
            return
        self._queue(event, time.time())

    def _on_fault(self, _change: CommFaultChange) -> None:
        """A communication fault changed: a ``disconnect`` cuts the session now (docs/record-replay.md)."""
        if self._faults.door_down(Door.MQTT):
            self._cut.set()
        else:
            self._cut.clear()
            self._wakeup.set()

    async def _while_cut(self) -> None:
        """While a ``disconnect`` fault is in effect, do not connect (it ends by itself or by the API)."""
        while self._faults.door_down(Door.MQTT) and not self._stop_requested.is_set():
            self.last_error = "disconnected on demand (communication fault)"
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stop_requested.wait(), 0.05)

    def _queue(self, event: Event, wall: float) -> None:
        self._seq += 1
        self._pending.append(_Queued(self._seq, wall, event))
        if len(self._pending) > self.bound:
            self._drop(len(self._pending) - self.bound)
        if event.KIND in STATE_KINDS:
            self._snapshot_due = True
        self._wakeup.set()

    def _drop(self, count: int) -> None:
        """Drop the ``count`` oldest waiting events (the newest are worth more), counted."""
        for _ in range(count):
            gone = self._pending.popleft()
            if self._unreported_drops == 0:
                self._drop_first_seq = gone.seq
            self._drop_last_seq = gone.seq
            self._unreported_drops += 1
            self.dropped += 1

    # --- the client task --------------------------------------------------------------------------
    async def _run(self) -> None:
        """Connect, publish, reconnect with backoff; until a stop is requested. Never raises: an
        unexpected error is logged with its traceback and retried like a lost broker."""
        import aiomqtt

        expected = (aiomqtt.MqttError, _BrokerGoneError, OSError, TimeoutError)
        delay = RECONNECT_MIN_S
        while not self._stop_requested.is_set():
            was_connected = False
            try:
                await self._while_cut()
                if self._stop_requested.is_set():
                    return
                was_connected = await self._session()
                if self._stop_requested.is_set():
                    return
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # broker away, refused, TLS, timeouts: retried, never fatal
                was_connected = was_connected or self._connected
                if not isinstance(exc, expected):
                    logger.exception("MQTT: unexpected error in the client task (retried)")
                self._connection_failed(exc)
            finally:
                self._requeue()
                if self._connected:
                    self._connected = False
                    self._connected_event.clear()
                    self._away_since = time.monotonic()
            if was_connected:
                delay = RECONNECT_MIN_S
            wait = delay * random.uniform(0.8, 1.2)  # jitter: not all clients of a farm at once
            delay = min(delay * 2, self.options.reconnect_max_s)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stop_requested.wait(), wait)

    def _connection_failed(self, exc: BaseException) -> None:
        text = _describe(exc)
        if self.library_said and self.library_said not in text:
            text = f"{text}: {self.library_said}"
        self.library_said = None
        first = self.last_error is None or self._connected
        self.last_error = text
        self.connect_failures += 1
        now = time.monotonic()
        if self._away_since is None:
            self._away_since = now
        queued = len(self._pending) + len(self._inflight)
        if first or now - self._last_away_log >= STILL_AWAY_LOG_S:
            self._last_away_log = now
            away = now - self._away_since
            logger.warning(
                "MQTT: broker %s %s: %s; retrying (backoff up to %g s); %d events queued (the newest %d "
                "are kept), %d dropped so far%s",
                self.url,
                "lost" if self._connected else "not reachable",
                text,
                self.options.reconnect_max_s,
                queued,
                self.bound,
                self.dropped,
                f"; away for {away:.0f} s" if away >= 1 else "",
            )
        else:
            logger.debug("MQTT: broker %s: %s (%d events queued)", self.url, text, queued)

    def _requeue(self) -> None:
        """Events in flight go back to the front of the queue (their order kept), then the bound."""
        if self._inflight:
            self._pending.extendleft(sorted(self._inflight.values(), key=lambda q: q.seq, reverse=True))
            self._inflight = {}
        if len(self._pending) > self.bound:
            self._drop(len(self._pending) - self.bound)

    def _client(self) -> aiomqtt.Client:
        import aiomqtt

        o = self.options
        password = o.password.get_secret_value() if o.password is not None else None
        return aiomqtt.Client(
            self.host_name,
            self.port,
            username=o.username,
            password=password,
            identifier=self.client_id,
            will=aiomqtt.Will(self.prefix + STATUS_TOPIC, b"offline", qos=self.qos, retain=True),
            keepalive=o.keepalive,
            timeout=o.timeout_s,
            tls_context=self._tls,
            max_inflight_messages=WINDOW,
            max_queued_incoming_messages=16,  # nothing is subscribed: a broker that sends anyway is bounded
            clean_session=True,
            socket_options=((socket.IPPROTO_TCP, socket.TCP_NODELAY, 1),),  # small messages, now
            logger=cast("logging.Logger", _PahoLog(self)),
        )

    async def _session(self) -> bool:
        """One connection: ``online``, the snapshot, a drop report, then the queue until the
        connection ends (raises) or a stop was requested and the queue is flushed (returns)."""
        client = self._client()
        client.pending_calls_threshold = 2 * WINDOW  # aiomqtt warns above this; the window is bounded
        self.library_said = None
        async with client:
            self._connected = True
            self._connected_event.set()
            self.connects += 1
            self.last_error = None
            if self._away_since is not None and self.connects > 1:
                logger.warning(
                    "MQTT: reconnected to %s after %.1f s away", self.url, time.monotonic() - self._away_since
                )
            else:
                logger.info("MQTT: connected to %s as %s", self.url, self.client_id)
            self._away_since = None
            await client.publish(self.prefix + STATUS_TOPIC, b"online", qos=self.qos, retain=True)
            if self.options.snapshot:
                await self._publish_snapshot(client)
            await self._report_drops(client)
            watcher = asyncio.ensure_future(_watch(client))
            pump = asyncio.ensure_future(self._pump(client))
            cut = asyncio.ensure_future(self._cut.wait())
            try:
                await asyncio.wait({watcher, pump, cut}, return_when=asyncio.FIRST_COMPLETED)
            finally:
                for task in (watcher, pump, cut):
                    task.cancel()
                await asyncio.gather(watcher, pump, cut, return_exceptions=True)
            if self._cut.is_set():
                _abort_socket(client)  # as a cable pulled: no DISCONNECT, the broker sends the Will
                raise _BrokerGoneError("disconnected on demand (communication fault)")
            if not pump.cancelled() and pump.exception() is None:
                # flushed at shutdown: say so, then a clean DISCONNECT (the Will is not sent)
                await client.publish(self.prefix + STATUS_TOPIC, b"offline", qos=self.qos, retain=True)
                return True
            error = (
                pump.exception()
                if not pump.cancelled() and pump.exception() is not None
                else (watcher.exception() if not watcher.cancelled() else None)
            )
            raise _BrokerGoneError(_describe(error) if error is not None else "connection closed")

    async def _pump(self, client: aiomqtt.Client) -> None:
        """Publish the queue with up to :data:`WINDOW` publishes in flight (a sliding window: a new
        one starts as soon as one is acknowledged); return when asked to stop and drained.

        A failed publish ends the session (raised here); what is still in flight is cancelled and,
        with the session, goes back to the front of the queue."""
        slots = asyncio.Semaphore(WINDOW)
        sends: set[asyncio.Task[None]] = set()
        failures: list[BaseException] = []
        stop_deadline: float | None = None
        started_in_slice = 0
        try:
            while True:
                if failures:
                    raise failures[0]
                if self._stop_requested.is_set() and stop_deadline is None:
                    stop_deadline = time.monotonic() + STOP_FLUSH_S
                if stop_deadline is not None and time.monotonic() > stop_deadline:
                    return
                if not self._pending:
                    if await self._idle(client, sends, stop_deadline):
                        return
                    continue
                await slots.acquire()
                if failures or not self._pending:
                    slots.release()
                    continue
                queued = self._pending.popleft()
                try:
                    topic, payload = encode_event(
                        queued.event,
                        prefix=self.prefix,
                        machine=self.machine,
                        seq=queued.seq,
                        wall=queued.wall,
                    )
                except Exception:  # a bad event must not stop the others
                    slots.release()
                    self.unencodable += 1
                    logger.exception(
                        "MQTT: cannot encode event %s (seq %d); skipped", queued.event.kind, queued.seq
                    )
                    continue
                self._inflight[queued.seq] = queued
                send = asyncio.ensure_future(self._send(client, queued, topic, payload, slots, failures))
                sends.add(send)
                send.add_done_callback(sends.discard)
                started_in_slice += 1
                if (
                    started_in_slice >= YIELD_EVERY
                ):  # let the clock's timer in between (a burst after a reconnect)
                    started_in_slice = 0
                    await asyncio.sleep(0)
                await self._now_and_then(client)
        finally:
            for send in list(sends):
                send.cancel()
            if sends:
                await asyncio.gather(*sends, return_exceptions=True)

    async def _send(
        self,
        client: aiomqtt.Client,
        queued: _Queued,
        topic: str,
        payload: bytes,
        slots: asyncio.Semaphore,
        failures: list[BaseException],
    ) -> None:
        try:
            await client.publish(topic, payload, qos=self.qos)
            del self._inflight[queued.seq]
            self.published += 1
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # stays in flight: requeued with the session
            failures.append(exc)
            self._wakeup.set()
        finally:
            slots.release()

    async def _idle(self, client: aiomqtt.Client, sends: set[asyncio.Task[None]], stop: float | None) -> bool:
        """Nothing waits: the drop report, the throttled snapshot, then wait for an event (or, at a
        stop, for the acknowledgements of what is in flight). True: stopped and drained."""
        await self._report_drops(client)
        timeout: float | None = None
        if self._snapshot_due and self.options.snapshot:
            timeout = SNAPSHOT_INTERVAL_S - (time.monotonic() - self._last_snapshot)
            if timeout <= 0 or stop is not None:
                await self._publish_snapshot(client)
                return False
        if stop is not None:
            if sends:
                await asyncio.wait(set(sends), timeout=max(0.0, stop - time.monotonic()))
            return not self._pending
        self._wakeup.clear()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._wakeup.wait(), timeout)
        return False

    async def _now_and_then(self, client: aiomqtt.Client) -> None:
        """While events flow: the snapshot and the drop report, each at most at its interval."""
        now = time.monotonic()
        if self._snapshot_due and self.options.snapshot and now - self._last_snapshot >= SNAPSHOT_INTERVAL_S:
            await self._publish_snapshot(client)
        if self._unreported_drops and now - self._last_drop_report >= DROP_REPORT_INTERVAL_S:
            await self._report_drops(client)

    async def _publish_snapshot(self, client: aiomqtt.Client) -> None:
        host = self._host
        if host is None:
            return
        self._snapshot_due = False
        self._last_snapshot = time.monotonic()
        try:
            snap = host.operator.snapshot()
            message = {
                "machine": self.machine,
                "seq": self._seq,
                "cycle": snap.get("cycle"),
                "time_s": snap.get("time_s"),
                "wall_time": wall_time_text(time.time()),
                "channels": snap.get("channels", []),
                "alarms": snap.get("alarms", []),
            }
            payload = dumps(message)
        except Exception:
            logger.exception("MQTT: cannot take the snapshot; not published")
            return
        await client.publish(self.prefix + SNAPSHOT_TOPIC, payload, qos=self.qos, retain=True)

    async def _report_drops(self, client: aiomqtt.Client) -> None:
        count = self._unreported_drops
        if count == 0:
            return
        first, last = self._drop_first_seq, self._drop_last_seq
        message = {
            "machine": self.machine,
            "dropped": count,
            "dropped_total": self.dropped,
            "first_seq": first,
            "last_seq": last,
            "queue_size": self.bound,
            "wall_time": wall_time_text(time.time()),
        }
        await client.publish(self.prefix + DROPPED_TOPIC, dumps(message), qos=self.qos)
        self._unreported_drops = 0
        self._last_drop_report = time.monotonic()
        logger.warning(
            "MQTT: %d events dropped while the broker %s was away or slow (seq %d..%d; queue bound %d; "
            "%d in total); reported on %s",
            count,
            self.url,
            first,
            last,
            self.bound,
            self.dropped,
            self.prefix + DROPPED_TOPIC,
        )

    def __repr__(self) -> str:
        return f"MqttAdapter({self.url}, prefix={self.prefix!r}, {self.stats()})"


class _PahoLog(logging.LoggerAdapter):  # type: ignore[type-arg]
    """paho's and aiomqtt's log lines, for one adapter: a warning or error (a TLS alert, a socket
    error) is kept as the reason of the next failure, which the adapter reports rate-limited, and is
    logged at debug only (paho would repeat it at every reconnect)."""

    def __init__(self, owner: MqttAdapter) -> None:
        super().__init__(logging.getLogger(f"{__name__}.paho"), {})
        self.owner = owner

    def log(self, level: int, msg: object, *args: object, **kwargs: Any) -> None:
        if level >= logging.WARNING:
            with contextlib.suppress(Exception):
                self.owner.library_said = str(msg) % args if args else str(msg)
            level = logging.DEBUG
        super().log(level, msg, *args, **kwargs)


def _abort_socket(client: aiomqtt.Client) -> None:
    """Close the connection's socket under paho (aiomqtt's ``_client``), as a lost link would."""
    with contextlib.suppress(Exception):
        sock = client._client.socket()
        if isinstance(sock, socket.socket):
            sock.shutdown(socket.SHUT_RDWR)


async def _watch(client: aiomqtt.Client) -> None:
    """Ends (with aiomqtt's MqttError) when the connection ends: the client's message iterator is
    aiomqtt's public signal of a disconnect. Nothing is subscribed, so no message arrives."""
    async for _ in client.messages:
        pass
    raise _BrokerGoneError("the message stream ended")


def _describe(exc: BaseException | None) -> str:
    """A short, useful text for an exception of aiomqtt/paho/ssl/OSError."""
    if exc is None:
        return "unknown error"
    text = str(exc) or type(exc).__name__
    cause = exc.__cause__ or exc.__context__
    if isinstance(exc, _BrokerGoneError) or cause is None:
        return text
    return f"{text} ({cause})" if str(cause) and str(cause) not in text else text
