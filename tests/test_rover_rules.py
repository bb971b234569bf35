"""The rover isolator's decision table (fdi/rover_rules.py): every rule on a short synthetic
sequence, each test failing if its rule is removed (the rule's id is written only by its own
function, and the test checks what the rule passes on); the reference page is current; the
paper's preset reaches rules R1-R8 only.

The sequences: a rover driving east at 2 m/s, its Doppler exact (speed and course), with a
small seeded noise where a test needs one, and a fault laid on top.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest

from fdi import rover_rules
from fdi.level import LevelHold
from fdi.rover import Decision, FixInput, RoverDetectorParams, RoverIsolator
from fdi.rover_evidence import Mode, Source

ROOT = Path(__file__).resolve().parent.parent
SPEED = 2.0
# Offline-calibrated drift σ (fdi-bridge calibrate writes such), so the drift test works from
# the first fix.
CAL = RoverDetectorParams(drift_calibrate_s=0.0, drift_precal_s=0.0,
                          drift_sigma_m=(0.05, 0.07, 0.1, 0.15, 0.25))
PAPER = RoverDetectorParams(alpha=0.05, use_gst=False, window=5, predictor="raw",
                            gate_axes="per_axis", gate_sigmas=0.0, test_up=False,
                            doppler_test=False, drift_test=False, replaced_r_factor=1.0,
                            min_sats=0)
Offset = Callable[[float], tuple[float, float]]


def _none(t: float) -> tuple[float, float]:
    return (0.0, 0.0)


def drive(seconds: float, rate_hz: float = 1.0, offset: Offset = _none, *, t0: float = 0.0,
          noise_m: float = 0.0, seed: int = 1) -> list[FixInput]:
    """Fixes of a rover driving east at SPEED from ``t0``, ``offset(t)`` (m) added."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(round(seconds * rate_hz)):
        t = t0 + k / rate_hz
        oe, on = offset(t)
        ne, nn = rng.normal(0.0, noise_m, 2) if noise_m else (0.0, 0.0)
        out.append(FixInput(t, (SPEED * t + oe + ne, on + nn, 10.0), SPEED, 90.0, None, 10,
                            0.9))
    return out


def run(params: RoverDetectorParams, fixes: Sequence[FixInput],
        iso: RoverIsolator | None = None) -> tuple[RoverIsolator, list[Decision]]:
    iso = iso or RoverIsolator(params)
    return iso, [iso.step(f) for f in fixes]


def rules(decs: Sequence[Decision]) -> list[str]:
    return [d.rule for d in decs]


def first(decs: Sequence[Decision], rule: str) -> int:
    ids = rules(decs)
    assert rule in ids, f"{rule} never decided: {sorted(set(ids))}"
    return ids.index(rule)


def step_at(t_on: float, t_off: float, de: float, dn: float = 0.0) -> Offset:
    return lambda t: (de, dn) if t_on <= t < t_off else (0.0, 0.0)


# ------------------------------------------------------------------ R1-R5: screens, restart


def test_r1_no_fix_passes_nothing() -> None:
    _, decs = run(CAL, [*drive(3), FixInput(3.0, None)])
    assert decs[-1].rule == "R1" and decs[-1].out_enu is None
    assert decs[-1].source is Source.NONE and decs[-1].reason == "no_fix"


def test_r2_a_repeated_time_is_not_passed_on() -> None:
    fixes = drive(5)
    _, decs = run(CAL, [*fixes, fixes[-1]._replace(enu=(99.0, 0.0, 10.0))])
    assert decs[-1].rule == "R2" and decs[-1].out_enu is None
    assert decs[-1].reason == "duplicate_time"


def test_r3_a_clock_jump_back_is_believed_only_after_fixes_in_a_row() -> None:
    fixes = drive(10)
    later = drive(3, t0=-100.0)
    _, decs = run(CAL, [*fixes, *later])
    assert rules(decs[-3:]) == ["R3", "R3", "R5"]
    assert decs[-3].out_enu is None and decs[-1].reason == "time_reset"


