"""The rover isolator's decision table: which rule decides an epoch, and what is passed on.

Each rule is a small function of the isolator and the epoch's evidence
(:class:`fdi.rover_evidence.Evidence`, computed once before any rule is asked) that returns
the epoch's ``Decision`` when its guard holds and ``None`` otherwise. :mod:`fdi.rover` asks
them in the order of the groups below; the first that answers decides, and its id is in the
``Decision`` (``rule``). :data:`RULES` lists every rule with its mode, guard, output source,
next mode, and the equation or reason; ``docs/reference/rover-decisions.md`` is generated from
it (:func:`markdown`, ``tests/test_rover_rules.py`` checks that the page is current).

The paper's preset (``config/rover-paper.toml``, Zhou & Zhang 2010) runs rules R1-R8 only:
without the Doppler predictor, the Doppler test and the drift test no other guard can hold.

Units: metres, seconds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from fdi.rover_evidence import (
    TIME_RESET_EPOCHS,
    Decision,
    Evidence,
    FixInput,
    Mode,
    Source,
    Stats,
)

# The isolator the rules act on (fdi.rover.RoverIsolator), named only in annotations: fdi.rover
# imports this table, so importing it here, even for types, would be an import cycle.
RoverIsolator = Any

if TYPE_CHECKING:
    from fdi.level import HoldStep, LevelHold


@dataclass(frozen=True)
class Rule:
    """One row of the decision table."""

    id: str
    name: str
    modes: tuple[Mode, ...]  # the modes it applies in
    guard: str
    source: Source  # what the epoch's estimate is when it fires
    next_mode: str
    equation: str  # the equation or the reason it exists
    params: tuple[str, ...] = ()  # the parameters it reads (``[rover.detector]``)
    reason: str = ""  # the ``reason`` string it writes (``+`` joins the failed tests)


ANY = (Mode.TRACK, Mode.REPLACE, Mode.STEP_BACK, Mode.STEP_END, Mode.COAST, Mode.HOLD)
NOT_HOLD = (Mode.TRACK, Mode.REPLACE, Mode.STEP_BACK, Mode.STEP_END, Mode.COAST)

RULES: tuple[Rule, ...] = (
    Rule("R1", "no_fix", ANY, "the receiver has no fix", Source.NONE, "unchanged",
         "nothing to test", reason="no_fix"),
    Rule("R2", "stale_time", ANY, "-max_gap_s <= dt <= 0", Source.NONE, "unchanged",
         "a repeated or stale epoch is not passed on", ("max_gap_s",),
         "duplicate_time / time_backwards"),
    Rule("R3", "clock_jump", ANY,
         "dt < -max_gap_s, fewer than TIME_RESET_EPOCHS fixes in a row on the new time base",
         Source.NONE, "unchanged", "one corrupt time must not restart the filter",
         ("max_gap_s",), "time_backwards"),
    Rule("R4", "restart_quality", ANY,
         "first fix, a gap over max_gap_s, or a believed clock jump; a quality screen fails",
         Source.NONE, "TRACK, alarm", "section 2.2: nothing to replace it with",
         ("max_gap_s", "min_sats", "max_hdop"), "sats / hdop"),
    Rule("R5", "restart", ANY,
         "first fix, a gap over max_gap_s, or a believed clock jump",
         Source.RAW, "TRACK", "window, filter and tests restarted on the fix", ("max_gap_s",),
         "start / gap_restart / time_reset"),
    Rule("R6", "accept", NOT_HOLD,
         "no test fails: F(k) <= T_d, |ε| <= gate, Doppler, drift, frozen and quality pass",
         Source.RAW, "TRACK", "eq. 6: F(k) = DᵀS⁻¹D <= T_d; eq. 18: |x⁰(k) − x̂⁰(k)| <= gate",
         ("alpha", "gate_m", "gate_sigmas", "doppler_sigmas", "drift_sigmas",
          "recover_epochs"), "'' / recovered"),
    Rule("R7", "replace", NOT_HOLD,
         "a test fails, a prediction exists, fewer than max_consecutive in a row",
         Source.PREDICTION, "REPLACE",
         "section 2.2: x⁰(k) := x̂⁰(k) (eq. 7-17) before the filter update, R x "
         "replaced_r_factor", ("max_consecutive", "replaced_r_factor"), "the failed tests"),
    Rule("R8", "alarm", NOT_HOLD,
         "a test fails and max_consecutive replacements ran out (or nothing to replace with)",
         Source.NONE, "TRACK, alarm",
         "section 2.2: alarm, stop automatic navigation, restart on the receiver",
         ("max_consecutive", "recover_epochs"), "the failed tests"),
    Rule("R9", "drift_warn", NOT_HOLD,
         "no test fails; drift_warn_sigmas < g", Source.RAW, "TRACK",
         "D4: flagged, kept out of the references and the gates' learning",
         ("drift_warn_sigmas",), "drift_warn"),
    Rule("R10", "drift_watch", NOT_HOLD,
         "no test fails; ramp_sigmas < g at the ramp_window_s horizon", Source.RAW, "TRACK",
         "D4 at one horizon: flagged only", ("ramp_window_s", "ramp_sigmas"), "drift_watch"),
    Rule("R11", "step_end", (Mode.STEP_END, Mode.REPLACE, Mode.STEP_BACK, Mode.TRACK),
         "the fix back before a remembered step, there for hold_exit_s and STEP_END_EPOCHS",
         Source.RAW, "TRACK",
         "|b − b_rev| <= hold_exit_sigmas σ(age) (D3); the stepped level's references go",
         ("step_pair_s", "hold_exit_s", "hold_exit_sigmas"), "step_end"),
    Rule("R12", "hold", NOT_HOLD,
         "frozen, or a slow drift fault, or max_consecutive replacements; a reference exists",
         Source.OLD_TRACK, "HOLD", "L1: x_track = b_a + D(t) + δ·v(t); then R17-R23, R25",
         ("drift_sigmas", "max_consecutive", "stale_s", "stale_p"), "the failed tests"),
    Rule("R13", "grey_fed", (Mode.REPLACE,),
         "only the grey test fails after 2+ replacements fed the window; g <= grey_fed_sigmas",
         Source.RAW, "REPLACE", "the window extrapolates its own predictions: no fair test",
         ("grey_fed_sigmas",), "grey+grey_fed"),
    Rule("R14", "step_back", NOT_HOLD,
         "an abrupt step back to an older trusted level the track left, or to before a "
         "remembered step", Source.RAW, "STEP_BACK",
         "|b − b_o| <= BACK_AT_OLD_FRAC |b_track − b_o| and <= hold_exit_sigmas σ(age)",
         ("hold_side_sigmas", "hold_exit_sigmas", "step_pair_s"), "...+step_back"),
    Rule("R15", "coast", (Mode.REPLACE, Mode.COAST),
         "replacements ran out; the receiver disagrees with its own Doppler; under "
         "max_coast_s", Source.DOPPLER_COAST, "COAST, alarm",
         "the prediction moved by the Doppler; the receiver is not restarted on",
         ("max_coast_s", "doppler_sigmas"), "...+coast"),
    Rule("R16", "step_end_restart", (Mode.STEP_BACK, Mode.REPLACE),
         "replacements ran out at a remembered step's end, with Doppler", Source.RAW,
         "TRACK", "restart on the fix, the drift test's levels kept (rebased)",
         ("max_consecutive", "step_pair_s"), "...+step_back"),
    Rule("R17", "hold_no_doppler", (Mode.HOLD,), "the Doppler chain broke during a hold",
         Source.NONE, "TRACK, alarm", "no old track to hold", (), "...+no_doppler"),
    Rule("R18", "hold_resume", (Mode.HOLD,),
         "the hold's evidence: exit, ended, new_level or consistent (fdi/level.py); none "
         "from a fix whose frozen test holds",
         Source.RAW, "TRACK", "the receiver is right again", ("hold_exit_s",
         "hold_exit_sigmas", "hold_side_sigmas", "hold_level_s"),
         "hold_exit / hold_ended / hold_new_level / hold_consistent"),
    Rule("R19", "hold_kept", (Mode.HOLD,),
         "an abrupt hold past hold_output_s whose fixes were passed on", Source.RAW, "TRACK",
         "neither side shown wrong: the receiver's level is kept (never worse than raw)",
         ("hold_output_s",), "hold_kept"),
    Rule("R20", "hold_timeout", (Mode.HOLD,),
         "past hold_output_s (abrupt) or hold_max_s (slow)", Source.NONE, "TRACK, alarm",
         "section 2.2: no lock-in, restart on the receiver", ("hold_output_s", "hold_max_s"),
         "...+hold_timeout"),
    Rule("R21", "hold_raw", (Mode.HOLD,),
         "not decided, the evidence points to the receiver, its frozen test does not hold",
         Source.RAW, "HOLD",
         "passed on flagged: never worse than doing nothing", (), "...+hold_raw"),
    Rule("R22", "hold_track", (Mode.HOLD,), "not decided, within hold_output_s",
         Source.OLD_TRACK, "HOLD", "L1", ("hold_output_s",), "...+hold"),
    Rule("R23", "hold_alarm", (Mode.HOLD,), "not decided, past hold_output_s",
         Source.OLD_TRACK, "HOLD, alarm", "section 2.2: stop automatic navigation",
         ("hold_output_s",), "...+hold"),
    Rule("R24", "zones", NOT_HOLD, "strategy three_zone or combined",
         Source.PREDICTION, "REPLACE / TRACK / alarm",
         "Cai & Shao eq. 7-8 per axis: DM = D_i²/S_ii against T1, T2",
         ("strategy", "three_zone"), "over_limit / deviation"),
    Rule("R25", "frozen_coast", (Mode.HOLD,),
         "not decided while the receiver repeats its whole fix (its speed and course void)",
         Source.OLD_TRACK, "HOLD; past the coast's bound or hold_output_s: alarm, NONE",
         "C1-C3 (fdi/coast.py): the last live fix (the old track then if it was not passed "
         "on) carried on at its speed and the turn rate fitted to the courses before it, "
         "while ½ a τ² + a (δ + σ_δ) τ <= frozen_coast_m",
         ("frozen_turn_s", "frozen_accel_mps2", "frozen_coast_m", "drift_lag_s",
          "drift_lag_sd_s", "hold_output_s"),
         "...+frozen_coast"),
)

RULE_BY_NAME: dict[str, Rule] = {r.name: r for r in RULES}


def rid(name: str) -> str:
    """The id of the rule ``name``."""
    return RULE_BY_NAME[name].id


# ----------------------------------------------------------------------- R1-R3: time screens

ScreenRule = Callable[["RoverIsolator", "FixInput", "float | None", Stats], "Decision | None"]


def r_no_fix(iso: RoverIsolator, fix: FixInput, dt: float | None, t: Stats) -> Decision | None:
    """R1: the receiver has no fix."""
    if fix.enu is not None:
        return None
    return iso._decision("no_fix", False, "no_fix", None, t, rule="R1")


def r_stale_time(iso: RoverIsolator, fix: FixInput, dt: float | None,
                 t: Stats) -> Decision | None:
    """R2: a stale or repeated epoch (its time at or before the last, within a gap)."""
    if dt is None or not -iso.p.max_gap_s <= dt <= 0.0:
        return None
    reason = "time_backwards" if dt < 0 else "duplicate_time"
    return iso._decision("no_fix", False, reason, None, t, rule="R2")


def r_clock_jump(iso: RoverIsolator, fix: FixInput, dt: float | None,
                 t: Stats) -> Decision | None:
    """R3: the clock jumped back by more than a gap. The new time base is taken once
    TIME_RESET_EPOCHS fixes in a row follow it, each after the last; until then they are not
    passed on (one corrupt time must not restart the filter on its fix)."""
    if dt is None or dt >= 0.0:
        return None
    ok = (iso._reset_t is not None and 0.0 < fix.t_s - iso._reset_t <= iso.p.max_gap_s)
    iso._reset_run = iso._reset_run + 1 if ok else 1
    iso._reset_t = fix.t_s
    if iso._reset_run < TIME_RESET_EPOCHS:
        return iso._decision("no_fix", False, "time_backwards", None, t, rule="R3")
    return None


SCREENS: tuple[ScreenRule, ...] = (r_no_fix, r_stale_time, r_clock_jump)

# ----------------------------------------------------------------------- R4-R5: restart

EvidenceRule = Callable[["RoverIsolator", Evidence], "Decision | None"]


def r_restart_quality(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R4: a restart whose fix fails a quality screen: nothing to replace it with."""
    if not ev.restart or not ev.quality:
        return None
    iso._last_v = ev.v
    return iso._raise_alarm(ev.z, ev.r, "+".join(ev.quality), ev.stats, rule="R4")


