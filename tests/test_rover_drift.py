"""The slow-fault test (fdi/drift.py) and the hold after a level change (fdi/level.py), on
synthetic Doppler-free series with known noise (seeded)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fdi.drift import DriftTest, calibrate, concave_cap, monotone_floor, sigma_at
from fdi.errors import ConfigError
from fdi.level import HoldParams, LevelHold
from fdi.rover import Decision, FixInput, RoverDetectorParams, RoverIsolator

H = (1.0, 3.0, 10.0, 30.0, 100.0)
SIG = (0.07, 0.1, 0.16, 0.27, 0.35)


def _walk(rng: np.random.Generator, n: int, dt: float, tau: float = 60.0,
          sigma: float = 0.35) -> np.ndarray:
    """A first-order Gauss-Markov error per axis (n x 2)."""
    phi = math.exp(-dt / tau)
    q = sigma * math.sqrt(1 - phi * phi)
    x = np.zeros((n, 2))
    x[0] = rng.normal(0, sigma, 2)
    for k in range(1, n):
        x[k] = phi * x[k - 1] + rng.normal(0, q, 2)
    return x


def test_sigma_at_interpolates_and_grows_beyond_the_last_horizon() -> None:
    assert sigma_at(0.5, H, SIG) == SIG[0]
    assert sigma_at(2.0, H, SIG) == pytest.approx(0.5 * (SIG[0] + SIG[1]))
    assert sigma_at(400.0, H, SIG) == pytest.approx(SIG[-1] * 2.0)


def test_bad_configuration_is_a_config_error() -> None:
    with pytest.raises(ConfigError):
        DriftTest((1.0, 3.0), (0.1,), 0.1)
    with pytest.raises(ConfigError):
        DriftTest((3.0, 1.0), (0.1, 0.1), 0.1)
    with pytest.raises(ConfigError):
        DriftTest((1.0, 3.0), (0.1, 0.0), 0.1)


def test_clean_series_stays_under_the_gate_and_a_ramp_is_seen_in_seconds() -> None:
    rng = np.random.default_rng(7)
    dt = 0.1
    n = 6000
    err = _walk(rng, n, dt, tau=60.0, sigma=0.2)
    sig = calibrate([(k * dt, err[k, 0], err[k, 1]) for k in range(n)], H)
    test = DriftTest(H, sig, 0.0)
    worst = 0.0
    for k in range(n):
        t = k * dt
        r = test.test(t, (err[k, 0], err[k, 1]), (0.0, 0.0))
        worst = max(worst, r.g)
        test.commit(t, (err[k, 0], err[k, 1]), (0.0, 0.0))
    assert worst < 5.0, worst
    # The same receiver, then a ramp of 0.2 m/s north: caught within 10 s (offset 2 m).
    start = n * dt
    detected = None
    for j in range(400):
        t = start + j * dt
        b = (err[-1, 0], err[-1, 1] + 0.2 * (j + 1) * dt)
        r = test.test(t, b, (0.0, 0.0))
        if r.g > 5.0:
            detected = t - start
            # The reported reference is from before the ramp began.
            assert r.ref_t <= start
            break
    assert detected is not None and detected <= 10.0, detected


def test_references_can_be_forgotten_and_rebased() -> None:
    test = DriftTest(H, SIG, 0.0)
    for k in range(50):
        test.commit(float(k), (0.0, 0.0), (1.0, 0.0))
    assert test.at_or_before(20.5) is not None
    test.forget_after(20.0)
    ref = test.at_or_before(49.0)
    assert ref is not None and ref[0] == 20.0
    test.rebase(1.0, -2.0)
    ref = test.at_or_before(49.0)
    assert ref is not None and ref[1] == (1.0, -2.0)
    old = test.oldest(15.0)
    assert old is not None and old[1] == (1.0, -2.0)
    test.reset_short()
    assert test.at_or_before(49.0) is None and test.oldest(15.0) is not None
    test.reset()
    assert test.oldest(15.0) is None


def test_calibration_once_at_start_then_frozen() -> None:
    rng = np.random.default_rng(3)
    dt = 0.2
    err = _walk(rng, 3000, dt, tau=60.0, sigma=0.2)
    test = DriftTest(H[:4], (1.0, 1.0, 1.0, 1.0), 0.0, calibrate_s=300.0)
    for k in range(3000):
        test.commit(k * dt, (err[k, 0], err[k, 1]), (0.0, 0.0))
        if k * dt < 299.0:
            assert not test.calibrated
    assert test.calibrated
    # Robust σ of a 60 s Gauss-Markov process's increments (σ 0.2): about 0.03 at 1 s, 0.14 at
    # 30 s; the floor (0.2 x the configured 1.0) holds the short horizons up.
    assert test.sigmas[0] == pytest.approx(0.2)
    assert 0.1 < test.sigmas[3] < 0.3
    frozen = test.sigmas
    for k in range(3000, 3100):
        test.commit(k * dt, (err[-1, 0] + 5.0, 0.0), (0.0, 0.0))
    assert test.sigmas == frozen


def test_the_long_horizons_carry_the_calibration_s_own_uncertainty() -> None:
    """(D8): σ_H x (1 + m/sqrt(n_H)) for H >= margin_min_h, n_H = 2 (T - H)/H: over 300 s,
    18 differences at 30 s (x 1.354 with m = 1.5), 58 at 10 s left alone; the concave cap
    (D5) still bounds the result by the shorter horizons."""
    rng = np.random.default_rng(11)
    dt = 0.2
    err = _walk(rng, 1600, dt, tau=5.0, sigma=0.2)  # saturated by 10 s: the cap is far
    plain = DriftTest(H[:4], (1.0,) * 4, 0.0, calibrate_s=300.0, floor_frac=0.02)
    wide = DriftTest(H[:4], (1.0,) * 4, 0.0, calibrate_s=300.0, floor_frac=0.02,
                     margin=1.5, margin_min_h=30.0)
    for k in range(1600):
        for d in (plain, wide):
            d.commit(k * dt, (err[k, 0], err[k, 1]), (0.0, 0.0))
    assert plain.calibrated and wide.calibrated
    assert wide.sigmas[:3] == plain.sigmas[:3]
    expected = plain.sigmas[3] * (1.0 + 1.5 / math.sqrt(2.0 * (300.0 - 30.0) / 30.0))
    cap = plain.sigmas[2] * math.sqrt(3.0)  # (D5) from the 10 s horizon
    assert wide.sigmas[3] == pytest.approx(min(expected, cap))
    assert wide.sigmas[3] > 1.2 * plain.sigmas[3]


def test_a_provisional_calibration_sharpens_the_watched_horizon_only() -> None:
    """After precal_s the watched horizon's statistic uses the same robust estimate x
    precal_factor (never wider than configured; at precal_s itself exactly that); the σ that
    hold or withhold fixes stay as configured until the calibration proper at calibrate_s."""
    rng = np.random.default_rng(5)
    dt = 0.2
    err = _walk(rng, 2000, dt, tau=60.0, sigma=0.2)
    configured = (1.0, 1.0, 1.0, 1.0)
    test = DriftTest(H[:4], configured, 0.0, calibrate_s=300.0, floor_frac=0.02,
                     watch_s=10.0, precal_s=120.0, precal_factor=2.0)
    plain = DriftTest(H[:4], configured, 0.0, calibrate_s=120.0, floor_frac=0.02)
    off = DriftTest(H[:4], configured, 0.0, calibrate_s=300.0, floor_frac=0.02, watch_s=10.0)
    for k in range(2000):
        t = k * dt
        b = (err[k, 0], err[k, 1])
        if k in (500, 601, 750, 1250):  # a 0.5 m step against the references 10 s before
            step = (b[0] + 0.5, b[1])
            r, r_off = test.test(t, step, (0.0, 0.0)), off.test(t, step, (0.0, 0.0))
            assert r.g == pytest.approx(r_off.g)  # the tests that hold fixes: unchanged
            if t < 120.0:
                assert r.g_watch == pytest.approx(r_off.g_watch)
            else:  # sharpened: at most 2 x a calibration's σ(10 s), itself under 0.5
                assert r.g_watch > 2.0 * r_off.g_watch
            if k == 601:  # the first provisional σ: 2 x the 120 s calibration's σ(10 s)
                ref = test.at_or_before(t - 10.0)
                assert ref is not None
                size = math.hypot(step[0] - ref[1][0], step[1] - ref[1][1])
                assert r.g_watch == pytest.approx(size / (2.0 * plain.sigmas[2]), rel=0.01)
        for d in (test, plain, off):
            d.commit(t, b, (0.0, 0.0))
        if t < 299.0:
            assert test.sigmas == configured and not test.calibrated
    assert plain.calibrated and plain.sigmas[2] < 0.5
    assert test.calibrated and test.sigmas == off.sigmas  # the same sample, the same σ


def test_the_provisional_calibration_s_margin_shrinks_as_its_sample_grows() -> None:
    """(D7) is estimated again every PRECAL_EVERY_S on every difference collected so far,
    its factor 1 + (k0 - 1)·sqrt(precal_s / T) after T seconds: 2.0 at 120 s, about 1.63
    near 300 s; dropped at the calibration proper."""
    rng = np.random.default_rng(9)
    dt = 0.2
    err = _walk(rng, 1600, dt, tau=60.0, sigma=0.2)
    test = DriftTest(H[:4], (1.0,) * 4, 0.0, calibrate_s=300.0, floor_frac=0.02,
                     watch_s=10.0, precal_s=120.0, precal_factor=2.0)
    seen: list[tuple[float, float]] = []  # (seconds collected, factor) at each estimate
    prov = None
    for k in range(1600):
        test.commit(k * dt, (err[k, 0], err[k, 1]), (0.0, 0.0))
        if test._prov is not prov and test._prov is not None:
            prov = test._prov
            # the same sample at factor 1: the ratio is the factor (nothing here is capped
            # by the configured σ or the floor, and D5 scales with it)
            unit = test._estimate(1.0, provisional=True)
            seen.append((k * dt, prov[2] / unit[2]))
    assert test.calibrated and test._prov is None
    assert len(seen) >= 17 and seen[0][0] == pytest.approx(120.0)
    for t, factor in seen:
        assert factor == pytest.approx(1.0 + math.sqrt(120.0 / t), rel=1e-9), (t, factor)
    assert seen[0][1] == pytest.approx(2.0) and seen[-1][1] < 1.65


HP = HoldParams(H, SIG, 0.0, 0.0, exit_sigmas=3.0, side_sigmas=2.0, exit_lag_s=1.0,
                output_s=10.0, max_s=120.0)


def _hold_run(hold: LevelHold, bs: list[tuple[float, float]], t0: float, dt: float,
              stale: bool = False, last_step: tuple[float, float] | None = None) -> list[str]:
    out = []
    for j, b in enumerate(bs):
        out.append(hold.step(t0 + j * dt, b, (1.0, 0.0), (0.0, 0.0), stale, dt,
                             last_step=last_step).action)
    return out


def test_hold_exits_when_the_fixes_come_back_to_the_old_track() -> None:
    hold = LevelHold(HP, 10.0, 9.0, (0.0, 0.0), (1.0, 0.0))
    acts = _hold_run(hold, [(1.5, 0.0)] * 20 + [(0.02, 0.0)] * 20, 10.0, 0.1)
    assert acts[:20] == ["track"] * 20
    assert "exit" in acts[20:]
    assert acts.index("exit") - 20 <= 12  # the short fixed lag (1 s at 10 Hz) and a margin


def test_hold_takes_the_new_fixes_when_they_sit_at_the_older_level() -> None:
    """The end of a missed ramp: the old track (anchor) is 3 m off the level of 60 s ago,
    the new fixes are back at it."""
    hold = LevelHold(HP, 100.0, 99.0, (3.0, 0.0), (1.0, 0.0), old=[(40.0, (0.0, 0.0))])
    acts = _hold_run(hold, [(0.1, 0.0)] * 30, 100.0, 0.1)
    assert "new_level" in acts and acts.index("new_level") <= 12


HP_LEVEL = replace(HP, level_lag_s=10.0)


def test_a_slow_hold_does_not_take_a_running_ramp_for_an_older_level() -> None:
    """A 0.1 m/s ramp (10 Hz) whose fixes pass the level of 60 s ago: with the short lag the
    hold takes them for the new level within 1 s; with level_lag_s it keeps the old track."""
    ramp = [(1.0 + 0.01 * j, 0.0) for j in range(200)]
    short = LevelHold(HP, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0), old=[(40.0, (1.5, 0.0))])
    acts = _hold_run(short, ramp, 100.0, 0.1)
    assert "new_level" in acts and acts.index("new_level") <= 12
    held = LevelHold(HP_LEVEL, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0), old=[(40.0, (1.5, 0.0))])
    assert "new_level" not in _hold_run(held, ramp, 100.0, 0.1)


def test_a_slow_hold_does_not_take_a_slow_ramp_that_lingers_near_an_older_level() -> None:
    """A 0.04 m/s ramp (10 Hz) that spends 25 s within a third of the old track's distance
    of the level of 60 s ago, moving 0.4 m in 10 s (under 3 σ(10 s), 0.48 m): with the short
    lag for every arrival (level_lag_s = 0) the hold takes it for the new level at once; with
    level_lag_s it drifted there and never does, and its fixes are passed on meanwhile."""
    ramp = [(1.0 + 0.004 * j, 0.0) for j in range(250)]
    short = LevelHold(HP, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0), old=[(40.0, (1.5, 0.0))])
    acts = _hold_run(short, ramp, 100.0, 0.1)
    assert "new_level" in acts and acts.index("new_level") <= 12
    held = LevelHold(HP_LEVEL, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0), old=[(40.0, (1.5, 0.0))])
    acts = _hold_run(held, ramp, 100.0, 0.1)
    assert "new_level" not in acts and acts.count("raw") >= 200


def test_a_slow_hold_takes_fixes_that_stepped_to_an_older_level() -> None:
    """The end of a fault: the fixes step from the old track to the older level (the
    caller's last step of the fixes, here as the hold begins) by half the track's distance
    from it or more: taken at once; by less: taken after level_lag_s there. Fixes that
    drifted there and stay are passed on, flagged, and end the hold only when they have been
    consistent with their own Doppler for 30 s."""
    stepped = LevelHold(HP_LEVEL, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0),
                        old=[(40.0, (1.5, 0.0))])
    acts = _hold_run(stepped, [(1.45, 0.0)] * 150, 100.0, 0.1, last_step=(100.0, 1.45))
    assert "new_level" in acts and acts.index("new_level") <= 12
    small = LevelHold(HP_LEVEL, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0),
                      old=[(40.0, (1.5, 0.0))])
    acts = _hold_run(small, [(1.45, 0.0)] * 150, 100.0, 0.1, last_step=(100.0, 0.5))
    assert "new_level" in acts and 99 <= acts.index("new_level") <= 102
    assert set(acts[:99]) == {"raw"}  # meanwhile the receiver's fix is passed on, flagged
    drifted = LevelHold(HP_LEVEL, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0),
                        old=[(40.0, (1.5, 0.0))])
    acts = _hold_run(drifted, [(1.45, 0.0)] * 400, 100.0, 0.1)
    assert "new_level" not in acts and "consistent" in acts
    assert 299 <= acts.index("consistent") <= 302 and set(acts[:299]) == {"raw"}


def test_hold_keeps_the_old_track_through_a_multipath_step() -> None:
    """A 1.5 m step: the old track is at the older level, the new fixes are not."""
    hold = LevelHold(HP, 100.0, 99.0, (0.05, 0.0), (1.0, 0.0), old=[(40.0, (0.0, 0.0))],
                     slow=False)
    acts = _hold_run(hold, [(1.55, 0.0)] * 150, 100.0, 0.1)
    assert acts[:100].count("track") == 100
    assert "give_up" in acts  # an abrupt step is the receiver's again after output_s


def test_hold_after_a_frozen_stretch_trusts_the_live_receiver() -> None:
    hold = LevelHold(HP, 10.0, 9.0, (0.0, 0.0), (1.0, 0.0), stale_m=1.0)
    frozen = _hold_run(hold, [(-0.1 * j, 0.0) for j in range(50)], 10.0, 0.1, stale=True)
    assert "exit" not in frozen
    live = _hold_run(hold, [(6.0, 0.0)] * 30, 15.0, 0.1)
    assert "exit" in live


def test_hold_passes_the_live_receiver_on_at_once_after_a_freeze() -> None:
    """Never worse than doing nothing: the first fresh fix after a frozen stretch is passed on
    (``raw``) while the evidence to end the hold builds up, not the void-Doppler track."""
    for fresh, action in ((True, "raw"), (False, "track")):
        hold = LevelHold(HP, 10.0, 9.0, (0.0, 0.0), (1.0, 0.0), stale_m=1.0)
        # 6 m off the track, 12 sigma with the frozen stretch's 0.5 m: not agreeing with it.
        step = hold.step(10.1, (6.0, 0.0), (1.0, 0.0), (0.0, 0.0), False, 0.1, fresh=fresh)
        assert step.action == action and step.g > HP.exit_sigmas


def test_hold_after_a_step_back_passes_the_consistent_receiver_on() -> None:
    hold = LevelHold(HP, 100.0, 99.0, (3.0, 0.0), (1.0, 0.0), prefer_raw=True, slow=False)
    assert set(_hold_run(hold, [(6.0, 0.0)] * 20, 100.0, 0.1)) == {"raw"}
    jumpy = LevelHold(HP, 100.0, 99.0, (3.0, 0.0), (1.0, 0.0), prefer_raw=True, slow=False)
    acts = _hold_run(jumpy, [(6.0 + 2.0 * (j % 2), 0.0) for j in range(20)], 100.0, 0.1)
    assert "track" in acts  # not consistent with its own Doppler: the track
    plain = LevelHold(HP, 100.0, 99.0, (3.0, 0.0), (1.0, 0.0), slow=False)
    assert set(_hold_run(plain, [(6.0, 0.0)] * 20, 100.0, 0.1)) == {"track"}


def test_after_a_step_back_the_older_level_is_matched_as_the_step_back_was() -> None:
    """Fixes that stepped back towards an older level (prefer_raw) end the hold at 0.6 of the
    way, the caller's rule for that step back; otherwise a third of the way is asked."""
    fixes = [(1.5, 0.0)] * 150  # 1.5 m from the older level, the track 3 m from it
    back = LevelHold(HP, 100.0, 99.0, (3.0, 0.0), (1.0, 0.0), old=[(40.0, (0.0, 0.0))],
                     slow=False, prefer_raw=True)
    acts = _hold_run(back, fixes, 100.0, 0.1)
    assert "new_level" in acts and acts.index("new_level") <= 12
    plain = LevelHold(HP, 100.0, 99.0, (3.0, 0.0), (1.0, 0.0), old=[(40.0, (0.0, 0.0))],
                      slow=False)
    assert "new_level" not in _hold_run(plain, fixes, 100.0, 0.1)


def test_a_slow_hold_ends_when_the_fixes_step_back_across_its_track() -> None:
    """The anchor sat 1.4 m inside a slow drift: at the drift's end the fixes step 2.8 m back,
    past the old track (1.4 m beyond it). That is the fault's end, not a new one."""
    fixes = [(1.5 + 0.005 * j, 0.0) for j in range(20)] + [(-1.35, 0.0)] * 30
    hold = LevelHold(HP, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0))
    acts = _hold_run(hold, fixes, 100.0, 0.1)
    assert "ended" in acts and 20 < acts.index("ended") <= 32
    # A step only part of the way back (not past the track) ends nothing by this rule.
    part = LevelHold(HP, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0))
    fixes = [(1.5 + 0.005 * j, 0.0) for j in range(20)] + [(0.9, 0.0)] * 30
    assert "ended" not in _hold_run(part, fixes, 100.0, 0.1)


