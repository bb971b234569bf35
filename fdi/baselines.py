"""What a user would otherwise rely on: GPS gating as the field's estimators document it.

Each baseline consumes the same fixes as the rover isolator (local east/north/up metres, the
pipeline's own conversion, with the fix time) and returns, per epoch, whether the fix was judged
faulty and the position it passes on. They share one filter, :class:`fdi.kalman.GpsKalman`
(three constant-velocity axes, white acceleration ``q``, ``R = σ²``) with the *same* ``q`` and
``σ`` as the isolator, so only the gating logic differs. That is the honest comparison on
NMEA-only data: the autopilots' filters are IMU-driven (their prediction is better than a
constant-velocity model in a turn, and a 24-state filter is out of scope), but their GPS gates
are the documented rules below, applied to the same innovation ``ν = z − H x̂⁻`` and
``S = H P⁻ Hᵀ + R``. Using the receiver's σ = 0.35 m rather than the autopilots' own defaults
(EK3_POSNE_M_NSE 0.5 m, EKF2_GPS_P_NOISE 0.5 m) makes their gates *tighter*, not looser.

* :class:`KalmanNoFdi`: every fix is fused; nothing is ever flagged.
* :class:`Ekf3Style`, ArduPilot EKF3, ``libraries/AP_NavEKF3/AP_NavEKF3_PosVelFusion.cpp``
  (``FuseVelPosNED``, "Test horizontal position measurements") and ``AP_NavEKF3.cpp`` (the
  ``POS_I_GATE``, ``HGT_I_GATE`` and ``GLITCH_RAD`` parameter docs):

  - horizontal test ratio ``posTestRatio = (ν_N² + ν_E²) / (max(0.01·POS_I_GATE, 1)² ·
    (S_N + S_E))`` (the pair is one test, against the *sum* of the variances), with
    ``EK3_POS_I_GATE = 500`` i.e. a 5σ gate; the fix passes when the ratio is < 1;
  - height alone: ``hgtTestRatio = ν_D² / (max(0.01·HGT_I_GATE, 1)² · S_D)``, HGT_I_GATE 500;
  - a rejected fix is not fused; when no fix has passed for ``gpsRetryTimeNoTAS_ms = 7000``
    (``AP_NavEKF3.cpp``; ``posTimeout``), or when a fix passes while the horizontal position
    variance exceeds ``EK3_GLITCH_RAD²`` (``posVarianceIsTooLarge``), the position is reset to
    the GPS (``ResetPosition``: state = fix, the reset fix itself is not fused) and its
    variance set to ``(0.5·GLITCH_RAD)²``; GLITCH_RAD = 25 m (``GLITCH_RADIUS_DEFAULT``);
  - ``EK3_GLITCH_RAD = 0`` switches to clipping: a failing fix is fused with its innovation
    variance multiplied by the test ratio (limited to a ratio-of-1 step) instead of rejected.
    The height uses the same clip when GLITCH_RAD = 0 and resets after ``hgtRetryTimeMode0_ms
    = 10000`` of rejections.

* :class:`Ekf2Style`, PX4 EKF2, ``src/modules/ekf2/EKF/ekf.h`` (``updateAidSourceStatus``) and
  ``EKF/aid_sources/gnss/gps_control.cpp`` (``controlGnssPosFusion``): a test ratio *per axis*,
  ``ν_i² / (EKF2_GPS_P_GATE² · S_ii)`` with ``EKF2_GPS_P_GATE = 5`` (``params_gnss.yaml``);
  the horizontal pair is rejected if either ratio is > 1; GNSS height is its own source with the
  same gate; when horizontal fusion has timed out for ``reset_timeout_max = 7 s``
  (``EKF/common.h``), ``resetHorizontalPositionToGnss`` sets the position to the fix with the
  fix's variance.
* :class:`RobotLocalizationStyle`, ``robot_localization`` ``src/filter_base.cpp``
  (``checkMahalanobisThreshold``: reject when ``νᵀ S⁻¹ ν ≥ threshold²``) and ``src/ekf.cpp``
  (``correct``: a rejected measurement is simply dropped, there is no reset), with
  ``pose0_rejection_threshold = 5.0``, the value in the package's ``params/ekf_template.yaml``
  (its built-in default is ``numeric_limits<double>::max()``, i.e. no rejection: that case is
  :class:`KalmanNoFdi`). The pose's x, y, z are tested together (3 dof).
* :class:`Chi2Only`: Zhou & Zhang (2010) section 1 alone, ``F = DᵀS⁻¹D > T_d`` with
  ``T_d = χ²₀.₉₅(3) = 7.815``; a faulty fix is not used, the filter's prediction is passed on.

Units: metres, seconds. A fix's up component may be NaN (a 2D fix): it is then not used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fdi.chi2 import threshold
from fdi.kalman import GpsKalman

Enu = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class BaselineStep:
    """One epoch's outcome, in the isolator's terms (``action``: accept/reject/reset/no_fix)."""

    fault: bool
    action: str
    reason: str
    out_enu: Enu | None
    stat: float | None  # the test statistic compared against ``stat_threshold``
    stat_threshold: float


@dataclass(frozen=True)
class BaselineParams:
    """The filter shared by every baseline (the isolator's defaults)."""

    sigma_m: float = 0.35
    sigma_up_m: float = 0.7
    q_accel: float = 0.5


class _CvBaseline:
    """A constant-velocity Kalman filter on fixes; subclasses decide what a fix does to it."""

    name = "kalman"
    stat_threshold = math.inf

    def __init__(self, params: BaselineParams | None = None) -> None:
        self.p = params or BaselineParams()
        self.kf = GpsKalman(q=self.p.q_accel)
        self.last_t: float | None = None

    def _r(self, up_known: bool) -> Enu:
        s = self.p.sigma_m**2
        return (s, s, self.p.sigma_up_m**2 if up_known else 1e12)

    def step(self, t_s: float, z: Enu | None) -> BaselineStep:
        """Feed one epoch (``z`` None: no fix). Epochs must come in time order."""
        dt = None if self.last_t is None else t_s - self.last_t
        if z is None:
            if self.kf.initialised and dt is not None and dt > 0.0:
                self.kf.predict(dt)
                self.last_t = t_s
            pos = self.kf.position if self.kf.initialised else None
            return BaselineStep(False, "no_fix", "", pos, None, self.stat_threshold)
        if dt is not None and dt <= 0.0:
            return BaselineStep(False, "no_fix", "time_backwards", None, None, self.stat_threshold)
        up_known = not math.isnan(z[2])
        if not up_known:
            z = (z[0], z[1], self.kf.position[2] if self.kf.initialised else 0.0)
        r = self._r(up_known)
        self.last_t = t_s
        if not self.kf.initialised or dt is None:
            self.kf.reset(z, r)
            self._on_start(t_s)
            return BaselineStep(False, "accept", "start", z, None, self.stat_threshold)
        self.kf.predict(dt)
        self.kf.test(z, r)  # fills D (innovation) and S (its variance) per axis
        return self._gate(t_s, z, r, up_known)

    def _on_start(self, t_s: float) -> None:
        """Called when the filter starts on a fix."""

    def _gate(self, t_s: float, z: Enu, r: Enu, up_known: bool) -> BaselineStep:
        self.kf.update(z, r)
        return BaselineStep(False, "accept", "", self.kf.position, None, self.stat_threshold)

    def _update_axes(self, z: Enu, r: Enu, axes: tuple[int, ...]) -> None:
        self.kf.update(z, r, only=axes)

    def _reset_axes(self, z: Enu, variance: float, axes: tuple[int, ...]) -> None:
        """Position of ``axes`` set to the fix (covariance rows/columns zeroed, velocity kept)."""
        for i in axes:
            ax = self.kf.axes[i]
            ax.p, ax.P00, ax.P01 = z[i], variance, 0.0


class KalmanNoFdi(_CvBaseline):
    """Every fix fused, nothing flagged: what a plain filter does with a glitch."""

    name = "kalman_no_fdi"


class Chi2Only(_CvBaseline):
    """Zhou & Zhang (2010) section 1 alone: F = DᵀS⁻¹D against T_d = χ²₁₋α(m) (eq. 5-6)."""

    name = "chi2_only"

    def __init__(self, params: BaselineParams | None = None, alpha: float = 0.05) -> None:
        super().__init__(params)
        self.stat_threshold = threshold(alpha, 3)

    def _gate(self, t_s: float, z: Enu, r: Enu, up_known: bool) -> BaselineStep:
        D, S = self.kf.D, self.kf.S
        axes = (0, 1, 2) if up_known else (0, 1)
        f_k = sum(D[i] * D[i] / S[i] for i in axes)  # (5) F(k) = DᵀS⁻¹D
        if f_k > self.stat_threshold:  # (6): faulty, not used; the prediction is passed on
            return BaselineStep(True, "reject", "chi2", self.kf.position, f_k, self.stat_threshold)
        self.kf.update(z, r)
        return BaselineStep(False, "accept", "", self.kf.position, f_k, self.stat_threshold)


class RobotLocalizationStyle(_CvBaseline):
    """robot_localization: Mahalanobis distance of the pose innovation against a threshold."""

    name = "robot_localization"

    def __init__(self, params: BaselineParams | None = None, rejection_threshold: float = 5.0):
        super().__init__(params)
        # checkMahalanobisThreshold compares the *squared* distance with threshold².
        self.stat_threshold = rejection_threshold * rejection_threshold

    def _gate(self, t_s: float, z: Enu, r: Enu, up_known: bool) -> BaselineStep:
        D, S = self.kf.D, self.kf.S
        axes = (0, 1, 2) if up_known else (0, 1)
        d2 = sum(D[i] * D[i] / S[i] for i in axes)
        if d2 >= self.stat_threshold:  # rejected: dropped, no reset, nothing else happens
            return BaselineStep(True, "reject", "mahalanobis", self.kf.position, d2,
                                self.stat_threshold)
        self.kf.update(z, r)
        return BaselineStep(False, "accept", "", self.kf.position, d2, self.stat_threshold)


class Ekf3Style(_CvBaseline):
    """ArduPilot EKF3 GPS position gating, reset on timeout and the glitch radius."""

    name = "ekf3"

    def __init__(
        self,
        params: BaselineParams | None = None,
        pos_i_gate: float = 500.0,  # EK3_POS_I_GATE, hundredths of σ
        hgt_i_gate: float = 500.0,  # EK3_HGT_I_GATE
        glitch_rad_m: float = 25.0,  # EK3_GLITCH_RAD
        retry_s: float = 7.0,  # gpsRetryTimeNoTAS_ms
        hgt_retry_s: float = 10.0,  # hgtRetryTimeMode0_ms
    ) -> None:
        super().__init__(params)
        self.gate = max(0.01 * pos_i_gate, 1.0)
        self.hgt_gate = max(0.01 * hgt_i_gate, 1.0)
        self.glitch_rad_m = glitch_rad_m
        self.retry_s = retry_s
        self.hgt_retry_s = hgt_retry_s
        self.stat_threshold = 1.0  # a test ratio
        self.last_pos_pass_t = 0.0
        self.last_hgt_pass_t = 0.0
        self.resets = 0

    def _on_start(self, t_s: float) -> None:
        self.last_pos_pass_t = self.last_hgt_pass_t = t_s

    def _gate(self, t_s: float, z: Enu, r: Enu, up_known: bool) -> BaselineStep:
        D, S = self.kf.D, self.kf.S
        # posTestRatio: the horizontal pair against the sum of its innovation variances.
        pos_ratio = (D[0] ** 2 + D[1] ** 2) / (self.gate**2 * (S[0] + S[1]))
        pos_pass = pos_ratio < 1.0
        r_h = r
        if pos_pass:
            self.last_pos_pass_t = t_s
        elif self.glitch_rad_m <= 0.0:
            # Clip mode: S ← S·ratio, i.e. R' = S·ratio − P, fused as if the ratio were 1.
            pos_pass = True
            self.last_pos_pass_t = t_s
            r_h = (S[0] * pos_ratio - self.kf.axes[0].P00,
                   S[1] * pos_ratio - self.kf.axes[1].P00, r[2])
        pos_timeout = t_s - self.last_pos_pass_t > self.retry_s
        action, reason, fault = "accept", "", False
        if pos_pass or pos_timeout:
            var_ne = self.kf.axes[0].P00 + self.kf.axes[1].P00
            too_large = self.glitch_rad_m > 0.0 and var_ne > self.glitch_rad_m**2
            if pos_timeout or too_large:
                # ResetPosition: to the GPS; the same fix is not fused; P = (GLITCH_RAD/2)².
                self._reset_axes(z, (0.5 * self.glitch_rad_m) ** 2, (0, 1))
                self.last_pos_pass_t = t_s
                self.resets += 1
                action, reason = "reset", "gps_timeout" if pos_timeout else "glitch_radius"
            else:
                self._update_axes(z, r_h, (0, 1))
        else:
            action, reason, fault = "reject", "pos_gate", True
        # hgtTestRatio: GPS height alone.
        if up_known:
            hgt_ratio = D[2] ** 2 / (self.hgt_gate**2 * S[2])
            hgt_pass = hgt_ratio < 1.0
            r_u = r[2]
            if hgt_pass:
                self.last_hgt_pass_t = t_s
            elif self.glitch_rad_m <= 0.0:
                hgt_pass = True
                self.last_hgt_pass_t = t_s
                r_u = S[2] * hgt_ratio - self.kf.axes[2].P00
            if hgt_pass:
                self.kf.update(z, (r[0], r[1], r_u), only=(2,))
            elif t_s - self.last_hgt_pass_t > self.hgt_retry_s:
                self._reset_axes(z, r[2], (2,))  # ResetHeight: P = the measurement variance
                self.last_hgt_pass_t = t_s
            else:
                fault = True
                reason = "+".join(x for x in (reason, "hgt_gate") if x)
                action = "reject" if action == "accept" else action
        return BaselineStep(fault, action, reason, self.kf.position, pos_ratio, 1.0)


class Ekf2Style(_CvBaseline):
    """PX4 EKF2 GNSS position gating: per-axis test ratios, reset after a 7 s fusion timeout."""

    name = "ekf2"

    def __init__(
        self,
        params: BaselineParams | None = None,
        gps_p_gate: float = 5.0,  # EKF2_GPS_P_GATE, σ
        reset_timeout_s: float = 7.0,  # reset_timeout_max
    ) -> None:
        super().__init__(params)
        self.gate = max(gps_p_gate, 1.0)
        self.reset_timeout_s = reset_timeout_s
        self.stat_threshold = 1.0
        self.last_fuse_t = 0.0
        self.last_hgt_fuse_t = 0.0
        self.resets = 0

    def _on_start(self, t_s: float) -> None:
        self.last_fuse_t = self.last_hgt_fuse_t = t_s

    def _gate(self, t_s: float, z: Enu, r: Enu, up_known: bool) -> BaselineStep:
        D, S = self.kf.D, self.kf.S
        g2 = self.gate**2
        ratios = [D[i] ** 2 / (g2 * S[i]) for i in range(3)]  # test_ratio[i]
        h_rejected = ratios[0] > 1.0 or ratios[1] > 1.0
        action, reason, fault = "accept", "", False
        if not h_rejected:
            self._update_axes(z, r, (0, 1))
            self.last_fuse_t = t_s
        elif t_s - self.last_fuse_t > self.reset_timeout_s:
            # resetHorizontalPositionToGnss: position = fix, variance = the fix's.
            self._reset_axes(z, r[0], (0, 1))
            self.last_fuse_t = t_s
            self.resets += 1
            action, reason = "reset", "fusion_timeout"
        else:
            action, reason, fault = "reject", "pos_gate", True
        if up_known:
            if ratios[2] <= 1.0:
                self.kf.update(z, r, only=(2,))
                self.last_hgt_fuse_t = t_s
            elif t_s - self.last_hgt_fuse_t > self.reset_timeout_s:
                self._reset_axes(z, r[2], (2,))
                self.last_hgt_fuse_t = t_s
            else:
                fault = True
                reason = "+".join(x for x in (reason, "hgt_gate") if x)
                action = "reject" if action == "accept" else action
        return BaselineStep(fault, action, reason, self.kf.position, max(ratios[0], ratios[1]),
                            1.0)


BASELINES: dict[str, type[_CvBaseline]] = {
    cls.name: cls for cls in (KalmanNoFdi, Ekf3Style, Ekf2Style, RobotLocalizationStyle, Chi2Only)
}


def make_baseline(name: str, params: BaselineParams | None = None) -> _CvBaseline:
    """A baseline by its table name (``kalman_no_fdi``, ``ekf3``, ``ekf2``, ...)."""
    try:
        cls = BASELINES[name]
    except KeyError as err:
        raise ValueError(f"unknown baseline {name!r} (known: {', '.join(BASELINES)})") from err
    return cls(params)
