"""Fault-tolerant compass heading: the substitution strategy of Zhu, Chen & Liu (2009), sec. 3.2.

Per control period the caller passes the command sent in the previous period (%) and the compass
reading (deg, or None when no telemetry arrived). :class:`FaultTolerantHeading` runs the
dual-criterion detector of :mod:`fdi.lms_fir` and decides which heading the PID uses:

* ``sensor``: no fault, or e^2 alone (a disturbance: keep the sensor, sec. 3.2).
* ``fir``: from the first e^2 exceedance (tentatively, ``substitute_while_suspect``) and after
  confirmation, the *stored* FIR's predicted increments are integrated from the last good heading
  (sec. 4.3: "the FIR output replaces the faulty sensor").
* ``compensated`` (an extension, ``offset_compensation``): dead reckoning on a frozen model drifts
  with the current, so after confirmation, if the reading minus the FIR heading is a steady offset
  (a fixed drift fault), the reading minus that offset is used instead. A new jump in the
  reading falls back to ``fir``.
* A reading that repeats for ``stuck_samples`` periods is a stuck sensor (an FIR on increments
  barely sees it while the vehicle holds course): confirmed at once, weights from the snapshot
  taken when the repetition began.

The sensor is consistent again when it agrees with the FIR heading within ``recover_gate_deg``
for ``recover_samples`` periods; the detector then restarts from the stored model. Headings
returned are in [0, 360) degrees; the internal state is unwrapped.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, fields
from typing import Literal

from fdi.gyro_witness import GyroWitness, WitnessParams, WitnessStep
from fdi.lms_fir import DetectorConfig, DetectorStep, DualCriterionDetector, wrap180

Source = Literal["sensor", "fir", "compensated", "fused", "gyro", "none"]
State = Literal["normal", "suspect", "fault_fir", "fault_comp", "fault_gyro"]


@dataclass(frozen=True)
class FtConfig:
    """The substitution and stuck/recovery rules (the ``[ft]`` table)."""

    substitute_while_suspect: bool = field(default=True, metadata={
        "doc": "while the detector suspects a fault (criterion 1 open), steer on the FIR heading"})
    offset_compensation: bool = field(default=True, metadata={
        "doc": "a confirmed fault whose reading sits at a steady offset from the FIR heading is "
               "compensated (the reading less the offset)"})
    offset_samples: int = field(default=10, metadata={
        "ge": 2, "unit": "samples", "doc": "the offset is the mean residual over this many "
                                           "samples"})
    offset_max_std_deg: float = field(default=1.5, metadata={
        "gt": 0.0, "unit": "deg", "doc": "... taken only when their σ is below this"})
    recover_gate_deg: float = field(default=3.0, metadata={
        "gt": 0.0, "unit": "deg", "doc": "the reading agrees with the FIR heading within this: a "
                                         "sample towards recovery (and the smallest offset "
                                         "compensated)"})
    recover_samples: int = field(default=10, metadata={
        "ge": 1, "unit": "samples", "doc": "agreeing samples in a row that end a fault"})
    stuck_samples: int = field(default=10, metadata={
        "ge": 0, "unit": "samples", "doc": "a reading unchanged this many samples in a row is "
                                           "stuck (0 disables)"})
    stuck_eps_deg: float = field(default=1e-6, metadata={
        "ge": 0.0, "unit": "deg", "doc": "unchanged: a change at most this"})
    smooth_gain: float = field(default=0.2, metadata={
        "gt": 0.0, "le": 1.0, "unit": "-",
        "doc": "normal state: heading used = prediction + gain × (reading − prediction)"})
    stuck_recover_increments: bool = field(default=True, metadata={
        "doc": "no gyro: a stuck compass is taken back once its increments fit the FIR again"})
    # The gyro witness (fdi.gyro_witness), used when the controller is given a yaw rate.
    # No gyro: after a setpoint change (the controller knows it: an input, not a guess) the
    # FIR's prediction error is at its largest; theta is raised by this factor for a while.
    turn_window_s: float = field(default=0.0, metadata={
        "ge": 0.0, "doc": "after a setpoint change, theta x turn_theta_factor (0: off)",
        "unit": "s"})
    turn_theta_factor: float = field(default=1.0, metadata={
        "ge": 1.0, "unit": "-", "doc": "theta's factor within turn_window_s of a setpoint change"})
    level_sigmas: float = field(default=5.0, metadata={
        "ge": 0.0, "doc": "no gyro: also confirm when the reading stays this * sigma_e off the "
                          "substitution heading for the detector's persist samples (0: off)",
        "unit": "σ"})
    level_min_deg: float = field(default=5.0, metadata={
        "ge": 0.0, "doc": "... and at least this far (the smallest drift step of interest)",
        "unit": "deg"})
    level_burst_ratio: float = field(default=2.5, metadata={
        "gt": 0.0, "doc": "... unless the short scale of e > this * sigma_e (a noise burst)",
        "unit": "-"})
    gyro_enabled: bool = field(default=True, metadata={
        "doc": "use the yaw-rate gyro witness when the link carries a rate"})
    gyro_heading_tau_s: float = field(default=10.0, metadata={
        "gt": 0.0, "unit": "s", "doc": "time constant of the witness's output heading loop "
                                       "(compass into integrated gyro)"})
    gyro_test_tau_s: float = field(default=30.0, metadata={
        "gt": 0.0, "unit": "s", "doc": "time constant of the test heading's loop"})
    gyro_bias_tau_s: float = field(default=600.0, metadata={
        "gt": 0.0, "unit": "s", "doc": "forgetting time of the gyro bias fit"})
    gyro_bias_delay_s: float = field(default=15.0, metadata={
        "ge": 0.0, "unit": "s", "doc": "the bias fit uses trusted samples this old"})
    gyro_ref_tau_s: float = field(default=5.0, metadata={
        "gt": 0.0, "unit": "s", "doc": "time constant of the innovation's slow mean"})
    gyro_max_suspect_s: float = field(default=20.0, metadata={
        "gt": 0.0, "unit": "s", "doc": "a suspect not confirmed by then is dismissed"})
    gyro_sigma0_deg: float = field(default=1.0, metadata={
        "gt": 0.0, "unit": "deg", "doc": "the innovation's initial σ"})
    # The floor of the innovation's sigma. ArduSub's EKF yaw is smooth (0.001 deg of noise)
    # but wanders +-0.4 deg against its own integrated rates over tens of seconds (0.02-0.04
    # deg/s: its magnetometer corrections; ../shared/corpus/ardusub-sitl), and RAW_IMU's gyro
    # bias walks (ArduPilot's SIM_DRIFT_SPEED): at 0.2 both captures of a healthy vehicle
    # confirmed a fault, at 0.5 their CUSUMs peaked at 0.2 % and 22 % of confirmation. The
    # Outland preset (config/rov.toml: a noisy compass whose sigma is well above it) keeps 0.2.
    gyro_sigma_min_deg: float = field(default=0.5, metadata={
        "gt": 0.0, "unit": "deg", "doc": "floor of the innovation's σ (ArduSub's EKF yaw wanders "
                                         "±0.4 deg against its own rates)"})
    gyro_sigma_samples: int = field(default=150, metadata={
        "ge": 1, "unit": "samples", "doc": "EWMA length of the innovation's σ²"})
    gyro_clip: float = field(default=4.5, metadata={
        "gt": 0.0, "unit": "σ", "doc": "fast CUSUM: score clip"})
    gyro_kappa: float = field(default=1.5, metadata={
        "ge": 0.0, "unit": "σ", "doc": "fast CUSUM: drift (allowance)"})
    gyro_h: float = field(default=11.0, metadata={
        "gt": 0.0, "unit": "-", "doc": "fast CUSUM: confirmation level (> 3 (clip − kappa))"})
    gyro_slow_clip: float = field(default=2.5, metadata={
        "gt": 0.0, "unit": "σ", "doc": "slow CUSUM: score clip"})
    gyro_slow_kappa: float = field(default=0.75, metadata={
        "ge": 0.0, "unit": "σ", "doc": "slow CUSUM: drift (allowance)"})
    gyro_slow_h: float = field(default=20.0, metadata={
        "gt": 0.0, "unit": "-", "doc": "slow CUSUM: confirmation level"})
    gyro_h_suspect: float = field(default=3.0, metadata={
        "gt": 0.0, "unit": "-", "doc": "the fast CUSUM above this opens a suspect"})
    gyro_jump_sigmas: float = field(default=4.0, metadata={
        "gt": 0.0, "unit": "σ", "doc": "an innovation this large opens a suspect at once (a jump)"})
    gyro_burst_ratio: float = field(default=2.5, metadata={
        "gt": 1.0, "unit": "-", "doc": "the innovation's short-scale σ above this × σ: a noise "
                                       "burst, not a bias"})
    gyro_spread_ratio: float = field(default=1.6, metadata={
        "gt": 0.0, "unit": "-", "doc": "a level's samples lie on a line within this × σ (a step, "
                                       "not noise)"})
    gyro_step_min_deg: float = field(default=3.5, metadata={
        "ge": 0.0, "doc": "the fast CUSUM confirms a level only this far off the innovation's "
                          "mean (the smallest step of interest, less the noise; 0: any)",
        "unit": "deg"})
    gyro_warmup_samples: int = field(default=100, metadata={
        "ge": 0, "unit": "samples", "doc": "samples before the witness tests (its bias fit's "
                                           "warm-up)"})
    gyro_recover_gate_deg: float = field(default=1.5, metadata={
        "gt": 0.0, "unit": "deg", "doc": "recovery: the innovation's mean within this (or 3 σ)"})
    gyro_recover_samples: int = field(default=10, metadata={
        "ge": 1, "unit": "samples", "doc": "recovery: this many agreeing samples"})
    gyro_comp_samples: int = field(default=50, metadata={
        "ge": 0, "doc": "after a step: learn its offset over this many samples (0: off)",
        "unit": "samples"})
    gyro_comp_max_slope_dps: float = field(default=0.25, metadata={
        "gt": 0.0, "unit": "deg/s", "doc": "... only if a level: its slope within this"})
    gyro_fast_margin_s: float = field(default=2.0, metadata={
        "ge": 0.0, "doc": "a step's (or stuck run's) compass trusted up to this before it",
        "unit": "s"})
    gyro_drift_window_s: float = field(default=90.0, metadata={
        "gt": 1.0, "doc": "the hinge test's window (compass minus integrated gyro)", "unit": "s"})
    gyro_drift_glr: float = field(default=30.0, metadata={
        "ge": 0.0, "doc": "the hinge test's confirmation level (likelihood ratio; 0: off)",
        "unit": "-"})
    gyro_drift_sigma_min_deg: float = field(default=1.5, metadata={
        "gt": 0.0, "doc": "the hinge test's noise floor (the integrated gyro noise's walk)",
        "unit": "deg"})
    gyro_drift_max_turn_deg: float = field(default=10.0, metadata={
        "gt": 0.0, "doc": "the hinge test only while the heading spans at most this (window)",
        "unit": "deg"})
    gyro_bias_hold_deg: float = field(default=10.0, metadata={
        "ge": 0.0, "doc": "the warm-up's bias line goes on while the heading stays this near its "
                          "end's (0: the later samples their own segment)", "unit": "deg"})
    gyro_comp_drift_glr: float = field(default=30.0, metadata={
        "ge": 0.0, "doc": "the hinge test on a step's compensated compass: a drift after the "
                          "step is a second fault (likelihood ratio; 0: off)", "unit": "-"})
    gyro_comp_drift_bias_sd_dps: float = field(default=0.005, metadata={
        "ge": 0.0, "doc": "... the bias before the step known to no better than this (0: its "
                          "fit's information)", "unit": "deg/s"})
    gyro_drift_recover_s: float = field(default=20.0, metadata={
        "ge": 0.0, "doc": "after a drift under a step's compensation, the compass is taken back "
                          "only once its innovation's slope over this long (0: off) ...",
        "unit": "s"})
    gyro_drift_recover_max_dps: float = field(default=0.05, metadata={
        "gt": 0.0, "doc": "... is within this (a drifting compass crossing the dead reckoning)",
        "unit": "deg/s"})
    gyro_maneuver_lag_s: float = field(default=0.15, metadata={
        "ge": 0.0, "le": 2.0, "doc": "s: the compass's lag behind the gyro, a bound (ArduSub's "
                                     "RAW_IMU compass: 0.12-0.17 s)", "unit": "s"})
    gyro_maneuver_deg: float = field(default=1.0, metadata={
        "ge": 0.0, "doc": "deg: a period whose lag + rate-sampling bound exceeds this is a "
                          "manoeuvre, carried by the gyro alone (0: off)", "unit": "deg"})
    gyro_maneuver_settle: int = field(default=2, metadata={
        "ge": 0, "le": 50, "doc": "periods after a manoeuvre still carried by the gyro",
        "unit": "periods"})
    gyro_maneuver_sample_s: float = field(default=0.1, metadata={
        "gt": 0.0, "le": 1.0, "unit": "s", "doc": "the yaw rate's sampling interval: a manoeuvre's "
        "integration error is bounded by half of it times each rate change (ArduSub's ATTITUDE "
        "at 10 Hz: 0.1)"})
    gyro_maneuver_dead_deg: float = field(default=0.5, metadata={
        "ge": 0.0, "unit": "deg", "doc": "a manoeuvre's end takes into the headings only the "
        "innovation's change beyond this (within it, a ramp's increment between two kicks, it "
        "is left to the test) times gyro_maneuver_deg / its sampling bound where smaller; for "
        "the EKF's yaw (ArduSub heading = attitude)"})
    gyro_maneuver_dead_min_deg: float = field(default=0.0, metadata={
        "ge": 0.0, "unit": "deg", "doc": "the dead band shrinks with gyro_maneuver_deg / the "
        "manoeuvre's sampling bound (a fast turn's error is sampling), never below this"})
    gyro_maneuver_dead_raw_deg: float = field(default=1.5, metadata={
        "ge": 0.0, "unit": "deg", "doc": "for a raw compass (ArduSub heading = raw_compass: one "
        "sample's noise and the compass's lag are larger) both of the above are this"})
    gyro_vote: bool = field(default=False, metadata={
        "doc": "the FIR's third vote may blame the gyro (off: it sided with slow drifts)"})
    gyro_vote_gate_deg: float = field(default=1.0, metadata={
        "gt": 0.0, "unit": "σ", "doc": "the FIR's vote blames the gyro only beyond this many σ "
                                       "of the witness's innovation"})
    gyro_hold_samples: int = field(default=5, metadata={
        "ge": 0, "unit": "samples", "doc": "a missing rate is replaced by the last one for at "
                                           "most this many samples"})

    def witness_params(self) -> WitnessParams:
        """The witness's parameters: each ``gyro_X`` key is ``WitnessParams.X``."""
        return WitnessParams(**{f.name: getattr(self, "gyro_" + f.name)
                                for f in fields(WitnessParams)})