def test_r4_a_restart_on_a_fix_that_fails_a_quality_screen_raises_the_alarm() -> None:
    fix = drive(1)[0]._replace(num_sats=2)
    _, decs = run(CAL, [fix])
    assert decs[0].rule == "R4" and decs[0].alarm and decs[0].out_enu is None
    assert decs[0].reason == "sats"


def test_r5_the_first_fix_restarts_on_the_receiver() -> None:
    fixes = drive(1)
    _, decs = run(CAL, fixes)
    assert decs[0].rule == "R5" and decs[0].out_enu == fixes[0].enu
    assert decs[0].reason == "start" and decs[0].source is Source.RAW


# ------------------------------------------------------------------ R6-R8: the paper's


def test_r6_a_clean_fix_is_passed_on() -> None:
    fixes = drive(30, noise_m=0.02)
    iso, decs = run(CAL, fixes)
    assert set(rules(decs[1:])) == {"R6"}
    assert all(d.out_enu == f.enu and d.source is Source.RAW
               for d, f in zip(decs, fixes, strict=True))
    assert iso.mode is Mode.TRACK


@pytest.mark.parametrize("params", [CAL, PAPER], ids=["default", "paper"])
def test_r7_a_jump_is_replaced_by_its_prediction(params: RoverDetectorParams) -> None:
    fixes = drive(40, offset=step_at(30.0, 31.0, 4.0), noise_m=0.02)
    _, decs = run(params, fixes)
    k = first(decs, "R7")
    assert k == 30 and decs[k].source is Source.PREDICTION
    assert decs[k].out_enu is not None and decs[k].pred_enu == decs[k].out_enu
    truth = SPEED * 30.0
    assert abs(decs[k].out_enu[0] - truth) < 0.5 < abs(fixes[k].enu[0] - truth)  # type: ignore[index]


def test_r8_past_the_replacement_limit_the_alarm_restarts_on_the_receiver() -> None:
    fixes = drive(40, offset=step_at(20.0, 100.0, 4.0), noise_m=0.02)
    _, decs = run(PAPER, fixes)
    k = first(decs, "R8")
    assert rules(decs[20:k]) == ["R7"] * PAPER.max_consecutive
    assert decs[k].alarm and decs[k].alarm_raised and decs[k].out_enu is None
    assert decs[k].source is Source.NONE


# ------------------------------------------------------------------ R9-R10: the drift test


def test_r9_r10_a_slow_ramp_is_watched_then_warned_of_and_passed_on() -> None:
    fixes = drive(120, 10.0, offset=lambda t: (0.04 * max(0.0, t - 60.0), 0.0))
    _, decs = run(CAL, fixes)
    k10, k9 = first(decs, "R10"), first(decs, "R9")
    assert k10 < k9
    for k, reason in ((k10, "drift_watch"), (k9, "drift_warn")):
        assert decs[k].fault and decs[k].reason == reason
        assert decs[k].out_enu == fixes[k].enu and decs[k].source is Source.RAW


# ------------------------------------------------------------------ R11, R14, R16: steps


def _multipath(rate_hz: float) -> tuple[list[FixInput], list[Decision]]:
    """A 1.5 m step at 60 s that stays (the hold gives up on it: R20), back at 100 s."""
    fixes = drive(130, rate_hz, offset=step_at(60.0, 100.0, 0.0, 1.5))
    _, decs = run(CAL, fixes)
    return fixes, decs


def test_r20_an_abrupt_step_that_stays_times_out_and_r11_ends_it_on_its_reverse() -> None:
    fixes, decs = _multipath(1.0)
    k20 = first(decs, "R20")
    assert 60 < k20 < 100 and decs[k20].alarm and decs[k20].reason.endswith("+hold_timeout")
    k14 = first(decs, "R14")
    k11 = first(decs, "R11")
    assert k14 == 100 < k11 <= 104
    assert decs[k14].out_enu == fixes[k14].enu and decs[k14].reason.endswith("+step_back")
    assert decs[k11].reason == "step_end" and decs[k11].out_enu == fixes[k11].enu


