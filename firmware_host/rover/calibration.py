"""The rover drift test's σ per horizon, calibrated offline on a receiver's clean recordings.

The drift test (:mod:`fdi.drift`) compares each fix with its own Doppler over horizons in
seconds, against a per-axis σ per horizon of *this* receiver. By default it calibrates once at
every start, over its first ``drift_calibrate_s`` (300 s), and uses the wide ``drift_sigma_m``
until then, so a slow drift that begins in those minutes is found late. A receiver used day
after day can instead be calibrated once, on a recording of a clean drive, as an autopilot
keeps its compass calibration in its parameters: :data:`START_FACTOR` × the σ go into
``drift_sigma_m``, the test starts from them and still calibrates on each day's first
``drift_calibrate_s`` (``fdi-bridge calibrate``; ``drift_calibrate_s = 0`` keeps them).

The recordings also measure the receiver's Doppler lag behind its position, δ of (D1)
(:func:`estimate_lag`, eq. L1; a receiver that filters its velocity reports it late): the
configuration's 0.15 ± 0.15 s covers every receiver but widens σ by up to 0.3 m in a headland
turn, so a ramp that begins in one is seen late; with δ measured (to about 0.01 s),
``drift_lag_sd_s`` becomes :data:`LAG_SD_K` of its standard errors, never below
:data:`LAG_SD_FLOOR_S`.

The recordings are replayed through the rover pipeline of the configuration (its parser, its
local frame, its Doppler integration); the Doppler-free value (D1), with the measured lag, is
formed from each record's fix, speed and course, split where the Doppler chain breaks, and
each chain long enough (twice the longest horizon) is calibrated by
:func:`fdi.drift.calibrate` (robust: a stray fault in the recording does not widen it). The
result is the largest σ over the chains (a receiver's worst clean day is its gate), times the
calibration's own uncertainty (D8) where the recordings hold few independent differences at a
horizon.
"""

from __future__ import annotations

import dataclasses
import math
from bisect import bisect_left
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from fdi.drift import calibrate, concave_cap
from fdi.rover import RoverDetectorParams


@dataclass(frozen=True)
class Calibration:
    """The result: σ per horizon and what it rests on."""

    horizons_s: tuple[float, ...]
    sigma_m: tuple[float, ...]  # per axis, D8 margin included
    chains: int  # unbroken Doppler chains used
    seconds: float  # their total length
    independent: tuple[float, ...]  # independent differences per horizon, 2·Σ(T − H)/H
    lag_s: float  # δ of (D1) the σ were calibrated with: estimated, or as configured
    lag_sd_s: float  # σ_δ of (D3) to go with it
    lag: LagEstimate | None = None  # the estimate, where the drives turned enough for one


def _chains(records: Sequence[dict[str, Any]]
            ) -> list[list[tuple[float, float, float, float, float]]]:
    """(t, e − D_e, n − D_n, v_e, v_n) per record: the fix less its integrated Doppler (D of
    (D1) in :mod:`fdi.drift`, trapezoidal) and the Doppler velocity, split where the Doppler
    chain breaks (no fix, no speed); the pipeline's own local metres."""
    chains: list[list[tuple[float, float, float, float, float]]] = [[]]
    de = dn = 0.0
    last: tuple[float, float, float] | None = None  # t, ve, vn
    for r in records:
        sp, co = r.get("speed"), r.get("course")
        if r.get("e") is None or sp is None or r.get("utc") is None:
            chains.append([])
            last = None
            continue
        c = math.radians(co) if co is not None else 0.0
        ve, vn = (sp * math.sin(c), sp * math.cos(c)) if co is not None else (0.0, 0.0)
        t = float(r["utc"])
        if last is not None:
            dt = t - last[0]
            de += 0.5 * (ve + last[1]) * dt
            dn += 0.5 * (vn + last[2]) * dt
        last = (t, ve, vn)
        chains[-1].append((t, r["e"] - de, r["n"] - dn, ve, vn))
    return [c for c in chains if len(c) > 10]


def doppler_free(records: Sequence[dict[str, Any]], lag_s: float
                 ) -> list[list[tuple[float, float, float]]]:
    """(t, b_e, b_n) of (D1) in :mod:`fdi.drift` from a pipeline's records, split where the
    Doppler chain breaks (no fix, no speed); the pipeline's own local metres."""
    return [[(t, e - lag_s * ve, n - lag_s * vn) for t, e, n, ve, vn in chain]
            for chain in _chains(records)]


