"""Adaptive FIR trained by LMS, and the dual-criterion compass fault detector.

Zhu, Chen & Liu (2009), "Sensor fault diagnosis and fault-tolerant control method of underwater
vehicles", Control and Decision 24(9):1335-1339, eq. (3)-(5) (the FIR and its LMS training),
(7) (criterion 1, e^2 > theta) and (8)-(12) (criterion 2, the weight-drift SNR R(k) > n0).

Units and shapes. Each call of :meth:`DualCriterionDetector.step` is one control period
(0.2 s on the Outland 1000). ``u`` is the yaw command that was *sent* during the previous period
(differential thrust, %, -100..100); ``y`` is the compass heading in degrees, unwrapped by the
caller or not (increments are wrapped to (-180, 180] here). The FIR has ``M`` input taps
u(k-1) ... u(k-M) (strictly causal: the command of step k is computed from the reading of step k,
so u(k) would let the filter read the sensor back through the controller and hide a fault), plus
an optional bias tap (constant input 1) that absorbs a steady current. Inputs are scaled to
(u - u_op) / u_scale so that |x| <= 1 and mu = 0.01 is inside the LMS stability bound
(mu < 1 / tr(R) = 1 / (M + 1)). The filter predicts the heading *increment* y(k) - y(k-1) in units
of deg / y_scale (an FIR cannot represent the yaw integrator when asked for absolute heading).
e^2 is reported in deg^2. The weight vector C_k has shape (M,) or (M + 1,) with the bias last.

Extensions in the default preset (each off in ``config/rov-paper.toml``): theta of eq. (7) is
raised to ``(theta_sigmas * sigma_e)^2`` with sigma_e a robust running scale of e
(:class:`fdi.noise_scale.RobustVariance`, frozen while a suspect is open), so that a noisier
compass does not raise suspects; and criterion 2 confirms only if the residual mean since the
suspect is ``mean_sigmas`` standard errors from 0 and the short scale of e shows no noise burst
(R(k) of eq. (11) is scale-free: any persisting weight change fires it, e.g. the LMS adapting to
a turn on a non-linear plant).

Measured traps this design avoids are listed in ``../shared/FINDINGS.md`` ("Adaptive FIR with
LMS"). Plain Python floats with a doubled ring buffer and running sums: one step costs a few
microseconds (see ``firmware_host.devtools.sim_rov.bench_rov_step``).
"""

from __future__ import annotations

import math
import operator
from collections import deque
from dataclasses import dataclass, field

from fdi.noise_scale import RobustVariance, TrimmedScale


