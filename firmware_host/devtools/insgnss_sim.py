"""INS/GNSS navigation data generator, the paper's fault scenarios and ``fdi-bridge sim insgnss``.

Cai & Shao simulated an aircraft for 501 s at 1 s steps, turned its trajectory into IMU and
GNSS data with errors, and injected GNSS faults. This module does the same:

- trajectory: a small aircraft at 60 m/s (climb, turns, acceleration, S-turns, descent),
  coordinated turns (roll = atan(V ψ̇ / g)), on the tangent plane of :mod:`fdi.insgnss`;
- IMU at ``imu_rate_hz`` (100 Hz): the exact inverse of the filter's mechanisation
  (:func:`fdi.insgnss.invert_mechanization`) plus a constant turn-on bias (drawn per run) and
  white noise, from ``[sim.imu]``;
- GNSS at 1 Hz: true position plus white noise (σ = ``gnss_sigma_h_m`` east/north,
  ``gnss_sigma_v_m`` up) and velocity plus white noise;
- optionally a lead-in before the paper's t = 0 (``[sim] rest_s``, ``takeoff_s``; none by
  default): at rest, then a straight take-off roll up to the paper's speed, without faults, so
  that a vehicle can align itself as a real one does (the live INS/GNSS of
  docs/insgnss-live.md); the offline filter runs through it too (a zero-velocity update at
  each rest epoch, as the live vehicle does), and the results are those of the paper's epochs;
- scenarios (faults added to the GNSS position, epochs are whole seconds 1..500):
  ``paper-random`` 100 distinct random epochs, +100 m east and north, +20 m up;
  ``paper-single`` every 10 s, +100/+100/+20 m; ``paper-continuous`` every epoch 10..200 s,
  +100/+100/+20 m; ``paper-deviation`` every 10 s, +20/+20/+4 m (the paper's deviation study
  used faults every 10 s; up keeps paper-random's 5:1 ratio; the *easier* Table 2 scenario);
  ``table2-calibrated`` every 10 s a zero-mean draw with 1σ ``table2_fault_h_m`` /
  ``table2_fault_v_m`` (the paper's "20 m of observation noise"; with
  ``config/insgnss-table2.toml`` the calibrated Table 2, docs/insgnss.md); ``clean`` no faults.

The same data runs through the five strategies (none, downweight, replace, three_zone,
fault_state) and
the summary gives per method min/max/RMS of the E, N, U position and velocity errors
(estimate − truth, at the 500 GNSS epochs after the update) and the zone/action counts.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import time
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from fdi.errors import ConfigError
from fdi.insgnss import (
    DEG,
    INS_STRATEGIES,
    EarthModel,
    InsGnssFilter,
    InsGnssParams,
    InsGnssStrategy,
    NavState,
    earth_step_quat,
    euler_to_quat,
    invert_mechanization,
)
from fdi.three_zone import Action, Zone
from firmware_host.commands.checks import input_file_arg, output_dir_arg
from firmware_host.commands.tables import table
from firmware_host.insgnss.align import zaru_sigma
from firmware_host.runtime.config import CONFIG_DIR as CONFIG_DIR
from firmware_host.runtime.config import insgnss_setup, load_bridge_file
from firmware_host.runtime.config_insgnss import InsGnssSetup as InsGnssSetup
from firmware_host.runtime.config_insgnss import InsGnssSimParams as InsGnssSimParams

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.floating[Any]]
Scenario = Literal["clean", "paper-random", "paper-single", "paper-continuous", "paper-deviation",
                   "table2-calibrated"]
SCENARIOS: tuple[Scenario, ...] = (
    "clean",
    "paper-random",
    "paper-single",
    "paper-continuous",
    "paper-deviation",
    "table2-calibrated",
)
PAPER_PRESET = CONFIG_DIR / "insgnss-paper.toml"


def load_setup(path: str | Path | None = None) -> InsGnssSetup:
    """Load a file or preset (default: ``insgnss-paper``; built-in defaults if absent)."""
    if path is None:
        if not PAPER_PRESET.is_file():
            return InsGnssSetup()
        path = PAPER_PRESET
    return insgnss_setup(load_bridge_file(path))


# ---------------------------------------------------------------- trajectory and sensors


def _box(t: FloatArray, a: float, b: float, ramp: float = 3.0) -> FloatArray:
    """Smooth indicator of [a, b] (tanh edges, ``ramp`` seconds)."""
    return 0.5 * (np.tanh((t - a) / ramp) - np.tanh((t - b) / ramp))


# (start s, end s, yaw rate deg/s, flight-path angle deg, acceleration m/s²)
_FLIGHT_PLAN: tuple[tuple[float, float, float, float, float], ...] = (
    (20, 50, 0.0, 4.0, 0.0),
    (60, 120, 1.5, 0.0, 0.0),
    (130, 170, 0.0, 0.0, 0.4),
    (180, 240, -3.0, 0.0, 0.0),
    (250, 290, 0.0, -3.0, 0.0),
    (300, 340, 2.0, 0.0, 0.0),
    (340, 380, -2.0, 0.0, 0.0),
    (390, 430, 0.0, 0.0, -0.3),
    (440, 480, 2.0, 2.0, 0.0),
)


@dataclass
class Trajectory:
    """Truth on the IMU grid: times (s), positions/velocities ENU (N×3), quaternions (N×4)."""

    t: FloatArray
    p: FloatArray
    v: FloatArray
    q: FloatArray
    rpy: FloatArray


def make_trajectory(duration_s: float, rate_hz: int, speed_m_s: float,
                    earth: EarthModel, rest_s: int = 0, takeoff_s: int = 0) -> Trajectory:
    """The aircraft of the experiment, sampled at ``rate_hz`` from t = 0 to ``duration_s``;
    position by (M3). With ``rest_s > 0`` a lead-in comes first (t < 0): ``rest_s`` at rest,
    level, heading 30°, then a straight take-off roll of ``takeoff_s`` from 0 to
    ``speed_m_s`` (speed by the quintic smooth step: acceleration zero at both ends), so the
    paper's flight starts at t = 0 as without it."""
    n = round(duration_s * rate_hz) + 1
    dt = 1.0 / rate_hz
    t = np.arange(n) * dt
    yaw_rate = np.zeros(n)
    gamma = np.zeros(n)
    acc = np.zeros(n)
    for a, b, r, g, ac in _FLIGHT_PLAN:
        box = _box(t, a, b)
        yaw_rate += r * DEG * box
        gamma += g * DEG * box
        acc += ac * box
    cumtrapz = np.concatenate([[0.0], np.cumsum(0.5 * (acc[1:] + acc[:-1]) * dt)])
    speed = speed_m_s + cumtrapz
    yaw = 30.0 * DEG + np.concatenate([[0.0], np.cumsum(0.5 * (yaw_rate[1:] + yaw_rate[:-1]) * dt)])
    if rest_s > 0:
        n_lead = (rest_s + takeoff_s) * rate_hz
        t_lead = (np.arange(n_lead) - n_lead) * dt
        tau = np.clip((t_lead + takeoff_s) / takeoff_s, 0.0, 1.0)
        t = np.concatenate([t_lead, t])
        speed = np.concatenate([speed_m_s * tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2), speed])
        yaw = np.concatenate([np.full(n_lead, 30.0 * DEG), yaw])
        yaw_rate = np.concatenate([np.zeros(n_lead), yaw_rate])
        gamma = np.concatenate([np.zeros(n_lead), gamma])
    roll = np.arctan(speed * yaw_rate / earth.g0)
    pitch = gamma
    v = np.stack(
        [speed * np.cos(gamma) * np.sin(yaw), speed * np.cos(gamma) * np.cos(yaw),
         speed * np.sin(gamma)], axis=1
    )
    p = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (v[1:] + v[:-1]) * dt, axis=0)])
    q = np.array([euler_to_quat(r_, p_, y_) for r_, p_, y_ in zip(roll, pitch, yaw, strict=True)])
    return Trajectory(t, p, v, q, np.stack([roll, pitch, yaw], axis=1))