def _stepped_run(hold: LevelHold, fixes: list[tuple[float, float]], j_step: int
                 ) -> list[str]:
    """``fixes`` at 10 Hz from t = 100 s, the caller's last step of b at index ``j_step``."""
    out = []
    for j, b in enumerate(fixes):
        step = None if j < j_step else (100.0 + j_step * 0.1, math.dist(b, fixes[j_step - 1]))
        out.append(hold.step(100.0 + j * 0.1, b, (1.0, 0.0), (0.0, 0.0), False, 0.1,
                             last_step=step).action)
    return out


def test_a_slow_hold_ends_when_the_fixes_step_back_past_it_to_the_older_levels() -> None:
    """A drift found late: the anchor sits 1.1 m into it, the fixes 0.6 m beyond the anchor
    when the drift ends and they step 1.7 m back, 1.1 m past the anchor (further off than
    before), to where the levels before the drift are. That is the fault's end."""
    older = [(40.0, (-1.1, 0.0)), (50.0, (-1.2, 0.1)), (60.0, (-1.0, -0.1))]
    fixes = [(0.5 + 0.005 * j, 0.0) for j in range(20)] + [(-1.1, 0.05)] * 30
    acts = _stepped_run(LevelHold(HP, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0), old=older),
                        fixes, 20)
    assert "ended" in acts and 20 < acts.index("ended") <= 32
    # ... and the returning fixes are passed on (raw) from the step on, not the old track
    assert acts[20:acts.index("ended")] == ["raw"] * (acts.index("ended") - 20)
    # Without older levels there is no evidence for the new fixes: no end by this rule.
    acts = _stepped_run(LevelHold(HP, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0)), fixes, 20)
    assert "ended" not in acts
    # The same step to a level that is no nearer the older ones (a multipath step past the
    # track, sideways): no end.
    side = [(0.5 + 0.005 * j, 0.0) for j in range(20)] + [(-0.8, 1.3)] * 30
    acts = _stepped_run(LevelHold(HP, 100.0, 99.0, (0.0, 0.0), (1.0, 0.0), old=older),
                        side, 20)
    assert "ended" not in acts


