"""A frozen receiver on a curved path (issue 42): how far the output goes from the truth.

``fdi-bridge sim rover-frozen [--config rover] [--seeds 1-5] [--rates 1,5,10]
[--models dgps,coarse] [--duration 900] [--json OUT]`` drives a tractor on a path of arcs
and straights at 1-2 m/s (:func:`generate_curves`), with a receiver of the field models of
:mod:`firmware_host.devtools.rover_sim` (``dgps`` or ``coarse``: error processes, Doppler lag
and noise, quantisation, drawn per seed) that freezes every 25-50 s for 5-20 s: it repeats its
whole last fix, position, speed and course (HDOP, satellites and age too). Most of the path
is in turns, so most freezes see the vehicle turn, enter a turn or leave one, and some a
stop. The run is replayed through the rover pipeline and, per frozen event, scored against
the issue's bullet:

* ``e0``: the receiver's distance to the truth when it froze (its event's first epoch, the
  live fix it then repeats);
* the worst *excess* over the event's epochs with an output: the output's distance to the
  truth minus ``e0`` (the bullet: at most 1 m), and the epochs with an output more than 1 m
  in excess (the bullet: none; past the coasting limit, no output rather than a worse one);
* for comparison the raw receiver's worst excess (doing nothing), the epochs with no output
  and the last output's time after the freeze;
* the 10 s after the event (the rover harness's measure): the output's RMS against the raw
  receiver's.

The WORST seed of each number is reported. The path, the receiver, the stops and the
freezes are drawn from ``--seed`` only (their own streams). ``--harness`` scores the frozen
events of ``sim rover-harness``'s runs the same way (straight passes and 6 m headland turns;
its ``gm`` model freezes the position only, its field models the whole fix).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fdi.errors import UsageError
from fdi.geodesy import LocalFrame
from firmware_host.commands import tables
from firmware_host.commands.checks import (
    choice_list,
    output_file_arg,
    positive_float,
    positive_float_list,
    seed_list,
)
from firmware_host.devtools.progress import Progress
from firmware_host.devtools.rover_harness import AFTER_S, _clean, measure, replay_stream
from firmware_host.devtools.rover_harness import scenario as harness_scenario
from firmware_host.devtools.rover_sim import (
    ERROR_MODELS,
    ReceiverError,
    RoverScenario,
    _nmea_epoch,
    _quantise_deg,
    draw_field_model,
    generate,
)
from firmware_host.runtime.config import BridgeConfig, load_config

MODELS: tuple[str, ...] = ("dgps", "coarse")
RATES: tuple[float, ...] = (1.0, 5.0, 10.0)
EXCESS_M = 1.0  # the bullet: no output more than this further from the truth than e0
# The RNG streams of a run (seed, stream): the path, the receiver's noise, the freezes, the
# stops (each its own, so that a longer run is the same run, longer).
_PATH, _NOISE, _FREEZE, _STOPS = 71, 72, 73, 74


@dataclass(frozen=True)
class CurveScenario:
    """A curved drive with a frozen receiver (units: m, s, m/s)."""

    rate_hz: float = 10.0
    duration_s: float = 900.0
    seed: int = 1
    model: str = "dgps"  # the receiver: a field model of rover_sim (dgps, coarse)
    speed_min_mps: float = 1.0
    speed_max_mps: float = 2.0
    lat_acc_max_mps2: float = 0.5  # the tightest turn at speed v: radius >= v² / this
    radius_min_m: float = 5.0
    radius_max_m: float = 30.0
    turn_fraction: float = 0.7  # of the path's segments, arcs (the rest straights)
    curvature_rate: float = 0.1  # 1/m per second: the steering's rate (a turn's entry)
    accel_mps2: float = 0.5  # speed changes (and stops) at most this
    frozen_min_s: float = 5.0
    frozen_max_s: float = 20.0
    gap_min_s: float = 25.0  # between freezes (end to start)
    gap_max_s: float = 50.0


@dataclass
class _Segment:
    curvature: float  # 1/m, signed (positive: to the right)
    length_m: float
    speed_mps: float


def _segments(sc: CurveScenario, rng: np.random.Generator) -> Iterator[_Segment]:
    """The path's segments, for ever: arcs (radius within the lateral acceleration at their
    speed, 45-200 degrees, either way) and straights (5-40 m)."""
    while True:
        v = float(rng.uniform(sc.speed_min_mps, sc.speed_max_mps))
        if rng.random() < sc.turn_fraction:
            r_min = max(sc.radius_min_m, v * v / sc.lat_acc_max_mps2)
            radius = float(rng.uniform(r_min, max(r_min, sc.radius_max_m)))
            angle = math.radians(float(rng.uniform(45.0, 200.0)))
            sign = 1.0 if rng.random() < 0.5 else -1.0
            yield _Segment(sign / radius, radius * angle, v)
        else:
            yield _Segment(0.0, float(rng.uniform(5.0, 40.0)), v)


@dataclass
class _Tractor:
    """The true state on the path: position, heading (rad from north), speed, curvature."""

    e: float = 0.0
    n: float = 0.0
    psi: float = 0.0
    v: float = 0.0
    kappa: float = 0.0
    s_seg: float = 0.0  # arclength into the current segment
    hist: list[tuple[float, float, float]] = field(default_factory=list)  # (t, ve, vn)

    def advance(self, seg: _Segment, stopped: bool, dt: float, sc: CurveScenario) -> None:
        target = 0.0 if stopped else seg.speed_mps
        acc = max(-sc.accel_mps2, min(sc.accel_mps2, (target - self.v) / 0.5))
        self.v = max(0.0, self.v + acc * dt)
        dk = seg.curvature - self.kappa
        step = sc.curvature_rate * dt
        self.kappa += max(-step, min(step, dk))
        ds = self.v * dt
        self.psi += self.kappa * ds
        self.e += ds * math.sin(self.psi)
        self.n += ds * math.cos(self.psi)
        self.s_seg += ds


def _stops(duration_s: float, rng: np.random.Generator) -> list[tuple[float, float]]:
    """Stops every 60-180 s, 5-20 s long."""
    out: list[tuple[float, float]] = []
    t = 0.0
    while t < duration_s:
        t += float(rng.uniform(60.0, 180.0))
        out.append((t, t + float(rng.uniform(5.0, 20.0))))
    return out


def _freezes(sc: CurveScenario, n: int, rng: np.random.Generator) -> list[tuple[int, int]]:
    """(first epoch, epochs) of each freeze, from 30 s on, 25-50 s apart."""
    out: list[tuple[int, int]] = []
    t = 30.0
    while True:
        length = round(float(rng.uniform(sc.frozen_min_s, sc.frozen_max_s)) * sc.rate_hz)
        start = round(t * sc.rate_hz)
        if start + length >= n - round(AFTER_S * sc.rate_hz):
            return out
        out.append((start, length))
        t = (start + length) / sc.rate_hz + float(rng.uniform(sc.gap_min_s, sc.gap_max_s))


def generate_curves(sc: CurveScenario) -> Iterator[tuple[float, bytes, dict[str, Any]]]:
    """``(time_s, nmea_bytes, truth_record)`` per epoch; the truth records are those of
    :func:`firmware_host.devtools.rover_sim.generate_field` (so the rover harness's
    :func:`~firmware_host.devtools.rover_harness.measure` reads them) plus the true turn rate
    (``turn_rate_dps``)."""
    fm = draw_field_model(sc.model, sc.seed)
    path_rng = np.random.default_rng([sc.seed, _PATH])
    rng = np.random.default_rng([sc.seed, _NOISE])
    dt = 1.0 / sc.rate_hz
    n = round(sc.duration_s * sc.rate_hz)
    rsc = RoverScenario(rate_hz=sc.rate_hz, duration_s=sc.duration_s, seed=sc.seed)
    frame = LocalFrame(rsc.origin_lat_deg, rsc.origin_lon_deg, rsc.origin_alt_m)
    freeze_at: dict[int, int] = {}
    for i, (start, length) in enumerate(_freezes(sc, n, np.random.default_rng(
            [sc.seed, _FREEZE]))):
        for k in range(start, start + length):
            freeze_at[k] = i
    stops = _stops(sc.duration_s, np.random.default_rng([sc.seed, _STOPS]))
    segs = _segments(sc, path_rng)
    seg = next(segs)
    err = ReceiverError(fm, dt, rng)
    car = _Tractor()
    sub = 10
    hdop, sats = 0.9, 9
    frozen: tuple[Any, ...] | None = None
    for k in range(n):
        t_rel = k * dt
        ve, vn = car.v * math.sin(car.psi), car.v * math.cos(car.psi)
        car.hist.append((t_rel, ve, vn))
        lve, lvn = _lagged(car.hist, t_rel - fm.lag_s)
        vne = lve + float(rng.normal(0, fm.vel_noise_mps))
        vnn = lvn + float(rng.normal(0, fm.vel_noise_mps))
        err_e, err_n, err_u = err.e, err.n, err.u
        we, wn, wu = (float(x) for x in rng.normal(0, fm.white_m, 3))
        lat, lon, h = frame.to_lla(car.e + err_e + we, car.n + err_n + wn, err_u + wu)
        lat = _quantise_deg(lat, fm.minute_decimals)
        lon = _quantise_deg(lon, fm.minute_decimals)
        h = round(h, 3)
        hdop = min(1.6, max(0.7, hdop + float(rng.normal(0, 0.01))))
        if rng.random() < 0.002:
            sats = int(np.clip(sats + rng.integers(-1, 2), 7, 11))
        age = 1.0 + t_rel % 5.0
        ev = freeze_at.get(k)
        offset = 0.0
        if ev is None:
            frozen = None
            fix = (lat, lon, h, vne, vnn, hdop, sats, age)
        else:
            if frozen is None:
                frozen = (lat, lon, h, vne, vnn, hdop, sats, age)
            fix = frozen
            fe, fn, _ = frame.to_enu(fix[0], fix[1], fix[2])
            offset = math.hypot(fe - (car.e + err_e + we), fn - (car.n + err_n + wn))
        t = rsc.start_utc_s + t_rel
        data = _nmea_epoch(rsc, t, (fix[0], fix[1], fix[2]), fix[3], fix[4], fix[5], fix[6],
                           fix[7], fm.speed_decimals)
        tlat, tlon, th = frame.to_lla(car.e, car.n, 0.0)
        yield t, data, {
            "k": k, "utc": round(t % 86400.0, 6), "true_lat": tlat, "true_lon": tlon,
            "true_alt": th, "true_e": car.e, "true_n": car.n, "true_u": 0.0,
            "err_e": err_e + we, "err_n": err_n + wn, "err_u": err_u + wu,
            "fault": ev is not None, "fault_kind": "frozen" if ev is not None else None,
            "fault_event": ev, "fault_offset_m": offset, "fault_sigmas": 0.0,
            "fault_rate_mps": 0.0, "outage": False, "speed_true": car.v,
            "turn_rate_dps": math.degrees(car.kappa * car.v),
        }
        for j in range(sub):
            t_sub = t_rel + j * dt / sub
            if car.s_seg >= seg.length_m:
                seg = next(segs)
                car.s_seg = 0.0
            car.advance(seg, any(a <= t_sub < b for a, b in stops), dt / sub, sc)
            car.hist.append((t_sub + dt / sub, car.v * math.sin(car.psi),
                             car.v * math.cos(car.psi)))
        err.step(rng)


def _lagged(hist: list[tuple[float, float, float]], t_lag: float) -> tuple[float, float]:
    """The true velocity at ``t_lag`` (linear between sub-steps; the oldest before it), the
    history pruned to what later calls need."""
    while len(hist) > 2 and hist[1][0] <= t_lag:
        hist.pop(0)
    if t_lag <= hist[0][0] or len(hist) == 1:
        return hist[0][1], hist[0][2]
    (t0, e0, n0), (t1, e1, n1) = hist[0], hist[1]
    w = (t_lag - t0) / (t1 - t0)
    return e0 + w * (e1 - e0), n0 + w * (n1 - n0)


# --------------------------------------------------------------------------- the score


@dataclass
class FrozenEvent:
    """One freeze, scored (m, s)."""

    start_s: float
    duration_s: float
    max_turn_dps: float  # the truth's largest turn rate during it
    speed_mps: float  # the truth's speed at the freeze
    e0_m: float  # the receiver's distance to the truth when it froze
    worst_excess_m: float  # the output's distance to the truth minus e0, worst epoch
    over: int  # epochs with an output more than EXCESS_M in excess
    raw_worst_excess_m: float  # the frozen receiver's own (doing nothing)
    outputs: int  # epochs of the freeze (after its first) with an output
    none: int  # ... with none
    last_output_s: float  # the last output's time after the freeze (nan: none)
    after_out_rms_m: float  # the AFTER_S after the end (rover_harness.measure)
    after_raw_rms_m: float


def score(epochs: Sequence[dict[str, Any]], truth: Sequence[dict[str, Any]]
          ) -> list[FrozenEvent]:
    """Every freeze of a run against the bullet (records matched by fix time)."""
    by_t = {round(e["utc"] * 1000.0): e for e in epochs if e.get("utc") is not None}
    ref = truth[0]
    frame = LocalFrame(ref["true_lat"], ref["true_lon"], ref["true_alt"])

    def dist(tr: dict[str, Any], lat: float | None, lon: float | None) -> float:
        if lat is None or lon is None:
            return math.nan
        e, n, _ = frame.to_enu(lat, lon, tr["true_alt"])
        return math.hypot(e - tr["true_e"], n - tr["true_n"])

    spans: dict[int, list[dict[str, Any]]] = {}
    for tr in truth:
        if tr["fault_kind"] == "frozen":
            spans.setdefault(tr["fault_event"], []).append(tr)
    harness = {round(ev.start_s, 3): ev for ev in measure(epochs, truth).events}
    out: list[FrozenEvent] = []
    for trs in spans.values():
        first = by_t.get(round(trs[0]["utc"] * 1000.0)) or {}
        e0 = dist(trs[0], first.get("raw_lat"), first.get("raw_lon"))
        worst = raw_worst = -math.inf
        over = outputs = none = 0
        last = math.nan
        for tr in trs[1:]:
            ep = by_t.get(round(tr["utc"] * 1000.0)) or {}
            raw_worst = max(raw_worst, dist(tr, ep.get("raw_lat"), ep.get("raw_lon")) - e0)
            d = dist(tr, ep.get("lat"), ep.get("lon"))
            if math.isnan(d):
                none += 1
                continue
            outputs += 1
            worst = max(worst, d - e0)
            over += d - e0 > EXCESS_M
            last = tr["utc"] - trs[0]["utc"]
        h = harness[round(trs[0]["utc"], 3)]
        out.append(FrozenEvent(
            trs[0]["utc"], trs[-1]["utc"] - trs[0]["utc"],
            max(abs(tr.get("turn_rate_dps", math.nan)) for tr in trs),
            trs[0].get("speed_true", math.nan), e0,
            worst if outputs else math.nan, over, raw_worst, outputs, none, last,
            h.after_out_rms_m, h.after_raw_rms_m))
    return out


@dataclass
class FrozenRun:
    model: str
    seed: int
    rate_hz: float
    events: list[FrozenEvent]


def run_matrix(cfg: BridgeConfig, models: Sequence[str], seeds: Sequence[int],
               rates: Sequence[float], duration_s: float,
               step: Any = None, harness: bool = False) -> list[FrozenRun]:
    """Every (model, rate, seed) run scored; ``harness``: the rover harness's runs instead
    (``sim rover-harness``: its frozen events, the other kinds between them)."""
    runs = []
    for model in models:
        for rate in rates:
            for seed in seeds:
                if harness:
                    stream = generate(harness_scenario(model, seed, rate, duration_s))
                else:
                    stream = generate_curves(CurveScenario(rate_hz=rate, duration_s=duration_s,
                                                           seed=seed, model=model))
                epochs, truth = replay_stream(cfg, stream)
                runs.append(FrozenRun(model, seed, rate, score(epochs, truth)))
                if step is not None:
                    step(f"{model} {rate:g} Hz seed {seed}")
    return runs


def _worst(runs: Sequence[FrozenRun], key: str) -> tuple[float, int | None]:
    best, seed = -math.inf, None
    for r in runs:
        for ev in r.events:
            x = getattr(ev, key)
            if not math.isnan(x) and x > best:
                best, seed = x, r.seed
    return best, seed


def summarise(runs: Sequence[FrozenRun], turning_dps: float = 3.0) -> list[dict[str, Any]]:
    """One row per (model, rate): pooled counts and the worst seed of each number."""
    rows = []
    for model, rate in sorted({(r.model, r.rate_hz) for r in runs}):
        rs = [r for r in runs if r.model == model and r.rate_hz == rate]
        evs = [e for r in rs for e in r.events]
        worst, wseed = _worst(rs, "worst_excess_m")
        raw, _ = _worst(rs, "raw_worst_excess_m")
        after = [e for e in evs if not math.isnan(e.after_raw_rms_m)]
        rows.append({
            "model": model, "rate_hz": rate, "seeds": [r.seed for r in rs],
            "events": len(evs),
            "in_turns": sum(e.max_turn_dps >= turning_dps for e in evs) if any(
                not math.isnan(e.max_turn_dps) for e in evs) else None,
            "worst_excess_m": worst, "worst_seed": wseed,
            "events_over": sum(e.over > 0 for e in evs), "epochs_over": sum(e.over for e in evs),
            "raw_worst_excess_m": raw,
            "outputs": sum(e.outputs for e in evs), "none": sum(e.none for e in evs),
            "longest_output_s": max((e.last_output_s for e in evs
                                     if not math.isnan(e.last_output_s)), default=math.nan),
            "after_worse_025": sum(e.after_out_rms_m > e.after_raw_rms_m + 0.25 for e in after),
            "after_events": len(after),
        })
    return rows


def console_table(rows: Sequence[dict[str, Any]]) -> str:
    t = tables.Table(["model", "Hz", "freezes (in turns)", "worst excess m (seed)",
                      "freezes > 1 m (epochs)", "raw frozen worst excess m",
                      "frozen epochs out / none", "last output s", "10 s after: > raw + 0.25"])
    for r in rows:
        turns = "–" if r["in_turns"] is None else r["in_turns"]
        t.add(r["model"], f"{r['rate_hz']:g}", f"{r['events']} ({turns})",
              f"{r['worst_excess_m']:.2f} ({r['worst_seed']})",
              f"{r['events_over']} ({r['epochs_over']})", f"{r['raw_worst_excess_m']:.2f}",
              f"{r['outputs']} / {r['none']}", f"{r['longest_output_s']:.1f}",
              f"{r['after_worse_025']}/{r['after_events']}")
    return t.console()


# --------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default="rover", help="config file or preset name")
    parser.add_argument("--seeds", type=seed_list, default="1-5", help="seeds, like 1-5 or 1,3")
    parser.add_argument("--models", type=choice_list(ERROR_MODELS, "models"), default=None,
                        help="receiver models, comma separated (default: dgps,coarse; with "
                             "--harness: gm,dgps,multipath,coarse)")
    parser.add_argument("--rates", type=positive_float_list, default="1,5,10",
                        help="fix rates in Hz, comma separated")
    parser.add_argument("--duration", type=positive_float, default=900.0,
                        help="seconds per run")
    parser.add_argument("--json", default=None, type=output_file_arg,
                        help="also write every event's numbers to this JSON file")
    parser.add_argument("--harness", action="store_true",
                        help="score the frozen events of the rover harness's runs instead "
                             "(sim rover-harness: straight passes and 6 m headland turns; "
                             "the gm model freezes the position only)")


def run(args: argparse.Namespace) -> int:
    logging.getLogger("fdi_bridge.rover").setLevel(logging.ERROR)
    cfg = load_config(args.config)
    models = args.models or list(ERROR_MODELS if args.harness else MODELS)
    bad = [m for m in models if m not in MODELS and not args.harness]
    if bad:
        raise UsageError(f"--models: {', '.join(bad)}: a curved drive's receiver is one of "
                         f"{', '.join(MODELS)} (the others with --harness)")
    t0 = time.perf_counter()
    n = len(models) * len(args.seeds) * len(args.rates)
    with Progress(n, "rover frozen", unit="run") as bar:
        runs = run_matrix(cfg, models, args.seeds, args.rates, args.duration,
                          step=bar.step, harness=args.harness)
    rows = summarise(runs)
    print(console_table(rows))
    print(f"\n{len(runs)} runs in {time.perf_counter() - t0:.1f} s (config {cfg.name}); "
          f"excess: the output's distance to the truth minus the receiver's when it froze")
    if args.json:
        doc = {"config": cfg.name, "rows": rows,
               "runs": [{"model": r.model, "seed": r.seed, "rate_hz": r.rate_hz,
                         "events": [e.__dict__ for e in r.events]} for r in runs]}
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(_clean(doc), f, indent=1)
    return 0