def test_r11_fixes_that_pass_the_tests_confirm_a_steps_end() -> None:
    # A 0.65 m step that the drift test alone flags is held, then kept; its reverse is
    # flagged (R14), and the fixes after it, which pass every test, end it.
    params = dataclasses.replace(CAL, drift_sigma_m=(0.12, 0.15, 0.2, 0.3, 0.4))
    fixes = drive(130, offset=step_at(60.0, 100.0, 0.0, 0.65))
    _, decs = run(params, fixes)
    assert rules(decs[100:103]) == ["R14", "R9", "R11"]
    d = decs[102]
    assert d.reason == "step_end" and not d.fault and d.out_enu == fixes[102].enu
    assert d.drift is not None and d.drift < params.drift_sigmas


def test_r16_replacements_that_run_out_at_a_steps_end_restart_on_the_receiver() -> None:
    fixes, decs = _multipath(10.0)
    k = first(decs, "R16")
    assert 1000 <= k < 1020 and decs[k].out_enu == fixes[k].enu
    assert not decs[k].alarm_raised and decs[k].reason.endswith("+step_back")


def test_r14_a_step_back_to_an_older_level_passes_the_receiver_on() -> None:
    # An undetected ramp of 0.01 m/s for 100 s moves the track 1 m off its level; the fixes
    # then step back to it: the old track is the faulty side.
    fixes = drive(170, offset=lambda t: (0.0, 0.01 * min(100.0, t - 60.0)
                                        if 60.0 <= t < 160.0 else 0.0))
    _, decs = run(CAL, fixes)
    k = first(decs, "R14")
    assert k == 160 and decs[k].out_enu == fixes[k].enu and decs[k].fault
    assert decs[k].source is Source.RAW


# ------------------------------------------------------------------ R13, R15: replacements


def test_r13_a_fix_only_the_self_fed_grey_test_flags_is_passed_on() -> None:
    params = dataclasses.replace(CAL, gate_m=0.01, gate_sigmas=0.0)
    fixes = drive(40, noise_m=0.03, seed=3)
    _, decs = run(params, fixes)
    k = first(decs, "R13")
    assert decs[k].reason == "grey+grey_fed" and decs[k].out_enu == fixes[k].enu
    assert decs[k].action == "replace"


def test_r15_a_receiver_at_odds_with_its_own_doppler_coasts_under_the_alarm() -> None:
    params = dataclasses.replace(CAL, drift_test=False)
    fixes = drive(40, offset=lambda t: (0.0, 1.5 * max(0.0, t - 30.0)))
    _, decs = run(params, fixes)
    k = first(decs, "R15")
    assert rules(decs[k - params.max_consecutive:k]) == ["R7"] * params.max_consecutive
    assert decs[k].alarm and decs[k].out_enu is None and decs[k].source is Source.DOPPLER_COAST
    assert decs[k].reason.endswith("+coast")


# ------------------------------------------------------------------ R12, R17-R23: the hold


def _frozen(seconds: float, live_after: float = math.inf) -> list[FixInput]:
    """The receiver repeats its whole fix from 30 s until ``live_after``."""
    fixes = drive(seconds)
    return [fixes[30]._replace(t_s=f.t_s) if 30.0 <= f.t_s < live_after else f for f in fixes]


def test_r12_r22_r23_a_slow_drift_is_held_on_the_old_track_then_alarmed() -> None:
    fixes = drive(100, offset=lambda t: (0.0, 0.3 * max(0.0, t - 60.0)))
    iso, decs = run(CAL, fixes)
    k = first(decs, "R22")
    assert 60 < k <= 62 and decs[k].source is Source.OLD_TRACK
    assert iso._hold is not None and not iso._hold.frozen
    out = decs[k].out_enu
    assert out is not None and abs(out[1]) < 0.1 < fixes[k].enu[1]  # type: ignore[index]
    k23 = first(decs, "R23")
    assert k23 - k >= CAL.hold_output_s and decs[k23].alarm and decs[k23].out_enu is None


def test_r12_r25_a_frozen_receiver_is_not_moved_by_its_frozen_doppler() -> None:
    fixes = _frozen(50)
    iso, decs = run(CAL, fixes)
    k = first(decs, "R25")
    assert 30 < k <= 33 and "R22" not in rules(decs) and iso.mode is Mode.HOLD
    # At 1 Hz the freeze is found at its second repeat, past the coast's bound (1.7 s):
    assert decs[k].alarm and decs[k].out_enu is None and decs[k].source is Source.NONE
    assert decs[k].reason.endswith("+frozen_coast")