def test_slow_hold_ends_when_the_receiver_is_consistent_for_30_s() -> None:
    hold = LevelHold(HP, 100.0, 99.0, (3.0, 0.0), (1.0, 0.0))
    acts = _hold_run(hold, [(6.0, 0.0)] * 400, 100.0, 0.1)
    assert "consistent" in acts
    assert 295 <= acts.index("consistent") <= 310  # CONSISTENT_S at 10 Hz
    # A receiver still drifting (0.1 m/s) is not consistent with its own Doppler.
    drifting = LevelHold(HP, 100.0, 99.0, (3.0, 0.0), (1.0, 0.0))
    acts = _hold_run(drifting, [(6.0 + 0.01 * j, 0.0) for j in range(400)], 100.0, 0.1)
    assert "consistent" not in acts


def _isolator_run(ramp_mps: float, jump_at: int | None = None) -> list[tuple[object, ...]]:
    """1 Hz, 2 m/s east, a wiggle of 2 cm; a ramp north from t = 200 s for 80 s that the tests
    miss (under their gates), then the fixes step back to the truth; optionally a 1.5 m jump
    at ``jump_at``. Returns (t, error of the fix, error of the output, decision) per epoch."""
    p = replace(RoverDetectorParams(), drift_sigma_m=(0.1, 0.15, 0.25, 0.4, 0.6),
                drift_calibrate_s=0.0, drift_warn_sigmas=0.0)
    iso = RoverIsolator(p)
    out: list[tuple[object, ...]] = []
    for k in range(400):
        t = float(k)
        err_n = 0.02 * math.sin(0.3 * k) + (ramp_mps * (k - 199) if 200 <= k < 280 else 0.0)
        if k == jump_at:
            err_n += 1.5
        z = (2.0 * t, err_n, 0.0)
        d = iso.step(FixInput(t, z, 2.0, 90.0))
        o = d.out_enu
        out.append((t, abs(err_n), None if o is None else math.hypot(o[0] - 2.0 * t, o[1]), d))
    return out


