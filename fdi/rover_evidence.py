"""The rover isolator's words: its modes, where an output comes from, one epoch's evidence,
and the small named records it remembers between epochs (:mod:`fdi.rover`).

The evidence is computed once per epoch, before any rule is asked (:mod:`fdi.rover_rules`):

* the chi-square statistic F(k) = DᵀS⁻¹D against T_d (eq. 1-6);
* the grey residual ε(k) = x⁰(k) − x̂⁰(k) against its gate (eq. 18);
* the Doppler residual: the fix against the accepted fix of ``window`` epochs ago moved by the
  Doppler displacement since, and the receiver against its own Doppler over RAW_HORIZON epochs;
* the drift statistic g (D4, :mod:`fdi.drift`) over its horizons;
* the frozen test (the fix repeated bit for bit);
* the quality screens (satellites, HDOP).

Units: metres, seconds; vectors are (east, north[, up]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import Literal, NamedTuple

from fdi.drift import DriftResult

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]


TIME_RESET_EPOCHS = 3
"""A receiver's clock that jumps back by more than ``max_gap_s`` is believed (the filter
restarts on the new time base) once this many fixes in a row follow the new time, each after
the last: one corrupt time cannot restart the filter on its fix."""

class Mode(Enum):
    """What the isolator is doing between epochs, from its memory (``RoverIsolator.mode``).

    The alarm is not a mode: it latches across modes (``Decision.alarm``)."""

    TRACK = "track"  # the receiver's fixes are passed on
    REPLACE = "replace"  # a run of replaced fixes (the paper's isolation)
    STEP_BACK = "step_back"  # a run of faults that began with a step back to an older level
    STEP_END = "step_end"  # fixes back before a remembered step, being confirmed
    COAST = "coast"  # under the alarm, coasting on the Doppler from the last accepted fix
    HOLD = "hold"  # holding the old track after a level change (fdi/level.py)


class Source(Enum):
    """Where the epoch's estimate comes from, apart from ``fault`` and ``alarm`` (under the
    alarm it is carried, not passed on: ``out_enu`` is then None)."""

    RAW = "raw"  # the receiver's fix
    PREDICTION = "prediction"  # the grey (GM(1,1)) prediction, eq. 7-17
    OLD_TRACK = "old_track"  # the last trusted level moved by the Doppler, eq. L1
    DOPPLER_COAST = "doppler_coast"  # the prediction carried on the Doppler, under the alarm
    NONE = "none"  # nothing


@dataclass(slots=True)
class Stats:
    """One epoch's test statistics, carried into its ``Decision``."""

    gate_h: float
    gate_u: float
    doppler_gate: float
    pred: Vec3 | None = None
    doppler_res: float | None = None
    res_h: float | None = None
    res_u: float | None = None
    F: float | None = None
    drift: float | None = None


class LiveFix(NamedTuple):
    """The last live fix with a Doppler (not a repeat of the one before): where a frozen
    receiver's coast starts (R25, fdi/coast.py)."""

    t: float
    e: float  # the fix (east, north)
    n: float
    de: float  # the Doppler displacement then (east, north)
    dn: float
    ve: float  # its Doppler velocity
    vn: float


@dataclass(slots=True)
class Evidence:
    """Everything the rules of :mod:`fdi.rover_rules` decide on, computed once an epoch."""

    t_s: float
    dt: float
    z: Vec3  # the fix (a 2D fix holds the last height)
    r: Vec3  # its variance (R)
    v: Vec2 | None  # the Doppler velocity
    up_known: bool  # the fix has a height to test
    quality: list[str]  # failed quality screens ("sats", "hdop")
    frozen: bool  # the frozen test: the receiver is frozen
    stale: bool  # ... and its whole fix repeats (its Doppler is void)
    stats: Stats
    restart: str = ""  # why the filter restarts on this fix ("start", ...), or ""
    d: list[float] = field(default_factory=list)  # the Doppler displacement
    have_doppler: bool = False  # a Doppler velocity at this epoch and the previous one
    raw_consistent: bool = True  # the receiver agrees with its own Doppler (RAW_HORIZON)
    doppler_fault: bool = False
    b: Vec2 | None = None  # the Doppler-free value (D1)
    prev_b: Vec2 | None = None  # ... the previous epoch's, and its time
    prev_bt: float = 0.0
    drift: DriftResult | None = None  # the drift test (D4)
    drift_fault: bool = False
    grey_fault: bool = False
    chi2_fault: bool = False
    # What the fault rules found (RoverIsolator._find, before the fault rules)
    reasons: list[str] = field(default_factory=list)
    back: bool = False  # a step back to an older level (or the end of a remembered step)
    back_level: float | None = None  # ... the older level's time
    rev: float | None = None  # the remembered step whose level the fix is back before
    # When no test fails (RoverIsolator._pass_clean)
    warn: bool = False  # drift_warn_sigmas < g
    watch: bool = False  # ramp_sigmas < g at the ramp_window_s horizon
    fed: bool = False  # the prediction was fed to the window and the filter (R7, R13, R14)

    @property
    def stale_fault(self) -> bool:
        """The frozen test fails and the drift test's value exists."""
        return self.frozen and self.b is not None

    @property
    def abrupt(self) -> bool:
        """A jump the grey or chi-square test sees."""
        return self.grey_fault or self.chi2_fault

    @property
    def any_fault(self) -> bool:
        return (self.grey_fault or self.chi2_fault or self.doppler_fault or bool(self.quality)
                or self.drift_fault or self.stale_fault)


