"""``fdi-bridge demo``: the rover method end to end, with no hardware.

Generates a 10-minute rover run with injected GPS faults (:mod:`firmware_host.devtools.rover_sim`),
replays it through a real pty into the pipeline with the default preset and with the paper's
preset, scores both against the truth, and prints an aligned table. With the ``plot`` extra
installed it also writes a PNG like the paper's figures (track raw vs corrected; χ² statistic
against its threshold; grey residual against its gate).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any, TextIO

from fdi.errors import UsageError
from firmware_host.commands import tables
from firmware_host.commands.checks import output_dir_arg, positive_float
from firmware_host.commands.replay import run_replay
from firmware_host.devtools.plots import HAVE_MATPLOTLIB, plot_rover
from firmware_host.devtools.progress import Progress
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from firmware_host.devtools.score import read_jsonl, score_rover
from firmware_host.runtime.config import load_config

MIN_DURATION_S = 10.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rate", type=float, default=10.0, choices=[1.0, 5.0, 10.0],
                        help="receiver rate, Hz")
    parser.add_argument("--duration", type=positive_float, default=600.0,
                        help="seconds of generated driving (at least 10)")
    parser.add_argument("--seed", type=int, default=1, help="random seed of the generated run")
    parser.add_argument("--out", type=output_dir_arg, default=None,
                        help="output directory (default: a temporary directory)")
    parser.add_argument("--presets", default="rover,rover-paper",
                        help="comma-separated presets to compare")
    parser.add_argument("--json", action="store_true",
                        help="print the scores as JSON (one object) instead of the table")


def run(args: argparse.Namespace) -> int:
    if args.duration < MIN_DURATION_S:  # the scoring needs fixes before and after the faults
        raise UsageError(f"--duration {args.duration:g}: expected at least "
                         f"{MIN_DURATION_S:g} s")
    # every preset loads (or the one-line config error) before any work
    configs = [load_config(p.strip()) for p in args.presets.split(",") if p.strip()]
    if not configs:
        raise UsageError(f"--presets {args.presets!r}: no preset named")
    out = args.out or Path(tempfile.mkdtemp(prefix="fdi-bridge-demo-"))
    sc = RoverScenario(rate_hz=args.rate, duration_s=args.duration, seed=args.seed)
    names = [p.strip() for p in args.presets.split(",") if p.strip()]
    rows: list[tuple[str, Any, dict[str, Any]]] = []
    # about 25 s at the defaults under load: a bar on a terminal (generate, each replay)
    with Progress(1 + len(names), "demo", unit="step") as bar:
        gen = write_run(sc, out / "run")
        truth = read_jsonl(out / "run" / "truth.jsonl")
        bar.step("generated")
        for preset, cfg in zip(names, configs, strict=True):
            summary = run_replay(cfg, out / "run" / "rover.nmea", out / preset)
            if summary.get("partial"):  # ^C in a replay: no comparison of part of the run
                print(f"fdi-bridge demo: interrupted during the {preset} replay; no "
                      f"comparison (the partial files are in {out})", file=sys.stderr)
                return 130
            score = score_rover(read_jsonl(out / preset / "epochs.jsonl"), truth)
            rows.append((preset, score, summary))
            bar.step(f"replayed {preset}")
    if args.json:  # stdout is the JSON alone; what was written goes to stderr
        print(json.dumps(tables.jsonable({
            "epochs": gen["epochs"], "rate_hz": args.rate, "seed": args.seed, "out": str(out),
            "presets": {preset: {"score": s.as_dict(),
                                 "processing_ms_p99": summ["processing_ms"]["p99"]}
                        for preset, s, summ in rows}})))
        return _plots(rows, out, truth, sys.stderr)
    print(f"Rover demo: {gen['epochs']} epochs at {args.rate:g} Hz, seed {args.seed}, "
          f"replayed through a pty; output in {out}")
    faulty = rows[0][1].faulty if rows else 0
    print(f"faulty epochs injected: {faulty} (jumps of 3-20 sigma, sigma = 0.35 m, and bursts)\n")
    print(tables.table(
        ["preset", "detected", "missed", "false alarms", "alarms", "raw RMS clean (m)",
         "out RMS faulty (m)", "out RMS all (m)", "p99 (ms/epoch)"],
        [[preset, f"{s.detected}/{s.faulty}", s.faulty - s.detected,
          f"{s.false_alarms}/{s.clean}", s.alarms, s.raw_rms_clean_m, s.out_rms_faulty_m,
          s.out_rms_all_m, summ["processing_ms"]["p99"]] for preset, s, summ in rows]))
    return _plots(rows, out, truth, sys.stdout)


def _plots(rows: list[tuple[str, Any, dict[str, Any]]], out: Path, truth: list[dict[str, Any]],
           say: TextIO) -> int:
    """One PNG per preset (with the plot extra), each named on ``say``."""
    if not HAVE_MATPLOTLIB:
        print("\n(for a PNG, install the dev extra: pip install 'fdi-bridge[dev]')",
              file=say)
        return 0
    for preset, _, _ in rows:
        png = plot_rover(read_jsonl(out / preset / "epochs.jsonl"), truth,
                         out / f"{preset}.png", title=f"fdi-bridge demo, preset {preset}")
        print(f"wrote {png}", file=say)
    return 0