def test_a_step_back_after_a_missed_ramp_passes_the_receiver_on() -> None:
    run = _isolator_run(0.03)
    ramp = [r for r in run if 200 <= r[0] < 280]
    assert not any(r[3].fault for r in ramp)  # missed: the step back is what is tested here
    first = run[280][3]
    assert first.fault and "step_back" in first.reason
    # Never worse than the receiver in the 10 s after the ramp's end.
    for t, raw, o, _ in run[280:291]:
        assert o is None or o <= raw + 1e-6, (t, raw, o)


def test_a_jump_is_still_replaced_by_the_prediction() -> None:
    run = _isolator_run(0.0, jump_at=150)
    d = run[150][3]
    assert d.fault and d.action == "replace" and "step_back" not in d.reason
    assert run[150][2] is not None and run[150][2] < 0.2


def test_concave_cap_bounds_long_horizons_by_the_shorter_ones() -> None:
    """(D5): σ_H <= σ_h √(H/h); a long horizon inflated by pairs across faults is capped."""
    capped = concave_cap(H, (0.1, 0.15, 0.27, 0.9, 1.8))
    assert capped[:3] == (0.1, 0.15, 0.27)
    assert capped[3] == pytest.approx(0.27 * math.sqrt(3.0))
    assert capped[4] == pytest.approx(capped[3] * math.sqrt(100.0 / 30.0))
    assert concave_cap(H, SIG) == SIG  # a consistent calibration is unchanged