def ideal_imu(traj: Trajectory, earth: EarthModel) -> tuple[FloatArray, FloatArray]:
    """Error-free gyro (rad/s) and specific force (m/s²), row k for the interval (k−1, k]."""
    n = len(traj.t)
    dt = float(traj.t[1] - traj.t[0])
    q_e = earth_step_quat(earth, dt)
    gyro = np.zeros((n, 3))
    accel = np.zeros((n, 3))
    # Python floats, not NumPy scalars: the same doubles, several times faster to compute with
    qs, vs, ps = traj.q.tolist(), traj.v.tolist(), traj.p.tolist()
    prev = NavState(tuple(qs[0]), tuple(vs[0]), tuple(ps[0]))
    for k in range(1, n):
        cur = NavState(tuple(qs[k]), tuple(vs[k]), tuple(ps[k]))
        w, f = invert_mechanization(prev, cur, dt, earth, q_e)
        gyro[k] = w
        accel[k] = f
        prev = cur
    return gyro, accel


@lru_cache(maxsize=4)
def _truth(epochs: int, rate: int, speed_m_s: float, earth: EarthModel, rest_s: int = 0,
           takeoff_s: int = 0) -> tuple[Trajectory, FloatArray, FloatArray]:
    """Trajectory and error-free IMU, shared by every seed and scenario (read-only arrays)."""
    traj = make_trajectory(epochs - 1, rate, speed_m_s, earth, rest_s, takeoff_s)
    gyro, accel = ideal_imu(traj, earth)
    for a in (traj.t, traj.p, traj.v, traj.q, traj.rpy, gyro, accel):
        a.flags.writeable = False
    return traj, gyro, accel


