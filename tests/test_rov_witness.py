"""The gyro witness and the noise scales on synthetic compass/gyro data (seeded).

No vehicle: a known heading, a compass of known noise and a gyro of known bias, so that each
property of :mod:`fdi.gyro_witness` (bias learned, spike bound, burst, ramp, recovery) is
checked against numbers it cannot tune itself to.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fdi.gyro_witness import GyroWitness, HingeDrift, WitnessParams
from fdi.heading_ft import FaultTolerantHeading, FtConfig
from fdi.lms_fir import DetectorConfig
from fdi.noise_scale import RobustVariance, TrimmedScale
from firmware_host.rov.config import load_rov_config, project_root
from firmware_host.rov.control import RovController

DT = 0.2


def test_trimmed_scale_follows_noise_not_steps() -> None:
    rng = np.random.default_rng(3)
    sc = TrimmedScale(6, 2)
    est = []
    x = 0.0
    for k in range(3000):
        x = float(rng.normal(0.0, 2.0)) + (30.0 if k >= 1500 else 0.0)  # a step half-way
        sc.push(x)
        if sc.full:
            est.append(sc.sigma)
    # unbiased on average (the trim's bias is calibrated), and the step does not show
    assert float(np.mean(est)) == pytest.approx(2.0, rel=0.1)
    assert max(est[1490:1510]) < 2.0 * 2.5


def test_robust_variance_clips_and_freezes() -> None:
    v = RobustVariance(1.0, 10, 3.0, 0.01)
    v.update(100.0)  # an outlier moves it by at most (9 - 1) / 10
    assert v.var == pytest.approx(1.8)
    v.frozen = True
    v.update(0.0)
    assert v.var == pytest.approx(1.8)


def _run(
    n: int,
    fault: str = "",
    start: int = 300,
    length: int = 10**9,
    mag: float = 0.0,
    noise: float = 1.0,
    seed: int = 1,
    params: WitnessParams | None = None,
    turn_dps: float = 2.0,
) -> tuple[GyroWitness, list[tuple[int, str]]]:
    """A vehicle turning slowly (sinusoid of ``turn_dps`` amplitude: 2 deg/s swings the heading
    by +-12.7 deg), compass noise ``noise``, gyro bias 0.15 deg/s."""
    rng = np.random.default_rng(seed)
    w = GyroWitness(params or WitnessParams())
    psi = 40.0
    events: list[tuple[int, str]] = []
    for k in range(n):
        r = turn_dps * math.sin(2 * math.pi * k * DT / 40.0)
        psi += r * DT
        w.propagate(r + 0.15 + float(rng.normal(0.0, 0.05)), DT)
        y = psi + float(rng.normal(0.0, noise))
        on = start <= k < start + length
        if on and fault == "step":
            y += mag
        elif on and fault == "ramp":
            y += mag * (k - start) * DT
        elif on and fault == "burst":
            y += float(rng.normal(0.0, mag))
        st = w.update(y % 360.0, DT)
        for name in ("confirmed", "dismissed", "recovered"):
            if getattr(st, name):
                events.append((k, name))
    return w, events


@pytest.mark.parametrize("seed", range(1, 6))
def test_bias_learned_and_quiet_without_fault(seed: int) -> None:
    w, events = _run(3000, noise=1.0, seed=seed)  # 10 minutes
    assert abs(w.bias - 0.15) < 0.01
    assert [e for e in events if e[1] == "confirmed"] == []


@pytest.mark.parametrize("length", [1, 2, 3])
@pytest.mark.parametrize("seed", range(1, 6))
def test_spike_of_up_to_3_samples_never_confirms(length: int, seed: int) -> None:
    # 3 (clip - kappa) < h: whatever the size, three samples cannot reach h
    p = WitnessParams()
    assert 3 * (p.clip - p.kappa) < p.h and 3 * (p.slow_clip - p.slow_kappa) < p.slow_h
    _, events = _run(600, "step", length=length, mag=90.0, seed=seed)
    assert [e for e in events if e[1] == "confirmed"] == []


@pytest.mark.parametrize("seed", range(1, 6))
def test_step_confirmed_within_5_samples_and_ramp_within_40_s(seed: int) -> None:
    _, ev = _run(400, "step", mag=-6.0, seed=seed)
    k = next(k for k, e in ev if e == "confirmed")
    assert 0 <= k - 300 <= 4
    _, ev = _run(700, "ramp", mag=0.1, seed=seed)
    k = next(k for k, e in ev if e == "confirmed")
    assert 0 < (k - 300) * DT <= 40.0


@pytest.mark.parametrize("seed", range(1, 6))
def test_noise_burst_not_confirmed(seed: int) -> None:
    _, ev = _run(600, "burst", length=50, mag=4.0, noise=0.5, seed=seed)
    assert [e for e in ev if e[1] == "confirmed"] == []


def test_drift_that_ends_is_taken_back() -> None:
    w, ev = _run(600, "step", length=100, mag=20.0)
    names = [e for _, e in ev if e != "dismissed"]
    assert names == ["confirmed", "recovered"]
    rec = next(k for k, e in ev if e == "recovered")
    assert 400 <= rec <= 400 + 2 * w.p.recover_samples
    assert not w.fault


def test_heading_ft_with_gyro_substitutes_the_gyro_heading() -> None:
    """Through FaultTolerantHeading: a 30 deg drift, the heading used stays on the truth."""
    rng = np.random.default_rng(9)
    ft = FaultTolerantHeading(DetectorConfig(), FtConfig())
    psi = 150.0
    errs = []
    events = []
    for k in range(800):
        psi += 0.0
        y = psi + float(rng.normal(0.0, 0.5)) + (30.0 if k >= 400 else 0.0)
        d = ft.step(0.0, y % 360.0, 0.1 + float(rng.normal(0.0, 0.05)), DT)
        if d.event:
            events.append((k, d.event))
        if k >= 400:
            assert d.heading_used is not None
            errs.append(abs((d.heading_used - psi + 180.0) % 360.0 - 180.0))
            assert d.source == "gyro" or k < 405
    assert ("confirmed" in [e for _, e in events])
    assert max(errs) < 1.0


def test_paper_preset_has_no_witness() -> None:
    ft = FaultTolerantHeading(DetectorConfig(), FtConfig(gyro_enabled=False))
    d = ft.step(0.0, 10.0, 0.5, DT)
    assert d.source == "sensor"


def test_third_vote_blames_a_failing_gyro_and_keeps_the_compass() -> None:
    """A gyro whose bias jumps by 1 deg/s while the vehicle (no commands) does not turn: the
    FIR (no commands, no increments) sides with the compass, so the gyro is blamed. (The vote
    is off in the default preset: on the closed loop the FIR learns a slow compass drift.)"""
    rng = np.random.default_rng(4)
    ft = FaultTolerantHeading(DetectorConfig(), FtConfig(gyro_vote=True))
    events = []
    sources = []
    for k in range(1000):
        y = 150.0 + float(rng.normal(0.0, 0.5))
        g = 0.1 + (1.0 if k >= 500 else 0.0) + float(rng.normal(0.0, 0.05))
        d = ft.step(0.0, y, g, DT)
        if d.event:
            events.append(d.event)
        sources.append(d.source)
    assert "gyro_fault" in events and "confirmed" not in events
    assert ft.gyro_failed and sources[-1] == "sensor"


def test_third_vote_does_not_blame_the_gyro_for_a_compass_drift() -> None:
    rng = np.random.default_rng(5)
    ft = FaultTolerantHeading(DetectorConfig(), FtConfig(gyro_vote=True))
    events = []
    for k in range(800):
        y = 150.0 + float(rng.normal(0.0, 0.5)) + (0.5 * (k - 500) * DT if k >= 500 else 0.0)
        d = ft.step(0.0, y % 360.0, 0.1 + float(rng.normal(0.0, 0.05)), DT)
        if d.event:
            events.append(d.event)
    assert "confirmed" in events and "gyro_fault" not in events



# The compass-minus-gyro innovations (deg) of harness seed 7, drift:10@26 (Nomoto plant), in
# the 9 samples before the step and the 8 from it (the step removed): a chance run of large
# alternating differences just before the step.
_PRE_STEP = [-1.04, -0.61, 0.14, -1.11, 0.39, -0.92, 0.34, -0.47, 0.35]
_FROM_STEP = [0.03, -0.80, 0.59, 0.67, -0.10, -0.20, -0.14, -0.54]


@pytest.mark.parametrize("seed", range(1, 6))
def test_step_after_a_run_of_large_differences_is_not_a_burst(seed: int) -> None:
    """That run pushed the short scale over the burst level at the step's first samples,
    the CUSUMs were reset, and the 10 deg step was confirmed 6 samples after it (goal 5).
    Three innovations at one level beyond the jump test are a step, not a burst."""
    conf = _replay_step(_PRE_STEP, _FROM_STEP, 10.0, seed, 0.45)
    assert conf is not None and 0 <= conf <= 5


def _replay_step(pre: list[float], from_step: list[float], mag: float, seed: int,
                 noise: float) -> int | None:
    """The slowly turning vehicle of :func:`_run` with a ``mag`` deg compass step at sample
    300: the compass error ``pre`` in the samples just before it and ``from_step`` (the step
    removed) in the first ones from it, seeded noise elsewhere; the samples from the step to
    its first confirmation (None: none)."""
    rng = np.random.default_rng(seed)
    w = GyroWitness(WitnessParams())
    psi = 40.0
    for k in range(320):
        r = 2.0 * math.sin(2 * math.pi * k * DT / 40.0)
        psi += r * DT
        w.propagate(r + 0.15 + float(rng.normal(0.0, 0.05)), DT)
        y = psi + float(rng.normal(0.0, noise))
        if 300 - len(pre) <= k < 300:
            y = psi + pre[k - 300 + len(pre)]
        elif 300 <= k < 300 + len(from_step):
            y = psi + from_step[k - 300]
        if k >= 300:
            y += mag
        if w.update(y % 360.0, DT).confirmed:
            return k - 300
    return None


def _step_with_bias_error(params: WitnessParams, seed: int) -> float:
    """A permanent 20 deg compass step at sample 300; at its confirmation the gyro bias
    estimate is made 0.05 deg/s wrong (what 20 s of warm-up at 1 deg noise can leave). The
    worst |heading used - true| over the 60 s after the confirmation."""
    rng = np.random.default_rng(seed)
    w = GyroWitness(params)
    psi = 40.0
    worst = 0.0
    conf: int | None = None
    for k in range(300 + 400):
        r = 2.0 * math.sin(2 * math.pi * k * DT / 40.0)
        psi += r * DT
        w.propagate(r + 0.15 + float(rng.normal(0.0, 0.05)), DT)
        y = psi + float(rng.normal(0.0, 1.0)) + (20.0 if k >= 300 else 0.0)
        st = w.update(y % 360.0, DT)
        if st.confirmed and conf is None:
            conf = k
            w.bias += 0.05
        if conf is not None and k - conf <= 300:
            worst = max(worst, abs(st.psi - psi))
    assert conf is not None and w.fault
    return worst


@pytest.mark.parametrize("seed", range(1, 6))
def test_step_offset_compensation_bounds_the_dead_reckoning_drift(seed: int) -> None:
    """After a step the compass minus its learned offset steers the heading again: the
    0.05 deg/s bias error does not integrate (dead reckoning alone: 1.5-4.1 deg in 60 s over
    these seeds, compensated 0.4-1.0)."""
    on = _step_with_bias_error(WitnessParams(), seed)
    off = _step_with_bias_error(WitnessParams(comp_samples=0), seed)
    assert off > 1.4
    assert on < 1.0


def test_setpoint_change_raises_theta_for_the_window_only() -> None:
    """No gyro: ``setpoint_changed`` multiplies theta for ``turn_window_s``, then not; the
    controller tells the FDI when its setpoint changes (firmware_host.rov.control)."""
    cfg, _ = load_rov_config(project_root() / "config" / "rov.toml")
    assert cfg.ft.turn_window_s > 0 and cfg.ft.turn_theta_factor > 1
    paper, _ = load_rov_config(project_root() / "config" / "rov-paper.toml")
    assert paper.ft.turn_window_s == 0.0  # the paper preset: no window
    ctl = RovController(cfg)
    scales = []
    for k in range(60):
        if k == 10:
            ctl.setpoint_deg = (ctl.setpoint_deg + 30.0) % 360.0
        ctl.step(150.0, 0.2)
        scales.append(ctl.heading.det.theta_scale)
    n = round(cfg.ft.turn_window_s / 0.2)
    assert scales[:10] == [1.0] * 10
    assert scales[10:10 + n] == [cfg.ft.turn_theta_factor] * n
    assert scales[10 + n:] == [1.0] * (50 - n)


def test_hinge_drift_matches_least_squares_through_its_rebuilds() -> None:
    """The running sums of :class:`HingeDrift` against numpy's least squares, over 1000
    samples (three rebuilds of a 300-sample window) with a ramp in the middle."""
    rng = np.random.default_rng(3)
    lags = (50, 100, 150, 200)
    h = HingeDrift(300, lags)
    T: list[float] = []
    Z: list[float] = []
    for k in range(1000):
        t = 35.0 + k * DT
        z = 400.0 - 0.13 * t + float(rng.normal(0.0, 1.0)) + (0.1 * (t - 100.0) if t > 100 else 0)
        T.append(t)
        Z.append(z)
        h.push(t, z)
        ratios = [h.test(1.0) for _ in lags]
        if k in (400, 500, 700, 999):
            t_, z_ = np.array(T[-300:]), np.array(Z[-300:])
            X = np.c_[np.ones(300), t_]
            r1 = z_ - X @ np.linalg.lstsq(X, z_, rcond=None)[0]
            want = []
            for L in lags:
                X2 = np.c_[X, np.maximum(0.0, t_ - t_[300 - L])]
                r2 = z_ - X2 @ np.linalg.lstsq(X2, z_, rcond=None)[0]
                want.append(float(r1 @ r1 - r2 @ r2))
            assert ratios[-1][0] == pytest.approx(max(want), rel=1e-6, abs=1e-6)


def test_slow_drift_found_by_the_hinge_not_by_the_cusums() -> None:
    """0.05 deg/s from 60 s at 1 deg noise, the vehicle holding its heading (+-1.3 deg),
    seeds 1-10: the CUSUMs alone confirm 4 of 10, at 29-48 s (the reference mean and the bias
    fit follow it; none before the warm-up's bias line went on through the hold, fifth pass;
    3 of 10 before the warm-up's end aligned the headings, issue A);
    the hinge test on compass minus integrated gyro confirms 8 of 10 within 45 s and all 10
    within 62 s (before: 9 within 45 s, seed 10 never; seeds 1-40: 37 -> 36 within 45 s, 37 ->
    38 at all). A drift this slow is ~1.5 deg from the dead reckoning when found, so it may be
    taken back later. While the vehicle swings +-12.7 deg the hinge's window restarts (heading
    span over 10 deg), so it confirms nothing there, as the CUSUMs."""
    def delay(params: WitnessParams, seed: int, turn: float = 0.2) -> float | None:
        _, ev = _run(300 + 600, "ramp", mag=0.05, seed=seed, params=params, turn_dps=turn)
        return next(((k - 300) * DT for k, e in ev if e == "confirmed"), None)

    cusum = [delay(WitnessParams(drift_glr=0.0), s) for s in range(1, 11)]
    hinge = [delay(WitnessParams(), s) for s in range(1, 11)]
    assert sum(d is not None for d in cusum) <= 4, cusum
    assert all(d is None or d > 25.0 for d in cusum), cusum
    assert sum(d is not None and 0.0 < d <= 45.0 for d in hinge) >= 8, hinge
    assert all(d is not None and 0.0 < d <= 65.0 for d in hinge), hinge
    swing = [delay(WitnessParams(), s, 2.0) for s in range(1, 4)]
    assert swing == [delay(WitnessParams(drift_glr=0.0), s, 2.0) for s in range(1, 4)]


def _fit_samples_at_step(params: WitnessParams, seed: int) -> tuple[float, float]:
    """A 20 deg step 15 s after the warm-up: the bias fit's sample weight after the warm-up
    (its line while the heading is held, and the later segment) just before its confirmation
    and just after."""
    rng = np.random.default_rng(seed)
    w = GyroWitness(params)
    psi = 40.0
    for k in range(250):
        r = 2.0 * math.sin(2 * math.pi * k * DT / 40.0)
        psi += r * DT
        w.propagate(r + 0.15 + float(rng.normal(0.0, 0.05)), DT)
        y = psi + float(rng.normal(0.0, 1.0)) + (20.0 if k >= 175 else 0.0)
        n = w._S[0] + w._Sp[0]
        if w.update(y % 360.0, DT).confirmed:
            return n, w._S[0] + w._Sp[0]
    raise AssertionError("not confirmed")


@pytest.mark.parametrize("seed", range(1, 4))
def test_a_confirmation_feeds_the_delay_lines_trusted_samples_to_the_bias(seed: int) -> None:
    """At the confirmation the trusted samples still waiting in the bias fit's delay line
    (15 s) go into the fit, up to fast_margin_s (2 s) before the step's change time; before,
    they were dropped during the fault (a step 15 s after the warm-up had its bias from the
    warm-up alone). With a margin of 30 s none qualifies."""
    before, after = _fit_samples_at_step(WitnessParams(), seed)
    assert after - before >= 55.0  # ~ (15 - 2) s at 5 Hz, less the suspect's samples
    before, after = _fit_samples_at_step(WitnessParams(fast_margin_s=30.0), seed)
    assert after - before <= 1.0


def test_the_warm_ups_bias_line_goes_on_while_the_heading_is_held() -> None:
    """Holding the heading (+-1.3 deg), the later samples join the warm-up's line: at 50 s
    (samples up to 35 s fed), seeds 1-10, the bias's RMS error 0.0151 deg/s as a second
    segment with its own intercept, 0.0121 on the warm-up's line. Swinging +-12.7 deg, the
    line closes at the first sample 10 deg from the warm-up's last heading."""
    def rms(hold: float) -> float:
        e = [_run(250, seed=s, params=WitnessParams(bias_hold_deg=hold), turn_dps=0.2)[0].bias
             - 0.15 for s in range(1, 11)]
        return math.sqrt(sum(x * x for x in e) / len(e))

    assert rms(10.0) < 0.013 < 0.014 < rms(0.0)
    w, _ = _run(250, seed=1, turn_dps=0.2)
    assert w._S[0] > 150.0 and w._Sp[0] == 0.0
    w, _ = _run(600, seed=1, turn_dps=2.0)
    assert w._hold_ref is None and w._Sp[0] > 300.0


