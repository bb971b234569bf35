"""A second, independent witness of the compass: the yaw-rate gyro (an extension of the paper).

Zhu, Chen & Liu (2009) detect a compass fault from the command FIR alone (eq. (3)-(12)); the FIR
sees a drift's onset only, and its dead reckoning drifts (~0.7 deg/s, ``FINDINGS.md``). With a
yaw-rate gyro the compass's heading increments can be checked against the integrated rate,
whose drift is the gyro's bias error (~0.01 deg/s once estimated). Per period (``dt`` s):

* propagation: ``psi^-(k) = psi(k-1) + (r(k) - b(k-1)) dt`` (r the gyro, deg/s; b its bias);
* innovation: ``nu(k) = wrap(y(k) - psi^-(k))`` (y the compass, deg);
* while the compass is trusted, a second-order (heading + bias) complementary loop on the
  innovation clipped at ``clip`` sigmas: ``psi = psi^- + alpha nu``, ``b = b - beta nu / dt``.
  During the warm-up the gains are those of the growing-memory least-squares line fit
  (``alpha_n = 2 (2n - 1) / (n (n + 1))``, ``beta_n = 6 / (n (n + 1))``: the bias is the fitted
  slope of compass minus integrated rate); afterwards a slow critically damped loop at
  ``omega_min`` (``alpha = 2 omega dt``, ``beta = (omega dt)^2``), so that a slow compass drift
  is not absorbed as gyro bias;
* the change test, in sigmas of the innovation: ``s = clip(nu / sigma, +-clip)``, a two-sided
  CUSUM ``g+ = max(0, g+ + s - kappa)``, ``g- = max(0, g- - s - kappa)``; ``sigma`` is a robust
  running estimate (:class:`fdi.noise_scale.RobustVariance`) frozen while a fault is suspected.
  A fault is *suspected* when ``max(g) > h_suspect`` or ``|s| >= jump_sigmas`` (the loop, the bias
  and sigma are then frozen, and ``psi`` is pure gyro dead reckoning), *confirmed* when
  ``max(g) >= h``, *dismissed* when ``g`` returns to 0. Because ``h > 3 (clip - kappa)``, a spike
  of 1 to 3 samples cannot confirm, whatever its size;
* a noise burst: the short trimmed scale of the innovation's first differences
  (:class:`fdi.noise_scale.TrimmedScale`) above ``burst_ratio`` times sigma blocks confirmation
  and resets the CUSUM (the compass is noisy, not biased; ``psi`` carries the heading meanwhile);
* after a confirmed fault, the compass is taken back when ``|nu| <= max(recover_gate, 3 sigma)``
  for ``recover_samples`` periods in a row while it is not repeating itself (the caller says so).

The heading to use is ``psi`` at every step: the filtered compass when it is trusted, the gyro
dead reckoning from the last trusted state when it is not, so switching is bumpless.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fdi.noise_scale import RobustVariance, TrimmedScale


def _wrap180(a: float) -> float:
    a = math.fmod(a + 180.0, 360.0)
    if a <= 0.0:
        a += 360.0
    return a - 180.0


@dataclass(frozen=True)
class WitnessParams:
    """The witness's parameters (the ``gyro_*`` keys of the ``[ft]`` table)."""

    omega_min: float = 0.02  # rad/s, the slow loop
    sigma0_deg: float = 1.0  # initial innovation sigma
    sigma_min_deg: float = 0.2  # floor of sigma
    sigma_samples: int = 150  # EWMA length of sigma^2
    clip: float = 4.0  # score clip, sigmas
    kappa: float = 1.0  # CUSUM drift, sigmas
    h: float = 11.0  # CUSUM confirmation level (> 3 (clip - kappa))
    h_suspect: float = 3.0
    jump_sigmas: float = 4.0
    burst_ratio: float = 2.5
    warmup_samples: int = 100
    recover_gate_deg: float = 1.5
    recover_samples: int = 10


@dataclass(frozen=True)
class WitnessStep:
    """What the witness concluded at step k."""

    psi: float  # heading to use (unwrapped), deg
    nu: float  # innovation, deg
    score: float  # CUSUM max(g+, g-), sigmas
    sigma: float  # innovation sigma, deg
    suspect: bool
    confirmed: bool  # edge
    dismissed: bool  # edge
    recovered: bool  # edge
    burst: bool