@dataclass(frozen=True)
class DetectorConfig:
    """Parameters of the FIR, LMS and both criteria (the ``[detector]`` table)."""

    order: int = field(default=70, metadata={
        "ge": 1, "le": 1000, "doc": "M, FIR taps", "unit": "taps"})
    mu: float = field(default=0.01, metadata={"gt": 0.0, "lt": 1.0, "doc": "LMS step", "unit": "-"})
    bias_tap: bool = field(default=True, metadata={
        "doc": "the FIR has a constant tap (learns a steady offset between command and heading "
               "change)"})
    u_op: float = field(default=0.0, metadata={
        "doc": "operating point of u, %", "ge": -100.0, "le": 100.0, "unit": "%"})
    u_op_samples: int = field(default=50, metadata={
        "ge": 0, "doc": "EMA of u_op, 0: fixed", "unit": "samples"})
    u_scale: float = field(default=100.0, metadata={
        "gt": 0.0, "doc": "% per unit input", "unit": "%"})
    y_scale: float = field(default=30.0, metadata={
        "gt": 0.0, "doc": "deg per unit output", "unit": "deg"})
    theta_deg2: float = field(default=9.0, metadata={
        "gt": 0.0, "doc": "theta of eq. (7)", "unit": "deg^2"})
    snr_window: int = field(default=50, metadata={
        "ge": 3, "doc": "n of eq. (8)-(11), samples", "unit": "samples"})
    n0: float = field(default=4.0, metadata={"gt": 0.0, "doc": "n0 of eq. (12)", "unit": "-"})
    persist: int = field(default=4, metadata={
        "ge": 1, "doc": "samples R > n0 in a row", "unit": "samples"})
    confirm_window: int = field(default=5, metadata={
        "ge": 1, "doc": "samples after suspect", "unit": "samples"})
    warmup_samples: int = field(default=100, metadata={
        "ge": 0, "doc": "train only, no check", "unit": "samples"})
    store_average_samples: int = field(default=50, metadata={
        "ge": 0, "doc": "0: C_k itself", "unit": "samples"})
    # Thresholds that follow the noise (extensions; 0 disables each, as in the paper preset).
    theta_sigmas: float = field(default=4.0, metadata={
        "ge": 0.0, "doc": "theta = max(theta_deg2, (theta_sigmas * sigma_e)^2)", "unit": "σ"})
    sigma_samples: int = field(default=150, metadata={
        "ge": 1, "doc": "EWMA length of sigma_e^2", "unit": "samples"})
    mean_sigmas: float = field(default=3.0, metadata={
        "ge": 0.0, "doc": "confirm only if |mean e| since the suspect >= this * sigma_e/sqrt(n)",
        "unit": "σ"})
    burst_ratio: float = field(default=0.0, metadata={
        "ge": 0.0, "doc": "no confirmation while the short scale of e > this * sigma_e",
        "unit": "-"})

    def __post_init__(self) -> None:
        if self.persist > self.confirm_window:
            raise ValueError("persist must be <= confirm_window")


def wrap180(angle_deg: float) -> float:
    """Wrap an angle to (-180, 180] degrees."""
    a = math.fmod(angle_deg + 180.0, 360.0)
    if a <= 0.0:
        a += 360.0
    return a - 180.0


class AdaptiveFir:
    """FIR of eq. (3) trained by LMS, eq. (5), on scaled, strictly causal inputs.

    ``push(u)`` appends the command of the period that just ended; ``predict()`` is d(k) of
    eq. (3) in output units; ``train(e)`` applies eq. (5) with e in output units.
    """

    def __init__(
        self,
        order: int,
        mu: float,
        bias_tap: bool,
        u_op: float,
        u_scale: float,
        u_op_samples: int = 0,
    ) -> None:
        self.M = order
        self.u_op_alpha = 1.0 / u_op_samples if u_op_samples else 0.0
        self.track_op = u_op_samples > 0
        self.mu = mu
        self.bias_tap = bias_tap
        self.u_op = u_op
        self.u_scale = u_scale
        n = order + (1 if bias_tap else 0)
        # C_k: weights; with a bias tap its weight is the last one and its input is always 1.
        self.C: list[float] = [0.0] * n
        # Doubled ring buffer: x = buf[pos:pos + M] is [u(k-1), ..., u(k-M)] (newest first).
        self._buf: list[float] = [0.0] * (2 * order + 1)
        self._pos = order
        self._x_sum = 0.0  # sum of the input taps (running)
        self.w_sum = 0.0  # sum_i C_i (running), the quantity of eq. (9)
        self.avg_alpha = 0.0  # > 0: keep an exponential average of C_k (for storage)
        self.C_avg: list[float] = [0.0] * n

    def push(self, u: float) -> None:
        """Shift in the (unscaled) command u(k-1), %."""
        if self.track_op:  # slow operating point: keeps sum(x) near 0 in steady state
            self.u_op += self.u_op_alpha * (u - self.u_op)
        x = (u - self.u_op) / self.u_scale
        if x > 1.0:  # clamp: keeps |x| <= 1 and the LMS step inside its stability bound
            x = 1.0
        elif x < -1.0:
            x = -1.0
        M = self.M
        dropped = self._buf[self._pos + M - 1]
        self._pos -= 1
        if self._pos < 0:  # rebase: the old window buf[0:M] moves to buf[M+1:2M+1]
            self._buf[M + 1 : 2 * M + 1] = self._buf[0:M]
            self._pos = M
        self._buf[self._pos] = x
        self._x_sum += x - dropped

    def regressor(self) -> list[float]:
        """The regressor u(k): the last M inputs, newest first (plus 1.0 with the bias tap)."""
        x = self._buf[self._pos : self._pos + self.M]
        if self.bias_tap:
            x.append(1.0)
        return x

    def predict(self, C: list[float] | None = None) -> float:
        # eq. (3): d(k) = sum_i C_i u(k + 1 - i), shifted one step back (strictly causal)
        """The FIR output d(k) with weights ``C`` (default: the current weights), eq. (3)."""
        w = self.C if C is None else C
        d = sum(map(operator.mul, w, self._buf[self._pos : self._pos + self.M]))
        if self.bias_tap:
            d += w[-1]
        return d

    def train(self, e: float) -> None:
        # eq. (5): C_{k+1} = C_k + 2 mu e(k) u(k), with e = y - d (the sign that descends e^2;
        # the paper's eq. (4) writes e = d - y, which with this update would ascend it).
        """One LMS update with the error ``e = y - d``, eq. (5)."""
        g = 2.0 * self.mu * e
        x = self._buf[self._pos : self._pos + self.M]
        C = self.C
        if self.bias_tap:
            C[:-1] = [c + g * xi for c, xi in zip(C[:-1], x, strict=True)]
            C[-1] += g
            self.w_sum += g * (self._x_sum + 1.0)
        else:
            self.C = [c + g * xi for c, xi in zip(C, x, strict=True)]
            self.w_sum += g * self._x_sum
        a = self.avg_alpha
        if a:
            self.C_avg = [ca + a * (c - ca) for ca, c in zip(self.C_avg, self.C, strict=True)]

    def set_weights(self, C: list[float]) -> None:
        """Replace the weights (and their running average) by ``C``."""
        self.C = list(C)
        self.C_avg = list(C)
        self.w_sum = math.fsum(self.C)