def circle(seconds: float, rate_hz: float, radius_m: float) -> list[FixInput]:
    """Fixes of a rover turning right on a circle of ``radius_m`` at SPEED from the origin,
    its Doppler exact (course from north)."""
    w = SPEED / radius_m
    return [FixInput(t, (radius_m * (1.0 - math.cos(w * t)), radius_m * math.sin(w * t), 10.0),
                     SPEED, math.degrees(w * t) % 360.0, None, 10, 0.9)
            for t in (k / rate_hz for k in range(round(seconds * rate_hz)))]


def test_r25_a_frozen_receiver_in_a_turn_coasts_on_its_turn_then_nothing() -> None:
    # 2 m/s on a 10 m radius at 10 Hz; the receiver repeats its whole fix from 30 s. The old
    # track moved by the frozen Doppler would run straight, 0.58 m off after 1.7 s.
    params = dataclasses.replace(CAL, drift_lag_s=0.0)
    truth = circle(45, 10.0, 10.0)
    fixes = [truth[300]._replace(t_s=f.t_s) if f.t_s >= 30.0 else f for f in truth]
    _, decs = run(params, fixes)
    k25 = first(decs, "R25")
    out = [(f.t_s - 30.0, d) for f, d in zip(truth[301:], decs[301:], strict=True)]
    passed = [(tau, d) for tau, d in out if d.out_enu is not None]
    for tau, d in passed:
        true_enu = truth[round(10 * (30.0 + tau))].enu
        assert d.out_enu is not None and true_enu is not None
        assert math.dist(d.out_enu[:2], true_enu[:2]) < 0.05, tau
    coasted = [tau for tau, d in passed if d.rule == "R25"]
    a, lag = params.frozen_accel_mps2, params.drift_lag_s + params.drift_lag_sd_s
    limit = (-a * lag + math.sqrt((a * lag) ** 2 + 2.0 * a * params.frozen_coast_m)) / a
    assert coasted and 301 <= k25 <= 303 and limit - 0.15 < max(coasted) <= limit
    assert all(d.out_enu is None and d.alarm for tau, d in out if tau > limit)


def test_r25_a_receiver_that_froze_on_a_jump_coasts_from_the_old_track() -> None:
    # The fix it repeats was 3 m off (replaced, R7): the coast starts from the old track at
    # the last live fix, not from the fix (10 Hz, straight east).
    fixes = drive(40, 10.0, offset=step_at(30.0, 30.05, 0.0, 3.0))
    fixes = [fixes[300]._replace(t_s=f.t_s) if f.t_s >= 30.0 else f for f in fixes]
    _, decs = run(CAL, fixes)
    assert decs[300].rule == "R7"
    coasted = [(k, d.out_enu) for k, d in enumerate(decs) if d.rule == "R25" and d.out_enu]
    assert len(coasted) >= 12
    assert all(math.dist(out[:2], (SPEED * k / 10.0, 0.0)) < 0.01 for k, out in coasted)


def test_r21_r18_a_receiver_live_again_is_passed_on_then_the_hold_ends() -> None:
    # A freeze shorter than the coast (10 Hz): the hold passes the live receiver on at once.
    fixes = drive(40, 10.0)
    fixes = [fixes[300]._replace(t_s=f.t_s) if 30.0 <= f.t_s < 31.0 else f for f in fixes]
    _, decs = run(CAL, fixes)
    assert "R25" in rules(decs[300:310])
    k21 = first(decs, "R21")
    assert k21 == 310 and decs[k21].out_enu == fixes[k21].enu
    k18 = first(decs, "R18")
    assert k21 < k18 <= 330 and decs[k18].reason.startswith("hold_")
    assert decs[k18].out_enu == fixes[k18].enu and decs[k18].action == "accept"


