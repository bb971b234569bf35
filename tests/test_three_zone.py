"""Three-zone gate: thresholds from α, zone boundaries, fit weights, equivalent weights, limit."""

from __future__ import annotations

import itertools
import math
from statistics import NormalDist

import numpy as np
import pytest

from fdi.three_zone import (
    Action,
    JumpTracker,
    ReceiverState,
    ThreeZoneGate,
    ThreeZoneParams,
    Zone,
    classify,
    detection_measure,
    extrapolation_weights,
    inflation_factor,
    noise_gain,
)


def _chi2_1dof(p: float) -> float:
    # Oracle independent of fdi.chi2: χ²(1) is the square of a standard normal.
    return NormalDist().inv_cdf(0.5 + p / 2.0) ** 2


def test_thresholds_are_computed_from_alpha() -> None:
    p = ThreeZoneParams()
    assert p.t1 == pytest.approx(2.7055, abs=1e-4)  # the paper's 2.706
    assert p.t2 == pytest.approx(6.6349, abs=1e-4)  # the paper's 6.635
    q = ThreeZoneParams(alpha1=0.05, alpha2=0.001)
    assert q.t1 == pytest.approx(_chi2_1dof(0.95), rel=1e-9)
    assert q.t2 == pytest.approx(_chi2_1dof(0.999), rel=1e-9)


def test_params_reject_inconsistent_values() -> None:
    with pytest.raises(ValueError, match="alpha2"):
        ThreeZoneParams(alpha1=0.01, alpha2=0.10)
    with pytest.raises(ValueError, match="degree"):
        ThreeZoneParams(window=3, degree=3)


def test_zone_boundaries() -> None:
    t1, t2 = 2.7055, 6.6349
    assert classify(0.0, t1, t2) is Zone.NO_FAULT
    assert classify(math.nextafter(t1, 0), t1, t2) is Zone.NO_FAULT
    assert classify(t1, t1, t2) is Zone.DEVIATION
    assert classify(t2, t1, t2) is Zone.DEVIATION
    assert classify(math.nextafter(t2, 10), t1, t2) is Zone.OVER_LIMIT
    # eq. (8): DM = ν²/S
    assert detection_measure(3.0, 4.0) == pytest.approx(2.25)
    assert detection_measure(-3.0, 4.0) == pytest.approx(2.25)


@pytest.mark.parametrize(
    ("degree", "weights", "gain"),
    [
        (1, (-0.5, 0.0, 0.5, 1.0), 1.5),
        (2, (0.75, -1.25, -0.75, 2.25), 7.75),
        (3, (-1.0, 4.0, -6.0, 4.0), 69.0),
    ],
)
def test_extrapolation_weights_n4(degree: int, weights: tuple[float, ...], gain: float) -> None:
    w = extrapolation_weights(4, degree)
    assert w == pytest.approx(weights, abs=1e-15)
    assert noise_gain(w) == pytest.approx(gain, abs=1e-12)


@pytest.mark.parametrize(("n", "degree"), [(3, 1), (5, 2), (6, 1), (8, 3), (4, 0)])
def test_extrapolation_weights_match_polyfit(n: int, degree: int) -> None:
    rng = np.random.default_rng(11)
    w = np.array(extrapolation_weights(n, degree))
    for _ in range(5):
        y = rng.normal(0.0, 10.0, n)
        coef = np.polyfit(np.arange(n), y, degree)
        assert float(w @ y) == pytest.approx(float(np.polyval(coef, n)), abs=1e-9)
    # exact on polynomials of the fit's degree
    poly = np.polynomial.Polynomial(rng.normal(size=degree + 1))
    assert float(w @ poly(np.arange(n))) == pytest.approx(float(poly(n)), rel=1e-9, abs=1e-9)


def test_inflation_factor_linear_and_igg3() -> None:
    t1, t2 = ThreeZoneParams().t1, ThreeZoneParams().t2
    assert inflation_factor(1.0, t1, t2) == 1.0
    assert inflation_factor(2 * t1, t1, t2, "linear") == pytest.approx(2.0)
    assert inflation_factor(50.0, t1, t2, "linear") == pytest.approx(50.0 / t1)
    # IGG-III: 1 at T1, grows monotonically, infinite (weight 0) from T2 on
    assert inflation_factor(t1, t1, t2, "igg3") == 1.0
    dms = np.linspace(t1 * 1.001, t2 * 0.999, 20)
    lam = [inflation_factor(float(d), t1, t2, "igg3") for d in dms]
    assert all(b > a for a, b in itertools.pairwise(lam))
    assert lam[0] == pytest.approx(1.0, abs=0.05)
    assert math.isinf(inflation_factor(t2, t1, t2, "igg3"))
    v = math.sqrt(4.0)
    k0, k1 = math.sqrt(t1), math.sqrt(t2)
    expected = 1.0 / ((k0 / v) * ((k1 - v) / (k1 - k0)) ** 2)
    assert inflation_factor(4.0, t1, t2, "igg3") == pytest.approx(expected)


