"""The operator port the runtime hands its adapters (``hli_server.adapters.host``).

:class:`OperatorPanel` is the operator panel's door onto the machine: every request goes through
the channel's own methods (latched at the next cycle, refused with the channel's own alarm), faults
through ``Machine.inject_fault`` (so that the ``fault`` event is emitted), so no adapter repeats an
engine rule.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import cast

from hli_server.adapters.host import (
    Accepted,
    ConflictError,
    InvalidRequestError,
    NotFoundError,
    OperatorPort,
)
from hli_server.engine.areas.monitor import AreaMonitor
from hli_server.engine.axis import Axis
from hli_server.engine.channel import Channel
from hli_server.engine.machine import Machine
from hli_server.runtime.dashboard import TrailRecorder, collision_pairs, live_scene, program_table, scene_key
from hli_server.runtime.programs import RuntimeLibrary
from schemas.results import (
    AlarmList,
    AreaTable,
    AxisFaults,
    CollisionPair,
    ExternalVariable,
    MachineState,
    ProbeDeviation,
    ProgramEntry,
    ProgramLoaded,
    ProgramSelected,
    Scene,
    SoftLimits,
    Timing,
)
from schemas.units import increments_from_mm, mm_from_increments
from schemas.wire import Mode

__all__ = ["OperatorPanel"]


class OperatorPanel(OperatorPort):
    """:class:`~hli_server.adapters.host.OperatorPort` on a :class:`Machine`."""

    def __init__(
        self, machine: Machine, timing: Callable[[], Timing], *, library: RuntimeLibrary | None = None
    ) -> None:
        self._m = machine
        self._library = library
        """The runtime's program library, which takes the files uploaded with a program (N-02)."""
        self._timing = timing
        self.recorder = TrailRecorder(machine)
        """The trails and scene revisions; fed by the runtime host (a cycle listener, an event listener)."""
        self._scenes: dict[int, tuple[tuple[object, ...], Scene]] = {}

    def rebind(self, machine: Machine) -> None:
        """The panel of ``machine`` from now on (the runtime restarted its machine: the same doors)."""
        self._m = machine
        self.recorder.rebind(machine)
        self._scenes.clear()

    # --- what and where -------------------------------------------------------------------
    @property
    def cycle(self) -> int:
        return self._m.cycle

    @property
    def time_s(self) -> float:
        return self._m.time

    @property
    def t_a_us(self) -> int:
        return self._m.config.cycle_time_us

    @property
    def machine_name(self) -> str:
        return self._m.config.name

    def channel_numbers(self) -> list[int]:
        return [ch.number for ch in self._m.channels]

    def axis_names(self, channel: int | None = None) -> list[str]:
        if channel is None:
            return [a.name for a in self._m.axes]
        return list(self._channel(channel).axis_names)

    def _channel(self, number: int) -> Channel:
        try:
            return self._m.channel(number)
        except KeyError:
            have = ", ".join(str(n) for n in self.channel_numbers())
            raise NotFoundError(f"no channel {number}; the machine has channels {have}") from None

    def _axis(self, name: str) -> Axis:
        axis = self._m.axes_by_name.get(name)
        if axis is None:
            raise NotFoundError(f"no axis {name!r}; the machine has axes {', '.join(self._m.axes_by_name)}")
        return axis

    def _accepted(self, ch: Channel, what: str) -> Accepted:
        cycle = self._m.cycle
        return Accepted(channel=ch.number, request=what, cycle=cycle, effective_cycle=cycle + 1)

    # --- programs -------------------------------------------------------------------------
    def load_program(
        self, channel: int, text: str, name: str = "program", files: Mapping[str, str] | None = None
    ) -> ProgramLoaded:
        ch = self._channel(channel)
        library = self._library
        uploads: dict[str, str] = {}
        if library is not None:
            try:
                uploads = library.check_uploads(files or {})
            except ValueError as exc:
                raise InvalidRequestError(f"channel {channel}: {exc}") from None
        elif files:
            raise InvalidRequestError("this machine takes no subprograms with a program (no program library)")
        refused = ch.load_program(text, name)
        if refused is not None:
            raise ConflictError(f"channel {channel}: {refused.message}; reset the channel first")
        if library is not None:
            library.set_uploads(channel, uploads)
        lines = text.count("\n") + (0 if text.endswith("\n") else 1)
        return {
            "channel": channel,
            "program": name,
            "lines": lines,
            "files": sorted(uploads),
            "cycle": self._m.cycle,
        }

    def select_program(self, channel: int, number: int) -> ProgramSelected:
        ch = self._channel(channel)
        entry = next((p for p in ch.config.programs if p.number == number), None)
        if entry is None:
            have = ", ".join(str(p.number) for p in ch.config.programs) or "none"
            raise NotFoundError(
                f"channel {channel}: program {number} is not in the program table (have: {have})"
            )
        refused = ch.select_program(number)
        if refused is not None:
            raise ConflictError(f"channel {channel}: {refused.message}")
        return {"channel": channel, "program": entry.name, "number": number, "cycle": self._m.cycle}

    # --- channel requests (latched at the next cycle) --------------------------------------
    def start(self, channel: int) -> Accepted:
        ch = self._channel(channel)
        ch.request_start()
        return self._accepted(ch, "start")

    def reset(self, channel: int) -> Accepted:
        ch = self._channel(channel)
        ch.request_reset()
        return self._accepted(ch, "reset")

    def feedhold(self, channel: int, on: bool) -> Accepted:
        ch = self._channel(channel)
        ch.request_feedhold(on)
        return self._accepted(ch, f"feedhold {'on' if on else 'off'}")

    def mode(self, channel: int, mode: Mode) -> Accepted:
        ch = self._channel(channel)
        ch.request_mode(Mode(mode))
        return self._accepted(ch, f"mode {Mode(mode).label}")

    def override(self, channel: int, permille: int) -> Accepted:
        if not 0 <= permille <= 1200:
            raise InvalidRequestError(f"override {permille / 10:g} % is outside 0..120 %")
        ch = self._channel(channel)
        ch.request_override(permille)
        return self._accepted(ch, f"override {permille / 10:g} %")

    def jog(self, channel: int, axis: str, direction: int) -> Accepted:
        ch = self._channel(channel)
        if axis not in ch.axis_names:
            raise NotFoundError(
                f"channel {channel} has no axis {axis!r}; its axes are {', '.join(ch.axis_names)}"
            )
        if direction not in (-1, 0, 1):
            raise InvalidRequestError(f"jog direction {direction}: use +1, -1 or 0 (release)")
        ch.request_jog(axis, direction)
        key = {1: "+", -1: "-"}.get(direction, " released")
        return self._accepted(ch, f"jog {axis}{key}")

    def probe(self, channel: int, on: bool) -> Accepted:
        ch = self._channel(channel)
        if not self._m.has_monitor(AreaMonitor):
            raise ConflictError("the machine has no area monitoring (no G100 measuring moves)")
        self._m.monitor(AreaMonitor).handler(ch.number).request_probe(on)
        return self._accepted(ch, f"probe {'on' if on else 'off'}")

    def probe_deviation(self, channel: int) -> ProbeDeviation:
        ch = self._channel(channel)
        values = self._m.probe_deviation(ch.number)
        return {
            "channel": ch.number,
            "deviation": {name: increments_from_mm(v) for name, v in values.items()},
            "variables": dict(self._m.probes[ch.number].variables),
        }

    def set_probe_deviation(self, channel: int, values: dict[str, int]) -> ProbeDeviation:
        ch = self._channel(channel)
        if not values:
            raise InvalidRequestError('give the deviation per axis [0.1 µm], e.g. {"X": 2000}')
        try:
            self._m.set_probe_deviation(ch.number, {k: mm_from_increments(v) for k, v in values.items()})
        except KeyError as exc:
            raise NotFoundError(str(exc.args[0])) from None
        except ValueError as exc:
            raise InvalidRequestError(str(exc)) from None
        return self.probe_deviation(channel)

    def reference(self, axis: str) -> Accepted:
        ax = self._axis(axis)
        ch = self._m.channel_of(ax)
        ch.request_reference(ax.name)
        return self._accepted(ch, f"reference {ax.name}")

    # --- faults (A3-05) -------------------------------------------------------------------
    def faults(self, axis: str) -> AxisFaults:
        ax = self._axis(axis)
        return cast(AxisFaults, {"axis": ax.name, **ax.faults.as_dict()})

    def inject_faults(self, axis: str, **fields: float | bool) -> AxisFaults:
        ax = self._axis(axis)
        if not fields:
            raise InvalidRequestError("give at least one fault field (DELETE clears them all)")
        try:
            self._m.inject_fault(ax.name, **fields)
        except ValueError as exc:
            raise InvalidRequestError(str(exc)) from None
        return self.faults(axis)

    def clear_faults(self, axis: str) -> AxisFaults:
        ax = self._axis(axis)
        self._m.inject_fault(ax.name)
        return self.faults(axis)

    # --- software limits (E-06, P-AXIS-00177/00178/00179) ------------------------------------
    def soft_limits(self, axis: str) -> SoftLimits:
        ax = self._axis(axis)
        rec = ax.config
        return {
            "axis": ax.name,
            "in_effect": {
                "swe_neg": increments_from_mm(ax.swe_neg),
                "swe_pos": increments_from_mm(ax.swe_pos),
                "swe_toleranz": increments_from_mm(ax.swe_tol),
            },
            "record": {"swe_neg": rec.swe_neg, "swe_pos": rec.swe_pos, "swe_toleranz": rec.swe_toleranz},
        }

    def set_soft_limits(self, axis: str, **values: int) -> SoftLimits:
        ax = self._axis(axis)
        unknown = sorted(set(values) - {"swe_neg", "swe_pos"})
        if unknown or not values:
            raise InvalidRequestError("give swe_neg and/or swe_pos [0.1 µm] (the limits in effect)")
        try:
            ax.set_soft_limits(
                mm_from_increments(values["swe_neg"]) if "swe_neg" in values else None,
                mm_from_increments(values["swe_pos"]) if "swe_pos" in values else None,
            )
        except ValueError as exc:
            raise InvalidRequestError(str(exc)) from None
        return self.soft_limits(axis)

    def update_axis_record(self, axis: str, **values: int) -> SoftLimits:
        ax = self._axis(axis)
        if not values:
            raise InvalidRequestError("give swe_neg, swe_pos and/or swe_toleranz [0.1 µm]")
        try:
            self._m.update_axis_record(ax.name, **values)
        except ValueError as exc:
            raise InvalidRequestError(str(exc)) from None
        return self.soft_limits(axis)

    # --- state ----------------------------------------------------------------------------
    def snapshot(self) -> MachineState:
        snap = cast(MachineState, self._m.snapshot())
        snap["external"] = self.external_variables()
        return snap

    def external_variables(self) -> list[ExternalVariable]:
        """The V.E. variables and their values now (N-05): ``name`` (``V.E.MODE``; a structure's
        elements each, ``V.E.UserInteraction.Message``), ``channel`` (None: the global area), ``symbol``
        (the image's ST path, ``gpVECh[0]^MODE``; an array's elements add ``[i]``, and ``[]`` marks where
        an array of structures takes its index: ``gpVECh[1]^TRACK[].LABEL``), ``type`` (the kernel's:
        ``SGN32``, ``STRING``, ``VSTRING``), ``dims`` (of every level in a row), ``value`` (a list,
        row-major, for an array)."""
        m = self._m
        index_of = {ch.number: i for i, ch in enumerate(m.channels)}
        out: list[ExternalVariable] = []
        for spec in m.external:
            values = m.external.values(spec)
            head = "gpVEGlob^" if spec.channel is None else f"gpVECh[{index_of[spec.channel]}]^"
            out.append(
                {
                    "name": f"V.E.{spec.name}",
                    "channel": spec.channel,
                    "symbol": head + spec.path.removeprefix("V.E."),
                    "type": spec.declared,
                    "dims": list(spec.dims),
                    "value": list(values) if spec.dims else values[0],
                }
            )
        return out

    def alarms(self, history: int = 200) -> AlarmList:
        m = self._m
        newest = list(m.alarm_history)[-history:] if history > 0 else []
        return cast(
            AlarmList,
            {"active": [a.to_json() for a in m.active_alarms], "history": [a.to_json() for a in newest]},
        )

    def areas(self, channel: int) -> AreaTable:
        ch = self._channel(channel)
        if not self._m.has_monitor(AreaMonitor):
            return {"channel": ch.number, "axes": list(ch.axis_names), "areas": []}
        return cast(AreaTable, self._m.monitor(AreaMonitor).handler(ch.number).to_json())

    def timing(self) -> Timing:
        return self._timing()

    # --- the dashboard (docs/dashboard.md): hli_server/runtime/dashboard.py ------------------------------
    def scene(self, channel: int) -> Scene:
        ch = self._channel(channel)
        key = scene_key(self._m, self.recorder, ch.number)
        cached = self._scenes.get(ch.number)
        if cached is not None and cached[0] == key:
            return cached[1]
        scene = live_scene(self._m, self.recorder, ch.number)
        self._scenes[ch.number] = (key, scene)
        return scene

    def programs(self, channel: int) -> list[ProgramEntry]:
        return program_table(self._channel(channel))

    def collision_pairs(self) -> list[CollisionPair]:
        return collision_pairs(self._m)