def _step_then_ramp(params: WitnessParams, seed: int, n: int = 800, rate: float = 0.1,
                    end: int = 10**9) -> tuple[list[int], float]:
    """A 10 deg compass step at sample 300 (60 s), then, from sample 400 (20 s later, the
    step's offset learned and compensating), a 0.1 deg/s ramp on top; the vehicle holds its
    heading (0.2 deg/s swings), gyro bias 0.15 deg/s, compass noise 1 deg. The samples of the
    confirmations (and, as ``-k``, the recoveries), and the worst |heading used - true| from
    the ramp's start on (80 s); ``rate`` deg/s, both faults end at sample ``end``."""
    rng = np.random.default_rng(seed)
    w = GyroWitness(params)
    psi = 40.0
    worst = 0.0
    conf: list[int] = []
    for k in range(n):
        r = 0.2 * math.sin(2 * math.pi * k * DT / 40.0)
        psi += r * DT
        w.propagate(r + 0.15 + float(rng.normal(0.0, 0.05)), DT)
        y = psi + float(rng.normal(0.0, 1.0))
        if k < end:
            y += (10.0 if k >= 300 else 0.0) + (rate * (k - 400) * DT if k >= 400 else 0.0)
        st = w.update(y % 360.0, DT)
        if st.confirmed:
            conf.append(k)
        if st.recovered:
            conf.append(-k)
        if k >= 400:
            worst = max(worst, abs(st.psi - psi))
    return conf, worst


