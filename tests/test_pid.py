"""Heading PID: wrapping, clamping, anti-windup, dt."""

from __future__ import annotations

import pytest

from fdi.pid import HeadingPid, PidConfig


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
