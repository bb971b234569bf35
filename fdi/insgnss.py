"""Loosely coupled INS/GNSS: strapdown mechanisation and a 15-state error-state Kalman filter
(18 with the receiver's correlated error, (G1)-(G6)) with the three-zone robust gate (Cai &
Shao) on the GNSS innovations.

Frames and units
----------------
- Navigation frame n: a local tangent plane fixed to the Earth at the origin, axes East, North,
  Up (ENU), position in metres from the origin. Gravity is the spherical model
  ``g(p) = −g0 (R/|r|)² r/|r|`` with ``r = (E, N, U + R)`` (so its direction follows the Earth's
  curvature over tens of kilometres), the Earth rate ``ω_ie^n = Ω (0, cos L, sin L)`` gives the
  Coriolis term. Because n is fixed to the Earth there is no transport rate. Adequate for a
  rover or small aircraft over a few kilometres (and the paper's 25 km flight).
- Body frame b: forward-right-down (FRD), the MAVLink/ArduPilot IMU convention. Attitude is the
  quaternion ``q`` of ``C_b^n``; Euler angles are the aerospace ZYX (yaw from north, clockwise).
- IMU: gyro ω̃ (rad/s) and specific force f̃ (m/s²) in b. A sample stamped ``t_k`` is taken as
  the mean over ``(t_{k−1}, t_k]`` (what integrating IMUs report).

Mechanisation (rectangular rule; the simulator inverts exactly these equations)
--------------------------------------------------------------------------------
(M1) ``C_{k} = Exp(−ω_ie^n Δt) · C_{k−1} · Exp((ω̃ − b̂_g) Δt)``
(M2) ``v_{k} = v_{k−1} + (C_{k−1}(f̃ − b̂_a) + g(p_{k−1}) − 2 ω_ie^n × v_{k−1}) Δt``
(M3) ``p_{k} = p_{k−1} + (v_{k−1} + v_{k}) Δt / 2``

Error state (true minus estimate), 15 states ``δx = [δp, δv, φ, δb_a, δb_g]`` with
``C_b^n = (I − [φ×]) Ĉ_b^n``:

(E1) ``δṗ = δv``
(E2) ``δv̇ = G δp − 2 Ω_ie δv + [f^n×] φ − Ĉ δb_a + Ĉ w_a``,  ``G = (g0/R) diag(−1, −1, 2)``
(E3) ``φ̇ = −Ω_ie φ + Ĉ δb_g − Ĉ w_g``
(E4) ``δḃ_a = w_ba``,  ``δḃ_g = w_bg`` (random walks; ``w_bg`` covers the configured 1σ
over an hour and a MEMS gyro's drift over a minute, ``ImuErrorModel.gyro_bias_rw_rad_s2``)

At rest (the live vehicle, :mod:`firmware_host.insgnss.vehicle`): a zero-velocity update
(ZUPT, ``H`` selects δv) and a zero-angular-rate update (ZARU, ``H`` selects δb_g: the mean
gyro less the Earth's rate is the bias), which observes all three gyro biases.

Discretised as ``Φ = I + FΔt + (FΔt)²/2``, ``Q_d = Q Δt``, propagated at ``cov_rate_hz``.

GNSS update, the paper's eqs. (2)–(8) per component i (antenna at the IMU):
(2) ``ν = z − H x̂``: position ``z − p̂`` (and velocity ``z_v − v̂``), ``H = [I 0 0 0 0]`` (and
``[0 I 0 0 0]``); (3) ``S = H P⁻ Hᵀ + R``; (7)–(8) ``DM(i) = ν_i²/S_ii`` against T1, T2 by
:class:`fdi.three_zone.ThreeZoneGate`, which returns the value and variance to use (or drops
the component). Before the gates, one :class:`fdi.three_zone.JumpTracker` looks at the position
fix as a whole and tells "the receiver jumped" from "the INS drifted" (the lock-in breaker; its
state goes to the three position gates). A gate that accepts the receiver again after the INS
drifted beyond ``P`` flags ``readmit``: ``P_ii += ν_i² − S_ii`` so that the fix pulls the state
back. Then ``K = P⁻H'ᵀ(H'P⁻H'ᵀ + R')⁻¹``, ``δx̂ = K ν'``, Joseph form
``P⁺ = (I − KH')P⁻(I − KH')ᵀ + KR'Kᵀ``, and the correction is fed back into the nominal
state (``δx̂`` reset to 0).

The receiver's correlated error (ours; ``gnss_gm_sigma_m > 0``, off by default). A receiver's
position error is not white: a DGPS fix wanders slowly (multipath, the atmosphere, the age of
the corrections), and a filter that takes each fix as independent averages that wander at rest
as if it were noise (its ``P`` collapses under the ZUPTs) and lags it. With the option, three
states ``g`` (E, N, U, m) follow it as a first-order Gauss-Markov process (the textbook
shaping filter of a correlated measurement error, e.g. Gelb, *Applied Optimal Estimation*):

(G1) ``ġ = −g/τ + w_g``, ``q_g = 2σ_g²/τ`` (stationary variance σ_g²: ``gnss_gm_sigma_m`` E/N,
``gnss_gm_sigma_up_m`` up; τ ``gnss_gm_tau_s``), its estimate decaying as ``ĝ e^(−Δt/τ)``;
(G2) ``z = p + g + v``: a position row of ``H`` selects δp_i and g_i, ``R`` (``gnss_sigma_*``)
is the white rest ``v``;
(G3) a fault's onset also when the receiver walks away from its own model (a walk at zero
speed that ``g`` would follow and the INS absorb through ``P_pg``): with the model right the
position innovations are white, ``u_i = ν_i/√S_ii ~ N(0, 1)``, and a walk shifts their mean;
Page's CUSUM per axis and side, ``C⁺_i = max(0, C⁺_i + u_i − k)``,
``C⁻_i = max(0, C⁻_i − u_i − k)`` (``k`` ``walk_k_sigma``), opens the fault above ``h``
(``walk_h_sigma``); the run's start (the epoch after the CUSUM was last 0) dates the walk;
(G4) the filter starts at a fix, ``p̂₀ = z₀``, ``ĝ₀ = 0``: ``δp₀ = −g₀ − v₀``, so
``P_pp = R + σ_g²``, ``P_pg = −σ_g²`` (:meth:`InsGnssFilter._start_at_fix`);
(G5) at a walk's onset the fixes taken since its start (at most ``rollback_max_s``) are taken
back out: ``p̂ −= Σ δp̂_k``, ``ĝ −= Σ δĝ_k`` (the position and wander corrections of those
updates), ``P_pp`` back to at least its prior before the first of them; the INS then coasts
from where it was before the walk (:meth:`InsGnssFilter._rollback`);
(G6) while a fault is believed the fix is ``z = p + b + v``: the fault's bias holds the
receiver's whole error, ``g`` is only predicted (``ĝ`` decays, ``P_gg`` grows back to ``σ_g²``),
so that a walk goes into ``b`` and not, through ``g`` and ``P_pg``, into the position.

Strategy ``fault_state`` (ours; :mod:`fdi.gnss_fault`): the gates only down-weight, and a
:class:`~fdi.gnss_fault.GnssFaultMonitor` decides per epoch between a healthy receiver and a
biased one. While a fault is believed the filter carries a GNSS position bias ``b`` (random
walk) beside the 15 states, with the blocks ``P_xb`` and ``P_bb``: position rows
``H = [I 0 0 0 0 | I]`` (``z = p + b + v``), velocity rows as usual; ``b`` is opened with
``P_bb = σ_b0² I`` at the onset (the jump goes into ``b``, the INS coasts), reopened when the
fault changes level, and marginalised out (its rows and columns dropped) when the receiver is
healthy again (with the receiver modelled, (G6): the position rows select ``δp`` and ``b``
only). :meth:`InsGnssFilter.coast` is the reference the fault's error is bounded by.

IMU rate: the rectangular rule integrates sampled rates, so it can only follow motion well
below the sample rate. A rover's or small aircraft's manoeuvres (turns, bank changes) have
content up to ~2 Hz; ten samples per period of that motion means at least 20 Hz
(``min_imu_rate_hz``). Below it, or with a gap longer than ``max_imu_gap_s``, the filter
raises :class:`~fdi.errors.EstimatorError` instead of producing numbers.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from fdi.errors import EstimatorError
from fdi.gnss_fault import GnssFaultMonitor, Verdict
from fdi.insgnss_params import (  # re-exported: the parameters live without numpy
    DEG as DEG,
)
from fdi.insgnss_params import (
    EARTH_RADIUS_M as EARTH_RADIUS_M,
)
from fdi.insgnss_params import (
    OMEGA_IE as OMEGA_IE,
)
from fdi.insgnss_params import (
    STANDARD_G as STANDARD_G,
)
from fdi.insgnss_params import (
    EarthModel as EarthModel,
)
from fdi.insgnss_params import (
    ImuErrorModel as ImuErrorModel,
)
from fdi.insgnss_params import (
    InsGnssParams as InsGnssParams,
)
from fdi.insgnss_params import (
    InsGnssStrategy as InsGnssStrategy,
)
from fdi.insgnss_params import (
    normal_gravity as normal_gravity,
)
from fdi.three_zone import (
    STRATEGIES,
    Action,
    GateDecision,
    JumpTracker,
    ReceiverState,
    Strategy,
    ThreeZoneGate,
    classify,
)

# The GNSS treatments: the gate's (fdi.three_zone.Strategy) and "fault_state", a persistent
# fault as a state of the filter (fdi.gnss_fault) with plain down-weighting while healthy.
INS_STRATEGIES: tuple[InsGnssStrategy, ...] = (*STRATEGIES, "fault_state")
Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
FloatArray = npt.NDArray[np.float64]
VecLike = Sequence[float] | npt.NDArray[Any]  # a 3-vector as a sequence or an array

N_STATES = 15
_RATE_WINDOW = 10  # IMU samples whose median interval decides the rate check


# ---------------------------------------------------------------- quaternion helpers (floats)


def quat_mul(a: Quat, b: Quat) -> Quat:
    """The Hamilton product ``a ⊗ b`` of quaternions ``(w, x, y, z)``."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_conj(q: Quat) -> Quat:
    """The conjugate of ``q`` (its inverse for a unit quaternion)."""
    return (q[0], -q[1], -q[2], -q[3])


