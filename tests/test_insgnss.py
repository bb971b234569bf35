"""INS/GNSS: mechanisation, rate refusal, convergence on clean data, presets, benchmark."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drivers.configload import load_file
from fdi.errors import ConfigError, EstimatorError
from fdi.insgnss import (
    EarthModel,
    InsGnssFilter,
    InsGnssParams,
    NavState,
    earth_step_quat,
    euler_to_quat,
    invert_mechanization,
    mechanize,
    quat_conj,
    quat_rotate,
    quat_to_euler,
)
from fdi.three_zone import Zone
from firmware_host.devtools.insgnss_sim import (
    InsGnssSetup,
    bench_insgnss_step,
    generate,
    load_setup,
    run_method,
)

ROOT = Path(__file__).resolve().parents[1]


def _stationary_samples(earth: EarthModel, rpy: tuple[float, float, float]) -> tuple:
    q = euler_to_quat(*rpy)
    qc = quat_conj(q)
    gyro = quat_rotate(qc, earth.omega_ie_n)  # the Earth's rate, seen in b
    g = earth.gravity((0.0, 0.0, 0.0))
    accel = quat_rotate(qc, (-g[0], -g[1], -g[2]))  # specific force = −g
    return gyro, accel


def _run_stationary(bias_g=(0.0, 0.0, 0.0), bias_a=(0.0, 0.0, 0.0), seconds=60.0):
    params = InsGnssParams()
    rpy = (0.0, 0.0, 0.0)  # level, facing north: body x = north, y = east, z = down
    gyro, accel = _stationary_samples(params.earth, rpy)
    kf = InsGnssFilter(params, 0.0, (0, 0, 0), (0, 0, 0), rpy)
    g = tuple(a + b for a, b in zip(gyro, bias_g, strict=True))
    f = tuple(a + b for a, b in zip(accel, bias_a, strict=True))
    n = round(seconds * 100)
    for k in range(1, n + 1):
        kf.propagate(k / 100.0, g, f)
    return kf


def test_euler_round_trip_and_frames() -> None:
    rpy = (0.1, -0.2, 2.5)
    assert quat_to_euler(euler_to_quat(*rpy)) == pytest.approx(rpy, abs=1e-12)
    q = euler_to_quat(0.0, 0.0, 0.0)  # facing north: body forward = north, down = −up
    assert quat_rotate(q, (1.0, 0.0, 0.0)) == pytest.approx((0.0, 1.0, 0.0), abs=1e-15)
    assert quat_rotate(q, (0.0, 0.0, 1.0)) == pytest.approx((0.0, 0.0, -1.0), abs=1e-15)
    q = euler_to_quat(0.0, 0.0, math.pi / 2)  # facing east
    assert quat_rotate(q, (1.0, 0.0, 0.0)) == pytest.approx((1.0, 0.0, 0.0), abs=1e-15)


def test_stationary_error_free_imu_stays_put() -> None:
    kf = _run_stationary()
    assert np.abs(kf.position).max() < 1e-6
    assert np.abs(kf.velocity).max() < 1e-7


def test_stationary_accel_bias_error_is_half_b_t2() -> None:
    b = 1e-3  # m/s² (≈ 100 µg) on body x = north
    kf = _run_stationary(bias_a=(b, 0.0, 0.0), seconds=60.0)
    expected = 0.5 * b * 60.0**2  # 1.8 m; Schuler and Coriolis change it by < 1 % in 60 s
    assert kf.position[1] == pytest.approx(expected, rel=0.01)
    assert abs(kf.position[0]) < 0.01 * expected


def test_stationary_gyro_bias_error_is_g_b_t3_over_6() -> None:
    b = 1e-5  # rad/s (≈ 2 °/h) about body x (north): tilts the east axis
    kf = _run_stationary(bias_g=(b, 0.0, 0.0), seconds=60.0)
    g = InsGnssParams().earth.g0
    expected = g * b * 60.0**3 / 6.0  # 3.5 m, towards east or west
    assert abs(kf.position[0]) == pytest.approx(expected, rel=0.03)
    assert abs(kf.position[1]) < 0.05 * expected


def test_mechanisation_inverse_is_exact() -> None:
    earth = EarthModel()
    s0 = NavState(euler_to_quat(0.1, 0.05, 1.0), (50.0, 20.0, 1.0), (100.0, -50.0, 30.0))
    s1 = NavState(euler_to_quat(0.11, 0.049, 1.003), (50.2, 20.1, 1.01), (100.5, -49.8, 30.01))
    qe = earth_step_quat(earth, 0.01)
    w, f = invert_mechanization(s0, s1, 0.01, earth, qe)
    s = NavState(s0.q, s0.v, s0.p)
    mechanize(s, w, f, 0.01, earth, qe)
    assert s.v == pytest.approx(s1.v, abs=1e-12)
    assert s.q == pytest.approx(s1.q, abs=1e-12)


def test_the_nominal_state_stays_python_floats_after_an_update() -> None:
    """The update's correction comes from NumPy; the nominal state is mechanised at the IMU
    rate in plain floats (NumPy scalars made the IMU step ~3x slower, same values)."""
    params = InsGnssParams()
    gyro, accel = _stationary_samples(params.earth, (0.0, 0.0, 0.0))
    kf = InsGnssFilter(params, 0.0, (0, 0, 0), (0, 0, 0), (0, 0, 0))
    for k in range(1, 101):
        kf.propagate(k * 0.01, gyro, accel)
    kf.update(1.0, (0.5, -0.3, 0.1), (0.0, 0.0, 0.0))
    nav = kf.nav
    for x in (*nav.q, *nav.v, *nav.p, *kf.b_a, *kf.b_g):
        assert type(x) is float


def test_refuses_slow_imu() -> None:
    params = InsGnssParams()
    gyro, accel = _stationary_samples(params.earth, (0.0, 0.0, 0.0))
    kf = InsGnssFilter(params, 0.0, (0, 0, 0), (0, 0, 0), (0, 0, 0))
    with pytest.raises(EstimatorError, match=r"rate 2 Hz is below the 20 Hz"):
        kf.propagate(0.5, gyro, accel)
    # 15 Hz with no single gap: the median-rate check after ten samples refuses it
    kf = InsGnssFilter(replace(params, max_imu_gap_s=1.0), 0.0, (0, 0, 0), (0, 0, 0), (0, 0, 0))
    with pytest.raises(EstimatorError, match="below the 20 Hz"):
        for k in range(1, 11):
            kf.propagate(k / 15.0, gyro, accel)
    kf = InsGnssFilter(params, 0.0, (0, 0, 0), (0, 0, 0), (0, 0, 0))
    kf.propagate(0.01, gyro, accel)
    with pytest.raises(EstimatorError, match="did not advance"):
        kf.propagate(0.01, gyro, accel)
    with pytest.raises(EstimatorError, match="propagate the IMU"):
        kf.update(5.0, (0.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def paper_setup() -> InsGnssSetup:
    return load_setup(ROOT / "config" / "insgnss-paper.toml")


def test_filter_converges_and_gate_is_consistent_on_clean_data(paper_setup: InsGnssSetup) -> None:
    data = generate(paper_setup, "clean", seed=7)
    run = run_method(data, paper_setup.filter, "none")
    settled = run.pos_err[30:]
    rms = np.sqrt(np.mean(settled**2, axis=0))
    # GNSS noise is 3/3/5 m: the filter averages it down to about a third
    assert rms[0] < 1.5 and rms[1] < 1.5 and rms[2] < 2.0
    assert np.sqrt(np.mean(run.vel_err[30:] ** 2)) < 0.1
    # With a consistent filter DM ~ χ²(1): 9 % deviation, 1 % over-limit (1500 components)
    n = sum(run.zone_counts.values())
    assert 0.06 < run.zone_counts[Zone.DEVIATION.name.lower()] / n < 0.13
    assert run.zone_counts[Zone.OVER_LIMIT.name.lower()] / n < 0.025


def test_presets_load(paper_setup: InsGnssSetup) -> None:
    p = paper_setup.filter
    assert (p.three_zone.alpha1, p.three_zone.alpha2, p.three_zone.window) == (0.10, 0.01, 4)
    assert p.use_velocity is False and paper_setup.sim.epochs == 501
    default = load_setup(ROOT / "config" / "insgnss.toml")
    assert default == InsGnssSetup()  # the default preset states the built-in defaults


def test_bad_preset_names_the_key(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[filter.three_zone]\nalpha1 = 1.5\n', encoding="utf-8")
    with pytest.raises(ConfigError, match=r"filter\.three_zone\.alpha1"):
        load_file(InsGnssSetup, bad)
    bad.write_text('[filter]\nstrategy = "grey"\n', encoding="utf-8")
    with pytest.raises(ConfigError, match="strategy"):
        load_file(InsGnssSetup, bad)


def test_bench_reports_percentiles() -> None:
    out = bench_insgnss_step(300)
    assert out["n"] == 300
    assert 0 < out["p50_ms"] <= out["p99_ms"]
    assert out["update_p50_ms"] > 0


def test_zaru_estimates_every_gyro_bias_at_rest_and_rejects_a_turn() -> None:
    """At rest (level, facing north) with a gyro bias of 0.1 deg/s on every axis (ArduPilot's
    simulated drift after 2 minutes) and ZUPT + ZARU each second: after 60 s the estimated
    bias is within 0.005 deg/s of it on every axis, yaw included (a ZUPT alone cannot see
    the yaw gyro), the yaw stays within 0.05 deg and its claimed 1σ covers the error; a
    slow turn of 1 deg/s is refused by the ZARU's gate."""
    params = InsGnssParams()
    params = replace(params, imu=replace(params.imu, gyro_bias_deg_h=900.0,
                                         gyro_bias_drift_deg_s_per_min=0.05))
    rpy = (0.0, 0.0, 0.0)
    gyro, accel = _stationary_samples(params.earth, rpy)
    b = math.radians(0.1)
    g = tuple(x + b for x in gyro)
    kf = InsGnssFilter(params, 0.0, (0, 0, 0), (0, 0, 0), rpy)
    for k in range(1, 6001):
        kf.propagate(k / 100.0, g, accel)
        if k % 100 == 0:
            kf.coast(k / 100.0)
            kf.zero_velocity(0.01)
            assert kf.zero_rate(g, math.radians(0.02))
    assert np.abs(np.degrees(kf.gyro_bias) - 0.1).max() < 0.005
    yaw_err = math.degrees(float(kf.attitude_rpy[2]))
    assert abs(yaw_err) < 0.05
    assert abs(yaw_err) < 3.0 * math.degrees(math.sqrt(float(kf.P[8, 8])))
    turning = (g[0], g[1], g[2] - math.radians(1.0))  # 1 deg/s about down
    assert not kf.zero_rate(turning, math.radians(0.02))


