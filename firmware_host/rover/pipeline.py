"""The rover pipeline: receiver bytes -> epochs -> isolation -> outputs, with its counters.

:class:`RoverPipeline` is fed bytes (from whatever port the loop reads) and, per receiver epoch,

1. converts the fix to local metres (reference: configured, else the first valid fix) and the
   fix time to a monotonic time (midnight rollover handled);
2. runs :class:`fdi.rover.RoverIsolator`;
3. writes one JSON Lines record (the replay contract, see README), a corrected NMEA burst and a
   MAVLink GPS_INPUT, as configured;
4. counts everything for ``summary()``.

It is deterministic given its input bytes: nothing from the wall clock reaches the epoch
records (processing times go to the summary only), so replaying a recorded session reproduces
the same ``epochs.jsonl``.
"""

from __future__ import annotations

import io
import json
import logging
import math
import time
from collections import Counter
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol, TextIO

from drivers.gps.epochs import GpsEpoch
from drivers.gps.link import LinkCheck, bits_per_byte
from drivers.gps.stream import NmeaStream
from drivers.ratelog import RateLimitedLog
from fdi.gate_health import GateHealth
from fdi.geodesy import LocalFrame
from fdi.rover import Decision, FixInput, RoverIsolator
from firmware_host.runtime.config import RoverConfig
from firmware_host.runtime.loop import EpochTimer, percentile
from firmware_host.runtime.records import (
    encode_line,
    encode_plain_line,
    numbers_spelled_alike,
    round2,
    round4_all,
)

GREY_GATE_MARGIN = 1.1  # the grey gate's width over the minimum jump that is worth a warning
GATE_PERSIST = 2  # gate-health checks in a row before a warning

log = logging.getLogger("fdi_bridge.rover")


class EpochSink(Protocol):
    """Something that takes each epoch's outcome (corrected NMEA, MAVLink, ...)."""

    def emit(self, out: EpochOutcome) -> None: ...

    def close(self) -> None: ...


class EpochOutcome(NamedTuple):
    """One epoch's input, decision and output position, handed to the sinks (immutable; a
    NamedTuple: built once an epoch, faster than a frozen dataclass)."""

    epoch: GpsEpoch
    decision: Decision
    lat: float | None
    lon: float | None
    alt: float | None
    t_s: float | None
    record: dict[str, Any]
    # The receiver's true heading in this epoch (HDT, THS mode A), carried to the outputs; it
    # takes no part in detection. None when the receiver gave none in this epoch.
    heading_deg: float | None = None


_new = tuple.__new__


_NONE3 = (None, None, None)


