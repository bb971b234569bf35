"""``fdi-bridge demo rov``: the paper's 30 deg drift at t = 70 s, with and without fault tolerance.

Prints a table; with matplotlib installed, writes figures like the paper's Fig. 3 (e^2, V and
R(k) with their thresholds) and Fig. 4 (heading with and without fault tolerance).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from firmware_host.commands import tables
from firmware_host.commands.checks import output_dir_arg
from firmware_host.devtools.rov_experiment import run_experiment, summarize
from firmware_host.devtools.rov_sim import parse_fault
from firmware_host.rov.config import load_rov_config


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default=None, help="ROV preset (default: built-in)")
    parser.add_argument("--drift", type=float, default=30.0,
                        help="compass drift fault from t = 70 s, deg")
    parser.add_argument("--out", type=output_dir_arg, default=Path("rov-demo"),
                        help="directory for the PNGs")
    parser.add_argument("--seed", type=int, default=None,
                        help="simulation seed (default: the config's sim.seed)")
    parser.add_argument("--plant", choices=("nomoto", "nonlinear"), default=None,
                        help="simulated yaw model (default: the config's)")
    parser.add_argument("--gyro", action="store_true", help="the controller gets the yaw gyro")
    parser.add_argument("--json", action="store_true",
                        help="print the two runs' summaries as JSON instead of the table "
                             "(the figures are written either way)")


def _err(e: dict[str, Any]) -> float:
    return float((e["heading_true"] - e["setpoint"] + 180.0) % 360.0 - 180.0)


def run(args: argparse.Namespace) -> int:
    cfg, _ = load_rov_config(args.config)
    if args.plant is not None:
        cfg = replace(cfg, sim=replace(cfg.sim, plant=args.plant))
    faults = [parse_fault(f"drift:{args.drift:g}@70")]
    runs = {ft: run_experiment(cfg, faults, 130.0, ft=ft, seed=args.seed, gyro=args.gyro)
            for ft in (False, True)}
    rows = []
    summaries = {}
    for ft, ep in runs.items():
        s = summarize(ep, faults)
        tail = [_err(e) for e in ep if e["t"] >= 104.0]
        s["mean_err_104_130_s_deg"] = sum(tail) / len(tail)
        summaries["ft" if ft else "no_ft"] = s
        rows.append(["on" if ft else "off", s["first_suspect_t"], s["first_fault_t"],
                     s.get("max_abs_err_after_fault_deg", 0.0), s["mean_err_104_130_s_deg"]])
    if args.json:
        print(json.dumps(tables.jsonable({"drift_deg": args.drift,
                                          "setpoint_deg": cfg.setpoint_deg, **summaries})))
    else:
        print(f"ROV compass drift {args.drift:g} deg at t = 70 s, "
              f"setpoint {cfg.setpoint_deg:g} deg")
        print(tables.table(["fault tolerance", "suspect at (s)", "confirmed at (s)",
                            "max |err| after (deg)", "mean err 104-130 s (deg)"], rows))
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no figures (pip install 'fdi-bridge[dev]')",
              file=sys.stderr if args.json else sys.stdout)
        return 0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ep = runs[True]
    t = [e["t"] for e in ep]
    t_end = t[-1] if t else 130.0

    def shade(a: Any) -> None:  # the injected drift: from its start to the end of the run
        for k, f in enumerate(faults):
            end = t_end if f.end_s is None else min(f.end_s, t_end)
            a.axvspan(f.start_s, end, color="tab:red", alpha=0.12, lw=0,
                      label="compass fault" if k == 0 else None)

    def legend(a: Any) -> None:  # beside the axes: it covers no data
        a.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)

    fig, ax = plt.subplots(2, 1, figsize=(9.5, 6), sharex=True)
    shade(ax[0])
    # e² cannot be negative: a log axis (a zero floored at 1e-4 deg², below the plot's range).
    ax[0].semilogy(t, [max(e["e2"], 1e-4) for e in ep], lw=0.9, label="e²(k)")
    ax[0].axhline(cfg.detector.theta_deg2, color="r", ls="--", label="θ")
    ax[0].set_ylabel("e² (deg²)")
    ax[0].set_ylim(bottom=1e-3)
    legend(ax[0])
    shade(ax[1])
    ax[1].plot(t, [e["V"] for e in ep], label="V")
    ax[1].plot(t, [e["snr"] for e in ep], label="R(k)")
    ax[1].axhline(cfg.detector.n0, color="r", ls="--", label="n₀")
    ax[1].set_xlabel("t (s)")
    legend(ax[1])
    fig.suptitle(f"Fault detection, {args.drift:g}° drift at t = 70 s (cf. paper Fig. 3)")
    fig.tight_layout()
    fig.savefig(out / "rov_fig3_detection.png", dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(2, 1, figsize=(9.5, 6), sharex=True)
    for i, ft in enumerate((False, True)):
        e_ = runs[ft]
        shade(ax[i])
        ax[i].plot(t, [e["heading_meas"] for e in e_], lw=0.7, label="compass (faulty)")
        ax[i].plot(t, [e["heading_used"] for e in e_], lw=0.7, label="heading used")
        ax[i].plot(t, [e["heading_true"] for e in e_], lw=1.2, label="true heading")
        ax[i].axhline(cfg.setpoint_deg, color="k", ls=":", label="setpoint")
        ax[i].set_ylabel("deg")
        ax[i].set_title("with fault tolerance" if ft else "without fault tolerance")
        legend(ax[i])
    ax[1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(out / "rov_fig4_heading.png", dpi=100)
    plt.close(fig)
    print(f"figures: {out / 'rov_fig3_detection.png'}, {out / 'rov_fig4_heading.png'}",
          file=sys.stderr if args.json else sys.stdout)  # --json: stdout is the JSON alone
    return 0