def test_the_receiver_s_correlated_error_is_a_state_and_a_walk_leaves_its_model() -> None:
    """fdi/insgnss.py (G1)-(G6) at rest (error-free IMU, ZUPT each second): fixes with a DGPS
    receiver's error (Gauss-Markov σ 0.35 m E/N, 0.7 m up, τ 60 s), the filter modelling it
    (R the 0.1 m white rest). It starts at the first fix with the fix's error tied to its
    position (P_pg = −σ_g²); 150 s of the receiver's wander open no fault and the position
    stays within 3σ of its claim; then a walk of 0.2 m/s east at zero speed is a fault within
    8 s (the walk test (G3): 5 s), the fixes since its start are taken back out (G5), so that
    the INS keeps less than 0.1 m of it (0.002 m; up to 0.4 m before (G5)), and while the
    fault holds the walk goes into the fault's bias, not the position (G6)."""
    params = replace(InsGnssParams(), use_velocity=False, gnss_sigma_h_m=0.1,
                     gnss_sigma_v_m=0.2, gnss_gm_sigma_m=0.35, gnss_gm_sigma_up_m=0.7,
                     gnss_gm_tau_s=60.0)
    rpy = (0.0, 0.0, 0.0)
    gyro, accel = _stationary_samples(params.earth, rpy)
    rng = np.random.default_rng(7)
    sig = np.array([0.35, 0.35, 0.7])
    phi = math.exp(-1.0 / 60.0)
    g = rng.normal(0.0, 1.0, 3) * sig
    kf = InsGnssFilter(params, 0.0, g, (0, 0, 0), rpy)
    assert kf.n == 18 and kf.P[0, 15] == pytest.approx(-0.35**2)
    assert kf.P[0, 0] == pytest.approx(params.init_sigma_pos_m**2 + 0.35**2)
    onset_t = None
    for t in range(1, 176):
        for k in range(1, 101):
            kf.propagate(t - 1 + k / 100.0, gyro, accel)
        g = phi * g + math.sqrt(1.0 - phi * phi) * sig * rng.normal(0.0, 1.0, 3)
        walk = 0.2 * (t - 150) if t > 150 else 0.0
        kf.update(float(t), g + np.array([walk, 0.0, 0.0]))
        kf.zero_velocity(0.01)
        if t <= 150:
            assert not kf.bias_active, t  # the receiver's own wander is no fault
            err = kf.position[:2]
            assert np.all(np.abs(err) <= 3.0 * np.sqrt(np.diag(kf.P)[:2])), (t, err)
            east_150 = float(kf.position[0])
        elif kf.bias_active and onset_t is None:
            onset_t = t
            east_at_onset = float(kf.position[0])
    assert onset_t is not None and onset_t - 150 <= 8, onset_t
    assert kf.rollbacks == 1
    assert abs(east_at_onset - east_150) < 0.1, (east_at_onset, east_150)
    assert abs(float(kf.position[0]) - east_at_onset) < 0.1  # held through the fault
