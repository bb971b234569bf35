"""Issue 13: the field error models of the rover generator, the done-means harness's scoring on
hand-made records, and the default preset on every error model (report seeds; tuning used
seeds 101-103 only, firmware_host/devtools/rover_harness.py)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import pytest

from fdi import rover
from fdi.geodesy import LocalFrame
from firmware_host.devtools.rover_harness import (
    measure,
    offline_calibrated,
    replay,
    run_matrix,
    scenario,
    summarise,
    table,
)
from firmware_host.devtools.rover_sim import (
    ERROR_MODELS,
    RoverScenario,
    draw_field_model,
    generate,
)
from firmware_host.runtime.config import load_config

FRAME = LocalFrame(32.0, 118.0, 10.0)

# ----------------------------------------------------------------------------- the generator


def _run(model: str, kinds: tuple[str, ...], rate: float = 5.0, seed: int = 4,
         duration: float = 600.0) -> list[tuple[bytes, dict[str, Any]]]:
    sc = RoverScenario(rate_hz=rate, duration_s=duration, seed=seed, kinds=kinds,
                       error_model=model, fault_every_s=40.0, min_gap_s=20.0)
    return [(d, tr) for _, d, tr in generate(sc)]


def _rmc(data: bytes) -> list[str]:
    line = next(x for x in data.decode().split("\r\n") if x.startswith("$GPRMC"))
    return line.split("*")[0].split(",")


def test_field_models_are_drawn_per_seed_within_their_ranges() -> None:
    for model in ("dgps", "multipath", "coarse"):
        a, b = draw_field_model(model, 1), draw_field_model(model, 2)
        assert a != b
        (_, tau_short), (s_long, tau_long) = a.gm_h
        assert tau_short < 31.0 and tau_long >= 120.0 and s_long >= 0.25
        assert 0.05 <= a.lag_s <= 0.4
        assert a.minute_decimals == (4 if model == "coarse" else 5)
        assert all(1.0 <= v <= 3.0 for v in a.pass_speeds_mps)
    with pytest.raises(ValueError):
        draw_field_model("gm", 1)


def test_field_model_quantises_coordinates_and_stops_the_tractor() -> None:
    run = _run("dgps", ("jump",))
    for data, _ in run[:200]:
        f = _rmc(data)
        if f[3]:
            assert f[3].endswith("000"), f[3]  # 5 decimals of minutes (8 written)
    speeds = [tr["speed_true"] for _, tr in run]
    assert min(speeds) < 0.01 and max(speeds) > 1.0
    assert sum(s < 0.05 for s in speeds) > 25  # at least one stop of 5 s or more


def test_frozen_receiver_repeats_its_whole_fix_and_ramps_grow_at_their_rate() -> None:
    run = _run("dgps", ("frozen", "ramp"))
    frozen = [(d, tr) for d, tr in run if tr["fault_kind"] == "frozen"]
    ramps = [tr for _, tr in run if tr["fault_kind"] == "ramp"]
    assert frozen and ramps
    by_event: dict[int, list[list[str]]] = {}
    for d, tr in frozen:
        by_event.setdefault(tr["fault_event"], []).append(_rmc(d))
    for rmcs in by_event.values():
        # Position, speed and course identical; only the time advances.
        assert len({tuple(f[3:9]) for f in rmcs}) == 1
        assert len({f[1] for f in rmcs}) == len(rmcs)
    for ev in {tr["fault_event"] for tr in ramps}:
        trs = [tr for tr in ramps if tr["fault_event"] == ev]
        rate = trs[0]["fault_rate_mps"]
        assert 0.02 <= rate <= 0.3
        span = trs[-1]["utc"] - trs[0]["utc"]
        assert trs[-1]["fault_offset_m"] - trs[0]["fault_offset_m"] == pytest.approx(
            rate * span, rel=1e-6)


def test_multipath_steps_are_abrupt_and_persist() -> None:
    run = _run("multipath", ("jump",), duration=900.0)
    steps: dict[int, list[dict[str, Any]]] = {}
    for _, tr in run:
        if tr["fault_kind"] == "multipath":
            steps.setdefault(tr["fault_event"], []).append(tr)
    assert len(steps) >= 3
    for trs in steps.values():
        offs = {round(tr["fault_offset_m"], 9) for tr in trs}
        assert len(offs) == 1 and 0.5 <= offs.pop() <= 2.0
        assert 5.0 - 0.3 <= trs[-1]["utc"] - trs[0]["utc"] <= 30.0


# ----------------------------------------------------------------------------- the scoring


def _truth(k: int, kind: str | None = None, event: int | None = None,
           offset: float = 0.0, rate: float = 0.0) -> dict[str, Any]:
    lat, lon, h = FRAME.to_lla(1.0 * k, 0.0, 0.0)  # 1 m east per epoch at 1 Hz
    return {"k": k, "utc": 36000.0 + k, "true_lat": lat, "true_lon": lon, "true_alt": h,
            "fault": kind is not None, "fault_kind": kind, "fault_event": event,
            "fault_offset_m": offset, "fault_rate_mps": rate, "outage": False,
            "err_e": 0.1, "err_n": 0.0}  # the live receiver's error (what a frozen one hides)


def _epoch(k: int, flagged: bool, raw_err: float, out_err: float | None,
           action: str = "accept") -> dict[str, Any]:
    rlat, rlon, _ = FRAME.to_lla(1.0 * k + raw_err, 0.0, 0.0)
    rec: dict[str, Any] = {"utc": 36000.0 + k, "fault": flagged, "raw_lat": rlat,
                           "raw_lon": rlon, "lat": None, "lon": None, "action": action}
    if out_err is not None:
        rec["lat"], rec["lon"], _ = FRAME.to_lla(1.0 * k + out_err, 0.0, 0.0)
    return rec


def test_measure_counts_every_bullet_exactly() -> None:
    # 100 epochs at 1 Hz. Event 0: a ramp of 0.1 m/s at k = 20..39, flagged from k = 27.
    # Event 1: a frozen fix at k = 60..64, offsets 0.4, 0.8, 1.2, 1.6, 2.0; k = 60..62 passed
    # on as good (accept), the output 0.4 / 0.8 / 1.2 m off: one epoch > 1 m off (where the
    # live receiver was 0.1 m off), one with an offset > 1 m; k = 60, the live fix the
    # receiver goes on to repeat, is not a frozen epoch (4 faulty epochs, 2 caught). Clean
    # epochs more than 10 s from the events: k = 0..9 and 75..99; k = 80 is flagged (k = 50
    # is exactly 10 s before event 1: not counted). After event 1 (k = 65..74) the output is
    # 0.2 m off where the raw is 0.1 m.
    truth = [_truth(k) for k in range(100)]
    for k in range(20, 40):
        truth[k] = _truth(k, "ramp", 0, 0.1 * (k - 19), 0.1)
    for k in range(60, 65):
        truth[k] = _truth(k, "frozen", 1, 0.4 * (k - 59))
    epochs = []
    for k in range(100):
        flagged = (27 <= k < 40) or k == 80 or 63 <= k < 65
        raw = truth[k]["fault_offset_m"] or 0.1
        out: float | None = raw
        action = "accept"
        if 27 <= k < 40 or 63 <= k < 65:
            out, action = 0.1, "replace"
        if 65 <= k < 75:
            out = 0.2
        epochs.append(_epoch(k, flagged, raw, out, action))
    m = measure(epochs, truth, model="t", seed=0, rate_hz=1.0)
    ramp, frozen = m.events
    assert (ramp.kind, ramp.detected, ramp.delay_s) == ("ramp", True, 7.0)
    assert ramp.rate_mps == pytest.approx(0.1)
    assert (ramp.faulty, ramp.caught) == (10, 10)  # offsets >= 1.05 m: k = 30..39
    assert (frozen.faulty, frozen.caught) == (4, 2)
    assert (frozen.frozen_good_far, frozen.frozen_good_far_live,
            frozen.frozen_good_offset) == (1, 1, 1)
    assert m.clean_far == 10 + 25 and m.clean_far_flagged == 1
    assert frozen.after_out_rms_m == pytest.approx(0.2, abs=1e-6)
    assert frozen.after_raw_rms_m == pytest.approx(0.1, abs=1e-6)
    rows = summarise([m])
    assert rows[0]["ramp"]["ramps_in_time"] == 1 and rows[0]["after_worse"] == 1
    assert rows[0]["frozen"]["good_far"] == 1
    assert table(rows).count("\n") == 2


# ----------------------------------------------------------------------------- the default


@pytest.fixture(scope="module")
def rows() -> list[dict[str, Any]]:
    """The default preset, every error model, report seeds 1 and 2, 1/5/10 Hz, 10 minutes."""
    runs = run_matrix(load_config("rover"), seeds=(1, 2), duration_s=600.0)
    return summarise(runs)


@pytest.mark.slow
def test_every_error_model_and_rate_is_measured(rows: list[dict[str, Any]]) -> None:
    assert {(r["model"], r["rate_hz"]) for r in rows} == {
        (m, r) for m in ERROR_MODELS for r in (1.0, 5.0, 10.0)}


@pytest.mark.slow
def test_jumps_and_bursts_on_every_model(rows: list[dict[str, Any]]) -> None:
    for r in rows:
        for kind in ("jump", "burst"):
            d = r.get(kind)
            if d is None:
                continue
            assert d["detected"] == d["events"], (r["model"], r["rate_hz"], kind, d)
            assert d["caught"] >= 0.99 * d["faulty"], (r["model"], r["rate_hz"], kind, d)


@pytest.mark.slow
def test_frozen_receiver_is_not_passed_on_far_from_the_truth(rows: list[dict[str, Any]]
                                                             ) -> None:
    """No frozen epoch is passed on as good more than 1 m from the truth (a frozen event's
    first epoch, the live fix the receiver then repeats, is not a frozen epoch). On these
    seeds: 0 with or without stale_p; over seeds 1-5 and 201-205 at 1200 s, 10 and 11 before
    it, 3 and 5 with it (docs/evaluation.md); tests/test_rover_drift.py times the repeats."""
    for r in rows:
        d = r["frozen"]
        assert d["detected"] == d["events"], (r["model"], r["rate_hz"], d)
        assert d["good_offset"] == 0, (r["model"], r["rate_hz"], d)
        assert d["good_far"] == 0, (r["model"], r["rate_hz"], d)


@pytest.mark.slow
def test_never_worse_than_the_receiver_overall(rows: list[dict[str, Any]]) -> None:
    for r in rows:
        assert r["rms_ratio_worst"] <= 0.9, (r["model"], r["rate_hz"], r["rms_ratio_worst"])


@pytest.mark.slow
def test_after_an_event_the_output_is_not_worse_than_the_receiver(rows: list[dict[str, Any]]
                                                                  ) -> None:
    """The bullet "in the 10 s after every event, output RMS <= raw": seeds 1-2, 10 minutes,
    no event (measured 0 since the remembered-step rule of fdi/rover.py; before it 0-2 events
    a model and rate, up to 0.41 m on multipath at 1 Hz; before the step-back rule 1-8, up to
    10.9 m). On held-out seeds 201-205 (20 minutes) it is not met everywhere:
    docs/evaluation.md."""
    for r in rows:
        assert r["after_worse"] == 0, (r["model"], r["rate_hz"], r["after_worse"])


@pytest.mark.slow
def test_clean_epochs_are_rarely_flagged(rows: list[dict[str, Any]]) -> None:
    """Clean epochs more than 10 s from any event, flagged: at its measured bound, 1 % a model
    and rate (measured 0-0.87 %, coarse at 1 Hz; the goal is 0.1 %, docs/evaluation.md)."""
    for r in rows:
        assert r["fa_worst"] <= 0.01, (r["model"], r["rate_hz"], r["fa_worst"])


@pytest.mark.slow
def test_field_models_detect_most_ramps_in_time(rows: list[dict[str, Any]]) -> None:
    """The ramp bullet (0.1 m/s within 10 s, 0.05 m/s within 30 s) is not met everywhere
    (docs/evaluation.md says where); pooled over the dgps-class models, most are."""
    in_time = required = 0
    for r in rows:
        if r["model"] in ("dgps", "multipath") and r.get("ramp"):
            in_time += r["ramp"]["ramps_in_time"]
            required += r["ramp"]["ramps_required"]
    assert required >= 5 and in_time >= 0.5 * required, (in_time, required)


def test_replay_of_a_field_model_run_is_deterministic() -> None:
    cfg = load_config("rover")
    sc = scenario("coarse", 1, 5.0, 120.0)
    a, _ = replay(cfg, sc)
    b, _ = replay(cfg, sc)
    assert a == b
    assert all(math.isfinite(e["kf_e"]) for e in a if e["kf_e"] is not None)


def _event(events: Any, kind: str, start_s: float, tol: float = 0.05) -> Any:
    """The event of ``kind`` starting at ``start_s`` (seconds of day)."""
    return next(e for e in events if e.kind == kind and abs(e.start_s % 86400 - start_s) < tol)


def _event_not_worse(events: Any, kind: str, start_s: float, tol: float = 0.05) -> Any:
    """The event of ``kind`` starting at ``start_s`` (seconds of day): detected, and the
    output's RMS over the 10 s after it at most the receiver's."""
    ev = _event(events, kind, start_s, tol)
    assert ev.detected
    assert ev.after_out_rms_m <= ev.after_raw_rms_m + 1e-9, (kind, start_s, ev.after_out_rms_m,
                                                            ev.after_raw_rms_m)
    return ev


def test_a_step_back_the_replacements_run_out_on_keeps_the_levels_it_came_back_to() -> None:
    """multipath 10 Hz seed 602: a missed 0.024 m/s ramp ends by stepping back (remembered as
    a step); a multipath step 36 s later lands at the ramp's last level, is taken as that
    step's reversal and passed on, and at 10 Hz its 5 replacements end before the reversal
    can be confirmed (hold_exit_s + 3 epochs): a restart (with an alarm until the sixteenth
    pass, docs/evaluation.md). Restarted without the drift test's levels, the receiver's
    return to the truth 23 s later was held as a fault, 1.38 m RMS against 0.20 m raw; so was
    it when _step_end confirmed the reversal there (the fourteenth pass's variant a). The
    restart keeps the levels (rebased) and the return is passed on."""
    eps, truth = replay(load_config("rover"), scenario("multipath", 602, 10.0))
    _event_not_worse(measure(eps, truth).events, "multipath", 36389.9)


def test_a_step_whose_end_passed_as_good_is_forgotten() -> None:
    """multipath 1 Hz seed 2001, offline-calibrated: a 0.5 m multipath step (148 s) was
    remembered and accepted, and its end (173 s) passed the tests (a drift warning), so the
    step was never matched. A 0.79 m multipath step at 200 s was its reverse within 0.14 m:
    taken for its end and passed on, and its own end at 220 s was held 7 s as a new fault
    (0.73 m against 0.22 m raw). Fixes that pass and stay at the reversal for hold_exit_s now
    forget the step (fdi/rover.py, _passed_reversal). At 10 Hz the same seed's first epoch of
    a step's end passes too, and the next is a fault: that end must still be matched."""
    for rate, start in ((1.0, 36200.0), (10.0, 36146.4)):
        cfg = offline_calibrated(load_config("rover"), "multipath", 2001, rate)
        eps, truth = replay(cfg, scenario("multipath", 2001, rate))
        _event_not_worse(measure(eps, truth).events, "multipath", start, 0.5)


def test_a_burst_s_self_fed_predictions_do_not_replace_the_clean_fixes_after_it() -> None:
    """coarse 1 Hz seed 3001 (a seed set no choice had looked at), the default: a 2.65 m
    burst of 4 epochs at 79 s was replaced by the grey prediction, and those predictions
    went into the window (0.58 to 1.02 m off the truth: GM(1,1) extrapolating itself). The
    first clean fix after it passed, but the next one, 0.19 m off, was replaced by a
    prediction 1.07 m off: 0.54 m against 0.43 m raw over the 10 s after the burst. Once a
    fix passes, the window's predictions are now the values between the fixes on either side
    (fdi/rover.py, _window_append)."""
    sc = scenario("coarse", 3001, 1.0)
    eps, truth = replay(load_config("rover"), sc)
    burst = _event_not_worse(measure(eps, truth).events, "burst", 36079.0, 0.5)
    assert burst.caught == burst.faulty == 4
    after = [(e["action"], e["reason"]) for e in eps[83:95]]
    assert after == [("accept", "")] * 12, after


def test_a_fix_that_passes_during_a_step_back_does_not_end_its_confirmation() -> None:
    """multipath 10 Hz seed 3003 (a seed set no choice had looked at), the default: a 0.52 m
    multipath step (462.7 s) was taken as the receiver's level after its hold. At its end
    (488.8 s) the fixes stepped back and were passed on as a step back, but one of them
    passed the tests (489.8 s): it ended the step back's confirmation and became a reference
    of the drift test at the level before the step, so the next epoch was no longer the step
    reversed, and the longer horizons' fault held the stepped level for 1.8 s (0.29 against
    0.16 m raw over the 10 s after the step). A fix that passes while a step back is being
    confirmed is now part of it (fdi/rover.py, the accept path)."""
    eps, truth = replay(load_config("rover"), scenario("multipath", 3003, 10.0))
    _event_not_worse(measure(eps, truth).events, "multipath", 36462.7)
    end = [e["reason"] for e in eps[4888:4920]]
    assert "step_end" in end and not any("hold" in r for r in end), end


def test_a_hold_after_a_step_back_forgets_the_missed_ramp_s_references() -> None:
    """dgps 1 Hz seed 8004 (a seed set no choice had looked at), the default: a 0.03 m/s ramp
    (235-291 s, under what the bullets ask for) passed unflagged, and its end stepped back
    1.6 m; the hold after the step back ended (the fixes agreed with the old track within
    3 σ) with the ramp's epochs still references of the drift test, so the clean fixes 11 s
    on were held again as a drift, 7 epochs flagged (1.26 % of the run's clean epochs). A
    hold that began after a step back to an older level forgets the references since that
    level when it ends (fdi/rover.py, _hold_step)."""
    eps, truth = replay(load_config("rover"), scenario("dgps", 8004, 1.0))
    after = [e for e in eps if 36298.0 <= e["utc"] % 86400 < 36330.0]
    assert after and not any(e["fault"] for e in after), [
        (e["utc"] % 86400, e["reason"]) for e in after if e["fault"]]
    assert measure(eps, truth).clean_far_flagged == 0


def test_a_clean_fix_after_a_burst_is_not_judged_by_the_grey_window_s_own_predictions() -> None:
    """dgps 1 Hz seed 9005 (a seed set no choice had looked at), the default: a 4-epoch burst
    (1141-1144 s) was replaced by GM(1,1) predictions, each from the second on extrapolating
    the one before, so they ran 0.41 -> 0.88 m off the truth; the first clean fix after it
    (1145 s, 0.25 m off) passed the chi-square, Doppler and drift tests but not the grey one,
    and was replaced 0.93 m off: the 10 s after the burst 0.11 m worse than the receiver.
    Such a fix is now passed on, flagged (`grey_fed_sigmas`, fdi/rover.py); with the rule off
    the event is worse than raw again."""
    def burst(cfg: Any) -> tuple[Any, list[dict[str, Any]]]:
        eps, truth = replay(cfg, scenario("dgps", 9005, 1.0))
        ev = _event(measure(eps, truth).events, "burst", 37141.0, 0.5)
        return ev, [e for e in eps if abs(e["utc"] % 86400 - 37145.0) < 0.01]

    cfg = load_config("rover")
    ev, (fix,) = burst(cfg)
    assert ev.detected and ev.after_out_rms_m <= ev.after_raw_rms_m + 1e-9, (
        ev.after_out_rms_m, ev.after_raw_rms_m)
    assert fix["fault"] and fix["reason"] == "grey+grey_fed", fix["reason"]
    assert abs(fix["lat"] - fix["raw_lat"]) < 1e-9 and abs(fix["lon"] - fix["raw_lon"]) < 1e-9
    det = dataclasses.replace(cfg.rover.detector, grey_fed_sigmas=0.0)
    off = dataclasses.replace(cfg, rover=dataclasses.replace(cfg.rover, detector=det))
    ev, (fix,) = burst(off)
    assert ev.after_out_rms_m > ev.after_raw_rms_m + 0.05 and fix["reason"] == "grey"


def test_a_slow_hold_does_not_take_a_drifted_ramp_for_a_level_minutes_old() -> None:
    """coarse 1 Hz seed 10001 (a seed set no choice had looked at), the default: a 0.063 m/s
    ramp (1004-1060 s) was caught at 1036 s; its fixes, which had drifted (no step), sat near
    the level of 751 s (256 s before the hold's anchor) of a receiver error that wanders over
    metres, and the hold took them for the new level at 1047 s, forgetting every reference
    since 751 s. The ramp then ran on unflagged, and its end (1060 s, a step back of 1.9 m
    with no older level left to match) was replaced by the ramp's track: 2.48 m against
    0.93 m raw over the 10 s after it, 2 clean epochs flagged. Fixes that drifted to an
    older level no longer end a slow hold (fdi/level.py)."""
    eps, truth = replay(load_config("rover"), scenario("coarse", 10001, 1.0))
    m = measure(eps, truth)
    _event_not_worse(m.events, "ramp", 37004.0, 0.5)
    during = [e["reason"] for e in eps if 37004.0 <= e["utc"] % 86400 < 37060.0]
    assert not any("new_level" in r for r in during), during
    assert m.clean_far_flagged == 0, m.clean_far_flagged


def test_a_missed_ramp_s_end_before_the_calibration_is_judged_with_the_provisional_sigma(
) -> None:
    """dgps 1 Hz seed 9001, the default: a 0.039 m/s ramp (88-134 s, under what the bullets
    ask for) passed unflagged, and at its end the fixes stepped back 1.4 m to the level before
    it. That was after the drift test's provisional σ (120 s) but before its calibration
    (300 s), and the step back's older-level test measured the track's departure against the
    configured σ(30 s) of 0.9 m (1.8 m asked): the return was replaced by the ramp's track
    and then held, 1.86 against 0.21 m raw over the 10 s after. The test now uses the
    provisional σ (fdi/drift.py, working_sigmas); without one (``drift_precal_s = 0``) the
    event is worse than raw again."""
    def ramp(cfg: Any) -> tuple[Any, dict[str, Any]]:
        eps, truth = replay(cfg, scenario("dgps", 9001, 1.0))
        ev = _event(measure(eps, truth).events, "ramp", 36088.0, 0.5)
        (end,) = [e for e in eps if abs(e["utc"] % 86400 - 36134.0) < 0.01]
        return ev, end

    cfg = load_config("rover")
    ev, end = ramp(cfg)
    assert not ev.detected  # under the bullets: nothing is asked of the ramp itself
    assert ev.after_out_rms_m <= ev.after_raw_rms_m + 1e-9, (ev.after_out_rms_m,
                                                             ev.after_raw_rms_m)
    assert end["fault"] and "step_back" in end["reason"], end["reason"]
    assert abs(end["lat"] - end["raw_lat"]) < 1e-9 and abs(end["lon"] - end["raw_lon"]) < 1e-9
    det = dataclasses.replace(cfg.rover.detector, drift_precal_s=0.0)
    off = dataclasses.replace(cfg, rover=dataclasses.replace(cfg.rover, detector=det))
    ev, end = ramp(off)
    assert ev.after_out_rms_m > ev.after_raw_rms_m + 0.5, (ev.after_out_rms_m,
                                                           ev.after_raw_rms_m)
    assert "step_back" not in end["reason"], end["reason"]


def test_a_step_back_only_the_drift_test_flags_is_held_as_a_step(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """multipath 5 Hz seed 12004 (a seed set no choice had looked at), the default: a 0.7 m
    multipath step (293.2 s, within the grey gate) was accepted, and its end at 311.8 s, a
    step back of the Doppler-free value that the grey and chi-square tests do not see, was
    flagged by the drift and Doppler tests alone and held as a *slow* fault: 10 s of the
    multipath track, then the alarm to 332 s, 48 clean epochs flagged more than 10 s from any
    event (1.67 %). A drift fault whose value stepped faster than any slow fault moves
    (fdi/rover.py, SLOW_MAX_MPS) is held as a step, which gives up at hold_output_s."""
    def run() -> tuple[Any, list[dict[str, Any]]]:
        eps, truth = replay(load_config("rover"), scenario("multipath", 12004, 5.0))
        return measure(eps, truth), [e for e in eps if 36311.7 <= e["utc"] % 86400 < 36335.0]

    def alarms(after: list[dict[str, Any]]) -> int:
        return sum(e["action"] == "alarm" for e in after)

    m, after = run()
    # The give-up at 322 s raises the alarm until recover_epochs good fixes (1 s).
    assert m.clean_far_flagged <= 2 and alarms(after) <= 6, (m.clean_far_flagged,
                                                              alarms(after))
    monkeypatch.setattr(rover, "SLOW_MAX_MPS", math.inf)
    m, after = run()
    # Without the rule (drift_cal_min_h 1 s, issue 42: 25 flagged, 28 alarms; 30 s: over 40).
    assert m.clean_far_flagged > 20 and alarms(after) > 20, (m.clean_far_flagged,
                                                             alarms(after))


def test_a_step_the_doppler_test_alone_flags_is_remembered() -> None:
    """multipath 5 Hz seed 10001 (the nineteenth seed set), the default: a 0.70 m multipath
    step began at 260.2 s with an epoch only the Doppler test flagged, so it was not
    remembered (_note_step asked for the grey, chi-square or drift test), and its end at
    283.8 s was replaced by the old track for 1 s: 0.36 against 0.22 m raw over the 10 s
    after. A run of faults that a Doppler fault starts now remembers its step too."""
    eps, truth = replay(load_config("rover"), scenario("multipath", 10001, 5.0))
    _event_not_worse(measure(eps, truth).events, "multipath", 36260.2)
    end = [e for e in eps if 36283.7 <= e["utc"] % 86400 < 36285.0]
    assert all(e["lat"] is not None for e in end)
    assert any("step_back" in e["reason"] for e in end), [e["reason"] for e in end]


def test_a_remembered_step_s_end_at_10_hz_passes_the_receiver_on_without_an_alarm() -> None:
    """multipath 10 Hz seed 4, the default: the end of a remembered step is passed on as a
    step back, but its 5 replacements (0.5 s) run out before _step_end can confirm it
    (hold_exit_s and 3 epochs), and the alarm that followed withheld 0.5 s of the fixes
    every step back had been passing on, seven times in the run (35 epochs with no output).
    The restart is still the alarm's (the drift test's levels kept, rebased: multipath 10 Hz
    seed 602 above), without the alarm."""
    eps, truth = replay(load_config("rover"), scenario("multipath", 4, 10.0))
    after_back = [round(eps[i]["utc"] % 86400, 1) for i in range(1, len(eps))
                  if eps[i]["action"] == "alarm" and eps[i - 1]["action"] == "replace"
                  and eps[i - 1]["reason"].endswith("step_back")]
    assert after_back == [], after_back
    backs = [i for i in range(5, len(eps))
             if all(eps[j]["reason"].endswith("step_back") for j in range(i - 5, i + 1))]
    assert backs, "no step back ran past max_consecutive in this run"
    for ev in measure(eps, truth).events:
        if ev.kind == "multipath" and ev.after_out_rms_m is not None:
            assert ev.after_out_rms_m <= ev.after_raw_rms_m + 1e-9, (ev.start_s,
                                                                     ev.after_out_rms_m,
                                                                     ev.after_raw_rms_m)


def test_a_small_step_s_end_is_its_reverse_within_the_epoch_s_noise(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """multipath 1 Hz seed 9001, the default (the run this floor was traced on): a
    0.55 m multipath step (684 s) was remembered and accepted; its end at 713 s stepped back
    0.80 m, 0.28 m from the step reversed, against 0.4 x 0.55 = 0.22 m, so it was held 8 s
    as a new fault (0.23 m worse than raw over the 10 s after). Both steps are measured over
    one epoch, each with that epoch's noise: the tolerance is now at least 3 x √2 x the
    calibrated drift σ(1 s) (0.35 m here), up to 0.6 x the step (0.33 m; fdi/rover.py,
    REVERSAL_FLOOR_SIGMAS)."""
    def run() -> tuple[Any, list[str]]:
        eps, truth = replay(load_config("rover"), scenario("multipath", 9001, 1.0))
        return (_event(measure(eps, truth).events, "multipath", 36685.0, 0.5),
                [e["reason"] for e in eps if 36713.0 <= e["utc"] % 86400 < 36716.0])

    ev, end = run()
    assert ev.after_out_rms_m <= ev.after_raw_rms_m + 1e-9, (ev.after_out_rms_m,
                                                             ev.after_raw_rms_m)
    assert "step_end" in end and not any("hold" in r for r in end), end
    monkeypatch.setattr(rover, "REVERSAL_FLOOR_SIGMAS", 0.0)
    ev, end = run()
    assert ev.after_out_rms_m > ev.after_raw_rms_m + 0.1, (ev.after_out_rms_m,
                                                           ev.after_raw_rms_m)
