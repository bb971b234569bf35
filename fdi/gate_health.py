"""Is the χ² gate doing anything? The normalised innovation squared, watched per epoch.

For a consistent Kalman filter the normalised innovation squared ``F(k) = DᵀS⁻¹D`` (Zhou & Zhang
eq. 5, the rover's χ² statistic) is χ²(m) distributed, so its mean is m, the number of degrees of
freedom (3 for an east/north/up fix). Two things go wrong in practice, and this monitor names
both:

* **mistuned filter** — the mean NIS far from m. Far below (the usual case with DGPS: R = 0.35²
  m² per axis while the epoch-to-epoch innovation is centimetres, so F sits near 0.01-0.1) means
  S is far larger than the innovations: the gate T_d = χ²₁₋α(m) sits many real σ away, and it
  flags only what is gross. Far above means S is too small: the gate fires on good fixes.
* **inert gate** — a jump of the configured minimum size ``min_jump_m`` (the issue's 3σ =
  1.05 m) could not push F over T_d. A horizontal jump J along the axis with the larger innovation
  variance adds ``J²/S_ii`` to F, so the smallest jump the gate can see is
  ``J_min = √(T_d · max(S_ee, S_nn))``; the gate is inert for jumps of ``min_jump_m`` when
  ``J_min > min_jump_m``. The same question is asked of the grey-model gate when the decision
  carries one (a horizontal residual gate wider than ``min_jump_m`` cannot see that jump).

The mean is over a sliding window of ``window`` epochs (the live figure) and over the whole run
(the summary), of the epochs the detector *accepted*: a 7 m jump gives F in the hundreds, and a
handful of faults would otherwise set the mean, so flagged epochs are counted apart
(``flagged_fraction``). A filter whose S is too small shows either way: a high accepted mean, or
more than ``max_flagged`` of the window flagged. The band ``[dof/band, dof·band]`` is
deliberately wide (default band 3): DGPS innovations are correlated in time, so the iid
confidence interval of a mean of χ² samples would be far too narrow to mean anything here.
Fed from :class:`fdi.rover.Decision` (``chi2``, ``chi2_threshold``, ``grey_gate_h``,
``fault``) plus the filter's ``S`` for the same epoch.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Literal, Protocol

Status = Literal["warming_up", "ok", "nis_low", "nis_high", "inert"]


class DecisionLike(Protocol):
    """The fields of :class:`fdi.rover.Decision` the monitor reads."""

    @property
    def chi2(self) -> float | None:
        """The epoch's χ² statistic F(k); None when the epoch was not tested."""

    @property
    def chi2_threshold(self) -> float:
        """The χ² gate T_d the statistic is compared with."""

    @property
    def grey_gate_h(self) -> float:
        """The grey model's horizontal gate at this epoch, m."""

    @property
    def fault(self) -> bool:
        """Whether the epoch's fix was judged faulty."""


@dataclass(frozen=True)
class GateHealthReport:
    """The monitor's verdict; ``messages`` say what is wrong in words, empty when all is well."""

    status: Status
    epochs: int  # epochs with a χ² statistic
    dof: int
    mean_nis: float | None  # over the whole run's accepted epochs
    mean_nis_window: float | None  # over the accepted epochs among the last ``window``
    flagged_fraction: float | None  # share of the last ``window`` tested epochs flagged
    min_detectable_jump_m: float | None  # J_min of the χ² gate at the last epoch
    grey_gate_h_m: float | None  # the grey gate at the last epoch
    min_jump_m: float
    chi2_inert_fraction: float | None  # share of epochs where J_min > min_jump_m
    messages: tuple[str, ...] = field(default=())

    def as_dict(self) -> dict[str, object]:
        """The report as a JSON-ready dict (floats rounded to 4 decimals)."""
        def r(x: float | None) -> float | None:
            return None if x is None else round(x, 4)

        return {
            "status": self.status,
            "epochs": self.epochs,
            "dof": self.dof,
            "mean_nis": r(self.mean_nis),
            "mean_nis_window": r(self.mean_nis_window),
            "flagged_fraction": r(self.flagged_fraction),
            "min_detectable_jump_m": r(self.min_detectable_jump_m),
            "grey_gate_h_m": r(self.grey_gate_h_m),
            "min_jump_m": self.min_jump_m,
            "chi2_inert_fraction": r(self.chi2_inert_fraction),
            "messages": list(self.messages),
        }