class WeightDriftSnr:
    """Criterion 2: R(k) of eq. (8)-(11) over a moving window of the weight sums.

    The window holds sum_i C_ij for the last n steps j. D_j = sum_i (C_ij - C_i0) (eq. (9));
    C_0 is the window's reference vector, which cancels in the normalisation of eq. (10), so the
    sums themselves are kept. std is the population standard deviation (ddof = 0). Both divisions
    are guarded: once the weights converge, std(D) -> 0 and R(k) is then 0, not NaN.
    """

    EPS = 1e-12

    def __init__(self, n: int) -> None:
        self.n = n
        self.s: deque[float] = deque(maxlen=n)
        self.V_last = 0.0

    def push(self, w_sum: float) -> float:
        """Append sum_i C_ik and return R(k) (0 until the window is full)."""
        self.s.append(w_sum)
        if len(self.s) < self.n:
            self.V_last = 0.0
            return 0.0
        return self._snr()

    def replace_last(self, count: int, w_sum: float) -> None:
        """Overwrite the last ``count`` sums (undo a disturbance's effect on the window)."""
        for i in range(1, min(count, len(self.s)) + 1):
            self.s[-i] = w_sum

    def reset(self) -> None:
        """Forget the weight-sum history."""
        self.s.clear()
        self.V_last = 0.0

    def _snr(self) -> float:
        s = self.s
        n = len(s)
        s0 = s[0]
        D = [sj - s0 for sj in s]  # eq. (9): D_j = sum_i (C_ij - C_i0)
        mD = sum(D) / n
        varD = sum((dj - mD) ** 2 for dj in D) / n
        if varD <= self.EPS * self.EPS:
            self.V_last = 0.0
            return 0.0
        sD = math.sqrt(varD)
        V = [abs((dj - mD) / sD) for dj in D]  # eq. (10): V = |(D - mean D) / std D|
        mV = sum(V) / n
        varV = sum((v - mV) ** 2 for v in V) / n
        self.V_last = V[-1]
        if varV <= self.EPS:
            return 0.0
        return (V[-1] - mV) ** 2 / varV  # eq. (11): R(k) = (V - mean V)^2 / std(V)^2