@dataclass
class NavData:
    """One generated run: truth, IMU, GNSS (with faults) and the filter's initial state."""

    traj: Trajectory
    gyro: FloatArray
    accel: FloatArray
    gnss_t: FloatArray
    gnss_p: FloatArray  # with faults
    gnss_v: FloatArray
    fault: FloatArray  # the fault added at each GNSS epoch (E, N, U), m
    init_p: FloatArray
    init_v: FloatArray
    init_rpy: FloatArray
    imu_bias: dict[str, list[float]]
    lead: int = 0  # GNSS epochs of lead-in (``[sim] rest_s``) before the paper's t = 0
    rest: int = 0  # of which the first this many (after epoch 0) are at rest
    zupt_sigma_m_s: float = 0.01  # at rest: the zero-velocity update's 1σ ([insgnss.live])
    zaru_sigma_rad_s: float = 0.02 * DEG  # at rest: the ZARU's floor ([insgnss.live])

    @property
    def flight(self) -> slice:
        """The GNSS epochs the results are taken at: the paper's 1..N-1 (after the lead-in)."""
        return slice(self.lead + 1, None)


def fault_table(scenario: Scenario, sim: InsGnssSimParams,
                rng: np.random.Generator) -> FloatArray:
    """Fault (E, N, U) in m added at each of the ``sim.epochs`` GNSS epochs."""
    m = sim.epochs
    fault = np.zeros((m, 3))
    big = np.array([sim.fault_h_m, sim.fault_h_m, sim.fault_v_m])
    small = np.array([sim.deviation_h_m, sim.deviation_h_m, sim.deviation_v_m])
    epochs = np.arange(m)
    if scenario == "paper-random":
        k = min(sim.random_faults, m - 1)
        fault[np.sort(rng.choice(np.arange(1, m), size=k, replace=False))] = big
    elif scenario == "paper-single":
        fault[(epochs % 10 == 0) & (epochs > 0)] = big
    elif scenario == "paper-continuous":
        fault[(epochs >= 10) & (epochs <= 200)] = big
    elif scenario == "paper-deviation":
        fault[(epochs % 10 == 0) & (epochs > 0)] = small
    elif scenario == "table2-calibrated":
        # "20 m of observation noise" every 10 s (the paper's wording): a zero-mean draw
        at = (epochs % 10 == 0) & (epochs > 0)
        sig = np.array([sim.table2_fault_h_m, sim.table2_fault_h_m, sim.table2_fault_v_m])
        fault[at] = rng.normal(0.0, 1.0, (int(at.sum()), 3)) * sig
    elif scenario != "clean":
        raise ValueError(f"unknown scenario {scenario!r}")
    return fault


