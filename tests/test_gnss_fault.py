"""fdi.gnss_fault: the healthy / biased hypotheses, decided on numbers given by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fdi.chi2 import chi2_ppf
from fdi.gnss_fault import (
    FaultStateParams,
    GnssFaultMonitor,
    Verdict,
    log_likelihood,
    mahalanobis2,
)

R = np.full(3, 9.0)  # 3 m fix noise
S0 = np.diag(R + 0.5)  # a converged INS: P_pp = 0.5 m² per axis
VAR_INC = R + 0.1


def _healthy(mon: GnssFaultMonitor, rng: np.random.Generator, n: int) -> None:
    for _ in range(n):
        nu = rng.normal(0.0, 3.0, 3)
        assert mon.healthy_epoch(nu, S0, nu, R, VAR_INC) is Verdict.HEALTHY


def test_thresholds_and_likelihood() -> None:
    p = FaultStateParams()
    assert p.t_onset == pytest.approx(chi2_ppf(0.99, 3))
    assert p.t_onset == pytest.approx(11.345, 1e-4)
    nu = np.array([1.0, -2.0, 0.5])
    s = np.diag([2.0, 3.0, 4.0])
    ref = -0.5 * (0.5 + 4.0 / 3.0 + 0.0625 + math.log(24.0) + 3 * math.log(2 * math.pi))
    assert log_likelihood(nu, s) == pytest.approx(ref)
    assert mahalanobis2(nu, s) == pytest.approx(0.5 + 4.0 / 3.0 + 0.0625)


def test_no_onset_without_history() -> None:
    mon = GnssFaultMonitor(FaultStateParams())
    big = np.array([100.0, 100.0, 20.0])
    # the first epoch: nothing to tell a jump from an initial error by, so no onset
    assert mon.healthy_epoch(big, S0, big, R, VAR_INC) is Verdict.HEALTHY
    assert mon.onsets == 0


def test_jump_opens_a_fault_and_its_end_returns_at_once() -> None:
    rng = np.random.default_rng(7)
    mon = GnssFaultMonitor(FaultStateParams())
    _healthy(mon, rng, 6)
    fault = np.array([100.0, 100.0, 20.0])
    assert mon.healthy_epoch(fault, S0, fault, R, VAR_INC) is Verdict.ONSET
    assert mon.faulted and mon.onsets == 1
    s1 = S0 + np.diag(np.full(3, 3.0))  # b estimated to ~1.7 m
    for _ in range(20):  # the fault persists: the evidence is all for H1
        nu0 = fault + rng.normal(0.0, 3.0, 3)
        assert mon.faulted_epoch(nu0, S0, nu0 - fault, s1, nu0, R) is Verdict.FAULTED
        assert mon.log_lr == 0.0
    nu0 = rng.normal(0.0, 3.0, 3)  # the receiver is back
    assert mon.faulted_epoch(nu0, S0, nu0 - fault, s1, nu0, R) is Verdict.RETURN
    assert not mon.faulted and mon.returns == 1


def test_consistent_offset_is_no_onset() -> None:
    # An INS that drifted 30 m beyond its P: every fix is over-limit, but none jumped against
    # the ones before (the offset is the INS's): no fault is opened, the fixes pull it back.
    mon = GnssFaultMonitor(FaultStateParams())
    rng = np.random.default_rng(3)
    offset = np.array([30.0, -30.0, 0.0])
    for _ in range(10):
        nu = offset + rng.normal(0.0, 3.0, 3)
        assert mahalanobis2(nu, S0) > mon.params.t_onset
        assert mon.healthy_epoch(nu, S0, nu, R, VAR_INC) is Verdict.HEALTHY
    assert mon.onsets == 0


def test_no_onset_where_the_ins_cannot_coast() -> None:
    # P⁻ = R: the INS loses as much between two fixes as the fix's noise; no fault state
    mon = GnssFaultMonitor(FaultStateParams())
    s_bad = np.diag(2.0 * R)
    rng = np.random.default_rng(5)
    for _ in range(5):
        nu = rng.normal(0.0, 4.0, 3)
        mon.healthy_epoch(nu, s_bad, nu, R, VAR_INC)
    jump = np.array([60.0, 60.0, 10.0])
    assert mon.healthy_epoch(jump, s_bad, jump, R, VAR_INC) is Verdict.HEALTHY


def test_false_onset_returns_by_evidence_and_level_change_relevels() -> None:
    rng = np.random.default_rng(11)
    mon = GnssFaultMonitor(FaultStateParams())
    _healthy(mon, rng, 5)
    outlier = np.array([11.0, -9.0, 6.0])  # a noise outlier that passes both tests
    assert mon.healthy_epoch(outlier, S0, outlier, R, VAR_INC) is Verdict.ONSET
    s1 = S0 + np.diag(R)  # b known to about the fix's noise after one epoch
    nu0 = np.array([0.5, -0.3, 0.2])
    # λ = ln N(ν0; S0) − ln N(ν0 − b; S1) > ln 10: back at the next epoch
    assert mon.faulted_epoch(nu0, S0, nu0 - outlier, s1, nu0, R) is Verdict.RETURN
    # a fault whose level changes: neither hypothesis fits, the bias is reopened
    _healthy(mon, rng, 4)
    f1 = np.array([100.0, 100.0, 20.0])
    assert mon.healthy_epoch(f1, S0, f1, R, VAR_INC) is Verdict.ONSET
    f2 = np.array([40.0, 40.0, 8.0])
    assert mon.faulted_epoch(f2, S0, f2 - f1, S0 + 3.0, f2, R) is Verdict.RELEVEL
    assert mon.faulted and mon.relevels == 1