@pytest.mark.parametrize("seed", range(1, 6))
def test_a_drift_under_the_step_compensation_is_a_second_fault(seed: int) -> None:
    """A compass that stepped and then keeps drifting: the hinge test on the compensated
    compass (its slope before the drift known from the bias fit) confirms the drift within
    40 s (15-18 s over these seeds) and the compensation ends (dead reckoning, the heading used
    0.7-1.3 deg off); without it the drift is never confirmed: the compensation follows it, or
    its slow CUSUM ends it unannounced (1.5-7.6 deg off)."""
    on, worst_on = _step_then_ramp(WitnessParams(), seed)
    off, worst_off = _step_then_ramp(WitnessParams(comp_drift_glr=0.0), seed)
    assert len(off) == 1 and 300 <= off[0] <= 305
    assert len(on) == 2 and on[0] == off[0]
    assert 0 < (on[1] - 400) * DT <= 40.0
    assert worst_on < 1.5 and worst_on < worst_off


@pytest.mark.parametrize("seed", range(1, 6))
def test_a_compass_drifting_back_across_the_truth_is_not_taken_back(seed: int) -> None:
    """After a drift under a step's compensation (10 deg, then -0.1 deg/s: the compass
    crosses the truth 100 s into the drift) the compass is not taken back while it drifts
    (before: taken back at the crossing, when it agreed with the dead reckoning for 2 s);
    a compass that stops drifting and is healthy again is (within drift_recover_s + 2 s)."""
    p = WitnessParams()
    drifting, _ = _step_then_ramp(p, seed, n=1000, rate=-0.1)
    assert len(drifting) == 2 and all(k > 0 for k in drifting)
    before, _ = _step_then_ramp(replace(p, drift_recover_s=0.0), seed, n=1000, rate=-0.1)
    assert any(k < 0 for k in before)
    healed, _ = _step_then_ramp(p, seed, n=1000, rate=-0.1, end=700)
    assert len(healed) == 3 and -healed[2] - 700 <= (p.drift_recover_s + 2.0) / DT


