"""The INS/GNSS filter's parameters and Earth model, without numpy.

Split from :mod:`fdi.insgnss` and :mod:`fdi.gnss_fault` (which re-export every name) so that a
configuration file can be loaded, and a rover replay started, without importing numpy (issue
19: start-up). The equations that use them are in those modules.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

from fdi.chi2 import chi2_ppf
from fdi.three_zone import ThreeZoneParams

Vec3 = tuple[float, float, float]
InsGnssStrategy = Literal["none", "downweight", "replace", "three_zone", "fault_state"]

OMEGA_IE = 7.2921151467e-5  # Earth rotation rate, rad/s (WGS 84)
EARTH_RADIUS_M = 6_371_008.8  # mean radius of the spherical Earth model, m
STANDARD_G = 9.80665  # m/s² per g
DEG = math.pi / 180.0
DIMS = 3  # E, N, U position (the fault-state test)


def normal_gravity(latitude_deg: float) -> float:
    """Somigliana normal gravity on the WGS 84 ellipsoid, m/s²."""
    s2 = math.sin(latitude_deg * DEG) ** 2
    return 9.7803253359 * (1 + 0.00193185265241 * s2) / math.sqrt(1 - 0.00669437999013 * s2)


@dataclass(frozen=True)
class EarthModel:
    """Spherical Earth seen from a tangent plane at ``latitude_deg`` (see the module docstring)."""

    latitude_deg: float = 34.25
    rotation: bool = True

    @cached_property
    def g0(self) -> float:
        """Normal gravity at ``latitude_deg`` on the ellipsoid, m/s²."""
        return normal_gravity(self.latitude_deg)

    @cached_property
    def _g0_r2(self) -> float:
        return self.g0 * EARTH_RADIUS_M**2

    @cached_property
    def omega_ie_n(self) -> Vec3:
        """Earth rate in ENU, rad/s."""
        if not self.rotation:
            return (0.0, 0.0, 0.0)
        lat = self.latitude_deg * DEG
        return (0.0, OMEGA_IE * math.cos(lat), OMEGA_IE * math.sin(lat))

    def gravity(self, p: Vec3) -> Vec3:
        """Gravity vector at ENU position p (m), m/s²."""
        rx, ry, rz = p[0], p[1], p[2] + EARTH_RADIUS_M
        r2 = rx * rx + ry * ry + rz * rz
        k = -self._g0_r2 / (r2 * math.sqrt(r2))
        return (k * rx, k * ry, k * rz)


@dataclass(frozen=True)
class FaultStateParams:
    """The ``[filter.fault_state]`` table of ``config/insgnss.toml``."""

    alpha_onset: float = field(default=0.01, metadata={
        "ge": 1e-15, "le": 0.5, "doc": "onset significance: T_on = χ²₃(1 − α_on)", "unit": "-"})
    window: int = field(default=4, metadata={
        "ge": 1, "le": 64, "doc": "innovation history of the jump test", "unit": "epochs"})
    return_log_lr: float = field(default=2.3026, metadata={
        "gt": 0.0, "unit": "-", "doc": "CUSUM threshold on ln L(H0)/L(H1) to return (ln 10: ten "
                                       "to one)"})
    bias_sigma0_m: float = field(default=1000.0, metadata={
        "gt": 0.0, "unit": "m", "doc": "prior 1σ of the bias at an onset"})
    bias_rw_m_sqrt_s: float = field(default=0.01, metadata={
        "ge": 0.0, "doc": "random walk of the bias while faulted", "unit": "m/√s"})
    max_prior_ratio: float = field(default=0.25, metadata={
        "gt": 0.0, "doc": "open a fault only while P⁻_ii ≤ ratio · R_ii (coasting on the INS "
                          "beats the fix)", "unit": "-"})
    # With the receiver's correlated error modelled (gnss_gm_sigma_m > 0, fdi/insgnss.py (G3),
    # (G5)): the walk test, Page's CUSUM of the normalised position innovations.
    walk_k_sigma: float = field(default=0.5, metadata={
        "ge": 0.0, "le": 10.0, "unit": "σ", "doc": "receiver modelled: the walk test's "
        "allowance, per axis, in σ of the innovation (a walk shifts it by more)"})
    walk_h_sigma: float = field(default=8.0, metadata={
        "gt": 0.0, "le": 1000.0, "unit": "σ", "doc": "receiver modelled: the walk test's "
        "threshold (its false-alarm interval ~e^(2kh)/(2k²) epochs per axis and side)"})
    rollback_max_s: float = field(default=30.0, metadata={
        "ge": 0.0, "le": 600.0, "unit": "s", "doc": "receiver modelled: at a walk's onset the "
        "fixes since its estimated start, at most this long ago, are taken back out of the "
        "position (0: off)"})

    @cached_property
    def t_onset(self) -> float:
        """T_on = χ²₃(1 − α_on) (11.345 at α_on = 0.01)."""
        return chi2_ppf(1.0 - self.alpha_onset, DIMS)


@dataclass(frozen=True)
class ImuErrorModel:
    """IMU errors: 1σ turn-on bias and white-noise densities (per axis).

    Defaults: a MEMS autopilot IMU after its turn-on calibration (ICM-42688 / BMI088 class).
    """

    gyro_bias_deg_h: float = field(default=30.0, metadata={
        "ge": 0.0, "doc": "1σ gyro bias", "unit": "deg/h"})
    gyro_arw_deg_sqrt_h: float = field(default=0.2, metadata={
        "ge": 0.0, "doc": "angle random walk", "unit": "deg/√h"})
    accel_bias_ug: float = field(default=2000.0, metadata={
        "ge": 0.0, "doc": "1σ accel bias", "unit": "µg"})
    accel_vrw_ug_sqrt_hz: float = field(default=70.0, metadata={
        "ge": 0.0, "doc": "accelerometer white noise density", "unit": "µg/√Hz"})
    gyro_bias_drift_deg_s_per_min: float = field(default=0.0, metadata={
        "ge": 0.0, "doc": "how fast the gyro bias may drift (a MEMS gyro warming up; ArduPilot's "
                          "simulated IMU: 0.05): its random walk reaches this change in one "
                          "minute at 1σ", "unit": "(deg/s)/min"})

    @property
    def gyro_bias_rad_s(self) -> float:
        """The gyro bias 1σ in rad/s (configured in deg/h)."""
        return self.gyro_bias_deg_h * DEG / 3600.0

    @property
    def gyro_bias_rw_rad_s2(self) -> float:
        """PSD of the gyro bias random walk, (rad/s)²/s: the configured 1σ over an hour, and
        the drift's change over a minute, ``(r · 60 s)² / 60 s``."""
        r = self.gyro_bias_drift_deg_s_per_min * DEG / 60.0  # rad/s²
        return self.gyro_bias_rad_s**2 / 3600.0 + r * r * 60.0

    @property
    def gyro_arw_rad_sqrt_s(self) -> float:
        """The gyro angle random walk in rad/√s (configured in deg/√h)."""
        return self.gyro_arw_deg_sqrt_h * DEG / 60.0

    @property
    def accel_bias_m_s2(self) -> float:
        """The accelerometer bias 1σ in m/s² (configured in µg)."""
        return self.accel_bias_ug * 1e-6 * STANDARD_G

    @property
    def accel_vrw_m_s_sqrt_s(self) -> float:
        """The accelerometer velocity random walk in m/s/√s (configured in µg/√Hz)."""
        return self.accel_vrw_ug_sqrt_hz * 1e-6 * STANDARD_G