#: The Doppler's lag behind the position, estimated on the clean drives (:func:`estimate_lag`):
#: pairs of fixes this far apart ...
LAG_PAIR_S = 3.0
#: ... whose Doppler velocity changed by at least this much (turns, starts and stops: where the
#: lag shows; elsewhere the pair only adds the Doppler's noise to the regressor).
LAG_MIN_DV_MPS = 0.3
#: ``drift_lag_sd_s`` after an estimate: this many of its standard errors, never below
#: :data:`LAG_SD_FLOOR_S` (the generator's true lag with 0.05 s found 19 more ramps in time of
#: 217 on ``sim rover-harness`` seeds 1-5 than 0.15 ± 0.15 s, none flagged; docs/evaluation.md).
LAG_SD_K = 3.0
LAG_SD_FLOOR_S = 0.05
#: ``ramp_sigmas`` after an estimate: the ramp's 10 s flag at the warning's level. Its 4 σ
#: were chosen under the lag's ±0.15 s, which widened σ in every turn and in the calibration
#: (the median of the 10 s differences); with the lag measured, the σ are this receiver's own
#: and 4 σ flagged 32 clean epochs on seeds 6001-6005 (a `gm` 5 Hz run 0.89 %: a 60 s
#: Gauss-Markov error over 4 σ for 5 s), 4.25 σ 20, 4.5 σ 6 (16 with neither change), while
#: ramps of 0.1 m/s or more found within 10 s went 141 → 177, 169 and 163 of 208.
LAG_RAMP_SIGMAS = 4.5


@dataclass(frozen=True)
class LagEstimate:
    lag_s: float  # δ of (D1)
    sd_s: float  # the σ_δ the drift test is to use: LAG_SD_K x the standard error, floored
    se_s: float  # the least-squares standard error
    pairs: int  # pairs used