class RoverPipeline:
    def __init__(
        self,
        cfg: RoverConfig,
        *,
        jsonl: TextIO | None = None,
        sinks: list[EpochSink] | None = None,
        perf_clock: Callable[[], float] = time.perf_counter,
        ratelog: RateLimitedLog | None = None,
        baudrate: int | None = None,
        warn_link: bool = False,
    ) -> None:
        self.cfg = cfg
        self.ratelog = ratelog or RateLimitedLog(log)
        self.stream = NmeaStream(cfg.max_line, self.ratelog)
        self.isolator = RoverIsolator(cfg.detector)
        # Is the chi-square gate doing anything? (min jump: 3 sigma, the smallest fault)
        self.gate_health = GateHealth(min_jump_m=3.0 * cfg.detector.sigma_m)
        # Does the receiver's output fit its line? (drivers/gps/link.py; ``baudrate``: the
        # capture's, else the port's; 0: unknown, not judged). ``warn_link``: say it in the log.
        port = cfg.port
        self.link = LinkCheck(cfg.port.baudrate if baudrate is None else baudrate,
                              bits_per_byte(port.bytesize, port.parity, port.stopbits))
        self.warn_link = warn_link
        self._gate_said: tuple[str, bool] | None = None  # the gate health last said
        self._gate_run = 0  # gate-health checks in a row that would warn
        self.frame: LocalFrame | None = None
        if cfg.reference is not None:
            ref = cfg.reference
            self.frame = LocalFrame(ref.lat_deg, ref.lon_deg, ref.alt_m)
        self.jsonl = jsonl
        self.sinks = sinks or []
        self.actions: Counter[str] = Counter()
        self.reasons: Counter[str] = Counter()
        self.epochs = 0
        self.faults = 0
        self.alarms_raised = 0
        self.sink_errors = 0
        self.timer = EpochTimer(perf_clock)  # per-epoch processing time and overruns
        self._last_utc: float | None = None
        self._day = 0.0
        self._period_s: float | None = None
        self._last_t: float | None = None
        self.last_outcome: EpochOutcome | None = None
        # The record's date, with what it was made from (_record).
        self._date_key: tuple[int, int, int] | None = None
        self._date_text: str | None = None

    # ------------------------------------------------------------------ feeding

    def feed(self, data: bytes) -> int:
        """Feed received bytes; process every epoch they complete. Returns epochs processed."""
        n = 0
        for epoch in self.stream.feed(data):
            self.process(epoch)
            n += 1
        if n and self.link.result is None:
            self._check_link()
        return n

    def _check_link(self) -> None:
        last = self.last_outcome
        fit = self.link.observe(self.stream.bytes_in, self.epochs, self._period_s,
                                last.epoch.sentences if last is not None else ())
        if fit is not None and not fit.fits and self.warn_link:
            log.warning("%s", fit.message())

    def finish(self) -> int:
        n = 0
        for epoch in self.stream.flush():
            self.process(epoch)
            n += 1
        for sink in self.sinks:
            sink.close()
        return n

    # ------------------------------------------------------------------ one epoch

    def _time(self, utc: float | None) -> float | None:
        if utc is None:
            return None
        if self._last_utc is not None and utc < self._last_utc - 43200.0:
            self._day += 86400.0  # midnight rollover
        self._last_utc = utc
        return utc + self._day

    def process(self, epoch: GpsEpoch) -> EpochOutcome:
        self.timer.start()
        t_s = self._time(epoch.utc_s)
        lat_deg, lon_deg, alt_msl = epoch.lat_deg, epoch.lon_deg, epoch.alt_msl_m
        frame = self.frame
        enu = None
        h = None
        if epoch.valid and lat_deg is not None and lon_deg is not None:
            if alt_msl is not None:
                h = alt_msl + (epoch.geoid_sep_m or 0.0)
            if frame is None:
                frame = self.frame = LocalFrame(lat_deg, lon_deg, h or 0.0)
            if h is None:
                e, n, _ = frame.to_enu(lat_deg, lon_deg, frame.h0_m)
                enu = (e, n, math.nan)  # a 2D fix: height unknown
            else:
                enu = frame.to_enu(lat_deg, lon_deg, h)
        sd = None
        sd_lat = epoch.sd_lat_m
        if sd_lat is not None and epoch.sd_lon_m is not None:
            sd = (epoch.sd_lon_m, sd_lat, epoch.sd_alt_m or 2.0 * sd_lat)
        if t_s is None and enu is not None:
            enu = None  # a fix with no time cannot be put in order: not passed on
        # The tuple of FixInput's fields, in order (this runs once an epoch).
        fix = _new(FixInput, (
            t_s if t_s is not None else 0.0,  # t_s
            enu,
            epoch.speed_mps,
            epoch.course_deg,
            sd,  # sd_enu_m
            epoch.num_sats,
            epoch.hdop,
        ))
        isolator = self.isolator
        d = isolator.step(fix)
        self.gate_health.update(d, isolator.kf.S if d.chi2 is not None else None)
        lat = lon = alt = None
        if d.out_enu is not None and frame is not None:
            if d.action == "accept":
                lat, lon, alt = lat_deg, lon_deg, alt_msl
            else:
                glat, glon, gh = frame.to_lla(*d.out_enu)
                lat, lon = glat, glon
                alt = gh - (epoch.geoid_sep_m or 0.0) if alt_msl is not None else None
        jsonl = self.jsonl
        record: dict[str, Any] = {}
        plain = False
        if jsonl is not None:
            record, plain = self._record(epoch, d, enu, lat, lon, alt)
        # The tuple of EpochOutcome's fields, in order (its __new__ without the Python call).
        outcome = _new(EpochOutcome, (epoch, d, lat, lon, alt, t_s, record, epoch.heading_deg))
        self.last_outcome = outcome
        # Counters.
        self.epochs += 1
        self.actions[d.action] += 1
        if d.reason:
            self.reasons[d.reason] += 1
        self.faults += d.fault
        if d.alarm_raised:
            self.alarms_raised += 1
            log.warning("GPS alarm at utc %s: %d faults in a row; stop automatic navigation",
                        epoch.utc_s, self.cfg.detector.max_consecutive)
        if self.epochs % 100 == 0:
            self._check_gate_health()
        if jsonl is not None:
            jsonl.write(encode_plain_line(record) if plain else encode_line(record))
        for sink in self.sinks:
            try:
                sink.emit(outcome)
            except Exception as err:  # an output failing must not stop the detectors
                self.sink_errors += 1
                self.ratelog.warning(f"output {type(sink).__name__}", str(err))
        # The receiver's epoch period (smoothed) is the budget an epoch overruns.
        if t_s is not None:
            last_t = self._last_t
            if last_t is not None and 0 < t_s - last_t < 5.0:
                p = t_s - last_t
                self._period_s = p if self._period_s is None else 0.9 * self._period_s + 0.1 * p
            self._last_t = t_s
        self.timer.stop(self._period_s)
        return outcome

    def _check_gate_health(self) -> None:
        """Say the gate's health when it changes, never the same state twice in a row.

        A χ² gate that only sees gross jumps (NIS far below its degrees of freedom) is what
        DGPS gives with R from the absolute sigma, and the default detector expects it: the
        grey test carries the detection (its gate covers the minimum jump). That state is kept
        in the summary (``gate_health``) and said at DEBUG only; on the project's own healthy
        receiver it used to be an INFO line every 100 epochs (8 640 a day at 10 Hz). A warning
        when nothing in the pipeline could see the minimum jump, or S is too small (good fixes
        flagged); an INFO line when that clears."""
        health = self.gate_health.report()
        said = self._gate_said
        # Hysteresis on the grey gate against the minimum jump: it wanders a few per cent with
        # the fixes, and on a DGPS receiver it sat at 1.05-1.08 m against a 1.05 m minimum
        # jump, so the warning and its all-clear alternated 20 times a day. A warning needs
        # the gate GREY_GATE_MARGIN wider than the minimum jump; it clears once within it.
        margin = 1.0 if said is not None and said[1] else GREY_GATE_MARGIN
        grey_covers = (
            self.cfg.detector.strategy == "grey"
            and health.grey_gate_h_m is not None
            and health.grey_gate_h_m <= margin * health.min_jump_m
        )
        alarming = bool(health.messages) and (health.status == "nis_high" or not grey_covers)
        # ... and it must hold on GATE_PERSIST checks in a row (each over its own 100 epochs):
        # a single check's excursion (2 a day on that receiver, each gone at the next check)
        # is the fixes' noise, not a mistuned gate.
        self._gate_run = self._gate_run + 1 if alarming else 0
        if alarming and not (said is not None and said[1]) and self._gate_run < GATE_PERSIST:
            return
        key = (health.status, alarming)
        if key == said:
            return
        self._gate_said = key
        if alarming:
            log.warning("gate health: %s", "; ".join(health.messages))
        elif said is not None and said[1]:
            log.info("gate health: %s", "; ".join(health.messages) or "consistent again")
        elif health.messages:
            log.debug("gate health (expected with the grey test): %s",
                      "; ".join(health.messages))

    def _record(
        self,
        e: GpsEpoch,
        d: Decision,
        enu: tuple[float, float, float] | None,
        lat: float | None,
        lon: float | None,
        alt: float | None,
    ) -> tuple[dict[str, Any], bool]:
        """The epoch's record, and whether it holds only values orjson writes as json.dumps
        does (then :func:`~firmware_host.runtime.records.encode_plain_line` writes it).
        Its rounded values in one :func:`~firmware_host.runtime.records.round4_all` (this runs
        once an epoch), which also says whether they are plain."""
        enu_v = None
        if enu:
            ee, nn, u = enu
            enu_v = (ee, nn, None if u != u else u)  # a 2D fix's NaN height: null
        pred, kf = d.pred_enu, d.kf_enu
        (e_, n_, u_, pe, pn, pu, ke, kn, ku, speed, rh, ru, dr, chi2, gh, gu, dg, ct
         ), plain = round4_all((*(enu_v or _NONE3), *(pred or _NONE3), *(kf or _NONE3),
                                e.speed_mps, d.grey_res_h, d.grey_res_u, d.doppler_res, d.chi2,
                                d.grey_gate_h, d.grey_gate_u, d.doppler_gate, d.chi2_threshold))
        date = e.date
        if date != self._date_key:  # the same date epoch after epoch: kept
            self._date_key = date
            self._date_text = None if date is None else "{:04d}-{:02d}-{:02d}".format(*date)
        drift, zones = d.drift, d.zones
        drift = None if drift is None else round2(drift)
        utc, raw_lat, raw_lon, raw_alt, hdop, course = (
            e.utc_s, e.lat_deg, e.lon_deg, e.alt_msl_m, e.hdop, e.course_deg)
        action, reason = d.action, d.reason
        # Does orjson write this record as json.dumps does (records.encode_line's test, done
        # here on what only this record can hold: its numbers and two strings; the keys are
        # the literals below, the date is digits, the rest booleans and small integers)? The
        # rounded ones said so above; an accepted fix's output is the receiver's own.
        text = action + reason
        plain = (plain and zones is None and text.isascii() and text.isprintable()
                 and numbers_spelled_alike(
                     (utc, raw_lat, raw_lon, raw_alt, hdop, course, drift)
                     if lat is raw_lat and lon is raw_lon and alt is raw_alt else
                     (utc, raw_lat, raw_lon, raw_alt, lat, lon, alt, hdop, course, drift)))
        return {
            "utc": utc,
            "date": self._date_text,
            "raw_lat": raw_lat,
            "raw_lon": raw_lon,
            "raw_alt": raw_alt,
            "lat": lat,
            "lon": lon,
            "alt": alt,
            "fault": d.fault,
            "action": action,
            "reason": reason,
            "alarm": d.alarm,
            "alarm_raised": d.alarm_raised,
            "quality": e.quality,
            "sats": e.num_sats,
            "hdop": hdop,
            "speed": speed,
            "course": course,
            "e": e_,
            "n": n_,
            "u": u_,
            "pred_e": pe,
            "pred_n": pn,
            "pred_u": pu,
            "grey_res_h": rh,
            "grey_res_u": ru,
            "grey_gate_h": gh,
            "grey_gate_u": gu,
            "doppler_res": dr,
            "doppler_gate": dg,
            "drift": drift,
            "chi2": chi2,
            "chi2_threshold": ct,
            "consecutive": d.consecutive,
            "zones": None if zones is None else list(zones),
            "kf_e": ke,
            "kf_n": kn,
            "kf_u": ku,
        }, plain

    # ------------------------------------------------------------------ summary

    def summary(self) -> dict[str, Any]:
        stats = self.timer.stats
        proc = sorted([v * 1e3 for v in stats.proc_s])  # once, for both percentiles
        return {
            "epochs": self.epochs,
            "faults": self.faults,
            "alarms": self.alarms_raised,
            "actions": dict(sorted(self.actions.items())),
            "reasons": dict(sorted(self.reasons.items())),
            "input": self.stream.counters(),
            "output_errors": self.sink_errors,
            "outputs": {type(sink).__name__: _sink_stats(sink) for sink in self.sinks},
            "epoch_period_s": None if self._period_s is None else round(self._period_s, 4),
            "processing_ms": {
                "p50": round(percentile(proc, 50), 4),
                "p99": round(percentile(proc, 99), 4),
                "max": round(stats.proc_s.peak * 1e3, 4),
            },
            "overruns": stats.overruns,
            "detector": {
                "strategy": self.cfg.detector.strategy,
                "chi2_threshold": round(self.isolator.T_d, 4),
                "predictor": self.cfg.detector.predictor,
            },
            "gate_health": self.gate_health.report().as_dict(),
            "link": None if self.link.result is None else self.link.result.as_dict(),
        }


def run_on_bytes(rover: RoverConfig, data: bytes, baudrate: int | None = None,
                 ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The pipeline on ``data`` (NMEA bytes), in-process (no pty, no output): its records as
    ``epochs.jsonl`` has them, and its summary (``link``: the receiver's rate and sentences
    against ``baudrate``, default the port's). ``calibrate`` and the evaluation read drives
    with it."""
    buf = io.StringIO()
    pipe = RoverPipeline(rover, jsonl=buf, baudrate=baudrate)
    pipe.feed(data)
    pipe.finish()
    return [json.loads(line) for line in buf.getvalue().splitlines()], pipe.summary()


def _sink_stats(sink: EpochSink) -> dict[str, Any]:
    stats = getattr(sink, "stats", None)
    return dict(stats()) if callable(stats) else {}
