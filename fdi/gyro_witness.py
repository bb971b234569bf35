"""A second, independent witness of the compass: the yaw-rate gyro (an extension of the paper).

Zhu, Chen & Liu (2009) detect a compass fault from the command FIR alone (eq. (3)-(12)); the FIR
sees a drift's onset only, and its dead reckoning drifts (~0.7 deg/s, ``FINDINGS.md``). With a
yaw-rate gyro the compass's heading increments are checked against the integrated rate, whose
drift is the error of the gyro bias estimate. Per period (``dt`` s; degrees, deg/s):

* propagation: ``psi^-(k) = psi(k-1) + (r(k) - b) dt`` (r the gyro, b its estimated bias);
  innovation ``nu(k) = wrap(y(k) - psi^-(k))`` (y the compass).
* Bias: the least-squares slope of ``z = y - sum(r dt)`` (``z = const - b t + noise``) over
  the warm-up, and, with forgetting (``bias_tau_s``), over the trusted samples of
  ``bias_delay_s`` ago, and over a compensated step's compass (the step's offset changes only
  its intercept): each segment its own intercept, the slopes combined by their information
  ``sum (t - mean t)^2``. The warm-up's line goes on with the later samples while the
  vehicle holds the heading it had at the warm-up's end (within ``bias_hold_deg``; closed for
  good at the first sample beyond, or at a confirmation): z is a line while the heading is
  held, and a real compass's deviation changes with heading, so a turn starts a new
  segment. The delay gives a slow drift that long
  to be detected before the bias absorbs it; the samples of a fault (from its estimated start
  minus ``test_tau_s``, or ``fast_margin_s`` for a step's or the hinge test's sharp onset) are
  never fed, nor, while the hinge test is halfway up, those of its hinge. At a confirmation
  the trusted samples still in the delay line are fed at once and the dead reckoning since
  the change is redone with the new bias (a step 15 s after the warm-up had its bias from
  the warm-up alone).
* Headings: ``psi = psi^- + alpha nu`` (nu clipped at ``clip`` sigmas), ``alpha =
  max(1/n, dt/heading_tau_s)``: the output. The test uses a second one, ``psi_t``, with the
  slower ``test_tau_s``, whose innovation a drift of rate rho moves by ``rho * test_tau_s``.
* Change test on ``s = (nu - nu_ref) / sigma``: ``nu_ref`` is the innovation's own slow mean
  (a running mean after the warm-up, then an EWMA over ``ref_tau_s``; it holds the steady
  offset a residual bias error leaves), ``sigma`` a robust running scale
  (:class:`fdi.noise_scale.RobustVariance`, from first differences during the warm-up); both
  frozen while a fault is suspected. Two two-sided CUSUMs (Page), each clipped,
  ``g+ = max(0, g+ + min(s, clip) - kappa)`` and the mirror ``g-``: a fast one (``kappa``,
  ``clip``, ``h``) for a level of several sigmas, and a slow one (``slow_*``) for a small level
  or a ramp. Since ``h > 3 (clip - kappa)``
  (likewise for the slow one), a spike of 1 to 3 samples cannot confirm, whatever its size.
* Suspect (the loops, the bias and sigma frozen; ``psi`` is gyro dead reckoning): fast CUSUM
  above ``h_suspect``, slow above ``slow_h / 2``, or ``|s| >= jump_sigmas``. Confirmed: either
  reaches its ``h`` and the innovations since the change began (Page's estimate: the last step
  the confirming CUSUM was 0; the newest 6) are a level or a ramp, their spread about a fitted
  line (without the one sample whose removal leaves the least spread) within
  ``spread_ratio`` sigmas, and, for the fast one, their mean at least ``step_min_deg`` off
  ``nu_ref`` (else the slow one judges: the first samples of a noise burst on one side look
  like a small step). Dismissed: the fast CUSUM
  back at 0 and the slow one under ``slow_h / 4``, or ``max_suspect_s`` elapsed.
* Noise burst: the trimmed short scale of the innovation's first differences
  (:class:`fdi.noise_scale.TrimmedScale`; it goes on across a manoeuvre: restarted at each,
  it never filled between the MANUAL limit cycle's kicks, and 3 deg bursts on ATTITUDE's
  yaw were confirmed as steps) above ``burst_ratio`` sigmas resets the CUSUMs,
  unless the last three innovations are one level beyond ``jump_sigmas`` sigmas and 3
  short-scale sigmas (same side, within 2.5 sigma of a difference of each other): a step,
  whose fast CUSUM is then rebuilt from those three (an earlier burst call may have reset it).
* Slow drifts (``drift_glr`` > 0): a hinge in ``z`` over ``drift_window_s``
  (:class:`HingeDrift`, a likelihood ratio against the straight line, the noise floored at
  ``drift_sigma_min_deg``): at ``drift_glr`` a drift is confirmed with its onset at the
  hinge. A 0.1 deg/s drift moves the CUSUMs' innovation by at most ``rho * test_tau_s``,
  which ``nu_ref`` and the bias fit follow; the hinge sees its whole length.
* At a confirmation the output loop's corrections since the change began are undone.
* Recovery: ``|nu| <= max(recover_gate, 3 sigma)`` for ``recover_samples`` periods with the
  compass alive (not repeating; the caller says so) and their mean within ``recover_gate``
  (a slow drift passing near the dead reckoning is not taken back); both headings are then
  re-aligned to the compass by that mean.

* Warm-up restart: three innovations in a row on one side beyond ``jump_sigmas`` sigmas
  (``sigma0_deg`` at least) during the warm-up are a step of the compass before it was ever
  trusted (ArduSub's EKF aligns its yaw, 0 -> 348.5 deg, about 1.6 s after boot): the warm-up
  starts again from the new level. Fitted as a slope, that step made a 1.6 deg/s "bias" on a
  gyro whose true bias was under 0.01 deg/s, and the dead reckoning then drifted 1 deg/s
  (``../shared/corpus/ardusub-sitl``).
* Manoeuvres: a period whose dead reckoning may be off the compass by more than
  ``maneuver_deg`` for reasons that are not a fault -- the compass's lag behind the gyro
  (``maneuver_lag_s`` x |r|: ArduSub's RAW_IMU compass trails its gyro by 0.12-0.17 s, 9.5
  deg at 77 deg/s) or the integration of a rate sampled once or twice a period (``dt`` x
  |r(k) - r(k-1)|: ArduSub's yaw rate steps from 2 to 77 deg/s between two samples) -- and
  the ``maneuver_settle`` periods after it are not tested, not fitted and do not move the
  loops (the gyro carries the headings through); at its end the test innovation's change
  across it (from the last tested one before it) beyond ``maneuver_dead_deg`` is taken into
  both headings if within the integration bound accumulated over it (sum of
  ``maneuver_sample_s / 2`` x |r(k) - r(k-1)|: a rate step between two samples), so that a
  fast turn's sampling error (~1 deg at ArduSub's 77 deg/s) is not a fault; a change within
  the dead band, or beyond the bound (a step, a noise burst's sample), is left to the test.
  The dead band (times ``maneuver_deg`` / the bound where smaller: a large bound is a fast
  turn, whose change is sampling; never below ``maneuver_dead_min_deg``, a raw compass's
  sample noise) protects a fault's increments: the MANUAL limit cycle kicks the vehicle every ~2 s,
  and a correction of the innovation's whole level (not its change) took a 0.3 deg/s ramp
  into the dead reckoning kick after kick (never confirmed, 61 deg off); with a raw compass
  one noisy sample (1.4 deg) once went in and was then confirmed as a fault. What is taken is
  undone with the loop's corrections at a confirmation, and goes into the bias fit's z too
  (z stays one line through a turn).
  Not while a fault is suspected: the innovation then holds
  the suspected fault (on ArduSub's MANUAL dead band the hold kicks every ~2 s, each kick a
  manoeuvre, and their ends took a 30 deg step into the headings before it was confirmed).
  Nor during a fault, but for a step's offset compensation once its offset is known: the
  compass minus the offset steers then as a healthy compass does, and a 57-77 deg/s turn's
  ~0.8 deg of sampling error, left in the compensated innovation, was taken by the
  compensation's slow CUSUM for a drift of the compass and ended it (ArduSub, 30 deg steps:
  4 of 10 compensations ended, each handed back to the pilot 120 s later).
* Warm-up's end: both headings aligned to the compass by the mean of its last 10
  innovations when beyond 3 sigma of that mean (the loops converge as a running mean, so
  a late turn's integration error was still in them and the test began on it).
* Offset compensation (``comp_samples`` > 0) after a step confirmed by the fast CUSUM: the
  compass minus its offset, once the offset is known to be a level, steers ``psi`` again
  (:meth:`GyroWitness._compensate`), so that the dead reckoning's drift stays bounded.

The heading to use is ``psi`` at every step: the filtered compass when it is trusted, the gyro
dead reckoning from the last trusted state when it is not, so switching is bumpless.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from fdi.noise_scale import RobustVariance, TrimmedScale


def _wrap180(a: float) -> float:
    a = math.fmod(a + 180.0, 360.0)
    if a <= 0.0:
        a += 360.0
    return a - 180.0


def _line_residuals(x: list[float], t: list[float] | None = None) -> list[float]:
    """Residuals of the least-squares line through (t, x) (t = 0, 1, ... by default)."""
    ts = t if t is not None else [float(i) for i in range(len(x))]
    n = len(x)
    mt = sum(ts) / n
    mx = sum(x) / n
    stt = sum((ti - mt) ** 2 for ti in ts)
    slope = sum((ti - mt) * (xi - mx) for ti, xi in zip(ts, x, strict=True)) / stt
    return [xi - mx - slope * (ti - mt) for ti, xi in zip(ts, x, strict=True)]


def _rss(A: list[list[float]], b: list[float], yy: float) -> float:
    """Residual sum of squares of the least squares with normal equations ``A x = b`` and
    ``yy = sum y^2``: ``yy - x . b`` (Gaussian elimination with pivoting; inf if singular)."""
    m = len(b)
    M = [[*row, b[i]] for i, row in enumerate(A)]
    for c in range(m):
        piv = max(range(c, m), key=lambda r: abs(M[r][c]))
        if abs(M[piv][c]) < 1e-9 * (abs(M[c][c]) + 1.0):
            return math.inf
        M[c], M[piv] = M[piv], M[c]
        for r in range(c + 1, m):
            f = M[r][c] / M[c][c]
            for j in range(c, m + 1):
                M[r][j] -= f * M[c][j]
    x = [0.0] * m
    for r in range(m - 1, -1, -1):
        x[r] = (M[r][m] - sum(M[r][j] * x[j] for j in range(r + 1, m))) / M[r][r]
    return yy - sum(x[i] * b[i] for i in range(m))


class HingeDrift:
    """A slow compass drift against the integrated gyro over a long window.

    ``z = y - sum r dt`` is ``a - b t + noise`` while the compass is healthy (b the gyro
    bias). Over the newest ``window`` samples the line is fitted, and for a lag L (samples) of
    ``lags`` the hinge ``a - b t + rho max(0, t - t0)``, t0 the time of the L-th newest
    sample; the generalised likelihood ratio of the hinge is ``(RSS_line - RSS_hinge) /
    sigma^2`` (chi^2 with 1 dof for a fixed L under no drift). A ramp of rate rho over T s at
    n samples a second gives roughly ``0.4 rho^2 n T^3 / 12 / sigma^2`` (0.1 deg/s, 1 deg,
    5 Hz, 30 s: ~45). One lag is evaluated a step, in turn. The sums are running sums (add
    the newest, subtract the one leaving), rebuilt from the buffer every ``window`` samples
    about its oldest sample, so that their rounding does not accumulate."""

    def __init__(self, window: int, lags: tuple[int, ...], min_baseline: int | None = None
                 ) -> None:
        if not lags or max(lags) >= window:
            raise ValueError("HingeDrift: lags must be non-empty and shorter than the window")
        self.window = window
        self.lags = lags
        # a lag L is tested once L + min_baseline samples are in (None: 2 L, or the window)
        self.min_baseline = min_baseline
        self._buf: deque[tuple[float, float]] = deque()  # (t, z) about the reference
        self._ref = (0.0, 0.0)
        self._S = [0.0] * 6  # 1, t, t^2, z, t z, z^2 over the window
        self._L = [[0.0] * 5 for _ in lags]  # 1, t, t^2, z, t z over the newest L samples
        self._stats = [0.0] * len(lags)
        self._i = 0
        self._pushes = 0

    def clear(self) -> None:
        self._buf.clear()
        self._S = [0.0] * 6
        self._L = [[0.0] * 5 for _ in self.lags]
        self._stats = [0.0] * len(self.lags)
        self._pushes = 0

    def __len__(self) -> int:
        return len(self._buf)

    @staticmethod
    def _add(S: list[float], t: float, z: float, sign: float) -> None:
        S[0] += sign
        S[1] += sign * t
        S[2] += sign * t * t
        S[3] += sign * z
        S[4] += sign * t * z
        if len(S) > 5:
            S[5] += sign * z * z

    def _rebuild(self) -> None:
        t_r, z_r = self._buf[0]
        pts = [(t - t_r, z - z_r) for t, z in self._buf]
        self._ref = (self._ref[0] + t_r, self._ref[1] + z_r)
        self._buf = deque(pts)
        self._S = [0.0] * 6
        for t, z in pts:
            self._add(self._S, t, z, 1.0)
        for j, L in enumerate(self.lags):
            self._L[j] = [0.0] * 5
            for t, z in pts[-L:]:
                self._add(self._L[j], t, z, 1.0)

    def push(self, t_abs: float, z_abs: float) -> None:
        if not self._buf:
            self._ref = (t_abs, z_abs)
        t, z = t_abs - self._ref[0], z_abs - self._ref[1]
        self._buf.append((t, z))
        self._add(self._S, t, z, 1.0)
        n = len(self._buf)
        for j, L in enumerate(self.lags):
            self._add(self._L[j], t, z, 1.0)
            if n > L:
                to, zo = self._buf[n - 1 - L]
                self._add(self._L[j], to, zo, -1.0)
        if n > self.window:
            to, zo = self._buf.popleft()
            self._add(self._S, to, zo, -1.0)
        self._pushes += 1
        if self._pushes % self.window == 0:
            self._rebuild()

    def test(self, sigma: float, prior: tuple[float, float] | None = None) -> tuple[float, int]:
        """Evaluate the next lag; ``(ratio, lag)``, the largest of the lags' latest ratios.

        ``prior = (beta0, info)``: the line's slope is also known from elsewhere as beta0 with
        the information ``info`` (s^2, as ``sum (t - mean t)^2`` of samples with this noise):
        both fits get the pseudo-observation, i.e. the window is fitted jointly with that
        other segment (its own intercept, the slope shared)."""
        j = self._i % len(self.lags)
        self._i += 1
        L = self.lags[j]
        stat = 0.0
        n = len(self._buf)
        need = min(self.window, 2 * L if self.min_baseline is None else L + self.min_baseline)
        if n >= need:
            N, St, Stt, Sz, Stz, Szz = self._S
            if prior is not None:  # + info (beta - beta0)^2 in both residual sums
                Stt += prior[1]
                Stz += prior[1] * prior[0]
                Szz += prior[1] * prior[0] ** 2
            m, s1, s2, sz, stz = self._L[j]
            t0 = self._buf[n - L][0]
            h1 = s1 - t0 * m  # sums of h = t - t0 over the newest L samples
            h2 = s2 - 2.0 * t0 * s1 + t0 * t0 * m
            ht = s2 - t0 * s1
            hz = stz - t0 * sz
            line = _rss([[N, St], [St, Stt]], [Sz, Stz], Szz)
            hinge = _rss([[N, St, h1], [St, Stt, ht], [h1, ht, h2]], [Sz, Stz, hz], Szz)
            if math.isfinite(line) and math.isfinite(hinge):
                stat = max(0.0, line - hinge) / (sigma * sigma)
        self._stats[j] = stat
        k = max(range(len(self.lags)), key=lambda i: self._stats[i])
        return self._stats[k], self.lags[k]


@dataclass(frozen=True)
class WitnessParams:
    """The witness's parameters (the ``gyro_*`` keys of the ``[ft]`` table)."""

    heading_tau_s: float = 10.0  # time constant of the output heading's loop
    test_tau_s: float = 30.0  # time constant of the test heading's loop
    bias_tau_s: float = 600.0  # forgetting of the bias fit
    bias_delay_s: float = 15.0  # the bias fit uses trusted samples this old
    ref_tau_s: float = 60.0  # the slow mean of the innovation
    max_suspect_s: float = 20.0  # a suspect not confirmed by then is dismissed
    sigma0_deg: float = 1.0  # initial innovation sigma
    sigma_min_deg: float = 0.2  # floor of sigma
    sigma_samples: int = 150  # EWMA length of sigma^2
    clip: float = 4.5  # fast CUSUM: score clip, sigmas
    kappa: float = 1.5  # fast CUSUM: drift, sigmas
    h: float = 11.0  # fast CUSUM: confirmation level (> 3 (clip - kappa))
    slow_clip: float = 2.5
    slow_kappa: float = 0.75
    slow_h: float = 20.0
    h_suspect: float = 3.0
    jump_sigmas: float = 4.0
    burst_ratio: float = 2.5
    spread_ratio: float = 1.6
    step_min_deg: float = 3.5  # the fast CUSUM confirms a level only this far off (0: any)
    warmup_samples: int = 100
    recover_gate_deg: float = 1.5
    recover_samples: int = 10
    comp_samples: int = 50  # after a step's confirmation: the offset learned over this many
    comp_max_slope_dps: float = 0.25  # ... if a level (slope within this); 0 samples: off
    fast_margin_s: float = 2.0  # a step's compass is trusted up to this before its change
    drift_window_s: float = 90.0  # the hinge test's window (lags 1/8 .. 6/8 of it)
    drift_glr: float = 30.0  # its confirmation level (likelihood ratio; 0: off)
    drift_sigma_min_deg: float = 0.75  # its noise floor (the integrated gyro noise's walk)
    drift_max_turn_deg: float = 10.0  # ... only while the heading spans at most this
    bias_hold_deg: float = 10.0  # the warm-up's line goes on while the heading stays this near
    comp_drift_glr: float = 30.0  # the hinge test on the compensated compass (0: off)
    comp_drift_bias_sd_dps: float = 0.005  # ... the bias before it known to no better than this
    drift_recover_s: float = 20.0  # after it, the compass taken back only once the slope of
    drift_recover_max_dps: float = 0.05  # ... its innovation over this long is within this
    maneuver_lag_s: float = 0.15  # the compass's lag behind the gyro (a bound), s
    maneuver_deg: float = 1.0  # a period whose lag + sampling bound exceeds this: a manoeuvre
    maneuver_settle: int = 2  # periods after a manoeuvre still carried by the gyro alone
    maneuver_sample_s: float = 0.1  # the rate's sampling interval (its error bound: half of it
    #                                 times each rate change), s
    maneuver_dead_deg: float = 0.5  # a manoeuvre's end leaves a change within this to the test
    #                                 (times maneuver_deg / its bound where that is larger) ...
    maneuver_dead_min_deg: float = 0.0  # ... and within this (one compass sample's noise)


