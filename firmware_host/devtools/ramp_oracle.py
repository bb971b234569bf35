"""The most any detector can find of a slow ramp in time: an oracle bound (issue 13).

``fdi-bridge sim ramp-oracle [--harness OUT.json] [--seeds 1-5] [--rates 1] [--models gm,coarse]``

Issue 13 asks for ramps of 0.1 m/s found within 10 s and 0.05 m/s within 30 s, with at most
0.1 % of clean epochs flagged. Whether that can be done depends on the receiver: a ramp is
seen only against the change of the receiver's own error over the same seconds. This module
measures, per receiver, how well the best test there is could do it. (``tools/ramp_bound.py``
scores one 10 s window with its threshold set on the runs it scores: what that test finds.
This bounds every test from above.)

**The observable** is the drift test's own (D1 of :mod:`fdi.drift`): the Doppler-free value
b(t) = fix − the displacement integrated from the receiver's own speed and course, on a
clean drive of the same generator receiver (another error realisation, path and Doppler
noise: ``seed + BOUND_SEED_OFFSET``; :func:`~firmware_host.devtools.rover_harness.clean_drive`),
through the pipeline (``doppler_free`` of :mod:`firmware_host.rover.calibration`, the
Doppler's lag estimated there as ``fdi-bridge calibrate`` does).

**The oracle** and its two columns (told the direction, and not) are
:mod:`firmware_host.rover.drift_bound`'s, which ``fdi-bridge calibrate`` uses on a receiver's
own recordings. The ``multipath`` model is not Gaussian (its steps inflate γ and make the bound
pessimistic) and is not offered.

With ``--harness`` (a ``fdi-bridge sim rover-harness --json`` file), every ramp the bullets
ask for in it is given its d' from its own receiver and rate, and the table puts the
number the oracle could expect to find in time (Σ P_D) beside the number the preset found.
The column "as the harness scores" is the oracle under the harness's own rules (a per-epoch
false-alarm budget, the delay from the first faulty epoch, direction unknown, 60 s of
history: :mod:`firmware_host.devtools.ramp_score`); ``fdi-bridge sim rover-harness --oracle``
prints it beside the preset's runs directly.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fdi.errors import UsageError
from firmware_host.commands import tables
from firmware_host.commands.checks import (
    choice_list,
    input_file_arg,
    output_file_arg,
    positive_float,
    positive_float_list,
    seed_list,
)
from firmware_host.devtools.progress import Progress
from firmware_host.devtools.ramp_score import (
    HARNESS_HISTORY_S,
    EpochTests,
    epoch_tests,
    p_detect,
    standard_draws,
)
from firmware_host.devtools.rover_harness import (
    BOUND_MODELS,
    REPORT_SEEDS,
    Receiver,
    bullet_deadline,
    receiver,
)
from firmware_host.devtools.rover_sim import RoverScenario
from firmware_host.rover.drift_bound import (
    BULLETS,
    bounds_from_gamma,
    d_prime,
    p_detect_2d,
    phi,
    z_alpha,
)
from firmware_host.runtime.config import load_config

#: Ramps that start this soon are before the online calibration (``drift_calibrate_s``).
CALIBRATION_S = 300.0
#: Where the generator's runs start (seconds of day).
START_UTC_S = RoverScenario.start_utc_s


@dataclass
class Row:
    """Ramps of one model, rate, bullet and side of the calibration."""

    model: str
    rate_hz: float
    deadline_s: float
    precal: bool
    ramps: int = 0
    found: int = 0
    oracle: float = 0.0
    oracle_2d: float = 0.0
    oracle_harness: float = 0.0  # scored as the harness scores (ramp_score)
    d: list[float] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {"model": self.model, "rate_hz": self.rate_hz, "deadline_s": self.deadline_s,
                "before_calibration": self.precal, "ramps": self.ramps,
                "found_in_time": self.found, "oracle_at_most": self.oracle,
                "oracle_2d_at_most": self.oracle_2d,
                "oracle_as_scored": self.oracle_harness,
                "d_min": min(self.d), "d_median": float(np.median(self.d))}


def load_harness(path: str) -> dict[str, Any]:
    """A ``fdi-bridge sim rover-harness --json`` file, checked for what :func:`harness_rows`
    reads; anything else is a :class:`UsageError` naming the file and what was found."""
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UsageError(f"--harness: expected a `fdi-bridge sim rover-harness --json` file, "
                         f"{path} could not be read as JSON ({exc})") from None
    runs = doc.get("runs") if isinstance(doc, dict) else None
    keys = ("model", "seed", "rate_hz", "events")
    ev_keys = ("kind", "rate_mps", "start_s", "delay_s")
    if not isinstance(runs, list) or not all(
            isinstance(r, dict) and all(k in r for k in keys)
            and isinstance(r["events"], list)
            and all(isinstance(e, dict) and all(k in e for k in ev_keys) for e in r["events"])
            for r in runs):
        raise UsageError(f"--harness: expected a `fdi-bridge sim rover-harness --json` file "
                         f"(runs with {', '.join(keys)}; events with {', '.join(ev_keys)}), "
                         f"found {path} without them")
    return doc


def harness_rows(doc: dict[str, Any], get: Any, alpha: float, history_s: float,
                 harness_history_s: float = HARNESS_HISTORY_S) -> list[Row]:
    """Every ramp the bullets ask for in a harness JSON ``doc``: the preset's result beside the
    oracle's expectation, per model, rate, bullet and side of the calibration. ``get(model,
    seed, rate)`` gives the :class:`Receiver` (its γ long enough for both histories). Three
    oracles: one test at the deadline told the direction (``history_s``), the same not told it,
    and the oracle scored as the harness scores (:mod:`firmware_host.devtools.ramp_score`, with
    ``harness_history_s``)."""
    z = z_alpha(alpha)
    rows: dict[tuple[str, float, float, bool], Row] = {}
    tests: dict[tuple[int, float], EpochTests] = {}
    draws: dict[int, Any] = {}
    for run in doc["runs"]:
        if run["model"] not in BOUND_MODELS:
            continue
        rec: Receiver | None = None
        for e in run["events"]:
            deadline = bullet_deadline(e["rate_mps"]) if e["kind"] == "ramp" else None
            if deadline is None:
                continue
            rec = rec or get(run["model"], run["seed"], run["rate_hz"])
            d = d_prime(rec.gamma, run["rate_hz"], e["rate_mps"], deadline, history_s)
            key_t = (id(rec), deadline)
            if key_t not in tests:
                tests[key_t] = epoch_tests(rec.gamma, run["rate_hz"], deadline,
                                           harness_history_s)
            et = tests[key_t]
            zs = draws.setdefault(len(et.y), standard_draws(len(et.y)))
            t0 = e["start_s"] % 86400.0 - START_UTC_S  # seconds into the run
            key = (run["model"], run["rate_hz"], deadline, t0 < CALIBRATION_S)
            row = rows.setdefault(key, Row(*key))
            row.ramps += 1
            row.found += e["delay_s"] is not None and e["delay_s"] <= deadline
            row.oracle += phi(d - z)
            row.oracle_2d += p_detect_2d(d, alpha)
            row.oracle_harness += p_detect(et, e["rate_mps"], alpha, zs)
            row.d.append(d)
    return [rows[k] for k in sorted(rows)]


def edge_rows(recs: Sequence[Receiver], alpha: float, history_s: float) -> list[dict[str, Any]]:
    """Per receiver, d' and the oracle's P_D at each bullet's slowest ramp."""
    out = []
    for rec in recs:
        row: dict[str, Any] = {"model": rec.model, "seed": rec.seed, "rate_hz": rec.rate_hz,
                               "lag_s": rec.lag_s}
        for r, dl, d, p, p2 in bounds_from_gamma(rec.gamma, rec.rate_hz, alpha, history_s):
            row[f"d_{r:g}_{dl:g}"] = d
            row[f"p_{r:g}_{dl:g}"] = p
            row[f"p2_{r:g}_{dl:g}"] = p2
        out.append(row)
    return out


