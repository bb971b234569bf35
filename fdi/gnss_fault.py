"""A persistent GNSS fault as a state: healthy / biased hypotheses on the position innovations.

Ours, not Cai & Shao's (their three zones and least-squares replacement are
:mod:`fdi.three_zone`). The design follows Willsky & Jones's generalised likelihood ratio for
jumps in linear systems (Automatica 12, 1976): a fault is a step ``b`` in the receiver's
position, ``z = p + b + v``, and the detector decides between two hypotheses on the evidence of
the innovations:

- **H0, healthy**: ``z = p + v``, innovation ``ν0 = z − p̂``, covariance ``S0 = P_pp + R``;
- **H1, biased**: ``z = p + b + v``, ``b`` a 3-vector state of the filter (a random walk,
  ``bias_rw_m_sqrt_s``), innovation ``ν1 = z − p̂ − b̂``, ``S1 = H1 P Hᵀ1 + R`` with
  ``H1 = [I 0 … I_b]`` (the filter's augmented covariance).

While H1 is believed the filter keeps ``b`` in its state: the receiver's absolute position goes
into ``b`` and the position comes from the INS (it coasts), while the receiver's *changes* of
position still correct the INS's velocity and attitude through the constant-bias model (a pure
coast would let them grow). :class:`fdi.insgnss.InsGnssFilter` does the filtering; this module
decides.

Onset (H0 → H1), the GLR of a step at the current epoch. A step of size ``b`` at epoch k makes
``ν_k ≈ b`` while the previous innovations are white: so the onset needs both

- the fix is over-limit against the prediction, ``ν0ᵀ S0⁻¹ ν0 > T_on`` with
  ``T_on = χ²₃(1 − α_on)``, and
- it *jumped* against the receiver's own previous ``window`` epochs, as seen through the
  INS: ``a = z − (p̂ − c)`` with ``c`` the filter's accumulated corrections (so ``p̂ − c`` is
  the INS as if never corrected, and the increments of ``a`` are the receiver's minus the
  INS's), ``J = a − median(a_j)``, ``Σ J_i² / σ_Ji² > T_on`` with ``σ_J²`` the fix's noise,
  the window's, and the INS's increment variance over the window
  (:meth:`GnssFaultMonitor.jump_statistic`).

The second condition is what tells a receiver's jump from an INS that drifted beyond ``P`` (its
innovations are offset too, but consistently: ``J`` is small), from an initial error outside
the prior, and from the filter's own correction after a fault it took in part (the innovation
then steps, ``a`` does not): no step, the fix is down-weighted and pulls the state back.
No onset while the history is empty (the first epoch); a return restarts the history with
the returning fix.

Only where coasting can pay: an onset needs the INS's prediction to be well inside the fix's
noise, ``P⁻_ii ≤ max_prior_ratio · R_ii`` on every axis (default a quarter: the INS's one-epoch
prediction at least twice as precise as the fix). Where the INS loses as much between two
fixes as the fix's own noise (``K ≈ 0.5``: the calibrated Table 2 regime of docs/insgnss.md)
the two hypotheses cannot be told apart after a few epochs of coasting: the bias absorbs
the INS's error and the filter holds a false fault (measured: 51 m 3-D RMS against 5.6 m for
down-weighting, seed 1); there the fix is only down-weighted.

Return (H1 → H0), by evidence: the log-likelihood ratio of the two hypotheses for this epoch,
``λ_k = ln N(ν0; 0, S0) − ln N(ν1; 0, S1)``, accumulated as a CUSUM ``Λ_k = max(0, Λ_{k−1} +
λ_k)`` (Page's test); the receiver is healthy again when ``Λ > return_log_lr`` (default
ln 10: the data are ten times likelier under H0) and H0 is plausible on its own
(``ν0ᵀ S0⁻¹ ν0 ≤ T_on``). A 100 m fault that ends gives ``λ`` in the thousands at once; a
false onset (a 3.5σ noise outlier) returns in one or two epochs (``λ ≈ 4`` each). No counter
and no timeout: a fault lasts as long as the evidence says.

Change of level (H1 → H1): neither hypothesis fits (``ν1ᵀ S1⁻¹ ν1 > T_on`` and no return): the
bias jumped again; the filter reopens ``b``'s covariance (``P_bb += σ_b0² I``) and keeps H1.

All quantities are in the observation's units (m, m²). The decisions are pure functions of the
numbers given, so the class is independent of the filter's layout.
"""

from __future__ import annotations

import enum
import math
from collections import deque

import numpy as np
import numpy.typing as npt

from fdi.insgnss_params import DIMS as DIMS  # re-exported
from fdi.insgnss_params import FaultStateParams as FaultStateParams  # re-exported

FloatArray = npt.NDArray[np.float64]


class Verdict(enum.Enum):
    """What the monitor decided for this epoch."""

    HEALTHY = "healthy"  # H0 holds: the ordinary update
    ONSET = "onset"  # H0 → H1: open the bias state, then update under H1
    FAULTED = "faulted"  # H1 holds: update under H1
    RELEVEL = "relevel"  # H1, but the bias moved: reopen its covariance, update under H1
    RETURN = "return"  # H1 → H0: drop the bias state, then the ordinary update


