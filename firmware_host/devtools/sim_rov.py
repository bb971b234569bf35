"""``fdi-bridge sim rov``: the ROV compass experiment, and the ROV step benchmark.

``fdi-bridge sim rov --config CONFIG --duration S --fault SPEC --out DIR [--no-ft]
[--plant nomoto|nonlinear] [--compass-noise-deg SIGMA] [--turn-every S] [--gyro]`` runs the
simulated vehicle step-locked in-process
(:func:`~firmware_host.devtools.rov_experiment.run_experiment`) and writes ``DIR/epochs.jsonl``
(one object per 200 ms step) and ``DIR/summary.json``. :func:`bench_rov_step` times one step.
The real-vehicle loop is the product's: :func:`firmware_host.rov.app.run_rov`.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from fdi.errors import UsageError
from firmware_host.commands.checks import non_negative_float, output_dir_arg, positive_float
from firmware_host.commands.tables import fields, summary_rows
from firmware_host.devtools.rov_experiment import run_experiment, summarize
from firmware_host.devtools.rov_sim import make_plant, parse_fault
from firmware_host.rov.config import RovConfig, load_rov_config
from firmware_host.rov.control import RovController


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default=None, help="ROV preset (default: built-in defaults)")
    parser.add_argument("--duration", type=positive_float, default=130.0,
                        help="simulated seconds")
    parser.add_argument("--fault", action="append", default=[], metavar="SPEC",
                        help="KIND:MAGNITUDE@START[-END], e.g. drift:30@70 (repeatable)")
    parser.add_argument("--out", required=True, type=output_dir_arg,
                        help="output directory (epochs.jsonl, summary.json)")
    parser.add_argument("--no-ft", action="store_true", help="detect but never substitute")
    parser.add_argument("--setpoint", type=float, default=None, help="heading setpoint, deg")
    parser.add_argument("--seed", type=int, default=None, help="simulation seed")
    parser.add_argument("--json", action="store_true",
                        help="print the summary as JSON (default: a table)")
    parser.add_argument("--plant", choices=("nomoto", "nonlinear"), default=None,
                        help="simulated yaw model (default: the config's, nomoto)")
    parser.add_argument("--compass-noise-deg", type=non_negative_float, default=None,
                        metavar="SIGMA", help="compass noise for the whole run, deg")
    parser.add_argument("--turn-every", type=non_negative_float, default=None, metavar="S",
                        help="alternate the setpoint by the config's turn_deg every S seconds")
    parser.add_argument("--gyro", action="store_true",
                        help="give the controller the vehicle's yaw-rate gyro (in-process)")


def run(args: argparse.Namespace) -> int:
    cfg, _ = load_rov_config(args.config)
    if args.duration < cfg.period_s:
        raise UsageError(f"--duration {args.duration:g}: shorter than one control period "
                         f"({cfg.period_s:g} s)")
    if args.setpoint is not None:
        cfg = replace(cfg, setpoint_deg=args.setpoint % 360.0)
    sim = cfg.sim
    if args.plant is not None:
        sim = replace(sim, plant=args.plant)
    if args.compass_noise_deg is not None:
        sim = replace(sim, compass_noise_deg=args.compass_noise_deg)
    if args.turn_every is not None:
        sim = replace(sim, turn_every_s=args.turn_every)
    cfg = replace(cfg, sim=sim)
    try:
        faults = [parse_fault(s) for s in args.fault]
    except ValueError as err:
        raise UsageError(f"--fault: {err}") from err
    epochs = run_experiment(cfg, faults, args.duration, ft=not args.no_ft, seed=args.seed,
                            gyro=args.gyro)
    summary = summarize(epochs, faults)
    summary.update({"ft": not args.no_ft, "config": args.config, "duration_s": args.duration,
                    "setpoint_deg": cfg.setpoint_deg, "plant": cfg.sim.plant,
                    "compass_noise_deg": cfg.sim.compass_noise_deg, "gyro": args.gyro})
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "epochs.jsonl", "w", encoding="utf-8") as fh:
        for e in epochs:
            fh.write(json.dumps(e) + "\n")
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    if args.json:
        print(json.dumps(summary))
    else:
        print(fields(summary_rows(summary)))
        print(f"wrote {out / 'epochs.jsonl'} and {out / 'summary.json'}")
    return 0


def bench_rov_step(n: int, gyro: bool = True) -> dict[str, float]:
    """p50/p99 (ms) of one ROV step (detector + substitution + PID), on simulated data.

    ``gyro``: the nonlinear plant with its yaw gyro fed to the controller (the gyro witness and
    the FIR both run: the heavier path); otherwise the Nomoto plant and the FIR alone.
    """
    cfg = RovConfig()
    sim = replace(cfg.sim, plant="nonlinear") if gyro else cfg.sim
    plant = make_plant(sim, [parse_fault("drift:30@70")])
    ctl = RovController(cfg)
    times = np.empty(n)
    perf = time.perf_counter
    for k in range(n):
        if k:
            plant.advance(ctl.command.yaw_pct, cfg.period_s)
        tel = plant.measure()
        meas = None if tel is None else tel.heading_deg
        rate = plant.gyro_dps() if gyro else None
        t0 = perf()
        ctl.step(meas, cfg.period_s, rate)
        times[k] = perf() - t0
    ms = times * 1e3
    return {"n": n, "p50_ms": float(np.percentile(ms, 50)), "p99_ms": float(np.percentile(ms, 99)),
            "max_ms": float(ms.max())}