def edge_table(rows: Sequence[dict[str, Any]]) -> tables.Table:
    t = tables.Table(["model", "seed", "Hz", "lag (s)"]
                     + [h for r, dl in BULLETS
                        for h in (f"d' {r:g} m/s in {dl:g} s", "oracle P_D",
                                  "direction unknown")])
    for row in rows:
        cells: list[Any] = [row["model"], row["seed"], f"{row['rate_hz']:g}",
                            f"{row['lag_s']:.2f}"]
        for r, dl in BULLETS:
            cells += [f"{row[f'd_{r:g}_{dl:g}']:.2f}", f"{row[f'p_{r:g}_{dl:g}']:.3f}",
                      f"{row[f'p2_{r:g}_{dl:g}']:.3f}"]
        t.add(*cells)
    return t


def harness_table(rows: Sequence[Row]) -> tables.Table:
    t = tables.Table(["model", "Hz", "bullet", "calibration", "ramps", "found in time",
                      "oracle at most", "direction unknown", "as the harness scores",
                      "d' min", "d' median"])
    for row in rows:
        bullet = next(f"{r:g} m/s in {dl:g} s" for r, dl in BULLETS if dl == row.deadline_s)
        t.add(row.model, f"{row.rate_hz:g}", bullet, "before" if row.precal else "after",
              row.ramps, row.found, f"{row.oracle:.1f}", f"{row.oracle_2d:.1f}",
              f"{row.oracle_harness:.1f}",
              f"{min(row.d):.2f}",
              f"{float(np.median(row.d)):.2f}")
    return t


