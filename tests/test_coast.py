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


def test_within_is_half_a_tau_squared() -> None:
    assert within(math.sqrt(3.0) - 1e-9, 0.5, 0.75)
    assert not within(math.sqrt(3.0) + 1e-6, 0.5, 0.75)