SIM_BOOT_S = 120.0  # the simulated autopilot's uptime at the data's first sample


def gyro_drift(t_s: FloatArray, sim: InsGnssSimParams) -> FloatArray:
    """ArduPilot's simulated gyro drift (AP_InertialSensor_SITL::gyro_drift, rad/s, the same
    on every axis) at the data's times ``t_s``: a triangle rising ``gyro_drift_deg_s_per_min``
    per minute of the autopilot's uptime for ``gyro_drift_time_min``, then falling back."""
    period = 2.0 * sim.gyro_drift_time_min
    minutes = np.fmod((t_s - t_s[0] + SIM_BOOT_S) / 60.0, period)
    ramp = np.where(minutes < 0.5 * period, minutes, period - minutes)
    return np.asarray(ramp * sim.gyro_drift_deg_s_per_min * DEG, dtype=float)


def generate(setup: InsGnssSetup, scenario: Scenario, seed: int) -> NavData:
    """Generate the data of one run (deterministic in ``seed``)."""
    sim, flt = setup.sim, setup.filter
    earth = flt.earth
    ss = np.random.SeedSequence(seed)
    rng_imu, rng_gnss, rng_fault, rng_init = (np.random.default_rng(s) for s in ss.spawn(4))
    rate = sim.imu_rate_hz
    lead = sim.lead_s
    traj, gyro, accel = _truth(sim.epochs, rate, sim.speed_m_s, earth,
                               sim.rest_s if lead else 0, sim.takeoff_s if lead else 0)
    n = len(traj.t)
    dt = 1.0 / rate
    e = sim.imu
    b_g = rng_imu.normal(0.0, e.gyro_bias_rad_s, 3)
    b_a = rng_imu.normal(0.0, e.accel_bias_m_s2, 3)
    gyro = gyro + b_g + rng_imu.normal(0.0, e.gyro_arw_rad_sqrt_s / math.sqrt(dt), (n, 3))
    if sim.gyro_drift_deg_s_per_min > 0.0:
        gyro = gyro + gyro_drift(traj.t, sim)[:, None]
    accel = accel + b_a + rng_imu.normal(0.0, e.accel_vrw_m_s_sqrt_s / math.sqrt(dt), (n, 3))
    m = sim.epochs + lead
    idx = np.arange(m) * rate
    sig = np.array([sim.gnss_sigma_h_m, sim.gnss_sigma_h_m, sim.gnss_sigma_v_m])
    gnss_p = traj.p[idx] + rng_gnss.normal(0.0, 1.0, (m, 3)) * sig
    gnss_v = traj.v[idx] + rng_gnss.normal(0.0, sim.gnss_sigma_vel_m_s, (m, 3))
    # the scenario's faults are on the paper's epochs; none in the lead-in
    fault = np.concatenate([np.zeros((lead, 3)), fault_table(scenario, sim, rng_fault)])
    tilt, yaw = flt.init_sigma_tilt_deg * DEG, flt.init_sigma_yaw_deg * DEG
    return NavData(
        traj=traj,
        gyro=gyro,
        accel=accel,
        gnss_t=traj.t[idx],
        gnss_p=gnss_p + fault,
        gnss_v=gnss_v,
        fault=fault,
        init_p=traj.p[0] + rng_init.normal(0.0, flt.init_sigma_pos_m, 3),
        init_v=traj.v[0] + rng_init.normal(0.0, flt.init_sigma_vel_m_s, 3),
        init_rpy=traj.rpy[0] + rng_init.normal(0.0, 1.0, 3) * np.array([tilt, tilt, yaw]),
        imu_bias={"gyro_rad_s": b_g.tolist(), "accel_m_s2": b_a.tolist()},
        lead=lead,
        rest=sim.rest_s if lead else 0,
        zupt_sigma_m_s=setup.live.rest_sigma_vel_m_s,
        zaru_sigma_rad_s=setup.live.rest_sigma_gyro_deg_s * DEG,
    )


# ---------------------------------------------------------------- running the filter