def test_a_long_horizon_is_never_below_a_shorter_one() -> None:
    """(D9): σ_H >= σ_h for H >= h; a long horizon whose few differences came out low (dgps
    1 Hz: σ(100 s) 0.39 m under σ(30 s) 0.52 m, a false hold) is raised to the shorter one's."""
    assert monotone_floor((0.095, 0.165, 0.3, 0.52, 0.386)) == (0.095, 0.165, 0.3, 0.52, 0.52)
    assert monotone_floor(SIG) == SIG  # a consistent calibration is unchanged
    # In the calibration at start: a series whose 100 s differences are small against its
    # 30 s ones (a 20 s oscillation that the 100 s pairs happen to straddle in phase).
    dt = 1.0
    t = np.arange(400) * dt
    b = 0.5 * np.sin(2.0 * math.pi * t / 20.0 + 0.3)
    test = DriftTest(H, (1.0,) * 5, 0.0, calibrate_s=300.0, floor_frac=0.01)
    for k in range(400):
        test.commit(k * dt, (float(b[k]), 0.0), (0.0, 0.0))
    assert test.calibrated
    assert list(test.sigmas) == sorted(test.sigmas)
    assert test.sigmas[4] == test.sigmas[3]


# ------------------------------------------------------------------ frozen receivers


