"""Adaptive FIR / LMS and the weight-drift SNR against NumPy references (seeded)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fdi.lms_fir import (
    AdaptiveFir,
    DetectorConfig,
    DualCriterionDetector,
    WeightDriftSnr,
    wrap180,
)


def test_wrap180() -> None:
    assert wrap180(190.0) == -170.0
    assert wrap180(-190.0) == 170.0
    assert wrap180(180.0) == 180.0
    assert wrap180(359.5 - 0.5) == pytest.approx(-1.0)


@pytest.mark.parametrize("bias", [False, True])
def test_lms_matches_numpy_reference_over_ring_rebase(bias: bool) -> None:
    rng = np.random.default_rng(11)
    M, mu = 7, 0.01
    fir = AdaptiveFir(M, mu, bias, u_op=0.0, u_scale=100.0)
    w = np.zeros(M + bias)
    hist = np.zeros(M)
    for _ in range(100):  # > 2M pushes: exercises the ring buffer rebase several times
        u = float(rng.uniform(-150, 150))
        fir.push(u)
        hist = np.roll(hist, 1)
        hist[0] = max(-1.0, min(1.0, u / 100.0))
        x = np.append(hist, 1.0) if bias else hist
        target = float(rng.normal())
        d = fir.predict()
        assert d == pytest.approx(float(w @ x), abs=1e-12)
        e = target - d
        fir.train(e)
        w = w + 2 * mu * e * x  # eq. (5)
        assert pytest.approx(list(w), abs=1e-12) == fir.C
        assert fir.w_sum == pytest.approx(float(w.sum()), abs=1e-9)


def test_lms_identifies_a_known_fir() -> None:
    rng = np.random.default_rng(5)
    h = np.array([0.3, -0.2, 0.1, 0.05])
    fir = AdaptiveFir(4, 0.05, False, 0.0, 1.0)
    u = rng.uniform(-1, 1, 5000)
    for k in range(1, 4):
        fir.push(float(u[k - 1]))
    for k in range(4, len(u)):
        fir.push(float(u[k - 1]))
        y = float(h @ u[[k - 1, k - 2, k - 3, k - 4]])  # strictly causal: u(k-1) ... u(k-4)
        fir.train(y - fir.predict())
    assert pytest.approx(list(h), abs=1e-6) == fir.C


def test_snr_matches_numpy_and_guards_zero_std() -> None:
    rng = np.random.default_rng(2)
    snr = WeightDriftSnr(10)
    s = np.cumsum(rng.normal(size=30))
    for k, v in enumerate(s):
        R = snr.push(float(v))
        if k >= 9:
            D = s[k - 9 : k + 1] - s[k - 9]
            V = np.abs((D - D.mean()) / D.std())  # eq. (10)
            ref = (V[-1] - V.mean()) ** 2 / V.std() ** 2  # eq. (11)
            assert pytest.approx(ref, rel=1e-9) == R
    flat = WeightDriftSnr(5)
    for _ in range(8):
        R = flat.push(0.25)
    assert R == 0.0 and not math.isnan(R)


def test_step_in_weights_gives_large_r_and_fades() -> None:
    snr = WeightDriftSnr(50)
    rng = np.random.default_rng(4)
    for _ in range(50):
        snr.push(float(rng.normal(0, 1e-4)))
    Rs = [snr.push(1e-2 + float(rng.normal(0, 1e-4))) for _ in range(5)]
    assert Rs[0] > 40 and Rs[3] > 9  # measured design values in config/rov.toml
    assert Rs == sorted(Rs, reverse=True)


def test_detector_stores_weights_before_the_faulty_update() -> None:
    cfg = DetectorConfig(order=5, warmup_samples=0, snr_window=10)
    det = DualCriterionDetector(cfg)
    rng = np.random.default_rng(8)
    for _ in range(50):
        det.push_command(float(rng.uniform(-20, 20)))
        det.step(float(rng.normal(0, 0.3)))
    before = list(det.fir.C_avg)
    det.push_command(0.0)
    r = det.step(30.0)
    assert r.exceed and r.suspect and r.e2 > 800
    assert det.stored == before
    assert before != det.fir.C  # the FIR itself kept learning (the paper's eq. (5))


def test_warmup_suppresses_criterion_1() -> None:
    det = DualCriterionDetector(DetectorConfig(order=5, warmup_samples=10))
    det.push_command(0.0)
    assert not det.step(50.0).exceed