def r_restart(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R5: the first fix, a gap, or a believed clock jump: restart on the fix."""
    if not ev.restart:
        return None
    iso._last_v = ev.v
    iso._restart(ev.z, ev.r)
    return iso._accept(ev.z, ev.stats, ev.restart, rule="R5")


RESTARTS: tuple[EvidenceRule, ...] = (r_restart_quality, r_restart)

# ----------------------------------------------------------------------- R24: the zones


def r_zones(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R24: strategies three_zone and combined: Cai & Shao's three zones per axis decide."""
    if iso.p.strategy == "grey":
        return None
    return iso._step_zones(ev)


# ----------------------------------------------------------------------- no test fails


def r_step_end_passing(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R11 (tests pass): a step back being confirmed ends the remembered step."""
    if iso._end_watch is None or ev.b is None or ev.v is None:
        return None
    ev.rev = iso._step_back_to(ev.t_s, ev.b)
    if ev.rev is not None and iso._step_end(ev.t_s, ev.b, ev.rev):
        return iso._resume(ev, "step_end", rule="R11")
    return None


def r_drift_warn(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R9: between the drift test's warning and its threshold: passed on as it is, flagged,
    neither a reference of the drift test nor learned from."""
    if not ev.warn:
        return None
    return iso._accept(ev.z, ev.stats, "drift_warn", fault=True, rule="R9")


def r_drift_watch(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R10: the ramp's own horizon over ramp_sigmas: flagged and nothing else."""
    if not ev.watch:
        return None
    return iso._accept(ev.z, ev.stats, "drift_watch", fault=True, rule="R10")


def r_accept(iso: RoverIsolator, ev: Evidence) -> Decision:
    """R6: every test passes (eq. 6 and eq. 18): the fix is passed on."""
    return iso._accept(ev.z, ev.stats, "", rule="R6")


# ----------------------------------------------------------------------- a test fails


def r_step_end(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R11 (a test fails): the fixes stayed back before a remembered step."""
    if ev.rev is None or ev.b is None or not iso._step_end(ev.t_s, ev.b, ev.rev):
        return None
    return iso._resume(ev, "step_end", rule="R11")


def r_hold(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R12: a level change (slow drift, frozen receiver, or fixes that stay off past the
    replacement limit): hold the old track and let the Doppler decide (fdi/level.py)."""
    p = iso.p
    b = ev.b
    if (b is None or ev.v is None or iso._drift is None or ev.quality or ev.rev is not None
            or not (ev.stale_fault or (ev.drift_fault and not ev.abrupt and not ev.back)
                    or iso._consec >= p.max_consecutive)):
        return None
    dres = ev.drift
    if not iso._enter_hold(ev.t_s, dres if ev.drift_fault else None, "+".join(ev.reasons),
                           iso._slow(ev)):
        return None
    return iso._hold_step(ev)


def _replaceable(iso: RoverIsolator, ev: Evidence) -> bool:
    """A prediction exists and the run of replacements has not run out; the prediction is
    fed to the window and (R x replaced_r_factor) to the filter, once an epoch."""
    if ev.stats.pred is None or iso._consec >= iso.p.max_consecutive:
        return False
    iso._feed_prediction(ev)
    return True


def r_grey_fed(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R13: only the grey test fails, and its window has fed on two or more of its own
    predictions (the prediction runs on past the receiver's level): the fix, which every other
    test passes, is passed on flagged; the state goes on as for a replacement."""
    p = iso.p
    dres = ev.drift
    if (not _replaceable(iso, ev) or ev.back or not p.grey_fed_sigmas > 0.0
            or iso._fed < 3 or ev.reasons != ["grey"]
            or dres is None or dres.g > p.grey_fed_sigmas):
        return None
    return iso._replace(ev.z, ev.stats, "grey+grey_fed", rule="R13", source=Source.RAW)


def r_step_back(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R14: an abrupt step back to an older trusted level the track had left: the receiver's
    fix is passed on (flagged); the state goes on as for a replacement."""
    if not ev.back or not _replaceable(iso, ev):
        return None
    if not iso._stepped_back:  # the run's first step back: a hold after it
        iso._back_t = ev.back_level  # forgets the references since that level
    iso._stepped_back = True
    return iso._replace(ev.z, ev.stats, "+".join(ev.reasons) + "+step_back", rule="R14",
                        source=Source.RAW)


def r_replace(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R7: the paper's isolation: the faulty fix is replaced by its prediction."""
    pred = ev.stats.pred
    if pred is None or not _replaceable(iso, ev):
        return None
    return iso._replace(pred, ev.stats, "+".join(ev.reasons), rule="R7",
                        source=Source.PREDICTION)


def r_coast(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R15: too many in a row, and the receiver's own fixes disagree with its Doppler (a
    frozen or wandering position): coast on the Doppler-propagated prediction under the
    alarm, up to max_coast_s."""
    pred = ev.stats.pred
    since = iso._coast_since
    if (pred is None or ev.raw_consistent
            or not (since is None or ev.t_s - since < iso.p.max_coast_s)):
        return None
    if since is None:
        iso._coast_since = ev.t_s
    iso._window_append(pred, ev.d, fed=True)
    iso.kf.update(pred, ev.r)
    return iso._coast(ev.stats, "+".join(ev.reasons) + "+coast", rule="R15",
                      source=Source.DOPPLER_COAST)


def r_step_end_restart(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R16: the replacements ran out at the end of a remembered step: restart with the drift
    test's levels kept (rebased); the fix every step back passed on is not withheld."""
    if ev.rev is None or not ev.have_doppler:
        return None
    iso._restart(ev.z, ev.r, keep_levels=True)
    return iso._replace(ev.z, ev.stats, "+".join(ev.reasons) + "+step_back", rule="R16",
                        source=Source.RAW)


def r_alarm(iso: RoverIsolator, ev: Evidence) -> Decision:
    """R8: section 2.2, the alarm: stop automatic navigation and restart on the receiver."""
    return iso._raise_alarm(ev.z, ev.r, "+".join(ev.reasons), ev.stats,
                            keep_levels=ev.back and ev.have_doppler, rule="R8")


FAULT_RULES: tuple[EvidenceRule, ...] = (r_step_end, r_hold, r_grey_fed, r_step_back,
                                         r_replace, r_coast, r_step_end_restart)

# ----------------------------------------------------------------------- R17-R23: the hold

def r_hold_no_doppler(iso: RoverIsolator, ev: Evidence) -> Decision | None:
    """R17: the Doppler chain broke during a hold: no old track to hold; the alarm."""
    if iso._hold is None or (ev.b is not None and ev.v is not None):
        return None
    return iso._raise_alarm(ev.z, ev.r, iso._hold_reason + "+no_doppler", ev.stats,
                            rule="R17")


HoldRule = Callable[["RoverIsolator", Evidence, "LevelHold", "HoldStep"], "Decision | None"]
RESUMING = ("exit", "ended", "new_level", "consistent")


def r_hold_resume(iso: RoverIsolator, ev: Evidence, hold: LevelHold,
                  hs: HoldStep) -> Decision | None:
    """R18: the new fixes agree with the old track (the receiver is right again), or sit at
    the older references' level while the old track does not (its references go)."""
    if hs.action not in RESUMING:
        return None
    drift = iso._drift
    assert drift is not None
    iso._hold = None
    if hold.frozen:
        # The Doppler was void while the receiver was frozen: the Doppler-free values
        # before and after no longer line up.
        drift.reset()
    elif hs.action == "new_level":
        drift.forget_after(hold.matched_t)  # the old track was the faulty side
    elif hs.action == "exit" and hold.prefer_raw and iso._back_t is not None:
        # The hold began after the fixes stepped back to an older level, and they agree
        # with the old track again: the references since that level may carry a slow fault
        # whose end the step was.
        drift.forget_after(iso._back_t)
    elif hs.action in ("ended", "consistent"):
        drift.reset_short()  # the references near a slow fault's start may carry part of it
    return iso._resume(ev, "hold_" + hs.action, rule="R18")


def r_hold_kept(iso: RoverIsolator, ev: Evidence, hold: LevelHold,
                hs: HoldStep) -> Decision | None:
    """R19: an abrupt step neither side was shown wrong about, whose fixes the hold has been
    passing on: the receiver's level is kept without an alarm."""
    if hs.action != "give_up" or hold.slow or not hold.was_raw:
        return None
    drift = iso._drift
    assert drift is not None
    drift.reset_short()
    return iso._resume(ev, "hold_kept", rule="R19")


def r_hold_timeout(iso: RoverIsolator, ev: Evidence, hold: LevelHold,
                   hs: HoldStep) -> Decision | None:
    """R20: the hold ran out: alarm, restart on the receiver (no lock-in)."""
    if hs.action != "give_up":
        return None
    return iso._raise_alarm(ev.z, ev.r, iso._hold_reason + "+hold_timeout", ev.stats,
                            keep_levels=True, rule="R20")


def r_hold_raw(iso: RoverIsolator, ev: Evidence, hold: LevelHold,
               hs: HoldStep) -> Decision | None:
    """R21: not decided, but the evidence points to the receiver: its fix is passed on,
    flagged as not verified; the hold goes on."""
    if hs.action != "raw":
        return None
    iso._carry_track(ev, hs)
    return iso._replace(ev.z, ev.stats, iso._hold_reason + "+hold_raw", rule="R21",
                        source=Source.RAW)


def r_frozen_coast(iso: RoverIsolator, ev: Evidence, hold: LevelHold,
                   hs: HoldStep) -> Decision | None:
    """R25: not decided while the receiver repeats its whole fix: its speed and course are
    void, so the old track moved by them is not passed on (in a turn it runs straight off).
    The vehicle carried on from the last live fix (the fix if it was passed on as it was,
    else the old track then) at its speed and turn rate (fdi/coast.py, C1-C2) is, while the
    coast's bound is within frozen_coast_m (C3) and the hold within hold_output_s; then
    nothing, under the alarm (no output rather than a worse one)."""
    if not ev.stale or hs.action not in ("track", "alarm"):
        return None
    iso._carry_track(ev, hs)
    out = iso._frozen_coast(ev.t_s, hold.anchor_b) if hs.action == "track" else None
    reason = iso._hold_reason + "+frozen_coast"
    if out is None:
        return iso._coast(ev.stats, reason, rule="R25", source=Source.NONE)
    ev.stats.pred = out
    return iso._replace(out, ev.stats, reason, rule="R25", source=Source.OLD_TRACK)


def r_hold_track(iso: RoverIsolator, ev: Evidence, hold: LevelHold,
                 hs: HoldStep) -> Decision | None:
    """R22: not decided: the old track (L1) is passed on, flagged."""
    if hs.action != "track":
        return None
    out = iso._carry_track(ev, hs)
    return iso._replace(out, ev.stats, iso._hold_reason + "+hold", rule="R22",
                        source=Source.OLD_TRACK)


def r_hold_alarm(iso: RoverIsolator, ev: Evidence, hold: LevelHold,
                 hs: HoldStep) -> Decision | None:
    """R23: not decided past hold_output_s: the alarm, nothing passed on."""
    iso._carry_track(ev, hs)
    return iso._coast(ev.stats, iso._hold_reason + "+hold", rule="R23",
                      source=Source.OLD_TRACK)


HOLD_RULES: tuple[HoldRule, ...] = (r_hold_resume, r_hold_kept, r_hold_timeout, r_hold_raw,
                                    r_frozen_coast, r_hold_track, r_hold_alarm)


# ----------------------------------------------------------------------- the reference page


def markdown(defaults: Any) -> str:
    """The decision table as the reference page ``docs/reference/rover-decisions.md``
    (``defaults``: the default preset's ``RoverDetectorParams()``, the values shown)."""
    lines = [
        "# The rover isolator's decision table",
        "",
        "Generated from `fdi/rover_rules.py` (`python -c 'import fdi.rover as v, "
        "fdi.rover_rules as r; print(r.markdown(v.RoverDetectorParams()), end=\"\")' "
        "> docs/reference/rover-decisions.md`);",
        "`tests/test_rover_rules.py` checks that this page is current.",
        "",
        "Each epoch's evidence is computed once (`fdi/rover_evidence.py`: F(k) against T_d,",
        "the grey residual, the Doppler residual, the drift statistic g, the frozen test,",
        "the quality screens); the rules are then asked in the order below (screens R1-R3,",
        "restarts R4-R5, the hold R17-R23 in mode HOLD (R25 between R21 and R22),",
        "otherwise R24 for the zone",
        "strategies, R11 R9 R10 R6 when no test fails, and R11 R12 R13 R14 R7 R15 R16 R8",
        "when one does). The first whose guard holds decides; its id is `Decision.rule`,",
        "and `Decision.source` says where the estimate comes from (under the alarm it is",
        "carried, not passed on). The paper's preset (`config/rover-paper.toml`) can only",
        "reach R1-R8.",
        "",
        "| rule | name | modes | guard | output | next mode | equation or reason | "
        "parameters | reason string |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in RULES:
        modes = "any" if r.modes == ANY else (
            "not HOLD" if r.modes == NOT_HOLD else ", ".join(m.name for m in r.modes))
        params = ", ".join(f"`{p}`" for p in r.params)
        cells = (r.id, r.name, modes, r.guard, r.source.name, r.next_mode, r.equation, params,
                 r.reason)
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    lines += ["", "## Parameters the rules read", "",
              "The default preset's values (`RoverDetectorParams`, the `[rover.detector]` table);",
              "their units and ranges are in `fdi/rover.py`.", "",
              "| parameter | default | rules |", "| --- | --- | --- |"]
    for name in sorted({p for r in RULES for p in r.params}):
        users = ", ".join(r.id for r in RULES if name in r.params)
        value = getattr(defaults, name)
        shown = "(table)" if name == "three_zone" else repr(value)
        lines.append(f"| `{name}` | {shown} | {users} |")
    return "\n".join(lines) + "\n"


def rule_functions() -> dict[str, list[Callable[..., object]]]:
    """The functions that implement each rule id (for the tests)."""
    out: dict[str, list[Callable[..., object]]] = {}
    fns: tuple[Callable[..., object], ...] = (
        *SCREENS, *RESTARTS, r_step_end_passing, r_drift_warn, r_drift_watch, r_accept,
        *FAULT_RULES, r_alarm, r_hold_no_doppler, *HOLD_RULES, r_zones)
    for fn in fns:
        doc = fn.__doc__ or ""
        out.setdefault(doc.split(":")[0].split(" ")[0], []).append(fn)
    return out

