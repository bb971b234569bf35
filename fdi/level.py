"""Isolation after a level change: which side is right, the old track or the new fixes?

Beyond Zhou & Zhang (2010), whose isolation replaces a faulty fix by its GM(1,1) prediction
and, after many in a row, alarms and restarts on the receiver (section 2.2). When the fixes
*step and stay* (a multipath step, a drift the slow test caught, a frozen receiver), neither
extrapolating the old track for a fixed number of epochs nor restarting on the receiver at once
is right: the first outputs a stale extrapolation after the fault has ended (3.1-3.3 m off
against 0.6 m raw, shared/FINDINGS.md), the second accepts the faulty level.

:class:`LevelHold` carries the *old track* instead: the last trusted Doppler-free value b_a
(:mod:`fdi.drift`, eq. D1) moved by the receiver's Doppler displacement,

    x_track(t) = b_a + D(t) + δ·v(t)                                (L1)

and decides with the Doppler evidence over a short fixed lag L (seconds, not epochs):

* the new fixes are right when, for L seconds, they agree with the old track within
  ``exit_sigmas`` of the drift σ at the track's age (eq. D3) **and** with their own Doppler
  over L (a receiver consistent with itself): then the hold ends and the receiver is
  accepted. After a frozen stretch (the receiver repeated its speed and course too, so the
  Doppler the old track was moved by is void, whatever speed it repeated: 0 at a stop while
  the vehicle drives off) only the second condition is asked;
* the new fixes are also right when, after L seconds consistent with their own Doppler, they
  sit at the level of an *older* trusted reference b_o (the long-term levels 20-300 s before
  the anchor, one every 10 s) while the old track does not: ``|b − b_o| ≤ ⅓·|b_a − b_o|`` and
  ``|b_a − b_o| ≥ side_sigmas·σ(30 s)`` (not grown with the age: the DGPS error is bounded,
  and the ratio carries the decision). That is the end of a slow fault the
  drift test missed (the old track is the faulty side), told apart from a multipath step
  (the new fixes are the faulty side: the old track is at the older level). In a hold on a
  slow fault the fixes must have *stepped* there: by half the old track's distance from that
  level or more, at most ``level_lag_s`` before (the short lag), or by less and then stay
  there, consistent with their own Doppler, for ``level_lag_s`` (a ramp still running passes,
  for a second or two, where some older level of a wandering DGPS error happens to be).
  Fixes that *drifted* there (no step of theirs within ``level_lag_s`` before they arrived)
  never end a slow hold as a new level: a slow ramp lingers near older levels of an error
  that wanders over metres, and the new level forgets every reference since the older one.
  They are passed on (``raw``, below) while they sit there;
* in a hold on a slow fault, the fixes are right again when they step back towards the old
  track and stay consistent with their own Doppler for L: their distance from it falls by
  more than half within L, by more than ``exit_sigmas`` of the 1 s σ (a drift ends at once;
  the anchor may sit a little into the drift, so agreement alone can come late); or when
  they *step* back past the old track and land nearer every older level than the old track
  is (a drift found late: the anchor sat deep inside it, and its end took the fixes back to
  where they were before it);
* while the evidence is not yet complete but points to the new fixes (they agree with the old
  track within ``exit_sigmas``, sit at an older level as above, or come live from a receiver
  that was frozen, or stepped back towards an older level before the hold and stay consistent
  with their own Doppler, or the receiver's fix was passed on at the last epoch and it stays
  consistent with its own Doppler), the hold goes on but passes the *receiver's* fix on,
  flagged (``raw``): when neither side is shown wrong, the raw fix is never worse than doing
  nothing, and the old track may be the faulty side (a late exit costs the epochs of the lag,
  3-12 m off at 1 Hz after a frozen stretch or a missed ramp: ``sim rover-harness``);
* a slow hold ends (``consistent``) when the receiver has been consistent with its own Doppler
  at every horizon up to CONSISTENT_S (30 s) for that long: a drift of 0.05 m/s still
  running would show there; held on, the old track only grows stale (a late-caught ramp
  whose anchor sat inside it held an alarm 40-120 s after the ramp ended);
* otherwise the old track is kept: passed on (flagged) for ``output_s``, then the alarm with
  nothing passed on (section 2.2: "stop automatic navigation") up to ``max_s``, after which
  the receiver's level is accepted again under the alarm (no lock-in). A hold that began with
  an abrupt step (``slow=False``: a jump that stayed, a multipath step) gives up at
  ``output_s``: a step that neither side can be shown wrong about is the receiver's to keep
  (never worse than doing nothing); a slow fault (a drift, a frozen receiver) is held to
  ``max_s``.

Nothing here feeds a filter: the caller keeps replaced values out of its Kalman filter.

Units: metres, seconds; vectors are (east, north).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Literal, NamedTuple

from fdi.drift import sigma_at

HoldAction = Literal["track", "raw", "alarm", "exit", "ended", "new_level", "consistent",
                     "give_up"]
CONSISTENT_S = 30.0  # a receiver consistent with its own Doppler this long ends a slow hold
# A fix within this fraction of the track's departure from an older level is back at it: the
# isolator's step back (rover.py, _back_at_old_level) and a hold entered after one.
BACK_AT_OLD_FRAC = 0.6
# ... and, in a hold not entered after such a step, within this fraction (``new_level``).
OLD_LEVEL_FRAC = 1.0 / 3.0
# The horizon (s) of the σ the old track must be off an older level by (``side_sigmas`` of
# it) for that level to be the other side: not grown with the age (the DGPS error is bounded).
SIDE_HORIZON_S = 30.0
# Older trusted levels are at least this long (s) before the anchor (the long-term levels of
# fdi/drift.py, up to LEVEL_KEEP_S).
OLD_LEVEL_MIN_AGE_S = 20.0
# ``ended``: the fixes stepped back towards the old track by more than this fraction of their
# distance from it.
ENDED_FRAC = 0.5
# ``new_level`` in a slow hold: fixes that stepped there by at least this fraction of the old
# track's distance from the level are a fault's end at the short lag; a smaller step asks for
# ``level_lag_s`` there.
LEVEL_STEP_FRAC = 0.5


@dataclass(frozen=True, slots=True)
class HoldParams:
    horizons_s: tuple[float, ...]
    sigma_m: tuple[float, ...]
    lag_s: float
    lag_sd_s: float
    exit_sigmas: float
    side_sigmas: float
    exit_lag_s: float
    output_s: float
    max_s: float
    level_lag_s: float = 0.0  # a slow hold's "new_level" lag (0: exit_lag_s, as an abrupt one)

    @property
    def side_m(self) -> float:
        """How far the old track must be off an older level for that level to be the other
        side: ``side_sigmas`` σ(30 s), not grown with the age (the DGPS error is bounded)."""
        return self.side_sigmas * sigma_at(SIDE_HORIZON_S, self.horizons_s, self.sigma_m)


@dataclass(frozen=True, slots=True)
class HoldStep:
    action: HoldAction
    track: tuple[float, float]  # (L1) at this epoch
    g: float  # the new fix against the old track, in σ


class LevelHold:
    """One hold, from the epoch it starts; :meth:`step` once an epoch with Doppler."""

    __slots__ = ("_agree_b", "_agree_since", "_dev", "_long", "_old_b", "_old_since", "_recent",
                 "anchor_b", "anchor_t", "anchor_v", "frozen", "matched_t", "old", "p",
                 "prefer_raw", "slow", "stale_m", "t0", "was_raw")

    def __init__(self, p: HoldParams, t0: float, anchor_t: float,
                 anchor_b: tuple[float, float], anchor_v: tuple[float, float],
                 stale_m: float = 0.0,
                 old: list[tuple[float, tuple[float, float]]] | None = None,
                 slow: bool = True, prefer_raw: bool = False, frozen: bool = False) -> None:
        self.p = p
        self.prefer_raw = prefer_raw  # the fixes stepped back to an older level before it
        self.t0 = t0
        self.anchor_t = anchor_t
        self.anchor_b = anchor_b
        self.anchor_v = anchor_v
        self.stale_m = stale_m  # displacement integrated from a void (frozen) Doppler
        # The receiver repeated its whole fix during the hold (or when it began): its Doppler
        # was void, whatever speed it repeated (a receiver frozen at a stop repeats 0 m/s while
        # the vehicle drives off: 10 m of the Doppler chain missing, with stale_m = 0).
        self.frozen = frozen or stale_m > 0.0
        self.old = old or []  # older trusted levels (t_o, b_o), before the anchor
        self.matched_t = math.nan  # the level the new fixes were found at ("new_level")
        self.slow = slow
        self._agree_since: float | None = None
        self.was_raw = False  # the last epoch passed the receiver's fix on
        self._agree_b = (0.0, 0.0)
        self._old_since: float | None = None  # the new fixes at an older level since, and
        self._old_b = (0.0, 0.0)  # ... their Doppler-free value then
        self._dev: deque[_Deviation] = deque()  # over 2L
        self._recent: deque[_Point] = deque()  # the receiver's b over L
        self._long: deque[_Point] = deque()  # ... over CONSISTENT_S

    def _nearer_old(self, b: tuple[float, float]) -> bool:
        """``b`` is nearer every older level than the old track (the anchor) is, and the
        anchor is off some older level by ``side_sigmas`` σ(30 s) or more (False with no older
        levels)."""
        if not self.old:
            return False
        ae, an = self.anchor_b
        far = 0.0
        for _, (oe, on) in self.old:
            e_track = math.hypot(ae - oe, an - on)
            if math.hypot(b[0] - oe, b[1] - on) >= e_track:
                return False
            far = max(far, e_track)
        return far >= self.p.side_m

    def step(self, t: float, b: tuple[float, float], v: tuple[float, float],
             d: tuple[float, float], stale: bool, dt: float, fresh: bool = False,
             last_step: tuple[float, float] | None = None, held: bool = False) -> HoldStep:
        """The receiver's Doppler-free value ``b`` at ``t``, its Doppler ``v`` and the
        integrated displacement ``d``; ``stale``: the receiver repeats its whole fix;
        ``fresh``: this fix differs from the previous one (position, speed or course);
        ``last_step``: the caller's last step of b between two epochs, (t, m); ``held``:
        the receiver's position repeats while its own speed says it moved (its frozen test):
        as with ``stale``, its fix is no evidence (no exit, end or new level) and is not
        passed on (``raw``), though its Doppler still moves the old track."""
        ep = self._evidence(t, b, v, d, stale, dt, held)
        if self._agreed(ep):
            return HoldStep("exit", ep.track, ep.g)
        across = self._across(ep, last_step)
        if self._ended(ep, across):
            return HoldStep("ended", ep.track, ep.g)
        if self._at_new_level(ep, last_step):
            return HoldStep("new_level", ep.track, ep.g)
        if self._consistent(ep):
            return HoldStep("consistent", ep.track, ep.g)
        lg = self._long
        while len(lg) > 1 and lg[1].t <= t - CONSISTENT_S:
            lg.popleft()
        p = self.p
        if t - self.t0 > (p.max_s if self.slow else p.output_s):
            return HoldStep("give_up", ep.track, ep.g)
        if not ep.stale and (ep.g <= p.exit_sigmas or not math.isnan(ep.at_old) or across
                          or (self.frozen and fresh)
                          or ((self.prefer_raw or self.was_raw) and ep.self_ok)):
            self.was_raw = True
            return HoldStep("raw", ep.track, ep.g)
        self.was_raw = False
        if t - self.t0 <= p.output_s:
            return HoldStep("track", ep.track, ep.g)
        return HoldStep("alarm", ep.track, ep.g)

    def _evidence(self, t: float, b: tuple[float, float], v: tuple[float, float],
                  d: tuple[float, float], stale: bool, dt: float, held: bool = False
                  ) -> _Epoch:
        """The old track (L1), the new fix against it in σ (g), and the receiver against its
        own Doppler over the fixed lag."""
        p = self.p
        lag = p.lag_s
        track = (self.anchor_b[0] + d[0] + lag * v[0], self.anchor_b[1] + d[1] + lag * v[1])
        if stale:
            self.stale_m += math.hypot(v[0], v[1]) * dt
            self.slow = True
            self.frozen = True
        age = t - self.anchor_t
        s = sigma_at(age, p.horizons_s, p.sigma_m)
        dv = p.lag_sd_s * math.hypot(v[0] - self.anchor_v[0], v[1] - self.anchor_v[1])
        var = s * s + dv * dv + (0.5 * self.stale_m) ** 2
        re, rn = b[0] - self.anchor_b[0], b[1] - self.anchor_b[1]
        g = math.sqrt((re * re + rn * rn) / var)
        # The receiver against its own Doppler over the fixed lag.
        rec = self._recent
        rec.append(_Point(t, b[0], b[1]))
        while len(rec) > 1 and rec[1].t <= t - p.exit_lag_s:
            rec.popleft()
        first = rec[0]
        self_ok = math.hypot(b[0] - first.e, b[1] - first.n) <= p.exit_sigmas * sigma_at(
            max(t - first.t, 1e-3), p.horizons_s, p.sigma_m)
        return _Epoch(t, b, stale or held, track, g, re, rn, self_ok)

    def _agreed(self, ep: _Epoch) -> bool:
        """``exit``: the new fixes have agreed with the old track within ``exit_sigmas`` for
        ``exit_lag_s``, consistent with their own Doppler since (after a frozen stretch, the
        old track rests on a void Doppler: the receiver's own consistency is the evidence)."""
        p, t, b = self.p, ep.t, ep.b
        agrees = not ep.stale and (ep.g <= p.exit_sigmas or (self.frozen and ep.self_ok))
        if agrees and self._agree_since is not None:
            # ... and the receiver stays consistent with itself since the agreement began.
            ab = self._agree_b
            s_a = sigma_at(max(t - self._agree_since, 1e-3), p.horizons_s, p.sigma_m)
            if math.hypot(b[0] - ab[0], b[1] - ab[1]) > p.exit_sigmas * s_a:
                self._agree_since = None
        if not agrees:
            self._agree_since = None
        elif self._agree_since is None:
            self._agree_since = t
            self._agree_b = b
        return self._agree_since is not None and t - self._agree_since >= p.exit_lag_s - 1e-9

    def _across(self, ep: _Epoch, last_step: tuple[float, float] | None) -> bool:
        """Record the fix's deviation from the old track over 2L; a *step* back across the
        old track that ends further off, nearer every older level than the old track: the
        anchor sat deep inside a slow drift (found late), and the drift's end took the fixes
        back past it to where they were before it. Passed on at once (``raw``), ended once
        consistent with their own Doppler over the lag."""
        p, t, re, rn = self.p, ep.t, ep.re, ep.rn
        dev = math.hypot(re, rn)
        hist = self._dev
        hist.append(_Deviation(t, dev, re, rn))
        while len(hist) > 1 and hist[1].t <= t - 2.0 * p.exit_lag_s:
            hist.popleft()
        h0 = hist[0]
        before = h0.dev
        s1 = p.exit_sigmas * p.sigma_m[0]
        # the move since then towards the old track, along the line from it
        back = -((re - h0.re) * h0.re + (rn - h0.rn) * h0.rn) / before if before > 0.0 else 0.0
        ep.dev, ep.before, ep.back, ep.t_b = dev, before, back, h0.t
        return (self.slow and not ep.stale and not self.frozen and back >= before
                and back >= 2.0 * s1 and last_step is not None and _step_time(last_step) >= h0.t
                and self._nearer_old(ep.b))

    def _ended(self, ep: _Epoch, across: bool) -> bool:
        """``ended``: in a slow hold, a step back towards the old track (by more than half its
        distance and ``exit_sigmas`` of the 1 s σ) or at least the whole way back, or
        ``across`` it, then consistent with their own Doppler for L."""
        p = self.p
        s1 = p.exit_sigmas * p.sigma_m[0]
        dev, before, back = ep.dev, ep.before, ep.back
        return (self.slow and not ep.stale and ep.self_ok and not self.frozen
                and ep.t - ep.t_b >= p.exit_lag_s
                and ((dev <= ENDED_FRAC * before and before - dev >= s1)
                     or (back >= before and dev <= before and back >= 2.0 * s1) or across))

    def _find_old(self, ep: _Epoch) -> None:
        """The older level the new fix sits at, if any (``ep.at_old``, and the old track's
        distance from it ``ep.e_old``): within a third of the old track's distance from it
        (OLD_LEVEL_FRAC; after a step back to an older level, ``prefer_raw``, the caller's
        BACK_AT_OLD_FRAC),
        the old track at least ``side_sigmas`` σ(30 s) off it."""
        if not self.old or ep.stale:
            return
        s_side = self.p.side_m
        frac = BACK_AT_OLD_FRAC if self.prefer_raw else OLD_LEVEL_FRAC
        b = ep.b
        for t_o, (oe, on) in self.old:
            e_new = math.hypot(b[0] - oe, b[1] - on)
            e_track = math.hypot(self.anchor_b[0] - oe, self.anchor_b[1] - on)
            if e_new <= frac * e_track and e_track >= s_side:
                ep.at_old, ep.e_old = t_o, e_track
                return

    def _track_old_since(self, ep: _Epoch) -> None:
        """How long the new fixes have sat at an older level, consistent with their own
        Doppler since (within ``exit_sigmas`` of the drift σ of where they were then)."""
        p, t, b = self.p, ep.t, ep.b
        at_old = not math.isnan(ep.at_old)
        if not at_old or not ep.self_ok or (self._old_since is not None and math.hypot(
                b[0] - self._old_b[0], b[1] - self._old_b[1]) > p.exit_sigmas * sigma_at(
                max(t - self._old_since, 1e-3), p.horizons_s, p.sigma_m)):
            self._old_since = None
        if self._old_since is None and at_old and ep.self_ok:
            self._old_since, self._old_b = t, b

    def _level_need(self, ep: _Epoch, last_step: tuple[float, float] | None) -> float:
        """How long (s) the fixes must sit at the older level: in a slow hold, none after a
        step of half the old track's distance from it or more within ``level_lag_s`` before
        they arrived; ``level_lag_s`` after a smaller one; never after no step (fixes that
        drifted there: a slow ramp lingers near older levels of an error that wanders)."""
        p = self.p
        if (self.slow and not self.frozen and p.level_lag_s > 0.0
                and self._old_since is not None):
            if last_step is None:
                return math.inf
            step_t, step_m = last_step
            if self._old_since - step_t > p.level_lag_s + 1e-9:
                return math.inf
            if step_m < LEVEL_STEP_FRAC * ep.e_old:
                return p.level_lag_s
        return 0.0

    def _at_new_level(self, ep: _Epoch, last_step: tuple[float, float] | None) -> bool:
        """``new_level``: the new fixes sit at an older trusted level while the old track
        does not, consistent with their own Doppler for the lag (and as long as
        :meth:`_level_need` asks): the old track was the faulty side."""
        self._find_old(ep)
        self._track_old_since(ep)
        need = self._level_need(ep, last_step)
        p, t = self.p, ep.t
        if (not math.isnan(ep.at_old) and ep.self_ok and t - self.t0 >= p.exit_lag_s - 1e-9
                and t - self._recent[0].t >= p.exit_lag_s - 1e-9
                and self._old_since is not None and t - self._old_since >= need - 1e-9):
            self.matched_t = ep.at_old
            return True
        return False

    def _consistent(self, ep: _Epoch) -> bool:
        """``consistent``: a slow hold whose receiver has been consistent with its own
        Doppler at every horizon up to CONSISTENT_S, for that long: a drift still running at
        0.05 m/s would show there (1.5 m against σ(30 s) of 0.2-0.6 m); the fault is over."""
        p, t, b = self.p, ep.t, ep.b
        lg = self._long
        if ep.stale or not ep.self_ok:
            lg.clear()
        else:
            lg.append(_Point(t, b[0], b[1]))
        if not (self.slow and lg and t - lg[0].t >= CONSISTENT_S - 1e-9):
            return False
        for h in p.horizons_s:
            if h > CONSISTENT_S:
                break
            j = 0
            while j + 1 < len(lg) and lg[j + 1].t <= t - h:
                j += 1
            o = lg[j]
            if math.hypot(b[0] - o.e, b[1] - o.n) > p.exit_sigmas * sigma_at(
                    t - o.t, p.horizons_s, p.sigma_m):
                return False
        return True


def _step_time(last_step: tuple[float, float]) -> float:
    """The time of the caller's last step of b, (t, m)."""
    step_t, _ = last_step
    return step_t


class _Point(NamedTuple):
    """The receiver's Doppler-free value at a time."""

    t: float
    e: float
    n: float


class _Deviation(NamedTuple):
    """The new fix's deviation from the old track at a time: its length and (east, north)."""

    t: float
    dev: float
    re: float
    rn: float


@dataclass(slots=True)
class _Epoch:
    """One epoch of the hold: what :meth:`LevelHold.step`'s tests decide on."""

    t: float
    b: tuple[float, float]
    stale: bool
    track: tuple[float, float]  # (L1)
    g: float  # the new fix against the old track, in σ
    re: float  # the new fix minus the anchor (east, north)
    rn: float
    self_ok: bool  # the receiver consistent with its own Doppler over the lag
    dev: float = 0.0  # |(re, rn)|
    before: float = 0.0  # ... 2L ago (at t_b)
    back: float = 0.0  # the move since then towards the old track
    t_b: float = 0.0
    at_old: float = math.nan  # the older level the new fix sits at
    e_old: float = math.nan  # the old track's distance from it