def estimate_lag(runs: Sequence[Sequence[dict[str, Any]]]) -> LagEstimate | None:
    """δ of (D1) by least squares on the clean drives: over pairs of fixes
    :data:`LAG_PAIR_S` apart whose Doppler changed by at least :data:`LAG_MIN_DV_MPS`,

        Δ(z − D) = δ·Δv + ε                                          (L1)

    per axis (the same δ), δ̂ = Σ Δ(z − D)·Δv / Σ|Δv|², refitted once without the pairs whose
    residual is beyond 4 robust σ (a stray fault in a recording). None where fewer than 20
    pairs turn (a straight drive says nothing of the lag); δ̂ is clipped to [0, 1] s."""
    xs: list[tuple[float, float, float, float]] = []  # (Δv_e, Δv_n, Δy_e, Δy_n)
    for records in runs:
        for chain in _chains(records):
            ts = [c[0] for c in chain]
            for i, (t, e, n, ve, vn) in enumerate(chain):
                j = bisect_left(ts, t - LAG_PAIR_S - 1e-6)
                if j >= i or abs(ts[j] - (t - LAG_PAIR_S)) > 0.26 * LAG_PAIR_S:
                    continue
                _, e0, n0, ve0, vn0 = chain[j]
                dve, dvn = ve - ve0, vn - vn0
                if math.hypot(dve, dvn) >= LAG_MIN_DV_MPS:
                    xs.append((dve, dvn, e - e0, n - n0))
    if len(xs) < 20:
        return None

    def fit(pairs: list[tuple[float, float, float, float]]) -> tuple[float, float]:
        sxx = sum(a * a + b * b for a, b, _, _ in pairs)
        lag = sum(a * y + b * z for a, b, y, z in pairs) / sxx
        rss = sum((y - lag * a) ** 2 + (z - lag * b) ** 2 for a, b, y, z in pairs)
        return lag, math.sqrt(rss / max(1, 2 * len(pairs) - 1) / sxx)

    lag, _ = fit(xs)
    res = [(abs(y - lag * a), abs(z - lag * b)) for a, b, y, z in xs]  # per axis
    per_axis = sorted(r for pair in res for r in pair)
    keep_m = 4.0 * 1.4826 * per_axis[len(per_axis) // 2]
    kept = [x for x, r in zip(xs, res, strict=True) if max(r) <= keep_m]
    if len(kept) >= 20:
        xs = kept
    lag, se = fit(xs)
    lag = min(1.0, max(0.0, lag))
    return LagEstimate(round(lag, 3), round(max(LAG_SD_FLOOR_S, LAG_SD_K * se), 3),
                       round(se, 4), len(xs))


def calibrate_records(runs: Sequence[Sequence[dict[str, Any]]], horizons_s: Sequence[float],
                      lag_s: float, lag_sd_s: float, margin: float = 0.0,
                      margin_min_h: float = 0.0) -> Calibration:
    """σ per horizon over the pipeline records of one receiver's recordings (``runs``).

    The Doppler's lag is estimated first (:func:`estimate_lag`) and the σ are those of (D1)
    with it; where the drives do not turn enough for an estimate, ``lag_s`` and ``lag_sd_s``
    (the configured ones) are kept.
    Chains shorter than twice the longest horizon are not used; :class:`ValueError` when none
    is long enough. ``margin``/``margin_min_h``: (D8) with n_H the independent H-long
    differences of all the chains used."""
    lag = estimate_lag(runs)
    if lag is not None:
        lag_s, lag_sd_s = lag.lag_s, lag.sd_s
    need = 2.0 * max(horizons_s)
    worst = [0.0] * len(horizons_s)
    used = 0
    total = 0.0
    indep = [0.0] * len(horizons_s)
    longest = 0.0
    for records in runs:
        for chain in doppler_free(records, lag_s):
            span = chain[-1][0] - chain[0][0]
            longest = max(longest, span)
            if span < need:
                continue
            sig = calibrate(chain, horizons_s)
            worst = [max(a, b) for a, b in zip(worst, sig, strict=True)]
            used += 1
            total += span
            indep = [n + 2.0 * (span - h) / h for n, h in zip(indep, horizons_s, strict=True)]
    if not used:
        raise ValueError(f"no stretch of fixes with an unbroken Doppler chain of {need:.0f} s "
                         f"or more (the longest: {longest:.0f} s)")
    out = []
    for s, h, n in zip(worst, horizons_s, indep, strict=True):
        if margin > 0.0 and h >= margin_min_h:
            s *= 1.0 + margin / math.sqrt(max(1.0, n))  # (D8)
        out.append(s)
    capped = concave_cap(horizons_s, out)  # (D5), as the calibration at start
    return Calibration(tuple(horizons_s), tuple(round(s, 4) for s in capped), used, total,
                       tuple(round(n, 1) for n in indep), lag_s, lag_sd_s, lag)


#: The calibrated σ are another day's: the drift test starts from this many times them (never
#: wider than configured), as the provisional calibration (D7) does from its short sample.
#: Chosen on `sim rover-harness --offline-calibration` seeds 1-5 and 801-805 (before the floor
#: below): 1.0 found 29 and 18 more ramps in time but flagged 12 and 64 clean epochs (a false
#: hold at 131 s on `dgps` 10 Hz seed 801: its clean drive gave σ(10 s) 0.13 m); 1.5: 10 and
#: 8 more ramps, 5 and 11 flagged (0 and 7 before); 2.0: 3 more on 1-5 (docs/evaluation.md,
#: seventh pass).
START_FACTOR = 1.5


#: ``drift_floor_frac`` with an offline calibration: the day's calibration at start may widen
#: the σ but not narrow them below the offline ones (it sees only the fixes it trusts, fewer
#: from the tighter start: `multipath` 10 Hz seed 202 of ``sim rover-harness
#: --offline-calibration``, a false hold at 860 s, 67 epochs, with the default 0.2).
START_FLOOR_FRAC = round(1.0 / START_FACTOR, 4)


def starting_sigma(cal: Calibration, configured: Sequence[float],
                   factor: float = START_FACTOR) -> tuple[float, ...]:
    """``drift_sigma_m`` for a receiver calibrated offline: ``factor`` × its σ, never wider
    than ``configured`` (the wide defaults)."""
    return tuple(round(min(c, factor * s), 4)
                 for s, c in zip(cal.sigma_m, configured, strict=True))


def calibrated_detector(det: RoverDetectorParams, cal: Calibration) -> RoverDetectorParams:
    """The ``[rover.detector]`` parameters ``det`` started from ``cal``: ``drift_sigma_m``
    from :func:`starting_sigma`, ``drift_floor_frac`` :data:`START_FLOOR_FRAC`, the Doppler's
    lag (``drift_lag_s``, ``drift_lag_sd_s``) the σ were calibrated with and, where it was
    measured, ``ramp_sigmas`` at least :data:`LAG_RAMP_SIGMAS`."""
    ramp_sigmas = det.ramp_sigmas
    if cal.lag is not None and 0.0 < ramp_sigmas < LAG_RAMP_SIGMAS:
        ramp_sigmas = LAG_RAMP_SIGMAS
    return dataclasses.replace(det, drift_sigma_m=starting_sigma(cal, det.drift_sigma_m),
                               drift_floor_frac=START_FLOOR_FRAC, drift_lag_s=cal.lag_s,
                               drift_lag_sd_s=cal.lag_sd_s, ramp_sigmas=ramp_sigmas)
