"""Linear Kalman filter on GPS fixes, with the residual chi-square test.

Zhou & Zhang (2010), section 1.1, equations (1)-(6). The state per axis is position and velocity
(a constant-velocity model with white acceleration noise ``q``); the measurement is the fix's
east/north/up position (m = 3). With a diagonal ``R`` the 6-state filter separates exactly into
three 2-state filters, which is how it is computed here (plain floats: a NumPy 6×6 filter costs
10× more on arrays this small; shared/FINDINGS.md). The symbols are filterpy's and the paper's:

    x̂(k,k−1) = Φ x̂(k−1)                       (1)
    ẑ(k,k−1) = H x̂(k,k−1)                      (2)
    D(k)     = Z(k) − ẑ(k,k−1)                  (3)   innovation ("residual")
    S(k)     = H P(k,k−1) Hᵀ + R(k)             (4)
    F(k)     = Dᵀ S⁻¹ D                         (5)   ~ χ²(m) when there is no fault
    fault  ⟺  F(k) > T_d,  P{F > T_d} = α       (6)

The covariance update is in Joseph form. Units: metres, seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(slots=True)
class AxisFilter:
    """One axis's state ``[p, v]`` and covariance ``[[P00, P01], [P01, P11]]``; the equations
    are :class:`GpsKalman`'s, written out over the axes once an epoch."""

    p: float = 0.0
    v: float = 0.0
    P00: float = 1e6
    P01: float = 0.0
    P11: float = 1e6


@dataclass
class GpsKalman:
    """Three decoupled constant-velocity axes (east, north, up) with the χ² residual test."""

    q: float = 0.5  # white acceleration spectral density, m²/s³
    axes: list[AxisFilter] = field(default_factory=lambda: [AxisFilter() for _ in range(3)])
    initialised: bool = False
    # Last test, kept for inspection (filterpy's x_prior / mahalanobis idea).
    D: tuple[float, float, float] = (0.0, 0.0, 0.0)
    S: tuple[float, float, float] = (1.0, 1.0, 1.0)
    F: float = 0.0

    def reset(self, z: tuple[float, float, float], r: tuple[float, float, float]) -> None:
        """Start at a fix with its own variance and an unknown velocity."""
        for ax, zi, ri in zip(self.axes, z, r, strict=True):
            ax.p, ax.v = zi, 0.0
            ax.P00, ax.P01, ax.P11 = ri, 0.0, 25.0
        self.initialised = True

    def predict(self, dt: float) -> None:
        """Time update over ``dt`` seconds, per axis: x = F x, P = F P Fᵀ + Q (white-noise
        acceleration of spectral density ``q``)."""
        q = self.q
        # Q = q [[dt³/3, dt²/2], [dt²/2, dt]], the same for every axis
        q00, q01, q11 = q * dt**3 / 3.0, q * dt * dt / 2.0, q * dt
        dt2 = dt * dt
        for ax in self.axes:
            P01, P11 = ax.P01, ax.P11
            ax.p += ax.v * dt  # (1) x̂(k,k−1) = Φ x̂(k−1), Φ = [[1, dt], [0, 1]]
            # P(k,k−1) = Φ P Φᵀ + Q
            ax.P00 = ax.P00 + 2.0 * dt * P01 + dt2 * P11 + q00
            ax.P01 = P01 + dt * P11 + q01
            ax.P11 = P11 + q11

    def test(self, z: tuple[float, float, float], r: tuple[float, float, float]) -> float:
        """F(k) of eq. (5) for the predicted state; also stores ``D`` and ``S``."""
        # (3) D = Z − H x̂(k,k−1) and (4) S = H P Hᵀ + R of each axis, H = [1, 0]
        a0, a1, a2 = self.axes
        d0, s0 = z[0] - a0.p, a0.P00 + r[0]
        d1, s1 = z[1] - a1.p, a1.P00 + r[1]
        d2, s2 = z[2] - a2.p, a2.P00 + r[2]
        self.D = (d0, d1, d2)
        self.S = (s0, s1, s2)
        # (5) F = Dᵀ S⁻¹ D with S diagonal
        self.F = d0 * d0 / s0 + d1 * d1 / s1 + d2 * d2 / s2
        return self.F

    def update(self, z: tuple[float, float, float], r: tuple[float, float, float],
               only: tuple[int, ...] = (0, 1, 2)) -> None:
        """The measurement update of the axes ``only`` (all by default) with fix ``z``."""
        axes = self.axes
        for i in only:
            ax, zi, ri = axes[i], z[i], r[i]
            P00, P01 = ax.P00, ax.P01
            # (3) D and (4) S, then the gain K = P Hᵀ S⁻¹
            d = zi - ax.p
            s = P00 + ri
            k0 = P00 / s
            k1 = P01 / s
            ax.p += k0 * d
            ax.v += k1 * d
            # Joseph form: P = (I − K H) P (I − K H)ᵀ + K R Kᵀ
            a = 1.0 - k0
            ax.P00 = a * a * P00 + k0 * k0 * ri
            ax.P01 = a * (P01 - k1 * P00) + k0 * k1 * ri
            ax.P11 = ax.P11 - 2.0 * k1 * P01 + k1 * k1 * P00 + k1 * k1 * ri

    @property
    def position(self) -> tuple[float, float, float]:
        """The position estimate per axis (east, north, up), m."""
        return (self.axes[0].p, self.axes[1].p, self.axes[2].p)
