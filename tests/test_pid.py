"""Heading PID: wrapping, clamping, anti-windup, dt."""

from __future__ import annotations

import pytest

from fdi.pid import HeadingPid, PidConfig, thrust_to_command
from firmware_host.devtools.rov_sim import NonlinearRovPlant
from firmware_host.rov.config import SimConfig


def test_error_is_wrapped_across_north() -> None:
    pid = HeadingPid(PidConfig(kp=1.0, ki=0.0, kd=0.0))
    assert pid.update(1.0, 359.0, 0.2) == pytest.approx(2.0)
    pid.reset()
    assert pid.update(359.0, 1.0, 0.2) == pytest.approx(-2.0)


def test_output_clamped() -> None:
    pid = HeadingPid(PidConfig(kp=10.0, ki=0.0, kd=0.0, out_min=-50, out_max=50))
    assert pid.update(90.0, 0.0, 0.2) == 50.0
    assert pid.update(-90.0, 0.0, 0.2) == -50.0


def test_anti_windup_integral_does_not_grow_while_saturated() -> None:
    cfg = PidConfig(kp=5.0, ki=1.0, kd=0.0, out_min=-100, out_max=100)
    pid = HeadingPid(cfg)
    for _ in range(100):
        pid.update(90.0, 0.0, 0.2)  # saturated for 20 s
    assert pid.integral < 1.0
    # once the error reverses, the output leaves saturation at once
    assert pid.update(0.0, 10.0, 0.2) < 0.0


def test_integral_scales_with_dt_and_bad_dt_is_ignored() -> None:
    a = HeadingPid(PidConfig(kp=0.0, ki=1.0, kd=0.0))
    b = HeadingPid(PidConfig(kp=0.0, ki=1.0, kd=0.0))
    for _ in range(10):
        a.update(1.0, 0.0, 0.1)
    for _ in range(5):
        b.update(1.0, 0.0, 0.2)
    assert a.output == pytest.approx(b.output) == pytest.approx(1.0)
    assert a.update(1.0, 0.0, 0.0) == a.output


def test_derivative_on_measurement_damps_turn() -> None:
    pid = HeadingPid(PidConfig(kp=0.0, ki=0.0, kd=1.0, d_tau_s=0.0))
    pid.update(0.0, 0.0, 0.2)
    assert pid.update(0.0, 2.0, 0.2) == pytest.approx(-10.0)  # 10 deg/s turning right
    assert pid.update(50.0, 2.0, 0.2) == pytest.approx(0.0)  # setpoint change: no kick


def test_thrust_curve_inverse() -> None:
    """The PID asks for thrust; the command steps over the dead band and inverts c|c|, so the
    nonlinear plant's own thrust curve gives back what was asked (identity by default)."""
    assert thrust_to_command(PidConfig(), 7.5) == 7.5
    cfg = PidConfig(thrust_dead_band_pct=3.0, thrust_expo=1.0)
    plant = NonlinearRovPlant(SimConfig(plant="nonlinear", dead_band_pct=3.0))
    assert thrust_to_command(cfg, 0.0) == 0.0
    for t in (0.01, 1.0, 12.5, 50.0, 100.0):
        c = thrust_to_command(cfg, t)
        assert 3.0 < c <= 100.0
        assert plant.thrust(c) == pytest.approx(t, rel=1e-9)
        assert thrust_to_command(cfg, -t) == -c
    half = PidConfig(thrust_expo=0.5)  # T = 0.5 x + 0.5 x^2
    x = thrust_to_command(half, 37.5) / 100.0
    assert 0.5 * x + 0.5 * x * x == pytest.approx(0.375)