class GyroWitness:
    """Compass against the integrated yaw rate (module docstring)."""

    def __init__(self, p: WitnessParams) -> None:
        self.p = p
        self.psi: float | None = None  # unwrapped heading estimate, deg
        self.bias = 0.0  # deg/s
        self.var = RobustVariance(p.sigma0_deg**2, p.sigma_samples, p.clip, p.sigma_min_deg**2)
        self.short = TrimmedScale(10, 2)
        self.g_pos = 0.0
        self.g_neg = 0.0
        self.k = 0  # steps with a compass reading since start
        self.t = 0.0  # s since start
        self.suspect = False
        self.fault = False
        self._ok = 0

    @property
    def ready(self) -> bool:
        return self.psi is not None

    def propagate(self, rate_dps: float, dt: float) -> None:
        """Advance ``psi`` by the gyro over the period (no compass needed)."""
        if self.psi is not None:
            self.psi += (rate_dps - self.bias) * dt
        self.t += dt

    def reset(self, heading_deg: float) -> None:
        self.psi = heading_deg
        self.short.restart()

    def update(self, y_deg: float, dt: float, repeating: bool = False) -> WitnessStep:
        """The compass reading of this period (after :meth:`propagate`)."""
        p = self.p
        if self.psi is None:
            self.psi = y_deg
            return WitnessStep(y_deg, 0.0, 0.0, self.var.sigma, False, False, False, False,
                               False)
        nu = _wrap180(y_deg - self.psi)
        self.short.push(nu)
        sigma = self.var.sigma
        confirmed = dismissed = recovered = burst = False
        self.k += 1
        if self.k <= p.warmup_samples:
            self._correct(nu, dt, self.k + 1)
            self.var.update(nu, alpha=max(self.var.alpha, 1.0 / self.k))
            return WitnessStep(self.psi, nu, 0.0, sigma, False, False, False, False, False)
        s = max(-p.clip, min(p.clip, nu / sigma))
        if self.fault:
            # Recovery: the compass agrees with the dead reckoning again, and is alive.
            gate = max(p.recover_gate_deg, 3.0 * sigma)
            self._ok = self._ok + 1 if abs(nu) <= gate and not repeating else 0
            if self._ok >= p.recover_samples:
                self.fault = self.suspect = False
                self.g_pos = self.g_neg = 0.0
                self.var.frozen = False
                self._ok = 0
                recovered = True
            return WitnessStep(self.psi, nu, 0.0, sigma, self.suspect, False, False, recovered,
                               False)
        self.g_pos = max(0.0, self.g_pos + s - p.kappa)
        self.g_neg = max(0.0, self.g_neg - s - p.kappa)
        g = max(self.g_pos, self.g_neg)
        ss = self.short.sigma
        if self.short.full and ss > p.burst_ratio * sigma:
            burst = True
            self.g_pos = self.g_neg = 0.0
            g = 0.0
        was = self.suspect
        if g >= p.h:
            confirmed = True
            self.fault = True
            self.suspect = True
        elif g > p.h_suspect or abs(s) >= p.jump_sigmas or burst:
            self.suspect = True
        elif was and g == 0.0:
            self.suspect = False
            dismissed = True
        elif not was:
            self.suspect = False
        self.var.frozen = self.suspect
        if not self.suspect:
            self._correct(nu, dt, 0)
            self.var.update(nu)
        return WitnessStep(self.psi, nu, g, sigma, self.suspect, confirmed, dismissed, False,
                           burst)

    def _correct(self, nu: float, dt: float, n: int) -> None:
        """Heading + bias loop; ``n`` > 0: the n-th sample of the least-squares warm-up."""
        assert self.psi is not None
        wdt = self.p.omega_min * dt
        alpha, beta = 2.0 * wdt, wdt * wdt
        if n >= 2:
            alpha = max(alpha, 2.0 * (2 * n - 1) / (n * (n + 1)))
            beta = max(beta, 6.0 / (n * (n + 1)))
        lim = self.p.clip * self.var.sigma
        if n > 10:  # Huber: an outlier moves the estimate by a bounded amount
            nu = max(-lim, min(lim, nu))
        self.psi += alpha * nu
        self.bias -= beta * nu / dt
