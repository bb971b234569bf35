"""Scenario generator for the farm rover: a field path, DGPS error, injected faults, truth.

``fdi-bridge sim rover --rate 10 --duration 600 --seed 1 --out DIR`` writes

* ``DIR/rover.nmea``: the receiver's NMEA stream (GGA, RMC, VTG per epoch; GST and ZDA with
  ``--gst`` / ``--zda``), a plain log with ``#`` header comments, as an AgGPS 132 would send it;
* ``DIR/rover.cap``: the same bytes in the project's capture format, timestamped at the epochs,
  its header's baud rate the smallest standard one from 9600 up that carries the sentences at
  the rate (10 Hz GGA+RMC+VTG: 38400; 5 Hz: 19200; 1 Hz: 9600), as the receiver would have to
  be set;
* ``DIR/truth.jsonl``: per epoch the true position, the DGPS error and the injected fault;
* ``DIR/scenario.json``: the parameters.

The model (all seeded from ``--seed``):

* path: straight passes (``pass_length_m`` at ``speed_mps``) joined by semicircular headland
  turns (radius ``turn_radius_m`` at ``turn_speed_mps``), speed changes ramped over 2 s;
* DGPS error: a first-order Gauss-Markov process per axis (σ 0.35 m horizontal, 0.7 m
  vertical, correlation time 60 s, so a few centimetres from one epoch to the next) plus 5 mm
  white noise; Doppler velocity with 0.03 m/s noise per axis;
* faults: single-epoch jumps and bursts of 2-5 epochs, of 3σ to 20σ (σ = 0.35 m), horizontal,
  in a random direction, events at least ``min_gap_s`` apart; other kinds (ramp, frozen
  position, outage) are available for the evaluation suite.

``--error-model`` picks the receiver model (issue 13: a detector must hold on data it was not
tuned on). ``gm`` is the model above and the default (the replay contract and the existing
tests are measured on it, byte for byte). The others are an independent generator
(:func:`generate_field`), each with its parameters drawn per seed from the ranges below:

* ``dgps``: a tractor on a boustrophedon at 1-3 m/s (a new speed per pass, headland turns at
  0.8-1.5 m/s, stops of 5-30 s every 1-3 minutes); DGPS error as the sum of a short
  Gauss-Markov process (σ 0.05-0.12 m, τ 3-15 s) and a long one (σ 0.25-0.40 m, τ 120-600 s)
  per horizontal axis plus white noise (0.01-0.03 m); Doppler that lags the position by
  0.05-0.3 s, with 0.02-0.06 m/s noise; coordinates quantised as the AgGPS sends them
  (5 decimals of minutes, about 1.8 cm), speed to 0.01 knot, course to 0.1°;
* ``multipath``: ``dgps`` plus multipath steps (0.5-2 m, persisting 5-30 s, abrupt on and
  off), marked in the truth as fault events of kind ``multipath`` (a receiver fault);
* ``coarse``: a worse receiver: short process σ 0.10-0.20 m, τ 10-30 s, white 0.03-0.05 m,
  Doppler lag 0.1-0.4 s and noise 0.05-0.1 m/s, coordinates to 4 decimals of minutes
  (about 0.18 m) and speed to 0.1 knot.

Fault kinds beyond jumps and bursts: ``ramp`` (a slow drift; in the field models at a rate
drawn from 0.02-0.3 m/s, for 30-60 s, then back to the truth at once), ``frozen`` (in the field
models the receiver repeats its whole last fix, speed and course too, for 5-20 s, at whatever
speed the tractor has, stops included), ``multipath`` and ``outage``.
"""

from __future__ import annotations

import argparse
import calendar
import json
import math
import sys
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from drivers.capture import CaptureWriter, Channel
from drivers.gps.link import STANDARD_BAUDS, smallest_baud
from drivers.gps.nmea import (
    KNOT_MPS,
    format_date,
    format_lat,
    format_lon,
    format_time,
    with_checksum,
)
from fdi.errors import UsageError
from fdi.geodesy import LocalFrame
from firmware_host.commands.checks import output_dir_arg, positive_float
from firmware_host.commands.tables import fields, summary_rows

