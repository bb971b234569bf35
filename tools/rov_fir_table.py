"""What the FIR method alone (no gyro: the Outland preset, or ArduSub with gyro = "none")
catches and misses, per fault kind and size, on both simulated plants, seeds 1-10.

    .venv/bin/python tools/rov_fir_table.py > table.md

Each run: config/rov.toml, 110 s, the fault from 50 s; "confirmed" is a confirmation or a stuck
event after the onset; the worst heading error is the true heading's distance from the setpoint
from the onset on (the hold's own floor is about 1.7 deg on nomoto, 3 deg on nonlinear). Prints
a Markdown table (docs/rov.md, "What the FIR method alone catches").
"""

from __future__ import annotations

import sys
from dataclasses import replace

from firmware_host.devtools.rov_experiment import run_experiment
from firmware_host.devtools.rov_sim import parse_fault
from firmware_host.rov.config import load_rov_config, project_root

NOISE_DEG = {"nomoto": 0.5, "nonlinear": 1.0}
ONSET_S = 50.0
CASES = [
    ("step 5 deg", "drift:5@50"), ("step 10 deg", "drift:10@50"),
    ("step 20 deg", "drift:20@50"), ("step 45 deg", "drift:45@50"),
    ("ramp 0.1 deg/s", "ramp:0.1@50"), ("ramp 0.3 deg/s", "ramp:0.3@50"),
    ("ramp 1 deg/s", "ramp:1@50"), ("ramp 3 deg/s", "ramp:3@50"),
    ("stuck 20 s", "stuck@50-70"),
    ("noise 3 deg for 10 s", "noise:3@50-60"), ("noise 5 deg for 5 s", "noise:5@50-55"),
]


def main() -> None:
    cfg0, _ = load_rov_config(project_root() / "config" / "rov.toml")
    print("| fault | plant | confirmed (of 10) | median delay (s) "
          "| worst heading error from the onset (deg) |")
    print("|---|---|---|---|---|")
    for name, spec in CASES:
        for plant, noise in NOISE_DEG.items():
            cfg = replace(cfg0, sim=replace(cfg0.sim, plant=plant, compass_noise_deg=noise))
            delays: list[float] = []
            worst = 0.0
            for seed in range(1, 11):
                ep = run_experiment(cfg, [parse_fault(spec)], 110.0, ft=True, seed=seed,
                                    gyro=False)
                t_c = next((r["t"] for r in ep if r["t"] >= ONSET_S
                            and r["event"] in ("confirmed", "stuck")), None)
                if t_c is not None:
                    delays.append(t_c - ONSET_S)
                worst = max([worst] + [abs((r["heading_true"] - r["setpoint"] + 180.0) % 360.0
                                           - 180.0) for r in ep
                                       if r["t"] >= ONSET_S and r["heading_true"] is not None])
            delays.sort()
            med = f"{delays[len(delays) // 2]:.1f}" if delays else "-"
            print(f"| {name} | {plant} | {len(delays)} | {med} | {worst:.1f} |")
            sys.stdout.flush()


if __name__ == "__main__":
    main()
