"""Axes: setpoint (from the interpolator or jog), the position-control loop and its faults (E-02).

The drive model (project's own, configurable per axis in ``DriveModel``):

    v_ff   = (setpoint_n - setpoint_n-1) / T_A                 velocity feed-forward
    v_cmd  = feed_forward * v_ff + kv_eff * (setpoint_n - measured)
    v     += (v_cmd - v) * T_A / (tau + T_A)                    first-order drive
    v      = 0 if |v_cmd| <= friction (stiction)
    actual += v * T_A
    measured = actual + drift (or frozen, for a stuck encoder)

so that following error in steady motion is about (1 - feed_forward) * v / kv and the axis settles
into the exact-stop window after the setpoint stops. Faults are injected at run time (A3-05).

Referencing (homing, E-02, C3-06; project's own model): :meth:`Axis.start_referencing` moves the
setpoint to the reference position (``reference_position``, default the start position) with the jog
velocity and acceleration, like a search for the reference mark; when it arrives there the axis is
referenced. The per-cycle code reads plain values copied once from the configuration (the pydantic
model is not touched per cycle).

The drive saturates: ``v_cmd`` is limited to :data:`DRIVE_SATURATION` times the axis' v_max, as a
real drive's speed limit does. A loop made unstable by its gain (kv * T_A > 2 without a time
constant, or a large ``gain_factor``) then oscillates with a bounded amplitude, the position
monitor reports it, and no value grows without bound (before, such a loop reached inf within a
few hundred cycles and ended the server, reliability.md, round 1, finding 2). Injected fault values are
checked by :func:`check_fault_value` before they reach the loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from schemas.config import AxisConfig, AxisType
from schemas.units import mm_from_increments, mm_per_min_to_mm_per_s, s_from_us

__all__ = ["DRIVE_SATURATION", "GAIN_FACTOR_MAX", "Axis", "AxisFaults", "DriveParams", "check_fault_value"]

DRIVE_SATURATION: Final = 2.0
"""The drive's speed limit as a multiple of the axis' v_max (project's own: motors are sized with
margin above the axis' rated speed; the PLC sees the velocity as a DINT in 0.1 µm/s, which the
configuration's bound on v_max keeps representable at twice v_max)."""

GAIN_FACTOR_MAX: Final = 100.0
"""Largest ``gain_factor``: a hundredfold kv is far beyond any mistuning worth simulating."""


@dataclass(frozen=True, slots=True)
class DriveParams:
    """The drive model's parameters (``DriveModel`` of the configuration) in engine units."""

    kv: float
    """1/s"""
    feed_forward: float
    tau: float
    """s"""

    @classmethod
    def from_config(cls, config: AxisConfig) -> DriveParams:
        d = config.drive
        return cls(kv=d.kv, feed_forward=d.feed_forward, tau=s_from_us(d.time_constant_us))


@dataclass(slots=True)
class AxisFaults:
    """Injected faults (A3-05): they make the position loop misbehave so a monitor can fire."""

    friction: float = 0.0
    """Stiction as a velocity dead band [mm/s]: commands below it do not move the axis."""
    gain_factor: float = 1.0
    """Multiplies kv (a worn or mistuned loop settles slower)."""
    encoder_drift: float = 0.0
    """Drift of the measuring system [mm/s]."""
    encoder_stuck: bool = False
    """The measuring system stops counting."""
    drive_error: bool = False
    """The drive reports an error: it stops at once (emergency deceleration)."""

    def as_dict(self) -> dict[str, float | bool]:
        return {
            "friction": self.friction,
            "gain_factor": self.gain_factor,
            "encoder_stuck": self.encoder_stuck,
            "encoder_drift": self.encoder_drift,
            "drive_error": self.drive_error,
        }

    def any(self) -> bool:
        return (
            self.friction > 0.0
            or self.gain_factor != 1.0
            or self.encoder_drift != 0.0
            or self.encoder_stuck
            or self.drive_error
        )


def check_fault_value(axis: Axis, name: str, value: object) -> float | bool:
    """A fault value the drive model can take (A3-05), else ValueError naming the field, the value
    and the allowed range. ``Machine.inject_fault`` checks every field before it changes any.

    The ranges, and why (reliability.md, round 1, finding 2: ``encoder_drift=1e308`` reached inf in the next
    cycle):

    * ``friction`` 0 .. v_max [mm/s]: a dead band as wide as the axis' top speed already swallows
      every command the path gives; a wider one says nothing more.
    * ``gain_factor`` > 0 .. :data:`GAIN_FACTOR_MAX`: 0 would open the loop (that is
      ``encoder_stuck`` or ``drive_error``); the drive's saturation bounds an unstable loop.
    * ``encoder_drift`` -v_max .. v_max [mm/s]: the loop compensates a drift by moving the axis at
      the drift's speed, which the drive can do up to v_max; a measuring system that runs away
      faster than the axis can travel is broken, not drifting (``encoder_stuck``).
    * ``encoder_stuck``, ``drive_error``: true or false.
    """
    default = getattr(AxisFaults(), name)
    where = f"fault {name} of axis {axis.name}"
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"{where}: true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{where}: a finite number, got {value!r}")
    v_max = axis.v_max
    unit = "°/s" if axis.rotary else "mm/s"
    if name == "friction":
        ok, allowed = 0.0 <= value <= v_max, f"0 .. {v_max:g} {unit} (the axis' v_max)"
    elif name == "gain_factor":
        ok, allowed = 0.0 < value <= GAIN_FACTOR_MAX, f"greater than 0, at most {GAIN_FACTOR_MAX:g}"
    else:  # encoder_drift
        ok = -v_max <= value <= v_max
        allowed = f"-{v_max:g} .. {v_max:g} {unit} (the axis' v_max; a faster one is encoder_stuck)"
    if not ok:
        raise ValueError(f"{where}: {value!r} is out of range; allowed {allowed}")
    return float(value)


