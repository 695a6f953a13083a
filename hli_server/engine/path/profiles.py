"""Acceleration profiles: ``#SLOPE [TYPE=STEP|TRAPEZ|SIN2|HSC]``, ``#SLOPE DEFAULT``, P-CHAN-00071
(M-01..M-05).

The kernel's profiles (programming manual "Selecting operating mode (#SLOPE, #SLOPE DEFAULT)",
https://infosys.beckhoff.com/content/1033/tf5200_programming_manual/207190411.html; P-CHAN-00071
``prog_start.slope.profile``: 0 STEP, 1 TRAPEZ, 2 SIN2, 3 HSC):

* STEP: the acceleration jumps (the linear velocity profile): the planner as before.
* TRAPEZ: the acceleration is built up and taken down linearly over the ramp time (a
  jerk-limited profile, jerk = a / t_r).
* SIN2: the acceleration is built up and taken down along sin² over the ramp time.
* HSC: the manual's "HSC slope" (trapezoidal, across blocks): simulated as TRAPEZ (documented in
  docs/nc-language.md).

How the simulator makes them (project's own model): the planner computes the path coordinate s(t)
with the step-shaped profile (velocity ramps, look-ahead, stop points exactly as before); the axes
follow the *filtered* path coordinate

    s_f[n] = sum_i w_i * s[n - i]          i = 0 .. N-1,  N = t_r / T_A,  sum w_i = 1,  w_i >= 0

with a boxcar kernel (w_i = 1/N) for TRAPEZ and a half-sine kernel (w_i ~ sin(pi (i + 1/2) / N))
for SIN2. Filtering a step in the acceleration with a boxcar gives a linear acceleration ramp of
length t_r (the trapezoid), with a half-sine kernel the ramp sin²(pi t / (2 t_r)): exactly the two
profiles' acceleration shapes. Because every w_i >= 0 and s(t) never decreases, the filtered path:

* never passes a point the step-profile path does not pass (a stop point, a dynamic limit, an area
  border on the path): ``s_f <= max(s)``;
* lies on the programmed geometry (the filter acts on the path coordinate, not on the axes), so the
  contour and the area path checks are those of the programmed path;
* never accelerates or brakes harder than the step profile (a convex combination of its
  accelerations), so the axes' a_max holds;
* stops where the step profile stops, lagging by the kernel's centre ``(N - 1) / 2 * T_A`` (half
  the ramp time): the braking distance from a steady velocity v with deceleration a is

      d = v² / (2 a) + v * (N - 1) / 2 * T_A            (:meth:`SlopeProfile.stop_distance`)

  which is the jerk-limited profile's distance v² / (2a) + v t_r / 2 of the manual's slopes.

Ramp time: the kernel has one ramp time per channel, the longest of the channel's axes' ramp times
P-AXIS-00195..00198 (``slope_profil.tr_beschl_ab/_zu``, ``tr_brems_ab/_zu``; the kernel's default
50000 µs each); the kernel distinguishes building up and taking down, acceleration and deceleration
(documented approximation).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import IntEnum

__all__ = ["PROFILE_NAMES", "PathFilter", "SlopeProfile", "SlopeType"]


class SlopeType(IntEnum):
    """P-CHAN-00071's values and ``#SLOPE [TYPE=..]``'s identifiers."""

    STEP = 0
    TRAPEZ = 1
    SIN2 = 2
    HSC = 3


PROFILE_NAMES: dict[str, SlopeType] = {t.name: t for t in SlopeType}
"""``#SLOPE [TYPE=<ident>]`` -> type."""


@dataclass(frozen=True, slots=True)
class SlopeProfile:
    """An acceleration profile with its ramp time [s]."""

    type: SlopeType = SlopeType.STEP
    ramp_time: float = 0.05

    def taps(self, t_a: float) -> int:
        """N, the kernel's length in cycles (1: no filter, the step profile)."""
        if self.type == SlopeType.STEP:
            return 1
        return max(1, round(self.ramp_time / t_a))

    def kernel(self, t_a: float) -> tuple[float, ...]:
        """The weights w_0 .. w_N-1 (w_0 for the newest sample), summing to 1."""
        n = self.taps(t_a)
        if n == 1:
            return (1.0,)
        if self.type == SlopeType.SIN2:
            raw = [math.sin(math.pi * (i + 0.5) / n) for i in range(n)]
        else:  # TRAPEZ, HSC
            raw = [1.0] * n
        total = sum(raw)
        return tuple(w / total for w in raw)

    def lag(self, t_a: float) -> float:
        """The filter's delay [s]: the kernel's centre (both kernels are symmetric)."""
        return 0.5 * (self.taps(t_a) - 1) * t_a

    def stop_distance(self, v: float, a: float, t_a: float) -> float:
        """Path travelled from a steady velocity ``v`` [mm/s] until rest, braking with ``a`` [mm/s²]
        in this profile (the step profile's discrete ramp plus the lag's travel)."""
        if v <= 0.0:
            return 0.0
        return v * v / (2.0 * a) + 0.5 * v * t_a + v * self.lag(t_a)

    @property
    def name(self) -> str:
        return self.type.name


class PathFilter:
    """The FIR filter on the path coordinate (see the module's description)."""

    __slots__ = ("_hist", "_sum", "boxcar", "kernel", "output")

    def __init__(self, kernel: tuple[float, ...], s: float = 0.0) -> None:
        self.kernel = kernel
        self.boxcar = all(w == kernel[0] for w in kernel)
        self._hist: deque[float] = deque([s] * len(kernel), maxlen=len(kernel))
        self._sum = s * len(kernel)
        self.output = s

    def reset(self, s: float) -> None:
        n = len(self.kernel)
        self._hist = deque([s] * n, maxlen=n)
        self._sum = s * n
        self.output = s

    def push(self, s: float) -> float:
        """Take this cycle's path coordinate; the filtered one."""
        hist = self._hist
        if self.boxcar:
            self._sum += s - hist[0]
            hist.append(s)
            out = self._sum / len(self.kernel)
            if self.settled:
                self._sum = s * len(self.kernel)  # no drift of the running sum at rest
                out = s
        else:
            hist.append(s)
            out = 0.0
            for w, x in zip(self.kernel, reversed(hist), strict=True):
                out += w * x
        # the output never runs ahead of the input, nor backwards (rounding)
        out = min(max(out, self.output), s) if s >= self.output else out
        self.output = out
        return out

    @property
    def settled(self) -> bool:
        """Every sample of the window is the same: the filtered path is at rest on the input."""
        hist = self._hist
        return hist[0] == hist[-1] and min(hist) == max(hist)

    @property
    def velocity_samples(self) -> int:
        return len(self.kernel)