def _receiver_run(freeze: tuple[float, float] | None = None, *, rate: float = 10.0,
                  quantum: float = 0.018, static_hold: bool = False, seed: int = 7,
                  position_only: bool = False) -> list[tuple[float, Decision]]:
    """A receiver east at 1 m/s with stops of 20 s every 100 s (from 95 s), white noise 2 cm
    per axis and altitude, coordinates rounded to ``quantum``, speed to 0.005 m/s, course to
    0.1 deg. ``freeze`` = (start, end) s: the receiver repeats its whole last fix (with
    ``position_only`` its position alone, its Doppler live). ``static_hold``: at stops it pins
    its fix, as a receiver's static navigation does (speed 0, course and position held)."""
    rng = np.random.default_rng(seed)
    iso = RoverIsolator(replace(RoverDetectorParams(), drift_calibrate_s=0.0))
    out: list[tuple[float, Decision]] = []
    x = 0.0
    held: FixInput | None = None
    pinned: FixInput | None = None
    for k in range(int(400 * rate)):
        t = k / rate
        stopped = (t - 95.0) % 100.0 < 20.0 and t >= 95.0
        v = 0.0 if stopped else 1.0
        x += v / rate
        e, n, u = (x + rng.normal(0, 0.02), rng.normal(0, 0.02), rng.normal(0, 0.02))
        ve, vn = v + rng.normal(0, 0.03), rng.normal(0, 0.03)
        fix = FixInput(t, (round(e / quantum) * quantum, round(n / quantum) * quantum,
                           round(u, 3)),
                       round(math.hypot(ve, vn) / 0.005) * 0.005,
                       round(math.degrees(math.atan2(ve, vn)) % 360.0, 1))
        if static_hold and stopped:
            pinned = pinned or fix._replace(speed_mps=0.0)
            fix = pinned._replace(t_s=t)
        else:
            pinned = None
        if freeze is not None and freeze[0] <= t < freeze[1]:
            held = held or fix
            fix = (held._replace(t_s=t) if not position_only
                   else fix._replace(enu=held.enu))
        out.append((t, iso.step(fix)))
    return out


