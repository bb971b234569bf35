"""Trace the ROV's gyro witness through an ArduSub recording, step by step, beside the truth.

    .venv/bin/python tools/witness_trace.py ../shared/corpus/ardusub-sitl/att.cap \
        ../shared/corpus/ardusub-sitl/att.toml [--truth att-yaw.csv] [--every 5]

Each printed step: its time, ATTITUDE's time_boot_ms, yaw and yaw rate, the simulator's true
yaw (the ``SIMSTATE`` rows of ``--truth``, the last at or before that time_boot_ms), then the
witness's heading ``psi``, gyro bias (deg/s), innovation reference, sigma, the fast and slow
CUSUMs (each side), whether it suspects or holds a fault, and the manoeuvre state. This is how
issue A's cause was found: on 07053ee the ``att`` capture's bias is 1.63 deg/s at 5 s (the
EKF's yaw alignment fitted as a slope); run it against a checkout of that commit with
``PYTHONPATH=<checkout>`` to see it.
"""

from __future__ import annotations

import argparse
import bisect
import csv
import math
import tempfile
from pathlib import Path

from drivers.capture import CaptureReader
from drivers.mavlink import io as mio
from firmware_host.rov.ardusub import RX, TICK, TX, ArduSubRovVehicle
from firmware_host.rov.replay import recorded_steps
from firmware_host.runtime.config import load_bridge_file, rov_config
from firmware_host.runtime.records import EpochLog


def _truth(path: Path | None) -> tuple[list[int], list[float]]:
    if path is None:
        return [], []
    rows = sorted((int(r["time_boot_ms"]), float(r["yaw_deg"]))
                  for r in csv.DictReader(path.open()) if r["source"] == "SIMSTATE")
    return [k for k, _ in rows], [y for _, y in rows]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("config", type=Path)
    ap.add_argument("--truth", type=Path, default=None, help="the capture's *-yaw.csv")
    ap.add_argument("--every", type=int, default=5, help="print every N-th step")
    args = ap.parse_args()
    keys, yaws = _truth(args.truth)
    rcfg, _ = rov_config(load_bridge_file(args.config))
    vehicle = ArduSubRovVehicle(rcfg)
    vehicle.start_replay(EpochLog(Path(tempfile.mkdtemp())))
    assert vehicle.loop is not None
    print("t tbm yaw rate true | psi bias nu_ref sigma g+ g- gs+ gs- suspect fault man")
    for st in recorded_steps(CaptureReader(args.capture), {}, (TICK, RX, TX)):
        att = [m for m in (mio.decode_packet(r) for r in st.rx)
               if m is not None and m.get_type() == "ATTITUDE"]
        vehicle.step_frames(st.rx)
        if st.k % args.every:
            continue
        w = vehicle.loop.ctl.heading.witness
        tbm = att[-1].time_boot_ms if att else None
        i = bisect.bisect_right(keys, tbm) - 1 if tbm is not None else -1
        true = f"{yaws[i]:.2f}" if i >= 0 else "-"
        yaw = f"{math.degrees(att[-1].yaw) % 360.0:.2f}" if att else "-"
        rate = f"{math.degrees(att[-1].yawspeed):.3f}" if att else "-"
        psi = f"{w.psi % 360.0:.2f}" if w.psi is not None else "-"
        print(f"{st.t:.1f} {tbm} {yaw} {rate} {true} | {psi} {w.bias:.4f} {w.nu_ref:.2f} "
              f"{w.var.sigma:.3f} {w.g_pos:.2f} {w.g_neg:.2f} {w.gs_pos:.2f} {w.gs_neg:.2f} "
              f"{int(w.suspect)} {int(w.fault)} {getattr(w, 'maneuvers', '-')}")


if __name__ == "__main__":
    main()