FaultKind = Literal["jump", "burst", "ramp", "frozen", "outage", "multipath"]
FAULT_KINDS: tuple[str, ...] = ("jump", "burst", "ramp", "frozen", "outage", "multipath")
ErrorModel = Literal["gm", "dgps", "multipath", "coarse"]
ERROR_MODELS: tuple[str, ...] = ("gm", "dgps", "multipath", "coarse")


@dataclass(frozen=True)
class RoverScenario:
    rate_hz: float = 10.0
    duration_s: float = 600.0
    seed: int = 1
    origin_lat_deg: float = 32.0206  # Nanjing Agricultural University farm, roughly
    origin_lon_deg: float = 118.8580
    origin_alt_m: float = 12.0
    geoid_sep_m: float = 3.0
    speed_mps: float = 2.0
    turn_speed_mps: float = 1.0
    pass_length_m: float = 100.0
    turn_radius_m: float = 6.0
    sigma_h_m: float = 0.35
    sigma_v_m: float = 0.7
    tau_s: float = 60.0
    white_m: float = 0.005
    vel_noise_mps: float = 0.03
    fault_sigma_m: float = 0.35
    fault_min_sigmas: float = 3.0
    fault_max_sigmas: float = 20.0
    fault_every_s: float = 15.0
    min_gap_s: float = 6.0
    burst_fraction: float = 0.4
    kinds: tuple[str, ...] = ("jump", "burst")
    ramp_rate_mps: float = 0.1
    ramp_duration_s: float = 30.0
    outage_s: float = 20.0
    frozen_s: float = 10.0
    gst: bool = False
    zda: bool = False
    start_utc_s: float = 10 * 3600.0
    # A date ArduPilot accepts: AP_GPS refuses GPS times before 2022-01-01 (SYSTEM_TIME stays
    # 0 on a date of 2010). Fixed, so that a seed gives the same bytes on any day.
    date: tuple[int, int, int] = (2025, 5, 12)
    error_model: str = "gm"  # one of ERROR_MODELS; "gm" is the model of the module docstring
    # The field models' receiver and tractor are drawn from this seed (None: ``seed``): the
    # same receiver on another day is another ``seed`` with the same ``receiver_seed``.
    receiver_seed: int | None = None


@dataclass
class _Path:
    """Arclength -> position/heading for passes and headland turns."""

    length: float
    radius: float
    segs: list[tuple[str, float, float, float, float, float]] = field(default_factory=list)

    def pose(self, s: float) -> tuple[float, float, float, bool]:
        """(east, north, heading_rad from north, in_turn) at arclength s (periodic pattern)."""
        L, R = self.length, self.radius
        turn = math.pi * R
        cycle = 2 * (L + turn)
        k, rem = divmod(s, cycle)
        x0 = k * 4 * R  # every cycle moves two rows (2 × 2R) east
        if rem < L:  # northward pass
            return x0, rem, 0.0, False
        rem -= L
        if rem < turn:  # turn right (east) at the north headland
            a = rem / R
            return x0 + R - R * math.cos(a), L + R * math.sin(a), a, True
        rem -= turn
        if rem < L:  # southward pass
            return x0 + 2 * R, L - rem, math.pi, False
        rem -= L
        a = rem / R  # turn left (east) at the south headland
        return x0 + 3 * R - R * math.cos(a), -R * math.sin(a), math.pi - a, True


def _speed_at(path: _Path, s: float, sc: RoverScenario) -> float:
    """Target speed with 2 s ramps around the turns (evaluated on the arclength)."""
    ramp = 2.0 * 0.5 * (sc.speed_mps + sc.turn_speed_mps)
    best = sc.speed_mps
    for ds in (-ramp, 0.0, ramp):
        _, _, _, turning = path.pose(s + ds)
        if turning:
            mid = 0.5 * (sc.speed_mps + sc.turn_speed_mps)
            best = min(best, sc.turn_speed_mps if ds == 0.0 else mid)
    return best


@dataclass(frozen=True)
class FaultEvent:
    kind: str
    start: int  # epoch index
    length: int  # epochs
    offset_e_m: float
    offset_n_m: float
    sigmas: float
    rate_mps: float = 0.0  # ramps of the field models: the drift rate