@dataclass(frozen=True)
class InsGnssParams:
    """Filter parameters (the ``[filter]`` table of ``config/insgnss*.toml``)."""

    strategy: InsGnssStrategy = field(
        default="fault_state", metadata={"doc": "robust treatment (the paper's: three_zone)"})
    three_zone: ThreeZoneParams = field(default_factory=ThreeZoneParams)
    fault_state: FaultStateParams = field(default_factory=FaultStateParams)
    imu: ImuErrorModel = field(default_factory=ImuErrorModel)
    gnss_sigma_h_m: float = field(default=3.0, metadata={
        "gt": 0.0, "doc": "R: E/N 1σ", "unit": "m"})
    gnss_sigma_v_m: float = field(default=5.0, metadata={"gt": 0.0, "doc": "R: up 1σ", "unit": "m"})
    gnss_sigma_vel_m_s: float = field(default=0.1, metadata={
        "gt": 0.0, "unit": "m/s", "doc": "R: GNSS velocity 1σ per axis"})
    gnss_gm_sigma_m: float = field(default=0.0, metadata={
        "off": 0.0, "ge": 0.001, "le": 100.0, "unit": "m",
        "doc": "1σ per horizontal axis of the receiver's slowly varying error (multipath, "
               "atmosphere, a DGPS correction's age): a first-order Gauss-Markov state per axis "
               "(E, N, U) in the filter, z = p + g + v; gnss_sigma_h_m / gnss_sigma_v_m are "
               "then the white rest (0: off, the fix's error white). A DGPS receiver: its "
               "[rover.detector] sigma_m"})
    gnss_gm_sigma_up_m: float = field(default=0.7, metadata={
        "gt": 0.0, "le": 100.0, "unit": "m",
        "doc": "the same error's 1σ up (with gnss_gm_sigma_m > 0; a DGPS receiver: its "
               "[rover.detector] sigma_up_m)"})
    gnss_gm_tau_s: float = field(default=60.0, metadata={
        "ge": 1.0, "le": 86400.0, "unit": "s",
        "doc": "correlation time of that error: ġ = −g/τ + w, E[g²] = gnss_gm_sigma_m²"})
    use_velocity: bool = field(default=True, metadata={"doc": "use GNSS velocity when given"})
    latitude_deg: float = field(default=34.25, metadata={
        "ge": -89.0, "le": 89.0, "unit": "deg",
        "doc": "latitude of the tangent plane (normal gravity, Earth rate)"})
    earth_rotation: bool = field(default=True, metadata={
        "doc": "model the Earth's rotation in the mechanisation"})
    min_imu_rate_hz: float = field(default=20.0, metadata={
        "ge": 10.0, "unit": "Hz", "doc": "an IMU slower than this (median of the first "
                                         "intervals) is refused"})
    max_imu_gap_s: float = field(default=0.25, metadata={
        "gt": 0.0, "unit": "s", "doc": "a gap between IMU samples longer than this is refused "
                                       "(the mechanisation cannot bridge it)"})
    cov_rate_hz: float = field(default=10.0, metadata={
        "gt": 0.0, "doc": "P propagation rate", "unit": "Hz"})
    init_sigma_pos_m: float = field(default=3.0, metadata={
        "gt": 0.0, "unit": "m", "doc": "initial 1σ of the position"})
    init_sigma_vel_m_s: float = field(default=0.1, metadata={
        "gt": 0.0, "unit": "m/s", "doc": "initial 1σ of the velocity"})
    init_sigma_tilt_deg: float = field(default=0.5, metadata={
        "gt": 0.0, "unit": "deg", "doc": "initial 1σ of roll and pitch"})
    init_sigma_yaw_deg: float = field(default=2.0, metadata={
        "gt": 0.0, "unit": "deg", "doc": "initial 1σ of the heading"})

    @property
    def earth(self) -> EarthModel:
        """The Earth model at the configured latitude, with or without its rotation."""
        return EarthModel(self.latitude_deg, self.earth_rotation)
