"""``fdi-bridge calibrate``: the rover's drift test calibrated once, on clean recordings.

By default the drift test (``fdi/drift.py``) learns the receiver's noise over its first
``drift_calibrate_s`` (300 s) of every start and uses the wide ``drift_sigma_m`` until then,
so a slow drift that begins in those minutes is found late. This command calibrates a receiver
once, on recordings of clean drives (``fdi-bridge record``, or a plain NMEA log), the way an
autopilot keeps its compass calibration: it measures the receiver's Doppler lag where the
drives turn (``drift_lag_s``, with ``drift_lag_sd_s`` 0.05 s or more instead of 0.15 ± 0.15 s, and
the ramp's 10 s flag at 4.5 σ of the tighter σ instead of 4), prints
σ per horizon and the lines to paste under ``[rover.detector]`` (``drift_sigma_m`` = 1.5 × σ,
never wider than before: :data:`firmware_host.rover.calibration.START_FACTOR`, and the lag),
and ``--out FILE`` writes the whole
configuration with it. The test starts from these instead of the wide ones and still
calibrates on the day's first ``drift_calibrate_s`` (the sky and the multipath are the day's); set
``drift_calibrate_s = 0`` to keep them for good. Record at the rate the receiver will run at,
for at least twice the longest horizon (200 s with the defaults) with speed and course on
every fix; several recordings are better than one (the largest σ is kept).

It also says how small a slow drift could be found on this receiver at all: the chance that
the best possible test (:mod:`firmware_host.rover.drift_bound`, told when the drift
starts) finds 0.1 m/s within 10 s and 0.05 m/s within 30 s at 0.1 % false alarms, from the
same recordings (an unbroken stretch of 5 minutes or more is needed for it).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

from drivers.gps.link import LinkFit
from fdi.errors import FdiBridgeError, UsageError
from fdi.rover import RoverDetectorParams
from firmware_host.commands.checks import input_file_arg, output_file_arg
from firmware_host.commands.config_cmd import effective_toml
from firmware_host.commands.replay import load_input
from firmware_host.rover.calibration import (
    START_FACTOR,
    calibrate_records,
    calibrated_detector,
    doppler_free,
)
from firmware_host.rover.drift_bound import bullet_bounds
from firmware_host.rover.pipeline import run_on_bytes
from firmware_host.runtime.config import bridge_config, load_bridge_file


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("logs", nargs="+", type=input_file_arg, metavar="LOG",
                        help="recordings of one receiver's clean drives (capture or NMEA log)")
    parser.add_argument("--config", default="rover",
                        help="the configuration the receiver runs with (file or preset)")
    parser.add_argument("--out", type=output_file_arg, default=None,
                        help="write that configuration with the calibration to this TOML file")


def detector_lines(det: RoverDetectorParams) -> list[str]:
    """The lines to paste under ``[rover.detector]``: what calibration changed in ``det``."""
    return ["[rover.detector]",
            "drift_sigma_m = [" + ", ".join(f"{s:g}" for s in det.drift_sigma_m) + "]",
            f"drift_floor_frac = {det.drift_floor_frac:g}",
            f"drift_lag_s = {det.drift_lag_s:g}",
            f"drift_lag_sd_s = {det.drift_lag_sd_s:g}",
            f"ramp_sigmas = {det.ramp_sigmas:g}"]


def ramp_bound_line(runs: list[list[dict[str, Any]]], lag_s: float) -> str:
    """What the best possible test could find of a slow drift on this receiver (issue 13's ramp
    bullets; :mod:`firmware_host.rover.drift_bound`): an upper bound, at 0.1 % false
    alarms, from the same recordings."""
    chains = [ch for records in runs for ch in doppler_free(records, lag_s)]
    try:
        bounds = bullet_bounds(chains)
    except ValueError as err:
        return (f"slow drifts: no bound on what a test could find on this receiver from these "
                f"recordings ({err}; an unbroken stretch of 5 x 60 s of fixes at a steady "
                f"rate is needed)")
    parts = [f"{r:g} m/s within {dl:g} s: at most {p:.2f} (direction unknown {p2:.2f})"
             for r, dl, _, p, p2 in bounds]
    return ("slow drifts on this receiver, the chance the best possible test finds them in "
            "time at 0.1 % false alarms (fdi-bridge sim ramp-oracle): " + "; ".join(parts))


def receiver_line(path: str | Path, link: dict[str, Any] | None, capture: bool) -> str:
    """What the receiver of a recording really sends: its rate and sentence set, and whether
    they fit the line's baud rate (the capture's, else ``[rover.port] baudrate``): the preset
    should be calibrated at the rate and sentences the vehicle will run (issue E)."""
    if link is None:
        return f"{path}: too few epochs to tell the receiver's rate and sentences"
    fit = LinkFit(int(link["baudrate"]), float(link["bytes_per_epoch"]),
                  float(link["rate_hz"]), tuple(link["sentences"]))
    where = "the capture's" if capture else "[rover.port]"
    head = (f"{path}: the receiver sends {fit.rate_hz:.3g} Hz of "
            f"{'+'.join(fit.sentences) or 'NMEA'} ({fit.bytes_per_epoch:.0f} B an epoch, "
            f"{fit.need_bytes_s:.0f} B/s)")
    if fit.fits:
        return f"{head}; fits {where} {fit.baudrate} baud ({fit.load:.0%} of the line)"
    tail = fit.message().split(" does not fit ", 1)[1]  # "9600 baud (960 B/s): at most ..."
    return f"{head}; does not fit {where} {tail}"


def run(args: argparse.Namespace) -> int:
    bf = load_bridge_file(args.config)  # ConfigError: printed by the CLI, exit 2
    cfg = bridge_config(bf)
    d = cfg.rover.detector
    if not d.runs_drift_test:
        raise UsageError(f"{args.config}: the drift test does not run in this configuration "
                         f"(drift_test = {str(d.drift_test).lower()}, predictor = "
                         f"{d.predictor!r}, strategy = {d.strategy!r}): nothing to calibrate")
    runs = []
    for p in args.logs:
        inp = load_input(p)
        records, summary = run_on_bytes(
            cfg.rover, inp.data(),
            baudrate=inp.baudrate if inp.kind == "capture" else None)
        runs.append(records)
        print(receiver_line(p, summary.get("link"), inp.kind == "capture"))
    for p, records in zip(args.logs, runs, strict=True):
        if not any(r.get("e") is not None for r in records):
            raise FdiBridgeError(f"{p}: no position fixes in it (a capture or NMEA log of the "
                                 f"receiver is expected)")
    try:
        cal = calibrate_records(runs, d.drift_horizons_s, d.drift_lag_s,
                                d.drift_lag_sd_s, margin=d.drift_cal_k,
                                margin_min_h=d.drift_cal_min_h)
    except ValueError as err:
        raise FdiBridgeError(f"cannot calibrate on {', '.join(map(str, args.logs))}: {err}; "
                             f"record a longer drive at a steady run of fixes") from None
    print(f"{len(args.logs)} recording(s), {cal.chains} stretch(es) with an unbroken Doppler "
          f"chain, {cal.seconds:.0f} s of fixes")
    if cal.lag is not None:
        print(f"Doppler lag {cal.lag_s:g} s (standard error {cal.lag.se_s:g} s over "
              f"{cal.lag.pairs} pairs that turn; drift_lag_sd_s {cal.lag_sd_s:g}, was "
              f"{d.drift_lag_s:g} +- {d.drift_lag_sd_s:g} s)")
    else:
        print(f"Doppler lag: the drives do not turn enough to measure it; kept "
              f"{d.drift_lag_s:g} +- {d.drift_lag_sd_s:g} s")
    det = calibrated_detector(d, cal)
    start = det.drift_sigma_m  # starting_sigma: START_FACTOR x sigma, never wider than was
    print(f"{'horizon s':>10} {'sigma m':>9} {'start m':>8} {'was m':>7} {'differences':>12}")
    for h, s, st, was, n in zip(cal.horizons_s, cal.sigma_m, start, d.drift_sigma_m,
                                cal.independent, strict=True):
        print(f"{h:>10g} {s:>9.4f} {st:>8.4f} {was:>7g} {n:>12.0f}")
    then = (f"still calibrates on each day's first {d.drift_calibrate_s:g} s"
            if d.drift_calibrate_s > 0 else "keeps them (drift_calibrate_s = 0)")
    print(f"(start: {START_FACTOR:g} x sigma, never wider than was; the drift test starts "
          f"there and {then})")
    print(ramp_bound_line(runs, cal.lag_s))
    print()
    print("\n".join(detector_lines(det)))
    if args.out:
        out_bf = dataclasses.replace(
            bf, name=f"{cfg.name}-calibrated",
            description=(f"{cfg.name} with the drift test calibrated by fdi-bridge calibrate "
                         f"on {', '.join(Path(p).name for p in args.logs)}"),
            rover=dataclasses.replace(cfg.rover, detector=det))
        body = effective_toml(out_bf).split("\n", 1)[1]  # its first line names the source
        try:
            Path(args.out).write_text(
                f"# {args.config} calibrated by: fdi-bridge calibrate "
                f"{' '.join(map(str, args.logs))} --config {args.config}\n" + body,
                encoding="utf-8")
        except OSError as err:  # a full disk, a read-only mount: said, not a traceback
            raise FdiBridgeError(f"{args.out}: cannot write the configuration: "
                                 f"{err.strerror or err}") from None
        print(f"\nwrote {args.out} (use it as --config {args.out})")
    return 0