def quat_rotate(q: Quat, v: Vec3) -> Vec3:
    """C(q) v for a unit quaternion q."""
    w, x, y, z = q
    vx, vy, vz = v
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (
        vx + w * tx + (y * tz - z * ty),
        vy + w * ty + (z * tx - x * tz),
        vz + w * tz + (x * ty - y * tx),
    )


def quat_exp(rx: float, ry: float, rz: float) -> Quat:
    """Unit quaternion of the rotation vector (rx, ry, rz), rad."""
    a2 = rx * rx + ry * ry + rz * rz
    if a2 < 1e-12:
        s = 0.5 - a2 / 48.0
        return (1.0 - a2 / 8.0, s * rx, s * ry, s * rz)
    a = math.sqrt(a2)
    s = math.sin(0.5 * a) / a
    return (math.cos(0.5 * a), s * rx, s * ry, s * rz)


def quat_log(q: Quat) -> Vec3:
    """Rotation vector of a unit quaternion (the inverse of :func:`quat_exp`), rad."""
    w, x, y, z = q if q[0] >= 0 else (-q[0], -q[1], -q[2], -q[3])
    n = math.sqrt(x * x + y * y + z * z)
    if n < 1e-12:
        return (2.0 * x, 2.0 * y, 2.0 * z)
    k = 2.0 * math.atan2(n, w) / n
    return (k * x, k * y, k * z)


def quat_normalize(q: Quat) -> Quat:
    """``q`` scaled to unit norm."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


_Q_NED_TO_ENU: Quat = (0.0, math.sqrt(0.5), math.sqrt(0.5), 0.0)  # 180° about (1, 1, 0)/√2


def euler_to_quat(roll: float, pitch: float, yaw: float) -> Quat:
    """C_b^n (body FRD → ENU) from aerospace ZYX Euler angles (rad, yaw from north)."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    q_ned = (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )
    return quat_mul(_Q_NED_TO_ENU, q_ned)


def quat_to_euler(q: Quat) -> Vec3:
    """(roll, pitch, yaw) in rad of C_b^n (body FRD → ENU); yaw in (−π, π]."""
    w, x, y, z = quat_mul(quat_conj(_Q_NED_TO_ENU), q)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return (roll, pitch, yaw)