class Axis:
    """One axis. ``index`` is its place in the configuration (gpAx[index]); ``number`` is A_ID."""

    __slots__ = (
        "_drift",
        "_home_velocity",
        "a_emergency",
        "a_max",
        "actual",
        "channel",
        "config",
        "drive",
        "drive_velocity",
        "faults",
        "home_position",
        "index",
        "jog_acceleration",
        "jog_velocity",
        "measured",
        "name",
        "number",
        "prev_setpoint",
        "referenced",
        "referencing",
        "rotary",
        "setpoint",
        "slope_ramp",
        "stop_deceleration",
        "stop_elapsed",
        "stop_velocity",
        "stopping",
        "swe_neg",
        "swe_pos",
        "swe_tol",
        "v_max",
        "v_rapid",
        "window",
        "window_inc",
    )

    def __init__(self, config: AxisConfig, index: int) -> None:
        self.config = config
        self.index = index
        self.number = config.number
        self.name = config.name
        self.channel = 0
        self.rotary = config.axis_type == AxisType.ROTARY
        self.a_max = config.a_max
        self.a_emergency = config.emergency_deceleration
        """P-AXIS-00003 in effect [mm/s²]: a_emergency, or a_max where it is 0"""
        self.v_max = mm_per_min_to_mm_per_s(config.v_max)
        self.v_rapid = min(mm_per_min_to_mm_per_s(config.v_rapid), self.v_max)
        self.jog_velocity = min(mm_per_min_to_mm_per_s(config.jog_velocity), self.v_max)
        self.jog_acceleration = min(config.jog_acceleration, config.a_max)
        self.swe_neg = mm_from_increments(config.swe_neg)
        self.swe_pos = mm_from_increments(config.swe_pos)
        self.swe_tol = mm_from_increments(config.swe_toleranz)
        start = mm_from_increments(config.start_position)
        self.setpoint = start
        self.prev_setpoint = start
        self.actual = start
        self.measured = start
        self._drift = 0.0
        self.drive_velocity = 0.0
        self.referenced = config.referenced
        self.referencing = False
        home = config.reference_position if config.reference_position is not None else config.start_position
        self.home_position = mm_from_increments(home)
        self._home_velocity = 0.0
        self.window = mm_from_increments(config.window)
        """P-AXIS-00236 exact-stop window [mm]"""
        self.window_inc = config.window
        self.drive = DriveParams.from_config(config)
        self.faults = AxisFaults()
        self.stopping = False
        self.stop_velocity = 0.0
        self.stop_deceleration = 0.0
        self.stop_elapsed = 0.0
        """Time since the independent stop began [s] (the deceleration's ramp, ``slope_ramp``)."""
        self.slope_ramp = 0.0
        """Ramp time of the channel's active acceleration profile [s] (0: STEP, M-05): an independent
        stop builds its deceleration up linearly over it (FCT-C3's braking distance counts it)."""

    # --- software limits in effect (P-AXIS-00177/00178) ------------------------------------
    def set_soft_limits(self, negative: float | None = None, positive: float | None = None) -> None:
        """Software limits [mm] in effect until the next reset, mode change or axis exchange (what the
        kernel's G98/G99 set): they are not the axis record's, which :meth:`reload_soft_limits` takes
        back. ValueError when the two would not leave a range (negative < positive)."""
        neg = self.swe_neg if negative is None else negative
        pos = self.swe_pos if positive is None else positive
        if not (math.isfinite(neg) and math.isfinite(pos)) or not neg < pos:
            raise ValueError(
                f"axis {self.name}: software limits {neg:g} .. {pos:g} mm: the negative must be less "
                "than the positive"
            )
        self.swe_neg, self.swe_pos = neg, pos

    def reload_soft_limits(self) -> None:
        """P-AXIS-00177/00178 "Anmerkungen": "Der Wert des Parameters wird bei Reset,
        Betriebsartenwechsel und Achstausch aus dem Achsdatensatz übernommen": the limits in effect
        (and the tolerance P-AXIS-00179) become the axis record's again. Called at reset and mode
        change; axis exchange is not simulated (this is its hook)."""
        self.swe_neg = mm_from_increments(self.config.swe_neg)
        self.swe_pos = mm_from_increments(self.config.swe_pos)
        self.swe_tol = mm_from_increments(self.config.swe_toleranz)

    # --- setpoint side --------------------------------------------------------------------
    @property
    def setpoint_step(self) -> float:
        """Setpoint travel of the last cycle [mm]; divided by T_A it is v_t of C3-08."""
        return self.setpoint - self.prev_setpoint

    def begin_cycle(self) -> None:
        self.prev_setpoint = self.setpoint

    def start_independent_stop(self, deceleration: float, t_a: float) -> None:
        """Stop this axis on its own ramp, detached from the path (C3-01, A3-04, drive errors)."""
        if self.stopping:
            self.stop_deceleration = max(self.stop_deceleration, deceleration)
            return
        self.stopping = True
        self.stop_velocity = (self.setpoint - self.prev_setpoint) / t_a
        self.stop_deceleration = deceleration
        self.stop_elapsed = 0.0

    def stop_distance(self, velocity: float, deceleration: float) -> float:
        """How far an independent stop from ``velocity`` with ``deceleration`` runs at most: v²/(2a),
        plus v * t_r / 2 while a jerk-limited profile builds the deceleration up over t_r (M-05)."""
        v = abs(velocity)
        return v * v / (2.0 * deceleration) + 0.5 * v * self.slope_ramp

    def advance_independent_stop(self, t_a: float) -> None:
        v = self.stop_velocity
        self.stop_elapsed += t_a
        ramp = self.slope_ramp
        dv = self.stop_deceleration * t_a * (min(1.0, self.stop_elapsed / ramp) if ramp > 0.0 else 1.0)
        v = max(0.0, v - dv) if v > 0 else min(0.0, v + dv)
        self.stop_velocity = v
        self.setpoint += v * t_a

    def release_stop(self) -> None:
        self.stopping = False
        self.stop_velocity = 0.0

    # --- referencing (homing) ---------------------------------------------------------------
    def start_referencing(self) -> None:
        """Begin the homing move; the axis is unreferenced until it ends (E-02)."""
        self.referencing = True
        self.referenced = False
        self._home_velocity = 0.0

    def cancel_referencing(self) -> None:
        self.referencing = False
        self._home_velocity = 0.0

    def advance_referencing(self, t_a: float) -> bool:
        """One cycle of the homing move (a jog to the reference position that stops there exactly);
        True in the cycle the axis arrives and is referenced."""
        remaining = self.home_position - self.setpoint
        v = abs(self._home_velocity)
        a = self.jog_acceleration
        distance = abs(remaining)
        # discrete braking curve: highest velocity from which v falls by a*T per cycle to 0 within distance
        half = 0.5 * a * t_a
        v_brake = -half + math.sqrt(half * half + 2.0 * a * distance)
        v = min(v + a * t_a, self.jog_velocity, v_brake)
        step = v * t_a
        if step >= distance - 1e-12:
            self.setpoint = self.home_position
            self.referencing = False
            self.referenced = True
            self._home_velocity = 0.0
            return True
        self._home_velocity = math.copysign(v, remaining)
        self.setpoint += math.copysign(step, remaining)
        return False

    # --- actual side: the position loop ---------------------------------------------------
    def update_drive(self, t_a: float) -> None:
        cfg = self.drive
        f = self.faults
        if f.drive_error:
            # the drive is off: it coasts to a stop with the emergency deceleration
            dv = self.a_emergency * t_a
            v = self.drive_velocity
            self.drive_velocity = max(0.0, v - dv) if v > 0 else min(0.0, v + dv)
        else:
            v_ff = (self.setpoint - self.prev_setpoint) / t_a
            kv = cfg.kv * f.gain_factor
            v_cmd = cfg.feed_forward * v_ff + kv * (self.setpoint - self.measured)
            limit = DRIVE_SATURATION * self.v_max  # the drive's speed limit (see the module docstring)
            if not -limit <= v_cmd <= limit:
                v_cmd = limit if v_cmd > 0.0 else -limit
            if f.friction > 0.0 and abs(v_cmd) <= f.friction:
                v_cmd = 0.0
                self.drive_velocity = 0.0
            self.drive_velocity += (v_cmd - self.drive_velocity) * t_a / (cfg.tau + t_a)
        self.actual += self.drive_velocity * t_a
        self._drift += f.encoder_drift * t_a
        if not f.encoder_stuck:
            self.measured = self.actual + self._drift

    @property
    def following_error(self) -> float:
        return self.setpoint - self.measured

    def reset_faults(self) -> None:
        self.faults = AxisFaults()
