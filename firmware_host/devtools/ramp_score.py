"""The ramp oracle scored as ``fdi-bridge sim rover-harness`` scores a detector (issue 42).

:mod:`firmware_host.rover.drift_bound` bounds one test at the deadline: told the ramp's start,
one matched filter over the ``T·rate`` increments after it at α = 0.001. The harness scores
otherwise, and this module puts the same oracle under the harness's rules:

* **a per-epoch false-alarm budget**: the bullet's 0.1 % is of clean epochs flagged, so the
  oracle may test at *every* epoch, each test at α = 0.001 per epoch;
* **the delay from the first faulty epoch**: a ramp of rate ρ is already ρ·dt off at its first
  epoch (``rover_sim``: offset (k − start + 1)·dt), and "within T s" takes the epochs at
  t₀, t₀ + dt, ..., t₀ + T: ``K = T·rate + 1`` increments carry the ramp (the single test had
  ``T·rate``);
* **direction unknown**: both axes, against χ²₂;
* **Doppler averaging allowed**: the oracle's history of clean increments before the ramp is
  ``history_s`` (60 s by default in the harness: the independent GLR of issue 42 averaged the
  Doppler over 60 s); the matched filter weighs that history optimally.

With C the covariance of the n = H·rate + K increments (γ(|i − j|), both axes alike), L its
Cholesky factor and u the unit ramp's increments (0 over the history, dt after t₀), the
whitened data z = L⁻¹x are independent N(ρ·y, 1) with y = L⁻¹u (y is 0 over the history:
forward substitution). The matched filter at the k-th faulty epoch uses the first n_k
increments; forward substitution is prefix-consistent, so

    T_k = Σ_{i<n_k} y_i z_i / d_k,      d_k² = Σ_{i<n_k} y_i²                (O1)

and the tests at two epochs j ≤ k are correlated by d_j / d_k (they are nested sums). Per axis
T_k is N(ρ·d_k·cos θ, 1) (east) and N(ρ·d_k·sin θ, 1) (north); with the direction unknown the
oracle flags epoch k when (T_kᵉ)² + (T_kⁿ)² > −2 ln α, and finds the ramp in time when it flags
any of the K epochs. P_D is the fraction of :data:`DRAWS` seeded draws of the two random walks
(O1) that do (the statistic is rotation invariant: θ = 0).

Not a bound on every detector in the strict sense (a detector may spend its per-epoch budget
unevenly); it is the known-start, known-covariance oracle under the harness's scoring, the
count the preset's ramps found in time is compared with (issue 42: at least 0.95 x).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Monte Carlo draws per P_D (the standard error is at most 0.5 / sqrt(DRAWS) = 0.0035).
DRAWS = 20_000
#: The draws' generator seed: every P_D of one run uses the same draws (common random numbers).
DRAWS_SEED = 42
#: The history of clean increments the harness-scored oracle uses before the ramp (s).
HARNESS_HISTORY_S = 60.0


@dataclass(frozen=True)
class EpochTests:
    """The oracle's tests at the K epochs from a ramp's first faulty epoch to its deadline, for a
    unit ramp (1 m/s): ``y`` the whitened unit ramp's increments after t₀ (O1)."""

    y: np.ndarray  # (K,)

    @property
    def d_unit(self) -> np.ndarray:
        """d_k for a 1 m/s ramp (d' scales with the rate)."""
        return np.sqrt(np.cumsum(self.y ** 2))


def epoch_tests(gamma: np.ndarray, rate_hz: float, deadline_s: float,
                history_s: float) -> EpochTests:
    """(O1) for a receiver whose increments have autocovariance ``gamma`` (lags 0, 1, ...).
    :class:`ValueError` when γ has too few lags or is not positive definite."""
    h = round(history_s * rate_hz)
    k = round(deadline_s * rate_hz) + 1
    n = h + k
    if n > len(gamma):
        raise ValueError(f"γ has {len(gamma)} lags; {n} are needed")
    idx = np.arange(n)
    cov = gamma[np.abs(idx[:, None] - idx[None, :])]
    try:
        low = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise ValueError("the increments' covariance is not positive definite") from None
    u = np.where(idx >= h, 1.0 / rate_hz, 0.0)
    y = np.linalg.solve(low, u)  # forward substitution on a lower-triangular matrix
    return EpochTests(y[h:])


def p_detect(tests: EpochTests, ramp_mps: float, alpha: float = 0.001,
             draws: np.ndarray | None = None) -> float:
    """P_D of the oracle under the harness's scoring: any of the K epochs' tests over
    −2 ln α (χ²₂), direction unknown. ``draws``: (DRAWS, 2, K) standard normals
    (:func:`standard_draws`), shared so that P_D grows with the rate."""
    y = tests.y
    kk = len(y)
    z = draws if draws is not None else standard_draws(kk)
    if z.shape[2] < kk:
        raise ValueError(f"draws for {z.shape[2]} epochs; {kk} are needed")
    z = z[:, :, :kk]
    d = tests.d_unit
    mean = ramp_mps * d * d  # Σ y_i (ρ y_i) up to k: ρ d_k², before the division by d_k
    noise = np.cumsum(y[None, None, :] * z, axis=2)  # Σ y_i ε_i, per axis
    east = (mean[None, :] + noise[:, 0, :]) / d[None, :]
    north = noise[:, 1, :] / d[None, :]
    flagged = east * east + north * north > -2.0 * math.log(alpha)
    return float(np.mean(np.any(flagged, axis=1)))


def standard_draws(epochs: int, n: int = DRAWS, seed: int = DRAWS_SEED) -> np.ndarray:
    """(n, 2, epochs) standard normal draws, seeded: the same for every ramp scored."""
    return np.random.default_rng(seed).standard_normal((n, 2, epochs))
