"""fdi.kalman: the decoupled 3-axis filter against a plain NumPy 6-state Kalman filter."""

from __future__ import annotations

import numpy as np
import pytest

from fdi.chi2 import threshold
from fdi.kalman import GpsKalman

Vec3 = tuple[float, float, float]


def vec3(a: np.ndarray) -> Vec3:
    return (float(a[0]), float(a[1]), float(a[2]))


class ReferenceKf:
    """6-state constant-velocity filter, x = [e, n, u, ve, vn, vu], textbook NumPy.

    Φ = [[I, dt·I], [0, I]];  Q = q [[dt³/3·I, dt²/2·I], [dt²/2·I, dt·I]];  H = [I, 0];
    R = diag(r);  Joseph form P = (I − KH) P (I − KH)ᵀ + K R Kᵀ.
    """

    H = np.hstack([np.eye(3), np.zeros((3, 3))])

    def __init__(self, q: float, z: Vec3, r: Vec3) -> None:
        self.q = q
        self.x = np.concatenate([np.asarray(z, dtype=float), np.zeros(3)])
        self.P = np.diag([*r, 25.0, 25.0, 25.0])

    def predict(self, dt: float) -> None:
        I3 = np.eye(3)
        Phi = np.block([[I3, dt * I3], [np.zeros((3, 3)), I3]])
        Q = self.q * np.block([[dt**3 / 3 * I3, dt**2 / 2 * I3], [dt**2 / 2 * I3, dt * I3]])
        self.x = Phi @ self.x
        self.P = Phi @ self.P @ Phi.T + Q

    def innovation(self, z: Vec3, r: Vec3) -> tuple[np.ndarray, np.ndarray]:
        D = np.asarray(z) - self.H @ self.x
        S = self.H @ self.P @ self.H.T + np.diag(r)
        return D, S

    def update(self, z: Vec3, r: Vec3) -> None:
        D, S = self.innovation(z, r)
        K = self.P @ self.H.T @ np.linalg.inv(S)
        self.x = self.x + K @ D
        A = np.eye(6) - K @ self.H
        self.P = A @ self.P @ A.T + K @ np.diag(r) @ K.T


def state_of(kf: GpsKalman) -> tuple[np.ndarray, np.ndarray]:
    """GpsKalman's state and covariance laid out like ReferenceKf's."""
    x = np.array([ax.p for ax in kf.axes] + [ax.v for ax in kf.axes])
    P = np.zeros((6, 6))
    for i, ax in enumerate(kf.axes):
        P[i, i], P[i, i + 3], P[i + 3, i], P[i + 3, i + 3] = ax.P00, ax.P01, ax.P01, ax.P11
    return x, P


def test_equals_the_numpy_six_state_filter_over_200_random_steps() -> None:
    rng = np.random.default_rng(1234)
    q = 0.7
    truth = np.array([100.0, -50.0, 20.0])
    vel = np.array([1.5, -0.5, 0.1])
    r0: Vec3 = (0.1, 0.2, 0.5)
    z0: Vec3 = vec3(truth + rng.normal(0.0, 0.3, 3))
    kf = GpsKalman(q=q)
    kf.reset(z0, r0)
    ref = ReferenceKf(q, z0, r0)
    for _ in range(200):
        dt = float(rng.uniform(0.05, 1.0))
        truth = truth + vel * dt
        r: Vec3 = vec3(rng.uniform(0.01, 1.0, 3))
        z: Vec3 = vec3(truth + rng.normal(0.0, 1.0, 3) * np.sqrt(r))
        kf.predict(dt)
        ref.predict(dt)
        f_k = kf.test(z, r)
        D, S = ref.innovation(z, r)
        np.testing.assert_allclose(kf.D, D, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(kf.S, np.diag(S), rtol=1e-9, atol=1e-12)
        # (5) F = Dᵀ S⁻¹ D with the full 3×3 S
        assert f_k == pytest.approx(float(D @ np.linalg.inv(S) @ D), rel=1e-9, abs=1e-12)
        kf.update(z, r)
        ref.update(z, r)
        x, P = state_of(kf)
        np.testing.assert_allclose(x, ref.x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(P, ref.P, rtol=1e-9, atol=1e-12)
    assert kf.position == pytest.approx(tuple(ref.x[:3]), rel=1e-12)


def test_residual_statistic_is_chi2_with_three_dof_under_no_fault() -> None:
    """Data generated from the filter's own model: F ~ χ²(3), mean 3, variance 6."""
    rng = np.random.default_rng(42)
    q, dt = 0.5, 0.1
    r: Vec3 = (0.35**2, 0.35**2, 0.7**2)
    Q1 = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    L = np.linalg.cholesky(Q1)
    pos = np.zeros(3)
    vel = rng.normal(0.0, 5.0, 3)  # P11 = 25 at reset
    z0: Vec3 = vec3(pos + rng.normal(0.0, 1.0, 3) * np.sqrt(r))
    kf = GpsKalman(q=q)
    kf.reset(z0, r)
    burn_in, steps = 100, 5000
    values: list[float] = []
    for k in range(steps):
        for i in range(3):
            w = L @ rng.normal(0.0, 1.0, 2)
            pos[i] += vel[i] * dt + w[0]
            vel[i] += w[1]
        z: Vec3 = vec3(pos + rng.normal(0.0, 1.0, 3) * np.sqrt(r))
        kf.predict(dt)
        f_k = kf.test(z, r)
        kf.update(z, r)
        if k >= burn_in:
            values.append(f_k)
    arr = np.asarray(values)
    n = len(arr)
    # Standard error of the mean: sqrt(6/n) ≈ 0.035; allow 4 of them.
    assert abs(arr.mean() - 3.0) < 4.0 * np.sqrt(6.0 / n)
    assert abs(arr.var() - 6.0) < 1.0  # the variance too (SE ≈ 0.25 for χ²(3) at this n)
    # False-alarm rate at α = 0.05 (T_d = 7.815): SE ≈ 0.0031; allow 4.
    rate = float(np.mean(arr > threshold(0.05, 3)))
    assert abs(rate - 0.05) < 4.0 * np.sqrt(0.05 * 0.95 / n)


def test_a_step_fault_is_seen_in_F() -> None:
    # The statistic must be able to fire: a 3 m jump on a settled filter.
    kf = GpsKalman(q=0.5)
    r: Vec3 = (0.1, 0.1, 0.4)
    kf.reset((0.0, 0.0, 0.0), r)
    for _ in range(50):
        kf.predict(0.1)
        kf.test((0.0, 0.0, 0.0), r)
        kf.update((0.0, 0.0, 0.0), r)
    kf.predict(0.1)
    assert kf.test((3.0, 0.0, 0.0), r) > 30.0