@dataclass
class MethodRun:
    """Errors (estimate − truth) at GNSS epochs 1.., and the gate's counts."""

    t: FloatArray
    pos_err: FloatArray
    vel_err: FloatArray
    zone_counts: dict[str, int]
    action_counts: dict[str, int]
    flagged: npt.NDArray[np.bool_]  # epoch with any position component outside zone 0
    restarts: int
    fault_onsets: int = 0  # receiver judged faulty by the jump tracker (position)
    returns: int = 0  # ... and healthy again
    readmissions: int = 0  # position components accepted again after the INS drifted
    # strategy "fault_state": epochs at which a receiver fault was believed (after the update)
    faulted: npt.NDArray[np.bool_] | None = None
    # median over the epochs of the innovation's 1σ per position axis, sqrt(S_ii) (m), of the
    # epochs whose position was used as is: what the paper's §2.2 DM statistics measure
    innovation_sigma: tuple[float, float, float] = (math.nan, math.nan, math.nan)


def _at_rest(kf: InsGnssFilter, data: NavData, j: int, rate: int) -> None:
    """The live vehicle's updates at rest after GNSS epoch ``j``: ZUPT, and ZARU on the mean
    gyro of the epoch (as firmware_host/insgnss/vehicle.py)."""
    if kf.bias_active:
        return
    kf.zero_velocity(data.zupt_sigma_m_s)
    w = data.gyro[(j - 1) * rate + 1:j * rate + 1]
    kf.zero_rate(w.mean(axis=0), zaru_sigma(data.zaru_sigma_rad_s, kf.params, len(w) / rate))


def _counters(kf: InsGnssFilter, strategy: InsGnssStrategy) -> dict[str, Any]:
    """The gate's and the fault detector's counters so far (position components)."""
    tracker = kf.position_tracker
    mon = kf.fault_monitor
    fs = strategy == "fault_state"
    return {
        "zones": {z.name.lower(): sum(g.zone_counts[z] for g in kf.gates[:3]) for z in Zone},
        "actions": {a.value: sum(g.action_counts[a] for g in kf.gates[:3]) for a in Action},
        "restarts": sum(g.restarts for g in kf.gates[:3]),
        "onsets": mon.onsets if fs else tracker.fault_onsets,
        "returns": mon.returns if fs else tracker.returns,
        "readmissions": sum(g.readmissions for g in kf.gates[:3]),
    }


def _since(now: dict[str, Any], then: dict[str, Any]) -> dict[str, Any]:
    return {k: ({kk: vv - then[k][kk] for kk, vv in v.items()} if isinstance(v, dict)
                else v - then[k]) for k, v in now.items()}


def run_method(data: NavData, params: InsGnssParams, strategy: InsGnssStrategy) -> MethodRun:
    """Run the filter with ``strategy`` over ``data`` (from its first sample, the lead-in
    included; the errors and counts are those of the paper's epochs after it)."""
    prm = replace(params, strategy=strategy)
    traj = data.traj
    kf = InsGnssFilter(prm, float(traj.t[0]), data.init_p, data.init_v, data.init_rpy)
    m = len(data.gnss_t)
    rate = round(1.0 / float(traj.t[1] - traj.t[0]))
    pos_err = np.zeros((m - 1, 3))
    vel_err = np.zeros((m - 1, 3))
    flagged = np.zeros(m - 1, dtype=bool)
    faulted = np.zeros(m - 1, dtype=bool)
    s_pos: list[list[float]] = []
    t_list = traj.t.tolist()
    gyro, accel = data.gyro.tolist(), data.accel.tolist()
    lead = data.lead
    at_lead = _counters(kf, strategy)
    for j in range(1, m):
        for k in range((j - 1) * rate + 1, j * rate + 1):
            kf.propagate(t_list[k], gyro[k], accel[k])
        rep = kf.update(float(data.gnss_t[j]), data.gnss_p[j], data.gnss_v[j])
        if j <= data.rest:  # the lead-in's rest: known, as the live vehicle detects it
            _at_rest(kf, data, j, rate)
        flagged[j - 1] = any(d.zone is not Zone.NO_FAULT for d in rep.decisions[:3])
        faulted[j - 1] = kf.bias_active
        if j > lead and kf.S.shape[0] >= 3 and \
                all(d.action is Action.ACCEPT for d in rep.decisions[:3]):
            s_pos.append([float(kf.S[i, i]) for i in range(3)])
        k = j * rate
        pos_err[j - 1] = kf.position - traj.p[k]
        vel_err[j - 1] = kf.velocity - traj.v[k]
        if j == lead:
            at_lead = _counters(kf, strategy)
    c = _since(_counters(kf, strategy), at_lead)
    flagged, faulted = flagged[lead:], faulted[lead:]
    if strategy == "fault_state":
        flagged |= faulted  # a fix taken as faulty is flagged whatever its zone
    return MethodRun(
        data.gnss_t[data.flight], pos_err[lead:], vel_err[lead:], c["zones"], c["actions"],
        flagged, c["restarts"], c["onsets"], c["returns"], c["readmissions"],
        faulted if strategy == "fault_state" else None,
        _median_sigma(s_pos),
    )


