"""A frozen receiver's coast (fdi/coast.py, C1-C3): the turn fitted to the live courses, the
constant-turn-rate motion, and its bound."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fdi.coast import ctrv, turn_fit, within


def _circle_velocities(rate_rad_s: float, speed: float, t_f: float, span_s: float,
                       rate_hz: float, noise: float = 0.0, psi_f: float = 3.0
                       ) -> list[tuple[float, float, float]]:
    rng = np.random.default_rng(5)
    out = []
    for k in range(round(span_s * rate_hz), -1, -1):
        t = t_f - k / rate_hz
        psi = psi_f + rate_rad_s * (t - t_f)
        ne, nn = rng.normal(0.0, noise, 2) if noise else (0.0, 0.0)
        out.append((t, speed * math.sin(psi) + ne, speed * math.cos(psi) + nn))
    return out


@pytest.mark.parametrize("rate", [0.0, 0.2, -0.35])
def test_turn_fit_finds_the_turn_rate_across_north(rate: float) -> None:
    # psi_f = 3.0 rad: the courses cross +-pi (south) inside the window: unwrapped.
    samples = _circle_velocities(rate, 1.5, 100.0, 2.0, 10.0)
    speed, course, fitted = turn_fit(samples, 100.0)
    assert speed == pytest.approx(1.5) and fitted == pytest.approx(rate, abs=1e-9)
    assert math.remainder(course - 3.0, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


def test_turn_fit_with_noise_and_nothing_to_fit() -> None:
    samples = _circle_velocities(0.2, 1.0, 50.0, 2.0, 10.0, noise=0.05)
    _, _, fitted = turn_fit(samples, 50.0)
    assert abs(fitted - 0.2) < 0.06
    assert turn_fit([], 0.0) == (0.0, 0.0, 0.0)
    assert turn_fit([(1.0, 0.0, 0.0), (2.0, 0.0, 0.0)], 2.0) == (0.0, 0.0, 0.0)  # stopped
    assert turn_fit([(2.0, 1.0, 0.0)], 2.0)[2] == 0.0  # one sample: no turn


def test_ctrv_is_the_circle_and_the_straight_line() -> None:
    r, v = 8.0, 2.0
    for tau in (0.5, 2.0, 10.0):
        de, dn = ctrv(v, 0.0, v / r, tau)  # north, turning right: centre (r, 0)
        a = v * tau / r
        assert (de, dn) == pytest.approx((r * (1 - math.cos(a)), r * math.sin(a)))
    assert ctrv(v, math.pi / 2, 0.0, 3.0) == pytest.approx((6.0, 0.0))
    assert ctrv(v, math.pi / 2, 1e-9, 3.0) == pytest.approx((6.0, 0.0))


def test_within_is_half_a_tau_squared_and_the_lag() -> None:
    assert within(math.sqrt(3.0) - 1e-9, 0.5, 0.0, 0.75)
    assert not within(math.sqrt(3.0) + 1e-6, 0.5, 0.0, 0.75)
    tau = (-0.15 + math.sqrt(0.15**2 + 0.75)) / 0.5  # 0.25 τ² + 0.15 τ = 0.75
    assert within(tau - 1e-9, 0.5, 0.3, 0.75) and not within(tau + 1e-6, 0.5, 0.3, 0.75)


def test_turn_fit_ignores_the_random_courses_of_a_stop() -> None:
    # Standing still (courses anywhere, 0.05 m/s of noise), then driving off north at
    # 0.5 m/s^2: the course at the end is north, not a sum of the stop's turns (unwrapped
    # one by one, this sequence's courses ended 13.16 rad, turning at 3.2 rad/s).
    rng = np.random.default_rng(5)
    samples = []
    for k in range(21):
        t = k / 10.0
        v = max(0.0, 0.5 * (t - 1.0))
        ne, nn = rng.normal(0.0, 0.05, 2)
        samples.append((t, ne, v + nn))
    _, course, rate = turn_fit(samples, 2.0)
    assert abs(math.remainder(course, 2 * math.pi)) < 0.25 and abs(rate) < 0.3
