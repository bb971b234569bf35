"""firmware_host.runtime.loop: absolute-deadline scheduling and overrun counting, on a fake clock.

No test here sleeps: ``FakeClock.sleep`` advances time instantly.
"""

from __future__ import annotations

import numpy as np
import pytest

from firmware_host.runtime.loop import EpochTimer, FakeClock, FixedRateLoop

PERIOD = 0.125  # a binary fraction: k·PERIOD is exact in floating point


def test_deadlines_are_absolute_no_drift_over_10000_steps() -> None:
    rng = np.random.default_rng(5)
    work = rng.uniform(0.0, 0.8 * PERIOD, 10_000)  # each step takes up to 0.8 periods
    clock = FakeClock(start=1000.0)
    deadlines: list[float] = []
    starts: list[float] = []

    def step(k: int, t: float) -> bool:
        deadlines.append(t)
        starts.append(clock())
        clock.advance(float(work[k]))
        return True

    stats = FixedRateLoop(PERIOD, clock=clock, sleep=clock.sleep).run(step, max_steps=10_000)
    assert stats.steps == 10_000
    assert stats.overruns == 0
    assert deadlines == [1000.0 + k * PERIOD for k in range(10_000)]  # exact
    assert max(abs(s - d) for s, d in zip(starts, deadlines, strict=True)) < 1e-9
    assert max(stats.jitter_s) < 1e-9
    np.testing.assert_allclose(stats.proc_s, work, rtol=0, atol=1e-9)


def test_deadlines_with_a_decimal_period_stay_on_the_grid() -> None:
    # 0.1 s is not exact in binary: `next += period` accumulates rounding only (< 1 ns here),
    # not the step's processing time.
    clock = FakeClock()
    deadlines: list[float] = []

    def step(k: int, t: float) -> bool:
        deadlines.append(t)
        clock.advance(0.07)
        return True

    FixedRateLoop(0.1, clock=clock, sleep=clock.sleep).run(step, max_steps=10_000)
    assert max(abs(t - k * 0.1) for k, t in enumerate(deadlines)) < 1e-9


def test_a_long_step_counts_overruns_and_skips_to_a_future_deadline() -> None:
    clock = FakeClock()
    log: list[tuple[int, float, float]] = []  # (k, deadline, start time)

    def step(k: int, t: float) -> bool:
        log.append((k, t, clock()))
        clock.advance(2.5 * PERIOD if k == 3 else 0.1 * PERIOD)
        return True

    stats = FixedRateLoop(PERIOD, clock=clock, sleep=clock.sleep).run(step, max_steps=8)
    # Step 3 starts at 3P and ends at 5.5P: it overran the deadlines 4P and 5P.
    assert stats.overruns == 2
    assert [(k, t / PERIOD) for k, t, _ in log] == [
        (0, 0.0), (1, 1.0), (2, 2.0), (3, 3.0), (4, 6.0), (5, 7.0), (6, 8.0), (7, 9.0)
    ]
    # No burst of late steps: every step starts at its own deadline, none earlier, none twice.
    assert all(abs(start - t) < 1e-12 for _, t, start in log)
    assert stats.proc_s[3] == pytest.approx(2.5 * PERIOD, abs=1e-12)


def test_a_step_ending_exactly_on_the_next_deadline_is_not_an_overrun() -> None:
    clock = FakeClock()

    def step(k: int, t: float) -> bool:
        clock.advance(PERIOD)
        return True

    stats = FixedRateLoop(PERIOD, clock=clock, sleep=clock.sleep).run(step, max_steps=100)
    assert stats.overruns == 0
    assert clock() == 100 * PERIOD


def test_jitter_is_recorded_when_the_sleep_is_late() -> None:
    clock = FakeClock()

    def late_sleep(seconds: float) -> None:
        clock.sleep(seconds + 0.002)  # the OS wakes us 2 ms late

    def step(k: int, t: float) -> bool:
        clock.advance(0.01)
        return True

    stats = FixedRateLoop(PERIOD, clock=clock, sleep=late_sleep).run(step, max_steps=50)
    assert stats.jitter_s[0] == 0.0  # the first step starts at once
    np.testing.assert_allclose(stats.jitter_s[1:], 0.002, rtol=0, atol=1e-12)
    summary = stats.summary()
    assert summary["steps"] == 50
    assert summary["overruns"] == 0
    assert summary["jitter_p50_ms"] == pytest.approx(2.0, abs=1e-9)
    assert summary["proc_max_ms"] == pytest.approx(10.0, abs=1e-9)


def test_step_returning_false_stops_the_loop_and_bad_period() -> None:
    clock = FakeClock()
    seen: list[int] = []

    def step(k: int, t: float) -> bool:
        seen.append(k)
        return k < 4

    stats = FixedRateLoop(PERIOD, clock=clock, sleep=clock.sleep).run(step)
    assert seen == [0, 1, 2, 3, 4]
    assert stats.steps == 5
    for bad in (0.0, -1.0):
        with pytest.raises(ValueError):
            FixedRateLoop(bad, clock=clock, sleep=clock.sleep)


def test_epoch_timer_counts_overruns_against_the_receiver_period() -> None:
    clock = FakeClock(start=50.0)
    timer = EpochTimer(clock=clock)
    for proc, period in [(0.05, 0.1), (0.15, 0.1), (0.125, 0.125), (3.0, None), (0.3, 0.2)]:
        timer.start()
        clock.advance(proc)
        assert timer.stop(period) == pytest.approx(proc, abs=1e-12)
    assert timer.stats.steps == 5
    assert timer.stats.overruns == 2  # 0.15 > 0.1 and 0.3 > 0.2; equal is on time; None unknown
    np.testing.assert_allclose(timer.stats.proc_s, [0.05, 0.15, 0.125, 3.0, 0.3], atol=1e-12)