class Accepted(NamedTuple):
    """An accepted fix with the Doppler displacement and velocity at it."""

    e: float
    n: float
    de: float
    dn: float
    ve: float
    vn: float


class RawFix(NamedTuple):
    """A receiver fix with the Doppler displacement at it."""

    e: float
    n: float
    de: float
    dn: float


class FixSignature(NamedTuple):
    """What the frozen test compares between consecutive fixes: the whole fix."""

    enu: Vec3 | None
    speed_mps: float | None
    course_deg: float | None


class LastStep(NamedTuple):
    """The last step of the Doppler-free value between two epochs."""

    t: float
    m: float  # its size


@dataclass(slots=True)
class Step:
    """An abrupt step remembered at the start of a run of faults (``_note_step``)."""

    t0: float  # time of the trusted reference before it
    b0e: float  # that reference's Doppler-free value (east, north)
    b0n: float
    se: float  # the step (east, north)
    sn: float
    accepted: bool = False  # the track was seen nearer the stepped level (_track_at)

    def reversed_by(self, je: float, jn: float, floor: float = 0.0) -> bool:
        """A step from the track of (``je``, ``jn``) is this step reversed, within
        REVERSAL_FRAC x its size or ``floor`` (both are measured over an epoch, so the slow
        DGPS error between them cancels; the epoch's own noise does not), but never
        REVERSAL_MAX_FRAC x its size: a reversal moves at least 1 - REVERSAL_FRAC of it back."""
        size = math.hypot(self.se, self.sn)
        return math.hypot(je + self.se, jn + self.sn) <= max(REVERSAL_FRAC * size,
                                                         min(floor, REVERSAL_MAX_FRAC * size))


# A step from the track reverses a remembered step within this fraction of its size ...
REVERSAL_FRAC = 0.4
# ... or within the epoch's noise floor, up to this fraction of its size.
REVERSAL_MAX_FRAC = 0.6


@dataclass(slots=True)
class StepEndWatch:
    """Fixes back before a remembered step, being confirmed (``_step_end``)."""

    rev: float  # the remembered step's time
    b: Vec2  # the Doppler-free value where the confirmation began ...
    t: float  # ... and its time
    epochs: int  # epochs since


@dataclass(slots=True)
class PassedReversal:
    """A remembered step reversed by fixes that pass the tests (``_passed_reversal``)."""

    t0: float  # the step's time
    b: Vec2  # the first such fix's Doppler-free value ...
    t: float  # ... and time
    last: float  # the last such fix's time


Action = Literal["accept", "replace", "alarm", "no_fix"]


class FixInput(NamedTuple):
    """One receiver epoch in local metres (``None`` position: the receiver has no fix).

    Immutable; a NamedTuple rather than a frozen dataclass (built once an epoch: a frozen
    dataclass's ``__init__`` sets each field through ``object.__setattr__``)."""

    t_s: float  # monotonic fix time (UTC seconds, rollover-corrected)
    enu: tuple[float, float, float] | None
    speed_mps: float | None = None
    course_deg: float | None = None
    sd_enu_m: tuple[float, float, float] | None = None  # from GST
    num_sats: int | None = None
    hdop: float | None = None


class Decision(NamedTuple):
    """What the isolator did with one epoch, and the statistics that led to it (immutable; a
    NamedTuple, built once an epoch: see :class:`FixInput`; ``_replace`` for a changed copy)."""

    action: Action
    fault: bool
    reason: str
    out_enu: tuple[float, float, float] | None  # what is passed on (None: nothing valid)
    pred_enu: tuple[float, float, float] | None
    grey_res_h: float | None
    grey_res_u: float | None
    grey_gate_h: float
    grey_gate_u: float
    doppler_res: float | None
    doppler_gate: float
    chi2: float | None
    chi2_threshold: float
    consecutive: int
    alarm: bool
    alarm_raised: bool  # the alarm was raised at this epoch
    kf_enu: tuple[float, float, float] | None
    zones: tuple[int, ...] | None = None  # three_zone/combined: per axis 0/1/2 (e, n[, u])
    drift: float | None = None  # the drift test's statistic (D4), or the hold's, in σ
    rule: str = ""  # the rule of fdi/rover_rules.py that decided (R1 ...)
    source: Source = Source.NONE  # where the estimate comes from (under the alarm: carried)