@dataclass(frozen=True)
class DetectorStep:
    """What the detector decided at step k."""

    d_deg: float  # predicted heading increment, deg
    e2: float  # e^2(k), deg^2 (0 when no reading)
    snr: float  # R(k)
    V: float  # V of the newest sample, eq. (10)
    exceed: bool  # e^2 > theta at this step
    suspect: bool  # criterion 1 is open (from the first exceedance until confirm/expiry)
    confirmed: bool  # criterion 2 confirmed at this step (an edge, once per event)
    dismissed: bool  # the suspect expired without confirmation: a disturbance


class DualCriterionDetector:
    """Criterion 1 (e^2(k) > theta, eq. (7)) then criterion 2 (R(k) > n0, eq. (12)).

    On the first e^2 exceedance the FIR weights are stored (``stored``). Criterion 2 confirms if
    R(k) > n0 holds for ``persist`` consecutive steps within ``confirm_window`` steps of the
    exceedance (R(k) jumps for a spike too; a drift keeps the weights displaced, a spike that
    ends undoes its own update). An unconfirmed suspect is a disturbance: the weights and the
    SNR window are restored to the stored state, so the disturbance leaves no trace.
    """

    def __init__(self, cfg: DetectorConfig) -> None:
        self.cfg = cfg
        self.fir = AdaptiveFir(
            cfg.order, cfg.mu, cfg.bias_tap, cfg.u_op, cfg.u_scale, cfg.u_op_samples
        )
        if cfg.store_average_samples:
            self.fir.avg_alpha = 1.0 / cfg.store_average_samples
        self.snr = WeightDriftSnr(cfg.snr_window)
        self.stored: list[float] | None = None
        self.frozen = False  # no training while a confirmed fault is being handled
        self._suspect_age = -1  # steps since the exceedance, -1 when no suspect is open
        self._over = 0
        self._stored_sum = 0.0
        self._trained = 0
        # sigma_e: robust running scale of the residual e (deg), frozen while suspect/frozen.
        ts = cfg.theta_sigmas if cfg.theta_sigmas > 0 else 1.0
        self.var = RobustVariance(cfg.theta_deg2 / (ts * ts), cfg.sigma_samples, 3.0, 1e-6)
        self.short = TrimmedScale(6, 2)
        # theta's multiplier in force (the caller raises it for a while after a commanded turn)
        self.theta_scale = 1.0
        self._cum_e = 0.0
        self._sum_e = 0.0
        self._n_e = 0

    @property
    def theta(self) -> float:
        """The e^2 threshold in force, deg^2 (theta of eq. (7), raised with the noise)."""
        c = self.cfg
        if c.theta_sigmas <= 0.0:
            return c.theta_deg2
        return max(c.theta_deg2, c.theta_sigmas * c.theta_sigmas * self.var.var)

    @property
    def suspect_open(self) -> bool:
        """Whether criterion 1 (e² over its threshold, eq. (7)) has opened a suspicion
        still being judged."""
        return self._suspect_age >= 0

    def push_command(self, u: float) -> None:
        """The command sent in the period that just ended (call once per period, first)."""
        self.fir.push(u)

    def predict_deg(self) -> float:
        """The FIR's predicted heading increment for this period, deg."""
        return self.fir.predict() * self.cfg.y_scale

    def step(self, dy_deg: float | None, flagged: bool = False) -> DetectorStep:
        """One period: ``dy_deg`` is the measured heading increment, None when no reading.

        ``flagged``: the driver found this increment faster than the vehicle can turn (its
        protocol's ``max_rate``); it counts as an e^2 exceedance (criterion 1, eq. (7)) even
        when e^2 <= theta or during warm-up. Confirmation (criterion 2) is unchanged."""
        cfg = self.cfg
        d = self.fir.predict()
        if dy_deg is None:
            return DetectorStep(d * cfg.y_scale, 0.0, 0.0, 0.0, False, self.suspect_open,
                                False, False)
        e = wrap180(dy_deg) / cfg.y_scale - d
        e_deg = e * cfg.y_scale
        e2 = e_deg * e_deg  # eq. (7): J^2(k) = [d(k) - y(k)]^2, deg^2
        self._trained += 1
        self._cum_e += e_deg
        self.short.push(self._cum_e)  # its first differences are e itself
        exceed = flagged or (e2 > self.theta * self.theta_scale
                             and self._trained > cfg.warmup_samples)
        if exceed and not self.suspect_open and not self.frozen:
            # Store the weights at the suspect instant (before this sample trains them); with
            # store_average_samples, their recent average: the instantaneous C_k carries the
            # LMS gradient noise, which a frozen model then integrates as a heading rate.
            self.stored = list(self.fir.C_avg if self.fir.avg_alpha else self.fir.C)
            self._stored_sum = self.fir.w_sum
            self._suspect_age = 0
            self._over = 0
            self._sum_e = 0.0
            self._n_e = 0
        if self.suspect_open:
            self._sum_e += e_deg
            self._n_e += 1
        elif not self.frozen:
            self.var.update(e_deg, alpha=max(self.var.alpha, 1.0 / self._trained))
        if not self.frozen:
            self.fir.train(e)
        R = self.snr.push(self.fir.w_sum) if not self.frozen else 0.0
        confirmed = dismissed = False
        if self.suspect_open:
            self._over = self._over + 1 if cfg.n0 < R else 0
            if self._over >= cfg.persist and self._level_changed():
                confirmed = True
                self._suspect_age = -1
            else:
                self._suspect_age += 1
                if self._suspect_age >= cfg.confirm_window:
                    dismissed = True
                    self.dismiss()
        return DetectorStep(d * cfg.y_scale, e2, R, self.snr.V_last, exceed,
                            self.suspect_open or confirmed, confirmed, dismissed)

    def _level_changed(self) -> bool:
        """Criterion 2 alone fires on any persisting weight change (R(k) is scale-free); also
        require a change of the residual mean, in sigma_e, and no noise burst."""
        cfg = self.cfg
        sigma = self.var.sigma
        if cfg.burst_ratio > 0.0 and self.short.full and self.short.sigma > cfg.burst_ratio * sigma:
            return False
        if cfg.mean_sigmas <= 0.0 or self._n_e == 0:
            return True
        return abs(self._sum_e) >= cfg.mean_sigmas * sigma * math.sqrt(self._n_e)

    def dismiss(self) -> None:
        """Close an open suspect as a disturbance: restore the stored weights and window."""
        if self.stored is not None:
            age = self._suspect_age + 1
            self.fir.set_weights(self.stored)
            self.snr.replace_last(age, self.fir.w_sum)
        self._suspect_age = -1
        self._over = 0

    def close_suspect(self) -> None:
        """Close an open suspect as confirmed by the caller's own test (no restore)."""
        self._suspect_age = -1
        self._over = 0

    def burst(self, ratio: float) -> bool:
        """The short scale of e (its largest 2 of 6 trimmed) above ``ratio`` sigma_e."""
        return self.short.full and self.short.sigma > ratio * self.var.sigma

    def force_store(self, C: list[float]) -> None:
        """Set the stored weights from outside (the stuck-reading detector's snapshot)."""
        self.stored = list(C)
        self._suspect_age = -1

    def freeze(self) -> None:
        """Stop adapting: the weights and the operating point are held (while a fault is
        handled)."""
        self.frozen = True
        self.fir.track_op = False

    def recover(self) -> None:
        """The sensor is consistent again: restart from the stored (pre-fault) model."""
        if self.stored is not None:
            self.fir.set_weights(self.stored)
        self.snr.reset()
        self.frozen = False
        self.fir.track_op = self.cfg.u_op_samples > 0
        self._suspect_age = -1
        self._over = 0
