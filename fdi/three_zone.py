"""Three-zone chi-square gate with least-squares-fit replacement, per observation component.

Cai Baojie & Shao Lei, "three-segment discrimination domain" fault detection and
least-squares-fitting robust filter for integrated navigation. The paper's numbered equations
were lost in extraction; the meaning below follows its text and standard practice.

For one scalar component i of a Kalman innovation ν (units of the observation, e.g. m):

- eq. (7)–(8), per-dimension test: ``DM(i) = ν_i² / S_ii`` with ``S = H P⁻ Hᵀ + R`` the
  innovation covariance; under H0 (no fault) ``DM(i) ~ χ²(1)``;
- zones: ``DM < T1`` no fault, ``T1 ≤ DM ≤ T2`` deviation, ``DM > T2`` over-limit, with
  ``T1 = χ²₁(1 − α1)`` (α1 = 0.10 → 2.7055) and ``T2 = χ²₁(1 − α2)`` (α2 = 0.01 → 6.6349),
  computed from α by :func:`fdi.chi2.chi2_ppf`;
- deviation: the observation is kept and its noise variance inflated, ``R'_ii = λ · R_ii``,
  by an equivalent-weight function (:func:`inflation_factor`): ``"linear"``,
  ``λ = DM/T1`` (Yang's variance-inflation form: it makes the standardised residual of the
  inflated observation about T1), or ``"igg3"``, the IGG-III weight
  ``w = (k0/|v|)·((k1 − |v|)/(k1 − k0))²`` with ``v = √DM``, ``k0 = √T1``, ``k1 = √T2``,
  ``λ = 1/w`` (λ → ∞ at the over-limit boundary);
- over-limit: the observation is discarded and replaced by the one-step extrapolation of a
  least-squares polynomial (degree d, default 1) fitted to the previous n (= 4) values of the
  component. The extrapolation is a fixed weighted sum ``ẑ_k = Σ_j w_j z_{k−n+j}`` (weights
  from :func:`extrapolation_weights`, computed once in exact rational arithmetic), and its
  variance is the fit's noise gain applied to the window's variances, ``Σ_j w_j² σ_j²``
  (``1.5 R_ii`` for degree 1 when the window holds ordinary fixes). Replaced values feed later
  fits; after ``max_replacements`` consecutive replacements the gate stops replacing, discards
  the observation and restarts its window (FINDINGS: degree 2 diverges when fits feed fits,
  degree 1 with a limit does not). An over-limit observation is also discarded without
  replacement while the window is not full, and when the replacement itself fails the
  over-limit test against the same prediction (a fit across a jump extrapolates a slope that
  is no better than the fault).

The gate knows nothing of a filter's state layout: the caller gives the observation value,
its innovation, ``S_ii`` and ``R_ii``, and uses the returned value and variance (or drops the
component when the action is :attr:`Action.REJECT`). Epochs are assumed equally spaced; call
:meth:`ThreeZoneGate.reset` after a gap.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass, field
from fractions import Fraction
from functools import cached_property, lru_cache
from typing import Literal

from fdi.chi2 import chi2_ppf

Strategy = Literal["none", "downweight", "replace", "three_zone"]
WeightFunction = Literal["linear", "igg3"]
STRATEGIES: tuple[Strategy, ...] = ("none", "downweight", "replace", "three_zone")


class Zone(enum.IntEnum):
    """The three discrimination zones of the per-dimension test."""

    NO_FAULT = 0
    DEVIATION = 1
    OVER_LIMIT = 2


class Action(enum.Enum):
    """What the gate did with an observation component."""

    ACCEPT = "accept"  # used as is, variance R_ii
    DOWNWEIGHT = "downweight"  # used, variance λ·R_ii
    REPLACE = "replace"  # replaced by the fit's extrapolation, variance Σw²σ²
    REJECT = "reject"  # discarded, no replacement available (window short or limit reached)


@dataclass(frozen=True)
class ThreeZoneParams:
    """Parameters of the three-zone gate (the paper's: α1 = 0.10, α2 = 0.01, n = 4)."""

    alpha1: float = field(
        default=0.10, metadata={"gt": 0.0, "lt": 1.0, "doc": "no-fault/deviation significance"}
    )
    alpha2: float = field(
        default=0.01, metadata={"gt": 0.0, "lt": 1.0, "doc": "deviation/over-limit significance"}
    )
    weight: WeightFunction = field(default="linear", metadata={"doc": "equivalent-weight function"})
    window: int = field(default=4, metadata={"ge": 2, "le": 32, "doc": "fit window n (epochs)"})
    degree: int = field(default=1, metadata={"ge": 0, "le": 5, "doc": "fit polynomial degree"})
    max_replacements: int = field(
        default=5, metadata={"ge": 1, "doc": "consecutive replacements before the window restarts"}
    )

    def __post_init__(self) -> None:
        if not self.alpha2 < self.alpha1:
            raise ValueError(f"alpha2 ({self.alpha2}) must be below alpha1 ({self.alpha1})")
        if not self.degree < self.window:
            raise ValueError(f"degree ({self.degree}) must be below window ({self.window})")

    @cached_property
    def t1(self) -> float:
        """T1 = χ²₁(1 − α1), eq. (7): no-fault / deviation threshold."""
        return chi2_ppf(1.0 - self.alpha1, 1)

    @cached_property
    def t2(self) -> float:
        """T2 = χ²₁(1 − α2), eq. (7): deviation / over-limit threshold."""
        return chi2_ppf(1.0 - self.alpha2, 1)

    @cached_property
    def weights(self) -> tuple[float, ...]:
        """One-step extrapolation weights of the fit, oldest sample first."""
        return extrapolation_weights(self.window, self.degree)

    @cached_property
    def noise_gain(self) -> float:
        """Σ w² of :attr:`weights`: variance of the extrapolation of i.i.d. unit samples."""
        return noise_gain(self.weights)


def detection_measure(nu: float, s: float) -> float:
    """DM(i) = ν_i² / S_ii, eq. (8). ``s`` must be positive."""
    return nu * nu / s


def classify(dm: float, t1: float, t2: float) -> Zone:
    """Zone of a per-dimension detection measure: [0, T1) / [T1, T2] / (T2, ∞)."""
    if dm < t1:
        return Zone.NO_FAULT
    if dm <= t2:
        return Zone.DEVIATION
    return Zone.OVER_LIMIT


def inflation_factor(dm: float, t1: float, t2: float, kind: WeightFunction = "linear") -> float:
    """Variance inflation λ = 1/w of the equivalent-weight function (1 below T1).

    ``linear``: λ = DM/T1, unbounded, so it also serves as a down-weighting of over-limit
    observations. ``igg3``: λ = 1/w with the IGG-III weight on ``v = √DM`` between ``k0 = √T1``
    and ``k1 = √T2``; λ = inf at and above T2 (weight 0: the observation is discarded).
    """
    if dm <= t1:
        return 1.0
    if kind == "linear":
        return dm / t1
    k0, k1, v = math.sqrt(t1), math.sqrt(t2), math.sqrt(dm)
    if v >= k1:
        return math.inf
    w = (k0 / v) * ((k1 - v) / (k1 - k0)) ** 2
    return 1.0 / w


@lru_cache(maxsize=64)
def extrapolation_weights(n: int, degree: int) -> tuple[float, ...]:
    """Weights w (oldest first) with ``Σ w_j y_j`` = the degree-d least-squares polynomial
    through ``(j, y_j), j = 0..n−1``, evaluated at ``j = n`` (one step ahead).

    Closed form ``wᵀ = eᵀ (AᵀA)⁻¹ Aᵀ`` with A the n×(d+1) Vandermonde matrix of j and
    ``e = (1, n, n², …)``, solved once in exact rationals. n = 4: degree 1 → [−1/2, 0, 1/2, 1],
    degree 2 → [3/4, −5/4, −3/4, 9/4], degree 3 → [−1, 4, −6, 4].
    """
    if n < 1 or degree < 0 or degree >= n:
        raise ValueError(f"need 0 <= degree < n, got n={n}, degree={degree}")
    m = degree + 1
    a = [[Fraction(j) ** k for k in range(m)] for j in range(n)]
    # Normal matrix M = AᵀA and right-hand side e; solve M y = e by Gauss-Jordan elimination.
    mat = [[sum((a[j][r] * a[j][c] for j in range(n)), Fraction(0)) for c in range(m)]
           for r in range(m)]
    rhs = [Fraction(n) ** k for k in range(m)]
    for col in range(m):
        piv = next(r for r in range(col, m) if mat[r][col] != 0)
        mat[col], mat[piv] = mat[piv], mat[col]
        rhs[col], rhs[piv] = rhs[piv], rhs[col]
        inv = 1 / mat[col][col]
        mat[col] = [x * inv for x in mat[col]]
        rhs[col] *= inv
        for r in range(m):
            if r != col and mat[r][col] != 0:
                f = mat[r][col]
                mat[r] = [x - f * y for x, y in zip(mat[r], mat[col], strict=True)]
                rhs[r] -= f * rhs[col]
    return tuple(float(sum((a[j][k] * rhs[k] for k in range(m)), Fraction(0))) for j in range(n))


def noise_gain(weights: tuple[float, ...]) -> float:
    """Σ w²: the variance of the extrapolation when the samples are i.i.d. with unit variance."""
    return math.fsum(w * w for w in weights)


@dataclass(frozen=True)
class GateDecision:
    """Outcome for one component: the zone, the action and what the update should use."""

    zone: Zone
    action: Action
    dm: float
    value: float  # observation value to use (raw, or the replacement)
    variance: float  # its noise variance (R_ii, λR_ii, the fit's variance; inf when rejected)


class ThreeZoneGate:
    """Per-component three-zone gate with a fit window (see the module docstring).

    ``strategy`` selects the treatment: ``"none"`` accepts everything (zones still counted),
    ``"downweight"`` down-weights deviation and over-limit, ``"replace"`` accepts deviation and
    replaces over-limit (the two-zone method with the fit), ``"three_zone"`` down-weights
    deviation and replaces over-limit.
    """

    def __init__(self, params: ThreeZoneParams, strategy: Strategy = "three_zone") -> None:
        if strategy not in STRATEGIES:
            raise ValueError(f"unknown strategy {strategy!r}; expected one of {STRATEGIES}")
        self.params = params
        self.strategy: Strategy = strategy
        self._t1 = params.t1
        self._t2 = params.t2
        self._w = params.weights
        self._hist: deque[tuple[float, float]] = deque(maxlen=params.window)
        self.consecutive = 0
        self.zone_counts = dict.fromkeys(Zone, 0)
        self.action_counts = dict.fromkeys(Action, 0)
        self.restarts = 0

    def reset(self) -> None:
        """Forget the window and the replacement count (after a gap in the epochs)."""
        self._hist.clear()
        self.consecutive = 0

    @property
    def window_full(self) -> bool:
        return len(self._hist) == self.params.window

    def fit(self) -> tuple[float, float] | None:
        """(value, variance) of the one-step extrapolation, or None while the window is short."""
        if not self.window_full:
            return None
        value = math.fsum(w * z for w, (z, _) in zip(self._w, self._hist, strict=True))
        var = math.fsum(w * w * v for w, (_, v) in zip(self._w, self._hist, strict=True))
        return value, var

    def step(
        self,
        z: float,
        nu: float,
        s: float,
        r: float,
        external: tuple[float, float] | None = None,
    ) -> GateDecision:
        """Gate one component: observation ``z``, innovation ``nu = z − ẑ``, ``S_ii``, ``R_ii``.

        ``external`` = (value, variance) replaces the fit as the replacement of an over-limit
        observation (e.g. a grey-model prediction); the replacement limit applies to it too.
        """
        dm = detection_measure(nu, s)
        zone = classify(dm, self._t1, self._t2)
        self.zone_counts[zone] += 1
        strat = self.strategy
        if strat == "none" or zone is Zone.NO_FAULT or (
            zone is Zone.DEVIATION and strat == "replace"
        ):
            return self._keep(zone, Action.ACCEPT, dm, z, r)
        if zone is Zone.DEVIATION or strat == "downweight":
            lam = inflation_factor(dm, self._t1, self._t2, self.params.weight)
            if math.isinf(lam):  # IGG-III weight 0: discarded
                return self._reject(zone, dm, z)
            return self._keep(zone, Action.DOWNWEIGHT, dm, z, lam * r)
        # Over-limit, strategy replace or three_zone.
        if self.consecutive >= self.params.max_replacements:
            self.restarts += 1
            self.reset()
            return self._reject(zone, dm, z)
        rep = external if external is not None else self.fit()
        # The replacement is an observation too: if the test would call it over-limit against
        # the same prediction (ẑ = z − ν, S' = S − R + σ²_rep), it is no better than the fault.
        if rep is None or detection_measure(rep[0] - (z - nu), s - r + rep[1]) > self._t2:
            return self._reject(zone, dm, z)
        self.consecutive += 1
        self._hist.append(rep)
        self.action_counts[Action.REPLACE] += 1
        return GateDecision(zone, Action.REPLACE, dm, rep[0], rep[1])

    def _keep(self, zone: Zone, action: Action, dm: float, z: float, var: float) -> GateDecision:
        self.consecutive = 0
        self._hist.append((z, var))
        self.action_counts[action] += 1
        return GateDecision(zone, action, dm, z, var)

    def _reject(self, zone: Zone, dm: float, z: float) -> GateDecision:
        self.action_counts[Action.REJECT] += 1
        return GateDecision(zone, Action.REJECT, dm, z, math.inf)
