"""How much of a slow drift any test could find on a receiver: the matched-filter bound.

Issue 13 asks for ramps of 0.1 m/s found within 10 s and 0.05 m/s within 30 s with at most
0.1 % of clean epochs flagged. Whether a receiver allows it depends on its own error: a ramp
is seen only against the change of that error over the same seconds.

The observable is the drift test's own (D1 of :mod:`fdi.drift`): the Doppler-free value
b(t), the fix less the displacement integrated from its own speed and course
(:func:`firmware_host.rover.calibration.doppler_free`), on clean recordings of the receiver.
The oracle is told the ramp's start t0, its direction and the autocovariance γ(k) of b's
increments (both axes pooled); at the deadline t0 + T it makes one Neyman-Pearson test, the
matched filter on the increments over [t0 − H, t0 + T] (s_k = r·dt after t0, 0 before,
C = γ(|i − j|)):

    d'² = sᵀ C⁻¹ s,        P_D ≤ Φ(d' − z_α),        z_α: P(Z > z_α) = α

A detector knows neither the start nor the direction and tests every epoch, so this is an
upper bound for Gaussian errors. :func:`p_detect_2d` is the same oracle not told the
direction (both axes against χ²₂). Used by ``fdi-bridge calibrate`` (a receiver's own
recordings) and ``fdi-bridge sim ramp-oracle`` (the generator's receivers).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from fdi.chi2 import threshold

#: The issue's ramp bullets: (rate m/s, deadline s).
BULLETS: tuple[tuple[float, float], ...] = ((0.1, 10.0), (0.05, 30.0))

Chain = Sequence[tuple[float, float, float]]  # (t, b_e, b_n)


def phi(x: float) -> float:
    """The standard normal distribution function."""
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def z_alpha(alpha: float) -> float:
    """Φ⁻¹(1 − α): one-sided, so Z² exceeds its square with probability 2α (:mod:`fdi.chi2`)."""
    return math.sqrt(threshold(2.0 * alpha, 1))


def p_detect_2d(d: float, alpha: float) -> float:
    """P_D of the oracle that is not told the ramp's direction: the matched filter on both
    axes, ‖(d + z₁, z₂)‖² against χ²₂'s 1 − α quantile (z₁, z₂ standard normal),
    integrated over z₂ on a fine grid."""
    r2 = threshold(alpha, 2)
    z2 = np.linspace(-8.0, 8.0, 4001)
    w = np.exp(-0.5 * z2**2) / math.sqrt(2.0 * math.pi) * (z2[1] - z2[0])
    rest = r2 - z2**2
    p = np.ones_like(z2)  # |z2| beyond the radius: detected whatever z1
    inside = rest > 0.0
    q = np.sqrt(rest[inside])
    p[inside] = np.array([1.0 - phi(x - d) + phi(-x - d) for x in q])
    return float(np.sum(p * w))


def increment_acov(chains: Sequence[Chain],
                   max_lag: int) -> np.ndarray:
    """γ(0..max_lag) of the increments of b, both axes pooled (each chain's mean increment
    removed; chains shorter than 5 x max_lag are left out)."""
    g = np.zeros(max_lag + 1)
    n = 0
    for ch in chains:
        a = np.asarray(ch, dtype=float)
        if len(a) < 5 * max_lag:
            continue
        for col in (1, 2):
            x = np.diff(a[:, col])
            x = x - x.mean()
            for k in range(max_lag + 1):
                g[k] += float(np.dot(x[:len(x) - k], x[k:])) * len(x) / (len(x) - k)
            n += len(x)
    if n == 0:
        raise ValueError(f"no Doppler chain longer than {5 * max_lag} epochs")
    return g / n


def chain_rate_hz(chains: Sequence[Chain]) -> float:
    """The fix rate of Doppler-free chains: 1 / the median interval between fixes."""
    dts = [b[0] - a[0] for ch in chains for a, b in itertools.pairwise(ch)]
    if not dts:
        raise ValueError("no two fixes in a row")
    return 1.0 / float(np.median(dts))


def gamma_lags(rate_hz: float, history_s: float) -> int:
    """How many lags of γ the bullets' tests need at ``rate_hz`` with ``history_s``."""
    return round((history_s + max(d for _, d in BULLETS)) * rate_hz) + 1


def bounds_from_gamma(gamma: np.ndarray, rate_hz: float, alpha: float = 0.001,
                      history_s: float = 30.0) -> list[tuple[float, float, float, float, float]]:
    """Per ramp bullet (rate m/s, deadline s): d' and the oracle's P_D told the direction and
    not told it. :class:`ValueError` where γ is no noise to test against."""
    if not (np.all(np.isfinite(gamma)) and gamma[0] > 0.0):
        raise ValueError("the Doppler-free value does not move between fixes")
    z = z_alpha(alpha)
    out = []
    for r, dl in BULLETS:
        try:
            d = d_prime(gamma, rate_hz, r, dl, history_s)
        except np.linalg.LinAlgError:  # a recording whose increments are not full rank
            raise ValueError("the increments' covariance is singular") from None
        if not math.isfinite(d):
            raise ValueError("the increments' covariance is not positive definite")
        out.append((r, dl, d, phi(d - z), p_detect_2d(d, alpha)))
    return out


def bullet_bounds(chains: Sequence[Chain], alpha: float = 0.001,
                  history_s: float = 30.0) -> list[tuple[float, float, float, float, float]]:
    """:func:`bounds_from_gamma` for a receiver's Doppler-free chains. :class:`ValueError`
    when no chain is long enough for γ (5 x (history + 30 s) of fixes)."""
    rate = chain_rate_hz(chains)
    return bounds_from_gamma(increment_acov(chains, gamma_lags(rate, history_s)), rate, alpha,
                             history_s)


def d_prime(gamma: np.ndarray, rate_hz: float, ramp_mps: float, deadline_s: float,
            history_s: float) -> float:
    """d' of the matched filter for a ramp of ``ramp_mps`` tested at ``deadline_s`` after its
    start, on the increments over the ``history_s`` before it and the ``deadline_s`` after."""
    n = round((history_s + deadline_s) * rate_hz)
    if n > len(gamma):
        raise ValueError(f"γ has {len(gamma)} lags; {n} are needed")
    idx = np.arange(n)
    cov = gamma[np.abs(idx[:, None] - idx[None, :])]
    t_end = (idx + 1 - round(history_s * rate_hz)) / rate_hz  # each increment's end time
    s = np.where(t_end > 0.0, ramp_mps / rate_hz, 0.0)
    return math.sqrt(float(s @ np.linalg.solve(cov, s)))