def _fill(gate: ThreeZoneGate, values: list[float], r: float = 1.0) -> None:
    for z in values:
        d = gate.step(z, 0.0, 2.0, r)  # innovation 0: no fault
        assert d.action is Action.ACCEPT


def test_gate_three_zones_actions() -> None:
    gate = ThreeZoneGate(ThreeZoneParams())
    _fill(gate, [10.0, 11.0, 12.0, 13.0])
    s, r = 2.0, 1.0
    # deviation: pick ν so that DM = ν²/S = 4 (between T1 and T2)
    nu = math.sqrt(4.0 * s)
    d = gate.step(14.0 + nu, nu, s, r)
    assert d.zone is Zone.DEVIATION and d.action is Action.DOWNWEIGHT
    assert d.variance == pytest.approx(r * 4.0 / gate.params.t1)
    assert d.value == 14.0 + nu
    # over-limit: replaced by the fit of the last four values (11, 12, 13, 14+ν)
    window = [11.0, 12.0, 13.0, 14.0 + nu]
    w = extrapolation_weights(4, 1)
    fit = sum(a * b for a, b in zip(w, window, strict=True))
    d = gate.step(115.0, 100.0, s, r)
    assert d.zone is Zone.OVER_LIMIT and d.action is Action.REPLACE
    assert d.value == pytest.approx(fit)
    vars_ = [r, r, r, r * 4.0 / gate.params.t1]
    assert d.variance == pytest.approx(sum(a * a * v for a, v in zip(w, vars_, strict=True)))


def test_gate_noise_gain_on_plain_window() -> None:
    gate = ThreeZoneGate(ThreeZoneParams())
    _fill(gate, [0.0, 1.0, 2.0, 3.0], r=9.0)
    d = gate.step(104.0, 100.0, 10.0, 9.0)
    assert d.action is Action.REPLACE
    assert d.value == pytest.approx(4.0)
    assert d.variance == pytest.approx(1.5 * 9.0)


def test_replacement_limit_then_restart() -> None:
    params = ThreeZoneParams(max_replacements=5)
    gate = ThreeZoneGate(params)
    _fill(gate, [0.0, 1.0, 2.0, 3.0])
    # truth continues 4, 5, 6 ...; the receiver is 100 m off. ẑ = truth (a good INS).
    actions = []
    for k in range(4, 12):
        d = gate.step(k + 100.0, 100.0, 2.0, 1.0)
        actions.append(d.action)
        if d.action is Action.REPLACE:
            assert d.value == pytest.approx(float(k), abs=1e-9)  # exact on a straight line
    assert actions[:5] == [Action.REPLACE] * 5
    assert actions[5:] == [Action.REJECT] * 3  # limit reached: window restarted, short
    assert gate.restarts == 1 and not gate.window_full
    # the receiver recovers: the window refills, and replacements are possible again
    _fill(gate, [12.0, 13.0, 14.0, 15.0])
    assert gate.window_full and gate.consecutive == 0
    assert gate.step(116.0, 100.0, 2.0, 1.0).action is Action.REPLACE


def test_replacement_failing_its_own_test_is_rejected() -> None:
    gate = ThreeZoneGate(ThreeZoneParams())
    _fill(gate, [0.0, 0.0, 50.0, 50.0])  # a jump inside the window: the fit's slope is wrong
    d = gate.step(100.0, 100.0, 2.0, 1.0)  # ẑ = 0; fit = 0·... → 25 + 50 = 75 → over-limit too
    assert d.action is Action.REJECT
    assert math.isinf(d.variance)


def test_strategies() -> None:
    p = ThreeZoneParams()
    nu_dev = math.sqrt(4.0 * 2.0)
    for strategy, dev_action, over_action in [
        ("none", Action.ACCEPT, Action.ACCEPT),
        ("downweight", Action.DOWNWEIGHT, Action.DOWNWEIGHT),
        ("replace", Action.ACCEPT, Action.REPLACE),
        ("three_zone", Action.DOWNWEIGHT, Action.REPLACE),
    ]:
        gate = ThreeZoneGate(p, strategy)  # type: ignore[arg-type]
        _fill(gate, [0.0, 0.0, 0.0, 0.0])
        assert gate.step(nu_dev, nu_dev, 2.0, 1.0).action is dev_action
        gate.reset()
        _fill(gate, [0.0, 0.0, 0.0, 0.0])
        assert gate.step(100.0, 100.0, 2.0, 1.0).action is over_action
        assert gate.zone_counts[Zone.OVER_LIMIT] == 1
    with pytest.raises(ValueError, match="strategy"):
        ThreeZoneGate(p, "grey")  # type: ignore[arg-type]