def log_likelihood(nu: FloatArray, s: FloatArray) -> float:
    """ln N(ν; 0, S) for a k-vector ν and its k×k covariance S."""
    sign, logdet = np.linalg.slogdet(s)
    if sign <= 0:
        return -math.inf
    k = nu.shape[0]
    return -0.5 * (float(nu @ np.linalg.solve(s, nu)) + logdet + k * math.log(2.0 * math.pi))


def mahalanobis2(nu: FloatArray, s: FloatArray) -> float:
    """νᵀ S⁻¹ ν."""
    return float(nu @ np.linalg.solve(s, nu))


class GnssFaultMonitor:
    """The two-hypothesis decision of the module docstring, one call per GNSS epoch.

    Counters: ``onsets``, ``returns``, ``relevels``; ``log_lr`` is the running CUSUM ``Λ``.
    """

    def __init__(self, params: FaultStateParams) -> None:
        self.params = params
        self._t_on = params.t_onset
        self._hist: deque[tuple[FloatArray, FloatArray]] = deque(maxlen=params.window)
        self.faulted = False
        self.log_lr = 0.0
        self.onsets = 0
        self.returns = 0
        self.relevels = 0

    def reset(self) -> None:
        """Forget the history and the fault state (after a gap in the epochs)."""
        self._hist.clear()
        self.faulted = False
        self.log_lr = 0.0

    def jump_statistic(self, a: FloatArray, var_inc: FloatArray) -> float | None:
        """``Σ J_i² / σ_Ji²`` of the step test, None without history.

        ``a``: the receiver's position minus the *uncorrected* INS trajectory (the INS with the
        filter's corrections since the start taken back out, see
        :meth:`fdi.insgnss.InsGnssFilter.update`): its increments are the receiver's
        increments minus the INS's, so a step in ``a`` is the receiver's own, never the
        filter's correction of an earlier fix. ``J = a − median(a_j)`` over the history (the
        median: one earlier fault in the window does not move it),
        ``σ_J² = var_inc + 1.25 R_i/m`` (the window's noise; 1.25: the median's efficiency
        loss, rounded up); ``var_inc`` = this fix's ``R_i`` plus the INS's own increment
        variance over the window.
        """
        m = len(self._hist)
        if m == 0:
            return None
        hist = np.array([h for h, _ in self._hist])
        r_mean = np.mean([v for _, v in self._hist], axis=0)
        j = a - np.median(hist, axis=0)
        return float(np.sum(j * j / (var_inc + 1.25 * r_mean / m)))

    def healthy_epoch(
        self, nu0: FloatArray, s0: FloatArray, a: FloatArray, r: FloatArray,
        var_inc: FloatArray, *, beyond_model: bool = False,
    ) -> Verdict:
        """H0 held up to now: test for an onset at this epoch.

        ``nu0``, ``s0``: the position innovation and its 3×3 covariance; ``a``: the receiver
        minus the uncorrected INS (:meth:`jump_statistic`), ``r`` the fix's noise variances,
        ``var_inc`` (per component) ``R_i`` plus the INS's increment variance over the window.
        ``beyond_model``: the receiver walked away from its own model (the walk test of
        :meth:`fdi.insgnss.InsGnssFilter._walk_step`, with the receiver's correlated error
        modelled): an onset whatever the step test says.
        """
        onset = beyond_model
        can_coast = bool(np.all(np.diag(s0) - r <= self.params.max_prior_ratio * r))
        if not onset and can_coast and mahalanobis2(nu0, s0) > self._t_on:
            g = self.jump_statistic(a, var_inc)
            onset = g is not None and g > self._t_on
        if onset:
            self.faulted = True
            self.log_lr = 0.0
            self.onsets += 1
            return Verdict.ONSET
        self._hist.append((a.copy(), r.copy()))
        return Verdict.HEALTHY

    def faulted_epoch(
        self, nu0: FloatArray, s0: FloatArray, nu1: FloatArray, s1: FloatArray,
        a: FloatArray, r: FloatArray,
    ) -> Verdict:
        """H1 is believed: accumulate the evidence for H0 and decide (return / relevel / stay).

        ``nu1``, ``s1``: the innovation and covariance under H1; ``a``, ``r`` as in
        :meth:`healthy_epoch` (they restart the history at a return)."""
        lam = log_likelihood(nu0, s0) - log_likelihood(nu1, s1)
        self.log_lr = max(0.0, self.log_lr + lam)
        plausible0 = mahalanobis2(nu0, s0) <= self._t_on
        if self.log_lr > self.params.return_log_lr and plausible0:
            self.faulted = False
            self.log_lr = 0.0
            self.returns += 1
            # the history restarts with this epoch's innovation: the healthy state it is
            # judged against is the one the filter carried through the fault
            self._hist.clear()
            self._hist.append((a.copy(), r.copy()))
            return Verdict.RETURN
        if mahalanobis2(nu1, s1) > self._t_on and not plausible0:
            self.relevels += 1
            return Verdict.RELEVEL
        return Verdict.FAULTED
