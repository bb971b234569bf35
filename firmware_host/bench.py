"""``fdi-bridge bench``: the project's benchmark command (prints a table, writes JSON).

Speed is measured here, never asserted in tests. Figures:

* rover per-epoch processing time (p50/p99/max, ms) — detector and outputs, per epoch;
* offline replay throughput (epochs/s, parse included), without and with a real pty.
"""

from __future__ import annotations

import argparse
import io
import json
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from firmware_host.config import BridgeConfig
from firmware_host.replay import load_input, replay_direct, replay_through_pty
from firmware_host.rover_pipeline import RoverPipeline
from firmware_host.rover_sim import RoverScenario, write_run


def bench_rover(duration_s: float = 600.0, rate_hz: float = 10.0) -> dict[str, Any]:
    tmp = Path(tempfile.mkdtemp(prefix="fdi-bench-"))
    write_run(RoverScenario(rate_hz=rate_hz, duration_s=duration_s, seed=7), tmp)
    inp = load_input(tmp / "rover.nmea")
    cfg = BridgeConfig()
    out: dict[str, Any] = {"epochs": int(duration_s * rate_hz)}
    # Throughput, no pty, no JSON output: parse + detect.
    best = 0.0
    proc: list[float] = []
    for _ in range(3):
        pipe = RoverPipeline(cfg.rover)
        t0 = time.perf_counter()
        replay_direct(inp, pipe)
        dt = time.perf_counter() - t0
        best = max(best, pipe.epochs / dt)
        proc = pipe.proc_s
    arr = np.asarray(proc) * 1e3
    out["epoch_ms"] = {"p50": float(np.percentile(arr, 50)), "p99": float(np.percentile(arr, 99)),
                       "max": float(arr.max())}
    out["throughput_eps_no_pty"] = best
    pipe = RoverPipeline(cfg.rover, jsonl=io.StringIO())
    t0 = time.perf_counter()
    replay_direct(inp, pipe)
    out["throughput_eps_no_pty_jsonl"] = pipe.epochs / (time.perf_counter() - t0)
    pipe = RoverPipeline(cfg.rover, jsonl=io.StringIO())
    t0 = time.perf_counter()
    replay_through_pty(inp, pipe)
    out["throughput_eps_pty_jsonl"] = pipe.epochs / (time.perf_counter() - t0)
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration", type=float, default=600.0,
                        help="simulated seconds of rover data (default 600)")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")


def run(args: argparse.Namespace) -> int:
    res: dict[str, Any] = {
        "machine": {"python": platform.python_version(), "cpu": platform.processor() or
                    platform.machine(), "system": platform.platform()},
        "rover": bench_rover(args.duration),
    }
    r = res["rover"]
    print("| figure | value | goal |")
    print("|---|---|---|")
    print(f"| rover per-epoch p50 (ms) | {r['epoch_ms']['p50']:.4f} | |")
    print(f"| rover per-epoch p99 (ms) | {r['epoch_ms']['p99']:.4f} | < 0.5 |")
    print(f"| rover per-epoch max (ms) | {r['epoch_ms']['max']:.4f} | |")
    print(f"| replay throughput, no pty (epochs/s) | {r['throughput_eps_no_pty']:.0f} | >= 20000 |")
    print(f"| replay throughput, no pty, JSONL (epochs/s) | "
          f"{r['throughput_eps_no_pty_jsonl']:.0f} | |")
    print(f"| replay throughput, pty, JSONL (epochs/s) | {r['throughput_eps_pty_jsonl']:.0f} | |")
    out = args.json or Path(tempfile.gettempdir()) / "fdi-bridge-bench.json"
    out.write_text(json.dumps(res, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {out}")
    return 0