def plan_faults(sc: RoverScenario, n_epochs: int, rng: np.random.Generator) -> list[FaultEvent]:
    """Fault events spread over the run, at least ``min_gap_s`` apart, after a 20 s start."""
    if not sc.kinds:  # a clean run
        return []
    dt = 1.0 / sc.rate_hz
    events: list[FaultEvent] = []
    t = 20.0
    while True:
        t += float(rng.uniform(sc.min_gap_s, 2 * sc.fault_every_s - sc.min_gap_s))
        start = round(t * sc.rate_hz)
        if start >= n_epochs - int(sc.min_gap_s * sc.rate_hz):
            break
        kind = str(rng.choice(list(sc.kinds)))
        sig = float(rng.uniform(sc.fault_min_sigmas, sc.fault_max_sigmas))
        mag = sig * sc.fault_sigma_m
        ang = float(rng.uniform(0, 2 * math.pi))
        if kind == "burst":
            length = int(rng.integers(2, 6))
        elif kind == "ramp":
            length = round(sc.ramp_duration_s * sc.rate_hz)
            mag = sc.ramp_rate_mps  # per second; offset grows
        elif kind == "outage":
            length = round(sc.outage_s * sc.rate_hz)
        elif kind == "frozen":
            length = round(sc.frozen_s * sc.rate_hz)
        else:
            length = 1
        events.append(
            FaultEvent(kind, start, length, mag * math.sin(ang), mag * math.cos(ang), sig)
        )
        t = (start + length) * dt
    return events


def generate(sc: RoverScenario) -> Iterator[tuple[float, bytes, dict[str, object]]]:
    """Yield ``(time_s, nmea_bytes, truth_record)`` per epoch."""
    if sc.error_model != "gm":
        yield from generate_field(sc)
        return
    rng = np.random.default_rng(sc.seed)
    dt = 1.0 / sc.rate_hz
    n = round(sc.duration_s * sc.rate_hz)
    path = _Path(sc.pass_length_m, sc.turn_radius_m)
    frame = LocalFrame(sc.origin_lat_deg, sc.origin_lon_deg, sc.origin_alt_m)
    faults = plan_faults(sc, n, rng)
    fault_at: dict[int, FaultEvent] = {}
    for event in faults:
        for i in range(event.start, event.start + event.length):
            fault_at[i] = event
    phi = math.exp(-dt / sc.tau_s)
    q_h = sc.sigma_h_m * math.sqrt(1 - phi * phi)
    q_v = sc.sigma_v_m * math.sqrt(1 - phi * phi)
    err = [
        float(rng.normal(0, sc.sigma_h_m)),
        float(rng.normal(0, sc.sigma_h_m)),
        float(rng.normal(0, sc.sigma_v_m)),
    ]
    s = 0.0
    v = sc.speed_mps
    sub = 10
    hdop = 0.9
    sats = 9
    frozen_fix: tuple[float, float, float] | None = None
    for k in range(n):
        t = sc.start_utc_s + k * dt
        e_true, n_true, heading, _ = path.pose(s)
        u_true = 0.0
        ve, vn = v * math.sin(heading), v * math.cos(heading)
        ev = fault_at.get(k)
        off = (0.0, 0.0)
        fault = False
        outage = False
        if ev is not None:
            fault = True
            if ev.kind == "ramp":
                grow = (k - ev.start + 1) * dt
                off = (ev.offset_e_m * grow, ev.offset_n_m * grow)
            elif ev.kind == "outage":
                outage = True
            elif ev.kind != "frozen":
                off = (ev.offset_e_m, ev.offset_n_m)
        we, wn, wu = (float(x) for x in rng.normal(0, sc.white_m, 3))
        fix = (
            e_true + err[0] + we + off[0],
            n_true + err[1] + wn + off[1],
            u_true + err[2] + wu,
        )
        if ev is not None and ev.kind == "frozen":
            if frozen_fix is None:
                frozen_fix = fix
            fix = frozen_fix
        else:
            frozen_fix = None
        vne = ve + float(rng.normal(0, sc.vel_noise_mps))
        vnn = vn + float(rng.normal(0, sc.vel_noise_mps))
        lat, lon, h = frame.to_lla(*fix)
        tlat, tlon, th = frame.to_lla(e_true, n_true, u_true)
        hdop = min(1.6, max(0.7, hdop + float(rng.normal(0, 0.01))))
        if rng.random() < 0.002:
            sats = int(np.clip(sats + rng.integers(-1, 2), 7, 11))
        age = 1.0 + (k * dt) % 5.0
        data = _nmea_epoch(sc, t, None if outage else (lat, lon, h), vne, vnn, hdop, sats, age)
        truth: dict[str, object] = {
            "k": k,
            "utc": round(t % 86400.0, 6),
            "true_lat": tlat,
            "true_lon": tlon,
            "true_alt": th,
            "true_e": e_true,
            "true_n": n_true,
            "true_u": u_true,
            "err_e": err[0] + we,
            "err_n": err[1] + wn,
            "err_u": err[2] + wu,
            "fault": fault,
            "fault_kind": ev.kind if ev else None,
            "fault_event": faults.index(ev) if ev else None,
            "fault_offset_m": math.hypot(*off) if ev else 0.0,
            "fault_sigmas": ev.sigmas if ev else 0.0,
            "outage": outage,
        }
        yield t, data, truth
        # Advance truth and error to the next epoch.
        for _ in range(sub):
            target = _speed_at(path, s, sc)
            acc = max(-0.5, min(0.5, (target - v) / 0.5))
            v += acc * dt / sub
            s += v * dt / sub
        err[0] = phi * err[0] + float(rng.normal(0, q_h))
        err[1] = phi * err[1] + float(rng.normal(0, q_h))
        err[2] = phi * err[2] + float(rng.normal(0, q_v))