def test_external_replacement_used_for_combined_strategy() -> None:
    gate = ThreeZoneGate(ThreeZoneParams())
    d = gate.step(100.0, 100.0, 2.0, 1.0, external=(1.5, 0.25))  # window empty: external used
    assert d.action is Action.REPLACE and d.value == 1.5 and d.variance == 0.25


def test_degree1_with_limit_does_not_coast_away() -> None:
    # FINDINGS: fits feeding fits diverge at degree 2; degree 1 with a limit does not.
    rng = np.random.default_rng(5)
    worst = {}
    for degree in (1, 2):
        gate = ThreeZoneGate(ThreeZoneParams(degree=degree, max_replacements=5))
        err = 0.0
        for _ in range(2000):
            z = float(rng.normal(0.0, 1.0))
            fault = 100.0 if rng.random() < 0.5 else 0.0  # half the epochs are over-limit
            d = gate.step(z + fault, z + fault, 2.0, 1.0)
            if d.action is Action.REPLACE:
                err = max(err, abs(d.value))
        worst[degree] = err
    assert worst[1] < 15.0  # stays within a few σ of the truth (0)
    assert worst[2] > worst[1]


# ---------------------------------------------------------------- lock-in breaker (ours)


def _healthy(tracker: JumpTracker, k: int, s: float = 10.0, r: float = 9.0) -> None:
    for _ in range(k):
        st = tracker.update((0.0,), (s,), (r,), (False,))
        assert not st.faulted


def test_jump_tracker_onset_hold_and_return() -> None:
    tr = JumpTracker(ThreeZoneParams(), 1)
    _healthy(tr, 4)
    st = tr.update((100.0,), (10.0,), (9.0,), (True,))  # the receiver jumps 100 m
    assert st.faulted and st.jumped and tr.offset[0] == pytest.approx(100.0)
    # The INS drifts towards the fault while P grows: ν slides into the deviation and no-fault
    # zones, but the receiver has not jumped back, so it stays faulted.
    for k in range(1, 60):
        drift, s = 1.5 * k, 10.0 + (0.5 * k) ** 2
        st = tr.update((100.0 - drift,), (s,), (9.0,), ((100.0 - drift) ** 2 > 6.63 * s,))
        assert st.faulted and not st.returned
    st = tr.update((-drift,), (s,), (9.0,), (False,))  # back on its own track: ν = −drift
    assert st.returned and not st.faulted and tr.offset == (0.0,)
    assert tr.fault_onsets == 1 and tr.returns == 1


def test_jump_tracker_single_outlier_returns_at_once() -> None:
    # A 3.5σ noise outlier can pass the onset test; the next fix is nearer the healthy track
    # than the "faulted" one, so the receiver is healthy again after one epoch.
    tr = JumpTracker(ThreeZoneParams(), 1)
    _healthy(tr, 4, s=9.5, r=9.0)
    assert tr.update((11.0,), (9.5,), (9.0,), (True,)).faulted
    st = tr.update((0.5,), (9.5,), (9.0,), (False,))
    assert st.returned and not st.faulted


def test_jump_tracker_drift_is_not_a_jump() -> None:
    # A smooth ramp in ν (the INS drifting, the receiver steady) never looks like a jump.
    tr = JumpTracker(ThreeZoneParams(), 1)
    for k in range(40):
        st = tr.update((0.8 * k,), (10.0,), (9.0,), ((0.8 * k) ** 2 > 66.0,))
        assert not st.jumped and not st.faulted


def test_jump_tracker_needs_the_jump_to_explain_the_innovation() -> None:
    # Over-limit because the INS drifted 80 m, plus a 15 m jump: not a receiver fault.
    tr = JumpTracker(ThreeZoneParams(), 1)
    for _ in range(4):
        tr.update((80.0,), (10.0,), (9.0,), (True,))
    st = tr.update((95.0,), (10.0,), (9.0,), (True,))
    assert st.jumped and not st.faulted


