"""The paper's experiment (Zhu, Chen & Liu 2009, sec. 4) on the step-locked simulated vehicle.

Fixed seeds; the plant and the controller run in-process (no clock, no I/O).
"""

from __future__ import annotations

import pytest

from firmware_host.devtools.rov_experiment import run_experiment, summarize
from firmware_host.devtools.rov_sim import parse_fault
from firmware_host.rov.config import RovConfig, load_rov_config, project_root

SETPOINT = 150.0
FAULT_T = 70.0
DT = 0.2


def err(e: dict) -> float:
    return (e["heading_true"] - SETPOINT + 180.0) % 360.0 - 180.0


@pytest.fixture(scope="module")
def cfg() -> RovConfig:
    c, _ = load_rov_config(project_root() / "config" / "rov.toml")
    return c


@pytest.mark.parametrize("drift", [30.0, 20.0, 10.0])
@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_paper_drift_with_ft(cfg: RovConfig, drift: float, seed: int) -> None:
    faults = [parse_fault(f"drift:{drift:g}@70")]
    ep = run_experiment(cfg, faults, 130.0, ft=True, seed=seed)
    events = [(e["t"], e["event"]) for e in ep if e["event"]]
    # Criterion 1 fires at the fault's first sample and at no other time.
    assert events[0] == (FAULT_T, "suspect")
    assert [e["t"] for e in ep if e["event"] == "suspect"] == [FAULT_T]
    # Criterion 2 confirms within 5 samples.
    t_conf = next(e["t"] for e in ep if e["event"] == "confirmed")
    assert 0 < (t_conf - FAULT_T) / DT <= 5 + 1e-9
    # From confirmation on, the true heading stays within the goal of +-1.5 deg.
    after = [abs(err(e)) for e in ep if e["t"] >= t_conf]
    assert max(after) < 1.5
    assert all(e["fault"] for e in ep if e["t"] >= t_conf)


@pytest.mark.parametrize("drift", [30.0, 20.0, 10.0])
def test_paper_drift_without_ft_settles_at_setpoint_minus_drift(
    cfg: RovConfig, drift: float
) -> None:
    faults = [parse_fault(f"drift:{drift:g}@70")]
    ep = run_experiment(cfg, faults, 130.0, ft=False, seed=1)
    tail = [err(e) for e in ep if e["t"] >= 100.0]
    mean_tail = sum(tail) / len(tail)
    assert mean_tail == pytest.approx(-drift, abs=1.0)
    # the detector still sees it (the flag), it just does not substitute
    assert any(e["fault"] for e in ep)
    assert all(e["source"] == "sensor" for e in ep)


def test_spikes_are_never_confirmed_100_seeds(cfg: RovConfig) -> None:
    faults = [parse_fault("spike:25@80-80.4")]
    confirmed = []
    suspected = 0
    for seed in range(1000, 1100):
        ep = run_experiment(cfg, faults, 90.0, ft=True, seed=seed)
        s = summarize(ep, faults)
        suspected += s["suspects"] > 0
        if s["confirmations"]:
            confirmed.append(seed)
    assert confirmed == []
    assert suspected == 100  # criterion 1 does see every spike: the test is not vacuous


def test_thirty_clean_minutes_no_confirmed_fault(cfg: RovConfig) -> None:
    ep = run_experiment(cfg, [], 1800.0, ft=True, seed=7)
    s = summarize(ep)
    assert s["confirmations"] == 0
    assert s["fault_epochs"] == 0
    assert abs(s["final_mean_err_deg"]) < 0.5


def test_stuck_compass_detected_and_substituted(cfg: RovConfig) -> None:
    faults = [parse_fault("stuck@60")]
    ep = run_experiment(cfg, faults, 130.0, ft=True, seed=3)
    t_stuck = next(e["t"] for e in ep if e["event"] == "stuck")
    assert 60.0 < t_stuck <= 60.0 + (cfg.ft.stuck_samples + 1) * DT + 1e-9
    assert all(e["source"] == "fir" for e in ep if e["t"] >= t_stuck)
    # dead reckoning on the stored FIR holds the course for a while (the paper's "for a
    # certain time"); without FT the stuck reading lets the current turn the vehicle away.
    near = [abs(err(e)) for e in ep if t_stuck <= e["t"] <= t_stuck + 20.0]
    assert max(near) < 3.0
    ep_noft = run_experiment(cfg, faults, 130.0, ft=False, seed=3)
    assert max(abs(err(e)) for e in ep_noft if e["t"] > 100) > 10.0


def test_stuck_then_recovered(cfg: RovConfig) -> None:
    faults = [parse_fault("stuck@60-75")]
    ep = run_experiment(cfg, faults, 110.0, ft=True, seed=3)
    events = [e["event"] for e in ep if e["event"]]
    assert events[:2] == ["stuck", "recovered"]
    assert ep[-1]["source"] == "sensor" and not ep[-1]["fault"]


def test_drift_that_ends_is_recovered(cfg: RovConfig) -> None:
    faults = [parse_fault("drift:30@70-100")]
    ep = run_experiment(cfg, faults, 130.0, ft=True, seed=3)
    assert "recovered" in [e["event"] for e in ep]
    assert max(abs(err(e)) for e in ep if e["t"] >= 70.0) < 1.5
    assert ep[-1]["source"] == "sensor"


def test_dropout_holds_then_neutral(cfg: RovConfig) -> None:
    faults = [parse_fault("dropout@90-95")]
    ep = run_experiment(cfg, faults, 100.0, ft=True, seed=3)
    by_t = {e["t"]: e for e in ep}
    last = by_t[89.8]
    hold = [e for e in ep if 90.0 <= e["t"] <= 90.0 + cfg.dropout_hold_s - 0.2 + 1e-9]
    assert hold and all(e["action"] == "hold" for e in hold)
    assert all(e["port_pct"] == last["port_pct"] for e in hold)
    neutral = [e for e in ep if 91.01 <= e["t"] < 95.0]
    assert neutral and all(e["action"] == "neutral" for e in neutral)
    assert all(e["port_pct"] == 0.0 and e["starboard_pct"] == 0.0 for e in neutral)
    assert by_t[95.0]["action"] == "control"
    assert not any(e["fault"] for e in ep)


def test_paper_preset_loads_and_detects(cfg: RovConfig) -> None:
    paper, _ = load_rov_config(project_root() / "config" / "rov-paper.toml")
    assert paper.detector.order == 70 and paper.detector.mu == 0.01
    assert paper.period_s == 0.2 and paper.setpoint_deg == 150.0
    faults = [parse_fault("drift:30@70")]
    ep = run_experiment(paper, faults, 100.0, ft=True, seed=1)
    assert next(e["t"] for e in ep if e["event"] == "suspect") == FAULT_T
    t_conf = next(e["t"] for e in ep if e["event"] == "confirmed")
    assert (t_conf - FAULT_T) / DT <= 5 + 1e-9
    # No assertion on the heading error: without a bias tap the frozen FIR cannot represent
    # the current, and its dead reckoning drifts (6-30 deg over 60 s, see the report).