# --------------------------------------------------------------------------- field models


@dataclass(frozen=True)
class FieldModel:
    """One receiver of the field models, drawn per seed (see the module docstring)."""

    gm_h: tuple[tuple[float, float], ...]  # (σ m, τ s) of each horizontal process, per axis
    gm_v: tuple[float, float]  # (σ m, τ s) vertical
    white_m: float
    lag_s: float  # Doppler lags the position by this much
    vel_noise_mps: float
    minute_decimals: int  # coordinates: decimals of minutes
    speed_decimals: int  # speed: decimals of knots
    pass_speeds_mps: tuple[float, ...]  # one per pass, cycled
    turn_speed_mps: float


def draw_field_model(model: str, seed: int) -> FieldModel:
    """The receiver and tractor of error model ``model`` for ``seed`` (its own RNG stream)."""
    if model not in ERROR_MODELS or model == "gm":
        raise ValueError(f"not a field error model: {model!r}")
    rng = np.random.default_rng([seed, ERROR_MODELS.index(model), 13])
    u = rng.uniform
    coarse = model == "coarse"
    short = (float(u(0.10, 0.20)), float(u(10.0, 30.0))) if coarse else (
        float(u(0.05, 0.12)), float(u(3.0, 15.0)))
    long_ = (float(u(0.25, 0.40)), float(u(120.0, 600.0)))
    return FieldModel(
        gm_h=(short, long_),
        gm_v=(float(u(0.5, 0.8)), float(u(120.0, 600.0))),
        white_m=float(u(0.03, 0.05)) if coarse else float(u(0.01, 0.03)),
        lag_s=float(u(0.1, 0.4)) if coarse else float(u(0.05, 0.3)),
        vel_noise_mps=float(u(0.05, 0.1)) if coarse else float(u(0.02, 0.06)),
        minute_decimals=4 if coarse else 5,
        speed_decimals=1 if coarse else 2,
        pass_speeds_mps=tuple(float(x) for x in u(1.0, 3.0, 64)),
        turn_speed_mps=float(u(0.8, 1.5)),
    )