def test_r21_r18_a_position_frozen_under_a_live_doppler_is_never_passed_on() -> None:
    # 0.5 m/s at 10 Hz, the drift test's wide configured sigma: the position repeats from
    # 30 s while speed and course stay live. Within 3 sigma of the old track for seconds, the
    # frozen fix was passed on (R21) and even resumed on (R18), 1.5 m behind after 3 s; the
    # old track, moved by the live Doppler, is right (R22), then the alarm (R23).
    params = RoverDetectorParams(drift_calibrate_s=0.0, drift_precal_s=0.0)
    v = 0.5
    fixes = [FixInput(k / 10, (v * k / 10, 0.0, 10.0), v + 0.01 * (k % 2), 90.0, None, 10, 0.9)
             for k in range(450)]
    fixes = [f._replace(enu=fixes[300].enu) if f.t_s >= 30.0 else f for f in fixes]
    _, decs = run(params, fixes)
    held = [(f.t_s, d) for f, d in zip(fixes, decs, strict=True) if f.t_s >= 30.3]
    assert not {"R21", "R18"} & {d.rule for _, d in held}
    out = [(t, d.out_enu) for t, d in held if d.out_enu is not None]
    assert len(out) >= 90 and all(abs(o[0] - v * t) < 0.1 for t, o in out)
    assert held[-1][1].rule == "R23" and held[-1][1].out_enu is None


def test_r17_a_doppler_chain_broken_in_a_hold_raises_the_alarm() -> None:
    fixes = _frozen(35)
    fixes.append(drive(36)[-1]._replace(speed_mps=None, course_deg=None))
    iso, decs = run(CAL, fixes)
    assert decs[-1].rule == "R17" and decs[-1].alarm and decs[-1].out_enu is None
    assert iso.mode is Mode.TRACK


def test_r19_an_abrupt_hold_whose_fixes_were_passed_on_keeps_the_receivers_level() -> None:
    fixes = drive(40)
    iso, _ = run(CAL, fixes[:30])
    drift, hp = iso._drift, iso._hold_p
    assert drift is not None and hp is not None
    ref = drift.at_or_before(29.0)
    assert ref is not None
    hold = LevelHold(hp, 0.0, *ref, slow=False)
    hold.was_raw = True
    iso._hold, iso._hold_reason = hold, "grey"
    _, decs = run(CAL, fixes[30:31], iso)
    assert decs[0].rule == "R19" and decs[0].reason == "hold_kept"
    assert decs[0].out_enu == fixes[30].enu and not decs[0].alarm and iso.mode is Mode.TRACK


# ------------------------------------------------------------------ R24: the zone strategies


def test_r24_the_three_zone_strategy_decides_every_epoch_after_the_first() -> None:
    params = dataclasses.replace(PAPER, strategy="three_zone")
    _, decs = run(params, drive(20, offset=step_at(15.0, 16.0, 5.0), noise_m=0.02))
    assert set(rules(decs[1:])) == {"R24"} and decs[15].fault


# ------------------------------------------------------------------ the table


def test_every_rule_of_the_table_has_its_function_and_no_other() -> None:
    fns = rover_rules.rule_functions()
    assert set(fns) == {r.id for r in rover_rules.RULES}
    assert [r.id for r in rover_rules.RULES] == [f"R{i}" for i in range(1, 26)]


def test_the_reference_page_is_current() -> None:
    page = ROOT / "docs" / "reference" / "rover-decisions.md"
    assert page.read_text(encoding="utf-8") == rover_rules.markdown(RoverDetectorParams()), (
        "regenerate it: python -c 'import fdi.rover as v, fdi.rover_rules as r; "
        "print(r.markdown(v.RoverDetectorParams()), end=\"\")' > docs/reference/rover-decisions.md")


def test_the_paper_preset_reaches_rules_r1_to_r8_only() -> None:
    fixes = drive(200, offset=lambda t: (4.0, 0.0) if 50 <= t % 60 < 58 else (0.0, 0.0),
                  noise_m=0.2, seed=5)
    fixes[100] = fixes[100]._replace(enu=None)
    _, decs = run(PAPER, fixes)
    ids = set(rules(decs))
    assert {"R1", "R5", "R6", "R7", "R8"} <= ids <= {f"R{i}" for i in range(1, 9)}
