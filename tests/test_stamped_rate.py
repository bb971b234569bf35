"""The gyro's samples integrated over each period by the trapezoid rule (``StampedRate``).

The compass sample the witness compares with the integrated gyro is the period's newest. The
period's mean rate times the period (what the vehicle gave the witness before) is a right-hand
Riemann sum: its heading at that stamp leads by half a sample times the rate then (0.5 deg in
one of ArduSub's ~9.5 deg/s MANUAL kicks, 3.9 deg in a 77 deg/s turn). The trapezoid over the
samples' stamps is the heading at the stamp.
"""

from __future__ import annotations

import math

import pytest

from firmware_host.rov.ardusub import StampedRate


def _turn(t: float) -> float:
    """A smooth turn back and forth, up to 40 deg/s."""
    return 40.0 * math.sin(2.0 * math.pi * t / 8.0)


def _heading(t: float) -> float:
    return 40.0 * 8.0 / (2.0 * math.pi) * (1.0 - math.cos(2.0 * math.pi * t / 8.0))


def test_the_heading_at_each_stamp_has_no_lead() -> None:
    """Samples at 10 Hz, periods of 200 ms. The mean's heading at the newest stamp is the
    trapezoid's plus h/2 (r(now) - r(start)), exactly: a lead of half a sample times the rate;
    the trapezoid's is the heading at the stamp, to the rule's O(h^2)."""
    dt, hz = 0.2, 10.0
    rate = StampedRate()
    t = 0.0
    rate.add(t, _turn(t))
    rate.take(dt)
    trap = mean = 0.0
    worst_trap = worst_mean = 0.0
    for _ in range(150):  # 30 s
        samples = []
        for _ in range(2):
            t = round(t + 1.0 / hz, 6)
            samples.append(_turn(t))
            rate.add(t, samples[-1])
        r = rate.take(dt)
        assert r is not None
        trap += r * dt
        mean += sum(samples) / len(samples) * dt
        assert mean - trap == pytest.approx(0.5 / hz * (samples[-1] - _turn(0.0)), abs=1e-9)
        worst_trap = max(worst_trap, abs(trap - _heading(t)))
        worst_mean = max(worst_mean, abs(mean - _heading(t)))
    assert worst_mean > 1.9  # 0.05 s x 40 deg/s
    assert worst_trap < 0.1  # measured 0.052


def test_a_gap_or_no_stamps_falls_back_to_the_mean() -> None:
    rate = StampedRate(max_gap_s=0.5)
    rate.add(1.0, 2.0)
    rate.add(1.1, 4.0)
    assert rate.take(0.2) == pytest.approx(3.0)  # the first: nothing before it to join
    rate.add(1.2, 6.0)
    rate.add(1.3, 6.0)
    assert rate.take(0.2) == pytest.approx((5.0 * 0.1 + 6.0 * 0.1) / 0.2)
    rate.add(3.0, 6.0)  # 1.9 s later: a lost stream
    rate.add(3.1, 8.0)
    assert rate.take(0.2) == pytest.approx(7.0)
    rate.add(None, 1.0)
    rate.add(None, 3.0)
    assert rate.take(0.2) == pytest.approx(2.0)
    assert rate.take(0.2) is None  # a silent period
    rate.add(3.5, 5.0)  # the next starts afresh: no sample to join
    assert rate.take(0.2) == pytest.approx(5.0)


def test_stamps_going_back_start_again() -> None:
    rate = StampedRate()
    rate.add(10.0, 1.0)
    rate.take(0.2)
    rate.add(0.1, 3.0)  # the autopilot rebooted
    assert rate.take(0.2) == pytest.approx(3.0)