def _median_sigma(s_pos: list[list[float]]) -> tuple[float, float, float]:
    if not s_pos:
        return (math.nan, math.nan, math.nan)
    med = np.sqrt(np.median(np.array(s_pos), axis=0))
    return (float(med[0]), float(med[1]), float(med[2]))


@dataclass
class CoastRun:
    """The INS coasting through a fault: position fixes withheld on the faulty epochs."""

    pos_err: FloatArray  # estimate − truth at GNSS epochs 1.., m
    sigma_h: FloatArray  # the filter's horizontal 1σ, sqrt(P_EE + P_NN), m


def run_coast(data: NavData, params: InsGnssParams) -> CoastRun:
    """The reference "INS coast": the plain filter told the faulty epochs (an oracle), which
    withholds their position fixes (velocity still used where the preset uses it) and takes
    every other fix as is. Its covariance bounds what any detector can do through the fault
    once it stops using the receiver's position: the bound of docs/insgnss.md is
    ``3 σ_h`` at the fault's end."""
    prm = replace(params, strategy="none")
    traj = data.traj
    kf = InsGnssFilter(prm, float(traj.t[0]), data.init_p, data.init_v, data.init_rpy)
    m = len(data.gnss_t)
    rate = round(1.0 / float(traj.t[1] - traj.t[0]))
    faulty = np.any(data.fault != 0, axis=1)
    pos_err = np.zeros((m - 1, 3))
    sigma_h = np.zeros(m - 1)
    t_list = traj.t.tolist()
    gyro, accel = data.gyro.tolist(), data.accel.tolist()
    for j in range(1, m):
        for k in range((j - 1) * rate + 1, j * rate + 1):
            kf.propagate(t_list[k], gyro[k], accel[k])
        if faulty[j]:
            kf.coast(float(data.gnss_t[j]), data.gnss_v[j])
        else:
            kf.update(float(data.gnss_t[j]), data.gnss_p[j], data.gnss_v[j])
        if j <= data.rest:
            _at_rest(kf, data, j, rate)
        pos_err[j - 1] = kf.position - traj.p[j * rate]
        sigma_h[j - 1] = math.sqrt(float(kf.P[0, 0] + kf.P[1, 1]))
    return CoastRun(pos_err[data.lead:], sigma_h[data.lead:])


def _stats(err: FloatArray) -> dict[str, dict[str, float]]:
    out = {}
    for i, axis in enumerate(("east", "north", "up")):
        e = err[:, i]
        out[axis] = {
            "min": round(float(e.min()), 4),
            "max": round(float(e.max()), 4),
            "rms": round(float(np.sqrt(np.mean(e * e))), 4),
        }
    return out


