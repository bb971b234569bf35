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
from dataclasses import dataclass, field
from typing import Literal

from fdi.lms_fir import DetectorConfig, DualCriterionDetector, wrap180

Source = Literal["sensor", "fir", "compensated", "none"]
State = Literal["normal", "suspect", "fault_fir", "fault_comp"]


@dataclass(frozen=True)
class FtConfig:
    """The substitution and stuck/recovery rules (the ``[ft]`` table)."""

    substitute_while_suspect: bool = True
    offset_compensation: bool = True
    offset_samples: int = field(default=10, metadata={"ge": 2})
    offset_max_std_deg: float = field(default=1.5, metadata={"gt": 0.0})
    recover_gate_deg: float = field(default=3.0, metadata={"gt": 0.0})
    recover_samples: int = field(default=10, metadata={"ge": 1})
    stuck_samples: int = field(default=10, metadata={"ge": 0, "doc": "0 disables"})
    stuck_eps_deg: float = field(default=1e-6, metadata={"ge": 0.0})
    smooth_gain: float = field(default=0.2, metadata={"gt": 0.0, "le": 1.0})


@dataclass(frozen=True)
class HeadingDecision:
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

    def step(self, u_prev: float, heading_meas: float | None) -> HeadingDecision:
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
        d_live = det.predict_deg()
        event = ""
        # Stuck reading: a run of identical values, snapshot of the weights when it began.
        if self.cfg.stuck_samples and abs(dy) <= self.cfg.stuck_eps_deg:
            if self._run == 0:
                if det.suspect_open and det.stored:
                    self._snap = list(det.stored)
                else:
                    self._snap = list(det.fir.C_avg if det.fir.avg_alpha else det.fir.C)
                self._run_start_y = y_prev
                self._run_pred = 0.0
            self._run += 1
            self._run_pred += d_live
        else:
            self._run = 0
        r = det.step(dy)
        if self.state == "normal":
            # Substitution starts from a smoothed heading, not from one noisy reading:
            # hf(k) = hf(k-1) + d(k) + L (y(k) - hf(k-1) - d(k)).
            pred = (self._hf if self._hf is not None else y_prev) + r.d_deg
            if r.suspect and r.exceed:
                self.state = "suspect"
                self._psi = pred
                event = "suspect"
            else:
                self._hf = pred + self.cfg.smooth_gain * (self._y - pred)
        elif self.state == "suspect":
            self._psi += r.d_deg if det.stored is None else self._stored_pred_deg()
            if r.confirmed:
                self._confirm("sensor")
                event = "confirmed"
            elif r.dismissed:
                self.state = "normal"
                self._hf = self._psi
                event = "dismissed"
        else:
            self._psi += r.d_deg  # frozen detector = stored model
            event = self._fault_step(r.exceed)
        stuck = self.cfg.stuck_samples and self._run >= self.cfg.stuck_samples
        if stuck and self.state in ("normal", "suspect"):
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
            event = "stuck"
        return self._decide(self._y, r.d_deg, r.e2, r.snr, r.V, event)

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

    def _fault_step(self, jump: bool) -> str:
        cfg = self.cfg
        resid = wrap180(self._y - self._psi)
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
        self, y: float | None, d: float, e2: float, snr: float, V: float, event: str
    ) -> HeadingDecision:
        substituting = self.enabled and self.state != "normal"
        if not self.cfg.substitute_while_suspect and self.state == "suspect":
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
        fault = self.state in ("fault_fir", "fault_comp")
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
