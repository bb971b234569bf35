"""Heading PID: angle wrapping, output clamp with anti-windup, injectable dt.

The error is ``wrap180(setpoint - heading)`` (degrees), so 359 deg -> 1 deg is a 2 deg turn, not
358. The derivative acts on the measurement (no kick on a setpoint change) through a first-order
low-pass of time constant ``d_tau_s``. Anti-windup: the integral only moves when the output is
not saturated in the direction the error pushes it, and only while the error is inside
``i_band_deg`` (a large turn does not wind it up), and it is itself bounded to the output range.
Output units are those of the gains (here % differential thrust per degree).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from fdi.lms_fir import wrap180


@dataclass(frozen=True)
class PidConfig:
    """Gains (% per deg, % per deg*s, % per deg/s) and limits (the ``[pid]`` table)."""

    kp: float = field(default=3.0, metadata={"ge": 0.0})
    ki: float = field(default=0.3, metadata={"ge": 0.0})
    kd: float = field(default=2.0, metadata={"ge": 0.0})
    d_tau_s: float = field(default=0.2, metadata={"ge": 0.0})
    i_band_deg: float = field(default=10.0, metadata={
        "ge": 0.0, "doc": "integrate only while |error| < this (0: always)"})
    out_min: float = -100.0
    out_max: float = 100.0

    def __post_init__(self) -> None:
        if self.out_min >= self.out_max:
            raise ValueError("out_min must be < out_max")


class HeadingPid:
    """``update(setpoint_deg, heading_deg, dt)`` -> clamped output."""

    def __init__(self, cfg: PidConfig) -> None:
        self.cfg = cfg
        self.integral = 0.0  # in output units (ki already applied)
        self._prev_heading: float | None = None
        self._d_filt = 0.0
        self.output = 0.0

    def reset(self) -> None:
        self.integral = 0.0
        self._prev_heading = None
        self._d_filt = 0.0
        self.output = 0.0

    def update(self, setpoint_deg: float, heading_deg: float, dt: float) -> float:
        if not (dt > 0.0) or not math.isfinite(heading_deg):
            return self.output
        c = self.cfg
        err = wrap180(setpoint_deg - heading_deg)
        rate = 0.0
        if self._prev_heading is not None:
            rate = wrap180(heading_deg - self._prev_heading) / dt
        self._prev_heading = heading_deg
        alpha = dt / (c.d_tau_s + dt)
        self._d_filt += alpha * (rate - self._d_filt)
        p = c.kp * err
        d = -c.kd * self._d_filt
        trial_i = self.integral + c.ki * err * dt
        unclamped = p + trial_i + d
        # Anti-windup: integrate only if that does not push a saturated output further out.
        in_band = c.i_band_deg <= 0.0 or abs(err) < c.i_band_deg
        if in_band and not ((unclamped > c.out_max and err > 0)
                            or (unclamped < c.out_min and err < 0)):
            self.integral = min(max(trial_i, c.out_min), c.out_max)
        out = p + self.integral + d
        self.output = min(max(out, c.out_min), c.out_max)
        return self.output