# --------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default="rover", help="config file or preset name")
    parser.add_argument("--harness", type=input_file_arg, default=None,
                        help="a `fdi-bridge sim rover-harness --json` file: the oracle's "
                             "expectation beside the preset's result for each of its ramps")
    parser.add_argument("--seeds", type=seed_list,
                        default=",".join(str(s) for s in REPORT_SEEDS),
                        help="receivers (without --harness), like 1-5 or 1,3")
    parser.add_argument("--models", type=choice_list(BOUND_MODELS, "models"),
                        default=",".join(BOUND_MODELS),
                        help="error models, comma separated (multipath is not Gaussian: "
                             "not offered)")
    parser.add_argument("--rates", type=positive_float_list, default="1",
                        help="fix rates in Hz, comma separated (without --harness)")
    parser.add_argument("--alpha", type=positive_float, default=0.001,
                        help="the oracle's false-alarm probability (the bullet's 0.1 %%)")
    parser.add_argument("--history", type=positive_float, default=30.0,
                        help="seconds of clean fixes before the ramp the oracle uses")
    parser.add_argument("--json", default=None, type=output_file_arg,
                        help="also write every number to this JSON file")


def run(args: argparse.Namespace) -> int:
    logging.getLogger("fdi_bridge.rover").setLevel(logging.ERROR)
    cfg = load_config(args.config)
    t0 = time.perf_counter()
    cache: dict[tuple[str, int, float], Receiver] = {}

    def get(model: str, seed: int, rate_hz: float) -> Receiver:
        key = (model, 0 if model == "gm" else seed, rate_hz)  # gm: one receiver (all seeds)
        if key not in cache:
            cache[key] = receiver(cfg, model, seed, rate_hz,
                                  max(args.history, HARNESS_HISTORY_S))
        return cache[key]

    doc: dict[str, Any] = {"config": cfg.name, "alpha": args.alpha, "history_s": args.history}
    if args.harness is not None:
        hdoc = load_harness(args.harness)
        rows = harness_rows(hdoc, get, args.alpha, args.history)
        print(harness_table(rows).console())
        doc["harness"] = str(args.harness)
        doc["rows"] = [r.as_dict() for r in rows]
    else:
        todo = list(dict.fromkeys((m, 0 if m == "gm" else s, r) for m in args.models
                                  for s in args.seeds for r in args.rates))
        with Progress(len(todo), "ramp oracle", unit="receiver") as bar:
            recs = []
            for m, s, r in todo:
                recs.append(get(m, s or args.seeds[0], r))
                bar.step()
        erows = edge_rows(recs, args.alpha, args.history)
        print(edge_table(erows).console())
        doc["receivers"] = erows
    print(f"\n{len(cache)} receivers in {time.perf_counter() - t0:.1f} s (config {cfg.name}); "
          f"oracle: start, direction and error covariance known, one test at alpha "
          f"{args.alpha:g}: an upper bound; as the harness scores: every epoch tested at "
          f"alpha {args.alpha:g}, direction unknown, {HARNESS_HISTORY_S:g} s of history")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(doc, f, indent=1)
    return 0
