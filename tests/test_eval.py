"""``fdi-bridge eval``: the scorer on hand-made inputs, the baselines' documented behaviour, the
gate-health monitor on synthetic inputs, and a reduced suite run (issue 6)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fdi.baselines import (
    BASELINES,
    Chi2Only,
    Ekf2Style,
    Ekf3Style,
    KalmanNoFdi,
    RobotLocalizationStyle,
)
from fdi.gate_health import GateHealth
from fdi.geodesy import LocalFrame
from firmware_host.devtools.score import score_rover

FRAME = LocalFrame(32.0, 118.0, 10.0)

# ----------------------------------------------------------------------------- the scorer


def _truth(k: int, fault: bool = False, event: int | None = None, offset: float = 0.0,
           kind: str | None = None, outage: bool = False) -> dict[str, Any]:
    lat, lon, h = FRAME.to_lla(2.0 * k, 0.0, 0.0)  # 2 m east per epoch at 1 Hz
    return {"k": k, "utc": 36000.0 + k, "true_lat": lat, "true_lon": lon, "true_alt": h,
            "err_e": 0.0, "err_n": 0.0, "fault": fault, "fault_kind": kind if fault else None,
            "fault_event": event, "fault_offset_m": offset, "outage": outage}


def _epoch(tr: dict[str, Any], flagged: bool, out_east_err: float | None = 0.0,
           raw_east_err: float = 0.0) -> dict[str, Any]:
    e0 = 2.0 * tr["k"]
    rlat, rlon, _ = FRAME.to_lla(e0 + raw_east_err, 0.0, 0.0)
    rec: dict[str, Any] = {"utc": tr["utc"], "fault": flagged, "raw_lat": rlat, "raw_lon": rlon,
                           "lat": None, "lon": None, "alarm_raised": False}
    if out_east_err is not None:
        rec["lat"], rec["lon"], _ = FRAME.to_lla(e0 + out_east_err, 0.0, 0.0)
    return rec


def test_scorer_counts_hits_misses_false_alarms_and_delays_exactly() -> None:
    # 40 epochs. Event 0: a 4-epoch burst at k = 5..8 (2 m), flagged from k = 7 (delay 2).
    # Event 1: a single 3 m jump at k = 20, flagged at once (delay 0).
    # Event 2: a 0.5 m jump at k = 25 (below the 1.05 m minimum), not flagged: not a miss.
    # Event 3: a 3-epoch frozen fault at k = 30..32 (offset 0: counted anyway), never flagged.
    # False alarms: k = 12 and 13 (isolated), k = 33 (the step back right after event 3).
    truth = [_truth(k) for k in range(40)]
    for k in range(5, 9):
        truth[k] = _truth(k, True, 0, 2.0, "burst")
    truth[20] = _truth(20, True, 1, 3.0, "jump")
    truth[25] = _truth(25, True, 2, 0.5, "jump")
    for k in range(30, 33):
        truth[k] = _truth(k, True, 3, 0.0, "frozen")
    flagged = {7, 8, 20, 12, 13, 33}
    epochs = [_epoch(tr, tr["k"] in flagged, out_east_err=0.5 if tr["fault"] else 0.0,
                     raw_east_err=2.0 if tr["fault"] else 1.0) for tr in truth]
    s = score_rover(epochs, truth)
    assert (s.faulty, s.detected) == (4 + 1 + 1 + 3, 3)
    assert (s.faulty_min, s.detected_min, s.missed) == (8, 3, 5)
    assert (s.clean, s.false_alarms, s.false_alarms_after_fault) == (31, 3, 1)
    assert (s.events, s.events_detected) == (3, 2)  # event 2 never reaches the minimum size
    assert s.delays_epochs == (2, 0)
    assert s.delays_s == pytest.approx((2.0, 0.0))
    assert s.mean_delay_s == pytest.approx(1.0)
    assert s.detection_rate == pytest.approx(3 / 8)
    assert s.out_rms_clean_m == pytest.approx(0.0, abs=1e-6)
    assert s.out_rms_faulty_m == pytest.approx(0.5, abs=1e-6)
    assert s.raw_rms_clean_m == pytest.approx(1.0, abs=1e-6)
    assert s.raw_max_faulty_m == pytest.approx(2.0, abs=1e-6)
    assert s.out_rms_all_m == pytest.approx(math.sqrt(9 * 0.25 / 40), abs=1e-6)
    d = s.as_dict()
    assert d["missed"] == 5 and d["false_alarms_isolated"] == 2


def test_scorer_no_output_and_outage_epochs_are_counted_apart() -> None:
    truth = [_truth(k) for k in range(10)]
    truth[3] = _truth(3, True, 0, 5.0, "jump")
    truth[6] = _truth(6, True, 1, 0.0, "outage", outage=True)
    epochs = [_epoch(tr, tr["k"] in (3, 7), out_east_err=None if tr["k"] == 3 else 0.0)
              for tr in truth]
    s = score_rover(epochs, truth)
    assert (s.faulty, s.detected_min, s.no_output_faulty) == (1, 1, 1)
    assert math.isnan(s.out_rms_faulty_m)
    assert s.clean == 8  # the outage epoch is neither
    assert (s.false_alarms, s.false_alarms_after_fault) == (1, 1)  # k = 7 right after the outage


# ----------------------------------------------------------------------------- baselines

DT = 0.1


def _run(bl: Any, fixes: list[tuple[float, float, float] | None]) -> list[Any]:
    return [bl.step(i * DT, z) for i, z in enumerate(fixes)]


def test_every_baseline_is_in_the_table_and_accepts_clean_standing_fixes() -> None:
    assert set(BASELINES) == {"kalman_no_fdi", "ekf3", "ekf2", "robot_localization", "chi2_only"}
    rng = np.random.default_rng(3)
    fixes = [tuple(float(x) for x in rng.normal(0.0, 0.05, 3)) for _ in range(200)]
    for cls in BASELINES.values():
        out = _run(cls(), fixes)  # type: ignore[arg-type]
        assert not any(o.fault for o in out), cls.name
        assert out[0].reason == "start"


def test_ekf3_rejects_a_step_then_resets_to_the_gps_after_7_s_of_rejections() -> None:
    # EK3_POS_I_GATE = 500: a 500 m step is rejected; gpsRetryTimeNoTAS_ms = 7000 after the
    # last fix that passed, ResetPosition puts the state on the fix; later fixes pass again.
    # (A smaller step is accepted before 7 s: the constant-velocity prediction's variance
    # grows as q·t³/3 while no fix is fused, 57 m² after 7 s with q = 0.5.)
    fixes: list[tuple[float, float, float] | None] = [(0.0, 0.0, 0.0)] * 50 + \
        [(500.0, 0.0, 0.0)] * 150
    bl = Ekf3Style()
    out = _run(bl, fixes)
    last_pass_t = 49 * DT
    rejected = [i for i, o in enumerate(out) if o.action == "reject"]
    reset = [i for i, o in enumerate(out) if o.action == "reset"]
    assert rejected[0] == 50
    assert len(reset) == 1
    k = reset[0]
    assert k * DT - last_pass_t > 7.0 >= (k - 1) * DT - last_pass_t  # the first epoch past 7 s
    assert rejected == list(range(50, k))
    assert out[k].out_enu is not None and out[k].out_enu[0] == pytest.approx(500.0)
    assert not out[k].fault and out[k].reason == "gps_timeout"
    assert all(o.action == "accept" for o in out[k + 1:])
    assert bl.kf.axes[0].P00 < 1.0  # converged again after the (GLITCH_RAD/2)² reset variance


def test_ekf3_glitch_radius_zero_clips_instead_of_rejecting() -> None:
    fixes: list[tuple[float, float, float] | None] = [(0.0, 0.0, 0.0)] * 50
    probe = Ekf3Style(glitch_rad_m=0.0)
    _run(probe, fixes)
    probe.kf.predict(DT)
    p00 = probe.kf.axes[0].P00
    s = p00 + 0.35**2
    ratio = 50.0**2 / (25.0 * 2 * s)
    out = _run(Ekf3Style(glitch_rad_m=0.0), [*fixes, (50.0, 0.0, 0.0)])
    last = out[-1]
    assert not last.fault and last.action == "accept"
    assert last.stat == pytest.approx(ratio, rel=1e-9)
    # Fused with the innovation variance multiplied by the ratio: gain P/(S·ratio).
    assert last.out_enu is not None
    assert last.out_enu[0] == pytest.approx(p00 / (s * ratio) * 50.0, rel=1e-9)


def test_ekf3_tests_the_horizontal_pair_ekf2_each_axis() -> None:
    # A step along east alone, sized between the two rules: per-axis ratio > 1 (EKF2 rejects),
    # pair ratio ν²/(25·(S_e + S_n)) < 1 (EKF3 accepts).
    fixes: list[tuple[float, float, float] | None] = [(0.0, 0.0, 0.0)] * 100
    probe = Ekf3Style()
    _run(probe, fixes)
    probe.kf.predict(DT)
    s_e = probe.kf.axes[0].P00 + 0.35**2
    step = 5.0 * math.sqrt(s_e) * 1.2  # 1.2² = 1.44 per axis; 1.44 / 2 = 0.72 for the pair
    fixes.append((step, 0.0, 0.0))
    e3, e2 = _run(Ekf3Style(), fixes)[-1], _run(Ekf2Style(), fixes)[-1]
    assert e3.action == "accept" and e3.stat == pytest.approx(0.72, rel=1e-6)
    assert e2.action == "reject" and e2.fault and e2.stat == pytest.approx(1.44, rel=1e-6)


def test_ekf2_resets_after_the_7_s_fusion_timeout() -> None:
    fixes: list[tuple[float, float, float] | None] = [(0.0, 0.0, 0.0)] * 50 + \
        [(0.0, 300.0, 0.0)] * 100
    out = _run(Ekf2Style(), fixes)
    k = next(i for i, o in enumerate(out) if o.action == "reset")
    assert k * DT - 49 * DT > 7.0 >= (k - 1) * DT - 49 * DT
    assert out[k].reason == "fusion_timeout"
    assert out[k].out_enu is not None and out[k].out_enu[1] == pytest.approx(300.0)


def test_robot_localization_drops_and_never_resets() -> None:
    # Mahalanobis threshold 5 (ekf_template.yaml): d² ≥ 25 rejects; no reset, so a 50 m step
    # stays rejected past the 7 s at which the autopilots would have reset, until the
    # prediction's own variance has grown enough to accept it.
    fixes: list[tuple[float, float, float] | None] = [(0.0, 0.0, 0.0)] * 50 + \
        [(50.0, 0.0, 0.0)] * 150
    bl = RobotLocalizationStyle()
    out = _run(bl, fixes)
    assert bl.stat_threshold == 25.0
    assert all(o.action == "reject" for o in out[50:50 + 76])  # still rejected after 7.5 s
    assert not any(o.action == "reset" for o in out)
    first_accept = next(i for i in range(50, 200) if out[i].action == "accept")
    assert out[first_accept].stat is not None and out[first_accept].stat < 25.0


def test_chi2_only_passes_the_prediction_on_and_kalman_fuses_everything() -> None:
    fixes: list[tuple[float, float, float] | None] = [(0.0, 0.0, 0.0)] * 50 + [(3.0, 0.0, 0.0)]
    c = _run(Chi2Only(), fixes)[-1]
    assert c.fault and c.stat_threshold == pytest.approx(7.8147, abs=1e-4)
    assert c.out_enu is not None and abs(c.out_enu[0]) < 1e-6  # the prediction, not the fix
    k = _run(KalmanNoFdi(), fixes)[-1]
    assert not k.fault and k.out_enu is not None and k.out_enu[0] > 0.5


def test_baselines_ignore_the_height_of_a_2d_fix_and_carry_on_through_no_fix() -> None:
    fixes: list[tuple[float, float, float] | None] = [(0.0, 0.0, 0.0)] * 20 + \
        [(0.0, 0.0, math.nan)] * 5 + [None] * 3 + [(0.0, 0.0, 0.0)]
    for cls in BASELINES.values():
        out = _run(cls(), fixes)  # type: ignore[arg-type]
        assert not any(o.fault for o in out), cls.name
        assert [o.action for o in out[25:28]] == ["no_fix"] * 3
        assert all(o.out_enu is not None and math.isfinite(o.out_enu[2]) for o in out)


# ----------------------------------------------------------------------------- gate health


class _D:
    def __init__(self, chi2: float | None, gate: float = 0.7, t_d: float = 7.8147,
                 fault: bool = False) -> None:
        self.chi2 = chi2
        self.fault = fault
        self.chi2_threshold = t_d
        self.grey_gate_h = gate


def test_gate_health_ok_on_a_consistent_filter() -> None:
    rng = np.random.default_rng(1)
    g = GateHealth(min_jump_m=1.05)
    assert g.report().status == "warming_up"
    for x in rng.chisquare(3, 500):
        g.update(_D(float(x)), (0.01, 0.01, 0.04))  # J_min = √(7.81·0.01) = 0.28 m
    r = g.report()
    assert r.status == "ok" and not r.messages
    assert r.mean_nis == pytest.approx(3.0, abs=0.3)
    assert r.min_detectable_jump_m == pytest.approx(math.sqrt(7.8147 * 0.01), rel=1e-6)


def test_gate_health_says_nis_low_and_inert_on_dgps_like_statistics() -> None:
    rng = np.random.default_rng(2)
    g = GateHealth(min_jump_m=1.05)
    for x in rng.chisquare(3, 300):
        g.update(_D(0.01 * float(x)), (0.15, 0.15, 0.5))  # R = 0.35² with cm innovations
    r = g.report()
    assert r.status == "nis_low"
    assert r.min_detectable_jump_m == pytest.approx(math.sqrt(7.8147 * 0.15), rel=1e-6)
    assert any("far below" in m for m in r.messages)
    assert any("inert for 1.05 m jumps" in m for m in r.messages)
    assert r.chi2_inert_fraction == pytest.approx(1.0)


def test_gate_health_says_nis_high_and_grey_gate_inert() -> None:
    g = GateHealth(min_jump_m=1.05, window=50, min_epochs=50)
    for _ in range(60):
        g.update(_D(40.0, gate=1.5), (0.01, 0.01, 0.01))
    r = g.report()
    assert r.status == "nis_high" and r.mean_nis_window == pytest.approx(40.0)
    assert any("grey gate 1.50 m" in m for m in r.messages)
    g2 = GateHealth(min_jump_m=1.05, window=50, min_epochs=50)
    for _ in range(60):
        g2.update(_D(3.0, gate=1.5), (0.01, 0.01, 0.01))
    assert g2.report().status == "inert"


def test_gate_health_leaves_flagged_epochs_out_of_the_mean() -> None:
    g = GateHealth(window=100, min_epochs=10)
    for k in range(100):
        g.update(_D(500.0, fault=True) if k % 10 == 0 else _D(3.0), None)
    r = g.report()
    assert r.mean_nis == pytest.approx(3.0) and r.status == "ok"
    assert r.flagged_fraction == pytest.approx(0.1)
    # Most epochs flagged by the chi-square test: S is too small whatever the accepted mean says.
    g2 = GateHealth(window=100, min_epochs=10)
    for k in range(100):
        g2.update(_D(20.0, fault=True) if k % 2 else _D(5.0), None)
    assert g2.report().status == "nis_high"


def test_gate_health_window_follows_the_latest_epochs() -> None:
    g = GateHealth(window=10, min_epochs=10)
    for _ in range(100):
        g.update(_D(3.0), None)
    for _ in range(10):
        g.update(_D(30.0), None)
    r = g.report()
    assert r.mean_nis_window == pytest.approx(30.0)
    assert r.mean_nis == pytest.approx((300 + 300) / 110)
    g.update(_D(None), None)  # epochs without a test are not counted
    assert g.report().epochs == 110


# ----------------------------------------------------------------------------- the suite


def test_reduced_suite_table_and_default_at_least_as_good_as_every_baseline() -> None:
    from firmware_host.devtools.eval import BASELINE_NAMES, STRATEGIES, run_suite

    doc = run_suite(None, quick=True, plots=False, include_rov=False, include_insgnss=False)
    (case,) = doc["rover"]
    assert case["scenario"] == "rover-10hz-jump"
    names = [m["name"] for m in case["methods"]]
    assert len(names) == len(STRATEGIES) + len(BASELINE_NAMES)
    assert names[0] == case["default"] and names[0].endswith("(default)")
    assert set(BASELINE_NAMES) <= set(names)
    table = [line for line in doc["markdown"].splitlines() if line.startswith("| rover-10hz")]
    assert len(table) == len(names)
    assert all(line.count("|") == 11 for line in table)
    by = {m["name"]: m for m in case["methods"]}
    d = by[case["default"]]
    assert d["faulty_min"] >= 30, "the scenario must inject enough faults to measure"
    for b in BASELINE_NAMES:
        assert d["detection_rate"] >= by[b]["detection_rate"], b
        assert d["false_alarms"] <= by[b]["false_alarms"], b
    assert case["losses"] == []
    # The plain Kalman filter flags nothing; the gated ones miss some of the 3σ-20σ jumps.
    assert by["kalman_no_fdi"]["detected_min"] == 0
    assert by["ekf3"]["detection_rate"] < 1.0
    # On DGPS data the gate-health monitor says the chi-square statistic sits far below 3.
    health = d["gate_health"]
    assert health["status"] == "nis_low" and health["mean_nis"] < 0.3


def test_eval_cli_scores_a_replay_output_with_the_baselines(tmp_path: Path) -> None:
    from firmware_host.cli import main
    from firmware_host.commands.replay import run_replay
    from firmware_host.devtools.rover_sim import RoverScenario, write_run
    from firmware_host.runtime.config import load_config

    run_dir, out = tmp_path / "run", tmp_path / "out"
    write_run(RoverScenario(rate_hz=5.0, duration_s=120.0, seed=11), run_dir)
    summary = run_replay(load_config("rover"), run_dir / "rover.nmea", out, use_pty=False)
    assert summary["gate_health"]["status"] in ("nis_low", "inert")
    assert main(["eval", str(out), "--truth", str(run_dir / "truth.jsonl"),
                 "--out", str(tmp_path / "ev")]) == 0
    doc = json.loads((tmp_path / "ev" / "eval.json").read_text())
    names = [m["name"] for m in doc["methods"]]
    assert names[0] == "this run" and "ekf3" in names and "robot_localization" in names
    this = doc["methods"][0]
    assert this["faulty"] > 0 and this["detected_min"] == this["faulty_min"]