def quat_to_dcm(q: Quat) -> FloatArray:
    """The rotation matrix C(q) (3x3) of a unit quaternion: ``C(q) @ v`` is
    :func:`quat_rotate` ``(q, v)``."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _skew(a: VecLike) -> FloatArray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


# ---------------------------------------------------------------- Earth model and mechanisation


@dataclass
class NavState:
    """Nominal navigation state: C_b^n as a quaternion, ENU velocity (m/s) and position (m)."""

    q: Quat
    v: Vec3
    p: Vec3


def mechanize(
    s: NavState, omega_b: Vec3, f_b: Vec3, dt: float, earth: EarthModel, q_earth: Quat
) -> Vec3:
    """Advance ``s`` in place by one IMU interval, eqs. (M1)–(M3); returns f^n (m/s²).

    ``omega_b`` and ``f_b`` are already bias-corrected; ``q_earth = Exp(−ω_ie^n Δt)``.
    """
    v0, p0 = s.v, s.p
    # (M2) specific force to n with the attitude at the start of the interval
    fn = quat_rotate(s.q, f_b)
    g = earth.gravity(p0)
    w = earth.omega_ie_n
    cor = (
        2.0 * (w[1] * v0[2] - w[2] * v0[1]),
        2.0 * (w[2] * v0[0] - w[0] * v0[2]),
        2.0 * (w[0] * v0[1] - w[1] * v0[0]),
    )
    v1 = (
        v0[0] + (fn[0] + g[0] - cor[0]) * dt,
        v0[1] + (fn[1] + g[1] - cor[1]) * dt,
        v0[2] + (fn[2] + g[2] - cor[2]) * dt,
    )
    # (M3) trapezoidal position
    s.p = (
        p0[0] + 0.5 * (v0[0] + v1[0]) * dt,
        p0[1] + 0.5 * (v0[1] + v1[1]) * dt,
        p0[2] + 0.5 * (v0[2] + v1[2]) * dt,
    )
    s.v = v1
    # (M1) attitude
    dq = quat_exp(omega_b[0] * dt, omega_b[1] * dt, omega_b[2] * dt)
    s.q = quat_normalize(quat_mul(quat_mul(q_earth, s.q), dq))
    return fn


def earth_step_quat(earth: EarthModel, dt: float) -> Quat:
    """Exp(−ω_ie^n Δt), the rotation of the tangent frame during Δt, as used in (M1)."""
    w = earth.omega_ie_n
    return quat_exp(-w[0] * dt, -w[1] * dt, -w[2] * dt)


def invert_mechanization(
    s0: NavState, s1: NavState, dt: float, earth: EarthModel, q_earth: Quat
) -> tuple[Vec3, Vec3]:
    """The (ω_b, f_b) that take ``s0`` to ``s1`` through (M1)–(M2): the error-free IMU sample."""
    dq = quat_mul(quat_mul(quat_conj(s0.q), quat_conj(q_earth)), s1.q)
    r = quat_log(dq)
    omega = (r[0] / dt, r[1] / dt, r[2] / dt)
    g = earth.gravity(s0.p)
    w = earth.omega_ie_n
    v0, v1 = s0.v, s1.v
    cor = (
        2.0 * (w[1] * v0[2] - w[2] * v0[1]),
        2.0 * (w[2] * v0[0] - w[0] * v0[2]),
        2.0 * (w[0] * v0[1] - w[1] * v0[0]),
    )
    fn = tuple((v1[i] - v0[i]) / dt - g[i] + cor[i] for i in range(3))
    f_b = quat_rotate(quat_conj(s0.q), (fn[0], fn[1], fn[2]))
    return omega, f_b


# ---------------------------------------------------------------- configuration


# ---------------------------------------------------------------- rate checks


def measure_imu_rate(times_s: Sequence[float]) -> float:
    """Median sample rate (Hz) of IMU timestamps (s); 0.0 with fewer than two samples."""
    if len(times_s) < 2:
        return 0.0
    dts = np.diff(np.asarray(times_s, dtype=float))
    med = float(np.median(dts))
    return math.inf if med <= 0 else 1.0 / med


def check_imu_rate(rate_hz: float, min_rate_hz: float, source: str = "IMU") -> None:
    """Raise EstimatorError if ``rate_hz`` is below what the mechanisation can use."""
    if not rate_hz >= min_rate_hz:
        raise EstimatorError(
            f"{source} rate {rate_hz:.3g} Hz is below the {min_rate_hz:g} Hz this INS "
            "mechanisation needs (it integrates sampled rates; motion above a tenth of the "
            "sample rate would alias into attitude and velocity errors); refusing to run"
        )


# ---------------------------------------------------------------- the filter


def _ins_noise(params: InsGnssParams) -> tuple[FloatArray, FloatArray]:
    """The 15 INS states' initial variances (P0's diagonal) and the continuous white-noise
    PSDs of (E2)–(E4); bias random walk: the 1σ bias over an hour (gyro: and its drift over
    a minute, ImuErrorModel.gyro_bias_rw_rad_s2)."""
    imu = params.imu
    p0 = np.concatenate(
        [
            np.full(3, params.init_sigma_pos_m**2),
            np.full(3, params.init_sigma_vel_m_s**2),
            np.array([params.init_sigma_tilt_deg, params.init_sigma_tilt_deg,
                      params.init_sigma_yaw_deg]) ** 2 * DEG**2,
            np.full(3, max(imu.accel_bias_m_s2, 1e-6) ** 2),
            np.full(3, max(imu.gyro_bias_rad_s, 1e-9) ** 2),
        ]
    )
    q = np.concatenate(
        [
            np.zeros(3),
            np.full(3, max(imu.accel_vrw_m_s_sqrt_s, 1e-6) ** 2),
            np.full(3, max(imu.gyro_arw_rad_sqrt_s, 1e-9) ** 2),
            np.full(3, max(imu.accel_bias_m_s2, 1e-6) ** 2 / 3600.0),
            np.full(3, max(imu.gyro_bias_rw_rad_s2, 1e-18 / 3600.0)),
        ]
    )
    return p0, q


@dataclass(frozen=True)
class EpochReport:
    """What one GNSS update did: per component (E, N, U position, then velocity) the decision."""

    t_s: float
    decisions: tuple[GateDecision, ...]
    verdict: Verdict | None = None  # strategy "fault_state": the fault monitor's decision

    @property
    def rejected(self) -> int:
        """How many of the epoch's measurements the three-zone gate rejected."""
        return sum(d.action is Action.REJECT for d in self.decisions)