@dataclass(frozen=True)
class HeadingDecision:
    """One period's heading decision: the heading to use (the compass's or the
    substitute's), its source, the detector's state and statistics (the FIR's predicted increment
    ``d_deg``, its error ``e2`` in deg², the weight-drift SNR ``R(k)`` and ``V``), and the event of
    this period."""
    heading_used: float | None  # deg in [0, 360), None: no heading this period
    source: Source
    state: State
    d_deg: float  # predicted increment, deg
    e2: float  # deg^2
    snr: float  # R(k)
    V: float
    suspect: bool  # criterion 1 open
    fault: bool  # confirmed fault being handled
    kind: str  # "", "sensor" (dual criterion) or "stuck"
    event: str  # "", "suspect", "confirmed", "dismissed", "stuck", "compensating",
    #             "fallback", "recovered"


class FaultTolerantHeading:
    """The compass FDI and substitution logic; ``enabled=False`` detects but never substitutes."""

    def __init__(self, det_cfg: DetectorConfig, ft_cfg: FtConfig, enabled: bool = True):
        self.det = DualCriterionDetector(det_cfg)
        self.cfg = ft_cfg
        self.enabled = enabled
        self.state: State = "normal"
        self.kind = ""
        self._y_raw: float | None = None  # last reading, deg
        self._y: float = 0.0  # unwrapped last reading
        self._used: float | None = None  # unwrapped last heading used
        self._psi = 0.0  # FIR heading (unwrapped)
        self._offset: list[float] = []
        self._bias = 0.0
        self._ok = 0
        self._run = 0
        self._snap: list[float] = []
        self._run_start_y = 0.0
        self._run_pred = 0.0
        self._hf: float | None = None  # model-aided smoothed heading (unwrapped), deg
        # The gyro witness (used while a yaw rate arrives) and the FIR's third vote.
        self.witness = GyroWitness(ft_cfg.witness_params())
        self._gyro_mode = False
        self._gyro_stale = False  # the gyro was lost: restart the witness on its return
        self.gyro_failed = False  # the vote blamed the gyro: no witness from then on
        self._last_rate: float | None = None
        self._rate_age = 0
        self._vote_C: list[float] = []
        # at the suspect: compass minus gyro heading (mean of 5); then the sums since of the
        # gyro's and the stored FIR's increments
        self._vote = [0.0, 0.0, 0.0]
        self._nu_o: deque[float] = deque(maxlen=5)  # compass minus gyro heading, newest
        self._turn_left_s = 0.0  # time left of the window after a setpoint change
        self._level_run = 0  # suspect samples in a row the reading is level_sigmas off
        self._level_pos = False  # ... on the positive side

    def setpoint_changed(self) -> None:
        """The heading setpoint was changed (a commanded turn): on the FIR path, theta is
        raised by ``turn_theta_factor`` for ``turn_window_s`` (the FIR's prediction error is
        largest while the command is large and changing; a turn's weight change on a noisy
        compass otherwise passed criterion 2). The gyro witness does not need it."""
        self._turn_left_s = self.cfg.turn_window_s

    def step(
        self,
        u_prev: float,
        heading_meas: float | None,
        yaw_rate_dps: float | None = None,
        dt: float = 0.2,
        heading_suspect: bool = False,
    ) -> HeadingDecision:
        """One period: the command sent in the last one (%), the compass (deg or None) and,
        when the vehicle has one, its yaw-rate gyro (deg/s or None).

        ``heading_suspect``: the driver flagged this reading as a jump faster than the vehicle
        can turn. Without a gyro it opens criterion 1 at once (:meth:`DualCriterionDetector.step`)
        and this sample is substituted by the model-predicted heading even when
        ``substitute_while_suspect`` is off; confirmation still needs criterion 2. With a gyro
        the witness's own jump test judges (``jump_sigmas``) and the flag is not used."""
        rate = yaw_rate_dps
        if rate is not None and not math.isfinite(rate):
            rate = None
        if self.cfg.gyro_enabled and not self.gyro_failed:
            if rate is not None:
                self._last_rate, self._rate_age = rate, 0
            elif self._last_rate is not None and self._rate_age < self.cfg.gyro_hold_samples:
                self._rate_age += 1
                rate = self._last_rate
            if rate is not None:
                return self._step_gyro(u_prev, heading_meas, rate, dt)
            if self._gyro_mode:
                self._leave_gyro()
        turning = self._turn_left_s > 1e-9
        self.det.theta_scale = self.cfg.turn_theta_factor if turning else 1.0
        if turning:
            self._turn_left_s -= dt
        return self._step_fir(u_prev, heading_meas, heading_suspect)

    def _step_fir(
        self, u_prev: float, heading_meas: float | None, flagged: bool = False
    ) -> HeadingDecision:
        det = self.det
        det.push_command(u_prev)
        substituting = self.state != "normal"
        if heading_meas is None or not math.isfinite(heading_meas):
            r = det.step(None)
            if substituting:
                self._psi += r.d_deg
            self._y_raw = None  # resync on the next reading
            return self._decide(None, r.d_deg, 0.0, 0.0, 0.0, "")
        if self._y_raw is None:
            if self._used is None:
                self._y = heading_meas
            else:  # after a gap: continue the unwrapped track near the last used heading
                self._y = self._used + wrap180(heading_meas - self._used)
            self._y_raw = heading_meas
            self._hf = self._y
            r = det.step(None)
            if substituting:
                self._psi += r.d_deg
            return self._decide(self._y, r.d_deg, 0.0, 0.0, 0.0, "")
        dy = wrap180(heading_meas - self._y_raw)
        self._y_raw = heading_meas
        y_prev = self._y
        self._y += dy
        self._stuck_run(dy, y_prev, det.predict_deg())
        r = det.step(dy, flagged)
        event = self._fir_transition(r, y_prev)
        stuck = self.cfg.stuck_samples and self._run >= self.cfg.stuck_samples
        if stuck and self.state in ("normal", "suspect"):
            event = self._fir_stuck()
        return self._decide(self._y, r.d_deg, r.e2, r.snr, r.V, event, flagged)

    def _stuck_run(self, dy: float, y_prev: float, d_live: float) -> None:
        """Stuck reading: a run of identical values, with a snapshot of the weights when it
        began (the stored ones while a suspect is open) and the live FIR's prediction since."""
        det = self.det
        if not (self.cfg.stuck_samples and abs(dy) <= self.cfg.stuck_eps_deg):
            self._run = 0
            return
        if self._run == 0:
            if det.suspect_open and det.stored:
                self._snap = list(det.stored)
            else:
                self._snap = list(det.fir.C_avg if det.fir.avg_alpha else det.fir.C)
            self._run_start_y = y_prev
            self._run_pred = 0.0
        self._run += 1
        self._run_pred += d_live

    def _fir_transition(self, r: DetectorStep, y_prev: float) -> str:
        """The FIR path's state after the detector's step: normal -> suspect (criterion 1),
        suspect -> confirmed (criterion 2, or the level held) or dismissed, a fault's own
        step; the event's name ("" for none)."""
        det = self.det
        if self.state == "normal":
            # Substitution starts from a smoothed heading, not from one noisy reading:
            # hf(k) = hf(k-1) + d(k) + L (y(k) - hf(k-1) - d(k)).
            pred = (self._hf if self._hf is not None else y_prev) + r.d_deg
            if r.suspect and r.exceed:
                self.state = "suspect"
                self._psi = pred
                self._level_run = 0
                self._level_held()
                return "suspect"
            self._hf = pred + self.cfg.smooth_gain * (self._y - pred)
            return ""
        if self.state == "suspect":
            self._psi += r.d_deg if det.stored is None else self._stored_pred_deg()
            if r.confirmed or self._level_held():
                if not r.confirmed:
                    det.close_suspect()
                self._confirm("sensor")
                return "confirmed"
            if r.dismissed:
                self.state = "normal"
                self._hf = self._psi
                return "dismissed"
            return ""
        self._psi += r.d_deg  # frozen detector = stored model
        return self._fault_step(r.exceed, r.e2)

    def _fir_stuck(self) -> str:
        """A stuck run long enough: the FIR frozen on the snapshot, the substitute its dead
        reckoning from where the run began."""
        det = self.det
        if det.suspect_open:
            det.dismiss()
        det.force_store(self._snap)
        det.fir.set_weights(self._snap)
        det.freeze()
        self._psi = self._run_start_y + self._run_pred
        self.state = "fault_fir"
        self.kind = "stuck"
        self._offset = []
        self._ok = 0
        return "stuck"

    # ------------------------------------------------------------------ with a yaw gyro

    def _step_gyro(
        self, u_prev: float, heading_meas: float | None, rate: float, dt: float
    ) -> HeadingDecision:
        """The gyro witness decides; the FIR keeps learning and gives the third vote."""
        det, w = self.det, self.witness
        det.push_command(u_prev)
        if not self._gyro_mode:
            self._enter_gyro()
        w.propagate(rate, dt)
        if heading_meas is None or not math.isfinite(heading_meas):
            r = det.step(None)
            self._y_raw = None
            w.short.restart()
            return self._decide_gyro(None, r.d_deg, 0.0, 0.0, 0.0, "")
        dy = self._follow_compass(heading_meas)
        d_stored = self._stored_pred_deg_from(self._vote_C) if self._vote_C else 0.0
        r = det.step(dy)
        if det.suspect_open and (w.suspect or w.fault):
            det.dismiss()  # the FIR's own criterion is not the judge here
        was_suspect = w.suspect
        ws = w.update(heading_meas, dt, repeating=self._run > 0)
        if ws.suspect and not was_suspect:  # open the vote: weights and sums from here
            self._vote_C = list(det.fir.C_avg if det.fir.avg_alpha else det.fir.C)
            self._vote = [sum(self._nu_o) / len(self._nu_o) if self._nu_o else 0.0, 0.0, 0.0]
            d_stored = 0.0
        if w.suspect and dy is not None:
            self._vote[1] += (rate - w.bias) * dt
            self._vote[2] += d_stored
        if w.psi is not None:
            self._nu_o.append(wrap180(heading_meas - w.psi))
        if ws.confirmed and self.cfg.gyro_vote and w.confirmed_fast and self._vote_blames_gyro():
            return self._gyro_blamed(heading_meas, r.d_deg, r.e2, r.snr, r.V)
        event = self._gyro_event(ws, was_suspect)
        return self._decide_gyro(self._y, r.d_deg, r.e2, ws.score, r.V, event)

    def _enter_gyro(self) -> None:
        """The first rate, or the rate back after a loss: restart the witness."""
        w = self.witness
        self._gyro_mode = True
        if self._gyro_stale and w.ready:
            w.fault = w.suspect = False
            w.clear()
            w.var.frozen = False
            w.psi = None
            self.state, self.kind = "normal", ""
            self.det.recover()
        self._gyro_stale = False

    def _follow_compass(self, heading_meas: float) -> float | None:
        """The unwrapped reading and the run of repeated ones; its change since the last
        reading (None after a gap)."""
        w, cfg = self.witness, self.cfg
        dy: float | None = None
        if self._y_raw is not None:
            dy = wrap180(heading_meas - self._y_raw)
            self._y += dy
        else:
            ref = w.psi if w.psi is not None else self._used
            self._y = heading_meas if ref is None else ref + wrap180(heading_meas - ref)
        self._y_raw = heading_meas
        if cfg.stuck_samples and dy is not None and abs(dy) <= cfg.stuck_eps_deg:
            self._run += 1
        else:
            self._run = 0
        return dy

    def _gyro_event(self, ws: WitnessStep, was_suspect: bool) -> str:
        """The state after the witness's step, first that holds: confirmed, stuck (a run of
        repeated readings), recovered, dismissed, suspect; the event's name ("" for none)."""
        w, cfg, det = self.witness, self.cfg, self.det
        if ws.confirmed:
            self.state, self.kind = "fault_gyro", "sensor"
            det.freeze()
            return "confirmed"
        if cfg.stuck_samples and self._run >= cfg.stuck_samples and not w.fault:
            w.force_fault(self._run)
            self.state, self.kind = "fault_gyro", "stuck"
            det.freeze()
            return "stuck"
        if ws.recovered:
            self.state, self.kind = "normal", ""
            det.recover()
            return "recovered"
        if ws.dismissed:
            self.state = "normal"
            return "dismissed"
        if ws.suspect and not was_suspect:
            self.state = "suspect"
            return "suspect"
        return ""

    def _stored_pred_deg_from(self, C: list[float]) -> float:
        return self.det.fir.predict(C) * self.det.cfg.y_scale

    def _vote_blames_gyro(self) -> bool:
        """Third vote, from when the suspect opened: the gyro moved by ``dg`` since (the
        witness's dead reckoning), the stored FIR predicts ``dd``, the compass moved ``d_cg``
        from the gyro heading (mean of its last 5 innovations minus the same at the open). The
        gyro is blamed only if the FIR is closer to the compass than to the gyro by
        ``gyro_vote_gate_deg`` sigmas of the innovation; otherwise the compass is (the gyro is
        the better witness, and the FIR's model is the least exact of the three). Asked only
        for a fast confirmation: the FIR's bias tap learns a slow drift as a current, so for a
        ramp it would side with the drifting compass."""
        base, dg, dd = self._vote
        d_fg = dd - dg  # FIR heading minus gyro heading, moved since the suspect opened
        d_cg = (sum(self._nu_o) / len(self._nu_o) if self._nu_o else 0.0) - base
        margin = self.cfg.gyro_vote_gate_deg * self.witness.var.sigma
        return abs(d_cg - d_fg) + margin < abs(d_fg)

    def _gyro_blamed(
        self, heading_meas: float, d: float, e2: float, snr: float, V: float
    ) -> HeadingDecision:
        """The gyro is the odd one out: keep the compass, stop using the witness."""
        self.gyro_failed = True
        self._gyro_mode = False
        self.state, self.kind = "normal", ""
        self._hf = self._y
        self.det.recover()
        dec = self._decide(self._y, d, e2, snr, V, "gyro_fault")
        return dec

    def _leave_gyro(self) -> None:
        """The yaw rate stopped arriving: hand over to the FIR alone."""
        w = self.witness
        self._gyro_mode = False
        self._gyro_stale = True
        if w.psi is not None and (w.fault or w.suspect):
            self._psi = w.psi
            if self.det.stored is None:
                self.det.stored = list(self.det.fir.C_avg if self.det.fir.avg_alpha
                                       else self.det.fir.C)
            self.det.freeze()
            self.state = "fault_fir"
            self.kind = self.kind or "sensor"
        else:
            self.state, self.kind = "normal", ""
        if w.psi is not None:
            self._hf = w.psi

    def _decide_gyro(
        self, y: float | None, d: float, e2: float, score: float, V: float, event: str
    ) -> HeadingDecision:
        w = self.witness
        fault = self.state == "fault_gyro"
        used: float | None
        source: Source
        if not self.enabled:
            used, source = (y, "sensor") if y is not None else (None, "none")
        elif w.psi is not None:
            used, source = w.psi, ("fused" if self.state == "normal" else "gyro")
        elif y is not None:
            used, source = y, "sensor"
        else:
            used, source = None, "none"
        if used is not None:
            self._used = used
        return HeadingDecision(
            heading_used=None if used is None else used % 360.0,
            source=source,
            state=self.state,
            d_deg=d,
            e2=e2,
            snr=score,
            V=V,
            suspect=self.state == "suspect" or event == "suspect",
            fault=fault,
            kind=self.kind if fault else "",
            event=event,
        )

    # ------------------------------------------------------------------ FIR only

    def _level_held(self) -> bool:
        """No gyro, criterion 2's other way (``level_sigmas``): the reading has stayed
        ``level_sigmas`` sigma_e off the substitution heading (the FIR's dead reckoning from
        the smoothed heading at the suspect), on one side, for the detector's ``persist``
        samples, with no noise burst and no commanded turn in progress. A step leaves a
        level; a spike of fewer samples comes back. R(k) of a 20 deg step at 2 deg compass
        noise once stayed above n0 for 3 samples, not 4 (nonlinear plant, seed 8, after 1 h
        with turns): missed."""
        cfg, det = self.cfg, self.det
        if cfg.level_sigmas <= 0.0:
            return False
        resid = self._y - self._psi
        if abs(resid) >= max(cfg.level_sigmas * det.var.sigma, cfg.level_min_deg):
            same = self._level_run == 0 or (resid > 0.0) == self._level_pos
            self._level_run = self._level_run + 1 if same else 1
            self._level_pos = resid > 0.0
        else:
            self._level_run = 0
        return (self._level_run >= det.cfg.persist and det.theta_scale <= 1.0
                and not det.burst(cfg.level_burst_ratio))

    def _stored_pred_deg(self) -> float:
        assert self.det.stored is not None
        return self.det.fir.predict(self.det.stored) * self.det.cfg.y_scale

    def _confirm(self, kind: str) -> None:
        det = self.det
        if det.stored is not None:
            det.fir.set_weights(det.stored)
        det.freeze()
        self.state = "fault_fir"
        self.kind = kind
        self._offset = []
        self._ok = 0

    def _fault_step(self, jump: bool, e2: float = 0.0) -> str:
        cfg = self.cfg
        resid = wrap180(self._y - self._psi)
        if self.kind == "stuck" and cfg.stuck_recover_increments and self.state == "fault_fir":
            # A stuck compass that moves again, with increments the FIR predicts, is healthy:
            # take it back (the dead reckoning, not the compass, carries the error by then).
            if self._run == 0 and e2 <= self.det.theta:
                self._ok += 1
                if self._ok >= cfg.recover_samples:
                    self.det.recover()
                    self.state = "normal"
                    self._psi = self._y
                    self._hf = self._y
                    self.kind = ""
                    return "recovered"
            else:
                self._ok = 0
            return ""
        if self.state == "fault_comp":
            if jump or (cfg.stuck_samples and self._run >= cfg.stuck_samples):
                self.state = "fault_fir"
                self._offset = []  # _psi is already the last used heading + d(k)
                return "fallback"
            self._psi = self._y - self._bias
            return ""
        # fault_fir: recovery when the reading agrees with the FIR heading again.
        if abs(resid) < cfg.recover_gate_deg and self._run == 0:
            self._ok += 1
            if self._ok >= cfg.recover_samples:
                self.det.recover()
                self.state = "normal"
                self._hf = self._psi
                self.kind = ""
                return "recovered"
        else:
            self._ok = 0
        if cfg.offset_compensation and self.kind != "stuck":
            self._offset.append(resid)
            if len(self._offset) >= cfg.offset_samples:
                n = len(self._offset)
                m = sum(self._offset) / n
                sd = math.sqrt(sum((x - m) ** 2 for x in self._offset) / n)
                self._offset = []
                if sd < cfg.offset_max_std_deg and abs(m) >= cfg.recover_gate_deg:
                    self._bias = m
                    self._psi = self._y - m
                    self.state = "fault_comp"
                    return "compensating"
        return ""

    def _decide(
        self, y: float | None, d: float, e2: float, snr: float, V: float, event: str,
        flagged: bool = False,
    ) -> HeadingDecision:
        substituting = self.enabled and self.state != "normal"
        if not self.cfg.substitute_while_suspect and self.state == "suspect" and not flagged:
            substituting = False
        used: float | None
        source: Source
        if substituting:
            used = self._psi
            source = "compensated" if self.state == "fault_comp" else "fir"
        elif y is not None:
            used, source = y, "sensor"
        else:
            used, source = None, "none"
        if used is not None:
            self._used = used
        fault = self.state in ("fault_fir", "fault_comp", "fault_gyro")
        return HeadingDecision(
            heading_used=None if used is None else used % 360.0,
            source=source,
            state=self.state,
            d_deg=d,
            e2=e2,
            snr=snr,
            V=V,
            suspect=self.state == "suspect" or event == "suspect",
            fault=fault,
            kind=self.kind if fault else "",
            event=event,
        )