def test_gate_keeps_a_persistent_fault_out_in_the_deviation_zone() -> None:
    gate = ThreeZoneGate(ThreeZoneParams())
    _fill(gate, [0.0, 0.0, 0.0, 0.0])
    d = gate.step(100.0, 100.0, 2.0, 1.0)
    assert d.action is Action.REPLACE
    # The INS drifts 3 m per epoch towards the fault while P grows (σ by 1.5 m per epoch, the
    # drift is 2σ): ν slides through the
    # deviation zone into the no-fault zone, where the paper would use the fix (and lock in).
    # The receiver has not jumped back: it stays faulted and is never used as is.
    zones, actions = set(), set()
    for k in range(1, 31):
        d = gate.step(100.0, 100.0 - 3.0 * k, 2.0 + (1.5 * k) ** 2, 1.0)
        zones.add(d.zone)
        actions.add(d.action)
    assert {Zone.DEVIATION, Zone.NO_FAULT} <= zones
    assert actions <= {Action.REPLACE, Action.REJECT}
    # The receiver jumps back to its own track (ν = −93, the INS's drift): healthy again.
    gate.step(0.0, -93.0, 2.0 + 46.5**2, 1.0)
    assert gate.tracker.returns == 1 and not gate.tracker.faulted


def test_gate_readmits_a_steady_receiver_after_the_limit() -> None:
    # No jump, yet over-limit epoch after epoch: the INS drifted beyond its P. After
    # max_replacements such epochs the receiver is accepted again, flagged for P inflation.
    params = ThreeZoneParams(max_replacements=5)
    gate = ThreeZoneGate(params)
    actions = []
    for k in range(30):
        nu = 0.3 * k  # a ramp: over-limit (ν² > T2·S = 13.3) from k = 13 on
        d = gate.step(nu, nu, 2.0, 1.0)
        actions.append((d.action, d.readmit))
    assert gate.tracker.fault_onsets == 0
    assert (Action.ACCEPT, True) in actions
    first = actions.index((Action.ACCEPT, True))
    assert all(a is not Action.ACCEPT for a, _ in actions[13:first])
    assert first - 13 == params.max_replacements and gate.readmissions >= 1


def test_track_jumps_false_is_the_paper_method() -> None:
    gate = ThreeZoneGate(ThreeZoneParams(track_jumps=False))
    _fill(gate, [0.0, 0.0, 0.0, 0.0])
    assert gate.step(100.0, 100.0, 2.0, 1.0).action is Action.REPLACE
    # without the tracker a deviation-zone fault is down-weighted and used
    assert gate.step(100.0, 3.0, 2.0, 1.0).action is Action.DOWNWEIGHT
    assert not gate.tracks_jumps and gate.tracker.fault_onsets == 0


def test_shared_receiver_state_overrides_the_own_tracker() -> None:
    gate = ThreeZoneGate(ThreeZoneParams())
    _fill(gate, [0.0, 0.0, 0.0, 0.0])
    d = gate.step(0.5, 0.5, 2.0, 1.0, receiver=ReceiverState(faulted=True, ready=True))
    assert d.action is Action.REPLACE  # no-fault on its own, faulty by the fix's verdict
    assert gate.tracker.fault_onsets == 0


def test_fault_in_other_components_leaves_a_normal_one_to_its_own_zone() -> None:
    # Section 2.1: a fault in one component must not make the normal ones faulty. A fix jumps
    # 20 m east and north, 0 m up (R: 9, 9, 25 m²): the tracker's verdict is per component.
    tr = JumpTracker(ThreeZoneParams(), 3)
    for _ in range(4):
        tr.update((0.0, 0.0, 0.0), (10.0, 10.0, 27.0), (9.0, 9.0, 25.0), (False,) * 3)
    st = tr.update((20.0, 20.0, 0.5), (10.0, 10.0, 27.0), (9.0, 9.0, 25.0), (True, True, False))
    assert st.faulted and st.axes == (True, True, False)
    assert st.component(0).axis_faulted and not st.component(2).axis_faulted
    gates = [ThreeZoneGate(ThreeZoneParams()) for _ in range(3)]
    for g in gates:
        _fill(g, [0.0, 0.0, 0.0, 0.0])
    up = gates[2].step(0.5, 0.5, 27.0, 25.0, receiver=st.component(2))
    assert up.action is Action.ACCEPT and up.variance == 25.0  # its own zone: no fault
    east = gates[0].step(20.0, 20.0, 10.0, 9.0, receiver=st.component(0))
    assert east.action is not Action.ACCEPT
    # A flagged component stays flagged until the return, even if its offset's variance grows
    st = tr.update((20.0, 20.0, 0.0), (10.0, 10.0, 27.0), (9.0, 9.0, 25.0), (True, True, False))
    assert st.faulted and st.axes[:2] == (True, True)
    # a component out of its no-fault zone is still overridden while the fix is faulted
    dev = gates[2].step(9.0, 9.0, 27.0, 25.0, receiver=st.component(2))
    assert dev.zone is Zone.DEVIATION and dev.action is Action.REPLACE
    # a state without per-component flags (older callers) keeps the whole-fix verdict
    assert ReceiverState(faulted=True).axis_faulted