class InsGnssFilter:
    """Loosely coupled 15-state error-state Kalman filter (see the module docstring).

    ``x`` is the error state (always 0 between updates, its estimate is fed back), ``P`` its
    covariance (``n × n``: 15, or 18 with the receiver's correlated error ``g``, states
    15-17, its estimate ``gnss_wander``), ``y``/``S`` the last innovation and its covariance
    (after the gate).
    """

    def __init__(
        self,
        params: InsGnssParams,
        t0_s: float,
        position_enu_m: VecLike,
        velocity_enu_m_s: VecLike,
        attitude_rpy_rad: VecLike,
    ) -> None:
        self.params = params
        self.earth = params.earth
        self.nav = NavState(
            euler_to_quat(*(float(a) for a in attitude_rpy_rad[:3])),
            _vec3(velocity_enu_m_s),
            _vec3(position_enu_m),
        )
        self.b_a: Vec3 = (0.0, 0.0, 0.0)  # accelerometer bias estimate, m/s²
        self.b_g: Vec3 = (0.0, 0.0, 0.0)  # gyro bias estimate, rad/s
        self.t_s = float(t0_s)
        self._init_wander(params)
        p0, q = _ins_noise(params)
        self.P: FloatArray = np.diag(np.concatenate([p0, self.gm_var[: self.n - N_STATES]]))
        self._start_at_fix()
        self.x: FloatArray = np.zeros(self.n)
        # the PSDs, with the receiver's error's (G1): q_g = 2σ_g²/τ
        self._q = np.concatenate([q, 2.0 * self.gm_var[: self.n - N_STATES] / self.gm_tau])
        self.y: FloatArray = np.zeros(0)
        self.S: FloatArray = np.zeros((0, 0))
        # The lock-in breaker (fdi.three_zone.JumpTracker) watches the position fix as a whole
        # (E, N, U jump together). Velocity gates go without it: its test needs the INS's
        # increment over n epochs to be well below the fix's noise, true for position (a MEMS
        # INS moves centimetres in 4 s against 3 m), not for velocity (a turn changes a MEMS
        # velocity error by 0.3 m/s in 4 s against 0.1 m/s: measured false onsets that locked
        # out the velocity aiding). They keep the paper's limit and window restart.
        vel = dataclasses.replace(params.three_zone, track_jumps=False)
        # "fault_state": plain down-weighting while the receiver is believed healthy (the
        # monitor below decides when it is not)
        gate: Strategy = "downweight" if params.strategy == "fault_state" else params.strategy
        self.gates = [ThreeZoneGate(params.three_zone, gate) for _ in range(3)] + [
            ThreeZoneGate(vel, gate) for _ in range(3)
        ]
        self.position_tracker = JumpTracker(params.three_zone, 3)
        # Strategy "fault_state" (fdi.gnss_fault): a GNSS position bias b, in the state only
        # while a fault is believed; its covariance blocks P_xb (15×3) and P_bb (3×3).
        self.fault_monitor = GnssFaultMonitor(params.fault_state)
        self.gnss_bias: FloatArray = np.zeros(3)
        self.bias_active = False
        self._Pxb: FloatArray = np.zeros((self.n, 3))
        self._Pbb: FloatArray = np.zeros((3, 3))
        self._q_bias = params.fault_state.bias_rw_m_sqrt_s**2
        # the filter's accumulated corrections as a trajectory (position offset c_p moved by
        # the velocity offset c_v): p̂ − c_p is the INS as if never corrected (jump test)
        self._corr_p: FloatArray = np.zeros(3)
        self._corr_v: FloatArray = np.zeros(3)
        self._corr_t = self.t_s
        self._cov_dt = 1.0 / params.cov_rate_hz
        self._acc_dt = 0.0
        self._acc_fn = [0.0, 0.0, 0.0]
        self._dts: list[float] = []
        self._q_earth_cache: tuple[float, Quat] = (-1.0, (1.0, 0.0, 0.0, 0.0))
        g0 = self.earth.g0
        self._grav_grad = np.diag([-g0, -g0, 2.0 * g0]) / EARTH_RADIUS_M
        self._omega_skew = _skew(self.earth.omega_ie_n)

    def _init_wander(self, params: InsGnssParams) -> None:
        """The receiver's correlated error g (E, N, U), a first-order Gauss-Markov state per
        axis ((G1), module docstring), appended as states 15-17 when gnss_gm_sigma_m > 0;
        ``gm_var``: its stationary variances σ_g²."""
        self.gm_sigma = params.gnss_gm_sigma_m
        self.gm_var = np.array([params.gnss_gm_sigma_m, params.gnss_gm_sigma_m,
                                params.gnss_gm_sigma_up_m]) ** 2
        self.gm_tau = params.gnss_gm_tau_s
        self.n = N_STATES + (3 if self.gm_sigma > 0.0 else 0)
        self.gnss_wander: FloatArray = np.zeros(self.n - N_STATES)  # ĝ, m (E, N, U)
        # (G3) the walk test's CUSUMs (rows C⁺, C⁻; columns E, N, U) and when each run
        # started; (G5) the healthy updates' corrections (t, δp̂, δĝ, P⁻_pp diagonal)
        self._walk_c: FloatArray = np.zeros((2, 3))
        self._walk_t0: FloatArray = np.full((2, 3), self.t_s)
        self._fix_log: deque[tuple[float, FloatArray, FloatArray, FloatArray]] = deque()
        self.rollbacks = 0  # (G5) walks taken back out

    def _start_at_fix(self) -> None:
        """(G4) The filter starts at a fix, ``p̂₀ = z₀``, ``ĝ₀ = 0``: its position error is the
        fix's, ``δp₀ = −g₀ − v₀``, so besides the white part (``init_sigma_pos_m``)
        ``P_pp += σ_g²`` and ``P_pg = −σ_g²`` (the fix tells p + g, not which)."""
        if self.n == N_STATES:
            return
        g = np.arange(N_STATES, self.n)
        p = np.arange(3)
        self.P[p, p] += self.gm_var
        self.P[p, g] = -self.gm_var
        self.P[g, p] = -self.gm_var

    def set_ins_covariance(self, P: FloatArray) -> None:
        """Replace the 15 INS states' covariance (an alignment's, with the attitude tied to
        the biases); the receiver's correlated error keeps its start (:meth:`_start_at_fix`)."""
        self.P = np.zeros((self.n, self.n))
        self.P[:N_STATES, :N_STATES] = P
        self.P[N_STATES:, N_STATES:] = np.diag(self.gm_var[: self.n - N_STATES])
        self._start_at_fix()

    # ------------------------------------------------------------ state accessors

    @property
    def position(self) -> FloatArray:
        """The position estimate (3,), m, in the navigation frame (a copy)."""
        return np.array(self.nav.p)

    @property
    def velocity(self) -> FloatArray:
        """The velocity estimate (3,), m/s, in the navigation frame (a copy)."""
        return np.array(self.nav.v)

    @property
    def attitude_rpy(self) -> FloatArray:
        """Roll, pitch, yaw (3,), rad."""
        return np.array(quat_to_euler(self.nav.q))

    @property
    def accel_bias(self) -> FloatArray:
        """The accelerometer bias estimate (3,), m/s² (a copy)."""
        return np.array(self.b_a)

    @property
    def gyro_bias(self) -> FloatArray:
        """The gyro bias estimate (3,), rad/s (a copy)."""
        return np.array(self.b_g)

    # ------------------------------------------------------------ time update

    def propagate(self, t_s: float, gyro_rad_s: VecLike, accel_m_s2: VecLike) -> None:
        """Mechanise one IMU sample stamped ``t_s`` (the mean over the interval since the last).

        Raises EstimatorError for time going backwards, an IMU rate below ``min_imu_rate_hz``
        (median of the first samples) or a gap above ``max_imu_gap_s``.
        """
        dt = float(t_s) - self.t_s
        p = self.params
        if not dt > 0.0:
            raise EstimatorError(f"IMU time did not advance: {t_s!r} after {self.t_s!r} s")
        if dt > p.max_imu_gap_s:
            check_imu_rate(1.0 / dt, p.min_imu_rate_hz, f"IMU (interval {dt:.3g} s)")
            raise EstimatorError(
                f"IMU gap of {dt:.3g} s at t = {t_s:.3f} s exceeds max_imu_gap_s = "
                f"{p.max_imu_gap_s:g} s; the mechanisation cannot bridge it"
            )
        if len(self._dts) < _RATE_WINDOW:
            self._dts.append(dt)
            if len(self._dts) == _RATE_WINDOW:
                check_imu_rate(1.0 / float(np.median(self._dts)), p.min_imu_rate_hz)
        w = gyro_rad_s
        f = accel_m_s2
        omega = (float(w[0]) - self.b_g[0], float(w[1]) - self.b_g[1], float(w[2]) - self.b_g[2])
        f_b = (float(f[0]) - self.b_a[0], float(f[1]) - self.b_a[1], float(f[2]) - self.b_a[2])
        if not math.isfinite(omega[0] + omega[1] + omega[2] + f_b[0] + f_b[1] + f_b[2]):
            raise EstimatorError(f"non-finite IMU sample at t = {t_s}")
        cached_dt, q_e = self._q_earth_cache
        if cached_dt != dt:
            q_e = earth_step_quat(self.earth, dt)
            self._q_earth_cache = (dt, q_e)
        fn = mechanize(self.nav, omega, f_b, dt, self.earth, q_e)
        self.t_s = float(t_s)
        a = self._acc_fn
        a[0] += fn[0] * dt
        a[1] += fn[1] * dt
        a[2] += fn[2] * dt
        self._acc_dt += dt
        if self._acc_dt >= self._cov_dt - 1e-9:
            self._propagate_covariance()

    def _propagate_covariance(self) -> None:
        dt = self._acc_dt
        if dt <= 0.0:
            return
        fn = np.array(self._acc_fn) / dt  # mean specific force in n over the block
        c = quat_to_dcm(self.nav.q)
        F = np.zeros((self.n, self.n))
        F[0:3, 3:6] = np.eye(3)  # (E1)
        F[3:6, 0:3] = self._grav_grad  # (E2)
        F[3:6, 3:6] = -2.0 * self._omega_skew
        F[3:6, 6:9] = _skew(fn)
        F[3:6, 9:12] = -c
        F[6:9, 6:9] = -self._omega_skew  # (E3)
        F[6:9, 12:15] = c
        if self.n > N_STATES:  # (G1) ġ = −g/τ: the estimate decays as its mean does
            F[N_STATES:, N_STATES:] = -np.eye(3) / self.gm_tau
            self.gnss_wander = self.gnss_wander * math.exp(-dt / self.gm_tau)
        Fdt = F * dt
        Phi = np.eye(self.n) + Fdt + 0.5 * (Fdt @ Fdt)
        # P⁻ = Φ P Φᵀ + Q_d
        self.P = Phi @ self.P @ Phi.T + np.diag(self._q * dt)
        if self.bias_active:  # b is a random walk: Φ_b = I, Q_b = q_b Δt
            self._Pxb = Phi @ self._Pxb
            self._Pbb = self._Pbb + np.eye(3) * (self._q_bias * dt)
        self._acc_dt = 0.0
        self._acc_fn = [0.0, 0.0, 0.0]

    def inflate(self, k: float) -> None:
        """Widen the covariance by ``k >= 1`` (``P ← k P``; the bias block and its cross terms
        too): a consistency check found the claims too small for the error (ArduPilot EKF3's
        "inflate the variance" outcome of its GPS position check). The correlations are kept,
        so the next update corrects the attitude and biases that caused the error."""
        if not k > 1.0 or not math.isfinite(k):
            return
        self.P = self.P * k
        if self.bias_active:
            self._Pxb = self._Pxb * k
            self._Pbb = self._Pbb * k

    # ------------------------------------------------------------ measurement update

    def _h_fix(self, k: int) -> FloatArray:
        """Row ``k`` of ``H`` (0-2: the E, N, U position fix, 3-5: the velocity) over the
        filter's states: a position row selects δp_k and, with the receiver's correlated error
        in the state, g_k too, (G2) ``z = p + g + v``."""
        h = np.zeros(self.n)
        h[k] = 1.0
        if k < 3 and self.n > N_STATES:
            h[N_STATES + k] = 1.0
        return h

    def predicted_fix(self) -> tuple[FloatArray, FloatArray]:
        """What a healthy receiver should report now, ``p̂ + ĝ`` (E, N, U, m), and its
        covariance ``H P Hᵀ`` (3×3, m², without the receiver's white noise R or a fault's
        bias)."""
        zhat = np.array(self.nav.p)
        zhat[: len(self.gnss_wander)] += self.gnss_wander
        H = np.array([self._h_fix(k) for k in range(3)])
        return zhat, H @ self.P @ H.T

    def _observation(
        self, t_s: float, position_enu_m: VecLike, velocity_enu_m_s: VecLike | None,
    ) -> tuple[list[float], list[float], list[float], list[int]]:
        """``z``, its prediction ``ẑ`` (position ``p̂ + ĝ``, velocity ``v̂``), the white
        variances ``R_ii`` and the rows of ``H`` (:meth:`_h_fix`) of one fix."""
        prm = self.params
        z = [float(c) for c in position_enu_m[:3]]
        zhat = self.predicted_fix()[0].tolist()
        r = [prm.gnss_sigma_h_m**2, prm.gnss_sigma_h_m**2, prm.gnss_sigma_v_m**2]
        rows = [0, 1, 2]
        if velocity_enu_m_s is not None and prm.use_velocity:
            z += [float(c) for c in velocity_enu_m_s[:3]]
            zhat += list(self.nav.v)
            r += [prm.gnss_sigma_vel_m_s**2] * 3
            rows += [3, 4, 5]
        if not all(math.isfinite(c) for c in z):
            raise EstimatorError(f"non-finite GNSS observation at t = {t_s}: {z}")
        return z, zhat, r, rows

    def update(
        self,
        t_s: float,
        position_enu_m: VecLike,
        velocity_enu_m_s: VecLike | None = None,
    ) -> EpochReport:
        """GNSS fix at ``t_s`` (the filter must have been propagated to it): robust update."""
        if abs(float(t_s) - self.t_s) > self.params.max_imu_gap_s:
            raise EstimatorError(
                f"GNSS fix at t = {t_s:.3f} s but the INS is at t = {self.t_s:.3f} s; "
                "propagate the IMU up to the fix first"
            )
        self._propagate_covariance()
        z, zhat, r, rows = self._observation(t_s, position_enu_m, velocity_enu_m_s)
        verdict: Verdict | None = None
        if self.params.strategy == "fault_state":
            verdict = self._fault_verdict(z, zhat, r)
            if self.bias_active:
                return self._update_biased(float(t_s), z, zhat, r, rows, verdict)
        H = np.array([self._h_fix(k) for k in rows])
        # (2) ν = z − H x̂ ; (3) S = H P⁻ Hᵀ + R
        nu = np.array(z) - np.array(zhat)
        s_diag = np.einsum("ij,jk,ik->i", H, self.P, H) + np.array(r)
        decisions = self._gate(z, nu, s_diag, r, rows)
        P = self._readmit(decisions, nu, s_diag, rows)
        keep = [j for j, d in enumerate(decisions) if d.action is not Action.REJECT]
        if keep:
            y = np.array([decisions[j].value - zhat[j] for j in keep])  # ν' with the gate's value
            Rm = np.diag([decisions[j].variance for j in keep])
            p_prior, g_prior = np.array(self.nav.p), self.gnss_wander.copy()
            self._correct(P, H[keep], y, Rm)
            self._log_fix(float(t_s), p_prior, g_prior, np.diag(P)[:3].copy())
        else:
            self.y, self.S = np.zeros(0), np.zeros((0, 0))
        return EpochReport(float(t_s), decisions, verdict)

    def _log_fix(self, t_s: float, p_prior: FloatArray, g_prior: FloatArray,
                 ppp_prior: FloatArray) -> None:
        """(G5) Keep what this healthy update did to the position and the receiver's error
        (and ``P⁻_pp``) for ``rollback_max_s``, with the receiver modelled."""
        window = self.params.fault_state.rollback_max_s
        if self.n == N_STATES or window <= 0.0:
            return
        log = self._fix_log
        log.append((t_s, np.array(self.nav.p) - p_prior, self.gnss_wander - g_prior, ppp_prior))
        while log and log[0][0] < t_s - window:
            log.popleft()

    def _gate(self, z: list[float], nu: FloatArray, s_diag: FloatArray, r: list[float],
              rows: list[int]) -> tuple[GateDecision, ...]:
        """(7)–(8): the per-dimension three-zone gate, after the lock-in breaker's look at the
        position fix as a whole (each position gate sees the tracker's verdict on its own
        component: a fault in east and north does not make a normal up value faulty,
        section 2.1)."""
        receiver: ReceiverState | None = None
        if self.gates[0].tracks_jumps:
            t2 = self.params.three_zone.t2
            receiver = self.position_tracker.update(
                nu[:3].tolist(), s_diag[:3].tolist(), r[:3],
                [float(nu[j]) ** 2 > t2 * float(s_diag[j]) for j in range(3)],
            )
        decisions = tuple(
            self.gates[k].step(
                z[j], float(nu[j]), float(s_diag[j]), r[j],
                receiver=receiver.component(j) if receiver is not None and k < 3 else None,
            )
            for j, k in enumerate(rows)
        )
        if any(d.readmit for d in decisions[:3]):
            self.position_tracker.clear()  # the state is corrected below: a step in ν follows
        return decisions

    def _readmit(self, decisions: Sequence[GateDecision], nu: FloatArray, s_diag: FloatArray,
                 rows: list[int]) -> FloatArray:
        """``P⁻`` for the update: a receiver accepted again after max_replacements over-limit
        epochs found the INS drifted beyond its covariance; ``P_kk`` is raised so that
        ``S_ii = ν_i²`` and the fix pulls the state back (velocity and attitude follow through
        the correlations). ``self.P`` itself when no gate readmits."""
        P = self.P
        for j, d in enumerate(decisions):
            if d.readmit and float(nu[j]) ** 2 > float(s_diag[j]):
                k = rows[j]
                P = P.copy() if P is self.P else P
                P[k, k] += float(nu[j]) ** 2 - float(s_diag[j])
        return P

    def _correct(self, P: FloatArray, H: FloatArray, y: FloatArray, Rm: FloatArray) -> None:
        """(4)–(6): ``K = P Hᵀ S⁻¹``, ``δx̂ = K y``, Joseph form
        ``P⁺ = (I − KH)P(I − KH)ᵀ + KRKᵀ``; the correction fed back (:meth:`_inject`)."""
        PHt = P @ H.T
        S = H @ PHt + Rm
        K = np.linalg.solve(S, PHt.T).T  # K = P Hᵀ S⁻¹
        IKH = np.eye(self.n) - K @ H
        self.P = IKH @ P @ IKH.T + K @ Rm @ K.T  # Joseph form
        self.P = 0.5 * (self.P + self.P.T)
        self.y, self.S = y, S
        self._inject(K @ y)

    def coast(self, t_s: float, velocity_enu_m_s: VecLike | None = None) -> None:
        """No position fix at ``t_s``: the INS coasts (a plain velocity update when the preset
        uses velocity and one is given). The reference against which a fault's error is
        bounded (``firmware_host.devtools.insgnss_sim.run_coast``)."""
        self._propagate_covariance()
        if velocity_enu_m_s is None or not self.params.use_velocity:
            return
        y = np.array([float(c) for c in velocity_enu_m_s[:3]]) - np.array(self.nav.v)
        self._select_update(3, y, np.eye(3) * self.params.gnss_sigma_vel_m_s**2)

    def zero_velocity(self, sigma_m_s: float) -> None:
        """Zero-velocity update (ZUPT): the vehicle is known to be at rest, ``v = 0`` with
        1σ ``sigma_m_s`` per axis, a plain Kalman update of the velocity states, (2)-(6) with
        ``H`` selecting them; after :meth:`update` or :meth:`coast` at the same time (the
        covariance is not propagated here). Used by the live vehicle's alignment at rest."""
        self._select_update(3, -np.array(self.nav.v), np.eye(3) * float(sigma_m_s) ** 2)

    def zero_rate(self, gyro_mean_rad_s: VecLike, sigma_rad_s: float,
                  gate: float = 21.108) -> bool:
        """Zero-angular-rate update (ZARU): the vehicle is known not to turn, so the mean gyro
        over the epoch is its bias plus the Earth's rate, ``z = ω̄ − Ĉᵀ ω_ie^n = b_g + w``,
        1σ ``sigma_rad_s`` per axis; ``H`` selects the gyro bias states, (2)-(6) as
        :meth:`zero_velocity` (after it, at the same time). Skipped (False) when the
        innovation's ``νᵀ S⁻¹ ν`` exceeds ``gate`` (χ²₃ at 1 − 10⁻⁴: a slow turn the rest
        detector let through is not a bias)."""
        c = quat_to_dcm(self.nav.q)
        w_ie_b = c.T @ np.array(self.earth.omega_ie_n)
        y = np.array([float(v) for v in gyro_mean_rad_s[:3]]) - w_ie_b - np.array(self.b_g)
        Rm = np.eye(3) * float(sigma_rad_s) ** 2
        S = self.P[12:15, 12:15] + Rm
        if float(y @ np.linalg.solve(S, y)) > gate:
            return False
        self._select_update(12, y, Rm)
        return True

    def _select_update(self, first: int, y: FloatArray, Rm: FloatArray) -> None:
        """(4)–(6) for an observation of the three states ``first .. first + 2`` (``H``
        selects them): ``K = P Hᵀ S⁻¹``, ``δx̂ = K y``, Joseph form; while a fault's bias is in
        the state (strategy "fault_state") on the augmented covariance, so that its blocks
        ``P_xb``, ``P_bb`` stay consistent with ``P`` (a ZUPT at rest goes on during a fault)."""
        sel = slice(first, first + 3)
        P = self._augmented() if self.bias_active else self.P
        PHt = P[:, sel]
        S = P[sel, sel] + Rm
        K = np.linalg.solve(S, PHt.T).T
        IKH = np.eye(len(P))
        IKH[:, sel] -= K
        P = IKH @ P @ IKH.T + K @ Rm @ K.T
        self._set_augmented(0.5 * (P + P.T), K @ y)

    def _augmented(self) -> FloatArray:
        """The covariance of ``[δx, b]`` (the fault's bias last), from ``P``, ``P_xb``, ``P_bb``."""
        m = self.n
        Pa = np.zeros((m + 3, m + 3))
        Pa[:m, :m] = self.P
        Pa[:m, m:] = self._Pxb
        Pa[m:, :m] = self._Pxb.T
        Pa[m:, m:] = self._Pbb
        return Pa

    def _set_augmented(self, P: FloatArray, dx: FloatArray) -> None:
        """Store an updated covariance (``[δx]`` or ``[δx, b]``) and feed back ``dx``."""
        m = self.n
        self.P = P[:m, :m].copy() if len(P) > m else P
        if len(P) > m:
            self._Pxb = P[:m, m:].copy()
            self._Pbb = P[m:, m:].copy()
            self.gnss_bias = self.gnss_bias + dx[m:]
        self._inject(dx[:m])

    # ------------------------------------------------------------ strategy "fault_state"

    def _fault_verdict(self, z: list[float], zhat: list[float], r: list[float]) -> Verdict:
        """The monitor's decision on this fix (fdi.gnss_fault); opens / drops the bias state."""
        nu0 = np.array(z[:3]) - np.array(zhat[:3])
        hph = self.predicted_fix()[1]
        s0 = hph + np.diag(r[:3])  # S0 = H0 P H0ᵀ + R
        mon = self.fault_monitor
        self._corr_p = self._corr_p + self._corr_v * (self.t_s - self._corr_t)
        self._corr_t = self.t_s
        a = nu0 + self._corr_p  # z − ĝ − (p̂ − c_p): the receiver minus the uncorrected INS
        rv = np.array(r[:3])
        t_w = float(self.params.fault_state.window)
        gm = np.zeros(3)  # the receiver's correlated error: its uncertainty now (G1)
        gm_inc = np.zeros(3)  # and its change over the window, 2σ²(1 − e^(−T/τ))
        if self.n > N_STATES:
            gm = np.diag(self.P)[N_STATES:].copy()
            gm_inc = 2.0 * self.gm_var * (1.0 - math.exp(-t_w / self.gm_tau))
        if not self.bias_active:
            # the INS's own increment over the window: velocity error over T plus the white
            # accelerometer noise, P_vv T² + q_a T³/3, with T the window's length
            var_inc = rv + gm_inc + np.diag(self.P)[3:6] * t_w**2 + self._q[3:6] * t_w**3 / 3.0
            walk = self._walk_step(nu0, s0)
            verdict = mon.healthy_epoch(nu0, s0, a, rv + gm, var_inc, beyond_model=walk)
            if verdict is Verdict.ONSET:
                if walk:  # (G5) the walk's fixes taken back out: the INS coasts from before it
                    self._rollback()
                self._walk_c[:] = 0.0
                self._fix_log.clear()
                # open b ~ N(0, σ_b0² I), uncorrelated: this epoch's update puts the jump in b
                self.bias_active = True
                self.gnss_bias = np.zeros(3)
                self._Pxb = np.zeros((self.n, 3))
                self._Pbb = np.eye(3) * self.params.fault_state.bias_sigma0_m**2
            return verdict
        h1 = np.eye(3, self.n)  # H1 = [I 0 … | I_b]: δp and b, (G6)
        pxb = h1 @ self._Pxb
        nu1 = nu0 + self._wander3() - self.gnss_bias  # ν1 = z − p̂ − b̂
        s1_ins = s0 if self.n == N_STATES else h1 @ self.P @ h1.T + np.diag(r[:3])
        s1 = s1_ins + pxb + pxb.T + self._Pbb  # S1 = H1 P H1ᵀ + R
        verdict = mon.faulted_epoch(nu0, s0, nu1, s1, a, rv + gm)
        if verdict is Verdict.RETURN:
            # b jumps back to 0: marginalise it out (its old estimate says nothing now)
            self.bias_active = False
            self.gnss_bias = np.zeros(3)
            self._Pxb = np.zeros((self.n, 3))
            self._Pbb = np.zeros((3, 3))
        elif verdict is Verdict.RELEVEL:
            self._Pbb = self._Pbb + np.eye(3) * self.params.fault_state.bias_sigma0_m**2
        return verdict

    def _wander3(self) -> FloatArray:
        """``ĝ`` (E, N, U, m), zeros without the receiver's correlated error in the state."""
        return self.gnss_wander if self.n > N_STATES else np.zeros(3)

    def _walk_step(self, nu0: FloatArray, s0: FloatArray) -> bool:
        """(G3) One epoch of the walk test (with the receiver modelled): Page's CUSUM of the
        normalised position innovations per axis and side; True when one is above
        ``walk_h_sigma``. A CUSUM at 0 before this epoch starts a run here (its start dates
        the walk, (G5))."""
        if self.n == N_STATES:
            return False
        fs = self.params.fault_state
        u = nu0 / np.sqrt(np.diag(s0))  # ν_i/√S_ii
        c = self._walk_c
        self._walk_t0[c <= 0.0] = self.t_s
        c[0] = np.maximum(0.0, c[0] + u - fs.walk_k_sigma)  # C⁺
        c[1] = np.maximum(0.0, c[1] - u - fs.walk_k_sigma)  # C⁻
        return bool(c.max() > fs.walk_h_sigma)

    def _rollback(self) -> None:
        """(G5) The walk's fixes taken back out: the position and receiver-error corrections of
        the healthy updates since the start of the CUSUM run that opened the fault (the
        largest), and ``P_pp`` back to at least its prior before the first of them (its
        diagonal raised: ``P`` stays positive definite)."""
        c = self._walk_c
        side, axis = np.unravel_index(int(np.argmax(c)), c.shape)
        t_start = float(self._walk_t0[side, axis])
        taken = [e for e in self._fix_log if e[0] >= t_start]
        if not taken:
            return
        dx = np.zeros(self.n)
        dx[0:3] = -np.sum([e[1] for e in taken], axis=0)
        dx[N_STATES:] = -np.sum([e[2] for e in taken], axis=0)
        self._inject(dx)  # through the corrections' record too: p̂ − c_p is unchanged
        idx = np.arange(3)
        self.P[idx, idx] += np.maximum(0.0, taken[0][3] - np.diag(self.P)[:3])
        self.rollbacks += 1

    def _update_biased(
        self, t_s: float, z: list[float], zhat: list[float], r: list[float], rows: list[int],
        verdict: Verdict,
    ) -> EpochReport:
        """Update of the 18-state filter ``[δx, b]`` under H1: position ``z = p + b + v``,
        velocity as usual (through its gates)."""
        m = self.n
        n = m + 3
        Pa = self._augmented()
        decisions: list[GateDecision] = []
        h_rows: list[FloatArray] = []
        y: list[float] = []
        rv: list[float] = []
        for j, k in enumerate(rows):
            nu = z[j] - zhat[j]
            if k < 3:
                # the fix informs b and, through b's constancy, the INS's changes; judged
                # against the healthy prediction for the zone counts
                hk = self._h_fix(k)
                s0 = float(hk @ self.P @ hk) + r[j]
                dm = nu * nu / s0
                zone = classify(dm, self.params.three_zone.t1, self.params.three_zone.t2)
                decisions.append(GateDecision(zone, Action.REJECT, dm, z[j], math.inf))
                h = np.zeros(n)
                h[k] = 1.0  # (G6) z = p + b + v: the bias holds the receiver's whole error
                h[m + k] = 1.0
                h_rows.append(h)
                y.append(nu + float(self._wander3()[k]) - float(self.gnss_bias[k]))
                rv.append(r[j])
                continue
            d = self.gates[k].step(z[j], nu, float(self.P[k, k]) + r[j], r[j])
            decisions.append(d)
            if d.action is not Action.REJECT:
                h = np.zeros(n)
                h[k] = 1.0
                h_rows.append(h)
                y.append(d.value - zhat[j])
                rv.append(d.variance)
        H = np.array(h_rows)
        Rm = np.diag(rv)
        yv = np.array(y)
        PHt = Pa @ H.T
        S = H @ PHt + Rm
        K = np.linalg.solve(S, PHt.T).T  # K = P Hᵀ S⁻¹
        dx = K @ yv
        IKH = np.eye(n) - K @ H
        Pa = IKH @ Pa @ IKH.T + K @ Rm @ K.T  # Joseph form
        self.y, self.S = yv, S
        self._set_augmented(0.5 * (Pa + Pa.T), dx)
        return EpochReport(t_s, tuple(decisions), verdict)

    def _inject(self, dx: FloatArray) -> None:
        """Feed the error estimate back into the nominal state; δx̂ ← 0."""
        n = self.nav
        self._corr_p = self._corr_p + dx[0:3]
        self._corr_v = self._corr_v + dx[3:6]
        # Python floats from here on: the nominal state is mechanised at the IMU rate, and
        # arithmetic on NumPy scalars is several times slower (the same IEEE doubles).
        d = dx.tolist()
        n.p = (n.p[0] + d[0], n.p[1] + d[1], n.p[2] + d[2])
        n.v = (n.v[0] + d[3], n.v[1] + d[4], n.v[2] + d[5])
        # C_b^n = (I − [φ×]) Ĉ  →  Ĉ ← Exp(−φ) Ĉ
        n.q = quat_normalize(quat_mul(quat_exp(-d[6], -d[7], -d[8]), n.q))
        self.b_a = (self.b_a[0] + d[9], self.b_a[1] + d[10], self.b_a[2] + d[11])
        self.b_g = (self.b_g[0] + d[12], self.b_g[1] + d[13], self.b_g[2] + d[14])
        if self.n > N_STATES:
            self.gnss_wander = self.gnss_wander + dx[N_STATES:self.n]
        self.x = np.zeros(self.n)


def _vec3(a: VecLike) -> Vec3:
    return (float(a[0]), float(a[1]), float(a[2]))
