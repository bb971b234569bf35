"""Score a rover replay (``epochs.jsonl``) against the generator's truth (``truth.jsonl``).

Epochs are matched by fix time (UTC seconds of day, to the millisecond). For every faulty epoch
of the truth file, a detection is an epoch the pipeline judged faulty (``fault``); on clean
epochs, the same flag is a false alarm. Accuracy is horizontal error in metres against the true
position: raw input over clean epochs, and output over clean, faulty and all epochs (epochs with
no output — alarms, no-fix — are counted apart, not as zero error).

For ``fdi-bridge eval`` it also gives: per fault event the detection delay in epochs and seconds
(from the event's first faulty epoch to its first flagged one), events detected, missed epochs,
the raw input's RMS and maximum error over faulty and all epochs, and the false alarms that are
the step back to the truth when a fault ends (a flagged run of clean epochs starting right after
a faulty epoch or an outage: ``false_alarms_after_fault``) apart from isolated ones.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fdi.geodesy import LocalFrame


def read_jsonl(path: str | Path) -> list[dict[str, Any]]:
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]


def _key(utc: float) -> int:
    return round(utc * 1000.0)


@dataclass
class RoverScore:
    faulty: int = 0
    detected: int = 0
    faulty_min: int = 0  # faulty epochs at or above the minimum jump size
    detected_min: int = 0
    clean: int = 0
    false_alarms: int = 0
    no_output_faulty: int = 0
    no_output_clean: int = 0
    raw_rms_clean_m: float = math.nan
    out_rms_clean_m: float = math.nan
    out_rms_faulty_m: float = math.nan
    out_rms_all_m: float = math.nan
    out_max_faulty_m: float = math.nan
    dgps_rms_faulty_m: float = math.nan  # the receiver's own error at the faulty epochs
    alarms: int = 0
    delays_epochs: tuple[int, ...] = ()
    # Added for ``fdi-bridge eval`` (issue 6).
    delays_s: tuple[float, ...] = ()
    events: int = 0  # fault events with at least one epoch at or above the minimum size
    events_detected: int = 0  # ... of which at least one epoch was flagged
    raw_rms_faulty_m: float = math.nan
    raw_rms_all_m: float = math.nan
    raw_max_clean_m: float = math.nan
    raw_max_faulty_m: float = math.nan
    raw_max_all_m: float = math.nan
    out_max_clean_m: float = math.nan
    out_max_all_m: float = math.nan
    # False alarms in the run of flagged clean epochs that starts right after a fault ends (the
    # step back from a ramp's or a frozen fix's offset to the truth), counted apart.
    false_alarms_after_fault: int = 0

    @property
    def missed(self) -> int:
        """Faulty epochs at or above the minimum size that were not flagged."""
        return self.faulty_min - self.detected_min

    @property
    def mean_delay_epochs(self) -> float:
        d = self.delays_epochs
        return sum(d) / len(d) if d else math.nan

    @property
    def mean_delay_s(self) -> float:
        d = self.delays_s
        return sum(d) / len(d) if d else math.nan

    @property
    def detection_rate(self) -> float:
        return self.detected_min / self.faulty_min if self.faulty_min else math.nan

    @property
    def false_alarm_rate(self) -> float:
        return self.false_alarms / self.clean if self.clean else math.nan

    def as_dict(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d["delays_epochs"] = list(self.delays_epochs)
        d["delays_s"] = list(self.delays_s)
        d["missed"] = self.missed
        d["false_alarms_isolated"] = self.false_alarms - self.false_alarms_after_fault
        d["mean_delay_epochs"] = self.mean_delay_epochs
        d["mean_delay_s"] = self.mean_delay_s
        d["detection_rate"] = self.detection_rate
        d["false_alarm_rate"] = self.false_alarm_rate
        ratio = self.out_rms_faulty_m / self.raw_rms_clean_m if self.raw_rms_clean_m else math.nan
        d["rms_ratio_faulty_vs_raw_clean"] = ratio
        return d


def _rms(values: Iterable[float]) -> float:
    vals = list(values)
    return math.sqrt(sum(v * v for v in vals) / len(vals)) if vals else math.nan


def _max(values: list[float]) -> float:
    return max(values) if values else math.nan


def score_rover(
    epochs: list[dict[str, Any]],
    truth: list[dict[str, Any]],
    min_offset_m: float = 1.05,
    fault_key: str = "fault",
) -> RoverScore:
    """Score ``epochs`` (pipeline records) against ``truth`` (generator records)."""
    by_t = {_key(e["utc"]): e for e in epochs if e.get("utc") is not None}
    ref = truth[0]
    frame = LocalFrame(ref["true_lat"], ref["true_lon"], ref["true_alt"])
    s = RoverScore()
    raw_clean: list[float] = []
    raw_faulty: list[float] = []
    out_clean: list[float] = []
    out_faulty: list[float] = []
    dgps_faulty: list[float] = []
    event_first: dict[int, int] = {}
    event_detect: dict[int, int] = {}
    event_first_t: dict[int, float] = {}
    event_detect_t: dict[int, float] = {}
    event_min: set[int] = set()
    transition = False  # inside a flagged run that began as a fault ended
    for tr in truth:
        ep = by_t.get(_key(tr["utc"]))
        if tr.get("outage"):
            transition = True
            continue
        if ep is None:
            continue
        te, tn, _ = frame.to_enu(tr["true_lat"], tr["true_lon"], tr["true_alt"])
        flagged = bool(ep.get(fault_key))
        if ep.get("alarm_raised"):
            s.alarms += 1
        out_err = None
        if ep.get("lat") is not None:
            oe, on, _ = frame.to_enu(ep["lat"], ep["lon"], tr["true_alt"])
            out_err = math.hypot(oe - te, on - tn)
        if tr["fault"]:
            s.faulty += 1
            s.detected += flagged
            ev = tr["fault_event"]
            if tr["fault_offset_m"] >= min_offset_m or tr["fault_kind"] in ("frozen",):
                s.faulty_min += 1
                s.detected_min += flagged
                event_min.add(ev)
            event_first.setdefault(ev, tr["k"])
            event_first_t.setdefault(ev, tr["utc"])
            if flagged and ev not in event_detect:
                event_detect[ev] = tr["k"]
                event_detect_t[ev] = tr["utc"]
            dgps_faulty.append(math.hypot(tr["err_e"], tr["err_n"]))
            if ep.get("raw_lat") is not None:
                re_, rn, _ = frame.to_enu(ep["raw_lat"], ep["raw_lon"], tr["true_alt"])
                raw_faulty.append(math.hypot(re_ - te, rn - tn))
            if out_err is None:
                s.no_output_faulty += 1
            else:
                out_faulty.append(out_err)
            transition = True
        else:
            s.clean += 1
            s.false_alarms += flagged
            transition = transition and flagged
            s.false_alarms_after_fault += transition
            if ep.get("raw_lat") is not None:
                re_, rn, _ = frame.to_enu(ep["raw_lat"], ep["raw_lon"], tr["true_alt"])
                raw_clean.append(math.hypot(re_ - te, rn - tn))
            if out_err is None:
                s.no_output_clean += 1
            else:
                out_clean.append(out_err)
    s.raw_rms_clean_m = _rms(raw_clean)
    s.raw_rms_faulty_m = _rms(raw_faulty)
    s.raw_rms_all_m = _rms(raw_clean + raw_faulty)
    s.raw_max_clean_m = _max(raw_clean)
    s.raw_max_faulty_m = _max(raw_faulty)
    s.raw_max_all_m = _max(raw_clean + raw_faulty)
    s.out_max_clean_m = _max(out_clean)
    s.out_max_all_m = _max(out_clean + out_faulty)
    s.events = len(event_min)
    s.events_detected = sum(1 for ev in event_min if ev in event_detect)
    s.delays_s = tuple(
        round((event_detect_t[e] - event_first_t[e]) % 86400.0, 6) for e in sorted(event_detect)
    )
    s.out_rms_clean_m = _rms(out_clean)
    s.out_rms_faulty_m = _rms(out_faulty)
    s.out_rms_all_m = _rms(out_clean + out_faulty)
    s.out_max_faulty_m = max(out_faulty) if out_faulty else math.nan
    s.dgps_rms_faulty_m = _rms(dgps_faulty)
    s.delays_epochs = tuple(event_detect[e] - event_first[e] for e in sorted(event_detect))
    return s
