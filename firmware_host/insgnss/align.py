"""Initial alignment of the live INS from its own sensors (never the truth): levelling from the
accelerometers, heading by gyrocompassing at rest or from the GNSS course in motion, and the
initial covariance each method can justify. Shared by the vehicle
(:mod:`firmware_host.insgnss.vehicle`) and the offline reference that aligns the same way
(:func:`firmware_host.devtools.insgnss_live.offline_aligned`).

Frames as :mod:`fdi.insgnss`: body FRD, navigation ENU, yaw clockwise from north.

* Levelling: at rest (or in unaccelerated motion) the mean specific force is ``f_b = −C_nb g``,
  so ``roll = atan2(−f_y, −f_z)``, ``pitch = atan2(f_x, sqrt(f_y² + f_z²))``. Its error is the
  accelerometer bias over g: ``σ_tilt = sqrt(b_a² + VRW²/T) / g``.
* Gyrocompassing (at rest): the mean gyro is the Earth's rate ``Ω (0, cos L, sin L)`` (ENU) in
  the body frame; levelled by roll and pitch its horizontal part is ``Ω cos L (−sin ψ, cos ψ)``,
  so ``ψ = atan2(−ω_E, ω_N)``. Its error: ``σ_ψ² = (b_g² + ARW²/T) / (Ω cos L)² + (σ_tilt tan L)²``
  (a gyro bias across the north axis, and the vertical rate leaking through a tilt error). Only
  a navigation-grade gyro (0.01 °/h: 0.05°) can do it; a MEMS gyro (10 °/h) cannot, and the
  heading then comes from the GNSS course once moving: ``σ_ψ = atan(σ_v / speed)``, and no
  better than ``course_sigma_deg`` (the course is the heading only without sideslip or crab).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from fdi.insgnss import DEG, InsGnssParams, euler_to_quat, quat_rotate, quat_to_dcm

Vec = npt.ArrayLike | tuple[float, float, float]
OMEGA_IE = 7.292115e-5  # rad/s (WGS 84)


@dataclass(frozen=True)
class Alignment:
    """The initial attitude (rad) and the 1σ of the initial state it justifies."""

    roll: float
    pitch: float
    yaw: float
    sigma_pos_m: float
    sigma_vel_m_s: float
    sigma_tilt_deg: float
    sigma_yaw_deg: float
    method: str  # "gyrocompass" | "gnss course" | "attitude"

    def params(self, base: InsGnssParams) -> InsGnssParams:
        """``base`` with this alignment's initial sigmas (the filter's initial P)."""
        return replace(base, init_sigma_pos_m=self.sigma_pos_m,
                       init_sigma_vel_m_s=self.sigma_vel_m_s,
                       init_sigma_tilt_deg=max(self.sigma_tilt_deg, 1e-4),
                       init_sigma_yaw_deg=max(self.sigma_yaw_deg, 1e-3))


def level(f_mean: Vec) -> tuple[float, float]:
    """Roll and pitch (rad) from the mean specific force (FRD, m/s²)."""
    fx, fy, fz = (float(v) for v in np.asarray(f_mean, dtype=float)[:3])
    return math.atan2(-fy, -fz), math.atan2(fx, math.hypot(fy, fz))


def tilt_sigma(params: InsGnssParams, seconds: float, extra_m_s2: float = 0.0) -> float:
    """1σ of the levelling (rad) over ``seconds`` of averaging; ``extra_m_s2``: an unmodelled
    acceleration (levelling in motion)."""
    imu = params.imu
    noise = imu.accel_vrw_m_s_sqrt_s / math.sqrt(max(seconds, 1e-3))
    return math.sqrt(imu.accel_bias_m_s2**2 + noise**2 + extra_m_s2**2) / params.earth.g0


def gyrocompass(w_mean: Vec, roll: float, pitch: float) -> float:
    """Heading (rad) from the mean gyro at rest (FRD, rad/s), levelled by roll and pitch."""
    w = np.asarray(w_mean, dtype=float)
    wh = quat_rotate(euler_to_quat(roll, pitch, 0.0), (float(w[0]), float(w[1]), float(w[2])))
    return math.atan2(-wh[0], wh[1])


def gyrocompass_sigma(params: InsGnssParams, seconds: float) -> float:
    """1σ (rad) of :func:`gyrocompass` over ``seconds`` at rest, from the configured IMU."""
    imu = params.imu
    lat = params.latitude_deg * DEG
    horiz = OMEGA_IE * math.cos(lat)
    gyro = math.sqrt(imu.gyro_bias_rad_s**2
                     + imu.gyro_arw_rad_sqrt_s**2 / max(seconds, 1e-3)) / horiz
    return math.hypot(gyro, tilt_sigma(params, seconds) * math.tan(abs(lat)))


def zaru_sigma(floor_rad_s: float, params: InsGnssParams, seconds: float) -> float:
    """1σ (rad/s) of a zero-angular-rate update on the mean gyro over ``seconds`` at rest: the
    configured floor (quantisation, vibration) and the white noise (ARW) over that time."""
    arw = params.imu.gyro_arw_rad_sqrt_s
    return math.sqrt(floor_rad_s**2 + arw * arw / max(seconds, 1e-3))


def at_rest(params: InsGnssParams, f: np.ndarray, w: np.ndarray, seconds: float,
            yaw: float | None, yaw_sigma_deg: float, rest_sigma_vel_m_s: float) -> Alignment:
    """The alignment at rest from the mean specific force ``f`` and gyro ``w`` over
    ``seconds``: levelling, then the heading ``yaw`` (1σ ``yaw_sigma_deg``) if given
    (ATTITUDE), else gyrocompassing."""
    roll, pitch = level(f)
    sig_tilt = tilt_sigma(params, seconds)
    if yaw is None:
        yaw, sig_yaw, method = gyrocompass(w, roll, pitch), gyrocompass_sigma(params, seconds), \
            "gyrocompass"
    else:
        sig_yaw, method = yaw_sigma_deg * DEG, "attitude"
    return Alignment(roll, pitch, yaw, max(params.gnss_sigma_h_m, params.gnss_sigma_v_m),
                     rest_sigma_vel_m_s, sig_tilt / DEG, sig_yaw / DEG, method)


def in_motion(params: InsGnssParams, f: np.ndarray, seconds: float, speed_m_s: float,
              course_rad: float, course_sigma_deg: float, yaw: float | None = None,
              yaw_sigma_deg: float = 0.0) -> Alignment:
    """The alignment in steady motion: levelling from ``f`` (its deviation from g taken as
    the unmodelled acceleration), heading from the GNSS course (or ``yaw``, ATTITUDE, 1σ
    ``yaw_sigma_deg``)."""
    roll, pitch = level(f)
    dev = abs(float(np.linalg.norm(f)) - params.earth.g0)
    sig_tilt = tilt_sigma(params, seconds, dev)
    if yaw is None:
        sig_yaw = math.hypot(math.atan2(params.gnss_sigma_vel_m_s, max(speed_m_s, 1e-3)),
                             course_sigma_deg * DEG)
        yaw, method = course_rad, "gnss course"
    else:
        sig_yaw, method = yaw_sigma_deg * DEG, "attitude"
    return Alignment(roll, pitch, yaw, max(params.gnss_sigma_h_m, params.gnss_sigma_v_m),
                     params.gnss_sigma_vel_m_s, sig_tilt / DEG, sig_yaw / DEG, method)


def attitude_dcm(f_mean: Vec, w_mean: Vec, yaw: float | None = None) -> npt.NDArray[np.float64]:
    """``C_b^n`` of the alignment at rest from the mean specific force and gyro (the heading
    ``yaw`` instead of gyrocompassing if given)."""
    roll, pitch = level(f_mean)
    psi = gyrocompass(w_mean, roll, pitch) if yaw is None else yaw
    return quat_to_dcm(euler_to_quat(roll, pitch, psi))


def rest_covariance(params: InsGnssParams, a: Alignment, f_mean: Vec, w_mean: Vec,
                    seconds: float, yaw: float | None = None) -> npt.NDArray[np.float64]:
    """The initial 15×15 covariance of an alignment at rest, with the attitude error tied to
    the sensor biases that cause it.

    The levelling and the gyrocompass take the biases for the Earth's gravity and rate: with
    the error state of :mod:`fdi.insgnss` (true minus estimate, ``C_b^n = (I − [φ×]) Ĉ``) the
    attitude error is ``φ = J [δb_a; δb_g] + noise``, ``J = ∂φ/∂b`` of the alignment (by finite
    differences of :func:`attitude_dcm`). So ``P_φφ = J P_bb Jᵀ + N``, ``P_φb = J P_bb``: when
    the filter later learns a bias (in manoeuvres), it corrects the attitude the bias had
    spoiled, as it would have if it had aligned itself. ``N``: the sensor noise over
    ``seconds`` (VRW, ARW), ``yaw`` given (ATTITUDE): its own 1σ, no gyro term."""
    imu = params.imu
    sb_a = max(imu.accel_bias_m_s2, 1e-6)
    sb_g = max(imu.gyro_bias_rad_s, 1e-9)
    f = np.asarray(f_mean, dtype=float)
    w = np.asarray(w_mean, dtype=float)
    c0 = attitude_dcm(f, w, yaw)
    jac = np.zeros((3, 6))
    for i in range(6):
        eps = (1e-4 if i < 3 else 1e-8)
        df, dw = np.zeros(3), np.zeros(3)
        (df if i < 3 else dw)[i % 3] = eps
        c1 = attitude_dcm(f - df, w - dw, yaw)  # the truth if the bias were eps larger
        s = 0.5 * ((c1 @ c0.T) - (c1 @ c0.T).T)  # = −[φ×]
        jac[:, i] = np.array([-s[2, 1], -s[0, 2], -s[1, 0]]) / eps
    g0 = params.earth.g0
    t = max(seconds, 1e-3)
    tilt_n = imu.accel_vrw_m_s_sqrt_s / math.sqrt(t) / g0
    if yaw is None:
        yaw_n = imu.gyro_arw_rad_sqrt_s / math.sqrt(t) / (
            OMEGA_IE * math.cos(params.latitude_deg * DEG))
    else:
        yaw_n = a.sigma_yaw_deg * DEG
    pbb = np.diag([sb_a**2] * 3 + [sb_g**2] * 3)
    P = np.diag(np.concatenate([
        np.full(3, a.sigma_pos_m**2), np.full(3, a.sigma_vel_m_s**2),
        np.array([tilt_n, tilt_n, yaw_n]) ** 2, np.diag(pbb)]))
    P[6:9, 6:9] += jac @ pbb @ jac.T
    P[6:9, 9:15] = jac @ pbb
    P[9:15, 6:9] = (jac @ pbb).T
    return P
