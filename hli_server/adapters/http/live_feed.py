"""The dashboard's live feed: one server-sent event stream per open page (``GET /api/live``,
docs/dashboard.md).

What a stream carries (``event:`` names, ``data:`` one JSON object each):

* ``hello`` once: the machine (name, clock, channels with their axes and program tables, axes), and
  whether state changes need a token (``token``) or are refused (``read_only``);
* ``state`` at a fixed rate (20 Hz by default): cycle and time, per channel mode, program state, holds,
  program, active block and line, the override and feedhold in effect; per axis command and actual
  position, following error, velocity, referenced / in position / moving / error, the dynamic position
  limits (enable, limit, state ``HLI_DYNPL_STATE_*``) and the collision monitoring's braking distance;
  the collision pairs with distance and braking distances; the active alarms;
* ``event``: every typed event of the event feed (``schemas.events``), as ``GET /api/events`` shows it;
* ``scene``: a channel's scene (``hli_server.scene``, the picture ``check --plot`` draws) when it
  changed: on an event of its channel that changes it (a program state, an alarm, the areas) at the next
  tick, else looked at every :data:`SCENE_PERIOD_S`;
* ``dropped``: how many events this stream has lost because the page read too slowly.

Why it never slows the cycle: the event listener runs inside the cycle and only appends the event
object to each stream's bounded queue (:attr:`LiveFeed.queue_size`; a full queue drops the event and
counts it, so a slow page falls behind, not the machine). The state is built by a task of its own
between cycles, once per tick for all streams, from one consistent copy of the image and the
operator's snapshot; a stream keeps only the newest state (states are not queued). Encoding to JSON
happens in the streams' own tasks, once per event however many streams send it. Without an open stream
nothing runs: no listener, no task.

Bounds: at most :attr:`LiveFeed.max_streams` streams at once (16 by default). A page that does not read
what it is sent holds nothing for long (reliability.md, round 2, finding 4): when every slot is taken, a
newcomer takes the slot of the stream that has waited longest (at least :data:`STALL_EVICT_S`) for its page to
take a message; and the door drops a connection whose client leaves an answer unread for ``write_timeout_s``
seconds (``protocol.py``). Only when every open page reads is a newcomer refused (503). At shutdown
:meth:`LiveFeed.close` ends every stream, so none holds the server's graceful shutdown.

With ``--api-token`` a stream carries the ``event`` messages (the event log, live) only to a holder of
the token (``?access_token=`` on the URL: an ``EventSource`` sends no headers); its ``hello`` says whether
it does (``events``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from hli_server.adapters.host import AdapterHost
from hli_server.adapters.http.deps import json_bytes
from schemas.events import Event
from schemas.image_format import read_field
from schemas.layout import Direction, Signal
from schemas.results import Scene
from schemas.wire import DynPosLimitState

__all__ = [
    "DEFAULT_MAX_STREAMS",
    "DEFAULT_RATE_HZ",
    "SCENE_PERIOD_S",
    "LiveFeed",
    "Stream",
    "TooManyStreamsError",
]

logger = logging.getLogger(__name__)

DEFAULT_MAX_STREAMS = 16
DEFAULT_RATE_HZ = 20.0
SCENE_PERIOD_S = 1.0
"""How often a channel's scene is looked at without an event of its channel (its trail grows, its path
ahead moves on). A scene of a moving channel costs a few milliseconds (``docs/performance.md``); between
two scenes the page moves the TCP and draws its newest trail from the states."""
STALL_EVICT_S = 1.0
"""A stream whose page has not taken a message for this long may give its slot to a newcomer."""
QUEUE_SIZE = 1000
"""Events one stream may have waiting; beyond, new events are dropped for it and counted."""

_MM = 1e-4
"""0.1 µm -> mm."""


class TooManyStreamsError(RuntimeError):
    """All stream slots are taken."""


_SCENE_KINDS = frozenset({"program_state", "areas", "alarm", "alarms_cleared", "area_violation"})
"""The events after which a channel's scene is looked at again at the next tick (the engine's scene changes
with them: ``runtime/dashboard.py``); a flood of other events (``#MSG``) asks for no scene."""


class _Shared:
    """An event queued for every stream, encoded once (by the first stream that sends it), however many
    streams there are."""

    __slots__ = ("_sse", "event")

    def __init__(self, event: Event) -> None:
        self.event = event
        self._sse: bytes | None = None

    def sse(self) -> bytes:
        if self._sse is None:
            self._sse = _sse(b"event", json_bytes(self.event.to_json()))
        return self._sse


@dataclass(eq=False)
class Stream:
    """One open page: its waiting events, its newest state and scenes, and what it lost."""

    events: deque[_Shared] = field(default_factory=deque)
    state: bytes | None = None
    scenes: dict[int, bytes] = field(default_factory=dict)
    dropped: int = 0
    dropped_told: int = 0
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    closed: bool = False
    events_allowed: bool = True
    """Whether this page gets the ``event`` messages (with a token set: only a holder of it)."""
    sending_since: float | None = None
    """When the message being sent was handed to the door (None: the page took it)."""

    async def next_chunk(self) -> bytes | None:
        """Everything waiting, as SSE text (events first, then scenes, then the state); ``None`` once the
        stream is closed."""
        while True:
            if self.closed:
                return None
            chunk = self._take()
            if chunk:
                return chunk
            self.wake.clear()
            await self.wake.wait()

    def _take(self) -> bytes:
        parts: list[bytes] = []
        while self.events:
            parts.append(self.events.popleft().sse())
        if self.dropped != self.dropped_told:
            self.dropped_told = self.dropped
            parts.append(_sse(b"dropped", json_bytes({"dropped": self.dropped})))
        for scene in self.scenes.values():
            parts.append(scene)
        self.scenes.clear()
        if self.state is not None:
            parts.append(self.state)
            self.state = None
        return b"".join(parts)


def _dpl_name(state: int) -> str:
    """HLI_DYNPL_STATE_* by number (FCT-C43 3.1.1), the number itself if it is none of them."""
    try:
        return DynPosLimitState(state).name
    except ValueError:
        return str(state)


def _sse(name: bytes, data: bytes) -> bytes:
    return b"event: " + name + b"\ndata: " + data + b"\n\n"


def _scene_bytes(scene: Scene) -> bytes:
    """A scene as an SSE message (its numbers are finite and rounded, ``hli_server.scene``)."""
    return _sse(b"scene", json_bytes(scene))


class _AxisSignals:
    """The image fields the state shows for one axis (layout ST paths, read from one copy per tick)."""

    def __init__(self, host: AdapterHost, index: int, name: str) -> None:
        layout = host.image.layout

        def sig(path: str) -> Signal:
            return layout.signal(f"gpAx[{index}]^{path}")

        self.name = name
        self.c2p = {
            "velocity": sig("ipo_state.velocity_r"),
            "in_position": sig("ipo_state.in_position_r"),
            "moving": sig("ipo_state.moving_r"),
            "error": sig("ipo_state.error_r"),
            "coll_active": sig("dyn_coll_mon.active"),
            "coll_brake_dist": sig("dyn_coll_mon.brake_dist"),
        }
        self.dpl = {
            side: (
                sig(f"ipo_mc_control.dyn_pos_limit_{side}.state_r"),
                sig(f"ipo_mc_control.dyn_pos_limit_{side}.enable_w"),
                sig(f"ipo_mc_control.dyn_pos_limit_{side}.command_w"),
            )
            for side in ("low", "high")
        }


class LiveFeed:
    """The streams of one application (see the module docstring)."""

    def __init__(
        self,
        host: AdapterHost,
        *,
        max_streams: int = DEFAULT_MAX_STREAMS,
        rate_hz: float = DEFAULT_RATE_HZ,
        queue_size: int = QUEUE_SIZE,
    ) -> None:
        self.host = host
        self.max_streams = max_streams
        self.period = 1.0 / rate_hz
        self.queue_size = queue_size
        self.streams: list[Stream] = []
        self.dropped = 0
        """Events dropped over all streams (slow pages)."""
        self.evicted = 0
        """Streams that gave their slot to a newcomer because their page did not read."""
        self.ticks = 0
        self._unsubscribe: Any = None
        self._task: asyncio.Task[None] | None = None
        self._closed = False
        self._dirty: set[int] = set()
        self._scenes: dict[int, Scene] = {}
        self._scene_failed: set[int] = set()
        self._scene_checked = 0.0
        self._axes: list[_AxisSignals] | None = None
        self._channel_signals: list[tuple[int, Signal, Signal, tuple[Signal, ...]]] | None = None

    # --- streams ------------------------------------------------------------------------------
    def open(self, *, events: bool = True) -> Stream:
        """A new stream (its first chunk is ``hello``; ``events``: whether it gets the events); when all
        slots are taken, the stream stalled longest gives its slot up (:data:`STALL_EVICT_S`), else
        :class:`TooManyStreamsError`; :class:`RuntimeError` after :meth:`close`."""
        if self._closed:
            raise RuntimeError("the server is stopping")
        if len(self.streams) >= self.max_streams and not self._evict_stalled():
            raise TooManyStreamsError(
                f"{self.max_streams} live streams are open and read (the most this server serves); close a "
                "dashboard tab, or start the server with --adapter http:max_streams=N"
            )
        stream = Stream(events_allowed=events)
        stream.scenes = {n: _scene_bytes(s) for n, s in self._current_scenes().items()}
        stream.state = _sse(b"state", json_bytes(self.state()))
        self.streams.append(stream)
        if self._unsubscribe is None:
            self._unsubscribe = self.host.events.subscribe(self._on_event)
        if self._task is None or self._task.done():
            self._task = asyncio.create_task(self._run(), name="hli-http-live")
        return stream

    def _evict_stalled(self) -> bool:
        """Release the stream whose page has not taken a message the longest, if that is at least
        :data:`STALL_EVICT_S`; its connection is dropped by the door's ``write_timeout_s``."""
        now = asyncio.get_running_loop().time()
        stalled = [
            s for s in self.streams if s.sending_since is not None and now - s.sending_since >= STALL_EVICT_S
        ]
        if not stalled:
            return False
        victim = min(stalled, key=lambda s: s.sending_since or now)
        self.evicted += 1
        logger.info(
            "live feed: a page has not read for %.1f s: its slot goes to a newcomer",
            now - (victim.sending_since or now),
        )
        self.release(victim)
        return True

    def hello(self, *, events: bool = True) -> bytes:
        return b"retry: 2000\n\n" + _sse(b"hello", json_bytes(self.hello_body(events=events)))

    def hello_body(self, *, events: bool = True) -> dict[str, Any]:
        """The ``hello`` message (also what the page carries when it is served); ``events``: whether the
        stream carries the events (with a token set: only to a holder of it)."""
        op = self.host.operator
        policy = self.host.policy
        channels = [
            {"number": n, "axes": op.axis_names(n), "programs": op.programs(n)} for n in op.channel_numbers()
        ]
        return {
            "machine": op.machine_name,
            "clock": self.host.clock,
            "t_a_us": op.t_a_us,
            "channels": channels,
            "axes": op.axis_names(),
            "token": policy.api_token is not None,
            "read_only": policy.read_only,
            "events": events,
            "rate_hz": round(1.0 / self.period, 3),
        }

    def release(self, stream: Stream) -> None:
        """The stream's page went away (or the stream ended)."""
        stream.closed = True
        stream.wake.set()
        with contextlib.suppress(ValueError):
            self.streams.remove(stream)
        if not self.streams:
            self._stop_listening()

    async def close(self) -> None:
        """Shutdown: end every stream (their responses complete) and the task."""
        self._closed = True
        for stream in list(self.streams):
            self.release(stream)
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    def _stop_listening(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        if self._task is not None and not self._task.done():
            self._task.cancel()
        self._task = None

    # --- inside the cycle: append and return ---------------------------------------------------
    def _on_event(self, event: Event) -> None:
        if event.channel is not None and event.KIND in _SCENE_KINDS:
            self._dirty.add(event.channel)
        shared = _Shared(event)
        for stream in self.streams:
            if not stream.events_allowed:
                continue
            if len(stream.events) >= self.queue_size:
                stream.dropped += 1
                self.dropped += 1
                continue
            stream.events.append(shared)
            stream.wake.set()

    # --- between cycles: the ticks --------------------------------------------------------------
    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        next_tick = loop.time()
        while self.streams:
            next_tick += self.period
            delay = next_tick - loop.time()
            if delay < 0:  # fell behind (a long step, a busy loop): skip, do not burst
                next_tick = loop.time()
                delay = 0.0
            await asyncio.sleep(delay)
            try:
                self._tick(loop.time())
            except Exception:  # a bug here must not end the streams' updates for good
                logger.exception("live feed tick failed")

    def _tick(self, now: float) -> None:
        self.ticks += 1
        scenes: dict[int, bytes] = {}
        if self._dirty or now - self._scene_checked >= SCENE_PERIOD_S:
            look_at = set(self._dirty) if now - self._scene_checked < SCENE_PERIOD_S else None
            self._dirty.clear()
            if look_at is None:
                self._scene_checked = now
            for number, scene in self._changed_scenes(look_at).items():
                scenes[number] = _scene_bytes(scene)
        state = _sse(b"state", json_bytes(self.state()))
        for stream in self.streams:
            stream.scenes.update(scenes)
            stream.state = state
            stream.wake.set()

    def _scene(self, number: int) -> Scene | None:
        """The channel's scene, or None (logged once per channel) if computing it fails: a page without
        one channel's picture is better than no page."""
        try:
            return self.host.operator.scene(number)
        except Exception:
            if number not in self._scene_failed:
                self._scene_failed.add(number)
                logger.exception(
                    "the scene of channel %d cannot be computed; the dashboard goes without it", number
                )
            return None

    def _current_scenes(self) -> dict[int, Scene]:
        for number in self.host.operator.channel_numbers():
            scene = self._scene(number)
            if scene is not None:
                self._scenes[number] = scene
        return dict(self._scenes)

    def _changed_scenes(self, channels: set[int] | None) -> dict[int, Scene]:
        """The scenes that changed since last sent (the operator returns the same object while its
        inputs are unchanged), of ``channels`` or all."""
        op = self.host.operator
        changed = {}
        for number in op.channel_numbers():
            if channels is not None and number not in channels:
                continue
            scene = self._scene(number)
            if scene is not None and scene is not self._scenes.get(number):
                self._scenes[number] = scene
                changed[number] = scene
        return changed

    def state(self) -> dict[str, Any]:
        """The state message (see the module docstring); lengths in mm."""
        host = self.host
        op = host.operator
        snap = op.snapshot()
        image = host.image
        c2p = memoryview(image.snapshot()[1])
        p2c = memoryview(image.read_half(Direction.PLC_TO_CNC))
        if self._axes is None:
            self._axes = [_AxisSignals(host, a.index, a.name) for a in image.layout.axes]
            self._channel_signals = [
                (
                    c.number,
                    image.layout.signal(f"gpCh[{c.index}]^bahn_mc_control.override.state_r"),
                    image.layout.signal(f"gpCh[{c.index}]^bahn_mc_control.feedhold.state_r"),
                    tuple(
                        image.layout.signal(f"gpCh[{c.index}]^bahn_state.{name}")
                        for name in ("kin_id_r", "trafo_active_r", "tcp_x_r", "tcp_y_r", "tcp_z_r")
                    ),
                )
                for c in image.layout.channels
            ]
        units = {
            number: (
                read_field(c2p, 0, override),
                read_field(c2p, 0, feedhold),
                [read_field(c2p, 0, k) for k in kin],
            )
            for number, override, feedhold, kin in self._channel_signals or ()
        }
        channels = []
        for ch in snap["channels"]:
            override, feedhold, kin = units.get(ch["number"], (None, None, None))
            channels.append(
                {
                    **ch,
                    "override_percent": None if override is None else int(override) / 10,
                    "feedhold": feedhold,
                    # K-07: the kinematic transformation and the tool tip (TCP), as the image has them
                    "kinematic": None
                    if kin is None
                    else {
                        "id": int(kin[0]),
                        "active": bool(kin[1]),
                        "tool_tip_mm": [int(v) * _MM for v in kin[2:]],
                    },
                }
            )
        axes = []
        for sigs in self._axes:
            base: Mapping[str, Any] = snap["axes"].get(sigs.name, {})
            values = {k: read_field(c2p, 0, s) for k, s in sigs.c2p.items()}
            dpl = {}
            for side, (state_sig, enable_sig, command_sig) in sigs.dpl.items():
                state = int(read_field(c2p, 0, state_sig))
                dpl[side] = {
                    "state": state,
                    "state_name": _dpl_name(state),
                    "enabled": bool(read_field(p2c, 0, enable_sig)),
                    "limit_mm": int(read_field(p2c, 0, command_sig)) * _MM,
                }
            axes.append(
                {
                    "name": sigs.name,
                    "command_mm": base.get("setpoint_mm"),
                    "actual_mm": base.get("actual_mm"),
                    "following_error_mm": base.get("following_error_mm"),
                    "referenced": base.get("referenced"),
                    "referencing": base.get("referencing"),
                    "velocity_mm_s": float(values["velocity"]) * _MM,
                    "in_position": bool(values["in_position"]),
                    "moving": bool(values["moving"]),
                    "error": bool(values["error"]),
                    "dyn_pos_limit": dpl,
                    "collision": {
                        "active": bool(values["coll_active"]),
                        "brake_dist_mm": float(values["coll_brake_dist"]) * _MM,
                    },
                }
            )
        return {
            "cycle": snap["cycle"],
            "time_s": snap["time_s"],
            "channels": channels,
            "axes": axes,
            "pairs": op.collision_pairs(),
            "alarms": snap["alarms"],
            "external": snap.get("external", []),
            "streams": len(self.streams),
            "dropped": self.dropped,
        }