def _frozen_at(run: list[tuple[float, Decision]]) -> list[float]:
    return [t for t, d in run if "frozen" in d.reason]


def test_a_receiver_that_never_repeats_is_frozen_at_its_second_repeat() -> None:
    """At a stop, where its own speed cannot tell: the chance of a live repeat is learned from
    the fixes passed on (none repeated in 3000), so two repeats in a row are a freeze."""
    assert _frozen_at(_receiver_run()) == []
    run = _receiver_run((300.0, 310.0))  # stopped from 295 s to 315 s
    first = _frozen_at(run)[0]
    assert first == pytest.approx(300.2)  # 300.0 is the live fix, 300.1 and 300.2 repeat it
    assert all(d.action != "accept" for t, d in run if 300.2 <= t < 310.0)


def test_a_receiver_with_a_static_hold_is_given_longer() -> None:
    """One that pins its fix at every stop: its first stop looks like a freeze (nothing says
    otherwise yet); from then on its repeat rate (~0.2) gives it 5 repeats (0.5 s at 10 Hz,
    at most stale_s); a freeze while moving is found by stale_move_m all the same."""
    run = _receiver_run(static_hold=True)
    firsts = [min(t for t in _frozen_at(run) if stop <= t < stop + 20.0)
              for stop in (95.0, 195.0, 295.0)]
    assert firsts == pytest.approx([95.2, 195.5, 295.5])
    moving = _receiver_run((150.0, 160.0), static_hold=True)
    assert min(t for t in _frozen_at(moving) if t >= 150.0) <= 150.3 + 1e-9  # stale_move_m


