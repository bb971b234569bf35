"""GPS hard-fault detection and isolation for the farm rover.

Zhou Jun, Zhang Peng, "Hard fault isolation of GPS navigation system based on gray prediction
for agricultural robot", Trans. CSAM 41(12), 2010. Per epoch:

1. the Kalman filter's residual chi-square test, F(k) = DᵀS⁻¹D against T_d (eq. 1-6,
   :mod:`fdi.kalman`), T_d computed from α and m = 3;
2. the GM(1,1) one-step prediction of each axis from the last n valid fixes (eq. 7-17,
   :mod:`fdi.grey`) and its residual ε(k) = x⁰(k) − x̂⁰(k) (eq. 18) against a gate;
3. isolation: a fix judged faulty is replaced by its prediction *before* the filter update, and
   the prediction window continues with the replaced value (section 2.2);
4. "if the GPS data stay abnormal ... raise an alarm or stop automatic navigation" (section
   2.2): past ``max_consecutive`` replacements the isolator raises an alarm, requests a stop of
   automatic navigation, and restarts the window on the receiver's own data (no lock-in,
   shared/FINDINGS.md), latching the alarm until ``recover_epochs`` fixes in a row pass.

Beyond the paper, for real data (each is a parameter, and the paper preset turns it off):

* ``predictor = "doppler"`` models, per axis, the fix minus the displacement integrated from the
  receiver's Doppler speed and course (RMC/VTG). That series is the slowly varying DGPS error,
  which GM(1,1) predicts to millimetres, so the residual no longer carries the vehicle's
  manoeuvres (a 1 Hz headland turn costs GM(1,1) 0.33 m on raw positions; FINDINGS). Once a
  fix passes after two or more replacements in a row, their predictions in the window are
  replaced by the values between the fixes on either side (a self-fed extrapolation is not
  the receiver's level; item 3 is the paper's, kept with its raw predictor).
* ``gate_sigmas > 0`` sets the grey gate from the residual spread actually observed (an
  exponentially weighted RMS of accepted residuals) rather than from the absolute σ: real DGPS
  error is correlated in time, so the residual is a few centimetres, not 1.55 σ.
* ``gate_axes = "horizontal"`` tests the horizontal residual's length, so a jump is caught
  whatever its direction; the vertical residual has its own gate.
* quality screens (satellites, HDOP) from GGA; R from GST where the receiver sends it.
* ``drift_test`` (issue 13, :mod:`fdi.drift`): the fix against its own Doppler displacement
  over horizons in seconds (1, 3, 10, 30 s), a GLR with σ calibrated once per receiver and
  never learned; it catches slow ramps and frozen receivers. A receiver that repeats its whole
  fix bit for bit for ``stale_s`` (position, speed and course) is frozen, whatever its speed;
  sooner when its position repeats while its own speed says it moved ``stale_move_m`` and
  ``stale_move_quanta`` of its coordinate quanta, or
  when it repeats its whole fix more often in a row than its own history makes likely
  (``stale_p``: a receiver whose fix changes every epoch is frozen at its second repeat; one
  that repeats often, a static hold at stops, is given up to ``stale_s``). Between
  ``drift_warn_sigmas`` and ``drift_sigmas`` the fix is flagged (a warning) but passed on as it
  is, and kept out of the drift test's references and the gates' learning: a slow fault is
  reported sooner without holding the old track on weaker evidence.
* never worse than doing nothing: an abrupt step *back* to an older trusted level the track
  had left (the end of a fault that was missed or taken as the receiver's level) passes the
  receiver's fix on, flagged, instead of the old track (``step_back``).
* isolation after a level change (:mod:`fdi.level`): when the drift test fires, a frozen fix
  is seen, or the fixes stay off after ``max_consecutive`` replacements, the isolator holds the
  old track (the last trusted Doppler-free value moved by the Doppler) and decides with the
  Doppler evidence over a short fixed lag which side is right, instead of extrapolating the
  old track for a number of epochs; replaced fixes enter the Kalman filter with R multiplied
  by ``replaced_r_factor`` (never at full weight) and not at all during a hold.

Units: metres, seconds; positions are local east/north/up (:mod:`fdi.geodesy`).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Literal

from fdi.chi2 import threshold
from fdi.coast import ctrv, turn_fit, within
from fdi.drift import LEVEL_KEEP_S, DriftResult, DriftTest, sigma_at
from fdi.fielddoc import documented
from fdi.grey import gm11_predict_shifted_enu
from fdi.kalman import GpsKalman
from fdi.level import (
    BACK_AT_OLD_FRAC,
    OLD_LEVEL_MIN_AGE_S,
    SIDE_HORIZON_S,
    HoldParams,
    HoldStep,
    LevelHold,
)
from fdi.rover_evidence import (
    TIME_RESET_EPOCHS as TIME_RESET_EPOCHS,
)
from fdi.rover_evidence import (
    Accepted,
    Action,
    Decision,
    Evidence,
    FixInput,
    FixSignature,
    LastStep,
    LiveFix,
    Mode,
    PassedReversal,
    RawFix,
    Source,
    Stats,
    Step,
    StepEndWatch,
)
from fdi.rover_rules import (
    FAULT_RULES,
    HOLD_RULES,
    RESTARTS,
    SCREENS,
    r_accept,
    r_alarm,
    r_drift_warn,
    r_drift_watch,
    r_hold_no_doppler,
    r_step_end_passing,
    r_zones,
)
from fdi.three_zone import Action as ZoneAction
from fdi.three_zone import ThreeZoneGate, ThreeZoneParams, Zone

# Epochs over which the receiver must agree with its own Doppler to be restarted on after an
# alarm: short, so a real step is accepted again soon, long enough to expose a frozen fix.
RAW_HORIZON = 3
# The Doppler residual's prior variance (doppler_s0_m over the window's span) weighs as this
# many residuals: its running mean learns the receiver's own within tens of epochs, then an
# exponential average over gate_tau_epochs follows it.
DOPPLER_PRIOR_N = 5
# Epochs (beyond hold_exit_s) a step back to the level before a remembered step must stay
# before the receiver is restarted on: more than a 2-epoch burst that happens to reverse it.
STEP_END_EPOCHS = 3
# No slow fault moves the Doppler-free value faster than this (m/s; the ramps of issue 13 run
# at 0.02-0.3 m/s): a drift fault whose value stepped since the previous epoch by more than
# this rate plus hold_exit_sigmas of the drift σ over the interval is a step, and its hold an
# abrupt one (a multipath step's end that only the drift and Doppler tests flagged, held as a
# slow fault, kept 20 s of track and alarm; docs/evaluation.md).
SLOW_MAX_MPS = 1.0
# A step is the reverse of a remembered one within REVERSAL_FRAC x its size, or within this
# many σ of the difference of two one-epoch steps (√2 x the calibrated drift σ at its shortest
# horizon) up to REVERSAL_MAX_FRAC x its size, whichever is wider: for small steps the epoch's
# noise is more than REVERSAL_FRAC x the step (fdi/rover_evidence.py, Step.reversed_by).
REVERSAL_FLOOR_SIGMAS = 3.0
# A fix is back before a remembered step when the track is within STEPPED_LEVEL_FRAC of the
# step of the stepped level, and the fix at least STEP_AWAY_FRAC x the step away from the
# track and within BACK_NEARER_FRAC of that distance of the level before (_step_back_to).
STEPPED_LEVEL_FRAC = 0.5
STEP_AWAY_FRAC = 0.6
BACK_NEARER_FRAC = 0.5
_new = tuple.__new__
# A GST σ at or above this is no error estimate (its square would not be a finite float): the
# configured σ is used instead (`RoverIsolator._r`).
_SD_MAX = math.sqrt(1.7976931348623157e308)


# Bounds of the detector's parameters, in which it works as documented: the loader
# (drivers/configload.py) checks a file against them and the MAVLink parameter table
# (FDI_ALPHA ...) is built from them, so a ground station cannot set what a file may not hold.
# "off": the documented value that turns a test off, accepted beside the range.
_ALPHA = {"ge": 1e-15, "le": 0.5}  # a significance level: its χ² threshold finite, at most 1/2
_SIGMAS = {"ge": 1.0, "le": 100.0}  # a test's width in σ: under 1 σ it flags a third of clean fixes
_SIGMA_M = {"ge": 0.001, "le": 100.0}  # a noise σ or gate in metres: at least 1 mm
_SPAN_S = {"off": 0.0, "ge": 0.01, "le": 3600.0}  # a time span, 0: off / at once
_LONG_S = {"off": 0.0, "ge": 1.0, "le": 86400.0}  # a calibration time, 0: none
_LAG_S = {"off": 0.0, "ge": 0.001, "le": 10.0}  # the Doppler's lag (fdi-bridge calibrate: 1 ms)
_COUNT = {"ge": 1, "le": 1000}  # a count of epochs

# Unit and doc of each field (docs/reference/config.md is generated from them), attached by
# @documented below so that each field's own line stays as it is.
_DOC: dict[str, dict[str, str]] = {
    "strategy": {"doc": "grey: the chi-square + GM(1,1) grey tests (Zhou & Zhang); three_zone: "
                 "Cai & Shao's per-axis zones on the Kalman innovation; combined: both"},
    "alpha": {"unit": "-", "doc": "significance level of the residual chi-square test "
              "(section 1; 3 degrees of freedom)"},
    "chi2_enabled": {"doc": "run the residual chi-square test"},
    "sigma_m": {"unit": "m", "doc": "horizontal noise σ per axis: R = σ² when the receiver "
                "sends no GST (or use_gst = false)"},
    "sigma_up_m": {"unit": "m", "doc": "vertical noise σ: R's up term when there is no GST"},
    "use_gst": {"doc": "take R from the receiver's GST σ when it sends them"},
    "q_accel": {"unit": "m^2/s^3", "doc": "the Kalman filter's process noise: white-"
                "acceleration spectral density"},
    "window": {"unit": "epochs", "doc": "GM(1,1) window: the accepted fixes the grey model "
               "is fitted on (section 2)"},
    "predictor": {"doc": "raw: GM(1,1) on the positions; doppler: GM(1,1) on the Doppler-free "
                  "positions, moved by the receiver's Doppler displacement"},
    "shift_m": {"unit": "m", "doc": "offset added to each axis of the window so that GM(1,1) "
                "sees positive values (the window's minimum becomes this)"},
    "gate_m": {"unit": "m", "doc": "grey test's horizontal gate (fixed; the floor when "
               "gate_sigmas > 0)"},
    "gate_up_m": {"unit": "m", "doc": "grey test's vertical gate (fixed; the floor when "
                  "gate_sigmas > 0)"},
    "gate_axes": {"doc": "per_axis: east and north gated apart; horizontal: the horizontal "
                  "distance against gate_m"},
    "gate_sigmas": {"unit": "σ", "doc": "adaptive gate: this many σ of the grey residual "
                    "learned on accepted fixes, at least gate_m (0: the fixed gate)"},
    "gate_tau_epochs": {"unit": "epochs", "doc": "time constant of the adaptive gate's "
                        "running residual variance (EWMA weight 1/tau)"},
    "gate_sigma0_m": {"unit": "m", "doc": "the adaptive gate's prior residual σ "
                      "(horizontal; twice it up)"},
    "test_up": {"doc": "the grey test also gates the vertical residual"},
    "doppler_test": {"doc": "the Doppler consistency test: the fix against the accepted fix of "
                     "window epochs ago moved by the Doppler displacement since"},
    "doppler_sigmas": {"unit": "σ", "doc": "Doppler test's width: this many σ of its residual "
                       "RMS on accepted fixes, at least doppler_floor_m"},
    "doppler_floor_m": {"unit": "m", "doc": "Doppler test's smallest gate"},
    "doppler_s0_m": {"unit": "m", "doc": "Doppler residual's prior σ per axis over a 1 s span "
                     "(scaled by sqrt of the window's span), then learned"},
    "max_coast_s": {"unit": "s", "doc": "at an alarm, coast on the Doppler at most this long "
                    "when the receiver disagrees with its own Doppler (0: no coast)"},
    "drift_test": {"doc": "the slow-fault test on the Doppler-free value (fdi/drift.py); needs "
                   "predictor = doppler and strategy = grey"},
    "drift_horizons_s": {"unit": "s", "doc": "horizons over which the Doppler-free value's "
                         "change is tested (ascending)"},
    "drift_sigma_m": {"unit": "m", "doc": "per-axis σ of the Doppler-free value's change over "
                      "each horizon (until the calibration at start replaces them)"},
    "drift_calibrate_s": {"unit": "s", "doc": "calibrate drift_sigma_m once on this many "
                          "seconds of trusted fixes (0: as configured, e.g. by fdi-bridge "
                          "calibrate)"},
    "drift_precal_s": {"unit": "s", "doc": "a provisional calibration after this long "
                       "(0: none), widened by drift_prefactor, until the calibration proper"},
    "drift_prefactor": {"unit": "-", "doc": "factor on the provisional calibration's σ; "
                        "shrinks as 1 + (f - 1) sqrt(drift_precal_s / elapsed)"},
    "drift_floor_frac": {"unit": "-", "doc": "the calibration never goes below this fraction "
                         "of drift_sigma_m (0: no floor)"},
    "drift_cal_k": {"unit": "-", "doc": "the calibration's own uncertainty: each σ_H times "
                    "1 + k / sqrt(n_H), n_H its independent differences (0: none)"},
    "drift_cal_min_h": {"unit": "s", "doc": "the horizon H at least this in drift_cal_k's "
                        "count of independent differences"},
    "drift_sigmas": {"unit": "σ", "doc": "drift test's threshold on its statistic (the "
                     "largest over the horizons)"},
    "drift_warn_sigmas": {"unit": "σ", "doc": "flag (warn) from this drift statistic on, the "
                          "fix passed on as it is (0: off)"},
    "ramp_window_s": {"unit": "s", "doc": "the one horizon whose drift statistic alone flags "
                      "a ramp (drift_watch; 0: off)"},
    "ramp_sigmas": {"unit": "σ", "doc": "threshold of that horizon's statistic (0: off)"},
    "drift_lag_s": {"unit": "s", "doc": "the receiver's Doppler lag behind its position, "
                    "taken out of the Doppler-free value (fdi-bridge calibrate measures it)"},
    "drift_lag_sd_s": {"unit": "s", "doc": "σ of that lag (its uncertainty, in the drift and "
                       "Doppler tests' widths)"},
    "stale_s": {"unit": "s", "doc": "a whole fix repeated this long is frozen"},
    "stale_move_m": {"unit": "m", "doc": "a position repeated while the receiver's own speed "
                     "says it moved this far is frozen (0: off)"},
    "stale_move_quanta": {"unit": "-", "doc": "... and by at least this many of its coordinate "
                          "quanta, learned from the fixes (0: stale_move_m alone)"},
    "stale_p": {"unit": "-", "doc": "frozen after n repeats in a row whose chance p^n, p the "
                "receiver's learned repeat rate, is at most this (0: off)"},
    "hold_exit_sigmas": {"unit": "σ", "doc": "a hold ends when the fixes agree with the old "
                         "track within this many drift σ (fdi/level.py)"},
    "hold_side_sigmas": {"unit": "σ", "doc": "an older level is the other side only when the "
                         "old track is this many σ(30 s) off it (fdi/level.py)"},
    "hold_exit_s": {"unit": "s", "doc": "the hold's short fixed lag: evidence for the new "
                    "fixes must last this long"},
    "hold_level_s": {"unit": "s", "doc": "a slow hold's new level: fixes that stepped there by "
                     "less than half the distance sit there this long (0: hold_exit_s)"},
    "hold_output_s": {"unit": "s", "doc": "the held old track is passed on (flagged) this "
                      "long, then the alarm with no output"},
    "hold_max_s": {"unit": "s", "doc": "after this long the receiver's level is accepted "
                   "again under the alarm (no lock-in)"},
    "step_pair_s": {"unit": "s", "doc": "an abrupt step the track accepted is remembered this "
                    "long: fixes stepping back to the level before it end it (0: off)"},
    "replaced_r_factor": {"unit": "-", "doc": "a replaced fix (its prediction) updates the "
                          "Kalman filter with R times this"},
    "grey_fed_sigmas": {"unit": "σ", "doc": "after two or more replacements a fix only the "
                        "grey test flags, drift statistic at most this, is passed on (0: off)"},
    "max_consecutive": {"unit": "epochs", "doc": "replacements in a row before the alarm "
                        "(section 2.2)"},
    "recover_epochs": {"unit": "epochs", "doc": "good fixes in a row that end an alarm"},
    "three_zone": {"doc": "the three_zone and combined strategies' parameters"},
    "min_sats": {"unit": "satellites", "doc": "quality screen: a fix with fewer satellites is "
                 "not trusted (0: off)"},
    "max_hdop": {"unit": "-", "doc": "quality screen: a fix with a larger HDOP is not trusted "
                 "(0: off)"},
    "max_gap_s": {"unit": "s", "doc": "a gap between fixes longer than this restarts the "
                  "filter (a clock step back beyond it: a time reset)"},
    "frozen_turn_s": {"unit": "s", "doc": "a frozen receiver's coast (R25, fdi/coast.py): its "
                      "speed and turn rate fitted to the live velocities of this long before "
                      "it froze; longer: less noise, but a turn's start is seen later"},
    "frozen_accel_mps2": {"unit": "m/s^2", "doc": "the largest change of the vehicle's speed "
                          "or turn the coast does not model (C3: ½ a t² + a (drift_lag_s + "
                          "drift_lag_sd_s) t is its bound); larger: a shorter coast, never "
                          "further off"},
    "frozen_coast_m": {"unit": "m", "doc": "the coast is passed on while its bound is within "
                       "this, then nothing under the alarm (C3); larger: a longer coast, "
                       "further off (0: no coast, nothing while the receiver repeats)"},
}



@documented(_DOC)
@dataclass(frozen=True)
class RoverDetectorParams:
    """Detector parameters (the ``[rover.detector]`` config table)."""

    strategy: Literal["grey", "three_zone", "combined"] = "grey"
    # Section 1: residual chi-square test.
    alpha: float = field(default=0.05, metadata=_ALPHA)
    chi2_enabled: bool = True
    sigma_m: float = field(default=0.35, metadata=_SIGMA_M)  # R = σ² when no GST
    sigma_up_m: float = field(default=0.7, metadata=_SIGMA_M)
    use_gst: bool = True
    q_accel: float = field(default=0.5, metadata={"ge": 1e-6, "le": 1e4})  # m²/s³
    # Section 2: GM(1,1) grey prediction.
    window: int = field(default=12, metadata={"ge": 4, "le": 50})
    predictor: Literal["raw", "doppler"] = "doppler"
    shift_m: float = field(default=100.0, metadata={"ge": 1.0, "le": 1e5})
    # fixed gate (the floor if adaptive)
    gate_m: float = field(default=0.7, metadata={"ge": 0.01, "le": 1000.0})
    gate_up_m: float = field(default=1.5, metadata={"ge": 0.01, "le": 1000.0})
    gate_axes: Literal["per_axis", "horizontal"] = "horizontal"
    gate_sigmas: float = field(default=6.0, metadata={**_SIGMAS, "off": 0.0})  # 0: fixed gate
    gate_tau_epochs: float = field(default=50.0, metadata={"ge": 1.0, "le": 1e4})
    gate_sigma0_m: float = field(default=0.1, metadata=_SIGMA_M)
    test_up: bool = True
    # Doppler consistency (beyond the paper): the fix must match the accepted fix of `window`
    # epochs ago moved by the receiver's Doppler displacement since, within
    # max(doppler_floor_m, doppler_sigmas × the RMS of that residual on accepted fixes). A
    # frozen position fails it within a few epochs (GM(1,1) would learn it as a trend), while a
    # receiver's lag between Doppler and position does not accumulate. At an alarm it also
    # decides whether the receiver agrees with its own Doppler over the last RAW_HORIZON
    # epochs: then restart on it (no lock-in), else coast on Doppler, up to max_coast_s.
    doppler_test: bool = True
    doppler_sigmas: float = field(default=6.0, metadata=_SIGMAS)
    doppler_floor_m: float = field(default=0.5, metadata={"ge": 0.01, "le": 1000.0})
    # The residual's prior σ per axis over a 1 s span, x sqrt(the window's span in s) at the
    # first fix interval (a random walk), then learned (weighing as DOPPLER_PRIOR_N residuals).
    doppler_s0_m: float = field(default=0.2, metadata=_SIGMA_M)
    max_coast_s: float = field(default=30.0, metadata=_SPAN_S)
    # Slow faults and level changes (issue 13, fdi/drift.py and fdi/level.py; beyond the
    # paper). Needs predictor = "doppler" and strategy = "grey". drift_sigma_m: the per-axis
    # σ of the Doppler-free value's change over each horizon: with drift_calibrate_s > 0 the
    # wide value used until the receiver is calibrated, once, on its first drift_calibrate_s
    # seconds of trusted fixes; with 0, as configured (a receiver calibrated offline:
    # fdi-bridge calibrate, firmware_host/rover/calibration.py).
    drift_test: bool = True
    drift_horizons_s: tuple[float, ...] = field(default=(1.0, 3.0, 10.0, 30.0, 100.0),
                                             metadata={"ge": 0.1, "le": 3600.0})
    drift_sigma_m: tuple[float, ...] = field(default=(0.3, 0.4, 0.6, 0.9, 1.4),
                                          metadata={"ge": 1e-4, "le": 100.0})
    drift_calibrate_s: float = field(default=300.0, metadata=_LONG_S)  # 0: as configured
    # A provisional calibration after drift_precal_s (0: none): the same robust estimate x
    # drift_prefactor, never wider than drift_sigma_m, until the calibration proper; estimated
    # again every 10 s, the factor shrinking as 1 + (f - 1) x sqrt(drift_precal_s / elapsed).
    drift_precal_s: float = field(default=120.0, metadata=_LONG_S)
    drift_prefactor: float = field(default=2.0, metadata={"ge": 1.0, "le": 100.0})
    # The calibration at start never goes below this fraction of drift_sigma_m: 0.2 for the
    # wide defaults; fdi-bridge calibrate writes 1/1.5, so a day's calibration can widen a
    # receiver's offline σ but not narrow them (it sees only the fixes it trusts, and from
    # the offline σ it trusts fewer: multipath 10 Hz seed 202, a false hold at 860 s).
    drift_floor_frac: float = field(default=0.2, metadata={"off": 0.0, "ge": 0.01, "le": 1.0})
    # The calibration's own uncertainty: each σ_H x (1 + drift_cal_k / sqrt(n_H)), n_H
    # the independent H-long differences the calibration saw (2 axes), H >= drift_cal_min_h.
    # 1.5 is about z = 1.29 (one-sided 10 %) standard errors of a median-absolute-deviation σ
    # from n Gaussian differences (1.166 / sqrt(n)): fdi/drift.py (D8). From every horizon on
    # (1 s): an underestimated σ(3 s), from about 200 differences, made 5σ false holds
    # (sim rover-harness, ten fresh seeds: worst run 1.89 % -> 0.10 % of clean epochs flagged),
    # at the price of some 0.1 m/s ramps found later than 10 s (gm 84 -> 74 of 159).
    drift_cal_k: float = field(default=1.5, metadata={"off": 0.0, "ge": 0.01, "le": 100.0})
    drift_cal_min_h: float = field(default=1.0, metadata=_LONG_S)
    drift_sigmas: float = field(default=5.0, metadata=_SIGMAS)
    # Flag (warn) from this statistic on, the fix still passed on as it is (0: off).
    drift_warn_sigmas: float = field(default=4.5, metadata={**_SIGMAS, "off": 0.0})
    # Flagged (reason drift_watch, the fix otherwise as if clean) from the drift statistic of
    # the ramp_window_s horizon alone over ramp_sigmas (0: off). The maximum over five horizons
    # at 4.5 σ flags ~0 clean epochs; one horizon at 4 σ is a budget of its own for the window
    # a ramp must be found in (10 s): tools/ramp_bound.py shows that its clean 99.9 %
    # (0.6-1.2 m) is under the 1 m a 0.1 m/s ramp makes there. (MAVLink parameters
    # FDI_RAMP_WINDOW and FDI_RAMP_SIGMAS.)
    ramp_window_s: float = field(default=10.0, metadata=_SPAN_S)
    ramp_sigmas: float = field(default=4.0, metadata={**_SIGMAS, "off": 0.0})
    # Doppler behind position
    drift_lag_s: float = field(default=0.15, metadata=_LAG_S)
    drift_lag_sd_s: float = field(default=0.15, metadata=_LAG_S)
    # whole fix repeated this long
    stale_s: float = field(default=2.0, metadata={"ge": 0.1, "le": 3600.0})
    # ... or its position repeated while its own speed says it moved this far (0: off);
    # beyond a coordinate quantum
    stale_move_m: float = field(default=0.15, metadata={"off": 0.0, "ge": 0.001, "le": 1000.0})
    # ... and at least this many of its coordinate quanta (the larger axis; learned from the
    # fixes, the rule waits for it; 0: stale_move_m alone)
    stale_move_quanta: float = field(default=1.6, metadata={"off": 0.0, "ge": 0.1, "le": 1000.0})
    # ... or after n repeats in a row where this receiver's chance of them, p^n, is at most
    # stale_p; p is learned from all its pairs of fixes: (repeats + 1) / (pairs + 2). A
    # receiver whose fix changes every epoch is found frozen at its second repeat; one that
    # repeats often (a static hold at stops) is given up to stale_s (0 = off).
    stale_p: float = field(default=1e-4, metadata={**_ALPHA, "off": 0.0})
    hold_exit_sigmas: float = field(default=3.0, metadata=_SIGMAS)
    hold_side_sigmas: float = field(default=2.0, metadata=_SIGMAS)
    hold_exit_s: float = field(default=1.0, metadata=_SPAN_S)  # the short fixed lag
    # A slow hold's (a drift) "new_level": fixes that stepped to an older level by less than
    # half the old track's distance from it sit there this long (0: as an abrupt one's,
    # hold_exit_s; with it, fixes that drifted there never end the hold: fdi/level.py).
    hold_level_s: float = field(default=10.0, metadata=_SPAN_S)
    hold_output_s: float = field(default=10.0, metadata=_SPAN_S)  # then alarm, no output
    # then the receiver again
    hold_max_s: float = field(default=120.0, metadata={"ge": 1.0, "le": 86400.0})
    # An abrupt step the track went on to accept (a multipath step) is remembered this long:
    # the fixes stepping back to the level before it end it (0: off).
    step_pair_s: float = field(default=60.0, metadata=_SPAN_S)
    replaced_r_factor: float = field(default=100.0, metadata={"ge": 1.0, "le": 1e6})
    # After two or more replacements, a fix that only the grey test flags (the chi-square,
    # Doppler and drift tests pass, the drift statistic at most this many σ) is passed on
    # (flagged): the grey window has fed on its own predictions (0: off).
    grey_fed_sigmas: float = field(default=2.0, metadata={**_SIGMAS, "off": 0.0})
    # Isolation and alarm.
    max_consecutive: int = field(default=5, metadata=_COUNT)
    recover_epochs: int = field(default=5, metadata=_COUNT)
    # Strategies three_zone and combined (Cai & Shao): per-axis zones on the Kalman innovation.
    three_zone: ThreeZoneParams = field(default_factory=ThreeZoneParams)
    # Quality screens (0 disables).
    min_sats: int = field(default=4, metadata={"ge": 0, "le": 64})  # 0: off
    max_hdop: float = field(default=0.0, metadata={"ge": 0.5, "le": 99.0, "off": 0.0})
    # Time.
    max_gap_s: float = field(default=5.0, metadata={"ge": 0.05, "le": 3600.0})
    # A frozen receiver's coast (R25, fdi/coast.py; issue 42): while it repeats its whole fix,
    # its speed and course are void, so the old track is not moved by them: the vehicle is
    # carried on from the last live fix at the speed and turn rate fitted to the live
    # velocities of the last frozen_turn_s (C1-C2), passed on while its bound, ½ a t² + a
    # (drift_lag_s + drift_lag_sd_s) t with a = frozen_accel_mps2 (the last live speed is
    # the vehicle's of the Doppler's lag before), is within frozen_coast_m (C3), then nothing
    # under the alarm. The defaults: a tractor's speed or turn changes by at most 0.5 m/s²
    # (a stop from 2 m/s in 4 s; a turn's entry at 2 m/s into a 8 m radius), and 0.75 m of
    # the 1 m a coast may add to the receiver's error when it froze (issue 42), the rest for
    # the last live speed's and course's noise: a 1.46 s coast.
    frozen_turn_s: float = field(default=2.0, metadata={"ge": 0.1, "le": 60.0})
    frozen_accel_mps2: float = field(default=0.5, metadata={"ge": 0.01, "le": 100.0})
    frozen_coast_m: float = field(default=0.75, metadata={"off": 0.0, "ge": 0.01,
                                                            "le": 1000.0})

    @property
    def runs_drift_test(self) -> bool:
        """The drift test runs: it needs the Doppler predictor and the grey strategy."""
        return self.drift_test and self.predictor == "doppler" and self.strategy == "grey"


class RoverIsolator:
    """Feed :class:`FixInput` epochs in time order; get a :class:`Decision` for each."""

    def __init__(self, params: RoverDetectorParams) -> None:
        self.p = params
        self.T_d = threshold(params.alpha, 3)  # eq. (6), m = 3
        self.kf = GpsKalman(q=params.q_accel)
        n = params.window
        self._win: deque[tuple[float, float, float]] = deque(maxlen=n)  # Doppler-free values
        self._fed = 0  # how many of the window's newest values are its own predictions
        self._disp = [0.0, 0.0, 0.0]  # Doppler-integrated displacement
        self._last_v: tuple[float, float] | None = None
        self._last_t: float | None = None
        # A jump back of the clock (see _step): the fixes that followed it, and the last's time
        self._reset_run = 0
        self._reset_t: float | None = None
        self._last_up = 0.0
        self._up_seen = False
        self._consec = 0
        self._stepped_back = False  # this run of replacements began with a step back
        self._back_t: float | None = None  # ... to the older level of this time (or None)
        # Accepted fixes (east, north) with the Doppler displacement at each, last `window`.
        # ... and the Doppler velocity at each (for the lag's share, with the drift test).
        self._acc_hist: deque[Accepted] = deque(maxlen=n)
        # The receiver's own recent fixes with the Doppler displacement at each: is it
        # consistent with itself over the window (a frozen or wandering fix is not)?
        self._raw_hist: deque[RawFix] = deque(maxlen=RAW_HORIZON)
        self._coast_since: float | None = None
        # The Doppler residual's variance per axis: its prior scaled to the window's span
        # once the fix interval is known (_set_inc_prior), then learned from accepted fixes.
        self._var_inc = params.doppler_s0_m**2
        self._inc_prior_set = False
        self._n_inc = 0  # residuals learned: the prior weighs as DOPPLER_PRIOR_N of them
        self._alarm = False
        self._good_run = 0
        self._var_h = params.gate_sigma0_m**2
        self._var_u = (2.0 * params.gate_sigma0_m) ** 2
        self._ewma = 1.0 / params.gate_tau_epochs
        self._zone_gates = (
            [ThreeZoneGate(params.three_zone, "three_zone") for _ in range(3)]
            if params.strategy != "grey"
            else []
        )
        self._drift: DriftTest | None = None
        self._hold_p: HoldParams | None = None
        self._make_drift(params)
        self._hold: LevelHold | None = None
        self._hold_up = 0.0
        self._hold_reason = ""
        self._run_t0 = 0.0  # time of the first replacement of the current run
        self._prev_sig: FixSignature | None = None
        self._prev_t = 0.0
        self._stale_since: float | None = None  # the position repeated since
        self._stale_run = 0  # repeats in a row of the whole fix, this epoch's included
        self._whole_since = 0.0  # ... since
        # Pairs of consecutive fixes, and how many of them repeated the whole fix: this
        # receiver's chance of a repeat (_stale_check).
        self._pairs = 0
        self._repeats = 0
        # Abrupt steps seen at the start of a run of faults, newest last; the step back being
        # confirmed; and a remembered step reversed by fixes that pass the tests.
        self._steps: list[Step] = []
        self._end_watch: StepEndWatch | None = None
        self._passed: PassedReversal | None = None
        self._prev_b: tuple[float, float] | None = None  # the last epoch's b ...
        self._prev_bt = 0.0  # ... and its time
        self._last_step: LastStep | None = None  # the last step of b
        # The coordinates' quantum per axis: the smallest non-zero change between consecutive
        # fixes (fdi/drift.py, D6); inf until seen.
        self._last_e = self._last_n = math.nan
        self._quant = [math.inf, math.inf]
        # The live fixes with a Doppler (their whole fix not a repeat) of the last
        # frozen_turn_s, newest last: where a frozen receiver's coast starts from and the
        # velocities its turn is fitted to (R25, fdi/coast.py).
        self._live_v: deque[LiveFix] = deque()
        self._acc_t: float | None = None  # the time of the last fix passed on as it was

    @staticmethod
    def _hold_params(p: RoverDetectorParams, sigma_m: tuple[float, ...]) -> HoldParams:
        return HoldParams(p.drift_horizons_s, sigma_m, p.drift_lag_s, p.drift_lag_sd_s,
                          p.hold_exit_sigmas, p.hold_side_sigmas, p.hold_exit_s,
                          p.hold_output_s, p.hold_max_s, p.hold_level_s)

    def _make_drift(self, p: RoverDetectorParams) -> None:
        if p.runs_drift_test:
            self._drift = DriftTest(p.drift_horizons_s, p.drift_sigma_m, p.drift_lag_sd_s,
                                    p.drift_calibrate_s, floor_frac=p.drift_floor_frac,
                                    watch_s=p.ramp_window_s,
                                    precal_s=p.drift_precal_s,
                                    precal_factor=p.drift_prefactor,
                                    margin=p.drift_cal_k,
                                    margin_min_h=p.drift_cal_min_h)
            self._hold_p = self._hold_params(p, p.drift_sigma_m)
        else:
            self._drift = None
            self._hold_p = None

    # -------------------------------------------------------------- helpers

    def _restart(self, z: tuple[float, float, float], r: tuple[float, float, float],
                 keep_levels: bool = False) -> None:
        """Restart the window, the filter and the tests on ``z``; ``keep_levels``: the
        Doppler chain is intact, so the drift test's long-term levels are kept (rebased)."""
        if self._drift is not None:
            if keep_levels:
                de, dn = self._disp[0], self._disp[1]
                self._drift.rebase(de, dn)
                self._drift.reset_short()
                for st in self._steps:
                    st.b0e += de
                    st.b0n += dn
            else:
                self._drift.reset()
                self._steps.clear()
        self._end_watch = None
        self._prev_b = None  # the displacement's origin moves
        self._last_step = None
        self._forget_live()
        self._acc_hist.clear()
        lv = self._last_v or (0.0, 0.0)
        self._acc_hist.append(Accepted(z[0], z[1], 0.0, 0.0, lv[0], lv[1]))
        self._coast_since = None
        self._window_clear()
        self._disp = [0.0, 0.0, 0.0]
        self._win.append(z)
        self.kf.reset(z, r)
        for gate in self._zone_gates:
            gate.reset()
        self._consec = 0
        self._stepped_back = False
        self._hold = None

    def _r(self, fix: FixInput) -> tuple[float, float, float]:
        sd = fix.sd_enu_m if self.p.use_gst else None
        # A σ whose square is not a finite float (or NaN) is no error estimate: the configured
        # σ then (the codec refuses such values; this keeps any caller's from overflowing).
        if sd is not None and sd[0] < _SD_MAX and sd[1] < _SD_MAX and sd[2] < _SD_MAX:
            return (max(sd[0], 0.01) ** 2, max(sd[1], 0.01) ** 2, max(sd[2], 0.01) ** 2)
        s, su = self.p.sigma_m, self.p.sigma_up_m
        return (s * s, s * s, su * su)

    def _velocity(self, fix: FixInput) -> tuple[float, float] | None:
        if self.p.predictor != "doppler" or fix.speed_mps is None:
            return None
        if fix.course_deg is None:
            return (0.0, 0.0) if fix.speed_mps < 0.05 else None
        if not math.isfinite(fix.course_deg):  # no direction (the codec refuses it)
            return None
        c = math.radians(fix.course_deg)
        return (fix.speed_mps * math.sin(c), fix.speed_mps * math.cos(c))

    def _predict(self) -> tuple[float, float, float] | None:
        """Grey prediction of the Doppler-free value at this epoch (per axis)."""
        w = self._win
        if self.p.predictor == "raw":
            if len(w) < self.p.window:
                return None
        elif not w:
            return None
        if len(w) < 4:
            return w[-1]
        return gm11_predict_shifted_enu(w, self.p.shift_m)  # per axis

    def _set_inc_prior(self, dt: float) -> None:
        """The Doppler residual's prior variance at the first fix interval ``dt``:
        ``doppler_s0_m`` is its σ per axis over a 1 s span, and the residual spans the window's
        (window - 1) x dt seconds. The Doppler's integrated noise is a random walk, so the
        variance grows with the span: at 1 Hz a 0.2 m prior was half a clean coarse
        receiver's 11 s residual and flagged its first 20 s (docs/evaluation.md, sixth pass);
        a span under 1 s keeps the 1 s value."""
        span = (self.p.window - 1) * dt
        self._var_inc = self.p.doppler_s0_m**2 * max(1.0, span)
        self._inc_prior_set = True

    def _doppler_gate(self) -> float:
        p = self.p
        return max(p.doppler_floor_m, p.doppler_sigmas * math.sqrt(self._var_inc))

    def _gates(self) -> tuple[float, float]:
        p = self.p
        if p.gate_sigmas <= 0.0:
            return p.gate_m, p.gate_up_m
        return (
            max(p.gate_m, p.gate_sigmas * math.sqrt(self._var_h)),
            max(p.gate_up_m, p.gate_sigmas * math.sqrt(self._var_u)),
        )

    # -------------------------------------------------------------- the step

    @property
    def mode(self) -> Mode:
        """What the isolator is doing, from its memory (the alarm latches apart from it)."""
        if self._hold is not None:
            return Mode.HOLD
        if self._coast_since is not None:
            return Mode.COAST
        if self._end_watch is not None:
            return Mode.STEP_END
        if self._stepped_back:
            return Mode.STEP_BACK
        return Mode.REPLACE if self._consec else Mode.TRACK

    def step(self, fix: FixInput) -> Decision:
        last_up = self._last_up
        d = self._step(fix)
        if d.action != "accept":
            # The height a later 2D fix holds is the last one passed on, not a fix the tests
            # refused (one 2 400 km off is 460 km below the frame's plane: a 2D fix after it
            # took that height and the grey prediction sent the output to the antipode).
            self._last_up = last_up
        return d

    def _step(self, fix: FixInput) -> Decision:
        """One epoch: the time screens (R1-R3), the evidence (once), then the rules of
        :mod:`fdi.rover_rules` in their order; the first that answers decides."""
        gate_h, gate_u = self._gates()
        t = Stats(gate_h, gate_u, self._doppler_gate())
        dt = None if self._last_t is None else fix.t_s - self._last_t
        if fix.enu is None or (dt is not None and dt <= 0.0):  # R1-R3 can only hold then
            for screen in SCREENS:
                dec = screen(self, fix, dt, t)
                if dec is not None:
                    return dec
        self._reset_run = 0
        self._reset_t = None
        ev = self._fix_evidence(fix, dt, t)
        if ev.restart:  # R4-R5 can only hold then
            for restart in RESTARTS:
                dec = restart(self, ev)
                if dec is not None:
                    return dec
        self._doppler_evidence(ev)
        if self._hold is not None:
            dec = r_hold_no_doppler(self, ev)
            if dec is not None:
                return dec
            self.kf.predict(ev.dt)
            return self._hold_step(ev)
        self._test_evidence(ev)
        dec = r_zones(self, ev)
        if dec is not None:
            return dec
        if not ev.any_fault:
            return self._pass_clean(ev)
        self._find(ev)
        for rule in FAULT_RULES:
            dec = rule(self, ev)
            if dec is not None:
                return dec
        return r_alarm(self, ev)

    # -------------------------------------------------------------- the evidence

    def _fix_evidence(self, fix: FixInput, dt: float | None, t: Stats) -> Evidence:
        """The fix itself: its variance, height, Doppler velocity, the frozen test and the
        quality screens; and whether the filter restarts on it."""
        p = self.p
        if (not self._inc_prior_set and p.doppler_test and dt is not None
                and 0.0 < dt <= p.max_gap_s):
            self._set_inc_prior(dt)
            t.doppler_gate = self._doppler_gate()
        z = fix.enu
        assert z is not None
        r = self._r(fix)
        # A 2D fix (no altitude: RMC/GLL only) has NaN up: hold the last known height with a
        # huge variance, so it neither moves the filter nor is tested.
        up_known = not math.isnan(z[2])
        if not up_known:
            z = (z[0], z[1], self._last_up)
            r = (r[0], r[1], 1e12)
        elif not self._up_seen:
            self._first_height(z, r)
            up_known = False  # nothing to test it against yet
        self._last_up = z[2]
        v = self._velocity(fix)
        self._last_t = fix.t_s
        # Frozen (the fault), and whether the Doppler is void with it (the receiver repeats
        # its speed and course too): what the hold must know.
        frozen = self._stale_check(fix)
        stale = frozen and self._stale_run > 0
        de, dn = abs(z[0] - self._last_e), abs(z[1] - self._last_n)
        self._last_e, self._last_n = z[0], z[1]
        quant = self._quant
        if 1e-4 < de < quant[0] or 1e-4 < dn < quant[1]:  # rare: NaN compares false
            self._learn_quantum(de, dn)
        quality = []
        if p.min_sats and fix.num_sats is not None and fix.num_sats < p.min_sats:
            quality.append("sats")
        if p.max_hdop and fix.hdop is not None and fix.hdop > p.max_hdop:
            quality.append("hdop")
        restart = ""
        if dt is None or not self.kf.initialised:
            restart = "start"
        elif dt > p.max_gap_s:
            restart = "gap_restart"
        elif dt < 0.0:
            restart = "time_reset"  # the receiver's clock jumped back by more than a gap
        return Evidence(fix.t_s, 0.0 if dt is None else dt, z, r, v, up_known, quality, frozen,
                        stale, t, restart)

    def _first_height(self, z: tuple[float, float, float],
                      r: tuple[float, float, float]) -> None:
        """The first fix with a height: the window and the filter take it."""
        self._up_seen = True
        self._win = deque(((w[0], w[1], z[2]) for w in self._win), maxlen=self.p.window)
        if self.kf.initialised:
            ax = self.kf.axes[2]
            ax.p, ax.v, ax.P00, ax.P01, ax.P11 = z[2], 0.0, r[2], 0.0, 25.0

    def _doppler_evidence(self, ev: Evidence) -> None:
        """The Doppler displacement (trapezoid; no Doppler breaks the chain), the Doppler
        residual against the accepted fix of ``window`` epochs ago, the receiver against its
        own Doppler over RAW_HORIZON epochs, and the Doppler-free value b (D1)."""
        p = self.p
        v, lv, dt, z = ev.v, self._last_v, ev.dt, ev.z
        if p.predictor == "doppler":
            if v is not None and lv is not None:
                self._disp[0] += 0.5 * (v[0] + lv[0]) * dt
                self._disp[1] += 0.5 * (v[1] + lv[1]) * dt
            else:
                self._break_chain()
        ev.have_doppler = v is not None and lv is not None
        self._last_v = v
        d = ev.d = self._disp
        if ev.have_doppler and v is not None and self._stale_run == 0:
            self._note_live(ev.t_s, ev.z, d, v)
        if p.doppler_test and ev.have_doppler:
            self._doppler_residuals(ev)
        self._raw_hist.append(_new(RawFix, (z[0], z[1], d[0], d[1])))
        # Slow faults (fdi/drift.py, D1-D4) and the hold after a level change (fdi/level.py).
        b: tuple[float, float] | None = None
        if self._drift is not None and ev.have_doppler and v is not None:
            lag = p.drift_lag_s
            b = (z[0] - d[0] - lag * v[0], z[1] - d[1] - lag * v[1])
        ev.b = b
        prev_b = ev.prev_b = self._prev_b
        prev_bt = ev.prev_bt = self._prev_bt
        self._prev_b, self._prev_bt = b, ev.t_s
        if b is not None and prev_b is not None and self._is_step(ev.t_s, b, prev_b, prev_bt):
            # The fixes stepped (the hold's "new_level" takes a step to an older level sooner
            # than a drift there).
            self._last_step = LastStep(ev.t_s, math.hypot(b[0] - prev_b[0], b[1] - prev_b[1]))

    def _break_chain(self) -> None:
        """No Doppler: the window's Doppler-free values no longer line up; start again."""
        self._window_clear()
        self._disp = [0.0, 0.0, 0.0]
        self._acc_hist.clear()
        self._raw_hist.clear()
        self._forget_live()
        if self._drift is not None:
            self._drift.reset()
            self._steps.clear()

    def _note_live(self, t_s: float, z: tuple[float, float, float], d: list[float],
                   v: tuple[float, float]) -> None:
        """A live fix with a Doppler: where a freeze's coast would start (R25)."""
        lv = self._live_v
        lv.append(_new(LiveFix, (t_s, z[0], z[1], d[0], d[1], v[0], v[1])))
        oldest = t_s - self.p.frozen_turn_s - 1e-9
        while lv[0].t < oldest:
            lv.popleft()

    def _forget_live(self) -> None:
        """The Doppler displacement restarts: the last live fix's no longer lines up."""
        self._live_v.clear()

    def _frozen_coast(self, t_s: float, anchor_b: tuple[float, float]
                     ) -> tuple[float, float, float] | None:
        """R25's output at ``t_s``: from the last live fix, the fix itself if it was passed on
        as it was (the receiver's position when it froze), else the old track then (L1 with
        the Doppler displacement then, from the hold's anchor ``anchor_b``), carried on at the
        speed and turn rate fitted to the live velocities before it (fdi/coast.py, C1-C2; the
        course moved on by the Doppler's lag); None past the coast's bound (C3) or with no
        live fix."""
        p, lv = self.p, self._live_v
        if not lv or p.frozen_coast_m <= 0.0:
            return None
        live = lv[-1]
        tau = t_s - live.t
        if not within(tau, p.frozen_accel_mps2, p.drift_lag_s + p.drift_lag_sd_s,
                      p.frozen_coast_m):
            return None
        speed, course, rate = turn_fit([(f.t, f.ve, f.vn) for f in lv], live.t)
        lag = p.drift_lag_s
        de, dn = ctrv(speed, course + rate * lag, rate, tau)
        if live.t == self._acc_t:
            return live.e + de, live.n + dn, self._hold_up
        return (anchor_b[0] + live.de + lag * live.ve + de,
                anchor_b[1] + live.dn + lag * live.vn + dn, self._hold_up)

    def _doppler_residuals(self, ev: Evidence) -> None:
        p, z, d, v, t = self.p, ev.z, ev.d, ev.v, ev.stats
        if self._acc_hist:
            a = self._acc_hist[0]
            re_, rn = z[0] - a.e - (d[0] - a.de), z[1] - a.n - (d[1] - a.dn)
            if self._drift is not None and v is not None:
                # As the drift test does (D1, D3): the Doppler's lag behind the position
                # moved out, and its uncertainty over the change of velocity (a headland
                # turn at 1 Hz put 1.5 m here on a clean receiver).
                dve, dvn = v[0] - a.ve, v[1] - a.vn
                re_ -= p.drift_lag_s * dve
                rn -= p.drift_lag_s * dvn
                lag_g = p.doppler_sigmas * p.drift_lag_sd_s * math.hypot(dve, dvn)
                t.doppler_gate = math.hypot(t.doppler_gate, lag_g)
            t.doppler_res = math.hypot(re_, rn)
            ev.doppler_fault = t.doppler_res > t.doppler_gate
        if self._raw_hist:
            q = self._raw_hist[0]
            raw_res = math.hypot(z[0] - q.e - (d[0] - q.de), z[1] - q.n - (d[1] - q.dn))
            ev.raw_consistent = raw_res <= t.doppler_gate

    def _test_evidence(self, ev: Evidence) -> None:
        """The drift test (D4), the grey residual (eq. 18) and the chi-square test (eq. 1-6)."""
        p, t, z, d, b, v = self.p, ev.stats, ev.z, ev.d, ev.b, ev.v
        drift = self._drift
        if b is not None and drift is not None and v is not None:
            ev.drift = dres = drift.test(ev.t_s, b, v)
            t.drift = dres.g
            ev.drift_fault = dres.g > p.drift_sigmas
        # Section 2: grey prediction and residual ε(k) = x⁰(k) − x̂⁰(k) (eq. 18).
        y_hat = self._predict()
        if y_hat is not None:
            pred = (y_hat[0] + d[0], y_hat[1] + d[1], y_hat[2] + d[2])
            t.pred = pred
            ee, en, eu = z[0] - pred[0], z[1] - pred[1], z[2] - pred[2]
            if p.gate_axes == "horizontal":
                t.res_h = math.hypot(ee, en)
            else:
                t.res_h = max(abs(ee), abs(en))
            ev.grey_fault = t.res_h > t.gate_h
            t.res_u = abs(eu) if ev.up_known else None
            if p.test_up and t.res_u is not None and t.res_u > t.gate_u:
                ev.grey_fault = True
        # Section 1: Kalman prediction and residual chi-square test (eq. 1-6).
        self.kf.predict(ev.dt)
        t.F = self.kf.test(z, ev.r)
        ev.chi2_fault = p.chi2_enabled and self.T_d < t.F
        if (p.strategy == "grey" and self._coast_since is not None and self._acc_hist
                and t.pred is not None):
            # Coasting on the receiver's Doppler from the last accepted fix: the grey window
            # has fed on its own predictions for a while, so it is neither the best prediction
            # nor a fair test; the Doppler test (its gate grows with √epochs) decides.
            a = self._acc_hist[-1]
            t.pred = (a.e + d[0] - a.de, a.n + d[1] - a.dn, t.pred[2])
            ev.grey_fault = False

    def _find(self, ev: Evidence) -> None:
        """What the fault rules ask beyond the tests: which tests failed; a step back to an
        older level the track had left (R14); the end of a remembered step (R11, R16); and the
        step that starts this run of faults, remembered (``_note_step``)."""
        p, b = self.p, ev.b
        ev.reasons = (
            (["grey"] if ev.grey_fault else [])
            + (["chi2"] if ev.chi2_fault else [])
            + (["doppler"] if ev.doppler_fault else [])
            + (["drift"] if ev.drift_fault else [])
            + (["frozen"] if ev.stale_fault else [])
            + ev.quality
        )
        if b is None or self._drift is None or ev.quality or ev.stale_fault:
            return
        # An abrupt step back to an older level the track had left (or a drift fault that
        # stepped since the previous epoch: not a ramp): the end of a fault that was missed
        # or accepted, or a jump that happens to land there. The old track is not shown right
        # either way: the receiver's fix is passed on (flagged), the state goes on as for a
        # replacement, so a jump is told apart at the next epoch and a step that stays goes to
        # the hold, whose "new_level" ends it.
        if ev.abrupt or (ev.drift_fault and self._is_step(ev.t_s, b, ev.prev_b, ev.prev_bt)):
            ev.back = self._stepped_back and ev.raw_consistent
            if not ev.back:
                ev.back_level = self._back_at_old_level(ev.t_s, b)
                ev.back = ev.back_level is not None
        if ev.v is None or p.step_pair_s <= 0.0:
            return
        # The end of a remembered step (a multipath step the track went on to accept): the
        # fixes step back to the level before it; passed on at once (flagged, as a step back).
        ev.rev = self._step_back_to(ev.t_s, b)
        if ev.rev is not None:
            ev.back = True
        elif self._consec == 0 and (ev.abrupt or ev.drift_fault or ev.doppler_fault):
            self._note_step(ev.t_s, b, ev.stats.gate_h)

    def _pass_clean(self, ev: Evidence) -> Decision:
        """No test fails: R11 (a step back being confirmed ends), else the fix is passed on
        (R9 flagged by the drift warning, R10 by the ramp's horizon, R6)."""
        p, b, v, dres = self.p, ev.b, ev.v, ev.drift
        # Between the warning and the alarm threshold of the drift test: passed on as it is
        # but flagged, and neither a reference of the drift test nor learned from.
        ev.warn = dres is not None and 0.0 < p.drift_warn_sigmas < dres.g
        # The ramp's own horizon over its level, below the warning: reported (flagged) and
        # nothing else; the fix stays a reference and is learned from as before.
        ev.watch = not ev.warn and dres is not None and 0.0 < p.ramp_sigmas < dres.g_watch
        # Part of a step back being confirmed: passed on, and the confirmation goes on; not a
        # reference of the drift test yet (one at the level before the step would hide the
        # step from _step_back_to while the longer horizons still saw it).
        if self._end_watch is not None and b is not None and v is not None:
            dec = r_step_end_passing(self, ev)
            if dec is not None:
                return dec
        elif self._steps and b is not None:
            self._passed_reversal(ev.t_s, b, ev.dt)
        confirming = ev.rev is not None
        self._accepted(ev.z, ev.stats, learn=not ev.warn, step_back=confirming)
        self._window_append(ev.z, ev.d)
        self.kf.update(ev.z, ev.r)
        dec = r_drift_warn(self, ev)
        if dec is not None:
            return dec
        drift = self._drift
        if not confirming and b is not None and drift is not None and v is not None:
            drift.commit(ev.t_s, b, v)
            if self._steps:
                self._track_at(b)
        return r_drift_watch(self, ev) or r_accept(self, ev)

    def _feed_prediction(self, ev: Evidence) -> None:
        """Isolation: the prediction replaces the faulty fix in the window and, with R
        inflated by ``replaced_r_factor`` (a prediction is not a measurement), in the filter
        before its update; once an epoch."""
        if ev.fed:
            return
        ev.fed = True
        pred = ev.stats.pred
        assert pred is not None
        self._window_append(pred, ev.d, fed=True)
        f = self.p.replaced_r_factor
        r = ev.r
        self.kf.update(pred, (r[0] * f, r[1] * f, r[2] * f))

    def _step_zones(self, ev: Evidence) -> Decision:
        """Cai & Shao's three zones per axis, eq. (7)-(8), on the Kalman innovation.

        DM(i) = D_i² / S_ii: below T1 accept; T1..T2 (deviation) use it with R_ii inflated;
        above T2 (over-limit) replace it, by the least-squares fit of the axis's previous n
        epochs (``three_zone``) or by the grey prediction (``combined``). A fix is judged
        faulty when an axis is over the limit (or a quality screen fails).
        """
        p, z, r, t, quality = self.p, ev.z, ev.r, ev.stats, ev.quality
        pred = t.pred
        values = list(z)
        variances = list(r)
        zones: list[int] = []
        replaced = rejected = False
        kfD, kfS = self.kf.D, self.kf.S
        for i in range(3 if ev.up_known else 2):
            ext = None
            if p.strategy == "combined" and pred is not None:
                ext = (pred[i], self._var_h if i < 2 else self._var_u)
            g = self._zone_gates[i].step(z[i], kfD[i], kfS[i], r[i], external=ext)
            zones.append(int(g.zone))
            if g.action is ZoneAction.REJECT:
                rejected = True
            elif g.action is ZoneAction.REPLACE:
                replaced = True
            values[i], variances[i] = g.value, g.variance
        over = Zone.OVER_LIMIT in zones
        reasons = (["over_limit"] if over else []) + quality
        if quality and not over:
            if pred is None:
                rejected = True
            else:
                values, variances, replaced = list(pred), list(r), True
        reason = "+".join(reasons) or ("deviation" if Zone.DEVIATION in zones else "")
        if rejected or (replaced and self._consec >= p.max_consecutive):
            return self._raise_alarm(z, r, reason or "over_limit", t, rule="R24")
        out = (values[0], values[1], values[2])
        self._window_append(out, ev.d)
        self.kf.update(out, (variances[0], variances[1], variances[2]))
        if replaced:
            return self._replace(out, t, reason, tuple(zones), rule="R24",
                                 source=Source.PREDICTION)
        self._accepted(z, t)
        return self._accept(z, t, reason, tuple(zones), fault=over or bool(quality), rule="R24")

    # -------------------------------------------------------------- the hold

    def _stale_check(self, fix: FixInput) -> bool:
        """Is the receiver frozen? Its position repeated bit for bit while its own speed says
        it moved stale_move_m, or its whole fix (position, speed, course) repeated for stale_s
        or more often in a row than this receiver's own repeat rate makes likely (stale_p)."""
        enu = fix.enu
        sig = _new(FixSignature, (enu, fix.speed_mps, fix.course_deg))
        prev = self._prev_sig
        same_pos = prev is not None and enu == prev.enu
        if prev is not None:  # every pair of fixes, frozen or not
            self._pairs += 1
        if same_pos and sig == prev:
            self._repeats += 1
            if self._stale_run == 0:
                self._whole_since = self._prev_t
            self._stale_run += 1
        else:
            self._stale_run = 0
        if same_pos:
            if self._stale_since is None:
                self._stale_since = self._prev_t
        else:
            self._stale_since = None
        self._prev_sig = sig
        self._prev_t = fix.t_s
        since = self._stale_since
        if since is None:
            return False
        held = fix.t_s - since
        p = self.p
        # A live receiver that says it moved stale_move_m, and stale_move_quanta of its
        # coordinate quanta, cannot repeat its position bit for bit. The quanta keep a coarse
        # receiver (0.19 m at 4 decimals of minutes: 0.30 m) where a 0.2 m step repeats its
        # rounded position; the floor keeps a fine one's noise (three quanta of 1.9 cm were
        # not enough: at 10 Hz and 0.84 m/s a live receiver repeated one, its noise undoing
        # the 8 cm it moved). The quantum is the larger of the axes that have changed (a
        # receiver driving along one axis may never move the other); the rule waits for one.
        move = p.stale_move_m
        if p.stale_move_quanta > 0.0:
            q = max((x for x in self._quant if x < math.inf), default=math.inf)
            move = max(move, p.stale_move_quanta * q)
        if move > 0.0 and fix.speed_mps is not None and fix.speed_mps * held >= move:
            return True
        run = self._stale_run
        if run == 0:
            return False
        if fix.t_s - self._whole_since >= p.stale_s - 1e-9:
            return True
        # The chance that this receiver repeats its whole fix this often in a row, the chance
        # of one repeat learned from all its fixes (Laplace's rule). Frozen stretches count:
        # a receiver that freezes often, or pins its fix at every stop, is given longer.
        rate = (self._repeats + 1) / (self._pairs + 2)
        return p.stale_p > 0.0 and rate**run <= p.stale_p

    def _enter_hold(self, t_s: float, dres: DriftResult | None, reason: str,
                    slow: bool) -> bool:
        """Start a hold on the last trusted reference before the fault; False if none."""
        drift, hp = self._drift, self._hold_p
        assert drift is not None and hp is not None
        if hp.sigma_m != drift.sigmas:  # calibrated since
            hp = self._hold_p = self._hold_params(self.p, drift.sigmas)
        if dres is not None:
            anchor = (dres.ref_t, dres.ref_b, dres.ref_v)
        else:
            since = self._stale_since
            anchor_or_none = drift.at_or_before(since if since is not None else t_s)
            if anchor_or_none is None:
                return False
            anchor = anchor_or_none
        a_t, a_b, a_v = anchor
        drift.forget_after(a_t)  # a fault may have been building since
        old = drift.levels_between(a_t - LEVEL_KEEP_S, a_t - OLD_LEVEL_MIN_AGE_S)
        stale_m = 0.0
        if self._stale_run > 0:  # the Doppler is void since the whole fix repeats
            stale_m = math.hypot(*a_v) * (t_s - self._whole_since)
        # The hold's clock starts with the run of replacements that led to it (seconds).
        t0 = self._run_t0 if self._consec > 0 else t_s
        self._hold = LevelHold(hp, t0, a_t, a_b, a_v, stale_m, old, slow,
                               prefer_raw=self._stepped_back, frozen=self._stale_run > 0)
        self._hold_reason = reason
        self._hold_up = self.kf.position[2] if self.kf.initialised else self._last_up
        return True

    def _hold_step(self, ev: Evidence) -> Decision:
        """One epoch of the hold (fdi/level.py), then R18-R23 on its answer."""
        hold = self._hold
        assert hold is not None and ev.b is not None and ev.v is not None
        d = ev.d
        hs = hold.step(ev.t_s, ev.b, ev.v, (d[0], d[1]), ev.stale, ev.dt, self._stale_run == 0,
                       self._last_step, ev.frozen)
        ev.stats.drift = hs.g
        for rule in HOLD_RULES:
            dec = rule(self, ev, hold, hs)
            if dec is not None:
                return dec
        raise AssertionError("R23 answers every epoch")  # pragma: no cover

    def _slow(self, ev: Evidence) -> bool:
        """Is the hold R12 enters a slow one (a frozen receiver, or a drift fault not seen by
        the grey or chi-square test, over a horizon beyond 1 s, that did not step)?"""
        dres, b = ev.drift, ev.b
        return ev.stale_fault or (
            ev.drift_fault and not ev.abrupt and dres is not None and dres.horizon_s > 1.0
            and b is not None
            and not self._is_step(ev.t_s, b, ev.prev_b, ev.prev_bt, SLOW_MAX_MPS))

    def _carry_track(self, ev: Evidence, hs: HoldStep) -> tuple[float, float, float]:
        """The old track (L1) at this epoch, fed to the window (the filter only predicts)."""
        out = (hs.track[0], hs.track[1], self._hold_up)
        ev.stats.pred = out
        self._window_append(out, ev.d, fed=True)
        return out

    def _resume(self, ev: Evidence, reason: str, rule: str) -> Decision:
        """The receiver is right again: restart the window, the filter and the Doppler
        history on the fix (the drift test's references are the caller's to prune)."""
        drift = self._drift
        z, d, v, b = ev.z, ev.d, ev.v, ev.b
        assert drift is not None and v is not None and b is not None
        self._hold = None
        self._window_clear()
        self._win.append((z[0] - d[0], z[1] - d[1], z[2] - d[2]))
        self._acc_hist.clear()
        self._acc_hist.append(Accepted(z[0], z[1], d[0], d[1], v[0], v[1]))
        self._raw_hist.clear()
        self.kf.reset(z, ev.r)
        self._consec = 0
        self._stepped_back = False
        self._coast_since = None
        drift.commit(ev.t_s, b, v)
        if self._steps:
            self._track_at(b)
        return self._accept(z, ev.stats, reason, rule=rule)

    def _note_step(self, t_s: float, b: tuple[float, float], gate_h: float) -> None:
        """Remember the step that starts this run of faults, if it is one: the fix against
        the newest trusted reference by more than the grey gate or ``hold_exit_sigmas`` of
        the drift σ at its age."""
        drift, p = self._drift, self.p
        assert drift is not None
        ref = drift.at_or_before(t_s)
        if ref is None:
            return
        r_t, (re_, rn), _ = ref
        se, sn = b[0] - re_, b[1] - rn
        size = math.hypot(se, sn)
        if size < min(gate_h, p.hold_exit_sigmas * sigma_at(
                t_s - r_t, drift.horizons, drift.sigmas)):
            return
        steps = [st for st in self._steps if t_s - st.t0 <= p.step_pair_s]
        steps.append(Step(r_t, re_, rn, se, sn))
        self._steps = steps[-4:]

    def _passed_reversal(self, t_s: float, b: tuple[float, float], dt: float) -> None:
        """A remembered step that ended with no fault to show it: fixes that pass the tests
        reverse it (this epoch's step from the track within REVERSAL_FRAC x its size: not the
        noise floor :meth:`_step_back_to` adds, with which passing fixes forgot a small step
        before its end) and stay there, passing, for ``hold_exit_s`` (within
        ``hold_exit_sigmas`` of the drift σ of where they began). The step is then forgotten:
        kept, a later step that happened to be its reverse was taken for its end (a multipath
        step passed on as a step back, and its own end held as a new fault). Forgotten at the
        first passing epoch, a step whose end then became a fault was no longer matched."""
        drift, p = self._drift, self.p
        assert drift is not None
        pr = self._passed
        if pr is not None:
            if t_s - pr.last <= 1.5 * dt + 1e-9 and self._near(b, pr.b, t_s - pr.t):
                if t_s - pr.t >= p.hold_exit_s - 1e-9:
                    self._steps = [st for st in self._steps if st.t0 != pr.t0]
                    self._passed = None
                else:
                    pr.last = t_s
                return
            self._passed = None
        ref = drift.at_or_before(t_s)
        if ref is None:
            return
        _, (ce, cn), _ = ref
        je, jn = b[0] - ce, b[1] - cn  # this epoch's step from the track
        for st in self._steps:
            if st.accepted and st.reversed_by(je, jn):
                self._passed = PassedReversal(st.t0, b, t_s, t_s)
                return

    def _track_at(self, b: tuple[float, float]) -> None:
        """A fix was accepted at ``b``: a remembered step whose stepped level it is nearer
        than the level before it was accepted (a replaced burst leaves the track nearer the
        level before)."""
        for st in self._steps:
            if not st.accepted and math.hypot(b[0] - st.b0e - st.se, b[1] - st.b0n - st.sn) < (
                    math.hypot(b[0] - st.b0e, b[1] - st.b0n)):
                st.accepted = True

    def _step_end(self, t_s: float, b: tuple[float, float], rev: float) -> bool:
        """The fix is back before the remembered step of time ``rev``: has it stayed there
        (within ``hold_exit_sigmas`` of the drift σ of where it began) for ``hold_exit_s`` and
        STEP_END_EPOCHS epochs (a burst is shorter)? Then the references of the stepped level
        go and True (the caller restarts on the receiver)."""
        drift, p = self._drift, self.p
        assert drift is not None
        w = self._end_watch
        if w is not None and w.rev == rev and self._near(b, w.b, t_s - w.t):
            if t_s - w.t >= p.hold_exit_s - 1e-9 and w.epochs + 1 >= STEP_END_EPOCHS:
                self._steps = [st for st in self._steps if st.t0 < rev]
                drift.forget_after(rev)
                self._end_watch = None
                return True
            w.epochs += 1
            return False
        self._end_watch = StepEndWatch(rev, b, t_s, 1)  # not where it began: start again
        return False

    def _learn_quantum(self, de: float, dn: float) -> None:
        """A smaller non-zero change of a coordinate between consecutive fixes (``de``, ``dn``;
        above 0.1 mm: the local frame's curvature; below 1 m): the receiver's rounding is the
        smallest, given to the drift test once both axes have one (D6), and the frozen test's
        scale (``stale_move_quanta``)."""
        q = self._quant
        changed = False
        for i, dz in ((0, de), (1, dn)):
            if 1e-4 < dz < q[i] and dz < 1.0:
                q[i] = dz
                changed = True
        drift = self._drift
        if changed and q[0] < math.inf and q[1] < math.inf and drift is not None:
            drift.set_quantum(max(q[0], q[1]))

    def _is_step(self, t_s: float, b: tuple[float, float],
                 prev: tuple[float, float] | None, prev_t: float,
                 rate_mps: float = 0.0) -> bool:
        """Did the fix's Doppler-free value step from the previous epoch's (``prev`` at
        ``prev_t``) by more than ``hold_exit_sigmas`` of the drift σ over the interval (and,
        with ``rate_mps``, that rate times the interval more)? (A ramp moves a little every
        epoch.)"""
        drift = self._drift
        assert drift is not None
        if prev is None:
            return False
        dt = t_s - prev_t
        return math.hypot(b[0] - prev[0], b[1] - prev[1]) > rate_mps * dt + (
            self.p.hold_exit_sigmas * sigma_at(dt, drift.horizons, drift.sigmas))

    def _near(self, b: tuple[float, float], b0: tuple[float, float], age: float) -> bool:
        """``b`` within ``hold_exit_sigmas`` of the drift σ at ``age`` (s) of ``b0``: still
        at the level where a step's end began (:meth:`_step_end`, :meth:`_passed_reversal`)."""
        drift = self._drift
        assert drift is not None
        return math.hypot(b[0] - b0[0], b[1] - b0[1]) <= self.p.hold_exit_sigmas * sigma_at(
            max(age, 1e-3), drift.horizons, drift.sigmas)

    def _reversal_floor(self) -> float:
        """The noise floor of :meth:`Step.reversed_by` (m): none until the drift test has
        calibrated (its configured σ are wide starting values)."""
        drift = self._drift
        assert drift is not None
        if not drift.calibrated:
            return 0.0
        return REVERSAL_FLOOR_SIGMAS * math.sqrt(2.0) * drift.sigmas[0]

    def _step_back_to(self, t_s: float, b: tuple[float, float]) -> float | None:
        """Is the fix back at the level before a remembered step that the track accepted?
        The time of that step's reference, if so.

        The track was seen at the stepped level after it (:meth:`_track_at`: the step was
        accepted, not replaced). Then either this epoch's step from the track is the
        remembered step reversed, within REVERSAL_FRAC x its size or the epoch's noise
        (:meth:`_reversal_floor`, up to REVERSAL_MAX_FRAC x its size; both are measured over an
        epoch, so the slow DGPS error between them cancels out); or the track is within half
        the step of the stepped level and the fix is at least 0.6 x the step away from it and
        twice as close to the level before. A jump that happens to land there costs that
        epoch the raw fix (flagged); only fixes that stay there for ``hold_exit_s`` and
        STEP_END_EPOCHS epochs end it (:meth:`_step_end`)."""
        drift = self._drift
        assert drift is not None
        ref = drift.at_or_before(t_s)
        if ref is None:
            return None
        r_t, (ce, cn), _ = ref
        je, jn = b[0] - ce, b[1] - cn  # this epoch's step from the track
        floor = self._reversal_floor()
        for st in reversed(self._steps):
            t0, b0e, b0n, se, sn = st.t0, st.b0e, st.b0n, st.se, st.sn
            if t_s - t0 > self.p.step_pair_s or r_t <= t0 or not st.accepted:
                continue  # too old, or the track was not seen at the stepped level
            if st.reversed_by(je, jn, floor):
                return t0  # the reverse of the remembered step (slow drift cancels out)
            size = math.hypot(se, sn)
            if math.hypot(ce - b0e - se, cn - b0n - sn) > STEPPED_LEVEL_FRAC * size:
                continue  # the track is not at the stepped level
            e_track = math.hypot(je, jn)
            e_old = math.hypot(b[0] - b0e, b[1] - b0n)
            if e_track >= STEP_AWAY_FRAC * size and e_old <= BACK_NEARER_FRAC * e_track:
                return t0
        return None

    def _back_at_old_level(self, t_s: float, b: tuple[float, float]) -> float | None:
        """An abrupt step back: is the fix at an older trusted level (20-300 s before the
        newest reference) that the newest reference has left? The time of that level.

        The end of a slow fault or a level step that was missed or accepted (an undetected
        ramp, a multipath step taken as the receiver's level): the old track is the faulty
        side, and replacing the returning fix by it would be worse than the receiver. The
        track left the level by at least ``hold_side_sigmas`` x σ(30 s) (fdi/level.py's
        ``new_level``; 1 x passed the end of two small missed ramps on, but also the 3 epochs
        of a 1.69 m burst before the calibration: docs/evaluation.md, fourth pass), and the
        fix is within :data:`BACK_AT_OLD_FRAC` of that departure of it and within
        ``hold_exit_sigmas`` of the drift σ at the level's age. The σ are the drift test's
        :attr:`~fdi.drift.DriftTest.working_sigmas`: while it calibrates, from its provisional
        σ on (D7), those instead of the wide configured ones, whose σ(30 s) of 0.9 m asked a
        missed ramp for 1.8 m before its end was seen as a return (a slow ramp's 1.4 m step
        back held; docs/evaluation.md). It only chooses what is passed on (the caller's state
        goes on as for a replacement), so a jump that happens to land there costs that epoch
        the raw fix, never more."""
        drift, hp = self._drift, self._hold_p
        assert drift is not None and hp is not None
        ref = drift.at_or_before(t_s)
        if ref is None:
            return None
        r_t, (re_, rn), _ = ref
        sig = drift.working_sigmas
        s_side = hp.side_sigmas * sigma_at(SIDE_HORIZON_S, hp.horizons_s, sig)
        for t_o, (oe, on) in drift.levels_between(r_t - LEVEL_KEEP_S,
                                                  r_t - OLD_LEVEL_MIN_AGE_S):
            e_track = math.hypot(re_ - oe, rn - on)
            s_age = sigma_at(t_s - t_o, hp.horizons_s, sig)
            if e_track < s_side:
                continue  # the track has not left that level by more than its own noise
            e_new = math.hypot(b[0] - oe, b[1] - on)
            if e_new <= BACK_AT_OLD_FRAC * e_track and e_new <= hp.exit_sigmas * s_age:
                return t_o
        return None

    # -------------------------------------------------------------- outcomes

    def _decision(
        self,
        action: Action,
        fault: bool,
        reason: str,
        out: tuple[float, float, float] | None,
        t: Stats,
        *,
        alarm_raised: bool = False,
        zones: tuple[int, ...] | None = None,
        rule: str,
        source: Source = Source.NONE,
    ) -> Decision:
        kf = self.kf
        # The tuple of Decision's fields, in order (this runs once an epoch: the NamedTuple's
        # own __new__ would bind 21 arguments in Python first).
        return _new(Decision, (
            action,
            fault,
            reason,
            out,  # out_enu
            t.pred,  # pred_enu
            t.res_h,  # grey_res_h
            t.res_u,  # grey_res_u
            t.gate_h,  # grey_gate_h
            t.gate_u,  # grey_gate_u
            t.doppler_res,
            t.doppler_gate,
            t.F,  # chi2
            self.T_d,  # chi2_threshold
            self._consec,  # consecutive
            self._alarm,  # alarm
            alarm_raised,
            kf.position if kf.initialised else None,  # kf_enu
            zones,
            t.drift,
            rule,
            source,
        ))

    def _accepted(self, z: tuple[float, float, float], t: Stats,
                  learn: bool = True, step_back: bool = False) -> None:
        """Bookkeeping for a fix passed on as it is: the run of replacements ends; ``learn``:
        the gates learn from it (not while the drift test warns); ``step_back``: the fix is
        part of a step back being confirmed, which goes on."""
        self._consec = 0
        self._stepped_back = False
        if not step_back:
            self._end_watch = None
        self._coast_since = None
        if learn and t.doppler_res is not None and len(self._acc_hist) == self.p.window:
            self._n_inc += 1
            w = max(self._ewma, 1.0 / (self._n_inc + DOPPLER_PRIOR_N))
            self._var_inc = _learn(self._var_inc, t.doppler_res**2 / 2.0, w)
        d = self._disp
        lv = self._last_v or (0.0, 0.0)
        self._acc_hist.append(_new(Accepted, (z[0], z[1], d[0], d[1], lv[0], lv[1])))
        if learn and t.pred is not None:
            self._learn_spread(z, t.pred, t.res_u is not None)

    def _accept(
        self,
        z: tuple[float, float, float],
        t: Stats,
        reason: str,
        zones: tuple[int, ...] | None = None,
        fault: bool = False,
        *,
        rule: str,
    ) -> Decision:
        """The receiver's fix is passed on (withheld while the alarm is latched; the alarm
        ends after ``recover_epochs`` of them in a row)."""
        self._acc_t = self._last_t
        if self._alarm:
            self._good_run += 1
            if self._good_run >= self.p.recover_epochs:
                self._alarm = False
                reason = reason or "recovered"
        action: Action = "alarm" if self._alarm else "accept"
        return self._decision(action, fault, reason, None if self._alarm else z, t, zones=zones,
                              rule=rule, source=Source.RAW)

    def _replace(
        self,
        out: tuple[float, float, float],
        t: Stats,
        reason: str,
        zones: tuple[int, ...] | None = None,
        *,
        rule: str,
        source: Source,
    ) -> Decision:
        """``out`` (from ``source``) is passed on for a fix judged faulty: a run goes on."""
        if self._consec == 0:
            self._run_t0 = self._last_t if self._last_t is not None else 0.0
        self._consec += 1
        self._good_run = 0
        action: Action = "alarm" if self._alarm else "replace"
        return self._decision(action, True, reason, None if self._alarm else out, t, zones=zones,
                              rule=rule, source=source)

    def _coast(self, t: Stats, reason: str, *, rule: str, source: Source) -> Decision:
        """Alarm up; the receiver is not consistent with itself: carry on ``source``."""
        raised = not self._alarm
        self._alarm = True
        self._good_run = 0
        return self._decision("alarm", True, reason, None, t, alarm_raised=raised, rule=rule,
                              source=source)

    def _raise_alarm(
        self,
        z: tuple[float, float, float],
        r: tuple[float, float, float],
        reason: str,
        t: Stats,
        keep_levels: bool = False,
        *,
        rule: str,
    ) -> Decision:
        """The alarm; the window, the filter and the tests restart on the fix."""
        raised = not self._alarm
        self._alarm = True
        self._good_run = 0
        consecutive = self._consec
        self._restart(z, r, keep_levels)
        dec = self._decision("alarm", True, reason, None, t, alarm_raised=raised, rule=rule)
        return dec._replace(consecutive=consecutive) if consecutive else dec

    # -------------------------------------------------------------- pieces

    def _window_clear(self) -> None:
        self._win.clear()
        self._fed = 0

    def _window_append(self, value: tuple[float, float, float], d: list[float],
                       fed: bool = False) -> None:
        """Append ``value`` (a fix, or with ``fed`` the window's own prediction) as its
        Doppler-free value.

        With the Doppler predictor, a fix that follows a run of two or more predictions
        replaces them by the values between the fixes on either side (linear in the epoch):
        from the second on, each was GM(1,1) extrapolating its own predictions, which is not
        the receiver's level, and left in the window they biased the next predictions enough
        to replace a clean fix (after a 4-epoch burst at 1 Hz: 1.07 m off against 0.19 m
        raw). A single prediction was made from fixes and stays. The paper's
        raw predictor keeps its self-fed window (section 2)."""
        y = (value[0] - d[0], value[1] - d[1], value[2] - d[2])
        w = self._win
        k = min(self._fed, len(w))
        if fed:
            self._fed = k + 1
        else:
            if k >= 2 and len(w) > k and self.p.predictor == "doppler":
                y0 = w[-k - 1]
                for j in range(1, k + 1):
                    a = j / (k + 1)
                    w[-k - 1 + j] = (y0[0] + a * (y[0] - y0[0]), y0[1] + a * (y[1] - y0[1]),
                                     y0[2] + a * (y[2] - y0[2]))
            self._fed = 0
        w.append(y)

    def _learn_spread(
        self, z: tuple[float, float, float], pred: tuple[float, float, float], up: bool
    ) -> None:
        ee, en, eu = z[0] - pred[0], z[1] - pred[1], z[2] - pred[2]
        self._var_h = _learn(self._var_h, 0.5 * (ee * ee + en * en), self._ewma)
        if up:
            self._var_u = _learn(self._var_u, eu * eu, self._ewma)

    def update_params(self, params: RoverDetectorParams) -> None:
        """Use ``params`` from the next :meth:`step` on (an operator's change, at run time).

        The state is kept: the window keeps its newest values (up to the new length), the
        filter its estimate; T_d is recomputed from α (eq. 6), and the gate's learning rate
        from ``gate_tau_epochs``.
        """
        self.p = params
        self.T_d = threshold(params.alpha, 3)  # eq. (6), m = 3
        self.kf.q = params.q_accel
        if self._win.maxlen != params.window:
            self._win = deque(self._win, maxlen=params.window)
        self._ewma = 1.0 / params.gate_tau_epochs
        self._make_drift(params)
        if self._drift is not None and max(self._quant) < math.inf:
            self._drift.set_quantum(max(self._quant))
        self._hold = None


def _learn(var: float, sample: float, w: float) -> float:
    """One step of the exponentially weighted variance of accepted residuals.

    Only residuals within 3σ of the current estimate are learned from (a fix accepted just
    under a wide gate would otherwise widen the gate further: a runaway a slowly frozen
    receiver can drive). Cut at 3σ the estimate is biased low by about 3 %.
    """
    if sample > 9.0 * var:
        return var
    return var + w * (sample - var)