class GateHealth:
    """Feed each epoch's decision (and ``S``); ask :meth:`report` at any time."""

    def __init__(
        self,
        dof: int = 3,
        min_jump_m: float = 1.05,
        window: int = 200,
        min_epochs: int = 50,
        band: float = 3.0,
        max_flagged: float = 0.25,
    ) -> None:
        if dof < 1 or window < 1 or band <= 1.0 or min_jump_m <= 0.0:
            raise ValueError("dof >= 1, window >= 1, band > 1 and min_jump_m > 0 are required")
        self.dof = dof
        self.min_jump_m = min_jump_m
        self.window = window
        self.min_epochs = min_epochs
        self.band = band
        self.max_flagged = max_flagged
        self._win: deque[float] = deque(maxlen=window)
        self._flags: deque[bool] = deque(maxlen=window)
        self._flag_sum = 0
        self._win_sum = 0.0
        self._sum = 0.0
        self._n = 0
        self._inert = 0
        self._tested = 0
        self._j_min: float | None = None
        self._grey_gate: float | None = None
        self._t_d: float | None = None

    def update(
        self, decision: DecisionLike, S: tuple[float, float, float] | None = None
    ) -> None:
        """One epoch. ``S``: the χ² test's per-axis innovation variances (east, north, up)."""
        F = decision.chi2
        if F is None or not math.isfinite(F):
            return
        t_d = self._t_d = decision.chi2_threshold
        grey_gate = decision.grey_gate_h
        if grey_gate is not None and math.isfinite(grey_gate):
            self._grey_gate = grey_gate
        if S is not None:
            s0, s1 = S[0], S[1]
            j_min = self._j_min = math.sqrt(t_d * (s1 if s1 > s0 else s0))  # max(s0, s1)
            self._inert += j_min > self.min_jump_m
            self._tested += 1
        window = self.window
        flags = self._flags
        fault = decision.fault
        if len(flags) == window:
            self._flag_sum -= flags[0]
        flags.append(fault)
        self._flag_sum += fault
        if fault:
            return
        self._n += 1
        self._sum += F
        win = self._win
        if len(win) == window:
            self._win_sum -= win[0]
        win.append(F)
        self._win_sum += F

    def report(self) -> GateHealthReport:
        """The verdict on the epochs seen so far (:class:`GateHealthReport`)."""
        n = self._n
        mean = self._sum / n if n else None
        wmean = self._win_sum / len(self._win) if self._win else None
        inert_frac = self._inert / self._tested if self._tested else None
        flagged = self._flag_sum / len(self._flags) if self._flags else None
        msgs: list[str] = []
        status: Status = "ok"
        if len(self._flags) < self.min_epochs:
            status = "warming_up"
        else:
            lo, hi = self.dof / self.band, self.dof * self.band
            if flagged is not None and flagged > self.max_flagged:
                status = "nis_high"
                msgs.append(
                    f"{100 * flagged:.0f} % of the last {len(self._flags)} epochs flagged: S is "
                    "too small for the data (or the receiver is failing)"
                )
            elif wmean is None:
                pass
            elif wmean < lo:
                status = "nis_low"
                msgs.append(
                    f"mean normalised innovation squared {wmean:.3g} over the last "
                    f"{len(self._win)} epochs is far below its {self.dof} degrees of freedom: "
                    "the filter's S (R, q) is much larger than the innovations, so the chi-square "
                    "gate only flags gross jumps (typical of DGPS with R from the absolute sigma)"
                )
            elif wmean > hi:
                status = "nis_high"
                msgs.append(
                    f"mean normalised innovation squared {wmean:.3g} over the last "
                    f"{len(self._win)} epochs is far above its {self.dof} degrees of freedom: "
                    "S is too small for the data, so the chi-square gate fires on good fixes"
                )
            if self._j_min is not None and self._j_min > self.min_jump_m:
                msgs.append(
                    f"chi-square gate is inert for {self.min_jump_m:.2f} m jumps: with the current "
                    f"S the smallest jump that can exceed T_d = {self._t_d:.3f} is "
                    f"{self._j_min:.2f} m"
                )
                status = "inert" if status == "ok" else status
            if self._grey_gate is not None and self._grey_gate > self.min_jump_m:
                msgs.append(
                    f"grey gate {self._grey_gate:.2f} m is wider than the {self.min_jump_m:.2f} m "
                    "minimum jump: such a jump passes the grey test"
                )
                status = "inert" if status == "ok" else status
        return GateHealthReport(
            status=status,
            epochs=n,
            dof=self.dof,
            mean_nis=mean,
            mean_nis_window=wmean,
            flagged_fraction=flagged,
            min_detectable_jump_m=self._j_min,
            grey_gate_h_m=self._grey_gate,
            min_jump_m=self.min_jump_m,
            chi2_inert_fraction=inert_frac,
            messages=tuple(msgs),
        )