def test_a_position_that_repeats_while_the_doppler_moves_is_frozen() -> None:
    """Its own speed (1 m/s) says it moved stale_move_m (0.15 m) and 1.6 of its coordinate
    quanta: with 1.8 cm coordinates at the second repeat at 10 Hz (0.3 m, the rule before,
    took the third), with 18 cm ones (0.29 m) at the third (the fourth where the reported
    speed is under 0.96 m/s)."""
    for quantum, (first, last) in ((0.018, (150.2, 150.2)), (0.18, (150.3, 150.4))):
        run = _receiver_run((150.0, 160.0), position_only=True, quantum=quantum)
        assert first - 1e-9 <= min(_frozen_at(run)) <= last + 1e-9
        assert _frozen_at(_receiver_run(quantum=quantum)) == []


def test_a_receiver_frozen_at_a_stop_is_taken_back_when_it_resumes() -> None:
    """A receiver that pins its fix at stops (speed 0) freezes at 110 s, at a stop; the vehicle
    drives off at 115 s and the receiver resumes at 125 s, 10 m on. Its frozen speed was 0, so
    no displacement was integrated from the void Doppler: the hold still knows the Doppler was
    void and takes the live, self-consistent receiver back within 2 s (it alarmed for 30 s,
    until CONSISTENT_S: `coarse` 10 Hz seed 602, 122 clean epochs)."""
    run = _receiver_run((110.0, 125.0), static_hold=True)
    back = min(t for t, d in run if t >= 125.0 and d.action == "accept")
    assert back <= 127.5
    assert all(d.action == "accept" for t, d in run if back <= t < 195.0)


# ------------------------------------------------------------------ the ramp's own horizon


def test_the_watched_horizon_is_reported_alone() -> None:
    """g_watch is sqrt(Λ_H) of the watched horizon (D4 before the maximum); 0 when unwatched."""
    for watch, expected in ((10.0, 0.5 / SIG[2]), (0.0, 0.0)):
        test = DriftTest(H, SIG, 0.0, watch_s=watch)
        for k in range(31):
            test.commit(float(k), (0.0, 0.0), (1.0, 0.0))
        res = test.test(31.0, (0.5, 0.0), (1.0, 0.0))
        assert res.g == pytest.approx(0.5 / SIG[0])  # the 1 s horizon gives the maximum
        assert res.g_watch == pytest.approx(expected)


def _ramp_flagged_at(watch_sigmas: float, rate_mps: float = 0.09) -> float:
    """1 Hz, 2 m/s east, exact fixes; a ramp north from t = 200 s: when is it first flagged by
    the drift test (the Doppler test off: on exact fixes its floor, 0.5 m, would see it)?"""
    p = replace(RoverDetectorParams(), drift_sigma_m=(0.1, 0.15, 0.2, 0.4, 0.6),
                drift_calibrate_s=0.0, ramp_sigmas=watch_sigmas, doppler_test=False)
    iso = RoverIsolator(p)
    for k in range(260):
        t = float(k)
        d = iso.step(FixInput(t, (2.0 * t, rate_mps * max(0, k - 199), 0.0), 2.0, 90.0))
        if d.fault:
            return t - 199.0
    return math.inf


def test_a_ramp_is_flagged_sooner_on_its_own_horizon() -> None:
    """A 0.09 m/s ramp: 0.9 m in 10 s, 4.5 σ of the 10 s horizon (σ 0.2 m): the maximum over
    the horizons at drift_warn_sigmas (4.5) flags it after 10 s, the watched horizon at 4 σ
    (0.8 m) before."""
    assert _ramp_flagged_at(4.0) <= 9.0
    assert _ramp_flagged_at(0.0) > 10.0