def plan_field_faults(sc: RoverScenario, n_epochs: int, rng: np.random.Generator
                      ) -> list[FaultEvent]:
    """Fault events of the field models: kinds drawn from ``sc.kinds`` (plus ``multipath`` for
    that model), magnitudes and durations from the ranges of the module docstring."""
    kinds = list(sc.kinds)
    if sc.error_model == "multipath" and "multipath" not in kinds:
        kinds.append("multipath")
    if not kinds:  # a clean run
        return []
    dt = 1.0 / sc.rate_hz
    events: list[FaultEvent] = []
    t = 30.0
    while True:
        t += float(rng.uniform(sc.min_gap_s, max(sc.min_gap_s, 2 * sc.fault_every_s
                                                  - sc.min_gap_s)))
        start = round(t * sc.rate_hz)
        kind = str(rng.choice(kinds))
        sig = float(rng.uniform(sc.fault_min_sigmas, sc.fault_max_sigmas))
        ang = float(rng.uniform(0, 2 * math.pi))
        mag = sig * sc.fault_sigma_m
        rate = 0.0
        if kind == "burst":
            length = int(rng.integers(2, 6))
        elif kind == "ramp":
            rate = float(rng.uniform(0.02, 0.3))
            mag = rate
            length = round(float(rng.uniform(30.0, 60.0)) * sc.rate_hz)
        elif kind == "frozen":
            length = round(float(rng.uniform(5.0, 20.0)) * sc.rate_hz)
        elif kind == "multipath":
            mag = float(rng.uniform(0.5, 2.0))
            sig = mag / sc.fault_sigma_m
            length = round(float(rng.uniform(5.0, 30.0)) * sc.rate_hz)
        elif kind == "outage":
            length = round(sc.outage_s * sc.rate_hz)
        else:
            length = 1
        if start + length >= n_epochs - int(sc.min_gap_s * sc.rate_hz):
            break
        events.append(FaultEvent(kind, start, length, mag * math.sin(ang), mag * math.cos(ang),
                                 sig, rate))
        t = (start + length) * dt
    return events


def _quantise_deg(x: float, decimals: int) -> float:
    """Degrees rounded as a receiver writes them: ``decimals`` decimals of minutes."""
    a = abs(x)
    d = math.floor(a)
    m = round((a - d) * 60.0, decimals)
    return math.copysign(d + m / 60.0, x)


class ReceiverError:
    """A field model's error processes, first-order Gauss-Markov: each horizontal one
    (phi, q, state e, state n), summed, and the vertical one; drawn from ``rng`` in one order
    (the generators' streams depend on it)."""

    def __init__(self, fm: FieldModel, dt: float, rng: np.random.Generator) -> None:
        self.procs: list[list[float]] = []
        for sig, tau in fm.gm_h:
            phi = math.exp(-dt / tau)
            self.procs.append([phi, sig * math.sqrt(1 - phi * phi), float(rng.normal(0, sig)),
                               float(rng.normal(0, sig))])
        sv, tv = fm.gm_v
        self.phi_v = math.exp(-dt / tv)
        self.q_v = sv * math.sqrt(1 - self.phi_v * self.phi_v)
        self.u = float(rng.normal(0, sv))

    @property
    def e(self) -> float:
        return sum(p[2] for p in self.procs)

    @property
    def n(self) -> float:
        return sum(p[3] for p in self.procs)

    def step(self, rng: np.random.Generator) -> None:
        """One epoch on."""
        for p in self.procs:
            p[2] = p[0] * p[2] + float(rng.normal(0, p[1]))
            p[3] = p[0] * p[3] + float(rng.normal(0, p[1]))
        self.u = self.phi_v * self.u + float(rng.normal(0, self.q_v))