@dataclass(frozen=True)
class WitnessStep:
    """What the witness concluded at step k."""

    psi: float  # heading to use (unwrapped), deg
    nu: float  # innovation, deg
    score: float  # max of the CUSUMs, each over its confirmation level (1 = confirms)
    sigma: float  # innovation sigma, deg
    suspect: bool
    confirmed: bool  # edge
    dismissed: bool  # edge
    recovered: bool  # edge
    burst: bool


class GyroWitness:
    """Compass against the integrated yaw rate (module docstring)."""

    def __init__(self, p: WitnessParams) -> None:
        self.p = p
        self.psi: float | None = None  # unwrapped heading estimate (the output), deg
        self.psi_t = 0.0  # the same with the test's slower loop, deg
        self.bias = 0.0  # deg/s
        self._G = 0.0  # raw integrated rate, deg
        self._lam = 1.0
        self._S = [0.0, 0.0, 0.0, 0.0, 0.0]  # warm-up sums: 1, t, t^2, z, t z
        self._Sp = [0.0, 0.0, 0.0, 0.0, 0.0]  # after the warm-up (delayed), with forgetting
        self._Sf = [0.0, 0.0, 0.0, 0.0, 0.0]  # a compensated step's compass (delayed)
        self._comp_delayed: deque[tuple[float, float]] = deque()  # (t, z) not yet fed
        self.info = 0.0  # the bias fit's slope information, s^2 (bias sd = sigma/sqrt(info))
        self.hinge: HingeDrift | None = None  # made at the first test (the period known)
        self._hinge_c: HingeDrift | None = None  # ... the one under a step's compensation
        self.drift_stat = 0.0  # the hinge test's ratio, this step
        self._drift_lag = 0  # ... and its lag (samples)
        self._recover_mean = p.recover_gate_deg  # the recovery's gate on the mean, deg
        # the output heading over the hinge window: monotonic deques of (k, psi) for max/min
        self._hmax: deque[tuple[int, float]] = deque()
        self._hmin: deque[tuple[int, float]] = deque()
        self._delayed: deque[tuple[float, float, bool, float]] = deque()  # (t, z, trusted, psi)
        # the warm-up's line goes on with the later samples while the heading stays within
        # bias_hold_deg of this (the heading at the warm-up's end); None: closed
        self._hold_ref: float | None = None
        self._dt = 0.2
        self.var = RobustVariance(p.sigma0_deg**2, p.sigma_samples, 3.0, p.sigma_min_deg**2,
                                  reject_sigmas=4.0)
        self.short = TrimmedScale(8, 3)  # a step with an outlier in it: 3 large differences
        self.g_pos = 0.0
        self.g_neg = 0.0
        self.gs_pos = 0.0
        self.gs_neg = 0.0
        self.k = 0  # steps with a compass reading since start
        self.t = 0.0  # s since start
        self.suspect = False
        self.fault = False
        # innovations (output, test) while the compass agrees again after a fault
        self._agree: deque[tuple[float, float]] = deque(maxlen=p.recover_samples)
        # after a drift under a compensation: (t, nu_o clipped at the gate) of the live
        # compass, and whether the recovery also needs it to have stopped (_not_drifting)
        self._agree_long: deque[tuple[float, float]] = deque()
        self._recover_still = False
        self._run: deque[tuple[int, float]] = deque(maxlen=10)  # the last innovations
        self.nu_ref = 0.0
        self._suspect_k = 0
        self.confirmed_fast = False  # the last confirmation came from the fast CUSUM
        self._nu_prev: float | None = None
        self._x_last: deque[float] = deque(maxlen=3)  # normalised innovations (burst test)
        self._ref_n = 0
        # Page's change-time estimate: the last step at which each CUSUM side was 0, and the
        # output loop's corrections since, undone at a confirmation.
        self._zero_at = [0, 0, 0, 0]  # fast +, fast -, slow +, slow -
        self._corr: deque[tuple[int, float]] = deque(maxlen=600)
        # Offset compensation after a step: (t, nu_o) since the confirmation, the offset once
        # learned, whether this fault may be compensated, and the CUSUMs that watch it.
        self._comp: list[tuple[float, float, float]] = []  # (t, nu_o, z)
        self.offset: float | None = None
        self._comp_ok = False
        self._gc = [0.0, 0.0]
        self._comp_prior: tuple[float, float] | None = None  # (z's slope, info) before it
        # Manoeuvres (module docstring): this period's and the last rate, the periods still
        # to settle, and the integration bound accumulated since the manoeuvre began (deg).
        self._r: float | None = None
        self._r_prev: float | None = None
        self._man_left = 0
        self._man_bound = 0.0
        self.maneuvers = 0  # manoeuvres carried by the gyro alone (for the summary)
        self._warm_nu: deque[float] = deque(maxlen=3)  # the warm-up's last innovations
        self.warmup_restarts = 0
        self._nu_pre: float | None = None  # the test's innovation before the manoeuvre
        # the warm-up's last innovations (output, test): the offset left at its end
        self._warm_end: deque[tuple[float, float]] = deque(maxlen=10)

    @property
    def ready(self) -> bool:
        return self.psi is not None

    def propagate(self, rate_dps: float, dt: float) -> None:
        """Advance ``psi`` by the gyro over the period (no compass needed)."""
        if self.psi is not None:
            step = (rate_dps - self.bias) * dt
            self.psi += step
            self.psi_t += step
        self._G += rate_dps * dt
        self._r_prev, self._r = self._r, rate_dps
        self.t += dt
        self._lam = 1.0 - dt / self.p.bias_tau_s
        self._dt = dt

    def reset(self, heading_deg: float) -> None:
        self.psi = self.psi_t = heading_deg
        self.short.restart()

    def update(self, y_deg: float, dt: float, repeating: bool = False) -> WitnessStep:
        """The compass reading of this period (after :meth:`propagate`): a manoeuvre is
        carried by the gyro, the warm-up fits, a fault waits for the compass to agree again,
        and otherwise the change test runs (module docstring, in that order)."""
        p = self.p
        if self.psi is None:
            self.psi = self.psi_t = y_deg
            return WitnessStep(y_deg, 0.0, 0.0, self.var.sigma, False, False, False, False,
                               False)
        nu_o = _wrap180(y_deg - self.psi)
        self._y_unw = self.psi + nu_o
        nu = _wrap180(y_deg - self.psi_t)
        # a step's compensation steers on the compass minus its offset as on a healthy
        # compass, so a manoeuvre is carried and its end taken in as then: a 57-77 deg/s
        # turn's sampling left ~0.8 deg in the compensated innovation, which its slow CUSUM
        # took for a drift of the compass, ending the compensation
        carried = not self.fault or self.offset is not None
        if not carried:
            self._man_bound, self._man_left = 0.0, 0
        elif self._maneuvering(dt):
            return self._carry(nu)
        if self._man_bound > 0.0:
            nu_o, nu = self._maneuver_end(nu_o, nu)
        self._nu_pre = nu  # the last tested innovation before a manoeuvre
        if self.k < p.warmup_samples and self._warmup_step(nu_o, y_deg):
            return WitnessStep(y_deg, 0.0, 0.0, self.var.sigma, False, False, False, False,
                               False)
        if self.k >= p.warmup_samples:
            self._feed_bias_fit()
        self.short.push(nu)
        self.k += 1
        if self.k <= p.warmup_samples:
            return self._warmup_update(nu_o, nu, dt)
        if self.fault:
            return self._fault_update(nu_o, nu, repeating)
        return self._test(nu_o, nu, y_deg, dt)

    def _carry(self, nu: float) -> WitnessStep:
        """A manoeuvre's period, carried by the gyro alone: nothing tested, fitted or
        corrected (module docstring); the burst test's short scale goes on across it."""
        assert self.psi is not None
        if self.k >= self.p.warmup_samples:
            self._delayed.append((self.t, self._y_unw - self._G, False, self.psi))
        self._nu_prev = None
        return WitnessStep(self.psi, nu, 0.0, self.var.sigma, self.suspect, False, False,
                           False, False)

    def _feed_bias_fit(self) -> None:
        """This sample into the bias fit's delay line (trusted: set by :meth:`_correct`), and
        the samples ``bias_delay_s`` old out of it into the fit, but for those of a fault and,
        while the hinge test is halfway up, of its hinge."""
        p = self.p
        assert self.psi is not None
        self._delayed.append((self.t, self._y_unw - self._G, False, self.psi))
        t_h = math.inf
        if p.drift_glr > 0.0 and self.drift_stat >= 0.5 * p.drift_glr:
            t_h = self.t - self._drift_lag * self._dt - p.fast_margin_s
        while self._delayed and self._delayed[0][0] < self.t - p.bias_delay_s - 1e-9:
            t_old, z_old, ok, psi_old = self._delayed.popleft()
            if ok and not self.fault and t_old < t_h:
                self._fit(self._segment(psi_old), self._lam, t_old, z_old)

    def _warmup_update(self, nu_o: float, nu: float, dt: float) -> WitnessStep:
        """A warm-up sample: the loops and the fit converge, the drift test gets its first
        baseline, sigma comes from the first differences."""
        assert self.psi is not None
        sigma = self.var.sigma
        self._correct(nu_o, nu, dt, self.k)
        self._warm_end.append((nu_o, nu))
        if self.k == self.p.warmup_samples:
            self._end_warmup()
        if self.k > 10:  # the warm-up's compass is the drift test's first baseline
            self._drift_test(nu_o, sigma, False, True)
        # sigma from the first differences while the loops converge (a transient of the
        # heading or the bias does not inflate it; white noise: var(d nu) = 2 sigma^2)
        if self._nu_prev is not None:
            self.var.update((nu - self._nu_prev) / math.sqrt(2.0),
                            alpha=max(self.var.alpha, 1.0 / self.k))
        self._nu_prev = nu
        return WitnessStep(self.psi, nu, 0.0, sigma, False, False, False, False, False)

    def _fault_update(self, nu_o: float, nu: float, repeating: bool) -> WitnessStep:
        """During a fault: recovery once the compass agrees with the dead reckoning again and
        is alive; else the step's offset compensation, where it applies."""
        assert self.psi is not None
        sigma = self.var.sigma
        confirmed = False
        recovered = self._recovery(nu_o, nu, sigma, repeating)
        if not recovered and self._comp_ok:
            confirmed = self._compensate(nu_o, nu, sigma)
        elif recovered:
            self._end_comp(keep_segment=True)
        return WitnessStep(self.psi, nu, 0.0, sigma, self.suspect, confirmed, False,
                           recovered, False)

    def _recovery(self, nu_o: float, nu: float, sigma: float, repeating: bool) -> bool:
        """Recovery (module docstring): ``recover_samples`` innovations within the gate with
        the compass alive, their mean within the recovery's gate, and not drifting; then both
        headings re-aligned to the compass. True if it recovered now."""
        p = self.p
        assert self.psi is not None
        gate = max(p.recover_gate_deg, 3.0 * sigma)
        if abs(nu_o) <= gate and not repeating:
            self._agree.append((nu_o, nu))
        else:
            self._agree.clear()
        if repeating:
            self._agree_long.clear()
        elif self._recover_still:
            self._agree_long.append((self.t, max(-gate, min(gate, nu_o))))
            while self._agree_long[0][0] < self.t - p.drift_recover_s - 1e-9:
                self._agree_long.popleft()
        n_ok = len(self._agree)
        mean_o = sum(a for a, _ in self._agree) / n_ok if n_ok else 0.0
        if (n_ok < p.recover_samples or abs(mean_o) > self._recover_mean
                or not self._not_drifting()):
            return False
        self.fault = self.suspect = False
        self.clear()
        self._recover_mean = p.recover_gate_deg
        # Back on the compass: re-align both headings to it (the dead reckoning's error, at
        # most the gate), so that the test restarts from no offset.
        self.psi += mean_o
        self.psi_t += sum(b for _, b in self._agree) / n_ok
        self._agree.clear()
        self._agree_long.clear()
        self._recover_still = False
        return True

    def _test(self, nu_o: float, nu: float, y_deg: float, dt: float) -> WitnessStep:
        """The change test on the normalised innovation (module docstring): the CUSUMs, the
        burst test, the hinge test, then the decision and, unless suspect, the loops."""
        p = self.p
        sigma = self.var.sigma
        x = (nu - self.nu_ref) / sigma
        s = max(-p.clip, min(p.clip, x))
        self._step_cusums(x, s)
        burst = self._burst_test(sigma)
        fast = max(self.g_pos, self.g_neg)
        slow = max(self.gs_pos, self.gs_neg)
        level = max(fast / p.h, slow / p.slow_h)
        was = self.suspect
        self._run.append((self.k, nu))
        for i, g_i in enumerate((self.g_pos, self.g_neg, self.gs_pos, self.gs_neg)):
            if g_i == 0.0:
                self._zero_at[i] = self.k
        drift_lag = self._drift_test(nu_o, sigma, burst or abs(x) >= p.jump_sigmas,
                                     fast > p.h_suspect)
        suspicious = (fast > p.h_suspect or slow > 0.5 * p.slow_h or abs(s) >= p.jump_sigmas
                      or burst)
        confirmed, dismissed = self._decide(fast, slow, suspicious, drift_lag, was, y_deg,
                                            dt, sigma)
        self.var.frozen = self.suspect
        if not self.suspect:
            self._track(nu_o, nu, dt, sigma)
        assert self.psi is not None
        return WitnessStep(self.psi, nu, level, sigma, self.suspect, confirmed, dismissed, False,
                           burst)

    def _step_cusums(self, x: float, s: float) -> None:
        """Both two-sided CUSUMs (Page), the fast on ``s`` (clipped at ``clip``), the slow on
        ``x`` clipped at ``slow_clip``."""
        p = self.p
        self.g_pos = max(0.0, self.g_pos + s - p.kappa)
        self.g_neg = max(0.0, self.g_neg - s - p.kappa)
        xs = max(-p.slow_clip, min(p.slow_clip, x))
        self.gs_pos = max(0.0, self.gs_pos + xs - p.slow_kappa)
        self.gs_neg = max(0.0, self.gs_neg - xs - p.slow_kappa)
        self._x_last.append(x)

    def _burst_test(self, sigma: float) -> bool:
        """A noise burst (module docstring): the short scale above ``burst_ratio`` sigmas
        resets the CUSUMs, unless the last 3 innovations are one level beyond the jump test
        and 3 short-scale (the burst's) sigmas, on the same side and within the noise of each
        other (2.5 sigma of a difference): a step after a chance run of large differences (a
        10 deg step once waited 2 more samples; against sigma alone, 3 deg bursts that dwelt on
        one side confirmed; 4 short sigmas delayed 10 deg steps at 1 deg noise)."""
        p = self.p
        ss = self.short.sigma
        if not (self.short.full and ss > p.burst_ratio * sigma):
            return False
        xs3 = self._x_last
        lo = min(abs(v) for v in xs3) if len(xs3) == 3 else 0.0
        a_step = (lo >= p.jump_sigmas and lo * sigma >= 3.0 * ss
                  and (min(xs3) > 0.0 or max(xs3) < 0.0)
                  and max(xs3) - min(xs3) <= 2.5 * math.sqrt(2.0))
        if not a_step:
            self.clear()
            return True
        # a step whose second sample a burst call reset (seed 409, drift:-10@23): the fast
        # CUSUM as Page's would have it from these three
        g3 = sum(min(abs(v), p.clip) - p.kappa for v in xs3)
        if xs3[0] > 0.0 and g3 > self.g_pos:
            self.g_pos = g3
            self._zero_at[0] = self.k - 3
        elif xs3[0] < 0.0 and g3 > self.g_neg:
            self.g_neg = g3
            self._zero_at[1] = self.k - 3
        return True

    def _decide(self, fast: float, slow: float, suspicious: bool, drift_lag: int, was: bool,
                y_deg: float, dt: float, sigma: float) -> tuple[bool, bool]:
        """The decision, first rule that holds: (confirmed, dismissed).

        1. a CUSUM at its level (a level too small for a step: the slow one's) and the run
           since the change one level or ramp: confirmed, rolled back to Page's change time;
        2. the hinge test: a slow drift, confirmed from its hinge;
        3. a suspect older than ``max_suspect_s``: a steady offset the frozen loops cannot
           follow (their own dead-reckoning drift), dismissed;
        4. a CUSUM past its suspect level, a jump or a burst: suspect;
        5. a suspect whose fast CUSUM is back at 0 and slow one under a quarter: dismissed."""
        p = self.p
        conf_level = max(fast / p.h, slow / p.slow_h)
        if fast / p.h >= 1.0 and self._too_small_for_a_step():
            conf_level = slow / p.slow_h  # a level too small for a step: the slow CUSUM judges
        if conf_level >= 1.0 and self._spread_ok(sigma):
            self._open_fault(fast / p.h >= slow / p.slow_h)
            self._comp_ok = p.comp_samples > 0 and self.confirmed_fast
            return True, False
        if drift_lag:
            # the change began drift_lag samples ago, sharply
            self._open_fault(False, self.k - drift_lag)
            # a slow drift is small when found (0.05 deg/s: ~1.8 deg): taken back only once
            # the compass is back nearer than half of that (else it was taken back at once)
            assert self.psi is not None
            self._recover_mean = min(p.recover_gate_deg, 0.5 * abs(y_deg - self.psi))
            return True, False
        if was and self.k - self._suspect_k > p.max_suspect_s / dt:
            self.suspect = False
            self.clear()
            return False, True
        if suspicious:
            if not was:
                self._suspect_k = self.k
            self.suspect = True
            return False, False
        if was and fast == 0.0 and slow <= 0.25 * p.slow_h:
            self.suspect = False
            return False, True
        return False, False

    def _open_fault(self, fast: bool, k0: int | None = None) -> None:
        """A confirmation: the fault state, the output loop's corrections since the change
        undone (from ``k0``, sharply, for the hinge test), the compensation and the hinge
        restarted."""
        self.confirmed_fast = fast
        self.fault = self.suspect = True
        self._agree.clear()
        self._recover_still = False
        if k0 is None:
            self._rollback()
        else:
            self._rollback(k0, fast=True)
        self._end_comp()
        if self.hinge is not None:
            self.hinge.clear()

    def _track(self, nu_o: float, nu: float, dt: float, sigma: float) -> None:
        """Not suspect: the loops and the bias fit take the sample, sigma and the
        innovation's slow mean follow it (a running mean at first: the offset is learned as
        fast as the data allow)."""
        p = self.p
        self._correct(nu_o, nu, dt, 0)
        self.var.update(nu - self.nu_ref)
        d = max(-p.clip * sigma, min(p.clip * sigma, nu - self.nu_ref))
        self._ref_n += 1
        self.nu_ref += max(dt / p.ref_tau_s, 1.0 / (self._ref_n + 25)) * d

    def _end_warmup(self) -> None:
        """The warm-up's end: both headings aligned to the compass by the mean of its last
        innovations, if beyond the noise (the loops converge as a running mean, so a turn's
        integration error late in the warm-up was still ~1 deg in them, and the test began
        on that offset:
        ArduSub's EKF yaw on the calibrated simulator, 7 of 10 runs confirmed it)."""
        assert self.psi is not None
        n = len(self._warm_end)
        mean_o = sum(a for a, _ in self._warm_end) / n if n else 0.0
        # only an offset the noise cannot explain (3 sigma of the mean): else the loops'
        # running mean over the whole warm-up is the better estimate
        if n and abs(mean_o) > 3.0 * self.var.sigma / math.sqrt(n):
            self.psi += mean_o
            self.psi_t += sum(b for _, b in self._warm_end) / n
        if self.p.bias_hold_deg > 0.0:
            self._hold_ref = self.psi

    def _maneuver_end(self, nu_o: float, nu: float) -> tuple[float, float]:
        """The first period after a manoeuvre: its sampling error (within the bound, beyond
        the dead band) into both headings; the innovations (output, test) after it."""
        p = self.p
        assert self.psi is not None
        if self.suspect and self.offset is None:
            # the innovation holds the suspected fault, which the correction would take into
            # the headings (a limit cycle's manoeuvres every few seconds absorbed a 30 deg
            # step in 5 s)
            self._man_bound = 0.0
            return nu_o, nu
        # the innovation's change across the manoeuvre (a level it had before, a ramp's or a
        # fault's, is not the manoeuvre's); within the dead band: left to the test
        d = nu - (self.nu_ref if self._nu_pre is None else self._nu_pre)
        # the dead band shrinks as the sampling bound grows (a 77 deg/s turn's ~1 deg is
        # sampling; a kick's is not), never below the compass's own sample noise
        dead = max(p.maneuver_dead_min_deg,
                   p.maneuver_dead_deg * min(1.0, p.maneuver_deg / self._man_bound))
        d = math.copysign(max(0.0, abs(d) - dead), d)
        if abs(d) > self._man_bound:
            # beyond what the sampling can explain: not the manoeuvre's (a step, or a noise
            # burst's sample: its 3 deg once went in at a kick's end and was confirmed after)
            d = 0.0
        self._man_bound = 0.0
        self.psi += d
        self.psi_t += d
        self._corr.append((self.k, d))  # undone with the loop's if a fault began before
        self._G += d  # z = y - sum r dt goes on as one line: the bias fit sees no step
        self._y_unw = self.psi + nu_o - d
        return nu_o - d, nu - d

    def _maneuvering(self, dt: float) -> bool:
        """This period is a manoeuvre, or settles after one (module docstring); keeps the
        integration bound accumulated since the manoeuvre began."""
        p = self.p
        if self._r is None or p.maneuver_deg <= 0.0:
            return False
        dr = abs(self._r - self._r_prev) if self._r_prev is not None else 0.0
        # a rate step between two samples is integrated with an error of at most half the
        # sampling interval times the step (``maneuver_sample_s``)
        per = 0.5 * p.maneuver_sample_s
        if p.maneuver_lag_s * abs(self._r) + dt * dr > p.maneuver_deg:
            if self._man_left == 0 and self._man_bound == 0.0:
                self.maneuvers += 1
            self._man_left = p.maneuver_settle + 1
            self._man_bound += per * dr
        elif self._man_left > 0:  # settling: its rate changes still add to the bound
            self._man_bound += per * dr
        if self._man_left > 0:
            self._man_left -= 1
            self._man_bound = max(self._man_bound, 1e-9)  # > 0: the end is handled
            return True
        return False

    def _warmup_step(self, nu_o: float, y_deg: float) -> bool:
        """A step of the compass during the warm-up (module docstring): start it again from
        the new level; True if it did."""
        p = self.p
        self._warm_nu.append(nu_o)
        w = self._warm_nu
        gate = p.jump_sigmas * max(self.var.sigma, p.sigma0_deg)
        if (len(w) < 3 or min(abs(v) for v in w) <= gate
                or not (min(w) > 0.0 or max(w) < 0.0)):
            return False
        self.warmup_restarts += 1
        self.psi = self.psi_t = y_deg
        self.k = 0
        self._S = [0.0, 0.0, 0.0, 0.0, 0.0]
        self.bias = 0.0
        self.info = 0.0
        self._warm_nu.clear()
        self._nu_prev = None
        self.nu_ref = 0.0
        self._ref_n = 0
        self._corr.clear()
        self._hold_ref = None
        if self.hinge is not None:
            self.hinge.clear()
        self._hmax.clear()
        self._hmin.clear()
        self.short.restart()
        self.clear()
        return True

    def _drift_test(self, nu_o: float, sigma: float, skip: bool, step: bool,
                    glr: float | None = None, offset: float = 0.0,
                    prior: tuple[float, float] | None = None) -> int:
        """The hinge test (:class:`HingeDrift`) on ``z = y - sum r dt``, the compass clipped
        at ``clip`` sigmas of the output heading (outliers, spikes); the lag (samples) of a
        confirmed drift, else 0. The samples of a noise burst or a jump (``skip``: a spike,
        an outlier, a step's first sample; a slow drift never jumps) are not pushed; while a
        fast CUSUM is rising (``step``) the CUSUMs judge, not this test. Under a step's
        compensation ``nu_o`` is the compensated innovation, ``offset`` the step's and ``glr``
        the level (``comp_drift_glr``)."""
        p = self.p
        level = p.drift_glr if glr is None else glr
        if level <= 0.0 or skip:
            return 0
        lim = p.clip * sigma
        c_o = max(-lim, min(lim, nu_o))
        nw = max(12, round(p.drift_window_s / self._dt))
        if prior is None:
            if self.hinge is None:
                self.hinge = HingeDrift(nw, tuple(nw * i // 8 for i in range(1, 7)))
            hinge = self.hinge
        else:
            # under a compensation the window starts at the offset's learning and the slope
            # before the drift is known (the prior): the hinge is tested from one lag of
            # baseline on, at lags of 1/16 of the window (its onset undoes the corrections)
            if self._hinge_c is None:
                self._hinge_c = HingeDrift(nw, tuple(nw * i // 16 for i in range(1, 13)),
                                           min_baseline=nw // 16)
            hinge = self._hinge_c
        hinge.push(self.t, self._y_unw - offset - (nu_o - c_o) - self._G)
        stat, lag = hinge.test(max(sigma, p.drift_sigma_min_deg), prior)
        # Only while the vehicle holds its heading: z of a real compass is not a line across
        # turns (deviation with heading, an untilted magnetometer, the gyro's scale); on the
        # BlueROV2 dive z fell 7 deg in 15 s while the vehicle turned 11 deg, and the test
        # reached 40 at 192.8 s (nothing else shows a fault there). The window restarts when
        # the output heading over it spans more than drift_max_turn_deg.
        assert self.psi is not None
        k, h = self.k, self.psi
        while self._hmax and self._hmax[-1][1] <= h:
            self._hmax.pop()
        self._hmax.append((k, h))
        while self._hmin and self._hmin[-1][1] >= h:
            self._hmin.pop()
        self._hmin.append((k, h))
        for dq in (self._hmax, self._hmin):
            while dq[0][0] <= k - hinge.window:
                dq.popleft()
        if self._hmax[0][1] - self._hmin[0][1] > p.drift_max_turn_deg:
            # a turn: the window restarts from here (its line would bend across the turn)
            hinge.clear()
            self._hmax.clear()
            self._hmin.clear()
            stat = 0.0
        self.drift_stat, self._drift_lag = stat, lag
        return lag if stat >= level and not step else 0

    def clear(self) -> None:
        """Reset both CUSUMs (after a recovery, or while a noise burst lasts)."""
        self.g_pos = self.g_neg = self.gs_pos = self.gs_neg = 0.0

    def _too_small_for_a_step(self) -> bool:
        """The innovations since the change began (as :meth:`_spread_ok` takes them) are,
        on average, nearer the slow mean than ``step_min_deg``: the first samples of a noise
        burst that dwell on one side look like a small step to the fast CUSUM (3 deg bursts on
        a 0.5 deg compass: means of 2.4-4.0 deg over 4-6 samples); steps of interest are 5 deg
        or more. Such a level is left to the slow CUSUM (a real 3 deg step on a 0.5 deg
        compass: 8-11 samples in the unit test, against 3 on the fast one)."""
        if self.p.step_min_deg <= 0.0:
            return False
        r = self._change_run()
        if not r:
            return False
        return abs(sum(r) / len(r) - self.nu_ref) < self.p.step_min_deg

    def _change_run(self) -> list[float]:
        """The innovations since the change began (Page's estimate: the last step the
        confirming CUSUM was 0), the newest 6: a step's first samples may straddle it."""
        k0 = self._zero_at[self._confirming_side()]
        return [x for k, x in self._run if k > k0][-6:]

    def _spread_ok(self, sigma: float) -> bool:
        """The innovations since the change began (Page's estimate; the newest 6) are a level
        or a ramp, not a burst: about a line fitted to them without one sample (the one whose
        removal leaves the least spread), their spread is within ``spread_ratio`` sigmas."""
        r = self._change_run()
        if len(r) < 4:
            return True
        # without the sample whose removal leaves the least spread: an outlier at an end
        # pulls the line through all of them to itself, and the farthest from that line was
        # another (seed 409, drift:20@46: a 34.7 sigma outlier on the step's first sample)
        ss = min(sum(e * e for e in _line_residuals(
            [x for i, x in enumerate(r) if i != j], [float(i) for i in range(len(r)) if i != j]))
            for j in range(len(r)))
        return math.sqrt(ss / (len(r) - 3)) <= self.p.spread_ratio * sigma

    def _fit(self, S: list[float], lam: float, t: float, z: float,
             update_bias: bool = True) -> None:
        """Least squares z = a - b t (b the gyro bias): add a sample to the sums ``S``, then
        the bias from all segments (:meth:`_combine`)."""
        S[0] = lam * S[0] + 1.0
        S[1] = lam * S[1] + t
        S[2] = lam * S[2] + t * t
        S[3] = lam * S[3] + z
        S[4] = lam * S[4] + t * z
        if update_bias:
            self._combine()

    def _combine(self) -> None:
        """The bias from the segments' sums, each with its own intercept (the warm-up, the
        later healthy compass, and a compensated step's compass, whose offset changes the
        intercept only): ``b = -sum stz / sum stt``; ``info`` = ``sum stt``, so that the bias
        is known to ``sigma / sqrt(info)``. The warm-up and all later samples as one line
        (one intercept) confirmed a fault at 192.8 s on the real BlueROV2 dive that nothing
        else shows: a real compass's deviation changes with heading, so z is not one line
        across turns; the warm-up's line therefore goes on only while the heading is held
        (:meth:`_segment`)."""
        bias, info = self._slope(self._S, self._Sp, self._Sf)
        if info > 0.0:
            self.bias = bias
        self.info = info

    @staticmethod
    def _slope(*segments: list[float]) -> tuple[float, float]:
        """The bias from these segments' sums (each its own intercept) and its information
        ``sum (t - mean t)^2`` (s^2); (0, 0) if none has any."""
        num = info = 0.0
        for T in segments:
            if T[0] < 3.0:
                continue
            stt = T[2] - T[1] * T[1] / T[0]  # sum (t - mean t)^2
            if stt <= 1e-9 * T[2]:
                continue
            stz = T[4] - T[1] * T[3] / T[0]
            num += -stz  # information-weighted slope: (stz / stt) * stt
            info += stt
        return (num / info if info > 0.0 else 0.0), info

    def _segment(self, psi: float) -> list[float]:
        """The bias fit's sums that a healthy compass sample taken at heading ``psi`` joins:
        the warm-up's line while the vehicle has held the heading it had at the warm-up's end
        (within ``bias_hold_deg``; the first sample beyond closes it for good), else the later
        samples' own segment. The 20 s warm-up alone knows the bias to ~0.017 deg/s at 1 deg
        compass noise, and its start turn's thrust-dependent deviation biases it (nonlinear
        plant: +0.011 deg/s on average, seeds 101-140); the warm-up's line carried on through
        the hold before a fault at 40 s, offline least squares: RMS error 0.0225 deg/s from
        the warm-up, 0.0139 with 5 s more of the line, 0.0076 with 20 s more (a second
        segment with its own intercept gains little: the slope of a short stretch)."""
        if self._hold_ref is not None:
            if abs(psi - self._hold_ref) <= self.p.bias_hold_deg:
                return self._S
            self._hold_ref = None
        return self._Sp

    def _correct(self, nu_o: float, nu: float, dt: float, n: int) -> None:
        """Bias fit and both heading loops; ``n`` > 0: the n-th sample of the warm-up."""
        assert self.psi is not None
        p = self.p
        if n > 10:  # Huber: an outlier moves the estimates by a bounded amount
            lim = p.clip * self.var.sigma
            c_o = max(-lim, min(lim, nu_o))
            c_t = max(-lim, min(lim, nu))
        else:
            c_o, c_t = nu_o, nu
        z = self._y_unw - (nu_o - c_o) - self._G
        if n > 0:
            self._fit(self._S, 1.0, self.t, z, update_bias=n > 20)
        elif self._delayed:
            t_new, _, _, psi_new = self._delayed[-1]
            self._delayed[-1] = (t_new, z, True, psi_new)
        a_o = dt / p.heading_tau_s
        a_t = dt / p.test_tau_s
        if n > 0:
            a_o = max(a_o, 1.0 / n)
            a_t = max(a_t, 1.0 / n)
        self.psi += a_o * c_o
        self.psi_t += a_t * c_t
        self._corr.append((self.k, a_o * c_o))

    def _confirming_side(self) -> int:
        """Which CUSUM side is nearest its confirmation level (index into ``_zero_at``)."""
        p = self.p
        gs = ((self.g_pos / p.h, 0), (self.g_neg / p.h, 1),
              (self.gs_pos / p.slow_h, 2), (self.gs_neg / p.slow_h, 3))
        return max(gs)[1]

    def _not_drifting(self) -> bool:
        """After a drift confirmed under a compensation: the slope of the innovation (clipped
        at the recovery's gate) over the last ``drift_recover_s`` is within
        ``drift_recover_max_dps`` (a drifting compass crosses the dead reckoning: within the
        gate for 2 s, its mean near 0, and still drifting); always True otherwise."""
        p = self.p
        if not self._recover_still:
            return True
        pts = self._agree_long  # (kept to drift_recover_s by update)
        if not pts or pts[0][0] > self.t - p.drift_recover_s + self._dt + 1e-9:
            return False
        n = len(pts)
        mt = sum(q[0] for q in pts) / n
        mx = sum(q[1] for q in pts) / n
        stt = sum((q[0] - mt) ** 2 for q in pts)
        slope = sum((q[0] - mt) * (q[1] - mx) for q in pts) / stt
        return abs(slope) <= p.drift_recover_max_dps

    def _end_comp(self, keep_segment: bool = False) -> None:
        """End the compensation; its compass segment stays in the bias fit only with
        ``keep_segment`` (the compass came back: the samples fed were a level's)."""
        self._comp.clear()
        self._comp_delayed.clear()
        self.offset = None
        self._comp_ok = False
        self._gc = [0.0, 0.0]
        self._comp_prior = None
        if not keep_segment and self._Sf[0] > 0.0:
            self._Sf = [0.0, 0.0, 0.0, 0.0, 0.0]
            self._combine()

    def _compensate(self, nu_o: float, nu: float, sigma: float) -> bool:
        """A confirmed step (fast CUSUM): a compass off by a constant still carries the
        heading's changes, and the gyro dead reckoning drifts by the bias estimate's error
        (0.05 deg/s made 3 deg in the minute after a step 3 s after the warm-up). Over
        ``comp_samples`` after the confirmation the innovation ``nu_o`` is fitted with a line
        (again without the samples beyond 3 sigma of it: compass outliers):
        if its slope is within ``comp_max_slope_dps`` (a level; its slope is the dead
        reckoning's drift) and its spread within ``spread_ratio`` sigmas, the offset is the
        line at the confirmation, and from then on the compass minus the offset steers the
        output heading as a healthy compass does (the heading loop, ``heading_tau_s``). A jump
        (``jump_sigmas``) of the compensated innovation is not used, and a slow CUSUM on it
        (``slow_*``) ends the compensation for this fault (a ramp, or the compass healing:
        the recovery test then takes it back). The hinge test (``comp_drift_glr``) watches the
        compensated compass as it watches a healthy one: a slow drift that begins under the
        compensation (a compass that stepped and then keeps drifting) is a second fault,
        confirmed (True): the compensation's corrections since the hinge are undone and the
        compensation ends (gyro dead reckoning, the bias without the step's segment)."""
        p = self.p
        assert self.psi is not None
        if self.offset is None:
            self._learn_offset(nu_o, sigma)
            return False
        x = (nu_o - self.offset) / sigma
        xs_ = max(-p.slow_clip, min(p.slow_clip, x))
        self._gc[0] = max(0.0, self._gc[0] + xs_ - p.slow_kappa)
        self._gc[1] = max(0.0, self._gc[1] - xs_ - p.slow_kappa)
        if max(self._gc) >= p.slow_h:
            self._end_comp()
            return False
        lag = self._drift_test(nu_o - self.offset, sigma, abs(x) >= p.jump_sigmas, False,
                               p.comp_drift_glr, self.offset, self._comp_prior)
        if lag:
            # a second fault: the compass drifts under the compensation (since the hinge)
            self._rollback(self.k - lag, fast=True)
            off = self.offset
            self._end_comp()
            self._recover_mean = min(p.recover_gate_deg,
                                     0.5 * abs(self._y_unw - off - self.psi))
            self._recover_still = p.drift_recover_s > 0.0
            self._agree_long.clear()
            return True
        if abs(x) >= p.jump_sigmas:
            return False
        c = max(-p.clip * sigma, min(p.clip * sigma, nu_o - self.offset))
        halfway = p.comp_drift_glr > 0.0 and self.drift_stat >= 0.5 * p.comp_drift_glr
        self._feed_segment(self._y_unw - (nu_o - self.offset - c) - self._G,
                           max(self._gc) >= 0.5 * p.slow_h or halfway)
        a = self._dt / p.heading_tau_s
        self.psi += a * c
        self.psi_t += a * c
        self._corr.append((self.k, a * c))
        return False

    def _learn_offset(self, nu_o: float, sigma: float) -> None:
        """The compensation's first ``comp_samples``: the innovation fitted with a line
        (again without the samples beyond 3 sigma of it); a level gives the offset, with the
        window's compass joining the bias fit as a segment; anything else ends the
        compensation for this fault (:meth:`_compensate`)."""
        p = self.p
        self._comp.append((self.t, nu_o, self._y_unw - self._G))
        if len(self._comp) < p.comp_samples:
            return
        t_first = self._comp[0][0]
        pts = self._comp
        for _ in range(2):  # the line, then again without the outliers (> 3 sigma)
            n = len(pts)
            mt = sum(q[0] for q in pts) / n
            mx = sum(q[1] for q in pts) / n
            stt = sum((q[0] - mt) ** 2 for q in pts)
            slope = sum((q[0] - mt) * (q[1] - mx) for q in pts) / stt
            res = [q[1] - mx - slope * (q[0] - mt) for q in pts]
            sd = math.sqrt(sum(e * e for e in res) / (n - 2))
            kept = [q for q, e in zip(pts, res, strict=True) if abs(e) <= 3.0 * sigma]
            if len(kept) < max(4, len(pts) // 2):
                break
            pts = kept
        if abs(slope) <= p.comp_max_slope_dps and sd <= p.spread_ratio * sigma:
            # The slope is the dead reckoning's drift: the bias estimate's error, which
            # the bias fit knows to sigma / sqrt(info). The window's compass (z = y -
            # sum r dt, a level: its own intercept) joins the fit as a segment, and the
            # offset is the line at the window's start with the combined slope (the
            # window's own slope alone has 2x the intercept's error there: 0.9 deg once
            # at 1 deg noise, seed 6 drift:20@35 of the nonlinear plant); the segment
            # then learns on from the compensated compass (_feed_segment).
            b_old = self.bias
            # the hinge's slope before the drift: the bias without the step's compass
            b0, info0 = self._slope(self._S, self._Sp)
            if p.comp_drift_bias_sd_dps > 0.0:  # known to no better than this
                s_h = max(sigma, p.drift_sigma_min_deg)
                info0 = min(info0, (s_h / p.comp_drift_bias_sd_dps) ** 2)
            self._comp_prior = (-b0, info0)
            self._Sf = [0.0, 0.0, 0.0, 0.0, 0.0]
            for t_i, _, z_i in pts:
                self._fit(self._Sf, self._lam, t_i, z_i, update_bias=False)
            self._combine()
            self.offset = mx + (b_old - self.bias) * (t_first - mt)
            if self._hinge_c is not None:
                self._hinge_c.clear()
        else:
            self._comp_ok = False  # not a level: dead reckoning for this fault
        self._comp.clear()

    def _feed_segment(self, z: float, doubtful: bool) -> None:
        """The compensated compass (``z = y - sum r dt``, its outliers clipped) into the bias
        fit's step segment, ``bias_delay_s`` late as the healthy compass's (a drift that
        begins under the compensation has that long to be seen: its slow CUSUM halfway up
        drops the samples not yet fed, and ending the compensation drops the segment)."""
        p = self.p
        if doubtful:
            self._comp_delayed.clear()
            return
        self._comp_delayed.append((self.t, z))
        while self._comp_delayed and self._comp_delayed[0][0] < self.t - p.bias_delay_s - 1e-9:
            t_old, z_old = self._comp_delayed.popleft()
            self._fit(self._Sf, self._lam, t_old, z_old)

    def force_fault(self, samples_back: int) -> None:
        """A fault found by another test (a stuck compass) that began ``samples_back`` ago."""
        self._end_comp()
        self.fault = self.suspect = True
        self.var.frozen = True
        self._agree.clear()
        self._recover_still = False
        self._rollback(self.k - samples_back, fast=True)

    def _rollback(self, k0: int | None = None, fast: bool | None = None) -> None:
        """Undo the output loop's corrections since the change began (Page's estimate: the
        last time the CUSUM that confirmed was 0): they followed the faulty compass.
        ``fast``: the change time is sharp (a step by the fast CUSUM, a stuck run; default:
        :attr:`confirmed_fast`)."""
        if k0 is None:
            k0 = self._zero_at[self._confirming_side()]
        if fast is None:
            fast = self.confirmed_fast
        undo = sum(c for k, c in self._corr if k > k0)
        if self.psi is not None:
            self.psi -= undo
        self._corr.clear()
        # ... and the bias fit does not get the samples since then, nor those of the test
        # loop's time constant before (a slow drift starts before the CUSUM sees it; a
        # step's change time is sharp: fast_margin_s before it). The trusted samples still
        # in the delay line go into the fit now (during the fault they would be dropped: a
        # step 15 s after the warm-up lost them all, its bias from 20 s of data, 0.05 deg/s
        # off), and the dead reckoning since the change is redone with the better bias.
        t_k0 = self.t - (self.k - k0) * self._dt
        t0 = t_k0 - (self.p.fast_margin_s if fast else self.p.test_tau_s)
        b_old = self.bias
        fed = False
        for t, z, ok, psi in self._delayed:
            if ok and t <= t0:
                self._fit(self._segment(psi), self._lam, t, z, update_bias=False)
                fed = True
        self._delayed.clear()
        self._hold_ref = None  # a fault may have moved the compass's intercept
        if fed:
            self._combine()
            if self.psi is not None:
                redo = (self.bias - b_old) * (self.t - t_k0)
                self.psi -= redo
                self.psi_t -= redo
