"""A frozen receiver's coast: the vehicle carried on from its last live fix at its last speed
and turn rate, for as long as what that model leaves out can be bounded.

Beyond Zhou & Zhang (2010). A receiver that freezes repeats its whole fix, its speed and course
too, so the old track the isolator holds (:mod:`fdi.level`, L1: the last trusted level moved by
the Doppler) would be moved on a void Doppler: in a straight line at the frozen velocity, 7.7 m
off after 10 s in a 6 m headland turn at 1 m/s. Instead, from the last live fix (time t_f; x_f
the fix, the receiver's position when it froze, if it was passed on as it was, else the old
track then; issue 42):

    ψ(t) ≈ ψ_f + ω (t − t_f),  v(t) ≈ v_f        (C1: fitted to the last live courses/speeds)
    x(t_f + τ) = x_f + v_f/ω (cos ψ_f − cos(ψ_f + ωτ), sin(ψ_f + ωτ) − sin ψ_f)      (C2)
               → x_f + v_f τ (sin ψ_f, cos ψ_f)  as ω → 0
    passed on while ½ a τ² + a (δ + σ_δ) τ ≤ budget                                   (C3)

(east, north; ψ the course from north, clockwise). C1 is a least-squares fit weighted by the
squared speed (a slow vehicle's course is noise) over the live velocities of the last
``span_s`` seconds; C2 the constant-turn-rate, constant-speed motion (CTRV); C3 bounds what
C2 leaves out: a change of speed or of turn (a stop, a turn's start or end) at most ``a``
(m/s²), whose displacement after τ is at most ½ a τ², and the Doppler's lag δ ± σ_δ behind
the position (the last live speed is the vehicle's of up to δ + σ_δ before: a (δ + σ_δ) off,
a vehicle that accelerates from a stop). Past the budget nothing is passed on: no output
rather than a worse one.

Units: metres, seconds, radians; vectors are (east, north).
"""

from __future__ import annotations

import math
from collections.abc import Sequence


def turn_fit(samples: Sequence[tuple[float, float, float]], t_f: float
             ) -> tuple[float, float, float]:
    """(C1) From live velocities ``(t, v_east, v_north)``, newest last: the speed, course
    (rad) and turn rate (rad/s) at ``t_f``. Each course is taken within ±π of the newest (a
    vehicle turns less than half a turn in a few seconds; unwrapped one by one, the random
    courses of a stop added whole turns); the fit is weighted by the squared speed; with
    fewer than two samples of speed, or all at one time, the turn rate is 0."""
    if not samples:
        return 0.0, 0.0, 0.0
    sw = swt = swp = 0.0
    _, ve_f, vn_f = samples[-1]
    speed, last = math.hypot(ve_f, vn_f), math.atan2(ve_f, vn_f)
    rows: list[tuple[float, float, float]] = []  # (w, t, course)
    for t, ve, vn in samples:
        w = ve * ve + vn * vn
        psi = last + _wrap(math.atan2(ve, vn) - last)
        sw += w
        swt += w * (t - t_f)
        swp += w * psi
        rows.append((w, t - t_f, psi))
    if sw <= 0.0:
        return speed, rows[-1][2], 0.0
    tm, pm = swt / sw, swp / sw
    stt = sum(w * (t - tm) ** 2 for w, t, _ in rows)
    stp = sum(w * (t - tm) * (p - pm) for w, t, p in rows)
    rate = stp / stt if stt > 0.0 else 0.0
    return speed, pm + rate * (0.0 - tm), rate


def ctrv(speed: float, course: float, rate: float, tau: float) -> tuple[float, float]:
    """(C2) The displacement (east, north) after ``tau`` seconds at ``speed`` (m/s) from
    ``course`` (rad from north), turning at ``rate`` (rad/s)."""
    turn = rate * tau
    if abs(turn) < 1e-6:
        return speed * tau * math.sin(course), speed * tau * math.cos(course)
    r = speed / rate
    return (r * (math.cos(course) - math.cos(course + turn)),
            r * (math.sin(course + turn) - math.sin(course)))


def within(tau: float, accel_mps2: float, lag_s: float, budget_m: float) -> bool:
    """(C3) The coast's bound after ``tau`` seconds, ½ a τ² + a lag τ (``lag_s``: the
    Doppler's lag and its σ), within ``budget_m``."""
    return accel_mps2 * tau * (0.5 * tau + lag_s) <= budget_m


def _wrap(a: float) -> float:
    """An angle difference to (-π, π]."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))