def summarize(data: NavData, runs: dict[str, MethodRun], scenario: str, seed: int,
              setup: InsGnssSetup) -> dict[str, Any]:
    """The ``summary.json`` document."""
    faulty = np.any(data.fault[data.flight] != 0, axis=1)
    methods: dict[str, Any] = {}
    for name, r in runs.items():
        horiz = np.hypot(r.pos_err[:, 0], r.pos_err[:, 1])
        pos3 = np.sqrt(np.mean(np.sum(r.pos_err**2, axis=1)))
        methods[name] = {
            "position_m": _stats(r.pos_err),
            "velocity_m_s": _stats(r.vel_err),
            "position_rms_3d_m": round(float(pos3), 4),
            "max_horizontal_error_m": round(float(horiz.max()), 4),
            "zones": r.zone_counts,
            "actions": r.action_counts,
            "window_restarts": r.restarts,
            "receiver_fault_onsets": r.fault_onsets,
            "receiver_returns": r.returns,
            "readmissions": r.readmissions,
            "fault_epochs_flagged": int(np.sum(r.flagged & faulty)),
            "clean_epochs_flagged": int(np.sum(r.flagged & ~faulty)),
        }
    sim = setup.sim
    return {
        "scenario": scenario,
        "seed": seed,
        "epochs": len(data.gnss_t) - data.lead,
        "fault_epochs": int(np.sum(faulty)),
        "imu_rate_hz": sim.imu_rate_hz,
        "gnss_sigma_m": {"h": sim.gnss_sigma_h_m, "v": sim.gnss_sigma_v_m,
                         "vel": sim.gnss_sigma_vel_m_s},
        "imu_truth_bias": data.imu_bias,
        "thresholds": {"T1": setup.filter.three_zone.t1, "T2": setup.filter.three_zone.t2},
        "errors_are": "estimate minus truth at GNSS epochs 1..N-1, after the update",
        "methods": methods,
        **({"lead_in_s": {"rest": sim.rest_s, "takeoff": sim.takeoff_s}} if data.lead else {}),
    }


def run_scenario(setup: InsGnssSetup, scenario: Scenario, seed: int,
                 strategies: tuple[InsGnssStrategy, ...] = INS_STRATEGIES,
                 ) -> tuple[dict[str, Any], NavData, dict[str, MethodRun]]:
    """Generate one run and pass it through each strategy; returns (summary, data, runs)."""
    data = generate(setup, scenario, seed)
    runs: dict[str, MethodRun] = {s: run_method(data, setup.filter, s) for s in strategies}
    return summarize(data, runs, scenario, seed, setup), data, runs


def fault_spans(t: FloatArray, faulty: npt.NDArray[np.bool_]) -> list[tuple[float, float]]:
    """The time spans of consecutive faulty epochs (each epoch covers half a period either
    side), for shading the plots."""
    spans: list[tuple[float, float]] = []
    if len(t) == 0:
        return spans
    half = 0.5 * float(np.median(np.diff(t))) if len(t) > 1 else 0.5
    start: float | None = None
    for k in range(len(t)):
        if faulty[k] and start is None:
            start = float(t[k]) - half
        if start is not None and (not faulty[k] or k == len(t) - 1):
            end = float(t[k]) + half if faulty[k] else float(t[k - 1]) + half
            spans.append((start, end))
            start = None
    return spans


