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

Lock-in, and what breaks it (``track_jumps``: ours, not the paper's)
---------------------------------------------------------------------
The over-limit test compares the fix with the filter's prediction, so it is only as good as
the prediction. While faults go on, the filter coasts on the INS, ``P`` grows and the INS
drifts; after a few minutes a drift towards the fault makes a 100 m fault look like a
deviation, the filter takes it in, ``P`` collapses, and from then on the *good* fixes fail the
test: the filter is locked on the fault (measured on ``paper-continuous``, seed 3: 600 m off
at the end, 3-D RMS 284 m against 90 m without robust filtering). That test cannot tell "the
receiver jumped" from "the INS drifted"; the receiver's own recent history can.

:class:`JumpTracker` keeps the innovations ``ν = z − ẑ`` of the last n epochs (whatever the
gate did with them) and tests each fix's *increment* against the INS's increment:
``J = (ν_k − b) − mean_j (ν_j − b)``, with ``σ_J² = R (1 + 1/n)`` plus the growth of ``√S``
across the window (0 in steady state; the drift rate while the filter coasts), a jump when
``Σ J_i²/σ_Ji² > T2``. The trajectory cancels (turns do not look like jumps) and so does the
INS's accumulated drift: only its drift over n epochs remains, centimetres for position. The
receiver is healthy (``b = 0``) or faulted (offset ``b``):

- healthy → faulted: a component is over-limit *and* the fix jumped, in the direction of the
  innovation, by an amount that explains it (``Σ (ν − J)²/(S + σ_J²) ≤ T2``); ``b = J``;
- faulted: every fix is treated as over-limit whatever its zone (it does not become
  acceptable because the INS drifted towards it), except a component in the no-fault zone
  whose own offset ``b_i`` is not significant (``ReceiverState.axes``: a fault in east and
  north does not make a normal up value faulty, section 2.1): the paper's replacement,
  within its limit, then rejection. The receiver is healthy again when its fix is back on
  its own pre-fault track: the healthy hypothesis (``ν`` against the offset-corrected
  window, ``J + b``) is plausible (``≤ T2``) and fits better than the faulted one (``J``);
  the fit window restarts and the fix gets the ordinary three-zone treatment. This also ends
  at once a false onset (a 3.5σ noise outlier). Otherwise a jump moves ``b`` (the fault
  changed level). The INS's prediction is not consulted for the return: after minutes of
  coasting it is what cannot be trusted;
- healthy, over-limit, no jump, for ``max_replacements`` epochs in a row: the receiver agrees
  with its own history and the INS does not, so the INS drifted beyond its ``P``. The receiver
  is accepted again (FINDINGS: a limit of 3-5 consecutive replacements, then accept the
  receiver again and restart the window), the decision says ``readmit``, and the caller
  raises its covariance of that component so that ``S_ii = ν²`` (:meth:`fdi.insgnss.
  InsGnssFilter.update`) and the fix pulls the state back.

A fault moves the whole fix, so the INS/GNSS filter runs one tracker over E, N and U together
(χ²(3) thresholds; a 20 m fault on a 5 m-noise up axis is only seen reliably with the 100 m on
east and north) and passes its state to the three gates (``receiver``); a gate used alone
tracks its own component.

Alternatives measured and not taken: (a) re-admitting after N rejections alone (the last rule
without the jump test) follows a continuous 100 m fault from its 6th epoch: 3-D RMS 88 m on
seeds 1-5, no better than no robust filtering; (b) testing the raw fixes against a
least-squares fit of the previous raw fixes (INS-free, the same fixed weights): at 60 m/s in a
3°/s turn the straight-line extrapolation is 8 m off, false jumps moved ``b`` and cascaded
(seed 1 ended 70 m off). Not tried: (c) inflating ``P`` while coasting, which cannot help here:
a larger ``P`` makes the fault's slide into the deviation zone come earlier.
``track_jumps = false`` gives the paper's method alone. ``none`` and ``downweight`` never use
the tracker (they never discard a fix, so they cannot lock the receiver out).

The gate knows nothing of a filter's state layout: the caller gives the observation value,
its innovation, ``S_ii`` and ``R_ii``, and uses the returned value and variance (or drops the
component when the action is :attr:`Action.REJECT`), and, when ``readmit`` is set, raises its
covariance of that component so that ``S_ii ≥ ν²`` (see :meth:`fdi.insgnss.InsGnssFilter.update`).
Epochs are assumed equally spaced; call :meth:`ThreeZoneGate.reset` after a gap.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections import deque
from collections.abc import Sequence
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

    alpha1: float = field(default=0.10, metadata={
        "ge": 1e-15, "le": 0.5, "doc": "no-fault/deviation significance", "unit": "-"})
    alpha2: float = field(default=0.01, metadata={
        "ge": 1e-15, "le": 0.5, "doc": "deviation/over-limit significance", "unit": "-"})
    weight: WeightFunction = field(default="linear", metadata={"doc": "equivalent-weight function"})
    window: int = field(default=4, metadata={
        "ge": 2, "le": 32, "doc": "fit window n (epochs)", "unit": "epochs"})
    degree: int = field(default=1, metadata={
        "ge": 0, "le": 5, "doc": "fit polynomial degree", "unit": "-"})
    max_replacements: int = field(default=5, metadata={
        "ge": 1, "le": 1000, "doc": "consecutive replacements before the window restarts",
        "unit": "epochs"})
    track_jumps: bool = field(
        default=True,
        metadata={"doc": "lock-in breaker: test fixes against their own history (module doc)"},
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
    readmit: bool = False  # receiver accepted again: raise P so that S_ii >= ν²


@dataclass(frozen=True)
class ReceiverState:
    """What the jump tracker concluded about the receiver at this epoch."""

    faulted: bool = False  # judged faulty since a jump; its fixes are treated as over-limit
    returned: bool = False  # healthy again at this epoch after a fault: re-admit it
    jumped: bool = False  # the fix jumped against the receiver's own recent history
    ready: bool = False  # the history window was full (the jump test was made)
    # Per component: is its tracked fault offset significant on its own (``b_i²/σ_bi² ≥ T1``
    # of χ²(1))? Empty: every component is (the whole-fix verdict; callers that predate it).
    axes: tuple[bool, ...] = ()

    def component(self, i: int) -> ReceiverState:
        """The state as seen by component ``i``'s gate (``axes`` reduced to that component)."""
        if not self.axes:
            return self
        return dataclasses.replace(self, axes=(self.axes[i],))

    @property
    def axis_faulted(self) -> bool:
        """Faulted, and (for a one-component view) this component is part of the fault."""
        return self.faulted and all(self.axes)


class JumpTracker:
    """Lock-in breaker: tells "the receiver jumped" from "the INS drifted" (module docstring).

    Works on the ``dims`` components of one fix together (3 for an E/N/U position: a fault
    moves the whole fix, and a 20 m fault on a 5 m-noise up axis is only seen reliably together
    with the 100 m on east and north), with χ²(dims) thresholds at the gate's α1, α2. Inputs
    per component: innovation ν (observation minus the filter's prediction), its ``S_ii`` and
    ``R_ii``, and whether the gate's zone was over-limit.

    Test: ``J = (ν_k − b) − mean_j (ν_j − b)`` over the previous n epochs, i.e. the fix's
    increment minus the INS's increment, so neither the trajectory (turns) nor the INS's
    accumulated drift appears, only its drift over n epochs; ``σ_J² = R (1 + 1/n)`` plus the
    growth of ``√S`` across the window (0 in steady state, the drift rate while coasting);
    a jump when ``Σ J_i²/σ_Ji² > T2(dims)``.
    """

    def __init__(self, params: ThreeZoneParams, dims: int = 1) -> None:
        if dims < 1:
            raise ValueError(f"dims must be positive, got {dims}")
        self.dims = dims
        self.n = params.window
        self._t1 = chi2_ppf(1.0 - params.alpha1, dims)
        self._t2 = chi2_ppf(1.0 - params.alpha2, dims)
        self._t1_axis = params.t1  # χ²(1): is one component's offset significant on its own
        # (ν − b, S) per component, of the last n epochs whatever the gates did with them
        self._seq: deque[tuple[tuple[float, ...], tuple[float, ...]]] = deque(maxlen=self.n)
        self.faulted = False
        self.offset = (0.0,) * dims  # b: the receiver's tracked fault offset, units of z
        self.offset_var = (0.0,) * dims  # σ_b²
        self.fault_onsets = 0
        self.returns = 0
        self._axes = (False,) * dims

    def clear(self) -> None:
        """Forget the history (after the filter's state was corrected by a re-admission)."""
        self._seq.clear()

    def reset(self) -> None:
        """Forget the history and the fault state (after a gap in the epochs)."""
        self._seq.clear()
        self._set_healthy()

    def _set_healthy(self) -> None:
        self.faulted = False
        self.offset = (0.0,) * self.dims
        self.offset_var = (0.0,) * self.dims

    def update(
        self,
        nu: Sequence[float],
        s: Sequence[float],
        r: Sequence[float],
        over_limit: Sequence[bool],
    ) -> ReceiverState:
        """One epoch: update the fault state from the innovations of the fix's components."""
        dims = self.dims
        b, vb = self.offset, self.offset_var
        ready, jv, var_j = self._increment(nu, s, r)
        jumped = ready and _chi2(jv, var_j) > self._t2
        was_faulted = self.faulted
        if not was_faulted:
            if jumped and self._explains(nu, s, jv, var_j, over_limit):
                self.faulted = True
                self.offset, self.offset_var = tuple(jv), tuple(var_j)
                self.fault_onsets += 1
        elif ready and self._back_on_track(jv, var_j):
            # Back on its own pre-fault track: the fix is closer to the receiver's healthy
            # history (ν against the offset-corrected window) than to its faulted one (J).
            self._set_healthy()
        elif jumped:  # the fault changed level
            self.offset = tuple(b[i] + jv[i] for i in range(dims))
            self.offset_var = tuple(vb[i] + var_j[i] for i in range(dims))
        returned = was_faulted and not self.faulted
        if returned:
            self.returns += 1
            self._seq.clear()  # the filter is about to correct its state: a step in ν follows
        else:
            self._seq.append(
                (tuple(nu[i] - self.offset[i] for i in range(dims)), tuple(s[:dims]))
            )
        axes = self._fault_axes(was_faulted)
        return ReceiverState(self.faulted, returned, jumped, ready, axes)

    def _increment(self, nu: Sequence[float], s: Sequence[float], r: Sequence[float]
                   ) -> tuple[bool, list[float], list[float]]:
        """(ready, J, σ_J²) per component: J = (ν_k − b) − mean_j (ν_j − b) over a full window
        (0 until it is full), σ_J² = R (1 + 1/n) plus the growth of √S across the window."""
        n, dims, b = self.n, self.dims, self.offset
        ready = len(self._seq) == n
        jv = [0.0] * dims
        var_j = [ri * (1.0 + 1.0 / n) for ri in r]
        if ready:
            s_old = self._seq[0][1]
            for i in range(dims):
                jv[i] = (nu[i] - b[i]) - math.fsum(x[i] for x, _ in self._seq) / n
                var_j[i] += (math.sqrt(s[i]) - math.sqrt(s_old[i])) ** 2
        return ready, jv, var_j

    def _explains(self, nu: Sequence[float], s: Sequence[float], jv: Sequence[float],
                  var_j: Sequence[float], over_limit: Sequence[bool]) -> bool:
        """A jump is a fault's onset: some component is over-limit, the jump is in the
        direction of the innovation where it is, and what it leaves of the innovation is what
        the prediction's S allows."""
        dims = self.dims
        return (
            any(over_limit)
            and all(jv[i] * nu[i] > 0.0 for i in range(dims) if over_limit[i])
            and _chi2([nu[i] - jv[i] for i in range(dims)],
                      [s[i] + var_j[i] for i in range(dims)]) <= self._t2
        )

    def _back_on_track(self, jv: Sequence[float], var_j: Sequence[float]) -> bool:
        """The fix against the offset-corrected window passes, and better than against the
        faulted one."""
        b, vb, dims = self.offset, self.offset_var, self.dims
        h = _chi2([jv[i] + b[i] for i in range(dims)], [var_j[i] + vb[i] for i in range(dims)])
        return h <= self._t2 and h < _chi2(jv, var_j)

    def _fault_axes(self, was_faulted: bool) -> tuple[bool, ...]:
        """Per component: faulted, and its offset significant on its own (or it was)."""
        dims = self.dims
        prev = self._axes if was_faulted else (False,) * dims
        axes = tuple(
            self.faulted and (prev[i] or self.offset[i] ** 2 >= self._t1_axis * self.offset_var[i])
            for i in range(dims)
        )
        self._axes = axes
        return axes


def _chi2(x: Sequence[float], var: Sequence[float]) -> float:
    """Σ x_i² / var_i."""
    return math.fsum(a * a / v for a, v in zip(x, var, strict=True))


class ThreeZoneGate:
    """Per-component three-zone gate with a fit window (see the module docstring).

    ``strategy`` selects the treatment: ``"none"`` accepts everything (zones still counted),
    ``"downweight"`` down-weights deviation and over-limit, ``"replace"`` accepts deviation and
    replaces over-limit (the two-zone method with the fit), ``"three_zone"`` down-weights
    deviation and replaces over-limit. ``replace`` and ``three_zone`` use the lock-in breaker
    unless ``params.track_jumps`` is false: the gate's own one-component :class:`JumpTracker`,
    or the state of a tracker shared by the fix's components, passed as ``receiver``.

    Counters: ``zone_counts``, ``action_counts``, ``restarts`` (fit window restarted at the
    replacement limit), ``readmissions`` (receiver accepted again after a fault or a drift).
    """

    def __init__(self, params: ThreeZoneParams, strategy: Strategy = "three_zone") -> None:
        if strategy not in STRATEGIES:
            raise ValueError(f"unknown strategy {strategy!r}; expected one of {STRATEGIES}")
        self.params = params
        self.strategy: Strategy = strategy
        self._t1 = params.t1
        self._t2 = params.t2
        self._w = params.weights
        self.tracks_jumps = params.track_jumps and strategy in ("replace", "three_zone")
        self.tracker = JumpTracker(params, 1)
        self._hist: deque[tuple[float, float]] = deque(maxlen=params.window)
        self.consecutive = 0  # consecutive replacements (the paper's fits feeding fits)
        self.outliers = 0  # consecutive epochs not kept (replaced or rejected)
        self.zone_counts = dict.fromkeys(Zone, 0)
        self.action_counts = dict.fromkeys(Action, 0)
        self.restarts = 0
        self.readmissions = 0

    def reset(self) -> None:
        """Forget the window, the replacement count and the own tracker (after a gap)."""
        self._hist.clear()
        self.tracker.reset()
        self.consecutive = 0
        self.outliers = 0

    @property
    def window_full(self) -> bool:
        """Whether the history holds ``window`` accepted values (the fit is possible)."""
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
        receiver: ReceiverState | None = None,
    ) -> GateDecision:
        """Gate one component: observation ``z``, innovation ``nu = z − ẑ``, ``S_ii``, ``R_ii``.

        ``external`` = (value, variance) replaces the fit as the replacement of an over-limit
        observation (e.g. a grey-model prediction); the replacement limit applies to it too.
        ``receiver``: the state of a :class:`JumpTracker` shared by the fix's components
        (updated by the caller for this epoch); without it the gate tracks this component.
        """
        dm = detection_measure(nu, s)
        zone = classify(dm, self._t1, self._t2)
        self.zone_counts[zone] += 1
        strat = self.strategy
        if strat == "none" or (zone is Zone.DEVIATION and strat == "replace") or (
            zone is Zone.NO_FAULT and not self.tracks_jumps
        ):
            return self._keep(zone, Action.ACCEPT, dm, z, r)
        if strat == "downweight" or (zone is Zone.DEVIATION and not self.tracks_jumps):
            return self._downweight(zone, dm, z, r)
        if not self.tracks_jumps:
            return self._over_limit(zone, dm, z, nu, s, r, external)
        own = receiver is None
        if receiver is None:
            receiver = self.tracker.update((nu,), (s,), (r,), (zone is Zone.OVER_LIMIT,))
        if receiver.faulted and (zone is not Zone.NO_FAULT or receiver.axis_faulted):
            # The fault persists: whatever its zone, the fix is no better than at the onset
            # (the INS may have drifted towards it). A component in the no-fault zone whose own
            # fault offset is not significant (the fault is in the other components) follows
            # its own zone: the per-dimension test's point is that a fault in one component
            # does not make the normal ones faulty.
            return self._over_limit(zone, dm, z, nu, s, r, external)
        if receiver.returned:
            # Back on its own pre-fault track: healthy again; the fit window, which holds the
            # fault's replacements, restarts. The fix gets the ordinary treatment below.
            self._hist.clear()
            self.consecutive = 0
            self.outliers = 0
        elif (
            zone is Zone.OVER_LIMIT and receiver.ready and not receiver.jumped
            and self.outliers >= self.params.max_replacements
        ):
            # Over-limit for max_replacements epochs while consistent with its own history:
            # the INS, not the receiver, has drifted. Accept the receiver again.
            if own:
                self.tracker.clear()
            return self._readmit(zone, dm, z, r)
        if zone is Zone.NO_FAULT:
            return self._keep(zone, Action.ACCEPT, dm, z, r)
        if zone is Zone.DEVIATION:
            return self._downweight(zone, dm, z, r)
        return self._over_limit(zone, dm, z, nu, s, r, external)

    # ------------------------------------------------------------ treatments

    def _over_limit(
        self, zone: Zone, dm: float, z: float, nu: float, s: float, r: float,
        external: tuple[float, float] | None,
    ) -> GateDecision:
        """The paper's over-limit treatment: replace by the fit, within the limit."""
        self.outliers += 1
        if self.consecutive >= self.params.max_replacements:
            self.restarts += 1
            self._hist.clear()
            self.consecutive = 0
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

    def _downweight(self, zone: Zone, dm: float, z: float, r: float) -> GateDecision:
        lam = inflation_factor(dm, self._t1, self._t2, self.params.weight)
        if math.isinf(lam):  # IGG-III weight 0: discarded
            return self._reject(zone, dm, z)
        return self._keep(zone, Action.DOWNWEIGHT, dm, z, lam * r)

    def _readmit(self, zone: Zone, dm: float, z: float, r: float) -> GateDecision:
        """Accept the receiver again: restart the fit window with this fix; flag ``readmit``."""
        self.readmissions += 1
        self._hist.clear()
        self.consecutive = 0
        self.outliers = 0
        self._hist.append((z, r))
        self.action_counts[Action.ACCEPT] += 1
        return GateDecision(zone, Action.ACCEPT, dm, z, r, readmit=True)

    def _keep(self, zone: Zone, action: Action, dm: float, z: float, var: float) -> GateDecision:
        self.consecutive = 0
        self.outliers = 0
        self._hist.append((z, var))
        self.action_counts[action] += 1
        return GateDecision(zone, action, dm, z, var)

    def _reject(self, zone: Zone, dm: float, z: float) -> GateDecision:
        self.action_counts[Action.REJECT] += 1
        return GateDecision(zone, Action.REJECT, dm, z, math.inf)
