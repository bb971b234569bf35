"""Slow-fault test for the rover: the fix against its own Doppler, over horizons in seconds.

Beyond Zhou & Zhang (2010), whose tests (eq. 1-6 and 18) compare a fix with a prediction from
the last few *epochs*: a drift of 0.1 m/s moves 1 cm an epoch at 10 Hz, well inside any
epoch-to-epoch gate, and a gate learned from the fixes it accepts widens with the drift
(shared/FINDINGS.md, "Measured on the first product"). Here the window is in seconds.

Per epoch, the *Doppler-free value* of the fix is

    b(t) = z(t) − D(t) − δ·v(t)                                    (D1)

with z the horizontal fix (east, north, m), D the displacement integrated from the receiver's
Doppler velocity v (m/s) and δ the receiver's lag of Doppler behind position (s). On clean data
b is the slowly varying DGPS error. For each horizon H (s) the residual against the newest
trusted reference at least H old,

    r_H(t) = b(t) − b(t_ref),   t_ref ≤ t − H                     (D2)

is zero-mean with a per-axis variance σ_H² calibrated once for the receiver (on a clean
recording: :func:`calibrate`), plus the lag's uncertainty σ_δ times the change of velocity
over the horizon (a turn):

    s_H² = σ(t − t_ref)² + (σ_δ·|v(t) − v(t_ref)|)²                (D3)

and a ramp of rate ρ that began A seconds ago gives E[r_H] = ρ·min(A, H). The statistic is the
generalised likelihood ratio for a change of mean of unknown size and direction, maximised over
the grid of change times {t − H}: for each H, Λ_H = |r_H|² / s_H² (χ² with 2 degrees of freedom
without a fault), and

    g(t) = max_H sqrt(Λ_H)                                         (D4)

against a threshold in sigmas. The σ are *fixed* after calibration: nothing is learned from
accepted fixes afterwards, so a fault that builds slowly cannot widen its own gate; references
are only the epochs the caller commits as trusted, and the caller drops those a fault may have
reached (:meth:`DriftTest.forget_after`).

Calibration, once per receiver: either offline on a clean recording (:func:`calibrate`, into
the configured σ) or, with ``calibrate_s > 0``, once at start: over the first ``calibrate_s``
seconds of committed references the test runs with the configured σ (meant to be wide) and
collects the references' differences at each horizon; then σ_H becomes 1.4826 × their median
absolute value (robust: faults that slip into the calibration, up to a large minority of the
time, barely move it, and only upwards), never below ``floor_frac`` of the configured σ,
capped by (D5) (:func:`concave_cap`), never below a shorter horizon's (D9,
:func:`monotone_floor`), and is frozen for good. Until then, with
``precal_s > 0``, a provisional σ from the differences collected over the first ``precal_s``,
estimated again every :data:`PRECAL_EVERY_S` on all collected so far (T seconds of them):

    σ_H ← min(σ_H,configured, k(T)·1.4826·median|Δb_H|)
    k(T) = 1 + (k₀ − 1)·√(precal_s / T)                             (D7)

with k₀ = ``precal_factor`` the margin for a short sample (from 120 s of fixes σ(10 s) came
out up to 1.71 × below the 300 s value on 120 runs of ``sim rover-harness``, σ(100 s) 2.18 ×),
shrinking as the sample grows, as a median's spread does (k 2.0 at 120 s, 1.63 at 300 s; on
16 seed sets of ``sim rover-harness`` ramps found in time in the first 300 s 321 → 342 of 815,
clean epochs flagged unchanged: docs/evaluation.md, fifteenth pass).
It only ever tightens the configured σ, and it is used for the watched horizon's statistic
(``g_watch``, a flag) and for the isolator's step back to an older level
(:attr:`DriftTest.working_sigmas`, ``fdi/rover.py``: what is passed on when the fixes return,
and where a hold after it starts from); the tests that flag a fix, hold it or keep it out of
the references keep the configured σ, so the calibration's sample is what it would have been
(used everywhere, the provisional σ kept long excursions out of it and σ(100 s) came out 15 %
lower; used for the hold too, four events on `multipath` seeds 6002 and 10001 came out
further from the truth than the receiver by more: docs/evaluation.md, fifteenth pass).

The calibration proper is a sample too: over 300 s there are about 2·(300 − H)/H independent
H-long differences (two axes), 58 at 10 s but 18 at 30 s and 4 at 100 s, and a median of 18
is 30-40 % low often enough to matter (``sim rover-harness``, seeds 401-405: σ(30 s) 0.187 m
on a 1 Hz receiver whose error and Doppler noise give about 0.27 m, and a 24 s false hold).
For horizons of at least ``margin_min_h`` the calibrated σ carries its own uncertainty:

    σ_H ← σ_H·(1 + m/√n_H),   n_H = max(1, 2·(T − H)/H)              (D8)

with m = ``margin`` and T = ``calibrate_s``. For Gaussian differences the median-absolute-
deviation estimate has a standard error of about 1.166·σ/√n (its efficiency is 0.37), so
m/1.166 is the margin in standard errors: m = 1.5 is 1.29 of them, a one-sided 10 % chance
that σ_H is still low. The rover's default applies it from the shortest horizon on: a 5σ test is
sensitive to a σ a few per cent low (P(χ²₂ > 25) = 3.7e-6, P(χ²₂ > (5·0.92)²) = 2.5e-5), and
σ(3 s) from about 200 differences is that low often enough to hold clean fixes.

Coarse coordinates (a receiver that writes 4 decimals of minutes rounds latitude to 0.19 m)
add the variance of the difference of two rounding errors, uniform in ±q/2, to every σ:

    σ_H ← sqrt(σ_H² + q²/6)                                        (D6)

with q the coordinate quantum the caller estimates from the fixes (the smallest non-zero
change between consecutive fixes): a robust calibration does not see it, since most
short-horizon differences are a fraction of a quantum and a few a whole one.

Units: metres, seconds; shapes: 2-tuples (east, north).
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_left, bisect_right
from collections.abc import Sequence
from typing import NamedTuple

from fdi.errors import ConfigError


class DriftResult(NamedTuple):
    """One epoch's test: the statistic (D4), the horizon that gave it, and its reference
    (a NamedTuple: built once an epoch)."""

    g: float  # max over horizons of |r_H| / s_H
    horizon_s: float  # the horizon of the reference below (0: no reference yet)
    ref_t: float  # the oldest reference whose statistic is within 0.6 of the maximum
    ref_b: tuple[float, float]  # its Doppler-free value
    ref_v: tuple[float, float]  # its Doppler velocity
    g_watch: float = 0.0  # sqrt(Λ_H) of the watched horizon alone, its reference at most 1.25 H
    # old (0: not watched, or no such reference)


_new = tuple.__new__
LEVEL_EVERY_S = 10.0
PRECAL_EVERY_S = 10.0  # the provisional calibration (D7) is estimated again this often
LEVEL_KEEP_S = 300.0
NO_TEST = DriftResult(0.0, 0.0, math.nan, (math.nan, math.nan), (math.nan, math.nan), 0.0)


def sigma_at(age_s: float, horizons: Sequence[float], sigmas: Sequence[float]) -> float:
    """σ of (D3) at a reference age: linear between the calibrated horizons, the first
    horizon's below it, growing as √age beyond the last (a random walk, pessimistic for a
    stationary error)."""
    if age_s <= horizons[0]:
        return sigmas[0]
    for i in range(1, len(horizons)):
        if age_s <= horizons[i]:
            h0, h1 = horizons[i - 1], horizons[i]
            w = (age_s - h0) / (h1 - h0)
            return sigmas[i - 1] + w * (sigmas[i] - sigmas[i - 1])
    return sigmas[-1] * math.sqrt(age_s / horizons[-1])


class DriftTest:
    """The multi-horizon test (D1)-(D4) over trusted references kept for the longest horizon.

    ``horizons_s`` ascending, ``sigma_m`` the per-axis σ of (D3) at each; ``lag_sd_s`` is σ_δ.
    """

    __slots__ = ("_base", "_be", "_bn", "_cal", "_cal_sorted", "_cal_until", "_configured",
                 "_keep", "_lt_e",
                 "_lt_n", "_lt_t", "_prov", "_prov_until", "_t", "_ve", "_vn", "calibrate_s",
                 "calibrated", "floor_frac", "horizons", "lag_sd", "margin", "margin_min_h",
                 "precal_factor", "precal_s", "quantum", "sigmas", "watch_s")

    def __init__(self, horizons_s: Sequence[float], sigma_m: Sequence[float],
                 lag_sd_s: float, calibrate_s: float = 0.0, floor_frac: float = 0.2,
                 watch_s: float = 0.0, precal_s: float = 0.0,
                 precal_factor: float = 2.0, margin: float = 0.0,
                 margin_min_h: float = 0.0) -> None:
        where = "[rover.detector]"
        if len(horizons_s) != len(sigma_m) or not horizons_s:
            raise ConfigError(where, "drift_sigma_m", "one value per drift_horizons_s",
                              f"{len(sigma_m)} for {len(horizons_s)}")
        if list(horizons_s) != sorted(horizons_s) or horizons_s[0] <= 0.0:
            raise ConfigError(where, "drift_horizons_s", "positive, ascending",
                              repr(list(horizons_s)))
        if min(sigma_m) <= 0.0:
            raise ConfigError(where, "drift_sigma_m", "positive values", repr(list(sigma_m)))
        self.horizons = tuple(float(h) for h in horizons_s)
        # One horizon whose statistic is also reported alone (DriftResult.g_watch; 0: none).
        self.watch_s = float(watch_s)
        # The calibrated (or configured) σ, and the σ used: with the coordinates' quantum
        # (:meth:`set_quantum`, D6).
        self._base = tuple(float(s) for s in sigma_m)
        self._configured = self._base
        self.sigmas = self._base
        self.quantum = 0.0
        self.lag_sd = lag_sd_s
        # References in flat float arrays (times ascending): nothing here for the cyclic
        # garbage collector to walk, which tuples in lists made a 2-8 ms pause every few
        # seconds (fdi-bridge bench, p99). The times in a list of floats (no tuples either):
        # each epoch bisects them at every horizon, and an array's item is a new float at
        # each step of the search (2 % of the detector's instructions).
        self._t: list[float] = []
        self._be, self._bn, self._ve, self._vn = array("d"), array("d"), array("d"), array("d")
        self._keep = 2.0 * self.horizons[-1]
        # The long-term levels: one reference every LEVEL_EVERY_S, kept LEVEL_KEEP_S, that
        # survive a restart on the receiver (fdi.level's "which side" looks back to them).
        self._lt_t, self._lt_e, self._lt_n = array("d"), array("d"), array("d")
        self.calibrate_s = calibrate_s
        # A provisional calibration after precal_s (< calibrate_s; 0: none): the same
        # estimate x precal_factor, never wider than configured (D7).
        self.precal_s = precal_s if 0.0 < precal_s < calibrate_s else 0.0
        self.precal_factor = precal_factor
        self._prov_until: float | None = None
        self._prov: tuple[float, ...] | None = None  # the provisional σ (with D6), till then
        self.floor_frac = floor_frac
        # The calibration's own uncertainty (D8), for H >= margin_min_h.
        self.margin = margin
        self.margin_min_h = margin_min_h
        self.calibrated = calibrate_s <= 0.0
        self._cal_until: float | None = None
        # Per horizon, the differences collected since the last estimate (_cal) and those
        # before it, sorted (_cal_sorted): each estimate sorts only the new ones and merges
        # (Timsort merges two sorted runs in one linear pass). Sorting all of them every
        # PRECAL_EVERY_S cost 7 % of the throughput at 10 Hz (bench --only against).
        self._cal: list[array[float]] = [array("d") for _ in self.horizons]
        self._cal_sorted: list[list[float]] = [[] for _ in self.horizons]

    def reset(self) -> None:
        """Forget every reference, long-term levels too (the Doppler chain broke)."""
        self.reset_short()
        for a in (self._lt_t, self._lt_e, self._lt_n):
            del a[:]

    def reset_short(self) -> None:
        """Forget the test's references, keep the long-term levels (a restart on the
        receiver's level, the Doppler chain intact)."""
        del self._t[:]
        for a in (self._be, self._bn, self._ve, self._vn):
            del a[:]

    def rebase(self, de: float, dn: float) -> None:
        """The caller's displacement origin moved by −(de, dn): every b moves by +(de, dn)."""
        self._be = array("d", (x + de for x in self._be))
        self._bn = array("d", (x + dn for x in self._bn))
        self._lt_e = array("d", (x + de for x in self._lt_e))
        self._lt_n = array("d", (x + dn for x in self._lt_n))

    def commit(self, t: float, b: tuple[float, float], v: tuple[float, float]) -> None:
        """Keep epoch ``t`` (trusted) as a reference for later epochs."""
        if not self.calibrated:
            self._calibrate_step(t, b)
        self._t.append(t)
        self._be.append(b[0])
        self._bn.append(b[1])
        self._ve.append(v[0])
        self._vn.append(v[1])
        lt = self._lt_t
        if not lt or t - lt[-1] >= LEVEL_EVERY_S:
            lt.append(t)
            self._lt_e.append(b[0])
            self._lt_n.append(b[1])
            if t - lt[0] > LEVEL_KEEP_S:
                for a in (lt, self._lt_e, self._lt_n):
                    del a[0]
        if t - self._t[0] > self._keep + 5.0:
            cut = bisect_right(self._t, t - self._keep)
            del self._t[:cut]
            for a in (self._be, self._bn, self._ve, self._vn):
                del a[:cut]

    def _estimate(self, factor: float = 1.0, provisional: bool = False) -> tuple[float, ...]:
        """σ_H from the differences collected so far (× ``factor``), never below
        ``floor_frac`` of the configured value, capped by (D5); the configured value where
        fewer than 20 were collected. The calibration proper carries its own uncertainty (D8);
        a ``provisional`` one (D7) has its factor instead and is never wider than configured."""
        out = []
        for j, configured in enumerate(self._configured):
            xs = self._sorted_cal(j)
            if len(xs) < 20:
                out.append(configured)
                continue
            est = factor * 1.4826 * xs[len(xs) // 2]
            h = self.horizons[j]
            if self.margin > 0.0 and h >= self.margin_min_h and not provisional:
                n = max(1.0, 2.0 * (self.calibrate_s - h) / h)  # (D8)
                est *= 1.0 + self.margin / math.sqrt(n)
            est = max(est, self.floor_frac * configured)
            out.append(min(configured, est) if provisional else est)
        return monotone_floor(concave_cap(self.horizons, out))

    def _sorted_cal(self, j: int) -> list[float]:
        """Every difference collected at horizon ``j``, ascending."""
        new = self._cal[j]
        if new:
            self._cal_sorted[j] = sorted(self._cal_sorted[j] + sorted(new))
            del new[:]
        return self._cal_sorted[j]

    def _calibrate_step(self, t: float, b: tuple[float, float]) -> None:
        if self._cal_until is None:
            self._cal_until = t + self.calibrate_s
            if self.precal_s > 0.0:
                self._prov_until = t + self.precal_s
        ts = self._t
        for j, h in enumerate(self.horizons):
            i = bisect_right(ts, t - h) - 1
            if i >= 0 and t - ts[i] <= h + max(1.5, 0.2 * h):
                self._cal[j].append(abs(b[0] - self._be[i]))
                self._cal[j].append(abs(b[1] - self._bn[i]))
        if self._prov_until is not None and t >= self._prov_until:
            # (D7), again every PRECAL_EVERY_S, its margin shrinking with the sample
            collected = max(self.precal_s, t - (self._cal_until - self.calibrate_s))
            k = 1.0 + (self.precal_factor - 1.0) * math.sqrt(self.precal_s / collected)
            self._prov_until = t + PRECAL_EVERY_S
            self._prov = self._estimate(k, provisional=True)
        if t >= self._cal_until:
            self._base = self._estimate()
            self._prov = None
            self.set_quantum(self.quantum)
            self.calibrated = True
            self._cal = []
            self._cal_sorted = []

    def set_quantum(self, q: float) -> None:
        """The receiver's coordinate quantum ``q`` (m, the larger axis): each σ of (D3)
        becomes sqrt(σ² + q²/6) (D6), the variance of the difference of two independent
        rounding errors, uniform in ±q/2. A calibration's median absolute difference misses
        it: with coarse coordinates most short-horizon differences are a fraction of a quantum
        and a few are a whole one (4 decimals of minutes: 0.19 m of latitude)."""
        self.quantum = q
        qv = q * q / 6.0
        self.sigmas = tuple(math.sqrt(s * s + qv) for s in self._base)

    @property
    def working_sigmas(self) -> tuple[float, ...]:
        """The σ of the isolator's step back to an older level: the provisional σ (D7, with
        the quantum's share D6) while calibrating, once it exists; else :attr:`sigmas`. Never
        wider than :attr:`sigmas` (D7 only tightens the configured σ). The tests that flag a
        fix, hold it or keep it out of the references use :attr:`sigmas` (the calibration's
        sample, above)."""
        prov = self._prov
        if prov is None:
            return self.sigmas
        qv = self.quantum * self.quantum / 6.0
        return tuple(math.sqrt(w * w + qv) for w in prov)

    def forget_after(self, t: float) -> None:
        """Drop the references newer than ``t`` (a fault may have been building since)."""
        cut = bisect_right(self._t, t)
        del self._t[cut:]
        for a in (self._be, self._bn, self._ve, self._vn):
            del a[cut:]
        cut = bisect_right(self._lt_t, t)
        for a in (self._lt_t, self._lt_e, self._lt_n):
            del a[cut:]

    def at_or_before(self, t: float) -> tuple[float, tuple[float, float], tuple[float, float]
                                               ] | None:
        """The newest trusted reference at or before ``t``: (time, b, v), if any."""
        i = bisect_right(self._t, t) - 1
        if i < 0:
            return None
        return self._t[i], (self._be[i], self._bn[i]), (self._ve[i], self._vn[i])

    def oldest(self, before: float) -> tuple[float, tuple[float, float]] | None:
        """The oldest long-term level, if it is at or before ``before``: (time, b)."""
        if not self._lt_t or self._lt_t[0] > before:
            return None
        return self._lt_t[0], (self._lt_e[0], self._lt_n[0])

    def levels_between(self, t0: float, t1: float) -> list[tuple[float, tuple[float, float]]]:
        """The long-term levels with t0 <= time <= t1: (time, b), oldest first."""
        lt = self._lt_t
        i, j = bisect_left(lt, t0), bisect_right(lt, t1)
        return [(lt[k], (self._lt_e[k], self._lt_n[k])) for k in range(i, j)]

    def test(self, t: float, b: tuple[float, float], v: tuple[float, float]) -> DriftResult:
        """(D2)-(D4) for an epoch at ``t`` with Doppler-free value ``b`` and velocity ``v``."""
        ts = self._t
        if not ts:
            return NO_TEST
        # Per horizon (statistic, horizon, index of its reference); one DriftResult at the end
        # (this runs once an epoch).
        found: list[tuple[float, float, int]] = []
        horizons, sigmas, lag_sd = self.horizons, self.sigmas, self.lag_sd
        b_e, b_n, v_e, v_n = self._be, self._bn, self._ve, self._vn
        be0, bn0 = b
        ve0, vn0 = v
        hypot, sqrt = math.hypot, math.sqrt
        last_i = -1
        g_max = -1.0
        g_watch = 0.0
        watch = self.watch_s
        prov = self._prov
        h0, s0, h_last, s_last = horizons[0], sigmas[0], horizons[-1], sigmas[-1]
        n_h = len(horizons)
        for h in horizons:
            i = bisect_right(ts, t - h) - 1
            if i < 0:
                break
            if i == last_i:
                continue  # the same reference as a shorter horizon (a gap in references)
            last_i = i
            # (D3): sigma_at(t - ts[i], horizons, sigmas), written out (the same operations)
            age = t - ts[i]
            if age <= h0:
                s = s0
            else:
                for k in range(1, n_h):
                    if age <= horizons[k]:
                        ha, hb = horizons[k - 1], horizons[k]
                        w = (age - ha) / (hb - ha)
                        s = sigmas[k - 1] + w * (sigmas[k] - sigmas[k - 1])
                        break
                else:
                    s = s_last * sqrt(age / h_last)
            dv = lag_sd * hypot(ve0 - v_e[i], vn0 - v_n[i])
            re, rn = be0 - b_e[i], bn0 - b_n[i]  # (D2)
            g = sqrt((re * re + rn * rn) / (s * s + dv * dv))
            if not found or g > g_max:  # (D4): max(r[0] for r in found), the first maximum
                g_max = g
            if h == watch and age <= 1.25 * h:  # a reference about H old, not one a gap left
                if prov is None:
                    g_watch = g
                else:  # calibrating: the provisional σ (D7), with the quantum's share (D6)
                    sw = sigma_at(age, horizons, prov)
                    g_watch = sqrt((re * re + rn * rn) / (
                        sw * sw + self.quantum * self.quantum / 6.0 + dv * dv))
            found.append((g, h, i))
        if not found or g_max != g_max:  # g_max NaN: a value not finite reached (D2), no test
            return NO_TEST
        # The statistic is the maximum (D4); the reference reported with it is the *oldest*
        # one whose statistic is within 0.6 of it: a slow fault is seen about as strongly at
        # every horizon longer than its age, and the oldest such reference is the one most
        # likely from before it began (the isolator anchors its hold there).
        near = 0.6 * g_max
        for k in range(len(found) - 1, -1, -1):  # the oldest: from the longest horizon down
            g, h, i = found[k]
            if g >= near:
                break
        return _new(DriftResult, (g_max, h, ts[i], (b_e[i], b_n[i]), (v_e[i], v_n[i]),
                                  g_watch))

def concave_cap(horizons_s: Sequence[float], sigmas: Sequence[float]) -> tuple[float, ...]:
    """σ_H capped at σ_h·√(H/h) from each shorter horizon h (D5).

    The error model's components (Gauss-Markov processes, white noise, the random walk of the
    Doppler's integrated noise) all have an increment variance D(H) = E[(b(t) − b(t−H))²]
    that is concave in H with D(0) ≥ 0, so D(H)/H does not grow with H:

        σ_H ≤ σ_h·√(H/h)  for H ≥ h                                  (D5)

    A calibration whose long horizons exceed it has pairs that straddle a fault (a long
    horizon's pairs reach across more of the recording: on fault-dense runs σ(30 s) came out
    3x σ(10 s) where (D5) allows 1.7x); the shorter horizons are the better estimate."""
    out = list(sigmas)
    for i in range(1, len(out)):
        cap = min(out[j] * math.sqrt(horizons_s[i] / horizons_s[j]) for j in range(i))
        out[i] = min(out[i], cap)
    return tuple(out)


def monotone_floor(sigmas: Sequence[float]) -> tuple[float, ...]:
    """σ_H raised to the largest σ_h of any shorter horizon h (D9).

    The same components' increment variance D(H) = E[(b(t) − b(t−H))²] does not fall as H
    grows (a Gauss-Markov process: 2σ²(1 − e^(−H/τ)); white noise: constant; a random walk:
    linear), so

        σ_H ≥ σ_h  for H ≥ h                                        (D9)

    and with (D5) σ_h ≤ σ_H ≤ σ_h·√(H/h). A long horizon has few independent differences in a
    calibration (about 2·(T − H)/H: 4 at 100 s in 300 s), and their median can come out far
    below a shorter horizon's, which has many: the test then flags clean fixes at that horizon
    (``sim rover-harness``, dgps 1 Hz: σ(100 s) 0.39 m under σ(30 s) 0.52 m, a false hold).
    Applied after (D5): a floor from capped values keeps every cap."""
    out = list(sigmas)
    for i in range(1, len(out)):
        out[i] = max(out[i], out[i - 1])
    return tuple(out)


def calibrate(samples: Sequence[tuple[float, float, float]],
              horizons_s: Sequence[float]) -> tuple[float, ...]:
    """Per-axis σ of (D2) at each horizon from a clean recording, once per receiver.

    ``samples``: (t, b_e, b_n) of consecutive clean epochs with an unbroken Doppler chain.
    Robust: 1.4826 × the median absolute difference over both axes (a stray fault in the
    recording does not widen it)."""
    ts = [s[0] for s in samples]
    out = []
    for h in horizons_s:
        diffs: list[float] = []
        for t, be, bn in samples:
            i = bisect_right(ts, t - h) - 1
            if i < 0 or t - ts[i] > h + 1.5:
                continue
            diffs.append(abs(be - samples[i][1]))
            diffs.append(abs(bn - samples[i][2]))
        if not diffs:
            raise ValueError(f"no pair of samples {h} s apart to calibrate on")
        diffs.sort()
        out.append(1.4826 * diffs[len(diffs) // 2])
    return monotone_floor(concave_cap(horizons_s, out))