def write_plots(out: Path, scenario: str, runs: dict[str, MethodRun],
                data: NavData | None = None) -> list[Path]:
    """PNGs like the paper's Fig. 9–18 (errors against time per method), the receiver's fault
    periods shaded (with ``data``); [] without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return []
    files = []
    spans: list[tuple[float, float]] = []
    if data is not None:
        spans = fault_spans(data.gnss_t[data.flight],
                            np.any(data.fault[data.flight] != 0, axis=1))
    for kind, unit in (("position", "m"), ("velocity", "m/s")):
        fig, axes = plt.subplots(3, 1, figsize=(9, 8.4), sharex=True)
        for i, axis in enumerate(("east", "north", "up")):
            ax = axes[i]
            for k, (a, b) in enumerate(spans):
                ax.axvspan(a, b, color="tab:red", alpha=0.15, lw=0,
                           label="GNSS fault" if k == 0 else None)
            for name, r in runs.items():
                err = r.pos_err if kind == "position" else r.vel_err
                ax.plot(r.t, err[:, i], lw=0.8, label=name)
            ax.set_ylabel(f"{axis} error / {unit}")
            ax.grid(True, lw=0.3)
        handles, labels = axes[0].get_legend_handles_labels()
        fig.suptitle(f"{scenario}: {kind} error (estimate − truth)"
                     + (", GNSS fault periods shaded" if spans else ""))
        # The legend in its own row above the plots: it covers no data.
        fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.96),
                   ncol=len(labels), fontsize=8, frameon=False)
        axes[-1].set_xlabel("t / s")
        path = out / f"{kind}_errors.png"
        fig.tight_layout(rect=(0, 0, 1, 0.94))
        fig.savefig(path, dpi=110)
        plt.close(fig)
        files.append(path)
    return files


# ---------------------------------------------------------------- benchmark


def bench_insgnss_step(n: int) -> dict[str, float]:
    """Time ``n`` IMU propagations (100 Hz, P at 10 Hz) and ``n // 100`` GNSS updates (ms)."""
    params = InsGnssParams()
    earth = params.earth
    kf = InsGnssFilter(params, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    f_rest = (0.0, 0.0, -earth.g0)  # FRD at rest, level, facing north
    prop: list[float] = []
    upd: list[float] = []
    t = 0.0
    for k in range(1, max(n, 1) + 1):
        t = k * 0.01
        t0 = time.perf_counter()
        kf.propagate(t, (0.0, 0.0, 0.0), f_rest)
        prop.append(time.perf_counter() - t0)
        if k % 100 == 0:
            t0 = time.perf_counter()
            kf.update(t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
            upd.append(time.perf_counter() - t0)
    out = {
        "n": float(len(prop)),
        "p50_ms": float(np.percentile(prop, 50)) * 1e3,
        "p99_ms": float(np.percentile(prop, 99)) * 1e3,
    }
    if upd:
        out["update_p50_ms"] = float(np.percentile(upd, 50)) * 1e3
        out["update_p99_ms"] = float(np.percentile(upd, 99)) * 1e3
    return out


# ---------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", choices=SCENARIOS, default="paper-random",
                        help="which scenario of the paper (faults and their times)")
    parser.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    parser.add_argument("--out", type=output_dir_arg, required=True,
                        help="output directory (summary.json, PNGs)")
    parser.add_argument(
        "--config", type=input_file_arg, default=None,
        help=f"preset TOML (default {PAPER_PRESET.relative_to(CONFIG_DIR.parent)})",
    )
    parser.add_argument("--no-plots", action="store_true", help="do not write PNGs")
    parser.add_argument("--json", action="store_true",
                        help="print summary.json instead of the result table")


def run(args: argparse.Namespace) -> int:
    setup = load_setup(args.config)
    out: Path = args.out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(str(out), "--out", "a writable directory", str(err)) from err
    summary, data, runs = run_scenario(setup, args.scenario, args.seed)
    text = json.dumps(summary, indent=2) + "\n"
    (out / "summary.json").write_text(text, encoding="utf-8")
    pngs = [] if args.no_plots else write_plots(out, args.scenario, runs, data)
    if getattr(args, "json", False):
        print(text, end="")
        return 0
    print(result_text(summary))
    written = [out / "summary.json", *pngs]
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


def result_text(summary: dict[str, Any]) -> str:
    """``sim insgnss``'s result for a human: the run, then one row a method (position RMS per
    axis and 3-D, the worst horizontal error, velocity RMS, epochs flagged)."""
    head = (f"{summary['scenario']}, seed {summary['seed']}: {summary['epochs']} GNSS epochs, "
            f"{summary['fault_epochs']} with a fault")
    rows = []
    for name, m in summary["methods"].items():
        p, v = m["position_m"], m["velocity_m_s"]
        vrms = math.sqrt(sum(v[a]["rms"] ** 2 for a in ("east", "north", "up")))
        rows.append([name, p["east"]["rms"], p["north"]["rms"], p["up"]["rms"],
                     m["position_rms_3d_m"], m["max_horizontal_error_m"], vrms,
                     m["fault_epochs_flagged"], m["clean_epochs_flagged"]])
    return head + "\n\n" + table(
        ["method", "RMS E m", "RMS N m", "RMS U m", "RMS 3D m", "max horiz m", "vel RMS m/s",
         "faulty flagged", "clean flagged"], rows)