@pytest.mark.parametrize("seed", range(1, 6))
def test_a_level_too_small_for_a_step_is_left_to_the_slow_cusum(seed: int) -> None:
    # The first samples of a noise burst that dwell on one side look like a 3 deg step to the
    # fast CUSUM; steps of interest are >= 5 deg (step_min_deg 3.5). A real 3 deg level on a
    # 0.5 deg compass is still confirmed, by the slow CUSUM, a few samples later.
    p = WitnessParams()
    assert p.step_min_deg == 3.5
    _, ev = _run(400, "step", mag=3.0, noise=0.5, seed=seed)
    k = next(k for k, e in ev if e == "confirmed")
    assert 5 < k - 300 <= 25
    _, ev = _run(400, "step", mag=3.0, noise=0.5, seed=seed, params=replace(p, step_min_deg=0.0))
    k = next(k for k, e in ev if e == "confirmed")
    assert 0 <= k - 300 <= 4
    # a 5 deg step at 1 deg noise is still the fast CUSUM's, within 5 samples
    _, ev = _run(400, "step", mag=5.0, noise=1.0, seed=seed)
    k = next(k for k, e in ev if e == "confirmed")
    assert 0 <= k - 300 <= 4


# Seed 409 of the nonlinear plant (rov_harness, 1 deg compass noise): the compass minus the
# true heading before and from a step's onset. A: drift:-10@23, whose differences raised the
# short scale to a burst call at the step's second sample (the CUSUMs were reset). B:
# drift:20@46, a compass outlier on the step's first sample (the spread test dropped another).
_STEPS_409 = {
    "burst-call": ([-1.21, 0.78, -0.50, -0.79, 1.78, -0.37, -1.65, 0.33, -1.76, 0.12],
                   [-9.04, -11.75, -11.02, -8.63, -8.97, -10.87, -11.47], -10.0),
    "outlier": ([-0.95, 0.52, -3.27, -0.72, 0.49, -0.19, 0.47],
                [34.15, 21.28, 21.24, 18.63, 18.00, 21.13, 19.40], 20.0),
}


@pytest.mark.parametrize("case", sorted(_STEPS_409))
@pytest.mark.parametrize("seed", range(1, 9))
def test_steps_seed_409_confirmed_within_5_samples(case: str, seed: int) -> None:
    """Both were confirmed at the sixth sample (eighth pass). A: the fast CUSUM is rebuilt
    from the three samples that pass the step rule; B: the spread test leaves out the sample
    whose removal leaves the least spread, not the farthest from a line the outlier pulled.
    Before either fix: A 6 samples on seed 7, B 6 samples on 7 of these 8 seeds."""
    pre, step, mag = _STEPS_409[case]
    conf = _replay_step(pre, [x - mag for x in step], mag, seed, 1.0)
    assert conf is not None and 0 <= conf <= 5