def generate_field(sc: RoverScenario) -> Iterator[tuple[float, bytes, dict[str, object]]]:
    """The field models' generator: ``(time_s, nmea_bytes, truth_record)`` per epoch."""
    fm = draw_field_model(sc.error_model, sc.seed if sc.receiver_seed is None
                          else sc.receiver_seed)
    rng = np.random.default_rng([sc.seed, ERROR_MODELS.index(sc.error_model), 1])
    dt = 1.0 / sc.rate_hz
    n = round(sc.duration_s * sc.rate_hz)
    path = _Path(sc.pass_length_m, sc.turn_radius_m)
    half = sc.pass_length_m + math.pi * sc.turn_radius_m
    frame = LocalFrame(sc.origin_lat_deg, sc.origin_lon_deg, sc.origin_alt_m)
    faults = plan_field_faults(sc, n, rng)
    fault_at: dict[int, FaultEvent] = {}
    for event in faults:
        for i in range(event.start, event.start + event.length):
            fault_at[i] = event
    # Stops: every 60-180 s, 5-30 s long.
    stops: list[tuple[float, float]] = []
    ts = 0.0
    while ts < sc.duration_s:
        ts += float(rng.uniform(60.0, 180.0))
        stops.append((ts, ts + float(rng.uniform(5.0, 30.0))))
    err = ReceiverError(fm, dt, rng)
    s = 0.0
    v = 0.0
    sub = 10
    hist: list[tuple[float, float, float]] = []  # (t, ve, vn) true velocity, sub-steps
    hdop, sats = 0.9, 9
    frozen: tuple[float, float, float, float, float, float, int, float] | None = None
    for k in range(n):
        t_rel = k * dt
        t = sc.start_utc_s + t_rel
        e_true, n_true, heading, _ = path.pose(s)
        ve, vn = v * math.sin(heading), v * math.cos(heading)
        hist.append((t_rel, ve, vn))
        # The Doppler the receiver reports: the true velocity lag_s ago, plus noise.
        t_lag = t_rel - fm.lag_s
        while len(hist) > 2 and hist[1][0] <= t_lag:
            hist.pop(0)
        if t_lag <= hist[0][0] or len(hist) == 1:
            lve, lvn = hist[0][1], hist[0][2]
        else:
            (t0, e0, n0), (t1, e1, n1) = hist[0], hist[1]
            w = (t_lag - t0) / (t1 - t0)
            lve, lvn = e0 + w * (e1 - e0), n0 + w * (n1 - n0)
        vne = lve + float(rng.normal(0, fm.vel_noise_mps))
        vnn = lvn + float(rng.normal(0, fm.vel_noise_mps))
        err_e, err_n, err_u = err.e, err.n, err.u
        we, wn, wu = (float(x) for x in rng.normal(0, fm.white_m, 3))
        ev = fault_at.get(k)
        off = (0.0, 0.0)
        outage = False
        if ev is not None:
            if ev.kind == "ramp":
                grow = (k - ev.start + 1) * dt
                off = (ev.offset_e_m * grow, ev.offset_n_m * grow)
            elif ev.kind == "outage":
                outage = True
            elif ev.kind != "frozen":
                off = (ev.offset_e_m, ev.offset_n_m)
        fe = e_true + err_e + we + off[0]
        fn = n_true + err_n + wn + off[1]
        fu = err_u + wu
        lat, lon, h = frame.to_lla(fe, fn, fu)
        lat = _quantise_deg(lat, fm.minute_decimals)
        lon = _quantise_deg(lon, fm.minute_decimals)
        h = round(h, 3)
        hdop = min(1.6, max(0.7, hdop + float(rng.normal(0, 0.01))))
        if rng.random() < 0.002:
            sats = int(np.clip(sats + rng.integers(-1, 2), 7, 11))
        age = 1.0 + (k * dt) % 5.0
        frozen_off = 0.0
        if ev is not None and ev.kind == "frozen":
            if frozen is None:
                frozen = (lat, lon, h, vne, vnn, hdop, sats, age)
            lat, lon, h, vne, vnn, hdop_f, sats_f, age_f = frozen
            fe_f, fn_f, _ = frame.to_enu(lat, lon, h)
            frozen_off = math.hypot(fe_f - (e_true + err_e + we), fn_f - (n_true + err_n + wn))
            data = _nmea_epoch(sc, t, (lat, lon, h), vne, vnn, hdop_f, sats_f, age_f,
                               fm.speed_decimals)
        else:
            frozen = None
            data = _nmea_epoch(sc, t, None if outage else (lat, lon, h), vne, vnn, hdop, sats,
                               age, fm.speed_decimals)
        tlat, tlon, th = frame.to_lla(e_true, n_true, 0.0)
        truth: dict[str, object] = {
            "k": k,
            "utc": round(t % 86400.0, 6),
            "true_lat": tlat,
            "true_lon": tlon,
            "true_alt": th,
            "true_e": e_true,
            "true_n": n_true,
            "true_u": 0.0,
            "err_e": err_e + we,
            "err_n": err_n + wn,
            "err_u": err_u + wu,
            "fault": ev is not None,
            "fault_kind": ev.kind if ev else None,
            "fault_event": faults.index(ev) if ev else None,
            "fault_offset_m": frozen_off if ev is not None and ev.kind == "frozen" else (
                math.hypot(*off) if ev else 0.0),
            "fault_sigmas": ev.sigmas if ev else 0.0,
            "fault_rate_mps": ev.rate_mps if ev else 0.0,
            "outage": outage,
            "speed_true": v,
        }
        yield t, data, truth
        # Advance the tractor: the pass's speed, slower in turns (2 s ahead), stops.
        idx = int(s // half)
        for _ in range(sub):
            t_now = t_rel
            stopped = any(a <= t_now < b for a, b in stops)
            if stopped:
                target = 0.0
            else:
                target = fm.pass_speeds_mps[idx % len(fm.pass_speeds_mps)]
                for ds in (0.0, 2.0 * v):
                    if path.pose(s + ds)[3]:
                        target = min(target, fm.turn_speed_mps)
            acc = max(-0.5, min(0.5, (target - v) / 0.5))
            v = max(0.0, v + acc * dt / sub)
            s += v * dt / sub
            t_rel += dt / sub
            _, _, hd, _ = path.pose(s)
            hist.append((t_rel, v * math.sin(hd), v * math.cos(hd)))
        err.step(rng)


def _nmea_epoch(
    sc: RoverScenario,
    t: float,
    fix: tuple[float, float, float] | None,
    ve: float,
    vn: float,
    hdop: float,
    sats: int,
    age: float,
    speed_decimals: int = 3,
) -> bytes:
    ts = format_time(t)
    date = format_date(sc.date)
    if fix is None:
        gga = f"GPGGA,{ts},,,,,0,{sats:02d},,,M,,M,,"
        rmc = f"GPRMC,{ts},V,,,,,,,{date},,,N"
        out = with_checksum(gga) + with_checksum(rmc) + with_checksum("GPVTG,,T,,M,,N,,K,N")
        return out
    lat, lon, h = fix
    la, ns = format_lat(lat)
    lo, ew = format_lon(lon)
    speed = math.hypot(ve, vn)
    course = math.degrees(math.atan2(ve, vn)) % 360.0
    msl = h - sc.geoid_sep_m
    gga = (
        f"GPGGA,{ts},{la},{ns},{lo},{ew},2,{sats:02d},{hdop:.1f},{msl:.3f},M,"
        f"{sc.geoid_sep_m:.3f},M,{age:.1f},0133"
    )
    kn = speed / KNOT_MPS
    if speed_decimals < 3:  # a receiver that sends fewer digits (the field models)
        kn = round(kn, speed_decimals)
        speed = kn * KNOT_MPS
        course = round(course, 1)
    rmc = f"GPRMC,{ts},A,{la},{ns},{lo},{ew},{kn:.3f},{course:.1f},{date},,,D"
    vtg = f"GPVTG,{course:.1f},T,,M,{kn:.3f},N,{speed * 3.6:.3f},K,D"
    out = with_checksum(gga)
    if sc.gst:
        sd = sc.sigma_h_m
        out += with_checksum(
            f"GPGST,{ts},{sd:.2f},{sd:.2f},{sd:.2f},0.0,{sd:.2f},{sd:.2f},{sc.sigma_v_m:.2f}"
        )
    out += with_checksum(rmc) + with_checksum(vtg)
    if sc.zda:
        y, m, d = sc.date
        out += with_checksum(f"GPZDA,{ts},{d:02d},{m:02d},{y:04d},00,00")
    return out


def write_run(sc: RoverScenario, out_dir: Path) -> dict[str, object]:
    """Write rover.nmea, rover.cap, truth.jsonl and scenario.json; return a short summary."""

    baud = link_baudrate(sc)
    out_dir.mkdir(parents=True, exist_ok=True)
    n_epochs = n_fault = 0
    header = (
        "# fdi-bridge generated rover run (Trimble AgGPS 132 style NMEA, DGPS)\n"
        f"# rate_hz: {sc.rate_hz}  duration_s: {sc.duration_s}  seed: {sc.seed}  "
        f"baud: {baud}\n"
        "# faults: see truth.jsonl; parameters: scenario.json\n"
    )
    channel = Channel(name="gps", url="/dev/ttyUSB0", baudrate=baud, direction="rx")
    t0_us = calendar.timegm((*sc.date, 0, 0, 0)) * 1_000_000
    with (
        open(out_dir / "rover.nmea", "wb") as nmea,
        open(out_dir / "truth.jsonl", "w", encoding="utf-8") as truth_f,
        CaptureWriter(out_dir / "rover.cap", [channel], note="generated rover run") as cap,
    ):
        nmea.write(header.encode("ascii"))
        for t, data, truth in generate(sc):
            nmea.write(data)
            cap.write(0, data, t_us=round((t - sc.start_utc_s) * 1e6) + t0_us)
            truth_f.write(json.dumps(truth) + "\n")
            n_epochs += 1
            n_fault += bool(truth["fault"])
    params = asdict(sc)
    (out_dir / "scenario.json").write_text(json.dumps(params, indent=2) + "\n", encoding="utf-8")
    return {"epochs": n_epochs, "faulty_epochs": n_fault, "baud": baud, "out": str(out_dir)}


SIM_MIN_BAUD = 9600  # the AgGPS 132's default; a slower line is never chosen for a run
SIZE_MARGIN = 1.1  # epochs differ by a few bytes (signs, digits, a no-fix epoch): 10 % spare


def link_baudrate(sc: RoverScenario) -> int:
    """The baud rate the run's capture says: the smallest standard rate from 9600 up that
    carries its sentences at its rate (the first epoch's bytes + 10 %; drivers/gps/link.py).
    Raises UsageError when none does (not even 115200)."""
    first = next(generate(sc))[1]
    need = len(first) * SIZE_MARGIN
    baud = smallest_baud(need, sc.rate_hz)
    if baud is not None and baud < SIM_MIN_BAUD:
        baud = SIM_MIN_BAUD
    if baud is None:
        raise UsageError(f"--rate {sc.rate_hz:g}: {len(first)} bytes an epoch at {sc.rate_hz:g}"
                         f" Hz do not fit even {STANDARD_BAUDS[-1]} baud")
    return baud


# --------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rate", type=float, default=10.0, choices=[1.0, 5.0, 10.0],
                        help="receiver rate in Hz (1, 5 or 10)")
    parser.add_argument("--duration", type=positive_float, default=600.0,
                        help="seconds of driving")
    parser.add_argument("--seed", type=int, default=1, help="random seed (faults and noise)")
    parser.add_argument("--gst", action="store_true", help="also send GST error estimates")
    parser.add_argument("--zda", action="store_true", help="also send ZDA")
    parser.add_argument("--kinds", default="jump,burst",
                        help="fault kinds, comma separated: " + ",".join(FAULT_KINDS))
    parser.add_argument("--error-model", default="gm", choices=list(ERROR_MODELS),
                        help="receiver error model (see the module docstring)")
    parser.add_argument("--out", required=True, type=output_dir_arg,
                        help="output directory (rover.nmea, rover.cap, truth.jsonl, ...)")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")


def run(args: argparse.Namespace) -> int:
    kinds = tuple(k.strip() for k in args.kinds.split(",") if k.strip())
    bad = [k for k in kinds if k not in FAULT_KINDS]
    if "multipath" in kinds and args.error_model == "gm":
        bad.append("multipath (a field error model only)")
    if bad:
        raise UsageError(f"--kinds: unknown fault kind(s): {', '.join(bad)} (known: jump, "
                         "burst, ramp, frozen, outage)")
    if args.duration * args.rate < 1:
        raise UsageError(f"--duration {args.duration:g}: shorter than one epoch at "
                         f"{args.rate:g} Hz")
    sc = RoverScenario(rate_hz=args.rate, duration_s=args.duration, seed=args.seed,
                       gst=args.gst, zda=args.zda, kinds=kinds, error_model=args.error_model)
    try:
        summary = write_run(sc, args.out)
    except KeyboardInterrupt:  # the files are cut where ^C came: say so, not a plain stop
        print(f"fdi-bridge sim rover: interrupted; the files in {args.out} are partial "
              f"(cut before {args.duration:g} s)", file=sys.stderr)
        return 130
    if args.json:
        print(json.dumps(summary))
    else:
        print(fields(summary_rows(summary)))
    return 0
