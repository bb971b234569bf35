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

    kp: float = field(default=3.0, metadata={
        "ge": 0.0, "unit": "%/deg", "doc": "proportional gain on the wrapped heading error"})
    ki: float = field(default=0.3, metadata={
        "ge": 0.0, "unit": "%/(deg s)", "doc": "integral gain (anti-windup: see i_band_deg and "
                                               "the output limits)"})
    kd: float = field(default=2.0, metadata={
        "ge": 0.0, "unit": "%/(deg/s)", "doc": "derivative gain on the measured heading rate (not "
                                               "the error: no kick on a setpoint change)"})
    d_tau_s: float = field(default=0.2, metadata={
        "ge": 0.0, "unit": "s", "doc": "time constant of the derivative's first-order low-pass"})
    i_band_deg: float = field(default=10.0, metadata={
        "ge": 0.0, "doc": "integrate only while |error| < this (0: always)", "unit": "deg"})
    out_min: float = field(default=-100.0, metadata={
        "ge": -100.0, "le": 100.0, "unit": "%", "doc": "lower output limit (differential thrust); "
                                                       "the integral is bounded to it too"})
    out_max: float = field(default=100.0, metadata={
        "ge": -100.0, "le": 100.0, "unit": "%", "doc": "upper output limit; must exceed out_min"})
    # The thrusters' curve, inverted so that the PID's output is thrust, not command (what
    # ArduSub's MOT_THST_EXPO and MOT_SPIN_MIN do): thrust fraction T = (1 - e) x + e x^2 of
    # x = (|c| - db) / (100 - db) outside the dead band db. 0 and 0: the identity (a linear
    # thruster, the Nomoto plant's and the paper's).
    thrust_dead_band_pct: float = field(default=0.0, metadata={
        "ge": 0.0, "lt": 100.0, "doc": "thruster dead band to step over (% command)", "unit": "%"})
    thrust_expo: float = field(default=0.0, metadata={
        "ge": 0.0, "le": 1.0, "doc": "thrust curve: 0 linear, 1 quadratic (c|c|)", "unit": "-"})

    def __post_init__(self) -> None:
        if self.out_min >= self.out_max:
            raise ValueError("out_min must be < out_max")


def thrust_to_command(cfg: PidConfig, thrust_pct: float) -> float:
    """The command (%) that gives ``thrust_pct`` (% of full) on the configured curve
    (T = (1 - e) x + e x^2 solved for x >= 0, then c = db + (100 - db) x; the identity when
    both are 0)."""
    db, e = cfg.thrust_dead_band_pct, cfg.thrust_expo
    if db == 0.0 and e == 0.0:
        return thrust_pct
    t = min(abs(thrust_pct), 100.0) / 100.0
    if t <= 1e-9:
        return 0.0
    x = t if e <= 1e-9 else (-(1.0 - e) + math.sqrt((1.0 - e) ** 2 + 4.0 * e * t)) / (2.0 * e)
    return math.copysign(db + (100.0 - db) * x, thrust_pct)


class HeadingPid:
    """``update(setpoint_deg, heading_deg, dt)`` -> clamped output."""

    def __init__(self, cfg: PidConfig) -> None:
        self.cfg = cfg
        self.integral = 0.0  # in output units (ki already applied)
        self._prev_heading: float | None = None
        self._d_filt = 0.0
        self.output = 0.0

    def reset(self) -> None:
        """Clear the integral, the derivative filter and the output."""
        self.integral = 0.0
        self._prev_heading = None
        self._d_filt = 0.0
        self.output = 0.0

    def update(self, setpoint_deg: float, heading_deg: float, dt: float) -> float:
        """One control step: the output (yaw command) for ``setpoint_deg`` and the measured
        ``heading_deg`` after ``dt`` seconds; the previous output when ``dt`` or the heading
        is not usable."""
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
